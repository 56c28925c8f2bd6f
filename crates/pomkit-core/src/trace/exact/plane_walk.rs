//! The exact walk with plane bounds per pyramid cell ([`crate::planes::CellPlanes`]), for rays
//! going down: the same hits as [`exact_first_hit`]'s walk on the least depths alone, with fewer
//! fetches on relief that slopes across its cells (docs/ACCURACY.md, "Affine bounds per cell").
//!
//! The ray's depth minus a cell's plane is linear in `t`, so two divisions bracket the hit
//! inside the cell: nothing is hit before the ray reaches `plane - shallower`, and once it
//! reaches `plane + deeper` it is under the surface. The walk differs from the least-depth walk
//! in four places:
//! - it skips a cell the ray crosses above `plane - shallower` as well as one it crosses above
//!   the least depth;
//! - where the bracket is at most [`SOLVE_SPAN`] texels of travel long, it solves the bilinear
//!   patches from the bracket's start, footprint by footprint, up to the footprint holding the
//!   bracket's end, with no descent; where they hold no hit (rounding, or a deeper width too
//!   small) it goes on from there at the same level;
//! - otherwise it descends from the bracket's start straight to the level whose cells are as
//!   wide as the bracket (one level where there is no bracket);
//! - it starts [`START_UP`] levels above the least-depth walk, but no higher than
//!   [`START_CAP`].
//!
//! Only the shallower width decides the hit. Fetches are counted as the GPU's twin
//! (`pomkit_planes_first_hit` in the shader library) reads: one 16-byte texel per cell visited
//! above level 0 (least depth, plane and widths together), kept while the ray stays in the cell;
//! at level 0 one gather per 2x2 block of least depths, as the least-depth walk; one gather per
//! bilinear patch. What is held is tracked as the GPU does, one bit per level cleared by the
//! walls the ray crosses ([`levels_left`]), so the two count alike by construction.

use glam::DVec3;

use super::*;
use crate::planes::CellPlanes;

/// Levels above [`start_level`]'s choice the walk starts at: with plane bounds a cell is skipped
/// or bracketed more often, so coarser cells pay (docs/ACCURACY.md: starting at `exact`'s level
/// took waves at 60 degrees from 6.3 to 7.5 fetches per ray).
pub(crate) const START_UP: usize = 2;

/// The highest level the walk starts at: above it, cells are wide enough that a ray's bracket
/// in them is rarely short (no cap took cobblestones at 85 degrees from 14.2 to 15.3).
pub(crate) const START_CAP: usize = 5;

/// The longest bracket, in texels of horizontal travel, whose patches are solved at once instead
/// of descending (2 and 4 were within 3% of it on the built-in maps).
pub(crate) const SOLVE_SPAN: f64 = 3.0;

/// The first `t` in `[t0, t1]` at or below the bilinear surface along `o + t d` (texel units,
/// depth z; `d.z > 0`), by the walk the module docs describe, on `planes` built for `surface`'s
/// field, pyramid and edges.
///
/// # Termination
/// The loop runs at most [`exact_step_bound`] times, for the same reasons as the least-depth
/// walk's: a step advances past a wall of its cell, descends, or returns; a step that solves a
/// bracket crosses at least one texel wall (it solves whole footprints) or reaches `t1`, and
/// the solve's own loop is bounded by the walls crossed as well.
pub(crate) fn planes_first_hit(
    surface: &Surface,
    planes: &CellPlanes,
    o: DVec3,
    d: DVec3,
    t0: f64,
    t1: f64,
) -> ExactResult {
    debug_assert!(d.z > 0.0, "the plane walk traces rays going down");
    let pyr = surface.pyramid();
    let f = surface.field();
    let (w, h) = (i64::from(f.width()), i64::from(f.height()));
    let edges = surface.edges();
    let top = pyr.len() - 1;
    let travel = d.x.hypot(d.y);
    let max_steps = exact_step_bound(d, t0, t1, w, h, edges);
    let mut fetches = 0u32;
    let mut t = t0;
    let mut level = (start_level(d, t0, t1, top) + START_UP).min(START_CAP).min(top);
    // Bit l: at level 0, the 2x2 block of least depths holding the current cell is held; above,
    // the current cell's texel is.
    let mut seen = 0u64;
    let mut last_patch: Option<(i64, i64)> = None;
    for _ in 0..max_steps {
        if t > t1 {
            break;
        }
        let Some((cell, _, t_exit)) = entered_cell(pyr, level, o, d, t, t1, w, h, edges) else { break };
        let left = levels_left(&cell, level, o, d, t_exit, w, h);
        let bit = 1u64 << level.min(63);
        if seen & bit == 0 {
            seen |= bit;
            fetches = fetches.saturating_add(1);
        }
        let bound = f64::from(pyr.min_depth(level, cell.ix, cell.iy));
        let mut skip = o.z + d.z * t_exit < bound;
        // Before t_lo the least depth keeps the ray above the surface.
        let mut t_lo = t.max(((bound - o.z) / d.z).min(t_exit));
        let mut under: Option<f64> = None;
        if !skip && level > 0 && bound < 1.0 {
            let pl = planes.cell(level, cell.ix, cell.iy);
            let centre = plane_centre(&cell, level, w, h, edges);
            // g(u): the ray's depth minus the plane's, linear, formed at the ray's point at `t`
            // (inside the cell) as the GPU forms it in f32.
            let p = o + d * t;
            let g0 = p.z - pl.at(centre, p.x, p.y);
            let g1 = d.z - (f64::from(pl.slope[0]) * d.x + f64::from(pl.slope[1]) * d.y);
            let g = |u: f64| g0 + g1 * (u - t);
            let (below, above) = (f64::from(pl.shallower), f64::from(pl.deeper));
            let g_exit = g(t_exit);
            if g(t_lo).max(g_exit) < -below {
                skip = true;
            } else {
                // g rises here (it is below -below at t_lo and not at t_exit), so g1 > 0.
                if g(t_lo) < -below {
                    t_lo = (t + (-below - g0) / g1).clamp(t_lo, t_exit);
                }
                if g(t_lo) >= above {
                    under = Some(t_lo);
                } else if g_exit >= above {
                    under = Some((t + (above - g0) / g1).clamp(t_lo, t_exit));
                }
            }
        }
        if skip {
            if t_exit >= t1 {
                break;
            }
            seen = forget(seen, left);
            if level < top && left > level {
                level += 1;
            }
            t = t_exit;
            continue;
        }
        if bound >= 1.0 {
            // A flat floor, as in the least-depth walk.
            return ExactResult { t: Some(t.max((1.0 - o.z) / d.z).min(t_exit)), fetches };
        }
        if level > 0 {
            let span = under.map(|u| (u - t_lo) * travel);
            if let (Some(under), Some(span)) = (under, span)
                && span <= SOLVE_SPAN
            {
                // The hit is in [t_lo, under]: solve the footprints' patches up to the one
                // holding `under`, without reading their least depths.
                let mut u = t_lo;
                for _ in 0..max_steps {
                    let Some((leaf, _, leaf_exit)) = entered_cell(pyr, 0, o, d, u, t1, w, h, edges) else {
                        break;
                    };
                    let (hit, gathers) = leaf_hit(f, edges, o, d, u, leaf_exit, &leaf, &mut last_patch);
                    fetches = fetches.saturating_add(gathers);
                    if hit.is_some() {
                        return ExactResult { t: hit, fetches };
                    }
                    seen = forget(seen, levels_left(&leaf, 0, o, d, leaf_exit, w, h));
                    u = leaf_exit;
                    if leaf_exit >= under || leaf_exit >= t_exit || leaf_exit >= t1 {
                        break;
                    }
                }
                t = u;
                if t >= t_exit {
                    if t_exit >= t1 {
                        break;
                    }
                    if level < top && left > level {
                        level += 1;
                    }
                }
                // Else rounding left the hit past the bracket: the next step brackets again
                // from here, in the same cell.
                continue;
            }
            t = t_lo;
            let wide = span.map_or(level - 1, |s| s.max(1.0).log2().floor() as usize);
            level = (level - 1).min(wide);
            continue;
        }
        let (hit, gathers) = leaf_hit(f, edges, o, d, t, t_exit, &cell, &mut last_patch);
        fetches = fetches.saturating_add(gathers);
        if hit.is_some() {
            return ExactResult { t: hit, fetches };
        }
        if t_exit >= t1 {
            break;
        }
        seen = forget(seen, left);
        t = t_exit;
    }
    ExactResult { t: None, fetches }
}

/// `seen` without the bits of the levels whose cells the ray leaves when it crosses a wall of
/// levels up to `left` ([`levels_left`]): the cells of levels 1 to `left`, and the 2x2 blocks of
/// level 0 (a block is a level-1 cell). Crossing a wall of level 0 alone keeps everything.
fn forget(seen: u64, left: usize) -> u64 {
    match left {
        0 => seen,
        l if l >= 63 => 0,
        l => seen & !((2u64 << l) - 1),
    }
}

/// The highest level whose cell the ray leaves when it leaves `cell` of `level` at `t_exit`
/// (0 when it leaves no cell there, at the end of its segment): a wall at local texel index `k`
/// is a wall of level `l`'s cells where `2^l` divides `k`, and a tile's edges (`k = 0` or the
/// size) are walls of every level (32 stands for them). The crossed walls are those whose
/// crossing time, computed as [`exit_time`] computes it, is `t_exit` (the GPU's
/// `pomkit_levels_left`).
fn levels_left(cell: &Cell, level: usize, o: DVec3, d: DVec3, t_exit: f64, w: i64, h: i64) -> usize {
    let size = 1i64 << level.min(62);
    let axis = |index: u32, lo: f64, hi: f64, p0: f64, dp: f64, n: i64| -> usize {
        if dp == 0.0 {
            return 0;
        }
        let (wall, k) =
            if dp > 0.0 { (hi, ((i64::from(index) + 1) * size).min(n)) } else { (lo, i64::from(index) * size) };
        // A clamped border cell's outer wall is at infinity: never crossed.
        if !wall.is_finite() || (wall - p0) / dp != t_exit {
            return 0;
        }
        if k <= 0 || k >= n { 32 } else { k.trailing_zeros() as usize }
    };
    axis(cell.ix, cell.x0, cell.x1, o.x, d.x, w).max(axis(cell.iy, cell.y0, cell.y1, o.y, d.y, h))
}

/// The centre of `cell`'s texel range ([`CellPlanes::centre`]) in the ray's unbounded
/// coordinates: moved by the cell's tile where the edges wrap. A clamped border cell's plane is
/// level along its unbounded axis, where the centre does not matter.
fn plane_centre(cell: &Cell, level: usize, w: i64, h: i64, edges: EdgeMode) -> [f64; 2] {
    let size = 1i64 << level.min(62);
    let axis = |index: u32, lo: f64, n: i64| {
        let first = i64::from(index) * size;
        let centre = 0.5 * (first + ((i64::from(index) + 1) * size).min(n)) as f64;
        match edges {
            EdgeMode::Wrap => lo - first as f64 + centre,
            EdgeMode::Clamp => centre,
        }
    };
    [axis(cell.ix, cell.x0, w), axis(cell.iy, cell.y0, h)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accuracy::ray_set;
    use crate::procedural::{Pattern, generate};

    /// Mean fetches per ray of the least-depth walk and of the plane walk on `rays` at `angle`,
    /// asserting that every hit of the plane walk is the least-depth walk's (to 1e-5 texel: the
    /// two solve a patch from different starts, which moves the root by rounding).
    fn compare(pattern: Pattern, w: u32, h: u32, edges: EdgeMode, angle: f32, rays: usize) -> (f64, f64) {
        let plain = Surface::new(generate(pattern, w, h), edges, 0.1);
        let mut planes = plain.clone();
        planes.use_plane_bounds();
        let (mut a, mut b) = (0.0, 0.0);
        for ray in ray_set(angle, rays, 3) {
            let p = TraceParams::default();
            let (e, q) = (trace(&plain, &ray, Technique::Exact, &p), trace(&planes, &ray, Technique::Exact, &p));
            let apart = ((e.uv - q.uv) * glam::Vec2::new(w as f32, h as f32)).length();
            assert!(apart < 1e-3, "{} {edges:?} {angle} {ray:?}: {q:?} vs {e:?}", pattern.name());
            assert!((e.depth - q.depth).abs() < 1e-5, "{} {edges:?} {angle} {ray:?}: {q:?} vs {e:?}", pattern.name());
            a += f64::from(e.fetches);
            b += f64::from(q.fetches);
        }
        (a / rays as f64, b / rays as f64)
    }

    #[test]
    fn the_plane_walk_finds_the_least_depth_walks_hits() {
        // Smooth, flat-faced, steep and thin relief, a size that is no power of two, both edge
        // modes, head-on to grazing: a short shallower width, a wrong plane centre or a solve
        // that stops early moves hits here.
        for pattern in [Pattern::Waves, Pattern::Bricks, Pattern::Cobblestones, Pattern::Fur, Pattern::Spike] {
            for (w, h) in [(64, 64), (48, 40)] {
                for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
                    for angle in [0.0f32, 45.0, 75.0, 89.0] {
                        compare(pattern, w, h, edges, angle, 60);
                    }
                }
            }
        }
    }

    #[test]
    fn the_plane_walk_reads_fewer_fetches_where_the_relief_slopes() {
        // On waves the least depth of a cell is loose everywhere; docs/ACCURACY.md measures 6.3
        // fetches per ray against 11.5 at 60 degrees on 512x512. On fur, thin strands between
        // long empty runs, the blocks of four least depths read fewer.
        let (exact, planes) = compare(Pattern::Waves, 256, 256, EdgeMode::Wrap, 60.0, 400);
        assert!(planes < 0.75 * exact, "waves: {planes} fetches per ray against {exact}");
        let (exact, planes) = compare(Pattern::Fur, 256, 256, EdgeMode::Wrap, 75.0, 400);
        assert!(planes > exact, "fur: {planes} fetches per ray against {exact}");
    }
}

#[cfg(test)]
mod choice {
    use std::sync::Arc;

    use super::*;
    use crate::procedural::{Pattern, generate};

    #[test]
    fn the_choice_keeps_the_planes_where_they_read_fewer_fetches() {
        // docs/ACCURACY.md: fewer fetches with the planes on waves, bricks and cobblestones,
        // more on fur and grass, at every angle measured.
        for (pattern, pays) in
            [(Pattern::Waves, true), (Pattern::Bricks, true), (Pattern::Cobblestones, true), (Pattern::Fur, false)]
        {
            let mut s = Surface::new(generate(pattern, 256, 256), EdgeMode::Wrap, 0.1);
            assert_eq!(s.choose_plane_bounds(), pays, "{}", pattern.name());
            assert_eq!(s.plane_bounds().is_some(), pays, "{}", pattern.name());
            let field = Arc::new(s.field().clone());
            let cached = cached_plane_bounds(&field, EdgeMode::Wrap, 0.1);
            assert_eq!(cached.is_some(), pays, "{}", pattern.name());
            // The same field again, at this depth scale or another: the same bounds, not built
            // anew.
            if let Some(p) = cached {
                assert!(Arc::ptr_eq(&p, &cached_plane_bounds(&field, EdgeMode::Wrap, 0.1).expect("cached")));
                assert!(Arc::ptr_eq(&p, &cached_plane_bounds(&field, EdgeMode::Wrap, 0.12).expect("still pays")));
            }
        }
    }

    #[test]
    fn bounds_of_another_size_are_refused() {
        let mut small = Surface::new(generate(Pattern::Waves, 32, 32), EdgeMode::Wrap, 0.1);
        let mut other = Surface::new(generate(Pattern::Waves, 32, 16), EdgeMode::Wrap, 0.1);
        other.use_plane_bounds();
        let planes = other.plane_bounds().cloned().map(Arc::new);
        assert!(matches!(
            small.set_plane_bounds(planes),
            Err(crate::planes::PlaneBoundsError::Size { width: 32, height: 32 })
        ));
        assert!(small.plane_bounds().is_none());
    }
}
