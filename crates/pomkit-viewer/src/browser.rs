//! A small file browser inside the window, for opening maps, meshes and scenes. (It needs no
//! desktop portal or GTK, so it works the same under Xvfb, over SSH and on a bare X server.)

use std::path::{Path, PathBuf};

use eframe::egui;

use crate::doc::MapSlot;

/// What a picked file is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Purpose {
    /// A scene file.
    Scene,
    /// The selected object's mesh.
    Mesh,
    /// A map of the selected material.
    Map(MapSlot),
}

impl Purpose {
    fn title(self) -> String {
        match self {
            Purpose::Scene => "Open a scene".into(),
            Purpose::Mesh => "Open a mesh".into(),
            Purpose::Map(s) => format!("Open the {} map", s.key()),
        }
    }

    /// File extensions shown (lowercase).
    fn extensions(self) -> &'static [&'static str] {
        match self {
            Purpose::Scene => &["toml"],
            Purpose::Mesh => &["obj", "gltf", "glb"],
            Purpose::Map(_) => &["png", "jpg", "jpeg", "tif", "tiff", "exr"],
        }
    }
}

/// The browser's state.
pub struct Browser {
    purpose: Purpose,
    dir: PathBuf,
    typed: String,
    entries: Vec<(String, bool)>,
    error: Option<String>,
}

impl Browser {
    /// A browser for `purpose`, in the current folder.
    #[must_use]
    pub fn new(purpose: Purpose) -> Self {
        let dir = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("/"));
        let mut b = Self {
            purpose,
            dir: dir.clone(),
            typed: dir.to_string_lossy().into_owned(),
            entries: Vec::new(),
            error: None,
        };
        b.list();
        b
    }

    /// What the picked file is for.
    #[must_use]
    pub fn purpose(&self) -> Purpose {
        self.purpose
    }

    fn list(&mut self) {
        self.entries.clear();
        self.error = None;
        match std::fs::read_dir(&self.dir) {
            Ok(rd) => {
                let exts = self.purpose.extensions();
                for e in rd.flatten() {
                    let name = e.file_name().to_string_lossy().into_owned();
                    if name.starts_with('.') {
                        continue;
                    }
                    let is_dir = e.path().is_dir();
                    let ext = Path::new(&name).extension().and_then(|x| x.to_str()).map(str::to_ascii_lowercase);
                    if is_dir || ext.is_some_and(|x| exts.contains(&x.as_str())) {
                        self.entries.push((name, is_dir));
                    }
                }
                self.entries.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.to_lowercase().cmp(&b.0.to_lowercase())));
            }
            Err(e) => self.error = Some(format!("cannot list {}: {e}", self.dir.display())),
        }
    }

    fn go(&mut self, dir: PathBuf) {
        self.dir = dir;
        self.typed = self.dir.to_string_lossy().into_owned();
        self.list();
    }

    /// Shows the window. `Some(Some(path))` when a file was picked, `Some(None)` when
    /// cancelled, `None` while open.
    pub fn show(&mut self, ctx: &egui::Context) -> Option<Option<PathBuf>> {
        let mut outcome = None;
        let mut open = true;
        egui::Window::new(self.purpose.title()).open(&mut open).default_size([460.0, 420.0]).collapsible(false).show(
            ctx,
            |ui| {
                ui.horizontal(|ui| {
                    if ui.button("Up").clicked()
                        && let Some(p) = self.dir.parent()
                    {
                        self.go(p.to_owned());
                    }
                    let r = ui.add(egui::TextEdit::singleline(&mut self.typed).desired_width(f32::INFINITY));
                    if r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                        let p = PathBuf::from(self.typed.trim());
                        if p.is_dir() {
                            self.go(p);
                        } else if p.is_file() {
                            outcome = Some(Some(p));
                        } else {
                            self.error = Some(format!("{} does not exist", p.display()));
                        }
                    }
                });
                ui.label(
                    egui::RichText::new(format!("Showing folders and {}", self.purpose.extensions().join(", ")))
                        .weak()
                        .small(),
                );
                if let Some(e) = &self.error {
                    ui.colored_label(egui::Color32::LIGHT_RED, e);
                }
                egui::ScrollArea::vertical().max_height(320.0).show(ui, |ui| {
                    let mut go = None;
                    for (name, is_dir) in &self.entries {
                        let label = if *is_dir { format!("[{name}]") } else { name.clone() };
                        if ui.selectable_label(false, label).clicked() {
                            let p = self.dir.join(name);
                            if *is_dir {
                                go = Some(p);
                            } else {
                                outcome = Some(Some(p));
                            }
                        }
                    }
                    if let Some(p) = go {
                        self.go(p);
                    }
                });
            },
        );
        if !open {
            outcome = Some(None);
        }
        outcome
    }
}
