//! A measurement, not part of the tracer: the exact walk with the plane bounds of
//! [`crate::planes::CellPlanes`] per pyramid cell, whose fetches docs/ACCURACY.md ("Affine
//! bounds per cell") reports.
//!
//! The ray's depth minus a cell's plane is linear in `t`, so two divisions bracket the hit
//! inside a cell: before the ray reaches `plane - shallower` nothing is hit, and once it
//! reaches `plane + deeper` it is under the surface. The walk ([`affine_first_hit`]) differs
//! from [`exact_first_hit`] in three places:
//! - it skips a cell the ray crosses above `plane - shallower` as well as one it crosses above
//!   the least depth;
//! - where the bracket is at most `span` texels long, it solves the patches in it at once,
//!   instead of descending;
//! - otherwise it descends from the bracket's start, straight to the level whose cells are as
//!   wide as the bracket (at most one level down when there is no bracket).
//!
//! Only the shallower width decides the hit: where the patches up to the bracket's end hold
//! none (a deeper width too small, or rounding), the walk goes on from there. Its hits are the
//! exact walk's; the fetches are counted as a GPU would read the data: one 16-byte texel per
//! cell visited above level 0 (least depth, plane and widths; its siblings are separate texels),
//! one gather per 2x2 block of level-0 least depths as in `exact`, and one gather per bilinear
//! patch. The walk can also read the plane only where the least depth does not skip the cell,
//! keeping `exact`'s sibling blocks at every level ([`Layout::PlaneOnDemand`]), or hold four
//! values per texel with no separate least depth ([`Layout::FourValues`]). Not modelled: the f32
//! arithmetic a GPU walk would add to the pad.

use glam::DVec3;

use super::*;
use crate::accuracy::ray_set;
use crate::planes::{CellPlane, CellPlanes};
use crate::procedural::{Pattern, generate};

/// The greatest depth of the surface over each cell, level by level (for [`Layout::FourValues`]):
/// at level 0 over the footprint's nine quarter corners, as the pyramid's least depth, then the
/// greatest of the children.
struct Maxima {
    levels: Vec<(u32, Vec<f32>)>,
}

impl Maxima {
    fn new(f: &HeightField, pyr: &MaxHeightPyramid, edges: EdgeMode) -> Self {
        let (w, h) = pyr.level_size(0);
        let base: Vec<f32> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                let d = |dx: i64, dy: i64| -f.depth_at(i64::from(x) + dx, i64::from(y) + dy, edges);
                -crate::pyramid::footprint_min(d)
            })
            .collect();
        let mut levels = vec![(w, base)];
        for level in 1..pyr.len() {
            let (nw, nh) = pyr.level_size(level);
            let (pw, ph) = pyr.level_size(level - 1);
            let prev = &levels[level - 1].1;
            let cells = (0..nh)
                .flat_map(|y| (0..nw).map(move |x| (x, y)))
                .map(|(x, y)| {
                    [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .into_iter()
                        .map(|(a, b)| (2 * x + a, 2 * y + b))
                        .filter(|&(a, b)| a < pw && b < ph)
                        .map(|(a, b)| prev[(b * pw + a) as usize])
                        .fold(0.0f32, f32::max)
                })
                .collect();
            levels.push((nw, cells));
        }
        Self { levels }
    }

    fn get(&self, level: usize, x: u32, y: u32) -> f64 {
        let (w, cells) = &self.levels[level];
        f64::from(cells[(y * w + x) as usize])
    }
}

/// A level plane at depth 0 with no widths.
const LEVEL: CellPlane = CellPlane { depth: 0.0, slope: [0.0, 0.0], shallower: 0.0, deeper: 0.0 };

/// What the walk reads: the planes, and the maxima for [`Layout::FourValues`].
struct Bounds {
    planes: CellPlanes,
    maxima: Maxima,
}

impl Bounds {
    fn new(surface: &Surface) -> Self {
        let (f, pyr, edges) = (surface.field(), surface.pyramid(), surface.edges());
        Self { planes: CellPlanes::new(f, pyr, edges), maxima: Maxima::new(f, pyr, edges) }
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
    bounds: &Bounds,
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
        let mut pl = if level > 0 { bounds.planes.cell(level, cell.ix, cell.iy) } else { LEVEL };
        if walk.layout == Layout::FourValues && level > 0 {
            let max = bounds.maxima.get(level, cell.ix, cell.iy);
            if max - bound <= f64::from(pl.shallower) + f64::from(pl.deeper) {
                pl = CellPlane { depth: bound as f32, deeper: (max - bound) as f32, ..LEVEL };
            } else {
                // The texel holds no least depth: only the plane bounds the cell.
                bound = 0.0;
            }
        }
        let (below, above) = (f64::from(pl.shallower), f64::from(pl.deeper));
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
            let g0 = o.z - pl.at([cx, cy], o.x, o.y);
            let g1 = d.z - (f64::from(pl.slope[0]) * d.x + f64::from(pl.slope[1]) * d.y);
            let g = |u: f64| g0 + g1 * u;
            // Before t_lo the least depth already keeps the ray above the surface.
            if g(t_lo).max(g(t_exit)) < -below {
                skip = true;
            } else {
                if g(t_lo) < -below {
                    t_lo = ((-below - g0) / g1).clamp(t_lo, t_exit);
                }
                let under = if g(t_lo) >= above {
                    Some(t_lo)
                } else if g(t_exit) >= above {
                    Some(((above - g0) / g1).clamp(t_lo, t_exit))
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
fn texel_rays(angle: f32, count: usize, seed: u64, size: f64, depth_scale: f32) -> Vec<(DVec3, DVec3)> {
    ray_set(angle, count, seed)
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
/// exact one (to 1e-5 texel: the two solve a patch from different starts, which moves the
/// root by rounding).
fn measure(surface: &Surface, bounds: &Bounds, rays: &[(DVec3, DVec3)], walks: &[Walk]) -> Vec<f64> {
    let mut sums = vec![0.0; walks.len() + 2];
    for &(o, d) in rays {
        let e = exact_first_hit(surface, o, d, 0.0, 1.0);
        sums[0] += f64::from(e.fetches);
        let tracer = super::plane_walk::planes_first_hit(surface, &bounds.planes, o, d, 0.0, 1.0);
        sums[walks.len() + 1] += f64::from(tracer.fetches);
        let apart = (tracer.t.unwrap_or(1.0) - e.t.unwrap_or(1.0)).abs() * d.x.hypot(d.y);
        assert!(apart < 1e-5, "ray {o} {d}: the plane walk's hit is {apart} texels from exact's");
        for (k, &walk) in walks.iter().enumerate() {
            let a = affine_first_hit(surface, bounds, walk, o, d, 0.0, 1.0);
            sums[k + 1] += f64::from(a.fetches);
            let apart = (a.t.unwrap_or(1.0) - e.t.unwrap_or(1.0)).abs() * d.x.hypot(d.y);
            assert!(apart < 1e-5, "ray {o} {d}: the affine walk's hit is {apart} texels from exact's");
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
            let bounds = Bounds::new(&surface);
            for angle in [45.0f32, 85.0] {
                let rays = texel_rays(angle, 150, 1, 64.0, 0.1);
                let means = measure(&surface, &bounds, &rays, &[PER_CELL, ON_DEMAND, FOUR_VALUES]);
                assert!(means.iter().all(|m| *m > 0.0), "{} {angle}: no fetches counted", pattern.name());
            }
        }
    }
}

/// The table of docs/ACCURACY.md, "Affine bounds per cell": `cargo test --release -p
/// pomkit-core --lib affine_bounds_fetch_table -- --ignored --nocapture` (`AFFINE_EDGES=clamp`
/// for clamped edges). The column "chosen per map" is the walk the renderers choose
/// ([`Surface::choose_plane_bounds`]), the last the tracer's plane walk.
#[test]
#[ignore = "a measurement for docs/ACCURACY.md, under 10 s in release"]
fn affine_bounds_fetch_table() {
    let edges =
        if std::env::var("AFFINE_EDGES").is_ok_and(|e| e == "clamp") { EdgeMode::Clamp } else { EdgeMode::Wrap };
    println!(
        "| map | angle | exact | plane on demand | plane per cell | four values | chosen per map | tracer's plane walk |"
    );
    println!("|---|--:|--:|--:|--:|--:|--:|--:|");
    for pattern in Pattern::ALL {
        let surface = Surface::new(generate(pattern, 512, 512), edges, 0.1);
        let bounds = Bounds::new(&surface);
        // The renderers' choice.
        let planes = surface.clone().choose_plane_bounds();
        for angle in [60.0f32, 75.0, 85.0] {
            let rays = texel_rays(angle, 2000, 1, 512.0, 0.1);
            let m = measure(&surface, &bounds, &rays, &[ON_DEMAND, PER_CELL, FOUR_VALUES]);
            let chosen = if planes { format!("{:.1} (planes)", m[2]) } else { format!("{:.1} (exact)", m[0]) };
            println!(
                "| {} | {angle}° | {:.1} | {:.1} | {:.1} | {:.1} | {chosen} | {:.1} |",
                pattern.name(),
                m[0],
                m[1],
                m[2],
                m[3],
                m[4]
            );
        }
    }
}
