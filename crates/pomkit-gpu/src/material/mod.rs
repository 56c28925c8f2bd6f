//! A pomkit material on the GPU, and the pipelines that draw it.
//!
//! This is the part a wgpu program uses in its own render pass: [`MaterialPipelines`] owns the
//! shader (`render.wgsl`) and one pipeline per technique and target layout; a [`GpuMaterial`]
//! holds a material's textures, uniforms and bind group; a [`GpuMesh`] its vertex buffers; and
//! [`FrameUniforms`] the camera and lights. `examples/wgpu_material.rs` shows the whole flow.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Mat3, Mat4, Vec3};
use pomkit_core::HeightField;
use pomkit_core::bake::NormalFilter;
use pomkit_core::mesh::Mesh;
use pomkit_core::scene::{Camera, Light, Material, NormalMap, Texture};
use pomkit_core::trace::Technique;
use wgpu::util::DeviceExt;

use crate::height::{HeightMaps, HeightPassOptions, HeightPasses};
use crate::host::HeightResource;
use crate::util::{Std140, rgba16f_bytes, texture_entry, trilinear_sampler};
use crate::{GpuContext, GpuError};

pub use crate::library::technique_index;
use crate::library::{ParamError, PomkitParams};
use crate::pipeline::{PipelineError, PipelineOptions};
use crate::planes::PlaneBounds;

mod frame;
mod objects;
mod pipelines;

pub use frame::{FrameUniforms, FrameView, frame_layout};
pub use objects::{GpuMesh, GpuObject};
use pipelines::*;
pub use pipelines::{AOV_FORMATS, MaterialPipelines, RENDER_WGSL, Targets, Variant};

/// Lights the shader reads per frame.
pub const MAX_LIGHTS: usize = 4;
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
    /// The plane bounds `exact` walks on (chosen per height map: where they read fewer
    /// fetches, `pomkit_core::trace::cached_plane_bounds`), while `plane_bounds_on` holds.
    planes: Option<PlaneBounds>,
    /// Cleared when the heights may have changed since the bounds were built: by
    /// [`GpuMaterial::update_height`], and by every [`GpuMaterial::encode_rebuild`] after the
    /// first (a compute shader of the caller's may have written the heights).
    plane_bounds_on: std::sync::atomic::AtomicBool,
    /// Whether [`GpuMaterial::encode_rebuild`] ran before.
    rebuilt: std::sync::atomic::AtomicBool,
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
        let depth_scale = pomkit_core::trace::sanitized_depth_scale(material.depth_scale);
        let height_options =
            HeightPassOptions { edges: material.edges, depth_scale, filter: normal_filter, build_cones: false };
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
        let planes = match &material.height {
            Some(field) if technique == Technique::Exact => plane_bounds(ctx, field, material, depth_scale)?,
            _ => None,
        };
        let explicit_normals = material.normal_map.as_ref().map(|n| upload_normal_map(ctx, n)).transpose()?;
        let albedo = {
            let base = material.albedo.as_ref().map_or_else(|| Texture::constant(Vec3::ONE), |t| (**t).clone());
            let limit = ctx.device.limits().max_texture_dimension_2d;
            if base.width() > limit || base.height() > limit {
                return Err(GpuError::TooLarge {
                    what: format!("material \"{}\" albedo", material.name),
                    width: base.width(),
                    height: base.height(),
                    limit,
                });
            }
            base.mip_chain()
        };
        let albedo_tex =
            texture_with_mips(ctx, "pomkit albedo", wgpu::TextureFormat::Rgba16Float, &rgba_levels(&albedo));
        let sampler = trilinear_sampler(&ctx.device, material.edges, "pomkit material");
        let field = material.height.as_deref();
        let has_normals = explicit_normals.is_some() || field.is_some_and(|f| f.width() >= 2 && f.height() >= 2);
        let params = PomkitParams::from_material(material, technique);
        let albedo_size = (albedo[0].width(), albedo[0].height(), albedo.len() as u32);
        let flags = Flags { has_height: field.is_some(), has_normals, plane_bounds: planes.is_some() };
        let u = material_block(&params, material, flags, albedo_size);
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
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: wgpu::BindingResource::TextureView(planes.as_ref().map_or(&d.planes, |p| &p.view)),
                },
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
            plane_bounds_on: planes.is_some().into(),
            planes,
            rebuilt: false.into(),
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
        if material.edges != height.edges() {
            return Err(GpuError::Unsupported(format!(
                "material \"{}\" traces with {:?} edges but height map \"{}\" was built with {:?} edges: build \
                 them with the same edge mode",
                material.name,
                material.edges,
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
        let flags = Flags { has_height: true, has_normals, plane_bounds: false };
        let u = material_block(&params, material, flags, albedo_size);
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
                wgpu::BindGroupEntry {
                    binding: 6,
                    resource: wgpu::BindingResource::TextureView(&pipelines.dummy.planes),
                },
            ],
        });
        Ok(Self {
            technique,
            pixel_depth_offset: material.pixel_depth_offset,
            silhouette: material.silhouette && technique.displaces(),
            height: None,
            height_options: height.options().pass_options(),
            cones_stale: false.into(),
            planes: None,
            plane_bounds_on: false.into(),
            rebuilt: false.into(),
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
        if params.edges != self.params.edges {
            return Err(ParamError::EdgesChanged);
        }
        ctx.queue.write_buffer(&self.uniforms, 0, &params.to_bytes());
        self.params = *params;
        if params.technique == Technique::Cone && self.technique != Technique::Cone {
            // Built on the GPU by the next rebuild (until then `cone` walks as `exact`).
            self.cones_stale.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        self.technique = params.technique;
        self.height_options.depth_scale = pomkit_core::trace::sanitized_depth_scale(params.depth_scale);
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
            if self.rebuilt.swap(true, std::sync::atomic::Ordering::Relaxed) {
                // The heights may have changed since the plane bounds were built.
                self.turn_off_plane_bounds(encoder);
            }
            let build_cones = self.cones_stale.swap(false, std::sync::atomic::Ordering::Relaxed);
            let opts = HeightPassOptions { build_cones, ..self.height_options };
            pipelines.passes.encode(device, encoder, maps, &opts, timestamps);
        }
    }

    /// Whether `exact` walks on plane bounds: chosen when the material was made (`exact`, a
    /// height map of its own, and bounds that read fewer fetches on it), and turned off for good
    /// once the heights may change ([`GpuMaterial::update_height`], a second
    /// [`GpuMaterial::encode_rebuild`]). The hits are the same either way.
    #[must_use]
    pub fn walks_on_plane_bounds(&self) -> bool {
        self.planes.is_some() && self.plane_bounds_on.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Zeroes the uniform's `plane_bounds` flag (a buffer clear recorded in `encoder`, before
    /// any pass of it that draws).
    fn turn_off_plane_bounds(&self, encoder: &mut wgpu::CommandEncoder) {
        if self.plane_bounds_on.swap(false, std::sync::atomic::Ordering::Relaxed) {
            encoder.clear_buffer(&self.uniforms, plane_bounds_offset(), Some(4));
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
        // The plane bounds described the old heights: `exact` walks on the least depths.
        if self.plane_bounds_on.swap(false, std::sync::atomic::Ordering::Relaxed) {
            ctx.queue.write_buffer(&self.uniforms, plane_bounds_offset(), &0u32.to_le_bytes());
        }
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
/// The material block's flags.
#[derive(Clone, Copy)]
struct Flags {
    has_height: bool,
    has_normals: bool,
    plane_bounds: bool,
}

fn material_block(
    params: &PomkitParams,
    material: &Material,
    Flags { has_height, has_normals, plane_bounds }: Flags,
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
    u.named("plane_bounds", 4).u(u32::from(plane_bounds));
    u
}

/// The byte offset of the `plane_bounds` flag in the material block.
fn plane_bounds_offset() -> u64 {
    material_layout().iter().find(|(name, _)| *name == "plane_bounds").map_or(0, |&(_, offset)| offset as u64)
}

/// The plane bounds `exact` walks on for `field`, if they read fewer fetches there
/// ([`pomkit_core::trace::cached_plane_bounds`], the choice the CPU renderer makes): built for
/// the f16-rounded depths the GPU samples, once per height field and edge mode while the field
/// lives (a viewer makes a new material at every edit), and uploaded.
fn plane_bounds(
    ctx: &GpuContext,
    field: &Arc<HeightField>,
    material: &Material,
    depth_scale: f32,
) -> Result<Option<PlaneBounds>, GpuError> {
    use std::sync::{Mutex, Weak};
    type Entry = (Weak<HeightField>, pomkit_core::EdgeMode, Arc<Vec<Vec<[u32; 4]>>>);
    static CACHE: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
    let edges = material.edges;
    if pomkit_core::trace::cached_plane_bounds(field, edges, depth_scale).is_none() {
        return Ok(None);
    }
    let lock = || CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let find = |cache: &mut Vec<Entry>| {
        cache.retain(|(f, ..)| f.strong_count() > 0);
        cache.iter().find(|(f, e, _)| *e == edges && f.as_ptr() == Arc::as_ptr(field)).map(|(.., t)| Arc::clone(t))
    };
    // (Its own statement: the guard of a `match` scrutinee would live through the arms, where
    // `lock` is taken again.)
    let found = find(&mut lock());
    let texels = match found {
        Some(t) => t,
        None => {
            // Built outside the lock: two threads may both build them, never wait on each other.
            let mut surface = pomkit_core::trace::Surface::new(crate::height::f16_surface(field), edges, depth_scale);
            surface.use_plane_bounds();
            let t = Arc::new(PlaneBounds::texels(&surface, &material.name)?);
            lock().push((Arc::downgrade(field), edges, Arc::clone(&t)));
            t
        }
    };
    PlaneBounds::from_texels(&ctx.device, &ctx.queue, (field.width(), field.height()), &texels, &material.name)
        .map(Some)
}

/// Each member's name and byte offset in `render.wgsl`'s `Material` uniform as pomkit writes
/// it (a test checks them against the WGSL struct).
#[must_use]
pub fn material_layout() -> Vec<(&'static str, usize)> {
    let params = PomkitParams::from_material(&Material::default(), Technique::Pom);
    let flags = Flags { has_height: true, has_normals: true, plane_bounds: true };
    material_block(&params, &Material::default(), flags, (1, 1, 1)).layout()
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
