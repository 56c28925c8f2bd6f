//! Reading input files with a cap on what is read (docs/LIMITS.md).
//!
//! Every input file is read through [`read_capped`]: a regular file larger than its format's cap
//! is refused before a byte is read, and anything else (a device such as `/dev/zero`, a FIFO, a
//! file that grows) is read only up to the cap. Images are checked further: the first bytes must
//! be the signature of an image format ([`read_image_file`]), so `/dev/zero` is refused after
//! 64 bytes, and the decoder is held to [`MAX_SIZE`] texels a side and the memory budget
//! ([`decode_image_limited`]).

use std::io::{Cursor, Read};
use std::path::Path;

use image::{DynamicImage, ImageDecoder, ImageReader};
use pomkit_core::MAX_SIZE;
use pomkit_core::memory::{self, format_bytes};

use crate::IoError;

/// The most a scene file (TOML) may hold: 64 MiB, far more than any hand-written or exported
/// scene (they are a few KiB; textures and meshes are separate files).
pub const MAX_SCENE_BYTES: u64 = 64 << 20;

/// The most a mesh file (OBJ, glTF, glb, or one buffer of a glTF) may hold: 1 GiB, some ten
/// million triangles of text OBJ.
pub const MAX_MESH_BYTES: u64 = 1 << 30;

/// The most an image file may hold: the size of the largest image pomkit reads ([`MAX_SIZE`]
/// texels a side, four 32-bit float channels) stored uncompressed, plus 64 MiB of headers and
/// tables.
pub const MAX_IMAGE_BYTES: u64 = (MAX_SIZE as u64) * (MAX_SIZE as u64) * 16 + (64 << 20);

/// How many bytes of an image file are read to recognise its format.
const SIGNATURE_BYTES: usize = 64;

/// Reads `path` whole when it holds at most `cap` bytes; `what` names the kind of file in the
/// error ("a scene file").
///
/// # Errors
/// The operating system's error; [`std::io::ErrorKind::FileTooLarge`] when the file is larger
/// than `cap` (a regular file is refused before reading; anything else once `cap` bytes have
/// been read); [`std::io::ErrorKind::OutOfMemory`] when the bytes cannot be allocated.
pub fn read_capped(path: &Path, cap: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let mut file = open_input(path)?;
    read_rest(&mut file, Vec::new(), cap, what)
}

/// How long an input that is a FIFO (a named pipe) is waited for a program to open it for
/// writing: opening a FIFO blocks until one does, which would otherwise hang forever.
pub const FIFO_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Opens an input file for reading. A FIFO (a named pipe; also `/dev/fd/N` of a shell's process
/// substitution, whose writer is already there) is opened on a helper thread and given
/// [`FIFO_WAIT`] to find a writer; everything else is opened as usual.
///
/// # Errors
/// The operating system's error; [`std::io::ErrorKind::TimedOut`] for a FIFO that no program
/// opened for writing in time.
pub fn open_input(path: &Path) -> std::io::Result<std::fs::File> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo()) {
            let (tx, rx) = std::sync::mpsc::channel();
            let owned = path.to_owned();
            // Left blocked in `open` when nothing ever writes: the process exits without it.
            std::thread::spawn(move || {
                let _ = tx.send(std::fs::File::open(owned));
            });
            return rx.recv_timeout(FIFO_WAIT).unwrap_or_else(|_| {
                Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!(
                        "it is a FIFO (named pipe) and no program opened it for writing within {} s",
                        FIFO_WAIT.as_secs()
                    ),
                ))
            });
        }
    }
    std::fs::File::open(path)
}

/// Reads the rest of `file` after `head` (already read from it), refusing more than `cap`
/// bytes in all.
fn read_rest(file: &mut std::fs::File, head: Vec<u8>, cap: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let meta = file.metadata()?;
    let too_large = |size: String| {
        std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!("{what} may be at most {} ({cap} bytes), and this one {size}", format_bytes(cap)),
        )
    };
    if meta.is_dir() {
        return Err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "it is a folder, not a file"));
    }
    let mut bytes = head;
    if meta.is_file() {
        if meta.len() > cap {
            return Err(too_large(format!("is {} ({} bytes)", format_bytes(meta.len()), meta.len())));
        }
        let more = usize::try_from(meta.len()).unwrap_or(usize::MAX).saturating_sub(bytes.len());
        bytes.try_reserve_exact(more).map_err(|e| std::io::Error::new(std::io::ErrorKind::OutOfMemory, e))?;
    }
    let room = (cap + 1).saturating_sub(bytes.len() as u64);
    file.take(room).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(too_large(
            "goes on beyond that (it is not a regular file, or it grew): reading stopped there".into(),
        ));
    }
    Ok(bytes)
}

/// Reads an image file: the first bytes must be the signature of a known image format, then
/// the rest is read up to [`MAX_IMAGE_BYTES`].
///
/// # Errors
/// [`IoError::Read`] naming `path` (missing, unreadable, too large);
/// [`IoError::NotAnImage`] when the first bytes are not an image format's signature.
pub fn read_image_file(path: &Path) -> Result<Vec<u8>, IoError> {
    let read_err = |reason| IoError::Read { path: path.to_owned(), reason };
    let mut file = open_input(path).map_err(read_err)?;
    if file.metadata().map_err(read_err)?.is_dir() {
        return Err(read_err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "it is a folder, not a file")));
    }
    let mut head = Vec::with_capacity(SIGNATURE_BYTES);
    (&mut file).take(SIGNATURE_BYTES as u64).read_to_end(&mut head).map_err(read_err)?;
    check_signature(&head, path)?;
    read_rest(&mut file, head, MAX_IMAGE_BYTES, "an image file").map_err(read_err)
}

/// Refuses bytes that do not start with the signature of an image format.
fn check_signature(head: &[u8], path: &Path) -> Result<(), IoError> {
    if image::guess_format(head).is_ok() {
        return Ok(());
    }
    let start: Vec<String> = head.iter().take(8).map(|b| format!("{b:02x}")).collect();
    let start = if start.is_empty() { "it is empty".to_owned() } else { format!("it starts with {}", start.join(" ")) };
    Err(IoError::NotAnImage { path: path.to_owned(), start })
}

/// What an image decoder may allocate for a header (its tables and metadata) whatever the
/// budget.
const HEADER_BYTES: u64 = 16 << 20;

/// The width, height and decoded size in bytes of the image file `path`, read from its header
/// alone (for memory estimates before a file is read); `None` when the header cannot be read
/// or the format is not one the image decoders know (single-channel OpenEXR, float TIFF).
#[must_use]
pub fn image_header(path: &Path) -> Option<(u32, u32, u64)> {
    let meta = std::fs::metadata(path).ok()?;
    if !meta.is_file() {
        return None;
    }
    let decoder = ImageReader::open(path).ok()?.with_guessed_format().ok()?.into_decoder().ok()?;
    let (width, height) = decoder.dimensions();
    Some((width, height, decoder.total_bytes()))
}

/// Decodes an image held to [`MAX_SIZE`] texels a side and to the memory budget
/// ([`pomkit_core::memory`]): `extra_per_pixel` bytes per pixel that the caller allocates
/// after decoding (a height field's floats, say) count toward it. The dimensions are read from
/// the header and checked before any pixel is decoded.
///
/// # Errors
/// [`IoError::NotAnImage`] for an unknown format, [`IoError::ImageTooLarge`] with the size and
/// the limit, [`IoError::Decode`] for a corrupt file, naming `path`.
pub fn decode_image_limited(bytes: &[u8], path: &Path, extra_per_pixel: u64) -> Result<DynamicImage, IoError> {
    let head = &bytes[..bytes.len().min(SIGNATURE_BYTES)];
    check_signature(head, path)?;
    let budget = memory::available_bytes().map_err(|e| IoError::Memory { path: path.to_owned(), reason: e })?;
    check_exr_blocks(bytes, path)?;
    let mut reader = ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|reason| IoError::Read { path: path.to_owned(), reason })?;
    // The decoder's own bookkeeping is held to the budget; the dimensions are checked below,
    // with the figures in the message.
    // (At least HEADER_BYTES: a tiny budget is reported below with the image's size and the
    // figures, not as a header the decoder could not allocate.)
    let mut construction = image::Limits::default();
    construction.max_alloc = budget.map(|b| b.bytes.max(HEADER_BYTES));
    reader.limits(construction);
    let decode_err = |reason| map_decode_error(reason, path, None);
    let mut decoder = reader.into_decoder().map_err(decode_err)?;
    let (width, height) = decoder.dimensions();
    let pixels = u64::from(width) * u64::from(height);
    let decoded = decoder.total_bytes();
    if width > MAX_SIZE || height > MAX_SIZE {
        return Err(IoError::ImageTooLarge {
            path: path.to_owned(),
            width,
            height,
            reason: format!("pomkit reads images of at most {MAX_SIZE} pixels a side"),
        });
    }
    let needed = decoded.saturating_add(pixels.saturating_mul(extra_per_pixel));
    if let Some(b) = budget.filter(|b| needed > b.bytes) {
        return Err(IoError::ImageTooLarge {
            path: path.to_owned(),
            width,
            height,
            reason: format!(
                "reading it needs about {}, but only {} is available ({})",
                format_bytes(needed),
                format_bytes(b.bytes),
                b.source
            ),
        });
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIZE);
    limits.max_image_height = Some(MAX_SIZE);
    limits.max_alloc = Some(budget.map_or(u64::MAX, |b| b.bytes));
    decoder.set_limits(limits).map_err(|e| map_decode_error(e, path, Some((width, height))))?;
    DynamicImage::from_decoder(decoder).map_err(|e| map_decode_error(e, path, Some((width, height))))
}

/// Refuses an OpenEXR file whose tiles are larger than [`MAX_SIZE`] a side, before it is
/// decoded: the decoder allocates a whole tile per block, whatever the image's size, so an
/// 8x6 image declaring tiles of 3211328x16384 pixels (found by fuzzing, see docs/FUZZING.md)
/// asked for gigabytes from an 848-byte file. Other files pass unchanged.
///
/// # Errors
/// [`IoError::ImageTooLarge`] naming the file, its size and the tile size.
pub fn check_exr_blocks(bytes: &[u8], path: &Path) -> Result<(), IoError> {
    if !bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return Ok(());
    }
    // A header that does not parse is the decoder's to report, with its own message.
    let Ok(meta) = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false) else {
        return Ok(());
    };
    for header in &meta.headers {
        if let exr::meta::BlockDescription::Tiles(tiles) = &header.blocks {
            let (tw, th) = (tiles.tile_size.0, tiles.tile_size.1);
            if tw > MAX_SIZE as usize || th > MAX_SIZE as usize {
                let size = header.layer_size;
                return Err(IoError::ImageTooLarge {
                    path: path.to_owned(),
                    width: u32::try_from(size.0).unwrap_or(u32::MAX),
                    height: u32::try_from(size.1).unwrap_or(u32::MAX),
                    reason: format!("its tiles are {tw}x{th} pixels, but pomkit reads at most {MAX_SIZE} a side"),
                });
            }
        }
    }
    Ok(())
}

/// The decoder's error, with its limit errors ("Memory limit exceeded") told as the image's
/// size and the limit.
fn map_decode_error(reason: image::ImageError, path: &Path, size: Option<(u32, u32)>) -> IoError {
    match (&reason, size) {
        (image::ImageError::Limits(limit), Some((width, height))) => {
            let why = match limit.kind() {
                image::error::LimitErrorKind::DimensionError => {
                    format!("pomkit reads images of at most {MAX_SIZE} pixels a side")
                }
                _ => match memory::available_bytes() {
                    Ok(Some(b)) => format!(
                        "decoding it needs more memory than the {} available ({})",
                        format_bytes(b.bytes),
                        b.source
                    ),
                    _ => "decoding it needs more memory than is available".to_owned(),
                },
            };
            IoError::ImageTooLarge { path: path.to_owned(), width, height, reason: why }
        }
        (image::ImageError::Limits(_), None) => IoError::Memory {
            path: path.to_owned(),
            reason: memory::MemoryError::Allocation {
                what: "its header".to_owned(),
                bytes: HEADER_BYTES,
                reason: "the decoder's limit".to_owned(),
                advice: format!("set {} higher", memory::LIMIT_VAR),
            },
        },
        _ => IoError::Decode { path: path.to_owned(), reason },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_over_the_cap_are_refused_before_reading() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.toml");
        std::fs::write(&p, vec![b'#'; 100]).unwrap();
        assert_eq!(read_capped(&p, 100, "a scene file").unwrap().len(), 100);
        let err = read_capped(&p, 99, "a scene file").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::FileTooLarge);
        assert!(err.to_string().contains("a scene file may be at most 99 B"), "{err}");
    }

    #[cfg(unix)]
    #[test]
    fn endless_devices_stop_at_the_cap() {
        let err = read_capped(Path::new("/dev/zero"), 1 << 20, "a mesh file").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::FileTooLarge);
        assert!(err.to_string().contains("reading stopped there"), "{err}");
        let err = read_image_file(Path::new("/dev/zero")).unwrap_err();
        assert!(matches!(err, IoError::NotAnImage { .. }), "{err}");
        assert!(err.to_string().contains("/dev/zero") && err.to_string().contains("00 00"), "{err}");
    }
}
