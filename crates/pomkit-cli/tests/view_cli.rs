//! `pomkit view` end to end: the real window under Xvfb, screenshots of two techniques, and
//! the viewer's "Export" reproduced by `pomkit render`.
//!
//! The window tests need an X display: the test uses `$DISPLAY` when set, else starts Xvfb
//! through `xvfb-run` (CI installs it, `apt-get install -y xvfb`). The viewer renders on a GPU
//! adapter, Mesa's lavapipe included. Without a display or an adapter the tests print
//! "skipping: <reason>" and pass, unless `POMKIT_REQUIRE_GPU=1`, where they fail.

// The viewer is the CLI's `view` feature (on by default).
#![cfg(feature = "view")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use pomkit_core::glam::Vec3;
use pomkit_viewer::doc::SceneDoc;
use pomkit_viewer::view::{ViewRenderer, ViewRequest, export};

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A command that runs `pomkit ARGS` with an X display: directly when `$DISPLAY` is set, else
/// under `xvfb-run`. `None` (after "skipping") when there is neither.
fn with_display(args: &[&str], data_home: &Path) -> Option<Command> {
    let exe = env!("CARGO_BIN_EXE_pomkit");
    let mut cmd = if std::env::var_os("DISPLAY").is_some() {
        let mut c = Command::new(exe);
        c.args(args);
        c
    } else if Command::new("xvfb-run").arg("--help").output().is_ok() {
        let mut c = Command::new("xvfb-run");
        c.args(["-a", "-s", "-screen 0 1280x800x24", exe]).args(args);
        c
    } else {
        pomkit_gpu::context::skip_without_gpu(&"no X display: DISPLAY is unset and xvfb-run is not installed");
        return None;
    };
    // Keep the viewer's saved settings out of the user's home.
    cmd.env("XDG_DATA_HOME", data_home).env_remove("WAYLAND_DISPLAY");
    Some(cmd)
}

fn gpu_available() -> bool {
    match pomkit_gpu::GpuContext::new() {
        Ok(_) => true,
        Err(e) => {
            pomkit_gpu::context::skip_without_gpu(&e);
            false
        }
    }
}

/// The default viewer scene with the technique and shadows set, written to `dir/name`.
fn scene_file(dir: &Path, name: &str, technique: &str, shadow: &str) -> PathBuf {
    let mut doc = SceneDoc::default();
    doc.set_material_field("technique", Some(toml::Value::String(technique.into())));
    doc.set_material_field("shadow", Some(toml::Value::String(shadow.into())));
    let path = dir.join(name);
    std::fs::write(&path, doc.to_toml()).expect("scene written");
    path
}

fn luma(img: &image::RgbImage, x: u32, y: u32) -> f64 {
    let p = img.get_pixel(x, y);
    0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
}

/// The central part of the 3D view in a 1280x800 screenshot (right of the 330-point panel,
/// clear of the figures drawn in the view's corners).
const VIEW: (std::ops::Range<u32>, std::ops::Range<u32>) = (520..1180, 120..660);

#[test]
fn screenshots_show_the_surface_and_differ_between_techniques() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut shots = Vec::new();
    for (technique, shadow) in [("flat", "none"), ("pom", "soft")] {
        let scene = scene_file(dir.path(), &format!("{technique}.toml"), technique, shadow);
        let png = dir.path().join(format!("{technique}.png"));
        let args = ["view", scene.to_str().unwrap(), "--screenshot", png.to_str().unwrap()];
        let Some(mut cmd) = with_display(&args, dir.path()) else { return };
        let out = cmd.output().expect("the viewer runs");
        assert!(out.status.success(), "pomkit view {technique} failed:\n{}", stderr(&out));
        let img = image::open(&png).expect("a PNG").to_rgb8();
        assert_eq!(img.dimensions(), (1280, 800), "the whole window");
        shots.push(img);
    }

    // Not blank: the view has texture (brick edges, mortar), not one colour.
    for (img, name) in shots.iter().zip(["flat", "pom"]) {
        let values: Vec<f64> =
            VIEW.1.clone().flat_map(|y| VIEW.0.clone().map(move |x| (x, y))).map(|(x, y)| luma(img, x, y)).collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64).sqrt();
        assert!(mean > 30.0 && sd > 12.0, "{name}: the view looks blank (mean luma {mean:.1}, sd {sd:.1})");
    }
    // The techniques differ where the relief is: many pixels change by a visible amount.
    let (a, b) = (&shots[0], &shots[1]);
    let mut differing = 0usize;
    let mut total = 0usize;
    for y in VIEW.1.clone() {
        for x in VIEW.0.clone() {
            total += 1;
            if (luma(a, x, y) - luma(b, x, y)).abs() > 16.0 {
                differing += 1;
            }
        }
    }
    let share = differing as f64 / total as f64;
    assert!(share > 0.05, "flat and pom screenshots barely differ: {:.2}% of the view", share * 100.0);
    // The panel is the same in both (only the technique combo and greyed controls change).
    let panel_diff = (0..300u32)
        .flat_map(|x| (200..400u32).map(move |y| (x, y)))
        .filter(|&(x, y)| a.get_pixel(x, y) != b.get_pixel(x, y))
        .count();
    assert!(panel_diff < 300 * 200 / 2, "the side panel changed too much: {panel_diff} pixels");
}

#[test]
fn exported_scene_renders_the_viewers_picture() {
    if !gpu_available() {
        return;
    }
    // A user's session: another mesh, technique, depth, samples, camera and light.
    let mut doc = SceneDoc::default();
    doc.set_mesh("sphere");
    doc.set_object_field("uv_repeat", Some(toml::Value::Array(vec![toml::Value::Float(4.0), toml::Value::Float(2.0)])));
    doc.set_material_field("technique", Some(toml::Value::String("relief".into())));
    doc.set_material_field("depth_scale", Some(toml::Value::Float(0.045)));
    doc.set_material_field("samples", Some(toml::Value::Integer(24)));
    doc.set_material_field("shadow", Some(toml::Value::String("hard".into())));
    doc.set_camera(Vec3::new(1.6, 1.1, 2.2), Vec3::new(0.0, 0.1, 0.0));
    doc.set_light_direction(Vec3::new(0.7, 0.5, 0.2));
    let (w, h) = (320u32, 240u32);

    // What the viewer's render thread draws for this saved session.
    let ctx = pomkit_gpu::GpuContext::new().expect("adapter");
    let mut renderer = ViewRenderer::new(ctx);
    let req = ViewRequest::new(doc.clone(), w, h);
    let result = renderer.render(&req);
    let images = result.images.expect("the view renders");
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("session.png");
    let toml_path = export(&doc, &images[0], &png, None).expect("export");
    assert_eq!(toml_path, dir.path().join("session.toml"));
    let text = std::fs::read_to_string(&toml_path).unwrap();
    assert!(text.contains(&format!("--size {w}x{h}")), "the header gives the size:\n{text}");

    // `pomkit render` on the exported scene, from another folder, on both renderers.
    let elsewhere = tempfile::tempdir().unwrap();
    let viewer = image::open(&png).unwrap().to_rgb8();
    for (backend, min_db) in [("gpu", 50.0), ("cpu", 38.0)] {
        let out_png = elsewhere.path().join(format!("{backend}.png"));
        let size = format!("{w}x{h}");
        let out = Command::new(env!("CARGO_BIN_EXE_pomkit"))
            .args(["render", toml_path.to_str().unwrap(), "--size", &size, "--backend", backend, "-o"])
            .arg(&out_png)
            .current_dir(elsewhere.path())
            .output()
            .unwrap();
        assert!(out.status.success(), "render --backend {backend} failed:\n{}", stderr(&out));
        let rendered = image::open(&out_png).unwrap().to_rgb8();
        assert_eq!(rendered.dimensions(), viewer.dimensions());
        let psnr = pomkit_core::compose::psnr(rendered.as_raw(), viewer.as_raw(), 255.0);
        assert!(
            psnr >= min_db,
            "{backend}: exported scene renders at {psnr:.1} dB from the viewer's view (< {min_db})"
        );
    }

    // And the export is not trivially equal to any render: a different technique differs.
    let mut other = doc.clone();
    other.set_material_field("technique", Some(toml::Value::String("flat".into())));
    let flat = renderer.render(&ViewRequest { doc: other, ..req });
    let flat = flat.images.expect("renders");
    let differing = flat[0].rgba.chunks(4).zip(images[0].rgba.chunks(4)).filter(|(a, b)| a[..3] != b[..3]).count();
    assert!(differing > (w * h / 20) as usize, "flat and relief should differ ({differing} pixels)");
}

#[test]
fn bad_scene_and_output_fail_before_opening_a_window() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[camera]\neye = [0, 1, 2]\ntarget = [0, 0, 0]\n[[material]]\nname = \"m\"\ndepth_scale = -1\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(["view", bad.to_str().unwrap(), "--screenshot", "x.png"])
        .current_dir(dir.path())
        .env_remove("DISPLAY")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("bad.toml") && err.contains("depth_scale"), "names the file and the field:\n{err}");
    assert!(!dir.path().join("x.png").exists());

    let good = scene_file(dir.path(), "good.toml", "pom", "none");
    let out = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(["view", good.to_str().unwrap(), "--screenshot", "no/such/folder/x.png"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("no/such/folder"), "names the output:\n{}", stderr(&out));

    let missing = Command::new(env!("CARGO_BIN_EXE_pomkit"))
        .args(["view", "nowhere.toml"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!missing.status.success());
    assert!(stderr(&missing).contains("nowhere.toml"), "{}", stderr(&missing));
}

/// Runs `script` (sh) on a fresh Xvfb display with `xdotool` to drive the window. `None` (after
/// "skipping") without xvfb-run or xdotool.
fn xvfb_script(script: &str, data_home: &Path) -> Option<Output> {
    for tool in ["xvfb-run", "xdotool"] {
        if Command::new(tool).arg("--help").output().is_err() {
            pomkit_gpu::context::skip_without_gpu(&format!("{tool} is not installed"));
            return None;
        }
    }
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x800x24", "sh", "-c", script])
        .env("XDG_DATA_HOME", data_home)
        .env("POMKIT", env!("CARGO_BIN_EXE_pomkit"))
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("xvfb-run runs");
    Some(out)
}

/// A shell script that starts `pomkit view FLAGS` on the display, waits for its window, focuses
/// it (the first click after focusing is swallowed, so it clicks once harmlessly), runs
/// `actions` (xdotool commands) and quits with ctrl+Q, which saves the session.
fn viewer_session(flags: &str, actions: &str) -> String {
    format!(
        r#"
        "$POMKIT" view {flags} &
        pid=$!
        win=$(xdotool search --sync --name "pomkit view" | head -1)
        sleep 3
        xdotool windowfocus --sync "$win"
        xdotool mousemove 700 300 click 1
        sleep 0.5
        {actions}
        xdotool key ctrl+q
        wait $pid
        "#
    )
}

/// The saved camera's eye, read from eframe's storage file.
fn saved_eye(data_home: &Path) -> (Vec3, String) {
    let text = std::fs::read_to_string(data_home.join("pomkit-viewer/app.ron")).expect("the session was saved");
    let at = text.find("eye = [").expect("a camera in the saved scene") + "eye = [".len();
    let end = at + text[at..].find(']').unwrap();
    let v: Vec<f32> = text[at..end].split(',').map(|s| s.trim().parse().unwrap()).collect();
    (Vec3::new(v[0], v[1], v[2]), text)
}

#[test]
fn the_camera_and_view_settings_are_saved_and_restored_between_runs() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // First run: a split view against steep; orbit the camera by dragging right (left of the
    // divider, which sits mid-view); quit.
    let first = viewer_session(
        "--compare steep",
        r#"xdotool mousemove 560 400 mousedown 1
        for i in 1 2 3 4 5 6 7 8 9 10 11 12; do xdotool mousemove $((560 + i * 10)) 400; sleep 0.05; done
        xdotool mouseup 1
        sleep 1"#,
    );
    let Some(out) = xvfb_script(&first, dir.path()) else { return };
    assert!(out.status.success(), "first run failed:\n{}", stderr(&out));
    let (eye, text) = saved_eye(dir.path());
    let (default_eye, _) = SceneDoc::default().camera();
    assert!(eye.x.abs() > 0.2, "dragging orbits the camera sideways: eye {eye} (default {default_eye})");
    assert!((eye.length() - default_eye.length()).abs() < 0.01, "orbiting keeps the distance: {eye}");
    assert!(text.contains("compare:true") && text.contains("steep"), "the split view is saved:\n{text}");

    // Second run, no flags: quit at once. The restored session is saved again unchanged (a
    // viewer that forgot it would save the default camera and no split).
    let second = viewer_session("", "");
    let Some(out) = xvfb_script(&second, dir.path()) else { return };
    assert!(out.status.success(), "second run failed:\n{}", stderr(&out));
    let (again, text) = saved_eye(dir.path());
    assert!((again - eye).length() < 1e-4, "restored camera {again}, saved {eye}");
    assert!(text.contains("compare:true") && text.contains("steep"), "restored view settings:\n{text}");
}
