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
            "render of 64x36 of displaced geometry of big.toml (1 object, 8 triangles, the largest map 4096x4096) \
             needs about",
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
        &["render", "s.toml", "--backend", "cpu", "--size", "1280x720", "-o", "o.png"],
        dir.path(),
        &[LOW],
        &[
            "render of 1280x720 of s.toml (11 objects, 83968028 triangles, the largest map 16x16) needs about",
            "1.0 GiB is available",
            "fewer or coarser meshes",
        ],
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
    // 256x256: the cones need several MiB, the pyramid and its atlas about 0.75 MiB and the
    // generated map 1 MiB: within 2 MiB.
    let args = ["bake", "cone", "builtin:bricks:256x256", "-o", "c.png"];
    refuses_env(
        &args,
        dir.path(),
        &[tiny],
        &["the cone map of a 256x256 map (builtin:bricks:256x256) needs about", "MiB", "smaller height map"],
    );
    let out = pomkit_env(
        &["bake", "maxmip", "builtin:bricks:256x256", "-o", "m.png"],
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", "2MiB")],
    );
    assert!(out.status.success(), "the pyramid fits: {}", stderr(&out));
    let args = ["bake", "maxmip", "builtin:bricks:512x512", "-o", "m2.png"];
    refuses_env(
        &args,
        dir.path(),
        &[tiny],
        &["maximum-height pyramid of a 512x512 map (builtin:bricks:512x512) needs about"],
    );
}

/// Runs `pomkit ARGS` in `dir` with `env` under an address-space limit of `gib` GiB (`ulimit -v`,
/// set by a shell that then execs pomkit), as in a container or a batch system; without
/// `POMKIT_MEMORY_LIMIT` unless `env` sets it.
#[cfg(unix)]
fn pomkit_ulimit(gib: u64, args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg(format!("ulimit -v {} && exec \"$0\" \"$@\"", gib << 20))
        .arg(env!("CARGO_BIN_EXE_pomkit"))
        .args(args)
        .current_dir(dir)
        .env_remove("POMKIT_MEMORY_LIMIT")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("sh runs")
}

/// Runs `args` under `ulimit -v` of `gib` GiB and asserts a clean refusal: an exit code (not a
/// signal: the allocator's abort is SIGABRT), no panic, the `needles`, and no file written.
#[cfg(unix)]
fn refuses_ulimit(gib: u64, args: &[&str], dir: &Path, env: &[(&str, &str)], needles: &[&str]) -> Output {
    let before = snapshot(dir);
    let out = pomkit_ulimit(gib, args, dir, env);
    assert!(!stderr(&out).contains("memory allocation of"), "{args:?} aborted: {}", stderr(&out));
    assert_refused(&out, args, dir, &before, needles);
    out
}

/// The figure after "needs about " in a refusal, in GiB.
fn needed_gib(msg: &str) -> f64 {
    let rest = msg.split("needs about ").nth(1).unwrap_or_else(|| panic!("no figure in {msg:?}"));
    let mut words = rest.split(' ');
    let value: f64 = words.next().unwrap().parse().unwrap();
    match words.next().unwrap().trim_end_matches(';') {
        "GiB" => value,
        "MiB" => value / 1024.0,
        "TiB" => value * 1024.0,
        unit => panic!("unit {unit} in {msg:?}"),
    }
}

#[cfg(unix)]
#[test]
fn a_cpu_render_over_the_address_space_limit_is_refused_not_aborted() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["render", "--backend", "cpu", "--size", "16384x16384", "--technique", "flat", "-o", "o.png"];
    let out = refuses_ulimit(4, &args, dir.path(), &[], &["render of 16384x16384 needs about", "ulimit -v"]);
    // The frame alone (12 bytes a pixel) is 3 GiB: the figure is at least that.
    assert!(needed_gib(&stderr(&out)) >= 3.0, "{}", stderr(&out));
}

#[cfg(unix)]
#[test]
fn a_gpu_render_over_the_address_space_limit_is_refused_not_aborted() {
    if let Err(e) = pomkit_gpu::GpuContext::new() {
        return pomkit_gpu::context::skip_without_gpu(&e);
    }
    let dir = tempfile::tempdir().unwrap();
    let args = ["render", "--backend", "gpu", "--size", "4096x4096", "--technique", "flat", "-o", "o.png"];
    refuses_ulimit(3, &args, dir.path(), &[], &["render of 4096x4096 on the GPU needs about", "ulimit -v"]);
}

#[cfg(unix)]
#[test]
fn a_large_built_in_map_on_the_gpu_is_refused_under_the_address_space_limit() {
    if let Err(e) = pomkit_gpu::GpuContext::new() {
        return pomkit_gpu::context::skip_without_gpu(&e);
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("w.toml"), scene("builtin:waves:16384x16384", "")).unwrap();
    let args = ["render", "w.toml", "--backend", "gpu", "--size", "64x36", "-o", "o.png"];
    let out = refuses_ulimit(
        8,
        &args,
        dir.path(),
        &[],
        &["the largest map 16384x16384", "on the GPU needs about", "ulimit -v"],
    );
    // The textures of a 16384 x 16384 map alone, with their mips, are over 8 GiB on the GPU.
    assert!(needed_gib(&stderr(&out)) > 8.0, "{}", stderr(&out));
}

#[test]
fn a_gpu_render_of_a_large_map_is_refused_in_one_line_with_the_figure() {
    if let Err(e) = pomkit_gpu::GpuContext::new() {
        return pomkit_gpu::context::skip_without_gpu(&e);
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("b.toml"), scene("builtin:bricks:16384x16384", "")).unwrap();
    let args = ["render", "b.toml", "--backend", "gpu", "--size", "64x36", "-o", "o.png"];
    let out = refuses_env(
        &args,
        dir.path(),
        &[LOW],
        &["on the GPU needs about", "1.0 GiB is available (POMKIT_MEMORY_LIMIT)"],
    );
    // One line of error (after the line naming the backend), not the device's report.
    let msg = stderr(&out);
    let lines: Vec<&str> = msg.lines().filter(|l| !l.starts_with("backend: ")).collect();
    assert_eq!(lines.len(), 1, "{msg}");
    assert!(lines[0].starts_with("error: "), "{msg}");
    assert!(!msg.contains("Validation"), "{msg}");
}

#[test]
fn built_in_maps_and_generate_are_held_to_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let small = ("POMKIT_MEMORY_LIMIT", "16MiB");
    // 4096 x 4096 values are 64 MiB before anything is baked.
    refuses_env(
        &["bake", "normal", "builtin:waves:4096x4096", "-o", "w.png"],
        dir.path(),
        &[small],
        &["builtin:waves:4096x4096", "needs about", "16.0 MiB is available (POMKIT_MEMORY_LIMIT)"],
    );
    std::fs::write(dir.path().join("rays.csv"), "u,v,dx,dy,dz\n0.5,0.5,0.0,0.0,-1.0\n").unwrap();
    refuses_env(
        &["trace", "--height", "builtin:waves:4096x4096", "--technique", "pom", "--rays", "rays.csv", "-o", "t.csv"],
        dir.path(),
        &[small],
        &["generating builtin:waves:4096x4096 needs about", "16.0 MiB is available"],
    );
    refuses_env(
        &["generate", "waves", "--size", "4096x4096", "-o", "g.png"],
        dir.path(),
        &[small],
        &["generating waves 4096x4096 needs about", "16.0 MiB is available", "--size"],
    );
    std::fs::write(dir.path().join("s.toml"), scene("builtin:waves:4096x4096", "")).unwrap();
    refuses_env(
        &["render", "s.toml", "--backend", "cpu", "--size", "64x36", "-o", "o.png"],
        dir.path(),
        &[small],
        &["the largest map 4096x4096", "needs about", "16.0 MiB is available"],
    );
    // The same budget holds a small job.
    let out = pomkit_env(&["generate", "waves", "--size", "256x256", "-o", "g.png"], dir.path(), &[small]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Work that would not fit is refused before it starts: under an address-space limit smaller
/// than the work itself, starting it would end in the allocator, so a clean refusal shows it
/// never started.
#[cfg(unix)]
#[test]
fn refusals_come_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    // The map alone, 16384 x 16384, is 2 GiB as it is generated.
    refuses_ulimit(
        2,
        &["bake", "cone", "builtin:fur:16384x16384", "-o", "c.png"],
        dir.path(),
        &[],
        &["the cone map of a 16384x16384 map", "needs about", "ulimit -v"],
    );
    // Ten spheres of 2048 x 2048 segments: 84 million triangles, 6 GiB as meshes.
    let spheres: String = (0..10)
        .map(|i| format!("\n[[object]]\nmesh = \"sphere\"\nrings = 2048\nsegments = 2048\nposition = [{i}.0, 0.0, 0.0]\nmaterial = \"m\"\n"))
        .collect();
    std::fs::write(dir.path().join("s.toml"), scene("builtin:bricks:16x16", &spheres)).unwrap();
    let out = refuses_ulimit(
        3,
        &["render", "s.toml", "--backend", "cpu", "--size", "1280x720", "-o", "o.png"],
        dir.path(),
        &[],
        &["render of 1280x720 of s.toml (11 objects, ", "needs about", "ulimit -v", "fewer or coarser meshes"],
    );
    assert!(needed_gib(&stderr(&out)) > 20.0, "{}", stderr(&out));
    // A displaced torus with a 16384 x 16384 map, under a budget of 1 GiB.
    let torus = scene("builtin:bricks:16384x16384", "").replace("mesh = \"plane\"", "mesh = \"torus\"");
    std::fs::write(dir.path().join("t.toml"), torus).unwrap();
    refuses_ulimit(
        4,
        &["render", "t.toml", "--technique", "displaced", "--size", "160x90", "-o", "o.png"],
        dir.path(),
        &[LOW],
        &["render of 160x90 of displaced geometry of t.toml", "1.0 GiB is available (POMKIT_MEMORY_LIMIT)"],
    );
}

#[test]
fn a_tiny_or_malformed_memory_limit_is_told_as_such_with_an_input_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = pomkit_env(&["generate", "bricks", "--size", "64x64", "-o", "h.png"], dir.path(), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let args = ["bake", "normal", "h.png", "-o", "n.png"];
    let out = refuses_env(
        &args,
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", "1")],
        &["h.png", "1 B is available (POMKIT_MEMORY_LIMIT)"],
    );
    assert!(!stderr(&out).contains("0x0"), "{}", stderr(&out));
    let out = refuses_env(
        &args,
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", "lots")],
        &["POMKIT_MEMORY_LIMIT=\"lots\" is not a memory size"],
    );
    assert!(!stderr(&out).contains("cannot read"), "{}", stderr(&out));
}

/// A CPU render of far more triangles than samples is refused up front for its time (it ran for
/// minutes, silently), saying how to let it run; with that, the memory budget still applies.
#[cfg(unix)]
#[test]
fn a_render_of_far_more_triangles_than_pixels_is_refused_for_its_time() {
    let dir = tempfile::tempdir().unwrap();
    let spheres: String = (0..10)
        .map(|i| format!("\n[[object]]\nmesh = \"sphere\"\nrings = 2048\nsegments = 2048\nposition = [{i}.0, 0.0, 0.0]\nmaterial = \"m\"\n"))
        .collect();
    std::fs::write(dir.path().join("s.toml"), scene("builtin:bricks:16x16", &spheres)).unwrap();
    let args = ["render", "s.toml", "--backend", "cpu", "--size", "160x90", "-o", "o.png"];
    // Under an address-space limit far below the meshes: the refusal comes before they are built.
    refuses_ulimit(
        3,
        &args,
        dir.path(),
        &[],
        &["s.toml has 83968028 triangles for a 160x90 frame (5831 per sample)", "POMKIT_ALLOW_SLOW=1"],
    );
    refuses_env(
        &args,
        dir.path(),
        &[LOW, ("POMKIT_ALLOW_SLOW", "1")],
        &["render of 160x90 of s.toml (11 objects, 83968028 triangles", "1.0 GiB is available"],
    );
}

/// A cone bake of an image file counts the height field it holds beside the cones: under a
/// fixed budget a little above the cones' own estimate (`ConeMap::build_bytes`) but below it
/// plus the field (4 bytes a texel), the bake is refused before it builds anything. (The field
/// was left out, about a tenth of a large cone bake's peak.)
#[test]
fn a_cone_bake_of_a_file_counts_the_height_field_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let made = pomkit_env(&["generate", "bricks", "--size", "256x256", "-o", "h.png"], dir.path(), &[]);
    assert!(made.status.success(), "{}", stderr(&made));
    let cones = pomkit_core::cone::ConeMap::build_bytes(256, 256);
    let field = 256 * 256 * 4;
    let limit = (cones + field / 2).to_string();
    refuses_env(
        &["bake", "cone", "h.png", "-o", "c.png"],
        dir.path(),
        &[("POMKIT_MEMORY_LIMIT", &limit)],
        &["the cone map of a 256x256 map (h.png) needs about", "smaller height map"],
    );
    let enough = (cones + field + (1 << 20)).to_string();
    let out = pomkit_env(&["bake", "cone", "h.png", "-o", "c.png"], dir.path(), &[("POMKIT_MEMORY_LIMIT", &enough)]);
    assert!(out.status.success(), "the cones and the field fit: {}", stderr(&out));
}

/// Long work that reports no rows shows a spinner on a terminal, so it does not look like a
/// hang: building a maximum-height pyramid and loading a scene with large built-in maps. Run
/// under a pseudo-terminal (`script`), as a user at a terminal sees it.
#[cfg(unix)]
#[test]
fn long_work_shows_progress_on_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("s.toml"), scene("builtin:fur:2048x2048", "")).unwrap();
    let exe = env!("CARGO_BIN_EXE_pomkit");
    let cases: [(&str, &[&str]); 2] = [
        ("bake maxmip builtin:fur:2048x2048 -o m.png", &["generating fur 2048x2048", "building the pyramid"]),
        ("render s.toml --backend cpu --size 32x18 -o r.png", &["loading s.toml"]),
    ];
    for (args, needles) in cases {
        let out = Command::new("script")
            .args(["-qec", &format!("{exe} {args}"), "/dev/null"])
            .current_dir(dir.path())
            .env("TERM", "xterm")
            .stdin(Stdio::null())
            .output()
            .expect("script runs");
        let seen = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{args}: {seen}");
        for needle in needles {
            assert!(seen.contains(needle), "{args}: no {needle:?} on the terminal: {seen}");
        }
    }
}
