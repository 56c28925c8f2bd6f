//! Scenes: camera, lights, materials and objects, shared by the CPU and GPU renderers.
//!
//! Pure data: loading a scene file is `pomkit-io`'s job, drawing it a renderer's. Colours are
//! linear RGB; textures loaded from sRGB files are converted on load.

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::heightfield::{EdgeMode, HeightField};
use crate::mesh::Mesh;
use crate::shadow::ShadowParams;
use crate::trace::{Technique, TraceParams};

/// An RGB texture in linear colour, sampled bilinearly over texel centres like a height field.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    width: u32,
    height: u32,
    texels: Vec<Vec3>,
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
        (width > 0 && height > 0 && texels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            texels,
        })
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
        Self { width: 1, height: 1, texels: vec![c] }
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The texels, row-major.
    #[must_use]
    pub fn texels(&self) -> &[Vec3] {
        &self.texels
    }

    /// Texel `(x, y)` with wrapping or clamping.
    #[inline]
    #[must_use]
    pub fn texel(&self, x: i64, y: i64, edges: EdgeMode) -> Vec3 {
        let xi = edges.resolve(x, self.width) as usize;
        let yi = edges.resolve(y, self.height) as usize;
        self.texels[yi * self.width as usize + xi]
    }

    /// Bilinear sample at `uv`.
    #[must_use]
    pub fn sample(&self, uv: Vec2, edges: EdgeMode) -> Vec3 {
        bilinear_vec3(&self.texels, self.width, self.height, uv, edges)
    }

    /// The next mip level by a 2x2 box filter (sides halve, never below 1; odd sides fold the
    /// last texel in with its neighbour).
    #[must_use]
    pub fn downsample(&self) -> Self {
        let (nw, nh) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let mut texels = Vec::with_capacity(nw as usize * nh as usize);
        for y in 0..nh {
            for x in 0..nw {
                let (x0, y0) = (x * self.width / nw, y * self.height / nh);
                let (x1, y1) = (((x + 1) * self.width / nw).max(x0 + 1), ((y + 1) * self.height / nh).max(y0 + 1));
                let mut acc = Vec3::ZERO;
                for yy in y0..y1 {
                    for xx in x0..x1 {
                        acc += self.texels[(yy * self.width + xx) as usize];
                    }
                }
                texels.push(acc / ((x1 - x0) * (y1 - y0)) as f32);
            }
        }
        Self { width: nw, height: nh, texels }
    }
}

/// A tangent-space normal map (+Y up, pomkit's convention), unit vectors per texel.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalMap {
    width: u32,
    height: u32,
    normals: Vec<Vec3>,
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
        Some(Self { width, height, normals })
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The normals, row-major.
    #[must_use]
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }

    /// Bilinear sample at `uv`, renormalized (as a shader does after filtering).
    #[must_use]
    pub fn sample(&self, uv: Vec2, edges: EdgeMode) -> Vec3 {
        bilinear_vec3(&self.normals, self.width, self.height, uv, edges).try_normalize().unwrap_or(Vec3::Z)
    }
}

/// Bilinear interpolation of a row-major grid of vectors over texel centres, as a GPU filters.
fn bilinear_vec3(texels: &[Vec3], width: u32, height: u32, uv: Vec2, edges: EdgeMode) -> Vec3 {
    let t = uv * Vec2::new(width as f32, height as f32) - 0.5;
    let t = if t.is_finite() { t } else { Vec2::ZERO };
    let f = t.floor();
    let (fx, fy) = (t.x - f.x, t.y - f.y);
    let (x0, y0) = (f.x as i64, f.y as i64);
    let at = |x: i64, y: i64| {
        let xi = edges.resolve(x, width) as usize;
        let yi = edges.resolve(y, height) as usize;
        texels[yi * width as usize + xi]
    };
    let top = at(x0, y0).lerp(at(x0 + 1, y0), fx);
    let bottom = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
    top.lerp(bottom, fy)
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
    /// Technique and its parameters; `trace.depth_scale` is the material's depth scale and
    /// `trace.edges` its texture addressing.
    pub technique: Technique,
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
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".to_owned(),
            albedo: None,
            base_color: Vec3::splat(0.8),
            normal_map: None,
            height: None,
            technique: Technique::Pom,
            trace: TraceParams::default(),
            shadow: ShadowParams::default(),
            lod_threshold: 4.0,
            specular: 0.25,
            shininess: 32.0,
            pixel_depth_offset: true,
        }
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

    #[test]
    fn srgb_round_trips() {
        for i in 0..=255 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }
}
