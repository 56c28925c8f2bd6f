//! [`FrameUniforms`]: the camera and lights the material's shader reads per frame.

use super::*;
/// A camera as the material's shader sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameView {
    /// World to clip space of the target.
    pub view_proj: Mat4,
    /// World to clip space for pixel depth offset: only its z and w rows are used, so any
    /// aspect ratio will do (pomkit passes its aspect-free projection; hosts pass `view_proj`).
    pub depth_proj: Mat4,
    /// The eye's world position.
    pub eye: Vec3,
}

/// Camera and lights for one frame (bind group 0).
pub struct FrameUniforms {
    buffer: wgpu::Buffer,
    /// The bind group to set at index 0.
    pub bind_group: wgpu::BindGroup,
}

impl FrameUniforms {
    /// A frame uniform block.
    #[must_use]
    pub fn new(ctx: &GpuContext, pipelines: &MaterialPipelines) -> Self {
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit frame"),
            size: Self::bytes_len(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pomkit frame"),
            layout: &pipelines.frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
        });
        Self { buffer, bind_group }
    }

    fn bytes_len() -> u64 {
        // 2 mat4 + eye + ambient + 4 lights x 2 vec4 + 2 u32 (padded to 16).
        (64 * 2 + 16 * 2 + 32 * MAX_LIGHTS as u64) + 16
    }

    /// Writes the camera (for a target of `aspect` = width / height), lights, ambient light and
    /// the LOD tint switch.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for more than [`MAX_LIGHTS`] lights.
    pub fn write(
        &self,
        ctx: &GpuContext,
        camera: &Camera,
        aspect: f32,
        lights: &[Light],
        ambient: Vec3,
        lod_tint: bool,
    ) -> Result<(), GpuError> {
        let view = camera.view();
        self.write_view(
            ctx,
            &FrameView {
                view_proj: camera.projection(aspect) * view,
                depth_proj: camera.projection(1.0) * view,
                eye: camera.eye,
            },
            lights,
            ambient,
            lod_tint,
        )
    }

    /// Writes a host renderer's camera (its own matrices: reverse-Z, infinite far plane or
    /// jitter included), lights, ambient light and the LOD tint switch.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for more than [`MAX_LIGHTS`] lights or a matrix or eye that is
    /// not finite.
    pub fn write_view(
        &self,
        ctx: &GpuContext,
        view: &FrameView,
        lights: &[Light],
        ambient: Vec3,
        lod_tint: bool,
    ) -> Result<(), GpuError> {
        if !(view.view_proj.is_finite() && view.depth_proj.is_finite() && view.eye.is_finite()) {
            return Err(GpuError::Unsupported("a camera matrix or eye position that is not finite".into()));
        }
        if lights.len() > MAX_LIGHTS {
            return Err(GpuError::Unsupported(format!(
                "{} lights: the GPU renderer shades at most {MAX_LIGHTS} per frame",
                lights.len()
            )));
        }
        let u = frame_block(view, lights, ambient, lod_tint);
        ctx.queue.write_buffer(&self.buffer, 0, &u.bytes());
        Ok(())
    }
}

/// Each member's name and byte offset in `render.wgsl`'s `Frame` uniform as
/// [`FrameUniforms::write_view`] writes it.
#[must_use]
pub fn frame_layout() -> Vec<(&'static str, usize)> {
    let view = FrameView { view_proj: Mat4::IDENTITY, depth_proj: Mat4::IDENTITY, eye: Vec3::ZERO };
    frame_block(&view, &[], Vec3::ZERO, false).layout()
}

pub(super) fn frame_block(view: &FrameView, lights: &[Light], ambient: Vec3, lod_tint: bool) -> Std140 {
    let mut u = Std140::new();
    u.named("view_proj", 16).mat4(view.view_proj);
    u.named("depth_proj", 16).mat4(view.depth_proj);
    u.named("eye", 16).vec4(view.eye.extend(1.0).to_array());
    u.named("ambient", 16).vec4(ambient.extend(0.0).to_array());
    u.named("lights", 16);
    for i in 0..MAX_LIGHTS {
        match lights.get(i) {
            Some(Light::Directional { direction, color, intensity }) => {
                u.vec4(direction.try_normalize().unwrap_or(Vec3::Y).extend(0.0).to_array());
                u.vec4((*color * *intensity).extend(0.0).to_array());
            }
            Some(Light::Point { position, color, intensity }) => {
                u.vec4(position.extend(1.0).to_array());
                u.vec4((*color * *intensity).extend(0.0).to_array());
            }
            None => {
                u.vec4([0.0; 4]);
                u.vec4([0.0; 4]);
            }
        }
    }
    u.named("light_count", 4).u(lights.len() as u32);
    u.named("lod_tint", 4).u(u32::from(lod_tint));
    u
}
