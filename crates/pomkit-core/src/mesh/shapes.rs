//! The built-in shapes: plane, quad, disc, cube, UV sphere, cylinder and torus, with exact
//! normals, tangents and `uv_scale`.

use std::f64::consts::{PI, TAU};

use glam::{DVec3, Vec2, Vec3};

use super::*;

impl Mesh {
    /// A flat grid in the XZ plane, centred on the origin, facing +Y: `size.x` along X (u
    /// increases along +X), `size.y` along Z (v increases along +Z, so the image's top is toward
    /// -Z), `segments` x `segments` quads. T = +X, B = -Z, `w = +1`; `uv_scale = size`.
    #[must_use]
    pub fn plane(size: Vec2, segments: u32) -> Mesh {
        let n = clamp_segments(segments, 1);
        let mut b = Builder::default();
        b.grid(Vec3::ZERO, Vec3::X, -Vec3::Z, sane_size(size), n, n);
        b.finish()
    }

    /// A single quad in the XY plane, centred on the origin, facing +Z: u increases along +X and
    /// v along -Y (the image upright, seen from +Z). T = +X, B = +Y, `w = +1`; `uv_scale = size`.
    #[must_use]
    pub fn quad(size: Vec2) -> Mesh {
        let mut b = Builder::default();
        b.grid(Vec3::ZERO, Vec3::X, Vec3::Y, sane_size(size), 1, 1);
        b.finish()
    }

    /// A disc of `radius` in the XZ plane facing +Y, a fan of `segments` triangles (at least 3)
    /// around a centre vertex, with planar UVs as [`Mesh::plane`]'s: the disc inscribed in the
    /// unit UV square, u along +X, v along +Z. `uv_scale = (2 radius, 2 radius)`.
    #[must_use]
    pub fn disc(radius: f32, segments: u32) -> Mesh {
        let mut b = Builder::default();
        b.disc(f64::from(sane_length(radius)), 0.0, clamp_segments(segments, 3), true);
        b.finish()
    }

    /// A cube of edge `size` centred on the origin, each face with its own four vertices and the
    /// whole `[0, 1]` UV square, unmirrored (`w = +1`) seen from outside. The side faces show
    /// the image upright (v increases downward, along -Y): +Z has T = +X, -Z has T = -X, +X has
    /// T = -Z, -X has T = +Z, all with B = +Y. The top (+Y) is mapped as [`Mesh::plane`] (T = +X,
    /// B = -Z), the bottom (-Y) with T = +X, B = +Z. `uv_scale = (size, size)`.
    #[must_use]
    pub fn cube(size: f32) -> Mesh {
        let s = sane_length(size);
        let h = s * 0.5;
        let faces = [
            (Vec3::Z, Vec3::X, Vec3::Y),
            (-Vec3::Z, -Vec3::X, Vec3::Y),
            (Vec3::X, -Vec3::Z, Vec3::Y),
            (-Vec3::X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, -Vec3::Z),
            (-Vec3::Y, Vec3::X, Vec3::Z),
        ];
        let mut b = Builder::default();
        for (n, t, bt) in faces {
            b.grid(n * h, t, bt, Vec2::splat(s), 1, 1);
        }
        b.finish()
    }

    /// A UV sphere of `radius` centred on the origin, poles on the Y axis.
    ///
    /// `rings` latitude bands (at least 2) and `segments` longitude segments (at least 3). v is 0
    /// at the north pole (+Y) and 1 at the south pole (the image upright); u is the longitude
    /// over 2 pi, increasing eastward seen from outside (T = east, B = north, `w = +1`), with
    /// u = 0.5 facing +Z and the seam (u = 0 and u = 1, a duplicated column of vertices) facing
    /// -Z. Each pole is a row of `segments` vertices at u = (i + 0.5) / segments. Normals are
    /// exact (`position / radius`); `uv_scale` approaches `(2 pi r cos(latitude), pi r)`.
    #[must_use]
    pub fn uv_sphere(radius: f32, rings: u32, segments: u32) -> Mesh {
        let r = f64::from(sane_length(radius));
        let (rings, segs) = (clamp_segments(rings, 2), clamp_segments(segments, 3));
        let mut b = Builder::default();
        let pole = |b: &mut Builder, v: f32, y: f64| -> u32 {
            let first = b.len();
            for i in 0..segs {
                b.push(DVec3::new(0.0, y, 0.0), DVec3::new(0.0, y.signum(), 0.0), (i as f32 + 0.5) / segs as f32, v);
            }
            first
        };
        let north = pole(&mut b, 0.0, r);
        let rows = b.len();
        let row_len = segs + 1;
        for j in 1..rings {
            let v = j as f64 / rings as f64;
            let lat = PI * (0.5 - v);
            for i in 0..=segs {
                let u = i as f64 / segs as f64;
                let lon = TAU * (u - 0.5);
                let n = DVec3::new(lat.cos() * lon.sin(), lat.sin(), lat.cos() * lon.cos());
                b.push(n * r, n, u as f32, v as f32);
            }
        }
        let south = pole(&mut b, 1.0, -r);
        let at = |i: u32, j: u32| rows + (j - 1) * row_len + i;
        for i in 0..segs {
            b.indices.extend([north + i, at(i, 1), at(i + 1, 1)]);
            for j in 1..rings - 1 {
                b.quad(at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
            }
            b.indices.extend([at(i, rings - 1), south + i, at(i + 1, rings - 1)]);
        }
        b.finish()
    }

    /// A cylinder of `radius` and `height` around the Y axis, centred on the origin, with caps.
    ///
    /// The side is mapped as [`Mesh::uv_sphere`]'s equator: u around (eastward, seam facing -Z,
    /// a duplicated column), v from 0 at the top to 1 at the bottom; T = east, B = +Y, `w = +1`,
    /// `uv_scale` about `(2 pi radius, height)`. The caps have their own vertices (a hard edge)
    /// and planar UVs: the top (+Y) as [`Mesh::disc`], the bottom (-Y) as [`Mesh::cube`]'s
    /// bottom face (T = +X, B = +Z). `segments` (at least 3) is the count around.
    #[must_use]
    pub fn cylinder(radius: f32, height: f32, segments: u32) -> Mesh {
        let r = f64::from(sane_length(radius));
        let h = f64::from(sane_length(height));
        let segs = clamp_segments(segments, 3);
        let mut b = Builder::default();
        let first = b.len();
        for j in 0..2u32 {
            for i in 0..=segs {
                let u = i as f64 / segs as f64;
                let lon = TAU * (u - 0.5);
                let n = DVec3::new(lon.sin(), 0.0, lon.cos());
                b.push(n * r + DVec3::Y * h * (0.5 - f64::from(j)), n, u as f32, j as f32);
            }
        }
        let at = |i: u32, j: u32| first + j * (segs + 1) + i;
        for i in 0..segs {
            b.quad(at(i, 0), at(i + 1, 0), at(i, 1), at(i + 1, 1));
        }
        b.disc(r, h * 0.5, segs, true);
        b.disc(r, -h * 0.5, segs, false);
        b.finish()
    }

    /// A torus around the Y axis, centred on the origin: tube centre circle of radius `major`,
    /// tube radius `minor`, `seg_major` segments around the axis and `seg_minor` around the tube
    /// (each at least 3), both seams duplicated.
    ///
    /// u runs around the axis as [`Mesh::uv_sphere`]'s longitude (eastward, seam facing -Z); v
    /// runs around the tube, 0 on the inner equator, 0.25 on top, 0.5 on the outer equator, 0.75
    /// underneath, so the image is upright on the outside (T = east, B = up there, `w = +1`).
    /// Normals point away from the tube's centre circle. `uv_scale` is about
    /// `(2 pi (major + minor cos b), 2 pi minor)` with b the angle above the outer equator.
    #[must_use]
    pub fn torus(major: f32, minor: f32, seg_major: u32, seg_minor: u32) -> Mesh {
        let big = f64::from(sane_length(major));
        let small = f64::from(sane_length(minor));
        let (sm, sn) = (clamp_segments(seg_major, 3), clamp_segments(seg_minor, 3));
        let mut b = Builder::default();
        for j in 0..=sn {
            let v = j as f64 / sn as f64;
            let beta = PI * (1.0 - 2.0 * v);
            for i in 0..=sm {
                let u = i as f64 / sm as f64;
                let lon = TAU * (u - 0.5);
                let radial = DVec3::new(lon.sin(), 0.0, lon.cos());
                let n = radial * beta.cos() + DVec3::Y * beta.sin();
                b.push(radial * big + n * small, n, u as f32, v as f32);
            }
        }
        let at = |i: u32, j: u32| j * (sm + 1) + i;
        for j in 0..sn {
            for i in 0..sm {
                b.quad(at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
            }
        }
        b.finish()
    }
}

// ---------------------------------------------------------------------------------------------
// Shapes
// ---------------------------------------------------------------------------------------------

/// Accumulates a shape's vertices (with exact normals) and triangles.
#[derive(Default)]
struct Builder {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    indices: Vec<u32>,
}

impl Builder {
    fn len(&self) -> u32 {
        self.positions.len() as u32
    }

    fn push(&mut self, p: DVec3, n: DVec3, u: f32, v: f32) {
        self.positions.push(clamp_to_f32(p));
        self.normals.push(n.as_vec3().normalize_or(Vec3::Y));
        self.uvs.push(Vec2::new(u, v));
    }

    /// Two counter-clockwise triangles for a quad laid out like the image: `a` top-left, `b`
    /// top-right, `c` bottom-left, `d` bottom-right, seen from the front (T to the right, B up).
    fn quad(&mut self, a: u32, b: u32, c: u32, d: u32) {
        self.indices.extend([a, c, b, b, c, d]);
    }

    /// A flat `nx` x `ny` grid centred on `center` with unit tangent `t` (u to the right) and
    /// bitangent `b` (up the image), facing `cross(t, b)`, spanning `size` and UV `[0, 1]^2`.
    fn grid(&mut self, center: Vec3, t: Vec3, b: Vec3, size: Vec2, nx: u32, ny: u32) {
        let first = self.len();
        let (c, t, b, n) = (center.as_dvec3(), t.as_dvec3(), b.as_dvec3(), t.cross(b).as_dvec3());
        let size = size.as_dvec2();
        for j in 0..=ny {
            for i in 0..=nx {
                let (s, r) = (f64::from(i) / f64::from(nx), f64::from(j) / f64::from(ny));
                self.push(c + t * ((s - 0.5) * size.x) + b * ((0.5 - r) * size.y), n, s as f32, r as f32);
            }
        }
        let at = |i: u32, j: u32| first + j * (nx + 1) + i;
        for j in 0..ny {
            for i in 0..nx {
                self.quad(at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
            }
        }
    }

    /// A fan disc at height `y`, facing +Y (`up`, mapped as the plane: v along +Z) or -Y (mapped
    /// with v along -Z, so that it is unmirrored seen from below).
    fn disc(&mut self, r: f64, y: f64, segs: u32, up: bool) {
        let n = if up { DVec3::Y } else { -DVec3::Y };
        let centre = self.len();
        self.push(DVec3::new(0.0, y, 0.0), n, 0.5, 0.5);
        for k in 0..segs {
            let a = TAU * f64::from(k) / f64::from(segs);
            let (s, c) = a.sin_cos();
            let v = if up { 0.5 + 0.5 * s } else { 0.5 - 0.5 * s };
            self.push(DVec3::new(r * c, y, r * s), n, (0.5 + 0.5 * c) as f32, v as f32);
        }
        for k in 0..segs {
            let (p, q) = (centre + 1 + k, centre + 1 + (k + 1) % segs);
            // Rim points go from +X toward +Z: clockwise seen from +Y.
            self.indices.extend(if up { [centre, q, p] } else { [centre, p, q] });
        }
    }

    fn finish(self) -> Mesh {
        let Builder { positions, normals, uvs, indices } = self;
        let opts = TangentOptions { method: TangentMethod::MikkTSpace, ..TangentOptions::default() };
        // The shapes' data is valid by construction; should that ever fail, fall back to frames
        // that are still orthonormal.
        let tangents = compute_tangents(&positions, &normals, &uvs, &indices, &opts)
            .unwrap_or_else(|_| normals.iter().map(|n| n.any_orthonormal_vector().extend(1.0)).collect());
        let uv_scale = compute_uv_scale(&positions, &uvs, &indices);
        Mesh { positions, normals, uvs, tangents, uv_scale, indices }
    }
}
