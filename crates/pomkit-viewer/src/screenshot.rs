//! Screenshot mode (`pomkit view --screenshot`): wait until the view is complete, let it
//! settle, take the window's picture and close.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use eframe::egui::{self, ColorImage};

/// Where screenshot mode leaves its result: the window's picture, or why there is none.
pub type ScreenshotOutcome = Arc<Mutex<Option<Result<Arc<ColorImage>, String>>>>;

/// A request to save the window to a PNG once the view is complete, then close.
pub struct ScreenshotJob {
    /// Where.
    pub path: PathBuf,
    /// What happened (read by `run` after the window closes): the window's picture, which
    /// `run` writes to `path` only once the window has closed without error, or why not.
    pub outcome: ScreenshotOutcome,
    /// Give up after this long.
    pub timeout: Duration,
}

#[derive(Default)]
enum ShotState {
    #[default]
    Waiting,
    /// Frames painted since the view completed.
    Settling(u32),
    Requested(Arc<Mutex<Option<Arc<ColorImage>>>>),
    Done,
}

/// A screenshot job and where it stands.
pub(crate) struct Shot {
    job: ScreenshotJob,
    state: ShotState,
    started: Instant,
}

impl Shot {
    pub(crate) fn new(job: ScreenshotJob) -> Self {
        Self { job, state: ShotState::Waiting, started: Instant::now() }
    }

    /// One frame of the state machine: once the view is `complete` (or shows an `error`), let
    /// two frames settle, ask egui for the window's picture, hand it (or the error) to the job
    /// and close the window; give up after the job's timeout.
    pub(crate) fn step(&mut self, ctx: &egui::Context, complete: bool, error: Option<&str>) {
        let Shot { job, state, started } = self;
        let finish = |job: &ScreenshotJob, r: Result<Arc<ColorImage>, String>| {
            if let Ok(mut o) = job.outcome.lock() {
                *o = Some(r);
            }
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        };
        if started.elapsed() > job.timeout && !matches!(state, ShotState::Done) {
            finish(job, Err(format!("the view did not complete within {} s", job.timeout.as_secs())));
            *state = ShotState::Done;
            return;
        }
        match state {
            ShotState::Waiting => {
                if complete {
                    *state = ShotState::Settling(0);
                }
                ctx.request_repaint();
            }
            ShotState::Settling(n) => {
                // A couple of frames so the new texture is on screen.
                if *n >= 2 {
                    let slot: Arc<Mutex<Option<Arc<ColorImage>>>> = Arc::default();
                    let sink = slot.clone();
                    let wake = ctx.clone();
                    ctx.request_screenshot(move |img| {
                        if let Ok(mut s) = sink.lock() {
                            *s = Some(img);
                        }
                        wake.request_repaint();
                    });
                    *state = ShotState::Requested(slot);
                } else {
                    *n += 1;
                }
                ctx.request_repaint();
            }
            ShotState::Requested(slot) => {
                let img = slot.lock().ok().and_then(|mut s| s.take());
                if let Some(img) = img {
                    // Not written here: a run that fails afterwards must leave no file.
                    let result = match error {
                        Some(e) => Err(format!("the view shows an error: {e}")),
                        None => Ok(img),
                    };
                    finish(job, result);
                    *state = ShotState::Done;
                } else {
                    ctx.request_repaint_after(Duration::from_millis(20));
                }
            }
            ShotState::Done => {}
        }
    }
}
