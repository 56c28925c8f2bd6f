//! Baking: normal maps and parallax maps from height fields, normal-map encodings and blending.
//!
//! Sources: Lengyel, *Foundations of Game Engine Development* vol. 2, section 7.6 (central
//! differences, eqs. 7.41 to 7.43; two-channel storage, eq. 7.44; blending, eqs. 7.46 and 7.47)
//! and 7.7 (parallax maps, eq. 7.51); Tatarchuk 2006 section 4 (Sobel normals for dynamic height
//! fields).
//!
//! # Conventions
//! Heights are measured in texel widths: with scale `s`, height `h = 1` stands `s` texels above
//! `h = 0` (Lengyel's `s`). The normal is `nrm(-dz/dx, -dz/dy, 1)` in pomkit's tangent space,
//! where x runs along +u (image columns) and y runs *up* the image (along -v), so with the
//! default "+Y up" a slope rising toward the top of the image gives a normal with negative y.
//! Lengyel's listing differences `h(j + 1) - h(j - 1)` down the rows; up the image is the
//! opposite sign. `y_down` flips y for DirectX-style maps.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::heightfield::{EdgeMode, HeightField};

/// Why a bake could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BakeError {
    /// The scale is NaN, infinite, or larger in magnitude than [`MAX_SCALE`].
    #[error(
        "scale is {0}: it must be a finite number from -{MAX_SCALE:e} to {MAX_SCALE:e} (texel widths spanned by \
         the full height range; 0 gives flat normals, a negative scale inverts the relief)"
    )]
    BadScale(f32),
    /// The height field is smaller than 2 texels on a side, so no slope can be measured.
    #[error("height map is {width}x{height}: at least 2x2 texels are needed to measure slopes")]
    TooSmall {
        /// Width of the field.
        width: u32,
        /// Height of the field.
        height: u32,
    },
    /// The output buffer does not have one element per texel.
    #[error("output buffer holds {got} elements but the height map has {expected} texels")]
    OutputSize {
        /// Texels in the field.
        expected: usize,
        /// Elements supplied.
        got: usize,
    },
}

/// The largest magnitude of [`NormalBakeOptions::scale`].
///
/// A slope filter gives at most 0.5 depth units per texel along each axis (a full-range step
/// between two neighbours), so the scaled slopes `g` reach `0.5 s` and the normalization
/// computes `g.x^2 + g.y^2 + 1 <= s^2 / 2 + 1` in f32. That overflows to infinity (and every
/// normal to zero) beyond `s = sqrt(2 f32::MAX) ~ 2.6e19`; 1e18 keeps a factor of 25 in
/// reserve. Above a few thousand texel widths every slope of an 8- or 16-bit map already gives a
/// practically horizontal normal, so the bound costs nothing.
pub const MAX_SCALE: f32 = 1.0e18;

/// How slopes are measured from the height field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NormalFilter {
    /// Central differences over the two neighbours (Lengyel eq. 7.41): sharpest, exact for
    /// quadratics, noisier on noisy inputs.
    #[default]
    Central,
    /// The 3x3 Sobel operator (Tatarchuk 2006 section 4), normalized so that a plane gives the
    /// same slope as central differences: smoother, slightly blurs fine detail.
    Sobel,
}

/// Options for [`bake_normals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalBakeOptions {
    /// Lengyel's `s`: the full height range spans this many texel widths. Default 8. Larger
    /// values give steeper normals; 0 gives a flat map (every normal +Z); negative values invert
    /// the relief (the map reads as a depth map). Its magnitude is at most [`MAX_SCALE`].
    pub scale: f32,
    /// Slope filter. Default [`NormalFilter::Central`].
    pub filter: NormalFilter,
    /// Neighbours of border texels: wrap for tiling textures (default), clamp otherwise.
    pub edges: EdgeMode,
    /// Store +Y down (DirectX convention) instead of +Y up (OpenGL, glTF; the default).
    pub y_down: bool,
}

impl Default for NormalBakeOptions {
    fn default() -> Self {
        Self { scale: 8.0, filter: NormalFilter::Central, edges: EdgeMode::Wrap, y_down: false }
    }
}

impl NormalBakeOptions {
    /// Checks the options against a field.
    ///
    /// # Errors
    /// [`BakeError::BadScale`] for a non-finite scale or one beyond [`MAX_SCALE`] in magnitude,
    /// [`BakeError::TooSmall`] for a field narrower or shorter than 2 texels.
    pub fn validate(&self, field: &HeightField) -> Result<(), BakeError> {
        if !(self.scale.is_finite() && self.scale.abs() <= MAX_SCALE) {
            return Err(BakeError::BadScale(self.scale));
        }
        if field.width() < 2 || field.height() < 2 {
            return Err(BakeError::TooSmall { width: field.width(), height: field.height() });
        }
        Ok(())
    }
}

/// Height slopes `(dh/dx, dh/dy)` at texel `(x, y)` in height units per texel, with y running
/// up the image.
#[inline]
#[must_use]
pub fn height_slope(field: &HeightField, x: i64, y: i64, filter: NormalFilter, edges: EdgeMode) -> Vec2 {
    // Work on depths and negate: h = 1 - d.
    let d = |dx: i64, dy: i64| field.depth_at(x + dx, y + dy, edges);
    match filter {
        NormalFilter::Central => {
            let ddx = (d(1, 0) - d(-1, 0)) * 0.5;
            // Up the image is row - 1.
            let ddy = (d(0, -1) - d(0, 1)) * 0.5;
            -Vec2::new(ddx, ddy)
        }
        NormalFilter::Sobel => {
            // Weights 1-2-1 across, difference over two texels along: a plane of slope g gives
            // 4 * 2g, hence the 1/8.
            let ddx = (d(1, -1) + 2.0 * d(1, 0) + d(1, 1)) - (d(-1, -1) + 2.0 * d(-1, 0) + d(-1, 1));
            let ddy = (d(-1, -1) + 2.0 * d(0, -1) + d(1, -1)) - (d(-1, 1) + 2.0 * d(0, 1) + d(1, 1));
            -Vec2::new(ddx, ddy) * 0.125
        }
    }
}

/// The unit normal for slopes `(dh/dx, dh/dy)` (height units per texel, y up) at scale `s`
/// (eq. 7.43): `nrm(-s dh/dx, -s dh/dy, 1)`, with y negated when `y_down`.
#[inline]
#[must_use]
pub fn normal_from_slope(slope: Vec2, scale: f32, y_down: bool) -> Vec3 {
    let g = slope * scale;
    let inv = 1.0 / (g.length_squared() + 1.0).sqrt();
    let n = Vec3::new(-g.x * inv, -g.y * inv, inv);
    if y_down { Vec3::new(n.x, -n.y, n.z) } else { n }
}

/// The tangent-space normal of texel `(x, y)`.
#[must_use]
pub fn normal_at(field: &HeightField, x: i64, y: i64, opts: &NormalBakeOptions) -> Vec3 {
    normal_from_slope(height_slope(field, x, y, opts.filter, opts.edges), opts.scale, opts.y_down)
}

/// Bakes the normal map of `field`, one unit vector per texel, row-major.
///
/// # Errors
/// See [`NormalBakeOptions::validate`].
pub fn bake_normals(field: &HeightField, opts: &NormalBakeOptions) -> Result<Vec<Vec3>, BakeError> {
    let mut out = vec![Vec3::Z; field.depths().len()];
    bake_normals_into(field, opts, &mut out, |n| n, &|_| {})?;
    Ok(out)
}

/// Bakes normals straight into an encoded buffer (for instance `[f32; 3]`), rows in parallel,
/// calling `progress(rows)` as each band of rows finishes. For RGB8 output use the faster
/// [`bake_normals_rgb8`], which gives the same bytes as `encode_rgb8`.
///
/// # Errors
/// See [`NormalBakeOptions::validate`]; [`BakeError::OutputSize`] if `out` does not hold one
/// element per texel.
pub fn bake_normals_into<T: Send>(
    field: &HeightField,
    opts: &NormalBakeOptions,
    out: &mut [T],
    encode: impl Fn(Vec3) -> T + Sync,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<(), BakeError> {
    bake_rows(field, opts, out, progress, |rn, row| {
        normalize_row(rn);
        for (i, px) in row.iter_mut().enumerate() {
            *px = encode(Vec3::new(rn.x[i], rn.y[i], rn.z[i]));
        }
    })
}

/// Bakes an RGB8 normal map (`n * 0.5 + 0.5`, exactly [`encode_rgb8`] per texel) into `out`,
/// rows in parallel, calling `progress(rows)` as each band of rows finishes.
///
/// The whole bake is two vectorized passes per row over structure-of-arrays scratch space, so a
/// 4096x4096 map costs a few memory copies' worth of time (see docs/BENCHMARKS.md).
///
/// # Errors
/// As [`bake_normals_into`].
pub fn bake_normals_rgb8(
    field: &HeightField,
    opts: &NormalBakeOptions,
    out: &mut [[u8; 3]],
    progress: &(dyn Fn(u32) + Sync),
) -> Result<(), BakeError> {
    bake_rows(field, opts, out, progress, |rn, row| {
        let n = row.len();
        // Normalize and quantize in one vectorized pass over the slopes into packed words,
        // then scatter three bytes per texel.
        let words = &mut rn.q[..n];
        for (i, word) in words.iter_mut().enumerate() {
            let (gx, gy) = (rn.x[i], rn.y[i]);
            let inv = 1.0 / (gx * gx + gy * gy + 1.0).sqrt();
            let (r, g, b) = (quantize_unit(gx * inv), quantize_unit(gy * inv), quantize_unit(inv));
            *word = u32::from(r) | u32::from(g) << 8 | u32::from(b) << 16;
        }
        for (px, word) in row.iter_mut().zip(words.iter()) {
            let [r, g, b, _] = word.to_le_bytes();
            *px = [r, g, b];
        }
    })
}

/// One row's scaled slopes, then normals, in structure-of-arrays form, plus byte scratch.
struct RowNormals {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    q: Vec<u32>,
}

/// Runs `emit` on every row's normals, bands of rows in parallel.
fn bake_rows<T: Send>(
    field: &HeightField,
    opts: &NormalBakeOptions,
    out: &mut [T],
    progress: &(dyn Fn(u32) + Sync),
    emit: impl Fn(&mut RowNormals, &mut [T]) + Sync,
) -> Result<(), BakeError> {
    opts.validate(field)?;
    let expected = field.depths().len();
    if out.len() != expected {
        return Err(BakeError::OutputSize { expected, got: out.len() });
    }
    let (w, h) = (field.width() as usize, field.height());
    let depth = field.depths();
    // Bands of rows keep rayon's overhead low, reuse the scratch rows and give the progress bar
    // steady ticks.
    let band = 16usize;
    out.par_chunks_mut(w * band).enumerate().for_each(|(b, chunk)| {
        let mut rn = RowNormals { x: vec![0.0; w], y: vec![0.0; w], z: vec![0.0; w], q: vec![0; w] };
        for (r, row) in chunk.chunks_mut(w).enumerate() {
            let y = (b * band + r) as i64;
            let up = &depth[opts.edges.resolve(y - 1, h) as usize * w..][..w];
            let mid = &depth[y as usize * w..][..w];
            let down = &depth[opts.edges.resolve(y + 1, h) as usize * w..][..w];
            row_normals(up, mid, down, opts, &mut rn);
            emit(&mut rn, row);
        }
        progress((chunk.len() / w) as u32);
    });
    Ok(())
}

/// One row's scaled slopes `(s dd/dx, s dd/dy)` into `rn.x`, `rn.y`, from the depth rows above,
/// at and below it; [`normalize_row`] makes them normals.
///
/// Interior columns run through branch-free loops over equal-length slices, which the compiler
/// vectorizes; the two border columns resolve their neighbours through the edge mode.
fn row_normals(up: &[f32], mid: &[f32], down: &[f32], opts: &NormalBakeOptions, rn: &mut RowNormals) {
    let w = mid.len();
    // The normal is nrm(-s dh/dx, -s dh/dy, 1) = nrm(s dd/dx, s dd/dy, 1) since h = 1 - d.
    let xs = opts.scale;
    let ys = if opts.y_down { -opts.scale } else { opts.scale };
    // Depth slopes along x and up the image at column x with neighbours l and r.
    let slope = |l: usize, x: usize, r: usize| match opts.filter {
        NormalFilter::Central => ((mid[r] - mid[l]) * 0.5, (up[x] - down[x]) * 0.5),
        NormalFilter::Sobel => (
            ((up[r] + 2.0 * mid[r] + down[r]) - (up[l] + 2.0 * mid[l] + down[l])) * 0.125,
            ((up[l] + 2.0 * up[x] + up[r]) - (down[l] + 2.0 * down[x] + down[r])) * 0.125,
        ),
    };
    // Stage 1: scaled slopes into x and y.
    for x in [0, w - 1] {
        let l = opts.edges.resolve(x as i64 - 1, w as u32) as usize;
        let r = opts.edges.resolve(x as i64 + 1, w as u32) as usize;
        let (ddx, ddy) = slope(l, x, r);
        (rn.x[x], rn.y[x]) = (ddx * xs, ddy * ys);
    }
    if w >= 3 {
        let n = w - 2;
        let (gx, gy) = (&mut rn.x[1..=n], &mut rn.y[1..=n]);
        match opts.filter {
            NormalFilter::Central => {
                let (ml, mr) = (&mid[..n], &mid[2..]);
                let (uc, dc) = (&up[1..=n], &down[1..=n]);
                for i in 0..n {
                    gx[i] = (mr[i] - ml[i]) * (0.5 * xs);
                    gy[i] = (uc[i] - dc[i]) * (0.5 * ys);
                }
            }
            NormalFilter::Sobel => {
                let (ul, uc, ur) = (&up[..n], &up[1..=n], &up[2..]);
                let (ml, mr) = (&mid[..n], &mid[2..]);
                let (dl, dc, dr) = (&down[..n], &down[1..=n], &down[2..]);
                for i in 0..n {
                    gx[i] = ((ur[i] + 2.0 * mr[i] + dr[i]) - (ul[i] + 2.0 * ml[i] + dl[i])) * (0.125 * xs);
                    gy[i] = ((ul[i] + 2.0 * uc[i] + ur[i]) - (dl[i] + 2.0 * dc[i] + dr[i])) * (0.125 * ys);
                }
            }
        }
    }
}

/// Turns the scaled slopes `(gx, gy)` in `rn.x`, `rn.y` into unit normals `nrm(gx, gy, 1)`.
fn normalize_row(rn: &mut RowNormals) {
    for ((x, y), z) in rn.x.iter_mut().zip(rn.y.iter_mut()).zip(rn.z.iter_mut()) {
        let inv = 1.0 / (*x * *x + *y * *y + 1.0).sqrt();
        *x *= inv;
        *y *= inv;
        *z = inv;
    }
}

/// Encodes a unit normal as RGB8, `n * 0.5 + 0.5` rounded to the nearest step.
#[inline]
#[must_use]
pub fn encode_rgb8(n: Vec3) -> [u8; 3] {
    [quantize_unit(n.x), quantize_unit(n.y), quantize_unit(n.z)]
}

/// `(c * 0.5 + 0.5) * 255` rounded to the nearest integer (ties to even), with `c` clamped to
/// `[-1, 1]` (NaN gives 0).
///
/// Adding 1.5 * 2^23 leaves the rounded integer in the low mantissa bits: no float-to-int
/// conversion, so the loops that call this vectorize.
#[inline]
#[must_use]
pub fn quantize_unit(c: f32) -> u8 {
    const MAGIC: f32 = 12_582_912.0;
    let v = c.clamp(-1.0, 1.0) * 127.5 + 127.5;
    (v + MAGIC).to_bits() as u8
}

/// Decodes an RGB8 normal (`c * 2 - 1`) and renormalizes it, as a shader does after filtering.
/// A black texel (which encodes no valid normal) decodes to +Z.
#[inline]
#[must_use]
pub fn decode_rgb8(c: [u8; 3]) -> Vec3 {
    let v = Vec3::new(f32::from(c[0]), f32::from(c[1]), f32::from(c[2])) / 127.5 - 1.0;
    v.try_normalize().unwrap_or(Vec3::Z)
}

/// Encodes the x and y of a unit normal as two 8-bit channels (`c * 0.5 + 0.5`); z is rebuilt
/// on decode (Lengyel eq. 7.44), which assumes z >= 0.
#[inline]
#[must_use]
pub fn encode_rg8(n: Vec3) -> [u8; 2] {
    let [r, g, _] = encode_rgb8(n);
    [r, g]
}

/// Decodes a two-channel normal, rebuilding `z = sqrt(1 - x^2 - y^2)` (eq. 7.44). Values
/// whose `x^2 + y^2` exceed 1 by quantization are scaled back onto the unit circle.
#[inline]
#[must_use]
pub fn decode_rg8(c: [u8; 2]) -> Vec3 {
    let xy = Vec2::new(f32::from(c[0]), f32::from(c[1])) / 127.5 - 1.0;
    rebuild_z(xy)
}

/// The unit normal with the given x and y and a non-negative z (eq. 7.44).
#[inline]
#[must_use]
pub fn rebuild_z(xy: Vec2) -> Vec3 {
    let len2 = xy.length_squared();
    if len2 >= 1.0 {
        let xy = xy / len2.sqrt();
        return Vec3::new(xy.x, xy.y, 0.0);
    }
    Vec3::new(xy.x, xy.y, (1.0 - len2).sqrt())
}

/// Weighted blend of two tangent-space normals as if their height maps were summed with
/// weights `a` and `b` (Lengyel eq. 7.46): slopes `x/z` and `y/z` are blended, then
/// renormalized. Weights may be negative (a negative weight inverts that map's bumps).
///
/// Normals with `z <= 0` carry no slope; their `z` is taken as a tiny positive number so the
/// result stays finite. The result has `z > 0`.
#[must_use]
pub fn blend_weighted(m1: Vec3, m2: Vec3, a: f32, b: f32) -> Vec3 {
    let s1 = slope_of(m1);
    let s2 = slope_of(m2);
    let s = s1 * a + s2 * b;
    let v = Vec3::new(s.x, s.y, 1.0);
    if v.is_finite() { v.normalize() } else { Vec3::Z }
}

/// Additive blend (Lengyel eq. 7.47): eq. 7.46 with `a = b = 1`, multiplied through by
/// `z1 * z2` to save the divisions: `nrm(z2 x1 + z1 x2, z2 y1 + z1 y2, z1 z2)`.
#[must_use]
pub fn blend_additive(m1: Vec3, m2: Vec3) -> Vec3 {
    let v = Vec3::new(m2.z * m1.x + m1.z * m2.x, m2.z * m1.y + m1.z * m2.y, m1.z * m2.z);
    v.try_normalize().filter(|n| n.z > 0.0).unwrap_or_else(|| blend_weighted(m1, m2, 1.0, 1.0))
}

/// `(x/z, y/z)` with z kept away from zero.
fn slope_of(m: Vec3) -> Vec2 {
    let z = m.z.max(1e-6);
    Vec2::new(m.x, m.y) / z
}

/// Bakes Lengyel's parallax map (eq. 7.51): `n_z * (2h - 1)` per texel, in `[-1, 1]`, where `n_z`
/// is the z of the normal baked with the same options. Heights above 1/2 shift texture
/// coordinates toward the viewer, below 1/2 away. A shader multiplies by `s / 2` over the
/// texture size (eq. 7.52) to get UV offsets.
///
/// # Errors
/// See [`NormalBakeOptions::validate`].
pub fn bake_parallax(field: &HeightField, opts: &NormalBakeOptions) -> Result<Vec<f32>, BakeError> {
    let normals = bake_normals(field, opts)?;
    Ok(normals.iter().zip(field.depths()).map(|(n, &d)| n.z * (2.0 * (1.0 - d) - 1.0)).collect())
}

/// Bakes a packed RGBA8 map: the RGB8 normal ([`encode_rgb8`]) in RGB and the height (white =
/// high) in alpha: the combined "NB" map of McGuire and McGuire 2005 (docs/REFERENCES.md).
///
/// # Errors
/// See [`NormalBakeOptions::validate`].
pub fn bake_packed_rgba8(
    field: &HeightField,
    opts: &NormalBakeOptions,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Vec<[u8; 4]>, BakeError> {
    let mut out = vec![[0u8; 4]; field.depths().len()];
    bake_normals_into(
        field,
        opts,
        &mut out,
        |n| {
            let [r, g, b] = encode_rgb8(n);
            [r, g, b, 0]
        },
        progress,
    )?;
    for (px, &d) in out.iter_mut().zip(field.depths()) {
        px[3] = ((1.0 - d) * 255.0).round() as u8;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f32::consts::TAU;

    const EPS: f32 = 1e-5;

    fn plane(w: u32, h: u32, gx: f32, gy_down: f32) -> HeightField {
        // Height rises by gx per texel along +x and by gy_down per texel down the rows;
        // offset so every value stays in [0, 1].
        HeightField::from_height_fn(w, h, |x, y| 0.2 + gx * x as f32 + gy_down * y as f32)
    }

    #[test]
    fn plane_gives_the_analytic_normal_with_both_filters() {
        let (gx, gy_down) = (0.01, 0.02);
        let f = plane(32, 32, gx, gy_down);
        for filter in [NormalFilter::Central, NormalFilter::Sobel] {
            let opts = NormalBakeOptions { scale: 4.0, filter, edges: EdgeMode::Clamp, y_down: false };
            // Up the image the height falls: dh/dy_up = -gy_down.
            let expect = Vec3::new(-4.0 * gx, 4.0 * gy_down, 1.0).normalize();
            for (x, y) in [(5, 5), (16, 20), (30, 1)] {
                let n = normal_at(&f, x, y, &opts);
                assert!((n - expect).length() < EPS, "{filter:?} at ({x},{y}): {n} vs {expect}");
            }
            let baked = bake_normals(&f, &opts).unwrap();
            assert!((baked[20 * 32 + 16] - expect).length() < EPS);
            let down = NormalBakeOptions { y_down: true, ..opts };
            let n = bake_normals(&f, &down).unwrap()[20 * 32 + 16];
            assert!((n - Vec3::new(expect.x, -expect.y, expect.z)).length() < EPS);
        }
    }

    /// A sine wave along x: h = 0.5 + A sin(2 pi k x / w). Central differences measure
    /// dh/dx * sin(omega) / omega with omega = 2 pi k / w; Sobel measures the same along x (its
    /// cross weights see a constant in y). Check both against the analytic slope with that factor.
    #[test]
    fn sine_waves_match_the_analytic_slope() {
        let (w, k, amp, s) = (64u32, 3.0f32, 0.4f32, 10.0f32);
        let omega = TAU * k / w as f32;
        let f = HeightField::from_height_fn(w, 8, |x, _| 0.5 + amp * (omega * x as f32).sin());
        for filter in [NormalFilter::Central, NormalFilter::Sobel] {
            let opts = NormalBakeOptions { scale: s, filter, edges: EdgeMode::Wrap, y_down: false };
            let baked = bake_normals(&f, &opts).unwrap();
            for x in 0..w {
                let exact_slope = amp * omega * (omega * x as f32).cos();
                let discrete = exact_slope * omega.sin() / omega;
                let expect = Vec3::new(-s * discrete, 0.0, 1.0).normalize();
                let n = baked[(3 * w + x) as usize];
                assert!((n - expect).length() < 1e-4, "{filter:?} x={x}: {n} vs {expect}");
                // And within the discretisation error of the continuous normal.
                let analytic = Vec3::new(-s * exact_slope, 0.0, 1.0).normalize();
                assert!(n.angle_between(analytic) < 0.03, "{filter:?} x={x}");
            }
        }
        // A wave down the rows: normal y has the sign of the slope up the image.
        let f = HeightField::from_height_fn(8, w, |_, y| 0.5 + amp * (omega * y as f32).sin());
        let baked = bake_normals(&f, &NormalBakeOptions { scale: s, ..Default::default() }).unwrap();
        for y in 0..w {
            let dh_dy_up = -amp * omega * (omega * y as f32).cos() * omega.sin() / omega;
            let expect = Vec3::new(0.0, -s * dh_dy_up, 1.0).normalize();
            assert!((baked[(y * 8 + 2) as usize] - expect).length() < 1e-4);
        }
    }

    #[test]
    fn non_power_of_two_wraps_across_the_edge() {
        // 5 columns: heights 0, .1, .2, .3, .4. Wrap: texel 0's left neighbour is texel 4.
        let f = HeightField::from_height_fn(5, 3, |x, _| x as f32 * 0.1);
        let opts = NormalBakeOptions { scale: 1.0, ..Default::default() };
        let n = normal_at(&f, 0, 1, &opts);
        let expect = normal_from_slope(Vec2::new((0.1 - 0.4) * 0.5, 0.0), 1.0, false);
        assert!((n - expect).length() < EPS);
        let clamp = NormalBakeOptions { edges: EdgeMode::Clamp, ..opts };
        let n = normal_at(&f, 0, 1, &clamp);
        assert!((n - normal_from_slope(Vec2::new(0.05, 0.0), 1.0, false)).length() < EPS);
        // The fast row path and the per-texel path agree everywhere, border texels included.
        for opts in [opts, clamp, NormalBakeOptions { filter: NormalFilter::Sobel, ..clamp }] {
            let baked = bake_normals(&f, &opts).unwrap();
            for y in 0..3 {
                for x in 0..5 {
                    assert!((baked[y * 5 + x] - normal_at(&f, x as i64, y as i64, &opts)).length() < EPS);
                }
            }
        }
    }

    #[test]
    fn fast_rgb8_path_gives_the_bytes_of_encode_rgb8() {
        let f = HeightField::from_height_fn(37, 9, |x, y| ((x * 13 + y * 7) % 10) as f32 / 9.0);
        for filter in [NormalFilter::Central, NormalFilter::Sobel] {
            for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
                let opts = NormalBakeOptions { scale: 6.0, filter, edges, y_down: edges == EdgeMode::Clamp };
                let mut fast = vec![[0u8; 3]; 37 * 9];
                bake_normals_rgb8(&f, &opts, &mut fast, &|_| {}).unwrap();
                let slow: Vec<[u8; 3]> = (0..9)
                    .flat_map(|y| (0..37).map(move |x| (x, y)))
                    .map(|(x, y)| encode_rgb8(normal_at(&f, x, y, &opts)))
                    .collect();
                assert_eq!(fast, slow, "{filter:?} {edges:?}");
            }
        }
    }

    #[test]
    fn scales_up_to_the_limit_give_unit_normals_and_larger_ones_are_refused() {
        // Full-range steps between neighbours along x and y: the steepest slopes any filter sees.
        let f = HeightField::from_height_fn(6, 6, |x, y| if (x / 2 + y / 2) % 2 == 0 { 1.0 } else { 0.0 });
        for filter in [NormalFilter::Central, NormalFilter::Sobel] {
            for scale in [MAX_SCALE, -MAX_SCALE, 1.0e12] {
                let opts = NormalBakeOptions { scale, filter, edges: EdgeMode::Clamp, y_down: false };
                let ns = bake_normals(&f, &opts).unwrap();
                for n in &ns {
                    assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-5, "{filter:?} {scale}: {n}");
                }
                let mut rgb = vec![[0u8; 3]; 36];
                bake_normals_rgb8(&f, &opts, &mut rgb, &|_| {}).unwrap();
                // A steep texel's normal is horizontal, never the zero vector (code 128, 128, 128).
                assert!(rgb.iter().all(|c| *c != [128, 128, 128]), "{filter:?} {scale}: {rgb:?}");
            }
            for scale in [1.0e25, -1.0e25, MAX_SCALE * 1.01] {
                let opts = NormalBakeOptions { scale, filter, ..Default::default() };
                assert_eq!(bake_normals(&f, &opts), Err(BakeError::BadScale(scale)));
                assert!(BakeError::BadScale(scale).to_string().contains("1e18"));
            }
        }
        // 0 is flat; a negative scale mirrors the slopes (the relief read as depth).
        let bump =
            HeightField::from_height_fn(8, 8, |x, y| ((x as f32 - 3.5).powi(2) + (y as f32 - 3.5).powi(2)) / 25.0);
        let flat = bake_normals(&bump, &NormalBakeOptions { scale: 0.0, ..Default::default() }).unwrap();
        assert!(flat.iter().all(|n| *n == Vec3::Z));
        let up = bake_normals(&bump, &NormalBakeOptions { scale: 4.0, ..Default::default() }).unwrap();
        let down = bake_normals(&bump, &NormalBakeOptions { scale: -4.0, ..Default::default() }).unwrap();
        for (a, b) in up.iter().zip(&down) {
            assert!((*a - Vec3::new(-b.x, -b.y, b.z)).length() < 1e-6, "{a} vs {b}");
        }
    }

    #[test]
    fn bad_options_and_tiny_fields_are_errors() {
        let f = HeightField::constant(4, 4, 0.5);
        let nan = NormalBakeOptions { scale: f32::NAN, ..Default::default() };
        assert!(matches!(bake_normals(&f, &nan), Err(BakeError::BadScale(_))));
        let inf = NormalBakeOptions { scale: f32::INFINITY, ..Default::default() };
        assert!(matches!(bake_normals(&f, &inf), Err(BakeError::BadScale(_))));
        let one = HeightField::constant(1, 1, 0.5);
        assert_eq!(bake_normals(&one, &Default::default()), Err(BakeError::TooSmall { width: 1, height: 1 }));
        let strip = HeightField::constant(7, 1, 0.5);
        assert!(matches!(bake_parallax(&strip, &Default::default()), Err(BakeError::TooSmall { .. })));
        let mut small = vec![0u8; 3];
        assert!(matches!(
            bake_normals_into(&f, &Default::default(), &mut small, |_| 0, &|_| {}),
            Err(BakeError::OutputSize { expected: 16, got: 3 })
        ));
    }

    #[test]
    fn encodings_round_trip_within_quantisation() {
        // Quantisation to 1/255 of the [0,1] range is 2/255 in [-1,1]: half a step of error
        // per channel before renormalisation.
        let step = 1.0 / 127.5;
        for (i, dir) in (0..200)
            .map(|i| (i, i as f32 * 0.731))
            .map(|(i, t)| (i, Vec3::new(t.cos() * (i as f32 * 0.004), t.sin() * (i as f32 * 0.004), 1.0).normalize()))
        {
            let rgb = decode_rgb8(encode_rgb8(dir));
            assert!((rgb - dir).length() < 1.5 * step, "rgb8 {i}: {dir} -> {rgb}");
            let rg = decode_rg8(encode_rg8(dir));
            // Rebuilding z amplifies xy error near the horizon; these normals stay within ~39deg.
            assert!((rg - dir).length() < 3.0 * step, "rg8 {i}: {dir} -> {rg}");
            assert!((rg.length() - 1.0).abs() < 1e-5);
        }
        assert_eq!(encode_rgb8(Vec3::Z), [128, 128, 255]);
        assert!(decode_rgb8([0, 0, 0]).is_finite());
        assert!(rebuild_z(Vec2::new(1.0, 1.0)).is_finite());
    }

    #[test]
    fn blending_with_flat_is_identity_and_weights_scale_slopes() {
        let m = Vec3::new(0.3, -0.2, 0.8).normalize();
        assert!((blend_weighted(m, Vec3::Z, 1.0, 1.0) - m).length() < EPS);
        assert!((blend_weighted(Vec3::Z, m, 1.0, 1.0) - m).length() < EPS);
        assert!((blend_additive(m, Vec3::Z) - m).length() < EPS);
        assert!((blend_additive(Vec3::Z, m) - m).length() < EPS);
        // Negative weight: subtracting a map from itself gives flat; -1 inverts the bumps.
        assert!((blend_weighted(m, m, 1.0, -1.0) - Vec3::Z).length() < EPS);
        let inv = blend_weighted(m, Vec3::Z, -1.0, 0.0);
        assert!((inv - Vec3::new(-m.x, -m.y, m.z)).length() < EPS);
        // Cross-fade endpoints.
        let m2 = Vec3::new(-0.1, 0.4, 0.9).normalize();
        assert!((blend_weighted(m, m2, 0.0, 1.0) - m2).length() < EPS);
        assert!(blend_weighted(Vec3::X, Vec3::Y, 1.0, 1.0).is_finite());
        assert!(blend_additive(Vec3::X, -Vec3::Z).is_finite());
    }

    /// Independent truth: central differences are linear in h, so the additive blend of the
    /// normal maps of h1 and h2 equals the normal map of h1 + h2. The sum can exceed 1, so bake
    /// (h1 + h2) / 2 at twice the scale.
    #[test]
    fn additive_blend_equals_normal_of_summed_heights() {
        let (w, h) = (24u32, 20u32);
        let f1 = HeightField::from_height_fn(w, h, |x, y| 0.5 + 0.4 * (0.7 * x as f32).sin() * (0.3 * y as f32).cos());
        let f2 = HeightField::from_height_fn(w, h, |x, y| ((x * 7 + y * 13) % 11) as f32 / 10.0);
        let sum = HeightField::from_height_fn(w, h, |x, y| {
            0.5 * (f1.height_at(x.into(), y.into(), EdgeMode::Wrap) + f2.height_at(x.into(), y.into(), EdgeMode::Wrap))
        });
        let opts = NormalBakeOptions { scale: 3.0, ..Default::default() };
        let n1 = bake_normals(&f1, &opts).unwrap();
        let n2 = bake_normals(&f2, &opts).unwrap();
        let ns = bake_normals(&sum, &NormalBakeOptions { scale: 6.0, ..opts }).unwrap();
        for i in 0..n1.len() {
            assert!((blend_additive(n1[i], n2[i]) - ns[i]).length() < 1e-4, "texel {i}");
            assert!((blend_weighted(n1[i], n2[i], 1.0, 1.0) - ns[i]).length() < 1e-4, "texel {i}");
            // Through RGB8 maps: equal to quantisation (a few steps after the blend amplifies).
            let q = blend_additive(decode_rgb8(encode_rgb8(n1[i])), decode_rgb8(encode_rgb8(n2[i])));
            assert!((q - ns[i]).length() < 0.05, "texel {i}: {q} vs {}", ns[i]);
        }
    }

    #[test]
    fn parallax_map_is_nz_times_signed_height() {
        let f = HeightField::from_height_fn(16, 16, |x, y| (x as f32 / 15.0) * 0.5 + (y as f32 / 15.0) * 0.25);
        let opts = NormalBakeOptions { edges: EdgeMode::Clamp, ..Default::default() };
        let p = bake_parallax(&f, &opts).unwrap();
        let n = bake_normals(&f, &opts).unwrap();
        for i in 0..p.len() {
            let hgt = 1.0 - f.depths()[i];
            assert!((p[i] - n[i].z * (2.0 * hgt - 1.0)).abs() < EPS);
            assert!((-1.0..=1.0).contains(&p[i]));
        }
        // Flat at h = 1/2: no offset; flat at 1: n_z = 1, value 1.
        assert!(bake_parallax(&HeightField::constant(4, 4, 0.5), &opts).unwrap().iter().all(|v| v.abs() < EPS));
        assert!(bake_parallax(&HeightField::constant(4, 4, 0.0), &opts).unwrap().iter().all(|v| (v - 1.0).abs() < EPS));
    }

    #[test]
    fn packed_map_carries_normal_and_height() {
        let f = HeightField::from_height_fn(8, 8, |x, y| ((x + y) % 5) as f32 / 4.0);
        let opts = NormalBakeOptions::default();
        let packed = bake_packed_rgba8(&f, &opts, &|_| {}).unwrap();
        let normals = bake_normals(&f, &opts).unwrap();
        for i in 0..packed.len() {
            let [r, g, b, a] = packed[i];
            assert_eq!([r, g, b], encode_rgb8(normals[i]));
            assert_eq!(a, ((1.0 - f.depths()[i]) * 255.0).round() as u8);
        }
    }

    /// the bump test (ARCHITECTURE.md, Conventions), shaded on a plane by a minimal Lambert helper: a raised
    /// bump lit from +x is brighter on its +x side, lit from "up the image" brighter on its top.
    ///
    /// The plane maps u to world +x and v to world -y (image top at +y), so T = +x, B = +y,
    /// N = +z and a tangent-space normal is also the world normal.
    #[test]
    fn bump_lit_from_plus_x_is_brighter_on_its_plus_x_side() {
        let size = 64u32;
        let c = size as f32 / 2.0;
        let f = HeightField::from_height_fn(size, size, |x, y| {
            let r2 = ((x as f32 + 0.5 - c).powi(2) + (y as f32 + 0.5 - c).powi(2)) / 64.0;
            (-r2).exp()
        });
        for filter in [NormalFilter::Central, NormalFilter::Sobel] {
            let opts = NormalBakeOptions { scale: 8.0, filter, ..Default::default() };
            // Through the RGB8 file encoding, as a renderer would read it.
            let map: Vec<Vec3> =
                bake_normals(&f, &opts).unwrap().into_iter().map(|n| decode_rgb8(encode_rgb8(n))).collect();
            let (t, b, nrm) = (Vec3::X, Vec3::Y, Vec3::Z);
            let shade = |x: u32, y: u32, light: Vec3| {
                let m = map[(y * size + x) as usize];
                let world = t * m.x + b * m.y + nrm * m.z;
                world.dot(light.normalize()).max(0.0)
            };
            let mid = size / 2;
            let (east, west) = (mid + 5, mid - 6);
            let from_x = Vec3::new(1.0, 0.0, 0.6);
            assert!(shade(east, mid, from_x) > shade(west, mid, from_x) + 0.3, "{filter:?}");
            // Image top (smaller rows) faces world +y.
            let from_top = Vec3::new(0.0, 1.0, 0.6);
            let (top, bottom) = (mid - 6, mid + 5);
            assert!(shade(mid, top, from_top) > shade(mid, bottom, from_top) + 0.3, "{filter:?}");
            // With the DirectX convention, a reader that flips y back sees the same picture.
            let dx = bake_normals(&f, &NormalBakeOptions { y_down: true, ..opts }).unwrap();
            let m = dx[(top * size + mid) as usize];
            assert!(m.y < -0.1 && map[(top * size + mid) as usize].y > 0.1);
        }
    }

    proptest! {
        #[test]
        fn normals_are_unit_and_face_out(
            w in 2u32..12, h in 2u32..12, seed in any::<u32>(), scale in -100.0f32..100.0, sobel in any::<bool>(), wrap in any::<bool>()
        ) {
            let f = HeightField::from_height_fn(w, h, |x, y| {
                let k = (x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503) ^ seed).wrapping_mul(2_246_822_519);
                (k >> 8) as f32 / (1u32 << 24) as f32
            });
            let opts = NormalBakeOptions {
                scale,
                filter: if sobel { NormalFilter::Sobel } else { NormalFilter::Central },
                edges: if wrap { EdgeMode::Wrap } else { EdgeMode::Clamp },
                y_down: false,
            };
            for n in bake_normals(&f, &opts).unwrap() {
                prop_assert!(n.is_finite());
                prop_assert!((n.length() - 1.0).abs() < 1e-4);
                prop_assert!(n.z > 0.0);
            }
            for p in bake_parallax(&f, &opts).unwrap() {
                prop_assert!((-1.0..=1.0).contains(&p));
            }
        }
    }
}
