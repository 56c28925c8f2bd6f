//! Colour and normal maps: image files decoded into linear colour and unit normals.

use super::*;

/// Opens and decodes an image, refusing empty ones.
fn open_image(path: &Path) -> Result<DynamicImage, IoError> {
    let bytes = crate::read::read_image_file(path)?;
    decode_image(&bytes, path)
}

/// Decodes the bytes of an image file named `path`, refusing empty images.
fn decode_image(bytes: &[u8], path: &Path) -> Result<DynamicImage, IoError> {
    // After decoding: a converted copy and the texture's linear floats, 24 bytes per pixel.
    let img = crate::read::decode_image_limited(bytes, path, 24)?;
    if img.width() == 0 || img.height() == 0 {
        return Err(IoError::Empty { path: path.to_owned(), width: img.width(), height: img.height() });
    }
    Ok(img)
}

/// Whether the image stores floats (taken as linear values rather than sRGB codes).
fn is_float(img: &DynamicImage) -> bool {
    matches!(img, DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_))
}

/// Loads a colour map: 8- and 16-bit images are sRGB and converted to linear, float (EXR)
/// images are linear already (non-finite or negative values become 0). Alpha is ignored;
/// greyscale images give grey.
///
/// # Errors
/// [`IoError::Read`], [`IoError::Decode`] or [`IoError::Empty`], naming `path`.
pub fn load_color_texture(path: &Path) -> Result<Texture, IoError> {
    let img = open_image(path)?;
    color_texture(img, path)
}

/// [`load_color_texture`] from the bytes of an image file; `path` names it in errors.
///
/// # Errors
/// As [`load_color_texture`], but for [`IoError::Read`].
pub fn decode_color_texture(bytes: &[u8], path: &Path) -> Result<Texture, IoError> {
    color_texture(decode_image(bytes, path)?, path)
}

fn color_texture(img: DynamicImage, path: &Path) -> Result<Texture, IoError> {
    let (w, h) = (img.width(), img.height());
    let texture = match &img {
        DynamicImage::ImageLuma8(_)
        | DynamicImage::ImageLumaA8(_)
        | DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgba8(_) => {
            let rgb = img.to_rgb8();
            let px: Vec<[u8; 3]> = rgb.pixels().map(|p| p.0).collect();
            Texture::from_srgb8(w, h, &px)
        }
        _ => {
            let float = is_float(&img);
            let rgb = img.to_rgb32f();
            let texels = rgb
                .pixels()
                .map(|p| {
                    Vec3::from(p.0.map(|c| {
                        let c = if c.is_finite() { c.max(0.0) } else { 0.0 };
                        if float { c } else { srgb_to_linear(c.min(1.0)) }
                    }))
                })
                .collect();
            Texture::new(w, h, texels)
        }
    };
    texture.ok_or_else(|| IoError::Empty { path: path.to_owned(), width: w, height: h })
}

/// Loads a tangent-space normal map (+Y up, or +Y down when `y_down`, which is flipped to
/// pomkit's +Y up).
///
/// 8- and 16-bit RGB images hold `n * 0.5 + 0.5`; when the blue channel is zero everywhere the
/// map is a two-channel one and z is rebuilt from x and y. Float (EXR) images hold the vectors
/// themselves. Vectors are renormalized. A texel that is not finite or is the zero vector is
/// refused. Texels that point into the surface are what lossy compression (JPEG) and 8-bit
/// rounding make of normals near the horizon, and real library maps have a few: a `z / |n|`
/// down to `-`[`NORMAL_Z_LOSSY`] is clamped to 0, as long as at most [`MAX_INWARD_SHARE`] of
/// the texels point inward by more than one 8-bit step ([`NORMAL_Z_TOLERANCE`]). A texel
/// further inward, or more inward texels than that share (an 8-bit blue channel mostly below
/// 127: probably not a tangent-space normal map, or a mis-encoded one), is refused
/// (docs/SCENES.md).
///
/// # Errors
/// [`IoError::Read`], [`IoError::Decode`], [`IoError::Empty`],
/// [`IoError::UnsupportedPixels`] for a greyscale image (probably a height map), or
/// [`IoError::BadNormal`] naming the texel, each naming `path`.
pub fn load_normal_map(path: &Path, y_down: bool) -> Result<NormalMap, IoError> {
    let bytes = crate::read::read_image_file(path)?;
    decode_normal_map(&bytes, path, y_down)
}

/// How far below the surface (as `z / |n|`) a stored normal may point and still be taken as
/// rounding of a horizontal one (then clamped to `z = 0`, and not counted toward
/// [`MAX_INWARD_SHARE`]): one step of an 8-bit channel.
pub const NORMAL_Z_TOLERANCE: f32 = 1.0 / 127.5;

/// How far below the surface (as `z / |n|`) a stored normal may point and still be taken as a
/// horizontal one damaged by lossy compression (then clamped to `z = 0`). ambientCG's JPEG
/// normal maps of rocks reach about -0.1.
pub const NORMAL_Z_LOSSY: f32 = 0.25;

/// The largest share of a normal map's texels that may point into the surface by more than
/// [`NORMAL_Z_TOLERANCE`] (each within [`NORMAL_Z_LOSSY`]) and be clamped: real maps have a few
/// hundredths of a percent; a map over this share is refused as not a tangent-space normal map.
pub const MAX_INWARD_SHARE: f64 = 0.01;

/// A normal map's texel `(x, y)` as a unit vector pointing out of the surface, and whether it
/// pointed inward by more than [`NORMAL_Z_TOLERANCE`]; or the reason it is none: not finite,
/// zero length, or `z` below `-NORMAL_Z_LOSSY` (a tangent-space normal pointing into the
/// surface). Slightly negative `z` is clamped to 0.
fn checked_normal(n: Vec3, path: &Path, x: u32, y: u32) -> Result<(Vec3, bool), IoError> {
    let bad = |reason: &'static str| IoError::BadNormal { path: path.to_owned(), x, y, value: n.to_array(), reason };
    if !n.is_finite() {
        return Err(bad("normals must be finite"));
    }
    let len = n.length();
    if len <= 1e-6 {
        return Err(bad("a zero vector is no direction"));
    }
    if n.z < -NORMAL_Z_LOSSY * len {
        return Err(bad("it points into the surface (z < 0); tangent-space normals point out of it"));
    }
    Ok((Vec3::new(n.x, n.y, n.z.max(0.0)).normalize_or(Vec3::Z), n.z < -NORMAL_Z_TOLERANCE * len))
}

/// Where a normal map's `z` comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NormalZ {
    /// As [`load_normal_map`] decides: rebuilt from x and y when an 8- or 16-bit map's blue is
    /// zero everywhere (a two-channel map), stored otherwise.
    #[default]
    Auto,
    /// Rebuilt from x and y (Lengyel eq. 7.44) whatever the blue channel holds: a two-channel
    /// (`rg8`) map whose blue carries something else.
    Rebuilt,
}

/// [`load_normal_map`] with the choice of where `z` comes from.
///
/// # Errors
/// As [`load_normal_map`].
pub fn load_normal_map_with(path: &Path, y_down: bool, z: NormalZ) -> Result<NormalMap, IoError> {
    let bytes = crate::read::read_image_file(path)?;
    decode_normal_map_with(&bytes, path, y_down, z)
}

/// [`load_normal_map`] from the bytes of an image file; `path` names it in errors.
///
/// # Errors
/// As [`load_normal_map`], but for [`IoError::Read`].
pub fn decode_normal_map(bytes: &[u8], path: &Path, y_down: bool) -> Result<NormalMap, IoError> {
    decode_normal_map_with(bytes, path, y_down, NormalZ::Auto)
}

/// [`decode_normal_map`] with the choice of where `z` comes from.
///
/// # Errors
/// As [`decode_normal_map`].
pub fn decode_normal_map_with(bytes: &[u8], path: &Path, y_down: bool, z: NormalZ) -> Result<NormalMap, IoError> {
    let img = decode_image(bytes, path)?;
    if !img.color().has_color() {
        return Err(IoError::UnsupportedPixels {
            path: path.to_owned(),
            format: format!("{:?}: a normal map needs RGB (is this a height map?)", img.color()),
        });
    }
    let (w, h) = (img.width(), img.height());
    let float = is_float(&img);
    let rgb = img.to_rgb32f();
    let two_channel = z == NormalZ::Rebuilt || (!float && rgb.pixels().all(|p| p.0[2] == 0.0));
    let mut normals = Vec::with_capacity(w as usize * h as usize);
    let (mut first_inward, mut inward_count) = (None, 0u64);
    for (x, y, p) in rgb.enumerate_pixels() {
        let [nx, ny, nz] = if float { p.0 } else { p.0.map(|c| c * 2.0 - 1.0) };
        let ny = if y_down { -ny } else { ny };
        let n = if two_channel { rebuild_z(Vec2::new(nx, ny)) } else { Vec3::new(nx, ny, nz) };
        let (n, inward) = checked_normal(n, path, x, y)?;
        if inward {
            first_inward.get_or_insert((x, y, Vec3::new(nx, ny, nz)));
            inward_count += 1;
        }
        normals.push(n);
    }
    if let Some((x, y, n)) = first_inward
        && inward_count as f64 > MAX_INWARD_SHARE * normals.len() as f64
    {
        return Err(IoError::BadNormal {
            path: path.to_owned(),
            x,
            y,
            value: n.to_array(),
            reason: "it points into the surface (z < 0), as do over 1% of the texels; tangent-space normals point out of it",
        });
    }
    NormalMap::new(w, h, normals).ok_or_else(|| IoError::Empty { path: path.to_owned(), width: w, height: h })
}
