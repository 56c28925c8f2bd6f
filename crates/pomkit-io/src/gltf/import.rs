//! A glTF file's default scene as pomkit's camera, lights, materials and objects
//! (docs/SCENES.md, glTF files).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::{displacement_depth_scale, mean_uv_unit_length};
use pomkit_core::scene::{Camera, Light, Material, NormalMap, Object, Texture};
use pomkit_core::{EdgeMode, HeightField, Technique};
use serde_json::Value;

use super::DISPLACEMENT_EXTENSION;
use crate::mesh::{
    MAX_NODE_DEPTH, MeshLoadError, OpenGltf, open_gltf, part_mesh, place, read_local, uri_path, where_in,
};
use crate::{Channel, HeightLoadOptions};

/// A glTF file read as pomkit's parts (before the scene loader applies the materials' pomkit
/// settings).
pub(crate) struct Import {
    /// The camera of the first camera node, when it is a perspective one.
    pub(crate) camera: Option<Camera>,
    /// A camera that frames the scene's bounds from above at an angle.
    pub(crate) framing: Camera,
    /// The `KHR_lights_punctual` lights of the scene's nodes.
    pub(crate) lights: Vec<Light>,
    /// One per glTF material and UV scale used.
    pub(crate) materials: Vec<Imported>,
    /// One per triangle primitive instance, in world space (identity transforms).
    pub(crate) objects: Vec<Object>,
    /// What is drawn otherwise than the file says, for the user.
    pub(crate) warnings: Vec<String>,
}

/// A pomkit material made from a glTF material.
pub(crate) struct Imported {
    /// The material (its name unique in the file).
    pub(crate) material: Material,
    /// The glTF material's name as scene files refer to it (shared by its UV-scale copies).
    pub(crate) gltf_name: String,
    /// `material 2 'Bricks'`, for messages.
    pub(crate) label: String,
    /// `extras.pomkit`, when given.
    pub(crate) pomkit: Option<Value>,
}

/// A 2D affine map of UVs (`KHR_texture_transform`): `uv' = m * uv + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct UvTransform {
    m: pomkit_core::glam::Mat2,
    t: Vec2,
}

impl UvTransform {
    /// `translation * rotation * scale` as the extension defines it.
    fn new(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> Self {
        let (s, c) = rotation.sin_cos();
        let r = pomkit_core::glam::Mat2::from_cols(Vec2::new(c, s), Vec2::new(-s, c));
        let m = r * pomkit_core::glam::Mat2::from_diagonal(Vec2::from(scale));
        Self { m, t: Vec2::from(offset) }
    }

    fn apply(&self, uv: Vec2) -> Vec2 {
        self.m * uv + self.t
    }

    /// Whether tangents given for the untransformed UVs still hold: no rotation, no mirror.
    fn keeps_tangents(&self) -> bool {
        self.m.x_axis.y == 0.0 && self.m.y_axis.x == 0.0 && self.m.x_axis.x > 0.0 && self.m.y_axis.y > 0.0
    }
}

/// The most image bytes one glTF texture may hold (as an image file).
fn image_cap() -> u64 {
    crate::read::MAX_IMAGE_BYTES
}

/// What a glTF material becomes before its meshes are known.
struct Prepared {
    material: Material,
    gltf_name: String,
    label: String,
    pomkit: Option<Value>,
    transform: Option<UvTransform>,
    /// `displacementGeometryFactor` when the material is traced.
    factor: Option<f32>,
}

/// Reads the glTF file at `path` (`.gltf` or `.glb`).
pub(crate) fn import(path: &Path) -> Result<Import, MeshLoadError> {
    let bytes = crate::read::read_capped(path, crate::read::MAX_MESH_BYTES, "a glTF file")
        .map_err(|reason| MeshLoadError::Read { path: path.to_owned(), reason })?;
    // Third-party parsers fed untrusted input: a panic becomes an error naming the file.
    catch_unwind(AssertUnwindSafe(|| import_bytes(&bytes, path))).unwrap_or_else(|_| {
        Err(MeshLoadError::Gltf { path: path.to_owned(), reason: "the parser failed on malformed data".to_owned() })
    })
}

fn invalid(path: &Path, message: String) -> MeshLoadError {
    MeshLoadError::Invalid { path: path.to_owned(), message }
}

/// `material 2 'Bricks'` (or `material 2`).
fn material_label(m: &gltf::Material<'_>) -> String {
    match (m.index(), m.name()) {
        (Some(i), Some(n)) => format!("material {i} '{n}'"),
        (Some(i), None) => format!("material {i}"),
        (None, _) => "the default material".to_owned(),
    }
}

fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind} {index} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

fn import_bytes(bytes: &[u8], path: &Path) -> Result<Import, MeshLoadError> {
    let OpenGltf { document, buffers } = open_gltf(bytes, path)?;
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_owned();
    let mut warnings = Vec::new();

    // The scene's nodes in document order (pre-order), with their world transforms.
    let mut nodes: Vec<(gltf::Node<'_>, Mat4)> = Vec::new();
    let scene = document.default_scene().or_else(|| document.scenes().next());
    if let Some(scene) = &scene {
        let mut stack: Vec<(gltf::Node<'_>, Mat4, usize)> =
            scene.nodes().collect::<Vec<_>>().into_iter().rev().map(|n| (n, Mat4::IDENTITY, 0)).collect();
        while let Some((node, parent, depth)) = stack.pop() {
            if depth > MAX_NODE_DEPTH {
                return Err(MeshLoadError::Gltf {
                    path: path.to_owned(),
                    reason: format!("the node hierarchy is deeper than {MAX_NODE_DEPTH} levels"),
                });
            }
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            let children: Vec<_> = node.children().collect();
            stack.extend(children.into_iter().rev().map(|c| (c, world, depth + 1)));
            nodes.push((node, world));
        }
    }

    // Materials: each glTF material prepared once, on first use.
    let mut prepared: Vec<Option<Prepared>> = (0..=document.materials().len()).map(|_| None).collect();
    let mut materials: Vec<Imported> = Vec::new();
    // (glTF material slot, depth_scale) -> pomkit material.
    let mut made: Vec<(usize, Option<f32>, usize)> = Vec::new();
    let mut objects = Vec::new();
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let instances: Vec<(gltf::Mesh<'_>, Mat4)> = if scene.is_some() {
        nodes.iter().filter_map(|(n, w)| n.mesh().map(|m| (m, *w))).collect()
    } else {
        document.meshes().map(|m| (m, Mat4::IDENTITY)).collect()
    };
    for (mesh, world) in &instances {
        for prim in mesh.primitives() {
            let Some(mut local) = read_local(&prim, mesh, &buffers, path)? else { continue };
            let gm = prim.material();
            let slot = gm.index().map_or(document.materials().len(), |i| i);
            if prepared[slot].is_none() {
                prepared[slot] = Some(prepare(&gm, &document, &buffers, &base, path, &mut warnings)?);
            }
            let Some(p) = prepared[slot].as_ref() else { continue };
            if let Some(t) = &p.transform {
                local.uvs.iter_mut().for_each(|uv| *uv = t.apply(*uv));
                if !t.keeps_tangents() {
                    local.tangents = None;
                }
            }
            let depth_scale = match p.factor {
                None => None,
                Some(factor) => {
                    let positions: Vec<[f32; 3]> = local.positions.iter().map(|v| v.to_array()).collect();
                    let uvs: Vec<[f32; 2]> = local.uvs.iter().map(|v| v.to_array()).collect();
                    let scale = mean_uv_unit_length(&positions, &uvs, &local.indices)
                        .and_then(|l| displacement_depth_scale(factor, l))
                        .ok_or_else(|| {
                            invalid(
                                path,
                                format!(
                                    "{}: its UVs cover no area, so the displacement of {} cannot be converted to a \
                                     depth in UV units",
                                    where_in(mesh, prim.index()),
                                    p.label
                                ),
                            )
                        })?;
                    pomkit_core::trace::check_depth_scale(scale).map_err(|e| {
                        invalid(
                            path,
                            format!(
                                "{} on {}: displacementGeometryFactor {factor} over a UV unit of {} units is a \
                                 depth_scale of {scale}: {e}",
                                p.label,
                                where_in(mesh, prim.index()),
                                factor / scale
                            ),
                        )
                    })?;
                    Some(scale)
                }
            };
            let close = |a: Option<f32>, b: Option<f32>| match (a, b) {
                (None, None) => true,
                (Some(a), Some(b)) => (a - b).abs() <= 1e-4 * a.abs().max(b.abs()),
                _ => false,
            };
            let index = match made.iter().find(|(s, d, _)| *s == slot && close(*d, depth_scale)) {
                Some(&(_, _, i)) => i,
                None => {
                    let copies = made.iter().filter(|(s, _, _)| *s == slot).count();
                    let mut material = p.material.clone();
                    if copies > 0 {
                        material.name = format!("{} ~{}", material.name, copies + 1);
                    }
                    if let Some(d) = depth_scale {
                        material.depth_scale = d;
                    }
                    materials.push(Imported {
                        material,
                        gltf_name: p.gltf_name.clone(),
                        label: p.label.clone(),
                        pomkit: p.pomkit.clone(),
                    });
                    made.push((slot, depth_scale, materials.len() - 1));
                    materials.len() - 1
                }
            };
            let part = place(local, &prim, mesh, *world, path)?;
            let mesh_data = part_mesh(part, path)?;
            let (a, b) = mesh_data.bounds();
            lo = lo.min(a);
            hi = hi.max(b);
            let name = match mesh.name() {
                Some(n) => format!("{n} {}", prim.index()),
                None => format!("mesh {} {}", mesh.index(), prim.index()),
            };
            objects.push(Object { name, mesh: Arc::new(mesh_data), material: index, transform: Mat4::IDENTITY });
        }
    }
    if objects.is_empty() {
        return Err(MeshLoadError::NoTriangles { path: path.to_owned() });
    }
    let bounds = (lo, hi);
    let framing = framing_camera(bounds);

    // The first camera of the scene's nodes.
    let mut camera = None;
    if let Some((node, world)) = nodes.iter().find(|(n, _)| n.camera().is_some()) {
        let Some(cam) = node.camera() else { unreachable!("found by its camera") };
        let label = named("camera", cam.index(), cam.name());
        match cam.projection() {
            gltf::camera::Projection::Perspective(p) => {
                if let Some(a) = p.aspect_ratio()
                    && !(a.is_finite() && a > 0.0)
                {
                    return Err(invalid(path, format!("{label}: aspectRatio is {a}: it must be greater than 0")));
                }
                let yfov = p.yfov();
                if !(yfov.is_finite() && yfov > 0.0) {
                    return Err(invalid(path, format!("{label}: yfov is {yfov}: it must be greater than 0")));
                }
                let eye = world.transform_point3(Vec3::ZERO);
                let forward = world.transform_vector3(Vec3::NEG_Z).try_normalize();
                let up = world.transform_vector3(Vec3::Y).try_normalize();
                let (Some(forward), Some(up)) = (forward, up) else {
                    return Err(invalid(path, format!("{label}: its node's transform is degenerate")));
                };
                let centre = 0.5 * (bounds.0 + bounds.1);
                let along = (centre - eye).dot(forward);
                let reach = (bounds.1 - bounds.0).length().max(1e-3);
                let target = eye + forward * if along > 1e-3 * reach { along } else { reach };
                let near = p.znear();
                let far = match p.zfar() {
                    Some(f) => f,
                    None => {
                        // Far enough for every corner of the scene's bounds.
                        let corners = (0..8).map(|k| {
                            let pick = |bit: usize, a: f32, b: f32| if k & bit == 0 { a } else { b };
                            Vec3::new(
                                pick(1, bounds.0.x, bounds.1.x),
                                pick(2, bounds.0.y, bounds.1.y),
                                pick(4, bounds.0.z, bounds.1.z),
                            )
                        });
                        let d = corners.map(|c| (c - eye).length()).fold(0.0f32, f32::max);
                        (2.0 * d).max(near * 1000.0)
                    }
                };
                camera = Some(Camera { eye, target, up, fov_y_deg: yfov.to_degrees(), near, far });
            }
            gltf::camera::Projection::Orthographic(_) => warnings.push(format!(
                "{label} is orthographic, which pomkit does not draw: the default camera (framing the scene from \
                 above) is used"
            )),
        }
    }

    // KHR_lights_punctual.
    let mut lights = Vec::new();
    for (node, world) in &nodes {
        let Some(light) = node.light() else { continue };
        let label = named("light", light.index(), light.name());
        let color = Vec3::from(light.color());
        let intensity = light.intensity();
        if !(color.is_finite() && color.min_element() >= 0.0 && intensity.is_finite() && intensity >= 0.0) {
            return Err(invalid(
                path,
                format!("{label}: color {color} and intensity {intensity} must be finite and not negative"),
            ));
        }
        let position = world.transform_point3(Vec3::ZERO);
        match light.kind() {
            gltf::khr_lights_punctual::Kind::Directional => {
                let Some(direction) = world.transform_vector3(Vec3::Z).try_normalize() else {
                    return Err(invalid(path, format!("{label}: its node's transform is degenerate")));
                };
                lights.push(Light::Directional { direction, color, intensity });
            }
            gltf::khr_lights_punctual::Kind::Point => lights.push(Light::Point { position, color, intensity }),
            gltf::khr_lights_punctual::Kind::Spot { .. } => {
                warnings.push(format!("{label} is a spot light: drawn as a point light (its cone is not modelled)"));
                lights.push(Light::Point { position, color, intensity });
            }
        }
    }

    Ok(Import { camera, framing, lights, materials, objects, warnings })
}

/// A camera looking at the bounds' centre from above at an angle, far enough to see them whole.
fn framing_camera((lo, hi): (Vec3, Vec3)) -> Camera {
    let centre = 0.5 * (lo + hi);
    let radius = (0.5 * (hi - lo).length()).max(1e-3);
    let fov = 45.0f32;
    let distance = radius / (0.5 * fov.to_radians()).sin() * 1.05;
    let eye = centre + Vec3::new(0.0, 1.0, 1.2).normalize() * distance;
    Camera {
        eye,
        target: centre,
        up: Vec3::Y,
        fov_y_deg: fov,
        near: (distance - radius).max(distance * 1e-3) * 0.5,
        far: (distance + radius) * 2.0,
    }
}

/// The bytes of a texture's image and a path naming it in messages (its file, or the glTF file
/// with the image's index).
fn image_bytes(
    texture: &gltf::Texture<'_>,
    buffers: &[gltf::buffer::Data],
    base: &Path,
    path: &Path,
) -> Result<(Vec<u8>, PathBuf), String> {
    let image = texture.source();
    let inside = || PathBuf::from(format!("{} ({})", path.display(), named("image", image.index(), image.name())));
    match image.source() {
        gltf::image::Source::Uri { uri, .. } => {
            if let Some(data) = uri.strip_prefix("data:") {
                let (_, encoded) =
                    data.split_once(";base64,").ok_or_else(|| "its data URI is not base64".to_owned())?;
                let bytes = base64::decode(encoded).map_err(|e| format!("its data URI does not decode: {e}"))?;
                return Ok((bytes, inside()));
            }
            let file = uri_path(uri, base).ok_or_else(|| format!("its image URI {uri:?} is not a file"))?;
            let bytes = crate::read::read_image_file(&file).map_err(|e| e.to_string())?;
            Ok((bytes, file))
        }
        gltf::image::Source::View { view, .. } => {
            let data = buffers.get(view.buffer().index()).map(|d| &d.0[..]).unwrap_or(&[]);
            let end = view.offset().saturating_add(view.length());
            let bytes = data.get(view.offset()..end).ok_or_else(|| {
                format!("its buffer view {} lies outside buffer {}", view.index(), view.buffer().index())
            })?;
            if bytes.len() as u64 > image_cap() {
                return Err(format!("its image is {} bytes, more than an image may be", bytes.len()));
            }
            Ok((bytes.to_vec(), inside()))
        }
    }
}

/// A JSON number at `key` of `obj`, or `default` when absent.
fn number(obj: &serde_json::Map<String, Value>, key: &str, default: f32) -> Result<f32, String> {
    match obj.get(key) {
        None => Ok(default),
        Some(v) => match v.as_f64() {
            Some(x) if (x as f32).is_finite() => Ok(x as f32),
            _ => Err(format!("{key} is {v}: it must be a finite number")),
        },
    }
}

/// A texture transform written as JSON (`extensions.KHR_texture_transform` of a textureInfo).
fn json_transform(info: &serde_json::Map<String, Value>) -> Result<(Option<UvTransform>, u64), String> {
    let tex_coord = info.get("texCoord").and_then(Value::as_u64).unwrap_or(0);
    let Some(t) = info.get("extensions").and_then(|e| e.get("KHR_texture_transform")).and_then(Value::as_object) else {
        return Ok((None, tex_coord));
    };
    let pair = |key: &str, default: [f32; 2]| -> Result<[f32; 2], String> {
        match t.get(key) {
            None => Ok(default),
            Some(v) => {
                let a = v.as_array().filter(|a| a.len() == 2);
                let xs: Option<Vec<f32>> = a.map(|a| a.iter().filter_map(Value::as_f64).map(|x| x as f32).collect());
                match xs {
                    Some(xs) if xs.len() == 2 && xs.iter().all(|x| x.is_finite()) => Ok([xs[0], xs[1]]),
                    _ => Err(format!("KHR_texture_transform {key} is {v}: it must be two finite numbers")),
                }
            }
        }
    };
    let rotation = number(t, "rotation", 0.0).map_err(|e| format!("KHR_texture_transform {e}"))?;
    let tc = t.get("texCoord").and_then(Value::as_u64).unwrap_or(tex_coord);
    Ok((Some(UvTransform::new(pair("offset", [0.0, 0.0])?, rotation, pair("scale", [1.0, 1.0])?)), tc))
}

fn typed_transform(t: Option<gltf::texture::TextureTransform<'_>>) -> Option<UvTransform> {
    t.map(|t| UvTransform::new(t.offset(), t.rotation(), t.scale()))
}

/// The pomkit edge mode of a sampler, with a warning for what pomkit cannot do.
fn edges_of(sampler: &gltf::texture::Sampler<'_>, label: &str, warnings: &mut Vec<String>) -> EdgeMode {
    use gltf::texture::WrappingMode::{ClampToEdge, MirroredRepeat};
    let (s, t) = (sampler.wrap_s(), sampler.wrap_t());
    if s == MirroredRepeat || t == MirroredRepeat {
        warnings.push(format!("{label}: mirrored repeat is drawn as repeat (wrap)"));
        return EdgeMode::Wrap;
    }
    match (s, t) {
        (ClampToEdge, ClampToEdge) => EdgeMode::Clamp,
        (ClampToEdge, _) | (_, ClampToEdge) => {
            warnings.push(format!(
                "{label}: its sampler clamps one axis and repeats the other; pomkit has one edge mode per material: \
                 wrap"
            ));
            EdgeMode::Wrap
        }
        _ => EdgeMode::Wrap,
    }
}

/// A glTF material as a pomkit material (no depth_scale yet), its UV transform and its
/// displacement factor.
fn prepare(
    gm: &gltf::Material<'_>,
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    base: &Path,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Prepared, MeshLoadError> {
    let label = material_label(gm);
    let err = |message: String| invalid(path, format!("{label}: {message}"));
    let gltf_name = match (gm.index(), gm.name()) {
        (_, Some(n)) if document.materials().filter(|m| m.name() == Some(n)).count() == 1 => n.to_owned(),
        (Some(i), Some(n)) => format!("{n} ({i})"),
        (Some(i), None) => format!("material {i}"),
        (None, _) => "default material".to_owned(),
    };
    let pbr = gm.pbr_metallic_roughness();
    let factor = Vec3::from_slice(&pbr.base_color_factor()[..3]);
    let mut material = Material {
        name: gltf_name.clone(),
        base_color: factor.max(Vec3::ZERO),
        shininess: crate::library::shininess_from_roughness(pbr.roughness_factor()),
        specular: crate::library::specular_for_shininess(crate::library::shininess_from_roughness(
            pbr.roughness_factor(),
        )),
        technique: Technique::Normal,
        ..Material::default()
    };

    // The textures and their UV transforms.
    let texture = |tex: &gltf::Texture<'_>, what: &str| -> Result<(Vec<u8>, PathBuf), MeshLoadError> {
        image_bytes(tex, buffers, base, path).map_err(|e| err(format!("{what} (texture {}): {e}", tex.index())))
    };
    let mut transforms: Vec<(&str, Option<UvTransform>)> = Vec::new();
    let mut tex_coords: Vec<(&str, u64)> = Vec::new();
    let mut edge_source: Option<(gltf::texture::Sampler<'_>, String)> = None;

    // Displacement (a draft extension: read from its JSON).
    let mut displacement = None;
    if let Some(ext) = gm.extension_value(DISPLACEMENT_EXTENSION) {
        let obj = ext.as_object().ok_or_else(|| err(format!("{DISPLACEMENT_EXTENSION} is not an object")))?;
        let f = number(obj, "displacementGeometryFactor", 1.0).map_err(|e| err(e.to_string()))?;
        let offset = number(obj, "displacementGeometryOffset", 0.0).map_err(|e| err(e.to_string()))?;
        if f < 0.0 {
            return Err(err(format!(
                "displacementGeometryFactor is {f}: it must not be negative (the height range, in the mesh's units)"
            )));
        }
        match obj.get("displacementGeometryTexture") {
            None => warnings
                .push(format!("{label}: {DISPLACEMENT_EXTENSION} has no displacementGeometryTexture: not traced")),
            Some(info) => {
                let info =
                    info.as_object().ok_or_else(|| err("displacementGeometryTexture is not an object".into()))?;
                let index = info
                    .get("index")
                    .and_then(Value::as_u64)
                    .ok_or_else(|| err("displacementGeometryTexture has no texture index".into()))?;
                let tex = document.textures().nth(index as usize).ok_or_else(|| {
                    err(format!(
                        "displacementGeometryTexture refers to texture {index}, but the file has {}",
                        document.textures().len()
                    ))
                })?;
                let (t, tc) = json_transform(info).map_err(|e| err(format!("displacementGeometryTexture: {e}")))?;
                transforms.push(("displacementGeometryTexture", t));
                tex_coords.push(("displacementGeometryTexture", tc));
                if f == 0.0 {
                    warnings.push(format!("{label}: displacementGeometryFactor is 0: not traced"));
                } else {
                    let (bytes, name) = texture(&tex, "displacementGeometryTexture")?;
                    let opts = HeightLoadOptions { channel: Channel::R, depth_map: false, normalize: false };
                    let field: HeightField = crate::decode_height_field(&bytes, &name, &opts)
                        .map_err(|e| err(format!("displacementGeometryTexture (texture {}): {e}", tex.index())))?;
                    if (offset + f).abs() > 1e-6 * f {
                        warnings.push(format!(
                            "{label}: displacementGeometryOffset is {offset}; pomkit draws the relief's top (red = 1) \
                             on the polygon, as if the offset were -{f}"
                        ));
                    }
                    material.height = Some(Arc::new(field));
                    material.technique = Material::default().technique;
                    displacement = Some(f);
                    edge_source = Some((tex.sampler(), format!("{label}: displacementGeometryTexture")));
                }
            }
        }
    }

    if let Some(info) = pbr.base_color_texture() {
        let tex = info.texture();
        transforms.push(("baseColorTexture", typed_transform(info.texture_transform())));
        tex_coords.push(("baseColorTexture", u64::from(info.tex_coord())));
        let (bytes, name) = texture(&tex, "baseColorTexture")?;
        let t: Texture = crate::scene::decode_color_texture(&bytes, &name)
            .map_err(|e| err(format!("baseColorTexture (texture {}): {e}", tex.index())))?;
        material.albedo = Some(Arc::new(t));
        edge_source.get_or_insert_with(|| (tex.sampler(), format!("{label}: baseColorTexture")));
    }
    if let Some(info) = gm.normal_texture() {
        let tex = info.texture();
        // The normal textureInfo's extensions are not typed by the gltf crate: read as JSON.
        let t = info.extension_value("KHR_texture_transform").and_then(Value::as_object);
        let t = match t {
            Some(t) => {
                let mut wrapped = serde_json::Map::new();
                wrapped.insert("extensions".into(), serde_json::json!({ "KHR_texture_transform": t }));
                json_transform(&wrapped).map_err(|e| err(format!("normalTexture: {e}")))?.0
            }
            None => None,
        };
        transforms.push(("normalTexture", t));
        tex_coords.push(("normalTexture", u64::from(info.tex_coord())));
        let (bytes, name) = texture(&tex, "normalTexture")?;
        let map = crate::scene::decode_normal_map(&bytes, &name, false)
            .map_err(|e| err(format!("normalTexture (texture {}): {e}", tex.index())))?;
        // glTF: the sampled normal's x and y are multiplied by `scale`, then normalized.
        let s = info.scale();
        let map = if s == 1.0 {
            map
        } else {
            let scaled = map.normals().iter().map(|n| Vec3::new(n.x * s, n.y * s, n.z)).collect();
            NormalMap::new(map.width(), map.height(), scaled).unwrap_or(map)
        };
        material.normal_map = Some(Arc::new(map));
        edge_source.get_or_insert_with(|| (tex.sampler(), format!("{label}: normalTexture")));
    }
    if let Some((sampler, what)) = &edge_source {
        material.edges = edges_of(sampler, what, warnings);
    }
    for (what, tc) in &tex_coords {
        if *tc != 0 {
            warnings.push(format!("{label}: {what} uses TEXCOORD_{tc}; pomkit maps every texture with TEXCOORD_0"));
        }
    }
    // One UV set per material: the displacement's transform, else the base colour's.
    let transform = transforms.first().and_then(|(_, t)| *t);
    if let Some((first, _)) = transforms.first()
        && let Some((other, _)) = transforms.iter().find(|(_, t)| *t != transform)
    {
        warnings.push(format!(
            "{label}: {other} has another KHR_texture_transform than {first}; pomkit uses one UV set per material: \
             {first}'s"
        ));
    }
    let pomkit = match gm.extras() {
        Some(raw) => {
            let v: Value = serde_json::from_str(raw.get()).map_err(|e| err(format!("extras: {e}")))?;
            v.get("pomkit").cloned()
        }
        None => None,
    };
    Ok(Prepared { material, gltf_name, label, pomkit, transform, factor: displacement })
}
