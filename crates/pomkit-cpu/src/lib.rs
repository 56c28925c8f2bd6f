//! pomkit-cpu: the CPU renderer.
//!
//! Per pixel it runs what a GPU would: the vertex stage (world position, tangent frame), near
//! clipping and triangle setup, rasterization in 2x2 quads (so UV gradients exist before any
//! loop), the material's technique from `pomkit-core`, every texture sampled at the displaced
//! UV, Blinn-Phong lighting with the normal map, self-shadowing, the LOD fade to normal mapping,
//! and optionally the displaced depth written to the depth buffer. Tiles of the image are shaded
//! in parallel with rayon.
//!
//! It is also the reference the GPU renderer is tested against, and it renders the ground truth:
//! [`Mode::Displaced`] tessellates every height-mapped mesh to the height map's resolution and
//! moves its vertices for real. That geometry is streamed ([`pomkit_core::mesh::DisplacedBlocks`]):
//! made a block of at most 128 triangles at a time in each tile that needs it and dropped, never
//! held whole, and coarsened for the view where the surface would move by less than
//! [`RenderOptions::displaced_tolerance`] samples on screen (docs/BENCHMARKS.md measures it
//! against the whole mesh).
//!
//! ```
//! use pomkit_cpu::{CpuRenderer, RenderOptions};
//!
//! let scene = pomkit_core::demo::demo_scene_sized(64);
//! let opts = RenderOptions { width: 64, height: 36, ..Default::default() };
//! let out = CpuRenderer::new().render(&scene, &opts, &|_, _| {})?;
//! let srgb: Vec<[u8; 3]> = out.to_srgb8(); // out.color is linear RGB
//! assert_eq!(srgb.len(), 64 * 36);
//! # Ok::<(), pomkit_cpu::RenderError>(())
//! ```

mod budget;
mod displaced;
mod fragment;
mod packet;
mod prepare;
pub mod raster;
mod shade8;
pub mod simd;
mod tiles;

use glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::DisplacementView;
use pomkit_core::scene::Scene;
use pomkit_core::silhouette::vertex_curvature;
use pomkit_core::trace::Technique;

pub use budget::{MaterialSize, advice_for, describe_job, estimate, estimate_from_sizes};
pub use pomkit_core::memory::{Estimate, MemoryError};
pub use pomkit_core::render::{
    Aovs, Mode, RenderError, RenderOptions, RenderOutput, Sample, resolve, resolve_rows, validate,
};

use budget::{advice, geometry_counts};
use displaced::{DisplacedGeometry, is_streamed, streamed_meshes};
use fragment::Shading;
use prepare::{AlbedoCache, Prepared, prepare};
use raster::{ClipVertex, Needs, ScreenTriangle, Varyings, clip_near, setup};
pub use simd::{SIMD_ENV, Simd8, SimdEnvError, cpu_features};
use tiles::shade_bands;

/// The CPU renderer: `CpuRenderer::new()` then `render(&scene, &options)`.
///
/// A renderer keeps the mip chains of the albedo textures it has drawn, for as long as those
/// textures live; everything derived from height maps is made anew every frame.
#[derive(Debug)]
pub struct CpuRenderer {
    simd: Simd8,
    albedo: AlbedoCache,
    /// Occlusion and back-face culling of the displaced reference's blocks
    /// ([`CpuRenderer::with_block_culling`]).
    cull_blocks: bool,
}

impl Default for CpuRenderer {
    fn default() -> Self {
        Self::new()
    }
}

impl CpuRenderer {
    /// A renderer shading with the best SIMD level of this CPU, or the one `POMKIT_SIMD` asks
    /// for ([`Simd8::from_env`]; a value it does not know is ignored here, and reported by
    /// [`Simd8::from_env`] itself).
    #[must_use]
    pub fn new() -> Self {
        Self::with_simd(Simd8::from_env().unwrap_or_else(|_| Simd8::detect()))
    }

    /// A renderer shading its packets with `simd`.
    #[must_use]
    pub fn with_simd(simd: Simd8) -> Self {
        Self { simd, albedo: AlbedoCache::default(), cull_blocks: true }
    }

    /// Whether the `displaced` reference skips, without making them, the blocks that what a
    /// tile already drew hides, and the triangles that clearly face away (on by default). Off,
    /// every block binned to a tile is made and every triangle set up: the same picture, bit
    /// for bit, only slower (the tests compare the two).
    #[must_use]
    pub fn with_block_culling(mut self, on: bool) -> Self {
        self.cull_blocks = on;
        self
    }

    /// The SIMD level the renderer shades with.
    #[must_use]
    pub fn simd(&self) -> Simd8 {
        self.simd
    }

    /// Renders `scene`, calling `progress(done, total)` as tiles finish.
    ///
    /// Before allocating anything big it checks [`estimate`] against the memory budget
    /// ([`pomkit_core::memory`]), and the buffers whose size comes from the options or the scene
    /// are allocated fallibly.
    ///
    /// # Errors
    /// [`RenderError`] for a bad size, a dangling material index, invalid trace parameters, or
    /// a frame that does not fit in memory ([`RenderError::Memory`]).
    pub fn render(
        &mut self,
        scene: &Scene,
        opts: &RenderOptions,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<RenderOutput, RenderError> {
        validate(scene, opts)?;
        let ss = opts.supersample.clamp(1, 8);
        let (w, h) = (opts.width, opts.height);
        let (sw, sh) = (w * ss, h * ss);
        estimate(scene, opts).check(|| describe_job(opts), &advice(scene, opts))?;
        let albedo = self.albedo.chains(scene);
        let prepared = prepare(scene, opts, &albedo);
        let aspect = sw as f32 / sh as f32;
        let vp = scene.camera.projection(aspect) * scene.camera.view();
        let triangles = self.triangles(scene, &prepared, opts, vp, (sw, sh))?;
        // The displaced reference's height-mapped objects are streamed: their subdivided
        // triangles are made a block at a time, in the tiles that need them, and dropped.
        let meshes = streamed_meshes(scene, &prepared, opts);
        let view = DisplacementView {
            view_proj: vp,
            size: Vec2::new(sw as f32, sh as f32),
            tolerance: opts.displaced_tolerance,
        };
        let displaced = DisplacedGeometry::new(scene, &prepared, opts, &meshes, view);
        let (mut color, mut aovs) = pomkit_core::render::output_buffers(w, h, opts.aovs)?;
        let covered = shade_bands(
            scene,
            &prepared,
            &triangles,
            &displaced,
            (w, h, ss),
            &mut color,
            opts.aovs.then_some(&mut aovs),
            self.shading(scene, &prepared, opts),
            progress,
        )?;
        Ok(RenderOutput { width: w, height: h, color, aovs: opts.aovs.then_some(aovs), covered })
    }

    /// How the fragments of a frame of `scene` are shaded.
    fn shading(&self, scene: &Scene, prepared: &[Prepared], opts: &RenderOptions) -> Shading {
        Shading {
            level: self.simd.level,
            packets: self.simd.packets,
            // (Not for unpacked: it is the reference, drawn as fragments arrive.)
            visibility_first: self.simd.packets
                && prepared
                    .iter()
                    .all(|p| !(p.has_silhouettes() || p.material.pixel_depth_offset && p.technique.displaces())),
            lod_tint: opts.lod_tint,
            cull_blocks: self.cull_blocks,
            depth_matrix: scene.camera.projection(1.0) * scene.camera.view(),
        }
    }

    /// The vertex stage and triangle setup for every object.
    fn triangles(
        &self,
        scene: &Scene,
        prepared: &[Prepared],
        opts: &RenderOptions,
        vp: Mat4,
        (sw, sh): (u32, u32),
    ) -> Result<Vec<ScreenTriangle>, MemoryError> {
        let tris = geometry_counts(scene, opts).triangles;
        let mut out = Vec::new();
        out.try_reserve_exact(usize::try_from(tris).unwrap_or(usize::MAX)).map_err(|e| MemoryError::Allocation {
            what: format!("the triangle list ({tris} triangles)"),
            bytes: pomkit_core::memory::bytes_of::<ScreenTriangle>(tris),
            reason: e.to_string(),
            advice: advice(scene, opts),
        })?;
        for (oi, obj) in scene.objects.iter().enumerate() {
            let prep = &prepared[obj.material];
            if is_streamed(&prep.material, opts) {
                continue;
            }
            let world = obj.mesh.transformed(obj.transform);
            // Silhouettes need the surface's curvature, estimated on the world mesh (a
            // non-uniform scale changes it); without them nothing is computed.
            let curvature = if prep.has_silhouettes() { vertex_curvature(&world) } else { Vec::new() };
            let verts: Vec<ClipVertex> = (0..world.positions.len())
                .map(|i| {
                    let p = world.positions[i];
                    ClipVertex {
                        clip: vp * p.extend(1.0),
                        v: Varyings {
                            world: p,
                            normal: world.normals[i],
                            tangent: world.tangents[i],
                            uv: world.uvs[i],
                            uv_scale: world.uv_scale[i],
                            depth: 0.0,
                            curvature: curvature.get(i).copied().unwrap_or(Vec3::ZERO),
                        },
                    }
                })
                .collect();
            let needs = Needs { frame: prep.technique != Technique::Flat, curvature: prep.has_silhouettes() };
            for tri in world.indices.chunks_exact(3) {
                let t = [verts[tri[0] as usize], verts[tri[1] as usize], verts[tri[2] as usize]];
                for c in clip_near(t) {
                    if let Some(st) = setup(&c, sw, sh, oi as u32, true) {
                        out.push(st.needing(needs));
                    }
                }
            }
        }
        Ok(out)
    }
}
