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
    /// The surface's curvature form `L * II` in the (T, B) basis
    /// ([`pomkit_core::silhouette::vertex_curvature`]; 0 unless the material has silhouettes).
    pub curvature: Vec3,
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
            curvature: a.curvature * w.x + b.curvature * w.y + c.curvature * w.z,
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

/// Subpixel precision of the fixed-point screen positions: 1/256 pixel, as GPUs snap.
const SUBPIXEL: f64 = 256.0;

/// Half-width of the guard band in NDC units (the visible screen is [-1, 1]): triangles reaching
/// beyond it are clipped to it in clip space, so snapped screen positions stay below
/// `(2^26 / 2 + 1) * 16384 ~ 2^39` pixels, whose products in the edge functions (about 2^96 in
/// 1/256 pixel units) fit an `i128` exactly.
const GUARD_NDC: f64 = 67_108_864.0;

/// A triangle ready to rasterize: screen positions, 1/w, depth, and varyings divided by w.
///
/// Coverage is decided on the positions snapped to a 1/256-pixel grid, with exact integer edge
/// functions and the top-left rule: two triangles sharing an edge evaluate it to exactly
/// opposite values, so every pixel centre along it is covered by exactly one of them, however
/// long or thin the triangles are (the rasterizer is watertight).
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
    /// Screen positions snapped to 1/256 pixel.
    fixed: [[i64; 2]; 3],
    /// Twice the signed area in squared 1/256 pixels (positive after setup), as `f64` (the
    /// barycentric weights' divisor).
    area: f64,
    /// Every fixed-point coordinate below 2^29 in magnitude: the edge functions at points as
    /// small fit in i64 (differences below 2^30, products below 2^60).
    small: bool,
    /// Least depth of the three vertices, for front-to-back ordering.
    pub min_z: f32,
    /// Which varyings the fragments need beyond the world position, normal, UV and depth (all
    /// of them after [`setup`]); the others are left zero.
    pub needs: Needs,
}

/// Varyings a triangle's fragments may go without ([`ScreenTriangle::needs`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Needs {
    /// The tangent and `uv_scale` (a tangent frame: all but `flat`).
    pub frame: bool,
    /// The curvature (silhouettes only).
    pub curvature: bool,
}

impl Needs {
    /// Every varying.
    pub const ALL: Self = Self { frame: true, curvature: true };
}

/// Clips a triangle against the near plane `z >= 0` (wgpu clip space) and against `w > 0`,
/// and against a guard band far outside the screen (so that screen positions stay in the range
/// the fixed-point rasterizer handles exactly), returning 0 or more triangles (as a fan).
///
/// The point where an edge crosses a plane is computed in f64 from the edge's endpoints taken
/// in a fixed order, so the two triangles sharing an edge get bit-identical new vertices and
/// no crack opens between them.
pub fn clip_near(tri: [ClipVertex; 3]) -> Vec<[ClipVertex; 3]> {
    if !needs_clipping(&tri) {
        return vec![tri];
    }
    if !tri.iter().any(|c| is_in_front(c.clip)) {
        return vec![];
    }
    // Sutherland-Hodgman against z >= 0 (which implies w > 0 for a perspective projection),
    // then against the four sides of the guard band.
    type Plane = fn(Vec4) -> f64;
    let planes: [(Plane, Option<usize>); 5] = [
        (|c| f64::from(c.z), Some(2)),
        (|c| GUARD_NDC * f64::from(c.w) - f64::from(c.x), None),
        (|c| GUARD_NDC * f64::from(c.w) + f64::from(c.x), None),
        (|c| GUARD_NDC * f64::from(c.w) - f64::from(c.y), None),
        (|c| GUARD_NDC * f64::from(c.w) + f64::from(c.y), None),
    ];
    let mut poly: Vec<ClipVertex> = tri.to_vec();
    for (dist, exact_zero) in planes {
        if poly.iter().all(|c| dist(c.clip) >= 0.0) {
            continue;
        }
        let mut next = Vec::with_capacity(poly.len() + 1);
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            let (da, db) = (dist(a.clip), dist(b.clip));
            if da >= 0.0 {
                next.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                next.push(crossing(a, b, dist, exact_zero));
            }
        }
        poly = next;
        if poly.len() < 3 {
            return vec![];
        }
    }
    (1..poly.len() - 1).map(|k| [poly[0], poly[k], poly[k + 1]]).collect()
}

/// Whether a clip-space position lies in front of the near plane (and at a positive `w`).
#[inline]
fn is_in_front(c: Vec4) -> bool {
    c.z >= 0.0 && c.w > 1e-6
}

/// Whether [`clip_near`] would change the triangle: some vertex lies behind the near plane or
/// beyond the guard band. A triangle that needs no clipping can go to [`setup`] as it is.
#[must_use]
pub fn needs_clipping(tri: &[ClipVertex; 3]) -> bool {
    !tri.iter().all(|c| unclipped(c.clip))
}

/// Whether a vertex at clip position `c` lies in front of the near plane and inside the guard
/// band: a triangle needs clipping ([`needs_clipping`]) unless all three of its vertices do.
pub fn unclipped(c: Vec4) -> bool {
    let g = GUARD_NDC * f64::from(c.w);
    is_in_front(c) && f64::from(c.x).abs() <= g && f64::from(c.y).abs() <= g
}

/// The point where edge `a`-`b` crosses the plane `dist = 0`, the same whichever way round the
/// edge is given; `exact_zero` is the clip component the plane sets to 0 (the near plane's z).
fn crossing(a: ClipVertex, b: ClipVertex, dist: fn(Vec4) -> f64, exact_zero: Option<usize>) -> ClipVertex {
    let key = |c: &ClipVertex| c.clip.to_array().map(f32::to_bits);
    let (p, q) = if key(&a) <= key(&b) { (a, b) } else { (b, a) };
    let (dp, dq) = (dist(p.clip), dist(q.clip));
    let t = dp / (dp - dq);
    let lerp = |x: f32, y: f32| (f64::from(x) + (f64::from(y) - f64::from(x)) * t) as f32;
    let mut clip = Vec4::new(
        lerp(p.clip.x, q.clip.x),
        lerp(p.clip.y, q.clip.y),
        lerp(p.clip.z, q.clip.z),
        lerp(p.clip.w, q.clip.w),
    );
    if let Some(k) = exact_zero {
        clip[k] = 0.0;
    }
    ClipVertex { clip, v: Varyings::lerp2(&p.v, &q.v, t as f32) }
}

/// Projects a clipped triangle to the screen. Returns `None` for back faces (when `cull`),
/// degenerate triangles (zero area once snapped to 1/256 pixel), and non-finite input.
pub fn setup(tri: &[ClipVertex; 3], width: u32, height: u32, object: u32, cull: bool) -> Option<ScreenTriangle> {
    let mut p = [Vec2::ZERO; 3];
    let mut fixed = [[0i64; 2]; 3];
    let mut z = [0.0; 3];
    let mut inv_w = [0.0; 3];
    for k in 0..3 {
        let c = tri[k].clip;
        if !c.is_finite() || c.w <= 0.0 {
            return None;
        }
        let iw = 1.0 / c.w;
        // Screen positions in f64 from the f32 clip position, then snapped.
        let w64 = f64::from(c.w);
        let sx = (f64::from(c.x) / w64 * 0.5 + 0.5) * f64::from(width);
        let sy = (0.5 - f64::from(c.y) / w64 * 0.5) * f64::from(height);
        // Beyond the guard band (only by rounding after clipping) the snapped position would
        // lose exactness: such a triangle cannot be drawn.
        let limit = (GUARD_NDC * 0.5 + 1.0) * f64::from(width.max(height)) * 1.01;
        if !(sx.abs() <= limit && sy.abs() <= limit) {
            return None;
        }
        fixed[k] = [round_to_i64(sx * SUBPIXEL), round_to_i64(sy * SUBPIXEL)];
        p[k] = Vec2::new(sx as f32, sy as f32);
        z[k] = c.z * iw;
        inv_w[k] = iw;
    }
    // Counter-clockwise in world is clockwise on a y-down screen: area < 0 is front-facing.
    let area2 = edge_function(fixed[0], fixed[1], fixed[2]);
    if area2 == 0 {
        return None;
    }
    let front = area2 < 0;
    if cull && !front {
        return None;
    }
    let mut v = [tri[0].v, tri[1].v, tri[2].v];
    let mut area2 = area2;
    if area2 < 0 {
        // Store with positive area: swap two vertices.
        p.swap(1, 2);
        fixed.swap(1, 2);
        z.swap(1, 2);
        inv_w.swap(1, 2);
        v.swap(1, 2);
        area2 = -area2;
    }
    let min_z = z[0].min(z[1]).min(z[2]);
    let small = fixed.iter().flatten().all(|c| c.abs() < SMALL);
    Some(ScreenTriangle { p, z, inv_w, v, object, fixed, area: area2 as f64, small, min_z, needs: Needs::ALL })
}

/// `x.round() as i64` (halves away from zero) for `|x| < 2^52`, as the guard band keeps the
/// snapped positions, without the call into libm that `round` is on baseline x86-64: the
/// truncation is one instruction and `x - trunc(x)` is exact there.
#[inline]
fn round_to_i64(x: f64) -> i64 {
    let i = x as i64;
    let f = x - i as f64;
    if f >= 0.5 {
        i + 1
    } else if f <= -0.5 {
        i - 1
    } else {
        i
    }
}

/// The bound below which fixed-point coordinates take the i64 edge functions.
const SMALL: i64 = 1 << 29;

/// `(b - a) x (q - a)` on fixed-point positions below [`SMALL`] in magnitude, exactly.
#[inline]
fn edge_function_small(a: [i64; 2], b: [i64; 2], q: [i64; 2]) -> i128 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let r = [q[0] - a[0], q[1] - a[1]];
    i128::from(d[0] * r[1] - d[1] * r[0])
}

/// `(b - a) x (q - a)` on fixed-point positions, exactly.
#[inline]
fn edge_function(a: [i64; 2], b: [i64; 2], q: [i64; 2]) -> i128 {
    let d = [i128::from(b[0]) - i128::from(a[0]), i128::from(b[1]) - i128::from(a[1])];
    let r = [i128::from(q[0]) - i128::from(a[0]), i128::from(q[1]) - i128::from(a[1])];
    d[0] * r[1] - d[1] * r[0]
}

/// What the rasterizer hands the shader for one pixel of a quad.
#[derive(Clone, Copy, Debug, Default)]
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
    /// The three edge functions at fixed-point point `q`: in i64 where the triangle and the
    /// point are [`SMALL`], else in i128 (the same values).
    #[inline]
    fn edges_at(&self, q: [i64; 2]) -> [i128; 3] {
        let [a, b, c] = self.fixed;
        if self.small && q[0].abs() < SMALL && q[1].abs() < SMALL {
            [edge_function_small(b, c, q), edge_function_small(c, a, q), edge_function_small(a, b, q)]
        } else {
            [edge_function(b, c, q), edge_function(c, a, q), edge_function(a, b, q)]
        }
    }

    /// Whether edge functions `w` put their point inside (top-left rule).
    #[inline]
    fn covers(&self, [w0, w1, w2]: [i128; 3]) -> bool {
        let [a, b, c] = self.fixed;
        is_inside_edge(w0, b, c) && is_inside_edge(w1, c, a) && is_inside_edge(w2, a, b)
    }

    /// The fixed-point centre of pixel `(x, y)`.
    #[inline]
    fn centre(x: u32, y: u32) -> [i64; 2] {
        [i64::from(x) * 256 + 128, i64::from(y) * 256 + 128]
    }

    /// Perspective-correct varyings and depth at screen point `q` (pixels).
    #[cfg(test)]
    fn interpolate_at(&self, q: Vec2) -> (Varyings, f32, bool) {
        let snap = |c: f32| (f64::from(c) * SUBPIXEL).round() as i64;
        self.interpolate_fixed([snap(q.x), snap(q.y)])
    }

    /// Perspective-correct varyings and depth at fixed-point screen point `q`.
    #[cfg(test)]
    fn interpolate_fixed(&self, q: [i64; 2]) -> (Varyings, f32, bool) {
        self.interpolate_edges(self.edges_at(q))
    }

    /// The triangle with its fragments' varyings cut to `needs`.
    #[must_use]
    pub fn needing(self, needs: Needs) -> Self {
        Self { needs, ..self }
    }

    /// [`Varyings::lerp3`] into `v`, field by field, of the varyings in
    /// [`ScreenTriangle::needs`] (the same values); the others are set to zero.
    #[inline(always)]
    fn lerp_into(&self, v: &mut Varyings, w: Vec3) {
        let [a, b, c] = &self.v;
        v.world = a.world * w.x + b.world * w.y + c.world * w.z;
        v.normal = a.normal * w.x + b.normal * w.y + c.normal * w.z;
        v.uv = a.uv * w.x + b.uv * w.y + c.uv * w.z;
        v.depth = a.depth * w.x + b.depth * w.y + c.depth * w.z;
        if self.needs.frame {
            v.tangent = a.tangent * w.x + b.tangent * w.y + c.tangent * w.z;
            v.uv_scale = a.uv_scale * w.x + b.uv_scale * w.y + c.uv_scale * w.z;
        } else {
            v.tangent = Vec4::ZERO;
            v.uv_scale = Vec2::ZERO;
        }
        v.curvature =
            if self.needs.curvature { a.curvature * w.x + b.curvature * w.y + c.curvature * w.z } else { Vec3::ZERO };
    }

    /// Perspective-correct varyings and depth at the point of edge functions `w`.
    #[cfg(test)]
    fn interpolate_edges(&self, w: [i128; 3]) -> (Varyings, f32, bool) {
        let (pc, z) = self.weights_at(w.map(|v| v as f64));
        let mut v = Varyings::default();
        self.lerp_into(&mut v, pc);
        (v, z, self.covers(w))
    }

    /// The perspective-correct barycentric weights and the depth at the point of edge
    /// functions `w` (exact integers, as `f64`).
    #[inline]
    fn weights_at(&self, w: [f64; 3]) -> (Vec3, f32) {
        let area = self.area;
        let b = Vec3::new((w[0] / area) as f32, (w[1] / area) as f32, (w[2] / area) as f32);
        let z = b.x * self.z[0] + b.y * self.z[1] + b.z * self.z[2];
        let pw = Vec3::new(b.x * self.inv_w[0], b.y * self.inv_w[1], b.z * self.inv_w[2]);
        let sum = pw.x + pw.y + pw.z;
        let pc = if sum.abs() > 1e-30 { pw / sum } else { b };
        (pc, z)
    }

    /// Pixel bounding box clamped to `[x0, x1) x [y0, y1)`, expanded to even coordinates so
    /// quads align.
    pub fn quad_bounds(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> Option<(u32, u32, u32, u32)> {
        let [a, b, c] = self.fixed;
        // Pixels whose centres (i * 256 + 128) can lie within the snapped vertices' extent.
        let lo = |k: usize| (a[k].min(b[k]).min(c[k]) - 128).div_euclid(256);
        let hi = |k: usize| (a[k].max(b[k]).max(c[k]) - 128).div_euclid(256) + 1;
        let clamp = |v: i64, l: u32, h: u32| v.clamp(i64::from(l), i64::from(h)) as u32;
        let bx0 = clamp(lo(0), x0, x1) & !1;
        let by0 = clamp(lo(1), y0, y1) & !1;
        let bx1 = clamp(hi(0), x0, x1);
        let by1 = clamp(hi(1), y0, y1);
        (bx0 < bx1 && by0 < by1).then_some((bx0.max(x0), by0.max(y0), bx1, by1))
    }

    /// Rasterizes the part of the triangle inside `[x0, x1) x [y0, y1)` (x0, y0 even) in 2x2
    /// quads, calling `shade` for each covered pixel with derivatives from its quad.
    pub fn rasterize(&self, x0: u32, y0: u32, x1: u32, y1: u32, shade: impl FnMut(&Fragment)) {
        /// Every covered pixel, handed to `shade` from a scratch fragment.
        struct Each<F>(F, Fragment);
        impl<F: FnMut(&Fragment)> FragmentSink for Each<F> {
            fn keep(&mut self, _: u32, _: u32, _: f32) -> bool {
                true
            }
            fn slot(&mut self, _: u32, _: u32) -> &mut Fragment {
                &mut self.1
            }
            fn written(&mut self, _: u32, _: u32) {
                (self.0)(&self.1);
            }
        }
        self.rasterize_into(x0, y0, x1, y1, &mut Each(shade, Fragment::default()));
    }

    /// [`ScreenTriangle::rasterize`] with a depth test before the interpolation, into `sink`:
    /// [`FragmentSink::keep`] decides from a covered pixel's position and depth whether it is
    /// shaded, and only the pixels it keeps get their varyings interpolated (the quad's other
    /// pixels, helpers for the derivatives, get their UV only), written field by field where
    /// the sink keeps them ([`FragmentSink::slot`]). The fragments are the ones `rasterize`
    /// gives, bit for bit.
    pub fn rasterize_into(&self, x0: u32, y0: u32, x1: u32, y1: u32, sink: &mut impl FragmentSink) {
        let Some((bx0, by0, bx1, by1)) = self.quad_bounds(x0, y0, x1, y1) else { return };
        let inside = |x: u32, y: u32| x >= x0 && x < x1 && y >= y0 && y < y1;
        // The quads start on even pixels.
        let quads = [bx0 & !1, by0 & !1, bx1, by1];
        if self.small {
            self.rasterize_stepped(quads, inside, sink);
        } else {
            self.rasterize_exact(quads, inside, sink);
        }
    }

    /// [`ScreenTriangle::rasterize_into`] for a [`SMALL`] triangle, over the quads from
    /// `(qx0, qy0)` (even) to `(bx1, by1)`: the edge functions stepped from pixel to pixel,
    /// exactly (in i64: the values at pixel centres stay below 2^60, module docs of `SMALL`),
    /// and the top-left rule as a least value: covered where every edge function is at least
    /// `least`.
    #[inline(always)]
    fn rasterize_stepped(
        &self,
        [qx0, qy0, bx1, by1]: [u32; 4],
        inside: impl Fn(u32, u32) -> bool + Copy,
        sink: &mut impl FragmentSink,
    ) {
        let [a, b, c] = self.fixed;
        let o = Self::centre(qx0, qy0);
        let mut row = [0i64; 3];
        let mut step_x = [0i64; 3];
        let mut step_y = [0i64; 3];
        let mut least = [0i64; 3];
        for (k, (p, q)) in [(b, c), (c, a), (a, b)].into_iter().enumerate() {
            let d = [q[0] - p[0], q[1] - p[1]];
            row[k] = d[0] * (o[1] - p[1]) - d[1] * (o[0] - p[0]);
            step_x[k] = -d[1] * 256;
            step_y[k] = d[0] * 256;
            least[k] = i64::from(!is_top_left(p, q));
        }
        let mut qy = qy0;
        while qy < by1 {
            let mut e = row;
            let mut qx = qx0;
            while qx < bx1 {
                let mut w = [[0i64; 3]; 4];
                let mut mask = 0u32;
                for (k, wk) in w.iter_mut().enumerate() {
                    let (dx, dy) = ((k & 1) as i64, (k >> 1) as i64);
                    let mut all = true;
                    for i in 0..3 {
                        wk[i] = e[i] + dx * step_x[i] + dy * step_y[i];
                        all &= wk[i] >= least[i];
                    }
                    mask |= u32::from(all) << k;
                }
                if mask != 0 {
                    let w = w.map(|wk| wk.map(|v| v as f64));
                    self.emit_quad(qx, qy, mask, &w, inside, sink);
                }
                for i in 0..3 {
                    e[i] += 2 * step_x[i];
                }
                qx += 2;
            }
            for i in 0..3 {
                row[i] += 2 * step_y[i];
            }
            qy += 2;
        }
    }

    /// [`ScreenTriangle::rasterize_into`] for any triangle, over the quads from `(qx0, qy0)`
    /// (even) to `(bx1, by1)`: the edge functions evaluated at each pixel centre
    /// ([`ScreenTriangle::edges_at`]).
    #[inline(always)]
    fn rasterize_exact(
        &self,
        [qx0, qy0, bx1, by1]: [u32; 4],
        inside: impl Fn(u32, u32) -> bool + Copy,
        sink: &mut impl FragmentSink,
    ) {
        let mut qy = qy0;
        while qy < by1 {
            let mut qx = qx0;
            while qx < bx1 {
                // Coverage first (exact integers only): a quad the triangle misses costs no
                // interpolation.
                let mut mask = 0u32;
                let mut w = [[0f64; 3]; 4];
                for (k, wk) in w.iter_mut().enumerate() {
                    let (x, y) = (qx + (k & 1) as u32, qy + (k >> 1) as u32);
                    let e = self.edges_at(Self::centre(x, y));
                    *wk = e.map(|v| v as f64);
                    mask |= u32::from(self.covers(e)) << k;
                }
                if mask != 0 {
                    self.emit_quad(qx, qy, mask, &w, inside, sink);
                }
                qx += 2;
            }
            qy += 2;
        }
    }

    /// The fragments of the quad at `(qx, qy)` whose pixels `mask` covers (bit `k` for pixel
    /// `(qx + k % 2, qy + k / 2)`) and `inside` and the sink accept, from the quad's edge
    /// functions `w` (as `f64`, exactly).
    #[inline(always)]
    fn emit_quad(
        &self,
        qx: u32,
        qy: u32,
        mask: u32,
        w: &[[f64; 3]; 4],
        inside: impl Fn(u32, u32) -> bool,
        sink: &mut impl FragmentSink,
    ) {
        let [va, vb, vc] = &self.v;
        // Every pixel's perspective-correct weights and UV (the derivatives need all four), the
        // depth of the covered ones.
        let mut pc = [Vec3::ZERO; 4];
        let mut uv = [Vec2::ZERO; 4];
        let mut z = [0.0f32; 4];
        for k in 0..4 {
            let (b, zk) = self.weights_at(w[k]);
            pc[k] = b;
            z[k] = zk;
            uv[k] = va.uv * b.x + vb.uv * b.y + vc.uv * b.z;
        }
        // Coarse derivatives, as a GPU's ddx/ddy: differences across the quad.
        let duv_dx = 0.5 * ((uv[1] - uv[0]) + (uv[3] - uv[2]));
        let duv_dy = 0.5 * ((uv[2] - uv[0]) + (uv[3] - uv[1]));
        for k in 0..4 {
            let (x, y) = (qx + (k & 1) as u32, qy + (k >> 1) as u32);
            if mask & (1 << k) != 0 && inside(x, y) && sink.keep(x, y, z[k]) {
                let f = sink.slot(x, y);
                f.x = x;
                f.y = y;
                f.z = z[k];
                f.duv_dx = duv_dx;
                f.duv_dy = duv_dy;
                self.lerp_into(&mut f.v, pc[k]);
                sink.written(x, y);
            }
        }
    }
}

/// Where [`ScreenTriangle::rasterize_into`] puts the fragments of a triangle.
pub trait FragmentSink {
    /// Whether the covered pixel `(x, y)`, at depth `z`, gets a fragment.
    fn keep(&mut self, x: u32, y: u32, z: f32) -> bool;
    /// Where the fragment of pixel `(x, y)` (just kept) is written; every field is set.
    fn slot(&mut self, x: u32, y: u32) -> &mut Fragment;
    /// The fragment of pixel `(x, y)` is written.
    fn written(&mut self, x: u32, y: u32);
}

/// Whether the edge from `a` to `b` is a top or a left edge, whose pixel centres exactly on it
/// belong to the triangle.
#[inline]
fn is_top_left(a: [i64; 2], b: [i64; 2]) -> bool {
    let d = [b[0] - a[0], b[1] - a[1]];
    // With positive area (counter-clockwise in y-down pixel space), top edges run toward -x
    // horizontally and left edges run toward +y.
    (d[1] == 0 && d[0] < 0) || d[1] > 0
}

/// Top-left rule: a pixel centre exactly on an edge belongs to the triangle only for top or
/// left edges, so shared edges are drawn once.
#[inline]
fn is_inside_edge(w: i128, a: [i64; 2], b: [i64; 2]) -> bool {
    if w != 0 { w > 0 } else { is_top_left(a, b) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vert(x: f32, y: f32, z: f32, w: f32, u: f32) -> ClipVertex {
        ClipVertex { clip: Vec4::new(x, y, z, w), v: Varyings { uv: Vec2::new(u, 0.0), ..Default::default() } }
    }

    #[test]
    fn snapping_rounds_as_round_does() {
        for x in [0.0, 0.5, -0.5, 1.5, -1.5, 2.499_999_999, -2.5, 1e15 + 0.5, -1e15 - 0.5, 0.499_999_999_999_999_94] {
            assert_eq!(round_to_i64(x), x.round() as i64, "{x}");
        }
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..100_000 {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let x = (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0e9 - 1.0e9;
            let half = x.floor() + 0.5;
            for v in [x, half, -half] {
                assert_eq!(round_to_i64(v), v.round() as i64, "{v}");
            }
        }
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

    /// Rasterizes every triangle (clipped, no culling) into a `w x h` count of fragments per pixel.
    fn coverage(tris: &[[ClipVertex; 3]], w: u32, h: u32) -> Vec<u32> {
        let mut count = vec![0u32; (w * h) as usize];
        for &t in tris {
            for c in clip_near(t) {
                if let Some(st) = setup(&c, w, h, 0, false) {
                    st.rasterize(0, 0, w, h, |f| count[(f.y * w + f.x) as usize] += 1);
                }
            }
        }
        count
    }

    #[test]
    fn a_fan_of_triangles_sharing_edges_covers_each_pixel_exactly_once() {
        let (w, h) = (64u32, 48u32);
        // Centres: an arbitrary point, and a pixel centre (so that every edge of the fan passes
        // exactly through pixel centres, where only the top-left rule decides).
        let centres =
            [Vec2::new(0.123_456, -0.056_789), Vec2::new((20.5 / 64.0) * 2.0 - 1.0, 1.0 - (30.5 / 48.0) * 2.0)];
        // Rings just outside the screen, and far out (long thin triangles, whose edge functions
        // f32 cannot evaluate near the screen).
        for (centre, radius) in centres.into_iter().flat_map(|c| [(c, 3.0f32), (c, 1.0e6)]) {
            for n in [3usize, 7, 37, 360] {
                // A ring outside the screen, so the fan covers all of it; every triangle shares
                // its two outer edges with its neighbours.
                let ring: Vec<Vec2> = (0..n)
                    .map(|i| {
                        let a = i as f32 / n as f32 * std::f32::consts::TAU + 0.1;
                        Vec2::new(a.cos(), a.sin()) * radius
                    })
                    .collect();
                let tris: Vec<[ClipVertex; 3]> = (0..n)
                    .map(|i| {
                        let (p, q) = (ring[i], ring[(i + 1) % n]);
                        [
                            vert(centre.x, centre.y, 0.5, 1.0, 0.0),
                            vert(p.x, p.y, 0.5, 1.0, 0.0),
                            vert(q.x, q.y, 0.5, 1.0, 0.0),
                        ]
                    })
                    .collect();
                let count = coverage(&tris, w, h);
                let bad: Vec<_> = count.iter().enumerate().filter(|(_, c)| **c != 1).take(8).collect();
                assert!(
                    bad.is_empty(),
                    "centre {centre}, radius {radius}, {n} triangles: pixels (index, count) {bad:?}"
                );
            }
        }
    }

    #[test]
    fn huge_and_long_thin_triangles_stay_watertight() {
        let (w, h) = (40u32, 30u32);
        let quad = |r: f32, tilt: f32| {
            let (a, b, c, d) = (
                vert(-r, -r + tilt, 0.5, 1.0, 0.0),
                vert(r, -r, 0.5, 1.0, 1.0),
                vert(r, r - tilt, 0.5, 1.0, 1.0),
                vert(-r, r, 0.5, 1.0, 0.0),
            );
            [[a, b, c], [a, c, d]]
        };
        // Corners far beyond f32's pixel precision (the diagonal's edge function would round
        // away in f32), beyond the guard band (1e8), and at 1e20 in NDC.
        for r in [1.0e4, 3.0e6, 1.0e8, 1.0e20] {
            for tilt in [0.0, 0.37 * r / 1.0e3] {
                let count = coverage(&quad(r, tilt), w, h);
                assert!(count.iter().all(|&c| c == 1), "r {r}, tilt {tilt}: {count:?}");
            }
        }
    }

    #[test]
    fn interpolation_is_perspective_correct() {
        // An edge from w = 1 to w = 3: the screen midpoint is at u = 1/4 of the way, not 1/2.
        let a = vert(-1.0, -1.0, 0.5, 1.0, 0.0);
        let b = vert(3.0, -3.0, 1.5, 3.0, 1.0); // same NDC x = 1, y = -1
        let c = vert(-1.0, 1.0, 0.5, 1.0, 0.0);
        let st = setup(&[a, b, c], 64, 64, 0, false).unwrap();
        // The centre of pixel (31.5, 63.5) is the screen point (32, 64).
        let (v, _, _) = st.interpolate_at(Vec2::new(32.0, 64.0));
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
