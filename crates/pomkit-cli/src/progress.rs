//! Progress bars for long work: shown on a terminal for jobs big enough to take a while.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Jobs over fewer texels than this finish in well under a second: no bar.
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

/// Runs `work` with a bar over `height` rows of `width` texels labelled `what` (hidden for small
/// jobs); `work` reports rows done through the callback it is given, from any thread.
pub fn rows<T>(height: u32, width: u32, what: &str, work: impl FnOnce(&(dyn Fn(u32) + Sync)) -> T) -> T {
    let pb = bar(u64::from(height), u64::from(width), what);
    let out = work(&|n| pb.inc(u64::from(n)));
    pb.finish_and_clear();
    out
}

/// Runs `work` under a spinner labelled `what` when it covers enough texels to take a while.
pub fn spinner<T>(texels: u64, what: &str, work: impl FnOnce() -> T) -> T {
    spinner_when(texels >= MIN_TEXELS, what, work)
}

/// Runs `work` under a spinner labelled `what` when `show` (and, by indicatif, stderr is a
/// terminal): for work that reports no progress, such as a GPU frame.
pub fn spinner_when<T>(show: bool, what: &str, work: impl FnOnce() -> T) -> T {
    if !show {
        return work();
    }
    let pb = ProgressBar::new_spinner();
    pb.set_message(what.to_owned());
    pb.enable_steady_tick(Duration::from_millis(120));
    let out = work();
    pb.finish_and_clear();
    out
}

/// A bar over `total` items named `unit` (rays...), hidden below `min_total` items (and, by
/// indicatif, when stderr is not a terminal).
pub fn items(total: u64, min_total: u64, what: &str, unit: &str) -> ProgressBar {
    if total < min_total {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total);
    let template = format!("{{msg:>10}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{eta}} left");
    pb.set_style(ProgressStyle::with_template(&template).expect("valid template").progress_chars("=> "));
    pb.set_message(what.to_owned());
    pb
}

/// A count of items whose total is not known in advance (rays streamed in), drawn once it
/// passes `min_shown` items (and, by indicatif, only when stderr is a terminal).
pub struct Counter {
    pb: ProgressBar,
    min_shown: u64,
    shown: bool,
}

impl Counter {
    /// A hidden counter of `unit`s labelled `what`.
    pub fn new(min_shown: u64, what: &str, unit: &str) -> Self {
        let pb = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
        let template = format!("{{msg:>10}} {{pos}} {unit} ({{per_sec}}), {{elapsed}}");
        pb.set_style(ProgressStyle::with_template(&template).expect("valid template"));
        pb.set_message(what.to_owned());
        Self { pb, min_shown, shown: false }
    }

    /// Counts `n` more items.
    pub fn inc(&mut self, n: u64) {
        self.pb.inc(n);
        if !self.shown && self.pb.position() >= self.min_shown {
            self.pb.set_draw_target(ProgressDrawTarget::stderr());
            self.shown = true;
        }
    }

    /// Removes the counter from the terminal.
    pub fn finish(&self) {
        self.pb.finish_and_clear();
    }
}
