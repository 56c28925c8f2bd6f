//! The fragment stage, one fragment at a time: the tangent frame and view ray ([`Lane`]), the
//! mip level and the LOD fade, the trace of the material's technique, the textures at the hit,
//! Blinn-Phong lighting with the normal map and self-shadows, and the pixel depth offset.
//! [`crate::packet`] runs the same stage on eight fragments at once, bit for bit.

use fearless_simd::Level;
use glam::{Mat4, Vec2, Vec3, Vec4};
use pomkit_core::heightfield::floor;
use pomkit_core::mesh::TangentMap;
use pomkit_core::scene::{Light, Scene, Texture};
use pomkit_core::shadow::{Shadow, ShadowMode, lod_weight, shadow};
use pomkit_core::silhouette::{trace_curved, view_curvature};
use pomkit_core::trace::{Hit, Ray, Surface, Technique, TraceParams, trace};
use pomkit_core::{EdgeMode, mip_level_from_gradients};

use crate::Sample;
use crate::prepare::Prepared;
use crate::raster::Fragment;

/// How the fragments of a frame are shaded: the SIMD level of the packets, and the LOD tint.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shading {
    pub(crate) level: Level,
    /// Packets of eight fragments, or one fragment at a time
    /// ([`Simd8::unpacked`](crate::Simd8::unpacked)).
    pub(crate) packets: bool,
    /// Every fragment's depth is its polygon's and none is discarded (no pixel depth offset, no
    /// silhouettes): each tile finds its visible fragments first and shades only those.
    pub(crate) visibility_first: bool,
    pub(crate) lod_tint: bool,
    /// Occlusion culling of streamed blocks and back-face culling of their triangles before
    /// set-up ([`CpuRenderer::with_block_culling`](crate::CpuRenderer::with_block_culling)).
    pub(crate) cull_blocks: bool,
    /// The camera's view-projection at aspect 1, for the pixel depth offset (NDC depth does not
    /// depend on the aspect).
    pub(crate) depth_matrix: Mat4,
}

/// A fragment's state between the stages of [`shade`]: its tangent frame, view ray and level of
/// detail, and where its ray met the relief.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Lane {
    pub(crate) n: Vec3,
    pub(crate) t: Vec3,
    pub(crate) b: Vec3,
    pub(crate) tangent: Vec4,
    pub(crate) to_eye: Vec3,
    /// Mip level of the height map, and the weight of the full technique in the LOD fade.
    pub(crate) lod: f32,
    pub(crate) weight: f32,
    /// World directions to tangent space (where a ray is traced), and the view ray there.
    pub(crate) map: Option<TangentMap>,
    pub(crate) dir: Vec3,
    pub(crate) hit_uv: Vec2,
    pub(crate) hit_depth: f32,
    /// How deep the hit lies along the view ray (pixel depth offset).
    pub(crate) ray_depth: f32,
    pub(crate) fetches: u32,
}

/// The fragment stage up to the trace: the tangent frame, the eye direction, the mip level and
/// the view ray.
fn begin(scene: &Scene, prep: &Prepared, f: &Fragment, levels: (f32, f32)) -> Lane {
    let n = f.v.normal.try_normalize().unwrap_or(Vec3::Z);
    let to_eye = (scene.camera.eye - f.v.world).try_normalize().unwrap_or(n);
    let mut lane = Lane::default();
    begin_into(&mut lane, prep, f, levels, n, to_eye);
    lane
}

/// [`begin`] into `lane`, from the fragment's unit normal `n` and eye direction `to_eye` (which
/// a packet computes for all its lanes at once,
/// [`shade_packet`](crate::packet::shade_packet)). It writes the lane field by field, where a
/// packet keeps it: a whole `Lane` built aside and copied in cost a store forwarding stall per
/// lane.
#[inline(always)]
pub(crate) fn begin_into(
    lane: &mut Lane,
    prep: &Prepared,
    f: &Fragment,
    (lod, weight): (f32, f32),
    n: Vec3,
    to_eye: Vec3,
) {
    let v = &f.v;
    // Tangent frame, re-orthonormalized after interpolation (Lengyel Listing 7.8).
    // `flat` reads none of the frame but the normal (no normal map, no ray in tangent space).
    let (t, b, tangent) = if prep.technique == Technique::Flat {
        (Vec3::ZERO, Vec3::ZERO, Vec4::ZERO)
    } else {
        let t_raw = v.tangent.truncate();
        let t = (t_raw - n * n.dot(t_raw)).try_normalize().unwrap_or_else(|| n.any_orthonormal_vector());
        let sign = if v.tangent.w < 0.0 { -1.0 } else { 1.0 };
        (t, n.cross(t) * sign, Vec4::new(t.x, t.y, t.z, sign))
    };
    // World directions to tangent space, for the view ray and the shadow rays.
    let map =
        if prep.technique.displaces() || prep.casts_shadows() { TangentMap::new(n, tangent, v.uv_scale) } else { None };
    lane.dir = match map {
        Some(m) if prep.technique.displaces() => m.apply(-to_eye),
        _ => Vec3::ZERO,
    };
    lane.map = map;
    lane.n = n;
    lane.t = t;
    lane.b = b;
    lane.tangent = tangent;
    lane.to_eye = to_eye;
    lane.lod = lod;
    lane.weight = weight;
    lane.hit_uv = v.uv;
    lane.hit_depth = v.depth;
    lane.ray_depth = v.depth;
    lane.fetches = 0;
    if v.depth > 0.0
        && let Some(surface) = &prep.surface
    {
        // Displaced geometry: a triangle is a chord of the surface, and where it passes under
        // it (over a ridge), shadows traced from the chord would start inside the relief. The
        // receiver is lifted onto the surface (one fetch), as for steep parallax below.
        lane.hit_depth = lane.hit_depth.min(surface.depth(v.uv, 0.0));
        lane.fetches += 1;
    }
}

/// The mip level of the height map from the quad's UV gradients (fixed before any loop), and
/// the weight of the full technique in the LOD fade.
pub(crate) fn level_of(prep: &Prepared, f: &Fragment) -> (f32, f32) {
    match prep.lod_basis {
        Some((size, coarsest)) => {
            let lod = mip_level_from_gradients(f.duv_dx, f.duv_dy, size, coarsest);
            (lod, lod_weight(lod, prep.material.lod_threshold))
        }
        None => (0.0, 0.0),
    }
}

/// Whether the fragment's view ray is traced. With silhouettes the ray is traced even where
/// the LOD fade shows normal mapping only: the relief's outline is decided there too (the rim
/// of a curved mesh, seen at grazing angles, is where the mip level is highest).
pub(crate) fn needs_trace(prep: &Prepared, lane: &Lane) -> bool {
    prep.surface.is_some() && (lane.weight > 0.0 || prep.has_silhouettes()) && prep.technique.displaces()
}

/// Takes the trace's `hit` into `lane` (its `ray_depth` already set where the ray is curved).
pub(crate) fn take_hit(prep: &Prepared, surface: &Surface, lane: &mut Lane, hit: &Hit) {
    if !prep.has_silhouettes() {
        lane.ray_depth = hit.depth;
    }
    lane.hit_uv = hit.uv;
    lane.hit_depth = hit.depth;
    lane.fetches += hit.fetches;
    if prep.technique == Technique::Steep {
        // Steep parallax stops on the first plane *below* the surface, up to one plane
        // spacing deep. Shadows traced from there start inside the relief and darken in
        // contour rings; lift the receiver onto the surface (one more fetch).
        let lifted = lane.hit_depth.min(surface.depth(lane.hit_uv, lane.lod));
        // The lift moves the point up the view ray as well (pixel depth offset).
        lane.ray_depth = if prep.has_silhouettes() { lane.ray_depth - (lane.hit_depth - lifted) } else { lifted };
        lane.hit_depth = lifted;
        lane.fetches += 1;
    }
}

/// The fragment stage for one fragment; `None` discards it (a silhouette ray that left the
/// relief).
pub(crate) fn shade(scene: &Scene, prep: &Prepared, shading: &Shading, f: &Fragment) -> Option<Sample> {
    let mut lane = begin(scene, prep, f, level_of(prep, f));
    if needs_trace(prep, &lane)
        && let Some(surface) = &prep.surface
    {
        let p = TraceParams { lod: lane.lod, ..prep.params };
        let ray = Ray::new(f.v.uv, lane.dir);
        let hit = if prep.has_silhouettes() {
            let c = view_curvature(-lane.to_eye, lane.n, lane.tangent, f.v.curvature, prep.depth_scale);
            let curved = trace_curved(surface, &ray, prep.technique, &p, c);
            if curved.left {
                return None;
            }
            lane.ray_depth = curved.ray_depth;
            curved.hit
        } else {
            trace(surface, &ray, prep.technique, &p)
        };
        take_hit(prep, surface, &mut lane, &hit);
    }
    Some(finish(scene, prep, shading, f, &lane, |_, surface, l| {
        // The map takes a direction of travel; toward the light it is the same map.
        let light = lane.map.map_or(Vec3::ZERO, |m| m.apply(l));
        let p = TraceParams { lod: lane.lod, ..prep.params };
        shadow(surface, lane.hit_uv, lane.hit_depth, light, &prep.material.shadow, &p)
    }))
}

/// Where the textures repeat, a UV's point in the tile (hit UVs are in the ray's own tile
/// frame): the filters then read inner texels without wrapping them one by one.
pub(crate) fn texture_uv(uv: Vec2, edges: EdgeMode) -> Vec2 {
    match edges {
        EdgeMode::Wrap => Vec2::new(uv.x - floor(uv.x), uv.y - floor(uv.y)),
        EdgeMode::Clamp => uv,
    }
}

/// The direction toward `light` from the fragment, and the radiance arriving.
pub(crate) fn light_at(light: &Light, world: Vec3) -> (Vec3, Vec3) {
    match *light {
        Light::Directional { direction, color, intensity } => {
            (direction.try_normalize().unwrap_or(Vec3::Y), color * intensity)
        }
        Light::Point { position, color, intensity } => {
            let d = position - world;
            let d2 = d.length_squared().max(1e-8);
            (d / d2.sqrt(), color * intensity / d2)
        }
    }
}

/// Whether the fragment traces a shadow ray toward `light` in the full technique, and its
/// tangent-space direction.
pub(crate) fn shadow_ray(prep: &Prepared, lane: &Lane, f: &Fragment, light: &Light) -> Option<Vec3> {
    let (l, _) = light_at(light, f.v.world);
    let traced = prep.casts_shadows() && lane.weight > 0.0 && lane.n.dot(l) > 0.0;
    // The map takes a direction of travel; toward the light it is the same map.
    (traced && prep.material.shadow.mode != ShadowMode::None && prep.surface.is_some())
        .then(|| lane.map.map_or(Vec3::ZERO, |m| m.apply(l)))
}

/// Whether the fragment blends the full result with the LOD fade's normal-mapped fallback: below
/// full weight on a height map, unless the fallback is the same lighting at the same point
/// (no shadows, no offset), where `a.lerp(a, w)` would only round `a`.
pub(crate) fn is_fading(prep: &Prepared, lane: &Lane, f: &Fragment, with_shadows: bool) -> bool {
    lane.weight < 1.0 && prep.lod_basis.is_some() && (with_shadows || lane.hit_uv != f.v.uv)
}

/// The fragment's depth: the polygon's, or with a pixel depth offset the traced point's along
/// the view ray.
pub(crate) fn depth_offset(prep: &Prepared, shading: &Shading, f: &Fragment, lane: &Lane) -> f32 {
    let v = &f.v;
    let mut z = f.z;
    if prep.material.pixel_depth_offset && lane.ray_depth > 0.0 && lane.weight > 0.0 && prep.technique.displaces() {
        let l_world = (v.uv_scale.x * v.uv_scale.y).max(0.0).sqrt();
        let down = lane.ray_depth * prep.depth_scale * l_world; // world depth below the polygon
        let cos = lane.to_eye.dot(lane.n).max(1e-3);
        let p = v.world - lane.to_eye * (down / cos);
        let c = shading.depth_matrix * p.extend(1.0);
        if c.w > 0.0 {
            z = (c.z / c.w).max(f.z);
        }
    }
    z
}

/// The fragment stage after the trace: textures at the hit, lighting with the shadows
/// `shadow_of(light index, surface, world direction toward the light)` gives, the LOD fade and the
/// pixel depth offset.
fn finish(
    scene: &Scene,
    prep: &Prepared,
    shading: &Shading,
    f: &Fragment,
    lane: &Lane,
    mut shadow_of: impl FnMut(usize, &Surface, Vec3) -> Shadow,
) -> Sample {
    let m = &prep.material;
    let v = &f.v;
    let (n, t, b, to_eye) = (lane.n, lane.t, lane.b, lane.to_eye);
    let edges = prep.edges;
    let mut fetches = lane.fetches;
    let albedo_lod = albedo_level(&prep.albedo, f.duv_dx, f.duv_dy);
    let mut lit = |uv: Vec2, with_shadows: bool, fetches: &mut u32| -> (Vec3, f32) {
        // Where the textures repeat, their coordinates in the tile (hit UVs are in the ray's own
        // tile frame): the filter then reads inner texels without wrapping them one by one.
        let uv = texture_uv(uv, edges);
        let base = sample_albedo(&prep.albedo, uv, albedo_lod, edges) * m.base_color;
        let shading_n = match (&prep.normals, prep.technique) {
            (Some(nm), tq) if tq != Technique::Flat => {
                let mt = nm.sample(uv, edges);
                (t * mt.x + b * mt.y + n * mt.z).try_normalize().unwrap_or(n)
            }
            _ => n,
        };
        let mut c = scene.ambient * base;
        let mut first_vis = 1.0;
        for (li, light) in scene.lights.iter().enumerate() {
            let (l, radiance) = light_at(light, v.world);
            let n_dot_l = n.dot(l);
            let mut vis = if n_dot_l > 0.0 { 1.0 } else { 0.0 };
            if with_shadows
                && n_dot_l > 0.0
                && m.shadow.mode != ShadowMode::None
                && let Some(surface) = &prep.surface
            {
                let sh = shadow_of(li, surface, l);
                vis = sh.visibility;
                *fetches += sh.fetches;
            }
            if li == 0 {
                first_vis = vis;
            }
            let diffuse = shading_n.dot(l).max(0.0);
            let h = (l + to_eye).try_normalize().unwrap_or(shading_n);
            let spec = if diffuse > 0.0 { m.specular * shading_n.dot(h).max(0.0).powf(m.shininess) } else { 0.0 };
            c += (base * diffuse + Vec3::splat(spec)) * radiance * vis;
        }
        (c, first_vis)
    };
    let weight = lane.weight;
    let with_shadows = prep.casts_shadows() && weight > 0.0;
    let (full, vis) = lit(lane.hit_uv, with_shadows, &mut fetches);
    let color = if !is_fading(prep, lane, f, with_shadows) {
        full
    } else {
        let (simple, _) = lit(v.uv, false, &mut fetches);
        simple.lerp(full, weight)
    };
    let z = depth_offset(prep, shading, f, lane);
    Sample { color, z, uv: lane.hit_uv, depth: lane.hit_depth, shadow: vis, fetches: fetches as f32, lod: lane.lod }
}

/// Texel count and mip count for gradient-based level selection.
pub(crate) fn albedo_level(chain: &[Texture], duv_dx: Vec2, duv_dy: Vec2) -> f32 {
    let base = &chain[0];
    let size = Vec2::new(base.width() as f32, base.height() as f32);
    mip_level_from_gradients(duv_dx, duv_dy, size, (chain.len() - 1) as f32)
}

pub(crate) fn sample_albedo(chain: &[Texture], uv: Vec2, lod: f32, edges: EdgeMode) -> Vec3 {
    let k = floor(lod).max(0.0) as usize;
    let f = lod - k as f32;
    let a = chain[k.min(chain.len() - 1)].sample(uv, edges);
    if f <= 0.0 || k + 1 >= chain.len() {
        return a;
    }
    a.lerp(chain[k + 1].sample(uv, edges), f)
}
