//! Height maps built on the GPU in Bevy (`HeightBuild::Gpu`, `GpuEveryFrame`), on lavapipe,
//! against independent answers: every texture level against pomkit-core's functions (the ones
//! pomkit-gpu's own height-pass tests compare with, at their tolerances), a traced picture
//! against the same scene with the CPU build, and bad sources against the plain material.
//!
//! All tests share one lock: each builds a Bevy app with its own GPU device.

#[path = "support/examples.rs"]
mod examples;
#[path = "../examples/support/headless.rs"]
mod headless;
#[path = "../examples/support/probe.rs"]
mod probe;

use std::sync::Mutex;
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Hdr, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    BindGroupEntry, BindGroupLayout, BindGroupLayoutEntry, BindingResource, BindingType, Buffer, BufferBindingType,
    BufferDescriptor, BufferSize, BufferUsages, CommandEncoderDescriptor, ComputePassDescriptor, ComputePipeline,
    Extent3d, MapMode, Origin3d, PipelineCompilationOptions, PipelineLayoutDescriptor, PollType,
    RawComputePipelineDescriptor, ShaderModuleDescriptor, ShaderSource, ShaderStages, StorageTextureAccess,
    TexelCopyBufferInfo, TexelCopyBufferLayout, TexelCopyTextureInfo, TextureAspect, TextureDimension, TextureFormat,
    TextureUsages, TextureViewDescriptor, TextureViewDimension,
};
use bevy::render::renderer::{RenderContext, RenderDevice, RenderGraph, RenderGraphSystems, RenderQueue};
use bevy::render::texture::GpuImage;
use bevy::render::{Extract, ExtractSchedule, RenderApp};
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{
    GpuHeightPass, HeightBuild, HeightMaps, MapKind, Pomkit, PomkitMaterial, ShadowMode, Technique,
    gpu_heights_supported,
};
use headless::{Frame, Headless};
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::{EdgeMode, HeightField, MaxHeightPyramid, MipChain};
use pomkit_gpu::util::{f16_to_f32, f32_to_f16};
use probe::{Tangents, quad};

static GPU: Mutex<()> = Mutex::new(());

const TIMEOUT: Duration = Duration::from_secs(300);
const DEPTH_SCALE: f32 = 0.08;

/// `field` with its depths rounded to f16, as the import stores them: the surface the GPU has.
fn f16_field(field: &HeightField) -> HeightField {
    let d = field.depths().iter().map(|&d| f16_to_f32(f32_to_f16(d))).collect();
    HeightField::from_depths(field.width(), field.height(), d).expect("rounding keeps depths in [0, 1]")
}

/// Half an f16 step at `v` plus slack for f32 rounding order (pomkit-gpu's height-pass tests).
fn f16_half_step(v: f32) -> f32 {
    v.abs().max(1.0 / 16384.0) / 2048.0 + 1e-5
}

/// `Surface::new`'s parallax map: clamp(n_z * d) from central normals at depth_scale * width.
fn parallax_map(field: &HeightField, edges: EdgeMode) -> HeightField {
    let n = normals(field, edges);
    let p = n.iter().zip(field.depths()).map(|(n, &d)| (n.z * d).clamp(0.0, 1.0)).collect();
    HeightField::from_depths(field.width(), field.height(), p).expect("parallax values lie in [0, 1]")
}

fn normals(field: &HeightField, edges: EdgeMode) -> Vec<pomkit_core::glam::Vec3> {
    let o = NormalBakeOptions {
        scale: DEPTH_SCALE * field.width() as f32,
        filter: NormalFilter::Central,
        edges,
        y_down: false,
    };
    bake_normals(field, &o).expect("2x2 or larger")
}

/// Asserts `|gpu - cpu| <= tol(cpu)` element by element and returns the largest difference.
fn compare(what: &str, gpu: &[f32], cpu: &[f32], tol: impl Fn(f32) -> f32) -> f32 {
    assert_eq!(gpu.len(), cpu.len(), "{what}: sizes");
    assert!(!gpu.is_empty(), "{what}: nothing compared");
    let mut worst = 0.0f32;
    for (i, (&g, &c)) in gpu.iter().zip(cpu).enumerate() {
        let err = (g - c).abs();
        assert!(err <= tol(c), "{what}: element {i}: GPU {g} vs CPU {c} (difference {err}, tolerance {})", tol(c));
        worst = worst.max(err);
    }
    worst
}

/// Every mip of a render-world image, as `f32` texels of `channels` values, read back by a copy
/// to a buffer (Rgba16Float or Rg32Float).
fn read_mips(app: &mut Headless, id: AssetId<Image>) -> Vec<(u32, u32, Vec<f32>)> {
    let world = app.app().sub_app(RenderApp).world();
    let image = world.resource::<RenderAssets<GpuImage>>().get(id).expect("the texture is on the GPU");
    let device = world.resource::<RenderDevice>();
    let queue = world.resource::<RenderQueue>();
    let desc = &image.texture_descriptor;
    let texel = desc.format.block_copy_size(None).expect("an uncompressed format") as usize;
    let mut out = Vec::new();
    for level in 0..desc.mip_level_count {
        let (w, h) = ((desc.size.width >> level).max(1), (desc.size.height >> level).max(1));
        let row = w as usize * texel;
        let padded = RenderDevice::align_copy_bytes_per_row(row);
        let buffer = device.create_buffer(&BufferDescriptor {
            label: Some("test readback"),
            size: (padded * h as usize) as u64,
            usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        encoder.copy_texture_to_buffer(
            TexelCopyTextureInfo {
                texture: &image.texture,
                mip_level: level,
                origin: Origin3d::ZERO,
                aspect: TextureAspect::All,
            },
            TexelCopyBufferInfo {
                buffer: &buffer,
                layout: TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded as u32), rows_per_image: None },
            },
            Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        queue.submit([encoder.finish()]);
        let slice = buffer.slice(..);
        slice.map_async(MapMode::Read, |r| r.expect("map"));
        device.poll(PollType::wait_indefinitely()).expect("device lost");
        let data = slice.get_mapped_range();
        let mut values = Vec::with_capacity(w as usize * h as usize * 4);
        for y in 0..h as usize {
            let line = &data[y * padded..y * padded + row];
            match desc.format {
                TextureFormat::Rgba16Float => {
                    values.extend(line.chunks_exact(2).map(|b| f16_to_f32(u16::from_le_bytes([b[0], b[1]]))));
                }
                TextureFormat::Rg32Float => {
                    values.extend(line.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])));
                }
                f => panic!("unexpected format {f:?}"),
            }
        }
        drop(data);
        buffer.unmap();
        out.push((w, h, values));
    }
    out
}

/// Channel `c` of texels of `n` channels.
fn channel(values: &[f32], n: usize, c: usize) -> Vec<f32> {
    values.chunks_exact(n).map(|t| t[c]).collect()
}

fn spawn_camera(app: &mut Headless) {
    let target = RenderTarget::Image(app.target().into());
    let camera = Transform::from_xyz(0.0, 1.3, 1.6).looking_at(Vec3::new(0.0, -0.1, 0.0), Vec3::Y);
    app.world().spawn((Camera3d::default(), Hdr, Tonemapping::None, Msaa::Off, camera, target));
    app.world().spawn((
        DirectionalLight { illuminance: 3000.0, shadow_maps_enabled: false, ..default() },
        Transform::default().looking_to(Vec3::new(-1.0, -0.45, -0.3), Vec3::Y),
    ));
}

/// The quad with a pomkit material on `source` (depths, white deep), built as `build` says.
fn spawn_quad(app: &mut Headless, source: Image, build: HeightBuild, technique: Technique) -> Handle<PomkitMaterial> {
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let source = app.world().resource_mut::<Assets<Image>>().add(source);
    let mut ext = Pomkit::new(source)
        .with_technique(technique)
        .with_shadow(ShadowMode::Hard)
        .with_depth_scale(DEPTH_SCALE)
        .with_height_build(build);
    ext.map_kind = MapKind::Depth;
    ext.lod_threshold = f32::MAX;
    let base = StandardMaterial { base_color: Color::srgb(0.8, 0.7, 0.5), perceptual_roughness: 0.6, ..default() };
    let material = app.world().resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial { base, extension: ext });
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
    material
}

/// A depth image of `field` kept in the render world only: the CPU build cannot read it, the
/// GPU build imports it.
fn render_world_image(field: &HeightField) -> Image {
    let mut image = depth_image(field);
    image.asset_usage = RenderAssetUsages::RENDER_WORLD;
    image
}

#[test]
fn gpu_built_levels_equal_pomkit_core() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // Not a power of two on either side, so the mips round down, the pyramid pads and its
    // levels round up.
    let field = generate(Pattern::Cobblestones, 45, 29);
    let edges = EdgeMode::Wrap;
    let mut app = Headless::new(48, 36);
    assert!(gpu_heights_supported(), "lavapipe runs compute passes");
    // Every frame, from a texture the main world holds no texels of.
    let material = spawn_quad(&mut app, render_world_image(&field), HeightBuild::GpuEveryFrame, Technique::Exact);
    spawn_camera(&mut app);
    app.frame(TIMEOUT).expect("frame");
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "reports: {reports:?}");
    let [heights, pyramid, normals_id] = gpu_textures(&mut app, &material);

    let f16 = f16_field(&field);
    let (w, h) = (field.width(), field.height());
    // Heights: R the depth mips, G the parallax value mips.
    let chain = MipChain::new(f16.clone());
    let parallax = MipChain::new(parallax_map(&f16, edges));
    let mips = read_mips(&mut app, heights);
    assert_eq!(mips.len(), chain.len(), "heights mip count");
    let (mut worst_depth, mut worst_parallax) = (0.0f32, 0.0f32);
    for (k, (lw, lh, values)) in mips.iter().enumerate() {
        let (cpu_d, cpu_p) = (chain.level(k), parallax.level(k));
        assert_eq!((*lw, *lh), (cpu_d.width(), cpu_d.height()), "mip {k} size");
        let levels = k as f32 + 1.0;
        if k == 0 {
            compare("mip 0 depth (the import, bit for bit)", &channel(values, 4, 0), cpu_d.depths(), |_| 0.0);
        }
        let e =
            compare(&format!("mip {k} depth"), &channel(values, 4, 0), cpu_d.depths(), |v| levels * f16_half_step(v));
        worst_depth = worst_depth.max(e);
        let e = compare(&format!("mip {k} parallax"), &channel(values, 4, 1), cpu_p.depths(), |v| {
            levels * f16_half_step(v)
        });
        worst_parallax = worst_parallax.max(e);
    }
    // Normals: bake_normals of the f16 depths at depth_scale * width.
    let cpu_normals = normals(&f16, edges);
    let gpu_normals = &read_mips(&mut app, normals_id)[0].2;
    let mut worst_normal = 0.0f32;
    for c in 0..3 {
        let cpu: Vec<f32> = cpu_normals.iter().map(|n| n[c]).collect();
        let e = compare(&format!("normal component {c}"), &channel(gpu_normals, 4, c), &cpu, f16_half_step);
        worst_normal = worst_normal.max(e);
    }
    // The pyramid: exact for the f16 surface; padded to powers of two.
    let cpu_pyramid = MaxHeightPyramid::new(&f16, edges);
    let levels = read_mips(&mut app, pyramid);
    assert_eq!(levels.len(), cpu_pyramid.len(), "pyramid levels");
    assert_eq!((levels[0].0, levels[0].1), (w.next_power_of_two(), h.next_power_of_two()), "pyramid padding");
    let mut worst_pyramid = 0.0f32;
    for (l, (stride, _, values)) in levels.iter().enumerate() {
        let (cw, ch) = cpu_pyramid.level_size(l);
        let cells: Vec<(u32, u32)> = (0..ch).flat_map(|y| (0..cw).map(move |x| (x, y))).collect();
        let gpu: Vec<f32> = cells.iter().map(|&(x, y)| values[2 * (y * stride + x) as usize]).collect();
        let cpu: Vec<f32> = cells.iter().map(|&(x, y)| cpu_pyramid.min_depth(l, x, y)).collect();
        worst_pyramid = worst_pyramid.max(compare(&format!("pyramid level {l}"), &gpu, &cpu, |_| 1e-6));
    }
    eprintln!(
        "{w}x{h}: {} height mips, worst depth {worst_depth:.2e}, parallax {worst_parallax:.2e}, normal {worst_normal:.2e}, {} pyramid levels, worst {worst_pyramid:.2e}",
        mips.len(),
        levels.len()
    );
}

/// The lit, self-shadowed quad drawn with `build`, `technique` on `field`.
fn picture(field: &HeightField, build: HeightBuild, technique: Technique) -> Frame {
    let mut app = Headless::new(96, 72);
    let mut source = depth_image(field);
    // On the GPU too, for the GPU build.
    source.asset_usage = RenderAssetUsages::default();
    let material = spawn_quad(&mut app, source, build, technique);
    spawn_camera(&mut app);
    let frame = app.frame(TIMEOUT).expect("frame");
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "reports: {reports:?}");
    // Built where asked: the GPU writes Rgba16Float heights, the CPU R16Float.
    let world = app.world();
    let [heights, ..] =
        world.resource::<Assets<PomkitMaterial>>().get(&material).unwrap().extension.height_textures().unwrap();
    let format = world.resource::<Assets<Image>>().get(heights).unwrap().texture_descriptor.format;
    let want = if build == HeightBuild::Cpu { TextureFormat::R16Float } else { TextureFormat::Rgba16Float };
    assert_eq!(format, want, "{build:?}: heights built elsewhere");
    frame
}

/// Largest and mean difference of two pictures' colours, and the share of pixels off by more
/// than `limit`.
fn difference(a: &Frame, b: &Frame, limit: f32) -> (f32, f32, f32) {
    let d: Vec<f32> =
        a.pixels.iter().zip(&b.pixels).map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f32::max)).collect();
    let worst = d.iter().copied().fold(0.0, f32::max);
    let mean = d.iter().sum::<f32>() / d.len() as f32;
    let off = d.iter().filter(|&&v| v > limit).count() as f32 / d.len() as f32;
    (worst, mean, off)
}

#[test]
fn a_picture_with_the_gpu_build_equals_the_cpu_builds() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // Depths already on the f16 grid, so both builds start from the same surface; what differs
    // is where each rounds the mips (the GPU once per level, the CPU once).
    let field = f16_field(&generate(Pattern::Bricks, 40, 40));
    for technique in [Technique::Pom, Technique::Exact] {
        let cpu = picture(&field, HeightBuild::Cpu, technique);
        let gpu = picture(&field, HeightBuild::Gpu, technique);
        // And an independent check that the picture shows relief: the flat plane differs.
        let flat = picture(&HeightField::constant(40, 40, 0.0), HeightBuild::Cpu, technique);
        let (worst, mean, off) = difference(&gpu, &cpu, 0.02);
        let (_, relief, _) = difference(&flat, &cpu, 0.02);
        eprintln!(
            "{technique:?}: GPU vs CPU build: worst {worst:.4}, mean {mean:.2e}, {:.2}% of pixels off by > 0.02; flat vs relief mean {relief:.3}",
            off * 100.0
        );
        assert!(relief > 0.01, "{technique:?}: the relief does not show ({relief})");
        assert!(
            worst < 0.05 && mean < 1e-3 && off < 0.002,
            "{technique:?}: the GPU build's picture differs from the CPU build's"
        );
    }
}

#[test]
fn a_storage_texture_of_the_wrong_format_or_size_draws_plain_and_says_why() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let storage = |w: u32, h: u32, format: TextureFormat| {
        let mut image = Image::new_uninit(
            Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            TextureDimension::D2,
            format,
            RenderAssetUsages::RENDER_WORLD,
        );
        image.texture_descriptor.usage = TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING;
        image
    };
    // The reference: the plain standard material on the same quad.
    let plain_frame = |app: &mut Headless| {
        let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
        let base = StandardMaterial { base_color: Color::srgb(0.8, 0.7, 0.5), perceptual_roughness: 0.6, ..default() };
        let plain = app.world().resource_mut::<Assets<StandardMaterial>>().add(base);
        app.world().spawn((Mesh3d(mesh), MeshMaterial3d(plain)));
        spawn_camera(app);
        app.frame(TIMEOUT).expect("frame")
    };
    let reference = plain_frame(&mut Headless::new(48, 36));
    let field = generate(Pattern::Bricks, 24, 24);
    for case in ["format", "size"] {
        let mut app = Headless::new(48, 36);
        let source = match case {
            "format" => storage(32, 32, TextureFormat::R32Uint),
            _ => render_world_image(&field),
        };
        let material = spawn_quad(&mut app, source, HeightBuild::GpuEveryFrame, Technique::Pom);
        spawn_camera(&mut app);
        let mut frame = app.frame(TIMEOUT).expect("frame");
        if case == "size" {
            // Traced at first; then the source is made again at another size.
            let (traced, ..) = difference(&frame, &reference, 0.02);
            assert!(traced > 0.02, "the relief does not show before the change");
            let id = app.world().resource::<Assets<PomkitMaterial>>().get(&material).unwrap().extension.height_map.id();
            let resized = render_world_image(&generate(Pattern::Bricks, 20, 24));
            app.world().resource_mut::<Assets<Image>>().insert(id, resized).expect("replaced");
            frame = app.frame(TIMEOUT).expect("frame");
        }
        let (worst, ..) = difference(&frame, &reference, 0.0);
        let reports = app.world().resource::<HeightMaps>().reports();
        eprintln!("{case}: worst difference from the plain material {worst}; reports {reports:?}");
        assert!(worst < 2e-3, "{case}: not the plain material's look (difference {worst})");
        let expect = if case == "format" { "R32Uint" } else { "size changed from 24x24 to 20x24" };
        assert!(
            reports.iter().any(|r| r.contains(expect) && r.contains("height map")),
            "{case}: no report naming the problem in {reports:?}"
        );
        assert_eq!(reports.len(), 1, "{case}: one message: {reports:?}");
    }
}

#[test]
fn an_srgb_colour_image_imports_its_stored_luma_as_the_cpu_reads_it() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // An 8-bit sRGB PNG's stored values, not decoded: the heights are data. Every texel's three
    // channels differ, so a wrong channel, a missing luma or an sRGB decode shows.
    let (w, h) = (23u32, 17u32);
    let data: Vec<u8> = (0..w * h)
        .flat_map(|k| {
            let (x, y) = (k % w, k / w);
            [(x * 11 + y * 3) as u8, (y * 14 + x * 5) as u8, ((x * y * 7) % 251) as u8, 255]
        })
        .collect();
    let image = Image::new(
        Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    );
    let cpu = bevy_pomkit::height::depths_from_image(&image, MapKind::Height, bevy_pomkit::Channel::Luma)
        .expect("the CPU reads it");
    let mut app = Headless::new(48, 36);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let source = app.world().resource_mut::<Assets<Image>>().add(image);
    let ext = Pomkit::new(source).with_height_build(HeightBuild::Gpu);
    let material = app
        .world()
        .resource_mut::<Assets<PomkitMaterial>>()
        .add(PomkitMaterial { base: StandardMaterial::default(), extension: ext });
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
    spawn_camera(&mut app);
    app.frame(TIMEOUT).expect("frame");
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "reports: {reports:?}");
    let [heights, ..] = gpu_textures(&mut app, &material);
    let gpu = channel(&read_mips(&mut app, heights)[0].2, 4, 0);
    let worst = compare("mip 0 depth from the luma", &gpu, cpu.depths(), |v| f16_half_step(v) + 1e-6);
    eprintln!("{w}x{h} Rgba8UnormSrgb, luma: worst difference from the CPU's depths {worst:.2e}");
}

/// The stamp the test's own compute pass writes into its storage texture this frame.
#[derive(Resource, Clone, Copy)]
struct Stamp(u32);

/// The render world's side of the test's compute pass.
#[derive(Resource)]
struct Writer {
    target: AssetId<Image>,
    stamp: u32,
    pipeline: Option<(BindGroupLayout, ComputePipeline, Buffer)>,
}

/// The test's pass: texel (x, y) of frame `stamp` holds ((x + 3 y + 5 stamp) mod 16) / 16.
const WRITER_WGSL: &str = "
@group(0) @binding(0) var out: texture_storage_2d<r32float, write>;
@group(0) @binding(1) var<uniform> stamp: vec4<u32>;
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(out);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let v = f32((id.x + 3u * id.y + 5u * stamp.x) % 16u) / 16.0;
    textureStore(out, vec2<i32>(id.xy), vec4<f32>(v, 0.0, 0.0, 1.0));
}
";

fn stamp_value(x: u32, y: u32, stamp: u32) -> f32 {
    ((x + 3 * y + 5 * stamp) % 16) as f32 / 16.0
}

/// The test's compute pass, as docs/EMBEDDING.md tells a user to order it: in the render graph,
/// before `GpuHeightPass`, recording into the frame's commands.
fn write_stamp(
    mut writer: ResMut<Writer>,
    images: Res<RenderAssets<GpuImage>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut ctx: RenderContext,
) {
    let Some(target) = images.get(writer.target) else { return };
    let stamp = writer.stamp;
    let (layout, pipeline, uniform) = writer.pipeline.get_or_insert_with(|| {
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
        let layout = device.create_bind_group_layout("stamp", &entries);
        let module = device.create_and_validate_shader_module(ShaderModuleDescriptor {
            label: Some("stamp"),
            source: ShaderSource::Wgsl(WRITER_WGSL.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&PipelineLayoutDescriptor {
            label: Some("stamp"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&RawComputePipelineDescriptor {
            label: Some("stamp"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: PipelineCompilationOptions::default(),
            cache: None,
        });
        let uniform = device.create_buffer(&BufferDescriptor {
            label: Some("stamp"),
            size: 16,
            usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        (layout, pipeline, uniform)
    });
    queue.write_buffer(uniform, 0, &[stamp.to_le_bytes(), [0; 4], [0; 4], [0; 4]].concat());
    let view = target.texture.create_view(&TextureViewDescriptor::default());
    let group = device.create_bind_group(
        "stamp",
        layout,
        &[
            BindGroupEntry { binding: 0, resource: BindingResource::TextureView(&view) },
            BindGroupEntry { binding: 1, resource: uniform.as_entire_binding() },
        ],
    );
    let size = target.texture_descriptor.size;
    let mut pass = ctx.command_encoder().begin_compute_pass(&ComputePassDescriptor::default());
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &*group, &[]);
    pass.dispatch_workgroups(size.width.div_ceil(8), size.height.div_ceil(8), 1);
}

#[test]
fn a_texture_written_by_a_compute_pass_is_built_in_the_same_frame() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let (w, h) = (20u32, 12u32);
    let mut app = Headless::new(48, 36);
    let mut texture = Image::new_uninit(
        Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        TextureDimension::D2,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    texture.texture_descriptor.usage = TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING;
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let source = app.world().resource_mut::<Assets<Image>>().add(texture);
    app.world().insert_resource(Stamp(1));
    let render = app.app().sub_app_mut(RenderApp);
    render.insert_resource(Writer { target: source.id(), stamp: 1, pipeline: None });
    render.add_systems(ExtractSchedule, |stamp: Extract<Res<Stamp>>, mut writer: ResMut<Writer>| {
        writer.stamp = stamp.0;
    });
    render.add_systems(RenderGraph, write_stamp.in_set(RenderGraphSystems::Render).before(GpuHeightPass));
    let mut ext = Pomkit::new(source).with_height_build(HeightBuild::GpuEveryFrame);
    ext.map_kind = MapKind::Depth;
    let material = app
        .world()
        .resource_mut::<Assets<PomkitMaterial>>()
        .add(PomkitMaterial { base: StandardMaterial::default(), extension: ext });
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
    spawn_camera(&mut app);
    app.frame(TIMEOUT).expect("frame");
    let [heights, ..] = gpu_textures(&mut app, &material);
    // Each frame a new stamp: the heights built in that frame hold that frame's texels.
    for stamp in 2..5 {
        app.world().insert_resource(Stamp(stamp));
        app.update();
        let mips = read_mips(&mut app, heights);
        let gpu = channel(&mips[0].2, 4, 0);
        let want: Vec<f32> = (0..h).flat_map(|y| (0..w).map(move |x| stamp_value(x, y, stamp))).collect();
        compare(&format!("frame {stamp}: mip 0"), &gpu, &want, |_| 0.0);
        // The coarsest mip is the mean, also of this frame.
        let mean = want.iter().sum::<f32>() / want.len() as f32;
        let top = mips.last().map(|m| m.2[0]).unwrap_or_default();
        assert!((top - mean).abs() < 0.01, "frame {stamp}: coarsest mip {top}, mean {mean}");
    }
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "reports: {reports:?}");
}

#[test]
fn the_ripples_example_draws_without_errors_or_warnings() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let args = ["--frames", "4", "--size", "64", "--width", "64", "--height", "36"];
    let Some(picture) = examples::picture_of("ripples", &args) else { return };
    // The pond covers the lower part of the picture: not the clear colour there.
    let clear = picture.get_pixel(32, 0);
    assert_ne!(picture.get_pixel(32, 30), clear, "no pond in the picture");
}

#[test]
fn an_edited_image_of_a_new_size_is_built_at_that_size() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let mut app = Headless::new(48, 36);
    let first = generate(Pattern::Bricks, 24, 24);
    let material = spawn_quad(&mut app, render_world_image(&first), HeightBuild::Gpu, Technique::Pom);
    spawn_camera(&mut app);
    app.frame(TIMEOUT).expect("frame");
    let id = app.world().resource::<Assets<PomkitMaterial>>().get(&material).unwrap().extension.height_map.id();
    let second = generate(Pattern::Cobblestones, 20, 27);
    app.world().resource_mut::<Assets<Image>>().insert(id, render_world_image(&second)).expect("replaced");
    app.frame(TIMEOUT).expect("frame");
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "an edit to a new size is no error: {reports:?}");
    let [heights, ..] = gpu_textures(&mut app, &material);
    let mip0 = read_mips(&mut app, heights).swap_remove(0);
    assert_eq!((mip0.0, mip0.1), (20, 27), "the textures' size");
    compare("mip 0 depth of the new image", &channel(&mip0.2, 4, 0), f16_field(&second).depths(), |_| 0.0);
}

/// The heights, pyramid and normals textures the plugin made for `material`.
fn gpu_textures(app: &mut Headless, material: &Handle<PomkitMaterial>) -> [AssetId<Image>; 3] {
    app.world()
        .resource::<Assets<PomkitMaterial>>()
        .get(material)
        .and_then(|m| m.extension.height_textures())
        .expect("the GPU textures are made")
}
