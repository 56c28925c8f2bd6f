//! Float height images decoded directly: single-channel EXR and float TIFF, which the `image`
//! crate would widen to RGBA, read as one channel of samples.

use super::*;

/// Float samples decoded directly: `channels` per pixel (1 grey, 2 grey + alpha, 3 RGB, 4 RGBA),
/// row-major.
pub(crate) struct FloatSamples {
    width: u32,
    height: u32,
    channels: usize,
    samples: Vec<f32>,
}

impl FloatSamples {
    pub(crate) fn into_height_field(self, path: &Path, opts: &HeightLoadOptions) -> Result<HeightField, IoError> {
        let has_alpha = self.channels == 2 || self.channels == 4;
        if opts.channel == Channel::A && !has_alpha {
            return Err(IoError::NoAlpha { path: path.to_owned() });
        }
        let pick = |p: &[f32]| -> f32 {
            let rgba = match *p {
                [g] => [g, g, g, 1.0],
                [g, a] => [g, g, g, a],
                [r, g, b] => [r, g, b, 1.0],
                [r, g, b, a] => [r, g, b, a],
                _ => [f32::NAN; 4],
            };
            match opts.channel {
                Channel::R => rgba[0],
                Channel::G => rgba[1],
                Channel::B => rgba[2],
                Channel::A => rgba[3],
                Channel::Luma if self.channels <= 2 => rgba[0],
                Channel::Luma => 0.2126 * rgba[0] + 0.7152 * rgba[1] + 0.0722 * rgba[2],
            }
        };
        let values: Vec<f32> = self.samples.chunks_exact(self.channels).map(pick).collect();
        heights_from_values(values, self.width, self.height, path, opts)
    }
}

/// The size limit of [`read::decode_image_limited`], for the direct decoders: at most
/// [`pomkit_core::MAX_SIZE`] a side, and the decoded floats (plus the height field's 8 bytes
/// per pixel) within the memory budget.
pub(crate) fn check_float_size(path: &Path, width: u32, height: u32, channels: usize) -> Result<(), IoError> {
    let too_large = |reason: String| Err(IoError::ImageTooLarge { path: path.to_owned(), width, height, reason });
    if width == 0 || height == 0 {
        return Err(IoError::Empty { path: path.to_owned(), width, height });
    }
    if width > pomkit_core::MAX_SIZE || height > pomkit_core::MAX_SIZE {
        return too_large(format!("pomkit reads images of at most {} pixels a side", pomkit_core::MAX_SIZE));
    }
    let needed = u64::from(width) * u64::from(height) * (4 * channels as u64 + 8);
    let budget =
        pomkit_core::memory::available_bytes().map_err(|e| IoError::Memory { path: path.to_owned(), reason: e })?;
    if let Some(b) = budget.filter(|b| needed > b.bytes) {
        return too_large(format!(
            "reading it needs about {}, but only {} is available",
            pomkit_core::memory::format_bytes(needed),
            pomkit_core::memory::format_bytes(b.bytes)
        ));
    }
    Ok(())
}

/// A decoder's error as [`IoError::Decode`].
pub(crate) fn direct_decode_error(path: &Path, format: image::ImageFormat, err: impl std::fmt::Display) -> IoError {
    let hint = image::error::ImageFormatHint::Exact(format);
    IoError::Decode {
        path: path.to_owned(),
        reason: image::ImageError::Decoding(image::error::DecodingError::new(hint, err.to_string())),
    }
}

/// Float samples of an OpenEXR file with one channel (any name: Y, Z, R...), or of a TIFF
/// whose samples are floats; `None` for any other file (which the image crate's error then
/// describes).
pub(crate) fn float_samples(bytes: &[u8], path: &Path) -> Result<Option<FloatSamples>, IoError> {
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return exr_single_channel(bytes, path);
    }
    if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        return tiff_float(bytes, path);
    }
    Ok(None)
}

/// The one channel of a single-channel OpenEXR file's first layer.
pub(crate) fn exr_single_channel(bytes: &[u8], path: &Path) -> Result<Option<FloatSamples>, IoError> {
    use exr::prelude::ReadChannels as _;
    use exr::prelude::ReadLayers as _;
    let err = |e: exr::error::Error| direct_decode_error(path, image::ImageFormat::OpenExr, e);
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false).map_err(err)?;
    let Some(header) = meta.headers.first() else { return Ok(None) };
    if header.channels.list.len() != 1 || header.deep {
        return Ok(None);
    }
    let size = header.layer_size;
    let (width, height) = (u32::try_from(size.0).unwrap_or(u32::MAX), u32::try_from(size.1).unwrap_or(u32::MAX));
    check_float_size(path, width, height, 1)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(err)?;
    let Some(channel) = image.layer_data.channel_data.list.first() else { return Ok(None) };
    let samples: Vec<f32> = channel.sample_data.values_as_f32().collect();
    if samples.len() != width as usize * height as usize {
        return Err(direct_decode_error(
            path,
            image::ImageFormat::OpenExr,
            "the channel's sample count does not match the image size",
        ));
    }
    Ok(Some(FloatSamples { width, height, channels: 1, samples }))
}

/// The samples of a TIFF whose samples are 32- or 64-bit floats (grey, grey + alpha, RGB,
/// RGBA); `None` for integer TIFFs (which the image crate reads).
pub(crate) fn tiff_float(bytes: &[u8], path: &Path) -> Result<Option<FloatSamples>, IoError> {
    use tiff::ColorType;
    use tiff::decoder::{Decoder, DecodingResult, Limits};
    let err = |e: tiff::TiffError| direct_decode_error(path, image::ImageFormat::Tiff, e);
    let mut decoder = Decoder::new(std::io::Cursor::new(bytes)).map_err(err)?;
    let (width, height) = decoder.dimensions().map_err(err)?;
    let channels = match decoder.colortype().map_err(err)? {
        ColorType::Gray(32 | 64) => 1,
        ColorType::GrayA(32 | 64) => 2,
        ColorType::RGB(32 | 64) => 3,
        ColorType::RGBA(32 | 64) => 4,
        _ => return Ok(None),
    };
    check_float_size(path, width, height, channels)?;
    let mut decoder = decoder.with_limits(Limits::unlimited());
    let samples: Vec<f32> = match decoder.read_image().map_err(err)? {
        DecodingResult::F32(v) => v,
        DecodingResult::F64(v) => v.into_iter().map(|x| x as f32).collect(),
        _ => return Ok(None),
    };
    if samples.len() != width as usize * height as usize * channels {
        return Err(direct_decode_error(
            path,
            image::ImageFormat::Tiff,
            "the sample count does not match the image size",
        ));
    }
    Ok(Some(FloatSamples { width, height, channels, samples }))
}
