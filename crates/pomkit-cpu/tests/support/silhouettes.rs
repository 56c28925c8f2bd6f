//! The silhouette test scenes, shared by the CPU renderer's tests and the GPU renderer's
//! (`#[path]`): a cobblestone sphere and a pyramid-textured torus, seen so that much of their
//! outline grazes, on a background colour no shaded pixel has.

use std::sync::Arc;

use pomkit_core::EdgeMode;
use pomkit_core::glam::{Mat4, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::render::RenderOutput;
use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
use pomkit_core::trace::{Technique, TraceParams};

/// The background: no lit pixel is pure magenta at this brightness.
pub const BACKGROUND: Vec3 = Vec3::new(1.0, 0.0, 1.0);

/// The two shapes of the silhouette tests.
#[derive(Clone, Copy, Debug)]
pub enum Shape {
    /// A unit cobblestone sphere, depth scale 0.04.
    CobblestoneSphere,
    /// A pyramid-textured torus (major 1, minor 0.45), depth scale 0.03.
    PyramidTorus,
}

/// The scene of `shape` with `technique`, silhouettes on or off; `texels` is the height map's size.
pub fn scene(shape: Shape, technique: Technique, silhouette: bool, texels: u32) -> Scene {
    let (mesh, pattern, depth_scale, repeat, eye) = match shape {
        Shape::CobblestoneSphere => {
            (Mesh::uv_sphere(1.0, 96, 192), Pattern::Cobblestones, 0.04, 1.0, Vec3::new(0.0, 0.6, 3.2))
        }
        Shape::PyramidTorus => (
            Mesh::torus(1.0, 0.45, 192, 96).scale_uvs(pomkit_core::glam::Vec2::new(4.0, 1.0)),
            Pattern::Pyramids,
            0.03,
            4.0,
            Vec3::new(0.0, 2.2, 2.6),
        ),
    };
    let _ = repeat;
    let material = Material {
        height: Some(Arc::new(generate(pattern, texels, texels))),
        technique,
        base_color: Vec3::splat(0.8),
        depth_scale,
        edges: EdgeMode::Wrap,
        trace: TraceParams { min_samples: 16, max_samples: 64, ..Default::default() },
        silhouette,
        ..Material::default()
    };
    Scene {
        camera: Camera { eye, target: Vec3::ZERO, fov_y_deg: 40.0, ..Camera::default() },
        lights: vec![Light::Directional { direction: Vec3::new(0.5, 0.8, 0.6), color: Vec3::ONE, intensity: 1.0 }],
        materials: vec![material],
        objects: vec![Object { name: "shape".into(), mesh: Arc::new(mesh), material: 0, transform: Mat4::IDENTITY }],
        ambient: Vec3::splat(0.15),
        background: BACKGROUND,
    }
}

/// Which pixels geometry covers.
pub fn coverage(out: &RenderOutput) -> Vec<bool> {
    out.color.iter().map(|c| *c != BACKGROUND).collect()
}

/// How many pixels two coverages disagree on.
pub fn disagreement(a: &[bool], b: &[bool]) -> usize {
    a.iter().zip(b).filter(|(x, y)| x != y).count()
}
