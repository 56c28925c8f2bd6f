//! Tiles and bands: the frame cut into tiles of [`TILE`] sample rows, each shaded on its own
//! thread from the triangles and displaced blocks binned to it (front to back), and into bands
//! of [`BAND`] pixel rows whose samples are resolved into the frame as soon as their tiles are
//! done. A tile either shades fragments as they arrive, or with visibility first finds each
//! sample's nearest fragment and shades only those.

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use pomkit_core::render::AovRows;
use pomkit_core::scene::Scene;
use rayon::prelude::*;

use crate::displaced::{BlockSamples, BlockVertices, DisplacedGeometry, is_occluded};
use crate::fragment::Shading;
use crate::packet::Packet;
use crate::prepare::Prepared;
use crate::raster::{self, Fragment, ScreenTriangle};
use crate::{Aovs, MemoryError, Sample, resolve_rows};

/// Sample rows per tile, and the width of a tile where the frame has no displaced geometry.
pub(crate) const TILE: u32 = 32;

/// The width in samples of a frame's tiles (all [`TILE`] rows high): [`TILE`], or with
/// displaced geometry ([`DisplacedGeometry`]) the whole row of the frame. A streamed block is
/// made in every tile it touches; a tile as wide as the frame makes each block once per band of
/// rows it crosses instead of once per tile (about half as often for the demo).
pub(crate) fn tile_width(sw: u32, has_displaced: bool) -> u32 {
    if has_displaced { sw.max(1) } else { TILE }
}

/// Pixel rows per band: each band's samples are shaded (tile by tile, in parallel) and
/// resolved into its rows of the frame, so the full-resolution samples never exist at once.
pub(crate) const BAND: u32 = TILE;

/// Bins triangles and displaced blocks into tiles, shades the tiles of each band of [`BAND`]
/// pixel rows in parallel and resolves each band into `color` (and `aovs`); returns the covered
/// pixel count.
#[expect(clippy::too_many_arguments, reason = "the frame's buffers and the shading inputs")]
pub(crate) fn shade_bands(
    scene: &Scene,
    prepared: &[Prepared],
    tris: &[ScreenTriangle],
    displaced: &DisplacedGeometry<'_>,
    (w, h, ss): (u32, u32, u32),
    color: &mut [Vec3],
    aovs: Option<&mut Aovs>,
    shading: Shading,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<usize, MemoryError> {
    let (sw, sh) = (w * ss, h * ss);
    let mut bins = TileBins::new((sw, sh), tile_width(sw, !displaced.objects.is_empty()))?;
    bins.add_triangles(tris);
    let block_samples = bins.add_blocks(displaced);
    // Front to back, so the early depth test rejects hidden fragments before they are traced.
    bins.sort_front_to_back();
    let frame = FrameTiles { scene, prepared, tris, displaced, block_samples: &block_samples, bins: &bins, shading };
    let done = AtomicUsize::new(0);
    let tiles_done = || {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(n, bins.bins.len());
    };
    let background = scene.background;
    band_outputs(color, aovs, w)
        .into_par_iter()
        .enumerate()
        .map(|(k, (color, rows))| -> Result<usize, MemoryError> {
            let samples = frame.shade_band(k as u32, (color.len() / w as usize) as u32, ss, &tiles_done)?;
            Ok(resolve_rows(&samples, w, ss, background, color, rows))
        })
        .sum()
}

/// The frame's rows of `w` pixels cut into bands of [`BAND`] rows: colour and, when asked for,
/// the AOVs.
fn band_outputs<'a>(
    color: &'a mut [Vec3],
    aovs: Option<&'a mut Aovs>,
    w: u32,
) -> Vec<(&'a mut [Vec3], Option<AovRows<'a>>)> {
    let band_px = (w * BAND) as usize;
    let mut outs: Vec<(&mut [Vec3], Option<AovRows<'_>>)> = Vec::new();
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
                        Some(AovRows { uv, depth, shadow, fetches, lod })
                    }
                    _ => None,
                };
                outs.push((c, rows));
            }
        }
        None => outs.extend(color.chunks_mut(band_px).map(|c| (c, None))),
    }
    outs
}

/// What a tile bin lists: a triangle of the frame's list, or block `.1` of displaced object
/// `.0`.
#[derive(Clone, Copy, Debug)]
enum Item {
    Triangle(u32),
    Block(u32, u32),
}

/// The frame's tiles and, per tile, what may cover its samples, with each item's least depth.
struct TileBins {
    /// The frame's size in samples.
    size: (u32, u32),
    /// The width of a tile ([`tile_width`]); every tile is [`TILE`] rows high.
    tile_w: u32,
    /// Tiles per row.
    tx: u32,
    /// Per tile, row-major.
    bins: Vec<Vec<(f32, Item)>>,
}

impl TileBins {
    /// Empty bins for a frame of `sw x sh` samples.
    fn new((sw, sh): (u32, u32), tile_w: u32) -> Result<Self, MemoryError> {
        let (tx, ty) = (sw.div_ceil(tile_w), sh.div_ceil(TILE));
        let bins =
            pomkit_core::memory::try_vec(Vec::new(), (tx * ty) as usize).map_err(|e| MemoryError::Allocation {
                what: format!("the tile bins of a {sw}x{sh}-sample frame"),
                bytes: u64::from(tx * ty) * 24,
                reason: e.to_string(),
                advice: "use a smaller --size or a lower --supersample".into(),
            })?;
        Ok(Self { size: (sw, sh), tile_w, tx, bins })
    }

    /// Lists `item`, at least `z` deep, in every tile the samples `[x0, x1) x [y0, y1)` touch.
    fn add(&mut self, (x0, y0, x1, y1): (u32, u32, u32, u32), z: f32, item: Item) {
        for by in y0 / TILE..=(y1 - 1) / TILE {
            for bx in x0 / self.tile_w..=(x1 - 1) / self.tile_w {
                self.bins[(by * self.tx + bx) as usize].push((z, item));
            }
        }
    }

    /// Lists every triangle in the tiles it may cover.
    fn add_triangles(&mut self, tris: &[ScreenTriangle]) {
        let (sw, sh) = self.size;
        for (i, t) in tris.iter().enumerate() {
            if let Some(b) = t.quad_bounds(0, 0, sw, sh) {
                self.add(b, t.min_z, Item::Triangle(i as u32));
            }
        }
    }

    /// Lists every block of the displaced objects in the tiles it may cover, bounded here (from
    /// its prism where it can be, else by making it); it is made in each tile it touches unless
    /// what the tile drew already hides it. Returns, per displaced object and block, the samples
    /// it may cover and its least depth (`f32::INFINITY` for a block that covers none).
    fn add_blocks(&mut self, displaced: &DisplacedGeometry<'_>) -> Vec<Vec<BlockSamples>> {
        let size = self.size;
        let mut all = Vec::with_capacity(displaced.objects.len());
        for (oi, object) in displaced.objects.iter().enumerate() {
            let bounds: Vec<Option<BlockSamples>> = (0..object.blocks.len())
                .into_par_iter()
                .map_init(BlockVertices::default, |v, b| displaced.block_samples(oi, b, size, v))
                .collect();
            let mut samples = Vec::with_capacity(bounds.len());
            for (b, found) in bounds.into_iter().enumerate() {
                if let Some(([x0, y0, x1, y1], z)) = found {
                    self.add((x0, y0, x1, y1), z, Item::Block(oi as u32, b as u32));
                }
                samples.push(found.unwrap_or(([0; 4], f32::INFINITY)));
            }
            all.push(samples);
        }
        all
    }

    /// Sorts each tile's items by their least depth (stably: equal depths keep their order).
    fn sort_front_to_back(&mut self) {
        self.bins.par_iter_mut().for_each(|b| b.sort_by(|a, c| a.0.total_cmp(&c.0)));
    }
}

/// A frame binned into tiles, and what its tiles are shaded from.
struct FrameTiles<'f, 'g> {
    scene: &'f Scene,
    prepared: &'f [Prepared],
    tris: &'f [ScreenTriangle],
    displaced: &'f DisplacedGeometry<'g>,
    /// Per displaced object and block, the samples it may cover and its least depth.
    block_samples: &'f [Vec<BlockSamples>],
    bins: &'f TileBins,
    shading: Shading,
}

impl FrameTiles<'_, '_> {
    /// The samples of band `k` (`rows` pixel rows of [`BAND`], `ss x ss` samples a pixel), its
    /// tiles shaded in parallel; `tile_done` is called as each tile finishes.
    fn shade_band(
        &self,
        k: u32,
        rows: u32,
        ss: u32,
        tile_done: &(dyn Fn() + Sync),
    ) -> Result<Vec<Option<Sample>>, MemoryError> {
        let (sw, sh) = self.bins.size;
        let (tile_w, tx) = (self.bins.tile_w, self.bins.tx);
        let (sy0, sy1) = (k * BAND * ss, (k * BAND + rows) * ss);
        let mut samples =
            pomkit_core::memory::try_vec(None, (sw * (sy1 - sy0)) as usize).map_err(|e| MemoryError::Allocation {
                what: format!("a band of {sw}x{} samples", sy1 - sy0),
                bytes: pomkit_core::memory::bytes_of::<Option<Sample>>(u64::from(sw * (sy1 - sy0))),
                reason: e.to_string(),
                advice: "use a smaller --size or a lower --supersample".into(),
            })?;
        let tiles: Vec<(u32, u32, Vec<Option<Sample>>)> = (sy0 / TILE..sy1.div_ceil(TILE))
            .flat_map(|by| (0..tx).map(move |bx| (bx, by)))
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|(bx, by)| {
                let buf = self.shade_tile(
                    &self.bins.bins[(by * tx + bx) as usize],
                    [bx * tile_w, by * TILE, ((bx + 1) * tile_w).min(sw), ((by + 1) * TILE).min(sh)],
                );
                tile_done();
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
        Ok(samples)
    }

    /// Shades the tile `[x0, x1) x [y0, y1)` from the items of its `bin`: its samples,
    /// row-major.
    fn shade_tile(&self, bin: &[(f32, Item)], tile: [u32; 4]) -> Vec<Option<Sample>> {
        let (scene, prepared, shading) = (self.scene, self.prepared, self.shading);
        let [x0, y0, x1, y1] = tile;
        let tw = x1 - x0;
        let mut buf: Vec<Option<Sample>> = vec![None; (tw * (y1 - y0)) as usize];
        // With visibility first, the triangles only find each sample's nearest fragment; the
        // visible ones are shaded at the end, in full packets.
        let mut visible = if shading.visibility_first { Visible::new(buf.len()) } else { Visible::default() };
        // One packet for the tile, emptied after each triangle.
        let mut packet = Packet::default();
        let mut draw_triangle = |tri: &ScreenTriangle, buf: &mut Vec<Option<Sample>>, visible: &mut Visible| {
            if shading.visibility_first {
                draw_visible(tri, (x0, y0, x1, y1), visible);
            } else {
                draw(scene, prepared, tri, (x0, y0, x1, y1), shading, &mut packet, buf);
            }
        };
        let mut block = BlockVertices::default();
        for &(_, item) in bin {
            match item {
                Item::Triangle(ti) => draw_triangle(&self.tris[ti as usize], &mut buf, &mut visible),
                Item::Block(o, b) => {
                    // Occlusion culling: a block behind what the tile holds is not made at all.
                    let samples = self.block_samples[o as usize][b as usize];
                    if shading.cull_blocks && is_block_hidden(samples, tile, shading.visibility_first, &visible, &buf) {
                        continue;
                    }
                    self.displaced.draw_block(
                        o as usize,
                        b as usize,
                        tile,
                        self.bins.size,
                        shading.cull_blocks,
                        &mut block,
                        |st| draw_triangle(st, &mut buf, &mut visible),
                    );
                }
            }
        }
        if shading.visibility_first {
            shade_visible(scene, prepared, &visible, tw, shading, &mut buf);
        }
        visible.give_back();
        buf
    }
}

/// Whether what the tile `[x0, x1) x [y0, y1)` holds hides a block that may cover `rect` no
/// nearer than `min_z` ([`is_occluded`]): the nearest fragments of its visibility pass, or its
/// shaded samples.
fn is_block_hidden(
    (rect, min_z): BlockSamples,
    tile: [u32; 4],
    visibility_first: bool,
    visible: &Visible,
    buf: &[Option<Sample>],
) -> bool {
    if visibility_first {
        is_occluded(rect, min_z, tile, |at, z| {
            let (object, near) = visible.nearest[at];
            object != Visible::EMPTY && near <= z
        })
    } else {
        is_occluded(rect, min_z, tile, |at, z| buf[at].is_some_and(|s| s.z <= z))
    }
}

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

/// Rasterizes `tri` into the tile `[x0, x1) x [y0, y1)` whose samples `buf` holds, shading the
/// fragments that pass the depth test eight at a time
/// ([`shade_packet`](crate::packet::shade_packet)).
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
