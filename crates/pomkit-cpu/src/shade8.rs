//! The shading of a packet of eight fragments after their traces, in portable SIMD: texture
//! filtering (albedo mips and the normal map), the normal-mapped frame, Blinn-Phong lighting
//! with each light's shadows, and the LOD fade.
//!
//! Every lane computes what the single-fragment `finish` computes, operation for operation and
//! in the same order (no fused multiply-adds), so the packets' pictures are the single
//! fragments' bit for bit; the texel loads and the specular power are per lane.

use fearless_simd::{Select, Simd, SimdBase, SimdFloat, f32x8, mask32x8};
use glam::{Vec2, Vec3};
use pomkit_core::EdgeMode;
use pomkit_core::heightfield::floor;
use pomkit_core::scene::{Light, Texture};
use pomkit_core::shadow::Shadow;
use pomkit_core::trace::packet::{LANES, finite, mask as mask8, vec as vec8};

/// Eight 3-vectors, one per lane.
#[derive(Clone, Copy)]
pub(crate) struct V3<S: Simd> {
    pub x: f32x8<S>,
    pub y: f32x8<S>,
    pub z: f32x8<S>,
}

impl<S: Simd> V3<S> {
    #[inline(always)]
    pub fn from_lanes(simd: S, v: &[Vec3; LANES]) -> Self {
        Self { x: vec8(simd, v.map(|v| v.x)), y: vec8(simd, v.map(|v| v.y)), z: vec8(simd, v.map(|v| v.z)) }
    }

    #[inline(always)]
    pub fn splat(simd: S, v: Vec3) -> Self {
        Self { x: f32x8::splat(simd, v.x), y: f32x8::splat(simd, v.y), z: f32x8::splat(simd, v.z) }
    }

    #[inline(always)]
    pub fn lanes(&self) -> [Vec3; LANES] {
        let (x, y, z): ([f32; LANES], [f32; LANES], [f32; LANES]) = (*self.x, *self.y, *self.z);
        std::array::from_fn(|i| Vec3::new(x[i], y[i], z[i]))
    }

    #[inline(always)]
    pub fn add(self, o: Self) -> Self {
        Self { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }

    #[inline(always)]
    pub fn sub(self, o: Self) -> Self {
        Self { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }

    #[inline(always)]
    pub fn mul(self, o: Self) -> Self {
        Self { x: self.x * o.x, y: self.y * o.y, z: self.z * o.z }
    }

    #[inline(always)]
    pub fn scale(self, s: f32x8<S>) -> Self {
        Self { x: self.x * s, y: self.y * s, z: self.z * s }
    }

    /// glam's `dot`: `(x * x') + (y * y') + (z * z')`.
    #[inline(always)]
    pub fn dot(self, o: Self) -> f32x8<S> {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// glam's `lerp`: `self * (1 - s) + o * s`.
    #[inline(always)]
    pub fn lerp(self, o: Self, s: f32x8<S>) -> Self {
        let r = s.witness().splat_f32x8(1.0) - s;
        self.scale(r).add(o.scale(s))
    }

    #[inline(always)]
    pub fn select(m: mask32x8<S>, a: Self, b: Self) -> Self {
        Self { x: m.select(a.x, b.x), y: m.select(a.y, b.y), z: m.select(a.z, b.z) }
    }

    /// glam's `try_normalize(...).unwrap_or(fallback)`: the vector times `1 / length` where that
    /// is finite and positive, else `fallback`.
    #[inline(always)]
    pub fn normalize_or(self, fallback: Self) -> Self {
        let simd = self.x.witness();
        let rcp = simd.splat_f32x8(1.0) / self.dot(self).sqrt();
        let ok = finite(rcp) & rcp.simd_gt(0.0);
        Self::select(ok, self.scale(rcp), fallback)
    }
}

/// One level of a texture per lane.
type Level<'a> = [&'a [Vec3]; LANES];

/// `bilinear_vec3` of `pomkit_core::scene` in every lane, lane `i` on texels `tex[i]` of size
/// `size[i]`.
#[inline(always)]
fn bilinear<S: Simd>(
    simd: S,
    tex: &Level<'_>,
    size: &[(u32, u32); LANES],
    u: f32x8<S>,
    v: f32x8<S>,
    edges: EdgeMode,
) -> V3<S> {
    let w = vec8(simd, size.map(|s| s.0 as f32));
    let h = vec8(simd, size.map(|s| s.1 as f32));
    let tx = u * w - 0.5;
    let ty = v * h - 0.5;
    let ok = finite(tx) & finite(ty);
    let zero = simd.splat_f32x8(0.0);
    let (tx, ty) = (ok.select(tx, zero), ok.select(ty, zero));
    let (x0, y0) = (tx.floor(), ty.floor());
    let (fx, fy) = (tx - x0, ty - y0);
    let (x0, y0): ([f32; LANES], [f32; LANES]) = (*x0, *y0);
    let mut c = [[Vec3::ZERO; LANES]; 4];
    let mut single = [false; LANES];
    for i in 0..LANES {
        let (tw, th) = size[i];
        let t = tex[i];
        if tw == 1 && th == 1 {
            single[i] = true;
            c[0][i] = t[0];
            continue;
        }
        let (x, y) = (x0[i] as i64, y0[i] as i64);
        if x >= 0 && y >= 0 && x < i64::from(tw) - 1 && y < i64::from(th) - 1 {
            let at = y as usize * tw as usize + x as usize;
            let below = at + tw as usize;
            c[0][i] = t[at];
            c[1][i] = t[at + 1];
            c[2][i] = t[below];
            c[3][i] = t[below + 1];
        } else {
            let at = |x: i64, y: i64| t[edges.resolve(y, th) as usize * tw as usize + edges.resolve(x, tw) as usize];
            let (x1, y1) = (x.saturating_add(1), y.saturating_add(1));
            c[0][i] = at(x, y);
            c[1][i] = at(x1, y);
            c[2][i] = at(x, y1);
            c[3][i] = at(x1, y1);
        }
    }
    let [c00, c10, c01, c11] = c.map(|a| V3::from_lanes(simd, &a));
    let top = c00.lerp(c10, fx);
    let bottom = c01.lerp(c11, fx);
    V3::select(mask8(simd, single), c00, top.lerp(bottom, fy))
}

/// `sample_albedo` in every lane: the trilinear albedo at `(u, v)`, lane `i` at mip level
/// `lods[i]` of `chain`.
#[inline(always)]
pub(crate) fn albedo<S: Simd>(
    simd: S,
    chain: &[Texture],
    u: f32x8<S>,
    v: f32x8<S>,
    lods: [f32; LANES],
    edges: EdgeMode,
) -> V3<S> {
    let last = chain.len() - 1;
    let mut a: Level<'_> = [chain[0].texels(); LANES];
    let mut b = a;
    let mut sa = [(chain[0].width(), chain[0].height()); LANES];
    let mut sb = sa;
    let mut frac = [0.0f32; LANES];
    let mut blend = [false; LANES];
    for i in 0..LANES {
        let k = floor(lods[i]).max(0.0) as usize;
        let f = lods[i] - k as f32;
        let ta = &chain[k.min(last)];
        a[i] = ta.texels();
        sa[i] = (ta.width(), ta.height());
        if !(f <= 0.0 || k + 1 >= chain.len()) {
            let tb = &chain[k + 1];
            b[i] = tb.texels();
            sb[i] = (tb.width(), tb.height());
            frac[i] = f;
            blend[i] = true;
        }
    }
    let lo = bilinear(simd, &a, &sa, u, v, edges);
    if !blend.contains(&true) {
        return lo;
    }
    let hi = bilinear(simd, &b, &sb, u, v, edges);
    V3::select(mask8(simd, blend), lo.lerp(hi, vec8(simd, frac)), lo)
}

/// `NormalMap::sample` in every lane: the filtered normal, renormalized (+Z where it vanishes).
#[inline(always)]
pub(crate) fn normal_map<S: Simd>(
    simd: S,
    map: &pomkit_core::scene::NormalMap,
    u: f32x8<S>,
    v: f32x8<S>,
    edges: EdgeMode,
) -> V3<S> {
    let n = bilinear(simd, &[map.normals(); LANES], &[(map.width(), map.height()); LANES], u, v, edges);
    n.normalize_or(V3::splat(simd, Vec3::Z))
}

/// The direction toward `light` from every lane's `world` point, and the radiance arriving
/// (`light_at` of the single fragment, lane by lane for point lights).
#[inline(always)]
pub(crate) fn light_dirs<S: Simd>(simd: S, light: &Light, world: &[Vec3; LANES]) -> (V3<S>, V3<S>) {
    match *light {
        Light::Directional { .. } => {
            let (l, radiance) = crate::fragment::light_at(light, Vec3::ZERO);
            (V3::splat(simd, l), V3::splat(simd, radiance))
        }
        Light::Point { .. } => {
            let mut l = [Vec3::ZERO; LANES];
            let mut r = [Vec3::ZERO; LANES];
            for i in 0..LANES {
                (l[i], r[i]) = crate::fragment::light_at(light, world[i]);
            }
            (V3::from_lanes(simd, &l), V3::from_lanes(simd, &r))
        }
    }
}

/// What the lighting of a packet reads per lane.
pub(crate) struct LitInputs<'a, S: Simd> {
    pub n: V3<S>,
    pub t: V3<S>,
    pub b: V3<S>,
    pub to_eye: V3<S>,
    pub world: [Vec3; LANES],
    pub albedo_lods: [f32; LANES],
    /// Per light, the shadows of the lanes that trace them.
    pub shadows: &'a [[Option<Shadow>; LANES]],
}

/// The single fragment's `lit` in every lane, at texture coordinates `uv` (already in their
/// tile where the edges wrap): the colour, the first light's visibility, and the shadow fetches
/// each lane spent (`with_shadows` lanes only).
#[inline(always)]
pub(crate) fn lit<S: Simd>(
    simd: S,
    scene: &pomkit_core::scene::Scene,
    prep: &crate::prepare::Prepared,
    inputs: &LitInputs<'_, S>,
    uv: &[Vec2; LANES],
    with_shadows: [bool; LANES],
) -> (V3<S>, [f32; LANES], [u32; LANES]) {
    let m = &prep.material;
    let edges = prep.edges;
    let (u, v) = (vec8(simd, uv.map(|p| p.x)), vec8(simd, uv.map(|p| p.y)));
    let base = albedo(simd, &prep.albedo, u, v, inputs.albedo_lods, edges).mul(V3::splat(simd, m.base_color));
    let n = inputs.n;
    let shading_n = match (&prep.normals, prep.technique) {
        (Some(nm), tq) if tq != pomkit_core::trace::Technique::Flat => {
            let mt = normal_map(simd, nm, u, v, edges);
            inputs.t.scale(mt.x).add(inputs.b.scale(mt.y)).add(n.scale(mt.z)).normalize_or(n)
        }
        _ => n,
    };
    let mut c = V3::splat(simd, scene.ambient).mul(base);
    let mut first_vis = [1.0f32; LANES];
    let mut fetches = [0u32; LANES];
    let zero = simd.splat_f32x8(0.0);
    let shadowed = m.shadow.mode != pomkit_core::shadow::ShadowMode::None && prep.surface.is_some();
    for (li, light) in scene.lights.iter().enumerate() {
        let (l, radiance) = light_dirs(simd, light, &inputs.world);
        let n_dot_l = n.dot(l);
        let facing = n_dot_l.simd_gt(0.0);
        let mut vis = facing.select(simd.splat_f32x8(1.0), zero);
        if shadowed && with_shadows.contains(&true) {
            let mut vs: [f32; LANES] = *vis;
            let lit_lanes: [i32; LANES] = *facing;
            for i in 0..LANES {
                if with_shadows[i] && lit_lanes[i] != 0 {
                    let sh = inputs.shadows[li][i].unwrap_or(Shadow { visibility: 1.0, fetches: 0 });
                    vs[i] = sh.visibility;
                    fetches[i] += sh.fetches;
                }
            }
            vis = vec8(simd, vs);
        }
        if li == 0 {
            first_vis = *vis;
        }
        let diffuse = shading_n.dot(l).max(zero);
        let h = l.add(inputs.to_eye).normalize_or(shading_n);
        let nh: [f32; LANES] = *shading_n.dot(h).max(zero);
        let d: [f32; LANES] = *diffuse;
        let spec: [f32; LANES] =
            std::array::from_fn(|i| if d[i] > 0.0 { m.specular * nh[i].powf(m.shininess) } else { 0.0 });
        let spec = vec8(simd, spec);
        let term = base.scale(diffuse);
        let term = V3 { x: term.x + spec, y: term.y + spec, z: term.z + spec };
        c = c.add(term.mul(radiance).scale(vis));
    }
    (c, first_vis, fetches)
}
