//! A bake over a whole texture library (`pomkit bake` with several inputs, folders or globs;
//! README, "Baking a library"; docs/LIMITS.md for how outputs are written): finding the files,
//! naming their outputs, checking everything that can be checked before baking, baking them in
//! parallel within the memory budget, then the summary and the JSON report.
//!
//! What one file's bake is, its options (a config's rules applied) and its memory estimate come
//! from the caller, through [`Baker`]; progress is shown by the caller, through [`Progress`],
//! and interruption (a signal) is wired by the caller too (the `on_interrupt` of [`run`]). This
//! module knows nothing of command-line parsing; its messages name the command line's flags
//! (`--name`, `--overwrite`, `--report`...), as the rest of the batch's messages do.
//!
//! Every file is baked by [`Baker::bake`], as a single bake is: its output is staged beside its
//! destination and renamed into place only when it is whole, so a file that fails leaves
//! nothing behind, and an interrupted batch leaves only finished outputs, which the next run
//! skips. Files are admitted by their memory estimate: the files being baked at once fit in the
//! memory budget together ([`pomkit_core::memory`]).

use std::collections::{HashMap, HashSet, VecDeque};
use std::error::Error;
use std::ffi::{OsStr, OsString};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

use pomkit_core::memory::{Budget, MemoryError};

use crate::output::{FileKey, OutputId, Outputs, regular_file_key};

/// Extensions of the files a folder input contributes (compared without case).
pub const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "tif", "tiff", "exr"];

/// Why a batch could not run, or why some of its files failed. The message is complete: it
/// holds the reasons of the errors it came from, as `context: reason: its reason`.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BatchError(String);

impl BatchError {
    fn new(message: impl Into<String>) -> Self {
        Self(message.into())
    }

    /// `context: ` and `error` with its sources.
    fn context(context: impl std::fmt::Display, error: &(dyn Error + 'static)) -> Self {
        Self(format!("{context}: {}", error_chain(error)))
    }
}

/// `error` and its sources, joined by `: ` (as `anyhow` shows an error with `{:#}`).
pub fn error_chain(error: &(dyn Error + 'static)) -> String {
    let mut s = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        s.push_str(": ");
        s.push_str(&e.to_string());
        source = e.source();
    }
    s
}

/// Whether a bake is a batch: several inputs, a folder, a glob that names no file, or any batch
/// option (`any_option`). Otherwise it is the single bake of one file into one output file.
pub fn is_batch(inputs: &[PathBuf], any_option: bool) -> bool {
    inputs.len() > 1 || any_option || inputs.iter().any(|p| p.is_dir() || is_glob(p))
}

/// A glob that names no file as it is.
fn is_glob(path: &Path) -> bool {
    has_glob(&path.to_string_lossy()) && !path.exists()
}

fn has_glob(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// One file of the batch, as found.
#[derive(Debug)]
pub struct Item {
    /// What to load: a path, or `builtin:NAME[:WxH]`.
    pub input: PathBuf,
    /// The folder under the output folder its output goes to (its folder relative to the
    /// folder or glob base it was found under).
    pub rel_dir: PathBuf,
    /// Its file name (for `builtin:` inputs, the pattern name).
    pub name: OsString,
    /// Its size in bytes, when it is a readable regular file.
    pub bytes: Option<u64>,
    /// Why it cannot be baked, found before baking (a folder, a FIFO, ...).
    problem: Option<String>,
}

impl Item {
    /// Whether a config rule with this `match` pattern (on the file name) and `folder` (a
    /// prefix of [`Item::rel_dir`]) applies to this file; a rule without one matches every file.
    pub fn matches(&self, pattern: Option<&glob::Pattern>, folder: Option<&Path>) -> bool {
        let name_ok = pattern.is_none_or(|p| p.matches(&self.name.to_string_lossy()));
        let folder_ok = folder.is_none_or(|f| self.rel_dir.starts_with(f));
        name_ok && folder_ok
    }
}

/// What one bake made: the map's size and, for `bake height`, the relief the normals imply.
#[derive(Clone, Copy, Debug)]
pub struct Baked {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `bake height`: the relief.
    pub relief: Option<Relief>,
}

/// The relief integrated from a normal map.
#[derive(Clone, Copy, Debug)]
pub struct Relief {
    /// Height range in texel widths.
    pub range: f32,
    /// The range as a depth_scale (UV units: range / width).
    pub depth_scale: f32,
}

/// What a batch bakes: the caller's side of [`run`].
pub trait Baker: Sync {
    /// One file's bake: the verb and its options.
    type Job: Sync;

    /// The job for `item`: the command line's, with every config rule that matches it applied.
    fn job(&self, item: &Item) -> Self::Job;

    /// The extension of `job`'s output (`{ext}` in the name template).
    fn extension(&self, job: &Self::Job) -> &'static str;

    /// An upper bound of the bytes baking `item` as `job` holds at its peak.
    fn estimate(&self, job: &Self::Job, item: &Item) -> u64;

    /// What baking `item` is, for a memory error: `baking rock.png (4096x4096)`.
    fn describe(&self, item: &Item) -> String;

    /// Bakes `input` into `output`, atomically (the output's folder exists); the error is the
    /// whole reason, as the summary lists it.
    fn bake(&self, job: &Self::Job, input: &Path, output: &Path) -> Result<Baked, String>;
}

/// Progress of the baking, shown by the caller (e.g. a progress bar): [`run`] makes one once
/// the files are found and checked.
pub trait Progress: Sync {
    /// One more file is done: `files_done` of `files`, with `bytes_done` of the inputs' bytes.
    fn file_done(&self, files_done: usize, files: usize, bytes_done: u64);
    /// The baking is over (finished or failed), before the summary is printed.
    fn finish(&self);
}

/// What to do when the process is interrupted (a signal) while the files are baked, given the
/// signal's name: print the summary of what was done and write the report. [`run`] hands one
/// to its `on_interrupt`, to run after the staged outputs are removed.
pub type InterruptHook = Box<dyn FnOnce(&str) + Send>;

/// A batch: its inputs, its output folder and its options.
#[derive(Debug)]
pub struct Batch<'a> {
    /// The inputs: files, folders, globs and `builtin:` maps.
    pub inputs: &'a [PathBuf],
    /// The output folder.
    pub out: &'a Path,
    /// The output file names.
    pub template: Template,
    /// Walk folder inputs' subfolders too; outputs mirror them under `out`.
    pub recursive: bool,
    /// Bake outputs that exist already (they are skipped otherwise).
    pub overwrite: bool,
    /// Where to write the JSON report.
    pub report: Option<PathBuf>,
    /// The config file of per-folder options (read by the caller; here only protected from
    /// being written over).
    pub config: Option<PathBuf>,
    /// Files baked at once, at most (at least one, and no more than there are files).
    pub jobs: usize,
    /// The batch options given, as flags (`--recursive`...), for messages.
    pub given: Vec<&'static str>,
    /// The verb (`normal`...), for the report.
    pub verb: &'static str,
    /// Whether the report holds each file's relief (`bake height`).
    pub relief: bool,
}

/// What happened to one file.
#[derive(Debug, Clone)]
enum Status {
    /// Baked; its size (and, for `bake height`, the relief), when known.
    Baked(Option<Baked>),
    Skipped,
    Failed(String),
    /// Not baked: the batch was stopped by a signal first.
    Interrupted,
}

#[derive(Clone)]
struct Outcome {
    status: Status,
    seconds: f64,
}

/// Where one file is while the batch runs.
#[derive(Clone)]
enum FileProgress {
    Waiting,
    /// Being baked: since when, and the file its output named before (an interrupted batch
    /// tells by it whether the output was renamed into place).
    Running {
        since: Instant,
        before: Option<FileKey>,
    },
    Done(Outcome),
}

/// What the workers and the interruption handler share.
struct Shared {
    verb: &'static str,
    relief: bool,
    out: PathBuf,
    items: Vec<Item>,
    /// Each file's output.
    outputs: Vec<PathBuf>,
    progress: Mutex<Vec<FileProgress>>,
    report: Option<PathBuf>,
    overwrite: bool,
    started: Instant,
}

/// Runs a batch: finds the files, checks everything that can be checked before baking, bakes
/// in parallel, then prints the failures and the summary to stderr and writes the report.
/// `on_interrupt` is given the hook to run if the process is interrupted while the files are
/// baked; what it returns is dropped once they are (e.g. a guard that removes the hook). Then
/// `progress` is given the inputs' total bytes and the number of files, and returns what shows
/// the progress.
///
/// # Errors
/// [`BatchError`]: a bad output folder or report, no file found, a glob that matches nothing,
/// a folder that cannot be listed, the memory budget's variable, the report that cannot be
/// written, or some files that failed (`N of M files failed (listed above)`).
pub fn run<B: Baker, G, P: Progress>(
    batch: &Batch<'_>,
    baker: &B,
    on_interrupt: impl FnOnce(InterruptHook) -> G,
    progress: impl FnOnce(u64, usize) -> P,
) -> Result<(), BatchError> {
    let started = Instant::now();
    let (inputs, out) = (batch.inputs, batch.out);
    if out.exists() && !out.is_dir() {
        return Err(BatchError::new(format!(
            "{} is not a folder: with several inputs, a folder or a glob, -o names the output folder",
            out.display()
        )));
    }
    if !out.exists() && has_image_extension(out) {
        let why = if inputs.len() > 1 {
            "several inputs make this a batch".to_owned()
        } else if inputs.iter().any(|p| p.is_dir() || is_glob(p)) {
            "a folder or glob input makes this a batch".to_owned()
        } else {
            format!("{} makes this a batch", batch.given.join(" and "))
        };
        return Err(BatchError::new(format!(
            "-o {}: a batch writes its outputs into a folder, and this looks like an image file name ({why}); \
             for a single bake into {}, give one input without --recursive, --name, --overwrite, --report, \
             --config or --jobs",
            out.display(),
            out.display()
        )));
    }
    // The output folder, when it lies inside a folder input, is not walked.
    let out_canonical = std::fs::canonicalize(out).ok();
    let mut items = collect(inputs, batch.recursive, out_canonical.as_deref())?;

    // Every output path, decided before baking.
    let plan = |items: &[Item]| -> Vec<(PathBuf, B::Job)> {
        items
            .iter()
            .map(|item| {
                let job = baker.job(item);
                let output = out.join(&item.rel_dir).join(batch.template.render(&item.name, baker.extension(&job)));
                (output, job)
            })
            .collect()
    };
    // A file that is the output of another file of this batch (a folder baked into itself, an
    // earlier run's outputs) is not an input.
    let first_plans = plan(&items);
    let own_count = drop_own_outputs(&mut items, &first_plans);
    if items.is_empty() {
        let names: Vec<String> = inputs.iter().map(|p| p.display().to_string()).collect();
        return Err(BatchError::new(format!(
            "no height maps found in {} (folders contribute their {} files)",
            names.join(", "),
            IMAGE_EXTENSIONS.join(", ")
        )));
    }
    let plans = plan(&items);
    let problems = problems(&items, &plans, batch.config.as_deref());

    // The report is checked now (never over an input, the config or an output) and written last.
    let report_out = batch.report.as_ref().map(|path| check_report(path, &items, &plans, batch)).transpose()?;
    std::fs::create_dir_all(out)
        .map_err(|e| BatchError::context(format_args!("cannot create the output folder {}", out.display()), &e))?;
    if own_count > 0 {
        eprintln!(
            "{}",
            escape_controls(&format!(
                "note: {own_count} files found are outputs of this batch (its own, or an earlier run's) and are not \
                 read as inputs"
            ))
        );
    }

    let budget = pomkit_core::memory::available_bytes().map_err(|e| BatchError::new(error_chain(&e)))?;
    let (outputs, jobs_per_file): (Vec<PathBuf>, Vec<B::Job>) = plans.into_iter().unzip();
    let total_bytes: u64 = items.iter().filter_map(|i| i.bytes).sum();
    let n = items.len();
    let shared = Arc::new(Shared {
        verb: batch.verb,
        relief: batch.relief,
        out: out.to_owned(),
        items,
        outputs,
        progress: Mutex::new(vec![FileProgress::Waiting; n]),
        report: batch.report.clone(),
        overwrite: batch.overwrite,
        started,
    });
    let hook = {
        let shared = Arc::clone(&shared);
        let hook: InterruptHook = Box::new(move |signal: &str| {
            let outcomes = shared.outcomes_when_interrupted();
            // The report is written anew: its staged file was removed with the others.
            let _ = shared.finish(&outcomes, Some(signal), None);
        });
        on_interrupt(hook)
    };
    let progress = progress(total_bytes, n);
    let jobs = batch.jobs.clamp(1, n);
    bake_all(&shared, baker, &jobs_per_file, &problems, budget, jobs, &progress);
    progress.finish();
    drop(hook);
    let outcomes = shared.outcomes_when_interrupted();
    let (failed, total) = shared.finish(&outcomes, None, report_out)?;
    if failed > 0 {
        return Err(BatchError::new(format!("{failed} of {total} files failed (listed above)")));
    }
    Ok(())
}

/// Removes from `items` the files that are the output of another file of the batch (`plans`
/// holds each file's output); returns how many.
fn drop_own_outputs<J>(items: &mut Vec<Item>, plans: &[(PathBuf, J)]) -> usize {
    // Which files each existing output is: the output of which files (by index).
    let mut own: HashMap<FileKey, Vec<usize>> = HashMap::new();
    for (j, (o, _)) in plans.iter().enumerate() {
        if let Some(k) = regular_file_key(o) {
            own.entry(k).or_default().push(j);
        }
    }
    let is_own: Vec<bool> = items
        .iter()
        .enumerate()
        .map(|(i, item)| {
            regular_file_key(&item.input).and_then(|k| own.get(&k)).is_some_and(|of| of.iter().any(|&j| j != i))
        })
        .collect();
    let own_count = is_own.iter().filter(|&&o| o).count();
    let mut flags = is_own.into_iter();
    items.retain(|_| !flags.next().unwrap_or(false));
    own_count
}

/// Why each file fails before it is baked: its own problem, an output that another file
/// claimed first, or an output that is an input (or the `config`). Existing outputs are not a
/// problem: they are skipped unless the batch overwrites them.
fn problems<J>(items: &[Item], plans: &[(PathBuf, J)], config: Option<&Path>) -> Vec<Option<String>> {
    let mut input_keys: HashMap<FileKey, String> = items
        .iter()
        .filter_map(|item| regular_file_key(&item.input).map(|k| (k, item.input.display().to_string())))
        .collect();
    if let Some(config) = config
        && let Some(k) = regular_file_key(config)
    {
        input_keys.insert(k, format!("--config {}", config.display()));
    }
    let mut claimed: HashMap<PathBuf, usize> = HashMap::new();
    let mut problems: Vec<Option<String>> = Vec::with_capacity(items.len());
    for (i, (item, (output, _))) in items.iter().zip(plans).enumerate() {
        let mut problem = item.problem.clone();
        if problem.is_none() {
            if let Some(&first) = claimed.get(output) {
                problem = Some(format!("{} is also the output of {}", output.display(), items[first].input.display()));
            } else if let Some(input) = regular_file_key(output).as_ref().and_then(|k| input_keys.get(k)) {
                problem =
                    Some(format!("its output {} is the input {input}: refusing to write over it", output.display()));
            } else {
                claimed.insert(output.clone(), i);
            }
        }
        problems.push(problem);
    }
    problems
}

/// Checks the report's file `path` before baking: never an output of the batch, an input or
/// the config. Returns it staged, to be written last.
fn check_report<J>(
    path: &Path,
    items: &[Item],
    plans: &[(PathBuf, J)],
    batch: &Batch<'_>,
) -> Result<(Outputs, OutputId), BatchError> {
    let context = || format!("--report {}", path.display());
    if let Some(report_place) = place(path)
        && let Some((output, _)) = plans.iter().find(|(o, _)| place(o).as_ref() == Some(&report_place))
    {
        return Err(BatchError::new(format!(
            "{}: it is the output {} of this batch; choose another file",
            context(),
            output.display()
        )));
    }
    let mut outs = Outputs::new();
    for item in items {
        outs.input(&item.input);
    }
    if let Some(config) = &batch.config {
        outs.input(config);
    }
    let id = outs.output(path);
    outs.check().map_err(|e| BatchError::context(context(), &e))?;
    Ok((outs, id))
}

/// Bakes every file on `jobs` threads, each admitted once its memory estimate fits in the
/// budget beside the files being baked.
fn bake_all<B: Baker>(
    shared: &Shared,
    baker: &B,
    jobs_per_file: &[B::Job],
    problems: &[Option<String>],
    budget: Option<Budget>,
    jobs: usize,
    progress: &dyn Progress,
) {
    let n = shared.items.len();
    let done = AtomicUsize::new(0);
    let next = AtomicUsize::new(0);
    let bytes_done = AtomicU64::new(0);
    let gate = Gate::new(budget);
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    let item = &shared.items[i];
                    let output = &shared.outputs[i];
                    let t0 = Instant::now();
                    let status = if let Some(p) = &problems[i] {
                        Status::Failed(p.clone())
                    } else if !shared.overwrite && output.exists() {
                        Status::Skipped
                    } else {
                        let job = &jobs_per_file[i];
                        match gate.admit(baker.estimate(job, item), || baker.describe(item)) {
                            Err(e) => Status::Failed(e.to_string()),
                            Ok(ticket) => {
                                shared.set(i, FileProgress::Running { since: t0, before: regular_file_key(output) });
                                let status = bake_one(baker, job, item, output);
                                drop(ticket);
                                status
                            }
                        }
                    };
                    shared.set(i, FileProgress::Done(Outcome { status, seconds: t0.elapsed().as_secs_f64() }));
                    let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                    bytes_done.fetch_add(item.bytes.unwrap_or(0), Ordering::Relaxed);
                    progress.file_done(k, n, bytes_done.load(Ordering::Relaxed));
                }
            });
        }
    });
}

impl Shared {
    fn set(&self, i: usize, p: FileProgress) {
        self.progress.lock().unwrap_or_else(PoisonError::into_inner)[i] = p;
    }

    /// Every file's outcome as it stands: a file being baked counts as baked when its output was
    /// renamed into place (another file than before), as interrupted otherwise.
    fn outcomes_when_interrupted(&self) -> Vec<Outcome> {
        let progress = self.progress.lock().unwrap_or_else(PoisonError::into_inner).clone();
        progress
            .into_iter()
            .zip(&self.outputs)
            .map(|(p, output)| match p {
                FileProgress::Done(o) => o,
                FileProgress::Waiting => Outcome { status: Status::Interrupted, seconds: 0.0 },
                FileProgress::Running { since, before } => {
                    let now = regular_file_key(output);
                    let status = if now.is_some() && now != before { Status::Baked(None) } else { Status::Interrupted };
                    Outcome { status, seconds: since.elapsed().as_secs_f64() }
                }
            })
            .collect()
    }

    /// Prints the failures and the summary, and writes the report (through `report_out`, checked
    /// before baking, or else anew). Returns the number of failed files and of all files.
    fn finish(
        &self,
        outcomes: &[Outcome],
        signal: Option<&str>,
        report_out: Option<(Outputs, OutputId)>,
    ) -> Result<(usize, usize), BatchError> {
        let count = |f: fn(&Status) -> bool| outcomes.iter().filter(|o| f(&o.status)).count();
        let baked = count(|s| matches!(s, Status::Baked(_)));
        let skipped = count(|s| matches!(s, Status::Skipped));
        let failed = count(|s| matches!(s, Status::Failed(_)));
        let interrupted = count(|s| matches!(s, Status::Interrupted));
        let total = self.items.len();
        for (item, outcome) in self.items.iter().zip(outcomes) {
            if let Status::Failed(reason) = &outcome.status {
                eprintln!("{}", escape_controls(&format!("failed: {}: {reason}", item.input.display())));
            }
        }
        if let Some(signal) = signal {
            eprintln!(
                "interrupted by {signal}: {interrupted} of {total} files not baked (their unfinished outputs removed; \
                 a rerun bakes them)"
            );
        }
        let report_result = match &self.report {
            Some(path) => {
                let json = report(self, outcomes, (baked, skipped, failed, interrupted));
                write_report(path, report_out, &json)
                    .map_err(|reason| BatchError::new(format!("cannot write the report: {reason}")))
            }
            None => Ok(()),
        };
        eprintln!(
            "{}",
            escape_controls(&format!(
                "baked {baked}, skipped {skipped}, failed {failed} of {total} files in {:.1} s -> {}",
                self.started.elapsed().as_secs_f64(),
                self.out.display()
            ))
        );
        if skipped > 0 && !self.overwrite {
            eprintln!("(skipped: their outputs exist; --overwrite bakes them again)");
        }
        if let (Err(e), Some(_)) = (&report_result, signal) {
            eprintln!("error: {e}");
        }
        report_result?;
        Ok((failed, total))
    }
}

/// `s` with its control characters (newlines, escape sequences...) written as Rust escapes
/// (`\n`, `\u{1b}`), so that a file name can neither forge a line nor reach the terminal.
fn escape_controls(s: &str) -> String {
    s.chars().map(|c| if c.is_control() { c.escape_debug().to_string() } else { c.to_string() }).collect()
}

/// Where a path's file is, whatever names it: the file itself when it exists, its canonical
/// folder and name when only the folder does.
fn place(path: &Path) -> Option<Place> {
    if let Some(key) = regular_file_key(path) {
        return Some(Place::File(key));
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(Place::New(std::fs::canonicalize(folder).ok()?.join(path.file_name()?)))
}

#[derive(PartialEq, Eq)]
enum Place {
    File(FileKey),
    New(PathBuf),
}

/// Bakes one file, turning an error (or a panic) into its reason.
fn bake_one<B: Baker>(baker: &B, job: &B::Job, item: &Item, output: &Path) -> Status {
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<Baked, String> {
        if let Some(parent) = output.parent() {
            std::fs::create_dir_all(parent).map_err(|e| {
                BatchError::context(format_args!("cannot create the folder {}", parent.display()), &e).0
            })?;
        }
        baker.bake(job, &item.input, output)
    }));
    match result {
        Ok(Ok(baked)) => Status::Baked(Some(baked)),
        Ok(Err(reason)) => Status::Failed(reason),
        Err(_) => Status::Failed("internal error: the bake panicked (please report this)".into()),
    }
}

// ---------------------------------------------------------------------------------------------
// Memory
// ---------------------------------------------------------------------------------------------

/// Admits files, in the order they ask, while the estimates of those being baked fit in the
/// budget together. A file whose estimate alone exceeds it is refused.
struct Gate {
    budget: Option<Budget>,
    state: Mutex<GateState>,
    changed: Condvar,
}

struct GateState {
    in_use: u64,
    queue: VecDeque<u64>,
    next_ticket: u64,
}

/// A file's admission: its bytes are given back when it is dropped.
struct Ticket<'a> {
    gate: &'a Gate,
    bytes: u64,
}

impl Gate {
    fn new(budget: Option<Budget>) -> Self {
        let state = GateState { in_use: 0, queue: VecDeque::new(), next_ticket: 0 };
        Self { budget, state: Mutex::new(state), changed: Condvar::new() }
    }

    /// Waits until `bytes` fit beside the files being baked; refuses them when they exceed the
    /// whole budget.
    fn admit(&self, bytes: u64, what: impl FnOnce() -> String) -> Result<Ticket<'_>, MemoryError> {
        let Some(budget) = self.budget else { return Ok(Ticket { gate: self, bytes: 0 }) };
        if bytes > budget.bytes {
            return Err(MemoryError::TooBig {
                what: what(),
                needed: bytes,
                available: budget.bytes,
                from: budget.source,
                advice: "bake a smaller height map, or raise the budget".to_owned(),
            });
        }
        let mut state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let ticket = state.next_ticket;
        state.next_ticket += 1;
        state.queue.push_back(ticket);
        while state.queue.front() != Some(&ticket) || state.in_use + bytes > budget.bytes {
            state = self.changed.wait(state).unwrap_or_else(PoisonError::into_inner);
        }
        state.queue.pop_front();
        state.in_use += bytes;
        self.changed.notify_all();
        Ok(Ticket { gate: self, bytes })
    }
}

impl Drop for Ticket<'_> {
    fn drop(&mut self) {
        if self.bytes > 0 {
            let mut state = self.gate.state.lock().unwrap_or_else(PoisonError::into_inner);
            state.in_use -= self.bytes;
            self.gate.changed.notify_all();
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Finding the files
// ---------------------------------------------------------------------------------------------

/// Expands the inputs into files, in order, each once; the folder `skip` (the output folder) is
/// not walked.
fn collect(inputs: &[PathBuf], recursive: bool, skip: Option<&Path>) -> Result<Vec<Item>, BatchError> {
    let mut items = Vec::new();
    let list = |folder: &Path| {
        std::fs::read_dir(folder)
            .map_err(|e| BatchError::context(format_args!("cannot list the folder {}", folder.display()), &e))
    };
    for input in inputs {
        if let Some(spec) = input.to_str().and_then(|s| s.strip_prefix("builtin:")) {
            let name = spec.split(':').next().unwrap_or(spec).into();
            items.push(Item { input: input.clone(), rel_dir: PathBuf::new(), name, bytes: None, problem: None });
            continue;
        }
        let walker = Walker { recursive, skip };
        if input.is_dir() {
            walker.walk(list(input)?, input, &mut items);
        } else if is_glob(input) {
            let pattern = input.to_string_lossy();
            let base = glob_base(&pattern);
            let matches = glob::glob(&pattern).map_err(|e| BatchError::context(format_args!("glob {pattern}"), &e))?;
            let mut found = false;
            for m in matches {
                let m = m.map_err(|e| BatchError::context(format_args!("glob {pattern}"), &e))?;
                found = true;
                if m.is_dir() {
                    // As if the folder were given itself: its files go to OUT directly.
                    walker.walk(list(&m)?, &m, &mut items);
                } else {
                    items.push(file_item(&m, &base));
                }
            }
            if !found {
                return Err(BatchError::new(format!("the glob {pattern} matches no file")));
            }
        } else {
            let base = input.parent().unwrap_or(Path::new("")).to_owned();
            items.push(file_item(input, &base));
        }
    }
    // Each file once, the first place it was found winning.
    let mut seen = HashSet::new();
    items.retain(|item| match regular_file_key(&item.input) {
        Some(key) => seen.insert(key),
        None => true,
    });
    Ok(items)
}

/// The longest leading part of a glob without wildcards: outputs mirror what lies below it.
fn glob_base(pattern: &str) -> PathBuf {
    let mut base = PathBuf::new();
    for c in Path::new(pattern).components() {
        if has_glob(&c.as_os_str().to_string_lossy()) {
            break;
        }
        base.push(c);
    }
    base
}

struct Walker<'a> {
    recursive: bool,
    /// The output folder (canonical), never walked.
    skip: Option<&'a Path>,
}

impl Walker<'_> {
    /// The image files of a folder (listed as `listing`) and, `recursive`, of its
    /// subfolders, in name order. A subfolder that cannot be listed fails alone, as an item.
    fn walk(&self, listing: std::fs::ReadDir, base: &Path, items: &mut Vec<Item>) {
        let mut entries: Vec<_> = listing
            .filter_map(std::result::Result::ok)
            .map(|e| e.path())
            .filter(|p| !p.file_name().is_some_and(|n| n.as_encoded_bytes().starts_with(b".")))
            .collect();
        entries.sort();
        for path in entries {
            // Symbolic links to folders are not followed (a link to a parent would never end).
            let is_link = path.symlink_metadata().is_ok_and(|m| m.file_type().is_symlink());
            if self.recursive && path.is_dir() {
                let is_out = self.skip.is_some_and(|out| std::fs::canonicalize(&path).is_ok_and(|p| p == out));
                if !is_link && !is_out {
                    match std::fs::read_dir(&path) {
                        Ok(listing) => self.walk(listing, base, items),
                        Err(e) => {
                            let mut item = file_item(&path, base);
                            item.problem = Some(format!("cannot list the folder: {e}"));
                            items.push(item);
                        }
                    }
                }
                continue;
            }
            if has_image_extension(&path) {
                items.push(file_item(&path, base));
            }
        }
    }
}

fn has_image_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.iter().any(|x| x.eq_ignore_ascii_case(e)))
}

/// A file found under `base`; anything but a regular file (or a link to one) is refused here,
/// before it is ever opened (a FIFO would block the run).
fn file_item(path: &Path, base: &Path) -> Item {
    let rel_dir = path.parent().and_then(|p| p.strip_prefix(base).ok()).map(Path::to_owned).unwrap_or_default();
    let name = path.file_name().map(OsStr::to_owned).unwrap_or_default();
    let (bytes, problem) = match std::fs::metadata(path) {
        Ok(m) if m.is_file() => (Some(m.len()), None),
        Ok(m) if m.is_dir() => (None, Some("it is a folder, not an image (--recursive walks folders)".to_owned())),
        Ok(_) => (None, Some("it is not a regular file (a FIFO, socket or device): not read".to_owned())),
        Err(e) => (None, Some(format!("cannot read it: {e}"))),
    };
    Item { input: path.to_owned(), rel_dir, name, bytes, problem }
}

// ---------------------------------------------------------------------------------------------
// Output names
// ---------------------------------------------------------------------------------------------

/// A checked `--name` template: `{stem}` (the input's name without its extension), `{name}`
/// (its whole name) and `{ext}` (the output's extension).
#[derive(Debug)]
pub struct Template(String);

impl Template {
    /// Checks a template.
    ///
    /// # Errors
    /// [`BatchError`] naming the template: empty, holding a path, with a placeholder not
    /// closed or unknown, or with neither `{stem}` nor `{name}`.
    pub fn parse(s: &str) -> Result<Self, BatchError> {
        let refuse = |why: &str| Err(BatchError::new(format!("--name '{s}': {why}")));
        if s.is_empty() {
            return refuse("the template is empty");
        }
        if s.contains(['/', '\\']) || Path::new(s).components().any(|c| matches!(c, Component::ParentDir)) || s == ".."
        {
            return refuse("a file name template cannot hold a path (no '/', '\\' or '..'): outputs go into -o");
        }
        let mut rest = s;
        while let Some(open) = rest.find('{') {
            let Some(close) = rest[open..].find('}') else { return refuse("a '{' is not closed") };
            let key = &rest[open + 1..open + close];
            if !matches!(key, "stem" | "name" | "ext") {
                return refuse(&format!("unknown placeholder {{{key}}} (use {{stem}}, {{name}} and {{ext}})"));
            }
            rest = &rest[open + close + 1..];
        }
        if !s.contains("{stem}") && !s.contains("{name}") {
            return refuse("it needs {stem} or {name}, or every file would be written to the same output");
        }
        Ok(Self(s.to_owned()))
    }

    /// The output name for the input named `name` (kept as it is, UTF-8 or not).
    pub fn render(&self, name: &OsStr, ext: &str) -> OsString {
        let stem = Path::new(name).file_stem().unwrap_or(name);
        let mut out = OsString::new();
        let mut rest = self.0.as_str();
        while let Some(open) = rest.find('{') {
            out.push(&rest[..open]);
            let close = open + rest[open..].find('}').expect("checked by parse");
            match &rest[open + 1..close] {
                "stem" => out.push(stem),
                "name" => out.push(name),
                _ => out.push(ext),
            }
            rest = &rest[close + 1..];
        }
        out.push(rest);
        out
    }
}

// ---------------------------------------------------------------------------------------------
// The report
// ---------------------------------------------------------------------------------------------

fn report(
    shared: &Shared,
    outcomes: &[Outcome],
    (baked, skipped, failed, interrupted): (usize, usize, usize, usize),
) -> serde_json::Value {
    let files: Vec<serde_json::Value> = shared
        .items
        .iter()
        .zip(outcomes)
        .zip(&shared.outputs)
        .map(|((item, o), output)| {
            let (status, baked, error) = match &o.status {
                Status::Baked(baked) => ("baked", *baked, None),
                Status::Skipped => ("skipped", None, None),
                Status::Failed(reason) => ("failed", None, Some(reason.clone())),
                Status::Interrupted => ("interrupted", None, None),
            };
            // What is on disk for this file after the run: nothing for a failed or interrupted
            // file.
            let outputs: Vec<String> = if matches!(o.status, Status::Baked(_) | Status::Skipped) {
                vec![output.to_string_lossy().into_owned()]
            } else {
                Vec::new()
            };
            let mut entry = serde_json::json!({
                "input": item.input.to_string_lossy(),
                "outputs": outputs,
                "status": status,
                "bytes": item.bytes,
                "width": baked.map(|b| b.width),
                "height": baked.map(|b| b.height),
                "seconds": o.seconds,
                "error": error,
            });
            // `bake height`: the relief the normals imply (null when not baked).
            if shared.relief
                && let Some(map) = entry.as_object_mut()
            {
                let relief = baked.and_then(|b| b.relief);
                map.insert("range_texels".into(), serde_json::json!(relief.map(|r| r.range)));
                map.insert("depth_scale".into(), serde_json::json!(relief.map(|r| r.depth_scale)));
            }
            entry
        })
        .collect();
    serde_json::json!({
        "verb": shared.verb,
        "out": shared.out.to_string_lossy(),
        "baked": baked,
        "skipped": skipped,
        "failed": failed,
        "interrupted": interrupted,
        "files": files,
    })
}

/// An error of writing the report, as its whole message.
struct ReportError(String);

impl From<crate::IoError> for ReportError {
    fn from(e: crate::IoError) -> Self {
        Self(error_chain(&e))
    }
}

/// Writes the report to `path`, through `checked` (its output, checked before baking) or anew;
/// the error is the whole reason.
fn write_report(path: &Path, checked: Option<(Outputs, OutputId)>, json: &serde_json::Value) -> Result<(), String> {
    let written = || -> Result<(), ReportError> {
        let (mut outs, id) = match checked {
            Some(checked) => checked,
            None => {
                let mut outs = Outputs::new();
                let id = outs.output(path);
                outs.check()?;
                (outs, id)
            }
        };
        let text = serde_json::to_string_pretty(json).map_err(|e| ReportError(error_chain(&e)))? + "\n";
        outs.write_with::<ReportError>(id, |f| f.write_all(text.as_bytes()).map_err(|e| ReportError(error_chain(&e))))?;
        outs.commit()?;
        Ok(())
    };
    written().map_err(|e| e.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_render_their_placeholders_and_refuse_paths() {
        let t = Template::parse("{stem}_n.{ext}").unwrap();
        assert_eq!(t.render(OsStr::new("rock.tif"), "png"), OsString::from("rock_n.png"));
        let t = Template::parse("{name}.{ext}").unwrap();
        assert_eq!(t.render(OsStr::new("rock.tif"), "exr"), OsString::from("rock.tif.exr"));
        for (bad, why) in [
            ("", "empty"),
            ("a/{stem}", "cannot hold a path"),
            ("{stem", "not closed"),
            ("{size}{stem}", "unknown placeholder {size}"),
            ("out.{ext}", "needs {stem} or {name}"),
        ] {
            let err = Template::parse(bad).unwrap_err().to_string();
            assert!(err.starts_with(&format!("--name '{bad}': ")) && err.contains(why), "{bad:?}: {err}");
        }
    }

    #[test]
    fn globs_keep_their_leading_folders_as_the_base() {
        assert_eq!(glob_base("lib/rocks/*.png"), PathBuf::from("lib/rocks"));
        assert_eq!(glob_base("lib/*/x.png"), PathBuf::from("lib"));
        assert_eq!(glob_base("*.png"), PathBuf::new());
    }

    #[test]
    fn controls_are_escaped() {
        assert_eq!(escape_controls("a\nb\u{1b}[31m"), "a\\nb\\u{1b}[31m");
    }

    #[test]
    fn error_chains_join_their_sources() {
        let inner = std::io::Error::other("disk full");
        let err = BatchError::context("cannot create the folder out", &inner);
        assert_eq!(err.to_string(), "cannot create the folder out: disk full");
    }
}
