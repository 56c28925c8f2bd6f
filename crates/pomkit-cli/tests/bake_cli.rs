//! `pomkit bake` and `pomkit generate` end to end: outputs decode to what core computes, and bad
//! input fails with a clear message and leaves no file behind (docs/LIMITS.md).

use std::path::Path;
use std::process::{Command, Output};

use pomkit_core::bake::{self, NormalBakeOptions, NormalFilter};
use pomkit_core::glam::Vec3;
use pomkit_core::procedural::{self, Pattern};

fn pomkit(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).current_dir(dir).output().expect("pomkit runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Files in `dir`, sorted, to prove nothing partial was left.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn bake_normal_from_a_generated_height_map_matches_core() {
    let dir = tempfile::tempdir().unwrap();
    let out = pomkit(&["generate", "pyramids", "-o", "h.png", "--size", "48x40"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let out = pomkit(&["bake", "normal", "h.png", "-o", "n.png", "--scale", "5", "--filter", "sobel"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let img = image::open(dir.path().join("n.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (48, 40));
    // Independent path: core on the generated field, quantised through the 16-bit file.
    let field = procedural::generate(Pattern::Pyramids, 48, 40);
    let q = pomkit_core::HeightField::from_heights(
        48,
        40,
        field.heights().iter().map(|h| (h * 65535.0).round() / 65535.0).collect(),
    )
    .unwrap();
    let opts = NormalBakeOptions { scale: 5.0, filter: NormalFilter::Sobel, ..Default::default() };
    let expect = bake::bake_normals(&q, &opts).unwrap();
    for (i, px) in img.pixels().enumerate() {
        assert_eq!(px.0, bake::encode_rgb8(expect[i]), "texel {i}");
    }
}

#[test]
fn encodings_and_conventions_reach_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let out = pomkit(args, dir.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    };
    run(&["bake", "normal", "builtin:waves:32x32", "-o", "up.png"]);
    run(&["bake", "normal", "builtin:waves:32x32", "-o", "down.png", "--y-down"]);
    run(&["bake", "normal", "builtin:waves:32x32", "-o", "rg.png", "--encoding", "rg8"]);
    run(&["bake", "normal", "builtin:waves:32x32", "-o", "f.exr", "--encoding", "float"]);
    // A built-in map has no depth to read (--depth-map is refused); a negative scale inverts.
    run(&["bake", "normal", "builtin:waves:32x32", "-o", "deep.png", "--scale=-8"]);
    let up = image::open(dir.path().join("up.png")).unwrap().to_rgb8();
    let down = image::open(dir.path().join("down.png")).unwrap().to_rgb8();
    let rg = image::open(dir.path().join("rg.png")).unwrap().to_rgb8();
    let deep = image::open(dir.path().join("deep.png")).unwrap().to_rgb8();
    let float = image::open(dir.path().join("f.exr")).unwrap().to_rgb32f();
    let mut saw_slope = false;
    for (((a, b), (c, d)), e) in up.pixels().zip(down.pixels()).zip(rg.pixels().zip(deep.pixels())).zip(float.pixels())
    {
        // +Y down mirrors green about 127.5; red and blue agree.
        assert_eq!(a.0[0], b.0[0]);
        assert!((i32::from(a.0[1]) + i32::from(b.0[1]) - 255).abs() <= 1);
        assert_eq!([a.0[0], a.0[1], 0], c.0);
        // Inverted, the relief's x and y flip sign.
        assert!((i32::from(a.0[0]) + i32::from(d.0[0]) - 255).abs() <= 1);
        let n = Vec3::from_array(e.0);
        assert!((n.length() - 1.0).abs() < 1e-5);
        assert!((bake::decode_rgb8(a.0) - n).length() < 0.01);
        saw_slope |= n.x.abs() > 0.2;
    }
    assert!(saw_slope, "waves should have slopes at scale 8");
}

#[test]
fn parallax_and_pack_write_their_formats() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        &["bake", "parallax", "builtin:bricks:64x32", "-o", "p.png"][..],
        &["bake", "parallax", "builtin:bricks:64x32", "-o", "p.exr", "--encoding", "float"],
        &["bake", "pack", "builtin:bricks:64x32", "-o", "nh.png"],
    ] {
        let out = pomkit(args, dir.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    }
    let field = procedural::generate(Pattern::Bricks, 64, 32);
    let expect = bake::bake_parallax(&field, &NormalBakeOptions::default()).unwrap();
    let p8 = image::open(dir.path().join("p.png")).unwrap().to_luma8();
    let pf = image::open(dir.path().join("p.exr")).unwrap().to_rgb32f();
    for (i, (a, b)) in p8.pixels().zip(pf.pixels()).enumerate() {
        assert!((f32::from(a.0[0]) / 255.0 * 2.0 - 1.0 - expect[i]).abs() <= 1.0 / 255.0 + 1e-6);
        assert!((b.0[0] - expect[i]).abs() < 1e-6);
    }
    let nh = image::open(dir.path().join("nh.png")).unwrap();
    assert!(nh.color().has_alpha());
    // The packed map's alpha reads back as the same height field.
    let out = pomkit(&["bake", "normal", "nh.png", "--channel", "a", "-o", "again.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn bad_input_fails_clearly_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let ok = pomkit(&["generate", "cobblestones", "-o", "h.png", "--size", "64x64"], dir.path());
    assert!(ok.status.success());
    let bytes = std::fs::read(dir.path().join("h.png")).unwrap();
    std::fs::write(dir.path().join("truncated.png"), &bytes[..bytes.len() / 3]).unwrap();
    std::fs::write(dir.path().join("notes.png"), b"this is not an image").unwrap();
    // A 0x0 PNG cannot be made by an encoder; this one has a valid signature and a zero-size IHDR.
    let mut zero = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\0\0\0\0\0\x08\0\0\0\0".to_vec();
    zero.extend_from_slice(&[0x3a, 0x7e, 0x9b, 0x55]);
    std::fs::write(dir.path().join("zero.png"), &zero).unwrap();
    image::GrayImage::from_raw(1, 1, vec![9]).unwrap().save(dir.path().join("one.png")).unwrap();
    let before = listing(dir.path());

    let cases: &[(&[&str], &str)] = &[
        (&["bake", "normal", "truncated.png", "-o", "out.png"], "truncated.png"),
        (&["bake", "normal", "notes.png", "-o", "out.png"], "notes.png"),
        (&["bake", "normal", "zero.png", "-o", "out.png"], "zero.png"),
        (&["bake", "normal", "one.png", "-o", "out.png"], "1x1"),
        (&["bake", "normal", "missing.png", "-o", "out.png"], "missing.png"),
        (&["bake", "normal", "h.png", "-o", "out.png", "--scale", "NaN"], "--scale"),
        (&["bake", "normal", "h.png", "-o", "out.png", "--scale", "inf"], "--scale"),
        (&["bake", "normal", "h.png", "-o", "out.png", "--channel", "q"], "--channel"),
        (&["bake", "normal", "h.png", "-o", "out.png", "--channel", "a"], "no alpha"),
        (&["bake", "normal", "h.png", "-o", "out.exr"], ".png"),
        (&["bake", "normal", "h.png", "-o", "out.png", "--encoding", "float"], ".exr"),
        (&["bake", "normal", "h.png", "-o", "no/such/dir/out.png"], "does not exist"),
        (&["bake", "parallax", "one.png", "-o", "out.png"], "1x1"),
        (&["bake", "pack", "builtin:nosuch", "-o", "out.png"], "nosuch"),
        (&["bake", "normal", "builtin:bricks:0x5", "-o", "out.png"], "between 1 and 16384"),
        (&["generate", "marble", "-o", "out.png"], "marble"),
        (&["bake", "cone", "h.png", "-o", "out.exr"], ".png"),
        (&["bake", "maxmip", "truncated.png", "-o", "out.png"], "truncated.png"),
        (&["bake", "cone", "h.png", "-o", "out.png", "--edges", "mirror"], "--edges"),
    ];
    for (args, needle) in cases {
        let out = pomkit(args, dir.path());
        assert!(!out.status.success(), "{args:?} should fail");
        let msg = stderr(&out);
        assert!(msg.contains(needle), "{args:?}: message {msg:?} should mention {needle:?}");
        assert!(!msg.contains("panicked"), "{args:?} panicked: {msg}");
        assert_eq!(listing(dir.path()), before, "{args:?} left a file behind");
    }
}

#[test]
fn unwritable_output_leaves_the_old_file_intact() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("keep.png");
    std::fs::write(&target, b"old contents").unwrap();
    // Writing a folder's name fails; and a failed bake must not touch an existing output.
    std::fs::create_dir(dir.path().join("folder.png")).unwrap();
    let out = pomkit(&["bake", "normal", "builtin:bricks:16x16", "-o", "folder.png"], dir.path());
    assert!(!out.status.success());
    assert!(stderr(&out).contains("folder.png"));
    let out = pomkit(&["bake", "normal", "builtin:bricks:1x1", "-o", "keep.png"], dir.path());
    assert!(!out.status.success());
    assert_eq!(std::fs::read(&target).unwrap(), b"old contents");
    assert_eq!(listing(dir.path()), vec!["folder.png".to_owned(), "keep.png".to_owned()]);
}

#[test]
fn every_verb_has_help() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        &["--help"][..],
        &["bake", "--help"],
        &["bake", "normal", "--help"],
        &["bake", "parallax", "--help"],
        &["bake", "pack", "--help"],
        &["bake", "maxmip", "--help"],
        &["bake", "cone", "--help"],
        &["generate", "--help"],
    ] {
        let out = pomkit(args, dir.path());
        assert!(out.status.success(), "{args:?}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("Usage"), "{args:?}");
    }
    let out = pomkit(&["bake", "normal", "--help"], dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    for flag in ["--scale", "--filter", "--edges", "--encoding", "--y-down", "--depth-map", "--channel"] {
        assert!(text.contains(flag), "bake normal --help lacks {flag}");
    }
}

/// The bilinear surface of `field` (heights, wrap or clamp) at `(x, y)` in texel units.
fn surface_height(field: &pomkit_core::HeightField, edges: pomkit_core::EdgeMode, x: f64, y: f64) -> f64 {
    let uv =
        pomkit_core::glam::Vec2::new((x / f64::from(field.width())) as f32, (y / f64::from(field.height())) as f32);
    1.0 - f64::from(field.sample_bilinear(uv, edges))
}

/// The greatest height of the bilinear surface over texel footprint `(i, j)`, sampled every
/// 1/8 texel (edges and corners included).
fn brute_top(field: &pomkit_core::HeightField, edges: pomkit_core::EdgeMode, i: u32, j: u32) -> f64 {
    (0..=8)
        .flat_map(|a| (0..=8).map(move |b| (a, b)))
        .map(|(a, b)| {
            surface_height(field, edges, f64::from(i) + f64::from(a) / 8.0, f64::from(j) + f64::from(b) / 8.0)
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn maxmip_holds_every_footprints_highest_point_and_each_level_the_highest_of_its_children() {
    use pomkit_core::EdgeMode;
    let dir = tempfile::tempdir().unwrap();
    let out = pomkit(&["bake", "maxmip", "builtin:cobblestones:24x20", "-o", "m.png", "--edges", "clamp"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let img = image::open(dir.path().join("m.png")).unwrap().to_luma16();
    // Levels 24x20, 12x10, 6x5, 3x3, 2x2, 1x1: level 0 on the left, the others stacked in a
    // column 12 wide (10 + 5 + 3 + 2 + 1 = 21 rows).
    assert_eq!(img.dimensions(), (36, 21));
    let at = |x: u32, y: u32| f64::from(img.get_pixel(x, y).0[0]) / 65535.0;
    let field = procedural::generate(Pattern::Cobblestones, 24, 20);
    for j in 0..20 {
        for i in 0..24 {
            let truth = brute_top(&field, EdgeMode::Clamp, i, j);
            assert!(
                at(i, j) >= truth - 1e-6 && at(i, j) <= truth + 2.0 / 65535.0,
                "({i},{j}): {} vs {truth}",
                at(i, j)
            );
        }
    }
    let sizes = [(24, 20), (12, 10), (6, 5), (3, 3), (2, 2), (1, 1)];
    let origins = [(0, 0), (24, 0), (24, 10), (24, 15), (24, 18), (24, 20)];
    for k in 1..sizes.len() {
        let ((w, h), (ox, oy), (fw, fh), (fx, fy)) = (sizes[k], origins[k], sizes[k - 1], origins[k - 1]);
        for y in 0..h {
            for x in 0..w {
                let children = [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)];
                let highest = children
                    .into_iter()
                    .filter(|&(cx, cy)| cx < fw && cy < fh)
                    .map(|(cx, cy)| at(fx + cx, fy + cy))
                    .fold(0.0, f64::max);
                assert_eq!(at(ox + x, oy + y), highest, "level {k} cell ({x},{y})");
            }
        }
    }
}

#[test]
fn cone_map_cones_hold_no_point_of_the_bilinear_surface() {
    use pomkit_core::EdgeMode;
    let dir = tempfile::tempdir().unwrap();
    for (edges, name) in [(EdgeMode::Wrap, "wrap"), (EdgeMode::Clamp, "clamp")] {
        let out = pomkit(&["bake", "cone", "builtin:cobblestones:16x12", "-o", "c.png", "--edges", name], dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
        let img = image::open(dir.path().join("c.png")).unwrap();
        assert!(img.color().has_alpha() && img.color().channel_count() == 2, "grey + alpha: {:?}", img.color());
        let img = img.to_luma_alpha16();
        assert_eq!(img.dimensions(), (16, 12));
        let field = procedural::generate(Pattern::Cobblestones, 16, 12);
        // Surface points every 1/4 texel over the area the cones must respect: the 3 x 3 tiles
        // around the map for wrap, the map for clamp (beyond it the border repeats).
        let tiles = if edges == EdgeMode::Wrap { -1..=1 } else { 0..=0 };
        let mut points = Vec::new();
        for ty in tiles.clone() {
            for tx in tiles.clone() {
                for b in 0..12 * 4 {
                    for a in 0..16 * 4 {
                        let (x, y) = (f64::from(tx * 16) + f64::from(a) / 4.0, f64::from(ty * 12) + f64::from(b) / 4.0);
                        points.push((x, y, surface_height(&field, edges, x, y)));
                    }
                }
            }
        }
        let mut shares = Vec::new();
        for j in 0..12 {
            for i in 0..16 {
                let [grey, alpha] = img.get_pixel(i, j).0;
                let top = f64::from(grey) / 65535.0;
                let ratio = (f64::from(alpha) / 65535.0).powi(2) * 12.0;
                assert!(
                    top >= brute_top(&field, edges, i, j) - 1e-6,
                    "{name} ({i},{j}): the apex is below the surface"
                );
                // The tightest cone the sampled points allow: dist(q, footprint) / (h(q) - top).
                let mut tightest = 12.0f64;
                for &(x, y, hq) in &points {
                    if hq > top + 1e-6 {
                        let dx = (f64::from(i) - x).max(x - f64::from(i) - 1.0).max(0.0);
                        let dy = (f64::from(j) - y).max(y - f64::from(j) - 1.0).max(0.0);
                        tightest = tightest.min(dx.hypot(dy) / (hq - top));
                    }
                }
                assert!(ratio <= tightest + 1e-6, "{name} ({i},{j}): cone {ratio} holds a surface point ({tightest})");
                shares.push(ratio / tightest);
            }
        }
        let mean = shares.iter().sum::<f64>() / shares.len() as f64;
        println!("{name}: the cones are {mean:.3} of the widest the sampled surface allows, on average");
        assert!(mean > 0.88, "{name}: cones only {mean} of the widest");
    }
}

/// `bake cone --relaxed`: 16-bit grey + alpha like the conservative map, the same tops, cones
/// no narrower than the search's tolerance allows (both builds stop within a factor
/// `(1 - SLACK) / (1 + FAR)` = 0.75 of their exact answers, and the exact relaxed cone is never
/// the narrower) and wider on average on cobblestones; and `compare --cone-map` steps on
/// them with hits within half a texel of exact's on all but a few rays.
#[test]
fn relaxed_cone_maps_are_wider_and_trace_close_to_exact() {
    let dir = tempfile::tempdir().unwrap();
    let height = "builtin:cobblestones:96x96";
    for (args, what) in [
        (vec!["bake", "cone", height, "-o", "c.png"], "conservative"),
        (vec!["bake", "cone", height, "--relaxed", "-o", "r.png"], "relaxed"),
    ] {
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(stderr(&out).contains(what), "{}", stderr(&out));
    }
    let c = image::open(dir.path().join("c.png")).unwrap().to_luma_alpha16();
    let r = image::open(dir.path().join("r.png")).unwrap().to_luma_alpha16();
    let (mut wider, mut n) = (0.0, 0.0);
    for (pc, pr) in c.pixels().zip(r.pixels()) {
        assert_eq!(pc.0[0], pr.0[0], "the same tops");
        let ratio = (f64::from(pr.0[1]) / f64::from(pc.0[1]).max(1.0)).powi(2);
        assert!(ratio >= 0.75, "a relaxed cone {ratio} times as wide as the conservative one");
        wider += ratio;
        n += 1.0;
    }
    assert!(wider / n > 1.5, "relaxed cones only {:.2} times as wide", wider / n);
    let out = pomkit(
        &[
            "compare",
            "--height",
            height,
            "--techniques",
            "cone",
            "--cone-map",
            "r.png",
            "--format",
            "csv",
            "--rays",
            "500",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let table = String::from_utf8_lossy(&out.stdout).into_owned();
    for row in table.lines().skip(1).filter(|l| l.starts_with("cone,")) {
        let share: f64 = row.split(',').nth(5).unwrap().parse().unwrap();
        assert!(share <= 0.02, "relaxed cone stepping over a texel from exact on {share} of the rays: {row}");
    }
}
