//! A renderer that is not pomkit's, using pomkit as a component.
//!
//! ```text
//! cargo run --release -p pomkit-gpu --example foreign_renderer -- [OUT.png] [--technique NAME]
//! ```
//!
//! Everything a graphics program already has is its own here: the device, the vertex format
//! (position, normal, glTF tangent, uv; no pomkit attribute), the camera (reverse-Z: near = 1,
//! far = 0, compare `Greater`), 4x MSAA resolved to an sRGB texture, and the shading in
//! `foreign_renderer.wgsl` (GGX + Lambert, a sun, hemisphere ambient, tone mapping, fog).
//!
//! pomkit supplies three things:
//! - the shader library, composed in front of the program's shader, which calls it to trace the
//!   relief (`pomkit_trace`), shadow it (`pomkit_shadow`) and move the pixel's depth onto the
//!   traced point (`pomkit_pixel_depth`), so relief meets other geometry where real geometry
//!   would;
//! - the `PomkitParams` uniform's bytes: changing the technique or the depth scale is one
//!   `queue.write_buffer`;
//! - `HeightResource`, which derives from the program's own height texture (`R8Unorm`, white =
//!   high) the textures the library traces against: mips and a maximum-height pyramid.

use std::error::Error;

use pomkit_core::glam::camera::rh::{proj::directx::perspective_infinite_reverse, view::look_at_mat4};
use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{Technique, TraceParams};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_gpu::height::HeightPasses;
use pomkit_gpu::host::{HeightBindings, HeightResource, HeightResourceOptions};
use pomkit_gpu::library::PomkitParams;
use wgpu::util::DeviceExt;

type Result<T> = std::result::Result<T, Box<dyn Error>>;

const SIZE: (u32, u32) = (960, 540);
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Distance of the near plane, where reverse-Z depth is 1 (0 at infinity).
const NEAR: f32 = 0.05;
/// Background and fog colour: linear values of the sRGB target (the pass's clear colour).
const FOG: [f32; 3] = [0.62, 0.7, 0.78];

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> std::process::ExitCode {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let mut out_path = String::from("foreign_renderer.png");
    let mut technique = Technique::Pom;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--technique" {
            technique = args.next().ok_or("--technique needs a name (e.g. pom, relief, exact)")?.parse()?;
        } else {
            out_path = arg;
        }
    }

    let (device, queue, adapter) = open_device()?;
    println!("adapter: {} ({:?}, {:?})", adapter.name, adapter.backend, adapter.device_type);
    let renderer = Renderer::new(device, queue, 4);

    // The scene: a brick cube sunk a little into a cobblestone floor.
    let floor_mesh = renderer.mesh(&floor(60.0, 1.5));
    let cube_mesh = renderer.mesh(&cube(CUBE_CENTRE, CUBE, 2.0));
    let (cobbles_depth, bricks_depth) = (0.04, 0.05);
    let cobbles = renderer.material(&generate(Pattern::Cobblestones, 256, 256), &COBBLES, cobbles_depth)?;
    let bricks = renderer.material(&generate(Pattern::Bricks, 256, 256), &BRICKS, bricks_depth)?;
    // pomkit's parameters: one buffer write per material. Changing them later (a settings menu
    // switching technique, an animated depth scale) is this same call; nothing is rebuilt.
    cobbles.set_params(&renderer.queue, &params(technique, cobbles_depth)?);
    bricks.set_params(&renderer.queue, &params(technique, bricks_depth)?);

    let view = View {
        eye: Vec3::new(3.1, 1.4, 3.2),
        target: Vec3::new(-0.3, 0.5, 0.0),
        fov_y_degrees: 40.0,
        sun: Vec3::new(0.8, 0.38, 0.22),
        occluder: (CUBE_CENTRE - CUBE / 2.0, CUBE_CENTRE + CUBE / 2.0),
    };
    let image = renderer.render(&view, &[(&floor_mesh, &cobbles), (&cube_mesh, &bricks)], SIZE)?;
    image::save_buffer(&out_path, &image.rgba, SIZE.0, SIZE.1, image::ExtendedColorType::Rgba8)
        .map_err(|e| format!("writing {out_path}: {e}"))?;
    println!("wrote {out_path} ({} technique)", technique.name());
    Ok(())
}

/// The program's own device: the first adapter wgpu offers on Vulkan, Metal or DX12 (Mesa's
/// lavapipe on a machine without a GPU) unless `WGPU_BACKEND` names others, with default
/// features and limits.
fn open_device() -> Result<(wgpu::Device, wgpu::Queue, wgpu::AdapterInfo)> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
    let instance = wgpu::Instance::new(desc);
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))?;
    Ok((device, queue, adapter.get_info()))
}

/// pomkit's parameters for one material, from pomkit_core's types: `depth_scale` UV units
/// deep with wrapping edges, the default sample counts, soft self-shadows, the relief traced up
/// to mip 4 (the LOD fade).
fn params(technique: Technique, depth_scale: f32) -> Result<PomkitParams> {
    let shadow = ShadowParams { mode: ShadowMode::Soft, softness: 0.1 };
    Ok(PomkitParams::new(technique, shadow, TraceParams::default(), depth_scale, EdgeMode::Wrap, 4.0)?)
}

// ---------------------------------------------------------------------------------------------
// Geometry: the program's own vertex format
// ---------------------------------------------------------------------------------------------

/// Floats per interleaved vertex: position (3), normal (3), tangent (xyz + w handedness, glTF),
/// uv (2).
const VERTEX_FLOATS: usize = 12;

/// World-space triangles in the program's vertex format.
#[derive(Default)]
struct Geometry {
    vertices: Vec<f32>,
    indices: Vec<u32>,
}

impl Geometry {
    /// A rectangle with UV (0, 0) at `origin`, u growing along `edge_u` and v along `edge_v` to
    /// `tiles`. glTF's bitangent B = w cross(N, T) runs along -v ("up the image"), so with w = +1
    /// the front face is the side `edge_v x edge_u` points to.
    fn quad(&mut self, origin: Vec3, edge_u: Vec3, edge_v: Vec3, tiles: Vec2) {
        let n = edge_v.cross(edge_u).normalize();
        let t = edge_u.normalize();
        let first = (self.vertices.len() / VERTEX_FLOATS) as u32;
        for (s, r) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            let p = origin + edge_u * s + edge_v * r;
            self.vertices.extend([p.x, p.y, p.z, n.x, n.y, n.z, t.x, t.y, t.z, 1.0, s * tiles.x, r * tiles.y]);
        }
        // Counter-clockwise seen from the front.
        self.indices.extend([0, 2, 1, 0, 3, 2].map(|i| first + i));
    }
}

/// Side of the cube.
const CUBE: f32 = 1.6;
/// The cube's centre: sunk 6 cm into the floor, so the two reliefs cut into each other.
const CUBE_CENTRE: Vec3 = Vec3::new(0.0, CUBE / 2.0 - 0.06, 0.0);

/// A square floor at y = 0, `side` wide, one UV tile every `tile` world units. Its UVs are not
/// stretched, but the shader does not know that: it derives the UV scale from derivatives.
fn floor(side: f32, tile: f32) -> Geometry {
    let mut g = Geometry::default();
    let h = side / 2.0;
    g.quad(Vec3::new(-h, 0.0, -h), Vec3::X * side, Vec3::Z * side, Vec2::splat(side / tile));
    g
}

/// A cube without its bottom face, `tiles` UV tiles along each edge, v running down the sides.
fn cube(centre: Vec3, side: f32, tiles: f32) -> Geometry {
    let mut g = Geometry::default();
    for n in [Vec3::X, Vec3::NEG_X, Vec3::Z, Vec3::NEG_Z, Vec3::Y] {
        let (u, v) = if n == Vec3::Y { (Vec3::X, Vec3::Z) } else { (Vec3::Y.cross(n), Vec3::NEG_Y) };
        let (u, v) = (u * side, v * side);
        g.quad(centre + n * (side / 2.0) - (u + v) / 2.0, u, v, Vec2::splat(tiles));
    }
    g
}

/// A mesh on the GPU.
struct Mesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
}

// ---------------------------------------------------------------------------------------------
// Materials: the program's shading constants, pomkit's parameters, the height textures
// ---------------------------------------------------------------------------------------------

/// The shader's `Look`: albedo (linear) and roughness of the lowest and the highest points, the
/// heights between which one blends into the other, and metallic.
struct Look {
    low: [f32; 4],
    high: [f32; 4],
    ramp: [f32; 4],
}

const BRICKS: Look = Look { low: [0.25, 0.24, 0.22, 0.95], high: [0.42, 0.12, 0.06, 0.6], ramp: [0.5, 0.8, 0.0, 0.0] };
const COBBLES: Look =
    Look { low: [0.07, 0.055, 0.045, 1.0], high: [0.28, 0.26, 0.23, 0.4], ramp: [0.3, 0.7, 0.0, 0.0] };

/// One material: the uniform buffer holding its `PomkitParams` and its bind group (group 1).
struct Material {
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl Material {
    /// Writes pomkit's parameters (technique, depth scale, shadows, ...): a buffer write,
    /// nothing rebuilt. (`iterative` reads a parallax map baked for the depth scale given to
    /// [`Renderer::material`]; rebuild the height resource when changing it for `iterative`.)
    fn set_params(&self, queue: &wgpu::Queue, params: &PomkitParams) {
        queue.write_buffer(&self.params, 0, &params.to_bytes());
    }
}

// ---------------------------------------------------------------------------------------------
// The renderer
// ---------------------------------------------------------------------------------------------

/// What one frame looks at.
struct View {
    eye: Vec3,
    target: Vec3,
    fov_y_degrees: f32,
    /// Direction toward the sun (any length).
    sun: Vec3,
    /// Corners of a box casting a sun shadow (empty: no shadow).
    occluder: (Vec3, Vec3),
}

impl View {
    /// World to clip space: an infinite reverse-Z perspective (near = 1, infinity = 0).
    fn view_proj(&self, aspect: f32) -> Mat4 {
        perspective_infinite_reverse(self.fov_y_degrees.to_radians(), aspect, NEAR)
            * look_at_mat4(self.eye, self.target, Vec3::Y)
    }
}

/// A rendered frame read back to the CPU.
struct Image {
    /// sRGB bytes, row-major, top row first.
    rgba: Vec<u8>,
    /// The depth buffer (reverse-Z), for single-sampled renderers only (an MSAA depth buffer
    /// cannot be copied).
    #[cfg_attr(not(test), expect(dead_code, reason = "the tests read it"))]
    depth: Option<Vec<f32>>,
}

/// The program's renderer: one pipeline (its shader with pomkit's library in front), drawing
/// meshes with materials into a reverse-Z depth buffer and an MSAA colour target.
struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// pomkit's compute passes that build height resources (one set per device).
    passes: HeightPasses,
    pipeline: wgpu::RenderPipeline,
    frame: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    material_layout: wgpu::BindGroupLayout,
    samples: u32,
}

/// Where pomkit's textures and sampler sit in the material's bind group (the shader's
/// `heights`, `pyramid`, `samp`).
const HEIGHT_BINDINGS: HeightBindings = HeightBindings { heights: 2, pyramid: 3, sampler: 4 };

impl Renderer {
    /// The pipeline and shared resources for `samples` samples per pixel (1 or 4).
    fn new(device: wgpu::Device, queue: wgpu::Queue, samples: u32) -> Self {
        // The program's shader with pomkit's library in front of it.
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("foreign_renderer.wgsl"),
            source: wgpu::ShaderSource::Wgsl(
                pomkit_gpu::library::compose(include_str!("foreign_renderer.wgsl")).into(),
            ),
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT)],
        });
        // The material's bind group: the program's two uniforms, then pomkit's three entries.
        let fragment = wgpu::ShaderStages::FRAGMENT;
        let mut entries = vec![uniform_entry(0, fragment), uniform_entry(1, fragment)];
        entries.extend(HeightResource::layout_entries(HEIGHT_BINDINGS, fragment));
        let material_layout = device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("material"), entries: &entries });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("foreign renderer"),
            bind_group_layouts: &[Some(&frame_layout), Some(&material_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("foreign renderer"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: (VERTEX_FLOATS * 4) as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4, 3 => Float32x2],
                })],
            },
            primitive: wgpu::PrimitiveState { cull_mode: Some(wgpu::Face::Back), ..Default::default() },
            // Reverse-Z: nearer is larger.
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(COLOR_FORMAT.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let frame = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame"),
            size: FRAME_FLOATS as u64 * 4,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: frame.as_entire_binding() }],
        });
        let passes = HeightPasses::new(&device);
        Self { device, queue, passes, pipeline, frame, frame_group, material_layout, samples }
    }

    fn mesh(&self, g: &Geometry) -> Mesh {
        let vertices: Vec<u8> = g.vertices.iter().flat_map(|f| f.to_le_bytes()).collect();
        let indices: Vec<u8> = g.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
        let buffer = |label, contents: &[u8], usage| {
            self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        Mesh {
            vertices: buffer("vertices", &vertices, wgpu::BufferUsages::VERTEX),
            indices: buffer("indices", &indices, wgpu::BufferUsages::INDEX),
            index_count: g.indices.len() as u32,
        }
    }

    /// A material with the height field `field`, which the program keeps as its own `R8Unorm`
    /// texture (white = high, as an art tool would save it), for relief `depth_scale` UV units
    /// deep. Write its parameters with [`Material::set_params`] before drawing it.
    fn material(&self, field: &HeightField, look: &Look, depth_scale: f32) -> Result<Material> {
        let texels: Vec<u8> = field.heights().iter().map(|h| (h * 255.0).round() as u8).collect();
        let texture = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("height map"),
                size: wgpu::Extent3d { width: field.width(), height: field.height(), depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::R8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            &texels,
        );
        // pomkit reads it into its own textures: depth with mips, and the maximum-height pyramid.
        let opts = HeightResourceOptions { depth_scale, ..Default::default() };
        let heights =
            HeightResource::from_texture(&self.device, &self.queue, &self.passes, &texture, &opts, "height map")?;

        let params = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit params"),
            size: PomkitParams::SIZE,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let look: Vec<u8> = [look.low, look.high, look.ramp].iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
        let look = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("look"),
            contents: &look,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: look.as_entire_binding() },
        ];
        entries.extend(heights.bind_group_entries(HEIGHT_BINDINGS));
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("material"),
            layout: &self.material_layout,
            entries: &entries,
        });
        // A program whose heights change keeps `heights` (and `texture`) and records
        // `heights.encode_rebuild` after each change. These never change: the bind group, which
        // keeps the textures it refers to alive, is all this one keeps.
        Ok(Material { params, bind_group })
    }

    /// Draws `draws` from `view` into a new `size` target and reads it back.
    fn render(&self, view: &View, draws: &[(&Mesh, &Material)], size: (u32, u32)) -> Result<Image> {
        self.queue.write_buffer(&self.frame, 0, &frame_bytes(view, size.0 as f32 / size.1 as f32));
        let extent = wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 };
        let target = |label, format, sample_count, usage| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: extent,
                mip_level_count: 1,
                sample_count,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT | usage,
                view_formats: &[],
            })
        };
        let copy = wgpu::TextureUsages::COPY_SRC;
        let msaa = self.samples > 1;
        // With MSAA, the pass renders into a multisampled texture and resolves into `resolved`.
        let resolved = target("colour", COLOR_FORMAT, 1, copy);
        let multisampled =
            msaa.then(|| target("colour (msaa)", COLOR_FORMAT, self.samples, wgpu::TextureUsages::empty()));
        let depth = target("depth", DEPTH_FORMAT, self.samples, if msaa { wgpu::TextureUsages::empty() } else { copy });
        let view_of = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (resolved_view, depth_view) = (view_of(&resolved), view_of(&depth));
        let multisampled_view = multisampled.as_ref().map(view_of);

        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let [r, g, b] = FOG.map(f64::from);
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("scene"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: multisampled_view.as_ref().unwrap_or(&resolved_view),
                    depth_slice: None,
                    resolve_target: msaa.then_some(&resolved_view),
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a: 1.0 }),
                        store: if msaa { wgpu::StoreOp::Discard } else { wgpu::StoreOp::Store },
                    },
                })],
                // Reverse-Z: cleared to 0, the far end.
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.frame_group, &[]);
            for (mesh, material) in draws {
                pass.set_bind_group(1, &material.bind_group, &[]);
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh.index_count, 0, 0..1);
            }
        }
        self.queue.submit([encoder.finish()]);
        let rgba = self.read_back(&resolved, wgpu::TextureAspect::All)?;
        let depth = if msaa {
            None
        } else {
            let bytes = self.read_back(&depth, wgpu::TextureAspect::DepthOnly)?;
            Some(bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
        };
        Ok(Image { rgba, depth })
    }

    /// The texels of a single-sampled texture with 4-byte texels, rows packed.
    fn read_back(&self, texture: &wgpu::Texture, aspect: wgpu::TextureAspect) -> Result<Vec<u8>> {
        let (w, h) = (texture.width(), texture.height());
        let row = (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(row * h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(h) },
            },
            texture.size(),
        );
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| drop(tx.send(r)));
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        rx.recv()??;
        let bytes = buffer.slice(..).get_mapped_range()?;
        Ok(bytes.chunks_exact(row as usize).flat_map(|r| &r[..(w * 4) as usize]).copied().collect())
    }
}

/// Floats of the shader's `Frame`: a matrix and eight vectors.
const FRAME_FLOATS: usize = 16 + 8 * 4;

/// The shader's `Frame` for `view` at `aspect` (width / height).
fn frame_bytes(view: &View, aspect: f32) -> Vec<u8> {
    let sun = view.sun.normalize();
    let (lo, hi) = view.occluder;
    let mut f: Vec<f32> = view.view_proj(aspect).to_cols_array().to_vec();
    f.extend([view.eye.x, view.eye.y, view.eye.z, 1.0]);
    f.extend([sun.x, sun.y, sun.z, 0.0]);
    f.extend([5.0, 4.5, 3.8, 0.0]); // sun radiance
    f.extend([0.22, 0.27, 0.36, 0.0]); // sky ambient
    f.extend([0.09, 0.08, 0.07, 0.0]); // ground ambient
    f.extend([FOG[0], FOG[1], FOG[2], 0.04]); // fog colour and density (per world unit)
    f.extend([lo.x, lo.y, lo.z, 0.0, hi.x, hi.y, hi.z, 0.0]);
    debug_assert_eq!(f.len(), FRAME_FLOATS);
    f.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Checks that fail if the integration were wrong: each against geometry computed here on the
/// CPU, not against a captured image. Without a GPU adapter they print "skipping: ..." and pass,
/// unless `POMKIT_REQUIRE_GPU=1`.
#[cfg(test)]
mod tests {
    use super::*;

    const TEST_SIZE: (u32, u32) = (192, 128);
    /// One colour whatever the height.
    const PLAIN: Look = Look { low: [0.5, 0.2, 0.1, 0.6], high: [0.5, 0.2, 0.1, 0.6], ramp: [0.0, 1.0, 0.0, 0.0] };

    /// A renderer with `samples` per pixel on the program's own device, or `None` (after
    /// printing why) without an adapter.
    fn renderer(samples: u32) -> Option<Renderer> {
        match open_device() {
            Ok((device, queue, _)) => Some(Renderer::new(device, queue, samples)),
            Err(e) => {
                pomkit_gpu::context::skip_without_gpu(&e);
                None
            }
        }
    }

    /// `technique` with `depth_scale`, soft shadows, and no LOD fade (the analytic checks want
    /// the full technique everywhere).
    fn unfaded(technique: Technique, depth_scale: f32) -> PomkitParams {
        let shadow = ShadowParams { mode: ShadowMode::Soft, softness: 0.1 };
        PomkitParams::new(technique, shadow, TraceParams::default(), depth_scale, EdgeMode::Wrap, 100.0)
            .expect("valid parameters")
    }

    /// A view down onto the floor from `eye` (every pixel sees the floor), the sun at `sun`.
    fn floor_view(eye: Vec3, sun: Vec3) -> View {
        View { eye, target: Vec3::ZERO, fov_y_degrees: 50.0, sun, occluder: (Vec3::ZERO, Vec3::ZERO) }
    }

    /// Where the ray through the centre of pixel `(x, y)` meets the plane at height `plane_y`,
    /// and that point's reverse-Z depth; `None` where it does not meet it in front of the eye.
    fn on_plane(view: &View, size: (u32, u32), (x, y): (u32, u32), plane_y: f32) -> Option<(Vec3, f32)> {
        let view_proj = view.view_proj(size.0 as f32 / size.1 as f32);
        let ndc = Vec2::new((x as f32 + 0.5) / size.0 as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / size.1 as f32 * 2.0);
        let inverse = view_proj.inverse();
        let near = inverse.project_point3(ndc.extend(1.0));
        let farther = inverse.project_point3(ndc.extend(0.5));
        let t = (plane_y - near.y) / (farther.y - near.y);
        (t > 0.0).then(|| {
            let p = near + (farther - near) * t;
            let clip = view_proj * p.extend(1.0);
            (p, clip.z / clip.w)
        })
    }

    fn pixels(size: (u32, u32)) -> impl Iterator<Item = (u32, u32)> {
        (0..size.1).flat_map(move |y| (0..size.0).map(move |x| (x, y)))
    }

    fn depth_of(image: &Image) -> &[f32] {
        image.depth.as_deref().expect("single-sampled renders keep their depth")
    }

    /// The traced image differs from the flat one, and pixel depth offset only ever moves depths
    /// farther (smaller, in reverse-Z), mostly by a visible amount.
    #[test]
    fn tracing_changes_the_image_and_pushes_depth_back() {
        let Some(r) = renderer(1) else { return };
        let floor_mesh = r.mesh(&floor(20.0, 1.5));
        let bricks = r.material(&generate(Pattern::Bricks, 128, 128), &BRICKS, 0.05).unwrap();
        let view = floor_view(Vec3::new(0.0, 1.6, 2.2), Vec3::new(0.6, 0.5, 0.3));
        let render = |technique, depth_scale| {
            // A parameter change is one buffer write; nothing else is rebuilt.
            bricks.set_params(&r.queue, &unfaded(technique, depth_scale));
            r.render(&view, &[(&floor_mesh, &bricks)], TEST_SIZE).unwrap()
        };
        let flat = render(Technique::Flat, 0.05);
        let flat_deeper = render(Technique::Flat, 0.1);
        let pom = render(Technique::Pom, 0.05);
        let pom_deeper = render(Technique::Pom, 0.1);

        // `flat` ignores the depth scale; `pom` does not.
        assert_eq!(flat.rgba, flat_deeper.rgba, "flat shading changed with the depth scale");
        assert_eq!(depth_of(&flat), depth_of(&flat_deeper), "flat depths changed with the depth scale");
        let changed = |a: &Image, b: &Image| {
            a.rgba
                .chunks(4)
                .zip(b.rgba.chunks(4))
                .filter(|(p, q)| p.iter().zip(*q).any(|(x, y)| x.abs_diff(*y) > 8))
                .count()
        };
        let total = (TEST_SIZE.0 * TEST_SIZE.1) as usize;
        let (traced, deeper) = (changed(&flat, &pom), changed(&pom, &pom_deeper));
        println!("pixels changed: flat -> pom {traced}, pom -> pom at twice the depth {deeper}, of {total}");
        assert!(traced > total / 5, "pom changed only {traced} of {total} pixels from flat");
        assert!(deeper > total / 10, "doubling the depth scale changed only {deeper} of {total} pixels");

        // Reverse-Z: the traced point is never nearer than the polygon (depth never larger),
        // and mostly visibly farther: the mortar lies 70 % of the depth range down, and even the
        // brick faces lie up to 6 % down.
        let (flat_depth, pom_depth) = (depth_of(&flat), depth_of(&pom));
        let mut farther = 0;
        for (&f, &p) in flat_depth.iter().zip(pom_depth) {
            assert!(f > 0.0, "a pixel missed the floor: the test view is wrong");
            assert!(p <= f * (1.0 + 1e-6), "pixel depth offset moved a pixel nearer: {p} > {f}");
            farther += usize::from(p < f * (1.0 - 1e-3));
        }
        println!("pixels pushed back: {farther} of {total}");
        assert!(farther > total / 10, "only {farther} of {total} pixels were pushed back");
    }

    /// On a height field of one constant depth d, the traced surface is the plane d *
    /// depth_scale * (world length of a UV unit) below the polygon: the depth buffer holds that
    /// plane's reverse-Z depth, computed here by ray casting, and the flat render the floor's.
    #[test]
    fn pixel_depth_is_the_depth_of_the_traced_plane() {
        let Some(r) = renderer(1) else { return };
        let (tile, depth_scale) = (1.5, 0.05);
        let floor_mesh = r.mesh(&floor(40.0, tile));
        // Height 128/255 in the program's R8Unorm texture: depth 1 - 128/255.
        let field = HeightField::from_height_fn(32, 32, |_, _| 128.0 / 255.0);
        let depth = 1.0 - 128.0 / 255.0;
        let plain = r.material(&field, &COBBLES, depth_scale).unwrap();
        let view = floor_view(Vec3::new(0.4, 2.0, 3.0), Vec3::Y);
        let size = TEST_SIZE;
        for (technique, plane_y) in [
            (Technique::Flat, 0.0),
            (Technique::Pom, -depth * depth_scale * tile),
            (Technique::Exact, -depth * depth_scale * tile),
        ] {
            plain.set_params(&r.queue, &unfaded(technique, depth_scale));
            let image = r.render(&view, &[(&floor_mesh, &plain)], size).unwrap();
            let got = depth_of(&image);
            let mut worst = 0.0f32;
            for (x, y) in pixels(size) {
                let (_, expected) = on_plane(&view, size, (x, y), plane_y).expect("every pixel sees the floor");
                let (_, polygon) = on_plane(&view, size, (x, y), 0.0).expect("every pixel sees the floor");
                let z = got[(y * size.0 + x) as usize];
                let error = (z - expected).abs() / expected;
                worst = worst.max(error);
                assert!(
                    error < 1e-3,
                    "{technique}: pixel ({x}, {y}) has depth {z}, the plane at y = {plane_y} has {expected} \
                     (the polygon {polygon})"
                );
                if technique != Technique::Flat {
                    // The check tells the two planes apart by far more than its tolerance.
                    assert!((polygon - expected) / expected > 5e-3, "offset too small to test at ({x}, {y})");
                }
            }
            println!("{technique}: worst relative depth error {worst:e}");
        }
    }

    /// A raised bump lit from +x is brighter on its +x side, and lit from the image's top
    /// (-v, the tangent frame's +B) brighter on its top (ARCHITECTURE.md, Conventions).
    #[test]
    fn bump_lit_from_plus_x_is_brighter_on_its_plus_x_side() {
        let Some(r) = renderer(1) else { return };
        // One tile, 1.5 world units, centred at the origin: u along +x, v along +z.
        let tile = 1.5;
        let floor_mesh = r.mesh(&floor(tile, tile));
        let n = 64;
        let bump = HeightField::from_height_fn(n, n, |x, y| {
            let r = Vec2::new(x as f32 + 0.5, y as f32 + 0.5).distance(Vec2::splat(n as f32 / 2.0)) / n as f32;
            if r < 0.35 { 0.5 + 0.5 * (std::f32::consts::PI * r / 0.35).cos() } else { 0.0 }
        });
        let look = Look { low: [0.5; 4], high: [0.5; 4], ramp: [0.0, 1.0, 0.0, 0.0] };
        let material = r.material(&bump, &look, 0.08).unwrap();
        material.set_params(&r.queue, &unfaded(Technique::Pom, 0.08));
        let eye = Vec3::new(0.0, 2.4, 1.0);
        // Mean luminance of the pixels whose floor point lies in `region` (world x, z).
        let mean = |sun: Vec3, region: &dyn Fn(Vec3) -> bool| {
            let view = floor_view(eye, sun);
            let image = r.render(&view, &[(&floor_mesh, &material)], TEST_SIZE).unwrap();
            let (mut sum, mut count) = (0.0, 0);
            for (x, y) in pixels(TEST_SIZE) {
                if on_plane(&view, TEST_SIZE, (x, y), 0.0).is_some_and(|(p, _)| region(p)) {
                    let px = &image.rgba[(y * TEST_SIZE.0 + x) as usize * 4..][..3];
                    sum += 0.2126 * f32::from(px[0]) + 0.7152 * f32::from(px[1]) + 0.0722 * f32::from(px[2]);
                    count += 1;
                }
            }
            assert!(count > 20, "only {count} pixels in a region: the test view is wrong");
            sum / count as f32
        };
        // The bump's flanks: between 0.1 and 0.4 of a tile from its centre, within a band.
        let side = |p: f32, q: f32| (0.1 * tile..0.4 * tile).contains(&p) && q.abs() < 0.15 * tile;
        let (elevation, flat) = (0.5f32.sin(), 0.5f32.cos());
        let from_plus_x = Vec3::new(flat, elevation, 0.0);
        let (plus_x, minus_x) = (mean(from_plus_x, &|p| side(p.x, p.z)), mean(from_plus_x, &|p| side(-p.x, p.z)));
        println!("lit from +x: +x side {plus_x:.1}, -x side {minus_x:.1}");
        assert!(
            plus_x > minus_x + 10.0,
            "lit from +x, the +x side ({plus_x}) is not brighter than the -x side ({minus_x})"
        );
        // The image's top is -v: world -z here, the far side from the eye.
        let from_top = Vec3::new(0.0, elevation, -flat);
        let (top, bottom) = (mean(from_top, &|p| side(-p.z, p.x)), mean(from_top, &|p| side(p.z, p.x)));
        println!("lit from the top: top side {top:.1}, bottom side {bottom:.1}");
        assert!(
            top > bottom + 10.0,
            "lit from the top, the top side ({top}) is not brighter than the bottom ({bottom})"
        );
    }

    /// 4x MSAA resolves the cube's silhouette to blends of cube and background, and changes
    /// nothing away from it. The cube is drawn `flat` in one colour, so that each face is nearly
    /// uniform and a blend must lie between the colours around it. (With relief, a partly
    /// covered pixel is shaded at its centre, outside the triangle, at a UV the single-sampled
    /// image may not show nearby.)
    #[test]
    fn msaa_blends_the_silhouette_only() {
        let (Some(single), Some(multi)) = (renderer(1), renderer(4)) else { return };
        let view = View {
            eye: Vec3::new(2.9, 1.9, 3.6),
            target: CUBE_CENTRE,
            fov_y_degrees: 40.0,
            sun: Vec3::new(0.8, 0.38, 0.22),
            occluder: (Vec3::ZERO, Vec3::ZERO),
        };
        let draw = |r: &Renderer| {
            let mesh = r.mesh(&cube(CUBE_CENTRE, CUBE, 2.0));
            let plain = r.material(&generate(Pattern::Bricks, 128, 128), &PLAIN, 0.05).unwrap();
            plain.set_params(&r.queue, &unfaded(Technique::Flat, 0.05));
            r.render(&view, &[(&mesh, &plain)], TEST_SIZE).unwrap().rgba
        };
        let (one, four) = (draw(&single), draw(&multi));
        let (w, h) = (TEST_SIZE.0 as i64, TEST_SIZE.1 as i64);
        let at = |img: &[u8], x: i64, y: i64| -> [u8; 3] {
            let i = (y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize * 4;
            [img[i], img[i + 1], img[i + 2]]
        };
        // The background: the clear colour, sRGB-encoded by the target.
        let encode = |c: f32| {
            let s = if c <= 0.0031308 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
            (s * 255.0).round() as u8
        };
        let background = FOG.map(encode);
        let near = |a: [u8; 3], b: [u8; 3], tolerance: u8| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= tolerance);
        assert!(
            near(at(&one, 0, 0), background, 1),
            "corner {:?} is not the clear colour {background:?}",
            at(&one, 0, 0)
        );

        let (lo, hi) = one.chunks(4).fold(([255u8; 3], [0u8; 3]), |(lo, hi), p| {
            (std::array::from_fn(|c| lo[c].min(p[c])), std::array::from_fn(|c| hi[c].max(p[c])))
        });
        let (mut edge, mut blended, mut interior, mut interior_same) = (0, 0, 0, 0);
        for y in 0..h {
            for x in 0..w {
                let window: Vec<[u8; 3]> =
                    (-1..=1).flat_map(|j| (-1..=1).map(move |i| (i, j))).map(|(i, j)| at(&one, x + i, y + j)).collect();
                let cube_pixels = window.iter().filter(|&&c| !near(c, background, 1)).count();
                let (a, b) = (at(&one, x, y), at(&four, x, y));
                if cube_pixels == 0 {
                    // Far from the cube both are the background.
                    assert!(near(b, background, 1), "MSAA changed a background pixel ({x}, {y}): {b:?}");
                } else if cube_pixels == window.len() {
                    interior += 1;
                    interior_same += usize::from(near(a, b, 2));
                } else {
                    // On the silhouette: the resolve averages samples of the background and of
                    // the cube's faces (a sliver of a face may cover samples but no pixel
                    // centre), so each channel lies within the range of the single-sampled image.
                    edge += 1;
                    for c in 0..3 {
                        assert!(
                            b[c] + 2 >= lo[c] && b[c] <= hi[c].saturating_add(2),
                            "({x}, {y}) resolved {b:?} outside {lo:?}..{hi:?}"
                        );
                    }
                    blended += usize::from(!near(b, a, 2) && !near(b, background, 2));
                }
            }
        }
        println!("silhouette pixels {edge}, of them blended {blended}; interior {interior}, unchanged {interior_same}");
        assert!(edge > 100, "only {edge} silhouette pixels: the test view is wrong");
        assert!(blended > edge / 5, "only {blended} of {edge} silhouette pixels are blends: no MSAA resolve?");
        assert!(
            interior_same * 100 > interior * 95,
            "MSAA changed {} of {interior} interior pixels",
            interior - interior_same
        );
    }
}
