//! The `cone` technique's walk: cone stepping on the surface's cone map, beside the exact
//! tracer whose cells and patch solver it shares. The maps themselves are built in
//! [`crate::cone`].

use glam::DVec3;

use super::{ExactResult, Surface, TraceParams, entered_cell, exact_step_bound, leaf_hit};
use crate::cone::bilinear;
use crate::heightfield::{EdgeMode, HeightField};

/// The `cone` technique: the first `t` in `[t0, t1]` where the ray `o + t d` (texel
/// coordinates and depth, going down: `d.z > 0`) is at or below the surface, by cone stepping on
/// `surface`'s cone map ([`Surface::cones`]).
///
/// Each step reads the cone of the footprint `C` the ray is in (one fetch) and
/// - above `C`'s top, advances by the longer of two safe moves: [`safe_step`](crate::cone::safe_step) to the cone's
///   boundary, and the stretch over `C` until the ray reaches the top or leaves `C` (the
///   surface over `C` is nowhere shallower than its top);
/// - at or below the top, solves the ray exactly against the bilinear patches it crosses in `C`
///   (one gather each, as `exact` does at its pyramid's level 0), then moves to the next
///   footprint.
///
/// With conservative cones ([`ConeMap::conservative`](crate::cone::ConeMap::conservative)) nothing is skipped that holds surface,
/// so the hit is the exact first intersection, as `exact`'s. A relaxed map (one read from an
/// image) may hold surface inside a cone: after each cone step one bilinear read says whether
/// the ray went under, and `binary_steps` halvings of that step find the crossing (Policarpo and
/// Oliveira's relaxed cone stepping).
///
/// # Termination
/// At most [`exact_step_bound`] steps for the ray's segment: each step either
/// ends the walk, crosses a texel boundary (a leaf step, or the column stretch to `C`'s edge),
/// or brings the ray to `C`'s top, after which the next step is a leaf step in `C`. So there are
/// at most two steps per boundary crossed; the bound counts each boundary twice already.
pub(crate) fn first_hit(surface: &Surface, o: DVec3, d: DVec3, t0: f64, t1: f64, p: &TraceParams) -> ExactResult {
    let cones = surface.cones();
    let f = surface.field();
    let pyr = surface.pyramid();
    let (w, h) = (i64::from(f.width()), i64::from(f.height()));
    let edges = surface.edges();
    let horizontal = d.x.hypot(d.y);
    let relaxed = cones.relaxed();
    let mut fetches = 0u32;
    let mut last_patch = None;
    let mut t = t0;
    let mut bracket = None;
    let max_steps = exact_step_bound(d, t0, t1, w, h, edges);
    for _ in 0..max_steps {
        if t >= t1 {
            break;
        }
        let Some((cell, _, t_exit)) = entered_cell(pyr, 0, o, d, t, t1, w, h, edges) else { break };
        let (top, ratio) = cones.cone_along(cell.ix, cell.iy, d.x, d.y);
        let (top, ratio) = (f64::from(top), f64::from(ratio));
        fetches = fetches.saturating_add(1);
        let z = o.z + d.z * t;
        if z < top {
            // Both moves keep the ray above every point of the surface they pass over.
            let rate = d.z + horizontal / ratio;
            let cone = if ratio > 0.0 && rate > 0.0 { (top - z) / rate } else { 0.0 };
            let column = ((top - o.z) / d.z).min(t_exit) - t;
            let next = (t + cone.max(column)).min(t1);
            if relaxed && cone > column {
                fetches = fetches.saturating_add(1);
                let q = o + d * next;
                if surface_depth(f, edges, q.x, q.y) <= q.z {
                    bracket = Some((t, next));
                    break;
                }
            }
            t = next;
            continue;
        }
        let (hit, gathers) = leaf_hit(f, edges, o, d, t, t_exit.min(t1), &cell, &mut last_patch);
        fetches = fetches.saturating_add(gathers);
        if hit.is_some() {
            return ExactResult { t: hit, fetches };
        }
        t = t_exit;
    }
    let Some((mut lo, mut hi)) = bracket else { return ExactResult { t: None, fetches } };
    for _ in 0..p.binary_steps {
        let mid = 0.5 * (lo + hi);
        let q = o + d * mid;
        fetches = fetches.saturating_add(1);
        if surface_depth(f, edges, q.x, q.y) <= q.z {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    ExactResult { t: Some(if p.binary_steps > 0 { 0.5 * (lo + hi) } else { hi }), fetches }
}

/// The bilinear surface of `f`'s texels at `(x, y)` in texel units (centres at half-integers).
fn surface_depth(f: &HeightField, edges: EdgeMode, x: f64, y: f64) -> f64 {
    bilinear(|i, j| f64::from(f.depth_at(i, j, edges)), x, y)
}
