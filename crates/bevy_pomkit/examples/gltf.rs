//! A glTF file in a window, its materials with `KHR_materials_displacement` or pomkit extras
//! traced by bevy_pomkit (feature `gltf`):
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example gltf -- FILE.gltf
//! ```
//!
//! The view starts at the file's camera (without one, a view framing the scene) and the file's
//! lights (without them, a sun). Drag with the left mouse button to orbit, scroll to zoom. Keys:
//! T / Shift+T next / previous technique, S self-shadow mode, D debug view, Up / Down depth
//! scale of every traced material. The window's title shows the settings.

#[path = "support/gltf.rs"]
mod gltf;

use std::path::PathBuf;
use std::process::ExitCode;

use bevy::input::mouse::{AccumulatedMouseMotion, AccumulatedMouseScroll};
use bevy::prelude::*;
use bevy_pomkit::{PomkitDebug, PomkitMaterial, PomkitPlugin, ShadowMode, Technique};

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() -> ExitCode {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    let Some(arg) = std::env::args_os().nth(1) else {
        eprintln!("usage: gltf FILE.gltf (or .glb)");
        return ExitCode::from(2);
    };
    let file = PathBuf::from(arg);
    // Bevy reads assets from its asset folder only: the file's folder becomes it.
    let path = match std::fs::canonicalize(&file) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {}: {e}", file.display());
            return ExitCode::FAILURE;
        }
    };
    let (Some(folder), Some(name)) = (path.parent(), path.file_name().and_then(|n| n.to_str())) else {
        eprintln!("error: {}: not a file name Bevy can load", file.display());
        return ExitCode::FAILURE;
    };
    let name = name.to_owned();
    App::new()
        .add_plugins((
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: Some(Window { title: format!("bevy_pomkit: {name}"), ..default() }),
                    ..default()
                })
                .set(AssetPlugin { file_path: folder.display().to_string(), ..default() }),
            PomkitPlugin,
        ))
        .insert_resource(File(name))
        .add_systems(Startup, |world: &mut World| {
            let file = world.resource::<File>().0.clone();
            gltf::spawn(world, &file);
        })
        .add_systems(Update, (arrive, (orbit, keys, title).run_if(resource_exists::<Orbit>)))
        .run();
    ExitCode::SUCCESS
}

/// The file shown.
#[derive(Resource)]
struct File(String);

/// The orbit camera: it looks at `centre` from `distance` away, at `yaw` about +Y and `pitch`
/// above the horizon.
#[derive(Resource)]
struct Orbit {
    camera: Entity,
    centre: Vec3,
    yaw: f32,
    pitch: f32,
    distance: f32,
}

impl Orbit {
    fn transform(&self) -> Transform {
        let dir = Vec3::new(self.pitch.cos() * self.yaw.sin(), self.pitch.sin(), self.pitch.cos() * self.yaw.cos());
        Transform::from_translation(self.centre + dir * self.distance).looking_at(self.centre, Vec3::Y)
    }
}

/// Once the scene is in the world: the camera (at the file's camera) and lights, and the orbit
/// around the scene.
fn arrive(world: &mut World, mut done: Local<u32>) {
    let Some(scene) = world.get_resource::<gltf::GltfScene>().cloned() else { return };
    if *done >= 2 {
        return;
    }
    match gltf::progress(world, &scene) {
        gltf::Progress::Failed(e) => {
            error!("{e}");
            *done = 2;
            return;
        }
        gltf::Progress::Loading => return,
        gltf::Progress::Spawned => {}
    }
    // One more frame, so the scene's global transforms are set.
    *done += 1;
    if *done < 2 {
        return;
    }
    let (camera, _) = gltf::finish(world, None);
    let (centre, radius) = gltf::bounds(world);
    let pose = world.get::<Transform>(camera).copied().unwrap_or_default();
    // The orbit's centre: where the view's axis passes closest to the scene's centre.
    let forward = pose.forward().as_vec3();
    let along = (centre - pose.translation).dot(forward).max(radius * 0.1);
    let target = pose.translation + forward * along;
    let offset = pose.translation - target;
    let distance = offset.length().max(1e-3);
    let orbit = Orbit {
        camera,
        centre: target,
        yaw: offset.x.atan2(offset.z),
        pitch: (offset.y / distance).clamp(-1.0, 1.0).asin(),
        distance,
    };
    world.insert_resource(orbit);
    println!(
        "drag to orbit, scroll to zoom; keys: T / Shift+T technique, S self-shadow, D debug view, Up / Down depth scale"
    );
}

fn orbit(
    buttons: Res<ButtonInput<MouseButton>>,
    motion: Res<AccumulatedMouseMotion>,
    scroll: Res<AccumulatedMouseScroll>,
    mut orbit: ResMut<Orbit>,
    mut transforms: Query<&mut Transform>,
) {
    if buttons.pressed(MouseButton::Left) && motion.delta != Vec2::ZERO {
        orbit.yaw -= motion.delta.x * 0.005;
        orbit.pitch = (orbit.pitch + motion.delta.y * 0.005).clamp(-1.5, 1.5);
    }
    if scroll.delta.y != 0.0 {
        orbit.distance *= (1.0 - scroll.delta.y * 0.1).clamp(0.5, 1.5);
    }
    if let Ok(mut t) = transforms.get_mut(orbit.camera) {
        let want = orbit.transform();
        if *t != want {
            *t = want;
        }
    }
}

fn keys(input: Res<ButtonInput<KeyCode>>, mut materials: ResMut<Assets<PomkitMaterial>>) {
    let shift = input.any_pressed([KeyCode::ShiftLeft, KeyCode::ShiftRight]);
    let ids: Vec<_> = materials.ids().collect();
    for id in ids {
        let Some(mut m) = materials.get_mut(id) else { continue };
        let e = &mut m.extension;
        if input.just_pressed(KeyCode::KeyT) {
            let n = Technique::ALL.len();
            let k = Technique::ALL.iter().position(|t| *t == e.technique).unwrap_or(0);
            e.technique = Technique::ALL[if shift { (k + n - 1) % n } else { (k + 1) % n }];
        }
        if input.just_pressed(KeyCode::KeyS) {
            let k = ShadowMode::ALL.iter().position(|m| *m == e.shadow.mode).unwrap_or(0);
            e.shadow.mode = ShadowMode::ALL[(k + 1) % ShadowMode::ALL.len()];
        }
        if input.just_pressed(KeyCode::KeyD) {
            e.debug = match e.debug {
                PomkitDebug::Off => PomkitDebug::HitUv,
                PomkitDebug::HitUv => PomkitDebug::Fetches,
                PomkitDebug::Fetches => PomkitDebug::Shadow,
                PomkitDebug::Shadow => PomkitDebug::Off,
            };
        }
        for (key, factor) in [(KeyCode::ArrowUp, 1.25f32), (KeyCode::ArrowDown, 0.8)] {
            if input.just_pressed(key) {
                e.depth_scale = (e.depth_scale * factor).clamp(1e-4, 16.0);
            }
        }
    }
}

/// The settings of the first traced material, in the window's title.
fn title(file: Res<File>, materials: Res<Assets<PomkitMaterial>>, mut windows: Query<&mut Window>) {
    let Ok(mut window) = windows.single_mut() else { return };
    let title = match materials.iter().next() {
        None => format!("bevy_pomkit: {} (no traced material)", file.0),
        Some((_, m)) => {
            let e = &m.extension;
            format!(
                "bevy_pomkit: {} | {} traced | [T] {} | [S] shadow {} | [D] {:?} | depth {:.4}",
                file.0,
                materials.len(),
                e.technique.name(),
                e.shadow.mode.name(),
                e.debug,
                e.depth_scale
            )
        }
    };
    if window.title != title {
        window.title = title;
    }
}
