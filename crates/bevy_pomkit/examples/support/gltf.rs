//! A glTF file in bevy_pomkit's examples and tests (included with `#[path]`): its first scene
//! spawned from Bevy's asset folder and, once it is in the world, its camera aimed at the
//! target, or a camera framing the scene where the file has none, and a sun where it has no
//! light.

#![allow(dead_code, reason = "each example and test uses a part of the helper")]

use bevy::asset::LoadState;
use bevy::camera::primitives::Aabb;
use bevy::camera::{Projection, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::gltf::{Gltf, GltfAssetLabel};
use bevy::light::CascadeShadowConfigBuilder;
use bevy::prelude::*;
use bevy::world_serialization::WorldAssetRoot;

/// A glTF file being loaded, and the entity its scene is spawned under.
#[derive(Resource, Clone)]
pub struct GltfScene {
    /// The file's asset.
    pub gltf: Handle<Gltf>,
    /// The parent of the scene's entities.
    pub root: Entity,
    /// The file's name inside Bevy's asset folder.
    pub file: String,
}

/// Starts loading `file`, a path inside Bevy's asset folder, and spawns its first scene when
/// it has loaded.
pub fn spawn(world: &mut World, file: &str) -> GltfScene {
    // The file's cameras come with Bevy's default tonemapping, which needs lookup tables this
    // crate leaves out (an error in the log at the first frame): they get ACES as they arrive.
    world.add_observer(|add: On<Add, Camera3d>, mut commands: Commands| {
        commands.entity(add.entity).insert(Tonemapping::AcesFitted);
    });
    let server = world.resource::<AssetServer>();
    let gltf = server.load::<Gltf>(file.to_owned());
    let scene = server.load(GltfAssetLabel::Scene(0).from_asset(file.to_owned()));
    let root = world.spawn(WorldAssetRoot(scene)).id();
    let s = GltfScene { gltf, root, file: file.to_owned() };
    world.insert_resource(s.clone());
    s
}

/// Where the load of a [`GltfScene`] stands.
#[derive(Debug, PartialEq)]
pub enum Progress {
    /// Still loading or spawning.
    Loading,
    /// The file could not be loaded (Bevy's error).
    Failed(String),
    /// The scene's entities are in the world.
    Spawned,
}

/// Whether the scene of `s` has been spawned.
pub fn progress(world: &World, s: &GltfScene) -> Progress {
    if let Some(LoadState::Failed(e)) = world.resource::<AssetServer>().get_load_state(&s.gltf) {
        return Progress::Failed(format!("{}: {e}", s.file));
    }
    if world.get::<Children>(s.root).is_some_and(|c| !c.is_empty()) { Progress::Spawned } else { Progress::Loading }
}

/// The centre and radius of the bounding sphere of the meshes in the world.
pub fn bounds(world: &mut World) -> (Vec3, f32) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let mut q = world.query::<(&Aabb, &GlobalTransform)>();
    for (aabb, gt) in q.iter(world) {
        let (c, e) = (Vec3::from(aabb.center), Vec3::from(aabb.half_extents));
        for k in 0..8 {
            let sign = Vec3::new(
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { -1.0 } else { 1.0 },
            );
            let p = gt.transform_point(c + sign * e);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if lo.x > hi.x || !(lo.is_finite() && hi.is_finite()) {
        return (Vec3::ZERO, 1.0);
    }
    ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-3))
}

/// Spawns a camera drawing into `target` (a window when `None`) at the pose and with the
/// projection of the file's camera, or, where the file has none, framing the scene, and adds a
/// sun with shadow maps where it has no light. Call it once the scene is
/// [`Progress::Spawned`] and an update has run (so its transforms are global). Returns the
/// camera and whether its view came from the file.
pub fn finish(world: &mut World, target: Option<RenderTarget>) -> (Entity, bool) {
    let (centre, radius) = bounds(world);
    let mut cameras = world.query_filtered::<(Entity, &Camera, &GlobalTransform, &Projection), With<Camera3d>>();
    let found: Vec<(Entity, bool, Transform, Projection)> =
        cameras.iter(world).map(|(e, c, gt, p)| (e, c.is_active, gt.compute_transform(), p.clone())).collect();
    // The file's active camera (the first), or one above and in front of the scene looking
    // down at it from about 35 degrees, far enough for the bounding sphere to fit a 45-degree
    // field of view.
    let file_camera = found.iter().find(|c| c.1).or(found.first());
    let (pose, projection) = match file_camera {
        Some((_, _, pose, projection)) => (*pose, projection.clone()),
        None => {
            let distance = radius / (22.5f32.to_radians().sin()) * 1.05;
            let eye = centre + Vec3::new(0.35, 0.6, 1.0).normalize() * distance;
            (Transform::from_translation(eye).looking_at(centre, Vec3::Y), Projection::default())
        }
    };
    // The file's cameras stay in the scene, inactive; the picture is drawn by a camera of our
    // own at the active one's pose, with its projection (a camera spawned by the scene did not
    // draw into an image target on Bevy 0.19).
    for (e, ..) in &found {
        if let Some(mut c) = world.get_mut::<Camera>(*e) {
            c.is_active = false;
        }
    }
    // Bevy's default tonemapping needs its lookup tables, which this crate leaves out.
    let mut c = world.spawn((Camera3d::default(), projection, pose, Tonemapping::AcesFitted, Msaa::Off));
    if let Some(t) = target {
        c.insert(t);
    }
    let camera = c.id();
    let from_file = file_camera.is_some();
    let lights = world
        .query_filtered::<(), Or<(With<DirectionalLight>, With<PointLight>, With<SpotLight>)>>()
        .iter(world)
        .count();
    if lights == 0 {
        world.spawn((
            DirectionalLight { illuminance: 8000.0, shadow_maps_enabled: true, ..default() },
            Transform::from_translation(centre + Vec3::new(-3.0, 2.0, 1.5)).looking_at(centre, Vec3::Y),
            CascadeShadowConfigBuilder {
                maximum_distance: radius * 8.0,
                first_cascade_far_bound: radius * 2.0,
                ..default()
            }
            .build(),
        ));
        world.insert_resource(GlobalAmbientLight { brightness: 300.0, ..default() });
    }
    (camera, from_file)
}
