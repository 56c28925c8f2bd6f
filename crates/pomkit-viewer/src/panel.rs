//! The side panel's controls: every material and technique parameter of a scene file, each
//! with its documentation as the tooltip. Each control reads and writes the [`SceneDoc`]; a
//! field the file leaves out shows its default and is written only once changed.

use eframe::egui::{self, Color32, Pos2, Rect, Ui};
use pomkit_core::glam::Vec3;
use pomkit_core::params::{self, Setting};
pub use pomkit_core::params::{Kind, Param};
use pomkit_core::scene::Material;
use pomkit_core::shadow::ShadowMode;
use pomkit_core::trace::Technique;
use toml::Value;

use crate::doc::SceneDoc;

/// The technique and its parameters, in panel order (the parameter table's).
pub const TECHNIQUE_PARAMS: [Param; 9] = params::TECHNIQUE_PARAMS;

/// Shadows, LOD, input conventions and shading, in panel order (the parameter table's).
pub const OTHER_PARAMS: [Param; 13] = params::OTHER_PARAMS;

/// The value a material has when the scene file leaves `key` out (the parameter table's
/// default; `false` for keys not in the table).
#[must_use]
pub fn default_value(key: &str) -> Value {
    params::get(key).map_or(Value::Boolean(false), |p| to_toml(p.default))
}

fn to_toml(v: params::Value) -> Value {
    match v {
        params::Value::Float(x) => Value::Float(x),
        params::Value::Int(n) => Value::Integer(n),
        params::Value::Bool(b) => Value::Boolean(b),
        params::Value::Name(s) => Value::String(s.to_owned()),
        params::Value::Color(c) => Value::Array(c.iter().map(|&x| Value::Float(x)).collect()),
    }
}

/// Whether the control of `key` affects the picture for the material as it is set, and if
/// not, why (shown greyed out with the reason). The parameter table says who uses what.
pub fn applies(doc: &SceneDoc, key: &str) -> Result<(), String> {
    let Some(p) = params::get(key) else { return Ok(()) };
    let get = |k: &str| doc.material_field(k).cloned().unwrap_or_else(|| default_value(k));
    let height = doc.material_field("height").and_then(Value::as_str);
    let setting = Setting {
        technique: get("technique")
            .as_str()
            .and_then(|s| s.parse::<Technique>().ok())
            .unwrap_or(Material::default().technique),
        shadow: get("shadow").as_str().and_then(|s| s.parse::<ShadowMode>().ok()).unwrap_or_default(),
        height: height.is_some(),
        height_file: height.is_some_and(|h| !h.starts_with("builtin:")),
        normal_file: doc.material_field("normal").is_some(),
    };
    p.applies(&setting)
}

/// One parameter's control. Returns whether the document changed.
pub fn param_control(ui: &mut Ui, doc: &mut SceneDoc, p: &Param) -> bool {
    let current = doc.material_field(p.key).cloned().unwrap_or_else(|| default_value(p.key));
    let enabled = applies(doc, p.key);
    let tooltip = match &enabled {
        Ok(()) => p.tooltip(),
        Err(why) => format!("{}\n\n(No effect now: {why}.)", p.tooltip()),
    };
    let mut changed: Option<Value> = None;
    ui.add_enabled_ui(enabled.is_ok(), |ui| match p.kind {
        Kind::Float { slider: (min, max), log, .. } => {
            let mut v = current.as_float().or_else(|| current.as_integer().map(|n| n as f64)).unwrap_or(min);
            let label = ui.label(p.label).on_hover_text(&tooltip).on_disabled_hover_text(&tooltip);
            let r = ui
                .add(egui::Slider::new(&mut v, min..=max).logarithmic(log).clamping(egui::SliderClamping::Edits))
                .labelled_by(label.id)
                .on_hover_text(&tooltip)
                .on_disabled_hover_text(&tooltip);
            if r.changed() && v.is_finite() {
                changed = Some(Value::Float((v * 1e6).round() / 1e6));
            }
        }
        Kind::Int { slider: (min, max), .. } => {
            let mut v = current.as_integer().unwrap_or(min);
            let label = ui.label(p.label).on_hover_text(&tooltip).on_disabled_hover_text(&tooltip);
            let r = ui
                .add(egui::Slider::new(&mut v, min..=max).clamping(egui::SliderClamping::Edits))
                .labelled_by(label.id)
                .on_hover_text(&tooltip)
                .on_disabled_hover_text(&tooltip);
            if r.changed() {
                changed = Some(Value::Integer(v));
            }
        }
        Kind::Bool => {
            let mut v = current.as_bool().unwrap_or(false);
            let r = ui.checkbox(&mut v, p.label).on_hover_text(&tooltip).on_disabled_hover_text(&tooltip);
            if r.changed() {
                changed = Some(Value::Boolean(v));
            }
        }
        Kind::Color => {
            if color_control(ui, doc, p, &tooltip) {
                changed = doc.material_field(p.key).cloned();
            }
        }
        Kind::Choice(options) => {
            let selected = current.as_str().unwrap_or("").to_owned();
            let label = ui.label(p.label).on_hover_text(&tooltip).on_disabled_hover_text(&tooltip);
            // Without a height map only flat and normal mapping are valid (the loader refuses
            // a displacing technique there).
            let no_height = p.key == "technique" && doc.material_field("height").is_none();
            egui::ComboBox::from_id_salt(p.key)
                .selected_text(&selected)
                // Tall enough for every technique without a scroll bar.
                .height(400.0)
                .show_ui(ui, |ui| {
                    for o in options {
                        let ok = !no_height || matches!(*o, "flat" | "normal");
                        let item = ui
                            .add_enabled(ok, egui::Button::selectable(selected == *o, *o))
                            .on_disabled_hover_text("needs a height map");
                        if item.clicked() && selected != *o {
                            changed = Some(Value::String((*o).to_owned()));
                        }
                    }
                })
                .response
                .labelled_by(label.id)
                .on_hover_text(&tooltip)
                .on_disabled_hover_text(&tooltip);
        }
    });
    let Some(v) = changed else { return false };
    doc.set_material_field(p.key, Some(v.clone()));
    // Keep the sample bounds ordered (the loader refuses min > max).
    let int = |d: &SceneDoc, k: &str| d.material_field(k).and_then(Value::as_integer).or(default_value(k).as_integer());
    match p.key {
        "min_samples" if int(doc, "min_samples") > int(doc, "max_samples") => {
            doc.set_material_field("max_samples", Some(v));
        }
        "max_samples" if int(doc, "max_samples") < int(doc, "min_samples") => {
            doc.set_material_field("min_samples", Some(v));
        }
        _ => {}
    }
    true
}

/// A colour parameter (linear RGB in the file; the picker works in sRGB). Writes the document
/// and returns whether it changed.
fn color_control(ui: &mut Ui, doc: &mut SceneDoc, p: &Param, tooltip: &str) -> bool {
    let linear = doc
        .material_field(p.key)
        .and_then(Value::as_array)
        .and_then(|a| {
            let f = |i: usize| a.get(i)?.as_float().or_else(|| a.get(i)?.as_integer().map(|n| n as f64));
            Some(Vec3::new(f(0)? as f32, f(1)? as f32, f(2)? as f32))
        })
        .unwrap_or_else(|| match p.default {
            params::Value::Color(c) => Vec3::from_array(c.map(|x| x as f32)),
            _ => Vec3::ONE,
        });
    let mut srgb = linear.to_array().map(|c| pomkit_core::scene::linear_to_srgb(c.clamp(0.0, 1.0)));
    let mut changed = false;
    ui.horizontal(|ui| {
        if ui.color_edit_button_rgb(&mut srgb).on_hover_text(tooltip).changed() {
            changed = true;
        }
        ui.label(p.label).on_hover_text(tooltip);
    });
    if changed {
        let lin = srgb.map(|c| {
            let l = f64::from(pomkit_core::scene::srgb_to_linear(c.clamp(0.0, 1.0)));
            Value::Float((l * 1e4).round() / 1e4)
        });
        doc.set_material_field(p.key, Some(Value::Array(lin.to_vec())));
    }
    changed
}

/// A widget to drag the light's direction: the hemisphere above the ground seen from above
/// (+X right, +Z toward the bottom). Returns the new direction when dragged.
pub fn light_pad(ui: &mut Ui, dir: Vec3) -> Option<Vec3> {
    let size = 120.0;
    let (rect, response) = ui.allocate_exact_size(egui::vec2(size, size), egui::Sense::click_and_drag());
    let center = rect.center();
    let radius = size * 0.5 - 4.0;
    let painter = ui.painter_at(rect);
    let visuals = ui.visuals();
    painter.circle_filled(center, radius, visuals.extreme_bg_color);
    painter.circle_stroke(center, radius, visuals.widgets.noninteractive.bg_stroke);
    painter.circle_stroke(
        center,
        radius * (60f32.to_radians().cos()),
        egui::Stroke::new(0.5, visuals.weak_text_color()),
    );
    let d = dir.try_normalize().unwrap_or(Vec3::Y);
    let dot = center + egui::vec2(d.x, d.z) * radius;
    let color = if d.y > 0.0 { egui::Color32::from_rgb(255, 210, 90) } else { egui::Color32::DARK_GRAY };
    painter.line_segment([center, dot], egui::Stroke::new(1.0, color));
    painter.circle_filled(dot, 6.0, color);
    let elevation = d.y.clamp(-1.0, 1.0).asin().to_degrees();
    let azimuth = d.x.atan2(-d.z).to_degrees();
    response.clone().on_hover_text(format!(
        "Light direction (the first directional light), seen from above: drag the sun. The centre is \
         straight overhead, the rim the horizon (the inner circle is 30 degrees up).\n\
         Elevation {elevation:.0} deg, azimuth {azimuth:.0} deg. Ctrl+drag in the view moves it too."
    ));
    if !(response.dragged() || response.clicked()) {
        return None;
    }
    let pos = response.interact_pointer_pos()?;
    let mut p = (pos - center) / radius;
    // Keep the light at least 2 degrees above the horizon.
    let max_r = 2f32.to_radians().cos();
    if p.length() > max_r {
        p = p.normalized() * max_r;
    }
    let y = (1.0 - p.length_sq()).max(0.0).sqrt();
    Some(Vec3::new(p.x, y, p.y))
}

/// A combo box choosing one of `names` (shown only when there is a choice).
pub(crate) fn pick(ui: &mut Ui, label: &str, names: &[String], index: &mut usize) {
    if names.len() < 2 {
        return;
    }
    let shown = &names[(*index).min(names.len() - 1)];
    egui::ComboBox::from_label(label).selected_text(shown).show_ui(ui, |ui| {
        for (i, n) in names.iter().enumerate() {
            ui.selectable_value(index, i, n);
        }
    });
}

pub(crate) fn heat_legend(ui: &mut Ui, scale: f32) {
    let (rect, _) = ui.allocate_exact_size(egui::vec2(ui.available_width().min(220.0), 12.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    let n = 32;
    for i in 0..n {
        let t = i as f32 / (n - 1) as f32;
        let c = crate::view::heat(t);
        let x0 = rect.left() + rect.width() * i as f32 / n as f32;
        let x1 = rect.left() + rect.width() * (i + 1) as f32 / n as f32;
        painter.rect_filled(
            Rect::from_min_max(Pos2::new(x0, rect.top()), Pos2::new(x1, rect.bottom())),
            0.0,
            Color32::from_rgb(c[0], c[1], c[2]),
        );
    }
    ui.horizontal(|ui| {
        ui.small("0");
        ui.add_space((ui.available_width() - 40.0).max(0.0));
        ui.small(format!("{scale:.0}"));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_param_default_is_what_the_loader_uses() {
        // Build a material from a scene that leaves every field out, and one that writes each
        // default explicitly: they must be equal.
        let mut doc = SceneDoc::default();
        for p in TECHNIQUE_PARAMS.iter().chain(&OTHER_PARAMS) {
            doc.set_material_field(p.key, None);
        }
        let mut explicit = doc.clone();
        for p in TECHNIQUE_PARAMS.iter().chain(&OTHER_PARAMS) {
            if matches!(p.key, "normal_y_down") {
                continue; // only valid with a normal map
            }
            explicit.set_material_field(p.key, Some(default_value(p.key)));
        }
        let mut cache = pomkit_io::scene::SceneCache::default();
        let a = doc.build(&mut cache).expect("defaults");
        let b = explicit.build(&mut cache).expect("explicit defaults");
        let (a, b) = (&a.materials[0], &b.materials[0]);
        assert_eq!(a.technique, b.technique);
        assert_eq!(a.trace, b.trace);
        assert_eq!(a.shadow, b.shadow);
        assert_eq!((a.lod_threshold, a.specular, a.shininess), (b.lod_threshold, b.specular, b.shininess));
        assert_eq!(a.pixel_depth_offset, b.pixel_depth_offset);
        assert_eq!(a.silhouette, b.silhouette);
    }

    #[test]
    fn applicability_follows_the_technique() {
        let mut doc = SceneDoc::default();
        doc.set_material_field("technique", Some(Value::String("relief".into())));
        doc.set_material_field("shadow", Some(Value::String("none".into())));
        assert!(applies(&doc, "binary_steps").is_ok());
        assert!(applies(&doc, "samples").is_ok());
        assert!(applies(&doc, "min_samples").is_err());
        assert!(applies(&doc, "iterations").is_err());
        doc.set_material_field("shadow", Some(Value::String("soft".into())));
        assert!(applies(&doc, "min_samples").is_ok(), "soft shadows use the pom bounds");
        assert!(applies(&doc, "softness").is_ok());
        assert!(applies(&doc, "normal_y_down").is_err());
        // Depth shadows trace no light ray: neither softness nor the sample bounds matter.
        doc.set_material_field("shadow", Some(Value::String("depth".into())));
        assert!(applies(&doc, "softness").is_err_and(|why| why.contains("depth")));
        assert!(applies(&doc, "min_samples").is_err());
        assert!(applies(&doc, "shadow").is_ok());
    }
}
