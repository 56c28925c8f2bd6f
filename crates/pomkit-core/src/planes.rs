//! Plane bounds per pyramid cell: for every cell of the maximum-height pyramid above level 0,
//! a plane and two widths that bound the bilinear surface over the cell from both sides.
//!
//! A cell's least depth ([`MaxHeightPyramid::min_depth`]) is a flat bound, loose wherever the
//! surface slopes across the cell. A plane `P` through the cell with the widths `shallower` and
//! `deeper` such that `P - shallower <= S <= P + deeper` over the cell follows the slope: a ray
//! is above the surface while it is above `P - shallower` and under it once it reaches
//! `P + deeper`, two divisions, which bracket the hit inside the cell far tighter than the least
//! depth on smooth relief (docs/ACCURACY.md, "Affine bounds per cell", measures an exact walk
//! that uses them).
//!
//! The plane of a cell is the least-squares plane of its texel centres' depths, through the
//! centre of its texel range, found from its children's sums (exact at every level, one pass per
//! level). Its slopes are stored as f16, its depth as f32, and the widths are those of the
//! stored plane, so the bounds hold for what is stored:
//! - up to [`EXACT_WIDTHS_UP_TO`], measured over the cell: `S - P` is bilinear on each patch,
//!   so its extremes over a cell lie at the corners of the patches cut by the cell's walls, all
//!   on the half-texel grid from wall to wall (texel centres, walls, and where they cross), where
//!   the build evaluates `S` in f64;
//! - above it, from the four children: a child's plane and widths bound the surface over the
//!   child, and the parent's plane differs from the child's by an affine function, extreme at the
//!   child's corners. Measured on the built-in maps, this costs an exact walk at most 3% more
//!   fetches than measuring every level, and a level costs one pass over its cells.
//!
//! Each width gets [`PAD`] and is rounded up to an f16. With clamped edges a border cell reaches
//! to infinity outward, where the clamped surface is constant along that axis, so its plane is
//! level along that axis and the widths measured inside the tile hold outside it too.

use half::f16;
use rayon::prelude::*;

use crate::heightfield::{EdgeMode, HeightField};
use crate::pyramid::MaxHeightPyramid;

/// The highest level whose widths are measured over the cell's texels (cells of up to 32x32
/// texels, 65x65 grid points); coarser levels bound theirs from their children's.
pub const EXACT_WIDTHS_UP_TO: usize = 5;

/// Added to every width before it is rounded up to an f16: room for the rounding of a walk that
/// evaluates the plane in f32.
pub const PAD: f64 = 1.0 / (1u32 << 20) as f64;

/// Why plane bounds were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaneBoundsError {
    /// The bounds were built for a field of another size.
    #[error("plane bounds built for another size than this {width}x{height} height map: build them from this one")]
    Size {
        /// Height map width.
        width: u32,
        /// Height map height.
        height: u32,
    },
}

/// One cell's bounds, as stored: the plane's depth at the centre of the cell's texel range
/// (f32), its slopes in depth per texel along x and y, and the widths (f16 values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellPlane {
    /// The plane's depth at the centre of the cell's texel range.
    pub depth: f32,
    /// The plane's slopes: depth per texel along x (u) and along y (v).
    pub slope: [f32; 2],
    /// How much shallower than the plane the surface can be anywhere over the cell.
    pub shallower: f32,
    /// How much deeper than the plane the surface can be anywhere over the cell.
    pub deeper: f32,
}

impl CellPlane {
    /// The plane's depth at texel-space point `(x, y)` of a cell whose texel range has its
    /// centre at `centre`.
    #[must_use]
    pub fn at(&self, centre: [f64; 2], x: f64, y: f64) -> f64 {
        f64::from(self.depth) + f64::from(self.slope[0]) * (x - centre[0]) + f64::from(self.slope[1]) * (y - centre[1])
    }
}

/// A cell as stored: the depth, and the slopes and widths as f16 bits.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Stored {
    depth: f32,
    halves: [u16; 4],
}

impl Stored {
    fn plane(self) -> CellPlane {
        let h = |k: usize| f16::from_bits(self.halves[k]).to_f32();
        CellPlane { depth: self.depth, slope: [h(0), h(1)], shallower: h(2), deeper: h(3) }
    }
}

/// The sums a cell's least-squares plane is formed from, over its texel centres: count, sum of
/// depths, sums of depth times the offset from the cell's centre along x and y, sums of the
/// squared offsets.
#[derive(Clone, Copy, Default)]
struct Sums {
    n: f64,
    v: f64,
    xv: f64,
    yv: f64,
    xx: f64,
    yy: f64,
}

/// Plane bounds for the cells of every pyramid level above level 0.
#[derive(Clone, Debug, PartialEq)]
pub struct CellPlanes {
    /// Levels 1 and up: width in cells and the cells, row by row.
    levels: Vec<(u32, Vec<Stored>)>,
}

/// The f16 nearest `g`.
fn half_nearest(g: f64) -> f16 {
    f16::from_f64(g)
}

/// The least f16 at or above the non-negative `w`.
fn half_up(w: f64) -> f16 {
    let h = f16::from_f64(w);
    if h.to_f64() < w { f16::from_bits(h.to_bits() + 1) } else { h }
}

/// The centre of cell `(ix, iy)`'s texel range at `level`.
fn centre(pyr: &MaxHeightPyramid, level: usize, ix: u32, iy: u32) -> [f64; 2] {
    let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
    [0.5 * f64::from(x0 + x1), 0.5 * f64::from(y0 + y1)]
}

/// The cell's up to four children at the level below: indices and texel ranges.
fn children(pyr: &MaxHeightPyramid, level: usize, ix: u32, iy: u32) -> impl Iterator<Item = (u32, u32)> + '_ {
    [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().map(move |(a, b)| (2 * ix + a, 2 * iy + b)).filter(move |&(a, b)| {
        let (w, h) = pyr.level_size(level - 1);
        a < w && b < h
    })
}

impl CellPlanes {
    /// The plane bounds of `field`'s pyramid `pyr` (built for the same field and `edges`).
    #[must_use]
    pub fn new(field: &HeightField, pyr: &MaxHeightPyramid, edges: EdgeMode) -> Self {
        let clamp = edges == EdgeMode::Clamp;
        let depth = |x: i64, y: i64| f64::from(field.depth_at(x, y, edges));
        // Level 0: one texel each, at its own centre.
        let (w0, h0) = pyr.level_size(0);
        let mut sums: Vec<Sums> = (0..h0)
            .flat_map(|y| (0..w0).map(move |x| (x, y)))
            .map(|(x, y)| Sums { n: 1.0, v: depth(i64::from(x), i64::from(y)), ..Sums::default() })
            .collect();
        let mut levels: Vec<(u32, Vec<Stored>)> = Vec::with_capacity(pyr.len().saturating_sub(1));
        for level in 1..pyr.len() {
            let (nw, nh) = pyr.level_size(level);
            let (cw, _) = pyr.level_size(level - 1);
            let below = &sums;
            let next: Vec<Sums> = (0..nh)
                .into_par_iter()
                .flat_map_iter(|iy| {
                    (0..nw).map(move |ix| {
                        let c = centre(pyr, level, ix, iy);
                        let mut s = Sums::default();
                        for (a, b) in children(pyr, level, ix, iy) {
                            let k = below[(b * cw + a) as usize];
                            let cc = centre(pyr, level - 1, a, b);
                            let (dx, dy) = (cc[0] - c[0], cc[1] - c[1]);
                            s.n += k.n;
                            s.v += k.v;
                            s.xv += k.xv + dx * k.v;
                            s.yv += k.yv + dy * k.v;
                            s.xx += k.xx + k.n * dx * dx;
                            s.yy += k.yy + k.n * dy * dy;
                        }
                        s
                    })
                })
                .collect();
            let prev = levels.last().map(|(w, cells)| (*w, cells.as_slice()));
            let cells: Vec<Stored> = (0..nh)
                .into_par_iter()
                .flat_map_iter(|iy| {
                    let next = &next;
                    (0..nw).map(move |ix| {
                        let s = next[(iy * nw + ix) as usize];
                        let border_x = clamp && (ix == 0 || ix + 1 == nw);
                        let border_y = clamp && (iy == 0 || iy + 1 == nh);
                        let slope = |sum: f64, squares: f64, border: bool| {
                            if border || squares <= 0.0 { f16::ZERO } else { half_nearest(sum / squares) }
                        };
                        let (gx, gy) = (slope(s.xv, s.xx, border_x), slope(s.yv, s.yy, border_y));
                        let plane = CellPlane {
                            depth: (s.v / s.n) as f32,
                            slope: [gx.to_f32(), gy.to_f32()],
                            shallower: 0.0,
                            deeper: 0.0,
                        };
                        let (shallower, deeper) = match prev {
                            Some((pw, prev)) if level > EXACT_WIDTHS_UP_TO => {
                                widths_from_children(pyr, level, ix, iy, &plane, pw, prev)
                            }
                            _ => measured_widths(pyr, &depth, level, ix, iy, &plane),
                        };
                        Stored {
                            depth: plane.depth,
                            halves: [
                                gx.to_bits(),
                                gy.to_bits(),
                                half_up(shallower + PAD).to_bits(),
                                half_up(deeper + PAD).to_bits(),
                            ],
                        }
                    })
                })
                .collect();
            levels.push((nw, cells));
            sums = next;
        }
        Self { levels }
    }

    /// The bounds of cell `(x, y)` of pyramid level `level` (1 and up).
    ///
    /// # Panics
    /// For level 0 (texel footprints have no plane: the walk solves their patches) or a cell
    /// outside the level.
    #[must_use]
    pub fn cell(&self, level: usize, x: u32, y: u32) -> CellPlane {
        assert!(level >= 1, "level 0 has no planes");
        let (w, cells) = &self.levels[level - 1];
        assert!(x < *w && (y * w + x) < cells.len() as u32, "cell ({x}, {y}) outside level {level}");
        cells[(y * w + x) as usize].plane()
    }

    /// Whether these bounds have the cells of `pyr`'s levels above level 0 (the pyramid of a
    /// field of the size they were built for).
    #[must_use]
    pub fn fits(&self, pyr: &MaxHeightPyramid) -> bool {
        self.levels.len() + 1 == pyr.len()
            && self.levels.iter().enumerate().all(|(k, (w, cells))| {
                let (pw, ph) = pyr.level_size(k + 1);
                *w == pw && cells.len() == pw as usize * ph as usize
            })
    }

    /// The centre of cell `(x, y)`'s texel range at `level`, the point [`CellPlane::depth`] is at.
    #[must_use]
    pub fn centre(pyr: &MaxHeightPyramid, level: usize, x: u32, y: u32) -> [f64; 2] {
        centre(pyr, level, x, y)
    }
}

/// The widths of `plane` over cell `(ix, iy)` of `level`, measured on the half-texel grid.
fn measured_widths(
    pyr: &MaxHeightPyramid,
    depth: &impl Fn(i64, i64) -> f64,
    level: usize,
    ix: u32,
    iy: u32,
    plane: &CellPlane,
) -> (f64, f64) {
    let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
    let c = centre(pyr, level, ix, iy);
    // Grid index k stands for x = k / 2: odd k a texel centre (texel (k - 1) / 2), even k a wall
    // between texels k / 2 - 1 and k / 2, where the bilinear surface is their mean.
    let along_x = |k: i64, row: i64| {
        if k % 2 == 1 { depth((k - 1) / 2, row) } else { 0.5 * (depth(k / 2 - 1, row) + depth(k / 2, row)) }
    };
    let surface = |kx: i64, ky: i64| {
        if ky % 2 == 1 { along_x(kx, (ky - 1) / 2) } else { 0.5 * (along_x(kx, ky / 2 - 1) + along_x(kx, ky / 2)) }
    };
    let (mut shallower, mut deeper) = (0.0f64, 0.0f64);
    for ky in 2 * i64::from(y0)..=2 * i64::from(y1) {
        for kx in 2 * i64::from(x0)..=2 * i64::from(x1) {
            let r = surface(kx, ky) - plane.at(c, 0.5 * kx as f64, 0.5 * ky as f64);
            shallower = shallower.max(-r);
            deeper = deeper.max(r);
        }
    }
    (shallower, deeper)
}

/// The widths of `plane` over cell `(ix, iy)` of `level`, bounded from its children's planes
/// and widths (`prev`, level `level - 1`, `pw` cells wide): the difference of two planes is
/// extreme at a corner of the child.
fn widths_from_children(
    pyr: &MaxHeightPyramid,
    level: usize,
    ix: u32,
    iy: u32,
    plane: &CellPlane,
    pw: u32,
    prev: &[Stored],
) -> (f64, f64) {
    let c = centre(pyr, level, ix, iy);
    let (mut shallower, mut deeper) = (0.0f64, 0.0f64);
    for (a, b) in children(pyr, level, ix, iy) {
        let child = prev[(b * pw + a) as usize].plane();
        let cc = centre(pyr, level - 1, a, b);
        let ([x0, x1], [y0, y1]) = pyr.cell_texels(level - 1, a, b);
        for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
            let (x, y) = (f64::from(x), f64::from(y));
            let gap = plane.at(c, x, y) - child.at(cc, x, y);
            shallower = shallower.max(gap + f64::from(child.shallower));
            deeper = deeper.max(f64::from(child.deeper) - gap);
        }
    }
    (shallower, deeper)
}

#[cfg(test)]
mod tests {
    use glam::Vec2;

    use super::*;
    use crate::accuracy::SplitMix64;
    use crate::procedural::{Pattern, generate};

    /// Every cell of every level, with its texel range.
    fn cells(pyr: &MaxHeightPyramid) -> impl Iterator<Item = (usize, u32, u32)> + '_ {
        (1..pyr.len()).flat_map(move |level| {
            let (w, h) = pyr.level_size(level);
            (0..h).flat_map(move |y| (0..w).map(move |x| (level, x, y)))
        })
    }

    #[test]
    fn the_planes_bound_the_surface_everywhere_over_their_cells() {
        // The surface read by the field's own bilinear sampling (not the build's grid), at
        // random points of every cell, on smooth, flat-faced, steep and thin relief, a size
        // that is not a power of two, both edge modes; for clamped border cells also outside
        // the tile, where they reach.
        let mut rng = SplitMix64::new(7);
        for pattern in [Pattern::Waves, Pattern::Bricks, Pattern::Cobblestones, Pattern::Fur] {
            for (w, h) in [(64, 64), (48, 40)] {
                for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
                    let f = generate(pattern, w, h);
                    let pyr = MaxHeightPyramid::new(&f, edges);
                    let planes = CellPlanes::new(&f, &pyr, edges);
                    for (level, ix, iy) in cells(&pyr) {
                        let p = planes.cell(level, ix, iy);
                        let c = CellPlanes::centre(&pyr, level, ix, iy);
                        let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
                        let (nw, nh) = pyr.level_size(level);
                        let reach = |lo: u32, hi: u32, first: bool, last: bool| {
                            let out = if edges == EdgeMode::Clamp { 5.0 } else { 0.0 };
                            (
                                f64::from(lo) - if first { out } else { 0.0 },
                                f64::from(hi) + if last { out } else { 0.0 },
                            )
                        };
                        let (xa, xb) = reach(x0, x1, ix == 0, ix + 1 == nw);
                        let (ya, yb) = reach(y0, y1, iy == 0, iy + 1 == nh);
                        for _ in 0..24 {
                            let x = xa + (xb - xa) * f64::from(rng.next_f32());
                            let y = ya + (yb - ya) * f64::from(rng.next_f32());
                            let uv = Vec2::new((x / f64::from(w)) as f32, (y / f64::from(h)) as f32);
                            let s = f64::from(f.sample_bilinear(uv, edges));
                            let at = p.at(c, x, y);
                            let tol = 1e-5;
                            assert!(
                                s >= at - f64::from(p.shallower) - tol && s <= at + f64::from(p.deeper) + tol,
                                "{} {w}x{h} {edges:?} level {level} cell ({ix}, {iy}) at ({x}, {y}): surface {s}, \
                                 plane {at}, widths {} / {}",
                                pattern.name(),
                                p.shallower,
                                p.deeper
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn a_tilted_plane_is_its_own_bound() {
        // A field that is a plane: the bilinear surface is that plane, so every cell's
        // least-squares plane is it (slopes to f16, the depth to f32) and the widths are what
        // that rounding leaves, a few 1e-4 at most even over a whole 64-texel cell.
        let (a, b, c) = (0.2f64, 0.004f64, -0.0025f64);
        let f = HeightField::from_depths(
            64,
            64,
            (0..64 * 64)
                .map(|k| (a + b * (f64::from(k % 64) + 0.5) + c * (f64::from(k / 64) + 0.5) + 0.1) as f32)
                .collect(),
        )
        .unwrap();
        let pyr = MaxHeightPyramid::new(&f, EdgeMode::Clamp);
        let planes = CellPlanes::new(&f, &pyr, EdgeMode::Clamp);
        for (level, ix, iy) in cells(&pyr) {
            let (nw, nh) = pyr.level_size(level);
            let p = planes.cell(level, ix, iy);
            // Clamped border cells are level along their infinite axis.
            let want_x = if ix == 0 || ix + 1 == nw { 0.0 } else { b };
            let want_y = if iy == 0 || iy + 1 == nh { 0.0 } else { c };
            assert!((f64::from(p.slope[0]) - want_x).abs() <= b.abs() / 1000.0, "level {level} ({ix}, {iy}): {p:?}");
            assert!((f64::from(p.slope[1]) - want_y).abs() <= c.abs() / 1000.0, "level {level} ({ix}, {iy}): {p:?}");
            if want_x != 0.0 && want_y != 0.0 {
                assert!(p.shallower < 5e-4 && p.deeper < 5e-4, "level {level} ({ix}, {iy}): {p:?}");
            }
        }
    }

    #[test]
    fn measured_widths_are_reached_by_the_surface() {
        // Up to EXACT_WIDTHS_UP_TO the widths are the surface's own reach from the stored plane
        // (plus the pad and the rounding up), not merely a bound: the field's sampling reaches
        // within 1e-3 of each somewhere on the cell's half-texel grid.
        let f = generate(Pattern::Cobblestones, 64, 64);
        let pyr = MaxHeightPyramid::new(&f, EdgeMode::Wrap);
        let planes = CellPlanes::new(&f, &pyr, EdgeMode::Wrap);
        for (level, ix, iy) in cells(&pyr).filter(|c| c.0 <= EXACT_WIDTHS_UP_TO) {
            let p = planes.cell(level, ix, iy);
            let c = CellPlanes::centre(&pyr, level, ix, iy);
            let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
            let (mut shallower, mut deeper) = (0.0f64, 0.0f64);
            for ky in 2 * y0..=2 * y1 {
                for kx in 2 * x0..=2 * x1 {
                    let (x, y) = (f64::from(kx) / 2.0, f64::from(ky) / 2.0);
                    let uv = Vec2::new((x / 64.0) as f32, (y / 64.0) as f32);
                    let r = f64::from(f.sample_bilinear(uv, EdgeMode::Wrap)) - p.at(c, x, y);
                    shallower = shallower.max(-r);
                    deeper = deeper.max(r);
                }
            }
            for (stored, reached) in [(p.shallower, shallower), (p.deeper, deeper)] {
                let stored = f64::from(stored);
                assert!(
                    stored >= reached - 1e-6 && stored <= reached * 1.001 + 1e-3,
                    "level {level} ({ix}, {iy}): width {stored}, reached {reached}"
                );
            }
        }
    }
}
