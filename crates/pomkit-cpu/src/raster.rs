//! Triangle setup and rasterization the way a GPU does it: clip-space near-plane clipping,
//! perspective-correct barycentrics, a top-left fill rule, and coverage in 2x2 quads so every
//! shaded pixel has screen-space derivatives from its quad neighbours.

use glam::{Vec2, Vec3, Vec4};

/// Per-vertex attributes carried to the pixel, interpolated perspective-correctly.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Varyings {
    /// World position.
    pub world: Vec3,
    /// World normal (not normalized after interpolation).
    pub normal: Vec3,
    /// World tangent xyz and handedness w.
    pub tangent: Vec4,
    /// Texture coordinate.
    pub uv: Vec2,
    /// World units per UV unit along T and B.
    pub uv_scale: Vec2,
    /// Depth below the polygon (displaced reference geometry only; 0 otherwise).
    pub depth: f32,
}

impl Varyings {
    fn lerp3(a: &Self, b: &Self, c: &Self, w: Vec3) -> Self {
        let f = |x: f32, y: f32, z: f32| x * w.x + y * w.y + z * w.z;
        Self {
            world: a.world * w.x + b.world * w.y + c.world * w.z,
            normal: a.normal * w.x + b.normal * w.y + c.normal * w.z,
            tangent: a.tangent * w.x + b.tangent * w.y + c.tangent * w.z,
            uv: a.uv * w.x + b.uv * w.y + c.uv * w.z,
            uv_scale: a.uv_scale * w.x + b.uv_scale * w.y + c.uv_scale * w.z,
            depth: f(a.depth, b.depth, c.depth),
        }
    }

    fn lerp2(a: &Self, b: &Self, t: f32) -> Self {
        Self::lerp3(a, b, b, Vec3::new(1.0 - t, t, 0.0))
    }
}

/// A vertex after the vertex stage: clip position and varyings.
#[derive(Clone, Copy, Debug)]
pub struct ClipVertex {
    /// Clip-space position.
    pub clip: Vec4,
    /// Attributes.
    pub v: Varyings,
}

/// A triangle ready to rasterize: screen positions, 1/w, depth, and varyings divided by w.
#[derive(Clone, Debug)]
pub struct ScreenTriangle {
    /// Screen positions (pixels, y down).
    pub p: [Vec2; 3],
    /// NDC depth per vertex (0 near .. 1 far).
    pub z: [f32; 3],
    /// 1 / w per vertex.
    pub inv_w: [f32; 3],
    /// Varyings per vertex.
    pub v: [Varyings; 3],
    /// Object index, for the material and AOVs.
    pub object: u32,
    /// Twice the signed screen area (positive after setup).
    area2: f32,
    /// Least depth of the three vertices, for front-to-back ordering.
    pub min_z: f32,
}

/// Clips a triangle against the near plane `z >= 0` (wgpu clip space) and against `w > 0`,
/// returning 0 to 2 triangles (as a fan).
pub fn clip_near(tri: [ClipVertex; 3]) -> Vec<[ClipVertex; 3]> {
    let inside = |c: &ClipVertex| c.clip.z >= 0.0 && c.clip.w > 1e-6;
    if tri.iter().all(inside) {
        return vec![tri];
    }
    if !tri.iter().any(inside) {
        return vec![];
    }
    // Sutherland-Hodgman against z >= 0 (which implies w > 0 for a perspective projection).
    let mut poly: Vec<ClipVertex> = Vec::with_capacity(4);
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let (da, db) = (a.clip.z, b.clip.z);
        if da >= 0.0 {
            poly.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            poly.push(ClipVertex { clip: a.clip.lerp(b.clip, t), v: Varyings::lerp2(&a.v, &b.v, t) });
        }
    }
    (1..poly.len().saturating_sub(1)).map(|k| [poly[0], poly[k], poly[k + 1]]).collect()
}

/// Projects a clipped triangle to the screen. Returns `None` for back faces (when `cull`),
/// degenerate triangles, and non-finite input.
pub fn setup(tri: &[ClipVertex; 3], width: u32, height: u32, object: u32, cull: bool) -> Option<ScreenTriangle> {
    let mut p = [Vec2::ZERO; 3];
    let mut z = [0.0; 3];
    let mut inv_w = [0.0; 3];
    for k in 0..3 {
        let c = tri[k].clip;
        if !c.is_finite() || c.w <= 0.0 {
            return None;
        }
        let iw = 1.0 / c.w;
        let ndc = Vec3::new(c.x * iw, c.y * iw, c.z * iw);
        p[k] = Vec2::new((ndc.x * 0.5 + 0.5) * width as f32, (0.5 - ndc.y * 0.5) * height as f32);
        z[k] = ndc.z;
        inv_w[k] = iw;
    }
    // Counter-clockwise in world is clockwise on a y-down screen: area < 0 is front-facing.
    let area2 = (p[1] - p[0]).perp_dot(p[2] - p[0]);
    if !area2.is_finite() || area2.abs() < 1e-12 {
        return None;
    }
    let front = area2 < 0.0;
    if cull && !front {
        return None;
    }
    let mut v = [tri[0].v, tri[1].v, tri[2].v];
    let mut area2 = area2;
    if area2 < 0.0 {
        // Store with positive area: swap two vertices.
        p.swap(1, 2);
        z.swap(1, 2);
        inv_w.swap(1, 2);
        v.swap(1, 2);
        area2 = -area2;
    }
    let min_z = z[0].min(z[1]).min(z[2]);
    Some(ScreenTriangle { p, z, inv_w, v, object, area2, min_z })
}

/// What the rasterizer hands the shader for one pixel of a quad.
#[derive(Clone, Copy, Debug)]
pub struct Fragment {
    /// Pixel coordinates.
    pub x: u32,
    /// Pixel row.
    pub y: u32,
    /// NDC depth of the polygon here.
    pub z: f32,
    /// Interpolated varyings.
    pub v: Varyings,
    /// Screen derivatives of the UV along x and y, from the quad.
    pub duv_dx: Vec2,
    /// See `duv_dx`.
    pub duv_dy: Vec2,
}

impl ScreenTriangle {
    /// Edge functions at point `q`, normalized to barycentric weights (not perspective
    /// corrected), and whether the point is covered under the top-left rule.
    fn barycentric(&self, q: Vec2) -> (Vec3, bool) {
        let e = |a: Vec2, b: Vec2| (b - a).perp_dot(q - a);
        let w0 = e(self.p[1], self.p[2]);
        let w1 = e(self.p[2], self.p[0]);
        let w2 = e(self.p[0], self.p[1]);
        let covered = self.edge_ok(w0, self.p[1], self.p[2])
            && self.edge_ok(w1, self.p[2], self.p[0])
            && self.edge_ok(w2, self.p[0], self.p[1]);
        (Vec3::new(w0, w1, w2) / self.area2, covered)
    }

    /// Top-left rule: a pixel exactly on an edge belongs to the triangle only for top or left
    /// edges, so shared edges are drawn once.
    fn edge_ok(&self, w: f32, a: Vec2, b: Vec2) -> bool {
        if w > 0.0 {
            return true;
        }
        if w < 0.0 {
            return false;
        }
        let d = b - a;
        // With positive area (counter-clockwise in y-down pixel space), top edges run toward
        // -x horizontally and left edges run toward +y.
        (d.y == 0.0 && d.x < 0.0) || d.y > 0.0
    }

    /// Perspective-correct varyings and depth at pixel centre `q`.
    fn interpolate(&self, q: Vec2) -> (Varyings, f32, bool) {
        let (b, covered) = self.barycentric(q);
        let z = b.x * self.z[0] + b.y * self.z[1] + b.z * self.z[2];
        let pw = Vec3::new(b.x * self.inv_w[0], b.y * self.inv_w[1], b.z * self.inv_w[2]);
        let sum = pw.x + pw.y + pw.z;
        let pc = if sum.abs() > 1e-30 { pw / sum } else { b };
        (Varyings::lerp3(&self.v[0], &self.v[1], &self.v[2], pc), z, covered)
    }

    /// Pixel bounding box clamped to `[x0, x1) x [y0, y1)`, expanded to even coordinates so
    /// quads align.
    pub fn quad_bounds(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> Option<(u32, u32, u32, u32)> {
        let lo = self.p[0].min(self.p[1]).min(self.p[2]);
        let hi = self.p[0].max(self.p[1]).max(self.p[2]);
        let bx0 = (lo.x.floor().max(x0 as f32) as u32) & !1;
        let by0 = (lo.y.floor().max(y0 as f32) as u32) & !1;
        let bx1 = (hi.x.ceil().min(x1 as f32)).max(0.0) as u32;
        let by1 = (hi.y.ceil().min(y1 as f32)).max(0.0) as u32;
        (bx0 < bx1 && by0 < by1).then_some((bx0.max(x0), by0.max(y0), bx1, by1))
    }

    /// Rasterizes the part of the triangle inside `[x0, x1) x [y0, y1)` (x0, y0 even) in 2x2
    /// quads, calling `shade` for each covered pixel with derivatives from its quad.
    pub fn rasterize(&self, x0: u32, y0: u32, x1: u32, y1: u32, mut shade: impl FnMut(&Fragment)) {
        let Some((bx0, by0, bx1, by1)) = self.quad_bounds(x0, y0, x1, y1) else { return };
        let mut qy = by0 & !1;
        while qy < by1 {
            let mut qx = bx0 & !1;
            while qx < bx1 {
                let mut px = [(Varyings::default(), 0.0f32, false); 4];
                let mut any = false;
                for (k, slot) in px.iter_mut().enumerate() {
                    let (dx, dy) = ((k & 1) as u32, (k >> 1) as u32);
                    let q = Vec2::new((qx + dx) as f32 + 0.5, (qy + dy) as f32 + 0.5);
                    *slot = self.interpolate(q);
                    let inside = qx + dx >= x0 && qx + dx < x1 && qy + dy >= y0 && qy + dy < y1;
                    slot.2 &= inside;
                    any |= slot.2;
                }
                if any {
                    // Coarse derivatives, as a GPU's ddx/ddy: differences across the quad.
                    let duv_dx = 0.5 * ((px[1].0.uv - px[0].0.uv) + (px[3].0.uv - px[2].0.uv));
                    let duv_dy = 0.5 * ((px[2].0.uv - px[0].0.uv) + (px[3].0.uv - px[1].0.uv));
                    for (k, (v, z, covered)) in px.iter().enumerate() {
                        if *covered {
                            let (dx, dy) = ((k & 1) as u32, (k >> 1) as u32);
                            shade(&Fragment { x: qx + dx, y: qy + dy, z: *z, v: *v, duv_dx, duv_dy });
                        }
                    }
                }
                qx += 2;
            }
            qy += 2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vert(x: f32, y: f32, z: f32, w: f32, u: f32) -> ClipVertex {
        ClipVertex { clip: Vec4::new(x, y, z, w), v: Varyings { uv: Vec2::new(u, 0.0), ..Default::default() } }
    }

    #[test]
    fn shared_edges_cover_each_pixel_once() {
        // Two triangles forming a quad covering the whole 8x8 screen: every pixel exactly once.
        let (a, b, c, d) = (
            vert(-1.0, -1.0, 0.5, 1.0, 0.0),
            vert(1.0, -1.0, 0.5, 1.0, 1.0),
            vert(1.0, 1.0, 0.5, 1.0, 1.0),
            vert(-1.0, 1.0, 0.5, 1.0, 0.0),
        );
        let mut count = vec![0u32; 64];
        for tri in [[a, b, c], [a, c, d]] {
            let st = setup(&tri, 8, 8, 0, false).unwrap();
            st.rasterize(0, 0, 8, 8, |f| count[(f.y * 8 + f.x) as usize] += 1);
        }
        assert!(count.iter().all(|&n| n == 1), "{count:?}");
    }

    #[test]
    fn interpolation_is_perspective_correct() {
        // An edge from w = 1 to w = 3: the screen midpoint is at u = 1/4 of the way, not 1/2.
        let a = vert(-1.0, -1.0, 0.5, 1.0, 0.0);
        let b = vert(3.0, -3.0, 1.5, 3.0, 1.0); // same NDC x = 1, y = -1
        let c = vert(-1.0, 1.0, 0.5, 1.0, 0.0);
        let st = setup(&[a, b, c], 64, 64, 0, false).unwrap();
        let (v, _, _) = st.interpolate(Vec2::new(32.0, 64.0));
        // At the screen midpoint of the bottom edge, 1/w interpolates linearly: (1 + 1/3) / 2;
        // u/w: (0 + 1/3) / 2; u = (1/6) / (2/3) = 1/4.
        assert!((v.uv.x - 0.25).abs() < 1e-3, "{}", v.uv.x);
    }

    #[test]
    fn near_clipping_keeps_the_visible_part() {
        let tri = [vert(0.0, 0.0, -1.0, 0.5, 0.0), vert(0.5, 0.0, 1.0, 1.0, 1.0), vert(0.0, 0.5, 1.0, 1.0, 1.0)];
        let out = clip_near(tri);
        assert_eq!(out.len(), 2);
        for t in &out {
            for v in t {
                assert!(v.clip.z >= -1e-6);
            }
        }
        assert!(clip_near([vert(0.0, 0.0, -1.0, 1.0, 0.0); 3]).is_empty());
    }

    #[test]
    fn quads_give_screen_derivatives() {
        // u = x / 16 across a 16-pixel-wide screen: du/dx = 1/16 exactly.
        let a = vert(-1.0, -1.0, 0.5, 1.0, 0.0);
        let b = vert(1.0, -1.0, 0.5, 1.0, 1.0);
        let c = vert(-1.0, 1.0, 0.5, 1.0, 0.0);
        let st = setup(&[a, b, c], 16, 16, 0, false).unwrap();
        let mut seen = 0;
        st.rasterize(0, 0, 16, 16, |f| {
            assert!((f.duv_dx.x - 1.0 / 16.0).abs() < 1e-5);
            assert!(f.duv_dy.x.abs() < 1e-5);
            seen += 1;
        });
        assert!(seen > 100);
    }
}
