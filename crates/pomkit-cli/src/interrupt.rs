//! Ctrl-C and SIGTERM: a run that is stopped removes its staged outputs, keeps what it finished
//! and exits with 128 + the signal's number (130 for SIGINT, 143 for SIGTERM), as a shell does
//! (docs/LIMITS.md, "Outputs").
//!
//! A thread waits for the signals. When one comes, another thread removes every staged file of
//! the process ([`pomkit_io::output::remove_staged_files`], which waits for a commit in
//! progress, so a run's outputs appear all together or not at all), runs the hook the running
//! verb left with [`on_interrupt`] (a batch prints its summary and writes its report), and
//! exits; a second signal meanwhile exits at once.

use std::sync::{Mutex, PoisonError};

/// What the running verb does when it is interrupted, given the signal's name.
type Hook = Box<dyn FnOnce(&str) + Send>;

static HOOK: Mutex<Option<Hook>> = Mutex::new(None);

/// Runs `hook` (with the signal's name, e.g. `SIGTERM`) if the process is interrupted before
/// the returned guard is dropped. Staged files are removed before the hook runs; the hook may
/// still write and commit outputs of its own.
pub(crate) fn on_interrupt(hook: impl FnOnce(&str) + Send + 'static) -> HookGuard {
    *HOOK.lock().unwrap_or_else(PoisonError::into_inner) = Some(Box::new(hook));
    HookGuard(())
}

/// Removes the hook of [`on_interrupt`] when dropped.
pub(crate) struct HookGuard(());

impl Drop for HookGuard {
    fn drop(&mut self) {
        HOOK.lock().unwrap_or_else(PoisonError::into_inner).take();
    }
}

/// Starts the thread that handles SIGINT and SIGTERM. Without it (or when it cannot start) the
/// signals keep their default action.
#[cfg(unix)]
pub(crate) fn install() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    use signal_hook::iterator::Signals;
    // The handlers are registered by the thread itself: if it cannot start, nothing is caught.
    let _ = std::thread::Builder::new().name("signals".into()).spawn(|| {
        let Ok(mut signals) = Signals::new([SIGINT, SIGTERM]) else { return };
        let mut stopping = false;
        for signal in signals.forever() {
            if stopping {
                // A second Ctrl-C while the first is handled: stop now.
                std::process::exit(128 + signal);
            }
            stopping = true;
            let name = if signal == SIGINT { "SIGINT" } else { "SIGTERM" };
            let handled =
                std::thread::Builder::new().name("interrupted".into()).spawn(move || stop(name, 128 + signal));
            if handled.is_err() {
                std::process::exit(128 + signal);
            }
        }
    });
}

/// Signals are not handled on this platform: they keep their default action.
#[cfg(not(unix))]
pub(crate) fn install() {}

/// Removes the staged files, runs the hook and exits with `code`.
#[cfg(unix)]
fn stop(name: &str, code: i32) -> ! {
    pomkit_io::output::remove_staged_files();
    let hook = HOOK.lock().unwrap_or_else(PoisonError::into_inner).take();
    match hook {
        Some(hook) => hook(name),
        None => eprintln!("interrupted by {name}: unfinished outputs removed"),
    }
    std::process::exit(code)
}
