//! The outputs of one run, checked up front and committed together at the end.
//!
//! A verb declares its inputs and outputs in an [`Outputs`], calls [`Outputs::check`] before
//! any heavy work, writes each output with [`Outputs::write_with`] or [`Outputs::write_image`],
//! and finally calls [`Outputs::commit`]. Until then nothing at any destination changes: each
//! output regular file is written to a temporary file in its destination's folder, and
//! `commit` renames them all into place; an [`Outputs`] dropped without `commit` (the run
//! failed) removes its temporary files, so a failed run leaves no new or changed file.
//!
//! What `check` refuses, each with an [`OutputError`] naming the output:
//! - an output that is one of the inputs, or another output of the same run: the same file
//!   through any path, `..`, hard link or symbolic link (device and inode for existing files on
//!   unix, canonical paths otherwise; an output that does not exist yet is its canonical folder
//!   plus its name);
//! - an existing read-only file (by its permission bits, so also when running as root), a
//!   folder, a missing folder, a symbolic link to a missing file.
//!
//! Outputs that are not regular files:
//! - `-` is standard output, written directly (it cannot be staged);
//! - an existing character device or FIFO (`/dev/null`, `/dev/full`, a pipe) is written
//!   directly, never renamed over, and its write errors are reported;
//! - a symbolic link to an existing file is written through: the file it points to is
//!   replaced (atomically, as above) and the link stays.
//!
//! Every write error names the output, e.g. `cannot write /dev/full: No space left on device`.
//!
//! Interruption: every staged file of the process is listed in one registry, so that a program
//! stopped by a signal can remove them all with [`remove_staged_files`] before it exits. Each
//! [`Outputs::commit`] renames its files while holding that registry, so an interruption comes
//! before or after a commit, never in the middle: a run's outputs appear all together or not at
//! all.

use std::cell::Cell;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};

use crate::{IoError, PixelLayout, Pixels, WriteFail};

/// Why an output was refused before any work was done. Every variant names the output.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is one of the run's inputs.
    #[error("cannot write {}: it is the same file as the input {}; choose another output", path.display(), input.display())]
    SameAsInput {
        /// The output, as given.
        path: PathBuf,
        /// The input it would overwrite, as given.
        input: PathBuf,
    },
    /// Two outputs of the run are the same file.
    #[error("cannot write {}: it is the same file as the output {}; every output needs its own file", path.display(), other.display())]
    SameAsOutput {
        /// The output, as given.
        path: PathBuf,
        /// The other output, as given.
        other: PathBuf,
    },
    /// The output exists and is read-only.
    #[error("cannot write {}: it is read-only", path.display())]
    ReadOnly {
        /// The output.
        path: PathBuf,
    },
    /// The output is a folder.
    #[error("cannot write {}: it is a folder", path.display())]
    Folder {
        /// The output.
        path: PathBuf,
    },
    /// The output's folder does not exist.
    #[error("cannot write {}: its folder {} does not exist", path.display(), folder.display())]
    NoFolder {
        /// The output.
        path: PathBuf,
        /// Its folder.
        folder: PathBuf,
    },
    /// The output is a symbolic link whose target does not exist.
    #[error("cannot write {}: it is a symbolic link to {}, which does not exist", path.display(), target.display())]
    DanglingLink {
        /// The output.
        path: PathBuf,
        /// Where the link points.
        target: PathBuf,
    },
    /// The output's file or folder cannot be examined or a temporary file cannot be made in its
    /// folder (no permission...).
    #[error("cannot write {}: {reason}", path.display())]
    Unusable {
        /// The output.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
}

/// One declared output of an [`Outputs`], returned by [`Outputs::output`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputId(usize);

/// What a file is, for telling whether two paths name the same file.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Identity {
    /// An existing regular file: device and inode (unix) or its canonical path.
    Existing(FileKey),
    /// A file that does not exist yet: its canonical folder joined with its name.
    New(PathBuf),
}

/// What identifies a file whatever path, `..`, hard link or symbolic link names it: device and
/// inode on unix, the canonical path elsewhere.
#[cfg(unix)]
pub type FileKey = (u64, u64);
/// What identifies a file whatever path, `..`, hard link or symbolic link names it: device and
/// inode on unix, the canonical path elsewhere.
#[cfg(not(unix))]
pub type FileKey = PathBuf;

/// The [`FileKey`] of the regular file `path` names (links followed); `None` when it names no
/// regular file.
#[must_use]
pub fn regular_file_key(path: &Path) -> Option<FileKey> {
    let meta = std::fs::metadata(path).ok().filter(std::fs::Metadata::is_file)?;
    file_key(path, &meta).ok()
}

#[cfg(unix)]
fn file_key(_path: &Path, meta: &std::fs::Metadata) -> std::io::Result<FileKey> {
    use std::os::unix::fs::MetadataExt;
    Ok((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn file_key(path: &Path, _meta: &std::fs::Metadata) -> std::io::Result<FileKey> {
    std::fs::canonicalize(path)
}

/// Where an output goes, once checked.
enum Dest {
    /// Standard output (`-`).
    Stdout,
    /// An existing file that is not a regular file (a device, a FIFO): written in place.
    Direct,
    /// A regular file (existing or not), replaced by renaming the staged file over `target`
    /// (the file itself, with symbolic links resolved).
    Replace {
        /// The staged file, in `target`'s folder.
        tmp: Staged,
        /// The file to replace.
        target: PathBuf,
    },
}

struct Slot {
    path: PathBuf,
    dest: Option<Dest>,
    written: bool,
}

/// The outputs of one run (see the [module docs](self)).
#[derive(Default)]
pub struct Outputs {
    inputs: Vec<(PathBuf, Identity)>,
    slots: Vec<Slot>,
    checked: bool,
}

/// Whether `path` means standard input or output.
#[must_use]
pub fn is_std_stream(path: &Path) -> bool {
    path.as_os_str() == "-"
}

impl Outputs {
    /// No inputs, no outputs.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Declares an input file that no output may overwrite. `-` (standard input) and paths
    /// that do not name an existing regular file are ignored: they cannot be overwritten.
    pub fn input(&mut self, path: impl AsRef<Path>) {
        let path = path.as_ref();
        if is_std_stream(path) {
            return;
        }
        if let Ok(meta) = std::fs::metadata(path)
            && meta.is_file()
            && let Ok(key) = file_key(path, &meta)
        {
            self.inputs.push((path.to_owned(), Identity::Existing(key)));
        }
    }

    /// Declares an output; `-` is standard output. Nothing is checked or created until
    /// [`Outputs::check`].
    pub fn output(&mut self, path: impl AsRef<Path>) -> OutputId {
        self.slots.push(Slot { path: path.as_ref().to_owned(), dest: None, written: false });
        OutputId(self.slots.len() - 1)
    }

    /// The path of an output, as declared.
    #[must_use]
    pub fn path(&self, id: OutputId) -> &Path {
        &self.slots[id.0].path
    }

    /// Checks every declared output (see the [module docs](self) for what is refused) and
    /// creates the temporary file of each regular one, so that a folder that cannot be written
    /// fails now, before any heavy work. Call it once, after declaring everything.
    ///
    /// # Errors
    /// [`IoError::Output`] naming the first output refused.
    pub fn check(&mut self) -> Result<(), IoError> {
        let mut seen: Vec<(usize, Identity)> = Vec::new();
        for i in 0..self.slots.len() {
            if self.slots[i].dest.is_some() {
                continue;
            }
            let path = self.slots[i].path.clone();
            let (dest, identity) = examine(&path)?;
            if let Some(id) = &identity {
                if let Some((input, _)) = self.inputs.iter().find(|(_, other)| other == id) {
                    return Err(OutputError::SameAsInput { path, input: input.clone() }.into());
                }
                if let Some((j, _)) = seen.iter().find(|(_, other)| other == id) {
                    let other = self.slots[*j].path.clone();
                    return Err(OutputError::SameAsOutput { path, other }.into());
                }
                seen.push((i, id.clone()));
            } else if matches!(dest, Dest::Stdout)
                && let Some(j) = self.slots[..i].iter().position(|s| is_std_stream(&s.path))
            {
                let other = self.slots[j].path.clone();
                return Err(OutputError::SameAsOutput { path, other }.into());
            }
            self.slots[i].dest = Some(dest);
        }
        self.checked = true;
        Ok(())
    }

    /// Writes output `id`: `body` gets a buffered writer whose errors name the output (e.g.
    /// `cannot write /dev/full: No space left on device`), and the writer is flushed after it.
    /// A regular file goes to its temporary file until [`Outputs::commit`]; standard output
    /// and devices are written now. Each output is written once.
    ///
    /// # Errors
    /// `body`'s error, or [`IoError::Write`] when flushing fails (converted to `E`).
    ///
    /// # Panics
    /// When [`Outputs::check`] has not succeeded, or `id` was written before (programming
    /// errors, not bad input).
    pub fn write_with<E: From<IoError>>(
        &mut self,
        id: OutputId,
        body: impl FnOnce(&mut dyn Write) -> Result<(), E>,
    ) -> Result<(), E> {
        let name = display_name(&self.slots[id.0].path);
        let mut sink = BufWriter::new(self.sink(id)?);
        let mut named = Named { inner: &mut sink, name: &name };
        body(&mut named)?;
        sink.flush().map_err(|reason| IoError::Write { path: PathBuf::from(&name), reason })?;
        Ok(())
    }

    /// Writes an image to output `id` (see [`crate::write_image`] for the formats).
    ///
    /// # Errors
    /// [`IoError::UnsupportedOutput`] when the extension does not fit the layout,
    /// [`IoError::Write`] or [`IoError::Encode`] when writing fails.
    ///
    /// # Panics
    /// As [`Outputs::write_with`], and when the sample count does not fit the size and layout.
    pub fn write_image(
        &mut self,
        id: OutputId,
        width: u32,
        height: u32,
        layout: PixelLayout,
        pixels: Pixels<'_>,
    ) -> Result<(), IoError> {
        let path = self.slots[id.0].path.clone();
        crate::check_output(&path, layout)?;
        let img = crate::to_image(width, height, layout, pixels);
        self.write_file(id, |w| crate::encode_image(w, &img, layout))
    }

    /// Writes output `id` through a seekable writer (encoders that need one, such as EXR's).
    /// Outputs that cannot seek (standard output, devices) are encoded in memory first.
    pub(crate) fn write_file(
        &mut self,
        id: OutputId,
        body: impl FnOnce(&mut dyn WriteSeek) -> Result<(), WriteFail>,
    ) -> Result<(), IoError> {
        let path = self.slots[id.0].path.clone();
        let fail = |e: WriteFail| e.naming(&path);
        match self.sink(id)? {
            Sink::Staged(file) => {
                let mut w = BufWriter::new(file);
                body(&mut w).map_err(fail)?;
                w.flush().map_err(|e| fail(WriteFail::Io(e)))?;
            }
            mut other => {
                let mut bytes = std::io::Cursor::new(Vec::new());
                body(&mut bytes).map_err(fail)?;
                other.write_all(bytes.get_ref()).and_then(|()| other.flush()).map_err(|e| fail(WriteFail::Io(e)))?;
            }
        }
        Ok(())
    }

    /// Runs `body` on output `id`'s own file: the temporary file of a regular output, the
    /// device itself otherwise (see [`crate::write_atomically`]).
    pub(crate) fn with_file(
        &mut self,
        id: OutputId,
        body: impl FnOnce(&mut File) -> Result<(), WriteFail>,
    ) -> Result<(), IoError> {
        let path = self.slots[id.0].path.clone();
        let fail = |e: WriteFail| e.naming(&path);
        match self.sink(id)? {
            Sink::Staged(file) => body(file).map_err(fail),
            Sink::Device(mut file) => body(&mut file).map_err(fail),
            Sink::Stdout(_) => {
                let reason = std::io::Error::other("standard output is not a file");
                Err(fail(WriteFail::Io(reason)))
            }
        }
    }

    /// Renames every staged output into place (each synced to disk first). Standard output and
    /// devices were written already. Nothing is renamed when a staged file cannot be synced.
    ///
    /// # Errors
    /// [`IoError::Write`] naming the output that could not be synced or renamed.
    ///
    /// # Panics
    /// When an output was declared but never written (a programming error).
    pub fn commit(mut self) -> Result<(), IoError> {
        assert!(self.checked, "Outputs::commit before Outputs::check");
        for slot in &self.slots {
            assert!(slot.written, "output {} was declared but not written", slot.path.display());
            if let Some(Dest::Replace { tmp, .. }) = &slot.dest {
                tmp.file().sync_all().map_err(|reason| IoError::Write { path: slot.path.clone(), reason })?;
            }
        }
        // All renames under the registry: an interruption waits for them to be done.
        let mut registry = registry();
        for slot in &mut self.slots {
            if let Some(Dest::Replace { tmp, target }) = &mut slot.dest {
                tmp.persist(&mut registry, target)
                    .map_err(|reason| IoError::Write { path: slot.path.clone(), reason })?;
            }
        }
        Ok(())
    }

    fn sink(&mut self, id: OutputId) -> Result<Sink<'_>, IoError> {
        let slot = &mut self.slots[id.0];
        assert!(!slot.written, "output {} written twice", slot.path.display());
        slot.written = true;
        let path = slot.path.clone();
        match slot.dest.as_mut().expect("Outputs::check succeeded before writing") {
            Dest::Stdout => Ok(Sink::Stdout(std::io::stdout().lock())),
            Dest::Direct => {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .open(&path)
                    .map_err(|reason| IoError::Write { path: path.clone(), reason })?;
                Ok(Sink::Device(file))
            }
            Dest::Replace { tmp, .. } => Ok(Sink::Staged(tmp.file_mut())),
        }
    }
}

/// What `check` decides about one output: where it goes, and its identity when it is (or will
/// be) a regular file.
fn examine(path: &Path) -> Result<(Dest, Option<Identity>), IoError> {
    if is_std_stream(path) {
        if stdout_was_closed() {
            let reason = std::io::Error::other("standard output is closed (nothing would be written)");
            return Err(OutputError::Unusable { path: path.to_owned(), reason }.into());
        }
        return Ok((Dest::Stdout, None));
    }
    let unusable = |reason| OutputError::Unusable { path: path.to_owned(), reason };
    let (meta, is_link) = match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => (None, false),
        Err(e) => return Err(unusable(e).into()),
        Ok(link) if link.file_type().is_symlink() => match std::fs::metadata(path) {
            Ok(meta) => (Some(meta), true),
            Err(_) => {
                let target = std::fs::read_link(path).unwrap_or_default();
                return Err(OutputError::DanglingLink { path: path.to_owned(), target }.into());
            }
        },
        Ok(meta) => (Some(meta), false),
    };
    let Some(meta) = meta else {
        let target = path.to_owned();
        // A new file: its folder must exist.
        let folder = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        let Some(name) = path.file_name() else {
            return Err(OutputError::Folder { path: path.to_owned() }.into());
        };
        if !folder.is_dir() {
            return Err(OutputError::NoFolder { path: path.to_owned(), folder }.into());
        }
        let canonical = std::fs::canonicalize(&folder).map_err(unusable)?.join(name);
        let tmp = stage_in(&folder, None).map_err(unusable)?;
        return Ok((Dest::Replace { tmp, target }, Some(Identity::New(canonical))));
    };
    if meta.is_dir() {
        return Err(OutputError::Folder { path: path.to_owned() }.into());
    }
    if !meta.is_file() {
        // A device, FIFO or socket: written in place, never compared (two writes to
        // /dev/null overwrite nothing).
        return Ok((Dest::Direct, None));
    }
    if is_read_only(&meta) {
        return Err(OutputError::ReadOnly { path: path.to_owned() }.into());
    }
    // A link is written through: the file it points to is replaced, the link stays.
    let target = if is_link { std::fs::canonicalize(path).map_err(unusable)? } else { path.to_owned() };
    let key = file_key(&target, &meta).map_err(unusable)?;
    let folder = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    let tmp = stage_in(&folder, Some(&meta)).map_err(unusable)?;
    Ok((Dest::Replace { tmp, target }, Some(Identity::Existing(key))))
}

/// Whether the program was started with its standard output closed (`>&-`). Rust's runtime
/// then opens `/dev/null` in its place, read-write, so that every write would vanish without an
/// error; a redirection to `/dev/null` opens it write-only, and is a choice. Linux only (it
/// reads `/proc/self/fdinfo/1`); `false` elsewhere.
fn stdout_was_closed() -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::{FileTypeExt, MetadataExt};
        let Ok(info) = std::fs::read_to_string("/proc/self/fdinfo/1") else { return false };
        let flags =
            info.lines().find_map(|l| l.strip_prefix("flags:")).and_then(|f| u32::from_str_radix(f.trim(), 8).ok());
        // O_ACCMODE: 2 is O_RDWR.
        let read_write = flags.is_some_and(|f| f & 3 == 2);
        let is_null = match (std::fs::metadata("/proc/self/fd/1"), std::fs::metadata("/dev/null")) {
            (Ok(out), Ok(null)) => out.file_type().is_char_device() && out.rdev() == null.rdev(),
            _ => false,
        };
        read_write && is_null
    }
    #[cfg(not(target_os = "linux"))]
    false
}

/// Read-only by its permission bits (not by trying: root can write anything).
#[cfg(unix)]
fn is_read_only(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::PermissionsExt;
    meta.permissions().mode() & 0o222 == 0
}

#[cfg(not(unix))]
fn is_read_only(meta: &std::fs::Metadata) -> bool {
    meta.permissions().readonly()
}

/// A temporary file in `folder` with the permissions of the file it replaces, or ordinary ones
/// for a new file (temporary files are private by default; the umask still applies).
fn stage_in(folder: &Path, replaces: Option<&std::fs::Metadata>) -> std::io::Result<Staged> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(".pomkit-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = replaces.map_or(0o666, |m| m.permissions().mode() & 0o7777);
        builder.permissions(std::fs::Permissions::from_mode(mode));
    }
    #[cfg(not(unix))]
    let _ = replaces;
    Staged::create(folder, &builder)
}

// ---------------------------------------------------------------------------------------------
// The registry of staged files
// ---------------------------------------------------------------------------------------------

/// Every staged file of the process, and whether [`remove_staged_files`] has run.
struct Registry {
    paths: Vec<PathBuf>,
    removed: bool,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry { paths: Vec::new(), removed: false });
/// Never notified: what the other threads wait on forever once the staged files are removed.
static NEVER: Condvar = Condvar::new();

thread_local! {
    /// Whether this thread removed the staged files (it may still write, e.g. a report).
    static REMOVER: Cell<bool> = const { Cell::new(false) };
}

/// The registry, locked. Once [`remove_staged_files`] has run, every other thread blocks here
/// for good (the process is about to exit): nothing more is staged or committed.
fn registry() -> MutexGuard<'static, Registry> {
    let mut guard = REGISTRY.lock().unwrap_or_else(PoisonError::into_inner);
    while guard.removed && !REMOVER.get() {
        guard = NEVER.wait(guard).unwrap_or_else(PoisonError::into_inner);
    }
    guard
}

/// Removes every file staged by any [`Outputs`] of the process, waiting for a commit in progress
/// to finish first, and returns how many were removed. From then on, other threads that stage,
/// commit or drop an output block for good; the calling thread may still write and commit (a
/// batch's report). Meant for a program that is about to exit on a signal.
pub fn remove_staged_files() -> usize {
    let mut registry = REGISTRY.lock().unwrap_or_else(PoisonError::into_inner);
    registry.removed = true;
    REMOVER.set(true);
    let mut removed = 0;
    for path in registry.paths.drain(..) {
        if std::fs::remove_file(&path).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// A staged file, listed in the registry from its creation until it is renamed into place or
/// removed.
struct Staged(Option<tempfile::NamedTempFile>);

impl Staged {
    fn create(folder: &Path, builder: &tempfile::Builder<'_, '_>) -> std::io::Result<Self> {
        let mut registry = registry();
        let tmp = builder.tempfile_in(folder)?;
        registry.paths.push(tmp.path().to_owned());
        Ok(Self(Some(tmp)))
    }

    fn file(&self) -> &File {
        self.0.as_ref().expect("a staged file before it is renamed").as_file()
    }

    fn file_mut(&mut self) -> &mut File {
        self.0.as_mut().expect("a staged file before it is renamed").as_file_mut()
    }

    /// Renames the staged file over `target`; `registry` is the locked registry. On failure the
    /// staged file is removed.
    fn persist(&mut self, registry: &mut Registry, target: &Path) -> std::io::Result<()> {
        let tmp = self.0.take().expect("a staged file is renamed once");
        let path = tmp.path().to_owned();
        registry.paths.retain(|p| *p != path);
        match tmp.persist(target) {
            Ok(_) => Ok(()),
            Err(e) => {
                drop(e.file);
                Err(e.error)
            }
        }
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if let Some(tmp) = self.0.take() {
            let mut registry = registry();
            let path = tmp.path().to_owned();
            registry.paths.retain(|p| *p != path);
            let _ = tmp.close();
        }
    }
}

fn display_name(path: &Path) -> String {
    if is_std_stream(path) { "standard output".to_owned() } else { path.display().to_string() }
}

/// A writer and a seek: what image encoders need.
pub(crate) trait WriteSeek: Write + Seek {}
impl<T: Write + Seek> WriteSeek for T {}

/// Where an output's bytes go.
enum Sink<'a> {
    Staged(&'a mut File),
    Device(File),
    Stdout(std::io::StdoutLock<'static>),
}

impl Write for Sink<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Sink::Staged(f) => f.write(buf),
            Sink::Device(f) => f.write(buf),
            Sink::Stdout(s) => s.write(buf),
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Sink::Staged(f) => f.flush(),
            Sink::Device(f) => f.flush(),
            Sink::Stdout(s) => s.flush(),
        }
    }
}

/// A writer whose errors name the output.
struct Named<'a, W: Write> {
    inner: &'a mut W,
    name: &'a str,
}

impl<W: Write> Named<'_, W> {
    fn name_err(&self, e: std::io::Error) -> std::io::Error {
        std::io::Error::new(e.kind(), format!("cannot write {}: {e}", self.name))
    }
}

impl<W: Write> Write for Named<'_, W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.inner.write(buf).map_err(|e| self.name_err(e))
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush().map_err(|e| self.name_err(e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    fn write(outs: &mut Outputs, id: OutputId, text: &str) {
        outs.write_with(id, |w| {
            w.write_all(text.as_bytes()).map_err(|reason| IoError::Write { path: PathBuf::new(), reason })
        })
        .unwrap();
    }

    #[test]
    fn commit_writes_all_outputs_and_dropping_writes_none() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
        std::fs::write(&b, "old").unwrap();
        let mut outs = Outputs::new();
        let (ia, ib) = (outs.output(&a), outs.output(&b));
        outs.check().unwrap();
        write(&mut outs, ia, "A");
        write(&mut outs, ib, "B");
        // Staged, not yet in place.
        assert!(!a.exists());
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "old");
        outs.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "A");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "B");
        assert_eq!(names(dir.path()), ["a.txt", "b.txt"]);

        // A run that fails after writing one output: nothing changes, no temporary file stays.
        let c = dir.path().join("c.txt");
        let mut outs = Outputs::new();
        let (ia, ic) = (outs.output(&a), outs.output(&c));
        outs.check().unwrap();
        write(&mut outs, ia, "new A");
        let failed: Result<(), IoError> = outs.write_with(ic, |w| {
            w.write_all(b"half").map_err(|reason| IoError::Write { path: c.clone(), reason })?;
            Err(IoError::Write { path: c.clone(), reason: std::io::Error::other("disk full") })
        });
        assert!(failed.is_err());
        drop(outs);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "A");
        assert_eq!(names(dir.path()), ["a.txt", "b.txt"]);
    }

    #[test]
    fn the_same_file_through_any_path_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir(d.join("sub")).unwrap();
        let input = d.join("in.png");
        std::fs::write(&input, "input").unwrap();
        let refused = |input_path: &Path, outputs: &[PathBuf]| -> String {
            let mut outs = Outputs::new();
            outs.input(input_path);
            for o in outputs {
                outs.output(o);
            }
            outs.check().err().map(|e| e.to_string()).unwrap_or_default()
        };
        let via_dots = d.join("sub/../in.png");
        let msg = refused(&input, std::slice::from_ref(&via_dots));
        assert!(msg.contains("same file as the input") && msg.contains("sub/../in.png"), "{msg}");
        std::fs::hard_link(&input, d.join("hard.png")).unwrap();
        assert!(refused(&input, &[d.join("hard.png")]).contains("same file as the input"));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("in.png", d.join("link.png")).unwrap();
            assert!(refused(&input, &[d.join("link.png")]).contains("same file as the input"));
            assert!(refused(&d.join("link.png"), std::slice::from_ref(&input)).contains("same file as the input"));
        }
        // Two outputs that do not exist yet, one through `..`.
        let msg = refused(&input, &[d.join("new.png"), d.join("sub/../new.png")]);
        assert!(msg.contains("same file as the output"), "{msg}");
        // Different files pass, and the check left only the input and links behind.
        assert_eq!(refused(&input, &[d.join("other.png"), d.join("sub/other.png")]), "");
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "input");
        assert!(names(d).iter().all(|n| !n.ends_with(".tmp")), "{:?}", names(d));
    }

    #[test]
    fn read_only_folders_and_missing_folders_are_refused_up_front() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let ro = d.join("ro.txt");
        std::fs::write(&ro, "keep").unwrap();
        let mut perms = std::fs::metadata(&ro).unwrap().permissions();
        perms.set_readonly(true);
        std::fs::set_permissions(&ro, perms).unwrap();
        let check = |p: &Path| {
            let mut outs = Outputs::new();
            outs.output(p);
            outs.check().err().map(|e| e.to_string()).unwrap_or_default()
        };
        assert!(check(&ro).contains("ro.txt: it is read-only"), "{}", check(&ro));
        assert!(check(d).contains("it is a folder"));
        assert!(check(&d.join("no/x.txt")).contains("does not exist"));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("missing.txt", d.join("dangling.txt")).unwrap();
            assert!(check(&d.join("dangling.txt")).contains("missing.txt, which does not exist"));
        }
        assert_eq!(std::fs::read_to_string(&ro).unwrap(), "keep");
    }

    #[cfg(unix)]
    #[test]
    fn symlinks_are_written_through_and_devices_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("target.txt"), "old").unwrap();
        std::os::unix::fs::symlink("target.txt", d.join("link.txt")).unwrap();
        let mut outs = Outputs::new();
        let id = outs.output(d.join("link.txt"));
        outs.check().unwrap();
        write(&mut outs, id, "new");
        outs.commit().unwrap();
        assert!(std::fs::symlink_metadata(d.join("link.txt")).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(d.join("target.txt")).unwrap(), "new");

        // /dev/full: written in place (not renamed over), and the error names it.
        if Path::new("/dev/full").exists() {
            let mut outs = Outputs::new();
            let id = outs.output("/dev/full");
            outs.check().unwrap();
            let err = outs.write_with(id, |w| {
                w.write_all(&[b'x'; 100_000]).map_err(|reason| IoError::Write { path: PathBuf::new(), reason })
            });
            let msg = err.unwrap_err().to_string();
            assert!(msg.contains("cannot write /dev/full"), "{msg}");
            use std::os::unix::fs::FileTypeExt;
            assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device());
        }
    }
}
