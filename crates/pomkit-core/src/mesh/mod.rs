//! Triangle meshes for parallax mapping: vertex frames, the world size of a UV unit, primitive
//! shapes, transforms, and truly displaced geometry (the `displaced` technique's ground truth).
//!
//! # Conventions (ARCHITECTURE.md)
//!
//! - Triangles are wound counter-clockwise seen from the front, the side their normals point to.
//! - Tangents are glTF's: `xyz` is the unit tangent T along increasing u, perpendicular to the unit
//!   normal N; `w = ±1` is the handedness and the bitangent is `B = w * cross(N, T)`, pointing up
//!   the image (along *decreasing* v, since UV `(0, 0)` is the image's top-left corner). An
//!   unmirrored mapping has `w = +1`.
//! - [`Mesh::uv_scale`] holds, per vertex, `(|dP/du|, |dP/dv|)`: how many world units one UV unit
//!   spans along T and along B. `L = sqrt(uv_scale.x * uv_scale.y)` ([`uv_unit_length`]) is the
//!   world length of one UV unit, which turns pomkit's `depth_scale` (in UV units) into world
//!   units: the deepest point lies `depth_scale * L` world units below the polygon.
//!
//! # From the world to pomkit's ray
//!
//! A renderer turns a world direction into a tangent-space [`Ray`](crate::Ray) direction with
//! [`tangent_ray`]; the tracers then place depth `z` at `uv0 + z * depth_scale * (du, dv) / -dz`,
//! exactly where the world ray is `z * depth_scale * L` world units below the surface, and
//! [`Mesh::displaced`] moves each vertex `depth * depth_scale * L` world units along `-N`, so
//! parallax and real geometry agree.
//!
//! # Degenerate arguments
//!
//! Nothing here panics. The shape constructors clamp their arguments: lengths (sizes, radii,
//! heights) that are NaN become 1, others are clamped to `[MIN_LENGTH, MAX_LENGTH]` (a negative
//! size becomes [`MIN_LENGTH`]); segment counts are clamped to the shape's minimum (1 for a
//! plane, 2 rings and 3 segments for a sphere, 3 for round things) and to [`MAX_SEGMENTS`].
//! Methods on a [`Mesh`] whose public fields were edited into an inconsistent state (attribute
//! lengths that differ, indices out of range, non-finite values) first repair a copy: missing
//! or non-finite attributes take defaults (normal +Z, UV 0, tangent perpendicular to the normal
//! with `w = +1`, `uv_scale` 1) and triangles with an index out of range are dropped.

use std::borrow::Cow;

use glam::{DMat3, DVec2, DVec3, Mat4, Vec2, Vec3, Vec4};
use thiserror::Error;

mod blocks;
mod displace;
mod ranges;

pub use blocks::{BLOCK_CELLS, DisplacedBlock, DisplacedBlocks, DisplacementView, ScreenBounds};
mod shapes;

use crate::tangent::{TangentError, TangentMethod, TangentOptions, compute_tangents, compute_vertex_normals};

/// The most segments (per direction) a shape constructor makes; larger requests are clamped.
/// A plane of `MAX_SEGMENTS` has 4.2 million vertices.
pub const MAX_SEGMENTS: u32 = 2048;

/// The smallest length (size, radius, height) a shape constructor accepts; smaller ones are
/// clamped up to it.
pub const MIN_LENGTH: f32 = 1e-6;

/// The largest length a shape constructor accepts; larger ones (and +infinity) are clamped to it.
pub const MAX_LENGTH: f32 = 1e15;

/// [`Mesh::displaced`] keeps its output below this many triangles (about 1 GB of mesh data) by
/// coarsening the subdivision as needed.
pub const MAX_DISPLACED_TRIANGLES: u64 = 20_000_000;

/// The finest subdivision [`Mesh::displaced`] makes: a quarter texel per edge. Smaller (and
/// non-positive) `max_edge_texels` are clamped up to it; NaN means 1 texel.
pub const MIN_EDGE_TEXELS: f32 = 0.25;

/// Why a [`Mesh`] could not be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MeshError {
    /// There are no vertices or no triangles.
    #[error("mesh is empty ({vertices} vertices, {triangles} triangles): it needs at least one triangle")]
    Empty {
        /// The number of positions.
        vertices: usize,
        /// The number of whole triangles in the index list.
        triangles: usize,
    },
    /// The UV list is empty, or its length differs from the number of positions.
    #[error("mesh has no texture coordinates (UVs): parallax mapping needs them")]
    NoUvs {
        /// The number of positions.
        vertices: usize,
        /// The number of UVs given.
        uvs: usize,
    },
    /// [`Mesh::with_tangents`] got a tangent list whose length differs from the number of
    /// positions.
    #[error("{tangents} tangents given for {vertices} vertices")]
    TangentCountMismatch {
        /// The number of positions.
        vertices: usize,
        /// The number of tangents given.
        tangents: usize,
    },
    /// [`Mesh::with_tangents`] got a tangent with a NaN or infinite component (the first such
    /// vertex is named).
    #[error("the tangent of vertex {vertex} is not finite: {value}")]
    NonFiniteTangent {
        /// The vertex.
        vertex: usize,
        /// Its tangent.
        value: Vec4,
    },
    /// Positions, normals, UVs or indices are invalid: see [`TangentError`] (index out of range,
    /// index count not a multiple of 3, a normal list of the wrong length, non-finite values).
    #[error(transparent)]
    Invalid(#[from] TangentError),
}

/// An indexed triangle mesh with everything parallax mapping needs per vertex.
///
/// Every attribute list has one entry per position. Build one with [`Mesh::new`],
/// [`Mesh::with_tangents`] or a shape constructor ([`Mesh::plane`], [`Mesh::quad`],
/// [`Mesh::disc`], [`Mesh::cube`], [`Mesh::uv_sphere`], [`Mesh::cylinder`], [`Mesh::torus`]);
/// these guarantee unit normals, unit tangents perpendicular to them with `w = ±1`, finite UVs
/// and finite positive `uv_scale`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Vertex positions (world or object units).
    pub positions: Vec<Vec3>,
    /// Unit vertex normals.
    pub normals: Vec<Vec3>,
    /// Texture coordinates, glTF style: `(0, 0)` is the image's top-left corner.
    pub uvs: Vec<Vec2>,
    /// Unit tangents along increasing u (`xyz`) with the handedness `w = ±1`; the bitangent
    /// `w * cross(N, T)` points up the image.
    pub tangents: Vec<Vec4>,
    /// World units per UV unit along the tangent (`x`, `|dP/du|`) and the bitangent (`y`,
    /// `|dP/dv|`), averaged over the vertex's triangles weighted by their area. Always finite
    /// and positive; 1 where no triangle with usable UVs touches the vertex.
    pub uv_scale: Vec<Vec2>,
    /// Triangle list, three indices per triangle, counter-clockwise seen from the front.
    pub indices: Vec<u32>,
}

/// The world length of one UV unit, `L = sqrt(uv_scale.x * uv_scale.y)` (the geometric mean of
/// the two directions' scales).
///
/// Components that are NaN, zero or negative count as 1; the result is computed without
/// overflow (`sqrt(x) * sqrt(y)`).
#[must_use]
pub fn uv_unit_length(uv_scale: Vec2) -> f32 {
    let s = sane_uv_scale(uv_scale);
    s.x.sqrt() * s.y.sqrt()
}

/// The mean world length of one UV unit over a triangle list: `sqrt(sum of world areas / sum of
/// UV areas)`, both summed over every triangle (so each triangle weighs by its area).
///
/// This is the one scale that turns a relief given in the mesh's own units (a glTF
/// `KHR_materials_displacement` factor, a texture library's "depth in centimetres") into
/// pomkit's `depth_scale` in UV units: `depth_scale = depth / L` ([`displacement_depth_scale`]).
/// Give the positions in the units the depth is measured in (a glTF mesh's own, before its node
/// transform: a uniform node scale changes both alike). For a mapping of uniform scale it equals
/// [`uv_unit_length`] at every vertex.
///
/// `None` when there is no triangle, an index is out of range, a value is not finite, or the
/// UVs cover no area (every triangle's UVs collinear).
#[must_use]
pub fn mean_uv_unit_length(positions: &[[f32; 3]], uvs: &[[f32; 2]], indices: &[u32]) -> Option<f32> {
    if positions.len() != uvs.len() {
        return None;
    }
    let (mut world, mut uv) = (0.0f64, 0.0f64);
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| i as usize);
        let (pa, pb, pc) = (positions.get(a)?, positions.get(b)?, positions.get(c)?);
        let (ta, tb, tc) = (uvs.get(a)?, uvs.get(b)?, uvs.get(c)?);
        let p = |v: &[f32; 3]| DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
        let t = |v: &[f32; 2]| DVec2::new(f64::from(v[0]), f64::from(v[1]));
        world += (p(pb) - p(pa)).cross(p(pc) - p(pa)).length() * 0.5;
        uv += (t(tb) - t(ta)).perp_dot(t(tc) - t(ta)).abs() * 0.5;
    }
    let l = (world / uv).sqrt();
    (world.is_finite() && uv > 0.0 && l.is_finite() && l > 0.0).then_some(l as f32)
}

/// pomkit's `depth_scale` (UV units) of a relief `depth` units deep on a mesh whose mean UV unit
/// is `units_per_uv` long ([`mean_uv_unit_length`]): `depth / units_per_uv`. `None` when either
/// is not finite or not positive.
#[must_use]
pub fn displacement_depth_scale(depth: f32, units_per_uv: f32) -> Option<f32> {
    let d = depth / units_per_uv;
    (depth.is_finite() && depth > 0.0 && units_per_uv.is_finite() && units_per_uv > 0.0 && d.is_finite() && d > 0.0)
        .then_some(d)
}

/// Converts a world direction into pomkit's tangent-space ray direction `(du, dv, dz)`.
///
/// `view_dir_world` is the direction of *travel* (from the eye toward the surface for a view
/// ray, so `V.N < 0` enters the surface; toward the light for a shadow ray). With T the unit
/// tangent (made perpendicular to the unit normal N), `B = w * cross(N, T)`, `(sx, sy) =
/// uv_scale` and `L = sqrt(sx * sy)` ([`uv_unit_length`]), the result is
///
/// ```text
/// (du, dv, dz) = (V.T * L / sx, -(V.B) * L / sy, V.N)
/// ```
///
/// Why: moving along V by world distance `s` moves in UV by `(V.T * s / sx, -(V.B) * s / sy)`
/// (T is along +u, B along -v) and descends `-(V.N) * s` world units along -N, which is pomkit
/// depth `z = -(V.N) * s / (depth_scale * L)`. Eliminating `s`, the tracers' `uv0 + z *
/// depth_scale * (du, dv) / -dz` is exactly where the world ray is at world depth
/// `z * depth_scale * L`. The factor L (rather than dividing by `sx` and `sy` alone) keeps the
/// result of the same magnitude as V when the mapping is isotropic: then `(du, dv, dz)` is V in
/// the (T, B, N) frame with `dv` negated.
///
/// V need not be unit length (the result scales with it and the traced path does not change).
/// The formula is exact for mappings whose `dP/du` and `dP/dv` are perpendicular (all shapes
/// here; any conformal or orthogonally stretched mapping), and a first-order approximation for
/// sheared UVs. Non-finite input, or a zero normal, gives `(0, 0, 0)`, a ray that does not
/// enter the surface (the tracers return the entry point). `uv_scale` components that are NaN,
/// zero or negative count as 1; a tangent parallel to the normal is replaced by
/// `N.any_orthonormal_vector()`; `tangent.w < 0` counts as -1, anything else as +1.
#[must_use]
pub fn tangent_ray(view_dir_world: Vec3, normal: Vec3, tangent: Vec4, uv_scale: Vec2) -> Vec3 {
    if !(view_dir_world.is_finite() && normal.is_finite() && tangent.is_finite()) {
        return Vec3::ZERO;
    }
    TangentMap::new(normal, tangent, uv_scale).map_or(Vec3::ZERO, |m| m.apply(view_dir_world))
}

/// [`tangent_ray`]'s map for one frame, made once and applied to any number of directions (a
/// fragment's view ray and its lights): `TangentMap::new(n, t, s)?.apply(v)` is
/// `tangent_ray(v, n, t, s)` for finite `v`, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentMap {
    t: Vec3,
    b: Vec3,
    n: Vec3,
    /// `L / sx` and `L / sy`.
    scale: Vec2,
}

impl TangentMap {
    /// The map of the frame (`normal`, `tangent`, `uv_scale`); `None` for a non-finite or zero
    /// normal or a non-finite tangent (where [`tangent_ray`] gives zero).
    #[must_use]
    pub fn new(normal: Vec3, tangent: Vec4, uv_scale: Vec2) -> Option<Self> {
        if !(normal.is_finite() && tangent.is_finite()) {
            return None;
        }
        let n = normal.try_normalize()?;
        let t = orthonormal_tangent(tangent.truncate(), n);
        let b = handedness(tangent.w) * n.cross(t);
        let s = sane_uv_scale(uv_scale);
        // L / sx = sqrt(sy / sx) and L / sy = sqrt(sx / sy), without forming sx * sy.
        Some(Self { t, b, n, scale: Vec2::new((s.y / s.x).sqrt(), (s.x / s.y).sqrt()) })
    }

    /// The tangent-space direction of the world direction `v`; zero for a non-finite `v` or
    /// result.
    #[inline]
    #[must_use]
    pub fn apply(&self, v: Vec3) -> Vec3 {
        if !v.is_finite() {
            return Vec3::ZERO;
        }
        let r = Vec3::new(v.dot(self.t) * self.scale.x, -v.dot(self.b) * self.scale.y, v.dot(self.n));
        if r.is_finite() { r } else { Vec3::ZERO }
    }
}

impl Mesh {
    /// Builds a mesh from positions, optional normals, UVs and a triangle list, computing what
    /// is missing.
    ///
    /// Normals: when `None`, area-weighted vertex normals from the geometry
    /// ([`compute_vertex_normals`]); when given, they are normalized, and zero ones replaced by
    /// the geometric normal. Tangents: [`compute_tangents`] with `method`
    /// ([`TangentMethod::MikkTSpace`] is the default and what baking tools use). `uv_scale`:
    /// from each triangle's `|dP/du|` and `|dP/dv|`, averaged per vertex weighted by area.
    ///
    /// # Errors
    ///
    /// Checked in this order: [`MeshError::Empty`] (no positions or no indices),
    /// [`MeshError::NoUvs`] (`uvs` empty or not one per position), then [`MeshError::Invalid`]
    /// with [`TangentError::AttributeLengthMismatch`] (normals not one per position),
    /// [`TangentError::IndexCountNotMultipleOf3`], [`TangentError::NonFinitePosition`],
    /// [`TangentError::NonFiniteNormal`], [`TangentError::NonFiniteUv`] and
    /// [`TangentError::IndexOutOfRange`].
    pub fn new(
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        uvs: Vec<Vec2>,
        indices: Vec<u32>,
        method: TangentMethod,
    ) -> Result<Mesh, MeshError> {
        let normals = prepare(&positions, normals, &uvs, &indices)?;
        let opts = TangentOptions { method, ..TangentOptions::default() };
        let tangents = compute_tangents(&positions, &normals, &uvs, &indices, &opts)?;
        let uv_scale = compute_uv_scale(&positions, &uvs, &indices);
        Ok(Mesh { positions, normals, uvs, tangents, uv_scale, indices })
    }

    /// As [`Mesh::new`], for meshes that ship their own tangents (glTF's `TANGENT`), which are
    /// kept rather than recomputed: a normal map must be shaded in the frame it was baked in.
    ///
    /// Each tangent is made unit length and perpendicular to its (unit) normal; one that is
    /// zero or parallel to the normal becomes `N.any_orthonormal_vector()` with `w = +1`.
    /// `w < 0` becomes -1 and anything else +1.
    ///
    /// # Errors
    ///
    /// Those of [`Mesh::new`], then [`MeshError::TangentCountMismatch`] and
    /// [`MeshError::NonFiniteTangent`].
    pub fn with_tangents(
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        uvs: Vec<Vec2>,
        indices: Vec<u32>,
        tangents: Vec<Vec4>,
    ) -> Result<Mesh, MeshError> {
        let normals = prepare(&positions, normals, &uvs, &indices)?;
        if tangents.len() != positions.len() {
            return Err(MeshError::TangentCountMismatch { vertices: positions.len(), tangents: tangents.len() });
        }
        if let Some(vertex) = tangents.iter().position(|t| !t.is_finite()) {
            return Err(MeshError::NonFiniteTangent { vertex, value: tangents[vertex] });
        }
        let tangents = tangents.iter().zip(&normals).map(|(t, &n)| fix_tangent(*t, n)).collect();
        let uv_scale = compute_uv_scale(&positions, &uvs, &indices);
        Ok(Mesh { positions, normals, uvs, tangents, uv_scale, indices })
    }

    /// The number of triangles (`indices.len() / 3`).
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The axis-aligned bounding box `(min, max)` of the finite positions; `(0, 0)` when there
    /// are none.
    #[must_use]
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut it = self.positions.iter().filter(|p| p.is_finite());
        match it.next() {
            Some(&first) => it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
            None => (Vec3::ZERO, Vec3::ZERO),
        }
    }

    /// Multiplies every UV by `repeat`, so that the texture tiles `repeat.x` times along u and
    /// `repeat.y` times along v (use a wrapping edge mode), and divides `uv_scale` accordingly
    /// (one UV unit now spans fewer world units). Tangents do not change.
    ///
    /// Components that are NaN, infinite or zero count as 1; negative ones are made positive
    /// (mirroring the texture would flip the tangent frames; mirror the mesh with
    /// [`Mesh::transformed`] instead); the rest are clamped to `[1e-6, 1e6]`.
    #[must_use]
    pub fn scale_uvs(mut self, repeat: Vec2) -> Mesh {
        let sane = |r: f32| if r.is_finite() && r != 0.0 { r.abs().clamp(1e-6, 1e6) } else { 1.0 };
        let r = Vec2::new(sane(repeat.x), sane(repeat.y));
        for uv in &mut self.uvs {
            *uv *= r;
        }
        for s in &mut self.uv_scale {
            *s = sane_uv_scale(*s / r);
        }
        self
    }

    /// The mesh transformed by the affine matrix `m` (its last row is ignored).
    ///
    /// Positions are transformed by `m`; normals by the inverse transpose of its linear part,
    /// renormalized; tangents' `xyz` by the linear part, made perpendicular to the new normal
    /// and renormalized. When `det(m) < 0` (a mirror), `w` is negated, so that `B = w *
    /// cross(N, T)` still points up the image, and every triangle's winding is reversed, so
    /// that counter-clockwise stays the front. `uv_scale` is multiplied by how much `m`
    /// stretches T and B.
    ///
    /// The normal matrix is computed as the cofactor matrix (the inverse transpose times the
    /// determinant, sign corrected), in `f64`, so singular matrices work: normals that it maps
    /// to zero are recomputed from the transformed geometry (+Z when that has no area), and
    /// tangents that collapse take `N.any_orthonormal_vector()` with `w = +1`. A matrix with a
    /// NaN or infinite element is treated as the identity. Positions beyond the `f32` range
    /// are clamped to `±f32::MAX`.
    #[must_use]
    pub fn transformed(&self, m: Mat4) -> Mesh {
        let mesh = self.repaired();
        let mesh = mesh.as_ref();
        if !m.is_finite() {
            return mesh.clone();
        }
        let m = m.as_dmat4();
        let linear = DMat3::from_mat4(m);
        let translation = m.w_axis.truncate();
        let det = linear.determinant();
        let (c0, c1, c2) = (linear.x_axis, linear.y_axis, linear.z_axis);
        let cofactor = DMat3::from_cols(c1.cross(c2), c2.cross(c0), c0.cross(c1));
        let normal_matrix = if det < 0.0 { -cofactor } else { cofactor };
        let mirror = det < 0.0;

        let positions: Vec<Vec3> =
            mesh.positions.iter().map(|p| clamp_to_f32(linear * p.as_dvec3() + translation)).collect();
        let mut indices = mesh.indices.clone();
        if mirror {
            for tri in indices.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
        }
        let mut geometric: Option<Vec<Vec3>> = None;
        let mut normals = Vec::with_capacity(positions.len());
        for (v, n) in mesh.normals.iter().enumerate() {
            let n = unit_f64(normal_matrix * n.as_dvec3()).and_then(|n| n.as_vec3().try_normalize());
            normals.push(n.unwrap_or_else(|| {
                geometric.get_or_insert_with(|| {
                    compute_vertex_normals(&positions, &indices).unwrap_or_else(|_| vec![Vec3::Z; positions.len()])
                })[v]
            }));
        }
        let mut tangents = Vec::with_capacity(positions.len());
        let mut uv_scale = Vec::with_capacity(positions.len());
        for (((n0, &t0), s0), &n) in mesh.normals.iter().zip(&mesh.tangents).zip(&mesh.uv_scale).zip(&normals) {
            let n0 = n0.normalize_or(Vec3::Z);
            let t_old = orthonormal_tangent(t0.truncate(), n0);
            let b_old = handedness(t0.w) * n0.cross(t_old);
            let t_new = linear * t_old.as_dvec3();
            let b_new = linear * b_old.as_dvec3();
            let w = if mirror { -handedness(t0.w) } else { handedness(t0.w) };
            let t = unit_f64(t_new)
                .map(|t| t.as_vec3())
                // A tangent (nearly) parallel to the new normal (a singular transform) leaves
                // only rounding noise after the projection: use the fallback, not the noise.
                .map(|t| t - n * n.dot(t))
                .filter(|r| r.length_squared() > 1e-8)
                .and_then(Vec3::try_normalize)
                .map_or_else(|| n.any_orthonormal_vector().extend(1.0), |t| t.extend(w));
            tangents.push(t);
            let s = s0.as_dvec2() * DVec2::new(t_new.length(), b_new.length());
            uv_scale.push(sane_scale_f64(s));
        }
        Mesh { positions, normals, uvs: mesh.uvs.clone(), tangents, uv_scale, indices }
    }

    /// Whether every attribute has one finite entry per position (normals and `uv_scale` also
    /// usable) and every index is in range.
    fn is_consistent(&self) -> bool {
        let n = self.positions.len();
        self.normals.len() == n
            && self.uvs.len() == n
            && self.tangents.len() == n
            && self.uv_scale.len() == n
            && self.indices.len().is_multiple_of(3)
            && self.indices.iter().all(|&i| (i as usize) < n)
            && self.positions.iter().all(|p| p.is_finite())
            && self.normals.iter().all(|v| v.is_finite() && v.length_squared() > 0.0)
            && self.uvs.iter().all(|v| v.is_finite())
            && self.tangents.iter().all(|v| v.is_finite())
            && self.uv_scale.iter().all(|s| s.is_finite() && s.x > 0.0 && s.y > 0.0)
    }

    /// The mesh itself when consistent, else a repaired copy (see the module documentation).
    pub(crate) fn repaired(&self) -> Cow<'_, Mesh> {
        if self.is_consistent() {
            return Cow::Borrowed(self);
        }
        let n = self.positions.len();
        let positions: Vec<Vec3> = self.positions.iter().map(|p| if p.is_finite() { *p } else { Vec3::ZERO }).collect();
        let normals: Vec<Vec3> = (0..n)
            .map(|v| self.normals.get(v).filter(|x| x.is_finite()).map_or(Vec3::Z, |x| x.normalize_or(Vec3::Z)))
            .collect();
        let uvs = (0..n).map(|v| self.uvs.get(v).copied().filter(|x| x.is_finite()).unwrap_or(Vec2::ZERO)).collect();
        let tangents = (0..n)
            .map(|v| {
                let t = self.tangents.get(v).copied().filter(|x| x.is_finite()).unwrap_or(Vec4::ZERO);
                fix_tangent(t, normals[v])
            })
            .collect();
        let uv_scale = (0..n).map(|v| sane_uv_scale(self.uv_scale.get(v).copied().unwrap_or(Vec2::ONE))).collect();
        let indices =
            self.indices.chunks_exact(3).filter(|t| t.iter().all(|&i| (i as usize) < n)).flatten().copied().collect();
        Cow::Owned(Mesh { positions, normals, uvs, tangents, uv_scale, indices })
    }
}

// ---------------------------------------------------------------------------------------------
// Validation and per-vertex helpers
// ---------------------------------------------------------------------------------------------

/// Checks the input of [`Mesh::new`] and [`Mesh::with_tangents`] and returns unit normals.
fn prepare(
    positions: &[Vec3],
    normals: Option<Vec<Vec3>>,
    uvs: &[Vec2],
    indices: &[u32],
) -> Result<Vec<Vec3>, MeshError> {
    if positions.is_empty() || indices.is_empty() {
        return Err(MeshError::Empty { vertices: positions.len(), triangles: indices.len() / 3 });
    }
    if uvs.is_empty() || uvs.len() != positions.len() {
        return Err(MeshError::NoUvs { vertices: positions.len(), uvs: uvs.len() });
    }
    if let Some(n) = normals.as_ref().filter(|n| n.len() != positions.len()) {
        return Err(TangentError::AttributeLengthMismatch {
            positions: positions.len(),
            normals: n.len(),
            uvs: uvs.len(),
        }
        .into());
    }
    if !indices.len().is_multiple_of(3) {
        return Err(TangentError::IndexCountNotMultipleOf3 { count: indices.len() }.into());
    }
    if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
        return Err(TangentError::NonFinitePosition { vertex, value: positions[vertex] }.into());
    }
    if let Some(n) = &normals
        && let Some(vertex) = n.iter().position(|x| !x.is_finite())
    {
        return Err(TangentError::NonFiniteNormal { vertex, value: n[vertex] }.into());
    }
    if let Some(vertex) = uvs.iter().position(|uv| !uv.is_finite()) {
        return Err(TangentError::NonFiniteUv { vertex, value: uvs[vertex] }.into());
    }
    // Checks the index count, the positions and the index range once more, in that order.
    let geometric = compute_vertex_normals(positions, indices)?;
    Ok(match normals {
        None => geometric,
        Some(n) => n
            .iter()
            .zip(&geometric)
            .map(|(&n, &g)| unit_f64(n.as_dvec3()).and_then(|n| n.as_vec3().try_normalize()).unwrap_or(g))
            .collect(),
    })
}

/// Per-vertex `(|dP/du|, |dP/dv|)`, averaged over the vertex's triangles weighted by their area.
///
/// For a triangle with edges `e1 = p1 - p0`, `e2 = p2 - p0` and UV edges `d1`, `d2`, the linear
/// map from UV to position has `[dP/du dP/dv] = [e1 e2] [d1 d2]^-1`. Triangles with zero area
/// or degenerate UVs (UV determinant at most 1e-9 of the product of the UV edge lengths)
/// contribute nothing; vertices with no contribution get 1. Computed in `f64`.
fn compute_uv_scale(positions: &[Vec3], uvs: &[Vec2], indices: &[u32]) -> Vec<Vec2> {
    let mut sums = vec![(DVec2::ZERO, 0.0f64); positions.len()];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let p0 = positions[a].as_dvec3();
        let (e1, e2) = (positions[b].as_dvec3() - p0, positions[c].as_dvec3() - p0);
        let uv0 = uvs[a].as_dvec2();
        let (d1, d2) = (uvs[b].as_dvec2() - uv0, uvs[c].as_dvec2() - uv0);
        let det = d1.x * d2.y - d2.x * d1.y;
        let area = e1.cross(e2).length();
        if !(det.abs() > 1e-9 * d1.length() * d2.length() && area > 0.0) {
            continue;
        }
        let dpdu = (e1 * d2.y - e2 * d1.y) / det;
        let dpdv = (e2 * d1.x - e1 * d2.x) / det;
        let s = DVec2::new(dpdu.length(), dpdv.length());
        if !(s.is_finite() && area.is_finite()) {
            continue;
        }
        for v in [a, b, c] {
            sums[v].0 += s * area;
            sums[v].1 += area;
        }
    }
    sums.into_iter().map(|(s, w)| if w > 0.0 { sane_scale_f64(s / w) } else { Vec2::ONE }).collect()
}

/// `+1` unless `w < 0`.
pub(crate) fn handedness(w: f32) -> f32 {
    if w < 0.0 { -1.0 } else { 1.0 }
}

/// `t` made perpendicular to the unit `n` and unit length, or `n.any_orthonormal_vector()`.
pub(crate) fn orthonormal_tangent(t: Vec3, n: Vec3) -> Vec3 {
    let t = t.normalize_or_zero();
    (t - n * n.dot(t)).try_normalize().filter(|r| r.dot(t) > 1e-4).unwrap_or_else(|| n.any_orthonormal_vector())
}

/// A tangent made unit and perpendicular to the unit normal `n`, `w = ±1`; the fallback
/// `n.any_orthonormal_vector()` with `w = +1` when it is zero or parallel to `n`.
fn fix_tangent(t: Vec4, n: Vec3) -> Vec4 {
    let xyz = t.truncate().normalize_or_zero();
    match (xyz - n * n.dot(xyz)).try_normalize().filter(|r| r.dot(xyz) > 1e-4) {
        Some(r) => r.extend(handedness(t.w)),
        None => n.any_orthonormal_vector().extend(1.0),
    }
}

/// The unit vector along `v`, or `None` when it is zero or not finite (scaled first, so huge and
/// tiny vectors normalize).
fn unit_f64(v: DVec3) -> Option<DVec3> {
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    (v / m).try_normalize()
}

/// A point clamped into the `f32` range.
fn clamp_to_f32(p: DVec3) -> Vec3 {
    let max = f64::from(f32::MAX);
    let c = |x: f64| if x.is_nan() { 0.0 } else { x.clamp(-max, max) as f32 };
    Vec3::new(c(p.x), c(p.y), c(p.z))
}

/// A `uv_scale` component made finite and positive: NaN, zero and negative give 1; the rest is
/// clamped to `[f32::MIN_POSITIVE, f32::MAX]`.
fn sane_scale_f64(s: DVec2) -> Vec2 {
    let c = |x: f64| {
        if x.is_nan() || x <= 0.0 { 1.0 } else { (x.min(f64::from(f32::MAX)) as f32).max(f32::MIN_POSITIVE) }
    };
    Vec2::new(c(s.x), c(s.y))
}

fn sane_uv_scale(s: Vec2) -> Vec2 {
    sane_scale_f64(s.as_dvec2())
}

/// A shape length: NaN gives 1, the rest is clamped to `[MIN_LENGTH, MAX_LENGTH]`.
fn sane_length(x: f32) -> f32 {
    if x.is_nan() { 1.0 } else { x.clamp(MIN_LENGTH, MAX_LENGTH) }
}

fn sane_size(s: Vec2) -> Vec2 {
    Vec2::new(sane_length(s.x), sane_length(s.y))
}

fn clamp_segments(n: u32, min: u32) -> u32 {
    n.clamp(min, MAX_SEGMENTS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::{EdgeMode, HeightField};
    use crate::trace::{Ray, Surface, Technique, TraceParams, trace};
    use displace::interior_count;
    use glam::{Quat, Vec3Swizzles};
    use proptest::prelude::*;
    use std::collections::HashMap;
    use std::f64::consts::PI;

    #[test]
    fn the_mean_uv_unit_of_a_plane_is_its_size_and_ignores_uv_offsets() {
        // A 4 x 2 rectangle mapped to UVs [0.5, 1.5] x [0, 2]: one UV unit is 4 world units along
        // u and 1 along v, so the mean is sqrt(8 / 2) = 2.
        let positions = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 2.0, 0.0], [0.0, 2.0, 0.0]];
        let uvs = [[0.5, 2.0], [1.5, 2.0], [1.5, 0.0], [0.5, 0.0]];
        let l = mean_uv_unit_length(&positions, &uvs, &[0, 1, 2, 0, 2, 3]).unwrap();
        assert!((l - 2.0).abs() < 1e-6, "{l}");
        // Equal to the per-vertex length of a uniformly mapped shape.
        let m = Mesh::plane(Vec2::splat(3.0), 4);
        let p: Vec<[f32; 3]> = m.positions.iter().map(|v| v.to_array()).collect();
        let t: Vec<[f32; 2]> = m.uvs.iter().map(|v| v.to_array()).collect();
        let l = mean_uv_unit_length(&p, &t, &m.indices).unwrap();
        assert!((l - uv_unit_length(m.uv_scale[0])).abs() < 1e-5, "{l}");
        assert!((displacement_depth_scale(0.3, l).unwrap() - 0.1).abs() < 1e-6);
        // Degenerate input is None, never NaN.
        assert_eq!(mean_uv_unit_length(&positions, &[[0.0, 0.0]; 4], &[0, 1, 2]), None);
        assert_eq!(mean_uv_unit_length(&positions, &uvs, &[0, 1, 9]), None);
        assert_eq!(mean_uv_unit_length(&positions, &uvs, &[]), None);
        assert_eq!(displacement_depth_scale(-1.0, 1.0), None);
        assert_eq!(displacement_depth_scale(f32::NAN, 1.0), None);
        assert_eq!(displacement_depth_scale(1.0, 0.0), None);
    }

    /// The angle between two vectors (atan2, accurate near 0 unlike acos in f32).
    fn degrees(a: Vec3, b: Vec3) -> f32 {
        let (a, b) = (a.normalize(), b.normalize());
        a.cross(b).length().atan2(a.dot(b)).to_degrees()
    }

    fn bitangent(m: &Mesh, v: usize) -> Vec3 {
        m.tangents[v].w * m.normals[v].cross(m.tangents[v].truncate())
    }

    /// The invariants every mesh must keep.
    fn assert_valid(m: &Mesh) {
        let n = m.positions.len();
        assert!(n > 0 && m.indices.len().is_multiple_of(3) && !m.indices.is_empty());
        assert_eq!((m.normals.len(), m.uvs.len(), m.tangents.len(), m.uv_scale.len()), (n, n, n, n));
        assert!(m.indices.iter().all(|&i| (i as usize) < n));
        for v in 0..n {
            let (p, nn, t, s) = (m.positions[v], m.normals[v], m.tangents[v], m.uv_scale[v]);
            assert!(p.is_finite() && m.uvs[v].is_finite(), "vertex {v}: {p} {}", m.uvs[v]);
            assert!(nn.is_finite() && (nn.length() - 1.0).abs() < 1e-4, "normal {v}: {nn}");
            assert!(t.is_finite() && (t.truncate().length() - 1.0).abs() < 1e-4, "tangent {v}: {t}");
            assert!(t.truncate().dot(nn).abs() < 1e-3, "tangent {v} not perpendicular: {t} {nn}");
            assert!(t.w == 1.0 || t.w == -1.0, "w {v}: {}", t.w);
            assert!(s.is_finite() && s.x > 0.0 && s.y > 0.0, "uv_scale {v}: {s}");
        }
    }

    /// Per triangle, `dP/du` and `dP/dv` from positions and UVs.
    fn gradients(m: &Mesh, tri: &[u32]) -> Option<(Vec3, Vec3)> {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (e1, e2) = (m.positions[b] - m.positions[a], m.positions[c] - m.positions[a]);
        let (d1, d2) = (m.uvs[b] - m.uvs[a], m.uvs[c] - m.uvs[a]);
        let det = d1.x * d2.y - d2.x * d1.y;
        (det.abs() > 1e-12).then(|| ((e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det))
    }

    /// On flat faces, every vertex's T is along dP/du, B along -dP/dv (up the image), N along
    /// the triangle's geometric normal (counter-clockwise = front), and uv_scale the gradients'
    /// lengths.
    fn assert_flat_frames_match_uvs(m: &Mesh) {
        for tri in m.indices.chunks_exact(3) {
            let (dpdu, dpdv) = gradients(m, tri).expect("usable UVs");
            let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            let geometric = (m.positions[b] - m.positions[a]).cross(m.positions[c] - m.positions[a]);
            for &v in tri {
                let v = v as usize;
                assert!(degrees(m.normals[v], geometric) < 1e-3, "normal {v}");
                assert!(degrees(m.tangents[v].truncate(), dpdu) < 1e-3, "T {v}: {} vs {dpdu}", m.tangents[v]);
                assert!(degrees(bitangent(m, v), -dpdv) < 1e-3, "B {v}: {} vs {}", bitangent(m, v), -dpdv);
                let s = m.uv_scale[v];
                assert!((s.x - dpdu.length()).abs() < 1e-4 * s.x && (s.y - dpdv.length()).abs() < 1e-4 * s.y);
            }
        }
    }

    #[test]
    fn plane_frames_are_the_axes() {
        let m = Mesh::plane(Vec2::new(4.0, 2.0), 3);
        assert_valid(&m);
        assert_eq!((m.positions.len(), m.triangle_count()), (16, 18));
        assert_eq!(m.bounds(), (Vec3::new(-2.0, 0.0, -1.0), Vec3::new(2.0, 0.0, 1.0)));
        for v in 0..m.positions.len() {
            assert_eq!(m.normals[v], Vec3::Y);
            assert!(degrees(m.tangents[v].truncate(), Vec3::X) < 1e-3);
            assert_eq!(m.tangents[v].w, 1.0);
            assert!(degrees(bitangent(&m, v), -Vec3::Z) < 1e-3);
            assert!((m.uv_scale[v] - Vec2::new(4.0, 2.0)).abs().max_element() < 1e-5);
            // u along +X, v along +Z: image top toward -Z.
            let p = m.positions[v];
            assert!((m.uvs[v] - Vec2::new(p.x / 4.0 + 0.5, p.z / 2.0 + 0.5)).length() < 1e-6);
        }
        assert_flat_frames_match_uvs(&m);
    }

    #[test]
    fn quad_frames_are_the_axes() {
        let m = Mesh::quad(Vec2::new(1.0, 3.0));
        assert_valid(&m);
        for v in 0..4 {
            assert_eq!(m.normals[v], Vec3::Z);
            assert!(degrees(m.tangents[v].truncate(), Vec3::X) < 1e-3);
            assert_eq!(m.tangents[v].w, 1.0);
            assert!(degrees(bitangent(&m, v), Vec3::Y) < 1e-3);
            let p = m.positions[v];
            assert!((m.uvs[v] - Vec2::new(p.x + 0.5, 0.5 - p.y / 3.0)).length() < 1e-6, "{p} {}", m.uvs[v]);
        }
        assert_flat_frames_match_uvs(&m);
    }

    #[test]
    fn cube_faces_are_upright_and_unmirrored() {
        let m = Mesh::cube(2.0);
        assert_valid(&m);
        assert_eq!((m.positions.len(), m.triangle_count()), (24, 12));
        assert_flat_frames_match_uvs(&m);
        let expected = [
            (Vec3::Z, Vec3::X, Vec3::Y),
            (-Vec3::Z, -Vec3::X, Vec3::Y),
            (Vec3::X, -Vec3::Z, Vec3::Y),
            (-Vec3::X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, -Vec3::Z),
            (-Vec3::Y, Vec3::X, Vec3::Z),
        ];
        for (face, (n, t, b)) in expected.into_iter().enumerate() {
            let vs = face * 4..face * 4 + 4;
            let uvs: Vec<Vec2> = m.uvs[vs.clone()].to_vec();
            assert!(uvs.contains(&Vec2::ZERO) && uvs.contains(&Vec2::ONE), "face {face}: {uvs:?}");
            for v in vs {
                assert_eq!(m.normals[v], n);
                assert!((m.positions[v].dot(n) - 1.0).abs() < 1e-6);
                assert!(degrees(m.tangents[v].truncate(), t) < 1e-3, "face {face}");
                assert_eq!(m.tangents[v].w, 1.0);
                assert!(degrees(bitangent(&m, v), b) < 1e-3, "face {face}");
                assert!((m.uv_scale[v] - Vec2::splat(2.0)).abs().max_element() < 1e-5);
            }
        }
    }

    #[test]
    fn disc_is_planar_mapped_like_the_plane() {
        let m = Mesh::disc(1.5, 24);
        assert_valid(&m);
        assert_flat_frames_match_uvs(&m);
        for v in 0..m.positions.len() {
            let p = m.positions[v];
            assert_eq!(m.normals[v], Vec3::Y);
            assert!((m.uvs[v] - (p.xz() / 3.0 + 0.5)).length() < 1e-6);
            assert!((m.uv_scale[v] - Vec2::splat(3.0)).abs().max_element() < 1e-4);
            assert_eq!(m.tangents[v].w, 1.0);
        }
    }

    fn east(p: Vec3) -> Vec3 {
        Vec3::new(p.z, 0.0, -p.x).normalize()
    }

    #[test]
    fn sphere_frames_and_scales_are_analytic() {
        let r = 2.5;
        let m = Mesh::uv_sphere(r, 96, 128);
        assert_valid(&m);
        let (mut checked, mut seam) = (0, 0);
        for v in 0..m.positions.len() {
            let (p, uv) = (m.positions[v], m.uvs[v]);
            assert!((m.normals[v] - p / r).length() < 1e-5, "normal {v}");
            assert!((p.length() - r).abs() < 1e-5);
            // v = 0 at the north pole, 1 at the south.
            let lat = (p.y / r).clamp(-1.0, 1.0).asin();
            assert!((uv.y - (0.5 - lat / std::f32::consts::PI)).abs() < 1e-5, "v {v}: {uv} {p}");
            if uv.x == 0.0 || uv.x == 1.0 {
                seam += 1;
                assert!(p.x.abs() < 1e-5 && p.z <= 1e-5, "the seam faces -Z: {p}");
            }
            if (uv.x - 0.5).abs() < 1e-6 && uv.y == 0.5 {
                assert!((p - Vec3::Z * r).length() < 1e-5, "u = 0.5 on the equator faces +Z: {p}");
            }
            if lat.abs().to_degrees() > 70.0 {
                continue;
            }
            checked += 1;
            // Seam vertices see triangles on one side only: MikkTSpace leaves their tangent
            // along those triangles' chords, up to half a segment (1.4 degrees) off east.
            let tolerance = if uv.x == 0.0 || uv.x == 1.0 { 1.5 } else { 0.5 };
            assert!(degrees(m.tangents[v].truncate(), east(p)) < tolerance, "T {v}: {}", m.tangents[v]);
            assert_eq!(m.tangents[v].w, 1.0);
            let north = Vec3::Y - m.normals[v] * m.normals[v].y;
            assert!(degrees(bitangent(&m, v), north) < tolerance, "B {v}");
            let s = m.uv_scale[v];
            let expected = Vec2::new(std::f32::consts::TAU * r * lat.cos(), std::f32::consts::PI * r);
            // Interior vertices average six triangles symmetrically (a second-order error);
            // seam vertices three from one side, a first-order error of about d(lat) tan(lat) / 3.
            let tolerance =
                if uv.x == 0.0 || uv.x == 1.0 { 0.01 + lat.abs().tan() * PI as f32 / 96.0 / 3.0 } else { 0.01 };
            let error = ((s - expected) / expected).abs().max_element();
            assert!(error < tolerance, "uv_scale {v}: {s} vs {expected}");
        }
        assert!(checked > 5000 && seam == 2 * 95, "{checked} {seam}");
        // The poles.
        for v in 0..128 {
            assert_eq!(m.positions[v], Vec3::Y * r);
            assert_eq!(m.uvs[v].y, 0.0);
        }
    }

    #[test]
    fn cylinder_frames_and_scales_are_analytic() {
        let (r, h) = (0.75, 3.0);
        let m = Mesh::cylinder(r, h, 64);
        assert_valid(&m);
        let side = 2 * 65;
        assert_eq!(m.positions.len(), side + 2 * 65);
        for v in 0..side {
            let p = m.positions[v];
            assert!((m.normals[v] - Vec3::new(p.x, 0.0, p.z) / r).length() < 1e-5);
            assert!(degrees(m.tangents[v].truncate(), east(p)) < 0.5, "T {v}");
            assert_eq!(m.tangents[v].w, 1.0);
            assert!(degrees(bitangent(&m, v), Vec3::Y) < 0.5);
            assert!((m.uvs[v].y - (0.5 - p.y / h)).abs() < 1e-6);
            let expected = Vec2::new(std::f32::consts::TAU * r, h);
            assert!(((m.uv_scale[v] - expected) / expected).abs().max_element() < 0.002, "{}", m.uv_scale[v]);
        }
        // Caps: planar, flat, top as the plane (B = -Z), bottom unmirrored from below (B = +Z).
        let caps = Mesh { indices: m.indices[6 * 64..].to_vec(), ..m.clone() };
        assert_flat_frames_match_uvs(&caps);
        for v in side..m.positions.len() {
            let top = v < side + 65;
            let n = if top { Vec3::Y } else { -Vec3::Y };
            assert_eq!(m.normals[v], n);
            assert!(degrees(m.tangents[v].truncate(), Vec3::X) < 1e-3);
            assert_eq!(m.tangents[v].w, 1.0);
            assert!(degrees(bitangent(&m, v), if top { -Vec3::Z } else { Vec3::Z }) < 1e-3);
            assert!((m.uv_scale[v] - Vec2::splat(2.0 * r)).abs().max_element() < 1e-4);
        }
    }

    #[test]
    fn torus_normals_point_away_from_the_tube() {
        let (big, small) = (2.0, 0.5);
        let m = Mesh::torus(big, small, 96, 48);
        assert_valid(&m);
        for v in 0..m.positions.len() {
            let p = m.positions[v];
            let centre = Vec3::new(p.x, 0.0, p.z).normalize() * big;
            assert!((m.normals[v] - (p - centre) / small).length() < 1e-5, "normal {v}");
            // Seam vertices: one-sided, up to half a segment (1.9 degrees) off.
            let tolerance = if m.uvs[v].x == 0.0 || m.uvs[v].x == 1.0 { 2.0 } else { 0.5 };
            assert!(degrees(m.tangents[v].truncate(), east(p)) < tolerance, "T {v}");
            assert_eq!(m.tangents[v].w, 1.0);
            let beta = (p.y / small).clamp(-1.0, 1.0).asin();
            let cos_beta = (p - centre).dot(centre.normalize()) / small;
            let expected = Vec2::new(std::f32::consts::TAU * (big + small * cos_beta), std::f32::consts::TAU * small);
            // Seam vertices average three triangles from one side, not six: a first-order error.
            let tolerance = if m.uvs[v].x == 0.0 || m.uvs[v].x == 1.0 { 0.02 } else { 0.01 };
            let error = ((m.uv_scale[v] - expected) / expected).abs().max_element();
            assert!(error < tolerance, "{v}: {} vs {expected}", m.uv_scale[v]);
            // v = 0.25 on top, 0.5 on the outer equator.
            if (m.uvs[v].y - 0.5).abs() < 1e-6 {
                assert!(beta.abs() < 1e-4 && cos_beta > 0.99);
                assert!(degrees(bitangent(&m, v), Vec3::Y) < 1.0);
            }
            if (m.uvs[v].y - 0.25).abs() < 1e-6 {
                assert!((p.y - small).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn degenerate_shape_arguments_are_clamped() {
        let meshes = [
            Mesh::plane(Vec2::new(f32::NAN, -1.0), 0),
            Mesh::plane(Vec2::splat(f32::INFINITY), 1),
            Mesh::quad(Vec2::ZERO),
            Mesh::disc(f32::NAN, 0),
            Mesh::cube(f32::NEG_INFINITY),
            Mesh::uv_sphere(0.0, 0, 0),
            Mesh::uv_sphere(f32::NAN, 1, 2),
            Mesh::cylinder(-1.0, f32::NAN, 1),
            Mesh::torus(f32::NAN, 0.0, 0, 0),
            Mesh::torus(0.5, 2.0, 3, 3),
        ];
        for m in &meshes {
            assert_valid(m);
        }
        assert_eq!(meshes[0].triangle_count(), 2);
        assert_eq!(meshes[0].bounds().1.x, 0.5);
        assert_eq!(meshes[5].triangle_count(), 2 * 3);
        assert_eq!((clamp_segments(u32::MAX, 1), clamp_segments(0, 3)), (MAX_SEGMENTS, 3));
    }

    #[test]
    fn scale_uvs_tiles_and_divides_the_scale() {
        let m = Mesh::uv_sphere(1.0, 16, 24);
        let tiled = m.clone().scale_uvs(Vec2::new(4.0, -2.0));
        assert_valid(&tiled);
        assert_eq!(tiled.tangents, m.tangents);
        let recomputed = compute_uv_scale(&tiled.positions, &tiled.uvs, &tiled.indices);
        for (v, r) in recomputed.iter().enumerate() {
            assert_eq!(tiled.uvs[v], m.uvs[v] * Vec2::new(4.0, 2.0));
            assert!((tiled.uv_scale[v] - *r).abs().max_element() < 1e-5 * r.max_element());
        }
        assert_eq!(m.clone().scale_uvs(Vec2::new(f32::NAN, 0.0)), m);
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let q = Mesh::quad(Vec2::ONE);
        let (p, uv, idx) = (q.positions.clone(), q.uvs.clone(), q.indices.clone());
        let no_uvs = Mesh::new(p.clone(), None, vec![], idx.clone(), TangentMethod::MikkTSpace).unwrap_err();
        assert_eq!(no_uvs, MeshError::NoUvs { vertices: 4, uvs: 0 });
        assert_eq!(no_uvs.to_string(), "mesh has no texture coordinates (UVs): parallax mapping needs them");
        let short = Mesh::new(p.clone(), None, uv[..3].to_vec(), idx.clone(), TangentMethod::Lengyel);
        assert_eq!(short, Err(MeshError::NoUvs { vertices: 4, uvs: 3 }));
        let mut bad = idx.clone();
        bad[4] = 9;
        assert_eq!(
            Mesh::new(p.clone(), None, uv.clone(), bad.clone(), TangentMethod::MikkTSpace),
            Err(MeshError::Invalid(TangentError::IndexOutOfRange { triangle: 1, index: 9, vertex_count: 4 }))
        );
        assert!(
            Mesh::with_tangents(p.clone(), None, uv.clone(), bad, q.tangents.clone())
                .unwrap_err()
                .to_string()
                .contains("vertex 9")
        );
        assert_eq!(
            Mesh::new(vec![], None, vec![], vec![], TangentMethod::MikkTSpace),
            Err(MeshError::Empty { vertices: 0, triangles: 0 })
        );
        assert_eq!(
            Mesh::new(p.clone(), None, uv.clone(), vec![], TangentMethod::MikkTSpace),
            Err(MeshError::Empty { vertices: 4, triangles: 0 })
        );
        assert_eq!(
            Mesh::new(p.clone(), Some(vec![Vec3::Z; 3]), uv.clone(), idx.clone(), TangentMethod::MikkTSpace),
            Err(MeshError::Invalid(TangentError::AttributeLengthMismatch { positions: 4, normals: 3, uvs: 4 }))
        );
        assert_eq!(
            Mesh::new(p.clone(), None, uv.clone(), idx[..4].to_vec(), TangentMethod::MikkTSpace),
            Err(MeshError::Invalid(TangentError::IndexCountNotMultipleOf3 { count: 4 }))
        );
        let mut nan_uv = uv.clone();
        nan_uv[2].y = f32::NAN;
        assert!(matches!(
            Mesh::new(p.clone(), None, nan_uv, idx.clone(), TangentMethod::MikkTSpace),
            Err(MeshError::Invalid(TangentError::NonFiniteUv { vertex: 2, .. }))
        ));
        assert_eq!(
            Mesh::with_tangents(p.clone(), None, uv.clone(), idx.clone(), vec![Vec4::X; 2]),
            Err(MeshError::TangentCountMismatch { vertices: 4, tangents: 2 })
        );
        let mut nan_t = q.tangents.clone();
        nan_t[1].w = f32::NAN;
        assert!(matches!(
            Mesh::with_tangents(p.clone(), None, uv.clone(), idx.clone(), nan_t),
            Err(MeshError::NonFiniteTangent { vertex: 1, .. })
        ));
    }

    #[test]
    fn new_and_with_tangents_build_valid_frames() {
        let q = Mesh::quad(Vec2::new(2.0, 1.0));
        // Normals computed from the winding; zero given normals replaced by it.
        let m = Mesh::new(q.positions.clone(), None, q.uvs.clone(), q.indices.clone(), TangentMethod::Lengyel).unwrap();
        assert_eq!(m.normals, vec![Vec3::Z; 4]);
        assert_eq!(m.uv_scale, vec![Vec2::new(2.0, 1.0); 4]);
        let given = vec![Vec3::ZERO, Vec3::Z * 3.0, Vec3::Z, Vec3::Z];
        let m =
            Mesh::new(q.positions.clone(), Some(given), q.uvs.clone(), q.indices.clone(), TangentMethod::MikkTSpace)
                .unwrap();
        assert_eq!(m.normals, vec![Vec3::Z; 4]);
        assert_valid(&m);
        // Shipped tangents are kept, made perpendicular; unusable ones fall back.
        let shipped = vec![Vec4::new(1.0, 0.0, 0.5, -1.0), Vec4::new(0.0, 0.0, 2.0, 1.0), Vec4::ZERO, Vec4::X];
        let m = Mesh::with_tangents(q.positions.clone(), None, q.uvs.clone(), q.indices.clone(), shipped).unwrap();
        assert_valid(&m);
        assert_eq!(m.tangents[0], Vec4::new(1.0, 0.0, 0.0, -1.0));
        assert_eq!(m.tangents[1], Vec3::Z.any_orthonormal_vector().extend(1.0));
        assert_eq!(m.tangents[3], Vec4::new(1.0, 0.0, 0.0, 1.0), "w = 0 counts as +1");
    }

    #[test]
    fn mirroring_flips_w_and_keeps_b_up_the_image() {
        let plane = Mesh::plane(Vec2::new(2.0, 1.0), 2);
        for mirror in [Vec3::new(-1.0, 1.0, 1.0), Vec3::new(1.0, 1.0, -3.0), Vec3::new(-2.0, -1.0, -1.0)] {
            let m = plane.transformed(Mat4::from_scale(mirror));
            assert_valid(&m);
            for v in 0..m.positions.len() {
                assert_eq!(m.tangents[v].w, -1.0, "{mirror}");
                // B points along -dP/dv: the image's up, which the mirror maps to mirror * -Z.
                assert!(degrees(bitangent(&m, v), mirror * -Vec3::Z) < 1e-3);
                assert!(degrees(m.tangents[v].truncate(), mirror * Vec3::X) < 1e-3);
                assert!(degrees(m.normals[v], mirror * Vec3::Y) < 1e-3);
            }
            assert_flat_frames_match_uvs(&m);
            // The winding was reversed too, so the geometry agrees with the normals, and
            // tangents computed from scratch agree with the transformed ones.
            let fresh =
                Mesh::new(m.positions.clone(), None, m.uvs.clone(), m.indices.clone(), TangentMethod::MikkTSpace)
                    .unwrap();
            for v in 0..m.positions.len() {
                assert!(degrees(fresh.normals[v], m.normals[v]) < 1e-3);
                assert!((fresh.tangents[v] - m.tangents[v]).length() < 1e-4);
                assert!((fresh.uv_scale[v] - m.uv_scale[v]).abs().max_element() < 1e-4);
            }
        }
        // A stretch scales uv_scale by the stretch of T and B.
        let m = plane.transformed(Mat4::from_scale(Vec3::new(2.0, 7.0, 3.0)));
        assert!(m.uv_scale.iter().all(|s| (*s - Vec2::new(4.0, 3.0)).abs().max_element() < 1e-5));
        assert!(m.tangents.iter().all(|t| t.w == 1.0));
    }

    #[test]
    fn transformed_sphere_keeps_exact_normals_under_nonuniform_scale() {
        let s = Mesh::uv_sphere(1.0, 24, 32);
        let scale = Vec3::new(2.0, 0.5, 1.0);
        let m = s.transformed(Mat4::from_scale_rotation_translation(scale, Quat::from_rotation_y(0.3), Vec3::ONE));
        assert_valid(&m);
        for v in 0..m.positions.len() {
            // An ellipsoid's normal is along the gradient of its implicit equation.
            let local = Quat::from_rotation_y(-0.3) * (m.positions[v] - Vec3::ONE);
            let grad = Quat::from_rotation_y(0.3) * (local / (scale * scale));
            assert!(degrees(m.normals[v], grad) < 1e-3, "{v}");
        }
    }

    #[test]
    fn singular_and_non_finite_transforms_stay_finite() {
        let c = Mesh::cube(1.0);
        for m in [
            Mat4::ZERO,
            Mat4::from_scale(Vec3::new(1.0, 0.0, 1.0)),
            Mat4::from_cols_array(&[f32::NAN; 16]),
            Mat4::from_scale(Vec3::splat(1e30)),
            Mat4::from_scale(Vec3::splat(1e-30)),
        ] {
            let t = c.transformed(m);
            assert_valid(&t);
        }
        assert_eq!(c.transformed(Mat4::from_cols_array(&[f32::INFINITY; 16])), c);
    }

    proptest! {
        #[test]
        fn random_transforms_give_valid_meshes(
            cols in proptest::array::uniform16(prop_oneof![Just(0.0f32), Just(1.0f32), -10.0f32..10.0]),
            shape in 0usize..4,
        ) {
            let m = [Mesh::cube(1.0), Mesh::uv_sphere(1.0, 6, 8), Mesh::torus(1.0, 0.3, 8, 6), Mesh::disc(1.0, 5)]
                [shape].clone();
            let mut a = cols;
            // Affine: last row (0, 0, 0, 1).
            a[3] = 0.0;
            a[7] = 0.0;
            a[11] = 0.0;
            a[15] = 1.0;
            let t = m.transformed(Mat4::from_cols_array(&a));
            assert_valid(&t);
            // Winding follows the normals (mirrors reverse it): checked on the cube, whose
            // normals are its faces' normals, wherever the transform keeps some volume.
            let det = Mat4::from_cols_array(&a).determinant();
            if shape == 0 && det.abs() > 1e-3 {
                for tri in t.indices.chunks_exact(3) {
                    let [p0, p1, p2] = [0, 1, 2].map(|k| t.positions[tri[k] as usize]);
                    let g = (p1 - p0).cross(p2 - p0);
                    prop_assert!(tri.iter().all(|&v| g.dot(t.normals[v as usize]) > 0.0), "det {}", det);
                }
            }
        }
    }

    // -----------------------------------------------------------------------------------------
    // tangent_ray
    // -----------------------------------------------------------------------------------------

    /// Where the world ray from `p0` along `view` is `depth` world units below the surface of
    /// the frame (n, t, b), in UV, for a mapping P(u, v) = p0 + (u - u0) sx T - (v - v0) sy B.
    fn world_uv_at_depth(uv0: Vec2, view: Vec3, n: Vec3, t: Vec3, b: Vec3, s: Vec2, depth: f32) -> Vec2 {
        let dist = depth / -view.dot(n);
        let d = view * dist;
        uv0 + Vec2::new(d.dot(t) / s.x, -d.dot(b) / s.y)
    }

    #[test]
    fn tangent_ray_matches_the_world_ray() {
        let mut rng = 0x1234_5678_u32;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            rng as f32 / u32::MAX as f32
        };
        for _ in 0..200 {
            let q = Quat::from_euler(glam::EulerRot::XYZ, next() * 6.3, next() * 6.3, next() * 6.3);
            let (n, t0) = (q * Vec3::Z, q * Vec3::X);
            let w = if next() < 0.5 { -1.0 } else { 1.0 };
            let b = w * n.cross(t0);
            let s = Vec2::new(0.2 + 5.0 * next(), 0.2 + 5.0 * next());
            let view = (q * Vec3::new(next() - 0.5, next() - 0.5, -0.05 - next())) * (0.1 + 3.0 * next());
            let uv0 = Vec2::new(next(), next());
            let (depth_scale, z) = (0.08, next());
            let d = tangent_ray(view, n * 2.0, t0.extend(w), s);
            assert!(d.z < 0.0);
            let l = uv_unit_length(s);
            assert!((l - (s.x * s.y).sqrt()).abs() < 1e-5);
            let pomkit = uv0 + z * depth_scale * Vec2::new(d.x, d.y) / -d.z;
            let world = world_uv_at_depth(uv0, view, n, t0, b, s, z * depth_scale * l);
            assert!((pomkit - world).length() < 1e-4, "{pomkit} vs {world} (s {s})");
        }
        // Isotropic: V in the (T, B, N) frame with dv negated, same length.
        let d = tangent_ray(Vec3::new(0.3, -0.4, -0.5), Vec3::Y, Vec4::new(1.0, 0.0, 0.0, 1.0), Vec2::splat(7.0));
        assert!((d - Vec3::new(0.3, -0.5, -0.4)).length() < 1e-6, "{d}");
        // Bad input gives a ray that does not enter.
        assert_eq!(tangent_ray(Vec3::NAN, Vec3::Y, Vec4::X, Vec2::ONE), Vec3::ZERO);
        assert_eq!(tangent_ray(-Vec3::Y, Vec3::ZERO, Vec4::X, Vec2::ONE), Vec3::ZERO);
        let d = tangent_ray(-Vec3::Y, Vec3::Y, Vec4::new(0.0, 1.0, 0.0, 0.0), Vec2::new(f32::NAN, -1.0));
        assert!(d.is_finite() && d.z == -1.0);
    }

    /// The nearest hit of a ray with a mesh (Moller-Trumbore, both sides), with the UV there.
    fn ray_mesh_uv(m: &Mesh, origin: Vec3, dir: Vec3) -> Option<(f32, Vec2)> {
        let mut best: Option<(f32, Vec2)> = None;
        for tri in m.indices.chunks_exact(3) {
            let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
            let (p0, e1, e2) = (m.positions[a], m.positions[b] - m.positions[a], m.positions[c] - m.positions[a]);
            let pv = dir.cross(e2);
            let det = e1.dot(pv);
            if det.abs() < 1e-12 {
                continue;
            }
            let tv = origin - p0;
            let u = tv.dot(pv) / det;
            let qv = tv.cross(e1);
            let v = dir.dot(qv) / det;
            let t = e2.dot(qv) / det;
            if u < -1e-6 || v < -1e-6 || u + v > 1.0 + 1e-6 || t <= 0.0 {
                continue;
            }
            if best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, m.uvs[a] * (1.0 - u - v) + m.uvs[b] * u + m.uvs[c] * v));
            }
        }
        best
    }

    #[test]
    fn parallax_agrees_with_displaced_geometry() {
        // A tilted plane of depth 0.2 + 0.6 u (exact under bilinear filtering between the
        // outermost texel centres), on an anisotropic, rotated, mirrored plane.
        let w = 32;
        let depths: Vec<f32> = (0..w * w).map(|k| 0.2 + 0.6 * ((k % w) as f32 + 0.5) / w as f32).collect::<Vec<_>>();
        let field = HeightField::from_depths(w, w, depths).unwrap();
        let depth_scale = 0.15;
        let xf = Mat4::from_rotation_translation(Quat::from_rotation_x(0.4), Vec3::new(0.5, 1.0, -2.0))
            * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0));
        let base = Mesh::plane(Vec2::new(4.0, 1.5), 1).transformed(xf);
        let displaced = base.displaced(&field, EdgeMode::Clamp, depth_scale, 2.0);
        assert_valid(&displaced);
        let surface = Surface::new(field, EdgeMode::Clamp, depth_scale);
        let params = TraceParams::default();
        let eye = xf.transform_point3(Vec3::new(0.7, 3.0, 1.2));
        for target in [Vec3::new(0.0, 0.0, 0.0), Vec3::new(-0.6, 0.0, 0.2), Vec3::new(0.8, 0.0, -0.3)] {
            let target = xf.transform_point3(target);
            let view = (target - eye).normalize();
            let (_, uv0) = ray_mesh_uv(&base, eye, view).unwrap();
            let (_, truth) = ray_mesh_uv(&displaced, eye, view).unwrap();
            let dir = tangent_ray(view, base.normals[0], base.tangents[0], base.uv_scale[0]);
            let hit = trace(&surface, &Ray::new(uv0, dir), Technique::Exact, &params);
            let texels = (hit.uv - truth).abs() * w as f32;
            assert!(texels.max_element() < 2e-3, "{} vs {truth}: {texels} texels", hit.uv);
            assert!((hit.uv - uv0).length() > 0.01, "the test must show parallax");
        }
    }

    // -----------------------------------------------------------------------------------------
    // displaced
    // -----------------------------------------------------------------------------------------

    /// Undirected edge -> directed uses; panics on a directed edge used twice.
    fn edge_uses(m: &Mesh) -> HashMap<(u32, u32), Vec<(u32, u32)>> {
        let mut uses: HashMap<(u32, u32), Vec<(u32, u32)>> = HashMap::new();
        for tri in m.indices.chunks_exact(3) {
            for k in 0..3 {
                let (p, q) = (tri[k], tri[(k + 1) % 3]);
                uses.entry((p.min(q), p.max(q))).or_default().push((p, q));
            }
        }
        for (e, u) in &uses {
            assert!(u.len() <= 2, "edge {e:?} used {} times", u.len());
            if u.len() == 2 {
                assert_ne!(u[0], u[1], "edge {e:?} used twice in the same direction");
            }
        }
        uses
    }

    fn uv_area(m: &Mesh, tri: &[u32]) -> f64 {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| m.uvs[i as usize].as_dvec2());
        let (d1, d2) = (b - a, c - a);
        0.5 * (d1.x * d2.y - d2.x * d1.y)
    }

    /// Total UV area and the most negative triangle's, with v flipped so that counter-clockwise
    /// in the image (u right, v down) counts as the plane's front (positive).
    fn uv_areas(m: &Mesh) -> (f64, f64) {
        let areas: Vec<f64> = m.indices.chunks_exact(3).map(|t| -uv_area(m, t)).collect();
        (areas.iter().sum(), areas.iter().copied().fold(0.0, f64::min))
    }

    #[test]
    fn constant_depth_moves_every_vertex_down_exactly() {
        let (c, depth_scale) = (0.6, 0.1);
        let plane = Mesh::plane(Vec2::new(2.0, 3.0), 2);
        let field = HeightField::constant(16, 16, c);
        let m = plane.displaced(&field, EdgeMode::Wrap, depth_scale, 1.0);
        assert_valid(&m);
        let expected = -c * depth_scale * 6.0f32.sqrt();
        for (v, p) in m.positions.iter().enumerate() {
            assert!((p.y - expected).abs() < 1e-6, "vertex {v}: {p}");
            assert!(degrees(m.normals[v], Vec3::Y) < 1e-3);
            assert!(degrees(m.tangents[v].truncate(), Vec3::X) < 1e-3 && m.tangents[v].w == 1.0);
        }
        // Edges of at most one texel (1.5 along edges with fewer parts than their triangle):
        // 8 parts per side of each of the 2 x 2 quads, 12 along their diagonals.
        assert!(m.triangle_count() >= 2 * 2 * 2 * 8 * 8);
        let mut longest: f32 = 0.0;
        for tri in m.indices.chunks_exact(3) {
            for k in 0..3 {
                let d = (m.uvs[tri[k] as usize] - m.uvs[tri[(k + 1) % 3] as usize]) * 16.0;
                longest = longest.max(d.length());
            }
        }
        assert!(longest > 0.9 && longest <= 1.5 + 1e-4, "{longest}");
    }

    #[test]
    fn tilted_depth_gives_analytic_heights_and_normals() {
        let w = 20u32;
        let (a, b) = (0.1, 0.7);
        let depths: Vec<f32> = (0..w * 10).map(|k| a + b * ((k % w) as f32 + 0.5) / w as f32).collect();
        let field = HeightField::from_depths(w, 10, depths).unwrap();
        let (size, depth_scale) = (Vec2::new(3.0, 1.0), 0.2);
        let m = Mesh::plane(size, 1).displaced(&field, EdgeMode::Clamp, depth_scale, 0.5);
        assert_valid(&m);
        let l = (size.x * size.y).sqrt();
        let lo = 0.5 / w as f32;
        let mut interior = 0;
        for (v, p) in m.positions.iter().enumerate() {
            let u = m.uvs[v].x;
            let d = a + b * u.clamp(lo, 1.0 - lo);
            assert!((p.y + d * depth_scale * l).abs() < 1e-5, "vertex {v} u {u}: {p}");
            assert!((p.x - (u - 0.5) * size.x).abs() < 1e-6, "vertices move straight down");
            if u > 2.0 * lo && u < 1.0 - 2.0 * lo {
                interior += 1;
                // The surface y = -(a + b u) ds L with u = x / sx + 0.5: slope -b ds L / sx.
                let expected = Vec3::new(b * depth_scale * l / size.x, 1.0, 0.0);
                assert!(degrees(m.normals[v], expected) < 1e-2, "normal {v}: {}", m.normals[v]);
            }
        }
        assert!(interior > 100);
    }

    /// Expected vertex count: originals + (parts - 1) per edge + interior per triangle.
    fn expected_vertices(m: &Mesh, size: Vec2, max_edge: f32) -> usize {
        let part = |p: u32, q: u32| {
            let d = (m.uvs[p as usize] - m.uvs[q as usize]).as_dvec2() * size.as_dvec2();
            (d.length() / f64::from(max_edge)).ceil() as u32
        };
        let mut edges = HashMap::new();
        let mut total = m.positions.len();
        for tri in m.indices.chunks_exact(3) {
            let mut n = 1;
            for k in 0..3 {
                let (p, q) = (tri[k], tri[(k + 1) % 3]);
                let parts = part(p, q).max(1);
                n = n.max(parts);
                edges.insert((p.min(q), p.max(q)), parts);
            }
            total += interior_count(n) as usize;
        }
        total + edges.values().map(|&p| p as usize - 1).sum::<usize>()
    }

    #[test]
    fn subdivision_grows_with_finer_edges_and_has_no_cracks() {
        let field = HeightField::from_height_fn(64, 48, |x, y| ((x * 7 + y * 3) % 11) as f32 / 10.0);
        let plane = Mesh::plane(Vec2::new(2.0, 1.0), 2);
        let mut previous = 0;
        for max_edge in [64.0, 16.0, 8.0, 4.0, 3.0, 1.5] {
            let m = plane.displaced(&field, EdgeMode::Wrap, 0.1, max_edge);
            assert_valid(&m);
            assert_eq!(m.positions.len(), expected_vertices(&plane, Vec2::new(64.0, 48.0), max_edge), "{max_edge}");
            assert!(m.triangle_count() > previous, "{max_edge}");
            previous = m.triangle_count();
            // Watertight: every edge is used twice (in opposite directions) except on the
            // boundary, whose edge count is the subdivided perimeter.
            let uses = edge_uses(&m);
            let boundary = uses.values().filter(|u| u.len() == 1).count();
            let per_side = |texels: f32| 2 * (texels / 2.0 / max_edge).ceil().max(1.0) as usize;
            assert_eq!(boundary, 2 * per_side(64.0) + 2 * per_side(48.0), "{max_edge}");
            // No folds: the UV area is covered once.
            let (total, most_negative) = uv_areas(&m);
            assert!((total - 1.0).abs() < 1e-6 && most_negative > -1e-9, "{total} {most_negative}");
        }
        // Roughly four times the triangles for half the edge length.
        let coarse = plane.displaced(&field, EdgeMode::Wrap, 0.1, 4.0).triangle_count() as f64;
        let fine = plane.displaced(&field, EdgeMode::Wrap, 0.1, 2.0).triangle_count() as f64;
        assert!((3.5..4.5).contains(&(fine / coarse)), "{}", fine / coarse);
    }

    #[test]
    fn uneven_triangles_stay_watertight_and_unfolded() {
        // A fan of triangles of very different UV sizes around a shared centre, plus slivers,
        // so that edges shared by a big and a small triangle get fewer parts than the big one.
        let mut positions = vec![Vec3::ZERO];
        let mut uvs = vec![Vec2::splat(0.5)];
        let rim = [0.05f32, 0.45, 0.1, 0.3, 0.02, 0.4, 0.2, 0.45];
        for (k, r) in rim.iter().enumerate() {
            let a = k as f32 / rim.len() as f32 * std::f32::consts::TAU;
            positions.push(Vec3::new(r * a.cos(), 0.0, r * a.sin()));
            uvs.push(Vec2::splat(0.5) + Vec2::new(a.cos(), a.sin()) * *r);
        }
        let k = rim.len() as u32;
        let indices: Vec<u32> = (0..k).flat_map(|i| [0, 1 + (i + 1) % k, 1 + i]).collect();
        let fan = Mesh::new(positions, None, uvs, indices, TangentMethod::MikkTSpace).unwrap();
        let field = HeightField::from_height_fn(37, 23, |x, y| ((x * y) % 5) as f32 / 4.0);
        let original = uv_areas(&fan).0;
        assert!(original > 0.0);
        for max_edge in [7.0, 3.0, 1.3, 0.6] {
            let m = fan.displaced(&field, EdgeMode::Clamp, 0.05, max_edge);
            assert_valid(&m);
            let uses = edge_uses(&m);
            let (total, most_negative) = uv_areas(&m);
            assert!((total - original).abs() < 1e-6 && most_negative > -1e-9, "{max_edge}: {total} {most_negative}");
            // Boundary: the rim edges, each split into its own parts.
            let boundary = uses.values().filter(|u| u.len() == 1).count();
            let rim_parts: usize = (0..k as usize)
                .map(|i| {
                    let d = (fan.uvs[1 + i] - fan.uvs[1 + (i + 1) % k as usize]) * Vec2::new(37.0, 23.0);
                    (d.length() / max_edge).ceil().max(1.0) as usize
                })
                .sum();
            assert_eq!(boundary, rim_parts, "{max_edge}");
        }
    }

    #[test]
    fn displacement_is_capped_and_never_nan() {
        let field = HeightField::from_height_fn(512, 512, |x, y| ((x ^ y) & 15) as f32 / 15.0);
        let sphere = Mesh::uv_sphere(1.0, 8, 12);
        let capped = sphere.displaced_capped(&field, EdgeMode::Wrap, 0.1, 0.25, 20_000, true).unwrap();
        assert_valid(&capped);
        assert!(capped.triangle_count() <= 20_000 && capped.triangle_count() > 15_000, "{}", capped.triangle_count());
        // More triangles than the cap to begin with: copied, not subdivided.
        let tiny = sphere.displaced_capped(&field, EdgeMode::Wrap, 0.1, 0.25, 10, true).unwrap();
        assert_eq!(tiny.triangle_count(), sphere.triangle_count());
        // Bad parameters: no displacement, finest/one-texel subdivision.
        for ds in [f32::NAN, -1.0, 0.0, f32::INFINITY] {
            let m = sphere.displaced_capped(&field, EdgeMode::Clamp, ds, f32::NAN, 50_000, true).unwrap();
            assert_valid(&m);
            for (p, n) in m.positions.iter().zip(&m.normals) {
                assert!(p.length() <= 1.0 + 1e-5 && n.dot(p.normalize()) > 0.8, "{p} {n}");
            }
        }
        // A huge depth scale saturates instead of overflowing.
        assert_valid(&sphere.displaced_capped(&field, EdgeMode::Clamp, 1e38, 64.0, 50_000, true).unwrap());
        // An inconsistent mesh (edited fields) is repaired, not a panic.
        let mut broken = Mesh::quad(Vec2::ONE);
        broken.indices.extend([0, 1, 9]);
        broken.normals.pop();
        broken.uvs[2] = Vec2::NAN;
        broken.uv_scale.clear();
        let m = broken.displaced(&field, EdgeMode::Wrap, 0.1, 64.0);
        assert_valid(&m);
        assert_valid(&broken.transformed(Mat4::from_rotation_z(1.0)));
    }

    #[test]
    fn sphere_vertices_move_inward_by_depth_times_l() {
        let (r, c, depth_scale) = (1.5, 0.5, 0.1);
        let s = Mesh::uv_sphere(r, 12, 16);
        let m = s.displaced(&HeightField::constant(64, 64, c), EdgeMode::Wrap, depth_scale, 2.0);
        assert_valid(&m);
        assert!(m.positions.len() > 4 * s.positions.len());
        // The original vertices come first and move along their exact normals.
        for v in 0..s.positions.len() {
            let inward = c * depth_scale * uv_unit_length(s.uv_scale[v]);
            assert!((m.positions[v] - (s.positions[v] - s.normals[v] * inward)).length() < 1e-5, "{v}");
            assert!((m.uvs[v], m.uv_scale[v]) == (s.uvs[v], s.uv_scale[v]));
        }
        // New vertices lie on chords, then move inward: inside the original sphere.
        assert!(m.positions.iter().all(|p| p.length() < r));
    }
}
