//! Input that would otherwise be ignored without a word: each is an error when it can only be a
//! mistake, a warning when it is harmless (docs/LIMITS.md, "Parameters"; docs/SCENES.md).

mod support;

use std::path::Path;
use std::process::{Command, Stdio};

use support::{pomkit, refuses, stderr};

fn write(dir: &Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

fn rays(dir: &Path) {
    write(dir, "r.csv", "u,v,dx,dy,dz\n0.3,0.4,0.5,0.2,-0.6\n");
}

#[test]
fn aov_with_compare_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    refuses(
        &["render", "--backend", "cpu", "--size", "16x16", "--compare", "pom,relief", "--aov", "depth", "-o", "c.png"],
        dir.path(),
        &["--aov", "--compare"],
    );
}

/// A scene of one plane whose material has no height map and sets `key`.
fn flat_material_scene(key: &str) -> String {
    format!(
        "[camera]\neye = [0.0, 2.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[light]]\ntype = \"directional\"\n\
         direction = [0.3, 1.0, 0.2]\n\n[[material]]\nname = \"m\"\nalbedo = \"builtin:bricks:16x16\"\n{key}\n\n\
         [[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
    )
}

#[test]
fn silhouette_and_depth_shadows_without_a_height_map_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (key, field) in [("silhouette = true", "silhouette"), ("shadow = \"depth\"", "shadow")] {
        write(d, "s.toml", &flat_material_scene(key));
        refuses(
            &["render", "s.toml", "--backend", "cpu", "--size", "8x8", "-o", "o.png"],
            d,
            &["s.toml", field, "no height map"],
        );
    }
    // Turning them off says nothing wrong.
    write(d, "s.toml", &flat_material_scene("silhouette = false"));
    let out = pomkit(&["render", "s.toml", "--backend", "cpu", "--size", "8x8", "-o", "o.png"], d);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn a_cone_map_the_technique_does_not_use_is_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bake = pomkit(&["bake", "cone", "builtin:bricks:16x16", "-o", "c.png"], d);
    assert!(bake.status.success(), "{}", stderr(&bake));
    rays(d);
    let trace = |technique: &str| {
        pomkit(
            &[
                "trace",
                "--height",
                "builtin:bricks:16x16",
                "--cone-map",
                "c.png",
                "--technique",
                technique,
                "--depth-scale",
                "0.1",
                "--rays",
                "r.csv",
                "-o",
                "h.csv",
            ],
            d,
        )
    };
    let out = trace("pom");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("warning: --cone-map") && stderr(&out).contains("pom"), "{}", stderr(&out));
    let out = trace("cone");
    assert!(out.status.success() && !stderr(&out).contains("warning"), "{}", stderr(&out));
    // In a scene: the material's technique is pom, and --technique does not make it cone.
    let scene = "[camera]\neye = [0.0, 2.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[light]]\ntype = \"directional\"\n\
                 direction = [0.3, 1.0, 0.2]\n\n[[material]]\nname = \"m\"\nheight = \"builtin:bricks:16x16\"\n\
                 technique = \"pom\"\ncone_map = \"c.png\"\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n";
    write(d, "s.toml", scene);
    let out = pomkit(&["render", "s.toml", "--backend", "cpu", "--size", "8x8", "-o", "o.png"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("warning: material \"m\"") && stderr(&out).contains("cone_map"), "{}", stderr(&out));
    let out =
        pomkit(&["render", "s.toml", "--backend", "cpu", "--size", "8x8", "--technique", "cone", "-o", "o.png"], d);
    assert!(out.status.success() && !stderr(&out).contains("warning"), "{}", stderr(&out));
}

#[test]
fn depth_map_with_a_builtin_height_is_refused_as_scene_files_do() {
    let dir = tempfile::tempdir().unwrap();
    refuses(
        &["bake", "normal", "builtin:bricks:16x16", "--depth-map", "-o", "n.png"],
        dir.path(),
        &["--depth-map", "builtin:bricks:16x16", "does not apply"],
    );
    rays(dir.path());
    refuses(
        &[
            "trace",
            "--height",
            "builtin:bricks:16x16",
            "--depth-map",
            "--technique",
            "pom",
            "--depth-scale",
            "0.1",
            "--rays",
            "r.csv",
            "-o",
            "h.csv",
        ],
        dir.path(),
        &["--depth-map", "builtin:bricks:16x16"],
    );
}

/// Runs `pomkit ARGS` in `dir` with standard output closed (`>&-`).
fn with_stdout_closed(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new("sh")
        .arg("-c")
        .arg("exec \"$0\" \"$@\" >&-")
        .arg(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("sh runs")
}

#[test]
fn a_closed_standard_output_fails_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    rays(d);
    let runs: [&[&str]; 3] = [
        &[
            "trace",
            "--height",
            "builtin:bricks:16x16",
            "--technique",
            "pom",
            "--depth-scale",
            "0.1",
            "--rays",
            "r.csv",
            "-o",
            "-",
        ],
        &["compare", "--height", "builtin:bricks:16x16", "--rays", "10", "--angles", "30", "--techniques", "pom"],
        &["bench", "--size", "8x8", "--runs", "1", "--techniques", "pom", "--backend", "cpu"],
    ];
    for args in runs {
        let out = with_stdout_closed(args, d);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("standard output") && err.contains("closed"), "{args:?}: {err}");
    }
    // Standard output on /dev/null is a choice, not a mistake.
    let out =
        Command::new(env!("CARGO_BIN_EXE_pomkit")).args(runs[1]).current_dir(d).stdout(Stdio::null()).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
}
