//! Bevy's own parallax mapping against bevy_pomkit, in the same Bevy app, on lavapipe or a GPU:
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example bench
//! ```
//!
//! For each method (Bevy's `Occlusion` and `Relief`, pomkit's `pom` and `exact`):
//! - **frame time**: the demo scene (a cube on a floor, sun with shadow maps) at 960 x 540,
//!   the median of `--frames` frames after the picture has settled;
//! - **accuracy**: a 2 x 2 quad with imported (glTF-convention) tangents, seen at about 50
//!   degrees, each pixel's hit UV read back (pomkit's debug output; for Bevy, an unlit
//!   material whose albedo stores its own UV) and compared with pomkit-core's exact tracer for
//!   the same camera ray: median and 90th percentile error in texels, share over one texel;
//! - **fetches**: height reads per pixel, counted as a GPU makes them (pomkit's debug output;
//!   for Bevy, its loop replayed on the CPU for the same rays, one read per `sample_depth_map`).
//!
//! The same quad with tangents of the opposite handedness (w = -1, as generated tangents have on
//! some assets) shows what that does to Bevy's own parallax (last rows). docs/BENCHMARKS.md
//! records a run.

#[path = "support/headless.rs"]
mod headless;
#[path = "support/probe.rs"]
mod probe;
#[path = "support/scene.rs"]
mod scene;

use std::time::{Duration, Instant};

use bevy::camera::Hdr;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::pbr::ParallaxMappingMethod;
use bevy::prelude::*;
use bevy::render::render_resource::TextureFormat;
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{MapKind, Pomkit, PomkitDebug, PomkitMaterial, ShadowMode, Technique};
use clap::Parser;
use headless::{Frame, Headless};
use pomkit_core::EdgeMode;
use pomkit_core::heightfield::HeightField;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::trace::{Ray, Surface, TraceParams, trace};
use scene::{Method, SceneOptions};

/// Bevy's parallax against bevy_pomkit: frame times, accuracy and fetches.
#[derive(Parser)]
struct Args {
    /// Frames timed per method.
    #[arg(long, default_value_t = 15)]
    frames: usize,
    /// Height pattern of the accuracy quad and the scene.
    #[arg(long, default_value = "cobblestones")]
    pattern: String,
    /// Skip the frame times (accuracy and fetches only).
    #[arg(long)]
    no_timing: bool,
    /// Skip the accuracy probe (frame times only).
    #[arg(long)]
    no_accuracy: bool,
    /// pomkit's self-shadow mode in the timed scene: none, hard, soft, exact or depth.
    #[arg(long, default_value = "soft")]
    shadow: String,
    /// Turn pomkit's pixel depth offset off in the timed scene.
    #[arg(long)]
    no_pixel_depth: bool,
    /// Trace in the directional light's shadow cascades too (`shadow_pixel_depth`).
    #[arg(long)]
    shadow_pixel_depth: bool,
    /// Methods to time (default all four): pom, exact, bevy-occlusion, bevy-relief,
    /// bevy-plain, or any pomkit technique. A pomkit method may carry its own settings,
    /// METHOD:SHADOW:PDO (PDO camera, off or shadow-maps), e.g. pom:none:off,pom:soft:camera.
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// Time every method this many times, in turn (a process per method and round), and
    /// report the median of each method's round medians: the machine's drift over a run then
    /// falls on every method alike.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    rounds: u32,
    /// Time the one method given and print its row only (each method is timed in a process of
    /// its own: Bevy apps made one after another in a process slow down).
    #[arg(long, hide = true)]
    child: bool,
}

/// A method to time with its settings: `METHOD[:SHADOW[:PDO]]`, the command line's where left
/// out.
struct Timed {
    method: Method,
    shadow: String,
    no_pixel_depth: bool,
    shadow_pixel_depth: bool,
}

impl Timed {
    fn parse(spec: &str, args: &Args) -> Result<Self, String> {
        let mut parts = spec.split(':');
        let method = Method::parse(parts.next().unwrap_or(spec))?;
        let shadow = parts.next().unwrap_or(&args.shadow).to_owned();
        shadow.parse::<ShadowMode>().map_err(|e| format!("{spec}: {e}"))?;
        let (no_pixel_depth, shadow_pixel_depth) = match parts.next() {
            None => (args.no_pixel_depth, args.shadow_pixel_depth),
            Some("off") => (true, false),
            Some("camera") => (false, false),
            Some("shadow-maps") => (false, true),
            Some(other) => return Err(format!("{spec}: depth offset '{other}': expected camera, off or shadow-maps")),
        };
        Ok(Self { method, shadow, no_pixel_depth, shadow_pixel_depth })
    }
}

const MAP: u32 = 256;
const DEPTH_SCALE: f32 = 0.08;
/// Bevy's layer count for both of its methods, as pom's most samples.
const LAYERS: f32 = 32.0;
const RELIEF_STEPS: u32 = 5;
const PW: u32 = 320;
const PH: u32 = 240;

fn methods() -> [Method; 4] {
    [
        Method::Bevy(ParallaxMappingMethod::Occlusion),
        Method::Bevy(ParallaxMappingMethod::Relief { max_steps: RELIEF_STEPS }),
        Method::Pomkit(Technique::Pom),
        Method::Pomkit(Technique::Exact),
    ]
}

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let args = Args::parse();
    let pattern: Pattern = match args.pattern.parse() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let shadow: ShadowMode = match args.shadow.parse() {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: --shadow: {e}");
            std::process::exit(2);
        }
    };
    let specs: Vec<String> =
        if args.methods.is_empty() { methods().iter().map(|m| m.name()).collect() } else { args.methods.clone() };
    let timed: Vec<Timed> = match specs.iter().map(|spec| Timed::parse(spec, &args)).collect() {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: --methods: {e}");
            std::process::exit(2);
        }
    };
    if args.child {
        for Timed { method, .. } in timed {
            let opts = SceneOptions {
                method,
                pattern,
                shadow,
                pixel_depth: !args.no_pixel_depth,
                shadow_pixel_depth: args.shadow_pixel_depth,
                ..Default::default()
            };
            let ms = frame_time(&opts, args.frames);
            let pdo = match (args.no_pixel_depth, args.shadow_pixel_depth) {
                (true, _) => "off",
                (false, false) => "camera",
                (false, true) => "camera and shadow maps",
            };
            let (sh, pdo) = match method {
                Method::Pomkit(_) => (shadow.name(), pdo),
                Method::Bevy(_) | Method::Plain => ("-", "-"),
            };
            println!("| {} | {ms:.1} | {sh} | {pdo} |", method.name());
        }
        return;
    }
    if !args.no_timing {
        time_methods(&timed, &args);
    }
    if args.no_accuracy {
        return;
    }
    let field = generate(pattern, MAP, MAP);
    let surface = Surface::new(field.clone(), EdgeMode::Wrap, DEPTH_SCALE);
    println!(
        "| method | tangent w | median error (texels) | p99 | max | over 0.5 texel | over 1 texel | mean fetches | max fetches |"
    );
    println!("|---|---|--:|--:|--:|--:|--:|--:|--:|");
    for flipped in [false, true] {
        for method in methods() {
            let r = accuracy(method, &field, &surface, flipped);
            println!(
                "| {} | {} | {:.3} | {:.3} | {:.2} | {:.2}% | {:.2}% | {:.1} | {} |",
                method.name(),
                if flipped { "-1" } else { "+1" },
                r.median,
                r.p99,
                r.max,
                r.over_half * 100.0,
                r.over_one * 100.0,
                r.mean_fetches,
                r.max_fetches
            );
        }
    }
}

/// Times each of `timed` in a process of its own (this program again, with `--child`),
/// `--rounds` times in turn, and prints the frame-time table: per method, the median of its
/// round medians (with the rounds' medians when there are several).
fn time_methods(timed: &[Timed], args: &Args) {
    // Per method, per round: the child's row cells after the name (median, shadows, offset), or
    // why it failed.
    let mut rows: Vec<Vec<Result<Vec<String>, String>>> = timed.iter().map(|_| Vec::new()).collect();
    for _ in 0..args.rounds {
        for (t, row) in timed.iter().zip(&mut rows) {
            let mut child = std::process::Command::new(std::env::current_exe().expect("the running program"));
            child.args([
                "--child",
                "--no-accuracy",
                "--methods",
                &t.method.name(),
                "--frames",
                &args.frames.to_string(),
            ]);
            child.args(["--pattern", &args.pattern, "--shadow", &t.shadow]);
            if t.no_pixel_depth {
                child.arg("--no-pixel-depth");
            }
            if t.shadow_pixel_depth {
                child.arg("--shadow-pixel-depth");
            }
            row.push(match child.stderr(std::process::Stdio::null()).output() {
                Ok(out) if out.status.success() => {
                    // `| name | ms | shadows | offset |`
                    let line = String::from_utf8_lossy(&out.stdout).into_owned();
                    let cells: Vec<String> =
                        line.trim().trim_matches('|').split('|').map(|c| c.trim().to_owned()).collect();
                    if cells.len() == 4 && cells[1].parse::<f64>().is_ok() {
                        Ok(cells[1..].to_vec())
                    } else {
                        Err(format!("unexpected output {line:?}"))
                    }
                }
                Ok(out) => Err(out.status.to_string()),
                Err(e) => Err(e.to_string()),
            });
        }
    }
    let rounds = args.rounds;
    if rounds == 1 {
        println!("| method | frame time, median of {} (ms) | pomkit self-shadows | pixel depth offset |", args.frames);
        println!("|---|--:|---|---|");
    } else {
        println!(
            "| method | frame time, median of {rounds} rounds' medians of {} frames (ms) | pomkit self-shadows | pixel depth offset | each round (ms) |",
            args.frames
        );
        println!("|---|--:|---|---|---|");
    }
    for (t, row) in timed.iter().zip(&rows) {
        let name = t.method.name();
        let failure = row.iter().find_map(|r| r.as_ref().err());
        let ok: Vec<&Vec<String>> = row.iter().filter_map(|r| r.as_ref().ok()).collect();
        let (Some(first), None) = (ok.first(), failure) else {
            let why = failure.map_or("no round ran", String::as_str);
            println!("| {name} | failed ({why}) | | |{}", if rounds == 1 { "" } else { " |" });
            continue;
        };
        let mut ms: Vec<f64> = ok.iter().filter_map(|c| c[0].parse().ok()).collect();
        let each = ms.iter().map(|m| format!("{m:.1}")).collect::<Vec<_>>().join(", ");
        ms.sort_by(f64::total_cmp);
        let half = ms.len() / 2;
        let median = if ms.len() % 2 == 1 { ms[half] } else { 0.5 * (ms[half - 1] + ms[half]) };
        if rounds == 1 {
            println!("| {name} | {median:.1} | {} | {} |", first[1], first[2]);
        } else {
            println!("| {name} | {median:.1} | {} | {} | {each} |", first[1], first[2]);
        }
    }
    println!();
}

/// The median time of `frames` frames of the demo scene with `opts` at 960 x 540.
fn frame_time(opts: &SceneOptions, frames: usize) -> f64 {
    let mut app = Headless::new(960, 540);
    let target = RenderTarget::Image(app.target().into());
    scene::spawn(app.world(), Some(target), opts);
    if let Some(h) = app.world().get_resource::<scene::SceneHandles>().and_then(|h| h.standard.clone())
        && let Some(mut m) = app.world().resource_mut::<Assets<StandardMaterial>>().get_mut(&h)
    {
        m.max_parallax_layer_count = LAYERS;
    }
    app.frame(Duration::from_secs(600)).expect("the scene renders");
    let mut times = Vec::with_capacity(frames);
    for _ in 0..frames {
        let t = Instant::now();
        app.update();
        times.push(t.elapsed().as_secs_f64() * 1000.0);
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// A half-float image whose texel centres hold their own UV: sampled bilinearly at `uv`, it
/// returns `uv` (away from the tile's edges).
fn uv_image(n: u32) -> Image {
    let mut data = Vec::with_capacity((n * n * 8) as usize);
    for y in 0..n {
        for x in 0..n {
            let (u, v) = ((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
            for c in [u, v, 0.0, 1.0] {
                data.extend_from_slice(&pomkit_gpu::util::f32_to_f16(c).to_le_bytes());
            }
        }
    }
    scene::repeating_image(n, n, data, TextureFormat::Rgba16Float)
}

struct Accuracy {
    median: f32,
    p99: f32,
    max: f32,
    over_half: f32,
    over_one: f32,
    mean_fetches: f32,
    max_fetches: u32,
}

/// Renders the probe quad with `method` and compares each pixel's hit UV with pomkit-core's
/// exact tracer.
fn accuracy(method: Method, field: &HeightField, surface: &Surface, flipped: bool) -> Accuracy {
    let mut app = Headless::new(PW, PH);
    let tangents = if flipped { probe::Tangents::Flipped } else { probe::Tangents::Imported };
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(probe::quad(tangents));
    let camera_at = Transform::from_xyz(0.0, 1.2, 1.4).looking_at(Vec3::new(0.0, -0.2, -0.2), Vec3::Y);
    let target = RenderTarget::Image(app.target().into());
    let camera = app.world().spawn((Camera3d::default(), Hdr, Tonemapping::None, Msaa::Off, camera_at, target)).id();
    let depth_map = app.world().resource_mut::<Assets<Image>>().add(scene::bevy_depth_map_of(field));
    let uvs = app.world().resource_mut::<Assets<Image>>().add(uv_image(1024));
    let mut fetch_frame = None;
    match method {
        Method::Bevy(_) | Method::Plain => {
            let parallax = match method {
                Method::Bevy(m) => StandardMaterial {
                    depth_map: Some(depth_map),
                    parallax_depth_scale: DEPTH_SCALE,
                    parallax_mapping_method: m,
                    max_parallax_layer_count: LAYERS,
                    ..default()
                },
                _ => StandardMaterial::default(),
            };
            let material = app.world().resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
                base_color_texture: Some(uvs),
                unlit: true,
                ..parallax
            });
            app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
        }
        Method::Pomkit(t) => {
            let heights = app.world().resource_mut::<Assets<Image>>().add(depth_image(field));
            let mut ext = Pomkit::new(heights).with_technique(t).with_depth_scale(DEPTH_SCALE);
            ext.map_kind = MapKind::Depth;
            ext.lod_threshold = f32::MAX;
            ext.debug = PomkitDebug::Fetches;
            let material = app
                .world()
                .resource_mut::<Assets<PomkitMaterial>>()
                .add(PomkitMaterial { base: default(), extension: ext });
            app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
            fetch_frame = Some(app.frame(Duration::from_secs(600)).expect("the probe renders"));
            if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
                m.extension.debug = PomkitDebug::HitUv;
            }
        }
    }
    let frame = app.frame(Duration::from_secs(600)).expect("the probe renders");
    let world = app.world();
    let (cam, gt) = world.query::<(&Camera, &GlobalTransform)>().get(world, camera).expect("camera");
    let n = MAP as f32;
    let mut errors = Vec::new();
    let mut fetches = Vec::new();
    for y in 0..PH {
        for x in 0..PW {
            let Ok(ray) = cam.viewport_to_world(gt, Vec2::new(x as f32 + 0.5, y as f32 + 0.5)) else { continue };
            let d = ray.direction.as_vec3();
            let Some(p) = probe::hit_plane(ray, 0.0) else { continue };
            let uv0 = probe::quad_uv(p);
            if uv0.min_element() < 0.02 || uv0.max_element() > 0.98 {
                continue;
            }
            let dir = pomkit_core::glam::Vec3::new(d.x, d.z, d.y).normalize();
            let start = pomkit_core::glam::Vec2::new(uv0.x, uv0.y);
            let params = TraceParams::default();
            let truth = trace(surface, &Ray::new(start, dir), Technique::Exact, &params).uv;
            let got = pixel(&frame, x, y);
            // Bevy's probe reads a repeating texture: compare within the tile, and skip hits
            // within a texel of the tile's edge, where the UV texture's filter wraps.
            let wrap = |a: f32| a - a.floor();
            let (tu, tv) = (wrap(truth.x), wrap(truth.y));
            let edge = 1.5 / 1024.0;
            if tu.min(tv) < edge || tu.max(tv) > 1.0 - edge {
                continue;
            }
            let du = (wrap(got.x) - tu).abs();
            let dv = (wrap(got.y) - tv).abs();
            let err = Vec2::new(du.min(1.0 - du), dv.min(1.0 - dv)).length() * n;
            errors.push(err);
            fetches.push(match (method, &fetch_frame) {
                (Method::Pomkit(_), Some(f)) => (f.at(x, y)[0] * 64.0).round() as u32,
                (Method::Bevy(m), _) => bevy_fetches(field, uv0, Vec3::new(d.x, d.z, d.y), m, flipped),
                _ => 0,
            });
        }
    }
    errors.sort_by(f32::total_cmp);
    let q = |p: f32| errors[((errors.len() - 1) as f32 * p) as usize];
    Accuracy {
        median: q(0.5),
        p99: q(0.99),
        max: q(1.0),
        over_half: errors.iter().filter(|&&e| e > 0.5).count() as f32 / errors.len() as f32,
        over_one: errors.iter().filter(|&&e| e > 1.0).count() as f32 / errors.len() as f32,
        mean_fetches: fetches.iter().sum::<u32>() as f32 / fetches.len().max(1) as f32,
        max_fetches: fetches.iter().copied().max().unwrap_or(0),
    }
}

fn pixel(frame: &Frame, x: u32, y: u32) -> Vec2 {
    let p = frame.at(x, y);
    Vec2::new(p[0], p[1])
}

/// Height reads Bevy's parallax loop makes for one ray (its shader, `parallaxed_uv`, replayed):
/// one before the layer loop, one per layer stepped, then one for Occlusion's interpolation or
/// `max_steps` for Relief's binary search. `dir` is the eye-to-point direction in (u, v, up)
/// terms; with `flipped` tangents (w = -1) Bevy's bitangent points down the image, so its steps
/// go the other way in v (which changes the count, as it changes the hit).
fn bevy_fetches(field: &HeightField, uv0: Vec2, dir: Vec3, method: ParallaxMappingMethod, flipped: bool) -> u32 {
    // Bevy's Vt is the point-to-eye vector in (T, B, N); it steps by -Vt.xy * (1, -1).
    let to_eye = -dir.normalize();
    let vt = Vec3::new(to_eye.x, if flipped { to_eye.y } else { -to_eye.y }, to_eye.z);
    let steepness = vt.z.abs();
    let layers = LAYERS + (1.0 - LAYERS) * steepness;
    let layer_depth = 1.0 / layers;
    let delta = -vt.truncate() * Vec2::new(1.0, -1.0) * DEPTH_SCALE * layer_depth / steepness;
    let sample = |uv: Vec2| field.sample_bilinear(pomkit_core::glam::Vec2::new(uv.x, uv.y), EdgeMode::Wrap);
    let mut uv = uv0;
    let mut current = 0.0;
    let mut depth = sample(uv);
    let mut reads = 1;
    let mut i = 0;
    while depth > current && i as f32 <= layers.floor() {
        current += layer_depth;
        uv += delta;
        depth = sample(uv);
        reads += 1;
        i += 1;
    }
    reads
        + match method {
            ParallaxMappingMethod::Occlusion => 1,
            ParallaxMappingMethod::Relief { max_steps } => max_steps,
        }
}
