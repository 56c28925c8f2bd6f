//! `pomkit bench`: whole frames of the built-in demo scene, timed per technique on the GPU
//! renderer (GPU timestamp queries around its passes) and on the CPU renderer (wall clock around
//! the render call), side by side (docs/BENCHMARKS.md: medians measured in one run, with the
//! fetches that explain them).

use std::io::Write;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};
use pomkit_gpu::GpuRenderer;

use crate::backend::{self, Backend, Opened};
use crate::{progress, technique};

/// The CSV header of the table: the CPU renderer's columns, then the GPU renderer's.
pub const CSV_HEADER: &str = "technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel,\
gpu_runs,gpu_render_pass_ms,gpu_height_passes_ms,gpu_wall_ms,gpu_timer,gpu_fetches_per_pixel,gpu_over_cpu";

#[derive(Args, Debug)]
#[command(after_long_help = "\
What is rendered: the built-in demo scene (bricks, pyramids, cobblestones and raised text on a \
plane, a cube, a sphere and a quad, every material with its soft self-shadows), with each listed \
technique in place of the materials' own (`material`: each material's own), at --size.

GPU (pomkit-gpu, with --backend gpu, or auto when an adapter exists): per technique the scene is \
prepared once (uploads, pipelines; not timed) and drawn once untimed (warm-up: shader \
compilation, first-use allocations; its AOVs give the fetches), then drawn --gpu-runs more times. \
The timed frames take turns: every technique is prepared and warmed up first, then each round \
draws one frame of each technique, so that a slow spell of a shared machine falls on all of them \
alike. Before each timed frame every height map is re-uploaded, as a dynamic height field would \
be, so the compute passes that rebuild its mips, normals, parallax map and maximum-height pyramid run \
every frame. The render pass (every object, every pixel traced, shadowed and shaded) and the \
compute passes are timed apart with GPU timestamp queries when the adapter has them (else with \
the wall clock around submit-and-wait, which includes driver overhead: the table says which). \
The wall time of the whole frame (uploads, passes, readback of colour and AOVs, resolve) is \
reported too. On a software adapter (lavapipe, llvmpipe, WARP) GPU times are CPU times.

CPU (pomkit-cpu, on all cores with rayon): per technique one untimed warm-up frame with the AOVs \
on (its fetches), then --cpu-runs frames timed with std::time::Instant around the whole render \
call: preparing the materials (tracing pyramids, baked normal maps, albedo mips), the vertex stage \
and triangle setup, shading, and the resolve; the techniques take turns as on the GPU. Generating \
the scene's textures is not timed. \
median_ms is the median of those frames, mpix_per_s is width * height / median.

Every figure is a median over the timed frames. gpu_over_cpu is the GPU render pass's median over \
the CPU frame's median (below 1: the GPU is faster). Fetches are the mean height fetches per \
covered pixel (view trace plus shadow trace; covered = a pixel whose uv AOV is not zero), from \
each renderer's own warm-up frame.

With --displaced, the ground truth is added on the CPU: the height-mapped meshes tessellated to \
one triangle edge per texel (coarsened where the screen cannot tell, by at most a quarter of a \
pixel) and displaced for real, streamed a block of triangles at a time, shaded with normal \
mapping and the materials' shadows. It is timed as the techniques are, a warm-up and then \
--cpu-runs frames, tessellation included (its fetches are the shadow trace's only). Standard error \
also shows, per CPU frame, the time until the first tile was shaded (setup: materials, \
tessellation, vertex stage, triangle setup), and every GPU frame's pass times.

Formats: md, a Markdown table for people (rounded; without GPU columns when the GPU did not run, \
without CPU columns with --cpu-runs 0); csv, with the header \
`technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel,gpu_runs,gpu_render_pass_ms,\
gpu_height_passes_ms,gpu_wall_ms,gpu_timer,gpu_fetches_per_pixel,gpu_over_cpu` and full \
precision (the first seven are the CPU's; a renderer that did not run leaves its fields empty and \
its runs 0; gpu_timer is `timestamps` or `wall`). The table goes to standard output, progress to \
standard error.")]
pub struct BenchArgs {
    /// Image size.
    #[arg(long, default_value = "1920x1080", value_name = "WxH")]
    size: String,
    /// Timed frames per technique on both renderers, after the warm-up (1 to 1000); sets
    /// --gpu-runs and --cpu-runs unless they are given.
    #[arg(long, value_name = "N")]
    runs: Option<u32>,
    /// Timed GPU frames per technique, after one untimed warm-up frame (1 to 1000) [default: 5].
    #[arg(long, value_name = "N")]
    gpu_runs: Option<u32>,
    /// Timed CPU frames per technique, after one untimed warm-up frame (0 to 1000; 0 times the
    /// GPU only) [default: 3].
    #[arg(long, value_name = "N")]
    cpu_runs: Option<u32>,
    /// Renderers: cpu (the CPU renderer only), gpu (the GPU renderer, with the CPU renderer's
    /// time for the same frame beside it; fails without a GPU adapter) or auto (as gpu when an
    /// adapter exists, else as cpu, saying why the GPU columns are missing).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Techniques to time, comma-separated: any of flat, normal, parallax, iterative, steep,
    /// pom-classic, pom, relief, exact, cone, `all` for all of those, and `material` for each
    /// material's own technique.
    #[arg(long, default_value = "all,material", value_name = "T,..")]
    techniques: String,
    /// Also time the `displaced` ground truth on the CPU renderer (a few times a POM frame).
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
/// Timed GPU frames per technique unless told.
const DEFAULT_GPU_RUNS: u32 = 5;
/// Timed CPU frames per technique unless told (the CPU renderer is slow at 1920x1080).
const DEFAULT_CPU_RUNS: u32 = 3;

/// One row of the table.
struct Row {
    name: String,
    /// `None` when the CPU renderer did not run.
    cpu: Option<CpuStats>,
    /// `None` when the GPU renderer did not run.
    gpu: Option<GpuStats>,
}

/// The CPU renderer's figures for one technique.
struct CpuStats {
    runs: u32,
    median_ms: f64,
    mpix_per_s: f64,
    /// `None` when no pixel was covered.
    fetches_per_pixel: Option<f64>,
}

/// The GPU renderer's figures for one technique (medians over the timed frames).
struct GpuStats {
    runs: u32,
    render_pass_ms: f64,
    height_passes_ms: f64,
    wall_ms: f64,
    /// Whether the pass times come from timestamp queries (else the wall clock).
    from_timestamps: bool,
    /// `None` when no pixel was covered.
    fetches_per_pixel: Option<f64>,
}

impl Row {
    /// The GPU render pass's median over the CPU frame's median.
    fn gpu_over_cpu(&self) -> Option<f64> {
        match (&self.cpu, &self.gpu) {
            (Some(c), Some(g)) if c.median_ms > 0.0 => Some(g.render_pass_ms / c.median_ms),
            _ => None,
        }
    }
}

/// Parses `--techniques`: technique names, `all` and `material`; duplicates dropped, order kept.
fn parse_techniques(s: &str) -> Result<Vec<(String, Mode)>> {
    let names = technique::names();
    let mut list: Vec<(String, Mode)> = Vec::new();
    let mut add = |name: &str, mode: Mode| {
        if !list.iter().any(|(_, m)| *m == mode) {
            list.push((name.to_owned(), mode));
        }
    };
    for part in s.split(',') {
        let t = part.trim();
        if t.is_empty() {
            bail!("--techniques '{s}': empty name in the list; expected 'all' or names from: {}, material", names);
        } else if t.eq_ignore_ascii_case("all") {
            Technique::ALL.iter().for_each(|t| add(t.name(), Mode::Technique(*t)));
        } else if t.eq_ignore_ascii_case("material") {
            add("material", Mode::Material);
        } else if t.eq_ignore_ascii_case("displaced") {
            bail!("--techniques '{s}': the displaced ground truth is timed once with --displaced, not in the list");
        } else {
            let technique: Technique = t.parse().map_err(|e| anyhow::anyhow!("--techniques: {e}, material"))?;
            add(&t.to_ascii_lowercase(), Mode::Technique(technique));
        }
    }
    Ok(list)
}

/// Checks a frame count against `min..=MAX_RUNS`, naming `flag`.
fn check_runs(flag: &str, n: u32, min: u32) -> Result<u32> {
    if !(min..=MAX_RUNS).contains(&n) {
        bail!("{flag} {n}: give between {min} and {MAX_RUNS} timed frames per technique");
    }
    Ok(n)
}

pub fn run(a: &BenchArgs) -> Result<()> {
    let (w, h) = crate::parse_size(&a.size).context("--size")?;
    if let Some(n) = a.runs {
        check_runs("--runs", n, 1)?;
    }
    let gpu_runs = check_runs("--gpu-runs", a.gpu_runs.or(a.runs).unwrap_or(DEFAULT_GPU_RUNS), 1)?;
    let cpu_runs = check_runs("--cpu-runs", a.cpu_runs.or(a.runs).unwrap_or(DEFAULT_CPU_RUNS), 0)?;
    let modes = parse_techniques(&a.techniques)?;
    // Standard output is checked before any timing (a closed one is refused now, not after).
    let mut outs = pomkit_io::output::Outputs::new();
    let table = outs.output("-");
    outs.check()?;
    if cpu_runs == 0 && a.backend == Backend::Cpu {
        bail!("--cpu-runs 0 with --backend cpu leaves nothing to time");
    }
    if cpu_runs == 0 && a.displaced {
        bail!("--displaced times the CPU renderer: it needs --cpu-runs of at least 1");
    }
    let (mut gpu, skipped) = match backend::open(a.backend)? {
        Opened::Gpu(g) => (Some(g), None),
        Opened::CpuAskedFor => (None, None),
        Opened::NoGpu(reason) => {
            eprintln!("GPU columns skipped: {reason}");
            (None, Some(reason))
        }
    };
    if cpu_runs == 0 && gpu.is_none() {
        bail!("--cpu-runs 0 leaves nothing to time: there is no GPU adapter");
    }
    eprintln!("generating the demo scene (not timed)");
    let scene = pomkit_core::demo::demo_scene();
    let base = RenderOptions { width: w, height: h, ..Default::default() };
    let techniques: Vec<(&str, RenderOptions)> =
        modes.iter().map(|(name, mode)| (name.as_str(), RenderOptions { mode: *mode, ..base })).collect();
    let gpu_stats: Vec<Option<GpuStats>> = match gpu.as_deref_mut() {
        Some(g) => gpu_frames(g, &scene, &techniques, gpu_runs)?.into_iter().map(Some).collect(),
        None => techniques.iter().map(|_| None).collect(),
    };
    let cpu_stats: Vec<Option<CpuStats>> = if cpu_runs > 0 {
        cpu_frames(&scene, &techniques, cpu_runs)?.into_iter().map(Some).collect()
    } else {
        techniques.iter().map(|_| None).collect()
    };
    let mut rows: Vec<Row> = modes
        .iter()
        .zip(gpu_stats.into_iter().zip(cpu_stats))
        .map(|((name, _), (gpu, cpu))| Row { name: name.clone(), cpu, gpu })
        .collect();
    if a.displaced {
        let opts = RenderOptions { mode: Mode::Displaced, ..base };
        let cpu = cpu_frames(&scene, &[("displaced", opts)], cpu_runs)?.remove(0);
        rows.push(Row { name: "displaced".into(), cpu: Some(cpu), gpu: None });
    }
    let caption = caption(a, w, h, gpu.as_deref(), gpu_runs, cpu_runs, skipped.as_deref(), &rows);
    outs.write_with(table, |wr| {
        match a.format {
            Format::Md => write_md(wr, &caption, &rows, w, h),
            Format::Csv => write_csv(wr, &rows, w, h),
        }
        .map_err(anyhow::Error::from)
    })?;
    outs.commit()?;
    Ok(())
}

/// What the Markdown table shows, for quoting.
#[expect(clippy::too_many_arguments, reason = "one caption from every setting of the run")]
fn caption(
    a: &BenchArgs,
    w: u32,
    h: u32,
    gpu: Option<&GpuRenderer>,
    gpu_runs: u32,
    cpu_runs: u32,
    skipped: Option<&str>,
    rows: &[Row],
) -> String {
    let mut parts = vec![format!("Demo scene at {w}x{h}.")];
    if let Some(g) = gpu {
        let timer = if rows.iter().filter_map(|r| r.gpu.as_ref()).all(|g| g.from_timestamps) {
            "pass times from GPU timestamp queries"
        } else {
            "pass times from the wall clock around submit-and-wait (no timestamp queries on this adapter)"
        };
        let software = if g.context().is_software() { ", a software adapter: its times are CPU times" } else { "" };
        parts.push(format!(
            "GPU: {}{software}; median of {gpu_runs} frame(s) per technique, drawn after one warm-up from one \
             prepared scene, the techniques taking turns frame by frame, height maps rebuilt every frame; \
             {timer}.",
            g.context().describe()
        ));
    }
    if cpu_runs > 0 {
        parts.push(format!(
            "CPU: pomkit-cpu on {} thread(s), shading packets of 8 fragments with {} SIMD (CPU features: {}); \
             median of {cpu_runs} frame(s) per technique after one warm-up, the techniques taking turns frame \
             by frame, whole render call{}.",
            rayon::current_num_threads(),
            pomkit_cpu::Simd8::from_env().unwrap_or_else(|_| pomkit_cpu::Simd8::detect()).name(),
            pomkit_cpu::cpu_features(),
            if a.displaced { ", tessellation included for displaced" } else { "" }
        ));
    }
    if gpu.is_some() && cpu_runs > 0 {
        parts.push("GPU/CPU: GPU render pass over CPU frame.".into());
    }
    if let Some(reason) = skipped {
        parts.push(format!("No GPU columns: {reason}."));
    }
    parts.push("Fetches: mean height fetches per covered pixel, view and shadow traces.".into());
    parts.join(" ")
}

/// Times `runs` GPU frames of each technique after a warm-up (docs/BENCHMARKS.md: prepare once,
/// draw repeatedly), reporting each on standard error. Every technique is prepared and warmed up
/// first; then the timed frames take turns, one of each technique per round, so that a slow spell
/// of a shared machine falls on every technique alike and their ratios stay steady.
fn gpu_frames(
    gpu: &mut GpuRenderer,
    scene: &Scene,
    techniques: &[(&str, RenderOptions)],
    runs: u32,
) -> Result<Vec<GpuStats>> {
    let mut timed = Vec::with_capacity(techniques.len());
    for &(name, opts) in techniques {
        let start = Instant::now();
        // The GPU renderer always draws its AOVs; `aovs` only keeps them in the output.
        let mut prepared =
            gpu.prepare(scene, &RenderOptions { aovs: true, ..opts }).with_context(|| gpu_failed(name))?;
        eprintln!("{name}: gpu prepare (uploads, pipelines): {:.1} ms", ms(start.elapsed()));
        let warm = gpu.draw(&mut prepared, scene).with_context(|| gpu_failed(name))?;
        report_gpu(gpu, &format!("{name}: gpu warm-up"));
        let fetches = fetches_per_covered_pixel(&warm);
        timed.push((name, opts, prepared, fetches, GpuTimes::default()));
    }
    let heights: Vec<_> =
        scene.materials.iter().enumerate().filter_map(|(i, m)| m.height.as_ref().map(|f| (i, f))).collect();
    for i in 0..runs {
        for (name, opts, prepared, _, times) in &mut timed {
            let fail = || gpu_failed(name);
            for (index, field) in &heights {
                prepared.set_height(gpu.context(), *index, field).with_context(fail)?;
                // set_height removes the cones (they described the old heights): give them
                // back, as a program with a changing field and CPU-built cones would, so that
                // `cone` is timed on its cones, not on exact's walk.
                let m = &scene.materials[*index];
                if opts.mode.technique(m.technique) == Technique::Cone {
                    prepared.set_cones(gpu.context(), *index, m.cones_to_trace().as_deref()).with_context(fail)?;
                }
            }
            let out = gpu.draw(prepared, scene).with_context(fail)?;
            if out.color.iter().any(|c| !c.is_finite()) {
                bail!("internal error: the GPU render ({name}) produced a non-finite pixel");
            }
            let t = report_gpu(gpu, &format!("{name}: gpu run {}/{runs}", i + 1));
            times.pass.push(t.render_pass_ms);
            times.height.push(t.height_passes_ms);
            times.wall.push(t.wall_ms);
            times.untimed |= !t.from_timestamps;
        }
    }
    Ok(timed
        .into_iter()
        .map(|(_, _, _, fetches, mut t)| GpuStats {
            runs,
            render_pass_ms: median_f64(&mut t.pass),
            height_passes_ms: median_f64(&mut t.height),
            wall_ms: median_f64(&mut t.wall),
            from_timestamps: !t.untimed,
            fetches_per_pixel: fetches,
        })
        .collect())
}

/// One technique's GPU frame times, gathered round by round.
#[derive(Default)]
struct GpuTimes {
    pass: Vec<f64>,
    height: Vec<f64>,
    wall: Vec<f64>,
    /// Some frame was timed with the wall clock, not timestamp queries.
    untimed: bool,
}

fn gpu_failed(name: &str) -> String {
    format!("cannot render ({name}) on the GPU")
}

/// Prints the last GPU frame's times, labelled `what`, and returns them.
fn report_gpu(gpu: &GpuRenderer, what: &str) -> pomkit_gpu::Timings {
    let t = gpu.timings();
    let timer = if t.from_timestamps { "timestamps" } else { "wall clock" };
    eprintln!(
        "{what}: render pass {:.1} ms, height passes {:.1} ms ({timer}); whole frame {:.1} ms",
        t.render_pass_ms, t.height_passes_ms, t.wall_ms
    );
    t
}

/// Times `runs` CPU frames of each technique after a warm-up with the AOVs on (which gives the
/// fetches), the techniques taking turns as on the GPU ([`gpu_frames`]). One renderer per
/// technique draws its frames, as one GPU renderer draws the GPU's: it keeps the albedo mip
/// chains from frame to frame (the GPU keeps its uploaded textures), while everything made
/// from the height maps is made again in every frame on both.
fn cpu_frames(scene: &Scene, techniques: &[(&str, RenderOptions)], runs: u32) -> Result<Vec<CpuStats>> {
    let mut timed = Vec::with_capacity(techniques.len());
    for &(name, opts) in techniques {
        let mut renderer = CpuRenderer::new();
        let warm =
            frame(&mut renderer, scene, &RenderOptions { aovs: true, ..opts }, &format!("{name}: warm-up with AOVs"))?;
        timed.push((name, opts, renderer, fetches_per_covered_pixel(&warm.out), Vec::new(), Vec::new()));
    }
    for i in 0..runs {
        for (name, opts, renderer, _, times, setups) in &mut timed {
            let f = frame(renderer, scene, opts, &format!("{name}: run {}/{runs}", i + 1))?;
            times.push(f.time);
            setups.push(f.setup);
        }
    }
    Ok(timed
        .into_iter()
        .map(|(name, opts, _, fetches, mut times, mut setups)| {
            let med = median(&mut times);
            eprintln!(
                "{name}: median {:.1} ms, of which setup (until the first tile) {:.1} ms",
                ms(med),
                ms(median(&mut setups))
            );
            cpu_stats(runs, med, opts.width, opts.height, fetches)
        })
        .collect())
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
fn frame(renderer: &mut CpuRenderer, scene: &Scene, opts: &RenderOptions, what: &str) -> Result<Frame> {
    let pixels = u64::from(opts.width) * u64::from(opts.height);
    let pb = progress::items(pixels.div_ceil(32 * 32), 64, what, "tiles");
    let first_tile = OnceLock::new();
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

/// The median of finite numbers (the mean of the middle two for an even count). `v` must not be
/// empty.
fn median_f64(v: &mut [f64]) -> f64 {
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn cpu_stats(runs: u32, median: Duration, w: u32, h: u32, fetches: Option<f64>) -> CpuStats {
    let secs = median.as_secs_f64().max(1e-9);
    CpuStats {
        runs,
        median_ms: ms(median),
        mpix_per_s: f64::from(w) * f64::from(h) / secs / 1e6,
        fetches_per_pixel: fetches,
    }
}

/// Milliseconds for people: more decimals for small values.
fn round_ms(v: f64) -> String {
    if v < 10.0 {
        format!("{v:.2}")
    } else if v < 100.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.0}")
    }
}

fn round_fetches(f: Option<f64>) -> String {
    f.map_or_else(|| "-".to_owned(), |f| format!("{f:.1}"))
}

fn write_md(wr: &mut dyn Write, caption: &str, rows: &[Row], w: u32, h: u32) -> std::io::Result<()> {
    writeln!(wr, "{caption}")?;
    writeln!(wr)?;
    let (gpu, cpu) = (rows.iter().any(|r| r.gpu.is_some()), rows.iter().any(|r| r.cpu.is_some()));
    if !gpu {
        // The CPU renderer alone: the table of earlier versions, unchanged.
        writeln!(wr, "| technique | size | runs | median ms/frame | Mpix/s | fetches per covered pixel |")?;
        writeln!(wr, "|---|---|--:|--:|--:|--:|")?;
        for r in rows {
            let Some(c) = &r.cpu else { continue };
            let rate =
                if c.mpix_per_s < 10.0 { format!("{:.3}", c.mpix_per_s) } else { format!("{:.1}", c.mpix_per_s) };
            let median =
                if c.median_ms < 100.0 { format!("{:.1}", c.median_ms) } else { format!("{:.0}", c.median_ms) };
            let fetches = round_fetches(c.fetches_per_pixel);
            writeln!(wr, "| {} | {w}x{h} | {} | {median} | {rate} | {fetches} |", r.name, c.runs)?;
        }
        return Ok(());
    }
    let mut head = vec!["technique", "GPU render pass ms", "GPU height passes ms", "GPU whole frame ms"];
    if cpu {
        head.extend(["CPU ms/frame", "GPU/CPU"]);
    }
    head.push("fetches per covered pixel (GPU)");
    if cpu {
        head.push("(CPU)");
    }
    writeln!(wr, "| {} |", head.join(" | "))?;
    writeln!(wr, "|---|{}", "--:|".repeat(head.len() - 1))?;
    for r in rows {
        let dash = || "-".to_owned();
        let mut cells = vec![r.name.clone()];
        match &r.gpu {
            Some(g) => cells.extend([round_ms(g.render_pass_ms), round_ms(g.height_passes_ms), round_ms(g.wall_ms)]),
            None => cells.extend([dash(), dash(), dash()]),
        }
        if cpu {
            cells.push(r.cpu.as_ref().map_or_else(dash, |c| round_ms(c.median_ms)));
            cells.push(r.gpu_over_cpu().map_or_else(dash, |x| format!("{x:.2}")));
        }
        cells.push(round_fetches(r.gpu.as_ref().and_then(|g| g.fetches_per_pixel)));
        if cpu {
            cells.push(round_fetches(r.cpu.as_ref().and_then(|c| c.fetches_per_pixel)));
        }
        writeln!(wr, "| {} |", cells.join(" | "))?;
    }
    Ok(())
}

fn write_csv(wr: &mut dyn Write, rows: &[Row], w: u32, h: u32) -> std::io::Result<()> {
    fn opt(x: Option<f64>) -> String {
        x.map_or_else(String::new, |f| f.to_string())
    }
    writeln!(wr, "{CSV_HEADER}")?;
    for r in rows {
        let cpu = match &r.cpu {
            Some(c) => format!("{},{},{},{}", c.runs, c.median_ms, c.mpix_per_s, opt(c.fetches_per_pixel)),
            None => "0,,,".to_owned(),
        };
        let gpu = match &r.gpu {
            Some(g) => format!(
                "{},{},{},{},{},{}",
                g.runs,
                g.render_pass_ms,
                g.height_passes_ms,
                g.wall_ms,
                if g.from_timestamps { "timestamps" } else { "wall" },
                opt(g.fetches_per_pixel)
            ),
            None => "0,,,,,".to_owned(),
        };
        writeln!(wr, "{},{w},{h},{cpu},{gpu},{}", r.name, opt(r.gpu_over_cpu()))?;
    }
    Ok(())
}
