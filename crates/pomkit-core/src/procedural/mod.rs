//! Procedural height maps and matching albedo (colour) maps.
//!
//! Every pattern is a function of the texel centre's UV, `u = (x + 0.5) / w`, `v = (y + 0.5) / h`
//! (ARCHITECTURE.md, Conventions: `(0, 0)` is the top-left corner, `v` runs down the rows). Bricks,
//! pyramids, cobblestones, waves, fur and grass are periodic in `u` and `v` with period 1, so
//! they tile seamlessly at any size, powers of two or not: the texel after the last column
//! continues the first one. Text and spike are not periodic but are flat along the border, so they tile too.
//! Randomness comes from an integer hash of cell indices taken modulo the tile's cell count, so
//! the output is deterministic and the same on every machine.
//!
//! Heights follow the art-tool convention: 1 (white) is the surface top, 0 the deepest point.
//! [`generate`] turns them into a [`HeightField`], which stores depth `1 - h`.

use std::f32::consts::{PI, TAU};
use std::fmt;
use std::str::FromStr;
use std::sync::LazyLock;

mod patterns;
use patterns::*;
pub use patterns::{
    FUR_CELLS, FUR_HAIRS_PER_CELL, GRASS_BLADES_PER_CELL, GRASS_CELLS, WAVES_PERIODS, waves_gradient, waves_height,
};

use rayon::prelude::*;

use crate::heightfield::HeightField;

/// A built-in procedural height map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Pattern {
    /// Running-bond brick wall: 4 courses of 2 bricks per tile, alternate courses shifted by half
    /// a brick. Flat brick faces near 1 (each brick lowered by up to 0.06 by a hash, plus a
    /// grain of 0.015) with quarter-round edges over 0.018 tile units; mortar joints
    /// 0.024 tile units wide, recessed to 0.3 (plus a grain of 0.02).
    Bricks,
    /// A 4x4 grid of square pyramids per tile: `h = 1 - 2 max(|fu - 1/2|, |fv - 1/2|)` where
    /// `(fu, fv)` is the position inside a pyramid's cell, so the apex is 1, the base 0 and each
    /// face is a plane of slope 8 per tile.
    Pyramids,
    /// Rounded stones: Voronoi cells over a jittered 6x6 grid per tile, each raised as a dome
    /// (a quarter-circle profile of the smoothed distance to the cell border) to a top between
    /// 0.82 and 1; the gaps between stones are low (0.08 to 0.16).
    Cobblestones,
    /// Raised lettering: the word POMKIT in two lines ("POM" over "KIT") of a built-in 5x7
    /// bitmap font drawn as round-capped strokes, letters at 1 with smooth bevelled edges, on a
    /// flat plate at 0.35. Reads normally with row 0 at the top. Tiles too, as the plate's
    /// margin is flat.
    Text,
    /// Flat at 0 except one texel of height 1: the texel `(w / 2, h / 2)` (integer division),
    /// the one nearest the centre. Tests that a tracer never misses a one-texel feature.
    Spike,
    /// A smooth analytic field, see [`waves_height`]:
    /// `h = 1/2 + 1/2 sin(2 pi k u) cos(2 pi k v)` with `k` = [`WAVES_PERIODS`].
    Waves,
    /// Short dense fur for McGuire 2005's fur rendering by steep parallax (docs/REFERENCES.md):
    /// [`FUR_HAIRS_PER_CELL`] hairs in each cell of a [`FUR_CELLS`] x [`FUR_CELLS`] grid per tile,
    /// each at a hashed position with a hashed base radius and tip height (0.55 to 1). A hair
    /// is a cone with concave flanks and a rounded tip, 1 x its tip height at the centre falling
    /// to the skin (height 0, depth 1) at its base radius; where hairs overlap the highest wins.
    /// Thin: at 512x512, 8% of the area lies above mid-height, in strands 2.3 texels thick on
    /// average, and three quarters of it deeper than 0.75.
    Fur,
    /// Grass for McGuire 2005's fur and grass (docs/REFERENCES.md): [`GRASS_BLADES_PER_CELL`]
    /// blades in each cell of a [`GRASS_CELLS`] x [`GRASS_CELLS`] grid per tile (sparser than
    /// [`Pattern::Fur`]), each a thin, slightly curved ridge in a hashed direction whose top
    /// edge rises to a pointed tip (heights 0.45 to 1) between steep sides, over a soil floor
    /// at heights 0 to 0.08. At 512x512, 3% of the area lies above mid-height, in blades 2.3
    /// texels thick on average.
    Grass,
}

impl Pattern {
    /// Every pattern, in declaration order.
    pub const ALL: [Pattern; 8] = [
        Pattern::Bricks,
        Pattern::Pyramids,
        Pattern::Cobblestones,
        Pattern::Text,
        Pattern::Spike,
        Pattern::Waves,
        Pattern::Fur,
        Pattern::Grass,
    ];

    /// The lowercase name used on the command line and in scene files (`"bricks"`, ...).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Pattern::Bricks => "bricks",
            Pattern::Pyramids => "pyramids",
            Pattern::Cobblestones => "cobblestones",
            Pattern::Text => "text",
            Pattern::Spike => "spike",
            Pattern::Waves => "waves",
            Pattern::Fur => "fur",
            Pattern::Grass => "grass",
        }
    }
}

impl fmt::Display for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The name given to [`Pattern::from_str`] is not a known pattern.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown pattern {name:?}: expected one of {}", valid_names())]
pub struct UnknownPattern {
    /// The name that was given.
    pub name: String,
}

/// `"bricks, pyramids, ..."`, for error messages.
fn valid_names() -> String {
    Pattern::ALL.map(Pattern::name).join(", ")
}

impl FromStr for Pattern {
    type Err = UnknownPattern;

    /// Parses a pattern name, ignoring ASCII case and surrounding white space.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let trimmed = s.trim();
        Pattern::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(trimmed))
            .ok_or_else(|| UnknownPattern { name: s.to_owned() })
    }
}

/// Builds the height map of `pattern` at `width` x `height` texels (a size of 0 is treated as 1).
///
/// Deterministic: the same arguments always give the same field.
#[must_use]
pub fn generate(pattern: Pattern, width: u32, height: u32) -> HeightField {
    generate_with_progress(pattern, width, height, &|_| {})
}

/// [`generate`], calling `progress(rows)` as each batch of `rows` rows is done (from the
/// worker threads, in no particular order; the calls add up to the height). Rows are computed
/// in parallel; the values are [`generate`]'s.
#[must_use]
pub fn generate_with_progress(
    pattern: Pattern,
    width: u32,
    height: u32,
    progress: &(dyn Fn(u32) + Sync),
) -> HeightField {
    let (w, h) = (width.max(1), height.max(1));
    let heights = per_texel(w, h, progress, |x, y| {
        let (u, v) = texel_uv(x, y, w, h);
        match pattern {
            Pattern::Bricks => bricks(u, v).height,
            Pattern::Pyramids => pyramid_height(u, v),
            Pattern::Cobblestones => cobbles(u, v).height,
            Pattern::Text => text(u, v).height,
            Pattern::Spike => spike_height(x, y, w, h),
            Pattern::Waves => waves_height(u, v),
            Pattern::Fur => fur(u, v).height,
            Pattern::Grass => grass(u, v).height,
        }
    });
    HeightField::from_height_fn(w, h, |x, y| heights[y as usize * w as usize + x as usize])
}

/// A colour map matching [`generate`]'s height map: `width * height` sRGB texels, row-major,
/// top row first (a size of 0 is treated as 1).
///
/// Bricks are red-brown with a per-brick tint in grey mortar, pyramids sandstone laid in
/// courses, cobblestones grey to brown per stone on dark soil, text brass letters on a slate
/// plate, waves deep to pale blue by height, the spike an orange texel on light grey, fur warm
/// brown per hair with dark roots and light tips on dark skin, and grass green blades with
/// yellowish tips over brown soil.
#[must_use]
pub fn albedo(pattern: Pattern, width: u32, height: u32) -> Vec<[u8; 3]> {
    albedo_with_progress(pattern, width, height, &|_| {})
}

/// [`albedo`], calling `progress(rows)` as rows are done (see [`generate_with_progress`]).
#[must_use]
pub fn albedo_with_progress(
    pattern: Pattern,
    width: u32,
    height: u32,
    progress: &(dyn Fn(u32) + Sync),
) -> Vec<[u8; 3]> {
    let (w, h) = (width.max(1), height.max(1));
    per_texel(w, h, progress, |x, y| {
        let (u, v) = texel_uv(x, y, w, h);
        let rgb = match pattern {
            Pattern::Bricks => bricks_albedo(u, v),
            Pattern::Pyramids => pyramid_albedo(u, v),
            Pattern::Cobblestones => cobbles_albedo(u, v),
            Pattern::Text => text_albedo(u, v),
            Pattern::Spike => {
                if spike_height(x, y, w, h) > 0.5 {
                    [0.93, 0.42, 0.13]
                } else {
                    [0.74, 0.74, 0.72]
                }
            }
            Pattern::Waves => {
                let t = waves_height(u, v);
                mix([0.12, 0.3, 0.5], [0.7, 0.85, 0.9], t)
            }
            Pattern::Fur => fur_albedo(u, v),
            Pattern::Grass => grass_albedo(u, v),
        };
        rgb.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
    })
}

/// Evaluates `f(x, y)` at every texel, rows in parallel; row-major result. `progress(1)` is
/// called after each row.
fn per_texel<T: Send + Copy + Default>(
    w: u32,
    h: u32,
    progress: &(dyn Fn(u32) + Sync),
    f: impl Fn(u32, u32) -> T + Sync,
) -> Vec<T> {
    let mut out = vec![T::default(); w as usize * h as usize];
    out.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| {
        for (x, texel) in row.iter_mut().enumerate() {
            *texel = f(x as u32, y as u32);
        }
        progress(1);
    });
    out
}

/// UV of the centre of texel `(x, y)`.
fn texel_uv(x: u32, y: u32, w: u32, h: u32) -> (f32, f32) {
    ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32)
}

// ---------------------------------------------------------------------------------------------
// Shared helpers: hashing, periodic value noise, blending.
// ---------------------------------------------------------------------------------------------

/// Mixes three integers into 32 well-scrambled bits (a 64-bit multiply-xorshift finalizer).
fn hash3(a: u32, b: u32, c: u32) -> u32 {
    let mut x = u64::from(a) | (u64::from(b) << 32);
    x ^= u64::from(c).wrapping_add(0x632b_e59b_d9b4_e019).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 31)).wrapping_mul(0xd6e8_feb8_6659_fd93);
    x = (x ^ (x >> 29)).wrapping_mul(0xa076_1d64_78bd_642f);
    (x ^ (x >> 32)) as u32
}

/// A hash in `[0, 1)`.
fn hash01(a: u32, b: u32, c: u32) -> f32 {
    (hash3(a, b, c) >> 8) as f32 / (1u32 << 24) as f32
}

/// The lattice cell containing coordinate `i` (any sign), wrapped into `0..n`.
fn wrap_index(i: f32, n: u32) -> u32 {
    (i.floor() as i64).rem_euclid(i64::from(n)) as u32
}

/// Hermite smoothstep of `t` clamped to `[0, 1]`.
fn smoothstep(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Value noise in `[0, 1]` over a lattice of `period` x `period` cells per tile: periodic in `u`
/// and `v` with period 1, smooth (quintic fade) between lattice values.
fn value_noise(u: f32, v: f32, period: u32, seed: u32) -> f32 {
    let (x, y) = (u * period as f32, v * period as f32);
    let (x0, y0) = (x.floor(), y.floor());
    let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (sx, sy) = (fade(x - x0), fade(y - y0));
    let corner = |dx: f32, dy: f32| hash01(wrap_index(x0 + dx, period), wrap_index(y0 + dy, period), seed);
    let top = corner(0.0, 0.0) + (corner(1.0, 0.0) - corner(0.0, 0.0)) * sx;
    let bottom = corner(0.0, 1.0) + (corner(1.0, 1.0) - corner(0.0, 1.0)) * sx;
    top + (bottom - top) * sy
}

/// Two octaves of [`value_noise`] (base `period` and twice it), in `[0, 1]`.
fn fbm(u: f32, v: f32, period: u32, seed: u32) -> f32 {
    (2.0 * value_noise(u, v, period, seed) + value_noise(u, v, 2 * period, seed ^ 0x5bd1)) / 3.0
}

/// Linear blend of two colours.
fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * t)
}

/// A colour scaled by `k`.
fn scale(c: [f32; 3], k: f32) -> [f32; 3] {
    c.map(|x| x * k)
}

/// A rounded edge profile on `[0, 1]`: a quarter circle, vertical at 0 and flat at 1.
fn quarter_round(t: f32) -> f32 {
    let s = 1.0 - t.clamp(0.0, 1.0);
    (1.0 - s * s).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::EdgeMode;

    fn heights(p: Pattern, w: u32, h: u32) -> Vec<f32> {
        let hf = generate(p, w, h);
        assert_eq!((hf.width(), hf.height()), (w.max(1), h.max(1)));
        hf.heights()
    }

    /// Largest jump across the wrap seam and largest jump between interior neighbours, along
    /// x (`along_y = false`) or y, plus the means of both.
    fn seam_stats(hf: &HeightField, along_y: bool) -> (f32, f32, f32, f32) {
        let (w, h) = (i64::from(hf.width()), i64::from(hf.height()));
        let (n, m) = if along_y { (h, w) } else { (w, h) };
        let at = |i: i64, j: i64| {
            if along_y { hf.height_at(j, i, EdgeMode::Clamp) } else { hf.height_at(i, j, EdgeMode::Clamp) }
        };
        let (mut edge_max, mut edge_sum, mut inner_max, mut inner_sum) = (0.0f32, 0.0, 0.0f32, 0.0);
        for j in 0..m {
            let e = (at(n - 1, j) - at(0, j)).abs();
            edge_max = edge_max.max(e);
            edge_sum += e;
            for i in 0..n - 1 {
                let d = (at(i + 1, j) - at(i, j)).abs();
                inner_max = inner_max.max(d);
                inner_sum += d;
            }
        }
        (edge_max, edge_sum / m as f32, inner_max, inner_sum / (m * (n - 1)) as f32)
    }

    /// The seam may be a little steeper than any interior pair (waves put their steepest point
    /// exactly on it), but not more than 10 % steeper, and not steeper on average than a few
    /// times the mean interior step.
    fn is_seamless(hf: &HeightField) -> bool {
        [false, true].into_iter().all(|along_y| {
            let (edge_max, edge_mean, inner_max, inner_mean) = seam_stats(hf, along_y);
            edge_max <= 1.1 * inner_max + 1e-6 && edge_mean <= 2.5 * inner_mean + 1e-6
        })
    }

    #[test]
    fn names_round_trip_and_errors_list_the_choices() {
        for p in Pattern::ALL {
            assert_eq!(p.name().parse::<Pattern>(), Ok(p));
            assert_eq!(p.to_string(), p.name());
            assert_eq!(p.name(), p.name().to_lowercase());
        }
        assert_eq!(" Bricks ".parse::<Pattern>(), Ok(Pattern::Bricks));
        let err = "marble".parse::<Pattern>().unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("marble"), "{msg}");
        for p in Pattern::ALL {
            assert!(msg.contains(p.name()), "{msg}");
        }
    }

    #[test]
    fn heights_are_finite_and_in_range_at_any_size() {
        for p in Pattern::ALL {
            for (w, h) in [(37, 23), (1, 1), (0, 0), (2, 3), (64, 64)] {
                let hs = heights(p, w, h);
                assert_eq!(hs.len(), (w.max(1) * h.max(1)) as usize);
                for (k, &v) in hs.iter().enumerate() {
                    assert!(v.is_finite() && (0.0..=1.0).contains(&v), "{p} {w}x{h} texel {k}: {v}");
                }
            }
        }
    }

    #[test]
    fn patterns_are_deterministic_and_not_constant() {
        for p in Pattern::ALL {
            let a = heights(p, 40, 30);
            assert_eq!(a, heights(p, 40, 30), "{p}");
            let (lo, hi) = a.iter().fold((1.0f32, 0.0f32), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            assert!(hi - lo > 0.5, "{p}: range {lo}..{hi}");
        }
    }

    #[test]
    fn tiling_patterns_are_seamless_at_odd_and_even_sizes() {
        // The check itself must reject a field that does not tile.
        let ramp = HeightField::from_height_fn(50, 40, |x, _| x as f32 / 49.0);
        assert!(!is_seamless(&ramp));
        let half_pyramids = HeightField::from_height_fn(64, 64, |x, y| {
            pyramid_height((x as f32 + 0.5) / 64.0 * 0.875, (y as f32 + 0.5) / 64.0 * 0.875)
        });
        assert!(!is_seamless(&half_pyramids));
        for p in [
            Pattern::Bricks,
            Pattern::Pyramids,
            Pattern::Cobblestones,
            Pattern::Waves,
            Pattern::Text,
            Pattern::Fur,
            Pattern::Grass,
        ] {
            for (w, h) in [(256, 256), (37, 23), (100, 60)] {
                let hf = generate(p, w, h);
                for along_y in [false, true] {
                    let stats = seam_stats(&hf, along_y);
                    assert!(is_seamless(&hf), "{p} {w}x{h} along_y={along_y}: {stats:?}");
                }
            }
        }
    }

    #[test]
    fn pyramids_have_apex_base_and_linear_faces() {
        let (w, h) = (256u32, 256u32);
        let hf = generate(Pattern::Pyramids, w, h);
        let at = |x: i64, y: i64| hf.height_at(x, y, EdgeMode::Clamp);
        // Cells are 64 texels: the apex lies between texels 31 and 32, the base corner between
        // texels 63 and 64 (and at the tile corner).
        assert!(at(31, 31) > 0.98 && at(32, 32) > 0.98, "{}", at(31, 31));
        assert!(at(0, 0) < 0.02 && at(63, 64) < 0.02 && at(255, 255) < 0.02, "{}", at(0, 0));
        // Along the row through the apex the height changes by 2 * 4 / w per texel, rising up to
        // the apex and falling after it.
        let slope = 2.0 * PYRAMIDS_PER_TILE / w as f32;
        for x in 1..30 {
            assert!((at(x + 1, 31) - at(x, 31) - slope).abs() < 1e-4, "x = {x}");
            assert!((at(x + 33, 31) - at(x + 32, 31) + slope).abs() < 1e-4, "x = {}", x + 32);
        }
        // Every texel matches the formula at an odd size too.
        let hf = generate(Pattern::Pyramids, 37, 23);
        for y in 0..23 {
            for x in 0..37 {
                let (u, v) = ((x as f32 + 0.5) / 37.0, (y as f32 + 0.5) / 23.0);
                let (fu, fv) = ((4.0 * u).fract(), (4.0 * v).fract());
                let expect = 1.0 - 2.0 * (fu - 0.5).abs().max((fv - 0.5).abs());
                assert!((hf.height_at(x, y, EdgeMode::Clamp) - expect).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn spike_is_one_texel_nearest_the_centre() {
        for (w, h) in [(256, 256), (37, 23), (1, 1), (2, 5)] {
            let hs = heights(Pattern::Spike, w, h);
            let ones: Vec<usize> = (0..hs.len()).filter(|&k| hs[k] == 1.0).collect();
            assert_eq!(ones, vec![(h / 2 * w + w / 2) as usize], "{w}x{h}");
            assert_eq!(hs.iter().filter(|&&v| v == 0.0).count(), hs.len() - 1, "{w}x{h}");
        }
    }

    #[test]
    fn text_has_letters_on_a_plate_reading_left_to_right() {
        let (w, h) = (256u32, 256u32);
        let hs = heights(Pattern::Text, w, h);
        let n = hs.len() as f32;
        let letters = hs.iter().filter(|&&v| v > 0.9).count() as f32 / n;
        let plate = hs.iter().filter(|&&v| (v - PLATE_HEIGHT).abs() < 0.01).count() as f32 / n;
        assert!((0.1..=0.4).contains(&letters), "letters {letters}");
        assert!(plate > 0.4, "plate {plate}");
        // The layout is 21 x 20 font pixels; the P occupies columns 2..7, rows 2..9.
        let (cols, rows) = (text_columns() as f32, text_rows() as f32);
        assert_eq!((cols, rows), (21.0, 20.0));
        let at_pixel = |col: f32, row: f32| {
            let x = ((col + 0.5) / cols * w as f32) as usize;
            let y = ((row + 0.5) / rows * h as f32) as usize;
            hs[y * w as usize + x]
        };
        // P's stem (column 0) on every row; its bowl closes on the right (column 4) at rows 1-2
        // but not at rows 4-6: the glyph is neither mirrored nor upside down.
        for row in 0..7 {
            assert!(at_pixel(2.0, 2.0 + row as f32) > 0.99, "stem row {row}");
        }
        for row in [1.0, 2.0] {
            assert!(at_pixel(6.0, 2.0 + row) > 0.99, "bowl row {row}");
        }
        for row in [4.0, 5.0, 6.0] {
            assert!((at_pixel(6.0, 2.0 + row) - PLATE_HEIGHT).abs() < 0.01, "row {row}");
        }
        // The left half holds the P; the plate margin is flat.
        assert!(hs.iter().enumerate().any(|(k, &v)| (k % w as usize) < 128 && v > 0.99));
        assert!((0..w as usize).all(|x| (hs[x] - PLATE_HEIGHT).abs() < 1e-6));
        // T's bar spans its top row, its stem only the middle column.
        assert!(at_pixel(14.0, 11.0) > 0.99 && at_pixel(18.0, 11.0) > 0.99);
        assert!((at_pixel(14.0, 15.0) - PLATE_HEIGHT).abs() < 0.01 && at_pixel(16.0, 15.0) > 0.99);
    }

    #[test]
    fn bricks_have_recessed_mortar_and_high_faces() {
        let hs = heights(Pattern::Bricks, 256, 256);
        let n = hs.len() as f32;
        let mortar = hs.iter().filter(|&&v| v < 0.35).count() as f32 / n;
        let faces = hs.iter().filter(|&&v| v > 0.9).count() as f32 / n;
        assert!((0.08..=0.3).contains(&mortar), "mortar {mortar}");
        assert!(faces > 0.6, "faces {faces}");
        assert!(hs.iter().all(|&v| v >= 0.28));
        // Alternate courses are offset by half a brick: the vertical joint at u = 0 cuts the
        // first course but not the second, the one at u = 1/4 the second but not the first.
        let course_mid = |c: usize| (c * 64 + 32) * 256;
        assert!(hs[course_mid(0)] < 0.35 && hs[course_mid(1)] > 0.9);
        assert!(hs[course_mid(0) + 64] > 0.9 && hs[course_mid(1) + 64] < 0.35);
    }

    #[test]
    fn cobbles_have_low_gaps_and_raised_stones() {
        let hs = heights(Pattern::Cobblestones, 256, 256);
        let n = hs.len() as f32;
        let gaps = hs.iter().filter(|&&v| v < 0.2).count() as f32 / n;
        let tops = hs.iter().filter(|&&v| v > 0.75).count() as f32 / n;
        assert!((0.05..=0.35).contains(&gaps), "gaps {gaps}");
        assert!(tops > 0.3, "tops {tops}");
    }

    #[test]
    fn waves_match_the_documented_formula_and_gradient() {
        let (w, h) = (48u32, 36u32);
        let hf = generate(Pattern::Waves, w, h);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = texel_uv(x, y, w, h);
                let k = WAVES_PERIODS as f32;
                let expect = 0.5 + 0.5 * (2.0 * PI * k * u).sin() * (2.0 * PI * k * v).cos();
                assert!((hf.height_at(x.into(), y.into(), EdgeMode::Wrap) - expect).abs() < 1e-5);
            }
        }
        let e = 1e-3f32;
        for (u, v) in [(0.1, 0.2), (0.37, 0.81), (0.5, 0.05), (0.93, 0.66)] {
            let (gu, gv) = waves_gradient(u, v);
            let fu = (waves_height(u + e, v) - waves_height(u - e, v)) / (2.0 * e);
            let fv = (waves_height(u, v + e) - waves_height(u, v - e)) / (2.0 * e);
            assert!((gu - fu).abs() < 2e-2 && (gv - fv).abs() < 2e-2, "({u}, {v})");
        }
        assert!((waves_gradient(0.0, 0.0).0 - PI * 2.0).abs() < 1e-5);
    }

    /// Mean error of the field's bilinear samples against the pattern `f` itself, at points
    /// halfway between texel centres: across the wrap seam (between the last texel and the
    /// first, where only a tiling field is continuous) and inside, along x and along y.
    fn seam_and_inner_errors(hf: &HeightField, f: impl Fn(f32, f32) -> f32) -> [(f32, f32); 2] {
        let (w, h) = (hf.width(), hf.height());
        let (wf, hf_) = (w as f32, h as f32);
        // The field stores depth, the pattern gives heights.
        let err = |u: f32, v: f32| (1.0 - hf.sample_bilinear(glam::Vec2::new(u, v), EdgeMode::Wrap) - f(u, v)).abs();
        let mean = |xs: &mut dyn Iterator<Item = f32>| {
            let (s, n) = xs.fold((0.0f32, 0u32), |(s, n), e| (s + e, n + 1));
            s / n.max(1) as f32
        };
        // Along x: u = k / w is halfway between texels k - 1 and k; k = 0 is the seam.
        let rows = |k: u32| (0..h).map(move |y| (k as f32 / wf, (y as f32 + 0.5) / hf_));
        let cols = |k: u32| (0..w).map(move |x| ((x as f32 + 0.5) / wf, k as f32 / hf_));
        let x_seam = mean(&mut rows(0).map(|(u, v)| err(u, v)));
        let x_inner = mean(&mut (1..w).flat_map(rows).map(|(u, v)| err(u, v)));
        let y_seam = mean(&mut cols(0).map(|(u, v)| err(u, v)));
        let y_inner = mean(&mut (1..h).flat_map(cols).map(|(u, v)| err(u, v)));
        [(x_seam, x_inner), (y_seam, y_inner)]
    }

    /// The strand patterns as functions of UV, for comparing with their fields.
    fn strand_height(p: Pattern) -> fn(f32, f32) -> f32 {
        match p {
            Pattern::Fur => |u, v| fur(u, v).height,
            _ => |u, v| grass(u, v).height,
        }
    }

    #[test]
    fn fur_and_grass_tile_seamlessly() {
        for p in [Pattern::Fur, Pattern::Grass] {
            let f = strand_height(p);
            // Periodic with period 1 in u and v: the same strands one tile over, either way.
            for k in 0..2000 {
                let (u, v) = (hash01(k, 0, 90), hash01(k, 1, 91));
                let here = f(u, v);
                for (du, dv) in [(1.0, 0.0), (0.0, 1.0), (-1.0, -1.0), (1.0, -1.0)] {
                    let there = f(u + du, v + dv);
                    assert!((here - there).abs() < 2e-3, "{p} at ({u}, {v}) + ({du}, {dv}): {here} vs {there}");
                }
            }
            // The field's bilinear samples across the seam are as close to the pattern as those
            // inside (a field that did not tile would jump there), at even and odd sizes.
            for (w, h) in [(512, 512), (300, 500)] {
                let hf = generate(p, w, h);
                for (axis, (seam, inner)) in ["x", "y"].into_iter().zip(seam_and_inner_errors(&hf, f)) {
                    println!("{p} {w}x{h} along {axis}: mean error across the seam {seam:.4}, inside {inner:.4}");
                    assert!(seam <= 1.5 * inner + 1e-3, "{p} {w}x{h} along {axis}: seam {seam}, inside {inner}");
                }
            }
        }
        // The check itself must reject a field that does not tile: the fur squeezed to 0.9 of
        // a tile, whose last column does not lead into its first.
        let squeezed = |u: f32, v: f32| fur(u * 0.9, v * 0.9).height;
        let hf = HeightField::from_height_fn(512, 512, |x, y| {
            let (u, v) = texel_uv(x, y, 512, 512);
            squeezed(u, v)
        });
        for (seam, inner) in seam_and_inner_errors(&hf, squeezed) {
            println!("fur squeezed to 0.9 tiles: mean error across the seam {seam:.4}, inside {inner:.4}");
            assert!(seam > 1.5 * inner + 1e-3, "the seam check misses a field that does not tile: {seam} vs {inner}");
        }
    }

    /// Statistics of a strand field `hs` (`w` x `h`, heights): the share of texels above
    /// mid-height, the share below a quarter of the height (deep: depth over 3/4), the mean
    /// thickness in texels of what stands above mid-height (at each such texel the shorter of
    /// its horizontal and vertical runs above mid-height, wrapping), the tips (texels above
    /// 0.3 and above their 8 neighbours; ties go to the first in row order) and their heights.
    struct StrandStats {
        above_mid: f32,
        deep: f32,
        thickness: f32,
        tips: Vec<f32>,
    }

    fn strand_stats(hs: &[f32], w: usize, h: usize) -> StrandStats {
        let at = |x: isize, y: isize| hs[y.rem_euclid(h as isize) as usize * w + x.rem_euclid(w as isize) as usize];
        let high = |x: isize, y: isize| at(x, y) > 0.5;
        let run = |x: isize, y: isize, dx: isize, dy: isize| {
            let mut n = 1;
            for sign in [-1, 1] {
                let mut k = 1;
                while k < (w + h) as isize && high(x + sign * k * dx, y + sign * k * dy) {
                    n += 1;
                    k += 1;
                }
            }
            n
        };
        let (mut above, mut deep, mut thick, mut tips) = (0usize, 0usize, 0usize, Vec::new());
        for y in 0..h as isize {
            for x in 0..w as isize {
                let v = at(x, y);
                deep += usize::from(v < 0.25);
                if high(x, y) {
                    above += 1;
                    thick += run(x, y, 1, 0).min(run(x, y, 0, 1));
                }
                let neighbours = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];
                let peak = neighbours.iter().enumerate().all(|(k, &(dx, dy))| {
                    let n = at(x + dx, y + dy);
                    if k < 4 { v > n } else { v >= n }
                });
                if v > 0.3 && peak {
                    tips.push(v);
                }
            }
        }
        let n = (w * h) as f32;
        StrandStats {
            above_mid: above as f32 / n,
            deep: deep as f32 / n,
            thickness: thick as f32 / above.max(1) as f32,
            tips,
        }
    }

    fn mean_and_spread(xs: &[f32]) -> (f32, f32) {
        let n = xs.len().max(1) as f32;
        let mean = xs.iter().sum::<f32>() / n;
        (mean, (xs.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / n).sqrt())
    }

    #[test]
    fn fur_and_grass_are_thin_dense_strands_of_varied_heights() {
        let (w, h) = (512usize, 512usize);
        let fur_hs = heights(Pattern::Fur, w as u32, h as u32);
        let grass_hs = heights(Pattern::Grass, w as u32, h as u32);
        let fur_stats = strand_stats(&fur_hs, w, h);
        let grass_stats = strand_stats(&grass_hs, w, h);
        for (p, hs, s) in [(Pattern::Fur, &fur_hs, &fur_stats), (Pattern::Grass, &grass_hs, &grass_stats)] {
            assert!(hs.iter().all(|v| (0.0..=1.0).contains(v)), "{p}");
            let (tip_mean, tip_spread) = mean_and_spread(&s.tips);
            println!(
                "{p} {w}x{h}: {:.1}% above mid-height, {:.1}% deep, strands {:.2} texels thick, {} tips, \
                 tip height {tip_mean:.2} +- {tip_spread:.2}",
                100.0 * s.above_mid,
                100.0 * s.deep,
                s.thickness,
                s.tips.len()
            );
            // Thin: most of the area deep, little of it above mid-height, and what stands there
            // 1 to 4 texels thick at 512x512.
            assert!(s.deep > 0.6, "{p}: only {} of the area is deep", s.deep);
            assert!((0.01..=0.15).contains(&s.above_mid), "{p}: {} above mid-height", s.above_mid);
            assert!((1.0..=4.0).contains(&s.thickness), "{p}: strands {} texels thick", s.thickness);
            // Varied heights: tips spread over the range, not one height.
            assert!(tip_spread > 0.08, "{p}: tip heights {tip_mean} +- {tip_spread}");
            assert!(s.tips.iter().any(|&t| t > 0.95) && s.tips.iter().any(|&t| t < 0.65), "{p}");
        }
        // Dense fur: thousands of hairs per tile (4096 placed; some hide under taller ones),
        // grass sparser, with a soil floor where fur has bare skin at depth 1.
        let n_fur = (FUR_CELLS * FUR_CELLS * FUR_HAIRS_PER_CELL) as usize;
        assert!(fur_stats.tips.len() > n_fur * 3 / 4 && fur_stats.tips.len() <= n_fur, "{}", fur_stats.tips.len());
        assert!(grass_stats.tips.len() * 3 < fur_stats.tips.len(), "{}", grass_stats.tips.len());
        let skin = fur_hs.iter().filter(|&&v| v == 0.0).count() as f32 / fur_hs.len() as f32;
        assert!((0.1..=0.5).contains(&skin), "fur: bare skin on {skin} of the area");
        let soil = grass_hs.iter().filter(|&&v| v <= GRASS_SOIL).count() as f32 / grass_hs.len() as f32;
        assert!(soil > 0.6, "grass: soil on {soil} of the area");
        assert!(grass_hs.iter().all(|&v| v >= 0.0) && grass_hs.iter().any(|&v| v > 0.02 && v < GRASS_SOIL));
        // The strands stay thin at other sizes: the thickness scales with the texels per tile.
        let small = strand_stats(&heights(Pattern::Fur, 256, 256), 256, 256);
        assert!(small.thickness < fur_stats.thickness, "{} vs {}", small.thickness, fur_stats.thickness);
    }

    #[test]
    fn fur_is_brown_with_light_tips_and_grass_green_with_yellow_tips_over_soil() {
        let (w, h) = (256u32, 256u32);
        let mean = |cs: &mut dyn Iterator<Item = [u8; 3]>| {
            let (mut s, mut n) = ([0.0f32; 3], 0.0f32);
            for c in cs {
                (0..3).for_each(|k| s[k] += f32::from(c[k]));
                n += 1.0;
            }
            assert!(n > 0.0);
            s.map(|x| x / n)
        };
        for p in [Pattern::Fur, Pattern::Grass] {
            let f = if p == Pattern::Fur { fur } else { grass };
            let a = albedo(p, w, h);
            let samples: Vec<(StrandSample, [u8; 3])> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let (u, v) = texel_uv(x, y, w, h);
                    (f(u, v), a[(y * w + x) as usize])
                })
                .collect();
            let tips = mean(&mut samples.iter().filter(|(s, _)| s.along > 0.9).map(|(_, c)| *c));
            let middle = mean(&mut samples.iter().filter(|(s, _)| (0.4..0.6).contains(&s.along)).map(|(_, c)| *c));
            let roots = mean(&mut samples.iter().filter(|(s, _)| s.id != 0 && s.along < 0.2).map(|(_, c)| *c));
            let floor = mean(&mut samples.iter().filter(|(s, _)| s.id == 0).map(|(_, c)| *c));
            let luma = |c: [f32; 3]| c[0] + c[1] + c[2];
            println!("{p}: tips {tips:?}, middle {middle:?}, roots {roots:?}, floor {floor:?}");
            assert!(
                luma(tips) > luma(middle) + 20.0 && luma(middle) > luma(roots) + 20.0,
                "{p}: dark roots, light tips"
            );
            // Skin and soil are brown.
            assert!(floor[0] > floor[1] + 10.0 && floor[1] > floor[2] + 10.0, "{p}: floor {floor:?}");
            if p == Pattern::Fur {
                assert!(middle[0] > middle[1] + 30.0 && middle[1] > middle[2] + 20.0, "fur: brown {middle:?}");
            } else {
                assert!(middle[1] > middle[0] + 30.0 && middle[1] > middle[2] + 60.0, "grass: green {middle:?}");
                // Yellowing: the tips' red catches up with their green.
                assert!(tips[0] / tips[1] > middle[0] / middle[1] + 0.15, "grass: yellow tips {tips:?}");
            }
        }
    }

    #[test]
    fn progress_counts_every_row_once_and_changes_no_value() {
        use std::sync::atomic::{AtomicU32, Ordering};
        for p in Pattern::ALL {
            let rows = AtomicU32::new(0);
            let tick = |n: u32| {
                rows.fetch_add(n, Ordering::Relaxed);
            };
            let field = generate_with_progress(p, 37, 23, &tick);
            assert_eq!(rows.load(Ordering::Relaxed), 23, "{p:?}");
            assert_eq!(field.depths(), generate(p, 37, 23).depths(), "{p:?}");
            rows.store(0, Ordering::Relaxed);
            assert_eq!(albedo_with_progress(p, 37, 23, &tick), albedo(p, 37, 23), "{p:?}");
            assert_eq!(rows.load(Ordering::Relaxed), 23, "{p:?}");
        }
    }

    #[test]
    fn albedo_has_one_texel_per_height_and_contrast() {
        for p in Pattern::ALL {
            for (w, h) in [(37, 23), (1, 1), (0, 3), (64, 64)] {
                assert_eq!(albedo(p, w, h).len(), (w.max(1) * h.max(1)) as usize, "{p}");
            }
            let a = albedo(p, 64, 64);
            assert_eq!(a, albedo(p, 64, 64));
            let luma: Vec<u32> = a.iter().map(|c| u32::from(c[0]) + u32::from(c[1]) + u32::from(c[2])).collect();
            let (lo, hi) = (luma.iter().min().unwrap(), luma.iter().max().unwrap());
            assert!(hi - lo > 30, "{p}: flat albedo");
        }
        // Bricks are red, the mortar grey.
        let a = albedo(Pattern::Bricks, 256, 256);
        let face = a[(32 * 256) + 64];
        assert!(face[0] > face[1] + 40 && face[0] > face[2] + 40, "{face:?}");
        let joint = a[(64 * 256) + 64];
        assert!(joint[0].abs_diff(joint[2]) < 30, "{joint:?}");
    }
}
