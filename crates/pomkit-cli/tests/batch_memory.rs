//! A batch holds the memory budget across the files it bakes at once (docs/LIMITS.md, "Memory"):
//! with `--jobs 4` and a budget that fits one file but not two, the files are baked one after
//! the other, and the peak resident memory of the run stays near one file's; a file that alone
//! exceeds the budget fails with the usual message and the others are baked.
//!
//! This test binary holds one test, so that the peak resident size of this process's children
//! (`getrusage(RUSAGE_CHILDREN)`) is the peak of the one `pomkit` run being measured.

mod support;

use std::path::Path;
use std::process::{Command, Output, Stdio};

/// Runs `pomkit ARGS` in `dir` with the environment variables `env`.
fn pomkit_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_pomkit"));
    cmd.args(args).current_dir(dir).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("pomkit runs")
}

/// The largest resident size, in bytes, of any child of this process that has ended.
#[expect(unsafe_code, reason = "getrusage fills a plain C struct; there is no safe wrapper in std")]
fn children_peak_rss() -> u64 {
    // SAFETY: `usage` is a valid, writable rusage; getrusage only writes it.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        assert_eq!(libc::getrusage(libc::RUSAGE_CHILDREN, &raw mut usage), 0);
        usage
    };
    // Linux gives ru_maxrss in KiB.
    u64::try_from(usage.ru_maxrss).unwrap() * 1024
}

#[test]
fn four_jobs_share_one_memory_budget() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    const MIB: u64 = 1 << 20;
    // A float normal map of 2048 x 2048 holds about 64 MiB of texels and floats (and the EXR
    // encoder's copy); the budget fits one such bake but not two.
    let limit = 200 * MIB;
    let inputs =
        ["builtin:bricks:2048x2048", "builtin:waves:2048x2048", "builtin:pyramids:2048x2048", "builtin:text:2048x2048"];
    let mut args = vec!["bake", "normal", "--encoding", "float", "-o", "out", "--jobs", "4"];
    args.extend(inputs);
    let out = pomkit_env(&args, d, &[("POMKIT_MEMORY_LIMIT", "200MiB")]);
    let err = support::stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("baked 4, skipped 0, failed 0 of 4 files"), "{err}");
    let peak = children_peak_rss();
    // The budget, plus the program itself (its code and libraries, about 40 MiB).
    assert!(peak < limit + 64 * MIB, "peak resident size {} MiB with a budget of {} MiB", peak / MIB, limit / MIB);

    // A file that alone needs more than the budget fails with the usual message; the others are
    // baked.
    let out = pomkit_env(
        &["bake", "normal", "builtin:bricks:4096x4096", "builtin:waves:64x64", "-o", "small"],
        d,
        &[("POMKIT_MEMORY_LIMIT", "64MiB")],
    );
    let err = support::stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("baked 1, skipped 0, failed 1 of 2 files"), "{err}");
    let line = err.lines().find(|l| l.starts_with("failed: builtin:bricks:4096x4096")).expect("a failed line");
    assert!(line.contains("needs about") && line.contains("64.0 MiB is available (POMKIT_MEMORY_LIMIT)"), "{line}");
    assert!(d.join("small/waves_normal.png").is_file() && !d.join("small/bricks_normal.png").exists());
}
