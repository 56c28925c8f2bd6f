//! Scene files: a complete scene loads with every field as written, a minimal one gets the
//! defaults, built-in textures need no file, and every kind of mistake is an error naming the
//! scene file and the field (never a panic).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use pomkit_core::glam::{Mat4, Quat, Vec2, Vec3};
use pomkit_core::procedural::{self, Pattern};
use pomkit_core::scene::{Camera, Light, Material, Texture};
use pomkit_core::{EdgeMode, ShadowMode, ShadowParams, Technique, TraceParams};
use pomkit_io::scene::{SceneError, load_scene, parse_scene};
use pomkit_io::{PixelLayout, Pixels, write_image};

fn write(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(&path, contents).unwrap();
    path
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-5
}

/// A quad with UVs (OBJ), for scenes that load a mesh file.
const OBJ_QUAD: &str = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";

/// Writes the textures and mesh the complete scene uses.
fn write_assets(dir: &Path) {
    // 2x1 albedo: sRGB 255 (linear 1) and sRGB 0.
    write_image(&dir.join("bricks_albedo.png"), 2, 1, PixelLayout::Rgb8, Pixels::U8(&[255, 255, 255, 0, 0, 0]))
        .unwrap();
    // 2x2 height: 255 is high (depth 0), 0 deep (depth 1).
    write_image(&dir.join("bricks_height.png"), 2, 2, PixelLayout::Gray8, Pixels::U8(&[255, 0, 0, 255])).unwrap();
    // 1x1 normal map: tilted toward +x, +Y down in the file.
    write_image(&dir.join("bricks_normal.png"), 1, 1, PixelLayout::Rgb8, Pixels::U8(&[200, 100, 200])).unwrap();
    write(dir, "models/quad.obj", OBJ_QUAD);
}

/// Every field written out, none at its default.
const COMPLETE: &str = r#"
background = [0.1, 0.2, 0.3]
ambient = [0.04, 0.05, 0.06]

[camera]
eye = [1.0, 3.0, 5.0]
target = [0.0, 0.5, 0.0]
up = [0.0, 0.0, 1.0]
fov = 60
near = 0.1
far = 50.0

[[light]]
type = "directional"
direction = [-1.0, 1.0, 0.5]
color = [1.0, 0.95, 0.9]
intensity = 3.0

[[light]]
type = "point"
position = [0.0, 4.0, 1.0]
color = [0.5, 0.5, 1.0]
intensity = 20

[[material]]
name = "bricks"
albedo = "bricks_albedo.png"
height = "bricks_height.png"
depth_map = true
channel = "r"
normalize = true
normal = "bricks_normal.png"
normal_y_down = true
base_color = [0.9, 0.8, 0.7]
technique = "relief"
depth_scale = 0.08
min_samples = 4
max_samples = 48
samples = 24
iterations = 6
binary_steps = 8
refine = 2
perspective_bias = 0.5
edges = "clamp"
shadow = "soft"
softness = 0.2
lod_threshold = 3.5
specular = 0.5
shininess = 64.0
pixel_depth_offset = false

[[material]]
name = "stone"
height = "builtin:cobblestones:32x16"
albedo = "builtin:cobblestones:32x16"

[[object]]
name = "floor"
mesh = "plane"
size = [4.0, 3.0]
segments = 2
uv_repeat = [2.0, 3.0]
material = "bricks"
position = [1.0, 2.0, 3.0]
rotation = [0.0, 45.0, 0.0]
scale = [1.0, 2.0, 3.0]

[[object]]
name = "panel"
mesh = "models/quad.obj"
material = "stone"
scale = 2

[[object]]
mesh = "models/quad.obj"
material = "stone"
"#;

#[test]
fn complete_scene_loads_every_field_as_written() {
    let dir = tempfile::tempdir().unwrap();
    write_assets(dir.path());
    let path = write(dir.path(), "scene.toml", COMPLETE);
    let scene = load_scene(&path).unwrap();

    assert_eq!(scene.background, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(scene.ambient, Vec3::new(0.04, 0.05, 0.06));
    let c = scene.camera;
    assert_eq!(
        c,
        Camera {
            eye: Vec3::new(1.0, 3.0, 5.0),
            target: Vec3::new(0.0, 0.5, 0.0),
            up: Vec3::Z,
            fov_y_deg: 60.0,
            near: 0.1,
            far: 50.0
        }
    );
    assert_eq!(
        scene.lights,
        vec![
            Light::Directional {
                direction: Vec3::new(-1.0, 1.0, 0.5),
                color: Vec3::new(1.0, 0.95, 0.9),
                intensity: 3.0
            },
            Light::Point { position: Vec3::new(0.0, 4.0, 1.0), color: Vec3::new(0.5, 0.5, 1.0), intensity: 20.0 },
        ]
    );

    assert_eq!(scene.materials.len(), 2);
    let m = &scene.materials[0];
    assert_eq!(m.name, "bricks");
    assert_eq!(m.base_color, Vec3::new(0.9, 0.8, 0.7));
    assert_eq!(m.technique, Technique::Relief);
    assert_eq!((m.depth_scale, m.edges), (0.08, EdgeMode::Clamp));
    assert_eq!(
        m.trace,
        TraceParams {
            min_samples: 4,
            max_samples: 48,
            samples: 24,
            iterations: 6,
            binary_steps: 8,
            refine: 2,
            perspective_bias: 0.5,
            ..TraceParams::default()
        }
    );
    assert_eq!(m.shadow, ShadowParams { mode: ShadowMode::Soft, softness: 0.2 });
    assert_eq!((m.lod_threshold, m.specular, m.shininess, m.pixel_depth_offset), (3.5, 0.5, 64.0, false));
    // Albedo: sRGB to linear.
    let albedo = m.albedo.as_ref().unwrap();
    assert_eq!((albedo.width(), albedo.height()), (2, 1));
    assert_eq!(albedo.texels(), &[Vec3::ONE, Vec3::ZERO]);
    // Height: red channel, read as depth (white = deep), normalized.
    let height = m.height.as_ref().unwrap();
    assert_eq!((height.width(), height.height()), (2, 2));
    assert_eq!(height.depths(), &[1.0, 0.0, 0.0, 1.0]);
    // Normal map: decoded, +Y down flipped to +Y up.
    let normal = m.normal_map.as_ref().unwrap();
    let n = normal.normals()[0];
    let raw = Vec3::new(200.0, 100.0, 200.0) / 255.0 * 2.0 - 1.0;
    assert!(close(n, Vec3::new(raw.x, -raw.y, raw.z).normalize()), "{n}");

    let stone = &scene.materials[1];
    let (h, a) = (stone.height.as_ref().unwrap(), stone.albedo.as_ref().unwrap());
    assert_eq!((h.width(), h.height(), a.width(), a.height()), (32, 16, 32, 16));

    assert_eq!(scene.objects.len(), 3);
    let floor = &scene.objects[0];
    assert_eq!((floor.name.as_str(), floor.material), ("floor", 0));
    let rotation = Quat::from_rotation_y(45f32.to_radians());
    let expected = Mat4::from_scale_rotation_translation(Vec3::new(1.0, 2.0, 3.0), rotation, Vec3::new(1.0, 2.0, 3.0));
    assert!(floor.transform.abs_diff_eq(expected, 1e-6), "{}", floor.transform);
    // A 4 x 3 plane of 2 x 2 segments, UVs repeated 2 x 3 times.
    assert_eq!(floor.mesh.positions.len(), 9);
    let (lo, hi) = floor.mesh.bounds();
    assert!(close(lo, Vec3::new(-2.0, 0.0, -1.5)) && close(hi, Vec3::new(2.0, 0.0, 1.5)), "{lo} {hi}");
    let max_uv = floor.mesh.uvs.iter().fold(Vec2::ZERO, |m, uv| m.max(*uv));
    assert_eq!(max_uv, Vec2::new(2.0, 3.0));

    let panel = &scene.objects[1];
    assert_eq!((panel.name.as_str(), panel.material), ("panel", 1));
    assert!(panel.transform.abs_diff_eq(Mat4::from_scale(Vec3::splat(2.0)), 1e-6));
    assert_eq!(panel.mesh.positions.len(), 4);
    // The same file is loaded once and shared.
    let third = &scene.objects[2];
    assert_eq!(third.name, "object 3");
    assert!(Arc::ptr_eq(&panel.mesh, &third.mesh));
}

#[test]
fn minimal_scene_gets_the_defaults() {
    let text = r#"
        [camera]
        eye = [0.0, 2.0, 4.0]
        target = [0.0, 0.0, 0.0]

        [[material]]

        [[object]]
        mesh = "cube"
        material = "material 1"
    "#;
    let scene = parse_scene(text, Path::new(".")).unwrap();
    assert_eq!(scene.camera, Camera { eye: Vec3::new(0.0, 2.0, 4.0), target: Vec3::ZERO, ..Camera::default() });
    assert!(scene.lights.is_empty(), "no [[light]]: ambient light only");
    assert_eq!(scene.background, Vec3::new(0.02, 0.02, 0.03));
    assert_eq!(scene.ambient, Vec3::new(0.05, 0.05, 0.06));
    let m = &scene.materials[0];
    let d = Material::default();
    assert_eq!(m.name, "material 1");
    assert!(m.albedo.is_none() && m.height.is_none() && m.normal_map.is_none());
    assert_eq!(m.base_color, d.base_color);
    assert_eq!(m.technique, d.technique);
    assert_eq!(m.trace, TraceParams::default());
    assert_eq!(m.shadow, ShadowParams::default());
    assert_eq!(
        (m.lod_threshold, m.specular, m.shininess, m.pixel_depth_offset),
        (d.lod_threshold, d.specular, d.shininess, d.pixel_depth_offset)
    );
    let o = &scene.objects[0];
    assert_eq!((o.name.as_str(), o.material), ("object 1", 0));
    assert_eq!(o.transform, Mat4::IDENTITY);
    let (lo, hi) = o.mesh.bounds();
    assert!(close(lo, Vec3::splat(-1.0)) && close(hi, Vec3::ONE), "default cube edge 2: {lo} {hi}");
}

#[test]
fn default_lights_and_shapes() {
    let text = r#"
        [camera]
        eye = [0, 0, 5]
        target = [0, 0, 0]
        [[light]]
        [[light]]
        type = "point"
        [[material]]
        name = "m"
        [[object]]
        mesh = "sphere"
        radius = 0.5
        rings = 4
        segments = 6
        material = "m"
        [[object]]
        mesh = "torus"
        radius = 2
        tube_radius = 0.5
        segments = 8
        tube_segments = 4
        material = "m"
        [[object]]
        mesh = "cylinder"
        height = 3
        material = "m"
        [[object]]
        mesh = "disc"
        segments = 5
        material = "m"
        [[object]]
        mesh = "quad"
        size = 1
        material = "m"
    "#;
    let scene = parse_scene(text, Path::new(".")).unwrap();
    assert_eq!(
        scene.lights,
        vec![
            Light::Directional { direction: Vec3::Y, color: Vec3::ONE, intensity: 1.0 },
            Light::Point { position: Vec3::new(0.0, 4.0, 0.0), color: Vec3::ONE, intensity: 1.0 },
        ]
    );
    let bounds: Vec<(Vec3, Vec3)> = scene.objects.iter().map(|o| o.mesh.bounds()).collect();
    assert!((bounds[0].1.y - 0.5).abs() < 1e-5, "sphere radius: {:?}", bounds[0]);
    assert!((bounds[1].1.x - 2.5).abs() < 1e-2, "torus outer radius: {:?}", bounds[1]);
    assert!((bounds[2].1.y - 1.5).abs() < 1e-5, "cylinder half height: {:?}", bounds[2]);
    assert!((bounds[4].1.x - 0.5).abs() < 1e-5, "quad half size: {:?}", bounds[4]);
    assert_eq!(scene.objects[3].mesh.triangle_count(), 5);
}

#[test]
fn rotation_is_about_x_then_y_then_z() {
    let text = r#"
        [camera]
        eye = [0, 0, 5]
        target = [0, 0, 0]
        [[material]]
        name = "m"
        [[object]]
        mesh = "quad"
        material = "m"
        rotation = [90, 90, 0]
        position = [0, 0, 1]
    "#;
    let scene = parse_scene(text, Path::new(".")).unwrap();
    let t = scene.objects[0].transform;
    // +Y: about X by 90 -> +Z; then about Y by 90 -> +X; then moved by (0, 0, 1).
    assert!(close(t.transform_point3(Vec3::Y), Vec3::new(1.0, 0.0, 1.0)), "{}", t.transform_point3(Vec3::Y));
    // +X: about X stays; about Y by 90 -> -Z.
    assert!(close(t.transform_vector3(Vec3::X), -Vec3::Z), "{}", t.transform_vector3(Vec3::X));
}

#[test]
fn builtin_textures_need_no_file() {
    let text = r#"
        [camera]
        eye = [0, 2, 4]
        target = [0, 0, 0]
        [[material]]
        name = "bricks"
        albedo = "builtin:bricks:16x8"
        height = "builtin:bricks"
        technique = "pom"
        [[material]]
        name = "waves"
        height = "builtin:WAVES:3x5"
        [[object]]
        mesh = "plane"
        material = "bricks"
    "#;
    let scene = parse_scene(text, Path::new("/nonexistent/folder")).unwrap();
    let bricks = &scene.materials[0];
    let height = bricks.height.as_ref().unwrap();
    assert_eq!((height.width(), height.height()), (512, 512), "default built-in size");
    assert_eq!(**height, procedural::generate(Pattern::Bricks, 512, 512));
    let albedo = bricks.albedo.as_ref().unwrap();
    assert_eq!(**albedo, Texture::from_srgb8(16, 8, &procedural::albedo(Pattern::Bricks, 16, 8)).unwrap());
    let waves = scene.materials[1].height.as_ref().unwrap();
    assert_eq!((waves.width(), waves.height()), (3, 5));
}

/// McGuire 2005's fur and grass: the built-in maps and the depth shadow mode in a scene file.
#[test]
fn fur_and_grass_with_depth_shadows() {
    let text = r#"
        [camera]
        eye = [0, 2, 4]
        target = [0, 0, 0]
        [[material]]
        name = "fur"
        albedo = "builtin:fur:48x40"
        height = "builtin:Fur:48x40"
        technique = "steep"
        shadow = "depth"
        [[material]]
        name = "grass"
        albedo = "builtin:grass:30x20"
        height = "builtin:grass:30x20"
        shadow = "DEPTH"
        [[object]]
        mesh = "sphere"
        material = "fur"
    "#;
    let scene = parse_scene(text, Path::new("/nonexistent/folder")).unwrap();
    for (m, pattern, (w, h)) in
        [(&scene.materials[0], Pattern::Fur, (48, 40)), (&scene.materials[1], Pattern::Grass, (30, 20))]
    {
        assert_eq!(**m.height.as_ref().unwrap(), procedural::generate(pattern, w, h), "{pattern}");
        let albedo = Texture::from_srgb8(w, h, &procedural::albedo(pattern, w, h)).unwrap();
        assert_eq!(**m.albedo.as_ref().unwrap(), albedo, "{pattern}");
        assert_eq!(m.shadow.mode, ShadowMode::Depth, "{pattern}");
    }
    assert_eq!(scene.materials[0].technique, Technique::Steep);
}

/// Loads `text` as `scene.toml` in a folder holding the test assets.
fn load_err(text: &str) -> SceneError {
    let dir = tempfile::tempdir().unwrap();
    write_assets(dir.path());
    write(dir.path(), "flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let path = write(dir.path(), "scene.toml", text);
    match load_scene(&path) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e,
    }
}

/// A valid scene with one line replaced or added: `field = value` goes into the [[material]]
/// "bricks" table, or wherever `table` says.
fn with(table: &str, line: &str) -> String {
    let mut text = String::from(
        "[camera]\neye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n\n\
         [[light]]\ndirection = [1.0, 1.0, 0.0]\n\n\
         [[material]]\nname = \"bricks\"\nheight = \"bricks_height.png\"\n\n\
         [[material]]\nname = \"stone\"\n\n\
         [[object]]\nname = \"floor\"\nmesh = \"plane\"\nmaterial = \"bricks\"\n\n\
         [[object]]\nname = \"wall\"\nmesh = \"quad\"\nmaterial = \"stone\"\n",
    );
    let anchor = match table {
        "camera" => "[camera]\n",
        "light" => "[[light]]\n",
        "material" => "name = \"bricks\"\n",
        "object" => "name = \"wall\"\n",
        "top" => "",
        other => panic!("{other}"),
    };
    let at = text.find(anchor).unwrap() + anchor.len();
    text.insert_str(at, &format!("{line}\n"));
    text
}

/// Asserts that the error's message names the scene file and contains every one of `parts`.
#[track_caller]
fn assert_names(err: &SceneError, parts: &[&str]) {
    let msg = err.to_string();
    assert!(msg.contains("scene.toml"), "no file name in: {msg}");
    for p in parts {
        assert!(msg.contains(p), "{p:?} missing from: {msg}");
    }
}

#[test]
fn the_valid_base_scene_loads() {
    let dir = tempfile::tempdir().unwrap();
    write_assets(dir.path());
    let path = write(dir.path(), "scene.toml", with("top", ""));
    let scene = load_scene(&path).unwrap();
    assert_eq!(scene.objects.len(), 2);
}

#[test]
fn missing_texture_names_field_and_file() {
    let err = load_err(&with("material", "albedo = \"nothere.png\""));
    assert_names(&err, &["material \"bricks\"", "albedo", "nothere.png"]);
    assert_eq!(err.field(), Some("albedo"));
    let err = load_err(&with("top", "").replace("bricks_height.png", "bricks.png"));
    assert_names(&err, &["material \"bricks\": height: cannot read", "bricks.png"]);
    let err = load_err(&with("material", "normal = \"missing_normal.png\""));
    assert_names(&err, &["normal", "missing_normal.png"]);
    // Not an image at all.
    let err = load_err(&with("material", "albedo = \"flat.obj\""));
    assert_names(&err, &["albedo", "flat.obj"]);
    // A greyscale image is not a normal map.
    let err = load_err(&with("material", "normal = \"bricks_height.png\""));
    assert_names(&err, &["normal", "bricks_height.png", "height map"]);
}

#[test]
fn wrong_types_name_the_field_and_line() {
    let cases = [
        ("material", "depth_scale = \"a\"", "depth_scale"),
        ("material", "min_samples = -1", "min_samples"),
        ("material", "min_samples = 1.5", "min_samples"),
        ("material", "pixel_depth_offset = 1", "pixel_depth_offset"),
        ("material", "base_color = [1.0, 1.0]", "base_color"),
        ("camera", "fov = \"wide\"", "fov"),
        ("object", "scale = \"big\"", "scale"),
        ("object", "position = 3", "position"),
        ("light", "intensity = [1]", "intensity"),
        ("top", "ambient = 0.5", "ambient"),
    ];
    for (table, line, field) in cases {
        let text = with(table, line);
        let err = load_err(&text);
        assert!(matches!(err, SceneError::Syntax { .. }), "{line}: {err:?}");
        let line_no = text.lines().position(|l| l == line).unwrap() + 1;
        assert_names(&err, &[field, &format!("line {line_no}")]);
    }
    let err = load_err(&with("material", "depth_scale = \"a\""));
    assert_names(&err, &["material \"bricks\"", "depth_scale", "expected a number"]);
    let err = load_err(&with("object", "scale = \"big\""));
    assert_names(&err, &["object 2 (\"wall\")", "a number or an array"]);
}

#[test]
fn unknown_names_list_the_choices() {
    let err = load_err(&with("material", "technique = \"pomm\""));
    assert_names(&err, &["material \"bricks\": technique \"pomm\" is unknown: expected one of flat, normal, "]);
    assert_eq!(err.field(), Some("technique"));
    let err = load_err(&with("material", "shadow = \"blurry\""));
    assert_names(&err, &["shadow \"blurry\" is unknown", "none, hard, soft, exact, depth"]);
    let err = load_err(&with("material", "edges = \"mirror\""));
    assert_names(&err, &["edges \"mirror\"", "wrap or clamp"]);
    let err = load_err(&with("material", "channel = \"alpha\""));
    assert_names(&err, &["channel \"alpha\"", "r, g, b, a, luma"]);
    let err = load_err(&with("light", "type = \"spot\""));
    assert_names(&err, &["light 1", "type \"spot\"", "directional or point"]);
    let err = load_err(&with("material", "albedo = \"builtin:marble\""));
    assert_names(&err, &["albedo", "marble", "bricks, pyramids"]);
    let err = load_err(&with("material", "albedo = \"builtin:bricks:0x5\""));
    assert_names(&err, &["albedo", "0x5", "16384"]);
    let err = load_err(&with("top", "").replace("mesh = \"quad\"", "mesh = \"pyramid\""));
    assert_names(&err, &["object 2 (\"wall\")", "mesh \"pyramid\"", "sphere", ".gltf"]);
}

#[test]
fn unknown_fields_are_errors_with_their_line() {
    let text = with("material", "tecnique = \"pom\"");
    let err = load_err(&text);
    let line_no = text.lines().position(|l| l.starts_with("tecnique")).unwrap() + 1;
    assert_names(&err, &[&format!("line {line_no}"), "unknown field `tecnique`", "material \"bricks\""]);
    let err = load_err(&with("camera", "position = [0, 0, 0]"));
    assert_names(&err, &["camera", "unknown field `position`"]);
    let err = load_err(&with("top", "backgroud = [0, 0, 0]"));
    assert_names(&err, &["unknown field `backgroud`"]);
    let err = load_err(&with("top", "[[lights]]"));
    assert_names(&err, &["unknown field `lights`"]);
}

#[test]
fn undefined_material_lists_the_defined_ones() {
    let err = load_err(&with("top", "").replace("material = \"bricks\"", "material = \"brick\""));
    assert_names(&err, &["object 1 (\"floor\"): material \"brick\" is not defined (materials: bricks, stone)"]);
    assert_eq!(err.field(), Some("material"));
}

#[test]
fn mesh_without_uvs_names_object_mesh_and_file() {
    let err = load_err(&with("object", "").replace("mesh = \"quad\"", "mesh = \"flat.obj\""));
    assert_names(&err, &["object 2 (\"wall\"): mesh \"flat.obj\"", "has no texture coordinates", "flat.obj"]);
    let err = load_err(&with("top", "").replace("mesh = \"quad\"", "mesh = \"gone.glb\""));
    assert_names(&err, &["mesh \"gone.glb\"", "cannot read", "gone.glb"]);
}

#[test]
fn out_of_range_values_name_the_field() {
    let cases: [(&str, &str, &[&str]); 19] = [
        ("material", "depth_scale = 0", &["material \"bricks\"", "depth_scale is 0"]),
        ("material", "depth_scale = -0.1", &["depth_scale is -0.1"]),
        ("material", "depth_scale = nan", &["depth_scale is NaN"]),
        ("material", "depth_scale = inf", &["depth_scale is inf"]),
        ("material", "min_samples = 40", &["min_samples (40) exceeds max_samples (32)"]),
        ("material", "perspective_bias = nan", &["perspective_bias"]),
        ("material", "softness = -1", &["softness is -1"]),
        ("material", "shininess = 0", &["shininess is 0"]),
        ("material", "specular = nan", &["specular is NaN"]),
        ("material", "base_color = [1, -1, 1]", &["base_color", "negative"]),
        ("camera", "fov = 180", &["camera", "fov is 180"]),
        ("camera", "fov = 0", &["fov is 0"]),
        ("camera", "near = 0", &["near is 0"]),
        ("camera", "far = 0.01", &["far is 0.01"]),
        ("camera", "up = [0.0, 0.0, 0.0]", &["up is"]),
        ("light", "intensity = -2", &["light 1", "intensity is -2"]),
        ("object", "scale = 0", &["object 2 (\"wall\")", "scale is"]),
        ("object", "uv_repeat = [1.0, inf]", &["uv_repeat is"]),
        ("object", "position = [0.0, nan, 0.0]", &["position is"]),
    ];
    for (table, line, parts) in cases {
        let err = load_err(&with(table, line));
        assert!(matches!(err, SceneError::Invalid { .. }), "{line}: {err:?}");
        assert_names(&err, parts);
    }
    // The camera cannot look at itself.
    let err = load_err(&with("top", "").replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 2.0, 4.0]"));
    assert_names(&err, &["camera", "target", "equals eye"]);
}

#[test]
fn inconsistent_fields_are_errors() {
    let cases: [(&str, &str, &[&str]); 11] = [
        ("object", "radius = 2.0", &["object 2 (\"wall\")", "radius does not apply to mesh \"quad\" (it takes: size)"]),
        ("object", "segments = 2", &["segments does not apply"]),
        ("light", "position = [0, 1, 0]", &["light 1", "position applies to point lights"]),
        ("light", "type = \"point\"", &["light 1", "direction applies to directional lights only"]),
        ("material", "normal_y_down = true", &["normal_y_down", "no normal map"]),
        ("material", "albedo = \"builtin:bricks:64\"", &["albedo", "WxH"]),
        ("material", "normal = \"builtin:bricks\"", &["normal", "built-in"]),
        ("top", "[[material]]\nname = \"bricks\"", &["name \"bricks\" is used"]),
        (
            "top",
            "[[material]]\nname = \"x\"\ntechnique = \"steep\"",
            &["material \"x\"", "technique \"steep\"", "height"],
        ),
        ("top", "[[material]]\nname = \"x\"\nchannel = \"r\"", &["channel is set", "no height map"]),
        (
            "top",
            "[[material]]\nname = \"x\"\nheight = \"builtin:waves\"\ndepth_map = true",
            &["depth_map", "builtin:waves"],
        ),
    ];
    for (table, line, parts) in cases {
        let err = load_err(&with(table, line));
        assert_names(&err, parts);
    }
    let zero_light = with("top", "").replace("direction = [1.0, 1.0, 0.0]", "direction = [0, 0, 0]");
    assert_names(&load_err(&zero_light), &["light 1", "direction is zero"]);
    let twice = with("light", "direction = [0, 1, 0]");
    assert_names(&load_err(&twice), &["light 1", "direction", "duplicate key"]);
    let plane_with_cube_size = with("top", "").replace("mesh = \"plane\"", "mesh = \"cube\"\nsize = [1.0, 2.0]");
    assert_names(&load_err(&plane_with_cube_size), &["size", "cube", "scale"]);
    let file_with_size = with("top", "").replace("mesh = \"quad\"", "mesh = \"models/quad.obj\"\nsize = 2");
    assert_names(&load_err(&file_with_size), &["size applies to built-in shapes", "models/quad.obj"]);
}

#[test]
fn structural_mistakes_are_errors() {
    // No camera.
    let err = load_err("[[material]]\nname = \"m\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n");
    assert_names(&err, &["missing field `camera`"]);
    // No eye.
    let err = load_err(&with("top", "").replace("eye = [0.0, 2.0, 4.0]\n", ""));
    assert_names(&err, &["camera", "missing field `eye`"]);
    // An object without a mesh or material.
    let err = load_err(&with("top", "").replace("mesh = \"quad\"\n", ""));
    assert_names(&err, &["object 2 (\"wall\")", "missing field `mesh`"]);
    // No objects.
    let err = load_err("[camera]\neye = [0, 1, 2]\ntarget = [0, 0, 0]\n");
    assert_names(&err, &["at least one", "object"]);
    // TOML syntax errors.
    let err = load_err("[camera\neye = [0, 1, 2]\n");
    assert_names(&err, &["line 1"]);
    let err = load_err(&with("material", "depth_scale = "));
    assert_names(&err, &["line"]);
    // An unreadable scene.
    let dir = tempfile::tempdir().unwrap();
    let err = load_scene(&dir.path().join("scene.toml")).unwrap_err();
    assert!(matches!(err, SceneError::Read { .. }));
    assert_names(&err, &["cannot read"]);
    let err = load_scene(&write(dir.path(), "scene.toml", [0xff, 0xfe, 0x00])).unwrap_err();
    assert_names(&err, &["cannot read"]);
}

#[test]
fn paths_are_relative_to_the_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("assets")).unwrap();
    write_assets(&dir.path().join("assets"));
    let text = with("top", "")
        .replace("bricks_height.png", "../assets/bricks_height.png")
        .replace("mesh = \"quad\"", "mesh = \"../assets/models/quad.obj\"");
    let path = write(dir.path(), "scenes/scene.toml", text);
    let scene = load_scene(&path).unwrap();
    assert_eq!(scene.objects[1].mesh.positions.len(), 4);
}

#[test]
fn no_prefix_of_a_scene_panics() {
    // Every truncation of a valid scene either loads or fails with an error naming the file.
    let dir = tempfile::tempdir().unwrap();
    write_assets(dir.path());
    let path = dir.path().join("scene.toml");
    for end in (0..COMPLETE.len()).step_by(7) {
        std::fs::write(&path, &COMPLETE[..end]).unwrap();
        if let Err(e) = load_scene(&path) {
            assert!(e.to_string().contains("scene.toml"), "{e}");
        }
    }
}

#[test]
fn missing_fields_are_not_blamed_on_their_neighbours() {
    let err = load_err(&with("top", "").replace("eye = [0.0, 2.0, 4.0]\n", ""));
    assert_eq!(err.field(), None, "{err}");
    assert!(!err.to_string().contains("target"), "{err}");
    let err = load_err(&with("material", "depth_scale = \"a\""));
    assert_eq!(err.field(), Some("depth_scale"), "{err}");
}

#[test]
fn a_scene_cache_loads_each_file_once_until_cleared() {
    use pomkit_io::scene::{SceneCache, parse_scene_cached};
    let dir = tempfile::tempdir().unwrap();
    let height: Vec<u8> = (0..64u32 * 64).map(|i| (i % 64 * 4) as u8).collect();
    write_image(&dir.path().join("h.png"), 64, 64, PixelLayout::Gray8, Pixels::U8(&height)).unwrap();
    let text = |depth: f32| {
        format!(
            "[camera]\neye = [0, 1, 2]\ntarget = [0, 0, 0]\n[[material]]\nname = \"m\"\nheight = \"h.png\"\n\
             albedo = \"builtin:bricks:32x32\"\ndepth_scale = {depth}\n[[object]]\nmesh = \"sphere\"\nmaterial = \"m\"\n"
        )
    };
    let file = dir.path().join("s.toml");
    let mut cache = SceneCache::default();
    let a = parse_scene_cached(&text(0.1), &file, dir.path(), &mut cache).unwrap();
    assert_eq!(cache.len(), 2, "the height and albedo maps (built-in shapes are not cached)");
    // An edit of a number reuses the loaded maps.
    let b = parse_scene_cached(&text(0.05), &file, dir.path(), &mut cache).unwrap();
    assert_eq!(b.materials[0].depth_scale, 0.05);
    assert!(Arc::ptr_eq(a.materials[0].height.as_ref().unwrap(), b.materials[0].height.as_ref().unwrap()));
    assert!(Arc::ptr_eq(a.materials[0].albedo.as_ref().unwrap(), b.materials[0].albedo.as_ref().unwrap()));
    // A changed file is picked up after clear().
    let flat = vec![128u8; 64 * 64];
    write_image(&dir.path().join("h.png"), 64, 64, PixelLayout::Gray8, Pixels::U8(&flat)).unwrap();
    let stale = parse_scene_cached(&text(0.05), &file, dir.path(), &mut cache).unwrap();
    assert!(Arc::ptr_eq(a.materials[0].height.as_ref().unwrap(), stale.materials[0].height.as_ref().unwrap()));
    cache.clear();
    assert!(cache.is_empty());
    let fresh = parse_scene_cached(&text(0.05), &file, dir.path(), &mut cache).unwrap();
    let f = fresh.materials[0].height.as_ref().unwrap();
    let old = a.materials[0].height.as_ref().unwrap();
    assert_ne!(f.depths()[10], old.depths()[10], "the new file's values");
}

#[test]
fn a_baked_cone_map_goes_with_its_height_map() {
    let dir = tempfile::tempdir().unwrap();
    write_assets(dir.path());
    // Relaxed cones of the built-in cobblestones, as `pomkit bake cone --relaxed` writes them.
    let field = procedural::generate(Pattern::Cobblestones, 32, 16);
    let cones = pomkit_core::cone::ConeMap::relaxed_cones(&field, EdgeMode::Wrap);
    let samples = cones.to_gray_alpha16();
    write_image(&dir.path().join("cones.png"), 32, 16, PixelLayout::GrayAlpha16, Pixels::U16(&samples)).unwrap();
    let scene_with = |material: &str| {
        format!(
            "[camera]\neye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[material]]\nname = \"stone\"\n{material}\n\n\
             [[object]]\nmesh = \"plane\"\nmaterial = \"stone\"\n"
        )
    };
    let good = scene_with("height = \"builtin:cobblestones:32x16\"\ntechnique = \"cone\"\ncone_map = \"cones.png\"");
    let scene = load_scene(&write(dir.path(), "scene.toml", good)).unwrap();
    let loaded = scene.materials[0].cones.as_ref().expect("the cone map");
    assert!(loaded.relaxed(), "a cone map read from an image is walked as relaxed cones");
    assert_eq!(loaded.size(), (32, 16));
    // The cones as baked: encoding rounds to the safe side, so a round trip may move a sample
    // by one step, never more.
    let again = loaded.to_gray_alpha16();
    assert!(again.iter().zip(&samples).all(|(&a, &b)| a.abs_diff(b) <= 1), "the cones as baked");
    // Without one, the cones are built when needed.
    let plain = scene_with("height = \"builtin:cobblestones:32x16\"\ntechnique = \"cone\"");
    assert!(load_scene(&write(dir.path(), "scene.toml", plain)).unwrap().materials[0].cones.is_none());

    let fails = |material: &str| load_scene(&write(dir.path(), "scene.toml", scene_with(material))).unwrap_err();
    // Another map's size: both sizes, and how to make the right one.
    let err = fails("height = \"builtin:cobblestones:64x16\"\ncone_map = \"cones.png\"");
    assert_names(&err, &["material \"stone\"", "cone_map", "cones.png", "32x16", "64x16", "bake cone"]);
    assert_eq!(err.field(), Some("cone_map"));
    // Not a cone map: a greyscale height image.
    let err = fails("height = \"builtin:cobblestones:2x2\"\ncone_map = \"bricks_height.png\"");
    assert_names(&err, &["cone_map", "bricks_height.png", "not a cone map"]);
    // No height map for it to belong to; missing file; built-in.
    assert_names(&fails("cone_map = \"cones.png\""), &["cone_map", "no height map"]);
    assert_names(&fails("height = \"builtin:cobblestones:32x16\"\ncone_map = \"gone.png\""), &["cone_map", "gone.png"]);
    assert_names(
        &fails("height = \"builtin:cobblestones:32x16\"\ncone_map = \"builtin:cobblestones\""),
        &["cone_map", "no built-in cone maps"],
    );
}
