//! `pomkit render` end to end: golden images of the demo scene, AOVs, the comparison sheet, and
//! bad scenes failing with a message that names the field; `--backend gpu` against `--backend
//! cpu`, and `auto` saying which it used.
//!
//! GPU tests run on any adapter, Mesa's lavapipe included. Where no adapter exists they print
//! "skipping: <reason>" and pass, unless `POMKIT_REQUIRE_GPU=1`, where they fail.
//!
//! Golden images live in `tests/golden/`. A render matches when at most 0.5% of its pixels
//! differ from the golden one by more than 24 (of 255) in some channel; failures write the
//! render and a difference image to `target/golden-failures/` for inspection. To re-approve
//! after an intended change, run with `POMKIT_APPROVE=1` and commit the new PNGs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

fn pomkit(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).current_dir(dir).output().expect("pomkit runs")
}

/// Whether this machine has a GPU adapter. Without one: prints "skipping: <reason>" and returns
/// false, or panics when `POMKIT_REQUIRE_GPU=1`.
fn gpu_available() -> bool {
    static NO_GPU: OnceLock<Option<String>> = OnceLock::new();
    let reason = NO_GPU.get_or_init(|| pomkit_gpu::GpuContext::new().err().map(|e| e.to_string()));
    match reason {
        None => true,
        Some(e) => {
            pomkit_gpu::context::skip_without_gpu(e);
            false
        }
    }
}

/// The backends to test: the CPU, and the GPU when there is an adapter (else "skipping").
fn backends() -> Vec<&'static str> {
    if gpu_available() { vec!["cpu", "gpu"] } else { vec!["cpu"] }
}

/// A `WGPU_BACKEND` value naming a graphics API this platform does not have, so that the GPU
/// renderer finds no adapter (pomkit-gpu honours the variable).
const ABSENT_API: &str = if cfg!(target_os = "macos") { "dx12" } else { "metal" };

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// Compares `actual` with the golden image `name`, or writes it when approving.
fn check_golden(actual: &Path, name: &str) {
    let golden = golden_dir().join(name);
    if std::env::var_os("POMKIT_APPROVE").is_some() {
        std::fs::create_dir_all(golden_dir()).unwrap();
        std::fs::copy(actual, &golden).unwrap();
        eprintln!("approved {}", golden.display());
        return;
    }
    let a = image::open(actual).expect("render decodes").to_rgb8();
    let g = image::open(&golden)
        .unwrap_or_else(|e| panic!("golden image {} missing ({e}); run with POMKIT_APPROVE=1", golden.display()))
        .to_rgb8();
    assert_eq!(a.dimensions(), g.dimensions(), "{name}: size");
    let mut diff = image::RgbImage::new(a.width(), a.height());
    let mut over = 0usize;
    for (x, y, p) in a.enumerate_pixels() {
        let q = g.get_pixel(x, y);
        let worst = (0..3).map(|c| (i32::from(p[c]) - i32::from(q[c])).unsigned_abs()).max().unwrap();
        if worst > 24 {
            over += 1;
        }
        diff.put_pixel(x, y, image::Rgb([(worst * 4).min(255) as u8; 3]));
    }
    let allowed = (a.width() * a.height()) as usize / 200;
    if over > allowed {
        let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/golden-failures");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::copy(actual, out.join(name)).unwrap();
        diff.save(out.join(format!("diff-{name}"))).unwrap();
        panic!("{name}: {over} pixels differ (allowed {allowed}); see {}", out.display());
    }
}

#[test]
fn demo_scene_matches_its_golden_images() {
    let dir = tempfile::tempdir().unwrap();
    for (args, name) in [
        // The demo's technique is the default one, `exact`: the same picture as `--technique
        // exact`, checked against that golden image.
        (vec!["render", "--backend", "cpu", "--size", "320x180", "-o", "demo.png"], "demo-exact.png"),
        (
            vec!["render", "--backend", "cpu", "--size", "320x180", "--technique", "pom", "-o", "pom.png"],
            "demo-pom.png",
        ),
        (
            vec!["render", "--backend", "cpu", "--size", "320x180", "--technique", "normal", "-o", "normal.png"],
            "demo-normal.png",
        ),
        (
            vec!["render", "--backend", "cpu", "--size", "320x180", "--technique", "steep", "-o", "steep.png"],
            "demo-steep.png",
        ),
        (
            vec!["render", "--backend", "cpu", "--size", "320x180", "--technique", "exact", "-o", "exact.png"],
            "demo-exact.png",
        ),
    ] {
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        let file = dir.path().join(args[args.len() - 1]);
        check_golden(&file, name);
    }
}

#[test]
fn aovs_are_float_exr_beside_the_png() {
    for backend in backends() {
        aovs_are_float_exr_beside_the_png_on(backend);
    }
}

fn aovs_are_float_exr_beside_the_png_on(backend: &str) {
    let dir = tempfile::tempdir().unwrap();
    // Large enough that the height maps are not minified past the LOD threshold (where the
    // LOD system stops tracing and fetches drop to 0).
    let args =
        ["render", "--backend", backend, "--size", "320x180", "-o", "f.png", "--aov", "uv,depth,shadow,fetches,lod"];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{backend}: {}", stderr(&out));
    let depth = image::open(dir.path().join("f.depth.exr")).unwrap().to_rgb32f();
    let fetches = image::open(dir.path().join("f.fetches.exr")).unwrap().to_rgb32f();
    let shadow = image::open(dir.path().join("f.shadow.exr")).unwrap().to_rgb32f();
    let uv = image::open(dir.path().join("f.uv.exr")).unwrap().to_rgb32f();
    assert_eq!(depth.dimensions(), (320, 180));
    assert!(depth.pixels().all(|p| (0.0..=1.0).contains(&p[0])));
    assert!(shadow.pixels().all(|p| (0.0..=1.0).contains(&p[0])));
    // The demo's pom materials fetch heights wherever a surface is visible.
    let covered = uv.pixels().filter(|p| p[0] != 0.0 || p[1] != 0.0).count();
    let fetched = fetches.pixels().filter(|p| p[0] > 0.0).count();
    assert!(covered > 320 * 180 / 3 && fetched > covered / 2, "{backend}: covered {covered}, fetched {fetched}");
    assert!(dir.path().join("f.lod.exr").exists());
    // The mean fetches it prints are the EXR's sum over the covered pixels.
    let err = stderr(&out);
    let printed: f64 = err
        .split("mean height fetches per covered pixel: ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{backend}: no mean fetches in {err:?}"));
    let total: f64 = fetches.pixels().map(|p| f64::from(p[0])).sum();
    let mean = total / covered as f64;
    assert!((printed - mean).abs() <= 0.01 + 0.005 * mean, "{backend}: printed {printed}, the EXR says {mean}");
}

/// A small scene file: one cobblestone plane with 64x64 maps, so the displaced reference
/// (tessellated to the map's resolution) is quick.
const SMALL_SCENE: &str = r#"
[camera]
eye = [0.0, 1.6, 2.2]
target = [0.0, 0.0, 0.0]
fov = 40.0
[[light]]
type = "directional"
direction = [0.5, 0.8, 0.3]
intensity = 2.0
[[material]]
name = "stones"
albedo = "builtin:cobblestones:64x64"
height = "builtin:cobblestones:64x64"
technique = "pom"
depth_scale = 0.06
shadow = "soft"
[[object]]
mesh = "plane"
size = [3.0, 3.0]
material = "stones"
"#;

#[test]
fn compare_sheet_and_difference_report() {
    for backend in backends() {
        compare_sheet_and_difference_report_on(backend);
    }
}

fn compare_sheet_and_difference_report_on(backend: &str) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("small.toml"), SMALL_SCENE).unwrap();
    let args = [
        "render",
        "small.toml",
        "--backend",
        backend,
        "--size",
        "96x64",
        "--compare",
        "normal,pom,displaced",
        "-o",
        "sheet.png",
    ];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{backend}: {}", stderr(&out));
    let msg = stderr(&out);
    assert!(msg.contains("PSNR") && msg.contains("normal") && msg.contains("pom"), "{msg}");
    // pom is closer to the displaced truth than normal mapping: parse the two PSNRs.
    let psnr = |name: &str| -> f64 {
        let line = msg.lines().find(|l| l.trim_start().starts_with(name) && l.contains("PSNR")).unwrap();
        line.split("PSNR").nth(1).unwrap().split_whitespace().next().unwrap().parse().unwrap()
    };
    assert!(psnr("pom") > psnr("normal") + 3.0, "{msg}");
    let sheet = image::open(dir.path().join("sheet.png")).unwrap();
    // Three 96x64 panels side by side with 4-pixel gaps.
    assert_eq!((sheet.width(), sheet.height()), (3 * 96 + 4 * 4, 64 + 2 * 4));
}

#[test]
fn bad_scenes_and_flags_fail_with_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let scene = |body: &str| {
        let p = dir.path().join("scene.toml");
        std::fs::write(&p, body).unwrap();
        p
    };
    let good_camera = "[camera]\neye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n";
    let cases: Vec<(String, &str)> = vec![
        (
            format!(
                "{good_camera}[[material]]\nname = \"m\"\ntechnique = \"pomm\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
            ),
            "technique",
        ),
        (
            format!(
                "{good_camera}[[material]]\nname = \"m\"\ndepth_scale = \"a\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
            ),
            "depth_scale",
        ),
        (
            format!(
                "{good_camera}[[material]]\nname = \"m\"\nheight = \"missing.png\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
            ),
            "missing.png",
        ),
        (
            format!("{good_camera}[[material]]\nname = \"m\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"nope\"\n"),
            "nope",
        ),
    ];
    for (body, needle) in &cases {
        let p = scene(body);
        let out = pomkit(&["render", p.to_str().unwrap(), "--size", "32x32", "-o", "x.png"], dir.path());
        assert!(!out.status.success(), "{body}");
        let msg = stderr(&out);
        assert!(
            msg.contains(needle) && msg.contains("scene.toml"),
            "message {msg:?} should name {needle:?} and the file"
        );
        assert!(!dir.path().join("x.png").exists());
    }
    for (args, needle) in [
        (vec!["render", "--technique", "cones", "-o", "x.png"], "cones"),
        (vec!["render", "--size", "0x10", "-o", "x.png"], "--size"),
        (vec!["render", "--aov", "normals", "-o", "x.png"], "normals"),
        (vec!["render", "-o", "x.jpg"], ".png"),
        (vec!["render", "missing.toml", "-o", "x.png"], "missing.toml"),
    ] {
        let out = pomkit(&args, dir.path());
        assert!(!out.status.success(), "{args:?}");
        assert!(stderr(&out).contains(needle), "{args:?}: {}", stderr(&out));
    }
}

#[test]
fn example_scenes_render() {
    let dir = tempfile::tempdir().unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&examples).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            for backend in backends() {
                let args = ["render", path.to_str().unwrap(), "--backend", backend, "--size", "48x27", "-o", "e.png"];
                let out = pomkit(&args, dir.path());
                assert!(out.status.success(), "{} ({backend}): {}", path.display(), stderr(&out));
            }
            n += 1;
        }
    }
    assert!(n > 0, "no example scenes found");
}

#[test]
fn lod_tint_changes_the_picture() {
    for backend in backends() {
        lod_tint_changes_the_picture_on(backend);
    }
}

fn lod_tint_changes_the_picture_on(backend: &str) {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        ["render", "--backend", backend, "--size", "80x45", "-o", "plain.png", ""],
        ["render", "--backend", backend, "--size", "80x45", "-o", "tint.png", "--lod-tint"],
    ] {
        let args: Vec<&str> = args.into_iter().filter(|a| !a.is_empty()).collect();
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{backend}: {}", stderr(&out));
    }
    let a = image::open(dir.path().join("plain.png")).unwrap().to_rgb8();
    let b = image::open(dir.path().join("tint.png")).unwrap().to_rgb8();
    let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(changed > (80 * 45) / 4, "{backend}: the tint should recolour the textured surfaces: {changed}");
}

/// sRGB8 pixels of a PNG.
fn rgb(path: &Path) -> image::RgbImage {
    image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8()
}

/// Mean absolute difference per channel (8-bit levels) and the share of pixels with some
/// channel off by more than 20.
fn difference(a: &image::RgbImage, b: &image::RgbImage) -> (f64, f64) {
    assert_eq!(a.dimensions(), b.dimensions());
    let (mut sum, mut over) = (0u64, 0usize);
    for (p, q) in a.pixels().zip(b.pixels()) {
        let d = (0..3).map(|c| (i32::from(p[c]) - i32::from(q[c])).unsigned_abs());
        sum += d.clone().map(u64::from).sum::<u64>();
        over += usize::from(d.max().unwrap() > 20);
    }
    let n = (a.width() * a.height()) as f64;
    (sum as f64 / (3.0 * n), over as f64 / n)
}

/// The GPU and the CPU draw the same demo frame. Tolerance: mean absolute difference under 1.0
/// level and at most 0.5% of pixels off by more than 20 in some channel. Measured on lavapipe
/// (Mesa 22.3): mean 0.025 levels, 0.002% of pixels (one) over 20; the margin is for real GPUs,
/// whose texture filtering is less precise.
#[test]
fn gpu_render_matches_the_cpu_render() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (backend, file) in [("gpu", "gpu.png"), ("cpu", "cpu.png")] {
        let out = pomkit(&["render", "--backend", backend, "--size", "320x180", "-o", file], dir.path());
        assert!(out.status.success(), "{backend}: {}", stderr(&out));
        if backend == "gpu" {
            assert!(stderr(&out).contains("backend: gpu ("), "{}", stderr(&out));
        }
    }
    let (mean, over) = difference(&rgb(&dir.path().join("gpu.png")), &rgb(&dir.path().join("cpu.png")));
    println!("GPU vs CPU: mean difference {mean:.3} levels, {:.3}% of pixels over 20", over * 100.0);
    assert!(mean < 1.0, "GPU and CPU renders differ: mean {mean:.3} levels");
    assert!(over <= 0.005, "GPU and CPU renders differ: {:.3}% of pixels by more than 20", over * 100.0);
}

/// Every option of `render` works on the GPU: supersampling, the displaced ground truth, a
/// technique override, and AOVs with supersampling; each agrees with the CPU's picture (mean
/// under 2 levels, at most 2% of pixels over 20; measured on lavapipe: means 0.02-0.2, and 0.26%
/// over 20 for the displaced meshes, whose silhouettes are most of the differing pixels at this size).
#[test]
fn gpu_backend_takes_every_render_option() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("small.toml"), SMALL_SCENE).unwrap();
    let cases: [&[&str]; 3] = [
        &["small.toml", "--size", "64x48", "--supersample", "2", "--aov", "fetches,uv"],
        &["small.toml", "--size", "64x48", "--technique", "displaced", "--displaced-tolerance", "0"],
        &["--size", "160x90", "--technique", "relief"],
    ];
    for (i, extra) in cases.into_iter().enumerate() {
        let mut files = Vec::new();
        for backend in ["gpu", "cpu"] {
            let file = format!("{backend}{i}.png");
            let mut args = vec!["render", "--backend", backend, "-o", &file];
            args.extend_from_slice(extra);
            let out = pomkit(&args, dir.path());
            assert!(out.status.success(), "{args:?}: {}", stderr(&out));
            files.push(dir.path().join(&file));
        }
        let (mean, over) = difference(&rgb(&files[0]), &rgb(&files[1]));
        println!("{extra:?}: GPU vs CPU mean {mean:.3}, {:.3}% over 20", over * 100.0);
        assert!(mean < 2.0 && over <= 0.02, "{extra:?}: GPU and CPU differ: mean {mean:.3}, {over:.4} over 20");
    }
    let fetches = image::open(dir.path().join("gpu0.fetches.exr")).unwrap().to_rgb32f();
    assert_eq!(fetches.dimensions(), (64, 48));
    assert!(fetches.pixels().any(|p| p[0] > 1.0), "pom fetches heights on the GPU too");
}

#[test]
fn auto_says_which_backend_it_used() {
    let dir = tempfile::tempdir().unwrap();
    let out = pomkit(&["render", "--size", "32x18", "-o", "a.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let expected = if gpu_available() { "backend: gpu (" } else { "backend: cpu (" };
    assert!(stderr(&out).contains(expected), "expected '{expected}' in:\n{}", stderr(&out));
}

#[test]
fn without_an_adapter_auto_falls_back_and_gpu_fails_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let run = |backend: &str, file: &str| {
        Command::new(env!("CARGO_BIN_EXE_pomkit"))
            .args(["render", "--backend", backend, "--size", "32x18", "-o", file])
            .env("WGPU_BACKEND", ABSENT_API)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    let out = run("auto", "auto.png");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("backend: cpu (no GPU adapter"), "{}", stderr(&out));
    assert!(dir.path().join("auto.png").exists());
    let out = run("gpu", "gpu.png");
    assert!(!out.status.success());
    for needle in ["--backend gpu", "no GPU adapter", "mesa-vulkan-drivers", "--backend cpu"] {
        assert!(stderr(&out).contains(needle), "lacks '{needle}': {}", stderr(&out));
    }
    assert!(!dir.path().join("gpu.png").exists());
}

#[test]
fn help_describes_the_backends() {
    let out = pomkit(&["render", "--help"], Path::new("."));
    let text = String::from_utf8_lossy(&out.stdout);
    for needle in ["--backend", "cpu", "gpu", "auto", "adapter"] {
        assert!(text.contains(needle), "--help lacks '{needle}':\n{text}");
    }
}

/// The GPU renderer shades at most 4 lights: `auto` falls back to the CPU and says why, `gpu`
/// fails naming the limit and writes nothing.
#[test]
fn auto_falls_back_to_the_cpu_for_what_the_gpu_cannot_draw() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let light = "[[light]]\ntype = \"directional\"\ndirection = [0.5, 0.8, 0.3]\nintensity = 0.4\n";
    let scene = format!(
        "[camera]\neye = [0.0, 1.6, 2.2]\ntarget = [0.0, 0.0, 0.0]\n{}[[material]]\nname = \"m\"\n\
         height = \"builtin:bricks:32x32\"\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n",
        light.repeat(5)
    );
    std::fs::write(dir.path().join("five.toml"), scene).unwrap();
    let out = pomkit(&["render", "five.toml", "--size", "32x18", "-o", "auto.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("backend: cpu (the GPU renderer cannot draw this"), "{}", stderr(&out));
    assert!(stderr(&out).contains("5 lights"), "{}", stderr(&out));
    assert!(dir.path().join("auto.png").exists());
    let out = pomkit(&["render", "five.toml", "--backend", "gpu", "--size", "32x18", "-o", "gpu.png"], dir.path());
    assert!(!out.status.success());
    assert!(stderr(&out).contains("5 lights"), "{}", stderr(&out));
    assert!(!dir.path().join("gpu.png").exists());
}
