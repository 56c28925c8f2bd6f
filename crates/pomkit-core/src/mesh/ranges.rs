//! Bounds on a height field's depth over a box of UV, without sampling inside it: a pyramid of
//! the least and greatest texel depth over blocks of `2^L x 2^L` texels. The displaced
//! reference's planning uses it to settle a block whose whole relief is too shallow to see
//! before sampling its grid, and to bound where its vertices can be.

use glam::Vec2;

use crate::heightfield::{EdgeMode, HeightField, floor};

/// Per level `L`, the least and greatest depth of the texels `[x 2^L, (x + 1) 2^L) x
/// [y 2^L, (y + 1) 2^L)` (clipped to the field) in cell `(x, y)`; each level halves the
/// previous one's sides, rounding up, down to one cell.
#[derive(Clone, Debug)]
pub(super) struct DepthRanges {
    edges: EdgeMode,
    levels: Vec<Level>,
}

/// A level of [`DepthRanges`]: its width, height and cells, row by row.
type Level = (u32, u32, Vec<(f32, f32)>);

impl DepthRanges {
    /// The pyramid of `field`, sampled with `edges`.
    pub(super) fn new(field: &HeightField, edges: EdgeMode) -> Self {
        let (w, h) = (field.width(), field.height());
        let mut levels = vec![(w, h, field.depths().iter().map(|&d| (d, d)).collect::<Vec<_>>())];
        while let Some((w, h, cells)) = levels.last().filter(|(w, h, _)| *w > 1 || *h > 1) {
            let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
            let mut next = Vec::with_capacity(nw as usize * nh as usize);
            for y in 0..nh {
                for x in 0..nw {
                    let mut r = (f32::INFINITY, f32::NEG_INFINITY);
                    for (cx, cy) in [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)] {
                        if cx < *w && cy < *h {
                            let c = cells[(cy * w + cx) as usize];
                            r = (r.0.min(c.0), r.1.max(c.1));
                        }
                    }
                    next.push(r);
                }
            }
            levels.push((nw, nh, next));
        }
        Self { edges, levels }
    }

    /// The least and greatest depth that bilinear samples ([`HeightField::sample_bilinear`] with
    /// this pyramid's edge mode) at any UV in `[lo, hi]` can take: every such sample blends
    /// four texels of the texel rectangle under the box (widened by a texel for rounding), so
    /// it lies within their range. `None` for a box that is not finite.
    pub(super) fn over(&self, lo: Vec2, hi: Vec2) -> Option<(f32, f32)> {
        let (w, h, _) = self.levels[0];
        let size = Vec2::new(w as f32, h as f32);
        let (a, b) = (lo * size - 0.5, hi * size - 0.5);
        if !(a.is_finite() && b.is_finite()) || a.x > b.x || a.y > b.y {
            return None;
        }
        // Texels x0 - 1 ..= x1 + 2 hold every footprint's pair (x, x + 1), with a texel spare
        // on both sides for the rounding of the box.
        let span = |a: f32, b: f32| -> Option<(i64, i64)> {
            let (x0, x1) = (floor(a), floor(b));
            (x0.abs() < 1e15 && x1.abs() < 1e15).then(|| (x0 as i64 - 1, x1 as i64 + 2))
        };
        let (xs, ys) = (span(a.x, b.x)?, span(a.y, b.y)?);
        let mut out = (f32::INFINITY, f32::NEG_INFINITY);
        for (x0, x1) in self.resolve(xs, w).into_iter().flatten() {
            for (y0, y1) in self.resolve(ys, h).into_iter().flatten() {
                let r = self.rect(x0, x1, y0, y1);
                out = (out.0.min(r.0), out.1.max(r.1));
            }
        }
        Some(out)
    }

    /// The texel ranges (inclusive, inside `0..size`) that the coordinates `first..=last`
    /// resolve to under the edge mode: one or two runs.
    fn resolve(&self, (first, last): (i64, i64), size: u32) -> [Option<(u32, u32)>; 2] {
        let n = i64::from(size);
        match self.edges {
            EdgeMode::Clamp => [Some((first.clamp(0, n - 1) as u32, last.clamp(0, n - 1) as u32)), None],
            EdgeMode::Wrap if last - first + 1 >= n => [Some((0, size - 1)), None],
            EdgeMode::Wrap => {
                let (a, b) = (first.rem_euclid(n), last.rem_euclid(n));
                if a <= b {
                    [Some((a as u32, b as u32)), None]
                } else {
                    [Some((a as u32, size - 1)), Some((0, b as u32))]
                }
            }
        }
    }

    /// The range of the texels `[x0, x1] x [y0, y1]` (inside the field), from the finest level
    /// at which they fall within two cells a side (so up to four cells, which may hold more
    /// texels than asked: the range is conservative).
    fn rect(&self, x0: u32, x1: u32, y0: u32, y1: u32) -> (f32, f32) {
        let mut l = 0;
        while l + 1 < self.levels.len() && ((x1 >> l) - (x0 >> l) > 1 || (y1 >> l) - (y0 >> l) > 1) {
            l += 1;
        }
        let (w, _, cells) = &self.levels[l];
        let mut out = (f32::INFINITY, f32::NEG_INFINITY);
        for y in (y0 >> l)..=(y1 >> l) {
            for x in (x0 >> l)..=(x1 >> l) {
                let c = cells[(y * w + x) as usize];
                out = (out.0.min(c.0), out.1.max(c.1));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::{Pattern, generate};

    /// Every bilinear sample on a fine grid over random boxes (some crossing the field's edges,
    /// some wider than it) lies in the range the pyramid gives, for both edge modes and a size
    /// that is not a power of two.
    #[test]
    fn bilinear_samples_in_a_box_lie_in_its_range() {
        for (w, h) in [(64, 64), (37, 23)] {
            let field = generate(Pattern::Cobblestones, w, h);
            for edges in EdgeMode::ALL {
                let ranges = DepthRanges::new(&field, edges);
                let mut seed = 12345u64;
                let mut rand = || {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    (seed >> 40) as f32 / (1u64 << 24) as f32
                };
                for _ in 0..300 {
                    let lo = Vec2::new(rand() * 6.0 - 3.0, rand() * 6.0 - 3.0);
                    let size = Vec2::new(rand(), rand()) * if rand() < 0.8 { 0.2 } else { 1.5 };
                    let hi = lo + size;
                    let (a, b) = ranges.over(lo, hi).unwrap();
                    assert!(a <= b);
                    for y in 0..=16 {
                        for x in 0..=16 {
                            let uv = lo + (hi - lo) * Vec2::new(x as f32, y as f32) / 16.0;
                            let d = field.sample_bilinear(uv, edges);
                            assert!(a <= d && d <= b, "{d} outside [{a}, {b}] at {uv} ({edges:?}, {w}x{h})");
                        }
                    }
                }
            }
        }
    }

    /// The range is the field's own over a box that holds it all, and is tight over one texel's
    /// centre region (a box inside the square between four texel centres reads those four).
    #[test]
    fn the_range_is_the_texels_range_where_it_can_tell() {
        let field = generate(Pattern::Bricks, 32, 32);
        let ranges = DepthRanges::new(&field, EdgeMode::Wrap);
        let all = field.depths().iter().fold((f32::INFINITY, f32::NEG_INFINITY), |r, &d| (r.0.min(d), r.1.max(d)));
        assert_eq!(ranges.over(Vec2::ZERO, Vec2::ONE), Some(all));
        assert_eq!(ranges.over(Vec2::splat(-5.0), Vec2::splat(7.0)), Some(all));
        assert_eq!(ranges.over(Vec2::NAN, Vec2::ONE), None);
        // A small box's range is within the field's and found from at most 4x4 texels' cells.
        let (a, b) = ranges.over(Vec2::splat(0.5), Vec2::splat(0.51)).unwrap();
        assert!(all.0 <= a && b <= all.1);
    }
}
