//! A host texture imported into pomkit's height maps: the texture checked (format, usage,
//! size, channel) and `import.wgsl`'s pass that copies its values as depths.

use super::*;

/// The import pass of a resource built from a host texture.
#[derive(Debug)]
pub(super) struct Import {
    /// `import_main` of `import.wgsl`.
    pub(super) pipeline: wgpu::ComputePipeline,
    /// Host texture view, `heights` mip 0 storage view, parameters.
    pub(super) group: wgpu::BindGroup,
}

impl Import {
    /// Compiles `import.wgsl` and binds `texture`'s mip 0 (already checked) to `maps`' mip 0.
    pub(super) fn new(
        device: &wgpu::Device,
        texture: &wgpu::Texture,
        maps: &HeightMaps,
        opts: &HeightResourceOptions,
        label: &str,
    ) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("import.wgsl"),
            source: wgpu::ShaderSource::Wgsl(crate::library::IMPORT_WGSL.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pomkit height import"),
            entries: &[
                // Unfilterable: accepts filterable and unfilterable float formats alike.
                entry(
                    0,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
                entry(
                    1,
                    wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format: wgpu::TextureFormat::Rgba16Float,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                ),
                entry(
                    2,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(IMPORT_PARAMS_SIZE),
                    },
                ),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("pomkit height import"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("pomkit height import"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("import_main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let encoding = match opts.encoding {
            HeightEncoding::Height => 0,
            HeightEncoding::Depth => 1,
        };
        let mut p = Std140::new();
        p.u(maps.width).u(maps.height).u(opts.channel).u(encoding);
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("{label} import params")),
            contents: &p.bytes(),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let source = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some(&format!("{label} (host texture, mip 0)")),
            dimension: Some(wgpu::TextureViewDimension::D2),
            aspect: wgpu::TextureAspect::All,
            base_mip_level: 0,
            mip_level_count: Some(1),
            base_array_layer: 0,
            array_layer_count: Some(1),
            ..Default::default()
        });
        let target = maps.heights.create_view(&wgpu::TextureViewDescriptor {
            label: Some(&format!("{label} heights mip 0")),
            base_mip_level: 0,
            mip_level_count: Some(1),
            ..Default::default()
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("{label} import")),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&source) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&target) },
                wgpu::BindGroupEntry { binding: 2, resource: params.as_entire_binding() },
            ],
        });
        Self { pipeline, group }
    }
}

/// Checks everything about `texture` that would make the import pass a wgpu validation error.
pub(super) fn check_texture(
    device: &wgpu::Device,
    texture: &wgpu::Texture,
    channel: u32,
    label: &str,
) -> Result<(), HostError> {
    let label = label.to_owned();
    let dimension = texture.dimension();
    if dimension != wgpu::TextureDimension::D2 {
        return Err(HostError::Dimension { label, dimension });
    }
    let layers = texture.depth_or_array_layers();
    if layers != 1 {
        return Err(HostError::Layers { label, layers });
    }
    let samples = texture.sample_count();
    if samples != 1 {
        return Err(HostError::Samples { label, samples });
    }
    let format = texture.format();
    let why = if format.is_depth_stencil_format() {
        Some("a depth or stencil format")
    } else if format.is_multi_planar_format() {
        Some("a multi-planar video format")
    } else {
        match format.sample_type(None, Some(device.features())) {
            Some(wgpu::TextureSampleType::Float { .. }) => None,
            Some(wgpu::TextureSampleType::Uint | wgpu::TextureSampleType::Sint) => Some("an integer format"),
            _ => Some("not a colour format with float samples"),
        }
    };
    if let Some(why) = why {
        return Err(HostError::Format { label, format, why });
    }
    let components = format.components();
    if channel > 3 || channel >= u32::from(components) {
        return Err(HostError::Channel { label, channel, format, components });
    }
    let usage = texture.usage();
    if !usage.contains(wgpu::TextureUsages::TEXTURE_BINDING) {
        return Err(HostError::Usage { label, usage });
    }
    check_size(device, texture.width(), texture.height(), &label)
}
