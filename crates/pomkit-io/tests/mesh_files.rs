//! Mesh files: OBJ and glTF 2.0 assets written by hand into a temporary folder, loaded with
//! `load_mesh`, checked attribute by attribute; bad files fail with errors naming them.

use std::path::{Path, PathBuf};

use pomkit_core::glam::{Vec2, Vec3, Vec4};
use pomkit_core::mesh::Mesh;
use pomkit_io::mesh::{MeshLoadError, load_mesh};

fn write(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, contents).unwrap();
    path
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-5
}

/// Every tangent unit length, perpendicular to its normal, with `w = ±1`.
fn assert_frames_sane(mesh: &Mesh) {
    assert_eq!(mesh.tangents.len(), mesh.positions.len());
    for (t, n) in mesh.tangents.iter().zip(&mesh.normals) {
        assert!(t.is_finite() && n.is_finite(), "{t} {n}");
        assert!((t.truncate().length() - 1.0).abs() < 1e-4, "{t}");
        assert!(t.truncate().dot(*n).abs() < 1e-4, "{t} not perpendicular to {n}");
        assert!(t.w == 1.0 || t.w == -1.0, "{t}");
    }
}

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

/// A unit quad in the XY plane facing +Z, wound counter-clockwise. OBJ's v runs up: the
/// bottom-left corner has (0, 0), so in pomkit's convention it is (0, 1).
const OBJ_QUAD: &str = "\
# a quad
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
";

#[test]
fn obj_quad_is_triangulated_with_v_flipped() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = load_mesh(&write(dir.path(), "quad.obj", OBJ_QUAD)).unwrap();
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(mesh.indices.len(), 6, "one quad, two triangles");
    let expected = [
        (Vec3::new(-1.0, -1.0, 0.0), Vec2::new(0.0, 1.0)),
        (Vec3::new(1.0, -1.0, 0.0), Vec2::new(1.0, 1.0)),
        (Vec3::new(1.0, 1.0, 0.0), Vec2::new(1.0, 0.0)),
        (Vec3::new(-1.0, 1.0, 0.0), Vec2::new(0.0, 0.0)),
    ];
    for (p, uv) in expected {
        let i = mesh.positions.iter().position(|q| close(*q, p)).unwrap_or_else(|| panic!("no vertex at {p}"));
        assert_eq!(mesh.uvs[i], uv, "v is flipped: OBJ's v = 0 is the image's bottom");
        assert!(close(mesh.normals[i], Vec3::Z));
    }
    assert_frames_sane(&mesh);
    // An unmirrored quad: T along +X (u grows to the right), w = +1 (ARCHITECTURE.md, Conventions).
    for t in &mesh.tangents {
        assert!(close(t.truncate(), Vec3::X), "{t}");
        assert_eq!(t.w, 1.0);
    }
    // u spans 2 world units per UV unit along X and Y.
    assert!(mesh.uv_scale.iter().all(|s| (*s - Vec2::splat(2.0)).length() < 1e-4), "{:?}", mesh.uv_scale);
}

#[test]
fn obj_without_normals_gets_computed_ones() {
    let dir = tempfile::tempdir().unwrap();
    let text = OBJ_QUAD.replace("vn 0 0 1\n", "").replace("f 1/1/1 2/2/1 3/3/1 4/4/1", "f 1/1 2/2 3/3 4/4");
    let mesh = load_mesh(&write(dir.path(), "quad.obj", text)).unwrap();
    assert!(mesh.normals.iter().all(|n| close(*n, Vec3::Z)), "{:?}", mesh.normals);
    assert_frames_sane(&mesh);
}

#[test]
fn obj_groups_are_merged() {
    let dir = tempfile::tempdir().unwrap();
    let text = "\
o first
v 0 0 0
v 1 0 0
v 0 1 0
vt 0 0
vt 1 0
vt 0 1
f 1/1 2/2 3/3
o second
v 0 0 1
v 1 0 1
v 0 1 1
f 4/1 5/2 6/3
";
    let mesh = load_mesh(&write(dir.path(), "two.obj", text)).unwrap();
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.positions.len(), 6);
    assert!(mesh.positions.iter().any(|p| close(*p, Vec3::new(1.0, 0.0, 1.0))));
    assert!(mesh.indices.iter().all(|&i| (i as usize) < mesh.positions.len()));
}

#[test]
fn obj_without_uvs_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let path = write(dir.path(), "pyramid.obj", text);
    let err = load_mesh(&path).unwrap_err();
    assert!(matches!(err, MeshLoadError::NoUvs { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("pyramid.obj"), "{msg}");
    assert!(msg.contains("has no texture coordinates (UVs): parallax mapping needs them"), "{msg}");

    // UVs on some faces only.
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 2 4 3\n";
    let err = load_mesh(&write(dir.path(), "partial.obj", text)).unwrap_err();
    assert!(matches!(err, MeshLoadError::NoUvs { .. }), "{err:?}");
    assert!(err.to_string().contains("partial.obj") && err.to_string().contains("some faces"), "{err}");
}

#[test]
fn bad_obj_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str); 6] = [
        ("empty.obj", ""),
        ("words.obj", "this is not an obj file\n"),
        ("badnum.obj", "v 0 zero 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n"),
        ("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 9/1\n"),
        ("relative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-100 2/1 3/1\n"),
        ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"),
    ];
    for (name, text) in cases {
        let err = load_mesh(&write(dir.path(), name, text)).unwrap_err();
        assert!(err.to_string().contains(name), "{name}: {err}");
    }
    // Binary garbage.
    let err = load_mesh(&write(dir.path(), "binary.obj", [0xffu8, 0xfe, 0, 1, 2, 3])).unwrap_err();
    assert!(err.to_string().contains("binary.obj"), "{err}");
}

#[test]
fn missing_files_and_unknown_formats_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let err = load_mesh(&dir.path().join("absent.obj")).unwrap_err();
    assert!(matches!(err, MeshLoadError::Read { .. }), "{err:?}");
    assert!(err.to_string().contains("absent.obj"), "{err}");
    let err = load_mesh(&write(dir.path(), "model.fbx", "x")).unwrap_err();
    assert!(matches!(err, MeshLoadError::UnsupportedFormat { .. }), "{err:?}");
    assert!(err.to_string().contains("model.fbx") && err.to_string().contains(".gltf"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// glTF
// ---------------------------------------------------------------------------------------------

/// Standard base64 with padding, for `data:` URIs.
fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Little-endian bytes of floats.
fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// One triangle's attributes, laid out in one buffer: the JSON of a glTF with a single mesh of
/// one primitive, plus its binary buffer. `nodes` is the JSON of the nodes array (node 0 is the
/// scene's root).
struct Triangle {
    positions: [[f32; 3]; 3],
    normals: Option<[[f32; 3]; 3]>,
    uvs: Option<[[f32; 2]; 3]>,
    tangents: Option<[[f32; 4]; 3]>,
    nodes: String,
}

impl Default for Triangle {
    fn default() -> Self {
        Self {
            positions: [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: Some([[0.0, 0.0, 1.0]; 3]),
            uvs: Some([[0.0, 1.0], [1.0, 1.0], [0.0, 0.0]]),
            tangents: None,
            nodes: r#"[{"mesh": 0}]"#.to_owned(),
        }
    }
}

impl Triangle {
    /// The JSON (with `uri` as the buffer's URI, or no URI for a GLB) and the buffer bytes.
    fn build(&self, uri: Option<&str>) -> (String, Vec<u8>) {
        let mut bin = Vec::new();
        let mut views = Vec::new();
        let mut accessors = Vec::new();
        let mut attributes = Vec::new();
        let mut add = |name: &str, kind: &str, flat: Vec<f32>, minmax: bool| {
            let offset = bin.len();
            bin.extend(f32_bytes(&flat));
            let index = views.len();
            views.push(format!(r#"{{"buffer": 0, "byteOffset": {offset}, "byteLength": {}}}"#, flat.len() * 4));
            let bounds = if minmax {
                let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
                for p in flat.chunks(3) {
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                format!(r#", "min": {lo:?}, "max": {hi:?}"#)
            } else {
                String::new()
            };
            accessors.push(format!(
                r#"{{"bufferView": {index}, "componentType": 5126, "count": 3, "type": "{kind}"{bounds}}}"#
            ));
            attributes.push(format!(r#""{name}": {index}"#));
        };
        add("POSITION", "VEC3", self.positions.concat(), true);
        if let Some(n) = self.normals {
            add("NORMAL", "VEC3", n.concat(), false);
        }
        if let Some(t) = self.uvs {
            add("TEXCOORD_0", "VEC2", t.concat(), false);
        }
        if let Some(t) = self.tangents {
            add("TANGENT", "VEC4", t.concat(), false);
        }
        let uri = uri.map(|u| format!(r#", "uri": "{u}""#)).unwrap_or_default();
        let json = format!(
            r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": {nodes},
  "meshes": [{{"name": "tri", "primitives": [{{"attributes": {{{attributes}}}}}]}}],
  "buffers": [{{"byteLength": {len}{uri}}}],
  "bufferViews": [{views}],
  "accessors": [{accessors}]
}}"#,
            nodes = self.nodes,
            attributes = attributes.join(", "),
            len = bin.len(),
            views = views.join(", "),
            accessors = accessors.join(", "),
        );
        (json, bin)
    }

    /// A `.gltf` with the buffer inline as a base64 data URI.
    fn gltf_embedded(&self) -> String {
        let (_, bin) = self.build(None);
        let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
        self.build(Some(&uri)).0
    }

    /// A binary `.glb`: header, JSON chunk, BIN chunk.
    fn glb(&self) -> Vec<u8> {
        let (json, mut bin) = self.build(None);
        let mut json = json.into_bytes();
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::new();
        out.extend(b"glTF");
        out.extend(2u32.to_le_bytes());
        out.extend((total as u32).to_le_bytes());
        out.extend((json.len() as u32).to_le_bytes());
        out.extend(b"JSON");
        out.extend(json);
        out.extend((bin.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(bin);
        out
    }
}

#[test]
fn gltf_with_data_uri_loads_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let tri = Triangle::default();
    let mesh = load_mesh(&write(dir.path(), "tri.gltf", tri.gltf_embedded())).unwrap();
    assert_eq!(mesh.indices, vec![0, 1, 2], "non-indexed primitive: vertices in order");
    assert_eq!(mesh.positions, tri.positions.map(Vec3::from).to_vec());
    assert_eq!(mesh.uvs, tri.uvs.unwrap().map(Vec2::from).to_vec(), "glTF UVs are not flipped");
    assert!(mesh.normals.iter().all(|n| close(*n, Vec3::Z)));
    assert_frames_sane(&mesh);
    for t in &mesh.tangents {
        assert!(close(t.truncate(), Vec3::X), "u grows along +X: {t}");
        assert_eq!(t.w, 1.0);
    }
}

#[test]
fn glb_and_external_bin_load_the_same_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let tri = Triangle::default();
    let from_glb = load_mesh(&write(dir.path(), "tri.glb", tri.glb())).unwrap();
    let (json, bin) = tri.build(Some("tri.bin"));
    write(dir.path(), "tri.bin", bin);
    let from_bin = load_mesh(&write(dir.path(), "external.gltf", json)).unwrap();
    let from_uri = load_mesh(&write(dir.path(), "tri.gltf", tri.gltf_embedded())).unwrap();
    assert_eq!(from_glb, from_uri);
    assert_eq!(from_bin, from_uri);

    // A missing .bin names both the .gltf and the .bin.
    std::fs::remove_file(dir.path().join("tri.bin")).unwrap();
    let err = load_mesh(&dir.path().join("external.gltf")).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("external.gltf") && msg.contains("tri.bin"), "{msg}");
}

#[test]
fn gltf_tangents_are_used_as_given() {
    let dir = tempfile::tempdir().unwrap();
    // The UVs would give T = +X and w = +1; the file says otherwise, and the file wins.
    let given = [0.0, 1.0, 0.0, -1.0];
    let tri = Triangle { tangents: Some([given; 3]), ..Triangle::default() };
    let mesh = load_mesh(&write(dir.path(), "tangents.gltf", tri.gltf_embedded())).unwrap();
    for t in &mesh.tangents {
        assert!((*t - Vec4::from(given)).length() < 1e-6, "{t}");
    }
    assert_frames_sane(&mesh);
}

#[test]
fn gltf_node_transforms_are_applied() {
    let dir = tempfile::tempdir().unwrap();
    // Root translated by (10, 0, 0) with a child rotated 90 degrees about Z (quaternion
    // [0, 0, sin 45, cos 45]) and scaled by 2, holding the mesh.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let nodes = format!(
        r#"[{{"translation": [10.0, 0.0, 0.0], "children": [1]}}, {{"mesh": 0, "rotation": [0.0, 0.0, {s}, {s}], "scale": [2.0, 2.0, 2.0]}}]"#
    );
    let tri = Triangle { nodes, tangents: Some([[1.0, 0.0, 0.0, 1.0]; 3]), ..Triangle::default() };
    let mesh = load_mesh(&write(dir.path(), "nodes.gltf", tri.gltf_embedded())).unwrap();
    let expect = [Vec3::new(10.0, 0.0, 0.0), Vec3::new(10.0, 2.0, 0.0), Vec3::new(8.0, 0.0, 0.0)];
    for (p, e) in mesh.positions.iter().zip(expect) {
        assert!(close(*p, e), "{p} != {e}");
    }
    assert!(mesh.normals.iter().all(|n| close(*n, Vec3::Z)), "rotation about the normal keeps it");
    // The given tangent +X turns with the node to +Y.
    assert!(mesh.tangents.iter().all(|t| close(t.truncate(), Vec3::Y) && t.w == 1.0), "{:?}", mesh.tangents);
    assert_frames_sane(&mesh);
}

#[test]
fn gltf_mirroring_node_flips_winding_and_handedness() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = r#"[{"mesh": 0, "scale": [-1.0, 1.0, 1.0]}]"#.to_owned();
    let tri = Triangle { nodes, tangents: Some([[1.0, 0.0, 0.0, 1.0]; 3]), ..Triangle::default() };
    let mesh = load_mesh(&write(dir.path(), "mirror.gltf", tri.gltf_embedded())).unwrap();
    assert_eq!(mesh.indices, vec![0, 2, 1], "winding reversed so the front stays counter-clockwise");
    let [a, b, c] = [0, 1, 2].map(|k| mesh.positions[mesh.indices[k] as usize]);
    assert!((b - a).cross(c - a).dot(Vec3::Z) > 0.0, "front face still faces its normal");
    assert!(mesh.tangents.iter().all(|t| close(t.truncate(), -Vec3::X) && t.w == -1.0), "{:?}", mesh.tangents);
}

#[test]
fn gltf_without_normals_gets_flat_normals_and_ignores_tangents() {
    let dir = tempfile::tempdir().unwrap();
    let tri = Triangle { normals: None, tangents: Some([[0.0, 1.0, 0.0, -1.0]; 3]), ..Triangle::default() };
    let mesh = load_mesh(&write(dir.path(), "flat.gltf", tri.gltf_embedded())).unwrap();
    assert!(mesh.normals.iter().all(|n| close(*n, Vec3::Z)), "{:?}", mesh.normals);
    assert!(mesh.tangents.iter().all(|t| close(t.truncate(), Vec3::X) && t.w == 1.0), "{:?}", mesh.tangents);
}

#[test]
fn gltf_without_uvs_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let tri = Triangle { uvs: None, ..Triangle::default() };
    let err = load_mesh(&write(dir.path(), "bare.gltf", tri.gltf_embedded())).unwrap_err();
    assert!(matches!(err, MeshLoadError::NoUvs { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("bare.gltf") && msg.contains("no texture coordinates") && msg.contains("\"tri\""), "{msg}");
    let err = load_mesh(&write(dir.path(), "bare.glb", tri.glb())).unwrap_err();
    assert!(err.to_string().contains("bare.glb"), "{err}");
}

#[test]
fn bad_gltf_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let good = Triangle::default().glb();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty.gltf", Vec::new()),
        ("text.gltf", b"{ not json".to_vec()),
        ("nothing.gltf", br#"{"asset": {"version": "2.0"}}"#.to_vec()),
        ("truncated.glb", good[..good.len() / 2].to_vec()),
        ("wrongmagic.glb", [b"glTX".as_slice(), &good[4..]].concat()),
    ];
    for (name, bytes) in cases {
        let err = load_mesh(&write(dir.path(), name, bytes)).unwrap_err();
        assert!(err.to_string().contains(name), "{name}: {err}");
    }
    // An accessor that claims more vertices than its buffer holds.
    let json = Triangle::default().gltf_embedded().replacen(r#""count": 3"#, r#""count": 3000"#, 1);
    let err = load_mesh(&write(dir.path(), "short.gltf", json)).unwrap_err();
    assert!(err.to_string().contains("short.gltf"), "{err}");
}
