//! The streamed displaced reference: in [`Mode::Displaced`] every height-mapped object is
//! tessellated to its height map's resolution and its vertices moved for real, a block of
//! triangles at a time ([`DisplacedBlocks`]). Here: which objects are streamed, each block's
//! vertex stage and screen bounds, the occlusion test that skips a block hidden behind what a
//! tile already holds, and the conservative back-face and sample-centre tests that spare most
//! of a block's triangles their set-up.

use glam::{Vec2, Vec3};
use pomkit_core::heightfield::floor;
use pomkit_core::mesh::{DisplacedBlock, DisplacedBlocks, DisplacementView, Mesh};
use pomkit_core::scene::{Material, Scene};

use crate::prepare::Prepared;
use crate::raster::{self, ClipVertex, ScreenTriangle, Varyings, clip_near, needs_clipping, setup};
use crate::{Mode, RenderOptions};

/// Whether an object of `material` is drawn as streamed displaced geometry
/// ([`DisplacedObject`]): the displaced reference of a height-mapped material.
pub(crate) fn is_streamed(material: &Material, opts: &RenderOptions) -> bool {
    opts.mode == Mode::Displaced && material.height.is_some()
}

/// The world-space meshes of the objects drawn as streamed displaced geometry, with their
/// indices in the scene.
pub(crate) fn streamed_meshes(scene: &Scene, prepared: &[Prepared], opts: &RenderOptions) -> Vec<(u32, Mesh)> {
    scene
        .objects
        .iter()
        .enumerate()
        .filter(|(_, obj)| is_streamed(&prepared[obj.material].material, opts))
        .map(|(oi, obj)| (oi as u32, obj.mesh.transformed(obj.transform)))
        .collect()
}

/// A height-mapped object of the displaced reference: its subdivided, displaced triangles in
/// blocks made on demand ([`DisplacedBlocks`]), in world space.
pub(crate) struct DisplacedObject<'a> {
    /// The object's index in the scene.
    pub(crate) object: u32,
    pub(crate) blocks: DisplacedBlocks<'a>,
}

/// Every [`DisplacedObject`] of a frame, and the view they are drawn in (its view-projection
/// takes their blocks to clip space).
pub(crate) struct DisplacedGeometry<'a> {
    pub(crate) objects: Vec<DisplacedObject<'a>>,
    pub(crate) view: DisplacementView,
}

/// The samples a streamed block may cover, `[x0, y0, x1, y1]` (end exclusive), and its least
/// NDC depth.
pub(crate) type BlockSamples = ([u32; 4], f32);

/// A block's vertices after the vertex stage, reused from block to block.
#[derive(Default)]
pub(crate) struct BlockVertices {
    block: DisplacedBlock,
    clip: Vec<ClipVertex>,
    /// Screen positions (samples) of the vertices in front of the near plane.
    screen: Vec<Vec2>,
    /// Per vertex, whether it is in front of the near plane and inside the guard band
    /// ([`raster::unclipped`]).
    unclipped: Vec<bool>,
}

impl<'a> DisplacedGeometry<'a> {
    /// The blocks of `meshes` ([`streamed_meshes`]), planned for `view`.
    pub(crate) fn new(
        scene: &Scene,
        prepared: &'a [Prepared],
        opts: &RenderOptions,
        meshes: &'a [(u32, Mesh)],
        view: DisplacementView,
    ) -> Self {
        let objects = meshes
            .iter()
            .filter_map(|(oi, world)| {
                let prep = &prepared[scene.objects[*oi as usize].material];
                let field = prep.material.height.as_deref()?;
                let blocks =
                    world.displaced_blocks(field, prep.edges, prep.depth_scale, opts.displaced_edge_texels, Some(view));
                Some(DisplacedObject { object: *oi, blocks })
            })
            .collect();
        Self { objects, view }
    }

    /// Makes block `b` of displaced object `o` and runs the vertex stage on it. For displaced
    /// geometry the normals are the undisplaced surface's (`Mesh::displaced_for_shading`): the
    /// normal map adds the bumps, as for every parallax technique.
    pub(crate) fn make_block(&self, o: usize, b: usize, out: &mut BlockVertices) {
        self.objects[o].blocks.block(b, &mut out.block);
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

    /// The samples block `b` of displaced object `o` may cover, `(x0, y0, x1, y1)` (end
    /// exclusive), and its least depth; `None` when it covers none (off screen, behind the
    /// camera, or facing away).
    pub(crate) fn block_samples(
        &self,
        o: usize,
        b: usize,
        (sw, sh): (u32, u32),
        v: &mut BlockVertices,
    ) -> Option<BlockSamples> {
        let (lo, hi, min_z) = match self.objects[o].blocks.screen_bounds(b) {
            Some(known) => (known.min, known.max, known.min_z),
            None => self.bounds_by_making(o, b, (sw, sh), v)?,
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

    /// [`DisplacedGeometry::block_samples`] by making the block: the box of its front-facing
    /// triangles.
    fn bounds_by_making(
        &self,
        o: usize,
        b: usize,
        (sw, sh): (u32, u32),
        v: &mut BlockVertices,
    ) -> Option<(Vec2, Vec2, f32)> {
        // Positions only (the same bits as `make_block` makes): the varyings are not needed
        // here.
        self.objects[o].blocks.block_positions(b, &mut v.block);
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

    /// Makes block `b` of displaced object `o` (into `block`) and sets up, for the tile
    /// `[x0, x1) x [y0, y1)` of a `sw x sh`-sample frame, its triangles that may cover a
    /// sample of the tile, handing each to `draw`. With `cull_back_faces`, the triangles that
    /// [`is_surely_back_facing`] rejects are skipped before their set-up (which would cull them).
    #[expect(clippy::too_many_arguments, reason = "the block, the tile and the frame")]
    pub(crate) fn draw_block(
        &self,
        o: usize,
        b: usize,
        [x0, y0, x1, y1]: [u32; 4],
        (sw, sh): (u32, u32),
        cull_back_faces: bool,
        block: &mut BlockVertices,
        mut draw: impl FnMut(&ScreenTriangle),
    ) {
        self.make_block(o, b, block);
        let object = self.objects[o].object;
        // Pixel centres a triangle can cover lie within its vertices' extent.
        let (fx0, fy0, fx1, fy1) = (x0 as f32 - 1.0, y0 as f32 - 1.0, x1 as f32 + 1.0, y1 as f32 + 1.0);
        for tri in &block.block.triangles {
            if !tri.iter().all(|&k| block.unclipped[k as usize]) {
                let t = tri.map(|k| block.clip[k as usize]);
                for c in clip_near(t) {
                    if let Some(st) = setup(&c, sw, sh, object, true) {
                        draw(&st);
                    }
                }
                continue;
            }
            let [a, b, c] = tri.map(|k| block.screen[k as usize]);
            let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
            if hi.x < fx0 || lo.x > fx1 || hi.y < fy0 || lo.y > fy1 || !may_hold_a_centre(lo, hi) {
                continue;
            }
            if cull_back_faces && is_surely_back_facing(a, b, c) {
                continue;
            }
            let t = tri.map(|k| block.clip[k as usize]);
            if let Some(st) = setup(&t, sw, sh, object, true) {
                draw(&st);
            }
        }
    }
}

/// Whether every sample of `rect` (a block's samples, end exclusive) inside the tile
/// `[x0, x1) x [y0, y1)` already holds a fragment at depth `z` or nearer (`holds(at, z)`, `at`
/// the sample's index in the tile), `z` being `min_z` (the least depth of anything in the
/// block) less [`Z_MARGIN`]: then every fragment of the block fails the depth test (a fragment
/// is kept only when strictly nearer) and the block need not be made.
pub(crate) fn is_occluded(
    rect: [u32; 4],
    min_z: f32,
    [x0, y0, x1, y1]: [u32; 4],
    holds: impl Fn(usize, f32) -> bool,
) -> bool {
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

/// How far below a block's least vertex depth (NDC, in `[0, 1]`) [`is_occluded`] looks: a
/// fragment's depth, interpolated in f32 from its triangle's vertices, can fall an ulp or two
/// below the least of them.
const Z_MARGIN: f32 = 1e-6;

/// Whether the triangle with screen positions `a`, `b`, `c` (samples, y down, in f32, as
/// [`DisplacementView::screen`] gives them) faces away so clearly that [`setup`], which decides
/// on the positions computed in f64 and snapped to 1/256 sample, culls it too. For positions
/// within `[-64, 4096)` (else it does not tell) the two differ by less than `D = 1/512 + 1/256`
/// sample per coordinate (the snap, and a few roundings of f32 below 4096), which changes twice
/// the signed area by at most `2 D (|b - a|_1 + |c - a|_1) + 8 D^2`: the margin is larger.
fn is_surely_back_facing(a: Vec2, b: Vec2, c: Vec2) -> bool {
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
fn may_hold_a_centre(lo: Vec2, hi: Vec2) -> bool {
    const MARGIN: f32 = 1.0 / 64.0;
    // (`floor`, not `f32::floor`: no call into libm on baseline x86-64.)
    let ceil = |x: f32| -floor(-x);
    let holds = |lo: f32, hi: f32| ceil(lo - (0.5 + MARGIN)) <= floor(hi - (0.5 - MARGIN));
    holds(lo.x, hi.x) && holds(lo.y, hi.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Vec4};

    /// Every triangle `is_surely_back_facing` rejects, `setup` culls too: small and long
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
            if is_surely_back_facing(a, b, c) {
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
        assert!(is_occluded([0, 0, 15, 100], 0.4, tile, holds));
        assert!(!is_occluded([0, 0, 16, 100], 0.4, tile, holds), "the sample at depth 0.5 is not nearer");
        assert!(is_occluded([0, 0, 16, 100], 0.6, tile, holds));
        assert!(!is_occluded([0, 0, 15, 100], 0.3, tile, holds), "equal depths within the margin do not hide");
        assert!(!is_occluded([0, 0, 15, 100], f32::INFINITY, tile, holds), "a block that covers nothing is not tested");
        assert!(!is_occluded([30, 0, 40, 100], 0.9, tile, holds), "no sample in the tile: drawn as binned");
    }
}
