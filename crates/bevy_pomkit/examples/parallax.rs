//! bevy_pomkit in a window, like Bevy's own parallax_mapping example: a parallax-mapped cube on
//! a parallax-mapped floor under a low sun.
//!
//! ```text
//! cargo run --release -p bevy_pomkit --example parallax
//! ```
//!
//! Keys: T / Shift+T next / previous technique, S self-shadow mode, L LOD fade threshold,
//! P pixel depth offset, D debug view, B Bevy's own parallax mapping (Occlusion, Relief) for
//! comparison, R rotate the cube, Up / Down depth scale. The window's title shows the settings
//! and the frame time (Bevy's UI text would more than double the build of this crate's tests).

#[path = "support/scene.rs"]
mod scene;

use bevy::diagnostic::{DiagnosticsStore, FrameTimeDiagnosticsPlugin};
use bevy::pbr::ParallaxMappingMethod;
use bevy::prelude::*;
use bevy_pomkit::{PomkitDebug, PomkitMaterial, PomkitPlugin, ShadowMode, Technique};
use scene::{Method, SceneHandles, SceneOptions};

#[expect(unsafe_code, reason = "ensure_runtime_dir sets an environment variable; no other thread runs yet")]
fn main() {
    // Without XDG_RUNTIME_DIR (containers, CI, SSH), Mesa's Vulkan layers print a harmless
    // error line on every device creation; this gives them a private directory.
    // SAFETY: first thing in main, before any other thread starts.
    unsafe { pomkit_gpu::util::ensure_runtime_dir() };
    App::new()
        .add_plugins((
            DefaultPlugins.set(WindowPlugin {
                primary_window: Some(Window { title: "bevy_pomkit: parallax".into(), ..default() }),
                ..default()
            }),
            PomkitPlugin,
            FrameTimeDiagnosticsPlugin::default(),
        ))
        .init_resource::<State>()
        .add_systems(Startup, setup)
        .add_systems(Update, (keys, rotate, overlay))
        .run();
}

/// What the keys have chosen.
#[derive(Resource)]
struct State {
    technique: usize,
    bevy: Option<ParallaxMappingMethod>,
    rotate: bool,
}

impl Default for State {
    fn default() -> Self {
        let technique = Technique::ALL.iter().position(|t| *t == Technique::Exact).unwrap_or(0);
        Self { technique, bevy: None, rotate: true }
    }
}

/// Bevy's own materials for the same surfaces, swapped in with B.
#[derive(Resource)]
struct BevyMaterials {
    standard: Handle<StandardMaterial>,
}

fn setup(world: &mut World) {
    let opts = SceneOptions::default();
    scene::spawn(world, None, &opts);
    // Bevy's own parallax material for the cube, shown with B.
    let bevy_opts = SceneOptions { method: Method::Bevy(ParallaxMappingMethod::Occlusion), ..opts };
    let depth = world.resource_mut::<Assets<Image>>().add(scene::bevy_depth_map(bevy_opts.pattern, bevy_opts.size));
    let albedo = world.resource_mut::<Assets<Image>>().add(scene::albedo_image(bevy_opts.pattern, bevy_opts.size));
    let standard = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color_texture: Some(albedo),
        depth_map: Some(depth),
        parallax_depth_scale: bevy_opts.depth_scale,
        max_parallax_layer_count: 32.0,
        perceptual_roughness: 0.8,
        reflectance: 0.3,
        ..default()
    });
    world.insert_resource(BevyMaterials { standard });
    println!(
        "keys: T / Shift+T technique, S self-shadow, L LOD fade, P pixel depth offset, D debug view, \
         B Bevy's own parallax on the cube, R rotate, Up / Down depth scale"
    );
}

#[expect(clippy::too_many_arguments, reason = "one system reads every key")]
fn keys(
    input: Res<ButtonInput<KeyCode>>,
    mut state: ResMut<State>,
    handles: Res<SceneHandles>,
    bevy_materials: Res<BevyMaterials>,
    mut pomkit: ResMut<Assets<PomkitMaterial>>,
    mut standard: ResMut<Assets<StandardMaterial>>,
    mut commands: Commands,
    cube: Query<Entity>,
) {
    let Some(handle) = handles.pomkit.clone() else { return };
    let shift = input.any_pressed([KeyCode::ShiftLeft, KeyCode::ShiftRight]);
    let n = Technique::ALL.len();
    let (shadow_now, lod_now) =
        pomkit.get(&handle).map_or((ShadowMode::None, 4.0), |m| (m.extension.shadow.mode, m.extension.lod_threshold));
    // Every pomkit material of the scene follows the cube's settings.
    let mut change = |f: &dyn Fn(&mut bevy_pomkit::Pomkit)| {
        let ids: Vec<_> = pomkit.ids().collect();
        for id in ids {
            if let Some(mut m) = pomkit.get_mut(id) {
                f(&mut m.extension);
            }
        }
    };
    if input.just_pressed(KeyCode::KeyT) {
        state.technique = if shift { (state.technique + n - 1) % n } else { (state.technique + 1) % n };
        let t = Technique::ALL[state.technique];
        change(&|e| e.technique = t);
    }
    if input.just_pressed(KeyCode::KeyS) {
        let k = ShadowMode::ALL.iter().position(|m| *m == shadow_now).unwrap_or(0);
        let next = ShadowMode::ALL[(k + 1) % ShadowMode::ALL.len()];
        change(&|e| e.shadow.mode = next);
    }
    if input.just_pressed(KeyCode::KeyL) {
        let next = if lod_now >= f32::MAX {
            2.0
        } else if lod_now <= 2.0 {
            4.0
        } else {
            f32::MAX
        };
        change(&|e| e.lod_threshold = next);
    }
    if input.just_pressed(KeyCode::KeyP) {
        change(&|e| e.pixel_depth_offset = !e.pixel_depth_offset);
    }
    if input.just_pressed(KeyCode::KeyD) {
        change(&|e| {
            e.debug = match e.debug {
                PomkitDebug::Off => PomkitDebug::HitUv,
                PomkitDebug::HitUv => PomkitDebug::Fetches,
                PomkitDebug::Fetches => PomkitDebug::Shadow,
                PomkitDebug::Shadow => PomkitDebug::Off,
            };
        });
    }
    for (key, factor) in [(KeyCode::ArrowUp, 1.25f32), (KeyCode::ArrowDown, 0.8)] {
        if input.just_pressed(key) {
            change(&|e| e.depth_scale = (e.depth_scale * factor).clamp(0.005, 0.5));
            if let Some(mut m) = standard.get_mut(&bevy_materials.standard) {
                m.parallax_depth_scale = (m.parallax_depth_scale * factor).clamp(0.005, 0.5);
            }
        }
    }
    if input.just_pressed(KeyCode::KeyR) {
        state.rotate = !state.rotate;
    }
    if input.just_pressed(KeyCode::KeyB) {
        state.bevy = match state.bevy {
            None => Some(ParallaxMappingMethod::Occlusion),
            Some(ParallaxMappingMethod::Occlusion) => Some(ParallaxMappingMethod::Relief { max_steps: 5 }),
            Some(_) => None,
        };
        let Ok(cube) = cube.get(handles.cube) else { return };
        match state.bevy {
            Some(method) => {
                if let Some(mut m) = standard.get_mut(&bevy_materials.standard) {
                    m.parallax_mapping_method = method;
                }
                commands
                    .entity(cube)
                    .remove::<MeshMaterial3d<PomkitMaterial>>()
                    .insert(MeshMaterial3d(bevy_materials.standard.clone()));
            }
            None => {
                commands
                    .entity(cube)
                    .remove::<MeshMaterial3d<StandardMaterial>>()
                    .insert(MeshMaterial3d(handle.clone()));
            }
        }
    }
}

fn rotate(time: Res<Time>, state: Res<State>, handles: Res<SceneHandles>, mut transforms: Query<&mut Transform>) {
    if !state.rotate {
        return;
    }
    if let Ok(mut t) = transforms.get_mut(handles.cube) {
        t.rotate_y(0.3 * time.delta_secs());
    }
}

/// The settings and the frame time, in the window's title.
fn overlay(
    diagnostics: Res<DiagnosticsStore>,
    state: Res<State>,
    handles: Res<SceneHandles>,
    pomkit: Res<Assets<PomkitMaterial>>,
    mut windows: Query<&mut Window>,
) {
    let Ok(mut window) = windows.single_mut() else { return };
    let frame_ms = diagnostics
        .get(&FrameTimeDiagnosticsPlugin::FRAME_TIME)
        .and_then(|d| d.smoothed())
        .map_or_else(|| "-".to_owned(), |ms| format!("{ms:.1} ms"));
    let Some(m) = handles.pomkit.as_ref().and_then(|h| pomkit.get(h)) else { return };
    let e = &m.extension;
    let cube = match state.bevy {
        None => String::new(),
        Some(ParallaxMappingMethod::Occlusion) => " | cube: Bevy Occlusion".to_owned(),
        Some(_) => " | cube: Bevy Relief".to_owned(),
    };
    let lod = if e.lod_threshold >= f32::MAX { "off".to_owned() } else { format!("mip {}", e.lod_threshold) };
    let title = format!(
        "{frame_ms} | [T] {} | [S] shadow {} | [L] LOD {lod} | [P] depth offset {} | [D] {:?} | depth {:.3}{cube}",
        e.technique.name(),
        e.shadow.mode.name(),
        if e.pixel_depth_offset { "on" } else { "off" },
        e.debug,
        e.depth_scale,
    );
    if window.title != title {
        window.title = title;
    }
}
