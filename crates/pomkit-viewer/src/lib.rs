//! `pomkit view`: an interactive viewer for tuning height maps and parallax techniques, on the
//! GPU renderer (`pomkit-gpu`), with eframe/egui.
//!
//! The scene being tuned is a scene file held in memory ([`doc::SceneDoc`]); every control
//! edits it and every frame renders it, so "Export" writes a file that `pomkit render` turns
//! into the same picture. See docs/VIEWER.md.

pub mod app;
pub mod browser;
pub mod camera;
pub mod doc;
pub mod panel;
mod screenshot;
mod settings;
pub mod view;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use eframe::egui;

pub use app::{Settings, ViewerApp};
pub use doc::SceneDoc;

/// What `pomkit view` was asked to do.
#[derive(Clone, Debug, Default)]
pub struct ViewerOptions {
    /// A scene file to open (else the saved session, else the default scene).
    pub scene: Option<PathBuf>,
    /// Save the whole window here as PNG once the view is complete, then exit. Settings are
    /// neither read nor saved in this mode, so the picture depends only on the scene.
    pub screenshot: Option<PathBuf>,
    /// Window size in points (default 1280x800).
    pub size: Option<[f32; 2]>,
    /// Screenshot mode gives up after this long (default 300 s).
    pub timeout: Option<Duration>,
    /// Start in a split view with this technique on the right.
    pub compare: Option<pomkit_core::trace::Technique>,
    /// Start with this overlay.
    pub overlay: Option<view::Overlay>,
}

/// Why the viewer could not run.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The scene could not be opened.
    #[error(transparent)]
    Scene(#[from] doc::DocError),
    /// The screenshot cannot be written there.
    #[error(transparent)]
    Output(#[from] pomkit_io::IoError),
    /// The window could not be opened.
    #[error("cannot open the viewer's window: {0}{hint}", hint = display_hint())]
    Window(String),
    /// Screenshot mode failed.
    #[error("screenshot {path}: {reason}")]
    Screenshot {
        /// The PNG asked for.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

fn display_hint() -> &'static str {
    if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        " (no display: DISPLAY is not set; on a machine without one, run under `xvfb-run -a`)"
    } else {
        ""
    }
}

/// Opens the viewer and returns when its window closes.
///
/// # Errors
/// [`ViewerError`] when the scene cannot be opened, the window cannot be created, or in
/// screenshot mode, when the screenshot could not be taken or written.
pub fn run(opts: ViewerOptions) -> Result<(), ViewerError> {
    let doc = opts.scene.as_deref().map(SceneDoc::open).transpose()?;
    // The screenshot is checked before the window opens (its folder, read-only, not a file
    // the scene reads) and written only once the whole run has succeeded.
    let mut outs = pomkit_io::output::Outputs::new();
    let shot_out = match &opts.screenshot {
        Some(p) => {
            pomkit_io::check_output(p, pomkit_io::PixelLayout::Rgb8)?;
            if let Some(scene) = &opts.scene {
                outs.input(scene);
                pomkit_io::scene::scene_inputs(scene).unwrap_or_default().into_iter().for_each(|f| outs.input(f));
            }
            let id = outs.output(p);
            outs.check()?;
            Some(id)
        }
        None => None,
    };
    let outcome: app::ScreenshotOutcome = Arc::default();
    let shot = opts.screenshot.clone().map(|path| app::ScreenshotJob {
        path,
        outcome: outcome.clone(),
        timeout: opts.timeout.unwrap_or(Duration::from_secs(300)),
    });
    let size = opts.size.unwrap_or([1280.0, 800.0]);
    let mut viewport = egui::ViewportBuilder::default()
        .with_title("pomkit view")
        .with_app_id("pomkit-viewer")
        .with_inner_size(size)
        .with_min_inner_size([640.0, 400.0])
        .with_drag_and_drop(true);
    if shot.is_some() {
        viewport = viewport.with_resizable(false).with_position([0.0, 0.0]);
    }
    let native = eframe::NativeOptions {
        viewport,
        persist_window: shot.is_none(),
        centered: shot.is_none(),
        ..Default::default()
    };
    let (compare, overlay) = (opts.compare, opts.overlay);
    eframe::run_native(
        "pomkit-viewer",
        native,
        Box::new(move |cc| {
            let mut app = ViewerApp::new(cc, doc, shot);
            app.start_with(compare, overlay);
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| ViewerError::Window(e.to_string()))?;
    if let (Some(path), Some(id)) = (opts.screenshot, shot_out) {
        let result = outcome.lock().ok().and_then(|mut o| o.take());
        match result {
            Some(Ok(img)) => {
                let [w, h] = img.size;
                let rgb: Vec<u8> = img.as_raw().chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
                outs.write_image(id, w as u32, h as u32, pomkit_io::PixelLayout::Rgb8, pomkit_io::Pixels::U8(&rgb))?;
                outs.commit()?;
            }
            Some(Err(reason)) => return Err(ViewerError::Screenshot { path, reason }),
            None => {
                return Err(ViewerError::Screenshot {
                    path,
                    reason: "the window closed before the view completed".into(),
                });
            }
        }
    }
    Ok(())
}
