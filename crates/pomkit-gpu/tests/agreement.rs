//! The GPU renderer against the CPU renderer (the independent truth here: a different
//! implementation of the same techniques, in f64/f32 Rust rather than WGSL), and against the
//! bump test (ARCHITECTURE.md, Conventions).
//!
//! Runs on any adapter, Mesa's lavapipe included. Where no adapter exists each test prints why
//! and passes, unless `POMKIT_REQUIRE_GPU=1` (set by `.ci/run`), where it fails.
//!
//! Tolerance, stated once: on 8-bit sRGB output, PSNR of at least 40 dB, at most 0.5% of covered
//! pixels differing by more than 20 levels in a channel (silhouette pixels and the odd ray that
//! f32 and f64 send to different sides of a texel edge), and coverage within 0.1% (edge pixels). Fetch counts agree
//! within 5% in total (exact walks in f32 and f64 can take different steps). Measured on lavapipe: 47-58 dB, under 0.05% of pixels over 20.

use std::sync::{Arc, Mutex, OnceLock};

use pomkit_core::compose::{Image, difference};
use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::render::{Mode, RenderOptions, RenderOutput};
use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{Technique, TraceParams};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_cpu::CpuRenderer;
use pomkit_gpu::{GpuContext, GpuRenderer};

/// The shared renderer (one device and one set of compiled pipelines for every test), or `None`
/// with the reason printed when there is no adapter.
fn gpu() -> Option<&'static Mutex<GpuRenderer>> {
    static RENDERER: OnceLock<Result<Mutex<GpuRenderer>, String>> = OnceLock::new();
    let r =
        RENDERER.get_or_init(|| GpuContext::new().map(|c| Mutex::new(GpuRenderer::new(c))).map_err(|e| e.to_string()));
    match r {
        Ok(m) => Some(m),
        Err(e) => {
            pomkit_gpu::context::skip_without_gpu(e);
            None
        }
    }
}

fn render_gpu(g: &Mutex<GpuRenderer>, scene: &Scene, opts: &RenderOptions) -> RenderOutput {
    let mut r = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let out = r.render(scene, opts).expect("GPU render");
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite GPU pixel");
    out
}

fn render_cpu(scene: &Scene, opts: &RenderOptions) -> RenderOutput {
    CpuRenderer::new().render(scene, opts, &|_, _| {}).expect("CPU render")
}

/// PSNR (dB) over all pixels, and the share of covered pixels with a channel off by more than 20.
fn compare(gpu: &RenderOutput, cpu: &RenderOutput) -> (f64, f64) {
    let (a, b) = (Image::from(gpu), Image::from(cpu));
    let d = difference(&a, &b, 20, None);
    // `difference` counts the share over all pixels; the tolerance is stated per covered pixel.
    let over = d.share_over * a.pixels.len() as f64;
    (d.psnr_db, over / cpu.covered.max(1) as f64)
}

fn assert_agree(gpu: &RenderOutput, cpu: &RenderOutput, what: &str) {
    let (psnr, over) = compare(gpu, cpu);
    println!("{what}: {psnr:.1} dB, {:.3}% of pixels over 20", over * 100.0);
    assert!(cpu.covered > 0, "{what}: nothing drawn");
    // Rasterizers may round a pixel centre on a triangle edge differently (fixed-point
    // snapping on the GPU, f32 edge functions on the CPU).
    let slack = 2 + cpu.covered / 1000;
    assert!(gpu.covered.abs_diff(cpu.covered) <= slack, "{what}: coverage {} vs {}", gpu.covered, cpu.covered);
    assert!(psnr >= 40.0, "{what}: GPU and CPU differ: {psnr:.1} dB");
    assert!(over <= 0.005, "{what}: {:.3}% of pixels differ by more than 20 levels", over * 100.0);
    if let (Some(ga), Some(ca)) = (&gpu.aovs, &cpu.aovs) {
        let (gf, cf): (f32, f32) = (ga.fetches.iter().sum(), ca.fetches.iter().sum());
        assert!((gf - cf).abs() <= 0.05 * cf.max(1.0), "{what}: fetches GPU {gf} vs CPU {cf}");
    }
}

fn opts(width: u32, height: u32, mode: Mode) -> RenderOptions {
    RenderOptions { width, height, mode, aovs: true, ..Default::default() }
}

#[test]
fn demo_scene_every_technique_matches_the_cpu() {
    let Some(g) = gpu() else { return };
    let scene = pomkit_core::demo::demo_scene_sized(128);
    let mut modes = vec![Mode::Material];
    modes.extend(Technique::ALL.map(Mode::Technique));
    for mode in modes {
        let o = opts(256, 144, mode);
        let (gpu_out, cpu_out) = (render_gpu(g, &scene, &o), render_cpu(&scene, &o));
        assert_agree(&gpu_out, &cpu_out, &format!("demo {mode:?}"));
        let fetches: f32 = cpu_out.aovs.as_ref().map_or(0.0, |a| a.fetches.iter().sum());
        if let Mode::Technique(t) = mode {
            // The test means something only if the techniques actually traced.
            assert_eq!(fetches > 0.0, t.displaces(), "{t}: fetches {fetches}");
        }
    }
}

#[test]
fn hit_uvs_of_exact_and_pom_match_the_cpu_to_a_fraction_of_a_texel() {
    let Some(g) = gpu() else { return };
    let scene = pomkit_core::demo::demo_scene_sized(128);
    for t in [Technique::Pom, Technique::Exact, Technique::Relief] {
        let o = opts(256, 144, Mode::Technique(t));
        let (ga, ca) = (render_gpu(g, &scene, &o).aovs.unwrap(), render_cpu(&scene, &o).aovs.unwrap());
        let mut errs: Vec<f32> = ga.uv.iter().zip(&ca.uv).map(|(a, b)| (*a - *b).length() * 128.0).collect();
        errs.sort_by(f32::total_cmp);
        let median = errs[errs.len() / 2];
        let p99 = errs[errs.len() * 99 / 100];
        println!("{t}: hit-UV difference median {median:.4} texels, p99 {p99:.4}");
        assert!(median < 0.01, "{t}: median {median} texels");
        assert!(p99 < 0.5, "{t}: p99 {p99} texels");
    }
}

#[test]
fn shadow_modes_pdo_supersampling_tint_and_displaced_match_the_cpu() {
    let Some(g) = gpu() else { return };
    let base = pomkit_core::demo::demo_scene_sized(128);
    for mode in ShadowMode::ALL {
        let mut s = base.clone();
        for m in &mut s.materials {
            m.shadow = ShadowParams { mode, softness: 0.1 };
        }
        for t in [Technique::Pom, Technique::Exact] {
            let o = opts(256, 144, Mode::Technique(t));
            assert_agree(&render_gpu(g, &s, &o), &render_cpu(&s, &o), &format!("shadows {mode:?} {t}"));
        }
    }
    let mut pdo = base.clone();
    pdo.materials.iter_mut().for_each(|m| m.pixel_depth_offset = true);
    let o = opts(256, 144, Mode::Material);
    assert_agree(&render_gpu(g, &pdo, &o), &render_cpu(&pdo, &o), "pixel depth offset");
    let o = RenderOptions { supersample: 2, ..opts(128, 72, Mode::Material) };
    assert_agree(&render_gpu(g, &base, &o), &render_cpu(&base, &o), "supersample 2");
    let o = RenderOptions { lod_tint: true, ..opts(256, 144, Mode::Material) };
    assert_agree(&render_gpu(g, &base, &o), &render_cpu(&base, &o), "lod tint");
    let small = pomkit_core::demo::demo_scene_sized(48);
    // The GPU renderer draws the whole subdivided mesh; the CPU's streamed blocks are that mesh
    // bit for bit when not coarsened for the view.
    let o = RenderOptions { displaced_tolerance: 0.0, ..opts(192, 108, Mode::Displaced) };
    assert_agree(&render_gpu(g, &small, &o), &render_cpu(&small, &o), "displaced");
}

/// A raised Gaussian bump at UV (0.5, 0.5).
fn bump_field() -> HeightField {
    let n = 64;
    HeightField::from_height_fn(n, n, |x, y| {
        let d2 = ((x as f32 + 0.5) / n as f32 - 0.5).powi(2) + ((y as f32 + 0.5) / n as f32 - 0.5).powi(2);
        (-d2 / (2.0 * 0.06f32.powi(2))).exp()
    })
}

fn one_object(mesh: Mesh, field: HeightField, technique: Technique, camera: Camera, light: Vec3) -> Scene {
    let material = Material {
        height: Some(Arc::new(field)),
        technique,
        base_color: Vec3::ONE,
        specular: 0.0,
        depth_scale: 0.05,
        edges: EdgeMode::Clamp,
        trace: TraceParams { min_samples: 32, max_samples: 96, refine: 3, ..Default::default() },
        shadow: ShadowParams { mode: ShadowMode::None, ..Default::default() },
        ..Material::default()
    };
    Scene {
        camera,
        lights: vec![Light::Directional { direction: light, color: Vec3::ONE, intensity: 1.0 }],
        materials: vec![material],
        objects: vec![Object { name: "test".into(), mesh: Arc::new(mesh), material: 0, transform: Mat4::IDENTITY }],
        ambient: Vec3::ZERO,
        background: Vec3::ZERO,
    }
}

fn brightness_at(out: &RenderOutput, cam: &Camera, p: Vec3) -> f32 {
    let c = cam.projection(1.0) * cam.view() * p.extend(1.0);
    let (x, y) = ((c.x / c.w * 0.5 + 0.5) * out.width as f32, (0.5 - c.y / c.w * 0.5) * out.height as f32);
    let i = (y as u32).min(out.height - 1) * out.width + (x as u32).min(out.width - 1);
    out.color[i as usize].dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// the bump test (ARCHITECTURE.md, Conventions) on the GPU: lit from the surface's +T side a raised bump is
/// brighter on its +T side, lit from +B brighter on its +B side; on a plane, a cube face and a
/// sphere, with normal mapping and POM. The pictures also agree with the CPU's.
#[test]
fn bump_test_on_a_plane_a_cube_face_and_a_sphere() {
    let Some(g) = gpu() else { return };
    let quad = Mesh::quad(Vec2::splat(2.0));
    let cube = Mesh::cube(2.0);
    let sphere = Mesh::uv_sphere(1.0, 48, 96);
    // The frame at uv (0.5, 0.5): the quad's centre, the centre of the cube's +Z face, and the
    // sphere's vertex nearest that uv.
    let nearest = |m: &Mesh| {
        let d = |i: usize| (m.uvs[i] - Vec2::splat(0.5)).length();
        let i = (0..m.uvs.len()).min_by(|&a, &b| d(a).total_cmp(&d(b))).unwrap();
        (m.positions[i], m.normals[i], m.tangents[i].truncate(), 0.05 * m.uv_scale[i].x)
    };
    let face: Vec<usize> = (0..cube.normals.len()).filter(|&i| cube.normals[i].z > 0.9).collect();
    let centre = face.iter().map(|&i| cube.positions[i]).sum::<Vec3>() / face.len() as f32;
    let cube_frame = (centre, Vec3::Z, cube.tangents[face[0]].truncate(), 0.1);
    let cases = [
        ((Vec3::ZERO, Vec3::Z, quad.tangents[0].truncate(), 0.05 * quad.uv_scale[0].x), quad.clone(), "quad"),
        (cube_frame, cube, "cube +Z face"),
        (nearest(&sphere), sphere.clone(), "sphere"),
    ];
    for ((p, n, t, offset), mesh, what) in cases {
        let b = n.cross(t);
        let cam = Camera { eye: p + n * 2.0, target: p, up: b, fov_y_deg: 30.0, ..Camera::default() };
        for technique in [Technique::Normal, Technique::Pom] {
            for (axis, name) in [(t, "+T"), (b, "+B")] {
                let s = one_object(mesh.clone(), bump_field(), technique, cam, axis + n * 0.4);
                let o = RenderOptions { width: 128, height: 128, aovs: true, ..Default::default() };
                let out = render_gpu(g, &s, &o);
                let plus = brightness_at(&out, &cam, p + axis * offset);
                let minus = brightness_at(&out, &cam, p - axis * offset);
                assert!(plus > minus + 0.1, "GPU {what} {technique} lit from {name}: {plus} vs {minus}");
                assert_agree(&out, &render_cpu(&s, &o), &format!("bump {what} {technique} {name}"));
            }
        }
    }
}

/// Concentric ripples moving outward: frame `k` of a dynamic height field.
fn ripple(k: u32) -> HeightField {
    let n = 96;
    HeightField::from_height_fn(n, n, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / n as f32 - 0.5, (y as f32 + 0.5) / n as f32 - 0.5);
        let r = (u * u + v * v).sqrt();
        0.5 + 0.5 * (r * 40.0 - k as f32 * 1.3).sin() * (-r * 3.0).exp()
    })
}

/// Dynamic height fields (Tatarchuk 2006, docs/REFERENCES.md): the same GPU scene, its height map replaced each frame and
/// rebuilt by the compute passes (mips, normals, parallax map, pyramid), matches a CPU render of
/// that frame's field, frame after frame, and is not the previous frame.
#[test]
fn dynamic_height_field_matches_the_cpu_frame_after_frame() {
    let Some(g) = gpu() else { return };
    let cam = Camera { eye: Vec3::new(0.0, 1.6, 1.6), target: Vec3::ZERO, fov_y_deg: 40.0, ..Camera::default() };
    let mesh = Mesh::plane(Vec2::splat(2.0), 1);
    let mut scene = one_object(mesh, ripple(0), Technique::Pom, cam, Vec3::new(0.6, 0.5, 0.2));
    scene.materials[0].depth_scale = 0.06;
    scene.materials[0].shadow = ShadowParams { mode: ShadowMode::Soft, softness: 0.1 };
    scene.ambient = Vec3::splat(0.1);
    let o = opts(160, 120, Mode::Material);
    let mut r = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut gs = r.prepare(&scene, &o).expect("prepare");
    let mut previous: Option<RenderOutput> = None;
    for k in 0..4 {
        let field = ripple(k);
        gs.set_height(r.context(), 0, &field).expect("same size");
        let gpu_out = r.draw(&mut gs, &scene).expect("draw");
        let mut frame_scene = scene.clone();
        frame_scene.materials[0].height = Some(Arc::new(field));
        let cpu_out = render_cpu(&frame_scene, &o);
        assert_agree(&gpu_out, &cpu_out, &format!("ripple frame {k}"));
        if let Some(prev) = &previous {
            let (psnr, _) = compare(&gpu_out, prev);
            assert!(psnr < 35.0, "frame {k} looks like frame {}: {psnr:.1} dB (stale height maps?)", k - 1);
        }
        previous = Some(cpu_out);
    }
    // Changing the size is an error, not a panic.
    assert!(gs.set_height(r.context(), 0, &HeightField::constant(8, 8, 0.5)).is_err());
    assert!(gs.set_height(r.context(), 3, &ripple(0)).is_err());
}

/// McGuire 2005's fur and grass (examples/scenes/fur.toml, docs/REFERENCES.md): steep parallax
/// over the built-in fur and grass maps with depth shadows, and the same scene with pom and
/// exact, agree with the CPU within the usual tolerance. The maps are 128x128 instead of 512x512
/// for speed.
#[test]
fn fur_scene_matches_the_cpu() {
    let Some(g) = gpu() else { return };
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/scenes");
    let text = std::fs::read_to_string(dir.join("fur.toml")).expect("examples/scenes/fur.toml");
    assert_eq!(text.matches(":512x512\"").count(), 4, "fur.toml's four built-in maps are 512x512");
    let scene = pomkit_io::scene::parse_scene(&text.replace(":512x512\"", ":128x128\""), &dir).expect("fur.toml loads");
    assert!(scene.materials.iter().all(|m| m.shadow.mode == ShadowMode::Depth && m.technique == Technique::Steep));
    for mode in [Mode::Material, Mode::Technique(Technique::Pom), Mode::Technique(Technique::Exact)] {
        let o = opts(256, 144, mode);
        let (gpu_out, cpu_out) = (render_gpu(g, &scene, &o), render_cpu(&scene, &o));
        assert_agree(&gpu_out, &cpu_out, &format!("fur scene {mode:?}"));
        // Depth shadows darken what lies deep: the first light's visibility spans the range.
        // (Covered pixels: those with a hit UV.)
        let aovs = cpu_out.aovs.as_ref().expect("AOVs");
        let dark = aovs.shadow.iter().zip(&aovs.uv).filter(|&(&v, uv)| *uv != Vec2::ZERO && v < 0.5).count();
        assert!(dark > cpu_out.covered / 20, "fur scene {mode:?}: only {dark} pixels darker than 0.5");
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let Some(g) = gpu() else { return };
    let scene = pomkit_core::demo::demo_scene_sized(32);
    let mut r = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut err = |s: &Scene, o: &RenderOptions| r.render(s, o).err().map(|e| e.to_string());
    let o = opts(64, 36, Mode::Material);
    assert!(err(&scene, &RenderOptions { width: 0, ..o }).is_some_and(|e| e.contains("0x36")));
    let mut lights = scene.clone();
    lights.lights = vec![lights.lights[0]; 5];
    assert!(err(&lights, &o).is_some_and(|e| e.contains("5 lights")));
    let mut dangling = scene.clone();
    dangling.objects[0].material = 9;
    assert!(err(&dangling, &o).is_some_and(|e| e.contains("material 9")));
    let mut nan = scene.clone();
    nan.materials[0].depth_scale = f32::NAN;
    assert!(err(&nan, &o).is_some_and(|e| e.contains("depth_scale")));
    // Huge sample counts are clamped, not hung on.
    let mut huge = scene.clone();
    huge.materials.iter_mut().for_each(|m| {
        m.trace.max_samples = u32::MAX;
        m.trace.samples = u32::MAX;
    });
    assert!(r.render(&huge, &opts(32, 18, Mode::Technique(Technique::Pom))).is_ok());
}

#[path = "../../pomkit-cpu/tests/support/silhouettes.rs"]
mod silhouettes;

/// Silhouettes on the GPU: the outline disagreement with the displaced truth drops by at least
/// 70% on a cobblestone sphere and a pyramid torus (as on the CPU, pomkit-cpu/tests/silhouette.rs),
/// and the silhouette picture agrees with the CPU renderer's within the usual tolerance.
#[test]
fn silhouettes_cut_the_outline_disagreement_and_match_the_cpu() {
    use silhouettes::{Shape, coverage, disagreement, scene};
    let Some(g) = gpu() else { return };
    let o = RenderOptions { width: 400, height: 400, displaced_edge_texels: 1.0, ..Default::default() };
    for shape in [Shape::CobblestoneSphere, Shape::PyramidTorus] {
        let truth = coverage(&render_cpu(
            &scene(shape, Technique::Pom, false, 256),
            &RenderOptions { mode: Mode::Displaced, ..o },
        ));
        for technique in [Technique::Pom, Technique::Exact] {
            let before = disagreement(&coverage(&render_gpu(g, &scene(shape, technique, false, 256), &o)), &truth);
            let with = scene(shape, technique, true, 256);
            let gpu_out = render_gpu(g, &with, &o);
            let after = disagreement(&coverage(&gpu_out), &truth);
            println!("GPU {shape:?} {technique}: {before} -> {after} pixels disagree with the displaced outline");
            assert!(before > 4000, "{shape:?} {technique}: only {before} pixels disagree without silhouettes");
            assert!((after as f64) <= 0.3 * before as f64, "{shape:?} {technique}: {before} -> {after}, less than 70%");
            let cpu_out = render_cpu(&with, &o);
            let between = disagreement(&coverage(&gpu_out), &coverage(&cpu_out));
            println!("GPU and CPU silhouettes: {between} pixels of coverage differ");
            assert!(between <= 2 + cpu_out.covered / 200, "{shape:?} {technique}: {between} pixels of coverage differ");
            assert_agree(&gpu_out, &cpu_out, &format!("silhouettes {shape:?} {technique}"));
        }
    }
}

/// A material given relaxed cones (`Material::cones`, a scene's `cone_map`): both renderers
/// walk them as relaxed cone stepping, and agree; the picture is the conservative cones' (whose
/// hits are exact) up to the relaxed walk's misses, at another count of fetches.
#[test]
fn given_relaxed_cones_render_alike_on_both_sides() {
    let Some(g) = gpu() else { return };
    let mut scene = pomkit_core::demo::demo_scene_sized(128);
    for m in &mut scene.materials {
        m.technique = Technique::Cone;
    }
    let o = opts(256, 144, Mode::Material);
    let (gpu_exact, cpu_exact) = (render_gpu(g, &scene, &o), render_cpu(&scene, &o));
    assert_agree(&gpu_exact, &cpu_exact, "conservative cones");
    for m in &mut scene.materials {
        if let Some(field) = &m.height {
            m.cones = Some(Arc::new(pomkit_core::cone::ConeMap::relaxed_cones(field, m.edges)));
        }
    }
    let (gpu_out, cpu_out) = (render_gpu(g, &scene, &o), render_cpu(&scene, &o));
    assert_agree(&gpu_out, &cpu_out, "relaxed cones");
    let (psnr, _) = compare(&cpu_out, &cpu_exact);
    println!("relaxed against conservative cones (CPU): {psnr:.1} dB");
    assert!(psnr >= 35.0, "relaxed cone stepping strays from the exact hits: {psnr:.1} dB");
    let fetches = |out: &RenderOutput| -> f32 { out.aovs.as_ref().map_or(0.0, |a| a.fetches.iter().sum()) };
    let (relaxed, conservative) = (fetches(&cpu_out), fetches(&cpu_exact));
    println!("fetches: relaxed {relaxed}, conservative {conservative}");
    assert!((relaxed - conservative).abs() > 0.01 * conservative, "the given cones were not used");
}

/// A new height field removes the old cones (`cone` then walks as `exact`: exact's picture, at
/// exact's fetches plus the one read that finds no cone); `GpuScene::set_cones` gives the new
/// field's back (the CPU's picture and fetches with cones).
#[test]
fn cones_come_back_with_set_cones_after_a_new_height_field() {
    let Some(g) = gpu() else { return };
    // Spikes on a floor at depth 0.8 (not 1: rays that end exactly on the volume's floor are
    // counted differently by the f32 and f64 walks).
    let spikes = |k: u32| {
        HeightField::from_height_fn(96, 96, move |x, y| if (x * 7 + y * 13 + k).is_multiple_of(97) { 1.0 } else { 0.2 })
    };
    let cam = Camera {
        eye: Vec3::new(0.0, 0.6, 1.9),
        target: Vec3::new(0.0, 0.0, -0.3),
        fov_y_deg: 40.0,
        ..Camera::default()
    };
    let scene = one_object(Mesh::plane(Vec2::splat(2.0), 1), spikes(0), Technique::Cone, cam, Vec3::new(0.6, 0.5, 0.2));
    let o = opts(160, 120, Mode::Material);
    let mut r = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut gs = r.prepare(&scene, &o).expect("prepare");
    let field = spikes(5);
    let mut next = scene.clone();
    next.materials[0].height = Some(Arc::new(field.clone()));
    let fetches = |out: &RenderOutput| -> f32 { out.aovs.as_ref().map_or(0.0, |a| a.fetches.iter().sum()) };
    let cpu_cone = render_cpu(&next, &o);
    let cpu_exact = render_cpu(&next, &opts(160, 120, Mode::Technique(Technique::Exact)));
    gs.set_height(r.context(), 0, &field).expect("same size");
    let without = r.draw(&mut gs, &next).expect("draw");
    let edges = next.materials[0].edges;
    gs.set_cones(r.context(), 0, Some(&pomkit_core::cone::ConeMap::conservative(&field, edges))).expect("they fit");
    let with = r.draw(&mut gs, &next).expect("draw");
    let (f_cone, f_exact, f_without, f_with) =
        (fetches(&cpu_cone), fetches(&cpu_exact), fetches(&without), fetches(&with));
    println!("fetches: CPU cone {f_cone}, CPU exact {f_exact}; GPU without cones {f_without}, with {f_with}");
    // Cone steps and exact's pyramid steps count differently (here cones cost more: docs/ACCURACY.md):
    // the fetch totals tell the walks apart.
    assert!((f_cone - f_exact).abs() > 0.1 * f_exact, "cones that change nothing test nothing");
    assert!((f_with - f_without).abs() > 0.1 * f_without, "set_cones changed nothing");
    assert_agree(&with, &cpu_cone, "new heights with their cones");
    let (psnr, _) = compare(&without, &cpu_exact);
    assert!(psnr >= 40.0, "without cones the picture is not exact's: {psnr:.1} dB");
    assert!(f_without > 0.95 * f_exact, "without cones fewer fetches than exact's: {f_without} against {f_exact}");
    // Errors, not panics.
    assert!(gs.set_cones(r.context(), 3, None).is_err());
    let small = pomkit_core::cone::ConeMap::conservative(&HeightField::constant(4, 4, 0.5), edges);
    assert!(gs.set_cones(r.context(), 0, Some(&small)).is_err());
}

/// A truncated cone: a flat top of radius 0.2 at UV (0.5, 0.5), sides falling to the ground
/// at radius 0.32, with a sharp convex rim (where pom's chords cut under the surface).
fn mesa_field() -> HeightField {
    let n = 64;
    HeightField::from_height_fn(n, n, |x, y| {
        let r = ((x as f32 + 0.5) / n as f32 - 0.5).hypot((y as f32 + 0.5) / n as f32 - 0.5);
        ((0.32 - r) / 0.12).clamp(0.0, 1.0)
    })
}

/// Self-shadow receivers lie on the surface the shadow ray marches, for every technique: a
/// truncated cone under a low sun (15 degrees above the horizon) has no shadowed pixel on the
/// side that faces the sun, on either renderer. Its height never rises with the distance from
/// its axis, and along a ray toward the sun from a point whose outward direction has a positive
/// component toward the sun that distance only grows, so the surface falls away under the ray:
/// such a point is lit (the analytic answer). The shadow ray of a receiver left below the
/// surface (pom's chords under the convex rim, steep's layers, a coarser mip) would start
/// inside the relief and shadow it in dashes. The far side must still be shadowed.
#[test]
fn a_low_sun_leaves_every_face_that_looks_at_it_lit() {
    let Some(g) = gpu() else { return };
    let elevation = 15f32.to_radians();
    // The quad lies in the XY plane with u along +X: a sun toward +X is a sun toward +u.
    let sun = Vec3::new(elevation.cos(), 0.0, elevation.sin());
    let cam = Camera {
        eye: Vec3::new(0.0, -1.3, 1.6),
        target: Vec3::ZERO,
        up: Vec3::Z,
        fov_y_deg: 45.0,
        ..Camera::default()
    };
    let o = RenderOptions { width: 160, height: 160, aovs: true, ..Default::default() };
    for technique in [Technique::Pom, Technique::Steep, Technique::Relief, Technique::Parallax, Technique::Exact] {
        for mode in [ShadowMode::Hard, ShadowMode::Soft, ShadowMode::Exact] {
            let mut s = one_object(Mesh::quad(Vec2::splat(2.0)), mesa_field(), technique, cam, sun);
            s.materials[0].trace = TraceParams::default();
            s.materials[0].shadow = ShadowParams { mode, softness: 0.1 };
            for (renderer, out) in [("CPU", render_cpu(&s, &o)), ("GPU", render_gpu(g, &s, &o))] {
                let a = out.aovs.as_ref().expect("AOVs");
                let (mut facing, mut dark_facing, mut far_shadowed) = (0, 0, 0);
                for (uv, &vis) in a.uv.iter().zip(&a.shadow) {
                    let p = *uv - Vec2::splat(0.5);
                    if !(uv.min_element() > 0.02 && uv.max_element() < 0.98) || p.length() < 0.02 {
                        continue;
                    }
                    let toward_sun = p.x / p.length();
                    if toward_sun > 0.3 {
                        facing += 1;
                        dark_facing += usize::from(vis < 0.999);
                    } else if toward_sun < -0.9 && p.length() < 0.4 && vis < 0.5 {
                        far_shadowed += 1;
                    }
                }
                let what = format!("{renderer} {technique} {mode:?}");
                println!(
                    "{what}: {facing} pixels face the sun, {dark_facing} of them shadowed; {far_shadowed} shadowed on the far side"
                );
                assert!(facing > 2000, "{what}: only {facing} pixels face the sun");
                assert_eq!(dark_facing, 0, "{what}: {dark_facing} of {facing} sunward pixels are self-shadowed");
                assert!(far_shadowed > 20, "{what}: the far side is not shadowed ({far_shadowed} pixels)");
            }
        }
    }
}
