//! Plane bounds per pyramid cell on the GPU: the texture the shader library's
//! `pomkit_planes_first_hit` (and `pomkit_trace_planes`) walks on.

use pomkit_core::trace::Surface;

use crate::GpuError;

/// An `Rgba32Uint` texture of a height map's plane bounds ([`pomkit_core::planes::CellPlanes`]):
/// mip `l - 1` holds pyramid level `l`'s cells in its top-left `MaxHeightPyramid::level_size`
/// texels, as [`crate::library::plane_texels`] packs them. The base is half the pyramid's
/// power-of-two padded base ([`crate::height::HeightMaps::pyramid`]), so mip `l - 1` always
/// holds level `l`; a 1x1 map, whose pyramid has one level, gets a 1x1 texture that is never
/// read.
#[derive(Debug)]
pub struct PlaneBounds {
    /// The texture (`TEXTURE_BINDING | COPY_DST`).
    pub texture: wgpu::Texture,
    /// A view over all its mips, for a `texture_2d<u32>` binding.
    pub view: wgpu::TextureView,
}

impl PlaneBounds {
    /// The texture's format.
    pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

    /// Uploads the plane bounds of `surface` ([`Surface::use_plane_bounds`] must have built
    /// them; the pyramid's least depths come along in each texel).
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if `surface` has no plane bounds; [`GpuError::TooLarge`] if the
    /// texture exceeds the device's `max_texture_dimension_2d`.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, surface: &Surface, label: &str) -> Result<Self, GpuError> {
        let Some(planes) = surface.plane_bounds() else {
            return Err(GpuError::Unsupported(format!(
                "plane bounds of \"{label}\": the surface has none (call Surface::use_plane_bounds first)"
            )));
        };
        let pyramid = surface.pyramid();
        let (w, h) = (surface.field().width(), surface.field().height());
        let (width, height) = ((w.next_power_of_two() / 2).max(1), (h.next_power_of_two() / 2).max(1));
        let limit = device.limits().max_texture_dimension_2d;
        if width > limit || height > limit {
            return Err(GpuError::TooLarge { what: format!("plane bounds of \"{label}\""), width, height, limit });
        }
        let mips = u32::try_from(pyramid.len().saturating_sub(1)).unwrap_or(u32::MAX).max(1);
        let bounds = Self::allocate(device, width, height, mips, label);
        for level in 1..pyramid.len() {
            let (cw, ch) = pyramid.level_size(level);
            let bytes: Vec<u8> = crate::library::plane_texels(planes, pyramid, level)
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &bounds.texture,
                    mip_level: u32::try_from(level - 1).unwrap_or(0),
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                &bytes,
                wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(cw * 16), rows_per_image: None },
                wgpu::Extent3d { width: cw, height: ch, depth_or_array_layers: 1 },
            );
        }
        Ok(bounds)
    }

    /// A 1x1 texture of zeros, to fill a `texture_2d<u32>` binding that is not read.
    #[must_use]
    pub fn empty(device: &wgpu::Device) -> Self {
        Self::allocate(device, 1, 1, 1, "no plane bounds")
    }

    fn allocate(device: &wgpu::Device, width: u32, height: u32, mips: u32, label: &str) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&format!("{label} plane bounds")),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: mips,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: Self::FORMAT,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        Self { texture, view }
    }
}
