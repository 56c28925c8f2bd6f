//! The built-in demo scene: `pomkit render` with no scene file draws this.
//!
//! A brick floor, a cube of pyramids, a cobblestone sphere and a plate of raised text (after
//! Tatarchuk 2006 figure 14), all procedural, under a low warm sun so the self-shadows show.

use std::sync::Arc;

use glam::{Mat4, Quat, Vec2, Vec3};

use crate::mesh::Mesh;
use crate::procedural::{self, Pattern};
use crate::scene::{Camera, Light, Material, Object, Scene, Texture};
use crate::shadow::{ShadowMode, ShadowParams};
use crate::trace::{Technique, TraceParams};

/// Texture size of the demo's procedural maps.
pub const DEMO_TEXTURE_SIZE: u32 = 512;

/// A material from a procedural pattern: its height map and colour map.
#[must_use]
pub fn procedural_material(pattern: Pattern, size: u32, depth_scale: f32) -> Material {
    let field = procedural::generate(pattern, size, size);
    let albedo = Texture::from_srgb8(size, size, &procedural::albedo(pattern, size, size)).map(Arc::new);
    Material {
        name: pattern.name().to_owned(),
        albedo,
        base_color: Vec3::ONE,
        height: Some(Arc::new(field)),
        technique: Technique::Exact,
        depth_scale,
        trace: TraceParams { min_samples: 8, max_samples: 32, refine: 2, ..TraceParams::default() },
        shadow: ShadowParams { mode: ShadowMode::Soft, softness: 0.08 },
        ..Material::default()
    }
}

/// The demo scene.
#[must_use]
pub fn demo_scene() -> Scene {
    demo_scene_sized(DEMO_TEXTURE_SIZE)
}

/// The demo scene with procedural textures of `size` texels (smaller is faster, for tests).
#[must_use]
pub fn demo_scene_sized(size: u32) -> Scene {
    let materials = vec![
        Material { specular: 0.15, shininess: 24.0, ..procedural_material(Pattern::Bricks, size, 0.04) },
        Material { specular: 0.2, ..procedural_material(Pattern::Pyramids, size, 0.1) },
        Material { specular: 0.35, shininess: 48.0, ..procedural_material(Pattern::Cobblestones, size, 0.05) },
        Material { specular: 0.5, shininess: 64.0, ..procedural_material(Pattern::Text, size, 0.06) },
    ];
    let object = |name: &str, mesh: Mesh, material: usize, transform: Mat4| Object {
        name: name.to_owned(),
        mesh: Arc::new(mesh),
        material,
        transform,
    };
    let objects = vec![
        object("floor", Mesh::plane(Vec2::splat(8.0), 1).scale_uvs(Vec2::splat(4.0)), 0, Mat4::IDENTITY),
        object(
            "cube",
            Mesh::cube(1.1),
            1,
            Mat4::from_rotation_translation(Quat::from_rotation_y(0.6), Vec3::new(-1.45, 0.55, 0.1)),
        ),
        object(
            "sphere",
            Mesh::uv_sphere(0.75, 48, 96).scale_uvs(Vec2::new(4.0, 2.0)),
            2,
            Mat4::from_rotation_translation(Quat::from_rotation_y(0.4), Vec3::new(1.35, 0.75, 0.2)),
        ),
        object(
            "sign",
            Mesh::quad(Vec2::new(1.7, 1.7)),
            3,
            Mat4::from_rotation_translation(Quat::from_rotation_x(-0.25), Vec3::new(0.0, 0.95, -1.6)),
        ),
    ];
    Scene {
        camera: Camera {
            eye: Vec3::new(0.0, 2.3, 4.6),
            target: Vec3::new(0.0, 0.55, -0.2),
            up: Vec3::Y,
            fov_y_deg: 40.0,
            near: 0.05,
            far: 50.0,
        },
        lights: vec![Light::Directional {
            direction: Vec3::new(0.7, 0.55, 0.5),
            color: Vec3::new(1.0, 0.93, 0.82),
            intensity: 2.6,
        }],
        materials,
        objects,
        ambient: Vec3::new(0.10, 0.11, 0.14),
        background: Vec3::new(0.035, 0.04, 0.055),
    }
}
