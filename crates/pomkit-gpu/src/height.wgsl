// Dynamic height fields: everything pomkit derives from a depth map, rebuilt on the GPU.
//
// Tatarchuk 2006 ("Dynamic parallax occlusion mapping with approximate soft shadows") notes that
// a height field which changes every frame (water, footprints, a painted map) needs its normals
// and mips regenerated on the GPU. These compute entry points are the WGSL twins of pomkit-core,
// stage for stage, and the tests in `tests/height_passes.rs` hold them to it:
//
//   normals_main       bake.rs  `bake_normals` (Central or Sobel) + trace.rs `Surface::new`'s
//                      parallax map clamp(n_z * d, 0, 1), written to a scratch texture
//   resolve_main       copies the scratch texture into `heights` mip 0 (see the stage header)
//   downsample_main    heightfield.rs `HeightField::downsample` (exact box weights, any size)
//   pyramid_base_main  pyramid.rs `MaxHeightPyramid::new`, level 0 (nine-point minimum)
//   pyramid_reduce_main                                         coarser levels (minimum of 4)
//
// Conventions (ARCHITECTURE.md): depth d in [0, 1], 0 = the polygon's surface; texel (x, y) is
// column x, row y, row 0 at the top of the image (v = 0); tangent-space y runs *up* the image.
// Every read is a `textureLoad` of one texel: no sampler, no filtering, so the results do not
// depend on the hardware's filtering precision.

/// Per-dispatch parameters (one 32-byte record per dispatch; see `height.rs`, `Params`).
struct Params {
    /// Logical size of the level read (for the pyramid: its ceil-halved size, not the padded
    /// texture size).
    src_size: vec2<u32>,
    /// Logical size of the level written.
    dst_size: vec2<u32>,
    /// Neighbours outside the field: EDGES_WRAP or EDGES_CLAMP.
    edges: u32,
    /// Slope filter of the normal map: FILTER_CENTRAL or FILTER_SOBEL.
    normal_filter: u32,
    /// Lengyel's s: the full depth range spans this many texel widths (depth_scale * width).
    scale: f32,
    /// Levels of the pyramid (cone_main only).
    levels: u32,
}

const EDGES_WRAP: u32 = 0u;
const EDGES_CLAMP: u32 = 1u;
const FILTER_CENTRAL: u32 = 0u;
const FILTER_SOBEL: u32 = 1u;

/// Texel coordinate `i` mapped into `0..n` by wrapping (a Euclidean remainder, so any size works:
/// docs/REFERENCES.md, Errata, Lengyel's `& (size - 1)` erratum) or clamping. HeightField::depth_at.
fn resolve(i: i32, n: i32, edges: u32) -> i32 {
    if edges == EDGES_WRAP {
        // A Euclidean remainder without `%`: integer division by a variable has no SIMD
        // instruction on CPUs, so llvmpipe would do it lane by lane. Floor division in f32 is
        // exact below 2^24, then one period of correction either way, and a clamp keeps a texel
        // beyond that in bounds.
        var q = i - n * i32(floor(f32(i) / f32(n)));
        q = select(q, q + n, q < 0);
        q = select(q, q - n, q >= n);
        return clamp(q, 0, n - 1);
    }
    return clamp(i, 0, n - 1);
}

/// `x` rounded to the nearest f16 value (ties to even), still as f32.
///
/// Workaround: how a shader's f32 becomes f16 when stored to an rgba16float texture is up to the
/// implementation; lavapipe truncates toward zero (measured: about half of all stored normal
/// components came out one f16 step smaller in magnitude than the nearest value), which would
/// bias every mip level a little shallower than the one above it. Rounding here first makes
/// the stored value exactly representable, so every GPU stores the same bits: the nearest.
/// Normal f16 numbers keep 10 of f32's 23 mantissa bits; below 2^-14 (f16 subnormals) the
/// step is a fixed 2^-24.
fn f16_nearest(x: vec4<f32>) -> vec4<f32> {
    let b = bitcast<vec4<u32>>(x);
    let odd = (b >> vec4<u32>(13u)) & vec4<u32>(1u);
    let normal = bitcast<vec4<f32>>((b + vec4<u32>(0xfffu) + odd) & vec4<u32>(0xffffe000u));
    let subnormal = round(x * 16777216.0) / 16777216.0;
    return select(normal, subnormal, abs(x) < vec4<f32>(6.103515625e-5));
}

// ---------------------------------------------------------------------------------------------
// Stage 1: normals and parallax values from mip 0.
//
// Source: Lengyel, Foundations of Game Engine Development vol. 2, eq. 7.41 to 7.43 (central
// differences, n = nrm(-s dh/dx, -s dh/dy, 1)); Tatarchuk 2006 section 4 (the 3x3 Sobel operator
// for dynamic height fields). Working on depths, h = 1 - d, the normal is nrm(s dd/dx, s dd/dy, 1)
// with y measured *up* the image (row - 1), pomkit's "+Y up" (glTF, OpenGL). Lengyel's listing
// differences down the rows; up is the opposite sign (bake.rs explains).
//
// Sobel is normalized as in bake.rs: weights 1-2-1 across, a difference over two texels along,
// so a plane of slope g gives 4 * 2g, hence the 1/8, and a plane bakes the same normal under
// both filters.
//
// The parallax value is Lengyel's parallax map (eq. 7.51) in pomkit's form, clamp(n_z * d, 0, 1),
// always from *central* normals at the same scale, exactly as `Surface::new` builds it whatever
// normal filter is chosen for shading.
//
// Fields narrower or shorter than 2 texels have no measurable slope (`bake_normals` refuses them
// with TooSmall): as `Surface::new` and the CPU renderer do, the normal is +Z and the parallax
// value is the depth itself.
//
// Workaround: the parallax value belongs in `heights` mip 0's G channel, but this dispatch reads
// mip 0, and a texture subresource cannot be both read and written (write-only storage) in one
// dispatch; read-write storage of rgba16float is not core WebGPU. So the result (d, p) goes to a
// scratch texture and `resolve_main` copies it back in the next dispatch.
// ---------------------------------------------------------------------------------------------

@group(0) @binding(0) var n_src: texture_2d<f32>;
@group(0) @binding(1) var n_normals: texture_storage_2d<rgba16float, write>;
@group(0) @binding(2) var n_scratch: texture_storage_2d<rgba16float, write>;
@group(0) @binding(3) var<uniform> n_params: Params;

/// Depth of texel (x, y) + (dx, dy) of mip 0, neighbours wrapped or clamped.
fn n_depth(p: vec2<i32>, dx: i32, dy: i32) -> f32 {
    let size = vec2<i32>(n_params.src_size);
    let q = vec2<i32>(resolve(p.x + dx, size.x, n_params.edges), resolve(p.y + dy, size.y, n_params.edges));
    return textureLoad(n_src, q, 0).r;
}

/// nrm(gx, gy, 1) for scaled depth slopes (gx, gy), as bake.rs `normalize_row`.
fn normal_from_scaled_slope(g: vec2<f32>) -> vec3<f32> {
    let inv = 1.0 / sqrt(g.x * g.x + g.y * g.y + 1.0);
    return vec3<f32>(g.x * inv, g.y * inv, inv);
}

@compute @workgroup_size(8, 8)
fn normals_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= n_params.dst_size) {
        return;
    }
    let p = vec2<i32>(id.xy);
    let c = n_depth(p, 0, 0);
    if any(n_params.src_size < vec2<u32>(2u)) {
        textureStore(n_normals, p, vec4<f32>(0.0, 0.0, 1.0, 0.0));
        textureStore(n_scratch, p, vec4<f32>(c, c, 0.0, 0.0));
        return;
    }
    let s = n_params.scale;
    // Central differences (Lengyel eq. 7.41), y up the image: row - 1 minus row + 1.
    let central = vec2<f32>(n_depth(p, 1, 0) - n_depth(p, -1, 0), n_depth(p, 0, -1) - n_depth(p, 0, 1)) * 0.5;
    let n_central = normal_from_scaled_slope(central * s);
    var n = n_central;
    if n_params.normal_filter == FILTER_SOBEL {
        // Tatarchuk 2006 section 4: the 3x3 Sobel operator, normalized by 1/8 (see above).
        let ul = n_depth(p, -1, -1);
        let uc = n_depth(p, 0, -1);
        let ur = n_depth(p, 1, -1);
        let ml = n_depth(p, -1, 0);
        let mr = n_depth(p, 1, 0);
        let dl = n_depth(p, -1, 1);
        let dc = n_depth(p, 0, 1);
        let dr = n_depth(p, 1, 1);
        let gx = ((ur + 2.0 * mr + dr) - (ul + 2.0 * ml + dl)) * (0.125 * s);
        let gy = ((ul + 2.0 * uc + ur) - (dl + 2.0 * dc + dr)) * (0.125 * s);
        n = normal_from_scaled_slope(vec2<f32>(gx, gy));
    }
    textureStore(n_normals, p, f16_nearest(vec4<f32>(n, 0.0)));
    let parallax = clamp(n_central.z * c, 0.0, 1.0);
    textureStore(n_scratch, p, f16_nearest(vec4<f32>(c, parallax, 0.0, 0.0)));
}

// ---------------------------------------------------------------------------------------------
// Stage 1b: copy (d, p) back into heights mip 0.
//
// Workaround for the read/write hazard of stage 1 (see there). Both textures are rgba16float,
// so the copy is exact. It is a dispatch rather than `copy_texture_to_texture` so that the whole
// rebuild stays one compute pass (one pair of timestamps).
// ---------------------------------------------------------------------------------------------

@group(0) @binding(0) var r_src: texture_2d<f32>;
@group(0) @binding(1) var r_dst: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8)
fn resolve_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= textureDimensions(r_dst)) {
        return;
    }
    let t = textureLoad(r_src, vec2<i32>(id.xy), 0);
    textureStore(r_dst, vec2<i32>(id.xy), vec4<f32>(t.r, t.g, 0.0, 0.0));
}

// ---------------------------------------------------------------------------------------------
// Stage 2: the box-filtered mip chain (R = depth, G = parallax value), one level per dispatch.
//
// Source: heightfield.rs `HeightField::downsample` and `box_weights`. Each side halves rounding
// down (never below 1), as GPU mip chains do, so for an odd side n the m = floor(n / 2) coarse
// texels each cover n / m > 2 fine texels: coarse texel o spans [o n / m, (o + 1) n / m), and
// each fine texel s is weighted by the length of its overlap with that span. This preserves the
// mean exactly, where the common 2x2 average would drift toward one edge of odd-sized images.
//
// Measured in units of 1/m fine texels every endpoint is an integer: the span is [o n, (o + 1) n)
// and fine texel s is [s m, (s + 1) m). So the weights are exact integer overlaps divided by n
// (the CPU computes them in f64; these are exact). A span meets at most 3 fine texels (n / m <= 3,
// equal only for n = 3).
// ---------------------------------------------------------------------------------------------

@group(0) @binding(0) var m_src: texture_2d<f32>;
@group(0) @binding(1) var m_dst: texture_storage_2d<rgba16float, write>;

/// The fine texels a coarse texel covers along one axis: the first one and the weights of it
/// and the next two (0 past the span or past the side).
struct Span {
    first: u32,
    weights: vec3<f32>,
}

/// The span of coarse texel `o` of `m` over `n` fine texels.
fn box_span(o: u32, n: u32, m: u32) -> Span {
    let a = o * n;
    let b = (o + 1u) * n;
    var span = Span(a / m, vec3<f32>(0.0));
    for (var k = 0u; k < 3u; k++) {
        let s = span.first + k;
        let lo = max(a, s * m);
        let hi = min(b, (s + 1u) * m);
        if s < n && hi > lo {
            span.weights[k] = f32(hi - lo) / f32(n);
        }
    }
    return span;
}

@compute @workgroup_size(8, 8)
fn downsample_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let dst_size = textureDimensions(m_dst);
    if any(id.xy >= dst_size) {
        return;
    }
    let src_size = textureDimensions(m_src);
    let sx = box_span(id.x, src_size.x, dst_size.x);
    let sy = box_span(id.y, src_size.y, dst_size.y);
    var acc = vec2<f32>(0.0);
    for (var j = 0u; j < 3u; j++) {
        for (var i = 0u; i < 3u; i++) {
            let w = sy.weights[j] * sx.weights[i];
            // Zero weights mark texels outside the span, possibly outside the texture: skip
            // the read.
            if w > 0.0 {
                acc += textureLoad(m_src, vec2<u32>(sx.first + i, sy.first + j), 0).rg * w;
            }
        }
    }
    // As the CPU: rounding may leave the sum a hair outside [0, 1].
    acc = clamp(acc, vec2<f32>(0.0), vec2<f32>(1.0));
    textureStore(m_dst, vec2<i32>(id.xy), f16_nearest(vec4<f32>(acc, 0.0, 0.0)));
}

// ---------------------------------------------------------------------------------------------
// Stage 3: the maximum-height (minimum-depth) pyramid.
//
// Source: Tevs, Ihrke and Seidel 2008, "Maximum mipmaps for fast, accurate, and scalable
// dynamic height field rendering": a quadtree whose cells bound the surface below them, so a
// tracer can skip a whole cell while the ray stays shallower than its value. pomkit's version
// (pyramid.rs) bounds the *bilinear* surface, not only the texel samples:
//
// Level 0, one cell per texel footprint [x, x + 1] x [y, y + 1]: the footprint straddles a
// quarter of four bilinear patches, on each of which the surface is monotone along both axes,
// so its least depth is the minimum of nine points: the texel centre, the four edge midpoints
// and the four footprint corners. Neighbours beyond the border are wrapped or clamped as
// bilinear sampling with the same edge mode would. The sums keep pyramid.rs's order so the two
// agree to the last bit or so.
//
// Coarser levels halve the cell count *rounding up* (so every texel of any size is covered) and
// keep the minimum of the up to four children that exist. GPU mips halve rounding down, so the
// texture's base is padded to powers of two; the logical sizes come in `Params` and the padding
// texels are never read or written.
//
// The bound is exact for the f16 depths of `heights` mip 0, the surface the GPU samples.
// ---------------------------------------------------------------------------------------------

@group(0) @binding(0) var p_src: texture_2d<f32>;
@group(0) @binding(1) var p_dst: texture_storage_2d<rg32float, write>;
@group(0) @binding(2) var<uniform> p_params: Params;
/// pyramid_base_main only: the cone ratio of each footprint (0 where there are none), copied into
/// level 0's green channel for the library's `cone` technique.
@group(0) @binding(3) var p_cones: texture_2d<f32>;

/// Depth of texel (x, y) + (dx, dy) of heights mip 0, neighbours wrapped or clamped.
fn p_depth(p: vec2<i32>, dx: i32, dy: i32) -> f32 {
    let size = vec2<i32>(p_params.src_size);
    let q = vec2<i32>(resolve(p.x + dx, size.x, p_params.edges), resolve(p.y + dy, size.y, p_params.edges));
    return textureLoad(p_src, q, 0).r;
}

@compute @workgroup_size(8, 8)
fn pyramid_base_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= p_params.dst_size) {
        return;
    }
    let p = vec2<i32>(id.xy);
    let c = p_depth(p, 0, 0);
    let l = p_depth(p, -1, 0);
    let r = p_depth(p, 1, 0);
    let u = p_depth(p, 0, -1);
    let b = p_depth(p, 0, 1);
    let ul = p_depth(p, -1, -1);
    let ur = p_depth(p, 1, -1);
    let bl = p_depth(p, -1, 1);
    let br = p_depth(p, 1, 1);
    // Edge midpoints, then footprint corners, of the bilinear surface.
    var m = c;
    m = min(m, (c + l) * 0.5);
    m = min(m, (c + r) * 0.5);
    m = min(m, (c + u) * 0.5);
    m = min(m, (c + b) * 0.5);
    m = min(m, (c + l + u + ul) * 0.25);
    m = min(m, (c + r + u + ur) * 0.25);
    m = min(m, (c + l + b + bl) * 0.25);
    m = min(m, (c + r + b + br) * 0.25);
    textureStore(p_dst, p, vec4<f32>(m, textureLoad(p_cones, p, 0).r, 0.0, 0.0));
}

@compute @workgroup_size(8, 8)
fn pyramid_reduce_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= p_params.dst_size) {
        return;
    }
    var m = 3.0e38;
    for (var j = 0u; j < 2u; j++) {
        for (var i = 0u; i < 2u; i++) {
            let child = 2u * id.xy + vec2<u32>(i, j);
            // Children beyond the logical size (odd sides) do not exist: skip them, never read
            // the padding.
            if all(child < p_params.src_size) {
                m = min(m, textureLoad(p_src, child, 0).r);
            }
        }
    }
    textureStore(p_dst, vec2<i32>(id.xy), vec4<f32>(m, 0.0, 0.0, 0.0));
}

// ---------------------------------------------------------------------------------------------
// Stage 4 (optional): conservative cone ratios, one footprint per invocation.
//
// Source: cone/mod.rs `ConeMap::conservative`, the same branch and bound over the pyramid built by
// stage 3, in f32 (cone/mod.rs explains the definition and why each bound holds). Per footprint
// C = [i, i + 1] x [j, j + 1] with top m (pyramid level 0), the ratio is the largest c with
// dist(q, C) >= c (m - depth(q)) for every point q of the bilinear surface of heights mip 0:
//
// - a region (a pyramid cell, or a rectangle inside one bilinear patch) whose least depth is
//   min_d bounds the ratio from below by dist(region, C) / (m - min_d); beside C also by the
//   slope bound `cone_near_bound` (cone/mod.rs `Search::near_bound`);
// - corners of patch rectangles are surface points: each bounds it from above;
// - regions whose lower bound is no better than the answer so far are dropped, others split;
//   regions small for their distance, or under CONE_MIN_REGION texels, keep their lower bound.
//
// Differences from the CPU build, none of which can make a cone too wide: no witness carried
// from the left neighbour (each invocation starts afresh: slower, same answer), and a region
// that finds the stack full keeps its lower bound instead of being split. f32 rounding of the
// bounds is some 1e-7 of the ratio; the library's walk lowers every top by
// POMKIT_CONE_TOP_MARGIN, thousands of times more than that moves a cone.
//
// The result goes to the `cones` texture; `pyramid_base_main`, dispatched again after this
// stage, copies it into the pyramid's level 0 (green), where the `cone` technique reads it.
// ---------------------------------------------------------------------------------------------

@group(0) @binding(0) var c_heights: texture_2d<f32>;
@group(0) @binding(1) var c_pyramid: texture_2d<f32>;
@group(0) @binding(2) var c_cones: texture_storage_2d<r32float, write>;
@group(0) @binding(3) var<uniform> c_params: Params;

/// cone/mod.rs SLACK, FAR, MIN_REGION and LEVEL.
const CONE_SLACK: f32 = 0.0625;
const CONE_FAR: f32 = 0.5;
const CONE_MIN_REGION: f32 = 0.125;
const CONE_LEVEL: f32 = 1e-6;
const CONE_INF: f32 = 3.0e38;
/// Regions waiting to be searched. A depth-first search over a pyramid of at most 16 levels
/// (65536 texels a side), 3 more splits inside a patch and 9 wrapped tiles holds at most
/// 9 + 3 x 20 of them.
const CONE_STACK: u32 = 72u;

/// A rectangle of the plane in texel units with the least depth of the surface over it.
struct ConeRegion {
    /// x0, x1, y0, y1 (texel units; the tile's offset applied).
    rect: vec4<f32>,
    min_depth: f32,
    /// Its lower bound on the ratio.
    lb: f32,
    /// Pyramid level of a cell, or -1 for a rectangle inside one bilinear patch.
    level: i32,
    /// The cell's coordinates at its level.
    cell: vec2<i32>,
    /// The tile (wrap: -1 to 1 along each axis) the cell lies in.
    tile: vec2<i32>,
}

var<private> cone_stack: array<ConeRegion, CONE_STACK>;

/// The depth of texel (x, y), any integers (wrapped or clamped).
fn c_texel(x: i32, y: i32) -> f32 {
    let size = vec2<i32>(c_params.src_size);
    let q = vec2<i32>(resolve(x, size.x, c_params.edges), resolve(y, size.y, c_params.edges));
    return textureLoad(c_heights, q, 0).r;
}

/// The four texels of patch (k, l): (k, l), (k + 1, l), (k, l + 1), (k + 1, l + 1).
fn c_patch(k: i32, l: i32) -> vec4<f32> {
    return vec4<f32>(c_texel(k, l), c_texel(k + 1, l), c_texel(k, l + 1), c_texel(k + 1, l + 1));
}

/// The bilinear surface of patch `d` (corner (k, l)) at (x, y).
fn c_patch_depth(d: vec4<f32>, k: f32, l: f32, x: f32, y: f32) -> f32 {
    let tx = x - k - 0.5;
    let ty = y - l - 0.5;
    let top = d.x + (d.y - d.x) * tx;
    return top + (d.z + (d.w - d.z) * tx - top) * ty;
}

/// The surface's depth at (x, y).
fn c_surface(x: f32, y: f32) -> f32 {
    let k = floor(x - 0.5);
    let l = floor(y - 0.5);
    return c_patch_depth(c_patch(i32(k), i32(l)), k, l, x, y);
}

/// The slope (along x, along y) of patch (k, l) at (x, y).
fn c_patch_slope(k: i32, l: i32, x: f32, y: f32) -> vec2<f32> {
    let d = c_patch(k, l);
    let tx = x - (f32(k) + 0.5);
    let ty = y - (f32(l) + 0.5);
    return vec2<f32>((d.y - d.x) * (1.0 - ty) + (d.w - d.z) * ty, (d.z - d.x) * (1.0 - tx) + (d.w - d.y) * tx);
}

/// Distance from the rectangle `r` (x0, x1, y0, y1) to the footprint with corner `c`.
fn c_dist(r: vec4<f32>, c: vec2<f32>) -> f32 {
    let dx = max(max(c.x - r.y, r.x - (c.x + 1.0)), 0.0);
    let dy = max(max(c.y - r.w, r.z - (c.y + 1.0)), 0.0);
    return sqrt(dx * dx + dy * dy);
}

/// Pyramid cell (x, y) of `level` in tile `tile`.
fn c_node(level: i32, cell: vec2<i32>, tile: vec2<i32>) -> ConeRegion {
    let size = vec2<i32>(c_params.src_size);
    let s = 1 << u32(level);
    let lo = min(cell * s, size);
    let hi = min((cell + 1) * s, size);
    let offset = vec2<f32>(tile * size);
    let rect = vec4<f32>(f32(lo.x) + offset.x, f32(hi.x) + offset.x, f32(lo.y) + offset.y, f32(hi.y) + offset.y);
    let min_depth = textureLoad(c_pyramid, cell, level).r;
    return ConeRegion(rect, min_depth, 0.0, level, cell, tile);
}

/// A rectangle inside one patch: its least depth is at a corner.
fn c_patch_rect(r: vec4<f32>) -> ConeRegion {
    let k = floor(0.5 * (r.x + r.y) - 0.5);
    let l = floor(0.5 * (r.z + r.w) - 0.5);
    let d = c_patch(i32(k), i32(l));
    let m = min(
        min(c_patch_depth(d, k, l, r.x, r.z), c_patch_depth(d, k, l, r.y, r.z)),
        min(c_patch_depth(d, k, l, r.x, r.w), c_patch_depth(d, k, l, r.y, r.w)),
    );
    return ConeRegion(r, m, 0.0, -1, vec2<i32>(0), vec2<i32>(0));
}

/// The largest slope across an edge, sign `sign`, of patch column or row `fixed`, at `x` or
/// `y` = `at` across, over the stretch [a0, a1] along the edge (its ends and the patch boundary
/// between them): cone/mod.rs `near_bound`'s `along`.
fn c_edge_rate(along_x: bool, fixed: i32, sign: f32, at: f32, a0: f32, a1: f32) -> f32 {
    let mid = floor(a0) + 0.5;
    var points = array<f32, 3>(a0, a1, select(a0, mid, mid > a0 && mid < a1));
    var rate = 0.0;
    for (var n = 0; n < 3; n++) {
        let a = points[n];
        let pk = i32(floor(a - 0.5));
        if along_x {
            // An edge running along x (above or below the footprint): slope along y.
            rate = max(rate, sign * c_patch_slope(pk, fixed, a, at).y);
        } else {
            rate = max(rate, sign * c_patch_slope(fixed, pk, at, a).x);
        }
    }
    return rate;
}

/// cone/mod.rs `Search::near_bound`: a lower bound on the ratio from how fast the surface can fall
/// below the footprint's edge, for regions half a texel or less beside the footprint (corner
/// `c`, integer texel `ij`, top `m`); 0 elsewhere.
fn c_near_bound(ij: vec2<i32>, c: vec2<f32>, m: f32, r: vec4<f32>) -> f32 {
    let c1 = c + 1.0;
    let right = r.x >= c1.x && r.y <= c1.x + 0.5;
    let left = r.y <= c.x && r.x >= c.x - 0.5;
    let below = r.z >= c1.y && r.w <= c1.y + 0.5;
    let above = r.w <= c.y && r.z >= c.y - 0.5;
    let across_x = r.x >= c.x && r.y <= c1.x;
    let across_y = r.z >= c.y && r.w <= c1.y;
    var rate = 0.0;
    if (right || left) && across_y {
        let k = select(ij.x - 1, ij.x, right);
        let x = select(c.x - 0.25, c1.x + 0.25, right);
        rate = c_edge_rate(false, k, select(1.0, -1.0, right), x, r.z, r.w);
    } else if (below || above) && across_x {
        let l = select(ij.y - 1, ij.y, below);
        let y = select(c.y - 0.25, c1.y + 0.25, below);
        rate = c_edge_rate(true, l, select(1.0, -1.0, below), y, r.x, r.y);
    } else if (right || left) && (below || above) {
        // Off a corner b: m - depth(q) <= -e + a |v| + t |v|^2 with v = q - b (cone/mod.rs).
        let k = select(ij.x - 1, ij.x, right);
        let bx = select(c.x, c1.x, right);
        let sx = select(-1.0, 1.0, right);
        let l = select(ij.y - 1, ij.y, below);
        let by = select(c.y, c1.y, below);
        let sy = select(-1.0, 1.0, below);
        let g = c_patch_slope(k, l, bx, by);
        let d = c_patch(k, l);
        let twist = d.x - d.y - d.z + d.w;
        let e = max(c_surface(bx, by) - m, 0.0);
        let a = length(vec2<f32>(max(-g.x * sx, 0.0), max(-g.y * sy, 0.0)));
        let t = max(-twist * sx * sy, 0.0) / 2.0;
        let far = length(vec2<f32>(max(abs(r.x - bx), abs(r.y - bx)), max(abs(r.z - by), abs(r.w - by))));
        let fall = -e + a * far + t * far * far;
        return select(CONE_INF, far / fall, fall > 0.0);
    } else {
        return 0.0;
    }
    return select(CONE_INF, 1.0 / rate, rate > 0.0);
}

/// The lower bound of region `r` for the footprint with corner `c`, top `m`.
fn c_lower(ij: vec2<i32>, c: vec2<f32>, m: f32, r: ConeRegion) -> f32 {
    if r.min_depth >= m - CONE_LEVEL {
        return CONE_INF;
    }
    let b = c_dist(r.rect, c) / (m - r.min_depth);
    return max(b, c_near_bound(ij, c, m, r.rect));
}

/// The ratio the surface point (x, y) allows the footprint (corner `c`, top `m`).
fn c_point(c: vec2<f32>, m: f32, x: f32, y: f32) -> f32 {
    let d = c_surface(x, y);
    if d >= m - CONE_LEVEL {
        return CONE_INF;
    }
    return c_dist(vec4<f32>(x, x, y, y), c) / (m - d);
}

/// The cone ratio of footprint `ij`.
fn cone_ratio(ij: vec2<i32>) -> f32 {
    let size = vec2<i32>(c_params.src_size);
    let top = i32(c_params.levels) - 1;
    let cap = f32(min(size.x, size.y));
    let m = textureLoad(c_pyramid, ij, 0).r;
    if m <= textureLoad(c_pyramid, vec2<i32>(0), top).r {
        // Nothing is shallower than this footprint's top.
        return cap;
    }
    let c = vec2<f32>(ij);
    var best = cap / (1.0 - CONE_SLACK);
    var floor_ = CONE_INF;
    var n = 0u;
    let tiles = select(0, 1, c_params.edges == EDGES_WRAP);
    for (var ty = -tiles; ty <= tiles; ty++) {
        for (var tx = -tiles; tx <= tiles; tx++) {
            var r = c_node(top, vec2<i32>(0), vec2<i32>(tx, ty));
            r.lb = c_lower(ij, c, m, r);
            cone_stack[n] = r;
            n++;
        }
    }
    var kids: array<ConeRegion, 4>;
    while n > 0u {
        n--;
        let r = cone_stack[n];
        if r.lb >= min(best * (1.0 - CONE_SLACK), floor_) {
            continue;
        }
        // Small for its distance: its bound is within 1 + CONE_FAR of its points' ratios.
        let diagonal = length(vec2<f32>(r.rect.y - r.rect.x, r.rect.w - r.rect.z));
        if diagonal <= CONE_FAR * c_dist(r.rect, c) {
            floor_ = min(floor_, r.lb);
            continue;
        }
        var count = 0;
        if r.level == 0 {
            // The footprint's quarters, each inside one patch.
            let xm = r.rect.x + 0.5;
            let ym = r.rect.z + 0.5;
            kids[0] = c_patch_rect(vec4<f32>(r.rect.x, xm, r.rect.z, ym));
            kids[1] = c_patch_rect(vec4<f32>(xm, r.rect.y, r.rect.z, ym));
            kids[2] = c_patch_rect(vec4<f32>(r.rect.x, xm, ym, r.rect.w));
            kids[3] = c_patch_rect(vec4<f32>(xm, r.rect.y, ym, r.rect.w));
            count = 4;
        } else if r.level > 0 {
            let child_size = (size + (1 << u32(r.level - 1)) - 1) >> vec2<u32>(u32(r.level - 1));
            for (var k = 0; k < 4; k++) {
                let cell = 2 * r.cell + vec2<i32>(k & 1, k >> 1u);
                if all(cell < child_size) {
                    kids[count] = c_node(r.level - 1, cell, r.tile);
                    count++;
                }
            }
        } else {
            // Its corners are surface points.
            best = min(best, c_point(c, m, r.rect.x, r.rect.z));
            best = min(best, c_point(c, m, r.rect.y, r.rect.z));
            best = min(best, c_point(c, m, r.rect.x, r.rect.w));
            best = min(best, c_point(c, m, r.rect.y, r.rect.w));
            // Level with the footprint along one axis, the ratio is least at a corner (cone/mod.rs).
            let band = (r.rect.z >= c.y && r.rect.w <= c.y + 1.0) || (r.rect.x >= c.x && r.rect.y <= c.x + 1.0);
            if band {
                continue;
            }
            let wide = r.rect.y - r.rect.x > CONE_MIN_REGION;
            let tall = r.rect.w - r.rect.z > CONE_MIN_REGION;
            if !wide && !tall {
                floor_ = min(floor_, r.lb);
                continue;
            }
            let xm = select(r.rect.y, 0.5 * (r.rect.x + r.rect.y), wide);
            let ym = select(r.rect.w, 0.5 * (r.rect.z + r.rect.w), tall);
            kids[0] = c_patch_rect(vec4<f32>(r.rect.x, xm, r.rect.z, ym));
            count = 1;
            if wide {
                kids[count] = c_patch_rect(vec4<f32>(xm, r.rect.y, r.rect.z, ym));
                count++;
            }
            if tall {
                kids[count] = c_patch_rect(vec4<f32>(r.rect.x, xm, ym, r.rect.w));
                count++;
            }
            if wide && tall {
                kids[count] = c_patch_rect(vec4<f32>(xm, r.rect.y, ym, r.rect.w));
                count++;
            }
        }
        for (var k = 0; k < count; k++) {
            kids[k].lb = c_lower(ij, c, m, kids[k]);
        }
        // Largest bound first, so the most promising child is on top of the stack.
        for (var a = 1; a < count; a++) {
            var b = a;
            while b > 0 && kids[b - 1].lb < kids[b].lb {
                let t = kids[b - 1];
                kids[b - 1] = kids[b];
                kids[b] = t;
                b--;
            }
        }
        let threshold = min(best * (1.0 - CONE_SLACK), floor_);
        for (var k = 0; k < count; k++) {
            if kids[k].lb < threshold {
                if n < CONE_STACK {
                    cone_stack[n] = kids[k];
                    n++;
                } else {
                    // No room to split it: it keeps its lower bound (safe, if narrower).
                    floor_ = min(floor_, kids[k].lb);
                }
            }
        }
    }
    return clamp(min(best * (1.0 - CONE_SLACK), floor_), 0.0, cap);
}

@compute @workgroup_size(8, 8)
fn cone_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= c_params.dst_size) {
        return;
    }
    textureStore(c_cones, vec2<i32>(id.xy), vec4<f32>(cone_ratio(vec2<i32>(id.xy)), 0.0, 0.0, 0.0));
}
