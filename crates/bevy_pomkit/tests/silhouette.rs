//! Silhouettes in Bevy (`Pomkit::silhouette`), against pomkit's CPU renderer drawing the really
//! displaced mesh: the cobblestone sphere of pomkit's own silhouette tests, seen by the same
//! camera, its coverage (which pixels the sphere covers) with and without silhouettes compared
//! with the displaced truth's. Also: discarded pixels show what lies behind them with a depth
//! prepass, and meshes whose curvature cannot be computed are reported and drawn plain.
//!
//! All tests share one lock: each builds a Bevy app with its own GPU device.

#[path = "../examples/support/headless.rs"]
mod headless;
#[path = "../../pomkit-cpu/tests/support/silhouettes.rs"]
#[expect(dead_code, reason = "the torus, pomkit's renderers' second shape, is not drawn here")]
mod silhouettes;
#[path = "../examples/support/sphere.rs"]
#[expect(dead_code, reason = "the tests build the sphere of pomkit's scene themselves")]
mod sphere;

use std::sync::Mutex;
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Hdr, RenderTarget};
use bevy::core_pipeline::prepass::{DeferredPrepass, DepthPrepass};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::pbr::DefaultOpaqueRendererMethod;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{HeightMaps, MapKind, Pomkit, PomkitMaterial, Technique};
use headless::{Frame, Headless};
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions};
use silhouettes::{Shape, coverage, disagreement, scene};
use sphere::bevy_mesh;

static GPU: Mutex<()> = Mutex::new(());

const W: u32 = 160;
const H: u32 = 120;
const TIMEOUT: Duration = Duration::from_secs(300);
/// The height map's size, as in pomkit's own silhouette tests.
const TEXELS: u32 = 256;

/// What the Bevy picture holds besides the sphere.
#[derive(Clone, Copy, PartialEq)]
enum Extra {
    None,
    /// A green unlit wall behind the sphere, and a depth prepass.
    WallAndPrepass,
    /// The same, drawn deferred (the G-buffer prepass).
    WallDeferred,
    /// A lit green wall behind the sphere, in the shadow of a point light (no ambient light).
    PointShadow,
    /// The same with a sun, and `shadow_pixel_depth` (the cascades trace).
    SunShadow,
}

/// pomkit's scene `s` (one object, one material) drawn by Bevy as `mesh` with the base
/// material `base` makes in the app, on black, seen by the scene's camera; the frame, and the
/// plugin's reports.
fn render_bevy(
    s: &pomkit_core::scene::Scene,
    mesh: Mesh,
    base: impl FnOnce(&mut Headless) -> StandardMaterial,
    extra: Extra,
) -> (Frame, Vec<String>) {
    let mut app = Headless::new(W, H);
    let base = base(&mut app);
    let m = &s.materials[0];
    let field = m.height.as_ref().expect("a height map");
    let heights = app.world().resource_mut::<Assets<Image>>().add(depth_image(field));
    let mut ext =
        Pomkit::new(heights).with_technique(m.technique).with_depth_scale(m.depth_scale).with_silhouette(m.silhouette);
    ext.map_kind = MapKind::Depth;
    ext.edges = m.edges;
    ext.trace = m.trace;
    ext.lod_threshold = m.lod_threshold;
    if matches!(extra, Extra::PointShadow | Extra::SunShadow) {
        // The shadow passes trace and discard without writing the traced depth: with it, this
        // sphere's shadow passes crash Mesa 22.3.6's lavapipe (silhouettes on or off).
        ext.pixel_depth_offset = false;
        ext.shadow_pixel_depth = extra == Extra::SunShadow;
    }
    let material = app.world().resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial { base, extension: ext });
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(mesh);
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    spawn_camera(&mut app, s, extra);
    let frame = app.frame(TIMEOUT).expect("frame");
    let reports = app.world().resource::<HeightMaps>().reports();
    (frame, reports)
}

/// The scene's camera, rendering into the app's target on black.
fn spawn_camera(app: &mut Headless, s: &pomkit_core::scene::Scene, extra: Extra) {
    let c = &s.camera;
    let target = RenderTarget::Image(app.target().into());
    let projection =
        Projection::Perspective(PerspectiveProjection { fov: c.fov_y_deg.to_radians(), near: c.near, ..default() });
    let camera = app
        .world()
        .spawn((
            Camera3d::default(),
            Hdr,
            Tonemapping::None,
            Msaa::Off,
            projection,
            Transform::from_translation(Vec3::from_array(c.eye.to_array()))
                .looking_at(Vec3::from_array(c.target.to_array()), Vec3::from_array(c.up.to_array())),
            target,
        ))
        .id();
    app.world().insert_resource(ClearColor(Color::BLACK));
    if extra == Extra::WallDeferred {
        app.world().entity_mut(camera).insert(DeferredPrepass);
        app.world().insert_resource(DefaultOpaqueRendererMethod::deferred());
    }
    let shadows = matches!(extra, Extra::PointShadow | Extra::SunShadow);
    if matches!(extra, Extra::WallAndPrepass | Extra::WallDeferred) {
        app.world().entity_mut(camera).insert(DepthPrepass);
    }
    if extra != Extra::None {
        let wall = app.world().resource_mut::<Assets<Mesh>>().add(Rectangle::new(8.0, 8.0));
        let green = app.world().resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
            base_color: Color::srgb(0.0, 1.0, 0.0),
            unlit: !shadows,
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
        app.world().spawn((Mesh3d(wall), MeshMaterial3d(green), Transform::from_xyz(0.0, 0.0, -1.5)));
    }
    if shadows {
        app.world().insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    }
    if extra == Extra::PointShadow {
        app.world().spawn((
            PointLight { intensity: 4.0e6, range: 30.0, radius: 0.0, shadow_maps_enabled: true, ..default() },
            Transform::from_xyz(2.6, 0.9, 2.2),
        ));
    }
    if extra == Extra::SunShadow {
        app.world().spawn((
            DirectionalLight { illuminance: 3000.0, shadow_maps_enabled: true, ..default() },
            Transform::default().looking_to(Vec3::new(-1.0, -0.35, -1.0), Vec3::Y),
        ));
    }
}

fn white(_: &mut Headless) -> StandardMaterial {
    StandardMaterial { base_color: Color::WHITE, unlit: true, ..default() }
}

/// Unlit, the UV image as its base colour.
fn uv_textured(app: &mut Headless) -> StandardMaterial {
    let texture = app.world().resource_mut::<Assets<Image>>().add(uv_texture());
    StandardMaterial { base_color_texture: Some(texture), unlit: true, ..default() }
}

/// Which pixels the sphere covers: white on black.
fn bevy_coverage(frame: &Frame) -> Vec<bool> {
    frame.pixels.iter().map(|p| p[0] > 0.5 && p[1] > 0.5).collect()
}

fn cpu_coverage(s: &pomkit_core::scene::Scene, mode: Mode) -> Vec<bool> {
    let opts = RenderOptions { width: W, height: H, mode, displaced_edge_texels: 1.0, ..Default::default() };
    coverage(&CpuRenderer::new().render(s, &opts, &|_, _| {}).expect("the CPU renders"))
}

/// Writes a picture of `frame` to `POMKIT_TEST_PICTURES/NAME` when that variable is set.
fn keep(frame: &Frame, name: &str) {
    if let Some(dir) = std::env::var_os("POMKIT_TEST_PICTURES")
        && let Some(png) = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8())
    {
        let path = std::path::Path::new(&dir).join(name);
        png.save(&path).expect("write the picture");
        eprintln!("wrote {}", path.display());
    }
}

/// With silhouettes, the sphere's outline disagrees with the displaced outline on at least 70%
/// fewer pixels than without (pomkit's renderers' own criterion), for `pom` and `exact`.
/// Without silhouettes Bevy draws the mesh's outline, as pomkit's CPU renderer does: the two
/// agree to a few pixels, which checks that the camera and mesh are the same.
#[test]
fn silhouettes_cut_the_outline_disagreement_with_the_displaced_truth_by_70_percent() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let shape = Shape::CobblestoneSphere;
    let plain_scene = scene(shape, Technique::Pom, false, TEXELS);
    let truth = cpu_coverage(&plain_scene, Mode::Displaced);
    let cpu_plain = cpu_coverage(&plain_scene, Mode::Material);
    let mesh = bevy_mesh(&plain_scene.objects[0].mesh);
    let (plain, _) = render_bevy(&plain_scene, mesh.clone(), white, Extra::None);
    keep(&plain, "bevy-silhouette-off.png");
    let plain = bevy_coverage(&plain);
    let before = disagreement(&plain, &truth);
    let camera = disagreement(&plain, &cpu_plain);
    eprintln!(
        "without silhouettes: {before} pixels off the displaced outline; {camera} differ from the CPU's plain outline ({} covered)",
        plain.iter().filter(|c| **c).count()
    );
    assert!(camera * 10 < before, "Bevy's plain outline is not the CPU renderer's: {camera} pixels differ");
    assert!(before > 400, "only {before} pixels disagree without silhouettes: the test is blind");
    let start = std::time::Instant::now();
    let k = bevy_pomkit::mesh_curvature(&mesh).expect("the sphere's curvature");
    eprintln!("the curvature of {} vertices took {:?}", k.len(), start.elapsed());
    for technique in [Technique::Pom, Technique::Exact] {
        let cpu = cpu_coverage(&scene(shape, technique, true, TEXELS), Mode::Material);
        let (frame, reports) = render_bevy(&scene(shape, technique, true, TEXELS), mesh.clone(), white, Extra::None);
        keep(&frame, &format!("bevy-silhouette-{}.png", technique.name()));
        assert!(reports.is_empty(), "reports for a good mesh: {reports:?}");
        let bevy = bevy_coverage(&frame);
        let after = disagreement(&bevy, &truth);
        let (cpu_after, between) = (disagreement(&cpu, &truth), disagreement(&bevy, &cpu));
        eprintln!(
            "{}: {before} -> {after} pixels disagree with the displaced outline (pomkit's CPU renderer with \
             silhouettes: {cpu_after}; {between} pixels differ between the two)",
            technique.name()
        );
        assert!(
            (after as f64) <= 0.3 * before as f64,
            "{}: {before} -> {after} pixels disagree, less than a 70% drop",
            technique.name()
        );
        // The same outline as pomkit's own renderer, to the odd grazing ray (f32 on the GPU).
        assert!(between * 20 < before, "{}: {between} pixels differ from the CPU's silhouette", technique.name());
    }
}

/// With a depth prepass, and drawn deferred, the prepass discards what the main pass does:
/// behind every pixel the silhouette cuts away, the wall shows (a prepass that wrote the
/// polygon's depth there would leave it black).
#[test]
fn discarded_pixels_show_the_wall_behind_with_a_depth_prepass_and_deferred() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = scene(Shape::CobblestoneSphere, Technique::Pom, true, TEXELS);
    let mesh = bevy_mesh(&s.objects[0].mesh);
    let plain = cpu_coverage(&scene(Shape::CobblestoneSphere, Technique::Pom, false, TEXELS), Mode::Material);
    for extra in [Extra::WallAndPrepass, Extra::WallDeferred] {
        let what = if extra == Extra::WallDeferred { "deferred" } else { "depth prepass" };
        let (frame, _) = render_bevy(&s, mesh.clone(), white, extra);
        keep(&frame, &format!("bevy-silhouette-wall-{}.png", what.replace(' ', "-")));
        let (mut cut, mut wall, mut sphere) = (0, 0, 0);
        for (k, p) in frame.pixels.iter().enumerate() {
            let white = p[0] > 0.5 && p[1] > 0.5;
            let green = p[0] < 0.1 && p[1] > 0.5;
            sphere += usize::from(white);
            if plain[k] && !white {
                cut += 1;
                wall += usize::from(green);
            }
        }
        eprintln!(
            "{what}: {sphere} sphere pixels; {cut} inside the mesh's outline cut away, {wall} of them show the wall"
        );
        assert!(cut > 200, "{what}: only {cut} pixels cut away");
        assert_eq!(wall, cut, "{what}: cut-away pixels that do not show the wall");
    }
}

/// An unlit image whose red and green are the UV: a traced surface shows other colours than
/// the plain material.
fn uv_texture() -> Image {
    let n = 64u32;
    let data = (0..n * n)
        .flat_map(|k| {
            let (i, j) = (k % n, k / n);
            [(i * 255 / (n - 1)) as u8, (j * 255 / (n - 1)) as u8, 64, 255]
        })
        .collect();
    Image::new(
        Extent3d { width: n, height: n, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8Unorm,
        RenderAssetUsages::default(),
    )
}

/// A silhouette material on a mesh without normals, or on one whose curvature cannot be
/// computed (a normal that is not a number): one message naming the mesh and the problem, and
/// exactly the plain StandardMaterial's picture (nothing traced, nothing discarded).
#[test]
fn meshes_without_curvature_are_reported_and_drawn_plain() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = scene(Shape::CobblestoneSphere, Technique::Pom, true, 64);
    let sphere = bevy_mesh(&s.objects[0].mesh);
    // The plain material (unlit: its picture does not depend on the normals).
    let reference = {
        let mut app = Headless::new(W, H);
        let plain = uv_textured(&mut app);
        let plain = app.world().resource_mut::<Assets<StandardMaterial>>().add(plain);
        let mesh = app.world().resource_mut::<Assets<Mesh>>().add(sphere.clone());
        app.world().spawn((Mesh3d(mesh), MeshMaterial3d(plain)));
        spawn_camera(&mut app, &s, Extra::None);
        app.frame(TIMEOUT).expect("frame")
    };
    for case in ["no normals", "a NaN normal"] {
        let mut mesh = sphere.clone();
        if case == "no normals" {
            mesh.remove_attribute(Mesh::ATTRIBUTE_NORMAL);
        } else if let Some(bevy::mesh::VertexAttributeValues::Float32x3(n)) = mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL)
        {
            n[100] = [f32::NAN; 3];
        }
        let (frame, reports) = render_bevy(&s, mesh, uv_textured, Extra::None);
        let worst = frame.max_difference(&reference);
        eprintln!("{case}: worst difference from the plain material {worst}; reports {reports:?}");
        assert!(worst < 2e-3, "{case}: not the plain material's picture (difference {worst})");
        let expect = if case == "no normals" { "no NORMAL" } else { "no silhouettes" };
        let matching: Vec<&String> = reports.iter().filter(|r| r.contains("mesh")).collect();
        assert_eq!(matching.len(), 1, "{case}: not one report about the mesh: {reports:?}");
        assert!(matching[0].contains(expect), "{case}: the report does not name the problem: {reports:?}");
    }
    // The same material on the intact sphere traces (and so differs from the plain picture),
    // and carries the curvature: the comparison above can fail.
    let (frame, reports) = render_bevy(&s, sphere, uv_textured, Extra::None);
    let differ =
        frame.pixels.iter().zip(&reference.pixels).filter(|(a, b)| (0..3).any(|c| (a[c] - b[c]).abs() > 0.05)).count();
    eprintln!("the intact sphere: {differ} pixels differ from the plain material");
    assert!(reports.is_empty(), "{reports:?}");
    assert!(differ > 500, "the intact sphere is not traced ({differ} pixels differ)");
}

/// The shadow maps of point lights, and of directional lights with `shadow_pixel_depth`, hold
/// the cut outline: the sphere's shadow on the wall behind it shrinks with silhouettes (the
/// rays the main pass lets through reach the wall from the light too). Counted on the wall
/// pixels seen in both pictures (the cut sphere uncovers some wall).
#[test]
fn shadow_maps_see_the_silhouette() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let mesh = bevy_mesh(&scene(Shape::CobblestoneSphere, Technique::Pom, false, TEXELS).objects[0].mesh);
    for extra in [Extra::PointShadow, Extra::SunShadow] {
        let what = if extra == Extra::PointShadow { "point light" } else { "sun" };
        let mut frames = Vec::new();
        for silhouette in [false, true] {
            let s = scene(Shape::CobblestoneSphere, Technique::Pom, silhouette, TEXELS);
            let (frame, _) = render_bevy(&s, mesh.clone(), white, extra);
            keep(&frame, &format!("bevy-silhouette-shadow-{}-{silhouette}.png", what.replace(' ', "-")));
            frames.push(frame);
        }
        // Wall pixels (not the white sphere), and whether any light reaches them.
        let wall = |p: &[f32; 4]| p[0] < 0.1;
        let dark = |p: &[f32; 4]| p[1] < 1e-3;
        let (mut shadowed, mut lit_now, mut shadowed_now) = (0, 0, 0);
        for (a, b) in frames[0].pixels.iter().zip(&frames[1].pixels) {
            if wall(a) && wall(b) {
                shadowed += usize::from(dark(a));
                lit_now += usize::from(dark(a) && !dark(b));
                shadowed_now += usize::from(!dark(a) && dark(b));
            }
        }
        eprintln!(
            "{what}: {shadowed} wall pixels in the sphere's shadow without silhouettes; with them {lit_now} of these \
             lit, {shadowed_now} others shadowed"
        );
        assert!(shadowed > 1000, "{what}: the sphere casts too little shadow on the wall ({shadowed} pixels)");
        assert!(lit_now > 40, "{what}: the shadow does not shrink with silhouettes ({lit_now} pixels lit)");
        assert!(shadowed_now * 10 < lit_now, "{what}: {shadowed_now} pixels newly shadowed");
    }
}

/// The plugin computes the curvature when a mesh is first drawn with a silhouette material, and
/// again when its vertices change: the attribute holds pomkit-core's values for the mesh as it
/// is (a sphere, then the same asset made a cylinder).
#[test]
fn the_curvature_follows_the_mesh() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = scene(Shape::CobblestoneSphere, Technique::Pom, true, 64);
    let mut app = Headless::new(W, H);
    let heights =
        app.world().resource_mut::<Assets<Image>>().add(depth_image(s.materials[0].height.as_ref().expect("a map")));
    let material = app.world().resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial {
        base: StandardMaterial::default(),
        extension: Pomkit::new(heights).with_silhouette(true),
    });
    let sphere = bevy_mesh(&pomkit_core::mesh::Mesh::uv_sphere(1.0, 12, 24));
    let cylinder = bevy_mesh(&pomkit_core::mesh::Mesh::cylinder(0.5, 2.0, 16));
    let handle = app.world().resource_mut::<Assets<Mesh>>().add(sphere.clone());
    app.world().spawn((Mesh3d(handle.clone()), MeshMaterial3d(material)));
    let stored = |app: &mut Headless| -> Option<Vec<[f32; 3]>> {
        match app.world().resource::<Assets<Mesh>>().get(&handle)?.attribute(bevy_pomkit::ATTRIBUTE_CURVATURE)? {
            bevy::mesh::VertexAttributeValues::Float32x3(k) => Some(k.clone()),
            _ => None,
        }
    };
    for (mesh, name) in [(sphere, "sphere"), (cylinder, "cylinder")] {
        let want = bevy_pomkit::mesh_curvature(&mesh).expect("the curvature");
        if name == "cylinder" {
            *app.world().resource_mut::<Assets<Mesh>>().get_mut(&handle).expect("the mesh") = mesh;
        }
        let mut got = None;
        for _ in 0..5 {
            app.update();
            got = stored(&mut app);
            if got.as_ref() == Some(&want) {
                break;
            }
        }
        let got = got.unwrap_or_default();
        eprintln!("{name}: {} curvature values stored, {} expected", got.len(), want.len());
        assert_eq!(got, want, "{name}: the stored curvature is not the mesh's");
        // A sphere of radius r curves by L / r in every direction away from the poles: not zero.
        assert!(want.iter().any(|k| k[0] > 0.1), "{name}: a flat curvature cannot tell the meshes apart");
    }
}
