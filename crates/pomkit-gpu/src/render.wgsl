// pomkit's material shader: every tracing technique of docs/REFERENCES.md on the GPU.
//
// This file is the WGSL twin of pomkit-core's `trace.rs` and `shadow.rs` and of pomkit-cpu's
// fragment stage (`shade`). Conventions (ARCHITECTURE.md): tangent space x = T, y = B, z = N;
// a tangent-space direction (x, y, z) moves in UV by (x, -y); the height texture holds depth
// d in [0, 1] (0 = the polygon's surface); a ray entering at uv0 with unit direction
// (du, dv, dz), dz < 0, is at depth z at uv0 + z * depth_scale * (du, dv) / -dz.
//
// The technique is a pipeline-overridable constant, so each pipeline variant compiles only its
// own loop (wgpu examples' style: `override` constants before any shader composer).

// ---------------------------------------------------------------------------------------------
// Technique selection (pipeline-overridable constants)
// ---------------------------------------------------------------------------------------------

const T_FLAT: u32 = 0u;
const T_NORMAL: u32 = 1u;
const T_PARALLAX: u32 = 2u;
const T_ITERATIVE: u32 = 3u;
const T_STEEP: u32 = 4u;
const T_POM_CLASSIC: u32 = 5u;
const T_POM: u32 = 6u;
const T_RELIEF: u32 = 7u;
const T_EXACT: u32 = 8u;

/// Which technique this pipeline runs (the `T_*` values above).
override TECHNIQUE: u32 = 6u;

const S_NONE: u32 = 0u;
const S_HARD: u32 = 1u;
const S_SOFT: u32 = 2u;
const S_EXACT: u32 = 3u;

/// The flattest ray accepted, as -dz of the unit direction (trace.rs MIN_COS).
const MIN_COS: f32 = 1e-3;
/// Most iterations of the exact walk before it gives up and reports the point reached. The
/// CPU's cap grows with the map; a shader needs a fixed bound. Typical rays take tens.
const EXACT_MAX_STEPS: u32 = 4096u;
/// Stand-in for infinity (clamped border cells reach outward forever).
const BIG: f32 = 1e30;
const MAX_LIGHTS: u32 = 4u;

// ---------------------------------------------------------------------------------------------
// Bindings
// ---------------------------------------------------------------------------------------------

struct Light {
    // xyz: direction toward the light (w = 0) or position (w = 1).
    vector: vec4<f32>,
    // rgb: colour * intensity.
    radiance: vec4<f32>,
}

struct Frame {
    view_proj: mat4x4<f32>,
    // Aspect-free projection * view: pixel depth offset needs only depth, which does not depend
    // on the aspect ratio (as the CPU renderer computes it).
    depth_proj: mat4x4<f32>,
    eye: vec4<f32>,
    ambient: vec4<f32>,
    lights: array<Light, 4>,
    light_count: u32,
    lod_tint: u32,
}

struct Material {
    base_color: vec4<f32>,
    specular: f32,
    shininess: f32,
    depth_scale: f32,
    lod_threshold: f32,
    min_samples: u32,
    max_samples: u32,
    samples: u32,
    iterations: u32,
    binary_steps: u32,
    refine: u32,
    shadow_mode: u32,
    // 0 wrap, 1 clamp (the sampler's address mode matches).
    edges: u32,
    perspective_bias: f32,
    softness: f32,
    has_height: u32,
    has_normals: u32,
    height_size: vec2<f32>,
    max_level: f32,
    pyramid_levels: u32,
    albedo_size: vec2<f32>,
    albedo_max_level: f32,
    pixel_depth_offset: u32,
}

struct Object {
    model: mat4x4<f32>,
    // Cofactor matrix of the model's linear part (normals), sign-corrected for mirrors.
    normal_matrix: mat4x4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var<uniform> material: Material;
// R = depth, G = parallax map n_z * d (Lengyel 7.51, depth convention); full mip chain.
@group(1) @binding(1) var heights: texture_2d<f32>;
// xyz = unit normal (+Y up); mip 0 only.
@group(1) @binding(2) var normals: texture_2d<f32>;
// Minimum depth (maximum height) per pyramid cell, mip l = level l (read with textureLoad).
@group(1) @binding(3) var pyramid: texture_2d<f32>;
@group(1) @binding(4) var albedo: texture_2d<f32>;
// Trilinear, address mode = the material's edge mode.
@group(1) @binding(5) var samp: sampler;
@group(2) @binding(0) var<uniform> object: Object;

// ---------------------------------------------------------------------------------------------
// Vertex stage: world position, tangent frame, tangent-space view and light vectors
// ---------------------------------------------------------------------------------------------

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    // World length of one UV unit along u and v (mesh.rs `uv_scale`).
    @location(4) uv_scale: vec2<f32>,
    // Depth of the vertex below the polygon (non-zero only for `displaced` geometry).
    @location(5) depth: f32,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: vec2<f32>,
    @location(5) depth: f32,
    // Eye-to-point vector in the vertex's tangent frame (T, B, N components, not normalized):
    // linear in the position, so it interpolates exactly across a flat face.
    @location(6) view_ts: vec3<f32>,
    // Per light: direction toward it (directional) or point-to-light vector (point), in the
    // vertex's tangent frame.
    @location(7) light_ts0: vec3<f32>,
    @location(8) light_ts1: vec3<f32>,
    @location(9) light_ts2: vec3<f32>,
    @location(10) light_ts3: vec3<f32>,
}

fn any_orthonormal(n: vec3<f32>) -> vec3<f32> {
    // glam's Vec3::any_orthonormal_vector (Duff et al. 2017), so both renderers pick the same.
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(b, s + n.y * n.y * a, -n.y);
}

fn safe_normalize(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l2 = dot(v, v);
    if l2 > 1e-30 && l2 < 1e30 {
        return v * inverseSqrt(l2);
    }
    return fallback;
}

/// The tangent frame (T, B, N) re-orthonormalized from interpolated attributes (Lengyel
/// Listing 7.8; the CPU renderer does the same).
struct Frame3 {
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
    sign: f32,
}

fn tangent_frame(normal: vec3<f32>, tangent: vec4<f32>) -> Frame3 {
    let n = safe_normalize(normal, vec3<f32>(0.0, 0.0, 1.0));
    let t_raw = tangent.xyz;
    let t = safe_normalize(t_raw - n * dot(n, t_raw), any_orthonormal(n));
    let sign = select(1.0, -1.0, tangent.w < 0.0);
    return Frame3(t, cross(n, t) * sign, n, sign);
}

fn light_vector(i: u32, world: vec3<f32>) -> vec3<f32> {
    let l = frame.lights[i].vector;
    if l.w > 0.5 {
        return l.xyz - world;
    }
    return l.xyz;
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let world = (object.model * vec4<f32>(v.position, 1.0)).xyz;
    let m3 = mat3x3<f32>(object.model[0].xyz, object.model[1].xyz, object.model[2].xyz);
    let nm3 = mat3x3<f32>(object.normal_matrix[0].xyz, object.normal_matrix[1].xyz, object.normal_matrix[2].xyz);
    let normal = safe_normalize(nm3 * v.normal, v.normal);
    let t_world = m3 * v.tangent.xyz;
    let f = tangent_frame(normal, vec4<f32>(t_world, v.tangent.w));
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.world = world;
    out.normal = f.n;
    out.tangent = vec4<f32>(f.t, f.sign);
    out.uv = v.uv;
    // The model's stretch along T and B changes the world length of a UV unit.
    let b_obj = cross(v.normal, v.tangent.xyz) * f.sign;
    let stretch = vec2<f32>(length(m3 * safe_normalize(v.tangent.xyz, f.t)), length(m3 * safe_normalize(b_obj, f.b)));
    out.uv_scale = v.uv_scale * stretch;
    out.depth = v.depth;
    let to_point = world - frame.eye.xyz;
    out.view_ts = vec3<f32>(dot(to_point, f.t), dot(to_point, f.b), dot(to_point, f.n));
    var ls = array<vec3<f32>, 4>();
    for (var i = 0u; i < MAX_LIGHTS; i++) {
        let l = light_vector(i, world);
        ls[i] = vec3<f32>(dot(l, f.t), dot(l, f.b), dot(l, f.n));
    }
    out.light_ts0 = ls[0];
    out.light_ts1 = ls[1];
    out.light_ts2 = ls[2];
    out.light_ts3 = ls[3];
    return out;
}

// ---------------------------------------------------------------------------------------------
// Rays (trace.rs `tangent_ray`, `entering`, `uv_per_depth`)
// ---------------------------------------------------------------------------------------------

/// A tangent-space vector (T, B, N components) as a ray direction in (u, v, depth) terms: the
/// UV axes are stretched by the surface's UV scale (mesh.rs `tangent_ray`), and B points up the
/// image, along -v.
fn uv_ray(ts: vec3<f32>, uv_scale: vec2<f32>) -> vec3<f32> {
    let s = clamp(uv_scale, vec2<f32>(1e-12), vec2<f32>(1e12));
    return vec3<f32>(ts.x * sqrt(s.y / s.x), -ts.y * sqrt(s.x / s.y), ts.z);
}

/// Normalizes a direction and steepens it to MIN_COS; w = 0 when the ray does not enter.
fn entering(dir: vec3<f32>) -> vec4<f32> {
    let l2 = dot(dir, dir);
    if !(l2 > 0.0) {
        return vec4<f32>(0.0);
    }
    let d = dir * inverseSqrt(l2);
    if d.z >= 0.0 {
        return vec4<f32>(0.0);
    }
    if -d.z >= MIN_COS {
        return vec4<f32>(d, 1.0);
    }
    let xy = d.xy;
    let lxy = length(xy);
    var dxy = vec2<f32>(0.0);
    if lxy > 0.0 {
        dxy = xy / lxy * sqrt(1.0 - MIN_COS * MIN_COS);
    }
    return vec4<f32>(dxy, -MIN_COS, 1.0);
}

// ---------------------------------------------------------------------------------------------
// Sampling: one filtered fetch at the mip level fixed before the loop (the seeds' tex2Dgrad).
// textureSampleLevel is allowed in non-uniform control flow; the gradients were taken at the
// top of the fragment stage, in uniform control flow.
// ---------------------------------------------------------------------------------------------

var<private> fetches: u32;
var<private> lod: f32;

fn depth_at(uv: vec2<f32>) -> f32 {
    fetches += 1u;
    return textureSampleLevel(heights, samp, uv, lod).r;
}

fn parallax_at(uv: vec2<f32>) -> f32 {
    fetches += 1u;
    return textureSampleLevel(heights, samp, uv, lod).g;
}

struct Hit {
    uv: vec2<f32>,
    depth: f32,
}

/// The point of the ray at a UV offset (trace.rs `hit_on_ray`).
fn hit_on_ray(uv0: vec2<f32>, s: vec2<f32>, offset: vec2<f32>, head_on: f32) -> Hit {
    let len2 = dot(s, s);
    var z = head_on;
    if len2 > 1e-20 {
        z = dot(offset, s) / len2;
    }
    z = clamp(z, 0.0, 1.0);
    return Hit(uv0 + s * z, z);
}

/// Intersection of the ray z = t with the line through (t0, d0) and (t1, d1).
fn line_intersection(t0: f32, d0: f32, t1: f32, d1: f32) -> f32 {
    let a = d0 - t0;
    let b = t1 - d1;
    let denom = a + b;
    if denom > 0.0 {
        return t0 + (t1 - t0) * (a / denom);
    }
    return t1;
}

/// Tatarchuk 2006 eq. (1) with the erratum of docs/REFERENCES.md fixed: n_max at grazing angles, n_min head-on.
fn adaptive_samples(cos_view: f32, n_min: u32, n_max: u32) -> u32 {
    let c = clamp(cos_view, 0.0, 1.0);
    let n = f32(n_max) + (f32(n_min) - f32(n_max)) * c;
    return clamp(u32(round(n)), max(min(n_min, n_max), 1u), max(n_max, 1u));
}

// ---------------------------------------------------------------------------------------------
// Parallax mapping with offset limiting (Kaneko 2001; Welsh 2004)
// ---------------------------------------------------------------------------------------------

fn trace_parallax(uv0: vec2<f32>, dir: vec3<f32>, s: vec2<f32>) -> Hit {
    // Welsh drops the division by V.z: the shift never exceeds depth * depth_scale.
    let d = depth_at(uv0);
    return hit_on_ray(uv0, s, dir.xy * (d * material.depth_scale), d * -dir.z);
}

// ---------------------------------------------------------------------------------------------
// Iterative parallax (Lengyel, FGED 2, Listing 7.9, in the depth convention)
// ---------------------------------------------------------------------------------------------

fn trace_iterative(uv0: vec2<f32>, dir: vec3<f32>, s: vec2<f32>) -> Hit {
    let k = material.iterations;
    let step = dir.xy * (material.depth_scale / f32(k));
    var uv = uv0;
    var sum = 0.0;
    for (var i = 0u; i < k; i++) {
        let value = parallax_at(uv);
        sum += value;
        uv += step * value;
    }
    return hit_on_ray(uv0, s, uv - uv0, sum / f32(k) * -dir.z);
}

// ---------------------------------------------------------------------------------------------
// Steep parallax (McGuire 2005). Erratum (docs/REFERENCES.md, Errata): the loop is capped; the plane at depth 1
// is always at or below the surface and needs no fetch.
// ---------------------------------------------------------------------------------------------

fn trace_steep(uv0: vec2<f32>, s: vec2<f32>) -> Hit {
    let n = material.samples;
    for (var i = 0u; i < n; i++) {
        let z = f32(i) / f32(n);
        if depth_at(uv0 + s * z) <= z {
            return Hit(uv0 + s * z, z);
        }
    }
    return Hit(uv0 + s, 1.0);
}

// ---------------------------------------------------------------------------------------------
// Parallax occlusion mapping, 2004 (Brawley & Tatarchuk, ShaderX3): 8 samples along the
// parallax vector with Brawley's perspective bias, line-line intersection. The article's
// ps_2_0 shader cannot branch, so all 8 samples are fetched.
//
// Brawley computes the parallax vector per vertex. Here it is computed per pixel from the
// interpolated tangent-space view vector: tan(theta) is not linear across a triangle, and on
// large polygons (the demo's floor is two triangles) the per-vertex version visibly bends the
// relief. The CPU twin does the same, so both renderers agree.
// ---------------------------------------------------------------------------------------------

fn trace_pom_classic(uv0: vec2<f32>, dir: vec3<f32>) -> Hit {
    let cos = -dir.z;
    let pb = material.perspective_bias;
    let bias = max(pb + (1.0 - pb) * (2.0 * cos - 1.0), 0.0);
    let s = dir.xy * (material.depth_scale / -dir.z) * bias;
    var t_prev = 0.0;
    var d_prev = 0.0;
    var found = false;
    var z = 1.0;
    for (var i = 1u; i <= 8u; i++) {
        let t = f32(i) / 8.0;
        let d = depth_at(uv0 + s * t);
        if i == 1u {
            d_prev = d;
        }
        if !found && d <= t {
            z = line_intersection(t_prev, max(d_prev, t_prev), t, d);
            found = true;
        }
        if !found {
            t_prev = t;
            d_prev = d;
        }
    }
    return Hit(uv0 + s * z, z);
}

// ---------------------------------------------------------------------------------------------
// Parallax occlusion mapping (Zink 2008 / Tatarchuk 2006): adaptive sample count, early exit,
// piecewise-linear intersection, then optional secant refinement (as Unity HDRP).
// ---------------------------------------------------------------------------------------------

fn trace_pom(uv0: vec2<f32>, dir: vec3<f32>, s: vec2<f32>) -> Hit {
    let n = adaptive_samples(-dir.z, material.min_samples, material.max_samples);
    let step = 1.0 / f32(n);
    var a = vec2<f32>(0.0, depth_at(uv0));
    if a.y <= 0.0 {
        return Hit(uv0, 0.0);
    }
    var b = vec2<f32>(1.0, 1.0);
    var found = false;
    for (var i = 1u; i <= n; i++) {
        var t = f32(i) * step;
        if i == n {
            t = 1.0;
        }
        let d = depth_at(uv0 + s * t);
        if d <= t {
            b = vec2<f32>(t, d);
            found = true;
            break;
        }
        a = vec2<f32>(t, d);
    }
    if !found {
        return Hit(uv0 + s, 1.0);
    }
    var z = line_intersection(a.x, a.y, b.x, b.y);
    for (var i = 0u; i < material.refine; i++) {
        let d = depth_at(uv0 + s * z);
        if d > z {
            a = vec2<f32>(z, d);
        } else {
            b = vec2<f32>(z, d);
        }
        z = line_intersection(a.x, a.y, b.x, b.y);
    }
    return Hit(uv0 + s * z, z);
}

// ---------------------------------------------------------------------------------------------
// Relief mapping (Policarpo, Oliveira & Comba 2005): linear search, then binary refinement.
// ---------------------------------------------------------------------------------------------

fn trace_relief(uv0: vec2<f32>, s: vec2<f32>) -> Hit {
    let n = material.samples;
    var lo = 0.0;
    var hi = 1.0;
    for (var i = 1u; i < n; i++) {
        let t = f32(i) / f32(n);
        if depth_at(uv0 + s * t) <= t {
            hi = t;
            break;
        }
        lo = t;
    }
    for (var i = 0u; i < material.binary_steps; i++) {
        let mid = 0.5 * (lo + hi);
        if depth_at(uv0 + s * mid) <= mid {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    var z = hi;
    if material.binary_steps > 0u {
        z = 0.5 * (lo + hi);
    }
    return Hit(uv0 + s * z, z);
}

// ---------------------------------------------------------------------------------------------
// The exact tracer: maximum-height pyramid traversal (after Tevs, Ihrke & Seidel 2008) with
// ray / bilinear-patch quadratics, the twin of trace.rs `exact_first_hit`.
//
// Differences from the CPU (which works in f64): f32 throughout, so the nudge that picks the
// cell a ray enters is 1e-3 texel rather than 1e-9, and the walk is capped at EXACT_MAX_STEPS.
// Fetches are counted as the CPU counts them: one gather per 2x2 sibling block of pyramid cells
// and one per bilinear patch, kept while the ray walks between them.
// ---------------------------------------------------------------------------------------------

struct Cell {
    ix: i32,
    iy: i32,
    lo: vec2<f32>,
    hi: vec2<f32>,
}

fn level_cells(n: i32, level: u32) -> i32 {
    let size = 1 << level;
    return (n + size - 1) / size;
}

/// One axis of `cell_at`: the cell index and its walls in unbounded texel coordinates.
fn cell_axis(p: f32, n: i32, level: u32) -> vec3<f32> {
    let size = 1 << level;
    let cells = level_cells(n, level);
    let fp = floor(p);
    if material.edges == 0u {
        let tile = floor(fp / f32(n));
        let local = clamp(i32(fp - tile * f32(n)), 0, n - 1);
        let c = min(local / size, cells - 1);
        let base = tile * f32(n);
        return vec3<f32>(f32(c), base + f32(c * size), base + f32(min((c + 1) * size, n)));
    }
    let local = i32(clamp(fp, 0.0, f32(n - 1)));
    let c = min(local / size, cells - 1);
    var lo = f32(c * size);
    var hi = f32(min((c + 1) * size, n));
    if c == 0 {
        lo = -BIG;
    }
    if c == cells - 1 {
        hi = BIG;
    }
    return vec3<f32>(f32(c), lo, hi);
}

fn cell_at(level: u32, p: vec2<f32>) -> Cell {
    let size = vec2<i32>(material.height_size);
    let ax = cell_axis(p.x, size.x, level);
    let ay = cell_axis(p.y, size.y, level);
    return Cell(i32(ax.x), i32(ay.x), vec2<f32>(ax.y, ay.y), vec2<f32>(ax.z, ay.z));
}

fn exit_time(c: Cell, o: vec3<f32>, d: vec3<f32>, t: f32, t1: f32) -> f32 {
    var te = t1;
    if d.x > 0.0 {
        te = min(te, (c.hi.x - o.x) / d.x);
    } else if d.x < 0.0 {
        te = min(te, (c.lo.x - o.x) / d.x);
    }
    if d.y > 0.0 {
        te = min(te, (c.hi.y - o.y) / d.y);
    } else if d.y < 0.0 {
        te = min(te, (c.lo.y - o.y) / d.y);
    }
    return max(te, t);
}

fn block_key(c: Cell, level: u32) -> vec2<i32> {
    if material.edges == 0u {
        let size = f32(1 << level);
        return vec2<i32>(
            i32(round(c.lo.x - f32(c.ix % 2) * size)),
            i32(round(c.lo.y - f32(c.iy % 2) * size)),
        );
    }
    return vec2<i32>(c.ix / 2, c.iy / 2);
}

/// Depth of mip-0 texel (i, j) with the material's edge mode.
fn texel_depth(i: i32, j: i32) -> f32 {
    let size = vec2<i32>(material.height_size);
    var p = vec2<i32>(i, j);
    if material.edges == 0u {
        p = ((p % size) + size) % size;
    } else {
        p = clamp(p, vec2<i32>(0), size - 1);
    }
    return textureLoad(heights, p, 0).r;
}

var<private> last_patch: vec2<i32>;

/// First t in [ta, tb] where the ray is at or below the bilinear patch holding the segment's
/// midpoint (trace.rs `patch_hit`); -1 when none.
fn patch_hit(o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32) -> f32 {
    let mid = o + d * (0.5 * (ta + tb));
    let i = floor(mid.x - 0.5);
    let j = floor(mid.y - 0.5);
    let key = vec2<i32>(i32(i), i32(j));
    if any(key != last_patch) {
        last_patch = key;
        fetches += 1u;
    }
    let s00 = texel_depth(key.x, key.y);
    let s10 = texel_depth(key.x + 1, key.y);
    let s01 = texel_depth(key.x, key.y + 1);
    let s11 = texel_depth(key.x + 1, key.y + 1);
    let a = s00;
    let b = s10 - s00;
    let c = s01 - s00;
    let e = s00 - s10 - s01 + s11;
    let fx0 = o.x - (i + 0.5);
    let fy0 = o.y - (j + 0.5);
    // g(t) = z(t) - S(x(t), y(t)) = qa t^2 + qb t + qc; at or below the surface where g >= 0.
    let qa = -e * d.x * d.y;
    let qb = d.z - b * d.x - c * d.y - e * (fx0 * d.y + fy0 * d.x);
    let qc = o.z - (a + b * fx0 + c * fy0 + e * fx0 * fy0);
    if (qa * ta + qb) * ta + qc >= 0.0 {
        return ta;
    }
    var best = BIG;
    let scale = max(max(abs(qb), abs(qc)), 1e-30);
    if abs(qa) <= 1e-6 * scale {
        if qb != 0.0 {
            let r = -qc / qb;
            if r > ta && r <= tb {
                best = r;
            }
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let sq = sqrt(disc);
            let q = -0.5 * (qb + select(-1.0, 1.0, qb >= 0.0) * sq);
            var r1 = -qb / (2.0 * qa);
            var r2 = r1;
            if q != 0.0 {
                r1 = q / qa;
                r2 = qc / q;
            }
            if r1 > ta && r1 <= tb {
                best = min(best, r1);
            }
            if r2 > ta && r2 <= tb {
                best = min(best, r2);
            }
        }
    }
    if best < BIG {
        return best;
    }
    if (qa * tb + qb) * tb + qc >= 0.0 {
        return tb;
    }
    return -1.0;
}

/// The patches a ray crosses inside one texel footprint (trace.rs `leaf_hit`): split at the
/// texel-centre lines, at most three segments.
fn leaf_hit(o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32, c: Cell) -> f32 {
    var centre = c.lo + 0.5;
    if material.edges != 0u {
        centre = vec2<f32>(f32(c.ix), f32(c.iy)) + 0.5;
    }
    var cut0 = tb;
    var cut1 = tb;
    if d.x != 0.0 {
        let tc = (centre.x - o.x) / d.x;
        if tc > ta && tc < tb {
            cut0 = tc;
        }
    }
    if d.y != 0.0 {
        let tc = (centre.y - o.y) / d.y;
        if tc > ta && tc < tb {
            cut1 = tc;
        }
    }
    let ends = array<f32, 3>(min(cut0, cut1), max(cut0, cut1), tb);
    var start = ta;
    for (var k = 0u; k < 3u; k++) {
        let end = ends[k];
        if end <= start && !(end == tb && start == ta) {
            continue;
        }
        let h = patch_hit(o, d, start, end);
        if h >= 0.0 {
            return h;
        }
        start = end;
    }
    return -1.0;
}

/// First t in [t0, t1] where the ray o + t d (texel x, y; depth z) is at or below the bilinear
/// surface; -1 when it stays above.
fn exact_first_hit(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> f32 {
    let top = material.pyramid_levels - 1u;
    var blocks = array<vec2<i32>, 16>();
    for (var k = 0u; k < 16u; k++) {
        blocks[k] = vec2<i32>(-2147483647);
    }
    last_patch = vec2<i32>(-2147483647);
    let speed = max(max(abs(d.x), abs(d.y)), 1.0);
    let nudge = max(1e-3 / speed, 1e-7);
    var t = t0;
    var level = 0u;
    for (var it = 0u; it < EXACT_MAX_STEPS; it++) {
        if t > t1 {
            break;
        }
        let probe = o + d * min(t + nudge, t1);
        let c = cell_at(level, probe.xy);
        let t_exit = exit_time(c, o, d, t, t1);
        let key = block_key(c, level);
        let slot = min(level, 15u);
        if any(blocks[slot] != key) {
            blocks[slot] = key;
            fetches += 1u;
        }
        let bound = textureLoad(pyramid, vec2<i32>(c.ix, c.iy), i32(level)).r;
        var deepest = o.z + d.z * t;
        if d.z >= 0.0 {
            deepest = o.z + d.z * t_exit;
        }
        if deepest < bound {
            if t_exit >= t1 {
                break;
            }
            if level < top {
                let parent = cell_at(level + 1u, probe.xy);
                if exit_time(parent, o, d, t, t1) <= t_exit {
                    level += 1u;
                }
            }
            t = t_exit;
            continue;
        }
        if level > 0u {
            if d.z > 0.0 {
                t = max(t, (bound - o.z) / d.z);
            }
            level -= 1u;
            continue;
        }
        let h = leaf_hit(o, d, t, t_exit, c);
        if h >= 0.0 {
            return h;
        }
        if t_exit >= t1 {
            break;
        }
        t = t_exit;
    }
    return -1.0;
}

/// With wrapping edges, texel coordinates relative to the entry point's tile keep f32 precise
/// for UVs far from 0 (the surface repeats, so the walk is the same). Clamped edges do not tile.
fn entry_tile(uv: vec2<f32>) -> vec2<f32> {
    if material.edges == 0u {
        return floor(uv);
    }
    return vec2<f32>(0.0);
}

fn trace_exact(uv0: vec2<f32>, s: vec2<f32>) -> Hit {
    let size = material.height_size;
    let tile = entry_tile(uv0);
    let o = vec3<f32>((uv0 - tile) * size, 0.0);
    let d = vec3<f32>(s * size, 1.0);
    var t = exact_first_hit(o, d, 0.0, 1.0);
    if t < 0.0 {
        t = 1.0;
    }
    t = clamp(t, 0.0, 1.0);
    let p = o + d * t;
    return Hit(tile + p.xy / size, t);
}

/// Runs this pipeline's technique. `dir` is an entering unit direction.
fn trace(uv0: vec2<f32>, dir: vec3<f32>) -> Hit {
    let s = dir.xy * (material.depth_scale / -dir.z);
    switch TECHNIQUE {
        case T_PARALLAX: {
            return trace_parallax(uv0, dir, s);
        }
        case T_ITERATIVE: {
            return trace_iterative(uv0, dir, s);
        }
        case T_STEEP: {
            return trace_steep(uv0, s);
        }
        case T_POM_CLASSIC: {
            return trace_pom_classic(uv0, dir);
        }
        case T_POM: {
            return trace_pom(uv0, dir, s);
        }
        case T_RELIEF: {
            return trace_relief(uv0, s);
        }
        case T_EXACT: {
            return trace_exact(uv0, s);
        }
        default: {
            return Hit(uv0, 0.0);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Self-shadowing (Brawley & Tatarchuk 2004; McGuire 2005; Tatarchuk 2006 section 3.2), the
// twin of shadow.rs. `light` is the tangent-space direction toward the light in ray terms.
// ---------------------------------------------------------------------------------------------

fn shadow(uv: vec2<f32>, depth_in: f32, light: vec3<f32>) -> f32 {
    let l2 = dot(light, light);
    if !(l2 > 0.0) {
        return 1.0;
    }
    let l = light * inverseSqrt(l2);
    if l.z <= 0.0 {
        return 0.0;
    }
    let depth = clamp(depth_in, 0.0, 1.0);
    let mode = material.shadow_mode;
    if mode == S_NONE || depth <= 0.0 {
        return 1.0;
    }
    let s = l.xy * (material.depth_scale / max(l.z, MIN_COS));
    if mode == S_EXACT {
        let size = material.height_size;
        // The receiver may lie below the exact surface (pom's linear segments cut under the
        // bilinear surface; coarser mips differ from mip 0): an exact ray from there shadows
        // itself in speckles. Lift it onto the exact surface (one fetch), then a hair above it
        // (f32: 1e-4 of the depth range; the CPU uses 1e-5 in f64).
        fetches += 1u;
        let on_surface = min(depth, textureSampleLevel(heights, samp, uv, 0.0).r);
        let eps = 1e-4;
        let z0 = max(on_surface - eps, 0.0);
        let tile = entry_tile(uv);
        let o = vec3<f32>((uv - tile) * size, z0);
        let d = vec3<f32>(s * size, -1.0);
        let t = exact_first_hit(o, d, min(eps, z0), z0);
        return select(1.0, 0.0, t >= 0.0);
    }
    let n = adaptive_samples(l.z, material.min_samples, material.max_samples);
    let soft = mode == S_SOFT;
    let rho = max(material.softness, 1e-4);
    let tan_theta = sqrt(max(1.0 - l.z * l.z, 0.0)) / l.z;
    let light_elevation = atan2(1.0, tan_theta);
    var visibility = 1.0;
    for (var i = 1u; i < n; i++) {
        let t = depth * f32(i) / f32(n);
        let d = depth_at(uv + s * t);
        if soft {
            let elevation = atan2(depth - d, t * tan_theta);
            let v = clamp(0.5 - (elevation - light_elevation) / (2.0 * rho), 0.0, 1.0);
            visibility = min(visibility, v);
        } else if d < depth - t - 1e-5 {
            return 0.0;
        }
    }
    return visibility;
}

/// Weight of the full technique in the LOD fade (Tatarchuk 2006 section 3.3).
fn lod_weight(level: f32, threshold: f32) -> f32 {
    return clamp(threshold - level, 0.0, 1.0);
}

/// Mip level for isotropic filtering from UV gradients (heightfield.rs
/// `mip_level_from_gradients`).
fn mip_level(duv_dx: vec2<f32>, duv_dy: vec2<f32>, size: vec2<f32>, max_level: f32) -> f32 {
    let rho2 = max(dot(duv_dx * size, duv_dx * size), dot(duv_dy * size, duv_dy * size));
    if !(rho2 > 1.0) || rho2 > 1e30 {
        return 0.0;
    }
    return clamp(0.5 * log2(rho2), 0.0, max(max_level, 0.0));
}

// ---------------------------------------------------------------------------------------------
// Fragment stage: trace, shade (Blinn-Phong with the normal map), shadows, LOD fade, AOVs
// ---------------------------------------------------------------------------------------------

struct Shaded {
    color: vec3<f32>,
    vis: f32,
}

fn light_ts(in: VertexOut, i: u32) -> vec3<f32> {
    switch i {
        case 0u: {
            return in.light_ts0;
        }
        case 1u: {
            return in.light_ts1;
        }
        case 2u: {
            return in.light_ts2;
        }
        default: {
            return in.light_ts3;
        }
    }
}

fn lit(in: VertexOut, f: Frame3, to_eye: vec3<f32>, uv: vec2<f32>, depth: f32, with_shadows: bool, albedo_lod: f32) -> Shaded {
    let base = textureSampleLevel(albedo, samp, uv, albedo_lod).rgb * material.base_color.rgb;
    var shading_n = f.n;
    if material.has_normals != 0u && TECHNIQUE != T_FLAT {
        let nm = safe_normalize(textureSampleLevel(normals, samp, uv, 0.0).xyz, vec3<f32>(0.0, 0.0, 1.0));
        shading_n = safe_normalize(f.t * nm.x + f.b * nm.y + f.n * nm.z, f.n);
    }
    var c = frame.ambient.rgb * base;
    var first_vis = 1.0;
    for (var i = 0u; i < min(frame.light_count, MAX_LIGHTS); i++) {
        let light = frame.lights[i];
        var l = safe_normalize(light.vector.xyz, vec3<f32>(0.0, 1.0, 0.0));
        var radiance = light.radiance.rgb;
        if light.vector.w > 0.5 {
            let dv = light.vector.xyz - in.world;
            let d2 = max(dot(dv, dv), 1e-8);
            l = dv / sqrt(d2);
            radiance = radiance / d2;
        }
        let n_dot_l = dot(f.n, l);
        var vis = select(0.0, 1.0, n_dot_l > 0.0);
        // Tatarchuk 2006: no shadow trace where the polygon faces away from the light.
        if with_shadows && n_dot_l > 0.0 && material.shadow_mode != S_NONE && material.has_height != 0u {
            vis = shadow(uv, depth, uv_ray(light_ts(in, i), in.uv_scale));
        }
        if i == 0u {
            first_vis = vis;
        }
        let diffuse = max(dot(shading_n, l), 0.0);
        let h = safe_normalize(l + to_eye, shading_n);
        var spec = 0.0;
        if diffuse > 0.0 {
            spec = material.specular * pow(max(dot(shading_n, h), 0.0), material.shininess);
        }
        c += (base * diffuse + vec3<f32>(spec)) * radiance * vis;
    }
    return Shaded(c, first_vis);
}

struct FragmentOut {
    // Linear colour; a = 1.
    @location(0) color: vec4<f32>,
    // Hit UV, hit depth, visibility of the first light.
    @location(1) aov0: vec4<f32>,
    // Fetches, height mip level, coverage (1), 0.
    @location(2) aov1: vec4<f32>,
}

struct Shading {
    out: FragmentOut,
    // Depth-buffer value after pixel depth offset.
    z: f32,
}

fn displaces() -> bool {
    return TECHNIQUE != T_FLAT && TECHNIQUE != T_NORMAL;
}

fn shade(in: VertexOut, duv_dx: vec2<f32>, duv_dy: vec2<f32>) -> Shading {
    fetches = 0u;
    let f = tangent_frame(in.normal, in.tangent);
    let to_eye = safe_normalize(frame.eye.xyz - in.world, f.n);
    // Mip level of the height map from the quad's UV gradients, fixed before any loop.
    var weight = 0.0;
    lod = 0.0;
    if material.has_height != 0u {
        lod = mip_level(duv_dx, duv_dy, material.height_size, material.max_level);
        weight = lod_weight(lod, material.lod_threshold);
    }
    var hit = Hit(in.uv, in.depth);
    if material.has_height != 0u && weight > 0.0 && displaces() {
        let e = entering(uv_ray(in.view_ts, in.uv_scale));
        if e.w > 0.0 {
            hit = trace(in.uv, e.xyz);
        } else {
            hit = Hit(in.uv, 0.0);
        }
        if TECHNIQUE == T_STEEP {
            // Steep parallax stops on the first plane below the surface; lift the receiver
            // onto the surface so shadows do not start inside the relief (contour-ring acne).
            hit.depth = min(hit.depth, depth_at(hit.uv));
        }
    }
    let albedo_lod = mip_level(duv_dx, duv_dy, material.albedo_size, material.albedo_max_level);
    let shadows = displaces() || (material.has_height != 0u && TECHNIQUE != T_FLAT);
    let full = lit(in, f, to_eye, hit.uv, hit.depth, shadows && weight > 0.0, albedo_lod);
    var color = full.color;
    if weight < 1.0 && material.has_height != 0u {
        let simple = lit(in, f, to_eye, in.uv, in.depth, false, albedo_lod);
        color = mix(simple.color, full.color, weight);
    }
    if frame.lod_tint != 0u && material.has_height != 0u {
        let tint = mix(vec3<f32>(1.0, 0.25, 0.2), vec3<f32>(0.25, 1.0, 0.3), weight);
        color = color * 0.5 + tint * 0.5 * max(length(color), 0.05);
    }
    var z = in.clip.z;
    // Pixel depth offset: move the depth to the traced point along the view ray.
    if material.pixel_depth_offset != 0u && hit.depth > 0.0 && weight > 0.0 && displaces() {
        let l_world = sqrt(max(in.uv_scale.x * in.uv_scale.y, 0.0));
        let down = hit.depth * material.depth_scale * l_world;
        let cos = max(dot(to_eye, f.n), 1e-3);
        let p = in.world - to_eye * (down / cos);
        let c = frame.depth_proj * vec4<f32>(p, 1.0);
        if c.w > 0.0 {
            z = clamp(max(c.z / c.w, in.clip.z), 0.0, 1.0);
        }
    }
    var out: FragmentOut;
    out.color = vec4<f32>(color, 1.0);
    out.aov0 = vec4<f32>(hit.uv, hit.depth, full.vis);
    out.aov1 = vec4<f32>(f32(fetches), lod, 1.0, 0.0);
    return Shading(out, z);
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    // Gradients first, in uniform control flow (the seeds' tex2Dgrad).
    let duv_dx = dpdx(in.uv);
    let duv_dy = dpdy(in.uv);
    return shade(in, duv_dx, duv_dy).out;
}

struct FragmentOutDepth {
    @location(0) color: vec4<f32>,
    @location(1) aov0: vec4<f32>,
    @location(2) aov1: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

/// The entry point for materials with pixel depth offset: writes `frag_depth` (which turns off
/// early depth testing, so it is a separate pipeline).
@fragment
fn fs_main_depth(in: VertexOut) -> FragmentOutDepth {
    let duv_dx = dpdx(in.uv);
    let duv_dy = dpdy(in.uv);
    let s = shade(in, duv_dx, duv_dy);
    return FragmentOutDepth(s.out.color, s.out.aov0, s.out.aov1, s.z);
}
