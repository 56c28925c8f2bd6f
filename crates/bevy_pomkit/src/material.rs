//! The material extension: settings, the uniform the shader reads, and pipeline
//! specialization (pixel depth offset, and a fragment stage in depth-only passes).

use bevy::asset::{AssetId, Handle};
use bevy::image::Image;
use bevy::math::UVec4;
use bevy::mesh::{Mesh, MeshVertexBufferLayoutRef, VertexAttributeDescriptor};
use bevy::pbr::{MaterialExtension, MaterialExtensionKey, MaterialExtensionPipeline, MeshPipelineKey};
use bevy::prelude::*;
use bevy::render::render_asset::RenderAssets;
use bevy::render::render_resource::{
    AsBindGroup, AsBindGroupShaderType, FragmentState, RenderPipelineDescriptor, ShaderType,
    SpecializedMeshPipelineError,
};
use bevy::render::texture::GpuImage;
use bevy::shader::{ShaderDefVal, ShaderRef};
use pomkit_core::EdgeMode;
use pomkit_core::shadow::ShadowMode;
use pomkit_core::shadow::ShadowParams;
use pomkit_core::trace::{Technique, TraceParams};
use pomkit_gpu::library::{ParamError, PomkitParams, shadow_index, technique_index};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::height::{Channel, MapKind};
use crate::{ATTRIBUTE_CURVATURE, MATERIAL_SHADER, SILHOUETTE_VERTEX_SHADER};

/// What the material outputs instead of its shaded colour, for inspection and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PomkitDebug {
    /// The shaded colour.
    #[default]
    Off,
    /// (hit u, hit v, hit depth, 1), unlit: the traced UV in the material's UV space (after
    /// `uv_transform`).
    HitUv,
    /// (fetches / 64, LOD weight, height mip level / 16, 1).
    Fetches,
    /// (self-shadow visibility of the first directional light, or with none of the first point
    /// or spot light of the fragment's cluster, LOD weight, 0, 1).
    Shadow,
}

impl PomkitDebug {
    fn index(self) -> u32 {
        match self {
            Self::Off => 0,
            Self::HitUv => 1,
            Self::Fetches => 2,
            Self::Shadow => 3,
        }
    }
}

/// pomkit's tracing for a `StandardMaterial`: the `extension` of a
/// [`PomkitMaterial`](crate::PomkitMaterial).
///
/// The fields are the settings; the plugin builds the textures the shader reads from
/// `height_map` (and rebuilds them when the image, `map_kind`, `channel`, `edges` or
/// `depth_scale` change).
#[derive(Asset, AsBindGroup, TypePath, Debug, Clone)]
#[uniform(100, PomkitUniform)]
#[bind_group_data(PomkitKey)]
pub struct Pomkit {
    /// The height (or depth, see `map_kind`) map.
    pub height_map: Handle<Image>,
    /// Whether white is high (the default) or deep.
    pub map_kind: MapKind,
    /// The channel that holds the height (default luma).
    pub channel: Channel,
    /// The tracing technique (default `pom`).
    pub technique: Technique,
    /// Self-shadowing from directional, point and spot lights (default none).
    pub shadow: ShadowParams,
    /// How far below the surface, in UV units (tile widths), the deepest point lies: greater
    /// than 0 and at most 16. Default 0.1.
    pub depth_scale: f32,
    /// Texture addressing: wrap tiles the height map, clamp repeats its edge texels. Default
    /// wrap.
    pub edges: EdgeMode,
    /// Sample counts, refinement steps and perspective bias; docs/SCENES.md gives each
    /// parameter's meaning and range.
    pub trace: TraceParams,
    /// The full technique runs up to this mip level of the height map and fades out over the
    /// next (Tatarchuk 2006); `f32::MAX` never fades. Default 4.
    pub lod_threshold: f32,
    /// Write the depth of the traced point in the main pass and the depth prepass (and the
    /// shadow maps of point and spot lights, which Bevy 0.19's pipeline keys do not tell apart
    /// from the depth prepass), so the surface meets other geometry where displaced geometry
    /// would. Where the device allows it the written depth is declared conservative (never
    /// nearer than the polygon's), which keeps early depth testing. Default on.
    pub pixel_depth_offset: bool,
    /// Also trace in directional lights' shadow maps, so their cascades hold the traced depth
    /// (needs `pixel_depth_offset`). Default off: every cascade texel the mesh covers then runs
    /// the tracer instead of Bevy's depth-only shadow pass, which made the demo frame 3.4x
    /// (pom) to 6.9x (exact) slower on lavapipe (docs/BENCHMARKS.md, Bevy).
    pub shadow_pixel_depth: bool,
    /// Shade with the height map's normals (default on). Off keeps the standard material's
    /// own normal map, or the vertex normal.
    pub normals: bool,
    /// Sample the standard material's textures at the hit with the screen gradients of the
    /// entry UV, the pixel's footprint (default on). Off samples them with the hit UV's own
    /// derivatives, as Bevy's parallax mapping does: those jump where neighbouring pixels hit
    /// different features and pick a far too coarse mip, in thin streaks at the feet of steep
    /// features. Kept for comparison.
    pub entry_gradients: bool,
    /// The colour the surface shows from afar, for the LOD fade to fade to (needs a finite
    /// `lod_threshold`). `None` (the default) fades to the untraced surface: the base colour
    /// texture at the entry point, whose coarse mips average every depth of the relief
    /// together. For fur and grass (McGuire and McGuire 2005, docs/REFERENCES.md) that average
    /// takes in the dark roots and the skin or soil, which a distant furry ball does not show:
    /// one sees the strands' tips. With a colour (the strands' tips' mean albedo, say) the base
    /// colour texture's sample is replaced by it over the LOD band, in proportion to the fade,
    /// and beyond it entirely; it is still multiplied by `base_color` (and vertex colours), as
    /// the texture is. The depth self-shadow fades out with the technique either way. A
    /// pipeline specialisation: unset, the shader has none of it. A colour that is not finite
    /// is reported once in the log and ignored.
    pub far_color: Option<Color>,
    /// Debug output instead of the shaded colour.
    pub debug: PomkitDebug,
    /// Bumpy outlines on curved meshes (default off): the view ray is bent under the curved
    /// surface the mesh's normals describe, and pixels whose ray leaves the relief are
    /// discarded, in the main pass, the depth prepass, the deferred G-buffer and the shadow
    /// maps of point and spot lights (and of directional lights with `shadow_pixel_depth`).
    /// The plugin gives the meshes drawn with such a material the
    /// [`ATTRIBUTE_CURVATURE`](crate::ATTRIBUTE_CURVATURE) it needs. A pipeline
    /// specialisation: off, the material's pipelines are exactly those without it.
    pub silhouette: bool,
    /// Where the plugin builds the textures traced from `height_map`: on the CPU (the default),
    /// or by compute passes on the GPU when it changes or every frame
    /// ([`HeightBuild`](crate::HeightBuild), docs/EMBEDDING.md, Height maps built on the GPU).
    pub height_build: crate::HeightBuild,
    /// What the plugin's log messages call this material (the glTF hook sets `glTF "FILE",
    /// material "NAME"`). `None`: its asset path, or its id.
    pub name: Option<String>,
    /// Depth (R) and parallax value (G), all mips; built by the plugin.
    #[texture(101)]
    #[sampler(102)]
    pub(crate) heights: Option<Handle<Image>>,
    /// The maximum-height pyramid; built by the plugin.
    #[texture(103, sample_type = "float", filterable = false)]
    pub(crate) pyramid: Option<Handle<Image>>,
    /// Tangent-space normals; built by the plugin.
    #[texture(104)]
    pub(crate) normal_texture: Option<Handle<Image>>,
    /// Which of the base material's textures exist (`texture_bits`); kept up to date by the
    /// plugin, for the pipeline key.
    pub(crate) base_textures: u8,
    /// Whether the world has point or spot lights; kept up to date by the plugin, for the
    /// pipeline key.
    pub(crate) point_lights: bool,
}

impl Pomkit {
    /// `exact` (the default technique) with pomkit's defaults on `height_map` (white high).
    #[must_use]
    pub fn new(height_map: Handle<Image>) -> Self {
        let defaults = pomkit_core::scene::Material::default();
        Self {
            height_map,
            map_kind: MapKind::Height,
            channel: Channel::Luma,
            technique: Technique::Exact,
            shadow: ShadowParams::default(),
            depth_scale: defaults.depth_scale,
            edges: defaults.edges,
            trace: TraceParams::default(),
            lod_threshold: defaults.lod_threshold,
            pixel_depth_offset: true,
            shadow_pixel_depth: false,
            normals: true,
            entry_gradients: true,
            far_color: None,
            debug: PomkitDebug::Off,
            silhouette: false,
            height_build: crate::HeightBuild::Cpu,
            name: None,
            heights: None,
            pyramid: None,
            normal_texture: None,
            base_textures: 0,
            point_lights: false,
        }
    }

    /// The same with another technique.
    #[must_use]
    pub fn with_technique(mut self, technique: Technique) -> Self {
        self.technique = technique;
        self
    }

    /// The same with another self-shadow mode.
    #[must_use]
    pub fn with_shadow(mut self, mode: pomkit_core::shadow::ShadowMode) -> Self {
        self.shadow.mode = mode;
        self
    }

    /// The same with silhouettes on or off ([`Pomkit::silhouette`]).
    #[must_use]
    pub fn with_silhouette(mut self, silhouette: bool) -> Self {
        self.silhouette = silhouette;
        self
    }

    /// The same with another depth scale.
    #[must_use]
    pub fn with_depth_scale(mut self, depth_scale: f32) -> Self {
        self.depth_scale = depth_scale;
        self
    }

    /// The same with the height textures built as `build` says (on the GPU: a source that
    /// changes often, or one a compute shader writes every frame).
    #[must_use]
    pub fn with_height_build(mut self, build: crate::HeightBuild) -> Self {
        self.height_build = build;
        self
    }

    /// The same with the LOD fade fading to `color`, the colour the surface shows from afar
    /// (see [`Pomkit::far_color`]).
    #[must_use]
    pub fn with_far_color(mut self, color: impl Into<Color>) -> Self {
        self.far_color = Some(color.into());
        self
    }

    /// The checked parameter block the shader library reads.
    ///
    /// # Errors
    /// [`ParamError`] naming a parameter the tracers refuse (a depth scale that is not finite
    /// and positive, a sample count out of range, ...).
    pub fn params(&self) -> Result<PomkitParams, ParamError> {
        PomkitParams::new(self.technique, self.shadow, self.trace, self.depth_scale, self.edges, self.lod_threshold)
    }

    /// The heights, pyramid and normals textures the plugin made for this material (built on the
    /// CPU, or written on the GPU by [`HeightBuild`](crate::HeightBuild)'s passes), for
    /// inspection; `None` until made, or for a material drawn plain.
    #[must_use]
    pub fn height_textures(&self) -> Option<[AssetId<Image>; 3]> {
        Some([self.heights.as_ref()?.id(), self.pyramid.as_ref()?.id(), self.normal_texture.as_ref()?.id()])
    }

    /// Whether the plugin has built this material's height textures.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.heights.is_some() && self.pyramid.is_some() && self.normal_texture.is_some()
    }
}

/// Flags of [`PomkitUniform::flags`].
const FLAG_READY: u32 = 1;

/// The uniform at binding 100 of the material: the library's `PomkitParams` (64 bytes, written
/// by pomkit's own serializer) and the extension's flags. Everything else the shader needs to
/// know is a pipeline specialisation ([`PomkitKey`]).
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct PomkitUniform {
    /// `PomkitParams` as 16 words.
    pub params: [UVec4; 4],
    /// Bit 0: textures built and parameters valid (else the plain standard material).
    pub flags: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
    /// Padding.
    pub pad2: u32,
    /// [`Pomkit::far_color`], linear RGBA (read only where the pipeline has `POMKIT_FAR_COLOR`).
    pub far_color: Vec4,
}

impl AsBindGroupShaderType<PomkitUniform> for Pomkit {
    fn as_bind_group_shader_type(&self, images: &RenderAssets<GpuImage>) -> PomkitUniform {
        let mut out = PomkitUniform::default();
        let present = |h: &Option<Handle<Image>>| h.as_ref().is_some_and(|h| images.get(h).is_some());
        let params = self.params();
        let bytes = match &params {
            Ok(p) => p.to_bytes(),
            // Drawn plain: the shader reads no parameter.
            Err(_) => vec![0; PomkitParams::SIZE as usize],
        };
        for (k, word) in bytes.chunks_exact(4).enumerate().take(16) {
            out.params[k / 4][k % 4] = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
        }
        if params.is_ok() && present(&self.heights) && present(&self.pyramid) && present(&self.normal_texture) {
            out.flags |= FLAG_READY;
        }
        if let Some(c) = self.far_color.filter(|c| finite_color(*c)) {
            out.far_color = c.to_linear().to_vec4();
        }
        out
    }
}

/// Which of the standard material's textures a material has (bits of [`PomkitKey::textures`]).
pub(crate) mod texture_bits {
    /// `base_color_texture`.
    pub const BASE_COLOR: u8 = 1;
    /// `emissive_texture`.
    pub const EMISSIVE: u8 = 2;
    /// `metallic_roughness_texture`.
    pub const METALLIC_ROUGHNESS: u8 = 4;
    /// `occlusion_texture`.
    pub const OCCLUSION: u8 = 8;
}

/// The bits of [`texture_bits`] for the textures `base` has.
pub(crate) fn base_textures(base: &bevy::pbr::StandardMaterial) -> u8 {
    use texture_bits as b;
    let mut bits = 0;
    for (present, bit) in [
        (base.base_color_texture.is_some(), b::BASE_COLOR),
        (base.emissive_texture.is_some(), b::EMISSIVE),
        (base.metallic_roughness_texture.is_some(), b::METALLIC_ROUGHNESS),
        (base.occlusion_texture.is_some(), b::OCCLUSION),
    ] {
        if present {
            bits |= bit;
        }
    }
    bits
}

/// The pipeline key: every option the shader is specialised for, so that what a material does
/// not use is not in its shader (docs/BENCHMARKS.md, Bevy: a GPU that runs both sides of every
/// branch, as Mesa's lavapipe does, paid for all of it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PomkitKey {
    /// Pixel depth offset on.
    pub pixel_depth_offset: bool,
    /// And in directional lights' shadow maps.
    pub shadow_pixel_depth: bool,
    /// The technique, as the library's `POMKIT_*` constant.
    pub technique: u8,
    /// The self-shadow mode, as the library's `POMKIT_SHADOW_*` constant.
    pub shadow: u8,
    /// Shade with the height map's normals.
    pub normals: bool,
    /// The LOD fade has a band to fade over (`lod_threshold` is finite).
    pub lod_fade: bool,
    /// [`PomkitDebug`] as an index.
    pub debug: u8,
    /// The standard material's textures that exist (the plugin copies them from the base
    /// material).
    pub textures: u8,
    /// The world has point or spot lights (the plugin keeps this up to date): self-shadows from
    /// them are in the shader only then.
    pub point_lights: bool,
    /// [`Pomkit::entry_gradients`].
    pub entry_gradients: bool,
    /// [`Pomkit::silhouette`].
    pub silhouette: bool,
    /// [`Pomkit::far_color`] is set and the LOD fade has a band.
    pub far_color: bool,
}

impl From<&Pomkit> for PomkitKey {
    fn from(m: &Pomkit) -> Self {
        // A material whose parameters are refused draws plain: trace nothing.
        let (technique, shadow) =
            if m.params().is_ok() { (m.technique, m.shadow.mode) } else { (Technique::Flat, ShadowMode::None) };
        let lod_fade = m.lod_threshold.is_finite() && m.lod_threshold < MAX_LOD_THRESHOLD;
        Self {
            pixel_depth_offset: m.pixel_depth_offset,
            shadow_pixel_depth: m.shadow_pixel_depth,
            technique: technique_index(technique) as u8,
            shadow: shadow_index(shadow) as u8,
            normals: m.normals,
            lod_fade,
            debug: m.debug.index() as u8,
            textures: m.base_textures,
            point_lights: m.point_lights,
            entry_gradients: m.entry_gradients,
            silhouette: m.silhouette,
            far_color: lod_fade && m.far_color.is_some_and(finite_color),
        }
    }
}

/// Whether every component of `c` (linear RGBA) is finite: a far colour that is not is
/// reported and ignored.
pub(crate) fn finite_color(c: Color) -> bool {
    c.to_linear().to_f32_array().iter().all(|v| v.is_finite())
}

/// A LOD threshold at or above this mip level never fades (no height map has that many levels).
const MAX_LOD_THRESHOLD: f32 = 64.0;

/// Whether the render device takes `@early_depth_test` (wgpu's `SHADER_EARLY_DEPTH_TEST`), set by
/// the plugin when the renderer starts. With it, the pixel depth offset passes declare their
/// written depth conservative (never nearer than the polygon's), so a GPU keeps rejecting
/// hidden fragments before they are traced.
pub(crate) static CONSERVATIVE_DEPTH: AtomicBool = AtomicBool::new(false);

impl PomkitKey {
    /// The shader definitions of this key, for a pipeline whose fragment stage already has
    /// `existing` (Bevy's own, for the standard material and the view).
    fn shader_defs(&self, existing: &[ShaderDefVal], pixel_depth: bool) -> Vec<ShaderDefVal> {
        let has = |name: &str| existing.iter().any(|d| shader_def_name(d) == name);
        let mut defs = vec![
            ShaderDefVal::UInt("POMKIT_TECHNIQUE".into(), u32::from(self.technique)),
            ShaderDefVal::UInt("POMKIT_SHADOW_MODE".into(), u32::from(self.shadow)),
            ShaderDefVal::UInt("POMKIT_DEBUG".into(), u32::from(self.debug)),
        ];
        let mut flag = |on: bool, name: &str| {
            if on {
                defs.push(name.into());
            }
        };
        flag(self.normals, "POMKIT_NORMALS");
        flag(self.lod_fade, "POMKIT_LOD_FADE");
        flag(self.lod_fade && self.far_color, "POMKIT_FAR_COLOR");
        flag(self.point_lights && self.shadow != 0, "POMKIT_POINT_LIGHTS");
        flag(!self.entry_gradients, "POMKIT_HIT_UV_DERIVATIVES");
        flag(pixel_depth, "POMKIT_PIXEL_DEPTH");
        flag(pixel_depth && CONSERVATIVE_DEPTH.load(Ordering::Relaxed), "POMKIT_CONSERVATIVE_DEPTH");
        flag(pixel_depth || has("UNCLIPPED_DEPTH_ORTHO_EMULATION"), "POMKIT_FRAG_DEPTH");
        use texture_bits as b;
        flag(self.textures & b::BASE_COLOR != 0, "POMKIT_TEX_BASE_COLOR");
        flag(self.textures & b::EMISSIVE != 0, "POMKIT_TEX_EMISSIVE");
        flag(self.textures & b::METALLIC_ROUGHNESS != 0, "POMKIT_TEX_METALLIC_ROUGHNESS");
        flag(self.textures & b::OCCLUSION != 0, "POMKIT_TEX_OCCLUSION");
        // What pomkit's own reading of the standard material leaves out: Bevy's reads it.
        let bevy_input = [
            "STANDARD_MATERIAL_CLEARCOAT",
            "STANDARD_MATERIAL_ANISOTROPY",
            "STANDARD_MATERIAL_DIFFUSE_OR_SPECULAR_TRANSMISSION",
            "PBR_SPECULAR_TEXTURES_SUPPORTED",
        ]
        .into_iter()
        .any(&has)
            || existing.iter().any(|d| {
                let n = shader_def_name(d);
                n.starts_with("STANDARD_MATERIAL_") && n.ends_with("_UV_B")
            });
        flag(bevy_input, "POMKIT_BEVY_INPUT");
        // Light that needs the shadow maps inside Bevy's lighting (transmitted light, contact
        // shadows) keeps them there.
        flag(has("STANDARD_MATERIAL_DIFFUSE_TRANSMISSION") || has("CONTACT_SHADOWS"), "POMKIT_BEVY_SHADOW_MAPS");
        defs
    }
}

impl MaterialExtension for Pomkit {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Handle(MATERIAL_SHADER)
    }

    fn prepass_fragment_shader() -> ShaderRef {
        ShaderRef::Handle(MATERIAL_SHADER)
    }

    fn deferred_fragment_shader() -> ShaderRef {
        ShaderRef::Handle(MATERIAL_SHADER)
    }

    fn specialize(
        _pipeline: &MaterialExtensionPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        layout: &MeshVertexBufferLayoutRef,
        key: MaterialExtensionKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        let k = key.bind_group_data;
        // Only directional lights' shadow passes set this key (their cascades are orthographic).
        let directional_shadow = key.mesh_key.contains(MeshPipelineKey::UNCLIPPED_DEPTH_ORTHO);
        let pixel_depth = k.pixel_depth_offset && (k.shadow_pixel_depth || !directional_shadow);
        let vertex_def = |name: &str| descriptor.vertex.shader_defs.iter().any(|d| d == &ShaderDefVal::from(name));
        let prepass = vertex_def("PREPASS_PIPELINE");
        // Silhouettes wherever the pass traces (directional shadow maps only with
        // `shadow_pixel_depth`), on meshes that carry the curvature and that the GPU does not
        // move (the silhouette vertex stage neither skins nor morphs).
        let silhouette = k.silhouette && (k.shadow_pixel_depth || !directional_shadow);
        let curved = silhouette
            && layout.0.contains(ATTRIBUTE_CURVATURE)
            && !vertex_def("SKINNED")
            && !vertex_def("MORPH_TARGETS");
        if prepass && (pixel_depth || curved) {
            // The prepass and shadow passes trace too, to write the traced depth or to discard
            // what the main pass discards: they need the normals and tangents Bevy's prepass
            // vertex stage passes on only for a normal prepass, and a fragment stage even where
            // no colour target is written.
            add_prepass_fragment(descriptor, layout)?;
        }
        if curved {
            add_curvature(descriptor, layout)?;
        }
        if let Some(f) = descriptor.fragment.as_mut() {
            let mut defs = k.shader_defs(&f.shader_defs, pixel_depth);
            if curved {
                defs.push("POMKIT_SILHOUETTE".into());
                // A depth-only pass's fragment stage needs an output.
                if prepass && !defs.iter().any(|d| shader_def_name(d) == "POMKIT_FRAG_DEPTH") {
                    defs.push("POMKIT_FRAG_DEPTH".into());
                }
            } else if silhouette {
                // No curvature (reported by the plugin): the plain standard material.
                defs.push("POMKIT_PLAIN".into());
            }
            f.shader_defs.extend(defs);
        }
        Ok(())
    }
}

/// The shader location of [`ATTRIBUTE_CURVATURE`] in the silhouette vertex stage (after Bevy's
/// own, 0 to 7, in both the forward and the prepass vertex layouts).
const CURVATURE_LOCATION: u32 = 8;

/// Makes a pipeline read [`ATTRIBUTE_CURVATURE`]: the attribute added to its vertex buffer, and
/// the silhouette vertex stage (Bevy's, plus the curvature passed on) in place of Bevy's.
fn add_curvature(
    descriptor: &mut RenderPipelineDescriptor,
    layout: &MeshVertexBufferLayoutRef,
) -> Result<(), SpecializedMeshPipelineError> {
    let curvature = layout.0.get_layout(&[ATTRIBUTE_CURVATURE.at_shader_location(CURVATURE_LOCATION)])?;
    match descriptor.vertex.buffers.first_mut() {
        Some(buffer) => buffer.attributes.extend(curvature.attributes),
        None => descriptor.vertex.buffers.push(curvature),
    }
    descriptor.vertex.shader = SILHOUETTE_VERTEX_SHADER;
    descriptor.vertex.entry_point = None;
    descriptor.vertex.shader_defs.push("POMKIT_SILHOUETTE".into());
    Ok(())
}

/// Makes a prepass or shadow pass pipeline trace: the vertex stage passes on normals and
/// tangents, and a fragment stage exists.
fn add_prepass_fragment(
    descriptor: &mut RenderPipelineDescriptor,
    layout: &MeshVertexBufferLayoutRef,
) -> Result<(), SpecializedMeshPipelineError> {
    let mut defs = descriptor.vertex.shader_defs.clone();
    let has = |defs: &[ShaderDefVal], name: &str| defs.iter().any(|d| d == &ShaderDefVal::from(name));
    let mut attributes: Vec<VertexAttributeDescriptor> = Vec::new();
    let by_location = [
        (0, Mesh::ATTRIBUTE_POSITION),
        (1, Mesh::ATTRIBUTE_UV_0),
        (2, Mesh::ATTRIBUTE_UV_1),
        (3, Mesh::ATTRIBUTE_NORMAL),
        (4, Mesh::ATTRIBUTE_TANGENT),
        (5, Mesh::ATTRIBUTE_JOINT_INDEX),
        (6, Mesh::ATTRIBUTE_JOINT_WEIGHT),
        (7, Mesh::ATTRIBUTE_COLOR),
    ];
    let used: Vec<u32> = descriptor
        .vertex
        .buffers
        .first()
        .map(|b| b.attributes.iter().map(|a| a.shader_location).collect())
        .unwrap_or_default();
    for (location, attribute) in by_location {
        let wanted = used.contains(&location) || ((location == 3 || location == 4) && layout.0.contains(attribute.id));
        if wanted {
            attributes.push(attribute.at_shader_location(location));
        }
    }
    if !has(&defs, "NORMAL_PREPASS_OR_DEFERRED_PREPASS") {
        defs.push("NORMAL_PREPASS_OR_DEFERRED_PREPASS".into());
        if layout.0.contains(Mesh::ATTRIBUTE_NORMAL) && !has(&defs, "VERTEX_NORMALS") {
            defs.push("VERTEX_NORMALS".into());
        }
        if layout.0.contains(Mesh::ATTRIBUTE_TANGENT) && !has(&defs, "VERTEX_TANGENTS") {
            defs.push("VERTEX_TANGENTS".into());
        }
    }
    let buffer = layout.0.get_layout(&attributes)?;
    descriptor.vertex.buffers = vec![buffer];
    descriptor.vertex.shader_defs.clone_from(&defs);
    match descriptor.fragment.as_mut() {
        Some(f) => {
            for d in defs {
                if !has(&f.shader_defs, &shader_def_name(&d)) {
                    f.shader_defs.push(d);
                }
            }
        }
        None => {
            descriptor.fragment = Some(FragmentState {
                shader: MATERIAL_SHADER,
                shader_defs: defs,
                entry_point: None,
                targets: Vec::new(),
            });
        }
    }
    Ok(())
}

fn shader_def_name(d: &ShaderDefVal) -> String {
    match d {
        ShaderDefVal::Bool(n, _) | ShaderDefVal::Int(n, _) | ShaderDefVal::UInt(n, _) => n.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn has_far_color(m: &Pomkit) -> bool {
        PomkitKey::from(m).shader_defs(&[], false).iter().any(|d| shader_def_name(d) == "POMKIT_FAR_COLOR")
    }

    #[test]
    fn the_far_colour_is_in_the_shader_only_where_set_and_the_lod_fade_has_a_band() {
        let plain = Pomkit::new(Handle::<Image>::default());
        assert!(!has_far_color(&plain));
        let far = plain.clone().with_far_color(Color::srgb(0.8, 0.6, 0.4));
        assert!(has_far_color(&far));
        let never_fades = Pomkit { lod_threshold: f32::MAX, ..far.clone() };
        assert!(!has_far_color(&never_fades));
        // A colour that is not finite is ignored (and reported by the plugin).
        assert!(!has_far_color(&plain.clone().with_far_color(Color::linear_rgb(f32::NAN, 0.5, 0.5))));
        // The uniform carries the colour in linear RGBA.
        let want = Color::srgb(0.8, 0.6, 0.4).to_linear();
        let uniform: PomkitUniform = far.as_bind_group_shader_type(&RenderAssets::<GpuImage>::default());
        let got = uniform.far_color;
        assert!((got - Vec4::new(want.red, want.green, want.blue, 1.0)).abs().max_element() < 1e-6);
    }
}
