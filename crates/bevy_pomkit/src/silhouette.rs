//! Silhouettes: the per-vertex curvature that lets a material with
//! [`Pomkit::silhouette`](crate::Pomkit::silhouette) bend its view rays under the curved surface
//! and discard the pixels whose ray leaves the relief, so that a curved mesh shows the bumpy
//! outline of the displaced surface (Oliveira and Policarpo 2005, docs/REFERENCES.md).
//!
//! The curvature is pomkit-core's ([`pomkit_core::silhouette::vertex_curvature`]): the second
//! fundamental form of the surface the mesh's normals describe, fitted over each vertex's
//! one-ring, times the world length of one UV unit, in the vertex's tangent frame. The plugin
//! computes it in `PostUpdate` for every mesh drawn with a silhouette material, and again when
//! the mesh's vertices change, and stores it in the mesh as [`ATTRIBUTE_CURVATURE`]. The
//! material's pipelines read it through a vertex stage of their own only when silhouettes are
//! on; every other pipeline keeps Bevy's vertex stage.

use std::hash::{Hash, Hasher};

use bevy::asset::{AssetEvent, AssetId, AssetServer, Assets};
use bevy::log::warn;
use bevy::mesh::{Indices, Mesh, Mesh3d, MeshVertexAttribute, PrimitiveTopology, VertexAttributeValues, VertexFormat};
use bevy::pbr::MeshMaterial3d;
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use pomkit_core::glam;

use crate::{HeightMaps, PomkitMaterial};

/// The curvature form `K = L * II` of the surface at each vertex, `(K_tt, K_tb, K_bb)` in the
/// vertex's `(T, B = w * cross(N, T))` basis (pomkit-core's
/// [`vertex_curvature`](pomkit_core::silhouette::vertex_curvature)), three floats per vertex.
///
/// The plugin inserts it into meshes drawn with a silhouette material; a mesh whose vertex data
/// does not stay in the main world (`RenderAssetUsages::RENDER_WORLD` alone) needs it inserted
/// by its owner, with [`mesh_curvature`].
pub const ATTRIBUTE_CURVATURE: MeshVertexAttribute =
    MeshVertexAttribute::new("Pomkit_Curvature", 0x706f_6d6b_6974_4b31, VertexFormat::Float32x3);

/// Why a mesh's curvature cannot be computed.
#[derive(Debug, thiserror::Error)]
pub enum CurvatureError {
    /// Only triangle lists have one-rings to fit.
    #[error("its topology is {0:?}, not a triangle list")]
    Topology(PrimitiveTopology),
    /// UVs, normals or tangents are missing (the plugin reports these for every pomkit
    /// material).
    #[error("it has no {0} attribute")]
    Missing(&'static str),
    /// An attribute has a format other than Bevy's standard one.
    #[error("its {0} attribute is not {1:?}")]
    Format(&'static str, VertexFormat),
    /// The vertex data went to the render world (`RenderAssetUsages::RENDER_WORLD` only).
    #[error("its vertex data is not kept in the main world (RenderAssetUsages::MAIN_WORLD)")]
    NotInMainWorld,
    /// Joints or morph targets move the vertices on the GPU, away from the pose the curvature
    /// would be fitted to.
    #[error("it is skinned or has morph targets")]
    Animated,
    /// pomkit-core refused the mesh (an index out of range, a value that is not finite, ...).
    #[error("{0}")]
    Mesh(#[from] pomkit_core::mesh::MeshError),
}

impl CurvatureError {
    /// Whether the plugin reports this error already for every pomkit material (a missing UV,
    /// normal or tangent attribute), so the silhouette system need not repeat it.
    fn reported_elsewhere(&self) -> bool {
        matches!(self, Self::Missing(_))
    }
}

/// The values of [`ATTRIBUTE_CURVATURE`] for `mesh`: pomkit-core's per-vertex curvature of the
/// mesh's positions, normals, tangents, UVs and indices (a mesh without indices is read as a
/// triangle list of its vertices in order).
///
/// # Errors
/// [`CurvatureError`] naming what the mesh lacks.
pub fn mesh_curvature(mesh: &Mesh) -> Result<Vec<[f32; 3]>, CurvatureError> {
    let (positions, normals, uvs, tangents, indices) = inputs(mesh)?;
    let core = pomkit_core::mesh::Mesh::with_tangents(positions, Some(normals), uvs, indices, tangents)?;
    Ok(pomkit_core::silhouette::vertex_curvature(&core).into_iter().map(|k| k.to_array()).collect())
}

type Inputs = (Vec<glam::Vec3>, Vec<glam::Vec3>, Vec<glam::Vec2>, Vec<glam::Vec4>, Vec<u32>);

/// The mesh's vertices in pomkit-core's terms.
fn inputs(mesh: &Mesh) -> Result<Inputs, CurvatureError> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(CurvatureError::Topology(mesh.primitive_topology()));
    }
    let attribute = |a: MeshVertexAttribute, name: &'static str| match mesh.try_attribute_option(a.id) {
        Err(_) => Err(CurvatureError::NotInMainWorld),
        Ok(None) => Err(CurvatureError::Missing(name)),
        Ok(Some(values)) => Ok(values),
    };
    let positions = match attribute(Mesh::ATTRIBUTE_POSITION, "POSITION")? {
        VertexAttributeValues::Float32x3(p) => p.iter().map(|p| glam::Vec3::from_array(*p)).collect(),
        _ => return Err(CurvatureError::Format("POSITION", VertexFormat::Float32x3)),
    };
    let uvs = match attribute(Mesh::ATTRIBUTE_UV_0, "UV_0")? {
        VertexAttributeValues::Float32x2(p) => p.iter().map(|p| glam::Vec2::from_array(*p)).collect(),
        _ => return Err(CurvatureError::Format("UV_0", VertexFormat::Float32x2)),
    };
    let normals = match attribute(Mesh::ATTRIBUTE_NORMAL, "NORMAL")? {
        VertexAttributeValues::Float32x3(p) => p.iter().map(|p| glam::Vec3::from_array(*p)).collect(),
        _ => return Err(CurvatureError::Format("NORMAL", VertexFormat::Float32x3)),
    };
    let tangents = match attribute(Mesh::ATTRIBUTE_TANGENT, "TANGENT")? {
        VertexAttributeValues::Float32x4(p) => p.iter().map(|p| glam::Vec4::from_array(*p)).collect(),
        _ => return Err(CurvatureError::Format("TANGENT", VertexFormat::Float32x4)),
    };
    if mesh.try_contains_attribute(Mesh::ATTRIBUTE_JOINT_INDEX).unwrap_or(false) || mesh.has_morph_targets() {
        return Err(CurvatureError::Animated);
    }
    let count = mesh.count_vertices();
    let indices = match mesh.try_indices_option() {
        Err(_) => return Err(CurvatureError::NotInMainWorld),
        Ok(Some(Indices::U16(i))) => i.iter().map(|&i| u32::from(i)).collect(),
        Ok(Some(Indices::U32(i))) => i.clone(),
        // Saturated at u32::MAX: pomkit-core refuses such an index as out of range.
        Ok(None) => (0..count).map(|i| u32::try_from(i).unwrap_or(u32::MAX)).collect(),
    };
    Ok((positions, normals, uvs, tangents, indices))
}

/// A hash of what the curvature is computed from (not of the curvature itself, so inserting it
/// does not make the mesh look changed).
fn fingerprint(mesh: &Mesh) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    format!("{:?}", mesh.primitive_topology()).hash(&mut h);
    for a in [Mesh::ATTRIBUTE_POSITION, Mesh::ATTRIBUTE_NORMAL, Mesh::ATTRIBUTE_TANGENT, Mesh::ATTRIBUTE_UV_0] {
        if let Ok(Some(values)) = mesh.try_attribute_option(a.id) {
            values.get_bytes().hash(&mut h);
        }
    }
    match mesh.try_indices_option() {
        Ok(Some(Indices::U16(i))) => i.hash(&mut h),
        Ok(Some(Indices::U32(i))) => i.hash(&mut h),
        _ => {}
    }
    h.finish()
}

/// Which meshes have had their curvature computed, from what.
#[derive(Default)]
pub(crate) struct Computed {
    from: HashMap<AssetId<Mesh>, u64>,
}

/// Computes [`ATTRIBUTE_CURVATURE`] for every mesh drawn with a silhouette material that lacks
/// it or whose vertices changed; reports (once each) the meshes it cannot be computed for,
/// which draw as the plain standard material.
pub(crate) fn prepare_curvature(
    drawn: Query<(Entity, &Mesh3d, &MeshMaterial3d<PomkitMaterial>)>,
    materials: Res<Assets<PomkitMaterial>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut events: MessageReader<AssetEvent<Mesh>>,
    mut computed: Local<Computed>,
    mut maps: ResMut<HeightMaps>,
    server: Option<Res<AssetServer>>,
) {
    let mut changed: HashSet<AssetId<Mesh>> = HashSet::default();
    for event in events.read() {
        match event {
            AssetEvent::Added { id } | AssetEvent::Modified { id } | AssetEvent::LoadedWithDependencies { id } => {
                changed.insert(*id);
            }
            AssetEvent::Removed { id } | AssetEvent::Unused { id } => {
                computed.from.remove(id);
            }
        }
    }
    let mut wanted: HashMap<AssetId<Mesh>, Entity> = HashMap::default();
    for (entity, mesh, material) in &drawn {
        if materials.get(&material.0).is_some_and(|m| m.extension.silhouette) {
            wanted.entry(mesh.0.id()).or_insert(entity);
        }
    }
    for (id, entity) in wanted {
        if computed.from.contains_key(&id) && !changed.contains(&id) {
            continue;
        }
        let Some(mesh) = meshes.get(id) else { continue };
        let print = fingerprint(mesh);
        let has = mesh.try_contains_attribute(ATTRIBUTE_CURVATURE).unwrap_or(false);
        if computed.from.get(&id) == Some(&print) && has {
            continue;
        }
        computed.from.insert(id, print);
        match mesh_curvature(mesh) {
            Ok(k) => {
                if let Some(mut mesh) = meshes.get_mut(id)
                    && let Err(e) = mesh.try_insert_attribute(ATTRIBUTE_CURVATURE, k)
                {
                    warn!("bevy_pomkit: could not store a mesh's curvature: {e}");
                }
            }
            Err(e) => {
                if has && let Some(mut mesh) = meshes.get_mut(id) {
                    // Stale values of vertices that changed: drawn plain instead.
                    let _ = mesh.try_remove_attribute(ATTRIBUTE_CURVATURE);
                }
                if !e.reported_elsewhere() {
                    let name = server
                        .as_deref()
                        .and_then(|s| s.get_path(id))
                        .map_or_else(|| format!("{id} of entity {entity}"), |p| format!("\"{p}\""));
                    maps.report(format!(
                        "bevy_pomkit: mesh {name}: no silhouettes, {e}: drawing the plain StandardMaterial"
                    ));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy::asset::RenderAssetUsages;

    /// pomkit-core's sphere as a Bevy mesh, with or without its index list.
    fn sphere(indexed: bool) -> (pomkit_core::mesh::Mesh, Mesh) {
        let core = pomkit_core::mesh::Mesh::uv_sphere(1.0, 8, 16);
        let at = |i: usize| if indexed { i } else { core.indices[i] as usize };
        let n = if indexed { core.positions.len() } else { core.indices.len() };
        let mut mesh = Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
            .with_inserted_attribute(
                Mesh::ATTRIBUTE_POSITION,
                (0..n).map(|i| core.positions[at(i)].to_array()).collect::<Vec<_>>(),
            )
            .with_inserted_attribute(
                Mesh::ATTRIBUTE_NORMAL,
                (0..n).map(|i| core.normals[at(i)].to_array()).collect::<Vec<_>>(),
            )
            .with_inserted_attribute(
                Mesh::ATTRIBUTE_UV_0,
                (0..n).map(|i| core.uvs[at(i)].to_array()).collect::<Vec<_>>(),
            )
            .with_inserted_attribute(
                Mesh::ATTRIBUTE_TANGENT,
                (0..n).map(|i| core.tangents[at(i)].to_array()).collect::<Vec<_>>(),
            );
        if indexed {
            mesh.insert_indices(Indices::U16(core.indices.iter().map(|&i| i as u16).collect()));
        }
        (core, mesh)
    }

    #[test]
    fn the_curvature_is_pomkit_cores_for_indexed_and_unindexed_meshes() {
        let (core, mesh) = sphere(true);
        let want: Vec<[f32; 3]> =
            pomkit_core::silhouette::vertex_curvature(&core).into_iter().map(|k| k.to_array()).collect();
        // The same up to rounding (the tangents pass through `Mesh::with_tangents` once more).
        let close = |a: [f32; 3], b: [f32; 3]| {
            (glam::Vec3::from_array(a) - glam::Vec3::from_array(b)).abs().max_element() < 1e-5
        };
        let k = mesh_curvature(&mesh).expect("indexed");
        assert_eq!(k.len(), want.len());
        for (v, (a, b)) in k.iter().zip(&want).enumerate() {
            assert!(close(*a, *b), "vertex {v}: {a:?} vs {b:?}");
        }
        // Without indices every corner is its own vertex, and alone it has two neighbours, too
        // few to fit: pomkit-core's seam welding joins the copies at one position, so every
        // corner is curved like its vertex (up to the length of a UV unit, which each copy takes
        // from its own triangle: within 30% here, on 8 x 16 quads).
        let (_, flat) = sphere(false);
        let k = mesh_curvature(&flat).expect("unindexed");
        for (corner, &v) in core.indices.iter().enumerate() {
            let (a, b) = (k[corner][0], want[v as usize][0]);
            assert!((a - b).abs() <= 0.3 * b, "corner {corner}: K_tt {a} vs {b}");
        }
    }

    #[test]
    fn what_cannot_be_fitted_is_named() {
        let (_, mesh) = sphere(true);
        let strip = Mesh::new(PrimitiveTopology::TriangleStrip, RenderAssetUsages::default())
            .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 4]);
        assert!(matches!(mesh_curvature(&strip), Err(CurvatureError::Topology(PrimitiveTopology::TriangleStrip))));
        let mut bare = mesh.clone();
        bare.remove_attribute(Mesh::ATTRIBUTE_TANGENT);
        assert!(matches!(mesh_curvature(&bare), Err(CurvatureError::Missing("TANGENT"))));
        let mut nan = mesh;
        if let Some(VertexAttributeValues::Float32x3(p)) = nan.attribute_mut(Mesh::ATTRIBUTE_POSITION) {
            p[3] = [f32::NAN; 3];
        }
        let e = mesh_curvature(&nan).expect_err("a NaN position");
        assert!(e.to_string().contains("vertex 3"), "{e}");
    }
}
