//! Texture-library folders: the maps found by name (ambientCG and Poly Haven layouts), the
//! errors, and the scene keys `material = "FOLDER"` and `folder = "FOLDER"` against scenes that
//! name the same maps one by one.

use std::path::{Path, PathBuf};

use pomkit_core::Technique;
use pomkit_io::library::{self, LibraryError, MapKind, find_maps};
use pomkit_io::scene::{SceneCache, parse_scene, parse_scene_cached, scene_inputs, scene_sizes};

const W: u32 = 24;
const H: u32 = 16;

/// A colour map with a gradient (no two texels alike along a row).
fn color_image() -> image::RgbImage {
    image::RgbImage::from_fn(W, H, |x, y| image::Rgb([(x * 10) as u8, (y * 15) as u8, 90]))
}

/// A height map: a raised square.
fn height_image() -> image::GrayImage {
    image::GrayImage::from_fn(W, H, |x, y| {
        image::Luma([if (6..18).contains(&x) && (4..12).contains(&y) { 220 } else { 30 }])
    })
}

/// An OpenGL normal map whose green varies (so that a flipped green is a different image).
fn normal_gl_image() -> image::RgbImage {
    image::RgbImage::from_fn(W, H, |x, y| {
        let nx = (x as f32 / W as f32 - 0.5) * 0.8;
        let ny = (y as f32 / H as f32 - 0.5) * 0.8;
        let nz = (1.0 - nx * nx - ny * ny).sqrt();
        let enc = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
        image::Rgb([enc(nx), enc(ny), enc(nz)])
    })
}

/// The DirectX twin of an OpenGL normal map: green flipped.
fn flip_green(img: &image::RgbImage) -> image::RgbImage {
    let mut out = img.clone();
    for p in out.pixels_mut() {
        p.0[1] = 255 - p.0[1];
    }
    out
}

fn grey(value: u8) -> image::GrayImage {
    image::GrayImage::from_pixel(W, H, image::Luma([value]))
}

fn touch(dir: &Path, name: &str) {
    std::fs::write(dir.join(name), b"not an image").unwrap();
}

/// An ambientCG folder: `Bricks_1K_Color.png` and the rest, with its preview, its USD and
/// MaterialX files, and a subfolder.
fn ambientcg(dir: &Path) {
    color_image().save(dir.join("Bricks_1K_Color.png")).unwrap();
    normal_gl_image().save(dir.join("Bricks_1K_NormalGL.png")).unwrap();
    flip_green(&normal_gl_image()).save(dir.join("Bricks_1K_NormalDX.png")).unwrap();
    height_image().save(dir.join("Bricks_1K_Displacement.png")).unwrap();
    grey(128).save(dir.join("Bricks_1K_Roughness.png")).unwrap();
    grey(200).save(dir.join("Bricks_1K_AmbientOcclusion.png")).unwrap();
    color_image().save(dir.join("Bricks.png")).unwrap();
    color_image().save(dir.join("Bricks_1K_Color_Preview.jpg")).unwrap();
    touch(dir, "Bricks_1K.usda");
    touch(dir, "Bricks_1K.mtlx");
    std::fs::create_dir(dir.join("2K")).unwrap();
    color_image().save(dir.join("2K").join("Bricks_2K_Color.png")).unwrap();
}

fn file_name(p: &Path) -> &str {
    p.file_name().unwrap().to_str().unwrap()
}

fn ignored(maps: &library::LibraryMaps) -> Vec<(&str, &str)> {
    maps.ignored.iter().map(|i| (file_name(&i.path), i.reason.as_str())).collect()
}

#[test]
fn an_ambientcg_folder_is_classified_and_its_directx_normal_map_left_for_the_opengl_one() {
    let dir = tempfile::tempdir().unwrap();
    ambientcg(dir.path());
    let maps = find_maps(dir.path()).unwrap();
    let name = |k: MapKind| maps.map(k).map(file_name);
    assert_eq!(name(MapKind::Color), Some("Bricks_1K_Color.png"));
    assert_eq!(name(MapKind::Normal), Some("Bricks_1K_NormalGL.png"));
    assert!(!maps.normal_y_down);
    assert_eq!(name(MapKind::Height), Some("Bricks_1K_Displacement.png"));
    assert!(!maps.height_is_bump);
    assert_eq!(name(MapKind::Roughness), Some("Bricks_1K_Roughness.png"));
    assert_eq!(name(MapKind::AmbientOcclusion), Some("Bricks_1K_AmbientOcclusion.png"));
    let ig = ignored(&maps);
    let reason = |n: &str| ig.iter().find(|(f, _)| *f == n).map(|(_, r)| *r).unwrap_or_else(|| panic!("{n} in {ig:?}"));
    assert_eq!(ig.len(), 6, "{ig:?}");
    assert!(reason("Bricks_1K_NormalDX.png").contains("the OpenGL one, Bricks_1K_NormalGL.png, is used"));
    assert_eq!(reason("Bricks.png"), "its name names no map");
    assert_eq!(reason("Bricks_1K_Color_Preview.jpg"), "a preview");
    assert!(reason("Bricks_1K.usda").starts_with("not an image pomkit reads"));
    assert!(reason("Bricks_1K.mtlx").starts_with("not an image pomkit reads"));
    assert!(reason("2K").contains("subfolders are not searched"));
    // The listing a person reads: one line per map, then the ignored files.
    let lines = maps.lines();
    assert_eq!(lines[1], "normal: Bricks_1K_NormalGL.png (OpenGL, +Y up)");
    assert!(lines[4].starts_with("ambient occlusion: Bricks_1K_AmbientOcclusion.png (found, unused"));
    assert_eq!(lines.len(), 5 + 6);
    // The files not to write over: every map found.
    assert_eq!(maps.files().len(), 5);
}

#[test]
fn a_poly_haven_folder_is_classified_despite_rough_in_the_asset_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    color_image().save(d.join("rough_brick_diff_1k.jpg")).unwrap();
    normal_gl_image().save(d.join("rough_brick_nor_gl_1k.png")).unwrap();
    flip_green(&normal_gl_image()).save(d.join("rough_brick_nor_dx_1k.png")).unwrap();
    height_image().save(d.join("rough_brick_disp_1k.png")).unwrap();
    grey(100).save(d.join("rough_brick_rough_1k.png")).unwrap();
    color_image().save(d.join("rough_brick_arm_1k.png")).unwrap();
    let maps = find_maps(d).unwrap();
    let name = |k: MapKind| maps.map(k).map(file_name);
    assert_eq!(name(MapKind::Color), Some("rough_brick_diff_1k.jpg"));
    assert_eq!(name(MapKind::Normal), Some("rough_brick_nor_gl_1k.png"));
    assert_eq!(name(MapKind::Height), Some("rough_brick_disp_1k.png"));
    assert_eq!(name(MapKind::Roughness), Some("rough_brick_rough_1k.png"));
    assert_eq!(name(MapKind::AmbientOcclusion), None);
    let ig = ignored(&maps);
    assert_eq!(ig.len(), 2, "{ig:?}");
    assert!(ig.iter().any(|(f, r)| *f == "rough_brick_arm_1k.png" && r.contains("pomkit does not use")));
    assert!(ig.iter().any(|(f, r)| *f == "rough_brick_nor_dx_1k.png" && r.contains("DirectX")));
}

#[test]
fn a_directx_normal_map_alone_is_read_with_the_flip_and_a_bump_map_serves_as_height() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    flip_green(&normal_gl_image()).save(d.join("Stone-Normal-DX.png")).unwrap();
    height_image().save(d.join("StoneBump.png")).unwrap();
    let maps = find_maps(d).unwrap();
    assert_eq!(maps.normal.as_deref().map(file_name), Some("Stone-Normal-DX.png"));
    assert!(maps.normal_y_down);
    assert_eq!(maps.height.as_deref().map(file_name), Some("StoneBump.png"));
    assert!(maps.height_is_bump);
    // With a displacement map as well, the bump map is left out.
    height_image().save(d.join("Stone_Height.png")).unwrap();
    let maps = find_maps(d).unwrap();
    assert_eq!(maps.height.as_deref().map(file_name), Some("Stone_Height.png"));
    assert!(!maps.height_is_bump);
    assert!(ignored(&maps).iter().any(|(f, r)| *f == "StoneBump.png" && r.contains("bump")));
}

#[test]
fn two_candidates_for_one_map_are_an_error_listing_every_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    color_image().save(d.join("x_Color.png")).unwrap();
    color_image().save(d.join("x_Color.jpg")).unwrap();
    height_image().save(d.join("x_Displacement.png")).unwrap();
    touch(d, "readme.txt");
    let err = find_maps(d).unwrap_err();
    assert!(matches!(&err, LibraryError::Ambiguous { map: MapKind::Color, candidates, .. } if candidates.len() == 2));
    let msg = err.to_string();
    for part in [
        d.to_str().unwrap(),
        "2 candidates for the colour map: x_Color.jpg, x_Color.png",
        "height: x_Displacement.png",
        "normal: none",
        "readme.txt (not an image pomkit reads",
    ] {
        assert!(msg.contains(part), "{part:?} not in: {msg}");
    }

    // Two resolutions of the height map.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    color_image().save(d.join("b_1K_Color.png")).unwrap();
    height_image().save(d.join("b_1K_Displacement.png")).unwrap();
    height_image().save(d.join("b_2K_Displacement.png")).unwrap();
    let msg = find_maps(d).unwrap_err().to_string();
    assert!(msg.contains("2 candidates for the height map: b_1K_Displacement.png, b_2K_Displacement.png"), "{msg}");
    assert!(msg.contains("colour: b_1K_Color.png"), "{msg}");
}

#[test]
fn no_height_no_maps_and_not_a_folder_are_errors_naming_what_was_found() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    color_image().save(d.join("y_Color.png")).unwrap();
    normal_gl_image().save(d.join("y_NormalGL.png")).unwrap();
    let err = find_maps(d).unwrap_err();
    assert!(matches!(err, LibraryError::NoHeight { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("no height map") && msg.contains("colour: y_Color.png") && msg.contains("normal: y_NormalGL.png")
    );

    // An empty folder, and one of other files only.
    let empty = tempfile::tempdir().unwrap();
    let msg = find_maps(empty.path()).unwrap_err().to_string();
    assert!(msg.contains("has no texture maps") && msg.contains("ignored: nothing"), "{msg}");
    touch(empty.path(), "notes.txt");
    let msg = find_maps(empty.path()).unwrap_err().to_string();
    assert!(msg.contains("has no texture maps") && msg.contains("notes.txt (not an image"), "{msg}");

    // A file, and nothing at all.
    let file = d.join("y_Color.png");
    let msg = find_maps(&file).unwrap_err().to_string();
    assert!(msg.contains("y_Color.png") && msg.contains("not a folder (a file)"), "{msg}");
    let msg = find_maps(&d.join("missing")).unwrap_err().to_string();
    assert!(msg.contains("missing") && msg.contains("no such folder"), "{msg}");
}

const CAMERA: &str =
    "[camera]\neye = [0.0, 2.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[light]]\ndirection = [-1.0, 1.0, 0.5]\n";

#[test]
fn material_folder_on_an_object_equals_the_maps_named_one_by_one() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("textures").join("Bricks");
    std::fs::create_dir_all(&tex).unwrap();
    ambientcg(&tex);
    let by_folder =
        parse_scene(&format!("{CAMERA}\n[[object]]\nmesh = \"plane\"\nmaterial = \"textures/Bricks\"\n"), dir.path())
            .unwrap();
    // Roughness 128/255 everywhere: alpha = r^2, shininess = 2 / alpha^2 - 2.
    let r = 128.0f64 / 255.0;
    let shininess = 2.0 / (r * r).powi(2) - 2.0;
    // The lobe normalized to a dielectric's 4%: 0.04 * (n + 8) / 8.
    let specular = 0.04 * (shininess + 8.0) / 8.0;
    let by_name = parse_scene(
        &format!(
            "{CAMERA}\n[[material]]\nname = \"m\"\nalbedo = \"textures/Bricks/Bricks_1K_Color.png\"\n\
             normal = \"textures/Bricks/Bricks_1K_NormalGL.png\"\nheight = \"textures/Bricks/Bricks_1K_Displacement.png\"\n\
             shininess = {shininess}\nspecular = {specular}\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
        ),
        dir.path(),
    )
    .unwrap();
    let (a, b) = (&by_folder.materials[0], &by_name.materials[0]);
    assert_eq!(a.name, "textures/Bricks");
    assert_eq!(by_folder.objects[0].material, 0);
    assert!((a.shininess - b.shininess).abs() < 1e-3, "{} vs {}", a.shininess, b.shininess);
    assert!((a.specular - b.specular).abs() < 1e-5, "{} vs {}", a.specular, b.specular);
    assert_eq!(a.albedo.as_ref().unwrap().texels(), b.albedo.as_ref().unwrap().texels());
    assert_eq!(a.normal_map.as_ref().unwrap().normals(), b.normal_map.as_ref().unwrap().normals());
    assert_eq!(a.height.as_ref().unwrap().depths(), b.height.as_ref().unwrap().depths());
    // Every other setting is the scene file's default.
    assert_eq!((a.technique, a.depth_scale), (b.technique, b.depth_scale));
    assert_eq!(a.technique, Technique::Exact);
}

#[test]
fn a_directx_normal_map_loads_as_its_opengl_twin() {
    let gl = tempfile::tempdir().unwrap();
    let dx = tempfile::tempdir().unwrap();
    for (d, normal) in [
        (gl.path(), ("m_NormalGL.png", normal_gl_image())),
        (dx.path(), ("m_NormalDX.png", flip_green(&normal_gl_image()))),
    ] {
        height_image().save(d.join("m_Displacement.png")).unwrap();
        normal.1.save(d.join(normal.0)).unwrap();
    }
    let load = |folder: &Path| {
        let text = format!("{CAMERA}\n[[object]]\nmesh = \"plane\"\nmaterial = {:?}\n", folder.to_str().unwrap());
        parse_scene(&text, Path::new(".")).unwrap().materials[0].normal_map.clone().unwrap()
    };
    let (a, b) = (load(gl.path()), load(dx.path()));
    let worst = a.normals().iter().zip(b.normals()).map(|(p, q)| (*p - *q).abs().max_element()).fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "the DX map read with the flip differs from the GL map by {worst}");
    // The flip matters: the DX file read as OpenGL is another map.
    let plain = pomkit_io::scene::load_normal_map(&dx.path().join("m_NormalDX.png"), false).unwrap();
    let off =
        a.normals().iter().zip(plain.normals()).map(|(p, q)| (*p - *q).abs().max_element()).fold(0.0f32, f32::max);
    assert!(off > 0.3, "{off}");
}

#[test]
fn a_material_folder_key_gives_defaults_that_the_tables_keys_override() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("lib");
    std::fs::create_dir(&tex).unwrap();
    ambientcg(&tex);
    let text = format!(
        "{CAMERA}\n[[material]]\nname = \"tuned\"\nfolder = \"lib\"\ntechnique = \"relief\"\ndepth_scale = 0.05\n\
         albedo = \"builtin:bricks:8x8\"\nshininess = 12.0\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"tuned\"\n"
    );
    let scene = parse_scene(&text, dir.path()).unwrap();
    let m = &scene.materials[0];
    assert_eq!((m.name.as_str(), m.technique, m.depth_scale, m.shininess), ("tuned", Technique::Relief, 0.05, 12.0));
    assert_eq!(m.albedo.as_ref().unwrap().width(), 8, "the table's albedo wins over the folder's");
    assert_eq!((m.height.as_ref().unwrap().width(), m.normal_map.as_ref().unwrap().width()), (W, W));
    // The table names the colour map: two colour candidates in the folder are then no error.
    color_image().save(tex.join("Bricks_1K_Color.jpg")).unwrap();
    parse_scene(&text, dir.path()).unwrap();
    // normal_y_down on the table applies to the folder's normal map.
    let flipped = parse_scene(&text.replace("shininess = 12.0", "normal_y_down = true"), dir.path()).unwrap();
    let (n0, n1) =
        (m.normal_map.as_ref().unwrap().normals()[0], flipped.materials[0].normal_map.as_ref().unwrap().normals()[0]);
    assert!((n0.y + n1.y).abs() < 1e-6 && n0.y.abs() > 0.1);
    // And without shininess, the roughness map sets it.
    let rough = parse_scene(&text.replace("shininess = 12.0", ""), dir.path()).unwrap();
    assert!((rough.materials[0].shininess - library::shininess_from_roughness(128.0 / 255.0)).abs() < 1e-3);
}

#[test]
fn folder_errors_name_the_scene_the_object_and_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("flat");
    std::fs::create_dir(&tex).unwrap();
    color_image().save(tex.join("f_Color.png")).unwrap();
    let err = parse_scene(
        &format!("{CAMERA}\n[[object]]\nname = \"floor\"\nmesh = \"plane\"\nmaterial = \"flat\"\n"),
        dir.path(),
    )
    .unwrap_err();
    let msg = err.to_string();
    assert_eq!(err.field(), Some("material"));
    assert!(msg.starts_with("<scene>: object 1 (\"floor\"): material \"flat\": the folder"), "{msg}");
    assert!(msg.contains("no height map") && msg.contains("colour: f_Color.png"), "{msg}");
    // On a [[material]], the key is `folder`.
    let err = parse_scene(
        &format!("{CAMERA}\n[[material]]\nname = \"m\"\nfolder = \"missing\"\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"),
        dir.path(),
    )
    .unwrap_err();
    assert_eq!(err.field(), Some("folder"));
    assert!(err.to_string().contains("material \"m\": folder \"missing\""), "{err}");
    // A name that is neither a material nor a folder is still "not defined".
    let msg = parse_scene(&format!("{CAMERA}\n[[object]]\nmesh = \"plane\"\nmaterial = \"nothing\"\n"), dir.path())
        .unwrap_err()
        .to_string();
    assert!(msg.contains("material \"nothing\" is not defined"), "{msg}");
}

#[test]
fn scene_inputs_and_sizes_include_the_folders_maps() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("Bricks");
    std::fs::create_dir(&tex).unwrap();
    ambientcg(&tex);
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, format!("{CAMERA}\n[[object]]\nmesh = \"plane\"\nmaterial = \"Bricks\"\n")).unwrap();
    let inputs: Vec<PathBuf> = scene_inputs(&scene).unwrap();
    for name in [
        "Bricks_1K_Color.png",
        "Bricks_1K_NormalGL.png",
        "Bricks_1K_Displacement.png",
        "Bricks_1K_Roughness.png",
        "Bricks_1K_AmbientOcclusion.png",
    ] {
        assert!(inputs.contains(&dir.path().join("Bricks").join(name)), "{name} not in {inputs:?}");
    }
    let sizes = scene_sizes(&scene).unwrap();
    assert_eq!(sizes.materials.len(), 1);
    let m = &sizes.materials[0];
    assert_eq!((m.height, m.albedo, m.normal_map), (Some((W, H)), Some((W, H)), Some((W, H))));
    assert_eq!(sizes.objects[0].material, Some(0));
}

#[test]
fn the_folder_is_listed_again_on_every_parse_and_map_contents_on_a_cleared_cache() {
    let dir = tempfile::tempdir().unwrap();
    let tex = dir.path().join("Bricks");
    std::fs::create_dir(&tex).unwrap();
    ambientcg(&tex);
    let text = format!("{CAMERA}\n[[object]]\nmesh = \"plane\"\nmaterial = \"Bricks\"\n");
    let mut cache = SceneCache::default();
    let first = parse_scene_cached(&text, Path::new("s.toml"), dir.path(), &mut cache).unwrap();
    // A changed roughness map: the cache keys files by path, so it takes a cleared cache (the
    // viewer's "Reload files") to read it again.
    grey(64).save(tex.join("Bricks_1K_Roughness.png")).unwrap();
    let cached = parse_scene_cached(&text, Path::new("s.toml"), dir.path(), &mut cache).unwrap();
    assert_eq!(cached.materials[0].shininess, first.materials[0].shininess);
    cache.clear();
    let reloaded = parse_scene_cached(&text, Path::new("s.toml"), dir.path(), &mut cache).unwrap();
    assert!((reloaded.materials[0].shininess - library::shininess_from_roughness(64.0 / 255.0)).abs() < 1e-2);
    // A file added to the folder is seen at once: here a second colour map, an error.
    color_image().save(tex.join("Bricks_2K_Color.png")).unwrap();
    let msg = parse_scene_cached(&text, Path::new("s.toml"), dir.path(), &mut cache).unwrap_err().to_string();
    assert!(msg.contains("2 candidates for the colour map"), "{msg}");
}
