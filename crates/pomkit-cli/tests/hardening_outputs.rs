//! Outputs, end to end: no output overwrites an input
//! or another output, through any path or link; a failed run leaves no file; write errors
//! (a full device, a full standard output) fail the run; read-only outputs are refused, symbolic
//! links written through; rays are streamed, and binary or endless rays fail within a line.

mod support;

use std::path::Path;
use std::process::{Command, Stdio};

use pomkit_core::EdgeMode;
use pomkit_core::glam::{Vec2, Vec3};
use pomkit_core::procedural::{self, Pattern};
use pomkit_core::trace::{Ray, Surface, Technique, TraceParams, trace};
use support::{pomkit, pomkit_with_input, refuses, snapshot, stderr};

/// A small grey PNG, as an input file.
fn png(path: &Path) {
    image::GrayImage::from_fn(8, 8, |x, y| image::Luma([(x * 30 + y) as u8])).save(path).unwrap();
}

/// A small RGB PNG (a colour or normal map).
fn rgb_png(path: &Path, rgb: [u8; 3]) {
    image::RgbImage::from_pixel(4, 4, image::Rgb(rgb)).save(path).unwrap();
}

#[cfg(unix)]
fn symlink(target: &str, link: &Path) {
    std::os::unix::fs::symlink(target, link).unwrap();
}

const GOOD_RAYS: &str = "u,v,dx,dy,dz\n0.5,0.5,0.1,0,-1\n0.25,0.75,-0.3,0.2,-0.5\n";

#[test]
fn bake_refuses_to_write_over_its_input_through_any_path() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("sub")).unwrap();
    png(&d.join("in.png"));
    std::fs::hard_link(d.join("in.png"), d.join("hard.png")).unwrap();
    for out in ["in.png", "sub/../in.png", "./in.png", "hard.png"] {
        refuses(&["bake", "normal", "in.png", "-o", out], d, &[out, "same file as the input in.png"]);
    }
    // The hard link read as the input, the original as the output.
    refuses(&["bake", "pack", "hard.png", "-o", "in.png"], d, &["in.png", "same file as the input hard.png"]);
    #[cfg(unix)]
    {
        symlink("in.png", &d.join("link.png"));
        refuses(&["bake", "parallax", "in.png", "-o", "link.png"], d, &["link.png", "same file as the input"]);
        refuses(&["bake", "normal", "link.png", "-o", "in.png"], d, &["in.png", "same file as the input link.png"]);
    }
}

#[test]
fn trace_refuses_to_write_over_its_rays_or_height_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("sub")).unwrap();
    std::fs::write(d.join("r.csv"), GOOD_RAYS).unwrap();
    png(&d.join("h.png"));
    std::fs::hard_link(d.join("r.csv"), d.join("r2.csv")).unwrap();
    let run = |rays: &str, height: &str, out: &str| {
        let args = ["trace", "--height", height, "--technique", "pom", "--rays", rays, "-o", out];
        refuses(&args, d, &[out, "same file as the input"]);
    };
    run("r.csv", "builtin:bricks:16x16", "r.csv");
    run("r.csv", "builtin:bricks:16x16", "sub/../r.csv");
    run("r.csv", "builtin:bricks:16x16", "r2.csv");
    run("r.csv", "h.png", "h.png");
    run("r.csv", "h.png", "sub/../h.png");
    #[cfg(unix)]
    {
        symlink("../r.csv", &d.join("sub/link.csv"));
        run("r.csv", "builtin:bricks:16x16", "sub/link.csv");
        run("sub/link.csv", "builtin:bricks:16x16", "r.csv");
    }
}

/// A scene in `d` that reads `scene.png` (itself), `tex.png` (colour), `h.png` (height),
/// `n.png` (normal map) and `out.depth.exr` (a float colour map).
fn scene_with_files(d: &Path) {
    rgb_png(&d.join("tex.png"), [200, 100, 50]);
    png(&d.join("h.png"));
    rgb_png(&d.join("n.png"), [128, 128, 255]);
    image::Rgb32FImage::from_pixel(2, 2, image::Rgb([0.5, 0.5, 0.5]))
        .save_with_format(d.join("out.depth.exr"), image::ImageFormat::OpenExr)
        .unwrap();
    let scene = r#"
[camera]
eye = [0.0, 2.0, 3.0]
target = [0.0, 0.0, 0.0]

[[light]]
type = "directional"
direction = [0.3, 1.0, 0.2]

[[material]]
name = "a"
albedo = "tex.png"
height = "h.png"
normal = "n.png"

[[material]]
name = "b"
albedo = "out.depth.exr"

[[object]]
mesh = "plane"
material = "a"

[[object]]
mesh = "cube"
size = 0.3
material = "b"
"#;
    std::fs::write(d.join("scene.png"), scene).unwrap();
}

#[test]
fn render_refuses_to_write_over_any_file_its_scene_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("sub")).unwrap();
    scene_with_files(d);
    // The scene is valid: it renders to a new file.
    let ok = pomkit(&["render", "scene.png", "--backend", "cpu", "--size", "8x8", "-o", "ok.png"], d);
    assert!(ok.status.success(), "{}", stderr(&ok));
    std::fs::remove_file(d.join("ok.png")).unwrap();
    let base = ["render", "scene.png", "--backend", "cpu", "--size", "8x8"];
    for (out, input) in
        [("tex.png", "tex.png"), ("sub/../h.png", "h.png"), ("./n.png", "n.png"), ("scene.png", "scene.png")]
    {
        refuses(&[&base[..], &["-o", out]].concat(), d, &[out, "same file as the input", input]);
    }
    std::fs::hard_link(d.join("tex.png"), d.join("hard.png")).unwrap();
    refuses(&[&base[..], &["-o", "hard.png"]].concat(), d, &["hard.png", "same file as the input"]);
    #[cfg(unix)]
    {
        symlink("../n.png", &d.join("sub/link.png"));
        refuses(&[&base[..], &["-o", "sub/link.png"]].concat(), d, &["sub/link.png", "same file as the input"]);
    }
    // An AOV beside the PNG is an output too: out.depth.exr is the second material's colour map.
    refuses(
        &[&base[..], &["-o", "out.png", "--aov", "depth"]].concat(),
        d,
        &["out.depth.exr", "same file as the input"],
    );
}

#[test]
fn generate_refuses_the_same_file_for_both_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("sub")).unwrap();
    refuses(
        &["generate", "bricks", "--size", "16x16", "-o", "x.png", "--albedo", "x.png"],
        d,
        &["x.png", "same file as the output"],
    );
    refuses(
        &["generate", "bricks", "--size", "16x16", "-o", "x.png", "--albedo", "sub/../x.png"],
        d,
        &["x.png", "same file as the output"],
    );
    // Also when the file exists already, through a hard link.
    png(&d.join("x.png"));
    std::fs::hard_link(d.join("x.png"), d.join("y.png")).unwrap();
    refuses(
        &["generate", "bricks", "--size", "16x16", "-o", "x.png", "--albedo", "y.png"],
        d,
        &["y.png", "same file as the output x.png"],
    );
}

#[test]
fn generate_with_a_bad_albedo_path_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    refuses(&["generate", "bricks", "-o", "g.png", "--albedo", "nodir/a.png"], d, &["nodir/a.png", "does not exist"]);
    refuses(&["generate", "bricks", "-o", "g.png", "--albedo", "a.jpg"], d, &["a.jpg", ".png"]);
    // Both are written when both can be, and the height map is what core generates.
    let ok = pomkit(&["generate", "pyramids", "--size", "24x16", "-o", "g.png", "--albedo", "a.png"], d);
    assert!(ok.status.success(), "{}", stderr(&ok));
    let g = image::open(d.join("g.png")).unwrap().to_luma16();
    let field = procedural::generate(Pattern::Pyramids, 24, 16);
    let want: Vec<u16> = field.heights().iter().map(|&v| (v * 65535.0).round() as u16).collect();
    assert_eq!(g.as_raw(), &want);
    let a = image::open(d.join("a.png")).unwrap().to_rgb8();
    let want: Vec<u8> = procedural::albedo(Pattern::Pyramids, 24, 16).into_iter().flatten().collect();
    assert_eq!(a.as_raw(), &want);
}

#[test]
fn render_leaves_no_png_when_an_aov_cannot_be_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // out.depth.exr is a folder: the AOV cannot be written, so neither is the PNG.
    std::fs::create_dir(d.join("out.depth.exr")).unwrap();
    let args = ["render", "--backend", "cpu", "--size", "16x16", "-o", "out.png", "--aov", "uv,depth"];
    refuses(&args, d, &["out.depth.exr", "it is a folder"]);
    // A read-only AOV too.
    std::fs::remove_dir(d.join("out.depth.exr")).unwrap();
    std::fs::write(d.join("out.uv.exr"), "keep").unwrap();
    set_read_only(&d.join("out.uv.exr"));
    refuses(&args, d, &["out.uv.exr", "read-only"]);
}

#[test]
#[cfg(feature = "view")]
fn view_screenshot_over_a_scene_input_is_refused_before_the_window_opens() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    scene_with_files(d);
    std::fs::rename(d.join("scene.png"), d.join("scene.toml")).unwrap();
    let before = snapshot(d);
    let args = ["view", "scene.toml", "--screenshot", "tex.png"];
    let out = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(d)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env("XDG_DATA_HOME", d.join("data"))
        .output()
        .unwrap();
    support::assert_refused(&out, &args, d, &before, &["tex.png", "same file as the input"]);
}

fn set_read_only(path: &Path) {
    let mut perms = std::fs::metadata(path).unwrap().permissions();
    perms.set_readonly(true);
    std::fs::set_permissions(path, perms).unwrap();
}

/// Runs `pomkit ARGS` in `dir` with standard output on `/dev/full`.
fn into_full_stdout(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::from(std::fs::File::create("/dev/full").unwrap()))
        .stderr(Stdio::piped())
        .output()
        .unwrap()
}

#[cfg(unix)]
#[test]
fn a_full_device_or_standard_output_fails_the_run() {
    use std::os::unix::fs::FileTypeExt;
    if !Path::new("/dev/full").exists() {
        println!("skipping: no /dev/full");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("r.csv"), GOOD_RAYS).unwrap();
    let trace = ["trace", "--height", "builtin:bricks:16x16", "--technique", "pom", "--rays", "r.csv"];
    let out = refuses(&[&trace[..], &["-o", "/dev/full"]].concat(), d, &["/dev/full", "No space left on device"]);
    assert!(!stderr(&out).contains("wrote"), "{}", stderr(&out));
    assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device(), "/dev/full was replaced");
    let compare = ["compare", "--height", "builtin:bricks:16x16", "--rays", "20", "--angles", "30"];
    refuses(&[&compare[..], &["-o", "/dev/full"]].concat(), d, &["/dev/full", "No space left on device"]);
    assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device(), "/dev/full was replaced");

    // Standard output on a full device: `-o -`, and compare's default.
    for args in [[&trace[..], &["-o", "-"]].concat(), compare.to_vec(), [&compare[..], &["--format", "json"]].concat()]
    {
        let before = snapshot(d);
        let out = into_full_stdout(&args, d);
        support::assert_refused(&out, &args, d, &before, &["standard output", "No space left on device"]);
    }
    // A device that takes everything works, in place.
    let out = pomkit(&[&trace[..], &["-o", "/dev/null"]].concat(), d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
}

#[test]
fn a_read_only_output_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("r.csv"), GOOD_RAYS).unwrap();
    std::fs::write(d.join("hits.csv"), "old hits\n").unwrap();
    set_read_only(&d.join("hits.csv"));
    png(&d.join("in.png"));
    std::fs::write(d.join("n.png"), "old normals").unwrap();
    set_read_only(&d.join("n.png"));
    // The mode bits decide, so this holds for root too, who could write the file.
    refuses(
        &["trace", "--height", "builtin:bricks:16x16", "--technique", "pom", "--rays", "r.csv", "-o", "hits.csv"],
        d,
        &["hits.csv", "it is read-only"],
    );
    refuses(&["bake", "normal", "in.png", "-o", "n.png"], d, &["n.png", "it is read-only"]);
    refuses(&["generate", "waves", "-o", "g.png", "--albedo", "n.png"], d, &["n.png", "it is read-only"]);
    refuses(&["compare", "--height", "in.png", "--rays", "10", "-o", "hits.csv"], d, &["hits.csv", "read-only"]);
}

#[cfg(unix)]
#[test]
fn a_symlink_output_is_written_through_and_stays_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("real")).unwrap();
    std::fs::write(d.join("r.csv"), GOOD_RAYS).unwrap();
    std::fs::write(d.join("real/hits.csv"), "old").unwrap();
    symlink("real/hits.csv", &d.join("hits.csv"));
    let args = ["trace", "--height", "builtin:bricks:16x16", "--technique", "pom", "--rays", "r.csv"];
    let out = pomkit(&[&args[..], &["-o", "hits.csv"]].concat(), d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(d.join("hits.csv")).unwrap().file_type().is_symlink(), "the link stays");
    assert_eq!(std::fs::read_link(d.join("hits.csv")).unwrap(), Path::new("real/hits.csv"));
    let direct = pomkit(&[&args[..], &["-o", "-"]].concat(), d);
    let written = std::fs::read_to_string(d.join("real/hits.csv")).unwrap();
    assert_eq!(written, String::from_utf8(direct.stdout).unwrap(), "the target holds the hits");
    assert!(written.starts_with("u,v,depth,fetches\n"));
    let mut names: Vec<String> =
        std::fs::read_dir(d.join("real")).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["hits.csv"], "no temporary file left beside the target");
    // A link to a missing file is refused.
    symlink("real/missing.csv", &d.join("dangling.csv"));
    refuses(&[&args[..], &["-o", "dangling.csv"]].concat(), d, &["dangling.csv", "does not exist"]);
}

/// Rays spread over the tile, many directions; deterministic.
fn many_rays(n: usize) -> Vec<Ray> {
    (0..n)
        .map(|i| {
            let t = i as f32;
            let uv = Vec2::new((t * 0.618_034).fract(), (t * 0.414_214).fract());
            let dir = Vec3::new((t * 0.37).sin(), (t * 0.53).cos(), -0.2 - (t * 0.11).sin().abs());
            Ray::new(uv, dir)
        })
        .collect()
}

fn rays_csv(rays: &[Ray]) -> String {
    let mut s = String::from("u,v,dx,dy,dz\n");
    for r in rays {
        s += &format!("{},{},{},{},{}\n", r.uv.x, r.uv.y, r.dir.x, r.dir.y, r.dir.z);
    }
    s
}

#[test]
fn streamed_trace_equals_core_across_batches_and_a_late_error_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // More rays than one batch (262,144), so several batches are traced and written.
    let rays = many_rays(300_000);
    let text = rays_csv(&rays);
    std::fs::write(d.join("r.csv"), &text).unwrap();
    let args = ["trace", "--height", "builtin:waves:32x32", "--technique", "parallax", "--rays", "r.csv"];
    let out = pomkit(&[&args[..], &["-o", "hits.csv"]].concat(), d);
    assert!(out.status.success(), "{}", stderr(&out));
    let hits = std::fs::read_to_string(d.join("hits.csv")).unwrap();
    let mut lines = hits.lines();
    assert_eq!(lines.next(), Some("u,v,depth,fetches"));
    let surface = Surface::new(procedural::generate(Pattern::Waves, 32, 32), EdgeMode::Wrap, 0.1);
    let params = TraceParams::default();
    let mut count = 0;
    for (line, ray) in lines.zip(&rays) {
        let want = trace(&surface, ray, Technique::Parallax, &params);
        let f: Vec<&str> = line.split(',').collect();
        let got = (f[0].parse::<f32>().unwrap(), f[1].parse::<f32>().unwrap(), f[2].parse::<f32>().unwrap());
        assert_eq!(got, (want.uv.x, want.uv.y, want.depth), "ray {count}");
        assert_eq!(f[3].parse::<u32>().unwrap(), want.fetches, "ray {count}");
        count += 1;
    }
    assert_eq!(count, rays.len());

    // The same rays through standard input, with a bad line after the first batch: no output.
    std::fs::remove_file(d.join("hits.csv")).unwrap();
    let bad = format!("{text}0.5,0.5,oops,0,-1\n");
    std::fs::write(d.join("bad.csv"), &bad).unwrap();
    let bad_args = ["trace", "--height", "builtin:waves:32x32", "--technique", "parallax", "--rays", "bad.csv"];
    refuses(&[&bad_args[..], &["-o", "hits.csv"]].concat(), d, &["bad.csv", "line 300002", "oops", "not a number"]);
    let before = snapshot(d);
    let stdin_args = ["trace", "--height", "builtin:waves:32x32", "--technique", "parallax", "--rays", "-"];
    let all = [&stdin_args[..], &["-o", "hits.csv"]].concat();
    let out = pomkit_with_input(&all, d, bad.as_bytes());
    support::assert_refused(&out, &all, d, &before, &["<stdin>", "line 300002", "oops"]);
}

#[test]
fn binary_or_endless_rays_fail_within_the_first_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let args = ["trace", "--height", "builtin:bricks:16x16", "--technique", "pom", "-o", "hits.csv"];
    if Path::new("/dev/zero").exists() {
        refuses(&[&args[..], &["--rays", "/dev/zero"]].concat(), d, &["/dev/zero", "line 1", "NUL byte"]);
    }
    // An endless line on standard input (here 8 MiB without a newline): refused after a line's
    // worth, without reading the rest.
    let all = [&args[..], &["--rays", "-"]].concat();
    let before = snapshot(d);
    let out = pomkit_with_input(&all, d, &vec![b'7'; 8 << 20]);
    support::assert_refused(&out, &all, d, &before, &["<stdin>", "line 1 is longer than 4096 bytes"]);
    // A long line later in a file names its line.
    std::fs::write(d.join("long.csv"), format!("{GOOD_RAYS}{}\n", "1".repeat(10_000))).unwrap();
    refuses(&[&args[..], &["--rays", "long.csv"]].concat(), d, &["long.csv", "line 4 is longer"]);
}
