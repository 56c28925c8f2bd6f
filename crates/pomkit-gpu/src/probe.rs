//! The shader library ray by ray: `pomkit_trace` and `pomkit_shadow` run in a compute shader
//! over a batch of rays, with the results read back as pomkit-core's [`Hit`] and [`Shadow`].
//!
//! This is what `tests/library_rays.rs` compares with `pomkit_core::trace::trace` and
//! `pomkit_core::shadow::shadow` (docs/GPU.md, "The shader library against pomkit-core, ray by
//! ray"), and what a tool measuring the GPU's accuracy or cost per ray can call. Rays use
//! pomkit-core's conventions ([`Ray`]: directions in ray terms (u, v, depth), `dz < 0`
//! entering); the shader (`probe.wgsl`) turns each direction into tangent space and sets it up
//! with the library's own `pomkit_view_ray` / `pomkit_light_ray` at UV scale 1, so those are
//! exercised as a host shader would use them. The technique and the shadow mode are read from
//! the parameters at run time (`params.technique`, `params.shadow_mode`).
//!
//! ```no_run
//! use glam::{Vec2, Vec3};
//! use pomkit_core::EdgeMode;
//! use pomkit_core::trace::{Ray, Technique, TraceParams};
//! use pomkit_core::shadow::ShadowParams;
//! use pomkit_gpu::GpuContext;
//! use pomkit_gpu::height::{HeightMaps, HeightPassOptions, HeightPasses};
//! use pomkit_gpu::library::PomkitParams;
//! use pomkit_gpu::probe::{ProbeRay, RayProbe};
//!
//! let ctx = GpuContext::new()?;
//! let maps = HeightMaps::new(&ctx, 64, 64, "probe")?;
//! maps.upload_depths(&ctx, &vec![0.5; 64 * 64])?;
//! let mut encoder = ctx.device.create_command_encoder(&Default::default());
//! HeightPasses::new(&ctx.device).encode(&ctx.device, &mut encoder, &maps, &HeightPassOptions::default(), None);
//! ctx.queue.submit([encoder.finish()]);
//!
//! let probe = RayProbe::new(&ctx.device)?;
//! // The depth scale and edges the maps were built with (HeightPassOptions::default()).
//! let (trace, shadow) = (TraceParams::default(), ShadowParams::default());
//! let params = PomkitParams::new(Technique::Pom, shadow, trace, 0.1, EdgeMode::Wrap, f32::MAX)
//!     .expect("valid parameters");
//! let ray = Ray::new(Vec2::new(0.25, 0.5), Vec3::new(0.5, 0.0, -0.8));
//! let hits = probe.trace(&ctx, &maps, &params, &[ProbeRay::new(&ray, 0.0)])?;
//! println!("hit at {} depth {} after {} fetches", hits[0].uv, hits[0].depth, hits[0].fetches);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use glam::{Vec2, Vec3};
use pomkit_core::EdgeMode;
use pomkit_core::shadow::Shadow;
use pomkit_core::trace::{Hit, Ray};
use wgpu::util::DeviceExt;

use crate::height::HeightMaps;
use crate::library::PomkitParams;
use crate::planes::PlaneBounds;
use crate::util::{texture_entry, trilinear_sampler};
use crate::{GpuContext, GpuError};

/// Bytes of one `ProbeIn` record of `probe.wgsl` (two vec4).
const IN_SIZE: u64 = 32;
/// Bytes of one `ProbeOut` record (vec2, f32, u32).
const OUT_SIZE: u64 = 16;
/// Invocations per workgroup in `probe.wgsl`.
const WORKGROUP: u32 = 64;
/// Most rays per dispatch (each dispatch is submitted and waited for on its own, so one call
/// never holds a GPU busy for long).
const BATCH: usize = 1 << 16;

/// One view ray for [`RayProbe::trace`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeRay {
    /// Entry point in UV (any tile).
    pub uv: Vec2,
    /// Direction in ray terms (u, v, depth), as [`Ray::dir`]: `z < 0` enters the surface. Any
    /// finite length; zero does not enter.
    pub dir: Vec3,
    /// Mip level the marching techniques read (`exact` reads mip 0).
    pub lod: f32,
}

impl ProbeRay {
    /// `ray` traced at mip level `lod`.
    #[must_use]
    pub fn new(ray: &Ray, lod: f32) -> Self {
        Self { uv: ray.uv, dir: ray.dir, lod }
    }
}

/// One shadow query for [`RayProbe::shadow`]: the arguments of `pomkit_core::shadow::shadow`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowQuery {
    /// The traced point's UV.
    pub uv: Vec2,
    /// Its depth in [0, 1].
    pub depth: f32,
    /// Direction toward the light in ray terms (u, v, depth), `z > 0` above the surface; any
    /// length as for [`ProbeRay::dir`].
    pub light: Vec3,
    /// Mip level the hard and soft shadows read.
    pub lod: f32,
}

/// Why a batch could not be probed.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    /// A ray or query holds a NaN or infinite number. The library's functions expect finite
    /// input (a host shader's interpolated values are), so the probe refuses it rather than
    /// report what the GPU makes of it.
    #[error("{what} {index}: {field} is {value}: it must be finite")]
    NotFinite {
        /// `ray` or `shadow query`.
        what: &'static str,
        /// Its index in the batch.
        index: usize,
        /// `uv`, `dir`, `light`, `depth` or `lod`.
        field: &'static str,
        /// The value, formatted.
        value: String,
    },
    /// The shader did not compile, or the device failed or was lost.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// The compute pipelines running `pomkit_trace` and `pomkit_shadow` per ray. Create once per
/// device; each call uploads its batch, dispatches and reads the results back (waiting for the
/// GPU), so it suits measuring, not rendering.
#[derive(Debug)]
pub struct RayProbe {
    layout: wgpu::BindGroupLayout,
    trace: wgpu::ComputePipeline,
    curved: wgpu::ComputePipeline,
    shadow: wgpu::ComputePipeline,
    exact: wgpu::ComputePipeline,
    planes: wgpu::ComputePipeline,
    no_planes: PlaneBounds,
    repeat: wgpu::Sampler,
    clamp: wgpu::Sampler,
}

impl RayProbe {
    /// The probe over the library as shipped ([`crate::library::WGSL`]).
    ///
    /// # Errors
    /// [`GpuError::Device`] if the device rejects the shader or a pipeline.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Self::with_library(device, crate::library::WGSL)
    }

    /// The probe over another plain-WGSL form of the library (`library_wgsl` in place of
    /// [`crate::library::WGSL`]): a library flattened from edited WESL modules, to see how an
    /// edit changes the rays.
    ///
    /// # Errors
    /// [`GpuError::Device`] if the device rejects the shader (say, `library_wgsl` lacks a
    /// function `probe.wgsl` calls) or a pipeline.
    pub fn with_library(device: &wgpu::Device, library_wgsl: &str) -> Result<Self, GpuError> {
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = Self::build(device, library_wgsl);
        if let Some(e) = pollster::block_on(validation.pop()) {
            return Err(GpuError::Device(format!("the ray probe's shader or pipelines: {e}")));
        }
        Ok(result)
    }

    fn build(device: &wgpu::Device, library_wgsl: &str) -> Self {
        let source = crate::library::compose_with(library_wgsl, include_str!("probe.wgsl"));
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("pomkit ray probe"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let texture = |binding, filterable| texture_entry(binding, filterable, wgpu::ShaderStages::COMPUTE);
        let buffer = |binding: u32, ty: wgpu::BufferBindingType, size: u64| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: wgpu::BufferSize::new(size),
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("pomkit ray probe"),
            entries: &[
                texture(0, true),
                texture(1, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                buffer(3, wgpu::BufferBindingType::Uniform, PomkitParams::SIZE),
                buffer(4, wgpu::BufferBindingType::Storage { read_only: true }, IN_SIZE),
                buffer(5, wgpu::BufferBindingType::Storage { read_only: false }, OUT_SIZE),
                wgpu::BindGroupLayoutEntry {
                    binding: 6,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("pomkit ray probe"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        Self {
            trace: pipeline("trace_main"),
            curved: pipeline("curved_main"),
            shadow: pipeline("shadow_main"),
            exact: pipeline("exact_main"),
            planes: pipeline("planes_main"),
            no_planes: PlaneBounds::empty(device),
            layout,
            // Trilinear, as the material's sampler.
            repeat: trilinear_sampler(device, EdgeMode::Wrap, "pomkit ray probe"),
            clamp: trilinear_sampler(device, EdgeMode::Clamp, "pomkit ray probe"),
        }
    }

    /// Traces every ray with `pomkit_trace(params.technique, ...)` on the surface of `maps`: one
    /// [`Hit`] per ray, in order (hit UV in the ray's own tile frame, depth, fetches as the
    /// library counts them).
    ///
    /// `maps` must have been built ([`crate::height::HeightPasses::encode`]) with the edge mode
    /// and depth scale of `params` (the pyramid and the parallax map depend on them); the
    /// sampler's address mode is taken from `params.edges`.
    ///
    /// # Errors
    /// [`ProbeError::NotFinite`] naming the first ray with a NaN or infinite number;
    /// [`ProbeError::Gpu`] if the device fails.
    pub fn trace(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        params: &PomkitParams,
        rays: &[ProbeRay],
    ) -> Result<Vec<Hit>, ProbeError> {
        let records =
            rays.iter().enumerate().map(|(index, r)| ray_record(index, r, 0.0)).collect::<Result<Vec<_>, _>>()?;
        let out = self.run(ctx, maps, None, params, &self.trace, &records)?;
        Ok(out.into_iter().map(|(uv, depth, fetches)| Hit { uv, depth, fetches }).collect())
    }

    /// Traces every ray with `exact`: with `planes`, by `pomkit_trace_planes` (the walk on plane
    /// bounds per cell), else by `pomkit_trace_exact` (the least-depth walk), each called
    /// directly rather than through `pomkit_trace`'s dispatch, so that timing one against the
    /// other times the walks alone. Otherwise as [`RayProbe::trace`].
    ///
    /// # Errors
    /// As [`RayProbe::trace`].
    pub fn trace_exact(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        planes: Option<&PlaneBounds>,
        params: &PomkitParams,
        rays: &[ProbeRay],
    ) -> Result<Vec<Hit>, ProbeError> {
        let records =
            rays.iter().enumerate().map(|(index, r)| ray_record(index, r, 0.0)).collect::<Result<Vec<_>, _>>()?;
        let pipeline = if planes.is_some() { &self.planes } else { &self.exact };
        let out = self.run(ctx, maps, planes, params, pipeline, &records)?;
        Ok(out.into_iter().map(|(uv, depth, fetches)| Hit { uv, depth, fetches }).collect())
    }

    /// Traces every ray with `pomkit_trace_curved` under a surface of curvature `c` along it
    /// (the pair's second member; see `pomkit_core::silhouette::trace_curved`): per ray, the hit
    /// (depth below the curved surface) and whether the ray left the relief. `maps` as for
    /// [`RayProbe::trace`].
    ///
    /// # Errors
    /// As [`RayProbe::trace`], and for a NaN or infinite curvature.
    pub fn trace_curved(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        params: &PomkitParams,
        rays: &[(ProbeRay, f32)],
    ) -> Result<Vec<(Hit, bool)>, ProbeError> {
        let records = rays
            .iter()
            .enumerate()
            .map(|(index, (r, c))| {
                let record = ray_record(index, r, *c)?;
                if !c.is_finite() {
                    let value = format!("{c}");
                    return Err(ProbeError::NotFinite { what: "ray", index, field: "curvature", value });
                }
                Ok(record)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let out = self.run(ctx, maps, None, params, &self.curved, &records)?;
        Ok(out
            .into_iter()
            .map(|(uv, depth, fetches)| (Hit { uv, depth, fetches: fetches & 0x7fff_ffff }, fetches >> 31 == 1))
            .collect())
    }

    /// The light's visibility from every query point with `pomkit_shadow` in
    /// `params.shadow.mode`: one [`Shadow`] per query, in order. `maps` as for
    /// [`RayProbe::trace`].
    ///
    /// # Errors
    /// [`ProbeError::NotFinite`] naming the first query with a NaN or infinite number;
    /// [`ProbeError::Gpu`] if the device fails.
    pub fn shadow(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        params: &PomkitParams,
        queries: &[ShadowQuery],
    ) -> Result<Vec<Shadow>, ProbeError> {
        let mut records = Vec::with_capacity(queries.len());
        for (index, q) in queries.iter().enumerate() {
            let bad = |field: &'static str, value: String| ProbeError::NotFinite {
                what: "shadow query",
                index,
                field,
                value,
            };
            if !q.uv.is_finite() {
                return Err(bad("uv", format!("{}", q.uv)));
            }
            if !q.depth.is_finite() {
                return Err(bad("depth", format!("{}", q.depth)));
            }
            if !q.light.is_finite() {
                return Err(bad("light", format!("{}", q.light)));
            }
            if !q.lod.is_finite() {
                return Err(bad("lod", format!("{}", q.lod)));
            }
            records.push([q.uv.x, q.uv.y, q.lod, q.depth, q.light.x, q.light.y, q.light.z, 0.0]);
        }
        let out = self.run(ctx, maps, None, params, &self.shadow, &records)?;
        Ok(out.into_iter().map(|(_, visibility, fetches)| Shadow { visibility, fetches }).collect())
    }

    /// Runs `pipeline` over `records` in batches of [`BATCH`]: (uv, value, fetches) per record.
    fn run(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        planes: Option<&PlaneBounds>,
        params: &PomkitParams,
        pipeline: &wgpu::ComputePipeline,
        records: &[[f32; 8]],
    ) -> Result<Vec<(Vec2, f32, u32)>, GpuError> {
        let mut out = Vec::with_capacity(records.len());
        if records.is_empty() {
            return Ok(out);
        }
        let device = &ctx.device;
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = self.run_batches(ctx, maps, planes, params, pipeline, records, &mut out);
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(oom.pop())];
        if let Some(e) = errors.into_iter().flatten().next() {
            return Err(GpuError::Device(format!("the ray probe: {e}")));
        }
        result.map(|()| out)
    }

    #[expect(clippy::too_many_arguments, reason = "the surface's textures, the parameters, the pipeline and the rays")]
    fn run_batches(
        &self,
        ctx: &GpuContext,
        maps: &HeightMaps,
        planes: Option<&PlaneBounds>,
        params: &PomkitParams,
        pipeline: &wgpu::ComputePipeline,
        records: &[[f32; 8]],
        out: &mut Vec<(Vec2, f32, u32)>,
    ) -> Result<(), GpuError> {
        let device = &ctx.device;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pomkit ray probe params"),
            contents: &params.to_bytes(),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let sampler = match params.edges {
            EdgeMode::Wrap => &self.repeat,
            EdgeMode::Clamp => &self.clamp,
        };
        for batch in records.chunks(BATCH) {
            let bytes: Vec<u8> = batch.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
            let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("pomkit ray probe rays"),
                contents: &bytes,
                usage: wgpu::BufferUsages::STORAGE,
            });
            let size = batch.len() as u64 * OUT_SIZE;
            let output = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pomkit ray probe results"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let readback = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pomkit ray probe readback"),
                size,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("pomkit ray probe"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(&maps.heights_view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(&maps.pyramid_view),
                    },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(sampler) },
                    wgpu::BindGroupEntry { binding: 3, resource: uniform.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 4, resource: input.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 5, resource: output.as_entire_binding() },
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: wgpu::BindingResource::TextureView(&planes.unwrap_or(&self.no_planes).view),
                    },
                ],
            });
            let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("probe") });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("pomkit ray probe"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                // BATCH / WORKGROUP groups at most: far below the 65535 every device allows.
                pass.dispatch_workgroups((batch.len() as u32).div_ceil(WORKGROUP), 1, 1);
            }
            encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, size);
            ctx.queue.submit([encoder.finish()]);
            let data = ctx.read_buffer(&readback)?;
            out.extend(data.chunks_exact(OUT_SIZE as usize).map(|c| {
                let word = |k: usize| [c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]];
                (
                    Vec2::new(f32::from_le_bytes(word(0)), f32::from_le_bytes(word(1))),
                    f32::from_le_bytes(word(2)),
                    u32::from_le_bytes(word(3)),
                )
            }));
        }
        Ok(())
    }
}

/// Ray `index` as the probe's record (`uv`, `lod`, direction, and `extra` in the last slot),
/// after checking that it is finite.
fn ray_record(index: usize, r: &ProbeRay, extra: f32) -> Result<[f32; 8], ProbeError> {
    let bad = |field: &'static str, value: String| ProbeError::NotFinite { what: "ray", index, field, value };
    if !r.uv.is_finite() {
        return Err(bad("uv", format!("{}", r.uv)));
    }
    if !r.dir.is_finite() {
        return Err(bad("dir", format!("{}", r.dir)));
    }
    if !r.lod.is_finite() {
        return Err(bad("lod", format!("{}", r.lod)));
    }
    Ok([r.uv.x, r.uv.y, r.lod, 0.0, r.dir.x, r.dir.y, r.dir.z, extra])
}
