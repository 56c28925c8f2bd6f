//! Texture-library folders in scene files ([`crate::library`]): `material = "FOLDER"` on an
//! `[[object]]` (a material of the folder's maps with default settings) and `folder =
//! "FOLDER"` on a `[[material]]` (the folder's maps fill in the maps the table does not name;
//! its other keys apply as usual).

use std::borrow::Cow;

use super::*;
use crate::library::{self, LibraryError, LibraryMaps, MapKind};

/// Adds a `[[material]]` for every object whose `material` names no material but a folder
/// (relative to `base`): named as the object writes it, with `folder` set to it. Objects that
/// name the same folder share it.
pub(super) fn add_folder_materials(f: &mut SceneFile, base: &Path) {
    let names: Vec<String> = f
        .material
        .iter()
        .enumerate()
        .map(|(i, m)| m.name.clone().unwrap_or_else(|| format!("material {}", i + 1)))
        .collect();
    for (i, o) in f.object.iter().enumerate() {
        let Some(value) = &o.material else { continue };
        if value.trim().is_empty() || value.contains('\0') || names.contains(value) {
            continue;
        }
        if f.material.iter().skip(names.len()).any(|m| m.name.as_ref() == Some(value)) {
            continue;
        }
        if base.join(value).is_dir() {
            let at = o.label(i);
            f.material.push(MaterialFile {
                name: Some(value.clone()),
                folder: Some(value.clone()),
                from_object: Some(at),
                ..MaterialFile::default()
            });
        }
    }
}

/// The maps a material names itself, which its folder does not fill in.
fn given(m: &MaterialFile) -> Vec<MapKind> {
    let mut given = Vec::new();
    if m.albedo.is_some() {
        given.push(MapKind::Color);
    }
    if m.normal.is_some() {
        given.push(MapKind::Normal);
    }
    if m.height.is_some() {
        given.push(MapKind::Height);
    }
    given
}

/// `m` with its folder's colour, normal and height maps filled in where it names none (paths
/// relative to the scene, as the table's), and what the folder holds. `None` without `folder`.
pub(super) fn fill(base: &Path, m: &MaterialFile) -> Option<Result<(MaterialFile, LibraryMaps), LibraryError>> {
    let folder = m.folder.as_deref()?;
    let maps = match library::find_maps_except(&base.join(folder), &given(m)) {
        Ok(maps) => maps,
        Err(e) => return Some(Err(e)),
    };
    // `folder/NAME`, which the loader joins to `base` as it joins every path.
    let relative = |p: &Option<PathBuf>| -> Option<String> {
        let name = p.as_deref()?.file_name()?;
        Some(Path::new(folder).join(name).to_string_lossy().into_owned())
    };
    let mut out = m.clone();
    if out.albedo.is_none() {
        out.albedo = relative(&maps.color);
    }
    if out.normal.is_none() {
        out.normal = relative(&maps.normal);
        if maps.normal_y_down && out.normal_y_down.is_none() {
            out.normal_y_down = Some(true);
        }
    }
    if out.height.is_none() {
        out.height = relative(&maps.height);
    }
    Some(Ok((out, maps)))
}

/// `m` with its folder's maps filled in, or `m` itself (no folder, or one the load will report).
pub(super) fn filled<'a>(base: &Path, m: &'a MaterialFile) -> Cow<'a, MaterialFile> {
    match fill(base, m) {
        Some(Ok((filled, _))) => Cow::Owned(filled),
        _ => Cow::Borrowed(m),
    }
}

/// The maps of every folder the scene's materials name (for [`scene_inputs`]); folders that
/// cannot be read are left to the load to report.
pub(super) fn folder_files(f: &SceneFile, base: &Path) -> Vec<PathBuf> {
    f.material.iter().filter_map(|m| fill(base, m)?.ok()).flat_map(|(_, maps)| maps.files()).collect()
}

impl Loader<'_> {
    /// A `[[material]]` with `folder` (or an object's folder) as the plain table the loader
    /// reads: the folder's maps filled in, and `shininess` from its roughness map's mean unless
    /// the table sets it.
    pub(super) fn folder_material(&mut self, at: &str, m: &MaterialFile) -> Result<MaterialFile, SceneError> {
        let field = if m.from_object.is_some() { "material" } else { "folder" };
        let folder = m.folder.as_deref().unwrap_or_default();
        if folder.trim().is_empty() {
            return Err(self.invalid(at, field, format!("{field} is empty: expected the path of a folder of maps")));
        }
        let (mut out, maps) = match fill(self.base, m) {
            Some(result) => result.map_err(|e| self.invalid(at, field, format!("{field} {folder:?}: {e}")))?,
            None => return Ok(m.clone()),
        };
        if let (None, Some(path)) = (m.shininess, &maps.roughness) {
            let mean = match self.cache.roughness.get(path) {
                Some(&mean) => mean,
                None => {
                    let mean = library::mean_roughness(path).map_err(|cause| SceneError::Texture {
                        file: self.file.to_owned(),
                        at: at.to_owned(),
                        field: format!("{field} {folder:?}: roughness"),
                        cause: Box::new(cause),
                    })?;
                    self.cache.roughness.insert(path.clone(), mean);
                    mean
                }
            };
            let shininess = library::shininess_from_roughness(mean);
            out.shininess = Some(shininess);
            if m.specular.is_none() {
                out.specular = Some(library::specular_for_shininess(shininess));
            }
        }
        Ok(out)
    }
}
