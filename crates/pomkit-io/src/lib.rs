//! pomkit-io: files in, pomkit-core types out, and baked maps back to files.
//!
//! - Height maps: 8- and 16-bit grey, RGB (luma), RGBA (any chosen channel, e.g. the alpha of a
//!   combined normal + height map), float EXR; height (white = high, the default) or depth
//!   (white = deep) convention; any size.
//! - Outputs are checked up front and committed together ([`output::Outputs`]): each goes to a
//!   temporary file in the destination's folder, renamed over the destination only once the
//!   whole run has succeeded. A failed run leaves no new or changed file.
//! - Rays files are read as a stream ([`rays::RayReader`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use image::{DynamicImage, ImageEncoder};
use pomkit_core::cone::ConeMap;
use pomkit_core::{EdgeMode, HeightField, HeightFieldError};

pub mod batch;
#[doc(hidden)]
pub mod batch_config;
mod float;
use float::float_samples;
pub mod fuzz_entry;
pub mod gltf;
pub mod library;
pub mod mesh;
pub mod output;
pub mod rays;
pub mod read;
pub mod scene;

pub use mesh::{MeshLoadError, decode_mesh, load_mesh};
pub use scene::{SceneError, load_scene, parse_scene};

/// A path for a message: as displayed, but with control characters (a NUL, a newline, an escape
/// sequence) escaped as in Rust string literals (`\u{0}`, `\n`), so that a hostile file name
/// cannot garble or hide the message. Ordinary paths print unchanged.
#[must_use]
pub fn shown(path: &Path) -> Shown<'_> {
    Shown(path)
}

/// See [`shown`].
#[derive(Clone, Copy, Debug)]
pub struct Shown<'a>(&'a Path);

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for c in self.0.to_string_lossy().chars() {
            if c.is_control() {
                write!(f, "{}", c.escape_debug())?;
            } else {
                write!(f, "{c}")?;
            }
        }
        Ok(())
    }
}

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
    #[error("cannot read {}: {reason}", crate::shown(path))]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The file is not an image pomkit can decode, or it is truncated or corrupt.
    #[error("cannot decode {} as an image: {reason}", crate::shown(path))]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's reason.
        reason: image::ImageError,
    },
    /// The image has no pixels.
    #[error("{} is {width}x{height}: an image needs at least one pixel", crate::shown(path))]
    Empty {
        /// The file.
        path: PathBuf,
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// `--channel a` on an image without alpha.
    #[error(
        "{} has no alpha channel, so --channel a cannot read a height from it (try luma, r, g or b)",
        crate::shown(path)
    )]
    NoAlpha {
        /// The file.
        path: PathBuf,
    },
    /// A channel name that is not r, g, b, a or luma.
    #[error("unknown channel '{0}': expected one of r, g, b, a, luma")]
    UnknownChannel(String),
    /// A float image holds NaN or infinity.
    #[error("{}: pixel ({x}, {y}) is {value}; heights must be finite", crate::shown(path))]
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
    #[error(
        "{}: heights span [{min}, {max}] but must lie in [0, 1]; pass --normalize to rescale them",
        crate::shown(path)
    )]
    OutOfRange {
        /// The file.
        path: PathBuf,
        /// Least value.
        min: f32,
        /// Greatest value.
        max: f32,
    },
    /// The pixel layout is not one pomkit reads.
    #[error("{}: unsupported pixel format {format}", crate::shown(path))]
    UnsupportedPixels {
        /// The file.
        path: PathBuf,
        /// The format, as the decoder names it.
        format: String,
    },
    /// The output's extension does not fit what is written.
    #[error("{}: cannot write {what} to this file type; use {expected}", crate::shown(path))]
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
    #[error("cannot write {}: {reason}", crate::shown(path))]
    Write {
        /// The file.
        path: PathBuf,
        /// The reason.
        reason: std::io::Error,
    },
    /// The encoder failed. Nothing was left at the destination.
    #[error("cannot encode {}: {reason}", crate::shown(path))]
    Encode {
        /// The file.
        path: PathBuf,
        /// The encoder's reason.
        reason: image::ImageError,
    },
    /// The image is not a cone map, or not this height map's.
    #[error("{} is not a cone map for this height map: {reason}", crate::shown(path))]
    ConeMap {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The pixels do not form a valid height field.
    #[error("{}: {reason}", crate::shown(path))]
    Field {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: HeightFieldError,
    },
    /// An output was refused before any work: it is an input, another output, read-only...
    #[error(transparent)]
    Output(#[from] output::OutputError),
    /// The file does not start with the signature of an image format (checked on its first
    /// bytes, before reading more).
    #[error("cannot decode {} as an image: it is not a PNG, JPEG, TIFF or OpenEXR file ({start})", crate::shown(path))]
    NotAnImage {
        /// The file.
        path: PathBuf,
        /// What its first bytes are.
        start: String,
    },
    /// The image is larger than pomkit reads, or than the memory there is (docs/LIMITS.md).
    #[error("{} is {width}x{height} pixels: {reason}", crate::shown(path))]
    ImageTooLarge {
        /// The file.
        path: PathBuf,
        /// Width in pixels, from the header.
        width: u32,
        /// Height in pixels, from the header.
        height: u32,
        /// The limit, and the figures.
        reason: String,
    },
    /// A normal map's texel is not a usable tangent-space normal.
    #[error("{}: texel ({x}, {y}) is ({}, {}, {}): {reason}", crate::shown(path), value[0], value[1], value[2])]
    BadNormal {
        /// The file.
        path: PathBuf,
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// The stored vector, as decoded (`c * 2 - 1` for integer images).
        value: [f32; 3],
        /// What is wrong.
        reason: &'static str,
    },
    /// The memory budget could not be read (a malformed `POMKIT_MEMORY_LIMIT`: the message is
    /// the variable's, not the file's), or reading the file does not fit in it.
    #[error("{}", memory_message(path, reason))]
    Memory {
        /// The file.
        path: PathBuf,
        /// The reason.
        reason: pomkit_core::memory::MemoryError,
    },
}

/// [`IoError::Memory`]'s message: a malformed budget is not the file's fault.
fn memory_message(path: &Path, reason: &pomkit_core::memory::MemoryError) -> String {
    match reason {
        pomkit_core::memory::MemoryError::BadLimit { .. } => reason.to_string(),
        _ => format!("cannot read {}: {reason}", crate::shown(path)),
    }
}

/// Reads a cone map baked by `pomkit bake cone` (a 16-bit grey + alpha PNG: grey the footprint's
/// top as a height, alpha the square root of the cone ratio over the shorter side) for a
/// `width` x `height` height map traced with `edges` (the map must have been baked with the same
/// `--edges`, which the file does not record). The cones are read as relaxed
/// ([`pomkit_core::cone::ConeMap::from_gray_alpha16`]).
///
/// # Errors
/// [`IoError::ConeMap`] for an image that is not 16-bit grey + alpha or is not `width` x
/// `height`, naming the file; the errors of [`read::read_image_file`] and
/// [`read::decode_image_limited`] for unreadable files.
pub fn load_cone_map(path: &Path, width: u32, height: u32, edges: EdgeMode) -> Result<ConeMap, IoError> {
    let bytes = read::read_image_file(path)?;
    let image = read::decode_image_limited(&bytes, path, 8)?;
    let bad = |reason: String| IoError::ConeMap { path: path.to_owned(), reason };
    let DynamicImage::ImageLumaA16(la) = image else {
        return Err(bad(format!(
            "its pixels are {:?}, and a cone map's are 16-bit grey + alpha (grey the top, alpha the cone), as \
             `pomkit bake cone` writes them",
            image.color()
        )));
    };
    if la.dimensions() != (width, height) {
        return Err(bad(format!(
            "it is {}x{} but the height map is {width}x{height}; bake the cone map from this height map \
             (`pomkit bake cone`)",
            la.width(),
            la.height()
        )));
    }
    ConeMap::from_gray_alpha16(width, height, edges, la.as_raw()).map_err(|e| bad(e.to_string()))
}

/// Reads a height map from `path`.
///
/// # Errors
/// Any [`IoError`] reading or decoding the file, or converting its pixels.
///
/// The file must start with an image format's signature (so `/dev/zero` is refused at once), it
/// is read up to [`read::MAX_IMAGE_BYTES`], and the image may have at most
/// [`pomkit_core::MAX_SIZE`] pixels a side and must fit in the memory budget
/// ([`read::decode_image_limited`]).
pub fn load_height_field(path: &Path, opts: &HeightLoadOptions) -> Result<HeightField, IoError> {
    let bytes = read::read_image_file(path)?;
    decode_height_field(&bytes, path, opts)
}

/// Decodes a height map from the bytes of an image file; `path` names it in errors and its
/// extension helps guess the format.
///
/// # Errors
/// As [`load_height_field`].
pub fn decode_height_field(bytes: &[u8], path: &Path, opts: &HeightLoadOptions) -> Result<HeightField, IoError> {
    // After decoding, the heights as floats and the height field: 8 bytes per pixel.
    match read::decode_image_limited(bytes, path, 8) {
        Ok(img) => image_to_height_field(&img, path, opts),
        // What the image crate cannot read, but a height map may well be: a single-channel
        // OpenEXR (a depth or height render) and a float TIFF, read with the decoders image
        // itself uses.
        Err(err) => match float_samples(bytes, path)? {
            Some(raw) => raw.into_height_field(path, opts),
            None => Err(err),
        },
    }
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
        // In f64: the span of finite f32 values (up to 2 * 3.4e38) overflows f32.
        let (lo, span) = (f64::from(min), f64::from(max) - f64::from(min));
        for v in &mut values {
            // A constant image normalizes to the surface (height 1).
            *v = if span > 0.0 { ((f64::from(*v) - lo) / span) as f32 } else { 1.0 };
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
    /// Two 16-bit channels, grey and alpha (PNG).
    GrayAlpha16,
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
            PixelLayout::GrayAlpha16 => 2,
            PixelLayout::Rgb8 | PixelLayout::RgbF32 => 3,
            PixelLayout::Rgba8 | PixelLayout::RgbaF32 => 4,
        }
    }
    /// Whether the samples are floats (written as OpenEXR).
    #[must_use]
    pub fn is_float(self) -> bool {
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
/// A one-output [`output::Outputs`]: the image is encoded into a temporary file beside `path`,
/// flushed, then renamed over `path` (see the [`output`] module for read-only files, links
/// and devices). To write several files of one run all or nothing, use [`output::Outputs`].
///
/// # Errors
/// [`IoError::UnsupportedOutput`] when the extension does not fit the layout,
/// [`IoError::Output`] when the output is refused, [`IoError::Write`] or [`IoError::Encode`]
/// when writing fails (no file is left behind).
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
    let mut outs = output::Outputs::new();
    let id = outs.output(path);
    outs.check()?;
    outs.write_image(id, width, height, layout, pixels)?;
    outs.commit()
}

/// The samples as an image of the layout's type.
fn to_image(width: u32, height: u32, layout: PixelLayout, pixels: Pixels<'_>) -> DynamicImage {
    let n = width as usize * height as usize * layout.channels();
    match (layout, pixels) {
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
        (PixelLayout::GrayAlpha16, Pixels::U16(p)) => {
            assert_eq!(p.len(), n, "sample count");
            image::ImageBuffer::<image::LumaA<u16>, _>::from_raw(width, height, p.to_vec())
                .expect("size checked")
                .into()
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
    }
}

/// Encodes `img` as PNG (8/16-bit layouts) or OpenEXR (float layouts) into `w`.
fn encode_image(w: &mut dyn output::WriteSeek, img: &DynamicImage, layout: PixelLayout) -> Result<(), WriteFail> {
    if layout.is_float() {
        // image's OpenEXR encoder reports the writer's I/O errors (a full disk) as "decoding"
        // errors carrying only text: keep the writer's own error and report that instead.
        let mut rec = RecordingWriter { inner: w, error: None };
        let result = img.write_to(&mut rec, image::ImageFormat::OpenExr);
        match (result, rec.error) {
            (Ok(()), _) => Ok(()),
            (Err(_), Some(io)) => Err(WriteFail::Io(io)),
            (Err(e), None) => Err(WriteFail::Encode(e)),
        }
    } else {
        // Fast compression: baked maps are large and PNG's best setting is several times
        // slower for a few percent.
        let enc = image::codecs::png::PngEncoder::new_with_quality(
            w,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Adaptive,
        );
        enc.write_image(img.as_bytes(), img.width(), img.height(), img.color().into()).map_err(WriteFail::Encode)
    }
}

/// A writer that keeps the first I/O error of the writer it wraps (the encoder sees a copy).
struct RecordingWriter<'a> {
    inner: &'a mut dyn output::WriteSeek,
    error: Option<std::io::Error>,
}

impl RecordingWriter<'_> {
    fn keep<T>(&mut self, r: std::io::Result<T>) -> std::io::Result<T> {
        r.map_err(|e| {
            let copy = std::io::Error::new(e.kind(), e.to_string());
            self.error.get_or_insert(e);
            copy
        })
    }
}

impl std::io::Write for RecordingWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let r = self.inner.write(buf);
        self.keep(r)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        let r = self.inner.flush();
        self.keep(r)
    }
}

impl std::io::Seek for RecordingWriter<'_> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        let r = self.inner.seek(pos);
        self.keep(r)
    }
}

/// Why the body of an atomic write failed.
#[derive(Debug)]
pub enum WriteFail {
    /// An I/O error.
    Io(std::io::Error),
    /// An encoder error.
    Encode(image::ImageError),
}

impl WriteFail {
    /// The [`IoError`] this failure is when writing `path`.
    #[must_use]
    pub fn naming(self, path: &Path) -> IoError {
        match self {
            WriteFail::Io(reason) => IoError::Write { path: path.to_owned(), reason },
            WriteFail::Encode(reason) => IoError::Encode { path: path.to_owned(), reason },
        }
    }
}

/// Runs `body` on a temporary file in `path`'s folder and renames it to `path` on success.
/// On any failure the temporary file is removed and `path` is untouched. A one-output
/// [`output::Outputs`]: an existing device is written in place, a read-only file is refused,
/// a symbolic link is written through.
///
/// # Errors
/// [`IoError::Output`], [`IoError::Write`] or [`IoError::Encode`] naming `path`.
pub fn write_atomically(
    path: &Path,
    body: impl FnOnce(&mut std::fs::File) -> Result<(), WriteFail>,
) -> Result<(), IoError> {
    let mut outs = output::Outputs::new();
    let id = outs.output(path);
    outs.check()?;
    outs.with_file(id, body)?;
    outs.commit()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

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
        assert!(matches!(err, IoError::Output(_)) && err.to_string().contains("does not exist"), "{err}");
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
        assert!(matches!(err, IoError::Output(_) | IoError::UnsupportedOutput { .. }));
    }

    /// A disk that fills after `room` bytes.
    struct FullDisk {
        data: std::io::Cursor<Vec<u8>>,
        room: u64,
    }

    impl std::io::Write for FullDisk {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.data.position() + buf.len() as u64 > self.room {
                return Err(std::io::Error::from(std::io::ErrorKind::StorageFull));
            }
            self.data.write(buf)
        }

        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl std::io::Seek for FullDisk {
        fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
            self.data.seek(pos)
        }
    }

    #[test]
    fn a_full_disk_while_writing_openexr_is_a_write_error_not_a_decoding_one() {
        let img: DynamicImage = image::Rgb32FImage::from_raw(64, 64, vec![0.5; 64 * 64 * 3]).unwrap().into();
        let mut disk = FullDisk { data: std::io::Cursor::new(Vec::new()), room: 100 };
        match encode_image(&mut disk, &img, PixelLayout::RgbF32) {
            Err(WriteFail::Io(e)) => assert_eq!(e.kind(), std::io::ErrorKind::StorageFull, "{e}"),
            Err(WriteFail::Encode(e)) => panic!("reported as an encoder error: {e}"),
            Ok(()) => panic!("the write succeeded on a full disk"),
        }
        // With room, the same image encodes.
        let mut roomy = FullDisk { data: std::io::Cursor::new(Vec::new()), room: u64::MAX };
        assert!(encode_image(&mut roomy, &img, PixelLayout::RgbF32).is_ok());
    }
}
