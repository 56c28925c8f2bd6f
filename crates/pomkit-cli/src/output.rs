//! Text outputs (CSV, Markdown, JSON): to a file, written atomically, or to stdout for `-`.

use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result, bail};
use pomkit_io::WriteFail;

/// Whether `path` means standard output.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// Fails early, before any heavy work, when `path` cannot be an output file: it is a folder or
/// its folder does not exist. Standard output (`-`) always passes.
pub fn check_writable(path: &Path) -> Result<()> {
    if is_stdout(path) {
        return Ok(());
    }
    if path.is_dir() {
        bail!("cannot write {}: it is a folder", path.display());
    }
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!("cannot write {}: its folder {} does not exist", path.display(), dir.display());
    }
    Ok(())
}

/// Writes what `body` produces to `path` (atomically: a temporary file renamed into place, so a
/// failure leaves nothing behind), or to stdout when `path` is `-`.
pub fn write_text(path: &Path, body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    if is_stdout(path) {
        let stdout = std::io::stdout();
        let mut w = BufWriter::new(stdout.lock());
        body(&mut w).and_then(|()| w.flush()).context("cannot write to stdout")?;
        return Ok(());
    }
    pomkit_io::write_atomically(path, |file| {
        let mut w = BufWriter::new(file);
        body(&mut w).and_then(|()| w.flush()).map_err(WriteFail::Io)
    })?;
    Ok(())
}
