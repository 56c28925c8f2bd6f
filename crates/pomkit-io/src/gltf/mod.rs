//! glTF 2.0 files as pomkit scenes, and glTF files that carry height maps.
//!
//! - [`write_sample`]: a small asset made from pomkit's built-in maps (a plane with base
//!   colour, normal and, optionally, `KHR_materials_displacement` textures), for tests and
//!   demonstrations.
//! - [`attach`]: a height map put into a material of a glTF file as
//!   `KHR_materials_displacement` (`pomkit gltf attach`).
//! - glTF files as scenes: `gltf = "FILE"` in a scene file, or a `.gltf`/`.glb` path given to
//!   [`crate::scene::load_scene`] (docs/SCENES.md, glTF files).

use std::path::PathBuf;

use crate::IoError;
use crate::output::Outputs;

mod attach;
pub(crate) mod import;
mod sample;

pub use attach::{AttachDepth, AttachError, Attached, MaterialChoice, attach};
pub use sample::{SampleCamera, SampleDisplacement, SampleLight, SampleOptions, write_sample};

/// The name of the (draft) glTF extension that carries a material's height map:
/// `displacementGeometryTexture` (its red channel), `displacementGeometryFactor` (default 1)
/// and `displacementGeometryOffset` (default 0); the surface moves along its normal by
/// `red * factor + offset` in the mesh's own units (docs/SCENES.md, glTF files).
pub const DISPLACEMENT_EXTENSION: &str = "KHR_materials_displacement";

/// The names of a glTF file's materials as scene files know them (a `[[material]]` of one of
/// these names overrides that material's keys), in the file's order, each once: the material's
/// own name, `NAME (INDEX)` when two share it, or `material INDEX` without one.
///
/// # Errors
/// [`crate::mesh::MeshLoadError`] naming the file when it cannot be read as a glTF scene.
pub fn material_names(path: &std::path::Path) -> Result<Vec<String>, crate::mesh::MeshLoadError> {
    let mut names: Vec<String> = Vec::new();
    for m in import::import(path)?.materials {
        if !names.contains(&m.gltf_name) {
            names.push(m.gltf_name);
        }
    }
    Ok(names)
}

/// Writes every `(path, bytes)` staged, and renames them into place only when all are written
/// (a failure leaves none of them).
pub(crate) fn write_all_or_nothing(files: &[(PathBuf, Vec<u8>)]) -> Result<(), IoError> {
    let mut outs = Outputs::new();
    let ids: Vec<_> = files.iter().map(|(p, _)| outs.output(p)).collect();
    outs.check()?;
    for (id, (path, bytes)) in ids.into_iter().zip(files) {
        outs.write_with::<IoError>(id, |w| {
            w.write_all(bytes).map_err(|reason| IoError::Write { path: path.clone(), reason })
        })?;
    }
    outs.commit()
}
