//! Limits (docs/LIMITS.md): jobs that will not fit in memory are refused up front with the
//! figures, unbounded inputs are read only up to their format's cap, image headers are checked
//! before any pixel is decoded, and GPU frames beyond the adapter's limits say what to do.
//!
//! The memory budget is set low with `POMKIT_MEMORY_LIMIT` so that every refusal is cheap and
//! deterministic: nothing here allocates more than a few hundred MiB.

mod support;

use std::path::Path;
use std::process::{Command, Output, Stdio};

use support::{assert_refused, snapshot, stderr};

/// Runs `pomkit ARGS` in `dir` with the environment variables `env` (no standard input).
fn pomkit_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_pomkit"));
    cmd.args(args).current_dir(dir).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("pomkit runs")
}

/// Runs `args` with `env` in `dir` and asserts the clean-failure contract
/// ([`support::assert_refused`]).
fn refuses_env(args: &[&str], dir: &Path, env: &[(&str, &str)], needles: &[&str]) -> Output {
    let before = snapshot(dir);
    let out = pomkit_env(args, dir, env);
    assert_refused(&out, args, dir, &before, needles);
    out
}

const LOW: (&str, &str) = ("POMKIT_MEMORY_LIMIT", "1GiB");

/// A scene of one height-mapped plane (`height` a `builtin:` or file) and `extra` objects.
fn scene(height: &str, extra: &str) -> String {
    format!(
        r#"
[camera]
eye = [0.0, 1.5, 2.0]
target = [0.0, 0.0, 0.0]

[[light]]
type = "directional"
direction = [0.5, 1.0, 0.3]

[[material]]
name = "m"
height = "{height}"
technique = "pom"
depth_scale = 0.05

[[object]]
mesh = "plane"
material = "m"
{extra}
"#
    )
}

#[test]
fn the_largest_size_is_refused_up_front_when_it_does_not_fit() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["render", "--size", "16384x16384", "--backend", "cpu", "--aov", "depth", "-o", "out.png"];
    let out = refuses_env(
        &args,
        dir.path(),
        &[LOW],
        &["render of 16384x16384 with AOVs needs about", "GiB; 1.0 GiB is available (POMKIT_MEMORY_LIMIT)", "--size"],
    );
    // The figure is the frame's real size at least: colour and AOVs alone are 36 bytes a pixel.
    let msg = stderr(&out);
    let needed: f64 = msg.split("needs about ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    assert!(needed >= 16384.0 * 16384.0 * 36.0 / f64::from(1u32 << 30), "{msg}");
}

#[test]
fn the_size_limit_is_one_constant() {
    let dir = tempfile::tempdir().unwrap();
    // Scene built-ins allow what --size and generate allow: 16384, not 16385.
    std::fs::write(dir.path().join("s.toml"), scene("builtin:bricks:16385x4", "")).unwrap();
    support::refuses(&["render", "s.toml", "--backend", "cpu", "-o", "o.png"], dir.path(), &["16385x4", "16384"]);
    support::refuses(&["render", "--size", "16385x4", "-o", "o.png"], dir.path(), &["16385x4", "16384"]);
    support::refuses(&["generate", "bricks", "--size", "16385x4", "-o", "o.png"], dir.path(), &["16385x4", "16384"]);
}

#[test]
fn displaced_geometry_of_a_large_height_map_is_refused_and_a_small_one_renders() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("big.toml"), scene("builtin:bricks:4096x4096", "")).unwrap();
    let args = ["render", "big.toml", "--technique", "displaced", "--backend", "cpu", "--size", "64x36", "-o", "o.png"];
    refuses_env(
        &args,
        dir.path(),
        &[LOW],
        &[
            "render of 64x36 of displaced geometry needs about",
            "1.0 GiB is available",
            "technique other than displaced",
        ],
    );

    std::fs::write(dir.path().join("small.toml"), scene("builtin:bricks:64x64", "")).unwrap();
    let args =
        ["render", "small.toml", "--technique", "displaced", "--backend", "cpu", "--size", "64x36", "-o", "o.png"];
    let out = pomkit_env(&args, dir.path(), &[LOW]);
    assert!(out.status.success(), "{}", stderr(&out));
    let img = image::open(dir.path().join("o.png")).unwrap();
    assert_eq!((img.width(), img.height()), (64, 36));
}

#[test]
fn ten_finely_divided_spheres_are_refused_with_the_figures() {
    let dir = tempfile::tempdir().unwrap();
    let spheres: String = (0..10)
        .map(|i| format!("\n[[object]]\nmesh = \"sphere\"\nrings = 2048\nsegments = 2048\nposition = [{i}.0, 0.0, 0.0]\nmaterial = \"m\"\n"))
        .collect();
    std::fs::write(dir.path().join("s.toml"), scene("builtin:bricks:16x16", &spheres)).unwrap();
    refuses_env(
        &["render", "s.toml", "--backend", "cpu", "--size", "64x36", "-o", "o.png"],
        dir.path(),
        &[LOW],
        &["s.toml", "building the 11 objects' built-in shapes needs about", "1.0 GiB is available", "fewer segments"],
    );
}

#[cfg(unix)]
#[test]
fn endless_inputs_fail_fast_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    support::refuses(
        &["bake", "normal", "/dev/zero", "-o", "out.png"],
        dir.path(),
        &["/dev/zero", "not a PNG, JPEG, TIFF or OpenEXR file", "00 00 00 00"],
    );
    support::refuses(
        &["render", "/dev/zero", "--backend", "cpu", "-o", "out.png"],
        dir.path(),
        &["/dev/zero", "a scene file may be at most 64.0 MiB"],
    );
    // A mesh named by a scene, and a colour map: the same caps.
    std::fs::write(
        dir.path().join("m.toml"),
        scene("builtin:bricks:16x16", "").replace("mesh = \"plane\"", "mesh = \"/dev/zero.obj\""),
    )
    .unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.png")).unwrap();
    std::fs::write(dir.path().join("a.toml"), scene("zero.png", "")).unwrap();
    support::refuses(
        &["render", "a.toml", "--backend", "cpu", "-o", "out.png"],
        dir.path(),
        &["zero.png", "not a PNG"],
    );
}

/// A PNG file of a header only: IHDR declaring `width x height` of `color_type` at `depth`
/// bits, an IDAT of an empty zlib stream, IEND.
fn png_header(width: u32, height: u32, depth: u8, color_type: u8) -> Vec<u8> {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    }
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend(width.to_be_bytes());
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([depth, color_type, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(&mut png, b"IEND", &[]);
    png
}

#[test]
fn image_headers_are_checked_before_any_pixel_is_decoded() {
    let dir = tempfile::tempdir().unwrap();
    // 60000 x 60000 grey: 3.4 GiB declared in a 70-byte file.
    std::fs::write(dir.path().join("big.png"), png_header(60000, 60000, 8, 0)).unwrap();
    let out = support::refuses(
        &["bake", "normal", "big.png", "-o", "out.png"],
        dir.path(),
        &["big.png is 60000x60000 pixels", "at most 16384 pixels a side"],
    );
    assert!(!stderr(&out).contains("Memory limit exceeded"), "{}", stderr(&out));
    // Within the size limit but not the memory budget: 16384 x 16384 RGBA at 16 bits is 2 GiB.
    std::fs::write(dir.path().join("wide.png"), png_header(16384, 16384, 16, 6)).unwrap();
    let out = refuses_env(
        &["bake", "normal", "wide.png", "-o", "out.png"],
        dir.path(),
        &[LOW],
        &[
            "wide.png is 16384x16384 pixels",
            "reading it needs about 4.0 GiB",
            "1.0 GiB is available (POMKIT_MEMORY_LIMIT)",
        ],
    );
    assert!(!stderr(&out).contains("Memory limit exceeded"), "{}", stderr(&out));
    // The same as a scene's colour map.
    std::fs::write(
        dir.path().join("s.toml"),
        scene("builtin:bricks:16x16", "").replace("technique = \"pom\"", "technique = \"pom\"\nalbedo = \"big.png\""),
    )
    .unwrap();
    support::refuses(
        &["render", "s.toml", "--backend", "cpu", "-o", "out.png"],
        dir.path(),
        &["big.png is 60000x60000 pixels", "16384"],
    );
}

#[test]
fn a_malformed_memory_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    refuses_env(
        &["render", "--size", "64x36", "--backend", "cpu", "-o", "o.png"],
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", "lots")],
        &["POMKIT_MEMORY_LIMIT=\"lots\" is not a memory size"],
    );
}

#[test]
fn an_unknown_simd_level_is_refused_and_the_scalar_one_renders() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["render", "--size", "64x36", "--backend", "cpu", "-o", "o.png"];
    refuses_env(&args, dir.path(), &[("POMKIT_SIMD", "avx9")], &["POMKIT_SIMD=\"avx9\" is not a SIMD level", "scalar"]);
    // The scalar fallback draws what the detected level draws, byte for byte.
    let detected = pomkit_env(&args, dir.path(), &[("POMKIT_SIMD", "auto")]);
    assert!(detected.status.success(), "{}", String::from_utf8_lossy(&detected.stderr));
    let auto = std::fs::read(dir.path().join("o.png")).unwrap();
    let scalar = pomkit_env(&args, dir.path(), &[("POMKIT_SIMD", "scalar")]);
    assert!(scalar.status.success(), "{}", String::from_utf8_lossy(&scalar.stderr));
    assert_eq!(std::fs::read(dir.path().join("o.png")).unwrap(), auto);
}

#[test]
fn a_gpu_frame_over_the_adapters_limits_says_what_to_do() {
    let limits = match pomkit_gpu::GpuContext::new() {
        Ok(ctx) => ctx.device.limits(),
        Err(e) => return pomkit_gpu::context::skip_without_gpu(&e),
    };
    let dir = tempfile::tempdir().unwrap();
    // Supersampled past max_texture_dimension_2d: one more sample than the adapter allows.
    let side = limits.max_texture_dimension_2d / 2 + 1;
    let size = format!("{side}x64");
    let wide = format!("{}x128", side * 2);
    refuses_env(
        &["render", "--backend", "gpu", "--size", &size, "--supersample", "2", "-o", "o.png"],
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", "64GiB")],
        &[&wide, "max_texture_dimension_2d", "use a smaller --size", "--backend cpu"],
    );
    assert!(
        !stderr(&pomkit_env(
            &["render", "--backend", "gpu", "--size", &size, "--supersample", "2", "-o", "o.png"],
            dir.path(),
            &[]
        ))
        .contains("Validation")
    );
}

#[test]
fn cone_and_maxmip_bakes_that_do_not_fit_are_refused_with_the_figure() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = ("POMKIT_MEMORY_LIMIT", "1MiB");
    // 256x256: the cones need about 2 MiB, the pyramid and its atlas about 0.75 MiB.
    let args = ["bake", "cone", "builtin:bricks:256x256", "-o", "c.png"];
    refuses_env(
        &args,
        dir.path(),
        &[tiny],
        &["the cone map of a 256x256 map needs about", "MiB", "smaller height map"],
    );
    let out = pomkit_env(&["bake", "maxmip", "builtin:bricks:256x256", "-o", "m.png"], dir.path(), &[tiny]);
    assert!(out.status.success(), "the pyramid fits: {}", stderr(&out));
    let args = ["bake", "maxmip", "builtin:bricks:512x512", "-o", "m2.png"];
    refuses_env(&args, dir.path(), &[tiny], &["maximum-height pyramid of a 512x512 map needs about"]);
}
