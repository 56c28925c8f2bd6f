//! `pomkit bake normal|parallax|pack|maxmip|cone`: maps baked from a height map; `bake height`
//! (bake_height.rs): a height map integrated from a normal map. A batch (several inputs, folders,
//! globs) runs through [`pomkit_io::batch`], with the per-file options of a `--config` file
//! ([`Rules`]) and the memory estimate of each file decided here.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, Subcommand, ValueEnum};
use pomkit_core::bake::{self, NormalBakeOptions};
use pomkit_core::cone::ConeMap;
use pomkit_core::{HeightField, MaxHeightPyramid};
use pomkit_io::Pixels;
use pomkit_io::batch::{Baked, Baker, Item};
use pomkit_io::output::{OutputId, Outputs};

use crate::bake_height::{self, HeightArgs};
use crate::batch::{self, BatchArgs};
use crate::job::{EdgesArg, FilterArg, HeightReadEncoding, Job, Kind, NormalEncoding, ParallaxEncoding, SlopeArgs};
use crate::{ChannelArg, HeightRead, progress};

#[derive(Subcommand, Debug)]
pub enum BakeVerb {
    /// Tangent-space normal map by central differences or Sobel (Lengyel 7.41-7.43).
    Normal(NormalArgs),
    /// Lengyel's parallax map n_z * (2h - 1), signed (eq. 7.51).
    Parallax(ParallaxArgs),
    /// Normal in RGB and height (white = high) in alpha, as one RGBA8 PNG.
    Pack(PackArgs),
    /// The maximum-height pyramid (what `exact` walks) as one 16-bit grey PNG: level 0 on the
    /// left, the coarser levels stacked to its right; each cell the greatest height of the
    /// bilinear surface over it, rounded up.
    Maxmip(MapArgs),
    /// Cone map (Dummer 2006, robust to the bilinear surface) as a 16-bit grey + alpha PNG: grey
    /// the top of each texel footprint as a height, alpha sqrt(cone ratio / shorter side in
    /// texels). Conservative cones, or relaxed ones with --relaxed.
    Cone(ConeArgs),
    /// Height map integrated from a tangent-space normal map (least squares: an FFT or DCT
    /// Poisson solve, or a weighted one near steep steps), normalized to [0, 1], with the depth
    /// the normals imply (height range in texel widths, and as a depth_scale).
    Height(HeightArgs),
}

/// The height maps to bake and how to read them.
#[derive(Args, Debug)]
pub struct BakeInputs {
    /// Height map: an image file (PNG, JPEG, TIFF, EXR; 8/16-bit or float), or `builtin:NAME`
    /// for a procedural one (bricks, pyramids, cobblestones, text, spike, waves, fur, grass), optionally
    /// sized as `builtin:NAME:WxH` (default 512x512). Several inputs, folders (their png, jpg,
    /// tif and exr files) and quoted globs bake a whole library: OUT is then a folder (see
    /// --name, --recursive). A FIFO (named pipe) is read once a program writes to it: pomkit
    /// waits 10 s for one to open it, then gives up.
    #[arg(value_name = "IN", required = true, num_args = 1..)]
    pub(crate) inputs: Vec<PathBuf>,
    #[command(flatten)]
    pub(crate) read: HeightRead,
    #[command(flatten)]
    pub(crate) batch: BatchArgs,
}

#[derive(Args, Debug)]
pub struct NormalArgs {
    #[command(flatten)]
    input: BakeInputs,
    /// Output file: PNG for rgb8 and rg8, EXR for float. With several inputs, a folder.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    slope: SlopeArgs,
    /// rgb8: n * 0.5 + 0.5 in RGB. rg8: x and y only (blue 0; z = sqrt(1 - x^2 - y^2) on read,
    /// eq. 7.44). float: 32-bit RGB EXR holding n itself.
    #[arg(long, value_enum, default_value_t = NormalEncoding::Rgb8)]
    encoding: NormalEncoding,
    /// Store +Y down (DirectX) instead of +Y up (OpenGL, glTF).
    #[arg(long)]
    y_down: bool,
}

#[derive(Args, Debug)]
pub struct ParallaxArgs {
    #[command(flatten)]
    input: BakeInputs,
    /// Output file: PNG for r8, EXR for float. With several inputs, a folder.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    slope: SlopeArgs,
    /// r8: the signed value v in [-1, 1] stored as round((v * 0.5 + 0.5) * 255) in grey (read
    /// back as c * 2 - 1). float: 32-bit EXR holding v itself.
    #[arg(long, value_enum, default_value_t = ParallaxEncoding::R8)]
    encoding: ParallaxEncoding,
}

#[derive(Args, Debug)]
pub struct PackArgs {
    #[command(flatten)]
    input: BakeInputs,
    /// Output RGBA PNG. With several inputs, a folder.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    slope: SlopeArgs,
    /// Store +Y down (DirectX) instead of +Y up (OpenGL, glTF).
    #[arg(long)]
    y_down: bool,
}

/// `bake maxmip` and `bake cone`: maps of the bilinear surface itself.
#[derive(Args, Debug)]
pub struct MapArgs {
    #[command(flatten)]
    input: BakeInputs,
    /// Output PNG. With several inputs, a folder.
    #[arg(short, long)]
    output: PathBuf,
    /// Border texels: wrap (tiling textures) or clamp. Decides the surface between the border
    /// texels and, for cones, which relief lies beyond the edge.
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap)]
    edges: EdgesArg,
}

/// `bake cone`: [`MapArgs`] and the kind of cones.
#[derive(Args, Debug)]
pub struct ConeArgs {
    #[command(flatten)]
    map: MapArgs,
    /// Relaxed cones (Policarpo and Oliveira 2007), built exactly for the bilinear surface: a ray
    /// from the top plane over a texel crosses the surface at most once inside its cone. Wider
    /// than conservative cones where relief faces the texel (1.27 times on cobblestones, the
    /// median); a tracer must look after each step. Without it: conservative cones, which hold
    /// no surface at all.
    #[arg(long)]
    relaxed: bool,
}

impl MapArgs {
    /// The slope options a [`Job`] carries: only the edges matter to these maps.
    fn slope(&self) -> SlopeArgs {
        SlopeArgs { scale: 8.0, filter: FilterArg::Central, edges: self.edges }
    }
}

pub fn run(verb: &BakeVerb) -> Result<()> {
    if let BakeVerb::Height(a) = verb {
        let job = Job {
            kind: Kind::Height { encoding: a.encoding, method: a.method, iterations: a.iterations },
            slope: SlopeArgs { scale: 8.0, filter: FilterArg::Central, edges: a.edges },
            y_down: a.y_down,
            read: crate::HeightRead { depth_map: false, channel: crate::ChannelArg::Luma, normalize: false },
        };
        if batch::is_batch(&a.inputs, &a.batch) {
            return run_batch(&job, &a.inputs, &a.batch, &a.output);
        }
        let baked = bake_file(&job, &a.inputs[0], &a.output, true)?;
        let (w, h) = (baked.width, baked.height);
        let opts = crate::bake_height::options(&job);
        eprintln!(
            "wrote {} ({w}x{h} height map, {}, {} edges)",
            a.output.display(),
            opts.method.name(),
            opts.edges.name()
        );
        if let Some(r) = baked.relief {
            eprintln!(
                "relief: {:.4} texel widths from lowest to highest; depth_scale {:.6} (the range over the width, in UV \
                 units)",
                r.range, r.depth_scale
            );
        }
        return Ok(());
    }
    let (job, inputs, output) = match verb {
        BakeVerb::Normal(a) => (
            Job {
                kind: Kind::Normal(a.encoding),
                slope: a.slope.clone(),
                y_down: a.y_down,
                read: a.input.read.clone(),
            },
            &a.input,
            &a.output,
        ),
        BakeVerb::Parallax(a) => (
            Job { kind: Kind::Parallax(a.encoding), slope: a.slope.clone(), y_down: false, read: a.input.read.clone() },
            &a.input,
            &a.output,
        ),
        BakeVerb::Pack(a) => (
            Job { kind: Kind::Pack, slope: a.slope.clone(), y_down: a.y_down, read: a.input.read.clone() },
            &a.input,
            &a.output,
        ),
        BakeVerb::Maxmip(a) => (
            Job { kind: Kind::Maxmip, slope: a.slope(), y_down: false, read: a.input.read.clone() },
            &a.input,
            &a.output,
        ),
        BakeVerb::Cone(a) => (
            Job {
                kind: Kind::Cone { relaxed: a.relaxed },
                slope: a.map.slope(),
                y_down: false,
                read: a.map.input.read.clone(),
            },
            &a.map.input,
            &a.map.output,
        ),
        BakeVerb::Height(_) => unreachable!("handled above"),
    };
    if batch::is_batch(&inputs.inputs, &inputs.batch) {
        return run_batch(&job, &inputs.inputs, &inputs.batch, output);
    }
    let Baked { width: w, height: h, .. } = bake_file(&job, &inputs.inputs[0], output, true)?;
    match job.kind {
        Kind::Normal(encoding) => {
            eprintln!("wrote {} ({w}x{h} normal map, {encoding:?}, scale {})", output.display(), job.slope.scale);
        }
        Kind::Parallax(encoding) => eprintln!("wrote {} ({w}x{h} parallax map, {encoding:?})", output.display()),
        Kind::Pack => eprintln!("wrote {} ({w}x{h} normal + height map)", output.display()),
        Kind::Maxmip => eprintln!("wrote {} (maximum-height pyramid of a {w}x{h} map)", output.display()),
        Kind::Cone { relaxed } => {
            let kind = if relaxed { "relaxed" } else { "conservative" };
            eprintln!("wrote {} ({w}x{h} {kind} cone map)", output.display());
        }
        Kind::Height { .. } => {}
    }
    Ok(())
}

/// Checks the output and the options, then loads the input, before any heavy work, so a bad
/// flag or output fails fast. The output is staged in the returned [`Outputs`] (which refuses
/// to overwrite the input) and appears only when the caller commits it.
fn prepare(
    input: &Path,
    read: &HeightRead,
    opts: &NormalBakeOptions,
    output: &Path,
    kind: Kind,
) -> Result<(HeightField, Outputs, OutputId)> {
    let layout = kind.layout();
    pomkit_io::check_output(output, layout)?;
    if !(opts.scale.is_finite() && opts.scale.abs() <= bake::MAX_SCALE) {
        anyhow::bail!(
            "--scale {}: the scale must be a finite number of texel widths from -{max:e} to {max:e} (beyond \
             that the normals overflow f32)",
            pomkit_core::scene::short_number(opts.scale),
            max = bake::MAX_SCALE
        );
    }
    let mut outs = Outputs::new();
    if !input.to_str().is_some_and(|s| s.starts_with("builtin:")) {
        outs.input(input);
    }
    let id = outs.output(output);
    outs.check()?;
    // The whole bake against the memory budget before a built-in map is generated; an image
    // file's reading is checked from its header before it is decoded, and the bake once it is
    // read (docs/LIMITS.md).
    let builtin = input.to_str().filter(|s| s.starts_with("builtin:"));
    let shown = input.display();
    if let Some(spec) = builtin
        && let Some((w, h)) = pomkit_io::scene::texture_size(Path::new("."), spec)
    {
        let (what, bytes) = kind.job(w, h);
        pomkit_core::memory::check(
            || format!("baking {what} ({shown})"),
            bytes.saturating_add(crate::height_load_bytes(true, w, h)),
            "bake a smaller height map",
        )?;
    }
    let field = crate::load_height(input, read)?;
    if builtin.is_none() {
        // On top of the height field, now held (4 bytes a texel): against a fixed budget the
        // two add up, as they did in the peak (the field is about a tenth of a cone bake's).
        let (what, bytes) = kind.job(field.width(), field.height());
        let held = pomkit_core::memory::bytes_of::<f32>(field.depths().len() as u64);
        pomkit_core::memory::check_more(
            || format!("baking {what} ({shown})"),
            held,
            bytes,
            "bake a smaller height map",
        )?;
    }
    opts.validate(&field).with_context(|| format!("cannot bake {shown}"))?;
    Ok((field, outs, id))
}

/// The output's `n` texels, allocated fallibly: an estimate that was too low ends in an error
/// naming the input, not in the allocator's abort (docs/LIMITS.md).
fn output_buffer<T: Clone>(value: T, n: usize, input: &Path) -> Result<Vec<T>> {
    pomkit_core::memory::try_vec(value, n).map_err(|e| {
        anyhow::Error::from(pomkit_core::memory::MemoryError::Allocation {
            what: format!("the baked map of {}", input.display()),
            bytes: pomkit_core::memory::bytes_of::<T>(n as u64),
            reason: e.to_string(),
            advice: "bake a smaller height map".to_owned(),
        })
    })
}

/// Bakes `job` from the height map `input` into `output`, atomically; `bars` shows progress
/// bars for big maps (single mode; a batch shows its own). Returns the map's size.
pub(crate) fn bake_file(job: &Job, input: &Path, output: &Path, bars: bool) -> Result<Baked> {
    if let Kind::Height { .. } = job.kind {
        return crate::bake_height::bake_height_file(job, input, output, bars);
    }
    let opts = job.slope.options(job.y_down);
    let layout = job.kind.layout();
    let (field, mut outs, id) = prepare(input, &job.read, &opts, output, job.kind)?;
    let (w, h) = (field.width(), field.height());
    // A cone costs many texels' worth of a normal map: its bar shows for smaller maps.
    let weight = if matches!(job.kind, Kind::Cone { .. }) { crate::CONE_TEXEL_WEIGHT } else { 1 };
    let pb = if bars {
        progress::bar(u64::from(h), u64::from(w) * u64::from(weight), "baking")
    } else {
        indicatif::ProgressBar::hidden()
    };
    let tick = |rows: u32| pb.inc(u64::from(rows));
    match job.kind {
        Kind::Normal(encoding @ (NormalEncoding::Rgb8 | NormalEncoding::Rg8)) => {
            let mut px = output_buffer([0u8; 3], field.depths().len(), input)?;
            bake::bake_normals_rgb8(&field, &opts, &mut px, &tick)?;
            if encoding == NormalEncoding::Rg8 {
                // Two-channel storage: z is rebuilt on read (eq. 7.44), blue carries nothing.
                px.iter_mut().for_each(|p| p[2] = 0);
            }
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::U8(px.as_flattened()))?;
        }
        Kind::Normal(NormalEncoding::Float) => {
            let mut px = output_buffer([0.0f32; 3], field.depths().len(), input)?;
            bake::bake_normals_into(&field, &opts, &mut px, |n| n.to_array(), &tick)?;
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::F32(px.as_flattened()))?;
        }
        Kind::Parallax(encoding) => {
            let values = bake::bake_parallax(&field, &opts)?;
            match encoding {
                ParallaxEncoding::R8 => {
                    let px: Vec<u8> = values.iter().map(|&v| ((v * 0.5 + 0.5) * 255.0).round() as u8).collect();
                    outs.write_image(id, w, h, layout, Pixels::U8(&px))?;
                }
                ParallaxEncoding::Float => outs.write_image(id, w, h, layout, Pixels::F32(&values))?,
            }
        }
        Kind::Pack => {
            let px = bake::bake_packed_rgba8(&field, &opts, &tick)?;
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::U8(px.as_flattened()))?;
        }
        Kind::Maxmip => {
            // The pyramid (4/3 of the texels in f32) and its atlas (1.5 times the texels in
            // u16, and the encoder's copy).
            let needed = u64::from(w) * u64::from(h) * 12;
            pomkit_core::memory::check(
                || format!("the maximum-height pyramid of a {w}x{h} map"),
                needed,
                "bake a smaller height map",
            )?;
            // No rows to count: a spinner, so a big map does not look like a hang.
            let texels = if bars { u64::from(w) * u64::from(h) } else { 0 };
            let (pyramid, atlas) = progress::spinner(texels, "building the pyramid", || {
                let pyramid = MaxHeightPyramid::new(&field, opts.edges);
                let atlas = pyramid.atlas_gray16();
                (pyramid, atlas)
            });
            let (aw, ah) = pyramid.atlas_size();
            drop(pyramid);
            progress::spinner(texels, "encoding", || outs.write_image(id, aw, ah, layout, Pixels::U16(&atlas)))?;
        }
        Kind::Cone { relaxed } => {
            pomkit_core::memory::check(
                || format!("the cone map of a {w}x{h} map"),
                ConeMap::build_bytes(w, h),
                "bake a smaller height map",
            )?;
            let cones = if relaxed {
                ConeMap::relaxed_with_progress(&field, opts.edges, &tick)
            } else {
                ConeMap::conservative_with_progress(&field, opts.edges, &tick)
            };
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::U16(&cones.to_gray_alpha16()))?;
        }
        Kind::Height { .. } => unreachable!("bake_height_file"),
    }
    outs.commit()?;
    Ok(Baked { width: w, height: h, relief: None })
}

// ---------------------------------------------------------------------------------------------
// Batches (pomkit_io::batch)
// ---------------------------------------------------------------------------------------------

/// Bakes a batch: `job` for every file, with the `--config` rules that match it applied.
fn run_batch(job: &Job, inputs: &[PathBuf], args: &BatchArgs, out: &Path) -> Result<()> {
    let template = batch::template(args, default_template(job.kind))?;
    let rules = match &args.config {
        Some(path) => Rules::load(path)?,
        None => Rules::default(),
    };
    let baker = BatchBaker { job, rules };
    batch::run(&baker, inputs, args, out, template, (job.kind.verb(), matches!(job.kind, Kind::Height { .. })))
}

/// What a batch bakes: the command line's job, with the config's rules.
struct BatchBaker<'a> {
    job: &'a Job,
    rules: Rules,
}

impl Baker for BatchBaker<'_> {
    type Job = Job;

    fn job(&self, item: &Item) -> Job {
        self.rules.apply(self.job, item)
    }

    fn extension(&self, job: &Job) -> &'static str {
        job.kind.extension()
    }

    fn estimate(&self, job: &Job, item: &Item) -> u64 {
        estimate(job, item)
    }

    fn describe(&self, item: &Item) -> String {
        describe(item)
    }

    fn bake(&self, job: &Job, input: &Path, output: &Path) -> Result<Baked, String> {
        bake_file(job, input, output, false).map_err(|e| format!("{e:#}"))
    }
}

/// The output name of a batch's files when `--name` is not given.
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

/// The width and height of an item's height map: a built-in's size, or an image file's header;
/// `None` when it cannot be told before reading.
fn dimensions(item: &Item) -> Option<(u32, u32, u64)> {
    if item.input.to_str().is_some_and(|s| s.starts_with("builtin:")) {
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
        Kind::Height { .. } => bake_height::bytes(&bake_height::options(job), w, h).saturating_sub(texels * 8),
    };
    decoded.saturating_add(texels * 8).saturating_add(map)
}

fn describe(item: &Item) -> String {
    match dimensions(item) {
        Some((w, h, _)) => format!("baking {} ({w}x{h})", item.input.display()),
        None => format!("baking {}", item.input.display()),
    }
}

/// One checked rule.
struct Rule {
    /// The file names it applies to (`match`).
    pattern: Option<glob::Pattern>,
    /// The folder it applies to.
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
            if !item.matches(rule.pattern.as_ref(), rule.folder.as_deref()) {
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
    T::from_str(s, true).map(Some).map_err(|_| anyhow!("{}: '{s}' is not one of {}", what(), names::<T>().join(", ")))
}
