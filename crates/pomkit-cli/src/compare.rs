//! `pomkit compare`: the accuracy table (ARCHITECTURE.md, Stable interfaces): each technique's error against
//! `exact` and its fetches per ray, per view angle, on a fixed random set of rays; with
//! `--yardstick`, the fewest samples with which `pom` meets a bar of accuracy, beside exact's
//! fetches (`pomkit_core::accuracy::yardstick`; this file only prints it).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use pomkit_core::accuracy::{self, AccuracyRow, DEFAULT_SEED, PomSearch, YardstickOptions, YardstickRow};
use pomkit_core::trace::MAX_SAMPLES;

use crate::technique::{self, TechniqueArgs};
use crate::{HeightOption, output, progress};

/// The CSV header (and the JSON keys) of the table.
pub const CSV_HEADER: &str = "technique,angle,rays,mean_error,p95_error,share_over_1,mean_fetches,max_fetches";

/// The CSV header (and the JSON keys) of the yardstick table (`--yardstick` with csv or json).
pub const YARDSTICK_HEADER: &str = "angle,rays,max_share,cap,\
pom_samples,pom_mean_fetches,pom_max_fetches,pom_share_over_1,pom_mean_error,pom_p95_error,pom_share_below,\
refine,refined_samples,refined_mean_fetches,refined_max_fetches,refined_share_over_1,refined_mean_error,\
refined_p95_error,refined_share_below,exact_mean_fetches,exact_max_fetches,ratio";

/// Most rays per angle accepted (memory grows with rays x techniques).
const MAX_RAYS: usize = 1_000_000;
/// Fewer rays in all than this finish in about a second: no bar.
const MIN_RAYS_FOR_BAR: u64 = 100_000;
/// About how many times the yardstick traces each ray (two searches of some 25 counts each),
/// for the "long enough for a bar" rule.
const YARDSTICK_TRACES_PER_RAY: u64 = 50;

#[derive(Args, Debug)]
#[command(after_long_help = "\
Error is the distance in texels between a technique's hit and the exact hit (the first \
intersection with the bilinear surface of the mip-0 texels) for the same ray. Each angle traces \
the same entry points and azimuths (uniformly random in the tile, from --seed), so the table is \
reproducible. A row for `exact` is always included (error 0 by definition; its fetches are the \
reference cost).

Formats: md, a Markdown table grouped by angle (numbers rounded); csv, with the header \
`technique,angle,rays,mean_error,p95_error,share_over_1,mean_fetches,max_fetches` and full \
precision; json, an array of objects with those keys. share_over_1 is a fraction in [0, 1]; \
p95_error is the nearest-rank 95th percentile.

--yardstick, the honest yardstick (docs/ACCURACY.md): per angle, on the same rays, the fewest \
samples N with which pom, --min-samples and --max-samples both N, leaves at most \
--yardstick-share of the rays (default 0.001, that is 0.1%) over one texel from exact's hit; \
once with --refine 0 and once with secant refinement (--refine, or 2 when --refine is 0); \
beside exact's mean fetches on the same rays, and the ratio of exact's mean fetches to those \
of the cheaper of the two pom counts found. The search doubles N from 8 to the first count \
that passes (if none up to --yardstick-cap, default 1024, passes: \"not reached at N=1024\"), \
bisects between that count and the last failing one, then checks the counts below the one \
found, one at a time, until 8 in a row fail: the N reported passes, and every count the search \
tried below it (N-1 included, unless N is 8) fails. --min-samples and --max-samples do not apply \
to it. It traces each ray some 50 times: 2000 rays at three angles take seconds.

With --yardstick, md prints the yardstick table after the accuracy table; csv and json print \
the yardstick table alone, one row per angle, with the header \
`angle,rays,max_share,cap,pom_samples,pom_mean_fetches,pom_max_fetches,pom_share_over_1,\
pom_mean_error,pom_p95_error,pom_share_below,refine,refined_samples,refined_mean_fetches,\
refined_max_fetches,refined_share_over_1,refined_mean_error,refined_p95_error,\
refined_share_below,exact_mean_fetches,exact_max_fetches,ratio` (json: objects with those \
keys, null where csv leaves a field empty). pom_* is pom with --refine 0, refined_* with \
`refine` steps. pom_samples and refined_samples are the N found, empty when not reached; the \
other pom_* and refined_* fields are pom's at that N (at the cap when not reached), but \
*_share_below, the share over one texel at N-1 (empty when N is 8 or not reached). ratio is \
exact_mean_fetches over the smaller mean fetches of the two searches that passed, empty when \
neither passed.")]
pub struct CompareArgs {
    #[command(flatten)]
    height: HeightOption,
    /// View angles from the normal, in degrees, comma-separated, each in [0, 90).
    #[arg(long, default_value = "0,30,60,75,85", allow_hyphen_values = true, value_name = "DEG,..")]
    angles: String,
    /// `all`, or techniques separated by commas (flat, normal, parallax, iterative, steep,
    /// pom-classic, pom, relief, exact, cone).
    #[arg(long, default_value = "all", value_name = "T,..")]
    techniques: String,
    /// Rays per angle (1 to 1000000). More rays give steadier statistics and take longer.
    #[arg(long, default_value_t = 2000, value_name = "N")]
    rays: usize,
    /// Seed of the random rays: the same seed gives the same table.
    #[arg(long, default_value_t = DEFAULT_SEED, value_name = "N")]
    seed: u64,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Md)]
    format: Format,
    /// Write the table here (atomically) instead of standard output; `-` is standard output.
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Also find the honest yardstick: per angle, the fewest samples N with which pom
    /// (--min-samples = --max-samples = N) leaves at most --yardstick-share of the rays over one
    /// texel, with --refine 0 and with refinement, beside exact's fetches (see below).
    #[arg(long)]
    yardstick: bool,
    /// The yardstick's bar: the largest share of rays over one texel that passes, in [0, 1].
    #[arg(
        long,
        default_value_t = accuracy::YARDSTICK_SHARE,
        value_name = "S",
        requires = "yardstick",
        allow_negative_numbers = true
    )]
    yardstick_share: f64,
    /// The largest N the yardstick tries (8 to 1024); a search that gets there without passing
    /// says "not reached".
    #[arg(long, default_value_t = MAX_SAMPLES, value_name = "N", requires = "yardstick")]
    yardstick_cap: u32,
    #[command(flatten)]
    options: TechniqueArgs,
}

/// Output formats of the table.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A Markdown table for people.
    Md,
    /// CSV, full precision.
    Csv,
    /// A JSON array of objects, full precision.
    Json,
}

pub fn run(a: &CompareArgs) -> Result<()> {
    let params = a.options.params()?;
    let angles = parse_angles(&a.angles)?;
    let techniques = technique::parse_list(&a.techniques)?;
    if let Some(path) = &a.height.cone_map
        && !techniques.contains(&pomkit_core::trace::Technique::Cone)
    {
        eprintln!(
            "warning: --cone-map {}: only the cone technique uses a cone map, and --techniques has no cone",
            path.display()
        );
    }
    if !(1..=MAX_RAYS).contains(&a.rays) {
        bail!("--rays {}: give between 1 and {MAX_RAYS} rays per angle", a.rays);
    }
    let yardstick = a.yardstick.then(|| yardstick_options(a, &params)).transpose()?;
    // csv and json with --yardstick hold the yardstick table alone.
    let table = yardstick.is_none() || a.format == Format::Md;
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    // Checked before any work; the table appears only when complete, never over the height map.
    let mut outs = pomkit_io::output::Outputs::new();
    for input in a.height.inputs() {
        outs.input(&input);
    }
    let out_id = outs.output(&out);
    outs.check()?;
    let cones = table && techniques.contains(&pomkit_core::trace::Technique::Cone);
    let surface = a.height.surface(&a.options, cones)?;
    let (w, h) = (surface.field().width(), surface.field().height());
    let rows = if table {
        let pb = progress::items((angles.len() * a.rays) as u64, MIN_RAYS_FOR_BAR, "comparing", "rays");
        let rows = accuracy::compare(&surface, &techniques, &angles, &params, a.rays, a.seed, &|n| pb.inc(n as u64));
        pb.finish_and_clear();
        rows
    } else {
        Vec::new()
    };
    let yard = yardstick.map(|options| {
        let traces = (angles.len() * a.rays) as u64 * YARDSTICK_TRACES_PER_RAY;
        let min = if traces >= MIN_RAYS_FOR_BAR { 0 } else { u64::MAX };
        let pb = progress::items(2 * angles.len() as u64, min, "yardstick", "searches");
        let rows = accuracy::yardstick(&surface, &angles, &params, a.rays, a.seed, &options, &|step| {
            pb.set_position(step.searches_done as u64);
            pb.set_message(format!("yardstick {}°, refine {}, N={}", step.angle_deg, step.refine, step.samples));
        });
        pb.finish_and_clear();
        rows
    });
    let edges = surface.edges().name();
    let setup = format!(
        "{} ({w}x{h}, depth scale {}, {edges} edges), {} rays per angle, seed {}",
        a.height.input,
        surface.depth_scale(),
        a.rays,
        a.seed
    );
    let caption = format!("Error in texels against `exact` on {setup}.");
    outs.write_with(out_id, |wr| {
        match (a.format, &yard) {
            (Format::Md, None) => write_md(wr, &caption, &rows),
            (Format::Md, Some(yard)) => write_md(wr, &caption, &rows)
                .and_then(|()| writeln!(wr))
                .and_then(|()| write_yardstick_md(wr, &setup, yard)),
            (Format::Csv, None) => write_csv(wr, &rows),
            (Format::Csv, Some(yard)) => write_yardstick_csv(wr, yard),
            (Format::Json, None) => write_json(wr, &rows),
            (Format::Json, Some(yard)) => write_yardstick_json(wr, yard),
        }
        .map_err(anyhow::Error::from)
    })?;
    outs.commit()?;
    if !output::is_stdout(&out) {
        eprintln!("wrote {} ({} rows)", out.display(), rows.len() + yard.map_or(0, |y| y.len()));
    }
    Ok(())
}

/// The yardstick's options from the command line: `--yardstick-share`, `--yardstick-cap`, and
/// the refined search's steps (`--refine`, or [`accuracy::YARDSTICK_REFINE`] when it is 0).
fn yardstick_options(a: &CompareArgs, params: &pomkit_core::trace::TraceParams) -> Result<YardstickOptions> {
    let share = a.yardstick_share;
    if !(0.0..=1.0).contains(&share) {
        bail!("--yardstick-share {share}: give a share of rays in [0, 1] (0.001 is 0.1%)");
    }
    let start = accuracy::YARDSTICK_START;
    if !(start..=MAX_SAMPLES).contains(&a.yardstick_cap) {
        bail!("--yardstick-cap {}: give a sample count from {start} to {MAX_SAMPLES}", a.yardstick_cap);
    }
    let refine = if params.refine > 0 { params.refine } else { accuracy::YARDSTICK_REFINE };
    Ok(YardstickOptions { max_share: share, cap: a.yardstick_cap, refine, ..YardstickOptions::default() })
}

/// Parses `--angles`: comma-separated degrees in [0, 90), duplicates dropped, order kept.
fn parse_angles(s: &str) -> Result<Vec<f32>> {
    let mut angles = Vec::new();
    for part in s.split(',') {
        let t = part.trim();
        let Ok(a) = t.parse::<f32>() else {
            bail!("--angles '{s}': '{t}' is not a number of degrees");
        };
        if !(a.is_finite() && (0.0..90.0).contains(&a)) {
            bail!("--angles '{s}': {t} is outside [0, 90): angles are degrees from the normal, below grazing");
        }
        if !angles.contains(&a) {
            angles.push(a);
        }
    }
    Ok(angles)
}

/// A number for people: three decimals below 10, fewer above.
fn round(x: f64) -> String {
    if x.abs() < 10.0 {
        format!("{x:.3}")
    } else if x.abs() < 100.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.1}")
    }
}

fn write_md(w: &mut dyn Write, caption: &str, rows: &[AccuracyRow]) -> std::io::Result<()> {
    writeln!(w, "{caption}")?;
    writeln!(w)?;
    writeln!(w, "| technique | angle | mean error (texels) | p95 | share > 1 texel | mean fetches | max fetches |")?;
    writeln!(w, "|---|--:|--:|--:|--:|--:|--:|")?;
    for r in rows {
        writeln!(
            w,
            "| {} | {}° | {} | {} | {:.1}% | {:.1} | {} |",
            r.technique,
            r.angle_deg,
            round(r.mean_error),
            round(r.p95_error),
            r.share_over_1 * 100.0,
            r.mean_fetches,
            r.max_fetches
        )?;
    }
    Ok(())
}

/// The machine-readable fields of a row, in `CSV_HEADER` order (the JSON keys are the same).
fn fields(r: &AccuracyRow) -> [String; 8] {
    [
        r.technique.to_string(),
        r.angle_deg.to_string(),
        r.rays.to_string(),
        num(r.mean_error),
        num(r.p95_error),
        num(r.share_over_1),
        num(r.mean_fetches),
        r.max_fetches.to_string(),
    ]
}

fn write_csv(w: &mut dyn Write, rows: &[AccuracyRow]) -> std::io::Result<()> {
    writeln!(w, "{CSV_HEADER}")?;
    for r in rows {
        writeln!(w, "{}", fields(r).join(","))?;
    }
    Ok(())
}

/// A JSON number: Rust's shortest round-trip decimal (never exponent notation); `null` for a
/// non-finite value, which the statistics never produce.
fn num(x: f64) -> String {
    if x.is_finite() { format!("{x}") } else { "null".to_owned() }
}

fn write_json(w: &mut dyn Write, rows: &[AccuracyRow]) -> std::io::Result<()> {
    writeln!(w, "[")?;
    for (i, r) in rows.iter().enumerate() {
        // Technique names are plain ASCII words with hyphens: no escaping needed; every other
        // field is a number.
        let pairs: Vec<String> = CSV_HEADER
            .split(',')
            .zip(fields(r))
            .enumerate()
            .map(
                |(k, (key, value))| {
                    if k == 0 { format!("\"{key}\": \"{value}\"") } else { format!("\"{key}\": {value}") }
                },
            )
            .collect();
        write!(w, "  {{{}}}", pairs.join(", "))?;
        writeln!(w, "{}", if i + 1 < rows.len() { "," } else { "" })?;
    }
    writeln!(w, "]")?;
    Ok(())
}

/// A share as a percentage for people: up to three decimals, trailing zeros dropped.
fn percent(x: f64) -> String {
    let s = format!("{:.3}", x * 100.0);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    format!("{s}%")
}

/// The md cell of a search's count: N, or that none up to the cap passed.
fn samples_cell(s: &PomSearch, cap: u32) -> String {
    s.samples().map_or_else(|| format!("not reached at N={cap}"), |n| n.to_string())
}

fn write_yardstick_md(w: &mut dyn Write, setup: &str, rows: &[YardstickRow]) -> std::io::Result<()> {
    let Some(first) = rows.first() else { return Ok(()) };
    let o = first.options;
    let (share, cap, k) = (percent(o.max_share), o.cap, o.refine);
    writeln!(
        w,
        "The honest yardstick on {setup}: the fewest samples N (pom with --min-samples = --max-samples = N, \
         tried from {start} to {cap}) with at most {share} of the rays over one texel from exact's hit, with \
         --refine 0 and --refine {k}, and pom's mean fetches, share over one texel and mean error at that N, \
         beside exact's mean fetches on the same rays; exact / best pom is exact's mean fetches over the fewer \
         of the two pom mean fetches (below 1, exact is cheaper). \"not reached\": no N up to {cap} passed \
         (the columns after it are then pom's at N={cap}).",
        start = o.start
    )?;
    writeln!(w)?;
    writeln!(
        w,
        "| angle | pom N, refine 0 | mean fetches | share > 1 texel | mean error | pom N, refine {k} | mean fetches \
         | share > 1 texel | mean error | exact mean fetches | exact / best pom |"
    )?;
    writeln!(w, "|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")?;
    for r in rows {
        let (p, q) = (r.plain.row(), r.refined.row());
        writeln!(
            w,
            "| {}° | {} | {:.1} | {:.2}% | {} | {} | {:.1} | {:.2}% | {} | {:.1} | {} |",
            r.angle_deg,
            samples_cell(&r.plain, cap),
            p.mean_fetches,
            p.share_over_1 * 100.0,
            round(p.mean_error),
            samples_cell(&r.refined, cap),
            q.mean_fetches,
            q.share_over_1 * 100.0,
            round(q.mean_error),
            r.exact.mean_fetches,
            r.ratio().map_or_else(|| "-".to_owned(), |x| format!("{x:.2}x")),
        )?;
    }
    Ok(())
}

/// The fields of a yardstick row, in `YARDSTICK_HEADER` order; `None` where there is no value.
fn yardstick_fields(r: &YardstickRow) -> Vec<Option<String>> {
    let search = |s: &PomSearch| {
        let row = s.row();
        [
            s.samples().map(|n| n.to_string()),
            Some(num(row.mean_fetches)),
            Some(row.max_fetches.to_string()),
            Some(num(row.share_over_1)),
            Some(num(row.mean_error)),
            Some(num(row.p95_error)),
            s.row_below().map(|b| num(b.share_over_1)),
        ]
    };
    let mut f = vec![
        Some(r.angle_deg.to_string()),
        Some(r.rays.to_string()),
        Some(num(r.options.max_share)),
        Some(r.options.cap.to_string()),
    ];
    f.extend(search(&r.plain));
    f.push(Some(r.refined.refine.to_string()));
    f.extend(search(&r.refined));
    f.extend([Some(num(r.exact.mean_fetches)), Some(r.exact.max_fetches.to_string()), r.ratio().map(num)]);
    f
}

fn write_yardstick_csv(w: &mut dyn Write, rows: &[YardstickRow]) -> std::io::Result<()> {
    writeln!(w, "{YARDSTICK_HEADER}")?;
    for r in rows {
        let f: Vec<String> = yardstick_fields(r).into_iter().map(Option::unwrap_or_default).collect();
        writeln!(w, "{}", f.join(","))?;
    }
    Ok(())
}

fn write_yardstick_json(w: &mut dyn Write, rows: &[YardstickRow]) -> std::io::Result<()> {
    writeln!(w, "[")?;
    for (i, r) in rows.iter().enumerate() {
        // Every field is a number (or null).
        let pairs: Vec<String> = YARDSTICK_HEADER
            .split(',')
            .zip(yardstick_fields(r))
            .map(|(key, value)| format!("\"{key}\": {}", value.as_deref().unwrap_or("null")))
            .collect();
        write!(w, "  {{{}}}", pairs.join(", "))?;
        writeln!(w, "{}", if i + 1 < rows.len() { "," } else { "" })?;
    }
    writeln!(w, "]")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pomkit_core::EdgeMode;
    use pomkit_core::heightfield::HeightField;
    use pomkit_core::trace::{Surface, TraceParams};

    #[test]
    fn yardstick_fields_follow_the_header() {
        let surface = Surface::new(HeightField::constant(16, 16, 0.3), EdgeMode::Wrap, 0.1);
        let options = YardstickOptions::default();
        let rows = accuracy::yardstick(&surface, &[60.0], &TraceParams::default(), 20, 1, &options, &|_| {});
        let fields = yardstick_fields(&rows[0]);
        assert_eq!(fields.len(), YARDSTICK_HEADER.split(',').count());
        // N = 8 passes on a flat plane: nothing below it was tried.
        let keys: Vec<&str> = YARDSTICK_HEADER.split(',').collect();
        let at = |k: &str| fields[keys.iter().position(|&x| x == k).unwrap()].clone();
        assert_eq!(at("pom_samples").as_deref(), Some("8"));
        assert_eq!(at("pom_share_below"), None);
        assert_eq!(at("refine").as_deref(), Some("2"));
        assert_eq!(at("cap").as_deref(), Some("1024"));
        assert_eq!(percent(0.001), "0.1%");
        assert_eq!(percent(0.0005), "0.05%");
        assert_eq!(percent(0.0), "0%");
    }
}
