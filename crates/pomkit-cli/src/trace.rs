//! `pomkit trace`: rays from a CSV file traced with one technique; hits to a CSV file
//! (DESIGN section 5).

use std::io::Read;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use pomkit_core::glam::{Vec2, Vec3};
use pomkit_core::trace::{Hit, Ray, Surface, Technique, trace};
use rayon::prelude::*;

use crate::technique::{TechniqueArgs, technique_parser};
use crate::{HeightOption, output, progress};

/// The header of a rays file.
pub const RAYS_HEADER: [&str; 5] = ["u", "v", "dx", "dy", "dz"];
/// The header of a hits file.
pub const HITS_HEADER: &str = "u,v,depth,fetches";

/// Rays per unit of parallel work (and per progress step).
const CHUNK: usize = 4096;
/// Fewer rays than this finish in well under a second: no bar.
const MIN_RAYS_FOR_BAR: u64 = 200_000;

#[derive(Args, Debug)]
#[command(after_long_help = "\
Rays file: CSV with the header line `u,v,dx,dy,dz`, then one ray per line: the entry point in \
UV, and the direction of travel along +u, +v and depth (the tangent-space normal), pointing into \
the surface: dz < 0. Directions need not be unit length. Blank lines are skipped.

Hits file: CSV with the header `u,v,depth,fetches`, one line per ray in the same order: the hit \
point in UV (not wrapped into [0, 1]), its depth in [0, 1] (0 = the polygon's surface) and the \
height fetches the technique made.

Rays that do not enter the surface (dz >= 0, or a zero direction) are not errors: every \
technique returns the entry point at depth 0 with 0 fetches. Rays flatter than about 89.94 \
degrees from the normal are steepened to it.")]
pub struct TraceArgs {
    #[command(flatten)]
    height: HeightOption,
    /// How far below the surface, in UV units, the deepest point lies (Bevy's
    /// parallax_depth_scale). Larger values give deeper relief and longer, costlier traces.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true, value_name = "S")]
    depth_scale: f32,
    /// Tracing technique.
    #[arg(long, value_parser = technique_parser(), value_name = "T")]
    technique: Technique,
    /// Rays to trace: CSV with header u,v,dx,dy,dz (see below); `-` reads standard input.
    #[arg(long, value_name = "RAYS.csv")]
    rays: PathBuf,
    /// Where to write the hits: CSV with header u,v,depth,fetches; `-` writes to standard output.
    #[arg(short, long, value_name = "HITS.csv")]
    output: PathBuf,
    #[command(flatten)]
    options: TechniqueArgs,
}

pub fn run(a: &TraceArgs) -> Result<()> {
    let params = a.options.params(a.depth_scale)?;
    output::check_writable(&a.output)?;
    let rays = read_rays(&a.rays)?;
    let field = a.height.load()?;
    let surface = Surface::new(field, params.edges, params.depth_scale);
    let pb = progress::items(rays.len() as u64, MIN_RAYS_FOR_BAR, "tracing", "rays");
    let hits: Vec<Hit> = rays
        .par_chunks(CHUNK)
        .map(|chunk| {
            let hits: Vec<Hit> = chunk.iter().map(|ray| trace(&surface, ray, a.technique, &params)).collect();
            pb.inc(chunk.len() as u64);
            hits
        })
        .flatten_iter()
        .collect();
    pb.finish_and_clear();
    output::write_text(&a.output, |w| {
        writeln!(w, "{HITS_HEADER}")?;
        for h in &hits {
            writeln!(w, "{},{},{},{}", h.uv.x, h.uv.y, h.depth, h.fetches)?;
        }
        Ok(())
    })?;
    if !output::is_stdout(&a.output) {
        eprintln!("wrote {} ({} rays, {})", a.output.display(), hits.len(), a.technique);
    }
    Ok(())
}

/// Reads a rays file (`-`: standard input).
fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    if output::is_stdout(path) {
        let mut text = String::new();
        std::io::stdin().read_to_string(&mut text).context("cannot read rays from standard input")?;
        return parse_rays(&text, "<stdin>");
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot read rays file {}", path.display()))?;
    let text = String::from_utf8(bytes)
        .map_err(|e| anyhow::anyhow!("{}: not UTF-8 text (byte {})", path.display(), e.utf8_error().valid_up_to()))?;
    parse_rays(&text, &path.display().to_string())
}

/// Parses the text of a rays file called `name` (for messages): the header `u,v,dx,dy,dz`, then
/// one ray per line. Blank lines are skipped; every other problem is an error naming the line.
pub fn parse_rays(text: &str, name: &str) -> Result<Vec<Ray>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text.lines().enumerate();
    let expected = RAYS_HEADER.join(",");
    let Some((_, header)) = lines.next() else {
        bail!("{name} is empty: expected the header line {expected}");
    };
    if !header.split(',').map(str::trim).eq(RAYS_HEADER) {
        bail!("{name}: line 1: the header is '{}', expected '{expected}'", header.trim());
    }
    let mut rays = Vec::new();
    for (i, line) in lines {
        let n = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != RAYS_HEADER.len() {
            bail!("{name}: line {n}: expected 5 values ({expected}), found {}", fields.len());
        }
        let mut v = [0.0f32; 5];
        for ((slot, text), column) in v.iter_mut().zip(&fields).zip(RAYS_HEADER) {
            let text = text.trim();
            let x: f32 =
                text.parse().map_err(|_| anyhow::anyhow!("{name}: line {n}: {column} '{text}' is not a number"))?;
            if !x.is_finite() {
                bail!("{name}: line {n}: {column} '{text}' is not finite (values must be finite numbers)");
            }
            *slot = x;
        }
        rays.push(Ray::new(Vec2::new(v[0], v[1]), Vec3::new(v[2], v[3], v[4])));
    }
    Ok(rays)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rays_and_reports_bad_lines() {
        let rays = parse_rays("\u{feff}u, v,dx,dy,dz\r\n0.5,0.25,1,0,-1\r\n\r\n1e-3,2,0,-0.5,-2\n", "r.csv").unwrap();
        assert_eq!(rays.len(), 2);
        assert_eq!(rays[1], Ray::new(Vec2::new(1e-3, 2.0), Vec3::new(0.0, -0.5, -2.0)));
        assert!(parse_rays("u,v,dx,dy,dz\n", "r.csv").unwrap().is_empty());
        let err = |t: &str| parse_rays(t, "r.csv").unwrap_err().to_string();
        assert!(err("").contains("r.csv is empty"));
        assert!(err("u,v,dz\n").contains("line 1"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,0,-1\n0,0,1,-1\n").contains("line 3: expected 5 values"));
        let e = err("u,v,dx,dy,dz\n0,0,0,0,-1\n0,0,x,0,-1\n");
        assert!(e.contains("line 3") && e.contains("dx 'x' is not a number"), "{e}");
        assert!(err("u,v,dx,dy,dz\n0,NaN,0,0,-1\n").contains("line 2: v 'NaN' is not finite"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,1e39,-1\n").contains("dy '1e39' is not finite"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,0,-inf\n").contains("line 2"));
    }
}
