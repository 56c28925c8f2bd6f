//! Bad or extreme input: a scale that overflows,
//! geometry f32 cannot draw, a glTF accessor past its buffer, unusable normal maps, flags a
//! built-in height cannot honour, Mesa's runtime-directory noise, causes printed twice, NUL
//! bytes in paths, and library jargon where the problem should be named; plus inputs at the
//! edge of what is read: single-channel OpenEXR and float TIFF height maps, `--normalize` on the extremes of
//! f32, and a watertight rasterizer.

mod support;

use std::path::Path;
use std::process::{Command, Stdio};

use pomkit_core::render::RenderOptions;
use support::{pomkit, refuses, stderr};

fn write(dir: &Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).expect("writable temp dir");
}

/// A scene of one flat-shaded plane with the given camera lines and object lines.
fn plane_scene(camera: &str, object: &str) -> String {
    format!(
        r#"
[camera]
{camera}

[[light]]
direction = [0.3, 1.0, 0.2]

[[material]]
name = "m"
technique = "flat"

[[object]]
name = "floor"
mesh = "plane"
material = "m"
{object}
"#
    )
}

/// Writes a float RGB OpenEXR (through the image crate) with `texels` (`w x h`).
fn write_rgb_exr(path: &Path, w: u32, h: u32, texels: &[[f32; 3]]) {
    let flat: Vec<f32> = texels.iter().flatten().copied().collect();
    image::Rgb32FImage::from_raw(w, h, flat).expect("size").save(path).expect("EXR written");
}

/// Decoded 8-bit RGB pixels of a PNG.
fn rgb8(path: &Path) -> Vec<[u8; 3]> {
    image::open(path).expect("readable PNG").to_rgb8().pixels().map(|p| p.0).collect()
}

/// Decoded float RGB texels of an EXR.
fn rgbf(path: &Path) -> Vec<[f32; 3]> {
    image::open(path).expect("readable EXR").to_rgb32f().pixels().map(|p| p.0).collect()
}

/// Heights in [0, 1] of a small test map, row-major, with slopes in both directions.
fn test_heights(w: u32, h: u32) -> Vec<f32> {
    (0..h).flat_map(|y| (0..w).map(move |x| ((x * 7 + y * 3) % 11) as f32 / 10.0)).collect()
}

// ---------------------------------------------------------------------------------------------
// 8 (a): --scale
// ---------------------------------------------------------------------------------------------

#[test]
fn bake_scale_1e25_is_refused_naming_the_flag_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    for scale in ["1e25", "-1e25", "1e19"] {
        refuses(
            &["bake", "normal", "builtin:bricks:16x16", "--scale", scale, "-o", "n.png"],
            dir.path(),
            &[&format!("--scale {scale}:"), "1e18", "overflow"],
        );
    }
}

#[test]
fn bake_scale_zero_is_flat_and_a_negative_scale_inverts_the_relief() {
    let dir = tempfile::tempdir().unwrap();
    let run = |scale: &str, out: &str| {
        let o = pomkit(&["bake", "normal", "builtin:cobblestones:32x32", "--scale", scale, "-o", out], dir.path());
        assert!(o.status.success(), "--scale {scale}: {}", stderr(&o));
        rgb8(&dir.path().join(out))
    };
    // 0: every normal +Z, encoded (128, 128, 255).
    assert!(run("0", "flat.png").iter().all(|c| *c == [128, 128, 255]));
    // -8 mirrors x and y of +8 (n * 0.5 + 0.5 rounded: codes add up to 255, up to a tie).
    let (up, down) = (run("8", "up.png"), run("-8", "down.png"));
    assert!(up.iter().any(|c| c[0] != 128), "the map has relief");
    for (a, b) in up.iter().zip(&down) {
        for k in 0..2 {
            assert!((i32::from(a[k]) + i32::from(b[k]) - 255).abs() <= 1, "{a:?} vs {b:?}");
        }
        assert_eq!(a[2], b[2], "z is the same");
    }
    // The largest allowed scale still gives unit normals, not zero vectors.
    let edge = run("1e18", "edge.png");
    assert!(edge.iter().all(|c| *c != [128, 128, 128]), "no zero normal at --scale 1e18");
}

// ---------------------------------------------------------------------------------------------
// 9: geometry f32 cannot draw, and watertight coverage
// ---------------------------------------------------------------------------------------------

/// Renders on the CPU and, where an adapter exists, on the GPU; returns the covered counts.
fn coverage(scene_text: &str, w: u32, h: u32) -> (usize, Option<usize>) {
    let scene = pomkit_io::scene::parse_scene(scene_text, Path::new(".")).expect("scene loads");
    let opts = RenderOptions { width: w, height: h, ..Default::default() };
    let cpu = pomkit_cpu::CpuRenderer::new().render(&scene, &opts, &|_, _| {}).expect("CPU renders");
    let gpu = match pomkit_gpu::GpuContext::new() {
        Ok(ctx) => Some(pomkit_gpu::GpuRenderer::new(ctx).render(&scene, &opts).expect("GPU renders").covered),
        Err(e) => {
            pomkit_gpu::context::skip_without_gpu(&e);
            None
        }
    };
    (cpu.covered, gpu)
}

#[test]
fn a_plane_filling_the_view_at_fov_1e_3_covers_every_pixel() {
    // The view's centre is the plane's centre, where its two triangles share their diagonal.
    let text = plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 1e-3", "size = 2.0");
    let (w, h) = (64, 48);
    let (cpu, gpu) = coverage(&text, w, h);
    assert_eq!(cpu, (w * h) as usize, "CPU: a crack along the shared edge");
    if let Some(gpu) = gpu {
        assert_eq!(gpu, cpu, "GPU coverage");
    }
}

#[test]
fn a_plane_of_size_1e8_crossing_the_near_plane_covers_every_pixel() {
    // Looking down at 26.6 degrees with a 45 degree view: the horizon is above the frame, so the
    // plane fills it; its triangles cross the near plane and reach 7e7 from the eye (7e5 near
    // distances, within the 2^20 that f32 clipping resolves).
    let camera = "eye = [0.0, 300.0, 600.0]\ntarget = [0.0, 0.0, 0.0]\nnear = 100.0\nfar = 1e9";
    let text = plane_scene(camera, "size = 1e8");
    let (w, h) = (64, 48);
    let (cpu, gpu) = coverage(&text, w, h);
    assert_eq!(cpu, (w * h) as usize, "CPU: a lost triangle or a crack");
    if let Some(gpu) = gpu {
        assert_eq!(gpu, cpu, "GPU coverage");
    }
}

#[test]
fn geometry_f32_cannot_draw_is_refused_naming_the_scene_key() {
    let dir = tempfile::tempdir().unwrap();
    let render = ["render", "s.toml", "--backend", "cpu", "--size", "32x24", "-o", "o.png"];
    let default_camera = "eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]";
    // Sizes of 1e15 drew 0 pixels.
    write(dir.path(), "s.toml", &plane_scene(default_camera, "size = 1e15"));
    refuses(&render, dir.path(), &["s.toml", "object 1 (\"floor\")", "near", "size"]);
    // fov 1e-30 covered 0 pixels on the CPU and half on the GPU.
    write(dir.path(), "s.toml", &plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 1e-30", ""));
    refuses(&render, dir.path(), &["s.toml", "camera", "fov is 1e-30", "1e-3"]);
    // An eye at 1e30 blamed `up`.
    write(dir.path(), "s.toml", &plane_scene("eye = [1e30, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", ""));
    let out = refuses(&render, dir.path(), &["s.toml", "camera", "eye is [1e30, 2, 4]", "1e18"]);
    assert!(!stderr(&out).contains("up is"), "{}", stderr(&out));
}

// ---------------------------------------------------------------------------------------------
// 10: glTF accessors, normal maps, built-in heights
// ---------------------------------------------------------------------------------------------

#[test]
fn a_gltf_index_accessor_running_past_its_buffer_is_refused_naming_the_accessor() {
    let dir = tempfile::tempdir().unwrap();
    // One triangle: 3 positions (36 bytes), 3 UVs (24 bytes), 3 u16 indices (6 bytes, + 2 pad).
    let mut bin = Vec::new();
    for p in [[-1.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]] {
        p.iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    for uv in [[0.0f32, 1.0], [1.0, 1.0], [0.5, 0.0]] {
        uv.iter().for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.path().join("m.bin"), &bin).unwrap();
    // The index accessor claims 3000 indices; its view holds 6 bytes.
    let gltf = r#"{
      "asset": {"version": "2.0"},
      "buffers": [{"uri": "m.bin", "byteLength": 68}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 36},
        {"buffer": 0, "byteOffset": 36, "byteLength": 24},
        {"buffer": 0, "byteOffset": 60, "byteLength": 6}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [-1, 0, -1], "max": [1, 0, 0]},
        {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
        {"bufferView": 2, "componentType": 5123, "count": 3000, "type": "SCALAR"}
      ],
      "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}],
      "nodes": [{"mesh": 0}],
      "scenes": [{"nodes": [0]}],
      "scene": 0
    }"#;
    write(dir.path(), "m.gltf", gltf);
    let text = plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", "")
        .replace("mesh = \"plane\"", "mesh = \"m.gltf\"");
    write(dir.path(), "s.toml", &text);
    refuses(
        &["render", "s.toml", "--backend", "cpu", "--size", "32x24", "-o", "o.png"],
        dir.path(),
        &["m.gltf", "mesh \"tri\"", "accessor 2", "indices", "3000"],
    );
}

/// A scene whose material uses the normal map `normal` (over a built-in height).
fn normal_scene(normal: &str) -> String {
    plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", "").replace(
        "technique = \"flat\"",
        &format!("technique = \"normal\"\nheight = \"builtin:bricks:8x8\"\nnormal = \"{normal}\""),
    )
}

#[test]
fn normal_maps_with_nan_zero_or_inward_texels_are_refused_naming_the_file_and_texel() {
    let dir = tempfile::tempdir().unwrap();
    let render = ["render", "s.toml", "--backend", "cpu", "--size", "32x24", "-o", "o.png"];
    let up = [0.0, 0.0, 1.0];
    // A NaN at texel (1, 0) of a float map.
    write_rgb_exr(&dir.path().join("nan.exr"), 3, 2, &[up, [f32::NAN, 0.0, 1.0], up, up, up, up]);
    write(dir.path(), "s.toml", &normal_scene("nan.exr"));
    refuses(&render, dir.path(), &["nan.exr", "texel (1, 0)", "NaN", "finite"]);
    // An infinity at texel (0, 1).
    write_rgb_exr(&dir.path().join("inf.exr"), 3, 2, &[up, up, up, [0.0, f32::INFINITY, 1.0], up, up]);
    write(dir.path(), "s.toml", &normal_scene("inf.exr"));
    refuses(&render, dir.path(), &["inf.exr", "texel (0, 1)", "finite"]);
    // A zero vector at texel (2, 1).
    write_rgb_exr(&dir.path().join("zero.exr"), 3, 2, &[up, up, up, up, up, [0.0, 0.0, 0.0]]);
    write(dir.path(), "s.toml", &normal_scene("zero.exr"));
    refuses(&render, dir.path(), &["zero.exr", "texel (2, 1)", "zero vector"]);
    // An 8-bit map whose texel (1, 1) points into the surface (blue 0 where the rest are 255).
    let mut png = image::RgbImage::from_pixel(2, 2, image::Rgb([128, 128, 255]));
    png.put_pixel(1, 1, image::Rgb([128, 128, 0]));
    png.save(dir.path().join("inward.png")).unwrap();
    write(dir.path(), "s.toml", &normal_scene("inward.png"));
    refuses(&render, dir.path(), &["inward.png", "texel (1, 1)", "into the surface"]);
    // Blue 127 (z = -1/255, rounding of a horizontal normal) is taken, clamped to z = 0.
    let mut png = image::RgbImage::from_pixel(2, 2, image::Rgb([128, 128, 255]));
    png.put_pixel(0, 0, image::Rgb([255, 128, 127]));
    png.save(dir.path().join("edge.png")).unwrap();
    write(dir.path(), "s.toml", &normal_scene("edge.png"));
    let out = pomkit(&render, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    // Lossy compression leaves a few texels near the horizon pointing slightly inward (real
    // library maps reach z = -0.1 on a few hundredths of a percent of their texels): 1 texel in
    // 400 at blue 115 (z = -0.098) is taken; 10 in 400 (2.5%) are refused as a mis-encoded map.
    let mut png = image::RgbImage::from_pixel(20, 20, image::Rgb([128, 128, 255]));
    png.put_pixel(3, 4, image::Rgb([250, 128, 115]));
    png.save(dir.path().join("jpeg.png")).unwrap();
    write(dir.path(), "s.toml", &normal_scene("jpeg.png"));
    let out = pomkit(&render, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    for x in 0..10 {
        png.put_pixel(x, 7, image::Rgb([250, 128, 115]));
    }
    png.save(dir.path().join("many.png")).unwrap();
    write(dir.path(), "s.toml", &normal_scene("many.png"));
    refuses(&render, dir.path(), &["many.png", "texel (3, 4)", "over 1% of the texels"]);
}

#[test]
fn builtin_heights_refuse_channel_and_normalize_as_scene_files_do() {
    let dir = tempfile::tempdir().unwrap();
    refuses(
        &["bake", "normal", "builtin:bricks:16x16", "--channel", "a", "-o", "n.png"],
        dir.path(),
        &["--channel a", "builtin:bricks:16x16", "does not apply"],
    );
    refuses(
        &["bake", "normal", "builtin:bricks:16x16", "--normalize", "-o", "n.png"],
        dir.path(),
        &["--normalize", "builtin:bricks:16x16", "does not apply"],
    );
    printf_rays(dir.path());
    refuses(
        &[
            "trace",
            "--height",
            "builtin:bricks:16x16",
            "--channel",
            "g",
            "--technique",
            "pom",
            "--rays",
            "r.csv",
            "-o",
            "h.csv",
        ],
        dir.path(),
        &["--channel g", "builtin:bricks:16x16"],
    );
}

fn printf_rays(dir: &Path) {
    write(dir, "r.csv", "u,v,dx,dy,dz\n0.3,0.4,0.5,0.2,-0.6\n");
}

// ---------------------------------------------------------------------------------------------
// 11: Mesa's runtime-directory message
// ---------------------------------------------------------------------------------------------

#[test]
fn a_gpu_render_without_xdg_runtime_dir_prints_no_runtime_dir_error() {
    if let Err(e) = pomkit_gpu::GpuContext::new() {
        pomkit_gpu::context::skip_without_gpu(&e);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(["render", "--backend", "gpu", "--size", "32x32", "-o", "x.png"])
        .current_dir(dir.path())
        .env_remove("XDG_RUNTIME_DIR")
        .stdin(Stdio::null())
        .output()
        .expect("pomkit runs");
    let msg = stderr(&out);
    assert!(out.status.success(), "{msg}");
    assert!(!msg.contains("XDG_RUNTIME_DIR"), "{msg}");
    assert!(dir.path().join("x.png").is_file());
}

// ---------------------------------------------------------------------------------------------
// 12: causes printed once, NUL in paths
// ---------------------------------------------------------------------------------------------

#[test]
fn a_missing_texture_in_a_scene_prints_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("sc")).unwrap();
    let text = plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", "")
        .replace("technique = \"flat\"", "technique = \"flat\"\nalbedo = \"x.png\"");
    write(&dir.path().join("sc"), "s.toml", &text);
    let out = refuses(&["render", "sc/s.toml", "--backend", "cpu", "-o", "o.png"], dir.path(), &["sc/x.png", "albedo"]);
    let msg = stderr(&out);
    assert_eq!(msg.matches("sc/x.png").count(), 1, "{msg}");
    assert_eq!(msg.matches("No such file").count(), 1, "{msg}");
}

#[test]
fn a_nul_byte_in_a_scene_path_is_a_clear_error_printed_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let render = ["render", "s.toml", "--backend", "cpu", "-o", "o.png"];
    let text = plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", "")
        .replace("technique = \"flat\"", "technique = \"flat\"\nalbedo = \"a\\u0000b.png\"");
    write(dir.path(), "s.toml", &text);
    let out = refuses(&render, dir.path(), &["s.toml", "albedo", "NUL", "a\\0b.png"]);
    assert!(!out.stderr.contains(&0), "a raw NUL byte in {:?}", stderr(&out));
    let text = plane_scene("eye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]", "")
        .replace("mesh = \"plane\"", "mesh = \"m\\u0000.obj\"");
    write(dir.path(), "s.toml", &text);
    let out = refuses(&render, dir.path(), &["s.toml", "mesh", "NUL"]);
    assert!(!out.stderr.contains(&0), "a raw NUL byte in {:?}", stderr(&out));
}

// ---------------------------------------------------------------------------------------------
// 14: the problem, not library jargon
// ---------------------------------------------------------------------------------------------

/// Bakes `input` (with `extra` flags) to a float normal map and returns its texels.
fn bake_float(dir: &Path, input: &str, extra: &[&str], out: &str) -> Vec<[f32; 3]> {
    let mut args = vec!["bake", "normal", input, "--encoding", "float", "--edges", "clamp", "-o", out];
    args.extend_from_slice(extra);
    let o = pomkit(&args, dir);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    rgbf(&dir.join(out))
}

#[test]
fn a_single_channel_exr_reads_as_a_height_map() {
    use exr::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (7u32, 5u32);
    let heights = test_heights(w, h);
    let channel = AnyChannel::new("Y", FlatSamples::F32(heights.clone()));
    let layer = Layer::new(
        (w as usize, h as usize),
        LayerAttributes::named("height"),
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    Image::from_layer(layer).write().to_file(dir.path().join("y.exr")).expect("EXR written");
    // The same heights in the red channel of an RGB EXR, which the image crate reads.
    let rgb: Vec<[f32; 3]> = heights.iter().map(|&v| [v, 0.0, 0.0]).collect();
    write_rgb_exr(&dir.path().join("rgb.exr"), w, h, &rgb);
    let single = bake_float(dir.path(), "y.exr", &[], "a.exr");
    let reference = bake_float(dir.path(), "rgb.exr", &["--channel", "r"], "b.exr");
    assert_eq!(single, reference);
    assert!(single.iter().any(|n| n[0].abs() > 0.1), "the map has slopes");
    // --channel a on it: it has no alpha.
    refuses(&["bake", "normal", "y.exr", "--channel", "a", "-o", "n.png"], dir.path(), &["y.exr", "no alpha"]);
}

#[test]
fn a_float_tiff_reads_as_a_height_map() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (6u32, 4u32);
    let heights = test_heights(w, h);
    let file = std::fs::File::create(dir.path().join("h.tif")).unwrap();
    let mut enc = tiff::encoder::TiffEncoder::new(file).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray32Float>(w, h, &heights).unwrap();
    drop(enc);
    let rgb: Vec<[f32; 3]> = heights.iter().map(|&v| [v, 0.0, 0.0]).collect();
    write_rgb_exr(&dir.path().join("rgb.exr"), w, h, &rgb);
    let tiff = bake_float(dir.path(), "h.tif", &[], "a.exr");
    let reference = bake_float(dir.path(), "rgb.exr", &["--channel", "r"], "b.exr");
    assert_eq!(tiff, reference);
    // A float TIFF outside [0, 1] says so (not "color type Unknown(32)").
    let file = std::fs::File::create(dir.path().join("big.tif")).unwrap();
    let mut enc = tiff::encoder::TiffEncoder::new(file).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray32Float>(2, 2, &[0.0, 5.0, 1.0, 2.0]).unwrap();
    drop(enc);
    refuses(&["bake", "normal", "big.tif", "-o", "n.png"], dir.path(), &["big.tif", "[0, 5]", "--normalize"]);
}

#[test]
fn render_compare_with_an_unknown_technique_names_compare() {
    let dir = tempfile::tempdir().unwrap();
    let out = refuses(&["render", "--compare", "pom,foo", "-o", "c.png"], dir.path(), &["--compare", "foo"]);
    assert!(!stderr(&out).contains("--technique"), "{}", stderr(&out));
}

#[test]
fn normalize_on_the_extremes_of_f32_rescales_them_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (4u32, 3u32);
    // -3.4e38, 3.4e38 and 0 normalize to exactly 0, 1 and 0.5.
    let extreme: Vec<f32> = (0..w * h).map(|i| [-3.4e38, 3.4e38, 0.0][(i % 3) as usize]).collect();
    let unit: Vec<f32> = (0..w * h).map(|i| [0.0, 1.0, 0.5][(i % 3) as usize]).collect();
    write_rgb_exr(&dir.path().join("x.exr"), w, h, &extreme.iter().map(|&v| [v, v, v]).collect::<Vec<_>>());
    write_rgb_exr(&dir.path().join("u.exr"), w, h, &unit.iter().map(|&v| [v, v, v]).collect::<Vec<_>>());
    let a = bake_float(dir.path(), "x.exr", &["--normalize", "--channel", "r"], "a.exr");
    let b = bake_float(dir.path(), "u.exr", &["--channel", "r"], "b.exr");
    assert_eq!(a, b);
    assert!(a.iter().all(|n| n.iter().all(|c| c.is_finite())));
}

// ---------------------------------------------------------------------------------------------
// A FIFO as the input of a single bake
// ---------------------------------------------------------------------------------------------

/// A FIFO (named pipe) that nothing writes to is given up on after the documented wait, with
/// the reason, instead of blocking forever in `open`; one that a program writes to is read.
#[cfg(unix)]
#[test]
fn a_fifo_with_no_writer_is_given_up_on_and_one_with_a_writer_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.png");
    assert!(Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs").success());
    let started = std::time::Instant::now();
    // (Not `refuses`: its snapshot of the folder would itself block reading the FIFO.)
    let out = pomkit(&["bake", "normal", "pipe.png", "-o", "n.png"], dir.path());
    let msg = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{msg}");
    for needle in ["pipe.png", "FIFO", "no program opened it for writing within 10 s"] {
        assert!(msg.contains(needle), "{needle:?} missing from: {msg}");
    }
    assert!(!dir.path().join("n.png").exists());
    assert!(started.elapsed() < std::time::Duration::from_secs(60), "the wait is bounded");
    // A writer: the map arrives through the pipe and is baked.
    let png = dir.path().join("h.png");
    let made = pomkit(&["generate", "bricks", "--size", "32x32", "-o", "h.png"], dir.path());
    assert!(made.status.success(), "{}", stderr(&made));
    let mut writer =
        Command::new("sh").arg("-c").arg("cat \"$0\" > \"$1\"").arg(&png).arg(&fifo).spawn().expect("sh runs");
    let out = pomkit(&["bake", "normal", "pipe.png", "-o", "n.png"], dir.path());
    writer.wait().expect("the writer ends");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("n.png").is_file());
}
