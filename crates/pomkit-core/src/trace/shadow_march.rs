//! A shadow ray's march and its answer: what [`crate::shadow::shadow`] returns, and the `hard` or
//! `soft` march that [`crate::shadow::shadow_start`] sets up, run one ray at a time here or eight
//! at once by [`super::packet::shadow_marches`]. Published as `pomkit_core::shadow::{Shadow,
//! ShadowMarch}`; they live beside the tracer so that the packets do not import the shadows.

use glam::Vec2;

use super::Surface;

/// Visibility of the light from a displaced point, and the fetches spent finding it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shadow {
    /// 1 lit, 0 fully shadowed.
    pub visibility: f32,
    /// Height fetches made.
    pub fetches: u32,
}

/// A `hard` or `soft` shadow ray, ready to march: samples `i = 1 .. n - 1` at the climbed depths
/// `t_i = depth * i / n`, at UV `uv + s * t_i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowMarch {
    /// The receiver's UV, in its own tile where the edges wrap.
    pub uv: Vec2,
    /// The receiver's depth, in `(0, 1]`, lifted onto the surface at mip `lod`.
    pub depth: f32,
    /// UV offset per unit of depth climbed toward the light.
    pub s: Vec2,
    /// Samples plus one (the adaptive count of the light's angle).
    pub n: u32,
    /// `soft` (a penumbra estimate) rather than `hard`.
    pub soft: bool,
    /// The light's tangent of the angle from the normal (`soft`).
    pub tan_theta: f32,
    /// The light's elevation above the tangent plane, radians (`soft`).
    pub light_elevation: f32,
    /// The light's angular radius, radians (`soft`).
    pub rho: f32,
    /// The mip level sampled.
    pub lod: f32,
}

impl ShadowMarch {
    /// The climbed depth of sample `i`.
    #[inline]
    #[must_use]
    pub fn climbed(&self, i: u32) -> f32 {
        self.depth * i as f32 / self.n as f32
    }

    /// Marches the ray on `surface`, one sample at a time. The fetches count the receiver's
    /// lift made by [`shadow_start`](crate::shadow::shadow_start).
    #[must_use]
    pub fn run(&self, surface: &Surface) -> Shadow {
        let mut slope = f32::NEG_INFINITY;
        let mut fetches = 1;
        for i in 1..self.n {
            let t = self.climbed(i);
            let d = surface.depth(self.uv + self.s * t, self.lod);
            fetches += 1;
            if self.soft {
                slope = slope.max(self.slope(d, t));
            } else if self.blocks(d, t) {
                return Shadow { visibility: 0.0, fetches };
            }
        }
        let visibility = if self.soft { self.soft_visibility(slope) } else { 1.0 };
        Shadow { visibility, fetches }
    }

    /// `hard`: whether a profile sample of depth `d` at climbed depth `t` rises above the ray.
    #[inline]
    #[must_use]
    pub fn blocks(&self, d: f32, t: f32) -> bool {
        d < self.depth - t - 1e-5
    }

    /// `soft`: the rise of a profile sample of depth `d` above the receiver per unit climbed at
    /// climbed depth `t` (its elevation seen from the receiver is `atan2(slope, tan_theta)`).
    #[inline]
    #[must_use]
    pub fn slope(&self, d: f32, t: f32) -> f32 {
        (self.depth - d) / t
    }

    /// `soft`: the visibility under the steepest sample's `slope` ([`ShadowMarch::slope`];
    /// `-inf` for no sample).
    ///
    /// Each sample's elevation as seen from the receiver, `atan2(depth - d, t * tan_theta)`,
    /// is set against the light's: nearer blockers subtend more, so they darken more (Tatarchuk
    /// 2006's distance weighting), and the darkest sample wins. The visibility
    /// `clamp(0.5 - (elevation - light_elevation) / (2 rho), 0, 1)` falls as the elevation
    /// rises, and the elevation rises with the slope `(depth - d) / t` (for `t > 0` and
    /// `tan_theta >= 0`), so the darkest sample is the steepest: one arctangent per ray.
    #[must_use]
    pub fn soft_visibility(&self, slope: f32) -> f32 {
        if slope == f32::NEG_INFINITY {
            return 1.0;
        }
        let elevation = slope.atan2(self.tan_theta);
        (0.5 - (elevation - self.light_elevation) / (2.0 * self.rho)).clamp(0.0, 1.0)
    }
}
