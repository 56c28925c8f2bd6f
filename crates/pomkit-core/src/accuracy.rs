//! Accuracy: how far each technique's hits land from the exact ones, and what they cost.
//!
//! The measure is the "error" of docs/ACCURACY.md: the distance in texels between a technique's hit
//! UV and the [`Technique::Exact`] hit UV for the same ray. [`compare`] traces a fixed random set
//! of rays per view angle ([`ray_set`], reproducible from a seed by the small [`SplitMix64`]
//! generator, so no random-number crate is needed) and reports, per technique and angle, the
//! mean, 95th percentile and share over one texel of that error, and the fetches per ray. This is
//! the table behind `pomkit compare`.
//!
//! [`yardstick`] is `pomkit compare --yardstick`: on the same rays, the fewest samples with which
//! `pom` (its least and most samples raised together) leaves no more than 0.1% of the rays over
//! one texel, without and with secant refinement, beside exact's fetches; the search over the
//! sample count is [`fewest_passing`].

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

/// The share over one texel `pom` may leave for the yardstick: 0.1% of the rays.
pub const YARDSTICK_SHARE: f64 = 0.001;

/// The smallest sample count the yardstick tries: pom's default `min_samples`.
pub const YARDSTICK_START: u32 = 8;

/// Secant refinement steps of the yardstick's refined search when none are asked for.
pub const YARDSTICK_REFINE: u32 = 2;

/// How many counts directly below the found one the yardstick's last step checks.
pub const YARDSTICK_WINDOW: u32 = 8;

/// What the yardstick looks for and how far ([`yardstick`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YardstickOptions {
    /// The largest share of rays over one texel that passes, in `[0, 1]` (default 0.001).
    pub max_share: f64,
    /// The first sample count tried (default 8).
    pub start: u32,
    /// The largest sample count tried, at most [`MAX_SAMPLES`](crate::trace::MAX_SAMPLES)
    /// (default 1024): a search that gets there without passing says "not reached".
    pub cap: u32,
    /// Counts directly below the found one that must fail before the search stops (default 8).
    pub window: u32,
    /// Secant refinement steps of the refined search (default 2; the plain search uses 0).
    pub refine: u32,
}

impl Default for YardstickOptions {
    fn default() -> Self {
        Self {
            max_share: YARDSTICK_SHARE,
            start: YARDSTICK_START,
            cap: crate::trace::MAX_SAMPLES,
            window: YARDSTICK_WINDOW,
            refine: YARDSTICK_REFINE,
        }
    }
}

/// One count tried by [`fewest_passing`], with what the evaluation gave there.
#[derive(Clone, Debug, PartialEq)]
pub struct Tried<T> {
    /// The count.
    pub n: u32,
    /// Whether it passed.
    pub passes: bool,
    /// What the evaluation returned.
    pub value: T,
}

/// The outcome of [`fewest_passing`].
#[derive(Clone, Debug, PartialEq)]
pub struct Search<T> {
    /// Every count evaluated, each once, in the order tried.
    pub tried: Vec<Tried<T>>,
    /// The index in `tried` of the count found: the smallest passing count tried. `None` when
    /// no count up to the cap passed ("not reached").
    pub found: Option<usize>,
}

impl<T> Search<T> {
    /// The count found and its evaluation, if any.
    #[must_use]
    pub fn found(&self) -> Option<&Tried<T>> {
        self.found.map(|i| &self.tried[i])
    }

    /// The evaluation at count `n`, if it was tried.
    #[must_use]
    pub fn at(&self, n: u32) -> Option<&Tried<T>> {
        self.tried.iter().find(|t| t.n == n)
    }

    /// The largest count tried (the cap when the search got there).
    #[must_use]
    pub fn largest(&self) -> Option<&Tried<T>> {
        self.tried.iter().max_by_key(|t| t.n)
    }
}

/// The fewest `n` in `start..=cap` whose evaluation passes, by a search that evaluates each
/// count at most once and always ends.
///
/// `passes` need not be monotone in `n` (pom's share over one texel is not: more samples move
/// every sample, and a sample that used to land on a thin feature can miss it). The search:
/// 1. **doubling**: `start`, `2 start`, `4 start`, ... (the last one `cap`) up to the first
///    count that passes; if even `cap` fails, nothing is found;
/// 2. **bisection** between the last failing count of the doubling and that first passing one,
///    keeping a failing lower and a passing upper end until they are adjacent;
/// 3. **linear check downward** from the passing end, one count at a time, until `window`
///    consecutive counts fail or `start` is reached; a count that passes on the way becomes the
///    answer and the check goes on below it.
///
/// So the count found passes, every count tried below it failed, and the `window` counts
/// directly below it (down to `start`) were all tried. A smaller passing count may exist beyond
/// that window: the answer is the fewest the search can vouch for, not a proven minimum. At
/// most `log2(cap / start) + 1` evaluations double, `log2(cap / 2)` bisect, and the linear
/// check stops after `window` failures (every pass it meets moves it at least one count down).
///
/// `start` is raised to 1 and `cap` to `start`.
pub fn fewest_passing<T>(
    start: u32,
    cap: u32,
    window: u32,
    mut evaluate: impl FnMut(u32) -> T,
    passes: impl Fn(&T) -> bool,
) -> Search<T> {
    let start = start.max(1);
    let cap = cap.max(start);
    let mut tried: Vec<Tried<T>> = Vec::new();
    let mut check = |n: u32, tried: &mut Vec<Tried<T>>| -> bool {
        if let Some(t) = tried.iter().find(|t| t.n == n) {
            return t.passes;
        }
        let value = evaluate(n);
        let ok = passes(&value);
        tried.push(Tried { n, passes: ok, value });
        ok
    };
    // 1. Doubling.
    let mut lo = None;
    let mut hi = start;
    loop {
        if check(hi, &mut tried) {
            break;
        }
        if hi == cap {
            return Search { tried, found: None };
        }
        lo = Some(hi);
        hi = hi.saturating_mul(2).min(cap);
    }
    // 2. Bisection: `lo` fails, `hi` passes.
    if let Some(mut lo) = lo {
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if check(mid, &mut tried) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
    }
    // 3. Linear check downward.
    let (mut n, mut fails) = (hi, 0);
    while n > start && fails < window {
        n -= 1;
        if check(n, &mut tried) {
            hi = n;
            fails = 0;
        } else {
            fails += 1;
        }
    }
    let found = tried.iter().position(|t| t.n == hi);
    Search { tried, found }
}

/// One of the yardstick's two searches: `pom` with `min_samples = max_samples = N` and
/// `refine` secant steps, the rows of every `N` tried.
#[derive(Clone, Debug, PartialEq)]
pub struct PomSearch {
    /// Secant refinement steps.
    pub refine: u32,
    /// pom's accuracy row at every count tried (technique [`Technique::Pom`]).
    pub search: Search<AccuracyRow>,
}

impl PomSearch {
    /// The fewest samples found to pass, if any.
    #[must_use]
    pub fn samples(&self) -> Option<u32> {
        self.search.found().map(|t| t.n)
    }

    /// pom's row at the count found, or at the largest count tried (the cap) when none passed.
    #[must_use]
    pub fn row(&self) -> &AccuracyRow {
        &self.search.found().or_else(|| self.search.largest()).expect("a search tries at least one count").value
    }

    /// pom's row one count below the count found, if the search tried it (always, unless the
    /// count found is the first one tried).
    #[must_use]
    pub fn row_below(&self) -> Option<&AccuracyRow> {
        let n = self.samples()?;
        self.search.at(n.checked_sub(1)?).map(|t| &t.value)
    }
}

/// The yardstick at one view angle: the fewest samples with which `pom` (min = max = N) leaves
/// no more than [`YardstickOptions::max_share`] of the rays over one texel, without and with
/// secant refinement, beside exact's cost on the same rays.
#[derive(Clone, Debug, PartialEq)]
pub struct YardstickRow {
    /// View angle from the normal, in degrees (a label when the rays were given).
    pub angle_deg: f32,
    /// Rays traced (the same rays for every count and for exact).
    pub rays: usize,
    /// The options searched with.
    pub options: YardstickOptions,
    /// pom without refinement.
    pub plain: PomSearch,
    /// pom with [`YardstickOptions::refine`] secant steps.
    pub refined: PomSearch,
    /// exact's row on the same rays (error 0; its fetches are the reference cost).
    pub exact: AccuracyRow,
}

impl YardstickRow {
    /// exact's mean fetches over the cheaper of the two pom counts found (by mean fetches):
    /// below 1 when exact is cheaper than the cheapest pom that meets the bar. `None` when
    /// neither search passed, or pom fetched nothing.
    #[must_use]
    pub fn ratio(&self) -> Option<f64> {
        let best = [&self.plain, &self.refined]
            .into_iter()
            .filter(|s| s.samples().is_some())
            .map(|s| s.row().mean_fetches)
            .min_by(f64::total_cmp)?;
        (best > 0.0).then(|| self.exact.mean_fetches / best)
    }
}

/// Progress of [`yardstick`]: reported before each count is traced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YardstickStep {
    /// The angle being searched.
    pub angle_deg: f32,
    /// The refinement steps of the search under way.
    pub refine: u32,
    /// The sample count about to be traced.
    pub samples: u32,
    /// Searches finished so far (two per angle in all).
    pub searches_done: usize,
}

/// The yardstick per angle of `angles_deg`, on [`ray_set`]`(angle, rays_per_angle, seed)`
/// (the rays [`compare`] traces): see [`yardstick_on_rays`]. `progress` is called on the
/// calling thread before each count is traced.
#[must_use]
pub fn yardstick(
    surface: &Surface,
    angles_deg: &[f32],
    params: &TraceParams,
    rays_per_angle: usize,
    seed: u64,
    options: &YardstickOptions,
    progress: &dyn Fn(YardstickStep),
) -> Vec<YardstickRow> {
    angles_deg
        .iter()
        .enumerate()
        .map(|(i, &angle)| {
            let rays = ray_set(angle, rays_per_angle, seed);
            let tick = |mut step: YardstickStep| {
                step.searches_done += 2 * i;
                progress(step);
            };
            yardstick_on_rays(surface, &rays, angle, params, options, &tick)
        })
        .collect()
}

/// The yardstick on the given rays (`angle_deg` only labels the rows): [`fewest_passing`] over
/// `pom`'s sample count N, with `min_samples = max_samples = N` and `refine` 0, then again
/// with [`YardstickOptions::refine`] steps, each count's errors measured against
/// [`Technique::Exact`]'s hits (traced once) as [`compare`] measures them. A count passes when
/// its share of rays over one texel is at most [`YardstickOptions::max_share`].
///
/// The other parameters of `params` are kept (pom reads only `lod` of them); the options'
/// `cap` is clamped to [`MAX_SAMPLES`](crate::trace::MAX_SAMPLES), which [`trace`] would
/// clamp to anyway, and `start` into `1..=cap`.
#[must_use]
pub fn yardstick_on_rays(
    surface: &Surface,
    rays: &[Ray],
    angle_deg: f32,
    params: &TraceParams,
    options: &YardstickOptions,
    progress: &dyn Fn(YardstickStep),
) -> YardstickRow {
    let (w, h) = (surface.field().width(), surface.field().height());
    let truths: Vec<Hit> = rays
        .par_chunks(CHUNK)
        .flat_map_iter(|c| c.iter().map(|r| trace(surface, r, Technique::Exact, params)))
        .collect();
    let mut zeros = vec![0.0; truths.len()];
    let exact = summarize(Technique::Exact, angle_deg, &mut zeros, truths.iter().map(|t| t.fetches));
    let cap = options.cap.min(crate::trace::MAX_SAMPLES);
    let start = options.start.clamp(1, cap.max(1));
    let search = |refine: u32, searches_done: usize| {
        let evaluate = |n: u32| {
            progress(YardstickStep { angle_deg, refine, samples: n, searches_done });
            let p = TraceParams { min_samples: n, max_samples: n, refine, ..*params };
            let samples: Vec<(f64, u32)> = rays
                .par_chunks(CHUNK)
                .zip(truths.par_chunks(CHUNK))
                .flat_map_iter(|(rs, ts)| {
                    rs.iter().zip(ts).map(|(ray, truth)| {
                        let hit = trace(surface, ray, Technique::Pom, &p);
                        (error_texels(&hit, truth, w, h), hit.fetches)
                    })
                })
                .collect();
            let mut errors: Vec<f64> = samples.iter().map(|s| s.0).collect();
            summarize(Technique::Pom, angle_deg, &mut errors, samples.iter().map(|s| s.1))
        };
        let search = fewest_passing(start, cap, options.window, evaluate, |row| row.share_over_1 <= options.max_share);
        PomSearch { refine, search }
    };
    let plain = search(0, 0);
    let refined = search(options.refine, 1);
    let options = YardstickOptions { start, cap, ..*options };
    YardstickRow { angle_deg, rays: rays.len(), options, plain, refined, exact }
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

    /// The counts `fewest_passing` tried, in order.
    fn ns<T>(s: &Search<T>) -> Vec<u32> {
        s.tried.iter().map(|t| t.n).collect()
    }

    /// What `fewest_passing` promises of its answer, checked against the predicate itself.
    fn check_promise<T>(s: &Search<T>, start: u32, window: u32, passes: impl Fn(u32) -> bool) {
        let mut seen = ns(s);
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), s.tried.len(), "a count evaluated twice: {:?}", ns(s));
        for t in &s.tried {
            assert_eq!(t.passes, passes(t.n), "count {} misjudged", t.n);
        }
        let Some(found) = s.found() else { return };
        assert!(passes(found.n), "{} reported but fails", found.n);
        for t in &s.tried {
            assert!(t.n >= found.n || !t.passes, "{} passed below the answer {}", t.n, found.n);
        }
        for n in found.n.saturating_sub(window).max(start)..found.n {
            assert!(s.at(n).is_some_and(|t| !t.passes), "{n}, within the window below {}, not tried", found.n);
        }
    }

    #[test]
    fn fewest_passing_finds_a_monotone_threshold() {
        let pow2: Vec<u32> = (3..=10).map(|k| 1 << k).collect();
        for threshold in [1u32, 7, 8, 9, 15, 16, 17, 100, 383, 511, 512, 513, 1000, 1023, 1024, 1025, 5000] {
            let passes = |n: u32| n >= threshold;
            let s = fewest_passing(8, 1024, 8, |n| n, |&n| passes(n));
            check_promise(&s, 8, 8, passes);
            match threshold {
                ..=8 => {
                    assert_eq!(s.found().map(|t| t.n), Some(8));
                    assert_eq!(ns(&s), [8], "8 passes: nothing else to try");
                }
                9..=1024 => assert_eq!(s.found().map(|t| t.n), Some(threshold), "threshold {threshold}"),
                _ => {
                    assert_eq!(s.found, None);
                    assert_eq!(ns(&s), pow2, "not reached: the doubling up to the cap only");
                }
            }
            // Doubling, bisection and the window, no more.
            assert!(s.tried.len() <= 8 + 9 + 8, "{} evaluations for {threshold}", s.tried.len());
        }
    }

    #[test]
    fn fewest_passing_checks_below_a_count_that_passes_by_luck() {
        // 57 passes alone below 60: bisection ends at 60 (59 fails) and the linear check finds 57.
        let passes = |n: u32| n == 57 || n >= 60;
        let s = fewest_passing(8, 1024, 8, |n| n, |&n| passes(n));
        check_promise(&s, 8, 8, passes);
        assert_eq!(s.found().map(|t| t.n), Some(57));
        assert_eq!(&ns(&s)[..4], [8, 16, 32, 64], "doubling first");
        // 50 passes alone, 10 below 60: beyond the window of eight, the search does not see it.
        let passes = |n: u32| n == 50 || n >= 60;
        let s = fewest_passing(8, 1024, 8, |n| n, |&n| passes(n));
        check_promise(&s, 8, 8, passes);
        assert_eq!(s.found().map(|t| t.n), Some(60));
        assert!(s.at(50).is_none());
        // A lucky pass in the doubling: bisection below it, then the window down to the floor.
        let passes = |n: u32| n == 16 || n >= 100;
        let s = fewest_passing(8, 1024, 8, |n| n, |&n| passes(n));
        check_promise(&s, 8, 8, passes);
        assert_eq!(s.found().map(|t| t.n), Some(16));
        let mut below: Vec<u32> = ns(&s).into_iter().filter(|&n| n < 16).collect();
        below.sort_unstable();
        assert_eq!(below, (8..16).collect::<Vec<_>>());
    }

    #[test]
    fn fewest_passing_always_ends() {
        let never = |_: &u32| false;
        assert_eq!(ns(&fewest_passing(8, 1024, 8, |n| n, never)), [8, 16, 32, 64, 128, 256, 512, 1024]);
        assert_eq!(ns(&fewest_passing(8, 100, 8, |n| n, never)), [8, 16, 32, 64, 100]);
        assert_eq!(ns(&fewest_passing(8, 3, 8, |n| n, never)), [8], "the cap is raised to the start");
        assert_eq!(ns(&fewest_passing(0, 2, 8, |n| n, never)), [1, 2], "the start is raised to 1");
        assert_eq!(ns(&fewest_passing(u32::MAX - 1, u32::MAX, 8, |n| n, never)), [u32::MAX - 1, u32::MAX]);
        // Every count passes: the first is the answer.
        let s = fewest_passing(8, 1024, 8, |n| n, |_| true);
        assert_eq!((ns(&s), s.found), (vec![8], Some(0)));
    }

    /// Uniformly spaced entry points along a row, all travelling along +u at 45 degrees.
    fn rays_along_u(count: usize, from_texel: f32, to_texel: f32, size: u32) -> Vec<Ray> {
        (0..count)
            .map(|k| {
                let x = from_texel + (to_texel - from_texel) * (k as f32 + 0.5) / count as f32;
                let v = (k as f32 * 0.618_034).fract();
                Ray::at_angle(Vec2::new(x / size as f32, v), 45f32.to_radians(), 0.0)
            })
            .collect()
    }

    /// The share of `rays` over one texel for pom with `n` samples and `refine` steps, by
    /// tracing here (not through the yardstick's code).
    fn direct_share(surface: &Surface, rays: &[Ray], n: u32, refine: u32) -> f64 {
        let p = TraceParams { min_samples: n, max_samples: n, refine, ..TraceParams::default() };
        let (w, h) = (surface.field().width(), surface.field().height());
        let over = rays
            .iter()
            .filter(|ray| {
                let truth = trace(surface, ray, Technique::Exact, &p);
                let hit = trace(surface, ray, Technique::Pom, &p);
                let du = (f64::from(hit.uv.x) - f64::from(truth.uv.x)) * f64::from(w);
                let dv = (f64::from(hit.uv.y) - f64::from(truth.uv.y)) * f64::from(h);
                du.hypot(dv) > 1.0
            })
            .count();
        over as f64 / rays.len() as f64
    }

    #[test]
    fn yardstick_on_a_flat_plane_passes_at_once_with_the_fetches_it_must_take() {
        // Depth 0.3: pom's entry sample, then samples at t = i / 8 until t >= 0.3, the third
        // (t = 0.375): 1 + ceil(0.3 * 8) = 4 fetches on every ray at every angle, plus one per
        // secant step; the linear intersection of a flat surface is exact.
        let c = 0.3f32;
        let surface = Surface::new(HeightField::constant(64, 64, c), EdgeMode::Wrap, 0.1);
        let params = TraceParams::default();
        let angles = [30.0, 60.0, 75.0, 85.0];
        for refine in [2, 3] {
            let options = YardstickOptions { refine, ..YardstickOptions::default() };
            let rows = yardstick(&surface, &angles, &params, 300, 4, &options, &|_| {});
            let table = compare(&surface, &[Technique::Exact], &angles, &params, 300, 4, &no_progress);
            assert_eq!(rows.len(), angles.len());
            let plain_fetches = 1.0 + (c * 8.0).ceil() as f64;
            for (row, exact) in rows.iter().zip(&table) {
                for (search, fetches) in
                    [(&row.plain, plain_fetches), (&row.refined, plain_fetches + f64::from(refine))]
                {
                    assert_eq!(search.samples(), Some(8), "{}°", row.angle_deg);
                    assert_eq!(ns(&search.search), [8], "8 passes: nothing else is traced");
                    let r = search.row();
                    assert_eq!((r.mean_fetches, f64::from(r.max_fetches)), (fetches, fetches), "{}°", row.angle_deg);
                    assert_eq!(r.share_over_1, 0.0);
                    assert!(r.mean_error < 1e-3, "{r:?}");
                    assert_eq!(search.row_below(), None, "nothing below the start");
                }
                assert_eq!(row.refined.refine, refine);
                // exact's cost, as compare measures it on the same rays.
                assert_eq!(&row.exact, exact);
                assert_eq!(row.ratio(), Some(exact.mean_fetches / plain_fetches));
            }
        }
    }

    /// A ridge two texels wide (depth 0) across a floor at depth 1, 256 texels square, depth
    /// scale 0.25, and rays at 45 degrees across it: they travel L = 64 texels from depth 0 to
    /// 1, and enter 16 to 48 texels before the ridge, so each meets it at a depth t between 1/4
    /// and 3/4. There the bilinear surface is at or above the ray over a stretch of
    /// W - 1 + 2t < 2.5 texels (the plateau between the two texel centres, and t on either
    /// side). pom's samples are L / N texels apart: with N <= 25 they are over 2.5 texels apart,
    /// longer than every ray's stretch, and of the rays meeting the ridge at depth t (their
    /// entry points are spread evenly) a share 1 - (1 + 2t) N / L puts no sample on it, some 20%
    /// in all; those find the floor at depth 1 past the ridge and land at least 15 texels from
    /// exact's hit. Refinement cannot bring back a ridge the linear search stepped over. So no
    /// N below L / 2.5, rounded up, 26, can pass, with or without refinement.
    fn ridge() -> (Surface, Vec<Ray>, u32) {
        let n = 256;
        let field = HeightField::from_height_fn(n, n, |x, _| if x == 200 || x == 201 { 1.0 } else { 0.0 });
        let surface = Surface::new(field, EdgeMode::Wrap, 0.25);
        let rays = rays_along_u(2000, 152.0, 184.0, n);
        (surface, rays, (64.0f32 / 2.5).ceil() as u32)
    }

    #[test]
    fn yardstick_on_a_ridge_needs_samples_closer_than_its_width() {
        let (surface, rays, bound) = ridge();
        // The analytic bound, checked by tracing directly: every N below it fails by far.
        for n in 8..bound {
            assert!(direct_share(&surface, &rays, n, 0) > 0.05, "N = {n} below the bound");
            assert!(direct_share(&surface, &rays, n, 2) > 0.05, "N = {n} (refine 2) below the bound");
        }
        let options = YardstickOptions::default();
        let steps = std::cell::RefCell::new(Vec::new());
        let row = yardstick_on_rays(&surface, &rays, 45.0, &TraceParams::default(), &options, &|s| {
            steps.borrow_mut().push(s);
        });
        assert_eq!(row.rays, 2000);
        for search in [&row.plain, &row.refined] {
            let refine = search.refine;
            let found = search.samples().unwrap_or_else(|| panic!("refine {refine}: not reached"));
            assert!(found >= bound, "refine {refine}: {found} below the analytic bound {bound}");
            check_promise(&search.search, 8, options.window, |n| {
                direct_share(&surface, &rays, n, refine) <= options.max_share
            });
            // The count found passes and the one below it fails, traced here.
            assert!(direct_share(&surface, &rays, found, refine) <= options.max_share);
            assert!(direct_share(&surface, &rays, found - 1, refine) > options.max_share);
            assert_eq!(search.row().share_over_1, direct_share(&surface, &rays, found, refine));
            assert_eq!(
                search.row_below().map(|r| r.share_over_1),
                Some(direct_share(&surface, &rays, found - 1, refine))
            );
        }
        assert_eq!(row.refined.refine, YARDSTICK_REFINE);
        // Progress: one step per count traced, in order, each search's own.
        let steps = steps.into_inner();
        assert_eq!(steps.len(), row.plain.search.tried.len() + row.refined.search.tried.len());
        let (plain, refined) = steps.split_at(row.plain.search.tried.len());
        assert!(
            plain
                .iter()
                .zip(&row.plain.search.tried)
                .all(|(s, t)| s.samples == t.n && s.refine == 0 && s.searches_done == 0)
        );
        assert!(
            refined
                .iter()
                .zip(&row.refined.search.tried)
                .all(|(s, t)| s.samples == t.n && s.refine == 2 && s.searches_done == 1)
        );
    }

    #[test]
    fn yardstick_below_the_bound_is_not_reached() {
        let (surface, rays, bound) = ridge();
        let options = YardstickOptions { cap: 16, ..YardstickOptions::default() };
        assert!(options.cap < bound);
        let row = yardstick_on_rays(&surface, &rays, 45.0, &TraceParams::default(), &options, &|_| {});
        for search in [&row.plain, &row.refined] {
            assert_eq!(search.samples(), None);
            assert_eq!(ns(&search.search), [8, 16]);
            // The row shown is the cap's, and it fails.
            assert_eq!(search.row(), &search.search.tried[1].value);
            assert_eq!(search.row().share_over_1, direct_share(&surface, &rays, 16, search.refine));
            assert!(search.row().share_over_1 > options.max_share);
            assert_eq!(search.row_below(), None);
        }
        assert_eq!(row.ratio(), None);
        // A cap above MAX_SAMPLES is held to it.
        let wide = YardstickOptions { cap: 5000, ..YardstickOptions::default() };
        let row = yardstick_on_rays(&surface, &rays[..10], 45.0, &TraceParams::default(), &wide, &|_| {});
        assert_eq!(row.options.cap, crate::trace::MAX_SAMPLES);
    }

    #[test]
    fn yardstick_rows_are_compare_rows_at_the_count_found() {
        // On 64x64 pyramids at 80 degrees one ray of 400 grazes a pyramid's edge where the
        // surface is above it for under 1/30 texel, which pom misses even with 1024 samples:
        // not reached, and the row shown is the cap's. At 60 degrees N = 10 passes where 12 to
        // 15 fail (the share is not monotone in N).
        let surface = Surface::new(procedural::generate(Pattern::Pyramids, 64, 64), EdgeMode::Wrap, 0.1);
        let params = TraceParams::default();
        let angles = [60.0, 80.0];
        let options = YardstickOptions { refine: 3, ..YardstickOptions::default() };
        let rows = yardstick(&surface, &angles, &params, 400, 2, &options, &|_| {});
        let found: Vec<[Option<u32>; 2]> = rows.iter().map(|r| [r.plain.samples(), r.refined.samples()]).collect();
        assert_eq!(found, [[Some(10), Some(10)], [None, None]]);
        for row in &rows {
            let at = |search: &PomSearch| {
                let n = search.samples().unwrap_or(options.cap);
                let p = TraceParams { min_samples: n, max_samples: n, refine: search.refine, ..params };
                compare(&surface, &[Technique::Pom], &[row.angle_deg], &p, 400, 2, &no_progress)
            };
            let plain = at(&row.plain);
            assert_eq!((row.plain.row(), &row.exact), (&plain[0], &plain[1]));
            let refined = at(&row.refined);
            assert_eq!((row.refined.row(), &row.exact), (&refined[0], &refined[1]));
            assert_eq!(row.refined.refine, 3);
            let best = plain[0].mean_fetches.min(refined[0].mean_fetches);
            let reached = row.plain.samples().is_some();
            assert_eq!(row.ratio(), reached.then(|| row.exact.mean_fetches / best));
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
