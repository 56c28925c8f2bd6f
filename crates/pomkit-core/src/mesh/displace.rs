//! Truly displaced geometry: [`Mesh::displaced`] subdivides a mesh to the texel size and moves
//! each vertex along its normal by the height field's depth (the `displaced` ground truth).

use std::collections::HashMap;

use glam::{DVec2, DVec3, Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::*;
use crate::heightfield::{EdgeMode, HeightField};
use crate::memory::MemoryError;

impl Mesh {
    /// True geometry for the `displaced` technique: every triangle subdivided finely and each
    /// vertex moved into the surface by the height field, so that rasterizing it shows what
    /// parallax mapping approximates (Tatarchuk 2006's experiment of 1,100 against 1.5 million
    /// polygons).
    ///
    /// # Subdivision
    ///
    /// Each edge of the mesh is split into `n_e = ceil(texels / max_edge_texels)` equal parts,
    /// where `texels` is the edge's length in UV times the field's size in texels, and each
    /// triangle is subdivided uniformly (an `n x n` barycentric grid of `n^2` triangles) with
    /// `n` the largest of its three edges' `n_e`, so that the grid's edges span at most
    /// `max_edge_texels` texels. Where an edge has fewer parts than its triangle, the grid's
    /// vertices on that edge snap to the nearest of the edge's own points (degenerate triangles
    /// are dropped; a few zero-area triangles may remain, which after displacement fill what
    /// would have been T-junction cracks; the triangles along such an edge can be up to 1.5
    /// times as long). Vertices on an edge are computed from the edge's two
    /// end vertices only, so triangles that share the edge (the same two vertex indices) share
    /// them: the output is as watertight as the input. (Across UV seams, where vertices are
    /// duplicated, the two sides are displaced independently, as a GPU would.)
    ///
    /// The output stays below [`MAX_DISPLACED_TRIANGLES`]: when the requested subdivision would
    /// exceed it, `max_edge_texels` is raised until it fits (a mesh that has more triangles than
    /// that to begin with is not subdivided). `max_edge_texels` is clamped to at least
    /// [`MIN_EDGE_TEXELS`] (NaN means 1 texel); 1 texel already reproduces the bilinear surface
    /// closely, and the triangle count grows with the inverse square of it.
    ///
    /// # Displacement
    ///
    /// Positions, normals, UVs, tangents and `uv_scale` are interpolated linearly (normals and
    /// tangents renormalized); then each vertex moves along `-N` (its interpolated normal) by
    /// `depth * depth_scale * L` world units, where `depth = field.sample_bilinear(uv, edges)`
    /// (0 = surface, 1 = deepest) and `L` = [`uv_unit_length`] of its `uv_scale`. The normals
    /// of the result are recomputed from its geometry ([`compute_vertex_normals`]); tangents
    /// are the interpolated ones made perpendicular to the new normals; `uv_scale` stays that
    /// of the undisplaced surface (it is what converts `depth_scale` to world units).
    ///
    /// A `depth_scale` that is NaN, infinite or not positive displaces nothing. Triangles that
    /// use one vertex twice are dropped.
    ///
    /// Like any allocation, this aborts the process when memory runs out; renderers use
    /// [`Mesh::try_displaced_for_shading`], which returns an error instead, after checking
    /// [`Mesh::displaced_bounds`] against the memory budget.
    #[must_use]
    pub fn displaced(&self, field: &HeightField, edges: EdgeMode, depth_scale: f32, max_edge_texels: f32) -> Mesh {
        self.displaced_capped(field, edges, depth_scale, max_edge_texels, MAX_DISPLACED_TRIANGLES, true)
            .unwrap_or_else(|_| std::alloc::handle_alloc_error(std::alloc::Layout::new::<Vec3>()))
    }

    /// As [`Mesh::displaced`], but the normals and tangents stay those of the *undisplaced*
    /// surface (interpolated), only the positions move. This is the renderers' `displaced`
    /// reference: it is shaded with the normal map like every parallax technique, so the bumps
    /// count once and the pictures differ only where the techniques sample.
    #[must_use]
    pub fn displaced_for_shading(
        &self,
        field: &HeightField,
        edges: EdgeMode,
        depth_scale: f32,
        max_edge_texels: f32,
    ) -> Mesh {
        self.displaced_capped(field, edges, depth_scale, max_edge_texels, MAX_DISPLACED_TRIANGLES, false)
            .unwrap_or_else(|_| std::alloc::handle_alloc_error(std::alloc::Layout::new::<Vec3>()))
    }

    /// [`Mesh::displaced_for_shading`], with the output's buffers allocated fallibly.
    ///
    /// # Errors
    /// [`MemoryError::Allocation`] when the subdivided mesh cannot be allocated.
    pub fn try_displaced_for_shading(
        &self,
        field: &HeightField,
        edges: EdgeMode,
        depth_scale: f32,
        max_edge_texels: f32,
    ) -> Result<Mesh, MemoryError> {
        self.displaced_capped(field, edges, depth_scale, max_edge_texels, MAX_DISPLACED_TRIANGLES, false)
    }

    /// Upper bounds on the triangles and vertices that [`Mesh::displaced`] (and
    /// [`Mesh::displaced_for_shading`]) make of this mesh for a `field_width x field_height`
    /// height field, computed without building anything: every triangle becomes at most `n^2`
    /// triangles and adds at most `n^2` vertices, `n` being the most parts of its three edges,
    /// and the total is held below [`MAX_DISPLACED_TRIANGLES`] as `displaced` does.
    #[must_use]
    pub fn displaced_bounds(&self, field_width: u32, field_height: u32, max_edge_texels: f32) -> (u64, u64) {
        let max_edge = f64::from(if max_edge_texels.is_nan() { 1.0 } else { max_edge_texels.max(MIN_EDGE_TEXELS) });
        let texels = DVec2::new(f64::from(field_width), f64::from(field_height));
        let n_vertices = self.positions.len();
        let uv = |i: u32| self.uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO).as_dvec2();
        let mut sum = 0u64;
        let mut input = 0u64;
        for t in self.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= n_vertices) {
                continue;
            }
            input += 1;
            let parts = |p: u32, q: u32| {
                let l = ((uv(q) - uv(p)) * texels).length();
                if l.is_finite() { (l / max_edge).ceil().clamp(1.0, f64::from(MAX_EDGE_PARTS)) as u64 } else { 1 }
            };
            let n = parts(t[0], t[1]).max(parts(t[0], t[2])).max(parts(t[1], t[2]));
            sum = sum.saturating_add(n * n);
        }
        let tris = if sum <= MAX_DISPLACED_TRIANGLES { sum } else { MAX_DISPLACED_TRIANGLES.max(input) };
        (tris, n_vertices as u64 + tris)
    }

    /// Bytes of a mesh of `vertices` vertices and `triangles` triangles (positions, normals,
    /// UVs, tangents, `uv_scale` and indices).
    #[must_use]
    pub fn bytes_for(vertices: u64, triangles: u64) -> u64 {
        let per_vertex =
            std::mem::size_of::<Vec3>() * 2 + std::mem::size_of::<Vec2>() * 2 + std::mem::size_of::<Vec4>();
        vertices.saturating_mul(per_vertex as u64).saturating_add(triangles.saturating_mul(12))
    }

    /// Bytes of this mesh's buffers ([`Mesh::bytes_for`] its vertices and triangles).
    #[must_use]
    pub fn bytes(&self) -> u64 {
        Mesh::bytes_for(self.positions.len() as u64, self.triangle_count() as u64)
    }

    pub(super) fn displaced_capped(
        &self,
        field: &HeightField,
        edges: EdgeMode,
        depth_scale: f32,
        max_edge_texels: f32,
        max_triangles: u64,
        geometric_normals: bool,
    ) -> Result<Mesh, MemoryError> {
        let mesh = self.repaired();
        let mesh = mesh.as_ref();
        let depth_scale = if depth_scale.is_finite() && depth_scale > 0.0 { depth_scale } else { 0.0 };
        let max_edge = if max_edge_texels.is_nan() { 1.0 } else { max_edge_texels.max(MIN_EDGE_TEXELS) };
        let plan = SubdivisionPlan::new(mesh, field.size_f32().as_dvec2(), f64::from(max_edge), max_triangles);
        let (mut out, interpolated_normals) = plan.build(mesh)?;

        out.positions
            .par_iter_mut()
            .zip(&interpolated_normals)
            .zip(&out.uvs)
            .zip(&out.uv_scale)
            .for_each(|(((p, n), uv), s)| *p = displace(*p, *n, *uv, *s, field, edges, depth_scale).0);
        out.normals = if geometric_normals {
            compute_vertex_normals(&out.positions, &out.indices).unwrap_or(interpolated_normals)
        } else {
            interpolated_normals
        };
        out.tangents.par_iter_mut().zip(&out.normals).for_each(|(t, &n)| *t = fix_tangent(*t, n));
        Ok(out)
    }
}

// ---------------------------------------------------------------------------------------------
// Subdivision for `Mesh::displaced`
// ---------------------------------------------------------------------------------------------

/// The largest number of parts one edge is split into (before the triangle cap applies).
const MAX_EDGE_PARTS: u32 = 1 << 16;

/// Which edges exist, how many parts each gets, and where their new vertices go.
#[derive(Debug)]
pub(super) struct SubdivisionPlan {
    /// Triangles `[a, b, c]` with three distinct vertices.
    pub(super) triangles: Vec<[u32; 3]>,
    /// Per triangle, the edge ids of `ab`, `ac` and `bc`.
    pub(super) triangle_edges: Vec<[u32; 3]>,
    /// Per edge, its vertices `(lo, hi)` with `lo < hi`.
    pub(super) edges: Vec<(u32, u32)>,
    /// Per edge, the number of parts.
    pub(super) parts: Vec<u32>,
    /// Per triangle, the parts it is split into when a view coarsened it (never fewer than its
    /// edges' parts); empty: the most of its edges' parts.
    pub(super) triangle_n: Vec<u32>,
}

pub(super) fn interior_count(n: u32) -> u64 {
    let n = u64::from(n);
    if n >= 3 { (n - 1) * (n - 2) / 2 } else { 0 }
}

impl SubdivisionPlan {
    pub(super) fn new(mesh: &Mesh, texels: DVec2, max_edge: f64, max_triangles: u64) -> Self {
        let triangles: Vec<[u32; 3]> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        let mut ids: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 2);
        let mut edges = Vec::with_capacity(triangles.len() * 2);
        let mut id = |p: u32, q: u32| {
            let key = (p.min(q), p.max(q));
            *ids.entry(key).or_insert_with(|| {
                edges.push(key);
                edges.len() as u32 - 1
            })
        };
        let triangle_edges: Vec<[u32; 3]> = triangles.iter().map(|&[a, b, c]| [id(a, b), id(a, c), id(b, c)]).collect();
        let lengths: Vec<f64> = edges
            .iter()
            .map(|&(p, q)| ((mesh.uvs[q as usize] - mesh.uvs[p as usize]).as_dvec2() * texels).length())
            .collect();

        // Raise the edge length until the output fits; give up subdividing if it never does.
        let vertex_limit = u64::from(u32::MAX);
        let mut max_edge = max_edge;
        let mut parts: Vec<u32> = Vec::new();
        let mut fits = false;
        for _ in 0..200 {
            parts =
                lengths.iter().map(|&l| (l / max_edge).ceil().clamp(1.0, f64::from(MAX_EDGE_PARTS)) as u32).collect();
            let (tris, verts) = Self::totals(mesh.positions.len(), &triangle_edges, &parts);
            if (tris <= max_triangles && verts <= vertex_limit) || parts.iter().all(|&n| n == 1) {
                fits = true;
                break;
            }
            max_edge *= (tris as f64 / max_triangles as f64).sqrt().max(1.02);
        }
        if !fits {
            parts = vec![1; edges.len()];
        }
        Self { triangles, triangle_edges, edges, parts, triangle_n: Vec::new() }
    }

    /// Upper bounds on the output's triangles and its exact vertex count.
    fn totals(vertices: usize, triangle_edges: &[[u32; 3]], parts: &[u32]) -> (u64, u64) {
        let mut tris = 0u64;
        let mut verts = vertices as u64 + parts.iter().map(|&n| u64::from(n) - 1).sum::<u64>();
        for e in triangle_edges {
            let n = e.iter().map(|&e| parts[e as usize]).max().unwrap_or(1);
            tris += u64::from(n) * u64::from(n);
            verts += interior_count(n);
        }
        (tris, verts)
    }

    /// The parts triangle `t` is split into: the most of its three edges' (unless a view
    /// coarsened it: [`SubdivisionPlan::triangle_n`]).
    pub(super) fn triangle_parts(&self, t: usize) -> u32 {
        match self.triangle_n.get(t) {
            Some(&n) => n,
            None => self.edge_parts(t),
        }
    }

    /// The most parts of triangle `t`'s three edges.
    pub(super) fn edge_parts(&self, t: usize) -> u32 {
        self.triangle_edges[t].iter().map(|&e| self.parts[e as usize]).max().unwrap_or(1)
    }

    /// Where grid point `(i, j)` of triangle `t` (split into `n` parts) lies: the point
    /// `a (n - i - j) / n + b i / n + c j / n`, except that on an edge with fewer parts than the
    /// triangle it snaps to the nearest of the edge's own points (round half up in the
    /// direction of travel), so that the triangles sharing an edge share its vertices.
    pub(super) fn grid_point(&self, t: usize, i: u32, j: u32, n: u32) -> GridPoint {
        let [a, b, c] = self.triangles[t];
        let [ab, ac, bc] = self.triangle_edges[t];
        // Parameter k / n from p toward q on edge e.
        let on_edge = |p: u32, q: u32, e: u32, k: u32| -> GridPoint {
            let parts = self.parts[e as usize];
            let kk = ((2 * u64::from(k) * u64::from(parts) + u64::from(n)) / (2 * u64::from(n))) as u32;
            if kk == 0 {
                GridPoint::Vertex(p)
            } else if kk >= parts {
                GridPoint::Vertex(q)
            } else {
                GridPoint::Edge { edge: e, k: if p < q { kk } else { parts - kk } }
            }
        };
        if j == 0 {
            on_edge(a, b, ab, i)
        } else if i == 0 {
            on_edge(a, c, ac, j)
        } else if i + j == n {
            on_edge(b, c, bc, j)
        } else {
            GridPoint::Interior { i, j }
        }
    }

    /// Triangle `t`'s face normal (its first vertex's normal when it has no area).
    pub(super) fn face(&self, mesh: &Mesh, t: usize) -> Vec3 {
        let [a, b, c] = self.triangles[t];
        let (pa, pb, pc) = (mesh.positions[a as usize], mesh.positions[b as usize], mesh.positions[c as usize]);
        (pb - pa).cross(pc - pa).normalize_or(mesh.normals[a as usize])
    }

    /// The undisplaced vertex at grid point `g` of triangle `t` (split into `n` parts):
    /// positions, normals, UVs, tangents and `uv_scale` interpolated from the triangle's corners
    /// (from the edge's two ends only for a point on an edge).
    /// `face` is the normal interior points fall back to ([`SubdivisionPlan::face`]).
    #[inline]
    pub(super) fn blend(&self, mesh: &Mesh, t: usize, g: GridPoint, n: u32, face: Vec3) -> Blended {
        match g {
            GridPoint::Vertex(v) => {
                let v = v as usize;
                Blended {
                    position: mesh.positions[v],
                    normal: mesh.normals[v],
                    uv: mesh.uvs[v],
                    tangent: mesh.tangents[v],
                    uv_scale: mesh.uv_scale[v],
                }
            }
            GridPoint::Edge { edge, k } => {
                let (lo, hi) = self.edges[edge as usize];
                let t = f64::from(k) / f64::from(self.parts[edge as usize]);
                blend(mesh, [lo, hi, hi], [1.0 - t, t, 0.0], mesh.normals[lo as usize])
            }
            GridPoint::Interior { i, j } => {
                let w = [f64::from(n - i - j), f64::from(i), f64::from(j)].map(|x| x / f64::from(n));
                blend(mesh, self.triangles[t], w, face)
            }
        }
    }

    /// The subdivided, undisplaced mesh (normals interpolated, tangents not yet orthogonalized),
    /// and a copy of its interpolated normals.
    fn build(&self, mesh: &Mesh) -> Result<(Mesh, Vec<Vec3>), MemoryError> {
        // Every buffer is reserved once, at its final size, fallibly: the sizes come from input.
        let (tris, verts) = Self::totals(mesh.positions.len(), &self.triangle_edges, &self.parts);
        let fail = |e: std::collections::TryReserveError| MemoryError::Allocation {
            what: format!("the displaced mesh ({tris} triangles, {verts} vertices)"),
            bytes: Mesh::bytes_for(verts, tris),
            reason: e.to_string(),
            advice: "use a smaller height map or a coarser --technique than displaced".into(),
        };
        fn reserved<T: Clone>(from: &[T], n: u64) -> Result<Vec<T>, std::collections::TryReserveError> {
            let mut v = Vec::new();
            v.try_reserve_exact(usize::try_from(n).unwrap_or(usize::MAX).max(from.len()))?;
            v.extend_from_slice(from);
            Ok(v)
        }
        let mut out = Mesh {
            positions: reserved(&mesh.positions, verts).map_err(fail)?,
            normals: reserved(&mesh.normals, verts).map_err(fail)?,
            uvs: reserved(&mesh.uvs, verts).map_err(fail)?,
            tangents: reserved(&mesh.tangents, verts).map_err(fail)?,
            uv_scale: reserved(&mesh.uv_scale, verts).map_err(fail)?,
            indices: reserved(&[], tris.saturating_mul(3)).map_err(fail)?,
        };
        let push = |out: &mut Mesh, v: Blended| {
            out.positions.push(v.position);
            out.normals.push(v.normal);
            out.uvs.push(v.uv);
            out.tangents.push(v.tangent);
            out.uv_scale.push(v.uv_scale);
            out.positions.len() as u32 - 1
        };
        // Edge vertices, from lo to hi, computed from the edge's end points only.
        let mut edge_base = Vec::with_capacity(self.edges.len());
        for (e, &n) in self.parts.iter().enumerate() {
            edge_base.push(out.positions.len() as u32);
            for k in 1..n {
                push(&mut out, self.blend(mesh, 0, GridPoint::Edge { edge: e as u32, k }, n, Vec3::Z));
            }
        }
        let mut grid: Vec<u32> = Vec::new();
        for t in 0..self.triangles.len() {
            let n = self.triangle_parts(t);
            let face = self.face(mesh, t);
            // Row j of the grid holds i in 0..=n - j.
            grid.clear();
            for j in 0..=n {
                for i in 0..=n - j {
                    let v = match self.grid_point(t, i, j, n) {
                        GridPoint::Vertex(v) => v,
                        GridPoint::Edge { edge, k } => edge_base[edge as usize] + k - 1,
                        g @ GridPoint::Interior { .. } => push(&mut out, self.blend(mesh, t, g, n, face)),
                    };
                    grid.push(v);
                }
            }
            let row = |j: u32| (j * (n + 1) - j * j.saturating_sub(1) / 2) as usize;
            let at = |i: u32, j: u32| grid[row(j) + i as usize];
            for j in 0..n {
                for i in 0..n - j {
                    push_triangle(&mut out.indices, [at(i, j), at(i + 1, j), at(i, j + 1)]);
                    if i + j + 1 < n {
                        push_triangle(&mut out.indices, [at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
                    }
                }
            }
        }
        let normals = reserved(&out.normals, 0).map_err(fail)?;
        Ok((out, normals))
    }
}

/// A point of a triangle's subdivision grid, named so that the triangles sharing it agree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum GridPoint {
    /// A vertex of the input mesh.
    Vertex(u32),
    /// Point `k` (1 ..= parts - 1, counted from the edge's lower vertex index) of an edge.
    Edge { edge: u32, k: u32 },
    /// Grid point `(i, j)` inside the triangle.
    Interior { i: u32, j: u32 },
}

/// An interpolated, undisplaced vertex.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blended {
    pub(super) position: Vec3,
    pub(super) normal: Vec3,
    pub(super) uv: Vec2,
    pub(super) tangent: Vec4,
    pub(super) uv_scale: Vec2,
}

/// Moves `p` along `-n` by `depth * depth_scale * L` world units, where `depth` is the field's
/// bilinear depth at `uv` and `L` = [`uv_unit_length`] of `uv_scale`; returns the moved point
/// and the depth.
pub(super) fn displace(
    p: Vec3,
    n: Vec3,
    uv: Vec2,
    uv_scale: Vec2,
    field: &HeightField,
    edges: EdgeMode,
    depth_scale: f32,
) -> (Vec3, f32) {
    let depth = field.sample_bilinear(uv, edges);
    let l = f64::from(uv_unit_length(uv_scale));
    (clamp_to_f32(p.as_dvec3() - n.as_dvec3() * (f64::from(depth) * f64::from(depth_scale) * l)), depth)
}

/// Appends a triangle unless two of its vertices are the same.
fn push_triangle(indices: &mut Vec<u32>, t: [u32; 3]) {
    if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
        indices.extend(t);
    }
}

/// The vertex with barycentric weights `w` of `mesh`'s vertices `v`; its normal falls back to
/// `fallback_normal` when the interpolated one is zero.
#[inline]
fn blend(mesh: &Mesh, v: [u32; 3], w: [f64; 3], fallback_normal: Vec3) -> Blended {
    let (mut p, mut n, mut uv, mut t, mut hand, mut s) =
        (DVec3::ZERO, DVec3::ZERO, DVec2::ZERO, DVec3::ZERO, 0.0f64, DVec2::ZERO);
    for (&k, &w) in v.iter().zip(&w) {
        let k = k as usize;
        p += mesh.positions[k].as_dvec3() * w;
        n += mesh.normals[k].as_dvec3() * w;
        uv += mesh.uvs[k].as_dvec2() * w;
        t += mesh.tangents[k].truncate().as_dvec3() * w;
        hand += f64::from(mesh.tangents[k].w) * w;
        s += mesh.uv_scale[k].as_dvec2() * w;
    }
    Blended {
        position: clamp_to_f32(p),
        normal: unit_f64(n).and_then(|n| n.as_vec3().try_normalize()).unwrap_or(fallback_normal),
        uv: uv.as_vec2(),
        tangent: t.as_vec3().extend(if hand < 0.0 { -1.0 } else { 1.0 }),
        uv_scale: sane_scale_f64(s),
    }
}
