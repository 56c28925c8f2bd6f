//! `pomkit bench`: whole frames of the built-in demo scene on the CPU renderer, timed per
//! technique (DESIGN section 8: medians measured in one run, with the fetches that explain them).

use std::io::Write;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};

use crate::{output, progress, technique};

/// The CSV header of the table.
pub const CSV_HEADER: &str = "technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel";

#[derive(Args, Debug)]
#[command(after_long_help = "\
What is measured: the built-in demo scene (bricks, pyramids, cobblestones and raised text on a \
plane, a cube, a sphere and a quad, every material with its soft self-shadows) rendered on the CPU \
renderer with each listed technique in place of the materials' own. Each technique gets one \
untimed warm-up frame, rendered with the AOVs on, which also gives the mean height fetches per \
covered pixel (view trace plus shadow trace; covered = a pixel whose uv AOV is not zero). Then \
--runs frames are timed with std::time::Instant around the whole render call: preparing the \
materials (tracing pyramids, baked normal maps, albedo mips), the vertex stage and triangle setup, \
shading on all cores (rayon), and the resolve. Generating the scene's textures is not timed. \
median_ms is the median of those frames, mpix_per_s is width * height / median.

With --displaced, the ground truth is added: the height-mapped meshes tessellated to one triangle \
edge per texel and displaced for real, shaded with normal mapping and the materials' shadows. It \
is timed once, with no warm-up (it takes minutes at 1280x720): the whole render call, \
tessellation included, with the AOVs on (its fetches are the shadow trace's only). Standard error \
also shows, per frame, the time until the first tile was shaded (setup: materials, tessellation, \
vertex stage, triangle setup).

Formats: md, a Markdown table for people (rounded); csv, with the header \
`technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel` and full precision. The \
table goes to standard output, progress to standard error.")]
pub struct BenchArgs {
    /// Image size.
    #[arg(long, default_value = "1280x720", value_name = "WxH")]
    size: String,
    /// Timed frames per technique, after one untimed warm-up frame (1 to 1000).
    #[arg(long, default_value_t = 5, value_name = "N")]
    runs: u32,
    /// Techniques to time, comma-separated: `all` or any of flat, normal, parallax, iterative,
    /// steep, pom-classic, pom, relief, exact, and `material` for each material's own technique.
    #[arg(long, default_value = "pom", value_name = "T,..")]
    techniques: String,
    /// Also time the `displaced` ground truth, once (slow: minutes at 1280x720).
    #[arg(long)]
    displaced: bool,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Md)]
    format: Format,
}

/// Output formats of the table.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A Markdown table for people.
    Md,
    /// CSV, full precision.
    Csv,
}

/// Most timed frames per technique accepted.
const MAX_RUNS: u32 = 1000;

/// One row of the table.
struct Row {
    name: String,
    runs: u32,
    median_ms: f64,
    mpix_per_s: f64,
    /// `None` when no pixel was covered.
    fetches_per_pixel: Option<f64>,
}

/// Parses `--techniques`: `all`, technique names and `material`; duplicates dropped, order kept.
fn parse_techniques(s: &str) -> Result<Vec<(String, Mode)>> {
    if s.trim().eq_ignore_ascii_case("all") {
        return Ok(Technique::ALL.iter().map(|t| (t.name().to_owned(), Mode::Technique(*t))).collect());
    }
    let names = technique::names();
    let mut list: Vec<(String, Mode)> = Vec::new();
    for part in s.split(',') {
        let t = part.trim();
        let mode = if t.is_empty() {
            bail!("--techniques '{s}': empty name in the list; expected 'all' or names from: {}, material", names);
        } else if t.eq_ignore_ascii_case("material") {
            Mode::Material
        } else if t.eq_ignore_ascii_case("displaced") {
            bail!("--techniques '{s}': the displaced ground truth is timed once with --displaced, not in the list");
        } else {
            Mode::Technique(t.parse().map_err(|e| anyhow::anyhow!("--techniques: {e}, material"))?)
        };
        if !list.iter().any(|(_, m)| *m == mode) {
            list.push((t.to_ascii_lowercase(), mode));
        }
    }
    Ok(list)
}

pub fn run(a: &BenchArgs) -> Result<()> {
    let (w, h) = crate::parse_size(&a.size).context("--size")?;
    if !(1..=MAX_RUNS).contains(&a.runs) {
        bail!("--runs {}: give between 1 and {MAX_RUNS} timed frames per technique", a.runs);
    }
    let modes = parse_techniques(&a.techniques)?;
    eprintln!("generating the demo scene (not timed)");
    let scene = pomkit_core::demo::demo_scene();
    let base = RenderOptions { width: w, height: h, ..Default::default() };
    let mut rows = Vec::new();
    for (name, mode) in &modes {
        let opts = RenderOptions { mode: *mode, ..base };
        let warm = frame(&scene, &RenderOptions { aovs: true, ..opts }, &format!("{name}: warm-up with AOVs"))?;
        let fetches = fetches_per_covered_pixel(&warm.out);
        let mut times = Vec::new();
        let mut setups = Vec::new();
        for i in 0..a.runs {
            let f = frame(&scene, &opts, &format!("{name}: run {}/{}", i + 1, a.runs))?;
            times.push(f.time);
            setups.push(f.setup);
        }
        let med = median(&mut times);
        eprintln!(
            "{name}: median {:.1} ms, of which setup (until the first tile) {:.1} ms",
            ms(med),
            ms(median(&mut setups))
        );
        rows.push(row(name, a.runs, med, w, h, fetches));
    }
    if a.displaced {
        let opts = RenderOptions { mode: Mode::Displaced, aovs: true, ..base };
        let f = frame(&scene, &opts, "displaced: one run (tessellation included, no warm-up)")?;
        rows.push(row("displaced", 1, f.time, w, h, fetches_per_covered_pixel(&f.out)));
    }
    let caption = format!(
        "CPU renderer, demo scene at {w}x{h}: median of {} timed frame(s) per technique after one warm-up{}.",
        a.runs,
        if a.displaced { "; displaced: one frame, no warm-up, tessellation included" } else { "" }
    );
    output::write_text(Path::new("-"), |wr| match a.format {
        Format::Md => write_md(wr, &caption, &rows, w, h),
        Format::Csv => write_csv(wr, &rows, w, h),
    })
}

/// A timed frame.
struct Frame {
    out: RenderOutput,
    /// The whole render call.
    time: Duration,
    /// From the call until the first tile was shaded (setup plus one tile).
    setup: Duration,
}

/// Renders one frame, timing the whole render call, and reports it on standard error.
fn frame(scene: &Scene, opts: &RenderOptions, what: &str) -> Result<Frame> {
    let pixels = u64::from(opts.width) * u64::from(opts.height);
    let pb = progress::items(pixels.div_ceil(32 * 32), 64, what, "tiles");
    let first_tile = OnceLock::new();
    let mut renderer = CpuRenderer::new();
    let start = Instant::now();
    let out = renderer
        .render(scene, opts, &|done, _total| {
            first_tile.get_or_init(Instant::now);
            pb.set_position(done as u64);
        })
        .with_context(|| format!("cannot render ({what})"))?;
    let time = start.elapsed();
    pb.finish_and_clear();
    let setup = first_tile.get().map_or(time, |t| t.duration_since(start));
    if out.color.iter().any(|c| !c.is_finite()) {
        bail!("internal error: the render ({what}) produced a non-finite pixel");
    }
    eprintln!("{what}: {:.1} ms (first tile after {:.1} ms)", ms(time), ms(setup));
    Ok(Frame { out, time, setup })
}

/// Mean of the `fetches` AOV over covered pixels (uv AOV not zero); `None` when none is covered
/// or the AOVs are missing.
fn fetches_per_covered_pixel(out: &RenderOutput) -> Option<f64> {
    let aovs = out.aovs.as_ref()?;
    let (sum, n) = aovs
        .uv
        .iter()
        .zip(&aovs.fetches)
        .filter(|(uv, _)| **uv != pomkit_core::glam::Vec2::ZERO)
        .fold((0.0f64, 0u64), |(s, n), (_, &f)| (s + f64::from(f), n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// The median (the mean of the middle two for an even count). `v` must not be empty.
fn median(v: &mut [Duration]) -> Duration {
    v.sort_unstable();
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2 }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn row(name: &str, runs: u32, median: Duration, w: u32, h: u32, fetches: Option<f64>) -> Row {
    let secs = median.as_secs_f64().max(1e-9);
    Row {
        name: name.to_owned(),
        runs,
        median_ms: ms(median),
        mpix_per_s: f64::from(w) * f64::from(h) / secs / 1e6,
        fetches_per_pixel: fetches,
    }
}

fn write_md(wr: &mut dyn Write, caption: &str, rows: &[Row], w: u32, h: u32) -> std::io::Result<()> {
    writeln!(wr, "{caption}")?;
    writeln!(wr)?;
    writeln!(wr, "| technique | size | runs | median ms/frame | Mpix/s | fetches per covered pixel |")?;
    writeln!(wr, "|---|---|--:|--:|--:|--:|")?;
    for r in rows {
        let fetches = r.fetches_per_pixel.map_or_else(|| "-".to_owned(), |f| format!("{f:.1}"));
        let median = if r.median_ms < 100.0 { format!("{:.1}", r.median_ms) } else { format!("{:.0}", r.median_ms) };
        let rate = if r.mpix_per_s < 10.0 { format!("{:.3}", r.mpix_per_s) } else { format!("{:.1}", r.mpix_per_s) };
        writeln!(wr, "| {} | {w}x{h} | {} | {median} | {rate} | {fetches} |", r.name, r.runs)?;
    }
    Ok(())
}

fn write_csv(wr: &mut dyn Write, rows: &[Row], w: u32, h: u32) -> std::io::Result<()> {
    writeln!(wr, "{CSV_HEADER}")?;
    for r in rows {
        let fetches = r.fetches_per_pixel.map_or_else(String::new, |f| f.to_string());
        writeln!(wr, "{},{w},{h},{},{},{},{fetches}", r.name, r.runs, r.median_ms, r.mpix_per_s)?;
    }
    Ok(())
}
