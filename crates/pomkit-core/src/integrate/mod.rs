//! Height from a normal map: least-squares integration of the gradient field that a
//! tangent-space normal map implies (`pomkit bake height`).
//!
//! # Conventions
//! The inverse of [`crate::bake`]: a normal `n` (+Y up, pomkit's tangent space) gives the
//! slopes of the height `z`, measured in texel widths, as
//! `dz/dx = -n.x / n.z` along the columns and `dz/dy = -n.y / n.z` up the image, so down the
//! rows (`v`, the row index) `dz/drow = +n.y / n.z` ([`slopes`]). `bake normal --scale s`
//! followed by this integration gives back `s` times the height map, up to a constant.
//!
//! # The problem
//! Each pair of 4-neighbours `a`, `b` (b to the right of or below a) is an edge `e` with a
//! target difference `g_e`, the mean of the two texels' slopes along it (the trapezoidal rule),
//! and a weight `w_e`. The heights minimize `sum_e w_e (z_b - z_a - g_e)^2`: the normal
//! equations are `D^T W D z = D^T W g`, with `D` the difference operator of the edges.
//!
//! - [`IntegrateMethod::Poisson`] takes every weight 1: the discrete Poisson equation, solved
//!   exactly by FFT (wrap, tiling maps: Frankot and Chellappa's projection in its discrete
//!   form) or DCT (clamp, Neumann boundaries), see `poisson.rs`.
//! - [`IntegrateMethod::Weighted`] is bilateral normal integration (Cao et al. 2022,
//!   docs/REFERENCES.md) on this grid: each texel lends its slope to its forward and backward
//!   edge along each axis with weights `w+ = sigmoid(k ((D- z)^2 - (D+ z)^2))` and
//!   `w- = 1 - w+`, so that beside a steep step a texel's slope goes to the side its surface
//!   continues on instead of being spread across the step. The weights depend on `z`: they are
//!   recomputed from the current heights a few times (iteratively reweighted least squares),
//!   and each weighted system is solved by conjugate gradients preconditioned by the Poisson
//!   solve, from the Poisson heights, within a bounded number of iterations. The weights do not
//!   conserve the sum of the slopes across a step, so the result's amplitude is fitted back to
//!   the slopes (the factor whose heights' differences best match the edges' targets). The
//!   weights are scale-free (relative differences), so a relief's depth does not change them.
//!
//! The heights are returned in texel widths with the lowest at 0 ([`Integrated`]), from which
//! come the normalized map (white = high) and the `depth_scale` the normals imply.

mod poisson;

use glam::Vec3;
use rayon::prelude::*;

use crate::heightfield::{EdgeMode, HeightField};
use crate::memory::{MemoryError, try_vec};
use poisson::Poisson;

/// The steepest slope, in texel widths per texel, that a normal gives: a normal whose `z` is
/// below `1 / MAX_SLOPE` (steeper than 89.4 degrees, horizontal included) is read as this
/// slope. An 8-bit map's steepest normal that is not horizontal has `z = 1/127.5`.
pub const MAX_SLOPE: f32 = 100.0;

/// The default bound on conjugate-gradient iterations of [`IntegrateMethod::Weighted`].
pub const DEFAULT_ITERATIONS: u32 = 120;

/// How many times [`IntegrateMethod::Weighted`] recomputes its weights.
const REWEIGHTS: u32 = 6;

/// The sharpness `k` of the bilateral weights: `w+ = sigmoid(k (b^2 - f^2) / (b^2 + f^2 + eps))`
/// for the backward and forward differences `b`, `f` (texel widths), so that only differences
/// unlike in size (a step beside a flat) make a texel lend its slope to one side.
const BILATERAL_K: f32 = 4.0;

/// The `eps` of [`BILATERAL_K`]'s weights, in squared texel widths: differences much below
/// 0.1 texel widths count as equal.
const BILATERAL_EPS: f32 = 0.01;

/// The least edge weight of the weighted solve: keeps the system's condition (and so the
/// number of iterations the Poisson preconditioner needs) bounded.
const MIN_EDGE_WEIGHT: f32 = 0.02;

/// The relative residual at which a weighted system counts as solved.
const CG_TOLERANCE: f64 = 1e-5;

/// How the heights are solved for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum IntegrateMethod {
    /// Plain least squares, every edge weighted 1: one FFT or DCT Poisson solve. Smooth, but
    /// spreads the error of steep steps over their neighbourhood. The default: it measures
    /// better overall (docs/ACCURACY.md, "Height from a normal map").
    #[default]
    Poisson,
    /// Bilateral weights near discontinuities, solved iteratively (see the module docs):
    /// sharper steps where the normals were not made from the heights by central differences.
    Weighted,
}

impl IntegrateMethod {
    /// The name used on the command line (`poisson`, `weighted`).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            IntegrateMethod::Poisson => "poisson",
            IntegrateMethod::Weighted => "weighted",
        }
    }
}

/// Options of [`integrate_normals`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegrateOptions {
    /// Wrap (a tiling map, the default: its slopes continue across the borders) or clamp (no
    /// slope is taken across a border).
    pub edges: EdgeMode,
    /// The solve. Default [`IntegrateMethod::Poisson`].
    pub method: IntegrateMethod,
    /// The most conjugate-gradient iterations of the weighted solve, over all its reweightings
    /// (each costs about one Poisson solve). Default [`DEFAULT_ITERATIONS`].
    pub max_iterations: u32,
}

impl Default for IntegrateOptions {
    fn default() -> Self {
        Self { edges: EdgeMode::Wrap, method: IntegrateMethod::Poisson, max_iterations: DEFAULT_ITERATIONS }
    }
}

impl IntegrateOptions {
    /// The units of work [`integrate_normals`] reports to its progress callback in all: one per
    /// Poisson solve or conjugate-gradient iteration. It may finish early (converged) and then
    /// reports the rest at once.
    #[must_use]
    pub fn work_units(&self) -> u64 {
        match self.method {
            IntegrateMethod::Poisson => 1,
            IntegrateMethod::Weighted => 1 + u64::from(self.max_iterations),
        }
    }

    /// An upper bound of the bytes [`integrate_normals`] allocates for a `width` x `height`
    /// map (besides the normals it is given): the slopes, the heights, the Poisson solve's
    /// scratch space and, weighted, the edges and the conjugate-gradient vectors.
    #[must_use]
    pub fn bytes(&self, width: u32, height: u32) -> u64 {
        let n = u64::from(width) * u64::from(height);
        let f32s = match self.method {
            // Slopes (2), right-hand side and heights (2).
            IntegrateMethod::Poisson => 4,
            // Slopes (2), edge weights and targets (4), heights, residual, search direction,
            // preconditioned residual, operator output (5).
            IntegrateMethod::Weighted => 11,
        };
        n * 4 * f32s + Poisson::scratch_bytes(width, height, self.edges)
    }
}

/// Why a normal map cannot be integrated.
#[derive(Debug, thiserror::Error)]
pub enum IntegrateError {
    /// Fewer than 2 texels on a side: no slope between two texels.
    #[error("the normal map is {width}x{height}: at least 2x2 texels are needed to integrate slopes")]
    TooSmall {
        /// Width in texels.
        width: u32,
        /// Height in texels.
        height: u32,
    },
    /// The normals do not hold one vector per texel.
    #[error("{got} normals were given for a {width}x{height} map")]
    Size {
        /// Width in texels.
        width: u32,
        /// Height in texels.
        height: u32,
        /// Normals given.
        got: usize,
    },
    /// A normal that gives no slope: not finite, zero, or pointing into the surface.
    #[error("the normal at texel ({x}, {y}) is {value:?}: {reason}")]
    BadNormal {
        /// Column.
        x: u32,
        /// Row.
        y: u32,
        /// The vector.
        value: [f32; 3],
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A buffer could not be allocated.
    #[error(transparent)]
    Memory(#[from] MemoryError),
}

/// Heights integrated from a normal map.
#[derive(Clone, Debug)]
pub struct Integrated {
    width: u32,
    height: u32,
    /// Texel widths, lowest 0.
    heights: Vec<f32>,
    iterations: u32,
}

impl Integrated {
    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The heights in texel widths, row-major, the lowest 0.
    #[must_use]
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The height range in texel widths: how far the highest texel stands above the lowest.
    #[must_use]
    pub fn range(&self) -> f32 {
        self.heights.iter().copied().fold(0.0, f32::max)
    }

    /// The range as a `depth_scale` (UV units, ARCHITECTURE.md, Conventions): the range over the
    /// width in texels. A material drawing the normalized map with this `depth_scale` has the
    /// relief the normals describe.
    #[must_use]
    pub fn depth_scale(&self) -> f32 {
        self.range() / self.width as f32
    }

    /// Conjugate-gradient iterations run (0 for [`IntegrateMethod::Poisson`]).
    #[must_use]
    pub fn iterations(&self) -> u32 {
        self.iterations
    }

    /// The heights scaled to `[0, 1]` (white = high); all 0 for a flat map.
    #[must_use]
    pub fn normalized(&self) -> Vec<f32> {
        let range = self.range();
        let inv = if range > 0.0 { 1.0 / range } else { 0.0 };
        self.heights.iter().map(|&z| (z * inv).clamp(0.0, 1.0)).collect()
    }

    /// The normalized heights as a [`HeightField`] (depth `1 - h`).
    #[must_use]
    pub fn to_height_field(&self) -> HeightField {
        HeightField::from_heights(self.width, self.height, self.normalized()).expect("sizes checked on integration")
    }
}

/// How close integrated heights come to true ones: Pearson's r, and the RMS of the difference
/// once both means are taken out (the unknown constant of an integration), over two equally long
/// lists (docs/ACCURACY.md, "Height from a normal map"). NaN when either list is constant.
#[must_use]
pub fn height_agreement(got: &[f32], truth: &[f32]) -> (f64, f64) {
    let n = got.len() as f64;
    let mg = got.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let mt = truth.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let (mut sgt, mut sgg, mut stt, mut sd) = (0.0, 0.0, 0.0, 0.0);
    for (&g, &t) in got.iter().zip(truth) {
        let (g, t) = (f64::from(g) - mg, f64::from(t) - mt);
        sgt += g * t;
        sgg += g * g;
        stt += t * t;
        sd += (g - t) * (g - t);
    }
    (sgt / (sgg * stt).sqrt(), (sd / n).sqrt())
}

/// The slopes `(dz/dx, dz/drow)` of a unit tangent-space normal (+Y up), in texel widths per
/// texel: `(-n.x / n.z, n.y / n.z)`, with `n.z` kept at least `1 / MAX_SLOPE` and each slope
/// within `MAX_SLOPE` in magnitude.
#[inline]
#[must_use]
pub fn slopes(n: Vec3) -> (f32, f32) {
    let z = n.z.max(1.0 / MAX_SLOPE);
    ((-n.x / z).clamp(-MAX_SLOPE, MAX_SLOPE), (n.y / z).clamp(-MAX_SLOPE, MAX_SLOPE))
}

/// Integrates a tangent-space normal map (+Y up, unit vectors, row-major) into heights.
///
/// `progress(units)` is called as work finishes, [`IntegrateOptions::work_units`] in all.
///
/// # Errors
/// [`IntegrateError::TooSmall`] below 2x2, [`IntegrateError::Size`] when `normals` is not
/// `width * height` long, [`IntegrateError::BadNormal`] for a non-finite or zero normal or
/// one pointing into the surface (`z < -1/127.5` of its length, as pomkit-io's loader
/// refuses), [`IntegrateError::Memory`] when a buffer cannot be allocated.
pub fn integrate_normals(
    width: u32,
    height: u32,
    normals: &[Vec3],
    opts: &IntegrateOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Integrated, IntegrateError> {
    if width < 2 || height < 2 {
        return Err(IntegrateError::TooSmall { width, height });
    }
    let n = width as usize * height as usize;
    if normals.len() != n {
        return Err(IntegrateError::Size { width, height, got: normals.len() });
    }
    let alloc = |what: &str, count: usize| {
        try_vec(0.0f32, count).map_err(|e| MemoryError::Allocation {
            what: format!("{what} of a {width}x{height} normal map"),
            bytes: crate::memory::bytes_of::<f32>(count as u64),
            reason: e.to_string(),
            advice: "integrate a smaller normal map".to_owned(),
        })
    };
    let mut p = alloc("the slopes", n)?;
    let mut q = alloc("the slopes", n)?;
    for (i, m) in normals.iter().enumerate() {
        let bad = |reason| IntegrateError::BadNormal {
            x: (i % width as usize) as u32,
            y: (i / width as usize) as u32,
            value: m.to_array(),
            reason,
        };
        if !m.is_finite() {
            return Err(bad("normals must be finite"));
        }
        let len = m.length();
        if len <= 1e-6 {
            return Err(bad("a zero vector is no direction"));
        }
        if m.z < -len / 127.5 {
            return Err(bad("it points into the surface (z < 0)"));
        }
        (p[i], q[i]) = slopes(*m / len);
    }
    let grid = Grid { w: width as usize, h: height as usize, edges: opts.edges };
    let mut solver = Poisson::new(width, height, opts.edges)?;
    let mut z = alloc("the heights", n)?;
    // The plain problem: weights 1, trapezoidal targets.
    grid.plain_rhs(&p, &q, &mut z);
    solver.solve(&mut z);
    progress(1);
    let mut iterations = 0;
    if opts.method == IntegrateMethod::Weighted && opts.max_iterations > 0 {
        iterations = grid.weighted(&p, &q, &mut z, &mut solver, opts.max_iterations, progress, &alloc)?;
    }
    drop((p, q));
    let low = z.par_iter().copied().reduce(|| f32::INFINITY, f32::min);
    z.par_iter_mut().for_each(|v| *v -= low);
    Ok(Integrated { width, height, heights: z, iterations })
}

/// A fallible allocation of `n` zeros, named for its error.
type Alloc<'a> = dyn Fn(&str, usize) -> Result<Vec<f32>, MemoryError> + 'a;

/// The texel grid and its edges.
struct Grid {
    w: usize,
    h: usize,
    edges: EdgeMode,
}

/// Edge weights and targets: `wx[i]`, `gx[i]` for the edge from texel `i` to its right-hand
/// neighbour, `wy[i]`, `gy[i]` to the one below (weight 0 where there is none).
struct Edges {
    wx: Vec<f32>,
    gx: Vec<f32>,
    wy: Vec<f32>,
    gy: Vec<f32>,
}

impl Grid {
    /// The right-hand neighbour of column `x`, if any.
    #[inline]
    fn right(&self, x: usize) -> Option<usize> {
        if x + 1 < self.w {
            Some(x + 1)
        } else if self.edges == EdgeMode::Wrap {
            Some(0)
        } else {
            None
        }
    }

    /// The row below `y`, if any.
    #[inline]
    fn below(&self, y: usize) -> Option<usize> {
        if y + 1 < self.h {
            Some(y + 1)
        } else if self.edges == EdgeMode::Wrap {
            Some(0)
        } else {
            None
        }
    }

    /// The left-hand neighbour of column `x`, if any.
    #[inline]
    fn left(&self, x: usize) -> Option<usize> {
        if x > 0 {
            Some(x - 1)
        } else if self.edges == EdgeMode::Wrap {
            Some(self.w - 1)
        } else {
            None
        }
    }

    /// The row above `y`, if any.
    #[inline]
    fn above(&self, y: usize) -> Option<usize> {
        if y > 0 {
            Some(y - 1)
        } else if self.edges == EdgeMode::Wrap {
            Some(self.h - 1)
        } else {
            None
        }
    }

    /// `D^T g` for weights 1 and trapezoidal targets, into `b`.
    fn plain_rhs(&self, p: &[f32], q: &[f32], b: &mut [f32]) {
        let w = self.w;
        b.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let i = y * w + x;
                let mut s = 0.0f32;
                // Edges leaving i (to the right, below) count -g, edges arriving count +g.
                if let Some(r) = self.right(x) {
                    s -= 0.5 * (p[i] + p[y * w + r]);
                }
                if let Some(l) = self.left(x) {
                    s += 0.5 * (p[y * w + l] + p[i]);
                }
                if let Some(d) = self.below(y) {
                    s -= 0.5 * (q[i] + q[d * w + x]);
                }
                if let Some(u) = self.above(y) {
                    s += 0.5 * (q[u * w + x] + q[i]);
                }
                *out = s;
            }
        });
    }

    /// The bilateral edges for the heights `z`: each texel's forward and backward weights
    /// along each axis, combined per edge into a weight and a target.
    fn bilateral(&self, p: &[f32], q: &[f32], z: &[f32], e: &mut Edges) {
        let w = self.w;
        // A texel's forward weight along an axis from its backward and forward differences
        // (either may be missing at a clamped border: then the texel's slope goes to the
        // edge it has).
        let forward = |back: Option<f32>, fwd: Option<f32>| -> f32 {
            match (back, fwd) {
                (Some(b), Some(f)) => sigmoid(BILATERAL_K * (b * b - f * f) / (b * b + f * f + BILATERAL_EPS)),
                (None, _) => 1.0,
                (_, None) => 0.0,
            }
        };
        let dx = |y: usize, x: usize| self.right(x).map(|r| z[y * w + r] - z[y * w + x]);
        let dy = |y: usize, x: usize| self.below(y).map(|d| z[d * w + x] - z[y * w + x]);
        let wxf = |y: usize, x: usize| forward(self.left(x).and_then(|l| dx(y, l)), dx(y, x));
        let wyf = |y: usize, x: usize| forward(self.above(y).and_then(|u| dy(u, x)), dy(y, x));
        let (wx, gx, wy, gy) = (&mut e.wx, &mut e.gx, &mut e.wy, &mut e.gy);
        wx.par_chunks_mut(w)
            .zip(gx.par_chunks_mut(w))
            .zip(wy.par_chunks_mut(w).zip(gy.par_chunks_mut(w)))
            .enumerate()
            .for_each(|(y, ((wxr, gxr), (wyr, gyr)))| {
                for x in 0..w {
                    let i = y * w + x;
                    (wxr[x], gxr[x]) = match self.right(x) {
                        Some(r) => {
                            let a = wxf(y, x);
                            let b = 1.0 - wxf(y, r);
                            edge(a, p[i], b, p[y * w + r])
                        }
                        None => (0.0, 0.0),
                    };
                    (wyr[x], gyr[x]) = match self.below(y) {
                        Some(d) => {
                            let a = wyf(y, x);
                            let b = 1.0 - wyf(d, x);
                            edge(a, q[i], b, q[d * w + x])
                        }
                        None => (0.0, 0.0),
                    };
                }
            });
    }

    /// The factor `c` that best explains the slopes by `c z`: the least-squares fit of the
    /// differences of `z` over every edge to the edges' trapezoidal targets.
    fn amplitude(&self, p: &[f32], q: &[f32], z: &[f32]) -> f32 {
        let w = self.w;
        let (num, den) = (0..self.h)
            .into_par_iter()
            .map(|y| {
                let (mut num, mut den) = (0.0f64, 0.0f64);
                for x in 0..w {
                    let i = y * w + x;
                    if let Some(r) = self.right(x) {
                        let j = y * w + r;
                        let d = f64::from(z[j] - z[i]);
                        num += d * 0.5 * f64::from(p[i] + p[j]);
                        den += d * d;
                    }
                    if let Some(b) = self.below(y) {
                        let j = b * w + x;
                        let d = f64::from(z[j] - z[i]);
                        num += d * 0.5 * f64::from(q[i] + q[j]);
                        den += d * d;
                    }
                }
                (num, den)
            })
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        if den > 0.0 && num > 0.0 { (num / den) as f32 } else { 1.0 }
    }

    /// `D^T W g`, into `b`.
    fn rhs(&self, e: &Edges, b: &mut [f32]) {
        let w = self.w;
        b.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                let i = y * w + x;
                let mut s = -e.wx[i] * e.gx[i] - e.wy[i] * e.gy[i];
                if let Some(l) = self.left(x) {
                    s += e.wx[y * w + l] * e.gx[y * w + l];
                }
                if let Some(u) = self.above(y) {
                    s += e.wy[u * w + x] * e.gy[u * w + x];
                }
                *out = s;
            }
        });
    }

    /// `D^T W D z`, into `out`.
    fn apply(&self, e: &Edges, z: &[f32], out: &mut [f32]) {
        let w = self.w;
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, o) in row.iter_mut().enumerate() {
                let i = y * w + x;
                let zi = z[i];
                let mut s = 0.0f32;
                if let Some(r) = self.right(x) {
                    s += e.wx[i] * (zi - z[y * w + r]);
                }
                if let Some(l) = self.left(x) {
                    let j = y * w + l;
                    s += e.wx[j] * (zi - z[j]);
                }
                if let Some(d) = self.below(y) {
                    s += e.wy[i] * (zi - z[d * w + x]);
                }
                if let Some(u) = self.above(y) {
                    let j = u * w + x;
                    s += e.wy[j] * (zi - z[j]);
                }
                *o = s;
            }
        });
    }

    /// The weighted solve from the Poisson heights `z`: [`REWEIGHTS`] rounds of bilateral
    /// weights, each system solved by preconditioned conjugate gradients, `max_iterations` in
    /// all. Returns the iterations run.
    #[expect(clippy::too_many_arguments, reason = "the solve's state, passed once")]
    fn weighted(
        &self,
        p: &[f32],
        q: &[f32],
        z: &mut [f32],
        solver: &mut Poisson,
        max_iterations: u32,
        progress: &(dyn Fn(u64) + Sync),
        alloc: &Alloc<'_>,
    ) -> Result<u32, MemoryError> {
        let n = z.len();
        let mut e =
            Edges { wx: alloc("edges", n)?, gx: alloc("edges", n)?, wy: alloc("edges", n)?, gy: alloc("edges", n)? };
        let mut r = alloc("the residual", n)?;
        let mut d = alloc("the search direction", n)?;
        let mut s = alloc("the preconditioned residual", n)?;
        let mut ad = alloc("the operator's output", n)?;
        let mut used = 0u32;
        for round in 0..REWEIGHTS {
            let left = max_iterations - used;
            if left == 0 {
                break;
            }
            // Spread the iterations over the rounds left.
            let budget = left.div_ceil(REWEIGHTS - round);
            self.bilateral(p, q, z, &mut e);
            e.wx.par_iter_mut().chain(e.wy.par_iter_mut()).for_each(|v| {
                if *v > 0.0 {
                    *v = v.max(MIN_EDGE_WEIGHT);
                }
            });
            // r = b - A z.
            self.rhs(&e, &mut r);
            self.apply(&e, z, &mut ad);
            r.par_iter_mut().zip(&ad).for_each(|(r, a)| *r -= a);
            let b_norm = dot(&r, &r).sqrt().max(f64::MIN_POSITIVE);
            let mut rs = 0.0;
            for k in 0..budget {
                s.copy_from_slice(&r);
                solver.solve(&mut s);
                let rs_new = dot(&r, &s);
                if k == 0 {
                    d.copy_from_slice(&s);
                } else {
                    let beta = (rs_new / rs) as f32;
                    d.par_iter_mut().zip(&s).for_each(|(d, s)| *d = s + beta * *d);
                }
                rs = rs_new;
                self.apply(&e, &d, &mut ad);
                let dad = dot(&d, &ad);
                used += 1;
                progress(1);
                if !(dad > 0.0 && rs > 0.0) {
                    break;
                }
                let alpha = (rs / dad) as f32;
                z.par_iter_mut().zip(&d).for_each(|(z, d)| *z += alpha * d);
                r.par_iter_mut().zip(&ad).for_each(|(r, a)| *r -= alpha * a);
                if dot(&r, &r).sqrt() < CG_TOLERANCE * b_norm {
                    break;
                }
            }
        }
        // The bilateral weights shape the relief but do not conserve the slopes' sum across a
        // step: its amplitude is fitted back to the slopes.
        let c = self.amplitude(p, q, z);
        z.par_iter_mut().for_each(|v| *v *= c);
        // Iterations not run are reported done.
        progress(u64::from(max_iterations - used));
        Ok(used)
    }
}

/// An edge's weight and target from the forward weight `a` of the texel before it (slope
/// `pa`) and the backward weight `b` of the texel after it (slope `pb`).
#[inline]
fn edge(a: f32, pa: f32, b: f32, pb: f32) -> (f32, f32) {
    let w = a + b;
    if w > 0.0 { (w, (a * pa + b * pb) / w) } else { (0.0, 0.5 * (pa + pb)) }
}

#[inline]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// `a . b` accumulated in f64.
fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.par_chunks(4096)
        .zip(b.par_chunks(4096))
        .map(|(a, b)| a.iter().zip(b).map(|(&x, &y)| f64::from(x) * f64::from(y)).sum::<f64>())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{NormalBakeOptions, bake_normals, decode_rgb8, encode_rgb8};
    use std::f32::consts::TAU;

    /// The exact normal of the height `z` (texel widths) with slopes `dz/dx`, `dz/drow`: the
    /// inverse of [`slopes`], +Y up (so y is the slope up the image, `-dz/drow`).
    fn normal_of(dzdx: f32, dzdrow: f32) -> Vec3 {
        Vec3::new(-dzdx, dzdrow, 1.0).normalize()
    }

    fn run(w: u32, h: u32, normals: &[Vec3], edges: EdgeMode, method: IntegrateMethod) -> Integrated {
        let opts = IntegrateOptions { edges, method, ..Default::default() };
        integrate_normals(w, h, normals, &opts, &|_| {}).unwrap()
    }

    /// A sum of sinusoids that tiles (whole periods across the map), through its exact point
    /// normals: both solves give it back up to a constant.
    #[test]
    fn tiling_sinusoids_come_back_through_their_exact_normals() {
        let (w, h) = (96u32, 64u32);
        // (amplitude in texel widths, periods along x, periods down the rows, phase)
        let waves = [(3.0f32, 1.0f32, 2.0f32, 0.3f32), (1.5, 3.0, 1.0, 1.1), (0.7, 5.0, 4.0, 2.0)];
        let (mut truth, mut normals) = (Vec::new(), Vec::new());
        for y in 0..h {
            for x in 0..w {
                let (mut z, mut dx, mut dy) = (0.0f32, 0.0f32, 0.0f32);
                for &(a, kx, ky, ph) in &waves {
                    let (wx, wy) = (TAU * kx / w as f32, TAU * ky / h as f32);
                    let t = wx * x as f32 + wy * y as f32 + ph;
                    z += a * t.sin();
                    dx += a * wx * t.cos();
                    dy += a * wy * t.cos();
                }
                truth.push(z);
                normals.push(normal_of(dx, dy));
            }
        }
        for method in [IntegrateMethod::Poisson, IntegrateMethod::Weighted] {
            let out = run(w, h, &normals, EdgeMode::Wrap, method);
            let (r, rms) = height_agreement(out.heights(), &truth);
            assert!(r > 0.999, "{method:?}: r = {r}");
            // Against a relief of 10 texel widths: the trapezoidal rule's error on these slopes.
            assert!(rms < 0.05, "{method:?}: RMS {rms} texel widths");
            let range = truth.iter().copied().fold(f32::MIN, f32::max) - truth.iter().copied().fold(f32::MAX, f32::min);
            assert!((out.range() / range - 1.0).abs() < 0.02, "{method:?}: range {} vs {range}", out.range());
            assert!((out.depth_scale() - out.range() / w as f32).abs() < 1e-6);
        }
    }

    /// A paraboloid plus a tilt, which does not tile, through its exact normals with clamped
    /// edges (the DCT solve).
    #[test]
    fn non_tiling_paraboloid_and_slope_come_back_with_clamped_edges() {
        let (w, h) = (70u32, 45u32);
        let (cx, cy) = (30.0f32, 12.0f32);
        let z = |x: f32, y: f32| 0.01 * ((x - cx).powi(2) + 0.5 * (y - cy).powi(2)) + 0.3 * x - 0.2 * y;
        let (mut truth, mut normals) = (Vec::new(), Vec::new());
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32, y as f32);
                truth.push(z(fx, fy));
                normals.push(normal_of(0.02 * (fx - cx) + 0.3, 0.01 * (fy - cy) - 0.2));
            }
        }
        for method in [IntegrateMethod::Poisson, IntegrateMethod::Weighted] {
            let out = run(w, h, &normals, EdgeMode::Clamp, method);
            let (r, rms) = height_agreement(out.heights(), &truth);
            assert!(r > 0.9999, "{method:?}: r = {r}");
            // A quadratic is integrated exactly by the trapezoidal rule (float error only); the
            // weighted solve's amplitude fit leaves a little more, on a relief of 40 texel widths.
            let limit = if method == IntegrateMethod::Poisson { 1e-3 } else { 0.02 };
            assert!(rms < limit, "{method:?}: RMS {rms} texel widths");
        }
        // Wrap on a map that does not tile cannot: the tilt has nowhere to go.
        let (r, _) = height_agreement(run(w, h, &normals, EdgeMode::Wrap, IntegrateMethod::Poisson).heights(), &truth);
        assert!(r < 0.9, "wrap on a non-tiling map: r = {r}");
    }

    /// `bake normal`'s conventions and this inverse agree: a map baked with `y_down` and read
    /// back flipped, or +Y up, integrates to the heights at the bake's scale, the right way up.
    #[test]
    fn baked_normals_integrate_back_to_the_heights_at_their_scale() {
        let (w, h) = (64u32, 48u32);
        // High on the right and at the bottom, not symmetric: a sign error would show.
        let field = HeightField::from_height_fn(w, h, |x, y| {
            let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            (0.2 + 0.5 * u * u + 0.3 * v).clamp(0.0, 1.0)
        });
        let scale = 6.0;
        let opts = NormalBakeOptions { scale, edges: EdgeMode::Clamp, ..Default::default() };
        let normals = bake_normals(&field, &opts).unwrap();
        let truth: Vec<f32> = field.heights().iter().map(|v| v * scale).collect();
        let out = run(w, h, &normals, EdgeMode::Clamp, IntegrateMethod::Poisson);
        let (r, rms) = height_agreement(out.heights(), &truth);
        assert!(r > 0.9999 && rms < 0.01, "r = {r}, RMS {rms}");
        // Through RGB8 as written to a file: within quantization.
        let q: Vec<Vec3> = normals.iter().map(|&n| decode_rgb8(encode_rgb8(n))).collect();
        let (r, _) = height_agreement(run(w, h, &q, EdgeMode::Clamp, IntegrateMethod::Poisson).heights(), &truth);
        assert!(r > 0.999, "rgb8: r = {r}");
        // The brightest corner is the bottom right one, the darkest the top left.
        let hs = out.normalized();
        assert!(hs[(h * w - 1) as usize] > 0.99 && hs[0] < 0.01, "{} {}", hs[(h * w - 1) as usize], hs[0]);
    }

    /// A raised square with steep sides whose normals were made apart from its heights: the
    /// heights and normals at 4 times the resolution, the normals averaged over 4x4 blocks (as
    /// a mip level is made) and quantized to RGB8, the heights averaged too. The weighted solve
    /// recovers it better than the plain one.
    #[test]
    fn raised_square_recovers_better_with_the_weighted_solve() {
        let (n, k) = (96u32, 4u32);
        let fine_n = n * k;
        // Sides from 0.3 to 0.7 of the map, rising over 1/64 of it (6 fine texels).
        let hf = |x: u32| {
            let u = (x as f32 + 0.5) / fine_n as f32;
            ((u - 0.3).min(0.7 - u) * 64.0 + 0.5).clamp(0.0, 1.0)
        };
        let fine = HeightField::from_height_fn(fine_n, fine_n, |x, y| hf(x).min(hf(y)));
        // The relief spans 4 texel widths; its sides are about 2 texels wide and 45 degrees
        // steep on average (as steep as 76 degrees at the fine resolution).
        let scale = 4.0;
        let opts = NormalBakeOptions { scale: scale * k as f32, edges: EdgeMode::Clamp, ..Default::default() };
        let fine_normals = bake_normals(&fine, &opts).unwrap();
        let fine_h = fine.heights();
        let (mut truth, mut normals) = (Vec::new(), Vec::new());
        for y in 0..n as usize {
            for x in 0..n as usize {
                let (mut hs, mut ns) = (0.0f32, Vec3::ZERO);
                for j in 0..k as usize {
                    for i in 0..k as usize {
                        let f = (y * k as usize + j) * fine_n as usize + x * k as usize + i;
                        hs += fine_h[f];
                        ns += fine_normals[f];
                    }
                }
                truth.push(hs / (k * k) as f32 * scale);
                normals.push(decode_rgb8(encode_rgb8(ns.normalize())));
            }
        }
        let plain = height_agreement(run(n, n, &normals, EdgeMode::Clamp, IntegrateMethod::Poisson).heights(), &truth);
        let weighted =
            height_agreement(run(n, n, &normals, EdgeMode::Clamp, IntegrateMethod::Weighted).heights(), &truth);
        // Measured: plain r 0.9923, RMS 0.243 texel widths; weighted r 0.9959, RMS 0.202.
        assert!(plain.0 > 0.99 && plain.1 < 0.3, "plain: {plain:?}");
        assert!(weighted.0 > plain.0 + 0.002, "weighted r {} vs plain {}", weighted.0, plain.0);
        assert!(weighted.1 < plain.1 * 0.9, "weighted RMS {} vs plain {}", weighted.1, plain.1);
    }

    #[test]
    fn progress_adds_up_to_the_work_units() {
        let normals = vec![Vec3::new(0.1, -0.2, 1.0).normalize(); 20 * 10];
        for method in [IntegrateMethod::Poisson, IntegrateMethod::Weighted] {
            for max_iterations in [1, 7, DEFAULT_ITERATIONS] {
                let opts = IntegrateOptions { edges: EdgeMode::Clamp, method, max_iterations };
                let done = std::sync::atomic::AtomicU64::new(0);
                let out = integrate_normals(20, 10, &normals, &opts, &|k| {
                    done.fetch_add(k, std::sync::atomic::Ordering::Relaxed);
                })
                .unwrap();
                assert_eq!(done.into_inner(), opts.work_units(), "{method:?} {max_iterations}");
                assert!(out.iterations() <= max_iterations);
                // A plane: heights 0.1/0.98.. per texel along x, range over the map.
                let hs = out.normalized();
                assert!(hs.iter().all(|v| (0.0..=1.0).contains(v)));
            }
        }
    }

    #[test]
    fn a_flat_map_is_flat_and_normalizes_to_zero() {
        let out = run(4, 3, &[Vec3::Z; 12], EdgeMode::Wrap, IntegrateMethod::Weighted);
        assert_eq!(out.range(), 0.0);
        assert!(out.normalized().iter().all(|&v| v == 0.0));
        assert_eq!(out.depth_scale(), 0.0);
    }

    #[test]
    fn bad_normals_and_sizes_are_refused() {
        let opts = IntegrateOptions::default();
        let none = &|_| {};
        let err = integrate_normals(1, 1, &[Vec3::Z], &opts, none).unwrap_err();
        assert!(matches!(err, IntegrateError::TooSmall { width: 1, height: 1 }) && err.to_string().contains("2x2"));
        assert!(matches!(integrate_normals(5, 1, &[Vec3::Z; 5], &opts, none), Err(IntegrateError::TooSmall { .. })));
        assert!(matches!(
            integrate_normals(2, 2, &[Vec3::Z; 3], &opts, none),
            Err(IntegrateError::Size { got: 3, .. })
        ));
        for (bad, what) in [
            (Vec3::ZERO, "zero"),
            (Vec3::new(f32::NAN, 0.0, 1.0), "finite"),
            (Vec3::new(0.0, 0.0, f32::INFINITY), "finite"),
            (Vec3::new(0.1, 0.0, -1.0), "into the surface"),
        ] {
            let mut normals = vec![Vec3::Z; 12];
            normals[7] = bad;
            let err = integrate_normals(4, 3, &normals, &opts, none).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, IntegrateError::BadNormal { x: 3, y: 1, .. }), "{msg}");
            assert!(msg.contains(what) && msg.contains("(3, 1)"), "{msg}");
        }
        // A horizontal normal is a steep slope, capped, never an infinity or a NaN.
        let mut normals = vec![Vec3::Z; 16];
        normals[5] = Vec3::X;
        let out = integrate_normals(4, 4, &normals, &opts, none).unwrap();
        assert!(out.heights().iter().all(|v| v.is_finite()));
        assert_eq!(slopes(Vec3::X), (-MAX_SLOPE, 0.0));
    }
}
