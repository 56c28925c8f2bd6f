//! The patterns themselves: each a height and a colour as functions of UV on one periodic tile.

use super::*;

// ---------------------------------------------------------------------------------------------
// Bricks.
// ---------------------------------------------------------------------------------------------

/// Brick courses (rows) per tile.
pub(super) const BRICK_COURSES: u32 = 4;
/// Bricks per course per tile.
pub(super) const BRICKS_PER_COURSE: u32 = 2;
/// Half the width of a mortar joint, in tile units.
pub(super) const MORTAR_HALF_WIDTH: f32 = 0.012;
/// Width of the rounded brick edge, in tile units.
pub(super) const BRICK_BEVEL: f32 = 0.018;
/// Height of the mortar.
pub(super) const MORTAR_HEIGHT: f32 = 0.3;

/// What a point of the brick wall is.
pub(super) struct BrickSample {
    pub(super) height: f32,
    /// Distance inside the brick face from the joint, in tile units; <= 0 in the mortar.
    inset: f32,
    /// Hash of the brick (course and index within the course, both wrapped).
    pub(super) id: u32,
}

/// Bricks: in course `r = floor(4 v)` the brick coordinate is `s = 2 u + (r odd ? 1/2 : 0)`.
/// The inset is the distance (tile units) to the brick's nearest side minus half a joint; the
/// face height is `top(brick) - 0.015 grain`, dropping to the mortar over a quarter-round edge
/// of width 0.018.
pub(super) fn bricks(u: f32, v: f32) -> BrickSample {
    let t = v * BRICK_COURSES as f32;
    let course = t.floor();
    let fy = t - course;
    let shift = if wrap_index(course, 2) == 1 { 0.5 } else { 0.0 };
    let s = u * BRICKS_PER_COURSE as f32 + shift;
    let column = s.floor();
    let fx = s - column;
    let id = hash3(wrap_index(course, BRICK_COURSES), wrap_index(column, BRICKS_PER_COURSE), 1);
    let dx = fx.min(1.0 - fx) / BRICKS_PER_COURSE as f32;
    let dy = fy.min(1.0 - fy) / BRICK_COURSES as f32;
    let inset = dx.min(dy) - MORTAR_HALF_WIDTH;
    let mortar = MORTAR_HEIGHT + 0.02 * (value_noise(u, v, 48, 2) - 0.5);
    let height = if inset <= 0.0 {
        mortar
    } else {
        let top = 1.0 - 0.06 * hash01(id, 0, 3) - 0.015 * fbm(u, v, 12, 4);
        mortar + (top - mortar) * quarter_round(inset / BRICK_BEVEL)
    };
    BrickSample { height, inset, id }
}

pub(super) fn bricks_albedo(u: f32, v: f32) -> [f32; 3] {
    let b = bricks(u, v);
    let grain = value_noise(u, v, 64, 7);
    if b.inset <= 0.0 {
        return scale([0.66, 0.64, 0.6], 0.9 + 0.2 * grain);
    }
    let tint = hash01(b.id, 1, 5);
    let base = if tint < 0.5 {
        mix([0.53, 0.21, 0.15], [0.6, 0.26, 0.18], tint * 2.0)
    } else {
        mix([0.6, 0.26, 0.18], [0.66, 0.33, 0.21], tint * 2.0 - 1.0)
    };
    let blotch = fbm(u, v, 16, 8);
    scale(base, 0.88 + 0.12 * hash01(b.id, 2, 6) + 0.1 * blotch + 0.08 * grain)
}

// ---------------------------------------------------------------------------------------------
// Pyramids.
// ---------------------------------------------------------------------------------------------

/// Pyramids per tile along each axis.
pub(super) const PYRAMIDS_PER_TILE: f32 = 4.0;

/// `h = 1 - 2 max(|fu - 1/2|, |fv - 1/2|)`, `(fu, fv)` = fractional part of `4 (u, v)`.
pub(super) fn pyramid_height(u: f32, v: f32) -> f32 {
    let fu = (u * PYRAMIDS_PER_TILE).rem_euclid(1.0);
    let fv = (v * PYRAMIDS_PER_TILE).rem_euclid(1.0);
    1.0 - 2.0 * (fu - 0.5).abs().max((fv - 0.5).abs())
}

pub(super) fn pyramid_albedo(u: f32, v: f32) -> [f32; 3] {
    let h = pyramid_height(u, v);
    // Six courses of stone up each pyramid, each a slightly different tone, with a darker
    // joint between them; each pyramid gets its own hue of sandstone.
    let courses = 6.0 * h;
    let course = courses.floor().min(5.0);
    let f = courses - course;
    let joint = 1.0 - smoothstep(f.min(1.0 - f) / 0.15);
    let cell = hash3(
        wrap_index(u * PYRAMIDS_PER_TILE, PYRAMIDS_PER_TILE as u32),
        wrap_index(v * PYRAMIDS_PER_TILE, PYRAMIDS_PER_TILE as u32),
        11,
    );
    let tone = 0.93 + 0.08 * hash01(cell, course as u32, 12);
    let sand = fbm(u, v, 24, 13);
    let base = mix([0.78, 0.64, 0.44], [0.88, 0.76, 0.55], 0.6 * sand + 0.4 * hash01(cell, 99, 14));
    scale(base, tone - 0.12 * joint + 0.05 * value_noise(u, v, 96, 15))
}

// ---------------------------------------------------------------------------------------------
// Cobblestones.
// ---------------------------------------------------------------------------------------------

/// Voronoi cells per tile along each axis.
pub(super) const COBBLE_CELLS: u32 = 6;
/// Half the gap between stones, in cell units.
pub(super) const COBBLE_GAP: f32 = 0.045;
/// Width of the dome's rounded flank, in cell units.
pub(super) const COBBLE_ROUND: f32 = 0.32;
/// Sharpness of the soft minimum that rounds the ridges of a cell's distance field.
pub(super) const COBBLE_SOFTNESS: f32 = 14.0;

/// What a point of the cobbled surface is.
pub(super) struct CobbleSample {
    pub(super) height: f32,
    /// The dome profile in `[0, 1]`: 0 in the gaps, 1 on a stone's top.
    dome: f32,
    /// Hash of the stone's (wrapped) cell.
    pub(super) id: u32,
}

/// The feature point of lattice cell `(i, j)` (any integers; hashed modulo the tile), in cell
/// units: jittered within the middle 60 % of the cell.
pub(super) fn cobble_point(i: f32, j: f32) -> (f32, f32, u32) {
    let id = hash3(wrap_index(i, COBBLE_CELLS), wrap_index(j, COBBLE_CELLS), 21);
    let jx = hash01(id, 0, 22);
    let jy = hash01(id, 1, 23);
    (i + 0.2 + 0.6 * jx, j + 0.2 + 0.6 * jy, id)
}

/// Cobbles: `p = 6 (u, v)`; the nearest feature point `a` picks the stone. The border distance
/// `e` is a soft minimum (log-sum-exp, sharpness 14) over the other points `b` of the distance
/// from `p` to the bisector of `a` and `b`; the dome is `quarter_round((e - 0.045) / 0.32)` and
/// `h = gap + (top - gap) dome`, `top` in `[0.82, 1]` per stone less a grain of 0.03.
pub(super) fn cobbles(u: f32, v: f32) -> CobbleSample {
    let (px, py) = (u * COBBLE_CELLS as f32, v * COBBLE_CELLS as f32);
    let (cx, cy) = (px.floor(), py.floor());
    let mut points = [(0.0f32, 0.0f32, 0u32); 25];
    let mut nearest = 0;
    let mut nearest_d2 = f32::INFINITY;
    for (k, point) in points.iter_mut().enumerate() {
        let (di, dj) = ((k % 5) as f32 - 2.0, (k / 5) as f32 - 2.0);
        *point = cobble_point(cx + di, cy + dj);
        let d2 = (point.0 - px).powi(2) + (point.1 - py).powi(2);
        if d2 < nearest_d2 {
            nearest_d2 = d2;
            nearest = k;
        }
    }
    let (ax, ay, id) = points[nearest];
    let mut sum = 0.0f32;
    for (k, &(bx, by, _)) in points.iter().enumerate() {
        if k == nearest {
            continue;
        }
        let (nx, ny) = (bx - ax, by - ay);
        let len = (nx * nx + ny * ny).sqrt();
        if len < 1e-6 {
            continue;
        }
        let (mx, my) = (0.5 * (ax + bx), 0.5 * (ay + by));
        let d = ((mx - px) * nx + (my - py) * ny) / len;
        sum += (-COBBLE_SOFTNESS * d).exp();
    }
    let border = if sum > 0.0 { -sum.ln() / COBBLE_SOFTNESS } else { 1.0 };
    let dome = quarter_round((border - COBBLE_GAP) / COBBLE_ROUND);
    let gap = 0.08 + 0.08 * fbm(u, v, 24, 24);
    let top = 0.85 + 0.15 * hash01(id, 2, 25) - 0.03 * fbm(u, v, 20, 26);
    CobbleSample { height: gap + (top - gap) * dome, dome, id }
}

pub(super) fn cobbles_albedo(u: f32, v: f32) -> [f32; 3] {
    let c = cobbles(u, v);
    let grain = value_noise(u, v, 80, 31);
    let soil = scale([0.3, 0.26, 0.21], 0.85 + 0.3 * grain);
    let hue = hash01(c.id, 3, 32);
    let stone = mix([0.52, 0.51, 0.49], [0.58, 0.47, 0.36], hue);
    let stone = scale(stone, 0.78 + 0.3 * hash01(c.id, 4, 33) + 0.12 * fbm(u, v, 24, 34));
    mix(soil, stone, smoothstep(c.dome * 4.0))
}

// ---------------------------------------------------------------------------------------------
// Text.
// ---------------------------------------------------------------------------------------------

/// The lines of text, top to bottom.
pub(super) const TEXT_LINES: [&str; 2] = ["POM", "KIT"];
/// Empty font pixels around the text block.
pub(super) const TEXT_MARGIN: u32 = 2;
/// Height of the plate the letters stand on.
pub(super) const PLATE_HEIGHT: f32 = 0.35;
/// Width of a letter's bevel, in font pixels, centred on the letter's outline.
pub(super) const TEXT_BEVEL: f32 = 0.5;
/// Half the width of a letter stroke, in font pixels.
pub(super) const STROKE_HALF_WIDTH: f32 = 0.5;

/// Glyphs of the built-in 5x7 font: seven rows, top first; bit 4 is the leftmost column.
/// Unknown characters are blank.
pub(super) const fn glyph(c: char) -> [u8; 7] {
    match c {
        'A' => [0b01110, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001],
        'E' => [0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b11111],
        'I' => [0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110],
        'K' => [0b10001, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b10001],
        'L' => [0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111],
        'M' => [0b10001, 0b11011, 0b10101, 0b10101, 0b10001, 0b10001, 0b10001],
        'O' => [0b01110, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110],
        'P' => [0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000],
        'T' => [0b11111, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100],
        'X' => [0b10001, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b10001],
        _ => [0; 7],
    }
}

/// Columns of the text layout in font pixels: margins plus the longest line (5 per glyph and 1
/// between glyphs).
pub(super) fn text_columns() -> u32 {
    let longest = TEXT_LINES.iter().map(|l| l.chars().count() as u32).max().unwrap_or(0);
    2 * TEXT_MARGIN + (6 * longest).saturating_sub(1)
}

/// Rows of the text layout in font pixels: margins plus 7 per line and 2 between lines.
pub(super) fn text_rows() -> u32 {
    2 * TEXT_MARGIN + (9 * TEXT_LINES.len() as u32).saturating_sub(2)
}

/// Whether font pixel `(col, row)` of the layout (row 0 at the top) is part of a letter.
pub(super) fn text_lit(col: i64, row: i64) -> bool {
    let (col, row) = (col - i64::from(TEXT_MARGIN), row - i64::from(TEXT_MARGIN));
    if col < 0 || row < 0 {
        return false;
    }
    let (line, glyph_row) = ((row / 9) as usize, (row % 9) as usize);
    let (index, glyph_col) = ((col / 6) as usize, (col % 6) as u32);
    if glyph_row >= 7 || glyph_col >= 5 {
        return false;
    }
    let Some(c) = TEXT_LINES.get(line).and_then(|l| l.chars().nth(index)) else {
        return false;
    };
    glyph(c)[glyph_row] & (0b10000 >> glyph_col) != 0
}

/// Distance from `(px, py)` to the segment `[ax, ay, bx, by]`.
pub(super) fn segment_distance(px: f32, py: f32, s: [f32; 4]) -> f32 {
    let (dx, dy) = (s[2] - s[0], s[3] - s[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((px - s[0]) * dx + (py - s[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (ex, ey) = (px - s[0] - t * dx, py - s[1] - t * dy);
    (ex * ex + ey * ey).sqrt()
}

/// The text block turned into strokes, built once: the bitmap's lit pixels become round-capped
/// strokes between the centres of neighbouring lit pixels, so that letters have rounded
/// corners and diagonals (K, M) are solid strokes rather than pixels touching at corners.
pub(super) struct TextLayout {
    cols: u32,
    rows: u32,
    /// Stroke centre lines `[ax, ay, bx, by]` in font pixels (a point for a lone pixel).
    strokes: Vec<[f32; 4]>,
    /// For each font pixel, row-major, the strokes close enough to shape it.
    near: Vec<Vec<u16>>,
}

/// Built on first use.
static TEXT_LAYOUT: LazyLock<TextLayout> = LazyLock::new(TextLayout::new);

impl TextLayout {
    fn new() -> Self {
        let (cols, rows) = (text_columns(), text_rows());
        let mut strokes = Vec::new();
        for r in 0..i64::from(rows) {
            for c in 0..i64::from(cols) {
                if !text_lit(c, r) {
                    continue;
                }
                let (ax, ay) = (c as f32 + 0.5, r as f32 + 0.5);
                strokes.push([ax, ay, ax, ay]);
                for (dc, dr) in [(1, 0), (0, 1), (1, 1), (-1, 1)] {
                    if !text_lit(c + dc, r + dr) {
                        continue;
                    }
                    // A diagonal joins two pixels only where nothing else does: if an
                    // orthogonal neighbour already links them, it would fill the inner corner.
                    if dc != 0 && dr != 0 && (text_lit(c + dc, r) || text_lit(c, r + dr)) {
                        continue;
                    }
                    strokes.push([ax, ay, ax + dc as f32, ay + dr as f32]);
                }
            }
        }
        // A stroke shapes the points within its half-width plus half the bevel.
        let reach = STROKE_HALF_WIDTH + 0.5 * TEXT_BEVEL + 0.01;
        let mut near = vec![Vec::new(); cols as usize * rows as usize];
        for (k, s) in strokes.iter().enumerate() {
            let (x0, x1) = (s[0].min(s[2]) - reach, s[0].max(s[2]) + reach);
            let (y0, y1) = (s[1].min(s[3]) - reach, s[1].max(s[3]) + reach);
            for r in (y0.floor().max(0.0) as u32)..(y1.ceil().min(rows as f32) as u32) {
                for c in (x0.floor().max(0.0) as u32)..(x1.ceil().min(cols as f32) as u32) {
                    near[(r * cols + c) as usize].push(k as u16);
                }
            }
        }
        Self { cols, rows, strokes, near }
    }

    /// Signed distance (font pixels) from layout point `(px, py)` to the letters' outline,
    /// negative inside; capped at the reach of a stroke outside.
    fn signed_distance(&self, px: f32, py: f32) -> f32 {
        let c = wrap_index(px.floor(), self.cols);
        let r = wrap_index(py.floor(), self.rows);
        let (px, py) = (px.rem_euclid(self.cols as f32), py.rem_euclid(self.rows as f32));
        self.near[(r * self.cols + c) as usize]
            .iter()
            .map(|&k| segment_distance(px, py, self.strokes[usize::from(k)]) - STROKE_HALF_WIDTH)
            .fold(1.0, f32::min)
    }
}

/// What a point of the text plate is.
pub(super) struct TextSample {
    pub(super) height: f32,
    /// How far the point is raised towards a letter top, in `[0, 1]`.
    raise: f32,
}

/// Text: `p = (u, v) * (columns, rows)` in font pixels (21 x 20). Each lit pixel of the 5x7
/// glyphs is joined to its lit neighbours by a stroke of half-width 1/2; `sd` is the signed
/// distance from `p` to the union of strokes (negative inside); the letter rises as
/// `raise = smoothstep(1/2 - sd / 0.5)` and `h = 0.35 + 0.65 raise`.
pub(super) fn text(u: f32, v: f32) -> TextSample {
    let layout = &*TEXT_LAYOUT;
    let sd = layout.signed_distance(u * layout.cols as f32, v * layout.rows as f32);
    let raise = smoothstep(0.5 - sd / TEXT_BEVEL);
    TextSample { height: PLATE_HEIGHT + (1.0 - PLATE_HEIGHT) * raise, raise }
}

pub(super) fn text_albedo(u: f32, v: f32) -> [f32; 3] {
    let t = text(u, v);
    let grain = fbm(u, v, 32, 41);
    let plate = scale([0.2, 0.24, 0.3], 0.9 + 0.2 * grain);
    let brass = scale([0.87, 0.7, 0.33], 0.92 + 0.12 * grain);
    mix(plate, brass, t.raise)
}

// ---------------------------------------------------------------------------------------------
// Spike.
// ---------------------------------------------------------------------------------------------

/// 1 at texel `(w / 2, h / 2)`, 0 elsewhere.
pub(super) fn spike_height(x: u32, y: u32, w: u32, h: u32) -> f32 {
    f32::from(x == w / 2 && y == h / 2)
}

// ---------------------------------------------------------------------------------------------
// Waves.
// ---------------------------------------------------------------------------------------------

/// Periods of [`Pattern::Waves`] per tile along each axis (`k` in [`waves_height`]).
pub const WAVES_PERIODS: u32 = 2;

/// The analytic height of [`Pattern::Waves`] at `(u, v)`:
/// `h(u, v) = 1/2 + 1/2 sin(2 pi k u) cos(2 pi k v)` with `k` = [`WAVES_PERIODS`].
///
/// [`generate`] samples it at texel centres `((x + 0.5) / w, (y + 0.5) / h)`. Periodic with
/// period 1 in `u` and `v`; the range is `[0, 1]`.
#[must_use]
pub fn waves_height(u: f32, v: f32) -> f32 {
    let k = WAVES_PERIODS as f32;
    0.5 + 0.5 * (TAU * k * u).sin() * (TAU * k * v).cos()
}

/// The analytic gradient `(dh/du, dh/dv)` of [`waves_height`], per UV unit:
/// `(pi k cos(2 pi k u) cos(2 pi k v), -pi k sin(2 pi k u) sin(2 pi k v))`.
///
/// Divide by the size in texels to get the change per texel.
#[must_use]
pub fn waves_gradient(u: f32, v: f32) -> (f32, f32) {
    let k = WAVES_PERIODS as f32;
    let (su, cu) = (TAU * k * u).sin_cos();
    let (sv, cv) = (TAU * k * v).sin_cos();
    (PI * k * cu * cv, -PI * k * su * sv)
}

// ---------------------------------------------------------------------------------------------
// Fur and grass.
// ---------------------------------------------------------------------------------------------

/// [`Pattern::Fur`]: hair cells per tile along each axis.
pub const FUR_CELLS: u32 = 32;
/// [`Pattern::Fur`]: hairs per cell, each anywhere in its cell.
pub const FUR_HAIRS_PER_CELL: u32 = 4;
/// A hair's base radius, in cell units: from this ...
pub(super) const FUR_RADIUS_MIN: f32 = 0.24;
/// ... to this (less than 1, so a hair reaches no further than the neighbouring cells).
pub(super) const FUR_RADIUS_MAX: f32 = 0.4;
/// The lowest hair tip; the highest is 1.
pub(super) const FUR_TIP_MIN: f32 = 0.55;
/// Rounding of a hair's tip, in base radii.
pub(super) const FUR_TIP_ROUND: f32 = 0.08;

/// [`Pattern::Grass`]: blade cells per tile along each axis.
pub const GRASS_CELLS: u32 = 16;
/// [`Pattern::Grass`]: blades per cell, each centred anywhere in its cell.
pub const GRASS_BLADES_PER_CELL: u32 = 3;
/// A blade's half-length, in cell units: from this ...
pub(super) const GRASS_HALF_LENGTH_MIN: f32 = 0.22;
/// ... to this.
pub(super) const GRASS_HALF_LENGTH_MAX: f32 = 0.4;
/// A blade's half-width, in cell units: from this ...
pub(super) const GRASS_HALF_WIDTH_MIN: f32 = 0.035;
/// ... to this. Length plus width stays under 1 cell (the blade reaches no further than the
/// neighbouring cells), with the bend added.
pub(super) const GRASS_HALF_WIDTH_MAX: f32 = 0.06;
/// The most a blade bends sideways at its ends, in cell units.
pub(super) const GRASS_BEND: f32 = 0.12;
/// The lowest blade tip; the highest is 1.
pub(super) const GRASS_TIP_MIN: f32 = 0.45;
/// The soil's highest point; its lowest is 0.
pub(super) const GRASS_SOIL: f32 = 0.08;

/// What a point of fur or grass is.
pub(super) struct StrandSample {
    pub(super) height: f32,
    /// How far up its strand the point is, `height / tip`, in `[0, 1]`; 0 on the skin or soil.
    pub(super) along: f32,
    /// Hash of the strand; 0 on the skin or soil.
    pub(super) id: u32,
}

/// A hair's profile at `t` base radii from its axis: 1 on the axis, 0 from `t = 1` on; a cone
/// with concave flanks, `(1 - s)^2`, of the rounded distance `s = (sqrt(t^2 + c^2) - c) /
/// (sqrt(1 + c^2) - c)` (`c` = the tip's rounding), so the tip is smooth and the flanks steepen
/// toward it.
pub(super) fn hair_profile(t: f32) -> f32 {
    if t >= 1.0 {
        return 0.0;
    }
    let c = FUR_TIP_ROUND;
    let s = ((t * t + c * c).sqrt() - c) / ((1.0 + c * c).sqrt() - c);
    let k = (1.0 - s).max(0.0);
    k * k
}

/// Fur: `p = 32 (u, v)`; in each of the 3 x 3 cells around `p`, 4 hairs at hashed positions
/// with hashed base radii `r` in `[0.24, 0.4]` cells and tips in `[0.55, 1]`; a hair stands
/// `tip * hair_profile(|p - centre| / r)` high, the highest hair wins, and the skin is 0.
pub(super) fn fur(u: f32, v: f32) -> StrandSample {
    let floor = StrandSample { height: 0.0, along: 0.0, id: 0 };
    highest_strand(u, v, FUR_CELLS, FUR_HAIRS_PER_CELL, 51, floor, |id, (i, j), (px, py)| {
        let (hx, hy) = (i + hash01(id, 0, 53), j + hash01(id, 1, 54));
        let r = FUR_RADIUS_MIN + (FUR_RADIUS_MAX - FUR_RADIUS_MIN) * hash01(id, 2, 55);
        let t = ((px - hx).powi(2) + (py - hy).powi(2)).sqrt() / r;
        if t >= 1.0 {
            return None;
        }
        Some((FUR_TIP_MIN + (1.0 - FUR_TIP_MIN) * hash01(id, 3, 56), hair_profile(t)))
    })
}

/// The highest strand over `(u, v)` of a pattern of `n` x `n` cells per tile with `per_cell`
/// strands in each: for each of the 3 x 3 cells `(i, j)` around `p = n (u, v)` (hashed with
/// `seed`, wrapped so the pattern tiles) and each of its strands (id hashed with `seed + 1`),
/// `strand(id, (i, j), p)` gives the strand's tip height and how far up it `p` lies, or `None`
/// off the strand. The highest `tip * along` wins over `floor`.
pub(super) fn highest_strand(
    u: f32,
    v: f32,
    n: u32,
    per_cell: u32,
    seed: u32,
    floor: StrandSample,
    strand: impl Fn(u32, (f32, f32), (f32, f32)) -> Option<(f32, f32)>,
) -> StrandSample {
    let (px, py) = (u * n as f32, v * n as f32);
    let (cx, cy) = (px.floor(), py.floor());
    let mut best = floor;
    for dj in -1..=1 {
        for di in -1..=1 {
            let (i, j) = (cx + di as f32, cy + dj as f32);
            let cell = hash3(wrap_index(i, n), wrap_index(j, n), seed);
            for k in 0..per_cell {
                let id = hash3(cell, k, seed + 1) | 1;
                if let Some((tip, along)) = strand(id, (i, j), (px, py))
                    && tip * along > best.height
                {
                    best = StrandSample { height: tip * along, along, id };
                }
            }
        }
    }
    best
}

pub(super) fn fur_albedo(u: f32, v: f32) -> [f32; 3] {
    let f = fur(u, v);
    let skin = scale([0.2, 0.12, 0.07], 0.85 + 0.3 * value_noise(u, v, 64, 61));
    if f.id == 0 {
        return skin;
    }
    // Each hair its own shade between dark brown and ginger, a little lighter or darker;
    // dark at the root, pale toward the tip.
    let hue = hash01(f.id, 4, 62);
    let coat = mix([0.46, 0.27, 0.13], [0.84, 0.56, 0.29], 0.6 * hue + 0.4 * fbm(u, v, 8, 63));
    let coat = scale(coat, 0.82 + 0.3 * hash01(f.id, 5, 64));
    let root = scale(coat, 0.45);
    let tip = mix(coat, [0.97, 0.89, 0.72], 0.6);
    let hair = if f.along < 0.6 { mix(root, coat, f.along / 0.6) } else { mix(coat, tip, (f.along - 0.6) / 0.4) };
    mix(skin, hair, smoothstep(f.along * 6.0))
}

/// Grass: `p = 16 (u, v)`; in each of the 3 x 3 cells around `p`, 3 blades, each centred at a
/// hashed point and turned to a hashed direction, with a hashed half-length `L` in
/// `[0.22, 0.4]` cells, half-width `w` in `[0.035, 0.06]`, bend `b` of at most 0.12 and tip in
/// `[0.45, 1]`. In the blade's frame (`s` along it, `n` across, less the bend `b (s / L)^2`), it
/// stands `tip * (1 - |s| / L) * sqrt(1 - (n / w)^2)` high: a pointed top edge over steep
/// rounded sides. The highest blade wins; the soil is `0.08` of two octaves of value noise.
pub(super) fn grass(u: f32, v: f32) -> StrandSample {
    let soil = GRASS_SOIL * fbm(u, v, 24, 71);
    let floor = StrandSample { height: soil, along: 0.0, id: 0 };
    highest_strand(u, v, GRASS_CELLS, GRASS_BLADES_PER_CELL, 72, floor, |id, (i, j), (px, py)| {
        let (bx, by) = (i + hash01(id, 0, 74), j + hash01(id, 1, 75));
        let (sin, cos) = (PI * hash01(id, 2, 76)).sin_cos();
        let (dx, dy) = (px - bx, py - by);
        let (s, across) = (dx * cos + dy * sin, -dx * sin + dy * cos);
        let len = GRASS_HALF_LENGTH_MIN + (GRASS_HALF_LENGTH_MAX - GRASS_HALF_LENGTH_MIN) * hash01(id, 3, 77);
        let half_width = GRASS_HALF_WIDTH_MIN + (GRASS_HALF_WIDTH_MAX - GRASS_HALF_WIDTH_MIN) * hash01(id, 4, 78);
        let bend = GRASS_BEND * (2.0 * hash01(id, 5, 79) - 1.0);
        let a = s.abs() / len;
        if a >= 1.0 {
            return None;
        }
        let c = (across - bend * a * a) / half_width;
        if c.abs() >= 1.0 {
            return None;
        }
        Some((GRASS_TIP_MIN + (1.0 - GRASS_TIP_MIN) * hash01(id, 6, 80), (1.0 - a) * (1.0 - c * c).sqrt()))
    })
}

pub(super) fn grass_albedo(u: f32, v: f32) -> [f32; 3] {
    let g = grass(u, v);
    let soil = scale([0.33, 0.23, 0.14], 0.75 + 0.4 * fbm(u, v, 40, 81));
    if g.id == 0 {
        return soil;
    }
    // Each blade its own green; darker at the base, yellowing toward the tip.
    let hue = hash01(g.id, 7, 82);
    let green = mix([0.2, 0.42, 0.1], [0.36, 0.58, 0.14], 0.7 * hue + 0.3 * fbm(u, v, 6, 83));
    let green = scale(green, 0.85 + 0.25 * hash01(g.id, 8, 84));
    let base = scale(green, 0.55);
    let tip = mix(green, [0.8, 0.74, 0.36], 0.6);
    let blade =
        if g.along < 0.65 { mix(base, green, g.along / 0.65) } else { mix(green, tip, (g.along - 0.65) / 0.35) };
    mix(soil, blade, smoothstep(g.along * 5.0))
}
