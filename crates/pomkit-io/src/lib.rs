//! pomkit-io: files in, pomkit-core types out, and baked maps back to files.
//!
//! - Height maps: 8- and 16-bit grey, RGB (luma), RGBA (any chosen channel, e.g. the alpha of a
//!   combined normal + height map), float EXR; height (white = high, the default) or depth
//!   (white = deep) convention; any size.
//! - Outputs are written atomically: the image goes to a temporary file in the destination's
//!   folder, which is renamed over the destination only once it is complete. A failed write
//!   leaves no partial file (DESIGN section 6).

use std::fmt;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use image::{DynamicImage, ImageEncoder};
use pomkit_core::{HeightField, HeightFieldError};

pub mod mesh;
pub mod scene;

pub use mesh::{MeshLoadError, load_mesh};
pub use scene::{SceneError, load_scene, parse_scene};

/// Which channel of an image holds the height.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Red.
    R,
    /// Green.
    G,
    /// Blue.
    B,
    /// Alpha, e.g. the height in a combined normal + height ("NB") map.
    A,
    /// Luma of the stored values, Rec. 709 weights `0.2126 R + 0.7152 G + 0.0722 B` (no
    /// linearisation: height maps hold data, not colour). For grey images, the grey value.
    #[default]
    Luma,
}

impl Channel {
    /// Every channel, in `--channel` order.
    pub const ALL: [Channel; 5] = [Channel::R, Channel::G, Channel::B, Channel::A, Channel::Luma];

    /// The name used on the command line and in scene files.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Channel::R => "r",
            Channel::G => "g",
            Channel::B => "b",
            Channel::A => "a",
            Channel::Luma => "luma",
        }
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Channel {
    type Err = IoError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| IoError::UnknownChannel(s.to_owned()))
    }
}

/// How to read a height map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeightLoadOptions {
    /// The image stores depth (white = deep) instead of height (white = high).
    pub depth_map: bool,
    /// The channel that holds the height. Default luma.
    pub channel: Channel,
    /// Rescale the values linearly so that their minimum becomes 0 and their maximum 1.
    /// Needed for float images in world units; without it, values outside `[0, 1]` are an error.
    pub normalize: bool,
}

/// What went wrong reading or writing a file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened or read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The file is not an image pomkit can decode, or it is truncated or corrupt.
    #[error("cannot decode {path} as an image: {reason}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's reason.
        reason: image::ImageError,
    },
    /// The image has no pixels.
    #[error("{path} is {width}x{height}: an image needs at least one pixel")]
    Empty {
        /// The file.
        path: PathBuf,
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// `--channel a` on an image without alpha.
    #[error("{path} has no alpha channel, so --channel a cannot read a height from it (try luma, r, g or b)")]
    NoAlpha {
        /// The file.
        path: PathBuf,
    },
    /// A channel name that is not r, g, b, a or luma.
    #[error("unknown channel '{0}': expected one of r, g, b, a, luma")]
    UnknownChannel(String),
    /// A float image holds NaN or infinity.
    #[error("{path}: pixel ({x}, {y}) is {value}; heights must be finite")]
    NotFinite {
        /// The file.
        path: PathBuf,
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// The value.
        value: f32,
    },
    /// A float image's values leave `[0, 1]` and normalisation was not asked for.
    #[error("{path}: heights span [{min}, {max}] but must lie in [0, 1]; pass --normalize to rescale them")]
    OutOfRange {
        /// The file.
        path: PathBuf,
        /// Least value.
        min: f32,
        /// Greatest value.
        max: f32,
    },
    /// The pixel layout is not one pomkit reads.
    #[error("{path}: unsupported pixel format {format}")]
    UnsupportedPixels {
        /// The file.
        path: PathBuf,
        /// The format, as the decoder names it.
        format: String,
    },
    /// The output's extension does not fit what is written.
    #[error("{path}: cannot write {what} to this file type; use {expected}")]
    UnsupportedOutput {
        /// The file.
        path: PathBuf,
        /// What was to be written.
        what: &'static str,
        /// The extensions that work.
        expected: &'static str,
    },
    /// The output could not be written (missing folder, no permission, disk full...). Nothing
    /// was left at the destination.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The reason.
        reason: std::io::Error,
    },
    /// The encoder failed. Nothing was left at the destination.
    #[error("cannot encode {path}: {reason}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// The encoder's reason.
        reason: image::ImageError,
    },
    /// The pixels do not form a valid height field.
    #[error("{path}: {reason}")]
    Field {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: HeightFieldError,
    },
}

/// Reads a height map from `path`.
///
/// # Errors
/// Any [`IoError`] reading or decoding the file, or converting its pixels.
pub fn load_height_field(path: &Path, opts: &HeightLoadOptions) -> Result<HeightField, IoError> {
    let bytes = std::fs::read(path).map_err(|reason| IoError::Read { path: path.to_owned(), reason })?;
    decode_height_field(&bytes, path, opts)
}

/// Decodes a height map from the bytes of an image file; `path` names it in errors and its
/// extension helps guess the format.
///
/// # Errors
/// As [`load_height_field`].
pub fn decode_height_field(bytes: &[u8], path: &Path, opts: &HeightLoadOptions) -> Result<HeightField, IoError> {
    let decode_err = |reason| IoError::Decode { path: path.to_owned(), reason };
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| IoError::Read { path: path.to_owned(), reason: e })?;
    let img = reader.decode().map_err(decode_err)?;
    image_to_height_field(&img, path, opts)
}

/// Converts a decoded image to a height field (see [`load_height_field`]).
///
/// # Errors
/// [`IoError::Empty`], [`IoError::NoAlpha`], [`IoError::NotFinite`], [`IoError::OutOfRange`],
/// [`IoError::UnsupportedPixels`].
pub fn image_to_height_field(
    img: &DynamicImage,
    path: &Path,
    opts: &HeightLoadOptions,
) -> Result<HeightField, IoError> {
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 {
        return Err(IoError::Empty { path: path.to_owned(), width, height });
    }
    let has_alpha = img.color().has_alpha();
    if opts.channel == Channel::A && !has_alpha {
        return Err(IoError::NoAlpha { path: path.to_owned() });
    }
    // Each pixel as normalized floats [r, g, b, a] (grey replicated), in the image's own units.
    let pick = |p: [f32; 4]| match opts.channel {
        Channel::R => p[0],
        Channel::G => p[1],
        Channel::B => p[2],
        Channel::A => p[3],
        Channel::Luma => 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2],
    };
    let values: Vec<f32> = match img {
        DynamicImage::ImageLuma8(b) => b.pixels().map(|p| f32::from(p.0[0]) / 255.0).collect(),
        DynamicImage::ImageLumaA8(b) => b
            .pixels()
            .map(|p| {
                let (g, a) = (f32::from(p.0[0]) / 255.0, f32::from(p.0[1]) / 255.0);
                pick([g, g, g, a])
            })
            .collect(),
        DynamicImage::ImageLuma16(b) => b.pixels().map(|p| f32::from(p.0[0]) / 65535.0).collect(),
        DynamicImage::ImageLumaA16(b) => b
            .pixels()
            .map(|p| {
                let (g, a) = (f32::from(p.0[0]) / 65535.0, f32::from(p.0[1]) / 65535.0);
                pick([g, g, g, a])
            })
            .collect(),
        DynamicImage::ImageRgb8(b) => {
            b.pixels().map(|p| pick(p.0.map(|c| f32::from(c) / 255.0).into_rgba(1.0))).collect()
        }
        DynamicImage::ImageRgba8(b) => b.pixels().map(|p| pick(p.0.map(|c| f32::from(c) / 255.0))).collect(),
        DynamicImage::ImageRgb16(b) => {
            b.pixels().map(|p| pick(p.0.map(|c| f32::from(c) / 65535.0).into_rgba(1.0))).collect()
        }
        DynamicImage::ImageRgba16(b) => b.pixels().map(|p| pick(p.0.map(|c| f32::from(c) / 65535.0))).collect(),
        DynamicImage::ImageRgb32F(b) => b.pixels().map(|p| pick(p.0.into_rgba(1.0))).collect(),
        DynamicImage::ImageRgba32F(b) => b.pixels().map(|p| pick(p.0)).collect(),
        other => {
            return Err(IoError::UnsupportedPixels { path: path.to_owned(), format: format!("{:?}", other.color()) });
        }
    };
    heights_from_values(values, width, height, path, opts)
}

/// Checks, optionally normalizes, and applies the height/depth convention.
fn heights_from_values(
    mut values: Vec<f32>,
    width: u32,
    height: u32,
    path: &Path,
    opts: &HeightLoadOptions,
) -> Result<HeightField, IoError> {
    let (mut min, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
    for (k, &value) in values.iter().enumerate() {
        if !value.is_finite() {
            let (x, y) = ((k % width as usize) as u32, (k / width as usize) as u32);
            return Err(IoError::NotFinite { path: path.to_owned(), x, y, value });
        }
        min = min.min(value);
        max = max.max(value);
    }
    if opts.normalize {
        let span = max - min;
        for v in &mut values {
            // A constant image normalizes to the surface (height 1).
            *v = if span > 0.0 { (*v - min) / span } else { 1.0 };
        }
    } else if min < 0.0 || max > 1.0 {
        return Err(IoError::OutOfRange { path: path.to_owned(), min, max });
    }
    let field = if opts.depth_map {
        HeightField::from_depths(width, height, values)
    } else {
        HeightField::from_heights(width, height, values)
    };
    field.map_err(|reason| IoError::Field { path: path.to_owned(), reason })
}

/// `[r, g, b]` to `[r, g, b, a]`.
trait IntoRgba {
    fn into_rgba(self, a: f32) -> [f32; 4];
}

impl IntoRgba for [f32; 3] {
    fn into_rgba(self, a: f32) -> [f32; 4] {
        [self[0], self[1], self[2], a]
    }
}

/// Pixel layouts pomkit writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelLayout {
    /// One 8-bit channel (PNG).
    Gray8,
    /// One 16-bit channel (PNG).
    Gray16,
    /// Three 8-bit channels (PNG).
    Rgb8,
    /// Four 8-bit channels (PNG).
    Rgba8,
    /// One 32-bit float channel (EXR, stored as RGB with equal channels for wide tool support).
    GrayF32,
    /// Three 32-bit float channels (EXR).
    RgbF32,
    /// Four 32-bit float channels (EXR).
    RgbaF32,
}

impl PixelLayout {
    fn channels(self) -> usize {
        match self {
            PixelLayout::Gray8 | PixelLayout::Gray16 | PixelLayout::GrayF32 => 1,
            PixelLayout::Rgb8 | PixelLayout::RgbF32 => 3,
            PixelLayout::Rgba8 | PixelLayout::RgbaF32 => 4,
        }
    }
    fn is_float(self) -> bool {
        matches!(self, PixelLayout::GrayF32 | PixelLayout::RgbF32 | PixelLayout::RgbaF32)
    }
}

/// Checks that `path`'s extension fits `layout` (`.png` for 8/16-bit, `.exr` for float), so a
/// command can fail before doing heavy work.
///
/// # Errors
/// [`IoError::UnsupportedOutput`] naming the extensions that work.
pub fn check_output(path: &Path, layout: PixelLayout) -> Result<(), IoError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    match (layout.is_float(), ext.as_str()) {
        (true, "exr") | (false, "png") => Ok(()),
        (true, _) => Err(IoError::UnsupportedOutput { path: path.to_owned(), what: "float data", expected: ".exr" }),
        (false, _) => {
            Err(IoError::UnsupportedOutput { path: path.to_owned(), what: "8- or 16-bit data", expected: ".png" })
        }
    }
}

/// Pixel data to write: 8-bit, 16-bit or float samples, interleaved, row-major.
#[derive(Clone, Copy, Debug)]
pub enum Pixels<'a> {
    /// 8-bit samples.
    U8(&'a [u8]),
    /// 16-bit samples.
    U16(&'a [u16]),
    /// Float samples.
    F32(&'a [f32]),
}

/// Writes an image atomically: PNG for 8- and 16-bit layouts, OpenEXR (`.exr`) for float ones.
///
/// The image is encoded into a temporary file beside `path`, flushed, then renamed over `path`.
///
/// # Errors
/// [`IoError::UnsupportedOutput`] when the extension does not fit the layout,
/// [`IoError::Write`] or [`IoError::Encode`] when writing fails (no file is left behind).
///
/// # Panics
/// If the sample count does not equal `width * height * channels`, or the sample type does
/// not fit the layout (a programming error, not bad input).
pub fn write_image(
    path: &Path,
    width: u32,
    height: u32,
    layout: PixelLayout,
    pixels: Pixels<'_>,
) -> Result<(), IoError> {
    check_output(path, layout)?;
    let want_exr = layout.is_float();
    let n = width as usize * height as usize * layout.channels();
    let img: DynamicImage = match (layout, pixels) {
        (PixelLayout::Gray8, Pixels::U8(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::GrayImage::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (PixelLayout::Rgb8, Pixels::U8(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::RgbImage::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (PixelLayout::Rgba8, Pixels::U8(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::RgbaImage::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (PixelLayout::Gray16, Pixels::U16(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::ImageBuffer::<image::Luma<u16>, _>::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (PixelLayout::GrayF32, Pixels::F32(p)) => {
            assert_eq!(p.len(), n, "sample count");
            let rgb: Vec<f32> = p.iter().flat_map(|&v| [v, v, v]).collect();
            image::Rgb32FImage::from_raw(width, height, rgb).expect("size checked").into()
        }
        (PixelLayout::RgbF32, Pixels::F32(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::Rgb32FImage::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (PixelLayout::RgbaF32, Pixels::F32(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::Rgba32FImage::from_raw(width, height, p.to_vec()).expect("size checked").into()
        }
        (layout, _) => panic!("pixel samples do not match layout {layout:?}"),
    };
    let format = if want_exr { image::ImageFormat::OpenExr } else { image::ImageFormat::Png };
    write_atomically(path, |file| {
        let mut w = BufWriter::new(file);
        if format == image::ImageFormat::Png {
            // Fast compression: baked maps are large and PNG's best setting is several times
            // slower for a few percent.
            let enc = image::codecs::png::PngEncoder::new_with_quality(
                &mut w,
                image::codecs::png::CompressionType::Fast,
                image::codecs::png::FilterType::Adaptive,
            );
            enc.write_image(img.as_bytes(), width, height, img.color().into()).map_err(WriteFail::Encode)?;
        } else {
            img.write_to(&mut w, format).map_err(WriteFail::Encode)?;
        }
        w.flush().map_err(WriteFail::Io)?;
        Ok(())
    })
}

/// Why the body of an atomic write failed.
#[derive(Debug)]
pub enum WriteFail {
    /// An I/O error.
    Io(std::io::Error),
    /// An encoder error.
    Encode(image::ImageError),
}

/// Runs `body` on a temporary file in `path`'s folder and renames it to `path` on success.
/// On any failure the temporary file is removed and `path` is untouched.
///
/// # Errors
/// [`IoError::Write`] or [`IoError::Encode`] naming `path`.
pub fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut std::fs::File) -> Result<(), WriteFail>,
) -> Result<(), IoError> {
    let write_err = |reason| IoError::Write { path: path.to_owned(), reason };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    if path.is_dir() {
        return Err(write_err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "it is a folder")));
    }
    if !dir.is_dir() {
        let msg = format!("its folder {} does not exist", dir.display());
        return Err(write_err(std::io::Error::new(std::io::ErrorKind::NotFound, msg)));
    }
    let mut builder = tempfile::Builder::new();
    builder.prefix(".pomkit-").suffix(".tmp");
    // Temporary files are private (0600) by default; outputs get ordinary permissions, as if
    // created by a plain open (the umask still applies).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(&dir).map_err(write_err)?;
    body(tmp.as_file_mut()).map_err(|e| match e {
        WriteFail::Io(reason) => IoError::Write { path: path.to_owned(), reason },
        WriteFail::Encode(reason) => IoError::Encode { path: path.to_owned(), reason },
    })?;
    tmp.as_file().sync_all().map_err(write_err)?;
    tmp.persist(path).map_err(|e| write_err(e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_bytes(img: &DynamicImage) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    }

    fn load(img: &DynamicImage, opts: HeightLoadOptions) -> Result<HeightField, IoError> {
        decode_height_field(&png_bytes(img), Path::new("test.png"), &opts)
    }

    #[test]
    fn reads_8_and_16_bit_grey_in_both_conventions() {
        let g8 = DynamicImage::ImageLuma8(image::GrayImage::from_raw(2, 1, vec![0, 255]).unwrap());
        let f = load(&g8, HeightLoadOptions::default()).unwrap();
        assert_eq!(f.depths(), &[1.0, 0.0]);
        let f = load(&g8, HeightLoadOptions { depth_map: true, ..Default::default() }).unwrap();
        assert_eq!(f.depths(), &[0.0, 1.0]);
        let g16 = DynamicImage::ImageLuma16(image::ImageBuffer::from_raw(3, 1, vec![0u16, 32768, 65535]).unwrap());
        let f = load(&g16, HeightLoadOptions::default()).unwrap();
        assert!((f.depths()[1] - (1.0 - 32768.0 / 65535.0)).abs() < 1e-7);
        // 16-bit keeps precision that 8-bit cannot hold.
        let fine = DynamicImage::ImageLuma16(image::ImageBuffer::from_raw(2, 1, vec![1000u16, 1001]).unwrap());
        let f = load(&fine, HeightLoadOptions::default()).unwrap();
        assert!(f.depths()[0] != f.depths()[1]);
    }

    #[test]
    fn reads_rgb_luma_and_rgba_channels() {
        let rgba = DynamicImage::ImageRgba8(image::RgbaImage::from_raw(1, 1, vec![255, 0, 0, 51]).unwrap());
        let h = |c| 1.0 - load(&rgba, HeightLoadOptions { channel: c, ..Default::default() }).unwrap().depths()[0];
        assert!((h(Channel::Luma) - 0.2126).abs() < 1e-6);
        assert_eq!(h(Channel::R), 1.0);
        assert_eq!(h(Channel::G), 0.0);
        assert!((h(Channel::A) - 0.2).abs() < 1e-6);
        let rgb = DynamicImage::ImageRgb8(image::RgbImage::from_raw(1, 1, vec![0, 255, 0]).unwrap());
        let f = load(&rgb, HeightLoadOptions::default()).unwrap();
        assert!((1.0 - f.depths()[0] - 0.7152).abs() < 1e-6);
        let err = load(&rgb, HeightLoadOptions { channel: Channel::A, ..Default::default() }).unwrap_err();
        assert!(matches!(err, IoError::NoAlpha { .. }), "{err}");
        assert!(err.to_string().contains("test.png"));
    }

    #[test]
    fn float_exr_round_trips_and_out_of_range_needs_normalize() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.exr");
        write_image(&path, 3, 1, PixelLayout::GrayF32, Pixels::F32(&[0.0, 0.25, 1.0])).unwrap();
        let f = load_height_field(&path, &HeightLoadOptions::default()).unwrap();
        assert_eq!(f.depths(), &[1.0, 0.75, 0.0]);
        let wide = dir.path().join("wide.exr");
        write_image(&wide, 3, 1, PixelLayout::GrayF32, Pixels::F32(&[-2.0, 0.0, 6.0])).unwrap();
        let err = load_height_field(&wide, &HeightLoadOptions::default()).unwrap_err();
        assert!(matches!(err, IoError::OutOfRange { min: -2.0, max: 6.0, .. }), "{err}");
        assert!(err.to_string().contains("--normalize"));
        let f = load_height_field(&wide, &HeightLoadOptions { normalize: true, ..Default::default() }).unwrap();
        assert_eq!(f.depths(), &[1.0, 0.75, 0.0]);
        let nan = dir.path().join("nan.exr");
        write_image(&nan, 2, 1, PixelLayout::GrayF32, Pixels::F32(&[0.5, f32::NAN])).unwrap();
        let err = load_height_field(&nan, &HeightLoadOptions::default()).unwrap_err();
        assert!(matches!(err, IoError::NotFinite { x: 1, y: 0, .. }), "{err}");
    }

    #[test]
    fn bad_files_are_clear_errors() {
        let g = DynamicImage::ImageLuma8(image::GrayImage::from_raw(16, 16, vec![7; 256]).unwrap());
        let bytes = png_bytes(&g);
        let cut = &bytes[..bytes.len() / 2];
        let err = decode_height_field(cut, Path::new("cut.png"), &HeightLoadOptions::default()).unwrap_err();
        assert!(matches!(err, IoError::Decode { .. }), "{err}");
        assert!(err.to_string().contains("cut.png"));
        let err =
            decode_height_field(b"not an image", Path::new("notes.txt"), &HeightLoadOptions::default()).unwrap_err();
        assert!(err.to_string().contains("notes.txt"), "{err}");
        let err = load_height_field(Path::new("/nonexistent/h.png"), &HeightLoadOptions::default()).unwrap_err();
        assert!(matches!(err, IoError::Read { .. }));
        assert_eq!(
            "x".parse::<Channel>().unwrap_err().to_string(),
            "unknown channel 'x': expected one of r, g, b, a, luma"
        );
        assert_eq!("A".parse::<Channel>().unwrap(), Channel::A);
    }

    #[test]
    fn writes_are_atomic_and_extensions_checked() {
        let dir = tempfile::tempdir().unwrap();
        let ok = dir.path().join("n.png");
        write_image(&ok, 2, 1, PixelLayout::Rgb8, Pixels::U8(&[1, 2, 3, 4, 5, 6])).unwrap();
        let back = image::open(&ok).unwrap().to_rgb8();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&ok).unwrap().permissions().mode();
            assert!(mode & 0o044 != 0 || mode & 0o600 == 0o600, "outputs are not private temp files: {mode:o}");
            assert_ne!(mode & 0o777, 0o600, "permissions of the temporary file leaked: {mode:o}");
        }
        assert_eq!(back.as_raw(), &[1, 2, 3, 4, 5, 6]);
        let err = write_image(&dir.path().join("n.jpg"), 1, 1, PixelLayout::Rgb8, Pixels::U8(&[0, 0, 0])).unwrap_err();
        assert!(matches!(err, IoError::UnsupportedOutput { .. }), "{err}");
        let err = write_image(&dir.path().join("f.png"), 1, 1, PixelLayout::GrayF32, Pixels::F32(&[0.0])).unwrap_err();
        assert!(err.to_string().contains(".exr"));
        let missing = dir.path().join("no/such/folder/n.png");
        let err = write_image(&missing, 1, 1, PixelLayout::Gray8, Pixels::U8(&[0])).unwrap_err();
        assert!(matches!(err, IoError::Write { .. }));
        // A failing body leaves neither the destination nor a temporary file.
        let target = dir.path().join("half.png");
        let err = write_atomically(&target, |f| {
            f.write_all(b"partial").map_err(WriteFail::Io)?;
            Err(WriteFail::Io(std::io::Error::other("disk full")))
        })
        .unwrap_err();
        assert!(err.to_string().contains("disk full"));
        assert!(!target.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, vec![std::ffi::OsString::from("n.png")]);
        // A folder is not overwritten.
        let err = write_image(dir.path(), 1, 1, PixelLayout::Gray8, Pixels::U8(&[0])).unwrap_err();
        assert!(matches!(err, IoError::Write { .. } | IoError::UnsupportedOutput { .. }));
    }
}
