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
    /// [`Grid::downsample_area`] do).
    #[must_use]
    pub fn mip_chain(self, mut next: impl FnMut(&Self) -> Self) -> Vec<Self> {
        let mut chain = vec![self];
        while let Some(last) = chain.last().filter(|g| g.width > 1 || g.height > 1) {
            let next = next(last);
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
