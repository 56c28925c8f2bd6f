//! `pomkit trace`: rays from a CSV file traced with one technique; hits to a CSV file
//! (ARCHITECTURE.md, Stable interfaces).

use std::io::{BufRead, BufReader};
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use pomkit_core::trace::{Hit, Ray, Technique, trace};
use pomkit_io::output::Outputs;
use pomkit_io::rays::RayReader;
use rayon::prelude::*;

use crate::technique::{TechniqueArgs, technique_parser};
use crate::{HeightOption, output, progress};

/// The header of a hits file.
pub const HITS_HEADER: &str = "u,v,depth,fetches";

/// Rays per unit of parallel work.
const CHUNK: usize = 4096;
/// Rays read, traced and written at a time: bounds the memory of a stream of any length.
const BATCH: usize = 64 * CHUNK;
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
degrees from the normal are steepened to it.

Rays are streamed: read, traced and written in batches, so any number of rays takes bounded \
memory. A line longer than 4096 bytes or holding a NUL byte is an error naming the line.

Output: the hits file appears only when the whole run succeeds (it is written to a temporary \
file beside it and renamed into place), so a bad line anywhere leaves no file. It may not be the \
rays file or the height map (through any path or link); a read-only file is refused; a symbolic \
link is written through (the file it points to is replaced, the link stays); a device such as \
/dev/null is written in place; to standard output (`-o -`) hits are written as they are traced. \
Write errors, a full disk or standard output included, fail the run.")]
pub struct TraceArgs {
    #[command(flatten)]
    height: HeightOption,
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
    let params = a.options.params()?;
    if let Some(path) = &a.height.cone_map
        && a.technique != Technique::Cone
    {
        eprintln!(
            "warning: --cone-map {}: only the cone technique uses a cone map, not {}",
            path.display(),
            a.technique
        );
    }
    // Every output is checked before any work, and never one of the inputs.
    let mut outs = Outputs::new();
    outs.input(&a.rays);
    for input in a.height.inputs() {
        outs.input(&input);
    }
    let out = outs.output(&a.output);
    outs.check()?;
    let (reader, name): (Box<dyn BufRead>, String) = if output::is_stdout(&a.rays) {
        (Box::new(std::io::stdin().lock()), "<stdin>".to_owned())
    } else {
        let file = pomkit_io::read::open_input(&a.rays)
            .with_context(|| format!("cannot read rays file {}", a.rays.display()))?;
        (Box::new(BufReader::new(file)), a.rays.display().to_string())
    };
    let mut rays = RayReader::new(reader, &name)?;
    let surface = a.height.surface(&a.options, a.technique == Technique::Cone)?;
    let mut counter = progress::Counter::new(MIN_RAYS_FOR_BAR, "tracing", "rays");
    let mut count = 0u64;
    // Streamed: a batch of rays is read, traced in parallel and written, then the next, so
    // memory stays bounded for any number of rays. A bad line stops the run, and the staged
    // output is then dropped: nothing is written.
    outs.write_with(out, |w| -> Result<()> {
        writeln!(w, "{HITS_HEADER}")?;
        let mut batch: Vec<Ray> = Vec::with_capacity(BATCH);
        loop {
            batch.clear();
            for ray in rays.by_ref().take(BATCH) {
                batch.push(ray?);
            }
            if batch.is_empty() {
                break;
            }
            let hits: Vec<Hit> = batch
                .par_chunks(CHUNK)
                .flat_map_iter(|chunk| chunk.iter().map(|ray| trace(&surface, ray, a.technique, &params)))
                .collect();
            for h in &hits {
                writeln!(w, "{},{},{},{}", h.uv.x, h.uv.y, h.depth, h.fetches)?;
            }
            count += hits.len() as u64;
            counter.inc(hits.len() as u64);
        }
        Ok(())
    })?;
    counter.finish();
    outs.commit()?;
    if !output::is_stdout(&a.output) {
        eprintln!("wrote {} ({count} rays, {})", a.output.display(), a.technique);
    }
    Ok(())
}
