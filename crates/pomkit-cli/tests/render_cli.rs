//! `pomkit render` end to end: golden images of the demo scene, AOVs, the comparison sheet, and
//! bad scenes failing with a message that names the field.
//!
//! Golden images live in `tests/golden/`. A render matches when at most 0.5% of its pixels
//! differ from the golden one by more than 24 (of 255) in some channel; failures write the
//! render and a difference image to `target/golden-failures/` for inspection. To re-approve
//! after an intended change, run with `POMKIT_APPROVE=1` and commit the new PNGs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn pomkit(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).current_dir(dir).output().expect("pomkit runs")
}

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
        (vec!["render", "--size", "320x180", "-o", "demo.png"], "demo.png"),
        (vec!["render", "--size", "320x180", "--technique", "normal", "-o", "normal.png"], "demo-normal.png"),
        (vec!["render", "--size", "320x180", "--technique", "steep", "-o", "steep.png"], "demo-steep.png"),
        (vec!["render", "--size", "320x180", "--technique", "exact", "-o", "exact.png"], "demo-exact.png"),
    ] {
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        let file = dir.path().join(args[args.len() - 1]);
        check_golden(&file, name);
    }
}

#[test]
fn aovs_are_float_exr_beside_the_png() {
    let dir = tempfile::tempdir().unwrap();
    // Large enough that the height maps are not minified past the LOD threshold (where the
    // LOD system stops tracing and fetches drop to 0).
    let out =
        pomkit(&["render", "--size", "320x180", "-o", "f.png", "--aov", "uv,depth,shadow,fetches,lod"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
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
    assert!(covered > 320 * 180 / 3 && fetched > covered / 2, "covered {covered}, fetched {fetched}");
    assert!(dir.path().join("f.lod.exr").exists());
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
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("small.toml"), SMALL_SCENE).unwrap();
    let args = ["render", "small.toml", "--size", "96x64", "--compare", "normal,pom,displaced", "-o", "sheet.png"];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
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
        (vec!["render", "--technique", "cone", "-o", "x.png"], "cone"),
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
            let out = pomkit(&["render", path.to_str().unwrap(), "--size", "48x27", "-o", "e.png"], dir.path());
            assert!(out.status.success(), "{}: {}", path.display(), stderr(&out));
            n += 1;
        }
    }
    assert!(n > 0, "no example scenes found");
}

#[test]
fn lod_tint_changes_the_picture() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        ["render", "--size", "80x45", "-o", "plain.png", ""],
        ["render", "--size", "80x45", "-o", "tint.png", "--lod-tint"],
    ] {
        let args: Vec<&str> = args.into_iter().filter(|a| !a.is_empty()).collect();
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let a = image::open(dir.path().join("plain.png")).unwrap().to_rgb8();
    let b = image::open(dir.path().join("tint.png")).unwrap().to_rgb8();
    let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(changed > (80 * 45) / 4, "the tint should recolour the textured surfaces: {changed}");
}
