//! pomkit-core's meshes in Bevy, for the silhouette example and tests (included with `#[path]`):
//! the same vertices, normals, UVs, tangents and triangles, so that Bevy draws exactly what
//! pomkit's renderers draw.

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;

/// pomkit-core's `mesh` as a Bevy mesh.
pub fn bevy_mesh(mesh: &pomkit_core::mesh::Mesh) -> Mesh {
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let normals: Vec<[f32; 3]> = mesh.normals.iter().map(|n| n.to_array()).collect();
    let uvs: Vec<[f32; 2]> = mesh.uvs.iter().map(|uv| uv.to_array()).collect();
    let tangents: Vec<[f32; 4]> = mesh.tangents.iter().map(|t| t.to_array()).collect();
    Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
        .with_inserted_attribute(Mesh::ATTRIBUTE_TANGENT, tangents)
        .with_inserted_indices(Indices::U32(mesh.indices.clone()))
}

/// pomkit's cobblestone sphere of the silhouette tests: a unit UV sphere of 96 rings and 192
/// segments, one tile of the height map over it.
pub fn cobblestone_sphere() -> Mesh {
    bevy_mesh(&pomkit_core::mesh::Mesh::uv_sphere(1.0, 96, 192))
}
