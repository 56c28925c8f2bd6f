//! Building conservative cones: for each footprint, a branch-and-bound search for the widest
//! cone above it that no part of the bilinear surface enters.

use super::*;

/// A rectangle of the plane in texel units, with the least depth of the surface over it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Region {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    min_depth: f64,
    kind: Kind,
}

#[derive(Clone, Copy, Debug)]
pub(super) enum Kind {
    /// Cell `(x, y)` of pyramid level `level`, in the tile `(tx, ty)` tiles from the map.
    Node { level: u8, x: u32, y: u32, tx: i8, ty: i8 },
    /// A rectangle inside one bilinear patch, with the surface's depth at its corners
    /// `(x0, y0)`, `(x1, y0)`, `(x0, y1)`, `(x1, y1)`.
    Patch([f64; 4]),
}

pub(super) struct Search<'a> {
    pub(super) field: &'a HeightField,
    pub(super) pyramid: &'a MaxHeightPyramid,
    pub(super) edges: EdgeMode,
    pub(super) w: f64,
    pub(super) h: f64,
    pub(super) cap: f64,
    pub(super) tiles: Vec<(i8, i8)>,
    /// The least depth of the whole surface: a footprint whose top is that shallow has nothing
    /// above it.
    pub(super) global_min: f64,
    /// The slope bound's table ([`slope`]); `None` only while the search is being made.
    pub(super) slopes: Option<slope::SlopeTable>,
}

impl<'a> Search<'a> {
    pub(super) fn new(field: &'a HeightField, pyramid: &'a MaxHeightPyramid, edges: EdgeMode) -> Self {
        let tiles = match edges {
            EdgeMode::Wrap => (-1..=1).flat_map(|ty| (-1..=1).map(move |tx| (tx, ty))).collect(),
            EdgeMode::Clamp => vec![(0, 0)],
        };
        let top = pyramid.len() - 1;
        let mut search = Self {
            field,
            pyramid,
            edges,
            w: f64::from(field.width()),
            h: f64::from(field.height()),
            cap: f64::from(field.width().min(field.height())),
            tiles,
            global_min: f64::from(pyramid.min_depth(top, 0, 0)),
            slopes: None,
        };
        search.slopes = Some(slope::SlopeTable::new(&search));
        search
    }

    /// The least depth of the bilinear surface over footprint `(i, j)`, in `f64`: the least of
    /// its texel centre, edge midpoints and corners ([`crate::pyramid`]).
    pub(super) fn exact_top(&self, i: i64, j: i64) -> f64 {
        crate::pyramid::footprint_min(|dx, dy| self.texel(i + dx, j + dy))
    }

    /// The depth of texel `(x, y)` (any integers: wrapped or clamped).
    #[inline]
    pub(super) fn texel(&self, x: i64, y: i64) -> f64 {
        let (w, h) = (i64::from(self.field.width()), i64::from(self.field.height()));
        let depths = self.field.depths();
        if (0..w).contains(&x) && (0..h).contains(&y) {
            return f64::from(depths[(y * w + x) as usize]);
        }
        f64::from(self.field.depth_at(x, y, self.edges))
    }

    /// The bilinear surface's depth at `(x, y)` in texel units (texel centres at half-integers).
    pub(super) fn surface(&self, x: f64, y: f64) -> f64 {
        bilinear(|i, j| self.texel(i, j), x, y)
    }

    /// The slope of patch `(k, l)` (corner texels `(k, l)` to `(k + 1, l + 1)`, covering
    /// `[k + 1/2, k + 3/2] x [l + 1/2, l + 3/2]`) at `(x, y)`: depth per texel along x and y.
    pub(super) fn patch_slope(&self, k: i64, l: i64, x: f64, y: f64) -> (f64, f64) {
        let (d00, d10, d01, d11) =
            (self.texel(k, l), self.texel(k + 1, l), self.texel(k, l + 1), self.texel(k + 1, l + 1));
        let (tx, ty) = (x - (k as f64 + 0.5), y - (l as f64 + 0.5));
        ((d10 - d00) * (1.0 - ty) + (d11 - d01) * ty, (d01 - d00) * (1.0 - tx) + (d11 - d10) * tx)
    }

    /// A lower bound on the ratio that points of `r` allow footprint `(i, j)` (whose top is
    /// `m`), from how fast the surface can fall below the footprint's edge, for regions half a
    /// texel or less beside the footprint; 0 (no bound) elsewhere.
    ///
    /// From a point `q` beside the footprint the nearest point `b` of the footprint lies
    /// straight across (beside an edge) or at a corner (diagonally off it), and the segment
    /// from `b` to `q` crosses one patch row or column (beside an edge) or lies in one patch
    /// (off a corner). The surface at `b` is no shallower than `m`, so `m - depth(q)` is at
    /// most the fall of the surface from `b` to `q`:
    /// - beside an edge, `|q - b|` times the slope away from the edge, which is linear along
    ///   the edge inside a patch: its largest value over `r` is at `r`'s ends or where a patch
    ///   boundary crosses it;
    /// - off a corner, at most `-e + a |q - b| + t |q - b|^2` (the surface along the segment is
    ///   quadratic; `e >= 0` is how far `b` lies below the top, `a` the rise rate toward the
    ///   quadrant and `t` half the twist where it raises the surface, using
    ///   `|vx vy| <= |v|^2 / 2`).
    ///
    /// So the ratio `|q - b| / (m - depth(q))` is at least one over the edge's rate, or the
    /// corner's bound at `r`'s farthest point (it falls as `|q - b|` grows).
    pub(super) fn near_bound(&self, i: i64, j: i64, m: f64, r: &Region) -> f64 {
        let (cx0, cy0) = (i as f64, j as f64);
        let (cx1, cy1) = (cx0 + 1.0, cy0 + 1.0);
        let right = r.x0 >= cx1 && r.x1 <= cx1 + 0.5;
        let left = r.x1 <= cx0 && r.x0 >= cx0 - 0.5;
        let below = r.y0 >= cy1 && r.y1 <= cy1 + 0.5;
        let above = r.y1 <= cy0 && r.y0 >= cy0 - 0.5;
        let across_x = r.x0 >= cx0 && r.x1 <= cx1;
        let across_y = r.y0 >= cy0 && r.y1 <= cy1;
        // The points along an edge where the slope across it may peak: r's ends and the patch
        // boundary between them (texel centres lie on half-integers).
        let along = |a0: f64, a1: f64| {
            let mid = floor_i(a0) as f64 + 0.5;
            [a0, a1, if mid > a0 && mid < a1 { mid } else { a0 }]
        };
        let patch_of = |a: f64| floor_i(a - 0.5);
        let rate = if (right || left) && across_y {
            let (k, sign, x) = if right { (i, -1.0, cx1 + 0.25) } else { (i - 1, 1.0, cx0 - 0.25) };
            along(r.y0, r.y1).into_iter().map(|y| sign * self.patch_slope(k, patch_of(y), x, y).0).fold(0.0, f64::max)
        } else if (below || above) && across_x {
            let (l, sign, y) = if below { (j, -1.0, cy1 + 0.25) } else { (j - 1, 1.0, cy0 - 0.25) };
            along(r.x0, r.x1).into_iter().map(|x| sign * self.patch_slope(patch_of(x), l, x, y).1).fold(0.0, f64::max)
        } else if (right || left) && (below || above) {
            // Off a corner b: with v = q - b, the surface is depth(b) + gx vx + gy vy + twist vx vy
            // inside the patch, so `m - depth(q)` is at most `-e + a |v| + t |v|^2` where
            // `e = depth(b) - m >= 0`, `a` the fall rate toward the quadrant (only the axes the
            // surface rises along count) and `t` half the twist where it raises the surface.
            // `|v| / (-e + a |v| + t |v|^2)` falls as `|v|` grows: least at r's farthest corner.
            let (k, bx, sx) = if right { (i, cx1, 1.0) } else { (i - 1, cx0, -1.0) };
            let (l, by, sy) = if below { (j, cy1, 1.0) } else { (j - 1, cy0, -1.0) };
            let (gx, gy) = self.patch_slope(k, l, bx, by);
            let twist = self.texel(k, l) - self.texel(k + 1, l) - self.texel(k, l + 1) + self.texel(k + 1, l + 1);
            let e = (self.surface(bx, by) - m).max(0.0);
            let a = (-gx * sx).max(0.0).hypot((-gy * sy).max(0.0));
            let t = (-twist * sx * sy).max(0.0) / 2.0;
            let far = (r.x0 - bx).abs().max((r.x1 - bx).abs()).hypot((r.y0 - by).abs().max((r.y1 - by).abs()));
            let fall = -e + a * far + t * far * far;
            return if fall > 0.0 { far / fall } else { f64::INFINITY };
        } else {
            return 0.0;
        };
        if rate > 0.0 { 1.0 / rate } else { f64::INFINITY }
    }

    pub(super) fn node(&self, level: usize, x: u32, y: u32, tx: i8, ty: i8) -> Region {
        let ([x0, x1], [y0, y1]) = self.pyramid.cell_texels(level, x, y);
        let (ox, oy) = (f64::from(tx) * self.w, f64::from(ty) * self.h);
        Region {
            x0: f64::from(x0) + ox,
            x1: f64::from(x1) + ox,
            y0: f64::from(y0) + oy,
            y1: f64::from(y1) + oy,
            min_depth: f64::from(self.pyramid.min_depth(level, x, y)),
            kind: Kind::Node { level: level as u8, x, y, tx, ty },
        }
    }

    /// A rectangle inside one patch; its least depth is at a corner.
    pub(super) fn patch_rect(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> Region {
        let (k, l) = (floor_i(0.5 * (x0 + x1) - 0.5) as f64, floor_i(0.5 * (y0 + y1) - 0.5) as f64);
        let (ki, li) = (k as i64, l as i64);
        let (d00, d10, d01, d11) =
            (self.texel(ki, li), self.texel(ki + 1, li), self.texel(ki, li + 1), self.texel(ki + 1, li + 1));
        let at = |x: f64, y: f64| {
            let (tx, ty) = (x - k - 0.5, y - l - 0.5);
            let top = d00 + (d10 - d00) * tx;
            top + (d01 + (d11 - d01) * tx - top) * ty
        };
        let d = [at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1)];
        let m = d[0].min(d[1]).min(d[2]).min(d[3]);
        Region { x0, x1, y0, y1, min_depth: m, kind: Kind::Patch(d) }
    }

    /// The cone ratio of footprint `(i, j)` and the surface point that decided it, starting
    /// from `witness` (a point that decided a neighbour's).
    /// Whether a ray that starts on the top plane (depth 0) over footprint `C = [cx0, cx0 + 1] x
    /// [cy0, cy0 + 1]` may leave the surface (pass from below it to above it) at a point of the
    /// rectangle `r`, which lies inside one bilinear patch (a point when it has no extent).
    ///
    /// A ray from `p` on `C` reaches `X` at depth `d(X)` with the slope `d(X) / |X - p|`, and
    /// leaves the surface there only if the surface falls along it faster than that:
    /// `grad d(X) . u > d(X) / |X - p|`, `u` the direction from `p` to `X`. False (no exit
    /// anywhere in `r`) when even the largest `grad . u` over `r` and every `p` is at most
    /// `min d / max |X - p|` over `r`; true otherwise. With clamped edges, rectangles within
    /// half a texel of the border are always true: the surface beyond repeats theirs.
    pub(super) fn may_exit(&self, cx0: f64, cy0: f64, r: &Region) -> bool {
        if self.edges == EdgeMode::Clamp && (r.x0 < 0.5 || r.y0 < 0.5 || r.x1 > self.w - 0.5 || r.y1 > self.h - 0.5) {
            return true;
        }
        let (k, l) = (floor_i(0.5 * (r.x0 + r.x1) - 0.5) as f64, floor_i(0.5 * (r.y0 + r.y1) - 0.5) as f64);
        let (ki, li) = (k as i64, l as i64);
        let (d00, d10, d01, d11) =
            (self.texel(ki, li), self.texel(ki + 1, li), self.texel(ki, li + 1), self.texel(ki + 1, li + 1));
        // The slope along x is linear in y inside the patch, and the slope along y in x.
        let gx = |y: f64| {
            let ty = y - l - 0.5;
            (d10 - d00) * (1.0 - ty) + (d11 - d01) * ty
        };
        let gy = |x: f64| {
            let tx = x - k - 0.5;
            (d01 - d00) * (1.0 - tx) + (d11 - d10) * tx
        };
        let (gx0, gx1) = (gx(r.y0).min(gx(r.y1)), gx(r.y0).max(gx(r.y1)));
        let (gy0, gy1) = (gy(r.x0).min(gy(r.x1)), gy(r.x0).max(gy(r.x1)));
        // The offsets X - p: a rectangle.
        let (vx0, vx1, vy0, vy1) = (r.x0 - cx0 - 1.0, r.x1 - cx0, r.y0 - cy0 - 1.0, r.y1 - cy0);
        let corners = [(vx0, vy0), (vx1, vy0), (vx0, vy1), (vx1, vy1)];
        let far = corners.iter().map(|&(x, y)| x.hypot(y)).fold(0.0, f64::max);
        let limit = r.min_depth / far;
        if vx0 <= 0.0 && vx1 >= 0.0 && vy0 <= 0.0 && vy1 >= 0.0 {
            // Every direction: the steepest slope counts.
            return gx0.abs().max(gx1.abs()).hypot(gy0.abs().max(gy1.abs())) > limit;
        }
        // Over a cone of directions g . u is largest at an edge direction (a corner of the offset
        // rectangle) unless g's own direction lies inside the cone, where it is |g|.
        let inside = |gx: f64, gy: f64| {
            // Does the ray {t (gx, gy), t > 0} meet the offset rectangle? (A slab test.)
            let slab = |g: f64, lo: f64, hi: f64| -> (f64, f64) {
                if g == 0.0 {
                    if lo <= 0.0 && hi >= 0.0 { (f64::NEG_INFINITY, f64::INFINITY) } else { (1.0, -1.0) }
                } else {
                    let (a, b) = (lo / g, hi / g);
                    (a.min(b), a.max(b))
                }
            };
            let (a0, a1) = slab(gx, vx0, vx1);
            let (b0, b1) = slab(gy, vy0, vy1);
            a0.max(b0).max(0.0) <= a1.min(b1) && a1.min(b1) > 0.0
        };
        let mut most = f64::NEG_INFINITY;
        for gx in [gx0, gx1] {
            for gy in [gy0, gy1] {
                let along = if inside(gx, gy) {
                    gx.hypot(gy)
                } else {
                    corners.iter().map(|&(x, y)| (gx * x + gy * y) / x.hypot(y)).fold(f64::NEG_INFINITY, f64::max)
                };
                most = most.max(along);
            }
        }
        most > limit
    }

    /// The cone ratio of footprint `(i, j)` and the surface point that decided it, starting from
    /// `witness` (a point that decided a neighbour's), over the surface a ray can reach from the
    /// footprint when its direction's signs along x and y are `quadrant` (the footprint swept
    /// along that quadrant; `None`: all of it), and, if `relaxed`, only where a ray from the top
    /// plane may leave the surface ([`Search::may_exit`]).
    ///
    /// The branch and bound: regions are popped from a stack, dropped when their lower bound
    /// ([`Search::lower`]) cannot beat the best ratio found, kept with their bound when small
    /// for their distance, and otherwise split ([`Search::split`]), the most promising child
    /// searched first.
    pub(super) fn ratio_ahead(
        &self,
        i: u32,
        j: u32,
        witness: Option<(f64, f64)>,
        quadrant: Option<(f64, f64)>,
        relaxed: bool,
    ) -> (f32, Option<(f64, f64)>) {
        let m = f64::from(self.pyramid.min_depth(0, i, j));
        if m <= self.global_min {
            // Nothing is shallower than this footprint's top.
            return (self.cap as f32, None);
        }
        let fp = self.footprint(i, j, m, quadrant, relaxed);
        let mut best = Best::new(self.cap);
        if let Some((x, y)) = witness {
            best.offer(fp.point_at(x, y, self.surface(x, y)), (x, y));
        }
        let far = if relaxed { FAR_RELAXED } else { FAR };
        let top = self.pyramid.len() - 1;
        let mut stack: Vec<(f64, Region)> = self
            .tiles
            .iter()
            .map(|&(tx, ty)| self.node(top, 0, 0, tx, ty))
            .map(|r| (self.lower(&fp, &r, f64::INFINITY), r))
            .collect();
        let mut children: Vec<(f64, Region)> = Vec::with_capacity(4);
        while let Some((lb, r)) = stack.pop() {
            if lb >= best.threshold() {
                continue;
            }
            // A region small for its distance: its bound is within a factor `1 + FAR` of the
            // least ratio of any of its points (which lie at most its diagonal further away).
            let diagonal = ((r.x1 - r.x0).powi(2) + (r.y1 - r.y0).powi(2)).sqrt();
            if diagonal <= far * fp.dist(&r) {
                best.floor = best.floor.min(lb);
                continue;
            }
            children.clear();
            self.split(&fp, &r, lb, &mut best, &mut children);
            let threshold = best.threshold();
            for c in &mut children {
                c.0 = self.lower(&fp, &c.1, threshold);
            }
            children.retain(|c| c.0 < threshold);
            // The most promising child is searched first: pushed last.
            for k in 1..children.len() {
                let mut n = k;
                while n > 0 && children[n - 1].0 < children[n].0 {
                    children.swap(n - 1, n);
                    n -= 1;
                }
            }
            stack.extend(children.iter());
        }
        let ratio = best.threshold().clamp(0.0, self.cap);
        (ratio as f32, best.at)
    }

    /// What the search of footprint `(i, j)`, whose top is `m`, needs to know of it.
    fn footprint(&self, i: u32, j: u32, m: f64, quadrant: Option<(f64, f64)>, relaxed: bool) -> Footprint {
        let (cx0, cy0) = (f64::from(i), f64::from(j));
        Footprint {
            i: i64::from(i),
            j: i64::from(j),
            m,
            cx0,
            cy0,
            cx1: cx0 + 1.0,
            cy1: cy0 + 1.0,
            // How far the stored top (f32) may lie below the surface over the footprint: the
            // slope bound starts from the surface, which is at least `m - excess` everywhere on it.
            excess: (m - self.exact_top(i64::from(i), i64::from(j))).max(0.0),
            quadrant,
            relaxed,
        }
    }

    /// The lower bound of region `r` for footprint `fp`, or infinity where it cannot matter;
    /// any value at or above `threshold` (which is all that is then needed of it) for a region
    /// that the distance bound alone already puts there.
    fn lower(&self, fp: &Footprint, r: &Region, threshold: f64) -> f64 {
        let (m, excess) = (fp.m, fp.excess);
        let (cx0, cx1, cy0, cy1) = (fp.cx0, fp.cx1, fp.cy0, fp.cy1);
        if r.min_depth >= m - LEVEL || !fp.ahead(r.x0, r.x1, r.y0, r.y1) {
            return f64::INFINITY;
        }
        let fall = m - r.min_depth;
        let dx = (cx0 - r.x1).max(r.x0 - cx1).max(0.0);
        let dy = (cy0 - r.y1).max(r.y0 - cy1).max(0.0);
        let reach = threshold * fall;
        if dx * dx + dy * dy >= reach * reach {
            return threshold;
        }
        if fp.relaxed && matches!(r.kind, Kind::Patch(_)) && !self.may_exit(cx0, cy0, r) {
            // Relaxed cones may hold surface where no ray from the top plane leaves it.
            return f64::INFINITY;
        }
        let near = (dx * dx + dy * dy).sqrt();
        let b = (near / fall).max(self.near_bound(fp.i, fp.j, m, r));
        if b >= threshold || excess >= LEVEL {
            return b;
        }
        // The slope bound ([`slope`]): over the box holding `r` and the part of the
        // footprint nearest to it, the surface rises at most `g` per texel from the
        // footprint's edge, so a point `t` away from it is at most `g t + excess` above the
        // top; it counts only if that is over LEVEL, so `t >= (LEVEL - excess) / g`, and
        // `t / (g t + excess)` grows with `t`.
        let (bx0, bx1) = (r.x0.min(r.x0.clamp(cx0, cx1)), r.x1.max(r.x1.clamp(cx0, cx1)));
        let (by0, by1) = (r.y0.min(r.y0.clamp(cy0, cy1)), r.y1.max(r.y1.clamp(cy0, cy1)));
        let slopes = self.slopes.as_ref().expect("made with the search");
        match slopes.max_over(bx0, bx1, by0, by1) {
            Some(g) if g > 0.0 => {
                let t = near.max((LEVEL - excess) / g);
                b.max(t / (g * t + excess))
            }
            Some(_) => f64::INFINITY,
            None => b,
        }
    }

    /// Splits region `r` (lower bound `lb`) into `children`: a pyramid cell into its children,
    /// a level-0 cell into the quarters that lie in one patch each, a rectangle inside a patch
    /// into halves along each axis after its corners are offered to `best`. A rectangle that
    /// needs no split (level with the footprint, or too small) gives none.
    fn split(&self, fp: &Footprint, r: &Region, lb: f64, best: &mut Best, children: &mut Vec<(f64, Region)>) {
        match r.kind {
            Kind::Node { level: 0, .. } => {
                // The footprint's four quarters, each inside one patch.
                let (xm, ym) = (r.x0 + 0.5, r.y0 + 0.5);
                for (x0, x1) in [(r.x0, xm), (xm, r.x1)] {
                    for (y0, y1) in [(r.y0, ym), (ym, r.y1)] {
                        children.push((0.0, self.patch_rect(x0, x1, y0, y1)));
                    }
                }
            }
            Kind::Node { level, x, y, tx, ty } => {
                let level = usize::from(level);
                let (cw, ch) = self.pyramid.level_size(level - 1);
                for (cx, cy) in [(2 * x, 2 * y), (2 * x + 1, 2 * y), (2 * x, 2 * y + 1), (2 * x + 1, 2 * y + 1)] {
                    if cx < cw && cy < ch {
                        children.push((0.0, self.node(level - 1, cx, cy, tx, ty)));
                    }
                }
            }
            Kind::Patch(d) => {
                for (k, (x, y)) in [(r.x0, r.y0), (r.x1, r.y0), (r.x0, r.y1), (r.x1, r.y1)].into_iter().enumerate() {
                    best.offer(fp.point_at(x, y, d[k]), (x, y));
                }
                // Level with the footprint along one axis, the ratio over the rectangle is
                // least at a corner: there the distance to the footprint is the offset along
                // the other axis, the surface is linear along each axis inside a patch, and
                // `offset / (m - depth)` is monotone along each. The corners just seen are
                // its exact least value: nothing to split.
                let band = (r.y0 >= fp.cy0 && r.y1 <= fp.cy1) || (r.x0 >= fp.cx0 && r.x1 <= fp.cx1);
                if band {
                    return;
                }
                if r.x1 - r.x0 <= MIN_REGION && r.y1 - r.y0 <= MIN_REGION {
                    best.floor = best.floor.min(lb);
                    return;
                }
                let (xm, ym) = (0.5 * (r.x0 + r.x1), 0.5 * (r.y0 + r.y1));
                let xs: &[(f64, f64)] =
                    if r.x1 - r.x0 > MIN_REGION { &[(r.x0, xm), (xm, r.x1)] } else { &[(r.x0, r.x1)] };
                let ys: &[(f64, f64)] =
                    if r.y1 - r.y0 > MIN_REGION { &[(r.y0, ym), (ym, r.y1)] } else { &[(r.y0, r.y1)] };
                for &(x0, x1) in xs {
                    for &(y0, y1) in ys {
                        children.push((0.0, self.patch_rect(x0, x1, y0, y1)));
                    }
                }
            }
        }
    }
}

/// The footprint `C = [cx0, cx1] x [cy0, cy1]` a cone is searched for, with its top `m`.
struct Footprint {
    i: i64,
    j: i64,
    m: f64,
    cx0: f64,
    cy0: f64,
    cx1: f64,
    cy1: f64,
    /// How far the stored (f32) top may lie below the surface over the footprint.
    excess: f64,
    /// The signs of the ray directions searched for (`None`: every direction).
    quadrant: Option<(f64, f64)>,
    relaxed: bool,
}

impl Footprint {
    /// Whether the rectangle `[x0, x1] x [y0, y1]` meets the footprint swept along the quadrant.
    fn ahead(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
        match self.quadrant {
            None => true,
            Some((sx, sy)) => {
                (if sx > 0.0 { x1 >= self.cx0 } else { x0 <= self.cx1 })
                    && (if sy > 0.0 { y1 >= self.cy0 } else { y0 <= self.cy1 })
            }
        }
    }

    /// The distance from region `r` to the footprint.
    fn dist(&self, r: &Region) -> f64 {
        let dx = (self.cx0 - r.x1).max(r.x0 - self.cx1).max(0.0);
        let dy = (self.cy0 - r.y1).max(r.y0 - self.cy1).max(0.0);
        (dx * dx + dy * dy).sqrt()
    }

    /// The ratio a surface point at `(x, y)` of depth `d` allows.
    fn point_at(&self, x: f64, y: f64, d: f64) -> f64 {
        if !self.ahead(x, x, y, y) || d >= self.m - LEVEL {
            return f64::INFINITY;
        }
        let dx = (self.cx0 - x).max(x - self.cx1).max(0.0);
        let dy = (self.cy0 - y).max(y - self.cy1).max(0.0);
        (dx * dx + dy * dy).sqrt() / (self.m - d)
    }
}

/// The search's state: the best (least) ratio a surface point gives and that point, and the
/// least lower bound of the regions kept unsplit.
struct Best {
    ratio: f64,
    at: Option<(f64, f64)>,
    floor: f64,
}

impl Best {
    /// Nothing needs a ratio over the cap: the search starts just above it.
    fn new(cap: f64) -> Self {
        Self { ratio: cap / (1.0 - SLACK), at: None, floor: f64::INFINITY }
    }

    /// Takes the point `at` if its ratio `r` is better.
    fn offer(&mut self, r: f64, at: (f64, f64)) {
        if r < self.ratio {
            (self.ratio, self.at) = (r, Some(at));
        }
    }

    /// The ratio found so far: the best point's with the slack, or a kept region's bound.
    fn threshold(&self) -> f64 {
        (self.ratio * (1.0 - SLACK)).min(self.floor)
    }
}
