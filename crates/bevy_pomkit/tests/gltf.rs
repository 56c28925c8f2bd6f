//! glTF files with height maps in Bevy (feature `gltf`), on lavapipe: pomkit's sample plane
//! (`pomkit_io::gltf::write_sample`) loaded by Bevy's glTF loader, seen from its own camera.
//!
//! The truth is pomkit's CPU renderer drawing the same plane, height map and camera with the
//! `displaced` technique, real geometry: its hit UV per pixel says where on the texture each
//! pixel's surface point lies, which is what the picture shows there. The traced material must
//! land much nearer that than Bevy's plain material, which shows each pixel the texture at the
//! polygon's UV.
//!
//! All tests share one lock: each builds a Bevy app with its own GPU device.

#[path = "../examples/support/gltf.rs"]
mod gltf;
#[path = "../examples/support/headless.rs"]
mod headless;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Hdr, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::image::{ImageSampler, ImageSamplerDescriptor};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_pomkit::{HeightMaps, PomkitDebug, PomkitMaterial, Technique};
use headless::{Frame, Headless};
use pomkit_core::glam;
use pomkit_io::gltf::{SampleCamera, SampleDisplacement, SampleLight, SampleOptions, write_sample};

static GPU: Mutex<()> = Mutex::new(());

const W: u32 = 160;
const H: u32 = 120;
const TIMEOUT: Duration = Duration::from_secs(300);
/// The relief's depth in the file's units, on a plane 2 units wide whose UVs run 0 to 1: a
/// depth scale of 0.1 UV units.
const FACTOR: f32 = 0.2;
const PLANE: f32 = 2.0;
/// The height map's side in texels.
const TEXELS: u32 = 64;

fn camera() -> SampleCamera {
    SampleCamera {
        eye: glam::Vec3::new(0.3, 1.1, 1.7),
        target: glam::Vec3::new(0.0, 0.0, 0.1),
        yfov_deg: 40.0,
        ..SampleCamera::default()
    }
}

/// The sample plane in a new folder: bricks with a base colour and a normal map, the height map
/// as `KHR_materials_displacement` when `displacement`, traced with `exact` (pomkit extras).
fn write(displacement: bool) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let options = SampleOptions {
        texture_size: TEXELS,
        size: PLANE,
        camera: Some(camera()),
        lights: vec![SampleLight::Directional {
            toward: glam::Vec3::new(-1.0, 1.5, 0.5),
            color: glam::Vec3::ONE,
            intensity: 3000.0,
        }],
        displacement: displacement.then_some(SampleDisplacement { factor: FACTOR, offset: -FACTOR }),
        extras: Some(serde_json::json!({ "pomkit": { "technique": "exact" } })),
        ..SampleOptions::default()
    };
    let file = write_sample(dir.path(), &options).expect("sample written");
    (dir, file)
}

/// A headless app with the file's first scene spawned, its camera aimed at the target.
fn load(file: &Path) -> (Headless, Entity) {
    let folder = file.parent().expect("folder");
    let name = file.file_name().and_then(|n| n.to_str()).expect("name");
    let mut app = Headless::with_assets(W, H, Some(folder));
    let scene = gltf::spawn(app.world(), name);
    let start = Instant::now();
    loop {
        app.update();
        match gltf::progress(app.world(), &scene) {
            gltf::Progress::Spawned => break,
            gltf::Progress::Failed(e) => panic!("{e}"),
            gltf::Progress::Loading => assert!(start.elapsed() < TIMEOUT, "the scene did not load"),
        }
    }
    app.update();
    let target = RenderTarget::Image(app.target().into());
    let (camera, from_file) = gltf::finish(app.world(), Some(target));
    assert!(from_file, "the file's camera");
    (app, camera)
}

/// The mesh entities drawn with a pomkit material and with a standard material.
fn drawn(app: &mut Headless) -> (Vec<Handle<PomkitMaterial>>, Vec<Handle<StandardMaterial>>) {
    let world = app.world();
    let pomkit = world.query::<&MeshMaterial3d<PomkitMaterial>>().iter(world).map(|m| m.0.clone()).collect();
    let standard = world.query::<&MeshMaterial3d<StandardMaterial>>().iter(world).map(|m| m.0.clone()).collect();
    (pomkit, standard)
}

/// The StandardMaterial Bevy made of the glTF material: the base of the PomkitMaterial.
fn base_of(app: &mut Headless, material: &Handle<PomkitMaterial>) -> StandardMaterial {
    app.world().resource::<Assets<PomkitMaterial>>().get(material).expect("the material").base.clone()
}

/// Writes `frame` to `name` in the system's temporary folder when `POMKIT_TEST_PICTURES` is set.
fn keep(frame: &Frame, name: &str) {
    if std::env::var_os("POMKIT_TEST_PICTURES").is_some() {
        let path = std::env::temp_dir().join(name);
        if let Some(png) = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8()) {
            let _ = png.save(&path);
            eprintln!("wrote {}", path.display());
        }
    }
}

/// The pixel's UV on the texture according to pomkit's CPU renderer, drawing the file's plane
/// as real displaced geometry (`None` where no surface is).
fn displaced_truth(dir: &Path) -> Vec<Option<Vec2>> {
    use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
    let heights = pomkit_io::load_height_field(&dir.join("sample_height.png"), &Default::default())
        .expect("the sample's height map");
    let material = Material {
        height: Some(Arc::new(heights)),
        depth_scale: FACTOR / PLANE,
        technique: Technique::Exact,
        ..Material::default()
    };
    let c = camera();
    let scene = Scene {
        camera: Camera {
            eye: c.eye,
            target: c.target,
            up: glam::Vec3::Y,
            fov_y_deg: c.yfov_deg,
            near: 0.05,
            far: 100.0,
        },
        lights: vec![Light::Directional { direction: glam::Vec3::Y, color: glam::Vec3::ONE, intensity: 1.0 }],
        materials: vec![material],
        objects: vec![Object {
            name: "plane".into(),
            mesh: Arc::new(pomkit_core::mesh::Mesh::plane(glam::Vec2::splat(PLANE), 1)),
            material: 0,
            transform: glam::Mat4::IDENTITY,
        }],
        ambient: glam::Vec3::splat(0.1),
        background: glam::Vec3::ZERO,
    };
    let opts = pomkit_core::render::RenderOptions {
        width: W,
        height: H,
        mode: pomkit_core::render::Mode::Displaced,
        aovs: true,
        ..Default::default()
    };
    let out = pomkit_cpu::CpuRenderer::new().render(&scene, &opts, &|_, _| {}).expect("CPU render");
    let aovs = out.aovs.expect("AOVs");
    aovs.uv
        .iter()
        .zip(&aovs.depth)
        .map(|(uv, d)| (*uv != glam::Vec2::ZERO || *d > 0.0).then(|| Vec2::new(uv.x, uv.y)))
        .collect()
}

/// A linear 256 x 256 image whose red and green are u and v at each texel's centre: drawn
/// unlit, the plain material shows the UV it samples its textures at.
fn uv_image() -> Image {
    let n = 256u32;
    let mut data = Vec::with_capacity((n * n * 8) as usize);
    for j in 0..n {
        for i in 0..n {
            for v in [(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32, 0.0, 1.0] {
                data.extend_from_slice(&pomkit_gpu::util::f32_to_f16(v).to_le_bytes());
            }
        }
    }
    let mut image = Image::new(
        Extent3d { width: n, height: n, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor::linear());
    image
}

/// The albedo map of the sample, sampled bilinearly with wrapping at `uv` (linear RGB of the
/// sRGB texels).
struct Albedo {
    size: u32,
    texels: Vec<[f32; 3]>,
}

impl Albedo {
    fn read(dir: &Path) -> Self {
        let img = image::open(dir.join("sample_albedo.png")).expect("albedo").to_rgb8();
        let lin = |c: u8| {
            let c = f32::from(c) / 255.0;
            if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
        };
        Self { size: img.width(), texels: img.pixels().map(|p| [lin(p[0]), lin(p[1]), lin(p[2])]).collect() }
    }

    fn at(&self, uv: Vec2) -> [f32; 3] {
        let n = self.size as i64;
        let (x, y) = (uv.x * n as f32 - 0.5, uv.y * n as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let t = |i: i64, j: i64| self.texels[(j.rem_euclid(n) * n + i.rem_euclid(n)) as usize];
        let (i, j) = (x0 as i64, y0 as i64);
        let mut out = [0.0; 3];
        for (di, dj, w) in
            [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
        {
            let c = t(i + di, j + dj);
            for k in 0..3 {
                out[k] += w * c[k];
            }
        }
        out
    }
}

fn psnr(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    let mse: f32 = a.iter().zip(b).map(|(x, y)| (0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f32>()).sum::<f32>()
        / (3 * a.len()) as f32;
    -10.0 * mse.max(1e-12).log10()
}

fn quantile(mut v: Vec<f32>, q: f32) -> f32 {
    v.sort_by(f32::total_cmp);
    v[((v.len() - 1) as f32 * q) as usize]
}

fn uv_at(frame: &Frame, k: usize) -> Vec2 {
    Vec2::new(frame.pixels[k][0], frame.pixels[k][1])
}

#[test]
fn a_displaced_gltf_is_traced_and_lands_nearer_the_displaced_truth_than_the_plain_material() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let (dir, file) = write(true);
    let (mut app, camera) = load(&file);
    let (pomkit, standard) = drawn(&mut app);
    assert_eq!((pomkit.len(), standard.len()), (1, 0), "the plane is drawn with a PomkitMaterial only");
    {
        let materials = app.world().resource::<Assets<PomkitMaterial>>();
        let m = materials.get(&pomkit[0]).expect("the material");
        // The factor over the mesh's UV unit: 2 file units per UV unit.
        let want = FACTOR / PLANE;
        assert!((m.extension.depth_scale - want).abs() < 1e-6, "depth_scale {} != {want}", m.extension.depth_scale);
        assert_eq!(m.extension.technique, Technique::Exact, "the extras' technique");
        assert!(m.base.base_color_texture.is_some() && m.base.normal_map_texture.is_some(), "the glTF's textures");
    }
    // Raw output: the traced UV in red and green.
    app.world().entity_mut(camera).insert((Hdr, Tonemapping::None));
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&pomkit[0]) {
        m.extension.debug = PomkitDebug::HitUv;
    }
    let traced = app.frame(TIMEOUT).expect("traced frame");
    keep(&traced, "pomkit-gltf-traced.png");
    assert!(
        app.world().resource::<HeightMaps>().reports().is_empty(),
        "{:?}",
        app.world().resource::<HeightMaps>().reports()
    );
    // The plain material Bevy made of the glTF's, drawing the UV it samples at.
    let uv = app.world().resource_mut::<Assets<Image>>().add(uv_image());
    let base = base_of(&mut app, &pomkit[0]);
    let plain = StandardMaterial { base_color: Color::WHITE, base_color_texture: Some(uv), unlit: true, ..base };
    let plain = app.world().resource_mut::<Assets<StandardMaterial>>().add(plain);
    let entity = {
        let world = app.world();
        world.query_filtered::<Entity, With<MeshMaterial3d<PomkitMaterial>>>().single(world).expect("one entity")
    };
    app.world().entity_mut(entity).remove::<MeshMaterial3d<PomkitMaterial>>().insert(MeshMaterial3d(plain));
    let plain = app.frame(TIMEOUT).expect("plain frame");
    keep(&plain, "pomkit-gltf-plain.png");
    drop(app);

    let truth = displaced_truth(dir.path());
    let albedo = Albedo::read(dir.path());
    let (mut e_traced, mut e_plain) = (Vec::new(), Vec::new());
    let (mut c_truth, mut c_traced, mut c_plain) = (Vec::new(), Vec::new(), Vec::new());
    for (k, t) in truth.iter().enumerate() {
        // Inside the plane, away from its edges (where the displaced walls and the tracer's
        // wrapped UVs part ways).
        let Some(t) = t else { continue };
        if t.min_element() < 0.05 || t.max_element() > 0.95 {
            continue;
        }
        let (a, b) = (uv_at(&traced, k), uv_at(&plain, k));
        e_traced.push((a - *t).length() * TEXELS as f32);
        e_plain.push((b - *t).length() * TEXELS as f32);
        c_truth.push(albedo.at(*t));
        c_traced.push(albedo.at(a));
        c_plain.push(albedo.at(b));
    }
    assert!(e_traced.len() > (W * H / 4) as usize, "the plane covers too little of the frame: {}", e_traced.len());
    let (m_traced, m_plain) = (quantile(e_traced.clone(), 0.5), quantile(e_plain.clone(), 0.5));
    let (p90_traced, p90_plain) = (quantile(e_traced, 0.9), quantile(e_plain, 0.9));
    let (db_traced, db_plain) = (psnr(&c_traced, &c_truth), psnr(&c_plain, &c_truth));
    eprintln!(
        "UV error against the displaced truth, texels: traced median {m_traced:.3} p90 {p90_traced:.3}, \
         plain median {m_plain:.3} p90 {p90_plain:.3}; base colour PSNR traced {db_traced:.1} dB, plain {db_plain:.1} dB"
    );
    // The relief shifts what a pixel sees by up to a few texels (the bricks' flat tops not at
    // all); the trace takes that back to a small fraction of a texel (exact traces the bilinear
    // surface that the displaced mesh, one vertex per texel, approximates). Measured: traced
    // median 0.02 and p90 0.08 texels, plain 0.49 and 2.9; base colour 34 dB against 22.
    assert!(p90_plain > 1.5, "the relief should move the picture: plain p90 {p90_plain}");
    assert!(m_traced < 0.1 && m_traced < 0.2 * m_plain, "traced median {m_traced}, plain {m_plain}");
    assert!(p90_traced < 0.3 && p90_traced < 0.1 * p90_plain, "traced p90 {p90_traced}, plain {p90_plain}");
    assert!(db_traced > db_plain + 6.0, "base colour PSNR: traced {db_traced}, plain {db_plain}");
}

#[test]
fn without_the_extension_a_gltf_material_stays_a_standard_material() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // The extras alone name no height map: the material is refused with one report.
    let (_dir, file) = write(false);
    let (mut app, _) = load(&file);
    let (pomkit, standard) = drawn(&mut app);
    assert_eq!((pomkit.len(), standard.len()), (0, 1));
    assert!(app.world().resource::<Assets<PomkitMaterial>>().is_empty());
    let reports = app.world().resource::<HeightMaps>().reports();
    assert_eq!(reports.len(), 1, "{reports:?}");
    assert!(
        reports[0].contains("sample.gltf") && reports[0].contains("\"Bricks\"") && reports[0].contains("no height map")
    );
}

#[test]
fn a_broken_displacement_texture_draws_the_plain_material_with_one_report() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let (dir, file) = write(true);
    std::fs::write(dir.path().join("sample_height.png"), b"not a PNG").expect("break the height map");
    let (mut app, camera) = load(&file);
    app.world().entity_mut(camera).insert((Hdr, Tonemapping::None));
    let (pomkit, _) = drawn(&mut app);
    assert_eq!(pomkit.len(), 1, "the hook does not know yet that the texture is broken");
    let broken = app.frame(TIMEOUT).expect("frame");
    keep(&broken, "pomkit-gltf-broken.png");
    let reports = app.world().resource::<HeightMaps>().reports();
    eprintln!("{reports:?}");
    assert_eq!(reports.len(), 1, "{reports:?}");
    for part in ["sample.gltf", "\"Bricks\"", "sample_height.png", "plain StandardMaterial"] {
        assert!(reports[0].contains(part), "{part} not in {}", reports[0]);
    }
    // The plain look: the same frame as Bevy's own StandardMaterial of the glTF material.
    let base = base_of(&mut app, &pomkit[0]);
    let std_handle = app.world().resource_mut::<Assets<StandardMaterial>>().add(base);
    let entity = {
        let world = app.world();
        world.query_filtered::<Entity, With<MeshMaterial3d<PomkitMaterial>>>().single(world).expect("one entity")
    };
    app.world().entity_mut(entity).remove::<MeshMaterial3d<PomkitMaterial>>().insert(MeshMaterial3d(std_handle));
    let plain = app.frame(TIMEOUT).expect("plain frame");
    let worst = broken.max_difference(&plain);
    let lit = plain.pixels.iter().filter(|p| p[0] + p[1] + p[2] > 0.05).count();
    assert!(lit > (W * H / 4) as usize, "the plane should be lit: {lit} pixels");
    assert!(worst < 2e-3, "not the plain material's look (difference {worst})");
}

/// The sample's `.gltf` with `attribute` taken out of the plane's primitive.
fn without_attribute(file: &Path, attribute: &str) {
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(file).expect("read")).expect("JSON");
    let attributes = json["meshes"][0]["primitives"][0]["attributes"].as_object_mut().expect("attributes");
    assert!(attributes.remove(attribute).is_some(), "the sample has {attribute}");
    std::fs::write(file, serde_json::to_vec(&json).expect("JSON")).expect("write");
}

#[test]
fn meshes_without_tangents_get_them_and_meshes_without_uvs_stay_plain() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // No tangents and no normal map (for which Bevy's loader would make them).
    let (_dir, file) = write(true);
    let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&file).expect("read")).expect("JSON");
    json["materials"][0].as_object_mut().expect("material").remove("normalTexture");
    std::fs::write(&file, serde_json::to_vec(&json).expect("JSON")).expect("write");
    without_attribute(&file, "TANGENT");
    let (mut app, _) = load(&file);
    for _ in 0..3 {
        app.update();
    }
    let world = app.world();
    let mesh = world.query_filtered::<&Mesh3d, With<MeshMaterial3d<PomkitMaterial>>>().single(world).expect("traced");
    let mesh = world.resource::<Assets<Mesh>>().get(&mesh.0).expect("mesh");
    assert!(mesh.contains_attribute(Mesh::ATTRIBUTE_TANGENT), "tangents generated");
    let reports = world.resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "{reports:?}");
    drop(app);

    // No UVs: nothing to trace in.
    let (_dir, file) = write(true);
    without_attribute(&file, "TEXCOORD_0");
    let (mut app, _) = load(&file);
    let (pomkit, standard) = drawn(&mut app);
    assert_eq!((pomkit.len(), standard.len()), (0, 1));
    let reports = app.world().resource::<HeightMaps>().reports();
    assert_eq!(reports.len(), 1, "{reports:?}");
    for part in ["sample.gltf", "\"Bricks\"", "TEXCOORD_0", "plain StandardMaterial"] {
        assert!(reports[0].contains(part), "{part} not in {}", reports[0]);
    }
}

#[test]
fn a_height_map_put_in_by_gltf_attach_is_traced_in_bevy() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // The sample without the extension, then `pomkit gltf attach`'s library call: the height map
    // written beside the output as a 16-bit PNG, the factor in the file's units.
    let (dir, plain) = write(false);
    let attached = dir.path().join("attached.gltf");
    let heights = pomkit_core::HeightField::from_height_fn(TEXELS, TEXELS, |x, y| ((x / 8 + y / 8) % 2) as f32);
    let choice = pomkit_io::gltf::MaterialChoice::Name("Bricks".into());
    let depth = pomkit_io::gltf::AttachDepth::Units(FACTOR);
    pomkit_io::gltf::attach(&plain, &attached, &choice, &heights, depth, &[]).expect("attached");
    let (mut app, _) = load(&attached);
    let (pomkit, standard) = drawn(&mut app);
    assert_eq!((pomkit.len(), standard.len()), (1, 0), "the attached material is traced");
    let materials = app.world().resource::<Assets<PomkitMaterial>>();
    let m = materials.get(&pomkit[0]).expect("the material");
    let want = FACTOR / PLANE;
    assert!((m.extension.depth_scale - want).abs() < 1e-6, "depth_scale {} != {want}", m.extension.depth_scale);
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "{reports:?}");
}
