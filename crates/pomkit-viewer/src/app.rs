//! The eframe application: the side panel, the 3D view with its camera and light controls,
//! the split view and overlays, files opened or dropped, export, persistence, screenshots.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use eframe::egui::{self, Color32, ColorImage, Pos2, Rect, RichText, TextureHandle, TextureOptions, Ui, Vec2};
use pomkit_core::glam::Vec3;
use pomkit_core::procedural::Pattern;
use pomkit_core::trace::Technique;
use toml::Value;

use crate::browser::{Browser, Purpose};
use crate::camera::{self, Orbit};
use crate::doc::{FileKind, MapSlot, SHAPES, SceneDoc};
use crate::panel::{self, OTHER_PARAMS, TECHNIQUE_PARAMS};
use crate::screenshot::Shot;
pub use crate::screenshot::{ScreenshotJob, ScreenshotOutcome};
pub use crate::settings::Settings;
use crate::settings::{STORAGE_KEY, Saved};
use crate::view::{Overlay, SideStats, ViewImage, ViewRequest, Worker, WorkerMessage, split_view};

/// The viewer.
pub struct ViewerApp {
    doc: SceneDoc,
    settings: Settings,
    worker: Worker,
    device: Option<Result<(String, bool), String>>,
    textures: Vec<TextureHandle>,
    images: Vec<ViewImage>,
    stats: Vec<SideStats>,
    error: Option<String>,
    message: Option<(String, Instant)>,
    next_id: u64,
    /// The last request sent, to send a new one only when something changed.
    sent: Option<(ViewRequest, bool)>,
    /// The id and preview flag of the frame on screen.
    shown: Option<(u64, bool)>,
    reload: bool,
    browser: Option<Browser>,
    slot_rects: Vec<(MapSlot, Rect)>,
    shot: Option<Shot>,
    persist: bool,
}

impl ViewerApp {
    /// The app on `doc` (or the saved session, or the default scene).
    pub fn new(cc: &eframe::CreationContext<'_>, doc: Option<SceneDoc>, shot: Option<ScreenshotJob>) -> Self {
        let persist = shot.is_none();
        let saved: Option<Saved> =
            if persist { cc.storage.and_then(|s| eframe::get_value::<Saved>(s, STORAGE_KEY)) } else { None };
        let mut settings = saved.as_ref().map(|s| s.settings.clone()).unwrap_or_default();
        let mut message = None;
        let doc = match (doc, &saved) {
            (Some(d), _) => d,
            (None, Some(s)) if !s.scene.is_empty() => match SceneDoc::from_text(&s.scene, Path::new(".")) {
                Ok(mut d) => {
                    d.material = s.material.min(d.material_names().len().saturating_sub(1));
                    d.object = s.object.min(d.object_names().len().saturating_sub(1));
                    d
                }
                Err(e) => {
                    message = Some((
                        format!("The saved scene could not be restored ({e}); opened the default."),
                        Instant::now(),
                    ));
                    SceneDoc::default()
                }
            },
            _ => SceneDoc::default(),
        };
        if !settings.resolution.is_finite() || settings.resolution <= 0.0 {
            settings.resolution = 1.0;
        }
        let ctx = cc.egui_ctx.clone();
        let worker = Worker::start(move || ctx.request_repaint());
        Self {
            doc,
            settings,
            worker,
            device: None,
            textures: Vec::new(),
            images: Vec::new(),
            stats: Vec::new(),
            error: None,
            message,
            next_id: 1,
            sent: None,
            shown: None,
            reload: false,
            browser: None,
            slot_rects: Vec::new(),
            shot: shot.map(Shot::new),
            persist,
        }
    }

    /// Starts in a split view against `compare` and/or with `overlay` (command-line flags,
    /// overriding the saved settings).
    pub fn start_with(&mut self, compare: Option<Technique>, overlay: Option<Overlay>) {
        if let Some(t) = compare {
            self.settings.compare = true;
            self.settings.compare_technique = t.name().to_owned();
        }
        if let Some(o) = overlay {
            self.settings.overlay = o;
        }
    }

    /// The scene being tuned.
    #[must_use]
    pub fn doc(&self) -> &SceneDoc {
        &self.doc
    }

    /// The view settings.
    pub fn settings_mut(&mut self) -> &mut Settings {
        &mut self.settings
    }

    /// Whether the picture on screen shows the current scene and settings at full resolution
    /// (nothing left to render).
    #[must_use]
    pub fn is_complete(&self) -> bool {
        self.complete()
    }

    /// The figures of the picture on screen (one per side of the split).
    #[must_use]
    pub fn stats(&self) -> &[SideStats] {
        &self.stats
    }

    /// Why the view shows no new picture, if it does not.
    #[must_use]
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }

    /// The device the view renders on (name, software?), once the render thread has started.
    #[must_use]
    pub fn device(&self) -> Option<&Result<(String, bool), String>> {
        self.device.as_ref()
    }

    fn notify(&mut self, text: impl Into<String>) {
        self.message = Some((text.into(), Instant::now()));
    }

    /// Whether the frame on screen shows the current settings at full resolution.
    fn complete(&self) -> bool {
        match (&self.sent, self.shown) {
            (Some((req, preview)), Some((id, shown_preview))) => req.id == id && !preview && !shown_preview,
            _ => false,
        }
    }

    fn receive(&mut self, ctx: &egui::Context) {
        for msg in self.worker.poll() {
            match msg {
                WorkerMessage::Device(d) => self.device = Some(d),
                WorkerMessage::Frame(result) => {
                    let preview = self.sent.as_ref().is_some_and(|(r, p)| r.id == result.id && *p);
                    self.shown = Some((result.id, preview));
                    match result.images {
                        Ok(images) => {
                            self.error = None;
                            self.textures = images
                                .iter()
                                .enumerate()
                                .map(|(i, im)| {
                                    let color = ColorImage::from_rgba_unmultiplied(
                                        [im.width as usize, im.height as usize],
                                        &im.rgba,
                                    );
                                    ctx.load_texture(format!("pomkit view {i}"), color, TextureOptions::LINEAR)
                                })
                                .collect();
                            self.images = images;
                            self.stats = result.stats;
                        }
                        Err(e) => self.error = Some(e),
                    }
                }
            }
        }
    }

    /// Sends a request when the view's size or anything it shows changed. While the user
    /// drags (`interacting`), changes render at half resolution; a press that changes nothing
    /// keeps the full-resolution picture.
    fn request(&mut self, size_px: [u32; 2], interacting: bool) {
        // The renderer shrinks a frame the adapter cannot hold, keeping its shape
        // (`pomkit_gpu::renderer::largest_frame`).
        let size = |scale: f32| {
            let w = ((size_px[0] as f32 * scale).round() as u32).max(16);
            let h = ((size_px[1] as f32 * scale).round() as u32).max(16);
            (w, h)
        };
        let compare =
            if self.settings.compare { self.settings.compare_technique.parse::<Technique>().ok() } else { None };
        let settings = &self.settings;
        let same_content = |s: &ViewRequest| {
            s.doc == self.doc
                && (s.compare, s.overlay) == (compare, settings.overlay)
                && (s.overlay_opacity, s.fetch_scale) == (settings.overlay_opacity, settings.fetch_scale)
        };
        if let Some((s, was_preview)) = &self.sent
            && same_content(s)
            && !self.reload
        {
            let sent_size = (s.width, s.height);
            if !was_preview && sent_size == size(1.0) {
                return; // the full picture of this is on its way or on screen
            }
            if *was_preview && interacting && sent_size == size(0.5) {
                return;
            }
        }
        let preview = interacting;
        let (w, h) = size(if preview { 0.5 } else { 1.0 });
        let req = ViewRequest {
            id: self.next_id,
            doc: self.doc.clone(),
            width: w,
            height: h,
            compare,
            split: self.settings.split,
            overlay: self.settings.overlay,
            overlay_opacity: self.settings.overlay_opacity,
            fetch_scale: self.settings.fetch_scale,
            reload: self.reload,
        };
        self.next_id += 1;
        self.reload = false;
        self.worker.request(req.clone());
        self.sent = Some((req, preview));
    }

    /// Opens a file dropped or picked for `purpose`.
    fn open_file(&mut self, path: &Path, purpose: Purpose) {
        match purpose {
            Purpose::Scene => match SceneDoc::open(path) {
                Ok(d) => {
                    self.doc = d;
                    self.notify(format!("Opened {}", path.display()));
                }
                Err(e) => self.notify(format!("Cannot open the scene: {e}")),
            },
            Purpose::Mesh => {
                self.doc.set_mesh(&path.to_string_lossy());
                self.notify(format!("Mesh: {}", path.display()));
            }
            Purpose::Map(slot) => {
                self.doc.set_map(slot, Some(path.to_string_lossy().into_owned()));
                self.notify(format!("{} map: {}", slot.key(), path.display()));
            }
        }
    }

    fn handle_drops(&mut self, ctx: &egui::Context) {
        let (dropped, pointer) = ctx.input(|i| (i.raw.dropped_files.clone(), i.pointer.latest_pos()));
        for f in dropped {
            let path = f.path().to_owned();
            let purpose = match FileKind::of(&path) {
                FileKind::Scene => Purpose::Scene,
                FileKind::Mesh => Purpose::Mesh,
                FileKind::Image => {
                    let over =
                        pointer.and_then(|p| self.slot_rects.iter().find(|(_, r)| r.contains(p)).map(|(s, _)| *s));
                    Purpose::Map(over.unwrap_or_else(|| MapSlot::guess(&path)))
                }
            };
            self.open_file(&path, purpose);
        }
    }

    fn side_panel(&mut self, ui: &mut Ui) {
        egui::ScrollArea::vertical().auto_shrink([false, false]).show(ui, |ui| {
            ui.heading("pomkit view");
            self.device_line(ui);
            ui.separator();
            self.scene_section(ui);
            self.maps_section(ui);
            egui::CollapsingHeader::new("Technique").default_open(true).show(ui, |ui| {
                for p in &TECHNIQUE_PARAMS {
                    panel::param_control(ui, &mut self.doc, p);
                }
            });
            egui::CollapsingHeader::new("Shadows, LOD, input, shading").default_open(true).show(ui, |ui| {
                for p in &OTHER_PARAMS {
                    panel::param_control(ui, &mut self.doc, p);
                    if p.key == "lod_threshold" {
                        let mut tint = self.settings.overlay == Overlay::LodTint;
                        if ui.checkbox(&mut tint, "LOD tint view").on_hover_text(Overlay::LodTint.doc()).changed() {
                            self.settings.overlay = if tint { Overlay::LodTint } else { Overlay::None };
                        }
                    }
                }
            });
            self.light_section(ui);
            self.view_section(ui);
            self.export_section(ui);
        });
    }

    fn device_line(&self, ui: &mut Ui) {
        match &self.device {
            None => {
                ui.label("Starting the GPU renderer...");
            }
            Some(Ok((name, software))) => {
                ui.label(format!("GPU: {name}")).on_hover_text("The adapter the view renders on (pomkit-gpu, wgpu).");
                if *software {
                    ui.label(
                        RichText::new(
                            "No hardware GPU: rendering on lavapipe, Mesa's software Vulkan. It draws the same \
                             picture, slowly; frame times are CPU times.",
                        )
                        .color(Color32::from_rgb(240, 170, 60)),
                    );
                }
            }
            Some(Err(e)) => {
                ui.colored_label(Color32::LIGHT_RED, format!("No GPU adapter: {e}"));
            }
        }
    }

    fn scene_section(&mut self, ui: &mut Ui) {
        egui::CollapsingHeader::new("Scene").default_open(true).show(ui, |ui| {
            ui.horizontal(|ui| {
                if ui.button("Open scene...").on_hover_text("Open a scene file (.toml, docs/SCENES.md).").clicked() {
                    self.browser = Some(Browser::new(Purpose::Scene));
                }
                if ui.button("Default scene").on_hover_text("Back to the built-in brick plane.").clicked() {
                    self.doc = SceneDoc::default();
                }
                if ui.button("Reload files").on_hover_text("Read the texture and mesh files again from disk.").clicked()
                {
                    self.reload = true;
                    self.sent = None;
                }
            });
            panel::pick(ui, "Material", &self.doc.material_names(), &mut self.doc.material);
            panel::pick(ui, "Object", &self.doc.object_names(), &mut self.doc.object);
            let mesh = self.doc.mesh();
            let shown = if SHAPES.iter().any(|(s, _)| *s == mesh) {
                mesh.clone()
            } else {
                Path::new(&mesh).file_name().map_or(mesh.clone(), |n| n.to_string_lossy().into_owned())
            };
            ui.horizontal(|ui| {
                let label =
                    ui.label("Mesh").on_hover_text("The selected object's mesh: a built-in shape or an OBJ/glTF file.");
                egui::ComboBox::from_id_salt("mesh")
                    .selected_text(shown)
                    .show_ui(ui, |ui| {
                        for (shape, _) in SHAPES {
                            if ui.selectable_label(mesh == shape, shape).clicked() && mesh != shape {
                                self.doc.set_mesh(shape);
                            }
                        }
                    })
                    .response
                    .labelled_by(label.id);
                if ui.button("File...").on_hover_text("Load an OBJ, glTF or GLB mesh.").clicked() {
                    self.browser = Some(Browser::new(Purpose::Mesh));
                }
            });
            let mut repeat = self
                .doc
                .object_field("uv_repeat")
                .and_then(|v| {
                    v.as_float()
                        .or_else(|| v.as_integer().map(|n| n as f64))
                        .or_else(|| v.as_array()?.first()?.as_float())
                })
                .unwrap_or(1.0);
            let label =
                ui.label("UV repeat").on_hover_text("How many times the maps tile across the object (uv_repeat).");
            if ui.add(egui::Slider::new(&mut repeat, 0.25..=16.0).logarithmic(true)).labelled_by(label.id).changed() {
                self.doc.set_object_field("uv_repeat", Some(Value::Float((repeat * 1e4).round() / 1e4)));
            }
        });
    }

    fn maps_section(&mut self, ui: &mut Ui) {
        self.slot_rects.clear();
        egui::CollapsingHeader::new("Maps").default_open(true).show(ui, |ui| {
            ui.label(RichText::new("Drop image files on a slot, or on the window (sorted by name).").weak().small());
            for slot in MapSlot::ALL {
                let r = ui
                    .group(|ui| {
                        ui.set_width(ui.available_width());
                        let current = self.doc.material_field(slot.key()).and_then(Value::as_str).map(str::to_owned);
                        let (title, doc) = match slot {
                            MapSlot::Albedo => {
                                ("Colour", "The colour map (sRGB images), multiplied by the base colour.")
                            }
                            MapSlot::Height => (
                                "Height",
                                "The height map: white is high (or deep, with 'Input is depth'). Without it the \
                                 surface is flat or normal-mapped only.",
                            ),
                            MapSlot::Normal => (
                                "Normal",
                                "A tangent-space normal map. Without one, it is baked from the height map with \
                                 the depth scale.",
                            ),
                        };
                        let mut title_id = ui.scope_id();
                        ui.horizontal(|ui| {
                            title_id = ui.strong(title).on_hover_text(doc).id;
                            let name = match &current {
                                Some(c) if c.starts_with("builtin:") => c.clone(),
                                Some(c) => {
                                    Path::new(c).file_name().map_or(c.clone(), |n| n.to_string_lossy().into_owned())
                                }
                                None if slot == MapSlot::Normal => "baked from height".into(),
                                None => "none".into(),
                            };
                            ui.label(RichText::new(name).monospace())
                                .on_hover_text(current.clone().unwrap_or_default());
                        });
                        ui.horizontal(|ui| {
                            if ui.button("Open...").clicked() {
                                self.browser = Some(Browser::new(Purpose::Map(slot)));
                            }
                            if slot != MapSlot::Normal {
                                egui::ComboBox::from_id_salt(("builtin", slot.key()))
                                    .selected_text("built-in")
                                    .show_ui(ui, |ui| {
                                        for p in Pattern::ALL {
                                            if ui.selectable_label(false, p.name()).clicked() {
                                                self.doc.set_map(slot, Some(format!("builtin:{}", p.name())));
                                            }
                                        }
                                    })
                                    .response
                                    .labelled_by(title_id)
                                    .on_hover_text("A built-in procedural pattern (builtin:NAME in a scene file).");
                            }
                            if current.is_some() && ui.button("Remove").clicked() {
                                self.doc.set_map(slot, None);
                            }
                        });
                    })
                    .response
                    .rect;
                self.slot_rects.push((slot, r));
            }
        });
    }

    fn light_section(&mut self, ui: &mut Ui) {
        egui::CollapsingHeader::new("Light").default_open(true).show(ui, |ui| {
            let dir = self.doc.light_direction().unwrap_or(Vec3::new(-0.5, 0.6, -0.4));
            if let Some(d) = panel::light_pad(ui, dir) {
                self.doc.set_light_direction(d);
            }
        });
    }

    fn view_section(&mut self, ui: &mut Ui) {
        egui::CollapsingHeader::new("Compare and inspect").default_open(true).show(ui, |ui| {
            ui.checkbox(&mut self.settings.compare, "Split view").on_hover_text(
                "Compare two techniques on the same surface: the material's own on the left, this one on the \
                 right. Drag the divider in the view.",
            );
            ui.add_enabled_ui(self.settings.compare, |ui| {
                egui::ComboBox::from_label("Right side").selected_text(&self.settings.compare_technique).show_ui(ui, |ui| {
                    for t in Technique::ALL {
                        ui.selectable_value(&mut self.settings.compare_technique, t.name().to_owned(), t.name());
                    }
                });
            });
            egui::ComboBox::from_label("Overlay").selected_text(self.settings.overlay.label()).show_ui(ui, |ui| {
                for o in Overlay::ALL {
                    ui.selectable_value(&mut self.settings.overlay, o, o.label()).on_hover_text(o.doc());
                }
            })
            .response
            .on_hover_text(self.settings.overlay.doc());
            ui.add_enabled_ui(!matches!(self.settings.overlay, Overlay::None | Overlay::LodTint), |ui| {
                ui.add(egui::Slider::new(&mut self.settings.overlay_opacity, 0.0..=1.0).text("opacity"));
            });
            if self.settings.overlay == Overlay::Fetches {
                ui.add(egui::Slider::new(&mut self.settings.fetch_scale, 1.0..=256.0).logarithmic(true).text("white at"))
                    .on_hover_text("The fetch count drawn white in the heat map.");
                panel::heat_legend(ui, self.settings.fetch_scale);
            }
            ui.add(egui::Slider::new(&mut self.settings.resolution, 0.25..=1.0).text("resolution")).on_hover_text(
                "Rendered pixels per screen pixel. Lower renders faster (while dragging, the view renders at half of this).",
            );
        });
    }

    fn export_section(&mut self, ui: &mut Ui) {
        egui::CollapsingHeader::new("Export").default_open(true).show(ui, |ui| {
            ui.add(egui::TextEdit::singleline(&mut self.settings.export_path).hint_text("view.png")).on_hover_text(
                "The PNG to write; the scene goes beside it as .toml. `pomkit render FILE.toml --size WxH` \
                 reproduces the picture (the exact command is in the TOML's first lines).",
            );
            let ready = self.complete() && !self.images.is_empty();
            if ui.add_enabled(ready, egui::Button::new("Export")).clicked() {
                self.export();
            }
        });
    }

    fn export(&mut self) {
        let Some(image) = split_view(&self.images, self.settings.split) else { return };
        let name = self.settings.export_path.trim();
        if name.is_empty() {
            self.notify("Export: type the PNG's file name first.");
            return;
        }
        let path = PathBuf::from(name);
        let mut notes = Vec::new();
        if self.settings.compare && self.images.len() > 1 {
            notes.push(format!(
                "The PNG is a split view; right of {:.0}% of the width it shows `--technique {}`.",
                self.settings.split * 100.0,
                self.settings.compare_technique
            ));
        }
        if self.settings.overlay != Overlay::None {
            notes.push(format!("The PNG shows the {} overlay.", self.settings.overlay.label()));
        }
        let note = (!notes.is_empty()).then(|| notes.join(" "));
        match crate::view::export(&self.doc, &image, &path, note.as_deref()) {
            Ok(toml) => self.notify(format!("Wrote {} and {}", path.with_extension("png").display(), toml.display())),
            Err(e) => self.notify(format!("Export failed: {e}")),
        }
    }

    /// The 3D view: the picture (split when comparing), its mouse controls, and the figures and
    /// messages drawn over it.
    fn view(&mut self, ui: &mut Ui) {
        let avail = ui.available_size();
        let (rect, response) = ui.allocate_exact_size(avail, egui::Sense::click_and_drag());
        let ppp = ui.ctx().pixels_per_point();
        let size_px = [
            (rect.width() * ppp * self.settings.resolution).round().max(1.0) as u32,
            (rect.height() * ppp * self.settings.resolution).round().max(1.0) as u32,
        ];
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, Color32::from_rgb(12, 12, 14));

        let split_x = rect.left() + rect.width() * self.settings.split;
        let divider_dragged = self.drag_divider(ui, rect, split_x);
        let moved = self.camera_and_light_input(ui, &response, rect, divider_dragged);
        let interacting = divider_dragged || moved || ui.ctx().dragged_id().is_some();
        self.request(size_px, interacting);

        self.paint_picture(&painter, rect, split_x);
        self.paint_figures(&painter, rect);
        if ui.input(|i| !i.raw.hovered_files.is_empty()) {
            paint_drop_hint(&painter, rect);
        }
    }

    /// The divider of the split view at `split_x`, when comparing: dragging it moves the split.
    /// Returns whether it is being dragged.
    fn drag_divider(&mut self, ui: &Ui, rect: Rect, split_x: f32) -> bool {
        if !self.settings.compare {
            return false;
        }
        let divider = Rect::from_min_max(Pos2::new(split_x - 5.0, rect.top()), Pos2::new(split_x + 5.0, rect.bottom()));
        let mut dragged = false;
        let d = ui.interact(divider, ui.scope_id().with("split"), egui::Sense::drag());
        if d.dragged() {
            self.settings.split =
                ((d.interact_pointer_pos().map_or(split_x, |p| p.x) - rect.left()) / rect.width()).clamp(0.0, 1.0);
            dragged = true;
        }
        if d.hovered() || d.dragged() {
            ui.ctx().set_cursor_icon(egui::CursorIcon::ResizeHorizontal);
        }
        dragged
    }

    /// The view's mouse controls (`response` is the view's): a drag orbits the camera, pans it
    /// with the right or middle button or Shift, or moves the light with Ctrl (not while the
    /// divider is dragged); the wheel zooms; a double click restores the default framing.
    /// Returns whether the camera or the light moved.
    fn camera_and_light_input(
        &mut self,
        ui: &Ui,
        response: &egui::Response,
        rect: Rect,
        divider_dragged: bool,
    ) -> bool {
        let mut moved = false;
        if !divider_dragged && response.dragged() {
            let delta = response.drag_delta();
            let (mods, secondary) = ui.input(|i| (i.modifiers, i.pointer.secondary_down() || i.pointer.middle_down()));
            if mods.ctrl || mods.command {
                let from = self.doc.light_direction().unwrap_or(Vec3::new(-0.5, 0.6, -0.4));
                self.doc.set_light_direction(camera::drag_light(from, pomkit_core::glam::Vec2::new(delta.x, delta.y)));
            } else if secondary || mods.shift {
                let mut c = self.camera();
                c.pan(pomkit_core::glam::Vec2::new(delta.x, delta.y), rect.height());
                self.set_camera(c);
            } else {
                let mut c = self.camera();
                c.orbit(pomkit_core::glam::Vec2::new(delta.x, delta.y));
                self.set_camera(c);
            }
            moved = true;
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y + i.zoom_delta().ln() * 200.0);
            if scroll != 0.0 {
                let mut c = self.camera();
                c.zoom((-scroll * 0.002).exp());
                self.set_camera(c);
                moved = true;
            }
        }
        if response.double_clicked() {
            // Back to the default scene's framing.
            let (eye, target) = SceneDoc::default().camera();
            self.doc.set_camera(eye, target);
        }
        moved
    }

    /// The rendered picture: one texture over the whole view, or, comparing, the left part of
    /// the first and the right part of the second with a line between them at `split_x`.
    fn paint_picture(&self, painter: &egui::Painter, rect: Rect, split_x: f32) {
        let uv_full = Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0));
        if let Some(tex) = self.textures.first() {
            if self.textures.len() > 1 {
                let s = self.settings.split;
                let left = Rect::from_min_max(rect.min, Pos2::new(split_x, rect.bottom()));
                painter.image(tex.id(), left, Rect::from_min_max(Pos2::ZERO, Pos2::new(s, 1.0)), Color32::WHITE);
                let right = Rect::from_min_max(Pos2::new(split_x, rect.top()), rect.max);
                painter.image(
                    self.textures[1].id(),
                    right,
                    Rect::from_min_max(Pos2::new(s, 0.0), Pos2::new(1.0, 1.0)),
                    Color32::WHITE,
                );
            } else {
                painter.image(tex.id(), rect, uv_full, Color32::WHITE);
            }
        }
        if self.settings.compare && self.textures.len() > 1 {
            painter.line_segment(
                [Pos2::new(split_x, rect.top()), Pos2::new(split_x, rect.bottom())],
                egui::Stroke::new(2.0, Color32::WHITE),
            );
        }
    }

    /// The figures over the picture: each side's frame time and fetches in the top corners,
    /// the render's state (preview, rendering) in the bottom right, and the last error.
    fn paint_figures(&self, painter: &egui::Painter, rect: Rect) {
        let font = egui::FontId::monospace(13.0);
        let shadowed = |pos: Pos2, anchor: egui::Align2, text: String| {
            painter.text(pos + Vec2::splat(1.0), anchor, &text, font.clone(), Color32::BLACK);
            painter.text(pos, anchor, text, font.clone(), Color32::WHITE);
        };
        let line = |s: &SideStats| {
            let clock = if s.from_timestamps { "GPU" } else { "wall" };
            format!(
                "{}  {:.1} ms ({clock})  {:.1} fetches/px (max {:.0})",
                s.label, s.frame_ms, s.fetches_per_pixel, s.max_fetches
            )
        };
        if let Some(a) = self.stats.first() {
            shadowed(rect.left_top() + Vec2::new(8.0, 8.0), egui::Align2::LEFT_TOP, line(a));
        }
        if let Some(b) = self.stats.get(1) {
            shadowed(rect.right_top() + Vec2::new(-8.0, 8.0), egui::Align2::RIGHT_TOP, line(b));
        }
        let status = if self.complete() {
            String::new()
        } else if self.sent.as_ref().is_some_and(|(_, p)| *p) {
            "preview".into()
        } else {
            "rendering...".into()
        };
        if !status.is_empty() {
            shadowed(rect.right_bottom() + Vec2::new(-8.0, -8.0), egui::Align2::RIGHT_BOTTOM, status);
        }
        if let Some(e) = &self.error {
            painter.text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                e,
                egui::FontId::proportional(15.0),
                Color32::LIGHT_RED,
            );
        }
    }

    /// The camera as the scene file holds it, for the orbit controls.
    fn camera(&self) -> Orbit {
        let (eye, target) = self.doc.camera();
        Orbit { eye, target, fov_deg: self.doc.fov_deg() }
    }

    fn set_camera(&mut self, c: Orbit) {
        self.doc.set_camera(c.eye, c.target);
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.receive(&ctx);
        self.handle_drops(&ctx);

        egui::Panel::left("controls").resizable(true).default_size(330.0).show(ui, |ui| {
            self.side_panel(ui);
        });
        egui::Panel::bottom("status").show(ui, |ui| {
            ui.horizontal(|ui| {
                match &self.message {
                    Some((m, at)) if at.elapsed() < Duration::from_secs(8) => {
                        ui.label(m.as_str());
                    }
                    _ => {
                        ui.label(RichText::new("Drop textures, meshes or scenes on the window.").weak());
                    }
                }
                ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                    ui.label(
                        RichText::new(
                            "drag: orbit   shift/right-drag: pan   wheel: zoom   ctrl-drag: light   \
                             double-click: reset   ctrl+Q: quit",
                        )
                        .weak(),
                    );
                });
            });
        });
        egui::CentralPanel::default().frame(egui::Frame::NONE).show(ui, |ui| self.view(ui));

        if let Some(b) = &mut self.browser {
            match b.show(&ctx) {
                Some(Some(path)) => {
                    let purpose = b.purpose();
                    self.browser = None;
                    self.open_file(&path, purpose);
                }
                Some(None) => self.browser = None,
                None => {}
            }
        }
        if ctx.input(|i| i.modifiers.command && i.key_pressed(egui::Key::Q)) {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
        let complete = self.complete() || (self.error.is_some() && self.shown.is_some());
        if let Some(shot) = &mut self.shot {
            shot.step(&ctx, complete, self.error.as_deref());
        }
        if !self.complete() {
            ctx.request_repaint_after(Duration::from_millis(50));
        }
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        if !self.persist {
            return;
        }
        let saved = Saved {
            scene: self.doc.to_toml(),
            material: self.doc.material,
            object: self.doc.object,
            settings: self.settings.clone(),
        };
        eframe::set_value(storage, STORAGE_KEY, &saved);
    }

    fn persist_egui_memory(&self) -> bool {
        self.persist
    }
}

/// The hint shown while files are dragged over the window: what dropping them does.
fn paint_drop_hint(painter: &egui::Painter, rect: Rect) {
    painter.rect_filled(rect, 0.0, Color32::from_black_alpha(140));
    painter.text(
        rect.center(),
        egui::Align2::CENTER_CENTER,
        "Drop: .toml opens a scene, .obj/.gltf/.glb sets the mesh,\nimages go to the map slot under the pointer (else by file name)",
        egui::FontId::proportional(16.0),
        Color32::WHITE,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// eframe's storage as a map (eframe writes the same RON strings to a file).
    #[derive(Default)]
    struct Memory(HashMap<String, String>);

    impl eframe::Storage for Memory {
        fn get_string(&self, key: &str) -> Option<String> {
            self.0.get(key).cloned()
        }
        fn set_string(&mut self, key: &str, value: String) {
            self.0.insert(key.to_owned(), value);
        }
        fn remove_string(&mut self, key: &str) {
            self.0.remove(key);
        }
        fn flush(&mut self) {}
    }

    #[test]
    fn a_session_survives_the_storage_round_trip() {
        let mut doc = SceneDoc::default();
        doc.set_material_field("technique", Some(Value::String("exact".into())));
        doc.set_camera(Vec3::new(0.5, 1.0, 1.5), Vec3::ZERO);
        let settings = Settings {
            compare: true,
            compare_technique: "steep".into(),
            split: 0.3,
            overlay: Overlay::Fetches,
            overlay_opacity: 0.6,
            fetch_scale: 20.0,
            resolution: 0.5,
            export_path: "out/x.png".into(),
        };
        let saved = Saved { scene: doc.to_toml(), material: 0, object: 0, settings: settings.clone() };
        let mut storage = Memory::default();
        eframe::set_value(&mut storage, STORAGE_KEY, &saved);
        let back: Saved = eframe::get_value(&storage, STORAGE_KEY).expect("restores");
        assert_eq!(back.settings, settings);
        let restored = SceneDoc::from_text(&back.scene, Path::new(".")).expect("the scene parses");
        assert_eq!(restored, doc);
    }

    #[test]
    fn settings_from_an_older_version_fill_in_defaults() {
        // A saved session that predates some fields still loads (serde default).
        let mut storage = Memory::default();
        eframe::Storage::set_string(&mut storage, STORAGE_KEY, "(settings: (compare: true))".into());
        let back: Saved = eframe::get_value(&storage, STORAGE_KEY).expect("restores");
        assert!(back.settings.compare);
        assert_eq!(back.settings.overlay, Overlay::None);
        assert_eq!(back.settings.resolution, 1.0);
    }
}
