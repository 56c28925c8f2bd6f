//! pomkit-core: the pure algorithms of pomkit.
//!
//! Height fields and their sampling, mip chains and the maximum-height pyramid, tangent frames
//! for triangle meshes, normal and parallax map baking, and procedural height maps. No file I/O
//! lives here: `pomkit-io` turns files into these types.
//!
//! Conventions are those of DESIGN section 2: tangent space x = T (along +u), y = B (up the
//! image, along -v), z = N; depth `d` in `[0, 1]` with 0 at the polygon's surface; UV `(0, 0)` at
//! the top-left corner of the image.

pub mod accuracy;
pub mod bake;
pub mod heightfield;
pub mod procedural;
pub mod pyramid;
pub mod shadow;
pub mod tangent;
pub mod trace;

pub use glam;
pub use heightfield::{EdgeMode, HeightField, HeightFieldError, MipChain, mip_level_from_gradients};
pub use pyramid::MaxHeightPyramid;
pub use shadow::{Shadow, ShadowMode, ShadowParams, lod_weight, shadow};
pub use tangent::{TangentError, TangentMethod, TangentOptions, compute_tangents, compute_vertex_normals};
pub use trace::{Hit, Ray, Surface, Technique, TraceParams, trace};
