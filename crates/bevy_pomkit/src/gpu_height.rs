//! Height maps built on the GPU (Tatarchuk 2006's dynamic height fields, docs/REFERENCES.md):
//! the textures pomkit's shader library reads, derived from the source image by compute passes
//! in Bevy's render world instead of by pomkit-core on the CPU.
//!
//! The passes are pomkit-gpu's own WGSL (`pomkit_gpu::library::IMPORT_WGSL` and `HEIGHT_WGSL`,
//! the text `pomkit_gpu::height::HeightPasses` drives on its own wgpu), driven here on Bevy's
//! device: import (one channel, or the luma, of the source's mip 0 as depths, rounded to f16)
//! -> normals and parallax values -> the box-filtered mips -> the maximum-height pyramid (-> the
//! conservative cone ratios, for materials drawn with `cone`).
//!
//! The textures are render-world Bevy images the material binds as it binds the CPU-built
//! ones: `heights` `Rgba16Float` with every mip (R depth, G the parallax value of `iterative`),
//! `pyramid` `Rg32Float` padded to powers of two (R the bound, G in mip 0 the cone ratios),
//! `normals` `Rgba16Float`.
//!
//! The main world decides what to build (`HeightMaps::prepare_gpu`, from `build_height_maps`:
//! the source checked, the images made) and hands the render world a list of jobs
//! ([`GpuHeightJobs`]); the render-world system in
//! [`GpuHeightPass`] records the passes of each job whose source changed (or every frame for
//! [`HeightBuild::GpuEveryFrame`]) into the frame's command encoder, before any camera draws.
//! What only the render world can see wrong (a texture written every frame that changed size
//! there) goes back through [`GpuReports`], and the main world draws that material plain.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use bevy::asset::{AssetId, Assets, RenderAssetUsages};
use bevy::image::{Image, ImageSampler};
use bevy::log::{error, info};
use bevy::platform::collections::HashMap;
use bevy::prelude::*;
use bevy::render::extract_resource::ExtractResource;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    BindGroupEntry, BindGroupLayout, BindGroupLayoutEntry, BindingResource, BindingType, BufferBinding,
    BufferInitDescriptor, BufferSize, BufferUsages, ComputePassDescriptor, ComputePipeline, DownlevelFlags, Extent3d,
    PipelineCompilationOptions, PipelineLayoutDescriptor, RawComputePipelineDescriptor, ShaderModuleDescriptor,
    ShaderSource, ShaderStages, StorageTextureAccess, Texture, TextureDescriptor, TextureDimension, TextureFormat,
    TextureSampleType, TextureUsages, TextureView, TextureViewDescriptor, TextureViewDimension,
};
use bevy::render::renderer::{RenderAdapter, RenderContext, RenderDevice};
use bevy::render::texture::GpuImage;
use pomkit_core::EdgeMode;

use crate::height::{Channel, MapKind};

/// How the plugin builds a material's height textures ([`Pomkit::height_build`](crate::Pomkit)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum HeightBuild {
    /// On the CPU with pomkit-core, when the source image or a setting changes (the default):
    /// the source needs its texels in the main world.
    #[default]
    Cpu,
    /// By compute passes on the GPU, when the source image changes (an `AssetEvent::Modified`,
    /// a new GPU texture for it) or a setting does. The source may live in the render world
    /// only (`RenderAssetUsages::RENDER_WORLD`).
    Gpu,
    /// By compute passes on the GPU, every frame: for a source written on the GPU, such as a
    /// storage texture a compute shader of your own writes each frame (order that shader's
    /// system before [`GpuHeightPass`]).
    GpuEveryFrame,
}

/// The render-world system set (in Bevy's `RenderGraph` schedule, inside
/// `RenderGraphSystems::Render`, before the cameras draw) that records the GPU height builds.
/// A compute pass of your own that writes a source texture goes before it:
///
/// ```ignore
/// render_app.add_systems(
///     RenderGraph,
///     write_my_heights.in_set(RenderGraphSystems::Render).before(bevy_pomkit::GpuHeightPass),
/// );
/// ```
///
/// and records into the same frame's commands (`RenderContext::command_encoder`), so the GPU
/// runs it first.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GpuHeightPass;

/// Whether the render device can run the passes (compute shaders, enough storage textures).
static SUPPORTED: AtomicBool = AtomicBool::new(false);

/// Looks at the render device once it exists and remembers whether it can build height maps.
pub(crate) fn detect(render_world: &World) {
    let (Some(device), Some(adapter)) =
        (render_world.get_resource::<RenderDevice>(), render_world.get_resource::<RenderAdapter>())
    else {
        return;
    };
    let limits = device.limits();
    let compute = adapter.get_downlevel_capabilities().flags.contains(DownlevelFlags::COMPUTE_SHADERS);
    let ok = compute
        && limits.max_storage_textures_per_shader_stage >= 2
        && limits.max_compute_workgroup_size_x >= WORKGROUP
        && limits.max_compute_workgroup_size_y >= WORKGROUP
        && limits.max_compute_invocations_per_workgroup >= WORKGROUP * WORKGROUP;
    SUPPORTED.store(ok, Ordering::Relaxed);
}

/// Whether height maps can be built on the GPU here (false until the renderer has started, and
/// without a render app at all).
#[must_use]
pub fn gpu_heights_supported() -> bool {
    SUPPORTED.load(Ordering::Relaxed)
}

/// The build a material gets: `wanted`, or the CPU where the device cannot run compute passes
/// (said once in the log).
pub(crate) fn effective(wanted: HeightBuild) -> HeightBuild {
    static SAID: AtomicBool = AtomicBool::new(false);
    if wanted == HeightBuild::Cpu || gpu_heights_supported() {
        return wanted;
    }
    if !SAID.swap(true, Ordering::Relaxed) {
        info!("bevy_pomkit: this device cannot run compute passes: building height maps on the CPU");
    }
    HeightBuild::Cpu
}

/// Side of the square workgroups of `height.wgsl` and `import.wgsl`.
const WORKGROUP: u32 = 8;
/// Bytes of `height.wgsl`'s `Params`.
const HEIGHT_PARAMS: u64 = 32;
/// Bytes of `import.wgsl`'s `Params`.
const IMPORT_PARAMS: u64 = 16;
/// `import.wgsl`'s channel that means the Rec. 709 luma.
const CHANNEL_LUMA: u32 = 4;

/// One material's build, as the render world needs it.
#[derive(Clone, Debug)]
pub(crate) struct GpuJob {
    pub source: AssetId<Image>,
    pub heights: AssetId<Image>,
    pub pyramid: AssetId<Image>,
    pub normals: AssetId<Image>,
    pub size: (u32, u32),
    /// `import.wgsl`'s channel: 0 to 3, or [`CHANNEL_LUMA`].
    pub channel: u32,
    /// `import.wgsl`'s encoding: 0 heights, 1 depths.
    pub encoding: u32,
    /// The source's format seen through a view without sRGB decoding, where it differs.
    pub view_format: Option<TextureFormat>,
    pub edges: EdgeMode,
    pub depth_scale: f32,
    pub cones: bool,
    pub every_frame: bool,
    /// Bumped by the main world whenever the source changed: the render world rebuilds.
    pub generation: u64,
    /// The source as the log names it.
    pub name: String,
}

/// The builds of the materials in use, extracted into the render world when they change.
#[derive(Resource, Clone, Default, ExtractResource)]
pub(crate) struct GpuHeightJobs(pub Vec<GpuJob>);

/// Problems only the render world sees (a source texture whose size or format no longer
/// matches), handed back to the main world: (the job's heights image, the message).
#[derive(Resource, Clone, Default)]
pub(crate) struct GpuReports(Arc<Mutex<Vec<GpuReport>>>);

/// A job's heights image and the message about its source.
type GpuReport = (AssetId<Image>, String);

impl GpuReports {
    fn push(&self, id: AssetId<Image>, message: String) {
        if let Ok(mut v) = self.0.lock() {
            v.push((id, message));
        }
    }

    pub(crate) fn take(&self) -> Vec<GpuReport> {
        self.0.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default()
    }
}

/// What a source image needs for the import pass; `Err` says why it cannot be read.
pub(crate) struct SourceInfo {
    pub size: (u32, u32),
    pub channel: u32,
    pub view_format: Option<TextureFormat>,
    /// The linear twin of an sRGB format the image's texture does not list yet among its view
    /// formats (the plugin adds it while the texels are still in the main world).
    pub needs_view_format: Option<&'static [TextureFormat]>,
}

/// Checks `image` as a source of the GPU import: a single 2D float-sampled colour image with
/// `TEXTURE_BINDING` usage, not empty, with the channel asked for.
pub(crate) fn check_source(image: &Image, channel: Channel) -> Result<SourceInfo, String> {
    let d = &image.texture_descriptor;
    let format = d.format;
    let float = matches!(format.sample_type(None, None), Some(TextureSampleType::Float { .. }));
    if !float || format.is_depth_stencil_format() || format.block_dimensions() != (1, 1) {
        return Err(format!(
            "its format {format:?} cannot be read by the GPU height build (use a float or unorm colour format: R32Float, R16Float, Rgba16Float, R8Unorm, Rgba8Unorm, ...)"
        ));
    }
    if d.dimension != TextureDimension::D2 || d.size.depth_or_array_layers != 1 || d.sample_count != 1 {
        return Err(format!(
            "it is not a single 2D image ({:?}, {} layers, {} samples)",
            d.dimension, d.size.depth_or_array_layers, d.sample_count
        ));
    }
    let (w, h) = (d.size.width, d.size.height);
    if w == 0 || h == 0 {
        return Err(format!("it is {w}x{h} texels"));
    }
    if !image.asset_usage.contains(RenderAssetUsages::RENDER_WORLD) {
        return Err("it is kept in the main world only (give it RenderAssetUsages::RENDER_WORLD too, so the GPU height build can read it)".into());
    }
    if !d.usage.contains(TextureUsages::TEXTURE_BINDING) {
        return Err("it lacks TextureUsages::TEXTURE_BINDING, which the GPU height build reads it through".into());
    }
    let components = u32::from(format.components());
    let channel = match channel {
        Channel::R => 0,
        Channel::G if components >= 2 => 1,
        Channel::B if components >= 3 => 2,
        Channel::G | Channel::B => 0,
        Channel::A if components == 4 => 3,
        Channel::A => return Err("it has no alpha channel to read heights from (use Channel::Luma, R, G or B)".into()),
        Channel::Luma if components >= 3 => CHANNEL_LUMA,
        Channel::Luma => 0,
    };
    // The stored values are heights, not colours: read them without sRGB decoding, as the CPU
    // build does, through a view of the linear twin.
    let (view_format, needs_view_format) = if format.is_srgb() {
        let twin: &'static [TextureFormat] = match format {
            TextureFormat::Rgba8UnormSrgb => &[TextureFormat::Rgba8Unorm],
            TextureFormat::Bgra8UnormSrgb => &[TextureFormat::Bgra8Unorm],
            _ => return Err(format!("its format {format:?} is sRGB-encoded (use a linear format)")),
        };
        let listed = d.view_formats.contains(&twin[0]);
        (Some(twin[0]), (!listed).then_some(twin))
    } else {
        (None, None)
    };
    Ok(SourceInfo { size: (w, h), channel, view_format, needs_view_format })
}

/// `import.wgsl`'s encoding of `kind`.
pub(crate) fn encoding(kind: MapKind) -> u32 {
    match kind {
        MapKind::Height => 0,
        MapKind::Depth => 1,
    }
}

/// The three render-world images a `w` x `h` source's build writes: `heights` (`Rgba16Float`,
/// every mip), `pyramid` (`Rg32Float`, padded to powers of two), `normals` (`Rgba16Float`).
pub(crate) fn derived_images(w: u32, h: u32, edges: EdgeMode) -> crate::height::HeightImages {
    let usage = TextureUsages::TEXTURE_BINDING
        | TextureUsages::STORAGE_BINDING
        | TextureUsages::COPY_SRC
        | TextureUsages::COPY_DST;
    let make = |w: u32, h: u32, mips: u32, format: TextureFormat, sampler: ImageSampler| {
        let mut image = Image::new_uninit(
            Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            TextureDimension::D2,
            format,
            RenderAssetUsages::RENDER_WORLD,
        );
        image.texture_descriptor.mip_level_count = mips;
        image.texture_descriptor.usage = usage;
        image.sampler = sampler;
        image
    };
    let levels = |n: u32| 32 - n.leading_zeros();
    let (pw, ph) = (w.next_power_of_two(), h.next_power_of_two());
    let linear = ImageSampler::Descriptor(crate::height::sampler(edges));
    crate::height::HeightImages {
        heights: make(w, h, levels(w.max(h)), TextureFormat::Rgba16Float, linear.clone()),
        pyramid: make(pw, ph, levels(pw.max(ph)), TextureFormat::Rg32Float, ImageSampler::nearest()),
        normals: make(w, h, 1, TextureFormat::Rgba16Float, linear),
    }
}

/// Puts `built` into the images of the handles, or into new images.
pub(crate) fn store_images(
    images: &mut Assets<Image>,
    handles: Option<[&Handle<Image>; 3]>,
    built: crate::height::HeightImages,
) -> [Handle<Image>; 3] {
    match handles {
        Some(h) => {
            for (handle, image) in h.iter().zip([built.heights, built.pyramid, built.normals]) {
                if let Err(e) = images.insert(handle.id(), image) {
                    error!("bevy_pomkit: could not replace a height texture: {e}");
                }
            }
            [h[0].clone(), h[1].clone(), h[2].clone()]
        }
        None => [images.add(built.heights), images.add(built.pyramid), images.add(built.normals)],
    }
}

// ---------------------------------------------------------------------------------------------
// The render world.
// ---------------------------------------------------------------------------------------------

/// A compute entry point and its bind group layout.
struct Stage {
    layout: BindGroupLayout,
    pipeline: ComputePipeline,
}

/// A binding slot of a stage.
#[derive(Clone, Copy)]
enum Slot {
    /// `texture_2d<f32>` read with `textureLoad`.
    Texture,
    /// `texture_storage_2d<format, write>`.
    Storage(TextureFormat),
    /// A uniform `Params` record of this many bytes.
    Params(u64),
}

impl Stage {
    fn new(device: &RenderDevice, source: &str, entry: &str, slots: &[Slot]) -> Self {
        let entries: Vec<BindGroupLayoutEntry> = slots
            .iter()
            .enumerate()
            .map(|(i, s)| BindGroupLayoutEntry {
                binding: i as u32,
                visibility: ShaderStages::COMPUTE,
                ty: match *s {
                    Slot::Texture => BindingType::Texture {
                        sample_type: TextureSampleType::Float { filterable: false },
                        view_dimension: TextureViewDimension::D2,
                        multisampled: false,
                    },
                    Slot::Storage(format) => BindingType::StorageTexture {
                        access: StorageTextureAccess::WriteOnly,
                        format,
                        view_dimension: TextureViewDimension::D2,
                    },
                    Slot::Params(size) => BindingType::Buffer {
                        ty: bevy::render::render_resource::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: BufferSize::new(size),
                    },
                },
                count: None,
            })
            .collect();
        let layout = device.create_bind_group_layout(entry, &entries);
        let module = device.create_and_validate_shader_module(ShaderModuleDescriptor {
            label: Some(entry),
            source: ShaderSource::Wgsl(source.into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&PipelineLayoutDescriptor {
            label: Some(entry),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&RawComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: PipelineCompilationOptions::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }
}

/// The pipelines of the import and height passes, made on first use.
struct Pipelines {
    import: Stage,
    normals: Stage,
    resolve: Stage,
    downsample: Stage,
    pyramid_base: Stage,
    pyramid_reduce: Stage,
    cones: Stage,
}

impl Pipelines {
    fn new(device: &RenderDevice) -> Self {
        let height = pomkit_gpu::library::HEIGHT_WGSL;
        let rgba16 = Slot::Storage(TextureFormat::Rgba16Float);
        let rg32 = Slot::Storage(TextureFormat::Rg32Float);
        let r32 = Slot::Storage(TextureFormat::R32Float);
        let p = Slot::Params(HEIGHT_PARAMS);
        let t = Slot::Texture;
        Self {
            import: Stage::new(
                device,
                pomkit_gpu::library::IMPORT_WGSL,
                "import_main",
                &[t, rgba16, Slot::Params(IMPORT_PARAMS)],
            ),
            normals: Stage::new(device, height, "normals_main", &[t, rgba16, rgba16, p]),
            resolve: Stage::new(device, height, "resolve_main", &[t, rgba16]),
            downsample: Stage::new(device, height, "downsample_main", &[t, rgba16]),
            pyramid_base: Stage::new(device, height, "pyramid_base_main", &[t, rg32, p, t]),
            pyramid_reduce: Stage::new(device, height, "pyramid_reduce_main", &[t, rg32, p]),
            cones: Stage::new(device, height, "cone_main", &[t, t, r32, p]),
        }
    }
}

/// What one job was last built from, and its scratch textures.
struct Record {
    generation: u64,
    source: bevy::render::render_resource::TextureId,
    heights: bevy::render::render_resource::TextureId,
    size: (u32, u32),
    /// `Rgba16Float`: (depth, parallax value) of mip 0 on their way back (`height.wgsl`, stage 1).
    scratch: Texture,
    /// `R32Float` cone ratios (zero until built).
    cones: Texture,
}

/// The render world's side: pipelines, what each job was built from, what was reported.
#[derive(Resource, Default)]
pub(crate) struct GpuHeightState {
    pipelines: Option<Pipelines>,
    records: HashMap<AssetId<Image>, Record>,
    reported: bevy::platform::collections::HashSet<AssetId<Image>>,
}

/// Records the build of every job whose source changed (every frame for every-frame jobs).
pub(crate) fn build_gpu_heights(
    jobs: Option<Res<GpuHeightJobs>>,
    images: Res<RenderAssets<GpuImage>>,
    device: Res<RenderDevice>,
    reports: Res<GpuReports>,
    mut state: ResMut<GpuHeightState>,
    mut ctx: RenderContext,
) {
    let Some(jobs) = jobs else { return };
    if jobs.0.is_empty() {
        state.records.clear();
        return;
    }
    let state = &mut *state;
    state.records.retain(|id, _| jobs.0.iter().any(|j| j.heights == *id));
    state.reported.retain(|id| jobs.0.iter().any(|j| j.heights == *id));
    for job in &jobs.0 {
        let (Some(source), Some(heights), Some(pyramid), Some(normals)) =
            (images.get(job.source), images.get(job.heights), images.get(job.pyramid), images.get(job.normals))
        else {
            continue;
        };
        if state.reported.contains(&job.heights) {
            continue;
        }
        let size = (source.texture_descriptor.size.width, source.texture_descriptor.size.height);
        let mut problem = None;
        if size != job.size {
            if !job.every_frame {
                // An edited image of a new size: the main world makes textures of that size.
                continue;
            }
            problem =
                Some(format!("its size changed from {}x{} to {}x{} texels", job.size.0, job.size.1, size.0, size.1));
        } else if job.view_format.is_some_and(|f| !source.texture_descriptor.view_formats.contains(&f)) {
            // The texture with the linear view format is on its way.
            continue;
        }
        if let Some(p) = problem {
            state.reported.insert(job.heights);
            reports.push(job.heights, format!("bevy_pomkit: {}: {p}: drawing the plain StandardMaterial", job.name));
            continue;
        }
        let record = state.records.get(&job.heights);
        let fresh = record.is_some_and(|r| {
            r.generation == job.generation && r.source == source.texture.id() && r.heights == heights.texture.id()
        });
        if fresh && !job.every_frame {
            continue;
        }
        if record.is_none_or(|r| r.size != job.size) {
            let texture = |label: &str, format: TextureFormat| {
                device.create_texture(&TextureDescriptor {
                    label: Some(label),
                    size: Extent3d { width: job.size.0, height: job.size.1, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: TextureDimension::D2,
                    format,
                    usage: TextureUsages::TEXTURE_BINDING | TextureUsages::STORAGE_BINDING,
                    view_formats: &[],
                })
            };
            state.records.insert(
                job.heights,
                Record {
                    generation: 0,
                    source: source.texture.id(),
                    heights: heights.texture.id(),
                    size: job.size,
                    scratch: texture("pomkit heights scratch", TextureFormat::Rgba16Float),
                    cones: texture("pomkit cones", TextureFormat::R32Float),
                },
            );
        }
        let pipelines = state.pipelines.get_or_insert_with(|| Pipelines::new(&device));
        let Some(record) = state.records.get_mut(&job.heights) else { continue };
        encode(&device, ctx.command_encoder(), pipelines, job, [source, heights, pyramid, normals], record);
        record.generation = job.generation;
        record.source = source.texture.id();
        record.heights = heights.texture.id();
    }
}

/// Records import -> normals -> mips -> pyramid (-> cones) of `job` as one compute pass.
fn encode(
    device: &RenderDevice,
    encoder: &mut bevy::render::render_resource::CommandEncoder,
    p: &Pipelines,
    job: &GpuJob,
    [source, heights, pyramid, normals]: [&GpuImage; 4],
    record: &Record,
) {
    let (w, h) = job.size;
    let (pw, ph) = (w.next_power_of_two(), h.next_power_of_two());
    let pyramid_levels = 32 - pw.max(ph).leading_zeros();
    let level_size = |l: u32| (w.div_ceil(1 << l.min(31)), h.div_ceil(1 << l.min(31)));
    let depth_scale = pomkit_core::trace::sanitized_depth_scale(job.depth_scale);
    let edges = pomkit_gpu::library::edges_index(job.edges);

    // The uniform records: the import's, the normals', then one per pyramid level.
    let stride = HEIGHT_PARAMS.next_multiple_of(u64::from(device.limits().min_uniform_buffer_offset_alignment));
    let mut bytes: Vec<u8> = Vec::new();
    let mut push = |words: [u32; 8]| -> u64 {
        let offset = bytes.len() as u64;
        bytes.extend(words.iter().flat_map(|v| v.to_le_bytes()));
        bytes.resize((offset + stride) as usize, 0);
        offset
    };
    let import_params = push([w, h, job.channel, job.encoding, 0, 0, 0, 0]);
    let record_of = |src: (u32, u32), dst: (u32, u32)| {
        [src.0, src.1, dst.0, dst.1, edges, 0, (depth_scale * w as f32).to_bits(), pyramid_levels]
    };
    let normals_params = push(record_of((w, h), (w, h)));
    let pyramid_params: Vec<u64> = (0..pyramid_levels)
        .map(|l| push(record_of(if l == 0 { (w, h) } else { level_size(l - 1) }, level_size(l))))
        .collect();
    let params = device.create_buffer_with_data(&BufferInitDescriptor {
        label: Some("pomkit height build params"),
        contents: &bytes,
        usage: BufferUsages::UNIFORM,
    });
    let uniform = |offset: u64, size: u64| {
        BindingResource::Buffer(BufferBinding { buffer: &params, offset, size: BufferSize::new(size) })
    };

    let level = |t: &Texture, l: u32| -> TextureView {
        t.create_view(&TextureViewDescriptor { base_mip_level: l, mip_level_count: Some(1), ..default() })
    };
    let source_view = source.texture.create_view(&TextureViewDescriptor {
        format: job.view_format,
        base_mip_level: 0,
        mip_level_count: Some(1),
        dimension: Some(TextureViewDimension::D2),
        ..default()
    });
    let height_levels: Vec<TextureView> =
        (0..heights.texture_descriptor.mip_level_count).map(|l| level(&heights.texture, l)).collect();
    let pyramid_views: Vec<TextureView> = (0..pyramid_levels).map(|l| level(&pyramid.texture, l)).collect();
    let pyramid_all = pyramid.texture.create_view(&TextureViewDescriptor::default());
    let normals_view = level(&normals.texture, 0);
    let scratch = record.scratch.create_view(&TextureViewDescriptor::default());
    let cones = record.cones.create_view(&TextureViewDescriptor::default());
    fn view(v: &TextureView) -> BindingResource<'_> {
        BindingResource::TextureView(v)
    }

    let mut pass = encoder
        .begin_compute_pass(&ComputePassDescriptor { label: Some("pomkit height build"), timestamp_writes: None });
    let mut dispatch = |stage: &Stage, resources: &[BindingResource<'_>], (dw, dh): (u32, u32)| {
        let entries: Vec<BindGroupEntry<'_>> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| BindGroupEntry { binding: i as u32, resource: r.clone() })
            .collect();
        let group = device.create_bind_group(None, &stage.layout, &entries);
        pass.set_pipeline(&stage.pipeline);
        pass.set_bind_group(0, &*group, &[]);
        pass.dispatch_workgroups(dw.div_ceil(WORKGROUP), dh.div_ceil(WORKGROUP), 1);
    };
    let mip0 = &height_levels[0];
    // Import, then normals and parallax values via the scratch texture back into mip 0.
    dispatch(&p.import, &[view(&source_view), view(mip0), uniform(import_params, IMPORT_PARAMS)], (w, h));
    dispatch(
        &p.normals,
        &[view(mip0), view(&normals_view), view(&scratch), uniform(normals_params, HEIGHT_PARAMS)],
        (w, h),
    );
    dispatch(&p.resolve, &[view(&scratch), view(mip0)], (w, h));
    // The mips, each from the one above.
    for (k, pair) in height_levels.windows(2).enumerate() {
        let k = k as u32 + 1;
        dispatch(&p.downsample, &[view(&pair[0]), view(&pair[1])], ((w >> k).max(1), (h >> k).max(1)));
    }
    // The pyramid: level 0 from the depths (and the cones, zero until built), then upward.
    for (l, &offset) in pyramid_params.iter().enumerate() {
        let size = level_size(l as u32);
        if l == 0 {
            let r = [view(mip0), view(&pyramid_views[0]), uniform(offset, HEIGHT_PARAMS), view(&cones)];
            dispatch(&p.pyramid_base, &r, size);
        } else {
            let r = [view(&pyramid_views[l - 1]), view(&pyramid_views[l]), uniform(offset, HEIGHT_PARAMS)];
            dispatch(&p.pyramid_reduce, &r, size);
        }
    }
    // Cones from the finished pyramid, then level 0 again to take them into its green.
    if job.cones {
        let r = [view(mip0), view(&pyramid_all), view(&cones), uniform(normals_params, HEIGHT_PARAMS)];
        dispatch(&p.cones, &r, (w, h));
        let r = [view(mip0), view(&pyramid_views[0]), uniform(pyramid_params[0], HEIGHT_PARAMS), view(&cones)];
        dispatch(&p.pyramid_base, &r, (w, h));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, format: TextureFormat, usage: RenderAssetUsages) -> Image {
        let mut image = Image::new_uninit(
            Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            TextureDimension::D2,
            format,
            usage,
        );
        image.texture_descriptor.usage = TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING;
        image
    }

    #[test]
    fn sources_the_import_cannot_read_are_refused_with_the_reason() {
        let gpu = RenderAssetUsages::RENDER_WORLD;
        let refused = |i: &Image, c: Channel| check_source(i, c).err().unwrap_or_default();
        assert!(refused(&image(8, 8, TextureFormat::R32Uint, gpu), Channel::Luma).contains("format R32Uint"));
        assert!(refused(&image(8, 8, TextureFormat::Depth32Float, gpu), Channel::R).contains("Depth32Float"));
        assert!(refused(&image(0, 8, TextureFormat::R32Float, gpu), Channel::R).contains("0x8 texels"));
        assert!(
            refused(&image(8, 8, TextureFormat::R32Float, RenderAssetUsages::MAIN_WORLD), Channel::R)
                .contains("main world only")
        );
        assert!(refused(&image(8, 8, TextureFormat::R32Float, gpu), Channel::A).contains("no alpha"));
        let mut unbound = image(8, 8, TextureFormat::R32Float, gpu);
        unbound.texture_descriptor.usage = TextureUsages::STORAGE_BINDING;
        assert!(refused(&unbound, Channel::R).contains("TEXTURE_BINDING"));
    }

    #[test]
    fn channels_follow_the_cpu_reading() {
        let gpu = RenderAssetUsages::RENDER_WORLD;
        let channel = |f: TextureFormat, c: Channel| check_source(&image(4, 4, f, gpu), c).map(|s| s.channel);
        // Luma of colour formats; the one channel of grey ones (as the CPU reads them).
        assert_eq!(channel(TextureFormat::Rgba16Float, Channel::Luma), Ok(CHANNEL_LUMA));
        assert_eq!(channel(TextureFormat::R16Float, Channel::Luma), Ok(0));
        assert_eq!(channel(TextureFormat::Rg8Unorm, Channel::B), Ok(0));
        assert_eq!(channel(TextureFormat::Rgba8Unorm, Channel::A), Ok(3));
        // sRGB: read through the linear view, which the texture must list.
        let srgb = check_source(&image(4, 4, TextureFormat::Rgba8UnormSrgb, gpu), Channel::R).unwrap();
        assert_eq!(srgb.view_format, Some(TextureFormat::Rgba8Unorm));
        assert_eq!(srgb.needs_view_format, Some(&[TextureFormat::Rgba8Unorm][..]));
    }

    #[test]
    fn without_a_device_that_runs_compute_passes_the_cpu_builds() {
        // No render app in a unit test: nothing was detected.
        assert!(!gpu_heights_supported());
        assert_eq!(effective(HeightBuild::GpuEveryFrame), HeightBuild::Cpu);
        assert_eq!(effective(HeightBuild::Cpu), HeightBuild::Cpu);
    }
}
