//! The side panel's controls driven through egui_kittest: each test clicks, hovers or drags a
//! control the way a user would and checks what the [`SceneDoc`] (or the light direction) holds
//! afterwards, not only that the ui runs.

use eframe::egui::accesskit::{Role, Toggled};
use eframe::egui::{self, Pos2};
use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT, Queryable};
use pomkit_core::glam::Vec3;
use pomkit_core::shadow::ShadowMode;
use pomkit_core::trace::Technique;
use pomkit_io::scene::SceneCache;
use pomkit_viewer::SceneDoc;
use pomkit_viewer::doc::MapSlot;
use pomkit_viewer::panel::{Kind, OTHER_PARAMS, Param, TECHNIQUE_PARAMS, light_pad, param_control};
use toml::Value;

/// A ui showing `params` the way the side panel does.
fn show(params: &'static [Param]) -> impl FnMut(&mut egui::Ui, &mut SceneDoc) {
    move |ui, doc| {
        for p in params {
            param_control(ui, doc, p);
        }
    }
}

/// A harness showing `params`, editing `doc`.
fn panel(params: &'static [Param], doc: SceneDoc) -> Harness<'static, SceneDoc> {
    let mut harness = Harness::builder().with_size((320.0, 480.0)).build_ui_state(show(params), doc);
    harness.run();
    harness
}

/// The control a panel label names (linked with `labelled_by`): its slider, combo box or
/// checkbox (a slider's number box carries the same name; the slider comes first).
fn control<'t>(harness: &'t Harness<'_, SceneDoc>, label: &'t str) -> egui_kittest::Node<'t> {
    harness
        .query_all_by_label(label)
        .find(|n| matches!(n.accesskit_node().role(), Role::Slider | Role::ComboBox | Role::CheckBox))
        .unwrap_or_else(|| panic!("no control named {label:?}"))
}

/// The text label itself (not the control it names).
fn label_node<'t>(harness: &'t Harness<'_, SceneDoc>, text: &'t str) -> egui_kittest::Node<'t> {
    harness.get_by(move |n| n.role() == Role::Label && n.value().is_some_and(|v| v == text))
}

fn disabled(node: &egui_kittest::Node<'_>) -> bool {
    node.accesskit_node().is_disabled()
}

/// The texts of the tooltips on screen containing `needle` (label nodes whose text contains
/// it: the panel's own labels are one or a few words, the docs are sentences).
fn tooltips_containing(harness: &Harness<'_, SceneDoc>, needle: &'static str) -> Vec<String> {
    harness
        .query_all_by(move |n| n.role() == Role::Label && n.value().is_some_and(|v| v.contains(needle)))
        .filter_map(|n| n.value())
        .collect()
}

fn string(s: &str) -> Value {
    Value::String(s.to_owned())
}

#[test]
fn choosing_a_technique_writes_it_and_the_scene_uses_it() {
    let mut harness = panel(&TECHNIQUE_PARAMS, SceneDoc::default());
    assert_eq!(control(&harness, "Technique").value().as_deref(), Some("exact"));

    control(&harness, "Technique").click();
    harness.run();
    harness.get_by_label("relief").click();
    harness.run();

    assert_eq!(harness.state().material_field("technique"), Some(&string("relief")));
    assert_eq!(control(&harness, "Technique").value().as_deref(), Some("relief"), "the combo box shows it");
    assert!(harness.query_by_label("exact").is_none(), "the list closed after the choice");
    let scene = harness.state().build(&mut SceneCache::default()).expect("the edited scene builds");
    assert_eq!(scene.materials[0].technique, Technique::Relief);
}

#[test]
fn every_technique_in_the_list_reaches_the_scene() {
    let mut harness = panel(&TECHNIQUE_PARAMS, SceneDoc::default());
    let Kind::Choice(names) = TECHNIQUE_PARAMS[0].kind else { panic!("the technique is a choice") };
    for &name in names.iter().rev() {
        control(&harness, "Technique").click();
        harness.run();
        harness.get_by_label(name).click();
        harness.run();
        let scene = harness.state().build(&mut SceneCache::default()).expect("the edited scene builds");
        assert_eq!(scene.materials[0].technique.name(), name);
    }
}

/// Every shadow mode of pomkit-core is in the list, and choosing it reaches the scene; under
/// `depth` (no light ray) the softness is greyed out, with the reason in its tooltip.
#[test]
fn every_shadow_mode_in_the_list_reaches_the_scene() {
    let mut harness = panel(&OTHER_PARAMS, SceneDoc::default());
    let Kind::Choice(names) = OTHER_PARAMS[0].kind else { panic!("the shadow is a choice") };
    assert_eq!(names, ShadowMode::ALL.map(ShadowMode::name).as_slice(), "the list is pomkit-core's modes");
    for &name in names {
        control(&harness, "Shadow").click();
        harness.run();
        harness.get_by_label(name).click();
        harness.run();
        let scene = harness.state().build(&mut SceneCache::default()).expect("the edited scene builds");
        assert_eq!(scene.materials[0].shadow.mode.name(), name);
        assert_eq!(disabled(&control(&harness, "Softness")), name != "soft", "softness under {name}");
    }
    assert_eq!(harness.state().material_field("shadow"), Some(&string("depth")));
    control(&harness, "Softness").hover();
    harness.run();
    assert!(
        !tooltips_containing(&harness, "depth shadows darken by depth alone").is_empty(),
        "the greyed-out softness says why"
    );
}

#[test]
fn choosing_the_current_technique_writes_nothing() {
    // A field the file leaves out shows its default and is written only once changed.
    let mut doc = SceneDoc::default();
    doc.set_material_field("technique", None);
    let mut harness = panel(&TECHNIQUE_PARAMS, doc.clone());
    assert_eq!(control(&harness, "Technique").value().as_deref(), Some("exact"), "the default is shown");

    control(&harness, "Technique").click();
    harness.run();
    harness.get_by_label("exact").click();
    harness.run();

    assert_eq!(harness.state().material_field("technique"), None);
    assert_eq!(*harness.state(), doc);
}

#[test]
fn untouched_controls_write_nothing() {
    let mut doc = SceneDoc::default();
    for p in TECHNIQUE_PARAMS.iter().chain(&OTHER_PARAMS) {
        doc.set_material_field(p.key, None);
    }
    let mut technique = panel(&TECHNIQUE_PARAMS, doc.clone());
    technique.run_steps(3);
    assert_eq!(*technique.state(), doc);
    let mut other = panel(&OTHER_PARAMS, doc.clone());
    other.run_steps(3);
    assert_eq!(*other.state(), doc);
}

#[test]
fn controls_that_do_not_apply_are_disabled() {
    // The default scene set to pom, with its soft shadows, which also use the pom sample bounds.
    let mut doc = SceneDoc::default();
    doc.set_material_field("technique", Some(string("pom")));
    let mut harness = panel(&TECHNIQUE_PARAMS, doc);
    for label in ["Binary steps", "Iterations", "Samples", "Perspective bias"] {
        assert!(disabled(&control(&harness, label)), "{label} is disabled under pom");
        assert!(disabled(&label_node(&harness, label)), "{label}'s label is greyed out too");
    }
    for label in ["Technique", "Depth scale", "Min samples", "Max samples", "Secant refinement"] {
        assert!(!disabled(&control(&harness, label)), "{label} is enabled under pom");
        assert!(!disabled(&label_node(&harness, label)), "{label}'s label is not greyed out");
    }

    control(&harness, "Technique").click();
    harness.run();
    harness.get_by_label("relief").click();
    harness.run();

    assert!(!disabled(&control(&harness, "Binary steps")), "relief uses binary steps");
    assert!(!disabled(&control(&harness, "Samples")), "relief uses samples");
    assert!(disabled(&control(&harness, "Secant refinement")), "only pom refines");
    assert!(disabled(&control(&harness, "Iterations")));
}

#[test]
fn a_disabled_control_ignores_clicks() {
    // No normal map file: the convention checkbox has nothing to act on.
    let mut harness = panel(&OTHER_PARAMS, SceneDoc::default());
    let before = harness.state().clone();
    let checkbox = harness.get_by_label("Normal map is +Y down (DirectX)");
    assert!(disabled(&checkbox));
    checkbox.click();
    harness.run();
    assert_eq!(*harness.state(), before);
}

#[test]
fn tooltips_carry_the_docs() {
    let mut harness = panel(&TECHNIQUE_PARAMS, SceneDoc::default());
    assert!(tooltips_containing(&harness, "UV units").is_empty(), "no tooltip before hovering");

    label_node(&harness, "Depth scale").hover();
    harness.run();
    let shown = tooltips_containing(&harness, "UV units");
    assert_eq!(shown.len(), 1, "hovering the label shows the doc: {shown:?}");
    assert!(!shown[0].contains("No effect now"), "depth scale applies to pom: {shown:?}");

    // The slider has the same tooltip.
    control(&harness, "Depth scale").hover();
    harness.run();
    assert_eq!(tooltips_containing(&harness, "UV units").len(), 1);

    // A disabled control says why it is disabled.
    label_node(&harness, "Iterations").hover();
    harness.run();
    assert!(tooltips_containing(&harness, "UV units").is_empty(), "the previous tooltip closed");
    let shown = tooltips_containing(&harness, "Parallax steps");
    assert_eq!(shown.len(), 1, "hovering a disabled label shows its doc: {shown:?}");
    assert!(shown[0].contains("No effect now: used by iterative."), "{shown:?}");

    control(&harness, "Iterations").hover();
    harness.run();
    let shown = tooltips_containing(&harness, "used by iterative");
    assert_eq!(shown.len(), 1, "hovering a disabled slider shows why too: {shown:?}");
}

/// The default scene with its height map read from a 4x4 PNG whose first texel is white and
/// the rest black (the reading options of `depth_map` and co. apply to images only).
fn doc_with_height_image(dir: &std::path::Path) -> SceneDoc {
    let path = dir.join("height.png");
    image::GrayImage::from_fn(4, 4, |x, y| image::Luma([if (x, y) == (0, 0) { 255 } else { 0 }]))
        .save(&path)
        .expect("writes the height image");
    let mut doc = SceneDoc::default();
    doc.set_map(MapSlot::Height, Some(path.to_string_lossy().into_owned()));
    doc
}

/// The depth of the first texel of the built scene's height field.
fn first_depth(doc: &SceneDoc) -> f32 {
    let scene = doc.build(&mut SceneCache::default()).expect("the edited scene builds");
    scene.materials[0].height.as_ref().expect("a height map").depths()[0]
}

#[test]
fn a_checkbox_writes_its_field() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut harness = panel(&OTHER_PARAMS, doc_with_height_image(dir.path()));
    let label = "Input is depth (white = deep)";
    assert_eq!(harness.state().material_field("depth_map"), None);
    assert_eq!(harness.get_by_label(label).accesskit_node().toggled(), Some(Toggled::False));
    assert_eq!(first_depth(harness.state()), 0.0, "white is high");

    harness.get_by_label(label).click();
    harness.run();
    assert_eq!(harness.state().material_field("depth_map"), Some(&Value::Boolean(true)));
    assert_eq!(harness.get_by_label(label).accesskit_node().toggled(), Some(Toggled::True));
    assert_eq!(first_depth(harness.state()), 1.0, "white is deep");

    harness.get_by_label(label).click();
    harness.run();
    assert_eq!(harness.state().material_field("depth_map"), Some(&Value::Boolean(false)));
}

/// With a built-in height map (the default scene's `builtin:bricks`) the options that describe
/// how to read a height image are disabled: the loader refuses them there, so an enabled
/// checkbox would leave the viewer on an error after one click.
#[test]
fn enabled_reading_options_keep_a_builtin_height_scene_valid() {
    let mut harness = panel(&OTHER_PARAMS, SceneDoc::default());
    harness.get_by_label("Input is depth (white = deep)").click();
    harness.run();
    harness.state().build(&mut SceneCache::default()).expect("the scene still builds");
}

/// Without a height map the technique list offers only flat and normal: the loader refuses a
/// displacing technique on a material without one.
#[test]
fn the_technique_list_keeps_a_scene_without_height_valid() {
    let mut doc = SceneDoc::default();
    doc.set_map(MapSlot::Height, None);
    let mut harness = panel(&TECHNIQUE_PARAMS, doc);
    control(&harness, "Technique").click();
    harness.run();
    assert!(!disabled(&harness.get_by_label("flat")), "flat stays available");
    let pom = harness.query_by_label("pom").expect("pom is listed");
    assert!(disabled(&pom), "pom needs a height map");
    pom.click();
    harness.run();
    harness.state().build(&mut SceneCache::default()).expect("the scene still builds");
}

#[test]
fn the_sample_bounds_stay_ordered() {
    let mut harness = panel(&TECHNIQUE_PARAMS, SceneDoc::default());
    control(&harness, "Min samples").set_value_accesskit(100.0);
    harness.run();
    assert_eq!(harness.state().material_field("min_samples"), Some(&Value::Integer(100)));
    assert_eq!(harness.state().material_field("max_samples"), Some(&Value::Integer(100)), "max follows min up");

    control(&harness, "Max samples").set_value_accesskit(4.0);
    harness.run();
    assert_eq!(harness.state().material_field("max_samples"), Some(&Value::Integer(4)));
    assert_eq!(harness.state().material_field("min_samples"), Some(&Value::Integer(4)), "min follows max down");
    let scene = harness.state().build(&mut SceneCache::default()).expect("the loader accepts the bounds");
    assert_eq!((scene.materials[0].trace.min_samples, scene.materials[0].trace.max_samples), (4, 4));
}

/// The light direction a pad edits, and how many times the pad reported a new one.
struct Pad {
    dir: Vec3,
    moves: usize,
}

fn pad_harness() -> Harness<'static, Pad> {
    let mut harness = Harness::builder().with_size((200.0, 200.0)).build_ui_state(
        |ui, pad: &mut Pad| {
            if let Some(d) = light_pad(ui, pad.dir) {
                pad.dir = d;
                pad.moves += 1;
            }
        },
        Pad { dir: Vec3::new(-0.55, 0.55, -0.35), moves: 0 },
    );
    harness.run();
    harness
}

/// The pad's rect, found by its tooltip.
fn pad_rect(harness: &Harness<'_, Pad>) -> egui::Rect {
    harness.get_by_label_contains("Light direction").rect()
}

fn click_at(harness: &mut Harness<'_, Pad>, pos: Pos2) {
    harness.hover_at(pos);
    harness.drag_at(pos);
    harness.drop_at(pos);
    harness.run();
}

#[test]
fn the_light_pad_maps_clicks_to_directions() {
    let mut harness = pad_harness();
    let rect = pad_rect(&harness);
    assert_eq!(rect.size(), egui::vec2(120.0, 120.0));

    harness.hover_at(rect.center());
    harness.run();
    assert_eq!(harness.state().moves, 0, "hovering moves nothing");

    // The right edge of the disc: low in the east (+X).
    click_at(&mut harness, Pos2::new(rect.right() - 5.0, rect.center().y));
    let d = harness.state().dir;
    assert!(harness.state().moves > 0, "the click reported a direction");
    assert!(d.x > 0.5 && d.z.abs() < 0.05 && d.y > 0.0, "{d}");
    assert!((d.length() - 1.0).abs() < 1e-4, "{d}");

    // The centre: straight overhead.
    click_at(&mut harness, rect.center());
    let d = harness.state().dir;
    assert!(d.y > 0.999 && d.x.abs() < 0.02 && d.z.abs() < 0.02, "{d}");

    // The bottom is +Z.
    click_at(&mut harness, Pos2::new(rect.center().x, rect.bottom() - 10.0));
    let d = harness.state().dir;
    assert!(d.z > 0.5 && d.x.abs() < 0.05, "{d}");

    // A corner, outside the disc, stays above the horizon.
    click_at(&mut harness, rect.min + egui::vec2(1.0, 1.0));
    let d = harness.state().dir;
    assert!(d.x < 0.0 && d.z < 0.0 && d.y > 0.0 && d.y < 0.1, "{d}");
    assert!((d.length() - 1.0).abs() < 1e-4, "{d}");
}

#[test]
fn dragging_on_the_light_pad_follows_the_pointer() {
    let mut harness = pad_harness();
    let rect = pad_rect(&harness);
    harness.hover_at(rect.center());
    harness.drag_at(rect.center());
    harness.run();
    for step in 1..=4 {
        harness.hover_at(rect.center() + egui::vec2(step as f32 * 13.0, 0.0));
        harness.run();
    }
    let d = harness.state().dir;
    assert!(d.x > 0.5 && d.z.abs() < 0.05, "mid-drag: {d}");
    harness.drop_at(rect.center() + egui::vec2(52.0, 0.0));
    harness.run();
    let d = harness.state().dir;
    assert!(d.x > 0.5 && d.z.abs() < 0.05, "after the drag: {d}");
}

#[test]
fn technique_panel_snapshot() {
    if let Err(e) = pomkit_gpu::GpuContext::new() {
        pomkit_gpu::context::skip_without_gpu(&e);
        return;
    }
    let mut harness =
        Harness::builder().with_fit_contents().build_ui_state(show(&TECHNIQUE_PARAMS), SceneDoc::default());
    harness.run();
    harness.snapshot("technique_panel");
}
