//! Accuracy: how far each technique's hits land from the exact ones, and what they cost.
//!
//! The measure is the "error" of docs/ACCURACY.md: the distance in texels between a technique's hit
//! UV and the [`Technique::Exact`] hit UV for the same ray. [`compare`] traces a fixed random set
//! of rays per view angle ([`ray_set`], reproducible from a seed by the small [`SplitMix64`]
//! generator, so no random-number crate is needed) and reports, per technique and angle, the
//! mean, 95th percentile and share over one texel of that error, and the fetches per ray. This is
//! the table behind `pomkit compare`.

use glam::Vec2;
use rayon::prelude::*;

use crate::heightfield::{EdgeMode, HeightField};
use crate::procedural::{Pattern, generate};
use crate::trace::{Hit, Ray, Surface, Technique, TraceParams, trace};

/// The first crossing of `ray` with the bilinear surface of `field`, found by a search that
/// shares nothing with the tracers: march the ray in steps of at most 1/100 texel of travel (and
/// at least 20 000 of them), sampling the surface in `f64`, then bisect the first step that went
/// under. Returns the depth of the crossing (0 where the ray starts under the surface, 1 where
/// it reaches the floor without crossing). The truth the `exact` and `cone` tracers are tested
/// against on the CPU and the GPU; slow (a few milliseconds a ray), so for tests and checks.
#[must_use]
pub fn brute_force_depth(field: &HeightField, edges: EdgeMode, ray: &Ray, depth_scale: f64) -> f64 {
    let dir = ray.dir.as_dvec3().normalize();
    let (w, h) = (f64::from(field.width()), f64::from(field.height()));
    let s = (dir.x * depth_scale / -dir.z * w, dir.y * depth_scale / -dir.z * h);
    let o = (f64::from(ray.uv.x) * w, f64::from(ray.uv.y) * h);
    let surf = |x: f64, y: f64| {
        let (x, y) = (x - 0.5, y - 0.5);
        let (i, j) = (x.floor(), y.floor());
        let (fx, fy) = (x - i, y - j);
        let d = |a: f64, b: f64| f64::from(field.depth_at(a as i64, b as i64, edges));
        let top = d(i, j) * (1.0 - fx) + d(i + 1.0, j) * fx;
        let bot = d(i, j + 1.0) * (1.0 - fx) + d(i + 1.0, j + 1.0) * fx;
        top * (1.0 - fy) + bot * fy
    };
    let below = |t: f64| t >= surf(o.0 + s.0 * t, o.1 + s.1 * t);
    let travel = (s.0 * s.0 + s.1 * s.1).sqrt();
    let steps = ((travel / 0.01).ceil() as usize).max(20_000);
    if below(0.0) {
        return 0.0;
    }
    let mut prev = 0.0;
    for k in 1..=steps {
        let t = k as f64 / steps as f64;
        if below(t) {
            let (mut lo, mut hi) = (prev, t);
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if below(mid) { hi = mid } else { lo = mid }
            }
            return hi;
        }
        prev = t;
    }
    1.0
}

/// Height fields of `n x n` texels whose surfaces are known in closed form, with their names:
/// flat, a tilted plane, a step, a pyramid, a sphere cap and a one-texel spike. The exact
/// tracers are checked on them against [`brute_force_depth`].
#[must_use]
pub fn analytic_fields(n: u32) -> Vec<(&'static str, HeightField)> {
    let c = n as f32 / 2.0;
    vec![
        ("flat", HeightField::constant(n, n, 0.6)),
        ("tilted plane", HeightField::from_height_fn(n, n, |x, _| 0.1 + 0.8 * x as f32 / (n - 1) as f32)),
        ("step", HeightField::from_height_fn(n, n, |x, _| if x < n / 2 { 0.8 } else { 0.2 })),
        (
            "pyramid",
            HeightField::from_height_fn(n, n, |x, y| {
                let r = ((x as f32 + 0.5 - c).abs()).max((y as f32 + 0.5 - c).abs());
                (1.0 - r / c).max(0.0)
            }),
        ),
        (
            "sphere cap",
            HeightField::from_height_fn(n, n, |x, y| {
                let r2 = ((x as f32 + 0.5 - c).powi(2) + (y as f32 + 0.5 - c).powi(2)) / (c * 0.8).powi(2);
                (1.0 - r2).max(0.0).sqrt()
            }),
        ),
        ("spike", generate(Pattern::Spike, n, n)),
    ]
}

/// The seed `pomkit compare` uses unless told otherwise.
pub const DEFAULT_SEED: u64 = 1;

/// Rays traced per unit of work handed to a thread (and per progress report).
const CHUNK: usize = 256;

/// SplitMix64 (Steele, Lea & Flood 2014, as in `java.util.SplittableRandom`): a tiny, fast
/// generator with a 64-bit state that passes BigCrush. Deterministic: the same seed always
/// gives the same sequence on every platform. Not for cryptography.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator started from `seed` (any value, 0 included).
    #[must_use]
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A uniform `f32` in `[0, 1)`: the top 24 bits, so every value is exactly representable
    /// and 1 is never returned.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// `count` rays entering at uniformly random UVs in `[0, 1)^2`, each travelling along a
/// uniformly random azimuth, all at `angle_deg` degrees from the normal ([`Ray::at_angle`]).
///
/// The UVs and azimuths depend only on `seed` (and `count`), not on the angle: the sets for
/// two angles with one seed differ only in how steeply the rays go in, so rows of a table
/// compare like with like. Angles of 90 degrees or more give rays that do not enter.
#[must_use]
pub fn ray_set(angle_deg: f32, count: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    let angle = angle_deg.to_radians();
    (0..count)
        .map(|_| {
            let uv = Vec2::new(rng.next_f32(), rng.next_f32());
            let azimuth = rng.next_f32() * std::f32::consts::TAU;
            Ray::at_angle(uv, angle, azimuth)
        })
        .collect()
}

/// One row of the accuracy table: one technique at one view angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccuracyRow {
    /// The technique measured.
    pub technique: Technique,
    /// View angle from the normal, in degrees.
    pub angle_deg: f32,
    /// Rays traced.
    pub rays: usize,
    /// Mean error in texels against [`Technique::Exact`] (0 when no ray was traced).
    pub mean_error: f64,
    /// 95th percentile of the error in texels (nearest rank: the smallest error that at least
    /// 95% of the rays do not exceed).
    pub p95_error: f64,
    /// Share of rays, in `[0, 1]`, whose error exceeds one texel.
    pub share_over_1: f64,
    /// Mean height fetches per ray.
    pub mean_fetches: f64,
    /// Most height fetches any one ray took.
    pub max_fetches: u32,
}

/// The error of `hit` against `truth`, in texels of a `width` x `height` field.
#[must_use]
pub fn error_texels(hit: &Hit, truth: &Hit, width: u32, height: u32) -> f64 {
    let du = (f64::from(hit.uv.x) - f64::from(truth.uv.x)) * f64::from(width);
    let dv = (f64::from(hit.uv.y) - f64::from(truth.uv.y)) * f64::from(height);
    (du * du + dv * dv).sqrt()
}

/// The accuracy table: for each angle of `angles_deg` (outer order) and each technique of
/// `techniques` (inner order, duplicates dropped), the error statistics of tracing
/// [`ray_set`]`(angle, rays_per_angle, seed)` against [`Technique::Exact`].
///
/// A row for `exact` itself is always reported, last in each angle's group if `techniques`
/// does not name it: its error is 0 by definition, and its fetches are the reference cost.
/// `progress` is called from worker threads with the number of rays just finished (each ray
/// counts once per angle, however many techniques trace it), so the total is
/// `angles_deg.len() * rays_per_angle`.
///
/// Parameters are used as given (and sanitized by [`trace`]); check them first with
/// [`TraceParams::validate`] to report bad input.
#[must_use]
pub fn compare(
    surface: &Surface,
    techniques: &[Technique],
    angles_deg: &[f32],
    params: &TraceParams,
    rays_per_angle: usize,
    seed: u64,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<AccuracyRow> {
    let mut list: Vec<Technique> = Vec::with_capacity(techniques.len() + 1);
    for &t in techniques.iter().chain(std::iter::once(&Technique::Exact)) {
        if !list.contains(&t) {
            list.push(t);
        }
    }
    let (w, h) = (surface.field().width(), surface.field().height());
    let mut rows = Vec::with_capacity(list.len() * angles_deg.len());
    for &angle in angles_deg {
        let rays = ray_set(angle, rays_per_angle, seed);
        // Ray-major, technique-minor (in `list` order): (error, fetches).
        let k = list.len();
        let samples: Vec<(f64, u32)> = rays
            .par_chunks(CHUNK)
            .map(|chunk| {
                let mut out = Vec::with_capacity(chunk.len() * k);
                for ray in chunk {
                    let truth = trace(surface, ray, Technique::Exact, params);
                    out.extend(list.iter().map(|&t| {
                        if t == Technique::Exact {
                            (0.0, truth.fetches)
                        } else {
                            let hit = trace(surface, ray, t, params);
                            (error_texels(&hit, &truth, w, h), hit.fetches)
                        }
                    }));
                }
                progress(chunk.len());
                out
            })
            .flatten_iter()
            .collect();
        for (j, &technique) in list.iter().enumerate() {
            let mut errors: Vec<f64> = samples.iter().skip(j).step_by(k).map(|s| s.0).collect();
            let fetches = samples.iter().skip(j).step_by(k).map(|s| s.1);
            rows.push(summarize(technique, angle, &mut errors, fetches));
        }
    }
    rows
}

/// Statistics of one technique's errors and fetches at one angle.
fn summarize(
    technique: Technique,
    angle_deg: f32,
    errors: &mut [f64],
    fetches: impl Iterator<Item = u32>,
) -> AccuracyRow {
    let n = errors.len();
    let (mut fetch_sum, mut max_fetches) = (0u64, 0u32);
    for f in fetches {
        fetch_sum += u64::from(f);
        max_fetches = max_fetches.max(f);
    }
    if n == 0 {
        return AccuracyRow {
            technique,
            angle_deg,
            rays: 0,
            mean_error: 0.0,
            p95_error: 0.0,
            share_over_1: 0.0,
            mean_fetches: 0.0,
            max_fetches,
        };
    }
    errors.sort_unstable_by(f64::total_cmp);
    // Nearest rank: the ceil(0.95 n)-th smallest (1-based).
    let rank = (n * 95).div_ceil(100).max(1);
    AccuracyRow {
        technique,
        angle_deg,
        rays: n,
        mean_error: errors.iter().sum::<f64>() / n as f64,
        p95_error: errors[rank - 1],
        share_over_1: errors.iter().filter(|&&e| e > 1.0).count() as f64 / n as f64,
        mean_fetches: fetch_sum as f64 / n as f64,
        max_fetches,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::{EdgeMode, HeightField};
    use crate::procedural::{self, Pattern};

    fn no_progress(_: usize) {}

    #[test]
    fn splitmix_matches_the_reference_sequence() {
        // First outputs for seed 1234567 from the reference implementation (Vigna's splitmix64.c).
        let mut r = SplitMix64::new(1_234_567);
        assert_eq!(r.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(r.next_u64(), 3_203_168_211_198_807_973);
        let mut r = SplitMix64::new(7);
        for _ in 0..10_000 {
            let x = r.next_f32();
            assert!((0.0..1.0).contains(&x));
        }
    }

    #[test]
    fn ray_set_is_deterministic_per_seed() {
        let a = ray_set(60.0, 100, 42);
        assert_eq!(a, ray_set(60.0, 100, 42));
        let b = ray_set(60.0, 100, 43);
        assert_eq!(b.len(), 100);
        assert!(a.iter().zip(&b).all(|(x, y)| x != y), "another seed gives other rays");
        // The same seed at another angle keeps the entry points.
        let c = ray_set(30.0, 100, 42);
        assert!(a.iter().zip(&c).all(|(x, y)| x.uv == y.uv && x.dir != y.dir));
        assert!(ray_set(10.0, 0, 1).is_empty());
    }

    #[test]
    fn ray_set_respects_the_angle_and_covers_the_tile() {
        for angle in [0.0f32, 30.0, 60.0, 75.0, 85.0] {
            let rays = ray_set(angle, 500, DEFAULT_SEED);
            let c = angle.to_radians().cos();
            let s = angle.to_radians().sin();
            let (mut sum_x, mut sum_y) = (0.0f32, 0.0f32);
            for r in &rays {
                assert!((r.dir.z + c).abs() < 1e-6, "{angle}: dz {} != -cos", r.dir.z);
                assert!((r.dir.length() - 1.0).abs() < 1e-5);
                assert!((r.dir.truncate().length() - s).abs() < 1e-5);
                assert!((0.0..1.0).contains(&r.uv.x) && (0.0..1.0).contains(&r.uv.y));
                sum_x += r.uv.x;
                sum_y += r.uv.y;
            }
            // Uniform UVs average about one half.
            assert!((sum_x / 500.0 - 0.5).abs() < 0.05 && (sum_y / 500.0 - 0.5).abs() < 0.05);
        }
    }

    #[test]
    fn flat_field_is_traced_exactly_by_the_marching_techniques() {
        // Depth 0.5 lies on a plane of the default 32-plane search, so steep is exact too.
        let c = 0.5;
        let params = TraceParams::default();
        let surface = Surface::new(HeightField::constant(64, 64, c), EdgeMode::Wrap, 0.1);
        let angles = [0.0, 30.0, 60.0, 75.0];
        let rows = compare(&surface, &Technique::ALL, &angles, &params, 200, 9, &no_progress);
        assert_eq!(rows.len(), angles.len() * Technique::ALL.len());
        for row in &rows {
            assert_eq!(row.rays, 200);
            let t = row.technique;
            if t.displaces() && !matches!(t, Technique::Parallax | Technique::Iterative) {
                assert!(row.mean_error < 0.01 && row.p95_error < 0.01, "{t} at {}: {row:?}", row.angle_deg);
                assert_eq!(row.share_over_1, 0.0);
            }
            if t == Technique::Exact {
                assert_eq!((row.mean_error, row.p95_error, row.share_over_1), (0.0, 0.0, 0.0));
                assert!(row.max_fetches > 0);
            }
        }
        for angle in angles {
            for ray in ray_set(angle, 50, 9) {
                let hit = trace(&surface, &ray, Technique::Exact, &params);
                assert!((hit.depth - c).abs() < 1e-4, "exact at {angle}: depth {}", hit.depth);
            }
        }
    }

    #[test]
    fn statistics_are_consistent_with_the_errors() {
        let params = TraceParams::default();
        let surface = Surface::new(procedural::generate(Pattern::Pyramids, 64, 64), EdgeMode::Wrap, 0.1);
        let angles = [0.0, 60.0, 85.0];
        let total = std::sync::atomic::AtomicUsize::new(0);
        let count = |n: usize| {
            total.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        };
        let rows = compare(&surface, &[Technique::Pom, Technique::Steep], &angles, &params, 700, 5, &count);
        assert_eq!(total.into_inner(), angles.len() * 700);
        // Exact is appended to a list that lacks it.
        let names: Vec<&str> = rows.iter().map(|r| r.technique.name()).collect();
        assert_eq!(names, ["pom", "steep", "exact"].repeat(angles.len()));
        for row in &rows {
            // Independent path: trace the same rays again here.
            let rays = ray_set(row.angle_deg, 700, 5);
            let mut max_err = 0.0f64;
            let mut max_f = 0;
            for ray in &rays {
                let truth = trace(&surface, ray, Technique::Exact, &params);
                let hit = trace(&surface, ray, row.technique, &params);
                let e = error_texels(&hit, &truth, 64, 64);
                assert!(e >= 0.0 && e.is_finite());
                max_err = max_err.max(e);
                max_f = max_f.max(hit.fetches);
            }
            assert!(row.mean_error >= 0.0 && row.p95_error >= 0.0);
            assert!(row.p95_error <= max_err && row.mean_error <= max_err, "{row:?} max {max_err}");
            assert!((0.0..=1.0).contains(&row.share_over_1));
            assert_eq!(row.max_fetches, max_f);
            assert!(row.mean_fetches <= f64::from(row.max_fetches));
            assert!(row.max_fetches <= row.technique.fetch_bound(&params, &surface));
        }
    }

    #[test]
    fn percentile_is_nearest_rank() {
        let mut e: Vec<f64> = (1..=20).map(f64::from).rev().collect();
        let r = summarize(Technique::Pom, 0.0, &mut e, [1, 5, 3].into_iter());
        assert_eq!(r.p95_error, 19.0);
        assert_eq!(r.mean_error, 10.5);
        assert_eq!(r.share_over_1, 19.0 / 20.0);
        assert_eq!(r.max_fetches, 5);
        let mut one = vec![0.25];
        assert_eq!(summarize(Technique::Pom, 0.0, &mut one, std::iter::once(2)).p95_error, 0.25);
        let empty = summarize(Technique::Pom, 0.0, &mut [], std::iter::empty());
        assert_eq!((empty.rays, empty.mean_error, empty.p95_error), (0, 0.0, 0.0));
    }
}
