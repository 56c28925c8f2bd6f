//! The technique options shared by `trace`, `compare` and (later) `render` (ARCHITECTURE.md, Stable interfaces),
//! and the parsing of technique names.

use anyhow::{Result, bail};
use clap::Args;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use pomkit_core::trace::{
    MAX_DEPTH_SCALE, MAX_PERSPECTIVE_BIAS, MAX_SAMPLES, MIN_PERSPECTIVE_BIAS, Technique, TraceParamError, TraceParams,
};

use crate::bake::EdgesArg;

/// Options of the tracing techniques. Each applies to the techniques named in its help and is
/// ignored by the others.
#[derive(Args, Debug, Clone)]
#[command(next_help_heading = "Technique options")]
pub struct TechniqueArgs {
    /// pom: fewest samples, taken head-on (1 to 1024; others are clamped). Fewer samples are
    /// cheaper but miss thin features and stair-step.
    #[arg(long, default_value_t = 8, value_name = "N")]
    pub min_samples: u32,
    /// pom: most samples, taken at grazing angles (1 to 1024; others are clamped). At most
    /// N + 1 + refine fetches per ray.
    #[arg(long, default_value_t = 32, value_name = "N")]
    pub max_samples: u32,
    /// steep and relief: depth planes of the linear search (1 to 1024; others are clamped). At
    /// most N fetches, plus relief's binary steps. Fewer planes cost less and stair-step more.
    #[arg(long, default_value_t = 32, value_name = "N")]
    pub samples: u32,
    /// iterative: parallax steps k (1 to 1024; others are clamped), k fetches. More steps settle
    /// better on slopes; no occlusion at any k.
    #[arg(long, default_value_t = 4, value_name = "K")]
    pub iterations: u32,
    /// relief and cone: binary refinement steps after the linear search (relief) or a relaxed
    /// cone step (cone), one fetch each, at most 64.
    #[arg(long, default_value_t = 6, value_name = "K")]
    pub binary_steps: u32,
    /// pom: secant refinement steps after the linear search (one fetch each, at most 64).
    #[arg(long, default_value_t = 0, value_name = "K")]
    pub refine: u32,
    /// pom-classic: Brawley's perspective bias, 0 to 1. 1 gives the exact parallax length;
    /// smaller values shorten the trace toward grazing angles (less shimmer, flatter relief).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_name = "B")]
    pub perspective_bias: f32,
    /// Height map borders: wrap (tiling textures) or clamp.
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap)]
    pub edges: EdgesArg,
}

impl TechniqueArgs {
    /// The trace parameters these options and `depth_scale` (from `--depth-scale`) give,
    /// checked; errors name the flag at fault.
    pub fn params(&self, depth_scale: f32) -> Result<TraceParams> {
        let params = TraceParams {
            depth_scale,
            min_samples: self.min_samples,
            max_samples: self.max_samples,
            samples: self.samples,
            iterations: self.iterations,
            binary_steps: self.binary_steps,
            refine: self.refine,
            perspective_bias: self.perspective_bias,
            edges: self.edges.into(),
            ..TraceParams::default()
        };
        if let Err(e) = params.validate() {
            match e {
                TraceParamError::DepthScale(v) => {
                    bail!(
                        "--depth-scale {v}: the depth scale must be greater than 0 and at most {MAX_DEPTH_SCALE} \
                         (UV units: the deepest point lies at most {MAX_DEPTH_SCALE} tile widths below the \
                         polygon; deeper relief is beyond what parallax mapping can show)"
                    )
                }
                TraceParamError::PerspectiveBias(v) => {
                    bail!(
                        "--perspective-bias {v}: the bias must lie in [{MIN_PERSPECTIVE_BIAS}, \
                         {MAX_PERSPECTIVE_BIAS}] (1 traces the exact parallax length, smaller values \
                         shorten it toward grazing angles)"
                    )
                }
                TraceParamError::SampleBounds { min, max } => {
                    bail!("--min-samples {min} exceeds --max-samples {max}")
                }
                other => bail!("invalid technique options: {other}"),
            }
        }
        Ok(params)
    }
}

/// The list of technique names, for help texts and errors.
pub fn names() -> String {
    Technique::ALL.map(Technique::name).join(", ")
}

/// A clap parser for one technique name, listing the valid ones in help and errors.
pub fn technique_parser() -> impl TypedValueParser<Value = Technique> {
    PossibleValuesParser::new(Technique::ALL.map(Technique::name)).try_map(|s: String| s.parse::<Technique>())
}

/// Parses `all` or a comma-separated list of technique names (duplicates dropped, order kept).
pub fn parse_list(s: &str) -> Result<Vec<Technique>> {
    if s.trim().eq_ignore_ascii_case("all") {
        return Ok(Technique::ALL.to_vec());
    }
    let mut list = Vec::new();
    for part in s.split(',') {
        if part.trim().is_empty() {
            bail!("--techniques '{s}': empty name in the list; expected 'all' or names from: {}", names());
        }
        let t: Technique = part.parse().map_err(|e| anyhow::anyhow!("--techniques: {e}"))?;
        if !list.contains(&t) {
            list.push(t);
        }
    }
    Ok(list)
}

// The help above quotes the clamp and the bias range: keep them true.
const _: () = assert!(MAX_SAMPLES == 1024, "update the sample-count clamp quoted in TechniqueArgs' help");
const _: () = assert!(
    MIN_PERSPECTIVE_BIAS == 0.0 && MAX_PERSPECTIVE_BIAS == 1.0,
    "update the perspective-bias range quoted in TechniqueArgs' help"
);
