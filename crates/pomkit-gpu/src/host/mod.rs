//! pomkit's height-map textures for any wgpu program: from a texture the program already has,
//! or from a pomkit [`HeightField`].
//!
//! The shader library ([`crate::library`]) traces against two textures and a sampler: `heights`
//! (`Rgba16Float` with mips, R = depth, G = parallax value), read through a trilinear sampler
//! whose address mode matches the edge mode, and the maximum-height `pyramid` (`Rg32Float`, read
//! with `textureLoad`). A [`HeightResource`] owns them (a [`HeightMaps`]) and the sampler, and
//! builds them:
//!
//! - [`HeightResource::from_texture`]: from one channel of a texture of the host program's own
//!   (any 2D, single-sampled colour format whose samples are floats: `R8Unorm`, `Rgba8Unorm`,
//!   `R16Float`, `R32Float`, ...), checked before any wgpu call so that a texture pomkit cannot
//!   read gives a [`HostError`] naming it, never a wgpu validation panic. A compute pass
//!   (`import.wgsl`) converts the channel to pomkit's depth into `heights` mip 0; then
//!   [`HeightPasses::encode`] derives everything else. When the program changes the texture's
//!   texels, [`HeightResource::encode_rebuild`] records both again.
//! - [`HeightResource::from_field`]: from a [`HeightField`] (depths uploaded from the CPU);
//!   [`HeightResource::update_field`] replaces them.
//!
//! The host adds pomkit's textures to a bind group of its own with
//! [`HeightResource::layout_entries`] and [`HeightResource::bind_group_entries`].
//!
//! [`HeightPasses`] is per device: create one and pass it to every call; a resource keeps
//! nothing of it. A resource built from a texture owns the small import pipeline (compiled once,
//! when the resource is built) and a bind group holding a view of the host texture, which keeps
//! that texture alive.
//!
//! ```no_run
//! use pomkit_gpu::GpuContext;
//! use pomkit_gpu::height::HeightPasses;
//! use pomkit_gpu::host::{HeightBindings, HeightResource, HeightResourceOptions};
//!
//! let ctx = GpuContext::new()?; // or the program's own device and queue
//! let (device, queue) = (&ctx.device, &ctx.queue);
//! let passes = HeightPasses::new(device);
//! // A height map the program already has: white = high, in the red channel.
//! let texture = device.create_texture(&wgpu::TextureDescriptor {
//!     label: Some("rocks"),
//!     size: wgpu::Extent3d { width: 512, height: 512, depth_or_array_layers: 1 },
//!     mip_level_count: 1,
//!     sample_count: 1,
//!     dimension: wgpu::TextureDimension::D2,
//!     format: wgpu::TextureFormat::R8Unorm,
//!     usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
//!     view_formats: &[],
//! });
//! let opts = HeightResourceOptions::default();
//! let rocks = HeightResource::from_texture(device, queue, &passes, &texture, &opts, "rocks")?;
//!
//! // pomkit's three bindings in the program's own bind group (next to its own entries).
//! let bindings = HeightBindings { heights: 1, pyramid: 2, sampler: 3 };
//! let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
//!     label: Some("material"),
//!     entries: &HeightResource::layout_entries(bindings, wgpu::ShaderStages::FRAGMENT),
//! });
//! let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
//!     label: Some("material"),
//!     layout: &layout,
//!     entries: &rocks.bind_group_entries(bindings),
//! });
//!
//! // Whenever the program writes new texels into `texture`:
//! let mut encoder = device.create_command_encoder(&Default::default());
//! rocks.encode_rebuild(device, &passes, &mut encoder);
//! queue.submit([encoder.finish()]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use pomkit_core::bake::NormalFilter;
use pomkit_core::{EdgeMode, HeightField};
use wgpu::util::DeviceExt;

use crate::GpuError;
use crate::height::{HeightMaps, HeightPassOptions, HeightPasses};
use crate::util::{Std140, texture_entry, trilinear_sampler};

/// Side of the square compute workgroups in `import.wgsl`.
mod import;
use import::{Import, check_texture};

const WORKGROUP: u32 = 8;

/// Bytes of `import.wgsl`'s `Params`.
const IMPORT_PARAMS_SIZE: u64 = 16;

/// What the values of a host texture's channel mean.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum HeightEncoding {
    /// Heights: white (1) is high, black (0) deep, as art tools make height maps. The default.
    /// pomkit's depth is `d = 1 - value`.
    #[default]
    Height,
    /// Depths: white (1) is deep, black (0) the surface; pomkit's own convention
    /// (ARCHITECTURE.md, Conventions), `d = value`.
    Depth,
}

/// How a [`HeightResource`] reads its heights and builds its maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightResourceOptions {
    /// What the host texture's values mean ([`HeightResource::from_texture`] only; a
    /// [`HeightField`] already holds depths). Default [`HeightEncoding::Height`].
    pub encoding: HeightEncoding,
    /// Which channel of the host texture holds the heights: 0 = R, 1 = G, 2 = B, 3 = A (as
    /// WGSL's `textureLoad` returns them, so for `Bgra8Unorm` 0 is still red). It must exist in
    /// the texture's format. Default 0. [`HeightResource::from_texture`] only.
    pub channel: u32,
    /// Wrap for tiling height maps (the default), clamp otherwise: the neighbours of border
    /// texels for the normals and the pyramid, and the sampler's address mode (repeat or
    /// clamp-to-edge). The shader's `PomkitParams::edges` must match it.
    pub edges: EdgeMode,
    /// How far, in UV units, the deepest point lies below the surface (default 0.1): the scale
    /// of the normals and of the parallax value, as [`HeightPassOptions::depth_scale`] (which
    /// replaces a non-finite or non-positive value by 0.1). Use the value the shader traces with.
    pub depth_scale: f32,
    /// Slope filter of the normal map (default central differences), as
    /// [`HeightPassOptions::filter`].
    pub normal_filter: NormalFilter,
    /// Build the conservative cones of the heights on the GPU at every rebuild
    /// ([`HeightPassOptions::build_cones`]), for shaders that trace with the library's `cone`
    /// technique. Default false: the cones cost a search per texel, far more than the other
    /// passes; without them (or [`HeightResource::write_cones`]) `cone` walks as `exact` does.
    pub cones: bool,
}

impl Default for HeightResourceOptions {
    fn default() -> Self {
        Self {
            encoding: HeightEncoding::Height,
            channel: 0,
            edges: EdgeMode::Wrap,
            depth_scale: 0.1,
            normal_filter: NormalFilter::Central,
            cones: false,
        }
    }
}

impl HeightResourceOptions {
    /// The options of [`HeightPasses::encode`] these imply.
    #[must_use]
    pub fn pass_options(&self) -> HeightPassOptions {
        HeightPassOptions {
            edges: self.edges,
            depth_scale: self.depth_scale,
            filter: self.normal_filter,
            build_cones: self.cones,
        }
    }
}

/// Binding numbers of pomkit's three resources in a host's bind group (default 0, 1, 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct HeightBindings {
    /// `texture_2d<f32>`: [`HeightResource::heights_view`] (filterable float, all mips).
    pub heights: u32,
    /// `texture_2d<f32>`: [`HeightResource::pyramid_view`] (unfilterable float, read with
    /// `textureLoad`).
    pub pyramid: u32,
    /// `sampler` (filtering): [`HeightResource::sampler`].
    pub sampler: u32,
}

impl Default for HeightBindings {
    fn default() -> Self {
        Self { heights: 0, pyramid: 1, sampler: 2 }
    }
}

/// Why a [`HeightResource`] could not be built or updated. Every message names the texture or
/// resource by its label, says what is wrong and what to do.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HostError {
    /// [`HeightResource::from_texture`]: the texture's format has no float samples to read
    /// heights from: a depth or stencil format, an integer (`Uint`, `Sint`) format, or a
    /// multi-planar video format.
    #[error(
        "height texture \"{label}\" has format {format:?} ({why}), which pomkit cannot read heights from: use a colour \
         format whose samples are floats, such as R8Unorm, Rg8Unorm, Rgba8Unorm, Rgba8UnormSrgb, Bgra8Unorm, R16Float, \
         Rgba16Float, R32Float or Rgba32Float (copy or render the heights into one)"
    )]
    Format {
        /// The texture's label (as given to pomkit).
        label: String,
        /// Its format.
        format: wgpu::TextureFormat,
        /// What kind of format it is.
        why: &'static str,
    },
    /// [`HeightResource::from_texture`]: the texture was created without
    /// [`wgpu::TextureUsages::TEXTURE_BINDING`], which the import pass needs to read it.
    #[error(
        "height texture \"{label}\" was created with usage {usage:?}, without TEXTURE_BINDING: pomkit reads it in a \
         compute shader, so add wgpu::TextureUsages::TEXTURE_BINDING to its usage"
    )]
    Usage {
        /// The texture's label.
        label: String,
        /// Its usage.
        usage: wgpu::TextureUsages,
    },
    /// [`HeightResource::from_texture`]: the texture is 1D or 3D.
    #[error(
        "height texture \"{label}\" is a {dimension:?} texture: pomkit reads 2D textures (TextureDimension::D2); copy \
         the slice you want into a 2D texture"
    )]
    Dimension {
        /// The texture's label.
        label: String,
        /// Its dimension.
        dimension: wgpu::TextureDimension,
    },
    /// [`HeightResource::from_texture`]: the texture is a 2D array (or cube) texture of more
    /// than one layer.
    #[error(
        "height texture \"{label}\" has {layers} array layers: pomkit reads a single 2D texture \
         (depth_or_array_layers 1); copy the layer you want into one"
    )]
    Layers {
        /// The texture's label.
        label: String,
        /// Its `depth_or_array_layers`.
        layers: u32,
    },
    /// [`HeightResource::from_texture`]: the texture is multisampled.
    #[error(
        "height texture \"{label}\" is multisampled ({samples} samples per texel): pomkit reads single-sampled \
         textures; resolve it into a texture with sample_count 1"
    )]
    Samples {
        /// The texture's label.
        label: String,
        /// Its `sample_count`.
        samples: u32,
    },
    /// [`HeightResource::from_texture`]: [`HeightResourceOptions::channel`] is not a channel of
    /// the texture's format (or is above 3).
    #[error(
        "height texture \"{label}\": channel {channel} ({}) was asked for, but format {format:?} has {components} \
         channel(s), numbered from 0 (R): set HeightResourceOptions::channel to one of them",
        channel_name(*.channel)
    )]
    Channel {
        /// The texture's label.
        label: String,
        /// The channel asked for.
        channel: u32,
        /// The texture's format.
        format: wgpu::TextureFormat,
        /// How many channels the format has.
        components: u8,
    },
    /// A side of the texture is 0 (only an invalid texture has one).
    #[error("height texture \"{label}\" is {width}x{height} texels: both sides must be at least 1")]
    Empty {
        /// The texture's label.
        label: String,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// A side of the field, or of its maximum-height pyramid (each side padded up to a power of
    /// two), exceeds the device's `max_texture_dimension_2d`.
    #[error(
        "height map \"{label}\": {what} is {width}x{height} texels, more than this device's limit of {limit} per side: \
         use a smaller height map (pomkit's maximum-height pyramid pads each side up to a power of two, which must \
         fit too)"
    )]
    TooLarge {
        /// The texture's or field's label.
        label: String,
        /// Which texture is too large.
        what: String,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The device's `max_texture_dimension_2d`.
        limit: u32,
    },
    /// [`HeightResource::update_field`]: the new field's size differs from the resource's.
    #[error(
        "height resource \"{label}\" is {}x{} texels but the new field is {}x{}: a resource keeps its size, so build \
         a new one with HeightResource::from_field",
        .expected.0, .expected.1, .found.0, .found.1
    )]
    SizeMismatch {
        /// The resource's label.
        label: String,
        /// The resource's (width, height).
        expected: (u32, u32),
        /// The new field's (width, height).
        found: (u32, u32),
    },
    /// [`HeightResource::update_field`] on a resource built from a host texture, whose
    /// [`HeightResource::encode_rebuild`] would read the texture again.
    #[error(
        "height resource \"{label}\" was built from a host texture, so update_field cannot change it: write the new \
         heights into that texture and call encode_rebuild"
    )]
    NotFromField {
        /// The resource's label.
        label: String,
    },
    /// wgpu reported an error pomkit did not foresee while building the resource (caught by an
    /// error scope, so not a panic): for example a host texture that belongs to another device,
    /// or the GPU out of memory.
    #[error(
        "wgpu refused to build height resource \"{label}\" (is the texture from this device? is the GPU out of \
         memory?): {message}"
    )]
    Device {
        /// The texture's or field's label.
        label: String,
        /// wgpu's message.
        message: String,
    },
}

/// "R", "G", "B", "A" or "no such channel".
fn channel_name(channel: u32) -> &'static str {
    match channel {
        0 => "R",
        1 => "G",
        2 => "B",
        3 => "A",
        _ => "no such channel: channels are 0 to 3",
    }
}

/// pomkit's height-map textures for one height field, and the sampler to read them with: what
/// the shader library traces against. Built from a host texture
/// ([`HeightResource::from_texture`]) or a [`HeightField`] ([`HeightResource::from_field`]).
///
/// Every method that takes a device must be given the device the resource was built on.
#[derive(Debug)]
pub struct HeightResource {
    maps: HeightMaps,
    sampler: wgpu::Sampler,
    opts: HeightResourceOptions,
    import: Option<Import>,
    label: String,
}

impl HeightResource {
    /// Builds the maps of one channel of `texture` (a texture of the host program on `device`):
    /// checks the texture, allocates pomkit's textures at its size, and submits the import pass
    /// and the height passes to `queue` (without waiting).
    ///
    /// The texture must be 2D with one layer and one sample, have
    /// [`wgpu::TextureUsages::TEXTURE_BINDING`], and a colour format whose samples are floats
    /// (unorm, snorm, float, sRGB; filterable or not). Only mip 0 is read, with `textureLoad`:
    /// an sRGB format is decoded to linear values first (store height maps in a non-sRGB
    /// format). The channel's values are read as [`HeightResourceOptions::encoding`] says,
    /// clamped to `[0, 1]` (NaN becomes the deepest point) and rounded to the nearest f16 (steps
    /// of 2^-11 near 1), as [`HeightMaps::upload_depths`] does: the maps equal
    /// [`HeightResource::from_field`]'s for the same values, bit for bit on lavapipe
    /// (`tests/host.rs`).
    ///
    /// `label` names the texture in error messages and pomkit's textures.
    ///
    /// # Errors
    /// Before any wgpu call: [`HostError::Dimension`], [`HostError::Layers`],
    /// [`HostError::Samples`], [`HostError::Format`], [`HostError::Channel`],
    /// [`HostError::Usage`], [`HostError::Empty`] and [`HostError::TooLarge`], in that order of
    /// checking. [`HostError::Device`] if wgpu reports an error nonetheless (a texture of another
    /// device, out of memory).
    pub fn from_texture(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        passes: &HeightPasses,
        texture: &wgpu::Texture,
        opts: &HeightResourceOptions,
        label: &str,
    ) -> Result<Self, HostError> {
        check_texture(device, texture, opts.channel, label)?;
        let (width, height) = (texture.width(), texture.height());
        guarded(device, label, || {
            let maps = HeightMaps::with_device(device, width, height, label).map_err(|e| gpu_error(e, label))?;
            let sampler = trilinear_sampler(device, opts.edges, &format!("{label} heights"));
            let import = Import::new(device, texture, &maps, opts, label);
            let resource = Self { maps, sampler, opts: *opts, import: Some(import), label: label.to_owned() };
            resource.submit_rebuild(device, queue, passes);
            Ok(resource)
        })
    }

    /// Builds the maps of `field`: allocates pomkit's textures at its size, uploads its depths
    /// (rounded to f16) and submits the height passes to `queue` (without waiting).
    /// [`HeightResourceOptions::encoding`] and [`HeightResourceOptions::channel`] are not used:
    /// a field holds depths.
    ///
    /// # Errors
    /// [`HostError::TooLarge`] if the field or its padded pyramid exceeds the device's texture
    /// size limit (checked before any wgpu call); [`HostError::Device`] if wgpu reports an
    /// error nonetheless (out of memory).
    pub fn from_field(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        passes: &HeightPasses,
        field: &HeightField,
        opts: &HeightResourceOptions,
        label: &str,
    ) -> Result<Self, HostError> {
        let (width, height) = (field.width(), field.height());
        check_size(device, width, height, label)?;
        guarded(device, label, || {
            let maps = HeightMaps::with_device(device, width, height, label).map_err(|e| gpu_error(e, label))?;
            let sampler = trilinear_sampler(device, opts.edges, &format!("{label} heights"));
            let resource = Self { maps, sampler, opts: *opts, import: None, label: label.to_owned() };
            resource.maps.write_depths(queue, field.depths()).map_err(|e| gpu_error(e, label))?;
            resource.submit_rebuild(device, queue, passes);
            Ok(resource)
        })
    }

    /// Replaces the depths of a resource built by [`HeightResource::from_field`] with
    /// `field`'s (rounded to f16). Record [`HeightResource::encode_rebuild`] afterwards: until
    /// it runs, mips, parallax values, normals and pyramid still describe the old field.
    ///
    /// # Errors
    /// [`HostError::SizeMismatch`] if `field`'s size differs from the resource's;
    /// [`HostError::NotFromField`] for a resource built from a host texture (write that
    /// texture instead). Nothing is written then.
    pub fn update_field(&self, queue: &wgpu::Queue, field: &HeightField) -> Result<(), HostError> {
        if self.import.is_some() {
            return Err(HostError::NotFromField { label: self.label.clone() });
        }
        let (w, h) = (self.maps.width, self.maps.height);
        if (field.width(), field.height()) != (w, h) {
            return Err(HostError::SizeMismatch {
                label: self.label.clone(),
                expected: (w, h),
                found: (field.width(), field.height()),
            });
        }
        self.maps.write_depths(queue, field.depths()).map_err(|e| gpu_error(e, &self.label))
    }

    /// Records the rebuild of every map into `encoder`: for a resource built from a host
    /// texture, the import of its current texels (so write them, with `queue.write_texture` or
    /// a pass of your own, before this command buffer runs), then [`HeightPasses::encode`]
    /// (mips, parallax values, normals, pyramid). For heights that change at run time; call it
    /// after every change, with the device the resource was built on.
    ///
    /// Cost: the import reads and writes each texel once (one dispatch); the height passes
    /// as [`HeightPasses::encode`] says.
    pub fn encode_rebuild(&self, device: &wgpu::Device, passes: &HeightPasses, encoder: &mut wgpu::CommandEncoder) {
        if let Some(import) = &self.import {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("pomkit height import"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&import.pipeline);
            pass.set_bind_group(0, &import.group, &[]);
            pass.dispatch_workgroups(self.maps.width.div_ceil(WORKGROUP), self.maps.height.div_ceil(WORKGROUP), 1);
        }
        passes.encode(device, encoder, &self.maps, &self.opts.pass_options(), None);
    }

    /// The three bind group layout entries of pomkit's resources at `bindings`, visible to
    /// `visibility`: `heights` (filterable float 2D texture), `pyramid` (unfilterable float 2D
    /// texture) and a filtering sampler. Add them to the host's own layout entries;
    /// [`HeightResource::bind_group_entries`] gives the matching bind group entries.
    #[must_use]
    pub fn layout_entries(bindings: HeightBindings, visibility: wgpu::ShaderStages) -> [wgpu::BindGroupLayoutEntry; 3] {
        let texture = |binding, filterable| texture_entry(binding, filterable, visibility);
        [
            texture(bindings.heights, true),
            texture(bindings.pyramid, false),
            wgpu::BindGroupLayoutEntry {
                binding: bindings.sampler,
                visibility,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ]
    }

    /// The bind group entries matching [`HeightResource::layout_entries`] with the same
    /// `bindings`: [`HeightResource::heights_view`], [`HeightResource::pyramid_view`],
    /// [`HeightResource::sampler`].
    #[must_use]
    pub fn bind_group_entries(&self, bindings: HeightBindings) -> [wgpu::BindGroupEntry<'_>; 3] {
        [
            wgpu::BindGroupEntry {
                binding: bindings.heights,
                resource: wgpu::BindingResource::TextureView(&self.maps.heights_view),
            },
            wgpu::BindGroupEntry {
                binding: bindings.pyramid,
                resource: wgpu::BindingResource::TextureView(&self.maps.pyramid_view),
            },
            wgpu::BindGroupEntry { binding: bindings.sampler, resource: wgpu::BindingResource::Sampler(&self.sampler) },
        ]
    }

    /// All mips of `heights` (`Rgba16Float`, R = depth, G = parallax value): the library's
    /// `heights` texture.
    #[must_use]
    pub fn heights_view(&self) -> &wgpu::TextureView {
        &self.maps.heights_view
    }

    /// All mips of the maximum-height pyramid (`Rg32Float`, read with `textureLoad`): the
    /// library's `pyramid` texture.
    #[must_use]
    pub fn pyramid_view(&self) -> &wgpu::TextureView {
        &self.maps.pyramid_view
    }

    /// The normal map (`Rgba16Float`, xyz = unit normal, +Y up, pomkit tangent space), for
    /// shading.
    #[must_use]
    pub fn normals_view(&self) -> &wgpu::TextureView {
        &self.maps.normals_view
    }

    /// A trilinear sampler (linear min, mag and mipmap filters) addressing by
    /// [`HeightResourceOptions::edges`] (repeat for wrap, clamp-to-edge for clamp).
    #[must_use]
    pub fn sampler(&self) -> &wgpu::Sampler {
        &self.sampler
    }

    /// The textures themselves (for reading back, or for binding single mips).
    #[must_use]
    pub fn maps(&self) -> &HeightMaps {
        &self.maps
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.maps.width
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.maps.height
    }

    /// The edge mode the maps and the sampler were built for; the shader's
    /// `PomkitParams::edges` must match it.
    #[must_use]
    pub fn edges(&self) -> EdgeMode {
        self.opts.edges
    }

    /// Gives the library's `cone` technique its cones: `cones` must be built from the heights
    /// this resource holds, with its edge mode (`pomkit_core::cone::ConeMap::conservative`, or
    /// `cached`); `None` removes them. Run [`HeightResource::encode_rebuild`] afterwards: the
    /// rebuild copies them into the pyramid. Relaxed cones (a baked `--relaxed` map) make the
    /// library's `cone` relaxed cone stepping. Without cones `cone` walks as `exact` does (the
    /// same hits); remove them when the heights change, or let the GPU build them at every
    /// rebuild instead ([`HeightResourceOptions::cones`]).
    ///
    /// # Errors
    /// [`crate::GpuError::Unsupported`] if the cones are not the resource's size.
    pub fn write_cones(
        &self,
        queue: &wgpu::Queue,
        cones: Option<&pomkit_core::cone::ConeMap>,
    ) -> Result<(), crate::GpuError> {
        self.maps.write_cones(queue, cones)
    }

    /// The options the resource was built with.
    #[must_use]
    pub fn options(&self) -> &HeightResourceOptions {
        &self.opts
    }

    /// The label given when it was built.
    #[must_use]
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Whether it was built from a host texture (and [`HeightResource::encode_rebuild`] reads
    /// that texture again).
    #[must_use]
    pub fn is_from_texture(&self) -> bool {
        self.import.is_some()
    }

    /// Records [`HeightResource::encode_rebuild`] into a new command buffer and submits it.
    fn submit_rebuild(&self, device: &wgpu::Device, queue: &wgpu::Queue, passes: &HeightPasses) {
        let mut encoder = device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pomkit height resource build") });
        self.encode_rebuild(device, passes, &mut encoder);
        queue.submit([encoder.finish()]);
    }
}

/// Checks a field's size against the device's limit, for it and for its pyramid.
fn check_size(device: &wgpu::Device, width: u32, height: u32, label: &str) -> Result<(), HostError> {
    let label = label.to_owned();
    if width == 0 || height == 0 {
        return Err(HostError::Empty { label, width, height });
    }
    let limit = device.limits().max_texture_dimension_2d;
    if width > limit || height > limit {
        return Err(HostError::TooLarge { label, what: "the height map".to_owned(), width, height, limit });
    }
    let (pw, ph) = (width.next_power_of_two(), height.next_power_of_two());
    if pw > limit || ph > limit {
        return Err(HostError::TooLarge {
            label,
            what: "its maximum-height pyramid (each side padded up to a power of two)".to_owned(),
            width: pw,
            height: ph,
            limit,
        });
    }
    Ok(())
}

/// [`HeightMaps::with_device`]'s error as a [`HostError`].
fn gpu_error(e: GpuError, label: &str) -> HostError {
    let label = label.to_owned();
    match e {
        GpuError::TooLarge { what, width, height, limit } => HostError::TooLarge { label, what, width, height, limit },
        other => HostError::Device { label, message: other.to_string() },
    }
}

/// Runs `f` inside validation and out-of-memory error scopes: an error wgpu reports there
/// becomes [`HostError::Device`] instead of reaching the device's uncaptured-error handler
/// (which panics by default).
fn guarded<T>(device: &wgpu::Device, label: &str, f: impl FnOnce() -> Result<T, HostError>) -> Result<T, HostError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let result = f();
    let errors = [pollster::block_on(validation.pop()), pollster::block_on(oom.pop())];
    if let Some(e) = errors.into_iter().flatten().next() {
        // wgpu's message already lists its causes ("Caused by: ...").
        let message = e.to_string().trim_end().to_owned();
        return Err(HostError::Device { label: label.to_owned(), message });
    }
    result
}
