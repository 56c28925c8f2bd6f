//! How steep the bilinear surface can be over a box: the cone build's slope bound.
//!
//! Along a segment the bilinear surface changes by at most the largest gradient norm `G` met
//! on the segment times its length (it is continuous and smooth inside each patch). So a
//! surface point `q` rises above a footprint `C` (whose least depth is `m`) by at most `G`
//! times its distance to `C`, with `G` taken over the box that holds `q`'s region and the
//! part of `C` nearest to it (which holds the segment from `q` to its nearest point of `C`):
//! every point of the region allows the cone a ratio of at least `1 / G`. Where the surface
//! is smooth this bound is close to the ratio the edge of `C` allows, and it prunes at once a
//! neighbourhood that the distance bound alone must split down to small rectangles.
//!
//! The table answers "the largest gradient over a box of patches" in at most four reads: a
//! sparse table of maxima over square windows of `2^L x 2^L` patches, for windows up to
//! [`MAX_SPAN`] patches wide, over the map's patches and a margin around it (patches outside
//! the map repeat or clamp its texels as the edge mode says).

use super::{Search, ceil_i, floor_i};

/// The widest box (in patches along its longer side) the table answers for; wider boxes get
/// no slope bound (their distance bound does well).
pub(super) const MAX_SPAN: i64 = 128;

/// Window sizes 1, 2, 4, ... MAX_SPAN.
const LEVELS: usize = MAX_SPAN.ilog2() as usize + 1;

/// Largest gradient norms of the bilinear surface over square windows of patches.
pub(super) struct SlopeTable {
    /// Patch `(k, l)` (corner texels `(k, l)` to `(k + 1, l + 1)`) is stored at
    /// `(k + pad, l + pad)`.
    pad: i64,
    /// Columns and rows of each level's grid.
    cols: i64,
    rows: i64,
    /// The slope one step of a stored value stands for.
    unit: f64,
    /// At `LEVELS * (l * cols + k) + L`: the largest gradient norm over the `2^L x 2^L`
    /// patches from `(k, l)`, in steps of `unit`, rounded up. The levels of a patch are
    /// together: one footprint's searches ask about boxes of every size around it.
    windows: Vec<u16>,
}

impl SlopeTable {
    pub(super) fn new(search: &Search<'_>) -> Self {
        use rayon::prelude::*;
        // A box touches the footprint (inside the map) and spans at most MAX_SPAN patches; its
        // window may reach half a span further along the box's shorter side.
        let pad = MAX_SPAN + MAX_SPAN / 2 + 2;
        let (w, h) = (i64::from(search.field.width()), i64::from(search.field.height()));
        let (cols, rows) = (w + 2 * pad, h + 2 * pad);
        // The gradient norm of a bilinear patch is largest at a corner: each component is
        // linear in one coordinate, so its square is convex, and so is their sum.
        let gradient = |c: i64, r: i64| {
            let (k, l) = (c - pad, r - pad);
            let (d00, d10, d01, d11) =
                (search.texel(k, l), search.texel(k + 1, l), search.texel(k, l + 1), search.texel(k + 1, l + 1));
            let (gx0, gx1, gy0, gy1) = (d10 - d00, d11 - d01, d01 - d00, d11 - d10);
            gx0.hypot(gy0).max(gx0.hypot(gy1)).max(gx1.hypot(gy0)).max(gx1.hypot(gy1))
        };
        // Two passes over the patches (the largest gradient, then each one quantized) rather
        // than a table of f64 gradients beside the windows: the windows are then the build's
        // whole extra memory, as `bytes` counts it.
        let most = (0..rows)
            .into_par_iter()
            .map(|r| (0..cols).map(|c| gradient(c, r)).fold(0.0, f64::max))
            .reduce(|| 0.0, f64::max);
        // Headroom below u16::MAX, and one step more than the rounded-up quotient, keep every
        // stored value at or above the slope it stands for despite rounding.
        let unit = if most > 0.0 { most / 65_000.0 } else { 1.0 };
        let mut windows = vec![u16::MAX; (cols * rows) as usize * LEVELS];
        windows.par_chunks_mut(LEVELS).enumerate().for_each(|(cell, levels)| {
            let (c, r) = (cell as i64 % cols, cell as i64 / cols);
            levels[0] = ((gradient(c, r) / unit).ceil() + 1.0).min(65_535.0) as u16;
        });
        for level in 1..LEVELS {
            let half = 1i64 << (level - 1);
            for r in 0..rows - half {
                for c in 0..cols - half {
                    let at = |c: i64, r: i64| windows[(r * cols + c) as usize * LEVELS + level - 1];
                    let most = at(c, r).max(at(c + half, r)).max(at(c, r + half)).max(at(c + half, r + half));
                    windows[(r * cols + c) as usize * LEVELS + level] = most;
                }
            }
        }
        Self { pad, cols, rows, unit, windows }
    }

    /// Bytes the table holds for a `w x h` map.
    pub(super) fn bytes(w: u32, h: u32) -> u64 {
        let pad = (MAX_SPAN + MAX_SPAN / 2 + 2) as u64;
        (u64::from(w) + 2 * pad) * (u64::from(h) + 2 * pad) * 2 * LEVELS as u64
    }

    /// An upper bound on the gradient norm of the surface over the box `[x0, x1] x [y0, y1]`
    /// (texel units, `x0 <= x1`, `y0 <= y1`), or `None` where the box is too wide or too far
    /// from the map for the table.
    pub(super) fn max_over(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> Option<f64> {
        // Patch k covers [k + 1/2, k + 3/2]: the patches that meet [x0, x1].
        let span = |a0: f64, a1: f64| {
            let k0 = floor_i(a0 - 0.5);
            let k1 = (ceil_i(a1 - 0.5) - 1).max(k0);
            (k0, k1)
        };
        let ((k0, k1), (l0, l1)) = (span(x0, x1), span(y0, y1));
        let (nx, ny) = (k1 - k0 + 1, l1 - l0 + 1);
        let n = nx.max(ny);
        if n > MAX_SPAN {
            return None;
        }
        // Windows of side s <= n < 2 s: two along an axis at least s long cover it exactly,
        // one centred on a shorter axis covers it.
        let level = n.ilog2();
        let s = 1i64 << level;
        let starts = |a0: i64, a1: i64, len: i64| -> [i64; 2] {
            if len >= s { [a0, a1 - s + 1] } else { [a0 - (s - len) / 2; 2] }
        };
        let mut most = 0u16;
        for c in starts(k0, k1, nx) {
            for r in starts(l0, l1, ny) {
                let (c, r) = (c + self.pad, r + self.pad);
                if c < 0 || r < 0 || c + s > self.cols || r + s > self.rows {
                    return None;
                }
                most = most.max(self.windows[(r * self.cols + c) as usize * LEVELS + level as usize]);
            }
        }
        Some(f64::from(most) * self.unit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::EdgeMode;
    use crate::pyramid::MaxHeightPyramid;
    use crate::pyramid::tests::noisy;

    /// The largest gradient norm of the bilinear surface over a box, sampled densely (a lower
    /// bound on the true largest, which the table must not undercut).
    fn sampled_max(search: &Search<'_>, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
        let n = 24;
        let mut most: f64 = 0.0;
        for a in 0..=n {
            for b in 0..=n {
                let x = x0 + (x1 - x0) * f64::from(a) / f64::from(n);
                let y = y0 + (y1 - y0) * f64::from(b) / f64::from(n);
                // The patch holding (x, y); on a patch boundary both sides' slopes count.
                for (ex, ey) in [(-1e-9, -1e-9), (1e-9, -1e-9), (-1e-9, 1e-9), (1e-9, 1e-9)] {
                    let (px, py) = (x + ex, y + ey);
                    if px < x0 || px > x1 || py < y0 || py > y1 {
                        continue;
                    }
                    let (k, l) = ((px - 0.5).floor() as i64, (py - 0.5).floor() as i64);
                    let (gx, gy) = search.patch_slope(k, l, px, py);
                    most = most.max(gx.hypot(gy));
                }
            }
        }
        most
    }

    /// The largest corner gradient norm of the patches that meet a box.
    fn patch_max(search: &Search<'_>, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
        let mut most: f64 = 0.0;
        for l in (y0 - 0.5).floor() as i64..=(y1 - 0.5).floor() as i64 {
            for k in (x0 - 0.5).floor() as i64..=(x1 - 0.5).floor() as i64 {
                for (x, y) in [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5), (1.5, 1.5)] {
                    let (gx, gy) = search.patch_slope(k, l, k as f64 + x, l as f64 + y);
                    most = most.max(gx.hypot(gy));
                }
            }
        }
        most
    }

    #[test]
    fn the_table_bounds_the_slope_over_any_box_and_not_by_much_more_than_its_windows() {
        for (w, h, edges, seed) in [(40, 33, EdgeMode::Wrap, 5), (37, 40, EdgeMode::Clamp, 6)] {
            let field = noisy(w, h, seed);
            let pyramid = MaxHeightPyramid::new(&field, edges);
            let search = Search::new(&field, &pyramid, edges);
            let table = SlopeTable::new(&search);
            let mut state = seed;
            let mut next = move || {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
                f64::from((state >> 8) & 0xffff) / 65_536.0
            };
            let mut answered = 0;
            for _ in 0..400 {
                let (x0, y0) = (next() * f64::from(w), next() * f64::from(h));
                let (sx, sy) = (next() * next() * 40.0, next() * next() * 40.0);
                let (x1, y1) = (x0 + sx, y0 + sy);
                let Some(g) = table.max_over(x0, x1, y0, y1) else {
                    assert!(sx.max(sy) > MAX_SPAN as f64 - 2.0, "box {sx:.1} x {sy:.1} unanswered");
                    continue;
                };
                answered += 1;
                let truth = sampled_max(&search, x0, x1, y0, y1);
                assert!(g >= truth, "box ({x0:.2}..{x1:.2}, {y0:.2}..{y1:.2}): table {g} below the slope {truth}");
                // Never more than the largest slope of the patches within the box's longer side
                // of it (the windows reach at most that far beyond the box).
                let grow = sx.max(sy) + 2.0;
                let around = patch_max(&search, x0 - grow, x1 + grow, y0 - grow, y1 + grow);
                assert!(g <= around * (1.0 + 1e-3) + 1e-12, "table {g} over {around} around the box");
            }
            assert!(answered > 300, "only {answered} boxes answered");
        }
    }
}
