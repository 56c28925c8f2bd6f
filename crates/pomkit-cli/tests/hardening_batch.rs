//! Batch baking and interrupted runs, end to end (README, "Baking a library"; docs/LIMITS.md,
//! "Outputs"): a run stopped by SIGINT or SIGTERM removes its staged files, keeps what it
//! finished, reports it and exits 130 or 143; the report and the config are protected like every
//! other input and output; an output folder inside the input tree is never read again; file names
//! that are not UTF-8 are baked and control characters in them are printed escaped; one config
//! serves every verb; every file a scene reads (glTF buffers and images included) is an input.

mod support;

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use support::{pomkit, refuses, stderr};

/// A small 8-bit grey height map with slopes everywhere.
fn height_png(path: &Path, w: u32, h: u32) {
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([((x * 7 + y * 3) % 256) as u8])).save(path).unwrap();
}

/// Every file under `dir` (relative names, recursive; folders end with '/').
fn tree(dir: &Path) -> BTreeSet<String> {
    support::snapshot(dir).into_keys().collect()
}

/// The staging files (`.pomkit-*`) anywhere under `dir`.
fn staged(dir: &Path) -> Vec<String> {
    tree(dir).into_iter().filter(|n| n.rsplit('/').next().is_some_and(|f| f.starts_with(".pomkit-"))).collect()
}

fn ok(args: &[&str], dir: &Path) -> String {
    let out = pomkit(args, dir);
    let err = stderr(&out);
    assert!(out.status.success(), "{args:?} should succeed, exited {:?}: {err}", out.status);
    err
}

// ---------------------------------------------------------------------------------------------
// Interrupted runs

/// Starts `pomkit ARGS` in `dir`, waits until `ready` holds (polling every 10 ms, at most a
/// minute), sends `signal` (`TERM` or `INT`) and returns the exit code and standard error.
fn interrupt_when(args: &[&str], dir: &Path, signal: &str, ready: impl Fn() -> bool) -> (Option<i32>, String) {
    let mut child: Child = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pomkit starts");
    let start = Instant::now();
    while !ready() {
        assert!(child.try_wait().unwrap().is_none(), "{args:?} ended before it could be interrupted");
        assert!(start.elapsed() < Duration::from_secs(60), "{args:?}: never ready to be interrupted");
        std::thread::sleep(Duration::from_millis(10));
    }
    let st = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(st.success(), "kill -{signal}");
    let out = child.wait_with_output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn sigterm_during_a_batch_keeps_finished_outputs_removes_staged_ones_and_reports() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let names = ["bricks", "waves", "pyramids", "cobblestones", "text", "spike"];
    let inputs: Vec<String> = names.iter().map(|n| format!("builtin:{n}:384x384")).collect();
    let mut args = vec!["bake", "cone"];
    args.extend(inputs.iter().map(String::as_str));
    args.extend(["-o", "out", "--jobs", "1", "--report", "report.json"]);
    let out = d.join("out");
    // Stopped while the second file (or a later one) is being baked: one finished, one staged.
    let (code, err) =
        interrupt_when(&args, d, "TERM", || out.join("bricks_cone.png").exists() && !staged(&out).is_empty());
    assert_eq!(code, Some(143), "SIGTERM exits 128 + 15: {err}");
    assert!(staged(d).is_empty(), "staged files left: {:?}", staged(d));
    // Finished outputs are whole, and the report says exactly which files were done.
    let done: Vec<&str> = names.iter().copied().filter(|n| out.join(format!("{n}_cone.png")).exists()).collect();
    assert!(!done.is_empty() && done.len() < names.len(), "{done:?}");
    for n in &done {
        let img = image::open(out.join(format!("{n}_cone.png"))).expect("a finished output is a whole PNG");
        assert_eq!((img.width(), img.height()), (384, 384));
    }
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap();
    let files = report["files"].as_array().unwrap();
    assert_eq!(files.len(), names.len());
    for (n, f) in names.iter().zip(files) {
        let expected = if done.contains(n) { "baked" } else { "interrupted" };
        assert_eq!(f["status"], expected, "{n}: {f}");
    }
    assert_eq!(report["baked"], done.len());
    assert_eq!(report["interrupted"], names.len() - done.len());
    let summary = format!("baked {}, skipped 0, failed 0 of {} files", done.len(), names.len());
    assert!(err.lines().any(|l| l.starts_with(&summary)), "{summary:?} in {err}");
    assert!(err.contains("interrupted") && err.contains("SIGTERM"), "{err}");
}

#[test]
fn sigint_during_a_single_bake_leaves_nothing_and_exits_130() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = ["bake", "cone", "builtin:cobblestones:1024x1024", "-o", "c.png"];
    let (code, err) = interrupt_when(&args, d, "INT", || !staged(d).is_empty());
    assert_eq!(code, Some(130), "SIGINT exits 128 + 2: {err}");
    assert!(tree(d).is_empty(), "left behind: {:?}", tree(d));
}

#[test]
fn sigterm_during_a_render_with_aovs_leaves_nothing_and_exits_143() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = ["render", "--backend", "cpu", "--size", "2048x2048", "--aov", "depth,uv", "-o", "r.png"];
    let (code, err) = interrupt_when(&args, d, "TERM", || staged(d).len() >= 3);
    assert_eq!(code, Some(143), "{err}");
    assert!(tree(d).is_empty(), "left behind: {:?}", tree(d));
}

// ---------------------------------------------------------------------------------------------
// The report and the config are protected

#[test]
fn the_report_may_not_replace_a_batch_output_or_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("lib")).unwrap();
    height_png(&d.join("lib/a.png"), 16, 16);
    ok(&["bake", "normal", "lib", "-o", "o5"], d);
    refuses(
        &["bake", "normal", "lib", "-o", "o5", "--overwrite", "--report", "o5/a_normal.png"],
        d,
        &["--report", "o5/a_normal.png", "output"],
    );
    image::open(d.join("o5/a_normal.png")).expect("the baked map is still a PNG");
    std::fs::write(d.join("rules.toml"), "[[rule]]\nscale = 4\n").unwrap();
    refuses(
        &["bake", "normal", "lib", "-o", "o6", "--config", "rules.toml", "--report", "rules.toml"],
        d,
        &["--report", "rules.toml", "same file as the input"],
    );
}

// ---------------------------------------------------------------------------------------------
// Output folders inside the input tree

#[test]
fn an_output_folder_inside_the_input_tree_is_never_read_again() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("lib/sub")).unwrap();
    height_png(&d.join("lib/a.png"), 16, 16);
    height_png(&d.join("lib/sub/b.png"), 16, 16);
    let first = ok(&["bake", "normal", "lib", "--recursive", "-o", "lib/baked"], d);
    assert!(first.contains("baked 2, skipped 0, failed 0 of 2 files"), "{first}");
    let again = ok(&["bake", "normal", "lib", "--recursive", "-o", "lib/baked"], d);
    assert!(again.contains("baked 0, skipped 2, failed 0 of 2 files"), "a rerun bakes only what is missing: {again}");
    // The output folder is the input folder itself: its earlier outputs are not inputs.
    ok(&["bake", "normal", "lib", "-o", "lib"], d);
    let again = ok(&["bake", "normal", "lib", "-o", "lib"], d);
    assert!(again.contains("baked 0, skipped 1, failed 0 of 1 files"), "{again}");
    let all = tree(d);
    assert!(all.iter().all(|n| !n.contains("_normal_normal")), "{all:?}");
    assert_eq!(
        all.iter().filter(|n| n.ends_with("_normal.png")).cloned().collect::<Vec<_>>(),
        ["lib/a_normal.png", "lib/baked/a_normal.png", "lib/baked/sub/b_normal.png"]
    );
}

// ---------------------------------------------------------------------------------------------
// One input with a batch flag

#[test]
fn one_input_with_a_batch_flag_and_an_image_file_output_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    height_png(&d.join("a.png"), 16, 16);
    refuses(
        &["bake", "normal", "a.png", "-o", "a_n.png", "--report", "r.json"],
        d,
        &["-o a_n.png", "folder", "--report"],
    );
    // An existing folder of that name is a folder: the batch writes into it.
    std::fs::create_dir(d.join("maps.png")).unwrap();
    ok(&["bake", "normal", "a.png", "-o", "maps.png", "--report", "r.json"], d);
    assert!(d.join("maps.png/a_normal.png").is_file() && d.join("r.json").is_file());
}

// ---------------------------------------------------------------------------------------------
// Unreadable folders, file names

#[test]
fn an_unreadable_subfolder_fails_alone() {
    // Root reads every folder whatever its permissions: this needs an ordinary user (CI runs as
    // root, so there the test only checks that nothing else changed).
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("lib/locked")).unwrap();
    height_png(&d.join("lib/a.png"), 16, 16);
    height_png(&d.join("lib/locked/b.png"), 16, 16);
    std::fs::set_permissions(d.join("lib/locked"), std::fs::Permissions::from_mode(0o000)).unwrap();
    let readable = std::fs::read_dir(d.join("lib/locked")).is_ok();
    let out = pomkit(&["bake", "normal", "lib", "--recursive", "-o", "out"], d);
    std::fs::set_permissions(d.join("lib/locked"), std::fs::Permissions::from_mode(0o755)).unwrap();
    let err = stderr(&out);
    assert!(d.join("out/a_normal.png").is_file(), "{err}");
    if readable {
        eprintln!("skipped the unreadable-folder check: running as root, every folder is readable");
        assert!(out.status.success(), "{err}");
        return;
    }
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("baked 1, skipped 0, failed 1 of 2 files"), "{err}");
    assert!(err.lines().any(|l| l.starts_with("failed: lib/locked") && l.contains("cannot list")), "{err}");
}

#[test]
fn file_names_that_are_not_utf8_are_baked_under_their_own_name() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("lib")).unwrap();
    height_png(&d.join("lib").join(OsStr::from_bytes(b"caf\xe9.png")), 16, 16);
    let err = ok(&["bake", "normal", "lib", "-o", "out"], d);
    assert!(err.contains("baked 1, skipped 0, failed 0 of 1 files"), "{err}");
    let out = d.join("out").join(OsStr::from_bytes(b"caf\xe9_normal.png"));
    assert_eq!(image::open(&out).expect("the output has the input's name").width(), 16);
}

#[test]
fn control_characters_in_failing_names_are_printed_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("lib")).unwrap();
    height_png(&d.join("lib/good.png"), 16, 16);
    let evil = "x\nbaked 9, skipped 0, failed 0 of 9 files\u{1b}[2J.png";
    std::fs::write(d.join("lib").join(evil), b"not a png").unwrap();
    let out = pomkit(&["bake", "normal", "lib", "-o", "out"], d);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(!err.contains('\u{1b}'), "an escape sequence reached the terminal: {err:?}");
    assert!(!err.lines().any(|l| l.starts_with("baked 9")), "a file name forged a summary line: {err:?}");
    let failed: Vec<&str> = err.lines().filter(|l| l.starts_with("failed: ")).collect();
    assert_eq!(failed.len(), 1, "{err:?}");
    assert!(failed[0].contains(r"x\nbaked 9") && failed[0].contains(r"\u{1b}[2J.png"), "{err:?}");
}

// ---------------------------------------------------------------------------------------------
// Config

#[test]
fn one_config_serves_every_verb_and_folder_dot_is_the_folder_argument() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("lib/sub")).unwrap();
    height_png(&d.join("lib/a.png"), 16, 16);
    height_png(&d.join("lib/sub/b.png"), 16, 16);
    std::fs::write(d.join("c.toml"), "[[rule]]\nencoding = \"rg8\"\n\n[[rule]]\nfolder = \".\"\nscale = 0\n").unwrap();
    ok(&["bake", "parallax", "lib", "--recursive", "-o", "p", "--config", "c.toml"], d);
    ok(&["bake", "normal", "lib", "--recursive", "-o", "n", "--config", "c.toml"], d);
    for out in ["n/a_normal.png", "n/sub/b_normal.png"] {
        let img = image::open(d.join(out)).unwrap().to_rgb8();
        // scale 0 (folder ".") gives flat normals; rg8 stores no blue.
        assert!(img.pixels().all(|p| p.0 == [128, 128, 0]), "{out}: {:?}", img.get_pixel(3, 3));
    }
    std::fs::write(d.join("bad.toml"), "[[rule]]\nencoding = \"rgb16\"\n").unwrap();
    refuses(&["bake", "parallax", "lib", "-o", "q", "--config", "bad.toml"], d, &["bad.toml", "encoding", "rgb16"]);
}

// ---------------------------------------------------------------------------------------------
// Scene inputs

/// One quad (two triangles) of glTF with its buffer in the file `buffer` and, when given, a
/// base-colour image `image`.
fn gltf_quad(d: &Path, buffer: &str, image: Option<&str>) {
    let mut bin = Vec::new();
    for p in [[-1.0f32, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]] {
        p.iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    for uv in [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        uv.iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    for i in [0u16, 2, 1, 0, 3, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(d.join(buffer), &bin).unwrap();
    let images = image.map_or(String::new(), |i| format!(r#""images": [{{"uri": "{i}"}}],"#));
    let gltf = format!(
        r#"{{
      "asset": {{"version": "2.0"}},
      "buffers": [{{"uri": "{buffer}", "byteLength": {len}}}],
      {images}
      "bufferViews": [
        {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
        {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
        {{"buffer": 0, "byteOffset": 80, "byteLength": 12}}
      ],
      "accessors": [
        {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, 0, -1], "max": [1, 0, 1]}},
        {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
        {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}}
      ],
      "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2}}]}}],
      "nodes": [{{"mesh": 0}}],
      "scenes": [{{"nodes": [0]}}],
      "scene": 0
    }}"#,
        len = bin.len()
    );
    std::fs::write(d.join("mesh.gltf"), gltf).unwrap();
}

const GLTF_SCENE: &str = r#"
[camera]
eye = [0.0, 3.0, 3.0]
target = [0.0, 0.0, 0.0]

[[light]]
type = "directional"
direction = [0.3, 1.0, 0.2]

[[material]]
name = "m"
height = "builtin:bricks:32x32"
technique = "cone"
cone_map = "cones.png"

[[object]]
mesh = "mesh.gltf"
material = "m"
"#;

#[test]
fn render_refuses_to_write_over_a_gltf_buffer_or_image_or_a_cone_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A legal (if odd) buffer name: the buffer lives in mesh.png.
    gltf_quad(d, "mesh.png", Some("tex%20ture.png"));
    height_png(&d.join("tex ture.png"), 4, 4);
    ok(&["bake", "cone", "builtin:bricks:32x32", "-o", "cones.png"], d);
    std::fs::write(d.join("s.toml"), GLTF_SCENE).unwrap();
    let base = ["render", "s.toml", "--backend", "cpu", "--size", "16x16"];
    // The scene is valid: it renders to a new file.
    ok(&[&base[..], &["-o", "new.png"]].concat(), d);
    for (out, input) in [("mesh.png", "mesh.png"), ("tex ture.png", "tex ture.png"), ("cones.png", "cones.png")] {
        refuses(&[&base[..], &["-o", out]].concat(), d, &[out, "same file as the input", input]);
    }
}
