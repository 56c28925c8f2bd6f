//! The exact tracer's walk: the first point of a ray at or below the bilinear height surface,
//! by maximum-height pyramid traversal, with the patches solved in closed form.

use glam::{DVec2, DVec3};

use super::*;

/// Result of a pyramid traversal.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExactResult {
    /// Ray parameter of the first point at or below the surface, if any in the segment.
    pub t: Option<f64>,
    /// Fetches made.
    pub fetches: u32,
}

/// The first `t` in `[t0, t1]` where the ray `o + t d` (unbounded texel coordinates x, y and
/// depth z) is at or below the bilinear surface of the mip-0 texels, by maximum-height pyramid
/// traversal (after Tevs, Ihrke & Seidel 2008, "Maximum Mipmaps for Fast, Accurate, and
/// Scalable Dynamic Height Field Rendering").
///
/// A cell whose minimum depth the ray never reaches inside it is skipped whole; a cell whose
/// minimum depth is 1 is a flat floor, met where the ray reaches depth 1; otherwise the
/// walk descends, and in a level-0 cell the ray is solved against the (up to three) bilinear
/// patches it crosses there. Works for rays going down (`d.z > 0`) and up (`d.z < 0`, shadow
/// rays) and for wrapped and clamped edges.
///
/// # Termination
/// The loop runs at most [`exact_step_bound`] times. Each step either returns, stops, descends
/// a level, or advances `t` strictly ([`entered_cell`] guarantees `t_exit > t`) to the moment
/// the ray crosses a wall of the current cell, a texel boundary. The ray crosses each texel
/// boundary once and the crossing moment of a wall is a fixed number, so advances are at most
/// the boundaries crossed; a level is climbed only on an advance and the walk starts at most
/// `top` levels up ([`start_level`]), so descents are at most the advances plus `top`. Callers
/// reduce the entry point to its tile where the edges wrap, so the coordinates stay small and the
/// f64 walls exact.
pub(crate) fn exact_first_hit(surface: &Surface, o: DVec3, d: DVec3, t0: f64, t1: f64) -> ExactResult {
    let pyr = surface.pyramid();
    let f = surface.field();
    let (w, h) = (i64::from(f.width()), i64::from(f.height()));
    let edges = surface.edges();
    let top = pyr.len() - 1;
    let max_steps = exact_step_bound(d, t0, t1, w, h, edges);
    let mut fetches = 0u32;
    let mut t = t0;
    // Start a few levels above the finest ([`start_level`]): near enough to it that a ray
    // meeting the surface a few texels from its entry descends in a few steps, far enough that
    // a long ray does not climb from the finest level cell by cell.
    let mut level = start_level(d, t0, t1, top);
    // The 2x2 block of sibling cells last gathered at each level (a GPU reads a block with one
    // `textureGather` and keeps it in registers while the ray walks between the siblings).
    // (A fixed array: no allocation per ray; a pyramid has at most 33 levels.)
    let mut blocks: [Option<(i64, i64)>; 34] = [None; 34];
    // The bilinear patch last gathered: neighbouring texel footprints share patches.
    let mut last_patch: Option<(i64, i64)> = None;
    for _ in 0..max_steps {
        if t > t1 {
            break;
        }
        let Some((cell, probe, t_exit)) = entered_cell(pyr, level, o, d, t, t1, w, h, edges) else {
            // No wall ahead can be told from the current point in f64: unreachable for rays whose
            // texel travel is below about 2^50 (all sanitized rays); give up rather than spin.
            break;
        };
        // One gather per sibling block: stepping between siblings costs no fetch.
        let key = block_key(&cell, level, edges);
        if blocks[level.min(33)] != Some(key) {
            blocks[level.min(33)] = Some(key);
            fetches = fetches.saturating_add(1);
        }
        let bound = f64::from(pyr.min_depth(level, cell.ix, cell.iy));
        // The deepest point of the ray inside the cell is at its exit (going down) or entry
        // (going up).
        let deepest = if d.z >= 0.0 { o.z + d.z * t_exit } else { o.z + d.z * t };
        if deepest < bound {
            // The ray stays above everything in this cell: skip it and climb a level.
            if t_exit >= t1 {
                break;
            }
            // Climb only when the ray also leaves the parent cell: inside the same parent the
            // parent's bound is already known to be reached, and climbing would only descend
            // again.
            if level < top {
                let parent = cell_at(pyr, level + 1, probe, d, w, h, edges);
                if exit_time(&parent, o, d, t, t1) <= t_exit {
                    level += 1;
                }
            }
            t = t_exit;
            continue;
        }
        if bound >= 1.0 && d.z > 0.0 {
            // The least depth of the cell is the deepest a field holds, so the surface in it is
            // the plane at depth 1 (a flat floor): going down, the ray meets it where it reaches
            // depth 1, which is inside the cell (the ray reaches the bound by the exit). The
            // descent to level 0 would find the same point after a fetch per level and a patch.
            return ExactResult { t: Some(t.max((1.0 - o.z) / d.z).min(t_exit)), fetches };
        }
        if level > 0 {
            // Going down, nothing is hit before the ray reaches the bound: jump there (never
            // past the cell, where the bound is known to be reached).
            if d.z > 0.0 {
                t = t.max(((bound - o.z) / d.z).min(t_exit));
            }
            level -= 1;
            continue;
        }
        // Level 0: solve against the bilinear patches inside this texel footprint.
        let (hit, gathers) = leaf_hit(f, edges, o, d, t, t_exit, &cell, &mut last_patch);
        fetches = fetches.saturating_add(gathers);
        if let Some(th) = hit {
            return ExactResult { t: Some(th), fetches };
        }
        if t_exit >= t1 {
            break;
        }
        // Stay at level 0: the ray is close to the surface here, and the next texel is the
        // likeliest place for the hit; a skip there climbs again.
        t = t_exit;
    }
    ExactResult { t: None, fetches }
}

/// The exact view trace's walk: [`plane_walk`]'s on a surface with plane bounds
/// ([`Surface::use_plane_bounds`]), else [`exact_first_hit`]'s; the same hits, other fetches.
/// Shadow and silhouette rays take [`exact_first_hit`]'s walk on every surface, as the shader
/// library's do.
pub(crate) fn view_first_hit(surface: &Surface, o: DVec3, d: DVec3, t0: f64, t1: f64) -> ExactResult {
    match surface.plane_bounds() {
        Some(planes) if d.z > 0.0 => plane_walk::planes_first_hit(surface, planes, o, d, t0, t1),
        _ => exact_first_hit(surface, o, d, t0, t1),
    }
}

/// How many levels below the one whose cells are as wide as the ray's horizontal travel the
/// walk starts: with `2^(k + START_BELOW)` texels of travel it starts at level `k`, cells of an
/// eighth of the travel. Measured on the built-in maps at 60 to 85 degrees (docs/ACCURACY.md):
/// starting at level 0 took 1% to 33% more fetches, starting with cells of half the travel more
/// again.
const START_BELOW: u32 = 3;

/// The level [`exact_first_hit`] starts at for a ray with texel-space direction `d` over `t` in
/// `[t0, t1]`: `floor(log2(travel)) - START_BELOW` for a horizontal travel of at least
/// `2^START_BELOW` texels, else 0, and never above `top`. The GPU's walk computes the same from
/// its f32 travel (`pomkit_start_level`): the two can differ only for a travel within rounding
/// of a power of two, which changes the fetches and steps, not the hit.
pub(crate) fn start_level(d: DVec3, t0: f64, t1: f64, top: usize) -> usize {
    let travel = d.x.hypot(d.y) * (t1 - t0);
    if travel.is_nan() || travel < f64::from(1u32 << START_BELOW) {
        return 0;
    }
    // `as` saturates: a travel beyond u32 starts at the top anyway.
    let whole = travel as u32;
    (whole.ilog2().saturating_sub(START_BELOW) as usize).min(top)
}

/// The most steps [`exact_first_hit`] takes for a ray with texel-space direction `d` over
/// `t` in `[t0, t1]` on a `w` x `h` field: `2 * (columns + rows) + 3 + top`, where `columns`
/// bounds the texel boundaries `x = integer` the ray crosses (`floor(|d.x| (t1 - t0)) + 2`, one
/// more than exact arithmetic needs, for rounding; with clamped edges at most the `w - 1`
/// interior boundaries, the border cells reaching to infinity) and `rows` likewise. See the proof on
/// [`exact_first_hit`]: at most one advance per boundary crossed plus the last, and at most as
/// many descents as advances plus the start level, which is at most `top`, the pyramid's
/// coarsest level, `ceil(log2(max(w, h)))`. Saturates at `u64::MAX`.
pub(crate) fn exact_step_bound(d: DVec3, t0: f64, t1: f64, w: i64, h: i64, edges: EdgeMode) -> u64 {
    let span = if t1 > t0 { t1 - t0 } else { 0.0 };
    let walls = |dp: f64, n: i64| -> f64 {
        let crossed = (dp.abs() * span).floor() + 2.0;
        let crossed = if crossed.is_finite() { crossed } else { f64::MAX };
        match edges {
            EdgeMode::Wrap => crossed,
            EdgeMode::Clamp => crossed.min((n - 1).max(0) as f64),
        }
    };
    // `as` saturates for huge values (and the sum cannot be NaN).
    let boundaries = (walls(d.x, w) + walls(d.y, h)) as u64;
    let n = w.max(h).max(1).unsigned_abs();
    let top = u64::from(u64::BITS - (n - 1).leading_zeros());
    boundaries.saturating_mul(2).saturating_add(3).saturating_add(top)
}

/// The cell of `level` the ray `o + t d` is in at `t`, moving forward: its probe point and the
/// time the ray leaves it, strictly after `t` (unless `t >= t1`).
///
/// On a wall the cell chosen is the one the ray enters ([`cell_at`] rounds by direction). When
/// rounding puts the computed point on the wrong side of a wall the ray is leaving (its
/// crossing time is at or before `t`: no progress), the probe steps half a texel across every
/// such wall, into the neighbour, whose far wall is at least a texel further. `None` if even
/// that makes no progress (only for texel travel beyond about 2^50).
#[expect(clippy::too_many_arguments, reason = "the pyramid level, the ray, its segment and the field's size")]
pub(crate) fn entered_cell(
    pyr: &MaxHeightPyramid,
    level: usize,
    o: DVec3,
    d: DVec3,
    t: f64,
    t1: f64,
    w: i64,
    h: i64,
    edges: EdgeMode,
) -> Option<(Cell, DVec2, f64)> {
    let p = o + d * t;
    let mut probe = DVec2::new(p.x, p.y);
    let cell = cell_at(pyr, level, probe, d, w, h, edges);
    let t_exit = exit_time(&cell, o, d, t, t1);
    if t_exit > t || t >= t1 {
        return Some((cell, probe, t_exit));
    }
    let crossed = |wall: f64, p0: f64, dp: f64| (wall - p0) / dp <= t;
    if d.x > 0.0 && crossed(cell.x1, o.x, d.x) {
        probe.x = cell.x1 + 0.5;
    } else if d.x < 0.0 && crossed(cell.x0, o.x, d.x) {
        probe.x = cell.x0 - 0.5;
    }
    if d.y > 0.0 && crossed(cell.y1, o.y, d.y) {
        probe.y = cell.y1 + 0.5;
    } else if d.y < 0.0 && crossed(cell.y0, o.y, d.y) {
        probe.y = cell.y0 - 0.5;
    }
    let cell = cell_at(pyr, level, probe, d, w, h, edges);
    let t_exit = exit_time(&cell, o, d, t, t1);
    (t_exit > t).then_some((cell, probe, t_exit))
}

/// Identifies the 2x2 sibling block holding `cell`. With wrapping edges: its parent's lower
/// corner in unbounded texel coordinates, so a ray entering the same texels in another tile
/// gathers them again. With clamped edges (no tiles): the parent's index.
fn block_key(cell: &Cell, level: usize, edges: EdgeMode) -> (i64, i64) {
    match edges {
        EdgeMode::Wrap => {
            let size = f64::from(1u32 << level.min(30));
            let corner = |lo: f64, index: u32| (lo - f64::from(index % 2) * size).round() as i64;
            (corner(cell.x0, cell.ix), corner(cell.y0, cell.iy))
        }
        EdgeMode::Clamp => (i64::from(cell.ix / 2), i64::from(cell.iy / 2)),
    }
}

/// Where the ray `o + t d` leaves `cell`, at or after `t` and no later than `t1`.
fn exit_time(cell: &Cell, o: DVec3, d: DVec3, t: f64, t1: f64) -> f64 {
    let mut t_exit = t1;
    if d.x > 0.0 {
        t_exit = t_exit.min((cell.x1 - o.x) / d.x);
    } else if d.x < 0.0 {
        t_exit = t_exit.min((cell.x0 - o.x) / d.x);
    }
    if d.y > 0.0 {
        t_exit = t_exit.min((cell.y1 - o.y) / d.y);
    } else if d.y < 0.0 {
        t_exit = t_exit.min((cell.y0 - o.y) / d.y);
    }
    t_exit.max(t)
}

/// A pyramid cell in unbounded texel coordinates, with its indices in the level.
pub(crate) struct Cell {
    pub(crate) ix: u32,
    pub(crate) iy: u32,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

/// The cell of `level` containing texel-space point `p`, moving along `d`: on a wall, the cell
/// on the side the ray travels to (an axis the ray moves backward along takes the cell whose
/// interval `(lo, hi]` holds the point, others `[lo, hi)`).
///
/// With wrapping edges the plane tiles: the cell is found in the tile containing the point and
/// its walls are returned in unbounded coordinates. With clamped edges the border cells extend
/// to infinity outward (the clamped surface continues the border texels unchanged).
fn cell_at(pyr: &MaxHeightPyramid, level: usize, p: DVec2, d: DVec3, w: i64, h: i64, edges: EdgeMode) -> Cell {
    let (nw, nh) = pyr.level_size(level);
    let size = 1i64 << level;
    let axis = |p: f64, dp: f64, n: i64, cells: u32| -> (u32, f64, f64) {
        let fp = if dp < 0.0 { p.ceil() - 1.0 } else { p.floor() };
        match edges {
            EdgeMode::Wrap => {
                let tile = (fp / n as f64).floor();
                let local = (fp as i64).rem_euclid(n);
                let c = (local / size).min(i64::from(cells) - 1);
                let base = tile * n as f64;
                let lo = base + (c * size) as f64;
                let hi = base + ((c + 1) * size).min(n) as f64;
                (c as u32, lo, hi)
            }
            EdgeMode::Clamp => {
                let local = (fp as i64).clamp(0, n - 1);
                let c = (local / size).min(i64::from(cells) - 1);
                let lo = if c == 0 { f64::NEG_INFINITY } else { (c * size) as f64 };
                let hi = if c == i64::from(cells) - 1 { f64::INFINITY } else { ((c + 1) * size).min(n) as f64 };
                (c as u32, lo, hi)
            }
        }
    };
    let (ix, x0, x1) = axis(p.x, d.x, w, nw);
    let (iy, y0, y1) = axis(p.y, d.y, h, nh);
    Cell { ix, iy, x0, x1, y0, y1 }
}

/// Solves the ray against the bilinear patches it crosses between `ta` and `tb` inside a
/// level-0 cell. Returns the first hit and the number of gathers (one per patch).
///
/// A texel footprint holds one line through texel centres per axis (`x0 + 0.5`): the ray is
/// split there into at most three segments, each inside one bilinear patch. A clamped border
/// cell reaches to infinity outward, but beyond the border texel's centre the clamped surface
/// is constant along that axis, so the same single split is exact there too.
#[expect(clippy::too_many_arguments, reason = "the ray, its segment, the cell and the gather cache")]
pub(crate) fn leaf_hit(
    f: &HeightField,
    edges: EdgeMode,
    o: DVec3,
    d: DVec3,
    ta: f64,
    tb: f64,
    cell: &Cell,
    last_patch: &mut Option<(i64, i64)>,
) -> (Option<f64>, u32) {
    let centre = |lo: f64, index: u32| match edges {
        EdgeMode::Wrap => lo + 0.5,
        EdgeMode::Clamp => f64::from(index) + 0.5,
    };
    let mut cuts = [tb, tb];
    for (k, (p0, dp, c)) in
        [(o.x, d.x, centre(cell.x0, cell.ix)), (o.y, d.y, centre(cell.y0, cell.iy))].into_iter().enumerate()
    {
        if dp != 0.0 {
            let tc = (c - p0) / dp;
            if tc > ta && tc < tb {
                cuts[k] = tc;
            }
        }
    }
    if cuts[1] < cuts[0] {
        cuts.swap(0, 1);
    }
    let mut gathers = 0;
    let mut start = ta;
    for end in [cuts[0], cuts[1], tb] {
        if end <= start && !(end == tb && start == ta) {
            continue;
        }
        let (hit, key) = patch_hit(f, edges, o, d, start, end);
        if *last_patch != Some(key) {
            *last_patch = Some(key);
            gathers += 1;
        }
        if let Some(th) = hit {
            return (Some(th), gathers);
        }
        start = end;
    }
    (None, gathers)
}

/// First `t` in `[ta, tb]` where the ray is at or below the one bilinear patch containing the
/// segment's midpoint.
fn patch_hit(f: &HeightField, edges: EdgeMode, o: DVec3, d: DVec3, ta: f64, tb: f64) -> (Option<f64>, (i64, i64)) {
    let mid = o + d * (0.5 * (ta + tb));
    // Patch between texel centres (i, j) and (i + 1, j + 1), centres at k + 0.5.
    let i = (mid.x - 0.5).floor();
    let j = (mid.y - 0.5).floor();
    // `as` saturates beyond the i64 range (clamped edges only: wrapped rays are reduced to their
    // tile), where the clamped surface is the border texel's whichever neighbour is read.
    let (ii, jj) = (i as i64, j as i64);
    let (ii1, jj1) = (ii.saturating_add(1), jj.saturating_add(1));
    let key = (ii, jj);
    let s00 = f64::from(f.depth_at(ii, jj, edges));
    let s10 = f64::from(f.depth_at(ii1, jj, edges));
    let s01 = f64::from(f.depth_at(ii, jj1, edges));
    let s11 = f64::from(f.depth_at(ii1, jj1, edges));
    // S(fx, fy) = a + b fx + c fy + e fx fy with fx = x - (i + 0.5), fy = y - (j + 0.5).
    let (a, b, c, e) = (s00, s10 - s00, s01 - s00, s00 - s10 - s01 + s11);
    let (fx0, fy0) = (o.x - (i + 0.5), o.y - (j + 0.5));
    // g(t) = z(t) - S(x(t), y(t)) = A t^2 + B t + C; the ray is at or below where g >= 0.
    let qa = -e * d.x * d.y;
    let qb = d.z - b * d.x - c * d.y - e * (fx0 * d.y + fy0 * d.x);
    let qc = o.z - (a + b * fx0 + c * fy0 + e * fx0 * fy0);
    let g = |t: f64| (qa * t + qb) * t + qc;
    if g(ta) >= 0.0 {
        return (Some(ta), key);
    }
    // Roots of g in (ta, tb], smallest first.
    let mut best: Option<f64> = None;
    let mut consider = |r: f64| {
        if r.is_finite() && r > ta && r <= tb && best.is_none_or(|b| r < b) {
            best = Some(r);
        }
    };
    let scale = qb.abs().max(qc.abs()).max(1e-300);
    if qa.abs() <= 1e-12 * scale {
        if qb != 0.0 {
            consider(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            // Numerically stable pair of roots.
            let q = -0.5 * (qb + qb.signum() * sq);
            if q != 0.0 {
                consider(q / qa);
                consider(qc / q);
            } else {
                consider(-qb / (2.0 * qa));
            }
        }
    }
    if let Some(r) = best {
        return (Some(r), key);
    }
    // No sign change found by the roots (a tangent touch lost to rounding): accept the end if
    // it is at or below the surface.
    (if g(tb) >= 0.0 { Some(tb) } else { None }, key)
}

mod plane_walk;

#[cfg(test)]
mod affine_bounds;
