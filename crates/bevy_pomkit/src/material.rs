//! The material extension: settings, the uniform the shader reads, and pipeline
//! specialization (pixel depth offset, and a fragment stage in depth-only passes).

use bevy::asset::Handle;
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
use pomkit_core::shadow::ShadowParams;
use pomkit_core::trace::{Technique, TraceParams};
use pomkit_gpu::library::{ParamError, PomkitParams};

use crate::MATERIAL_SHADER;
use crate::height::{Channel, MapKind};

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
    /// (visibility of the first directional light, LOD weight, 0, 1).
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
    /// Self-shadowing from directional lights (default none).
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
    /// would. Turns off early depth testing for these meshes. Default on.
    pub pixel_depth_offset: bool,
    /// Also trace in directional lights' shadow maps, so their cascades hold the traced depth
    /// (needs `pixel_depth_offset`). Default off: every cascade texel the mesh covers then runs
    /// the tracer instead of Bevy's depth-only shadow pass, which made the demo frame 3.4x
    /// (pom) to 6.9x (exact) slower on lavapipe (docs/BENCHMARKS.md, Bevy).
    pub shadow_pixel_depth: bool,
    /// Shade with the height map's normals (default on). Off keeps the standard material's
    /// own normal map, or the vertex normal.
    pub normals: bool,
    /// Debug output instead of the shaded colour.
    pub debug: PomkitDebug,
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
}

impl Pomkit {
    /// `pom` with pomkit's defaults on `height_map` (white high).
    #[must_use]
    pub fn new(height_map: Handle<Image>) -> Self {
        let defaults = pomkit_core::scene::Material::default();
        Self {
            height_map,
            map_kind: MapKind::Height,
            channel: Channel::Luma,
            technique: Technique::Pom,
            shadow: ShadowParams::default(),
            depth_scale: defaults.depth_scale,
            edges: defaults.edges,
            trace: TraceParams::default(),
            lod_threshold: defaults.lod_threshold,
            pixel_depth_offset: true,
            shadow_pixel_depth: false,
            normals: true,
            debug: PomkitDebug::Off,
            heights: None,
            pyramid: None,
            normal_texture: None,
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

    /// The same with another depth scale.
    #[must_use]
    pub fn with_depth_scale(mut self, depth_scale: f32) -> Self {
        self.depth_scale = depth_scale;
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

    /// Whether the plugin has built this material's height textures.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.heights.is_some() && self.pyramid.is_some() && self.normal_texture.is_some()
    }
}

/// Flags of [`PomkitUniform::flags`].
const FLAG_READY: u32 = 1;
const FLAG_NORMALS: u32 = 2;
const FLAG_PIXEL_DEPTH: u32 = 4;

/// The uniform at binding 100 of the material: the library's `PomkitParams` (64 bytes, written
/// by pomkit's own serializer) and the extension's flags.
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct PomkitUniform {
    /// `PomkitParams` as 16 words.
    pub params: [UVec4; 4],
    /// Bit 0: textures built and parameters valid (else the plain standard material); bit 1:
    /// shade with the height map's normals; bit 2: pixel depth offset.
    pub flags: u32,
    /// [`PomkitDebug`] as an index.
    pub debug: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
}

impl AsBindGroupShaderType<PomkitUniform> for Pomkit {
    fn as_bind_group_shader_type(&self, images: &RenderAssets<GpuImage>) -> PomkitUniform {
        let mut out = PomkitUniform { debug: self.debug.index(), ..Default::default() };
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
        if self.normals {
            out.flags |= FLAG_NORMALS;
        }
        if self.pixel_depth_offset {
            out.flags |= FLAG_PIXEL_DEPTH;
        }
        out
    }
}

/// The pipeline key: where the fragment stage writes the traced depth.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PomkitKey {
    /// Pixel depth offset on.
    pub pixel_depth_offset: bool,
    /// And in directional lights' shadow maps.
    pub shadow_pixel_depth: bool,
}

impl From<&Pomkit> for PomkitKey {
    fn from(m: &Pomkit) -> Self {
        Self { pixel_depth_offset: m.pixel_depth_offset, shadow_pixel_depth: m.shadow_pixel_depth }
    }
}

impl MaterialExtension for Pomkit {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Handle(MATERIAL_SHADER)
    }

    fn prepass_fragment_shader() -> ShaderRef {
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
        let prepass = descriptor.vertex.shader_defs.iter().any(|d| d == &ShaderDefVal::from("PREPASS_PIPELINE"));
        if pixel_depth {
            descriptor.vertex.shader_defs.push("POMKIT_PIXEL_DEPTH".into());
            if let Some(f) = descriptor.fragment.as_mut() {
                f.shader_defs.push("POMKIT_PIXEL_DEPTH".into());
            }
        }
        if !prepass || !pixel_depth {
            return Ok(());
        }
        // The prepass and shadow passes trace too, to write the traced depth: they need the
        // normals and tangents Bevy's prepass vertex stage passes on only for a normal prepass,
        // and a fragment stage even where no colour target is written.
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
            let wanted =
                used.contains(&location) || ((location == 3 || location == 4) && layout.0.contains(attribute.id));
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
}

fn shader_def_name(d: &ShaderDefVal) -> String {
    match d {
        ShaderDefVal::Bool(n, _) | ShaderDefVal::Int(n, _) | ShaderDefVal::UInt(n, _) => n.clone(),
    }
}
