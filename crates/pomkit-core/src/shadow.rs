//! Self-shadowing from the displaced point toward the light, and the level-of-detail fade.
//!
//! Sources: Brawley & Tatarchuk 2004 ("Self-Occlusion and Shadowing Computation": any sample of
//! the profile above the light ray shadows the point), McGuire 2005 (shadow rays marched like
//! view rays), Tatarchuk 2006 sections 3.2 (soft shadows by penumbra estimation; skip where
//! N.L < 0) and 3.3 (LOD fade to normal mapping); McGuire 2005's fur and grass, after Lengyel,
//! Praun, Finkelstein and Hoppe 2001 (self-shadowing that grows with depth, no shadow ray). The
//! sources are listed in docs/REFERENCES.md.
//!
//! The light direction uses the ray convention of [`crate::trace()`]: `(du, dv, dz)` *toward* the
//! light, with `dz > 0` for a light above the surface. Visibility is 1 for lit, 0 for shadowed.

use glam::{DVec3, Vec2, Vec3};

use crate::heightfield::EdgeMode;
pub use crate::modes::ShadowMode;
pub use crate::trace::shadow_march::{Shadow, ShadowMarch};
use crate::trace::{MIN_COS, Surface, Technique, TraceParams, adaptive_samples, exact_first_hit, unit_direction};

impl ShadowMode {
    /// The most fetches one [`shadow`] call may make in this mode with `params` on `surface`:
    /// 0 for `none` and `depth`; `max_samples` for `hard` and `soft` (the receiver's lift and
    /// samples `1..n` with `n <= max_samples <= MAX_SAMPLES`); for `exact`, the exact tracer's bound
    /// ([`Surface::exact_fetch_bound`], which counts the fetch that lifts the receiver).
    #[must_use]
    pub fn fetch_bound(self, params: &TraceParams, surface: &Surface) -> u32 {
        let p = params.sanitized();
        match self {
            ShadowMode::None | ShadowMode::Depth => 0,
            ShadowMode::Hard | ShadowMode::Soft => p.max_samples,
            ShadowMode::Exact => Technique::Exact.fetch_bound(&p, surface),
        }
    }
}

/// Shadow parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowParams {
    /// The mode.
    pub mode: ShadowMode,
    /// `soft`: the light's angular radius in radians. Larger gives wider, lighter penumbrae;
    /// 0 tends to a hard shadow. Default 0.1 (about 6 degrees, a large soft light).
    pub softness: f32,
}

impl ShadowParams {
    /// The defaults, from the parameter table ([`crate::params`]; evaluated when building).
    pub const DEFAULT: Self = Self { mode: ShadowMode::None, softness: crate::table::SOFTNESS.default.f32() };
}

impl Default for ShadowParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Light visibility at the displaced point `(uv, depth)` toward `light` (tangent-space
/// direction toward the light, `dz > 0` above the surface).
///
/// Where the geometric N.L <= 0 the polygon faces away from the light: visibility 0 with no
/// fetch (Tatarchuk 2006 skips the trace there). `depth` mode gives `1 - depth` (the depth
/// clamped to `[0, 1]`) with no fetch. Samples use `params.lod` and the pom sample
/// bounds, adapted to the light's angle as view rays are. `light` need not be unit length: any
/// finite, non-zero vector is normalized ([`unit_direction`]); a zero or non-finite one gives
/// visibility 1 with no fetch. Where the edges wrap, `uv` is first reduced to its tile (as
/// [`crate::trace::trace`] does), so huge UVs cost what small ones do. Every loop is bounded:
/// `hard`/`soft` take `n - 1 < MAX_SAMPLES` samples, `exact` at most
/// [`ShadowMode::fetch_bound`] fetches.
#[must_use]
pub fn shadow(
    surface: &Surface,
    uv: Vec2,
    depth: f32,
    light: Vec3,
    shadow: &ShadowParams,
    params: &TraceParams,
) -> Shadow {
    match shadow_start(surface, uv, depth, light, shadow, params) {
        ShadowStart::Done(s) => s,
        ShadowStart::March(m) => m.run(surface),
    }
}

/// Where [`shadow`] stands after its checks: answered already, or a hard or soft march still to
/// run ([`ShadowMarch::run`], or eight at once with [`crate::trace::packet::shadow_marches`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ShadowStart {
    /// The visibility, found without a march (or by the exact tracer).
    Done(Shadow),
    /// A `hard` or `soft` shadow ray to march.
    March(ShadowMarch),
}

/// The checks of [`shadow`], and the exact shadow; the hard and soft marches are returned to
/// run.
#[must_use]
pub fn shadow_start(
    surface: &Surface,
    uv: Vec2,
    depth: f32,
    light: Vec3,
    shadow: &ShadowParams,
    params: &TraceParams,
) -> ShadowStart {
    let done = |visibility: f32, fetches: u32| ShadowStart::Done(Shadow { visibility, fetches });
    let Some(l) = unit_direction(light) else {
        return done(1.0, 0);
    };
    if l.z <= 0.0 {
        return done(0.0, 0);
    }
    let l = l.as_vec3();
    // The point in its own tile where the surface repeats (the result is a visibility, so the
    // tile offset is not needed back).
    let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
    let uv = match surface.edges() {
        EdgeMode::Wrap => (uv.as_dvec2() - uv.as_dvec2().floor()).as_vec2(),
        EdgeMode::Clamp => uv,
    };
    let depth = if depth.is_finite() { depth.clamp(0.0, 1.0) } else { 0.0 };
    if shadow.mode == ShadowMode::None || depth <= 0.0 {
        // Nothing lies above the polygon's surface: a point on it is never self-shadowed.
        return done(1.0, 0);
    }
    let p = params.sanitized();
    // UV offset per unit of depth climbed toward the light.
    let s = Vec2::new(l.x, l.y) * (surface.depth_scale() / l.z.max(MIN_COS));
    match shadow.mode {
        ShadowMode::None => done(1.0, 0),
        // McGuire 2005's fur and grass: darker the deeper, no light ray.
        ShadowMode::Depth => done(1.0 - depth, 0),
        ShadowMode::Hard | ShadowMode::Soft => {
            // The receiver lifted onto the surface the march reads (one fetch): a hit below it
            // (steep parallax stops up to one layer deep, pom's linear segments cut under
            // convex slopes, the exact hit lies on mip 0 while the march reads mip `lod`) would
            // start the ray inside the relief and shadow itself in dashes along the tops.
            let depth = depth.min(surface.depth(uv, p.lod));
            if depth <= 0.0 {
                return done(1.0, 1);
            }
            // Samples at climbed depths t_i = depth * i / n, i = 1 .. n - 1: the last point lies
            // on the polygon's surface, which nothing rises above.
            let n = adaptive_samples(l.z, p.min_samples, p.max_samples);
            // The light's elevation above the tangent plane, and the horizontal distance
            // (in depth units) covered per unit climbed.
            let tan_theta = (1.0 - l.z * l.z).max(0.0).sqrt() / l.z;
            ShadowStart::March(ShadowMarch {
                uv,
                depth,
                s,
                n,
                soft: shadow.mode == ShadowMode::Soft,
                tan_theta,
                light_elevation: (1.0f32).atan2(tan_theta),
                rho: if shadow.softness.is_finite() { shadow.softness.max(1e-4) } else { 0.1 },
                lod: p.lod,
            })
        }
        ShadowMode::Exact => {
            let f = surface.field();
            let size = (f64::from(f.width()), f64::from(f.height()));
            // The receiver may lie below the exact surface: an approximate technique's hit
            // (pom's linear segments cut under the bilinear surface) or a coarser mip's. An
            // exact ray from there starts inside the relief and shadows itself in speckles, so
            // lift it onto the exact surface (one fetch), then a hair above it.
            let on_surface = depth.min(f.sample_bilinear(uv, surface.edges()));
            if on_surface <= 0.0 {
                // Lifted onto the polygon's surface, which nothing rises above (a walk from
                // there would stop at once on the surface it starts on).
                return done(1.0, 1);
            }
            let eps = 1e-5;
            let z0 = (f64::from(on_surface) - eps).max(0.0);
            let o = DVec3::new(f64::from(uv.x) * size.0, f64::from(uv.y) * size.1, z0);
            let d = DVec3::new(f64::from(s.x) * size.0, f64::from(s.y) * size.1, -1.0);
            let r = exact_first_hit(surface, o, d, eps.min(z0), z0);
            done(if r.t.is_some() { 0.0 } else { 1.0 }, r.fetches + 1)
        }
    }
}

/// Weight of the full parallax result in Tatarchuk 2006's LOD fade (section 3.3): 1 up to one
/// level below `threshold`, 0 from `threshold` on (normal mapping only), and the fractional
/// mip level in between, so the blend is continuous. Non-finite input gives 1 (full effect).
#[must_use]
pub fn lod_weight(mip_level: f32, threshold: f32) -> f32 {
    let w = threshold - mip_level;
    if w.is_finite() { w.clamp(0.0, 1.0) } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::{EdgeMode, HeightField};

    #[test]
    fn depth_shadow_is_one_minus_the_depth_with_no_fetch() {
        let p = ShadowParams { mode: ShadowMode::Depth, softness: 0.1 };
        for d in [0.0f32, 0.1, 0.25, 0.5, 0.8, 1.0] {
            // On a flat field at depth d the point lies on the surface: nothing above it could
            // shadow it (hard shadows say 1), but fur darkens with depth: 1 - d.
            let s = Surface::new(HeightField::constant(16, 16, d), EdgeMode::Wrap, 0.1);
            for (uv, light) in [
                (Vec2::new(0.3, 0.7), Vec3::new(0.6, 0.2, 0.5)),
                (Vec2::new(-3.2, 17.9), Vec3::new(0.0, 0.0, 1.0)),
                (Vec2::new(0.99, 0.01), Vec3::new(-5.0, 3.0, 0.01)),
            ] {
                let sh = shadow(&s, uv, d, light, &p, &TraceParams::default());
                assert_eq!(sh.fetches, 0, "depth {d}");
                assert!((sh.visibility - (1.0 - d)).abs() < 1e-6, "depth {d}: {sh:?}");
                let hard = ShadowParams { mode: ShadowMode::Hard, ..p };
                assert_eq!(shadow(&s, uv, d, light, &hard, &TraceParams::default()).visibility, 1.0);
            }
            // The polygon facing away from the light (N.L <= 0): 0, as every mode.
            for light in [Vec3::new(0.3, 0.2, 0.0), Vec3::new(0.3, -0.2, -0.5)] {
                assert_eq!(
                    shadow(&s, Vec2::splat(0.5), d, light, &p, &TraceParams::default()),
                    Shadow { visibility: 0.0, fetches: 0 }
                );
            }
        }
        // The receiver's depth counts, not the field's: a hit below a coarser mip's surface, or
        // out of range, is clamped to [0, 1].
        let s = Surface::new(HeightField::constant(8, 8, 0.2), EdgeMode::Clamp, 0.1);
        for (d, vis) in [(0.7, 0.3), (-0.5, 1.0), (1.5, 0.0), (f32::NAN, 1.0)] {
            let sh = shadow(&s, Vec2::splat(0.5), d, Vec3::Z, &p, &TraceParams::default());
            assert!((sh.visibility - vis).abs() < 1e-6 && sh.fetches == 0, "depth {d}: {sh:?}");
        }
        assert_eq!(ShadowMode::Depth.fetch_bound(&TraceParams::default(), &s), 0);
        assert_eq!("Depth".parse::<ShadowMode>(), Ok(ShadowMode::Depth));
        let err = "blurry".parse::<ShadowMode>().unwrap_err();
        assert!(ShadowMode::ALL.iter().all(|m| err.contains(m.name())), "{err}");
    }

    #[test]
    fn every_shadow_ray_lifts_a_receiver_below_the_surface() {
        let modes = [ShadowMode::Hard, ShadowMode::Soft, ShadowMode::Exact];
        let light = Vec3::new(0.6, 0.2, 0.5);
        let t = TraceParams::default();
        for mode in modes {
            let p = ShadowParams { mode, softness: 0.1 };
            // A flat surface at depth 0.5 (or 0, the polygon's own) with nothing above it: a
            // receiver reported below it (as an approximate technique's hit can be) is lit, not
            // shadowed by the surface it lies on.
            for level in [0.5, 0.0] {
                let s = Surface::new(HeightField::constant(16, 16, level), EdgeMode::Wrap, 0.1);
                for depth in [level, level + 0.05, 0.8] {
                    let sh = shadow(&s, Vec2::new(0.3, 0.7), depth, light, &p, &t);
                    assert_eq!(sh.visibility, 1.0, "{mode:?}: receiver at depth {depth} under a plane at {level}");
                    assert!(sh.fetches <= mode.fetch_bound(&t, &s), "{mode:?}: {} fetches", sh.fetches);
                }
            }
            // A real blocker still shadows: a wall toward the light, higher than the receiver.
            let wall =
                HeightField::from_depths(16, 16, (0..256).map(|i| if i % 16 == 8 { 0.0 } else { 0.5 }).collect())
                    .expect("valid field");
            let s = Surface::new(wall, EdgeMode::Wrap, 0.1);
            let sh = shadow(&s, Vec2::new(6.5 / 16.0, 0.5), 0.55, Vec3::new(1.0, 0.0, 0.1), &p, &t);
            assert_eq!(sh.visibility, 0.0, "{mode:?}");
        }
    }
}
