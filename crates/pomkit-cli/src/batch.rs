//! `pomkit bake` over a whole texture library: several inputs, folders and globs, baked in
//! parallel into an output folder, with a summary, a JSON report and per-folder options
//! (README, "Baking a library"; docs/LIMITS.md for how outputs are written).
//!
//! Every file is baked by [`crate::bake::bake_file`], as a single bake is: its output is staged
//! beside its destination and renamed into place only when it is whole, so a file that fails
//! leaves nothing behind, and an interrupted batch leaves only finished outputs, which the next
//! run skips.

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Deserialize;

use pomkit_io::output::regular_file_key;

use crate::ChannelArg;
use crate::bake::{EdgesArg, FilterArg, Job, Kind, NormalEncoding, ParallaxEncoding};

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
    /// '{stem}_normal.{ext}', '{stem}_parallax.{ext}' or '{stem}_packed.{ext}'.
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
    /// Files baked at once (default: the number of cores).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1024))]
    jobs: Option<u32>,
}

/// Whether a `bake` command is a batch: several inputs, a folder, a glob that names no file, or
/// any batch option. Otherwise it is the single bake of one file into one output file.
pub(crate) fn is_batch(inputs: &[String], args: &BatchArgs) -> bool {
    inputs.len() > 1
        || args.recursive
        || args.name.is_some()
        || args.overwrite
        || args.report.is_some()
        || args.config.is_some()
        || args.jobs.is_some()
        || inputs.iter().any(|i| {
            let p = Path::new(i);
            p.is_dir() || (has_glob(i) && !p.exists())
        })
}

fn has_glob(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// One file of the batch, as found.
#[derive(Debug)]
struct Item {
    /// What to load: a path, or `builtin:NAME[:WxH]`.
    input: String,
    /// The folder under OUT its output goes to (its folder relative to the folder or glob base
    /// it was found under).
    rel_dir: PathBuf,
    /// Its file name (for `builtin:` inputs, the pattern name).
    name: String,
    /// Its size in bytes, when it is a readable regular file.
    bytes: Option<u64>,
    /// Why it cannot be baked, found before baking (a folder, a FIFO, ...).
    problem: Option<String>,
}

/// What happened to one file.
#[derive(Debug)]
enum Status {
    Baked { width: u32, height: u32 },
    Skipped,
    Failed(String),
}

struct Outcome {
    output: Option<PathBuf>,
    status: Status,
    seconds: f64,
}

/// Runs a batch: finds the files, checks everything that can be checked before baking, bakes
/// in parallel, then reports.
pub(crate) fn run(job: &Job, inputs: &[String], args: &BatchArgs, out: &Path) -> Result<()> {
    let started = Instant::now();
    let template = Template::parse(args.name.as_deref().unwrap_or(default_template(job.kind)))?;
    let rules = match &args.config {
        Some(path) => Rules::load(path, job.kind)?,
        None => Rules::default(),
    };
    if out.exists() && !out.is_dir() {
        bail!("{} is not a folder: with several inputs, a folder or a glob, -o names the output folder", out.display());
    }
    let items = collect(inputs, args.recursive)?;
    if items.is_empty() {
        bail!("no height maps found in {} (folders contribute their {} files)", inputs.join(", "), extensions());
    }
    // The report is checked now (never over an input, its folder writable) and written last.
    let mut report_out = args
        .report
        .as_ref()
        .map(|path| -> Result<_> {
            let mut outs = pomkit_io::output::Outputs::new();
            for item in &items {
                outs.input(&item.input);
            }
            let id = outs.output(path);
            outs.check().with_context(|| format!("--report {}", path.display()))?;
            Ok((outs, id))
        })
        .transpose()?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create the output folder {}", out.display()))?;

    // Every output path, decided before baking: collisions and outputs over inputs fail their
    // file; existing outputs are skipped unless --overwrite.
    let input_keys: HashMap<pomkit_io::output::FileKey, usize> = items
        .iter()
        .enumerate()
        .filter_map(|(i, item)| regular_file_key(Path::new(&item.input)).map(|k| (k, i)))
        .collect();
    let mut claimed: HashMap<PathBuf, usize> = HashMap::new();
    let mut plans: Vec<(Option<PathBuf>, Option<String>, Job)> = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let job = rules.apply(job, item);
        let output = out.join(&item.rel_dir).join(template.render(&item.name, job.kind.extension()));
        let mut problem = item.problem.clone();
        if problem.is_none() {
            if let Some(&first) = claimed.get(&output) {
                problem = Some(format!("{} is also the output of {}", output.display(), items[first].input));
            } else if let Some(&j) = regular_file_key(&output).as_ref().and_then(|k| input_keys.get(k)) {
                problem = Some(format!(
                    "its output {} is the input {}: refusing to write over it",
                    output.display(),
                    items[j].input
                ));
            } else {
                claimed.insert(output.clone(), i);
            }
        }
        plans.push((Some(output), problem, job));
    }

    let total_bytes: u64 = items.iter().filter_map(|i| i.bytes).sum();
    let bar = batch_bar(total_bytes, items.len());
    let done = AtomicUsize::new(0);
    let bytes_done = AtomicU64::new(0);
    let jobs = args.jobs.map_or_else(rayon::current_num_threads, |n| n as usize);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(jobs).build().context("cannot start the worker threads")?;
    let overwrite = args.overwrite;
    let outcomes: Vec<Outcome> = pool.install(|| {
        items
            .par_iter()
            .zip(plans.par_iter())
            .map(|(item, (output, problem, job))| {
                let t0 = Instant::now();
                let status = match (problem, output) {
                    (Some(p), _) => Status::Failed(p.clone()),
                    (None, Some(output)) if !overwrite && output.exists() => Status::Skipped,
                    (None, Some(output)) => bake_one(job, item, output),
                    (None, None) => Status::Failed("no output".into()),
                };
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                bytes_done.fetch_add(item.bytes.unwrap_or(0), Ordering::Relaxed);
                bar.set_position(bytes_done.load(Ordering::Relaxed));
                bar.set_message(format!("{n}/{} files", items.len()));
                Outcome { output: output.clone(), status, seconds: t0.elapsed().as_secs_f64() }
            })
            .collect()
    });
    bar.finish_and_clear();

    let count = |f: fn(&Status) -> bool| outcomes.iter().filter(|o| f(&o.status)).count();
    let baked = count(|s| matches!(s, Status::Baked { .. }));
    let skipped = count(|s| matches!(s, Status::Skipped));
    let failed = count(|s| matches!(s, Status::Failed(_)));
    for (item, outcome) in items.iter().zip(&outcomes) {
        if let Status::Failed(reason) = &outcome.status {
            eprintln!("failed: {}: {reason}", item.input);
        }
    }
    if let Some((outs, id)) = report_out.take() {
        let json = report(job.kind, out, &items, &outcomes, (baked, skipped, failed));
        write_report(outs, id, &json).with_context(|| "cannot write the report".to_owned())?;
    }
    eprintln!(
        "baked {baked}, skipped {skipped}, failed {failed} of {} files in {:.1} s -> {}",
        items.len(),
        started.elapsed().as_secs_f64(),
        out.display()
    );
    if skipped > 0 && !overwrite {
        eprintln!("(skipped: their outputs exist; --overwrite bakes them again)");
    }
    if failed > 0 {
        bail!("{failed} of {} files failed (listed above)", items.len());
    }
    Ok(())
}

/// Bakes one file, turning an error (or a panic) into its reason.
fn bake_one(job: &Job, item: &Item, output: &Path) -> Status {
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<(u32, u32)> {
        if let Some(parent) = output.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create the folder {}", parent.display()))?;
        }
        crate::bake::bake_file(job, &item.input, output, false)
    }));
    match result {
        Ok(Ok((width, height))) => Status::Baked { width, height },
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
    }
}

// ---------------------------------------------------------------------------------------------
// Finding the files
// ---------------------------------------------------------------------------------------------

/// Expands the inputs into files, in order, each once.
fn collect(inputs: &[String], recursive: bool) -> Result<Vec<Item>> {
    let mut items = Vec::new();
    for input in inputs {
        if let Some(spec) = input.strip_prefix("builtin:") {
            let name = spec.split(':').next().unwrap_or(spec).to_owned();
            items.push(Item { input: input.clone(), rel_dir: PathBuf::new(), name, bytes: None, problem: None });
            continue;
        }
        let path = Path::new(input);
        if path.is_dir() {
            walk(path, path, recursive, &mut items)?;
        } else if has_glob(input) && !path.exists() {
            let base = glob_base(input);
            let matches = glob::glob(input).with_context(|| format!("glob {input}"))?;
            let mut found = false;
            for m in matches {
                let m = m.with_context(|| format!("glob {input}"))?;
                found = true;
                if m.is_dir() {
                    // As if the folder were given itself: its files go to OUT directly.
                    walk(&m, &m, recursive, &mut items)?;
                } else {
                    items.push(file_item(&m, &base));
                }
            }
            if !found {
                bail!("the glob {input} matches no file");
            }
        } else {
            let base = path.parent().unwrap_or(Path::new("")).to_owned();
            items.push(file_item(path, &base));
        }
    }
    // Each file once, the first place it was found winning.
    let mut seen = std::collections::HashSet::new();
    items.retain(|item| match regular_file_key(Path::new(&item.input)) {
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

/// The folder `dir`'s image files (and, `recursive`, its subfolders'), in name order.
fn walk(dir: &Path, base: &Path, recursive: bool, items: &mut Vec<Item>) -> Result<()> {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list the folder {}", dir.display()))?
        .filter_map(std::result::Result::ok)
        .map(|e| e.path())
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.')))
        .collect();
    entries.sort();
    for path in entries {
        // Symbolic links to folders are not followed (a link to a parent would never end).
        let is_link = path.symlink_metadata().is_ok_and(|m| m.file_type().is_symlink());
        if recursive && path.is_dir() {
            if !is_link {
                walk(&path, base, recursive, items)?;
            }
            continue;
        }
        if has_image_extension(&path) {
            items.push(file_item(&path, base));
        }
    }
    Ok(())
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
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let (bytes, problem) = match std::fs::metadata(path) {
        Ok(m) if m.is_file() => (Some(m.len()), None),
        Ok(m) if m.is_dir() => (None, Some("it is a folder, not an image (--recursive walks folders)".to_owned())),
        Ok(_) => (None, Some("it is not a regular file (a FIFO, socket or device): not read".to_owned())),
        Err(e) => (None, Some(format!("cannot read it: {e}"))),
    };
    Item { input: path.to_string_lossy().into_owned(), rel_dir, name, bytes, problem }
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

    fn render(&self, name: &str, ext: &str) -> String {
        let stem = Path::new(name).file_stem().map_or_else(|| name.to_owned(), |s| s.to_string_lossy().into_owned());
        self.0.replace("{stem}", &stem).replace("{name}", name).replace("{ext}", ext)
    }
}

// ---------------------------------------------------------------------------------------------
// Per-folder and per-pattern options
// ---------------------------------------------------------------------------------------------

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RuleFile {
    #[serde(rename = "match")]
    pattern: Option<String>,
    folder: Option<String>,
    scale: Option<f32>,
    filter: Option<String>,
    edges: Option<String>,
    y_down: Option<bool>,
    depth_map: Option<bool>,
    channel: Option<String>,
    normalize: Option<bool>,
    encoding: Option<String>,
}

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
    kind: Option<Kind>,
}

/// The rules of a `--config` file, in order.
#[derive(Default)]
struct Rules(Vec<Rule>);

impl Rules {
    fn load(path: &Path, kind: Kind) -> Result<Self> {
        let bytes = pomkit_io::read::read_capped(path, pomkit_io::read::MAX_SCENE_BYTES, "a config file")
            .with_context(|| format!("cannot read the config {}", path.display()))?;
        let text = String::from_utf8(bytes).with_context(|| format!("config {}: not UTF-8 text", path.display()))?;
        let table: toml::Table = toml::from_str(&text).with_context(|| format!("config {}", path.display()))?;
        if let Some(key) = table.keys().find(|k| k.as_str() != "rule") {
            bail!("config {}: unknown key `{key}` (a config holds [[rule]] tables only)", path.display());
        }
        let raw_rules = match table.get("rule") {
            None => Vec::new(),
            Some(toml::Value::Array(rules)) => rules.clone(),
            Some(_) => bail!("config {}: `rule` must be written as [[rule]] tables", path.display()),
        };
        let mut rules = Vec::new();
        for (i, raw) in raw_rules.into_iter().enumerate() {
            let at = |key: &str| format!("config {}, [[rule]] {}, {key}", path.display(), i + 1);
            let r: RuleFile =
                raw.try_into().with_context(|| format!("config {}, [[rule]] {}", path.display(), i + 1))?;
            let filter = choice::<FilterArg>(r.filter.as_deref(), || at("filter"))?;
            let edges = choice::<EdgesArg>(r.edges.as_deref(), || at("edges"))?;
            let channel = choice::<ChannelArg>(r.channel.as_deref(), || at("channel"))?;
            let rule_kind = match kind {
                Kind::Pack | Kind::Maxmip | Kind::Cone { .. } => None,
                Kind::Normal(_) => {
                    choice::<NormalEncoding>(r.encoding.as_deref(), || at("encoding"))?.map(Kind::Normal)
                }
                Kind::Parallax(_) => {
                    choice::<ParallaxEncoding>(r.encoding.as_deref(), || at("encoding"))?.map(Kind::Parallax)
                }
            };
            if let Some(scale) = r.scale
                && !(scale.is_finite() && scale.abs() <= pomkit_core::bake::MAX_SCALE)
            {
                bail!(
                    "{}: {scale} is not a finite number of texel widths from -{max:e} to {max:e}",
                    at("scale"),
                    max = pomkit_core::bake::MAX_SCALE
                );
            }
            let pattern = r.pattern.as_deref().map(glob::Pattern::new).transpose().with_context(|| at("match"))?;
            let folder = r.folder.as_deref().map(|f| PathBuf::from(f.trim_matches('/')));
            rules.push(Rule {
                pattern,
                folder,
                scale: r.scale,
                filter,
                edges,
                y_down: r.y_down,
                depth_map: r.depth_map,
                channel,
                normalize: r.normalize,
                kind: rule_kind,
            });
        }
        Ok(Self(rules))
    }

    /// `job` with every rule that matches `item` applied, in order.
    fn apply(&self, job: &Job, item: &Item) -> Job {
        let mut job = job.clone();
        for rule in &self.0 {
            let name_ok = rule.pattern.as_ref().is_none_or(|p| p.matches(&item.name));
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
            if let Some(v) = rule.kind {
                job.kind = v;
            }
        }
        job
    }
}

/// A config value that names one of `T`'s values (any case); `what` names the key in the error.
fn choice<T: ValueEnum>(value: Option<&str>, what: impl Fn() -> String) -> Result<Option<T>> {
    let Some(s) = value else { return Ok(None) };
    T::from_str(s, true).map(Some).map_err(|_| {
        let names: Vec<String> = T::value_variants()
            .iter()
            .filter_map(ValueEnum::to_possible_value)
            .map(|p| p.get_name().to_owned())
            .collect();
        anyhow::anyhow!("{}: '{s}' is not one of {}", what(), names.join(", "))
    })
}

// ---------------------------------------------------------------------------------------------
// The report
// ---------------------------------------------------------------------------------------------

fn report(
    kind: Kind,
    out: &Path,
    items: &[Item],
    outcomes: &[Outcome],
    (baked, skipped, failed): (usize, usize, usize),
) -> serde_json::Value {
    let files: Vec<serde_json::Value> = items
        .iter()
        .zip(outcomes)
        .map(|(item, o)| {
            let (status, size, error) = match &o.status {
                Status::Baked { width, height } => ("baked", Some((*width, *height)), None),
                Status::Skipped => ("skipped", None, None),
                Status::Failed(reason) => ("failed", None, Some(reason.clone())),
            };
            serde_json::json!({
                "input": item.input,
                // What is on disk for this file after the run: nothing for a failed file.
                "outputs": o
                    .output
                    .iter()
                    .filter(|_| !matches!(o.status, Status::Failed(_)))
                    .map(|p| p.to_string_lossy().into_owned())
                    .collect::<Vec<_>>(),
                "status": status,
                "bytes": item.bytes,
                "width": size.map(|s| s.0),
                "height": size.map(|s| s.1),
                "seconds": o.seconds,
                "error": error,
            })
        })
        .collect();
    serde_json::json!({
        "verb": kind.verb(),
        "out": out.to_string_lossy(),
        "baked": baked,
        "skipped": skipped,
        "failed": failed,
        "files": files,
    })
}

fn write_report(
    mut outs: pomkit_io::output::Outputs,
    id: pomkit_io::output::OutputId,
    json: &serde_json::Value,
) -> Result<()> {
    let text = serde_json::to_string_pretty(json)? + "\n";
    outs.write_with::<anyhow::Error>(id, |f| Ok(f.write_all(text.as_bytes())?))?;
    outs.commit()?;
    Ok(())
}
