//! Texture-library folders as materials: the maps of a folder (ambientCG, Poly Haven and
//! Quixel-like exports) found by the names libraries give them.
//!
//! [`find_maps`] reads one folder (not its subfolders) and tells which file is the colour map,
//! the normal map, the height map, the roughness map and the ambient occlusion map, and which
//! files it ignored and why. The scene loader uses it for `material = "FOLDER"` on an object
//! and `folder = "FOLDER"` on a `[[material]]` (docs/SCENES.md, "Texture-library folders");
//! `pomkit render --material FOLDER` prints it.
//!
//! # Names
//!
//! A file name (without its extension) is cut into lower-case words at `_`, `-`, `.`, spaces
//! and camel case (`NormalGL` is `normal gl`, `AmbientOcclusion` is `ambient occlusion`; a
//! digit followed by a capital, as in `1K`, is not cut). Reading from the end of the name, the
//! first word, or pair of words written together, that names a map decides the file (so the
//! asset name `rough_plaster_brick` in `rough_plaster_brick_diff_1k.jpg` does not make it a
//! roughness map):
//!
//! | map | words |
//! |---|---|
//! | colour | `color`, `colour`, `albedo`, `basecolor` (`base_color`), `diffuse`, `diff`, `col` |
//! | normal, OpenGL (+Y up) | `normalgl`, `nor_gl`, `normal_gl`; and `normal`, `nor`, `nrm` (pomkit's default) |
//! | normal, DirectX (+Y down) | `normaldx`, `nor_dx`, `normal_dx`: read with `normal_y_down` |
//! | height | `displacement`, `height`, `disp`, `heightmap` (`height_map`); `bump` only when none of these |
//! | roughness | `roughness`, `rough` |
//! | ambient occlusion | `ambientocclusion` (`ambient_occlusion`), `ao`, `occlusion` |
//!
//! Ignored, and listed with the reason: files whose name has a word `preview`, `thumb`,
//! `thumbnail`, `icon` or `swatch`; maps pomkit does not use (`metalness`, `specular`,
//! `opacity`, `arm`, ...); files whose name names no map (an ambientCG asset's preview
//! `Bricks076C.png`); files that are not images pomkit reads (by extension: PNG, JPEG, TIFF and
//! OpenEXR are read; `.txt`, `.usda`, `.mtlx` are not); hidden files; subfolders and anything
//! that is not a regular file.
//!
//! When a folder has both an OpenGL and a DirectX normal map (ambientCG ships both), the OpenGL
//! one is used and the DirectX one listed as ignored. Two candidates for one map (the same map
//! in two formats or two resolutions) are an error listing what was found for every map; so is
//! a folder without a height map, one without any map, and a path that is not a folder.
//!
//! # Roughness
//!
//! The renderers shade with a Blinn-Phong lobe (`specular`, `shininess`). A roughness map sets
//! `shininess` from its mean roughness `r` by the Beckmann-to-Phong relation
//! ([`shininess_from_roughness`]): `alpha = r^2`, `shininess = 2 / alpha^2 - 2`, clamped to
//! [`MIN_SHININESS`]..=[`MAX_SHININESS`]. The renderers have no ambient occlusion input: an
//! ambient occlusion map is reported as found and is not read.

use std::fmt::{self, Write as _};
use std::path::{Path, PathBuf};

/// The most entries a texture-library folder may hold: a folder with more is refused rather
/// than listed (texture libraries ship a few dozen files per material).
pub const MAX_FOLDER_ENTRIES: usize = 10_000;

/// The least `shininess` a roughness map gives (fully rough: `2 / 1 - 2 = 0` would be no lobe).
pub const MIN_SHININESS: f32 = 1.0;

/// The largest `shininess` a roughness map gives (a mirror, roughness 0, would be infinite).
pub const MAX_SHININESS: f32 = 4096.0;

/// A map of a texture-library material.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MapKind {
    /// The colour map (sRGB), the scene's `albedo`.
    Color,
    /// The tangent-space normal map, the scene's `normal`.
    Normal,
    /// The height (displacement) map, white = high, the scene's `height`.
    Height,
    /// The roughness map: its mean sets `shininess`.
    Roughness,
    /// The ambient occlusion map: found, not used (the renderers have no input for it).
    AmbientOcclusion,
}

impl MapKind {
    /// Every map, in listing order.
    pub const ALL: [MapKind; 5] =
        [MapKind::Color, MapKind::Normal, MapKind::Height, MapKind::Roughness, MapKind::AmbientOcclusion];

    /// The map's name in listings and errors.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            MapKind::Color => "colour",
            MapKind::Normal => "normal",
            MapKind::Height => "height",
            MapKind::Roughness => "roughness",
            MapKind::AmbientOcclusion => "ambient occlusion",
        }
    }
}

impl fmt::Display for MapKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A file of the folder that is not one of the maps used, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ignored {
    /// The file (or subfolder).
    pub path: PathBuf,
    /// Why it was left out, e.g. `a preview` or `not an image pomkit reads`.
    pub reason: String,
}

/// What [`find_maps`] found in a folder: which file is which map, and which were ignored.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LibraryMaps {
    /// The folder, as given.
    pub folder: PathBuf,
    /// The colour map.
    pub color: Option<PathBuf>,
    /// The normal map.
    pub normal: Option<PathBuf>,
    /// The normal map is DirectX-style (+Y down; its name says `dx`): read it with the y flip.
    pub normal_y_down: bool,
    /// The height map. `None` only from [`find_maps_except`] when the height is given
    /// elsewhere.
    pub height: Option<PathBuf>,
    /// The height map is a bump map (named `bump`; taken as no other height map was found).
    pub height_is_bump: bool,
    /// The roughness map.
    pub roughness: Option<PathBuf>,
    /// The ambient occlusion map (reported, not used).
    pub ambient_occlusion: Option<PathBuf>,
    /// Every other entry of the folder, with the reason, in name order.
    pub ignored: Vec<Ignored>,
}

impl LibraryMaps {
    /// The file found for `kind`.
    #[must_use]
    pub fn map(&self, kind: MapKind) -> Option<&Path> {
        match kind {
            MapKind::Color => self.color.as_deref(),
            MapKind::Normal => self.normal.as_deref(),
            MapKind::Height => self.height.as_deref(),
            MapKind::Roughness => self.roughness.as_deref(),
            MapKind::AmbientOcclusion => self.ambient_occlusion.as_deref(),
        }
    }

    /// Every map found (the ambient occlusion map too, which is not read): the files a program
    /// must not write over.
    #[must_use]
    pub fn files(&self) -> Vec<PathBuf> {
        MapKind::ALL.iter().filter_map(|&k| self.map(k)).map(Path::to_path_buf).collect()
    }

    /// One line per map and per ignored file, for people: `normal: x_NormalGL.png (OpenGL, +Y
    /// up)`, `ignored: x.usda (not an image pomkit reads)`.
    #[must_use]
    pub fn lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        for kind in MapKind::ALL {
            let Some(path) = self.map(kind) else {
                let none = match kind {
                    MapKind::Height => "none here (given in the scene)",
                    _ => "none",
                };
                lines.push(format!("{kind}: {none}"));
                continue;
            };
            let note = match kind {
                MapKind::Normal if self.normal_y_down => " (DirectX, +Y down: read with the y flip)",
                MapKind::Normal => " (OpenGL, +Y up)",
                MapKind::Height if self.height_is_bump => " (a bump map, as there is no displacement map)",
                MapKind::Roughness => " (its mean sets shininess)",
                MapKind::AmbientOcclusion => " (found, unused: the renderers have no ambient occlusion input)",
                _ => "",
            };
            lines.push(format!("{kind}: {}{note}", file_name(path)));
        }
        for i in &self.ignored {
            lines.push(format!("ignored: {} ({})", file_name(&i.path), i.reason));
        }
        lines
    }
}

/// Why a folder is not a texture-library material. Every variant names the folder; those about
/// its contents list what was found for every map.
#[derive(Debug, thiserror::Error)]
pub enum LibraryError {
    /// The path does not exist, or is not a folder.
    #[error("{}: {reason}", crate::shown(path))]
    NotAFolder {
        /// The path.
        path: PathBuf,
        /// Why, e.g. `not a folder (a file)`.
        reason: String,
    },
    /// The folder could not be listed.
    #[error("cannot list the folder {}: {reason}", crate::shown(path))]
    Read {
        /// The folder.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The folder holds more than [`MAX_FOLDER_ENTRIES`] entries.
    #[error(
        "the folder {} has more than {MAX_FOLDER_ENTRIES} entries: a texture-library material has a few maps",
        crate::shown(path)
    )]
    TooMany {
        /// The folder.
        path: PathBuf,
    },
    /// No file of the folder is named as a map.
    #[error("the folder {} has no texture maps (found: {found})", crate::shown(path))]
    NoMaps {
        /// The folder.
        path: PathBuf,
        /// What was found, every map and the ignored files.
        found: String,
    },
    /// The folder has maps, but no height (displacement) map.
    #[error(
        "the folder {} has no height map (a file named displacement, height, disp, heightmap or bump); found: {found}",
        crate::shown(path)
    )]
    NoHeight {
        /// The folder.
        path: PathBuf,
        /// What was found.
        found: String,
    },
    /// Two or more files are candidates for one map.
    #[error(
        "the folder {} has {} candidates for the {map} map: {}; keep one (or name it in a [[material]] with folder = ...); found: {found}",
        crate::shown(path),
        candidates.len(),
        names(candidates)
    )]
    Ambiguous {
        /// The folder.
        path: PathBuf,
        /// The map.
        map: MapKind,
        /// The candidates, in name order.
        candidates: Vec<PathBuf>,
        /// What was found.
        found: String,
    },
}

/// Finds the maps of the texture-library folder `folder` (see the module documentation).
///
/// # Errors
/// [`LibraryError`]: `folder` is not a folder or cannot be listed, has too many entries, has
/// no maps, no height map, or two candidates for one map.
pub fn find_maps(folder: &Path) -> Result<LibraryMaps, LibraryError> {
    find_maps_except(folder, &[])
}

/// [`find_maps`], but the maps of `given` are not looked for (a scene names them itself):
/// their candidates are listed as ignored, so two of them are no error, and a folder without a
/// height map is no error when `given` holds [`MapKind::Height`].
///
/// # Errors
/// As [`find_maps`].
pub fn find_maps_except(folder: &Path, given: &[MapKind]) -> Result<LibraryMaps, LibraryError> {
    let meta = std::fs::metadata(folder)
        .map_err(|e| LibraryError::NotAFolder { path: folder.to_owned(), reason: format!("no such folder ({e})") })?;
    if !meta.is_dir() {
        let what = if meta.is_file() { "a file" } else { "not a regular file" };
        return Err(LibraryError::NotAFolder {
            path: folder.to_owned(),
            reason: format!("not a folder ({what}): a texture-library material is a folder of maps"),
        });
    }
    let read = |reason| LibraryError::Read { path: folder.to_owned(), reason };
    let mut entries = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(read)? {
        entries.push(entry.map_err(read)?.path());
        if entries.len() > MAX_FOLDER_ENTRIES {
            return Err(LibraryError::TooMany { path: folder.to_owned() });
        }
    }
    entries.sort();

    // Every entry classified.
    let mut candidates: Vec<(Word, PathBuf)> = Vec::new();
    let mut ignored = Vec::new();
    for path in entries {
        match classify(&path) {
            Ok(word) => candidates.push((word, path)),
            Err(reason) => ignored.push(Ignored { path, reason }),
        }
    }
    let of = |pred: &dyn Fn(Word) -> bool| -> Vec<PathBuf> {
        candidates.iter().filter(|(w, _)| pred(*w)).map(|(_, p)| p.clone()).collect()
    };
    let mut maps = LibraryMaps { folder: folder.to_owned(), ..LibraryMaps::default() };
    let mut ambiguous: Vec<(MapKind, Vec<PathBuf>)> = Vec::new();
    // One file of `files` (or none), or the error for two.
    let mut pick = |kind: MapKind, files: Vec<PathBuf>, ignored: &mut Vec<Ignored>| -> Option<PathBuf> {
        if given.contains(&kind) {
            ignored.extend(files.into_iter().map(|path| Ignored {
                path,
                reason: format!("a {kind} map, but the scene names the {kind} map itself"),
            }));
            return None;
        }
        match files.len() {
            0 => None,
            1 => files.into_iter().next(),
            _ => {
                ambiguous.push((kind, files));
                None
            }
        }
    };
    maps.color = pick(MapKind::Color, of(&|w| w == Word::Color), &mut ignored);
    let gl = of(&|w| w == Word::NormalGl);
    let dx = of(&|w| w == Word::NormalDx);
    if gl.is_empty() {
        maps.normal = pick(MapKind::Normal, dx, &mut ignored);
        maps.normal_y_down = maps.normal.is_some();
    } else {
        maps.normal = pick(MapKind::Normal, gl, &mut ignored);
        let reason = match &maps.normal {
            Some(used) => format!("a DirectX normal map; the OpenGL one, {}, is used", file_name(used)),
            None => "a DirectX normal map; the folder has an OpenGL one".to_owned(),
        };
        ignored.extend(dx.into_iter().map(|path| Ignored { path, reason: reason.clone() }));
    }
    let heights = of(&|w| w == Word::Height);
    let bumps = of(&|w| w == Word::Bump);
    if heights.is_empty() {
        maps.height = pick(MapKind::Height, bumps, &mut ignored);
        maps.height_is_bump = maps.height.is_some();
    } else {
        maps.height = pick(MapKind::Height, heights, &mut ignored);
        ignored.extend(
            bumps.into_iter().map(|path| Ignored { path, reason: "a bump map; the folder has a height map".into() }),
        );
    }
    maps.roughness = pick(MapKind::Roughness, of(&|w| w == Word::Roughness), &mut ignored);
    maps.ambient_occlusion = pick(MapKind::AmbientOcclusion, of(&|w| w == Word::Occlusion), &mut ignored);
    ignored.sort_by(|a, b| a.path.cmp(&b.path));
    maps.ignored = ignored;

    let found = || listing(&maps, &ambiguous);
    if let Some((map, files)) = ambiguous.first() {
        return Err(LibraryError::Ambiguous {
            path: folder.to_owned(),
            map: *map,
            candidates: files.clone(),
            found: found(),
        });
    }
    if candidates.is_empty() {
        return Err(LibraryError::NoMaps { path: folder.to_owned(), found: found() });
    }
    if maps.height.is_none() && !given.contains(&MapKind::Height) {
        return Err(LibraryError::NoHeight { path: folder.to_owned(), found: found() });
    }
    Ok(maps)
}

/// The `shininess` of a Blinn-Phong lobe for a surface of (perceptual) roughness `roughness`:
/// `alpha = roughness^2` (the squared roughness of the libraries' metal-roughness workflow),
/// then the Beckmann-to-Phong relation `shininess = 2 / alpha^2 - 2`, clamped to
/// [`MIN_SHININESS`]..=[`MAX_SHININESS`] (roughness 0.5 gives 30, 0.25 gives 510). A NaN gives
/// [`MIN_SHININESS`].
#[must_use]
pub fn shininess_from_roughness(roughness: f32) -> f32 {
    let r = if roughness.is_nan() { 1.0 } else { roughness.clamp(0.0, 1.0) };
    let alpha = r * r;
    let s = 2.0 / (alpha * alpha) - 2.0;
    // 1/0 is infinite, clamped like any large exponent.
    s.clamp(MIN_SHININESS, MAX_SHININESS)
}

/// The reflectance at normal incidence of the dielectrics that texture libraries and glTF's
/// metal-roughness materials mostly describe (stone, wood, plastic): 4%.
pub const DIELECTRIC_F0: f32 = 0.04;

/// The `specular` strength that makes a Blinn-Phong lobe of exponent `shininess` reflect
/// [`DIELECTRIC_F0`] of the light, as the renderers shade it (diffuse `albedo * N.L`, specular
/// `specular * (N.H)^shininess * N.L`): `DIELECTRIC_F0 * (shininess + 8) / 8`, the usual
/// normalization of the lobe. A rough surface's broad lobe is dim and a smooth one's narrow lobe
/// bright, instead of a broad lobe at full strength washing a rough surface out to white. The
/// scene files' defaults (32 and 0.25) are close to it (0.2).
#[must_use]
pub fn specular_for_shininess(shininess: f32) -> f32 {
    DIELECTRIC_F0 * (shininess.clamp(MIN_SHININESS, MAX_SHININESS) + 8.0) / 8.0
}

/// The mean roughness of a roughness map: the mean of its values (its luma, as a height map's
/// values are read: no sRGB decoding, roughness is data), in [0, 1].
///
/// # Errors
/// As [`crate::load_height_field`], naming the file.
pub fn mean_roughness(path: &Path) -> Result<f32, crate::IoError> {
    let field = crate::load_height_field(path, &crate::HeightLoadOptions::default())?;
    let depths = field.depths();
    // Heights are `1 - depth`; summed in f64 so that large maps do not lose the small values.
    let mean_depth = depths.iter().map(|&d| f64::from(d)).sum::<f64>() / depths.len().max(1) as f64;
    Ok((1.0 - mean_depth).clamp(0.0, 1.0) as f32)
}

/// The scene pomkit draws a texture-library folder on (`pomkit render --material FOLDER`,
/// `pomkit view --material FOLDER`): a 2 x 2 plane (the maps once across it) under a low sun,
/// seen from about 40 degrees above it, filling most of a 16:9 frame, with a `[[material]]` named after the folder whose `folder` is `folder` (every
/// other key at its default, as for `material = "FOLDER"`). Parse it with the paths relative
/// to the current folder (`pomkit_io::scene::parse_scene(&text, Path::new("."))`).
#[must_use]
pub fn preview_scene(folder: &Path) -> String {
    let name = folder
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .or_else(|| folder.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "library".to_owned());
    let quoted = |s: &str| toml::Value::String(s.to_owned()).to_string();
    format!(
        r#"background = [0.02, 0.02, 0.03]
ambient = [0.05, 0.05, 0.06]

[camera]
eye = [0.0, 1.2, 1.6]
target = [0.0, -0.15, 0.05]
fov = 45.0

[[light]]
type = "directional"
direction = [-0.55, 0.55, -0.35]
color = [1.0, 0.96, 0.9]
intensity = 2.5

[[material]]
name = {name}
folder = {folder}

[[object]]
name = "surface"
mesh = "plane"
size = 2.0
material = {name}
"#,
        name = quoted(&name),
        folder = quoted(&folder.to_string_lossy()),
    )
}

/// What a file's name says it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Word {
    Color,
    NormalGl,
    NormalDx,
    Height,
    Bump,
    Roughness,
    Occlusion,
    /// A map pomkit does not use; the word says which.
    Unused(&'static str),
    Preview,
}

/// The words of the names, each with what it names (pairs written together included:
/// `nor_gl` is `norgl`).
const WORDS: &[(&str, Word)] = &[
    ("color", Word::Color),
    ("colour", Word::Color),
    ("albedo", Word::Color),
    ("basecolor", Word::Color),
    ("basecolour", Word::Color),
    ("diffuse", Word::Color),
    ("diff", Word::Color),
    ("col", Word::Color),
    ("normal", Word::NormalGl),
    ("nor", Word::NormalGl),
    ("nrm", Word::NormalGl),
    ("normalgl", Word::NormalGl),
    ("norgl", Word::NormalGl),
    ("nrmgl", Word::NormalGl),
    ("normalopengl", Word::NormalGl),
    ("normaldx", Word::NormalDx),
    ("nordx", Word::NormalDx),
    ("nrmdx", Word::NormalDx),
    ("normaldirectx", Word::NormalDx),
    ("displacement", Word::Height),
    ("height", Word::Height),
    ("disp", Word::Height),
    ("heightmap", Word::Height),
    ("bump", Word::Bump),
    ("roughness", Word::Roughness),
    ("rough", Word::Roughness),
    ("ambientocclusion", Word::Occlusion),
    ("ao", Word::Occlusion),
    ("occlusion", Word::Occlusion),
    ("metalness", Word::Unused("metalness")),
    ("metallic", Word::Unused("metalness")),
    ("metal", Word::Unused("metalness")),
    ("specular", Word::Unused("specular")),
    ("spec", Word::Unused("specular")),
    ("glossiness", Word::Unused("glossiness")),
    ("gloss", Word::Unused("glossiness")),
    ("opacity", Word::Unused("opacity")),
    ("alpha", Word::Unused("opacity")),
    ("mask", Word::Unused("mask")),
    ("idmask", Word::Unused("mask")),
    ("emission", Word::Unused("emission")),
    ("emissive", Word::Unused("emission")),
    ("translucency", Word::Unused("translucency")),
    ("transmission", Word::Unused("transmission")),
    ("arm", Word::Unused("packed ambient occlusion, roughness and metalness")),
    ("orm", Word::Unused("packed occlusion, roughness and metalness")),
    ("cavity", Word::Unused("cavity")),
    ("preview", Word::Preview),
    ("thumb", Word::Preview),
    ("thumbnail", Word::Preview),
    ("icon", Word::Preview),
    ("swatch", Word::Preview),
];

fn word(s: &str) -> Option<Word> {
    WORDS.iter().find(|(w, _)| *w == s).map(|&(_, k)| k)
}

/// What `path` is, or why it is ignored.
fn classify(path: &Path) -> Result<Word, String> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot be read: {e}"))?;
    if meta.is_dir() {
        return Err("a folder: subfolders are not searched".into());
    }
    if !meta.is_file() {
        return Err("not a regular file".into());
    }
    if name.starts_with('.') {
        return Err("a hidden file".into());
    }
    if !readable_image(path) {
        return Err("not an image pomkit reads (PNG, JPEG, TIFF, OpenEXR)".into());
    }
    let stem = path.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let words = tokens(&stem);
    if words.iter().any(|w| word(w) == Some(Word::Preview)) {
        return Err("a preview".into());
    }
    match map_word(&words) {
        Some(Word::Unused(what)) => Err(format!("a {what} map, which pomkit does not use")),
        Some(w) => Ok(w),
        None => Err("its name names no map".into()),
    }
}

/// Whether pomkit-io reads images with `path`'s extension (the `image` crate's formats this
/// build decodes).
fn readable_image(path: &Path) -> bool {
    image::ImageFormat::from_path(path).is_ok_and(|f| f.reading_enabled())
}

/// The word that decides what a name is: from the end, the first pair of words written
/// together, or single word, that names something.
fn map_word(words: &[String]) -> Option<Word> {
    (0..words.len()).rev().find_map(|i| {
        let pair = i.checked_sub(1).and_then(|j| word(&format!("{}{}", words[j], words[i])));
        pair.or_else(|| word(&words[i]))
    })
}

/// A name cut into lower-case words at `_`, `-`, `.`, spaces and camel case (`NormalGL` ->
/// `normal`, `gl`; `AOMap` -> `ao`, `map`; `1K` stays whole).
fn tokens(stem: &str) -> Vec<String> {
    let chars: Vec<char> = stem.chars().collect();
    let mut words = Vec::new();
    let mut current = String::new();
    for (i, &c) in chars.iter().enumerate() {
        if matches!(c, '_' | '-' | '.' | ' ') {
            if !current.is_empty() {
                words.push(std::mem::take(&mut current));
            }
            continue;
        }
        if c.is_uppercase() && !current.is_empty() && i > 0 {
            let prev = chars[i - 1];
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_lowercase());
            if prev.is_lowercase() || (prev.is_uppercase() && next_lower) {
                words.push(std::mem::take(&mut current));
            }
        }
        current.extend(c.to_lowercase());
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

fn file_name(path: &Path) -> String {
    let name = path.file_name().unwrap_or(path.as_os_str());
    crate::shown(Path::new(name)).to_string()
}

fn names(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| file_name(p)).collect::<Vec<_>>().join(", ")
}

/// What was found for every map, then the ignored files (at most 20 named), for errors.
fn listing(maps: &LibraryMaps, ambiguous: &[(MapKind, Vec<PathBuf>)]) -> String {
    let mut s = String::new();
    for kind in MapKind::ALL {
        let shown = match (maps.map(kind), ambiguous.iter().find(|(k, _)| *k == kind)) {
            (_, Some((_, files))) => format!("{} ({} candidates)", names(files), files.len()),
            (Some(p), None) => file_name(p),
            (None, None) => "none".to_owned(),
        };
        let _ = write!(s, "{kind}: {shown}; ");
    }
    const SHOWN: usize = 20;
    if maps.ignored.is_empty() {
        s.push_str("ignored: nothing");
    } else {
        s.push_str("ignored: ");
        let list: Vec<String> =
            maps.ignored.iter().take(SHOWN).map(|i| format!("{} ({})", file_name(&i.path), i.reason)).collect();
        s.push_str(&list.join(", "));
        if maps.ignored.len() > SHOWN {
            let _ = write!(s, " and {} more", maps.ignored.len() - SHOWN);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: &str) -> Vec<String> {
        tokens(s)
    }

    #[test]
    fn names_are_cut_at_separators_and_camel_case() {
        assert_eq!(t("Bricks_1K_NormalGL"), ["bricks", "1k", "normal", "gl"]);
        assert_eq!(t("Bricks076C_1K-PNG_AmbientOcclusion"), ["bricks076c", "1k", "png", "ambient", "occlusion"]);
        assert_eq!(t("brick wall.nor_gl-1k"), ["brick", "wall", "nor", "gl", "1k"]);
        assert_eq!(t("AOMap"), ["ao", "map"]);
        assert_eq!(t("BASECOLOR"), ["basecolor"]);
        assert_eq!(t("__"), Vec::<String>::new());
    }

    #[test]
    fn the_last_word_naming_a_map_decides() {
        let w = |s: &str| map_word(&tokens(s));
        assert_eq!(w("rough_plaster_brick_diff_1k"), Some(Word::Color));
        assert_eq!(w("rough_plaster_brick_rough_1k"), Some(Word::Roughness));
        assert_eq!(w("rough_plaster_brick_nor_gl_1k"), Some(Word::NormalGl));
        assert_eq!(w("rough_plaster_brick_nor_dx_1k"), Some(Word::NormalDx));
        assert_eq!(w("Bricks_1K_NormalDX"), Some(Word::NormalDx));
        assert_eq!(w("Bricks_normal_dx"), Some(Word::NormalDx));
        assert_eq!(w("x_Base_Color"), Some(Word::Color));
        assert_eq!(w("x_height_map"), Some(Word::Height));
        assert_eq!(w("Bricks_1K_AmbientOcclusion"), Some(Word::Occlusion));
        assert_eq!(w("x_Metalness"), Some(Word::Unused("metalness")));
        assert_eq!(w("Bricks076C"), None);
    }

    #[test]
    fn roughness_maps_to_the_beckmann_phong_exponent() {
        // alpha = r^2; s = 2 / alpha^2 - 2.
        assert!((shininess_from_roughness(0.5) - 30.0).abs() < 1e-4);
        assert!((shininess_from_roughness(0.25) - 510.0).abs() < 1e-2);
        assert_eq!(shininess_from_roughness(1.0), MIN_SHININESS);
        assert_eq!(shininess_from_roughness(0.0), MAX_SHININESS);
        assert_eq!(shininess_from_roughness(f32::NAN), MIN_SHININESS);
        // The normalized lobe: rough surfaces reflect dimly, and the defaults are near it.
        assert!((specular_for_shininess(32.0) - 0.2).abs() < 1e-6);
        assert!((specular_for_shininess(1.0) - 0.045).abs() < 1e-6);
        // Monotone: rougher is never shinier.
        let s: Vec<f32> = (0..=100).map(|i| shininess_from_roughness(i as f32 / 100.0)).collect();
        assert!(s.windows(2).all(|p| p[1] <= p[0]));
    }
}
