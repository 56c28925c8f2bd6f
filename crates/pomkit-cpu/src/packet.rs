//! Packets: up to eight fragments of one material shaded together. Their view rays are
//! traced as a packet and their shadow rays marched as packets ([`pomkit_core::trace::packet`]),
//! their textures filtered and lit in SIMD ([`crate::shade8`]); every lane gets what
//! [`crate::fragment::shade`] gives its fragment alone, bit for bit.

use fearless_simd::{Simd, dispatch};
use glam::{Vec2, Vec3};
use pomkit_core::scene::Scene;
use pomkit_core::shadow::{Shadow, ShadowStart, lod_weight, shadow_start};
use pomkit_core::trace::packet::{self, LANES};
use pomkit_core::trace::{Ray, TraceParams};

use crate::Sample;
use crate::fragment::{
    Lane, Shading, albedo_level, begin_into, depth_offset, is_fading, level_of, needs_trace, shade, shadow_ray,
    take_hit, texture_uv,
};
use crate::prepare::Prepared;
use crate::raster::Fragment;
use crate::shade8;

/// Up to [`LANES`] fragments of one material waiting to be shaded, and the samples they go to.
#[derive(Default)]
pub(crate) struct Packet {
    /// The fragments (the first `written`; the rest are scratch for the next ones).
    frags: Vec<Fragment>,
    written: usize,
    slots: [usize; LANES],
    /// Scratch: each light's shadows of the packet.
    shadows: Vec<[Option<Shadow>; LANES]>,
}

impl Packet {
    /// Adds fragment `f` for sample `slot`; true when the packet is full.
    pub(crate) fn push(&mut self, f: Fragment, slot: usize) -> bool {
        *self.slot() = f;
        self.commit(slot)
    }

    /// Where the packet's next fragment is written (then [`Packet::commit`]).
    pub(crate) fn slot(&mut self) -> &mut Fragment {
        if self.frags.len() == self.written {
            self.frags.push(Fragment::default());
        }
        &mut self.frags[self.written]
    }

    /// Takes the fragment written to [`Packet::slot`] into the packet, for sample `slot`; true
    /// when the packet is full.
    pub(crate) fn commit(&mut self, slot: usize) -> bool {
        self.slots[self.written] = slot;
        self.written += 1;
        self.written == LANES
    }

    /// Shades the packet's fragments ([`shade_packet`], or one at a time for
    /// [`Simd8::unpacked`](crate::Simd8::unpacked)) and writes those nearer than what `buf`
    /// holds; empties the packet.
    pub(crate) fn shade_into(&mut self, scene: &Scene, prep: &Prepared, shading: Shading, buf: &mut [Option<Sample>]) {
        if self.written == 0 {
            return;
        }
        let frags = &self.frags[..self.written];
        let mut out = [None; LANES];
        let level = shading.level;
        if shading.packets {
            let shadows = &mut self.shadows;
            dispatch!(level, simd => shade_packet(simd, scene, prep, &shading, frags, shadows, &mut out));
        } else {
            for (o, f) in out.iter_mut().zip(frags) {
                *o = shade(scene, prep, &shading, f);
            }
        }
        for (k, s) in out.into_iter().enumerate().take(frags.len()) {
            // A silhouette pixel whose ray leaves the relief is discarded: it writes nothing.
            let Some(mut s) = s else { continue };
            if shading.lod_tint && prep.lod_basis.is_some() {
                let w = lod_weight(s.lod, prep.material.lod_threshold);
                let tint = Vec3::new(1.0, 0.25, 0.2).lerp(Vec3::new(0.25, 1.0, 0.3), w);
                s.color = s.color * 0.5 + tint * 0.5 * s.color.length().max(0.05);
            }
            let slot = &mut buf[self.slots[k]];
            if slot.is_none_or(|old| s.z < old.z) {
                *slot = Some(s);
            }
        }
        self.written = 0;
    }
}

/// `level(f)` for each of `frags`, computed once per quad: the fragments of a quad share their
/// UV gradients, and consecutive fragments with the same gradients get the same value.
fn per_quad<T: Copy + Default>(frags: &[Fragment], level: impl Fn(&Fragment) -> T) -> [T; LANES] {
    let mut out = [T::default(); LANES];
    let mut last: Option<(Vec2, Vec2, T)> = None;
    for (o, f) in out.iter_mut().zip(frags) {
        *o = match last {
            Some((dx, dy, v)) if dx == f.duv_dx && dy == f.duv_dy => v,
            _ => level(f),
        };
        last = Some((f.duv_dx, f.duv_dy, *o));
    }
    out
}

/// Up to [`LANES`] fragments of one triangle shaded at once: their view rays traced as a
/// packet ([`pomkit_core::trace::packet`]) and their hard and soft shadow rays marched as
/// packets, the rest lane by lane. Lane `i` of `out` is `shade(scene, prep, &frags[i])`, bit
/// for bit (the packet tracers are the single-ray ones).
#[inline(always)]
pub(crate) fn shade_packet<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    frags: &[Fragment],
    shadows: &mut Vec<[Option<Shadow>; LANES]>,
    out: &mut [Option<Sample>; LANES],
) {
    if prep.has_silhouettes() {
        // Curved rays: one at a time.
        for (o, f) in out.iter_mut().zip(frags) {
            *o = shade(scene, prep, shading, f);
        }
        return;
    }
    let mut lanes = [Lane::default(); LANES];
    let (rays, lods) = begin_packet(simd, scene, prep, frags, &mut lanes);
    if let Some(surface) = prep.surface.as_deref()
        && rays.iter().any(Option::is_some)
    {
        let hits = packet::trace_packet(simd, surface, &rays, prep.technique, &prep.params, lods);
        for (lane, hit) in lanes.iter_mut().zip(&hits) {
            if let Some(hit) = hit {
                take_hit(prep, surface, lane, hit);
            }
        }
    }
    trace_shadows(simd, scene, prep, frags, &lanes, shadows);
    finish_packet(simd, scene, prep, shading, frags, &lanes, shadows, out);
}

/// [`begin_into`] for every fragment of a packet into `lanes`, with the normalizations of
/// [`crate::fragment::shade`]'s `begin` computed for all lanes at once (the same operations as
/// glam's); returns each lane's view ray where it is traced, and its mip level.
#[inline(always)]
fn begin_packet<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    frags: &[Fragment],
    lanes: &mut [Lane; LANES],
) -> ([Option<Ray>; LANES], [f32; LANES]) {
    let mut rays = [None; LANES];
    let mut lods = [0.0; LANES];
    let levels = per_quad(frags, |f| level_of(prep, f));
    let frag = |i: usize| frags.get(i).unwrap_or(&frags[0]);
    let normals = shade8::V3::from_lanes(simd, &std::array::from_fn(|i| frag(i).v.normal))
        .normalize_or(shade8::V3::splat(simd, Vec3::Z));
    let worlds = shade8::V3::from_lanes(simd, &std::array::from_fn(|i| frag(i).v.world));
    let to_eye = shade8::V3::splat(simd, scene.camera.eye).sub(worlds).normalize_or(normals);
    let (normals, to_eye) = (normals.lanes(), to_eye.lanes());
    for (i, f) in frags.iter().enumerate() {
        let lane = &mut lanes[i];
        begin_into(lane, prep, f, levels[i], normals[i], to_eye[i]);
        if needs_trace(prep, lane) {
            rays[i] = Some(Ray::new(f.v.uv, lane.dir));
        }
        lods[i] = lane.lod;
    }
    (rays, lods)
}

/// Every light's shadow rays from the packet's lanes (traced to their hits) into `shadows`
/// (`shadows[light][lane]`, `None` where a lane traces none): a packet per light, the hard and
/// soft ones marched together.
#[inline(always)]
fn trace_shadows<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    frags: &[Fragment],
    lanes: &[Lane; LANES],
    shadows: &mut Vec<[Option<Shadow>; LANES]>,
) {
    let m = &prep.material;
    shadows.clear();
    for light in scene.lights.iter() {
        let Some(surface) = prep.surface.as_deref() else { break };
        let mut done = [None; LANES];
        let mut marches = [None; LANES];
        for (i, (lane, f)) in lanes.iter().zip(frags).enumerate() {
            let Some(lt) = shadow_ray(prep, lane, f, light) else { continue };
            let p = TraceParams { lod: lane.lod, ..prep.params };
            match shadow_start(surface, lane.hit_uv, lane.hit_depth, lt, &m.shadow, &p) {
                ShadowStart::Done(s) => done[i] = Some(s),
                ShadowStart::March(march) => marches[i] = Some(march),
            }
        }
        if marches.iter().any(Option::is_some) {
            let marched = packet::shadow_marches(simd, surface, &marches);
            for (d, s) in done.iter_mut().zip(marched) {
                if s.is_some() {
                    *d = s;
                }
            }
        }
        shadows.push(done);
    }
}

/// `fragment::finish` for a packet of fragments (`lanes[i]` begun for every `frags[i]`), with
/// the shadows already traced (`shadows[light][lane]`): the texture filtering and lighting run
/// on all lanes at once ([`shade8`]), the pixel depth offset lane by lane.
#[expect(clippy::too_many_arguments, reason = "a packet's fragments, their state and the frame")]
#[inline(always)]
fn finish_packet<S: Simd>(
    simd: S,
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    frags: &[Fragment],
    lanes: &[Lane; LANES],
    shadows: &[[Option<Shadow>; LANES]],
    out: &mut [Option<Sample>; LANES],
) {
    if frags.is_empty() {
        return;
    }
    // Lanes past the packet's fragments repeat the first (their results are not used).
    let lane = |i: usize| -> &Lane { if i < frags.len() { &lanes[i] } else { &lanes[0] } };
    let frag = |i: usize| frags.get(i).unwrap_or(&frags[0]);
    let pick = |g: fn(&Lane) -> Vec3| shade8::V3::from_lanes(simd, &std::array::from_fn(|i| g(lane(i))));
    let edges = prep.edges;
    let inputs = shade8::LitInputs {
        n: pick(|l| l.n),
        t: pick(|l| l.t),
        b: pick(|l| l.b),
        to_eye: pick(|l| l.to_eye),
        world: std::array::from_fn(|i| frag(i).v.world),
        albedo_lods: per_quad(frags, |f| albedo_level(&prep.albedo, f.duv_dx, f.duv_dy)),
        shadows,
    };
    let weight: [f32; LANES] = std::array::from_fn(|i| lane(i).weight);
    let with_shadows: [bool; LANES] = std::array::from_fn(|i| prep.casts_shadows() && weight[i] > 0.0);
    let hit_uv: [Vec2; LANES] = std::array::from_fn(|i| texture_uv(lane(i).hit_uv, edges));
    let (full, vis, shadow_fetches) = shade8::lit(simd, scene, prep, &inputs, &hit_uv, with_shadows);
    // The LOD fade's normal-mapped fallback, where it differs from the full result.
    let simple: [bool; LANES] = std::array::from_fn(|i| is_fading(prep, lane(i), frag(i), with_shadows[i]));
    let color = if simple.contains(&true) {
        let uv: [Vec2; LANES] = std::array::from_fn(|i| texture_uv(frag(i).v.uv, edges));
        let (plain, _, _) = shade8::lit(simd, scene, prep, &inputs, &uv, [false; LANES]);
        let faded = plain.lerp(full, packet::vec(simd, weight));
        shade8::V3::select(packet::mask(simd, simple), faded, full)
    } else {
        full
    };
    let color = color.lanes();
    for (i, f) in frags.iter().enumerate() {
        let l = lane(i);
        out[i] = Some(Sample {
            color: color[i],
            z: depth_offset(prep, shading, f, l),
            uv: l.hit_uv,
            depth: l.hit_depth,
            shadow: vis[i],
            fetches: (l.fetches + shadow_fetches[i]) as f32,
            lod: l.lod,
        });
    }
}
