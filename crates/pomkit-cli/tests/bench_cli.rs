//! `pomkit bench` end to end: the CSV table has the promised header and one row per technique
//! with sane numbers, fetches agree with what the techniques are (normal mapping reads no
//! heights), and bad input fails with a clear message before any work (docs/LIMITS.md). The
//! CPU tests pin `--backend cpu`; the GPU tests print "skipping: <reason>" and pass when the
//! machine has no adapter (the binary says so), unless `POMKIT_REQUIRE_GPU=1`.
//!
//! Sizes: at 64x36 the demo's textures are minified so far (mip level above 5) that every
//! material takes its LOD fallback to normal mapping, and pom fetches nothing either. 160x90 is
//! the smallest cheap size where pom traces most covered pixels.

use std::process::{Command, Output};

const HEADER: &str = "technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel,\
gpu_runs,gpu_render_pass_ms,gpu_height_passes_ms,gpu_wall_ms,gpu_timer,gpu_fetches_per_pixel,gpu_over_cpu";

fn pomkit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).output().expect("pomkit runs")
}

/// The CPU renderer only: `pomkit bench --backend cpu ARGS`.
fn pomkit_cpu(args: &[&str]) -> Output {
    let mut all = vec!["bench", "--backend", "cpu"];
    all.extend_from_slice(args);
    pomkit(&all)
}

/// Runs `pomkit bench --backend gpu ARGS`; `None` (after printing "skipping: <reason>") when the
/// binary found no GPU adapter, a failure when `POMKIT_REQUIRE_GPU=1`.
fn pomkit_gpu(args: &[&str]) -> Option<Output> {
    let mut all = vec!["bench", "--backend", "gpu"];
    all.extend_from_slice(args);
    let out = pomkit(&all);
    let err = stderr(&out);
    if !out.status.success() && err.contains("no GPU adapter") {
        pomkit_gpu::context::skip_without_gpu(&err.lines().last().unwrap_or_default());
        return None;
    }
    Some(out)
}

/// A number field, empty meaning `None`.
fn num(f: &str) -> Option<f64> {
    (!f.is_empty()).then(|| f.parse().unwrap_or_else(|e| panic!("'{f}': {e}")))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// One CSV row: the CPU's fields, then the GPU's (empty when that renderer did not run).
#[derive(Debug)]
struct Row {
    technique: String,
    width: u32,
    height: u32,
    runs: u32,
    median_ms: f64,
    mpix_per_s: f64,
    fetches_per_pixel: f64,
    gpu_runs: u32,
    gpu_render_pass_ms: Option<f64>,
    gpu_height_passes_ms: Option<f64>,
    gpu_wall_ms: Option<f64>,
    gpu_timer: String,
    gpu_fetches_per_pixel: Option<f64>,
    gpu_over_cpu: Option<f64>,
}

/// Parses the CSV table, checking the header.
fn parse(text: &str) -> Vec<Row> {
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(HEADER), "header of:\n{text}");
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 14, "row '{l}'");
            Row {
                technique: f[0].to_owned(),
                width: f[1].parse().unwrap(),
                height: f[2].parse().unwrap(),
                runs: f[3].parse().unwrap(),
                median_ms: f[4].parse().unwrap(),
                mpix_per_s: f[5].parse().unwrap(),
                fetches_per_pixel: f[6].parse().unwrap(),
                gpu_runs: f[7].parse().unwrap(),
                gpu_render_pass_ms: num(f[8]),
                gpu_height_passes_ms: num(f[9]),
                gpu_wall_ms: num(f[10]),
                gpu_timer: f[11].to_owned(),
                gpu_fetches_per_pixel: num(f[12]),
                gpu_over_cpu: num(f[13]),
            }
        })
        .collect()
}

#[test]
fn csv_has_one_row_per_technique_and_normal_mapping_fetches_nothing() {
    let out = pomkit_cpu(&["--size", "160x90", "--runs", "1", "--techniques", "pom,normal", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = parse(&stdout(&out));
    let names: Vec<&str> = rows.iter().map(|r| r.technique.as_str()).collect();
    assert_eq!(names, ["pom", "normal"]);
    for r in &rows {
        assert_eq!((r.width, r.height, r.runs), (160, 90, 1), "{r:?}");
        assert!(r.median_ms.is_finite() && r.median_ms > 0.0, "{r:?}");
        assert!(r.mpix_per_s.is_finite() && r.mpix_per_s > 0.0, "{r:?}");
        // Megapixels per second is the frame's pixels over the median time.
        let expected = 160.0 * 90.0 / (r.median_ms / 1e3) / 1e6;
        assert!((r.mpix_per_s - expected).abs() <= 1e-6 * expected, "{r:?}: expected {expected} Mpix/s");
        assert!(r.fetches_per_pixel.is_finite() && r.fetches_per_pixel >= 0.0, "{r:?}");
        // --backend cpu: no GPU fields.
        assert_eq!((r.gpu_runs, r.gpu_render_pass_ms, r.gpu_over_cpu), (0, None, None), "{r:?}");
    }
    // Independent truth: normal mapping reads the normal map only, never the heights (its hit
    // is the polygon's surface, where no shadow trace can find an occluder); pom traces.
    assert_eq!(rows[1].fetches_per_pixel, 0.0, "normal: {:?}", rows[1]);
    assert!(rows[0].fetches_per_pixel > 1.0, "pom: {:?}", rows[0]);
}

#[test]
fn material_means_each_material_s_own_technique_exact_in_the_demo() {
    // The demo's materials all use the default technique, exact: `material` and `exact` draw
    // the same frames, so their fetches are the same.
    let out = pomkit_cpu(&["--size", "160x90", "--runs", "1", "--techniques", "material,exact", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = parse(&stdout(&out));
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].technique, "material");
    assert!(rows[0].fetches_per_pixel > 1.0, "{:?}", rows[0]);
    assert_eq!(rows[0].fetches_per_pixel, rows[1].fetches_per_pixel, "{rows:?}");
}

#[test]
fn markdown_is_the_default_and_progress_goes_to_stderr() {
    let out = pomkit_cpu(&["--size", "32x18", "--runs", "2", "--techniques", "pom"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains("| technique | size | runs | median ms/frame | Mpix/s | fetches per covered pixel |"),
        "{text}"
    );
    assert!(text.contains("| pom | 32x18 | 2 |"), "{text}");
    assert_eq!(text.lines().filter(|l| l.starts_with("| pom")).count(), 1, "{text}");
    assert!(stderr(&out).contains("pom: run 2/2"), "{}", stderr(&out));
}

/// Where each of `needles` first appears in `text`, in order; panics naming a missing one.
fn positions(text: &str, needles: &[&str]) -> Vec<usize> {
    needles.iter().map(|n| text.find(n).unwrap_or_else(|| panic!("'{n}' missing from:\n{text}"))).collect()
}

#[test]
fn the_techniques_take_turns_frame_by_frame() {
    // A slow spell of a shared machine should fall on every technique alike: the second frame
    // of any technique comes after the first frame of every other.
    let out = pomkit_cpu(&["--size", "32x18", "--runs", "2", "--techniques", "pom,normal"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let at = positions(&stderr(&out), &["pom: run 1/2", "normal: run 1/2", "pom: run 2/2", "normal: run 2/2"]);
    assert!(at.is_sorted(), "frames out of turn ({at:?}):\n{}", stderr(&out));
    let Some(out) =
        pomkit_gpu(&["--size", "32x18", "--gpu-runs", "2", "--cpu-runs", "0", "--techniques", "pom,normal"])
    else {
        return;
    };
    assert!(out.status.success(), "{}", stderr(&out));
    let at = positions(
        &stderr(&out),
        &["pom: gpu warm-up", "normal: gpu warm-up", "pom: gpu run 1/2", "normal: gpu run 1/2", "pom: gpu run 2/2"],
    );
    assert!(at.is_sorted(), "GPU frames out of turn ({at:?}):\n{}", stderr(&out));
}

#[test]
fn help_says_what_is_measured() {
    let out = pomkit(&["bench", "--help"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for needle in ["warm-up", "median", "--displaced", "fetches", "timestamp", "--backend", "1920x1080", HEADER] {
        assert!(text.contains(needle), "--help lacks '{needle}':\n{text}");
    }
}

#[test]
fn bad_input_fails_with_a_clear_message() {
    let cases: [(&[&str], &[&str]); 9] = [
        (&["--runs", "0"], &["--runs 0", "between 1 and"]),
        (&["--gpu-runs", "0"], &["--gpu-runs 0", "between 1 and"]),
        (&["--cpu-runs", "1001"], &["--cpu-runs 1001", "between 0 and 1000"]),
        (&["--backend", "cpu", "--cpu-runs", "0"], &["--cpu-runs 0", "nothing to time"]),
        (&["--size", "0x5"], &["--size", "'0x5'", "between 1 and 16384"]),
        (&["--size", "64"], &["--size", "not WxH"]),
        (&["--techniques", "pom,bogus"], &["unknown technique 'bogus'", "pom-classic", "material"]),
        (&["--techniques", "pom,,normal"], &["empty name"]),
        (&["--techniques", "displaced"], &["--displaced"]),
    ];
    for (args, needles) in cases {
        let mut all = vec!["bench"];
        all.extend_from_slice(args);
        let out = pomkit(&all);
        assert!(!out.status.success(), "{all:?} succeeded");
        let err = stderr(&out);
        for n in needles {
            assert!(err.contains(n), "{all:?}: stderr lacks '{n}':\n{err}");
        }
        assert!(stdout(&out).is_empty(), "{all:?} wrote a table:\n{}", stdout(&out));
    }
}

/// `all` in the list means every technique; `material` adds the materials' own; duplicates go.
#[test]
fn all_and_material_list_every_technique_once() {
    let out = pomkit_cpu(&["--size", "8x8", "--runs", "1", "--techniques", "pom,all,material,pom", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let names: Vec<String> = parse(&stdout(&out)).into_iter().map(|r| r.technique).collect();
    assert_eq!(
        names,
        [
            "pom",
            "flat",
            "normal",
            "parallax",
            "iterative",
            "steep",
            "pom-classic",
            "relief",
            "exact",
            "cone",
            "material"
        ]
    );
}

#[test]
fn gpu_columns_time_the_passes_and_count_the_same_fetches_as_the_cpu() {
    let args = ["--size", "160x90", "--gpu-runs", "2", "--cpu-runs", "1", "--techniques", "pom,normal", "--format"];
    let Some(out) = pomkit_gpu(&[&args[..], &["csv"]].concat()) else { return };
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("backend: gpu ("), "{}", stderr(&out));
    assert!(stderr(&out).contains("pom: gpu run 2/2"), "{}", stderr(&out));
    let rows = parse(&stdout(&out));
    assert_eq!(rows.len(), 2);
    for r in &rows {
        assert_eq!((r.gpu_runs, r.runs), (2, 1), "{r:?}");
        assert!(["timestamps", "wall"].contains(&r.gpu_timer.as_str()), "{r:?}");
        let (pass, heights, wall) =
            (r.gpu_render_pass_ms.unwrap(), r.gpu_height_passes_ms.unwrap(), r.gpu_wall_ms.unwrap());
        assert!(pass > 0.0 && heights > 0.0 && pass.is_finite() && heights.is_finite(), "{r:?}");
        // The whole frame holds both passes.
        assert!(wall >= pass && wall >= heights, "{r:?}");
        let ratio = r.gpu_over_cpu.unwrap();
        assert!((ratio - pass / r.median_ms).abs() <= 1e-9 * ratio, "{r:?}");
        // The GPU runs the same techniques as the CPU: the same fetches, within 2%.
        let (g, c) = (r.gpu_fetches_per_pixel.unwrap(), r.fetches_per_pixel);
        assert!((g - c).abs() <= 0.02 * c.max(1.0), "{r:?}");
    }
    assert_eq!(rows[1].gpu_fetches_per_pixel, Some(0.0), "normal: {:?}", rows[1]);
    assert!(rows[0].gpu_fetches_per_pixel.unwrap() > 1.0, "pom: {:?}", rows[0]);
}

#[test]
fn gpu_markdown_has_the_gpu_columns() {
    let Some(out) = pomkit_gpu(&["--size", "32x18", "--runs", "1", "--techniques", "normal"]) else { return };
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains(
            "| technique | GPU render pass ms | GPU height passes ms | GPU whole frame ms | CPU ms/frame | GPU/CPU |"
        ),
        "{text}"
    );
    assert!(text.contains("GPU: ") && text.contains("median of 1 frame"), "{text}");
    assert_eq!(text.lines().filter(|l| l.starts_with("| normal |")).count(), 1, "{text}");
    // --cpu-runs 0: the GPU alone.
    let Some(out) = pomkit_gpu(&["--size", "32x18", "--runs", "1", "--cpu-runs", "0", "--techniques", "flat"]) else {
        return;
    };
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("| technique | GPU render pass ms |") && !text.contains("CPU ms/frame"), "{text}");
}

#[test]
fn without_an_adapter_auto_skips_the_gpu_columns_and_says_why() {
    // A graphics API this platform lacks: the GPU renderer finds no adapter.
    let absent = if cfg!(target_os = "macos") { "dx12" } else { "metal" };
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).env("WGPU_BACKEND", absent).output().unwrap()
    };
    let out = run(&["bench", "--size", "16x9", "--runs", "1", "--techniques", "normal"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("GPU columns skipped: no GPU adapter"), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("No GPU columns: no GPU adapter") && !text.contains("GPU render pass"), "{text}");
    assert!(text.contains("| normal | 16x9 | 1 |"), "{text}");
    let out = run(&["bench", "--backend", "gpu", "--size", "16x9", "--runs", "1"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("no GPU adapter") && stderr(&out).contains("mesa-vulkan-drivers"),
        "{}",
        stderr(&out)
    );
    assert!(stdout(&out).is_empty());
}
