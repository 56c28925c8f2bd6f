//! Progress bars for long work: shown on a terminal for jobs big enough to take a while.

use indicatif::{ProgressBar, ProgressStyle};

/// Work below this many units of `per_unit` texels finishes in well under a second.
const MIN_TEXELS: u64 = 2_000_000;

/// A bar over `total` units (rows, tiles...) of about `texels_per_unit` texels each, hidden for
/// small jobs (and, by indicatif, when stderr is not a terminal).
pub fn bar(total: u64, texels_per_unit: u64, what: &str) -> ProgressBar {
    if total.saturating_mul(texels_per_unit) < MIN_TEXELS {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} rows, {eta} left")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}
