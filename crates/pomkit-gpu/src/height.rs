//! Dynamic height fields: a height map's mips, normals, parallax map and maximum-height pyramid,
//! rebuilt by compute passes so that the field may change every frame (Tatarchuk 2006).
//!
//! [`HeightMaps`] owns the textures of one field; [`HeightPasses`] owns the pipelines (one set
//! per device) and records the rebuild into a command encoder. The shader, `height.wgsl`, is the
//! WGSL twin of pomkit-core's `bake_normals`, `Surface::new` (the parallax map),
//! `HeightField::downsample` and `MaxHeightPyramid::new`; `tests/height_passes.rs` compares them
//! texel by texel.
//!
//! ```no_run
//! use pomkit_gpu::GpuContext;
//! use pomkit_gpu::height::{HeightMaps, HeightPassOptions, HeightPasses};
//!
//! let ctx = GpuContext::new()?;
//! let passes = HeightPasses::new(&ctx.device);
//! let maps = HeightMaps::new(&ctx, 256, 256, "water")?;
//! let depths = vec![0.5f32; 256 * 256];
//! // Every frame: new depths in, everything derived from them rebuilt.
//! maps.upload_depths(&ctx, &depths)?;
//! let mut encoder = ctx.device.create_command_encoder(&Default::default());
//! passes.encode(&ctx.device, &mut encoder, &maps, &HeightPassOptions::default(), None);
//! ctx.queue.submit([encoder.finish()]);
//! # Ok::<(), pomkit_gpu::GpuError>(())
//! ```

use pomkit_core::bake::NormalFilter;
use pomkit_core::{EdgeMode, HeightField};
use wgpu::util::DeviceExt;

use crate::util::Std140;
use crate::{GpuContext, GpuError};

/// Side of the square compute workgroups in `height.wgsl`.
const WORKGROUP: u32 = 8;

/// Bytes of one `Params` record in `height.wgsl`.
const PARAMS_SIZE: u64 = 32;

/// The depth scale used when the given one is not a finite positive number (as
/// `TraceParams::sanitized` and `Surface::new` do).
const DEFAULT_DEPTH_SCALE: f32 = 0.1;

/// GPU textures of one height field.
///
/// All three textures are written by [`HeightPasses::encode`] from `heights` mip 0's R channel,
/// which [`HeightMaps::upload_depths`] fills (or a shader of the caller's own, for a field made
/// on the GPU).
#[derive(Debug)]
pub struct HeightMaps {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `Rgba16Float` with the full mip chain (sides halve rounding down, so there are
    /// `floor(log2(max(w, h))) + 1` levels, as `MipChain` has); usage
    /// `TEXTURE_BINDING | STORAGE_BINDING | COPY_DST | COPY_SRC`.
    /// R = depth d, G = parallax value `clamp(n_z * d, 0, 1)` (`Surface::new`'s map); B, A = 0.
    /// Each mip is the exact box filter of the one above (`HeightField::downsample`).
    pub heights: wgpu::Texture,
    /// A view over all mips of `heights` (for `textureSampleLevel` with a trilinear sampler).
    pub heights_view: wgpu::TextureView,
    /// `Rgba16Float`, one mip: xyz = unit normal (+Y up, pomkit tangent space), w = 0.
    pub normals: wgpu::Texture,
    /// A view of `normals`.
    pub normals_view: wgpu::TextureView,
    /// `Rg32Float` maximum-height (minimum-depth) pyramid, read with `textureLoad`: mip `l` holds
    /// pyramid level `l` (`MaxHeightPyramid::min_depth`) in its top-left
    /// [`HeightMaps::pyramid_level_size`] texels, in red. Green is 0, except in mip 0 of a map
    /// given cones ([`HeightMaps::write_cones`]): there it holds each footprint's cone ratio.
    ///
    /// GPU mips halve rounding down but the pyramid halves rounding up, so the base is padded to
    /// `(next_power_of_two(w), next_power_of_two(h))`; the padding texels are never written (they
    /// hold 0) and must not be read. Costs up to 4x the texels of an unpadded base for sizes
    /// just above a power of two.
    pub pyramid: wgpu::Texture,
    /// A view over all mips of `pyramid`.
    pub pyramid_view: wgpu::TextureView,
    /// Mip levels of `pyramid` (= `MaxHeightPyramid::len()`, `ceil(log2(max(w, h))) + 1`).
    pub pyramid_levels: u32,
    /// Single-mip views of `heights`, one per level (read or written by the passes).
    height_levels: Vec<wgpu::TextureView>,
    /// Single-mip views of `pyramid`, one per level.
    pyramid_level_views: Vec<wgpu::TextureView>,
    /// `Rgba16Float` w x h: (d, parallax) of mip 0 on their way back into `heights` (a texture
    /// cannot be read and written in one dispatch; see `height.wgsl`, stage 1).
    scratch_view: wgpu::TextureView,
    /// `R32Float`, one texel per footprint: the cone ratios the pyramid's level 0 carries in
    /// green ([`HeightMaps::write_cones`]); 0 (no cones) until written.
    cones: wgpu::Texture,
    cones_view: wgpu::TextureView,
}

/// `field` with its depths rounded to f16 as [`HeightMaps::upload_depths`] stores them: the
/// surface the GPU samples, so the one to compare the GPU's answers with on the CPU.
#[must_use]
pub fn f16_surface(field: &HeightField) -> HeightField {
    let depths = field.depths().iter().map(|&d| half::f16::from_f32(d).to_f32()).collect();
    HeightField::from_depths(field.width(), field.height(), depths).expect("f16 rounding keeps depths in [0, 1]")
}

impl HeightMaps {
    /// Allocates the textures of a `width` x `height` field (contents zero until the first
    /// upload and [`HeightPasses::encode`]).
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if a side is 0; [`GpuError::TooLarge`] if a side, or the
    /// pyramid's power-of-two padded side, exceeds the device's `max_texture_dimension_2d`.
    pub fn new(ctx: &GpuContext, width: u32, height: u32, label: &str) -> Result<Self, GpuError> {
        Self::with_device(&ctx.device, width, height, label)
    }

    /// [`HeightMaps::new`] for a program that has a bare `wgpu::Device` rather than a
    /// [`GpuContext`] (`crate::host::HeightResource` uses it).
    ///
    /// # Errors
    /// As [`HeightMaps::new`].
    pub fn with_device(device: &wgpu::Device, width: u32, height: u32, label: &str) -> Result<Self, GpuError> {
        if width == 0 || height == 0 {
            return Err(GpuError::Unsupported(format!(
                "height map \"{label}\" of {width}x{height} texels: both sides must be at least 1"
            )));
        }
        let limit = device.limits().max_texture_dimension_2d;
        if width > limit || height > limit {
            return Err(GpuError::TooLarge { what: format!("height map \"{label}\""), width, height, limit });
        }
        let (pw, ph) = (width.next_power_of_two(), height.next_power_of_two());
        if pw > limit || ph > limit {
            return Err(GpuError::TooLarge {
                what: format!("maximum-height pyramid of \"{label}\" (padded to powers of two)"),
                width: pw,
                height: ph,
                limit,
            });
        }
        let mips = 32 - width.max(height).leading_zeros();
        let pyramid_levels = 32 - pw.max(ph).leading_zeros();
        let usage = wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::COPY_DST
            | wgpu::TextureUsages::COPY_SRC;
        let texture = |what: &str, w: u32, h: u32, mip_level_count: u32, format: wgpu::TextureFormat| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(&format!("{label} {what}")),
                size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
                mip_level_count,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let heights = texture("heights", width, height, mips, wgpu::TextureFormat::Rgba16Float);
        let normals = texture("normals", width, height, 1, wgpu::TextureFormat::Rgba16Float);
        let pyramid = texture("pyramid", pw, ph, pyramid_levels, wgpu::TextureFormat::Rg32Float);
        let scratch = texture("scratch", width, height, 1, wgpu::TextureFormat::Rgba16Float);
        // Zero-initialised: no cones.
        let cones = texture("cones", width, height, 1, wgpu::TextureFormat::R32Float);
        let level_views = |t: &wgpu::Texture| -> Vec<wgpu::TextureView> {
            (0..t.mip_level_count())
                .map(|l| {
                    t.create_view(&wgpu::TextureViewDescriptor {
                        base_mip_level: l,
                        mip_level_count: Some(1),
                        ..Default::default()
                    })
                })
                .collect()
        };
        Ok(Self {
            width,
            height,
            heights_view: heights.create_view(&Default::default()),
            height_levels: level_views(&heights),
            heights,
            normals_view: normals.create_view(&Default::default()),
            normals,
            pyramid_view: pyramid.create_view(&Default::default()),
            pyramid_level_views: level_views(&pyramid),
            pyramid,
            pyramid_levels,
            scratch_view: scratch.create_view(&Default::default()),
            cones_view: cones.create_view(&Default::default()),
            cones,
        })
    }

    /// Mip levels of `heights` (`floor(log2(max(w, h))) + 1`).
    #[must_use]
    pub fn height_levels(&self) -> u32 {
        self.heights.mip_level_count()
    }

    /// Cells `(columns, rows)` of pyramid level `level`: the sides halved `level` times rounding
    /// up (`MaxHeightPyramid::level_size`). Levels past the last give `(1, 1)`.
    #[must_use]
    pub fn pyramid_level_size(&self, level: u32) -> (u32, u32) {
        let l = level.min(31);
        (self.width.div_ceil(1 << l), self.height.div_ceil(1 << l))
    }

    /// Writes `depths` (row-major, top row first, `width * height` values; 0 = surface,
    /// 1 = deepest) into `heights` mip 0: R = depth, G = B = A = 0, rounded to f16 (steps of
    /// 2^-11 near 1, so about 5e-4 of the depth range). Values outside `[0, 1]` are clamped and
    /// NaN becomes 1 (deepest), as `HeightField::from_height_fn` treats a NaN height.
    ///
    /// Run [`HeightPasses::encode`] afterwards: until then mips, G, normals and pyramid are
    /// stale.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if `depths.len()` is not `width * height`.
    pub fn upload_depths(&self, ctx: &GpuContext, depths: &[f32]) -> Result<(), GpuError> {
        self.write_depths(&ctx.queue, depths)
    }

    /// [`HeightMaps::upload_depths`] through a queue of the caller's own.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if `depths.len()` is not `width * height`.
    pub fn write_depths(&self, queue: &wgpu::Queue, depths: &[f32]) -> Result<(), GpuError> {
        let expected = self.width as usize * self.height as usize;
        if depths.len() != expected {
            return Err(GpuError::Unsupported(format!(
                "uploading {} depths to a {}x{} height map ({expected} texels)",
                depths.len(),
                self.width,
                self.height
            )));
        }
        // Fallible: the upload's copies are the largest host allocations of a big height map.
        let cannot = |e: std::collections::TryReserveError| {
            GpuError::Unsupported(format!(
                "uploading a {}x{} height map: cannot allocate its {} upload ({e}): use a smaller height map",
                self.width,
                self.height,
                pomkit_core::memory::format_bytes(expected as u64 * 24)
            ))
        };
        let mut texels: Vec<f32> = Vec::new();
        texels.try_reserve_exact(expected * 4).map_err(cannot)?;
        texels.extend(depths.iter().flat_map(|&d| {
            let d = if d.is_nan() { 1.0 } else { d.clamp(0.0, 1.0) };
            [d, 0.0, 0.0, 0.0]
        }));
        let mut halfs: Vec<u8> = Vec::new();
        halfs.try_reserve_exact(expected * 8).map_err(cannot)?;
        halfs.extend(texels.iter().flat_map(|&v| crate::util::f32_to_f16(v).to_le_bytes()));
        drop(texels);
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.heights,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &halfs,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.width * 8), rows_per_image: None },
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
        );
        Ok(())
    }
}

impl HeightMaps {
    /// Writes the cone ratios of `cones` (built for this map's depths,
    /// [`pomkit_core::cone::ConeMap`]) for the height passes to put into the pyramid's level 0
    /// (green), where the library's `cone` technique steps on them; `None` removes them (then
    /// `cone` walks as `exact` does). They stay until replaced: remove them when the heights
    /// change. Run [`HeightPasses::encode`] afterwards. Relaxed cones ([`ConeMap::relaxed`],
    /// a map read from `pomkit bake cone --relaxed`) are stored negated, and the library then
    /// walks them as relaxed cone stepping: a look after each cone step, then the
    /// `binary_steps` halvings.
    ///
    /// [`ConeMap::relaxed`]: pomkit_core::cone::ConeMap::relaxed
    ///
    /// The cones hold for the depths they were built from; the GPU samples them rounded to
    /// f16, so the library lowers each top by `POMKIT_CONE_TOP_MARGIN` (three times that
    /// rounding) before stepping: the cones then hold for the surface it samples.
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] if the cones are not this map's size.
    pub fn write_cones(&self, queue: &wgpu::Queue, cones: Option<&pomkit_core::cone::ConeMap>) -> Result<(), GpuError> {
        if let Some(c) = cones
            && c.size() != (self.width, self.height)
        {
            return Err(GpuError::Unsupported(format!(
                "writing {}x{} cones into a {}x{} height map's pyramid",
                c.size().0,
                c.size().1,
                self.width,
                self.height
            )));
        }
        let mut bytes = Vec::with_capacity(self.width as usize * self.height as usize * 4);
        for y in 0..self.height {
            for x in 0..self.width {
                let ratio = cones.map_or(0.0, |c| crate::library::cone_green(c, x, y));
                bytes.extend_from_slice(&ratio.to_le_bytes());
            }
        }
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.cones,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &bytes,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.width * 4), rows_per_image: None },
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
        );
        Ok(())
    }
}

/// Options of [`HeightPasses::encode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightPassOptions {
    /// Neighbours of border texels for the normals and the pyramid: wrap for tiling textures
    /// (the default), clamp otherwise. Must match the sampler the tracer uses, or border cells
    /// of the pyramid bound the wrong surface.
    pub edges: EdgeMode,
    /// How far, in UV units, the deepest point lies below the surface (ARCHITECTURE.md, Conventions; default
    /// 0.1). The normals are baked at Lengyel's scale `depth_scale * width` texel widths, so they
    /// match the displaced geometry; the parallax value (G) depends on it through `n_z`.
    /// Non-finite or non-positive values are replaced by 0.1, as `TraceParams::sanitized` does.
    pub depth_scale: f32,
    /// Slope filter of the normal map (not of the parallax value, which always uses central
    /// differences, as `Surface::new`). Central (the default) is sharpest; Sobel costs 8 texel
    /// reads instead of 4 and blurs detail finer than 2 texels, which hides noise in the input.
    pub filter: NormalFilter,
    /// Also build the conservative cone ratios of the new depths on the GPU (stage 4 of
    /// [`HeightPasses::encode`]) and put them into the pyramid's level 0, for the library's
    /// `cone` technique. Off by default: cones cost far more than the other passes (a search
    /// per texel, `pomkit_core::cone`), and only `cone` reads them. With it off, the cones last
    /// written ([`HeightMaps::write_cones`] or an earlier build) stay. The build is one
    /// dispatch of a search per texel: for large maps on a driver with a watchdog (Windows
    /// stops a GPU job after about 2 s) build them on the CPU instead
    /// (`pomkit_core::cone::ConeMap::conservative`, then [`HeightMaps::write_cones`]).
    pub build_cones: bool,
}

impl Default for HeightPassOptions {
    fn default() -> Self {
        Self {
            edges: EdgeMode::Wrap,
            depth_scale: DEFAULT_DEPTH_SCALE,
            filter: NormalFilter::Central,
            build_cones: false,
        }
    }
}

/// One slot of a bind group layout.
#[derive(Clone, Copy)]
enum Slot {
    /// `texture_2d<f32>` read with `textureLoad` (unfilterable, so `R32Float` fits too).
    Texture,
    /// `texture_storage_2d<format, write>`.
    Storage(wgpu::TextureFormat),
    /// `var<uniform> Params`.
    Params,
}

/// The storage slot of the `cones` texture.
const R32: Slot = Slot::Storage(wgpu::TextureFormat::R32Float);

/// One compute entry point of `height.wgsl` with its bind group layout.
#[derive(Debug)]
struct Stage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl Stage {
    fn new(device: &wgpu::Device, module: &wgpu::ShaderModule, entry: &str, slots: &[Slot]) -> Self {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = slots
            .iter()
            .enumerate()
            .map(|(i, slot)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: match *slot {
                    Slot::Texture => wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    Slot::Storage(format) => wgpu::BindingType::StorageTexture {
                        access: wgpu::StorageTextureAccess::WriteOnly,
                        format,
                        view_dimension: wgpu::TextureViewDimension::D2,
                    },
                    Slot::Params => wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(PARAMS_SIZE),
                    },
                },
                count: None,
            })
            .collect();
        let layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(entry), entries: &entries });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(entry),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }

    fn bind(&self, device: &wgpu::Device, resources: &[wgpu::BindingResource<'_>]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| wgpu::BindGroupEntry { binding: i as u32, resource: r.clone() })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: None, layout: &self.layout, entries: &entries })
    }
}

/// The compute pipelines that rebuild a [`HeightMaps`] from its depths. Create once per device.
#[derive(Debug)]
pub struct HeightPasses {
    normals: Stage,
    resolve: Stage,
    downsample: Stage,
    pyramid_base: Stage,
    pyramid_reduce: Stage,
    cones: Stage,
}

impl HeightPasses {
    /// Compiles `height.wgsl` and builds its five pipelines.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("height.wgsl"),
            source: wgpu::ShaderSource::Wgsl(crate::library::HEIGHT_WGSL.into()),
        });
        let rgba16 = Slot::Storage(wgpu::TextureFormat::Rgba16Float);
        let r32 = Slot::Storage(wgpu::TextureFormat::Rg32Float);
        Self {
            normals: Stage::new(device, &module, "normals_main", &[Slot::Texture, rgba16, rgba16, Slot::Params]),
            resolve: Stage::new(device, &module, "resolve_main", &[Slot::Texture, rgba16]),
            downsample: Stage::new(device, &module, "downsample_main", &[Slot::Texture, rgba16]),
            pyramid_base: Stage::new(
                device,
                &module,
                "pyramid_base_main",
                &[Slot::Texture, r32, Slot::Params, Slot::Texture],
            ),
            pyramid_reduce: Stage::new(device, &module, "pyramid_reduce_main", &[Slot::Texture, r32, Slot::Params]),
            cones: Stage::new(device, &module, "cone_main", &[Slot::Texture, Slot::Texture, R32, Slot::Params]),
        }
    }

    /// Records the rebuild of everything in `maps` derived from `heights` mip 0's R channel, as
    /// one compute pass (`timestamps`, if given, are written at its beginning and end):
    ///
    /// 1. normals (filter `opts.filter`, scale `depth_scale * width`, `opts.edges`, +Y up) into
    ///    `normals`, and the parallax value `clamp(n_z * d, 0, 1)` from central normals into
    ///    `heights` mip 0's G (fields under 2 texels on a side: normal +Z, parallax value d);
    /// 2. every coarser mip of `heights` (R and G), the exact box filter of the one above;
    /// 3. pyramid level 0 (least depth of the bilinear surface over each texel's footprint),
    ///    then each coarser level (least of its up to four children);
    /// 4. with `opts.build_cones`, the conservative cone ratio of every footprint (a branch and
    ///    bound over the pyramid, as `pomkit_core::cone::ConeMap::conservative`), then level 0
    ///    again to take them in.
    ///
    /// Cost: about 17 texel reads and 5 writes per texel of the field (8 more reads with Sobel
    /// normals), in `1 + height_levels + pyramid_levels` dispatches; a small uniform buffer and
    /// one bind group per dispatch are created per call. Stage 4 costs a search per texel
    /// instead, hundreds of texel reads (about 7 s for 256x256 on lavapipe, docs/BENCHMARKS.md).
    /// With `opts.build_cones` false the cones last written stay.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        maps: &HeightMaps,
        opts: &HeightPassOptions,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let size = (maps.width, maps.height);
        let edges = crate::library::edges_index(opts.edges);
        let filter = match opts.filter {
            NormalFilter::Central => 0,
            NormalFilter::Sobel => 1,
        };
        let depth_scale =
            if opts.depth_scale.is_finite() && opts.depth_scale > 0.0 { opts.depth_scale } else { DEFAULT_DEPTH_SCALE };
        let scale = depth_scale * maps.width as f32;

        // One Params record per dispatch that reads one: the normals, then each pyramid level.
        let stride = PARAMS_SIZE.next_multiple_of(u64::from(device.limits().min_uniform_buffer_offset_alignment));
        let mut records = Vec::new();
        let mut push = |src: (u32, u32), dst: (u32, u32)| -> u64 {
            let offset = records.len() as u64;
            let mut p = Std140::new();
            p.u(src.0).u(src.1).u(dst.0).u(dst.1).u(edges).u(filter).f(scale).u(maps.pyramid_levels);
            records.extend(p.bytes());
            records.resize((offset + stride) as usize, 0);
            offset
        };
        let normals_params = push(size, size);
        let pyramid_params: Vec<u64> = (0..maps.pyramid_levels)
            .map(|l| {
                let src = if l == 0 { size } else { maps.pyramid_level_size(l - 1) };
                push(src, maps.pyramid_level_size(l))
            })
            .collect();
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit height pass params"),
            contents: &records,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let record = |offset: u64| {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &params,
                offset,
                size: wgpu::BufferSize::new(PARAMS_SIZE),
            })
        };
        let view = wgpu::BindingResource::TextureView;

        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("pomkit height passes"),
            timestamp_writes: timestamps,
        });
        let mut dispatch = |stage: &Stage, resources: &[wgpu::BindingResource<'_>], (w, h): (u32, u32)| {
            let group = stage.bind(device, resources);
            pass.set_pipeline(&stage.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(w.div_ceil(WORKGROUP), h.div_ceil(WORKGROUP), 1);
        };

        // 1. Normals and parallax values, via the scratch texture back into mip 0.
        let mip0 = &maps.height_levels[0];
        dispatch(
            &self.normals,
            &[view(mip0), view(&maps.normals_view), view(&maps.scratch_view), record(normals_params)],
            size,
        );
        dispatch(&self.resolve, &[view(&maps.scratch_view), view(mip0)], size);

        // 2. The mip chain, each level from the one above.
        for (k, pair) in maps.height_levels.windows(2).enumerate() {
            let k = k as u32 + 1;
            let dst = ((maps.width >> k).max(1), (maps.height >> k).max(1));
            dispatch(&self.downsample, &[view(&pair[0]), view(&pair[1])], dst);
        }

        // 3. The pyramid: level 0 from the depths, then each level from the one below it.
        for (l, &offset) in pyramid_params.iter().enumerate() {
            let dst = &maps.pyramid_level_views[l];
            let size = maps.pyramid_level_size(l as u32);
            if l == 0 {
                dispatch(&self.pyramid_base, &[view(mip0), view(dst), record(offset), view(&maps.cones_view)], size);
            } else {
                dispatch(
                    &self.pyramid_reduce,
                    &[view(&maps.pyramid_level_views[l - 1]), view(dst), record(offset)],
                    size,
                );
            }
        }

        // 4. Cones from the finished pyramid, then level 0 again to copy them into its green.
        if opts.build_cones {
            let base = &maps.pyramid_level_views[0];
            dispatch(
                &self.cones,
                &[view(mip0), view(&maps.pyramid_view), view(&maps.cones_view), record(normals_params)],
                size,
            );
            dispatch(
                &self.pyramid_base,
                &[view(mip0), view(base), record(pyramid_params[0]), view(&maps.cones_view)],
                size,
            );
        }
    }
}
