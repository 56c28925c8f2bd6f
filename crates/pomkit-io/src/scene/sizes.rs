//! The sizes of a scene file's parts, read without building or decoding anything: for the
//! memory estimates made before the work starts (docs/LIMITS.md).

use super::*;

/// The sizes of a scene file's textures and built-in shapes ([`scene_sizes`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneSizes {
    /// Per `[[material]]`, in order.
    pub materials: Vec<MaterialSizes>,
    /// Per `[[object]]`, in order.
    pub objects: Vec<ObjectSizes>,
}

/// A material's texture sizes (`None` for none, or one whose size cannot be told without
/// loading it: its load reports the problem) and technique.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MaterialSizes {
    /// The height map: a built-in's `WxH`, or a file's header.
    pub height: Option<(u32, u32)>,
    /// Whether the height map is built in (generated, not decoded).
    pub height_builtin: bool,
    /// The colour map.
    pub albedo: Option<(u32, u32)>,
    /// Whether the colour map is built in.
    pub albedo_builtin: bool,
    /// The normal map.
    pub normal_map: Option<(u32, u32)>,
    /// The technique (the default when absent or unknown).
    pub technique: Technique,
}

/// An object's material and the size of its mesh (0 for a mesh file: it is held to its file's
/// size cap and counted once loaded).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjectSizes {
    /// The index of its material, when the name is one.
    pub material: Option<usize>,
    /// Vertices of its built-in shape.
    pub vertices: u64,
    /// Triangles of its built-in shape.
    pub triangles: u64,
}

impl SceneSizes {
    /// The bytes the loader itself holds for the textures: the fields and textures it makes
    /// (4 bytes a height texel, 12 a colour or normal texel) and, for built-in maps, what
    /// generating them takes on the way (4 bytes a height texel, 3 a colour texel). A decoded
    /// file's own bytes are checked when it is read.
    #[must_use]
    pub fn texture_bytes(&self) -> u64 {
        let texels = |s: Option<(u32, u32)>| s.map_or(0, |(w, h)| u64::from(w) * u64::from(h));
        self.materials.iter().fold(0u64, |sum, m| {
            let height = texels(m.height) * if m.height_builtin { 8 } else { 4 };
            let albedo = texels(m.albedo) * if m.albedo_builtin { 15 } else { 12 };
            sum.saturating_add(height).saturating_add(albedo).saturating_add(texels(m.normal_map) * 12)
        })
    }

    /// The largest texture, for messages: `(w, h)`.
    #[must_use]
    pub fn largest_texture(&self) -> Option<(u32, u32)> {
        self.materials
            .iter()
            .flat_map(|m| [m.height, m.albedo, m.normal_map])
            .flatten()
            .max_by_key(|&(w, h)| u64::from(w) * u64::from(h))
    }

    /// Triangles of every built-in shape.
    #[must_use]
    pub fn triangles(&self) -> u64 {
        self.objects.iter().fold(0u64, |a, o| a.saturating_add(o.triangles))
    }
}

/// The size of the texture `value` names, relative to `base`: a built-in's `WxH` (the default
/// size without one), or an image file's header (regular files only: a pipe or device is not
/// read here). `None` when it cannot be told (the load then reports why).
#[must_use]
pub fn texture_size(base: &Path, value: &str) -> Option<(u32, u32)> {
    if let Some(rest) = value.strip_prefix("builtin:") {
        let Some((_, size)) = rest.split_once(':') else { return Some((BUILTIN_SIZE, BUILTIN_SIZE)) };
        let (w, h) = size.split_once(['x', 'X'])?;
        let (w, h) = (w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?);
        return ((1..=MAX_BUILTIN_SIZE).contains(&w) && (1..=MAX_BUILTIN_SIZE).contains(&h)).then_some((w, h));
    }
    let path = base.join(value);
    if !std::fs::metadata(&path).is_ok_and(|m| m.is_file()) {
        return None;
    }
    let (w, h) = image::ImageReader::open(&path).ok()?.with_guessed_format().ok()?.into_dimensions().ok()?;
    (w <= MAX_BUILTIN_SIZE && h <= MAX_BUILTIN_SIZE).then_some((w, h))
}

impl MaterialSizes {
    pub(super) fn of(base: &Path, m: &MaterialFile) -> Self {
        let m = &*folder::filled(base, m);
        let size = |v: &Option<String>| v.as_deref().and_then(|v| texture_size(base, v));
        let builtin = |v: &Option<String>| v.as_deref().is_some_and(|v| v.starts_with("builtin:"));
        MaterialSizes {
            height: size(&m.height),
            height_builtin: builtin(&m.height),
            albedo: size(&m.albedo),
            albedo_builtin: builtin(&m.albedo),
            normal_map: size(&m.normal),
            technique: m.technique.as_deref().and_then(|t| t.parse().ok()).unwrap_or(Material::default().technique),
        }
    }
}

fn sizes_of(f: &SceneFile, base: &Path) -> SceneSizes {
    let materials: Vec<MaterialSizes> = f.material.iter().map(|m| MaterialSizes::of(base, m)).collect();
    let names: Vec<String> = f
        .material
        .iter()
        .enumerate()
        .map(|(i, m)| m.name.clone().unwrap_or_else(|| format!("material {}", i + 1)))
        .collect();
    let objects = f
        .object
        .iter()
        .map(|o| {
            let (vertices, triangles) = object::shape_counts(o).unwrap_or((0, 0));
            let material = o.material.as_ref().and_then(|m| names.iter().position(|n| n == m));
            ObjectSizes { material, vertices, triangles }
        })
        .collect();
    let mut sizes = SceneSizes { materials, objects };
    // The glTF file's textures and primitives, after the scene file's own.
    if let Some(g) = &f.gltf {
        let (materials, objects) = gltf::gltf_sizes(&base.join(g));
        let offset = sizes.materials.len();
        sizes.materials.extend(materials);
        sizes
            .objects
            .extend(objects.into_iter().map(|o| ObjectSizes { material: o.material.map(|m| m + offset), ..o }));
    }
    sizes
}

/// The sizes of the scene file at `path`'s textures and shapes, without building or decoding
/// anything: for an estimate of a job's memory before the scene is loaded.
///
/// # Errors
/// [`SceneError::Read`] or [`SceneError::Syntax`], as [`load_scene`] gives them.
pub fn scene_sizes(path: &Path) -> Result<SceneSizes, SceneError> {
    let text = if is_gltf(path) { gltf_scene_text(path) } else { read_scene_text(path)? };
    let mut parsed: SceneFile = toml::from_str(&text).map_err(|e| syntax_error(path, &text, &e))?;
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    folder::add_folder_materials(&mut parsed, base);
    Ok(sizes_of(&parsed, base))
}

/// [`scene_sizes`] of scene text (named `file` in errors) whose relative paths are relative to
/// `base_dir`, as [`parse_scene_named`] reads it.
///
/// # Errors
/// [`SceneError::Syntax`], as [`parse_scene_named`] gives it.
pub fn scene_text_sizes(text: &str, file: &Path, base_dir: &Path) -> Result<SceneSizes, SceneError> {
    let mut parsed: SceneFile = toml::from_str(text).map_err(|e| syntax_error(file, text, &e))?;
    folder::add_folder_materials(&mut parsed, base_dir);
    Ok(sizes_of(&parsed, base_dir))
}

impl Loader<'_> {
    /// Refuses a scene whose textures will not fit, before any is generated or decoded.
    pub(super) fn check_textures(&self, f: &SceneFile) -> Result<(), SceneError> {
        let sizes = sizes_of(f, self.base);
        let bytes = sizes.texture_bytes();
        let largest = sizes.largest_texture().map_or_else(String::new, |(w, h)| format!(" (the largest {w}x{h})"));
        pomkit_core::memory::check(
            || format!("loading the {} materials' maps{largest}", f.material.len()),
            bytes,
            "use smaller height and colour maps",
        )
        .map_err(|e| self.invalid("scene", "material", e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_come_from_built_in_names_image_headers_and_shape_counts() {
        let dir = tempfile::tempdir().unwrap();
        image::RgbImage::new(10, 20).save(dir.path().join("a.png")).unwrap();
        let scene = r#"
[camera]
eye = [0.0, 1.0, 2.0]
target = [0.0, 0.0, 0.0]

[[material]]
name = "m"
height = "builtin:waves:300x200"
albedo = "a.png"
technique = "cone"

[[material]]
name = "n"
height = "missing.png"

[[object]]
mesh = "sphere"
rings = 4
segments = 8
material = "n"

[[object]]
mesh = "model.obj"
material = "m"
"#;
        std::fs::write(dir.path().join("s.toml"), scene).unwrap();
        let s = scene_sizes(&dir.path().join("s.toml")).unwrap();
        assert_eq!(s.materials[0].height, Some((300, 200)));
        assert!(s.materials[0].height_builtin);
        assert_eq!(s.materials[0].albedo, Some((10, 20)));
        assert!(!s.materials[0].albedo_builtin);
        assert_eq!(s.materials[0].technique, Technique::Cone);
        // A file that cannot be read has no size here: its load reports it.
        assert_eq!(s.materials[1].height, None);
        // The sphere's grid with poles: (4 + 3) x (8 + 3) vertices, 2 x 5 x 9 triangles at most.
        assert_eq!(s.objects[0], ObjectSizes { material: Some(1), vertices: 77, triangles: 90 });
        assert_eq!(s.objects[1], ObjectSizes { material: Some(0), vertices: 0, triangles: 0 });
        assert_eq!(s.largest_texture(), Some((300, 200)));
        // Generated heights 8 bytes a texel, a decoded colour map 12.
        assert_eq!(s.texture_bytes(), 300 * 200 * 8 + 10 * 20 * 12);
    }
}
