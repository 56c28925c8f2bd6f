//! A measurement, not part of the tracer: the exact walk with an affine (tilted) bound per
//! pyramid cell, whose fetches docs/ACCURACY.md ("Affine bounds per cell") reports.
//!
//! Each cell keeps, besides its least depth, the least-squares plane `P` of the depths of its
//! texel centres and how far the bilinear surface `S` reaches below and above it over the cell:
//! `P - below <= S <= P + above`. `S - P` is bilinear on each patch, so its extremes over a cell
//! lie at the corners of the patches cut by the cell's walls, which are all points of the
//! half-texel grid from wall to wall: the build evaluates `S` there, so the two widths are exact
//! (plus `PAD` for rounding). With clamped edges a border cell reaches to infinity outward,
//! where the surface is constant along that axis, so its plane is level along it.
//!
//! The ray's depth minus `P` is linear in `t`, so two divisions bracket the hit inside a cell:
//! before the ray reaches `P - below` nothing is hit, and once it reaches `P + above` it is
//! under the surface. The walk ([`affine_first_hit`]) differs from [`exact_first_hit`] in three
//! places:
//! - it skips a cell the ray crosses above `P - below` as well as one it crosses above the
//!   least depth;
//! - where the bracket is at most `span` texels long, it solves the patches in it at once,
//!   instead of descending;
//! - otherwise it descends from the bracket's start, straight to the level whose cells are as
//!   wide as the bracket (at most one level down when there is no bracket).
//!
//! Only the lower width decides the hit: where the patches up to the bracket's end hold none
//! (an upper width too small, or rounding), the walk goes on from there. Its hits are the exact
//! walk's; the fetches are counted as a GPU would read the data: one
//! 16-byte texel per cell visited above level 0 (least depth, plane and widths; its siblings
//! are separate texels), one gather per 2x2 block of level-0 least depths as in `exact`, and
//! one gather per bilinear patch. The walk can also read the plane only where the least depth
//! does not skip the cell, keeping `exact`'s sibling blocks at every level
//! ([`Layout::PlaneOnDemand`]). Not modelled: the f32 arithmetic and the rounding of the stored
//! planes that a GPU walk would add to the pads.

use glam::DVec3;

use super::*;
use crate::accuracy::ray_set;
use crate::procedural::{Pattern, generate};

/// Added to each width for the rounding of the plane's evaluation in f64.
const PAD: f64 = 1e-6;

/// A cell's plane `p + gx (x - cx) + gy (y - cy)` (depth, texel coordinates), and how far the
/// surface reaches below and above it.
#[derive(Clone, Copy, Default)]
struct Plane {
    p: f64,
    gx: f64,
    gy: f64,
    below: f64,
    above: f64,
    /// The greatest depth of the surface over the cell.
    max: f64,
}

/// The planes of every level of a pyramid, cell by cell.
struct Planes {
    levels: Vec<(u32, Vec<Plane>)>,
}

/// The bilinear surface's depth at texel-space point `(x, y)` (texel centres at `k + 0.5`).
fn bilinear(f: &HeightField, edges: EdgeMode, x: f64, y: f64) -> f64 {
    let (fx, fy) = (x - 0.5, y - 0.5);
    let (i, j) = (fx.floor(), fy.floor());
    let (ax, ay) = (fx - i, fy - j);
    let (i, j) = (i as i64, j as i64);
    let s = |a: i64, b: i64| f64::from(f.depth_at(a, b, edges));
    let top = s(i, j) * (1.0 - ax) + s(i + 1, j) * ax;
    let bottom = s(i, j + 1) * (1.0 - ax) + s(i + 1, j + 1) * ax;
    top * (1.0 - ay) + bottom * ay
}

/// The half-texel grid from wall `a` to wall `b`: the walls and the texel centres between.
fn grid(a: u32, b: u32) -> Vec<f64> {
    std::iter::once(f64::from(a)).chain((a..b).map(|k| f64::from(k) + 0.5)).chain([f64::from(b)]).collect()
}

impl Planes {
    /// Planes at levels up to `tilted_up_to`, level planes (`gx = gy = 0`) above; with
    /// `half_slopes` the slopes are rounded to an f16's 11 significant bits first, as a GPU
    /// texel would store them (the widths are then those of the rounded plane).
    fn new(pyr: &MaxHeightPyramid, f: &HeightField, edges: EdgeMode, tilted_up_to: usize, half_slopes: bool) -> Self {
        let clamp = edges == EdgeMode::Clamp;
        // Round to 10 stored mantissa bits (f16's, for slopes in its normal range).
        let half =
            |g: f64| if half_slopes { f64::from(f32::from_bits(((g as f32).to_bits() + 0x1000) & !0x1fff)) } else { g };
        let levels = (0..pyr.len())
            .map(|level| {
                let (nw, nh) = pyr.level_size(level);
                let mut cells = Vec::with_capacity((nw * nh) as usize);
                for iy in 0..nh {
                    for ix in 0..nw {
                        let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
                        let (cx, cy) = (0.5 * f64::from(x0 + x1), 0.5 * f64::from(y0 + y1));
                        let (mut sum, mut sx, mut sy, mut xx, mut yy, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                        for y in y0..y1 {
                            for x in x0..x1 {
                                let v = f64::from(f.depth_at(i64::from(x), i64::from(y), edges));
                                let (dx, dy) = (f64::from(x) + 0.5 - cx, f64::from(y) + 0.5 - cy);
                                sum += v;
                                sx += dx * v;
                                sy += dy * v;
                                xx += dx * dx;
                                yy += dy * dy;
                                n += 1.0;
                            }
                        }
                        let p = sum / n;
                        let border_x = clamp && (ix == 0 || ix + 1 == nw);
                        let border_y = clamp && (iy == 0 || iy + 1 == nh);
                        let tilted = level <= tilted_up_to;
                        let gx = half(if xx > 0.0 && !border_x && tilted { sx / xx } else { 0.0 });
                        let gy = half(if yy > 0.0 && !border_y && tilted { sy / yy } else { 0.0 });
                        let (mut below, mut above, mut max) = (0.0f64, 0.0f64, 0.0f64);
                        let xs = grid(x0, x1);
                        for y in grid(y0, y1) {
                            for &x in &xs {
                                let depth = bilinear(f, edges, x, y);
                                max = max.max(depth);
                                let r = depth - (p + gx * (x - cx) + gy * (y - cy));
                                below = below.max(-r);
                                above = above.max(r);
                            }
                        }
                        cells.push(Plane { p, gx, gy, below: below + PAD, above: above + PAD, max });
                    }
                }
                (nw, cells)
            })
            .collect();
        Self { levels }
    }

    /// The same planes (least squares over the texel centres, from the children's sums), with
    /// widths bounded from the children's instead of measured over the texels: a child's plane
    /// and widths bound the surface over the child, and the parent's plane differs from the
    /// child's by an affine function, extreme at the child's corners. Wider than [`Planes::new`]'s,
    /// but a level costs one pass over its cells, reading four children each, as a GPU's
    /// pyramid pass does.
    fn hierarchical(pyr: &MaxHeightPyramid, f: &HeightField, edges: EdgeMode) -> Self {
        let clamp = edges == EdgeMode::Clamp;
        // Per cell: the plane, and the sums n, sum v, sum (x - cx) v, sum (y - cy) v,
        // sum (x - cx)^2, sum (y - cy)^2 over its texel centres.
        let mut levels: Vec<(u32, Vec<Plane>)> = Vec::new();
        let mut sums: Vec<[f64; 6]> = Vec::new();
        for level in 0..pyr.len() {
            let (nw, nh) = pyr.level_size(level);
            let mut cells = Vec::with_capacity((nw * nh) as usize);
            let mut next = Vec::with_capacity((nw * nh) as usize);
            for iy in 0..nh {
                for ix in 0..nw {
                    let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
                    let (cx, cy) = (0.5 * f64::from(x0 + x1), 0.5 * f64::from(y0 + y1));
                    let border_x = clamp && (ix == 0 || ix + 1 == nw);
                    let border_y = clamp && (iy == 0 || iy + 1 == nh);
                    if level == 0 {
                        let (i, j) = (i64::from(ix), i64::from(iy));
                        let v = |a: i64, b: i64| f64::from(f.depth_at(a, b, edges));
                        let p = v(i, j);
                        let gx = if border_x { 0.0 } else { 0.5 * (v(i + 1, j) - v(i - 1, j)) };
                        let gy = if border_y { 0.0 } else { 0.5 * (v(i, j + 1) - v(i, j - 1)) };
                        let (mut below, mut above, mut max) = (0.0f64, 0.0f64, 0.0f64);
                        for y in grid(y0, y1) {
                            for x in grid(x0, x1) {
                                let depth = bilinear(f, edges, x, y);
                                max = max.max(depth);
                                let r = depth - (p + gx * (x - cx) + gy * (y - cy));
                                below = below.max(-r);
                                above = above.max(r);
                            }
                        }
                        cells.push(Plane { p, gx, gy, below, above, max });
                        next.push([1.0, p, 0.0, 0.0, 0.0, 0.0]);
                        continue;
                    }
                    let (cw, _) = pyr.level_size(level - 1);
                    let children: Vec<(u32, u32)> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .into_iter()
                        .map(|(a, b)| (2 * ix + a, 2 * iy + b))
                        .filter(|&(a, b)| {
                            let ([c0, c1], [d0, d1]) = pyr.cell_texels(level - 1, a, b);
                            c0 < c1 && d0 < d1
                        })
                        .collect();
                    let mut m = [0.0f64; 6];
                    for &(a, b) in &children {
                        let ([c0, c1], [d0, d1]) = pyr.cell_texels(level - 1, a, b);
                        let (ccx, ccy) = (0.5 * f64::from(c0 + c1), 0.5 * f64::from(d0 + d1));
                        let c = sums[(b * cw + a) as usize];
                        let (dx, dy) = (ccx - cx, ccy - cy);
                        m[0] += c[0];
                        m[1] += c[1];
                        m[2] += c[2] + dx * c[1];
                        m[3] += c[3] + dy * c[1];
                        m[4] += c[4] + c[0] * dx * dx;
                        m[5] += c[5] + c[0] * dy * dy;
                    }
                    let p = m[1] / m[0];
                    let gx = if m[4] > 0.0 && !border_x { m[2] / m[4] } else { 0.0 };
                    let gy = if m[5] > 0.0 && !border_y { m[3] / m[5] } else { 0.0 };
                    let (mut below, mut above, mut max) = (0.0f64, 0.0f64, 0.0f64);
                    let (prev_w, prev) = &levels[level - 1];
                    for &(a, b) in &children {
                        let ([c0, c1], [d0, d1]) = pyr.cell_texels(level - 1, a, b);
                        let (ccx, ccy) = (0.5 * f64::from(c0 + c1), 0.5 * f64::from(d0 + d1));
                        let child = prev[(b * prev_w + a) as usize];
                        max = max.max(child.max);
                        for (x, y) in [(c0, d0), (c1, d0), (c0, d1), (c1, d1)] {
                            let (x, y) = (f64::from(x), f64::from(y));
                            let parent = p + gx * (x - cx) + gy * (y - cy);
                            let own = child.p + child.gx * (x - ccx) + child.gy * (y - ccy);
                            below = below.max(parent - own + child.below);
                            above = above.max(own - parent + child.above);
                        }
                    }
                    cells.push(Plane { p, gx, gy, below, above, max });
                    next.push(m);
                }
            }
            levels.push((nw, cells));
            sums = next;
        }
        for (_, cells) in &mut levels {
            for c in cells {
                c.below += PAD;
                c.above += PAD;
            }
        }
        Self { levels }
    }

    /// Replaces the widths of the levels above `up_to` by bounds from their children's planes
    /// and widths, as [`Planes::hierarchical`] forms them (the planes stay): what a GPU pass
    /// per level could compute above the levels it measures texel by texel.
    fn widths_from_children_above(mut self, pyr: &MaxHeightPyramid, up_to: usize) -> Self {
        for level in (up_to + 1)..pyr.len() {
            let (nw, nh) = pyr.level_size(level);
            let (cw, _) = pyr.level_size(level - 1);
            for iy in 0..nh {
                for ix in 0..nw {
                    let ([x0, x1], [y0, y1]) = pyr.cell_texels(level, ix, iy);
                    let (cx, cy) = (0.5 * f64::from(x0 + x1), 0.5 * f64::from(y0 + y1));
                    let parent = self.get(level, ix, iy);
                    let (mut below, mut above, mut max) = (0.0f64, 0.0f64, 0.0f64);
                    for (a, b) in [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(a, b)| (2 * ix + a, 2 * iy + b)) {
                        let ([c0, c1], [d0, d1]) = pyr.cell_texels(level - 1, a, b);
                        if c0 >= c1 || d0 >= d1 {
                            continue;
                        }
                        let (ccx, ccy) = (0.5 * f64::from(c0 + c1), 0.5 * f64::from(d0 + d1));
                        let child = self.levels[level - 1].1[(b * cw + a) as usize];
                        max = max.max(child.max);
                        for (x, y) in [(c0, d0), (c1, d0), (c0, d1), (c1, d1)] {
                            let (x, y) = (f64::from(x), f64::from(y));
                            let theirs = parent.p + parent.gx * (x - cx) + parent.gy * (y - cy);
                            let own = child.p + child.gx * (x - ccx) + child.gy * (y - ccy);
                            below = below.max(theirs - own + child.below);
                            above = above.max(own - theirs + child.above);
                        }
                    }
                    self.levels[level].1[(iy * nw + ix) as usize] = Plane { below, above, max, ..parent };
                }
            }
        }
        self
    }

    fn get(&self, level: usize, ix: u32, iy: u32) -> Plane {
        let (nw, cells) = &self.levels[level];
        cells[(iy * nw + ix) as usize]
    }
}

/// How the walk reads the cells' data, for counting fetches.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Layout {
    /// `exact`'s sibling blocks of least depths at every level, and the plane read (one more
    /// fetch) only where the least depth does not skip the cell.
    PlaneOnDemand,
    /// One texel per cell above level 0 holds both; sibling blocks at level 0.
    PerCell,
    /// As `PerCell`, in four values with no separate least depth: the plane and its widths'
    /// sum, or where the least and greatest depths are nearer each other than the widths'
    /// sum, those (a level plane).
    FourValues,
}

/// One variant of the walk.
#[derive(Clone, Copy)]
struct Walk {
    layout: Layout,
    /// The longest bracket, in texels of horizontal travel, solved patch by patch at once.
    span: f64,
    /// Levels added to [`start_level`]'s choice.
    start_up: usize,
    /// The highest level the walk starts at.
    start_cap: usize,
}

/// The first `t` in `[t0, t1]` at or below the surface, as [`exact_first_hit`] (rays going
/// down only), by the walk with affine bounds the module docs describe.
#[expect(clippy::too_many_lines, reason = "one walk, kept in one piece to compare with exact_first_hit")]
fn affine_first_hit(
    surface: &Surface,
    planes: &Planes,
    walk: Walk,
    o: DVec3,
    d: DVec3,
    t0: f64,
    t1: f64,
) -> ExactResult {
    assert!(d.z > 0.0, "the measurement traces view rays only");
    let pyr = surface.pyramid();
    let f = surface.field();
    let (w, h) = (i64::from(f.width()), i64::from(f.height()));
    let edges = surface.edges();
    let top = pyr.len() - 1;
    let travel = d.x.hypot(d.y);
    // Advances and patch walks are bounded by the texel walls crossed, as for the exact walk;
    // descents by the advances plus the start level. Twice that is ample for a measurement.
    let max_steps = exact_step_bound(d, t0, t1, w, h, edges).saturating_mul(2);
    let mut fetches = 0u32;
    let mut t = t0;
    let mut level = (start_level(d, t0, t1, top) + walk.start_up).min(walk.start_cap).min(top);
    let mut read: [Option<(i64, i64)>; 34] = [None; 34];
    let mut last_patch: Option<(i64, i64)> = None;
    // Where the ray leaves `cell` at `t_exit`: climb when it also leaves the parent.
    let climb = |level: usize, probe, t: f64, t_exit: f64| -> usize {
        if level < top && exit_time(&cell_at(pyr, level + 1, probe, d, w, h, edges), o, d, t, t1) <= t_exit {
            level + 1
        } else {
            level
        }
    };
    for _ in 0..max_steps {
        if t > t1 {
            break;
        }
        let Some((cell, probe, t_exit)) = entered_cell(pyr, level, o, d, t, t1, w, h, edges) else { break };
        let per_cell = walk.layout != Layout::PlaneOnDemand && level > 0;
        let key = if per_cell { (cell.x0 as i64, cell.y0 as i64) } else { block_key(&cell, level, edges) };
        if read[level.min(33)] != Some(key) {
            read[level.min(33)] = Some(key);
            fetches += 1;
        }
        let mut bound = f64::from(pyr.min_depth(level, cell.ix, cell.iy));
        let mut pl = planes.get(level, cell.ix, cell.iy);
        if walk.layout == Layout::FourValues && level > 0 {
            if pl.max - bound <= pl.below + pl.above {
                pl = Plane { p: bound, gx: 0.0, gy: 0.0, below: 0.0, above: pl.max - bound, max: pl.max };
            } else {
                // The texel holds no least depth: only the plane bounds the cell.
                bound = 0.0;
            }
        }
        let mut skip = o.z + d.z * t_exit < bound;
        let mut t_lo = t.max(((bound - o.z) / d.z).min(t_exit));
        let mut bracket: Option<f64> = None;
        if !skip && level > 0 && bound < 1.0 {
            if !per_cell {
                fetches += 1;
            }
            // The plane's centre in the ray's unbounded coordinates (a clamped border cell's
            // plane is level along its infinite axis, where the centre does not matter).
            let centre = |lo: f64, hi: f64| if lo.is_finite() && hi.is_finite() { 0.5 * (lo + hi) } else { 0.0 };
            let (cx, cy) = (centre(cell.x0, cell.x1), centre(cell.y0, cell.y1));
            // g(t): the ray's depth minus the plane's, linear in t.
            let g0 = o.z - (pl.p + pl.gx * (o.x - cx) + pl.gy * (o.y - cy));
            let g1 = d.z - (pl.gx * d.x + pl.gy * d.y);
            let g = |u: f64| g0 + g1 * u;
            // Before t_lo the least depth already keeps the ray above the surface.
            if g(t_lo).max(g(t_exit)) < -pl.below {
                skip = true;
            } else {
                if g(t_lo) < -pl.below {
                    t_lo = ((-pl.below - g0) / g1).clamp(t_lo, t_exit);
                }
                let under = if g(t_lo) >= pl.above {
                    Some(t_lo)
                } else if g(t_exit) >= pl.above {
                    Some(((pl.above - g0) / g1).clamp(t_lo, t_exit))
                } else {
                    None
                };
                bracket = under;
            }
        }
        if skip {
            if t_exit >= t1 {
                break;
            }
            level = climb(level, probe, t, t_exit);
            t = t_exit;
            continue;
        }
        if bound >= 1.0 {
            return ExactResult { t: Some(t.max((1.0 - o.z) / d.z).min(t_exit)), fetches };
        }
        let span = bracket.map(|u| (u - t_lo) * travel);
        if let (Some(under), Some(span)) = (bracket, span)
            && span <= walk.span
        {
            // The hit is in [t_lo, under]: solve the patches there, footprint by footprint.
            let mut u = t_lo;
            while let Some((leaf, _, leaf_exit)) = entered_cell(pyr, 0, o, d, u, t1, w, h, edges) {
                let leaf_exit = leaf_exit.min(t_exit);
                let (hit, gathers) = leaf_hit(f, edges, o, d, u, leaf_exit, &leaf, &mut last_patch);
                fetches += gathers;
                if hit.is_some() {
                    return ExactResult { t: hit, fetches };
                }
                if leaf_exit >= under || leaf_exit >= t_exit {
                    u = leaf_exit;
                    break;
                }
                u = leaf_exit;
            }
            // Rounding left the hit beyond the bracket: go on from where the solves ended.
            t = u;
            if t >= t_exit {
                if t_exit >= t1 {
                    break;
                }
                level = climb(level, probe, t, t_exit);
                continue;
            }
            t_lo = t;
        }
        if level > 0 {
            t = t_lo;
            let wide = span.map_or(level - 1, |s| s.max(1.0).log2().floor() as usize);
            level = (level - 1).min(wide);
            continue;
        }
        let (hit, gathers) = leaf_hit(f, edges, o, d, t, t_exit, &cell, &mut last_patch);
        fetches += gathers;
        if hit.is_some() {
            return ExactResult { t: hit, fetches };
        }
        if t_exit >= t1 {
            break;
        }
        t = t_exit;
    }
    ExactResult { t: None, fetches }
}

/// The walk the table recommends: one texel per cell, brackets up to 3 texels solved at once,
/// starting two levels above `exact` but no higher than level 5.
const PER_CELL: Walk = Walk { layout: Layout::PerCell, span: 3.0, start_up: 2, start_cap: 5 };

/// [`PER_CELL`] in four values per texel.
const FOUR_VALUES: Walk = Walk { layout: Layout::FourValues, ..PER_CELL };

/// `exact`'s blocks with the plane read where the least depth does not skip, starting where
/// `exact` starts.
const ON_DEMAND: Walk = Walk { layout: Layout::PlaneOnDemand, span: 3.0, start_up: 0, start_cap: 99 };

/// The view rays of `ray_set` in texel units, as the exact view trace forms them.
fn texel_rays(angle: f32, count: usize, size: f64, depth_scale: f32) -> Vec<(DVec3, DVec3)> {
    ray_set(angle, count, 1)
        .iter()
        .map(|ray| {
            let dir = entering(ray.dir).expect("ray_set's rays enter");
            let s = uv_per_depth(dir, depth_scale);
            let o = DVec3::new(f64::from(ray.uv.x) * size, f64::from(ray.uv.y) * size, 0.0);
            (o, DVec3::new(f64::from(s.x) * size, f64::from(s.y) * size, 1.0))
        })
        .collect()
}

/// Mean fetches per ray of `exact` and of each walk, asserting that every walk's hit is the
/// exact one.
fn measure(surface: &Surface, planes: &Planes, rays: &[(DVec3, DVec3)], walks: &[Walk]) -> Vec<f64> {
    let mut sums = vec![0.0; walks.len() + 1];
    for &(o, d) in rays {
        let e = exact_first_hit(surface, o, d, 0.0, 1.0);
        sums[0] += f64::from(e.fetches);
        for (k, &walk) in walks.iter().enumerate() {
            let a = affine_first_hit(surface, planes, walk, o, d, 0.0, 1.0);
            sums[k + 1] += f64::from(a.fetches);
            let apart = (a.t.unwrap_or(1.0) - e.t.unwrap_or(1.0)).abs() * d.x.hypot(d.y);
            assert!(apart < 1e-6, "ray {o} {d}: the affine walk's hit is {apart} texels from exact's");
        }
    }
    sums.iter().map(|s| s / rays.len() as f64).collect()
}

#[test]
fn the_affine_walk_finds_the_exact_hits() {
    // Smooth, flat-faced, steep and thin relief, both edge modes, a steep and a grazing angle:
    // if a lower width were short anywhere (a skipped cell or stretch holding surface), some
    // hit would move (halving them moves hits here).
    for pattern in [Pattern::Waves, Pattern::Bricks, Pattern::Cobblestones, Pattern::Fur] {
        for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
            let f = generate(pattern, 64, 64);
            let surface = Surface::new(f.clone(), edges, 0.1);
            let planes = Planes::new(surface.pyramid(), &f, edges, usize::MAX, false);
            for angle in [45.0f32, 85.0] {
                let rays = texel_rays(angle, 150, 64.0, 0.1);
                let means = measure(&surface, &planes, &rays, &[PER_CELL, ON_DEMAND, FOUR_VALUES]);
                assert!(means.iter().all(|m| *m > 0.0), "{} {angle}: no fetches counted", pattern.name());
            }
        }
    }
}

/// The table of docs/ACCURACY.md, "Affine bounds per cell": `cargo test --release -p
/// pomkit-core --lib affine_bounds_fetch_table -- --ignored --nocapture`. The variants the
/// text reports: `AFFINE_EDGES=clamp` (clamped edges), `AFFINE_BUILD=hierarchical` (widths
/// from the children's), `AFFINE_TILTED_UP_TO=5` (level planes above level 5),
/// `AFFINE_HALF_SLOPES=1` (slopes rounded to f16), `AFFINE_EXACT_WIDTHS_UP_TO=5` (widths from
/// the children's above level 5).
#[test]
#[ignore = "a measurement for docs/ACCURACY.md, under 10 s in release"]
fn affine_bounds_fetch_table() {
    let edges =
        if std::env::var("AFFINE_EDGES").is_ok_and(|e| e == "clamp") { EdgeMode::Clamp } else { EdgeMode::Wrap };
    println!("| map | angle | exact | plane on demand | plane per cell | four values |");
    println!("|---|--:|--:|--:|--:|--:|");
    for pattern in Pattern::ALL {
        let f = generate(pattern, 512, 512);
        let surface = Surface::new(f.clone(), edges, 0.1);
        let planes = if std::env::var("AFFINE_BUILD").is_ok_and(|b| b == "hierarchical") {
            Planes::hierarchical(surface.pyramid(), &f, edges)
        } else {
            let tilted_up_to = std::env::var("AFFINE_TILTED_UP_TO").map_or(usize::MAX, |v| v.parse().expect("a level"));
            let exact_up_to =
                std::env::var("AFFINE_EXACT_WIDTHS_UP_TO").map_or(usize::MAX, |v| v.parse().expect("a level"));
            Planes::new(surface.pyramid(), &f, edges, tilted_up_to, std::env::var("AFFINE_HALF_SLOPES").is_ok())
                .widths_from_children_above(surface.pyramid(), exact_up_to)
        };
        for angle in [60.0f32, 75.0, 85.0] {
            let rays = texel_rays(angle, 2000, 512.0, 0.1);
            let m = measure(&surface, &planes, &rays, &[ON_DEMAND, PER_CELL, FOUR_VALUES]);
            println!("| {} | {angle}° | {:.1} | {:.1} | {:.1} | {:.1} |", pattern.name(), m[0], m[1], m[2], m[3]);
        }
    }
}
