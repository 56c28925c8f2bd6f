//! Text outputs (CSV, Markdown, JSON) of one-output verbs: to a file, staged and committed by
//! [`pomkit_io::output::Outputs`], or to standard output for `-`.

use std::io::Write;
use std::path::Path;

use anyhow::Result;
use pomkit_io::output::Outputs;

/// Whether `path` means standard input or output.
pub fn is_stdout(path: &Path) -> bool {
    pomkit_io::output::is_std_stream(path)
}

/// Writes what `body` produces to `path` (a file appears only once complete; a failure leaves
/// nothing behind), or to standard output when `path` is `-`. Every write error, a full disk
/// or a closed standard output included, is an error naming the output.
pub fn write_text(path: &Path, body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let mut outs = Outputs::new();
    let id = outs.output(path);
    outs.check()?;
    outs.write_with(id, |w| body(w).map_err(anyhow::Error::from))?;
    outs.commit()?;
    Ok(())
}
