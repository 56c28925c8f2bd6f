//! bevy_pomkit: pomkit's parallax techniques in Bevy.
//!
//! Add [`PomkitPlugin`], then draw meshes with a [`PomkitMaterial`]: Bevy's
//! `StandardMaterial` extended with a height map and pomkit's tracing. Every texture of the
//! standard material is sampled at the traced UV, so Bevy's PBR shading, lights, shadow maps,
//! fog and post-processing apply to the displaced surface as to any other.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_pomkit::{Pomkit, PomkitMaterial, PomkitPlugin, Technique};
//!
//! fn setup(
//!     mut commands: Commands,
//!     mut meshes: ResMut<Assets<Mesh>>,
//!     mut materials: ResMut<Assets<PomkitMaterial>>,
//!     asset_server: Res<AssetServer>,
//! ) {
//!     let mesh = Mesh::from(Plane3d::default().mesh().size(2.0, 2.0)).with_generated_tangents().unwrap();
//!     commands.spawn((
//!         Mesh3d(meshes.add(mesh)),
//!         MeshMaterial3d(materials.add(PomkitMaterial {
//!             base: StandardMaterial { base_color_texture: Some(asset_server.load("albedo.png")), ..default() },
//!             extension: Pomkit::new(asset_server.load("height.png")).with_technique(Technique::Exact),
//!         })),
//!     ));
//! }
//! # fn main() { App::new().add_plugins((DefaultPlugins, PomkitPlugin)).add_systems(Startup, setup).run(); }
//! ```
//!
//! What the extension adds to the standard material (docs/EMBEDDING.md has the whole story):
//! - any pomkit technique (`pom`, `relief`, `exact`, ...), in the material's UV space after its
//!   `uv_transform`;
//! - self-shadowing from Bevy's directional, point and spot lights (hard, soft, exact or depth),
//!   applied to each light's direct contribution only (forward rendering; Bevy's deferred
//!   lighting pass shades without them);
//! - the LOD fade: the full technique up to a mip level of the height map, faded out over the
//!   next, on request to a colour seen from afar (fur's tips, [`Pomkit::far_color`]);
//! - the standard material's textures sampled at the hit with the entry UV's gradients;
//! - every option a pipeline specialisation (shader defs), so what is off costs nothing;
//! - pixel depth offset, in the main pass, the depth prepass and the deferred G-buffer, and on
//!   request in directional lights' shadow cascades;
//! - height maps from any Bevy `Image` of a readable format, rebuilt when the image changes, on
//!   the CPU or, per material, by compute passes on the GPU ([`HeightBuild`]), also every frame
//!   for a height map a compute shader writes;
//! - a debug output of the hit UV, the fetch count, the LOD weight or the self-shadow;
//! - on request ([`Pomkit::silhouette`]), the outline of the displaced surface on curved
//!   meshes, from a per-vertex curvature ([`ATTRIBUTE_CURVATURE`]) the plugin computes.
//!
//! Tangent handedness: tangents from different sources (authoring tools, Bevy's
//! `Mesh::generate_tangents`) do not always agree on the sign of `w` (docs/EMBEDDING.md,
//! Tangent handedness). The shader orients the bitangent by the screen-space UV derivatives, so
//! either sign traces the same way.

#[cfg(feature = "gltf")]
pub mod gltf;
mod gpu_height;
pub mod height;
mod material;
mod silhouette;

pub use gpu_height::{GpuHeightPass, HeightBuild, gpu_heights_supported};
pub use height::{Channel, HeightImageError, MapKind};
pub use material::{Pomkit, PomkitDebug, PomkitKey, PomkitUniform};
pub use pomkit_core::EdgeMode;
pub use pomkit_core::shadow::{ShadowMode, ShadowParams};
pub use pomkit_core::trace::{Technique, TraceParams};
pub use silhouette::{ATTRIBUTE_CURVATURE, CurvatureError, mesh_curvature};

use bevy::asset::{AssetEvent, AssetId, Assets, Handle, uuid_handle};
use bevy::image::Image;
use bevy::log::{error, warn};
use bevy::mesh::{Mesh, Mesh3d};
use bevy::pbr::{ExtendedMaterial, MaterialPlugin, MeshMaterial3d, StandardMaterial};
use bevy::platform::collections::{HashMap, HashSet};
use bevy::prelude::*;
use bevy::shader::Shader;

/// Bevy's `StandardMaterial` with pomkit's tracing.
pub type PomkitMaterial = ExtendedMaterial<StandardMaterial, Pomkit>;

/// pomkit's shader library as a Bevy import module, `pomkit::library`: every `pomkit_*`
/// function, struct and constant of docs/EMBEDDING.md. A shader of your own can
/// `#import pomkit::library::{pomkit_trace, PomkitParams}` once [`PomkitPlugin`] is added.
pub const LIBRARY_SHADER: Handle<Shader> = uuid_handle!("6f2a4c55-3b0e-4a3e-9d0c-5b7e2f1c9a10");

/// The material extension's shader (forward pass, prepass, deferred G-buffer and shadow passes).
pub const MATERIAL_SHADER: Handle<Shader> = uuid_handle!("0b8e41d2-7c4f-4f5b-a1c6-2e9d3f6a8b21");

/// The vertex stage of silhouette materials' pipelines (forward pass and prepass): Bevy's,
/// plus [`ATTRIBUTE_CURVATURE`] passed on to the fragment stage.
pub const SILHOUETTE_VERTEX_SHADER: Handle<Shader> = uuid_handle!("3c1f7a9e-52d4-4b8a-8e6f-d40b7c2a5e93");

/// The import path of [`LIBRARY_SHADER`].
pub const LIBRARY_IMPORT_PATH: &str = "pomkit::library";

/// The library source as a Bevy shader module: pomkit's plain-WGSL library with an import path.
///
/// Bevy composes shader modules with naga_oil, which refuses identifiers that naga would rename
/// when writing WGSL back, those ending in a digit (`uv0`, `t1`, `pad0`): each of the library's
/// own such identifiers gets a trailing `_` here (`uv0_`). No function, struct or constant of
/// the library's interface ends in a digit, so what your shader imports keeps its name.
#[must_use]
pub fn library_module_source() -> String {
    format!("#define_import_path {LIBRARY_IMPORT_PATH}\n\n{}", naga_oil_safe(pomkit_gpu::library::WGSL))
}

/// WGSL built-in names that end in a digit (types and functions), left as they are.
fn is_builtin(ident: &str) -> bool {
    let vec_or_mat = |p: &str| {
        ident.strip_prefix(p).is_some_and(|rest| {
            let b = rest.as_bytes();
            matches!(b, [b'2'..=b'4'] | [b'2'..=b'4', b'x', b'2'..=b'4'])
        })
    };
    matches!(ident, "f16" | "f32" | "i32" | "u32" | "atan2" | "log2" | "exp2")
        || vec_or_mat("vec")
        || vec_or_mat("mat")
        || (ident.starts_with("texture")
            && (ident.ends_with("_1d") || ident.ends_with("_2d") || ident.ends_with("_3d")))
}

/// `source` with `_` appended to every identifier that ends in a digit, built-ins aside.
fn naga_oil_safe(source: &str) -> String {
    let mut out = String::with_capacity(source.len() + 256);
    let mut chars = source.char_indices().peekable();
    while let Some((start, c)) = chars.next() {
        if c.is_ascii_alphabetic() || c == '_' {
            let mut end = start + c.len_utf8();
            while let Some(&(i, d)) = chars.peek() {
                if d.is_ascii_alphanumeric() || d == '_' {
                    end = i + d.len_utf8();
                    chars.next();
                } else {
                    break;
                }
            }
            let ident = &source[start..end];
            out.push_str(ident);
            if ident.ends_with(|d: char| d.is_ascii_digit()) && !is_builtin(ident) {
                out.push('_');
            }
        } else if c.is_ascii_digit() {
            // A number literal, suffixes and exponents included (`1e30`, `0x1Fu`, `2.5f`).
            out.push(c);
            while let Some(&(_, d)) = chars.peek() {
                if d.is_ascii_alphanumeric() || d == '_' || d == '.' {
                    out.push(d);
                    chars.next();
                } else {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// Adds [`PomkitMaterial`], the shader library module, and the systems that build height
/// resources from the materials' height maps.
#[derive(Default)]
pub struct PomkitPlugin;

impl Plugin for PomkitPlugin {
    fn build(&self, app: &mut App) {
        let mut shaders = app.world_mut().resource_mut::<Assets<Shader>>();
        let library = Shader::from_wgsl(library_module_source(), "bevy_pomkit/pomkit_library.wgsl");
        let material =
            Shader::from_wgsl(include_str!("../shaders/pomkit_material.wgsl"), "bevy_pomkit/pomkit_material.wgsl");
        let vertex = Shader::from_wgsl(
            include_str!("../shaders/pomkit_silhouette_vertex.wgsl"),
            "bevy_pomkit/pomkit_silhouette_vertex.wgsl",
        );
        for (id, shader) in
            [(LIBRARY_SHADER.id(), library), (MATERIAL_SHADER.id(), material), (SILHOUETTE_VERTEX_SHADER.id(), vertex)]
        {
            if let Err(e) = shaders.insert(id, shader) {
                error!("bevy_pomkit: could not register a shader: {e}");
            }
        }
        let maps = HeightMaps::default();
        #[cfg(feature = "gltf")]
        gltf::register(app, maps.gltf_reports.clone());
        app.add_plugins((
            MaterialPlugin::<PomkitMaterial>::default(),
            bevy::render::extract_resource::ExtractResourcePlugin::<gpu_height::GpuHeightJobs>::default(),
        ))
        .init_resource::<gpu_height::GpuHeightJobs>()
        .insert_resource(maps.gpu_reports.clone())
        .insert_resource(maps)
        .add_systems(PostUpdate, (build_height_maps, check_meshes, silhouette::prepare_curvature));
    }

    fn finish(&self, app: &mut App) {
        // Conservative depth for pixel depth offset, where the device takes it.
        if let Some(render_app) = app.get_sub_app(bevy::render::RenderApp)
            && let Some(device) = render_app.world().get_resource::<bevy::render::renderer::RenderDevice>()
        {
            let supported =
                device.features().contains(bevy::render::render_resource::WgpuFeatures::SHADER_EARLY_DEPTH_TEST);
            material::CONSERVATIVE_DEPTH.store(supported, std::sync::atomic::Ordering::Relaxed);
        }
        // The GPU height builds: in the render graph, before the cameras draw.
        let reports = app.world().get_resource::<gpu_height::GpuReports>().cloned();
        if let Some(render_app) = app.get_sub_app_mut(bevy::render::RenderApp)
            && let Some(reports) = reports
        {
            use bevy::render::renderer::{RenderGraph, RenderGraphSystems};
            gpu_height::detect(render_app.world());
            render_app
                .insert_resource(reports)
                .init_resource::<gpu_height::GpuHeightState>()
                .configure_sets(
                    RenderGraph,
                    GpuHeightPass
                        .in_set(RenderGraphSystems::Render)
                        .before(bevy::core_pipeline::schedule::camera_driver),
                )
                .add_systems(RenderGraph, gpu_height::build_gpu_heights.in_set(GpuHeightPass));
        }
    }
}

/// What was built for one material, so that a rebuild happens only when an input changed.
#[derive(Clone, PartialEq, Eq, Hash)]
struct Built {
    source: AssetId<Image>,
    kind: MapKind,
    channel: Channel,
    edges: EdgeMode,
    depth_scale_bits: u32,
    /// Whether the pyramid carries cone ratios (materials drawn with `cone`).
    cones: bool,
    /// Whether the heights carry parallax values (materials drawn with `iterative`).
    parallax: bool,
    /// Where the textures are built (after the fall-back to the CPU).
    build: HeightBuild,
}

/// Height resources of the materials in use: what each was built from, and which inputs were
/// reported bad (each reported once).
#[derive(Resource, Default)]
pub struct HeightMaps {
    built: HashMap<AssetId<PomkitMaterial>, Built>,
    /// The materials whose height map was refused (reported, drawn plain) at their `built` inputs.
    refused: HashSet<AssetId<PomkitMaterial>>,
    cache: HashMap<Built, Textures>,
    reported: HashSet<String>,
    derived: HashSet<AssetId<Image>>,
    /// What the glTF hook reported while loading files.
    #[cfg(feature = "gltf")]
    gltf_reports: gltf::SharedReports,
    /// The builds done on the GPU, by what they build.
    gpu: HashMap<Built, gpu_height::GpuJob>,
    /// What the render world found wrong with a GPU build's source.
    gpu_reports: gpu_height::GpuReports,
    /// The size each source built every frame was first built at: another size is refused.
    gpu_sizes: HashMap<AssetId<Image>, (u32, u32)>,
}

/// The textures of one height map at one set of settings.
#[derive(Clone)]
struct Textures {
    heights: Handle<Image>,
    pyramid: Handle<Image>,
    normals: Handle<Image>,
}

impl HeightMaps {
    /// Whether `id` is a texture this plugin built (heights, pyramid or normals).
    #[must_use]
    pub fn is_derived(&self, id: AssetId<Image>) -> bool {
        self.derived.contains(&id)
    }

    /// Whether the plugin has dealt with material `id`'s height map: built its textures, or
    /// reported why it cannot (then the material draws as the plain standard material).
    #[must_use]
    pub fn settled(&self, id: AssetId<PomkitMaterial>) -> bool {
        self.built.contains_key(&id)
    }

    /// Every bad input reported so far (each message also went to Bevy's log once), those of
    /// glTF files' materials included.
    #[must_use]
    pub fn reports(&self) -> Vec<String> {
        let mut r: Vec<String> = self.reported.iter().cloned().collect();
        #[cfg(feature = "gltf")]
        r.extend(self.gltf_reports.all());
        r.sort();
        r
    }

    /// Puts `built` into the images of `cached` (a source that changed), or into new images.
    fn store(
        &mut self,
        images: &mut Assets<Image>,
        key: &Built,
        cached: Option<Textures>,
        built: height::HeightImages,
    ) -> Textures {
        match cached {
            Some(t) => {
                for (handle, image) in
                    [(&t.heights, built.heights), (&t.pyramid, built.pyramid), (&t.normals, built.normals)]
                {
                    if let Err(e) = images.insert(handle.id(), image) {
                        error!("bevy_pomkit: could not update a height texture: {e}");
                    }
                }
                t
            }
            None => {
                let t = Textures {
                    heights: images.add(built.heights),
                    pyramid: images.add(built.pyramid),
                    normals: images.add(built.normals),
                };
                for h in [&t.heights, &t.pyramid, &t.normals] {
                    self.derived.insert(h.id());
                }
                self.cache.insert(key.clone(), t.clone());
                t
            }
        }
    }

    /// The GPU build of `key`: checks the source, makes (or reuses) the render-world images it
    /// writes and hands the render world its job, to run again now.
    fn prepare_gpu(
        &mut self,
        images: &mut Assets<Image>,
        key: &Built,
        cached: Option<Textures>,
        whose: &str,
        name: &str,
    ) -> Result<Textures, String> {
        let plain =
            |e: String| format!("bevy_pomkit: {whose}height map {name}: {e}: drawing the plain StandardMaterial");
        let Some(source) = images.get(key.source) else {
            return Err(plain("it is not loaded".into()));
        };
        let info = gpu_height::check_source(source, key.channel).map_err(plain)?;
        if let Some(formats) = info.needs_view_format {
            // Read through a linear view: the texture must list that format, so it is made
            // again (once) from the texels still in the main world.
            if source.data.is_none() {
                return Err(plain(format!(
                    "its format {:?} is sRGB-encoded and its texels are already on the GPU (give it a linear format, or RenderAssetUsages::MAIN_WORLD)",
                    source.texture_descriptor.format
                )));
            }
            if let Some(mut image) = images.get_mut(key.source) {
                image.texture_descriptor.view_formats = formats;
            }
        }
        // Until it is built again (a refused source is not built at all).
        let previous = self.gpu.remove(key);
        let every_frame = key.build == HeightBuild::GpuEveryFrame;
        if every_frame {
            // A texture written every frame keeps its size: a new one means a source the
            // textures (and the user's own passes) were not made for.
            let first = *self.gpu_sizes.entry(key.source).or_insert(info.size);
            if first != info.size {
                return Err(plain(format!(
                    "its size changed from {}x{} to {}x{} texels",
                    first.0, first.1, info.size.0, info.size.1
                )));
            }
        }
        let reuse = match (&cached, &previous) {
            (Some(t), Some(job)) if job.size == info.size => Some(t.clone()),
            _ => None,
        };
        let textures = match reuse {
            Some(t) => t,
            None => {
                let built = gpu_height::derived_images(info.size.0, info.size.1, key.edges);
                let handles = cached.as_ref().map(|t| [&t.heights, &t.pyramid, &t.normals]);
                let [heights, pyramid, normals] = gpu_height::store_images(images, handles, built);
                let t = Textures { heights, pyramid, normals };
                for h in [&t.heights, &t.pyramid, &t.normals] {
                    self.derived.insert(h.id());
                }
                self.cache.insert(key.clone(), t.clone());
                t
            }
        };
        let generation = previous.map_or(1, |j| j.generation + 1);
        self.gpu.insert(
            key.clone(),
            gpu_height::GpuJob {
                source: key.source,
                heights: textures.heights.id(),
                pyramid: textures.pyramid.id(),
                normals: textures.normals.id(),
                size: info.size,
                channel: info.channel,
                encoding: gpu_height::encoding(key.kind),
                view_format: info.view_format,
                edges: key.edges,
                depth_scale: want_depth_scale(f32::from_bits(key.depth_scale_bits)),
                cones: key.cones,
                every_frame,
                generation,
                name: format!("{whose}height map {name}"),
            },
        );
        Ok(textures)
    }

    fn report(&mut self, message: String) {
        if self.reported.insert(message.clone()) {
            error!("{message}");
        }
    }
}

fn image_name(server: Option<&AssetServer>, id: AssetId<Image>) -> String {
    server.and_then(|s| s.get_path(id)).map_or_else(|| format!("image {id}"), |p| format!("\"{p}\""))
}

/// Builds (or rebuilds) the height resources of every material whose height map, map kind,
/// channel, edge mode or depth scale changed, and reports bad inputs in the log.
/// Point and spot lights (whose self-shadows a material's shader carries only where some exist).
type PointOrSpot = Or<(With<PointLight>, With<SpotLight>)>;

fn build_height_maps(
    point_lights: Query<(), PointOrSpot>,
    mut materials: ResMut<Assets<PomkitMaterial>>,
    mut images: ResMut<Assets<Image>>,
    mut image_events: MessageReader<AssetEvent<Image>>,
    mut maps: ResMut<HeightMaps>,
    mut gpu_jobs: ResMut<gpu_height::GpuHeightJobs>,
    server: Option<Res<AssetServer>>,
) {
    let server = server.as_deref();
    let jobs_before = maps.gpu.len();
    let mut jobs_changed = false;
    // GPU builds whose source the render world could not read: reported, drawn plain.
    for (heights, message) in maps.gpu_reports.take() {
        maps.report(message);
        let failed: Vec<Built> =
            maps.gpu.iter().filter(|(_, j)| j.heights == heights).map(|(k, _)| k.clone()).collect();
        for key in failed {
            maps.gpu.remove(&key);
            maps.cache.remove(&key);
            jobs_changed = true;
            let users: Vec<_> = maps.built.iter().filter(|(_, b)| **b == key).map(|(id, _)| *id).collect();
            for id in users {
                if let Some(mut m) = materials.get_mut(id) {
                    m.extension.heights = None;
                    m.extension.pyramid = None;
                    m.extension.normal_texture = None;
                }
            }
        }
    }
    let mut changed: HashSet<AssetId<Image>> = HashSet::default();
    for event in image_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::LoadedWithDependencies { id } | AssetEvent::Added { id } =
            event
            && !maps.is_derived(*id)
        {
            changed.insert(*id);
        }
    }
    let mut work = Vec::new();
    for (id, m) in materials.iter() {
        let e = &m.extension;
        let want = Built {
            source: e.height_map.id(),
            kind: e.map_kind,
            channel: e.channel,
            edges: e.edges,
            depth_scale_bits: e.depth_scale.to_bits(),
            cones: e.technique == Technique::Cone,
            parallax: e.technique == Technique::Iterative,
            build: gpu_height::effective(e.height_build),
        };
        // A material whose textures are gone while the plugin thinks them built was replaced
        // by a copy without them (`Assets::insert` of the same id, an asset reloaded): built
        // again. One the plugin refused stays plain until an input changes.
        let lost = !e.is_ready() && !maps.refused.contains(&id);
        let stale = maps.built.get(&id) != Some(&want) || changed.contains(&want.source) || lost;
        if stale {
            let whose = e.name.as_ref().map(|n| format!("{n}: ")).unwrap_or_default();
            work.push((id, want, whose));
        }
    }
    // Materials with the same height map and settings share one set of textures; a changed
    // source is rebuilt once, in place, for all of them.
    let mut done: HashMap<Built, Result<Textures, String>> = HashMap::default();
    for (id, want, whose) in work {
        let name = image_name(server, want.source);
        let result = if let Some(r) = done.get(&want) {
            r.clone()
        } else {
            let cached = maps.cache.get(&want).cloned();
            let r = match cached {
                Some(t) if !changed.contains(&want.source) => Ok(t),
                cached if want.build != HeightBuild::Cpu && images.contains(want.source) => {
                    jobs_changed = true;
                    maps.prepare_gpu(&mut images, &want, cached, &whose, &name)
                }
                cached => {
                    let Some(source) = images.get(want.source) else {
                        if let Some(s) = server
                            && let Some(bevy::asset::LoadState::Failed(err)) = s.get_load_state(want.source)
                        {
                            maps.report(format!(
                                "bevy_pomkit: {whose}height map {name} failed to load ({}): drawing the plain StandardMaterial",
                                err.to_string().trim_end()
                            ));
                            maps.built.insert(id, want);
                            maps.refused.insert(id);
                        }
                        continue;
                    };
                    let depth_scale = want_depth_scale(f32::from_bits(want.depth_scale_bits));
                    match height::depths_from_image(source, want.kind, want.channel) {
                        Ok(field) => {
                            // Cones cost a search per texel (about 1.5 s for 512x512 on two
                            // cores): only for materials that step on them.
                            let cones =
                                want.cones.then(|| pomkit_core::cone::ConeMap::conservative(&field, want.edges));
                            let built = height::height_images_with(
                                &field,
                                want.edges,
                                depth_scale,
                                cones.as_ref(),
                                want.parallax,
                            );
                            Ok(maps.store(&mut images, &want, cached, built))
                        }
                        Err(e) => Err(format!(
                            "bevy_pomkit: {whose}height map {name}: {e}: drawing the plain StandardMaterial"
                        )),
                    }
                }
            };
            done.insert(want.clone(), r.clone());
            r
        };
        let Some(mut material) = materials.get_mut(id) else { continue };
        let ext = &mut material.extension;
        match result {
            Ok(t) => {
                ext.heights = Some(t.heights);
                ext.pyramid = Some(t.pyramid);
                ext.normal_texture = Some(t.normals);
                maps.refused.remove(&id);
            }
            Err(message) => {
                maps.refused.insert(id);
                maps.report(message);
                ext.heights = None;
                ext.pyramid = None;
                ext.normal_texture = None;
            }
        }
        maps.built.insert(id, want);
    }
    // The pipeline key follows the base material's textures, and whether the world has point
    // or spot lights.
    let any_point_lights = !point_lights.is_empty();
    let stale: Vec<_> = materials
        .iter()
        .filter(|(_, m)| {
            m.extension.base_textures != material::base_textures(&m.base)
                || m.extension.point_lights != any_point_lights
        })
        .map(|(id, _)| id)
        .collect();
    for id in stale {
        if let Some(mut m) = materials.get_mut(id) {
            m.extension.base_textures = material::base_textures(&m.base);
            m.extension.point_lights = any_point_lights;
        }
    }
    // Forget removed materials, and textures no material uses any more.
    maps.built.retain(|id, _| materials.contains(*id));
    maps.refused.retain(|id| materials.contains(*id));
    let used: HashSet<Built> = maps.built.values().cloned().collect();
    maps.cache.retain(|k, _| used.contains(k));
    maps.gpu.retain(|k, _| used.contains(k));
    let sources: HashSet<AssetId<Image>> = used.iter().map(|k| k.source).collect();
    maps.gpu_sizes.retain(|id, _| sources.contains(id));
    if jobs_changed || maps.gpu.len() != jobs_before {
        gpu_jobs.0 = maps.gpu.values().cloned().collect();
    }
    // Parameters the tracers refuse (a depth scale that is not finite and positive, ...).
    for (id, m) in materials.iter() {
        if let Err(e) = m.extension.params() {
            let whose = m.extension.name.clone().unwrap_or_else(|| format!("material {id}"));
            maps.report(format!("bevy_pomkit: {whose}: {e}: drawing the plain StandardMaterial"));
        }
        if let Some(c) = m.extension.far_color
            && !material::finite_color(c)
        {
            let whose = m.extension.name.clone().unwrap_or_else(|| format!("material {id}"));
            maps.report(format!(
                "bevy_pomkit: {whose}: far_color {:?} (linear RGBA) is not a finite colour: fading to the entry point's texture",
                c.to_linear().to_f32_array()
            ));
        }
    }
}

/// The depth scale the maps are built with: a bad one is reported by `params` and the material
/// drawn plain, so the tracers' own stand-in will do here.
fn want_depth_scale(s: f32) -> f32 {
    pomkit_core::trace::sanitized_depth_scale(s)
}

/// Reports meshes drawn with a pomkit material that lack what tracing needs (UVs, normals and
/// tangents); the shader draws them as the plain standard material.
/// The filter of the meshes `check_meshes` looks at: drawn with a pomkit material whose mesh
/// or material was just set.
type NewlyDrawn = (With<MeshMaterial3d<PomkitMaterial>>, Or<(Changed<Mesh3d>, Added<MeshMaterial3d<PomkitMaterial>>)>);

pub(crate) fn check_meshes(
    query: Query<(Entity, &Mesh3d), NewlyDrawn>,
    meshes: Res<Assets<Mesh>>,
    server: Option<Res<AssetServer>>,
    mut maps: ResMut<HeightMaps>,
) {
    for (entity, mesh3d) in &query {
        let Some(mesh) = meshes.get(&mesh3d.0) else { continue };
        let missing: Vec<&str> = [
            (Mesh::ATTRIBUTE_UV_0, "UV_0"),
            (Mesh::ATTRIBUTE_NORMAL, "NORMAL"),
            (Mesh::ATTRIBUTE_TANGENT, "TANGENT (call Mesh::generate_tangents or export tangents)"),
        ]
        .into_iter()
        // A mesh whose vertex data lives in the render world only (RenderAssetUsages::RENDER_WORLD)
        // cannot be looked at here: the shader still draws it plain if an attribute is missing.
        .filter(|(a, _)| matches!(mesh.try_contains_attribute(a.id), Ok(false)))
        .map(|(_, n)| n)
        .collect();
        if !missing.is_empty() {
            let name = server
                .as_deref()
                .and_then(|s| s.get_path(mesh3d.0.id()))
                .map_or_else(|| format!("{} of entity {entity}", mesh3d.0.id()), |p| format!("\"{p}\""));
            let message = format!(
                "bevy_pomkit: mesh {name} has no {} attribute: drawing the plain StandardMaterial",
                missing.join(", no ")
            );
            if maps.reported.insert(message.clone()) {
                warn!("{message}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn library_identifiers_ending_in_digits_get_an_underscore() {
        let src = "fn f(uv0: vec2<f32>, t1: f32) -> mat4x4<f32> { let x = atan2(t1, 1e30) + log2(2.5) + 0x1Fu; let t: texture_2d<f32>; return pad0; }";
        let want = "fn f(uv0_: vec2<f32>, t1_: f32) -> mat4x4<f32> { let x = atan2(t1_, 1e30) + log2(2.5) + 0x1Fu; let t: texture_2d<f32>; return pad0_; }";
        assert_eq!(naga_oil_safe(src), want);
        // The library's interface keeps its names.
        let module = library_module_source();
        for name in ["fn pomkit_trace(", "struct PomkitParams", "fn pomkit_shadow(", "const POMKIT_EXACT:"] {
            assert!(module.contains(name), "{name} renamed");
        }
        assert!(!module.contains(" uv0:") && module.contains(" uv0_:"));
    }
}
