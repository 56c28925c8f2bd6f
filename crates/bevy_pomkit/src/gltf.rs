//! glTF files with height maps (feature `gltf`): a hook in Bevy's glTF loader that draws with a
//! [`PomkitMaterial`] every material that carries `KHR_materials_displacement` or pomkit's
//! settings in its `extras`.
//!
//! `KHR_materials_displacement` is a draft extension (docs/REFERENCES.md) that NVIDIA's
//! samples read. On a material it gives `displacementGeometryTexture` (a texture info; the red
//! channel is the height, white out), `displacementGeometryFactor` (default 1) and
//! `displacementGeometryOffset` (default 0): the surface moves along the normal by `red * factor
//! + offset`, in the mesh's own units. pomkit cannot raise a surface above its polygon: it draws
//! the polygon as the top of the relief (red = 1) and recesses the rest up to `factor` below it,
//! as if the offset were `-factor` (the offset is read and otherwise ignored). The depth scale,
//! in UV units, is `factor / L` with `L` the mean length of one UV unit of the mesh in its own
//! units ([`pomkit_core::mesh::mean_uv_unit_length`]), computed per mesh primitive.
//!
//! pomkit's own settings ride in the material's `extras` under `"pomkit"`, with the scene-file
//! material keys of docs/SCENES.md: `{"pomkit": {"technique": "relief", "shadow": "soft",
//! "depth_scale": 0.05}}`. `depth_scale` there replaces the one the factor gives; `height` (a
//! path relative to the glTF file) gives a material without the extension a height map. A key
//! that is unknown, has a bad value, or means nothing in Bevy (the glTF's own textures and
//! shading stand) is ignored with one warning naming the material.
//!
//! The base colour, normal map, roughness and every other part of the material stay the
//! `StandardMaterial` Bevy made of it. What cannot be traced (a displacement texture that does
//! not exist or cannot be loaded, a factor that is negative or not a number, a mesh without
//! UVs) is reported once in the log, naming the file and the material, and drawn as that plain
//! `StandardMaterial`. Every report also lands in [`HeightMaps::reports`](crate::HeightMaps).

use std::sync::{Arc, Mutex};

use bevy::asset::{Handle, LoadContext};
use bevy::ecs::world::EntityWorldMut;
use bevy::gltf::GltfMaterial;
use bevy::gltf::extensions::{ErasedGltfExtensionHandler, GltfExtensionHandler, GltfExtensionHandlers};
use bevy::image::Image;
use bevy::log::{info, warn};
use bevy::mesh::{Mesh, Mesh3d, MeshVertexAttribute};
use bevy::pbr::{MeshMaterial3d, StandardMaterial};
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::tasks::ConditionalSendFuture;
use pomkit_core::EdgeMode;
use pomkit_core::params::{self, Kind, Value};
use serde_json::{Map, Value as Json};

use crate::height::{Channel, MapKind};
use crate::{Pomkit, PomkitMaterial};

/// The glTF extension a material's height map comes from.
pub const DISPLACEMENT_EXTENSION: &str = "KHR_materials_displacement";

/// The key of pomkit's settings in a material's `extras`.
pub const EXTRAS_KEY: &str = "pomkit";

/// Reports shared between the loader's hook (on the loader's threads) and [`crate::HeightMaps`]:
/// each message is logged once, when first added.
#[derive(Clone, Default)]
pub(crate) struct SharedReports(Arc<Mutex<Vec<String>>>);

impl SharedReports {
    fn add(&self, message: String) {
        let Ok(mut all) = self.0.lock() else { return };
        if !all.contains(&message) {
            warn!("{message}");
            all.push(message);
        }
    }

    pub(crate) fn all(&self) -> Vec<String> {
        self.0.lock().map(|r| r.clone()).unwrap_or_default()
    }
}

/// Adds the hook to Bevy's glTF loader, if the app has one (`GltfPlugin`, in `DefaultPlugins`
/// with Bevy's `bevy_gltf` feature).
pub(crate) fn register(app: &mut App, reports: SharedReports) {
    let Some(handlers) = app.world().get_resource::<GltfExtensionHandlers>() else {
        info!("bevy_pomkit: no glTF loader in this app (GltfPlugin): glTF height maps are not read");
        return;
    };
    handlers.0.write_blocking().push(Box::new(GltfHook { reports, ..Default::default() }));
    app.register_type::<GltfPomkitMesh>();
    app.add_systems(PostUpdate, generate_tangents.before(crate::check_meshes));
}

/// Where a material's height map comes from.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum HeightSource {
    /// `KHR_materials_displacement`'s texture: its index in the file's textures.
    Texture(usize),
    /// `extras.pomkit.height`: a path relative to the glTF file.
    File(String),
}

/// What a material's JSON asks of pomkit.
#[derive(Clone, Debug)]
pub(crate) struct Request {
    /// The height map.
    pub source: HeightSource,
    /// The extension's `displacementGeometryFactor`: the relief's depth in the mesh's units.
    pub factor: Option<f32>,
    /// `extras.pomkit.depth_scale`, which replaces the depth the factor gives.
    pub depth_scale: Option<f32>,
    /// The settings (technique, shadows, ...), with a placeholder height map.
    pub extension: Pomkit,
}

/// Reads a material's extensions and extras.
///
/// `Ok(None)`: no extension and no pomkit extras, a plain material. `Err`: the one reason the
/// material cannot be traced. `warnings` gets one line per ignored setting.
pub(crate) fn read_material(
    extensions: Option<&Map<String, Json>>,
    extras: Option<&str>,
    warnings: &mut Vec<String>,
) -> Result<Option<Request>, String> {
    let displacement = extensions.and_then(|e| e.get(DISPLACEMENT_EXTENSION));
    let pomkit = match extras.map(serde_json::from_str::<Json>) {
        Some(Ok(Json::Object(mut o))) => match o.remove(EXTRAS_KEY) {
            Some(Json::Object(p)) => Some(p),
            Some(other) => {
                warnings.push(format!("extras.{EXTRAS_KEY} is {other}, not an object: ignored"));
                None
            }
            None => None,
        },
        // Extras that are not an object, or not JSON pomkit can read, belong to someone else.
        _ => None,
    };
    if displacement.is_none() && pomkit.is_none() {
        return Ok(None);
    }
    let mut extension = Pomkit::new(Handle::default());
    // The extension's height is the red channel, white out.
    extension.channel = Channel::R;
    extension.map_kind = MapKind::Height;
    let mut request = Request { source: HeightSource::File(String::new()), factor: None, depth_scale: None, extension };
    let mut height_file = None;
    if let Some(settings) = &pomkit {
        for (key, value) in settings {
            match apply_setting(&mut request, key, value) {
                Ok(Some(path)) => height_file = Some(path),
                Ok(None) => {}
                Err(why) => warnings.push(format!("extras.{EXTRAS_KEY}.{key}: {why}: ignored")),
            }
        }
    }
    match displacement {
        Some(d) => {
            let (texture, factor) = read_displacement(d)?;
            if height_file.is_some() {
                warnings.push(format!(
                    "extras.{EXTRAS_KEY}.height: the {DISPLACEMENT_EXTENSION} texture is the height map: ignored"
                ));
            }
            request.source = HeightSource::Texture(texture);
            request.factor = Some(factor);
        }
        None => match height_file {
            Some(path) => request.source = HeightSource::File(path),
            None => {
                return Err(format!(
                    "extras.{EXTRAS_KEY} has settings but the material has no height map (no {DISPLACEMENT_EXTENSION}, no \"height\" key)"
                ));
            }
        },
    }
    Ok(Some(request))
}

/// The extension's texture index and factor.
fn read_displacement(d: &Json) -> Result<(usize, f32), String> {
    let Json::Object(d) = d else {
        return Err(format!("{DISPLACEMENT_EXTENSION} is {d}, not an object"));
    };
    let Some(info) = d.get("displacementGeometryTexture") else {
        return Err(format!("{DISPLACEMENT_EXTENSION} has no displacementGeometryTexture"));
    };
    let index = info.get("index").and_then(Json::as_u64).and_then(|i| usize::try_from(i).ok());
    let Some(index) = index else {
        return Err(format!("{DISPLACEMENT_EXTENSION}'s displacementGeometryTexture has no texture index ({info})"));
    };
    match info.get("texCoord") {
        None => {}
        Some(t) if t.as_u64() == Some(0) => {}
        Some(t) => {
            return Err(format!(
                "{DISPLACEMENT_EXTENSION}'s displacementGeometryTexture reads UV set {t}: pomkit traces in the first (TEXCOORD_0)"
            ));
        }
    }
    let factor = match d.get("displacementGeometryFactor") {
        None => 1.0,
        Some(f) => match f.as_f64() {
            Some(x) if x.is_finite() && x > 0.0 && (x as f32).is_finite() => x as f32,
            Some(0.0) => return Err(format!("{DISPLACEMENT_EXTENSION}'s displacementGeometryFactor is 0: no relief")),
            _ => {
                return Err(format!(
                    "{DISPLACEMENT_EXTENSION}'s displacementGeometryFactor is {f}, not a finite number above 0"
                ));
            }
        },
    };
    if let Some(offset) = d.get("displacementGeometryOffset")
        && !offset.as_f64().is_some_and(f64::is_finite)
    {
        return Err(format!("{DISPLACEMENT_EXTENSION}'s displacementGeometryOffset is {offset}, not a number"));
    }
    Ok((index, factor))
}

/// The table's value of `json` for parameter `p`, if it is of the parameter's type.
fn value_of(p: &params::Param, json: &Json) -> Option<Value> {
    match (p.kind, json) {
        (Kind::Float { .. }, Json::Number(n)) => n.as_f64().map(Value::Float),
        (Kind::Int { .. }, Json::Number(n)) => n.as_i64().map(Value::Int),
        (Kind::Bool, Json::Bool(b)) => Some(Value::Bool(*b)),
        (Kind::Choice(names), Json::String(s)) => {
            names.iter().find(|n| n.eq_ignore_ascii_case(s)).map(|n| Value::Name(n))
        }
        (Kind::Color, Json::Array(a)) if a.len() == 3 => {
            let c: Vec<f64> = a.iter().filter_map(Json::as_f64).collect();
            (c.len() == 3).then(|| Value::Color([c[0], c[1], c[2]]))
        }
        _ => None,
    }
}

/// Applies one `extras.pomkit` key to `r`. `Ok(Some(path))` for `height`; `Err` says why the key
/// is ignored.
fn apply_setting(r: &mut Request, key: &str, json: &Json) -> Result<Option<String>, String> {
    match key {
        "height" => {
            return match json {
                Json::String(s) if !s.is_empty() && !s.starts_with("builtin:") => Ok(Some(s.clone())),
                Json::String(s) if s.starts_with("builtin:") => {
                    Err("built-in height maps are not read from glTF files (give an image file)".to_owned())
                }
                _ => Err(format!("{json} is not a file name")),
            };
        }
        "name" | "albedo" | "normal" | "base_color" | "specular" | "shininess" => {
            return Err("the glTF material's own textures and values are drawn, by Bevy's PBR".to_owned());
        }
        "normal_y_down" | "normalize" | "cone_map" => {
            return Err("not supported by bevy_pomkit".to_owned());
        }
        _ => {}
    }
    let Some(p) = params::get(key) else {
        return Err("unknown key (docs/SCENES.md lists the material keys)".to_owned());
    };
    let value = value_of(p, json).filter(|v| p.kind.accepts(v));
    let Some(value) = value else {
        return Err(format!("{json} is not {}", p.kind.describe()));
    };
    let e = &mut r.extension;
    let count = |v: i64| -> u32 {
        match p.kind {
            Kind::Int { min, max, .. } => u32::try_from(v.clamp(min, max)).unwrap_or(u32::MAX),
            _ => 0,
        }
    };
    match (key, value) {
        ("technique", Value::Name(n)) => e.technique = n.parse().map_err(|err| format!("{err}"))?,
        ("shadow", Value::Name(n)) => e.shadow.mode = n.parse()?,
        ("edges", Value::Name(n)) => e.edges = EdgeMode::from_name(n).unwrap_or_default(),
        ("channel", Value::Name(n)) => {
            e.channel = match n {
                "r" => Channel::R,
                "g" => Channel::G,
                "b" => Channel::B,
                "a" => Channel::A,
                _ => Channel::Luma,
            };
        }
        ("depth_map", Value::Bool(b)) => e.map_kind = if b { MapKind::Depth } else { MapKind::Height },
        ("pixel_depth_offset", Value::Bool(b)) => e.pixel_depth_offset = b,
        ("silhouette", Value::Bool(b)) => e.silhouette = b,
        ("depth_scale", Value::Float(x)) => r.depth_scale = Some(x as f32),
        ("perspective_bias", Value::Float(x)) => e.trace.perspective_bias = x as f32,
        ("softness", Value::Float(x)) => e.shadow.softness = x as f32,
        ("lod_threshold", Value::Float(x)) => e.lod_threshold = x as f32,
        ("min_samples", Value::Int(n)) => e.trace.min_samples = count(n),
        ("max_samples", Value::Int(n)) => e.trace.max_samples = count(n),
        ("samples", Value::Int(n)) => e.trace.samples = count(n),
        ("iterations", Value::Int(n)) => e.trace.iterations = count(n),
        ("binary_steps", Value::Int(n)) => e.trace.binary_steps = count(n),
        ("refine", Value::Int(n)) => e.trace.refine = count(n),
        // A whole number where a number is expected.
        ("depth_scale" | "perspective_bias" | "softness" | "lod_threshold", Value::Int(n)) => {
            return apply_setting(r, key, &Json::from(n as f64));
        }
        _ => return Err("not supported by bevy_pomkit".to_owned()),
    }
    Ok(None)
}

/// A material of the file that is drawn with pomkit, before its depth is known (that takes the
/// mesh it is drawn on).
#[derive(Clone)]
struct Prepared {
    base: StandardMaterial,
    request: Request,
}

/// The mean length of a UV unit of each primitive (mesh index, primitive index), or why there
/// is none.
type UvUnits = HashMap<(usize, usize), Result<f32, String>>;

/// The hook. One clone per load holds that load's state.
#[derive(Clone, Default)]
struct GltfHook {
    reports: SharedReports,
    /// The file, for messages.
    asset: String,
    /// The file's textures, in its order.
    textures: Vec<Handle<Image>>,
    /// Materials drawn with pomkit, by Bevy's material label.
    materials: HashMap<String, Prepared>,
    /// Names of materials, by label, for messages.
    names: HashMap<String, String>,
    uv_units: UvUnits,
    /// The PomkitMaterials made, by material label and depth scale.
    made: HashMap<(String, u32), Handle<PomkitMaterial>>,
    /// Material labels that have a PomkitMaterial already.
    labels: HashSet<String>,
}

/// A marker on the mesh entities of glTF scenes that the hook drew with pomkit: their meshes get
/// tangents where the file has none (Bevy generates them only for materials with a normal map).
///
/// Registered for reflection, as every component of a glTF scene must be.
#[derive(Component, Reflect, Clone, Copy, Debug, Default)]
#[reflect(Component, Default)]
pub struct GltfPomkitMesh;

impl GltfHook {
    fn whose(&self, name: &str) -> String {
        format!("bevy_pomkit: glTF \"{}\", material {name}", self.asset)
    }

    fn plain(&self, name: &str, why: &str) {
        self.reports.add(format!("{}: {why}: drawing the plain StandardMaterial", self.whose(name)));
    }
}

fn material_name(m: &::gltf::Material) -> String {
    match (m.name(), m.index()) {
        (Some(n), _) => format!("\"{n}\""),
        (None, Some(i)) => format!("#{i}"),
        (None, None) => "(the default material)".to_owned(),
    }
}

/// The mean UV unit of a primitive, in the mesh's own units.
fn uv_unit(primitive: &::gltf::Primitive, buffers: &[Vec<u8>]) -> Result<f32, String> {
    if primitive.mode() != ::gltf::mesh::Mode::Triangles {
        return Err(format!("it is drawn as {:?}, not as triangles", primitive.mode()));
    }
    let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let positions: Vec<[f32; 3]> = reader.read_positions().ok_or("it has no POSITION")?.collect();
    let uvs: Vec<[f32; 2]> =
        reader.read_tex_coords(0).ok_or("it has no TEXCOORD_0 (UVs) to trace in")?.into_f32().collect();
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..u32::try_from(positions.len()).map_err(|_| "it has too many vertices")?).collect(),
    };
    pomkit_core::mesh::mean_uv_unit_length(&positions, &uvs, &indices)
        .ok_or_else(|| "its UVs cover no area (or its vertices are not finite)".to_owned())
}

impl GltfExtensionHandler for GltfHook {
    fn dyn_clone(&self) -> Box<dyn ErasedGltfExtensionHandler> {
        Box::new(self.clone())
    }

    fn on_root(
        &mut self,
        load_context: &mut LoadContext<'_>,
        _gltf: &::gltf::Gltf,
        _settings: &bevy::gltf::GltfLoaderSettings,
    ) {
        self.asset = load_context.path().to_string();
    }

    fn on_texture(&mut self, _gltf_texture: &::gltf::Texture, texture: Handle<Image>) {
        self.textures.push(texture);
    }

    fn on_material(
        &mut self,
        load_context: &mut LoadContext<'_>,
        gltf_material: &::gltf::Material,
        _material: Handle<GltfMaterial>,
        _material_asset: &GltfMaterial,
        material_label: &str,
    ) {
        let name = material_name(gltf_material);
        let mut warnings = Vec::new();
        let extras = gltf_material.extras().as_ref().map(|r| r.get());
        let read = read_material(gltf_material.extensions(), extras, &mut warnings);
        for w in warnings {
            self.reports.add(format!("{}: {w}", self.whose(&name)));
        }
        let mut request = match read {
            Ok(Some(r)) => r,
            Ok(None) => return,
            Err(why) => return self.plain(&name, &why),
        };
        let height = match &request.source {
            HeightSource::Texture(i) => match self.textures.get(*i) {
                Some(h) => h.clone(),
                None => {
                    let why = format!(
                        "{DISPLACEMENT_EXTENSION}'s texture index {i} names no texture (the file has {})",
                        self.textures.len()
                    );
                    return self.plain(&name, &why);
                }
            },
            HeightSource::File(path) => match load_context.path().resolve_embed_str(path) {
                Ok(p) => load_context.load(p),
                Err(e) => return self.plain(&name, &format!("extras.{EXTRAS_KEY}.height \"{path}\": {e}")),
            },
        };
        // The StandardMaterial Bevy made of it (bevy_pbr's own glTF hook, which runs first).
        let base = load_context.get_labeled(format!("{material_label}/std")).and_then(|a| a.get::<StandardMaterial>());
        let Some(base) = base.cloned() else {
            return self.plain(
                &name,
                "Bevy made no StandardMaterial of it (PbrPlugin's gltf_enable_standard_materials is off?)",
            );
        };
        request.extension.height_map = height;
        request.extension.name = Some(format!("glTF \"{}\", material {name}", self.asset));
        self.names.insert(material_label.to_owned(), name);
        self.materials.insert(material_label.to_owned(), Prepared { base, request });
    }

    fn on_gltf_primitive(
        &mut self,
        _load_context: &mut LoadContext<'_>,
        _gltf_document: &::gltf::Gltf,
        gltf_mesh: &::gltf::Mesh,
        gltf_primitive: &::gltf::Primitive,
        buffer_data: &[Vec<u8>],
        _custom_vertex_attributes: &HashMap<Box<str>, MeshVertexAttribute>,
        _gltf_mesh_on_skinned_nodes: bool,
        _gltf_mesh_on_non_skinned_nodes: bool,
        _user_mesh: &mut Option<Mesh>,
    ) -> impl ConditionalSendFuture<Output = ()> {
        // Only the primitives of materials drawn with pomkit (materials are read first; the
        // inverted-scale copies Bevy makes later share their index).
        let pomkit = gltf_primitive.material().index().is_some_and(|i| {
            self.materials.contains_key(&format!("Material{i}"))
                || self.materials.contains_key(&format!("Material{i} (inverted)"))
        });
        if pomkit {
            let unit = uv_unit(gltf_primitive, buffer_data);
            self.uv_units.insert((gltf_mesh.index(), gltf_primitive.index()), unit);
        }
        async {}
    }

    fn on_spawn_mesh_and_material(
        &mut self,
        load_context: &mut LoadContext<'_>,
        primitive: &::gltf::Primitive,
        mesh: &::gltf::Mesh,
        _material: &::gltf::Material,
        entity: &mut EntityWorldMut,
        material_label: &str,
    ) {
        let Some(prepared) = self.materials.get(material_label) else { return };
        let name = self.names.get(material_label).cloned().unwrap_or_default();
        let key = (mesh.index(), primitive.index());
        let mesh_name = mesh.name().map_or_else(|| format!("#{}", mesh.index()), |n| format!("\"{n}\""));
        let unit = match self.uv_units.get(&key) {
            Some(Ok(unit)) => *unit,
            Some(Err(why)) => {
                return self.plain(&name, &format!("mesh {mesh_name}, primitive {}: {why}", primitive.index()));
            }
            None => return self.plain(&name, &format!("mesh {mesh_name} was not read")),
        };
        let r = &prepared.request;
        let depth = match (r.depth_scale, r.factor) {
            (Some(d), _) => d,
            (None, Some(f)) => match pomkit_core::mesh::displacement_depth_scale(f, unit) {
                Some(d) => d,
                None => {
                    return self
                        .plain(&name, &format!("a depth of {f} on mesh {mesh_name} (UV unit {unit}) is no depth"));
                }
            },
            // A height file without a depth: pomkit's default.
            (None, None) => r.extension.depth_scale,
        };
        let made_key = (material_label.to_owned(), depth.to_bits());
        let handle = match self.made.get(&made_key) {
            Some(h) => h.clone(),
            None => {
                let label = if self.labels.insert(material_label.to_owned()) {
                    format!("{material_label}/pomkit")
                } else {
                    format!("{material_label}/pomkit/Mesh{}/Primitive{}", key.0, key.1)
                };
                let material = PomkitMaterial {
                    base: prepared.base.clone(),
                    extension: prepared.request.extension.clone().with_depth_scale(depth),
                };
                let h = load_context.add_labeled_asset(label, material);
                self.made.insert(made_key, h.clone());
                h
            }
        };
        entity.remove::<MeshMaterial3d<StandardMaterial>>().insert((MeshMaterial3d(handle), GltfPomkitMesh));
    }

    fn on_scene_completed(
        &mut self,
        _load_context: &mut LoadContext<'_>,
        _scene: &::gltf::Scene,
        _world_root_id: Entity,
        scene_world: &mut World,
    ) {
        // Whatever order the hooks ran in, an entity drawn with pomkit has no StandardMaterial.
        let mut both = scene_world
            .query_filtered::<Entity, (With<MeshMaterial3d<PomkitMaterial>>, With<MeshMaterial3d<StandardMaterial>>)>();
        let entities: Vec<Entity> = both.iter(scene_world).collect();
        for e in entities {
            scene_world.entity_mut(e).remove::<MeshMaterial3d<StandardMaterial>>();
        }
    }
}

/// The glTF mesh entities drawn with pomkit whose mesh was just set.
type NewGltfMeshes = (With<GltfPomkitMesh>, Or<(Added<GltfPomkitMesh>, Changed<Mesh3d>)>);

/// Gives the meshes of glTF entities drawn with pomkit the tangents the file left out (Bevy's
/// loader generates them only for materials with a normal map), with Bevy's MikkTSpace.
fn generate_tangents(
    query: Query<&Mesh3d, NewGltfMeshes>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut pending: Local<Vec<AssetId<Mesh>>>,
) {
    pending.extend(query.iter().map(|m| m.0.id()));
    pending.retain(|id| {
        let Some(mesh) = meshes.get(*id) else { return true };
        let wants = !mesh.contains_attribute(Mesh::ATTRIBUTE_TANGENT)
            && mesh.contains_attribute(Mesh::ATTRIBUTE_NORMAL)
            && mesh.contains_attribute(Mesh::ATTRIBUTE_UV_0);
        if wants && let Some(mut mesh) = meshes.get_mut(*id) {
            // On failure the mesh stays without tangents, and the plugin reports it.
            let _ = mesh.generate_tangents();
        }
        false
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use pomkit_core::trace::Technique;

    fn read(ext: &str, extras: Option<&str>) -> (Result<Option<Request>, String>, Vec<String>) {
        let ext: Json = serde_json::from_str(ext).expect("JSON");
        let mut warnings = Vec::new();
        let r = read_material(ext.as_object(), extras, &mut warnings);
        (r, warnings)
    }

    const DISP: &str = r#"{"KHR_materials_displacement": {"displacementGeometryTexture": {"index": 2}, "displacementGeometryFactor": 0.05}}"#;

    #[test]
    fn the_extension_gives_the_texture_and_the_factor() {
        let (r, w) = read(DISP, None);
        let r = r.expect("read").expect("a pomkit material");
        assert!(w.is_empty(), "{w:?}");
        assert_eq!(r.source, HeightSource::Texture(2));
        assert_eq!(r.factor, Some(0.05));
        assert_eq!(r.depth_scale, None);
        assert_eq!((r.extension.channel, r.extension.map_kind), (Channel::R, MapKind::Height));
        // Without the factor, 1.
        let (r, _) = read(r#"{"KHR_materials_displacement": {"displacementGeometryTexture": {"index": 0}}}"#, None);
        assert_eq!(r.expect("read").expect("pomkit").factor, Some(1.0));
        // Neither extension nor extras (nor extras of someone else): plain.
        assert!(read("{}", None).0.expect("read").is_none());
        assert!(read("{}", Some(r#"{"other": 1}"#)).0.expect("read").is_none());
        assert!(read("{}", Some("[1, 2]")).0.expect("read").is_none());
    }

    #[test]
    fn extras_override_and_bad_keys_are_ignored_with_a_warning() {
        let extras = r#"{"pomkit": {"technique": "relief", "shadow": "soft", "depth_scale": 0.25,
            "max_samples": 5000, "edges": "clamp", "colour": 3, "binary_steps": "many", "specular": 1}}"#;
        let (r, w) = read(DISP, Some(extras));
        let r = r.expect("read").expect("pomkit");
        assert_eq!(r.extension.technique, Technique::Relief);
        assert_eq!(r.extension.shadow.mode, pomkit_core::shadow::ShadowMode::Soft);
        assert_eq!(r.depth_scale, Some(0.25));
        assert_eq!(r.extension.edges, EdgeMode::Clamp);
        // Counts are clamped as in scene files.
        assert_eq!(r.extension.trace.max_samples, pomkit_core::trace::MAX_SAMPLES);
        assert_eq!(w.len(), 3, "{w:?}");
        for key in ["colour", "binary_steps", "specular"] {
            assert!(w.iter().any(|m| m.contains(&format!("pomkit.{key}")) && m.ends_with("ignored")), "{key}: {w:?}");
        }
        assert_eq!(r.extension.trace.binary_steps, pomkit_core::trace::TraceParams::default().binary_steps);
        assert!(!r.extension.silhouette, "silhouettes are off unless asked for");
        // Silhouettes, as in scene files; a key bevy_pomkit cannot honour still warns.
        let (r, w) = read(DISP, Some(r#"{"pomkit": {"silhouette": true, "cone_map": "c.exr"}}"#));
        assert!(r.expect("read").expect("pomkit").extension.silhouette);
        assert!(w.len() == 1 && w[0].contains("pomkit.cone_map"), "{w:?}");
    }

    #[test]
    fn bad_factors_and_textures_refuse_the_material() {
        for (ext, expect) in [
            (r#"{"displacementGeometryTexture": {"index": 0}, "displacementGeometryFactor": -1}"#, "is -1"),
            (r#"{"displacementGeometryTexture": {"index": 0}, "displacementGeometryFactor": "NaN"}"#, "is \"NaN\""),
            (r#"{"displacementGeometryFactor": 1}"#, "no displacementGeometryTexture"),
            (r#"{"displacementGeometryTexture": {"index": 0, "texCoord": 1}}"#, "UV set 1"),
            (r#"{"displacementGeometryTexture": {"index": -3}}"#, "no texture index"),
        ] {
            let (r, _) = read(&format!("{{\"{DISPLACEMENT_EXTENSION}\": {ext}}}"), None);
            let err = r.expect_err(ext);
            assert!(err.contains(expect), "{ext}: {err}");
        }
        // Extras alone need a height map.
        let (r, _) = read("{}", Some(r#"{"pomkit": {"technique": "pom"}}"#));
        assert!(r.expect_err("no height").contains("no height map"));
        let (r, w) = read("{}", Some(r#"{"pomkit": {"height": "h.png", "depth_map": true}}"#));
        let r = r.expect("read").expect("pomkit");
        assert_eq!(r.source, HeightSource::File("h.png".into()));
        assert_eq!(r.extension.map_kind, MapKind::Depth);
        assert!(w.is_empty());
    }
}
