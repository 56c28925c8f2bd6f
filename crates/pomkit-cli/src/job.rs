//! What a bake is, apart from how it runs: the verb and encoding of a bake ([`Kind`]), its
//! per-file options ([`Job`]), and the value enums of the bake verbs' flags. bake.rs (every
//! verb, batches) and bake_height.rs (`bake height`) both build on it, and it on neither.

use clap::{Args, ValueEnum};
use pomkit_core::EdgeMode;
use pomkit_core::bake::{NormalBakeOptions, NormalFilter};
use pomkit_core::cone::ConeMap;
use pomkit_core::integrate::IntegrateMethod;
use pomkit_io::PixelLayout;

use crate::HeightRead;

/// Options shared by every map derived from slopes.
#[derive(Args, Debug, Clone)]
pub struct SlopeArgs {
    /// Lengyel's s: the full height range spans this many texel widths. Larger is steeper; 0
    /// gives flat normals (every texel +Z); a negative scale inverts the relief (reads the map
    /// as depth). At most 1e18 in magnitude, beyond which the normals overflow f32.
    #[arg(long, default_value_t = 8.0, allow_negative_numbers = true)]
    pub(crate) scale: f32,
    /// Slope filter: central differences (sharp) or the 3x3 Sobel operator (smoother).
    #[arg(long, value_enum, default_value_t = FilterArg::Central)]
    pub(crate) filter: FilterArg,
    /// Border texels: wrap (tiling textures) or clamp.
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap)]
    pub(crate) edges: EdgesArg,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterArg {
    Central,
    Sobel,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
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
    pub(crate) fn options(&self, y_down: bool) -> NormalBakeOptions {
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

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormalEncoding {
    Rgb8,
    Rg8,
    Float,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParallaxEncoding {
    R8,
    Float,
}

/// Where z comes from (`--encoding`).
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeightReadEncoding {
    Auto,
    Rgb8,
    Rg8,
}

/// `--method`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodArg {
    Poisson,
    Weighted,
}

impl From<MethodArg> for IntegrateMethod {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Poisson => IntegrateMethod::Poisson,
            MethodArg::Weighted => IntegrateMethod::Weighted,
        }
    }
}

/// What to bake from one height map: the verb and its per-file options (the command line's,
/// or a batch config's overrides of them).
#[derive(Clone, Debug)]
pub(crate) struct Job {
    /// Which map, in which encoding.
    pub(crate) kind: Kind,
    /// Slope scale, filter and edges.
    pub(crate) slope: SlopeArgs,
    /// Store +Y down (normal and pack).
    pub(crate) y_down: bool,
    /// How to read the height map.
    pub(crate) read: HeightRead,
}

/// A bake verb and its encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// `bake normal`.
    Normal(NormalEncoding),
    /// `bake parallax`.
    Parallax(ParallaxEncoding),
    /// `bake pack`.
    Pack,
    /// `bake maxmip`.
    Maxmip,
    /// `bake cone`, conservative or relaxed.
    Cone {
        /// Relaxed cones (`--relaxed`).
        relaxed: bool,
    },
    /// `bake height`: how the normal map is read and integrated.
    Height {
        /// Where z comes from.
        encoding: HeightReadEncoding,
        /// The solve.
        method: MethodArg,
        /// The weighted solve's iteration bound.
        iterations: u32,
    },
}

impl Kind {
    /// The verb's name.
    pub(crate) fn verb(self) -> &'static str {
        match self {
            Kind::Normal(_) => "normal",
            Kind::Parallax(_) => "parallax",
            Kind::Pack => "pack",
            Kind::Maxmip => "maxmip",
            Kind::Cone { .. } => "cone",
            Kind::Height { .. } => "height",
        }
    }

    /// The pixel layout written.
    pub(crate) fn layout(self) -> PixelLayout {
        match self {
            Kind::Normal(NormalEncoding::Rgb8 | NormalEncoding::Rg8) => PixelLayout::Rgb8,
            Kind::Normal(NormalEncoding::Float) => PixelLayout::RgbF32,
            Kind::Parallax(ParallaxEncoding::R8) => PixelLayout::Gray8,
            Kind::Parallax(ParallaxEncoding::Float) => PixelLayout::GrayF32,
            Kind::Pack => PixelLayout::Rgba8,
            Kind::Maxmip => PixelLayout::Gray16,
            Kind::Cone { .. } => PixelLayout::GrayAlpha16,
            // A float EXR when the output's name asks for one (bake_height::layout_for).
            Kind::Height { .. } => PixelLayout::Gray16,
        }
    }

    /// What baking a `w` x `h` map makes, for messages, and an upper bound on the bytes it
    /// allocates besides the height field: the output, the encoder's copy, and the pyramid or
    /// the cones being built.
    pub(crate) fn job(self, w: u32, h: u32) -> (String, u64) {
        let n = u64::from(w) * u64::from(h);
        match self {
            Kind::Normal(NormalEncoding::Rgb8 | NormalEncoding::Rg8) => {
                (format!("a normal map of a {w}x{h} map"), n * 6)
            }
            Kind::Normal(NormalEncoding::Float) => (format!("a float normal map of a {w}x{h} map"), n * 24),
            Kind::Parallax(_) => (format!("a parallax map of a {w}x{h} map"), n * 9),
            Kind::Pack => (format!("a packed map of a {w}x{h} map"), n * 8),
            // The pyramid (4/3 of the texels in f32) and its atlas (1.5 times the texels in
            // u16, and the encoder's copy).
            Kind::Maxmip => (format!("the maximum-height pyramid of a {w}x{h} map"), n * 12),
            Kind::Cone { .. } => (format!("the cone map of a {w}x{h} map"), ConeMap::build_bytes(w, h)),
            Kind::Height { .. } => (format!("the heights of a {w}x{h} normal map"), n * 64),
        }
    }

    /// The output file's extension.
    pub(crate) fn extension(self) -> &'static str {
        if self.layout().is_float() { "exr" } else { "png" }
    }
}
