//! Loading an `[[object]]`: its placement and its mesh, a built-in shape or a mesh file.

use super::*;

impl Loader<'_> {
    pub(super) fn object(&mut self, i: usize, o: &ObjectFile, materials: &[Material]) -> Result<Object, SceneError> {
        let name = o.name.clone().unwrap_or_else(|| format!("object {}", i + 1));
        let at = o.label(i);
        let at = at.as_str();
        let Some(wanted) = &o.material else {
            return Err(self.invalid(
                at,
                "material",
                "material is missing: every object needs one (only a glTF mesh may leave it out, to take the file's \
                 own materials)",
            ));
        };
        let material = materials.iter().position(|m| m.name == *wanted).ok_or_else(|| {
            let names: Vec<&str> = materials.iter().map(|m| m.name.as_str()).collect();
            let known = if names.is_empty() {
                "there are no [[material]] tables".to_owned()
            } else {
                format!("materials: {}", names.join(", "))
            };
            self.invalid(at, "material", format!("material {wanted:?} is not defined ({known})"))
        })?;

        let transform = self.placement(at, o)?;
        let uv_repeat = match o.uv_repeat {
            None => Vec2::ONE,
            Some(NumberOr::One(r)) => Vec2::splat(r),
            Some(NumberOr::Each(r)) => Vec2::from(r),
        };
        if !(uv_repeat.is_finite() && uv_repeat.min_element() > 0.0) {
            return Err(self.invalid(
                at,
                "uv_repeat",
                format!("uv_repeat is {uv_repeat}: both components must be finite and greater than 0"),
            ));
        }

        let mesh = self.mesh(at, o)?;
        let mesh = if uv_repeat == Vec2::ONE { mesh } else { Arc::new((*mesh).clone().scale_uvs(uv_repeat)) };
        Ok(Object { name, mesh, material, transform })
    }

    /// An object's transform from its position, rotation and scale.
    pub(super) fn placement(&self, at: &str, o: &ObjectFile) -> Result<Mat4, SceneError> {
        let position = self.vec3(at, "position", o.position.unwrap_or([0.0; 3]))?;
        let rotation = self.vec3(at, "rotation", o.rotation.unwrap_or([0.0; 3]))?;
        let scale = match o.scale {
            None => Vec3::ONE,
            Some(NumberOr::One(s)) => Vec3::splat(s),
            Some(NumberOr::Each(s)) => Vec3::from(s),
        };
        if !(scale.is_finite() && scale.min_element() > 0.0) {
            return Err(self.invalid(
                at,
                "scale",
                format!("scale is {scale}: every component must be finite and greater than 0"),
            ));
        }
        let r = rotation * (std::f32::consts::PI / 180.0);
        // X first, then Y, then Z (extrinsic): R = Rz * Ry * Rx.
        let rotation = Quat::from_rotation_z(r.z) * Quat::from_rotation_y(r.y) * Quat::from_rotation_x(r.x);
        Ok(Mat4::from_scale_rotation_translation(scale, rotation, position))
    }

    /// The object's mesh: a built-in shape with its parameters, or a file (cached).
    fn mesh(&mut self, at: &str, o: &ObjectFile) -> Result<Arc<Mesh>, SceneError> {
        let shape = o.mesh.trim().to_ascii_lowercase();
        let given = o.shape_keys();
        let takes: &[&str] = match shape.as_str() {
            "plane" => &["size", "segments"],
            "quad" => &["size"],
            "disc" => &["radius", "segments"],
            "cube" => &["size"],
            "sphere" => &["radius", "rings", "segments"],
            "cylinder" => &["radius", "height", "segments"],
            "torus" => &["radius", "tube_radius", "segments", "tube_segments"],
            _ => &[],
        };
        if let Some((field, _)) = given.iter().find(|(f, set)| *set && !takes.contains(f)) {
            let what = if takes.is_empty() && !is_shape(&shape) {
                format!("{field} applies to built-in shapes, not to the mesh file {:?}", o.mesh)
            } else if takes.is_empty() {
                format!("{field} does not apply to mesh {shape:?} (it takes no parameters)")
            } else {
                format!("{field} does not apply to mesh {shape:?} (it takes: {})", takes.join(", "))
            };
            return Err(self.invalid(at, field, what));
        }
        let length = |field: &str, v: Option<f32>, default: f32| -> Result<f32, SceneError> {
            self.number(at, field, v.unwrap_or(default), 0.0, true)
        };
        let count = |field: &str, v: Option<u32>, default: u32, min: u32| -> Result<u32, SceneError> {
            let n = v.unwrap_or(default);
            if (min..=MAX_SEGMENTS).contains(&n) {
                Ok(n)
            } else {
                Err(self.invalid(at, field, format!("{field} is {n}: mesh {shape:?} needs {min} to {MAX_SEGMENTS}")))
            }
        };
        let size2 = |default: f32| -> Result<Vec2, SceneError> {
            let s = match o.size {
                None => Vec2::splat(default),
                Some(NumberOr::One(s)) => Vec2::splat(s),
                Some(NumberOr::Each(s)) => Vec2::from(s),
            };
            if s.is_finite() && s.min_element() > 0.0 {
                Ok(s)
            } else {
                Err(self.invalid(at, "size", format!("size is {s}: both components must be finite and greater than 0")))
            }
        };
        let mesh = match shape.as_str() {
            "plane" => Mesh::plane(size2(2.0)?, count("segments", o.segments, 1, 1)?),
            "quad" => Mesh::quad(size2(2.0)?),
            "disc" => Mesh::disc(length("radius", o.radius, 1.0)?, count("segments", o.segments, 64, 3)?),
            "cube" => {
                let s = match o.size {
                    None => 2.0,
                    Some(NumberOr::One(s)) => s,
                    Some(NumberOr::Each(_)) => {
                        return Err(self.invalid(
                            at,
                            "size",
                            "size of a cube is one number (the edge); use scale for a box",
                        ));
                    }
                };
                Mesh::cube(length("size", Some(s), 2.0)?)
            }
            "sphere" => Mesh::uv_sphere(
                length("radius", o.radius, 1.0)?,
                count("rings", o.rings, 32, 2)?,
                count("segments", o.segments, 64, 3)?,
            ),
            "cylinder" => Mesh::cylinder(
                length("radius", o.radius, 1.0)?,
                length("height", o.height, 2.0)?,
                count("segments", o.segments, 64, 3)?,
            ),
            "torus" => Mesh::torus(
                length("radius", o.radius, 1.0)?,
                length("tube_radius", o.tube_radius, 0.25)?,
                count("segments", o.segments, 64, 3)?,
                count("tube_segments", o.tube_segments, 32, 3)?,
            ),
            _ => return self.mesh_file(at, &o.mesh),
        };
        Ok(Arc::new(mesh))
    }

    fn mesh_file(&mut self, at: &str, value: &str) -> Result<Arc<Mesh>, SceneError> {
        if value.contains('\0') {
            return Err(self.invalid(
                at,
                "mesh",
                format!("mesh {value:?}: a file name cannot contain a NUL byte (\\u{{0}})"),
            ));
        }
        let path = self.base.join(value);
        if let Some(m) = self.cache.meshes.get(&path) {
            return Ok(m.clone());
        }
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("obj" | "gltf" | "glb")) {
            return Err(self.invalid(
                at,
                "mesh",
                format!(
                    "mesh {value:?} is neither a built-in shape (plane, quad, disc, cube, sphere, cylinder, torus) \
                     nor a .obj, .gltf or .glb file"
                ),
            ));
        }
        let mesh = load_mesh(&path).map_err(|source| SceneError::Mesh {
            file: self.file.to_owned(),
            at: at.to_owned(),
            mesh: value.to_owned(),
            cause: Box::new(source),
        })?;
        let mesh = Arc::new(mesh);
        self.cache.meshes.insert(path, mesh.clone());
        Ok(mesh)
    }
}

/// An upper bound on the memory building an object's built-in shape takes (0 for mesh files,
/// which are held to their own cap): its vertices and triangles (a grid of its segment counts,
/// clamped as the loader will, plus poles and caps) twice over, for the buffers growing while it
/// is built and the tangent computation.
pub(super) fn shape_bytes(o: &ObjectFile) -> u64 {
    shape_counts(o).map_or(0, |(verts, tris)| Mesh::bytes_for(verts, tris).saturating_mul(2))
}

/// Upper bounds on the vertices and triangles of an object's built-in shape (a grid of its
/// segment counts, clamped as the loader will, plus poles and caps); `None` for a mesh file.
pub(super) fn shape_counts(o: &ObjectFile) -> Option<(u64, u64)> {
    let count = |v: Option<u32>, default: u32| u64::from(v.unwrap_or(default).clamp(1, MAX_SEGMENTS));
    let (a, b) = match o.mesh.trim().to_ascii_lowercase().as_str() {
        "plane" => (count(o.segments, 1), count(o.segments, 1)),
        "disc" => (1, count(o.segments, 64)),
        "sphere" => (count(o.rings, 32), count(o.segments, 64)),
        "cylinder" => (3, count(o.segments, 64)),
        "torus" => (count(o.segments, 64), count(o.tube_segments, 32)),
        "quad" | "cube" => (6, 1),
        _ => return None,
    };
    Some(((a + 3) * (b + 3), 2 * (a + 1) * (b + 1)))
}

/// Whether `name` (lowercase) is a built-in shape.
pub(super) fn is_shape(name: &str) -> bool {
    matches!(name, "plane" | "quad" | "disc" | "cube" | "sphere" | "cylinder" | "torus")
}
