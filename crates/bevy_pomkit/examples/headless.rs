//! One frame of the demo scene rendered by Bevy with no window (it runs on Mesa's software
//! Vulkan, lavapipe), written to a PNG:
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example headless -- --technique exact -o exact.png
//! ```
//!
//! Techniques are named as everywhere in pomkit (`pom`, `relief`, `exact`, ...); `bevy-occlusion`
//! and `bevy-relief` draw the same scene with Bevy's own parallax mapping.

#[path = "support/headless.rs"]
mod headless;
#[path = "support/scene.rs"]
mod scene;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use bevy::camera::RenderTarget;
use clap::Parser;
use pomkit_core::procedural::Pattern;

/// Renders bevy_pomkit's demo scene to a PNG without a window.
#[derive(Parser)]
struct Args {
    /// pomkit technique (flat, normal, parallax, iterative, steep, pom-classic, pom, relief,
    /// exact) or bevy-occlusion / bevy-relief.
    #[arg(long, default_value = "pom")]
    technique: String,
    /// Self-shadow mode: none, hard, soft, exact or depth.
    #[arg(long, default_value = "soft")]
    shadow: String,
    /// Height pattern: bricks, pyramids, cobblestones, text, spike, waves, fur, grass.
    #[arg(long, default_value = "cobblestones")]
    pattern: String,
    /// Depth scale (UV units of one tile).
    #[arg(long, default_value_t = 0.08)]
    depth_scale: f32,
    /// Turn pixel depth offset off.
    #[arg(long)]
    no_pixel_depth: bool,
    /// Image width.
    #[arg(long, default_value_t = 960)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 540)]
    height: u32,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> ExitCode {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let args = Args::parse();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    let method = scene::Method::parse(&args.technique)?;
    let shadow: bevy_pomkit::ShadowMode = args.shadow.parse().map_err(|e| format!("--shadow: {e}"))?;
    let pattern: Pattern = args.pattern.parse().map_err(|e| format!("--pattern: {e}"))?;
    if !(args.depth_scale.is_finite() && args.depth_scale > 0.0) {
        return Err(format!("--depth-scale {}: it must be a finite number above 0", args.depth_scale));
    }
    if args.width == 0 || args.height == 0 || args.width > 8192 || args.height > 8192 {
        return Err(format!("--width {} --height {}: each must be 1 to 8192", args.width, args.height));
    }
    let opts = scene::SceneOptions {
        method,
        shadow,
        pattern,
        depth_scale: args.depth_scale,
        pixel_depth: !args.no_pixel_depth,
        ..Default::default()
    };
    let mut app = headless::Headless::new(args.width, args.height);
    let target = RenderTarget::Image(app.target().into());
    scene::spawn(app.world(), Some(target), &opts);
    let frame = app.frame(Duration::from_secs(600)).map_err(|e| e.to_string())?;
    let png = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8())
        .ok_or("the frame's size does not match its pixels")?;
    let tmp = args.output.with_extension("png.tmp");
    png.save_with_format(&tmp, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", args.output.display()))?;
    std::fs::rename(&tmp, &args.output).map_err(|e| format!("{}: {e}", args.output.display()))?;
    println!("wrote {} ({}x{}, {})", args.output.display(), frame.width, frame.height, method.name());
    Ok(())
}
