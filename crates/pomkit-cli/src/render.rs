//! `pomkit render`: the main job. With no scene it renders the built-in demo scene.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use pomkit_core::compose::{self, Image};
use pomkit_core::scene::Scene;
use pomkit_core::trace::Technique;
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};
use pomkit_gpu::{GpuRenderError, GpuRenderer};
use pomkit_io::output::{OutputId, Outputs};
use pomkit_io::scene::SceneSizes;
use pomkit_io::{PixelLayout, Pixels};

use crate::backend::{self, Backend, Opened};
use crate::progress;

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (TOML; see docs/SCENES.md), or a glTF file (.gltf, .glb: its scene, camera,
    /// lights and materials; a material with KHR_materials_displacement is traced). Without
    /// one, the built-in demo scene: bricks, pyramids, cobblestones and raised text on a plane,
    /// a cube and a sphere.
    scene: Option<PathBuf>,
    /// Output PNG. AOVs go beside it as OUT.NAME.exr. Every output appears only when the whole
    /// run succeeds, may not be a file the scene reads, and may not be read-only; a symbolic
    /// link is written through (the file it points to is replaced, the link stays).
    #[arg(short, long, default_value = "pomkit.png")]
    output: PathBuf,
    /// Use this technique on every material (flat, normal, parallax, iterative, steep,
    /// pom-classic, pom, relief, exact, cone) or `displaced` for the ground truth: the meshes
    /// tessellated to the height map's resolution and displaced for real (on the CPU renderer
    /// unless --backend gpu: streamed, and coarsened where the screen cannot tell, by at most an
    /// eighth of a pixel).
    #[arg(long)]
    technique: Option<String>,
    /// Renderer: cpu (pomkit-cpu, on all cores), gpu (pomkit-gpu on wgpu: Vulkan, Metal or
    /// DX12; fails when there is no adapter), or auto: the GPU when an adapter exists, else the
    /// CPU, and also the CPU when the GPU cannot draw the scene (e.g. more than 4 lights) and
    /// for the `displaced` reference. The choice is reported on standard error. Both give the same picture within a small tolerance.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    backend: Backend,
    /// Image size.
    #[arg(long, default_value = "1280x720")]
    size: String,
    /// Write these AOVs as 32-bit float EXR beside the PNG: any of uv, depth, shadow, fetches,
    /// lod (comma-separated).
    #[arg(long, value_delimiter = ',')]
    aov: Vec<String>,
    /// Samples per pixel along each axis (2 = 4 samples per pixel).
    #[arg(long, default_value_t = 1)]
    supersample: u32,
    /// Render the scene once per listed technique (comma-separated; `displaced` allowed) and
    /// write them side by side with labels; with `displaced` in the list, also print each
    /// technique's PSNR and share of differing pixels against it.
    #[arg(long, value_delimiter = ',')]
    compare: Vec<String>,
    /// Debug view of the LOD system: green where the full technique runs, red where only
    /// normal mapping does (beyond each material's lod_threshold), blended across the fade.
    #[arg(long)]
    lod_tint: bool,
    /// `displaced` on the CPU renderer: how far, in pixels, its coarsened surface may lie on
    /// screen from the full subdivision's (0: the full subdivision, one triangle edge per
    /// texel everywhere; several times slower).
    #[arg(long, default_value_t = pomkit_core::render::DISPLACED_TOLERANCE, value_name = "PX")]
    displaced_tolerance: f32,
    /// A texture-library folder (ambientCG, Poly Haven, ...): its colour, normal, height and
    /// roughness maps, found by their names and listed on standard error, drawn as one material
    /// on a plane under a low sun. Not with a scene file: in a scene, write material = "DIR" on
    /// an object (docs/SCENES.md).
    #[arg(long, value_name = "DIR", conflicts_with = "scene")]
    material: Option<PathBuf>,
}

/// A technique name or `displaced`, given to `flag` (`--technique` or `--compare`), which an
/// error names.
fn parse_mode(name: &str, flag: &str) -> Result<Mode> {
    if name.eq_ignore_ascii_case("displaced") {
        return Ok(Mode::Displaced);
    }
    let t: Technique = name.parse().map_err(|e| anyhow::anyhow!("{flag}: {e}, displaced"))?;
    Ok(Mode::Technique(t))
}

const AOVS: [&str; 5] = ["uv", "depth", "shadow", "fetches", "lod"];

pub fn run(a: &RenderArgs) -> Result<()> {
    let (w, h) = crate::parse_size(&a.size).context("--size")?;
    for name in &a.aov {
        if !AOVS.contains(&name.as_str()) {
            bail!("--aov: unknown AOV '{name}': expected any of {}", AOVS.join(", "));
        }
    }
    if !(1..=8).contains(&a.supersample) {
        bail!("--supersample {}: must be 1 to 8", a.supersample);
    }
    if !(0.0..=64.0).contains(&a.displaced_tolerance) {
        bail!("--displaced-tolerance {}: must be 0 to 64 pixels", a.displaced_tolerance);
    }
    let mode = match &a.technique {
        Some(t) => parse_mode(t, "--technique")?,
        None => Mode::Material,
    };
    let modes: Vec<(String, Mode)> =
        a.compare.iter().map(|n| Ok((n.to_ascii_lowercase(), parse_mode(n, "--compare")?))).collect::<Result<_>>()?;
    if !modes.is_empty() && !a.aov.is_empty() {
        bail!(
            "--aov does not apply to --compare: the side-by-side sheet has no AOVs; render one technique \
             (--technique T) with --aov"
        );
    }
    pomkit_io::check_output(&a.output, PixelLayout::Rgb8)?;
    // Every output (the PNG and its AOVs) is checked before any work, may not be a file the
    // scene reads, and appears only when the whole run succeeds.
    let mut outs = Outputs::new();
    if let Some(path) = &a.scene {
        for input in pomkit_io::scene::scene_inputs(path)? {
            outs.input(input);
        }
    }
    let folder = a.material.as_deref().map(crate::library::Folder::open).transpose()?;
    for input in folder.iter().flat_map(crate::library::Folder::inputs) {
        outs.input(input);
    }
    let png = outs.output(&a.output);
    let mut aov_outputs: Vec<(String, OutputId)> = Vec::new();
    if modes.is_empty() {
        for name in &a.aov {
            if !aov_outputs.iter().any(|(n, _)| n == name) {
                aov_outputs.push((name.clone(), outs.output(aov_path(&a.output, name))));
            }
        }
    }
    outs.check()?;
    let mut renderer = Renderer::open(a.backend)?;
    let all_modes: Vec<Mode> = if modes.is_empty() { vec![mode] } else { modes.iter().map(|(_, m)| *m).collect() };
    let base = RenderOptions {
        width: w,
        height: h,
        supersample: a.supersample,
        mode,
        aovs: !a.aov.is_empty(),
        lod_tint: a.lod_tint,
        // In samples: the same distance on screen whatever the supersampling.
        displaced_tolerance: a.displaced_tolerance * a.supersample as f32,
        ..Default::default()
    };
    // The whole job against the memory budget before the scene is built: the sizes of its maps
    // and shapes are known from the file and the images' headers (docs/LIMITS.md).
    if let Some(path) = &a.scene {
        let sizes = pomkit_io::scene::scene_sizes(path)?;
        for m in &all_modes {
            renderer.check_sizes(&sizes, &RenderOptions { mode: *m, ..base }, path)?;
        }
    }
    if let Some(f) = &folder {
        let sizes = f.sizes()?;
        for m in &all_modes {
            renderer.check_sizes(&sizes, &RenderOptions { mode: *m, ..base }, &f.dir)?;
        }
    }
    let scene = match &a.scene {
        // Generating big built-in maps and shapes reports no progress: a spinner, so it does
        // not look like a hang.
        Some(path) => {
            let work = pomkit_io::scene::scene_sizes(path).map_or(0, |s| scene_work(&s));
            let mut warnings = Vec::new();
            let scene = progress::spinner(work, &format!("loading {}", path.display()), || {
                pomkit_io::scene::load_scene_warned(path, &mut warnings)
            })?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
            scene
        }
        None => match &folder {
            Some(f) => f.load()?,
            None => pomkit_core::demo::demo_scene(),
        },
    };
    // A baked cone map that no technique of this render steps on is harmless, but likely not
    // what was meant.
    for m in scene.materials.iter().filter(|m| m.cones.is_some()) {
        if !all_modes.iter().any(|mode| mode.technique(m.technique) == Technique::Cone) {
            eprintln!(
                "warning: material {:?}: its cone_map is used by the cone technique only, and this render draws it with {}",
                m.name,
                all_modes[0].technique(m.technique)
            );
        }
    }
    let _cones = build_cones(&scene, &all_modes);
    if modes.is_empty() {
        let out = renderer.render(&scene, &base, "rendering")?;
        write_png(&mut outs, png, &image_of(&out))?;
        if !aov_outputs.is_empty() {
            let aovs = out.aovs.as_ref().context("internal error: the renderer returned no AOVs")?;
            write_aovs(&mut outs, &aov_outputs, &out, aovs)?;
        }
        outs.commit()?;
        eprintln!("wrote {} ({w}x{h}, {} of {} pixels covered)", a.output.display(), out.covered, w * h);
        for (name, _) in &aov_outputs {
            eprintln!("wrote {}", aov_path(&a.output, name).display());
        }
        if let (Some(aovs), true) = (&out.aovs, aov_outputs.iter().any(|(n, _)| n == "fetches")) {
            let total: f64 = aovs.fetches.iter().map(|&f| f64::from(f)).sum();
            eprintln!(
                "mean height fetches per covered pixel: {:.2} (view trace and shadows)",
                total / out.covered.max(1) as f64
            );
        }
        return Ok(());
    }
    let mut panels = Vec::new();
    for (name, m) in &modes {
        let out = renderer.render(&scene, &RenderOptions { mode: *m, aovs: false, ..base }, name)?;
        panels.push((name.clone(), image_of(&out)));
    }
    if let Some((_, reference)) = panels.iter().find(|(n, _)| n == "displaced").cloned() {
        eprintln!("difference from displaced (threshold 16 of 255):");
        for (name, img) in &mut panels {
            if name != "displaced" {
                let d = compose::difference(img, &reference, 16, None);
                eprintln!("  {name:<12} PSNR {:6.2} dB, {:5.2}% of pixels differ", d.psnr_db, 100.0 * d.share_over);
                *name = format!("{name} {:.1}db", d.psnr_db);
            }
        }
    }
    let columns = if panels.len() <= 3 { panels.len() } else { panels.len().div_ceil(2) };
    let sheet = compose::sheet(&panels, columns, 4);
    write_png(&mut outs, png, &sheet)?;
    outs.commit()?;
    eprintln!("wrote {} ({} panels)", a.output.display(), panels.len());
    Ok(())
}

/// Builds, under a progress bar, the cones of every height map drawn with `cone` in one of
/// `modes` (both renderers then find them in `pomkit_core::cone::cached`); returns them so that
/// they outlive the renders.
fn build_cones(scene: &Scene, modes: &[Mode]) -> Vec<std::sync::Arc<pomkit_core::cone::ConeMap>> {
    scene
        .materials
        .iter()
        .filter(|m| m.cones.is_none() && modes.iter().any(|mode| mode.technique(m.technique) == Technique::Cone))
        .filter_map(|m| {
            let field = m.height.as_ref()?;
            let edges = m.edges;
            let what = format!("building the cones of \"{}\" ({}x{})", m.name, field.width(), field.height());
            Some(progress::rows(
                field.height(),
                field.width().saturating_mul(crate::CONE_TEXEL_WEIGHT),
                &what,
                |tick| pomkit_core::cone::cached_with_progress(field, edges, tick),
            ))
        })
        .collect()
}

/// Samples per frame from which the GPU renderer shows a spinner (a software adapter such as
/// lavapipe takes about a second for this many, shader compilation included).
const GPU_SPINNER_SAMPLES: u64 = 250_000;

/// The renderer chosen by `--backend`, kept across the frames of a `--compare` sheet (one GPU
/// device, pipelines compiled once).
struct Renderer {
    /// `None`: the CPU renderer.
    gpu: Option<Box<GpuRenderer>>,
    /// `--backend auto`: fall back to the CPU when the GPU cannot draw a scene.
    fallback: bool,
}

impl Renderer {
    fn open(backend: Backend) -> Result<Self> {
        let gpu = match backend::open(backend)? {
            Opened::Gpu(g) => Some(g),
            Opened::CpuAskedFor | Opened::NoGpu(_) => None,
        };
        Ok(Self { gpu, fallback: backend == Backend::Auto })
    }

    /// Refuses a render of the scene file `path` (of `sizes`) with `opts` that will not fit in
    /// memory on the renderer that will draw it, before anything is built: the scene's maps
    /// and shapes as loaded, and the renderer's own estimate ([`pomkit_cpu::estimate_from_sizes`],
    /// [`pomkit_gpu::renderer::material_host_bytes`]). With `--backend auto` a render the GPU
    /// cannot hold is drawn on the CPU, so it passes when the CPU's estimate fits.
    fn check_sizes(&self, sizes: &SceneSizes, opts: &RenderOptions, path: &Path) -> Result<()> {
        let on_gpu = self.gpu.is_some() && !(self.fallback && opts.mode == Mode::Displaced);
        let loading = sizes.texture_bytes();
        let material = |i: Option<usize>| i.and_then(|i| sizes.materials.get(i));
        let displaced =
            |i: Option<usize>| opts.mode == Mode::Displaced && material(i).is_some_and(|m| m.height.is_some());
        let texels = |s: Option<(u32, u32)>| s.map_or(0, |(w, h)| u64::from(w) * u64::from(h));
        let triangles = sizes.triangles();
        let what = || {
            let largest =
                sizes.largest_texture().map_or_else(String::new, |(w, h)| format!(", the largest map {w}x{h}"));
            let n = sizes.objects.len();
            format!(
                "{} of {} ({n} object{}, {triangles} triangles{largest})",
                pomkit_cpu::describe_job(opts),
                path.display(),
                if n == 1 { "" } else { "s" },
            )
        };
        let cpu = || -> Result<(), pomkit_core::memory::MemoryError> {
            let mut drawn = 0u64;
            let mut streamed = 0u64;
            for o in &sizes.objects {
                if displaced(o.material) {
                    streamed = streamed.saturating_add(texels(material(o.material).and_then(|m| m.height)));
                } else {
                    drawn = drawn.saturating_add(o.triangles);
                }
            }
            let largest = sizes.objects.iter().map(|o| o.vertices).max().unwrap_or(0);
            let mats: Vec<pomkit_cpu::MaterialSize> = sizes
                .materials
                .iter()
                .map(|m| pomkit_cpu::MaterialSize {
                    height: m.height,
                    albedo: m.albedo,
                    cone: opts.mode.technique(m.technique) == Technique::Cone,
                })
                .collect();
            let e = pomkit_cpu::estimate_from_sizes(opts, drawn, largest, streamed, &mats);
            pomkit_core::memory::check(
                what,
                e.total().saturating_add(loading),
                &pomkit_cpu::advice_for(opts, triangles),
            )
        };
        if !on_gpu {
            check_time(sizes, opts, path)?;
            return cpu().context("cannot render");
        }
        let (w, h, ss) = (opts.width, opts.height, opts.supersample.clamp(1, 8));
        let mut gpu_bytes = pomkit_gpu::renderer::frame_host_bytes(w, h, ss, opts.aovs).saturating_add(loading);
        for m in &sizes.materials {
            let cone = opts.mode.technique(m.technique) == Technique::Cone;
            gpu_bytes = gpu_bytes.saturating_add(pomkit_gpu::renderer::material_host_bytes(
                m.height,
                m.albedo,
                m.normal_map,
                cone,
            ));
        }
        for o in &sizes.objects {
            let (verts, tris) = if displaced(o.material) {
                // The whole subdivided mesh: about two triangles a texel, held to the cap.
                let tris = texels(material(o.material).and_then(|m| m.height))
                    .saturating_mul(2)
                    .clamp(o.triangles, pomkit_core::mesh::MAX_DISPLACED_TRIANGLES.max(o.triangles));
                (o.vertices.saturating_add(tris), tris)
            } else {
                (o.vertices, o.triangles)
            };
            gpu_bytes = gpu_bytes.saturating_add(pomkit_gpu::renderer::mesh_host_bytes(verts, tris).saturating_mul(2));
        }
        let gpu = pomkit_core::memory::check(
            || format!("{} on the GPU", what()),
            gpu_bytes,
            "use a smaller --size, smaller height and colour maps, fewer or coarser meshes, or --backend cpu",
        );
        match gpu {
            Ok(()) => Ok(()),
            // `--backend auto` draws it on the CPU when the GPU renderer refuses it.
            Err(_) if self.fallback => cpu().context("cannot render"),
            Err(e) => Err(e).context("cannot render"),
        }
    }

    /// Renders one frame (`what` labels the progress and errors) and checks it is finite.
    fn render(&mut self, scene: &Scene, opts: &RenderOptions, what: &str) -> Result<RenderOutput> {
        let ss = opts.supersample.max(1);
        let samples = u64::from(opts.width * ss) * u64::from(opts.height * ss);
        // `--backend auto` draws the displaced reference on the CPU renderer, which streams it
        // and coarsens it for the view (docs/BENCHMARKS.md); the GPU renderer holds the whole
        // subdivided mesh, tens of millions of triangles for the demo.
        let on_cpu = self.fallback && opts.mode == Mode::Displaced && self.gpu.is_some();
        if on_cpu {
            eprintln!("backend: cpu (for the displaced reference, which the CPU renderer streams)");
        }
        let gpu = self.gpu.as_mut().filter(|_| !on_cpu);
        let out = match gpu {
            Some(gpu) => {
                let result = progress::spinner_when(samples >= GPU_SPINNER_SAMPLES, &format!("{what} (GPU)"), || {
                    gpu.render(scene, opts)
                });
                match result {
                    Ok(out) => out,
                    Err(GpuRenderError::Gpu(e)) if self.fallback => {
                        // A limit of the GPU renderer or the device, not a fault of the scene.
                        eprintln!("backend: cpu (the GPU renderer cannot draw this: {e})");
                        self.gpu = None;
                        render_cpu(scene, opts, what, samples)?
                    }
                    Err(e) => return Err(e).with_context(|| format!("cannot render ({what}) on the GPU")),
                }
            }
            None => render_cpu(scene, opts, what, samples)?,
        };
        if out.color.iter().any(|c| !c.is_finite()) {
            bail!("internal error: the render produced a non-finite pixel");
        }
        Ok(out)
    }
}

/// The texels and vertices a scene's loading generates: the measure of its spinner.
fn scene_work(sizes: &SceneSizes) -> u64 {
    let texels = |s: Option<(u32, u32)>| s.map_or(0, |(w, h)| u64::from(w) * u64::from(h));
    let maps = sizes.materials.iter().map(|m| texels(m.height) + texels(m.albedo)).sum::<u64>();
    maps.saturating_add(sizes.objects.iter().map(|o| o.vertices).sum::<u64>())
}

/// The environment variable that lets a render through [`check_time`].
pub(crate) const ALLOW_SLOW_VAR: &str = "POMKIT_ALLOW_SLOW";

/// Triangles a CPU render may set up per sample before it is refused as out of proportion.
const TRIANGLES_PER_SAMPLE: u64 = 256;

/// Triangles below which a CPU render is never refused for its time.
const SLOW_TRIANGLES: u64 = 16_000_000;

/// Refuses a CPU render whose meshes are out of all proportion to its frame (more than
/// [`TRIANGLES_PER_SAMPLE`] triangles a sample, and over [`SLOW_TRIANGLES`]): every triangle
/// is built, transformed and set up, which takes minutes for a picture of a few thousand
/// pixels (docs/LIMITS.md). [`ALLOW_SLOW_VAR`]`=1` lets it run.
fn check_time(sizes: &SceneSizes, opts: &RenderOptions, path: &Path) -> Result<()> {
    let ss = u64::from(opts.supersample.clamp(1, 8));
    let samples = u64::from(opts.width) * u64::from(opts.height) * ss * ss;
    let triangles = sizes.triangles();
    let allowed = std::env::var_os(ALLOW_SLOW_VAR).is_some_and(|v| v == "1");
    if triangles > SLOW_TRIANGLES && triangles > samples.saturating_mul(TRIANGLES_PER_SAMPLE) && !allowed {
        bail!(
            "cannot render: {} has {triangles} triangles for a {}x{} frame ({} per sample): setting them up would \
             take many minutes on the CPU for a picture that cannot show them; use fewer segments or rings, or \
             set {ALLOW_SLOW_VAR}=1 to render it anyway",
            path.display(),
            opts.width,
            opts.height,
            triangles / samples.max(1)
        );
    }
    Ok(())
}

fn render_cpu(scene: &Scene, opts: &RenderOptions, what: &str, samples: u64) -> Result<RenderOutput> {
    let pb = progress::items(samples.div_ceil(32 * 32), 64, what, "tiles");
    let out = CpuRenderer::new()
        .render(scene, opts, &|done, _total| pb.set_position(done as u64))
        .with_context(|| format!("cannot render ({what})"))?;
    pb.finish_and_clear();
    Ok(out)
}

fn image_of(out: &RenderOutput) -> Image {
    Image::from(out)
}

fn write_png(outs: &mut Outputs, id: OutputId, img: &Image) -> Result<()> {
    outs.write_image(id, img.width, img.height, PixelLayout::Rgb8, Pixels::U8(img.pixels.as_flattened()))?;
    Ok(())
}

/// `out.png` -> `out.<name>.exr`.
fn aov_path(png: &Path, name: &str) -> PathBuf {
    let stem = png.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "pomkit".into());
    png.with_file_name(format!("{stem}.{name}.exr"))
}

/// Stages each AOV in its output (committed with the PNG).
fn write_aovs(
    outs: &mut Outputs,
    names: &[(String, OutputId)],
    out: &RenderOutput,
    aovs: &pomkit_cpu::Aovs,
) -> Result<()> {
    let (w, h) = (out.width, out.height);
    for (name, id) in names {
        let id = *id;
        match name.as_str() {
            "uv" => {
                let rgb: Vec<f32> = aovs.uv.iter().flat_map(|uv| [uv.x, uv.y, 0.0]).collect();
                outs.write_image(id, w, h, PixelLayout::RgbF32, Pixels::F32(&rgb))?;
            }
            "depth" => outs.write_image(id, w, h, PixelLayout::GrayF32, Pixels::F32(&aovs.depth))?,
            "shadow" => outs.write_image(id, w, h, PixelLayout::GrayF32, Pixels::F32(&aovs.shadow))?,
            "fetches" => outs.write_image(id, w, h, PixelLayout::GrayF32, Pixels::F32(&aovs.fetches))?,
            "lod" => outs.write_image(id, w, h, PixelLayout::GrayF32, Pixels::F32(&aovs.lod))?,
            _ => unreachable!("checked against AOVS"),
        }
    }
    Ok(())
}
