//! `pomkit bake normal|parallax|pack`: maps baked from a height map.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use pomkit_core::bake::{self, NormalBakeOptions, NormalFilter};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_io::output::{OutputId, Outputs};
use pomkit_io::{PixelLayout, Pixels};

use crate::HeightInput;
use crate::progress;

#[derive(Subcommand, Debug)]
pub enum BakeVerb {
    /// Tangent-space normal map by central differences or Sobel (Lengyel 7.41-7.43).
    Normal(NormalArgs),
    /// Lengyel's parallax map n_z * (2h - 1), signed (eq. 7.51).
    Parallax(ParallaxArgs),
    /// Normal in RGB and height (white = high) in alpha, as one RGBA8 PNG.
    Pack(PackArgs),
}

/// Options shared by every map derived from slopes.
#[derive(Args, Debug, Clone)]
pub struct SlopeArgs {
    /// Lengyel's s: the full height range spans this many texel widths. Larger is steeper; 0
    /// gives flat normals (every texel +Z); a negative scale inverts the relief (reads the map
    /// as depth). At most 1e18 in magnitude, beyond which the normals overflow f32.
    #[arg(long, default_value_t = 8.0, allow_negative_numbers = true)]
    scale: f32,
    /// Slope filter: central differences (sharp) or the 3x3 Sobel operator (smoother).
    #[arg(long, value_enum, default_value_t = FilterArg::Central)]
    filter: FilterArg,
    /// Border texels: wrap (tiling textures) or clamp.
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap)]
    edges: EdgesArg,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum FilterArg {
    Central,
    Sobel,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum EdgesArg {
    Wrap,
    Clamp,
}

impl From<EdgesArg> for EdgeMode {
    fn from(e: EdgesArg) -> Self {
        match e {
            EdgesArg::Wrap => EdgeMode::Wrap,
            EdgesArg::Clamp => EdgeMode::Clamp,
        }
    }
}

impl SlopeArgs {
    fn options(&self, y_down: bool) -> NormalBakeOptions {
        NormalBakeOptions {
            scale: self.scale,
            filter: match self.filter {
                FilterArg::Central => NormalFilter::Central,
                FilterArg::Sobel => NormalFilter::Sobel,
            },
            edges: self.edges.into(),
            y_down,
        }
    }
}

#[derive(Args, Debug)]
pub struct NormalArgs {
    #[command(flatten)]
    input: HeightInput,
    /// Output file: PNG for rgb8 and rg8, EXR for float.
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

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormalEncoding {
    Rgb8,
    Rg8,
    Float,
}

#[derive(Args, Debug)]
pub struct ParallaxArgs {
    #[command(flatten)]
    input: HeightInput,
    /// Output file: PNG for r8, EXR for float.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    slope: SlopeArgs,
    /// r8: the signed value v in [-1, 1] stored as round((v * 0.5 + 0.5) * 255) in grey (read
    /// back as c * 2 - 1). float: 32-bit EXR holding v itself.
    #[arg(long, value_enum, default_value_t = ParallaxEncoding::R8)]
    encoding: ParallaxEncoding,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParallaxEncoding {
    R8,
    Float,
}

#[derive(Args, Debug)]
pub struct PackArgs {
    #[command(flatten)]
    input: HeightInput,
    /// Output RGBA PNG.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    slope: SlopeArgs,
    /// Store +Y down (DirectX) instead of +Y up (OpenGL, glTF).
    #[arg(long)]
    y_down: bool,
}

pub fn run(verb: &BakeVerb) -> Result<()> {
    match verb {
        BakeVerb::Normal(a) => normal(a),
        BakeVerb::Parallax(a) => parallax(a),
        BakeVerb::Pack(a) => pack(a),
    }
}

/// Checks the output and the options, then loads the input, before any heavy work, so a bad
/// flag or output fails fast. The output is staged in the returned [`Outputs`] (which refuses
/// to overwrite the input) and appears only when the caller commits it.
fn prepare(
    input: &HeightInput,
    opts: &NormalBakeOptions,
    output: &Path,
    layout: PixelLayout,
) -> Result<(HeightField, Outputs, OutputId)> {
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
    if !input.input.starts_with("builtin:") {
        outs.input(&input.input);
    }
    let id = outs.output(output);
    outs.check()?;
    let field = input.load()?;
    opts.validate(&field).with_context(|| format!("cannot bake {}", input.input))?;
    Ok((field, outs, id))
}

fn normal(a: &NormalArgs) -> Result<()> {
    let opts = a.slope.options(a.y_down);
    let layout = match a.encoding {
        NormalEncoding::Rgb8 | NormalEncoding::Rg8 => PixelLayout::Rgb8,
        NormalEncoding::Float => PixelLayout::RgbF32,
    };
    let (field, mut outs, id) = prepare(&a.input, &opts, &a.output, layout)?;
    let (w, h) = (field.width(), field.height());
    let pb = progress::bar(u64::from(h), u64::from(w), "baking");
    let tick = |rows: u32| pb.inc(u64::from(rows));
    match a.encoding {
        NormalEncoding::Rgb8 | NormalEncoding::Rg8 => {
            let mut px = vec![[0u8; 3]; field.depths().len()];
            bake::bake_normals_rgb8(&field, &opts, &mut px, &tick)?;
            if a.encoding == NormalEncoding::Rg8 {
                // Two-channel storage: z is rebuilt on read (eq. 7.44), blue carries nothing.
                px.iter_mut().for_each(|p| p[2] = 0);
            }
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::U8(px.as_flattened()))?;
        }
        NormalEncoding::Float => {
            let mut px = vec![[0.0f32; 3]; field.depths().len()];
            bake::bake_normals_into(&field, &opts, &mut px, |n| n.to_array(), &tick)?;
            pb.finish_and_clear();
            outs.write_image(id, w, h, layout, Pixels::F32(px.as_flattened()))?;
        }
    }
    outs.commit()?;
    eprintln!("wrote {} ({w}x{h} normal map, {:?}, scale {})", a.output.display(), a.encoding, opts.scale);
    Ok(())
}

fn parallax(a: &ParallaxArgs) -> Result<()> {
    let opts = a.slope.options(false);
    let layout = match a.encoding {
        ParallaxEncoding::R8 => PixelLayout::Gray8,
        ParallaxEncoding::Float => PixelLayout::GrayF32,
    };
    let (field, mut outs, id) = prepare(&a.input, &opts, &a.output, layout)?;
    let (w, h) = (field.width(), field.height());
    let values = bake::bake_parallax(&field, &opts)?;
    match a.encoding {
        ParallaxEncoding::R8 => {
            let px: Vec<u8> = values.iter().map(|&v| ((v * 0.5 + 0.5) * 255.0).round() as u8).collect();
            outs.write_image(id, w, h, layout, Pixels::U8(&px))?;
        }
        ParallaxEncoding::Float => outs.write_image(id, w, h, layout, Pixels::F32(&values))?,
    }
    outs.commit()?;
    eprintln!("wrote {} ({w}x{h} parallax map, {:?})", a.output.display(), a.encoding);
    Ok(())
}

fn pack(a: &PackArgs) -> Result<()> {
    let opts = a.slope.options(a.y_down);
    let (field, mut outs, id) = prepare(&a.input, &opts, &a.output, PixelLayout::Rgba8)?;
    let (w, h) = (field.width(), field.height());
    let pb = progress::bar(u64::from(h), u64::from(w), "baking");
    let px = bake::bake_packed_rgba8(&field, &opts, &|rows| pb.inc(u64::from(rows)))?;
    pb.finish_and_clear();
    outs.write_image(id, w, h, PixelLayout::Rgba8, Pixels::U8(px.as_flattened()))?;
    outs.commit()?;
    eprintln!("wrote {} ({w}x{h} normal + height map)", a.output.display());
    Ok(())
}
