//! pomkit's material in a host renderer's pipeline state: the host's own vertex layout (separate
//! buffers, no UV scale), reverse-Z, MSAA, and parameter changes through the uniform buffer.
//! The truth each time is pomkit's own pipeline (depth `Less`, its interleaved vertices, one
//! sample) drawing the same scene, or a freshly built material.
//!
//! Without a GPU adapter the tests print "skipping: ..." and pass, unless POMKIT_REQUIRE_GPU=1.

use std::sync::{Arc, Mutex, OnceLock};

use pomkit_core::demo::procedural_material;
use pomkit_core::glam::{Mat4, Vec2, Vec3, Vec4};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::Pattern;
use pomkit_core::scene::{Camera, Light, Material};
use pomkit_core::shadow::ShadowMode;
use pomkit_core::trace::Technique;
use pomkit_core::{EdgeMode, bake::NormalFilter};
use pomkit_gpu::library::{ParamError, PomkitParams};
use pomkit_gpu::{
    AttributeKind, FrameUniforms, FrameView, GpuContext, GpuMaterial, GpuMesh, GpuObject, MaterialPipelines,
    PipelineError, PipelineOptions, VertexLayout,
};
use wgpu::util::DeviceExt;

const W: u32 = 192;
const H: u32 = 144;
const COLOR: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

struct Gpu {
    ctx: GpuContext,
    pipelines: MaterialPipelines,
}

fn gpu() -> Option<&'static Mutex<Gpu>> {
    static GPU: OnceLock<Option<Mutex<Gpu>>> = OnceLock::new();
    GPU.get_or_init(|| match GpuContext::new() {
        Ok(ctx) => {
            let pipelines = MaterialPipelines::new(&ctx);
            Some(Mutex::new(Gpu { ctx, pipelines }))
        }
        Err(e) => {
            pomkit_gpu::context::skip_without_gpu(&e);
            None
        }
    })
    .as_ref()
}

/// A plane seen at an angle, its far edge inside the frame (so it has a silhouette).
fn camera() -> Camera {
    Camera { eye: Vec3::new(0.3, 1.4, 2.2), target: Vec3::new(0.0, 0.0, -0.2), ..Camera::default() }
}

fn mesh() -> Mesh {
    Mesh::plane(Vec2::new(2.0, 1.6), 1).scale_uvs(Vec2::splat(2.0))
}

fn material(technique: Technique, depth_scale: f32, pdo: bool) -> Material {
    let mut m = procedural_material(Pattern::Bricks, 128, depth_scale);
    m.technique = technique;
    m.pixel_depth_offset = pdo;
    m.shadow.mode = ShadowMode::Hard;
    m
}

/// The reverse-Z version of a [0, 1]-depth projection: z' = w - z, so near maps to 1 and far to
/// 0.
fn reverse_z(p: Mat4) -> Mat4 {
    Mat4::from_cols(Vec4::X, Vec4::Y, Vec4::new(0.0, 0.0, -1.0, 0.0), Vec4::new(0.0, 0.0, 1.0, 1.0)) * p
}

/// The mesh as a host keeps it: one buffer per attribute, no UV scale.
struct HostMesh {
    buffers: Vec<wgpu::Buffer>,
    indices: wgpu::Buffer,
    count: u32,
}

fn host_mesh(ctx: &GpuContext, mesh: &Mesh) -> HostMesh {
    let buffer = |floats: Vec<f32>| {
        ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("host attribute"),
            contents: &floats.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>(),
            usage: wgpu::BufferUsages::VERTEX,
        })
    };
    let buffers = vec![
        buffer(mesh.positions.iter().flat_map(|p| p.to_array()).collect()),
        buffer(mesh.normals.iter().flat_map(|p| p.to_array()).collect()),
        buffer(mesh.tangents.iter().flat_map(|p| p.to_array()).collect()),
        buffer(mesh.uvs.iter().flat_map(|p| p.to_array()).collect()),
    ];
    let indices = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("host indices"),
        contents: &mesh.indices.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>(),
        usage: wgpu::BufferUsages::INDEX,
    });
    HostMesh { buffers, indices, count: mesh.indices.len() as u32 }
}

fn host_layout() -> VertexLayout {
    VertexLayout::separate(&[AttributeKind::Position, AttributeKind::Normal, AttributeKind::Tangent, AttributeKind::Uv])
}

/// Colour (RGBA, linear) and, single-sampled, the depth buffer of one frame.
struct Frame {
    color: Vec<f32>,
    depth: Option<Vec<f32>>,
}

enum Vertices<'a> {
    Pomkit(&'a GpuMesh),
    Host(&'a HostMesh),
}

fn draw(g: &mut Gpu, material: &GpuMaterial, vertices: &Vertices<'_>, options: &PipelineOptions) -> Frame {
    draw_model(g, material, vertices, options, Mat4::IDENTITY)
}

/// [`draw`] with the object's model matrix `model`; the pipeline takes the object's front face.
fn draw_model(
    g: &mut Gpu,
    material: &GpuMaterial,
    vertices: &Vertices<'_>,
    options: &PipelineOptions,
    model: Mat4,
) -> Frame {
    let Gpu { ctx, pipelines } = g;
    let device = &ctx.device;
    let cam = camera();
    let aspect = W as f32 / H as f32;
    let reverse = options.reverse_z();
    let view = if reverse {
        let vp = reverse_z(cam.projection(aspect)) * cam.view();
        FrameView { view_proj: vp, depth_proj: vp, eye: cam.eye }
    } else {
        FrameView {
            view_proj: cam.projection(aspect) * cam.view(),
            depth_proj: cam.projection(1.0) * cam.view(),
            eye: cam.eye,
        }
    };
    let frame = FrameUniforms::new(ctx, pipelines);
    let sun = Light::Directional { direction: Vec3::new(0.6, 0.5, 0.4), color: Vec3::ONE, intensity: 1.0 };
    frame.write_view(ctx, &view, &[sun], Vec3::splat(0.1), false).expect("frame");
    let object = GpuObject::new(ctx, pipelines, model);
    let options = &PipelineOptions { front_face: object.front_face(options.front_face), ..options.clone() };
    let pipeline = pipelines
        .pipeline_with(device, material.technique, material.pixel_depth_offset, options)
        .expect("valid options")
        .clone();
    let samples = options.sample_count;
    let texture = |format, sample_count, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("test target"),
            size: wgpu::Extent3d { width: W, height: H, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let copy = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
    let resolved = texture(COLOR, 1, copy);
    let msaa = (samples > 1).then(|| texture(COLOR, samples, wgpu::TextureUsages::RENDER_ATTACHMENT));
    let depth =
        texture(options.depth, samples, if samples > 1 { wgpu::TextureUsages::RENDER_ATTACHMENT } else { copy });
    let resolved_view = resolved.create_view(&Default::default());
    let msaa_view = msaa.as_ref().map(|t| t.create_view(&Default::default()));
    let depth_view = depth.create_view(&Default::default());
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("host pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: msaa_view.as_ref().unwrap_or(&resolved_view),
                depth_slice: None,
                resolve_target: msaa_view.as_ref().map(|_| &resolved_view),
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(if reverse { 0.0 } else { 1.0 }),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &frame.bind_group, &[]);
        pass.set_bind_group(1, &material.bind_group, &[]);
        pass.set_bind_group(2, &object.bind_group, &[]);
        match vertices {
            Vertices::Pomkit(m) => {
                pass.set_vertex_buffer(0, m.vertices.slice(..));
                pass.set_index_buffer(m.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..m.index_count, 0, 0..1);
            }
            Vertices::Host(m) => {
                for (slot, b) in m.buffers.iter().enumerate() {
                    pass.set_vertex_buffer(slot as u32, b.slice(..));
                }
                pass.set_index_buffer(m.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..m.count, 0, 0..1);
            }
        }
    }
    ctx.queue.submit([encoder.finish()]);
    let color = ctx.read_texture(&resolved, 0).expect("read colour");
    let depth = (samples == 1).then(|| ctx.read_texture(&depth, 0).expect("read depth"));
    Frame { color, depth }
}

fn new_material(g: &Gpu, m: &Material) -> GpuMaterial {
    let gm = GpuMaterial::new(&g.ctx, &g.pipelines, m, m.technique, NormalFilter::Central).expect("material");
    let mut encoder = g.ctx.device.create_command_encoder(&Default::default());
    gm.encode_rebuild(&g.ctx.device, &g.pipelines, &mut encoder, None);
    g.ctx.queue.submit([encoder.finish()]);
    gm
}

/// A model matrix that mirrors draws what the mesh mirrored on the CPU (`Mesh::transformed`,
/// which swaps every triangle's winding and flips the tangents' handedness) draws with the
/// identity: the same pixels covered, the same relief lit from the same side. Without the
/// object's front face the mirrored plane is culled away; without the handedness flip its
/// relief is traced and lit upside down in v.
#[test]
fn a_mirroring_model_matrix_draws_what_the_mirrored_mesh_draws() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let m = mesh();
    let gm = new_material(&g, &material(Technique::Pom, 0.06, false));
    let own = PipelineOptions { color: COLOR, ..PipelineOptions::default() };
    for mirror in [Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)), Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0))] {
        // Turned a little so that the mirror is not a symmetry of the picture.
        let model = Mat4::from_rotation_y(0.4) * mirror;
        let on_cpu = GpuMesh::new(&g.ctx, &m.transformed(model), None);
        let reference = draw(&mut g, &gm, &Vertices::Pomkit(&on_cpu), &own);
        let original = GpuMesh::new(&g.ctx, &m, None);
        let mirrored = draw_model(&mut g, &gm, &Vertices::Pomkit(&original), &own, model);
        let n_cover = covered(&reference).iter().filter(|&&c| c).count();
        assert!(n_cover > (W * H / 8) as usize, "the mirrored plane covers {n_cover} pixels");
        let same = covered(&reference).iter().zip(covered(&mirrored)).filter(|(a, b)| **a == *b).count();
        assert!(same as u32 >= W * H - W, "coverage differs on {} pixels", (W * H) as usize - same);
        let p = psnr(&reference.color, &mirrored.color);
        println!("mirror scale {:?}: {p:.1} dB over {n_cover} pixels", mirror.to_scale_rotation_translation().0);
        assert!(p >= 40.0, "the mirroring model matrix draws another picture: {p:.1} dB");
    }
}

/// PSNR (dB) of the colours clamped to [0, 1] (pomkit's one PSNR, `compose::psnr`).
fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let unit = |c: &[f32]| c.iter().map(|x| x.clamp(0.0, 1.0)).collect::<Vec<f32>>();
    pomkit_core::compose::psnr(&unit(a), &unit(b), 1.0)
}

fn covered(f: &Frame) -> Vec<bool> {
    f.color.chunks_exact(4).map(|c| c[3] > 0.5).collect()
}

/// A host's vertices (separate buffers, no UV scale: the shader derives it from derivatives)
/// and a reverse-Z depth buffer draw the same picture as pomkit's own pipeline, and pixel depth
/// offset moves depths away from the eye in both conventions: toward 1 with `Less`, toward 0
/// with reverse-Z, by the same amounts.
#[test]
fn host_layout_and_reverse_z_draw_what_pomkit_draws() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let m = mesh();
    let pomkit_mesh = GpuMesh::new(&g.ctx, &m, None);
    let hm = host_mesh(&g.ctx, &m);
    let with_pdo = new_material(&g, &material(Technique::Pom, 0.06, true));
    let without_pdo = new_material(&g, &material(Technique::Pom, 0.06, false));
    let own = PipelineOptions { color: COLOR, ..PipelineOptions::default() };
    let host = PipelineOptions {
        color: COLOR,
        depth_compare: wgpu::CompareFunction::Greater,
        vertex: host_layout(),
        ..PipelineOptions::default()
    };
    let a = draw(&mut g, &with_pdo, &Vertices::Pomkit(&pomkit_mesh), &own);
    let b = draw(&mut g, &with_pdo, &Vertices::Host(&hm), &host);
    let flat = draw(&mut g, &without_pdo, &Vertices::Pomkit(&pomkit_mesh), &own);

    let cover = covered(&a);
    let n_cover = cover.iter().filter(|&&c| c).count();
    assert!(n_cover > (W * H / 4) as usize && n_cover < (W * H) as usize, "the plane covers {n_cover} pixels");
    assert_eq!(cover, covered(&b), "coverage differs between pomkit's and the host's pipeline");
    let p = psnr(&a.color, &b.color);
    println!("host layout + reverse-Z vs pomkit's pipeline: {p:.1} dB over {n_cover} covered pixels");
    assert!(p >= 45.0, "host pipeline picture differs from pomkit's: {p:.1} dB");

    let (da, db, dflat) = (a.depth.expect("depth"), b.depth.expect("depth"), flat.depth.expect("depth"));
    let mut moved = 0;
    for i in 0..da.len() {
        if !cover[i] {
            assert_eq!((da[i], db[i]), (1.0, 0.0), "uncovered pixel {i} has depth");
            continue;
        }
        assert!(da[i] >= dflat[i] - 1e-7, "pixel depth offset moved pixel {i} toward the eye");
        assert!((db[i] - (1.0 - da[i])).abs() <= 2e-5, "reverse-Z depth {} is not 1 - {}", db[i], da[i]);
        if da[i] > dflat[i] + 1e-6 {
            moved += 1;
        }
    }
    println!("pixel depth offset moved {moved} of {n_cover} covered pixels");
    assert!(moved * 2 > n_cover, "pixel depth offset moved only {moved} of {n_cover} pixels");
}

/// With 4x MSAA the host's pipeline shades each pixel once as before (the interior is the
/// single-sampled picture) and the resolve blends the silhouette: partly covered pixels appear
/// there, and only there.
#[test]
fn msaa_blends_the_silhouette_and_nothing_else() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let m = mesh();
    let hm = host_mesh(&g.ctx, &m);
    let mat = new_material(&g, &material(Technique::Pom, 0.06, false));
    let one = PipelineOptions { color: COLOR, vertex: host_layout(), ..PipelineOptions::default() };
    let four = PipelineOptions { sample_count: 4, ..one.clone() };
    let a = draw(&mut g, &mat, &Vertices::Host(&hm), &one);
    let b = draw(&mut g, &mat, &Vertices::Host(&hm), &four);
    let cover = covered(&a);
    let edge = |i: usize| {
        let (x, y) = ((i as u32 % W) as i64, (i as u32 / W) as i64);
        (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                let (nx, ny) = (x + dx, y + dy);
                nx >= 0
                    && ny >= 0
                    && nx < i64::from(W)
                    && ny < i64::from(H)
                    && cover[(ny * i64::from(W) + nx) as usize] != cover[i]
            })
        })
    };
    let mut partial = 0;
    let mut interior_max = 0.0f32;
    for i in 0..cover.len() {
        let alpha = b.color[4 * i + 3];
        if alpha > 0.01 && alpha < 0.99 {
            assert!(edge(i), "pixel {i} is partly covered but not on the silhouette");
            partial += 1;
        }
        if !edge(i) {
            for c in 0..4 {
                interior_max = interior_max.max((a.color[4 * i + c] - b.color[4 * i + c]).abs());
            }
        }
    }
    println!("4x MSAA: {partial} partly covered pixels; interior differs by at most {interior_max}");
    assert!(partial > 20, "only {partial} partly covered pixels on the silhouette");
    assert!(interior_max <= 2e-3, "MSAA changed the interior by {interior_max}");
}

/// Changing parameters through the uniform buffer (technique, depth scale, shadow mode) draws
/// exactly what a material built with those parameters draws, and differs from before.
#[test]
fn set_params_equals_a_rebuilt_material() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let m = mesh();
    let pm = GpuMesh::new(&g.ctx, &m, None);
    let opts = PipelineOptions { color: COLOR, ..PipelineOptions::default() };
    let before = material(Technique::Pom, 0.03, false);
    let mut after = material(Technique::Relief, 0.07, false);
    after.shadow.mode = ShadowMode::Soft;
    let mut changed = new_material(&g, &before);
    let old = draw(&mut g, &changed, &Vertices::Pomkit(&pm), &opts);
    changed.set_params(&g.ctx, &PomkitParams::from_material(&after, Technique::Relief)).expect("same edges");
    let mut encoder = g.ctx.device.create_command_encoder(&Default::default());
    changed.encode_rebuild(&g.ctx.device, &g.pipelines, &mut encoder, None);
    g.ctx.queue.submit([encoder.finish()]);
    let fresh = new_material(&g, &after);
    let x = draw(&mut g, &changed, &Vertices::Pomkit(&pm), &opts);
    let y = draw(&mut g, &fresh, &Vertices::Pomkit(&pm), &opts);
    assert_eq!(changed.technique, Technique::Relief);
    assert!(x.color == y.color, "set_params drew {:.1} dB from a rebuilt material", psnr(&x.color, &y.color));
    let p = psnr(&old.color, &x.color);
    assert!(p < 40.0, "the change did not show: {p:.1} dB from before");

    let mut clamp = PomkitParams::from_material(&after, Technique::Relief);
    clamp.edges = EdgeMode::Clamp;
    assert_eq!(changed.set_params(&g.ctx, &clamp), Err(ParamError::EdgesChanged));
    let (shadow, trace) = (Default::default(), Default::default());
    let e =
        PomkitParams::new(Technique::Pom, shadow, trace, f32::NAN, EdgeMode::Wrap, 4.0).expect_err("NaN depth scale");
    assert!(e.to_string().contains("depth_scale is NaN"), "{e}");
    let e = PomkitParams::new(Technique::Pom, shadow, trace, 17.0, EdgeMode::Wrap, 4.0).expect_err("too deep");
    assert!(e.to_string().contains("depth_scale is 17"), "{e}");
}

/// What a host can get wrong is an error value naming the problem, never a wgpu panic.
#[test]
fn bad_pipeline_options_are_errors() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let Gpu { ctx, pipelines } = &mut *g;
    let no_tangent = VertexLayout::separate(&[AttributeKind::Position, AttributeKind::Normal, AttributeKind::Uv]);
    let mut overlapping = VertexLayout::interleaved(&[
        AttributeKind::Position,
        AttributeKind::Normal,
        AttributeKind::Tangent,
        AttributeKind::Uv,
    ]);
    overlapping.buffers[0].attributes[3].offset = overlapping.buffers[0].array_stride - 4;
    let mut twice = host_layout();
    twice.buffers.push(twice.buffers[0].clone());
    let cases: Vec<(PipelineOptions, &str)> = vec![
        (PipelineOptions { vertex: no_tangent, ..Default::default() }, "no tangent attribute"),
        (PipelineOptions { vertex: overlapping, ..Default::default() }, "the uv attribute at byte"),
        (PipelineOptions { vertex: twice, ..Default::default() }, "appears 2 times"),
        (PipelineOptions { color: wgpu::TextureFormat::Rgba8Uint, ..Default::default() }, "Rgba8Uint"),
        (PipelineOptions { depth: wgpu::TextureFormat::Rgba8Unorm, ..Default::default() }, "has no depth"),
        (PipelineOptions { sample_count: 3, ..Default::default() }, "3 samples"),
        (PipelineOptions { sample_count: 4, aovs: true, ..Default::default() }, "cannot be multisampled"),
        (
            PipelineOptions { sample_count: 4, color: wgpu::TextureFormat::Rgba32Float, ..Default::default() },
            "Rgba32Float",
        ),
    ];
    for (options, expected) in cases {
        match pipelines.pipeline_with(&ctx.device, Technique::Pom, false, &options) {
            Ok(_) => panic!("accepted {options:?}"),
            Err(e) => {
                let text = e.to_string();
                assert!(text.contains(expected), "{text:?} does not say {expected:?}");
                assert!(!matches!(e, PipelineError::Wgpu(_)), "{text} reached wgpu");
            }
        }
    }
    // And the layouts pomkit offers are accepted.
    for vertex in [VertexLayout::pomkit(), host_layout(), {
        let mut v = host_layout();
        v.buffers.push(pomkit_gpu::VertexBuffer {
            array_stride: 8,
            attributes: vec![pomkit_gpu::VertexAttribute { kind: AttributeKind::UvScale, offset: 0 }],
        });
        v
    }] {
        let options = PipelineOptions { vertex, ..Default::default() };
        pipelines.pipeline_with(&ctx.device, Technique::Exact, true, &options).expect("valid layout");
    }
}

/// pomkit's material on a `HeightResource` (here built from a host's R8Unorm texture) draws
/// what the material built from the same height field draws; a resource whose edge mode
/// differs from the material's is refused.
#[test]
fn material_on_a_host_height_texture_equals_the_material_on_the_field() {
    use pomkit_gpu::height::HeightPasses;
    use pomkit_gpu::host::{HeightResource, HeightResourceOptions};
    let Some(g) = gpu() else { return };
    let mut g = g.lock().expect("gpu lock");
    let m = mesh();
    let pm = GpuMesh::new(&g.ctx, &m, None);
    let opts = PipelineOptions { color: COLOR, ..PipelineOptions::default() };
    let mut mat = material(Technique::Exact, 0.06, true);
    mat.albedo = None;
    mat.shadow.mode = ShadowMode::Exact;
    // Heights with 8 bits, as the host's texture holds them, so both paths see the same field.
    let field = mat.height.as_ref().expect("procedural height").as_ref().clone();
    let bytes: Vec<u8> = field.heights().iter().map(|h| (h.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
    let quantized = pomkit_core::HeightField::from_heights(
        field.width(),
        field.height(),
        bytes.iter().map(|&b| f32::from(b) / 255.0).collect(),
    )
    .expect("field");
    mat.height = Some(Arc::new(quantized));
    let texture = g.ctx.device.create_texture_with_data(
        &g.ctx.queue,
        &wgpu::TextureDescriptor {
            label: Some("host heights"),
            size: wgpu::Extent3d { width: field.width(), height: field.height(), depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        &bytes,
    );
    let passes = HeightPasses::new(&g.ctx.device);
    let ho = HeightResourceOptions { depth_scale: 0.06, ..Default::default() };
    let resource = HeightResource::from_texture(&g.ctx.device, &g.ctx.queue, &passes, &texture, &ho, "host heights")
        .expect("readable texture");
    let on_resource =
        GpuMaterial::with_height_resource(&g.ctx, &g.pipelines, &mat, Technique::Exact, &resource, None).expect("fits");
    let on_field = new_material(&g, &mat);
    let x = draw(&mut g, &on_resource, &Vertices::Pomkit(&pm), &opts);
    let y = draw(&mut g, &on_field, &Vertices::Pomkit(&pm), &opts);
    let p = psnr(&x.color, &y.color);
    println!("material on a host R8 texture vs on the field: {p:.1} dB");
    assert!(p >= 60.0, "the host texture's material differs: {p:.1} dB");
    // The field's material walks on plane bounds (`exact`, its own height map), the host
    // texture's on the least depths: the same hits to rounding, so depths equal to rounding.
    let (dx, dy) = (x.depth.as_ref().expect("depth read back"), y.depth.as_ref().expect("depth read back"));
    let apart = dx.iter().zip(dy).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    println!("pixel depth offset: at most {apart:e} apart");
    assert!(on_field.walks_on_plane_bounds() && !on_resource.walks_on_plane_bounds());
    assert!(apart <= 1e-6, "pixel depth offset differs by {apart:e}");

    mat.edges = EdgeMode::Clamp;
    let e = GpuMaterial::with_height_resource(&g.ctx, &g.pipelines, &mat, Technique::Exact, &resource, None)
        .err()
        .expect("edge modes differ");
    assert!(e.to_string().contains("same edge mode"), "{e}");
}

/// The cone ratios in the material's pyramid (level 0, green), row-major.
fn pyramid_cones(g: &Gpu, gm: &GpuMaterial) -> Vec<f32> {
    let maps = gm.height.as_ref().expect("a height map");
    let texels = g.ctx.read_texture(&maps.pyramid, 0).expect("read the pyramid");
    let stride = maps.pyramid.width();
    let (w, h) = (maps.width, maps.height);
    (0..w * h).map(|k| texels[2 * ((k / w) * stride + k % w) as usize + 1]).collect()
}

#[test]
fn a_cone_material_keeps_its_cones_in_step_with_its_heights() {
    let Some(g) = gpu() else { return };
    let g = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let m = material(Technique::Cone, 0.08, false);
    let field = m.height.clone().expect("a height map");
    let edges = m.edges;
    let gm = new_material(&g, &m);
    // Built on the CPU from the material's heights.
    let cpu = pomkit_core::cone::ConeMap::conservative(&field, edges);
    let gpu_cones = pyramid_cones(&g, &gm);
    assert!(gpu_cones.iter().enumerate().all(|(k, &c)| c == cpu.ratio(k as u32 % 128, k as u32 / 128)));
    // New heights: the old cones go (`cone` walks as `exact`), until the GPU builds new ones.
    let next = pomkit_core::procedural::generate(Pattern::Cobblestones, 128, 128);
    gm.update_height(&g.ctx, &next).expect("same size");
    let rebuild = |gm: &GpuMaterial| {
        let mut encoder = g.ctx.device.create_command_encoder(&Default::default());
        gm.encode_rebuild(&g.ctx.device, &g.pipelines, &mut encoder, None);
        g.ctx.queue.submit([encoder.finish()]);
    };
    rebuild(&gm);
    assert!(pyramid_cones(&g, &gm).iter().all(|&c| c == 0.0), "stale cones survived new heights");
    gm.rebuild_cones();
    rebuild(&gm);
    let rounded: Vec<f32> = next.depths().iter().map(|&d| half::f16::from_f32(d).to_f32()).collect();
    let truth = pomkit_core::cone::ConeMap::conservative(
        &pomkit_core::HeightField::from_depths(128, 128, rounded).unwrap(),
        edges,
    );
    let built = pyramid_cones(&g, &gm);
    let (sum_gpu, sum_cpu) = built.iter().enumerate().fold((0.0f64, 0.0f64), |(a, b), (k, &c)| {
        (a + f64::from(c), b + f64::from(truth.ratio(k as u32 % 128, k as u32 / 128)))
    });
    assert!((sum_gpu / sum_cpu - 1.0).abs() < 0.03, "GPU cones are {} of the CPU's on average", sum_gpu / sum_cpu);
    // Built once: the next rebuild keeps them rather than searching again.
    rebuild(&gm);
    assert_eq!(pyramid_cones(&g, &gm), built);
}

/// An `exact` material walks on plane bounds where they pay (bricks), and stops once its heights
/// change: with new heights (waves) it draws what a material made from them draws. Bounds left
/// from the old heights would skip cells the new surface fills.
#[test]
fn an_exact_material_leaves_its_plane_bounds_when_its_heights_change() {
    let Some(g) = gpu() else { return };
    let mut g = g.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let m = mesh();
    let pm = GpuMesh::new(&g.ctx, &m, None);
    let opts = PipelineOptions { color: COLOR, ..PipelineOptions::default() };
    let mat = material(Technique::Exact, 0.08, true);
    let gm = new_material(&g, &mat);
    assert!(gm.walks_on_plane_bounds(), "bricks read fewer fetches with plane bounds");
    let mut next = mat.clone();
    next.height = Some(Arc::new(pomkit_core::procedural::generate(Pattern::Waves, 128, 128)));
    let fresh = new_material(&g, &next);
    assert!(fresh.walks_on_plane_bounds(), "so do waves");
    gm.update_height(&g.ctx, next.height.as_deref().expect("waves")).expect("same size");
    assert!(!gm.walks_on_plane_bounds());
    let mut encoder = g.ctx.device.create_command_encoder(&Default::default());
    gm.encode_rebuild(&g.ctx.device, &g.pipelines, &mut encoder, None);
    g.ctx.queue.submit([encoder.finish()]);
    let (x, y) =
        (draw(&mut g, &gm, &Vertices::Pomkit(&pm), &opts), draw(&mut g, &fresh, &Vertices::Pomkit(&pm), &opts));
    let p = psnr(&x.color, &y.color);
    assert!(p >= 60.0, "new heights on the old material: {p:.1} dB from a material made from them");
    // A second rebuild (the heights may have been written by a shader) turns them off too.
    let again = new_material(&g, &next);
    let mut encoder = g.ctx.device.create_command_encoder(&Default::default());
    again.encode_rebuild(&g.ctx.device, &g.pipelines, &mut encoder, None);
    g.ctx.queue.submit([encoder.finish()]);
    assert!(!again.walks_on_plane_bounds());
    let z = draw(&mut g, &again, &Vertices::Pomkit(&pm), &opts);
    assert!(psnr(&z.color, &y.color) >= 60.0);
}

/// The wgpu example, run where `XDG_RUNTIME_DIR` is unset (a container, CI), draws its picture
/// and prints no error: without `util::ensure_runtime_dir`, Mesa's device-select layer
/// prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." twice. `cargo
/// test` builds the examples beside the tests; a run of this test file alone may not have it.
#[test]
fn the_wgpu_example_prints_no_runtime_dir_error() {
    if gpu().is_none() {
        return;
    }
    let exe = std::env::current_exe().expect("test binary");
    let Some(example) = exe.parent().and_then(|deps| deps.parent()).map(|d| d.join("examples/wgpu_material")) else {
        return;
    };
    if !example.is_file() {
        println!("skipping: {} is not built (`cargo test` builds the examples)", example.display());
        return;
    }
    let png = std::env::temp_dir().join(format!("pomkit-wgpu-example-{}.png", std::process::id()));
    let out = std::process::Command::new(&example)
        .arg(&png)
        .env_remove("XDG_RUNTIME_DIR")
        .stdin(std::process::Stdio::null())
        .output()
        .expect("the example runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "the example printed Mesa's runtime-directory error: {err}");
    assert!(png.is_file(), "the example wrote no picture");
    std::fs::remove_file(&png).expect("remove the picture");
}
