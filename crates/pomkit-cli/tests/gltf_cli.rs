//! `pomkit render FILE.gltf`: glTF files made by `pomkit_io::gltf::write_sample`, rendered from
//! the file alone and checked against the `displaced` truth of the same file, and bad glTF
//! input refused cleanly.

mod support;

use std::path::{Path, PathBuf};

use pomkit_core::glam::Vec3;
use pomkit_io::gltf::{SampleCamera, SampleDisplacement, SampleLight, SampleOptions, write_sample};
use support::{pomkit, stderr};

/// A grazing view of the sample plane, lit from the side.
fn grazing(displacement: Option<SampleDisplacement>) -> SampleOptions {
    SampleOptions {
        displacement,
        camera: Some(SampleCamera {
            eye: Vec3::new(0.0, 0.7, 2.0),
            target: Vec3::new(0.0, 0.0, -0.2),
            yfov_deg: 40.0,
            ..SampleCamera::default()
        }),
        lights: vec![SampleLight::Directional { toward: Vec3::new(-1.0, 0.6, 0.3), color: Vec3::ONE, intensity: 1.0 }],
        ..SampleOptions::default()
    }
}

fn render(dir: &Path, file: &Path, out: &str, extra: &[&str]) -> Vec<u8> {
    let mut args = vec!["render", file.to_str().unwrap(), "-o", out, "--backend", "cpu", "--size", "160x120"];
    args.extend_from_slice(extra);
    let o = pomkit(&args, dir);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    image::open(dir.join(out)).unwrap().to_rgb8().into_raw()
}

/// Mean absolute difference per channel, in 0..255.
fn mad(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(&x, &y)| f64::from(x.abs_diff(y))).sum::<f64>() / a.len() as f64
}

#[test]
fn a_displaced_material_is_traced_from_the_file_alone_and_looks_like_its_displaced_truth() {
    let dir = tempfile::tempdir().unwrap();
    let file = write_sample(dir.path(), &grazing(Some(SampleDisplacement { factor: 0.2, offset: -0.2 }))).unwrap();
    let traced = render(dir.path(), &file, "traced.png", &[]);
    let truth = render(dir.path(), &file, "truth.png", &["--technique", "displaced"]);
    let normal = render(dir.path(), &file, "normal.png", &["--technique", "normal"]);
    let (d_traced, d_normal) = (mad(&traced, &truth), mad(&normal, &truth));
    eprintln!("mean absolute difference from displaced: traced {d_traced:.2}, normal mapping {d_normal:.2}");
    // The relief shows (normal mapping is far from the truth) and the trace follows it.
    assert!(d_normal > 4.0, "normal mapping is {d_normal:.2} from the truth: the view shows no relief");
    assert!(d_traced < 0.6 * d_normal, "traced {d_traced:.2} vs normal {d_normal:.2}");
}

#[test]
fn without_the_extension_the_file_renders_as_normal_mapping() {
    let dir = tempfile::tempdir().unwrap();
    let file = write_sample(dir.path(), &grazing(None)).unwrap();
    let plain = render(dir.path(), &file, "plain.png", &[]);
    let normal = render(dir.path(), &file, "normal.png", &["--technique", "normal"]);
    assert_eq!(mad(&plain, &normal), 0.0);
}

#[test]
fn extras_choose_the_technique() {
    let dir = tempfile::tempdir().unwrap();
    let extras = serde_json::json!({ "pomkit": { "technique": "flat" } });
    let file = write_sample(
        dir.path(),
        &SampleOptions { extras: Some(extras), ..grazing(Some(SampleDisplacement { factor: 0.2, offset: -0.2 })) },
    )
    .unwrap();
    let own = render(dir.path(), &file, "own.png", &[]);
    let flat = render(dir.path(), &file, "flat.png", &["--technique", "flat"]);
    let pom = render(dir.path(), &file, "pom.png", &["--technique", "pom"]);
    assert_eq!(mad(&own, &flat), 0.0);
    assert!(mad(&own, &pom) > 1.0);
}

/// Mean brightness of the left and right halves of the picture.
fn halves(rgb: &[u8], w: usize) -> (f64, f64) {
    let (mut l, mut r) = (0.0, 0.0);
    for (i, px) in rgb.chunks_exact(3).enumerate() {
        let v: f64 = px.iter().map(|&c| f64::from(c)).sum();
        if i % w < w / 2 { l += v } else { r += v }
    }
    (l, r)
}

#[test]
fn the_file_camera_node_transform_and_point_light_are_used() {
    let dir = tempfile::tempdir().unwrap();
    let lit = |x: f32, name: &str| -> PathBuf {
        let opts = SampleOptions {
            name: name.into(),
            displacement: None,
            normal_texture: false,
            // The plane moved down by 1 and seen from straight above: it fills the view only
            // when both the node's translation and the camera are applied.
            translation: Vec3::new(0.0, -1.0, 0.0),
            camera: Some(SampleCamera {
                eye: Vec3::new(0.0, 1.0, 0.001),
                target: Vec3::new(0.0, -1.0, 0.0),
                yfov_deg: 40.0,
                ..SampleCamera::default()
            }),
            lights: vec![SampleLight::Point { position: Vec3::new(x, -0.7, 0.0), color: Vec3::ONE, intensity: 0.5 }],
            ..SampleOptions::default()
        };
        write_sample(dir.path(), &opts).unwrap()
    };
    let left = render(dir.path(), &lit(-0.9, "left"), "left.png", &[]);
    let right = render(dir.path(), &lit(0.9, "right"), "right.png", &[]);
    let (ll, lr) = halves(&left, 160);
    let (rl, rr) = halves(&right, 160);
    assert!(ll > 1.3 * lr, "a light on the left lights the left: {ll} vs {lr}");
    assert!(rr > 1.3 * rl, "a light on the right lights the right: {rr} vs {rl}");
    // The whole frame is the plane (no background pixel at the corners).
    let o = pomkit(&["render", "left.gltf", "-o", "c.png", "--backend", "cpu", "--size", "64x48"], dir.path());
    assert!(stderr(&o).contains("3072 of 3072 pixels covered"), "{}", stderr(&o));
}

/// A change made to a glTF file's JSON.
type Edit = Box<dyn Fn(&mut serde_json::Value)>;

#[test]
fn bad_gltf_input_fails_naming_the_file_and_item_with_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let file = write_sample(dir.path(), &SampleOptions::default()).unwrap();
    let original = std::fs::read(&file).unwrap();
    let edit = |change: &dyn Fn(&mut serde_json::Value)| {
        let mut json: serde_json::Value = serde_json::from_slice(&original).unwrap();
        change(&mut json);
        std::fs::write(&file, serde_json::to_vec(&json).unwrap()).unwrap();
    };
    const EXT: &str = "KHR_materials_displacement";
    let cases: Vec<(Edit, Vec<&str>)> = vec![
        (Box::new(|j| j["images"][1]["uri"] = "missing.png".into()), vec!["normalTexture", "missing.png"]),
        (Box::new(|j| j["buffers"][0]["uri"] = "missing.bin".into()), vec!["missing.bin"]),
        (
            Box::new(|j| j["images"][2]["uri"] = "sample.bin".into()),
            vec!["material 0 'Bricks'", "displacementGeometryTexture", "sample.bin"],
        ),
        (
            Box::new(|j| j["materials"][0]["extensions"][EXT]["displacementGeometryFactor"] = (-1.0).into()),
            vec!["material 0 'Bricks'", "displacementGeometryFactor is -1"],
        ),
        (
            Box::new(|j| j["materials"][0]["extensions"][EXT]["displacementGeometryFactor"] = "NaN".into()),
            vec!["material 0 'Bricks'", "displacementGeometryFactor"],
        ),
        (
            Box::new(|j| {
                j["cameras"] = serde_json::json!([{ "type": "perspective", "perspective": { "yfov": 0.8, "znear": 0.1, "aspectRatio": 0 } }]);
                j["nodes"].as_array_mut().unwrap().push(serde_json::json!({ "camera": 0 }));
                j["scenes"][0]["nodes"].as_array_mut().unwrap().push(1.into());
            }),
            vec!["camera 0", "aspectRatio is 0"],
        ),
    ];
    for (change, expected) in cases {
        edit(&*change);
        let o = pomkit(&["render", "sample.gltf", "-o", "out.png", "--backend", "cpu", "--size", "32x32"], dir.path());
        let e = stderr(&o);
        assert!(!o.status.success(), "{e}");
        assert!(e.contains("sample.gltf") && !e.contains("panicked"), "{e}");
        for x in expected {
            assert!(e.contains(x), "{x}: {e}");
        }
        assert!(!dir.path().join("out.png").exists());
    }
    // The output may not be one of the file's inputs.
    std::fs::write(&file, &original).unwrap();
    let before = std::fs::read(dir.path().join("sample_albedo.png")).unwrap();
    let o = pomkit(&["render", "sample.gltf", "-o", "sample_albedo.png", "--backend", "cpu"], dir.path());
    assert!(!o.status.success());
    assert_eq!(std::fs::read(dir.path().join("sample_albedo.png")).unwrap(), before);
}

fn json_of(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn attach_round_trips_a_gltf_into_another_folder_and_render_traces_it() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("in")).unwrap();
    std::fs::create_dir(dir.path().join("out")).unwrap();
    let plain = SampleOptions { name: "plain".into(), ..grazing(None) };
    write_sample(&dir.path().join("in"), &plain).unwrap();
    let o = pomkit(
        &["gltf", "attach", "in/plain.gltf", "--height", "builtin:bricks:64x64", "--depth", "0.2", "-o", "out/a.gltf"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let json = json_of(&dir.path().join("out/a.gltf"));
    let ext = &json["materials"][0]["extensions"]["KHR_materials_displacement"];
    assert_eq!(ext["displacementGeometryFactor"].as_f64().unwrap() as f32, 0.2);
    assert_eq!(ext["displacementGeometryOffset"].as_f64().unwrap() as f32, -0.2);
    assert!(json["extensionsUsed"].as_array().unwrap().iter().any(|e| e == "KHR_materials_displacement"));
    assert!(json.get("extensionsRequired").is_none());
    assert_eq!(json["buffers"][0]["uri"], "../in/plain.bin");
    assert!(dir.path().join("out/a_height.png").exists());
    // The scene of the output: traced at depth 0.2 over a UV unit of 2, the built-in heights.
    let scene = pomkit_io::load_scene(&dir.path().join("out/a.gltf")).unwrap();
    let m = &scene.materials[0];
    assert!((m.depth_scale - 0.1).abs() < 1e-6, "{}", m.depth_scale);
    let truth = pomkit_core::procedural::generate(pomkit_core::procedural::Pattern::Bricks, 64, 64);
    for (a, b) in m.height.as_ref().unwrap().heights().iter().zip(truth.heights()) {
        assert!((a - b).abs() <= 1.0 / 65535.0, "{a} vs {b}");
    }
    // It renders as the same plane written with the extension in the first place.
    let attached = render(dir.path(), &dir.path().join("out/a.gltf"), "attached.png", &[]);
    let made = write_sample(dir.path(), &grazing(Some(SampleDisplacement { factor: 0.2, offset: -0.2 }))).unwrap();
    let direct = render(dir.path(), &made, "direct.png", &[]);
    let normal = render(dir.path(), &made, "normal.png", &["--technique", "normal"]);
    let (same, apart) = (mad(&attached, &direct), mad(&normal, &direct));
    assert!(same < 0.2 * apart, "attached vs direct {same:.3}, normal vs direct {apart:.3}");
}

#[test]
fn attach_writes_a_glb_with_the_image_inside_and_converts_depth_scale() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SampleOptions { name: "plain".into(), binary: true, displacement: None, ..SampleOptions::default() };
    write_sample(dir.path(), &opts).unwrap();
    let o = pomkit(
        &["gltf", "attach", "plain.glb", "--height", "builtin:waves:32x32", "--depth-scale", "0.05", "-o", "b.glb"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    names.sort();
    assert_eq!(names, ["b.glb", "plain.glb"]);
    let scene = pomkit_io::load_scene(&dir.path().join("b.glb")).unwrap();
    // 0.05 UV units over a UV unit of 2: a factor of 0.1, back to 0.05.
    assert!((scene.materials[0].depth_scale - 0.05).abs() < 1e-6);
    assert_eq!(scene.materials[0].height.as_ref().unwrap().width(), 32);
    assert!(stderr(&o).contains("factor 0.1"), "{}", stderr(&o));
}

#[test]
fn attach_refuses_bad_input_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    write_sample(dir.path(), &SampleOptions { displacement: None, ..SampleOptions::default() }).unwrap();
    let before = std::fs::read(dir.path().join("sample.gltf")).unwrap();
    let h = ["--height", "builtin:bricks:16x16"];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--depth", "0.1", "-o", "sample.gltf"], "sample.gltf"),
        (vec!["--depth", "0.1", "-o", "x.glb"], "format"),
        (vec!["--depth=-1", "-o", "x.gltf"], "--depth"),
        (vec!["--depth", "NaN", "-o", "x.gltf"], "--depth"),
        (vec!["-o", "x.gltf"], "--depth"),
        (vec!["--depth", "0.1", "--material", "Stone", "-o", "x.gltf"], "\"Stone\""),
        (vec!["--depth", "0.1", "--material", "3", "-o", "x.gltf"], "material 3"),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["gltf", "attach", "sample.gltf"];
        args.extend_from_slice(&h);
        args.extend_from_slice(&extra);
        let o = pomkit(&args, dir.path());
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains(expected) && !e.contains("panicked"), "{args:?}: {e}");
        assert!(!dir.path().join("x.gltf").exists() && !dir.path().join("x_height.png").exists());
    }
    // The height image beside the output may not overwrite the height map read.
    std::fs::copy(dir.path().join("sample_albedo.png"), dir.path().join("y_height.png")).unwrap();
    let h_before = std::fs::read(dir.path().join("y_height.png")).unwrap();
    let o = pomkit(
        &["gltf", "attach", "sample.gltf", "--height", "y_height.png", "--depth", "0.1", "-o", "y.gltf"],
        dir.path(),
    );
    assert!(!o.status.success() && stderr(&o).contains("y_height.png"), "{}", stderr(&o));
    assert_eq!(std::fs::read(dir.path().join("y_height.png")).unwrap(), h_before);
    assert!(!dir.path().join("y.gltf").exists());
    let o = pomkit(
        &["gltf", "attach", "sample.gltf", "--height", "sample_albedo.png", "--depth", "0.1", "-o", "x.gltf"],
        dir.path(),
    );
    assert!(o.status.success(), "a file's own image may be the height: {}", stderr(&o));
    assert_eq!(std::fs::read(dir.path().join("sample.gltf")).unwrap(), before);
}
