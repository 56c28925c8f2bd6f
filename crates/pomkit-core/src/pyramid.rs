//! The maximum-height (minimum-depth) pyramid: a quadtree of conservative depth bounds.
//!
//! Level 0 has one cell per texel, covering that texel's footprint in UV,
//! `[i / w, (i + 1) / w] x [j / h, (j + 1) / h]`. Its value is the *least depth* (the greatest
//! height) that the bilinear surface reaches anywhere inside the footprint. Each coarser level
//! halves the cell count (rounding up, so any size works) and keeps the minimum of its up to
//! four children. So every cell bounds the exact surface inside it: a ray that stays shallower
//! than a cell's value cannot hit anything in that cell. The exact tracer walks this tree.
//!
//! Why the bound is tight: a texel footprint straddles four bilinear patches (the squares
//! between texel centres), a quarter of each. A bilinear function restricted to an axis-aligned
//! rectangle inside one patch is monotone along each axis, so its extremes lie at the
//! rectangle's corners. The corners of the four quarters are the texel centre, the four edge
//! midpoints and the four footprint corners: the minimum of those nine values is exactly the
//! minimum depth of the surface over the footprint (not merely a bound).

use crate::heightfield::{EdgeMode, HeightField};

/// One level of the pyramid.
#[derive(Clone, Debug, PartialEq)]
struct Level {
    width: u32,
    height: u32,
    min_depth: Vec<f32>,
}

/// Minimum-depth bounds over texel footprints and their quadtree ancestors.
#[derive(Clone, Debug, PartialEq)]
pub struct MaxHeightPyramid {
    edges: EdgeMode,
    base_width: u32,
    base_height: u32,
    levels: Vec<Level>,
}

/// A depth type the footprint minimum is computed in: `f32` for the pyramid, `f64` for the cone
/// build's exact tops. The same expression in either, so each is what its caller always had.
pub(crate) trait Depth: Copy + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self> {
    /// 1/2.
    const HALF: Self;
    /// 1/4.
    const QUARTER: Self;
    /// The smaller of the two.
    fn min(self, other: Self) -> Self;
}

impl Depth for f32 {
    const HALF: Self = 0.5;
    const QUARTER: Self = 0.25;
    fn min(self, other: Self) -> Self {
        f32::min(self, other)
    }
}

impl Depth for f64 {
    const HALF: Self = 0.5;
    const QUARTER: Self = 0.25;
    fn min(self, other: Self) -> Self {
        f64::min(self, other)
    }
}

/// The least depth of the bilinear surface over one texel's footprint: the least of the nine
/// corners of its four quarters (its centre, edge midpoints and corners; the module docs say
/// why that is exact). `d(dx, dy)` is the depth of the texel at offset `(dx, dy)`, each in
/// `-1..=1`. The pyramid's level 0 and the cone build's exact tops both use it.
pub(crate) fn footprint_min<T: Depth>(d: impl Fn(i64, i64) -> T) -> T {
    let c = d(0, 0);
    let (l, r, u, b) = (d(-1, 0), d(1, 0), d(0, -1), d(0, 1));
    let (ul, ur, bl, br) = (d(-1, -1), d(1, -1), d(-1, 1), d(1, 1));
    let mids = [(c + l) * T::HALF, (c + r) * T::HALF, (c + u) * T::HALF, (c + b) * T::HALF];
    let q = T::QUARTER;
    let corners = [(c + l + u + ul) * q, (c + r + u + ur) * q, (c + l + b + bl) * q, (c + r + b + br) * q];
    mids.into_iter().chain(corners).fold(c, T::min)
}

impl MaxHeightPyramid {
    /// Builds the pyramid of `field` for the given edge mode (which decides the neighbours of
    /// border texels, exactly as bilinear sampling with that mode does).
    #[must_use]
    pub fn new(field: &HeightField, edges: EdgeMode) -> Self {
        let (w, h) = (field.width(), field.height());
        let mut base = Vec::with_capacity(w as usize * h as usize);
        for y in 0..i64::from(h) {
            for x in 0..i64::from(w) {
                base.push(footprint_min(|dx, dy| field.depth_at(x + dx, y + dy, edges)));
            }
        }
        let mut levels = vec![Level { width: w, height: h, min_depth: base }];
        while let Some(last) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            let (nw, nh) = (last.width.div_ceil(2), last.height.div_ceil(2));
            let mut next = Vec::with_capacity(nw as usize * nh as usize);
            for y in 0..nh {
                for x in 0..nw {
                    let mut m = f32::INFINITY;
                    for (cx, cy) in [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)] {
                        if cx < last.width && cy < last.height {
                            m = m.min(last.min_depth[(cy * last.width + cx) as usize]);
                        }
                    }
                    next.push(m);
                }
            }
            levels.push(Level { width: nw, height: nh, min_depth: next });
        }
        Self { edges, base_width: w, base_height: h, levels }
    }

    /// Number of levels; the last one is a single cell bounding the whole field.
    #[must_use]
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// Always false: a pyramid has at least one level.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// The edge mode the bounds were built for.
    #[must_use]
    pub fn edges(&self) -> EdgeMode {
        self.edges
    }

    /// Cells `(columns, rows)` at `level`.
    ///
    /// # Panics
    /// If `level >= self.len()`.
    #[must_use]
    pub fn level_size(&self, level: usize) -> (u32, u32) {
        let l = &self.levels[level];
        (l.width, l.height)
    }

    /// Least depth of the bilinear surface inside cell `(x, y)` of `level`.
    ///
    /// # Panics
    /// If the level or cell is out of range.
    #[inline]
    #[must_use]
    pub fn min_depth(&self, level: usize, x: u32, y: u32) -> f32 {
        let l = &self.levels[level];
        assert!(x < l.width && y < l.height, "cell ({x}, {y}) outside level {level} ({}x{})", l.width, l.height);
        l.min_depth[(y * l.width + x) as usize]
    }

    /// The range of level-0 texels `[x0, x1) x [y0, y1)` covered by cell `(x, y)` of `level`
    /// (the last row and column may be cut short on sizes that are not powers of two).
    #[must_use]
    pub fn cell_texels(&self, level: usize, x: u32, y: u32) -> ([u32; 2], [u32; 2]) {
        let s = 1u32 << level.min(31);
        let x0 = x.saturating_mul(s).min(self.base_width);
        let y0 = y.saturating_mul(s).min(self.base_height);
        let x1 = (x.saturating_add(1)).saturating_mul(s).min(self.base_width);
        let y1 = (y.saturating_add(1)).saturating_mul(s).min(self.base_height);
        ([x0, x1], [y0, y1])
    }
}

impl MaxHeightPyramid {
    /// The size of [`MaxHeightPyramid::atlas_gray16`]'s image: level 0 on the left and the
    /// coarser levels stacked in a column to its right, each at the top of the space left.
    #[must_use]
    pub fn atlas_size(&self) -> (u32, u32) {
        let (w, h) = self.level_size(0);
        if self.levels.len() == 1 {
            return (w, h);
        }
        let column: u32 = self.levels[1..].iter().map(|l| l.height).sum();
        (w + self.levels[1].width, h.max(column))
    }

    /// Where level `level` starts in the atlas: `(x, y)` of its top-left cell.
    ///
    /// # Panics
    /// If `level >= self.len()`.
    #[must_use]
    pub fn atlas_origin(&self, level: usize) -> (u32, u32) {
        assert!(level < self.levels.len(), "level {level} of {}", self.levels.len());
        if level == 0 {
            return (0, 0);
        }
        (self.base_width, self.levels[1..level].iter().map(|l| l.height).sum())
    }

    /// The whole pyramid as one 16-bit grey image (row-major, [`MaxHeightPyramid::atlas_size`]),
    /// as `pomkit bake maxmip` writes it: each cell's greatest height `1 - min_depth`, rounded up
    /// (so the stored bound stays a bound), white = high; the space no level uses is 0. Level
    /// `k` starts at [`MaxHeightPyramid::atlas_origin`].
    #[must_use]
    pub fn atlas_gray16(&self) -> Vec<u16> {
        let (aw, ah) = self.atlas_size();
        let mut out = vec![0u16; aw as usize * ah as usize];
        for (k, l) in self.levels.iter().enumerate() {
            let (ox, oy) = self.atlas_origin(k);
            for y in 0..l.height {
                for x in 0..l.width {
                    let height = f64::from(1.0 - l.min_depth[(y * l.width + x) as usize]).clamp(0.0, 1.0);
                    out[((oy + y) * aw + ox + x) as usize] = (height * 65535.0).ceil() as u16;
                }
            }
        }
        out
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec2;

    /// Hashed noise in `[0, 1)`, a different field per seed (shared with the cone map tests).
    pub(crate) fn noisy(w: u32, h: u32, seed: u32) -> HeightField {
        HeightField::from_height_fn(w, h, |x, y| {
            let mut k = x.wrapping_mul(374_761_393) ^ y.wrapping_mul(668_265_263) ^ seed.wrapping_mul(2_246_822_519);
            k = (k ^ (k >> 13)).wrapping_mul(1_274_126_177);
            (k >> 8) as f32 / (1u32 << 24) as f32
        })
    }

    /// Independent truth: sample the bilinear surface densely (including the footprint's
    /// corners and edge midpoints) and take the minimum.
    fn brute_min_depth(f: &HeightField, edges: EdgeMode, x0: u32, x1: u32, y0: u32, y1: u32) -> f32 {
        let n = 8;
        let mut m = f32::INFINITY;
        for ty in y0 * n..=y1 * n {
            for tx in x0 * n..=x1 * n {
                let uv = Vec2::new(tx as f32 / n as f32 / f.width() as f32, ty as f32 / n as f32 / f.height() as f32);
                m = m.min(f.sample_bilinear(uv, edges));
            }
        }
        m
    }

    #[test]
    fn every_cell_bounds_the_surface_tightly() {
        for (w, h, edges) in
            [(8, 8, EdgeMode::Wrap), (7, 5, EdgeMode::Clamp), (5, 9, EdgeMode::Wrap), (1, 3, EdgeMode::Clamp)]
        {
            let f = noisy(w, h, w * 31 + h);
            let p = MaxHeightPyramid::new(&f, edges);
            for level in 0..p.len() {
                let (cw, ch) = p.level_size(level);
                for y in 0..ch {
                    for x in 0..cw {
                        let ([x0, x1], [y0, y1]) = p.cell_texels(level, x, y);
                        let truth = brute_min_depth(&f, edges, x0, x1, y0, y1);
                        let bound = p.min_depth(level, x, y);
                        assert!(
                            bound <= truth + 1e-6,
                            "{w}x{h} {edges:?} level {level} cell ({x},{y}): {bound} > {truth}"
                        );
                        assert!((bound - truth).abs() < 1e-5, "bound not tight: {bound} vs {truth}");
                    }
                }
            }
            let top = p.len() - 1;
            assert_eq!(p.level_size(top), (1, 1));
        }
    }

    #[test]
    fn wrap_and_clamp_differ_at_the_border() {
        // A deep left column next to a shallow right column: with wrap the left footprint sees
        // the right column's shallow values, with clamp it does not.
        let f = HeightField::from_depths(3, 1, vec![1.0, 1.0, 0.0]).unwrap();
        assert_eq!(MaxHeightPyramid::new(&f, EdgeMode::Wrap).min_depth(0, 0, 0), 0.5);
        assert_eq!(MaxHeightPyramid::new(&f, EdgeMode::Clamp).min_depth(0, 0, 0), 1.0);
    }

    #[test]
    fn cell_texels_cover_non_power_of_two_sizes() {
        let p = MaxHeightPyramid::new(&HeightField::constant(5, 3, 0.5), EdgeMode::Wrap);
        assert_eq!(p.level_size(1), (3, 2));
        assert_eq!(p.cell_texels(1, 2, 1), ([4, 5], [2, 3]));
        assert_eq!(p.level_size(p.len() - 1), (1, 1));
        assert_eq!(p.cell_texels(p.len() - 1, 0, 0), ([0, 5], [0, 3]));
    }

    #[test]
    fn the_atlas_holds_every_level_where_it_says_rounded_up() {
        for (w, h) in [(8, 8), (7, 5), (1, 1), (1, 6)] {
            let f = noisy(w, h, 7);
            let p = MaxHeightPyramid::new(&f, EdgeMode::Wrap);
            let (aw, ah) = p.atlas_size();
            let atlas = p.atlas_gray16();
            assert_eq!(atlas.len(), (aw * ah) as usize);
            let mut used = vec![false; atlas.len()];
            for level in 0..p.len() {
                let (ox, oy) = p.atlas_origin(level);
                let (lw, lh) = p.level_size(level);
                for y in 0..lh {
                    for x in 0..lw {
                        let k = ((oy + y) * aw + ox + x) as usize;
                        assert!(!used[k], "{w}x{h}: levels overlap at ({}, {})", ox + x, oy + y);
                        used[k] = true;
                        let stored = f64::from(atlas[k]) / 65535.0;
                        let bound = 1.0 - f64::from(p.min_depth(level, x, y));
                        assert!(stored >= bound - 1e-7 && stored < bound + 1.0 / 65535.0, "{w}x{h} level {level}");
                    }
                }
            }
            // Level 0 fills the left, the rest a column one level-1 width wide.
            assert_eq!(aw, if p.len() > 1 { w + p.level_size(1).0 } else { w });
            assert!(used.iter().zip(&atlas).all(|(&u, &v)| u || v == 0));
        }
    }
}
