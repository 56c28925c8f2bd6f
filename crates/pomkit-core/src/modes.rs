//! What a material chooses: the tracing technique, the self-shadowing mode, and the limits of
//! the parameters that go with them.
//!
//! This module imports nothing else of the crate, so that the parameter table (`params`), the
//! tracer (`trace`), the shadows (`shadow`) and the scene can all name these choices without
//! importing one another. Everything here is re-exported where it has always been used from:
//! `pomkit_core::trace` (and the crate root) for [`Technique`] and the limits,
//! `pomkit_core::shadow` (and the crate root) for [`ShadowMode`]. The methods that need a
//! surface, [`Technique::fetch_bound`] and [`ShadowMode::fetch_bound`], live beside the tracer
//! and the shadows.

/// The most samples any technique takes in one trace; larger requests are clamped (docs/LIMITS.md,
/// "Parameters").
pub const MAX_SAMPLES: u32 = 1024;

/// The deepest relief accepted: `depth_scale` is at most this many UV units (tile widths).
///
/// `depth_scale` is the depth of the deepest point below the polygon relative to the width of
/// one texture tile. Parallax mapping models the relief as a shallow displacement seen through
/// the polygon: at 1 it is already as deep as the tile is wide (slopes of 45 degrees across the
/// whole tile), and beyond a few tile widths a view ray crosses many tiles before it reaches
/// the bottom (up to `depth_scale / MIN_COS`, 1000 tile widths per unit of depth scale, at the
/// flattest ray accepted), so the picture is the texture smeared along the ray while the cost of
/// every marching technique, and of `exact`, grows with that length. 16 leaves ample room above
/// any value that shows relief (the viewer's slider stops at 0.3) and keeps the exact tracer's
/// worst case bounded ([`Technique::fetch_bound`]). [`TraceParams::validate`](crate::trace::TraceParams::validate) refuses larger
/// values; [`TraceParams::sanitized`](crate::trace::TraceParams::sanitized) clamps them.
pub const MAX_DEPTH_SCALE: f32 = 16.0;

/// The smallest `perspective_bias` accepted (see [`MAX_PERSPECTIVE_BIAS`]).
pub const MIN_PERSPECTIVE_BIAS: f32 = 0.0;

/// The largest `perspective_bias` accepted.
///
/// `pom-classic` scales the parallax vector by `b(cos) = pb + (1 - pb) (2 cos - 1)`, clamped at 0,
/// where `cos` is the cosine of the view angle: 1 head-on for every `pb`, and `2 pb - 1` at
/// grazing. For `pb` in `[0, 1]` the factor stays in `[0, 1]`: 1 traces the exact parallax
/// length, smaller values shorten the trace toward grazing angles, down to 0 (which switches the
/// parallax off from 60 degrees on). Above 1 the trace is longer than the ray itself (the hit is
/// reported at a depth the ray has not reached there), and below 0 the parallax vanishes at ever
/// steeper angles; both are refused by [`TraceParams::validate`](crate::trace::TraceParams::validate) and clamped by
/// [`TraceParams::sanitized`](crate::trace::TraceParams::sanitized).
pub const MAX_PERSPECTIVE_BIAS: f32 = 1.0;

/// The tracing techniques of docs/REFERENCES.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Technique {
    /// Plain texturing: no offset, geometric normal. 0 fetches.
    Flat,
    /// Normal mapping only: no offset. 0 fetches.
    Normal,
    /// One-sample parallax (Kaneko 2001) with Welsh's offset limiting: the offset is
    /// `d * depth_scale * (du, dv)` for a unit direction, never longer than the depth itself.
    /// 1 fetch. Swims and flattens at grazing angles.
    Parallax,
    /// Lengyel's iterative parallax (Listing 7.9) on a parallax map `n_z * d`: `k` steps of a
    /// `1/k` share of the locally estimated offset. `k` fetches. Better on slopes, still no
    /// occlusion.
    Iterative,
    /// Steep parallax (McGuire 2005): `n` depth planes, the first plane below the height field.
    /// At most `n` fetches. Stair-steps between planes.
    Steep,
    /// Brawley & Tatarchuk 2004: the parallax vector scaled by the perspective bias, 8 fixed
    /// samples (all fetched: the article's shader has no early exit), line-line intersection.
    /// 8 fetches. Misses features thinner than 1/8 of the trace.
    PomClassic,
    /// Zink / Tatarchuk 2006: between `n_min` and `n_max` samples (more at grazing angles),
    /// early exit, piecewise-linear intersection, optional secant refinement. At most
    /// `n_max + 1 + refine` fetches.
    Pom,
    /// Relief mapping (Policarpo 2005): linear search then `k` binary steps. At most
    /// `n + k` fetches.
    Relief,
    /// The exact first intersection with the bilinear surface of the mip-0 texels, by
    /// maximum-height pyramid traversal. Never misses a feature; O(log size) fetches typically.
    Exact,
    /// Cone stepping (Dummer 2006; Policarpo & Oliveira 2007) on the surface's cone map
    /// ([`crate::cone`]): jumps as far as each footprint's cone allows, texel by texel where the
    /// ray is below a footprint's top, then `binary_steps` of binary search in the step that
    /// ended below the surface. With the cones pomkit builds (conservative) the hit is exact,
    /// as `exact`'s; with a baked map read from an image, relaxed cone stepping. Bounded as
    /// `exact` is ([`Surface::cone_fetch_bound`](crate::trace::Surface::cone_fetch_bound)).
    Cone,
}

impl Technique {
    /// Every technique: the published ones, cheapest first, then pomkit's own.
    pub const ALL: [Technique; 10] = [
        Technique::Flat,
        Technique::Normal,
        Technique::Parallax,
        Technique::Iterative,
        Technique::Steep,
        Technique::PomClassic,
        Technique::Pom,
        Technique::Relief,
        Technique::Exact,
        Technique::Cone,
    ];

    /// The name used by the command line and scene files.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Technique::Flat => "flat",
            Technique::Normal => "normal",
            Technique::Parallax => "parallax",
            Technique::Iterative => "iterative",
            Technique::Steep => "steep",
            Technique::PomClassic => "pom-classic",
            Technique::Pom => "pom",
            Technique::Relief => "relief",
            Technique::Exact => "exact",
            Technique::Cone => "cone",
        }
    }

    /// Whether the technique displaces the texture coordinate at all.
    #[must_use]
    pub const fn displaces(self) -> bool {
        !matches!(self, Technique::Flat | Technique::Normal)
    }
}

impl std::fmt::Display for Technique {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A technique name that pomkit does not know.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownTechnique(pub String);

impl std::fmt::Display for UnknownTechnique {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = Technique::ALL.iter().map(|t| t.name()).collect();
        write!(f, "unknown technique '{}': expected one of {}", self.0, names.join(", "))
    }
}

impl std::error::Error for UnknownTechnique {}

impl std::str::FromStr for Technique {
    type Err = UnknownTechnique;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        Technique::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(t))
            .ok_or_else(|| UnknownTechnique(s.to_owned()))
    }
}

/// How self-shadowing is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ShadowMode {
    /// No self-shadowing: visibility 1 wherever N.L > 0.
    #[default]
    None,
    /// Any sample of the height profile above the light ray shadows the point (Brawley 2004,
    /// McGuire 2005). Between `min_samples` and `max_samples` fetches; aliases into stairs on
    /// thin blockers.
    Hard,
    /// A horizon-angle penumbra estimate after Tatarchuk 2006: each sample's blocker elevation
    /// is weighed by its distance from the receiver and the darkest sample wins. Same fetches as `Hard`; soft,
    /// stable edges; no contact hardening for very thin features.
    Soft,
    /// The exact tracer along the light ray: shadowed if the ray meets the bilinear surface.
    /// Exact, hard-edged; O(log size) fetches typically.
    Exact,
    /// No shadow ray: visibility `1 - depth` at the displaced point, from 1 on the polygon's
    /// surface (the tips of fur or grass) to 0 at the deepest point (the skin or soil). Zero
    /// fetches. McGuire 2005 ("Fur and Grass") approximates the self-shadowing of short straight
    /// fur and grass "as simply increasing with depth", after Lengyel, Praun, Finkelstein and
    /// Hoppe 2001, whose fur shells darken linearly from the tips down to the skin
    /// (docs/REFERENCES.md). Meant for dense, thin relief, where every point is shadowed by
    /// strands in every direction in proportion to how deep it lies; on sparse relief (bricks)
    /// it darkens what the light actually reaches.
    Depth,
}

impl ShadowMode {
    /// Every mode.
    pub const ALL: [ShadowMode; 5] =
        [ShadowMode::None, ShadowMode::Hard, ShadowMode::Soft, ShadowMode::Exact, ShadowMode::Depth];

    /// The name used by the command line and scene files.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            ShadowMode::None => "none",
            ShadowMode::Hard => "hard",
            ShadowMode::Soft => "soft",
            ShadowMode::Exact => "exact",
            ShadowMode::Depth => "depth",
        }
    }
}

impl std::str::FromStr for ShadowMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ShadowMode::ALL.into_iter().find(|m| m.name().eq_ignore_ascii_case(s.trim())).ok_or_else(|| {
            let names: Vec<&str> = ShadowMode::ALL.iter().map(|m| m.name()).collect();
            format!("unknown shadow mode '{s}': expected one of {}", names.join(", "))
        })
    }
}
