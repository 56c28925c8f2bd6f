//! The technique options shared by `trace` and `compare` (ARCHITECTURE.md, Stable interfaces),
//! and the parsing of technique names (`trace`, `compare`, `bench`). `render` parses its own
//! `--technique` and `--compare`, which also accept `displaced` (render.rs).

use anyhow::{Result, bail};
use clap::Args;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use pomkit_core::EdgeMode;
use pomkit_core::params;
use pomkit_core::trace::{
    MAX_DEPTH_SCALE, MAX_PERSPECTIVE_BIAS, MIN_PERSPECTIVE_BIAS, Technique, TraceParamError, TraceParams,
    check_depth_scale,
};

use crate::job::EdgesArg;

/// Options of the tracing techniques. Each applies to the techniques named in its help and is
/// ignored by the others. Defaults and help come from the parameter table
/// (`pomkit_core::params`), as scene files' keys do.
#[derive(Args, Debug, Clone)]
#[command(next_help_heading = "Technique options")]
pub struct TechniqueArgs {
    // Bevy calls it parallax_depth_scale.
    #[arg(
        long,
        default_value_t = params::DEPTH_SCALE.default.f32(),
        help = params::DEPTH_SCALE.help(),
        allow_negative_numbers = true,
        value_name = "S"
    )]
    pub depth_scale: f32,
    #[arg(long, default_value_t = params::MIN_SAMPLES.default.u32(), help = params::MIN_SAMPLES.help(), value_name = "N")]
    pub min_samples: u32,
    #[arg(long, default_value_t = params::MAX_SAMPLES.default.u32(), help = params::MAX_SAMPLES.help(), value_name = "N")]
    pub max_samples: u32,
    #[arg(long, default_value_t = params::SAMPLES.default.u32(), help = params::SAMPLES.help(), value_name = "N")]
    pub samples: u32,
    #[arg(long, default_value_t = params::ITERATIONS.default.u32(), help = params::ITERATIONS.help(), value_name = "K")]
    pub iterations: u32,
    #[arg(long, default_value_t = params::BINARY_STEPS.default.u32(), help = params::BINARY_STEPS.help(), value_name = "K")]
    pub binary_steps: u32,
    #[arg(long, default_value_t = params::REFINE.default.u32(), help = params::REFINE.help(), value_name = "K")]
    pub refine: u32,
    #[arg(
        long,
        default_value_t = params::PERSPECTIVE_BIAS.default.f32(),
        help = params::PERSPECTIVE_BIAS.help(),
        allow_negative_numbers = true,
        value_name = "B"
    )]
    pub perspective_bias: f32,
    #[arg(long, value_enum, default_value_t = EdgesArg::Wrap, help = params::EDGES.help())]
    pub edges: EdgesArg,
}

impl TechniqueArgs {
    /// The trace parameters these options give, checked with `--depth-scale`; errors name the
    /// flag at fault. The depth scale and the edge mode are the surface's
    /// ([`crate::HeightOption::surface`]).
    pub fn params(&self) -> Result<TraceParams> {
        let params = TraceParams {
            min_samples: self.min_samples,
            max_samples: self.max_samples,
            samples: self.samples,
            iterations: self.iterations,
            binary_steps: self.binary_steps,
            refine: self.refine,
            perspective_bias: self.perspective_bias,
            ..TraceParams::default()
        };
        if let Err(e) = check_depth_scale(self.depth_scale).and_then(|()| params.validate()) {
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

    /// `--edges`.
    pub fn edges(&self) -> EdgeMode {
        self.edges.into()
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

#[cfg(test)]
mod tests {
    use clap::CommandFactory;
    use pomkit_core::params::{self, Value};

    /// Every flag of `trace` and `compare` that sets a material parameter is in the parameter
    /// table with the table's default, and every table parameter with a flag has it.
    #[test]
    fn the_flags_are_the_parameter_tables() {
        let cli = crate::Cli::command();
        for verb in ["trace", "compare"] {
            let cmd = cli.find_subcommand(verb).unwrap();
            for p in params::all() {
                let Some(flag) = p.flag else { continue };
                let arg = cmd
                    .get_arguments()
                    .find(|a| a.get_long() == flag.strip_prefix("--"))
                    .unwrap_or_else(|| panic!("{verb} has no {flag} ({})", p.key));
                let default = arg.get_default_values().first().and_then(|d| d.to_str()).unwrap_or_default();
                let same = match p.default {
                    Value::Float(x) => default.parse::<f64>().is_ok_and(|d| (d - x).abs() < 1e-6),
                    Value::Int(n) => default.parse::<i64>() == Ok(n),
                    Value::Name(name) => default == name,
                    other => panic!("{}: a flag for {other:?}", p.key),
                };
                assert!(same, "{verb} {flag}: default {default:?}, the table's {:?}", p.default);
            }
            // The other way: technique options not in the table would be a second source.
            let table: Vec<&str> = params::all().filter_map(|p| p.flag?.strip_prefix("--")).collect();
            for arg in cmd.get_arguments().filter(|a| a.get_help_heading() == Some("Technique options")) {
                let long = arg.get_long().unwrap_or_default();
                assert!(table.contains(&long), "{verb} --{long} is a technique option missing from the table");
            }
        }
    }
}
