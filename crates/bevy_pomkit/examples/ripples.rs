//! Rain on a pond: a height map that a compute shader of this example writes every frame
//! (`ripples.wgsl`: expanding, damped rings), built into pomkit's textures on the GPU in the
//! same frame (`HeightBuild::GpuEveryFrame`), traced with self-shadows from a low sun.
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example ripples
//! cargo run --release -p bevy_pomkit --example ripples -- --frames 90 -o ripples.png
//! cargo run --release -p bevy_pomkit --example ripples -- --rebuild-bench
//! ```
//!
//! The first opens a window (T switches `pom` / `exact`). The second renders without a window
//! (lavapipe will do): the rain runs `--frames` frames of 1/30 s, then stops, and that picture
//! is written. The third times the rebuild of a `--size` (default 1024) height map every frame,
//! on the GPU passes and on the CPU path (docs/BENCHMARKS.md).
//!
//! How the example's compute pass is ordered before the height build: its render-world system
//! runs in Bevy's `RenderGraph` schedule, in `RenderGraphSystems::Render`, `.before(GpuHeightPass)`,
//! and records into the frame's command encoder (`RenderContext`), so the GPU writes the heights
//! before bevy_pomkit's passes read them, and both before any camera draws.

#[path = "support/headless.rs"]
mod headless;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    BindGroupEntry, BindGroupLayout, BindGroupLayoutEntry, BindingResource, BindingType, Buffer, BufferBindingType,
    BufferDescriptor, BufferSize, BufferUsages, ComputePassDescriptor, ComputePipeline, Extent3d,
    PipelineCompilationOptions, PipelineLayoutDescriptor, PollType, RawComputePipelineDescriptor,
    ShaderModuleDescriptor, ShaderSource, ShaderStages, StorageTextureAccess, TextureDimension, TextureFormat,
    TextureUsages, TextureViewDescriptor, TextureViewDimension,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, RenderApp};
use bevy_pomkit::{GpuHeightPass, HeightBuild, Pomkit, PomkitMaterial, PomkitPlugin, ShadowMode, Technique};
use clap::Parser;

/// Rain on a pond, traced by bevy_pomkit from a height map written on the GPU every frame.
#[derive(Parser)]
struct Args {
    /// Render without a window: run the rain this many frames of 1/30 s, then write the picture.
    #[arg(long)]
    frames: Option<u32>,
    /// The PNG of the headless mode.
    #[arg(short, long, default_value = "ripples.png")]
    output: PathBuf,
    /// Side of the height map in texels.
    #[arg(long)]
    size: Option<u32>,
    /// pom or exact.
    #[arg(long, default_value = "pom")]
    technique: String,
    /// Picture width (headless).
    #[arg(long, default_value_t = 480)]
    width: u32,
    /// Picture height (headless).
    #[arg(long, default_value_t = 270)]
    height: u32,
    /// Time the rebuild of the height map every frame, GPU passes against the CPU path.
    #[arg(long)]
    rebuild_bench: bool,
}

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> ExitCode {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let args = Args::parse();
    let result = if args.rebuild_bench {
        rebuild_bench(&args)
    } else if let Some(frames) = args.frames {
        headless_picture(&args, frames)
    } else {
        window(&args)
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn technique(args: &Args) -> Result<Technique, String> {
    match args.technique.parse::<Technique>() {
        Ok(t @ (Technique::Pom | Technique::Exact)) => Ok(t),
        _ => Err(format!("--technique {}: use pom or exact", args.technique)),
    }
}

/// The rain's clock: seconds since it began, and whether it runs.
#[derive(Resource, Clone, Copy)]
struct Clock {
    time: f32,
    /// Fixed steps of 1/30 s (headless), or the app's time (window).
    fixed_step: bool,
    running: bool,
    /// Drops falling at once.
    drops: u32,
}

fn tick(mut clock: ResMut<Clock>, time: Res<Time>) {
    if clock.running {
        clock.time += if clock.fixed_step { 1.0 / 30.0 } else { time.delta_secs() };
    }
}

/// The storage texture the rain writes: `R32Float`, on the GPU only.
fn pond_texture(size: u32) -> Image {
    let mut image = Image::new_uninit(
        Extent3d { width: size, height: size, depth_or_array_layers: 1 },
        TextureDimension::D2,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage = TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING;
    image
}

/// The pond: a 2 x 2 plane of water traced from `heights`, a low sun and a camera.
fn spawn_pond(world: &mut World, heights: Handle<Image>, technique: Technique, build: HeightBuild) {
    let mesh = Mesh::from(Plane3d::default().mesh().size(2.0, 2.0)).with_generated_tangents();
    let Ok(mesh) = mesh else { return };
    let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
    let mut extension = Pomkit::new(heights)
        .with_technique(technique)
        .with_shadow(ShadowMode::Soft)
        .with_depth_scale(0.025)
        .with_height_build(build);
    extension.shadow.softness = 0.05;
    let base = StandardMaterial {
        base_color: Color::srgb(0.16, 0.36, 0.42),
        perceptual_roughness: 0.22,
        reflectance: 0.6,
        ..default()
    };
    let material = world.resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial { base, extension });
    world.spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    // A low sun ahead, to the left: each crest shadows the trough behind it, and the slopes
    // facing it glint.
    world.spawn((
        DirectionalLight { illuminance: 20000.0, shadow_maps_enabled: false, ..default() },
        Transform::default().looking_to(Vec3::new(0.55, -0.2, 0.8), Vec3::Y),
    ));
    world.insert_resource(GlobalAmbientLight { color: Color::srgb(0.7, 0.8, 1.0), brightness: 400.0, ..default() });
    world.insert_resource(ClearColor(Color::srgb(0.55, 0.62, 0.7)));
}

fn camera_transform() -> Transform {
    Transform::from_xyz(0.0, 1.05, 1.25).looking_at(Vec3::new(0.0, -0.05, -0.15), Vec3::Y)
}

/// The rain's compute pass in the render world (made on first use).
struct RainPipeline {
    layout: BindGroupLayout,
    pipeline: ComputePipeline,
    uniform: Buffer,
}

/// The render world's view of the rain: the texture it writes, the clock, the pipeline.
#[derive(Resource)]
struct Rain {
    target: AssetId<Image>,
    clock: Clock,
    pipeline: Option<RainPipeline>,
}

/// Adds the rain: the clock in the main world, the compute pass in the render world, ordered
/// before bevy_pomkit's height build.
fn add_rain(app: &mut App, target: AssetId<Image>, clock: Clock) {
    app.insert_resource(clock).add_systems(Update, tick);
    let render_app = app.sub_app_mut(RenderApp);
    render_app
        .insert_resource(Rain { target, clock, pipeline: None })
        .add_systems(ExtractSchedule, |clock: Extract<Res<Clock>>, mut rain: ResMut<Rain>| rain.clock = **clock)
        .add_systems(RenderGraph, write_rain.in_set(RenderGraphSystems::Render).before(GpuHeightPass));
}

/// Writes this frame's heights into the pond's storage texture.
fn write_rain(
    mut rain: ResMut<Rain>,
    images: Res<RenderAssets<GpuImage>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut ctx: RenderContext,
) {
    let Some(target) = images.get(rain.target) else { return };
    let size = target.texture_descriptor.size.width;
    let clock = rain.clock;
    let p = rain.pipeline.get_or_insert_with(|| rain_pipeline(&device));
    let words = [clock.time.to_bits(), size, clock.drops, 0];
    queue.write_buffer(&p.uniform, 0, &words.iter().flat_map(|w| w.to_le_bytes()).collect::<Vec<u8>>());
    let view = target.texture.create_view(&TextureViewDescriptor::default());
    let group = device.create_bind_group(
        "rain",
        &p.layout,
        &[
            BindGroupEntry { binding: 0, resource: BindingResource::TextureView(&view) },
            BindGroupEntry { binding: 1, resource: p.uniform.as_entire_binding() },
        ],
    );
    let mut pass = ctx
        .command_encoder()
        .begin_compute_pass(&ComputePassDescriptor { label: Some("rain"), timestamp_writes: None });
    pass.set_pipeline(&p.pipeline);
    pass.set_bind_group(0, &*group, &[]);
    pass.dispatch_workgroups(size.div_ceil(8), size.div_ceil(8), 1);
}

fn rain_pipeline(device: &RenderDevice) -> RainPipeline {
    let entries = [
        BindGroupLayoutEntry {
            binding: 0,
            visibility: ShaderStages::COMPUTE,
            ty: BindingType::StorageTexture {
                access: StorageTextureAccess::WriteOnly,
                format: TextureFormat::R32Float,
                view_dimension: TextureViewDimension::D2,
            },
            count: None,
        },
        BindGroupLayoutEntry {
            binding: 1,
            visibility: ShaderStages::COMPUTE,
            ty: BindingType::Buffer {
                ty: BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: BufferSize::new(16),
            },
            count: None,
        },
    ];
    let layout = device.create_bind_group_layout("rain", &entries);
    let module = device.create_and_validate_shader_module(ShaderModuleDescriptor {
        label: Some("ripples.wgsl"),
        source: ShaderSource::Wgsl(include_str!("ripples.wgsl").into()),
    });
    let pipeline_layout = device.create_pipeline_layout(&PipelineLayoutDescriptor {
        label: Some("rain"),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&RawComputePipelineDescriptor {
        label: Some("rain"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("rain_main"),
        compilation_options: PipelineCompilationOptions::default(),
        cache: None,
    });
    let uniform = device.create_buffer(&BufferDescriptor {
        label: Some("rain"),
        size: 16,
        usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    RainPipeline { layout, pipeline, uniform }
}

const DROPS: u32 = 14;

fn window(args: &Args) -> Result<(), String> {
    let technique = technique(args)?;
    let size = args.size.unwrap_or(512);
    let mut app = App::new();
    app.add_plugins((
        DefaultPlugins.set(WindowPlugin {
            primary_window: Some(Window { title: "bevy_pomkit: ripples (T: pom / exact)".into(), ..default() }),
            ..default()
        }),
        PomkitPlugin,
    ));
    let pond = app.world_mut().resource_mut::<Assets<Image>>().add(pond_texture(size));
    add_rain(&mut app, pond.id(), Clock { time: 0.0, fixed_step: false, running: true, drops: DROPS });
    spawn_pond(app.world_mut(), pond, technique, HeightBuild::GpuEveryFrame);
    app.world_mut().spawn((Camera3d::default(), Tonemapping::AcesFitted, camera_transform()));
    app.add_systems(Update, switch_technique);
    app.run();
    Ok(())
}

fn switch_technique(keys: Res<ButtonInput<KeyCode>>, mut materials: ResMut<Assets<PomkitMaterial>>) {
    if keys.just_pressed(KeyCode::KeyT) {
        for (_, m) in materials.iter_mut() {
            let e = &mut m.extension;
            e.technique = if e.technique == Technique::Pom { Technique::Exact } else { Technique::Pom };
        }
    }
}

fn headless_picture(args: &Args, frames: u32) -> Result<(), String> {
    if !(1..=4096).contains(&args.width) || !(1..=4096).contains(&args.height) {
        return Err(format!("--width {} --height {}: each must be 1 to 4096", args.width, args.height));
    }
    let technique = technique(args)?;
    let mut app = headless::Headless::new(args.width, args.height);
    let pond = app.world().resource_mut::<Assets<Image>>().add(pond_texture(args.size.unwrap_or(512)));
    add_rain(app.app(), pond.id(), Clock { time: 0.0, fixed_step: true, running: true, drops: DROPS });
    spawn_pond(app.world(), pond, technique, HeightBuild::GpuEveryFrame);
    let target = RenderTarget::Image(app.target().into());
    app.world().spawn((Camera3d::default(), Tonemapping::AcesFitted, camera_transform(), target));
    for _ in 0..frames {
        app.update();
    }
    // The rain stops; the picture settles.
    app.world().resource_mut::<Clock>().running = false;
    let frame = app.frame(Duration::from_secs(600)).map_err(|e| e.to_string())?;
    let reports = app.world().resource::<bevy_pomkit::HeightMaps>().reports();
    if !reports.is_empty() {
        return Err(format!("bevy_pomkit reported: {reports:?}"));
    }
    let png = image::RgbaImage::from_raw(frame.width, frame.height, frame.to_srgb8())
        .ok_or("the frame's size does not match its pixels")?;
    png.save_with_format(&args.output, image::ImageFormat::Png)
        .map_err(|e| format!("{}: {e}", args.output.display()))?;
    println!("wrote {} ({}x{}, {frames} frames of rain)", args.output.display(), frame.width, frame.height);
    Ok(())
}

/// Median frame time (update and GPU work done) of `frames` frames of `app`, after `warm_up`.
fn median_frame(app: &mut headless::Headless, warm_up: u32, frames: u32, mut each: impl FnMut(&mut World)) -> f64 {
    let mut times = Vec::new();
    for k in 0..warm_up + frames {
        let start = Instant::now();
        each(app.world());
        app.update();
        let device = app.app().sub_app(RenderApp).world().resource::<RenderDevice>().clone();
        let _ = device.poll(PollType::wait_indefinitely());
        if k >= warm_up {
            times.push(start.elapsed().as_secs_f64() * 1000.0);
        }
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Times the rebuild of a `size` x `size` height map every frame: the GPU passes (the pond's
/// storage texture written every frame, built every frame against built once) and the CPU path
/// (a main-world image changed every frame against left alone). Each figure is the difference
/// of the median frame times (the frame's own update and GPU work waited for) with and without.
fn rebuild_bench(args: &Args) -> Result<(), String> {
    let size = args.size.unwrap_or(1024);
    let technique = technique(args)?;
    let (warm_up, frames) = (5, 31);
    let (w, h) = (160, 90);
    let mut results = Vec::new();
    for (label, gpu, rebuild) in [
        ("GPU, built every frame", true, true),
        ("GPU, built once", true, false),
        ("CPU, built every frame", false, true),
        ("CPU, built once", false, false),
    ] {
        let mut app = headless::Headless::new(w, h);
        let target = RenderTarget::Image(app.target().into());
        app.world().spawn((Camera3d::default(), Tonemapping::AcesFitted, camera_transform(), target));
        let ms = if gpu {
            let pond = app.world().resource_mut::<Assets<Image>>().add(pond_texture(size));
            // No drops: the rain's pass writes still water, cheaply, so the frame is the build.
            add_rain(app.app(), pond.id(), Clock { time: 0.0, fixed_step: true, running: true, drops: 0 });
            let build = if rebuild { HeightBuild::GpuEveryFrame } else { HeightBuild::Gpu };
            spawn_pond(app.world(), pond, technique, build);
            median_frame(&mut app, warm_up, frames, |_| {})
        } else {
            // The same rain, on the CPU once; each frame one texel changes, so the whole map is
            // rebuilt (and its textures uploaded) as for any edit.
            let field = pomkit_core::HeightField::from_height_fn(size, size, |x, y| {
                let (u, v) = (x as f32 / size as f32, y as f32 / size as f32);
                0.5 + 0.2 * (40.0 * u).sin() * (33.0 * v).cos()
            });
            let mut image = bevy_pomkit::height::depth_image(&field);
            image.asset_usage = RenderAssetUsages::MAIN_WORLD;
            let pond = app.world().resource_mut::<Assets<Image>>().add(image);
            spawn_pond(app.world(), pond.clone(), technique, HeightBuild::Cpu);
            let mut k = 0u8;
            median_frame(&mut app, warm_up, frames, |world| {
                if rebuild && let Some(mut image) = world.resource_mut::<Assets<Image>>().get_mut(&pond) {
                    k = k.wrapping_add(1);
                    if let Some(data) = image.data.as_mut() {
                        data[0] = k;
                    }
                }
            })
        };
        let reports = app.world().resource::<bevy_pomkit::HeightMaps>().reports();
        if !reports.is_empty() {
            return Err(format!("bevy_pomkit reported: {reports:?}"));
        }
        println!("{label}: median frame {ms:.1} ms");
        results.push(ms);
    }
    println!(
        "rebuild of a {size}x{size} height map ({technique:?}, {w}x{h} frame): GPU passes {:.1} ms, CPU path {:.1} ms",
        results[0] - results[1],
        results[2] - results[3]
    );
    Ok(())
}
