//! Shared by the examples, tests and benchmark of bevy_pomkit (included with `#[path]`).
//!
//! Frames rendered by Bevy with no window: for tests, CI machines without a display (it runs on
//! Mesa's software Vulkan, lavapipe), benchmarks and offline pictures.
//!
//! [`Headless::new`] builds an app with Bevy's default plugins minus the window, plus
//! [`PomkitPlugin`](crate::PomkitPlugin), and a target image the caller's camera renders into.
//! [`Headless::frame`] runs the app until every pomkit material is built and the picture has
//! settled (shader pipelines compile in the background over the first frames), then reads the
//! target back.

#![allow(dead_code, reason = "each example and test uses a part of the helper")]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bevy::app::{PluginsState, ScheduleRunnerPlugin};
use bevy::asset::RenderAssetUsages;
use bevy::image::Image;
use bevy::log::LogPlugin;
use bevy::prelude::*;
use bevy::render::RenderApp;
use bevy::render::gpu_readback::{Readback, ReadbackComplete};
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::{CachedPipelineState, PipelineCache};
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};
use bevy::shader::ShaderCacheError;
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;

use bevy_pomkit::{HeightMaps, PomkitMaterial, PomkitPlugin};

/// Why a headless frame could not be rendered.
#[derive(Debug)]
pub enum HeadlessError {
    /// The picture did not settle in time (no GPU adapter, or a height map that never loads).
    Timeout(Duration),
    /// A render pipeline failed to build (a shader that does not compile).
    Pipeline(String),
}

impl std::fmt::Display for HeadlessError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Timeout(t) => write!(f, "the frame did not settle within {t:?}: see Bevy's log above for the cause"),
            Self::Pipeline(e) => write!(f, "a render pipeline failed: {e}"),
        }
    }
}

impl std::error::Error for HeadlessError {}

/// The colour format of the target image: half floats, so that debug outputs (hit UVs) come
/// back with about 11 bits of precision, and colours without sRGB encoding.
pub const TARGET_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// A Bevy app that renders into an image.
pub struct Headless {
    app: App,
    target: Handle<Image>,
    width: u32,
    height: u32,
    latest: Arc<Mutex<Option<Vec<u8>>>>,
    readback: Entity,
}

/// A frame read back: linear RGBA, row by row from the top.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// One RGBA value per pixel.
    pub pixels: Vec<[f32; 4]>,
}

impl Frame {
    /// The largest difference of any colour channel between this frame and `other`, pixel by
    /// pixel (alpha aside).
    #[must_use]
    pub fn max_difference(&self, other: &Frame) -> f32 {
        self.pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0, f32::max))
            .fold(0.0, f32::max)
    }

    /// The pixel at column `x`, row `y` (0 at the top).
    #[must_use]
    pub fn at(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[(y * self.width + x) as usize]
    }

    /// 8-bit sRGB bytes (RGBA) of the colours, clamped to [0, 1], for writing a PNG.
    #[must_use]
    pub fn to_srgb8(&self) -> Vec<u8> {
        let encode = |c: f32| {
            let c = if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 };
            let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
            (s * 255.0 + 0.5) as u8
        };
        self.pixels.iter().flat_map(|p| [encode(p[0]), encode(p[1]), encode(p[2]), 255]).collect()
    }
}

impl Headless {
    /// An app rendering `width` x `height` frames. Spawn the scene with [`Headless::world`] and
    /// give the camera `RenderTarget::Image(headless.target().into())`.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        Self::with_assets(width, height, None)
    }

    /// The same, with Bevy's asset folder at `assets` (the folder of a glTF file to load: Bevy
    /// loads no file outside its asset folder).
    #[must_use]
    pub fn with_assets(width: u32, height: u32, assets: Option<&std::path::Path>) -> Self {
        let mut app = App::new();
        let mut plugins = DefaultPlugins
            .set(WindowPlugin { primary_window: None, exit_condition: ExitCondition::DontExit, ..default() })
            .disable::<WinitPlugin>()
            // Render on the main thread: frames finish in order, and the render world's
            // pipeline cache is at hand to see when shaders have compiled.
            .disable::<PipelinedRenderingPlugin>();
        // The global logger can be set once per process: later apps log through it.
        static LOGGING: AtomicBool = AtomicBool::new(false);
        if LOGGING.swap(true, Ordering::SeqCst) {
            plugins = plugins.disable::<LogPlugin>();
        }
        if let Some(folder) = assets {
            plugins = plugins.set(AssetPlugin { file_path: folder.display().to_string(), ..default() });
        }
        app.add_plugins((plugins, ScheduleRunnerPlugin::run_loop(Duration::ZERO), PomkitPlugin));
        // Finish plugin set-up (the renderer initializes asynchronously).
        while app.plugins_state() == PluginsState::Adding {
            bevy::tasks::tick_global_task_pools_on_main_thread();
        }
        app.finish();
        app.cleanup();
        let mut image = Image::new_fill(
            Extent3d { width, height, depth_or_array_layers: 1 },
            TextureDimension::D2,
            &[0; 8],
            TARGET_FORMAT,
            RenderAssetUsages::default(),
        );
        image.texture_descriptor.usage |=
            TextureUsages::COPY_SRC | TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING;
        let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
        let latest = Arc::new(Mutex::new(None));
        let sink = latest.clone();
        let readback = app
            .world_mut()
            .spawn(Readback::texture(target.clone()))
            .observe(move |done: On<ReadbackComplete>| {
                if let Ok(mut slot) = sink.lock() {
                    *slot = Some(done.data.clone());
                }
            })
            .id();
        Self { app, target, width, height, latest, readback }
    }

    /// The image the camera renders into.
    #[must_use]
    pub fn target(&self) -> Handle<Image> {
        self.target.clone()
    }

    /// The app's world, to spawn the scene and change it between frames.
    pub fn world(&mut self) -> &mut World {
        self.app.world_mut()
    }

    /// The app.
    pub fn app(&mut self) -> &mut App {
        &mut self.app
    }

    /// Runs one frame.
    pub fn update(&mut self) {
        self.app.update();
    }

    /// Runs frames until the plugin has built (or refused) every pomkit material's textures
    /// and two frames read back
    /// in a row are identical (pipelines compile over the first frames), then returns the last.
    ///
    /// # Errors
    /// [`HeadlessError::Timeout`] after `timeout`.
    pub fn frame(&mut self, timeout: Duration) -> Result<Frame, HeadlessError> {
        let start = Instant::now();
        let mut previous: Option<Vec<u8>> = None;
        let mut stable = 0;
        if let Ok(mut slot) = self.latest.lock() {
            *slot = None;
        }
        while start.elapsed() < timeout {
            self.app.update();
            let world = self.app.world();
            let maps = world.resource::<HeightMaps>();
            let settled = world.resource::<Assets<PomkitMaterial>>().iter().all(|(id, _)| maps.settled(id));
            let cache = self.app.sub_app(RenderApp).world().resource::<PipelineCache>();
            // Shaders still loading are retried; anything else is final.
            if let Some(e) = cache.pipelines().find_map(|p| match &p.state {
                CachedPipelineState::Err(
                    ShaderCacheError::ShaderNotLoaded(_) | ShaderCacheError::ShaderImportNotYetAvailable,
                ) => None,
                CachedPipelineState::Err(e) => Some(e.to_string()),
                _ => None,
            }) {
                return Err(HeadlessError::Pipeline(e));
            }
            let compiled = cache.waiting_pipelines().next().is_none()
                && cache.pipelines().all(|p| matches!(p.state, CachedPipelineState::Ok(_)));
            let ready = settled && compiled;
            let data = self.latest.lock().ok().and_then(|mut s| s.take());
            let Some(data) = data else { continue };
            if ready && previous.as_ref() == Some(&data) {
                stable += 1;
                if stable >= 3 {
                    return Ok(self.decode(&data));
                }
            } else {
                stable = 0;
            }
            previous = Some(data);
        }
        Err(HeadlessError::Timeout(timeout))
    }

    /// Stops reading frames back and lets the copies in flight land. Dropped with a copy still
    /// mapping, Bevy's readback would find its receiver gone and log "Failed to send readback
    /// result" at exit.
    fn stop_reading_back(&mut self) {
        let world = self.app.world_mut();
        if world.get_entity(self.readback).is_err() {
            return;
        }
        world.despawn(self.readback);
        // A copy requested in the last frame is mapped during the next one and received in the
        // one after.
        for _ in 0..3 {
            self.app.update();
        }
    }

    fn decode(&self, data: &[u8]) -> Frame {
        let row = self.width as usize * 8;
        let padded = row.div_ceil(256) * 256;
        let stride = if data.len() >= padded * self.height as usize { padded } else { row };
        let mut pixels = Vec::with_capacity(self.width as usize * self.height as usize);
        for y in 0..self.height as usize {
            let line = &data[y * stride..y * stride + row];
            for px in line.chunks_exact(8) {
                let c = |k: usize| pomkit_gpu::util::f16_to_f32(u16::from_le_bytes([px[2 * k], px[2 * k + 1]]));
                pixels.push([c(0), c(1), c(2), c(3)]);
            }
        }
        Frame { width: self.width, height: self.height, pixels }
    }
}

impl Drop for Headless {
    fn drop(&mut self) {
        // After a panic (a failed assertion, a panicking system) the app may not run again.
        if std::thread::panicking() {
            return;
        }
        self.stop_reading_back();
    }
}
