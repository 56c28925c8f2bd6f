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
        let f = surface.field();
        Self::from_texels(device, queue, (f.width(), f.height()), &Self::texels(surface, label)?, label)
    }

    /// The texels of [`PlaneBounds::new`] for `surface`, level by level from level 1
    /// ([`crate::library::plane_texels`]), to upload with [`PlaneBounds::from_texels`] (a
    /// renderer can keep them for the next material on the same heights).
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if `surface` has no plane bounds.
    pub fn texels(surface: &Surface, label: &str) -> Result<Vec<Vec<[u32; 4]>>, GpuError> {
        let Some(planes) = surface.plane_bounds() else {
            return Err(GpuError::Unsupported(format!(
                "plane bounds of \"{label}\": the surface has none (call Surface::use_plane_bounds first)"
            )));
        };
        let pyramid = surface.pyramid();
        Ok((1..pyramid.len()).map(|level| crate::library::plane_texels(planes, pyramid, level)).collect())
    }

    /// Uploads `levels` ([`PlaneBounds::texels`]) of a `width` x `height` height map.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if `levels` are not those of a map of that size;
    /// [`GpuError::TooLarge`] if the texture exceeds the device's `max_texture_dimension_2d`.
    pub fn from_texels(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        (w, h): (u32, u32),
        levels: &[Vec<[u32; 4]>],
        label: &str,
    ) -> Result<Self, GpuError> {
        let (width, height) = ((w.next_power_of_two() / 2).max(1), (h.next_power_of_two() / 2).max(1));
        let limit = device.limits().max_texture_dimension_2d;
        if width > limit || height > limit {
            return Err(GpuError::TooLarge { what: format!("plane bounds of \"{label}\""), width, height, limit });
        }
        // The pyramid's levels above 0: the sides halved rounding up, `level` times.
        let size = |level: u32| (w.div_ceil(1 << level.min(31)), h.div_ceil(1 << level.min(31)));
        let expected = 32 - w.max(h).max(1).next_power_of_two().leading_zeros() - 1;
        let fits = levels.len() == expected as usize
            && levels.iter().enumerate().all(|(k, l)| {
                let (cw, ch) = size(k as u32 + 1);
                l.len() == cw as usize * ch as usize
            });
        if !fits {
            return Err(GpuError::Unsupported(format!(
                "plane bounds of \"{label}\": {} levels that are not those of a {w}x{h} height map",
                levels.len()
            )));
        }
        let bounds = Self::allocate(device, width, height, expected.max(1), label);
        for (k, texels) in levels.iter().enumerate() {
            let (cw, ch) = size(k as u32 + 1);
            let bytes: Vec<u8> = texels.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
            queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &bounds.texture,
                    mip_level: k as u32,
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
