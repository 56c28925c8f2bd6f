//! A user's app: a plane drawn with bevy_pomkit's material (built by `.ci/run`, not run).

use bevy::prelude::*;
use bevy_pomkit::{Pomkit, PomkitMaterial, PomkitPlugin, ShadowMode, Technique};

fn main() {
    App::new().add_plugins((DefaultPlugins, PomkitPlugin)).add_systems(Startup, setup).run();
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<PomkitMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    let mesh = Mesh::from(Plane3d::default().mesh().size(2.0, 2.0));
    let height = images.add(Image::default());
    commands.spawn((
        Mesh3d(meshes.add(mesh)),
        MeshMaterial3d(materials.add(PomkitMaterial {
            base: StandardMaterial::default(),
            extension: Pomkit::new(height).with_technique(Technique::Exact).with_shadow(ShadowMode::Soft),
        })),
    ));
}
