//! `pomkit compare`: the accuracy table (ARCHITECTURE.md, Stable interfaces): each technique's error against
//! `exact` and its fetches per ray, per view angle, on a fixed random set of rays.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use pomkit_core::accuracy::{self, AccuracyRow, DEFAULT_SEED};

use crate::technique::{self, TechniqueArgs};
use crate::{HeightOption, output, progress};

/// The CSV header (and the JSON keys) of the table.
pub const CSV_HEADER: &str = "technique,angle,rays,mean_error,p95_error,share_over_1,mean_fetches,max_fetches";

/// Most rays per angle accepted (memory grows with rays x techniques).
const MAX_RAYS: usize = 1_000_000;
/// Fewer rays in all than this finish in about a second: no bar.
const MIN_RAYS_FOR_BAR: u64 = 100_000;

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
p95_error is the nearest-rank 95th percentile.")]
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
    let out = a.output.clone().unwrap_or_else(|| PathBuf::from("-"));
    // Checked before any work; the table appears only when complete, never over the height map.
    let mut outs = pomkit_io::output::Outputs::new();
    for input in a.height.inputs() {
        outs.input(&input);
    }
    let out_id = outs.output(&out);
    outs.check()?;
    let surface = a.height.surface(&a.options, techniques.contains(&pomkit_core::trace::Technique::Cone))?;
    let (w, h) = (surface.field().width(), surface.field().height());
    let pb = progress::items((angles.len() * a.rays) as u64, MIN_RAYS_FOR_BAR, "comparing", "rays");
    let rows = accuracy::compare(&surface, &techniques, &angles, &params, a.rays, a.seed, &|n| pb.inc(n as u64));
    pb.finish_and_clear();
    let edges = surface.edges().name();
    let caption = format!(
        "Error in texels against `exact` on {} ({w}x{h}, depth scale {}, {edges} edges), {} rays per angle, seed {}.",
        a.height.input,
        surface.depth_scale(),
        a.rays,
        a.seed
    );
    outs.write_with(out_id, |wr| {
        match a.format {
            Format::Md => write_md(wr, &caption, &rows),
            Format::Csv => write_csv(wr, &rows),
            Format::Json => write_json(wr, &rows),
        }
        .map_err(anyhow::Error::from)
    })?;
    outs.commit()?;
    if !output::is_stdout(&out) {
        eprintln!("wrote {} ({} rows)", out.display(), rows.len());
    }
    Ok(())
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

// The help above quotes the depth-scale limit: keep it true.
const _: () =
    assert!(pomkit_core::trace::MAX_DEPTH_SCALE == 16.0, "update the depth-scale limit quoted in CompareArgs' help");
