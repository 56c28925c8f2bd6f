//! A glTF file's scene inside a scene file: `gltf = "FILE"` (the file's camera, lights,
//! materials and objects), `[[object]]`s whose `mesh` is a glTF file and `material` is left
//! out (the file's own materials), and the materials' pomkit settings (`extras.pomkit`, or a
//! `[[material]]` of the same name).

use super::*;
use crate::gltf::import::{Import, import};

/// The light of a scene that imports a glTF file with no light, and gives none itself: the
/// `[[light]]` of scene files with every key at its default (directional, from straight above,
/// white, intensity 1).
pub(super) const DEFAULT_SUN: Light = Light::Directional { direction: Vec3::Y, color: Vec3::ONE, intensity: 1.0 };

/// What `gltf = ...` brings to a scene, with the materials' settings applied.
pub(super) struct ImportedScene {
    pub(super) camera: Camera,
    pub(super) lights: Vec<Light>,
    pub(super) materials: Vec<Material>,
    /// The glTF materials' names (which `[[material]]` tables override).
    pub(super) gltf_names: Vec<String>,
    pub(super) objects: Vec<Object>,
}

/// The keys of a material that name or read textures: the glTF file gives those.
const TEXTURE_KEYS: [&str; 9] =
    ["name", "albedo", "height", "normal", "cone_map", "depth_map", "channel", "normalize", "normal_y_down"];

fn texture_keys_set(m: &MaterialFile) -> [(&'static str, bool); 9] {
    let set = [
        m.name.is_some(),
        m.albedo.is_some(),
        m.height.is_some(),
        m.normal.is_some(),
        m.cone_map.is_some(),
        m.depth_map.is_some(),
        m.channel.is_some(),
        m.normalize.is_some(),
        m.normal_y_down.is_some(),
    ];
    std::array::from_fn(|i| (TEXTURE_KEYS[i], set[i]))
}

/// Whether a `[[material]]` named `name` overrides one of the glTF file's materials.
pub(super) fn overrides(name: &str, gltf_names: &[String]) -> bool {
    gltf_names.iter().any(|n| n == name)
}

impl Loader<'_> {
    fn gltf_error(&self, value: &str, cause: MeshLoadError) -> SceneError {
        SceneError::Gltf { file: self.file.to_owned(), value: value.to_owned(), cause: Box::new(cause) }
    }

    /// Imports the glTF file `value` (relative to the scene): its materials with their
    /// `extras.pomkit` applied, then the `[[material]]` tables of the same names.
    pub(super) fn import_gltf(&mut self, value: &str, tables: &[MaterialFile]) -> Result<ImportedScene, SceneError> {
        if value.trim().is_empty() || value.contains('\0') {
            return Err(self.invalid("scene", "gltf", format!("gltf {value:?} is not a file name")));
        }
        let path = self.base.join(value);
        if !is_gltf(&path) {
            return Err(self.invalid("scene", "gltf", format!("gltf {value:?} is not a .gltf or .glb file")));
        }
        let Import { camera, framing, lights, materials, objects, warnings } =
            import(&path).map_err(|e| self.gltf_error(value, e))?;
        self.cache.warnings.extend(warnings);
        let camera = camera.unwrap_or(framing);
        camera.check().map_err(|e| {
            self.gltf_error(value, MeshLoadError::Invalid { path: path.clone(), message: e.to_string() })
        })?;
        let mut gltf_names = Vec::new();
        let mut out = Vec::new();
        for imported in materials {
            let mut material = self.apply_extras(&path, &imported)?;
            for table in tables.iter().filter(|t| t.name.as_deref() == Some(imported.gltf_name.as_str())) {
                let at = format!("material {:?}", imported.gltf_name);
                self.apply_settings(&mut material, table, &at, false)?;
            }
            if !gltf_names.contains(&imported.gltf_name) {
                gltf_names.push(imported.gltf_name.clone());
            }
            out.push(material);
        }
        Ok(ImportedScene { camera, lights, materials: out, gltf_names, objects })
    }

    /// The imported material with its `extras.pomkit` settings, checked as a `[[material]]`'s
    /// keys are; errors name the glTF file and the material.
    fn apply_extras(&mut self, path: &Path, imported: &crate::gltf::import::Imported) -> Result<Material, SceneError> {
        let mut material = imported.material.clone();
        let Some(extras) = &imported.pomkit else { return Ok(material) };
        let at = format!("{}: extras.pomkit", imported.label);
        let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_owned();
        let mut sub = Loader { file: path, base: &base, cache: self.cache };
        let table: MaterialFile = serde_json::from_value(extras.clone()).map_err(|e| SceneError::Invalid {
            file: path.to_owned(),
            at: at.clone(),
            field: "extras".to_owned(),
            message: format!("{e} (the keys of a scene file's [[material]], docs/SCENES.md)"),
        })?;
        sub.apply_settings(&mut material, &table, &at, true)?;
        Ok(material)
    }

    /// Applies the keys `m` sets to `base`, validated as the loader validates a `[[material]]`.
    /// From a glTF file's extras (`extras`), texture keys are refused and a tracing technique
    /// on a material without a height map is a warning (it is not traced); from a scene file,
    /// they load as in a `[[material]]`.
    fn apply_settings(
        &mut self,
        base: &mut Material,
        m: &MaterialFile,
        at: &str,
        extras: bool,
    ) -> Result<(), SceneError> {
        let keys = texture_keys_set(m);
        if extras && let Some((key, _)) = keys.iter().find(|(_, set)| *set) {
            return Err(self.invalid(
                at,
                key,
                format!("{key} cannot be set here: the glTF file gives the material's name and textures"),
            ));
        }
        if m.height.is_none()
            && let Some((key, _)) = keys[5..8].iter().find(|(_, set)| *set)
        {
            return Err(self.invalid(at, key, format!("{key} describes how to read the height key, which is not set")));
        }
        if m.cone_map.is_some() && m.height.is_none() {
            return Err(self.invalid(
                at,
                "cone_map",
                "cone_map is set without height: give the height map it belongs to",
            ));
        }
        let mut check = m.clone();
        check.name = Some(base.name.clone());
        let mut keep_technique = m.technique.is_some();
        if check.height.is_none() {
            if base.height.is_some() {
                // Stands for the material's own height map in the checks that need one.
                check.height = Some("builtin:spike:2x2".to_owned());
            } else if let Some(t) = m.technique.as_deref().and_then(|t| t.parse::<Technique>().ok())
                && t.displaces()
                && extras
            {
                self.cache.warnings.push(format!(
                    "{}: {at}: technique {:?} traces a height map, but the material has no displacement texture: \
                     not traced",
                    crate::shown(self.file),
                    t.name()
                ));
                check.technique = None;
                keep_technique = false;
            }
        }
        let v = self.material(0, &check).map_err(|e| match e {
            SceneError::Invalid { file, field, message, .. } => {
                SceneError::Invalid { file, at: at.to_owned(), field, message }
            }
            SceneError::Texture { file, field, cause, .. } => {
                SceneError::Texture { file, at: at.to_owned(), field, cause }
            }
            other => other,
        })?;
        if m.height.is_some() {
            if base.height.is_none() && m.technique.is_none() {
                base.technique = Material::default().technique;
            }
            base.height = v.height.clone();
            base.cones = v.cones.clone();
        }
        if m.albedo.is_some() {
            base.albedo = v.albedo.clone();
        }
        if m.normal.is_some() {
            base.normal_map = v.normal_map.clone();
        }
        if keep_technique {
            base.technique = v.technique;
        }
        let t = &mut base.trace;
        let set = |o: bool, dst: &mut u32, src: u32| {
            if o {
                *dst = src;
            }
        };
        set(m.min_samples.is_some(), &mut t.min_samples, v.trace.min_samples);
        set(m.max_samples.is_some(), &mut t.max_samples, v.trace.max_samples);
        set(m.samples.is_some(), &mut t.samples, v.trace.samples);
        set(m.iterations.is_some(), &mut t.iterations, v.trace.iterations);
        set(m.binary_steps.is_some(), &mut t.binary_steps, v.trace.binary_steps);
        set(m.refine.is_some(), &mut t.refine, v.trace.refine);
        if m.perspective_bias.is_some() {
            t.perspective_bias = v.trace.perspective_bias;
        }
        if m.depth_scale.is_some() {
            base.depth_scale = v.depth_scale;
        }
        if m.edges.is_some() {
            base.edges = v.edges;
        }
        if m.shadow.is_some() {
            base.shadow.mode = v.shadow.mode;
        }
        if m.softness.is_some() {
            base.shadow.softness = v.shadow.softness;
        }
        if m.lod_threshold.is_some() {
            base.lod_threshold = v.lod_threshold;
        }
        if m.specular.is_some() {
            base.specular = v.specular;
        }
        if m.shininess.is_some() {
            base.shininess = v.shininess;
        }
        if m.pixel_depth_offset.is_some() {
            base.pixel_depth_offset = v.pixel_depth_offset;
        }
        if m.silhouette.is_some() {
            base.silhouette = v.silhouette;
        }
        if m.base_color.is_some() {
            base.base_color = v.base_color;
        }
        Ok(())
    }

    /// An `[[object]]` whose mesh is a glTF file and whose material is left out: every triangle
    /// primitive of the file's scene with its node transform and its own material (with its
    /// pomkit settings), placed by the object's position, rotation and scale.
    pub(super) fn gltf_object(
        &mut self,
        i: usize,
        o: &ObjectFile,
        materials: &mut Vec<Material>,
        objects: &mut Vec<Object>,
    ) -> Result<(), SceneError> {
        let name = o.name.clone().unwrap_or_else(|| format!("object {}", i + 1));
        let at = o.label(i);
        let mut given = [("uv_repeat", o.uv_repeat.is_some())].into_iter().chain(o.shape_keys());
        if let Some((field, _)) = given.find(|(_, set)| *set) {
            return Err(self.invalid(
                &at,
                field,
                format!(
                    "{field} does not apply to a glTF mesh drawn with its own materials (their depth comes from the \
                     file's UVs)"
                ),
            ));
        }
        let transform = self.placement(&at, o)?;
        let path = self.base.join(o.mesh.trim());
        let Import { materials: mats, objects: objs, warnings, .. } =
            import(&path).map_err(|cause| SceneError::Mesh {
                file: self.file.to_owned(),
                at: at.clone(),
                mesh: o.mesh.clone(),
                cause: Box::new(cause),
            })?;
        self.cache.warnings.extend(warnings);
        let offset = materials.len();
        for imported in &mats {
            let mut m = self.apply_extras(&path, imported)?;
            m.name = format!("{name}: {}", m.name);
            materials.push(m);
        }
        for mut obj in objs {
            obj.material += offset;
            obj.transform = transform;
            obj.name = format!("{name}: {}", obj.name);
            objects.push(obj);
        }
        Ok(())
    }
}

/// The sizes of a glTF file's textures (per material: the displacement texture's image as
/// the height map, the base colour's as the colour map, the normal texture's) and of its
/// primitive instances, from its JSON and the images' headers, without loading anything
/// else. Empty when the file cannot be read (its load reports why).
pub(super) fn gltf_sizes(path: &Path) -> (Vec<MaterialSizes>, Vec<ObjectSizes>) {
    let Ok(bytes) = crate::read::read_capped(path, crate::read::MAX_MESH_BYTES, "a glTF file") else {
        return (Vec::new(), Vec::new());
    };
    let Ok(::gltf::Gltf { document, blob }) = ::gltf::Gltf::from_slice_without_validation(&bytes) else {
        return (Vec::new(), Vec::new());
    };
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let image_size = |index: usize| -> Option<(u32, u32)> {
        let image = document.images().nth(index)?;
        match image.source() {
            ::gltf::image::Source::Uri { uri, .. } => {
                let file = crate::mesh::uri_path(uri, base)?;
                texture_size(Path::new(""), file.to_str()?)
            }
            ::gltf::image::Source::View { view, .. } => {
                // Only the GLB's own binary chunk is read here.
                if view.buffer().index() != 0 || !matches!(view.buffer().source(), ::gltf::buffer::Source::Bin) {
                    return None;
                }
                let data = blob.as_deref()?.get(view.offset()..view.offset().checked_add(view.length())?)?;
                let (w, h) = image::ImageReader::new(std::io::Cursor::new(data))
                    .with_guessed_format()
                    .ok()?
                    .into_dimensions()
                    .ok()?;
                (w <= MAX_BUILTIN_SIZE && h <= MAX_BUILTIN_SIZE).then_some((w, h))
            }
        }
    };
    let texture_image = |t: usize| document.textures().nth(t).and_then(|t| image_size(t.source().index()));
    let mut materials: Vec<MaterialSizes> = document
        .materials()
        .map(|m| {
            let height = m
                .extension_value(crate::gltf::DISPLACEMENT_EXTENSION)
                .and_then(|e| e.get("displacementGeometryTexture")?.get("index")?.as_u64())
                .and_then(|t| texture_image(t as usize));
            MaterialSizes {
                height,
                height_builtin: false,
                albedo: m
                    .pbr_metallic_roughness()
                    .base_color_texture()
                    .and_then(|i| texture_image(i.texture().index())),
                albedo_builtin: false,
                normal_map: m.normal_texture().and_then(|i| texture_image(i.texture().index())),
                technique: if height.is_some() { Material::default().technique } else { Technique::Normal },
            }
        })
        .collect();
    let default_material = materials.len();
    let mut objects = Vec::new();
    let mut used_default = false;
    for mesh in document.meshes() {
        for prim in mesh.primitives() {
            let vertices = prim.get(&::gltf::Semantic::Positions).map_or(0, |a| a.count() as u64);
            let triangles = prim.indices().map_or(vertices, |a| a.count() as u64) / 3;
            let material = prim.material().index().unwrap_or_else(|| {
                used_default = true;
                default_material
            });
            objects.push(ObjectSizes { material: Some(material), vertices, triangles });
        }
    }
    if used_default {
        materials.push(MaterialSizes {
            height: None,
            height_builtin: false,
            albedo: None,
            albedo_builtin: false,
            normal_map: None,
            technique: Technique::Normal,
        });
    }
    (materials, objects)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gltf::{SampleCamera, SampleDisplacement, SampleLight, SampleOptions, write_sample};

    fn sample(dir: &Path, opts: SampleOptions) -> PathBuf {
        write_sample(dir, &opts).unwrap()
    }

    fn load(path: &Path) -> (Scene, Vec<String>) {
        let mut warnings = Vec::new();
        let scene = load_scene_warned(path, &mut warnings).unwrap_or_else(|e| panic!("{e}"));
        (scene, warnings)
    }

    fn err(path: &Path) -> String {
        load_scene(path).map(|_| ()).unwrap_err().to_string()
    }

    /// Rewrites the sample's JSON with `edit`.
    fn edit(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
        let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
        edit(&mut json);
        std::fs::write(path, serde_json::to_vec(&json).unwrap()).unwrap();
    }

    #[test]
    fn the_depth_scale_is_the_factor_over_the_mean_uv_unit_in_the_mesh_own_units() {
        let dir = tempfile::tempdir().unwrap();
        // A 2 x 2 plane, UVs 0..1: a UV unit is 2 units; the node's scale of 3 does not count.
        let opts = SampleOptions { scale: Vec3::splat(3.0), ..SampleOptions::default() };
        let (scene, _) = load(&sample(dir.path(), opts));
        let m = &scene.materials[0];
        assert_eq!(m.name, "Bricks");
        assert!((m.depth_scale - 0.1 / 2.0).abs() < 1e-6, "{}", m.depth_scale);
        assert_eq!(m.technique, Material::default().technique);
        let field = m.height.as_ref().unwrap();
        let truth = pomkit_core::procedural::generate(pomkit_core::procedural::Pattern::Bricks, 64, 64);
        // Red = height, white = high, within the 8-bit step.
        for (a, b) in field.heights().iter().zip(truth.heights()) {
            assert!((a - b).abs() <= 0.5 / 255.0 + 1e-6);
        }
        assert!(m.albedo.is_some() && m.normal_map.is_some());
        // The node's scale is applied to the geometry: the plane spans 6 units.
        let (lo, hi) = scene.objects[0].mesh.bounds();
        assert!((hi.x - lo.x - 6.0).abs() < 1e-5);
        // UVs repeated 4 times over a 2 x 2 plane: a UV unit is half a unit.
        let dir = tempfile::tempdir().unwrap();
        let (scene, _) = load(&sample(dir.path(), SampleOptions { uv_repeat: 4.0, ..SampleOptions::default() }));
        assert!((scene.materials[0].depth_scale - 0.1 / 0.5).abs() < 1e-5);
    }

    #[test]
    fn a_texture_transform_scales_the_uvs_before_the_depth_is_derived() {
        let dir = tempfile::tempdir().unwrap();
        let path = sample(dir.path(), SampleOptions::default());
        edit(&path, |j| {
            let t = serde_json::json!({ "KHR_texture_transform": { "scale": [2.0, 2.0], "offset": [0.5, 0.0] } });
            j["materials"][0]["extensions"][crate::gltf::DISPLACEMENT_EXTENSION]["displacementGeometryTexture"]["extensions"] =
                t.clone();
            j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = t;
        });
        let (scene, warnings) = load(&path);
        assert!((scene.materials[0].depth_scale - 0.1).abs() < 1e-5, "{}", scene.materials[0].depth_scale);
        let uvs = &scene.objects[0].mesh.uvs;
        assert!(uvs.iter().any(|uv| (*uv - Vec2::new(2.5, 2.0)).length() < 1e-6), "{uvs:?}");
        // The normal texture has none: one UV set, the displacement's, with a warning.
        assert!(
            warnings.iter().any(|w| w.contains("normalTexture") && w.contains("KHR_texture_transform")),
            "{warnings:?}"
        );
    }

    #[test]
    fn without_the_extension_the_material_is_not_traced() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, _) = load(&sample(dir.path(), SampleOptions { displacement: None, ..SampleOptions::default() }));
        assert!(scene.materials[0].height.is_none());
        assert_eq!(scene.materials[0].technique, Technique::Normal);
        // A factor of 0: not traced, with a warning.
        let dir = tempfile::tempdir().unwrap();
        let disp = Some(SampleDisplacement { factor: 0.0, offset: 0.0 });
        let (scene, warnings) =
            load(&sample(dir.path(), SampleOptions { displacement: disp, ..SampleOptions::default() }));
        assert!(scene.materials[0].height.is_none());
        assert!(warnings.iter().any(|w| w.contains("material 0 'Bricks'") && w.contains("not traced")), "{warnings:?}");
    }

    #[test]
    fn the_camera_and_lights_come_from_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let camera =
            SampleCamera { eye: Vec3::new(1.0, 2.0, 3.0), yfov_deg: 30.0, zfar: None, ..SampleCamera::default() };
        let lights = vec![
            SampleLight::Point {
                position: Vec3::new(-1.0, 0.5, 0.0),
                color: Vec3::new(1.0, 0.5, 0.25),
                intensity: 2.0,
            },
            SampleLight::Directional { toward: Vec3::new(0.0, 1.0, 1.0), color: Vec3::ONE, intensity: 3.0 },
            SampleLight::Spot { position: Vec3::Y, target: Vec3::ZERO, color: Vec3::ONE, intensity: 1.0 },
        ];
        let opts = SampleOptions { camera: Some(camera), lights, ..SampleOptions::default() };
        let (scene, warnings) = load(&sample(dir.path(), opts));
        let c = scene.camera;
        assert!((c.eye - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-5);
        assert!((c.fov_y_deg - 30.0).abs() < 1e-4);
        let dir_seen = (c.target - c.eye).normalize();
        assert!((dir_seen - (-c.eye).normalize()).length() < 1e-5, "looks at the origin: {dir_seen}");
        // No zfar: far enough for the scene (the plane's far corner is under 5 units away).
        assert!(c.far > 5.0 && c.near == 0.05);
        assert_eq!(scene.lights.len(), 3);
        assert_eq!(
            scene.lights[0],
            Light::Point { position: Vec3::new(-1.0, 0.5, 0.0), color: Vec3::new(1.0, 0.5, 0.25), intensity: 2.0 }
        );
        let Light::Directional { direction, intensity, .. } = scene.lights[1] else { panic!("directional") };
        assert!((direction - Vec3::new(0.0, 1.0, 1.0).normalize()).length() < 1e-5 && intensity == 3.0);
        assert!(matches!(scene.lights[2], Light::Point { position, .. } if (position - Vec3::Y).length() < 1e-6));
        assert!(warnings.iter().any(|w| w.contains("light 2") && w.contains("spot")), "{warnings:?}");
    }

    #[test]
    fn without_camera_or_light_the_scene_is_framed_and_lit_by_the_default_sun() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, _) = load(&sample(dir.path(), SampleOptions::default()));
        assert_eq!(scene.lights, vec![DEFAULT_SUN]);
        let c = scene.camera;
        assert!(c.eye.y > 0.5 && c.eye.z > 0.5 && c.target.length() < 1e-5, "{c:?}");
        // The plane's corners are in view.
        let vp = c.projection(1.0) * c.view();
        for corner in [Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 0.0, 1.0)] {
            let p = vp * corner.extend(1.0);
            assert!(p.w > 0.0 && (p.x / p.w).abs() <= 1.0 && (p.y / p.w).abs() <= 1.0);
        }
    }

    #[test]
    fn extras_set_pomkit_settings_checked_as_scene_keys() {
        let dir = tempfile::tempdir().unwrap();
        let extras = serde_json::json!({ "pomkit": { "technique": "relief", "shadow": "soft", "depth_scale": 0.03 } });
        let path = sample(dir.path(), SampleOptions { extras: Some(extras), ..SampleOptions::default() });
        let (scene, _) = load(&path);
        let m = &scene.materials[0];
        assert_eq!(m.technique, Technique::Relief);
        assert_eq!(m.shadow.mode, pomkit_core::ShadowMode::Soft);
        assert_eq!(m.depth_scale, 0.03);
        for (bad, names) in [
            (serde_json::json!({ "pomkit": { "techniqe": "relief" } }), "techniqe"),
            (serde_json::json!({ "pomkit": { "technique": "magic" } }), "magic"),
            (serde_json::json!({ "pomkit": { "depth_scale": -1.0 } }), "depth_scale"),
            (serde_json::json!({ "pomkit": { "albedo": "x.png" } }), "albedo"),
        ] {
            edit(&path, |j| j["materials"][0]["extras"] = bad);
            let e = err(&path);
            assert!(e.contains("sample.gltf") && e.contains("material 0 'Bricks'") && e.contains(names), "{e}");
        }
        // Extras asking to trace a material without a height map: a warning, not traced.
        let dir = tempfile::tempdir().unwrap();
        let extras = serde_json::json!({ "pomkit": { "technique": "relief", "specular": 0.5 } });
        let opts = SampleOptions { extras: Some(extras), displacement: None, ..SampleOptions::default() };
        let (scene, warnings) = load(&sample(dir.path(), opts));
        assert_eq!(scene.materials[0].technique, Technique::Normal);
        assert_eq!(scene.materials[0].specular, 0.5);
        assert!(warnings.iter().any(|w| w.contains("relief") && w.contains("not traced")), "{warnings:?}");
    }

    #[test]
    fn a_scene_file_imports_a_gltf_and_overrides_its_camera_and_materials() {
        let dir = tempfile::tempdir().unwrap();
        sample(dir.path(), SampleOptions::default());
        let toml = dir.path().join("s.toml");
        std::fs::write(
            &toml,
            r#"gltf = "sample.gltf"
[camera]
eye = [0.0, 5.0, 0.5]
target = [0.0, 0.0, 0.0]
[[material]]
name = "Bricks"
technique = "exact"
[[material]]
name = "grey"
[[object]]
mesh = "cube"
material = "grey"
position = [3.0, 0.0, 0.0]
[[object]]
mesh = "sample.gltf"
position = [0.0, 0.0, -3.0]
"#,
        )
        .unwrap();
        let (scene, _) = load(&toml);
        assert_eq!(scene.camera.eye, Vec3::new(0.0, 5.0, 0.5));
        let names: Vec<&str> = scene.materials.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["Bricks", "grey", "object 2: Bricks"]);
        assert_eq!(scene.materials[0].technique, Technique::Exact);
        assert!((scene.materials[0].depth_scale - 0.05).abs() < 1e-6, "derived depth kept");
        assert_eq!(scene.objects.len(), 3);
        assert_eq!(scene.objects[2].material, 2);
        assert_eq!(scene.objects[2].transform.w_axis.z, -3.0);
        // What the scene reads, and its sizes before loading.
        let inputs = scene_inputs(&toml).unwrap();
        for f in ["sample.gltf", "sample.bin", "sample_albedo.png", "sample_normal.png", "sample_height.png"] {
            assert!(inputs.contains(&dir.path().join(f)), "{f}: {inputs:?}");
        }
        let sizes = scene_sizes(&toml).unwrap();
        assert_eq!(sizes.materials.len(), 3);
        assert_eq!(sizes.materials[2].height, Some((64, 64)));
        assert_eq!(sizes.materials[2].albedo, Some((64, 64)));
        assert_eq!(sizes.objects[2], ObjectSizes { material: Some(2), vertices: 4, triangles: 2 });
        let direct = scene_sizes(&dir.path().join("sample.gltf")).unwrap();
        assert_eq!(direct.materials[0].normal_map, Some((64, 64)));
        // A .glb's images are in the file.
        let glb = sample(dir.path(), SampleOptions { binary: true, name: "b".into(), ..SampleOptions::default() });
        assert_eq!(scene_sizes(&glb).unwrap().materials[0].height, Some((64, 64)));
        assert_eq!(scene_inputs(&glb).unwrap(), vec![glb.clone()]);
        let (scene, _) = load(&glb);
        assert!((scene.materials[0].depth_scale - 0.05).abs() < 1e-6);
    }

    /// A change made to a glTF file's JSON.
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;

    #[test]
    fn bad_gltf_input_is_refused_naming_the_file_and_the_item() {
        let dir = tempfile::tempdir().unwrap();
        let path = sample(dir.path(), SampleOptions::default());
        fn ext(j: &mut serde_json::Value) -> &mut serde_json::Value {
            &mut j["materials"][0]["extensions"][crate::gltf::DISPLACEMENT_EXTENSION]
        }
        let original = std::fs::read(&path).unwrap();
        let cases: Vec<(Edit, &[&str])> = vec![
            (
                Box::new(|j| ext(j)["displacementGeometryFactor"] = serde_json::json!(-0.1)),
                &["material 0 'Bricks'", "displacementGeometryFactor is -0.1"],
            ),
            (
                Box::new(|j| ext(j)["displacementGeometryFactor"] = serde_json::json!("NaN")),
                &["material 0 'Bricks'", "displacementGeometryFactor"],
            ),
            (
                Box::new(|j| ext(j)["displacementGeometryOffset"] = serde_json::json!(null)),
                &["material 0 'Bricks'", "displacementGeometryOffset"],
            ),
            (
                Box::new(|j| ext(j)["displacementGeometryTexture"]["index"] = serde_json::json!(9)),
                &["material 0 'Bricks'", "texture 9"],
            ),
            (
                Box::new(|j| j["images"][2]["uri"] = serde_json::json!("sample.bin")),
                &["material 0 'Bricks'", "displacementGeometryTexture (texture 2)", "sample.bin"],
            ),
            (
                Box::new(|j| j["images"][0]["uri"] = serde_json::json!("gone.png")),
                &["material 0 'Bricks'", "baseColorTexture (texture 0)", "gone.png"],
            ),
            (Box::new(|j| j["buffers"][0]["uri"] = serde_json::json!("gone.bin")), &["sample.gltf", "gone.bin"]),
            (
                Box::new(|j| {
                    j["cameras"] = serde_json::json!([{ "type": "perspective", "name": "cam",
                        "perspective": { "yfov": 0.8, "znear": 0.1, "aspectRatio": 0.0 } }]);
                    j["nodes"].as_array_mut().unwrap().push(serde_json::json!({ "camera": 0 }));
                    j["scenes"][0]["nodes"].as_array_mut().unwrap().push(serde_json::json!(1));
                }),
                &["camera 0 'cam'", "aspectRatio is 0"],
            ),
        ];
        for (change, expected) in cases {
            std::fs::write(&path, &original).unwrap();
            edit(&path, change);
            let e = err(&path);
            assert!(e.contains("sample.gltf"), "{e}");
            for x in expected {
                assert!(e.contains(x), "{x}: {e}");
            }
        }
    }
}
