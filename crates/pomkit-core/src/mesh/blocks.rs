//! The displaced reference a block at a time: [`Mesh::displaced_blocks`] hands a renderer the
//! triangles of [`Mesh::displaced_for_shading`] in small blocks made on demand, so that memory
//! does not grow with the subdivision, and, given the view, coarsens each block as far as the
//! picture allows.
//!
//! # Coarsening for a view
//!
//! With a [`DisplacementView`], a block whose surface is smooth enough on screen is made with
//! every second, fourth or eighth grid line of the subdivision (its *stride*). The test is
//! geometric: the coarse surface interpolates the fine one linearly, so at a fine grid point it
//! is off by `|d - d_coarse| * depth_scale * L` world units along the normal, where `d` is the
//! field's depth there and `d_coarse` the coarse triangle's interpolation of the depths at its
//! corners. On screen that is at most `|d - d_coarse|` times the projected length of the full
//! depth `depth_scale * L` at the block's corners. A block takes the largest stride whose worst
//! grid point stays within [`DisplacementView::tolerance`] samples; a flat or gently sloping
//! block far away coarsens, a brick's mortar edge seen close does not.
//!
//! Neighbouring blocks may take different strides. Each side a block shares with another has a
//! stride of its own, decided by the same test on the side's own points and ends (so both blocks
//! compute the same), never finer than either block's (the side's points and ends are among
//! each block's); a block's grid points on a coarser side snap to the side's points, as the
//! subdivision's vertices snap on an edge with fewer parts. So the blocks stay watertight.
//! Blocks that touch an edge of the input triangle are never coarsened, which leaves the
//! stitching between input triangles as it is without a view.

use std::borrow::Cow;
use std::sync::OnceLock;

use glam::{Mat4, Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::displace::{GridPoint, SubdivisionPlan, displace};
use super::ranges::DepthRanges;
use super::{MAX_DISPLACED_TRIANGLES, MIN_EDGE_TEXELS, Mesh, fix_tangent, uv_unit_length};
use crate::heightfield::{EdgeMode, HeightField};
use glam::DVec2;

/// Grid cells per side of a [`DisplacedBlocks`] block: a block holds at most
/// `2 * BLOCK_CELLS^2` triangles and `(BLOCK_CELLS + 1)^2` vertices.
pub const BLOCK_CELLS: u32 = 8;

/// The strides a block or side may take, coarsest first (each divides [`BLOCK_CELLS`]).
const STRIDES: [u32; 3] = [8, 4, 2];

/// The view a [`DisplacedBlocks`] is drawn in, which lets it coarsen where the screen cannot
/// tell (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplacementView {
    /// World to clip space (wgpu's conventions: visible depth `0 <= z <= w`), for the mesh the
    /// blocks are made of.
    pub view_proj: Mat4,
    /// The viewport in samples (pixels times supersampling).
    pub size: Vec2,
    /// The most samples the coarsened surface may lie from the full subdivision's on screen.
    pub tolerance: f32,
}

impl DisplacementView {
    /// The screen position (samples, y down) of a clip-space position, divided by its `w`
    /// whatever its sign (meaningful in front of the near plane only).
    #[must_use]
    pub fn screen(&self, c: Vec4) -> Vec2 {
        Vec2::new((c.x / c.w * 0.5 + 0.5) * self.size.x, (0.5 - c.y / c.w * 0.5) * self.size.y)
    }

    /// The screen position (samples) of a world point, when it lies in front of the near plane.
    fn project(&self, p: Vec3) -> Option<Vec2> {
        let c = self.view_proj * p.extend(1.0);
        (c.z >= 0.0 && c.w > 1e-6 && c.is_finite()).then(|| self.screen(c))
    }

    /// The screen box and least NDC depth of world `points`, which hold the projection of their
    /// convex hull (and its least depth, a ratio of affine functions, at one of them) when all
    /// lie in front of the near plane; `None` when one does not.
    fn hull_bounds(&self, points: impl IntoIterator<Item = Vec3>) -> Option<ScreenBounds> {
        let mut out = ScreenBounds { min: Vec2::splat(f32::INFINITY), max: Vec2::splat(f32::NEG_INFINITY), min_z: 1.0 };
        for q in points {
            let clip = self.view_proj * q.extend(1.0);
            let s = self.project(q)?;
            out.min = out.min.min(s);
            out.max = out.max.max(s);
            out.min_z = out.min_z.min(clip.z / clip.w);
        }
        Some(out)
    }
}

/// The triangles of [`Mesh::displaced_for_shading`], made a small block at a time instead of all
/// at once, so that a renderer can stream them (generate a block, draw it, forget it). Made by
/// [`Mesh::displaced_blocks`].
///
/// Without a view, the blocks together hold exactly the triangles of
/// [`Mesh::displaced_for_shading`] with the same arguments, with bit-identical vertices (each
/// vertex is a function of where it lies in the subdivision, computed the same way by every
/// block and triangle that shares it, so the blocks are as watertight as the mesh). Block `b` of
/// triangle `t` covers the cells `i0 <= i < i0 + BLOCK_CELLS`, `j0 <= j < j0 + BLOCK_CELLS` of
/// its barycentric grid. With a view, blocks may be coarser (module docs).
#[derive(Debug)]
pub struct DisplacedBlocks<'a> {
    mesh: Cow<'a, Mesh>,
    plan: SubdivisionPlan,
    field: &'a HeightField,
    edges: EdgeMode,
    depth_scale: f32,
    view: Option<DisplacementView>,
    /// Per block: the triangle, and the first grid column and row of its cells.
    blocks: Vec<[u32; 3]>,
    /// Per block with a view: its strides and maybe its screen bounds (empty without a view);
    /// planned up front, except the blocks of flat triangles facing away, which are planned
    /// when first made (they are seldom drawn: the back of a closed object).
    plans: Vec<OnceLock<BlockPlan>>,
    /// The field's least and greatest depth (with a view).
    depth_range: (f32, f32),
    /// Depth bounds over boxes of UV (with a view).
    ranges: Option<DepthRanges>,
    triangles: u64,
}

/// One block of a [`DisplacedBlocks`]: displaced vertices (with the interpolated normals and
/// orthogonalized tangents of the undisplaced surface, as [`Mesh::displaced_for_shading`] gives)
/// and the triangles over them, wound as the input's. Reused from block to block.
#[derive(Clone, Debug, Default)]
pub struct DisplacedBlock {
    /// Displaced positions.
    pub positions: Vec<Vec3>,
    /// The undisplaced surface's interpolated normals.
    pub normals: Vec<Vec3>,
    /// Texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Tangents, perpendicular to `normals`, handedness in `w`.
    pub tangents: Vec<Vec4>,
    /// World units per UV unit of the undisplaced surface.
    pub uv_scale: Vec<Vec2>,
    /// The field's depth at each vertex (0 = surface, 1 = deepest), as displaced.
    pub depths: Vec<f32>,
    /// Triangles, as indices into the vertices.
    pub triangles: Vec<[u32; 3]>,
    /// The grid lines the block was made with: 1 (every line of the subdivision), 2, 4 or 8.
    pub stride: u32,
    /// Per grid point of the block, its vertex (`u32::MAX`: not made yet) and where it lies.
    slots: Vec<(u32, GridPoint)>,
}

/// A block's plan for the view: its stride, its sides' strides (`LEFT`, `RIGHT`, `BOTTOM`,
/// `TOP`) and, when known without making it, its screen bounds.
#[derive(Clone, Copy, Debug)]
struct BlockPlan {
    stride: u32,
    sides: [u32; 4],
    bounds: Option<ScreenBounds>,
}

/// A box on screen holding a block's projected vertices, and their least depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenBounds {
    /// The least screen position (samples, y down).
    pub min: Vec2,
    /// The greatest screen position.
    pub max: Vec2,
    /// The least NDC depth.
    pub min_z: f32,
}

/// The sides of a block, in the order [`DisplacedBlocks::strides`] gives their strides.
const LEFT: usize = 0;
const RIGHT: usize = 1;
const BOTTOM: usize = 2;
const TOP: usize = 3;

impl Mesh {
    /// [`Mesh::displaced_for_shading`]'s triangles as blocks made on demand
    /// ([`DisplacedBlocks`]); only the plan (which edge splits into how many parts) and a list
    /// of blocks (12 bytes per up to `2 * BLOCK_CELLS^2` triangles) are held. With `view`,
    /// blocks coarsen where it cannot be seen (see [`DisplacementView`]).
    #[must_use]
    pub fn displaced_blocks<'a>(
        &'a self,
        field: &'a HeightField,
        edges: EdgeMode,
        depth_scale: f32,
        max_edge_texels: f32,
        view: Option<DisplacementView>,
    ) -> DisplacedBlocks<'a> {
        let mesh = self.repaired();
        let depth_scale = if depth_scale.is_finite() && depth_scale > 0.0 { depth_scale } else { 0.0 };
        let max_edge = if max_edge_texels.is_nan() { 1.0 } else { max_edge_texels.max(MIN_EDGE_TEXELS) };
        let plan =
            SubdivisionPlan::new(&mesh, field.size_f32().as_dvec2(), f64::from(max_edge), MAX_DISPLACED_TRIANGLES);
        let view = view.filter(|v| v.view_proj.is_finite() && v.size.is_finite() && v.tolerance > 0.0);
        let mut plan = plan;
        if let Some(view) = &view {
            coarsen_plan(&mut plan, &mesh, field, edges, depth_scale, view);
        }
        let mut blocks = Vec::new();
        let mut triangles = 0u64;
        for t in 0..plan.triangles.len() {
            let n = plan.triangle_parts(t);
            triangles += u64::from(n) * u64::from(n);
            for j0 in (0..n).step_by(BLOCK_CELLS as usize) {
                for i0 in (0..n - j0).step_by(BLOCK_CELLS as usize) {
                    blocks.push([t as u32, i0, j0]);
                }
            }
        }
        // (Only the view's planning reads it.)
        let depth_range = if view.is_some() { depth_range(field.depths()) } else { (0.0, 0.0) };
        let mut out = DisplacedBlocks {
            mesh,
            plan,
            field,
            edges,
            depth_scale,
            view,
            blocks,
            plans: Vec::new(),
            depth_range,
            ranges: view.is_some().then(|| DepthRanges::new(field, edges)),
            triangles,
        };
        // Every block's strides, decided once (each is a function of the block alone, so the
        // blocks sharing a side agree whenever each is planned).
        if let Some(view) = out.view {
            let away: Vec<bool> = (0..out.plan.triangles.len()).map(|t| out.faces_away(t, &view)).collect();
            let plans: Vec<OnceLock<BlockPlan>> = (0..out.blocks.len())
                .into_par_iter()
                .map_init(Vec::new, |fine, b| {
                    let t = out.blocks[b][0] as usize;
                    if away[t] { OnceLock::new() } else { OnceLock::from(out.plan_block(b, fine)) }
                })
                .collect();
            out.plans = plans;
        }
        out
    }
}

impl DisplacedBlocks<'_> {
    /// The number of blocks.
    #[must_use]
    pub fn len(&self) -> usize {
        self.blocks.len()
    }

    /// Whether there are no blocks (a mesh without triangles).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// An upper bound on the triangles of all blocks together (`n^2` per input triangle split
    /// into `n` parts).
    #[must_use]
    pub fn triangle_bound(&self) -> u64 {
        self.triangles
    }

    /// Fills `out` with block `index` (`< len()`; a larger one gives an empty block).
    pub fn block(&self, index: usize, out: &mut DisplacedBlock) {
        self.make::<true>(index, out);
    }

    /// [`DisplacedBlocks::block`]'s positions and triangles only (the other attributes of `out`
    /// are left empty), for a renderer that needs to know where a block is on screen before
    /// it draws it: the same bits as `block` gives, at a fraction of the cost (no tangent
    /// frame).
    pub fn block_positions(&self, index: usize, out: &mut DisplacedBlock) {
        self.make::<false>(index, out);
    }

    /// [`DisplacedBlocks::block`] (`FULL`) or [`DisplacedBlocks::block_positions`].
    fn make<const FULL: bool>(&self, index: usize, out: &mut DisplacedBlock) {
        out.positions.clear();
        out.normals.clear();
        out.uvs.clear();
        out.tangents.clear();
        out.uv_scale.clear();
        out.depths.clear();
        out.triangles.clear();
        out.slots.clear();
        out.stride = 1;
        let Some(&[t, i0, j0]) = self.blocks.get(index) else { return };
        let (mesh, plan, t) = (self.mesh.as_ref(), &self.plan, t as usize);
        let n = plan.triangle_parts(t);
        let face = plan.face(mesh, t);
        let (i1, j1) = ((i0 + BLOCK_CELLS).min(n), (j0 + BLOCK_CELLS).min(n));
        let (s, sides) = self.plan_of(index).map_or((1, [1; 4]), |p| (p.stride, p.sides));
        out.stride = s;
        let width = (BLOCK_CELLS + 1) as usize;
        out.slots.resize(width * width, (u32::MAX, GridPoint::Vertex(u32::MAX)));
        // A grid point on a side coarser than the block moves to the side's nearest point.
        let snap = |i: u32, j: u32| -> (u32, u32) {
            let round = |x: u32, from: u32, s: u32| from + (x - from + s / 2) / s * s;
            if i == i0 && sides[LEFT] > 1 {
                (i, round(j, j0, sides[LEFT]))
            } else if i == i1 && sides[RIGHT] > 1 {
                (i, round(j, j0, sides[RIGHT]))
            } else if j == j0 && sides[BOTTOM] > 1 {
                (round(i, i0, sides[BOTTOM]), j)
            } else if j == j1 && sides[TOP] > 1 {
                (round(i, i0, sides[TOP]), j)
            } else {
                (i, j)
            }
        };
        let vertex = |out: &mut DisplacedBlock, i: u32, j: u32| -> (u32, GridPoint) {
            let (i, j) = snap(i, j);
            let slot = (j - j0) as usize * width + (i - i0) as usize;
            if out.slots[slot].0 == u32::MAX {
                let g = plan.grid_point(t, i, j, n);
                let v = plan.blend(mesh, t, g, n, face);
                let (p, depth) =
                    displace(v.position, v.normal, v.uv, v.uv_scale, self.field, self.edges, self.depth_scale);
                out.slots[slot] = (out.positions.len() as u32, g);
                out.positions.push(p);
                if FULL {
                    out.normals.push(v.normal);
                    out.uvs.push(v.uv);
                    out.tangents.push(fix_tangent(v.tangent, v.normal));
                    out.uv_scale.push(v.uv_scale);
                    out.depths.push(depth);
                }
            }
            out.slots[slot]
        };
        let push = |out: &mut DisplacedBlock, tri: [(u32, GridPoint); 3]| {
            if tri[0].1 != tri[1].1 && tri[1].1 != tri[2].1 && tri[0].1 != tri[2].1 {
                out.triangles.push(tri.map(|(v, _)| v));
            }
        };
        // Cells of `s x s` grid cells (only whole blocks inside the triangle coarsen, so with
        // s > 1 every cell is whole).
        for j in (j0..j1).step_by(s as usize) {
            for i in (i0..i1.min(n - j)).step_by(s as usize) {
                let (a, b, c) = (vertex(out, i, j), vertex(out, i + s, j), vertex(out, i, j + s));
                push(out, [a, b, c]);
                if i + j + s < n {
                    let d = vertex(out, i + s, j + s);
                    push(out, [b, d, c]);
                }
            }
        }
    }

    /// The stride of block `[i0, j0, i1, j1]` of triangle `t` (split into `n` parts) and of its
    /// sides (`LEFT`, `RIGHT`, `BOTTOM`, `TOP`): 1 everywhere without a view.
    ///
    /// In steps: which of the block and its sides may coarsen at all ([`coarsenable`]); a block
    /// out of view; a block too shallow to show its relief ([`DisplacedBlocks::shallow_block`]);
    /// otherwise the field sampled at the block's grid points ([`DisplacedBlocks::sample_grid`])
    /// and the coarsest stride each side ([`side_stride`]) and the block ([`block_stride`]) can
    /// take within the view's tolerance.
    fn strides(&self, t: usize, block: [u32; 4], n: u32, face: Vec3, fine: &mut Vec<f32>) -> BlockPlan {
        let fine_block = BlockPlan { stride: 1, sides: [1; 4], bounds: None };
        let Some(view) = &self.view else { return fine_block };
        let Some((side_ok, block_ok)) = coarsenable(block, n) else { return fine_block };
        let [i0, j0, i1, j1] = block;
        let (mesh, plan) = (self.mesh.as_ref(), &self.plan);
        // The corners, undisplaced.
        let corners = [(i0, j0), (i1, j0), (i0, j1), (i1, j1)];
        let blended =
            corners.map(|(i, j)| (i + j <= n).then(|| plan.blend(mesh, t, plan.grid_point(t, i, j, n), n, face)));
        if block_ok && self.outside_view(t, &blended, view) {
            // Never drawn: no strides to plan, and bounds that bin it nowhere. (A neighbour may
            // give their common side another stride: the side is out of view too.)
            let nowhere = ScreenBounds { min: Vec2::INFINITY, max: Vec2::NEG_INFINITY, min_z: 1.0 };
            return BlockPlan { stride: 1, sides: [1; 4], bounds: Some(nowhere) };
        }
        let [ua, ub, uc] = plan.triangles[t].map(|v| mesh.uvs[v as usize]);
        let inv = 1.0 / n as f32;
        let uv_at = |i: u32, j: u32| ua + (ub - ua) * (i as f32 * inv) + (uc - ua) * (j as f32 * inv);
        // The projected length of the full depth at each corner, in samples.
        let reaches: [Option<f32>; 4] = blended.map(|v| {
            let v = v?;
            let down = v.normal * (self.depth_scale * uv_unit_length(v.uv_scale));
            Some(view.project(v.position)?.distance(view.project(v.position - down)?))
        });
        // The largest of them, when all are known.
        let reach = reaches.iter().try_fold(0.0f32, |m, r| r.map(|r| m.max(r)));
        let tol = view.tolerance;
        if block_ok && let Some(shallow) = self.shallow_block(t, block, &uv_at, reach, &blended, view) {
            return shallow;
        }
        self.sample_grid(block, n, &uv_at, fine);
        let k = BLOCK_CELLS;
        let width = (k + 1) as usize;
        let f = |a: u32, b: u32| fine[b as usize * width + a as usize];
        let side = |ends: [usize; 2], at: &dyn Fn(u32) -> f32| -> u32 {
            let (Some(r0), Some(r1)) = (reaches[ends[0]], reaches[ends[1]]) else { return 1 };
            side_stride(at, r0.max(r1), tol)
        };
        let mut sides = [1; 4];
        if side_ok[LEFT] {
            sides[LEFT] = side([0, 2], &|x| f(0, x));
        }
        if side_ok[RIGHT] {
            sides[RIGHT] = side([1, 3], &|x| f(k, x));
        }
        if side_ok[BOTTOM] {
            sides[BOTTOM] = side([0, 1], &|x| f(x, 0));
        }
        if side_ok[TOP] {
            sides[TOP] = side([2, 3], &|x| f(x, k));
        }
        if !block_ok {
            return BlockPlan { stride: 1, sides, bounds: None };
        }
        let bounds = self.flat_bounds(t, &blended, depth_range(fine), view);
        let Some(r) = reach else {
            return BlockPlan { stride: 1, sides, bounds };
        };
        let stride = block_stride(f, r, tol);
        // A side passes wherever its block does (its points and ends are the block's), up to
        // rounding: the block takes the coarsest stride all of its sides take too, so that a
        // side's stride, which its other block computes alike, is never finer than the block's.
        BlockPlan { stride: sides.into_iter().fold(stride, u32::min), sides, bounds }
    }

    /// The plan of an interior block whose relief is too shallow to see whole, `None` for
    /// others. Such a block passes every test of [`DisplacedBlocks::strides`] at the coarsest
    /// stride: a grid point and the coarse surface over it (which interpolates other grid
    /// points) both lie within the depths of the texels under the block, so they differ by at
    /// most that range. Settled without sampling its grid (the pyramid's range holds every
    /// sample's; a margin covers the rounding of the interpolation).
    fn shallow_block(
        &self,
        t: usize,
        [i0, j0, i1, j1]: [u32; 4],
        uv_at: &dyn Fn(u32, u32) -> Vec2,
        reach: Option<f32>,
        blended: &[Option<super::displace::Blended>; 4],
        view: &DisplacementView,
    ) -> Option<BlockPlan> {
        let ranges = self.ranges.as_ref()?;
        let corners = [(i0, j0), (i1, j0), (i0, j1), (i1, j1)].map(|(i, j)| uv_at(i, j));
        let lo = corners.iter().fold(Vec2::INFINITY, |m, &c| m.min(c));
        let hi = corners.iter().fold(Vec2::NEG_INFINITY, |m, &c| m.max(c));
        if let (Some((d0, d1)), Some(r)) = (ranges.over(lo, hi), reach)
            && (d1 - d0 + 1e-5) * r <= view.tolerance
        {
            let s = STRIDES[0];
            let bounds = self.flat_bounds(t, blended, (d0, d1), view);
            return Some(BlockPlan { stride: s, sides: [s; 4], bounds });
        }
        None
    }

    /// The field's depth at every grid point of block `[i0, j0, i1, j1]` inside the triangle
    /// (at the point's barycentric UV, in f32: a function of the point alone, as both blocks of
    /// a side need), into `fine`, `BLOCK_CELLS + 1` points a row.
    fn sample_grid(&self, [i0, j0, i1, j1]: [u32; 4], n: u32, uv_at: &dyn Fn(u32, u32) -> Vec2, fine: &mut Vec<f32>) {
        let width = (BLOCK_CELLS + 1) as usize;
        fine.clear();
        fine.resize(width * width, 0.0);
        for j in j0..=j1 {
            for i in i0..=i1.min(n - j) {
                fine[(j - j0) as usize * width + (i - i0) as usize] =
                    self.field.sample_bilinear(uv_at(i, j), self.edges);
            }
        }
    }

    /// Where on screen an interior block of a flat input triangle (one normal and one
    /// `uv_scale` at its three corners) can be: its vertices are its undisplaced square moved
    /// along that normal by depths within `(lo, hi)` (the least and the most of its grid
    /// points', or bounds on them), so they lie in the prism over the square's `corners`, whose
    /// projection holds theirs. `None` for a curved triangle or a prism reaching behind the near plane.
    fn flat_bounds(
        &self,
        t: usize,
        corners: &[Option<super::displace::Blended>; 4],
        (lo, hi): (f32, f32),
        view: &DisplacementView,
    ) -> Option<ScreenBounds> {
        let down = self.flat_down(t)?;
        if corners.iter().any(Option::is_none) {
            return None;
        }
        view.hull_bounds(corners.iter().flatten().flat_map(|v| [lo, hi].map(|d| v.position - down * d)))
    }

    /// For a flat input triangle `t` (one normal and one `uv_scale` at its three corners), the
    /// world offset of the field's full depth (`normal * depth_scale * L`): a vertex of depth
    /// `d` lies `d` times it below the undisplaced surface. `None` for a curved triangle.
    fn flat_down(&self, t: usize) -> Option<Vec3> {
        let [a, b, c] = self.plan.triangles[t].map(|v| v as usize);
        let m = self.mesh.as_ref();
        let same = |x: usize| m.normals[x] == m.normals[a] && m.uv_scale[x] == m.uv_scale[a];
        (same(b) && same(c)).then(|| m.normals[a] * (self.depth_scale * uv_unit_length(m.uv_scale[a])))
    }

    /// Whether an interior block of a flat input triangle (one normal and one `uv_scale` at its
    /// corners) lies wholly outside the view: its vertices are its undisplaced square moved
    /// along that normal by depths within the field's range, so they lie in the prism over the
    /// square's `corners` from the field's least to its greatest depth, which is outside when
    /// all of its eight corners are beyond one plane of the view volume (clip space is affine
    /// in the world). `false` whenever it cannot tell.
    fn outside_view(&self, t: usize, corners: &[Option<super::displace::Blended>; 4], view: &DisplacementView) -> bool {
        let Some(down) = self.flat_down(t) else { return false };
        let (lo, hi) = self.depth_range;
        // Per plane of the view volume, whether every corner is beyond it.
        let mut beyond = [true; 5];
        for v in corners {
            let Some(v) = v.as_ref() else { return false };
            for d in [lo, hi] {
                let q = view.view_proj * (v.position - down * d).extend(1.0);
                if !q.is_finite() {
                    return false;
                }
                for (k, out) in [q.x > q.w, q.x < -q.w, q.y > q.w, q.y < -q.w, q.z < 0.0].into_iter().enumerate() {
                    beyond[k] &= out;
                }
            }
        }
        beyond.contains(&true)
    }

    /// Where block `index` can be on screen, when it can be told without making the block: from
    /// its plan for the view (an interior block of a flat triangle, `flat_bounds`), else from
    /// the prism that holds its vertices ([`DisplacedBlocks::prism_bounds`]). `None` without a
    /// view, or where neither tells (a block reaching behind the near plane). The caller adds a
    /// sample of margin for rounding.
    #[must_use]
    pub fn screen_bounds(&self, index: usize) -> Option<ScreenBounds> {
        self.plans.get(index).and_then(|p| p.get()).and_then(|p| p.bounds).or_else(|| self.prism_bounds(index))
    }

    /// Block `index`'s plan for the view (`None` without one), planned now if it was not yet.
    fn plan_of(&self, index: usize) -> Option<&BlockPlan> {
        let cell = self.plans.get(index)?;
        Some(cell.get_or_init(|| self.plan_block(index, &mut Vec::new())))
    }

    /// Plans block `index` ([`DisplacedBlocks::strides`]); `fine` is scratch.
    fn plan_block(&self, index: usize, fine: &mut Vec<f32>) -> BlockPlan {
        let [t, i0, j0] = self.blocks[index];
        let t = t as usize;
        let n = self.plan.triangle_parts(t);
        let face = self.plan.face(&self.mesh, t);
        let (i1, j1) = ((i0 + BLOCK_CELLS).min(n), (j0 + BLOCK_CELLS).min(n));
        self.strides(t, [i0, j0, i1, j1], n, face, fine)
    }

    /// Whether the plane of flat input triangle `t` faces away from the eye of `view` (the
    /// orientation of its corners' homogeneous `(x, y, w)` in clip space, which needs no
    /// clipping: Olano and Greer's 2D homogeneous rasterization). Only when to plan its blocks
    /// depends on it.
    fn faces_away(&self, t: usize, view: &DisplacementView) -> bool {
        if self.flat_down(t).is_none() {
            return false;
        }
        let [a, b, c] = self.plan.triangles[t].map(|v| {
            let q = view.view_proj * self.mesh.positions[v as usize].extend(1.0);
            glam::DVec3::new(f64::from(q.x), f64::from(q.y), f64::from(q.w))
        });
        // In front of the eye, this is w_a w_b w_c times twice the signed area in NDC (y up),
        // positive for a front face (counter-clockwise seen from the eye).
        a.dot(b.cross(c)) < 0.0
    }

    /// Where block `index` of any input triangle, curved or flat, can be on screen, from a
    /// prism that holds its displaced vertices, without making them.
    ///
    /// Over the input triangle, the undisplaced position `P`, the interpolated normal `N`
    /// (before it is normalized) and `uv_scale` are affine functions of the grid coordinates
    /// `(i, j)`. The block's grid points lie in a box of those coordinates: its cells, widened
    /// where points on the input triangle's edges snap to an edge's own points. A vertex is
    /// `P - N / |N| * d * depth_scale * L`, with `d` within the field's depth range and
    /// `L = sqrt(sx * sy)` at most its value for the greatest `uv_scale` components at the box's
    /// corners, so it is `P - s N` with `s` between 0 and `s_max = max(d) depth_scale L_max /
    /// min |N|` (a lower bound on `|N|` over the box: its corners' least `N . c` for a unit
    /// `c`). For a fixed `s` that is affine in `(i, j)`, and for fixed `(i, j)` affine in `s`,
    /// so every vertex lies in the convex hull of the eight points `P - s N` at the box's
    /// corners and `s` in `{0, s_max}`. A projection (all eight in front of the near plane)
    /// keeps the hull's points within the eight points' screen box, and the least NDC depth of
    /// the hull (a ratio of affine functions) is at one of them. `None` when a corner is behind
    /// the near plane or not finite, or the normals or `uv_scale` of the triangle are
    /// degenerate (zero or opposed normals, non-positive scales): the caller makes the block.
    #[must_use]
    pub fn prism_bounds(&self, index: usize) -> Option<ScreenBounds> {
        let view = self.view.as_ref()?;
        let &[t, i0, j0] = self.blocks.get(index)?;
        let (mesh, plan, t) = (self.mesh.as_ref(), &self.plan, t as usize);
        let n = plan.triangle_parts(t);
        let (i1, j1) = ((i0 + BLOCK_CELLS).min(n), (j0 + BLOCK_CELLS).min(n));
        let [ab, ac, bc] = plan.triangle_edges[t];
        // Grid coordinate (in the triangle's n parts) of edge point k of n, snapped to the
        // edge's own parts, as `SubdivisionPlan::grid_point` snaps it.
        let snapped = |e: u32, k: u32| -> f64 {
            let parts = u64::from(plan.parts[e as usize]);
            let kk = (2 * u64::from(k) * parts + u64::from(n)) / (2 * u64::from(n));
            kk.min(parts) as f64 * f64::from(n) / parts as f64
        };
        let (mut ilo, mut ihi, mut jlo, mut jhi) = (f64::from(i0), f64::from(i1), f64::from(j0), f64::from(j1));
        if j0 == 0 {
            // Points (i, 0) on edge ab.
            ilo = ilo.min(snapped(ab, i0));
            ihi = ihi.max(snapped(ab, i1.min(n)));
        }
        if i0 == 0 {
            // Points (0, j) on edge ac.
            jlo = jlo.min(snapped(ac, j0));
            jhi = jhi.max(snapped(ac, j1.min(n)));
        }
        // Points (n - j, j) on edge bc, for the rows where it crosses the block.
        let (ja, jb) = (j0.max(n.saturating_sub(i1)), j1.min(n - i0.min(n)));
        if ja <= jb {
            for j in [ja, jb] {
                let jj = snapped(bc, j);
                (jlo, jhi) = (jlo.min(jj), jhi.max(jj));
                (ilo, ihi) = (ilo.min(f64::from(n) - jj), ihi.max(f64::from(n) - jj));
            }
        }
        // A hair wider, for the rounding of the blends.
        let pad = 1e-3;
        let (ilo, ihi, jlo, jhi) = (ilo - pad, ihi + pad, jlo - pad, jhi + pad);
        let vs = plan.triangles[t].map(|v| v as usize);
        if vs.iter().any(|&v| !(mesh.uv_scale[v].cmpgt(Vec2::ZERO).all() && mesh.uv_scale[v].is_finite())) {
            return None;
        }
        let nf = f64::from(n);
        let corners = [(ilo, jlo), (ihi, jlo), (ilo, jhi), (ihi, jhi)].map(|(i, j)| {
            let w = [(nf - i - j) / nf, i / nf, j / nf];
            let mut p = glam::DVec3::ZERO;
            let mut nn = glam::DVec3::ZERO;
            let mut sc = DVec2::ZERO;
            let mut uv = DVec2::ZERO;
            for (&v, &w) in vs.iter().zip(&w) {
                p += mesh.positions[v].as_dvec3() * w;
                nn += mesh.normals[v].as_dvec3() * w;
                sc += mesh.uv_scale[v].as_dvec2() * w;
                uv += mesh.uvs[v].as_dvec2() * w;
            }
            (p, nn, sc, uv.as_vec2())
        });
        let c = corners.iter().fold(glam::DVec3::ZERO, |a, k| a + k.1).try_normalize()?;
        let n_min = corners.iter().map(|k| k.1.dot(c)).fold(f64::INFINITY, f64::min);
        let s_max = corners.iter().fold(DVec2::ZERO, |m, k| m.max(k.2));
        if !(n_min > 0.05 && s_max.is_finite()) {
            return None;
        }
        // The depths of the texels under the block's box of UV (the field's, failing that).
        let uv_lo = corners.iter().fold(Vec2::INFINITY, |m, k| m.min(k.3));
        let uv_hi = corners.iter().fold(Vec2::NEG_INFINITY, |m, k| m.max(k.3));
        let (d_min, d_max) = self.ranges.as_ref().and_then(|r| r.over(uv_lo, uv_hi)).unwrap_or(self.depth_range);
        let per_depth = f64::from(self.depth_scale) * s_max.x.sqrt() * s_max.y.sqrt() / n_min * (1.0 + 1e-4);
        let reach = [f64::from(d_min.min(0.0)) * per_depth, f64::from(d_max.max(0.0)) * per_depth];
        view.hull_bounds(corners.into_iter().flat_map(|(p, nn, _, _)| reach.map(|s| (p - nn * s).as_vec3())))
    }
}

/// Where a point of a fine triangle grid lies on a coarser one: on the coarse triangle with
/// corners `at` (indices into the coarse grid's depths, listed row by row as `coarsen_plan`'s
/// `grid` lists them), at `at[0] + (at[1] - at[0]) w[0] + (at[2] - at[0]) w[1]`.
#[derive(Clone, Copy, Debug)]
struct Lerp {
    at: [u32; 3],
    w: [f32; 2],
}

impl Lerp {
    /// The coarse surface's depth at the point, `depth(k)` giving the coarse grid's `k`-th.
    fn of(&self, mut depth: impl FnMut(usize) -> f32) -> f32 {
        let [a, b, c] = self.at.map(|k| depth(k as usize));
        a + (b - a) * self.w[0] + (c - a) * self.w[1]
    }
}

/// For every point `(i, j)` of an `n`-part triangle grid (row by row: `j` from 0, then `i`),
/// the triangle of the `m`-part grid (`m < n`) over it and its weights there: cells split along
/// the diagonal from `(1, 0)` to `(0, 1)`, and the points of the far edge in its last cells.
fn coarse_lerps(n: u32, m: u32) -> Vec<Lerp> {
    let row = |j: u32| j * (m + 1) - j * j.saturating_sub(1) / 2;
    let at = |i: u32, j: u32| row(j) + i;
    let mut out = Vec::with_capacity(((n + 1) * (n + 2) / 2) as usize);
    for j in 0..=n {
        for i in 0..=n - j {
            let (x, y) = (f64::from(i) / f64::from(n) * f64::from(m), f64::from(j) / f64::from(n) * f64::from(m));
            let (mut ci, mut cj) = (x.floor() as u32, y.floor() as u32);
            // On the far edge: the last cell along it.
            for _ in 0..2 {
                if ci + cj >= m {
                    if ci > 0 { ci -= 1 } else { cj -= 1 }
                }
            }
            let (fx, fy) = ((x - f64::from(ci)) as f32, (y - f64::from(cj)) as f32);
            out.push(if fx + fy <= 1.0 || ci + cj + 1 >= m {
                Lerp { at: [at(ci, cj), at(ci + 1, cj), at(ci, cj + 1)], w: [fx, fy] }
            } else {
                Lerp { at: [at(ci + 1, cj + 1), at(ci, cj + 1), at(ci + 1, cj)], w: [1.0 - fx, 1.0 - fy] }
            });
        }
    }
    out
}

/// Which sides of block `[i0, j0, i1, j1]` of a triangle split into `n` parts may coarsen, and
/// whether the block may (`None`: none of them). A side coarsens when it is whole, inside the
/// triangle and not on its edges; a block when it is whole and strictly inside.
///
/// A triangle of fewer than `4k + 1` parts (`k` = [`BLOCK_CELLS`]) has no block strictly inside
/// (that needs `i0, j0 >= k` and `i0 + j0 + 2k < n`): all of its blocks stay fine, and so may
/// all of its sides, which only this triangle's blocks share. (The sphere of the demo is such
/// triangles, tens of thousands of blocks whose planning would sample every grid point for
/// nothing but the sides.)
fn coarsenable([i0, j0, i1, j1]: [u32; 4], n: u32) -> Option<([bool; 4], bool)> {
    let k = BLOCK_CELLS;
    if n <= 4 * k {
        return None;
    }
    let whole = i1 == i0 + k && j1 == j0 + k;
    let side_ok = [
        i0 > 0 && j1 == j0 + k && i0 + j1 <= n,
        whole && i1 + j1 <= n,
        j0 > 0 && i1 == i0 + k && i1 + j0 <= n,
        whole && i1 + j1 <= n,
    ];
    let block_ok = whole && i0 > 0 && j0 > 0 && i1 + j1 < n;
    (block_ok || side_ok.iter().any(|&ok| ok)).then_some((side_ok, block_ok))
}

/// The coarsest of [`STRIDES`] (1 if none) at which a side's depths `at(0..=BLOCK_CELLS)` stay
/// within `tol` samples, at `reach` samples per unit of depth, of the straight lines between
/// every s-th point.
fn side_stride(at: &dyn Fn(u32) -> f32, reach: f32, tol: f32) -> u32 {
    let k = BLOCK_CELLS;
    STRIDES
        .into_iter()
        .find(|&s| {
            (0..=k).all(|x| {
                let c = (x / s * s).min(k - s);
                let u = (x - c) as f32 / s as f32;
                let line = at(c) + (at(c + s) - at(c)) * u;
                (at(x) - line).abs() * reach <= tol
            })
        })
        .unwrap_or(1)
}

/// The coarsest of [`STRIDES`] (1 if none) at which every grid point `f(a, b)` of a block lies
/// within `tol` samples, at `reach` samples per unit of depth, of the coarse cell's triangle
/// under it, split along the diagonal from `(s, 0)` to `(0, s)` as the cells are.
fn block_stride(f: impl Fn(u32, u32) -> f32, reach: f32, tol: f32) -> u32 {
    let k = BLOCK_CELLS;
    STRIDES
        .into_iter()
        .find(|&s| {
            (0..=k).all(|b| {
                (0..=k).all(|a| {
                    let (ca, cb) = ((a / s * s).min(k - s), (b / s * s).min(k - s));
                    let (u, v) = ((a - ca) as f32 / s as f32, (b - cb) as f32 / s as f32);
                    let (f00, f10, f01) = (f(ca, cb), f(ca + s, cb), f(ca, cb + s));
                    let coarse = if u + v <= 1.0 {
                        f00 + (f10 - f00) * u + (f01 - f00) * v
                    } else {
                        let f11 = f(ca + s, cb + s);
                        f11 + (f01 - f11) * (1.0 - u) + (f10 - f11) * (1.0 - v)
                    };
                    (f(a, b) - coarse).abs() * reach <= tol
                })
            })
        })
        .unwrap_or(1)
}

/// The least and the greatest of `depths`.
fn depth_range(depths: &[f32]) -> (f32, f32) {
    depths.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &d| (l.min(d), h.max(d)))
}

/// The largest input triangle (in parts a side) that [`coarsen_plan`] coarsens as a whole;
/// larger ones coarsen block by block.
const COARSEN_WHOLE_PARTS: u32 = 8 * BLOCK_CELLS;

/// Coarsens the subdivision of small input triangles and of input edges for `view`, by the test
/// of the module docs: every edge takes the fewest parts (its own, or a half, quarter or eighth
/// of them, rounded up) whose straight pieces stay within the tolerance of its points, and
/// every triangle of at most [`COARSEN_WHOLE_PARTS`] parts the fewest whose grid's triangles
/// stay within it over the fine grid's points, never fewer than its edges' parts. The edges'
/// points stay functions of the edge alone, so the stitching between triangles holds as before.
fn coarsen_plan(
    plan: &mut SubdivisionPlan,
    mesh: &Mesh,
    field: &HeightField,
    edges: EdgeMode,
    depth_scale: f32,
    view: &DisplacementView,
) {
    // The projected length of the full depth at each input vertex.
    let reach: Vec<Option<f32>> = (0..mesh.positions.len())
        .into_par_iter()
        .map(|v| {
            let (p, n) = (mesh.positions[v], mesh.normals[v]);
            let down = n * (depth_scale * uv_unit_length(mesh.uv_scale[v]));
            Some(view.project(p)?.distance(view.project(p - down)?))
        })
        .collect();
    let depth = |uv: DVec2| field.sample_bilinear(uv.as_vec2(), edges);
    let tol = view.tolerance;
    let fine = plan.parts.clone();
    let coarse: Vec<u32> = plan
        .edges
        .par_iter()
        .zip(&fine)
        .map(|(&(lo, hi), &p)| {
            let (Some(r0), Some(r1)) = (reach[lo as usize], reach[hi as usize]) else { return p };
            let r = r0.max(r1);
            let (a, b) = (mesh.uvs[lo as usize].as_dvec2(), mesh.uvs[hi as usize].as_dvec2());
            let at = |t: f64| depth(a * (1.0 - t) + b * t);
            let fine_depths: Vec<f32> = (0..=p).map(|k| at(f64::from(k) / f64::from(p))).collect();
            STRIDES
                .into_iter()
                .map(|s| p.div_ceil(s))
                .filter(|&q| q < p)
                .find(|&q| {
                    let ends: Vec<f32> = (0..=q).map(|k| at(f64::from(k) / f64::from(q))).collect();
                    fine_depths.iter().enumerate().all(|(k, &d)| {
                        let x = k as f64 / f64::from(p) * f64::from(q);
                        let c = (x.floor() as u32).min(q - 1);
                        let u = (x - f64::from(c)) as f32;
                        let line = ends[c as usize] + (ends[c as usize + 1] - ends[c as usize]) * u;
                        (d - line).abs() * r <= tol
                    })
                })
                .unwrap_or(p)
        })
        .collect();
    // Per part count n of a triangle coarsened whole, and per coarser grid it may take, where
    // each of the fine grid's points falls in the coarse one (a function of n and m alone).
    let mut tables: Vec<Vec<(u32, Vec<Lerp>)>> = vec![Vec::new(); COARSEN_WHOLE_PARTS as usize + 1];
    for t in 0..plan.triangles.len() {
        let n = plan.triangle_edges[t].iter().map(|&e| fine[e as usize]).max().unwrap_or(1);
        if (2..=COARSEN_WHOLE_PARTS).contains(&n) && tables[n as usize].is_empty() {
            tables[n as usize] = STRIDES
                .into_iter()
                .map(|s| n.div_ceil(s))
                .filter(|&m| m < n)
                .map(|m| (m, coarse_lerps(n, m)))
                .collect();
        }
    }
    // Each grid's points (i, j), row by row, as the tables list them.
    let points: Vec<Vec<[u8; 2]>> = (0..=COARSEN_WHOLE_PARTS)
        .map(|m| (0..=m).flat_map(|j| (0..=m - j).map(move |i| [i as u8, j as u8])).collect())
        .collect();
    let triangle_n: Vec<u32> = (0..plan.triangles.len())
        .into_par_iter()
        .map(|t| {
            let own = plan.triangle_edges[t].iter().map(|&e| coarse[e as usize]).max().unwrap_or(1);
            let n = plan.triangle_edges[t].iter().map(|&e| fine[e as usize]).max().unwrap_or(1);
            let verts = plan.triangles[t];
            let r = verts.iter().try_fold(0.0f32, |m, &v| reach[v as usize].map(|r| m.max(r)));
            let Some(r) = r.filter(|_| (2..=COARSEN_WHOLE_PARTS).contains(&n)) else { return n };
            let [ua, ub, uc] = verts.map(|v| mesh.uvs[v as usize].as_dvec2());
            // The depth at barycentric grid point (i, j) of an m-part grid.
            let at = |i: u32, j: u32, m: u32| {
                let m = f64::from(m);
                depth(ua * ((m - f64::from(i) - f64::from(j)) / m) + ub * (f64::from(i) / m) + uc * (f64::from(j) / m))
            };
            // The grids' depths, sampled when first read (NaN: not yet): a grid that does not
            // fit usually fails within its first few points.
            let lazy = |cache: &mut Vec<f32>, k: usize, m: u32| -> f32 {
                if cache[k].is_nan() {
                    let [i, j] = points[m as usize][k];
                    cache[k] = at(u32::from(i), u32::from(j), m);
                }
                cache[k]
            };
            let mut fine_depths = vec![f32::NAN; points[n as usize].len()];
            let inside = tables[n as usize]
                .iter()
                .find(|(m, lerps)| {
                    let mut ends = vec![f32::NAN; points[*m as usize].len()];
                    lerps.iter().enumerate().all(|(k, l)| {
                        let d = lazy(&mut fine_depths, k, n);
                        (d - l.of(|q| lazy(&mut ends, q, *m))).abs() * r <= tol
                    })
                })
                .map_or(n, |&(m, _)| m);
            inside.max(own)
        })
        .collect();
    plan.parts = coarse;
    plan.triangle_n = triangle_n;
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use glam::{Vec2, Vec3};

    use super::*;
    use crate::mesh::TangentMethod;
    use crate::procedural::{Pattern, generate};

    type Key = [u32; 3];

    fn key(p: Vec3) -> Key {
        p.to_array().map(f32::to_bits)
    }

    /// A triangle as its three positions, rotated to start at the least (orientation kept).
    fn canonical(t: [Vec3; 3]) -> [Key; 3] {
        let k = t.map(key);
        let m = (0..3).min_by_key(|&i| k[i]).unwrap_or(0);
        [k[m], k[(m + 1) % 3], k[(m + 2) % 3]]
    }

    fn all_blocks(b: &DisplacedBlocks<'_>) -> Vec<DisplacedBlock> {
        (0..b.len())
            .map(|i| {
                let mut out = DisplacedBlock::default();
                b.block(i, &mut out);
                out
            })
            .collect()
    }

    fn block_triangles(blocks: &[DisplacedBlock]) -> Vec<[Key; 3]> {
        blocks.iter().flat_map(|b| b.triangles.iter().map(|t| canonical(t.map(|v| b.positions[v as usize])))).collect()
    }

    /// A fan of triangles of very different sizes: its edges split into different parts.
    fn fan() -> Mesh {
        let mut positions = vec![Vec3::ZERO];
        let mut uvs = vec![Vec2::splat(0.5)];
        let rim = [0.05f32, 0.45, 0.1, 0.3, 0.02, 0.4];
        for (k, r) in rim.iter().enumerate() {
            let a = k as f32 / rim.len() as f32 * std::f32::consts::TAU;
            positions.push(Vec3::new(r * a.cos(), 0.0, r * a.sin()));
            uvs.push(Vec2::splat(0.5) + Vec2::new(a.cos(), a.sin()) * *r);
        }
        let k = rim.len() as u32;
        let indices: Vec<u32> = (0..k).flat_map(|i| [0, 1 + (i + 1) % k, 1 + i]).collect();
        Mesh::new(positions, None, uvs, indices, TangentMethod::MikkTSpace).unwrap()
    }

    #[test]
    fn without_a_view_the_blocks_are_the_displaced_mesh_bit_for_bit() {
        let field = generate(Pattern::Cobblestones, 48, 40);
        let meshes = [
            Mesh::plane(Vec2::new(2.0, 1.5), 3).scale_uvs(Vec2::new(2.0, 1.0)),
            Mesh::uv_sphere(0.8, 5, 7),
            Mesh::cube(1.0),
            fan(),
        ];
        for (m, mesh) in meshes.iter().enumerate() {
            for (edges, max_edge) in [(EdgeMode::Wrap, 1.0), (EdgeMode::Clamp, 0.6), (EdgeMode::Wrap, 3.0)] {
                let whole = mesh.displaced_for_shading(&field, edges, 0.07, max_edge);
                let blocks = mesh.displaced_blocks(&field, edges, 0.07, max_edge, None);
                let made = all_blocks(&blocks);
                assert!(made.iter().all(|b| b.stride == 1));
                let mut ours = block_triangles(&made);
                let mut theirs: Vec<[Key; 3]> = whole
                    .indices
                    .chunks_exact(3)
                    .map(|t| canonical([0, 1, 2].map(|k| whole.positions[t[k] as usize])))
                    .collect();
                assert!(ours.len() as u64 <= blocks.triangle_bound());
                ours.sort_unstable();
                theirs.sort_unstable();
                assert_eq!(ours.len(), theirs.len(), "mesh {m}, {edges:?}, {max_edge}");
                assert!(ours == theirs, "mesh {m}, {edges:?}, {max_edge}: the triangles differ");
                // Every vertex carries the mesh's attributes at that position.
                let mut at: HashMap<Key, Vec<(Vec3, Vec2, Vec4)>> = HashMap::new();
                for v in 0..whole.positions.len() {
                    at.entry(key(whole.positions[v])).or_default().push((
                        whole.normals[v],
                        whole.uvs[v],
                        whole.tangents[v],
                    ));
                }
                for b in &made {
                    for v in 0..b.positions.len() {
                        let want = (b.normals[v], b.uvs[v], b.tangents[v]);
                        assert!(at[&key(b.positions[v])].contains(&want), "mesh {m}: vertex {v}");
                        assert_eq!(b.depths[v], field.sample_bilinear(b.uvs[v], edges));
                    }
                }
            }
        }
    }

    /// A perspective view of the unit square plane (y = 0) from low over its near edge.
    fn grazing_view(size: Vec2, tolerance: f32) -> DisplacementView {
        let camera = crate::scene::Camera {
            eye: Vec3::new(0.0, 0.35, 1.6),
            target: Vec3::new(0.0, -0.1, 0.0),
            up: Vec3::Y,
            fov_y_deg: 40.0,
            near: 0.05,
            far: 20.0,
        };
        DisplacementView { view_proj: camera.projection(size.x / size.y) * camera.view(), size, tolerance }
    }

    /// Asserts that the triangles close up: every directed edge is matched by exactly one in
    /// the other direction, except the ones on the plane's rim (|x| or |z| at `half`).
    fn assert_watertight(tris: &[[Key; 3]], half: f32, what: &str) {
        let mut uses: HashMap<(Key, Key), i32> = HashMap::new();
        for t in tris {
            for k in 0..3 {
                *uses.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        let on_rim = |p: Key| {
            let [x, _, z] = p.map(f32::from_bits);
            (x.abs() - half).abs() < 1e-6 || (z.abs() - half).abs() < 1e-6
        };
        for (&(p, q), &n) in &uses {
            let back = uses.get(&(q, p)).copied().unwrap_or(0);
            if back == 0 && on_rim(p) && on_rim(q) {
                assert_eq!(n, 1, "{what}: a rim edge used {n} times");
                continue;
            }
            assert!(n == 1 && back == 1, "{what}: edge {p:?} -> {q:?} used {n} times, back {back} times");
        }
    }

    #[test]
    fn coarsened_blocks_stay_watertight_and_are_fewer_where_the_screen_cannot_tell() {
        // One big pair of triangles (coarsened block by block) and a grid of small ones
        // (coarsened whole), under bricks (flat faces, steep mortar) and smooth waves.
        let size = Vec2::new(480.0, 270.0);
        for pattern in [Pattern::Bricks, Pattern::Waves] {
            let field = generate(pattern, 128, 128);
            for (segments, repeat) in [(1, 2.0), (12, 1.0)] {
                let plane = Mesh::plane(Vec2::ONE, segments).scale_uvs(Vec2::splat(repeat));
                let what = format!("{pattern:?}, {segments} segments");
                let fine = all_blocks(&plane.displaced_blocks(&field, EdgeMode::Wrap, 0.05, 1.0, None));
                let view = grazing_view(size, 0.125);
                let blocks = plane.displaced_blocks(&field, EdgeMode::Wrap, 0.05, 1.0, Some(view));
                let made = all_blocks(&blocks);
                let tris = block_triangles(&made);
                assert_watertight(&tris, 0.5, &what);
                let fine_count: usize = fine.iter().map(|b| b.triangles.len()).sum();
                assert!(
                    (tris.len() as f64) < 0.8 * fine_count as f64,
                    "{what}: {} of {fine_count} triangles",
                    tris.len()
                );
                if segments == 1 {
                    assert!(made.iter().any(|b| b.stride >= 4), "{what}: no block coarsened to 4");
                    assert!(made.iter().any(|b| b.stride == 1), "{what}: every block coarsened");
                }
            }
        }
    }

    #[test]
    fn a_flat_field_coarsens_fully_and_a_rough_one_seen_close_does_not() {
        let plane = Mesh::plane(Vec2::ONE, 1).scale_uvs(Vec2::splat(2.0));
        let view = grazing_view(Vec2::new(960.0, 540.0), 0.125);
        let flat = HeightField::constant(128, 128, 0.5);
        let blocks = plane.displaced_blocks(&flat, EdgeMode::Wrap, 0.05, 1.0, Some(view));
        let made = all_blocks(&blocks);
        // Every block inside the triangles (not touching their edges) takes the coarsest stride.
        let interior = made.iter().filter(|b| b.stride == 8).count();
        assert!(interior as f64 > 0.8 * made.len() as f64, "{interior} of {}", made.len());
        // Noise of a texel's period, deep and seen from close: no block may coarsen.
        let rough = HeightField::from_height_fn(128, 128, |x, y| if (x + y) % 2 == 0 { 0.0 } else { 1.0 });
        let blocks = plane.displaced_blocks(&rough, EdgeMode::Wrap, 0.05, 1.0, Some(view));
        assert!(all_blocks(&blocks).iter().all(|b| b.stride == 1));
    }

    #[test]
    fn blocks_planned_out_of_view_have_every_vertex_beyond_one_plane_of_the_view() {
        // A plane far larger than the view, partly behind the camera: many blocks are out of it.
        let field = generate(Pattern::Pyramids, 96, 96);
        let plane = Mesh::plane(Vec2::splat(6.0), 1).scale_uvs(Vec2::splat(8.0));
        let view = grazing_view(Vec2::new(320.0, 180.0), 0.125);
        let blocks = plane.displaced_blocks(&field, EdgeMode::Wrap, 0.08, 1.0, Some(view));
        let mut b = DisplacedBlock::default();
        let (mut out, mut seen) = (0, 0);
        for i in 0..blocks.len() {
            blocks.block(i, &mut b);
            let beyond = |k: usize| {
                b.positions.iter().all(|&p| {
                    let q = view.view_proj * p.extend(1.0);
                    [q.x > q.w, q.x < -q.w, q.y > q.w, q.y < -q.w, q.z < 0.0][k]
                })
            };
            let outside = (0..5).any(beyond);
            match blocks.screen_bounds(i) {
                Some(s) if !s.min.is_finite() => {
                    out += 1;
                    assert!(outside, "block {i} planned out of view has a vertex in it");
                }
                _ => seen += usize::from(!outside),
            }
        }
        assert!(out as f64 > 0.3 * blocks.len() as f64, "{out} of {} blocks out of view", blocks.len());
        assert!(seen > 0);
    }

    #[test]
    fn known_screen_bounds_hold_every_vertex_of_their_block() {
        let field = generate(Pattern::Pyramids, 96, 96);
        let plane = Mesh::plane(Vec2::ONE, 1).scale_uvs(Vec2::splat(3.0));
        let view = grazing_view(Vec2::new(640.0, 360.0), 0.125);
        let blocks = plane.displaced_blocks(&field, EdgeMode::Wrap, 0.08, 1.0, Some(view));
        let mut known = 0;
        let mut b = DisplacedBlock::default();
        for i in 0..blocks.len() {
            let Some(bounds) = blocks.screen_bounds(i) else { continue };
            known += 1;
            blocks.block(i, &mut b);
            for &p in &b.positions {
                let s = view.project(p).unwrap();
                let clip = view.view_proj * p.extend(1.0);
                assert!(s.cmpge(bounds.min - 1e-3).all() && s.cmple(bounds.max + 1e-3).all(), "{s} not in {bounds:?}");
                assert!(clip.z / clip.w >= bounds.min_z - 1e-6);
            }
        }
        assert!(known as f64 > 0.5 * blocks.len() as f64, "{known} of {} blocks", blocks.len());
    }

    /// Every block's known screen bounds (planned, or from its prism) hold every vertex it
    /// makes, and its least depth is no deeper than theirs, for the demo's four objects (a
    /// plane reaching behind the camera, a rotated cube, a UV sphere whose triangles all touch
    /// their edges, a tilted quad) seen by its camera.
    #[test]
    fn screen_bounds_hold_every_vertex_on_the_demo_objects() {
        let scene = crate::demo::demo_scene_sized(256);
        let size = Vec2::new(640.0, 360.0);
        let view_proj = scene.camera.projection(size.x / size.y) * scene.camera.view();
        let view = DisplacementView { view_proj, size, tolerance: 0.125 };
        let mut b = DisplacedBlock::default();
        for obj in &scene.objects {
            let material = &scene.materials[obj.material];
            let field = material.height.as_deref().unwrap();
            let world = obj.mesh.transformed(obj.transform);
            let blocks = world.displaced_blocks(field, material.edges, material.depth_scale, 1.0, Some(view));
            let mut known = 0;
            for i in 0..blocks.len() {
                let Some(bounds) = blocks.screen_bounds(i) else { continue };
                known += 1;
                blocks.block(i, &mut b);
                for &p in &b.positions {
                    let clip = view.view_proj * p.extend(1.0);
                    if !bounds.min.is_finite() {
                        // Planned out of view: beyond one plane of it.
                        continue;
                    }
                    let s = view.project(p).unwrap();
                    assert!(
                        s.cmpge(bounds.min - 1e-3).all() && s.cmple(bounds.max + 1e-3).all(),
                        "{}: block {i}: {s} not in {bounds:?}",
                        obj.name
                    );
                    assert!(clip.z / clip.w >= bounds.min_z - 1e-6, "{}: block {i}", obj.name);
                }
            }
            assert!(known as f64 > 0.5 * blocks.len() as f64, "{}: {known} of {} blocks", obj.name, blocks.len());
        }
    }

    /// The flat triangles planned late are the ones whose corners wind clockwise on screen
    /// (the cube's three faces turned away from the demo's camera), and planning them late
    /// gives the plans planning them first does.
    #[test]
    fn triangles_facing_away_are_planned_late_and_alike() {
        let scene = crate::demo::demo_scene_sized(64);
        let cube = &scene.objects[1];
        let material = &scene.materials[cube.material];
        let field = material.height.as_deref().unwrap();
        let size = Vec2::new(320.0, 180.0);
        let view_proj = scene.camera.projection(size.x / size.y) * scene.camera.view();
        let view = DisplacementView { view_proj, size, tolerance: 0.125 };
        let world = cube.mesh.transformed(cube.transform);
        let blocks = world.displaced_blocks(field, material.edges, material.depth_scale, 1.0, Some(view));
        let mut away = 0;
        for t in 0..blocks.plan.triangles.len() {
            let [a, b, c] = blocks.plan.triangles[t].map(|v| view.project(world.positions[v as usize]).unwrap());
            let back = (b - a).perp_dot(c - a) > 0.0;
            assert_eq!(blocks.faces_away(t, &view), back, "triangle {t}");
            away += usize::from(back);
        }
        assert_eq!(away, 6, "three faces of the cube turn away");
        let late = (0..blocks.len()).filter(|&i| blocks.plans[i].get().is_none()).count();
        assert!(late > blocks.len() / 3, "{late} of {} planned late", blocks.len());
        for i in 0..blocks.len() {
            let first = blocks.plan_block(i, &mut Vec::new());
            let got = blocks.plan_of(i).unwrap();
            assert_eq!((got.stride, got.sides), (first.stride, first.sides), "block {i}");
        }
    }

    #[test]
    fn block_positions_are_the_blocks_positions_and_triangles_bit_for_bit() {
        let field = generate(Pattern::Waves, 128, 96);
        let view = grazing_view(Vec2::new(480.0, 270.0), 0.125);
        let meshes =
            [Mesh::plane(Vec2::ONE, 1).scale_uvs(Vec2::splat(3.0)), Mesh::uv_sphere(0.4, 12, 16), Mesh::cube(0.6)];
        for (m, mesh) in meshes.iter().enumerate() {
            for view in [None, Some(view)] {
                let blocks = mesh.displaced_blocks(&field, EdgeMode::Wrap, 0.07, 1.0, view);
                let (mut full, mut light) = (DisplacedBlock::default(), DisplacedBlock::default());
                let mut coarse = 0;
                for i in 0..blocks.len() {
                    blocks.block(i, &mut full);
                    blocks.block_positions(i, &mut light);
                    let bits = |b: &DisplacedBlock| {
                        b.positions.iter().map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>()
                    };
                    assert_eq!(bits(&full), bits(&light), "mesh {m}, block {i}: positions");
                    assert_eq!(full.triangles, light.triangles, "mesh {m}, block {i}: triangles");
                    assert_eq!(full.stride, light.stride);
                    assert!(light.normals.is_empty() && light.tangents.is_empty() && light.depths.is_empty());
                    coarse += usize::from(full.stride > 1);
                }
                // The view's coarsening is exercised too, not only the fine blocks.
                assert!(view.is_none() || m != 0 || coarse > 0, "mesh {m}: no block coarsened");
            }
        }
    }
}
