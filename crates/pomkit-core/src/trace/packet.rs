//! Packets: eight rays traced at once, in portable SIMD.
//!
//! The CPU renderer shades its pixels eight at a time (two 2x2 quads). Here are the techniques'
//! marches and the hard and soft shadow rays for such a packet, written once over
//! [`fearless_simd`]'s eight-lane vectors, so that one source runs on AVX2, on SSE4.2 (two
//! halves), on NEON (two halves) and on the crate's scalar fallback, chosen at run time by the
//! caller's [`fearless_simd::dispatch!`].
//!
//! Every lane computes exactly what [`super::trace()`] and [`crate::shadow::shadow`] compute for its
//! ray, operation for operation in the same order (no fused multiply-adds), so a packet's hits
//! are bit-identical to the single rays' (the tests compare them lane by lane). Lanes leave a
//! loop at their own step under a mask; the packet's loop runs until no lane is active. The
//! filtered height reads are gathers: the filter's arithmetic runs on all lanes at once, the four
//! texel loads of each lane are scalar, and a lane whose footprint crosses the field's edge reads
//! its texels through the edge mode as [`HeightField::sample_bilinear`] does.
//!
//! The techniques with a traversal rather than a march, `exact` and `cone`, trace their lanes one
//! at a time.

use fearless_simd::{Select, Simd, SimdBase, SimdFloat, SimdMask, f32x8, mask32x8};
use glam::{Vec2, Vec3};

use super::shadow_march::{Shadow, ShadowMarch};
use super::{Hit, Ray, Surface, Technique, TraceParams, adaptive_samples, entering, hit_on_ray};
use super::{reduce_to_tile, trace_entering, unreduce, uv_per_depth};
use crate::heightfield::{EdgeMode, HeightField, MipChain};

/// Rays per packet.
pub const LANES: usize = 8;

/// Eight booleans as a lane mask.
#[inline(always)]
pub fn mask<S: Simd>(simd: S, b: [bool; LANES]) -> mask32x8<S> {
    mask32x8::from_slice(simd, &b.map(|x| if x { -1 } else { 0 }))
}

/// A lane mask as eight booleans.
#[inline(always)]
fn bools<S: Simd>(m: mask32x8<S>) -> [bool; LANES] {
    let a: [i32; LANES] = *m;
    a.map(|x| x != 0)
}

/// Eight floats as a vector.
#[inline(always)]
pub fn vec<S: Simd>(simd: S, a: [f32; LANES]) -> f32x8<S> {
    f32x8::from_slice(simd, &a)
}

#[inline(always)]
fn splat<S: Simd>(simd: S, x: f32) -> f32x8<S> {
    f32x8::splat(simd, x)
}

#[inline(always)]
fn array<S: Simd>(v: f32x8<S>) -> [f32; LANES] {
    *v
}

/// Whether each lane is finite (neither infinite nor NaN).
#[inline(always)]
pub fn finite<S: Simd>(x: f32x8<S>) -> mask32x8<S> {
    x.abs().simd_lt(f32::INFINITY)
}

/// Eight lanes' view of a mip chain: each lane reads the two levels around its own level of
/// detail and blends them by its fraction, as [`MipChain::sample`] does.
struct Levels<'a> {
    a: [&'a HeightField; LANES],
    b: [&'a HeightField; LANES],
    frac: [f32; LANES],
    blend: [bool; LANES],
    any_blend: bool,
    edges: EdgeMode,
}

impl<'a> Levels<'a> {
    fn new(chain: &'a MipChain, lods: [f32; LANES], edges: EdgeMode) -> Self {
        let base = chain.base();
        let mut l = Levels {
            a: [base; LANES],
            b: [base; LANES],
            frac: [0.0; LANES],
            blend: [false; LANES],
            any_blend: false,
            edges,
        };
        for (i, &lod) in lods.iter().enumerate() {
            // MipChain::sample's level choice, lane by lane.
            let lod = if lod.is_finite() { lod.clamp(0.0, chain.max_level()) } else { 0.0 };
            let k = crate::heightfield::floor(lod) as usize;
            let f = lod - k as f32;
            l.a[i] = chain.level(k);
            if !(f <= 0.0 || k + 1 >= chain.len()) {
                l.b[i] = chain.level(k + 1);
                l.frac[i] = f;
                l.blend[i] = true;
                l.any_blend = true;
            }
        }
        l
    }

    /// The trilinear depth at `(u, v)` in every lane (one fetch each).
    #[inline(always)]
    fn sample<S: Simd>(&self, simd: S, u: f32x8<S>, v: f32x8<S>) -> f32x8<S> {
        let a = bilinear(simd, &self.a, u, v, self.edges);
        if !self.any_blend {
            return a;
        }
        let b = bilinear(simd, &self.b, u, v, self.edges);
        mask(simd, self.blend).select(a + (b - a) * vec(simd, self.frac), a)
    }
}

/// [`HeightField::sample_bilinear`] in every lane, each lane on its own field.
#[inline(always)]
fn bilinear<S: Simd>(simd: S, fields: &[&HeightField; LANES], u: f32x8<S>, v: f32x8<S>, edges: EdgeMode) -> f32x8<S> {
    let w = vec(simd, fields.map(|f| f.width() as f32));
    let h = vec(simd, fields.map(|f| f.height() as f32));
    let tx = u * w - 0.5;
    let ty = v * h - 0.5;
    let ok = finite(tx) & finite(ty);
    let zero = splat(simd, 0.0);
    let (tx, ty) = (ok.select(tx, zero), ok.select(ty, zero));
    let (x0, y0) = (tx.floor(), ty.floor());
    let (fx, fy) = (tx - x0, ty - y0);
    let (x0, y0) = (array(x0), array(y0));
    let mut c = [[0.0f32; LANES]; 4];
    for i in 0..LANES {
        let f = fields[i];
        let (x, y) = (x0[i] as i64, y0[i] as i64);
        let (fw, fh) = (i64::from(f.width()), i64::from(f.height()));
        if x >= 0 && y >= 0 && x < fw - 1 && y < fh - 1 {
            let d = f.depths();
            let at = y as usize * f.width() as usize + x as usize;
            let below = at + f.width() as usize;
            c[0][i] = d[at];
            c[1][i] = d[at + 1];
            c[2][i] = d[below];
            c[3][i] = d[below + 1];
        } else {
            // The texels depth_at would read, each coordinate resolved once.
            let (xa, xb) = edges.resolve_pair(x, f.width());
            let (ya, yb) = edges.resolve_pair(y, f.height());
            let (xa, xb, ya, yb) = (xa as usize, xb as usize, ya as usize, yb as usize);
            let (d, w) = (f.depths(), f.width() as usize);
            c[0][i] = d[ya * w + xa];
            c[1][i] = d[ya * w + xb];
            c[2][i] = d[yb * w + xa];
            c[3][i] = d[yb * w + xb];
        }
    }
    let [d00, d10, d01, d11] = c.map(|a| vec(simd, a));
    let top = d00 + (d10 - d00) * fx;
    let bottom = d01 + (d11 - d01) * fx;
    top + (bottom - top) * fy
}

/// [`line_intersection`] in every lane.
#[inline(always)]
fn lines<S: Simd>(t0: f32x8<S>, d0: f32x8<S>, t1: f32x8<S>, d1: f32x8<S>) -> f32x8<S> {
    let a = d0 - t0;
    let b = t1 - d1;
    let denom = a + b;
    denom.simd_gt(0.0).select(t0 + (t1 - t0) * (a / denom), t1)
}

/// Entering rays of a packet: per lane the entry point (reduced to its tile), the unit
/// direction and the UV step per unit of depth.
struct Rays<S: Simd> {
    u0: f32x8<S>,
    v0: f32x8<S>,
    su: f32x8<S>,
    sv: f32x8<S>,
    live: [bool; LANES],
}

/// Traces up to eight rays with `technique` on `surface`, each at its own mip level `lods[i]`
/// (the other parameters shared): lane `i` of the answer is
/// `trace(surface, rays[i], technique, &TraceParams { lod: lods[i], ..*params })`, bit for bit,
/// and `None` where `rays[i]` is.
#[inline(always)]
pub fn trace_packet<S: Simd>(
    simd: S,
    surface: &Surface,
    rays: &[Option<Ray>; LANES],
    technique: Technique,
    params: &TraceParams,
    lods: [f32; LANES],
) -> [Option<Hit>; LANES] {
    let mut out = [None; LANES];
    // trace()'s checks, lane by lane.
    let mut starts = [None; LANES];
    let mut p = [*params; LANES];
    for i in 0..LANES {
        let Some(ray) = rays[i] else { continue };
        p[i] = TraceParams { lod: lods[i], ..*params }.sanitized();
        let uv0 = if ray.uv.is_finite() { ray.uv } else { Vec2::ZERO };
        let none = Hit { uv: uv0, depth: 0.0, fetches: 0 };
        match entering(ray.dir) {
            None => out[i] = Some(none),
            Some(dir) => {
                let (reduced, tile) = reduce_to_tile(uv0, surface.edges);
                starts[i] = Some((reduced, dir, tile));
            }
        }
    }
    let marching = matches!(
        technique,
        Technique::Parallax
            | Technique::Iterative
            | Technique::Steep
            | Technique::PomClassic
            | Technique::Pom
            | Technique::Relief
    );
    if !marching {
        for i in 0..LANES {
            if let Some((uv, dir, tile)) = starts[i] {
                let hit = trace_entering(surface, uv, dir, technique, &p[i]);
                out[i] = Some(Hit { uv: unreduce(hit.uv, tile), ..hit });
            }
        }
        return out;
    }
    let q = p.iter().zip(&starts).find(|(_, s)| s.is_some()).map_or(params.sanitized(), |(p, _)| *p);
    let lods = p.map(|p| p.lod);
    let hits = march_packet(simd, surface, &starts.map(|s| s.map(|(uv, dir, _)| (uv, dir))), technique, &q, lods);
    for i in 0..LANES {
        if let (Some((_, _, tile)), Some(hit)) = (starts[i], hits[i]) {
            out[i] = Some(Hit { uv: unreduce(hit.uv, tile), ..hit });
        }
    }
    out
}

/// The marching techniques for entering rays `(uv0, unit dir)` and sanitized parameters, as
/// `march` with the straight profile.
#[inline(always)]
fn march_packet<S: Simd>(
    simd: S,
    surface: &Surface,
    starts: &[Option<(Vec2, Vec3)>; LANES],
    technique: Technique,
    p: &TraceParams,
    lods: [f32; LANES],
) -> [Option<Hit>; LANES] {
    let ds = surface.depth_scale;
    let live = starts.map(|s| s.is_some());
    let uv0 = starts.map(|s| s.map_or(Vec2::ZERO, |(uv, _)| uv));
    let dirs = starts.map(|s| s.map_or(-Vec3::Z, |(_, d)| d));
    let s = dirs.map(|d| uv_per_depth(d, ds));
    let rays = Rays {
        u0: vec(simd, uv0.map(|v| v.x)),
        v0: vec(simd, uv0.map(|v| v.y)),
        su: vec(simd, s.map(|v| v.x)),
        sv: vec(simd, s.map(|v| v.y)),
        live,
    };
    let mut out = [None; LANES];
    match technique {
        Technique::Parallax => {
            let mips = Levels::new(&surface.mips, lods, surface.edges);
            let d = array(mips.sample(simd, rays.u0, rays.v0));
            for i in 0..LANES {
                if live[i] {
                    let offset = Vec2::new(dirs[i].x, dirs[i].y) * (d[i] * ds);
                    out[i] = Some(hit_on_ray(uv0[i], s[i], offset, d[i] * -dirs[i].z, 1));
                }
            }
        }
        Technique::Iterative => {
            let k = p.iterations;
            let par = Levels::new(surface.parallax_mips(), lods, surface.edges);
            let step = dirs.map(|d| Vec2::new(d.x, d.y) * (ds / k as f32));
            let (stu, stv) = (vec(simd, step.map(|v| v.x)), vec(simd, step.map(|v| v.y)));
            let (mut u, mut v) = (rays.u0, rays.v0);
            let mut sum = splat(simd, 0.0);
            for _ in 0..k {
                let value = par.sample(simd, u, v);
                sum += value;
                u += stu * value;
                v += stv * value;
            }
            let (u, v, sum) = (array(u), array(v), array(sum));
            for i in 0..LANES {
                if live[i] {
                    let uv = Vec2::new(u[i], v[i]);
                    out[i] = Some(hit_on_ray(uv0[i], s[i], uv - uv0[i], sum[i] / k as f32 * -dirs[i].z, k));
                }
            }
        }
        Technique::Steep => steep(simd, surface, &rays, p, lods, &mut out),
        Technique::PomClassic => pom_classic(simd, surface, &rays, &dirs, p, lods, &mut out),
        Technique::Pom => pom(simd, surface, &rays, &dirs, p, lods, &mut out),
        Technique::Relief => relief(simd, surface, &rays, p, lods, &mut out),
        Technique::Flat | Technique::Normal | Technique::Exact | Technique::Cone => {
            for i in 0..LANES {
                if let Some((uv, dir)) = starts[i] {
                    out[i] = Some(trace_entering(surface, uv, dir, technique, &TraceParams { lod: lods[i], ..*p }));
                }
            }
        }
    }
    out
}

/// The hits of lanes `live` at depths `z` along the rays (`uv0 + s * z`), with their fetches.
fn hits_at<S: Simd>(rays: &Rays<S>, z: [f32; LANES], fetches: [u32; LANES], out: &mut [Option<Hit>; LANES]) {
    let (u0, v0, su, sv) = (array(rays.u0), array(rays.v0), array(rays.su), array(rays.sv));
    for i in 0..LANES {
        if rays.live[i] {
            let uv = Vec2::new(u0[i], v0[i]) + Vec2::new(su[i], sv[i]) * z[i];
            out[i] = Some(Hit { uv, depth: z[i], fetches: fetches[i] });
        }
    }
}

/// Adds one fetch to the lanes of `m`.
#[inline(always)]
fn count(fetches: &mut [u32; LANES], m: [bool; LANES]) {
    for i in 0..LANES {
        fetches[i] += u32::from(m[i]);
    }
}

/// Steep parallax: the first of `n` depth planes at or below the surface.
#[inline(always)]
fn steep<S: Simd>(
    simd: S,
    surface: &Surface,
    rays: &Rays<S>,
    p: &TraceParams,
    lods: [f32; LANES],
    out: &mut [Option<Hit>; LANES],
) {
    let mips = Levels::new(&surface.mips, lods, surface.edges);
    let n = p.samples;
    let mut active = mask(simd, rays.live);
    let mut z = [1.0f32; LANES];
    let mut fetches = [0u32; LANES];
    for i in 0..n {
        if !active.any_true() {
            break;
        }
        let t = i as f32 / n as f32;
        let d = mips.sample(simd, rays.u0 + rays.su * t, rays.v0 + rays.sv * t);
        count(&mut fetches, bools(active));
        let hit = active & d.simd_le(t);
        for (k, h) in bools(hit).into_iter().enumerate() {
            if h {
                z[k] = t;
            }
        }
        active &= !hit;
    }
    hits_at(rays, z, fetches, out);
}

/// Brawley & Tatarchuk's eight samples along the biased parallax vector.
#[inline(always)]
fn pom_classic<S: Simd>(
    simd: S,
    surface: &Surface,
    rays: &Rays<S>,
    dirs: &[Vec3; LANES],
    p: &TraceParams,
    lods: [f32; LANES],
    out: &mut [Option<Hit>; LANES],
) {
    let mips = Levels::new(&surface.mips, lods, surface.edges);
    let s = dirs.map(|d| {
        let cos = -d.z;
        let bias = (p.perspective_bias + (1.0 - p.perspective_bias) * (2.0 * cos - 1.0)).max(0.0);
        uv_per_depth(d, surface.depth_scale) * bias
    });
    let biased = Rays {
        u0: rays.u0,
        v0: rays.v0,
        su: vec(simd, s.map(|v| v.x)),
        sv: vec(simd, s.map(|v| v.y)),
        live: rays.live,
    };
    let n = 8u32;
    let mut active = mask(simd, rays.live);
    let mut z = [1.0f32; LANES];
    let (mut prev_t, mut prev_d) = (splat(simd, 0.0), splat(simd, 0.0));
    for i in 1..=n {
        if !active.any_true() {
            break;
        }
        let t = i as f32 / n as f32;
        let d = mips.sample(simd, biased.u0 + biased.su * t, biased.v0 + biased.sv * t);
        if i == 1 {
            prev_d = d;
        }
        let hit = active & d.simd_le(t);
        if hit.any_true() {
            let zi = array(lines(prev_t, prev_d.max(prev_t), splat(simd, t), d));
            for (k, h) in bools(hit).into_iter().enumerate() {
                if h {
                    z[k] = zi[k];
                }
            }
        }
        active &= !hit;
        prev_t = splat(simd, t);
        prev_d = d;
    }
    hits_at(&biased, z, [n; LANES], out);
}

/// Zink / Tatarchuk's POM: adaptive sample counts per lane, early exit, secant refinement.
#[inline(always)]
fn pom<S: Simd>(
    simd: S,
    surface: &Surface,
    rays: &Rays<S>,
    dirs: &[Vec3; LANES],
    p: &TraceParams,
    lods: [f32; LANES],
    out: &mut [Option<Hit>; LANES],
) {
    let mips = Levels::new(&surface.mips, lods, surface.edges);
    let n = dirs.map(|d| adaptive_samples(-d.z, p.min_samples, p.max_samples));
    let step = vec(simd, n.map(|n| 1.0 / n as f32));
    let nf = vec(simd, n.map(|n| n as f32));
    let most = n.iter().zip(&rays.live).filter(|(_, l)| **l).map(|(n, _)| *n).max().unwrap_or(0);
    let mut fetches = [1u32; LANES];
    let mut z = [0.0f32; LANES];
    let (mut a_t, mut a_d) = (splat(simd, 0.0), mips.sample(simd, rays.u0, rays.v0));
    // The entry sample at or above the surface: the hit is the entry point.
    let entry = mask(simd, rays.live) & a_d.simd_le(0.0);
    let mut active = mask(simd, rays.live) & !entry;
    let mut bracketed = entry;
    let (mut b_t, mut b_d) = (splat(simd, 1.0), splat(simd, 1.0));
    for i in 1..=most {
        if !active.any_true() {
            break;
        }
        let fi = i as f32;
        // The lanes still searching whose count reaches i; the last sample lies at t = 1.
        active &= nf.simd_ge(fi);
        let t = nf.simd_eq(fi).select(splat(simd, 1.0), step * fi);
        let d = mips.sample(simd, rays.u0 + rays.su * t, rays.v0 + rays.sv * t);
        count(&mut fetches, bools(active));
        let hit = active & d.simd_le(t);
        b_t = hit.select(t, b_t);
        b_d = hit.select(d, b_d);
        bracketed |= hit;
        let go_on = active & !hit;
        a_t = go_on.select(t, a_t);
        a_d = go_on.select(d, a_d);
        active = go_on;
    }
    let found = bracketed & !entry;
    let mut zv = lines(a_t, a_d, b_t, b_d);
    let refining = found;
    for _ in 0..p.refine {
        let d = mips.sample(simd, rays.u0 + rays.su * zv, rays.v0 + rays.sv * zv);
        count(&mut fetches, bools(refining));
        let above = refining & d.simd_gt(zv);
        let below = refining & !above;
        a_t = above.select(zv, a_t);
        a_d = above.select(d, a_d);
        b_t = below.select(zv, b_t);
        b_d = below.select(d, b_d);
        zv = refining.select(lines(a_t, a_d, b_t, b_d), zv);
    }
    let (found, entry, zv) = (bools(found), bools(entry), array(zv));
    for k in 0..LANES {
        z[k] = if entry[k] {
            0.0
        } else if found[k] {
            zv[k]
        } else {
            // No bracket (unreachable for depths in [0, 1]): the bottom of the segment.
            1.0
        };
    }
    hits_at(rays, z, fetches, out);
}

/// Relief mapping: `n` planes of linear search, then binary refinement.
#[inline(always)]
fn relief<S: Simd>(
    simd: S,
    surface: &Surface,
    rays: &Rays<S>,
    p: &TraceParams,
    lods: [f32; LANES],
    out: &mut [Option<Hit>; LANES],
) {
    let mips = Levels::new(&surface.mips, lods, surface.edges);
    let n = p.samples;
    let mut fetches = [0u32; LANES];
    let (mut lo, mut hi) = (splat(simd, 0.0), splat(simd, 1.0));
    let mut active = mask(simd, rays.live);
    for i in 1..n {
        if !active.any_true() {
            break;
        }
        let t = i as f32 / n as f32;
        count(&mut fetches, bools(active));
        let d = mips.sample(simd, rays.u0 + rays.su * t, rays.v0 + rays.sv * t);
        let hit = active & d.simd_le(t);
        hi = hit.select(splat(simd, t), hi);
        let go_on = active & !hit;
        lo = go_on.select(splat(simd, t), lo);
        active = go_on;
    }
    for _ in 0..p.binary_steps {
        let mid = (lo + hi) * 0.5;
        let d = mips.sample(simd, rays.u0 + rays.su * mid, rays.v0 + rays.sv * mid);
        let below = d.simd_le(mid);
        hi = below.select(mid, hi);
        lo = below.select(lo, mid);
    }
    count_n(&mut fetches, p.binary_steps);
    let z = if p.binary_steps > 0 { array((lo + hi) * 0.5) } else { array(hi) };
    hits_at(rays, z, fetches, out);
}

fn count_n(fetches: &mut [u32; LANES], n: u32) {
    for f in fetches {
        *f += n;
    }
}

/// Marches up to eight hard or soft shadow rays on `surface` at once: lane `i` of the answer is
/// `marches[i].run(surface)` ([`ShadowMarch::run`]), bit for bit.
#[inline(always)]
pub fn shadow_marches<S: Simd>(
    simd: S,
    surface: &Surface,
    marches: &[Option<ShadowMarch>; LANES],
) -> [Option<Shadow>; LANES] {
    let live = marches.map(|m| m.is_some());
    let m = marches.map(|m| m.unwrap_or(ShadowMarch { n: 1, ..IDLE }));
    let mips = Levels::new(&surface.mips, m.map(|m| m.lod), surface.edges);
    let most = m.iter().map(|m| m.n).max().unwrap_or(1);
    let (u0, v0) = (vec(simd, m.map(|m| m.uv.x)), vec(simd, m.map(|m| m.uv.y)));
    let (su, sv) = (vec(simd, m.map(|m| m.s.x)), vec(simd, m.map(|m| m.s.y)));
    let depth = vec(simd, m.map(|m| m.depth));
    let nf = vec(simd, m.map(|m| m.n as f32));
    let soft = mask(simd, m.map(|m| m.soft));
    let mut slope = splat(simd, f32::NEG_INFINITY);
    let mut blocked = mask(simd, [false; LANES]);
    let mut active = mask(simd, live);
    // The receiver's lift, made by `shadow_start`.
    let mut fetches = [1u32; LANES];
    for i in 1..most {
        let fi = i as f32;
        active &= nf.simd_gt(fi);
        if !active.any_true() {
            break;
        }
        let t = depth * fi / nf;
        let d = mips.sample(simd, u0 + su * t, v0 + sv * t);
        count(&mut fetches, bools(active));
        let steeper = active & soft;
        slope = steeper.select(slope.max((depth - d) / t), slope);
        // Hard: a sample above the ray ends the lane's march in shadow.
        let hits = active & !soft & d.simd_lt(depth - t - 1e-5);
        blocked |= hits;
        active &= !hits;
    }
    let (slope, blocked) = (array(slope), bools(blocked));
    let mut out = [None; LANES];
    for i in 0..LANES {
        if live[i] {
            let visibility = if m[i].soft {
                m[i].soft_visibility(slope[i])
            } else if blocked[i] {
                0.0
            } else {
                1.0
            };
            out[i] = Some(Shadow { visibility, fetches: fetches[i] });
        }
    }
    out
}

/// The march of an idle lane: no sample.
const IDLE: ShadowMarch = ShadowMarch {
    uv: Vec2::ZERO,
    depth: 0.0,
    s: Vec2::ZERO,
    n: 1,
    soft: false,
    tan_theta: 0.0,
    light_elevation: 0.0,
    rho: 1.0,
    lod: 0.0,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accuracy::{SplitMix64, analytic_fields};
    use crate::procedural::{Pattern, generate};
    use crate::shadow::{ShadowMode, ShadowParams, ShadowStart, shadow_start};
    use crate::trace::trace;
    use fearless_simd::{Level, dispatch};

    /// Both levels this machine runs: the one detected, and the scalar fallback.
    fn levels() -> [Level; 2] {
        [Level::new(), Level::fallback()]
    }

    fn surfaces() -> Vec<(String, Surface)> {
        let mut out = Vec::new();
        let mut fields = analytic_fields(16);
        fields.push(("cobbles", generate(Pattern::Cobblestones, 64, 48)));
        fields.push(("one texel", HeightField::constant(1, 1, 0.4)));
        for (name, f) in fields {
            for edges in EdgeMode::ALL {
                for ds in [0.05, 0.3] {
                    out.push((format!("{name} {edges:?} {ds}"), Surface::new(f.clone(), edges, ds)));
                }
            }
        }
        out
    }

    /// Eight rays: mostly entering at random angles and places (some far outside the tile),
    /// and some lanes empty, leaving, straight down or not finite.
    fn packet(rng: &mut SplitMix64) -> ([Option<Ray>; LANES], [f32; LANES]) {
        let mut rays = [None; LANES];
        let mut lods = [0.0; LANES];
        for i in 0..LANES {
            let angle = rng.next_f32() * 1.55;
            let mut ray = Ray::at_angle(
                Vec2::new(rng.next_f32() * 3.0 - 1.0, rng.next_f32() * 3.0 - 1.0),
                angle,
                rng.next_f32() * std::f32::consts::TAU,
            );
            match (rng.next_u64() % 16) as u32 {
                0 => continue,
                1 => ray.dir.z = -ray.dir.z,
                2 => ray.dir = -Vec3::Z,
                3 => ray.uv = Vec2::new(f32::NAN, 0.5),
                4 => ray.uv *= 1e6,
                _ => {}
            }
            rays[i] = Some(ray);
            lods[i] = match rng.next_u64() % 4 {
                0 => 0.0,
                1 => rng.next_f32() * 3.0,
                2 => 100.0,
                _ => rng.next_f32(),
            };
        }
        (rays, lods)
    }

    #[test]
    fn packets_trace_every_technique_as_single_rays_do_bit_for_bit() {
        let mut rng = SplitMix64::new(7);
        let params = TraceParams { refine: 3, ..TraceParams::default() };
        for (name, surface) in surfaces() {
            for technique in Technique::ALL {
                for _ in 0..6 {
                    let (rays, lods) = packet(&mut rng);
                    for level in levels() {
                        let got =
                            dispatch!(level, simd => trace_packet(simd, &surface, &rays, technique, &params, lods));
                        for i in 0..LANES {
                            let want = rays[i]
                                .map(|r| trace(&surface, &r, technique, &TraceParams { lod: lods[i], ..params }));
                            assert_eq!(got[i], want, "{name}, {technique}, lane {i}, {level:?}: {:?}", rays[i]);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn packets_march_hard_and_soft_shadows_as_single_rays_do_bit_for_bit() {
        let mut rng = SplitMix64::new(11);
        let mut marched = 0;
        for (name, surface) in surfaces() {
            for mode in [ShadowMode::Hard, ShadowMode::Soft] {
                let sp = ShadowParams { mode, softness: 0.1 };
                for _ in 0..8 {
                    let (rays, lods) = packet(&mut rng);
                    let mut marches = [None; LANES];
                    let mut want = [None; LANES];
                    for i in 0..LANES {
                        let Some(r) = rays[i] else { continue };
                        let light = Vec3::new(r.dir.x, r.dir.y, -r.dir.z);
                        let depth = rng.next_f32();
                        let p = TraceParams { lod: lods[i], ..TraceParams::default() };
                        if let ShadowStart::March(m) = shadow_start(&surface, r.uv, depth, light, &sp, &p) {
                            marches[i] = Some(m);
                            want[i] = Some(crate::shadow::shadow(&surface, r.uv, depth, light, &sp, &p));
                            marched += 1;
                        }
                    }
                    for level in levels() {
                        let got = dispatch!(level, simd => shadow_marches(simd, &surface, &marches));
                        assert_eq!(got, want, "{name}, {mode:?}, {level:?}");
                    }
                }
            }
        }
        assert!(marched > 1000, "only {marched} shadow rays marched");
    }

    #[test]
    fn soft_shadows_keep_the_darkest_sample_of_the_elevation_form() {
        // The steepest slope's elevation is the highest elevation: the visibility of the one
        // arctangent equals the darkest of the per-sample ones, within float rounding.
        let surface = Surface::new(generate(Pattern::Cobblestones, 64, 64), EdgeMode::Wrap, 0.1);
        let mut rng = SplitMix64::new(3);
        let sp = ShadowParams { mode: ShadowMode::Soft, softness: 0.1 };
        let mut compared = 0;
        for _ in 0..2000 {
            let uv = Vec2::new(rng.next_f32(), rng.next_f32());
            let light = Ray::at_angle(uv, rng.next_f32() * 1.5, rng.next_f32() * std::f32::consts::TAU).dir
                * Vec3::new(1.0, 1.0, -1.0);
            let depth = 0.05 + 0.95 * rng.next_f32();
            let ShadowStart::March(m) = shadow_start(&surface, uv, depth, light, &sp, &TraceParams::default()) else {
                continue;
            };
            let mut darkest = 1.0f32;
            for i in 1..m.n {
                let t = m.climbed(i);
                let d = surface.depth(m.uv + m.s * t, m.lod);
                let elevation = (m.depth - d).atan2(t * m.tan_theta);
                darkest = darkest.min((0.5 - (elevation - m.light_elevation) / (2.0 * m.rho)).clamp(0.0, 1.0));
            }
            let got = m.run(&surface).visibility;
            assert!((got - darkest).abs() < 1e-4, "{got} against {darkest} at {uv}, light {light}");
            compared += 1;
        }
        assert!(compared > 1500);
    }
}
