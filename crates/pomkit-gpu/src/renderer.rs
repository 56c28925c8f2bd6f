//! Headless rendering of a [`Scene`] to linear colour and AOVs, as `pomkit-cpu` does.

use std::time::Instant;

use glam::{Mat4, Vec2, Vec3};
use pomkit_core::bake::NormalFilter;
use pomkit_core::render::{Mode, RenderError, RenderOptions, RenderOutput, Sample, resolve, validate};
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;

use crate::material::{
    AOV_FORMATS, FrameUniforms, GpuMaterial, GpuMesh, GpuObject, MaterialPipelines, Targets, Variant,
};
use crate::pipeline::PipelineOptions;
use crate::{GpuContext, GpuError};
use pomkit_core::silhouette::vertex_curvature;

/// Why a GPU render could not run.
#[derive(Debug, thiserror::Error)]
pub enum GpuRenderError {
    /// The scene or options are invalid (the same checks as the CPU renderer).
    #[error(transparent)]
    Scene(#[from] RenderError),
    /// The device failed or lacks something.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Times of the last frame, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// The compute passes that rebuilt height maps (mips, normals, parallax, pyramid).
    pub height_passes_ms: f64,
    /// The render pass (every object, every pixel traced and shaded).
    pub render_pass_ms: f64,
    /// Whether the two figures above come from GPU timestamp queries (else wall-clock time of
    /// submit and wait, which includes the driver's overhead).
    pub from_timestamps: bool,
    /// Wall-clock time of the whole `render` call, uploads and readback included.
    pub wall_ms: f64,
}

/// The GPU renderer: `GpuRenderer::new(ctx)` then `render(&scene, &options)`.
pub struct GpuRenderer {
    ctx: GpuContext,
    pipelines: MaterialPipelines,
    timings: Timings,
}

const COLOR: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl GpuRenderer {
    /// A renderer on `ctx`'s device.
    #[must_use]
    pub fn new(ctx: GpuContext) -> Self {
        let pipelines = MaterialPipelines::new(&ctx);
        Self { ctx, pipelines, timings: Timings::default() }
    }

    /// The device.
    #[must_use]
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Times of the last [`GpuRenderer::render`].
    #[must_use]
    pub fn timings(&self) -> Timings {
        self.timings
    }

    /// Renders `scene` as the CPU renderer does (same options, same output types).
    ///
    /// # Errors
    /// [`GpuRenderError::Scene`] for a bad size, a dangling material index or invalid trace
    /// parameters; [`GpuRenderError::Gpu`] for device failures, more than 4 lights, or maps
    /// beyond the device's limits.
    pub fn render(&mut self, scene: &Scene, opts: &RenderOptions) -> Result<RenderOutput, GpuRenderError> {
        // wgpu reports validation errors and allocation failures to an error scope if one is
        // open (else its default handler panics): turn them into errors.
        let oom = self.ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = self.render_inner(scene, opts);
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(oom.pop())];
        if let Some(e) = errors.into_iter().flatten().next() {
            return Err(GpuError::Device(e.to_string()).into());
        }
        result
    }

    fn render_inner(&mut self, scene: &Scene, opts: &RenderOptions) -> Result<RenderOutput, GpuRenderError> {
        let mut prepared = self.prepare_inner(scene, opts)?;
        self.draw_inner(&mut prepared, scene)
    }

    /// Uploads `scene` for drawing with `opts` (meshes, materials, camera, lights): the retained
    /// form for rendering many frames, with height maps that may change between them
    /// ([`GpuScene::set_height`]).
    ///
    /// # Errors
    /// As [`GpuRenderer::render`].
    pub fn prepare(&mut self, scene: &Scene, opts: &RenderOptions) -> Result<GpuScene, GpuRenderError> {
        let validation = self.ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = self.prepare_inner(scene, opts);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(GpuError::Device(e.to_string()).into());
        }
        result
    }

    /// Draws a prepared scene: rebuilds the height maps that changed since the last draw (on the
    /// GPU, by the compute passes), renders, and reads the pixels back. `scene` supplies the
    /// background colour and must be the scene `gpu_scene` was prepared from.
    ///
    /// # Errors
    /// [`GpuRenderError::Gpu`] for device failures.
    pub fn draw(&mut self, gpu_scene: &mut GpuScene, scene: &Scene) -> Result<RenderOutput, GpuRenderError> {
        let validation = self.ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = self.draw_inner(gpu_scene, scene);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(GpuError::Device(e.to_string()).into());
        }
        result
    }

    fn prepare_inner(&mut self, scene: &Scene, opts: &RenderOptions) -> Result<GpuScene, GpuRenderError> {
        validate(scene, opts)?;
        let ss = opts.supersample.clamp(1, 8);
        let (w, h) = (opts.width, opts.height);
        let (sw, sh) = (w * ss, h * ss);
        // Before creating anything: the device's limits, then the memory the frame needs.
        check_frame(&self.ctx.device.limits(), w, h, ss)?;
        // The frame and every material's textures (host memory on a software adapter), and the
        // meshes' buffers, before any is made (docs/LIMITS.md).
        let mut host = frame_host_bytes(w, h, ss, opts.aovs);
        for m in &scene.materials {
            host = host.saturating_add(material_host_bytes(
                m.height.as_ref().map(|f| (f.width(), f.height())),
                m.albedo.as_ref().map(|t| (t.width(), t.height())),
                m.normal_map.as_ref().map(|n| (n.width(), n.height())),
                opts.mode.technique(m.technique) == Technique::Cone,
            ));
        }
        for obj in &scene.objects {
            host =
                host.saturating_add(mesh_host_bytes(obj.mesh.positions.len() as u64, obj.mesh.triangle_count() as u64));
        }
        pomkit_core::memory::check(
            || format!("render of {w}x{h} on the GPU"),
            host,
            "use a smaller --size, a lower --supersample, smaller textures, or --backend cpu",
        )
        .map_err(|e| GpuError::Unsupported(e.to_string()))?;
        let ctx = &self.ctx;
        let frame = FrameUniforms::new(ctx, &self.pipelines);
        frame.write(ctx, &scene.camera, sw as f32 / sh as f32, &scene.lights, scene.ambient, opts.lod_tint)?;

        // Materials: textures, uniforms; height maps rebuilt by the compute passes.
        let mut materials = Vec::with_capacity(scene.materials.len());
        for m in &scene.materials {
            let technique = opts.mode.technique(m.technique);
            materials.push(GpuMaterial::new(ctx, &self.pipelines, m, technique, NormalFilter::Central)?);
        }
        // Objects: world-space meshes (transformed on the CPU exactly as the CPU renderer does,
        // mirrors included), identity model matrix.
        let mut objects = Vec::with_capacity(scene.objects.len());
        for obj in &scene.objects {
            let m = &scene.materials[obj.material];
            let displaced = opts.mode == Mode::Displaced && m.height.is_some();
            let mesh = match (displaced, &m.height) {
                (true, Some(field)) => {
                    let (tris, verts) =
                        obj.mesh.displaced_bounds(field.width(), field.height(), opts.displaced_edge_texels);
                    pomkit_core::memory::check(
                        || format!("the displaced mesh of object \"{}\"", obj.name),
                        pomkit_core::mesh::Mesh::bytes_for(verts, tris).saturating_mul(3),
                        "use smaller height maps, a technique other than displaced, or --backend cpu",
                    )
                    .map_err(|e| GpuError::Unsupported(e.to_string()))?;
                    obj.mesh
                        .try_displaced_for_shading(field, m.edges, m.depth_scale, opts.displaced_edge_texels)
                        .map_err(|e| GpuError::Unsupported(e.to_string()))?
                }
                _ => (*obj.mesh).clone(),
            };
            let world = mesh.transformed(obj.transform);
            let depths: Option<Vec<f32>> = match (&m.height, displaced) {
                (Some(field), true) => Some(world.uvs.iter().map(|&uv| field.sample_bilinear(uv, m.edges)).collect()),
                _ => None,
            };
            check_mesh(&ctx.device.limits(), &obj.name, world.positions.len() as u64, world.indices.len() as u64)?;
            // Silhouettes need the curvature of the surface as drawn (the CPU renderer
            // estimates it on the same world mesh).
            let curvature = materials[obj.material].silhouette.then(|| vertex_curvature(&world));
            let gpu_mesh = GpuMesh::with_curvature(ctx, &world, depths.as_deref(), curvature.as_deref());
            objects.push((obj.material, gpu_mesh, GpuObject::new(ctx, &self.pipelines, Mat4::IDENTITY)));
        }

        let targets = Targets { color: COLOR, aovs: true, depth: DEPTH };
        for gm in &materials {
            self.pipelines
                .pipeline_variant(&ctx.device, gm.technique, Variant::of(gm), &PipelineOptions::from(targets))
                .map_err(|e| GpuError::Unsupported(e.to_string()))?;
        }
        let dirty = vec![true; materials.len()];
        Ok(GpuScene { frame, materials, objects, dirty, width: w, height: h, ss, aovs: opts.aovs })
    }

    /// Draws a prepared scene: the height maps that changed rebuilt, the render pass, the
    /// pixels read back and resolved; the frame's times kept for [`GpuRenderer::timings`].
    fn draw_inner(&mut self, gs: &mut GpuScene, scene: &Scene) -> Result<RenderOutput, GpuRenderError> {
        let start = Instant::now();
        let ctx = &self.ctx;
        let (w, h, ss) = (gs.width, gs.height, gs.ss);
        let targets = FrameTargets::new(ctx, w * ss, h * ss);
        let queries = ctx.timestamps.then(|| Timestamps::new(ctx));

        let (compute_wall, has_compute) = self.rebuild_heights(gs, queries.as_ref())?;
        let render_wall = self.render_pass(gs, &targets, queries.as_ref())?;
        let mut timings = Timings { height_passes_ms: compute_wall, render_pass_ms: render_wall, ..Timings::default() };
        if let Some(queries) = &queries {
            queries.read(ctx, has_compute, &mut timings)?;
        }

        let samples = targets.read_samples(ctx)?;
        timings.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        self.timings = timings;
        Ok(resolve(&samples, w, h, ss, scene.background, gs.aovs).map_err(RenderError::from)?)
    }

    /// Rebuilds every height map that changed since the last draw, in one submission (its
    /// first and last passes timed by `queries`). Returns the wall-clock milliseconds it took
    /// and whether any map was rebuilt.
    fn rebuild_heights(&self, gs: &mut GpuScene, queries: Option<&Timestamps>) -> Result<(f64, bool), GpuError> {
        let ctx = &self.ctx;
        ctx.wait()?;
        let t_compute = Instant::now();
        let mut enc =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pomkit heights") });
        let mut first = true;
        let materials = &gs.materials;
        let rebuild = |i: usize| gs.dirty[i] && materials[i].height.is_some();
        let last = (0..materials.len()).rev().find(|&i| rebuild(i));
        for (i, m) in materials.iter().enumerate() {
            if !rebuild(i) {
                continue;
            }
            let (begin, end) = (first.then_some(0), (Some(i) == last).then_some(1));
            let ts = queries.filter(|_| begin.is_some() || end.is_some()).map(|q| wgpu::ComputePassTimestampWrites {
                query_set: &q.set,
                beginning_of_pass_write_index: begin,
                end_of_pass_write_index: end,
            });
            first = false;
            m.encode_rebuild(&ctx.device, &self.pipelines, &mut enc, ts);
        }
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        gs.dirty.iter_mut().for_each(|d| *d = false);
        Ok((t_compute.elapsed().as_secs_f64() * 1e3, last.is_some()))
    }

    /// Renders every object into `targets` (timed by `queries`, whose results are then copied
    /// where [`Timestamps::read`] maps them). Returns the wall-clock milliseconds it took.
    fn render_pass(
        &self,
        gs: &GpuScene,
        targets: &FrameTargets,
        queries: Option<&Timestamps>,
    ) -> Result<f64, GpuError> {
        let ctx = &self.ctx;
        let t_render = Instant::now();
        let mut enc =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pomkit render") });
        {
            let attachment = |view| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            };
            let views = &targets.views;
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("pomkit scene"),
                color_attachments: &[attachment(&views[0]), attachment(&views[1]), attachment(&views[2])],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &views[3],
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: queries.map(|q| wgpu::RenderPassTimestampWrites {
                    query_set: &q.set,
                    beginning_of_pass_write_index: Some(2),
                    end_of_pass_write_index: Some(3),
                }),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &gs.frame.bind_group, &[]);
            let options = PipelineOptions::from(Targets { color: COLOR, aovs: true, depth: DEPTH });
            for (mi, mesh, object) in &gs.objects {
                let gm = &gs.materials[*mi];
                let Some(pipeline) = self.pipelines.cached_variant(gm.technique, Variant::of(gm), &options) else {
                    continue;
                };
                pass.set_pipeline(pipeline);
                pass.set_bind_group(1, &gm.bind_group, &[]);
                pass.set_bind_group(2, &object.bind_group, &[]);
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh.index_count, 0, 0..1);
            }
        }
        if let Some(q) = queries {
            enc.resolve_query_set(&q.set, 0..4, &q.resolve, 0);
            enc.copy_buffer_to_buffer(&q.resolve, 0, &q.read, 0, 32);
        }
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        Ok(t_render.elapsed().as_secs_f64() * 1e3)
    }
}

/// A frame's render targets at the supersampled size: colour, the two AOV targets and depth.
struct FrameTargets {
    color: wgpu::Texture,
    aov0: wgpu::Texture,
    aov1: wgpu::Texture,
    /// Kept with its view for the frame's length.
    _depth: wgpu::Texture,
    /// Views of the colour, AOV and depth targets, in that order.
    views: Vec<wgpu::TextureView>,
    /// Width and height in samples.
    size: (u32, u32),
}

impl FrameTargets {
    fn new(ctx: &GpuContext, sw: u32, sh: u32) -> Self {
        let make = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width: sw, height: sh, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let rt = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let color = make("pomkit colour", COLOR, rt);
        let aov0 = make("pomkit aov0", AOV_FORMATS[0], rt);
        let aov1 = make("pomkit aov1", AOV_FORMATS[1], rt);
        let depth = make("pomkit depth", DEPTH, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let views: Vec<wgpu::TextureView> =
            [&color, &aov0, &aov1, &depth].iter().map(|t| t.create_view(&Default::default())).collect();
        Self { color, aov0, aov1, _depth: depth, views, size: (sw, sh) }
    }

    /// Reads the targets back as the CPU renderer's samples (`None` where nothing was drawn),
    /// to be resolved exactly as it resolves its own.
    fn read_samples(&self, ctx: &GpuContext) -> Result<Vec<Option<Sample>>, GpuError> {
        let c = ctx.read_texture(&self.color, 0)?;
        let a0 = ctx.read_texture(&self.aov0, 0)?;
        let a1 = ctx.read_texture(&self.aov1, 0)?;
        let (sw, sh) = self.size;
        Ok((0..(sw * sh) as usize)
            .map(|i| {
                let k = i * 4;
                (a1[k + 2] > 0.5).then(|| Sample {
                    color: Vec3::new(c[k], c[k + 1], c[k + 2]),
                    z: 0.0,
                    uv: Vec2::new(a0[k], a0[k + 1]),
                    depth: a0[k + 2],
                    shadow: a0[k + 3],
                    fetches: a1[k],
                    lod: a1[k + 1],
                })
            })
            .collect())
    }
}

/// GPU timestamps of a frame (when the device has them): the height passes' start and end
/// (queries 0 and 1) and the render pass's (2 and 3).
struct Timestamps {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
}

impl Timestamps {
    fn new(ctx: &GpuContext) -> Self {
        let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pomkit timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 4,
        });
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit timestamps"),
            size: 32,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit timestamps read"),
            size: 32,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Self { set, resolve, read }
    }

    /// Replaces the wall-clock times of `timings` with the GPU's (the height passes' 0 when
    /// none ran: `has_compute` false).
    fn read(&self, ctx: &GpuContext, has_compute: bool, timings: &mut Timings) -> Result<(), GpuError> {
        let bytes = ctx.read_buffer(&self.read)?;
        let stamp = |i: usize| u64::from_le_bytes(bytes[i * 8..i * 8 + 8].try_into().unwrap_or([0; 8]));
        let period = f64::from(ctx.queue.get_timestamp_period()) * 1e-6;
        timings.height_passes_ms = if has_compute { stamp(1).saturating_sub(stamp(0)) as f64 * period } else { 0.0 };
        timings.render_pass_ms = stamp(3).saturating_sub(stamp(2)) as f64 * period;
        timings.from_timestamps = true;
        Ok(())
    }
}

/// Bytes per sample of a GPU frame's render targets (colour `Rgba16Float`, the two AOV targets
/// and `Depth32Float`).
const TARGET_BYTES_PER_SAMPLE: u64 = 8 + 16 + 8 + 4;

/// Bytes per texel of the largest readback (the first AOV target, `Rgba32Float`).
const LARGEST_READBACK_TEXEL: u32 = 16;

/// Bytes per vertex of a [`GpuMesh`]'s vertex buffer (15 floats: position, normal, tangent, uv,
/// uv scale, depth).
const VERTEX_BYTES: u64 = 15 * 4;

/// Checks a `w x h` frame with `ss x ss` supersampling against the device's `limits` before
/// anything is created: the render targets against `max_texture_dimension_2d`, and the
/// readback buffers against `max_buffer_size`.
///
/// # Errors
/// [`GpuError::Unsupported`] saying which limit, by how much, and what to do: a smaller
/// `--size` (the largest that fits), a lower `--supersample`, or `--backend cpu`.
pub fn check_frame(limits: &wgpu::Limits, w: u32, h: u32, ss: u32) -> Result<(), GpuError> {
    let ss = ss.max(1);
    let (sw, sh) = (u64::from(w) * u64::from(ss), u64::from(h) * u64::from(ss));
    let dim = u64::from(limits.max_texture_dimension_2d);
    let supersampled =
        if ss > 1 { format!(" with {ss}x{ss} supersampling ({sw}x{sh} samples)") } else { String::new() };
    let lower = if ss > 1 { ", a lower --supersample" } else { "" };
    if sw > dim || sh > dim {
        let largest = dim / u64::from(ss);
        return Err(GpuError::Unsupported(format!(
            "a {w}x{h} frame{supersampled} is larger than this GPU's limit of {dim} texels per side \
             (max_texture_dimension_2d): use a smaller --size (at most {largest}x{largest}){lower}, or --backend cpu"
        )));
    }
    let align = u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let row = (sw * u64::from(LARGEST_READBACK_TEXEL)).div_ceil(align) * align;
    let bytes = row * sh;
    if bytes > limits.max_buffer_size {
        let fmt = pomkit_core::memory::format_bytes;
        // The largest square frame whose readback fits.
        let side = ((limits.max_buffer_size / u64::from(LARGEST_READBACK_TEXEL)) as f64).sqrt() as u64 / u64::from(ss);
        return Err(GpuError::Unsupported(format!(
            "a {w}x{h} frame{supersampled} needs a readback buffer of {}, over this GPU's max_buffer_size of {}: \
             use a smaller --size (about {side}x{side} at most){lower}, or --backend cpu",
            fmt(bytes),
            fmt(limits.max_buffer_size)
        )));
    }
    Ok(())
}

/// The largest frame of at most `w x h` pixels, of the same shape (the aspect ratio kept to
/// within a pixel), that [`check_frame`] admits with `ss x ss` supersampling and that is at most
/// [`pomkit_core::MAX_SIZE`] a side: `(w, h)` itself when it fits. For a frame whose size
/// follows a window (the viewer), which should shrink rather than fail. Each side is at least 1.
#[must_use]
pub fn largest_frame(limits: &wgpu::Limits, w: u32, h: u32, ss: u32) -> (u32, u32) {
    let (w, h) = (w.max(1), h.max(1));
    let fits = |k: f64| {
        let side = |v: u32| ((f64::from(v) * k).floor() as u32).max(1);
        let (a, b) = (side(w), side(h));
        (a <= pomkit_core::MAX_SIZE && b <= pomkit_core::MAX_SIZE && check_frame(limits, a, b, ss).is_ok())
            .then_some((a, b))
    };
    if let Some(whole) = fits(1.0) {
        return whole;
    }
    // Bisect the scale: the checks are monotonic in it.
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if fits(mid).is_some() { lo = mid } else { hi = mid }
    }
    fits(lo).unwrap_or((1, 1))
}

/// Checks an object's vertex and index buffers (`vertices` vertices, `indices` indices)
/// against the device's `max_buffer_size` before they are created.
///
/// # Errors
/// [`GpuError::Unsupported`] naming the object, the buffer's size and the limit.
pub fn check_mesh(limits: &wgpu::Limits, object: &str, vertices: u64, indices: u64) -> Result<(), GpuError> {
    let fmt = pomkit_core::memory::format_bytes;
    for (what, bytes) in [("vertex", vertices * VERTEX_BYTES), ("index", indices * 4)] {
        if bytes > limits.max_buffer_size {
            return Err(GpuError::Unsupported(format!(
                "object \"{object}\" needs a {what} buffer of {} ({vertices} vertices, {} triangles), over this \
                 GPU's max_buffer_size of {}: use a coarser mesh (or a technique other than displaced), or --backend cpu",
                fmt(bytes),
                indices / 3,
                fmt(limits.max_buffer_size)
            )));
        }
    }
    Ok(())
}

/// An upper bound on the host memory a GPU frame takes beyond the scene: the render targets and
/// a readback buffer (host memory on a software adapter such as lavapipe), the read-back texels
/// as floats, the samples, and the output frame with an 8-bit copy for the PNG.
#[must_use]
pub fn frame_host_bytes(w: u32, h: u32, ss: u32, aovs: bool) -> u64 {
    let samples = u64::from(w) * u64::from(h) * u64::from(ss.max(1)).pow(2);
    let readback = 16 + 2 * 16; // the largest readback buffer and its bytes, while converting
    let floats = 3 * 16; // the three targets read back as four floats per sample
    let per_sample = TARGET_BYTES_PER_SAMPLE + readback + floats + std::mem::size_of::<Option<Sample>>() as u64;
    samples.saturating_mul(per_sample) + pomkit_core::render::output_bytes(w, h, aovs) + u64::from(w) * u64::from(h) * 6
}

/// An upper bound on the host memory a material's textures take on the GPU renderer (all of
/// it on a software adapter such as lavapipe, where textures live in host memory): for a
/// `height` map, its mip chain, normals, scratch, cones and maximum-height pyramid (padded to
/// powers of two) and the upload's copies; with `cone`, the cones built on the CPU; for an
/// `albedo` map, its mip chain as linear RGB, as floats and as the texture; for a normal map,
/// its floats and texture.
#[must_use]
pub fn material_host_bytes(
    height: Option<(u32, u32)>,
    albedo: Option<(u32, u32)>,
    normal_map: Option<(u32, u32)>,
    cone: bool,
) -> u64 {
    let texels = |(w, h): (u32, u32)| u64::from(w) * u64::from(h);
    let mut bytes = 0u64;
    if let Some((w, h)) = height {
        let n = texels((w, h));
        let padded = texels((w.next_power_of_two(), h.next_power_of_two()));
        // Heights with mips (8 bytes, 4/3), normals, scratch (8 each), cones (4); the pyramid
        // (8 bytes, 4/3, padded); the upload's floats, half floats and staging copy (32).
        let per = 11 + 8 + 8 + 4 + 32;
        bytes = bytes.saturating_add(n.saturating_mul(per)).saturating_add(padded.saturating_mul(11));
        if cone {
            bytes =
                bytes.saturating_add(pomkit_core::cone::ConeMap::build_bytes(w, h)).saturating_add(n.saturating_mul(8));
        }
    }
    // Albedo: the chain of linear RGB (12 bytes), its floats (16), half floats and texture (8
    // each), all with mips (4/3).
    let a = albedo.map_or(1, texels);
    bytes = bytes.saturating_add(a.saturating_mul(44 * 4).div_ceil(3));
    if let Some(size) = normal_map {
        bytes = bytes.saturating_add(texels(size).saturating_mul(16 + 8 + 8));
    }
    bytes
}

/// An upper bound on the host memory of a mesh of `vertices` and `triangles` on the GPU
/// renderer: the world-space copy, the vertex and index bytes and the buffers.
#[must_use]
pub fn mesh_host_bytes(vertices: u64, triangles: u64) -> u64 {
    pomkit_core::mesh::Mesh::bytes_for(vertices, triangles)
        .saturating_add(vertices.saturating_mul(VERTEX_BYTES * 3))
        .saturating_add(triangles.saturating_mul(12 * 3))
}

/// A scene uploaded to the GPU ([`GpuRenderer::prepare`]), drawn by [`GpuRenderer::draw`].
pub struct GpuScene {
    frame: FrameUniforms,
    materials: Vec<GpuMaterial>,
    objects: Vec<(usize, GpuMesh, GpuObject)>,
    dirty: Vec<bool>,
    width: u32,
    height: u32,
    ss: u32,
    aovs: bool,
}

impl GpuScene {
    /// Material `index`, or an error naming it.
    fn material(&self, index: usize) -> Result<&GpuMaterial, GpuError> {
        self.materials.get(index).ok_or_else(|| {
            GpuError::Unsupported(format!("material {index} does not exist ({} materials)", self.materials.len()))
        })
    }

    /// Replaces material `index`'s height field with `field` (same size): a dynamic height
    /// field. The next [`GpuRenderer::draw`] rebuilds its mips, normals, parallax map and
    /// maximum-height pyramid on the GPU before rendering.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for an index out of range, a material without a height map or
    /// a different size.
    pub fn set_height(
        &mut self,
        ctx: &GpuContext,
        index: usize,
        field: &pomkit_core::HeightField,
    ) -> Result<(), GpuError> {
        let m = self.material(index)?;
        m.update_height(ctx, field)?;
        self.dirty[index] = true;
        Ok(())
    }

    /// Gives material `index` the cones of its current heights (after
    /// [`GpuScene::set_height`], which removes the old ones: `cone` then walks as `exact`), or
    /// removes them; the next [`GpuRenderer::draw`] puts them into the pyramid.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for an index out of range, a material without a height map or
    /// cones of another size.
    pub fn set_cones(
        &mut self,
        ctx: &GpuContext,
        index: usize,
        cones: Option<&pomkit_core::cone::ConeMap>,
    ) -> Result<(), GpuError> {
        let m = self.material(index)?;
        m.set_cones(ctx, cones)?;
        self.dirty[index] = true;
        Ok(())
    }

    /// Moves the camera and changes the lights (and ambient light, and the LOD tint view) of a
    /// prepared scene without uploading anything else: the retained form for a moving camera or
    /// light. The next [`GpuRenderer::draw`] uses them. `scene` must be the scene this one was
    /// prepared from, with only its camera, lights or ambient light changed.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for more than 4 lights.
    pub fn set_view(&self, ctx: &GpuContext, scene: &Scene, lod_tint: bool) -> Result<(), GpuError> {
        let aspect = (self.width * self.ss) as f32 / (self.height * self.ss) as f32;
        self.frame.write(ctx, &scene.camera, aspect, &scene.lights, scene.ambient, lod_tint)
    }

    /// The uploaded materials, in scene order.
    #[must_use]
    pub fn materials(&self) -> &[GpuMaterial] {
        &self.materials
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_frame_fits_the_limits_and_keeps_the_shape() {
        let limits = wgpu::Limits { max_texture_dimension_2d: 8192, max_buffer_size: 256 << 20, ..Default::default() };
        // Fits already: unchanged.
        assert_eq!(largest_frame(&limits, 1280, 720, 1), (1280, 720));
        for (w, h, ss) in [(20000, 2000, 1), (9000, 300, 1), (3000, 5000, 2), (16384, 16384, 1), (12000, 9000, 1)] {
            let (a, b) = largest_frame(&limits, w, h, ss);
            assert!(check_frame(&limits, a, b, ss).is_ok(), "{w}x{h} -> {a}x{b}");
            // The shape is kept to within a pixel (an 8192 clamp of one side alone would not).
            let want = f64::from(w) / f64::from(h);
            assert!((f64::from(a) / f64::from(b) - want).abs() <= want / f64::from(b.min(a)), "{w}x{h} -> {a}x{b}");
            // And it is the largest: the same shape two pixels larger on its shorter side no
            // longer fits.
            let grow = 1.0 + 2.0 / f64::from(a.min(b));
            let bigger = ((f64::from(a) * grow).ceil() as u32, (f64::from(b) * grow).ceil() as u32);
            assert!(check_frame(&limits, bigger.0, bigger.1, ss).is_err(), "{w}x{h} -> {a}x{b} is not the largest");
        }
        // A side over MAX_SIZE on an adapter that would take it shrinks to MAX_SIZE.
        let huge = wgpu::Limits { max_texture_dimension_2d: 65536, max_buffer_size: u64::MAX, ..Default::default() };
        assert_eq!(largest_frame(&huge, 40000, 20000, 1), (pomkit_core::MAX_SIZE, pomkit_core::MAX_SIZE / 2));
    }

    #[test]
    fn frames_over_the_limits_are_refused_with_what_to_do() {
        let limits = wgpu::Limits { max_texture_dimension_2d: 8192, max_buffer_size: 256 << 20, ..Default::default() };
        assert!(check_frame(&limits, 1280, 720, 1).is_ok());
        // 8193 is one texel over the texture limit.
        let err = check_frame(&limits, 8193, 16, 1).unwrap_err().to_string();
        assert!(err.contains("8193x16 frame") && err.contains("limit of 8192"), "{err}");
        assert!(err.contains("at most 8192x8192") && err.contains("--backend cpu"), "{err}");
        let err = check_frame(&limits, 4097, 16, 2).unwrap_err().to_string();
        assert!(err.contains("(8194x32 samples)") && err.contains("at most 4096x4096"), "{err}");
        assert!(err.contains("a lower --supersample"), "{err}");
        // 8192 x 8192 of Rgba32Float read back is 1 GiB: over 256 MiB.
        let err = check_frame(&limits, 8192, 8192, 1).unwrap_err().to_string();
        assert!(err.contains("readback buffer of 1.0 GiB") && err.contains("max_buffer_size of 256.0 MiB"), "{err}");
        assert!(err.contains("about 4096x4096 at most"), "{err}");
        assert!(check_frame(&limits, 4096, 4096, 1).is_ok());
        let err = check_mesh(&limits, "ball", 5_000_000, 30_000_000).unwrap_err().to_string();
        assert!(err.contains("object \"ball\"") && err.contains("vertex buffer of 286.1 MiB"), "{err}");
        assert!(check_mesh(&limits, "ball", 1000, 3000).is_ok());
    }
}
