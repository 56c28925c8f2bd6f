//! McGuire and McGuire 2005's fur and grass drawn by Bevy (lavapipe on CI) against pomkit's own
//! CPU renderer of the same scene, examples/scenes/fur.toml: the same meshes, camera and
//! materials (examples/support/fur.rs), pixel for pixel. Bevy lights with its PBR and pomkit
//! with Blinn-Phong, so what is compared is what both compute the same way: the traced UV and
//! depth, the depth self-shadow at the hit, and which surface is in front (the grass blades
//! before the ball's bottom, by pixel depth offset). And the LOD fade's far colour: a distant
//! ball shows the strands' tips' colour with it, the texture's darker average without.
//!
//! All tests share one lock: each builds a Bevy app with its own GPU device.

#[path = "support/examples.rs"]
mod examples;
#[path = "../examples/support/fur.rs"]
mod fur;
#[path = "../examples/support/headless.rs"]
mod headless;

use std::sync::Mutex;
use std::time::Duration;

use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy_pomkit::{PomkitDebug, PomkitMaterial};
use fur::FurOptions;
use headless::{Frame, Headless};
use pomkit_core::render::{RenderOptions, RenderOutput};
use pomkit_core::scene::Scene;

static GPU: Mutex<()> = Mutex::new(());

const W: u32 = 160;
const H: u32 = 90;
const TIMEOUT: Duration = Duration::from_secs(300);

/// The scene with the LOD fade off (the full technique everywhere, in both renderers) and only
/// its first light (the sun), whose self-shadow both debug outputs show.
fn traced_scene() -> Scene {
    let mut scene = fur::load_scene().expect("examples/scenes/fur.toml loads");
    for m in &mut scene.materials {
        m.lod_threshold = f32::MAX;
    }
    scene.lights.truncate(1);
    scene
}

/// pomkit-cpu's `w` x `h` picture of `scene` with its AOVs (hit UV, depth, first light's
/// visibility).
fn cpu_render(scene: &Scene, (w, h): (u32, u32)) -> RenderOutput {
    let opts = RenderOptions { width: w, height: h, aovs: true, ..RenderOptions::default() };
    pomkit_cpu::CpuRenderer::new().render(scene, &opts, &|_, _| {}).expect("pomkit-cpu renders the scene")
}

/// Bevy's `w` x `h` frame of `scene` with `opts` (raw half floats, no tone mapping, no shadow
/// maps), after `edit` changed what was spawned; and the camera ray of every pixel.
fn bevy_render(
    scene: &Scene,
    size: (u32, u32),
    opts: &FurOptions,
    edit: impl FnOnce(&mut World, &fur::FurHandles),
) -> (Frame, Vec<Ray3d>) {
    let (frame, rays, _) = bevy_render_reported(scene, size, opts, edit);
    (frame, rays)
}

/// [`bevy_render`], and what the plugin reported.
fn bevy_render_reported(
    scene: &Scene,
    (w, h): (u32, u32),
    opts: &FurOptions,
    edit: impl FnOnce(&mut World, &fur::FurHandles),
) -> (Frame, Vec<Ray3d>, Vec<String>) {
    let mut app = Headless::new(w, h);
    let target = RenderTarget::Image(app.target().into());
    let opts = FurOptions { tonemapping: Tonemapping::None, shadow_maps: false, ..opts.clone() };
    let handles = fur::spawn(app.world(), scene, Some(target), &opts);
    edit(app.world(), &handles);
    let frame = app.frame(TIMEOUT).expect("frame");
    let world = app.world();
    let (cam, gt) = world.query::<(&Camera, &GlobalTransform)>().get(world, handles.camera).expect("camera");
    let mut rays = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            rays.push(cam.viewport_to_world(gt, p).expect("a ray through every pixel"));
        }
    }
    let reports = app.world().resource::<bevy_pomkit::HeightMaps>().reports();
    (frame, rays, reports)
}

/// The ball of the scene file: centre and radius.
const BALL: (Vec3, f32) = (Vec3::new(0.0, 0.5, 0.0), 0.6);

/// Where `ray` first meets the ball's sphere (the polygons' envelope), if it does.
fn ball_hit(ray: Ray3d) -> Option<Vec3> {
    let (c, r) = BALL;
    let d = ray.direction.as_vec3();
    let o = ray.origin - c;
    let b = o.dot(d);
    let disc = b * b - (o.length_squared() - r * r);
    (disc > 0.0).then(|| ray.origin + d * (-b - disc.sqrt()))
}

/// `a - b` reduced to the nearest tile (UVs repeat with period 1).
fn wrapped(a: f32, b: f32) -> f32 {
    let d = a - b;
    d - d.round()
}

fn quantile(mut v: Vec<f32>, q: f32) -> f32 {
    v.sort_by(f32::total_cmp);
    v[((v.len() - 1) as f32 * q) as usize]
}

/// Over the pixels where both renderers traced the ball or the lawn, with the LOD fade off in
/// both: the hit UV (in texels of the 512-texel maps, reduced to one tile), the hit depth and
/// the sun's depth self-shadow, Bevy's debug outputs against pomkit-cpu's AOVs. Steep parallax
/// quantises the hit to its 32 planes, and the two renderers take the ray into the tangent
/// frame each its own way (Bevy from the UV derivatives, pomkit-cpu from per-vertex UV scales),
/// so a pixel may land one plane apart: the medians are tight, the tails bounded.
#[test]
fn hit_uv_depth_and_depth_shadow_agree_with_pomkit_cpu() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let scene = traced_scene();
    let cpu = cpu_render(&scene, (W, H));
    let aovs = cpu.aovs.as_ref().expect("AOVs");
    let (hit, rays) = bevy_render(&scene, (W, H), &FurOptions { debug: PomkitDebug::HitUv, ..default() }, |_, _| {});
    let (shadow, _) = bevy_render(&scene, (W, H), &FurOptions { debug: PomkitDebug::Shadow, ..default() }, |_, _| {});
    let size = 512.0;
    // Pixels where pomkit-cpu drew a surface (its UV AOV is 0 on the background), off the
    // frame's edge, split by the surface: the ball's sphere met by the ray, or not (the lawn).
    let (mut ball, mut lawn) = (Vec::new(), Vec::new());
    for (k, ray) in rays.iter().enumerate() {
        let (x, y) = (k as u32 % W, k as u32 / W);
        if aovs.uv[k] == pomkit_core::glam::Vec2::ZERO || x == 0 || y == 0 || x + 1 == W || y + 1 == H {
            continue;
        }
        if ball_hit(*ray).is_some() { ball.push(k) } else { lawn.push(k) }
    }
    for (name, pixels) in [("ball", &ball), ("lawn", &lawn)] {
        let (mut uv_err, mut depth_err, mut vis_err) = (Vec::new(), Vec::new(), Vec::new());
        let (mut cpu_vis, mut bevy_vis) = (0.0, 0.0);
        for &k in pixels {
            let got = hit.pixels[k];
            let (du, dv) = (wrapped(got[0], aovs.uv[k].x), wrapped(got[1], aovs.uv[k].y));
            uv_err.push((du * du + dv * dv).sqrt() * size);
            depth_err.push((got[2] - aovs.depth[k]).abs());
            let v = shadow.pixels[k][0];
            vis_err.push((v - aovs.shadow[k]).abs());
            cpu_vis += aovs.shadow[k];
            bevy_vis += v;
        }
        let n = pixels.len();
        let share = |e: &[f32], over: f32| e.iter().filter(|&&e| e > over).count() as f32 / n as f32;
        let (uv_far, vis_far) = (share(&uv_err, 2.0), share(&vis_err, 0.1));
        let (uv_median, depth_median, vis_median) =
            (quantile(uv_err.clone(), 0.5), quantile(depth_err.clone(), 0.5), quantile(vis_err.clone(), 0.5));
        eprintln!(
            "{name}: {n} pixels: hit UV median {uv_median:.3} texels, {:.1}% over 2 texels; depth median \
             {depth_median:.4}; visibility median {vis_median:.4}, {:.1}% off by over 0.1; mean visibility \
             pomkit-cpu {:.3}, Bevy {:.3}",
            uv_far * 100.0,
            vis_far * 100.0,
            cpu_vis / n as f32,
            bevy_vis / n as f32,
        );
        assert!(n > 1500, "{name}: too few pixels ({n})");
        assert!(uv_median < 0.5, "{name}: hit UV median error {uv_median} texels");
        assert!(uv_far < 0.05, "{name}: {:.1}% of pixels hit over 2 texels from pomkit-cpu's hit", uv_far * 100.0);
        assert!(depth_median < 0.005, "{name}: hit depth median error {depth_median}");
        assert!(vis_median < 0.005, "{name}: depth self-shadow median error {vis_median}");
        assert!(vis_far < 0.05, "{name}: {:.1}% of pixels' self-shadow off by over 0.1", vis_far * 100.0);
    }
}

/// Which surface each pixel shows: the scene with the ball's material plain red and the lawn's
/// plain green, unlit (pomkit-cpu: no lights and a white ambient light, so a pixel is its base
/// colour), the LOD fade off; seen from low over the lawn, toward the ball's bottom.
fn identity_scene() -> Scene {
    let mut scene = traced_scene();
    scene.camera.eye = pomkit_core::glam::Vec3::new(0.0, 0.1, 1.6);
    scene.camera.target = pomkit_core::glam::Vec3::new(0.0, 0.0, 0.0);
    scene.lights.clear();
    scene.ambient = pomkit_core::glam::Vec3::ONE;
    for (m, c) in scene.materials.iter_mut().zip([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) {
        m.albedo = None;
        m.base_color = pomkit_core::glam::Vec3::from(c);
    }
    scene
}

/// Bevy's frame of [`identity_scene`]: the same colours, unlit; pixel depth offset as given.
fn bevy_identity(scene: &Scene, size: (u32, u32), pixel_depth: bool) -> (Frame, Vec<Ray3d>) {
    bevy_render(scene, size, &FurOptions::default(), |world, handles| {
        let mut materials = world.resource_mut::<Assets<PomkitMaterial>>();
        for (h, c) in handles.materials.iter().zip([Color::linear_rgb(1.0, 0.0, 0.0), Color::linear_rgb(0.0, 1.0, 0.0)])
        {
            let mut m = materials.get_mut(h).expect("material");
            m.base.base_color_texture = None;
            m.base.base_color = c;
            m.base.unlit = true;
            m.extension.pixel_depth_offset = pixel_depth;
        }
    })
}

/// The ball is sunk 0.1 into the lawn, whose polygon is the top of the grass: the part of the
/// ball below the polygon shows between the blades only where the traced depth (pixel depth
/// offset) puts the blade or soil behind it. Over the pixels whose view ray crosses the lawn's
/// polygon near the ball's foot before it meets the ball (if it does), Bevy must show the ball
/// or the lawn as pomkit-cpu does; without pixel depth offset the lawn's polygon hides the ball
/// there.
#[test]
fn the_balls_foot_in_the_grass_agrees_with_pomkit_cpu() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let size = (2 * W, 2 * H);
    let scene = identity_scene();
    let cpu = cpu_render(&scene, size);
    let (bevy, rays) = bevy_identity(&scene, size, true);
    let (flat, _) = bevy_identity(&scene, size, false);
    let ball = |c: [f32; 3]| c[0] > c[1];
    let (mut n, mut cpu_ball, mut agree, mut flat_ball) = (0, 0, 0, 0);
    // The pixels whose ray meets the ball's sphere below the lawn's polygon, and how many of
    // them pomkit-cpu shows the ball on (the rest: a blade in front).
    let (mut sunk, mut sunk_ball) = (0, 0);
    for (k, ray) in rays.iter().enumerate() {
        let d = ray.direction.as_vec3();
        if d.y >= 0.0 {
            continue;
        }
        // Where the ray crosses the lawn's polygon: within 0.5 of the ball's axis (its foot is
        // 0.33 wide there), and before it meets the ball.
        let crossing = ray.origin + d * (-ray.origin.y / d.y);
        if Vec2::new(crossing.x, crossing.z).length() > 0.5 || ball_hit(*ray).is_some_and(|p| p.y >= 0.0) {
            continue;
        }
        let c = cpu.color[k];
        let want = ball([c.x, c.y, c.z]);
        if ball_hit(*ray).is_some() {
            sunk += 1;
            sunk_ball += usize::from(want);
        }
        let b = bevy.pixels[k];
        n += 1;
        cpu_ball += usize::from(want);
        agree += usize::from(want == ball([b[0], b[1], b[2]]));
        let f = flat.pixels[k];
        flat_ball += usize::from(ball([f[0], f[1], f[2]]));
    }
    if let Some(dir) = std::env::var_os("POMKIT_PICTURES") {
        let cpu_bytes: Vec<u8> = cpu.to_srgb8().into_iter().flat_map(|[r, g, b]| [r, g, b, 255]).collect();
        for (name, bytes) in [("bevy", bevy.to_srgb8()), ("bevy-no-pdo", flat.to_srgb8()), ("cpu", cpu_bytes)] {
            let path = std::path::Path::new(&dir).join(format!("fur-foot-{name}.png"));
            image::RgbaImage::from_raw(size.0, size.1, bytes).expect("a whole frame").save(path).expect("write");
        }
    }
    let share = |k: usize| k as f32 / n.max(1) as f32;
    eprintln!(
        "{n} pixels cross the lawn at the ball's foot: pomkit-cpu shows the ball on {:.1}% ({sunk_ball} of the \
         {sunk} that meet its sphere below the lawn), Bevy agrees on {:.1}%; without pixel depth offset Bevy \
         shows the ball on {:.1}%",
        share(cpu_ball) * 100.0,
        share(agree) * 100.0,
        share(flat_ball) * 100.0
    );
    assert!(n > 500, "too few pixels see the ball's foot: {n}");
    assert!(
        share(cpu_ball) > 0.1 && share(cpu_ball) < 0.9,
        "pomkit-cpu shows the ball on {:.1}% of them: the test cannot tell the ball from the grass",
        share(cpu_ball) * 100.0
    );
    assert!(share(agree) > 0.95, "Bevy and pomkit-cpu agree on {:.1}% of the pixels", share(agree) * 100.0);
    assert!(share(flat_ball) < 0.01, "without pixel depth offset the ball shows through the lawn's polygon");
}

/// The linear colour of the mean of `pixels` among `frame`'s.
fn mean_color(frame: &Frame, pixels: &[usize]) -> Vec3 {
    pixels.iter().map(|&k| Vec3::new(frame.pixels[k][0], frame.pixels[k][1], frame.pixels[k][2])).sum::<Vec3>()
        / pixels.len() as f32
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// Seen from four times the scene's distance the ball lies beyond the LOD band (its height
/// map's mip level is over 5 there; the band ends at 4). Unlit, its pixels show the base
/// colour: with `far_color` the strands' tips' colour, computed here from the procedural fur's
/// height map and albedo (the texels in the top fifth of the height range, times the
/// material's `base_color`); without it the
/// albedo's coarse mips, the mean of tips, roots and skin, which is darker. The depth
/// self-shadow fades out with the technique: lit by the sun, the distant ball's pixels that
/// face it see all of it.
#[test]
fn a_distant_ball_shows_the_tips_colour_with_far_color_and_a_darker_average_without() {
    use pomkit_core::procedural::{Pattern, albedo, generate};
    use pomkit_core::scene::srgb_to_linear;
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // The truth, from the textures.
    let (field, colors) = (generate(Pattern::Fur, 512, 512), albedo(Pattern::Fur, 512, 512));
    let linear = |c: [u8; 3]| Vec3::from(c.map(|v| srgb_to_linear(f32::from(v) / 255.0)));
    let depths = field.depths();
    let (lo, hi) = depths.iter().fold((f32::MAX, f32::MIN), |(a, b), &d| (a.min(d), b.max(d)));
    let tips: Vec<Vec3> =
        depths.iter().zip(&colors).filter(|(d, _)| **d <= lo + 0.2 * (hi - lo)).map(|(_, c)| linear(*c)).collect();
    let tips = tips.iter().sum::<Vec3>() / tips.len() as f32;
    let average = colors.iter().map(|c| linear(*c)).sum::<Vec3>() / colors.len() as f32;
    let mut scene = fur::load_scene().expect("examples/scenes/fur.toml loads");
    scene.lights.truncate(1);
    // Both are multiplied by the material's base colour, as the texture is.
    let base = scene.materials[0].base_color;
    let (tips, average) = (tips * Vec3::new(base.x, base.y, base.z), average * Vec3::new(base.x, base.y, base.z));
    let target = Vec3::new(scene.camera.target.x, scene.camera.target.y, scene.camera.target.z);
    let eye = Vec3::new(scene.camera.eye.x, scene.camera.eye.y, scene.camera.eye.z);
    let far = Transform::from_translation(target + (eye - target) * 4.0).looking_at(target, Vec3::Y);
    let unlit = |world: &mut World, handles: &fur::FurHandles| {
        let mut materials = world.resource_mut::<Assets<PomkitMaterial>>();
        for h in &handles.materials {
            materials.get_mut(h).expect("material").base.unlit = true;
        }
    };
    let with = FurOptions { far_color: true, camera: Some(far), ..default() };
    let (shown, rays) = bevy_render(&scene, (W, H), &with, unlit);
    let without = FurOptions { far_color: false, ..with.clone() };
    let (plain, _) = bevy_render(&scene, (W, H), &without, unlit);
    let (shadow, _) = bevy_render(&scene, (W, H), &FurOptions { debug: PomkitDebug::Shadow, ..with }, |_, _| {});
    // The ball's middle: pixels whose ray meets its sphere head on (away from its outline).
    let sun = match scene.lights[0] {
        pomkit_core::scene::Light::Directional { direction, .. } => {
            Vec3::new(direction.x, direction.y, direction.z).normalize()
        }
        pomkit_core::scene::Light::Point { .. } => panic!("the scene's first light is the sun"),
    };
    let (mut middle, mut sunny) = (Vec::new(), Vec::new());
    for (k, ray) in rays.iter().enumerate() {
        let Some(p) = ball_hit(*ray) else { continue };
        let n = (p - BALL.0) / BALL.1;
        if n.dot(-ray.direction.as_vec3()) > 0.6 {
            middle.push(k);
            if n.dot(sun) > 0.3 {
                sunny.push(k);
            }
        }
    }
    let (got, mip_average) = (mean_color(&shown, &middle), mean_color(&plain, &middle));
    let faded = middle.iter().filter(|&&k| shadow.pixels[k][1] == 0.0).count();
    let visibility = sunny.iter().map(|&k| shadow.pixels[k][0]).sum::<f32>() / sunny.len().max(1) as f32;
    eprintln!(
        "{} pixels in the ball's middle ({faded} beyond the LOD band, {} facing the sun): far colour {got:.4}, tips \
         {tips:.4}; without {mip_average:.4}, the albedo's mean {average:.4}; depth self-shadow visibility {visibility:.4}",
        middle.len(),
        sunny.len()
    );
    assert!(middle.len() > 60 && sunny.len() > 20, "the distant ball covers too few pixels");
    assert_eq!(faded, middle.len(), "some of the distant ball is not beyond the LOD band");
    let off = (got - tips).abs().max_element();
    assert!(off < 0.01, "the distant ball's colour {got} is not the tips' {tips}");
    let off = ((mip_average - average) / average).abs().max_element();
    assert!(off < 0.15, "without the far colour the ball shows {mip_average}, not about the albedo's mean {average}");
    assert!(
        luminance(mip_average) < 0.8 * luminance(tips),
        "the albedo's mean {mip_average} is not darker than the tips' colour {tips}: the test is blind"
    );
    assert!(visibility > 0.99, "the depth self-shadow does not fade out beyond the LOD band: {visibility}");
}

/// A far colour that is not a number is reported once, naming the material, and ignored: the
/// picture is the one without it.
#[test]
fn a_far_colour_that_is_not_finite_is_reported_and_ignored() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let scene = fur::load_scene().expect("examples/scenes/fur.toml loads");
    let size = (W / 2, H / 2);
    let opts = FurOptions { far_color: false, ..default() };
    let (plain, _) = bevy_render(&scene, size, &opts, |_, _| {});
    let (bad, _, reports) = bevy_render_reported(&scene, size, &opts, |world, handles| {
        let mut materials = world.resource_mut::<Assets<PomkitMaterial>>();
        materials.get_mut(&handles.materials[0]).expect("material").extension.far_color =
            Some(Color::linear_rgb(f32::NAN, 0.3, 0.2));
    });
    eprintln!("{reports:#?}");
    assert_eq!(reports.len(), 1, "{reports:#?}");
    assert!(reports[0].contains("material \"fur\"") && reports[0].contains("far_color"), "{}", reports[0]);
    assert_eq!(plain.pixels, bad.pixels, "a far colour that is not finite changed the picture");
}

/// The `fur` example, run where `XDG_RUNTIME_DIR` is unset (a container, CI), writes its
/// picture and logs no error or warning of its own making (Bevy's warning that lavapipe renders
/// in software is the machine's). `cargo test` builds the examples beside the tests; a run of
/// this file alone may not have it.
#[test]
fn the_fur_example_writes_its_picture_without_errors_or_warnings() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let Some(picture) = examples::picture_of("fur", &["--width", "64", "--height", "36", "--distance", "2"]) else {
        return;
    };
    assert_eq!(picture.dimensions(), (64, 36));
    // A bad option is one clear message and a failure, not a panic.
    let example = examples::built_example("fur").expect("built");
    let png = std::env::temp_dir().join(format!("pomkit-bevy-fur-bad-{}.png", std::process::id()));
    let out = examples::run(&example, &["--distance", "0"], &png);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--distance 0"), "{err}");
    assert!(!err.contains("panicked") && !png.exists(), "{err}");
}
