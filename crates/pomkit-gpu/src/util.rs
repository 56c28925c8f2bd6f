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

/// Gives the process a private runtime directory when `XDG_RUNTIME_DIR` is unset or not an
/// absolute path to a directory. Without one, Mesa's device-select Vulkan layer (through
/// libwayland) prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." twice
/// whenever a device is created, although nothing is wrong (a container, a CI job, an SSH
/// session). The directory is `$TMPDIR/pomkit-runtime-UID`, mode 0700, created once and reused;
/// when it cannot be made safely (not ours, not private, not a directory), the environment is
/// left alone. Does nothing where there is no such variable to set (not unix).
///
/// # Safety
/// It sets an environment variable (`std::env::set_var`): call it first thing in `main`,
/// before any other thread starts, as the `pomkit` command line and the examples do.
#[cfg(unix)]
#[expect(
    unsafe_code,
    reason = "std::env::set_var is unsafe in Rust 2024 because another thread may read the environment \
              concurrently; the caller promises that no other thread runs yet"
)]
pub unsafe fn ensure_runtime_dir() {
    let usable = std::env::var_os("XDG_RUNTIME_DIR")
        .map(std::path::PathBuf::from)
        .is_some_and(|d| d.is_absolute() && d.is_dir());
    if usable {
        return;
    }
    if let Some(dir) = private_runtime_dir() {
        // SAFETY: the caller guarantees that no other thread reads or writes the environment.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir) };
    }
}

/// As on unix: nothing to do elsewhere.
///
/// # Safety
/// None needed; `unsafe` only to match the unix signature.
#[cfg(not(unix))]
#[expect(unsafe_code, reason = "the same signature as on unix, where it sets an environment variable")]
pub unsafe fn ensure_runtime_dir() {}

/// `$TMPDIR/pomkit-runtime-UID`, created with mode 0700 if absent; `None` unless it is a real
/// directory (not a link) owned by this user and closed to everyone else.
#[cfg(unix)]
fn private_runtime_dir() -> Option<std::path::PathBuf> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    let uid = std::fs::metadata("/proc/self").ok()?.uid();
    let dir = std::env::temp_dir().join(format!("pomkit-runtime-{uid}"));
    match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(_) => return None,
    }
    let meta = std::fs::symlink_metadata(&dir).ok()?;
    (meta.is_dir() && meta.uid() == uid && meta.permissions().mode() & 0o077 == 0 && dir.is_absolute()).then_some(dir)
}
