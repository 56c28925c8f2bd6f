//! `pomkit bake height`: a height map integrated from a tangent-space normal map
//! (pomkit-core's `integrate`), one file; batches go through bake.rs and `pomkit_io::batch` as the other bakes do.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use pomkit_core::integrate::{self, IntegrateOptions};
use pomkit_io::batch::{Baked, Relief};
use pomkit_io::output::Outputs;
use pomkit_io::scene::NormalZ;
use pomkit_io::{PixelLayout, Pixels};

use crate::batch::BatchArgs;
use crate::job::{EdgesArg, HeightReadEncoding, Job, Kind, MethodArg};
use crate::progress;

/// `pomkit bake height NORMAL -o HEIGHT`.
#[derive(Args, Debug)]
pub struct HeightArgs {
    /// Tangent-space normal map: an image file (PNG, JPEG, TIFF: n * 0.5 + 0.5 in RGB, as `bake
    /// normal` writes; EXR: the vectors themselves). Zero, NaN or inward-pointing texels are
    /// refused. Several inputs, folders (their png, jpg, tif and exr files) and quoted globs
    /// integrate a whole library: OUT is then a folder (see --name, --recursive).
    #[arg(value_name = "NORMAL", required = true, num_args = 1..)]
    pub(crate) inputs: Vec<PathBuf>,
    #[command(flatten)]
    pub(crate) batch: BatchArgs,
    /// Output height map (white = high, normalized to [0, 1]): a 16-bit grey PNG, or a float
    /// EXR when the name ends in .exr. With several inputs, a folder (the outputs are PNG
    /// unless --name ends in .exr).
    #[arg(short, long)]
    pub(crate) output: PathBuf,
    /// The map stores +Y down (DirectX) instead of +Y up (OpenGL, glTF), as `bake normal
    /// --y-down` writes.
    #[arg(long)]
    pub(crate) y_down: bool,
    /// How to read z: auto (rebuilt from x and y when blue is 0 everywhere, the `rg8` that `bake
    /// normal` writes; as stored otherwise), rgb8 (as stored) or rg8 (always rebuilt from x and
    /// y, whatever blue holds).
    #[arg(long, value_enum, default_value_t = HeightReadEncoding::Auto)]
    pub(crate) encoding: HeightReadEncoding,
    /// Border texels: wrap (a tiling map: slopes continue across the borders; an FFT solve) or
    /// clamp (no slope across a border; a DCT solve).
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap)]
    pub(crate) edges: EdgesArg,
    /// poisson: plain least squares (one FFT or DCT Poisson solve). weighted: bilateral weights
    /// near steep steps, solved by conjugate gradients preconditioned by the Poisson solve
    /// (docs/ACCURACY.md compares them).
    #[arg(long, value_enum, default_value_t = MethodArg::Poisson)]
    pub(crate) method: MethodArg,
    /// weighted: the most conjugate-gradient iterations, each about one Poisson solve.
    #[arg(long, value_name = "N", default_value_t = integrate::DEFAULT_ITERATIONS,
          value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub(crate) iterations: u32,
}

/// The output's layout, by its extension: float EXR for `.exr`, else 16-bit PNG.
pub(crate) fn layout_for(output: &Path) -> PixelLayout {
    let exr = output.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if exr { PixelLayout::GrayF32 } else { PixelLayout::Gray16 }
}

/// The integration options of a job.
pub(crate) fn options(job: &Job) -> IntegrateOptions {
    let (method, iterations) = match job.kind {
        Kind::Height { method, iterations, .. } => (method, iterations),
        _ => (MethodArg::Poisson, integrate::DEFAULT_ITERATIONS),
    };
    IntegrateOptions { edges: job.slope.edges.into(), method: method.into(), max_iterations: iterations }
}

/// The bytes integrating a `w` x `h` map holds besides the decoded image: the normals (12 a
/// texel), the solve ([`IntegrateOptions::bytes`]) and the output with the encoder's copy (8).
pub(crate) fn bytes(opts: &IntegrateOptions, w: u32, h: u32) -> u64 {
    let n = u64::from(w) * u64::from(h);
    (n * 20).saturating_add(opts.bytes(w, h))
}

/// Integrates the normal map `input` into the height map `output`, atomically; `bars` shows a
/// progress bar for big maps (single mode).
pub(crate) fn bake_height_file(job: &Job, input: &Path, output: &Path, bars: bool) -> Result<Baked> {
    let Kind::Height { encoding, .. } = job.kind else { bail!("internal error: not a height bake") };
    let opts = options(job);
    let shown = input.display();
    if input.to_str().is_some_and(|s| s.starts_with("builtin:")) {
        bail!(
            "{shown} is a height map, not a normal map: bake its normals first (pomkit bake normal {shown} -o \
             normal.png), then integrate them"
        );
    }
    let layout = layout_for(output);
    pomkit_io::check_output(output, layout)?;
    let mut outs = Outputs::new();
    outs.input(input);
    let id = outs.output(output);
    outs.check()?;
    // The whole job against the memory budget before the image is decoded (its decoding is
    // checked from its header by the loader), and again once the normals are held.
    if let Some((w, h, _)) = pomkit_io::read::image_header(input) {
        pomkit_core::memory::check(
            || format!("integrating the {w}x{h} normal map {shown}"),
            bytes(&opts, w, h),
            "integrate a smaller normal map",
        )?;
    }
    let z = match encoding {
        HeightReadEncoding::Rg8 => NormalZ::Rebuilt,
        HeightReadEncoding::Auto | HeightReadEncoding::Rgb8 => NormalZ::Auto,
    };
    let map = pomkit_io::scene::load_normal_map_with(input, job.y_down, z)?;
    let (w, h) = (map.width(), map.height());
    let texels = u64::from(w) * u64::from(h);
    pomkit_core::memory::check_more(
        || format!("integrating the {w}x{h} normal map {shown}"),
        texels * 12,
        bytes(&opts, w, h) - texels * 12,
        "integrate a smaller normal map",
    )?;
    let units = opts.work_units();
    let big = bars && texels.saturating_mul(units) >= 2_000_000;
    let pb = progress::items(units, if big { 0 } else { u64::MAX }, "integrating", "solves");
    let result = integrate::integrate_normals(w, h, map.normals(), &opts, &|n| pb.inc(n));
    pb.finish_and_clear();
    let heights = result.with_context(|| format!("cannot integrate {shown}"))?;
    drop(map);
    let relief = Relief { range: heights.range(), depth_scale: heights.depth_scale() };
    let normalized = heights.normalized();
    drop(heights);
    if layout.is_float() {
        outs.write_image(id, w, h, layout, Pixels::F32(&normalized))?;
    } else {
        let samples: Vec<u16> = normalized.iter().map(|&v| (v * 65535.0).round() as u16).collect();
        outs.write_image(id, w, h, layout, Pixels::U16(&samples))?;
    }
    outs.commit()?;
    Ok(Baked { width: w, height: h, relief: Some(relief) })
}
