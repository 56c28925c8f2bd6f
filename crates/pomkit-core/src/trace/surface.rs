//! [`Surface`]: a height field prepared for tracing (mip chain, maximum-height pyramid,
//! parallax map and, on first use, the cone map).

use super::*;

/// A height field prepared for tracing: its mip chain, its maximum-height pyramid and the
/// parallax map `n_z * d` used by [`Technique::Iterative`] (these two made on first use).
#[derive(Clone, Debug)]
pub struct Surface {
    pub(super) mips: MipChain,
    /// The maximum-height pyramid (`exact`, `cone`, exact shadows), built on first use.
    pyramid: std::sync::OnceLock<MaxHeightPyramid>,
    /// The parallax map's mip chain (`iterative`), built on first use.
    parallax: std::sync::OnceLock<MipChain>,
    pub(super) edges: EdgeMode,
    pub(super) depth_scale: f32,
    /// The cone map of `cone`, built on first use or set by [`Surface::set_cones`].
    cones: std::sync::OnceLock<std::sync::Arc<ConeMap>>,
    /// The plane bounds `exact`'s view rays walk on, when [`Surface::use_plane_bounds`] set them.
    planes: Option<std::sync::Arc<CellPlanes>>,
}

impl Surface {
    /// Prepares `field` for tracing with the given edge mode and depth scale (the parallax map
    /// depends on the depth scale through its normals: the full depth spans
    /// `depth_scale * width` texels). Every trace and shadow on the surface works at this depth
    /// scale and samples with these edges. The mip chain is built here; the maximum-height
    /// pyramid and the parallax map on first use (by `exact`, `cone` and exact shadows, and by
    /// `iterative`), so a frame pays only for what its technique reads. `depth_scale` is [`sanitized_depth_scale`]d, so any
    /// value gives a usable surface; check it with [`check_depth_scale`] to report bad input.
    #[must_use]
    pub fn new(field: HeightField, edges: EdgeMode, depth_scale: f32) -> Self {
        Self {
            mips: MipChain::new(field),
            pyramid: std::sync::OnceLock::new(),
            parallax: std::sync::OnceLock::new(),
            edges,
            depth_scale: sanitized_depth_scale(depth_scale),
            cones: std::sync::OnceLock::new(),
            planes: None,
        }
    }

    /// The parallax map `clamp(n_z * d, 0, 1)` of `field` at `scale` (Lengyel 7.51).
    fn build_parallax(field: &HeightField, edges: EdgeMode, scale: f32) -> MipChain {
        if field.width() < 2 || field.height() < 2 {
            return MipChain::new(field.clone());
        }
        let opts = NormalBakeOptions {
            scale: scale * field.width() as f32,
            filter: NormalFilter::Central,
            edges,
            y_down: false,
        };
        let normals = bake_normals(field, &opts).unwrap_or_else(|_| vec![Vec3::Z; field.depths().len()]);
        let values: Vec<f32> = normals.iter().zip(field.depths()).map(|(n, &d)| (n.z * d).clamp(0.0, 1.0)).collect();
        MipChain::new(HeightField::from_depths(field.width(), field.height(), values).unwrap_or_else(|_| field.clone()))
    }

    /// The cone map `cone` steps on: the one given to [`Surface::set_cones`], or else the
    /// conservative cones of the field, built on first use ([`ConeMap::conservative`]: about
    /// 1.5 s for a 512 x 512 map on two cores).
    pub fn cones(&self) -> &ConeMap {
        self.cones.get_or_init(|| std::sync::Arc::new(ConeMap::conservative(self.field(), self.edges)))
    }

    /// Uses `cones` (a baked cone map, [`ConeMap::from_gray_alpha16`], or the shared map of
    /// [`crate::cone::cached`]) instead of building them. They must be this field's cones for
    /// this edge mode: only the size can be checked.
    ///
    /// # Errors
    /// [`ConeMapError::Size`] if the map's size is not the field's.
    pub fn set_cones(&mut self, cones: impl Into<std::sync::Arc<ConeMap>>) -> Result<(), ConeMapError> {
        let cones = cones.into();
        cones.check_size(self.field().width(), self.field().height())?;
        self.cones = std::sync::OnceLock::from(cones);
        Ok(())
    }

    /// Builds the plane bounds of every pyramid cell ([`CellPlanes`]) and from then on walks
    /// `exact`'s view rays on them: the same hits, with fewer fetches where the relief slopes across the cells, more where rays
    /// cross long runs of empty cells between thin features (docs/ACCURACY.md, "Affine bounds
    /// per cell"). Shadow and silhouette rays keep the least-depth walk, as the shader library's
    /// do. About five times the pyramid's build (docs/BENCHMARKS.md).
    pub fn use_plane_bounds(&mut self) {
        let planes = CellPlanes::new(self.field(), self.pyramid(), self.edges);
        self.planes = Some(std::sync::Arc::new(planes));
    }

    /// Walks `exact`'s view rays on plane bounds ([`Surface::use_plane_bounds`]) if they pay on
    /// this surface: if [`PLANE_CHOICE_RAYS`] view rays at 75 degrees, spread over the tile,
    /// read fewer fetches with them than without. They do on relief that slopes across its
    /// pyramid cells (bricks, stones, waves, text on the built-in maps) and do not where rays
    /// cross long runs of empty cells between thin features (fur, grass, a lone spike); the
    /// hits are the same either way (docs/ACCURACY.md, "Affine bounds per cell"). Returns
    /// whether it kept them. Costs the bounds' build and 128 traces.
    pub fn choose_plane_bounds(&mut self) -> bool {
        let planes = CellPlanes::new(self.field(), self.pyramid(), self.edges);
        self.choose_with(std::sync::Arc::new(planes))
    }

    /// [`Surface::choose_plane_bounds`] with `planes`, this field's bounds, built already.
    fn choose_with(&mut self, planes: std::sync::Arc<CellPlanes>) -> bool {
        self.planes = None;
        let params = TraceParams::default();
        let rays: Vec<Ray> = (0..PLANE_CHOICE_RAYS)
            .map(|k| {
                // An R2 low-discrepancy set over the tile, azimuths by the golden angle.
                let k = k as f32;
                let uv = Vec2::new((0.5 + k * 0.754_877_7).fract(), (0.5 + k * 0.569_840_3).fract());
                Ray::at_angle(uv, 75f32.to_radians(), k * 2.399_963)
            })
            .collect();
        let fetches = |s: &Surface| -> u64 {
            rays.iter().map(|r| u64::from(trace(s, r, Technique::Exact, &params).fetches)).sum()
        };
        let without = fetches(self);
        self.planes = Some(planes);
        let with = fetches(self);
        if with >= without {
            self.planes = None;
        }
        self.planes.is_some()
    }

    /// Walks `exact`'s view rays on `planes` (from [`cached_plane_bounds`], or built for this
    /// field and edge mode by [`CellPlanes::new`]); `None` walks them on the least depths again.
    /// Only the sizes can be checked.
    ///
    /// # Errors
    /// [`PlaneBoundsError::Size`] if `planes` were built for a field of another size.
    pub fn set_plane_bounds(&mut self, planes: Option<std::sync::Arc<CellPlanes>>) -> Result<(), PlaneBoundsError> {
        if let Some(p) = &planes
            && !p.fits(self.pyramid())
        {
            let f = self.field();
            return Err(PlaneBoundsError::Size { width: f.width(), height: f.height() });
        }
        self.planes = planes;
        Ok(())
    }

    /// The plane bounds [`Surface::use_plane_bounds`] built, if it was called.
    #[must_use]
    pub fn plane_bounds(&self) -> Option<&CellPlanes> {
        self.planes.as_deref()
    }

    /// The height field (mip 0).
    #[must_use]
    pub fn field(&self) -> &HeightField {
        self.mips.base()
    }

    /// The mip chain.
    #[must_use]
    pub fn mips(&self) -> &MipChain {
        &self.mips
    }

    /// The parallax map's mip chain: `clamp(n_z * d, 0, 1)` per texel (Lengyel 7.51), with `n`
    /// the central-difference normal at this surface's depth scale (what the `parallax`
    /// technique reads; a GPU host uploads it beside the depths).
    #[must_use]
    pub fn parallax_mips(&self) -> &MipChain {
        self.parallax.get_or_init(|| Self::build_parallax(self.field(), self.edges, self.depth_scale))
    }

    /// The maximum-height pyramid.
    #[must_use]
    pub fn pyramid(&self) -> &MaxHeightPyramid {
        self.pyramid.get_or_init(|| MaxHeightPyramid::new(self.field(), self.edges))
    }

    /// The edge mode the surface was prepared for.
    #[must_use]
    pub fn edges(&self) -> EdgeMode {
        self.edges
    }

    /// The depth scale the parallax map was built for.
    #[must_use]
    pub fn depth_scale(&self) -> f32 {
        self.depth_scale
    }

    /// Filtered depth at `uv` and mip level `lod` (one fetch).
    #[must_use]
    pub fn depth(&self, uv: Vec2, lod: f32) -> f32 {
        self.mips.sample(uv, lod, self.edges)
    }

    /// The most fetches the exact tracer makes for any one view or shadow ray at this surface's
    /// depth scale, saturating at `u32::MAX`.
    ///
    /// A ray's UV travel per unit of depth is at most `depth_scale / MIN_COS` (the flattest ray
    /// accepted), so it crosses at most `depth_scale / MIN_COS * width + 2` texel columns and as
    /// many rows (scaled by the height); the traversal makes at most
    /// `2 * (columns + rows) + 3 + top` steps (`exact_step_bound`, `top` the pyramid's coarsest
    /// level) and at most 4 fetches per step (one pyramid gather, up to three bilinear patches).
    /// This is a proof of termination, not the typical cost: the pyramid skips empty stretches a tile at a time, so a typical ray
    /// makes O(log size) fetches per tile it crosses.
    #[must_use]
    pub fn exact_fetch_bound(&self) -> u32 {
        let f = self.field();
        // A relative margin covers the f32 rounding of the ray's UV step.
        let travel = f64::from(self.depth_scale) / f64::from(MIN_COS) * (1.0 + 1e-4);
        let d = DVec3::new(travel * f64::from(f.width()), travel * f64::from(f.height()), 1.0);
        let (w, h) = (i64::from(f.width()), i64::from(f.height()));
        let steps = exact_step_bound(d, 0.0, 1.0, w, h, self.edges);
        // One pyramid gather per step plus up to three patches on the leaf steps; shadows add
        // one fetch to lift the receiver (counted here too).
        u32::try_from(steps.saturating_mul(4).saturating_add(1)).unwrap_or(u32::MAX)
    }
}

impl Surface {
    /// The most fetches the `cone` technique makes for one view ray at this surface's depth
    /// scale with
    /// `binary_steps`: at most two steps per texel boundary the ray crosses (as for `exact`,
    /// [`Surface::exact_fetch_bound`]), each one cone read and then up to three gathers, and the
    /// binary search. Saturates at `u32::MAX`.
    #[must_use]
    pub fn cone_fetch_bound(&self, binary_steps: u32) -> u32 {
        let steps = cone_step_bound(self);
        u32::try_from(steps.saturating_mul(4).saturating_add(u64::from(binary_steps.min(64)))).unwrap_or(u32::MAX)
    }
}

/// The plane bounds `exact`'s view rays on `field` walk on, if they pay there
/// ([`Surface::choose_plane_bounds`], at `depth_scale` with `edges`). Shared while the field
/// lives, as [`crate::cone::cached`] shares cones, so renderers that prepare their surfaces every
/// frame build the bounds once per height field and edge mode (they do not depend on the depth
/// scale) and choose once per depth scale (128 traces). Entries of fields that were dropped are
/// forgotten.
#[must_use]
pub fn cached_plane_bounds(
    field: &std::sync::Arc<HeightField>,
    edges: EdgeMode,
    depth_scale: f32,
) -> Option<std::sync::Arc<CellPlanes>> {
    use std::sync::{Arc, Mutex, Weak};
    /// A field's bounds, and the choice made at each depth scale (its bits) so far.
    type Entry = (Weak<HeightField>, EdgeMode, Arc<CellPlanes>, Vec<(u32, bool)>);
    static CACHE: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
    let depth_scale = sanitized_depth_scale(depth_scale);
    let key = depth_scale.to_bits();
    let lock = || CACHE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // The entry's bounds and its choice at this depth scale, where known.
    let find = |cache: &mut Vec<Entry>| {
        cache.retain(|(f, ..)| f.strong_count() > 0);
        cache
            .iter()
            .find(|(f, e, ..)| *e == edges && f.as_ptr() == Arc::as_ptr(field))
            .map(|(_, _, p, chosen)| (Arc::clone(p), chosen.iter().find(|(k, _)| *k == key).map(|&(_, pays)| pays)))
    };
    // A poisoned lock only means another thread panicked while holding it; the list stays valid.
    let known = find(&mut lock());
    if let Some((planes, Some(pays))) = &known {
        return pays.then(|| Arc::clone(planes));
    }
    // Built and chosen outside the lock: two threads may both do it, never wait on each other.
    let mut surface = Surface::new((**field).clone(), edges, depth_scale);
    let planes = match known {
        Some((planes, None)) => planes,
        _ => Arc::new(CellPlanes::new(surface.field(), surface.pyramid(), edges)),
    };
    let pays = surface.choose_with(Arc::clone(&planes));
    let mut cache = lock();
    match cache.iter_mut().find(|(f, e, ..)| *e == edges && f.as_ptr() == Arc::as_ptr(field)) {
        Some((.., chosen)) => {
            if !chosen.iter().any(|(k, _)| *k == key) {
                chosen.push((key, pays));
            }
        }
        None => cache.push((Arc::downgrade(field), edges, Arc::clone(&planes), vec![(key, pays)])),
    }
    pays.then_some(planes)
}
