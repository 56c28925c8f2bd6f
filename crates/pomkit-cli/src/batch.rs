//! The batch options of `pomkit bake` (a whole texture library: several inputs, folders and
//! globs, baked in parallel into an output folder; README, "Baking a library") and the command
//! line's side of a batch: its progress bar and its interruption by a signal. The batch itself
//! (finding the files, naming and checking their outputs, baking them within the memory
//! budget, the summary and the report) is [`pomkit_io::batch`]; what one file's bake is comes
//! from bake.rs, through [`pomkit_io::batch::Baker`].

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use pomkit_io::batch::{self, Baker, Batch, Progress, Template};

/// The batch options of every `bake` verb.
#[derive(Args, Debug, Default)]
pub struct BatchArgs {
    /// Walk folder inputs' subfolders too; outputs mirror them under OUT.
    #[arg(long)]
    recursive: bool,
    /// Output file name in a batch: {stem} (the input's name without its extension), {name}
    /// (its whole name) and {ext} (png, or exr for float encodings). Default
    /// '{stem}_normal.{ext}', '{stem}_parallax.{ext}', '{stem}_packed.{ext}', '{stem}_maxmip.{ext}',
    /// '{stem}_cone.{ext}' or '{stem}_height.{ext}' ('{stem}_height.exr' writes float heights).
    #[arg(long, value_name = "TEMPLATE")]
    name: Option<String>,
    /// Bake outputs that exist already (a batch skips them otherwise, so that a rerun only
    /// bakes what is missing).
    #[arg(long)]
    overwrite: bool,
    /// Write a JSON report of the batch here: one entry per file with its input, outputs,
    /// status, size, time and error.
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Options per folder or per name pattern, as TOML `[[rule]]` tables (README, "Baking a
    /// library").
    #[arg(long, value_name = "FILE.toml")]
    pub(crate) config: Option<PathBuf>,
    /// Files baked at once (default: the number of cores), as many as fit in the memory budget
    /// together.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    jobs: Option<u32>,
}

impl BatchArgs {
    /// The batch options given, as flags.
    fn given(&self) -> Vec<&'static str> {
        let flags = [
            (self.recursive, "--recursive"),
            (self.name.is_some(), "--name"),
            (self.overwrite, "--overwrite"),
            (self.report.is_some(), "--report"),
            (self.config.is_some(), "--config"),
            (self.jobs.is_some(), "--jobs"),
        ];
        flags.into_iter().filter(|(on, _)| *on).map(|(_, flag)| flag).collect()
    }
}

/// Whether a `bake` command is a batch: several inputs, a folder, a glob that names no file, or
/// any batch option. Otherwise it is the single bake of one file into one output file.
pub(crate) fn is_batch(inputs: &[PathBuf], args: &BatchArgs) -> bool {
    batch::is_batch(inputs, !args.given().is_empty())
}

/// The `--name` template, or `default` (the verb's).
pub(crate) fn template(args: &BatchArgs, default: &str) -> Result<Template> {
    Ok(Template::parse(args.name.as_deref().unwrap_or(default))?)
}

/// Runs a batch of `inputs` into the folder `out`, baked by `baker`, with a progress bar; an
/// interruption prints the summary and writes the report. `verb` and `relief` are for the
/// report (its verb, and whether each file's relief is in it).
pub(crate) fn run<B: Baker>(
    baker: &B,
    inputs: &[PathBuf],
    args: &BatchArgs,
    out: &Path,
    template: Template,
    (verb, relief): (&'static str, bool),
) -> Result<()> {
    let batch = Batch {
        inputs,
        out,
        template,
        recursive: args.recursive,
        overwrite: args.overwrite,
        report: args.report.clone(),
        config: args.config.clone(),
        jobs: args.jobs.map_or_else(rayon::current_num_threads, |j| j as usize),
        given: args.given(),
        verb,
        relief,
    };
    batch::run(&batch, baker, |hook| crate::interrupt::on_interrupt(hook), Bar::new)?;
    Ok(())
}

/// The batch's progress bar: the inputs' bytes, and the files done.
struct Bar(ProgressBar);

impl Bar {
    fn new(total_bytes: u64, files: usize) -> Self {
        let pb = ProgressBar::new(total_bytes);
        pb.set_style(
            ProgressStyle::with_template("{msg:>14} [{bar:40}] {bytes}/{total_bytes}, {eta} left")
                .expect("valid template")
                .progress_chars("=> "),
        );
        pb.set_message(format!("0/{files} files"));
        Self(pb)
    }
}

impl Progress for Bar {
    fn file_done(&self, files_done: usize, files: usize, bytes_done: u64) {
        self.0.set_position(bytes_done);
        self.0.set_message(format!("{files_done}/{files} files"));
    }

    fn finish(&self) {
        self.0.finish_and_clear();
    }
}
