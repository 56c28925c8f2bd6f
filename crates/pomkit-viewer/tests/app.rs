//! The whole viewer app in egui_kittest (no window): it renders on the GPU renderer's thread
//! and says which device; dragging in the view orbits the camera and ctrl-dragging moves the
//! light; dropped files land in the right slot; the split view renders both sides; Export
//! writes a PNG and a scene that loads back to the same document.
//!
//! Runs on any wgpu adapter, Mesa's lavapipe included; without one it prints "skipping" and
//! passes, unless `POMKIT_REQUIRE_GPU=1`.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use eframe::egui::{self, Pos2};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use pomkit_core::glam::Vec3;
use pomkit_viewer::ViewerApp;
use pomkit_viewer::doc::SceneDoc;

fn gpu_available() -> bool {
    match pomkit_gpu::GpuContext::new() {
        Ok(_) => true,
        Err(e) => {
            pomkit_gpu::context::skip_without_gpu(&e);
            false
        }
    }
}

/// The app in a 1100x700 harness, on `doc` (or the default scene).
fn harness(doc: Option<SceneDoc>) -> Harness<'static, ViewerApp> {
    harness_sized(doc, 700.0)
}

/// The app in a harness `height` points tall (tall enough, the whole panel is on screen).
fn harness_sized(doc: Option<SceneDoc>, height: f32) -> Harness<'static, ViewerApp> {
    let ctx = egui::Context::default();
    let app = ViewerApp::new(&eframe::CreationContext::_new_kittest(ctx), doc, None);
    Harness::builder().with_size((1100.0, height)).with_max_steps(1_000_000).build_ui_state(
        |ui, app: &mut ViewerApp| {
            let mut frame = eframe::Frame::_new_kittest();
            eframe::App::ui(app, ui, &mut frame);
        },
        app,
    )
}

/// Steps the UI (in real time, as the render thread works) until the view is complete.
fn settle(h: &mut Harness<'static, ViewerApp>) {
    let start = Instant::now();
    loop {
        h.step();
        if h.state().is_complete() {
            // One more frame so that the picture is on screen.
            h.step();
            return;
        }
        assert!(start.elapsed() < Duration::from_secs(180), "the view did not complete in 180 s");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A point inside the 3D view (right of the side panel, left of a centred split).
fn in_view() -> Pos2 {
    Pos2::new(560.0, 350.0)
}

fn drag(h: &mut Harness<'static, ViewerApp>, from: Pos2, by: egui::Vec2, modifiers: egui::Modifiers) {
    let press = |pressed: bool, pos: Pos2| egui::Event::PointerButton {
        pos,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers,
    };
    h.event(egui::Event::ModifiersChanged(modifiers));
    h.event(egui::Event::PointerMoved(from));
    h.step();
    h.event(press(true, from));
    h.step();
    for i in 1..=8 {
        h.event(egui::Event::PointerMoved(from + by * (i as f32 / 8.0)));
        h.step();
    }
    h.event(press(false, from + by));
    h.step();
    h.event(egui::Event::ModifiersChanged(egui::Modifiers::NONE));
    h.step();
}

#[derive(Debug)]
struct Dropped(PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &Path {
        &self.0
    }
    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

#[test]
fn renders_on_the_gpu_thread_and_names_the_device() {
    if !gpu_available() {
        return;
    }
    let mut h = harness(None);
    settle(&mut h);
    assert_eq!(h.state().error(), None);
    let stats = h.state().stats().to_vec();
    assert_eq!(stats.len(), 1);
    // The default scene's technique is the default one, exact.
    assert_eq!(stats[0].label, "exact");
    assert!(stats[0].covered > 10_000, "the plane covers the view: {stats:?}");
    assert!(stats[0].fetches_per_pixel > 4.0, "exact with soft shadows fetches: {stats:?}");
    assert!(stats[0].frame_ms > 0.0);
    let Some(Ok((name, software))) = h.state().device().cloned() else { panic!("a device") };
    assert!(h.query_by_label_contains(&format!("GPU: {name}")).is_some(), "the panel names the adapter");
    assert_eq!(
        h.query_by_label_contains("lavapipe").is_some(),
        software,
        "the window says so exactly when it renders in software"
    );
}

#[test]
fn dragging_orbits_the_camera_and_ctrl_dragging_moves_the_light() {
    if !gpu_available() {
        return;
    }
    let mut h = harness(None);
    settle(&mut h);
    let (eye0, target0) = h.state().doc().camera();
    drag(&mut h, in_view(), egui::vec2(120.0, 0.0), egui::Modifiers::NONE);
    let (eye1, target1) = h.state().doc().camera();
    assert_eq!(target1, target0, "orbiting keeps the target");
    assert!((eye1 - target1).length() - (eye0 - target0).length() < 1e-3, "and the distance");
    assert!(eye1.x < -0.3, "dragging right swings the eye to -x: {eye0} -> {eye1}");

    let light0 = h.state().doc().light_direction().expect("the default scene's sun");
    drag(&mut h, in_view(), egui::vec2(0.0, 60.0), egui::Modifiers::CTRL);
    let light1 = h.state().doc().light_direction().expect("still there");
    assert_eq!(h.state().doc().camera().0, eye1, "ctrl-drag leaves the camera alone");
    assert!(light1.y < light0.normalize().y - 0.1, "dragging down lowers the sun: {light0} -> {light1}");
    settle(&mut h);
    assert_eq!(h.state().error(), None);
}

#[test]
fn dropped_files_go_to_their_slots_and_render() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // A 32x32 height map of raised squares, named like a height map.
    let h32: Vec<u8> = (0..32 * 32).map(|i| if (i % 32) / 8 % 2 == (i / 32) / 8 % 2 { 230 } else { 40 }).collect();
    let height = dir.path().join("tiles_height.png");
    pomkit_io::write_image(&height, 32, 32, pomkit_io::PixelLayout::Gray8, pomkit_io::Pixels::U8(&h32)).unwrap();
    let albedo = dir.path().join("tiles_basecolor.png");
    let rgb: Vec<u8> = (0..32 * 32).flat_map(|_| [200u8, 120, 60]).collect();
    pomkit_io::write_image(&albedo, 32, 32, pomkit_io::PixelLayout::Rgb8, pomkit_io::Pixels::U8(&rgb)).unwrap();

    let mut h = harness(None);
    settle(&mut h);
    // Dropped over the 3D view (not over a slot): sorted by name.
    h.event(egui::Event::PointerMoved(in_view()));
    h.input_mut().dropped_files = vec![Arc::new(Dropped(height.clone())), Arc::new(Dropped(albedo.clone()))];
    h.step();
    let field = |h: &Harness<'static, ViewerApp>, k: &str| {
        h.state().doc().material_field(k).and_then(|v| v.as_str()).map(str::to_owned)
    };
    assert_eq!(field(&h, "height").as_deref(), height.to_str());
    assert_eq!(field(&h, "albedo").as_deref(), albedo.to_str());
    settle(&mut h);
    assert_eq!(h.state().error(), None, "the dropped maps load and render");

    // An image dropped onto the normal slot goes there whatever its name.
    let normal = dir.path().join("tiles_basecolor_copy.png");
    let flat_normal: Vec<u8> = (0..32 * 32).flat_map(|_| [128u8, 128, 255]).collect();
    pomkit_io::write_image(&normal, 32, 32, pomkit_io::PixelLayout::Rgb8, pomkit_io::Pixels::U8(&flat_normal)).unwrap();
    let slot = h.get_by_label_contains("baked from height").rect().center();
    h.event(egui::Event::PointerMoved(slot));
    h.input_mut().dropped_files = vec![Arc::new(Dropped(normal.clone()))];
    h.step();
    assert_eq!(field(&h, "normal").as_deref(), normal.to_str());

    // A scene file replaces the document.
    let scene = dir.path().join("other.toml");
    let mut doc = SceneDoc::default();
    doc.set_mesh("torus");
    std::fs::write(&scene, doc.to_toml()).unwrap();
    h.input_mut().dropped_files = vec![Arc::new(Dropped(scene))];
    h.step();
    assert_eq!(h.state().doc().mesh(), "torus");
    settle(&mut h);
    assert_eq!(h.state().error(), None);
}

#[test]
fn split_view_renders_both_techniques_and_export_writes_png_and_scene() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Tall enough for the whole side panel (Split view and Export are near its end).
    let mut h = harness_sized(None, 1800.0);
    settle(&mut h);
    h.get_by_label("Split view").click();
    h.step();
    settle(&mut h);
    let stats = h.state().stats().to_vec();
    assert_eq!(stats.iter().map(|s| s.label.as_str()).collect::<Vec<_>>(), ["exact", "relief"]);
    assert_ne!(stats[0].fetches_per_pixel, stats[1].fetches_per_pixel, "two different traces: {stats:?}");

    let png = dir.path().join("view.png");
    h.state_mut().settings_mut().export_path = png.to_string_lossy().into_owned();
    h.step();
    let button = h.get_by_role_and_label(egui::accesskit::Role::Button, "Export");
    assert!(button.rect().bottom() < 1800.0, "the Export button is on screen: {:?}", button.rect());
    button.click();
    h.step();
    h.step();
    if let Some(msg) = h.query_by_label_contains("Export failed") {
        panic!("{msg:?}");
    }
    let img = image::open(&png).expect("the PNG was written").to_rgb8();
    assert!(img.width() > 300 && img.height() > 300, "the view's size: {:?}", img.dimensions());
    let text = std::fs::read_to_string(dir.path().join("view.toml")).expect("the scene was written");
    assert!(text.contains("split view"), "the note says the PNG is a split view:\n{text}");
    let back = SceneDoc::from_text(&text, Path::new("/")).expect("the exported scene parses");
    assert_eq!(&back, h.state().doc(), "the exported scene is the document");
    let (eye, _) = back.camera();
    assert_eq!(eye, h.state().doc().camera().0);
    assert_ne!(eye, Vec3::ZERO);
}

#[test]
fn a_moved_camera_or_light_reuses_the_prepared_scene_and_draws_the_same_picture() {
    if !gpu_available() {
        return;
    }
    use pomkit_viewer::view::{Overlay, ViewRenderer, ViewRequest};
    let request = |doc: SceneDoc, compare| ViewRequest {
        compare,
        overlay: Overlay::Fetches,
        overlay_opacity: 0.5,
        fetch_scale: 40.0,
        ..ViewRequest::new(doc, 240, 160)
    };
    let ctx = pomkit_gpu::GpuContext::new().expect("adapter");
    let mut retained = ViewRenderer::new(ctx.clone());
    let first = SceneDoc::default();
    let mut moved = first.clone();
    moved.set_camera(Vec3::new(1.2, 0.9, 1.4), Vec3::new(0.1, 0.0, 0.0));
    moved.set_light_direction(Vec3::new(0.3, 0.4, 0.8));
    let compare = Some(pomkit_core::trace::Technique::Relief);
    let a = retained.render(&request(first.clone(), compare)).images.expect("renders");
    assert!(!retained.reused());
    let b = retained.render(&request(moved.clone(), compare)).images.expect("renders");
    assert!(retained.reused(), "only the camera and light changed");
    let fresh = ViewRenderer::new(ctx).render(&request(moved.clone(), compare)).images.expect("renders");
    for (side, (b, f)) in b.iter().zip(&fresh).enumerate() {
        assert!(b.rgba == f.rgba, "side {side}: the retained frame equals a fresh render of the moved view");
    }
    assert!(a[0].rgba != b[0].rgba, "and the view did move");

    // Anything else (here the depth scale) prepares again.
    let mut deeper = moved;
    deeper.set_material_field("depth_scale", Some(toml::Value::Float(0.1)));
    retained.render(&request(deeper, compare)).images.expect("renders");
    assert!(!retained.reused());
}

/// A view wider than the adapter's largest texture (a very wide window, or a high scale factor)
/// renders the largest frame of its shape that the adapter holds, instead of failing (or, with a
/// fixed clamp of each side, stretching the picture).
#[test]
fn a_view_larger_than_the_adapter_shrinks_and_keeps_its_shape() {
    if !gpu_available() {
        return;
    }
    use pomkit_viewer::view::{ViewRenderer, ViewRequest};
    let ctx = pomkit_gpu::GpuContext::new().expect("adapter");
    let limits = ctx.device.limits();
    let (w, h) = (limits.max_texture_dimension_2d.saturating_mul(2).min(60000), 60);
    let mut view = ViewRenderer::new(ctx);
    let result = view.render(&ViewRequest::new(SceneDoc::default(), w, h));
    let images = result.images.expect("the view renders");
    let image = &images[0];
    let (a, b) = pomkit_gpu::renderer::largest_frame(&limits, w, h, 1);
    assert_eq!((image.width, image.height), (a, b));
    assert!(image.width <= limits.max_texture_dimension_2d && image.width >= limits.max_texture_dimension_2d / 2);
    let want = f64::from(w) / f64::from(h);
    let got = f64::from(image.width) / f64::from(image.height);
    assert!((got - want).abs() / want < 0.05, "shape {}x{} for a {w}x{h} view", image.width, image.height);
}
