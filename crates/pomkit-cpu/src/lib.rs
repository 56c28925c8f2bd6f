//! pomkit-cpu: the CPU renderer.
//!
//! Per pixel it runs what a GPU would: the vertex stage (world position, tangent frame), near
//! clipping and triangle setup, rasterization in 2x2 quads (so UV gradients exist before any
//! loop), the material's technique from `pomkit-core`, every texture sampled at the displaced
//! UV, Blinn-Phong lighting with the normal map, self-shadowing, the LOD fade to normal mapping,
//! and optionally the displaced depth written to the depth buffer. Tiles of the image are shaded
//! in parallel with rayon.
//!
//! It is also the reference the GPU renderer is tested against, and it renders the ground truth:
//! [`Mode::Displaced`] tessellates every height-mapped mesh to the height map's resolution and
//! moves its vertices for real.
//!
//! ```
//! use pomkit_cpu::{CpuRenderer, RenderOptions};
//!
//! let scene = pomkit_core::demo::demo_scene_sized(64);
//! let opts = RenderOptions { width: 64, height: 36, ..Default::default() };
//! let out = CpuRenderer::new().render(&scene, &opts, &|_, _| {})?;
//! let srgb: Vec<[u8; 3]> = out.to_srgb8(); // out.color is linear RGB
//! assert_eq!(srgb.len(), 64 * 36);
//! # Ok::<(), pomkit_cpu::RenderError>(())
//! ```

pub mod compose;
pub mod raster;

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Vec2, Vec3, Vec4};
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use pomkit_core::mesh::{Mesh, tangent_ray};
use pomkit_core::scene::{Light, Material, NormalMap, Scene, Texture};
use pomkit_core::shadow::{ShadowMode, lod_weight, shadow};
use pomkit_core::trace::{Ray, Surface, Technique, TraceParams, trace};
use pomkit_core::{EdgeMode, mip_level_from_gradients};
use rayon::prelude::*;

pub use pomkit_core::render::{Aovs, Mode, RenderError, RenderOptions, RenderOutput, Sample, resolve, validate};

use raster::{ClipVertex, Fragment, ScreenTriangle, Varyings, clip_near, setup};

/// A material prepared for shading: surfaces, mip chains, normal maps.
struct Prepared {
    material: Material,
    surface: Option<Arc<Surface>>,
    normals: Option<Arc<NormalMap>>,
    albedo: Vec<Texture>,
    technique: Technique,
    params: TraceParams,
}

/// Texel count and mip count for gradient-based level selection.
fn albedo_level(chain: &[Texture], duv_dx: Vec2, duv_dy: Vec2) -> f32 {
    let base = &chain[0];
    let size = Vec2::new(base.width() as f32, base.height() as f32);
    mip_level_from_gradients(duv_dx, duv_dy, size, (chain.len() - 1) as f32)
}

fn sample_albedo(chain: &[Texture], uv: Vec2, lod: f32, edges: EdgeMode) -> Vec3 {
    let k = lod.floor().max(0.0) as usize;
    let f = lod - k as f32;
    let a = chain[k.min(chain.len() - 1)].sample(uv, edges);
    if f <= 0.0 || k + 1 >= chain.len() {
        return a;
    }
    a.lerp(chain[k + 1].sample(uv, edges), f)
}

/// The CPU renderer: `CpuRenderer::new()` then `render(&scene, &options)`.
#[derive(Debug, Default)]
pub struct CpuRenderer {
    _private: (),
}

const TILE: u32 = 32;

impl CpuRenderer {
    /// A renderer.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `scene`, calling `progress(done, total)` as tiles finish.
    ///
    /// # Errors
    /// [`RenderError`] for a bad size, a dangling material index or invalid trace parameters.
    pub fn render(
        &mut self,
        scene: &Scene,
        opts: &RenderOptions,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<RenderOutput, RenderError> {
        validate(scene, opts)?;
        let ss = opts.supersample.clamp(1, 8);
        let (w, h) = (opts.width, opts.height);
        let (sw, sh) = (w * ss, h * ss);
        let prepared = prepare(scene, opts);
        let triangles = self.triangles(scene, &prepared, opts, sw, sh);
        let samples = shade_tiles(scene, &prepared, &triangles, sw, sh, opts.lod_tint, progress);
        Ok(resolve(&samples, w, h, ss, scene.background, opts.aovs))
    }

    /// The vertex stage and triangle setup for every object.
    fn triangles(
        &self,
        scene: &Scene,
        prepared: &[Prepared],
        opts: &RenderOptions,
        sw: u32,
        sh: u32,
    ) -> Vec<ScreenTriangle> {
        let aspect = sw as f32 / sh as f32;
        let vp = scene.camera.projection(aspect) * scene.camera.view();
        let mut out = Vec::new();
        for (oi, obj) in scene.objects.iter().enumerate() {
            let prep = &prepared[obj.material];
            let mesh: Arc<Mesh> = match (opts.mode, &prep.material.height) {
                (Mode::Displaced, Some(field)) => {
                    let p = &prep.params;
                    Arc::new(obj.mesh.displaced_for_shading(field, p.edges, p.depth_scale, opts.displaced_edge_texels))
                }
                _ => obj.mesh.clone(),
            };
            let world = mesh.transformed(obj.transform);
            let displaced = opts.mode == Mode::Displaced && prep.material.height.is_some();
            let verts: Vec<ClipVertex> = (0..world.positions.len())
                .map(|i| {
                    let p = world.positions[i];
                    let uv = world.uvs[i];
                    let depth = match (&prep.surface, displaced) {
                        (Some(s), true) => s.field().sample_bilinear(uv, prep.params.edges),
                        _ => 0.0,
                    };
                    ClipVertex {
                        clip: vp * p.extend(1.0),
                        v: Varyings {
                            world: p,
                            // For displaced geometry these are the undisplaced surface's
                            // normals (`Mesh::displaced_for_shading`): the normal map adds the
                            // bumps, as for every parallax technique.
                            normal: world.normals[i],
                            tangent: world.tangents[i],
                            uv,
                            uv_scale: world.uv_scale[i],
                            depth,
                        },
                    }
                })
                .collect();
            for tri in world.indices.chunks_exact(3) {
                let t = [verts[tri[0] as usize], verts[tri[1] as usize], verts[tri[2] as usize]];
                for c in clip_near(t) {
                    if let Some(st) = setup(&c, sw, sh, oi as u32, true) {
                        out.push(st);
                    }
                }
            }
        }
        out
    }
}

/// Prepares every material (after [`validate`]): surfaces for tracing, normal maps (baked when
/// absent), albedo mips.
fn prepare(scene: &Scene, opts: &RenderOptions) -> Vec<Prepared> {
    scene
        .materials
        .par_iter()
        .map(|m| {
            let technique = opts.mode.technique(m.technique);
            let params = m.trace.sanitized();
            let surface =
                m.height.as_ref().map(|f| Arc::new(Surface::new((**f).clone(), params.edges, params.depth_scale)));
            let normals = match (&m.normal_map, &m.height) {
                (Some(n), _) => Some(n.clone()),
                (None, Some(f)) if f.width() >= 2 && f.height() >= 2 => {
                    // The normal map that matches the geometry: the full depth spans
                    // depth_scale * width texels.
                    let o = NormalBakeOptions {
                        scale: params.depth_scale * f.width() as f32,
                        filter: NormalFilter::Central,
                        edges: params.edges,
                        y_down: false,
                    };
                    bake_normals(f, &o).ok().and_then(|n| NormalMap::new(f.width(), f.height(), n)).map(Arc::new)
                }
                _ => None,
            };
            let mut albedo = vec![m.albedo.as_ref().map_or_else(|| Texture::constant(Vec3::ONE), |t| (**t).clone())];
            while let Some(last) = albedo.last().filter(|t| t.width() > 1 || t.height() > 1) {
                let next = last.downsample();
                albedo.push(next);
            }
            Prepared { material: m.clone(), surface, normals, albedo, technique, params }
        })
        .collect()
}

/// Bins triangles into tiles and shades tiles in parallel; returns the full-resolution samples.
fn shade_tiles(
    scene: &Scene,
    prepared: &[Prepared],
    tris: &[ScreenTriangle],
    w: u32,
    h: u32,
    lod_tint: bool,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<Option<Sample>> {
    let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); (tx * ty) as usize];
    for (i, t) in tris.iter().enumerate() {
        let Some((x0, y0, x1, y1)) = t.quad_bounds(0, 0, w, h) else { continue };
        for by in y0 / TILE..=(y1 - 1) / TILE {
            for bx in x0 / TILE..=(x1 - 1) / TILE {
                bins[(by * tx + bx) as usize].push(i as u32);
            }
        }
    }
    // Front to back, so the early depth test rejects hidden fragments before they are traced.
    for b in &mut bins {
        b.sort_by(|&a, &c| tris[a as usize].min_z.total_cmp(&tris[c as usize].min_z));
    }
    let done = AtomicUsize::new(0);
    let total = bins.len();
    let tiles: Vec<(u32, u32, Vec<Option<Sample>>)> = bins
        .par_iter()
        .enumerate()
        .map(|(k, bin)| {
            let (bx, by) = (k as u32 % tx, k as u32 / tx);
            let (x0, y0) = (bx * TILE, by * TILE);
            let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
            let tw = x1 - x0;
            let mut buf: Vec<Option<Sample>> = vec![None; (tw * (y1 - y0)) as usize];
            for &ti in bin {
                let tri = &tris[ti as usize];
                let obj = &scene.objects[tri.object as usize];
                let prep = &prepared[obj.material];
                tri.rasterize(x0, y0, x1, y1, |f: &Fragment| {
                    let slot = &mut buf[((f.y - y0) * tw + (f.x - x0)) as usize];
                    // Early depth test with the polygon's depth: the displaced depth is never
                    // nearer, so a fragment behind the stored one stays behind.
                    if slot.is_some_and(|s| s.z <= f.z) {
                        return;
                    }
                    let mut s = shade(scene, prep, f);
                    if lod_tint && prep.surface.is_some() {
                        let w = lod_weight(s.lod, prep.material.lod_threshold);
                        let tint = Vec3::new(1.0, 0.25, 0.2).lerp(Vec3::new(0.25, 1.0, 0.3), w);
                        s.color = s.color * 0.5 + tint * 0.5 * s.color.length().max(0.05);
                    }
                    if slot.is_none_or(|old| s.z < old.z) {
                        *slot = Some(s);
                    }
                });
            }
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(n, total);
            (x0, y0, buf)
        })
        .collect();
    let mut out = vec![None; (w * h) as usize];
    for (x0, y0, buf) in tiles {
        let tw = (x0 + TILE).min(w) - x0;
        for (i, s) in buf.into_iter().enumerate() {
            let (x, y) = (x0 + i as u32 % tw, y0 + i as u32 / tw);
            out[(y * w + x) as usize] = s;
        }
    }
    out
}

/// The fragment stage.
fn shade(scene: &Scene, prep: &Prepared, f: &Fragment) -> Sample {
    let m = &prep.material;
    let v = &f.v;
    let cam = &scene.camera;
    // Tangent frame, re-orthonormalized after interpolation (Lengyel Listing 7.8).
    let n = v.normal.try_normalize().unwrap_or(Vec3::Z);
    let t_raw = v.tangent.truncate();
    let t = (t_raw - n * n.dot(t_raw)).try_normalize().unwrap_or_else(|| n.any_orthonormal_vector());
    let sign = if v.tangent.w < 0.0 { -1.0 } else { 1.0 };
    let b = n.cross(t) * sign;
    let tangent = Vec4::new(t.x, t.y, t.z, sign);
    let to_eye = (cam.eye - v.world).try_normalize().unwrap_or(n);
    let params = prep.params;
    let edges = params.edges;

    // Mip level of the height map from the quad's UV gradients, fixed before any loop.
    let (lod, weight) = match &prep.surface {
        Some(s) => {
            let f0 = s.field();
            let lod = mip_level_from_gradients(f.duv_dx, f.duv_dy, f0.size_f32(), s.mips().max_level());
            (lod, lod_weight(lod, m.lod_threshold))
        }
        None => (0.0, 0.0),
    };
    let dir = tangent_ray(-to_eye, n, tangent, v.uv_scale);
    let mut fetches = 0u32;
    // The full technique (weight > 0) and the normal-mapped fallback (weight < 1).
    let mut hit_uv = v.uv;
    let mut hit_depth = v.depth;
    if let (Some(surface), true) = (&prep.surface, weight > 0.0 && prep.technique.displaces()) {
        let p = TraceParams { lod, ..params };
        let hit = trace(surface, &Ray::new(v.uv, dir), prep.technique, &p);
        hit_uv = hit.uv;
        hit_depth = hit.depth;
        fetches += hit.fetches;
        if prep.technique == Technique::Steep {
            // Steep parallax stops on the first plane *below* the surface, up to one plane
            // spacing deep. Shadows traced from there start inside the relief and darken in
            // contour rings; lift the receiver onto the surface (one more fetch).
            hit_depth = hit_depth.min(surface.depth(hit_uv, lod));
            fetches += 1;
        }
    }
    let albedo_lod = albedo_level(&prep.albedo, f.duv_dx, f.duv_dy);
    let lit = |uv: Vec2, depth: f32, with_shadows: bool, fetches: &mut u32| -> (Vec3, f32) {
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
            let (l, radiance) = match *light {
                Light::Directional { direction, color, intensity } => {
                    (direction.try_normalize().unwrap_or(Vec3::Y), color * intensity)
                }
                Light::Point { position, color, intensity } => {
                    let d = position - v.world;
                    let d2 = d.length_squared().max(1e-8);
                    (d / d2.sqrt(), color * intensity / d2)
                }
            };
            let n_dot_l = n.dot(l);
            let mut vis = if n_dot_l > 0.0 { 1.0 } else { 0.0 };
            if with_shadows && n_dot_l > 0.0 && m.shadow.mode != ShadowMode::None {
                if let Some(surface) = &prep.surface {
                    let lt = tangent_ray(l, n, tangent, v.uv_scale);
                    // tangent_ray maps a direction of travel; toward the light it is the same map.
                    let sh = shadow(surface, uv, depth, lt, &m.shadow, &TraceParams { lod, ..params });
                    vis = sh.visibility;
                    *fetches += sh.fetches;
                }
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
    let shadows = prep.technique.displaces() || prep.material.height.is_some() && prep.technique != Technique::Flat;
    let (full, vis) = lit(hit_uv, hit_depth, shadows && weight > 0.0, &mut fetches);
    let color = if weight >= 1.0 || prep.surface.is_none() {
        full
    } else {
        let (simple, _) = lit(v.uv, v.depth, false, &mut fetches);
        simple.lerp(full, weight)
    };
    // Pixel depth offset: move the depth to the traced point along the view ray.
    let mut z = f.z;
    if m.pixel_depth_offset && hit_depth > 0.0 && weight > 0.0 && prep.technique.displaces() {
        let l_world = (v.uv_scale.x * v.uv_scale.y).max(0.0).sqrt();
        let down = hit_depth * params.depth_scale * l_world; // world depth below the polygon
        let cos = to_eye.dot(n).max(1e-3);
        let p = v.world - to_eye * (down / cos);
        let aspect_free = cam.projection(1.0) * cam.view(); // depth does not depend on aspect
        let c = aspect_free * p.extend(1.0);
        if c.w > 0.0 {
            z = (c.z / c.w).max(f.z);
        }
    }
    Sample { color, z, uv: hit_uv, depth: hit_depth, shadow: vis, fetches: fetches as f32, lod }
}
