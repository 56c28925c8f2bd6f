//! `pomkit render --material DIR`: a texture-library folder drawn on the preview scene, against
//! a scene file that names the same maps one by one (another path through the loader); a
//! DirectX normal map against its OpenGL twin; the maps listed; outputs onto a map refused.

mod support;

use std::path::Path;

use support::{pomkit, refuses, stderr};

const N: u32 = 64;

/// Height: rounded bumps, one per 16 texels (relief that parallax shows).
fn height_image() -> image::GrayImage {
    image::GrayImage::from_fn(N, N, |x, y| {
        let f = |t: u32| (std::f32::consts::TAU * t as f32 / 16.0).sin();
        image::Luma([(127.5 + 110.0 * f(x) * f(y)) as u8])
    })
}

fn color_image() -> image::RgbImage {
    image::RgbImage::from_fn(N, N, |x, y| image::Rgb([(60 + x * 3) as u8, (40 + y * 3) as u8, 120]))
}

/// An OpenGL normal map with a strong, varying green (not derived from the height: any valid
/// map serves to compare the two conventions).
fn normal_gl_image() -> image::RgbImage {
    image::RgbImage::from_fn(N, N, |x, y| {
        let a = std::f32::consts::TAU * x as f32 / 32.0;
        let b = std::f32::consts::TAU * y as f32 / 24.0;
        let (nx, ny) = (0.35 * a.cos(), 0.55 * b.sin());
        let nz = (1.0 - nx * nx - ny * ny).sqrt();
        let enc = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
        image::Rgb([enc(nx), enc(ny), enc(nz)])
    })
}

fn flip_green(img: &image::RgbImage) -> image::RgbImage {
    let mut out = img.clone();
    for p in out.pixels_mut() {
        p.0[1] = 255 - p.0[1];
    }
    out
}

/// An ambientCG-style folder `dir/name`, its normal map `normal` saved as `_NormalGL` or
/// `_NormalDX` (`dx`); roughness 128 of 255 everywhere.
fn folder(dir: &Path, name: &str, normal: &image::RgbImage, dx: bool) -> std::path::PathBuf {
    let d = dir.join(name);
    std::fs::create_dir_all(&d).unwrap();
    color_image().save(d.join("Bricks_1K_Color.png")).unwrap();
    height_image().save(d.join("Bricks_1K_Displacement.png")).unwrap();
    normal.save(d.join(if dx { "Bricks_1K_NormalDX.png" } else { "Bricks_1K_NormalGL.png" })).unwrap();
    image::GrayImage::from_pixel(N, N, image::Luma([128])).save(d.join("Bricks_1K_Roughness.png")).unwrap();
    image::GrayImage::from_pixel(N, N, image::Luma([230])).save(d.join("Bricks_1K_AmbientOcclusion.png")).unwrap();
    std::fs::write(d.join("Bricks_1K.mtlx"), "<materialx/>").unwrap();
    d
}

fn render(args: &[&str], dir: &Path) -> image::RgbImage {
    let mut all = vec!["render", "--backend", "cpu", "--size", "160x96"];
    all.extend_from_slice(args);
    let out = pomkit(&all, dir);
    assert!(out.status.success(), "{all:?}: {}", stderr(&out));
    let png = all.iter().position(|a| *a == "-o").map_or("pomkit.png", |i| all[i + 1]);
    image::open(dir.join(png)).unwrap().to_rgb8()
}

/// Pixels differing by more than `tolerance` in some channel, and the largest difference.
fn differ(a: &image::RgbImage, b: &image::RgbImage, tolerance: u8) -> (usize, u8) {
    assert_eq!(a.dimensions(), b.dimensions());
    let mut count = 0;
    let mut worst = 0u8;
    for (p, q) in a.pixels().zip(b.pixels()) {
        let d = (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap();
        worst = worst.max(d);
        if d > tolerance {
            count += 1;
        }
    }
    (count, worst)
}

#[test]
fn render_material_equals_a_scene_naming_the_maps_one_by_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let lib = folder(dir, "Bricks", &normal_gl_image(), false);
    let out = pomkit(&["render", "--backend", "cpu", "--size", "160x96", "--material", "Bricks", "-o", "a.png"], dir);
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    // The maps, one line each, before the render.
    for line in [
        "colour: Bricks_1K_Color.png",
        "normal: Bricks_1K_NormalGL.png (OpenGL, +Y up)",
        "height: Bricks_1K_Displacement.png",
        "roughness: Bricks_1K_Roughness.png",
        "ambient occlusion: Bricks_1K_AmbientOcclusion.png (found, unused",
        "ignored: Bricks_1K.mtlx (not an image pomkit reads",
    ] {
        assert!(log.contains(line), "{line:?} not in: {log}");
    }
    assert!(log.find("colour:").unwrap() < log.find("wrote a.png").unwrap());

    // The same scene, the maps named one by one, shininess from the Beckmann-Phong relation
    // for roughness 128/255 worked out here.
    let r = 128.0f64 / 255.0;
    let shininess = 2.0 / (r * r).powi(2) - 2.0;
    // The lobe normalized to a dielectric's 4%: 0.04 * (n + 8) / 8.
    let specular = 0.04 * (shininess + 8.0) / 8.0;
    let preview = pomkit_io::library::preview_scene(Path::new("Bricks"));
    let folder_line = preview.lines().find(|l| l.starts_with("folder = ")).unwrap();
    let named = preview.replace(
        folder_line,
        &format!(
            "albedo = \"Bricks/Bricks_1K_Color.png\"\nnormal = \"Bricks/Bricks_1K_NormalGL.png\"\n\
             height = \"Bricks/Bricks_1K_Displacement.png\"\nshininess = {shininess}\nspecular = {specular}"
        ),
    );
    assert_ne!(named, preview);
    std::fs::write(dir.join("named.toml"), &named).unwrap();
    let a = image::open(dir.join("a.png")).unwrap().to_rgb8();
    let b = render(&["named.toml", "-o", "b.png"], dir);
    assert_eq!(differ(&a, &b, 0), (0, 0), "render --material and the scene naming its maps differ");

    // The picture shows the maps: without the height map's relief (flat) it is another one.
    let flat = render(&["--material", "Bricks", "--technique", "flat", "-o", "flat.png"], dir);
    let (count, _) = differ(&a, &flat, 8);
    assert!(count > 1000, "only {count} pixels differ from flat shading");
    assert!(lib.join("Bricks_1K_Color.png").exists());
}

#[test]
fn a_directx_normal_map_renders_as_its_opengl_twin() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let gl = normal_gl_image();
    folder(dir, "gl", &gl, false);
    folder(dir, "dx", &flip_green(&gl), true);
    // The DX map saved under an OpenGL name: read without the flip.
    folder(dir, "wrong", &flip_green(&gl), false);
    let a = render(&["--material", "gl", "--technique", "normal", "-o", "gl.png"], dir);
    let out = pomkit(
        &[
            "render",
            "--backend",
            "cpu",
            "--size",
            "160x96",
            "--material",
            "dx",
            "--technique",
            "normal",
            "-o",
            "dx.png",
        ],
        dir,
    );
    assert!(stderr(&out).contains("normal: Bricks_1K_NormalDX.png (DirectX, +Y down"), "{}", stderr(&out));
    let b = image::open(dir.join("dx.png")).unwrap().to_rgb8();
    let c = render(&["--material", "wrong", "--technique", "normal", "-o", "wrong.png"], dir);
    // Flipping an 8-bit green is exact but for the last bit of f32 decoding.
    let (count, worst) = differ(&a, &b, 1);
    assert_eq!(count, 0, "{count} pixels differ, by up to {worst}");
    let (count, worst) = differ(&a, &c, 8);
    assert!(count > 500 && worst > 20, "the unflipped map should light differently: {count} pixels, {worst}");
}

#[test]
fn render_material_takes_the_other_flags() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    folder(dir, "Bricks", &normal_gl_image(), false);
    let out = pomkit(
        &[
            "render",
            "--backend",
            "cpu",
            "--size",
            "96x64",
            "--material",
            "Bricks",
            "--technique",
            "relief",
            "--aov",
            "depth",
            "--supersample",
            "2",
            "-o",
            "r.png",
        ],
        dir,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(image::image_dimensions(dir.join("r.png")).unwrap(), (96, 64));
    assert!(dir.join("r.depth.exr").exists());
}

#[test]
fn outputs_onto_a_folders_map_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    folder(dir, "Bricks", &normal_gl_image(), false);
    refuses(
        &["render", "--backend", "cpu", "--size", "32x32", "--material", "Bricks", "-o", "Bricks/Bricks_1K_Color.png"],
        dir,
        &["Bricks_1K_Color.png"],
    );
    // Through a scene file's `material = "FOLDER"` too, the ambient occlusion map included.
    std::fs::write(
        dir.join("s.toml"),
        "[camera]\neye = [0.0, 2.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"Bricks\"\n",
    )
    .unwrap();
    for map in ["Bricks/Bricks_1K_Roughness.png", "Bricks/Bricks_1K_AmbientOcclusion.png"] {
        refuses(&["render", "s.toml", "--backend", "cpu", "--size", "32x32", "-o", map], dir, &[map]);
    }
    // The scene file renders.
    let out = pomkit(&["render", "s.toml", "--backend", "cpu", "--size", "32x32", "-o", "s.png"], dir);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn bad_folders_and_a_scene_with_material_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    folder(dir, "Bricks", &normal_gl_image(), false);
    std::fs::create_dir(dir.join("empty")).unwrap();
    std::fs::write(dir.join("s.toml"), "").unwrap();
    let o = ["-o", "out.png", "--size", "32x32", "--backend", "cpu"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut a = vec!["render"];
        a.extend_from_slice(extra);
        a.extend_from_slice(&o);
        a
    };
    refuses(&with(&["--material", "missing"]), dir, &["--material", "missing", "no such folder"]);
    refuses(&with(&["--material", "s.toml"]), dir, &["s.toml", "not a folder"]);
    refuses(&with(&["--material", "empty"]), dir, &["empty", "has no texture maps"]);
    let out = refuses(&with(&["s.toml", "--material", "Bricks"]), dir, &["--material", "cannot be used with"]);
    assert_eq!(out.status.code(), Some(2), "a usage error");
    // No height map: the error lists what was found.
    std::fs::remove_file(dir.join("Bricks/Bricks_1K_Displacement.png")).unwrap();
    refuses(&with(&["--material", "Bricks"]), dir, &["no height map", "colour: Bricks_1K_Color.png"]);
}

/// Mean of the 8-bit channels over the middle of a picture (the plane fills it).
fn middle_mean(path: &Path) -> f64 {
    let img = image::open(path).unwrap().to_rgb8();
    let (w, h) = img.dimensions();
    let mut sum = 0.0;
    let mut n = 0.0;
    for y in h / 3..h * 9 / 10 {
        for x in w / 5..w * 4 / 5 {
            sum += img.get_pixel(x, y).0.iter().map(|&c| f64::from(c)).sum::<f64>();
            n += 3.0;
        }
    }
    sum / n
}

/// The repository's real library folder (ambientCG's Rocks011, assets/README.md): a JPEG normal
/// map with texels lossy compression turned slightly inward (once refused), both an OpenGL and
/// a DirectX map, and a rough surface whose highlight must not wash the picture out: with the
/// normalized lobe, the specular adds at most a third to the diffuse-only picture (the full
/// default strength with the roughness's broad lobe added two thirds).
#[test]
fn the_real_library_folder_renders_and_its_rough_surface_is_not_washed_out() {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/Rocks011");
    let dir = tempfile::tempdir().unwrap();
    let folder_arg = folder.to_str().unwrap();
    let args = ["render", "--material", folder_arg, "--backend", "cpu", "--size", "96x54", "-o", "lib.png"];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    for needle in [
        "colour: Rocks011_512_Color.jpg",
        "normal: Rocks011_512_NormalGL.jpg (OpenGL, +Y up)",
        "height: Rocks011_512_Displacement.png",
        "ignored: Rocks011_512_NormalDX.jpg",
    ] {
        assert!(err.contains(needle), "{needle:?} not in {err}");
    }
    // The same scene with the highlight off: the diffuse light alone.
    let scene = pomkit_io::library::preview_scene(&folder).replace(
        &format!("folder = {}", toml::Value::String(folder.to_string_lossy().into_owned())),
        &format!("folder = {}\nspecular = 0.0", toml::Value::String(folder.to_string_lossy().into_owned())),
    );
    assert!(scene.contains("specular = 0.0"), "{scene}");
    std::fs::write(dir.path().join("diffuse.toml"), scene).unwrap();
    let out =
        pomkit(&["render", "diffuse.toml", "--backend", "cpu", "--size", "96x54", "-o", "diffuse.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let (lit, diffuse) = (middle_mean(&dir.path().join("lib.png")), middle_mean(&dir.path().join("diffuse.png")));
    assert!(diffuse > 40.0, "the diffuse picture is dark: {diffuse}");
    assert!(lit > diffuse && lit < diffuse * 4.0 / 3.0, "with the highlight {lit}, without {diffuse}");
}
