//! pomkit-gpu: the wgpu/WGSL renderer.
//!
//! The same system as `pomkit-cpu`, on the GPU: every technique of docs/REFERENCES.md as a
//! pipeline variant (a WGSL `override` constant), hard, soft, exact and depth self-shadows, the LOD
//! fade and its tint view, Blinn-Phong shading and pixel depth offset; compute passes that
//! rebuild a height map's mips, normals, parallax map and maximum-height pyramid on the GPU, so
//! a height field may change every frame.

#[cfg(feature = "renderer")]
pub mod context;
#[cfg(feature = "renderer")]
pub mod height;
#[cfg(feature = "renderer")]
pub mod host;
pub mod library;
#[cfg(feature = "renderer")]
pub mod material;
#[cfg(feature = "renderer")]
pub mod pipeline;
#[cfg(feature = "renderer")]
pub mod planes;
// Public for pomkit-gpu's own tests (tests/library_rays.rs, tests/analytic.rs: the shader
// library against pomkit-core, ray by ray; docs/GPU.md), which are outside the crate and need a
// public path to it. It is not part of the renderer's API, so it is hidden from the docs.
#[cfg(feature = "renderer")]
#[doc(hidden)]
pub mod probe;
#[cfg(feature = "renderer")]
pub mod renderer;
pub mod util;

#[cfg(feature = "renderer")]
pub use context::GpuContext;
#[cfg(feature = "renderer")]
pub use host::{HeightBindings, HeightEncoding, HeightResource, HeightResourceOptions, HostError};
#[cfg(feature = "renderer")]
pub use material::{FrameUniforms, FrameView, GpuMaterial, GpuMesh, GpuObject, MaterialPipelines, Targets, Variant};
#[cfg(feature = "renderer")]
pub use pipeline::{AttributeKind, PipelineError, PipelineOptions, VertexAttribute, VertexBuffer, VertexLayout};
#[cfg(feature = "renderer")]
pub use renderer::{GpuRenderError, GpuRenderer, GpuScene, Timings};

/// Why the GPU renderer could not run.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter: the machine has no Vulkan, Metal, DX12 or GL driver (on Linux without a GPU,
    /// `apt-get install mesa-vulkan-drivers` gives the software adapter lavapipe).
    #[error(
        "no GPU adapter found (on Linux without a GPU, install Mesa's software Vulkan driver: apt-get install mesa-vulkan-drivers)"
    )]
    NoAdapter,
    /// The adapter refused to open a device, or the device was lost.
    #[error("GPU device error: {0}")]
    Device(String),
    /// Something the adapter or this renderer does not support (the message says what).
    #[error("not supported: {0}")]
    Unsupported(String),
    /// A texture is larger than the device allows.
    #[error("{what} is {width}x{height}, larger than this GPU's limit of {limit} texels per side")]
    TooLarge {
        /// Which texture.
        what: String,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// The device's `max_texture_dimension_2d`.
        limit: u32,
    },
}
