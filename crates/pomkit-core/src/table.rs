//! The parameter table itself, published as [`crate::params`] (whose page describes it).
//!
//! It imports only [`crate::modes`] (the technique and shadow choices its rows name), so the
//! tracer, the shadows and the scene read their defaults from it without a cycle; the one
//! function that reads a [`Material`](crate::scene::Material), [`value_of`](crate::params::value_of), is in
//! `params`.

use crate::modes::{self, MAX_DEPTH_SCALE, MAX_PERSPECTIVE_BIAS, MIN_PERSPECTIVE_BIAS, ShadowMode, Technique};

/// A parameter's value: what a scene file writes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// A number.
    Float(f64),
    /// A whole number.
    Int(i64),
    /// On or off.
    Bool(bool),
    /// One of a [`Kind::Choice`]'s names.
    Name(&'static str),
    /// A linear RGB colour.
    Color([f64; 3]),
}

impl Value {
    /// The number (a whole number too), for defaults known to be numbers.
    ///
    /// # Panics
    /// In const evaluation only, when the value is not a number (a build error then).
    #[must_use]
    pub const fn f32(self) -> f32 {
        match self {
            Value::Float(x) => x as f32,
            Value::Int(n) => n as f32,
            _ => panic!("not a number"),
        }
    }

    /// The whole number, for defaults known to be whole numbers.
    ///
    /// # Panics
    /// In const evaluation only, when the value is not a non-negative whole number.
    #[must_use]
    pub const fn u32(self) -> u32 {
        match self {
            Value::Int(n) if n >= 0 && n <= u32::MAX as i64 => n as u32,
            _ => panic!("not a non-negative whole number"),
        }
    }

    /// The flag, for defaults known to be flags.
    ///
    /// # Panics
    /// In const evaluation only, when the value is not a flag.
    #[must_use]
    pub const fn bool(self) -> bool {
        match self {
            Value::Bool(b) => b,
            _ => panic!("not a flag"),
        }
    }

    /// The colour, for defaults known to be colours.
    ///
    /// # Panics
    /// In const evaluation only, when the value is not a colour.
    #[must_use]
    pub const fn color(self) -> [f32; 3] {
        match self {
            Value::Color([r, g, b]) => [r as f32, g as f32, b as f32],
            _ => panic!("not a colour"),
        }
    }

    /// The value as a scene file (TOML) writes it: `0.1`, `8`, `true`, `"pom"`, `[0.8, 0.8, 0.8]`.
    #[must_use]
    pub fn toml(&self) -> String {
        let num = |x: f64| if x.fract() == 0.0 && x.abs() < 1e15 { format!("{x:.1}") } else { format!("{x}") };
        match *self {
            Value::Float(x) => num(x),
            Value::Int(n) => n.to_string(),
            Value::Bool(b) => b.to_string(),
            Value::Name(s) => format!("{s:?}"),
            Value::Color(c) => format!("[{}, {}, {}]", num(c[0]), num(c[1]), num(c[2])),
        }
    }
}

/// A parameter's type, its valid range and the range its slider offers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A finite number at least `min` (greater than `min` when `min_exclusive`) and at most
    /// `max` (`f64::INFINITY`: no bound). Values outside are refused.
    Float {
        /// Smallest valid value.
        min: f64,
        /// `min` itself is refused.
        min_exclusive: bool,
        /// Largest valid value.
        max: f64,
        /// The slider's range (the useful values; a file may hold any valid one).
        slider: (f64, f64),
        /// Logarithmic slider.
        log: bool,
    },
    /// A whole number from `min` to `max`; values outside are clamped when tracing (0 and
    /// counts above the most are not errors: a trace cannot run away).
    Int {
        /// Smallest value used.
        min: i64,
        /// Largest value used.
        max: i64,
        /// The slider's range.
        slider: (i64, i64),
    },
    /// On or off.
    Bool,
    /// One of these names.
    Choice(&'static [&'static str]),
    /// Linear RGB, every component at least 0.
    Color,
}

impl Kind {
    /// The type and range in words, for docs and help: "number in (0, 16]", "whole number 1
    /// to 1024, others clamped", "wrap or clamp".
    #[must_use]
    pub fn describe(&self) -> String {
        match *self {
            Kind::Float { min, min_exclusive, max, .. } => {
                let open = if min_exclusive { "(" } else { "[" };
                if max.is_infinite() {
                    if min_exclusive { format!("number > {min}") } else { format!("number >= {min}") }
                } else {
                    format!("number in {open}{min}, {max}]")
                }
            }
            Kind::Int { min, max, .. } => format!("whole number {min} to {max}, others clamped"),
            Kind::Bool => "true or false".to_owned(),
            Kind::Choice(names) => match names.split_last() {
                Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
                _ => names.join(", "),
            },
            Kind::Color => "linear RGB, each >= 0".to_owned(),
        }
    }

    /// Whether `v` is of this kind and in range (an integer counts as a number).
    #[must_use]
    pub fn accepts(&self, v: &Value) -> bool {
        // A whole number is a number where one is expected.
        let v = match (*self, *v) {
            (Kind::Float { .. }, Value::Int(n)) => Value::Float(n as f64),
            (_, v) => v,
        };
        match (*self, v) {
            (Kind::Float { min, min_exclusive, max, .. }, Value::Float(x)) => {
                x.is_finite() && (if min_exclusive { x > min } else { x >= min }) && x <= max
            }
            (Kind::Int { .. }, Value::Int(_)) | (Kind::Bool, Value::Bool(_)) => true,
            (Kind::Choice(names), Value::Name(s)) => names.contains(&s),
            (Kind::Color, Value::Color(c)) => c.iter().all(|x| x.is_finite() && *x >= 0.0),
            _ => false,
        }
    }
}

/// Which materials a parameter affects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Uses {
    /// Every material.
    Always,
    /// Materials with a height map.
    HeightMap,
    /// Materials whose height map is an image file (it says how to read the file).
    HeightFile,
    /// Materials with a normal-map file.
    NormalFile,
    /// Materials with a height map drawn with one of `techniques` or self-shadowed with one of
    /// `shadows`.
    Some {
        /// The techniques that read it.
        techniques: &'static [Technique],
        /// The shadow modes that read it.
        shadows: &'static [ShadowMode],
    },
}

/// What [`Param::applies`] needs to know of a material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setting {
    /// Its technique.
    pub technique: Technique,
    /// Its shadow mode.
    pub shadow: ShadowMode,
    /// It has a height map.
    pub height: bool,
    /// Its height map is an image file (not a built-in one).
    pub height_file: bool,
    /// It has a normal-map file.
    pub normal_file: bool,
}

impl Uses {
    /// Who uses the parameter, in words: "every material", "pom; hard and soft shadows".
    #[must_use]
    pub fn describe(&self) -> String {
        match *self {
            Uses::Always => "every material".to_owned(),
            Uses::HeightMap => "materials with a height map".to_owned(),
            Uses::HeightFile => "height map files".to_owned(),
            Uses::NormalFile => "normal map files".to_owned(),
            Uses::Some { techniques, shadows } => {
                let and = |names: Vec<&str>| match names.split_last() {
                    Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
                    _ => names.join(""),
                };
                let mut parts = Vec::new();
                if techniques.len() == DISPLACING.len() {
                    parts.push("every displacing technique".to_owned());
                } else if !techniques.is_empty() {
                    parts.push(and(techniques.iter().map(|t| t.name()).collect()));
                }
                if !shadows.is_empty() {
                    parts.push(format!("{} shadows", and(shadows.iter().map(|s| s.name()).collect())));
                }
                parts.join("; ")
            }
        }
    }
}

/// One material parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Param {
    /// The scene file's key.
    pub key: &'static str,
    /// The viewer's label.
    pub label: &'static str,
    /// Type and range.
    pub kind: Kind,
    /// The value when the scene file leaves the key out.
    pub default: Value,
    /// What it does, in one line.
    pub doc: &'static str,
    /// More, for tooltips (may be empty).
    pub details: &'static str,
    /// Which materials it affects.
    pub uses: Uses,
    /// The flag of `pomkit trace` and `pomkit compare`, if any.
    pub flag: Option<&'static str>,
    /// The member of the library's `PomkitParams` uniform that carries it, if any.
    pub uniform: Option<&'static str>,
}

impl Param {
    /// Whether the parameter affects the picture of a material set as `s`, and if not, why.
    ///
    /// # Errors
    /// A short reason ("used by relief and cone") when it has no effect.
    pub fn applies(&self, s: &Setting) -> Result<(), String> {
        let by = || format!("used by {}", self.uses.describe());
        match self.uses {
            Uses::Always => Ok(()),
            _ if !s.height && !matches!(self.uses, Uses::NormalFile) => Err("needs a height map".to_owned()),
            Uses::HeightMap => Ok(()),
            Uses::HeightFile if !s.height_file => {
                Err("describes how to read a height image file, not a built-in map".to_owned())
            }
            Uses::HeightFile => Ok(()),
            Uses::NormalFile if !s.normal_file => {
                Err("needs a normal map file (without one, it is baked from the height)".to_owned())
            }
            Uses::NormalFile => Ok(()),
            Uses::Some { techniques, shadows } => {
                if techniques.contains(&s.technique) || shadows.contains(&s.shadow) {
                    Ok(())
                } else if !shadows.is_empty() && s.shadow == ShadowMode::Depth {
                    Err(format!("{}; depth shadows darken by depth alone and trace no light ray", by()))
                } else {
                    Err(by())
                }
            }
        }
    }

    /// Whether the key says how to read an input image (it acts when loading and is not kept in
    /// the [`Material`](crate::scene::Material)).
    #[must_use]
    pub fn reads_input(&self) -> bool {
        matches!(self.uses, Uses::HeightFile | Uses::NormalFile)
    }

    /// The command line's help: the doc, who uses it and the range.
    #[must_use]
    pub fn help(&self) -> String {
        format!("{} ({}; {}).", self.doc, self.uses.describe(), self.kind.describe())
    }

    /// The tooltip: the doc, the details and who uses it.
    #[must_use]
    pub fn tooltip(&self) -> String {
        let mut s = format!("{}.", self.doc);
        if !self.details.is_empty() {
            s.push('\n');
            s.push_str(self.details);
        }
        s.push_str(&format!("\nUsed by {}. Default {}.", self.uses.describe(), self.default.toml()));
        s
    }
}

const fn technique_names() -> [&'static str; Technique::ALL.len()] {
    let mut names = [""; Technique::ALL.len()];
    let mut i = 0;
    while i < names.len() {
        names[i] = Technique::ALL[i].name();
        i += 1;
    }
    names
}

const fn shadow_names() -> [&'static str; ShadowMode::ALL.len()] {
    let mut names = [""; ShadowMode::ALL.len()];
    let mut i = 0;
    while i < names.len() {
        names[i] = ShadowMode::ALL[i].name();
        i += 1;
    }
    names
}

const TECHNIQUE_NAMES: [&str; Technique::ALL.len()] = technique_names();
const SHADOW_NAMES: [&str; ShadowMode::ALL.len()] = shadow_names();

/// The techniques that displace the texture coordinate ([`Technique::displaces`]: all but flat
/// and normal), in [`Technique::ALL`]'s order.
pub const DISPLACING: [Technique; 8] = {
    let mut out = [Technique::Flat; 8];
    let (mut i, mut n) = (0, 0);
    while i < Technique::ALL.len() {
        if Technique::ALL[i].displaces() {
            out[n] = Technique::ALL[i];
            n += 1;
        }
        i += 1;
    }
    assert!(n == out.len(), "DISPLACING's length is the number of displacing techniques");
    out
};

/// The most samples a count parameter may ask for ([`MAX_SAMPLES`](crate::trace::MAX_SAMPLES)).
const SAMPLE_LIMIT: i64 = modes::MAX_SAMPLES as i64;

/// `technique`.
pub const TECHNIQUE: Param = Param {
    key: "technique",
    label: "Technique",
    kind: Kind::Choice(&TECHNIQUE_NAMES),
    default: Value::Name("exact"),
    doc: "How the surface is displaced",
    details: "flat: plain texturing. normal: normal mapping only.\n\
              parallax: one-sample offset with offset limiting (Kaneko 2001, Welsh 2004).\n\
              iterative: Lengyel's iterative parallax, `iterations` steps.\n\
              steep: steep parallax (McGuire 2005), `samples` depth planes.\n\
              pom-classic: Brawley & Tatarchuk 2004, 8 samples and the perspective bias.\n\
              pom: parallax occlusion mapping (Tatarchuk 2006): adaptive samples, early exit, \
              piecewise-linear intersection, optional secant refinement.\n\
              relief: relief mapping (Policarpo 2005): linear then binary search.\n\
              exact: the exact first hit on the bilinear height surface (max-height pyramid); never \
              misses a feature.\n\
              cone: cone stepping (Dummer 2006) on cones that hold for the bilinear surface, solving \
              the patches where the cones cannot skip: exact's hits for fewer fetches.",
    uses: Uses::Always,
    flag: None,
    uniform: Some("technique"),
};

/// `depth_scale`.
pub const DEPTH_SCALE: Param = Param {
    key: "depth_scale",
    label: "Depth scale",
    kind: Kind::Float { min: 0.0, min_exclusive: true, max: MAX_DEPTH_SCALE as f64, slider: (0.002, 0.3), log: true },
    default: Value::Float(0.1),
    doc: "Depth of the deepest point below the polygon, in UV units (tile widths)",
    details: "0.1 on a tile 1 UV wide is a tenth of its width. Also scales the normal map baked from the \
              height map.",
    uses: Uses::HeightMap,
    flag: Some("--depth-scale"),
    uniform: Some("depth_scale"),
};

/// `min_samples`.
pub const MIN_SAMPLES: Param = Param {
    key: "min_samples",
    label: "Min samples",
    kind: Kind::Int { min: 1, max: SAMPLE_LIMIT, slider: (1, 256) },
    default: Value::Int(8),
    doc: "Fewest height samples along a ray, taken head-on",
    details: "The count grows toward max_samples as the ray grazes the surface (Tatarchuk 2006). Fewer \
              samples are cheaper but miss thin features and stair-step.",
    uses: Uses::Some { techniques: &[Technique::Pom], shadows: &[ShadowMode::Hard, ShadowMode::Soft] },
    flag: Some("--min-samples"),
    uniform: Some("min_samples"),
};

/// `max_samples`.
pub const MAX_SAMPLES: Param = Param {
    key: "max_samples",
    label: "Max samples",
    kind: Kind::Int { min: 1, max: SAMPLE_LIMIT, slider: (1, 256) },
    default: Value::Int(32),
    doc: "Most height samples along a ray, taken at grazing angles; at least min_samples",
    details: "Too few and thin features are stepped over; more cost fetches (at most max_samples + 1 + \
              refine per ray).",
    uses: Uses::Some { techniques: &[Technique::Pom], shadows: &[ShadowMode::Hard, ShadowMode::Soft] },
    flag: Some("--max-samples"),
    uniform: Some("max_samples"),
};

/// `samples`.
pub const SAMPLES: Param = Param {
    key: "samples",
    label: "Samples",
    kind: Kind::Int { min: 1, max: SAMPLE_LIMIT, slider: (1, 256) },
    default: Value::Int(32),
    doc: "Depth planes of the linear search",
    details: "Fewer planes cost fewer fetches and stair-step more.",
    uses: Uses::Some { techniques: &[Technique::Steep, Technique::Relief], shadows: &[] },
    flag: Some("--samples"),
    uniform: Some("samples"),
};

/// `iterations`.
pub const ITERATIONS: Param = Param {
    key: "iterations",
    label: "Iterations",
    kind: Kind::Int { min: 1, max: SAMPLE_LIMIT, slider: (1, 32) },
    default: Value::Int(4),
    doc: "Parallax steps, each moving a 1/k share of the locally estimated offset",
    details: "More steps settle better on slopes; there is no occlusion at any count.",
    uses: Uses::Some { techniques: &[Technique::Iterative], shadows: &[] },
    flag: Some("--iterations"),
    uniform: Some("iterations"),
};

/// `binary_steps`.
pub const BINARY_STEPS: Param = Param {
    key: "binary_steps",
    label: "Binary steps",
    kind: Kind::Int { min: 0, max: 64, slider: (0, 16) },
    default: Value::Int(6),
    doc: "Binary refinement steps after relief's linear search or a relaxed cone step",
    details: "One fetch each; each halves the interval that holds the hit.",
    uses: Uses::Some { techniques: &[Technique::Relief, Technique::Cone], shadows: &[] },
    flag: Some("--binary-steps"),
    uniform: Some("binary_steps"),
};

/// `refine`.
pub const REFINE: Param = Param {
    key: "refine",
    label: "Secant refinement",
    kind: Kind::Int { min: 0, max: 64, slider: (0, 8) },
    default: Value::Int(0),
    doc: "Secant refinement steps after pom's linear search",
    details: "One fetch each, as Unity HDRP does; 0 is Tatarchuk's single line-line intersection.",
    uses: Uses::Some { techniques: &[Technique::Pom], shadows: &[] },
    flag: Some("--refine"),
    uniform: Some("refine"),
};

/// `perspective_bias`.
pub const PERSPECTIVE_BIAS: Param = Param {
    key: "perspective_bias",
    label: "Perspective bias",
    kind: Kind::Float {
        min: MIN_PERSPECTIVE_BIAS as f64,
        min_exclusive: false,
        max: MAX_PERSPECTIVE_BIAS as f64,
        slider: (0.0, 1.0),
        log: false,
    },
    default: Value::Float(1.0),
    doc: "Brawley's perspective bias: 1 traces the exact parallax length",
    details: "Smaller values shorten the trace toward grazing angles (less shimmer, flatter relief).",
    uses: Uses::Some { techniques: &[Technique::PomClassic], shadows: &[] },
    flag: Some("--perspective-bias"),
    uniform: Some("perspective_bias"),
};

/// `shadow`.
pub const SHADOW: Param = Param {
    key: "shadow",
    label: "Shadow",
    kind: Kind::Choice(&SHADOW_NAMES),
    default: Value::Name("none"),
    doc: "Self-shadowing of the relief by the first light",
    details: "none: only N.L.\nhard: any height sample above the light ray shadows (Brawley 2004).\n\
              soft: a horizon-angle penumbra after Tatarchuk 2006, widened by `softness`.\n\
              exact: the exact tracer along the light ray.\n\
              depth: no shadow ray, darker the deeper the point (1 - depth), for fur and grass \
              (McGuire 2005 after Lengyel et al. 2001).",
    uses: Uses::HeightMap,
    flag: None,
    uniform: Some("shadow_mode"),
};

/// `softness`.
pub const SOFTNESS: Param = Param {
    key: "softness",
    label: "Softness",
    kind: Kind::Float { min: 0.0, min_exclusive: false, max: f64::INFINITY, slider: (0.0, 0.5), log: false },
    default: Value::Float(0.1),
    doc: "The light's angular radius in radians",
    details: "Larger gives wider, lighter penumbrae; 0 tends to a hard shadow.",
    uses: Uses::Some { techniques: &[], shadows: &[ShadowMode::Soft] },
    flag: None,
    uniform: Some("softness"),
};

/// `lod_threshold`.
pub const LOD_THRESHOLD: Param = Param {
    key: "lod_threshold",
    label: "LOD threshold",
    kind: Kind::Float { min: 0.0, min_exclusive: false, max: f64::INFINITY, slider: (0.0, 12.0), log: false },
    default: Value::Float(4.0),
    doc: "Mip level of the height map beyond which only normal mapping is done",
    details: "Tatarchuk 2006 uses 4. The technique fades out over the level before it, so distant \
              surfaces cost no fetches. The viewer's LOD tint overlay shows where.",
    uses: Uses::HeightMap,
    flag: None,
    uniform: Some("lod_threshold"),
};

/// `edges`.
pub const EDGES: Param = Param {
    key: "edges",
    label: "Edges",
    kind: Kind::Choice(&["wrap", "clamp"]),
    default: Value::Name("wrap"),
    doc: "Texture addressing: wrap tiles the maps, clamp repeats the edge texels",
    details: "",
    uses: Uses::HeightMap,
    flag: Some("--edges"),
    uniform: Some("edges"),
};

/// `depth_map`.
pub const DEPTH_MAP: Param = Param {
    key: "depth_map",
    label: "Input is depth (white = deep)",
    kind: Kind::Bool,
    default: Value::Bool(false),
    doc: "The height image stores depth (white is deep) instead of height (white is high)",
    details: "Some engines store depth; the usual convention is height.",
    uses: Uses::HeightFile,
    flag: None,
    uniform: None,
};

/// `channel`.
pub const CHANNEL: Param = Param {
    key: "channel",
    label: "Height channel",
    kind: Kind::Choice(&["luma", "r", "g", "b", "a"]),
    default: Value::Name("luma"),
    doc: "The channel of the height image that holds the height",
    details: "luma for greyscale images, a for a height packed in a normal map's alpha.",
    uses: Uses::HeightFile,
    flag: None,
    uniform: None,
};

/// `normalize`.
pub const NORMALIZE: Param = Param {
    key: "normalize",
    label: "Normalize height",
    kind: Kind::Bool,
    default: Value::Bool(false),
    doc: "Rescale the height image's values to fill [0, 1]",
    details: "Needed for float images whose values lie outside [0, 1].",
    uses: Uses::HeightFile,
    flag: None,
    uniform: None,
};

/// `normal_y_down`.
pub const NORMAL_Y_DOWN: Param = Param {
    key: "normal_y_down",
    label: "Normal map is +Y down (DirectX)",
    kind: Kind::Bool,
    default: Value::Bool(false),
    doc: "The normal map is DirectX-style (+Y down) instead of OpenGL-style (+Y up)",
    details: "Off for OpenGL, glTF and Blender maps, on for DirectX and Unreal ones. A wrong setting lights \
              the bumps from the opposite side.",
    uses: Uses::NormalFile,
    flag: None,
    uniform: None,
};

/// `specular`.
pub const SPECULAR: Param = Param {
    key: "specular",
    label: "Specular",
    kind: Kind::Float { min: 0.0, min_exclusive: false, max: f64::INFINITY, slider: (0.0, 2.0), log: false },
    default: Value::Float(0.25),
    doc: "Strength of the Blinn-Phong highlight",
    details: "",
    uses: Uses::Always,
    flag: None,
    uniform: None,
};

/// `shininess`.
pub const SHININESS: Param = Param {
    key: "shininess",
    label: "Shininess",
    kind: Kind::Float { min: 0.0, min_exclusive: true, max: f64::INFINITY, slider: (1.0, 512.0), log: true },
    default: Value::Float(32.0),
    doc: "Blinn-Phong exponent: larger gives a smaller, sharper highlight",
    details: "",
    uses: Uses::Always,
    flag: None,
    uniform: None,
};

/// `pixel_depth_offset`.
pub const PIXEL_DEPTH_OFFSET: Param = Param {
    key: "pixel_depth_offset",
    label: "Pixel depth offset",
    kind: Kind::Bool,
    default: Value::Bool(true),
    doc: "Write the displaced depth to the depth buffer",
    details: "Displaced surfaces then meet other geometry where the real surface would (it costs early-z).",
    uses: Uses::Some { techniques: &DISPLACING, shadows: &[] },
    flag: None,
    uniform: None,
};

/// `silhouette`.
pub const SILHOUETTE: Param = Param {
    key: "silhouette",
    label: "Silhouettes",
    kind: Kind::Bool,
    default: Value::Bool(false),
    doc: "Trace under the mesh's curved surface and discard pixels whose ray leaves the relief",
    details: "Curved meshes get a bumpy, displaced outline instead of the smooth one (with clamped edges, \
              rays that leave the texture are discarded too). Free when off.",
    uses: Uses::Some { techniques: &DISPLACING, shadows: &[] },
    flag: None,
    uniform: None,
};

/// `base_color`.
pub const BASE_COLOR: Param = Param {
    key: "base_color",
    label: "Base colour",
    kind: Kind::Color,
    default: Value::Color([0.8, 0.8, 0.8]),
    doc: "Multiplies the colour map (linear RGB); without a colour map, the surface's colour",
    details: "",
    uses: Uses::Always,
    flag: None,
    uniform: None,
};

/// The technique and its options, in the viewer's order.
pub const TECHNIQUE_PARAMS: [Param; 9] =
    [TECHNIQUE, DEPTH_SCALE, MIN_SAMPLES, MAX_SAMPLES, SAMPLES, ITERATIONS, BINARY_STEPS, REFINE, PERSPECTIVE_BIAS];

/// Shadows, LOD, addressing, how the inputs are read and shading, in the viewer's order.
pub const OTHER_PARAMS: [Param; 13] = [
    SHADOW,
    SOFTNESS,
    LOD_THRESHOLD,
    EDGES,
    DEPTH_MAP,
    CHANNEL,
    NORMALIZE,
    NORMAL_Y_DOWN,
    SPECULAR,
    SHININESS,
    PIXEL_DEPTH_OFFSET,
    SILHOUETTE,
    BASE_COLOR,
];

/// The material keys that name files or the material itself, which are not parameters.
pub const FILE_KEYS: [&str; 6] = ["name", "albedo", "height", "normal", "cone_map", "folder"];

/// Every parameter, in table order.
pub fn all() -> impl Iterator<Item = &'static Param> {
    TECHNIQUE_PARAMS.iter().chain(OTHER_PARAMS.iter())
}

/// The parameter of `key`.
#[must_use]
pub fn get(key: &str) -> Option<&'static Param> {
    all().find(|p| p.key == key)
}

/// The Markdown table of every parameter: key, type and range, default, who uses it, meaning
/// (docs/SCENES.md holds it between `<!-- params:begin -->` and `<!-- params:end -->`; a test
/// keeps the two equal).
#[must_use]
pub fn markdown_table() -> String {
    let mut s = String::from("| Key | Type and range | Default | Used by | Meaning |\n|---|---|---|---|---|\n");
    for p in all() {
        s.push_str(&format!(
            "| `{}` | {} | `{}` | {} | {}. |\n",
            p.key,
            p.kind.describe(),
            p.default.toml(),
            p.uses.describe(),
            p.doc
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_unique_and_defaults_valid() {
        let keys: Vec<&str> = all().map(|p| p.key).chain(FILE_KEYS).collect();
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), keys.len(), "a key appears twice: {keys:?}");
        for p in all() {
            assert!(p.kind.accepts(&p.default), "{}: default {:?} is not a valid {:?}", p.key, p.default, p.kind);
            if let Kind::Float { slider: (lo, hi), .. } = p.kind {
                assert!(p.kind.accepts(&Value::Float(lo)) && p.kind.accepts(&Value::Float(hi)), "{}", p.key);
            }
            if let Kind::Int { min, max, slider: (lo, hi) } = p.kind {
                assert!(min <= lo && lo < hi && hi <= max, "{}", p.key);
            }
        }
    }

    #[test]
    fn applicability_follows_uses() {
        let s = Setting {
            technique: Technique::Relief,
            shadow: ShadowMode::None,
            height: true,
            height_file: false,
            normal_file: false,
        };
        assert!(BINARY_STEPS.applies(&s).is_ok());
        assert!(SAMPLES.applies(&s).is_ok());
        assert_eq!(MIN_SAMPLES.applies(&s), Err("used by pom; hard and soft shadows".to_owned()));
        assert!(ITERATIONS.applies(&s).is_err());
        assert!(CHANNEL.applies(&s).is_err_and(|why| why.contains("built-in")));
        assert!(NORMAL_Y_DOWN.applies(&s).is_err());
        let soft = Setting { shadow: ShadowMode::Soft, ..s };
        assert!(MIN_SAMPLES.applies(&soft).is_ok() && SOFTNESS.applies(&soft).is_ok());
        let depth = Setting { shadow: ShadowMode::Depth, ..s };
        assert!(SOFTNESS.applies(&depth).is_err() && MIN_SAMPLES.applies(&depth).is_err());
        let flat = Setting { height: false, technique: Technique::Flat, ..s };
        assert_eq!(DEPTH_SCALE.applies(&flat), Err("needs a height map".to_owned()));
        assert!(SPECULAR.applies(&flat).is_ok());
        assert!(NORMAL_Y_DOWN.applies(&Setting { normal_file: true, ..flat }).is_ok());
    }

    #[test]
    fn words() {
        assert_eq!(DEPTH_SCALE.kind.describe(), "number in (0, 16]");
        assert_eq!(EDGES.kind.describe(), "wrap or clamp");
        assert_eq!(SILHOUETTE.uses.describe(), "every displacing technique");
        assert_eq!(BASE_COLOR.default.toml(), "[0.8, 0.8, 0.8]");
        assert_eq!(TECHNIQUE.default.toml(), "\"exact\"");
    }
}
