//! What every renderer shares: render options, outputs, AOVs, the sample resolve and the tone
//! curve. `pomkit-cpu` and `pomkit-gpu` take the same [`RenderOptions`] and return the same
//! [`RenderOutput`], so their pictures can be compared pixel for pixel.

use glam::{Vec2, Vec3};

use crate::memory::{MAX_SIZE, MemoryError, try_vec};
use crate::scene::Scene;
use crate::trace::Technique;

/// Which geometry and technique the renderer uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Each material's own technique (or the override).
    Material,
    /// Every material with this technique.
    Technique(Technique),
    /// The ground truth: height-mapped meshes tessellated and displaced for real, shaded with
    /// normal mapping at the true surface point and the material's shadows.
    Displaced,
}

/// The default [`RenderOptions::displaced_tolerance`]: an eighth of a sample.
pub const DISPLACED_TOLERANCE: f32 = 0.125;

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// Supersampling factor per axis (1 = off): renders k x k samples per pixel and averages.
    pub supersample: u32,
    /// Technique selection.
    pub mode: Mode,
    /// Also produce the AOVs (hit UV, depth, shadow, fetches, LOD).
    pub aovs: bool,
    /// `displaced` mode: largest triangle edge in texels of the height map (1 = the height
    /// map's resolution, the ground truth of docs/ACCURACY.md).
    pub displaced_edge_texels: f32,
    /// `displaced` mode on the CPU renderer: how far (in samples) the surface may lie on screen
    /// from that of the full subdivision where the renderer coarsens it
    /// ([`DisplacementView`](crate::mesh::DisplacementView)); 0 keeps the full subdivision.
    pub displaced_tolerance: f32,
    /// Debug view of the LOD system (Tatarchuk 2006 figure 12): tint pixels green where the
    /// full technique runs, red where only normal mapping does, blended across the fade.
    pub lod_tint: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width: 1280,
            height: 720,
            supersample: 1,
            mode: Mode::Material,
            aovs: false,
            displaced_edge_texels: 1.0,
            displaced_tolerance: DISPLACED_TOLERANCE,
            lod_tint: false,
        }
    }
}

/// Per-pixel outputs besides colour (each `width * height`, row-major).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Aovs {
    /// Displaced texture coordinate (0 where no surface).
    pub uv: Vec<Vec2>,
    /// Hit depth in `[0, 1]` below the polygon.
    pub depth: Vec<f32>,
    /// Light visibility of the first light (1 lit).
    pub shadow: Vec<f32>,
    /// Height fetches (trace + shadows).
    pub fetches: Vec<f32>,
    /// Mip level of the height map.
    pub lod: Vec<f32>,
}

/// What `CpuRenderer::render` (pomkit-cpu) returns.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, row-major.
    pub color: Vec<Vec3>,
    /// AOVs when asked for.
    pub aovs: Option<Aovs>,
    /// Pixels covered by geometry.
    pub covered: usize,
}

impl RenderOutput {
    /// sRGB8 pixels (`[r, g, b]` per pixel), with a gentle filmic tone curve applied first.
    #[must_use]
    pub fn to_srgb8(&self) -> Vec<[u8; 3]> {
        self.color.iter().map(|&c| srgb8(c)).collect()
    }
}

/// One pixel of [`RenderOutput::to_srgb8`]: linear colour through [`tone`], then sRGB-encoded
/// to 8 bits.
#[must_use]
pub fn srgb8(c: Vec3) -> [u8; 3] {
    let t = tone(c);
    [t.x, t.y, t.z].map(|v| (crate::scene::linear_to_srgb(v) * 255.0 + 0.5) as u8)
}

/// The tone curve both renderers apply before sRGB encoding. A soft shoulder so bright highlights do not clip hard: `x / (1 + x / 4)` per channel after
/// an exposure of 1 (identity for dark values).
#[must_use]
pub fn tone(c: Vec3) -> Vec3 {
    let c = if c.is_finite() { c.max(Vec3::ZERO) } else { Vec3::ZERO };
    c / (Vec3::ONE + c / 4.0)
}

impl Mode {
    /// The technique a material whose own technique is `own` draws with in this mode
    /// (`Displaced` shades its tessellated geometry with normal mapping).
    #[must_use]
    pub fn technique(self, own: Technique) -> Technique {
        match self {
            Mode::Technique(t) => t,
            Mode::Displaced => Technique::Normal,
            Mode::Material => own,
        }
    }
}

/// The checks every renderer makes before drawing, in this order: the image size (1 to
/// [`MAX_SIZE`] pixels a side), every object's material index, every material's trace
/// parameters, and that the camera and geometry can be drawn in f32
/// ([`Scene::check_drawable`]). (The memory a frame needs is checked by each renderer, which knows its buffers.)
///
/// # Errors
/// The first [`RenderError`] found.
pub fn validate(scene: &Scene, opts: &RenderOptions) -> Result<(), RenderError> {
    let (w, h) = (opts.width, opts.height);
    if w == 0 || h == 0 || w > MAX_SIZE || h > MAX_SIZE {
        return Err(RenderError::Size { width: w, height: h });
    }
    for obj in &scene.objects {
        if obj.material >= scene.materials.len() {
            return Err(RenderError::Material {
                object: obj.name.clone(),
                index: obj.material,
                count: scene.materials.len(),
            });
        }
    }
    for m in &scene.materials {
        crate::trace::check_depth_scale(m.depth_scale)
            .and_then(|()| m.trace.validate())
            .map_err(|e| RenderError::Params { material: m.name.clone(), reason: e.to_string() })?;
    }
    scene.check_drawable()?;
    Ok(())
}

/// Why a render could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RenderError {
    /// Width or height is 0 or too large.
    #[error("image size {width}x{height} is not allowed: each side must be 1 to {MAX_SIZE} pixels")]
    Size {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// An object names a material that does not exist.
    #[error("object \"{object}\" uses material {index}, but the scene has {count} materials")]
    Material {
        /// The object.
        object: String,
        /// Its material index.
        index: usize,
        /// Materials in the scene.
        count: usize,
    },
    /// The camera or an object lies where f32 cannot draw it
    /// ([`Scene::check_drawable`](crate::scene::Scene::check_drawable)).
    #[error(transparent)]
    Drawable(#[from] crate::scene::DrawableError),
    /// A material's trace parameters are invalid.
    #[error("material \"{material}\": {reason}")]
    Params {
        /// The material.
        material: String,
        /// What is wrong.
        reason: String,
    },
    /// The frame will not fit in the memory there is (see [`crate::memory`]).
    #[error(transparent)]
    Memory(#[from] MemoryError),
}

/// A shaded sample: colour, depth and AOV values.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sample {
    /// Linear colour.
    pub color: Vec3,
    /// Depth-buffer value (smaller is nearer).
    pub z: f32,
    /// Displaced UV.
    pub uv: Vec2,
    /// Hit depth below the polygon.
    pub depth: f32,
    /// Visibility of the first light.
    pub shadow: f32,
    /// Height fetches.
    pub fetches: f32,
    /// Mip level of the height map.
    pub lod: f32,
}

/// Averages `ss x ss` supersamples per pixel (samples are `(w ss) x (h ss)`, row-major), fills
/// uncovered samples with `background`, and collects the AOVs when `aovs`.
///
/// # Errors
/// [`MemoryError::Allocation`] when the output buffers cannot be allocated.
pub fn resolve(
    samples: &[Option<Sample>],
    w: u32,
    h: u32,
    ss: u32,
    background: Vec3,
    aovs: bool,
) -> Result<RenderOutput, MemoryError> {
    let (mut color, mut a) = output_buffers(w, h, aovs)?;
    let rows =
        AovRows { uv: &mut a.uv, depth: &mut a.depth, shadow: &mut a.shadow, fetches: &mut a.fetches, lod: &mut a.lod };
    let covered = resolve_rows(samples, w, ss, background, &mut color, aovs.then_some(rows));
    Ok(RenderOutput { width: w, height: h, color, aovs: aovs.then_some(a), covered })
}

/// Rows of the AOV buffers that [`resolve_rows`] fills.
#[derive(Debug)]
pub struct AovRows<'a> {
    /// Rows of [`Aovs::uv`].
    pub uv: &'a mut [Vec2],
    /// Rows of [`Aovs::depth`].
    pub depth: &'a mut [f32],
    /// Rows of [`Aovs::shadow`].
    pub shadow: &'a mut [f32],
    /// Rows of [`Aovs::fetches`].
    pub fetches: &'a mut [f32],
    /// Rows of [`Aovs::lod`].
    pub lod: &'a mut [f32],
}

/// [`resolve`] for a band of `color.len() / w` whole pixel rows, whose samples (`ss` sample rows
/// per pixel row, `w ss` samples each) are `samples`: writes the colour (and the AOVs, when
/// given) of those rows and returns how many of their pixels are covered.
pub fn resolve_rows(
    samples: &[Option<Sample>],
    w: u32,
    ss: u32,
    background: Vec3,
    color: &mut [Vec3],
    mut aovs: Option<AovRows<'_>>,
) -> usize {
    let sw = (w * ss) as usize;
    let (w, ss) = (w as usize, ss as usize);
    let n = (ss * ss) as f32;
    let h = color.len() / w.max(1);
    let mut covered = 0;
    if ss == 1 && aovs.is_none() {
        // One sample per pixel: the sum below of its colour or the background, `0 + c`, and
        // `/ 1` leaves it as it is.
        let background = Vec3::ZERO + background;
        for (c, s) in color.iter_mut().zip(samples) {
            *c = match s {
                Some(s) => {
                    covered += 1;
                    Vec3::ZERO + if s.color.is_finite() { s.color } else { Vec3::ZERO }
                }
                None => background,
            };
        }
        return covered;
    }
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut acc = Vec3::ZERO;
            let mut any = false;
            for sy in 0..ss {
                for sx in 0..ss {
                    match samples[(y * ss + sy) * sw + x * ss + sx] {
                        Some(s) => {
                            any = true;
                            acc += if s.color.is_finite() { s.color } else { Vec3::ZERO };
                            if let Some(a) = aovs.as_mut() {
                                a.uv[i] += s.uv / n;
                                a.depth[i] += s.depth / n;
                                a.shadow[i] += s.shadow / n;
                                a.fetches[i] += s.fetches / n;
                                a.lod[i] += s.lod / n;
                            }
                        }
                        None => acc += background,
                    }
                }
            }
            covered += usize::from(any);
            color[i] = acc / n;
        }
    }
    covered
}

/// The colour buffer and (when `aovs`) the AOV buffers of a `w x h` frame, allocated fallibly.
///
/// # Errors
/// [`MemoryError::Allocation`] naming the buffer.
pub fn output_buffers(w: u32, h: u32, aovs: bool) -> Result<(Vec<Vec3>, Aovs), MemoryError> {
    let n = w as usize * h as usize;
    let fail = |what: &'static str, bytes: usize| {
        move |e: std::collections::TryReserveError| MemoryError::Allocation {
            what: format!("the {w}x{h} frame's {what}"),
            bytes: bytes as u64,
            reason: e.to_string(),
            advice: "use a smaller --size or fewer AOVs".into(),
        }
    };
    let color = try_vec(Vec3::ZERO, n).map_err(fail("colour buffer", n * 12))?;
    let mut a = Aovs::default();
    if aovs {
        a.uv = try_vec(Vec2::ZERO, n).map_err(fail("uv AOV", n * 8))?;
        a.depth = try_vec(0.0, n).map_err(fail("depth AOV", n * 4))?;
        a.shadow = try_vec(0.0, n).map_err(fail("shadow AOV", n * 4))?;
        a.fetches = try_vec(0.0, n).map_err(fail("fetches AOV", n * 4))?;
        a.lod = try_vec(0.0, n).map_err(fail("lod AOV", n * 4))?;
    }
    Ok((color, a))
}

/// Bytes of a `w x h` frame's [`RenderOutput`]: colour and, when `aovs`, every AOV.
#[must_use]
pub fn output_bytes(w: u32, h: u32, aovs: bool) -> u64 {
    let px = u64::from(w) * u64::from(h);
    let per = std::mem::size_of::<Vec3>() + if aovs { std::mem::size_of::<Vec2>() + 4 * 4 } else { 0 };
    px * per as u64
}
