//! One frame of the demo scene rendered by Bevy with no window (it runs on Mesa's software
//! Vulkan, lavapipe), written to a PNG:
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example headless -- --technique exact -o exact.png
//! ```
//!
//! Techniques are named as everywhere in pomkit (`pom`, `relief`, `exact`, ...); `bevy-occlusion`
//! and `bevy-relief` draw the same scene with Bevy's own parallax mapping.
//!
//! With `--gltf FILE` it draws the first scene of a glTF file instead, its materials with
//! `KHR_materials_displacement` or pomkit extras traced by bevy_pomkit (feature `gltf`), seen
//! from the file's camera and lit by its lights (without them, a camera framing the scene and a
//! sun); `--technique`, `--shadow` and `--depth-scale`, when given, override every traced
//! material's:
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example headless -- --gltf scene.gltf --technique relief -o relief.png
//! ```
//!
//! `--silhouette` turns on silhouettes (`Pomkit::silhouette`) for every traced material;
//! `--spheres` draws pomkit's cobblestone sphere twice instead of the demo scene, on the left
//! without silhouettes and on the right with them:
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example headless -- --spheres --width 640 --height 300 -o spheres.png
//! ```

#[cfg(feature = "gltf")]
#[path = "support/gltf.rs"]
mod gltf;
#[path = "support/headless.rs"]
mod headless;
#[path = "support/scene.rs"]
mod scene;
#[path = "support/sphere.rs"]
mod sphere;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use bevy::camera::RenderTarget;
use bevy::prelude::*;
use bevy_pomkit::PomkitMaterial;
use clap::Parser;
use pomkit_core::procedural::Pattern;

/// Renders bevy_pomkit's demo scene to a PNG without a window.
#[derive(Parser)]
struct Args {
    /// pomkit technique (flat, normal, parallax, iterative, steep, pom-classic, pom, relief,
    /// exact, cone) or bevy-occlusion / bevy-relief [default: exact; with --gltf, the file's].
    #[arg(long)]
    technique: Option<String>,
    /// Self-shadow mode: none, hard, soft, exact or depth [default: soft; with --gltf, the
    /// file's].
    #[arg(long)]
    shadow: Option<String>,
    /// Height pattern: bricks, pyramids, cobblestones, text, spike, waves, fur, grass.
    #[arg(long, default_value = "cobblestones")]
    pattern: String,
    /// Depth scale (UV units of one tile) [default: 0.08; with --gltf, the file's].
    #[arg(long)]
    depth_scale: Option<f32>,
    /// Draw the first scene of this glTF file (.gltf or .glb) instead of the demo scene.
    #[arg(long, value_name = "FILE")]
    gltf: Option<PathBuf>,
    /// Turn pixel depth offset off.
    #[arg(long)]
    no_pixel_depth: bool,
    /// Silhouettes: bumpy outlines on curved meshes.
    #[arg(long)]
    silhouette: bool,
    /// Draw pomkit's cobblestone sphere twice, without silhouettes (left) and with them
    /// (right), instead of the demo scene.
    #[arg(long, conflicts_with = "gltf")]
    spheres: bool,
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
    if args.width == 0 || args.height == 0 || args.width > 8192 || args.height > 8192 {
        return Err(format!("--width {} --height {}: each must be 1 to 8192", args.width, args.height));
    }
    if let Some(d) = args.depth_scale
        && !(d.is_finite() && d > 0.0)
    {
        return Err(format!("--depth-scale {d}: it must be a finite number above 0"));
    }
    let shadow: Option<bevy_pomkit::ShadowMode> =
        args.shadow.as_deref().map(str::parse).transpose().map_err(|e| format!("--shadow: {e}"))?;
    let (mut app, name) = match &args.gltf {
        Some(file) => gltf_scene(args, file, shadow)?,
        None if args.spheres => spheres_scene(args, shadow)?,
        None => demo_scene(args, shadow)?,
    };
    let frame = app.frame(Duration::from_secs(600)).map_err(|e| e.to_string())?;
    let png = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8())
        .ok_or("the frame's size does not match its pixels")?;
    let tmp = args.output.with_extension("png.tmp");
    png.save_with_format(&tmp, image::ImageFormat::Png).map_err(|e| format!("{}: {e}", args.output.display()))?;
    std::fs::rename(&tmp, &args.output).map_err(|e| format!("{}: {e}", args.output.display()))?;
    println!("wrote {} ({}x{}, {name})", args.output.display(), frame.width, frame.height);
    Ok(())
}

/// The demo scene, as the arguments set it up.
fn demo_scene(args: &Args, shadow: Option<bevy_pomkit::ShadowMode>) -> Result<(headless::Headless, String), String> {
    let method = scene::Method::parse(args.technique.as_deref().unwrap_or("exact"))?;
    let pattern: Pattern = args.pattern.parse().map_err(|e| format!("--pattern: {e}"))?;
    let opts = scene::SceneOptions {
        method,
        shadow: shadow.unwrap_or(bevy_pomkit::ShadowMode::Soft),
        pattern,
        depth_scale: args.depth_scale.unwrap_or(0.08),
        pixel_depth: !args.no_pixel_depth,
        ..Default::default()
    };
    let mut app = headless::Headless::new(args.width, args.height);
    let target = RenderTarget::Image(app.target().into());
    scene::spawn(app.world(), Some(target), &opts);
    // The cube's and the floor's material.
    let mut materials = app.world().resource_mut::<Assets<PomkitMaterial>>();
    let ids: Vec<_> = materials.ids().collect();
    for id in ids {
        if let Some(mut m) = materials.get_mut(id) {
            m.extension.silhouette = args.silhouette;
        }
    }
    Ok((app, method.name()))
}

/// pomkit's cobblestone sphere (the silhouette tests' unit sphere, depth scale 0.04 unless
/// `--depth-scale`), twice: without silhouettes on the left, with them on the right, lit by a
/// sun on a grey background.
fn spheres_scene(args: &Args, shadow: Option<bevy_pomkit::ShadowMode>) -> Result<(headless::Headless, String), String> {
    let technique: bevy_pomkit::Technique = match args.technique.as_deref() {
        None => bevy_pomkit::Technique::Exact,
        Some(t) => t.parse().map_err(|e| format!("--technique: {e} (with --spheres, a pomkit technique)"))?,
    };
    let pattern: Pattern = args.pattern.parse().map_err(|e| format!("--pattern: {e}"))?;
    let mut app = headless::Headless::new(args.width, args.height);
    let world = app.world();
    let size = 512;
    let albedo = world.resource_mut::<Assets<Image>>().add(scene::albedo_image(pattern, size));
    let heights = world
        .resource_mut::<Assets<Image>>()
        .add(bevy_pomkit::height::depth_image(&pomkit_core::procedural::generate(pattern, size, size)));
    let mesh = world.resource_mut::<Assets<Mesh>>().add(sphere::cobblestone_sphere());
    let base =
        StandardMaterial { base_color_texture: Some(albedo), perceptual_roughness: 0.8, reflectance: 0.3, ..default() };
    for (x, silhouette) in [(-1.15, false), (1.15, true)] {
        let mut ext = bevy_pomkit::Pomkit::new(heights.clone())
            .with_technique(technique)
            .with_shadow(shadow.unwrap_or(bevy_pomkit::ShadowMode::Soft))
            .with_depth_scale(args.depth_scale.unwrap_or(0.04))
            .with_silhouette(silhouette);
        ext.map_kind = bevy_pomkit::MapKind::Depth;
        ext.pixel_depth_offset = !args.no_pixel_depth;
        let material =
            world.resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial { base: base.clone(), extension: ext });
        world.spawn((Mesh3d(mesh.clone()), MeshMaterial3d(material), Transform::from_xyz(x, 0.0, 0.0)));
    }
    world.spawn((
        DirectionalLight { illuminance: 8000.0, ..default() },
        Transform::from_xyz(-2.0, 2.5, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    world.insert_resource(GlobalAmbientLight { brightness: 300.0, ..default() });
    world.insert_resource(ClearColor(Color::srgb(0.25, 0.27, 0.3)));
    let target = RenderTarget::Image(app.target().into());
    app.world().spawn((
        Camera3d::default(),
        Projection::Perspective(PerspectiveProjection { fov: 32f32.to_radians(), ..default() }),
        Transform::from_xyz(0.0, 0.6, 4.6).looking_at(Vec3::ZERO, Vec3::Y),
        bevy::core_pipeline::tonemapping::Tonemapping::AcesFitted,
        Msaa::Off,
        target,
    ));
    Ok((app, format!("{}, without and with silhouettes", technique.name())))
}

/// The first scene of a glTF file, with the arguments' overrides.
#[cfg(feature = "gltf")]
fn gltf_scene(
    args: &Args,
    file: &std::path::Path,
    shadow: Option<bevy_pomkit::ShadowMode>,
) -> Result<(headless::Headless, String), String> {
    let technique: Option<bevy_pomkit::Technique> = match args.technique.as_deref() {
        None => None,
        Some(t) => Some(t.parse().map_err(|e| format!("--technique: {e} (with --gltf, a pomkit technique)"))?),
    };
    // Bevy reads assets from its asset folder only: the file's folder becomes it.
    let path = std::fs::canonicalize(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let (Some(folder), Some(name)) = (path.parent(), path.file_name().and_then(|n| n.to_str())) else {
        return Err(format!("{}: not a file name Bevy can load", file.display()));
    };
    let mut app = headless::Headless::with_assets(args.width, args.height, Some(folder));
    let scene = gltf::spawn(app.world(), name);
    let start = std::time::Instant::now();
    loop {
        app.update();
        match gltf::progress(app.world(), &scene) {
            gltf::Progress::Spawned => break,
            gltf::Progress::Failed(e) => return Err(e),
            gltf::Progress::Loading if start.elapsed() > Duration::from_secs(120) => {
                return Err(format!("{}: its scene did not load within 120 s", file.display()));
            }
            gltf::Progress::Loading => {}
        }
    }
    // Global transforms of the new entities, for the default camera's framing.
    app.update();
    let target = RenderTarget::Image(app.target().into());
    gltf::finish(app.world(), Some(target));
    let mut materials = app.world().resource_mut::<Assets<PomkitMaterial>>();
    let ids: Vec<_> = materials.ids().collect();
    for id in &ids {
        let Some(mut m) = materials.get_mut(*id) else { continue };
        let e = &mut m.extension;
        if let Some(t) = technique {
            e.technique = t;
        }
        if let Some(s) = shadow {
            e.shadow.mode = s;
        }
        if let Some(d) = args.depth_scale {
            e.depth_scale = d;
        }
        e.pixel_depth_offset &= !args.no_pixel_depth;
        e.silhouette |= args.silhouette;
    }
    let what = match technique {
        Some(t) => t.name().to_owned(),
        None => format!("{} traced materials", ids.len()),
    };
    Ok((app, what))
}

/// Without the `gltf` feature there is no glTF loader.
#[cfg(not(feature = "gltf"))]
fn gltf_scene(
    _args: &Args,
    file: &std::path::Path,
    _shadow: Option<bevy_pomkit::ShadowMode>,
) -> Result<(headless::Headless, String), String> {
    Err(format!("{}: bevy_pomkit was built without its `gltf` feature", file.display()))
}
