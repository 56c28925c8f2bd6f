//! The device: adapter selection, the features pomkit uses when present, and buffer readback.

use crate::GpuError;

/// A wgpu device and queue with what pomkit needs to know about them.
///
/// Make one with [`GpuContext::new`] (pomkit picks an adapter) or wrap your own device with
/// [`GpuContext::from_device`] to render into a program that already has one.
#[derive(Clone, Debug)]
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's name, backend and device type (for "which GPU rendered this").
    pub info: wgpu::AdapterInfo,
    /// Whether `TIMESTAMP_QUERY` is enabled: pass times come from the GPU; otherwise
    /// [`crate::Timings`] are wall-clock times around submit-and-wait.
    pub timestamps: bool,
}

impl GpuContext {
    /// Picks an adapter (a discrete or integrated GPU first, then any, software included:
    /// Mesa's lavapipe on a machine without a GPU) and opens a device on it.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] when no adapter exists (no Vulkan, Metal, DX12 or GL driver);
    /// [`GpuError::Device`] when the adapter refuses the device.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<Self, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            // Vulkan, Metal and DX12 only: the GL backend's llvmpipe would be picked on
            // machines without a GPU otherwise, and it lacks the features pomkit checks.
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let mut adapter = None;
        for power in [wgpu::PowerPreference::HighPerformance, wgpu::PowerPreference::LowPower] {
            let options = wgpu::RequestAdapterOptions {
                power_preference: power,
                force_fallback_adapter: false,
                compatible_surface: None,
                ..Default::default()
            };
            if let Ok(a) = instance.request_adapter(&options).await {
                adapter = Some(a);
                break;
            }
        }
        let adapter = adapter.ok_or(GpuError::NoAdapter)?;
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut features = wgpu::Features::empty();
        if timestamps {
            features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        // The adapter's own texture and buffer size limits (wgpu's defaults are 8192 texels and
        // 256 MiB), so that every frame the adapter can hold can be drawn and read back.
        let supported = adapter.limits();
        let limits = wgpu::Limits {
            max_buffer_size: supported.max_buffer_size,
            ..wgpu::Limits::default().using_resolution(supported)
        };
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("pomkit"),
                required_features: features,
                required_limits: limits,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Self { device, queue, info: adapter.get_info(), timestamps })
    }

    /// Wraps a device the caller already has. GPU timestamps are used if the device was created
    /// with [`wgpu::Features::TIMESTAMP_QUERY`], and not otherwise.
    #[must_use]
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> Self {
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        Self { device, queue, info, timestamps }
    }

    /// One line naming the adapter, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)`.
    #[must_use]
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?})", self.info.name, self.info.backend, self.info.device_type)
    }

    /// Whether the adapter is a software rasterizer (lavapipe, llvmpipe, WARP).
    #[must_use]
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Waits for all submitted work.
    ///
    /// # Errors
    /// [`GpuError::Device`] if the device was lost.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| GpuError::Device(e.to_string()))
    }

    /// Copies `buffer` (created with `MAP_READ`) back to the CPU after the submitted work is done.
    ///
    /// # Errors
    /// [`GpuError::Device`] if mapping fails or the device was lost.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|e| GpuError::Device(e.to_string()))?
            .map_err(|e| GpuError::Device(format!("mapping a readback buffer failed: {e}")))?;
        let data = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Device(format!("reading a mapped buffer failed: {e}")))?
            .to_vec();
        buffer.unmap();
        Ok(data)
    }

    /// Reads mip `level` of a 2D texture with 16-byte texels (`Rgba32Float`) or 8-byte texels
    /// (`Rgba16Float`, `Rg32Float`) or 4-byte texels (`R32Float`, and the depth of
    /// `Depth32Float`), returning its texels' channels as `f32`s, rows packed. The texture needs `COPY_SRC` usage.
    ///
    /// # Errors
    /// [`GpuError::Device`] as [`GpuContext::read_buffer`]; [`GpuError::Unsupported`] for another
    /// format.
    pub fn read_texture(&self, texture: &wgpu::Texture, level: u32) -> Result<Vec<f32>, GpuError> {
        let (bpp, channels, half) = match texture.format() {
            wgpu::TextureFormat::Rgba32Float => (16u32, 4usize, false),
            wgpu::TextureFormat::Rgba16Float => (8, 4, true),
            wgpu::TextureFormat::Rg32Float => (8, 2, false),
            wgpu::TextureFormat::R32Float | wgpu::TextureFormat::Depth32Float => (4, 1, false),
            f => return Err(GpuError::Unsupported(format!("reading back {f:?} textures"))),
        };
        let w = (texture.width() >> level).max(1);
        let h = (texture.height() >> level).max(1);
        let row = (w * bpp).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pomkit readback"),
            size: u64::from(row) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: level,
                origin: wgpu::Origin3d::ZERO,
                aspect: if texture.format().has_depth_aspect() {
                    wgpu::TextureAspect::DepthOnly
                } else {
                    wgpu::TextureAspect::All
                },
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(h) },
            },
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        self.queue.submit([enc.finish()]);
        let bytes = self.read_buffer(&buffer)?;
        let mut out = Vec::with_capacity(w as usize * h as usize * channels);
        for y in 0..h as usize {
            let line = &bytes[y * row as usize..y * row as usize + (w * bpp) as usize];
            if half {
                out.extend(line.chunks_exact(2).map(|b| crate::util::f16_to_f32(u16::from_le_bytes([b[0], b[1]]))));
            } else {
                out.extend(line.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])));
            }
        }
        Ok(out)
    }
}

/// The rule pomkit's tests follow when there is no adapter: print `skipping: {reason}` so the
/// test can return early, unless the environment sets `POMKIT_REQUIRE_GPU=1` (CI does), where a
/// missing GPU is a failure.
///
/// # Panics
/// When `POMKIT_REQUIRE_GPU=1`.
pub fn skip_without_gpu(reason: &dyn std::fmt::Display) {
    assert!(
        std::env::var("POMKIT_REQUIRE_GPU").as_deref() != Ok("1"),
        "POMKIT_REQUIRE_GPU=1 but the GPU is unavailable: {reason}"
    );
    println!("skipping: {reason}");
}
