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

pub mod raster;
mod shade8;
pub mod simd;

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use fearless_simd::{Level, Simd, dispatch};
use glam::{Mat4, Vec2, Vec3, Vec4};
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use pomkit_core::heightfield::floor;
use pomkit_core::mesh::{DisplacedBlock, DisplacedBlocks, DisplacementView, Mesh, TangentMap};
use pomkit_core::scene::{Light, Material, NormalMap, Scene, Texture};
use pomkit_core::shadow::{Shadow, ShadowMode, ShadowStart, lod_weight, shadow, shadow_start};
use pomkit_core::silhouette::{trace_curved, vertex_curvature, view_curvature};
use pomkit_core::trace::packet::{self, LANES};
use pomkit_core::trace::{Hit, Ray, Surface, Technique, TraceParams, sanitized_depth_scale, trace};
use pomkit_core::{EdgeMode, mip_level_from_gradients};
use rayon::prelude::*;

pub use pomkit_core::memory::{Estimate, MemoryError};
pub use pomkit_core::render::{
    Aovs, Mode, RenderError, RenderOptions, RenderOutput, Sample, resolve, resolve_rows, validate,
};

use raster::{ClipVertex, Fragment, Needs, ScreenTriangle, Varyings, clip_near, needs_clipping, setup};
pub use simd::{SIMD_ENV, Simd8, SimdEnvError, cpu_features};

/// A material prepared for shading: surfaces, mip chains, normal maps.
struct Prepared {
    material: Material,
    /// The height map prepared for tracing, where the frame traces it: a displacing technique,
    /// or the displaced reference's shadows. `flat` and `normal` only need `lod_basis`.
    surface: Option<Arc<Surface>>,
    /// The height map's size in texels and its coarsest mip level, for the level of detail.
    lod_basis: Option<(Vec2, f32)>,
    normals: Option<Arc<NormalMap>>,
    /// The albedo and its mip chain (shared between frames while the texture lives).
    albedo: Arc<Vec<Texture>>,
    technique: Technique,
    params: TraceParams,
    /// The material's depth scale, sanitized ([`pomkit_core::trace::sanitized_depth_scale`]).
    depth_scale: f32,
    edges: EdgeMode,
}

/// Texel count and mip count for gradient-based level selection.
fn albedo_level(chain: &[Texture], duv_dx: Vec2, duv_dy: Vec2) -> f32 {
    let base = &chain[0];
    let size = Vec2::new(base.width() as f32, base.height() as f32);
    mip_level_from_gradients(duv_dx, duv_dy, size, (chain.len() - 1) as f32)
}

fn sample_albedo(chain: &[Texture], uv: Vec2, lod: f32, edges: EdgeMode) -> Vec3 {
    let k = floor(lod).max(0.0) as usize;
    let f = lod - k as f32;
    let a = chain[k.min(chain.len() - 1)].sample(uv, edges);
    if f <= 0.0 || k + 1 >= chain.len() {
        return a;
    }
    a.lerp(chain[k + 1].sample(uv, edges), f)
}

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

const TILE: u32 = 32;

/// The width in samples of a frame's tiles (all [`TILE`] rows high): [`TILE`], or with
/// [`Stream`]s (the displaced reference) the whole row of the frame. A streamed block is made in
/// every tile it touches; a tile as wide as the frame makes each block once per band of rows it
/// crosses instead of once per tile (about half as often for the demo).
fn tile_width(sw: u32, streams: bool) -> u32 {
    if streams { sw.max(1) } else { TILE }
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
        let worlds: Vec<(u32, Mesh)> = scene
            .objects
            .iter()
            .enumerate()
            .filter(|(_, obj)| streamed(&prepared[obj.material], opts))
            .map(|(oi, obj)| (oi as u32, obj.mesh.transformed(obj.transform)))
            .collect();
        let view = DisplacementView {
            view_proj: vp,
            size: Vec2::new(sw as f32, sh as f32),
            tolerance: opts.displaced_tolerance,
        };
        let streams: Vec<Stream<'_>> = worlds
            .iter()
            .filter_map(|(oi, world)| {
                let prep = &prepared[scene.objects[*oi as usize].material];
                let field = prep.material.height.as_deref()?;
                let blocks =
                    world.displaced_blocks(field, prep.edges, prep.depth_scale, opts.displaced_edge_texels, Some(view));
                Some(Stream { object: *oi, blocks })
            })
            .collect();
        let (mut color, mut aovs) = pomkit_core::render::output_buffers(w, h, opts.aovs)?;
        let covered = shade_bands(
            scene,
            &prepared,
            &triangles,
            &Streamed { streams: &streams, view },
            (w, h, ss),
            &mut color,
            opts.aovs.then_some(&mut aovs),
            Shading {
                level: self.simd.level,
                packets: self.simd.packets,
                // (Not for unpacked: it is the reference, drawn as fragments arrive.)
                visibility_first: self.simd.packets
                    && prepared
                        .iter()
                        .all(|p| !(silhouettes(p) || p.material.pixel_depth_offset && p.technique.displaces())),
                lod_tint: opts.lod_tint,
                cull_blocks: self.cull_blocks,
                depth_matrix: scene.camera.projection(1.0) * scene.camera.view(),
            },
            progress,
        )?;
        Ok(RenderOutput { width: w, height: h, color, aovs: opts.aovs.then_some(aovs), covered })
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
            if streamed(prep, opts) {
                continue;
            }
            let world = obj.mesh.transformed(obj.transform);
            // Silhouettes need the surface's curvature, estimated on the world mesh (a
            // non-uniform scale changes it); without them nothing is computed.
            let curvature = if silhouettes(prep) { vertex_curvature(&world) } else { Vec::new() };
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
            let needs = Needs { frame: prep.technique != Technique::Flat, curvature: silhouettes(prep) };
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

/// Whether an object of this material is drawn as a [`Stream`]: the displaced reference of a
/// height-mapped material.
fn streamed(prep: &Prepared, opts: &RenderOptions) -> bool {
    streams(&prep.material, opts)
}

/// [`streamed`] for a material not yet prepared.
fn streams(material: &Material, opts: &RenderOptions) -> bool {
    opts.mode == Mode::Displaced && material.height.is_some()
}

/// A height-mapped object of the displaced reference: its subdivided, displaced triangles in
/// blocks made on demand ([`DisplacedBlocks`]), in world space.
struct Stream<'a> {
    object: u32,
    blocks: DisplacedBlocks<'a>,
}

/// Every [`Stream`] of a frame, and the view they are drawn in (its view-projection takes
/// their blocks to clip space).
struct Streamed<'a> {
    streams: &'a [Stream<'a>],
    view: DisplacementView,
}

/// The samples a streamed block may cover, `[x0, y0, x1, y1]` (end exclusive), and its least
/// NDC depth.
type BlockSamples = ([u32; 4], f32);

/// A block's vertices after the vertex stage, reused from block to block.
#[derive(Default)]
struct BlockVertices {
    block: DisplacedBlock,
    clip: Vec<ClipVertex>,
    /// Screen positions (samples) of the vertices in front of the near plane.
    screen: Vec<Vec2>,
    /// Per vertex, whether it is in front of the near plane and inside the guard band
    /// ([`raster::unclipped`]).
    unclipped: Vec<bool>,
}

impl Streamed<'_> {
    /// Makes block `b` of stream `s` and runs the vertex stage on it. For displaced geometry
    /// the normals are the undisplaced surface's (`Mesh::displaced_for_shading`): the normal
    /// map adds the bumps, as for every parallax technique.
    fn vertices(&self, s: usize, b: usize, out: &mut BlockVertices) {
        self.streams[s].blocks.block(b, &mut out.block);
        let blk = &out.block;
        out.clip.clear();
        out.screen.clear();
        out.unclipped.clear();
        for i in 0..blk.positions.len() {
            let p = blk.positions[i];
            let clip = self.view.view_proj * p.extend(1.0);
            out.clip.push(ClipVertex {
                clip,
                v: Varyings {
                    world: p,
                    normal: blk.normals[i],
                    tangent: blk.tangents[i],
                    uv: blk.uvs[i],
                    uv_scale: blk.uv_scale[i],
                    depth: blk.depths[i],
                    curvature: Vec3::ZERO,
                },
            });
            out.screen.push(self.view.screen(clip));
            out.unclipped.push(raster::unclipped(clip));
        }
    }

    /// The samples block `b` of stream `s` may cover, `(x0, y0, x1, y1)` (end exclusive), and
    /// its least depth; `None` when it covers none (off screen, behind the camera, or facing
    /// away).
    fn bounds(&self, s: usize, b: usize, (sw, sh): (u32, u32), v: &mut BlockVertices) -> Option<BlockSamples> {
        let (lo, hi, min_z) = match self.streams[s].blocks.screen_bounds(b) {
            Some(known) => (known.min, known.max, known.min_z),
            None => self.made_bounds(s, b, (sw, sh), v)?,
        };
        if !(lo.is_finite() && hi.is_finite()) {
            return None;
        }
        // One sample of margin: pixel centres, the snap to 1/256 and the quads' even corners.
        let x0 = (lo.x - 1.0).floor().clamp(0.0, sw as f32) as u32;
        let y0 = (lo.y - 1.0).floor().clamp(0.0, sh as f32) as u32;
        let x1 = (hi.x + 2.0).ceil().clamp(0.0, sw as f32) as u32;
        let y1 = (hi.y + 2.0).ceil().clamp(0.0, sh as f32) as u32;
        (x0 < x1 && y0 < y1).then_some(([x0, y0, x1, y1], min_z))
    }

    /// [`Streamed::bounds`] by making the block: the box of its front-facing triangles.
    fn made_bounds(
        &self,
        s: usize,
        b: usize,
        (sw, sh): (u32, u32),
        v: &mut BlockVertices,
    ) -> Option<(Vec2, Vec2, f32)> {
        // Positions only (the same bits as `vertices` makes): the varyings are not needed here.
        self.streams[s].blocks.block_positions(b, &mut v.block);
        v.clip.clear();
        v.screen.clear();
        for &p in &v.block.positions {
            let clip = self.view.view_proj * p.extend(1.0);
            v.clip.push(ClipVertex { clip, v: Varyings { world: p, ..Varyings::default() } });
            v.screen.push(self.view.screen(clip));
        }
        let mut lo = Vec2::splat(f32::INFINITY);
        let mut hi = Vec2::splat(f32::NEG_INFINITY);
        let mut min_z = f32::INFINITY;
        let mut any = false;
        for tri in &v.block.triangles {
            let t = tri.map(|k| v.clip[k as usize]);
            if needs_clipping(&t) {
                // Rare (blocks at the near plane or beyond the guard band): clip and set up.
                for c in clip_near(t) {
                    if let Some(st) = setup(&c, sw, sh, 0, true)
                        && let Some((x0, y0, x1, y1)) = st.quad_bounds(0, 0, sw, sh)
                    {
                        lo = lo.min(Vec2::new(x0 as f32, y0 as f32));
                        hi = hi.max(Vec2::new(x1 as f32, y1 as f32));
                        min_z = min_z.min(st.min_z);
                        any = true;
                    }
                }
                continue;
            }
            let [a, b, c] = tri.map(|k| v.screen[k as usize]);
            // Front faces have negative area on the y-down screen (`setup`); keep the nearly
            // flat ones too, whose sign the fixed-point snap decides.
            if (b - a).perp_dot(c - a) > 0.01 {
                continue;
            }
            lo = lo.min(a.min(b).min(c));
            hi = hi.max(a.max(b).max(c));
            min_z = min_z.min(t.iter().map(|c| c.clip.z / c.clip.w).fold(f32::INFINITY, f32::min));
            any = true;
        }
        any.then_some((lo, hi, min_z))
    }
}

/// Whether the material traces with silhouettes: asked for, and a displacing technique on a
/// height map (so never in the `displaced` reference, which has true outlines).
fn silhouettes(prep: &Prepared) -> bool {
    prep.material.silhouette && prep.surface.is_some() && prep.technique.displaces()
}

/// Upper bounds on what the vertex stage makes of `scene`: the triangles of its drawn meshes,
/// the vertices of its largest object, and the blocks of its streamed (displaced) objects.
fn geometry_counts(scene: &Scene, opts: &RenderOptions) -> Geometry {
    let mut g = Geometry::default();
    for obj in &scene.objects {
        let field = scene.materials.get(obj.material).and_then(|m| m.height.as_ref());
        let (tris, verts) = (obj.mesh.triangle_count() as u64, obj.mesh.positions.len() as u64);
        g.largest = g.largest.max(verts);
        match (opts.mode, field) {
            (Mode::Displaced, Some(f)) => {
                // A triangle split into n parts makes at most (n / K + 1)^2 <= 2 n^2 / K^2 + 2
                // blocks of K x K cells (n^2 triangles).
                let (sub, _) = obj.mesh.displaced_bounds(f.width(), f.height(), opts.displaced_edge_texels);
                let cells = u64::from(pomkit_core::mesh::BLOCK_CELLS).pow(2);
                g.blocks = g.blocks.saturating_add((2 * sub).div_ceil(cells).saturating_add(2 * tris));
            }
            _ => g.triangles = g.triangles.saturating_add(tris),
        }
    }
    g
}

/// What [`geometry_counts`] bounds.
#[derive(Clone, Copy, Debug, Default)]
struct Geometry {
    /// Triangles of the meshes drawn as they are (set up all at once).
    triangles: u64,
    /// Vertices of the largest object (before any subdivision).
    largest: u64,
    /// Blocks of the streamed objects ([`DisplacedBlocks`]).
    blocks: u64,
}

/// Bytes a streamed block holds for a frame: its place in the list, its plan for the view,
/// its bounds and its entries in the tile bins (about two).
const BLOCK_BYTES: u64 = 12 + 48 + 24 + 2 * 16;

/// What a render is, for messages: "render of 16384x16384 with AOVs".
#[must_use]
pub fn describe_job(opts: &RenderOptions) -> String {
    let mut s = format!("render of {}x{}", opts.width, opts.height);
    if opts.supersample > 1 {
        s += &format!(" with {0}x{0} supersampling", opts.supersample.min(8));
    }
    if opts.aovs {
        s += " with AOVs";
    }
    if opts.mode == Mode::Displaced {
        s += " of displaced geometry";
    }
    s
}

/// What to change when a render does not fit.
fn advice(scene: &Scene, opts: &RenderOptions) -> String {
    advice_for(opts, scene.objects.iter().map(|o| o.mesh.triangle_count() as u64).sum::<u64>())
}

/// What to change when a render with `opts` of a scene of `triangles` does not fit.
#[must_use]
pub fn advice_for(opts: &RenderOptions, triangles: u64) -> String {
    let mut ways = vec!["a smaller --size"];
    if opts.supersample > 1 {
        ways.push("a lower --supersample");
    }
    if opts.aovs {
        ways.push("fewer AOVs");
    }
    if opts.mode == Mode::Displaced {
        ways.push("smaller height maps or a technique other than displaced");
    }
    if triangles > 1_000_000 {
        ways.push("fewer or coarser meshes");
    }
    let last = ways.pop().unwrap_or_default();
    if ways.is_empty() { format!("use {last}") } else { format!("use {} or {last}", ways.join(", ")) }
}

/// Bytes per height-map texel a prepared material holds: the surface (a copy of the field, its
/// mip chain, the maximum-height pyramid, the parallax map and its mips, and the normals baked on
/// the way) and the baked normal map.
const HEIGHT_BYTES_PER_TEXEL: u64 = 80;

/// Bytes per albedo texel: the texture and its mip chain (4/3 of it) of linear RGB.
const ALBEDO_BYTES_PER_TEXEL: u64 = 16;

/// An upper bound on the memory [`CpuRenderer::render`] allocates for `scene` with `opts`
/// (beyond the scene itself), by part: the output frame (colour, AOVs, and an 8-bit copy for
/// the PNG), the sample bands in flight, the triangle list and its tile bins, the largest
/// object's vertex stage (its world-space copy and clip-space vertices), the displaced
/// reference's blocks (streamed: the subdivided triangles themselves are never held), and the
/// prepared materials (surfaces, normal maps, albedo mips).
#[must_use]
pub fn estimate(scene: &Scene, opts: &RenderOptions) -> Estimate {
    let streamed = scene.objects.iter().any(|o| scene.materials.get(o.material).is_some_and(|m| streams(m, opts)));
    let materials: Vec<MaterialSize> = scene
        .materials
        .iter()
        .map(|m| MaterialSize {
            height: m.height.as_ref().map(|f| (f.width(), f.height())),
            albedo: m.albedo.as_ref().map(|t| (t.width(), t.height())),
            cone: opts.mode.technique(m.technique) == Technique::Cone,
        })
        .collect();
    estimate_parts(opts, streamed, geometry_counts(scene, opts), &materials)
}

/// The sizes of a material that its part of [`estimate`] needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MaterialSize {
    /// The height map's size.
    pub height: Option<(u32, u32)>,
    /// The colour map's size.
    pub albedo: Option<(u32, u32)>,
    /// Whether it is drawn with the `cone` technique (its cones are built for the render).
    pub cone: bool,
}

/// [`estimate`] before the scene is built, from sizes alone (a scene file's shapes and the
/// headers of its images): `triangles` of the meshes drawn as they are, `largest` the most
/// vertices of one object, `displaced_texels` the texels of the height maps of objects drawn
/// as displaced geometry (streamed in blocks of about two triangles a texel).
#[must_use]
pub fn estimate_from_sizes(
    opts: &RenderOptions,
    triangles: u64,
    largest: u64,
    displaced_texels: u64,
    materials: &[MaterialSize],
) -> Estimate {
    let cells = u64::from(pomkit_core::mesh::BLOCK_CELLS).pow(2);
    let g = Geometry { triangles, largest, blocks: displaced_texels.saturating_mul(4).div_ceil(cells) };
    estimate_parts(opts, displaced_texels > 0, g, materials)
}

fn estimate_parts(opts: &RenderOptions, streamed: bool, g: Geometry, materials: &[MaterialSize]) -> Estimate {
    use pomkit_core::memory::bytes_of;
    let ss = u64::from(opts.supersample.clamp(1, 8));
    let (w, h) = (u64::from(opts.width), u64::from(opts.height));
    let mut e = Estimate::default();
    e.add("frame", pomkit_core::render::output_bytes(opts.width, opts.height, opts.aovs));
    e.add("frame: 8-bit copy for the PNG", w * h * 6);
    // Bands of BAND pixel rows: their samples, and the tiles being shaded into them.
    let threads = rayon::current_num_threads() as u64 + 1;
    let band = bytes_of::<Option<Sample>>(w * ss * u64::from(BAND) * ss);
    e.add(
        "sample bands",
        threads.saturating_mul(2).saturating_mul(band).min(2 * bytes_of::<Option<Sample>>(w * h * ss * ss)),
    );
    // Each tile being shaded: its samples, and with visibility first its nearest fragments.
    let tile_w = u64::from(tile_width(opts.width.saturating_mul(opts.supersample.clamp(1, 8)), streamed));
    let tile = tile_w * u64::from(TILE);
    e.add(
        "tiles in flight",
        threads.saturating_mul(
            tile * (bytes_of::<Option<Sample>>(1) + bytes_of::<(u32, f32)>(1) + bytes_of::<Fragment>(1)),
        ),
    );
    let tiles = (w * ss).div_ceil(tile_w) * (h * ss).div_ceil(u64::from(TILE));
    e.add("triangles", bytes_of::<ScreenTriangle>(g.triangles));
    e.add("triangles: tile bins", g.triangles.saturating_mul(16).saturating_add(tiles * 32));
    // The largest object's world-space mesh and clip-space vertices (its triangles are
    // counted above).
    let per_vertex = Mesh::bytes_for(1, 0) + bytes_of::<ClipVertex>(1);
    e.add("vertex stage", g.largest.saturating_mul(per_vertex).saturating_add(g.largest.saturating_mul(2 * 12)));
    e.add("displaced blocks", g.blocks.saturating_mul(BLOCK_BYTES));
    let mut bytes = 0u64;
    for m in materials {
        if let Some((fw, fh)) = m.height {
            bytes = bytes.saturating_add(u64::from(fw) * u64::from(fh) * HEIGHT_BYTES_PER_TEXEL);
            if m.cone {
                bytes = bytes.saturating_add(pomkit_core::cone::ConeMap::build_bytes(fw, fh));
            }
        }
        let albedo = m.albedo.map_or(1, |(aw, ah)| u64::from(aw) * u64::from(ah));
        bytes = bytes.saturating_add(albedo * ALBEDO_BYTES_PER_TEXEL);
    }
    e.add("materials", bytes);
    e
}

/// Prepares every material (after [`validate`]): surfaces for tracing, normal maps (baked when
/// absent), albedo mips.
fn prepare(scene: &Scene, opts: &RenderOptions, albedo: &[Arc<Vec<Texture>>]) -> Vec<Prepared> {
    scene
        .materials
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let technique = opts.mode.technique(m.technique);
            let params = m.trace.sanitized();
            let (depth_scale, edges) = (sanitized_depth_scale(m.depth_scale), m.edges);
            let lod_basis = m.height.as_ref().map(|f| (f.size_f32(), coarsest_level(f.width(), f.height())));
            // Without a displacing technique the surface is traced only by the displaced
            // reference's shadows (its fragments lie below the polygon); elsewhere every
            // fragment lies on the polygon, where nothing shadows it.
            let traced = technique.displaces() || opts.mode == Mode::Displaced;
            let surface = m.height.as_ref().filter(|_| traced).map(|f| {
                let mut surface = Surface::new((**f).clone(), edges, depth_scale);
                // The material's own cones or the field's, built once (not inside the first
                // pixel's trace nor again for the next frame); either fits the field.
                if technique == Technique::Cone
                    && let Some(cones) = m.cones_to_trace()
                {
                    let _ = surface.set_cones(cones);
                }
                Arc::new(surface)
            });
            let normals = match (&m.normal_map, &m.height) {
                // `flat` shades with the geometric normal.
                _ if technique == Technique::Flat => None,
                (Some(n), _) => Some(n.clone()),
                (None, Some(f)) if f.width() >= 2 && f.height() >= 2 => {
                    // The normal map that matches the geometry: the full depth spans
                    // depth_scale * width texels.
                    let o = NormalBakeOptions {
                        scale: depth_scale * f.width() as f32,
                        filter: NormalFilter::Central,
                        edges,
                        y_down: false,
                    };
                    bake_normals(f, &o).ok().and_then(|n| NormalMap::new(f.width(), f.height(), n)).map(Arc::new)
                }
                _ => None,
            };
            let albedo = albedo[i].clone();
            Prepared { material: m.clone(), surface, lod_basis, normals, albedo, technique, params, depth_scale, edges }
        })
        .collect()
}

/// The coarsest level of a `w x h` mip chain (sides halve, never below 1, down to 1 x 1), as
/// [`pomkit_core::MipChain::max_level`] counts it.
fn coarsest_level(mut w: u32, mut h: u32) -> f32 {
    let mut k = 0u32;
    while w > 1 || h > 1 {
        (w, h) = ((w / 2).max(1), (h / 2).max(1));
        k += 1;
    }
    k as f32
}

/// A texture and its mip chain down to 1 x 1.
fn mip_chain(texture: Texture) -> Vec<Texture> {
    let mut chain = vec![texture];
    while let Some(last) = chain.last().filter(|t| t.width() > 1 || t.height() > 1) {
        let next = last.downsample();
        chain.push(next);
    }
    chain
}

/// The albedo mip chains of the frames so far, by texture: a texture is immutable once shared
/// (`Arc<Texture>`), so its chain holds for as long as it lives. Height maps, which may change
/// from frame to frame (dynamic height fields), are prepared anew every frame.
#[derive(Debug, Default)]
struct AlbedoCache {
    chains: Vec<(std::sync::Weak<Texture>, Arc<Vec<Texture>>)>,
}

impl AlbedoCache {
    /// Each material's albedo chain (a white texel for a material without an albedo map),
    /// built where the cache has none; chains of textures dropped since are forgotten.
    fn chains(&mut self, scene: &Scene) -> Vec<Arc<Vec<Texture>>> {
        self.chains.retain(|(t, _)| t.strong_count() > 0);
        let known = |t: &Arc<Texture>| {
            self.chains.iter().find(|(w, _)| std::ptr::eq(w.as_ptr(), Arc::as_ptr(t))).map(|(_, c)| c.clone())
        };
        let found: Vec<Option<Arc<Vec<Texture>>>> =
            scene.materials.iter().map(|m| m.albedo.as_ref().and_then(known)).collect();
        let built: Vec<Arc<Vec<Texture>>> = scene
            .materials
            .par_iter()
            .zip(found)
            .map(|(m, found)| {
                found.unwrap_or_else(|| {
                    Arc::new(mip_chain(
                        m.albedo.as_ref().map_or_else(|| Texture::constant(Vec3::ONE), |t| (**t).clone()),
                    ))
                })
            })
            .collect();
        let new: Vec<(std::sync::Weak<Texture>, Arc<Vec<Texture>>)> = scene
            .materials
            .iter()
            .zip(&built)
            .filter_map(|(m, chain)| {
                m.albedo.as_ref().filter(|t| known(t).is_none()).map(|t| (Arc::downgrade(t), chain.clone()))
            })
            .collect();
        for entry in new {
            if !self.chains.iter().any(|(w, _)| w.ptr_eq(&entry.0)) {
                self.chains.push(entry);
            }
        }
        built
    }
}

/// Pixel rows per band: each band's samples are shaded (tile by tile, in parallel) and
/// resolved into its rows of the frame, so the full-resolution samples never exist at once.
const BAND: u32 = TILE;

/// Bins triangles into tiles, shades the tiles of each band of [`BAND`] pixel rows in parallel
/// and resolves each band into `color` (and `aovs`); returns the covered pixel count.
#[expect(clippy::too_many_arguments, reason = "the frame's buffers and the shading inputs")]
fn shade_bands(
    scene: &Scene,
    prepared: &[Prepared],
    tris: &[ScreenTriangle],
    streamed: &Streamed<'_>,
    (w, h, ss): (u32, u32, u32),
    color: &mut [Vec3],
    aovs: Option<&mut Aovs>,
    shading: Shading,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<usize, MemoryError> {
    let (sw, sh) = (w * ss, h * ss);
    let tile_w = tile_width(sw, !streamed.streams.is_empty());
    let (tx, ty) = (sw.div_ceil(tile_w), sh.div_ceil(TILE));
    let mut bins: Vec<Vec<(f32, Item)>> =
        pomkit_core::memory::try_vec(Vec::new(), (tx * ty) as usize).map_err(|e| MemoryError::Allocation {
            what: format!("the tile bins of a {sw}x{sh}-sample frame"),
            bytes: u64::from(tx * ty) * 24,
            reason: e.to_string(),
            advice: "use a smaller --size or a lower --supersample".into(),
        })?;
    let mut bin = |(x0, y0, x1, y1): (u32, u32, u32, u32), z: f32, item: Item| {
        for by in y0 / TILE..=(y1 - 1) / TILE {
            for bx in x0 / tile_w..=(x1 - 1) / tile_w {
                bins[(by * tx + bx) as usize].push((z, item));
            }
        }
    };
    for (i, t) in tris.iter().enumerate() {
        if let Some(b) = t.quad_bounds(0, 0, sw, sh) {
            bin(b, t.min_z, Item::Triangle(i as u32));
        }
    }
    // Each block of the streamed objects is bounded here (from its prism where it can be, else
    // by making it), and made in each tile it touches unless what the tile drew already hides
    // it: per stream and block, the samples it may cover and its least depth.
    // (`f32::INFINITY` for a block that covers none.)
    let mut rects: Vec<Vec<BlockSamples>> = Vec::with_capacity(streamed.streams.len());
    for (si, stream) in streamed.streams.iter().enumerate() {
        let bounds: Vec<Option<BlockSamples>> = (0..stream.blocks.len())
            .into_par_iter()
            .map_init(BlockVertices::default, |v, b| streamed.bounds(si, b, (sw, sh), v))
            .collect();
        let mut stream_rects = Vec::with_capacity(bounds.len());
        for (b, found) in bounds.into_iter().enumerate() {
            if let Some(([x0, y0, x1, y1], z)) = found {
                bin((x0, y0, x1, y1), z, Item::Block(si as u32, b as u32));
            }
            stream_rects.push(found.unwrap_or(([0; 4], f32::INFINITY)));
        }
        rects.push(stream_rects);
    }
    // Front to back, so the early depth test rejects hidden fragments before they are traced.
    bins.par_iter_mut().for_each(|b| b.sort_by(|a, c| a.0.total_cmp(&c.0)));
    let done = AtomicUsize::new(0);
    let total = bins.len();
    // The frame's rows, cut into bands of BAND rows (AOV rows too, when asked for).
    let band_px = (w * BAND) as usize;
    let mut outs: Vec<(&mut [Vec3], Option<pomkit_core::render::AovRows<'_>>)> = Vec::new();
    match aovs {
        Some(a) => {
            let mut uv = a.uv.chunks_mut(band_px);
            let mut depth = a.depth.chunks_mut(band_px);
            let mut shadow = a.shadow.chunks_mut(band_px);
            let mut fetches = a.fetches.chunks_mut(band_px);
            let mut lod = a.lod.chunks_mut(band_px);
            for c in color.chunks_mut(band_px) {
                let rows = match (uv.next(), depth.next(), shadow.next(), fetches.next(), lod.next()) {
                    (Some(uv), Some(depth), Some(shadow), Some(fetches), Some(lod)) => {
                        Some(pomkit_core::render::AovRows { uv, depth, shadow, fetches, lod })
                    }
                    _ => None,
                };
                outs.push((c, rows));
            }
        }
        None => outs.extend(color.chunks_mut(band_px).map(|c| (c, None))),
    }
    let background = scene.background;
    let covered: Result<usize, MemoryError> = outs
        .into_par_iter()
        .enumerate()
        .map(|(k, (color, rows))| {
            let rows_px = (color.len() / w as usize) as u32;
            let (sy0, sy1) = (k as u32 * BAND * ss, (k as u32 * BAND + rows_px) * ss);
            let mut samples = pomkit_core::memory::try_vec(None, (sw * (sy1 - sy0)) as usize).map_err(|e| {
                MemoryError::Allocation {
                    what: format!("a band of {sw}x{} samples", sy1 - sy0),
                    bytes: pomkit_core::memory::bytes_of::<Option<Sample>>(u64::from(sw * (sy1 - sy0))),
                    reason: e.to_string(),
                    advice: "use a smaller --size or a lower --supersample".into(),
                }
            })?;
            let tiles: Vec<(u32, u32, Vec<Option<Sample>>)> = (sy0 / TILE..sy1.div_ceil(TILE))
                .flat_map(|by| (0..tx).map(move |bx| (bx, by)))
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|(bx, by)| {
                    let buf = shade_tile(
                        scene,
                        prepared,
                        (tris, streamed, &rects),
                        &bins[(by * tx + bx) as usize],
                        [bx * tile_w, by * TILE, ((bx + 1) * tile_w).min(sw), ((by + 1) * TILE).min(sh)],
                        (sw, sh),
                        shading,
                    );
                    let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                    progress(n, total);
                    (bx * tile_w, by * TILE, buf)
                })
                .collect();
            for (x0, y0, buf) in tiles {
                let tw = ((x0 + tile_w).min(sw) - x0) as usize;
                for (r, line) in buf.chunks(tw).enumerate() {
                    let y = y0 as usize + r - sy0 as usize;
                    let at = y * sw as usize + x0 as usize;
                    samples[at..at + tw].copy_from_slice(line);
                }
            }
            Ok(resolve_rows(&samples, w, ss, background, color, rows))
        })
        .sum();
    covered
}

/// What a tile bin lists: a triangle of the frame's list, or block `.1` of stream `.0`.
#[derive(Clone, Copy, Debug)]
enum Item {
    Triangle(u32),
    Block(u32, u32),
}

/// Shades the tile `[x0, x1) x [y0, y1)` of a `sw x sh`-sample frame: its samples, row-major.
fn shade_tile(
    scene: &Scene,
    prepared: &[Prepared],
    (tris, streamed, rects): (&[ScreenTriangle], &Streamed<'_>, &[Vec<BlockSamples>]),
    bin: &[(f32, Item)],
    [x0, y0, x1, y1]: [u32; 4],
    (sw, sh): (u32, u32),
    shading: Shading,
) -> Vec<Option<Sample>> {
    let tw = x1 - x0;
    let mut buf: Vec<Option<Sample>> = vec![None; (tw * (y1 - y0)) as usize];
    // With visibility first, the triangles only find each sample's nearest fragment; the
    // visible ones are shaded at the end, in full packets.
    let mut visible = if shading.visibility_first { Visible::new(buf.len()) } else { Visible::default() };
    // One packet for the tile, emptied after each triangle.
    let mut packet = Packet::default();
    let mut draw = |tri: &ScreenTriangle, buf: &mut Vec<Option<Sample>>, visible: &mut Visible| {
        if shading.visibility_first {
            draw_visible(tri, (x0, y0, x1, y1), visible);
        } else {
            draw(scene, prepared, tri, (x0, y0, x1, y1), shading, &mut packet, buf);
        }
    };
    let mut block = BlockVertices::default();
    let tile = [x0, y0, x1, y1];
    for &(_, item) in bin {
        match item {
            Item::Triangle(ti) => draw(&tris[ti as usize], &mut buf, &mut visible),
            Item::Block(si, b) => {
                // Occlusion culling: a block behind what the tile holds is not made at all.
                let (rect, min_z) = rects[si as usize][b as usize];
                let hidden = if !shading.cull_blocks {
                    false
                } else if shading.visibility_first {
                    occluded(rect, min_z, tile, |at, z| {
                        let (object, near) = visible.nearest[at];
                        object != Visible::EMPTY && near <= z
                    })
                } else {
                    occluded(rect, min_z, tile, |at, z| buf[at].is_some_and(|s| s.z <= z))
                };
                if hidden {
                    continue;
                }
                streamed.vertices(si as usize, b as usize, &mut block);
                let object = streamed.streams[si as usize].object;
                // Pixel centres a triangle can cover lie within its vertices' extent.
                let (fx0, fy0, fx1, fy1) = (x0 as f32 - 1.0, y0 as f32 - 1.0, x1 as f32 + 1.0, y1 as f32 + 1.0);
                for tri in &block.block.triangles {
                    if !tri.iter().all(|&k| block.unclipped[k as usize]) {
                        let t = tri.map(|k| block.clip[k as usize]);
                        for c in clip_near(t) {
                            if let Some(st) = setup(&c, sw, sh, object, true) {
                                draw(&st, &mut buf, &mut visible);
                            }
                        }
                        continue;
                    }
                    let [a, b, c] = tri.map(|k| block.screen[k as usize]);
                    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                    if hi.x < fx0 || lo.x > fx1 || hi.y < fy0 || lo.y > fy1 || !holds_a_centre(lo, hi) {
                        continue;
                    }
                    if shading.cull_blocks && surely_back_facing(a, b, c) {
                        continue;
                    }
                    let t = tri.map(|k| block.clip[k as usize]);
                    if let Some(st) = setup(&t, sw, sh, object, true) {
                        draw(&st, &mut buf, &mut visible);
                    }
                }
            }
        }
    }
    if shading.visibility_first {
        shade_visible(scene, prepared, &visible, tw, shading, &mut buf);
    }
    visible.give_back();
    buf
}

/// Whether every sample of `rect` (a block's samples, end exclusive) inside the tile
/// `[x0, x1) x [y0, y1)` already holds a fragment at depth `z` or nearer (`holds(at, z)`, `at`
/// the sample's index in the tile), `z` being `min_z` (the least depth of anything in the
/// block) less [`Z_MARGIN`]: then every fragment of the block fails the depth test (a fragment
/// is kept only when strictly nearer) and the block need not be made.
fn occluded(rect: [u32; 4], min_z: f32, [x0, y0, x1, y1]: [u32; 4], holds: impl Fn(usize, f32) -> bool) -> bool {
    let (rx0, ry0, rx1, ry1) = (rect[0].max(x0), rect[1].max(y0), rect[2].min(x1), rect[3].min(y1));
    if !(min_z.is_finite() && rx0 < rx1 && ry0 < ry1) {
        return false;
    }
    let z = min_z - Z_MARGIN;
    let tw = (x1 - x0) as usize;
    (ry0..ry1).all(|y| {
        let row = (y - y0) as usize * tw;
        (rx0..rx1).all(|x| holds(row + (x - x0) as usize, z))
    })
}

/// How far below a block's least vertex depth (NDC, in `[0, 1]`) [`occluded`] looks: a
/// fragment's depth, interpolated in f32 from its triangle's vertices, can fall an ulp or two
/// below the least of them.
const Z_MARGIN: f32 = 1e-6;

/// What a tile's visibility pass finds: per sample the object and depth of its nearest fragment
/// so far (`EMPTY`: none), and the fragment itself (in a buffer of this thread's, reused from
/// tile to tile: only the slots `nearest` marks are read).
#[derive(Default)]
struct Visible {
    nearest: Vec<(u32, f32)>,
    frags: Vec<Fragment>,
}

impl Visible {
    const EMPTY: u32 = u32::MAX;

    thread_local! {
        static SCRATCH: std::cell::RefCell<Vec<Fragment>> = const { std::cell::RefCell::new(Vec::new()) };
    }

    fn new(samples: usize) -> Self {
        let mut frags = Self::SCRATCH.with_borrow_mut(std::mem::take);
        if frags.len() < samples {
            frags.resize(samples, Fragment::default());
        }
        Self { nearest: vec![(Self::EMPTY, 0.0); samples], frags }
    }

    /// The fragment buffer back to the thread, for its next tile.
    fn give_back(self) {
        if !self.frags.is_empty() {
            Self::SCRATCH.with_borrow_mut(|s| *s = self.frags);
        }
    }

    /// The object and fragment nearest at sample `at`, if any.
    fn get(&self, at: usize) -> Option<(u32, &Fragment)> {
        let (object, _) = self.nearest[at];
        (object != Self::EMPTY).then(|| (object, &self.frags[at]))
    }
}

/// Whether the triangle with screen positions `a`, `b`, `c` (samples, y down, in f32, as
/// [`DisplacementView::screen`] gives them) faces away so clearly that [`setup`], which decides
/// on the positions computed in f64 and snapped to 1/256 sample, culls it too. For positions
/// within `[-64, 4096)` (else it does not tell) the two differ by less than `D = 1/512 + 1/256`
/// sample per coordinate (the snap, and a few roundings of f32 below 4096), which changes twice
/// the signed area by at most `2 D (|b - a|_1 + |c - a|_1) + 8 D^2`: the margin is larger.
fn surely_back_facing(a: Vec2, b: Vec2, c: Vec2) -> bool {
    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
    if !(lo.cmpge(Vec2::splat(-64.0)).all() && hi.cmplt(Vec2::splat(4096.0)).all()) {
        return false;
    }
    let (e1, e2) = (b - a, c - a);
    let margin = 0.05 * (e1.abs().element_sum() + e2.abs().element_sum()) + 0.01;
    e1.perp_dot(e2) > margin
}

/// Whether the box `[lo, hi]` of a triangle's screen positions (samples, in f32) may hold a
/// sample's centre (`k + 0.5` on both axes) once its vertices are snapped to 1/256 sample by
/// [`setup`]: the snap and the f32 positions differ by far less than the 1/64 sample of margin.
/// A subdivided triangle smaller than a sample usually holds none and needs no set-up.
fn holds_a_centre(lo: Vec2, hi: Vec2) -> bool {
    const MARGIN: f32 = 1.0 / 64.0;
    // (`floor`, not `f32::floor`: no call into libm on baseline x86-64.)
    let ceil = |x: f32| -floor(-x);
    let holds = |lo: f32, hi: f32| ceil(lo - (0.5 + MARGIN)) <= floor(hi - (0.5 - MARGIN));
    holds(lo.x, hi.x) && holds(lo.y, hi.y)
}

/// Rasterizes `tri` into the tile `[x0, x1) x [y0, y1)` whose samples `buf` holds, shading the
/// fragments that pass the depth test eight at a time ([`shade_packet`]).
fn draw(
    scene: &Scene,
    prepared: &[Prepared],
    tri: &ScreenTriangle,
    (x0, y0, x1, y1): (u32, u32, u32, u32),
    shading: Shading,
    packet: &mut Packet,
    buf: &mut [Option<Sample>],
) {
    let tw = x1 - x0;
    let prep = &prepared[scene.objects[tri.object as usize].material];
    /// The packet's sink: the early depth test against the tile's samples, fragments into the
    /// packet, shaded when it is full.
    struct Packets<'a> {
        scene: &'a Scene,
        prep: &'a Prepared,
        shading: Shading,
        packet: &'a mut Packet,
        buf: &'a mut [Option<Sample>],
        tile: TileOrigin,
    }
    impl raster::FragmentSink for Packets<'_> {
        fn keep(&mut self, x: u32, y: u32, z: f32) -> bool {
            // Early depth test with the polygon's depth: the displaced depth is never nearer, so
            // a fragment behind the stored one stays behind. The fragments of one triangle cover
            // distinct samples, so the test may run before the packet's earlier fragments land.
            !self.buf[self.tile.at(x, y)].is_some_and(|s| s.z <= z)
        }
        fn slot(&mut self, _: u32, _: u32) -> &mut Fragment {
            self.packet.slot()
        }
        fn written(&mut self, x: u32, y: u32) {
            if self.packet.commit(self.tile.at(x, y)) {
                self.packet.shade_into(self.scene, self.prep, self.shading, self.buf);
            }
        }
    }
    let mut sink = Packets { scene, prep, shading, packet, buf, tile: TileOrigin { x0, y0, tw } };
    tri.rasterize_into(x0, y0, x1, y1, &mut sink);
    sink.packet.shade_into(scene, prep, shading, sink.buf);
}

/// Rasterizes `tri` into the tile `[x0, x1) x [y0, y1)` for a visibility pass: `visible` keeps
/// each sample's nearest fragment (the first drawn among equals) and its object, unshaded.
fn draw_visible(tri: &ScreenTriangle, (x0, y0, x1, y1): (u32, u32, u32, u32), visible: &mut Visible) {
    /// The nearest fragment of each sample, written where it is kept.
    struct Nearest<'a> {
        visible: &'a mut Visible,
        object: u32,
        tile: TileOrigin,
    }
    impl raster::FragmentSink for Nearest<'_> {
        fn keep(&mut self, x: u32, y: u32, z: f32) -> bool {
            let (object, near) = &mut self.visible.nearest[self.tile.at(x, y)];
            let nearer = *object == Visible::EMPTY || z < *near;
            if nearer {
                (*object, *near) = (self.object, z);
            }
            nearer
        }
        fn slot(&mut self, x: u32, y: u32) -> &mut Fragment {
            &mut self.visible.frags[self.tile.at(x, y)]
        }
        fn written(&mut self, _: u32, _: u32) {}
    }
    let tile = TileOrigin { x0, y0, tw: x1 - x0 };
    tri.rasterize_into(x0, y0, x1, y1, &mut Nearest { visible, object: tri.object, tile });
}

/// A tile's first sample and width: where a sample of the frame is in the tile's buffers.
#[derive(Clone, Copy)]
struct TileOrigin {
    x0: u32,
    y0: u32,
    tw: u32,
}

impl TileOrigin {
    /// The index of sample `(x, y)` (inside the tile) in its row-major buffers.
    #[inline]
    fn at(self, x: u32, y: u32) -> usize {
        ((y - self.y0) * self.tw + (x - self.x0)) as usize
    }
}

/// Shades the visible fragments of a tile `tw` samples wide ([`draw_visible`]) into `buf`,
/// eight at a time per material, gathered quad by quad.
fn shade_visible(
    scene: &Scene,
    prepared: &[Prepared],
    visible: &Visible,
    tw: u32,
    shading: Shading,
    buf: &mut [Option<Sample>],
) {
    let th = visible.nearest.len() as u32 / tw.max(1);
    // One open packet per material seen in the tile.
    let mut open: Vec<(usize, Packet)> = Vec::new();
    for qy in (0..th).step_by(2) {
        for qx in (0..tw).step_by(2) {
            for k in 0..4 {
                let (x, y) = (qx + (k & 1), qy + (k >> 1));
                if x >= tw || y >= th {
                    continue;
                }
                let at = (y * tw + x) as usize;
                let Some((object, f)) = visible.get(at) else { continue };
                let material = scene.objects[object as usize].material;
                let i = match open.iter().position(|(m, _)| *m == material) {
                    Some(i) => i,
                    None => {
                        open.push((material, Packet::default()));
                        open.len() - 1
                    }
                };
                let (m, packet) = &mut open[i];
                if packet.push(*f, at) {
                    packet.shade_into(scene, &prepared[*m], shading, buf);
                }
            }
        }
    }
    for (m, mut packet) in open {
        packet.shade_into(scene, &prepared[m], shading, buf);
    }
}

/// Up to [`LANES`] fragments of one material waiting to be shaded, and the samples they go to.
#[derive(Default)]
struct Packet {
    /// The fragments (the first `written`; the rest are scratch for the next ones).
    frags: Vec<Fragment>,
    written: usize,
    slots: [usize; LANES],
    /// Scratch: each light's shadows of the packet.
    shadows: Vec<[Option<Shadow>; LANES]>,
}

impl Packet {
    /// Adds fragment `f` for sample `slot`; true when the packet is full.
    fn push(&mut self, f: Fragment, slot: usize) -> bool {
        *self.slot() = f;
        self.commit(slot)
    }

    /// Where the packet's next fragment is written (then [`Packet::commit`]).
    fn slot(&mut self) -> &mut Fragment {
        if self.frags.len() == self.written {
            self.frags.push(Fragment::default());
        }
        &mut self.frags[self.written]
    }

    /// Takes the fragment written to [`Packet::slot`] into the packet, for sample `slot`; true
    /// when the packet is full.
    fn commit(&mut self, slot: usize) -> bool {
        self.slots[self.written] = slot;
        self.written += 1;
        self.written == LANES
    }

    /// Shades the packet's fragments ([`shade_packet`], or one at a time for
    /// [`Simd8::unpacked`]) and writes those nearer than what `buf` holds; empties the packet.
    fn shade_into(&mut self, scene: &Scene, prep: &Prepared, shading: Shading, buf: &mut [Option<Sample>]) {
        if self.written == 0 {
            return;
        }
        let frags = &self.frags[..self.written];
        let mut out = [None; LANES];
        let level = shading.level;
        if shading.packets {
            let shadows = &mut self.shadows;
            dispatch!(level, simd => shade_packet(simd, scene, prep, &shading, frags, shadows, &mut out));
        } else {
            for (o, f) in out.iter_mut().zip(frags) {
                *o = shade(scene, prep, &shading, f);
            }
        }
        for (k, s) in out.into_iter().enumerate().take(frags.len()) {
            // A silhouette pixel whose ray leaves the relief is discarded: it writes nothing.
            let Some(mut s) = s else { continue };
            if shading.lod_tint && prep.lod_basis.is_some() {
                let w = lod_weight(s.lod, prep.material.lod_threshold);
                let tint = Vec3::new(1.0, 0.25, 0.2).lerp(Vec3::new(0.25, 1.0, 0.3), w);
                s.color = s.color * 0.5 + tint * 0.5 * s.color.length().max(0.05);
            }
            let slot = &mut buf[self.slots[k]];
            if slot.is_none_or(|old| s.z < old.z) {
                *slot = Some(s);
            }
        }
        self.written = 0;
    }
}

/// How the fragments of a frame are shaded: the SIMD level of the packets, and the LOD tint.
#[derive(Clone, Copy, Debug)]
struct Shading {
    level: Level,
    /// Packets of eight fragments, or one fragment at a time ([`Simd8::unpacked`]).
    packets: bool,
    /// Every fragment's depth is its polygon's and none is discarded (no pixel depth offset, no
    /// silhouettes): each tile finds its visible fragments first and shades only those.
    visibility_first: bool,
    lod_tint: bool,
    /// Occlusion culling of streamed blocks and back-face culling of their triangles before
    /// set-up ([`CpuRenderer::with_block_culling`]).
    cull_blocks: bool,
    /// The camera's view-projection at aspect 1, for the pixel depth offset (NDC depth does not
    /// depend on the aspect).
    depth_matrix: Mat4,
}

/// A fragment's state between the stages of [`shade`]: its tangent frame, view ray and level of
/// detail, and where its ray met the relief.
#[derive(Clone, Copy, Debug, Default)]
struct Lane {
    n: Vec3,
    t: Vec3,
    b: Vec3,
    tangent: Vec4,
    to_eye: Vec3,
    /// Mip level of the height map, and the weight of the full technique in the LOD fade.
    lod: f32,
    weight: f32,
    /// World directions to tangent space (where a ray is traced), and the view ray there.
    map: Option<TangentMap>,
    dir: Vec3,
    hit_uv: Vec2,
    hit_depth: f32,
    /// How deep the hit lies along the view ray (pixel depth offset).
    ray_depth: f32,
    fetches: u32,
}

/// The fragment stage up to the trace: the tangent frame, the eye direction, the mip level and
/// the view ray.
fn begin(scene: &Scene, prep: &Prepared, f: &Fragment, levels: (f32, f32)) -> Lane {
    let n = f.v.normal.try_normalize().unwrap_or(Vec3::Z);
    let to_eye = (scene.camera.eye - f.v.world).try_normalize().unwrap_or(n);
    let mut lane = Lane::default();
    begin_into(&mut lane, prep, f, levels, n, to_eye);
    lane
}

/// [`begin`] into `lane`, from the fragment's unit normal `n` and eye direction `to_eye` (which
/// a packet computes for all its lanes at once, [`shade_packet`]). It writes the lane field by
/// field, where a packet keeps it: a whole `Lane` built aside and copied in cost a store
/// forwarding stall per lane.
#[inline(always)]
fn begin_into(lane: &mut Lane, prep: &Prepared, f: &Fragment, (lod, weight): (f32, f32), n: Vec3, to_eye: Vec3) {
    let v = &f.v;
    // Tangent frame, re-orthonormalized after interpolation (Lengyel Listing 7.8).
    // `flat` reads none of the frame but the normal (no normal map, no ray in tangent space).
    let (t, b, tangent) = if prep.technique == Technique::Flat {
        (Vec3::ZERO, Vec3::ZERO, Vec4::ZERO)
    } else {
        let t_raw = v.tangent.truncate();
        let t = (t_raw - n * n.dot(t_raw)).try_normalize().unwrap_or_else(|| n.any_orthonormal_vector());
        let sign = if v.tangent.w < 0.0 { -1.0 } else { 1.0 };
        (t, n.cross(t) * sign, Vec4::new(t.x, t.y, t.z, sign))
    };
    // World directions to tangent space, for the view ray and the shadow rays.
    let map =
        if prep.technique.displaces() || shadows_cast(prep) { TangentMap::new(n, tangent, v.uv_scale) } else { None };
    lane.dir = match map {
        Some(m) if prep.technique.displaces() => m.apply(-to_eye),
        _ => Vec3::ZERO,
    };
    lane.map = map;
    lane.n = n;
    lane.t = t;
    lane.b = b;
    lane.tangent = tangent;
    lane.to_eye = to_eye;
    lane.lod = lod;
    lane.weight = weight;
    lane.hit_uv = v.uv;
    lane.hit_depth = v.depth;
    lane.ray_depth = v.depth;
    lane.fetches = 0;
    if v.depth > 0.0
        && let Some(surface) = &prep.surface
    {
        // Displaced geometry: a triangle is a chord of the surface, and where it passes under
        // it (over a ridge), shadows traced from the chord would start inside the relief. The
        // receiver is lifted onto the surface (one fetch), as for steep parallax below.
        lane.hit_depth = lane.hit_depth.min(surface.depth(v.uv, 0.0));
        lane.fetches += 1;
    }
}

/// The mip level of the height map from the quad's UV gradients (fixed before any loop), and
/// the weight of the full technique in the LOD fade.
fn level_of(prep: &Prepared, f: &Fragment) -> (f32, f32) {
    match prep.lod_basis {
        Some((size, coarsest)) => {
            let lod = mip_level_from_gradients(f.duv_dx, f.duv_dy, size, coarsest);
            (lod, lod_weight(lod, prep.material.lod_threshold))
        }
        None => (0.0, 0.0),
    }
}

/// `level(f)` for each of `frags`, computed once per quad: the fragments of a quad share their
/// UV gradients, and consecutive fragments with the same gradients get the same value.
fn per_quad<T: Copy + Default>(frags: &[Fragment], level: impl Fn(&Fragment) -> T) -> [T; LANES] {
    let mut out = [T::default(); LANES];
    let mut last: Option<(Vec2, Vec2, T)> = None;
    for (o, f) in out.iter_mut().zip(frags) {
        *o = match last {
            Some((dx, dy, v)) if dx == f.duv_dx && dy == f.duv_dy => v,
            _ => level(f),
        };
        last = Some((f.duv_dx, f.duv_dy, *o));
    }
    out
}

/// Whether the fragment's view ray is traced. With silhouettes the ray is traced even where
/// the LOD fade shows normal mapping only: the relief's outline is decided there too (the rim
/// of a curved mesh, seen at grazing angles, is where the mip level is highest).
fn traces(prep: &Prepared, lane: &Lane) -> bool {
    prep.surface.is_some() && (lane.weight > 0.0 || silhouettes(prep)) && prep.technique.displaces()
}

/// Takes the trace's `hit` into `lane` (its `ray_depth` already set where the ray is curved).
fn take_hit(prep: &Prepared, surface: &Surface, lane: &mut Lane, hit: &Hit) {
    if !silhouettes(prep) {
        lane.ray_depth = hit.depth;
    }
    lane.hit_uv = hit.uv;
    lane.hit_depth = hit.depth;
    lane.fetches += hit.fetches;
    if prep.technique == Technique::Steep {
        // Steep parallax stops on the first plane *below* the surface, up to one plane
        // spacing deep. Shadows traced from there start inside the relief and darken in
        // contour rings; lift the receiver onto the surface (one more fetch).
        let lifted = lane.hit_depth.min(surface.depth(lane.hit_uv, lane.lod));
        // The lift moves the point up the view ray as well (pixel depth offset).
        lane.ray_depth = if silhouettes(prep) { lane.ray_depth - (lane.hit_depth - lifted) } else { lifted };
        lane.hit_depth = lifted;
        lane.fetches += 1;
    }
}

/// The fragment stage for one fragment; `None` discards it (a silhouette ray that left the
/// relief).
fn shade(scene: &Scene, prep: &Prepared, shading: &Shading, f: &Fragment) -> Option<Sample> {
    let mut lane = begin(scene, prep, f, level_of(prep, f));
    if traces(prep, &lane)
        && let Some(surface) = &prep.surface
    {
        let p = TraceParams { lod: lane.lod, ..prep.params };
        let ray = Ray::new(f.v.uv, lane.dir);
        let hit = if silhouettes(prep) {
            let c = view_curvature(-lane.to_eye, lane.n, lane.tangent, f.v.curvature, prep.depth_scale);
            let curved = trace_curved(surface, &ray, prep.technique, &p, c);
            if curved.left {
                return None;
            }
            lane.ray_depth = curved.ray_depth;
            curved.hit
        } else {
            trace(surface, &ray, prep.technique, &p)
        };
        take_hit(prep, surface, &mut lane, &hit);
    }
    Some(finish(scene, prep, shading, f, &lane, |_, surface, l| {
        // The map takes a direction of travel; toward the light it is the same map.
        let light = lane.map.map_or(Vec3::ZERO, |m| m.apply(l));
        let p = TraceParams { lod: lane.lod, ..prep.params };
        shadow(surface, lane.hit_uv, lane.hit_depth, light, &prep.material.shadow, &p)
    }))
}

/// Up to [`LANES`] fragments of one triangle shaded at once: their view rays traced as a
/// packet ([`pomkit_core::trace::packet`]) and their hard and soft shadow rays marched as
/// packets, the rest lane by lane. Lane `i` of `out` is `shade(scene, prep, &frags[i])`, bit
/// for bit (the packet tracers are the single-ray ones).
#[inline(always)]
fn shade_packet<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    frags: &[Fragment],
    shadows: &mut Vec<[Option<Shadow>; LANES]>,
    out: &mut [Option<Sample>; LANES],
) {
    if silhouettes(prep) {
        // Curved rays: one at a time.
        for (o, f) in out.iter_mut().zip(frags) {
            *o = shade(scene, prep, shading, f);
        }
        return;
    }
    let surface = prep.surface.as_deref();
    let mut lanes = [Lane::default(); LANES];
    let mut rays = [None; LANES];
    let mut lods = [0.0; LANES];
    let levels = per_quad(frags, |f| level_of(prep, f));
    // `begin`'s normalizations, for all lanes at once (the same operations as glam's).
    let frag = |i: usize| frags.get(i).unwrap_or(&frags[0]);
    let normals = shade8::V3::from_lanes(simd, &std::array::from_fn(|i| frag(i).v.normal))
        .normalize_or(shade8::V3::splat(simd, Vec3::Z));
    let worlds = shade8::V3::from_lanes(simd, &std::array::from_fn(|i| frag(i).v.world));
    let to_eye = shade8::V3::splat(simd, scene.camera.eye).sub(worlds).normalize_or(normals);
    let (normals, to_eye) = (normals.lanes(), to_eye.lanes());
    for (i, f) in frags.iter().enumerate() {
        let lane = &mut lanes[i];
        begin_into(lane, prep, f, levels[i], normals[i], to_eye[i]);
        if traces(prep, lane) {
            rays[i] = Some(Ray::new(f.v.uv, lane.dir));
        }
        lods[i] = lane.lod;
    }
    if let Some(surface) = surface
        && rays.iter().any(Option::is_some)
    {
        let hits = packet::trace_packet(simd, surface, &rays, prep.technique, &prep.params, lods);
        for (lane, hit) in lanes.iter_mut().zip(&hits) {
            if let Some(hit) = hit {
                take_hit(prep, surface, lane, hit);
            }
        }
    }
    // Every light's shadow rays, a packet per light; the hard and soft ones marched together.
    let m = &prep.material;
    shadows.clear();
    for light in scene.lights.iter() {
        let Some(surface) = surface else { break };
        let mut done = [None; LANES];
        let mut marches = [None; LANES];
        for (i, (lane, f)) in lanes.iter().zip(frags).enumerate() {
            let Some(lt) = shadow_ray(prep, lane, f, light) else { continue };
            let p = TraceParams { lod: lane.lod, ..prep.params };
            match shadow_start(surface, lane.hit_uv, lane.hit_depth, lt, &m.shadow, &p) {
                ShadowStart::Done(s) => done[i] = Some(s),
                ShadowStart::March(march) => marches[i] = Some(march),
            }
        }
        if marches.iter().any(Option::is_some) {
            let marched = packet::shadow_marches(simd, surface, &marches);
            for (d, s) in done.iter_mut().zip(marched) {
                if s.is_some() {
                    *d = s;
                }
            }
        }
        shadows.push(done);
    }
    finish_packet(simd, scene, prep, shading, frags, &lanes, shadows, out);
}

/// Where the textures repeat, a UV's point in the tile (hit UVs are in the ray's own tile
/// frame): the filters then read inner texels without wrapping them one by one.
fn texture_uv(uv: Vec2, edges: EdgeMode) -> Vec2 {
    match edges {
        EdgeMode::Wrap => Vec2::new(uv.x - floor(uv.x), uv.y - floor(uv.y)),
        EdgeMode::Clamp => uv,
    }
}

/// [`finish`] for a packet of fragments (`lanes[i]` begun for every `frags[i]`), with the
/// shadows already traced (`shadows[light][lane]`): the texture filtering and lighting run on
/// all lanes at once ([`shade8`]), the pixel depth offset lane by lane.
#[expect(clippy::too_many_arguments, reason = "a packet's fragments, their state and the frame")]
#[inline(always)]
fn finish_packet<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    frags: &[Fragment],
    lanes: &[Lane; LANES],
    shadows: &[[Option<Shadow>; LANES]],
    out: &mut [Option<Sample>; LANES],
) {
    if frags.is_empty() {
        return;
    }
    // Lanes past the packet's fragments repeat the first (their results are not used).
    let lane = |i: usize| -> &Lane { if i < frags.len() { &lanes[i] } else { &lanes[0] } };
    let frag = |i: usize| frags.get(i).unwrap_or(&frags[0]);
    let pick = |g: fn(&Lane) -> Vec3| shade8::V3::from_lanes(simd, &std::array::from_fn(|i| g(lane(i))));
    let edges = prep.edges;
    let inputs = shade8::LitInputs {
        n: pick(|l| l.n),
        t: pick(|l| l.t),
        b: pick(|l| l.b),
        to_eye: pick(|l| l.to_eye),
        world: std::array::from_fn(|i| frag(i).v.world),
        albedo_lods: per_quad(frags, |f| albedo_level(&prep.albedo, f.duv_dx, f.duv_dy)),
        shadows,
    };
    let weight: [f32; LANES] = std::array::from_fn(|i| lane(i).weight);
    let with_shadows: [bool; LANES] = std::array::from_fn(|i| shadows_cast(prep) && weight[i] > 0.0);
    let hit_uv: [Vec2; LANES] = std::array::from_fn(|i| texture_uv(lane(i).hit_uv, edges));
    let (full, vis, shadow_fetches) = shade8::lit(simd, scene, prep, &inputs, &hit_uv, with_shadows);
    // The LOD fade's normal-mapped fallback, where it differs from the full result.
    let simple: [bool; LANES] = std::array::from_fn(|i| fades(prep, lane(i), frag(i), with_shadows[i]));
    let color = if simple.contains(&true) {
        let uv: [Vec2; LANES] = std::array::from_fn(|i| texture_uv(frag(i).v.uv, edges));
        let (plain, _, _) = shade8::lit(simd, scene, prep, &inputs, &uv, [false; LANES]);
        let faded = plain.lerp(full, packet::vec(simd, weight));
        shade8::V3::select(packet::mask(simd, simple), faded, full)
    } else {
        full
    };
    let color = color.lanes();
    for (i, f) in frags.iter().enumerate() {
        let l = lane(i);
        out[i] = Some(Sample {
            color: color[i],
            z: depth_offset(prep, shading, f, l),
            uv: l.hit_uv,
            depth: l.hit_depth,
            shadow: vis[i],
            fetches: (l.fetches + shadow_fetches[i]) as f32,
            lod: l.lod,
        });
    }
}

/// The direction toward `light` from the fragment, and the radiance arriving.
fn light_at(light: &Light, world: Vec3) -> (Vec3, Vec3) {
    match *light {
        Light::Directional { direction, color, intensity } => {
            (direction.try_normalize().unwrap_or(Vec3::Y), color * intensity)
        }
        Light::Point { position, color, intensity } => {
            let d = position - world;
            let d2 = d.length_squared().max(1e-8);
            (d / d2.sqrt(), color * intensity / d2)
        }
    }
}

/// Whether the fragment traces a shadow ray toward `light` in the full technique, and its
/// tangent-space direction.
fn shadow_ray(prep: &Prepared, lane: &Lane, f: &Fragment, light: &Light) -> Option<Vec3> {
    let (l, _) = light_at(light, f.v.world);
    let traced = shadows_cast(prep) && lane.weight > 0.0 && lane.n.dot(l) > 0.0;
    // The map takes a direction of travel; toward the light it is the same map.
    (traced && prep.material.shadow.mode != ShadowMode::None && prep.surface.is_some())
        .then(|| lane.map.map_or(Vec3::ZERO, |m| m.apply(l)))
}

/// Whether the fragment blends the full result with the LOD fade's normal-mapped fallback: below
/// full weight on a height map, unless the fallback is the same lighting at the same point
/// (no shadows, no offset), where `a.lerp(a, w)` would only round `a`.
fn fades(prep: &Prepared, lane: &Lane, f: &Fragment, with_shadows: bool) -> bool {
    lane.weight < 1.0 && prep.lod_basis.is_some() && (with_shadows || lane.hit_uv != f.v.uv)
}

/// The fragment's depth: the polygon's, or with a pixel depth offset the traced point's along
/// the view ray.
fn depth_offset(prep: &Prepared, shading: &Shading, f: &Fragment, lane: &Lane) -> f32 {
    let v = &f.v;
    let mut z = f.z;
    if prep.material.pixel_depth_offset && lane.ray_depth > 0.0 && lane.weight > 0.0 && prep.technique.displaces() {
        let l_world = (v.uv_scale.x * v.uv_scale.y).max(0.0).sqrt();
        let down = lane.ray_depth * prep.depth_scale * l_world; // world depth below the polygon
        let cos = lane.to_eye.dot(lane.n).max(1e-3);
        let p = v.world - lane.to_eye * (down / cos);
        let c = shading.depth_matrix * p.extend(1.0);
        if c.w > 0.0 {
            z = (c.z / c.w).max(f.z);
        }
    }
    z
}

/// Whether the material's full technique casts self-shadows.
fn shadows_cast(prep: &Prepared) -> bool {
    prep.technique.displaces() || prep.material.height.is_some() && prep.technique != Technique::Flat
}

/// The fragment stage after the trace: textures at the hit, lighting with the shadows
/// `shadow_of(light index, surface, world direction toward the light)` gives, the LOD fade and the
/// pixel depth offset.
fn finish(
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    f: &Fragment,
    lane: &Lane,
    mut shadow_of: impl FnMut(usize, &Surface, Vec3) -> Shadow,
) -> Sample {
    let m = &prep.material;
    let v = &f.v;
    let (n, t, b, to_eye) = (lane.n, lane.t, lane.b, lane.to_eye);
    let edges = prep.edges;
    let mut fetches = lane.fetches;
    let albedo_lod = albedo_level(&prep.albedo, f.duv_dx, f.duv_dy);
    let mut lit = |uv: Vec2, with_shadows: bool, fetches: &mut u32| -> (Vec3, f32) {
        // Where the textures repeat, their coordinates in the tile (hit UVs are in the ray's own
        // tile frame): the filter then reads inner texels without wrapping them one by one.
        let uv = texture_uv(uv, edges);
        let base = sample_albedo(&prep.albedo, uv, albedo_lod, edges) * m.base_color;
        let shading_n = match (&prep.normals, prep.technique) {
            (Some(nm), tq) if tq != Technique::Flat => {
                let mt = nm.sample(uv, edges);
                (t * mt.x + b * mt.y + n * mt.z).try_normalize().unwrap_or(n)
            }
            _ => n,
        };
        let mut c = scene.ambient * base;
        let mut first_vis = 1.0;
        for (li, light) in scene.lights.iter().enumerate() {
            let (l, radiance) = light_at(light, v.world);
            let n_dot_l = n.dot(l);
            let mut vis = if n_dot_l > 0.0 { 1.0 } else { 0.0 };
            if with_shadows
                && n_dot_l > 0.0
                && m.shadow.mode != ShadowMode::None
                && let Some(surface) = &prep.surface
            {
                let sh = shadow_of(li, surface, l);
                vis = sh.visibility;
                *fetches += sh.fetches;
            }
            if li == 0 {
                first_vis = vis;
            }
            let diffuse = shading_n.dot(l).max(0.0);
            let h = (l + to_eye).try_normalize().unwrap_or(shading_n);
            let spec = if diffuse > 0.0 { m.specular * shading_n.dot(h).max(0.0).powf(m.shininess) } else { 0.0 };
            c += (base * diffuse + Vec3::splat(spec)) * radiance * vis;
        }
        (c, first_vis)
    };
    let weight = lane.weight;
    let with_shadows = shadows_cast(prep) && weight > 0.0;
    let (full, vis) = lit(lane.hit_uv, with_shadows, &mut fetches);
    let color = if !fades(prep, lane, f, with_shadows) {
        full
    } else {
        let (simple, _) = lit(v.uv, false, &mut fetches);
        simple.lerp(full, weight)
    };
    let z = depth_offset(prep, shading, f, lane);
    Sample { color, z, uv: lane.hit_uv, depth: lane.hit_depth, shadow: vis, fetches: fetches as f32, lod: lane.lod }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pomkit_core::demo::demo_scene_sized;

    /// The bytes a [`RenderOutput`]'s buffers hold, from their lengths and element sizes.
    fn output_buffer_bytes(out: &RenderOutput) -> u64 {
        let mut bytes = out.color.len() * std::mem::size_of::<Vec3>();
        if let Some(a) = &out.aovs {
            bytes += a.uv.len() * 8 + (a.depth.len() + a.shadow.len() + a.fetches.len() + a.lod.len()) * 4;
        }
        bytes as u64
    }

    /// Every triangle `surely_back_facing` rejects, `setup` culls too: small and long
    /// triangles, nearly degenerate ones whose winding only the snap decides, anywhere on a
    /// 1280x720 frame and beyond its edges, at random depths.
    #[test]
    fn what_surely_faces_away_setup_culls() {
        let view = DisplacementView { view_proj: Mat4::IDENTITY, size: Vec2::new(1280.0, 720.0), tolerance: 0.125 };
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rand = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut rejected, mut back) = (0, 0);
        for k in 0..200_000 {
            let w = 0.2 + 5.0 * rand();
            let centre = Vec2::new(rand() * 2.4 - 1.2, rand() * 2.4 - 1.2);
            // Sizes from a tenth of a sample to a few hundred samples.
            let reach = 10f32.powf(rand() * 3.5 - 1.0) / 640.0;
            let mut corner = || {
                let p = centre + (Vec2::new(rand(), rand()) - 0.5) * reach;
                Vec4::new(p.x * w, p.y * w, rand() * w, w)
            };
            let mut clip = [corner(), corner(), corner()];
            if k % 4 == 0 {
                // Nearly on a line: the third corner close to the middle of the other two.
                let mid = (clip[0] + clip[1]) * 0.5;
                clip[2] = mid + Vec4::new(rand() - 0.5, rand() - 0.5, 0.0, 0.0) * (reach * w * 1e-3);
            }
            let [a, b, c] = clip.map(|c| view.screen(c));
            let tri = clip.map(|clip| ClipVertex { clip, v: Varyings::default() });
            let culled = setup(&tri, 1280, 720, 0, true).is_none();
            back += usize::from(culled);
            if surely_back_facing(a, b, c) {
                rejected += 1;
                assert!(culled, "{clip:?}: surely facing away, yet set up");
            }
        }
        // About half face away (and some are degenerate or off the frame, which it leaves to
        // setup): the test is not vacuous.
        assert!(rejected > back / 3, "{rejected} of {back} culled triangles rejected");
    }

    /// A block is hidden only when every sample it may cover, inside the tile, holds something
    /// at least `Z_MARGIN` nearer than its least depth.
    #[test]
    fn a_block_is_occluded_only_behind_a_full_cover() {
        let tile = [10, 20, 18, 24];
        let depth = |x: u32, y: u32| if (x, y) == (15, 22) { 0.5 } else { 0.3 };
        let at = |i: usize| (10 + (i % 8) as u32, 20 + (i / 8) as u32);
        let holds = |i: usize, z: f32| {
            let (x, y) = at(i);
            depth(x, y) <= z
        };
        // Reaching past the tile does not matter: only its own samples are read.
        assert!(occluded([0, 0, 15, 100], 0.4, tile, holds));
        assert!(!occluded([0, 0, 16, 100], 0.4, tile, holds), "the sample at depth 0.5 is not nearer");
        assert!(occluded([0, 0, 16, 100], 0.6, tile, holds));
        assert!(!occluded([0, 0, 15, 100], 0.3, tile, holds), "equal depths within the margin do not hide");
        assert!(!occluded([0, 0, 15, 100], f32::INFINITY, tile, holds), "a block that covers nothing is not tested");
        assert!(!occluded([30, 0, 40, 100], 0.9, tile, holds), "no sample in the tile: drawn as binned");
    }

    #[test]
    fn a_renderer_reuses_albedo_chains_only_for_the_same_live_texture() {
        let opts = RenderOptions { width: 48, height: 27, ..Default::default() };
        let mut scene = demo_scene_sized(32);
        let fresh = |scene: &Scene| CpuRenderer::new().render(scene, &opts, &|_, _| {}).unwrap().color;
        let mut r = CpuRenderer::new();
        let first = r.render(&scene, &opts, &|_, _| {}).unwrap().color;
        let textured = scene.materials.iter().filter(|m| m.albedo.is_some()).count();
        assert!(textured > 0 && r.albedo.chains.len() == textured, "{} chains", r.albedo.chains.len());
        assert_eq!(r.render(&scene, &opts, &|_, _| {}).unwrap().color, first);
        // A new texture (here: another one's, darkened) is a new chain, never a stale one.
        for m in &mut scene.materials {
            if let Some(t) = &m.albedo {
                let dark: Vec<Vec3> = t.texels().iter().map(|c| *c * 0.25).collect();
                m.albedo = Some(Arc::new(Texture::new(t.width(), t.height(), dark).unwrap()));
            }
        }
        let second = r.render(&scene, &opts, &|_, _| {}).unwrap().color;
        assert_ne!(second, first);
        assert_eq!(second, fresh(&scene));
        // The first textures are gone: so are their chains.
        assert_eq!(r.albedo.chains.len(), textured);
    }

    #[test]
    fn the_coarsest_level_is_the_mip_chains() {
        for (w, h) in [(1, 1), (2, 1), (512, 512), (640, 48), (3, 7), (1, 1000)] {
            let chain = pomkit_core::MipChain::new(pomkit_core::HeightField::constant(w, h, 0.5));
            assert_eq!(coarsest_level(w, h), chain.max_level(), "{w}x{h}");
        }
    }

    #[test]
    fn the_frame_estimate_bounds_the_real_output_within_2x() {
        let scene = demo_scene_sized(32);
        for (aovs, ss) in [(false, 1), (true, 1), (true, 3)] {
            let opts = RenderOptions { width: 48, height: 20, aovs, supersample: ss, ..Default::default() };
            let out = CpuRenderer::new().render(&scene, &opts, &|_, _| {}).unwrap();
            let real = output_buffer_bytes(&out);
            // 12 bytes a pixel of colour, 24 more with the AOVs: 48 * 20 * 36 = 34,560.
            assert_eq!(real, 48 * 20 * if aovs { 36 } else { 12 });
            let est = estimate(&scene, &opts);
            let frame = est.part("frame");
            assert!(frame >= real && frame <= 2 * real, "frame estimate {frame} against {real} bytes");
            // The samples of one band in flight are at least a band's worth of Option<Sample>.
            let band = 48 * u64::from(ss) * u64::from(BAND.min(20)) * u64::from(ss) * 44;
            assert!(est.part("sample bands") >= band, "{est:?}");
            assert!(est.total() >= frame + est.part("triangles"));
        }
    }

    #[test]
    fn the_displaced_estimate_bounds_the_real_blocks_within_3x_and_stays_small() {
        let scene = demo_scene_sized(32);
        let opts = RenderOptions { width: 48, height: 20, mode: Mode::Displaced, ..Default::default() };
        let bound = geometry_counts(&scene, &opts).blocks;
        let real: usize = scene
            .objects
            .iter()
            .map(|obj| {
                let m = &scene.materials[obj.material];
                let f = m.height.as_deref().unwrap();
                obj.mesh.displaced_blocks(f, m.edges, m.depth_scale, opts.displaced_edge_texels, None).len()
            })
            .sum();
        assert!(bound >= real as u64 && bound <= 3 * real as u64, "{bound} against {real} blocks");
        let est = estimate(&scene, &opts);
        assert_eq!(est.part("displaced blocks"), bound * BLOCK_BYTES);
        // Streamed, nothing of the subdivision is set up whole: no screen triangles.
        assert_eq!(geometry_counts(&scene, &opts).triangles, 0);
        // The demo's reference at 1920x1080 (32 million triangles subdivided) fits in 1 GiB
        // with room to spare, and the render itself works.
        let full = demo_scene_sized(512);
        let big = RenderOptions { width: 1920, height: 1080, ..opts };
        assert!(estimate(&full, &big).total() < 600 << 20, "{:?}", estimate(&full, &big));
        let out = CpuRenderer::new().render(&scene, &opts, &|_, _| {}).unwrap();
        assert!(out.covered > 0);
    }
}
