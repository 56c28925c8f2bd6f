//! The probe quad of bevy_pomkit's tests and benchmark (included with `#[path]`): a 2 x 2 quad
//! in the y = 0 plane with normal +y, u along +x and v along +z (so up the image, -v, is -z),
//! one UV unit per 2 world units, and a choice of tangents.

#![allow(dead_code, reason = "the benchmark uses two of the tangent kinds")]

use bevy::asset::RenderAssetUsages;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;

/// How the quad's tangents are made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tangents {
    /// Written by hand in the glTF convention (B = w cross(N, T) points up the image), as an
    /// authoring tool exports them: w = +1 here.
    Imported,
    /// The opposite handedness (w = -1, B down the image), as tangents from a generator that
    /// takes glTF's v-down UVs for v-up ones have on real assets (docs/EMBEDDING.md).
    Flipped,
    /// Bevy's `Mesh::generate_tangents`.
    Generated,
}

/// The quad.
pub fn quad(tangents: Tangents) -> Mesh {
    let p = [[-1.0f32, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]];
    let uv: Vec<[f32; 2]> = p.iter().map(|q| [(q[0] + 1.0) / 2.0, (q[2] + 1.0) / 2.0]).collect();
    let mut mesh = Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, p.to_vec())
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0f32, 1.0, 0.0]; 4])
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uv)
        .with_inserted_indices(Indices::U32(vec![0, 2, 1, 0, 3, 2]));
    match tangents {
        // cross(+y, +x) = -z: w = +1 points B up the image.
        Tangents::Imported => mesh.insert_attribute(Mesh::ATTRIBUTE_TANGENT, vec![[1.0f32, 0.0, 0.0, 1.0]; 4]),
        Tangents::Flipped => mesh.insert_attribute(Mesh::ATTRIBUTE_TANGENT, vec![[1.0f32, 0.0, 0.0, -1.0]; 4]),
        Tangents::Generated => mesh.generate_tangents().expect("the quad has normals and UVs"),
    }
    mesh
}

/// The quad's UV at a world point of its plane (or a plane parallel to it).
pub fn quad_uv(p: Vec3) -> Vec2 {
    Vec2::new((p.x + 1.0) / 2.0, (p.z + 1.0) / 2.0)
}

/// Where a world ray meets the plane y = `y`, if in front of the eye.
pub fn hit_plane(ray: Ray3d, y: f32) -> Option<Vec3> {
    let d = ray.direction.as_vec3();
    if d.y.abs() < 1e-6 {
        return None;
    }
    let t = (y - ray.origin.y) / d.y;
    (t > 0.0).then(|| ray.origin + d * t)
}
