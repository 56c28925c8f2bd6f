//! `pomkit`: the command line. Thin: every verb parses its flags, calls pomkit-core and
//! pomkit-io, and reports. The flag names and formats are stable (ARCHITECTURE.md, Stable interfaces).

mod backend;
mod bake;
mod bake_height;
mod batch;
mod bench;
mod compare;
mod gltf;
mod interrupt;
mod job;
mod library;
mod output;
mod progress;
mod render;
mod technique;
mod trace;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use pomkit_core::HeightField;
use pomkit_core::procedural::{self, Pattern};
use pomkit_io::{Channel, HeightLoadOptions, PixelLayout, Pixels};

/// Parallax occlusion mapping toolkit: bake maps from height maps, trace, compare and render.
#[derive(Parser, Debug)]
#[command(name = "pomkit", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand, Debug)]
enum Verb {
    /// Render a scene (or, with none, the built-in demo scene) to a PNG, on the GPU or the CPU.
    Render(render::RenderArgs),
    /// Bake normal, parallax, packed, maximum-height or cone maps from a height map, or a height
    /// map from a normal map (normal, parallax, pack, maxmip, cone, height).
    #[command(subcommand)]
    Bake(bake::BakeVerb),
    /// Write one of the built-in procedural height maps (and optionally its colour map).
    Generate(GenerateArgs),
    /// Trace rays read from a CSV file with one technique; write where they hit.
    Trace(trace::TraceArgs),
    /// The accuracy table: each technique's error against `exact`, and its fetches, per view angle.
    Compare(compare::CompareArgs),
    /// Time whole frames of the demo scene per technique, on the GPU and the CPU (see --help).
    Bench(bench::BenchArgs),
    /// The interactive viewer: tune a height map and its technique on the GPU renderer.
    View(ViewArgs),
    /// glTF files: `attach` puts a height map into a material (KHR_materials_displacement).
    #[command(subcommand)]
    Gltf(gltf::GltfVerb),
}

/// `pomkit view [SCENE] [--screenshot OUT.png]`.
#[derive(Args, Debug)]
struct ViewArgs {
    /// Scene file to open (TOML; see docs/SCENES.md). Without one, the viewer restores the last
    /// session, or opens a plane of built-in bricks.
    scene: Option<PathBuf>,
    /// Open the window, render until the view is complete, save the whole window to this PNG
    /// and exit (for tests and documentation). The saved session is neither read nor changed.
    #[arg(long, value_name = "OUT.png")]
    screenshot: Option<PathBuf>,
    /// Start in a split view: the material's technique on the left, this one on the right
    /// (flat, normal, parallax, iterative, steep, pom-classic, pom, relief, exact, cone).
    #[arg(long, value_name = "TECHNIQUE")]
    compare: Option<String>,
    /// Start with an overlay: none, fetches (heat map of height fetches per pixel), lod-tint,
    /// shadow (the light's visibility) or depth (hit depth).
    #[arg(long, value_name = "NAME")]
    overlay: Option<String>,
    /// A texture-library folder to open (its maps found by name, as `render --material`), as a
    /// scene of one plane whose material's `folder` is DIR; the panel then tunes it. Not with
    /// a scene file.
    #[arg(long, value_name = "DIR", conflicts_with = "scene")]
    material: Option<PathBuf>,
}

#[cfg(feature = "view")]
fn view(args: &ViewArgs) -> Result<()> {
    let compare =
        args.compare.as_deref().map(str::parse::<pomkit_core::trace::Technique>).transpose().context("--compare")?;
    let overlay = args
        .overlay
        .as_deref()
        .map(str::parse::<pomkit_viewer::view::Overlay>)
        .transpose()
        .map_err(anyhow::Error::msg)
        .context("--overlay")?;
    // A texture-library folder: its maps listed (and checked) before the window opens.
    if let Some(dir) = &args.material {
        library::Folder::open(dir)?;
    }
    pomkit_viewer::run(pomkit_viewer::ViewerOptions {
        scene: args.scene.clone().or_else(|| args.material.clone()),
        screenshot: args.screenshot.clone(),
        compare,
        overlay,
        ..Default::default()
    })?;
    if let Some(p) = &args.screenshot {
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

/// `pomkit view` in a build without the viewer.
#[cfg(not(feature = "view"))]
fn view(_args: &ViewArgs) -> Result<()> {
    anyhow::bail!(
        "this pomkit was built without the viewer (the `view` feature, on by default): reinstall it without --no-default-features to use `pomkit view`"
    )
}

/// Building a texel's cone costs about as much as baking 16 texels of a normal map: the weight
/// of a cone build in the progress bars' "long enough for a bar" rule.
pub(crate) const CONE_TEXEL_WEIGHT: u32 = 16;

/// Where a height map comes from and how to read it, as `--height H` (`trace`, `compare`).
#[derive(Args, Debug, Clone)]
pub(crate) struct HeightOption {
    /// Height map: an image file (PNG, JPEG, TIFF, EXR; 8/16-bit or float), or `builtin:NAME`
    /// for a procedural one (bricks, pyramids, cobblestones, text, spike, waves, fur, grass), optionally
    /// sized as `builtin:NAME:WxH` (default 512x512).
    #[arg(long = "height", value_name = "H")]
    pub(crate) input: String,
    #[command(flatten)]
    read: HeightRead,
    /// cone: a cone map baked from this height map with the same --edges (`pomkit bake cone`),
    /// stepped on as relaxed cones (a look after each step). Without it, `cone` builds the
    /// conservative cones itself (about 1.5 s for 512x512 on two cores).
    #[arg(long, value_name = "CONE.png")]
    pub(crate) cone_map: Option<PathBuf>,
}

/// How to read a height map: shared by every verb that reads one.
#[derive(Args, Debug, Clone)]
pub(crate) struct HeightRead {
    /// The image stores depth (white = deep) instead of height (white = high).
    #[arg(long)]
    pub(crate) depth_map: bool,
    /// Channel holding the height: r, g, b, a (e.g. a normal map with height in alpha) or luma
    /// (Rec. 709 weights; the grey value of a grey image).
    #[arg(long, value_enum, default_value_t = ChannelArg::Luma)]
    pub(crate) channel: ChannelArg,
    /// Rescale values so the lowest becomes 0 and the highest 1 (for float maps in world units).
    #[arg(long)]
    pub(crate) normalize: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ChannelArg {
    R,
    G,
    B,
    A,
    Luma,
}

impl From<ChannelArg> for Channel {
    fn from(c: ChannelArg) -> Self {
        match c {
            ChannelArg::R => Channel::R,
            ChannelArg::G => Channel::G,
            ChannelArg::B => Channel::B,
            ChannelArg::A => Channel::A,
            ChannelArg::Luma => Channel::Luma,
        }
    }
}

impl HeightOption {
    /// Loads the height field this option names.
    pub(crate) fn load(&self) -> Result<HeightField> {
        load_height(Path::new(&self.input), &self.read)
    }

    /// The files this option reads (for the output checks: no output may be one of them).
    pub(crate) fn inputs(&self) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = self.cone_map.iter().cloned().collect();
        if !self.input.starts_with("builtin:") {
            files.push(PathBuf::from(&self.input));
        }
        files
    }

    /// The height field prepared for tracing at the depth scale and with the edges of
    /// `options` (checked by [`technique::TechniqueArgs::params`]), with the cone map of
    /// `--cone-map` when one is given, or else, when `cones` (the `cone` technique will run),
    /// the cones built here under a progress bar.
    pub(crate) fn surface(
        &self,
        options: &technique::TechniqueArgs,
        cones: bool,
    ) -> Result<pomkit_core::trace::Surface> {
        let field = self.load()?;
        let (w, h) = (field.width(), field.height());
        let edges = options.edges();
        let mut surface = pomkit_core::trace::Surface::new(field, edges, options.depth_scale);
        if let Some(path) = &self.cone_map {
            let cones = pomkit_io::load_cone_map(path, w, h, edges)?;
            surface.set_cones(cones).with_context(|| format!("--cone-map {}", path.display()))?;
        } else if cones {
            let built = progress::rows(
                h,
                w.saturating_mul(CONE_TEXEL_WEIGHT),
                &format!("building the cones of {w}x{h}"),
                |tick| pomkit_core::cone::ConeMap::conservative_with_progress(surface.field(), edges, tick),
            );
            surface.set_cones(built).context("internal error: cones of another size")?;
        }
        Ok(surface)
    }
}

/// Loads the height field `input` names (a file or `builtin:NAME[:WxH]`), read as `read` says.
pub(crate) fn load_height(input: &Path, read: &HeightRead) -> Result<HeightField> {
    if let Some(spec) = input.to_str().and_then(|s| s.strip_prefix("builtin:")) {
        let input = input.display();
        // As scene files do (docs/SCENES.md): these flags say how to read an image's values, and
        // a built-in map has none to read (a negative --scale inverts a baked relief).
        if read.depth_map {
            bail!("--depth-map describes how to read a height image: it does not apply to {input}");
        }
        if read.channel != ChannelArg::Luma {
            let channel = Channel::from(read.channel);
            bail!("--channel {channel} describes how to read a height image: it does not apply to {input}");
        }
        if read.normalize {
            bail!("--normalize describes how to read a height image: it does not apply to {input}");
        }
        let (name, size) = spec.split_once(':').unwrap_or((spec, "512x512"));
        let pattern: Pattern = name.parse().with_context(|| format!("input {input}"))?;
        let (w, h) = parse_size(size).with_context(|| format!("input {input}"))?;
        pomkit_core::memory::check(
            || format!("generating {input}"),
            height_load_bytes(true, w, h),
            "use a smaller size (builtin:NAME:WxH)",
        )?;
        return Ok(progress::rows(h, w, &format!("generating {name} {w}x{h}"), |tick| {
            procedural::generate_with_progress(pattern, w, h, tick)
        }));
    }
    let opts = HeightLoadOptions { depth_map: read.depth_map, channel: read.channel.into(), normalize: read.normalize };
    Ok(pomkit_io::load_height_field(input, &opts)?)
}

/// The bytes loading a height map of `w` x `h` takes: a built-in's (`builtin`) values as it is
/// generated and its field (16 bytes a texel, with room for the generator's own copy), or a
/// file's field (its decoded pixels are checked as it is read).
pub(crate) fn height_load_bytes(builtin: bool, w: u32, h: u32) -> u64 {
    let n = u64::from(w) * u64::from(h);
    if builtin { n * 16 } else { n * 4 }
}

/// Parses `WxH` with both sides in 1..=[`pomkit_core::MAX_SIZE`] (16384).
fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("size '{s}' is not WxH, e.g. 512x512"))?;
    let parse = |v: &str| -> Result<u32> {
        let n: u32 = v.trim().parse().with_context(|| format!("size '{s}': '{v}' is not a whole number"))?;
        if !(1..=pomkit_core::MAX_SIZE).contains(&n) {
            bail!("size '{s}': each side must be between 1 and {}", pomkit_core::MAX_SIZE);
        }
        Ok(n)
    };
    Ok((parse(w)?, parse(h)?))
}

#[derive(Args, Debug)]
struct GenerateArgs {
    /// bricks, pyramids, cobblestones, text, spike, waves, fur or grass.
    pattern: String,
    /// Output height map (16-bit grey PNG, white = high). The outputs appear only when the whole
    /// run succeeds and may not be read-only; a symbolic link is written through (the file it
    /// points to is replaced, the link stays).
    #[arg(short, long)]
    output: PathBuf,
    /// Size in texels.
    #[arg(long, default_value = "512x512")]
    size: String,
    /// Also write the matching colour map (RGB8 PNG) here.
    #[arg(long)]
    albedo: Option<PathBuf>,
}

fn generate(args: &GenerateArgs) -> Result<()> {
    let pattern: Pattern = args.pattern.parse()?;
    let (w, h) = parse_size(&args.size)?;
    // Every output is checked before the work and appears only when both are written.
    pomkit_io::check_output(&args.output, PixelLayout::Gray16)?;
    let mut outs = pomkit_io::output::Outputs::new();
    let height_out = outs.output(&args.output);
    let albedo_out = args.albedo.as_ref().map(|path| outs.output(path));
    if let Some(path) = &args.albedo {
        pomkit_io::check_output(path, PixelLayout::Rgb8)?;
    }
    outs.check()?;
    let what = format!("{} {w}x{h}", pattern.name());
    // Before the work: the values and the field (8 bytes a texel), the 16-bit samples and the
    // encoder's copy (4), and the colour map's texels and copy (6).
    let texels = u64::from(w) * u64::from(h);
    let needed = texels * (8 + 4) + if args.albedo.is_some() { texels * 6 } else { 0 };
    pomkit_core::memory::check(|| format!("generating {what}"), needed, "use a smaller --size")?;
    let field =
        progress::rows(h, w, &format!("height {what}"), |tick| procedural::generate_with_progress(pattern, w, h, tick));
    let samples: Vec<u16> = field.heights().iter().map(|&v| (v * 65535.0).round() as u16).collect();
    drop(field);
    progress::spinner(u64::from(w) * u64::from(h), "encoding", || {
        outs.write_image(height_out, w, h, PixelLayout::Gray16, Pixels::U16(&samples))
    })?;
    drop(samples);
    if let Some(id) = albedo_out {
        let rgb = progress::rows(h, w, &format!("colour {what}"), |tick| {
            procedural::albedo_with_progress(pattern, w, h, tick)
        });
        progress::spinner(u64::from(w) * u64::from(h), "encoding", || {
            outs.write_image(id, w, h, PixelLayout::Rgb8, Pixels::U8(rgb.as_flattened()))
        })?;
    }
    outs.commit()?;
    eprintln!("wrote {} ({w}x{h} height map, {})", args.output.display(), pattern.name());
    if let Some(path) = &args.albedo {
        eprintln!("wrote {} (colour map)", path.display());
    }
    Ok(())
}

/// Mesa's runtime-directory warning silenced (`pomkit_gpu::util::ensure_runtime_dir`).
#[expect(
    unsafe_code,
    reason = "ensure_runtime_dir sets an environment variable, unsafe in Rust 2024 because another thread \
              may read the environment concurrently; this runs first thing in main, before pomkit or any \
              library starts a thread"
)]
fn ensure_runtime_dir() {
    // SAFETY: single-threaded at this point (see the reason above).
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
}

fn main() -> ExitCode {
    ensure_runtime_dir();
    let cli = Cli::parse();
    // The memory budget's variable (POMKIT_MEMORY_LIMIT): a value that is not a size is bad
    // input, reported as such before any file is read (docs/LIMITS.md).
    if let Err(e) = pomkit_core::memory::available_bytes() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    // Ctrl-C and SIGTERM remove staged outputs and exit 130 or 143 (docs/LIMITS.md, "Outputs").
    interrupt::install();
    // The CPU renderer's SIMD level (POMKIT_SIMD): a value it does not know is bad input.
    if let Err(e) = pomkit_cpu::Simd8::from_env() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let result = match &cli.verb {
        Verb::Render(args) => render::run(args),
        Verb::Bake(verb) => bake::run(verb),
        Verb::Generate(args) => generate(args),
        Verb::Trace(args) => trace::run(args),
        Verb::Compare(args) => compare::run(args),
        Verb::Bench(args) => bench::run(args),
        Verb::View(args) => view(args),
        Verb::Gltf(verb) => gltf::run(verb),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(all(test, not(feature = "view")))]
mod headless {
    #[test]
    fn view_without_the_viewer_says_how_to_get_it() {
        let args = super::ViewArgs { scene: None, screenshot: None, compare: None, overlay: None, material: None };
        let err = super::view(&args).unwrap_err().to_string();
        assert!(err.contains("without the viewer") && err.contains("--no-default-features"), "{err}");
    }
}
