//! Small helpers: byte packing for uniforms and textures (no `unsafe`, no derive macros).

/// `f32` to IEEE half bits (round to nearest).
#[must_use]
pub fn f32_to_f16(x: f32) -> u16 {
    half::f16::from_f32(x).to_bits()
}

/// IEEE half bits to `f32`.
#[must_use]
pub fn f16_to_f32(bits: u16) -> f32 {
    half::f16::from_bits(bits).to_f32()
}

/// Little-endian bytes of `f32` values packed as `Rgba16Float` texels (`values.len()` a multiple of 4).
#[must_use]
pub fn rgba16f_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|&v| f32_to_f16(v).to_le_bytes()).collect()
}

/// A uniform block under construction: 4-byte words appended in WGSL layout order.
///
/// The caller keeps WGSL's alignment rules (vec3 and vec4 on 16 bytes, mat4 as four vec4s) by
/// padding with [`Std140::pad_to`].
#[derive(Clone, Debug, Default)]
pub struct Std140 {
    words: Vec<u32>,
    names: Vec<(&'static str, usize)>,
}

impl Std140 {
    /// An empty block.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends one `f32`.
    pub fn f(&mut self, x: f32) -> &mut Self {
        self.words.push(x.to_bits());
        self
    }

    /// Appends one `u32`.
    pub fn u(&mut self, x: u32) -> &mut Self {
        self.words.push(x);
        self
    }

    /// Appends several `f32`s.
    pub fn fs(&mut self, xs: &[f32]) -> &mut Self {
        self.words.extend(xs.iter().map(|x| x.to_bits()));
        self
    }

    /// Appends a `vec4<f32>` (16-byte aligned).
    pub fn vec4(&mut self, v: [f32; 4]) -> &mut Self {
        self.pad_to(16);
        self.fs(&v)
    }

    /// Appends a column-major `mat4x4<f32>`.
    pub fn mat4(&mut self, m: glam::Mat4) -> &mut Self {
        self.pad_to(16);
        self.fs(&m.to_cols_array())
    }

    /// Pads to `align` bytes and records that the member `name` starts here (see
    /// [`Std140::layout`]).
    pub fn named(&mut self, name: &'static str, align: usize) -> &mut Self {
        self.pad_to(align);
        self.names.push((name, self.words.len() * 4));
        self
    }

    /// The byte offset of each member recorded with [`Std140::named`], in order: tests compare
    /// it with the WGSL struct's layout as naga computes it.
    #[must_use]
    pub fn layout(&self) -> Vec<(&'static str, usize)> {
        self.names.clone()
    }

    /// Appends a nested struct's bytes (a whole number of 16-byte rows, 16-byte aligned).
    pub fn raw(&mut self, bytes: &[u8]) -> &mut Self {
        self.pad_to(16);
        self.words.extend(bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])));
        self
    }

    /// Pads with zeros to a multiple of `align` bytes.
    pub fn pad_to(&mut self, align: usize) -> &mut Self {
        while !(self.words.len() * 4).is_multiple_of(align) {
            self.words.push(0);
        }
        self
    }

    /// The bytes, padded to 16.
    #[must_use]
    pub fn bytes(&self) -> Vec<u8> {
        let mut w = self.clone();
        w.pad_to(16);
        w.words.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
}

/// A bind group layout entry for a `texture_2d<f32>` (float samples, `filterable` or not).
#[cfg(feature = "renderer")]
#[must_use]
pub fn texture_entry(binding: u32, filterable: bool, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// The sampler pomkit reads height maps and material textures with: trilinear, wrapping or
/// clamping as `edges` says (the material's, the height resource's and the ray probe's).
#[cfg(feature = "renderer")]
#[must_use]
pub fn trilinear_sampler(device: &wgpu::Device, edges: pomkit_core::EdgeMode, label: &str) -> wgpu::Sampler {
    let address = match edges {
        pomkit_core::EdgeMode::Wrap => wgpu::AddressMode::Repeat,
        pomkit_core::EdgeMode::Clamp => wgpu::AddressMode::ClampToEdge,
    };
    device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some(label),
        address_mode_u: address,
        address_mode_v: address,
        address_mode_w: address,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        mipmap_filter: wgpu::MipmapFilterMode::Linear,
        ..Default::default()
    })
}
