//! pomkit's tracing as a WGSL library that other shaders import.
//!
//! The library is eight modules in WESL form under `crates/pomkit-gpu/shaders/pomkit/`
//! ([`MODULES`]): `common` (constants, [`PomkitParams`] and the ray set-up), `lod` (mip level
//! and LOD fade), `exact` (the exact tracer's walk), `cone` (the cone technique's walk), `trace` (every technique and the
//! `pomkit_trace` dispatch), `silhouette` (tracing under a curved surface, for true outlines),
//! `shadow` (hard, soft, exact and depth self-shadowing) and `depth` (pixel
//! depth offset). Every function is pure: it reads heights only through the textures and
//! sampler it is given, and no module has module-level variables.
//!
//! Two ways to use it:
//! - **WESL** (Bevy 0.20, the `wesl` crate): put the eight files in a folder of your shader
//!   package and `import package::pomkit::trace::pomkit_trace;` (the modules import each other
//!   with `super::`, so the folder may sit anywhere).
//! - **Plain WGSL** ([`WGSL`], the file `crates/pomkit-gpu/shaders/pomkit.wgsl`): the modules
//!   concatenated without their `import` lines. Paste it in front of your shader, or call
//!   [`compose`]. Every name starts with `pomkit_` or `POMKIT_`, so it does not collide with
//!   yours.
//!
//! docs/EMBEDDING.md shows a whole program; `examples/foreign_renderer.rs` is one.

use pomkit_core::EdgeMode;
use pomkit_core::scene::Material;
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{Technique, TraceParamError, TraceParams};

use crate::util::Std140;

/// The library's modules in WESL form, as (module name, source), each after the modules it
/// imports.
pub const MODULES: [(&str, &str); 8] = [
    ("common", include_str!("../shaders/pomkit/common.wesl")),
    ("lod", include_str!("../shaders/pomkit/lod.wesl")),
    ("exact", include_str!("../shaders/pomkit/exact.wesl")),
    ("cone", include_str!("../shaders/pomkit/cone.wesl")),
    ("trace", include_str!("../shaders/pomkit/trace.wesl")),
    ("silhouette", include_str!("../shaders/pomkit/silhouette.wesl")),
    ("shadow", include_str!("../shaders/pomkit/shadow.wesl")),
    ("depth", include_str!("../shaders/pomkit/depth.wesl")),
];

/// The whole library as plain WGSL (no entry points, no bindings): [`flatten`]ed from
/// [`MODULES`] and kept in the repository as `crates/pomkit-gpu/shaders/pomkit.wgsl` for programs
/// that are not written in Rust (a test keeps the file equal to [`flatten`]'s output).
pub const WGSL: &str = include_str!("../shaders/pomkit.wgsl");

/// The compute passes that derive everything the library reads from a depth map (`normals_main`,
/// `resolve_main`, `downsample_main`, `pyramid_base_main`, `pyramid_reduce_main`, `cone_main`):
/// the WGSL of `crates/pomkit-gpu/src/height.wgsl`, which the `renderer` feature's
/// `height::HeightPasses` drives. Version-free text, so a renderer on another wgpu version (or
/// none) can drive the same passes (bevy_pomkit does, on Bevy's wgpu); the header of the file
/// documents each entry point's bindings.
pub const HEIGHT_WGSL: &str = include_str!("height.wgsl");

/// The import pass (`import_main`): one channel of a host texture's mip 0 (or the Rec. 709 luma
/// of its colour channels) as depths into mip 0 of the `heights` texture that [`HEIGHT_WGSL`]
/// derives the rest from. The WGSL of `crates/pomkit-gpu/src/import.wgsl`.
pub const IMPORT_WGSL: &str = include_str!("import.wgsl");

/// The plain-WGSL form of the library: a header, then each module of [`MODULES`] with its
/// `import` lines removed.
#[must_use]
pub fn flatten() -> String {
    let mut out = String::from(
        "// pomkit shader library, plain WGSL: generated from crates/pomkit-gpu/shaders/pomkit/*.wesl by\n\
         // pomkit_gpu::library::flatten (do not edit; `UPDATE_SHADERS=1 cargo test -p pomkit-gpu --test\n\
         // library` rewrites it). Paste it in front of your shader; docs/EMBEDDING.md shows how.\n",
    );
    for (name, source) in MODULES {
        out.push_str(&format!("\n// ===== module {name} =====\n\n"));
        for line in source.lines() {
            if line.starts_with("import ") {
                continue;
            }
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// `host` (WGSL that calls the library) with the library in front of it.
#[must_use]
pub fn compose(host: &str) -> String {
    compose_with(WGSL, host)
}

/// `host` with `library` (the library's plain WGSL, or an edited copy of it) in front of it.
#[must_use]
pub fn compose_with(library: &str, host: &str) -> String {
    format!("{library}\n// ===== host shader =====\n\n{host}")
}

/// The value of the library's `POMKIT_*` technique constant for `t`.
#[must_use]
pub const fn technique_index(t: Technique) -> u32 {
    match t {
        Technique::Flat => 0,
        Technique::Normal => 1,
        Technique::Parallax => 2,
        Technique::Iterative => 3,
        Technique::Steep => 4,
        Technique::PomClassic => 5,
        Technique::Pom => 6,
        Technique::Relief => 7,
        Technique::Exact => 8,
        Technique::Cone => 9,
    }
}

/// The value of the library's `POMKIT_SHADOW_*` constant for `m`.
#[must_use]
pub const fn shadow_index(m: ShadowMode) -> u32 {
    match m {
        ShadowMode::None => 0,
        ShadowMode::Hard => 1,
        ShadowMode::Soft => 2,
        ShadowMode::Exact => 3,
        ShadowMode::Depth => 4,
    }
}

/// A parameter of [`PomkitParams`] that cannot be traced with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// A float parameter is NaN or infinite.
    #[error("{name} is {value}: it must be a finite number")]
    NotFinite {
        /// The parameter (`depth_scale`, `softness`, ...).
        name: &'static str,
        /// Its value.
        value: f32,
    },
    /// A tracing parameter is outside the range the tracers accept (the message names it and
    /// the range).
    #[error(transparent)]
    Trace(#[from] TraceParamError),
    /// [`crate::GpuMaterial::set_params`] was asked to change the edge mode, which is part of
    /// the material's sampler.
    #[error(
        "the edge mode cannot change on an existing material (it sets the sampler's address mode): create a new material"
    )]
    EdgesChanged,
    /// `softness` is negative.
    #[error("softness is {0}: it must be at least 0 (radians of the light's angular radius)")]
    Softness(f32),
}

/// The library's `PomkitParams` uniform: a material's tracing parameters, 64 bytes.
///
/// Build one with [`PomkitParams::new`] (checked) or [`PomkitParams::from_material`], write it
/// with [`PomkitParams::to_bytes`] into a uniform buffer the shader reads, and write it again
/// when a parameter changes: nothing else needs rebuilding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PomkitParams {
    /// The technique `pomkit_trace` runs when the shader passes `params.technique`.
    pub technique: Technique,
    /// The self-shadow mode and soft-shadow penumbra.
    pub shadow: ShadowParams,
    /// The tracing parameters (sample counts, refinement steps, perspective bias).
    pub trace: TraceParams,
    /// How far below the polygon, in UV units, the deepest point lies ([`Material::depth_scale`]).
    pub depth_scale: f32,
    /// Texture addressing: the tracers' wrap or clamp arithmetic, which must match the
    /// sampler's address mode ([`crate::util::trilinear_sampler`]).
    pub edges: EdgeMode,
    /// Mip level up to which the full technique runs (Tatarchuk 2006's LOD fade).
    pub lod_threshold: f32,
}

impl PomkitParams {
    /// Bytes of the WGSL struct.
    pub const SIZE: u64 = 64;

    /// Checked parameters: `trace` as [`TraceParams::validate`] accepts it, a depth scale as
    /// [`pomkit_core::trace::check_depth_scale`] accepts it, a finite softness and LOD
    /// threshold.
    ///
    /// # Errors
    /// [`ParamError`] naming the first parameter that is not finite or out of range.
    pub fn new(
        technique: Technique,
        shadow: ShadowParams,
        trace: TraceParams,
        depth_scale: f32,
        edges: EdgeMode,
        lod_threshold: f32,
    ) -> Result<Self, ParamError> {
        for (name, value) in [
            ("depth_scale", depth_scale),
            ("perspective_bias", trace.perspective_bias),
            ("softness", shadow.softness),
            ("lod_threshold", lod_threshold),
        ] {
            if !value.is_finite() {
                return Err(ParamError::NotFinite { name, value });
            }
        }
        pomkit_core::trace::check_depth_scale(depth_scale)?;
        trace.validate()?;
        if shadow.softness < 0.0 {
            return Err(ParamError::Softness(shadow.softness));
        }
        Ok(Self { technique, shadow, trace, depth_scale, edges, lod_threshold })
    }

    /// The parameters of a pomkit material drawn with `technique`, sanitized as the renderers
    /// sanitize them (a scene loader has already checked them).
    #[must_use]
    pub fn from_material(material: &Material, technique: Technique) -> Self {
        Self {
            technique,
            shadow: material.shadow,
            trace: material.trace.sanitized(),
            depth_scale: pomkit_core::trace::sanitized_depth_scale(material.depth_scale),
            edges: material.edges,
            lod_threshold: material.lod_threshold,
        }
    }

    /// The uniform's bytes (std140 and WGSL uniform layout agree for this struct).
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        self.block().bytes()
    }

    /// Each member's name and byte offset as [`PomkitParams::to_bytes`] writes them (a test
    /// checks them against the WGSL struct).
    #[must_use]
    pub fn layout() -> Vec<(&'static str, usize)> {
        Self::from_material(&Material::default(), Technique::Pom).block().layout()
    }

    fn block(&self) -> Std140 {
        let p = self.trace.sanitized();
        let softness = if self.shadow.softness.is_finite() { self.shadow.softness } else { 0.1 };
        let lod_threshold = if self.lod_threshold.is_finite() { self.lod_threshold } else { f32::MAX };
        let mut u = Std140::new();
        u.named("technique", 4).u(technique_index(self.technique));
        u.named("shadow_mode", 4).u(shadow_index(self.shadow.mode));
        u.named("edges", 4).u(edges_index(self.edges));
        u.named("min_samples", 4).u(p.min_samples);
        u.named("max_samples", 4).u(p.max_samples);
        u.named("samples", 4).u(p.samples);
        u.named("iterations", 4).u(p.iterations);
        u.named("binary_steps", 4).u(p.binary_steps);
        u.named("refine", 4).u(p.refine);
        u.named("depth_scale", 4).f(pomkit_core::trace::sanitized_depth_scale(self.depth_scale));
        u.named("perspective_bias", 4).f(p.perspective_bias);
        u.named("softness", 4).f(softness);
        u.named("lod_threshold", 4).f(lod_threshold);
        u.named("pad0", 4).u(0).named("pad1", 4).u(0).named("pad2", 4).u(0);
        u
    }
}

/// What the library's `cone.wesl` reads from the pyramid's green channel (mip 0) for footprint
/// `(x, y)` of `cones`: its cone ratio, negated for relaxed cones (which the walk then steps on
/// with a look after each step). 0 means no cones.
#[must_use]
pub fn cone_green(cones: &pomkit_core::cone::ConeMap, x: u32, y: u32) -> f32 {
    if cones.relaxed() { -cones.ratio(x, y) } else { cones.ratio(x, y) }
}

/// The value of the library's `POMKIT_WRAP` / `POMKIT_CLAMP` for `e`.
#[must_use]
pub const fn edges_index(e: EdgeMode) -> u32 {
    match e {
        EdgeMode::Wrap => 0,
        EdgeMode::Clamp => 1,
    }
}

/// The texels of pyramid level `level` (1 and up) that the library's `pomkit_planes_first_hit`
/// reads from its `planes` texture (`Rgba32Uint`, mip `level - 1`), row by row over the level's
/// [`MaxHeightPyramid::level_size`] cells: x = the cell's least depth (f32 bits), y = its plane's
/// depth (f32 bits), z = the slopes along x (low half) and y (high half) as f16, w = the
/// shallower (low) and deeper (high) widths as f16. `CellPlanes` stores slopes and widths as
/// f16 values, so the halves are theirs exactly.
///
/// [`MaxHeightPyramid::level_size`]: pomkit_core::pyramid::MaxHeightPyramid::level_size
///
/// # Panics
/// For level 0 or a level past the pyramid's last.
#[must_use]
pub fn plane_texels(
    planes: &pomkit_core::planes::CellPlanes,
    pyramid: &pomkit_core::pyramid::MaxHeightPyramid,
    level: usize,
) -> Vec<[u32; 4]> {
    let half = |a: f32, b: f32| {
        u32::from(half::f16::from_f32(a).to_bits()) | (u32::from(half::f16::from_f32(b).to_bits()) << 16)
    };
    let (w, h) = pyramid.level_size(level);
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let c = planes.cell(level, x, y);
            [
                pyramid.min_depth(level, x, y).to_bits(),
                c.depth.to_bits(),
                half(c.slope[0], c.slope[1]),
                half(c.shallower, c.deeper),
            ]
        })
        .collect()
}
