//! pomkit-core: the pure algorithms of pomkit.
//!
//! Height fields and their sampling, mip chains and the maximum-height pyramid, tangent frames
//! for triangle meshes, normal and parallax map baking, and procedural height maps. No file I/O
//! lives here: `pomkit-io` turns files into these types. The one contact with the environment
//! is [`memory`]'s budget probe (`POMKIT_MEMORY_LIMIT` and, on Linux, `/proc`).
//!
//! Conventions are those of ARCHITECTURE.md: tangent space x = T (along +u), y = B (up the
//! image, along -v), z = N; depth `d` in `[0, 1]` with 0 at the polygon's surface; UV `(0, 0)` at
//! the top-left corner of the image.
//!
//! ```
//! use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
//! use pomkit_core::glam::{Vec2, Vec3};
//! use pomkit_core::procedural::{Pattern, generate};
//! use pomkit_core::{EdgeMode, Ray, ShadowMode, ShadowParams, Surface, Technique, TraceParams, shadow, trace};
//!
//! let field = generate(Pattern::Bricks, 256, 256);
//! let opts = NormalBakeOptions { scale: 8.0, filter: NormalFilter::Sobel, ..Default::default() };
//! let normals = bake_normals(&field, &opts)?;
//! assert_eq!(normals.len(), 256 * 256);
//!
//! // Trace a view ray with parallax occlusion mapping, then shadow the hit point softly. The
//! // surface holds the depth scale (the deepest point lies 0.1 tile widths down) and the edges.
//! let surface = Surface::new(field, EdgeMode::Wrap, 0.1);
//! let params = TraceParams { refine: 2, ..Default::default() };
//! let ray = Ray::new(Vec2::new(0.3, 0.4), Vec3::new(0.6, 0.1, -0.8));
//! let hit = trace(&surface, &ray, Technique::Pom, &params);
//! let light = Vec3::new(-0.5, 0.2, 0.7); // toward the light, in the same (u, v, normal) frame
//! let soft = ShadowParams { mode: ShadowMode::Soft, softness: 0.1 };
//! let lit = shadow(&surface, hit.uv, hit.depth, light, &soft, &params);
//! assert!((0.0..=1.0).contains(&lit.visibility) && (0.0..=1.0).contains(&hit.depth));
//! # Ok::<(), pomkit_core::bake::BakeError>(())
//! ```

pub mod accuracy;
pub mod bake;
pub mod compose;
pub mod cone;
pub mod demo;
pub mod grid;
pub mod heightfield;
pub mod integrate;
pub mod memory;
pub mod mesh;
mod modes;
pub mod params;
pub mod planes;
pub mod procedural;
pub mod pyramid;
pub mod render;
pub mod scene;
pub mod shadow;
pub mod silhouette;
mod table;
pub mod tangent;
pub mod trace;

pub use glam;
pub use heightfield::{EdgeMode, HeightField, HeightFieldError, MipChain, mip_level_from_gradients};
pub use memory::MAX_SIZE;
pub use pyramid::MaxHeightPyramid;
pub use shadow::{Shadow, ShadowMarch, ShadowMode, ShadowParams, ShadowStart, lod_weight, shadow, shadow_start};
pub use tangent::{TangentError, TangentMethod, TangentOptions, compute_tangents, compute_vertex_normals};
pub use trace::{Hit, Ray, Surface, Technique, TraceParams, trace};
