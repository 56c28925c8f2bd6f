//! `pomkit gltf attach`: a height map put into a glTF file's material as
//! `KHR_materials_displacement` (docs/SCENES.md, Attaching a height map).

use std::path::{Component, Path, PathBuf};

use pomkit_core::HeightField;
use pomkit_core::mesh::mean_uv_unit_length;
use serde_json::{Value, json};

use super::{DISPLACEMENT_EXTENSION, write_all_or_nothing};
use crate::mesh::{MeshLoadError, OpenGltf, open_gltf, read_local};
use crate::output::Outputs;

/// Which material receives the height map.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MaterialChoice {
    /// The file's only material (an error when it has several).
    Only,
    /// By index.
    Index(usize),
    /// By name.
    Name(String),
}

/// How deep the relief is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AttachDepth {
    /// In the mesh's own units (`displacementGeometryFactor`).
    Units(f32),
    /// In UV units (pomkit's `depth_scale`), converted through the mean UV unit of the
    /// material's meshes.
    UvUnits(f32),
}

/// Why [`attach`] failed. Every message names the file and the item.
#[derive(Debug, thiserror::Error)]
pub enum AttachError {
    /// The input could not be read or parsed.
    #[error(transparent)]
    Gltf(#[from] MeshLoadError),
    /// An option does not fit the file (no such material, a bad depth, mixed formats...).
    #[error("{}: {message}", crate::shown(path))]
    Invalid {
        /// The glTF file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Writing failed, or an output is refused (the input, a file it reads, read-only).
    #[error(transparent)]
    Io(#[from] crate::IoError),
}

/// What [`attach`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Attached {
    /// The material's index.
    pub material: usize,
    /// `displacementGeometryFactor` (the relief's depth in the mesh's units).
    pub factor: f32,
    /// The height image written beside the output (`None` for a `.glb`, which holds it).
    pub image: Option<PathBuf>,
}

/// Writes `output`: `input` with `height` as its material's `KHR_materials_displacement`
/// (factor = the depth in the mesh's units, offset = -factor, so the file's displaced surface
/// is the one pomkit draws; `extensionsUsed` gains the extension). For a `.gltf` output the
/// height goes to `OUTSTEM_height.png` beside it (16-bit, height in every channel, white =
/// high) and the input's relative URIs are rewritten to stay valid from the output's folder;
/// for a `.glb` (the input must be one too) the PNG goes into its binary chunk. The outputs
/// may not be the input, a file it reads, or one of `other_inputs` (the height map's file);
/// every file appears only when all are written.
///
/// # Errors
/// [`AttachError`] naming the file and the item.
pub fn attach(
    input: &Path,
    output: &Path,
    material: &MaterialChoice,
    height: &HeightField,
    depth: AttachDepth,
    other_inputs: &[PathBuf],
) -> Result<Attached, AttachError> {
    let bad = |message: String| AttachError::Invalid { path: input.to_owned(), message };
    let binary = |p: &Path| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if !crate::scene::is_gltf(input) {
        return Err(bad("not a .gltf or .glb file".into()));
    }
    if !crate::scene::is_gltf(output) {
        return Err(AttachError::Invalid {
            path: output.to_owned(),
            message: "the output must be a .gltf or .glb file".into(),
        });
    }
    if binary(input) != binary(output) {
        return Err(bad(format!(
            "the output {} must have the input's format (.gltf to .gltf, .glb to .glb)",
            crate::shown(output)
        )));
    }
    // Refuse outputs that are inputs before reading anything heavy.
    let image_path = (!binary(output)).then(|| {
        let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        output.with_file_name(format!("{stem}_height.png"))
    });
    let mut outs = Outputs::new();
    outs.input(input);
    for f in crate::mesh::mesh_references(input).iter().chain(other_inputs) {
        outs.input(f);
    }
    outs.output(output);
    if let Some(p) = &image_path {
        outs.output(p);
    }
    outs.check()?;
    drop(outs);

    let bytes = crate::read::read_capped(input, crate::read::MAX_MESH_BYTES, "a glTF file")
        .map_err(|reason| MeshLoadError::Read { path: input.to_owned(), reason })?;
    let OpenGltf { document, buffers } = open_gltf(&bytes, input)?;
    let count = document.materials().len();
    let index = match material {
        MaterialChoice::Only if count == 1 => 0,
        MaterialChoice::Only => {
            let names: Vec<String> = document
                .materials()
                .map(|m| format!("{} {:?}", m.index().unwrap_or(0), m.name().unwrap_or("")))
                .collect();
            return Err(bad(format!(
                "it has {count} materials: choose one with --material (by name or index): {}",
                if names.is_empty() { "none".to_owned() } else { names.join(", ") }
            )));
        }
        MaterialChoice::Index(i) if *i < count => *i,
        MaterialChoice::Index(i) => return Err(bad(format!("material {i} does not exist: the file has {count}"))),
        MaterialChoice::Name(n) => {
            let found: Vec<usize> =
                document.materials().filter(|m| m.name() == Some(n.as_str())).filter_map(|m| m.index()).collect();
            match found.as_slice() {
                [i] => *i,
                [] => return Err(bad(format!("no material is named {n:?}"))),
                _ => return Err(bad(format!("{} materials are named {n:?}: choose one by index", found.len()))),
            }
        }
    };
    let label = match document.materials().nth(index).and_then(|m| m.name().map(str::to_owned)) {
        Some(n) => format!("material {index} '{n}'"),
        None => format!("material {index}"),
    };
    let factor = match depth {
        AttachDepth::Units(d) => d,
        AttachDepth::UvUnits(s) => {
            // The mean UV unit over every primitive of the material, in the meshes' own units.
            let (mut positions, mut uvs, mut indices) = (Vec::new(), Vec::new(), Vec::new());
            for mesh in document.meshes() {
                for prim in mesh.primitives().filter(|p| p.material().index() == Some(index)) {
                    let Some(local) = read_local(&prim, &mesh, &buffers, input)? else { continue };
                    let base = positions.len() as u32;
                    positions.extend(local.positions.iter().map(|p| p.to_array()));
                    uvs.extend(local.uvs.iter().map(|p| p.to_array()));
                    indices.extend(local.indices.iter().map(|i| i + base));
                }
            }
            let l = mean_uv_unit_length(&positions, &uvs, &indices)
                .ok_or_else(|| bad(format!("{label}: no triangle with UVs uses it, so --depth-scale has no length")))?;
            s * l
        }
    };
    if !(factor.is_finite() && factor > 0.0) {
        return Err(bad(format!("{label}: the depth is {factor}: it must be a finite number greater than 0")));
    }

    // The height image: 16-bit grey PNG, white = high.
    let (w, h) = (height.width(), height.height());
    let samples: Vec<u16> = height.heights().iter().map(|&v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16).collect();
    let mut png = Vec::new();
    {
        use image::ImageEncoder;
        let raw: Vec<u8> = samples.iter().flat_map(|s| s.to_ne_bytes()).collect();
        image::codecs::png::PngEncoder::new(&mut png).write_image(&raw, w, h, image::ExtendedColorType::L16).map_err(
            |e| crate::IoError::Encode { path: image_path.clone().unwrap_or_else(|| output.to_owned()), reason: e },
        )?;
    }

    // The JSON, edited as it is (unknown fields and extensions kept).
    let (mut json, mut bin): (Value, Option<Vec<u8>>) = if binary(input) {
        let glb = ::gltf::binary::Glb::from_slice(&bytes).map_err(|e| bad(format!("not a valid GLB: {e}")))?;
        (serde_json::from_slice(&glb.json).map_err(|e| bad(e.to_string()))?, glb.bin.map(|b| b.into_owned()))
    } else {
        (serde_json::from_slice(&bytes).map_err(|e| bad(e.to_string()))?, None)
    };
    let image_json = match &image_path {
        Some(p) => {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            json!({ "uri": percent_encode(&name), "mimeType": "image/png" })
        }
        None => {
            if json["buffers"].get(0).is_some_and(|b| b.get("uri").is_some()) {
                return Err(bad(
                    "its buffer 0 is an external file, not the GLB's binary chunk: convert it first".into()
                ));
            }
            let bin = bin.get_or_insert_with(Vec::new);
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            let offset = bin.len();
            bin.extend_from_slice(&png);
            let views = array(&mut json, "bufferViews");
            views.push(json!({ "buffer": 0, "byteOffset": offset, "byteLength": png.len() }));
            let view = views.len() - 1;
            let length = bin.len();
            let buffers = array(&mut json, "buffers");
            if buffers.is_empty() {
                buffers.push(json!({ "byteLength": length }));
            } else {
                buffers[0]["byteLength"] = json!(length);
            }
            json!({ "bufferView": view, "mimeType": "image/png" })
        }
    };
    let images = array(&mut json, "images");
    images.push(image_json);
    let image = images.len() - 1;
    // The base colour's sampler, so that the relief tiles as the colour does.
    let sampler = json["materials"][index]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        .as_u64()
        .and_then(|t| json["textures"][t as usize]["sampler"].as_u64());
    let mut texture = json!({ "source": image });
    if let Some(s) = sampler {
        texture["sampler"] = json!(s);
    }
    let textures = array(&mut json, "textures");
    textures.push(texture);
    let tex = textures.len() - 1;
    let m = &mut json["materials"][index];
    if !m["extensions"].is_object() {
        m["extensions"] = json!({});
    }
    m["extensions"][DISPLACEMENT_EXTENSION] = json!({
        "displacementGeometryTexture": { "index": tex },
        "displacementGeometryFactor": factor,
        "displacementGeometryOffset": -factor,
    });
    let used = array(&mut json, "extensionsUsed");
    if !used.iter().any(|v| v == DISPLACEMENT_EXTENSION) {
        used.push(json!(DISPLACEMENT_EXTENSION));
    }

    // Relative URIs made valid from the output's folder.
    if !binary(output) {
        let from = folder(input);
        let to = folder(output);
        for key in ["buffers", "images"] {
            let Some(items) = json[key].as_array_mut() else { continue };
            for (i, item) in items.iter_mut().enumerate() {
                if key == "images" && i == image {
                    continue;
                }
                let Some(uri) = item["uri"].as_str() else { continue };
                if uri.contains(':') {
                    continue;
                }
                let Some(file) = crate::mesh::uri_path(uri, &from) else { continue };
                item["uri"] = json!(percent_encode(&relative(&file, &to).to_string_lossy().replace('\\', "/")));
            }
        }
    }

    let text = serde_json::to_vec_pretty(&json).map_err(|e| bad(e.to_string()))?;
    let mut files = Vec::new();
    if binary(output) {
        let glb = ::gltf::binary::Glb {
            header: ::gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
            json: text.into(),
            bin: bin.map(Into::into),
        };
        files.push((output.to_owned(), glb.to_vec().map_err(|e| bad(e.to_string()))?));
    } else {
        files.push((output.to_owned(), text));
    }
    if let Some(p) = &image_path {
        files.push((p.clone(), png));
    }
    write_all_or_nothing(&files)?;
    Ok(Attached { material: index, factor, image: image_path })
}

/// The array at `key` of the root, made when absent.
fn array<'a>(json: &'a mut Value, key: &str) -> &'a mut Vec<Value> {
    if !json[key].is_array() {
        json[key] = json!([]);
    }
    json[key].as_array_mut().expect("made an array above")
}

/// A file's folder, absolute.
fn folder(file: &Path) -> PathBuf {
    let dir = file.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::path::absolute(dir).unwrap_or_else(|_| dir.to_owned())
}

/// `file` relative to the folder `to` (both made absolute, `..` where needed).
fn relative(file: &Path, to: &Path) -> PathBuf {
    let file = std::path::absolute(file).unwrap_or_else(|_| file.to_owned());
    fn normal(p: &Path) -> Vec<Component<'_>> {
        let mut out: Vec<Component<'_>> = Vec::new();
        for c in p.components() {
            match c {
                Component::CurDir => {}
                Component::ParentDir if matches!(out.last(), Some(Component::Normal(_))) => {
                    out.pop();
                }
                c => out.push(c),
            }
        }
        out
    }
    let (f, t) = (normal(&file), normal(to));
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    let mut rel = PathBuf::new();
    for _ in common..t.len() {
        rel.push("..");
    }
    for c in &f[common..] {
        rel.push(c.as_os_str());
    }
    rel
}

/// A relative path as a URI reference: characters that are not unreserved or `/` escaped.
fn percent_encode(path: &str) -> String {
    let mut out = String::new();
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}
