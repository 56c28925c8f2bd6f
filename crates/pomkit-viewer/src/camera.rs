//! The orbit camera of the 3D view: drag to orbit about the target, shift-drag to pan, scroll to
//! zoom, and the drag that moves the light. Pure functions of the camera the scene file holds,
//! so they are tested without a window.

use pomkit_core::glam::{Vec2, Vec3};

/// Radians of orbit per pixel dragged.
const ORBIT_PER_PX: f32 = 0.008;
/// The steepest pitch, just short of the poles (where yaw is undefined).
const MAX_PITCH: f32 = 1.54;
/// The nearest and farthest the eye may zoom to from the target.
const ZOOM_RANGE: (f32, f32) = (0.05, 200.0);

/// A camera looking from `eye` at `target` with a vertical field of view of `fov_deg` degrees
/// (the scene file's `camera.fov`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orbit {
    /// The eye.
    pub eye: Vec3,
    /// The point looked at, which orbiting turns about.
    pub target: Vec3,
    /// Vertical field of view in degrees.
    pub fov_deg: f32,
}

impl Orbit {
    /// Turns the eye about the target by a drag of `delta` pixels: right turns the view left
    /// (yaw about +Y), down raises the eye; the distance stays and the pitch stops short of the
    /// poles.
    pub fn orbit(&mut self, delta: Vec2) {
        let offset = self.eye - self.target;
        let r = offset.length().max(1e-3);
        let yaw = offset.x.atan2(offset.z) - delta.x * ORBIT_PER_PX;
        let pitch = ((offset.y / r).clamp(-1.0, 1.0).asin() + delta.y * ORBIT_PER_PX).clamp(-MAX_PITCH, MAX_PITCH);
        let dir = Vec3::new(pitch.cos() * yaw.sin(), pitch.sin(), pitch.cos() * yaw.cos());
        self.eye = self.target + dir * r;
    }

    /// Moves eye and target together by a drag of `delta` pixels in a view `view_height` pixels
    /// tall, so that the point under the cursor at the target's distance follows it: a drag of
    /// the whole view height moves by the height the view shows there, `2 d tan(fov / 2)`.
    pub fn pan(&mut self, delta: Vec2, view_height: f32) {
        let forward = (self.target - self.eye).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(Vec3::Y).normalize_or(Vec3::X);
        let up = right.cross(forward);
        let half = (0.5 * self.fov_deg).clamp(0.01, 89.0).to_radians();
        let per_px = 2.0 * (self.eye - self.target).length() * half.tan() / view_height.max(1.0);
        let shift = (-right * delta.x + up * delta.y) * per_px;
        self.eye += shift;
        self.target += shift;
    }

    /// Scales the eye's distance from the target by `factor`, kept within 0.05 to 200.
    pub fn zoom(&mut self, factor: f32) {
        let offset = self.eye - self.target;
        let r = (offset.length() * factor).clamp(ZOOM_RANGE.0, ZOOM_RANGE.1);
        self.eye = self.target + offset.normalize_or(Vec3::Z) * r;
    }
}

/// The light direction after a ctrl-drag of `delta` pixels from `dir` (toward the light):
/// right turns it about +Y, up raises it, kept between 2 and 89.5 degrees above the horizon.
#[must_use]
pub fn drag_light(dir: Vec3, delta: Vec2) -> Vec3 {
    let d = dir.normalize_or(Vec3::Y);
    let azimuth = d.x.atan2(d.z) + delta.x * 0.01;
    let elevation = (d.y.clamp(-1.0, 1.0).asin() - delta.y * 0.01).clamp(2f32.to_radians(), 89.5f32.to_radians());
    Vec3::new(elevation.cos() * azimuth.sin(), elevation.sin(), elevation.cos() * azimuth.cos())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    #[test]
    fn orbiting_keeps_the_target_and_the_distance() {
        let mut c = Orbit { eye: Vec3::new(0.0, 0.0, 4.0), target: Vec3::new(1.0, 0.0, 0.0), fov_deg: 45.0 };
        let r = (c.eye - c.target).length();
        // A quarter turn of yaw: pi/2 radians of drag.
        c.orbit(Vec2::new(-std::f32::consts::FRAC_PI_2 / ORBIT_PER_PX, 0.0));
        assert!(((c.eye - c.target).length() - r).abs() < 1e-4);
        let yaw = (c.eye - c.target).x.atan2((c.eye - c.target).z);
        let yaw0 = (-1.0f32).atan2(4.0);
        assert!((yaw - yaw0 - std::f32::consts::FRAC_PI_2).abs() < 1e-4, "yaw {yaw} from {yaw0}");
        assert_eq!(c.target, Vec3::new(1.0, 0.0, 0.0));
        // Far up: the pitch stops short of the pole.
        c.orbit(Vec2::new(0.0, 1e5));
        let pitch = ((c.eye - c.target).y / r).asin();
        assert!((pitch - MAX_PITCH).abs() < 1e-4, "{pitch}");
    }

    /// A drag of the whole view height moves by the height the view shows at the target's
    /// distance, `2 d tan(fov / 2)`, for the scene's field of view (not a fixed 45 degrees).
    #[test]
    fn panning_follows_the_cursor_for_any_field_of_view() {
        for fov in [20.0f32, 45.0, 90.0] {
            let mut c = Orbit { eye: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, fov_deg: fov };
            c.pan(Vec2::new(0.0, 600.0), 600.0);
            let want = 2.0 * 5.0 * (0.5 * fov).to_radians().tan();
            assert!(close(c.target, Vec3::new(0.0, want, 0.0)), "fov {fov}: target {}", c.target);
            assert!(close(c.eye, Vec3::new(0.0, want, 5.0)), "the eye moves with it");
            // Right drag moves the scene right: the camera goes left.
            let mut c = Orbit { eye: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, fov_deg: fov };
            c.pan(Vec2::new(300.0, 0.0), 600.0);
            assert!(close(c.target, Vec3::new(-want / 2.0, 0.0, 0.0)), "fov {fov}: target {}", c.target);
        }
    }

    #[test]
    fn zoom_scales_the_distance_within_its_range() {
        let mut c = Orbit { eye: Vec3::new(0.0, 3.0, 4.0), target: Vec3::ZERO, fov_deg: 45.0 };
        c.zoom(0.5);
        assert!(close(c.eye, Vec3::new(0.0, 1.5, 2.0)));
        c.zoom(1e-9);
        assert!(((c.eye - c.target).length() - ZOOM_RANGE.0).abs() < 1e-6);
        c.zoom(1e12);
        assert!(((c.eye - c.target).length() - ZOOM_RANGE.1).abs() < 1e-3);
    }

    #[test]
    fn the_light_stays_above_the_horizon() {
        let d = drag_light(Vec3::new(0.0, 1.0, 1.0), Vec2::new(0.0, 1e4));
        assert!((d.y.asin().to_degrees() - 2.0).abs() < 1e-3, "{d}");
        let d = drag_light(Vec3::new(0.0, 1.0, 1.0), Vec2::new(0.0, -1e4));
        assert!((d.y.asin().to_degrees() - 89.5).abs() < 1e-3, "{d}");
        assert!((d.length() - 1.0).abs() < 1e-5);
    }
}
