//! McGuire and McGuire 2005's fur and grass (docs/REFERENCES.md) in Bevy: a furry ball on a
//! lawn, the scene of examples/scenes/fur.toml (steep parallax with 32 samples over the
//! procedural fur and grass height maps, depth self-shadows), with the LOD fade fading to the
//! strands' tips' colour (`Pomkit::far_color`).
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example fur
//! cargo run --release -p bevy_pomkit --example fur -- --supersample 2 -o bevy_fur.png
//! ```
//!
//! In the window the ball turns slowly. Keys: F the far colour on / off, Up / Down the camera
//! nearer / farther, Space stop / start the ball. The title shows the settings and the frame
//! time. With `-o FILE` one frame is written to a PNG without a window (`--width`,
//! `--height`, `--supersample`); both take `--distance` to pull the camera back,
//! `--no-far-color`, `--no-shadow-maps` and `--debug hit-uv|fetches|shadow`.

#[path = "support/fur.rs"]
mod fur;
#[path = "support/headless.rs"]
mod headless;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use bevy::camera::RenderTarget;
use bevy::diagnostic::{DiagnosticsStore, FrameTimeDiagnosticsPlugin};
use bevy::prelude::*;
use bevy_pomkit::{PomkitDebug, PomkitMaterial, PomkitPlugin};
use clap::Parser;
use fur::{FurHandles, FurOptions};

/// A furry ball on a lawn, drawn by bevy_pomkit.
#[derive(Parser)]
struct Args {
    /// Write one frame to this PNG without a window.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Image width (with `-o`).
    #[arg(long, default_value_t = 640)]
    width: u32,
    /// Image height (with `-o`).
    #[arg(long, default_value_t = 360)]
    height: u32,
    /// Render `N` x `N` samples per pixel and average them (with `-o`), as pomkit's
    /// `render --supersample`.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4))]
    supersample: u32,
    /// The camera's distance from the point it looks at, as a multiple of the scene's.
    #[arg(long, default_value_t = 1.0)]
    distance: f32,
    /// Fade to the entry point's texture in the LOD band instead of the strands' tips' colour.
    #[arg(long)]
    no_far_color: bool,
    /// No shadow maps from the sun (pomkit's own renderers cast no shadows between objects).
    #[arg(long)]
    no_shadow_maps: bool,
    /// Debug view: off, hit-uv, fetches or shadow.
    #[arg(long, default_value = "off")]
    debug: String,
}

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> ExitCode {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let args = Args::parse();
    let result = if args.output.is_some() { picture(&args) } else { window(&args) };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The scene's options and camera for `args`.
fn options(args: &Args, scene: &pomkit_core::scene::Scene) -> Result<FurOptions, String> {
    if !(args.distance.is_finite() && args.distance > 0.0 && args.distance <= 100.0) {
        return Err(format!("--distance {}: it must be above 0 and at most 100", args.distance));
    }
    let target = Vec3::new(scene.camera.target.x, scene.camera.target.y, scene.camera.target.z);
    let mut camera = fur::camera_transform(scene);
    camera.translation = target + (camera.translation - target) * args.distance;
    let debug = match args.debug.as_str() {
        "off" => PomkitDebug::Off,
        "hit-uv" => PomkitDebug::HitUv,
        "fetches" => PomkitDebug::Fetches,
        "shadow" => PomkitDebug::Shadow,
        other => return Err(format!("--debug {other}: one of off, hit-uv, fetches, shadow")),
    };
    Ok(FurOptions {
        far_color: !args.no_far_color,
        shadow_maps: !args.no_shadow_maps,
        debug,
        camera: Some(camera),
        ..default()
    })
}

/// One frame to a PNG.
fn picture(args: &Args) -> Result<(), String> {
    let output = args.output.as_ref().ok_or("no output")?;
    if args.width == 0 || args.height == 0 || args.width > 8192 || args.height > 8192 {
        return Err(format!("--width {} --height {}: each must be 1 to 8192", args.width, args.height));
    }
    let scene = fur::load_scene()?;
    let opts = options(args, &scene)?;
    let ss = args.supersample;
    let mut app = headless::Headless::new(args.width * ss, args.height * ss);
    let target = RenderTarget::Image(app.target().into());
    fur::spawn(app.world(), &scene, Some(target), &opts);
    let frame = downsample(&app.frame(Duration::from_secs(600)).map_err(|e| e.to_string())?, ss);
    let png = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8())
        .ok_or("the frame's size does not match its pixels")?;
    let tmp = output.with_extension("png.tmp");
    png.save_with_format(&tmp, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", output.display()))?;
    std::fs::rename(&tmp, output).map_err(|e| format!("{}: {e}", output.display()))?;
    println!("wrote {} ({}x{})", output.display(), frame.width, frame.height);
    Ok(())
}

/// `frame` with each `k` x `k` block of pixels averaged (in linear colour) into one.
fn downsample(frame: &headless::Frame, k: u32) -> headless::Frame {
    let (w, h) = (frame.width / k, frame.height / k);
    let mut pixels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let mut sum = [0.0f32; 4];
            for sy in 0..k {
                for sx in 0..k {
                    let p = frame.at(x * k + sx, y * k + sy);
                    for c in 0..4 {
                        sum[c] += p[c];
                    }
                }
            }
            pixels.push(sum.map(|v| v / (k * k) as f32));
        }
    }
    headless::Frame { width: w, height: h, pixels }
}

/// What the keys have chosen.
#[derive(Resource)]
struct State {
    far_color: bool,
    turning: bool,
    /// The point the camera looks at.
    target: Vec3,
}

/// The scene in a window.
fn window(args: &Args) -> Result<(), String> {
    let scene = fur::load_scene()?;
    let opts = options(args, &scene)?;
    let target = Vec3::new(scene.camera.target.x, scene.camera.target.y, scene.camera.target.z);
    App::new()
        .add_plugins((
            DefaultPlugins.set(WindowPlugin {
                primary_window: Some(Window { title: "bevy_pomkit: fur".into(), ..default() }),
                ..default()
            }),
            PomkitPlugin,
            FrameTimeDiagnosticsPlugin::default(),
        ))
        .insert_resource(State { far_color: opts.far_color, turning: true, target })
        .add_systems(Startup, move |world: &mut World| {
            fur::spawn(world, &scene, None, &opts);
        })
        .add_systems(Update, (keys, turn, title))
        .run();
    Ok(())
}

fn keys(
    input: Res<ButtonInput<KeyCode>>,
    time: Res<Time>,
    mut state: ResMut<State>,
    handles: Res<FurHandles>,
    mut materials: ResMut<Assets<PomkitMaterial>>,
    mut cameras: Query<&mut Transform, With<Camera3d>>,
) {
    if input.just_pressed(KeyCode::KeyF) {
        state.far_color = !state.far_color;
        for (handle, tips) in handles.materials.iter().zip(&handles.tips) {
            if let Some(mut m) = materials.get_mut(handle) {
                m.extension.far_color = tips.filter(|_| state.far_color).map(|t| Color::linear_rgb(t.x, t.y, t.z));
            }
        }
    }
    if input.just_pressed(KeyCode::Space) {
        state.turning = !state.turning;
    }
    let zoom = match (input.pressed(KeyCode::ArrowUp), input.pressed(KeyCode::ArrowDown)) {
        (true, false) => -1.0,
        (false, true) => 1.0,
        _ => 0.0,
    };
    if zoom != 0.0 {
        for mut t in &mut cameras {
            let offset = t.translation - state.target;
            let d = (offset.length() * (1.0 + zoom * time.delta_secs())).clamp(1.0, 60.0);
            t.translation = state.target + offset.normalize_or_zero() * d;
        }
    }
}

/// Turns the ball (the scene's first object) slowly about the vertical.
fn turn(time: Res<Time>, state: Res<State>, handles: Res<FurHandles>, mut transforms: Query<&mut Transform>) {
    if !state.turning {
        return;
    }
    if let Some(&ball) = handles.objects.first()
        && let Ok(mut t) = transforms.get_mut(ball)
    {
        t.rotate_y(0.15 * time.delta_secs());
    }
}

fn title(
    state: Res<State>,
    diagnostics: Res<DiagnosticsStore>,
    cameras: Query<&Transform, With<Camera3d>>,
    mut windows: Query<&mut Window>,
) {
    let ms = diagnostics
        .get(&FrameTimeDiagnosticsPlugin::FRAME_TIME)
        .and_then(bevy::diagnostic::Diagnostic::smoothed)
        .unwrap_or(0.0);
    let distance = cameras.iter().next().map_or(0.0, |t| (t.translation - state.target).length());
    let far = if state.far_color { "tips' colour" } else { "entry texture" };
    let text = format!("bevy_pomkit: fur | LOD fade to {far} (F) | distance {distance:.1} (Up/Down) | {ms:.1} ms");
    for mut w in &mut windows {
        if w.title != text {
            w.title.clone_from(&text);
        }
    }
}
