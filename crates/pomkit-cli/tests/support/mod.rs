//! What the hardening tests share: run `pomkit` with a time limit, and check the clean-failure
//! contract of bad input (docs/LIMITS.md): a non-zero exit, a message that names the input and
//! the problem, no panic, and no file written or changed.
//!
//! Included with `mod support;` by each test file that needs it; not every file uses every helper.
#![allow(dead_code, reason = "each test crate includes this module and uses a different part of it")]

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// How long any one `pomkit` run in these tests may take before it counts as a hang.
pub const HANG_LIMIT: Duration = Duration::from_secs(120);

/// Runs `pomkit ARGS` in `dir` with `stdin` as standard input; kills it and fails the test when
/// it runs longer than [`HANG_LIMIT`].
pub fn pomkit_with_input(args: &[&str], dir: &Path, stdin: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pomkit starts");
    let mut input = child.stdin.take().expect("stdin is piped");
    let bytes = stdin.to_vec();
    // A child that stops reading early closes the pipe: that is not an error of the test.
    let feeder = std::thread::spawn(move || {
        let _ = input.write_all(&bytes);
    });
    let pid = child.id();
    let start = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    let out = match rx.recv_timeout(HANG_LIMIT) {
        Ok(out) => out.expect("pomkit runs"),
        Err(_) => {
            let _ = Command::new("kill").args(["-9", &pid.to_string()]).status();
            panic!("pomkit {args:?} hung: still running after {:?}", start.elapsed());
        }
    };
    let _ = feeder.join();
    out
}

/// Runs `pomkit ARGS` in `dir` with empty standard input (see [`pomkit_with_input`]).
pub fn pomkit(args: &[&str], dir: &Path) -> Output {
    pomkit_with_input(args, dir, b"")
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Standard output as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Every file under `dir` (recursively, relative names) with its contents, to prove that a run
/// wrote, changed and removed nothing.
pub fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).expect("readable folder") {
            let entry = entry.expect("folder entry");
            let path = entry.path();
            let name = path.strip_prefix(root).expect("under root").to_string_lossy().into_owned();
            let kind = entry.file_type().expect("file type");
            if kind.is_dir() {
                out.insert(format!("{name}/"), Vec::new());
                walk(root, &path, out);
            } else if kind.is_symlink() {
                let target = std::fs::read_link(&path).expect("link target");
                out.insert(format!("{name} ->"), target.to_string_lossy().into_owned().into_bytes());
            } else {
                out.insert(name, std::fs::read(&path).expect("readable file"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// Asserts the clean-failure contract for a run of `args` in `dir`: non-zero exit, no panic,
/// standard error naming every one of `needles`, and `dir` exactly as `before`.
pub fn assert_refused(out: &Output, args: &[&str], dir: &Path, before: &BTreeMap<String, Vec<u8>>, needles: &[&str]) {
    let msg = stderr(out);
    assert!(!out.status.success(), "{args:?} should fail, but exited 0; stderr: {msg}");
    assert_ne!(out.status.code(), Some(101), "{args:?} panicked: {msg}");
    assert!(out.status.code().is_some(), "{args:?} was killed by a signal ({:?}): {msg}", out.status);
    assert!(!msg.contains("panicked"), "{args:?} panicked: {msg}");
    for needle in needles {
        assert!(msg.contains(needle), "{args:?}: the message {msg:?} should mention {needle:?}");
    }
    let after = snapshot(dir);
    let added: Vec<_> = after.keys().filter(|k| !before.contains_key(*k)).collect();
    let removed: Vec<_> = before.keys().filter(|k| !after.contains_key(*k)).collect();
    let changed: Vec<_> =
        before.iter().filter(|(k, v)| after.get(*k).is_some_and(|w| w != *v)).map(|(k, _)| k).collect();
    assert!(
        added.is_empty() && removed.is_empty() && changed.is_empty(),
        "{args:?} touched files: added {added:?}, removed {removed:?}, changed {changed:?}"
    );
}

/// Runs `args` in `dir` and asserts the clean-failure contract (see [`assert_refused`]).
pub fn refuses(args: &[&str], dir: &Path, needles: &[&str]) -> Output {
    let before = snapshot(dir);
    let out = pomkit(args, dir);
    assert_refused(&out, args, dir, &before, needles);
    out
}
