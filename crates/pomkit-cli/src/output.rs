//! Text outputs (CSV, Markdown, JSON) of one-output verbs: to a file, staged and committed by
//! [`pomkit_io::output::Outputs`], or to standard output for `-`.

use std::path::Path;

/// Whether `path` means standard input or output.
pub fn is_stdout(path: &Path) -> bool {
    pomkit_io::output::is_std_stream(path)
}
