//! One texel grid under height fields, colour textures and normal maps: size, row-major
//! storage, wrap/clamp addressing, nearest and bilinear sampling, box downsampling, mip chains.
//!
//! Texel `(i, j)` (column `i`, row `j`) has its centre at `((i + 0.5) / w, (j + 0.5) / h)` in
//! UV; bilinear filtering interpolates between texel centres, as a GPU does. Any size is
//! allowed, not only powers of two.

use std::ops::{AddAssign, Div, Mul};

use glam::{DVec3, Vec2, Vec3};

/// What happens to texel coordinates outside the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum EdgeMode {
    /// The image tiles: texel `-1` is the last texel (`GL_REPEAT`). The default.
    #[default]
    Wrap,
    /// Coordinates clamp to the border texel (`GL_CLAMP_TO_EDGE`).
    Clamp,
}

impl EdgeMode {
    /// Both modes.
    pub const ALL: [EdgeMode; 2] = [EdgeMode::Wrap, EdgeMode::Clamp];

    /// The name scene files and the command line use.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            EdgeMode::Wrap => "wrap",
            EdgeMode::Clamp => "clamp",
        }
    }

    /// The mode named `name` (case-insensitive), if any.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|e| e.name().eq_ignore_ascii_case(name))
    }

    /// Maps an integer texel coordinate into `0..size` by wrapping or clamping.
    ///
    /// # Panics
    /// Panics in debug builds if `size` is 0.
    #[inline]
    #[must_use]
    pub fn resolve(self, i: i64, size: u32) -> u32 {
        debug_assert!(size > 0);
        // Most coordinates are inside already: no division for them.
        if (0..i64::from(size)).contains(&i) {
            return i as u32;
        }
        match self {
            // A power-of-two size (the usual texture) wraps by a mask, which two's complement
            // makes right for negative `i` too; any other by `rem_euclid`, in 32 bits when `i`
            // fits (a 64-bit division costs several times a 32-bit one).
            EdgeMode::Wrap if size.is_power_of_two() => (i & (i64::from(size) - 1)) as u32,
            EdgeMode::Wrap => match (i32::try_from(i), i32::try_from(size)) {
                (Ok(i), Ok(size)) => i.rem_euclid(size) as u32,
                _ => i.rem_euclid(i64::from(size)) as u32,
            },
            EdgeMode::Clamp => i.clamp(0, i64::from(size) - 1) as u32,
        }
    }

    /// `(self.resolve(i, size), self.resolve(i.saturating_add(1), size))`, the coordinates of a
    /// bilinear footprint's two columns (or rows), with one division at most.
    #[inline]
    #[must_use]
    pub fn resolve_pair(self, i: i64, size: u32) -> (u32, u32) {
        let a = self.resolve(i, size);
        let b = match self {
            // The wrapped neighbour of a wrapped coordinate: one step on, or back to 0.
            EdgeMode::Wrap if i < i64::MAX => {
                if a + 1 == size {
                    0
                } else {
                    a + 1
                }
            }
            _ => self.resolve(i.saturating_add(1), size),
        };
        (a, b)
    }
}

/// `x.floor()` without a call into libm on targets without SSE4.1 (the baseline x86-64 this
/// crate builds for), exact for every finite `x`.
#[inline]
#[must_use]
pub fn floor(x: f32) -> f32 {
    // Beyond 2^23 every f32 is a whole number already.
    if x.abs() < 8_388_608.0 {
        let i = x as i32 as f32;
        if i > x { i - 1.0 } else { i }
    } else {
        x
    }
}

/// The arithmetic a texel type brings to a [`Grid`]: interpolation for bilinear sampling, sums
/// for [`Grid::downsample_box`] and `f64` sums for [`Grid::downsample_area`].
pub trait Texel: Copy + Default + AddAssign + Div<f32, Output = Self> {
    /// The `f64` counterpart [`Grid::downsample_area`] accumulates in.
    type Wide: Copy + Default + AddAssign + Mul<f64, Output = Self::Wide>;

    /// From `self` (at `t = 0`) to `to` (at `t = 1`): `self + (to - self) * t` for `f32`,
    /// glam's `self * (1 - t) + to * t` for [`Vec3`].
    #[must_use]
    fn lerp(self, to: Self, t: f32) -> Self;

    /// `self` in `f64`.
    #[must_use]
    fn widen(self) -> Self::Wide;

    /// `wide` rounded to `f32`.
    #[must_use]
    fn narrow(wide: Self::Wide) -> Self;
}

impl Texel for f32 {
    type Wide = f64;

    #[inline]
    fn lerp(self, to: Self, t: f32) -> Self {
        self + (to - self) * t
    }

    #[inline]
    fn widen(self) -> f64 {
        f64::from(self)
    }

    #[inline]
    fn narrow(wide: f64) -> Self {
        wide as f32
    }
}

impl Texel for Vec3 {
    type Wide = DVec3;

    #[inline]
    fn lerp(self, to: Self, t: f32) -> Self {
        Vec3::lerp(self, to, t)
    }

    #[inline]
    fn widen(self) -> DVec3 {
        self.as_dvec3()
    }

    #[inline]
    fn narrow(wide: DVec3) -> Self {
        wide.as_vec3()
    }
}

/// A `width x height` grid of texels, row-major, top row first; both sides at least 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    width: u32,
    height: u32,
    texels: Vec<T>,
}

impl<T> Grid<T> {
    /// A grid of `texels`, row-major; `None` if a side is 0 or the length is not
    /// `width * height`.
    #[must_use]
    pub fn new(width: u32, height: u32, texels: Vec<T>) -> Option<Self> {
        (width > 0 && height > 0 && texels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            texels,
        })
    }

    /// A grid whose texel `(x, y)` is `f(x, y)`, called row by row, top row first. Sides of 0
    /// become 1.
    #[must_use]
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> T) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                texels.push(f(x, y));
            }
        }
        Self { width, height, texels }
    }

    /// A grid the caller has checked (sides at least 1, `width * height` texels).
    pub(crate) fn from_checked(width: u32, height: u32, texels: Vec<T>) -> Self {
        debug_assert!(width > 0 && height > 0 && texels.len() == width as usize * height as usize);
        Self { width, height, texels }
    }

    /// Width in texels (columns).
    #[inline]
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels (rows).
    #[inline]
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// `(width, height)` as floats, for UV <-> texel conversions.
    #[inline]
    #[must_use]
    pub fn size_f32(&self) -> Vec2 {
        Vec2::new(self.width as f32, self.height as f32)
    }

    /// The texels, row-major, top row first.
    #[inline]
    #[must_use]
    pub fn texels(&self) -> &[T] {
        &self.texels
    }

    /// The same grid with every texel mapped through `f`.
    #[must_use]
    pub fn map<U>(self, f: impl FnMut(T) -> U) -> Grid<U> {
        Grid { width: self.width, height: self.height, texels: self.texels.into_iter().map(f).collect() }
    }

    /// Every level from `self` down to 1x1, each level `next` of the one before (`next` must
    /// shrink a grid larger than 1x1, as [`Grid::downsample_box`] and
    /// [`Grid::downsample_area`] do; the chain ends at a level that `next` does not shrink).
    #[must_use]
    pub fn mip_chain(self, mut next: impl FnMut(&Self) -> Self) -> Vec<Self> {
        let mut chain = vec![self];
        while let Some(last) = chain.last().filter(|g| g.width > 1 || g.height > 1) {
            let next = next(last);
            // A `next` that does not shrink the grid would loop for ever: the chain ends there.
            let shrank = next.width < last.width || next.height < last.height;
            debug_assert!(shrank, "mip_chain: a level of {}x{} did not shrink", last.width, last.height);
            if !shrank {
                break;
            }
            chain.push(next);
        }
        chain
    }
}

impl<T: Copy> Grid<T> {
    /// Texel `(x, y)`, with out-of-range coordinates wrapped or clamped.
    #[inline]
    #[must_use]
    pub fn at(&self, x: i64, y: i64, edges: EdgeMode) -> T {
        let xi = edges.resolve(x, self.width) as usize;
        let yi = edges.resolve(y, self.height) as usize;
        self.texels[yi * self.width as usize + xi]
    }

    /// The texel containing `uv` (nearest filtering). Non-finite UVs sample texel (0, 0).
    #[must_use]
    pub fn sample_nearest(&self, uv: Vec2, edges: EdgeMode) -> T {
        let t = uv * self.size_f32();
        let t = if t.is_finite() { t } else { Vec2::ZERO };
        self.at(t.x.floor() as i64, t.y.floor() as i64, edges)
    }
}

impl<T: Texel> Grid<T> {
    /// Bilinear interpolation at `uv` between the four nearest texel centres: along x in the
    /// top and the bottom row, then between the two along y. Non-finite UVs sample around
    /// texel (0, 0) rather than panic.
    #[inline]
    #[must_use]
    pub fn sample_bilinear(&self, uv: Vec2, edges: EdgeMode) -> T {
        let t = uv * self.size_f32() - 0.5;
        let t = if t.is_finite() { t } else { Vec2::ZERO };
        let f = Vec2::new(floor(t.x), floor(t.y));
        let (fx, fy) = (t.x - f.x, t.y - f.y);
        // `as` saturates far outside the i64 range (|uv| * size beyond 9.2e18); the neighbour then
        // saturates too rather than overflow (such coordinates carry no sub-texel position in f32
        // anyway).
        let (x0, y0) = (f.x as i64, f.y as i64);
        let width = self.width as usize;
        let [t00, t10, t01, t11] =
            if x0 >= 0 && y0 >= 0 && x0 < i64::from(self.width) - 1 && y0 < i64::from(self.height) - 1 {
                // Inside: the four texels without edge handling.
                let at = y0 as usize * width + x0 as usize;
                [self.texels[at], self.texels[at + 1], self.texels[at + width], self.texels[at + width + 1]]
            } else {
                // The texels `at` would read at x0, x0 + 1 (saturating) and y0, y0 + 1, each
                // coordinate resolved once.
                let (xa, xb) = edges.resolve_pair(x0, self.width);
                let (ya, yb) = edges.resolve_pair(y0, self.height);
                let (ra, rb) = (ya as usize * width, yb as usize * width);
                let (xa, xb) = (xa as usize, xb as usize);
                [self.texels[ra + xa], self.texels[ra + xb], self.texels[rb + xa], self.texels[rb + xb]]
            };
        let top = t00.lerp(t10, fx);
        let bottom = t01.lerp(t11, fx);
        top.lerp(bottom, fy)
    }

    /// The next coarser level by a 2x2 box filter in `f32`: sides halve (rounding down, never
    /// below 1), and an odd side folds its last texel into the last block (which then averages
    /// 3 texels along that side).
    #[must_use]
    pub fn downsample_box(&self) -> Self {
        let (nw, nh) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let mut texels = Vec::with_capacity(nw as usize * nh as usize);
        for y in 0..nh {
            for x in 0..nw {
                let (x0, y0) = (x * self.width / nw, y * self.height / nh);
                let (x1, y1) = (((x + 1) * self.width / nw).max(x0 + 1), ((y + 1) * self.height / nh).max(y0 + 1));
                let mut acc = T::default();
                for yy in y0..y1 {
                    for xx in x0..x1 {
                        acc += self.texels[(yy * self.width + xx) as usize];
                    }
                }
                texels.push(acc / ((x1 - x0) * (y1 - y0)) as f32);
            }
        }
        Self { width: nw, height: nh, texels }
    }

    /// The next coarser level by a box filter over the exact footprint, summed in `f64`.
    ///
    /// Sides halve as in [`Grid::downsample_box`]. For odd sides a coarse texel covers
    /// 2 + 1/(n') fine texels; each fine texel is weighted by the length of its overlap with
    /// that footprint, so the mean is preserved.
    #[must_use]
    pub fn downsample_area(&self) -> Self {
        let nw = (self.width / 2).max(1);
        let nh = (self.height / 2).max(1);
        let wx = box_weights(self.width, nw);
        let wy = box_weights(self.height, nh);
        let mut texels = Vec::with_capacity(nw as usize * nh as usize);
        for row_weights in &wy {
            for col_weights in &wx {
                let mut acc = T::Wide::default();
                for &(sy, wyv) in row_weights {
                    for &(sx, wxv) in col_weights {
                        acc += self.texels[sy as usize * self.width as usize + sx as usize].widen() * wyv * wxv;
                    }
                }
                texels.push(T::narrow(acc));
            }
        }
        Self { width: nw, height: nh, texels }
    }
}

/// For each of the `m` coarse cells over `n` fine cells, the fine indices it overlaps and the
/// normalized overlap weights.
fn box_weights(n: u32, m: u32) -> Vec<Vec<(u32, f64)>> {
    let ratio = f64::from(n) / f64::from(m);
    (0..m)
        .map(|o| {
            let (a, b) = (f64::from(o) * ratio, f64::from(o + 1) * ratio);
            let mut w = Vec::new();
            let first = a.floor() as u32;
            let last = (b.ceil() as u32).min(n);
            for s in first..last {
                let overlap = (b.min(f64::from(s + 1)) - a.max(f64::from(s))).max(0.0);
                if overlap > 0.0 {
                    w.push((s, overlap / ratio));
                }
            }
            w
        })
        .collect()
}

/// The index of the coarsest level (1x1) of a `width x height` mip chain whose sides halve,
/// rounding down, never below 1: the length of [`Grid::mip_chain`] minus 1.
#[must_use]
pub fn coarsest_level(mut width: u32, mut height: u32) -> u32 {
    let mut k = 0;
    while width > 1 || height > 1 {
        (width, height) = ((width / 2).max(1), (height / 2).max(1));
        k += 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Texel `(x, y)` holds `x + 4y`: small whole numbers, so bilinear weights that are
    /// multiples of 1/4 give exact results.
    fn ramp(w: u32, h: u32) -> Grid<f32> {
        Grid::from_fn(w, h, |x, y| (x + 4 * y) as f32)
    }

    #[test]
    fn wrap_is_the_euclidean_remainder() {
        for size in [1u32, 2, 3, 7, 512, 1000, 1 << 20, i32::MAX as u32, 1 << 31, u32::MAX] {
            let far = [i64::MIN, i64::MIN + 1, -(1 << 40), i64::from(i32::MIN) - 1, i64::from(i32::MIN)];
            let far2 = [i64::from(i32::MAX), i64::from(i32::MAX) + 1, i64::MAX - 1, i64::MAX];
            for i in (-1100i64..1100).chain(far).chain(far2) {
                let want = i.rem_euclid(i64::from(size)) as u32;
                assert_eq!(EdgeMode::Wrap.resolve(i, size), want, "{i} {size}");
            }
        }
    }

    #[test]
    fn resolve_pair_is_two_resolves() {
        for edges in EdgeMode::ALL {
            for size in [1u32, 2, 3, 7, 512] {
                let far = [i64::MIN, i64::MIN + 1, -(1 << 40), i64::MAX - 1, i64::MAX];
                for i in (-1100i64..1100).chain(far) {
                    let want = (edges.resolve(i, size), edges.resolve(i.saturating_add(1), size));
                    assert_eq!(edges.resolve_pair(i, size), want, "{edges:?} {i} {size}");
                }
            }
        }
    }

    #[test]
    fn wrap_and_clamp_any_size() {
        assert_eq!(EdgeMode::Wrap.resolve(-1, 5), 4);
        assert_eq!(EdgeMode::Wrap.resolve(5, 5), 0);
        assert_eq!(EdgeMode::Wrap.resolve(-11, 5), 4);
        assert_eq!(EdgeMode::Clamp.resolve(-3, 5), 0);
        assert_eq!(EdgeMode::Clamp.resolve(9, 5), 4);
    }

    #[test]
    fn construction_checks_the_size_and_from_fn_fills_row_by_row() {
        assert!(Grid::<f32>::new(0, 2, vec![]).is_none());
        assert!(Grid::new(2, 2, vec![0.0f32; 3]).is_none());
        let g = Grid::new(3, 2, vec![0.0f32, 1.0, 2.0, 4.0, 5.0, 6.0]).unwrap();
        assert_eq!(g, ramp(3, 2));
        assert_eq!((g.width(), g.height(), g.size_f32()), (3, 2, Vec2::new(3.0, 2.0)));
        assert_eq!(g.at(2, 1, EdgeMode::Wrap), 6.0);
        assert_eq!(g.at(3, -1, EdgeMode::Wrap), 4.0);
        assert_eq!(g.at(3, -1, EdgeMode::Clamp), 2.0);
        let one = Grid::from_fn(0, 0, |_, _| 7.0f32);
        assert_eq!((one.width(), one.height(), one.texels()), (1, 1, &[7.0][..]));
    }

    #[test]
    fn bilinear_reproduces_a_linear_ramp_exactly_between_texel_centres() {
        // Power-of-two sides, so that UV <-> texel conversions are exact too.
        for (w, h, edges) in [(8u32, 4u32, EdgeMode::Wrap), (4, 8, EdgeMode::Clamp), (16, 2, EdgeMode::Clamp)] {
            let g = ramp(w, h);
            let colours = g.clone().map(|v| Vec3::new(v, 2.0 * v, -v));
            // Every point between the first and the last texel centres, in steps of 1/4 texel:
            // the ramp's value there is x + 4y with x = u * w - 0.5, y = v * h - 0.5.
            for qy in 0..=(4 * (h - 1)) {
                for qx in 0..=(4 * (w - 1)) {
                    let (x, y) = (qx as f32 / 4.0, qy as f32 / 4.0);
                    let uv = Vec2::new((x + 0.5) / w as f32, (y + 0.5) / h as f32);
                    let want = x + 4.0 * y;
                    assert_eq!(g.sample_bilinear(uv, edges), want, "{edges:?} ({x}, {y})");
                    assert_eq!(colours.sample_bilinear(uv, edges), Vec3::new(want, 2.0 * want, -want), "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn bilinear_wraps_or_clamps_beyond_the_outer_texel_centres() {
        let g = ramp(4, 3);
        // A quarter texel left of the first column's centre, on row 1: wrapping blends a
        // quarter of the last column (7) into the first (4); clamping gives the first.
        let uv = Vec2::new(0.25 / 4.0, 1.5 / 3.0);
        assert_eq!(g.sample_bilinear(uv, EdgeMode::Wrap), 0.75 * 4.0 + 0.25 * 7.0);
        assert_eq!(g.sample_bilinear(uv, EdgeMode::Clamp), 4.0);
        // Halfway past the bottom row's centre, on column 2: rows 2 (10) and 0 (2) when
        // wrapping, row 2 when clamping.
        let uv = Vec2::new(2.5 / 4.0, 1.0);
        assert_eq!(g.sample_bilinear(uv, EdgeMode::Wrap), 6.0);
        assert_eq!(g.sample_bilinear(uv, EdgeMode::Clamp), 10.0);
        // One whole tile on, wrapping samples the same point.
        let uv = Vec2::new(0.3125, 0.625);
        assert_eq!(g.sample_bilinear(uv + Vec2::ONE, EdgeMode::Wrap), g.sample_bilinear(uv, EdgeMode::Wrap));
        // Non-finite coordinates fall back to the corner instead of panicking.
        assert_eq!(g.sample_bilinear(Vec2::NAN, EdgeMode::Clamp), 0.0);
        assert_eq!(g.sample_nearest(Vec2::new(f32::INFINITY, 0.0), EdgeMode::Wrap), 0.0);
        // Nearest: the containing texel, wrapped or clamped.
        assert_eq!(g.sample_nearest(Vec2::new(0.6, 0.9), EdgeMode::Clamp), 10.0);
        assert_eq!(g.sample_nearest(Vec2::new(-0.1, 0.5), EdgeMode::Wrap), 7.0);
        assert_eq!(g.sample_nearest(Vec2::new(-0.1, 0.5), EdgeMode::Clamp), 4.0);
    }

    #[test]
    fn downsampling_a_constant_gives_the_constant_for_any_size() {
        for (w, h) in [(8, 8), (7, 5), (3, 1), (1, 9), (13, 6), (1, 1), (5, 2)] {
            // 0.375 and its sums of up to 9 terms are exact in f32.
            let c = Grid::from_fn(w, h, |_, _| 0.375f32);
            let v = Grid::from_fn(w, h, |_, _| Vec3::new(0.375, 0.5, 0.25));
            let sides = ((w / 2).max(1), (h / 2).max(1));
            for d in [c.downsample_box(), c.downsample_area()] {
                assert_eq!((d.width(), d.height()), sides, "{w}x{h}");
                assert!(d.texels().iter().all(|&t| t == 0.375), "{w}x{h}: {:?}", d.texels());
            }
            for d in [v.downsample_box(), v.downsample_area()] {
                assert_eq!((d.width(), d.height()), sides, "{w}x{h}");
                assert!(d.texels().iter().all(|&t| t == Vec3::new(0.375, 0.5, 0.25)), "{w}x{h}");
            }
        }
        // Not exact in binary: the f64 sum of the exact-footprint filter still rounds back.
        let c = Grid::from_fn(7, 3, |_, _| 0.3f32);
        assert!(c.downsample_area().texels().iter().all(|&t| t == 0.3), "{:?}", c.downsample_area());
    }

    #[test]
    fn odd_sides_fold_in_the_last_texel_or_weigh_the_exact_footprint() {
        // One row 0, 1, 2, 3, 4: two coarse texels.
        let g = Grid::from_fn(5, 1, |x, _| x as f32);
        // 2x2 box: (0 + 1) / 2, then the last block takes three texels: (2 + 3 + 4) / 3.
        assert_eq!(g.downsample_box().texels(), &[0.5, 3.0]);
        // Exact footprint: each coarse texel covers 2.5 fine ones.
        // (0 + 1 + 2 / 2) / 2.5 and (2 / 2 + 3 + 4) / 2.5.
        let area = g.downsample_area();
        assert!((area.texels()[0] - 0.8).abs() < 1e-6 && (area.texels()[1] - 3.2).abs() < 1e-6, "{area:?}");
        // 3 wide: one texel, the mean of all three either way.
        let g = Grid::from_fn(3, 3, |x, y| (x + 3 * y) as f32);
        assert_eq!(g.downsample_box().texels(), &[4.0]);
        assert_eq!(g.downsample_area().texels(), &[4.0]);
        // An even block is a plain mean.
        let g = Grid::from_fn(4, 2, |x, y| (x + 4 * y) as f32);
        assert_eq!(g.downsample_box().texels(), &[2.5, 4.5]);
        assert_eq!(g.downsample_area().texels(), &[2.5, 4.5]);
    }

    #[test]
    fn mip_chains_halve_down_to_one_texel() {
        for (w, h) in [(1, 1), (2, 1), (512, 512), (640, 48), (3, 7), (1, 1000)] {
            let chain = Grid::from_fn(w, h, |x, y| (x ^ y) as f32).mip_chain(Grid::downsample_box);
            assert_eq!(chain.len() as u32, coarsest_level(w, h) + 1, "{w}x{h}");
            for pair in chain.windows(2) {
                assert_eq!(
                    (pair[1].width(), pair[1].height()),
                    ((pair[0].width() / 2).max(1), (pair[0].height() / 2).max(1))
                );
                assert_eq!(pair[1], pair[0].downsample_box());
            }
            let last = chain.last().unwrap();
            assert_eq!((last.width(), last.height()), (1, 1));
        }
        assert_eq!(coarsest_level(1, 1), 0);
        assert_eq!(coarsest_level(640, 48), 9);
        assert_eq!(coarsest_level(3, 7), 2);
    }
}
