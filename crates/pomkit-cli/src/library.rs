//! `--material DIR` of `render` and `view`: a texture-library folder (pomkit_io::library) drawn
//! on its preview scene, a plane under a low sun.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use pomkit_core::scene::Scene;
use pomkit_io::library::{LibraryMaps, find_maps, preview_scene};
use pomkit_io::scene::SceneSizes;

/// A texture-library folder and the scene that draws it.
pub(crate) struct Folder {
    /// The folder, as given.
    pub(crate) dir: PathBuf,
    maps: LibraryMaps,
    /// The preview scene's text (paths relative to the current folder).
    text: String,
    /// How errors name the scene: `--material DIR`.
    name: PathBuf,
}

impl Folder {
    /// Finds the folder's maps and prints them, one line each, on standard error.
    pub(crate) fn open(dir: &Path) -> Result<Self> {
        let maps = find_maps(dir).context("--material")?;
        eprintln!("material {}:", dir.display());
        for line in maps.lines() {
            eprintln!("  {line}");
        }
        let name = PathBuf::from(format!("--material {}", dir.display()));
        Ok(Self { dir: dir.to_owned(), text: preview_scene(dir), maps, name })
    }

    /// The files the render reads (its outputs may not be one of them): every map found.
    pub(crate) fn inputs(&self) -> Vec<PathBuf> {
        self.maps.files()
    }

    /// The preview scene's map and shape sizes, for the memory estimate.
    pub(crate) fn sizes(&self) -> Result<SceneSizes> {
        Ok(pomkit_io::scene::scene_text_sizes(&self.text, &self.name, Path::new("."))?)
    }

    /// Loads the preview scene; says which shininess the roughness map gave.
    pub(crate) fn load(&self) -> Result<Scene> {
        let scene = pomkit_io::scene::parse_scene_named(&self.text, &self.name, Path::new("."))?;
        if let (Some(m), Some(_)) = (scene.materials.first(), &self.maps.roughness) {
            eprintln!("  shininess {:.1}, from the roughness map's mean", m.shininess);
        }
        Ok(scene)
    }
}
