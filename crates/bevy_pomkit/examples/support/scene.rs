//! The demo scene of bevy_pomkit's examples (included with `#[path]`): a parallax-mapped cube
//! resting on a parallax-mapped floor, lit by a low sun with shadow maps, as in Bevy's own
//! parallax_mapping example. Height maps and albedos are pomkit's procedural patterns, so no
//! asset files are needed.

#![allow(dead_code, reason = "each example uses a part of the shared scene")]

use bevy::asset::RenderAssetUsages;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::light::{CascadeShadowConfigBuilder, DirectionalLightShadowMap};
use bevy::math::Affine2;
use bevy::pbr::ParallaxMappingMethod;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{MapKind, Pomkit, PomkitMaterial, ShadowMode, Technique};
use pomkit_core::procedural::{Pattern, albedo, generate};

/// What to draw the surfaces with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// bevy_pomkit with a pomkit technique.
    Pomkit(Technique),
    /// Bevy's own `StandardMaterial` parallax.
    Bevy(ParallaxMappingMethod),
    /// Bevy's `StandardMaterial` with the same albedo and no depth map: the cost of the frame
    /// without any parallax.
    Plain,
}

impl Method {
    /// Parses a pomkit technique name, or `bevy-occlusion` / `bevy-relief`.
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "bevy-occlusion" => Ok(Self::Bevy(ParallaxMappingMethod::Occlusion)),
            "bevy-relief" => Ok(Self::Bevy(ParallaxMappingMethod::Relief { max_steps: 5 })),
            "bevy-plain" => Ok(Self::Plain),
            _ => name.parse::<Technique>().map(Self::Pomkit).map_err(|e| {
                format!("{e} (or bevy-occlusion, bevy-relief for Bevy's own parallax mapping, bevy-plain for none)")
            }),
        }
    }

    /// The name [`Method::parse`] reads.
    pub fn name(self) -> String {
        match self {
            Self::Pomkit(t) => t.name().to_owned(),
            Self::Bevy(ParallaxMappingMethod::Occlusion) => "bevy-occlusion".to_owned(),
            Self::Bevy(ParallaxMappingMethod::Relief { .. }) => "bevy-relief".to_owned(),
            Self::Plain => "bevy-plain".to_owned(),
        }
    }
}

/// The scene's settings.
#[derive(Clone, Debug)]
pub struct SceneOptions {
    /// Surface method.
    pub method: Method,
    /// pomkit self-shadow mode.
    pub shadow: ShadowMode,
    /// Height pattern.
    pub pattern: Pattern,
    /// Height map side in texels.
    pub size: u32,
    /// Depth scale in UV units of one tile.
    pub depth_scale: f32,
    /// pomkit's pixel depth offset.
    pub pixel_depth: bool,
    /// pomkit's pixel depth offset in the sun's shadow cascades too.
    pub shadow_pixel_depth: bool,
    /// pomkit's LOD threshold (mip level).
    pub lod_threshold: f32,
}

impl Default for SceneOptions {
    fn default() -> Self {
        Self {
            method: Method::Pomkit(Technique::Pom),
            shadow: ShadowMode::Soft,
            pattern: Pattern::Cobblestones,
            size: 512,
            depth_scale: 0.08,
            pixel_depth: true,
            shadow_pixel_depth: false,
            lod_threshold: 4.0,
        }
    }
}

/// Handles of what [`spawn`] made, to change at run time.
#[derive(Resource, Clone)]
pub struct SceneHandles {
    /// The pomkit material of the cube and the floor (when the method is pomkit's).
    pub pomkit: Option<Handle<PomkitMaterial>>,
    /// The standard material (when the method is Bevy's).
    pub standard: Option<Handle<StandardMaterial>>,
    /// The camera.
    pub camera: Entity,
    /// The cube.
    pub cube: Entity,
    /// The sun.
    pub sun: Entity,
}

/// A repeating, bilinearly filtered `width` x `height` image of `format` holding `data`.
pub fn repeating_image(width: u32, height: u32, data: Vec<u8>, format: TextureFormat) -> Image {
    let mut image = Image::new(
        Extent3d { width, height, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data,
        format,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}

/// An sRGB albedo image of `pattern`.
pub fn albedo_image(pattern: Pattern, size: u32) -> Image {
    let data: Vec<u8> = albedo(pattern, size, size).into_iter().flat_map(|[r, g, b]| [r, g, b, 255]).collect();
    repeating_image(size, size, data, TextureFormat::Rgba8UnormSrgb)
}

/// A half-float depth map (white deep) for Bevy's own `StandardMaterial::depth_map`.
pub fn bevy_depth_map(pattern: Pattern, size: u32) -> Image {
    bevy_depth_map_of(&generate(pattern, size, size))
}

/// [`bevy_depth_map`] of any height field.
pub fn bevy_depth_map_of(field: &pomkit_core::heightfield::HeightField) -> Image {
    let data: Vec<u8> = field.depths().iter().flat_map(|&d| pomkit_gpu::util::f32_to_f16(d).to_le_bytes()).collect();
    repeating_image(field.width(), field.height(), data, TextureFormat::R16Float)
}

/// The camera's pose: above and in front of the cube, looking down at about 30 degrees.
pub fn camera_transform() -> Transform {
    Transform::from_xyz(1.8, 1.6, 2.6).looking_at(Vec3::new(0.0, 0.3, 0.0), Vec3::Y)
}

/// Spawns the scene; the camera renders into `target` (a window when `None`).
pub fn spawn(world: &mut World, target: Option<RenderTarget>, opts: &SceneOptions) -> SceneHandles {
    let albedo = world.resource_mut::<Assets<Image>>().add(albedo_image(opts.pattern, opts.size));
    let cube_mesh =
        Mesh::from(Cuboid::new(1.0, 1.0, 1.0)).with_generated_tangents().expect("a cuboid has normals and UVs");
    let floor_mesh = Mesh::from(Plane3d::default().mesh().size(8.0, 8.0))
        .with_generated_tangents()
        .expect("a plane has normals and UVs");
    let (cube_mesh, floor_mesh) = {
        let mut meshes = world.resource_mut::<Assets<Mesh>>();
        (meshes.add(cube_mesh), meshes.add(floor_mesh))
    };
    let base =
        StandardMaterial { base_color_texture: Some(albedo), perceptual_roughness: 0.8, reflectance: 0.3, ..default() };
    let mut handles = SceneHandles {
        pomkit: None,
        standard: None,
        camera: Entity::PLACEHOLDER,
        cube: Entity::PLACEHOLDER,
        sun: Entity::PLACEHOLDER,
    };
    // The floor repeats the tile four times; the cube shows one tile per face.
    let floor_uv = Affine2::from_scale(Vec2::splat(4.0));
    let cube = match opts.method {
        Method::Pomkit(technique) => {
            let heights =
                world.resource_mut::<Assets<Image>>().add(depth_image(&generate(opts.pattern, opts.size, opts.size)));
            let mut ext = Pomkit::new(heights)
                .with_technique(technique)
                .with_shadow(opts.shadow)
                .with_depth_scale(opts.depth_scale);
            ext.map_kind = MapKind::Depth;
            ext.pixel_depth_offset = opts.pixel_depth;
            ext.shadow_pixel_depth = opts.shadow_pixel_depth;
            ext.lod_threshold = opts.lod_threshold;
            let mut materials = world.resource_mut::<Assets<PomkitMaterial>>();
            let cube = materials.add(PomkitMaterial { base: base.clone(), extension: ext.clone() });
            let floor = materials
                .add(PomkitMaterial { base: StandardMaterial { uv_transform: floor_uv, ..base }, extension: ext });
            handles.pomkit = Some(cube.clone());
            let c = world.spawn((Mesh3d(cube_mesh), MeshMaterial3d(cube), Transform::from_xyz(0.0, 0.5, 0.0))).id();
            world.spawn((Mesh3d(floor_mesh), MeshMaterial3d(floor)));
            c
        }
        Method::Bevy(_) | Method::Plain => {
            let standard = match opts.method {
                Method::Bevy(method) => StandardMaterial {
                    depth_map: Some(world.resource_mut::<Assets<Image>>().add(bevy_depth_map(opts.pattern, opts.size))),
                    parallax_depth_scale: opts.depth_scale,
                    parallax_mapping_method: method,
                    max_parallax_layer_count: 32.0,
                    ..base
                },
                _ => base,
            };
            let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
            let cube = materials.add(standard.clone());
            let floor = materials.add(StandardMaterial { uv_transform: floor_uv, ..standard });
            handles.standard = Some(cube.clone());
            let c = world.spawn((Mesh3d(cube_mesh), MeshMaterial3d(cube), Transform::from_xyz(0.0, 0.5, 0.0))).id();
            world.spawn((Mesh3d(floor_mesh), MeshMaterial3d(floor)));
            c
        }
    };
    handles.cube = cube;
    world.insert_resource(DirectionalLightShadowMap { size: 2048 });
    handles.sun = world
        .spawn((
            DirectionalLight { illuminance: 8000.0, shadow_maps_enabled: true, ..default() },
            Transform::from_xyz(-3.0, 2.0, 1.5).looking_at(Vec3::ZERO, Vec3::Y),
            CascadeShadowConfigBuilder { maximum_distance: 12.0, first_cascade_far_bound: 4.0, ..default() }.build(),
        ))
        .id();
    world.insert_resource(GlobalAmbientLight { brightness: 300.0, ..default() });
    let mut camera = world.spawn((Camera3d::default(), camera_transform(), Tonemapping::AcesFitted, Msaa::Off));
    if let Some(target) = target {
        camera.insert(target);
    }
    handles.camera = camera.id();
    world.insert_resource(handles.clone());
    handles
}
