//! Triangle meshes from files: Wavefront OBJ and glTF 2.0 (`.gltf` and `.glb`).
//!
//! [`load_mesh`] picks the format by the file's extension and returns one [`Mesh`]: every
//! triangle of the file in one vertex and index buffer.
//!
//! # UV convention
//!
//! pomkit's UVs are glTF's: `(0, 0)` is the top-left corner of the image and v runs down the
//! rows (ARCHITECTURE.md, Conventions). glTF files are read as they are. OBJ files store v *up* the image
//! (OpenGL's convention, `(0, 0)` at the bottom-left), so the OBJ reader flips it: `v' = 1 - v`.
//! A texture that looks right on an OBJ model in Blender or any OpenGL viewer therefore looks
//! right in pomkit too.
//!
//! # What is read
//!
//! - **OBJ** (through `tobj`): every object and group of the file, polygons triangulated as fans,
//!   one index per unique (position, UV, normal) corner. `vn` normals are used when every corner
//!   has one; otherwise the normals of the whole mesh are computed (area-weighted, smooth).
//!   Materials (`mtllib`, `usemtl`), points and lines are ignored. Tangents are computed with
//!   MikkTSpace.
//! - **glTF 2.0** (through `gltf`): every triangle primitive (`TRIANGLES`, `TRIANGLE_STRIP`,
//!   `TRIANGLE_FAN`; points and lines are skipped) of every mesh instanced by the nodes of the
//!   default scene (the first scene when none is marked default; every mesh, untransformed, when
//!   the file has no scene), with the nodes' transforms applied. Attributes: `POSITION`,
//!   `NORMAL`, `TEXCOORD_0` and `TANGENT`. As the glTF specification requires, a primitive
//!   without `NORMAL` gets flat normals (its triangles no longer share vertices) and its
//!   `TANGENT`, if any, is ignored. When every primitive has a usable `TANGENT` the tangents are
//!   taken as given ([`Mesh::with_tangents`]); primitives without one get MikkTSpace tangents, as
//!   glTF prescribes. A node transform that mirrors (negative determinant) reverses the winding
//!   and the tangent handedness, so the result still has counter-clockwise front faces.
//!   Buffers may be in the `.glb` container, in `.bin` files beside the `.gltf`, or in base64
//!   `data:` URIs. Images, materials, skins and morph targets are ignored.
//!
//! A mesh must have texture coordinates: parallax mapping offsets them, so a model without UVs
//! is an error ([`MeshLoadError::NoUvs`]), not a silently flat surface.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use pomkit_core::glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use pomkit_core::mesh::{Mesh, MeshError};
use pomkit_core::{TangentMethod, TangentOptions, compute_tangents};

/// The deepest node hierarchy followed in a glTF file (deeper ones, or cycles, are an error).
pub(crate) const MAX_NODE_DEPTH: usize = 256;

/// Why a mesh file could not be loaded. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MeshLoadError {
    /// The file could not be opened or read.
    #[error("cannot read {}: {reason}", crate::shown(path))]
    Read {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The extension is not `.obj`, `.gltf` or `.glb`.
    #[error("{}: unknown mesh format: expected a .obj, .gltf or .glb file", crate::shown(path))]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// The OBJ parser refused the file (bad numbers, faces referring to missing vertices...).
    #[error("{}: not a valid OBJ file: {reason}", crate::shown(path))]
    Obj {
        /// The file.
        path: PathBuf,
        /// The parser's reason.
        reason: String,
    },
    /// The glTF parser refused the file, or its buffers could not be loaded.
    #[error("{}: not a valid glTF 2.0 file: {reason}", crate::shown(path))]
    Gltf {
        /// The file.
        path: PathBuf,
        /// The parser's reason.
        reason: String,
    },
    /// The mesh, or part of it, has no texture coordinates.
    #[error("{} has no texture coordinates (UVs){detail}: parallax mapping needs them", crate::shown(path))]
    NoUvs {
        /// The file.
        path: PathBuf,
        /// Which part lacks them (empty when none has any), e.g. ` (mesh "rock", primitive 1)`.
        detail: String,
    },
    /// The file holds no triangles.
    #[error("{} has no triangles", crate::shown(path))]
    NoTriangles {
        /// The file.
        path: PathBuf,
    },
    /// An attribute is inconsistent: wrong length, out-of-range index, degenerate node
    /// transform, missing positions.
    #[error("{}: {message}", crate::shown(path))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
    /// The geometry was refused by [`Mesh`] (non-finite positions, bad indices...).
    #[error("{}: {reason}", crate::shown(path))]
    Mesh {
        /// The file.
        path: PathBuf,
        /// The reason.
        reason: MeshError,
    },
}

/// Loads a triangle mesh from an OBJ (`.obj`) or glTF 2.0 (`.gltf`, `.glb`) file.
///
/// See the [module documentation](self) for what is read and the UV convention (OBJ's v is
/// flipped). Normals are computed when the file has none, tangents when it has none.
///
/// # Errors
/// A [`MeshLoadError`] naming the file: it cannot be read, its extension is unknown, it does
/// not parse, it has no triangles or no UVs, or its geometry is invalid.
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshLoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if !matches!(ext.as_str(), "obj" | "gltf" | "glb") {
        return Err(MeshLoadError::UnsupportedFormat { path: path.to_owned() });
    }
    // At most MAX_MESH_BYTES: a device or a huge file is refused, not read whole.
    let bytes = crate::read::read_capped(path, crate::read::MAX_MESH_BYTES, "a mesh file")
        .map_err(|reason| MeshLoadError::Read { path: path.to_owned(), reason })?;
    decode_mesh(&bytes, path)
}

/// The other files a mesh file refers to, as the glTF reader finds them: a `.gltf` or `.glb`
/// file's external buffers and images (relative URIs percent-decoded against its folder, and
/// `file:` URIs). Empty for OBJ files (their `.mtl` files are never read) and for a file that
/// cannot be read or parsed (loading it reports why). Used to keep outputs off every input.
#[must_use]
pub fn mesh_references(path: &Path) -> Vec<PathBuf> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if !matches!(ext.as_str(), "gltf" | "glb") {
        return Vec::new();
    }
    let Ok(bytes) = crate::read::read_capped(path, crate::read::MAX_MESH_BYTES, "a mesh file") else {
        return Vec::new();
    };
    let Ok(gltf) = gltf::Gltf::from_slice_without_validation(&bytes) else { return Vec::new() };
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let buffers = gltf.document.buffers().filter_map(|b| match b.source() {
        gltf::buffer::Source::Uri(uri) => Some(uri),
        gltf::buffer::Source::Bin => None,
    });
    let images = gltf.document.images().filter_map(|i| match i.source() {
        gltf::image::Source::Uri { uri, .. } => Some(uri),
        gltf::image::Source::View { .. } => None,
    });
    buffers.chain(images).filter_map(|uri| uri_path(uri, base)).collect()
}

/// The file a glTF URI names, as the glTF reader resolves it: `file:` URIs as they are, other
/// schemes (`data:`, `http:`) none, relative ones percent-decoded against `base`.
pub(crate) fn uri_path(uri: &str, base: &Path) -> Option<PathBuf> {
    if uri.contains(':') {
        let rest = uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:"))?;
        return Some(PathBuf::from(rest));
    }
    let bytes = uri.as_bytes();
    let mut decoded = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%'
            && let (Some(hi), Some(lo)) =
                (bytes.get(i + 1).and_then(|&b| hex(b)), bytes.get(i + 2).and_then(|&b| hex(b)))
        {
            decoded.push((hi * 16 + lo) as u8);
            i += 3;
        } else {
            decoded.push(bytes[i]);
            i += 1;
        }
    }
    Some(base.join(String::from_utf8_lossy(&decoded).as_ref()))
}

/// [`load_mesh`] from the bytes of a mesh file; `path` names it in errors, its extension picks
/// the format, and a `.gltf` file's external buffers are read from its folder.
///
/// # Errors
/// As [`load_mesh`].
pub fn decode_mesh(bytes: &[u8], path: &Path) -> Result<Mesh, MeshLoadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if !matches!(ext.as_str(), "obj" | "gltf" | "glb") {
        return Err(MeshLoadError::UnsupportedFormat { path: path.to_owned() });
    }
    // The parsers are third-party code fed untrusted input: a panic in them (an arithmetic
    // overflow on an absurd index, say) becomes an error naming the file, never a crash.
    let parsed = catch_unwind(AssertUnwindSafe(|| match ext.as_str() {
        "obj" => parse_obj(bytes, path),
        _ => parse_gltf(bytes, path),
    }));
    let raw = match parsed {
        Ok(r) => r?,
        Err(_) => {
            let reason = "the parser failed on malformed data".to_owned();
            return Err(if ext == "obj" {
                MeshLoadError::Obj { path: path.to_owned(), reason }
            } else {
                MeshLoadError::Gltf { path: path.to_owned(), reason }
            });
        }
    };
    raw.into_mesh(path)
}

/// Geometry gathered from a file before it becomes a [`Mesh`].
#[derive(Default)]
struct Raw {
    positions: Vec<Vec3>,
    /// Empty, or one per position.
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    /// `Some` (one per position) when every part of the file came with tangents.
    tangents: Option<Vec<Vec4>>,
    indices: Vec<u32>,
}

impl Raw {
    fn into_mesh(self, path: &Path) -> Result<Mesh, MeshLoadError> {
        if self.indices.is_empty() {
            return Err(MeshLoadError::NoTriangles { path: path.to_owned() });
        }
        let mesh_err = |reason| MeshLoadError::Mesh { path: path.to_owned(), reason };
        let normals = (!self.normals.is_empty()).then_some(self.normals);
        match (self.tangents, normals) {
            (Some(tangents), Some(normals)) => {
                Mesh::with_tangents(self.positions, Some(normals), self.uvs, self.indices, tangents).map_err(mesh_err)
            }
            (_, normals) => {
                Mesh::new(self.positions, normals, self.uvs, self.indices, TangentMethod::MikkTSpace).map_err(mesh_err)
            }
        }
    }
}

/// The next vertex index after `len` vertices, or an error for meshes beyond `u32` indices.
fn base_index(len: usize, path: &Path) -> Result<u32, MeshLoadError> {
    u32::try_from(len).map_err(|_| MeshLoadError::Invalid {
        path: path.to_owned(),
        message: format!("{len} vertices are more than 32-bit indices can address"),
    })
}

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

/// Parses an OBJ file: all models merged, v flipped to pomkit's convention.
fn parse_obj(bytes: &[u8], path: &Path) -> Result<Raw, MeshLoadError> {
    check_obj_indices(bytes, path)?;
    let mut reader = std::io::BufReader::new(bytes);
    // Materials are not used: refuse to open .mtl files rather than read them for nothing.
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &tobj::GPU_LOAD_OPTIONS, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| MeshLoadError::Obj { path: path.to_owned(), reason: e.to_string() })?;
    let mut raw = Raw::default();
    let mut all_normals = true;
    let mut any_uvs = false;
    let mut missing_uvs = None;
    for model in &models {
        let m = &model.mesh;
        let n = m.positions.len() / 3;
        if n == 0 || m.indices.is_empty() {
            continue;
        }
        let base = base_index(raw.positions.len(), path)?;
        raw.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        if m.texcoords.len() == 2 * n {
            any_uvs = true;
            // OBJ stores v up the image (OpenGL); pomkit's v runs down it (glTF).
            raw.uvs.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], 1.0 - t[1])));
        } else {
            any_uvs |= !m.texcoords.is_empty();
            missing_uvs.get_or_insert_with(|| model.name.clone());
        }
        if m.normals.len() == 3 * n {
            raw.normals.extend(m.normals.chunks_exact(3).map(|v| Vec3::new(v[0], v[1], v[2])));
        } else {
            all_normals = false;
        }
        for &i in &m.indices {
            let i = base.checked_add(i).ok_or_else(|| MeshLoadError::Invalid {
                path: path.to_owned(),
                message: "vertex indices overflow 32 bits".to_owned(),
            })?;
            raw.indices.push(i);
        }
    }
    if let Some(name) = missing_uvs {
        // Either the file has no `vt` at all, or some faces lack them (tobj then stores fewer
        // UVs than vertices).
        let detail = if any_uvs || models.len() > 1 {
            if name.is_empty() { " on some faces".to_owned() } else { format!(" on some faces of {name:?}") }
        } else {
            String::new()
        };
        return Err(MeshLoadError::NoUvs { path: path.to_owned(), detail });
    }
    if !all_normals {
        // Some corners have no `vn`: compute every normal rather than mix the two.
        raw.normals.clear();
    }
    Ok(raw)
}

/// Refuses corners of faces (`f` lines, and `l` or `p` lines of three corners or more, which tobj
/// reads as faces) that point at no position, texture coordinate or normal of the file: index 0,
/// a relative (negative) one before the first element, or one past the last.
/// tobj computes with such indices unchecked: an arithmetic overflow, or a wrong element read
/// (found by the `obj` fuzz target, docs/FUZZING.md). Kinds the file has none of are not
/// checked, as tobj does not read them.
fn check_obj_indices(bytes: &[u8], path: &Path) -> Result<(), MeshLoadError> {
    const KINDS: [(&str, &str); 3] = [("v", "position (v)"), ("vt", "texture coordinate (vt)"), ("vn", "normal (vn)")];
    let lines = || bytes.split(|&b| b == b'\n').map(String::from_utf8_lossy);
    let kind = |word: Option<&str>| KINDS.iter().position(|(k, _)| word == Some(*k));
    let mut total = [0u64; 3];
    for line in lines() {
        if let Some(k) = kind(line.split_whitespace().next()) {
            total[k] += 1;
        }
    }
    let mut seen = [0u64; 3];
    for (n, line) in lines().enumerate() {
        let mut words = line.split_whitespace();
        let first = words.next();
        if let Some(k) = kind(first) {
            seen[k] += 1;
        }
        if !matches!(first, Some("f" | "l" | "p")) {
            continue;
        }
        for corner in words {
            for (k, part) in corner.split('/').enumerate().take(3) {
                // Unparsable corners are tobj's to refuse.
                let Ok(x) = part.parse::<i64>() else { continue };
                let fits = if x < 0 { x.unsigned_abs() <= seen[k] } else { x != 0 && x.unsigned_abs() <= total[k] };
                if !fits && total[k] > 0 {
                    return Err(MeshLoadError::Invalid {
                        path: path.to_owned(),
                        message: format!("line {}: corner {corner:?} refers to no {}", n + 1, KINDS[k].1),
                    });
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// glTF
// ---------------------------------------------------------------------------------------------

/// One primitive's vertices, already in world (file) space.
pub(crate) struct Part {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    tangents: Option<Vec<Vec4>>,
    indices: Vec<u32>,
}

/// Parses a `.gltf` or `.glb` file and gathers the triangles of its default scene.
/// Holds a glTF's buffers to [`crate::read::MAX_MESH_BYTES`] in all before any is read: the
/// declared lengths, and each external file's size (which must be a regular file, so a device
/// or a FIFO is never read whole by the glTF reader).
fn check_buffer_sizes(document: &gltf::Document, base: &Path) -> Result<(), String> {
    let cap = crate::read::MAX_MESH_BYTES;
    let fmt = pomkit_core::memory::format_bytes;
    let declared = document.buffers().map(|b| b.length() as u64).fold(0u64, u64::saturating_add);
    if declared > cap {
        return Err(format!("its buffers declare {} in all; a mesh may have at most {}", fmt(declared), fmt(cap)));
    }
    for b in document.buffers() {
        if let gltf::buffer::Source::Uri(uri) = b.source() {
            if uri.starts_with("data:") {
                continue;
            }
            let file = base.join(uri);
            // A missing file (or a percent-encoded name) is left to the glTF reader to report.
            let Ok(meta) = std::fs::metadata(&file) else { continue };
            if !meta.is_file() {
                return Err(format!("its buffer {uri} is not a regular file"));
            }
            if meta.len() > cap {
                return Err(format!("its buffer {uri} is {}; a mesh may have at most {}", fmt(meta.len()), fmt(cap)));
            }
        }
    }
    Ok(())
}

/// A parsed and validated glTF file with its buffers loaded (the blob of a `.glb` is buffer 0).
pub(crate) struct OpenGltf {
    /// The document.
    pub(crate) document: gltf::Document,
    /// Each buffer's bytes, by index.
    pub(crate) buffers: Vec<gltf::buffer::Data>,
}

/// Parses a `.gltf` or `.glb` file's bytes and loads its buffers (external ones from `path`'s
/// folder), with the checks that keep the glTF reader from panicking or reading too much.
pub(crate) fn open_gltf(bytes: &[u8], path: &Path) -> Result<OpenGltf, MeshLoadError> {
    let gltf_err = |reason: String| MeshLoadError::Gltf { path: path.to_owned(), reason };
    // gltf 1.4.1 takes the 12-byte header off a GLB's declared length unchecked (an overflow,
    // found by the `gltf` fuzz target, docs/FUZZING.md).
    if let Some(length) = bytes.strip_prefix(b"glTF").and_then(|b| b.get(4..8)) {
        let declared = u32::from_le_bytes([length[0], length[1], length[2], length[3]]);
        if declared < 12 {
            return Err(gltf_err(format!("its GLB header declares {declared} bytes, fewer than the header's 12")));
        }
    }
    // Validated only once the attributes' accessors are known to exist (see
    // `check_attribute_accessors`); otherwise as `gltf::Gltf::from_slice`.
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_err(e.to_string()))?;
    let json = document.into_json();
    check_attribute_accessors(&json).map_err(gltf_err)?;
    let document = gltf::Document::from_json(json).map_err(|e| gltf_err(e.to_string()))?;
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    check_buffer_sizes(&document, base).map_err(gltf_err)?;
    let buffers = gltf::import_buffers(&document, Some(base), blob).map_err(|e| {
        let files: Vec<String> = document
            .buffers()
            .filter_map(|b| match b.source() {
                gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => Some(uri.to_owned()),
                _ => None,
            })
            .collect();
        if files.is_empty() {
            gltf_err(format!("cannot load its buffers: {e}"))
        } else {
            gltf_err(format!("cannot load its buffers ({}): {e}", files.join(", ")))
        }
    })?;
    Ok(OpenGltf { document, buffers })
}

fn parse_gltf(bytes: &[u8], path: &Path) -> Result<Raw, MeshLoadError> {
    let gltf_err = |reason: String| MeshLoadError::Gltf { path: path.to_owned(), reason };
    let OpenGltf { document, buffers } = open_gltf(bytes, path)?;
    // (mesh, world transform) for every mesh instance.
    let mut instances: Vec<(gltf::Mesh<'_>, Mat4)> = Vec::new();
    match document.default_scene().or_else(|| document.scenes().next()) {
        Some(scene) => {
            let mut stack: Vec<(gltf::Node<'_>, Mat4, usize)> = scene.nodes().map(|n| (n, Mat4::IDENTITY, 0)).collect();
            while let Some((node, parent, depth)) = stack.pop() {
                if depth > MAX_NODE_DEPTH {
                    return Err(gltf_err(format!("the node hierarchy is deeper than {MAX_NODE_DEPTH} levels")));
                }
                let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
                if let Some(mesh) = node.mesh() {
                    instances.push((mesh, world));
                }
                stack.extend(node.children().map(|c| (c, world, depth + 1)));
            }
        }
        None => instances.extend(document.meshes().map(|m| (m, Mat4::IDENTITY))),
    }

    let mut parts = Vec::new();
    for (mesh, world) in &instances {
        for prim in mesh.primitives() {
            if let Some(part) = read_primitive(&prim, mesh, *world, &buffers, path)? {
                parts.push(part);
            }
        }
    }
    merge_parts(parts, path)
}

/// Refuses a primitive attribute that names an accessor the file does not have: gltf-json 1.4.1
/// validates a `POSITION` accessor by indexing the accessors unchecked, a panic (found by the
/// `gltf` fuzz target, docs/FUZZING.md).
fn check_attribute_accessors(json: &gltf::json::Root) -> Result<(), String> {
    let n = json.accessors.len();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(index) = prim.attributes.values().find(|i| i.value() >= n) {
                return Err(format!(
                    "meshes[{m}].primitives[{p}]: an attribute refers to accessor {}, but the file has {n}",
                    index.value()
                ));
            }
        }
    }
    Ok(())
}

/// `mesh "name", primitive 2` (or `mesh 0, primitive 2` for an unnamed mesh), for messages.
pub(crate) fn where_in(mesh: &gltf::Mesh<'_>, prim: usize) -> String {
    match mesh.name() {
        Some(name) => format!("mesh {name:?}, primitive {prim}"),
        None => format!("mesh {}, primitive {prim}", mesh.index()),
    }
}

/// Reads one primitive and moves it to world space; `None` for points and lines.
fn read_primitive(
    prim: &gltf::Primitive<'_>,
    mesh: &gltf::Mesh<'_>,
    world: Mat4,
    buffers: &[gltf::buffer::Data],
    path: &Path,
) -> Result<Option<Part>, MeshLoadError> {
    match read_local(prim, mesh, buffers, path)? {
        Some(local) => place(local, prim, mesh, world, path).map(Some),
        None => Ok(None),
    }
}

/// One primitive's vertices as the file stores them (the mesh's own space).
pub(crate) struct LocalPart {
    /// Positions.
    pub(crate) positions: Vec<Vec3>,
    /// Normals, when the primitive has them.
    pub(crate) normals: Option<Vec<Vec3>>,
    /// `TEXCOORD_0`.
    pub(crate) uvs: Vec<Vec2>,
    /// Tangents, when the primitive has them and normals.
    pub(crate) tangents: Option<Vec<Vec4>>,
    /// The triangle list.
    pub(crate) indices: Vec<u32>,
}

/// Reads one primitive in the mesh's own space; `None` for points and lines.
pub(crate) fn read_local(
    prim: &gltf::Primitive<'_>,
    mesh: &gltf::Mesh<'_>,
    buffers: &[gltf::buffer::Data],
    path: &Path,
) -> Result<Option<LocalPart>, MeshLoadError> {
    use gltf::mesh::Mode;
    let invalid = |what: String| MeshLoadError::Invalid {
        path: path.to_owned(),
        message: format!("{}: {what}", where_in(mesh, prim.index())),
    };
    let mode = prim.mode();
    if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
        return Ok(None);
    }
    check_accessors(prim, buffers).map_err(invalid)?;
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| invalid("no POSITION attribute (or its data lies outside its buffer)".to_owned()))?
        .map(Vec3::from)
        .collect();
    let n = positions.len();
    let uvs: Vec<Vec2> = match reader.read_tex_coords(0) {
        Some(t) => t.into_f32().map(Vec2::from).collect(),
        None => {
            return Err(MeshLoadError::NoUvs {
                path: path.to_owned(),
                detail: format!(" ({})", where_in(mesh, prim.index())),
            });
        }
    };
    if uvs.len() != n {
        return Err(invalid(format!("{} TEXCOORD_0 values for {n} positions", uvs.len())));
    }
    let normals: Option<Vec<Vec3>> = reader.read_normals().map(|r| r.map(Vec3::from).collect());
    if let Some(len) = normals.as_ref().map(Vec::len).filter(|&len| len != n) {
        return Err(invalid(format!("{len} NORMAL values for {n} positions")));
    }
    // glTF: tangents are ignored when normals are absent (flat normals are computed instead).
    let tangents: Option<Vec<Vec4>> = match (&normals, reader.read_tangents()) {
        (Some(_), Some(r)) => Some(r.map(Vec4::from).collect()),
        _ => None,
    };
    if let Some(len) = tangents.as_ref().map(Vec::len).filter(|&len| len != n) {
        return Err(invalid(format!("{len} TANGENT values for {n} positions")));
    }
    let listed: Vec<u32> = match reader.read_indices() {
        Some(r) => r.into_u32().collect(),
        None => (0..base_index(n, path)?).collect(),
    };
    if let Some(&bad) = listed.iter().find(|&&i| i as usize >= n) {
        return Err(invalid(format!("index {bad} refers past its {n} vertices")));
    }
    let indices = triangle_list(&listed, mode);
    Ok(Some(LocalPart { positions, normals, uvs, tangents, indices }))
}

/// Moves a primitive read by [`read_local`] to world space by its node's `world` transform.
pub(crate) fn place(
    local: LocalPart,
    prim: &gltf::Primitive<'_>,
    mesh: &gltf::Mesh<'_>,
    world: Mat4,
    path: &Path,
) -> Result<Part, MeshLoadError> {
    let invalid = |what: String| MeshLoadError::Invalid {
        path: path.to_owned(),
        message: format!("{}: {what}", where_in(mesh, prim.index())),
    };
    let LocalPart { positions, normals, uvs, tangents, mut indices } = local;
    // To world space: normals by the inverse transpose, tangents by the matrix itself; a
    // mirroring transform flips the winding (glTF 3.7.4) and the tangents' handedness.
    let m3 = Mat3::from_mat4(world);
    let det = m3.determinant();
    if !(det.is_finite() && det.abs() > f32::MIN_POSITIVE && world.is_finite()) {
        return Err(invalid("its node transform is degenerate (zero scale or not finite)".to_owned()));
    }
    let normal_matrix = m3.inverse().transpose();
    let flip = det < 0.0;
    let positions: Vec<Vec3> = positions.into_iter().map(|p| world.transform_point3(p)).collect();
    let normals = normals.map(|ns| ns.into_iter().map(|v| (normal_matrix * v).normalize_or_zero()).collect());
    let tangents = tangents.map(|ts| {
        ts.into_iter()
            .map(|t| {
                let w = if t.w < 0.0 { -1.0 } else { 1.0 };
                (m3 * t.truncate()).normalize_or_zero().extend(if flip { -w } else { w })
            })
            .collect()
    });
    if flip {
        indices.chunks_exact_mut(3).for_each(|t| t.swap(1, 2));
    }

    let part = match normals {
        Some(normals) => Part { positions, normals, uvs, tangents, indices },
        None => flat_part(&positions, &uvs, &indices),
    };
    Ok(part)
}

/// Checks that every accessor of the primitive (its indices and attributes) lies inside its
/// buffer view, and every such view inside the buffer as loaded: the glTF reader silently
/// yields nothing for data past the end, which would draw nothing (or the wrong triangles).
fn check_accessors(prim: &gltf::Primitive<'_>, buffers: &[gltf::buffer::Data]) -> Result<(), String> {
    let named = prim.attributes().map(|(sem, a)| (sem.to_string(), a));
    let all = prim.indices().map(|a| ("indices".to_owned(), a)).into_iter().chain(named);
    for (role, acc) in all {
        let what = match acc.name() {
            Some(name) => format!("accessor {} ({name:?}, {role})", acc.index()),
            None => format!("accessor {} ({role})", acc.index()),
        };
        check_accessor_type(&role, &acc).map_err(|e| format!("{what}: {e}"))?;
        // An accessor without a view (sparse or all zeros) reads no buffer.
        let Some(view) = acc.view() else { continue };
        let buffer = view.buffer();
        let have = buffers.get(buffer.index()).map_or(0, |d| d.0.len() as u64);
        let view_end = (view.offset() as u64).saturating_add(view.length() as u64);
        if view_end > have {
            return Err(format!(
                "{what}: its buffer view {} spans bytes {} to {view_end}, but buffer {} holds {have} bytes",
                view.index(),
                view.offset(),
                buffer.index()
            ));
        }
        let count = acc.count() as u64;
        if count == 0 {
            continue;
        }
        let elem = acc.size() as u64;
        let stride = view.stride().map_or(elem, |s| s as u64);
        let need = (acc.offset() as u64).saturating_add((count - 1).saturating_mul(stride)).saturating_add(elem);
        if need > view.length() as u64 {
            return Err(format!(
                "{what}: {count} elements of {elem} bytes (stride {stride}) from byte {} need {need} bytes, but its \
                 buffer view {} holds {}",
                acc.offset(),
                view.index(),
                view.length()
            ));
        }
    }
    Ok(())
}

/// Refuses an accessor whose element type is not the one glTF requires for what pomkit reads
/// it as (specification 3.7.2.1: POSITION and NORMAL float VEC3, TANGENT float VEC4,
/// TEXCOORD_0 VEC2 of floats or normalized unsigned bytes or shorts, indices unsigned SCALAR):
/// the glTF reader asserts the element size and panics otherwise (found by fuzzing).
/// Attributes pomkit does not read are not checked.
fn check_accessor_type(role: &str, acc: &gltf::Accessor<'_>) -> Result<(), String> {
    use gltf::accessor::{DataType, Dimensions};
    let (dims, types, wanted): (Dimensions, &[DataType], &str) = match role {
        "POSITION" | "NORMAL" => (Dimensions::Vec3, &[DataType::F32], "VEC3 of floats"),
        "TANGENT" => (Dimensions::Vec4, &[DataType::F32], "VEC4 of floats"),
        "TEXCOORD_0" => (
            Dimensions::Vec2,
            &[DataType::F32, DataType::U8, DataType::U16],
            "VEC2 of floats, unsigned bytes or unsigned shorts",
        ),
        "indices" => (
            Dimensions::Scalar,
            &[DataType::U8, DataType::U16, DataType::U32],
            "SCALAR of unsigned bytes, shorts or ints",
        ),
        _ => return Ok(()),
    };
    if acc.dimensions() != dims || !types.contains(&acc.data_type()) {
        return Err(format!(
            "its elements are {:?} of {:?}, but {role} must be a {wanted}",
            acc.dimensions(),
            acc.data_type()
        ));
    }
    Ok(())
}

/// Triangle list from the indices of a `TRIANGLES`, `TRIANGLE_STRIP` or `TRIANGLE_FAN`
/// primitive, keeping glTF's winding (specification 3.7.2.1). A trailing partial triangle is
/// dropped.
fn triangle_list(ix: &[u32], mode: gltf::mesh::Mode) -> Vec<u32> {
    use gltf::mesh::Mode;
    match mode {
        Mode::TriangleStrip => (0..ix.len().saturating_sub(2))
            .flat_map(|i| if i % 2 == 0 { [ix[i], ix[i + 1], ix[i + 2]] } else { [ix[i + 1], ix[i], ix[i + 2]] })
            .collect(),
        Mode::TriangleFan => (1..ix.len().saturating_sub(1)).flat_map(|i| [ix[i], ix[i + 1], ix[0]]).collect(),
        _ => ix[..ix.len() / 3 * 3].to_vec(),
    }
}

/// A primitive without normals, unwelded so that every triangle gets its own flat normal
/// (glTF 3.7.2.1: "client implementations MUST calculate flat normals").
fn flat_part(positions: &[Vec3], uvs: &[Vec2], indices: &[u32]) -> Part {
    let mut part = Part {
        positions: Vec::with_capacity(indices.len()),
        normals: Vec::with_capacity(indices.len()),
        uvs: Vec::with_capacity(indices.len()),
        tangents: None,
        indices: Vec::with_capacity(indices.len()),
    };
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| positions[i as usize]);
        // A degenerate triangle gets a zero normal, which `Mesh` replaces by its own fallback.
        let normal = (b - a).cross(c - a).normalize_or_zero();
        for &i in tri {
            part.indices.push(part.positions.len() as u32);
            part.positions.push(positions[i as usize]);
            part.uvs.push(uvs[i as usize]);
            part.normals.push(normal);
        }
    }
    part
}

/// Concatenates the primitives. Tangents are kept as given when every primitive has them;
/// when only some do, the others get MikkTSpace tangents so that the given ones are kept.
fn merge_parts(parts: Vec<Part>, path: &Path) -> Result<Raw, MeshLoadError> {
    let any_tangents = parts.iter().any(|p| p.tangents.is_some());
    let mut raw = Raw { tangents: any_tangents.then(Vec::new), ..Raw::default() };
    for part in parts {
        let base = base_index(raw.positions.len(), path)?;
        if let Some(all) = &mut raw.tangents {
            match &part.tangents {
                Some(t) => all.extend_from_slice(t),
                None => {
                    let opts = TangentOptions { method: TangentMethod::MikkTSpace, ..TangentOptions::default() };
                    let t = compute_tangents(&part.positions, &part.normals, &part.uvs, &part.indices, &opts)
                        .map_err(|e| MeshLoadError::Invalid { path: path.to_owned(), message: e.to_string() })?;
                    all.extend(t);
                }
            }
        }
        raw.positions.extend_from_slice(&part.positions);
        raw.normals.extend_from_slice(&part.normals);
        raw.uvs.extend_from_slice(&part.uvs);
        for i in part.indices {
            raw.indices.push(base.checked_add(i).ok_or_else(|| MeshLoadError::Invalid {
                path: path.to_owned(),
                message: "vertex indices overflow 32 bits".to_owned(),
            })?);
        }
    }
    Ok(raw)
}

/// One primitive placed by [`place`] as a [`Mesh`] (its tangents kept when the file gives them,
/// else MikkTSpace).
pub(crate) fn part_mesh(part: Part, path: &Path) -> Result<Mesh, MeshLoadError> {
    merge_parts(vec![part], path)?.into_mesh(path)
}
