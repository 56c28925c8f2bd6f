//! `pomkit bake` over a whole texture library: several inputs, folders and globs, baked in
//! parallel into an output folder, with a summary, a JSON report and per-folder options
//! (README, "Baking a library"; docs/LIMITS.md for how outputs are written).
//!
//! Every file is baked by [`crate::bake::bake_file`], as a single bake is: its output is staged
//! beside its destination and renamed into place only when it is whole, so a file that fails
//! leaves nothing behind, and an interrupted batch leaves only finished outputs, which the next
//! run skips. Files are admitted by their memory estimate: the files being baked at once fit
//! in the memory budget together ([`pomkit_core::memory`]).

use std::collections::{HashMap, HashSet, VecDeque};
use std::ffi::{OsStr, OsString};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use pomkit_core::cone::ConeMap;
use pomkit_core::memory::{Budget, MemoryError};

use pomkit_io::output::{FileKey, Outputs, regular_file_key};

use crate::ChannelArg;
use crate::bake::{Baked, EdgesArg, FilterArg, Job, Kind, NormalEncoding, ParallaxEncoding};
use crate::bake_height::HeightReadEncoding;

/// Extensions of the files a folder input contributes (compared without case).
pub(crate) const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "tif", "tiff", "exr"];

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
    config: Option<PathBuf>,
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
    inputs.len() > 1 || !args.given().is_empty() || inputs.iter().any(|p| p.is_dir() || is_glob(p))
}

/// A glob that names no file as it is.
fn is_glob(path: &Path) -> bool {
    has_glob(&path.to_string_lossy()) && !path.exists()
}

fn has_glob(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// `builtin:NAME[:WxH]` inputs.
fn is_builtin(path: &Path) -> bool {
    path.to_str().is_some_and(|s| s.starts_with("builtin:"))
}

/// One file of the batch, as found.
#[derive(Debug)]
struct Item {
    /// What to load: a path, or `builtin:NAME[:WxH]`.
    input: PathBuf,
    /// The folder under OUT its output goes to (its folder relative to the folder or glob base
    /// it was found under).
    rel_dir: PathBuf,
    /// Its file name (for `builtin:` inputs, the pattern name).
    name: OsString,
    /// Its size in bytes, when it is a readable regular file.
    bytes: Option<u64>,
    /// Why it cannot be baked, found before baking (a folder, a FIFO, ...).
    problem: Option<String>,
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
enum Progress {
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
    kind: Kind,
    out: PathBuf,
    items: Vec<Item>,
    /// Each file's output.
    outputs: Vec<PathBuf>,
    progress: Mutex<Vec<Progress>>,
    report: Option<PathBuf>,
    overwrite: bool,
    started: Instant,
}

/// Runs a batch: finds the files, checks everything that can be checked before baking, bakes
/// in parallel, then reports.
pub(crate) fn run(job: &Job, inputs: &[PathBuf], args: &BatchArgs, out: &Path) -> Result<()> {
    let started = Instant::now();
    let template = Template::parse(args.name.as_deref().unwrap_or(default_template(job.kind)))?;
    let rules = match &args.config {
        Some(path) => Rules::load(path)?,
        None => Rules::default(),
    };
    if out.exists() && !out.is_dir() {
        bail!("{} is not a folder: with several inputs, a folder or a glob, -o names the output folder", out.display());
    }
    if !out.exists() && has_image_extension(out) {
        let why = if inputs.len() > 1 {
            "several inputs make this a batch".to_owned()
        } else if inputs.iter().any(|p| p.is_dir() || is_glob(p)) {
            "a folder or glob input makes this a batch".to_owned()
        } else {
            format!("{} makes this a batch", args.given().join(" and "))
        };
        bail!(
            "-o {}: a batch writes its outputs into a folder, and this looks like an image file name ({why}); \
             for a single bake into {}, give one input without --recursive, --name, --overwrite, --report, \
             --config or --jobs",
            out.display(),
            out.display()
        );
    }
    // The output folder, when it lies inside a folder input, is not walked.
    let out_canonical = std::fs::canonicalize(out).ok();
    let mut items = collect(inputs, args.recursive, out_canonical.as_deref())?;

    // Every output path, decided before baking.
    let plan = |items: &[Item]| -> Vec<(PathBuf, Job)> {
        items
            .iter()
            .map(|item| {
                let job = rules.apply(job, item);
                let output = out.join(&item.rel_dir).join(template.render(&item.name, job.kind.extension()));
                (output, job)
            })
            .collect()
    };
    // A file that is the output of another file of this batch (a folder baked into itself, an
    // earlier run's outputs) is not an input.
    let plans = plan(&items);
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
    if items.is_empty() {
        let names: Vec<String> = inputs.iter().map(|p| p.display().to_string()).collect();
        bail!("no height maps found in {} (folders contribute their {} files)", names.join(", "), extensions());
    }
    let plans = plan(&items);

    // Collisions and outputs over inputs (or the config) fail their file; existing outputs are
    // skipped unless --overwrite.
    let mut input_keys: HashMap<FileKey, String> = items
        .iter()
        .filter_map(|item| regular_file_key(&item.input).map(|k| (k, item.input.display().to_string())))
        .collect();
    if let Some(config) = &args.config
        && let Some(k) = regular_file_key(config)
    {
        input_keys.insert(k, format!("--config {}", config.display()));
    }
    let mut claimed: HashMap<PathBuf, usize> = HashMap::new();
    let mut problems: Vec<Option<String>> = Vec::with_capacity(items.len());
    for (i, (item, (output, _))) in items.iter().zip(&plans).enumerate() {
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

    // The report is checked now (never over an input, the config or an output) and written last.
    let report_out = args
        .report
        .as_ref()
        .map(|path| -> Result<_> {
            let context = || format!("--report {}", path.display());
            if let Some(report_place) = place(path)
                && let Some((output, _)) = plans.iter().find(|(o, _)| place(o).as_ref() == Some(&report_place))
            {
                bail!("{}: it is the output {} of this batch; choose another file", context(), output.display());
            }
            let mut outs = Outputs::new();
            for item in &items {
                outs.input(&item.input);
            }
            if let Some(config) = &args.config {
                outs.input(config);
            }
            let id = outs.output(path);
            outs.check().with_context(context)?;
            Ok((outs, id))
        })
        .transpose()?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create the output folder {}", out.display()))?;
    if own_count > 0 {
        eprintln!(
            "{}",
            escape_controls(&format!(
                "note: {own_count} files found are outputs of this batch (its own, or an earlier run's) and are not \
                 read as inputs"
            ))
        );
    }

    let budget = pomkit_core::memory::available_bytes()?;
    let (outputs, jobs_per_file): (Vec<PathBuf>, Vec<Job>) = plans.into_iter().unzip();
    let total_bytes: u64 = items.iter().filter_map(|i| i.bytes).sum();
    let n = items.len();
    let shared = Arc::new(Shared {
        kind: job.kind,
        out: out.to_owned(),
        items,
        outputs,
        progress: Mutex::new(vec![Progress::Waiting; n]),
        report: args.report.clone(),
        overwrite: args.overwrite,
        started,
    });
    let hook = {
        let shared = Arc::clone(&shared);
        crate::interrupt::on_interrupt(move |signal| {
            let outcomes = shared.outcomes_when_interrupted();
            // The report is written anew: its staged file was removed with the others.
            let _ = shared.finish(&outcomes, Some(signal), None);
        })
    };

    let bar = batch_bar(total_bytes, n);
    let done = AtomicUsize::new(0);
    let next = AtomicUsize::new(0);
    let bytes_done = AtomicU64::new(0);
    let gate = Gate::new(budget);
    let jobs = args.jobs.map_or_else(rayon::current_num_threads, |j| j as usize).clamp(1, n);
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
                        match gate.admit(estimate(job, item), || describe(item)) {
                            Err(e) => Status::Failed(format!("{e:#}")),
                            Ok(ticket) => {
                                shared.set(i, Progress::Running { since: t0, before: regular_file_key(output) });
                                let status = bake_one(job, item, output);
                                drop(ticket);
                                status
                            }
                        }
                    };
                    shared.set(i, Progress::Done(Outcome { status, seconds: t0.elapsed().as_secs_f64() }));
                    let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                    bytes_done.fetch_add(item.bytes.unwrap_or(0), Ordering::Relaxed);
                    bar.set_position(bytes_done.load(Ordering::Relaxed));
                    bar.set_message(format!("{k}/{n} files"));
                }
            });
        }
    });
    bar.finish_and_clear();
    drop(hook);
    let outcomes = shared.outcomes_when_interrupted();
    let (failed, total) = shared.finish(&outcomes, None, report_out)?;
    if failed > 0 {
        bail!("{failed} of {total} files failed (listed above)");
    }
    Ok(())
}

impl Shared {
    fn set(&self, i: usize, p: Progress) {
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
                Progress::Done(o) => o,
                Progress::Waiting => Outcome { status: Status::Interrupted, seconds: 0.0 },
                Progress::Running { since, before } => {
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
        report_out: Option<(Outputs, pomkit_io::output::OutputId)>,
    ) -> Result<(usize, usize)> {
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
                write_report(path, report_out, &json).context("cannot write the report")
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
            eprintln!("error: {e:#}");
        }
        report_result?;
        Ok((failed, total))
    }
}

/// `s` with its control characters (newlines, escape sequences...) written as Rust escapes
/// (`\n`, `\u{1b}`), so that a file name can neither forge a line nor reach the terminal.
pub(crate) fn escape_controls(s: &str) -> String {
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
fn bake_one(job: &Job, item: &Item, output: &Path) -> Status {
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<Baked> {
        if let Some(parent) = output.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create the folder {}", parent.display()))?;
        }
        crate::bake::bake_file(job, &item.input, output, false)
    }));
    match result {
        Ok(Ok(baked)) => Status::Baked(Some(baked)),
        Ok(Err(e)) => Status::Failed(format!("{e:#}")),
        Err(_) => Status::Failed("internal error: the bake panicked (please report this)".into()),
    }
}

fn batch_bar(total_bytes: u64, files: usize) -> ProgressBar {
    let pb = ProgressBar::new(total_bytes);
    pb.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {bytes}/{total_bytes}, {eta} left")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(format!("0/{files} files"));
    pb
}

fn extensions() -> String {
    IMAGE_EXTENSIONS.join(", ")
}

fn default_template(kind: Kind) -> &'static str {
    match kind {
        Kind::Normal(_) => "{stem}_normal.{ext}",
        Kind::Parallax(_) => "{stem}_parallax.{ext}",
        Kind::Pack => "{stem}_packed.{ext}",
        Kind::Maxmip => "{stem}_maxmip.{ext}",
        Kind::Cone { .. } => "{stem}_cone.{ext}",
        Kind::Height { .. } => "{stem}_height.{ext}",
    }
}

// ---------------------------------------------------------------------------------------------
// Memory
// ---------------------------------------------------------------------------------------------

/// The width and height of an item's height map: a built-in's size, or an image file's header;
/// `None` when it cannot be told before reading.
fn dimensions(item: &Item) -> Option<(u32, u32, u64)> {
    if is_builtin(&item.input) {
        let spec = item.input.to_str()?.strip_prefix("builtin:")?;
        let size = spec.split_once(':').map_or("512x512", |(_, s)| s);
        let (w, h) = crate::parse_size(size).ok()?;
        return Some((w, h, 0));
    }
    pomkit_io::read::image_header(&item.input)
}

/// An upper bound of the bytes baking `item` as `kind` holds at its peak: the decoded image,
/// the height field and its floats (8 bytes a texel, as reading a height map counts them), and
/// what the map itself needs (`ConeMap::build_bytes` for cones; 12 bytes a texel for the
/// maximum-height pyramid and its atlas, as `bake maxmip` checks; the texels and the encoder's
/// copy of them for the others). A file whose size cannot be told from its header counts as
/// its length.
fn estimate(job: &Job, item: &Item) -> u64 {
    let Some((w, h, decoded)) = dimensions(item) else { return item.bytes.unwrap_or(0) };
    let kind = job.kind;
    let texels = u64::from(w) * u64::from(h);
    let map = match kind {
        Kind::Cone { .. } => ConeMap::build_bytes(w, h),
        Kind::Maxmip => texels * 12,
        Kind::Normal(NormalEncoding::Float) => texels * 24,
        Kind::Normal(_) | Kind::Parallax(ParallaxEncoding::R8) => texels * 6,
        Kind::Parallax(ParallaxEncoding::Float) => texels * 8,
        // The normals, then the RGBA texels and the encoder's copy.
        Kind::Pack => texels * 20,
        // The normals, the solve and the output (no height field: less its 8 bytes a texel).
        Kind::Height { .. } => {
            crate::bake_height::bytes(&crate::bake_height::options(job), w, h).saturating_sub(texels * 8)
        }
    };
    decoded.saturating_add(texels * 8).saturating_add(map)
}

fn describe(item: &Item) -> String {
    match dimensions(item) {
        Some((w, h, _)) => format!("baking {} ({w}x{h})", item.input.display()),
        None => format!("baking {}", item.input.display()),
    }
}

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
fn collect(inputs: &[PathBuf], recursive: bool, skip: Option<&Path>) -> Result<Vec<Item>> {
    let mut items = Vec::new();
    for input in inputs {
        if let Some(spec) = input.to_str().and_then(|s| s.strip_prefix("builtin:")) {
            let name = spec.split(':').next().unwrap_or(spec).into();
            items.push(Item { input: input.clone(), rel_dir: PathBuf::new(), name, bytes: None, problem: None });
            continue;
        }
        let walker = Walker { recursive, skip };
        if input.is_dir() {
            let listing =
                std::fs::read_dir(input).with_context(|| format!("cannot list the folder {}", input.display()));
            walker.walk(listing?, input, &mut items);
        } else if is_glob(input) {
            let pattern = input.to_string_lossy();
            let base = glob_base(&pattern);
            let matches = glob::glob(&pattern).with_context(|| format!("glob {pattern}"))?;
            let mut found = false;
            for m in matches {
                let m = m.with_context(|| format!("glob {pattern}"))?;
                found = true;
                if m.is_dir() {
                    // As if the folder were given itself: its files go to OUT directly.
                    let listing =
                        std::fs::read_dir(&m).with_context(|| format!("cannot list the folder {}", m.display()));
                    walker.walk(listing?, &m, &mut items);
                } else {
                    items.push(file_item(&m, &base));
                }
            }
            if !found {
                bail!("the glob {pattern} matches no file");
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

/// A checked `--name` template.
struct Template(String);

impl Template {
    fn parse(s: &str) -> Result<Self> {
        let refuse = |why: &str| bail!("--name '{s}': {why}");
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
    fn render(&self, name: &OsStr, ext: &str) -> OsString {
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
// Per-folder and per-pattern options
// ---------------------------------------------------------------------------------------------

/// One checked rule.
struct Rule {
    pattern: Option<glob::Pattern>,
    folder: Option<PathBuf>,
    scale: Option<f32>,
    filter: Option<FilterArg>,
    edges: Option<EdgesArg>,
    y_down: Option<bool>,
    depth_map: Option<bool>,
    channel: Option<ChannelArg>,
    normalize: Option<bool>,
    /// An encoding of `bake normal` or `bake parallax` (the verbs that have one), applied to the
    /// verb whose encoding it is.
    encoding: Option<String>,
}

/// The rules of a `--config` file, in order.
#[derive(Default)]
struct Rules(Vec<Rule>);

impl Rules {
    fn load(path: &Path) -> Result<Self> {
        let raw_rules = pomkit_io::batch_config::load_config(path)?;
        let mut rules = Vec::with_capacity(raw_rules.len());
        for (i, r) in raw_rules.into_iter().enumerate() {
            let at = |key: &str| format!("config {}, [[rule]] {}, {key}", path.display(), i + 1);
            let filter = choice::<FilterArg>(r.filter.as_deref(), || at("filter"))?;
            let edges = choice::<EdgesArg>(r.edges.as_deref(), || at("edges"))?;
            let channel = choice::<ChannelArg>(r.channel.as_deref(), || at("channel"))?;
            // One config serves every verb: an encoding of any verb is accepted, and applied
            // where it belongs.
            let encoding = match r.encoding {
                Some(e)
                    if NormalEncoding::from_str(&e, true).is_err() && ParallaxEncoding::from_str(&e, true).is_err() =>
                {
                    let mut known = names::<NormalEncoding>();
                    known.extend(names::<ParallaxEncoding>().into_iter().filter(|n| n != "float"));
                    bail!(
                        "{}: '{e}' is not one of {} (the encodings of bake normal and bake parallax)",
                        at("encoding"),
                        known.join(", ")
                    );
                }
                e => e,
            };
            rules.push(Rule {
                pattern: r.pattern,
                folder: r.folder,
                scale: r.scale,
                filter,
                edges,
                y_down: r.y_down,
                depth_map: r.depth_map,
                channel,
                normalize: r.normalize,
                encoding,
            });
        }
        Ok(Self(rules))
    }

    /// `job` with every rule that matches `item` applied, in order.
    fn apply(&self, job: &Job, item: &Item) -> Job {
        let mut job = job.clone();
        for rule in &self.0 {
            let name_ok = rule.pattern.as_ref().is_none_or(|p| p.matches(&item.name.to_string_lossy()));
            let folder_ok = rule.folder.as_ref().is_none_or(|f| item.rel_dir.starts_with(f));
            if !(name_ok && folder_ok) {
                continue;
            }
            if let Some(v) = rule.scale {
                job.slope.scale = v;
            }
            if let Some(v) = rule.filter {
                job.slope.filter = v;
            }
            if let Some(v) = rule.edges {
                job.slope.edges = v;
            }
            if let Some(v) = rule.y_down
                && !matches!(job.kind, Kind::Parallax(_))
            {
                job.y_down = v;
            }
            if let Some(v) = rule.depth_map {
                job.read.depth_map = v;
            }
            if let Some(v) = rule.channel {
                job.read.channel = v;
            }
            if let Some(v) = rule.normalize {
                job.read.normalize = v;
            }
            if let Some(e) = &rule.encoding {
                match job.kind {
                    Kind::Normal(_) => {
                        if let Ok(v) = NormalEncoding::from_str(e, true) {
                            job.kind = Kind::Normal(v);
                        }
                    }
                    Kind::Parallax(_) => {
                        if let Ok(v) = ParallaxEncoding::from_str(e, true) {
                            job.kind = Kind::Parallax(v);
                        }
                    }
                    Kind::Height { method, iterations, .. } => {
                        if let Ok(v) = HeightReadEncoding::from_str(e, true) {
                            job.kind = Kind::Height { encoding: v, method, iterations };
                        }
                    }
                    Kind::Pack | Kind::Maxmip | Kind::Cone { .. } => {}
                }
            }
        }
        job
    }
}

/// The names of `T`'s values.
fn names<T: ValueEnum>() -> Vec<String> {
    T::value_variants().iter().filter_map(ValueEnum::to_possible_value).map(|p| p.get_name().to_owned()).collect()
}

/// A config value that names one of `T`'s values (any case); `what` names the key in the error.
fn choice<T: ValueEnum>(value: Option<&str>, what: impl Fn() -> String) -> Result<Option<T>> {
    let Some(s) = value else { return Ok(None) };
    T::from_str(s, true)
        .map(Some)
        .map_err(|_| anyhow::anyhow!("{}: '{s}' is not one of {}", what(), names::<T>().join(", ")))
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
            if let (Kind::Height { .. }, Some(map)) = (shared.kind, entry.as_object_mut()) {
                let relief = baked.and_then(|b| b.relief);
                map.insert("range_texels".into(), serde_json::json!(relief.map(|r| r.range)));
                map.insert("depth_scale".into(), serde_json::json!(relief.map(|r| r.depth_scale)));
            }
            entry
        })
        .collect();
    serde_json::json!({
        "verb": shared.kind.verb(),
        "out": shared.out.to_string_lossy(),
        "baked": baked,
        "skipped": skipped,
        "failed": failed,
        "interrupted": interrupted,
        "files": files,
    })
}

/// Writes the report to `path`, through `checked` (its output, checked before baking) or anew.
fn write_report(
    path: &Path,
    checked: Option<(Outputs, pomkit_io::output::OutputId)>,
    json: &serde_json::Value,
) -> Result<()> {
    let (mut outs, id) = match checked {
        Some(checked) => checked,
        None => {
            let mut outs = Outputs::new();
            let id = outs.output(path);
            outs.check()?;
            (outs, id)
        }
    };
    let text = serde_json::to_string_pretty(json)? + "\n";
    outs.write_with::<anyhow::Error>(id, |f| Ok(f.write_all(text.as_bytes())?))?;
    outs.commit()?;
    Ok(())
}
