//! The side panel's controls: every material and technique parameter of a scene file, each
//! with its documentation as the tooltip. Each control reads and writes the [`SceneDoc`]; a
//! field the file leaves out shows its default and is written only once changed.

use eframe::egui::{self, Ui};
use pomkit_core::glam::Vec3;
use pomkit_core::scene::Material;
use pomkit_core::shadow::ShadowMode;
use pomkit_core::trace::Technique;
use toml::Value;

use crate::doc::SceneDoc;

/// How a parameter is edited.
#[derive(Clone, Copy, Debug)]
pub enum Kind {
    /// A number in `[min, max]` (logarithmic slider when `log`).
    Float {
        /// Smallest.
        min: f64,
        /// Largest.
        max: f64,
        /// Logarithmic slider.
        log: bool,
    },
    /// A whole number in `[min, max]`.
    Int {
        /// Smallest.
        min: i64,
        /// Largest.
        max: i64,
    },
    /// On or off.
    Bool,
    /// One of these names.
    Choice(&'static [&'static str]),
}

/// One material parameter of the scene file.
#[derive(Clone, Copy, Debug)]
pub struct Param {
    /// The scene file's field.
    pub key: &'static str,
    /// The control's label.
    pub label: &'static str,
    /// The control.
    pub kind: Kind,
    /// The tooltip: what it does and which techniques use it.
    pub doc: &'static str,
}

const TECHNIQUES: [&str; 10] =
    ["flat", "normal", "parallax", "iterative", "steep", "pom-classic", "pom", "relief", "exact", "cone"];
const SHADOWS: [&str; 5] = ["none", "hard", "soft", "exact", "depth"];

/// The technique and its parameters, in panel order.
pub const TECHNIQUE_PARAMS: [Param; 9] = [
    Param {
        key: "technique",
        label: "Technique",
        kind: Kind::Choice(&TECHNIQUES),
        doc: "How the surface is displaced.\n\
              flat: plain texturing. normal: normal mapping only.\n\
              parallax: one-sample offset with offset limiting (Kaneko 2001, Welsh 2004).\n\
              iterative: Lengyel's iterative parallax, `iterations` steps.\n\
              steep: steep parallax (McGuire 2005), `samples` depth planes.\n\
              pom-classic: Brawley & Tatarchuk 2004, 8 samples and the perspective bias.\n\
              pom: parallax occlusion mapping (Tatarchuk 2006): adaptive samples, early exit, \
              piecewise-linear intersection, optional secant refinement.\n\
              relief: relief mapping (Policarpo 2005): linear then binary search.\n\
              exact: the exact first hit on the bilinear height surface (max-height pyramid); never \
              misses a feature.\n\
              cone: cone stepping (Dummer 2006) on conservative cones that hold for the bilinear \
              surface, with the patches solved where the cones cannot skip: exact's hits. On the GPU \
              (this viewer) it runs exact's walk until its WGSL port lands.",
    },
    Param {
        key: "depth_scale",
        label: "Depth scale",
        kind: Kind::Float { min: 0.002, max: 0.3, log: true },
        doc: "How deep the deepest point of the height map lies below the polygon, in UV units (so 0.1 on \
              a tile 1 UV wide is a tenth of its width). Also scales the normal map baked from the height \
              map. Every displacing technique.",
    },
    Param {
        key: "min_samples",
        label: "Min samples",
        kind: Kind::Int { min: 1, max: 256 },
        doc: "pom (and hard/soft shadows): the fewest height samples along the ray, used when looking \
              straight down. The count grows toward max_samples as the view grazes the surface \
              (Tatarchuk 2006).",
    },
    Param {
        key: "max_samples",
        label: "Max samples",
        kind: Kind::Int { min: 1, max: 256 },
        doc: "pom (and hard/soft shadows): the most height samples along the ray, used at grazing angles. \
              Too few and thin features are stepped over; more cost fetches.",
    },
    Param {
        key: "samples",
        label: "Samples",
        kind: Kind::Int { min: 1, max: 256 },
        doc: "steep and relief: the number of depth planes of the linear search.",
    },
    Param {
        key: "iterations",
        label: "Iterations",
        kind: Kind::Int { min: 1, max: 32 },
        doc: "iterative: parallax steps, each moving a 1/k share of the locally estimated offset.",
    },
    Param {
        key: "binary_steps",
        label: "Binary steps",
        kind: Kind::Int { min: 0, max: 16 },
        doc: "relief: halvings of the interval found by the linear search. Each halves the error.",
    },
    Param {
        key: "refine",
        label: "Secant refinement",
        kind: Kind::Int { min: 0, max: 8 },
        doc: "pom: secant steps after the linear search (as Unity HDRP does); 0 is Tatarchuk's single \
              line-line intersection.",
    },
    Param {
        key: "perspective_bias",
        label: "Perspective bias",
        kind: Kind::Float { min: 0.0, max: 1.0, log: false },
        doc: "pom-classic: Brawley's perspective bias, from 0 to 1. 1 gives the exact parallax length; smaller \
              values shorten the trace toward grazing angles (less shimmer, flatter relief).",
    },
];

/// Shadows, LOD, input conventions and shading, in panel order.
pub const OTHER_PARAMS: [Param; 12] = [
    Param {
        key: "shadow",
        label: "Shadow",
        kind: Kind::Choice(&SHADOWS),
        doc: "Self-shadowing of the relief by the first light.\n\
              none: only N.L.\nhard: any height sample above the light ray shadows (Brawley 2004).\n\
              soft: Tatarchuk 2006's penumbra estimate, softened by `softness`.\n\
              exact: the exact tracer along the light ray.\n\
              depth: no shadow ray, darker the deeper the point (1 - depth), for fur and grass \
              (McGuire 2005 after Lengyel et al. 2001).",
    },
    Param {
        key: "softness",
        label: "Softness",
        kind: Kind::Float { min: 0.0, max: 0.5, log: false },
        doc: "soft shadows: the light's angular radius in radians. Larger gives wider, lighter penumbrae; \
              0 tends to a hard shadow.",
    },
    Param {
        key: "lod_threshold",
        label: "LOD threshold",
        kind: Kind::Float { min: 0.0, max: 12.0, log: false },
        doc: "Mip level of the height map beyond which only normal mapping is done (Tatarchuk 2006: 4). \
              The technique fades out over the level before it, so distant surfaces cost no fetches. \
              The LOD tint overlay shows where.",
    },
    Param {
        key: "edges",
        label: "Edges",
        kind: Kind::Choice(&["wrap", "clamp"]),
        doc: "Texture addressing: wrap tiles the maps, clamp repeats the edge texels.",
    },
    Param {
        key: "depth_map",
        label: "Input is depth (white = deep)",
        kind: Kind::Bool,
        doc: "Height or depth input: off reads the height map as height (white is high, the usual \
              convention); on reads it as depth (white is deep), as some engines store it.",
    },
    Param {
        key: "channel",
        label: "Height channel",
        kind: Kind::Choice(&["luma", "r", "g", "b", "a"]),
        doc: "The channel of the height image that holds the height: luma for greyscale images, a for a \
              height packed in a normal map's alpha.",
    },
    Param {
        key: "normalize",
        label: "Normalize height",
        kind: Kind::Bool,
        doc: "Rescale the height image's values to fill [0, 1] (needed for float images outside it).",
    },
    Param {
        key: "normal_y_down",
        label: "Normal map is +Y down (DirectX)",
        kind: Kind::Bool,
        doc: "Normal-map convention: off for +Y up (OpenGL, glTF, Blender), on for +Y down (DirectX, \
              Unreal). A wrong setting lights the bumps from the opposite side.",
    },
    Param {
        key: "specular",
        label: "Specular",
        kind: Kind::Float { min: 0.0, max: 2.0, log: false },
        doc: "Strength of the Blinn-Phong highlight.",
    },
    Param {
        key: "shininess",
        label: "Shininess",
        kind: Kind::Float { min: 1.0, max: 512.0, log: true },
        doc: "Blinn-Phong exponent: larger gives a smaller, sharper highlight.",
    },
    Param {
        key: "pixel_depth_offset",
        label: "Pixel depth offset",
        kind: Kind::Bool,
        doc: "Write the displaced depth to the depth buffer, so that displaced surfaces meet other geometry \
              where the real surface would (costs early-z).",
    },
    Param {
        key: "silhouette",
        label: "Silhouettes",
        kind: Kind::Bool,
        doc: "Trace under the curved surface of the mesh and discard pixels whose ray leaves the relief: curved \
              meshes get a bumpy, displaced outline instead of the smooth one (with clamped edges, rays that \
              leave the texture are discarded too). Free when off.",
    },
];

/// The value a material has when the scene file leaves `key` out.
#[must_use]
pub fn default_value(key: &str) -> Value {
    let m = Material::default();
    let f = |x: f32| Value::Float(f64::from(x));
    let i = |x: u32| Value::Integer(i64::from(x));
    let s = |x: &str| Value::String(x.to_owned());
    match key {
        "technique" => s(m.technique.name()),
        "depth_scale" => f(m.trace.depth_scale),
        "min_samples" => i(m.trace.min_samples),
        "max_samples" => i(m.trace.max_samples),
        "samples" => i(m.trace.samples),
        "iterations" => i(m.trace.iterations),
        "binary_steps" => i(m.trace.binary_steps),
        "refine" => i(m.trace.refine),
        "perspective_bias" => f(m.trace.perspective_bias),
        "edges" => s("wrap"),
        "shadow" => s(m.shadow.mode.name()),
        "softness" => f(m.shadow.softness),
        "lod_threshold" => f(m.lod_threshold),
        "channel" => s("luma"),
        "specular" => f(m.specular),
        "shininess" => f(m.shininess),
        "pixel_depth_offset" => Value::Boolean(m.pixel_depth_offset),
        "silhouette" => Value::Boolean(m.silhouette),
        _ => Value::Boolean(false),
    }
}

/// Whether the control of `key` affects the picture for the material as it is set, and if
/// not, why (shown greyed out with the reason).
pub fn applies(doc: &SceneDoc, key: &str) -> Result<(), &'static str> {
    let get = |k: &str| doc.material_field(k).cloned().unwrap_or_else(|| default_value(k));
    let technique: Technique =
        get("technique").as_str().and_then(|s| s.parse().ok()).unwrap_or(Material::default().technique);
    let shadow: ShadowMode = get("shadow").as_str().and_then(|s| s.parse().ok()).unwrap_or_default();
    let height = doc.material_field("height").and_then(Value::as_str);
    let has_height = height.is_some();
    let builtin_height = height.is_some_and(|h| h.starts_with("builtin:"));
    let has_normal = doc.material_field("normal").is_some();
    let t = technique;
    let tracing_shadow = matches!(shadow, ShadowMode::Hard | ShadowMode::Soft);
    match key {
        "depth_scale" | "depth_map" | "channel" | "normalize" | "lod_threshold" | "shadow" | "edges" if !has_height => {
            Err("needs a height map")
        }
        "depth_map" | "channel" | "normalize" if builtin_height => {
            Err("describes how to read a height image file, not a built-in map")
        }
        "min_samples" | "max_samples" if !(t == Technique::Pom || tracing_shadow) => {
            Err("used by pom and by hard and soft shadows")
        }
        "samples" if !matches!(t, Technique::Steep | Technique::Relief) => Err("used by steep and relief"),
        "iterations" if t != Technique::Iterative => Err("used by iterative"),
        "binary_steps" if t != Technique::Relief => Err("used by relief"),
        "refine" if t != Technique::Pom => Err("used by pom"),
        "perspective_bias" if t != Technique::PomClassic => Err("used by pom-classic"),
        "softness" if shadow == ShadowMode::Depth => {
            Err("used by soft shadows; depth shadows darken by depth alone and trace no light ray")
        }
        "softness" if shadow != ShadowMode::Soft => Err("used by soft shadows"),
        "silhouette" if !has_height || !t.displaces() => Err("needs a height map and a displacing technique"),
        "normal_y_down" if !has_normal => Err("needs a normal map file (without one, it is baked from the height)"),
        _ => Ok(()),
    }
}

/// One parameter's control. Returns whether the document changed.
pub fn param_control(ui: &mut Ui, doc: &mut SceneDoc, p: &Param) -> bool {
    let current = doc.material_field(p.key).cloned().unwrap_or_else(|| default_value(p.key));
    let enabled = applies(doc, p.key);
    let tooltip = match enabled {
        Ok(()) => p.doc.to_owned(),
        Err(why) => format!("{}\n\n(No effect now: {why}.)", p.doc),
    };
    let mut changed: Option<Value> = None;
    ui.add_enabled_ui(enabled.is_ok(), |ui| match p.kind {
        Kind::Float { min, max, log } => {
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
        Kind::Int { min, max } => {
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

/// The base colour (linear RGB in the file; the picker works in sRGB).
pub fn base_color_control(ui: &mut Ui, doc: &mut SceneDoc) -> bool {
    let linear = doc
        .material_field("base_color")
        .and_then(Value::as_array)
        .and_then(|a| {
            let f = |i: usize| a.get(i)?.as_float().or_else(|| a.get(i)?.as_integer().map(|n| n as f64));
            Some(Vec3::new(f(0)? as f32, f(1)? as f32, f(2)? as f32))
        })
        .unwrap_or(Material::default().base_color);
    let mut srgb = linear.to_array().map(|c| pomkit_core::scene::linear_to_srgb(c.clamp(0.0, 1.0)));
    let mut changed = false;
    ui.horizontal(|ui| {
        if ui.color_edit_button_rgb(&mut srgb).changed() {
            changed = true;
        }
        ui.label("Base colour").on_hover_text(
            "Multiplies the colour map (linear RGB in the scene file). Without a colour map, the surface's colour.",
        );
    });
    if changed {
        let lin = srgb.map(|c| {
            let l = f64::from(pomkit_core::scene::srgb_to_linear(c.clamp(0.0, 1.0)));
            Value::Float((l * 1e4).round() / 1e4)
        });
        doc.set_material_field("base_color", Some(Value::Array(lin.to_vec())));
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
