//! Height fields: depths over a [`Grid`] (storage, edge modes, nearest and bilinear sampling),
//! their box-filtered mip chains.
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

use crate::grid::Grid;
pub use crate::grid::{EdgeMode, floor};

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
#[derive(Clone, PartialEq)]
pub struct HeightField {
    grid: Grid<f32>,
}

impl std::fmt::Debug for HeightField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.grid;
        f.debug_struct("HeightField")
            .field("width", &g.width())
            .field("height", &g.height())
            .field("depth", &g.texels())
            .finish()
    }
}

impl HeightField {
    /// Builds a field from *depths* (0 = surface, 1 = deepest), row-major, top row first.
    ///
    /// # Errors
    /// [`HeightFieldError`] if a side is 0, the length is not `width * height`, or a sample is
    /// not finite or lies outside `[0, 1]`.
    pub fn from_depths(width: u32, height: u32, depth: Vec<f32>) -> Result<Self, HeightFieldError> {
        validate(width, height, &depth)?;
        Ok(Self { grid: Grid::from_checked(width, height, depth) })
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
        Ok(Self { grid: Grid::from_checked(width, height, h) })
    }

    /// Builds a field by evaluating `height(x, y)` (white = high, in `[0, 1]`; values outside
    /// are clamped, NaN becomes 0) at every texel.
    #[must_use]
    pub fn from_height_fn(width: u32, height: u32, f: impl Fn(u32, u32) -> f32) -> Self {
        let grid = Grid::from_fn(width, height, |x, y| {
            let h = f(x, y);
            let h = if h.is_nan() { 0.0 } else { h.clamp(0.0, 1.0) };
            1.0 - h
        });
        Self { grid }
    }

    /// A field of constant depth `d` (clamped to `[0, 1]`).
    #[must_use]
    pub fn constant(width: u32, height: u32, d: f32) -> Self {
        Self::from_height_fn(width, height, |_, _| 1.0 - d)
    }

    /// Width in texels (columns).
    #[must_use]
    pub fn width(&self) -> u32 {
        self.grid.width()
    }

    /// Height in texels (rows).
    #[must_use]
    pub fn height(&self) -> u32 {
        self.grid.height()
    }

    /// `(width, height)` as floats, handy for UV <-> texel conversions.
    #[must_use]
    pub fn size_f32(&self) -> Vec2 {
        self.grid.size_f32()
    }

    /// The depth samples, row-major, top row first.
    #[must_use]
    pub fn depths(&self) -> &[f32] {
        self.grid.texels()
    }

    /// Heights `1 - d`, row-major (allocates).
    #[must_use]
    pub fn heights(&self) -> Vec<f32> {
        self.depths().iter().map(|d| 1.0 - d).collect()
    }

    /// Depth of texel `(x, y)`, with out-of-range coordinates wrapped or clamped.
    #[inline]
    #[must_use]
    pub fn depth_at(&self, x: i64, y: i64, edges: EdgeMode) -> f32 {
        self.grid.at(x, y, edges)
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
        self.grid.sample_nearest(uv, edges)
    }

    /// Bilinearly filtered depth at `uv`, interpolating between texel centres. One fetch.
    ///
    /// Non-finite UVs sample texel (0, 0) rather than panic.
    #[must_use]
    pub fn sample_bilinear(&self, uv: Vec2, edges: EdgeMode) -> f32 {
        self.grid.sample_bilinear(uv, edges)
    }

    /// The next coarser mip level by a box filter over the exact footprint.
    ///
    /// Each side halves (rounding down, never below 1), as GPU mip chains do. For odd sides a
    /// coarse texel covers 2 + 1/(n') fine texels; the filter weights each fine texel by the
    /// length of its overlap with that footprint, so the mean depth is preserved exactly.
    #[must_use]
    pub fn downsample(&self) -> Self {
        Self { grid: downsample_depths(&self.grid) }
    }
}

/// [`Grid::downsample_area`], each depth then clamped to `[0, 1]` (the `f64` sum may round
/// past the ends).
fn downsample_depths(grid: &Grid<f32>) -> Grid<f32> {
    grid.downsample_area().map(|d| d.clamp(0.0, 1.0))
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
        let levels = base.grid.mip_chain(downsample_depths).into_iter().map(|grid| HeightField { grid }).collect();
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

    /// The sampling and the mip chain as they were written before [`Grid`] held them, to
    /// compare bit for bit.
    mod before {
        use super::*;

        pub fn bilinear(w: u32, h: u32, depth: &[f32], uv: Vec2, edges: EdgeMode) -> f32 {
            let t = uv * Vec2::new(w as f32, h as f32) - 0.5;
            let t = if t.is_finite() { t } else { Vec2::ZERO };
            let f = Vec2::new(floor(t.x), floor(t.y));
            let (fx, fy) = (t.x - f.x, t.y - f.y);
            let (x0, y0) = (f.x as i64, f.y as i64);
            if x0 >= 0 && y0 >= 0 && x0 < i64::from(w) - 1 && y0 < i64::from(h) - 1 {
                let at = y0 as usize * w as usize + x0 as usize;
                let (d00, d10) = (depth[at], depth[at + 1]);
                let (d01, d11) = (depth[at + w as usize], depth[at + w as usize + 1]);
                let top = d00 + (d10 - d00) * fx;
                let bottom = d01 + (d11 - d01) * fx;
                return top + (bottom - top) * fy;
            }
            let (xa, xb) = edges.resolve_pair(x0, w);
            let (ya, yb) = edges.resolve_pair(y0, h);
            let row = |y: u32| y as usize * w as usize;
            let (d00, d10) = (depth[row(ya) + xa as usize], depth[row(ya) + xb as usize]);
            let (d01, d11) = (depth[row(yb) + xa as usize], depth[row(yb) + xb as usize]);
            let top = d00 + (d10 - d00) * fx;
            let bottom = d01 + (d11 - d01) * fx;
            top + (bottom - top) * fy
        }

        fn weights(n: u32, m: u32) -> Vec<Vec<(u32, f64)>> {
            let ratio = f64::from(n) / f64::from(m);
            (0..m)
                .map(|o| {
                    let (a, b) = (f64::from(o) * ratio, f64::from(o + 1) * ratio);
                    let last = (b.ceil() as u32).min(n);
                    (a.floor() as u32..last)
                        .filter_map(|s| {
                            let overlap = (b.min(f64::from(s + 1)) - a.max(f64::from(s))).max(0.0);
                            (overlap > 0.0).then_some((s, overlap / ratio))
                        })
                        .collect()
                })
                .collect()
        }

        pub fn downsample(w: u32, h: u32, depth: &[f32]) -> (u32, u32, Vec<f32>) {
            let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
            let (wx, wy) = (weights(w, nw), weights(h, nh));
            let mut out = vec![0.0f32; nw as usize * nh as usize];
            for (oy, row_weights) in wy.iter().enumerate() {
                for (ox, col_weights) in wx.iter().enumerate() {
                    let mut acc = 0.0f64;
                    for &(sy, wyv) in row_weights {
                        for &(sx, wxv) in col_weights {
                            acc += f64::from(depth[sy as usize * w as usize + sx as usize]) * wyv * wxv;
                        }
                    }
                    out[oy * nw as usize + ox] = (acc as f32).clamp(0.0, 1.0);
                }
            }
            (nw, nh, out)
        }
    }

    /// A field of irregular depths over the whole of `[0, 1]`, ends included.
    fn irregular(w: u32, h: u32) -> HeightField {
        HeightField::from_height_fn(w, h, |x, y| {
            let k = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503)).rotate_left(7);
            if k % 11 == 0 { f32::from(k % 2 == 0) } else { (k % 10_007) as f32 / 10_006.0 }
        })
    }

    #[test]
    fn sampling_and_mips_match_the_former_per_type_code_bit_for_bit() {
        let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        for (w, h) in [(1, 1), (1, 7), (6, 1), (2, 2), (7, 5), (16, 16), (33, 12), (77, 53)] {
            let hf = irregular(w, h);
            for edges in EdgeMode::ALL {
                for k in 0..2000u32 {
                    // UVs inside, on, and well beyond the tile, some far away.
                    let u = (k.wrapping_mul(7919) % 4001) as f32 / 1000.0 - 1.5;
                    let v = (k.wrapping_mul(104_729) % 3001) as f32 / 1000.0 - 1.0;
                    let uv = if k % 97 == 0 { Vec2::new(u * 1e7, v) } else { Vec2::new(u, v) };
                    let want = before::bilinear(w, h, hf.depths(), uv, edges);
                    assert_eq!(hf.sample_bilinear(uv, edges).to_bits(), want.to_bits(), "{w}x{h} {edges:?} {uv}");
                }
            }
            let chain = MipChain::new(hf.clone());
            let (mut lw, mut lh, mut level) = (w, h, hf.depths().to_vec());
            for k in 0..chain.len() {
                let got = chain.level(k);
                assert_eq!(
                    (got.width(), got.height(), bits(got.depths())),
                    (lw, lh, bits(&level)),
                    "{w}x{h} level {k}"
                );
                (lw, lh, level) = before::downsample(lw, lh, &level);
            }
            assert_eq!((chain.level(chain.len() - 1).width(), chain.level(chain.len() - 1).height()), (1, 1));
            let (dw, dh, d) = before::downsample(w, h, hf.depths());
            let down = hf.downsample();
            assert_eq!((down.width(), down.height(), bits(down.depths())), (dw, dh, bits(&d)), "{w}x{h}");
        }
    }
}
