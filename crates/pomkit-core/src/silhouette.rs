//! Silhouettes: tracing under a curved surface, so that rays which graze a curved mesh leave the
//! relief and the pixel shows what lies behind, as the real displaced surface would.
//!
//! Every parallax technique traces inside the polygon against the tangent plane at the pixel, so
//! the outline of a mesh stays the outline of the undisplaced mesh. Oliveira and Policarpo 2005
//! ("An Efficient Representation for Surface Details", docs/REFERENCES.md) bend the ray instead:
//! near a point the surface is approximated by a quadric, and the ray's depth is measured from
//! that curved surface rather than from the tangent plane. A ray that comes back out of the
//! relief without meeting it is discarded.
//!
//! # The model
//!
//! Per vertex, [`vertex_curvature`] estimates the second fundamental form `II` of the smooth
//! surface the mesh's normals describe, in the vertex's `(T, B)` basis, from how the normals of
//! its neighbours turn (`dN = II dP`, least squares over the one-ring). It stores `K = L * II`,
//! with `L` the world length of a UV unit ([`crate::mesh::uv_unit_length`]): a dimensionless
//! form, unchanged by uniform scaling of the object.
//!
//! A ray that travels world depth `D` below the tangent plane moves sideways by `D * w`, where
//! `w = (V.T, V.B) / -(V.N)`. The curved surface lies `0.5 * D^2 * w' II w` below the tangent
//! plane there, which in pomkit's depth units (`depth_scale * L` world units per unit) is
//! `c * z^2` with
//!
//! ```text
//! c = 0.5 * depth_scale * (w' K w)            (view_curvature)
//! ```
//!
//! So the ray's depth below the curved surface is `z - c z^2`: for `c > 0` (convex, seen from
//! outside) it climbs back to 0 at `z = 1 / c`, where it leaves the relief; for `c <= 0` it
//! only goes deeper faster. [`trace_curved`] finds the first point where the height field is at
//! or above that bent ray.
//!
//! # How each technique bends
//!
//! The marching techniques (steep, pom-classic, pom, relief) march the straight ray from depth 0
//! to `t_end`, the point where the bent ray reaches the floor (`z - c z^2 = 1`) or leaves
//! (`z = 1 / c`), comparing `z - c z^2` with the height field instead of `z`. Reaching the end
//! without a hit is a miss where the ray leaves. `exact` solves against the bent ray as a
//! polyline of up to 16 chords, each traced exactly by the pyramid walk (the chords lie inside
//! the parabola by at most `|c| dt^2 / 4`, kept under 0.001 of the depth range where 16 chords
//! suffice). `parallax` and `iterative` have no march to bend: their offset is kept, and the
//! pixel is discarded when the offset point lies beyond the ray's exit.
//!
//! On flat charts with clamped edges (a plane's border, a cube face), a ray that enters inside
//! the unit UV square and hits outside it has left the chart: discarded as well.

use std::collections::HashMap;

use glam::{DVec3, Vec2, Vec3, Vec4};

use crate::heightfield::EdgeMode;
use crate::mesh::{Mesh, handedness, orthonormal_tangent, uv_unit_length};
use crate::trace::{
    Hit, MIN_COS, Profile, Ray, Straight, Surface, Technique, TraceParams, entering, exact_first_hit, march,
    reduce_to_tile, unreduce, uv_per_depth,
};

/// The largest `|c|` [`trace_curved`] uses; larger values (and infinities) are clamped to it.
/// At `c = 1e6` a ray leaves the relief after a millionth of its depth range.
pub const MAX_CURVATURE: f32 = 1e6;

/// The fewest distinct neighbours a vertex needs for [`vertex_curvature`] to fit a curvature;
/// with fewer (a lone triangle's corners) the vertex is flat.
pub const MIN_NEIGHBOURS: usize = 3;

/// The most chords `exact` bends its ray into.
const MAX_CHORDS: u32 = 16;

/// The chord sag (in depth units) `exact` aims for.
const CHORD_SAG: f64 = 1e-3;

/// A view trace under a curved surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurvedHit {
    /// The hit: its UV, its depth below the curved surface (in `[0, 1]`; what shading and
    /// self-shadows use) and the fetches made.
    pub hit: Hit,
    /// How deep the hit lies along the straight view ray, below the tangent plane at the entry
    /// point, in depth units: what pixel depth offset moves the depth by. Equal to
    /// `hit.depth` where the surface is flat; may exceed 1 under a concave surface.
    pub ray_depth: f32,
    /// The ray left the relief without meeting it (out through the curved surface, or out of
    /// a clamped chart): the pixel shows what lies behind it.
    pub left: bool,
}

/// The straight ray's march bent by curvature `c`: depth below the curved surface
/// `t - c t^2` at straight depth `t`, marched from 0 to `t_end`.
#[derive(Clone, Copy, Debug)]
struct Bend {
    c: f32,
    /// `c * t_end^2`.
    k: f32,
    t_end: f32,
    exits: bool,
}

impl Bend {
    fn new(c: f32) -> Self {
        let c = if c.is_finite() { c.clamp(-MAX_CURVATURE, MAX_CURVATURE) } else { 0.0 };
        if 4.0 * c <= 1.0 {
            // The bent ray reaches the floor: t - c t^2 = 1, the smaller root, written without
            // cancellation (c = 0 gives exactly 1).
            let t_end = 2.0 / (1.0 + (1.0 - 4.0 * c).sqrt());
            Self { c, k: c * t_end * t_end, t_end, exits: false }
        } else {
            // The bent ray turns back above depth 1/4c < 1 and leaves at t = 1/c.
            let t_end = 1.0 / c;
            Self { c, k: t_end, t_end, exits: true }
        }
    }

    /// Depth below the curved surface at straight depth `t`.
    fn relative(&self, t: f32) -> f32 {
        t - self.c * t * t
    }
}

impl Profile for Bend {
    #[inline]
    fn depth(&self, surface: &Surface, uv: Vec2, tau: f32, lod: f32) -> f32 {
        // d <= t - c t^2 with t = t_end tau, divided by t_end: compared with tau.
        (surface.depth(uv, lod) + self.k * tau * tau) / self.t_end
    }
    #[inline]
    fn extent(&self) -> f32 {
        self.t_end
    }
    #[inline]
    fn exits(&self) -> bool {
        self.exits
    }
}

/// Traces `ray` into `surface` with `technique` under a surface of curvature `curvature` along
/// the ray ([`view_curvature`]; 0 is the flat tangent plane, where the hit equals
/// [`crate::trace()`]'s).
///
/// Parameters are sanitized as [`crate::trace()`] does; a non-finite curvature counts as 0 and
/// larger magnitudes than [`MAX_CURVATURE`] are clamped. Every loop is bounded as in
/// [`crate::trace()`] (`exact` walks at most 16 chords, each within its own bound).
#[must_use]
pub fn trace_curved(
    surface: &Surface,
    ray: &Ray,
    technique: Technique,
    params: &TraceParams,
    curvature: f32,
) -> CurvedHit {
    let uv0 = if ray.uv.is_finite() { ray.uv } else { Vec2::ZERO };
    let none = CurvedHit { hit: Hit { uv: uv0, depth: 0.0, fetches: 0 }, ray_depth: 0.0, left: false };
    let Some(dir) = entering(ray.dir) else { return none };
    if !technique.displaces() {
        return none;
    }
    let p = params.sanitized();
    let bend = Bend::new(curvature);
    let (reduced, tile) = reduce_to_tile(uv0, surface.edges());
    let (uv, t, fetches, found) = match technique {
        Technique::Parallax | Technique::Iterative => {
            let h = march(surface, reduced, dir, technique, &p, &Straight);
            (h.uv, h.depth, h.fetches, bend.relative(h.depth) >= 0.0)
        }
        Technique::Cone if bend.c == 0.0 => {
            let h = march(surface, reduced, dir, technique, &p, &Straight);
            (h.uv, h.depth, h.fetches, true)
        }
        // A cone map holds for the straight ray only: a bent `cone` ray is walked as `exact`'s
        // (the same hits: both are exact).
        Technique::Exact | Technique::Cone => exact_curved(surface, reduced, dir, &bend),
        _ => {
            let h = march(surface, reduced, dir, technique, &p, &bend);
            (h.uv, h.depth * bend.t_end, h.fetches, !(bend.exits && h.depth >= 1.0))
        }
    };
    let inside = |q: Vec2| (0.0..=1.0).contains(&q.x) && (0.0..=1.0).contains(&q.y);
    let off_chart = surface.edges() == EdgeMode::Clamp && inside(uv0) && !inside(uv);
    let depth = bend.relative(t);
    CurvedHit {
        hit: Hit {
            uv: unreduce(uv, tile),
            depth: if depth.is_finite() { depth.clamp(0.0, 1.0) } else { 0.0 },
            fetches,
        },
        ray_depth: if t.is_finite() { t.max(0.0) } else { 0.0 },
        left: !found || off_chart,
    }
}

/// `exact` along the bent ray: the parabola `z = t - c t^2` as a polyline of chords, each solved
/// exactly against the bilinear surface by the pyramid walk. Returns the hit's UV, its straight
/// depth, the fetches and whether it was found before the ray left.
fn exact_curved(surface: &Surface, uv0: Vec2, dir: Vec3, bend: &Bend) -> (Vec2, f32, u32, bool) {
    let s = uv_per_depth(dir, surface.depth_scale());
    let f = surface.field();
    let (w, h) = (f64::from(f.width()), f64::from(f.height()));
    let (ox, oy) = (f64::from(uv0.x) * w, f64::from(uv0.y) * h);
    let (dx, dy) = (f64::from(s.x) * w, f64::from(s.y) * h);
    let c = f64::from(bend.c);
    let t_end = f64::from(bend.t_end);
    // A chord of length dt lies inside the parabola by at most |c| dt^2 / 4.
    let chords = (c.abs() * t_end * t_end / (4.0 * CHORD_SAG)).sqrt().ceil().clamp(1.0, f64::from(MAX_CHORDS)) as u32;
    let z = |t: f64| t - c * t * t;
    let mut fetches = 0u32;
    for j in 0..chords {
        let ta = t_end * f64::from(j) / f64::from(chords);
        let tb = if j + 1 == chords { t_end } else { t_end * f64::from(j + 1) / f64::from(chords) };
        let (za, zb) = (z(ta), z(tb));
        let slope = (zb - za) / (tb - ta);
        let o = DVec3::new(ox, oy, za - slope * ta);
        let d = DVec3::new(dx, dy, slope);
        let r = exact_first_hit(surface, o, d, ta, tb);
        fetches = fetches.saturating_add(r.fetches);
        if let Some(t) = r.t {
            // The hit's UV as `exact` computes it without curvature (in f64).
            let uv = Vec2::new(((ox + dx * t) / w) as f32, ((oy + dy * t) / h) as f32);
            return (uv, t as f32, fetches, true);
        }
    }
    (uv0 + s * bend.t_end, bend.t_end, fetches, !bend.exits)
}

/// The curvature `c` of [`trace_curved`] for a view ray of world direction of travel
/// `view_dir_world` entering at a point with unit-ish `normal`, glTF `tangent` and the
/// interpolated per-vertex form `curvature` = `K = L * II` of [`vertex_curvature`]:
/// `c = 0.5 * depth_scale * (w' K w)` with `w = (V.T, V.B) / -(V.N)`.
///
/// `-(V.N)` is taken at least [`MIN_COS`] (the tracers steepen flatter rays to it). Rays that do
/// not enter, and non-finite input, give 0.
#[must_use]
pub fn view_curvature(view_dir_world: Vec3, normal: Vec3, tangent: Vec4, curvature: Vec3, depth_scale: f32) -> f32 {
    let (Some(v), Some(n)) = (view_dir_world.try_normalize(), normal.try_normalize()) else {
        return 0.0;
    };
    if !(tangent.is_finite() && curvature.is_finite() && depth_scale.is_finite()) {
        return 0.0;
    }
    let t = orthonormal_tangent(tangent.truncate(), n);
    let b = handedness(tangent.w) * n.cross(t);
    let vn = -v.dot(n);
    if vn <= 0.0 {
        return 0.0;
    }
    let vn = vn.max(MIN_COS);
    let (wt, wb) = (v.dot(t) / vn, v.dot(b) / vn);
    let q = curvature.x * wt * wt + 2.0 * curvature.y * wt * wb + curvature.z * wb * wb;
    let c = 0.5 * depth_scale * q;
    if c.is_finite() { c.clamp(-MAX_CURVATURE, MAX_CURVATURE) } else { 0.0 }
}

/// Per vertex, the second fundamental form of the surface the mesh's normals describe, in the
/// vertex's `(T, B)` basis (`B = w * cross(N, T)`), times the world length `L` of a UV unit:
/// `(K_tt, K_tb, K_bb)`. Positive where the surface curves away from its normal (a sphere seen
/// from outside: `L / radius` on the diagonal).
///
/// Fitted by least squares to the one-ring: for each neighbour, the change of normal projected
/// on the tangent plane `(dN.T, dN.B)` against the step `(dP.T, dP.B)` (Weingarten:
/// `dN = II dP`). Exact for spheres and cylinders whatever the tessellation. A vertex with
/// fewer than [`MIN_NEIGHBOURS`] distinct neighbours, an ill-conditioned fit (neighbours on a
/// line) or a non-finite result is flat: `(0, 0, 0)`, so a lone triangle or degenerate normals
/// give the flat-chart behaviour. A mesh whose fields are inconsistent is repaired first, as
/// [`Mesh`]'s methods do.
#[must_use]
pub fn vertex_curvature(mesh: &Mesh) -> Vec<Vec3> {
    let m = mesh.repaired();
    let n = m.positions.len();
    let mut ring: Vec<Vec<u32>> = vec![Vec::new(); n];
    for tri in m.indices.chunks_exact(3) {
        for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
            if a != b {
                ring[a as usize].push(b);
                ring[b as usize].push(a);
            }
        }
    }
    // Seams split a smooth surface into vertices at one position with one normal: each sees
    // only its side of the ring. Weld them (same position, normals within about 2.5 degrees)
    // so that every copy fits over the whole ring; hard edges (normals that differ) stay apart.
    // Positions are compared on a grid of 1e-6 of the mesh's extent (seams computed from
    // angles differ in the last bits: sin(-pi) and sin(pi)).
    let (lo, hi) = m.bounds();
    let cell = f64::from((hi - lo).max_element()).max(1e-30) * 1e-6;
    let key = |v: usize| (m.positions[v].as_dvec3() / cell).round().to_array().map(|x| x as i64);
    let mut at_position: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for v in 0..n {
        at_position.entry(key(v)).or_default().push(v as u32);
    }
    (0..n)
        .map(|i| {
            let twins: Vec<u32> = at_position[&key(i)]
                .iter()
                .copied()
                .filter(|&j| m.normals[j as usize].dot(m.normals[i]) > 0.999)
                .collect();
            let mut neighbours: Vec<u32> = twins.iter().flat_map(|&j| ring[j as usize].iter().copied()).collect();
            // One neighbour per position (its copies repeat the same equations).
            neighbours.retain(|&j| key(j as usize) != key(i));
            neighbours.sort_unstable_by_key(|&j| key(j as usize));
            neighbours.dedup_by_key(|j| key(*j as usize));
            fit(&m, i, &neighbours)
        })
        .collect()
}

/// The least-squares `L * II` at vertex `i` from its distinct `neighbours`.
fn fit(m: &Mesh, i: usize, neighbours: &[u32]) -> Vec3 {
    let p = m.positions[i].as_dvec3();
    let Some(nrm) = m.normals[i].try_normalize() else { return Vec3::ZERO };
    let t = orthonormal_tangent(m.tangents[i].truncate(), nrm);
    let b = handedness(m.tangents[i].w) * nrm.cross(t);
    let (nrm, t, b) = (nrm.as_dvec3(), t.as_dvec3(), b.as_dvec3());
    let mut used = 0usize;
    // Normal equations of  a = e x + f y,  b = f x + g y  over the neighbours.
    let (mut sxx, mut sxy, mut syy) = (0.0f64, 0.0f64, 0.0f64);
    let (mut sxa, mut syb, mut sya_xb) = (0.0f64, 0.0f64, 0.0f64);
    for &j in neighbours {
        let dp = m.positions[j as usize].as_dvec3() - p;
        let Some(nj) = m.normals[j as usize].try_normalize() else { continue };
        let dn = nj.as_dvec3() - nrm;
        let (x, y) = (dp.dot(t), dp.dot(b));
        if x * x + y * y <= 1e-24 * dp.length_squared().max(1e-300) || !(x.is_finite() && y.is_finite()) {
            continue;
        }
        let (a, bb) = (dn.dot(t), dn.dot(b));
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sxa += x * a;
        syb += y * bb;
        sya_xb += y * a + x * bb;
        used += 1;
    }
    if used < MIN_NEIGHBOURS {
        return Vec3::ZERO;
    }
    // M = [[sxx, sxy, 0], [sxy, sxx + syy, sxy], [0, sxy, syy]], rhs = [sxa, sya_xb, syb].
    let mat =
        glam::DMat3::from_cols(DVec3::new(sxx, sxy, 0.0), DVec3::new(sxy, sxx + syy, sxy), DVec3::new(0.0, sxy, syy));
    let scale = (sxx + syy).powi(3);
    let det = mat.determinant();
    // Neighbours on a line (or NaN sums) leave the form undetermined.
    if det.is_nan() || det <= 1e-9 * scale {
        return Vec3::ZERO;
    }
    let form = mat.inverse() * DVec3::new(sxa, sya_xb, syb);
    let k = form * f64::from(uv_unit_length(m.uv_scale[i]));
    if k.is_finite() { k.as_vec3() } else { Vec3::ZERO }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::HeightField;
    use crate::procedural::{Pattern, generate};
    use crate::trace::trace;

    fn constant(depth: f32, edges: EdgeMode) -> Surface {
        let field = HeightField::constant(8, 8, depth);
        Surface::new(field, edges, 0.1)
    }

    #[test]
    fn a_sphere_has_curvature_l_over_r_in_every_direction() {
        let r = 2.0;
        let mesh = Mesh::uv_sphere(r, 24, 48);
        let k = vertex_curvature(&mesh);
        let mut checked = 0;
        for (v, (kv, p)) in k.iter().zip(&mesh.positions).enumerate() {
            // Away from the poles, where the UV mapping degenerates.
            if p.y.abs() > 0.8 * r {
                continue;
            }
            let l = uv_unit_length(mesh.uv_scale[v]);
            let want = l / r;
            assert!((kv.x - want).abs() < 0.03 * want, "vertex {v}: K_tt {} vs {want}", kv.x);
            assert!((kv.z - want).abs() < 0.03 * want, "vertex {v}: K_bb {} vs {want}", kv.z);
            assert!(kv.y.abs() < 0.03 * want, "vertex {v}: K_tb {}", kv.y);
            checked += 1;
        }
        assert!(checked > 500, "{checked} vertices checked");
    }

    #[test]
    fn a_cylinder_curves_around_and_not_along() {
        let r = 1.5;
        let mesh = Mesh::cylinder(r, 3.0, 40);
        let k = vertex_curvature(&mesh);
        let mut checked = 0;
        for (v, kv) in k.iter().enumerate() {
            let n = mesh.normals[v];
            if n.y.abs() > 0.1 {
                continue; // caps
            }
            // T runs around the cylinder (u), B along its axis.
            let l = uv_unit_length(mesh.uv_scale[v]);
            assert!((kv.x - l / r).abs() < 0.02 * l / r, "vertex {v}: K_tt {} vs {}", kv.x, l / r);
            assert!(kv.y.abs() < 1e-3 * l / r && kv.z.abs() < 1e-3 * l / r, "vertex {v}: {kv}");
            checked += 1;
        }
        assert!(checked >= 40, "{checked} side vertices checked");
    }

    #[test]
    fn flat_meshes_a_lone_triangle_and_degenerate_normals_are_flat() {
        for k in vertex_curvature(&Mesh::plane(Vec2::splat(2.0), 8)) {
            assert!(k.abs().max_element() < 1e-6, "plane: {k}");
        }
        for k in vertex_curvature(&Mesh::cube(1.0)) {
            assert!(k.abs().max_element() < 1e-6, "cube: {k}");
        }
        // One triangle whose normals disagree wildly: too few neighbours to fit, so flat.
        let mut tri = Mesh::plane(Vec2::ONE, 1);
        tri.indices.truncate(3);
        tri.normals = vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::Z];
        assert!(vertex_curvature(&tri).iter().all(|k| *k == Vec3::ZERO));
        // NaN and zero normals (a mesh edited into an inconsistent state) never give NaN.
        let mut bad = Mesh::uv_sphere(1.0, 6, 8);
        for (i, n) in bad.normals.iter_mut().enumerate() {
            *n = if i % 2 == 0 { Vec3::NAN } else { Vec3::ZERO };
        }
        assert!(vertex_curvature(&bad).iter().all(|k| k.is_finite()));
    }

    #[test]
    fn view_curvature_is_half_depth_scale_times_the_form_along_the_lateral_travel() {
        let (n, t) = (Vec3::Z, Vec4::new(1.0, 0.0, 0.0, 1.0));
        // 45 degrees along T: w = (1, 0).
        let v = Vec3::new(1.0, 0.0, -1.0);
        let c = view_curvature(v, n, t, Vec3::new(2.0, 0.5, 7.0), 0.1);
        assert!((c - 0.5 * 0.1 * 2.0).abs() < 1e-6, "{c}");
        // Along B (B = cross(N, T) = +Y): the K_bb entry.
        let c = view_curvature(Vec3::new(0.0, 1.0, -1.0), n, t, Vec3::new(2.0, 0.5, 7.0), 0.1);
        assert!((c - 0.5 * 0.1 * 7.0).abs() < 1e-6, "{c}");
        // Head-on: no lateral travel. Leaving rays and NaN: 0.
        assert_eq!(view_curvature(-Vec3::Z, n, t, Vec3::ONE, 0.1), 0.0);
        assert_eq!(view_curvature(Vec3::Z, n, t, Vec3::ONE, 0.1), 0.0);
        assert_eq!(view_curvature(Vec3::NAN, n, t, Vec3::ONE, 0.1), 0.0);
    }

    #[test]
    fn without_curvature_every_technique_traces_as_on_the_plane() {
        let field = generate(Pattern::Cobblestones, 64, 64);
        let surface = Surface::new(field, EdgeMode::Wrap, 0.08);
        let p = TraceParams { refine: 2, ..Default::default() };
        for technique in Technique::ALL {
            for k in 0..40 {
                let a = k as f32 * 0.37;
                let ray = Ray::new(Vec2::new(0.1 * k as f32, 0.03 * k as f32), Vec3::new(a.cos(), a.sin(), -0.4));
                let flat = trace(&surface, &ray, technique, &p);
                let curved = trace_curved(&surface, &ray, technique, &p, 0.0);
                assert_eq!(curved.hit, flat, "{technique} ray {k}");
                assert_eq!(curved.ray_depth, flat.depth, "{technique} ray {k}");
                assert!(!curved.left);
            }
        }
    }

    /// On a field of constant depth `d0` the bent ray `t - c t^2` meets it at
    /// `t = (1 - sqrt(1 - 4 c d0)) / 2c` if `4 c d0 <= 1`, and otherwise leaves.
    #[test]
    fn a_constant_field_is_met_or_left_where_the_parabola_says() {
        let d0 = 0.5;
        let surface = constant(d0, EdgeMode::Wrap);
        let p = TraceParams { samples: 64, min_samples: 64, max_samples: 64, ..Default::default() };
        let ray = Ray::new(Vec2::new(0.3, 0.6), Vec3::new(0.8, 0.1, -0.3));
        for c in [-3.0f32, -0.5, 0.0, 0.2, 0.45, 0.49, 0.51, 1.0, 4.0, 100.0] {
            let want = if 4.0 * c * d0 <= 1.0 {
                Some(if c == 0.0 { d0 } else { (1.0 - (1.0 - 4.0 * c * d0).sqrt()) / (2.0 * c) })
            } else {
                None
            };
            for technique in
                [Technique::Steep, Technique::Pom, Technique::Relief, Technique::PomClassic, Technique::Exact]
            {
                let r = trace_curved(&surface, &ray, technique, &p, c);
                // Steep stops on the first plane below; the others interpolate or solve.
                let tolerance = match technique {
                    Technique::Steep => 2.0 / 64.0,
                    Technique::PomClassic => 1.0 / 8.0,
                    // The chords' sag over the slope at which the bent ray meets the field.
                    Technique::Exact => 1e-2,
                    _ => 2e-3,
                };
                match want {
                    Some(t) => {
                        assert!(!r.left, "{technique} c {c}: left, expected a hit at {t}");
                        assert!(
                            (r.ray_depth - t).abs() <= tolerance * t.max(1.0),
                            "{technique} c {c}: {} vs {t}",
                            r.ray_depth
                        );
                        if technique != Technique::PomClassic && technique != Technique::Steep {
                            assert!((r.hit.depth - d0).abs() < 3e-3, "{technique} c {c}: depth {}", r.hit.depth);
                        }
                    }
                    None => assert!(r.left, "{technique} c {c}: hit at {} but the ray leaves", r.ray_depth),
                }
            }
        }
    }

    #[test]
    fn a_ray_leaving_a_clamped_chart_is_discarded_and_one_inside_is_kept() {
        let surface = constant(0.5, EdgeMode::Clamp);
        let p = TraceParams::default();
        // Depth 0.5 lies 0.05 * 0.5 / 0.3 * 0.95 = 0.08 UV along +u: out of the chart from
        // u = 0.95, inside from u = 0.5.
        let dir = Vec3::new(0.95, 0.0, -0.3);
        for technique in [Technique::Parallax, Technique::Pom, Technique::Exact] {
            assert!(trace_curved(&surface, &Ray::new(Vec2::new(0.97, 0.5), dir), technique, &p, 0.0).left);
            assert!(!trace_curved(&surface, &Ray::new(Vec2::new(0.5, 0.5), dir), technique, &p, 0.0).left);
        }
    }

    #[test]
    fn huge_and_non_finite_curvatures_give_finite_results() {
        let field = generate(Pattern::Bricks, 32, 32);
        let surface = Surface::new(field, EdgeMode::Wrap, 0.1);
        let ray = Ray::new(Vec2::new(0.2, 0.2), Vec3::new(0.7, 0.2, -0.2));
        for c in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, f32::MIN_POSITIVE] {
            for technique in Technique::ALL {
                let r = trace_curved(&surface, &ray, technique, &TraceParams::default(), c);
                assert!(r.hit.uv.is_finite() && r.hit.depth.is_finite() && r.ray_depth.is_finite(), "{technique} {c}");
                assert!((0.0..=1.0).contains(&r.hit.depth));
            }
        }
    }
}
