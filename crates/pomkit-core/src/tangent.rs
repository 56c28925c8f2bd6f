//! Tangent frames for triangle meshes: area-weighted vertex normals and per-vertex tangents.
//!
//! # Conventions (ARCHITECTURE.md)
//!
//! Tangent space is glTF 2.0's: x = T, y = B, z = N. A vertex tangent is a [`Vec4`] whose `xyz`
//! is the unit tangent T, perpendicular to the unit vertex normal N, and whose `w` is the
//! handedness, +1 or -1; the bitangent is rebuilt as `B = w * cross(N, T)` (Lengyel eq. 7.40).
//!
//! - T points along increasing u.
//! - B points along *decreasing* v, that is up the image, because UV `(0, 0)` is the top-left
//!   corner of the image. Both methods therefore work with `v' = 1 - v`: a quad whose texture
//!   is not mirrored (u to the right, v down the image, seen from the front) gets `w = +1`, and a
//!   UV island mirrored in u (or in v) gets `w = -1`. A tangent-space direction `(x, y, z)`
//!   moves in UV by `(x, -y)`.
//! - Triangles wound counter-clockwise, seen from the side their normal points to, are front
//!   faces ([`compute_vertex_normals`] makes normals point to that side).
//!
//! # Methods
//!
//! [`TangentMethod::MikkTSpace`] (the default) runs Morten Mikkelsen's algorithm through the
//! `bevy_mikktspace` crate: it is what Blender, Substance and the glTF sample models bake against,
//! so normal maps made by those tools shade without seams. [`TangentMethod::Lengyel`] is the
//! method of Lengyel, *Foundations of Game Engine Development, Vol. 2: Rendering*, section 7.5:
//! per-triangle tangent and bitangent from eq. 7.37, summed per vertex, then Gram-Schmidt
//! (eq. 7.38) and the handedness from the sign of `det(M_tangent)` (eq. 7.40).
//!
//! # Errata (docs/REFERENCES.md, Errata)
//!
//! Lengyel's Listing 7.4 prints `x1 = w1.x - w1.x` and `y2 = w2.y - w1.y`; they are misprints of
//! `w1.x - w0.x` and `w2.y - w0.y`, which is what eq. 7.34 says and what [`compute_tangents`]
//! implements. The listing's `r = 1 / (x1 * y2 - x2 * y1)` divides by zero when a triangle's
//! UVs are degenerate; here such a triangle (and a triangle of zero area) contributes nothing.
//!
//! # Robustness
//!
//! The functions validate their input (see [`TangentError`]) and otherwise never panic and never
//! return a non-finite value. A vertex that ends up with no usable tangent (no triangle with
//! usable UVs touches it, or its summed tangent is parallel to its normal) gets a fixed
//! fallback: `N.any_orthonormal_vector()` from glam with `w = +1`. A zero-length input normal is
//! replaced by the area-weighted geometric normal of the vertex (+Z when that is zero too).

use std::panic::{AssertUnwindSafe, catch_unwind};

use glam::{DVec3, Vec2, Vec3, Vec4};
use thiserror::Error;

/// How [`compute_tangents`] derives tangents from positions and UVs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TangentMethod {
    /// Mikkelsen's MikkTSpace, the tangent space that glTF 2.0 prescribes when a file carries
    /// no tangents and that common bakers use. Pick it when the normal map was baked by another
    /// tool. It costs roughly ten times as much as [`TangentMethod::Lengyel`] (0.6 s against
    /// 0.05 s for a 262k-triangle sphere in a release build, one core), and `weld_seams` does
    /// not apply to it.
    #[default]
    MikkTSpace,
    /// Lengyel's sum of per-triangle tangents (section 7.5, eq. 7.37 to 7.40), optionally welded
    /// across UV seams. Cheap and smooth; matches maps baked in pomkit's own texture space
    /// (height-to-normal bakes), but not exactly the maps of tools that bake with MikkTSpace.
    Lengyel,
}

/// The default of [`TangentOptions::weld_cos_threshold`]: `cos 45°`.
pub const DEFAULT_WELD_COS_THRESHOLD: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// Options of [`compute_tangents`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentOptions {
    /// The method; [`TangentMethod::MikkTSpace`] by default.
    pub method: TangentMethod,
    /// Average the tangents of vertices that are duplicated along UV seams (Lengyel 7.5), so
    /// that the seam does not show as an abrupt change of shading. Default `true`.
    ///
    /// Duplicates are vertices with bit-identical positions (+0 and -0 count as equal). Within
    /// one position, vertices with the same handedness whose tangents are within
    /// [`weld_cos_threshold`](Self::weld_cos_threshold) of each other have their tangent sums
    /// merged (greedy clustering around the first vertex of each cluster, at most 64 clusters
    /// per position); each vertex then orthonormalizes the merged sum against its own normal
    /// and keeps its own handedness. Costs one sort of the vertices.
    ///
    /// Applies to [`TangentMethod::Lengyel`] only: MikkTSpace output must stay exactly what
    /// the baking tools computed, or their normal maps show the very seams welding hides.
    /// (MikkTSpace already shares one tangent between vertices whose position, normal and UV
    /// are all equal.)
    pub weld_seams: bool,
    /// The cosine of the largest angle between two duplicates' tangents that still welds them;
    /// default [`DEFAULT_WELD_COS_THRESHOLD`] (`cos 45°`). Lower values weld more (smoother
    /// seams, but tangents that really differ get bent toward each other); `1.0` or more (or
    /// NaN) welds nothing; `-1.0` welds every pair of the same handedness.
    pub weld_cos_threshold: f32,
}

impl Default for TangentOptions {
    fn default() -> Self {
        Self { method: TangentMethod::default(), weld_seams: true, weld_cos_threshold: DEFAULT_WELD_COS_THRESHOLD }
    }
}

/// Why [`compute_tangents`] or [`compute_vertex_normals`] rejected a mesh.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TangentError {
    /// A triangle refers to a vertex index not below the number of vertices.
    #[error("triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        /// The triangle, counting from 0 (its indices start at `3 * triangle`).
        triangle: usize,
        /// The offending vertex index.
        index: u32,
        /// The number of vertices (the length of `positions`).
        vertex_count: usize,
    },
    /// The index list's length is not a multiple of 3 (the mesh must be a triangle list).
    #[error("the index count {count} is not a multiple of 3")]
    IndexCountNotMultipleOf3 {
        /// The length of the index list.
        count: usize,
    },
    /// `positions`, `normals` and `uvs` do not all have the same length.
    #[error("attribute lengths differ: {positions} positions, {normals} normals, {uvs} UVs")]
    AttributeLengthMismatch {
        /// The number of positions.
        positions: usize,
        /// The number of normals.
        normals: usize,
        /// The number of UVs.
        uvs: usize,
    },
    /// A vertex position has a NaN or infinite component (the first such vertex is named).
    #[error("the position of vertex {vertex} is not finite: {value}")]
    NonFinitePosition {
        /// The vertex.
        vertex: usize,
        /// Its position.
        value: Vec3,
    },
    /// A vertex normal has a NaN or infinite component (the first such vertex is named).
    #[error("the normal of vertex {vertex} is not finite: {value}")]
    NonFiniteNormal {
        /// The vertex.
        vertex: usize,
        /// Its normal.
        value: Vec3,
    },
    /// A vertex UV has a NaN or infinite component (the first such vertex is named).
    #[error("the UV of vertex {vertex} is not finite: {value}")]
    NonFiniteUv {
        /// The vertex.
        vertex: usize,
        /// Its UV.
        value: Vec2,
    },
}

/// Area-weighted vertex normals of a triangle list.
///
/// Each triangle `(p0, p1, p2)` adds `cross(p1 - p0, p2 - p0)` (twice its area times its unit
/// normal) to its three vertices, so a counter-clockwise triangle seen from the front adds a
/// normal pointing toward the viewer; each sum is then normalized. A vertex that no triangle of
/// non-zero area touches (or whose contributions cancel) gets `+Z`. Computed in `f64`, so huge
/// or tiny coordinates do not overflow.
///
/// # Errors
///
/// [`TangentError::IndexCountNotMultipleOf3`], [`TangentError::NonFinitePosition`] and
/// [`TangentError::IndexOutOfRange`], checked in that order.
pub fn compute_vertex_normals(positions: &[Vec3], indices: &[u32]) -> Result<Vec<Vec3>, TangentError> {
    check_index_count(indices)?;
    check_positions(positions)?;
    check_indices(indices, positions.len())?;
    Ok(geometric_normals(positions, indices))
}

/// One tangent per vertex: `xyz` unit length and perpendicular to the vertex normal, `w` = ±1.
///
/// `normals` need not be unit length (they are normalized; a zero normal is replaced as the
/// [module documentation](self) says); `uvs` follow glTF (`(0, 0)` at the top-left of the
/// image). The bitangent is `w * cross(N, T)` and points along decreasing v. See
/// [`TangentOptions`] for the method and seam welding, and the module documentation for the
/// conventions and the fallback given to vertices without a usable tangent.
///
/// With [`TangentMethod::MikkTSpace`], MikkTSpace may give one vertex different tangents in
/// different triangles (it splits vertices where the UV mapping changes handedness); since
/// this function returns one tangent per input vertex, the tangents of the handedness that
/// most of the vertex's triangle corners have are averaged (ties go to `w = +1`). Meshes of
/// 2^29 triangles or more, and the unlikely case of `mikktspace` failing, use Lengyel's method.
///
/// # Errors
///
/// [`TangentError::AttributeLengthMismatch`], [`TangentError::IndexCountNotMultipleOf3`],
/// [`TangentError::NonFinitePosition`], [`TangentError::NonFiniteNormal`],
/// [`TangentError::NonFiniteUv`] and [`TangentError::IndexOutOfRange`], checked in that order.
pub fn compute_tangents(
    positions: &[Vec3],
    normals: &[Vec3],
    uvs: &[Vec2],
    indices: &[u32],
    opts: &TangentOptions,
) -> Result<Vec<Vec4>, TangentError> {
    if positions.len() != normals.len() || positions.len() != uvs.len() {
        return Err(TangentError::AttributeLengthMismatch {
            positions: positions.len(),
            normals: normals.len(),
            uvs: uvs.len(),
        });
    }
    check_index_count(indices)?;
    check_positions(positions)?;
    if let Some(vertex) = normals.iter().position(|n| !n.is_finite()) {
        return Err(TangentError::NonFiniteNormal { vertex, value: normals[vertex] });
    }
    if let Some(vertex) = uvs.iter().position(|uv| !uv.is_finite()) {
        return Err(TangentError::NonFiniteUv { vertex, value: uvs[vertex] });
    }
    check_indices(indices, positions.len())?;

    let unit_normals = unit_normals(positions, normals, indices);
    let mesh = Mesh { positions, normals: &unit_normals, uvs, indices };
    let tangents = match opts.method {
        TangentMethod::MikkTSpace => mikktspace_tangents(&mesh).unwrap_or_else(|| lengyel_tangents(&mesh, None)),
        TangentMethod::Lengyel => lengyel_tangents(&mesh, opts.weld_seams.then_some(opts.weld_cos_threshold)),
    };
    Ok(tangents)
}

// ---------------------------------------------------------------------------------------------
// Validation
// ---------------------------------------------------------------------------------------------

fn check_index_count(indices: &[u32]) -> Result<(), TangentError> {
    if indices.len().is_multiple_of(3) {
        Ok(())
    } else {
        Err(TangentError::IndexCountNotMultipleOf3 { count: indices.len() })
    }
}

fn check_positions(positions: &[Vec3]) -> Result<(), TangentError> {
    match positions.iter().position(|p| !p.is_finite()) {
        Some(vertex) => Err(TangentError::NonFinitePosition { vertex, value: positions[vertex] }),
        None => Ok(()),
    }
}

fn check_indices(indices: &[u32], vertex_count: usize) -> Result<(), TangentError> {
    match indices.iter().position(|&i| i as usize >= vertex_count) {
        Some(k) => Err(TangentError::IndexOutOfRange { triangle: k / 3, index: indices[k], vertex_count }),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Shared helpers. Everything below runs on validated input: finite attributes, indices in range,
// a whole number of triangles.
// ---------------------------------------------------------------------------------------------

/// Validated mesh with unit normals.
struct Mesh<'a> {
    positions: &'a [Vec3],
    normals: &'a [Vec3],
    uvs: &'a [Vec2],
    indices: &'a [u32],
}

/// A tangent whose component perpendicular to the normal is shorter than this fraction of its
/// length is taken as parallel to the normal (its direction would be rounding noise).
const PARALLEL_EPS: f64 = 1e-4;

/// A triangle whose `|cross(e1, e2)|` is at most this fraction of `|e1| |e2|` (the sine of its
/// angle at vertex 0) has zero area for Lengyel's method.
const AREA_EPS: f64 = 1e-7;

/// A triangle whose UV determinant is at most this fraction of the product of its two UV edge
/// lengths (the sine of the UV angle at vertex 0) has degenerate UVs for Lengyel's method.
const UV_EPS: f64 = 1e-6;

/// The unit vector along `v`, or `None` when `v` is zero or not finite. Scales by the largest
/// component first, so that neither tiny nor huge vectors underflow or overflow.
fn unit_or_none(v: DVec3) -> Option<DVec3> {
    let m = v.abs().max_element();
    if !(m > 0.0 && m.is_finite()) {
        return None;
    }
    (v / m).try_normalize()
}

/// `t` made perpendicular to the unit `n` and unit length (eq. 7.38), or `None` when `t` is
/// zero, not finite, or (nearly) parallel to `n`.
fn reject_normalize(t: DVec3, n: DVec3) -> Option<DVec3> {
    let t = unit_or_none(t)?;
    let r = t - n * n.dot(t);
    if r.length() > PARALLEL_EPS { r.try_normalize() } else { None }
}

/// The output tangent for a vertex, with all invariants enforced in `f32`: the fallback
/// `n.any_orthonormal_vector()` with `w = +1` when `t` is unusable.
fn finish(t: Option<DVec3>, w: f64, n: Vec3) -> Vec4 {
    let n64 = n.as_dvec3();
    let t32 = t.and_then(|t| reject_normalize(t, n64)).map(DVec3::as_vec3);
    // Re-orthonormalize in f32, since the conversion rounds.
    let t32 = t32.map(|t| t - n * n.dot(t)).and_then(Vec3::try_normalize);
    match t32 {
        Some(t) => t.extend(if w < 0.0 { -1.0 } else { 1.0 }),
        None => n.any_orthonormal_vector().extend(1.0),
    }
}

/// Sums of area-weighted face normals, in `f64`.
fn normal_sums(positions: &[Vec3], indices: &[u32]) -> Vec<DVec3> {
    let mut sums = vec![DVec3::ZERO; positions.len()];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let p0 = positions[a].as_dvec3();
        let face = (positions[b].as_dvec3() - p0).cross(positions[c].as_dvec3() - p0);
        for v in [a, b, c] {
            sums[v] += face;
        }
    }
    sums
}

fn geometric_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    normal_sums(positions, indices).into_iter().map(|s| unit_or_none(s).map_or(Vec3::Z, DVec3::as_vec3)).collect()
}

/// The input normals normalized; zero ones replaced by the geometric normal (or +Z).
fn unit_normals(positions: &[Vec3], normals: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut geometric: Option<Vec<Vec3>> = None;
    (0..normals.len())
        .map(|v| match unit_or_none(normals[v].as_dvec3()) {
            Some(n) => n.as_vec3().try_normalize().unwrap_or(Vec3::Z),
            None => geometric.get_or_insert_with(|| geometric_normals(positions, indices))[v],
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Lengyel, section 7.5
// ---------------------------------------------------------------------------------------------

/// Lengyel's tangents, welded across seams when `weld_cos` is given.
fn lengyel_tangents(mesh: &Mesh<'_>, weld_cos: Option<f32>) -> Vec<Vec4> {
    let (mut tsum, mut bsum) = lengyel_sums(mesh);
    if let Some(cos) = weld_cos {
        weld(mesh, &mut tsum, &mut bsum, f64::from(cos));
    }
    (0..mesh.positions.len())
        .map(|v| {
            let n = mesh.normals[v];
            match frame(tsum[v], bsum[v], n.as_dvec3()) {
                Some((t, w)) => finish(Some(t), w, n),
                None => finish(None, 1.0, n),
            }
        })
        .collect()
}

/// Per-vertex sums of the per-triangle tangents t and bitangents b of eq. 7.37, in `f64`.
///
/// With `e1 = p1 - p0`, `e2 = p2 - p0`, `(x_k, y_k) = uv_k - uv_0` (eq. 7.34; Listing 7.4 has
/// `x1 = w1.x - w1.x` and `y2 = w2.y - w1.y`, misprints of `w1.x - w0.x` and `w2.y - w0.y`):
/// `t = (y2 e1 - y1 e2) / det`, `b = (x1 e2 - x2 e1) / det`, `det = x1 y2 - x2 y1`.
/// The y are differences of `v' = 1 - v` (ARCHITECTURE.md, Conventions), so b points along decreasing v.
fn lengyel_sums(mesh: &Mesh<'_>) -> (Vec<DVec3>, Vec<DVec3>) {
    let n = mesh.positions.len();
    let (mut tsum, mut bsum) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
    for tri in mesh.indices.chunks_exact(3) {
        let [i0, i1, i2] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let p0 = mesh.positions[i0].as_dvec3();
        let e1 = mesh.positions[i1].as_dvec3() - p0;
        let e2 = mesh.positions[i2].as_dvec3() - p0;
        // Zero-area triangles contribute nothing (their tangent would lie along a line). The
        // products are finite: differences of f32 values cannot overflow f64.
        if e1.cross(e2).length() <= AREA_EPS * e1.length() * e2.length() {
            continue;
        }
        let w0 = mesh.uvs[i0].as_dvec2();
        let (w1, w2) = (mesh.uvs[i1].as_dvec2(), mesh.uvs[i2].as_dvec2());
        let (x1, x2) = (w1.x - w0.x, w2.x - w0.x);
        // v' = 1 - v, so v' differences are negated v differences.
        let (y1, y2) = (w0.y - w1.y, w0.y - w2.y);
        let det = x1 * y2 - x2 * y1;
        // Listing 7.4 divides by det unconditionally; skip degenerate UVs instead. The test is
        // relative to the UV edge lengths, so it does not depend on the texture's scale.
        if det.abs() <= UV_EPS * x1.hypot(y1) * x2.hypot(y2) {
            continue;
        }
        let r = det.recip();
        let t = (e1 * y2 - e2 * y1) * r;
        let b = (e2 * x1 - e1 * x2) * r;
        if !(t.is_finite() && b.is_finite()) {
            continue;
        }
        for v in [i0, i1, i2] {
            tsum[v] += t;
            bsum[v] += b;
        }
    }
    (tsum, bsum)
}

/// The orthonormalized tangent (eq. 7.38) and handedness `sign(dot(cross(t, b), n))` of a
/// vertex from its sums, or `None` when the tangent sum is unusable. A zero handedness
/// determinant (no usable bitangent) counts as `+1`.
fn frame(tsum: DVec3, bsum: DVec3, n: DVec3) -> Option<(DVec3, f64)> {
    let t = reject_normalize(tsum, n)?;
    // cross(tsum, b) . n == cross(t, b) . n up to a positive factor (the n part of tsum drops
    // out); the unit b keeps the product finite.
    let det = unit_or_none(bsum).map_or(0.0, |b| t.cross(b).dot(n));
    Some((t, if det < 0.0 { -1.0 } else { 1.0 }))
}

/// The bits of a position, with -0 and +0 made equal.
fn position_key(p: Vec3) -> [u32; 3] {
    p.to_array().map(|c| if c == 0.0 { 0 } else { c.to_bits() })
}

/// Seam welding forms at most this many clusters per position (later vertices that match none
/// stay unwelded), which bounds the work on meshes with thousands of vertices at one point.
const MAX_WELD_CLUSTERS: usize = 64;

/// Seam welding (Lengyel 7.5): merges the sums of duplicated vertices whose frames have the
/// same handedness and whose tangents' cosine exceeds `cos`. The vertex's own normal and
/// handedness are applied afterwards, so only the tangent direction is shared.
fn weld(mesh: &Mesh<'_>, tsum: &mut [DVec3], bsum: &mut [DVec3], cos: f64) {
    let mut order: Vec<([u32; 3], usize)> =
        mesh.positions.iter().enumerate().map(|(v, &p)| (position_key(p), v)).collect();
    order.sort_unstable();
    // (representative tangent, handedness, merged tangent sum)
    let mut clusters: Vec<(DVec3, f64, DVec3)> = Vec::new();
    let mut member_of: Vec<(usize, usize)> = Vec::new();
    for run in order.chunk_by(|a, b| a.0 == b.0).filter(|run| run.len() > 1) {
        clusters.clear();
        member_of.clear();
        for &(_, v) in run {
            let Some((t, w)) = frame(tsum[v], bsum[v], mesh.normals[v].as_dvec3()) else {
                continue;
            };
            let found = clusters.iter().position(|c| c.1 == w && c.0.dot(t) > cos);
            let c = match found {
                Some(c) => c,
                None if clusters.len() < MAX_WELD_CLUSTERS => {
                    clusters.push((t, w, DVec3::ZERO));
                    clusters.len() - 1
                }
                None => continue,
            };
            // Sums can be of very different magnitudes (Lengyel's t scales with the ratio of
            // position to UV lengths), so add them as they are, as section 7.5 averages them.
            clusters[c].2 += tsum[v];
            member_of.push((v, c));
        }
        for &(v, c) in &member_of {
            let (_, w, merged_t) = clusters[c];
            let n = mesh.normals[v].as_dvec3();
            // A merged sum parallel to this vertex's normal (possible at hard edges) leaves the
            // vertex as it was.
            if reject_normalize(merged_t, n).is_some() {
                tsum[v] = merged_t;
                // Keep the vertex's own handedness: a bitangent that reproduces it.
                bsum[v] = n.cross(merged_t) * w;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// MikkTSpace
// ---------------------------------------------------------------------------------------------

/// Per-vertex sums of the face-corner tangents MikkTSpace produced, split by handedness.
#[derive(Clone, Copy, Default)]
struct SignedSums {
    positive: Vec3,
    positive_count: u32,
    negative: Vec3,
    negative_count: u32,
}

/// `bevy_mikktspace::Geometry` over the validated slices. Positions and UVs are scaled by powers of
/// two (exact, and tangent directions, handedness and vertex identity do not change under
/// uniform scaling) so that MikkTSpace's `f32` arithmetic neither overflows on huge meshes nor
/// treats tiny ones as degenerate.
struct MikkAdapter<'a> {
    mesh: &'a Mesh<'a>,
    position_scale: f32,
    uv_scale: f32,
    sums: Vec<SignedSums>,
}

impl MikkAdapter<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        self.mesh.indices.get(face * 3 + vert.min(2)).map_or(0, |&i| i as usize)
    }
}

impl bevy_mikktspace::Geometry for MikkAdapter<'_> {
    fn num_faces(&self) -> usize {
        self.mesh.indices.len() / 3
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.mesh.positions.get(self.vertex(face, vert)).map_or([0.0; 3], |p| (*p * self.position_scale).to_array())
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.mesh.normals.get(self.vertex(face, vert)).map_or([0.0, 0.0, 1.0], |n| n.to_array())
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        // v' = 1 - v (ARCHITECTURE.md, Conventions): MikkTSpace's bitangent then points along decreasing
        // v and an unmirrored quad is orientation preserving (w = +1).
        self.mesh
            .uvs
            .get(self.vertex(face, vert))
            .map_or([0.0; 2], |uv| [uv.x * self.uv_scale, (1.0 - uv.y) * self.uv_scale])
    }

    fn set_tangent(&mut self, tangent_space: Option<bevy_mikktspace::TangentSpace>, face: usize, vert: usize) {
        // No tangent space for this corner (a degenerate face with no neighbour to borrow
        // from): the vertex's other corners, or the fallback, decide.
        let Some(ts) = tangent_space else { return };
        self.add(ts.tangent_encoded(), face, vert);
    }
}

impl MikkAdapter<'_> {
    /// Adds one corner's tangent `(x, y, z, w)` to its vertex's sums.
    fn add(&mut self, tangent: [f32; 4], face: usize, vert: usize) {
        let v = self.vertex(face, vert);
        let t = Vec3::new(tangent[0], tangent[1], tangent[2]);
        // MikkTSpace can emit zero tangents (on slivers); those are left to the fallback.
        let (Some(t), Some(sums)) = (t.try_normalize(), self.sums.get_mut(v)) else {
            return;
        };
        if tangent[3] < 0.0 {
            sums.negative += t;
            sums.negative_count += 1;
        } else {
            sums.positive += t;
            sums.positive_count += 1;
        }
    }
}

/// The power of two that brings `max_abs` to about 1 (1 for zero).
fn power_of_two_scale(max_abs: f32) -> f32 {
    if !(max_abs > 0.0 && max_abs.is_finite()) {
        return 1.0;
    }
    let e = (max_abs.log2().ceil() as i32).clamp(-125, 125);
    // An exact power of two, built from its exponent bits.
    f32::from_bits(((127 - e) as u32) << 23)
}

/// MikkTSpace tangents (bevy_mikktspace), or `None` when the mesh is too large for it or it
/// failed.
fn mikktspace_tangents(mesh: &Mesh<'_>) -> Option<Vec<Vec4>> {
    let mut adapter = MikkAdapter::new(mesh)?;
    // bevy_mikktspace is safe Rust and handles degenerate meshes (every triangle with two
    // equal positions included, where the C port it replaces read out of bounds). Should it
    // panic all the same, fall back to Lengyel rather than take the caller down.
    catch_unwind(AssertUnwindSafe(|| bevy_mikktspace::generate_tangents(&mut adapter))).ok()?.ok()?;
    Some(adapter.resolve())
}

impl<'a> MikkAdapter<'a> {
    /// The adapter, with its power-of-two scales; `None` when the mesh has too many triangles
    /// for MikkTSpace, which stores `face << 2 | corner` in an i32.
    fn new(mesh: &'a Mesh<'a>) -> Option<Self> {
        if mesh.indices.len() / 3 > (i32::MAX >> 2) as usize {
            return None;
        }
        let max_position = mesh.positions.iter().fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let max_uv = mesh.uvs.iter().fold(0.0f32, |m, uv| m.max(uv.x.abs()).max((1.0 - uv.y).abs()));
        Some(MikkAdapter {
            mesh,
            position_scale: power_of_two_scale(max_position),
            uv_scale: power_of_two_scale(max_uv),
            sums: vec![SignedSums::default(); mesh.positions.len()],
        })
    }

    /// Each vertex's tangent from its corners' sums: the handedness most corners have (their
    /// mean direction made perpendicular to the normal), else the other, else the fallback.
    fn resolve(&self) -> Vec<Vec4> {
        self.sums
            .iter()
            .zip(self.mesh.normals)
            .map(|(s, &n)| {
                let positive = (s.positive.as_dvec3(), 1.0);
                let negative = (s.negative.as_dvec3(), -1.0);
                let preferred =
                    if s.negative_count > s.positive_count { [negative, positive] } else { [positive, negative] };
                let n64 = n.as_dvec3();
                preferred
                    .into_iter()
                    .find_map(|(t, w)| reject_normalize(t, n64).map(|t| finish(Some(t), w, n)))
                    .unwrap_or_else(|| finish(None, 1.0, n))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{PI, TAU};

    type MeshData = (Vec<Vec3>, Vec<Vec3>, Vec<Vec2>, Vec<u32>);

    const BOTH: [TangentMethod; 2] = [TangentMethod::MikkTSpace, TangentMethod::Lengyel];

    fn opts(method: TangentMethod, weld_seams: bool) -> TangentOptions {
        TangentOptions { method, weld_seams, ..TangentOptions::default() }
    }

    fn degrees_between(a: Vec3, b: Vec3) -> f32 {
        a.normalize().dot(b.normalize()).clamp(-1.0, 1.0).acos().to_degrees()
    }

    fn bitangent(n: Vec3, t: Vec4) -> Vec3 {
        n.cross(t.truncate()) * t.w
    }

    /// Checks the invariants every output must satisfy.
    fn assert_valid(tangents: &[Vec4], normals: &[Vec3]) {
        assert_eq!(tangents.len(), normals.len());
        for (v, (t, n)) in tangents.iter().zip(normals).enumerate() {
            assert!(t.is_finite(), "vertex {v}: {t}");
            assert!(t.w == 1.0 || t.w == -1.0, "vertex {v}: w = {}", t.w);
            assert!((t.truncate().length() - 1.0).abs() < 1e-4, "vertex {v}: |t| = {}", t.truncate().length());
            if let Some(n) = n.try_normalize() {
                assert!(t.truncate().dot(n).abs() < 1e-4, "vertex {v}: t.n = {}", t.truncate().dot(n));
            }
        }
    }

    /// A unit square in the xy plane, normal +z, `cells` x `cells` quads, the top of the image
    /// at +y (v = 1 - y). `mirror_u` gives u = 1 - x instead of x.
    fn plane(cells: u32, mirror_u: bool) -> MeshData {
        let (mut p, mut uv, mut idx) = (vec![], vec![], vec![]);
        for j in 0..=cells {
            for i in 0..=cells {
                let (x, y) = (i as f32 / cells as f32, j as f32 / cells as f32);
                p.push(Vec3::new(x, y, 0.0));
                uv.push(Vec2::new(if mirror_u { 1.0 - x } else { x }, 1.0 - y));
            }
        }
        let at = |i: u32, j: u32| j * (cells + 1) + i;
        for j in 0..cells {
            for i in 0..cells {
                // Counter-clockwise seen from +z.
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                idx.extend([a, b, d, a, d, c]);
            }
        }
        let n = vec![Vec3::Z; p.len()];
        (p, n, uv, idx)
    }

    /// Grid triangles for a (columns + 1) x (rows + 1) vertex grid laid out column-major by
    /// row (`j * (columns + 1) + i`), with i along increasing u and j along increasing v,
    /// wound counter-clockwise when u runs to the right and v down, seen from outside.
    fn grid_indices(columns: u32, rows: u32) -> Vec<u32> {
        let at = |i: u32, j: u32| j * (columns + 1) + i;
        let mut idx = vec![];
        for j in 0..rows {
            for i in 0..columns {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
                idx.extend([a, c, b, b, c, d]);
            }
        }
        idx
    }

    /// A UV sphere around the z axis: u = longitude / 2 pi, v = colatitude / pi (v = 0 at the
    /// north pole +z), the seam column (u = 0 and u = 1) duplicated, poles duplicated per
    /// column. Normals are analytic.
    fn uv_sphere(columns: u32, rows: u32) -> MeshData {
        let (mut p, mut uv) = (vec![], vec![]);
        for j in 0..=rows {
            for i in 0..=columns {
                let (phi, theta) =
                    (TAU * f64::from(i % columns) / f64::from(columns), PI * f64::from(j) / f64::from(rows));
                let pos = if j == 0 {
                    DVec3::Z
                } else if j == rows {
                    -DVec3::Z
                } else {
                    DVec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
                };
                p.push(pos.as_vec3());
                uv.push(Vec2::new(i as f32 / columns as f32, j as f32 / rows as f32));
            }
        }
        let n = p.clone();
        (p, n, uv, grid_indices(columns, rows))
    }

    /// A cylinder of radius 1 around z, z in [0, 1], u = angle / 2 pi, v = 1 - z plus a shear
    /// `shear * u * (1 - u)` (0 for the plain mapping), seam column duplicated; analytic normals.
    fn cylinder(columns: u32, rows: u32, shear: f32) -> MeshData {
        let (mut p, mut n, mut uv) = (vec![], vec![], vec![]);
        for j in 0..=rows {
            for i in 0..=columns {
                let phi = TAU * f64::from(i % columns) / f64::from(columns);
                let z = 1.0 - j as f32 / rows as f32;
                p.push(Vec3::new(phi.cos() as f32, phi.sin() as f32, z));
                n.push(Vec3::new(phi.cos() as f32, phi.sin() as f32, 0.0));
                let u = i as f32 / columns as f32;
                uv.push(Vec2::new(u, 1.0 - z + shear * u * (1.0 - u)));
            }
        }
        (p, n, uv, grid_indices(columns, rows))
    }

    #[test]
    fn plane_gets_plus_x_and_w_plus_one() {
        let (p, n, uv, idx) = plane(4, false);
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert_valid(&t, &n);
            for (v, t) in t.iter().enumerate() {
                assert!(degrees_between(t.truncate(), Vec3::X) < 1e-3, "{method:?} vertex {v}: {t}");
                assert_eq!(t.w, 1.0, "{method:?} vertex {v}");
                // B = w cross(N, T) is up the image: +y.
                assert!(degrees_between(bitangent(n[v], *t), Vec3::Y) < 1e-3);
            }
        }
    }

    #[test]
    fn plane_mirrored_in_u_gets_minus_x_and_w_minus_one() {
        let (p, n, uv, idx) = plane(4, true);
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert_valid(&t, &n);
            for (v, t) in t.iter().enumerate() {
                assert!(degrees_between(t.truncate(), -Vec3::X) < 1e-3, "{method:?} vertex {v}: {t}");
                assert_eq!(t.w, -1.0, "{method:?} vertex {v}");
                // v is not mirrored, so the bitangent still points up the image.
                assert!(degrees_between(bitangent(n[v], *t), Vec3::Y) < 1e-3);
            }
        }
    }

    #[test]
    fn plane_mirrored_in_v_gets_w_minus_one() {
        let (p, n, mut uv, idx) = plane(3, false);
        for uv in &mut uv {
            uv.y = 1.0 - uv.y;
        }
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            for (v, t) in t.iter().enumerate() {
                assert!(degrees_between(t.truncate(), Vec3::X) < 1e-3, "{method:?} vertex {v}: {t}");
                assert_eq!(t.w, -1.0, "{method:?} vertex {v}");
                // The image's top is now at -y.
                assert!(degrees_between(bitangent(n[v], *t), -Vec3::Y) < 1e-3);
            }
        }
    }

    #[test]
    fn uv_sphere_tangents_follow_longitude_and_bitangents_point_north() {
        let (columns, rows) = (48, 24);
        let (p, n, uv, idx) = uv_sphere(columns, rows);
        for method in BOTH {
            for weld in [false, true] {
                let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, weld)).unwrap();
                assert_valid(&t, &n);
                let mut checked = 0;
                for j in 0..=rows {
                    let theta = PI * f64::from(j) / f64::from(rows);
                    // Away from the poles.
                    if !(PI / 8.0..=7.0 * PI / 8.0).contains(&theta) {
                        continue;
                    }
                    for i in 0..=columns {
                        let v = (j * (columns + 1) + i) as usize;
                        let phi = TAU * f64::from(i) / f64::from(columns);
                        // dP/du is along increasing longitude; north is -dP/dv.
                        let along_u = DVec3::new(-phi.sin(), phi.cos(), 0.0).as_vec3();
                        let north =
                            DVec3::new(-theta.cos() * phi.cos(), -theta.cos() * phi.sin(), theta.sin()).as_vec3();
                        // An unwelded seam copy sees the triangles on one side only, whose
                        // secant tangents tilt by up to half a column (3.5 degrees here).
                        let seam = i == 0 || i == columns;
                        let welded = weld && method == TangentMethod::Lengyel;
                        let tolerance = if seam && !welded { 4.0 } else { 1.0 };
                        let tv = t[v];
                        let what = format!("{method:?} weld {weld} vertex ({i}, {j}): {tv}");
                        assert_eq!(tv.w, 1.0, "{what}");
                        assert!(degrees_between(tv.truncate(), along_u) < tolerance, "{what}");
                        assert!(degrees_between(bitangent(n[v], tv), north) < tolerance, "{what}");
                        checked += 1;
                    }
                }
                assert!(checked > 500);
            }
        }
    }

    #[test]
    fn cylinder_tangents_follow_the_circumference() {
        let (columns, rows) = (32, 4);
        let (p, n, uv, idx) = cylinder(columns, rows, 0.0);
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert_valid(&t, &n);
            for j in 0..=rows {
                for i in 0..=columns {
                    let v = (j * (columns + 1) + i) as usize;
                    let phi = TAU * f64::from(i) / f64::from(columns);
                    let along_u = Vec3::new(-phi.sin() as f32, phi.cos() as f32, 0.0);
                    let tv = t[v];
                    let what = format!("{method:?} vertex ({i}, {j}): {tv}");
                    assert_eq!(tv.w, 1.0, "{what}");
                    assert!(degrees_between(tv.truncate(), along_u) < 1.0, "{what}");
                    // Up the image is +z (v = 0 at the top).
                    assert!(degrees_between(bitangent(n[v], tv), Vec3::Z) < 1.0, "{what}");
                }
            }
        }
    }

    /// Seam copies (i = 0 and i = columns) of each row of a sheared cylinder.
    fn seam_pairs(columns: u32, rows: u32) -> impl Iterator<Item = (usize, usize)> {
        (0..=rows).map(move |j| ((j * (columns + 1)) as usize, (j * (columns + 1) + columns) as usize))
    }

    #[test]
    fn lengyel_welds_seams_of_the_same_handedness() {
        // dv/du = shear (1 - 2u): the analytic tangents at u = 0 and u = 1 lean opposite ways,
        // 2 atan(1.5 / 2 pi) = 27 degrees apart, within the 45 degree threshold.
        let (columns, rows) = (32, 4);
        let (p, n, uv, idx) = cylinder(columns, rows, 1.5);
        let welded = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, true)).unwrap();
        let apart = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, false)).unwrap();
        assert_valid(&welded, &n);
        assert_valid(&apart, &n);
        for (a, b) in seam_pairs(columns, rows) {
            assert!((welded[a] - welded[b]).length() < 1e-5, "welded {a} {b}: {} {}", welded[a], welded[b]);
            assert!(degrees_between(apart[a].truncate(), apart[b].truncate()) > 15.0, "apart {a} {b}");
        }
        // The weld averages the two sides: on the rows where both copies have three triangles,
        // the tangent is along the circumference, +y here.
        for (a, _) in seam_pairs(columns, rows).skip(1).take(rows as usize - 1) {
            assert!(degrees_between(welded[a].truncate(), Vec3::Y) < 1e-3, "{a}: {}", welded[a]);
        }
        // Vertices off the seam are not touched by welding.
        for v in 0..p.len() {
            if v % (columns as usize + 1) != 0 && v % (columns as usize + 1) != columns as usize {
                assert_eq!(welded[v], apart[v]);
            }
        }
    }

    #[test]
    fn lengyel_does_not_weld_beyond_the_threshold() {
        // 2 atan(8 / 2 pi) = 104 degrees apart: more than 45.
        let (columns, rows) = (32, 4);
        let (p, n, uv, idx) = cylinder(columns, rows, 8.0);
        let welded = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, true)).unwrap();
        let apart = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, false)).unwrap();
        assert_eq!(welded, apart);
        // ... unless the threshold says so.
        let all = TangentOptions { weld_cos_threshold: -1.0, ..opts(TangentMethod::Lengyel, true) };
        let forced = compute_tangents(&p, &n, &uv, &idx, &all).unwrap();
        for (a, b) in seam_pairs(columns, rows) {
            assert!((forced[a] - forced[b]).length() < 1e-5);
        }
    }

    /// Two unit quads side by side in the xy plane sharing the edge x = 1 through duplicated
    /// vertices; the right quad's UVs are mirrored in u (`mirror_u`) or in v (a mirrored UV
    /// island).
    fn mirrored_halves(mirror_u: bool) -> MeshData {
        let mut p = vec![];
        let mut uv = vec![];
        for (k, x) in [0.0, 1.0, 1.0, 2.0].into_iter().enumerate() {
            for y in [0.0f32, 1.0] {
                p.push(Vec3::new(x, y, 0.0));
                let right = k >= 2;
                let u = if right && mirror_u { 2.0 - x } else { x };
                let v = if right && !mirror_u { y } else { 1.0 - y };
                uv.push(Vec2::new(u, v));
            }
        }
        // Vertices: 0 (0,0) 1 (0,1) | 2 (1,0) 3 (1,1) | 4 (1,0) 5 (1,1) | 6 (2,0) 7 (2,1).
        let idx = vec![0, 2, 3, 0, 3, 1, 4, 6, 7, 4, 7, 5];
        let n = vec![Vec3::Z; p.len()];
        (p, n, uv, idx)
    }

    #[test]
    fn welding_keeps_mirrored_copies_apart() {
        for mirror_u in [true, false] {
            let (p, n, uv, idx) = mirrored_halves(mirror_u);
            let right_t = if mirror_u { -Vec3::X } else { Vec3::X };
            for method in BOTH {
                let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
                let what = format!("{method:?} mirror_u {mirror_u}: {t:?}");
                for (v, tv) in t.iter().enumerate() {
                    let (expected_t, expected_w) = if v < 4 { (Vec3::X, 1.0) } else { (right_t, -1.0) };
                    assert!(degrees_between(tv.truncate(), expected_t) < 1e-3, "{what}");
                    assert_eq!(tv.w, expected_w, "{what}");
                }
            }
        }
    }

    #[test]
    fn a_vertex_shared_across_a_mirror_line_takes_its_majority_handedness() {
        // As `mirrored_halves(true)`, but the right quad uses vertices 2 and 3 themselves.
        // Vertex 2 has one corner on the left (w = +1) and two on the right (w = -1); vertex 3
        // the other way round.
        let (p, n, uv, _) = mirrored_halves(true);
        let idx = vec![0, 2, 3, 0, 3, 1, 2, 6, 7, 2, 7, 3];
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert_valid(&t, &n);
            let what = format!("{method:?}: {t:?}");
            assert!(degrees_between(t[2].truncate(), -Vec3::X) < 1e-3, "{what}");
            assert_eq!(t[2].w, -1.0, "{what}");
            assert!(degrees_between(t[3].truncate(), Vec3::X) < 1e-3, "{what}");
            assert_eq!(t[3].w, 1.0, "{what}");
        }
    }

    #[test]
    fn mikktspace_ignores_weld_seams() {
        let (p, n, uv, idx) = cylinder(16, 2, 1.5);
        let a = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::MikkTSpace, true)).unwrap();
        let b = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::MikkTSpace, false)).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn methods_agree_on_a_smooth_mapping() {
        let (p, n, uv, idx) = uv_sphere(24, 12);
        let m = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::MikkTSpace, false)).unwrap();
        let l = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, false)).unwrap();
        for v in 0..p.len() {
            let theta = f64::from(uv[v].y) * PI;
            if (PI / 8.0..=7.0 * PI / 8.0).contains(&theta) {
                assert_eq!(m[v].w, l[v].w);
                assert!(degrees_between(m[v].truncate(), l[v].truncate()) < 2.0, "{v}: {} {}", m[v], l[v]);
            }
        }
    }

    #[test]
    fn zero_area_triangle_gets_finite_perpendicular_tangents() {
        // Collinear positions with good UVs, and a triangle whose positions are all equal.
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::ONE,
            Vec3::ONE,
            Vec3::ONE,
        ];
        let n = vec![Vec3::Z, Vec3::Z, Vec3::Z, Vec3::Y, Vec3::Y, Vec3::Y];
        let uv = vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ZERO, Vec2::X, Vec2::Y];
        let idx = vec![0, 1, 2, 3, 4, 5];
        for method in BOTH {
            for weld in [false, true] {
                let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, weld)).unwrap();
                assert_valid(&t, &n);
            }
        }
    }

    #[test]
    fn zero_area_triangles_contribute_nothing() {
        // A unit quad plus a collinear triangle at vertex 0 whose UVs would give t = -y.
        let (mut p, mut n, mut uv, mut idx) = plane(1, false);
        let uv0 = uv[0];
        p.extend([Vec3::new(0.0, -1.0, 0.0), Vec3::new(0.0, -2.0, 0.0)]);
        n.extend([Vec3::Z; 2]);
        uv.extend([uv0 + Vec2::X, uv0 - Vec2::Y]);
        idx.extend([0, 4, 5]);
        let t = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, true)).unwrap();
        assert_valid(&t, &n);
        assert!(degrees_between(t[0].truncate(), Vec3::X) < 1e-3, "{}", t[0]);
    }

    #[test]
    fn a_tangent_parallel_to_the_normal_gets_the_fallback() {
        // The UVs say T = +x, the normals say N = +x.
        let (p, _, uv, idx) = plane(2, false);
        let n = vec![Vec3::X; p.len()];
        let fallback = Vec3::X.any_orthonormal_vector().extend(1.0);
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert!(t.iter().all(|&t| t == fallback), "{method:?}: {t:?}");
        }
        // Nearly parallel: the perpendicular part is rounding noise, not a direction.
        let n = vec![Vec3::new(1.0, 0.0, 1e-6).normalize(); p.len()];
        let fallback = n[0].any_orthonormal_vector().extend(1.0);
        let t = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, true)).unwrap();
        assert!(t.iter().all(|&t| t == fallback), "{t:?}");
    }

    #[test]
    fn degenerate_uvs_get_finite_perpendicular_tangents() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        let n = vec![Vec3::new(0.3, -0.2, 1.0); 3];
        for uv in [vec![Vec2::splat(0.5); 3], vec![Vec2::ZERO, Vec2::X, Vec2::X * 2.0]] {
            for method in BOTH {
                let t = compute_tangents(&p, &n, &uv, &[0, 1, 2], &opts(method, true)).unwrap();
                assert_valid(&t, &n);
            }
        }
    }

    #[test]
    fn mikktspace_all_degenerate_input_does_not_panic() {
        // The input reported to Bevy as bevyengine/bevy#14874, where mikktspace 0.3 underflows.
        let p = vec![Vec3::Y, Vec3::ZERO, Vec3::Y];
        let n = vec![Vec3::ZERO; 3];
        let uv = vec![Vec2::Y, Vec2::ZERO, Vec2::Y];
        let t = compute_tangents(&p, &n, &uv, &[0, 1, 2], &TangentOptions::default()).unwrap();
        // The normals fall back to +Z (no area), the tangents to a vector perpendicular to it.
        assert_valid(&t, &[Vec3::Z; 3]);
        // ... and that without bevy_mikktspace panicking (a caught panic would give `None`).
        let unit = unit_normals(&p, &n, &[0, 1, 2]);
        let mesh = Mesh { positions: &p, normals: &unit, uvs: &uv, indices: &[0, 1, 2] };
        assert!(mikktspace_tangents(&mesh).is_some());
    }

    #[test]
    fn lengyel_ignores_nearly_degenerate_uvs() {
        // A unit quad plus a triangle at vertex 0 whose UVs are almost collinear (sine of the
        // UV angle about 1e-7): its t = 2 e1 - e2 would pull vertex 0's tangent 18 degrees off.
        let (mut p, mut n, mut uv, mut idx) = plane(1, false);
        let uv0 = uv[0];
        p.extend([Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, -1.0, 0.0)]);
        n.extend([Vec3::Z; 2]);
        uv.extend([uv0 + Vec2::new(1.0, 1.2e-7), uv0 + Vec2::new(1.0, 2.4e-7)]);
        idx.extend([0, 4, 5]);
        let t = compute_tangents(&p, &n, &uv, &idx, &opts(TangentMethod::Lengyel, true)).unwrap();
        assert_valid(&t, &n);
        assert!(degrees_between(t[0].truncate(), Vec3::X) < 1e-3, "{}", t[0]);
    }

    #[test]
    fn vertex_without_triangles_gets_the_fallback() {
        let (mut p, mut n, mut uv, idx) = plane(1, false);
        p.push(Vec3::new(5.0, 5.0, 5.0));
        n.push(Vec3::new(0.0, 2.0, 0.0));
        uv.push(Vec2::ZERO);
        for method in BOTH {
            let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            assert_valid(&t, &n);
            assert_eq!(t[4], Vec3::Y.any_orthonormal_vector().extend(1.0));
        }
    }

    #[test]
    fn huge_and_tiny_meshes_get_the_same_tangents() {
        let (p, n, uv, idx) = uv_sphere(12, 6);
        for method in BOTH {
            let reference = compute_tangents(&p, &n, &uv, &idx, &opts(method, true)).unwrap();
            for scale in [1e-30f32, 1e30] {
                let ps: Vec<Vec3> = p.iter().map(|&q| q * scale).collect();
                let t = compute_tangents(&ps, &n, &uv, &idx, &opts(method, true)).unwrap();
                for v in 0..p.len() {
                    let what = format!("{method:?} scale {scale} vertex {v}: {} vs {}", t[v], reference[v]);
                    assert!((t[v] - reference[v]).length() < 1e-3, "{what}");
                }
            }
        }
    }

    #[test]
    fn errors_name_the_culprit() {
        let (p, n, uv, idx) = plane(1, false);
        let o = TangentOptions::default();
        let mut bad = idx.clone();
        bad[4] = 7;
        assert_eq!(
            compute_tangents(&p, &n, &uv, &bad, &o),
            Err(TangentError::IndexOutOfRange { triangle: 1, index: 7, vertex_count: 4 })
        );
        assert_eq!(
            compute_vertex_normals(&p, &bad),
            Err(TangentError::IndexOutOfRange { triangle: 1, index: 7, vertex_count: 4 })
        );
        assert_eq!(
            compute_tangents(&p, &n, &uv, &idx[..4], &o),
            Err(TangentError::IndexCountNotMultipleOf3 { count: 4 })
        );
        assert_eq!(compute_vertex_normals(&p, &idx[..5]), Err(TangentError::IndexCountNotMultipleOf3 { count: 5 }));
        assert_eq!(
            compute_tangents(&p, &n[..3], &uv, &idx, &o),
            Err(TangentError::AttributeLengthMismatch { positions: 4, normals: 3, uvs: 4 })
        );
        assert_eq!(
            compute_tangents(&p, &n, &uv[..2], &idx, &o),
            Err(TangentError::AttributeLengthMismatch { positions: 4, normals: 4, uvs: 2 })
        );
        let mut pn = p.clone();
        pn[2].y = f32::NAN;
        assert!(matches!(
            compute_tangents(&pn, &n, &uv, &idx, &o),
            Err(TangentError::NonFinitePosition { vertex: 2, .. })
        ));
        assert!(matches!(compute_vertex_normals(&pn, &idx), Err(TangentError::NonFinitePosition { vertex: 2, .. })));
        let mut nn = n.clone();
        nn[3].x = f32::INFINITY;
        assert!(matches!(
            compute_tangents(&p, &nn, &uv, &idx, &o),
            Err(TangentError::NonFiniteNormal { vertex: 3, .. })
        ));
        let mut un = uv.clone();
        un[1].x = f32::NEG_INFINITY;
        assert!(matches!(compute_tangents(&p, &n, &un, &idx, &o), Err(TangentError::NonFiniteUv { vertex: 1, .. })));
        // The message names the triangle and index.
        let msg = TangentError::IndexOutOfRange { triangle: 1, index: 7, vertex_count: 4 }.to_string();
        assert!(msg.contains("triangle 1") && msg.contains("vertex 7"), "{msg}");
        // Empty meshes are fine.
        assert_eq!(compute_tangents(&[], &[], &[], &[], &o), Ok(vec![]));
        assert_eq!(compute_vertex_normals(&[], &[]), Ok(vec![]));
    }

    #[test]
    fn vertex_normals_of_a_tetrahedron_point_outward() {
        let p = vec![
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ];
        // Counter-clockwise seen from outside (checked by hand, face by face).
        let idx = vec![0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2];
        let n = compute_vertex_normals(&p, &idx).unwrap();
        for v in 0..4 {
            // By symmetry (three faces of equal area), the normal is along the position.
            assert!(degrees_between(n[v], p[v]) < 1e-3, "vertex {v}: {}", n[v]);
            assert!((n[v].length() - 1.0).abs() < 1e-6);
        }
        // Reversed winding turns every normal inward.
        let reversed: Vec<u32> = idx.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
        let n = compute_vertex_normals(&p, &reversed).unwrap();
        for v in 0..4 {
            assert!(degrees_between(n[v], -p[v]) < 1e-3);
        }
    }

    #[test]
    fn vertex_normals_of_a_plane_and_of_lonely_vertices() {
        let (mut p, _, _, mut idx) = plane(3, false);
        let n = compute_vertex_normals(&p, &idx).unwrap();
        assert!(n.iter().all(|n| degrees_between(*n, Vec3::Z) < 1e-4));
        // A vertex used by no triangle, and one used only by a zero-area triangle, get +Z.
        p.extend([Vec3::new(0.0, 5.0, 1.0), Vec3::new(9.0, 9.0, 9.0), Vec3::new(9.0, 9.0, 9.0)]);
        let k = p.len() as u32;
        idx.extend([k - 2, k - 1, k - 2]);
        let n = compute_vertex_normals(&p, &idx).unwrap();
        assert_eq!(&n[n.len() - 3..], &[Vec3::Z; 3]);
        // The area weighting: a big triangle outweighs a small one sharing the vertex.
        let p = vec![Vec3::ZERO, Vec3::X * 10.0, Vec3::Y * 10.0, Vec3::Z * 0.1, Vec3::Y * 0.1];
        let n = compute_vertex_normals(&p, &[0, 1, 2, 0, 3, 4]).unwrap();
        // Triangle 0 adds 100 z, triangle 1 adds cross(0.1z, 0.1y) = -0.01 x.
        assert!(degrees_between(n[0], Vec3::new(-0.01, 0.0, 100.0)) < 1e-3);
    }

    fn coordinate() -> impl Strategy<Value = f32> {
        prop_oneof![Just(0.0f32), Just(1.0f32), -10.0f32..10.0]
    }

    fn small_mesh() -> impl Strategy<Value = MeshData> {
        (1usize..8).prop_flat_map(|count| {
            let vec3 = (coordinate(), coordinate(), coordinate()).prop_map(|(x, y, z)| Vec3::new(x, y, z));
            let normal = (-1.0f32..1.0, -1.0f32..1.0, prop_oneof![Just(0.0f32), -1.0f32..1.0])
                .prop_map(|(x, y, z)| Vec3::new(x, y, z));
            let uv = (coordinate(), coordinate()).prop_map(|(u, v)| Vec2::new(u, v));
            let scales = (
                prop_oneof![Just(1.0f32), Just(1e-30f32), Just(1e30f32)],
                prop_oneof![Just(1.0f32), Just(1e-20f32), Just(1e20f32)],
            );
            (
                proptest::collection::vec(vec3, count),
                proptest::collection::vec(prop_oneof![Just(Vec3::ZERO), normal], count),
                proptest::collection::vec(uv, count),
                proptest::collection::vec(0..count as u32, 0..=24),
                scales,
            )
                .prop_map(|(p, n, uv, mut idx, (ps, us))| {
                    idx.truncate(idx.len() / 3 * 3);
                    let p = p.into_iter().map(|q| q * ps).collect();
                    let uv = uv.into_iter().map(|w| w * us).collect();
                    (p, n, uv, idx)
                })
        })
    }

    proptest! {
        #[test]
        fn random_meshes_give_valid_tangents((p, n, uv, idx) in small_mesh(), weld in any::<bool>()) {
            for method in BOTH {
                let t = compute_tangents(&p, &n, &uv, &idx, &opts(method, weld)).unwrap();
                assert_valid(&t, &n);
            }
            let normals = compute_vertex_normals(&p, &idx).unwrap();
            for m in normals {
                prop_assert!(m.is_finite() && (m.length() - 1.0).abs() < 1e-4);
            }
        }
    }

    impl mikktspace::Geometry for MikkAdapter<'_> {
        fn num_faces(&self) -> usize {
            bevy_mikktspace::Geometry::num_faces(self)
        }
        fn num_vertices_of_face(&self, face: usize) -> usize {
            bevy_mikktspace::Geometry::num_vertices_of_face(self, face)
        }
        fn position(&self, face: usize, vert: usize) -> [f32; 3] {
            bevy_mikktspace::Geometry::position(self, face, vert)
        }
        fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
            bevy_mikktspace::Geometry::normal(self, face, vert)
        }
        fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
            bevy_mikktspace::Geometry::tex_coord(self, face, vert)
        }
        fn set_tangent_encoded(&mut self, tangent: [f32; 4], face: usize, vert: usize) {
            self.add(tangent, face, vert);
        }
    }

    /// The tangents of the `mikktspace` 0.3 crate pomkit used before `bevy_mikktspace`, through
    /// the same adapter and resolution.
    fn old_mikktspace_tangents(mesh: &Mesh<'_>) -> Vec<Vec4> {
        let mut adapter = MikkAdapter::new(mesh).unwrap();
        assert!(mikktspace::generate_tangents(&mut adapter));
        adapter.resolve()
    }

    /// bevy_mikktspace gives the tangents mikktspace 0.3 gave, on the built-in shapes (poles,
    /// seams, caps, mirrored and rotated UVs) and on randomly perturbed grids.
    #[test]
    fn bevy_mikktspace_agrees_with_the_tangents_before_it() {
        use crate::mesh::Mesh as Shape;
        let mut meshes = vec![
            Shape::uv_sphere(1.0, 12, 24),
            Shape::torus(1.0, 0.3, 24, 12),
            Shape::cylinder(0.5, 2.0, 16),
            Shape::cube(2.0),
            Shape::disc(1.0, 16),
            Shape::plane(Vec2::new(2.0, 3.0), 4),
        ];
        // Grids with jittered positions and UVs, some mirrored in u.
        for seed in 0..6u32 {
            let mut m = Shape::plane(Vec2::splat(2.0), 6);
            for (k, (p, uv)) in m.positions.iter_mut().zip(&mut m.uvs).enumerate() {
                let h = |i: u32| {
                    ((k as u32).wrapping_mul(2_654_435_761).wrapping_add(seed * 97 + i) % 1000) as f32 / 1000.0
                };
                p.y += 0.3 * (h(1) - 0.5);
                *uv += Vec2::new(h(2) - 0.5, h(3) - 0.5) * 0.04;
                if seed % 2 == 1 {
                    uv.x = 1.0 - uv.x;
                }
            }
            meshes.push(m);
        }
        for (i, m) in meshes.iter().enumerate() {
            let unit = unit_normals(&m.positions, &m.normals, &m.indices);
            let mesh = Mesh { positions: &m.positions, normals: &unit, uvs: &m.uvs, indices: &m.indices };
            let new = mikktspace_tangents(&mesh).unwrap();
            let old = old_mikktspace_tangents(&mesh);
            for (k, (a, b)) in new.iter().zip(&old).enumerate() {
                assert_eq!(a.w, b.w, "mesh {i} vertex {k}: handedness {a} against {b}");
                let angle = a.truncate().angle_between(b.truncate()).to_degrees();
                assert!(angle < 0.01, "mesh {i} vertex {k}: {angle} degrees apart ({a} against {b})");
            }
        }
    }
}
