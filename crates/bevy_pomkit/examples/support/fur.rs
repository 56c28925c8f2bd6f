//! McGuire and McGuire 2005's fur and grass in Bevy (included with `#[path]` by the `fur`
//! example and tests/fur.rs): pomkit's scene file examples/scenes/fur.toml, loaded by pomkit-io,
//! spawned as Bevy entities. The same meshes (pomkit-core's sphere and plane with their UVs and
//! tangents), camera, lights and materials (steep parallax over the procedural fur and grass
//! height maps with their albedos, depth self-shadows) as pomkit's own renderers draw, so the
//! two can be compared pixel for pixel.
//!
//! pomkit's renderers light with Blinn-Phong (`albedo * intensity * N.L` per light, plus
//! `ambient * albedo`); Bevy's PBR divides the diffuse light by pi and scales everything by
//! the camera's exposure. The lights are converted so that a white Lambertian surface receives
//! the same light in both: `illuminance = intensity * pi / exposure` and an ambient
//! brightness of `1 / exposure`.

#![allow(dead_code, reason = "the example and the tests use different parts")]

use std::f32::consts::PI;
use std::path::PathBuf;

use bevy::asset::RenderAssetUsages;
use bevy::camera::{Exposure, RenderTarget};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
use bevy::light::CascadeShadowConfigBuilder;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{MapKind, Pomkit, PomkitDebug, PomkitMaterial};
use pomkit_core::heightfield::HeightField;
use pomkit_core::scene::{Light, Scene, Texture, linear_to_srgb};

/// The scene file.
pub fn scene_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/scenes/fur.toml")
}

/// examples/scenes/fur.toml as pomkit-io loads it (the procedural maps at 512x512).
///
/// # Errors
/// The loader's message, naming the file.
pub fn load_scene() -> Result<Scene, String> {
    let path = scene_path();
    pomkit_io::scene::load_scene(&path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The share of the height range that counts as the strands' tips in [`tips_color`].
pub const TIPS_BAND: f32 = 0.2;

/// The colour of fur or grass seen from afar: the mean linear albedo of the texels whose height
/// lies in the top `band` of the map's height range (the strands' tips), the albedo read at the
/// height texel's centre. `None` when the maps have no texel in that band.
pub fn tips_color(field: &HeightField, albedo: &Texture, band: f32) -> Option<Vec3> {
    let depths = field.depths();
    let shallowest = depths.iter().copied().fold(f32::INFINITY, f32::min);
    let deepest = depths.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let limit = shallowest + band * (deepest - shallowest);
    let (w, h) = (field.width(), field.height());
    let (aw, ah) = (albedo.width(), albedo.height());
    let mut sum = Vec3::ZERO;
    let mut n = 0u32;
    for y in 0..h {
        for x in 0..w {
            if depths[(y * w + x) as usize] <= limit {
                // The albedo texel under the height texel's centre.
                let ax = ((x as f32 + 0.5) / w as f32 * aw as f32) as i64;
                let ay = ((y as f32 + 0.5) / h as f32 * ah as f32) as i64;
                let c = albedo.texel(ax, ay, pomkit_core::EdgeMode::Clamp);
                sum += Vec3::new(c.x, c.y, c.z);
                n += 1;
            }
        }
    }
    (n > 0).then(|| sum / n as f32)
}

/// An sRGB albedo image of `texture` with its whole mip chain, each level a box filter of the
/// one before in linear colour (Bevy builds no mips of its own), repeating, filtered
/// trilinearly and anisotropically: the lawn is seen at grazing angles.
pub fn albedo_image(texture: &Texture) -> Image {
    let mut level = texture.clone();
    let mut data = Vec::new();
    let mut levels = 0;
    loop {
        data.extend(level.texels().iter().flat_map(|c| {
            let e = |v: f32| (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8;
            [e(c.x), e(c.y), e(c.z), 255]
        }));
        levels += 1;
        if level.width() == 1 && level.height() == 1 {
            break;
        }
        level = level.downsample();
    }
    let (w, h) = (texture.width(), texture.height());
    let mut image = Image::new_uninit(
        Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        TextureDimension::D2,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.data = Some(data);
    image.texture_descriptor.mip_level_count = levels;
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        anisotropy_clamp: 8,
        ..ImageSamplerDescriptor::linear()
    });
    image
}

/// pomkit-core's mesh as a Bevy mesh: the same positions, normals, UVs, tangents and triangles.
pub fn bevy_mesh(mesh: &pomkit_core::mesh::Mesh) -> Mesh {
    let v3 = |v: &[pomkit_core::glam::Vec3]| v.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>();
    Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, v3(&mesh.positions))
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, v3(&mesh.normals))
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, mesh.uvs.iter().map(|t| [t.x, t.y]).collect::<Vec<_>>())
        .with_inserted_attribute(
            Mesh::ATTRIBUTE_TANGENT,
            mesh.tangents.iter().map(|t| [t.x, t.y, t.z, t.w]).collect::<Vec<_>>(),
        )
        .with_inserted_indices(Indices::U32(mesh.indices.clone()))
}

fn vec3(v: pomkit_core::glam::Vec3) -> Vec3 {
    Vec3::new(v.x, v.y, v.z)
}

/// How to draw the scene.
#[derive(Clone, Debug)]
pub struct FurOptions {
    /// The LOD fade fades to the strands' tips' colour ([`tips_color`]) instead of the
    /// entry point's texture.
    pub far_color: bool,
    /// Debug view of every pomkit material.
    pub debug: PomkitDebug,
    /// Replaces every material's LOD threshold (`f32::MAX`: no fade).
    pub lod_threshold: Option<f32>,
    /// The sun casts Bevy's shadow maps (the ball's shadow on the lawn; pomkit's own renderers
    /// cast none between objects).
    pub shadow_maps: bool,
    /// Tone mapping of the camera (`None` for raw debug outputs).
    pub tonemapping: Tonemapping,
    /// The camera's pose instead of the scene's.
    pub camera: Option<Transform>,
}

impl Default for FurOptions {
    fn default() -> Self {
        Self {
            far_color: true,
            debug: PomkitDebug::Off,
            lod_threshold: None,
            shadow_maps: true,
            tonemapping: Tonemapping::ReinhardLuminance,
            camera: None,
        }
    }
}

/// What [`spawn`] made.
#[derive(Resource, Clone, Debug)]
pub struct FurHandles {
    /// One material per material of the scene, in its order.
    pub materials: Vec<Handle<PomkitMaterial>>,
    /// The tips' colour of each material (linear), where it has a height map and an albedo.
    pub tips: Vec<Option<Vec3>>,
    /// One entity per object of the scene, in its order.
    pub objects: Vec<Entity>,
    /// The camera.
    pub camera: Entity,
}

/// The camera's pose in `scene`.
pub fn camera_transform(scene: &Scene) -> Transform {
    let c = &scene.camera;
    Transform::from_translation(vec3(c.eye)).looking_at(vec3(c.target), vec3(c.up))
}

/// Spawns `scene`'s objects, lights and camera; the camera renders into `target` (a window
/// when `None`).
pub fn spawn(world: &mut World, scene: &Scene, target: Option<RenderTarget>, opts: &FurOptions) -> FurHandles {
    let exposure = Exposure::default().exposure();
    let mut materials = Vec::new();
    let mut tips = Vec::new();
    for m in &scene.materials {
        let tip = match (&m.height, &m.albedo) {
            (Some(h), Some(a)) => tips_color(h, a, TIPS_BAND),
            _ => None,
        };
        tips.push(tip);
        let albedo = m.albedo.as_ref().map(|a| world.resource_mut::<Assets<Image>>().add(albedo_image(a)));
        // Blinn-Phong's shininess as a Beckmann roughness (alpha^2 = 2 / (n + 2)), Bevy's
        // perceptual roughness its square root; the specular weight as reflectance.
        let alpha = (2.0 / (m.shininess + 2.0)).sqrt();
        let base = StandardMaterial {
            base_color: Color::linear_rgb(m.base_color.x, m.base_color.y, m.base_color.z),
            base_color_texture: albedo,
            perceptual_roughness: alpha.sqrt().clamp(0.089, 1.0),
            reflectance: (m.specular * 2.0).clamp(0.0, 1.0),
            ..default()
        };
        let heights = m.height.as_ref().map(|h| world.resource_mut::<Assets<Image>>().add(depth_image(h)));
        let mut ext = Pomkit::new(heights.unwrap_or_default());
        ext.map_kind = MapKind::Depth;
        ext.technique = m.technique;
        ext.shadow = m.shadow;
        ext.trace = m.trace;
        ext.depth_scale = m.depth_scale;
        ext.edges = m.edges;
        ext.lod_threshold = opts.lod_threshold.unwrap_or(m.lod_threshold);
        ext.pixel_depth_offset = m.pixel_depth_offset;
        ext.debug = opts.debug;
        ext.name = Some(format!("examples/scenes/fur.toml, material \"{}\"", m.name));
        if opts.far_color
            && let Some(t) = tip
        {
            ext = ext.with_far_color(Color::linear_rgb(t.x, t.y, t.z));
        }
        materials.push(world.resource_mut::<Assets<PomkitMaterial>>().add(PomkitMaterial { base, extension: ext }));
    }
    let mut objects = Vec::new();
    for o in &scene.objects {
        let mesh = world.resource_mut::<Assets<Mesh>>().add(bevy_mesh(&o.mesh));
        let transform = Transform::from_matrix(Mat4::from_cols_array(&o.transform.to_cols_array()));
        let material = materials[o.material].clone();
        objects.push(world.spawn((Mesh3d(mesh), MeshMaterial3d(material), transform, Name::new(o.name.clone()))).id());
    }
    let mut first = true;
    for light in &scene.lights {
        if let Light::Directional { direction, color, intensity } = *light {
            let c = color * intensity;
            let peak = c.max_element().max(1e-6);
            let shadows = opts.shadow_maps && first;
            first = false;
            world.spawn((
                DirectionalLight {
                    color: Color::linear_rgb(c.x / peak, c.y / peak, c.z / peak),
                    illuminance: peak * PI / exposure,
                    shadow_maps_enabled: shadows,
                    ..default()
                },
                Transform::default().looking_to(-vec3(direction), Vec3::Y),
                CascadeShadowConfigBuilder { maximum_distance: 10.0, first_cascade_far_bound: 4.0, ..default() }
                    .build(),
            ));
        }
    }
    let a = scene.ambient;
    world.insert_resource(GlobalAmbientLight {
        color: Color::linear_rgb(a.x, a.y, a.z),
        brightness: 1.0 / exposure,
        ..default()
    });
    let b = scene.background;
    world.insert_resource(ClearColor(Color::linear_rgb(b.x, b.y, b.z)));
    let projection = Projection::Perspective(PerspectiveProjection {
        fov: scene.camera.fov_y_deg.to_radians(),
        near: scene.camera.near,
        far: scene.camera.far,
        ..default()
    });
    let pose = opts.camera.unwrap_or_else(|| camera_transform(scene));
    let mut camera = world.spawn((Camera3d::default(), projection, pose, opts.tonemapping, Msaa::Off));
    if opts.tonemapping == Tonemapping::None {
        camera.insert(bevy::camera::Hdr);
    }
    if let Some(target) = target {
        camera.insert(target);
    }
    let handles = FurHandles { materials, tips, objects, camera: camera.id() };
    world.insert_resource(handles.clone());
    handles
}
