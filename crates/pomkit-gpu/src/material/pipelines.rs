//! [`MaterialPipelines`]: pomkit's material shader and one render pipeline per technique,
//! variant and target layout, built on first use.

use super::*;

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
pub(super) const VERTEX_FLOATS: usize = 18;

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
    pub(super) shader: wgpu::ShaderModule,
    pub(super) layout: wgpu::PipelineLayout,
    /// Bind group layout of group 0 (frame).
    pub frame_layout: wgpu::BindGroupLayout,
    /// Bind group layout of group 1 (material).
    pub material_layout: wgpu::BindGroupLayout,
    /// Bind group layout of group 2 (object).
    pub object_layout: wgpu::BindGroupLayout,
    pub(super) pipelines: HashMap<(u32, Variant, PipelineOptions), wgpu::RenderPipeline>,
    pub(super) passes: HeightPasses,
    pub(super) dummy: Arc<DummyTextures>,
}

pub(super) struct DummyTextures {
    pub(super) heights: wgpu::TextureView,
    pub(super) normals: wgpu::TextureView,
    pub(super) pyramid: wgpu::TextureView,
    /// A 1x1 `Rgba32Uint` for a material without plane bounds (never read).
    pub(super) planes: wgpu::TextureView,
}

pub(super) fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
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

pub(super) fn texture_with_mips(
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

pub(super) fn rgba_levels(chain: &[Texture]) -> Vec<(u32, u32, Vec<u8>)> {
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
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: fragment,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
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
            planes: crate::planes::PlaneBounds::empty(device).view,
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

pub(super) fn create_pipeline(
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
