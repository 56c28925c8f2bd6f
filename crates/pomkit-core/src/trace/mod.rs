//! Tracing: where does a ray entering a height-mapped polygon meet the displaced surface?
//!
//! Every technique of docs/REFERENCES.md is a pure function of (surface, ray, parameters) that
//! returns a [`Hit`] and counts its height fetches. The renderers call these functions per pixel
//! (the GPU calls their WGSL twins).
//!
//! # The ray
//! A [`Ray`] enters the polygon at `uv` with direction `(du, dv, dz)`: along +u, +v and along the
//! tangent-space normal, so `dz < 0` points into the surface. Depth `z` in `[0, 1]` is reached at
//! `uv + z * depth_scale * (du, dv) / -dz` (ARCHITECTURE.md, Conventions). Directions need not be unit length.
//! Rays with `dz >= 0` do not enter the surface: every technique returns the entry point, depth 0,
//! with no fetch. Rays flatter than [`MIN_COS`] are steepened to it (about 89.94 degrees from the
//! normal) so that every trace is finite.
//!
//! # Error
//! "Error" is the distance in texels between a technique's hit UV and the [`Technique::Exact`]
//! hit UV for the same ray. Hit UVs are not wrapped into `[0, 1]`: with wrapping edges a long
//! grazing ray can travel several tiles, and the error is measured along the ray.

use glam::{DVec2, DVec3, Vec2, Vec3};

use crate::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use crate::cone::{ConeMap, ConeMapError};
use crate::heightfield::{EdgeMode, HeightField, MipChain};
pub use crate::modes::{
    MAX_DEPTH_SCALE, MAX_PERSPECTIVE_BIAS, MAX_SAMPLES, MIN_PERSPECTIVE_BIAS, Technique, UnknownTechnique,
};
use crate::planes::{CellPlanes, PlaneBoundsError};
use crate::pyramid::MaxHeightPyramid;

mod cone;
mod exact;
pub mod packet;
pub(crate) mod shadow_march;
mod surface;

pub(crate) use exact::*;
pub use surface::{Surface, cached_plane_bounds};

/// View rays [`Surface::choose_plane_bounds`] decides by, per walk.
pub const PLANE_CHOICE_RAYS: usize = 64;

/// The flattest ray accepted, as `-dz` of the unit direction; flatter rays are steepened to it.
pub const MIN_COS: f32 = 1e-3;

/// A ray entering the polygon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Entry point in UV.
    pub uv: Vec2,
    /// Direction of travel `(du, dv, dz)`; `dz < 0` enters the surface.
    pub dir: Vec3,
}

impl Ray {
    /// A ray from `uv` with direction `dir`.
    #[must_use]
    pub fn new(uv: Vec2, dir: Vec3) -> Self {
        Self { uv, dir }
    }

    /// The ray seen at `angle` radians from the normal, travelling along azimuth `azimuth`
    /// radians in the UV plane (0 = +u).
    #[must_use]
    pub fn at_angle(uv: Vec2, angle: f32, azimuth: f32) -> Self {
        let (s, c) = angle.sin_cos();
        Self { uv, dir: Vec3::new(s * azimuth.cos(), s * azimuth.sin(), -c) }
    }
}

/// Where a technique says the ray meets the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Hit point in UV (not wrapped).
    pub uv: Vec2,
    /// Depth of the hit point on the ray, in `[0, 1]`.
    pub depth: f32,
    /// Height fetches made (ARCHITECTURE.md, Conventions: a filtered sample, a gather or a pyramid texel
    /// read each count 1).
    pub fetches: u32,
}

impl Technique {
    /// The most fetches one view trace may take with `params` (the bound the tests check).
    ///
    /// Every technique's loops run a fixed number of times (each at most [`MAX_SAMPLES`], or 64
    /// refinement steps), except `exact`'s traversal, whose bound grows with the length of the
    /// ray in texels: see [`Surface::exact_fetch_bound`].
    #[must_use]
    pub fn fetch_bound(self, params: &TraceParams, surface: &Surface) -> u32 {
        let p = params.sanitized();
        match self {
            Technique::Flat | Technique::Normal => 0,
            Technique::Parallax => 1,
            Technique::Iterative => p.iterations,
            Technique::Steep => p.samples,
            Technique::PomClassic => 8,
            Technique::Pom => p.max_samples + 1 + p.refine,
            Technique::Relief => p.samples + p.binary_steps,
            Technique::Exact => surface.exact_fetch_bound(),
            Technique::Cone => surface.cone_fetch_bound(p.binary_steps),
        }
    }
}

/// Parameters shared by the techniques (the command line's technique options).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceParams {
    /// `pom`: fewest samples (head-on). Default 8.
    pub min_samples: u32,
    /// `pom`: most samples (grazing). Default 32.
    pub max_samples: u32,
    /// `steep` and `relief`'s linear search: depth planes. Default 32.
    pub samples: u32,
    /// `iterative`: parallax steps k. Default 4 (Lengyel's listing).
    pub iterations: u32,
    /// `relief` and `cone`: binary refinement steps. Default 6.
    pub binary_steps: u32,
    /// `pom`: secant refinement steps after the linear search (Unity HDRP style). Default 0.
    pub refine: u32,
    /// `pom-classic`: Brawley's perspective bias, in `[0, 1]` ([`MAX_PERSPECTIVE_BIAS`]). 1
    /// gives the exact parallax length; smaller values shorten the trace toward grazing angles
    /// (less shimmer, flatter relief). Default 1.
    pub perspective_bias: f32,
    /// Mip level the sampling techniques read (fixed before the loop, from UV gradients).
    /// `exact` always works on mip 0. Default 0.
    pub lod: f32,
}

impl TraceParams {
    /// The defaults, from the parameter table ([`crate::params`]; evaluated when building).
    pub const DEFAULT: Self = {
        use crate::table as p;
        Self {
            min_samples: p::MIN_SAMPLES.default.u32(),
            max_samples: p::MAX_SAMPLES.default.u32(),
            samples: p::SAMPLES.default.u32(),
            iterations: p::ITERATIONS.default.u32(),
            binary_steps: p::BINARY_STEPS.default.u32(),
            refine: p::REFINE.default.u32(),
            perspective_bias: p::PERSPECTIVE_BIAS.default.f32(),
            lod: 0.0,
        }
    };
}

impl Default for TraceParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why trace parameters were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TraceParamError {
    /// `depth_scale` is NaN, infinite, zero, negative or above [`MAX_DEPTH_SCALE`].
    #[error(
        "depth_scale is {0}: it must be greater than 0 and at most {max} (UV units: the deepest point \
         lies at most {max} tile widths below the polygon; deeper relief is beyond what parallax \
         mapping can show)",
        max = MAX_DEPTH_SCALE
    )]
    DepthScale(f32),
    /// `perspective_bias` is NaN, infinite or outside
    /// `[MIN_PERSPECTIVE_BIAS, MAX_PERSPECTIVE_BIAS]`.
    #[error(
        "perspective_bias is {0}: it must lie in [{min}, {max}] (1 traces the exact parallax length, \
         smaller values shorten it toward grazing angles)",
        min = MIN_PERSPECTIVE_BIAS,
        max = MAX_PERSPECTIVE_BIAS
    )]
    PerspectiveBias(f32),
    /// `lod` is NaN or infinite.
    #[error("lod is {0}: it must be a finite number")]
    Lod(f32),
    /// `min_samples` exceeds `max_samples`.
    #[error("min_samples ({min}) exceeds max_samples ({max})")]
    SampleBounds {
        /// The minimum.
        min: u32,
        /// The maximum.
        max: u32,
    },
}

impl TraceParams {
    /// Checks the parameters.
    ///
    /// # Errors
    /// [`TraceParamError`] for a perspective bias outside `[MIN_PERSPECTIVE_BIAS, MAX_PERSPECTIVE_BIAS]`, a non-finite LOD,
    /// or `min_samples > max_samples`. Sample counts above [`MAX_SAMPLES`] and of zero are not
    /// errors: they are clamped to `1..=MAX_SAMPLES`.
    pub fn validate(&self) -> Result<(), TraceParamError> {
        if !(MIN_PERSPECTIVE_BIAS..=MAX_PERSPECTIVE_BIAS).contains(&self.perspective_bias) {
            return Err(TraceParamError::PerspectiveBias(self.perspective_bias));
        }
        if !self.lod.is_finite() {
            return Err(TraceParamError::Lod(self.lod));
        }
        if self.min_samples > self.max_samples {
            return Err(TraceParamError::SampleBounds { min: self.min_samples, max: self.max_samples });
        }
        Ok(())
    }

    /// The parameters with counts clamped to `1..=MAX_SAMPLES` (refine and binary steps to
    /// `0..=64`), the perspective bias into
    /// `[MIN_PERSPECTIVE_BIAS, MAX_PERSPECTIVE_BIAS]`, and non-finite or non-positive values
    /// replaced by defaults, so tracing never hangs or panics.
    #[must_use]
    pub fn sanitized(&self) -> Self {
        let d = Self::default();
        let c = |n: u32| n.clamp(1, MAX_SAMPLES);
        let max_samples = c(self.max_samples);
        Self {
            min_samples: c(self.min_samples).min(max_samples),
            max_samples,
            samples: c(self.samples),
            iterations: c(self.iterations),
            binary_steps: self.binary_steps.min(64),
            refine: self.refine.min(64),
            perspective_bias: if self.perspective_bias.is_finite() {
                self.perspective_bias.clamp(MIN_PERSPECTIVE_BIAS, MAX_PERSPECTIVE_BIAS)
            } else {
                d.perspective_bias
            },
            lod: if self.lod.is_finite() { self.lod.max(0.0) } else { 0.0 },
        }
    }
}

/// Checks a depth scale (a material's, or the one a [`Surface`] is built for).
///
/// # Errors
/// [`TraceParamError::DepthScale`] for a depth scale outside `(0, MAX_DEPTH_SCALE]` (NaN and
/// infinities included). [`Surface::new`] takes any value and sanitizes it
/// ([`sanitized_depth_scale`]); check first to report bad input instead.
pub fn check_depth_scale(depth_scale: f32) -> Result<(), TraceParamError> {
    if depth_scale > 0.0 && depth_scale <= MAX_DEPTH_SCALE {
        Ok(())
    } else {
        Err(TraceParamError::DepthScale(depth_scale))
    }
}

/// `depth_scale` clamped to `(0, MAX_DEPTH_SCALE]`; NaN, infinite, zero and negative values give
/// the default (infinity too: it is no depth at all, not the deepest one).
#[must_use]
pub fn sanitized_depth_scale(depth_scale: f32) -> f32 {
    if depth_scale.is_finite() && depth_scale > 0.0 {
        depth_scale.min(MAX_DEPTH_SCALE)
    } else {
        crate::table::DEPTH_SCALE.default.f32()
    }
}

/// The most steps of [`cone::first_hit`] for a view ray on `surface` (at its depth
/// scale): two per texel boundary crossed (a step above a footprint's top ends at the top or
/// past a boundary; a step at or below it crosses the footprint), over the longest ray accepted.
pub(crate) fn cone_step_bound(surface: &Surface) -> u64 {
    let f = surface.field();
    let travel = f64::from(surface.depth_scale()) / f64::from(MIN_COS) * (1.0 + 1e-4);
    let d = DVec3::new(travel * f64::from(f.width()), travel * f64::from(f.height()), 1.0);
    let (w, h) = (i64::from(f.width()), i64::from(f.height()));
    exact_step_bound(d, 0.0, 1.0, w, h, surface.edges())
}

/// Splits `uv` into its tile `k = floor(uv)` (per axis, in f64) and the point `uv - k` in that
/// tile, where the edges wrap; with clamped edges the plane does not tile: `(uv, 0)`.
///
/// Where the surface repeats, tracing from `uv - k` and adding `k` back to the hit gives the
/// hit of the ray in its own tile frame, with the f32 arithmetic of the trace done on small
/// numbers. The reduced point is exact (an f32 `uv` with `|uv| >= 1` is a multiple of its ulp,
/// so is `uv - k < 1`; for `|uv| >= 2^23` it is 0: such a `uv` is a whole number of tiles); for
/// small negative `uv` it may round up to 1, the same point of the surface within 2^-24.
pub(crate) fn reduce_to_tile(uv: Vec2, edges: EdgeMode) -> (Vec2, DVec2) {
    match edges {
        EdgeMode::Wrap => {
            let u = uv.as_dvec2();
            let k = u.floor();
            ((u - k).as_vec2(), k)
        }
        EdgeMode::Clamp => (uv, DVec2::ZERO),
    }
}

/// A point of the reduced frame of [`reduce_to_tile`] back in the ray's own tile frame: the
/// sum is formed in f64 and rounded once to f32, so far from the origin the result carries what
/// f32 can hold there (at `u = 1e15` its spacing is 2^26 = 67 108 864 tiles: a hit there is the
/// entry point, rounded, while its depth is the exact one of the reduced trace).
pub(crate) fn unreduce(uv: Vec2, tile: DVec2) -> Vec2 {
    if tile == DVec2::ZERO { uv } else { (uv.as_dvec2() + tile).as_vec2() }
}

/// The UV offset per unit depth along `dir` (unit, `dz < 0`): `depth_scale * (du, dv) / -dz`.
pub(crate) fn uv_per_depth(dir: Vec3, depth_scale: f32) -> Vec2 {
    Vec2::new(dir.x, dir.y) * (depth_scale / -dir.z)
}

/// `v` as a unit vector, whatever its finite length: it is divided by its largest component
/// first and normalized in f64, so `(1e20, 1e20, -1e20)` and `(1e-30, 1e-30, -1e-30)` (whose
/// squared lengths overflow or underflow f32) both give `(1, 1, -1) / sqrt(3)`. `None` for a
/// zero or non-finite vector.
#[must_use]
pub fn unit_direction(v: Vec3) -> Option<DVec3> {
    if !v.is_finite() {
        return None;
    }
    let d = v.as_dvec3();
    let largest = d.abs().max_element();
    if largest == 0.0 {
        return None;
    }
    // Every component of d / largest lies in [-1, 1] and one is +-1: the length is in [1, 2].
    Some((d / largest).normalize())
}

/// Normalizes `dir` ([`unit_direction`]) and steepens it to [`MIN_COS`]; `None` for rays that do
/// not enter (`dz >= 0`, decided in f64 before rounding to f32) or are zero or not finite.
pub(crate) fn entering(dir: Vec3) -> Option<Vec3> {
    let d = unit_direction(dir)?;
    if d.z >= 0.0 {
        return None;
    }
    if -d.z >= f64::from(MIN_COS) {
        return Some(d.as_vec3());
    }
    let xy = Vec2::new(d.x as f32, d.y as f32).normalize_or_zero() * (1.0 - MIN_COS * MIN_COS).sqrt();
    Some(Vec3::new(xy.x, xy.y, -MIN_COS))
}

/// Traces `ray` into `surface` with `technique`.
///
/// Parameters are [`TraceParams::sanitized`] first, so any input gives a finite hit in a
/// bounded time ([`Technique::fetch_bound`]); validate them with [`TraceParams::validate`] to
/// report bad input instead. The depth scale and the edge mode are the surface's
/// ([`Surface::new`]).
///
/// Where the surface's edges wrap, the entry point is first reduced to its tile
/// (`reduce_to_tile`): the trace runs from `uv - floor(uv)` and the hit is moved back by the
/// same whole number of tiles, so the returned UV stays in the ray's own tile frame (not wrapped
/// into `[0, 1]`) and the result does not depend on which tile the ray enters, up to the f32
/// rounding of the returned UV: at `|u| = 1e15` an f32 cannot hold a sub-tile offset, so the
/// hit's UV there is the entry tile's (rounded), while its depth and fetches are those of the
/// same ray entering at the reduced point.
#[must_use]
pub fn trace(surface: &Surface, ray: &Ray, technique: Technique, params: &TraceParams) -> Hit {
    let uv0 = if ray.uv.is_finite() { ray.uv } else { Vec2::ZERO };
    let none = Hit { uv: uv0, depth: 0.0, fetches: 0 };
    let Some(dir) = entering(ray.dir) else { return none };
    let (reduced, tile) = reduce_to_tile(uv0, surface.edges);
    let hit = trace_entering(surface, reduced, dir, technique, &params.sanitized());
    Hit { uv: unreduce(hit.uv, tile), ..hit }
}

/// [`trace`] for a unit, entering direction and sanitized parameters.
///
/// Every loop here runs a bounded number of times: `iterative` `k <= MAX_SAMPLES`, `steep`
/// `n <= MAX_SAMPLES`, `pom-classic` 8, `pom` `n <= MAX_SAMPLES` then `refine <= 64`, `relief`
/// `n - 1 < MAX_SAMPLES` then `binary_steps <= 64`, and `exact` at most [`exact_step_bound`]
/// steps.
fn trace_entering(surface: &Surface, uv0: Vec2, dir: Vec3, technique: Technique, p: &TraceParams) -> Hit {
    march(surface, uv0, dir, technique, p, &Straight)
}

/// How a marching technique reads the depth profile under its ray: the depth it compares with
/// the ray's own depth `tau` in `[0, 1]` at the point `uv` the ray reaches there, and how far
/// along the straight ray `tau = 1` lies (the UV extent of the march is scaled by it).
///
/// [`Straight`] is the flat tangent plane of every technique's source; [`crate::silhouette`]'s
/// bent profile follows a curved surface. Generic, so the straight case compiles to the
/// techniques as written (a multiplication by 1.0 and nothing else).
pub(crate) trait Profile {
    /// The depth the ray at parameter `tau` (point `uv`) is compared with.
    fn depth(&self, surface: &Surface, uv: Vec2, tau: f32, lod: f32) -> f32;
    /// The straight ray's depth at `tau = 1`.
    fn extent(&self) -> f32;
    /// Whether the march ends where the ray leaves the relief (so reaching `tau = 1` without a
    /// hit is a miss, not the floor).
    fn exits(&self) -> bool;
}

/// The techniques' own profile: the height field under the tangent plane.
pub(crate) struct Straight;

impl Profile for Straight {
    #[inline]
    fn depth(&self, surface: &Surface, uv: Vec2, _tau: f32, lod: f32) -> f32 {
        surface.depth(uv, lod)
    }
    #[inline]
    fn extent(&self) -> f32 {
        1.0
    }
    #[inline]
    fn exits(&self) -> bool {
        false
    }
}

/// The techniques over a depth profile: `parallax` and `iterative` read the surface directly
/// (they have no march to bend), the others compare `profile`'s depth with the ray's.
pub(crate) fn march<P: Profile>(
    surface: &Surface,
    uv0: Vec2,
    dir: Vec3,
    technique: Technique,
    p: &TraceParams,
    profile: &P,
) -> Hit {
    let none = Hit { uv: uv0, depth: 0.0, fetches: 0 };
    let s = uv_per_depth(dir, surface.depth_scale) * profile.extent();
    let at = |z: f32| uv0 + s * z;
    match technique {
        Technique::Flat | Technique::Normal => none,
        Technique::Parallax => {
            // Kaneko's offset d * ds * V.xy / V.z, limited (Welsh 2004) by dropping the division:
            // the shift never exceeds the sampled depth times the depth scale.
            let s = uv_per_depth(dir, surface.depth_scale);
            let d = surface.depth(uv0, p.lod);
            let offset = Vec2::new(dir.x, dir.y) * (d * surface.depth_scale);
            hit_on_ray(uv0, s, offset, d * -dir.z, 1)
        }
        Technique::Iterative => {
            // Lengyel Listing 7.9 in pomkit's depth convention: the polygon is the top, so the
            // map holds n_z * d (no signed remap) and every step moves away from the viewer.
            let s = uv_per_depth(dir, surface.depth_scale);
            let k = p.iterations;
            let step = Vec2::new(dir.x, dir.y) * (surface.depth_scale / k as f32);
            let mut uv = uv0;
            let mut sum = 0.0;
            for _ in 0..k {
                let value = surface.parallax_mips().sample(uv, p.lod, surface.edges);
                sum += value;
                uv += step * value;
            }
            hit_on_ray(uv0, s, uv - uv0, sum / k as f32 * -dir.z, k)
        }
        Technique::Steep => {
            // McGuire 2005: march depth planes 0, 1/n, ... until the surface is at or above the
            // plane. Erratum (docs/REFERENCES.md, Errata): the loop is capped; the plane at depth 1 is always at or
            // below the surface, so it needs no fetch.
            let n = p.samples;
            let mut fetches = 0;
            for i in 0..n {
                let z = i as f32 / n as f32;
                fetches += 1;
                if profile.depth(surface, at(z), z, p.lod) <= z {
                    return Hit { uv: at(z), depth: z, fetches };
                }
            }
            Hit { uv: at(1.0), depth: 1.0, fetches }
        }
        Technique::PomClassic => pom_classic(surface, uv0, dir, p, profile),
        Technique::Pom => pom(surface, uv0, dir, s, p, profile),
        Technique::Relief => relief(surface, uv0, s, p, profile),
        Technique::Exact => exact_view(surface, uv0, s),
        // The cones hold for the straight ray; `trace_curved` walks bent rays as `exact` does.
        Technique::Cone => cone_view(surface, uv0, s, p),
    }
}

/// The hit for an offset along the ray direction: the point of the ray at that UV offset.
/// For a ray straight down (no UV travel) the offset says nothing about depth; `head_on` is the
/// depth the technique estimated, the limit of the projection as the ray tilts toward vertical.
fn hit_on_ray(uv0: Vec2, s: Vec2, offset: Vec2, head_on: f32, fetches: u32) -> Hit {
    let len2 = s.length_squared();
    let z = if len2 > 1e-20 { offset.dot(s) / len2 } else { head_on };
    let z = if z.is_finite() { z.clamp(0.0, 1.0) } else { 0.0 };
    Hit { uv: uv0 + s * z, depth: z, fetches }
}

/// Intersection of the ray `z = t` with the line through `(t0, d0)` and `(t1, d1)`, where the
/// ray is above the surface at `t0` (`d0 > t0`) and at or below it at `t1` (`d1 <= t1`).
fn line_intersection(t0: f32, d0: f32, t1: f32, d1: f32) -> f32 {
    let a = d0 - t0;
    let b = t1 - d1;
    let denom = a + b;
    if denom > 0.0 { t0 + (t1 - t0) * (a / denom) } else { t1 }
}

/// Brawley & Tatarchuk 2004: 8 samples along the biased parallax vector.
fn pom_classic<P: Profile>(surface: &Surface, uv0: Vec2, dir: Vec3, p: &TraceParams, profile: &P) -> Hit {
    // Parallax length tan(theta) = sqrt(1 - z^2) / z of the unit view vector; the bias
    // pb + (1 - pb)(2 cos(theta) - 1) shortens it toward grazing angles for pb < 1 (Brawley's
    // vertex shader). Clamped at 0 so the vector never points back toward the viewer.
    let cos = -dir.z;
    let bias = (p.perspective_bias + (1.0 - p.perspective_bias) * (2.0 * cos - 1.0)).max(0.0);
    let s = uv_per_depth(dir, surface.depth_scale) * (bias * profile.extent());
    let n = 8;
    // Brawley samples at 1/8 .. 8/8 of the vector; the entry (t = 0) is not fetched, and the
    // first segment reuses the first sample's depth for its start, as the article's shader does.
    let mut prev = (0.0f32, f32::NAN);
    for i in 1..=n {
        let t = i as f32 / n as f32;
        let d = profile.depth(surface, uv0 + s * t, t, p.lod);
        if prev.1.is_nan() {
            prev.1 = d;
        }
        if d <= t {
            let z = line_intersection(prev.0, prev.1.max(prev.0), t, d);
            // The article's ps_2_0 shader has no dynamic branching: it fetches all eight
            // samples before choosing the segment, so the cost is always 8.
            return Hit { uv: uv0 + s * z, depth: z, fetches: n };
        }
        prev = (t, d);
    }
    Hit { uv: uv0 + s, depth: 1.0, fetches: n }
}

/// The adaptive sample count of Tatarchuk 2006 eq. (1), with the erratum of docs/REFERENCES.md
/// fixed: `n_max` at grazing angles (N.V = 0), `n_min` head-on (N.V = 1).
#[must_use]
pub fn adaptive_samples(cos_view: f32, min_samples: u32, max_samples: u32) -> u32 {
    let c = if cos_view.is_finite() { cos_view.clamp(0.0, 1.0) } else { 0.0 };
    let n = max_samples as f32 + (min_samples as f32 - max_samples as f32) * c;
    (n.round() as u32).clamp(min_samples.min(max_samples).max(1), max_samples.max(1))
}

/// Zink / Tatarchuk 2006 POM with optional secant refinement.
fn pom<P: Profile>(surface: &Surface, uv0: Vec2, dir: Vec3, s: Vec2, p: &TraceParams, profile: &P) -> Hit {
    let n = adaptive_samples(-dir.z, p.min_samples, p.max_samples);
    let step = 1.0 / n as f32;
    // The entry sample: a real fetch, so the first segment's line is the surface's.
    let mut fetches = 1;
    let mut prev = (0.0f32, profile.depth(surface, uv0, 0.0, p.lod));
    if prev.1 <= 0.0 {
        return Hit { uv: uv0, depth: 0.0, fetches };
    }
    let mut bracket = None;
    for i in 1..=n {
        let t = if i == n { 1.0 } else { i as f32 * step };
        let d = profile.depth(surface, uv0 + s * t, t, p.lod);
        fetches += 1;
        // Early exit: the first sample at or above the ray ends the search.
        if d <= t {
            bracket = Some((prev, (t, d)));
            break;
        }
        prev = (t, d);
    }
    let Some((mut a, mut b)) = bracket else {
        // Unreachable for depths in [0, 1] (the last sample, at t = 1, is never below the ray);
        // kept so that a surprise cannot produce a hit outside the segment.
        return Hit { uv: uv0 + s, depth: 1.0, fetches };
    };
    let mut z = line_intersection(a.0, a.1, b.0, b.1);
    // Secant refinement (as Unity HDRP): sample at the intersection and keep the half of the
    // bracket that still straddles the surface.
    for _ in 0..p.refine {
        let d = profile.depth(surface, uv0 + s * z, z, p.lod);
        fetches += 1;
        if d > z {
            a = (z, d);
        } else {
            b = (z, d);
        }
        z = line_intersection(a.0, a.1, b.0, b.1);
    }
    Hit { uv: uv0 + s * z, depth: z, fetches }
}

/// Relief mapping: linear search over `samples` planes, then binary refinement.
fn relief<P: Profile>(surface: &Surface, uv0: Vec2, s: Vec2, p: &TraceParams, profile: &P) -> Hit {
    let n = p.samples;
    let mut fetches = 0;
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for i in 1..n {
        let t = i as f32 / n as f32;
        fetches += 1;
        if profile.depth(surface, uv0 + s * t, t, p.lod) <= t {
            hi = t;
            break;
        }
        lo = t;
    }
    // Binary search between the last plane above the surface and the first below it; the
    // plane at depth 1 needs no fetch (it is never above the surface).
    for _ in 0..p.binary_steps {
        let mid = 0.5 * (lo + hi);
        fetches += 1;
        if profile.depth(surface, uv0 + s * mid, mid, p.lod) <= mid {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    // Where the march ends at the ray's exit from the relief, a search that never found the
    // surface below the ray is a miss: report the end itself.
    let missed = profile.exits() && hi >= 1.0;
    let z = if p.binary_steps > 0 && !missed { 0.5 * (lo + hi) } else { hi };
    Hit { uv: uv0 + s * z, depth: z, fetches }
}

/// The exact view trace: first intersection from depth 0 down to depth 1.
fn exact_view(surface: &Surface, uv0: Vec2, s: Vec2) -> Hit {
    let f = surface.field();
    let size = DVec2::new(f64::from(f.width()), f64::from(f.height()));
    // Work in unbounded texel coordinates and depth: P(t) = o + t * d with t = depth.
    let o = DVec3::new(f64::from(uv0.x) * size.x, f64::from(uv0.y) * size.y, 0.0);
    let d = DVec3::new(f64::from(s.x) * size.x, f64::from(s.y) * size.y, 1.0);
    let r = exact::view_first_hit(surface, o, d, 0.0, 1.0);
    let t = r.t.unwrap_or(1.0).clamp(0.0, 1.0);
    let p = o + d * t;
    Hit { uv: Vec2::new((p.x / size.x) as f32, (p.y / size.y) as f32), depth: t as f32, fetches: r.fetches }
}

/// The cone view trace ([`cone::first_hit`]) from depth 0 down to depth 1.
fn cone_view(surface: &Surface, uv0: Vec2, s: Vec2, p: &TraceParams) -> Hit {
    let f = surface.field();
    let size = DVec2::new(f64::from(f.width()), f64::from(f.height()));
    let o = DVec3::new(f64::from(uv0.x) * size.x, f64::from(uv0.y) * size.y, 0.0);
    let d = DVec3::new(f64::from(s.x) * size.x, f64::from(s.y) * size.y, 1.0);
    let r = cone::first_hit(surface, o, d, 0.0, 1.0, p);
    let t = r.t.unwrap_or(1.0).clamp(0.0, 1.0);
    let q = o + d * t;
    Hit { uv: Vec2::new((q.x / size.x) as f32, (q.y / size.y) as f32), depth: t as f32, fetches: r.fetches }
}
