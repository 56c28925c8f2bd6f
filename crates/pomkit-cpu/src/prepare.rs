//! Preparation: each material made ready for shading before a frame is drawn (its height map
//! as a traceable surface, its normal map, baked when absent), and the albedo mip chains a
//! renderer keeps from frame to frame.

use std::sync::Arc;

use glam::{Vec2, Vec3};
use pomkit_core::EdgeMode;
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals};
use pomkit_core::scene::{Material, NormalMap, Scene, Texture};
use pomkit_core::trace::{Surface, Technique, TraceParams, sanitized_depth_scale};
use rayon::prelude::*;

use crate::{Mode, RenderOptions};

/// A material prepared for shading: surfaces, mip chains, normal maps.
pub(crate) struct Prepared {
    pub(crate) material: Material,
    /// The height map prepared for tracing, where the frame traces it: a displacing technique,
    /// or the displaced reference's shadows. `flat` and `normal` only need `lod_basis`.
    pub(crate) surface: Option<Arc<Surface>>,
    /// The height map's size in texels and its coarsest mip level, for the level of detail.
    pub(crate) lod_basis: Option<(Vec2, f32)>,
    pub(crate) normals: Option<Arc<NormalMap>>,
    /// The albedo and its mip chain (shared between frames while the texture lives).
    pub(crate) albedo: Arc<Vec<Texture>>,
    pub(crate) technique: Technique,
    pub(crate) params: TraceParams,
    /// The material's depth scale, sanitized ([`pomkit_core::trace::sanitized_depth_scale`]).
    pub(crate) depth_scale: f32,
    pub(crate) edges: EdgeMode,
}

impl Prepared {
    /// Whether the material traces with silhouettes: asked for, and a displacing technique on
    /// a height map (so never in the `displaced` reference, which has true outlines).
    pub(crate) fn has_silhouettes(&self) -> bool {
        self.material.silhouette && self.surface.is_some() && self.technique.displaces()
    }

    /// Whether the material's full technique casts self-shadows.
    pub(crate) fn casts_shadows(&self) -> bool {
        self.technique.displaces() || self.material.height.is_some() && self.technique != Technique::Flat
    }
}

/// Prepares every material (after [`validate`](crate::validate)): surfaces for tracing, normal
/// maps (baked when absent), albedo mips.
pub(crate) fn prepare(scene: &Scene, opts: &RenderOptions, albedo: &[Arc<Vec<Texture>>]) -> Vec<Prepared> {
    scene
        .materials
        .par_iter()
        .enumerate()
        .map(|(i, m)| {
            let technique = opts.mode.technique(m.technique);
            let params = m.trace.sanitized();
            let (depth_scale, edges) = (sanitized_depth_scale(m.depth_scale), m.edges);
            let lod_basis = m
                .height
                .as_ref()
                .map(|f| (f.size_f32(), pomkit_core::grid::coarsest_level(f.width(), f.height()) as f32));
            // Without a displacing technique the surface is traced only by the displaced
            // reference's shadows (its fragments lie below the polygon); elsewhere every
            // fragment lies on the polygon, where nothing shadows it.
            let traced = technique.displaces() || opts.mode == Mode::Displaced;
            let surface = m.height.as_ref().filter(|_| traced).map(|f| {
                let mut surface = Surface::new((**f).clone(), edges, depth_scale);
                // The material's own cones or the field's, built once (not inside the first
                // pixel's trace nor again for the next frame); either fits the field.
                if technique == Technique::Cone
                    && let Some(cones) = m.cones_to_trace()
                {
                    let _ = surface.set_cones(cones);
                }
                // `exact`'s view rays on plane bounds where they pay on this field, chosen once
                // per field (the GPU renderer makes the same choice).
                if technique == Technique::Exact
                    && let Some(planes) = pomkit_core::trace::cached_plane_bounds(f, edges, depth_scale)
                {
                    let _ = surface.set_plane_bounds(Some(planes));
                }
                Arc::new(surface)
            });
            let normals = match (&m.normal_map, &m.height) {
                // `flat` shades with the geometric normal.
                _ if technique == Technique::Flat => None,
                (Some(n), _) => Some(n.clone()),
                (None, Some(f)) if f.width() >= 2 && f.height() >= 2 => {
                    // The normal map that matches the geometry: the full depth spans
                    // depth_scale * width texels.
                    let o = NormalBakeOptions {
                        scale: depth_scale * f.width() as f32,
                        filter: NormalFilter::Central,
                        edges,
                        y_down: false,
                    };
                    bake_normals(f, &o).ok().and_then(|n| NormalMap::new(f.width(), f.height(), n)).map(Arc::new)
                }
                _ => None,
            };
            let albedo = albedo[i].clone();
            Prepared { material: m.clone(), surface, lod_basis, normals, albedo, technique, params, depth_scale, edges }
        })
        .collect()
}

/// The albedo mip chains of the frames so far, by texture: a texture is immutable once shared
/// (`Arc<Texture>`), so its chain holds for as long as it lives. Height maps, which may change
/// from frame to frame (dynamic height fields), are prepared anew every frame.
#[derive(Debug, Default)]
pub(crate) struct AlbedoCache {
    chains: Vec<(std::sync::Weak<Texture>, Arc<Vec<Texture>>)>,
}

impl AlbedoCache {
    /// Each material's albedo chain (a white texel for a material without an albedo map),
    /// built where the cache has none; chains of textures dropped since are forgotten.
    pub(crate) fn chains(&mut self, scene: &Scene) -> Vec<Arc<Vec<Texture>>> {
        self.chains.retain(|(t, _)| t.strong_count() > 0);
        let known = |t: &Arc<Texture>| {
            self.chains.iter().find(|(w, _)| std::ptr::eq(w.as_ptr(), Arc::as_ptr(t))).map(|(_, c)| c.clone())
        };
        let found: Vec<Option<Arc<Vec<Texture>>>> =
            scene.materials.iter().map(|m| m.albedo.as_ref().and_then(known)).collect();
        let built: Vec<Arc<Vec<Texture>>> = scene
            .materials
            .par_iter()
            .zip(found)
            .map(|(m, found)| {
                found.unwrap_or_else(|| {
                    Arc::new(
                        m.albedo.as_ref().map_or_else(|| Texture::constant(Vec3::ONE), |t| (**t).clone()).mip_chain(),
                    )
                })
            })
            .collect();
        let new: Vec<(std::sync::Weak<Texture>, Arc<Vec<Texture>>)> = scene
            .materials
            .iter()
            .zip(&built)
            .filter_map(|(m, chain)| {
                m.albedo.as_ref().filter(|t| known(t).is_none()).map(|t| (Arc::downgrade(t), chain.clone()))
            })
            .collect();
        for entry in new {
            if !self.chains.iter().any(|(w, _)| w.ptr_eq(&entry.0)) {
                self.chains.push(entry);
            }
        }
        built
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CpuRenderer;
    use pomkit_core::demo::demo_scene_sized;

    #[test]
    fn a_renderer_reuses_albedo_chains_only_for_the_same_live_texture() {
        let opts = RenderOptions { width: 48, height: 27, ..Default::default() };
        let mut scene = demo_scene_sized(32);
        let fresh = |scene: &Scene| CpuRenderer::new().render(scene, &opts, &|_, _| {}).unwrap().color;
        let mut r = CpuRenderer::new();
        let first = r.render(&scene, &opts, &|_, _| {}).unwrap().color;
        let textured = scene.materials.iter().filter(|m| m.albedo.is_some()).count();
        assert!(textured > 0 && r.albedo.chains.len() == textured, "{} chains", r.albedo.chains.len());
        assert_eq!(r.render(&scene, &opts, &|_, _| {}).unwrap().color, first);
        // A new texture (here: another one's, darkened) is a new chain, never a stale one.
        for m in &mut scene.materials {
            if let Some(t) = &m.albedo {
                let dark: Vec<Vec3> = t.texels().iter().map(|c| *c * 0.25).collect();
                m.albedo = Some(Arc::new(Texture::new(t.width(), t.height(), dark).unwrap()));
            }
        }
        let second = r.render(&scene, &opts, &|_, _| {}).unwrap().color;
        assert_ne!(second, first);
        assert_eq!(second, fresh(&scene));
        // The first textures are gone: so are their chains.
        assert_eq!(r.albedo.chains.len(), textured);
    }
}
