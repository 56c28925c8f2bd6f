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
    _pad: u32,
}

const EDGES_WRAP: u32 = 0u;
const EDGES_CLAMP: u32 = 1u;
const FILTER_CENTRAL: u32 = 0u;
const FILTER_SOBEL: u32 = 1u;

/// Texel coordinate `i` mapped into `0..n` by wrapping (a Euclidean remainder, so any size works:
/// docs/REFERENCES.md, Errata, Lengyel's `& (size - 1)` erratum) or clamping. HeightField::depth_at.
fn resolve(i: i32, n: i32, edges: u32) -> i32 {
    if edges == EDGES_WRAP {
        // WGSL's % truncates toward zero; adding n once makes it Euclidean.
        return ((i % n) + n) % n;
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
