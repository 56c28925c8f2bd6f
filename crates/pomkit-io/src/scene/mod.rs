//! Scene files: a camera, lights, materials and objects in TOML, loaded into a
//! [`Scene`].
//!
//! [`load_scene`] reads a file; [`parse_scene`] parses text. Paths inside a scene (textures,
//! meshes) are relative to the scene file's folder (to `base_dir` for [`parse_scene`]); absolute
//! paths work too. Colours are linear RGB. Every error names the scene file, the table (for
//! example `material "bricks"` or `object 2 ("floor")`) and the field, and a typo in a field
//! name is an error, not a silently ignored line.
//!
//! # Format
//!
//! A complete scene, every field written out (the values shown for optional fields are their
//! defaults unless the comment says otherwise):
//!
//! ```toml
//! background = [0.02, 0.02, 0.03]   # linear RGB behind everything
//! ambient = [0.05, 0.05, 0.06]      # linear RGB, multiplied by the albedo
//!
//! [camera]                          # required
//! eye = [0.0, 2.0, 4.0]             # required; coordinates at most 1e18 in magnitude
//! target = [0.0, 0.0, 0.0]          # required; must differ from eye
//! up = [0.0, 1.0, 0.0]              # must not be parallel to target - eye
//! fov = 45.0                        # vertical field of view, degrees, 1e-3 to 179
//! near = 0.05                       # near clipping distance, > 0
//! far = 100.0                       # far clipping distance, > near
//!
//! [[light]]                         # any number, including none (ambient light only)
//! type = "directional"              # "directional" or "point"
//! direction = [0.0, 1.0, 0.0]       # directional only: toward the light (normalized on use)
//! color = [1.0, 1.0, 1.0]
//! intensity = 1.0                   # >= 0
//!
//! [[light]]
//! type = "point"
//! position = [0.0, 4.0, 0.0]        # point only; inverse-square falloff
//! color = [1.0, 1.0, 1.0]
//! intensity = 1.0                   # illuminance at distance 1
//!
//! [[material]]
//! name = "bricks"                   # default "material N" (N counts from 1); names are unique
//! folder = "textures/Bricks"        # a texture-library folder whose maps fill in albedo,
//!                                   # normal and height where the table names none
//! albedo = "bricks_albedo.png"      # colour map (sRGB file, or linear float EXR); default white
//! height = "bricks_height.png"      # height map; default none (the material is then flat
//!                                   # or normal-mapped only)
//! depth_map = false                 # the height image stores depth (white = deep)
//! channel = "luma"                  # r, g, b, a or luma: the channel holding the height
//! normalize = false                 # rescale the height image's values to [0, 1]
//! normal = "bricks_normal.png"      # tangent-space normal map; default none: the renderer
//!                                   # bakes one from the height map
//! normal_y_down = false             # the normal map is DirectX-style (+Y down)
//! base_color = [0.8, 0.8, 0.8]      # multiplies the albedo
//! technique = "exact"               # flat, normal, parallax, iterative, steep, pom-classic,
//!                                   # pom, relief, exact or cone
//! depth_scale = 0.1                 # depth of the deepest point, in UV units; > 0, <= 16
//! min_samples = 8                   # pom: fewest samples (head-on)
//! max_samples = 32                  # pom: most samples (grazing); >= min_samples
//! samples = 32                      # steep, relief: depth planes
//! iterations = 4                    # iterative: parallax steps
//! binary_steps = 6                  # relief, cone: binary refinement steps
//! refine = 0                        # pom: secant refinement steps
//! perspective_bias = 1.0            # pom-classic: 0 to 1 (1 = the exact parallax length)
//! edges = "wrap"                    # wrap or clamp: texture addressing
//! cone_map = "bricks_cone.png"      # cone: a baked cone map of the height map (bake cone)
//! shadow = "none"                   # none, hard, soft, exact or depth self-shadowing
//! softness = 0.1                    # soft: light's angular radius in radians, >= 0
//! lod_threshold = 4.0               # mip level beyond which only normal mapping is done
//! specular = 0.25                   # Blinn-Phong strength, >= 0
//! shininess = 32.0                  # Blinn-Phong exponent, > 0
//! pixel_depth_offset = true         # write the displaced depth to the depth buffer
//! silhouette = false                # curved meshes show a displaced outline (docs/SCENES.md)
//!
//! [[object]]                        # at least one
//! name = "floor"                    # default "object N"
//! mesh = "plane"                    # required: a built-in shape or a .obj/.gltf/.glb path
//! material = "bricks"               # required: a material's name, or a texture-library folder
//! size = [4.0, 4.0]                 # shape parameters, see below (this one: default 2)
//! uv_repeat = [2.0, 2.0]            # texture repeats along u and v (or one number); default 1
//! position = [0.0, 0.0, 0.0]
//! rotation = [0.0, 45.0, 0.0]       # degrees about X, then Y, then Z (default 0)
//! scale = [1.0, 1.0, 1.0]           # or one number; every component > 0
//! ```
//!
//! # Texture-library folders
//!
//! `material = "FOLDER"` on an object (when no material has that name and the path is a
//! folder) and `folder = "FOLDER"` on a material take a texture library's folder of maps,
//! found by their names ([`crate::library`], docs/SCENES.md).
//!
//! # Built-in textures
//!
//! `albedo` and `height` also accept `"builtin:NAME"` or `"builtin:NAME:WxH"`, where NAME is a
//! pattern of [`pomkit_core::procedural`] (bricks, pyramids, cobblestones, text, spike, waves,
//! fur, grass) and `WxH` the size in texels (default 512x512, each side 1 to 16384). The built-in colour
//! map matches the built-in height map of the same name. `depth_map`, `channel` and
//! `normalize` describe how to read a height *image*; with a built-in height they are an
//! error when set to anything but their defaults. `normal` takes files only.
//!
//! # Images
//!
//! Height maps are read by [`load_height_field`] (8- and 16-bit,
//! float EXR, any channel). Colour maps in 8- or 16-bit formats are sRGB and converted to linear;
//! float (EXR) colour maps are taken as linear; alpha is ignored. Normal maps store `n * 0.5 +
//! 0.5` in RGB (8 or 16 bits), +Y up unless `normal_y_down`; a map whose blue channel is zero
//! everywhere is a two-channel map (`pomkit bake normal --encoding rg8`) and z is rebuilt;
//! float (EXR) normal maps hold the vectors themselves (`--encoding float`). Greyscale images are
//! refused as normal maps.
//!
//! # Shapes
//!
//! `mesh` names a built-in shape of [`Mesh`] or a file loaded by [`load_mesh`] (OBJ's v is
//! flipped, see [`crate::mesh`]). Shape parameters, each with its default, and which shapes
//! take them (any other parameter on a shape is an error; files take none):
//!
//! | shape | parameters |
//! |---|---|
//! | `plane` (XZ, facing +Y) | `size = 2.0` (one number or `[x, z]`), `segments = 1` (per side) |
//! | `quad` (XY, facing +Z) | `size = 2.0` (one number or `[x, y]`) |
//! | `disc` (XZ, facing +Y) | `radius = 1.0`, `segments = 64` (at least 3) |
//! | `cube` | `size = 2.0` (one number: the edge; use `scale` for a box) |
//! | `sphere` | `radius = 1.0`, `rings = 32` (at least 2), `segments = 64` (at least 3) |
//! | `cylinder` (axis Y, with caps) | `radius = 1.0`, `height = 2.0`, `segments = 64` (at least 3) |
//! | `torus` (axis Y) | `radius = 1.0` (of the tube's centre circle), `tube_radius = 0.25`, `segments = 64` (around the axis), `tube_segments = 32` (around the tube), each count at least 3 |
//!
//! Lengths must be finite and positive, counts at most [`MAX_SEGMENTS`]. `uv_repeat` multiplies
//! the UVs (with `edges = "wrap"` the texture tiles); both components must be positive.
//!
//! # Transforms
//!
//! An object's transform is `translate(position) * rotate_z * rotate_y * rotate_x *
//! scale(scale)`: the mesh is scaled, then rotated about X, then about Y, then about Z (angles in
//! degrees, right-handed: counter-clockwise seen from the positive end of the axis), then
//! moved to `position`. Mirroring (negative) scales are refused.
//!
//! # Numbers and limits
//!
//! Every number must be finite (TOML allows `nan` and `inf`; they are errors here). Whole
//! numbers may be written where decimals are expected (`fov = 45`). Sample counts above
//! [`MAX_SAMPLES`](pomkit_core::trace::MAX_SAMPLES), and counts of 0, are clamped when tracing
//! ([`TraceParams::sanitized`]). A displacing technique written explicitly on a material
//! without a height map is an error (it would silently render flat).
//!
//! What f32 cannot draw is refused, naming the key ([`Scene::check_drawable`], docs/SCENES.md):
//! `fov` outside 1e-3 to 179 degrees, coordinates beyond 1e18, and triangles that cross the
//! near plane reaching more than 2^20 times `near` from the eye. Normal-map texels that are not
//! finite, are zero, or point into the surface are refused naming the texel.
//!
//! # Example
//!
//! A scene made only of built-in textures and shapes loads without any file:
//!
//! ```
//! use pomkit_io::scene::parse_scene;
//! use pomkit_core::Technique;
//!
//! let scene = parse_scene(r#"
//!     [camera]
//!     eye = [0.0, 2.0, 4.0]
//!     target = [0.0, 0.0, 0.0]
//!
//!     [[light]]
//!     direction = [-1.0, 1.0, 0.5]
//!
//!     [[material]]
//!     name = "bricks"
//!     albedo = "builtin:bricks:64x64"
//!     height = "builtin:bricks:64x64"
//!     technique = "relief"
//!     depth_scale = 0.05
//!
//!     [[object]]
//!     mesh = "plane"
//!     size = 4.0
//!     uv_repeat = 2.0
//!     material = "bricks"
//! "#, std::path::Path::new("."))?;
//! assert_eq!(scene.materials[0].technique, Technique::Relief);
//! assert_eq!(scene.objects[0].name, "object 1");
//! # Ok::<(), pomkit_io::scene::SceneError>(())
//! ```

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use image::DynamicImage;
use pomkit_core::bake::rebuild_z;
use pomkit_core::glam::{Mat4, Quat, Vec2, Vec3};
use pomkit_core::mesh::{MAX_SEGMENTS, Mesh};
use pomkit_core::params;
use pomkit_core::procedural::{self, Pattern};
use pomkit_core::scene::{Camera, DrawableError, Light, Material, NormalMap, Object, Scene, Texture, srgb_to_linear};
use pomkit_core::trace::TraceParamError;
use pomkit_core::{EdgeMode, HeightField, ShadowMode, Technique, TraceParams};
use serde::Deserialize;

use crate::mesh::{MeshLoadError, load_mesh};

mod folder;
mod gltf;
mod maps;
mod material;
mod object;
mod sizes;

use crate::{Channel, HeightLoadOptions, IoError, load_height_field};
pub use maps::{
    MAX_INWARD_SHARE, NORMAL_Z_LOSSY, NORMAL_Z_TOLERANCE, NormalZ, decode_color_texture, decode_normal_map,
    decode_normal_map_with, load_color_texture, load_normal_map, load_normal_map_with,
};
use object::{is_shape, shape_bytes};
pub use sizes::{MaterialSizes, ObjectSizes, SceneSizes, scene_sizes, scene_text_sizes, texture_size};

/// The side of a built-in texture when the scene gives no size.
pub const BUILTIN_SIZE: u32 = 512;

/// The largest side of a built-in texture.
pub const MAX_BUILTIN_SIZE: u32 = pomkit_core::MAX_SIZE;

/// Why a scene could not be loaded. Every variant names the scene file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file could not be read (missing, unreadable, not UTF-8).
    #[error("cannot read {}: {reason}", crate::shown(path))]
    Read {
        /// The scene file.
        path: PathBuf,
        /// The operating system's reason.
        reason: std::io::Error,
    },
    /// The text is not valid TOML or does not fit the format: a syntax error, an unknown field,
    /// a value of the wrong type, a missing required field.
    #[error("{}", syntax_message(file, *position, context.as_deref(), field.as_deref(), message))]
    Syntax {
        /// The scene file.
        file: PathBuf,
        /// 1-based line and column (in characters) of the problem, when known.
        position: Option<(usize, usize)>,
        /// The table it lies in, e.g. `material "bricks"`, when it could be told.
        context: Option<String>,
        /// The field concerned, when it could be told.
        field: Option<String>,
        /// What is wrong (the TOML parser's words).
        message: String,
    },
    /// A value is out of range, unknown or inconsistent (an unknown technique, a material that
    /// is not defined, `depth_scale = 0`, a NaN, a camera looking at itself...).
    #[error("{}: {at}: {message}", crate::shown(file))]
    Invalid {
        /// The scene file.
        file: PathBuf,
        /// The table, e.g. `material "bricks"`, `object 2 ("floor")` or `camera`.
        at: String,
        /// The field, e.g. `technique`.
        field: String,
        /// What is wrong; it names the field.
        message: String,
    },
    /// A texture the scene refers to could not be loaded.
    // The cause is part of the message and deliberately not a `source()`: a chain printer
    // (anyhow's `{:#}`) would print it a second time.
    #[error("{}: {at}: {field}: {cause}", crate::shown(file))]
    Texture {
        /// The scene file.
        file: PathBuf,
        /// The material, e.g. `material "bricks"`.
        at: String,
        /// `albedo`, `height`, `normal` or `cone_map`.
        field: String,
        /// Why the image failed; it names the image file.
        cause: Box<IoError>,
    },
    /// A mesh file the scene refers to could not be loaded.
    #[error("{}: {at}: mesh {mesh:?}: {cause}", crate::shown(file))]
    Mesh {
        /// The scene file.
        file: PathBuf,
        /// The object, e.g. `object 1 ("statue")`.
        at: String,
        /// The `mesh` value as written.
        mesh: String,
        /// Why the mesh failed; it names the mesh file.
        cause: Box<MeshLoadError>,
    },
    /// The glTF file the scene imports (`gltf = ...`, or the glTF file rendered itself) could
    /// not be read, or an item of it (a material, a texture, a camera) is invalid.
    #[error("{}", gltf_message(file, value, cause))]
    Gltf {
        /// The scene file (the glTF file itself when it is rendered directly).
        file: PathBuf,
        /// The `gltf` value as written.
        value: String,
        /// Why; it names the glTF file and the item.
        cause: Box<MeshLoadError>,
    },
}

/// `cause`, prefixed by the scene file and the `gltf` key unless the scene is the glTF file.
fn gltf_message(file: &Path, value: &str, cause: &MeshLoadError) -> String {
    let same = match cause {
        MeshLoadError::Read { path, .. }
        | MeshLoadError::UnsupportedFormat { path }
        | MeshLoadError::Obj { path, .. }
        | MeshLoadError::Gltf { path, .. }
        | MeshLoadError::NoUvs { path, .. }
        | MeshLoadError::NoTriangles { path }
        | MeshLoadError::Invalid { path, .. }
        | MeshLoadError::Mesh { path, .. } => path == file,
    };
    if same { cause.to_string() } else { format!("{}: gltf {value:?}: {cause}", crate::shown(file)) }
}

impl SceneError {
    /// The field the error is about (`technique`, `mesh`, ...), when known.
    #[must_use]
    pub fn field(&self) -> Option<&str> {
        match self {
            SceneError::Read { .. } => None,
            SceneError::Syntax { field, .. } => field.as_deref(),
            SceneError::Invalid { field, .. } | SceneError::Texture { field, .. } => Some(field),
            SceneError::Mesh { .. } => Some("mesh"),
            SceneError::Gltf { .. } => Some("gltf"),
        }
    }
}

/// `file: line 3, column 7: material "x": field: message`, leaving out what is unknown.
fn syntax_message(
    file: &Path,
    position: Option<(usize, usize)>,
    context: Option<&str>,
    field: Option<&str>,
    message: &str,
) -> String {
    let mut s = crate::shown(file).to_string();
    if let Some((l, c)) = position {
        write!(s, ": line {l}, column {c}").unwrap_or_default();
    }
    if let Some(ctx) = context {
        write!(s, ": {ctx}").unwrap_or_default();
    }
    // Name the field unless the parser's message already does (`unknown field `x``).
    if let Some(f) = field.filter(|f| !message.contains(&format!("`{f}`"))) {
        write!(s, ": {f}").unwrap_or_default();
    }
    write!(s, ": {message}").unwrap_or_default();
    s
}

// ---------------------------------------------------------------------------------------------
// The file's shape (serde)
// ---------------------------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    background: Option<[f32; 3]>,
    ambient: Option<[f32; 3]>,
    /// A glTF file whose scene is imported (docs/SCENES.md, glTF files).
    gltf: Option<String>,
    camera: Option<CameraFile>,
    #[serde(default)]
    light: Vec<LightFile>,
    #[serde(default)]
    material: Vec<MaterialFile>,
    #[serde(default)]
    object: Vec<ObjectFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    eye: [f32; 3],
    target: [f32; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
    near: Option<f32>,
    far: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightFile {
    #[serde(rename = "type")]
    kind: Option<String>,
    direction: Option<[f32; 3]>,
    position: Option<[f32; 3]>,
    color: Option<[f32; 3]>,
    intensity: Option<f32>,
}

#[derive(Deserialize, Clone, Default)]
#[serde(deny_unknown_fields)]
struct MaterialFile {
    name: Option<String>,
    /// A texture-library folder whose maps fill in the maps the table leaves out (folder.rs).
    folder: Option<String>,
    /// Made for an object whose `material` names a folder: that object, for errors.
    #[serde(skip)]
    from_object: Option<String>,
    albedo: Option<String>,
    height: Option<String>,
    depth_map: Option<bool>,
    channel: Option<String>,
    normalize: Option<bool>,
    normal: Option<String>,
    normal_y_down: Option<bool>,
    base_color: Option<[f32; 3]>,
    technique: Option<String>,
    depth_scale: Option<f32>,
    min_samples: Option<u32>,
    max_samples: Option<u32>,
    samples: Option<u32>,
    iterations: Option<u32>,
    binary_steps: Option<u32>,
    refine: Option<u32>,
    perspective_bias: Option<f32>,
    edges: Option<String>,
    shadow: Option<String>,
    softness: Option<f32>,
    lod_threshold: Option<f32>,
    specular: Option<f32>,
    shininess: Option<f32>,
    pixel_depth_offset: Option<bool>,
    silhouette: Option<bool>,
    cone_map: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    name: Option<String>,
    mesh: String,
    material: Option<String>,
    position: Option<[f32; 3]>,
    rotation: Option<[f32; 3]>,
    scale: Option<NumberOr<[f32; 3]>>,
    uv_repeat: Option<NumberOr<[f32; 2]>>,
    size: Option<NumberOr<[f32; 2]>>,
    radius: Option<f32>,
    height: Option<f32>,
    tube_radius: Option<f32>,
    segments: Option<u32>,
    rings: Option<u32>,
    tube_segments: Option<u32>,
}

impl ObjectFile {
    /// `object N` or `object N ("NAME")`: where errors about the `i`-th object (from 0) point.
    fn label(&self, i: usize) -> String {
        match &self.name {
            Some(n) => format!("object {} ({n:?})", i + 1),
            None => format!("object {}", i + 1),
        }
    }

    /// The built-in shapes' keys and whether the table sets each.
    fn shape_keys(&self) -> [(&'static str, bool); 7] {
        [
            ("size", self.size.is_some()),
            ("radius", self.radius.is_some()),
            ("height", self.height.is_some()),
            ("tube_radius", self.tube_radius.is_some()),
            ("segments", self.segments.is_some()),
            ("rings", self.rings.is_some()),
            ("tube_segments", self.tube_segments.is_some()),
        ]
    }
}

/// One number for every component, or one per component.
#[derive(Deserialize, Clone, Copy)]
#[serde(untagged, expecting = "expected a number or an array of numbers")]
enum NumberOr<A> {
    One(f32),
    Each(A),
}

// ---------------------------------------------------------------------------------------------
// Loading
// ---------------------------------------------------------------------------------------------

/// Loads a scene file. Relative paths in it are relative to its folder.
///
/// # Errors
/// A [`SceneError`] naming `path`, the table and the field: the file cannot be read, is not
/// valid TOML, has an unknown field or a value of the wrong type or out of range, refers to an
/// undefined material, or a texture or mesh it names cannot be loaded.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    load_scene_warned(path, &mut Vec::new())
}

/// Whether `path` names a glTF file (`.gltf` or `.glb`), loaded as the scene `gltf = "FILE"`.
#[must_use]
pub fn is_gltf(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("gltf" | "glb"))
}

/// The scene text that imports the glTF file `path` whole (`gltf = "NAME"`, relative to its
/// folder).
#[must_use]
pub fn gltf_scene_text(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    format!("gltf = {}\n", toml::Value::String(name))
}

/// [`load_scene`], adding to `warnings` what is drawn otherwise than a glTF file says (a spot
/// light's cone, a mirrored repeat, an orthographic camera...). A `.gltf` or `.glb` path is
/// loaded as the scene `gltf = "FILE"` (docs/SCENES.md, glTF files).
///
/// # Errors
/// As [`load_scene`].
pub fn load_scene_warned(path: &Path, warnings: &mut Vec<String>) -> Result<Scene, SceneError> {
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let text = if is_gltf(path) { gltf_scene_text(path) } else { read_scene_text(path)? };
    let mut cache = SceneCache::default();
    let scene = parse_scene_cached(&text, path, base, &mut cache);
    warnings.append(&mut cache.warnings);
    scene
}

/// The text of a scene file: at most [`crate::read::MAX_SCENE_BYTES`] (docs/LIMITS.md), so a
/// device or a huge file is refused, not read whole; it must be UTF-8.
fn read_scene_text(path: &Path) -> Result<String, SceneError> {
    let bytes = crate::read::read_capped(path, crate::read::MAX_SCENE_BYTES, "a scene file")
        .map_err(|reason| SceneError::Read { path: path.to_owned(), reason })?;
    String::from_utf8(bytes).map_err(|e| SceneError::Read {
        path: path.to_owned(),
        reason: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
    })
}

/// The files a scene file reads, without loading them: the scene file itself, then every
/// texture (albedo, height, normal and cone map) and mesh file it names, resolved as
/// [`load_scene`] resolves them (built-in maps and shapes are not files), and the external
/// buffers and images of its glTF meshes ([`crate::mesh::mesh_references`]). For a program
/// that must not write over its inputs (`pomkit render -o`).
///
/// # Errors
/// [`SceneError::Read`] or [`SceneError::Syntax`], as [`load_scene`] gives them (so scene files
/// over the size cap of docs/LIMITS.md are refused as unreadable).
pub fn scene_inputs(path: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let text = if is_gltf(path) { gltf_scene_text(path) } else { read_scene_text(path)? };
    let mut parsed: SceneFile = toml::from_str(&text).map_err(|e| syntax_error(path, &text, &e))?;
    let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    folder::add_folder_materials(&mut parsed, base);
    let mut files = vec![path.to_owned()];
    let mut meshes = Vec::new();
    if let Some(g) = &parsed.gltf {
        let file = base.join(g);
        if file != path {
            files.push(file.clone());
        }
        meshes.push(file);
    }
    let mut add = |value: &str| {
        if !value.trim().is_empty() && !value.starts_with("builtin:") {
            files.push(base.join(value));
        }
    };
    for m in &parsed.material {
        [&m.albedo, &m.height, &m.normal, &m.cone_map].into_iter().flatten().for_each(|v| add(v));
    }
    for o in &parsed.object {
        if !is_shape(&o.mesh.trim().to_ascii_lowercase()) {
            add(&o.mesh);
            meshes.push(base.join(&o.mesh));
        }
    }
    // The maps of texture-library folders.
    files.extend(folder::folder_files(&parsed, base));
    // A glTF mesh's external buffers and images.
    for mesh in meshes {
        files.extend(crate::mesh::mesh_references(&mesh));
    }
    Ok(files)
}

/// Parses scene text; relative paths are resolved against `base_dir`. Errors name the scene
/// `<scene>`; see [`parse_scene_named`] to give it a name.
///
/// # Errors
/// As [`load_scene`].
pub fn parse_scene(text: &str, base_dir: &Path) -> Result<Scene, SceneError> {
    parse_scene_named(text, Path::new("<scene>"), base_dir)
}

/// Parses scene text, naming it `file` in errors; relative paths are resolved against
/// `base_dir`.
///
/// # Errors
/// As [`load_scene`].
pub fn parse_scene_named(text: &str, file: &Path, base_dir: &Path) -> Result<Scene, SceneError> {
    parse_scene_cached(text, file, base_dir, &mut SceneCache::default())
}

/// Textures and meshes already loaded, kept between parses so that a program that re-reads a
/// scene after every edit (the viewer) loads each file and generates each built-in map once.
///
/// Entries are keyed by path and load options, not by file contents: call
/// [`SceneCache::clear`] to pick up files changed on disk.
#[derive(Default)]
pub struct SceneCache {
    heights: HashMap<(Source, bool, Channel, bool), Arc<HeightField>>,
    albedos: HashMap<Source, Arc<Texture>>,
    normals: HashMap<(PathBuf, bool), Arc<NormalMap>>,
    meshes: HashMap<PathBuf, Arc<Mesh>>,
    /// Mean roughness of texture-library roughness maps.
    roughness: HashMap<PathBuf, f32>,
    /// What the last parses drew otherwise than their glTF files say.
    warnings: Vec<String>,
}

impl SceneCache {
    /// Forgets everything loaded.
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Takes the warnings of the parses since the last call: what is drawn otherwise than a glTF
    /// file says (docs/SCENES.md, glTF files).
    pub fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }

    /// How many textures and meshes are held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.heights.len() + self.albedos.len() + self.normals.len() + self.meshes.len() + self.roughness.len()
    }

    /// Whether nothing is held.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// [`parse_scene_named`] with textures and meshes taken from, and added to, `cache`.
///
/// # Errors
/// As [`load_scene`].
pub fn parse_scene_cached(
    text: &str,
    file: &Path,
    base_dir: &Path,
    cache: &mut SceneCache,
) -> Result<Scene, SceneError> {
    let mut parsed: SceneFile = toml::from_str(text).map_err(|e| syntax_error(file, text, &e))?;
    folder::add_folder_materials(&mut parsed, base_dir);
    let mut loader = Loader { file, base: base_dir, cache };
    loader.scene(parsed)
}

/// Turns a TOML error into a [`SceneError::Syntax`] with line, table and field.
fn syntax_error(file: &Path, text: &str, err: &toml::de::Error) -> SceneError {
    let message = friendlier(err.message().trim());
    let mut out = (None, None, None);
    if let Some(span) = err.span() {
        let start = (0..=span.start.min(text.len())).rev().find(|&i| text.is_char_boundary(i)).unwrap_or(0);
        let before = &text[..start];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        let line_text = text.lines().nth(line - 1).unwrap_or("");
        out = (Some((line, column)), table_at(text, line), key_of(line_text, column, &message));
    }
    let (position, context, field) = out;
    SceneError::Syntax { file: file.to_owned(), position, context, field, message }
}

/// Serde's type names in plainer words.
fn friendlier(message: &str) -> String {
    message
        .replace("expected f32", "expected a number")
        .replace("expected u32", "expected a whole number from 0 to 4294967295")
        .replace("expected a boolean", "expected true or false")
        .replace("expected a string", "expected a quoted string")
}

/// The key of a `key = value` line when `column` (1-based, in characters) points into the value,
/// as it does for a value of the wrong type, or when the key itself is the problem (a duplicate).
/// (A missing field's error points at the start of its table, whose first key is innocent.)
fn key_of(line: &str, column: usize, message: &str) -> Option<String> {
    let (key, _) = line.split_once('=')?;
    if key.chars().count() >= column && !message.starts_with("duplicate key") {
        return None;
    }
    let key = key.trim().trim_matches('"');
    let ok = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    ok.then(|| key.to_owned())
}

/// The table holding line `line` (1-based): `camera`, `light 2`, `material "bricks"`, ... found
/// from the headers above it (names of materials and objects looked up in the TOML when it
/// parses as plain TOML).
fn table_at(text: &str, line: usize) -> Option<String> {
    let mut current: Option<(String, usize)> = None;
    let mut counts: HashMap<String, usize> = HashMap::new();
    for l in text.lines().take(line) {
        let l = l.split('#').next().unwrap_or("").trim();
        let (inner, array) = if let Some(i) = l.strip_prefix("[[").and_then(|r| r.strip_suffix("]]")) {
            (i.trim(), true)
        } else if let Some(i) = l.strip_prefix('[').and_then(|r| r.strip_suffix(']')) {
            (i.trim(), false)
        } else {
            continue;
        };
        // Headers are keys; lines of a multi-line array of numbers are not.
        if !inner.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_' || c == '"') {
            continue;
        }
        let name = inner.trim_matches('"').to_owned();
        let k = if array {
            let c = counts.entry(name.clone()).or_insert(0);
            *c += 1;
            *c
        } else {
            0
        };
        current = Some((name, k));
    }
    let (name, k) = current?;
    if k == 0 {
        return Some(name);
    }
    let named = toml::from_str::<toml::Table>(text)
        .ok()
        .and_then(|t| t.get(&name)?.as_array()?.get(k - 1)?.get("name")?.as_str().map(str::to_owned));
    Some(match (name.as_str(), named) {
        ("material", Some(n)) => format!("material {n:?}"),
        ("object", Some(n)) => format!("object {k} ({n:?})"),
        (_, _) => format!("{name} {k}"),
    })
}

/// Where a texture comes from.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
enum Source {
    File(PathBuf),
    Builtin(Pattern, u32, u32),
}

/// The scene under construction, with caches so that a texture or mesh file used twice is
/// loaded once (and shared through `Arc`).
struct Loader<'a> {
    file: &'a Path,
    base: &'a Path,
    cache: &'a mut SceneCache,
}

impl Loader<'_> {
    fn invalid(&self, at: &str, field: &str, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.to_owned(),
            at: at.to_owned(),
            field: field.to_owned(),
            message: message.into(),
        }
    }

    /// A finite vector.
    fn vec3(&self, at: &str, field: &str, v: [f32; 3]) -> Result<Vec3, SceneError> {
        let v = Vec3::from(v);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.invalid(at, field, format!("{field} is {v}: every component must be finite")))
        }
    }

    /// A finite colour with no negative component.
    fn color(&self, at: &str, field: &str, v: [f32; 3]) -> Result<Vec3, SceneError> {
        let c = self.vec3(at, field, v)?;
        if c.min_element() < 0.0 {
            return Err(self.invalid(at, field, format!("{field} is {c}: colour components must not be negative")));
        }
        Ok(c)
    }

    /// A number in the range the parameter table gives `p`.
    fn param(&self, at: &str, p: &params::Param, v: f32) -> Result<f32, SceneError> {
        let params::Kind::Float { min, min_exclusive, max, .. } = p.kind else {
            return Ok(v);
        };
        let v = self.number(at, p.key, v, min as f32, min_exclusive)?;
        if f64::from(v) > max {
            return Err(self.invalid(at, p.key, format!("{} is {v}: it must be at most {max}", p.key)));
        }
        Ok(v)
    }

    /// A finite number at least `min` (or above it when `strict`).
    fn number(&self, at: &str, field: &str, v: f32, min: f32, strict: bool) -> Result<f32, SceneError> {
        let ok = v.is_finite() && if strict { v > min } else { v >= min };
        if ok {
            return Ok(v);
        }
        let bound = if strict { format!("greater than {min}") } else { format!("at least {min}") };
        Err(self.invalid(at, field, format!("{field} is {v}: it must be a finite number {bound}")))
    }

    fn scene(&mut self, f: SceneFile) -> Result<Scene, SceneError> {
        let background = self.color("scene", "background", f.background.unwrap_or([0.02, 0.02, 0.03]))?;
        let ambient = self.color("scene", "ambient", f.ambient.unwrap_or([0.05, 0.05, 0.06]))?;
        let imported = match &f.gltf {
            Some(g) => Some(self.import_gltf(g, &f.material)?),
            None => None,
        };
        let camera = match (&f.camera, &imported) {
            (Some(c), _) => self.camera(c)?,
            (None, Some(g)) => g.camera,
            (None, None) => {
                return Err(SceneError::Syntax {
                    file: self.file.to_owned(),
                    position: None,
                    context: None,
                    field: None,
                    message: "missing field `camera` (a [camera] table, or a gltf file that brings one)".to_owned(),
                });
            }
        };
        let mut lights = f.light.iter().enumerate().map(|(i, l)| self.light(i, l)).collect::<Result<Vec<_>, _>>()?;
        if let Some(g) = &imported {
            lights.extend(g.lights.iter().copied());
            if lights.is_empty() {
                lights.push(gltf::DEFAULT_SUN);
            }
        }
        // The maps, checked against the memory budget before any is generated or decoded.
        self.check_textures(&f)?;
        let (mut materials, gltf_objects, gltf_names) = match imported {
            Some(g) => (g.materials, g.objects, g.gltf_names),
            None => (Vec::new(), Vec::new(), Vec::new()),
        };
        for (i, m) in f.material.iter().enumerate() {
            // A material named as one of the glTF file's overrides it (import_gltf).
            if m.name.as_ref().is_some_and(|n| gltf::overrides(n, &gltf_names)) {
                continue;
            }
            let material = self.material(i, m)?;
            if materials.iter().any(|other| other.name == material.name) {
                let at = format!("material {} ({:?})", i + 1, material.name);
                return Err(self.invalid(
                    &at,
                    "name",
                    format!("name {:?} is used by an earlier material", material.name),
                ));
            }
            materials.push(material);
        }
        if f.object.is_empty() && gltf_objects.is_empty() {
            return Err(self.invalid("scene", "object", "the scene has no [[object]]: it needs at least one"));
        }
        // The built-in shapes' meshes, checked against the memory budget before any is built.
        let shapes = f.object.iter().map(shape_bytes).fold(0u64, u64::saturating_add);
        pomkit_core::memory::check(
            || format!("building the {} objects' built-in shapes", f.object.len()),
            shapes,
            "use fewer segments or rings, or fewer objects",
        )
        .map_err(|e| self.invalid("scene", "object", e.to_string()))?;
        let mut objects = gltf_objects;
        for (i, o) in f.object.iter().enumerate() {
            if o.material.is_none() && is_gltf(Path::new(o.mesh.trim())) {
                // A glTF mesh with the file's own materials.
                self.gltf_object(i, o, &mut materials, &mut objects)?;
            } else {
                objects.push(self.object(i, o, &materials)?);
            }
        }
        let scene = Scene { camera, lights, materials, objects, ambient, background };
        // What f32 cannot draw (docs/SCENES.md), named here with the file; the renderers check
        // it again for scenes built in code.
        scene.check_drawable().map_err(|e| match e {
            DrawableError::Camera { field, message } => self.invalid("camera", field, message),
            DrawableError::Object { object, message } => {
                let i = scene.objects.iter().position(|o| o.name == object).unwrap_or(0);
                self.invalid(&format!("object {} ({object:?})", i + 1), "size", message)
            }
        })?;
        Ok(scene)
    }

    fn camera(&self, c: &CameraFile) -> Result<Camera, SceneError> {
        let at = "camera";
        let d = Camera::default();
        let eye = self.vec3(at, "eye", c.eye)?;
        let target = self.vec3(at, "target", c.target)?;
        let up = self.vec3(at, "up", c.up.unwrap_or(d.up.to_array()))?;
        let fov_y_deg = c.fov.unwrap_or(d.fov_y_deg);
        let near = c.near.unwrap_or(d.near);
        let far = c.far.unwrap_or(d.far);
        let camera = Camera { eye, target, up, fov_y_deg, near, far };
        // The renderers' own checks (pomkit_core::scene::Camera::check): magnitudes of eye and
        // target first, so a far-away eye is blamed rather than the up vector it breaks.
        camera.check().map_err(|e| match e {
            DrawableError::Camera { field, message } => self.invalid(at, field, message),
            DrawableError::Object { message, .. } => self.invalid(at, "camera", message),
        })?;
        let view = (target - eye).normalize();
        if view.cross(up.normalize_or_zero()).length_squared() < 1e-10 {
            return Err(self.invalid(
                at,
                "up",
                format!("up is {up}: it must not be zero or parallel to the view direction {view}"),
            ));
        }
        Ok(camera)
    }

    fn light(&self, i: usize, l: &LightFile) -> Result<Light, SceneError> {
        let at = format!("light {}", i + 1);
        let color = self.color(&at, "color", l.color.unwrap_or([1.0; 3]))?;
        let intensity = self.number(&at, "intensity", l.intensity.unwrap_or(1.0), 0.0, false)?;
        match l.kind.as_deref().unwrap_or("directional") {
            "directional" => {
                if l.position.is_some() {
                    return Err(self.invalid(
                        &at,
                        "position",
                        "position applies to point lights (type = \"point\") only",
                    ));
                }
                let direction = self.vec3(&at, "direction", l.direction.unwrap_or([0.0, 1.0, 0.0]))?;
                if direction.length_squared() <= f32::MIN_POSITIVE {
                    return Err(self.invalid(&at, "direction", "direction is zero: it must point toward the light"));
                }
                Ok(Light::Directional { direction, color, intensity })
            }
            "point" => {
                if l.direction.is_some() {
                    return Err(self.invalid(&at, "direction", "direction applies to directional lights only"));
                }
                let position = self.vec3(&at, "position", l.position.unwrap_or([0.0, 4.0, 0.0]))?;
                Ok(Light::Point { position, color, intensity })
            }
            other => {
                Err(self.invalid(&at, "type", format!("type {other:?} is unknown: expected directional or point")))
            }
        }
    }
}
