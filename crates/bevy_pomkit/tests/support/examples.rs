//! Runs one of bevy_pomkit's examples as a user does, without a window, and checks what every
//! example owes its user: it exits successfully, writes its picture, and logs no error or
//! warning of its own making (Bevy's warning that lavapipe renders in software is the
//! machine's). `XDG_RUNTIME_DIR` is unset, as in a container or on CI, where Mesa logs an error
//! for it unless the example gives the process a runtime directory
//! (`pomkit_gpu::util::ensure_runtime_dir`).

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

/// The example `name` built beside this test binary, if `cargo test` built it (a run of one
/// test file alone may not have).
pub fn built_example(name: &str) -> Option<PathBuf> {
    let exe = std::env::current_exe().expect("test binary");
    let example = exe.parent()?.parent()?.join("examples").join(name);
    if example.is_file() {
        Some(example)
    } else {
        println!("skipping: {} is not built (`cargo test` builds the examples)", example.display());
        None
    }
}

/// Runs `example` with `args` and `-o PNG`, without `XDG_RUNTIME_DIR` or colours.
pub fn run(example: &PathBuf, args: &[&str], png: &PathBuf) -> Output {
    Command::new(example)
        .args(args)
        .arg("-o")
        .arg(png)
        .env_remove("XDG_RUNTIME_DIR")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .output()
        .expect("the example runs")
}

/// Runs the example `name` with `args` and returns the picture it wrote, after checking that it
/// succeeded and logged nothing of its own; `None` if the example is not built.
pub fn picture_of(name: &str, args: &[&str]) -> Option<image::RgbImage> {
    let example = built_example(name)?;
    let png = std::env::temp_dir().join(format!("pomkit-bevy-{name}-{}.png", std::process::id()));
    let out = run(&example, args, &png);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{name}: {err}");
    let picture = image::open(&png).unwrap_or_else(|e| panic!("{name} wrote no picture ({e}): {err}")).to_rgb8();
    std::fs::remove_file(&png).expect("remove the picture");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{name}: Mesa's runtime-directory error: {err}");
    assert!(!err.contains("Failed to send readback result"), "{name}: the readback warning at exit: {err}");
    let own: Vec<&str> = err
        .lines()
        .filter(|l| (l.contains("WARN") || l.contains("ERROR")) && !l.contains("software rendering"))
        .collect();
    assert!(own.is_empty(), "{name}: warnings or errors: {own:#?}");
    Some(picture)
}
