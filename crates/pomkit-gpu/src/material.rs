//! A pomkit material on the GPU, and the pipelines that draw it.
//!
//! This is the part a wgpu program uses in its own render pass: [`MaterialPipelines`] owns the
//! shader (`render.wgsl`) and one pipeline per technique and target layout; a [`GpuMaterial`]
//! holds a material's textures, uniforms and bind group; a [`GpuMesh`] its vertex buffers; and
//! [`FrameUniforms`] the camera and lights. `examples/wgpu_material.rs` shows the whole flow.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Mat3, Mat4, Vec3};
use pomkit_core::bake::NormalFilter;
use pomkit_core::mesh::Mesh;
use pomkit_core::scene::{Camera, Light, Material, NormalMap, Texture};
use pomkit_core::trace::Technique;
use pomkit_core::{EdgeMode, HeightField};
use wgpu::util::DeviceExt;

use crate::height::{HeightMaps, HeightPassOptions, HeightPasses};
use crate::host::HeightResource;
use crate::util::{Std140, rgba16f_bytes, texture_entry};
use crate::{GpuContext, GpuError};

/// Lights the shader reads per frame.
pub const MAX_LIGHTS: usize = 4;

pub use crate::library::technique_index;
use crate::library::{ParamError, PomkitParams};
use crate::pipeline::{PipelineError, PipelineOptions};

/// The render targets a pipeline draws into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Targets {
    /// Colour target format (linear colour is written; use an `*Srgb` format for display).
    pub color: wgpu::TextureFormat,
    /// Also write the two AOV targets ([`AOV_FORMATS`]): (hit u, hit v, hit depth, visibility)
    /// and (fetches, height mip level, coverage, 0).
    pub aovs: bool,
    /// Depth format (depth test `Less`, cleared to 1).
    pub depth: wgpu::TextureFormat,
}

/// Formats of the two AOV targets: hit UV and depth need f32; fetches, mip level and coverage fit
/// f16 (fetch counts are exact up to 2048). With an `Rgba16Float` colour target the three stay
/// within WebGPU's default 32 bytes of colour attachments per sample.
pub const AOV_FORMATS: [wgpu::TextureFormat; 2] = [wgpu::TextureFormat::Rgba32Float, wgpu::TextureFormat::Rgba16Float];

/// pomkit's own material shader; the library is composed in front of it.
pub const RENDER_WGSL: &str = include_str!("render.wgsl");

/// Vertex layout: position, normal, tangent (xyz, w handedness), uv, uv scale, depth,
/// curvature.
const VERTEX_FLOATS: usize = 18;

/// Which fragment stage a material's pipeline runs: with pixel depth offset (`frag_depth`) or
/// not, with silhouettes (fragments whose ray leaves the relief are discarded) or not. Each is
/// its own entry point, so a pipeline pays only for what it uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Variant {
    /// Write the traced depth (`fs_main_depth`, `fs_silhouette_depth`).
    pub pixel_depth_offset: bool,
    /// Trace under the curved surface and discard rays that leave (`fs_silhouette*`).
    pub silhouette: bool,
}

impl Variant {
    /// The variant `material` draws with.
    #[must_use]
    pub fn of(material: &GpuMaterial) -> Self {
        Self { pixel_depth_offset: material.pixel_depth_offset, silhouette: material.silhouette }
    }

    /// The fragment entry point of `render.wgsl`.
    fn entry_point(self) -> &'static str {
        match (self.silhouette, self.pixel_depth_offset) {
            (false, false) => "fs_main",
            (false, true) => "fs_main_depth",
            (true, false) => "fs_silhouette",
            (true, true) => "fs_silhouette_depth",
        }
    }
}

/// The shader and its pipelines, created once per device.
pub struct MaterialPipelines {
    shader: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    /// Bind group layout of group 0 (frame).
    pub frame_layout: wgpu::BindGroupLayout,
    /// Bind group layout of group 1 (material).
    pub material_layout: wgpu::BindGroupLayout,
    /// Bind group layout of group 2 (object).
    pub object_layout: wgpu::BindGroupLayout,
    pipelines: HashMap<(u32, Variant, PipelineOptions), wgpu::RenderPipeline>,
    passes: HeightPasses,
    dummy: Arc<DummyTextures>,
}

struct DummyTextures {
    heights: wgpu::TextureView,
    normals: wgpu::TextureView,
    pyramid: wgpu::TextureView,
}

fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn texture_with_mips(
    ctx: &GpuContext,
    label: &str,
    format: wgpu::TextureFormat,
    levels: &[(u32, u32, Vec<u8>)],
) -> wgpu::Texture {
    let (w, h, _) = &levels[0];
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width: *w, height: *h, depth_or_array_layers: 1 },
        mip_level_count: levels.len() as u32,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let bpp = format.block_copy_size(None).unwrap_or(8);
    for (level, (lw, lh, bytes)) in levels.iter().enumerate() {
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: level as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(lw * bpp), rows_per_image: Some(*lh) },
            wgpu::Extent3d { width: *lw, height: *lh, depth_or_array_layers: 1 },
        );
    }
    texture
}

fn rgba_levels(chain: &[Texture]) -> Vec<(u32, u32, Vec<u8>)> {
    chain
        .iter()
        .map(|t| {
            let values: Vec<f32> = t.texels().iter().flat_map(|c| [c.x, c.y, c.z, 1.0]).collect();
            (t.width(), t.height(), rgba16f_bytes(&values))
        })
        .collect()
}

impl MaterialPipelines {
    /// Compiles the shader and the compute passes for `ctx`'s device.
    #[must_use]
    pub fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("pomkit material (render.wgsl + the shader library)"),
            source: wgpu::ShaderSource::Wgsl(crate::library::compose(RENDER_WGSL).into()),
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pomkit frame"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT)],
        });
        let fragment = wgpu::ShaderStages::FRAGMENT;
        let material_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pomkit material"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::FRAGMENT),
                texture_entry(1, true, fragment),
                texture_entry(2, true, fragment),
                texture_entry(3, false, fragment),
                texture_entry(4, true, fragment),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let object_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pomkit object"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("pomkit material"),
            bind_group_layouts: &[Some(&frame_layout), Some(&material_layout), Some(&object_layout)],
            immediate_size: 0,
        });
        let one = |label: &str, format: wgpu::TextureFormat, bytes: Vec<u8>| {
            texture_with_mips(ctx, label, format, &[(1, 1, bytes)]).create_view(&Default::default())
        };
        let dummy = DummyTextures {
            heights: one("pomkit no height", wgpu::TextureFormat::Rgba16Float, rgba16f_bytes(&[0.0; 4])),
            normals: one("pomkit no normals", wgpu::TextureFormat::Rgba16Float, rgba16f_bytes(&[0.0, 0.0, 1.0, 0.0])),
            pyramid: one("pomkit no pyramid", wgpu::TextureFormat::Rg32Float, [0u8; 8].to_vec()),
        };
        Self {
            shader,
            layout,
            frame_layout,
            material_layout,
            object_layout,
            pipelines: HashMap::new(),
            passes: HeightPasses::new(device),
            dummy: Arc::new(dummy),
        }
    }

    /// The compute passes that rebuild height maps.
    #[must_use]
    pub fn height_passes(&self) -> &HeightPasses {
        &self.passes
    }

    /// The pipeline for `technique` if [`MaterialPipelines::pipeline`] created it already.
    #[must_use]
    pub fn cached(&self, technique: Technique, depth_offset: bool, targets: Targets) -> Option<&wgpu::RenderPipeline> {
        let variant = Variant { pixel_depth_offset: depth_offset, silhouette: false };
        self.cached_variant(technique, variant, &PipelineOptions::from(targets))
    }

    /// The pipeline for `technique` and `variant` if it was created already.
    #[must_use]
    pub fn cached_variant(
        &self,
        technique: Technique,
        variant: Variant,
        options: &PipelineOptions,
    ) -> Option<&wgpu::RenderPipeline> {
        self.pipelines.get(&(technique_index(technique), variant, options.clone()))
    }

    /// The pipeline drawing `technique` into `targets` with pomkit's own vertex layout
    /// ([`GpuMesh`]), depth test `Less` and back-face culling (created on first use). Materials
    /// with pixel depth offset use the `frag_depth` variant.
    pub fn pipeline(
        &mut self,
        device: &wgpu::Device,
        technique: Technique,
        depth_offset: bool,
        targets: Targets,
    ) -> &wgpu::RenderPipeline {
        let variant = Variant { pixel_depth_offset: depth_offset, silhouette: false };
        let key = (technique_index(technique), variant, PipelineOptions::from(targets));
        let (shader, layout) = (&self.shader, &self.layout);
        self.pipelines.entry(key).or_insert_with_key(|key| create_pipeline(device, shader, layout, technique, key))
    }

    /// The pipeline drawing `technique` with a host renderer's pipeline state: its depth test
    /// (reverse-Z included), MSAA, culling, formats and vertex layout (created on first use).
    ///
    /// # Errors
    /// [`PipelineError`] when the options do not fit the shader or the device (checked before
    /// wgpu sees them; anything wgpu still refuses is caught in an error scope and returned as
    /// [`PipelineError::Wgpu`], never a panic).
    pub fn pipeline_with(
        &mut self,
        device: &wgpu::Device,
        technique: Technique,
        depth_offset: bool,
        options: &PipelineOptions,
    ) -> Result<&wgpu::RenderPipeline, PipelineError> {
        let variant = Variant { pixel_depth_offset: depth_offset, silhouette: false };
        self.pipeline_variant(device, technique, variant, options)
    }

    /// [`MaterialPipelines::pipeline_with`] for any [`Variant`], silhouettes included
    /// ([`Variant::of`] a material gives the one it needs).
    ///
    /// # Errors
    /// As [`MaterialPipelines::pipeline_with`].
    pub fn pipeline_variant(
        &mut self,
        device: &wgpu::Device,
        technique: Technique,
        variant: Variant,
        options: &PipelineOptions,
    ) -> Result<&wgpu::RenderPipeline, PipelineError> {
        let key = (technique_index(technique), variant, options.clone());
        if !self.pipelines.contains_key(&key) {
            options.validate(device)?;
            let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
            let pipeline = create_pipeline(device, &self.shader, &self.layout, technique, &key);
            if let Some(e) = pollster::block_on(scope.pop()) {
                return Err(PipelineError::Wgpu(e.to_string()));
            }
            self.pipelines.insert(key.clone(), pipeline);
        }
        self.pipelines.get(&key).ok_or_else(|| PipelineError::Wgpu("pipeline cache lost an entry".into()))
    }
}

impl From<Targets> for PipelineOptions {
    fn from(t: Targets) -> Self {
        Self { color: t.color, aovs: t.aovs, depth: t.depth, ..Self::default() }
    }
}

fn create_pipeline(
    device: &wgpu::Device,
    shader: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    technique: Technique,
    key: &(u32, Variant, PipelineOptions),
) -> wgpu::RenderPipeline {
    let (index, variant, o) = key;
    let constants = [("TECHNIQUE", f64::from(*index)), ("REVERSE_Z", if o.reverse_z() { 1.0 } else { 0.0 })];
    let target = |format| wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL };
    // Without AOVs the pipeline has one target, so it fits a pass with one attachment (the
    // shader's AOV outputs are then discarded).
    let mut color_targets = vec![Some(target(o.color))];
    if o.aovs {
        color_targets.extend([Some(target(AOV_FORMATS[0])), Some(target(AOV_FORMATS[1]))]);
    }
    let attributes = o.vertex.wgpu_attributes();
    let buffers: Vec<Option<wgpu::VertexBufferLayout<'_>>> = o
        .vertex
        .buffers
        .iter()
        .zip(&attributes)
        .map(|(b, attributes)| {
            Some(wgpu::VertexBufferLayout {
                array_stride: b.array_stride,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes,
            })
        })
        .collect();
    let label = format!(
        "pomkit {}{}{}",
        technique.name(),
        if variant.pixel_depth_offset { " +pdo" } else { "" },
        if variant.silhouette { " +silhouette" } else { "" }
    );
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(&label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some(o.vertex.entry_point()),
            compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
            buffers: &buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            front_face: o.front_face,
            cull_mode: o.cull_mode,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: o.depth,
            depth_write_enabled: Some(true),
            depth_compare: Some(o.depth_compare),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState { count: o.sample_count, ..Default::default() },
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some(variant.entry_point()),
            compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
            targets: &color_targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A camera as the material's shader sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameView {
    /// World to clip space of the target.
    pub view_proj: Mat4,
    /// World to clip space for pixel depth offset: only its z and w rows are used, so any
    /// aspect ratio will do (pomkit passes its aspect-free projection; hosts pass `view_proj`).
    pub depth_proj: Mat4,
    /// The eye's world position.
    pub eye: Vec3,
}

/// Camera and lights for one frame (bind group 0).
pub struct FrameUniforms {
    buffer: wgpu::Buffer,
    /// The bind group to set at index 0.
    pub bind_group: wgpu::BindGroup,
}

impl FrameUniforms {
    /// A frame uniform block.
    #[must_use]
    pub fn new(ctx: &GpuContext, pipelines: &MaterialPipelines) -> Self {
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit frame"),
            size: Self::bytes_len(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pomkit frame"),
            layout: &pipelines.frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
        });
        Self { buffer, bind_group }
    }

    fn bytes_len() -> u64 {
        // 2 mat4 + eye + ambient + 4 lights x 2 vec4 + 2 u32 (padded to 16).
        (64 * 2 + 16 * 2 + 32 * MAX_LIGHTS as u64) + 16
    }

    /// Writes the camera (for a target of `aspect` = width / height), lights, ambient light and
    /// the LOD tint switch.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for more than [`MAX_LIGHTS`] lights.
    pub fn write(
        &self,
        ctx: &GpuContext,
        camera: &Camera,
        aspect: f32,
        lights: &[Light],
        ambient: Vec3,
        lod_tint: bool,
    ) -> Result<(), GpuError> {
        let view = camera.view();
        self.write_view(
            ctx,
            &FrameView {
                view_proj: camera.projection(aspect) * view,
                depth_proj: camera.projection(1.0) * view,
                eye: camera.eye,
            },
            lights,
            ambient,
            lod_tint,
        )
    }

    /// Writes a host renderer's camera (its own matrices: reverse-Z, infinite far plane or
    /// jitter included), lights, ambient light and the LOD tint switch.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for more than [`MAX_LIGHTS`] lights or a matrix or eye that is
    /// not finite.
    pub fn write_view(
        &self,
        ctx: &GpuContext,
        view: &FrameView,
        lights: &[Light],
        ambient: Vec3,
        lod_tint: bool,
    ) -> Result<(), GpuError> {
        if !(view.view_proj.is_finite() && view.depth_proj.is_finite() && view.eye.is_finite()) {
            return Err(GpuError::Unsupported("a camera matrix or eye position that is not finite".into()));
        }
        if lights.len() > MAX_LIGHTS {
            return Err(GpuError::Unsupported(format!(
                "{} lights: the GPU renderer shades at most {MAX_LIGHTS} per frame",
                lights.len()
            )));
        }
        let u = frame_block(view, lights, ambient, lod_tint);
        ctx.queue.write_buffer(&self.buffer, 0, &u.bytes());
        Ok(())
    }
}

/// A material's textures, uniforms and bind group (bind group 1).
pub struct GpuMaterial {
    /// The technique this material draws with.
    pub technique: Technique,
    /// Whether it writes pixel depth offset (selects the `frag_depth` pipeline).
    pub pixel_depth_offset: bool,
    /// Whether it draws silhouettes (selects the discarding pipeline): the material asks for
    /// them and has a height map and a displacing technique. Meshes then need the curvature
    /// attribute ([`GpuMesh::with_curvature`]).
    pub silhouette: bool,
    /// The height field's GPU textures (mips, normals, parallax map, pyramid), if it has one.
    pub height: Option<HeightMaps>,
    height_options: HeightPassOptions,
    /// Whether the next [`GpuMaterial::encode_rebuild`] builds the cones on the GPU: set by
    /// [`GpuMaterial::rebuild_cones`], or when [`GpuMaterial::set_params`] switches to `cone`.
    cones_stale: std::sync::atomic::AtomicBool,
    /// The material's uniform block: [`PomkitParams`] in its first 64 bytes.
    uniforms: wgpu::Buffer,
    params: PomkitParams,
    /// The bind group to set at index 1.
    pub bind_group: wgpu::BindGroup,
}

impl GpuMaterial {
    /// Uploads `material` to draw with `technique`, and rebuilds its height maps on the GPU
    /// (mips, normals, parallax map, maximum-height pyramid). `normal_filter` is the filter of
    /// the normals computed from the height map when the material has no normal map of its own
    /// (the CPU renderer uses central differences; Sobel is smoother for dynamic fields).
    ///
    /// # Errors
    /// [`GpuError::TooLarge`] for maps beyond the device's texture limit.
    pub fn new(
        ctx: &GpuContext,
        pipelines: &MaterialPipelines,
        material: &Material,
        technique: Technique,
        normal_filter: NormalFilter,
    ) -> Result<Self, GpuError> {
        let p = material.trace.sanitized();
        let height_options =
            HeightPassOptions { edges: p.edges, depth_scale: p.depth_scale, filter: normal_filter, build_cones: false };
        let height = match &material.height {
            Some(field) => {
                let maps = HeightMaps::new(ctx, field.width(), field.height(), &material.name)?;
                maps.upload_depths(ctx, field.depths())?;
                if technique == Technique::Cone {
                    // The cones `cone` steps on: the material's own, or built on the CPU.
                    maps.write_cones(&ctx.queue, material.cones_to_trace().as_deref())?;
                }
                Some(maps)
            }
            None => None,
        };
        let explicit_normals = material.normal_map.as_ref().map(|n| upload_normal_map(ctx, n)).transpose()?;
        let albedo = {
            let mut chain =
                vec![material.albedo.as_ref().map_or_else(|| Texture::constant(Vec3::ONE), |t| (**t).clone())];
            let limit = ctx.device.limits().max_texture_dimension_2d;
            let base = &chain[0];
            if base.width() > limit || base.height() > limit {
                return Err(GpuError::TooLarge {
                    what: format!("material \"{}\" albedo", material.name),
                    width: base.width(),
                    height: base.height(),
                    limit,
                });
            }
            while let Some(last) = chain.last().filter(|t| t.width() > 1 || t.height() > 1) {
                let next = last.downsample();
                chain.push(next);
            }
            chain
        };
        let albedo_tex =
            texture_with_mips(ctx, "pomkit albedo", wgpu::TextureFormat::Rgba16Float, &rgba_levels(&albedo));
        let address = match p.edges {
            EdgeMode::Wrap => wgpu::AddressMode::Repeat,
            EdgeMode::Clamp => wgpu::AddressMode::ClampToEdge,
        };
        let sampler = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("pomkit material"),
            address_mode_u: address,
            address_mode_v: address,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let field = material.height.as_deref();
        let has_normals = explicit_normals.is_some() || field.is_some_and(|f| f.width() >= 2 && f.height() >= 2);
        let params = PomkitParams::from_material(material, technique);
        let albedo_size = (albedo[0].width(), albedo[0].height(), albedo.len() as u32);
        let u = material_block(&params, material, field.is_some(), has_normals, albedo_size);
        let uniforms = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit material"),
            contents: &u.bytes(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let albedo_view = albedo_tex.create_view(&Default::default());
        let d = &pipelines.dummy;
        let (heights_view, pyramid_view) =
            height.as_ref().map_or((&d.heights, &d.pyramid), |m| (&m.heights_view, &m.pyramid_view));
        let explicit_view = explicit_normals.as_ref().map(|t| t.create_view(&Default::default()));
        let normals_view = match (&explicit_view, &height) {
            (Some(v), _) => v,
            (None, Some(m)) => &m.normals_view,
            (None, None) => &d.normals,
        };
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&material.name),
            layout: &pipelines.material_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(heights_view) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(normals_view) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(pyramid_view) },
                wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::TextureView(&albedo_view) },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::Sampler(&sampler) },
            ],
        });
        let silhouette = material.silhouette && height.is_some() && technique.displaces();
        Ok(Self {
            technique,
            pixel_depth_offset: material.pixel_depth_offset,
            silhouette,
            height,
            height_options,
            cones_stale: false.into(),
            uniforms,
            params,
            bind_group,
        })
    }

    /// pomkit's material drawing with textures the program already has: the height maps of
    /// `height` (built from a host texture or a field; rebuild them with
    /// [`HeightResource::encode_rebuild`] when the heights change, not with
    /// [`GpuMaterial::encode_rebuild`], which does nothing here) and, optionally, a colour
    /// texture `albedo` sampled at the traced UV (any filterable float format with
    /// `TEXTURE_BINDING`, all its mips used; sRGB formats are decoded by the sampler).
    /// `material` gives the rest: base colour, specular, tracing parameters, shadows, pixel depth
    /// offset and its normal map if it has one (else `height`'s normals). Its own height field
    /// and albedo are ignored.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] when `material`'s edge mode differs from `height`'s (the
    /// sampler would not match the pyramid), or `albedo` is a texture the shader cannot sample
    /// (not 2D, multisampled, no `TEXTURE_BINDING`, not filterable float); [`GpuError::TooLarge`]
    /// for a normal map beyond the device's limit.
    pub fn with_height_resource(
        ctx: &GpuContext,
        pipelines: &MaterialPipelines,
        material: &Material,
        technique: Technique,
        height: &HeightResource,
        albedo: Option<&wgpu::Texture>,
    ) -> Result<Self, GpuError> {
        let p = material.trace.sanitized();
        if p.edges != height.edges() {
            return Err(GpuError::Unsupported(format!(
                "material \"{}\" traces with {:?} edges but height map \"{}\" was built with {:?} edges: build \
                 them with the same edge mode",
                material.name,
                p.edges,
                height.label(),
                height.edges()
            )));
        }
        if let Some(t) = albedo {
            let filterable = matches!(
                t.format().sample_type(None, Some(ctx.device.features())),
                Some(wgpu::TextureSampleType::Float { filterable: true })
            );
            if t.dimension() != wgpu::TextureDimension::D2
                || t.depth_or_array_layers() != 1
                || t.sample_count() != 1
                || !t.usage().contains(wgpu::TextureUsages::TEXTURE_BINDING)
                || !filterable
            {
                return Err(GpuError::Unsupported(format!(
                    "albedo texture of material \"{}\" ({:?}, {:?}, {} layers, {} samples, usage {:?}): it must \
                     be a single-sampled 2D texture of a filterable float format with TEXTURE_BINDING usage",
                    material.name,
                    t.format(),
                    t.dimension(),
                    t.depth_or_array_layers(),
                    t.sample_count(),
                    t.usage()
                )));
            }
        }
        let explicit_normals = material.normal_map.as_ref().map(|n| upload_normal_map(ctx, n)).transpose()?;
        let explicit_view = explicit_normals.as_ref().map(|t| t.create_view(&Default::default()));
        let white;
        let (albedo_view, albedo_size) = match albedo {
            Some(t) => (t.create_view(&Default::default()), (t.width(), t.height(), t.mip_level_count())),
            None => {
                white = texture_with_mips(
                    ctx,
                    "pomkit albedo",
                    wgpu::TextureFormat::Rgba16Float,
                    &rgba_levels(&[Texture::constant(Vec3::ONE)]),
                );
                (white.create_view(&Default::default()), (1, 1, 1))
            }
        };
        let params = PomkitParams::from_material(material, technique);
        let has_normals = explicit_view.is_some() || (height.width() >= 2 && height.height() >= 2);
        let u = material_block(&params, material, true, has_normals, albedo_size);
        let uniforms = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit material"),
            contents: &u.bytes(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let normals_view = explicit_view.as_ref().unwrap_or(height.normals_view());
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&material.name),
            layout: &pipelines.material_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniforms.as_entire_binding() },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(height.heights_view()),
                },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(normals_view) },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(height.pyramid_view()),
                },
                wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::TextureView(&albedo_view) },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::Sampler(height.sampler()) },
            ],
        });
        Ok(Self {
            technique,
            pixel_depth_offset: material.pixel_depth_offset,
            silhouette: material.silhouette && technique.displaces(),
            height: None,
            height_options: height.options().pass_options(),
            cones_stale: false.into(),
            uniforms,
            params,
            bind_group,
        })
    }

    /// The tracing parameters the material draws with.
    #[must_use]
    pub fn params(&self) -> &PomkitParams {
        &self.params
    }

    /// Changes the tracing parameters (technique, shadow mode, samples, depth scale, LOD
    /// threshold, ...) by writing the uniform buffer: no texture, bind group or pipeline is
    /// rebuilt. Draw with the pipeline of the new [`GpuMaterial::technique`]. A new depth scale
    /// also changes the normals baked from the height map: call
    /// [`GpuMaterial::encode_rebuild`] to bring them along. Switching to `cone` from another
    /// technique has the next rebuild build the cones on the GPU (until then `cone` walks as
    /// `exact` does: the same hits, without the cones' speed).
    ///
    /// # Errors
    /// [`ParamError::EdgesChanged`] when the edge mode differs: the sampler's address mode
    /// is part of the bind group, so make a new material for that.
    pub fn set_params(&mut self, ctx: &GpuContext, params: &PomkitParams) -> Result<(), ParamError> {
        if params.trace.edges != self.params.trace.edges {
            return Err(ParamError::EdgesChanged);
        }
        ctx.queue.write_buffer(&self.uniforms, 0, &params.to_bytes());
        self.params = *params;
        if params.technique == Technique::Cone && self.technique != Technique::Cone {
            // Built on the GPU by the next rebuild (until then `cone` walks as `exact`).
            self.cones_stale.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        self.technique = params.technique;
        let depth_scale = params.trace.sanitized().depth_scale;
        self.height_options.depth_scale = depth_scale;
        Ok(())
    }

    /// Records the compute passes that rebuild the height maps from mip 0 of the height
    /// texture (after [`GpuMaterial::update_height`] or a compute shader of yours wrote it).
    pub fn encode_rebuild(
        &self,
        device: &wgpu::Device,
        pipelines: &MaterialPipelines,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        if let Some(maps) = &self.height {
            let build_cones = self.cones_stale.swap(false, std::sync::atomic::Ordering::Relaxed);
            let opts = HeightPassOptions { build_cones, ..self.height_options };
            pipelines.passes.encode(device, encoder, maps, &opts, timestamps);
        }
    }

    /// Uploads a new height field of the same size (a dynamic height field: call each frame,
    /// then [`GpuMaterial::encode_rebuild`]). Under the `cone` technique the old cones are
    /// removed; [`GpuMaterial::rebuild_cones`] builds new ones.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if the material has no height map or the size differs.
    pub fn update_height(&self, ctx: &GpuContext, field: &HeightField) -> Result<(), GpuError> {
        let maps = self
            .height
            .as_ref()
            .ok_or_else(|| GpuError::Unsupported("updating the height of a material without a height map".into()))?;
        if (maps.width, maps.height) != (field.width(), field.height()) {
            return Err(GpuError::Unsupported(format!(
                "changing a height map's size from {}x{} to {}x{} (create a new GpuMaterial)",
                maps.width,
                maps.height,
                field.width(),
                field.height()
            )));
        }
        maps.upload_depths(ctx, field.depths())?;
        // The cones described the old heights: `cone` walks as `exact` does from now on, unless
        // the caller asks for new ones (`rebuild_cones`).
        if self.technique == Technique::Cone {
            maps.write_cones(&ctx.queue, None)?;
        }
        Ok(())
    }

    /// Gives the `cone` technique the cones of the current heights, built on the CPU
    /// (`pomkit_core::cone::cached`, or a baked map), or removes them (`None`); the next
    /// [`GpuMaterial::encode_rebuild`] puts them into the pyramid. Use after
    /// [`GpuMaterial::update_height`], which removes the old heights' cones.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if the material has no height map or the cones are not its
    /// size.
    pub fn set_cones(&self, ctx: &GpuContext, cones: Option<&pomkit_core::cone::ConeMap>) -> Result<(), GpuError> {
        let maps = self
            .height
            .as_ref()
            .ok_or_else(|| GpuError::Unsupported("giving cones to a material without a height map".into()))?;
        maps.write_cones(&ctx.queue, cones)
    }

    /// Has the next [`GpuMaterial::encode_rebuild`] build the cones of the current heights on
    /// the GPU ([`HeightPassOptions::build_cones`]), for the `cone` technique after
    /// [`GpuMaterial::update_height`] (which removes the old heights' cones: `cone` then walks
    /// as `exact` does, with the same hits). A search per texel: far dearer than the other
    /// passes (docs/BENCHMARKS.md), so for heights that change every frame leave them out.
    pub fn rebuild_cones(&self) {
        self.cones_stale.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// `render.wgsl`'s `Material` uniform: the library's parameters, then pomkit's shading.
fn material_block(
    params: &PomkitParams,
    material: &Material,
    has_height: bool,
    has_normals: bool,
    (albedo_w, albedo_h, albedo_levels): (u32, u32, u32),
) -> Std140 {
    let mut u = Std140::new();
    u.named("params", 16).raw(&params.to_bytes());
    u.named("base_color", 16).vec4(material.base_color.extend(1.0).to_array());
    u.named("specular", 4).f(material.specular);
    u.named("shininess", 4).f(material.shininess);
    u.named("has_height", 4).u(u32::from(has_height));
    u.named("has_normals", 4).u(u32::from(has_normals));
    u.named("albedo_size", 8).f(albedo_w as f32).f(albedo_h as f32);
    u.named("albedo_max_level", 4).f(albedo_levels.saturating_sub(1) as f32);
    u.named("pixel_depth_offset", 4).u(u32::from(material.pixel_depth_offset));
    u
}

/// Each member's name and byte offset in `render.wgsl`'s `Material` uniform as pomkit writes
/// it (a test checks them against the WGSL struct).
#[must_use]
pub fn material_layout() -> Vec<(&'static str, usize)> {
    let params = PomkitParams::from_material(&Material::default(), Technique::Pom);
    material_block(&params, &Material::default(), true, true, (1, 1, 1)).layout()
}

/// Each member's name and byte offset in `render.wgsl`'s `Frame` uniform as
/// [`FrameUniforms::write_view`] writes it.
#[must_use]
pub fn frame_layout() -> Vec<(&'static str, usize)> {
    let view = FrameView { view_proj: Mat4::IDENTITY, depth_proj: Mat4::IDENTITY, eye: Vec3::ZERO };
    frame_block(&view, &[], Vec3::ZERO, false).layout()
}

fn frame_block(view: &FrameView, lights: &[Light], ambient: Vec3, lod_tint: bool) -> Std140 {
    let mut u = Std140::new();
    u.named("view_proj", 16).mat4(view.view_proj);
    u.named("depth_proj", 16).mat4(view.depth_proj);
    u.named("eye", 16).vec4(view.eye.extend(1.0).to_array());
    u.named("ambient", 16).vec4(ambient.extend(0.0).to_array());
    u.named("lights", 16);
    for i in 0..MAX_LIGHTS {
        match lights.get(i) {
            Some(Light::Directional { direction, color, intensity }) => {
                u.vec4(direction.try_normalize().unwrap_or(Vec3::Y).extend(0.0).to_array());
                u.vec4((*color * *intensity).extend(0.0).to_array());
            }
            Some(Light::Point { position, color, intensity }) => {
                u.vec4(position.extend(1.0).to_array());
                u.vec4((*color * *intensity).extend(0.0).to_array());
            }
            None => {
                u.vec4([0.0; 4]);
                u.vec4([0.0; 4]);
            }
        }
    }
    u.named("light_count", 4).u(lights.len() as u32);
    u.named("lod_tint", 4).u(u32::from(lod_tint));
    u
}

fn upload_normal_map(ctx: &GpuContext, n: &NormalMap) -> Result<wgpu::Texture, GpuError> {
    let limit = ctx.device.limits().max_texture_dimension_2d;
    if n.width() > limit || n.height() > limit {
        return Err(GpuError::TooLarge { what: "normal map".into(), width: n.width(), height: n.height(), limit });
    }
    let values: Vec<f32> = n.normals().iter().flat_map(|v| [v.x, v.y, v.z, 0.0]).collect();
    Ok(texture_with_mips(
        ctx,
        "pomkit normal map",
        wgpu::TextureFormat::Rgba16Float,
        &[(n.width(), n.height(), rgba16f_bytes(&values))],
    ))
}

/// A mesh's vertex and index buffers.
pub struct GpuMesh {
    /// Interleaved vertices (see the shader's `VertexIn`).
    pub vertices: wgpu::Buffer,
    /// `u32` triangle list.
    pub indices: wgpu::Buffer,
    /// Index count.
    pub index_count: u32,
}

impl GpuMesh {
    /// Uploads `mesh`; `depths`, when given, is each vertex's depth below the polygon (for
    /// `displaced` geometry), else 0. The curvature attribute is 0 (flat): see
    /// [`GpuMesh::with_curvature`].
    #[must_use]
    pub fn new(ctx: &GpuContext, mesh: &Mesh, depths: Option<&[f32]>) -> Self {
        Self::with_curvature(ctx, mesh, depths, None)
    }

    /// [`GpuMesh::new`] with each vertex's curvature form for silhouettes
    /// (`pomkit_core::silhouette::vertex_curvature` of the mesh as drawn in the world; rotation
    /// and uniform scale leave it unchanged).
    #[must_use]
    pub fn with_curvature(ctx: &GpuContext, mesh: &Mesh, depths: Option<&[f32]>, curvature: Option<&[Vec3]>) -> Self {
        let mut data = Vec::with_capacity(mesh.positions.len() * VERTEX_FLOATS);
        for i in 0..mesh.positions.len() {
            let (p, n, t, uv, s) =
                (mesh.positions[i], mesh.normals[i], mesh.tangents[i], mesh.uvs[i], mesh.uv_scale[i]);
            let d = depths.and_then(|d| d.get(i)).copied().unwrap_or(0.0);
            let k = curvature.and_then(|k| k.get(i)).copied().unwrap_or(Vec3::ZERO);
            data.extend_from_slice(&[
                p.x, p.y, p.z, n.x, n.y, n.z, t.x, t.y, t.z, t.w, uv.x, uv.y, s.x, s.y, d, k.x, k.y, k.z,
            ]);
        }
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let vertices = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit vertices"),
            contents: &bytes,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let ibytes: Vec<u8> = mesh.indices.iter().flat_map(|x| x.to_le_bytes()).collect();
        let indices = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit indices"),
            contents: &ibytes,
            usage: wgpu::BufferUsages::INDEX,
        });
        Self { vertices, indices, index_count: mesh.indices.len() as u32 }
    }
}

/// An object's model matrix (bind group 2).
pub struct GpuObject {
    /// The bind group to set at index 2.
    pub bind_group: wgpu::BindGroup,
    buffer: wgpu::Buffer,
}

impl GpuObject {
    /// An object with the model matrix `model`.
    #[must_use]
    pub fn new(ctx: &GpuContext, pipelines: &MaterialPipelines, model: Mat4) -> Self {
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit object"),
            size: 128,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pomkit object"),
            layout: &pipelines.object_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
        });
        let o = Self { bind_group, buffer };
        o.set_model(ctx, model);
        o
    }

    /// Sets the model matrix (normals use its cofactor matrix, sign-corrected for mirrors).
    pub fn set_model(&self, ctx: &GpuContext, model: Mat4) {
        let m = Mat3::from_mat4(model);
        let (c0, c1, c2) = (m.x_axis, m.y_axis, m.z_axis);
        let cof = Mat3::from_cols(c1.cross(c2), c2.cross(c0), c0.cross(c1));
        let cof = if m.determinant() < 0.0 { -cof } else { cof };
        let mut u = Std140::new();
        u.mat4(model).mat4(Mat4::from_mat3(cof));
        ctx.queue.write_buffer(&self.buffer, 0, &u.bytes());
    }
}
