//! `pomkit bake height`, end to end: a built-in map baked to normals by `bake normal` and
//! integrated back matches the built-in's heights (pomkit-core's generator is the truth), at
//! the scale the normals were baked with; EXR output; batch mode with the relief in the report;
//! bad normal maps refused naming the file, nothing written.

mod support;

use std::path::Path;

use pomkit_core::procedural::{Pattern, generate};
use pomkit_io::{HeightLoadOptions, PixelLayout, Pixels};
use support::{pomkit, refuses, stderr};

/// Pearson's r of two equal-length sequences.
fn pearson(a: &[f32], b: &[f32]) -> f64 {
    pomkit_core::integrate::height_agreement(a, b).0
}

fn heights(path: &Path) -> Vec<f32> {
    pomkit_io::load_height_field(path, &HeightLoadOptions::default()).unwrap().heights()
}

/// The number after `key` in `text`.
fn number_after(text: &str, key: &str) -> f64 {
    let rest = &text[text.find(key).unwrap_or_else(|| panic!("{key} in {text}")) + key.len()..];
    rest.trim_start().split(|c: char| !(c.is_ascii_digit() || c == '.')).next().unwrap().parse().unwrap()
}

#[test]
fn builtin_round_trip_recovers_the_heights_and_their_depth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = pomkit(&["bake", "normal", "builtin:cobblestones:128x128", "--scale", "8", "-o", "n.png"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let truth = generate(Pattern::Cobblestones, 128, 128).heights();
    let true_range = truth.iter().copied().fold(f32::MIN, f32::max) - truth.iter().copied().fold(f32::MAX, f32::min);
    for (method, file) in [("poisson", "h.png"), ("weighted", "hw.exr")] {
        let out = pomkit(&["bake", "height", "n.png", "-o", file, "--method", method], d);
        let msg = stderr(&out);
        assert!(out.status.success(), "{msg}");
        assert!(msg.contains(&format!("wrote {file} (128x128 height map, {method}, wrap edges)")), "{msg}");
        let got = heights(&d.join(file));
        assert!(got.iter().all(|v| (0.0..=1.0).contains(v)));
        let r = pearson(&got, &truth);
        assert!(r > 0.99, "{method}: r = {r}");
        // The depth the normals imply: the true range times the bake's scale (8 texel widths).
        let range = number_after(&msg, "relief:");
        let depth_scale = number_after(&msg, "depth_scale");
        let expect = f64::from(true_range) * 8.0;
        assert!((range / expect - 1.0).abs() < 0.1, "{method}: range {range} vs {expect}");
        assert!((depth_scale - range / 128.0).abs() < 1e-5, "{depth_scale} vs {range} / 128");
    }
    // The EXR holds floats: more than 256 distinct values, and the PNG 16-bit ones.
    let exr = heights(&d.join("hw.exr"));
    let mut distinct: Vec<u32> = exr.iter().map(|v| v.to_bits()).collect();
    distinct.sort_unstable();
    distinct.dedup();
    assert!(distinct.len() > 1000, "{}", distinct.len());
}

#[test]
fn y_down_and_two_channel_maps_read_as_bake_normal_wrote_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Not symmetric in y, so a flipped green would integrate upside down.
    let spec = "builtin:text:96x64";
    let truth = generate(Pattern::Text, 96, 64).heights();
    for (flags, read) in [(vec!["--y-down"], vec!["--y-down"]), (vec!["--encoding", "rg8"], vec!["--encoding", "rg8"])]
    {
        let mut args = vec!["bake", "normal", spec, "--edges", "clamp", "-o", "n.png"];
        args.extend(&flags);
        assert!(pomkit(&args, d).status.success());
        let mut args = vec!["bake", "height", "n.png", "--edges", "clamp", "-o", "h.png"];
        args.extend(&read);
        let out = pomkit(&args, d);
        assert!(out.status.success(), "{}", stderr(&out));
        let r = pearson(&heights(&d.join("h.png")), &truth);
        assert!(r > 0.98, "{flags:?}: r = {r}");
        // Read the wrong way up, the same map does not match.
        if flags[0] == "--y-down" {
            let out = pomkit(&["bake", "height", "n.png", "--edges", "clamp", "-o", "wrong.png"], d);
            assert!(out.status.success());
            let r = pearson(&heights(&d.join("wrong.png")), &truth);
            assert!(r < 0.9, "read as +Y up: r = {r}");
        }
    }
}

#[test]
fn batch_mode_integrates_a_folder_and_reports_the_relief() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("maps")).unwrap();
    for (name, scale) in [("bricks", "4"), ("waves", "8")] {
        let out = pomkit(
            &["bake", "normal", &format!("builtin:{name}:64x64"), "--scale", scale, "-o", &format!("maps/{name}.png")],
            d,
        );
        assert!(out.status.success());
    }
    let out = pomkit(&["bake", "height", "maps", "-o", "out", "--report", "report.json"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(d.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["verb"], "height");
    assert_eq!(report["baked"], 2);
    for file in report["files"].as_array().unwrap() {
        let input = file["input"].as_str().unwrap();
        let name = Path::new(input).file_stem().unwrap().to_str().unwrap();
        let output = d.join(format!("out/{name}_height.png"));
        assert_eq!(file["outputs"][0].as_str().map(|s| d.join(s)), Some(output.clone()));
        // Each output is what the single bake of the same file writes.
        let single = d.join(format!("{name}_single.png"));
        assert!(pomkit(&["bake", "height", input, "-o", single.to_str().unwrap()], d).status.success());
        assert_eq!(std::fs::read(&output).unwrap(), std::fs::read(&single).unwrap(), "{name}");
        let range = file["range_texels"].as_f64().unwrap();
        let depth_scale = file["depth_scale"].as_f64().unwrap();
        assert!((depth_scale - range / 64.0).abs() < 1e-6);
        // waves spans the whole [0, 1] at scale 8; bricks 0.3 to 1 or so at scale 4.
        let expect = if name == "waves" { 8.0 } else { 4.0 * 0.7 };
        assert!((range / expect - 1.0).abs() < 0.15, "{name}: range {range} vs {expect}");
    }
    // --name with .exr writes float outputs.
    let out = pomkit(&["bake", "height", "maps", "-o", "exr", "--name", "{stem}.exr"], d);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(d.join("exr/bricks.exr").is_file() && d.join("exr/waves.exr").is_file());
}

/// Writes a float RGB EXR of 4x4 normals, `bad` at texel (2, 1).
fn exr_with(path: &Path, bad: [f32; 3]) {
    let mut px = [0.0f32, 0.0, 1.0].repeat(16);
    px[(4 + 2) * 3..(4 + 2) * 3 + 3].copy_from_slice(&bad);
    pomkit_io::write_image(path, 4, 4, PixelLayout::RgbF32, Pixels::F32(&px)).unwrap();
}

#[test]
fn bad_normal_maps_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    exr_with(&d.join("zero.exr"), [0.0, 0.0, 0.0]);
    refuses(&["bake", "height", "zero.exr", "-o", "h.png"], d, &["zero.exr", "(2, 1)", "zero vector"]);
    exr_with(&d.join("nan.exr"), [f32::NAN, 0.0, 1.0]);
    refuses(&["bake", "height", "nan.exr", "-o", "h.png"], d, &["nan.exr", "(2, 1)", "finite"]);
    // An 8-bit texel with blue 0 among others: it points into the surface.
    let mut img = image::RgbImage::from_pixel(4, 4, image::Rgb([128, 128, 255]));
    img.put_pixel(2, 1, image::Rgb([128, 128, 0]));
    img.save(d.join("inward.png")).unwrap();
    refuses(&["bake", "height", "inward.png", "-o", "h.png"], d, &["inward.png", "into the surface"]);
    std::fs::write(d.join("text.png"), "not an image").unwrap();
    refuses(&["bake", "height", "text.png", "-o", "h.png"], d, &["text.png"]);
    image::RgbImage::from_pixel(1, 1, image::Rgb([128, 128, 255])).save(d.join("one.png")).unwrap();
    refuses(&["bake", "height", "one.png", "-o", "h.png"], d, &["one.png", "1x1", "2x2"]);
    // A height map is not a normal map, and neither is a built-in.
    image::GrayImage::from_pixel(4, 4, image::Luma([100])).save(d.join("grey.png")).unwrap();
    refuses(&["bake", "height", "grey.png", "-o", "h.png"], d, &["grey.png", "normal map needs RGB"]);
    refuses(&["bake", "height", "builtin:bricks", "-o", "h.png"], d, &["builtin:bricks", "bake normal"]);
    // Outputs: a JPEG cannot hold 16-bit heights; the input is never overwritten.
    refuses(&["bake", "height", "one.png", "-o", "h.jpg"], d, &["h.jpg", ".png"]);
    image::RgbImage::from_pixel(4, 4, image::Rgb([128, 128, 255])).save(d.join("flat.png")).unwrap();
    refuses(&["bake", "height", "flat.png", "-o", "flat.png"], d, &["flat.png"]);
    refuses(&["bake", "height", "flat.png", "-o", "h.png", "--iterations", "0"], d, &["--iterations"]);
}
