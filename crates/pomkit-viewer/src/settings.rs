//! The view settings that are not part of the scene, and what the viewer saves between runs.

use serde::{Deserialize, Serialize};

use crate::view::Overlay;

/// The view settings that are not part of the scene (saved between runs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Settings {
    /// Split the view between the material's technique and another.
    pub compare: bool,
    /// The technique on the right of the split.
    pub compare_technique: String,
    /// Where the split is (share of the width).
    pub split: f32,
    /// The AOV overlay.
    pub overlay: Overlay,
    /// Its opacity.
    pub overlay_opacity: f32,
    /// Fetches drawn white in the heat map.
    pub fetch_scale: f32,
    /// Rendered pixels per screen pixel (lower is faster).
    pub resolution: f32,
    /// Where "Export" writes (the PNG; the TOML goes beside it).
    pub export_path: String,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            compare: false,
            compare_technique: "relief".into(),
            split: 0.5,
            overlay: Overlay::None,
            overlay_opacity: 1.0,
            fetch_scale: 48.0,
            resolution: 1.0,
            export_path: "pomkit-view.png".into(),
        }
    }
}

/// What is saved between runs.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default)]
pub(crate) struct Saved {
    pub(crate) scene: String,
    pub(crate) material: usize,
    pub(crate) object: usize,
    pub(crate) settings: Settings,
}

pub(crate) const STORAGE_KEY: &str = "pomkit-viewer";
