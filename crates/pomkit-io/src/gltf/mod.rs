//! glTF 2.0 files as pomkit scenes, and glTF files that carry height maps.
//!
//! - [`write_sample`]: a small asset made from pomkit's built-in maps (a plane with base
//!   colour, normal and, optionally, `KHR_materials_displacement` textures), for tests and
//!   demonstrations.

use std::path::PathBuf;

use crate::IoError;
use crate::output::Outputs;

mod sample;

pub use sample::{SampleCamera, SampleDisplacement, SampleLight, SampleOptions, write_sample};

/// The name of the (draft) glTF extension that carries a material's height map:
/// `displacementGeometryTexture` (its red channel), `displacementGeometryFactor` (default 1)
/// and `displacementGeometryOffset` (default 0); the surface moves along its normal by
/// `red * factor + offset` in the mesh's own units (docs/SCENES.md, glTF files).
pub const DISPLACEMENT_EXTENSION: &str = "KHR_materials_displacement";

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
