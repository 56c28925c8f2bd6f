//! What a host renderer decides about the pipelines that draw pomkit's material: depth compare
//! (reverse-Z included), MSAA sample count, cull mode and winding, colour and depth formats, and
//! the vertex layout of its own meshes ([`PipelineOptions`], [`VertexLayout`]).
//!
//! [`crate::MaterialPipelines::pipeline_with`] checks the options against the device and
//! returns a [`PipelineError`] naming the problem instead of a wgpu validation panic.

/// A vertex attribute pomkit's material shader reads, with its fixed shader location.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AttributeKind {
    /// Object-space position, `Float32x3`; location 0. Required.
    Position,
    /// Object-space normal, `Float32x3`; location 1. Required.
    Normal,
    /// Object-space tangent along +u with its handedness in w (glTF: B = w * cross(N, T)),
    /// `Float32x4`; location 2. Required.
    Tangent,
    /// Texture coordinate, (0, 0) at the image's top-left corner (glTF), `Float32x2`;
    /// location 3. Required.
    Uv,
    /// World length of one UV unit along u and v (pomkit's `Mesh::uv_scale`), `Float32x2`;
    /// location 4. Optional: without it the shader derives it per pixel from screen-space
    /// derivatives, which is exact on flat triangles.
    UvScale,
    /// Depth of the vertex below the polygon (pomkit's `displaced` geometry), `Float32`;
    /// location 5. Optional, and only with [`AttributeKind::UvScale`].
    Depth,
    /// The surface's curvature form `K = L * II` in the vertex's (T, B) basis
    /// (`pomkit_core::silhouette::vertex_curvature`), `Float32x3`; location 6. Optional, and
    /// only with [`AttributeKind::UvScale`]; read by materials with silhouettes (without it
    /// they see a flat surface: only clamped charts cut the outline).
    Curvature,
}

impl AttributeKind {
    /// Every kind, in shader-location order.
    pub const ALL: [AttributeKind; 7] = [
        AttributeKind::Position,
        AttributeKind::Normal,
        AttributeKind::Tangent,
        AttributeKind::Uv,
        AttributeKind::UvScale,
        AttributeKind::Depth,
        AttributeKind::Curvature,
    ];

    /// The shader location.
    #[must_use]
    pub const fn location(self) -> u32 {
        match self {
            AttributeKind::Position => 0,
            AttributeKind::Normal => 1,
            AttributeKind::Tangent => 2,
            AttributeKind::Uv => 3,
            AttributeKind::UvScale => 4,
            AttributeKind::Depth => 5,
            AttributeKind::Curvature => 6,
        }
    }

    /// The format the shader reads.
    #[must_use]
    pub const fn format(self) -> wgpu::VertexFormat {
        match self {
            AttributeKind::Position | AttributeKind::Normal | AttributeKind::Curvature => wgpu::VertexFormat::Float32x3,
            AttributeKind::Tangent => wgpu::VertexFormat::Float32x4,
            AttributeKind::Uv | AttributeKind::UvScale => wgpu::VertexFormat::Float32x2,
            AttributeKind::Depth => wgpu::VertexFormat::Float32,
        }
    }

    /// Whether a layout must have it.
    #[must_use]
    pub const fn required(self) -> bool {
        matches!(self, AttributeKind::Position | AttributeKind::Normal | AttributeKind::Tangent | AttributeKind::Uv)
    }

    /// A lower-case name for messages.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            AttributeKind::Position => "position",
            AttributeKind::Normal => "normal",
            AttributeKind::Tangent => "tangent",
            AttributeKind::Uv => "uv",
            AttributeKind::UvScale => "uv scale",
            AttributeKind::Depth => "depth",
            AttributeKind::Curvature => "curvature",
        }
    }
}

/// One attribute of a vertex buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct VertexAttribute {
    /// What it holds.
    pub kind: AttributeKind,
    /// Byte offset within one vertex.
    pub offset: u64,
}

/// One vertex buffer of a host's mesh: its stride and the attributes it holds.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct VertexBuffer {
    /// Bytes from one vertex to the next.
    pub array_stride: u64,
    /// The attributes in this buffer.
    pub attributes: Vec<VertexAttribute>,
}

/// How a host's vertex buffers hold the attributes pomkit's material reads: bind buffer `i` of
/// [`VertexLayout::buffers`] at vertex-buffer slot `i` when drawing.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct VertexLayout {
    /// The buffers, in slot order.
    pub buffers: Vec<VertexBuffer>,
}

impl VertexLayout {
    /// pomkit's own layout ([`crate::GpuMesh`]): one buffer of 18 floats per vertex, position,
    /// normal, tangent, uv, uv scale, depth, curvature.
    #[must_use]
    pub fn pomkit() -> Self {
        Self::interleaved(&AttributeKind::ALL)
    }

    /// One buffer holding `kinds` tightly packed in the given order.
    #[must_use]
    pub fn interleaved(kinds: &[AttributeKind]) -> Self {
        let mut offset = 0;
        let attributes = kinds
            .iter()
            .map(|&kind| {
                let a = VertexAttribute { kind, offset };
                offset += kind.format().size();
                a
            })
            .collect();
        Self { buffers: vec![VertexBuffer { array_stride: offset, attributes }] }
    }

    /// One buffer per attribute, each tightly packed, in the given order (the layout of
    /// programs that keep positions, normals, tangents and UVs in separate arrays).
    #[must_use]
    pub fn separate(kinds: &[AttributeKind]) -> Self {
        Self {
            buffers: kinds
                .iter()
                .map(|&kind| VertexBuffer {
                    array_stride: kind.format().size(),
                    attributes: vec![VertexAttribute { kind, offset: 0 }],
                })
                .collect(),
        }
    }

    /// Whether the layout has the attribute.
    #[must_use]
    pub fn has(&self, kind: AttributeKind) -> bool {
        self.buffers.iter().flat_map(|b| &b.attributes).any(|a| a.kind == kind)
    }

    /// Checks the layout against what the shader reads and what `limits` allow.
    ///
    /// # Errors
    /// [`PipelineError::VertexLayout`] naming the attribute or buffer and the problem.
    pub fn validate(&self, limits: &wgpu::Limits) -> Result<(), PipelineError> {
        let err = |m: String| Err(PipelineError::VertexLayout(m));
        if self.buffers.len() as u64 > u64::from(limits.max_vertex_buffers) {
            return err(format!(
                "{} vertex buffers: this device binds at most {}",
                self.buffers.len(),
                limits.max_vertex_buffers
            ));
        }
        for kind in AttributeKind::ALL {
            let count = self.buffers.iter().flat_map(|b| &b.attributes).filter(|a| a.kind == kind).count();
            if count > 1 {
                return err(format!("the {} attribute appears {count} times: give it once", kind.name()));
            }
            if count == 0 && kind.required() {
                return err(format!(
                    "no {} attribute: pomkit's material needs position, normal, tangent (xyz + w handedness, glTF \
                     style) and uv",
                    kind.name()
                ));
            }
        }
        if self.has(AttributeKind::Depth) && !self.has(AttributeKind::UvScale) {
            return err(
                "a depth attribute without a uv scale attribute: give both (pomkit's own layout) or neither".into()
            );
        }
        if self.has(AttributeKind::Curvature) && !self.has(AttributeKind::UvScale) {
            return err("a curvature attribute without a uv scale attribute: silhouettes need both".into());
        }
        for (slot, b) in self.buffers.iter().enumerate() {
            if b.attributes.is_empty() {
                return err(format!("vertex buffer {slot} holds no attribute"));
            }
            if b.array_stride % 4 != 0 || b.array_stride > u64::from(limits.max_vertex_buffer_array_stride) {
                return err(format!(
                    "vertex buffer {slot} has a stride of {} bytes: it must be a multiple of 4 and at most {}",
                    b.array_stride, limits.max_vertex_buffer_array_stride
                ));
            }
            for a in &b.attributes {
                let end = a.offset.checked_add(a.kind.format().size());
                if a.offset % 4 != 0 || end.is_none_or(|e| b.array_stride != 0 && e > b.array_stride) {
                    return err(format!(
                        "the {} attribute at byte {} of vertex buffer {slot} ({:?}, {} bytes) does not fit a \
                         4-byte-aligned place inside the stride of {} bytes",
                        a.kind.name(),
                        a.offset,
                        a.kind.format(),
                        a.kind.format().size(),
                        b.array_stride
                    ));
                }
            }
        }
        Ok(())
    }

    /// The vertex entry point of `render.wgsl` that reads this layout.
    pub(crate) fn entry_point(&self) -> &'static str {
        let has = |k| self.has(k);
        match (has(AttributeKind::UvScale), has(AttributeKind::Depth), has(AttributeKind::Curvature)) {
            (true, true, true) => "vs_main",
            (true, true, false) => "vs_depth",
            (true, false, true) => "vs_scaled_curved",
            (true, false, false) => "vs_scaled",
            _ => "vs_basic",
        }
    }

    /// The wgpu attributes of each buffer.
    pub(crate) fn wgpu_attributes(&self) -> Vec<Vec<wgpu::VertexAttribute>> {
        self.buffers
            .iter()
            .map(|b| {
                b.attributes
                    .iter()
                    .map(|a| wgpu::VertexAttribute {
                        format: a.kind.format(),
                        offset: a.offset,
                        shader_location: a.kind.location(),
                    })
                    .collect()
            })
            .collect()
    }
}

/// The pipeline state a host renderer decides.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PipelineOptions {
    /// Colour target format. The shader writes linear colour: use an `*Srgb` format to display
    /// it, or a float format to tone-map it yourself.
    pub color: wgpu::TextureFormat,
    /// Also write the two AOV targets ([`crate::material::AOV_FORMATS`]); single-sampled only.
    pub aovs: bool,
    /// Depth format.
    pub depth: wgpu::TextureFormat,
    /// Depth test. `Less` (the default) for a depth buffer cleared to 1; `Greater` or
    /// `GreaterEqual` for reverse-Z (cleared to 0), which also makes pixel depth offset move
    /// depths toward 0.
    pub depth_compare: wgpu::CompareFunction,
    /// MSAA samples per pixel: 1 (the default), or what the formats support (4 everywhere).
    pub sample_count: u32,
    /// Faces not drawn (default `Some(Back)`).
    pub cull_mode: Option<wgpu::Face>,
    /// The winding of front faces (default counter-clockwise).
    pub front_face: wgpu::FrontFace,
    /// The host's vertex buffers (default [`VertexLayout::pomkit`]).
    pub vertex: VertexLayout,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        Self {
            color: wgpu::TextureFormat::Rgba8UnormSrgb,
            aovs: false,
            depth: wgpu::TextureFormat::Depth32Float,
            depth_compare: wgpu::CompareFunction::Less,
            sample_count: 1,
            cull_mode: Some(wgpu::Face::Back),
            front_face: wgpu::FrontFace::Ccw,
            vertex: VertexLayout::pomkit(),
        }
    }
}

impl PipelineOptions {
    /// Whether the depth test is reverse-Z (`Greater` or `GreaterEqual`).
    #[must_use]
    pub fn reverse_z(&self) -> bool {
        matches!(self.depth_compare, wgpu::CompareFunction::Greater | wgpu::CompareFunction::GreaterEqual)
    }

    /// Checks the options against the device's features and limits (the formats' guaranteed
    /// capabilities; an adapter may support more MSAA counts than are checked here, and
    /// [`crate::MaterialPipelines::pipeline_with`] still turns anything wgpu refuses into an
    /// error value).
    ///
    /// # Errors
    /// [`PipelineError`] naming the option and the problem.
    pub fn validate(&self, device: &wgpu::Device) -> Result<(), PipelineError> {
        let features = device.features();
        let color = self.color.guaranteed_format_features(features);
        let float_target =
            matches!(self.color.sample_type(None, Some(features)), Some(wgpu::TextureSampleType::Float { .. }));
        if self.color.is_depth_stencil_format()
            || !float_target
            || !color.allowed_usages.contains(wgpu::TextureUsages::RENDER_ATTACHMENT)
        {
            return Err(PipelineError::Format(format!(
                "colour format {:?} cannot be rendered to by a shader writing float colour: use a unorm, srgb or \
                 float colour format such as Rgba8UnormSrgb or Rgba16Float",
                self.color
            )));
        }
        if !self.depth.has_depth_aspect() {
            return Err(PipelineError::Format(format!(
                "depth format {:?} has no depth: use Depth32Float, Depth24Plus or another depth format",
                self.depth
            )));
        }
        if !matches!(self.sample_count, 1 | 2 | 4 | 8 | 16) {
            return Err(PipelineError::SampleCount(format!("{} samples: use 1, 2, 4, 8 or 16", self.sample_count)));
        }
        if self.sample_count > 1 {
            if self.aovs {
                return Err(PipelineError::SampleCount(format!(
                    "{} samples with AOVs: the AOV targets (Rgba32Float) cannot be multisampled; draw AOVs in a \
                     single-sampled pass",
                    self.sample_count
                )));
            }
            let depth = self.depth.guaranteed_format_features(features);
            // Formats may support more counts on a given adapter; with adapter-specific format
            // features enabled, wgpu itself is the judge (pipeline_with catches its refusal).
            let adapter_specific = features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
            for (what, format, f) in [("colour", self.color, color), ("depth", self.depth, depth)] {
                if !f.flags.sample_count_supported(self.sample_count) && !adapter_specific {
                    return Err(PipelineError::SampleCount(format!(
                        "{} samples for the {what} format {format:?}: WebGPU guarantees {:?} for it",
                        self.sample_count,
                        f.flags.supported_sample_counts()
                    )));
                }
            }
        }
        self.vertex.validate(&device.limits())
    }
}

/// Why [`crate::MaterialPipelines::pipeline_with`] could not make a pipeline.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PipelineError {
    /// The vertex layout lacks an attribute the shader reads (position, normal, tangent, uv),
    /// repeats one, or places one outside its buffer's stride.
    #[error("vertex layout: {0}")]
    VertexLayout(String),
    /// A colour or depth format the material cannot draw into.
    #[error("target format: {0}")]
    Format(String),
    /// An MSAA sample count the formats or the AOVs do not support.
    #[error("sample count: {0}")]
    SampleCount(String),
    /// wgpu refused the pipeline for a reason the checks above do not cover (its message).
    #[error("wgpu refused the pipeline: {0}")]
    Wgpu(String),
}
