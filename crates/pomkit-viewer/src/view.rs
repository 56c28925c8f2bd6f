//! Rendering the view: the scene document through the GPU renderer, the split between two
//! techniques, the AOV overlays and the figures shown on screen. Runs on a worker thread so the
//! window stays responsive while a frame renders (on lavapipe a frame can take a second).

use std::path::Path;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::thread::JoinHandle;

use pomkit_core::render::{Mode, RenderOptions, RenderOutput};
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;
use pomkit_gpu::{GpuContext, GpuRenderer, GpuScene};
use pomkit_io::scene::SceneCache;
use serde::{Deserialize, Serialize};

use crate::doc::SceneDoc;

/// What is drawn over (or instead of) the shaded picture.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Overlay {
    /// The shaded picture only.
    #[default]
    None,
    /// Height fetches per pixel (trace + shadow) as a heat map.
    Fetches,
    /// The LOD system's debug tint: green where the full technique runs, red where only
    /// normal mapping does.
    LodTint,
    /// The first light's visibility (1 lit, 0 shadowed), grey.
    Shadow,
    /// The hit's depth below the polygon (0 at the top of the relief, 1 at the deepest).
    Depth,
}

impl Overlay {
    /// Every overlay.
    pub const ALL: [Overlay; 5] = [Overlay::None, Overlay::Fetches, Overlay::LodTint, Overlay::Shadow, Overlay::Depth];

    /// Its name on the command line (`pomkit view --overlay`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Overlay::None => "none",
            Overlay::Fetches => "fetches",
            Overlay::LodTint => "lod-tint",
            Overlay::Shadow => "shadow",
            Overlay::Depth => "depth",
        }
    }

    /// Its name in the panel.
    #[must_use]
    pub fn label(self) -> &'static str {
        match self {
            Overlay::None => "none",
            Overlay::Fetches => "fetches per pixel",
            Overlay::LodTint => "LOD tint",
            Overlay::Shadow => "shadow term",
            Overlay::Depth => "hit depth",
        }
    }

    /// What it shows, for the tooltip.
    #[must_use]
    pub fn doc(self) -> &'static str {
        match self {
            Overlay::None => "The shaded picture, as `pomkit render` draws it.",
            Overlay::Fetches => {
                "Height-map fetches per pixel (trace and shadow), as a heat map from black (0) through red \
                 and yellow to white (the scale's maximum). Where the budget goes."
            }
            Overlay::LodTint => {
                "The LOD system's debug view (Tatarchuk 2006, figure 12): green where the full technique runs, \
                 red beyond lod_threshold where only normal mapping does, blended across the one-level fade."
            }
            Overlay::Shadow => "The first light's visibility from the displaced point: white lit, black shadowed.",
            Overlay::Depth => {
                "Depth of the hit below the polygon: black at the top of the relief, white at the deepest."
            }
        }
    }
}

impl ViewRequest {
    /// A request for `doc` at `width` x `height`: the material's own technique, no overlay.
    #[must_use]
    pub fn new(doc: SceneDoc, width: u32, height: u32) -> Self {
        Self {
            id: 0,
            doc,
            width,
            height,
            compare: None,
            split: 0.5,
            overlay: Overlay::None,
            overlay_opacity: 1.0,
            fetch_scale: 48.0,
            reload: false,
        }
    }
}

impl std::str::FromStr for Overlay {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Overlay::ALL.into_iter().find(|o| o.name().eq_ignore_ascii_case(s.trim())).ok_or_else(|| {
            let names: Vec<&str> = Overlay::ALL.iter().map(|o| o.name()).collect();
            format!("unknown overlay '{s}': expected one of {}", names.join(", "))
        })
    }
}

/// One frame to render.
#[derive(Clone, Debug)]
pub struct ViewRequest {
    /// Increases with every request; the answer carries it back.
    pub id: u64,
    /// The scene.
    pub doc: SceneDoc,
    /// Size in pixels.
    pub width: u32,
    /// Size in pixels.
    pub height: u32,
    /// The right-hand side of the split: this technique on every material.
    pub compare: Option<Technique>,
    /// Where the split is, as a share of the width (0..1).
    pub split: f32,
    /// The overlay.
    pub overlay: Overlay,
    /// Opacity of the overlay over the picture (0..1).
    pub overlay_opacity: f32,
    /// The fetch count drawn white in the heat map.
    pub fetch_scale: f32,
    /// Forget loaded textures and meshes first (files changed on disk).
    pub reload: bool,
}

/// Figures of one side of the view.
#[derive(Clone, Debug, PartialEq)]
pub struct SideStats {
    /// What was drawn ("material" for each material's own technique, else the technique).
    pub label: String,
    /// GPU render-pass time in milliseconds.
    pub frame_ms: f64,
    /// Whether `frame_ms` comes from GPU timestamps (else from the wall clock).
    pub from_timestamps: bool,
    /// Mean height fetches per covered pixel.
    pub fetches_per_pixel: f64,
    /// Most fetches at one pixel.
    pub max_fetches: f32,
    /// Covered pixels.
    pub covered: usize,
}

/// A rendered view.
#[derive(Clone, Debug)]
pub struct ViewImage {
    /// Size in pixels.
    pub width: u32,
    /// Size in pixels.
    pub height: u32,
    /// sRGB RGBA8, row-major.
    pub rgba: Vec<u8>,
}

/// The worker's answer.
#[derive(Debug)]
pub struct ViewResult {
    /// The request's id.
    pub id: u64,
    /// The pictures (the material's own technique, then in a split view the compared one),
    /// overlays applied, or why there are none.
    pub images: Result<Vec<ViewImage>, String>,
    /// The figures of each picture.
    pub stats: Vec<SideStats>,
}

/// Messages from the worker.
#[derive(Debug)]
pub enum WorkerMessage {
    /// The device the worker renders on: its description and whether it is a software
    /// rasterizer (lavapipe, llvmpipe, WARP...), or why there is none.
    Device(Result<(String, bool), String>),
    /// A frame.
    Frame(ViewResult),
}

/// Renders [`ViewRequest`]s on a thread of its own.
pub struct Worker {
    requests: Option<Sender<ViewRequest>>,
    results: Receiver<WorkerMessage>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the thread; `wake` is called whenever a message is ready (to repaint the UI).
    #[must_use]
    pub fn start(wake: impl Fn() + Send + 'static) -> Self {
        let (req_tx, req_rx) = channel::<ViewRequest>();
        let (res_tx, res_rx) = channel::<WorkerMessage>();
        let thread = std::thread::Builder::new()
            .name("pomkit-view-render".into())
            .spawn(move || {
                let mut renderer = match GpuContext::new() {
                    Ok(ctx) => {
                        let _ = res_tx.send(WorkerMessage::Device(Ok((ctx.describe(), ctx.is_software()))));
                        Some(ViewRenderer::new(ctx))
                    }
                    Err(e) => {
                        let _ = res_tx.send(WorkerMessage::Device(Err(e.to_string())));
                        None
                    }
                };
                wake();
                while let Ok(mut req) = req_rx.recv() {
                    // Only the newest request matters.
                    loop {
                        match req_rx.try_recv() {
                            Ok(newer) => {
                                let reload = req.reload;
                                req = newer;
                                req.reload |= reload;
                            }
                            Err(TryRecvError::Empty) => break,
                            Err(TryRecvError::Disconnected) => return,
                        }
                    }
                    let result = match renderer.as_mut() {
                        Some(r) => r.render(&req),
                        None => ViewResult { id: req.id, images: Err("no GPU adapter".into()), stats: Vec::new() },
                    };
                    if res_tx.send(WorkerMessage::Frame(result)).is_err() {
                        return;
                    }
                    wake();
                }
            })
            .ok();
        Self { requests: Some(req_tx), results: res_rx, thread }
    }

    /// Queues a frame (replacing any queued one the worker has not started).
    pub fn request(&self, req: ViewRequest) {
        if let Some(tx) = &self.requests {
            let _ = tx.send(req);
        }
    }

    /// The messages that arrived since the last call. If the render thread has stopped (a
    /// device lost, a panic in the driver), a frame saying so.
    pub fn poll(&self) -> Vec<WorkerMessage> {
        let mut out = Vec::new();
        loop {
            match self.results.try_recv() {
                Ok(m) => out.push(m),
                Err(TryRecvError::Empty) => return out,
                Err(TryRecvError::Disconnected) => {
                    if self.thread.as_ref().is_some_and(JoinHandle::is_finished) {
                        out.push(WorkerMessage::Frame(ViewResult {
                            id: u64::MAX,
                            images: Err(
                                "the render thread stopped (see the terminal for why); restart the viewer".into()
                            ),
                            stats: Vec::new(),
                        }));
                    }
                    return out;
                }
            }
        }
    }

    /// Waits for the next message (tests and headless use).
    #[must_use]
    pub fn wait(&self) -> Option<WorkerMessage> {
        self.results.recv().ok()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.requests = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Renders view requests: the GPU renderer, the loaded maps, and the scenes prepared on the GPU
/// for the last request, kept while only the camera or the lights change (an orbit or a light
/// drag then uploads nothing and reruns no height pass).
pub struct ViewRenderer {
    renderer: GpuRenderer,
    cache: SceneCache,
    /// What the prepared scenes were prepared from, and one prepared scene per side.
    prepared: Option<(PreparedKey, Vec<GpuScene>)>,
    reused: bool,
}

/// Everything a prepared scene depends on except the camera and the lights.
#[derive(Clone, Debug, PartialEq)]
struct PreparedKey {
    structure: String,
    width: u32,
    height: u32,
    modes: Vec<Mode>,
    lod_tint: bool,
}

impl ViewRenderer {
    /// A renderer on `ctx`'s device.
    #[must_use]
    pub fn new(ctx: GpuContext) -> Self {
        Self { renderer: GpuRenderer::new(ctx), cache: SceneCache::default(), prepared: None, reused: false }
    }

    /// Whether the last [`ViewRenderer::render`] reused the prepared scenes (only the camera
    /// or lights had changed).
    #[must_use]
    pub fn reused(&self) -> bool {
        self.reused
    }

    /// Renders one request (blocking).
    pub fn render(&mut self, req: &ViewRequest) -> ViewResult {
        if req.reload {
            self.cache.clear();
            self.prepared = None;
        }
        let fail = |msg: String| ViewResult { id: req.id, images: Err(msg), stats: Vec::new() };
        let scene = match req.doc.build(&mut self.cache) {
            Ok(s) => s,
            Err(e) => return fail(e.to_string()),
        };
        // The largest frame of the view's shape that this adapter and pomkit's size limit
        // admit (the picture is scaled to the view): a huge window shrinks rather than fails.
        let (width, height) =
            pomkit_gpu::renderer::largest_frame(&self.renderer.context().device.limits(), req.width, req.height, 1);
        let opts = RenderOptions {
            width,
            height,
            supersample: 1,
            mode: Mode::Material,
            aovs: true,
            displaced_edge_texels: 1.0,
            displaced_tolerance: pomkit_core::render::DISPLACED_TOLERANCE,
            lod_tint: req.overlay == Overlay::LodTint,
        };
        let mut sides = vec![(Mode::Material, "material".to_owned())];
        if let Some(t) = req.compare {
            sides.push((Mode::Technique(t), t.name().to_owned()));
        }
        let key = PreparedKey {
            structure: req.doc.structure_key(),
            width: opts.width,
            height: opts.height,
            modes: sides.iter().map(|(m, _)| *m).collect(),
            lod_tint: opts.lod_tint,
        };
        let ctx = self.renderer.context().clone();
        let reuse = self.prepared.as_ref().is_some_and(|(k, _)| *k == key);
        self.reused = reuse;
        if reuse {
            for gs in self.prepared.iter().flat_map(|(_, g)| g) {
                if let Err(e) = gs.set_view(&ctx, &scene, opts.lod_tint) {
                    return fail(format!("the GPU renderer failed: {e}"));
                }
            }
        } else {
            self.prepared = None;
            let mut prepared = Vec::new();
            for (mode, _) in &sides {
                match self.renderer.prepare(&scene, &RenderOptions { mode: *mode, ..opts }) {
                    Ok(gs) => prepared.push(gs),
                    Err(e) => return fail(format!("the GPU renderer failed: {e}")),
                }
            }
            self.prepared = Some((key, prepared));
        }
        let mut outputs = Vec::new();
        let mut stats = Vec::new();
        let Some((_, prepared)) = self.prepared.as_mut() else { return fail("nothing prepared".into()) };
        for ((_, label), gs) in sides.into_iter().zip(prepared.iter_mut()) {
            let out = match self.renderer.draw(gs, &scene) {
                Ok(o) => o,
                Err(e) => return fail(format!("the GPU renderer failed: {e}")),
            };
            let t = self.renderer.timings();
            stats.push(side_stats(&scene, &out, label, t.render_pass_ms, t.from_timestamps));
            outputs.push(out);
        }
        let images = outputs
            .iter()
            .map(|o| ViewImage {
                width: o.width,
                height: o.height,
                rgba: overlaid(o, req.overlay, req.overlay_opacity, req.fetch_scale),
            })
            .collect();
        ViewResult { id: req.id, images: Ok(images), stats }
    }
}

fn side_stats(scene: &Scene, out: &RenderOutput, label: String, frame_ms: f64, from_timestamps: bool) -> SideStats {
    let label = if label == "material" {
        // Each technique once, in the materials' order.
        let mut names: Vec<&str> = Vec::new();
        for m in &scene.materials {
            if !names.contains(&m.technique.name()) {
                names.push(m.technique.name());
            }
        }
        names.join("+")
    } else {
        label
    };
    let (sum, max) = out
        .aovs
        .as_ref()
        .map_or((0.0, 0.0), |a| a.fetches.iter().fold((0.0f64, 0.0f32), |(s, m), &f| (s + f64::from(f), m.max(f))));
    let fetches_per_pixel = if out.covered > 0 { sum / out.covered as f64 } else { 0.0 };
    SideStats { label, frame_ms, from_timestamps, fetches_per_pixel, max_fetches: max, covered: out.covered }
}

/// A render as sRGB RGBA8 (the tone curve and encoding of [`RenderOutput::to_srgb8`]) with the
/// overlay blended over it at `opacity`. In parallel: it runs on every frame.
#[must_use]
pub fn overlaid(out: &RenderOutput, overlay: Overlay, opacity: f32, fetch_scale: f32) -> Vec<u8> {
    use rayon::prelude::*;
    let opacity = opacity.clamp(0.0, 1.0);
    let mut rgba = vec![0u8; out.color.len() * 4];
    rgba.par_chunks_mut(4).enumerate().for_each(|(i, px)| {
        let base = pomkit_core::render::srgb8(out.color[i]);
        let c = match overlay_color(out, i, overlay, fetch_scale) {
            Some(c) => std::array::from_fn(|k| {
                (f32::from(base[k]) * (1.0 - opacity) + f32::from(c[k]) * opacity).round() as u8
            }),
            None => base,
        };
        px.copy_from_slice(&[c[0], c[1], c[2], 255]);
    });
    rgba
}

/// The split view as one picture: columns left of `split` (a share of the width) from
/// `images[0]`, the rest from `images[1]` when there is one.
#[must_use]
pub fn split_view(images: &[ViewImage], split: f32) -> Option<ViewImage> {
    let a = images.first()?;
    let Some(b) = images.get(1).filter(|b| b.width == a.width && b.height == a.height) else {
        return Some(a.clone());
    };
    let split_x = (split.clamp(0.0, 1.0) * a.width as f32).round() as usize;
    let mut rgba = a.rgba.clone();
    let w = a.width as usize;
    for y in 0..a.height as usize {
        let row = y * w * 4;
        rgba[row + split_x * 4..row + w * 4].copy_from_slice(&b.rgba[row + split_x * 4..row + w * 4]);
    }
    Some(ViewImage { width: a.width, height: a.height, rgba })
}

fn overlay_color(out: &RenderOutput, i: usize, overlay: Overlay, fetch_scale: f32) -> Option<[u8; 3]> {
    let a = out.aovs.as_ref()?;
    let grey = |v: f32| {
        let g = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        [g, g, g]
    };
    match overlay {
        Overlay::None | Overlay::LodTint => None,
        Overlay::Fetches => Some(heat(a.fetches[i] / fetch_scale.max(1e-3))),
        Overlay::Shadow => Some(grey(a.shadow[i])),
        Overlay::Depth => Some(grey(a.depth[i])),
    }
}

/// The heat map: black at 0, through red, orange and yellow to white at 1 and above.
#[must_use]
pub fn heat(t: f32) -> [u8; 3] {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let r = (t * 3.0).min(1.0);
    let g = (t * 3.0 - 1.0).clamp(0.0, 1.0);
    let b = (t * 3.0 - 2.0).clamp(0.0, 1.0);
    [r, g, b].map(|v| (v * 255.0).round() as u8)
}

/// Writes the view as PNG (atomically) and the scene as TOML beside it (`OUT.toml`), the
/// TOML headed by the `pomkit render` command that reproduces the PNG.
///
/// # Errors
/// A message naming the file that could not be written.
pub fn export(doc: &SceneDoc, image: &ViewImage, png: &Path, note: Option<&str>) -> Result<std::path::PathBuf, String> {
    if image.width == 0 || image.height == 0 || image.rgba.len() != (image.width * image.height * 4) as usize {
        return Err("there is no rendered view to export yet".into());
    }
    let png = if png.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        png.to_owned()
    } else {
        png.with_extension("png")
    };
    let toml_path = png.with_extension("toml");
    let mut text = format!(
        "# Exported by `pomkit view`. This reproduces {}:\n#   pomkit render {} --size {}x{} -o {}\n",
        png.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
        toml_path.display(),
        image.width,
        image.height,
        png.display(),
    );
    if let Some(n) = note {
        text.push_str(&format!("# {n}\n"));
    }
    text.push('\n');
    text.push_str(&doc.to_toml());
    pomkit_io::write_atomically(&toml_path, |f| {
        use std::io::Write as _;
        f.write_all(text.as_bytes()).map_err(pomkit_io::WriteFail::Io)
    })
    .map_err(|e| e.to_string())?;
    write_rgb_png(&png, image.width, image.height, &image.rgba)?;
    Ok(toml_path)
}

/// Writes RGBA8 pixels as an RGB PNG (atomically), dropping alpha.
///
/// # Errors
/// The write error's message, naming the file.
pub fn write_rgb_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<(), String> {
    let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    pomkit_io::write_image(path, width, height, pomkit_io::PixelLayout::Rgb8, pomkit_io::Pixels::U8(&rgb))
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pomkit_core::glam::{Vec2, Vec3};
    use pomkit_core::render::Aovs;

    fn output(color: Vec3, fetches: f32) -> RenderOutput {
        let n = 4 * 2;
        RenderOutput {
            width: 4,
            height: 2,
            color: vec![color; n],
            aovs: Some(Aovs {
                uv: vec![Vec2::ZERO; n],
                depth: vec![0.5; n],
                shadow: vec![0.25; n],
                fetches: vec![fetches; n],
                lod: vec![0.0; n],
            }),
            covered: n,
        }
    }

    fn image(o: &RenderOutput) -> ViewImage {
        ViewImage { width: o.width, height: o.height, rgba: overlaid(o, Overlay::None, 0.0, 1.0) }
    }

    #[test]
    fn the_split_takes_each_side_from_its_own_render() {
        let (a, b) = (output(Vec3::ZERO, 0.0), output(Vec3::ONE, 0.0));
        let px = split_view(&[image(&a), image(&b)], 0.25).expect("an image").rgba;
        assert_eq!(&px[0..4], &[0, 0, 0, 255]);
        // Right of the split: white through the tone curve and sRGB.
        let white = pomkit_core::scene::linear_to_srgb(pomkit_core::render::tone(Vec3::ONE).x);
        assert_eq!(px[4], (white * 255.0 + 0.5) as u8);
        assert_eq!(px[4 * 5], px[4], "second row, second column");
        assert_eq!(px[4 * 4], 0, "second row, first column");
        let alone = split_view(&[image(&a)], 0.25).expect("one side");
        assert_eq!(alone.rgba, image(&a).rgba);
    }

    #[test]
    fn overlays_blend_by_opacity() {
        let a = output(Vec3::ZERO, 16.0);
        let full = overlaid(&a, Overlay::Fetches, 1.0, 32.0);
        assert_eq!(&full[0..3], &heat(0.5));
        let half = overlaid(&a, Overlay::Shadow, 0.5, 32.0);
        assert_eq!(half[0], 32); // 0.25 * 255 = 63.75 -> 64, half of it over black
        let none = overlaid(&a, Overlay::None, 1.0, 32.0);
        assert_eq!(&none[0..4], &[0, 0, 0, 255]);
        // Without an overlay, exactly the renderers' own sRGB encoding.
        let mut ramp = output(Vec3::ZERO, 0.0);
        ramp.color = (0..8).map(|i| Vec3::new(i as f32 * 0.3, i as f32 * 0.1, 2.0 - i as f32 * 0.25)).collect();
        let ours: Vec<u8> =
            overlaid(&ramp, Overlay::None, 0.0, 1.0).chunks(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let theirs: Vec<u8> = ramp.to_srgb8().into_iter().flatten().collect();
        assert_eq!(ours, theirs);
    }

    #[test]
    fn heat_runs_black_to_white_and_survives_nan() {
        assert_eq!(heat(0.0), [0, 0, 0]);
        assert_eq!(heat(1.0), [255, 255, 255]);
        assert_eq!(heat(f32::NAN), [0, 0, 0]);
        let mid = heat(0.5);
        assert!(mid[0] == 255 && mid[1] > 100 && mid[2] == 0, "{mid:?}");
    }
}
