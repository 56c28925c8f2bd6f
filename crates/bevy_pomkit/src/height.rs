//! Height resources from a Bevy [`Image`]: the textures pomkit's shader library reads, built on
//! the CPU by pomkit-core (the same maps pomkit's GPU passes build, see ARCHITECTURE.md).
//!
//! - `heights`: a full mip chain of depth d in [0, 1] (0 the surface, 1 the deepest point) in
//!   red: `R16Float`, or for a material drawn with the `iterative` technique `Rg16Float` with
//!   the parallax value `clamp(n_z * d, 0, 1)` that it reads in green. The tracers read this
//!   texture at every step, and a one-channel texture is the cheapest to filter.
//! - `pyramid`: the maximum-height (minimum-depth) pyramid of the exact tracer, padded to powers
//!   of two; mip `l` holds level `l` in its top-left corner, in red. `R32Float`, or for a
//!   material drawn with the `cone` technique `Rg32Float` with the conservative cone ratios of
//!   the texel footprints in mip 0's green ([`pomkit_core::cone::ConeMap`]), which the library's
//!   `cone` walk steps on. (Without green, `cone` walks as `exact` does: the same hits.)
//! - `normals`: `Rgba16Float`, the tangent-space normal (x along +u, y up the image, z out of
//!   the surface) baked at Lengyel's scale `depth_scale * width`.

use bevy::asset::RenderAssetUsages;
use bevy::image::{Image, ImageAddressMode, ImageFilterMode, ImageSampler, ImageSamplerDescriptor};
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use pomkit_core::EdgeMode;
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use pomkit_core::heightfield::HeightField;
use pomkit_core::trace::Surface;
use pomkit_gpu::util::f32_to_f16;

/// How the source image's values map to depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MapKind {
    /// White is high (a height map, as pomkit's command line reads them): depth = 1 - value.
    #[default]
    Height,
    /// White is deep (a depth map, as `StandardMaterial::depth_map` expects): depth = value.
    Depth,
}

/// Which channel of the source image holds the height.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Red (the only channel of `R8Unorm`, `R16Unorm`, `R32Float` images).
    R,
    /// Green.
    G,
    /// Blue.
    B,
    /// Alpha.
    A,
    /// Rec. 709 luma of the stored values, `0.2126 R + 0.7152 G + 0.0722 B` (the default, as
    /// pomkit's command line). For a single-channel image it is that channel.
    #[default]
    Luma,
}

/// Why a Bevy image cannot be read as a height map.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HeightImageError {
    /// A texture format this crate cannot read heights from (compressed, depth, integer, ...).
    #[error(
        "its format {0:?} cannot be read as heights (use an 8- or 16-bit unorm or a float format: R8Unorm, Rgba8UnormSrgb, R16Unorm, R32Float, ...)"
    )]
    Format(TextureFormat),
    /// Not a single 2D image.
    #[error("it is not a single 2D image ({0})")]
    Shape(String),
    /// The image holds no pixel data on the CPU (it was created render-world only).
    #[error(
        "it has no pixel data in the main world (give it RenderAssetUsages::MAIN_WORLD so its heights can be read)"
    )]
    NoData,
    /// `Channel::A` of an image without alpha.
    #[error("it has no alpha channel to read heights from (use Channel::Luma, R, G or B)")]
    NoAlpha,
    /// A sample is not finite.
    #[error("its texel ({x}, {y}) is {value}, not a finite number")]
    NotFinite {
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// The value read.
        value: f32,
    },
    /// The pixel data is shorter than the size says.
    #[error("its pixel data holds {got} bytes, {want} expected for its size and format")]
    DataSize {
        /// Bytes present.
        got: usize,
        /// Bytes needed.
        want: usize,
    },
}

/// The texel layout of the formats heights are read from: channels, bytes per channel, and how a
/// channel's bytes become a value.
#[derive(Clone, Copy)]
enum Sample {
    Unorm8,
    Unorm16,
    Float16,
    Float32,
}

fn layout(format: TextureFormat) -> Option<(usize, Sample)> {
    use TextureFormat as F;
    Some(match format {
        F::R8Unorm => (1, Sample::Unorm8),
        F::Rg8Unorm => (2, Sample::Unorm8),
        F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb => (4, Sample::Unorm8),
        // Bevy's image loader labels 16-bit grey and grey-alpha PNGs (what `pomkit bake` and
        // `pomkit gltf attach` write) `R16Uint`/`Rg16Uint`: the same 16-bit numbers, read as unorm.
        F::R16Unorm | F::R16Uint => (1, Sample::Unorm16),
        F::Rg16Unorm | F::Rg16Uint => (2, Sample::Unorm16),
        F::Rgba16Unorm | F::Rgba16Uint => (4, Sample::Unorm16),
        F::R16Float => (1, Sample::Float16),
        F::Rg16Float => (2, Sample::Float16),
        F::Rgba16Float => (4, Sample::Float16),
        F::R32Float => (1, Sample::Float32),
        F::Rg32Float => (2, Sample::Float32),
        F::Rgba32Float => (4, Sample::Float32),
        _ => return None,
    })
}

/// The depths of mip 0 of `image`: the stored values of `channel` (no sRGB decoding: a height
/// map's bytes are data, even where Bevy's loader marked the image sRGB), turned into depth by
/// `kind`. Float values are clamped to [0, 1].
///
/// # Errors
/// [`HeightImageError`] naming what cannot be read.
pub fn depths_from_image(image: &Image, kind: MapKind, channel: Channel) -> Result<HeightField, HeightImageError> {
    let desc = &image.texture_descriptor;
    let format = desc.format;
    let (channels, sample) = layout(format).ok_or(HeightImageError::Format(format))?;
    if desc.dimension != TextureDimension::D2 || desc.size.depth_or_array_layers != 1 {
        return Err(HeightImageError::Shape(format!(
            "{:?} with {} layers",
            desc.dimension, desc.size.depth_or_array_layers
        )));
    }
    let (w, h) = (desc.size.width, desc.size.height);
    if w == 0 || h == 0 {
        return Err(HeightImageError::Shape(format!("{w}x{h} texels")));
    }
    let data = image.data.as_deref().ok_or(HeightImageError::NoData)?;
    let size = match sample {
        Sample::Unorm8 => 1,
        Sample::Unorm16 | Sample::Float16 => 2,
        Sample::Float32 => 4,
    };
    let texel = channels * size;
    let want = w as usize * h as usize * texel;
    if data.len() < want {
        return Err(HeightImageError::DataSize { got: data.len(), want });
    }
    let bgra = matches!(format, TextureFormat::Bgra8Unorm | TextureFormat::Bgra8UnormSrgb);
    // Index of R, G, B, A within a texel, or None when the image lacks it.
    let slot = |c: usize| -> Option<usize> {
        let c = if bgra && c != 3 { 2 - c } else { c };
        (c < channels).then_some(c)
    };
    if channel == Channel::A && channels != 4 {
        return Err(HeightImageError::NoAlpha);
    }
    let read = |t: &[u8], c: usize| -> f32 {
        let b = &t[c * size..(c + 1) * size];
        match sample {
            Sample::Unorm8 => f32::from(b[0]) / 255.0,
            Sample::Unorm16 => f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
            Sample::Float16 => pomkit_gpu::util::f16_to_f32(u16::from_le_bytes([b[0], b[1]])),
            Sample::Float32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        }
    };
    let mut depths = Vec::with_capacity(w as usize * h as usize);
    for (k, t) in data[..want].chunks_exact(texel).enumerate() {
        let value = match channel {
            Channel::R => read(t, 0),
            Channel::G => slot(1).map_or_else(|| read(t, 0), |c| read(t, c)),
            Channel::B => slot(2).map_or_else(|| read(t, 0), |c| read(t, c)),
            Channel::A => read(t, 3),
            Channel::Luma => match (slot(1), slot(2)) {
                (Some(g), Some(b)) => {
                    0.2126 * read(t, slot(0).unwrap_or(0)) + 0.7152 * read(t, g) + 0.0722 * read(t, b)
                }
                _ => read(t, 0),
            },
        };
        if !value.is_finite() {
            let k = k as u32;
            return Err(HeightImageError::NotFinite { x: k % w, y: k / w, value });
        }
        let v = value.clamp(0.0, 1.0);
        depths.push(match kind {
            MapKind::Height => 1.0 - v,
            MapKind::Depth => v,
        });
    }
    // Every value is finite and in [0, 1], so this cannot fail.
    HeightField::from_depths(w, h, depths).map_err(|e| HeightImageError::Shape(e.to_string()))
}

/// The three textures of a height resource, as Bevy images.
pub struct HeightImages {
    /// Depth (R) and, for `iterative`, the parallax value (G), all mips.
    pub heights: Image,
    /// Maximum-height pyramid.
    pub pyramid: Image,
    /// Tangent-space normals.
    pub normals: Image,
}

/// Builds the textures of `field` for tracing with `edges` at `depth_scale` (UV units; the
/// normals depend on it), with an `R32Float` pyramid (no cones) and `R16Float` heights (no
/// parallax values).
#[must_use]
pub fn height_images(field: &HeightField, edges: EdgeMode, depth_scale: f32) -> HeightImages {
    height_images_with(field, edges, depth_scale, None, false)
}

/// [`height_images`], and if `cones` is given (built from `field` with `edges`: checked), an
/// `Rg32Float` pyramid carrying them in mip 0's green for the `cone` technique; with
/// `parallax`, `Rg16Float` heights carrying the parallax values (which depend on `depth_scale`)
/// in green for the `iterative` technique.
///
/// # Panics
/// If `cones` is not `field`'s size or was built for another edge mode (a caller's bug: build
/// them with `ConeMap::conservative(field, edges)`).
#[must_use]
pub fn height_images_with(
    field: &HeightField,
    edges: EdgeMode,
    depth_scale: f32,
    cones: Option<&pomkit_core::cone::ConeMap>,
    parallax: bool,
) -> HeightImages {
    let (w, h) = (field.width(), field.height());
    if let Some(c) = cones {
        assert!(c.size() == (w, h) && c.edges() == edges, "cones of another map or edge mode");
    }
    let surface = Surface::new(field.clone(), edges, depth_scale);
    let mips = surface.mips();
    let values = parallax.then(|| surface.parallax_mips());
    let mut bytes = Vec::new();
    for k in 0..mips.len() {
        let d = mips.level(k).depths();
        match values {
            Some(v) => {
                for (&dv, &gv) in d.iter().zip(v.level(k).depths()) {
                    bytes.extend_from_slice(&f32_to_f16(dv).to_le_bytes());
                    bytes.extend_from_slice(&f32_to_f16(gv).to_le_bytes());
                }
            }
            None => d.iter().for_each(|&dv| bytes.extend_from_slice(&f32_to_f16(dv).to_le_bytes())),
        }
    }
    let format = if parallax { TextureFormat::Rg16Float } else { TextureFormat::R16Float };
    let mut heights = image(w, h, mips.len() as u32, format, bytes);
    heights.sampler = ImageSampler::Descriptor(sampler(edges));

    // The pyramid: power-of-two mips, level l in the top-left of mip l.
    let pyr = surface.pyramid();
    let (pw, ph) = (w.next_power_of_two(), h.next_power_of_two());
    let mut bytes = Vec::new();
    for l in 0..pyr.len() {
        let (mw, mh) = ((pw >> l).max(1), (ph >> l).max(1));
        let (lw, lh) = pyr.level_size(l);
        for y in 0..mh {
            for x in 0..mw {
                let inside = x < lw && y < lh;
                let v = if inside { pyr.min_depth(l, x, y) } else { 0.0 };
                bytes.extend_from_slice(&v.to_le_bytes());
                if let Some(c) = cones {
                    let ratio = if inside && l == 0 { pomkit_gpu::library::cone_green(c, x, y) } else { 0.0 };
                    bytes.extend_from_slice(&ratio.to_le_bytes());
                }
            }
        }
    }
    let format = if cones.is_some() { TextureFormat::Rg32Float } else { TextureFormat::R32Float };
    let mut pyramid = image(pw, ph, pyr.len() as u32, format, bytes);
    pyramid.sampler = ImageSampler::nearest();

    let opts = NormalBakeOptions { scale: depth_scale * w as f32, filter: NormalFilter::Central, edges, y_down: false };
    let n = bake_normals(field, &opts).unwrap_or_else(|_| vec![pomkit_core::glam::Vec3::Z; field.depths().len()]);
    let mut bytes = Vec::with_capacity(n.len() * 8);
    for v in n {
        for c in [v.x, v.y, v.z, 0.0] {
            bytes.extend_from_slice(&f32_to_f16(c).to_le_bytes());
        }
    }
    let mut normals = image(w, h, 1, TextureFormat::Rgba16Float, bytes);
    normals.sampler = ImageSampler::Descriptor(sampler(edges));
    HeightImages { heights, pyramid, normals }
}

fn image(w: u32, h: u32, mips: u32, format: TextureFormat, data: Vec<u8>) -> Image {
    // `Image::new` checks the data against mip 0 alone; these hold every mip.
    let mut image = Image::new_uninit(
        Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        TextureDimension::D2,
        format,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.data = Some(data);
    image.texture_descriptor.mip_level_count = mips;
    image
}

/// The sampler the tracers need: bilinear within a mip and between mips, repeating where the
/// edges wrap.
pub(crate) fn sampler(edges: EdgeMode) -> ImageSamplerDescriptor {
    let address = match edges {
        EdgeMode::Wrap => ImageAddressMode::Repeat,
        EdgeMode::Clamp => ImageAddressMode::ClampToEdge,
    };
    ImageSamplerDescriptor {
        label: Some("pomkit heights".into()),
        address_mode_u: address,
        address_mode_v: address,
        address_mode_w: address,
        mag_filter: ImageFilterMode::Linear,
        min_filter: ImageFilterMode::Linear,
        mipmap_filter: ImageFilterMode::Linear,
        ..Default::default()
    }
}

/// A Bevy image of `field`'s depths (`R32Float`, white deep: use it with [`MapKind::Depth`]),
/// kept in the main world only: the plugin reads it on the CPU and uploads the textures it
/// builds. For height fields made in code, such as pomkit's procedural patterns.
#[must_use]
pub fn depth_image(field: &HeightField) -> Image {
    let data: Vec<u8> = field.depths().iter().flat_map(|d| d.to_le_bytes()).collect();
    let mut image = Image::new_uninit(
        Extent3d { width: field.width(), height: field.height(), depth_or_array_layers: 1 },
        TextureDimension::D2,
        TextureFormat::R32Float,
        RenderAssetUsages::MAIN_WORLD,
    );
    image.data = Some(data);
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use pomkit_core::cone::ConeMap;
    use pomkit_core::procedural::{Pattern, generate};

    /// The `f32` values of `image`'s mip `level` (each mip `(w >> level) x (h >> level)`).
    fn floats(image: &Image, level: u32, channels: usize) -> Vec<f32> {
        let (w, h) = (image.width() as usize, image.height() as usize);
        let start: usize = (0..level).map(|l| (w >> l).max(1) * (h >> l).max(1) * channels * 4).sum();
        let len = (w >> level).max(1) * (h >> level).max(1) * channels * 4;
        let data = image.data.as_ref().expect("built with data");
        data[start..start + len].chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    }

    #[test]
    fn a_cone_pyramid_carries_the_cones_beside_the_same_bounds() {
        // 24x20: padded to 32x32, so the padding is in every mip.
        let field = generate(Pattern::Cobblestones, 24, 20);
        let cones = ConeMap::conservative(&field, EdgeMode::Clamp);
        let plain = height_images(&field, EdgeMode::Clamp, 0.08);
        let coned = height_images_with(&field, EdgeMode::Clamp, 0.08, Some(&cones), false);
        assert_eq!(plain.pyramid.texture_descriptor.format, TextureFormat::R32Float);
        assert_eq!(coned.pyramid.texture_descriptor.format, TextureFormat::Rg32Float);
        let levels = plain.pyramid.texture_descriptor.mip_level_count;
        assert_eq!(coned.pyramid.texture_descriptor.mip_level_count, levels);
        for l in 0..levels {
            let (red, rg) = (floats(&plain.pyramid, l, 1), floats(&coned.pyramid, l, 2));
            assert!(red.iter().zip(rg.chunks_exact(2)).all(|(&r, p)| r == p[0]), "mip {l}: red differs");
            let stride = 32 >> l;
            for (k, p) in rg.chunks_exact(2).enumerate() {
                let (x, y) = ((k % stride) as u32, (k / stride) as u32);
                let want = if l == 0 && x < 24 && y < 20 { cones.ratio(x, y) } else { 0.0 };
                assert_eq!(p[1], want, "mip {l} texel ({x}, {y}): green");
            }
        }
        assert!(cones.ratio(3, 3) > 0.0 || cones.ratio(10, 10) > 0.0, "a map without cones tests nothing");
    }
}
