//! Replays the saved fuzz corpora and crash reproducers (docs/FUZZING.md) through the fuzz
//! targets' own entry points, `pomkit_io::fuzz_entry`: no input may panic, and every error
//! must name its input. No fuzzing happens here; this keeps what the fuzzer found fixed.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use pomkit_io::fuzz_entry::{Outcome, TARGETS, Target};

/// `fuzz/<kind>/<target>/` in the repository.
fn folder(kind: &str, target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz").join(kind).join(target)
}

/// The files of a folder, sorted; none when it does not exist.
fn files(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut files: Vec<PathBuf> = entries.map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect();
    files.sort();
    files
}

/// Runs every file through the target; returns the failures, one line each naming the file.
fn replay(target: &Target, files: &[PathBuf]) -> Vec<String> {
    let mut failures = Vec::new();
    for file in files {
        let bytes = std::fs::read(file).unwrap();
        if let Err(panic) = catch_unwind(AssertUnwindSafe(|| (target.run)(&bytes))) {
            let message = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("(no message)");
            failures.push(format!("{}: {message}", file.display()));
        }
    }
    failures
}

/// Reproducers of open findings, not replayed until their fix lands (docs/FUZZING.md, "What
/// was found"). None is open.
const OPEN: &[&str] = &[];

/// Replays the corpus (which must not be empty) and the reproducers of one target.
fn check(name: &str) {
    let target = TARGETS.iter().find(|t| t.name == name).unwrap();
    let corpus = files(&folder("corpus", name));
    assert!(
        !corpus.is_empty(),
        "{} is missing or empty: the saved corpus of the {name} fuzz target (docs/FUZZING.md)",
        folder("corpus", name).display()
    );
    let mut all = corpus;
    let open = |f: &PathBuf| f.file_name().is_some_and(|n| OPEN.iter().any(|o| n == *o));
    all.extend(files(&folder("regressions", name)).into_iter().filter(|f| !open(f)));
    let failures = replay(target, &all);
    assert!(failures.is_empty(), "{} of {} inputs failed:\n{}", failures.len(), all.len(), failures.join("\n"));
}

#[test]
fn every_target_has_a_test_here() {
    let names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
    assert_eq!(names, ["height_image", "normal_map", "scene", "obj", "gltf", "rays", "batch_config"]);
    for t in TARGETS {
        let source = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../fuzz/fuzz_targets/{}.rs", t.name));
        assert!(source.is_file(), "no fuzz target {}", source.display());
    }
}

#[test]
fn height_image_corpus() {
    check("height_image");
}

#[test]
fn normal_map_corpus() {
    check("normal_map");
}

#[test]
fn scene_corpus() {
    check("scene");
}

#[test]
fn obj_corpus() {
    check("obj");
}

#[test]
fn gltf_corpus() {
    check("gltf");
}

#[test]
fn rays_corpus() {
    check("rays");
}

#[test]
fn batch_config_corpus() {
    check("batch_config");
}

/// The entries refuse what is not a file of their format with a message naming the input, and
/// load the smallest valid file of their format.
#[test]
fn entries_refuse_garbage_and_load_valid_files() {
    // Not a valid file of any format, even after its first (options) byte; UTF-8, as the scene
    // entry skips other bytes (`load_scene` refuses them before parsing).
    let garbage = b"\x00\x01not a valid file of any kind ~~~";
    for t in TARGETS {
        match (t.run)(garbage) {
            Outcome::Refused(message) => assert!(message.contains(t.input), "{}: {message}", t.name),
            other => panic!("{}: garbage gave {other:?}", t.name),
        }
    }
    let run = |name: &str, bytes: &[u8]| (TARGETS.iter().find(|t| t.name == name).unwrap().run)(bytes);
    let quad = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n";
    assert_eq!(run("obj", quad.as_bytes()), Outcome::Loaded);
    assert_eq!(run("rays", b"\x03u,v,dx,dy,dz\n0.5,0.5,0,0,-1\n"), Outcome::Loaded);
    let scene = "[camera]\neye = [0, 2, 4]\ntarget = [0, 0, 0]\n[[material]]\nname = \"m\"\nheight = \"h.png\"\n\
                 [[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n";
    assert_eq!(run("scene", scene.as_bytes()), Outcome::Loaded);
    // A scene asking for a 4096x4096 built-in is not passed to the parser.
    let big = scene.replace("h.png", "builtin:bricks:4096x4096");
    assert_eq!(run("scene", big.as_bytes()), Outcome::Skipped);
    let rules = "[[rule]]\nfolder = \"rocks\"\nscale = 4.0\n\n[[rule]]\nmatch = \"*_gl.png\"\ny_down = false\n";
    assert_eq!(run("batch_config", rules.as_bytes()), Outcome::Loaded);
}

/// The crashes the fuzzer found (docs/FUZZING.md, "What was found") are refused with their
/// cause, not only without a panic: without pomkit-io's checks, each is a panic in tobj or gltf,
/// which `load_mesh` turns into "the parser failed on malformed data".
#[test]
fn reproducers_are_refused_with_their_cause() {
    let cases = [
        ("obj", "face-index-overflow", "line 7: corner \"-3/-3\" refers to no texture coordinate (vt)"),
        ("obj", "line-element-index-overflow", "refers to no texture coordinate (vt)"),
        ("gltf", "position-accessor-out-of-range", "an attribute refers to accessor"),
        ("gltf", "glb-length-below-header", "its GLB header declares"),
        ("gltf", "normal-accessor-wrong-type", "but NORMAL must be a VEC3 of floats"),
        ("normal_map", "exr-huge-chunk-oom", "its tiles are 3211328x16384 pixels"),
    ];
    for (name, file, needle) in cases {
        let target = TARGETS.iter().find(|t| t.name == name).unwrap();
        let bytes = std::fs::read(folder("regressions", name).join(file)).unwrap();
        match (target.run)(&bytes) {
            Outcome::Refused(message) => {
                assert!(message.contains(needle) && message.contains(target.input), "{file}: {message}");
            }
            other => panic!("{file}: {other:?}"),
        }
    }
}
