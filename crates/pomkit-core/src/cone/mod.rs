//! Cone maps: a safety cone over every texel footprint of the bilinear height surface.
//!
//! Cone step mapping (Dummer 2006, docs/REFERENCES.md) stores, per texel, the widest upward
//! cone with its apex on the surface that holds no point of the surface: a ray inside it can
//! jump to the cone's boundary without missing anything. Dummer's cones, and most cone maps
//! shipped since, are measured between texel *centres*: the surface between them, which is what
//! a bilinear sampler shows and what pomkit's `exact` tracer hits, can poke into them. Bán,
//! Valasek, Bálint and Vad 2024 ("Robust Cone Step Mapping") make the cones hold for the
//! interpolated surface. pomkit's cones do that in the form its tracers use:
//!
//! - A cone belongs to a texel's **footprint** `C = [i, i+1] x [j, j+1]` (texel units, the
//!   texel centre at `(i + 1/2, j + 1/2)`), not to a point. Its apex is the footprint's **top**
//!   `m`, the least depth the bilinear surface reaches anywhere on `C` (the maximum-height
//!   pyramid's level 0, [`crate::pyramid`]).
//! - Its **ratio** `c` (texels of horizontal distance per unit of depth) is the largest for which
//!   every point `q` of the surface shallower than the top satisfies
//!   `dist(q, C) >= c (m - depth(q))`, where `dist` is the distance from `q` to the square `C`
//!   (not to its centre).
//!
//! So the region `depth < m - dist(p, C) / c` is empty of surface, and a ray at any point of
//! `C`, above the top, may advance by [`safe_step`] without passing through the surface. The
//! ratio is capped at [`ConeMap::cap`], one tile's width: wider cones are never needed to cross
//! a tile in one step.
//!
//! Besides these conservative cones, [`ConeMap::relaxed_cones`] builds relaxed ones (Policarpo
//! and Oliveira 2007: a ray from the top plane crosses the surface at most once inside the cone)
//! and [`ConeMap::directional`] one ratio per quadrant of ray directions. The `cone` technique's
//! walk over these maps is the tracer's (`trace/cone.rs`); [`cached`] shares a field's cones between the frames
//! and renderers that use them.
//!
//! # How the ratio is found
//!
//! The naive build tests every texel against every other, quadratic in the texel count. This
//! one is a branch and bound per footprint over the maximum-height pyramid, exact for the
//! bilinear surface up to a relative slack of [`SLACK`], and always on the safe side:
//! - A region `R` of the plane (a pyramid cell, or a rectangle inside one bilinear patch) whose
//!   least depth is `min_d` bounds the ratio from below by `dist(R, C) / (m - min_d)`; inside the
//!   square `D` half a texel around `C` (the four patches that meet `C`) also by `1 / L`, where
//!   `L` bounds the surface's slope there (the surface can fall below `m` no faster than that
//!   from `C`'s edge).
//!   Near the footprint (regions up to 128 texels across, with the footprint)
//!   also by `1 / G`, where `G` is the largest slope of the surface over the box holding the
//!   region and the side of `C` facing it (`cone/slope.rs`): along the segment from a point to its
//!   nearest point of `C` the surface can rise no faster. On smooth relief this bound prunes
//!   the neighbourhood that the distance bound must split down to small rectangles, and the
//!   cones come out wider (fewer regions stop at [`MIN_REGION`] with their lower bound).
//! - A rectangle inside one patch and level with the footprint along one axis needs no bound:
//!   the ratio over it is least at one of its corners (see the search), which are evaluated.
//! - Regions whose bound is no better than the best ratio found so far are dropped; others are
//!   split (pyramid cells into their children, level-0 cells into the quarters that lie in one
//!   patch each, those into halves along each axis) until they are smaller than [`MIN_REGION`]
//!   texels, or small for their distance (a diagonal under [`FAR`] times it: their bound is
//!   then within a factor `1 + FAR` of any of their points' ratios). The least depth of a
//!   rectangle inside one patch is the least of its corners (a bilinear function is monotone
//!   along each axis there).
//! - Corners of those rectangles are points of the surface: each gives an upper bound, the best
//!   of which ends the search. The answer is the smaller of `(1 - SLACK)` times that and the
//!   bounds of the regions not split: never wider than the true cone, and at least
//!   `(1 - SLACK) / (1 + FAR)` of it where the slope bound beside the footprint does not
//!   decide (measured against brute force: 0.92 of it on average on noise, 0.86 on a smooth
//!   sine field).
//! - Each footprint starts from the point that decided its left neighbour's cone, which is
//!   usually nearly as good for it, so most of the pyramid is pruned at once.
//!
//! With wrap edges the surface repeats: the search covers the 3 x 3 tiles around the map
//! (points further away are more than the cap's distance). With clamp edges the surface outside
//! the map repeats the border texels outward, so every point outside has a point on the map's
//! border with the same depth and no further from any footprint: the map alone is searched.

use rayon::prelude::*;

mod build;
mod slope;

use build::Search;

use crate::heightfield::{EdgeMode, HeightField};
use crate::pyramid::MaxHeightPyramid;

/// The relative slack of the branch and bound: the ratio found is at least `1 - SLACK` times
/// the true one (on the safe side, narrower).
pub const SLACK: f64 = 1.0 / 16.0;

/// A region whose diagonal is at most `FAR` times its distance from the footprint is not split:
/// its lower bound is within a factor `1 + FAR` of the least ratio of its points.
pub const FAR: f64 = 1.0 / 2.0;

/// [`FAR`] for relaxed cones. A region kept whole keeps its conservative bound: only its
/// rectangles inside one patch learn whether a ray can leave the surface there, so a coarser
/// tolerance takes most of the relaxation away (at `FAR` 1/2 relaxed cones on cobblestones are
/// 1.07 times the conservative ones on average, at 1/4 about 1.4).
pub const FAR_RELAXED: f64 = 1.0 / 4.0;

/// Regions smaller than this (texels, along both axes) are not split further; the ratio keeps
/// their lower bound. Only regions touching the footprint's neighbourhood get this small.
pub const MIN_REGION: f64 = 1.0 / 8.0;

/// Surface points less than this far above a footprint's top (in depth) count as level with
/// it: they are rounding errors of the top (computed in `f32`), not relief, and would otherwise
/// close the cone at the footprint's own edge. The cone they may poke into is less than
/// `LEVEL` deep.
pub const LEVEL: f64 = 1e-6;

/// Conservative cones of a height field: per texel footprint its top and its cone ratio.
#[derive(Clone, Debug, PartialEq)]
pub struct ConeMap {
    width: u32,
    height: u32,
    edges: EdgeMode,
    /// Least depth of the bilinear surface over each footprint, row-major.
    top: Vec<f32>,
    /// Cone ratio of each footprint, texels per unit depth, in `[0, cap]`, row-major.
    ratio: Vec<f32>,
    /// Whether the cones may hold surface (relaxed: a ray must look after each step) or are
    /// known to hold none (conservative: a step inside a cone needs no look).
    relaxed: bool,
    /// Directional cones ([`ConeMap::directional`]): per footprint the ratio for rays whose
    /// direction has the signs of quadrant `k` (`k = [x < 0] + 2 [y < 0]`), over the surface
    /// such rays can reach. Each is at least `ratio`.
    ahead: Option<Vec<[f32; 4]>>,
}

/// Why a cone map image was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConeMapError {
    /// The cone map's size is not the height map's.
    #[error(
        "the cone map is {got_w}x{got_h} but the height map is {want_w}x{want_h}: bake the cone map from this height map (`pomkit bake cone`)"
    )]
    Size {
        /// Cone map width.
        got_w: u32,
        /// Cone map height.
        got_h: u32,
        /// Height map width.
        want_w: u32,
        /// Height map height.
        want_h: u32,
    },
    /// The sample count is not two per texel (grey + alpha).
    #[error(
        "the cone map has {got} samples for {w}x{h} texels: expected 2 per texel (grey = top, alpha = cone), as `pomkit bake cone` writes"
    )]
    Samples {
        /// Samples given.
        got: usize,
        /// Width.
        w: u32,
        /// Height.
        h: u32,
    },
}

impl ConeMap {
    /// Builds the conservative cones of `field` for the given edge mode. Runs on every core.
    #[must_use]
    pub fn conservative(field: &HeightField, edges: EdgeMode) -> Self {
        Self::conservative_with_progress(field, edges, &|_| {})
    }

    /// As [`ConeMap::conservative`], calling `progress(rows)` as each row of footprints is done.
    #[must_use]
    pub fn conservative_with_progress(field: &HeightField, edges: EdgeMode, progress: &(dyn Fn(u32) + Sync)) -> Self {
        Self::build(field, edges, false, progress)
    }

    /// Relaxed cones (Policarpo and Oliveira 2007), built exactly for the bilinear surface: per
    /// footprint the widest cone above its top in which no ray that starts on the top plane
    /// (depth 0) over the footprint can leave the surface after entering it, so such a ray
    /// crosses the surface at most once inside the cone ([`ConeMap::relaxed`] is true: a tracer
    /// looks after each step, and searches the step that went under). Each ratio is at least the
    /// conservative one. The same branch and bound, where a rectangle of surface counts only if
    /// a ray from the footprint's top plane may leave the surface in it (the surface falls away
    /// there faster than such a ray descends). The search's tolerance is the conservative
    /// one's, so a footprint's relaxed ratio may come out below its conservative ratio (by at
    /// most that tolerance) where the two exact ratios are equal.
    ///
    /// The guarantee is for rays from the top plane, as Policarpo and Oliveira's: a walk's later
    /// steps start deeper, and may step over a thin feature.
    #[must_use]
    pub fn relaxed_cones(field: &HeightField, edges: EdgeMode) -> Self {
        Self::build(field, edges, true, &|_| {})
    }

    /// As [`ConeMap::relaxed_cones`], calling `progress(rows)` as each row is done.
    #[must_use]
    pub fn relaxed_with_progress(field: &HeightField, edges: EdgeMode, progress: &(dyn Fn(u32) + Sync)) -> Self {
        Self::build(field, edges, true, progress)
    }

    fn build(field: &HeightField, edges: EdgeMode, relaxed: bool, progress: &(dyn Fn(u32) + Sync)) -> Self {
        let (w, h) = (field.width(), field.height());
        let pyramid = MaxHeightPyramid::new(field, edges);
        let search = Search::new(field, &pyramid, edges);
        let rows: Vec<Vec<(f32, f32)>> = (0..h)
            .into_par_iter()
            .map(|j| {
                let mut witness = None;
                let row = (0..w)
                    .map(|i| {
                        let (ratio, q) = search.ratio_ahead(i, j, witness, None, relaxed);
                        witness = q.or(witness);
                        (pyramid.min_depth(0, i, j), ratio)
                    })
                    .collect();
                progress(1);
                row
            })
            .collect();
        let (top, ratio) = rows.into_iter().flatten().unzip();
        Self { width: w, height: h, edges, top, ratio, relaxed, ahead: None }
    }

    /// Conservative cones per direction quadrant: for each footprint, four ratios, each over the
    /// surface a ray with that quadrant's direction signs can reach from the footprint (the
    /// footprint swept along the quadrant), so surface behind or beside the ray does not narrow
    /// its cone. Four searches per footprint: about four times [`ConeMap::conservative`]'s time.
    /// The isotropic ratio is the least of the four.
    #[must_use]
    pub fn directional(field: &HeightField, edges: EdgeMode) -> Self {
        let (w, h) = (field.width(), field.height());
        let pyramid = MaxHeightPyramid::new(field, edges);
        let search = Search::new(field, &pyramid, edges);
        const QUADRANTS: [(f64, f64); 4] = [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];
        let rows: Vec<Vec<(f32, [f32; 4])>> = (0..h)
            .into_par_iter()
            .map(|j| {
                let mut witness = [None; 4];
                (0..w)
                    .map(|i| {
                        let mut ahead = [0.0f32; 4];
                        for (k, &q) in QUADRANTS.iter().enumerate() {
                            let (ratio, at) = search.ratio_ahead(i, j, witness[k], Some(q), false);
                            witness[k] = at.or(witness[k]);
                            ahead[k] = ratio;
                        }
                        (pyramid.min_depth(0, i, j), ahead)
                    })
                    .collect()
            })
            .collect();
        let (top, ahead): (Vec<f32>, Vec<[f32; 4]>) = rows.into_iter().flatten().unzip();
        let ratio = ahead.iter().map(|a| a.iter().copied().fold(f32::INFINITY, f32::min)).collect();
        Self { width: w, height: h, edges, top, ratio, relaxed: false, ahead: Some(ahead) }
    }

    /// The top and the ratio of footprint `(x, y)` for a ray moving along `(dx, dy)`, without
    /// the bounds check (the walk's read): the directional ratio where the map has them, else
    /// the isotropic one.
    #[inline]
    pub(crate) fn cone_along(&self, x: u32, y: u32, dx: f64, dy: f64) -> (f32, f32) {
        let k = (y * self.width + x) as usize;
        let ratio = match &self.ahead {
            Some(a) => a[k][usize::from(dx < 0.0) + 2 * usize::from(dy < 0.0)],
            None => self.ratio[k],
        };
        (self.top[k], ratio)
    }

    /// Decodes the grey + alpha samples of [`ConeMap::to_gray_alpha16`] (a baked cone map,
    /// `2 * width * height` values) for a `width` x `height` height map traced with `edges`
    /// (which the map must have been baked for). A loaded map counts as relaxed: nothing in the
    /// image says its cones are conservative, so a tracer looks after every step.
    ///
    /// # Errors
    /// [`ConeMapError::Samples`] if `samples` does not hold two values per texel.
    pub fn from_gray_alpha16(width: u32, height: u32, edges: EdgeMode, samples: &[u16]) -> Result<Self, ConeMapError> {
        let n = width as usize * height as usize;
        if samples.len() != 2 * n || n == 0 {
            return Err(ConeMapError::Samples { got: samples.len(), w: width, h: height });
        }
        let cap = width.min(height) as f32;
        let (top, ratio) = samples
            .chunks_exact(2)
            .map(|g| {
                let top = 1.0 - f32::from(g[0]) / 65535.0;
                let a = f32::from(g[1]) / 65535.0;
                // Rounding down in f32 keeps the decoded cone inside the stored one.
                (top, (a * a * cap * (1.0 - 1e-6)).min(cap))
            })
            .unzip();
        Ok(Self { width, height, edges, top, ratio, relaxed: true, ahead: None })
    }

    /// Whether the cones may hold surface points (a tracer must look after each step): true for
    /// maps read from images, false for conservative cones built here.
    #[must_use]
    pub fn relaxed(&self) -> bool {
        self.relaxed
    }

    /// Checks that these cones belong to a `width` x `height` height map.
    ///
    /// # Errors
    /// [`ConeMapError::Size`] if the sizes differ.
    pub fn check_size(&self, width: u32, height: u32) -> Result<(), ConeMapError> {
        if (self.width, self.height) == (width, height) {
            Ok(())
        } else {
            Err(ConeMapError::Size { got_w: self.width, got_h: self.height, want_w: width, want_h: height })
        }
    }

    /// About how many bytes building the cones of a `width` x `height` map and writing them
    /// takes beyond the height field itself: the pyramid (5.4 bytes a texel), the rows as they
    /// are built and the map (8 each), and the 16-bit image and its encoder's copy (4 each),
    /// rounded up to 32 bytes a texel, and the slope bound's table (16 bytes a texel and a
    /// margin around the map).
    #[must_use]
    pub fn build_bytes(width: u32, height: u32) -> u64 {
        u64::from(width) * u64::from(height) * 32 + slope::SlopeTable::bytes(width, height)
    }

    /// Footprints `(columns, rows)`: the height field's size.
    #[must_use]
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The edge mode the cones were built for.
    #[must_use]
    pub fn edges(&self) -> EdgeMode {
        self.edges
    }

    /// The widest ratio stored: the map's shorter side in texels, per unit depth (a cone that
    /// wide crosses a whole tile on its way from depth 1 to depth 0).
    #[must_use]
    pub fn cap(&self) -> f32 {
        self.width.min(self.height) as f32
    }

    /// Least depth of the surface over footprint `(x, y)`: the cone's apex.
    ///
    /// # Panics
    /// If the footprint is outside the map.
    #[must_use]
    pub fn top(&self, x: u32, y: u32) -> f32 {
        assert!(x < self.width && y < self.height, "footprint ({x}, {y}) outside {}x{}", self.width, self.height);
        self.top[(y * self.width + x) as usize]
    }

    /// Cone ratio of footprint `(x, y)`, in texels per unit depth.
    ///
    /// # Panics
    /// If the footprint is outside the map.
    #[must_use]
    pub fn ratio(&self, x: u32, y: u32) -> f32 {
        assert!(x < self.width && y < self.height, "footprint ({x}, {y}) outside {}x{}", self.width, self.height);
        self.ratio[(y * self.width + x) as usize]
    }
}

impl ConeMap {
    /// The cones as 16-bit grey + alpha samples, row-major (`2 * width * height` values), as
    /// `pomkit bake cone` writes them:
    /// - grey: the footprint's top as a height, `1 - top`, rounded up (a higher apex only
    ///   narrows the cone's free region);
    /// - alpha: `sqrt(ratio / cap)`, rounded down (a narrower cone), where `cap` is
    ///   [`ConeMap::cap`], the shorter side in texels. On a square map `ratio / cap` is the
    ///   ratio in UV units per unit depth, the convention of Dummer's and Policarpo's cone maps,
    ///   and the square root spends the precision on the narrow cones, as theirs do.
    #[must_use]
    pub fn to_gray_alpha16(&self) -> Vec<u16> {
        let cap = self.cap();
        self.top
            .iter()
            .zip(&self.ratio)
            .flat_map(|(&top, &ratio)| {
                let height = (f64::from(1.0 - top).clamp(0.0, 1.0) * 65535.0).ceil() as u16;
                let cone = (f64::from((ratio / cap).clamp(0.0, 1.0)).sqrt() * 65535.0).floor() as u16;
                [height, cone]
            })
            .collect()
    }
}

/// The conservative cones of `field` for `edges`, built once per height field and shared while
/// the field lives: renderers that prepare their surfaces for every frame (the CPU renderer)
/// find them here instead of building them again. Entries of fields that were dropped are
/// forgotten.
#[must_use]
pub fn cached(field: &std::sync::Arc<HeightField>, edges: EdgeMode) -> std::sync::Arc<ConeMap> {
    cached_with_progress(field, edges, &|_| {})
}

/// As [`cached`], calling `progress(rows)` as each row of footprints is built (not at all when
/// the cones are there already).
#[must_use]
pub fn cached_with_progress(
    field: &std::sync::Arc<HeightField>,
    edges: EdgeMode,
    progress: &(dyn Fn(u32) + Sync),
) -> std::sync::Arc<ConeMap> {
    use std::sync::{Arc, Mutex, Weak};
    type Entry = (Weak<HeightField>, EdgeMode, Arc<ConeMap>);
    static CACHE: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
    let find = |cache: &mut Vec<Entry>| {
        cache.retain(|(f, _, _)| f.strong_count() > 0);
        cache.iter().find(|(f, e, _)| *e == edges && f.as_ptr() == Arc::as_ptr(field)).map(|(_, _, c)| Arc::clone(c))
    };
    // A poisoned lock only means another thread panicked while holding it; the list stays valid.
    if let Some(c) = find(&mut CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner)) {
        return c;
    }
    // Built outside the lock: two threads may both build the same cones, never wait on each other.
    let cones = Arc::new(ConeMap::conservative_with_progress(field, edges, progress));
    let mut cache = CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(c) = find(&mut cache) {
        return c;
    }
    cache.push((Arc::downgrade(field), edges, Arc::clone(&cones)));
    cones
}

/// How far a ray may advance without meeting the surface, from a point of footprint `C` at depth
/// `z`: the ray parameter `t` of the cone's boundary, for a ray that moves `horizontal` texels
/// and `dz` in depth per unit of `t` (`dz >= 0`, down). `top` and `ratio` are `C`'s
/// ([`ConeMap::top`], [`ConeMap::ratio`]).
///
/// At `t` the ray has moved at most `horizontal t` from `C` and is at depth `z + dz t`, which
/// the cone keeps above every surface point that far from `C`. Zero when the point is at or
/// below the top (the cone says nothing there) or the ratio is 0.
#[must_use]
pub fn safe_step(top: f32, ratio: f32, z: f32, horizontal: f32, dz: f32) -> f32 {
    // Written to give 0 for NaN inputs too.
    let above = z < top && ratio > 0.0;
    if !above {
        return 0.0;
    }
    let rate = dz.max(0.0) + horizontal.max(0.0) / ratio;
    if rate > 0.0 { (top - z) / rate } else { f32::INFINITY }
}

/// `x.floor()` as an integer, without the library call that a baseline x86-64 build makes for
/// `f64::floor` (the build floors for every region it looks at). `|x|` must be below 2^62.
#[inline]
pub(crate) fn floor_i(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from((t as f64) > x)
}

/// `x.ceil()` as an integer, as [`floor_i`].
#[inline]
pub(crate) fn ceil_i(x: f64) -> i64 {
    let t = x as i64;
    t + i64::from((t as f64) < x)
}

/// The bilinear interpolation at `(x, y)` (texel units, centres at half-integers) of the texel
/// depths `texel(i, j)` gives.
#[inline]
pub(crate) fn bilinear(texel: impl Fn(i64, i64) -> f64, x: f64, y: f64) -> f64 {
    let (sx, sy) = (x - 0.5, y - 0.5);
    let (fx, fy) = (floor_i(sx) as f64, floor_i(sy) as f64);
    let (tx, ty) = (sx - fx, sy - fy);
    let (k, l) = (fx as i64, fy as i64);
    let top = texel(k, l) + (texel(k + 1, l) - texel(k, l)) * tx;
    let bottom = texel(k, l + 1) + (texel(k + 1, l + 1) - texel(k, l + 1)) * tx;
    top + (bottom - top) * ty
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pyramid::tests::noisy;

    /// The brute-force definition: over surface points sampled every `1 / n` texel across the
    /// searched area (3 x 3 tiles for wrap, the map for clamp), the least `dist(q, C) / (m -
    /// depth(q))`. Sampling can only miss the minimum, so this is at least the true ratio.
    fn brute_ratio(f: &HeightField, edges: EdgeMode, top: f32, i: u32, j: u32, n: u32) -> f64 {
        let (w, h) = (f64::from(f.width()), f64::from(f.height()));
        let (lo_x, hi_x, lo_y, hi_y) = match edges {
            EdgeMode::Wrap => (-w, 2.0 * w, -h, 2.0 * h),
            EdgeMode::Clamp => (0.0, w, 0.0, h),
        };
        let (cx0, cy0) = (f64::from(i), f64::from(j));
        let m = f64::from(top);
        let mut best = f64::from(f.width().min(f.height()));
        let steps_x = ((hi_x - lo_x) * f64::from(n)) as u32;
        let steps_y = ((hi_y - lo_y) * f64::from(n)) as u32;
        for sy in 0..=steps_y {
            for sx in 0..=steps_x {
                let (x, y) = (lo_x + f64::from(sx) / f64::from(n), lo_y + f64::from(sy) / f64::from(n));
                let uv = glam::Vec2::new((x / w) as f32, (y / h) as f32);
                let d = f64::from(f.sample_bilinear(uv, edges));
                if d < m - LEVEL {
                    let dx = (cx0 - x).max(x - cx0 - 1.0).max(0.0);
                    let dy = (cy0 - y).max(y - cy0 - 1.0).max(0.0);
                    best = best.min((dx * dx + dy * dy).sqrt() / (m - d));
                }
            }
        }
        best
    }

    #[test]
    fn cones_hold_no_surface_point_and_are_nearly_as_wide_as_they_can_be() {
        for (w, h, edges, seed) in [(6, 5, EdgeMode::Wrap, 1), (7, 6, EdgeMode::Clamp, 2), (5, 5, EdgeMode::Wrap, 3)] {
            let f = noisy(w, h, seed);
            let cones = ConeMap::conservative(&f, edges);
            let pyramid = MaxHeightPyramid::new(&f, edges);
            let mut ratios = Vec::new();
            for j in 0..h {
                for i in 0..w {
                    let (top, c) = (cones.top(i, j), f64::from(cones.ratio(i, j)));
                    assert_eq!(top, pyramid.min_depth(0, i, j));
                    let truth = brute_ratio(&f, edges, top, i, j, 16);
                    // Valid: no sampled surface point inside the cone.
                    assert!(c <= truth * (1.0 + 1e-5), "{w}x{h} {edges:?} ({i},{j}): ratio {c} > brute force {truth}");
                    ratios.push((c, truth));
                }
            }
            // Tight: the slope bound near the footprint and the slack (SLACK, and regions
            // small for their distance) cost some width; never most of it. (A cone map of zeros
            // would pass the first check.)
            let mean_share = ratios.iter().map(|(c, t)| c / t).sum::<f64>() / ratios.len() as f64;
            let worst = ratios.iter().map(|(c, t)| c / t).fold(f64::INFINITY, f64::min);
            println!("{w}x{h} {edges:?}: mean share of the brute-force ratio {mean_share:.3}, worst {worst:.3}");
            assert!(mean_share > 0.9 && worst > 0.6, "{w}x{h} {edges:?}: {mean_share} {worst}");
        }
    }

    /// On a smooth field most cones are decided by the slope beside the footprint, where the
    /// slope bound ([`slope`]) prunes the neighbourhood: those cones must hold too, and be as
    /// wide as the brute force allows, up to the slack.
    #[test]
    fn cones_of_a_smooth_field_hold_and_are_nearly_as_wide_as_they_can_be() {
        let n = 16u32;
        let depths: Vec<f32> = (0..n * n)
            .map(|k| {
                let (x, y) = (f64::from(k % n) + 0.5, f64::from(k / n) + 0.5);
                let t = std::f64::consts::TAU / f64::from(n);
                (0.5 + 0.4 * (t * x).sin() * (t * y + 0.3).cos()) as f32
            })
            .collect();
        let f = HeightField::from_depths(n, n, depths).expect("valid");
        for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
            let cones = ConeMap::conservative(&f, edges);
            let mut shares = Vec::new();
            // Every third footprint along a diagonal-ish walk: both slopes and crests.
            for k in 0..40 {
                let (i, j) = ((k * 5) % n, (k * 3 + k / n) % n);
                let c = f64::from(cones.ratio(i, j));
                let truth = brute_ratio(&f, edges, cones.top(i, j), i, j, 6);
                assert!(c <= truth * (1.0 + 1e-5), "{edges:?} ({i},{j}): ratio {c} > brute force {truth}");
                shares.push(c / truth);
            }
            let mean = shares.iter().sum::<f64>() / shares.len() as f64;
            println!("smooth {edges:?}: mean share of the brute-force ratio {mean:.3}");
            assert!(mean > 0.8, "{edges:?}: mean share {mean}");
        }
    }

    #[test]
    fn a_spike_gives_the_distance_to_its_peak_along_its_row_and_column() {
        // One texel at height 1 on a floor at depth 1: the bilinear surface is a tent of
        // `1 - depth = (1 - |dx|)(1 - |dy|)` around the centre (5.5, 7.5). From a footprint in
        // the spike's row, `dist / (1 - depth)` over the tent is least at the peak (for
        // footprints two or more texels away): the distance from the peak to the footprint.
        const WORST: f32 = ((1.0 - SLACK) / (1.0 + FAR)) as f32;
        let (w, h) = (16, 16);
        let f = HeightField::from_height_fn(w, h, |x, y| if (x, y) == (5, 7) { 1.0 } else { 0.0 });
        for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
            let cones = ConeMap::conservative(&f, edges);
            assert_eq!((cones.top(5, 7), cones.ratio(5, 7)), (0.0, cones.cap()), "the peak has nothing above it");
            for (i, j, truth) in [(8, 7, 2.5), (12, 7, 6.5), (2, 7, 2.5), (0, 7, 4.5), (5, 10, 2.5), (5, 1, 5.5)] {
                let c = cones.ratio(i, j);
                assert_eq!(cones.top(i, j), 1.0);
                assert!(c <= truth && c >= truth * WORST - 1e-4, "{edges:?} ({i},{j}): {c} vs {truth}");
            }
            // With wrap the spike one tile over is nearer: footprint (14, 7) is 6.5 from the
            // peak's copy at 21.5 but 8.5 from the peak itself.
            let c = cones.ratio(14, 7);
            let truth = if edges == EdgeMode::Wrap { 6.5 } else { 8.5 };
            assert!(c <= truth && c >= truth * WORST - 1e-4, "{edges:?} (14,7): {c} vs {truth}");
        }
        // A flat field has no cones to close: every ratio is the cap.
        let flat = ConeMap::conservative(&HeightField::constant(7, 3, 0.4), EdgeMode::Wrap);
        assert!((0..3).all(|j| (0..7).all(|i| flat.ratio(i, j) == 3.0)));
        // The smallest maps: one texel, and one row.
        let one = ConeMap::conservative(&HeightField::constant(1, 1, 0.3), EdgeMode::Clamp);
        assert_eq!((one.size(), one.top(0, 0), one.ratio(0, 0)), ((1, 1), 0.3, 1.0));
        let row = HeightField::from_depths(4, 1, vec![1.0, 0.0, 1.0, 1.0]).unwrap();
        for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
            let cones = ConeMap::conservative(&row, edges);
            assert!((0..4).all(|i| (0.0..=1.0).contains(&cones.ratio(i, 0))), "{edges:?}");
        }
    }

    /// Numbers in `[0, 1]` from a xorshift generator seeded with `seed` (not 0).
    fn uniform(seed: u32) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f64::from(state) / f64::from(u32::MAX)
        }
    }

    #[test]
    fn a_ray_advanced_by_the_safe_step_never_passes_through_the_surface() {
        use glam::Vec2;
        let mut next = uniform(0x9e37_79b9);
        for (w, h, edges) in [(12, 10, EdgeMode::Wrap), (9, 13, EdgeMode::Clamp)] {
            let f = noisy(w, h, w + h);
            let cones = ConeMap::conservative(&f, edges);
            let size = Vec2::new(w as f32, h as f32);
            let mut advanced = 0.0;
            for _ in 0..3000 {
                let (i, j) = ((next() * f64::from(w)) as u32 % w, (next() * f64::from(h)) as u32 % h);
                let (top, ratio) = (cones.top(i, j), cones.ratio(i, j));
                let (x, y) = (f64::from(i) + next(), f64::from(j) + next());
                let z = f64::from(top) * next();
                // From head-on to grazing: 0 to 60 texels across per unit of depth.
                let speed = 60.0 * next() * next();
                let azimuth = std::f64::consts::TAU * next();
                let t_end = f64::from(safe_step(top, ratio, z as f32, speed as f32, 1.0)).min(1.0);
                advanced += t_end * speed;
                for k in 0..=400 {
                    let t = t_end * f64::from(k) / 400.0;
                    let (px, py) = (x + t * speed * azimuth.cos(), y + t * speed * azimuth.sin());
                    let uv = Vec2::new(px as f32, py as f32) / size;
                    let surface = f64::from(f.sample_bilinear(uv, edges));
                    assert!(
                        z + t <= surface + 1e-4,
                        "{edges:?} footprint ({i},{j}) from ({x:.3},{y:.3}) at depth {z:.4}: below the surface at t {t}"
                    );
                }
            }
            // The steps are not trivially short: on average they cross a good part of a texel.
            println!("{w}x{h} {edges:?}: mean step {:.2} texels", advanced / 3000.0);
            assert!(advanced / 3000.0 > 0.2, "{edges:?}: mean step {}", advanced / 3000.0);
        }
    }

    /// Relaxed cones against their definition, by brute force: a ray that starts on the top
    /// plane over a footprint and advances by the relaxed safe step never leaves the surface
    /// after entering it (sampled densely along the step), and the relaxed ratio is not below
    /// the conservative one beyond the search's tolerance (how much wider depends on the
    /// relief: trace_analytic.rs measures it on cobblestones). A planted error (cones twice as wide) is caught, so the check can
    /// fail.
    #[test]
    fn relaxed_cones_let_a_ray_from_the_top_plane_cross_the_surface_at_most_once() {
        use glam::Vec2;
        for (w, h, edges) in [(14, 12, EdgeMode::Wrap), (11, 13, EdgeMode::Clamp)] {
            let f = noisy(w, h, 3 * w + h);
            let conservative = ConeMap::conservative(&f, edges);
            let relaxed = ConeMap::relaxed_cones(&f, edges);
            assert!(relaxed.relaxed() && !conservative.relaxed());
            let size = Vec2::new(w as f32, h as f32);
            let (mut sum_relaxed, mut sum_conservative) = (0.0, 0.0);
            for j in 0..h {
                for i in 0..w {
                    // Both searches stop within (1 - SLACK) / (1 + FAR) of their exact answers
                    // (the relaxed search's FAR being the smaller), and the exact relaxed cone is
                    // never the narrower.
                    let floor = (1.0 - SLACK) / (1.0 + FAR);
                    assert!(
                        f64::from(relaxed.ratio(i, j)) >= floor * f64::from(conservative.ratio(i, j)),
                        "{edges:?} ({i},{j})"
                    );
                    sum_relaxed += f64::from(relaxed.ratio(i, j));
                    sum_conservative += f64::from(conservative.ratio(i, j));
                }
            }
            println!("{w}x{h} {edges:?}: mean ratio relaxed {sum_relaxed:.1}, conservative {sum_conservative:.1}");
            // Rays from the top plane, stepped; `widen` > 1 plants an error.
            let exits = |widen: f32| {
                let mut next = uniform(0x2545_f491);
                let mut bad = 0;
                for _ in 0..3000 {
                    let (i, j) = ((next() * f64::from(w)) as u32 % w, (next() * f64::from(h)) as u32 % h);
                    let (top, ratio) = (relaxed.top(i, j), relaxed.ratio(i, j) * widen);
                    let (x, y) = (f64::from(i) + next(), f64::from(j) + next());
                    let speed = 60.0 * next() * next();
                    let azimuth = std::f64::consts::TAU * next();
                    let t_end = f64::from(safe_step(top, ratio, 0.0, speed as f32, 1.0)).min(1.0);
                    // Below the surface at some sample, then above it again at a later one.
                    let mut entered = false;
                    for k in 0..=800 {
                        let t = t_end * f64::from(k) / 800.0;
                        let (px, py) = (x + t * speed * azimuth.cos(), y + t * speed * azimuth.sin());
                        let surface = f64::from(f.sample_bilinear(Vec2::new(px as f32, py as f32) / size, edges));
                        if t > surface + 1e-4 {
                            entered = true;
                        } else if entered && t < surface - 1e-4 {
                            bad += 1;
                            break;
                        }
                    }
                }
                bad
            };
            assert_eq!(exits(1.0), 0, "{edges:?}: rays left the surface inside relaxed cones");
            assert!(exits(2.0) > 0, "{edges:?}: cones twice too wide should let some ray out");
        }
    }
}
