//! Using pomkit's material in your own wgpu render pass, with a height field that changes every
//! frame (Tatarchuk 2006's dynamic height fields).
//!
//! ```text
//! cargo run --release -p pomkit-gpu --example wgpu_material -- [OUT.png]
//! ```
//!
//! The program owns its device, its render target (an sRGB swap-chain-like texture), its depth
//! buffer, its encoder and its render pass. pomkit supplies the pipeline for a technique, the
//! material's bind group, the mesh's buffers, and the compute passes that rebuild a height map's
//! mips, normals, parallax map and maximum-height pyramid after the program changes it.

use std::sync::Arc;

use pomkit_core::demo::procedural_material;
use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::scene::{Camera, Light};
use pomkit_core::trace::Technique;
use pomkit_core::{HeightField, bake::NormalFilter};
use pomkit_gpu::{FrameUniforms, GpuContext, GpuMaterial, GpuMesh, GpuObject, MaterialPipelines, Targets};

const SIZE: (u32, u32) = (960, 540);
const FRAMES: u32 = 8;

/// Bricks with a ripple running across them: frame `k` of the animation.
fn rippled_bricks(bricks: &HeightField, k: u32) -> HeightField {
    let (w, h) = (bricks.width(), bricks.height());
    let heights = bricks.heights();
    HeightField::from_height_fn(w, h, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / w as f32 - 0.5, (y as f32 + 0.5) / h as f32 - 0.5);
        let r = (u * u + v * v).sqrt();
        let wave = 0.5 * (r * 30.0 - k as f32 * 0.8).sin() * (-r * 3.0).exp();
        (heights[(y * w + x) as usize] * 0.5 + 0.5 * (0.5 + wave)).clamp(0.0, 1.0)
    })
}

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    // 0. Optional: without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a
    //    harmless error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let out_path = std::env::args().nth(1).unwrap_or_else(|| "wgpu_material.png".into());

    // 1. Your device. (Here pomkit picks one; `GpuContext::from_device` wraps one you made.)
    let ctx = GpuContext::new()?;
    println!("adapter: {}", ctx.describe());
    let device = &ctx.device;

    // 2. Your targets: an sRGB colour texture and a depth buffer.
    let color_format = wgpu::TextureFormat::Rgba8UnormSrgb;
    let extent = wgpu::Extent3d { width: SIZE.0, height: SIZE.1, depth_or_array_layers: 1 };
    let target = |format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some("example target"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let color = target(color_format, wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC);
    let depth = target(wgpu::TextureFormat::Depth32Float, wgpu::TextureUsages::RENDER_ATTACHMENT);
    let (color_view, depth_view) = (color.create_view(&Default::default()), depth.create_view(&Default::default()));

    // 3. pomkit: pipelines for your target formats, a material, a mesh, an object, a frame.
    let mut pipelines = MaterialPipelines::new(&ctx);
    let targets = Targets { color: color_format, aovs: false, depth: wgpu::TextureFormat::Depth32Float };
    let bricks = generate(Pattern::Bricks, 256, 256);
    let mut material = procedural_material(Pattern::Bricks, 256, 0.06);
    material.height = Some(Arc::new(rippled_bricks(&bricks, 0)));
    material.technique = Technique::Pom;
    // Sobel normals: smoother on a height field that moves (Tatarchuk 2006 section 4).
    let gpu_material = GpuMaterial::new(&ctx, &pipelines, &material, Technique::Pom, NormalFilter::Sobel)?;
    let mesh = Mesh::plane(Vec2::splat(4.0), 1).scale_uvs(Vec2::splat(2.0));
    let gpu_mesh = GpuMesh::new(&ctx, &mesh, None);
    let object = GpuObject::new(&ctx, &pipelines, Mat4::from_rotation_y(0.3));
    let frame = FrameUniforms::new(&ctx, &pipelines);
    let camera = Camera { eye: Vec3::new(0.0, 2.2, 3.0), target: Vec3::new(0.0, 0.0, -0.3), ..Camera::default() };
    let sun = Light::Directional { direction: Vec3::new(0.8, 0.5, 0.3), color: Vec3::ONE, intensity: 1.0 };
    frame.write(&ctx, &camera, SIZE.0 as f32 / SIZE.1 as f32, &[sun], Vec3::splat(0.12), false)?;
    let pipeline = pipelines.pipeline(device, Technique::Pom, false, targets).clone();

    for k in 0..FRAMES {
        // 4. Each frame: change the height field (here from the CPU; a compute shader of yours
        //    could write `gpu_material.height.heights` mip 0 instead), rebuild, then draw.
        gpu_material.update_height(&ctx, &rippled_bricks(&bricks, k))?;
        let mut encoder = device.create_command_encoder(&Default::default());
        gpu_material.encode_rebuild(device, &pipelines, &mut encoder, None);
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("example pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color { r: 0.05, g: 0.07, b: 0.1, a: 1.0 }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            // Your own draws would go here too; pomkit's need three bind groups and one buffer.
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &frame.bind_group, &[]);
            pass.set_bind_group(1, &gpu_material.bind_group, &[]);
            pass.set_bind_group(2, &object.bind_group, &[]);
            pass.set_vertex_buffer(0, gpu_mesh.vertices.slice(..));
            pass.set_index_buffer(gpu_mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..gpu_mesh.index_count, 0, 0..1);
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        println!("frame {k} done");
    }

    // 5. Read the last frame back and save it.
    let row = (SIZE.0 * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("example readback"),
        size: u64::from(row * SIZE.1),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        color.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(SIZE.1) },
        },
        extent,
    );
    ctx.queue.submit([encoder.finish()]);
    let bytes = ctx.read_buffer(&buffer)?;
    let mut rgba = Vec::with_capacity((SIZE.0 * SIZE.1 * 4) as usize);
    for y in 0..SIZE.1 as usize {
        rgba.extend_from_slice(&bytes[y * row as usize..y * row as usize + SIZE.0 as usize * 4]);
    }
    image::save_buffer(&out_path, &rgba, SIZE.0, SIZE.1, image::ExtendedColorType::Rgba8)?;
    println!("wrote {out_path}");
    Ok(())
}
