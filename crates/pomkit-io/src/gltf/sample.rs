//! A small glTF asset written from pomkit's built-in maps: a textured plane with a base colour
//! map, a normal map baked from the height map and, optionally, the height map itself as
//! `KHR_materials_displacement`. For tests, examples and demonstrations; every file it needs
//! is made here, nothing is downloaded.

use std::path::{Path, PathBuf};

use pomkit_core::bake::{NormalBakeOptions, bake_normals_rgb8};
use pomkit_core::glam::{Mat3, Quat, Vec3};
use pomkit_core::procedural::{self, Pattern};
use serde_json::{Value, json};

use crate::IoError;

use super::{DISPLACEMENT_EXTENSION, write_all_or_nothing};

/// The relief of a sample's material, written as `KHR_materials_displacement`: the surface
/// moves along its normal by `red * factor + offset` file units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleDisplacement {
    /// `displacementGeometryFactor`: the height range in the file's units.
    pub factor: f32,
    /// `displacementGeometryOffset`: `-factor` puts the top of the relief on the polygon, which
    /// is how pomkit draws it.
    pub offset: f32,
}

/// A camera of a sample: a node at `eye` looking at `target` (up +Y) with a perspective
/// projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleCamera {
    /// The eye, in world units.
    pub eye: Vec3,
    /// The point looked at.
    pub target: Vec3,
    /// Vertical field of view in degrees (written in radians, as glTF stores it).
    pub yfov_deg: f32,
    /// `aspectRatio`; `None` leaves it out (the viewport's).
    pub aspect_ratio: Option<f32>,
    /// `znear`.
    pub znear: f32,
    /// `zfar`; `None` leaves it out (an infinite projection).
    pub zfar: Option<f32>,
}

impl Default for SampleCamera {
    fn default() -> Self {
        Self {
            eye: Vec3::new(0.0, 1.5, 2.5),
            target: Vec3::ZERO,
            yfov_deg: 45.0,
            aspect_ratio: None,
            znear: 0.05,
            zfar: Some(100.0),
        }
    }
}

/// A `KHR_lights_punctual` light of a sample, placed on its own node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SampleLight {
    /// A directional light; `toward` points from the scene toward the light (the node's +Z).
    Directional {
        /// Direction toward the light.
        toward: Vec3,
        /// Linear RGB.
        color: Vec3,
        /// Illuminance (lux).
        intensity: f32,
    },
    /// A point light at `position`.
    Point {
        /// Where it is.
        position: Vec3,
        /// Linear RGB.
        color: Vec3,
        /// Luminous intensity (candela).
        intensity: f32,
    },
    /// A spot light at `position` shining toward `target`.
    Spot {
        /// Where it is.
        position: Vec3,
        /// The point it shines at.
        target: Vec3,
        /// Linear RGB.
        color: Vec3,
        /// Luminous intensity (candela).
        intensity: f32,
    },
}

/// What [`write_sample`] writes. The default: a 2 x 2 plane of built-in bricks (64 x 64 maps)
/// in the XZ plane facing +Y, with base colour and normal textures and a displacement of 0.1
/// (offset -0.1), no camera, no light, as a `.gltf` with its `.bin` and PNGs.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleOptions {
    /// The file stem: `NAME.gltf` (or `.glb`), `NAME.bin`, `NAME_albedo.png`, `NAME_normal.png`,
    /// `NAME_height.png`.
    pub name: String,
    /// The built-in height map (and its matching colour map).
    pub pattern: Pattern,
    /// The maps' side in texels (at least 2).
    pub texture_size: u32,
    /// The plane's side in the file's units.
    pub size: f32,
    /// The UVs run from 0 to this along both axes (the texture repeats this many times across
    /// the plane; the samplers wrap).
    pub uv_repeat: f32,
    /// The material's name.
    pub material_name: String,
    /// Write the colour map as `baseColorTexture`.
    pub base_color_texture: bool,
    /// Write a normal map baked from the height map (at the displacement's depth, or at a tenth
    /// of a UV unit without one) as `normalTexture`.
    pub normal_texture: bool,
    /// Write the height map as `KHR_materials_displacement`.
    pub displacement: Option<SampleDisplacement>,
    /// The plane node's `translation`.
    pub translation: Vec3,
    /// The plane node's `rotation`.
    pub rotation: Quat,
    /// The plane node's `scale`.
    pub scale: Vec3,
    /// A camera node (before the lights in the scene's node list).
    pub camera: Option<SampleCamera>,
    /// Light nodes.
    pub lights: Vec<SampleLight>,
    /// The material's `extras` (e.g. `{"pomkit": {"technique": "relief"}}`).
    pub extras: Option<Value>,
    /// `roughnessFactor` (`metallicFactor` is 0).
    pub roughness: f32,
    /// Write one `.glb` (images in its binary chunk) instead of `.gltf` + `.bin` + PNGs.
    pub binary: bool,
}

impl Default for SampleOptions {
    fn default() -> Self {
        Self {
            name: "sample".to_owned(),
            pattern: Pattern::Bricks,
            texture_size: 64,
            size: 2.0,
            uv_repeat: 1.0,
            material_name: "Bricks".to_owned(),
            base_color_texture: true,
            normal_texture: true,
            displacement: Some(SampleDisplacement { factor: 0.1, offset: -0.1 }),
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
            camera: None,
            lights: Vec::new(),
            extras: None,
            roughness: 0.5,
            binary: false,
        }
    }
}

/// Appends `bytes` to `bin` 4-byte aligned, with a buffer view (of buffer 0); returns the view's
/// index.
fn push_view(bin: &mut Vec<u8>, views: &mut Vec<Value>, bytes: &[u8], target: Option<u32>) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut view = json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len() });
    if let Some(t) = target {
        view["target"] = json!(t);
    }
    bin.extend_from_slice(bytes);
    views.push(view);
    views.len() - 1
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// PNG bytes of an 8-bit RGB image.
fn png_rgb8(w: u32, h: u32, rgb: &[[u8; 3]]) -> Result<Vec<u8>, image::ImageError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out).write_image(
        rgb.as_flattened(),
        w,
        h,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}

/// The rotation of a node whose -Z looks from `eye` at `target`, +Y up as far as possible.
fn look_rotation(eye: Vec3, target: Vec3) -> Quat {
    let back = (eye - target).try_normalize().unwrap_or(Vec3::Z);
    let right = Vec3::Y.cross(back).try_normalize().unwrap_or(Vec3::X);
    let up = back.cross(right);
    Quat::from_mat3(&Mat3::from_cols(right, up, back))
}

fn node_trs(translation: Vec3, rotation: Quat, scale: Vec3) -> Value {
    json!({
        "translation": translation.to_array(),
        "rotation": rotation.normalize().to_array(),
        "scale": scale.to_array(),
    })
}

/// Writes a sample glTF asset into the folder `dir` (which must exist) and returns the path of
/// its `.gltf` or `.glb` file.
///
/// The plane lies in the XZ plane facing +Y, `size` units on a side, with `POSITION`,
/// `NORMAL`, `TANGENT` (+X, handedness +1) and `TEXCOORD_0` (u along +X, v along +Z, from 0 to
/// `uv_repeat`); its material has `metallicFactor` 0, `roughnessFactor` as given, and the
/// textures the options ask for, all sampled with `REPEAT` and linear filters. The height map
/// is written with its height in the red channel (and green and blue), white = high; the
/// normal map is baked from it (central differences, +Y up) with the slope that a relief of
/// `factor` units has on this plane. Every file is staged and appears only when all are
/// written ([`crate::output::Outputs`]).
///
/// # Errors
/// [`IoError`] naming the file that could not be written, or [`IoError::Output`] when an output
/// is refused.
pub fn write_sample(dir: &Path, options: &SampleOptions) -> Result<PathBuf, IoError> {
    let o = options;
    let n = o.texture_size.max(2);
    let field = procedural::generate(o.pattern, n, n);
    let heights: Vec<[u8; 3]> = field
        .heights()
        .iter()
        .map(|h| {
            let v = (h.clamp(0.0, 1.0) * 255.0).round() as u8;
            [v, v, v]
        })
        .collect();
    let albedo = procedural::albedo(o.pattern, n, n);
    // Lengyel's scale: the height range in texel widths. A UV unit is size / uv_repeat file
    // units and spans n texels.
    let depth = o.displacement.map_or(0.1 * o.size / o.uv_repeat, |d| d.factor);
    let texel = o.size / (o.uv_repeat * n as f32);
    let scale = if texel > 0.0 && (depth / texel).is_finite() { depth / texel } else { 8.0 };
    let mut normals = vec![[0u8; 3]; (n * n) as usize];
    bake_normals_rgb8(&field, &NormalBakeOptions { scale, ..NormalBakeOptions::default() }, &mut normals, &|_| {})
        .map_err(|e| IoError::Write { path: dir.join(&o.name), reason: std::io::Error::other(e.to_string()) })?;

    let encode_fail = |file: &str, e: image::ImageError| IoError::Encode { path: dir.join(file), reason: e };
    let ext = if o.binary { "glb" } else { "gltf" };
    let main = dir.join(format!("{}.{ext}", o.name));
    let mut images: Vec<(String, Vec<u8>)> = Vec::new();
    let mut texture_of = |what: &str, px: &[[u8; 3]]| -> Result<usize, IoError> {
        let file = format!("{}_{what}.png", o.name);
        let bytes = png_rgb8(n, n, px).map_err(|e| encode_fail(&file, e))?;
        images.push((file, bytes));
        Ok(images.len() - 1)
    };
    let albedo_tex = if o.base_color_texture { Some(texture_of("albedo", &albedo)?) } else { None };
    let normal_tex = if o.normal_texture { Some(texture_of("normal", &normals)?) } else { None };
    let height_tex = if o.displacement.is_some() { Some(texture_of("height", &heights)?) } else { None };

    // Geometry: one quad, two counter-clockwise triangles seen from +Y.
    let h = 0.5 * o.size;
    let r = o.uv_repeat;
    let positions = [-h, 0.0, -h, h, 0.0, -h, h, 0.0, h, -h, 0.0, h];
    let normals_v = [0.0, 1.0, 0.0].repeat(4);
    let tangents = [1.0, 0.0, 0.0, 1.0].repeat(4);
    let uvs = [0.0, 0.0, r, 0.0, r, r, 0.0, r];
    let indices: Vec<u8> = [0u16, 3, 2, 0, 2, 1].iter().flat_map(|i| i.to_le_bytes()).collect();
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let vp = push_view(&mut bin, &mut views, &f32_bytes(&positions), Some(34962));
    let vn = push_view(&mut bin, &mut views, &f32_bytes(&normals_v), Some(34962));
    let vt = push_view(&mut bin, &mut views, &f32_bytes(&tangents), Some(34962));
    let vu = push_view(&mut bin, &mut views, &f32_bytes(&uvs), Some(34962));
    let vi = push_view(&mut bin, &mut views, &indices, Some(34963));
    let accessors = json!([
        { "bufferView": vp, "componentType": 5126, "count": 4, "type": "VEC3",
          "min": [-h, 0.0, -h], "max": [h, 0.0, h] },
        { "bufferView": vn, "componentType": 5126, "count": 4, "type": "VEC3" },
        { "bufferView": vt, "componentType": 5126, "count": 4, "type": "VEC4" },
        { "bufferView": vu, "componentType": 5126, "count": 4, "type": "VEC2" },
        { "bufferView": vi, "componentType": 5123, "count": 6, "type": "SCALAR" },
    ]);
    let image_json: Vec<Value> = images
        .iter()
        .map(|(file, bytes)| {
            if o.binary {
                let view = push_view(&mut bin, &mut views, bytes, None);
                json!({ "bufferView": view, "mimeType": "image/png" })
            } else {
                json!({ "uri": file })
            }
        })
        .collect();
    let textures: Vec<Value> = (0..images.len()).map(|i| json!({ "source": i, "sampler": 0 })).collect();

    let mut pbr = json!({ "metallicFactor": 0.0, "roughnessFactor": o.roughness });
    if let Some(t) = albedo_tex {
        pbr["baseColorTexture"] = json!({ "index": t });
    }
    let mut material = json!({ "name": o.material_name, "pbrMetallicRoughness": pbr });
    if let Some(t) = normal_tex {
        material["normalTexture"] = json!({ "index": t });
    }
    let mut extensions_used = Vec::new();
    if let (Some(t), Some(d)) = (height_tex, o.displacement) {
        material["extensions"] = json!({ DISPLACEMENT_EXTENSION: {
            "displacementGeometryTexture": { "index": t },
            "displacementGeometryFactor": d.factor,
            "displacementGeometryOffset": d.offset,
        }});
        extensions_used.push(DISPLACEMENT_EXTENSION);
    }
    if let Some(extras) = &o.extras {
        material["extras"] = extras.clone();
    }

    let mut plane = node_trs(o.translation, o.rotation, o.scale);
    plane["mesh"] = json!(0);
    plane["name"] = json!("plane");
    let mut nodes = vec![plane];
    let mut cameras = Vec::new();
    if let Some(c) = &o.camera {
        let mut persp = json!({ "yfov": c.yfov_deg.to_radians(), "znear": c.znear });
        if let Some(a) = c.aspect_ratio {
            persp["aspectRatio"] = json!(a);
        }
        if let Some(f) = c.zfar {
            persp["zfar"] = json!(f);
        }
        cameras.push(json!({ "name": "camera", "type": "perspective", "perspective": persp }));
        let mut node = node_trs(c.eye, look_rotation(c.eye, c.target), Vec3::ONE);
        node["camera"] = json!(0);
        node["name"] = json!("camera");
        nodes.push(node);
    }
    let mut lights = Vec::new();
    for (i, l) in o.lights.iter().enumerate() {
        let (light, node) = match *l {
            SampleLight::Directional { toward, color, intensity } => (
                json!({ "type": "directional", "color": color.to_array(), "intensity": intensity }),
                node_trs(Vec3::ZERO, look_rotation(toward, Vec3::ZERO), Vec3::ONE),
            ),
            SampleLight::Point { position, color, intensity } => (
                json!({ "type": "point", "color": color.to_array(), "intensity": intensity }),
                node_trs(position, Quat::IDENTITY, Vec3::ONE),
            ),
            SampleLight::Spot { position, target, color, intensity } => (
                json!({ "type": "spot", "color": color.to_array(), "intensity": intensity, "spot": {} }),
                node_trs(position, look_rotation(position, target), Vec3::ONE),
            ),
        };
        lights.push(light);
        let mut node = node;
        node["name"] = json!(format!("light {i}"));
        node["extensions"] = json!({ "KHR_lights_punctual": { "light": i } });
        nodes.push(node);
    }
    if !lights.is_empty() {
        extensions_used.push("KHR_lights_punctual");
    }

    let mut buffer = json!({ "byteLength": bin.len() });
    if !o.binary {
        buffer["uri"] = json!(format!("{}.bin", o.name));
    }
    let mut root = json!({
        "asset": { "version": "2.0", "generator": "pomkit (pomkit_io::gltf::write_sample)" },
        "scene": 0,
        "scenes": [{ "nodes": (0..nodes.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": [{ "name": "plane", "primitives": [{
            "attributes": { "POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3 },
            "indices": 4, "material": 0 }] }],
        "materials": [material],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [buffer],
        "samplers": [{ "magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497 }],
    });
    if !images.is_empty() {
        root["images"] = json!(image_json);
        root["textures"] = json!(textures);
    }
    if !cameras.is_empty() {
        root["cameras"] = json!(cameras);
    }
    if !lights.is_empty() {
        root["extensions"] = json!({ "KHR_lights_punctual": { "lights": lights } });
    }
    if !extensions_used.is_empty() {
        root["extensionsUsed"] = json!(extensions_used);
    }

    let text = serde_json::to_vec_pretty(&root)
        .map_err(|e| IoError::Write { path: main.clone(), reason: std::io::Error::other(e.to_string()) })?;
    let mut files: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    if o.binary {
        let glb = ::gltf::binary::Glb {
            header: ::gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
            json: text.into(),
            bin: Some(bin.into()),
        };
        let bytes = glb
            .to_vec()
            .map_err(|e| IoError::Write { path: main.clone(), reason: std::io::Error::other(e.to_string()) })?;
        files.push((main.clone(), bytes));
    } else {
        files.push((main.clone(), text));
        files.push((dir.join(format!("{}.bin", o.name)), bin));
        files.extend(images.into_iter().map(|(file, bytes)| (dir.join(file), bytes)));
    }
    write_all_or_nothing(&files)?;
    Ok(main)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sample_is_a_valid_gltf_plane_with_its_maps() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_sample(dir.path(), &SampleOptions::default()).unwrap();
        assert_eq!(path, dir.path().join("sample.gltf"));
        // The mesh loader reads it: one quad, tangents along +X, normals +Y.
        let mesh = crate::load_mesh(&path).unwrap();
        assert_eq!(mesh.triangle_count(), 2);
        assert!(mesh.normals.iter().all(|n| (*n - Vec3::Y).length() < 1e-6));
        assert!(mesh.tangents.iter().all(|t| (t.truncate() - Vec3::X).length() < 1e-6 && t.w == 1.0));
        // The extension, with the factor and offset given.
        let json: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let ext = &json["materials"][0]["extensions"][DISPLACEMENT_EXTENSION];
        assert_eq!(ext["displacementGeometryFactor"].as_f64().unwrap() as f32, 0.1);
        assert_eq!(ext["displacementGeometryOffset"].as_f64().unwrap() as f32, -0.1);
        // The height image holds the built-in map's heights in red.
        let tex = ext["displacementGeometryTexture"]["index"].as_u64().unwrap() as usize;
        let src = json["textures"][tex]["source"].as_u64().unwrap() as usize;
        let file = json["images"][src]["uri"].as_str().unwrap();
        let img = image::open(dir.path().join(file)).unwrap().to_rgb8();
        let field = procedural::generate(Pattern::Bricks, 64, 64);
        for (p, h) in img.pixels().zip(field.heights()) {
            assert!((f32::from(p.0[0]) / 255.0 - h).abs() <= 0.5 / 255.0 + 1e-6);
        }
    }

    #[test]
    fn the_binary_sample_holds_its_images_in_the_glb() {
        let dir = tempfile::tempdir().unwrap();
        let opts = SampleOptions { binary: true, name: "b".into(), ..SampleOptions::default() };
        let path = write_sample(dir.path(), &opts).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("b.glb")]);
        assert_eq!(crate::load_mesh(&path).unwrap().triangle_count(), 2);
        assert!(crate::mesh::mesh_references(&path).is_empty());
    }
}
