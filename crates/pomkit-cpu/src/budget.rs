//! The memory budget: an upper bound on what a render allocates ([`estimate`], also from sizes
//! alone before a scene is built), the geometry it counts on, and the advice given when a
//! render does not fit.

use pomkit_core::mesh::Mesh;
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;

use crate::displaced::is_streamed;
use crate::raster::{ClipVertex, Fragment, ScreenTriangle};
use crate::tiles::{BAND, TILE, tile_width};
use crate::{Estimate, Mode, RenderOptions, Sample};

/// Upper bounds on what the vertex stage makes of `scene`: the triangles of its drawn meshes,
/// the vertices of its largest object, and the blocks of its streamed (displaced) objects.
pub(crate) fn geometry_counts(scene: &Scene, opts: &RenderOptions) -> Geometry {
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
pub(crate) struct Geometry {
    /// Triangles of the meshes drawn as they are (set up all at once).
    pub(crate) triangles: u64,
    /// Vertices of the largest object (before any subdivision).
    pub(crate) largest: u64,
    /// Blocks of the streamed objects ([`DisplacedBlocks`](pomkit_core::mesh::DisplacedBlocks)).
    pub(crate) blocks: u64,
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
pub(crate) fn advice(scene: &Scene, opts: &RenderOptions) -> String {
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

/// An upper bound on the memory [`CpuRenderer::render`](crate::CpuRenderer::render)
/// allocates for `scene` with `opts` (beyond the scene itself), by part: the output frame
/// (colour, AOVs, and an 8-bit copy for the PNG), the sample bands in flight, the triangle list
/// and its tile bins, the largest object's vertex stage (its world-space copy and clip-space
/// vertices), the displaced reference's blocks (streamed: the subdivided triangles themselves
/// are never held), and the prepared materials (surfaces, normal maps, albedo mips).
#[must_use]
pub fn estimate(scene: &Scene, opts: &RenderOptions) -> Estimate {
    let any_streamed =
        scene.objects.iter().any(|o| scene.materials.get(o.material).is_some_and(|m| is_streamed(m, opts)));
    let materials: Vec<MaterialSize> = scene
        .materials
        .iter()
        .map(|m| MaterialSize {
            height: m.height.as_ref().map(|f| (f.width(), f.height())),
            albedo: m.albedo.as_ref().map(|t| (t.width(), t.height())),
            cone: opts.mode.technique(m.technique) == Technique::Cone,
        })
        .collect();
    estimate_parts(opts, any_streamed, geometry_counts(scene, opts), &materials)
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

/// [`estimate`] from the geometry's bounds and the materials' sizes; `any_streamed` when some
/// object is drawn as streamed displaced geometry (its tiles are as wide as the frame).
fn estimate_parts(opts: &RenderOptions, any_streamed: bool, g: Geometry, materials: &[MaterialSize]) -> Estimate {
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
    let tile_w = u64::from(tile_width(opts.width.saturating_mul(opts.supersample.clamp(1, 8)), any_streamed));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CpuRenderer, RenderOutput};
    use glam::Vec3;
    use pomkit_core::demo::demo_scene_sized;

    /// The bytes a [`RenderOutput`]'s buffers hold, from their lengths and element sizes.
    fn output_buffer_bytes(out: &RenderOutput) -> u64 {
        let mut bytes = out.color.len() * std::mem::size_of::<Vec3>();
        if let Some(a) = &out.aovs {
            bytes += a.uv.len() * 8 + (a.depth.len() + a.shadow.len() + a.fetches.len() + a.lod.len()) * 4;
        }
        bytes as u64
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
