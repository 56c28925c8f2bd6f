//! Scenes: camera, lights, materials and objects, shared by the CPU and GPU renderers.
//!
//! Pure data: loading a scene file is `pomkit-io`'s job, drawing it a renderer's. Colours are
//! linear RGB; textures loaded from sRGB files are converted on load.

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::grid::Grid;
use crate::heightfield::{EdgeMode, HeightField};
use crate::mesh::Mesh;
use crate::shadow::ShadowParams;
use crate::trace::{Technique, TraceParams};

/// An RGB texture in linear colour, sampled bilinearly over texel centres like a height field.
#[derive(Clone, PartialEq)]
pub struct Texture {
    grid: Grid<Vec3>,
}

impl std::fmt::Debug for Texture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.grid;
        f.debug_struct("Texture")
            .field("width", &g.width())
            .field("height", &g.height())
            .field("texels", &g.texels())
            .finish()
    }
}

/// sRGB-encoded value in `[0, 1]` to linear.
#[must_use]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

/// Linear value to sRGB-encoded in `[0, 1]` (clamped).
#[must_use]
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 };
    if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

impl Texture {
    /// A texture from linear texels, row-major; `None` if the sizes disagree or a side is 0.
    #[must_use]
    pub fn new(width: u32, height: u32, texels: Vec<Vec3>) -> Option<Self> {
        Grid::new(width, height, texels).map(|grid| Self { grid })
    }

    /// A texture from sRGB8 pixels (`[r, g, b]` per texel), converted to linear.
    #[must_use]
    pub fn from_srgb8(width: u32, height: u32, pixels: &[[u8; 3]]) -> Option<Self> {
        let lut: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f32 / 255.0)).collect();
        let texels =
            pixels.iter().map(|p| Vec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize])).collect();
        Self::new(width, height, texels)
    }

    /// A 1x1 texture of one colour.
    #[must_use]
    pub fn constant(c: Vec3) -> Self {
        Self { grid: Grid::from_checked(1, 1, vec![c]) }
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.grid.width()
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.grid.height()
    }

    /// The texels, row-major.
    #[must_use]
    pub fn texels(&self) -> &[Vec3] {
        self.grid.texels()
    }

    /// Texel `(x, y)` with wrapping or clamping.
    #[inline]
    #[must_use]
    pub fn texel(&self, x: i64, y: i64, edges: EdgeMode) -> Vec3 {
        self.grid.at(x, y, edges)
    }

    /// Bilinear sample at `uv`.
    #[must_use]
    pub fn sample(&self, uv: Vec2, edges: EdgeMode) -> Vec3 {
        bilinear_vec3(&self.grid, uv, edges)
    }

    /// The next mip level by a 2x2 box filter (sides halve, never below 1; odd sides fold the
    /// last texel in with its neighbour).
    #[must_use]
    pub fn downsample(&self) -> Self {
        Self { grid: self.grid.downsample_box() }
    }

    /// This texture and its mip chain down to 1x1, each level the [`Texture::downsample`] of
    /// the one before.
    #[must_use]
    pub fn mip_chain(self) -> Vec<Self> {
        self.grid.mip_chain(Grid::downsample_box).into_iter().map(|grid| Self { grid }).collect()
    }
}

/// A tangent-space normal map (+Y up, pomkit's convention), unit vectors per texel.
#[derive(Clone, PartialEq)]
pub struct NormalMap {
    grid: Grid<Vec3>,
}

impl std::fmt::Debug for NormalMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.grid;
        f.debug_struct("NormalMap")
            .field("width", &g.width())
            .field("height", &g.height())
            .field("normals", &g.texels())
            .finish()
    }
}

impl NormalMap {
    /// A normal map from unit vectors, row-major; `None` if the sizes disagree or a side is 0.
    /// Vectors are renormalized; non-finite or zero ones become +Z.
    #[must_use]
    pub fn new(width: u32, height: u32, normals: Vec<Vec3>) -> Option<Self> {
        if width == 0 || height == 0 || normals.len() != width as usize * height as usize {
            return None;
        }
        let normals = normals.into_iter().map(|n| n.try_normalize().unwrap_or(Vec3::Z)).collect();
        Some(Self { grid: Grid::from_checked(width, height, normals) })
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.grid.width()
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.grid.height()
    }

    /// The normals, row-major.
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        self.grid.texels()
    }

    /// Bilinear sample at `uv`, renormalized (as a shader does after filtering).
    #[must_use]
    pub fn sample(&self, uv: Vec2, edges: EdgeMode) -> Vec3 {
        bilinear_vec3(&self.grid, uv, edges).try_normalize().unwrap_or(Vec3::Z)
    }
}

/// [`Grid::sample_bilinear`], except that a 1x1 grid (a material without an albedo map, the
/// last mip) gives its one texel as it is: glam's `lerp` of a texel with itself may round.
fn bilinear_vec3(grid: &Grid<Vec3>, uv: Vec2, edges: EdgeMode) -> Vec3 {
    if grid.width() == 1 && grid.height() == 1 {
        return grid.texels()[0];
    }
    grid.sample_bilinear(uv, edges)
}

/// A perspective camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position (world).
    pub eye: Vec3,
    /// The point looked at.
    pub target: Vec3,
    /// Up direction.
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
    /// Near clipping distance (> 0).
    pub near: f32,
    /// Far clipping distance (> near).
    pub far: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self { eye: Vec3::new(0.0, 2.0, 4.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0, near: 0.05, far: 100.0 }
    }
}

impl Camera {
    /// The view matrix (right-handed, looking down -Z).
    #[must_use]
    pub fn view(&self) -> Mat4 {
        let f = (self.target - self.eye).try_normalize().unwrap_or(Vec3::NEG_Z);
        let s = f.cross(self.up).try_normalize().unwrap_or_else(|| f.any_orthonormal_vector());
        let u = s.cross(f);
        Mat4::from_cols(
            Vec4::new(s.x, u.x, -f.x, 0.0),
            Vec4::new(s.y, u.y, -f.y, 0.0),
            Vec4::new(s.z, u.z, -f.z, 0.0),
            Vec4::new(-s.dot(self.eye), -u.dot(self.eye), f.dot(self.eye), 1.0),
        )
    }

    /// The projection for an aspect ratio (width / height), depth mapped to `[0, 1]` as wgpu
    /// expects.
    #[must_use]
    pub fn projection(&self, aspect: f32) -> Mat4 {
        let f = 1.0 / (0.5 * self.fov_y_deg.to_radians()).tan();
        let (n, fa) = (self.near, self.far);
        let r = fa / (n - fa);
        Mat4::from_cols(
            Vec4::new(f / aspect, 0.0, 0.0, 0.0),
            Vec4::new(0.0, f, 0.0, 0.0),
            Vec4::new(0.0, 0.0, r, -1.0),
            Vec4::new(0.0, 0.0, r * n, 0.0),
        )
    }
}

/// The narrowest vertical field of view, in degrees, that a renderer draws.
///
/// A vertex is placed in view space with f32's relative precision (about 6e-8 of its distance
/// from the eye); at 1e-3 degrees the whole view spans only about 2.9e5 such steps, so the
/// rounding already moves vertices by a few pixels in a large frame. Narrower views (1e-30
/// once covered no pixel at all) are refused.
pub const MIN_FOV_DEG: f32 = 1.0e-3;

/// The widest vertical field of view, in degrees. Closer to 180 the f32 tangent of the half
/// angle loses its sign and the picture collapses to a point.
pub const MAX_FOV_DEG: f32 = 179.0;

/// The largest magnitude of any world-space coordinate (the camera's eye and target, every
/// vertex of every object after its transform), so that the view and projection transforms
/// (which multiply coordinates by up to `1 / tan(MIN_FOV_DEG / 2)`, about 1.1e5, and square
/// distances) stay far from f32's overflow at 3.4e38.
pub const MAX_COORDINATE: f32 = 1.0e18;

/// How far from the eye, in multiples of the camera's near distance, a triangle crossing the
/// near plane may reach: 2^20.
///
/// Clipping computes where an edge crosses the near plane from its endpoints' f32 clip
/// coordinates, which carry rounding of about 6e-8 of their distance from the eye; beyond
/// 2^20 near distances that rounding exceeds 1/16 of the near distance itself, and the clipped
/// vertex lands visibly wrong or behind the eye (a plane of size 1e15 in front of the default
/// camera drew no pixel). Triangles entirely beyond the near plane are not limited by this.
pub const NEAR_RANGE: f32 = 1_048_576.0;

/// Why a scene cannot be drawn in f32 (see [`Camera::check`] and [`Scene::check_drawable`]).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DrawableError {
    /// A camera parameter is out of range; `field` is its scene-file key.
    #[error("camera: {field}: {message}")]
    Camera {
        /// `eye`, `target`, `up`, `fov`, `near` or `far`.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
    /// An object's geometry lies where f32 cannot draw it.
    #[error("object \"{object}\": {message}")]
    Object {
        /// The object's name.
        object: String,
        /// What is wrong.
        message: String,
    },
}

/// A number for a message: plain when ordinary, in scientific notation when huge or tiny (f32's
/// `Display` writes 1e30 with 31 digits).
#[must_use]
pub fn short_number(v: f32) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}

/// A vector for a message, its components as [`short_number`].
fn short_vec(v: Vec3) -> String {
    format!("[{}, {}, {}]", short_number(v.x), short_number(v.y), short_number(v.z))
}

impl Camera {
    /// Checks that the camera can be drawn with in f32: finite eye, target and up, eye and
    /// target with coordinates at most [`MAX_COORDINATE`] in magnitude and apart, fov from
    /// [`MIN_FOV_DEG`] to [`MAX_FOV_DEG`], `0 < near < far`, both finite.
    ///
    /// # Errors
    /// The first [`DrawableError::Camera`] found, naming the scene-file key.
    pub fn check(&self) -> Result<(), DrawableError> {
        let bad = |field: &'static str, message: String| Err(DrawableError::Camera { field, message });
        for (field, v) in [("eye", self.eye), ("target", self.target)] {
            if !(v.is_finite() && v.abs().max_element() <= MAX_COORDINATE) {
                return bad(
                    field,
                    format!(
                        "{field} is {}: every component must be finite and at most {MAX_COORDINATE:e} in magnitude",
                        short_vec(v)
                    ),
                );
            }
        }
        let view = self.target - self.eye;
        if view.length_squared() <= f32::MIN_POSITIVE {
            return bad("target", format!("target {} equals eye: the camera looks nowhere", self.target));
        }
        // An up vector parallel to the view is not refused here: `view` then picks another
        // (scene files refuse it, where it is a typo).
        if !self.up.is_finite() {
            return bad("up", format!("up is {}: every component must be finite", self.up));
        }
        if !(self.fov_y_deg.is_finite() && (MIN_FOV_DEG..=MAX_FOV_DEG).contains(&self.fov_y_deg)) {
            return bad(
                "fov",
                format!(
                    "fov is {}: it must be from {MIN_FOV_DEG:e} to {MAX_FOV_DEG} degrees (narrower views cannot place \
                     vertices to within a pixel in f32)",
                    short_number(self.fov_y_deg)
                ),
            );
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return bad("near", format!("near is {}: it must be a finite number greater than 0", self.near));
        }
        if !(self.far.is_finite() && self.far > self.near) {
            return bad("far", format!("far is {}: it must be finite and greater than near ({})", self.far, self.near));
        }
        Ok(())
    }
}

impl Scene {
    /// Checks that the camera and every object can be drawn in f32 ([`Camera::check`]; every
    /// world-space vertex finite with coordinates at most [`MAX_COORDINATE`]; every triangle
    /// that crosses the near plane within [`NEAR_RANGE`] near distances of the eye).
    ///
    /// # Errors
    /// The first [`DrawableError`] found.
    pub fn check_drawable(&self) -> Result<(), DrawableError> {
        self.camera.check()?;
        let view = self.camera.view();
        let near = self.camera.near;
        let reach = near * NEAR_RANGE;
        for obj in &self.objects {
            let bad = |message: String| Err(DrawableError::Object { object: obj.name.clone(), message });
            if !obj.transform.is_finite() {
                return bad("its transform is not finite".to_owned());
            }
            let mv = view * obj.transform;
            let mut eye_space = Vec::with_capacity(obj.mesh.positions.len());
            for &p in &obj.mesh.positions {
                let w = obj.transform.transform_point3(p);
                if !(w.is_finite() && w.abs().max_element() <= MAX_COORDINATE) {
                    return bad(format!(
                        "a vertex lies at {w}: size, scale and position must keep every coordinate finite and at \
                         most {MAX_COORDINATE:e} in magnitude"
                    ));
                }
                eye_space.push(mv.transform_point3(p));
            }
            for tri in obj.mesh.indices.chunks_exact(3) {
                let v = [0, 1, 2].map(|k| eye_space.get(tri[k] as usize).copied().unwrap_or(Vec3::ZERO));
                // View depth is -z; the triangle crosses the near plane when it has vertices on
                // both sides.
                let behind = v.iter().filter(|p| -p.z < near).count();
                if behind == 0 || behind == 3 {
                    continue;
                }
                let far = v.iter().map(|p| p.length()).fold(0.0f32, f32::max);
                if far > reach {
                    return bad(format!(
                        "it crosses the camera's near plane and reaches {far:.3e} from the eye, more than \
                         {NEAR_RANGE} (2^20) times near ({near}), where f32 clipping cannot place it: make the object \
                         smaller (size, scale) or raise the camera's near"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// A light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// A light at infinity.
    Directional {
        /// Direction *toward* the light (world; normalized on use).
        direction: Vec3,
        /// Linear colour.
        color: Vec3,
        /// Multiplier.
        intensity: f32,
    },
    /// A point light with inverse-square falloff.
    Point {
        /// Position (world).
        position: Vec3,
        /// Linear colour.
        color: Vec3,
        /// Multiplier (radiant intensity; illuminance at distance 1).
        intensity: f32,
    },
}

/// How a surface looks: textures, displacement technique and its parameters, shading.
#[derive(Clone, Debug)]
pub struct Material {
    /// Name (scene files refer to materials by it).
    pub name: String,
    /// Colour map, multiplied by `base_color`; white when absent.
    pub albedo: Option<Arc<Texture>>,
    /// Colour multiplier (linear).
    pub base_color: Vec3,
    /// Tangent-space normal map; baked from `height` (central differences, with the scale that
    /// matches `depth_scale`) when absent.
    pub normal_map: Option<Arc<NormalMap>>,
    /// Height field (depth inside pomkit). Without it the material is flat or normal-mapped.
    pub height: Option<Arc<HeightField>>,
    /// The displacement technique.
    pub technique: Technique,
    /// How far below the polygon, in UV units (tile widths), the deepest point of `height`
    /// lies: greater than 0 and at most [`crate::trace::MAX_DEPTH_SCALE`]. The renderers build
    /// the material's [`crate::trace::Surface`] for it (and the baked normals and displaced
    /// meshes).
    pub depth_scale: f32,
    /// Texture addressing of every map of the material: wrap tiles them, clamp repeats the
    /// edge texels.
    pub edges: EdgeMode,
    /// Technique options.
    pub trace: TraceParams,
    /// Self-shadowing.
    pub shadow: ShadowParams,
    /// LOD threshold in mip levels (Tatarchuk 2006: 4): beyond it, normal mapping only.
    pub lod_threshold: f32,
    /// Specular strength of the Blinn-Phong highlight.
    pub specular: f32,
    /// Blinn-Phong exponent.
    pub shininess: f32,
    /// Write the displaced depth to the depth buffer, so that displaced surfaces intersect
    /// other geometry where the real surface would.
    pub pixel_depth_offset: bool,
    /// Silhouettes: trace under the curved surface the mesh's normals describe (per-vertex
    /// curvature, [`crate::silhouette`]) and discard pixels whose ray leaves the relief, or
    /// leaves the unit UV square with clamped edges. Off by default (it then costs nothing).
    pub silhouette: bool,
    /// The cones the `cone` technique steps on, for example a baked cone map (`pomkit bake
    /// cone`, `--relaxed` for relaxed cone stepping) of `height` with the material's edge mode.
    /// `None` (the default): conservative cones built from `height` when first needed
    /// ([`crate::cone::cached`]). Cones of another size are ignored (the built ones are used).
    pub cones: Option<Arc<crate::cone::ConeMap>>,
}

/// The material defaults that are not trace or shadow parameters, from the parameter table
/// (evaluated when building).
mod defaults {
    use crate::table as p;
    pub const BASE_COLOR: [f32; 3] = p::BASE_COLOR.default.color();
    pub const DEPTH_SCALE: f32 = p::DEPTH_SCALE.default.f32();
    pub const LOD_THRESHOLD: f32 = p::LOD_THRESHOLD.default.f32();
    pub const SPECULAR: f32 = p::SPECULAR.default.f32();
    pub const SHININESS: f32 = p::SHININESS.default.f32();
    pub const PIXEL_DEPTH_OFFSET: bool = p::PIXEL_DEPTH_OFFSET.default.bool();
    pub const SILHOUETTE: bool = p::SILHOUETTE.default.bool();
}

impl Default for Material {
    /// The defaults of the parameter table ([`crate::params`]).
    fn default() -> Self {
        use defaults as p;
        Self {
            name: "default".to_owned(),
            albedo: None,
            base_color: Vec3::from_array(p::BASE_COLOR),
            normal_map: None,
            height: None,
            technique: Technique::Exact,
            depth_scale: p::DEPTH_SCALE,
            edges: EdgeMode::Wrap,
            trace: TraceParams::default(),
            shadow: ShadowParams::default(),
            lod_threshold: p::LOD_THRESHOLD,
            specular: p::SPECULAR,
            shininess: p::SHININESS,
            pixel_depth_offset: p::PIXEL_DEPTH_OFFSET,
            silhouette: p::SILHOUETTE,
            cones: None,
        }
    }
}

impl Material {
    /// The cones the `cone` technique steps on for this material: its own ([`Material::cones`])
    /// if they are its height map's size, else the height map's conservative cones, built once
    /// per height field ([`crate::cone::cached`], on every core). `None` without a height map.
    #[must_use]
    pub fn cones_to_trace(&self) -> Option<Arc<crate::cone::ConeMap>> {
        let field = self.height.as_ref()?;
        let own = self.cones.as_ref().filter(|c| c.check_size(field.width(), field.height()).is_ok());
        Some(own.cloned().unwrap_or_else(|| crate::cone::cached(field, self.edges)))
    }
}

/// A mesh placed in the world with a material.
#[derive(Clone, Debug)]
pub struct Object {
    /// Name, for messages.
    pub name: String,
    /// The mesh (object space).
    pub mesh: Arc<Mesh>,
    /// Index into [`Scene::materials`].
    pub material: usize,
    /// Object-to-world transform.
    pub transform: Mat4,
}

/// Everything a renderer needs for one picture.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The camera.
    pub camera: Camera,
    /// The lights.
    pub lights: Vec<Light>,
    /// Materials, referred to by index.
    pub materials: Vec<Material>,
    /// Objects.
    pub objects: Vec<Object>,
    /// Ambient light (linear colour), multiplied by the albedo.
    pub ambient: Vec3,
    /// Background colour (linear).
    pub background: Vec3,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_maps_near_and_far_to_zero_and_one_and_looks_at_the_target() {
        let cam = Camera { eye: Vec3::new(1.0, 2.0, 3.0), target: Vec3::new(0.0, 0.5, 0.0), ..Camera::default() };
        let vp = cam.projection(1.5) * cam.view();
        let c = vp * cam.target.extend(1.0);
        assert!((c.x / c.w).abs() < 1e-5 && (c.y / c.w).abs() < 1e-5, "target at the centre");
        let dir = (cam.target - cam.eye).normalize();
        for (dist, expect) in [(cam.near, 0.0), (cam.far, 1.0)] {
            let c = vp * (cam.eye + dir * dist).extend(1.0);
            assert!((c.z / c.w - expect).abs() < 1e-4, "{dist}: {}", c.z / c.w);
        }
        // Up in the world is up on the screen (positive NDC y).
        let c = vp * (cam.target + Vec3::Y * 0.1).extend(1.0);
        assert!(c.y / c.w > 0.0);
    }

    #[test]
    fn textures_and_normal_maps_filter_between_texel_centres() {
        let t = Texture::new(2, 1, vec![Vec3::ZERO, Vec3::ONE]).unwrap();
        assert!((t.sample(Vec2::new(0.5, 0.5), EdgeMode::Clamp) - Vec3::splat(0.5)).length() < 1e-6);
        assert_eq!(t.sample(Vec2::new(0.25, 0.5), EdgeMode::Clamp), Vec3::ZERO);
        // Wrapping: halfway between the last and the first texel.
        assert!((t.sample(Vec2::new(0.0, 0.5), EdgeMode::Wrap) - Vec3::splat(0.5)).length() < 1e-6);
        assert_eq!(t.downsample().texels(), &[Vec3::splat(0.5)]);
        assert!(Texture::new(2, 2, vec![Vec3::ZERO; 3]).is_none());
        let n = NormalMap::new(2, 1, vec![Vec3::X, Vec3::Y]).unwrap();
        let m = n.sample(Vec2::new(0.5, 0.5), EdgeMode::Clamp);
        assert!((m - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6, "renormalized: {m}");
        assert_eq!(NormalMap::new(1, 1, vec![Vec3::ZERO]).unwrap().normals(), &[Vec3::Z]);
    }

    /// Texture and normal map sampling and the texture mip chain as they were written before
    /// [`Grid`] held them, to compare bit for bit.
    mod before {
        use super::*;

        pub fn bilinear_vec3(texels: &[Vec3], width: u32, height: u32, uv: Vec2, edges: EdgeMode) -> Vec3 {
            if width == 1 && height == 1 {
                return texels[0];
            }
            let t = uv * Vec2::new(width as f32, height as f32) - 0.5;
            let t = if t.is_finite() { t } else { Vec2::ZERO };
            let f = Vec2::new(crate::heightfield::floor(t.x), crate::heightfield::floor(t.y));
            let (fx, fy) = (t.x - f.x, t.y - f.y);
            let (x0, y0) = (f.x as i64, f.y as i64);
            if x0 >= 0 && y0 >= 0 && x0 < i64::from(width) - 1 && y0 < i64::from(height) - 1 {
                let at = y0 as usize * width as usize + x0 as usize;
                let below = at + width as usize;
                let top = texels[at].lerp(texels[at + 1], fx);
                let bottom = texels[below].lerp(texels[below + 1], fx);
                return top.lerp(bottom, fy);
            }
            let at = |x: i64, y: i64| {
                let xi = edges.resolve(x, width) as usize;
                let yi = edges.resolve(y, height) as usize;
                texels[yi * width as usize + xi]
            };
            let (x1, y1) = (x0.saturating_add(1), y0.saturating_add(1));
            let top = at(x0, y0).lerp(at(x1, y0), fx);
            let bottom = at(x0, y1).lerp(at(x1, y1), fx);
            top.lerp(bottom, fy)
        }

        pub fn downsample(width: u32, height: u32, texels: &[Vec3]) -> (u32, u32, Vec<Vec3>) {
            let (nw, nh) = ((width / 2).max(1), (height / 2).max(1));
            let mut out = Vec::with_capacity(nw as usize * nh as usize);
            for y in 0..nh {
                for x in 0..nw {
                    let (x0, y0) = (x * width / nw, y * height / nh);
                    let (x1, y1) = (((x + 1) * width / nw).max(x0 + 1), ((y + 1) * height / nh).max(y0 + 1));
                    let mut acc = Vec3::ZERO;
                    for yy in y0..y1 {
                        for xx in x0..x1 {
                            acc += texels[(yy * width + xx) as usize];
                        }
                    }
                    out.push(acc / ((x1 - x0) * (y1 - y0)) as f32);
                }
            }
            (nw, nh, out)
        }

        /// pomkit-cpu's albedo chain: the texture, then downsampled until 1x1.
        pub fn mip_chain(width: u32, height: u32, texels: Vec<Vec3>) -> Vec<(u32, u32, Vec<Vec3>)> {
            let mut chain = vec![(width, height, texels)];
            while let Some(last) = chain.last().filter(|t| t.0 > 1 || t.1 > 1) {
                let next = downsample(last.0, last.1, &last.2);
                chain.push(next);
            }
            chain
        }
    }

    fn irregular_vec3(w: u32, h: u32) -> Vec<Vec3> {
        (0..w * h)
            .map(|k| {
                let r = k.wrapping_mul(2_654_435_761).rotate_left(9);
                Vec3::new((r % 1009) as f32 / 1008.0, (r % 997) as f32 / 331.0 - 1.0, (r % 101) as f32 / 7.0 - 3.0)
            })
            .collect()
    }

    #[test]
    fn textures_and_normal_maps_match_the_former_per_type_code_bit_for_bit() {
        let bits = |v: &[Vec3]| v.iter().flat_map(|c| c.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        for (w, h) in [(1, 1), (1, 7), (6, 1), (2, 2), (7, 5), (16, 16), (33, 12), (67, 45)] {
            let texels = irregular_vec3(w, h);
            let t = Texture::new(w, h, texels.clone()).unwrap();
            let n = NormalMap::new(w, h, texels.clone()).unwrap();
            for edges in EdgeMode::ALL {
                for k in 0..1000u32 {
                    let u = (k.wrapping_mul(7919) % 4001) as f32 / 1000.0 - 1.5;
                    let v = (k.wrapping_mul(104_729) % 3001) as f32 / 1000.0 - 1.0;
                    let uv = if k % 97 == 0 { Vec2::new(u, v * 1e7) } else { Vec2::new(u, v) };
                    let want = before::bilinear_vec3(&texels, w, h, uv, edges);
                    assert_eq!(bits(&[t.sample(uv, edges)]), bits(&[want]), "{w}x{h} {edges:?} {uv}");
                    let want = before::bilinear_vec3(n.normals(), w, h, uv, edges).try_normalize().unwrap_or(Vec3::Z);
                    assert_eq!(bits(&[n.sample(uv, edges)]), bits(&[want]), "{w}x{h} {edges:?} {uv}");
                }
            }
            let (dw, dh, d) = before::downsample(w, h, &texels);
            let down = t.downsample();
            assert_eq!((down.width(), down.height(), bits(down.texels())), (dw, dh, bits(&d)), "{w}x{h}");
            let chain = t.mip_chain();
            let want = before::mip_chain(w, h, texels);
            assert_eq!(chain.len(), want.len(), "{w}x{h}");
            for (k, (got, want)) in chain.iter().zip(&want).enumerate() {
                assert_eq!((got.width(), got.height(), bits(got.texels())), (want.0, want.1, bits(&want.2)), "{k}");
            }
        }
    }

    fn plane_scene(camera: Camera, size: f32) -> Scene {
        let mesh = Arc::new(Mesh::plane(Vec2::splat(size), 1));
        Scene {
            camera,
            lights: vec![],
            materials: vec![Material::default()],
            objects: vec![Object { name: "floor".into(), mesh, material: 0, transform: Mat4::IDENTITY }],
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        }
    }

    #[test]
    fn what_f32_cannot_draw_is_refused_naming_the_key() {
        let field = |r: Result<(), DrawableError>| match r {
            Err(DrawableError::Camera { field, .. }) => field.to_owned(),
            Err(DrawableError::Object { object, .. }) => format!("object {object}"),
            Ok(()) => "ok".to_owned(),
        };
        let d = Camera::default();
        assert_eq!(field(plane_scene(d, 2.0).check_drawable()), "ok");
        for fov in [1e-30, 9e-4, 179.5, 180.0, f32::NAN] {
            assert_eq!(field(Camera { fov_y_deg: fov, ..d }.check()), "fov", "{fov}");
        }
        assert_eq!(field(Camera { fov_y_deg: MIN_FOV_DEG, ..d }.check()), "ok");
        // An eye at 1e30 is the eye's fault, not the up vector's.
        assert_eq!(field(Camera { eye: Vec3::new(1e30, 2.0, 4.0), ..d }.check()), "eye");
        assert_eq!(field(Camera { target: Vec3::splat(f32::INFINITY), ..d }.check()), "target");
        // Crossing the near plane: 1e15 and 1e8 reach too far for near 0.05; 1e8 is fine with
        // near 100.
        assert_eq!(field(plane_scene(d, 1e15).check_drawable()), "object floor");
        assert_eq!(field(plane_scene(d, 1e8).check_drawable()), "object floor");
        let far_cam = Camera { eye: Vec3::new(0.0, 300.0, 600.0), near: 100.0, far: 1e9, ..d };
        assert_eq!(field(plane_scene(far_cam, 1e8).check_drawable()), "ok");
        // Wholly beyond the near plane (looking straight down), size is not limited by near.
        let down = Camera { eye: Vec3::new(0.0, 10.0, 0.0), up: Vec3::Z, ..d };
        assert_eq!(field(plane_scene(down, 1e12).check_drawable()), "ok");
        // Beyond 1e18 (a plane of 1e15, the largest shape, scaled by 1e5).
        let mut huge = plane_scene(down, 1e15);
        huge.objects[0].transform = Mat4::from_scale(Vec3::splat(1e5));
        assert_eq!(field(huge.check_drawable()), "object floor");
    }

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }
}
