//! The scene being tuned, kept as a scene file (docs/SCENES.md) in memory.
//!
//! Every control of the viewer edits this document, and every frame renders what
//! `pomkit_io::scene::parse_scene_cached` makes of it. "Export" writes the same text, so
//! `pomkit render` on the exported file draws the viewer's picture by construction.

use std::path::{Path, PathBuf};

use pomkit_core::glam::Vec3;
use pomkit_core::scene::Scene;
use pomkit_io::scene::{SceneCache, SceneError, parse_scene_cached};
use toml::{Table, Value};

/// The scene the viewer opens with when it has no file and no saved session: one plane of
/// built-in bricks under a low sun, seen at 45 degrees.
pub const DEFAULT_SCENE: &str = r#"background = [0.02, 0.02, 0.03]
ambient = [0.05, 0.05, 0.06]

[camera]
eye = [0.0, 1.45, 2.55]
target = [0.0, 0.0, 0.0]
fov = 45.0

[[light]]
type = "directional"
direction = [-0.55, 0.55, -0.35]
color = [1.0, 0.96, 0.9]
intensity = 2.5

[[material]]
name = "bricks"
albedo = "builtin:bricks"
height = "builtin:bricks"
base_color = [1.0, 1.0, 1.0]
technique = "exact"
depth_scale = 0.06
min_samples = 8
max_samples = 32
refine = 2
shadow = "soft"
softness = 0.08

[[object]]
name = "surface"
mesh = "plane"
size = 2.0
uv_repeat = 2.0
material = "bricks"
"#;

/// The built-in shapes the viewer offers, and their parameters (docs/SCENES.md).
pub const SHAPES: [(&str, &[&str]); 7] = [
    ("plane", &["size", "segments"]),
    ("quad", &["size"]),
    ("disc", &["radius", "segments"]),
    ("cube", &["size"]),
    ("sphere", &["radius", "rings", "segments"]),
    ("cylinder", &["radius", "height", "segments"]),
    ("torus", &["radius", "tube_radius", "segments", "tube_segments"]),
];

/// Every shape parameter a scene file knows.
const SHAPE_PARAMS: [&str; 7] = ["size", "radius", "height", "tube_radius", "segments", "rings", "tube_segments"];

/// Why a scene document could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum DocError {
    /// The file could not be read.
    #[error("cannot read scene {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// The text is not a valid scene.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The viewer cannot edit this scene.
    #[error("{0}")]
    Unsupported(String),
}

/// A scene file being edited, with paths made absolute so that it renders (and exports) the
/// same wherever it is written.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneDoc {
    table: Table,
    /// The material the panel edits (index into `[[material]]`).
    pub material: usize,
    /// The object whose mesh the panel edits (index into `[[object]]`).
    pub object: usize,
}

impl Default for SceneDoc {
    fn default() -> Self {
        Self::from_text(DEFAULT_SCENE, Path::new(".")).unwrap_or_else(|_| Self::empty())
    }
}

impl SceneDoc {
    fn empty() -> Self {
        Self { table: Table::new(), material: 0, object: 0 }
    }

    /// Opens a scene file, or a texture-library folder ([`pomkit_io::library`]) as the scene
    /// `pomkit render --material` draws: one plane whose `[[material]]` has `folder` set to it.
    ///
    /// # Errors
    /// [`DocError`] naming the file when it cannot be read or is not a valid scene (for a
    /// folder, when its maps cannot be told or loaded).
    pub fn open(path: &Path) -> Result<Self, DocError> {
        if pomkit_io::scene::is_gltf(path) {
            return Self::open_gltf(path);
        }
        if path.is_dir() {
            let text = pomkit_io::library::preview_scene(path);
            let doc = Self::parse(&text, path, Path::new("."))?;
            doc.build_named(path, &mut SceneCache::default())?;
            return Ok(doc);
        }
        let text = std::fs::read_to_string(path).map_err(|reason| DocError::Read { path: path.to_owned(), reason })?;
        let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let doc = Self::parse(&text, path, base)?;
        // Check now that the scene loads (textures, meshes), naming the file in errors.
        doc.build_named(path, &mut SceneCache::default())?;
        Ok(doc)
    }

    /// A glTF file as the scene `gltf = "FILE"` (docs/SCENES.md), with a `[[material]]` per
    /// material of the file, so that the panel tunes it: empty but for the name, and for a
    /// traced material its technique and `depth_scale` as the file gives them (the keys a
    /// `[[material]]` of a glTF material's name overrides); not the `depth_scale` of a material
    /// drawn at several UV scales, whose copies each have their own until the panel sets one.
    fn open_gltf(path: &Path) -> Result<Self, DocError> {
        let scene = pomkit_io::scene::load_scene(path)?;
        let file = std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
        let mut table = Table::new();
        table.insert("gltf".into(), Value::String(file.to_string_lossy().into_owned()));
        let names = pomkit_io::gltf::material_names(path)
            .map_err(|e| DocError::Unsupported(format!("{}: {e}", path.display())))?;
        let mut materials: Vec<Value> = Vec::new();
        // A material drawn at several UV scales is split into copies (`NAME ~2`...); the first
        // keeps the file's name, and a table of that name tunes them all.
        for (name, m) in names.iter().filter_map(|n| Some((n, scene.materials.iter().find(|m| &m.name == n)?))) {
            let mut t = Table::new();
            t.insert("name".into(), Value::String(name.clone()));
            if m.height.is_some() {
                t.insert("technique".into(), Value::String(m.technique.to_string()));
                // Split copies keep their own depths unless the panel sets one for all.
                let copy = format!("{name} ~");
                if !scene.materials.iter().any(|c| c.name.starts_with(&copy)) {
                    t.insert("depth_scale".into(), Value::Float(f64::from(m.depth_scale)));
                }
            }
            materials.push(Value::Table(t));
        }
        table.insert("material".into(), Value::Array(materials));
        let doc = Self::parse(&toml::to_string(&table).unwrap_or_default(), path, Path::new("."))?;
        doc.build_named(path, &mut SceneCache::default())?;
        Ok(doc)
    }

    /// A document from scene text whose relative paths are relative to `base_dir`. Checks the
    /// syntax and the structure, not the textures (see [`SceneDoc::build`]).
    ///
    /// # Errors
    /// [`DocError`] when the text is not a valid scene file.
    pub fn from_text(text: &str, base_dir: &Path) -> Result<Self, DocError> {
        Self::parse(text, Path::new("<scene>"), base_dir)
    }

    fn parse(text: &str, file: &Path, base_dir: &Path) -> Result<Self, DocError> {
        let mut table: Table = match text.parse() {
            Ok(t) => t,
            Err(_) => {
                // Let the scene loader word the syntax error (line, table, field).
                return Err(pomkit_io::scene::parse_scene_named(text, file, base_dir)
                    .err()
                    .map_or_else(|| DocError::Unsupported("the scene is not valid TOML".into()), DocError::Scene));
            }
        };
        absolutize(&mut table, base_dir);
        let doc = Self { table, material: 0, object: 0 };
        if doc.array("material").is_empty() {
            return Err(DocError::Unsupported(format!(
                "{}: the scene has no [[material]]; the viewer tunes a material, so it needs one",
                file.display()
            )));
        }
        if doc.array("object").is_empty() && !doc.table.contains_key("gltf") {
            return Err(DocError::Unsupported(format!("{}: the scene has no [[object]]", file.display())));
        }
        Ok(doc)
    }

    /// The scene file's text (every path absolute).
    #[must_use]
    pub fn to_toml(&self) -> String {
        toml::to_string(&self.table).unwrap_or_default()
    }

    /// The scene file without its camera and lights: equal for two documents that differ only
    /// in where they are seen from and lit from.
    #[must_use]
    pub fn structure_key(&self) -> String {
        let mut t = self.table.clone();
        t.remove("camera");
        t.remove("light");
        t.remove("ambient");
        toml::to_string(&t).unwrap_or_default()
    }

    /// Builds the scene, loading textures and meshes through `cache`.
    ///
    /// # Errors
    /// The scene loader's error for an invalid value or a texture or mesh that cannot be
    /// loaded.
    pub fn build(&self, cache: &mut SceneCache) -> Result<Scene, SceneError> {
        self.build_named(Path::new("<viewer>"), cache)
    }

    fn build_named(&self, file: &Path, cache: &mut SceneCache) -> Result<Scene, SceneError> {
        parse_scene_cached(&self.to_toml(), file, Path::new("."), cache)
    }

    fn array(&self, key: &str) -> &[Value] {
        self.table.get(key).and_then(Value::as_array).map_or(&[], Vec::as_slice)
    }

    fn entry(&self, key: &str, index: usize) -> Option<&Table> {
        self.array(key).get(index).and_then(Value::as_table)
    }

    fn entry_mut(&mut self, key: &str, index: usize) -> Option<&mut Table> {
        self.table.get_mut(key)?.as_array_mut()?.get_mut(index)?.as_table_mut()
    }

    /// Names of the `[[kind]]` tables (the loader's defaults for unnamed ones).
    fn names(&self, kind: &str) -> Vec<String> {
        (0..self.array(kind).len())
            .map(|i| {
                self.entry(kind, i)
                    .and_then(|t| t.get("name"))
                    .and_then(Value::as_str)
                    .map_or_else(|| format!("{kind} {}", i + 1), str::to_owned)
            })
            .collect()
    }

    /// Sets (or, with `None`, removes) `key` of table `index` of `[[kind]]`.
    fn set_field(&mut self, kind: &str, index: usize, key: &str, value: Option<Value>) {
        if let Some(t) = self.entry_mut(kind, index) {
            match value {
                Some(v) => t.insert(key.to_owned(), v),
                None => t.remove(key),
            };
        }
    }

    /// Names of the materials, in order.
    #[must_use]
    pub fn material_names(&self) -> Vec<String> {
        self.names("material")
    }

    /// Names of the objects, in order.
    #[must_use]
    pub fn object_names(&self) -> Vec<String> {
        self.names("object")
    }

    /// A field of the selected material, if the file sets it.
    #[must_use]
    pub fn material_field(&self, key: &str) -> Option<&Value> {
        self.entry("material", self.material)?.get(key)
    }

    /// Sets (or, with `None`, removes) a field of the selected material.
    pub fn set_material_field(&mut self, key: &str, value: Option<Value>) {
        self.set_field("material", self.material, key, value);
    }

    /// A field of the selected object, if the file sets it.
    #[must_use]
    pub fn object_field(&self, key: &str) -> Option<&Value> {
        self.entry("object", self.object)?.get(key)
    }

    /// Sets (or removes) a field of the selected object.
    pub fn set_object_field(&mut self, key: &str, value: Option<Value>) {
        self.set_field("object", self.object, key, value);
    }

    /// The selected object's mesh: a built-in shape name or a file path.
    #[must_use]
    pub fn mesh(&self) -> String {
        self.object_field("mesh").and_then(Value::as_str).unwrap_or("plane").to_owned()
    }

    /// Gives the selected object a built-in shape or a mesh file, dropping the previous shape's
    /// parameters that the new one does not take.
    pub fn set_mesh(&mut self, mesh: &str) {
        let takes: &[&str] = SHAPES.iter().find(|(s, _)| *s == mesh).map_or(&[], |(_, p)| p);
        for p in SHAPE_PARAMS {
            if !takes.contains(&p) {
                self.set_object_field(p, None);
            }
        }
        self.set_object_field("mesh", Some(Value::String(mesh.to_owned())));
    }

    /// Camera eye and target.
    #[must_use]
    pub fn camera(&self) -> (Vec3, Vec3) {
        let cam = self.table.get("camera").and_then(Value::as_table);
        let get = |k: &str, d: Vec3| cam.and_then(|c| c.get(k)).and_then(vec3).unwrap_or(d);
        (get("eye", Vec3::new(0.0, 2.0, 4.0)), get("target", Vec3::ZERO))
    }

    /// The camera's vertical field of view in degrees (the loader's default when the file
    /// leaves it out or holds something that is not a number).
    #[must_use]
    pub fn fov_deg(&self) -> f32 {
        let fov = self.table.get("camera").and_then(Value::as_table).and_then(|c| c.get("fov"));
        let fov = fov.and_then(|v| v.as_float().or_else(|| v.as_integer().map(|n| n as f64)));
        fov.map_or(pomkit_core::scene::Camera::default().fov_y_deg, |f| f as f32)
    }

    /// Moves the camera.
    pub fn set_camera(&mut self, eye: Vec3, target: Vec3) {
        let cam = self.table.entry("camera").or_insert_with(|| Value::Table(Table::new()));
        if let Some(c) = cam.as_table_mut() {
            c.insert("eye".into(), vec3_value(eye));
            c.insert("target".into(), vec3_value(target));
        }
    }

    /// Direction toward the first directional light, if the scene has one.
    #[must_use]
    pub fn light_direction(&self) -> Option<Vec3> {
        self.first_directional().and_then(|i| self.entry("light", i)?.get("direction").and_then(vec3))
    }

    fn first_directional(&self) -> Option<usize> {
        (0..self.array("light").len()).find(|&i| {
            self.entry("light", i).and_then(|l| l.get("type")).and_then(Value::as_str).unwrap_or("directional")
                == "directional"
        })
    }

    /// Points the first directional light (adding one when the scene has none) toward `dir`.
    pub fn set_light_direction(&mut self, dir: Vec3) {
        let index = match self.first_directional() {
            Some(i) => i,
            None => {
                let lights = self.table.entry("light").or_insert_with(|| Value::Array(Vec::new()));
                let Some(a) = lights.as_array_mut() else { return };
                let mut l = Table::new();
                l.insert("type".into(), Value::String("directional".into()));
                a.push(Value::Table(l));
                a.len() - 1
            }
        };
        if let Some(l) = self.entry_mut("light", index) {
            l.insert("direction".into(), vec3_value(dir));
        }
    }

    /// Sets a map of the selected material (`albedo`, `height` or `normal`) to a file or a
    /// `builtin:` pattern, or removes it.
    pub fn set_map(&mut self, slot: MapSlot, source: Option<String>) {
        let key = slot.key();
        self.set_material_field(key, source.map(Value::String));
        if slot == MapSlot::Normal && self.material_field("normal").is_none() {
            self.set_material_field("normal_y_down", None);
        }
        if slot == MapSlot::Height && self.material_field("height").is_none() {
            for k in ["depth_map", "channel", "normalize"] {
                self.set_material_field(k, None);
            }
            // Without a height map only flat and normal mapping make sense.
            let t = self.material_field("technique").and_then(Value::as_str).unwrap_or("exact");
            if !matches!(t, "flat" | "normal") {
                self.set_material_field("technique", Some(Value::String("normal".into())));
            }
        }
    }
}

/// A material's map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MapSlot {
    /// Colour.
    Albedo,
    /// Height (or depth).
    Height,
    /// Tangent-space normals.
    Normal,
}

impl MapSlot {
    /// Every slot.
    pub const ALL: [MapSlot; 3] = [MapSlot::Albedo, MapSlot::Height, MapSlot::Normal];

    /// The scene file's field.
    #[must_use]
    pub fn key(self) -> &'static str {
        match self {
            MapSlot::Albedo => "albedo",
            MapSlot::Height => "height",
            MapSlot::Normal => "normal",
        }
    }

    /// Guesses the slot of a dropped image from its file name: "normal"/"nrm" is a normal
    /// map, "height"/"disp"/"depth"/"bump" a height map, anything else a colour map.
    #[must_use]
    pub fn guess(path: &Path) -> MapSlot {
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("").to_ascii_lowercase();
        let has = |words: &[&str]| words.iter().any(|w| name.contains(w));
        if has(&["normal", "nrm", "norm"]) || name.ends_with("_n") {
            MapSlot::Normal
        } else if has(&["height", "disp", "depth", "bump", "parallax"]) || name.ends_with("_h") {
            MapSlot::Height
        } else {
            MapSlot::Albedo
        }
    }
}

/// What a file dropped on the window or picked in the browser is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// A scene file (.toml).
    Scene,
    /// A mesh (.obj, .gltf, .glb).
    Mesh,
    /// An image (anything else the image loader may read).
    Image,
}

impl FileKind {
    /// By extension.
    #[must_use]
    pub fn of(path: &Path) -> FileKind {
        // A folder is opened as a texture-library material.
        if path.is_dir() {
            return FileKind::Scene;
        }
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("toml") => FileKind::Scene,
            Some("obj" | "gltf" | "glb") => FileKind::Mesh,
            _ => FileKind::Image,
        }
    }
}

fn vec3(v: &Value) -> Option<Vec3> {
    let a = v.as_array()?;
    let f = |i: usize| a.get(i).and_then(|x| x.as_float().or_else(|| x.as_integer().map(|n| n as f64)));
    Some(Vec3::new(f(0)? as f32, f(1)? as f32, f(2)? as f32))
}

fn vec3_value(v: Vec3) -> Value {
    // Rounded to 5 decimals so that exported files stay readable.
    let r = |x: f32| Value::Float((f64::from(x) * 1e5).round() / 1e5);
    Value::Array(vec![r(v.x), r(v.y), r(v.z)])
}

/// Makes every texture and mesh path absolute (relative to `base`), leaving `builtin:` maps and
/// built-in shapes alone.
fn absolutize(table: &mut Table, base: &Path) {
    let base = std::path::absolute(base).unwrap_or_else(|_| base.to_owned());
    let fix = |v: &mut Value| {
        if let Value::String(s) = v {
            let p = Path::new(s.as_str());
            if !s.starts_with("builtin:") && p.is_relative() {
                *s = base.join(p).to_string_lossy().into_owned();
            }
        }
    };
    if let Some(v) = table.get_mut("gltf") {
        fix(v);
    }
    if let Some(ms) = table.get_mut("material").and_then(Value::as_array_mut) {
        for m in ms.iter_mut().filter_map(Value::as_table_mut) {
            // Every key that names a file (the loader's list, so a new one is not missed).
            for key in pomkit_core::params::FILE_KEYS.into_iter().filter(|k| *k != "name") {
                if let Some(v) = m.get_mut(key) {
                    fix(v);
                }
            }
        }
    }
    let materials: Vec<String> = table
        .get("material")
        .and_then(Value::as_array)
        .map_or(&[][..], Vec::as_slice)
        .iter()
        .enumerate()
        .map(|(i, m)| {
            m.get("name").and_then(Value::as_str).map_or_else(|| format!("material {}", i + 1), str::to_owned)
        })
        .collect();
    if let Some(os) = table.get_mut("object").and_then(Value::as_array_mut) {
        for o in os.iter_mut().filter_map(Value::as_table_mut) {
            // `material = "FOLDER"`: a texture-library folder, when no material has that name.
            let folder = o
                .get("material")
                .and_then(Value::as_str)
                .is_some_and(|m| !m.trim().is_empty() && !materials.iter().any(|n| n == m) && base.join(m).is_dir());
            if folder && let Some(v) = o.get_mut("material") {
                fix(v);
            }
            let shape = o.get("mesh").and_then(Value::as_str).map(|s| s.trim().to_ascii_lowercase());
            let builtin = shape.as_deref().is_some_and(|s| SHAPES.iter().any(|(n, _)| *n == s));
            if !builtin && let Some(v) = o.get_mut("mesh") {
                fix(v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gltf_file_opens_as_its_scene_with_its_materials_to_tune() {
        use pomkit_core::Technique;
        use pomkit_io::gltf::{SampleOptions, write_sample};
        let dir = tempfile::tempdir().unwrap();
        // A 2 x 2 plane with UVs 0..1 and a displacement 0.1 deep: depth_scale 0.1 / 2 = 0.05.
        let file = write_sample(dir.path(), &SampleOptions::default()).unwrap();
        let mut doc = SceneDoc::open(&file).expect("the sample opens");
        assert_eq!(doc.material_names(), ["Bricks"]);
        assert_eq!(doc.material_field("technique").and_then(Value::as_str), Some("exact"));
        let depth = doc.material_field("depth_scale").and_then(Value::as_float).unwrap();
        assert!((depth - 0.05).abs() < 1e-6, "{depth}");
        let scene = doc.build(&mut SceneCache::default()).unwrap();
        assert_eq!(scene.objects.len(), 1);
        assert_eq!(scene.materials[0].technique, Technique::Exact);
        // The panel's edits reach the file's material, and the doc survives its TOML round trip.
        doc.set_material_field("technique", Some(Value::String("relief".into())));
        let again = SceneDoc::from_text(&doc.to_toml(), Path::new("/elsewhere")).expect("round trip");
        let scene = again.build(&mut SceneCache::default()).unwrap();
        assert_eq!(scene.materials[0].technique, Technique::Relief);
        // A material drawn at two UV scales (the repository's rocks.gltf: a floor whose UV unit
        // is 1 long and a box whose is 0.8) is split into two copies with their own
        // depth_scale; the doc lists the file's material once, and it builds.
        let rocks = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rocks.gltf");
        let heights = pomkit_core::HeightField::from_height_fn(8, 8, |x, y| ((x + y) % 4) as f32 / 3.0);
        let traced = dir.path().join("rocks_pom.gltf");
        let choice = pomkit_io::gltf::MaterialChoice::Name("Rocks".into());
        pomkit_io::gltf::attach(&rocks, &traced, &choice, &heights, pomkit_io::gltf::AttachDepth::Units(0.05), &[])
            .unwrap();
        let doc = SceneDoc::open(&traced).expect("a split material opens");
        assert_eq!(doc.material_names(), ["Rocks"]);
        let scene = doc.build(&mut SceneCache::default()).unwrap();
        let depths: Vec<f32> = scene.materials.iter().map(|m| m.depth_scale).collect();
        assert_eq!(depths.len(), 2, "{depths:?}");
        assert!((depths[0] - 0.05).abs() < 1e-5 && (depths[1] - 0.0625).abs() < 1e-5, "{depths:?}");
        // Without the extension the material is not traced, and the doc says so.
        let plain = SampleOptions { name: "plain".into(), displacement: None, ..SampleOptions::default() };
        let doc = SceneDoc::open(&write_sample(dir.path(), &plain).unwrap()).unwrap();
        assert_eq!(doc.material_field("technique"), None);
        assert_eq!(doc.build(&mut SceneCache::default()).unwrap().materials[0].technique, Technique::Normal);
    }

    #[test]
    fn default_scene_builds_and_round_trips() {
        let doc = SceneDoc::default();
        assert_eq!(doc.material_names(), ["bricks"]);
        let scene = doc.build(&mut SceneCache::default()).expect("default scene");
        assert_eq!(scene.materials[0].depth_scale, 0.06);
        assert_eq!(scene.objects.len(), 1);
        let again = SceneDoc::from_text(&doc.to_toml(), Path::new("/elsewhere")).expect("round trip");
        assert_eq!(again, doc);
    }

    #[test]
    fn relative_paths_become_absolute_and_builtins_stay() {
        let text = DEFAULT_SCENE
            .replace("albedo = \"builtin:bricks\"", "albedo = \"maps/a.png\"\ncone_map = \"maps/a_cone.png\"")
            .replace("mesh = \"plane\"\nsize = 2.0", "mesh = \"models/statue.obj\"");
        let base = Path::new("/data/scenes");
        let doc = SceneDoc::from_text(&text, base).expect("parses");
        assert_eq!(doc.material_field("albedo").and_then(Value::as_str), Some("/data/scenes/maps/a.png"));
        assert_eq!(doc.material_field("cone_map").and_then(Value::as_str), Some("/data/scenes/maps/a_cone.png"));
        assert_eq!(doc.material_field("height").and_then(Value::as_str), Some("builtin:bricks"));
        assert_eq!(doc.mesh(), "/data/scenes/models/statue.obj");
    }

    #[test]
    fn edits_reach_the_built_scene() {
        let mut doc = SceneDoc::default();
        doc.set_material_field("technique", Some(Value::String("relief".into())));
        doc.set_material_field("binary_steps", Some(Value::Integer(9)));
        doc.set_camera(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, 0.5, 0.0));
        doc.set_light_direction(Vec3::new(0.0, 1.0, 0.0));
        doc.set_mesh("torus");
        let scene = doc.build(&mut SceneCache::default()).expect("builds");
        let m = &scene.materials[0];
        assert_eq!(m.technique, pomkit_core::trace::Technique::Relief);
        assert_eq!(m.trace.binary_steps, 9);
        assert_eq!(scene.camera.eye, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(scene.camera.target, Vec3::new(0.0, 0.5, 0.0));
        match scene.lights[0] {
            pomkit_core::scene::Light::Directional { direction, .. } => assert_eq!(direction, Vec3::Y),
            pomkit_core::scene::Light::Point { .. } => panic!("expected the directional light"),
        }
        // The plane's `size` was dropped: a torus does not take it (the loader would refuse it).
        assert!(doc.object_field("size").is_none());
        assert!(scene.objects[0].mesh.triangle_count() > 1000);
    }

    /// A folder of ambientCG-style maps: colour, OpenGL normal, displacement (8 x 8).
    fn library_folder(dir: &Path) {
        image::RgbImage::from_pixel(8, 8, image::Rgb([200, 100, 50])).save(dir.join("Rock_1K_Color.png")).unwrap();
        image::RgbImage::from_pixel(8, 8, image::Rgb([128, 200, 200])).save(dir.join("Rock_1K_NormalGL.png")).unwrap();
        image::GrayImage::from_fn(8, 8, |x, _| image::Luma([(x * 30) as u8]))
            .save(dir.join("Rock_1K_Displacement.png"))
            .unwrap();
    }

    #[test]
    fn a_texture_library_folder_opens_as_a_tunable_material() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("Rock");
        std::fs::create_dir(&dir).unwrap();
        library_folder(&dir);
        assert_eq!(FileKind::of(&dir), FileKind::Scene, "a dropped folder opens as a scene");
        let mut doc = SceneDoc::open(&dir).expect("the folder opens");
        assert_eq!(doc.material_names(), ["Rock"]);
        let folder = doc.material_field("folder").and_then(Value::as_str).map(PathBuf::from).unwrap();
        assert!(folder.is_absolute() && folder.ends_with("Rock"), "{}", folder.display());
        // The panel's edits override the folder's defaults.
        doc.set_material_field("technique", Some(Value::String("relief".into())));
        let scene = doc.build(&mut SceneCache::default()).expect("builds");
        let m = &scene.materials[0];
        assert_eq!(m.technique, pomkit_core::trace::Technique::Relief);
        assert_eq!(m.albedo.as_ref().map(|t| t.width()), Some(8));
        assert!(m.normal_map.is_some() && m.height.is_some());
        // Exported and opened elsewhere, it still finds the folder.
        let again = SceneDoc::from_text(&doc.to_toml(), Path::new("/elsewhere")).expect("round trip");
        assert!(again.build(&mut SceneCache::default()).is_ok());
        // A folder without a height map is refused, naming it and what it holds.
        std::fs::remove_file(dir.join("Rock_1K_Displacement.png")).unwrap();
        let err = SceneDoc::open(&dir).expect_err("no height").to_string();
        assert!(err.contains("no height map") && err.contains("Rock_1K_Color.png"), "{err}");
    }

    #[test]
    fn an_objects_relative_folder_material_becomes_absolute() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::create_dir(tmp.path().join("Rock")).unwrap();
        library_folder(&tmp.path().join("Rock"));
        let text = DEFAULT_SCENE.replace("material = \"bricks\"\n", "material = \"Rock\"\n");
        let doc = SceneDoc::from_text(&text, tmp.path()).expect("parses");
        let material = doc.object_field("material").and_then(Value::as_str).unwrap();
        assert_eq!(Path::new(material), tmp.path().join("Rock"));
        let scene = doc.build(&mut SceneCache::default()).expect("builds from anywhere");
        assert_eq!(scene.objects[0].material, 1, "the folder's material, after the table's");
    }

    #[test]
    fn removing_the_height_map_leaves_a_valid_scene() {
        let mut doc = SceneDoc::default();
        doc.set_material_field("depth_map", Some(Value::Boolean(true)));
        doc.set_map(MapSlot::Height, None);
        let scene = doc.build(&mut SceneCache::default()).expect("a material without height is valid");
        assert!(scene.materials[0].height.is_none());
        assert_eq!(scene.materials[0].technique, pomkit_core::trace::Technique::Normal);
    }

    #[test]
    fn a_light_is_added_when_the_scene_has_no_directional_one() {
        let text = DEFAULT_SCENE.replace(
            "type = \"directional\"\ndirection = [-0.55, 0.55, -0.35]",
            "type = \"point\"\nposition = [0.0, 3.0, 0.0]",
        );
        let mut doc = SceneDoc::from_text(&text, Path::new(".")).expect("parses");
        assert_eq!(doc.light_direction(), None);
        doc.set_light_direction(Vec3::new(0.0, 1.0, 0.0));
        let scene = doc.build(&mut SceneCache::default()).expect("builds");
        assert_eq!(scene.lights.len(), 2);
    }

    #[test]
    fn bad_scenes_are_refused_with_the_loader_message() {
        let err = SceneDoc::from_text("[camera\n", Path::new(".")).expect_err("syntax");
        assert!(err.to_string().contains("line"), "{err}");
        let err = SceneDoc::from_text("[camera]\neye=[0,1,2]\ntarget=[0,0,0]\n", Path::new(".")).expect_err("empty");
        assert!(err.to_string().contains("[[material]]"), "{err}");
    }

    #[test]
    fn dropped_files_are_sorted_by_name() {
        assert_eq!(MapSlot::guess(Path::new("rock_normal.png")), MapSlot::Normal);
        assert_eq!(MapSlot::guess(Path::new("rock_Height.exr")), MapSlot::Height);
        assert_eq!(MapSlot::guess(Path::new("rock_disp.tif")), MapSlot::Height);
        assert_eq!(MapSlot::guess(Path::new("rock_basecolor.jpg")), MapSlot::Albedo);
        assert_eq!(FileKind::of(Path::new("a.GLB")), FileKind::Mesh);
        assert_eq!(FileKind::of(Path::new("s.toml")), FileKind::Scene);
    }
}
