//! The discrete Poisson equation `L z = b` on a grid, solved exactly in the frequency domain.
//!
//! `L` is the graph Laplacian of the texel grid whose edges join 4-neighbours (the 5-point
//! Laplacian with the sign that makes it positive semi-definite): `(L z)_i = sum over the
//! neighbours j of i of (z_i - z_j)`. Its null space is the constants, so the solution returned
//! has mean 0 and the mean of `b` (0 for any `b = D^T g`) is ignored.
//!
//! - Wrap (a tiling map): every texel has four neighbours, across the borders too. Fourier
//!   modes diagonalize `L` with eigenvalues `4 - 2 cos(2 pi k / w) - 2 cos(2 pi l / h)`: a real
//!   FFT along the rows (`realfft`) and a complex one down the columns (`rustfft`). This is
//!   Frankot and Chellappa's projection in its discrete form (docs/REFERENCES.md).
//! - Clamp: no edge leaves the map (Neumann boundaries, zero slope across the border). The
//!   DCT-II basis diagonalizes `L` with eigenvalues `4 - 2 cos(pi k / w) - 2 cos(pi l / h)`
//!   (`rustdct`; Simchony, Chellappa and Shao 1990).
//!
//! Both solves are two passes of 1-D transforms over rows and, after a transpose, over
//! columns, each pass in parallel (rayon).

use std::f64::consts::PI;
use std::sync::Arc;

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustdct::{DctPlanner, TransformType2And3};
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use crate::heightfield::EdgeMode;
use crate::memory::{MemoryError, try_vec};

/// A planned Poisson solve for one grid size and edge mode, with its scratch space.
pub(crate) struct Poisson {
    width: usize,
    height: usize,
    /// `2 - 2 cos(theta_k)` along x, per frequency.
    eig_x: Vec<f64>,
    /// The same down the columns.
    eig_y: Vec<f64>,
    plan: Plan,
}

enum Plan {
    /// Wrap: real FFTs of the rows, complex FFTs of the half-spectrum's columns.
    Fft {
        rows_forward: Arc<dyn RealToComplex<f32>>,
        rows_inverse: Arc<dyn ComplexToReal<f32>>,
        cols_forward: Arc<dyn Fft<f32>>,
        cols_inverse: Arc<dyn Fft<f32>>,
        /// The rows' half-spectra, `height` rows of `width / 2 + 1`.
        spectrum: Vec<Complex<f32>>,
        /// Its transpose: `width / 2 + 1` columns of `height`, contiguous.
        columns: Vec<Complex<f32>>,
    },
    /// Clamp: DCT-II forward, DCT-III back, both ways.
    Dct {
        rows: Arc<dyn TransformType2And3<f32>>,
        cols: Arc<dyn TransformType2And3<f32>>,
        /// The transpose, `width` columns of `height`.
        columns: Vec<f32>,
    },
}

impl Poisson {
    /// The bytes of scratch space a solve of `width` x `height` texels holds.
    pub(crate) fn scratch_bytes(width: u32, height: u32, edges: EdgeMode) -> u64 {
        let (w, h) = (u64::from(width), u64::from(height));
        match edges {
            // Two half-spectra of complex f32.
            EdgeMode::Wrap => 2 * (w / 2 + 1) * h * 8,
            EdgeMode::Clamp => w * h * 4,
        }
    }

    /// Plans the solve and allocates its scratch space (fallibly: `what` names the job).
    pub(crate) fn new(width: u32, height: u32, edges: EdgeMode) -> Result<Self, MemoryError> {
        let (w, h) = (width as usize, height as usize);
        let alloc = |e: std::collections::TryReserveError| MemoryError::Allocation {
            what: format!("the Poisson solve of {width}x{height} texels"),
            bytes: Self::scratch_bytes(width, height, edges),
            reason: e.to_string(),
            advice: "integrate a smaller normal map".to_owned(),
        };
        let eig = |n: usize, period: f64| -> Vec<f64> {
            (0..n).map(|k| 2.0 - 2.0 * (2.0 * PI * k as f64 / period).cos()).collect()
        };
        match edges {
            EdgeMode::Wrap => {
                let mut real = RealFftPlanner::<f32>::new();
                let mut complex = FftPlanner::<f32>::new();
                let cw = w / 2 + 1;
                Ok(Self {
                    width: w,
                    height: h,
                    eig_x: eig(cw, w as f64),
                    eig_y: eig(h, h as f64),
                    plan: Plan::Fft {
                        rows_forward: real.plan_fft_forward(w),
                        rows_inverse: real.plan_fft_inverse(w),
                        cols_forward: complex.plan_fft_forward(h),
                        cols_inverse: complex.plan_fft_inverse(h),
                        spectrum: try_vec(Complex::default(), cw * h).map_err(alloc)?,
                        columns: try_vec(Complex::default(), cw * h).map_err(alloc)?,
                    },
                })
            }
            EdgeMode::Clamp => {
                let mut planner = DctPlanner::<f32>::new();
                Ok(Self {
                    width: w,
                    height: h,
                    // cos(pi k / n) = cos(2 pi k / 2n).
                    eig_x: eig(w, 2.0 * w as f64),
                    eig_y: eig(h, 2.0 * h as f64),
                    plan: Plan::Dct {
                        rows: planner.plan_dct2(w),
                        cols: planner.plan_dct2(h),
                        columns: try_vec(0.0, w * h).map_err(alloc)?,
                    },
                })
            }
        }
    }

    /// Solves `L z = b` in place: `data` holds `b` (row-major) on entry and `z`, mean 0, on
    /// return.
    pub(crate) fn solve(&mut self, data: &mut [f32]) {
        let (w, h) = (self.width, self.height);
        debug_assert_eq!(data.len(), w * h);
        let (eig_x, eig_y) = (&self.eig_x, &self.eig_y);
        match &mut self.plan {
            Plan::Fft { rows_forward, rows_inverse, cols_forward, cols_inverse, spectrum, columns } => {
                let cw = w / 2 + 1;
                data.par_chunks_mut(w).zip(spectrum.par_chunks_mut(cw)).for_each_init(
                    || rows_forward.make_scratch_vec(),
                    |scratch, (row, out)| {
                        rows_forward.process_with_scratch(row, out, scratch).expect("planned lengths");
                    },
                );
                transpose(spectrum, columns, h, cw);
                // The unnormalized transforms scale by w h on the way back.
                let norm = 1.0 / (w as f64 * h as f64);
                let len = cols_forward.get_inplace_scratch_len().max(cols_inverse.get_inplace_scratch_len());
                columns.par_chunks_mut(h).enumerate().for_each_init(
                    || vec![Complex::default(); len],
                    |scratch, (k, col)| {
                        cols_forward.process_with_scratch(col, scratch);
                        for (l, c) in col.iter_mut().enumerate() {
                            let lambda = eig_x[k] + eig_y[l];
                            let f = if lambda > 1e-9 { (norm / lambda) as f32 } else { 0.0 };
                            *c *= f;
                        }
                        cols_inverse.process_with_scratch(col, scratch);
                    },
                );
                transpose(columns, spectrum, cw, h);
                data.par_chunks_mut(w).zip(spectrum.par_chunks_mut(cw)).for_each_init(
                    || rows_inverse.make_scratch_vec(),
                    |scratch, (row, spec)| {
                        // A real signal's spectrum: DC (and Nyquist for even widths) are real.
                        spec[0].im = 0.0;
                        if w % 2 == 0 {
                            spec[cw - 1].im = 0.0;
                        }
                        rows_inverse.process_with_scratch(spec, row, scratch).expect("planned lengths");
                    },
                );
            }
            Plan::Dct { rows, cols, columns } => {
                let dct_rows = |data: &mut [f32], inverse: bool| {
                    data.par_chunks_mut(w).for_each_init(
                        || vec![0.0f32; rows.get_scratch_len()],
                        |scratch, row| {
                            if inverse {
                                rows.process_dct3_with_scratch(row, scratch);
                            } else {
                                rows.process_dct2_with_scratch(row, scratch);
                            }
                        },
                    );
                };
                dct_rows(data, false);
                transpose(data, columns, h, w);
                // DCT-III after DCT-II scales by n / 2 along each axis.
                let norm = 4.0 / (w as f64 * h as f64);
                columns.par_chunks_mut(h).enumerate().for_each_init(
                    || vec![0.0f32; cols.get_scratch_len()],
                    |scratch, (k, col)| {
                        cols.process_dct2_with_scratch(col, scratch);
                        for (l, c) in col.iter_mut().enumerate() {
                            let lambda = eig_x[k] + eig_y[l];
                            let f = if lambda > 1e-9 { (norm / lambda) as f32 } else { 0.0 };
                            *c *= f;
                        }
                        cols.process_dct3_with_scratch(col, scratch);
                    },
                );
                transpose(columns, data, w, h);
                dct_rows(data, true);
            }
        }
    }
}

/// Writes the transpose of `src` (`rows` rows of `cols`) into `dst` (`cols` rows of `rows`),
/// bands of destination rows in parallel.
fn transpose<T: Copy + Send + Sync>(src: &[T], dst: &mut [T], rows: usize, cols: usize) {
    const BAND: usize = 16;
    dst.par_chunks_mut(rows * BAND).enumerate().for_each(|(b, band)| {
        let c0 = b * BAND;
        let n = band.len() / rows;
        for r in 0..rows {
            let line = &src[r * cols + c0..][..n];
            for (i, &v) in line.iter().enumerate() {
                band[i * rows + r] = v;
            }
        }
    });
}

/// `L z` for the grid Laplacian of [`Poisson`] (for tests and the weighted solve's checks).
#[cfg(test)]
pub(crate) fn laplacian(z: &[f32], w: usize, h: usize, edges: EdgeMode) -> Vec<f64> {
    let mut out = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut s = 0.0f64;
            for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                let j = match edges {
                    EdgeMode::Wrap => Some(nx.rem_euclid(w as i64) as usize + ny.rem_euclid(h as i64) as usize * w),
                    EdgeMode::Clamp => ((0..w as i64).contains(&nx) && (0..h as i64).contains(&ny))
                        .then(|| nx as usize + ny as usize * w),
                };
                if let Some(j) = j {
                    s += f64::from(z[i]) - f64::from(z[j]);
                }
            }
            out[i] = s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The solve inverts the Laplacian (checked by applying it, texel by texel, to the result)
    /// on odd, even, prime and non-square sizes, with both edge modes.
    #[test]
    fn solve_inverts_the_grid_laplacian() {
        for (w, h) in [(8usize, 8usize), (7, 5), (2, 3), (13, 32), (64, 17)] {
            for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
                // A right-hand side with zero mean.
                let mut b: Vec<f32> =
                    (0..w * h).map(|i| ((i * 7919 % 97) as f32 / 97.0 - 0.5) + (i as f32 * 0.37).sin()).collect();
                let mean = b.iter().map(|&v| f64::from(v)).sum::<f64>() / (w * h) as f64;
                b.iter_mut().for_each(|v| *v -= mean as f32);
                let mut z = b.clone();
                let mut solver = Poisson::new(w as u32, h as u32, edges).unwrap();
                solver.solve(&mut z);
                let lz = laplacian(&z, w, h, edges);
                let zmean = z.iter().map(|&v| f64::from(v)).sum::<f64>() / (w * h) as f64;
                assert!(zmean.abs() < 1e-4, "{w}x{h} {edges:?}: mean {zmean}");
                for i in 0..w * h {
                    assert!(
                        (lz[i] - f64::from(b[i])).abs() < 2e-4,
                        "{w}x{h} {edges:?} texel {i}: {} vs {}",
                        lz[i],
                        b[i]
                    );
                }
                // The same plan solves again with the same answer (scratch reused).
                let mut again = b.clone();
                solver.solve(&mut again);
                assert!(again.iter().zip(&z).all(|(a, b)| (a - b).abs() < 1e-5));
            }
        }
    }

    #[test]
    fn transpose_of_transpose_is_the_identity() {
        let (r, c) = (37usize, 21usize);
        let a: Vec<usize> = (0..r * c).collect();
        let mut t = vec![0; r * c];
        transpose(&a, &mut t, r, c);
        assert_eq!(t[5 * r + 3], a[3 * c + 5]);
        let mut back = vec![0; r * c];
        transpose(&t, &mut back, c, r);
        assert_eq!(a, back);
    }
}
