//! Height fields: storage, edge modes, nearest and bilinear sampling, mip chains.
//!
//! Conventions (ARCHITECTURE.md):
//! - pomkit stores *depth* `d` in `[0, 1]`: 0 is the polygon's surface, 1 the deepest point.
//!   Height `h = 1 - d` (white = high in an ordinary height map).
//! - UV `(0, 0)` is the top-left corner of the image; texel `(i, j)` (column `i`, row `j`) has
//!   its centre at `((i + 0.5) / w, (j + 0.5) / h)`. Bilinear filtering interpolates between
//!   texel centres, as a GPU does.
//! - Any size is allowed, not only powers of two (Lengyel's `& (size - 1)` wrap is erratum 5 in
//!   docs/REFERENCES.md, Errata: pomkit wraps with a Euclidean remainder).

use glam::Vec2;

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
}

impl EdgeMode {
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

/// Why a height field could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum HeightFieldError {
    /// The width or the height is zero.
    #[error("height field is {width}x{height}: both sides must be at least 1 texel")]
    Empty {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// The sample count does not equal `width * height`.
    #[error("height field is {width}x{height} but {len} samples were given")]
    SizeMismatch {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// Samples supplied.
        len: usize,
    },
    /// A sample is NaN or infinite.
    #[error("sample at texel ({x}, {y}) is {value}: heights must be finite")]
    NotFinite {
        /// Column of the bad sample.
        x: u32,
        /// Row of the bad sample.
        y: u32,
        /// The offending value.
        value: f32,
    },
    /// A sample lies outside `[0, 1]`.
    #[error("sample at texel ({x}, {y}) is {value}: heights must lie in [0, 1]")]
    OutOfRange {
        /// Column of the bad sample.
        x: u32,
        /// Row of the bad sample.
        y: u32,
        /// The offending value.
        value: f32,
    },
}

/// A rectangular grid of depth samples in `[0, 1]` (0 = surface, 1 = deepest).
#[derive(Clone, Debug, PartialEq)]
pub struct HeightField {
    width: u32,
    height: u32,
    depth: Vec<f32>,
}

impl HeightField {
    /// Builds a field from *depths* (0 = surface, 1 = deepest), row-major, top row first.
    ///
    /// # Errors
    /// [`HeightFieldError`] if a side is 0, the length is not `width * height`, or a sample is
    /// not finite or lies outside `[0, 1]`.
    pub fn from_depths(width: u32, height: u32, depth: Vec<f32>) -> Result<Self, HeightFieldError> {
        validate(width, height, &depth)?;
        Ok(Self { width, height, depth })
    }

    /// Builds a field from *heights* (1 = surface, 0 = deepest; white = high), row-major.
    ///
    /// # Errors
    /// As [`HeightField::from_depths`].
    pub fn from_heights(width: u32, height: u32, mut h: Vec<f32>) -> Result<Self, HeightFieldError> {
        validate(width, height, &h)?;
        for v in &mut h {
            *v = 1.0 - *v;
        }
        Ok(Self { width, height, depth: h })
    }

    /// Builds a field by evaluating `height(x, y)` (white = high, in `[0, 1]`; values outside
    /// are clamped, NaN becomes 0) at every texel.
    #[must_use]
    pub fn from_height_fn(width: u32, height: u32, f: impl Fn(u32, u32) -> f32) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let mut depth = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height {
            for x in 0..width {
                let h = f(x, y);
                let h = if h.is_nan() { 0.0 } else { h.clamp(0.0, 1.0) };
                depth.push(1.0 - h);
            }
        }
        Self { width, height, depth }
    }

    /// A field of constant depth `d` (clamped to `[0, 1]`).
    #[must_use]
    pub fn constant(width: u32, height: u32, d: f32) -> Self {
        Self::from_height_fn(width, height, |_, _| 1.0 - d)
    }

    /// Width in texels (columns).
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels (rows).
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// `(width, height)` as floats, handy for UV <-> texel conversions.
    #[must_use]
    pub fn size_f32(&self) -> Vec2 {
        Vec2::new(self.width as f32, self.height as f32)
    }

    /// The depth samples, row-major, top row first.
    #[must_use]
    pub fn depths(&self) -> &[f32] {
        &self.depth
    }

    /// Heights `1 - d`, row-major (allocates).
    #[must_use]
    pub fn heights(&self) -> Vec<f32> {
        self.depth.iter().map(|d| 1.0 - d).collect()
    }

    /// Depth of texel `(x, y)`, with out-of-range coordinates wrapped or clamped.
    #[inline]
    #[must_use]
    pub fn depth_at(&self, x: i64, y: i64, edges: EdgeMode) -> f32 {
        let xi = edges.resolve(x, self.width) as usize;
        let yi = edges.resolve(y, self.height) as usize;
        self.depth[yi * self.width as usize + xi]
    }

    /// Height (`1 - depth`) of texel `(x, y)`, with out-of-range coordinates wrapped or clamped.
    #[inline]
    #[must_use]
    pub fn height_at(&self, x: i64, y: i64, edges: EdgeMode) -> f32 {
        1.0 - self.depth_at(x, y, edges)
    }

    /// Depth of the texel containing `uv` (nearest filtering). One fetch.
    ///
    /// Non-finite UVs sample texel (0, 0) rather than panic.
    #[must_use]
    pub fn sample_nearest(&self, uv: Vec2, edges: EdgeMode) -> f32 {
        let t = uv * self.size_f32();
        let t = if t.is_finite() { t } else { Vec2::ZERO };
        self.depth_at(t.x.floor() as i64, t.y.floor() as i64, edges)
    }

    /// Bilinearly filtered depth at `uv`, interpolating between texel centres. One fetch.
    ///
    /// Non-finite UVs sample texel (0, 0) rather than panic.
    #[must_use]
    pub fn sample_bilinear(&self, uv: Vec2, edges: EdgeMode) -> f32 {
        let t = uv * self.size_f32() - 0.5;
        let t = if t.is_finite() { t } else { Vec2::ZERO };
        let f = Vec2::new(floor(t.x), floor(t.y));
        let (fx, fy) = (t.x - f.x, t.y - f.y);
        // `as` saturates far outside the i64 range (|uv| * size beyond 9.2e18); the neighbour then
        // saturates too rather than overflow (such coordinates carry no sub-texel position in f32
        // anyway).
        let (x0, y0) = (f.x as i64, f.y as i64);
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        if x0 >= 0 && y0 >= 0 && x0 < w - 1 && y0 < h - 1 {
            // Inside: the four texels without edge handling.
            let at = y0 as usize * self.width as usize + x0 as usize;
            let (d00, d10) = (self.depth[at], self.depth[at + 1]);
            let (d01, d11) = (self.depth[at + self.width as usize], self.depth[at + self.width as usize + 1]);
            let top = d00 + (d10 - d00) * fx;
            let bottom = d01 + (d11 - d01) * fx;
            return top + (bottom - top) * fy;
        }
        // The texels depth_at would read at x0, x0 + 1 (saturating) and y0, y0 + 1, each
        // coordinate resolved once.
        let (xa, xb) = edges.resolve_pair(x0, self.width);
        let (ya, yb) = edges.resolve_pair(y0, self.height);
        let row = |y: u32| y as usize * self.width as usize;
        let d00 = self.depth[row(ya) + xa as usize];
        let d10 = self.depth[row(ya) + xb as usize];
        let d01 = self.depth[row(yb) + xa as usize];
        let d11 = self.depth[row(yb) + xb as usize];
        let top = d00 + (d10 - d00) * fx;
        let bottom = d01 + (d11 - d01) * fx;
        top + (bottom - top) * fy
    }

    /// The next coarser mip level by a box filter over the exact footprint.
    ///
    /// Each side halves (rounding down, never below 1), as GPU mip chains do. For odd sides a
    /// coarse texel covers 2 + 1/(n') fine texels; the filter weights each fine texel by the
    /// length of its overlap with that footprint, so the mean depth is preserved exactly.
    #[must_use]
    pub fn downsample(&self) -> Self {
        let nw = (self.width / 2).max(1);
        let nh = (self.height / 2).max(1);
        let wx = box_weights(self.width, nw);
        let wy = box_weights(self.height, nh);
        let mut depth = vec![0.0f32; nw as usize * nh as usize];
        for (oy, row_weights) in wy.iter().enumerate() {
            for (ox, col_weights) in wx.iter().enumerate() {
                let mut acc = 0.0f64;
                for &(sy, wyv) in row_weights {
                    for &(sx, wxv) in col_weights {
                        acc += f64::from(self.depth[sy as usize * self.width as usize + sx as usize]) * wyv * wxv;
                    }
                }
                depth[oy * nw as usize + ox] = (acc as f32).clamp(0.0, 1.0);
            }
        }
        Self { width: nw, height: nh, depth }
    }
}

/// Checks the size and that every sample is finite and in `[0, 1]`.
fn validate(width: u32, height: u32, samples: &[f32]) -> Result<(), HeightFieldError> {
    if width == 0 || height == 0 {
        return Err(HeightFieldError::Empty { width, height });
    }
    if samples.len() as u64 != u64::from(width) * u64::from(height) {
        return Err(HeightFieldError::SizeMismatch { width, height, len: samples.len() });
    }
    for (k, &value) in samples.iter().enumerate() {
        let (x, y) = ((k % width as usize) as u32, (k / width as usize) as u32);
        if !value.is_finite() {
            return Err(HeightFieldError::NotFinite { x, y, value });
        }
        if !(0.0..=1.0).contains(&value) {
            return Err(HeightFieldError::OutOfRange { x, y, value });
        }
    }
    Ok(())
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

/// Mip level (lambda) for the given UV derivatives along screen x and y, as a GPU computes it
/// for isotropic filtering: `log2(max(|dUV/dx|, |dUV/dy|))` measured in texels of level 0.
///
/// The result is clamped to `[0, max_level]`; non-finite derivatives give level 0.
#[must_use]
pub fn mip_level_from_gradients(duv_dx: Vec2, duv_dy: Vec2, size: Vec2, max_level: f32) -> f32 {
    let rho2 = (duv_dx * size).length_squared().max((duv_dy * size).length_squared());
    if !rho2.is_finite() || rho2 <= 1.0 {
        return 0.0;
    }
    (0.5 * rho2.log2()).clamp(0.0, max_level.max(0.0))
}

/// A height field with its box-filtered mip chain (level 0 is the original).
#[derive(Clone, Debug, PartialEq)]
pub struct MipChain {
    levels: Vec<HeightField>,
}

impl MipChain {
    /// Builds every level down to 1x1.
    #[must_use]
    pub fn new(base: HeightField) -> Self {
        let mut levels = vec![base];
        loop {
            let last = levels.last().expect("chain starts with the base level");
            if last.width == 1 && last.height == 1 {
                break;
            }
            let next = last.downsample();
            levels.push(next);
        }
        Self { levels }
    }

    /// Number of levels (at least 1).
    #[must_use]
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// Always false: a chain has at least its base level.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Level `k` (clamped to the coarsest).
    #[must_use]
    pub fn level(&self, k: usize) -> &HeightField {
        &self.levels[k.min(self.levels.len() - 1)]
    }

    /// The original field.
    #[must_use]
    pub fn base(&self) -> &HeightField {
        &self.levels[0]
    }

    /// The coarsest level index, as a float for [`mip_level_from_gradients`].
    #[must_use]
    pub fn max_level(&self) -> f32 {
        (self.levels.len() - 1) as f32
    }

    /// Trilinear sample: bilinear in the two levels around `lod`, blended by its fraction.
    /// One fetch, as `textureSampleLevel` counts on a GPU. `lod` is clamped to the chain.
    #[must_use]
    pub fn sample(&self, uv: Vec2, lod: f32, edges: EdgeMode) -> f32 {
        let lod = if lod.is_finite() { lod.clamp(0.0, self.max_level()) } else { 0.0 };
        let k = lod.floor() as usize;
        let f = lod - k as f32;
        let a = self.levels[k].sample_bilinear(uv, edges);
        if f <= 0.0 || k + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[k + 1].sample_bilinear(uv, edges);
        a + (b - a) * f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> HeightField {
        HeightField::from_height_fn(w, h, |x, y| (x + 2 * y) as f32 / (w + 2 * h) as f32)
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
    fn rejects_bad_construction() {
        assert!(matches!(HeightField::from_depths(0, 3, vec![]), Err(HeightFieldError::Empty { .. })));
        assert!(matches!(
            HeightField::from_depths(2, 2, vec![0.0; 3]),
            Err(HeightFieldError::SizeMismatch { len: 3, .. })
        ));
        assert!(matches!(
            HeightField::from_heights(2, 1, vec![0.5, f32::NAN]),
            Err(HeightFieldError::NotFinite { x: 1, y: 0, .. })
        ));
        assert!(matches!(
            HeightField::from_heights(2, 1, vec![1.5, 0.0]),
            Err(HeightFieldError::OutOfRange { x: 0, y: 0, .. })
        ));
        assert!(matches!(HeightField::from_heights(0, 0, vec![]), Err(HeightFieldError::Empty { .. })));
    }

    #[test]
    fn heights_and_depths_are_complements() {
        let hf = HeightField::from_heights(2, 1, vec![1.0, 0.25]).unwrap();
        assert_eq!(hf.depths(), &[0.0, 0.75]);
        assert_eq!(hf.height_at(1, 0, EdgeMode::Wrap), 0.25);
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
    fn bilinear_hits_texel_centres_and_interpolates_linearly() {
        let hf = ramp(7, 5);
        for y in 0..5 {
            for x in 0..7 {
                let uv = Vec2::new((x as f32 + 0.5) / 7.0, (y as f32 + 0.5) / 5.0);
                let s = hf.sample_bilinear(uv, EdgeMode::Clamp);
                assert!((s - hf.depth_at(x, y, EdgeMode::Clamp)).abs() < 1e-6);
            }
        }
        // Halfway between texel centres (2,1) and (3,1): the mean of the two.
        let uv = Vec2::new(3.0 / 7.0, 1.5 / 5.0);
        let expect = 0.5 * (hf.depth_at(2, 1, EdgeMode::Clamp) + hf.depth_at(3, 1, EdgeMode::Clamp));
        assert!((hf.sample_bilinear(uv, EdgeMode::Clamp) - expect).abs() < 1e-6);
        // Wrap: halfway between the last and the first column.
        let uv = Vec2::new(1.0, 0.5 / 5.0);
        let expect = 0.5 * (hf.depth_at(6, 0, EdgeMode::Wrap) + hf.depth_at(0, 0, EdgeMode::Wrap));
        assert!((hf.sample_bilinear(uv, EdgeMode::Wrap) - expect).abs() < 1e-6);
        // Clamp: beyond the last centre the value is flat.
        let uv = Vec2::new(0.999, 0.5 / 5.0);
        assert!((hf.sample_bilinear(uv, EdgeMode::Clamp) - hf.depth_at(6, 0, EdgeMode::Clamp)).abs() < 1e-6);
    }

    #[test]
    fn nearest_picks_the_containing_texel() {
        let hf = ramp(4, 4);
        assert_eq!(hf.sample_nearest(Vec2::new(0.26, 0.74), EdgeMode::Wrap), hf.depth_at(1, 2, EdgeMode::Wrap));
        assert_eq!(hf.sample_nearest(Vec2::new(-0.01, 0.0), EdgeMode::Wrap), hf.depth_at(3, 0, EdgeMode::Wrap));
        assert!(hf.sample_nearest(Vec2::NAN, EdgeMode::Wrap).is_finite());
        assert!(hf.sample_bilinear(Vec2::new(f32::INFINITY, 0.0), EdgeMode::Wrap).is_finite());
    }

    #[test]
    fn box_filter_preserves_the_mean_for_any_size() {
        for (w, h) in [(8, 8), (7, 5), (3, 1), (1, 9), (13, 6)] {
            let hf = HeightField::from_height_fn(w, h, |x, y| ((x * 37 + y * 11) % 17) as f32 / 16.0);
            let mean =
                |f: &HeightField| f.depths().iter().map(|&d| f64::from(d)).sum::<f64>() / f.depths().len() as f64;
            let chain = MipChain::new(hf.clone());
            assert_eq!(chain.level(chain.len() - 1).width(), 1);
            assert_eq!(chain.level(chain.len() - 1).height(), 1);
            for k in 1..chain.len() {
                assert!((mean(chain.level(k)) - mean(&hf)).abs() < 1e-5, "{w}x{h} level {k}");
            }
        }
        // An even 2x2 block averages exactly.
        let hf = HeightField::from_depths(2, 2, vec![0.0, 0.5, 1.0, 0.5]).unwrap();
        assert_eq!(hf.downsample().depths(), &[0.5]);
    }

    #[test]
    fn mip_level_matches_the_gpu_formula() {
        let size = Vec2::new(256.0, 128.0);
        // One texel per pixel: level 0. Four texels per pixel along u: level 2.
        assert_eq!(mip_level_from_gradients(Vec2::new(1.0 / 256.0, 0.0), Vec2::new(0.0, 1.0 / 128.0), size, 8.0), 0.0);
        let l = mip_level_from_gradients(Vec2::new(4.0 / 256.0, 0.0), Vec2::new(0.0, 1.0 / 128.0), size, 8.0);
        assert!((l - 2.0).abs() < 1e-6);
        assert_eq!(mip_level_from_gradients(Vec2::splat(1e9), Vec2::ZERO, size, 7.0), 7.0);
        assert_eq!(mip_level_from_gradients(Vec2::NAN, Vec2::ZERO, size, 7.0), 0.0);
    }

    #[test]
    fn trilinear_blends_levels() {
        let hf = HeightField::from_depths(2, 2, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
        let chain = MipChain::new(hf);
        let uv = Vec2::new(0.25, 0.25);
        assert_eq!(chain.sample(uv, 0.0, EdgeMode::Clamp), 0.0);
        assert_eq!(chain.sample(uv, 1.0, EdgeMode::Clamp), 0.5);
        assert!((chain.sample(uv, 0.5, EdgeMode::Clamp) - 0.25).abs() < 1e-6);
        assert_eq!(chain.sample(uv, 99.0, EdgeMode::Clamp), 0.5);
    }
}
