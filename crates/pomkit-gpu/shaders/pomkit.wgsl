// pomkit shader library, plain WGSL: generated from crates/pomkit-gpu/shaders/pomkit/*.wesl by
// pomkit_gpu::library::flatten (do not edit; `UPDATE_SHADERS=1 cargo test -p pomkit-gpu --test
// library` rewrites it). Paste it in front of your shader; docs/EMBEDDING.md shows how.

// ===== module common =====

// pomkit shader library: constants, parameters, results and the ray set-up every module shares.
//
// Conventions (ARCHITECTURE.md, Conventions; docs/EMBEDDING.md for a host renderer):
// - Tangent space: x = T, y = B, z = N (out of the surface), B = w * cross(N, T) with w the
//   vertex tangent's handedness (glTF). T points along +u, B along -v (up the image), so a
//   tangent-space direction (x, y, z) moves in UV by (x, -y).
// - The height texture holds depth d in [0, 1]: 0 is the polygon's surface, 1 the deepest point.
// - `depth_scale`: how far, in UV units, the deepest point lies below the surface. A ray
//   entering at uv0 with unit direction (du, dv, dz), dz < 0, in "ray terms" (u, v, depth) is at
//   depth z at uv0 + z * depth_scale * (du, dv) / -dz.
//
// Every function is pure: it reads heights only through the textures and sampler it is given,
// and the library has no module-level variables. Names start with `pomkit_` (`POMKIT_` for
// constants), so the plain-WGSL form (pomkit.wgsl) can be pasted in front of any shader.

// ---------------------------------------------------------------------------------------------
// Techniques and shadow modes (pomkit_core's `Technique` and `ShadowMode`; a naga test keeps
// these equal to the Rust side)
// ---------------------------------------------------------------------------------------------

const POMKIT_FLAT: u32 = 0u;
const POMKIT_NORMAL: u32 = 1u;
const POMKIT_PARALLAX: u32 = 2u;
const POMKIT_ITERATIVE: u32 = 3u;
const POMKIT_STEEP: u32 = 4u;
const POMKIT_POM_CLASSIC: u32 = 5u;
const POMKIT_POM: u32 = 6u;
const POMKIT_RELIEF: u32 = 7u;
const POMKIT_EXACT: u32 = 8u;
/// `cone`: cone stepping on the cones in the pyramid's mip 0 (cone.wesl), exact's walk where
/// there are none. The same hits as `exact`.
const POMKIT_CONE: u32 = 9u;

const POMKIT_SHADOW_NONE: u32 = 0u;
const POMKIT_SHADOW_HARD: u32 = 1u;
const POMKIT_SHADOW_SOFT: u32 = 2u;
const POMKIT_SHADOW_EXACT: u32 = 3u;
/// Darkening with depth, no fetch (McGuire 2005's fur, after Lengyel et al. 2001).
const POMKIT_SHADOW_DEPTH: u32 = 4u;

/// `PomkitParams::edges`: the height map repeats (the sampler must use `repeat`).
const POMKIT_WRAP: u32 = 0u;
/// `PomkitParams::edges`: the height map's border texels extend outward (`clamp-to-edge`).
const POMKIT_CLAMP: u32 = 1u;

/// The flattest ray accepted, as -dz of the unit direction (pomkit_core trace.rs `MIN_COS`).
const POMKIT_MIN_COS: f32 = 1e-3;
/// Most iterations of the exact walk before it gives up and reports the point reached. The
/// CPU's cap grows with the map; a shader needs a fixed bound. Typical rays take tens.
const POMKIT_EXACT_MAX_STEPS: u32 = 4096u;
/// Stand-in for infinity (clamped border cells reach outward forever).
const POMKIT_BIG: f32 = 1e30;

// ---------------------------------------------------------------------------------------------
// Parameters and results
// ---------------------------------------------------------------------------------------------

/// A material's tracing parameters: 64 bytes, laid out for a uniform buffer (all members are
/// 4-byte scalars), written by `pomkit_gpu::library::PomkitParams`. The meaning, range and
/// default of each is pomkit_core's `TraceParams` (docs/SCENES.md).
struct PomkitParams {
    /// Which technique `pomkit_trace` runs (`POMKIT_FLAT` .. `POMKIT_CONE`).
    technique: u32,
    /// Which self-shadow `pomkit_shadow` computes (`POMKIT_SHADOW_*`).
    shadow_mode: u32,
    /// `POMKIT_WRAP` or `POMKIT_CLAMP`; the sampler's address mode must match.
    edges: u32,
    /// Adaptive sample count of `pom` and of hard/soft shadows: used head-on ...
    min_samples: u32,
    /// ... and at grazing angles.
    max_samples: u32,
    /// Fixed layer count of `steep` and `relief`.
    samples: u32,
    /// Iterations of `iterative`.
    iterations: u32,
    /// Binary-search steps of `relief`, and of `cone` after a relaxed cone's step went under the
    /// surface.
    binary_steps: u32,
    /// Secant refinements of `pom`.
    refine: u32,
    /// UV distance of the deepest point below the surface.
    depth_scale: f32,
    /// Brawley's perspective bias of `pom-classic`, in [0, 1].
    perspective_bias: f32,
    /// Penumbra width of soft shadows (radians of light elevation).
    softness: f32,
    /// Mip level up to which the full technique runs; it fades out over the next level.
    lod_threshold: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

/// Where a view ray meets the height field.
struct PomkitHit {
    /// The hit's UV: sample every texture of the material here.
    uv: vec2<f32>,
    /// The hit's depth in [0, 1] below the surface.
    depth: f32,
    /// Texture reads made (the GPU's count: one filtered sample, or one texel load, each).
    fetches: u32,
}

/// The visibility of a light from a traced point.
struct PomkitShadow {
    /// 1 lit, 0 shadowed, between for soft shadows.
    visibility: f32,
    /// Texture reads made.
    fetches: u32,
}

/// The height map's size as the tracers need it (from the textures themselves).
struct PomkitMap {
    /// Width and height in texels.
    size: vec2<f32>,
    /// The last mip level of the height texture.
    max_level: f32,
    /// Mip levels of the maximum-height pyramid.
    pyramid_levels: u32,
    /// `POMKIT_WRAP` or `POMKIT_CLAMP`.
    edges: u32,
}

/// The sizes of `heights` and `pyramid`.
fn pomkit_map(heights: texture_2d<f32>, pyramid: texture_2d<f32>, params: PomkitParams) -> PomkitMap {
    let size = vec2<f32>(textureDimensions(heights, 0));
    return PomkitMap(size, f32(textureNumLevels(heights)) - 1.0, textureNumLevels(pyramid), params.edges);
}

// ---------------------------------------------------------------------------------------------
// Vectors and frames
// ---------------------------------------------------------------------------------------------

/// `v` normalized, or `fallback` when `v` is zero, tiny or huge.
fn pomkit_safe_normalize(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l2 = dot(v, v);
    if l2 > 1e-30 && l2 < 1e30 {
        return v * inverseSqrt(l2);
    }
    return fallback;
}

/// A unit vector orthogonal to the unit vector `n` (glam's `any_orthonormal_vector`, Duff et
/// al. 2017, so the CPU and the GPU pick the same).
fn pomkit_any_orthonormal(n: vec3<f32>) -> vec3<f32> {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(b, s + n.y * n.y * a, -n.y);
}

/// An orthonormal tangent frame.
struct PomkitFrame {
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
    /// The tangent's handedness w, +1 or -1.
    sign: f32,
}

/// The tangent frame (T, B, N) re-orthonormalized from an interpolated normal and a glTF
/// tangent (xyz, w = handedness): B = w * cross(N, T) (Lengyel, Listing 7.8).
fn pomkit_tangent_frame(normal: vec3<f32>, tangent: vec4<f32>) -> PomkitFrame {
    let n = pomkit_safe_normalize(normal, vec3<f32>(0.0, 0.0, 1.0));
    let t_raw = tangent.xyz;
    let t = pomkit_safe_normalize(t_raw - n * dot(n, t_raw), pomkit_any_orthonormal(n));
    let sign = select(1.0, -1.0, tangent.w < 0.0);
    return PomkitFrame(t, cross(n, t) * sign, n, sign);
}

/// A world vector in the frame's tangent space (T, B, N components).
fn pomkit_to_tangent(f: PomkitFrame, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, f.t), dot(v, f.b), dot(v, f.n));
}

// ---------------------------------------------------------------------------------------------
// Rays: tangent space to "ray terms" (u, v, depth)
// ---------------------------------------------------------------------------------------------

/// A tangent-space vector (T, B, N components) in ray terms (u, v, depth): the UV axes are
/// stretched by the surface's UV scale (the world length of one UV unit along u and v; pass
/// vec2(1.0) where UVs are not stretched), and B points up the image, along -v.
fn pomkit_light_ray(ts: vec3<f32>, uv_scale: vec2<f32>) -> vec3<f32> {
    let s = clamp(uv_scale, vec2<f32>(1e-12), vec2<f32>(1e12));
    return vec3<f32>(ts.x * sqrt(s.y / s.x), -ts.y * sqrt(s.x / s.y), ts.z);
}

/// `v` scaled to unit length, for any finite non-zero length (it is first divided by its
/// largest component, so its square neither overflows nor underflows); zero for a zero or
/// non-finite `v`.
fn pomkit_unit(v: vec3<f32>) -> vec3<f32> {
    let m = max(max(abs(v.x), abs(v.y)), abs(v.z));
    if !(m > 0.0 && m <= 3.4028235e38) {
        return vec3<f32>(0.0);
    }
    let w = v / m;
    return w * inverseSqrt(dot(w, w));
}

/// The view ray of a pixel for `pomkit_trace`: `view_ts` is the eye-to-point vector in tangent
/// space (any length). Returns the unit direction in ray terms, steepened to `POMKIT_MIN_COS`,
/// with w = 1; or w = 0 when the ray does not enter the surface (it comes from below or is
/// zero).
fn pomkit_view_ray(view_ts: vec3<f32>, uv_scale: vec2<f32>) -> vec4<f32> {
    let d = pomkit_unit(pomkit_light_ray(view_ts, uv_scale));
    if !(dot(d, d) > 0.0) {
        return vec4<f32>(0.0);
    }
    if d.z >= 0.0 {
        return vec4<f32>(0.0);
    }
    if -d.z >= POMKIT_MIN_COS {
        return vec4<f32>(d, 1.0);
    }
    let xy = d.xy;
    let lxy = length(xy);
    var dxy = vec2<f32>(0.0);
    if lxy > 0.0 {
        dxy = xy / lxy * sqrt(1.0 - POMKIT_MIN_COS * POMKIT_MIN_COS);
    }
    return vec4<f32>(dxy, -POMKIT_MIN_COS, 1.0);
}

/// The world length of one UV unit along u and v, from screen-space derivatives of the world
/// position and the UV (`dpdx`, `dpdy`), for hosts whose vertices carry no UV scale. Exact on a
/// flat triangle; returns vec2(1.0) where the UV mapping is degenerate.
fn pomkit_uv_scale(dworld_dx: vec3<f32>, dworld_dy: vec3<f32>, duv_dx: vec2<f32>, duv_dy: vec2<f32>) -> vec2<f32> {
    // d(world) = J d(uv) with J = [dP/du dP/dv]; solve from the two screen directions.
    let det = duv_dx.x * duv_dy.y - duv_dx.y * duv_dy.x;
    if !(abs(det) > 1e-20) {
        return vec2<f32>(1.0);
    }
    let dp_du = (dworld_dx * duv_dy.y - dworld_dy * duv_dx.y) / det;
    let dp_dv = (dworld_dy * duv_dx.x - dworld_dx * duv_dy.x) / det;
    let s = vec2<f32>(length(dp_du), length(dp_dv));
    if !(s.x > 0.0 && s.y > 0.0 && s.x < 1e30 && s.y < 1e30) {
        return vec2<f32>(1.0);
    }
    return s;
}

// ---------------------------------------------------------------------------------------------
// Height reads: one filtered fetch at a mip level fixed before any loop (the tex2Dgrad of
// docs/REFERENCES.md). textureSampleLevel is allowed in non-uniform control flow.
// ---------------------------------------------------------------------------------------------

/// Depth at `uv` (R of the height texture), filtered at mip `lod`.
fn pomkit_depth_at(heights: texture_2d<f32>, samp: sampler, uv: vec2<f32>, lod: f32) -> f32 {
    return textureSampleLevel(heights, samp, uv, lod).r;
}

/// Parallax value clamp(n_z * d, 0, 1) at `uv` (G of the height texture; Lengyel 7.51).
fn pomkit_parallax_at(heights: texture_2d<f32>, samp: sampler, uv: vec2<f32>, lod: f32) -> f32 {
    return textureSampleLevel(heights, samp, uv, lod).g;
}

// ===== module lod =====

// pomkit shader library: the height map's mip level and the LOD fade (Tatarchuk 2006, section
// 3.3; docs/REFERENCES.md).
//
// Call `pomkit_mip_level` with gradients taken in uniform control flow (`dpdx(uv)`, `dpdy(uv)`
// at the top of the fragment shader), then trace at that level: the level stays fixed for the
// whole ray, as HLSL's tex2Dgrad does in the published POM shaders.

/// Mip level for isotropic filtering of a `size`-texel texture with `max_level` as its last
/// level, from the UV gradients (pomkit_core heightfield.rs `mip_level_from_gradients`).
fn pomkit_mip_level_sized(duv_dx: vec2<f32>, duv_dy: vec2<f32>, size: vec2<f32>, max_level: f32) -> f32 {
    let rho2 = max(dot(duv_dx * size, duv_dx * size), dot(duv_dy * size, duv_dy * size));
    if !(rho2 > 1.0) || rho2 > 1e30 {
        return 0.0;
    }
    return clamp(0.5 * log2(rho2), 0.0, max(max_level, 0.0));
}

/// Mip level of the height texture `heights` from the UV gradients.
fn pomkit_mip_level(heights: texture_2d<f32>, duv_dx: vec2<f32>, duv_dy: vec2<f32>) -> f32 {
    let size = vec2<f32>(textureDimensions(heights, 0));
    return pomkit_mip_level_sized(duv_dx, duv_dy, size, f32(textureNumLevels(heights)) - 1.0);
}

/// Weight of the full technique in the LOD fade: 1 up to mip level `threshold - 1`, falling to
/// 0 at `threshold`. Blend `mix(plain, traced, weight)`; skip the trace where it is 0.
fn pomkit_lod_weight(level: f32, threshold: f32) -> f32 {
    return clamp(threshold - level, 0.0, 1.0);
}

// ===== module exact =====

// pomkit shader library: the exact tracer's walk. A maximum-height pyramid traversal (after
// Tevs, Ihrke & Seidel 2008) with ray / bilinear-patch quadratics, the twin of pomkit_core
// trace.rs `exact_first_hit` (docs/REFERENCES.md).
//
// Differences from the CPU (which works in f64): f32 throughout, and the walk is capped at
// POMKIT_EXACT_MAX_STEPS. As on the CPU, the cell a ray enters is chosen by its direction on a
// wall, and patch quadratics are formed at the segment's start, so f32 stays within 0.006
// texel of the f64 walk (docs/GPU.md). Fetches are counted as the CPU counts them: one gather
// per 2x2 sibling block of pyramid cells and one per bilinear patch, kept while the ray walks
// between them.
//
// Shaped for SIMD (a GPU's warp, or llvmpipe's 8 lanes per instruction on a CPU), with the same
// cells, patches and fetch counts as the CPU's loop: one bilinear patch per step (the CPU solves
// a level-0 cell's up to three patches at once; here the lanes in a leaf and the lanes still
// walking share each step); no integer division or remainder by a variable (levels are powers
// of two: shifts); the held sibling blocks as one bit per level, cleared by the levels whose
// walls the ray crosses, rather than an array indexed by level; the climb decided by that same
// crossed wall; one cell computed per step (a rounding retry waits for the next step); a patch's
// four texels read with one gather. llvmpipe runs every instruction of the loop body for every
// lane, whichever branch the lanes take (a branch no ray ever took, of 32 square roots and
// divisions, added 40% to the pass), so there what the body holds is what a step costs.
// docs/BENCHMARKS.md ("The exact walk on lavapipe") measures each.
//
// Coordinates: texel units, x along u and y along v (texel (i, j) has its centre at
// (i + 0.5, j + 0.5)); z is depth in [0, 1]. A ray is o + t d.


/// A pyramid cell: its index and its walls in unbounded texel coordinates.
struct PomkitCell {
    ix: i32,
    iy: i32,
    lo: vec2<f32>,
    hi: vec2<f32>,
}

/// The result of a walk: the ray parameter of the first hit (-1 when none) and the fetches.
struct PomkitWalk {
    t: f32,
    fetches: u32,
}

/// What the walk remembers between patches: fetches so far and the patch last read.
struct PomkitWalkState {
    fetches: u32,
    last_patch: vec2<i32>,
}

// Integer division and remainder by a variable have no SIMD instruction on CPUs: llvmpipe
// (lavapipe) does them lane by lane, which made them the largest cost of a step. So the walk
// shifts by the level (sizes are powers of two, indices non-negative) and wraps with a float
// floor; the results are the same integers.

fn pomkit_level_cells(n: i32, level: u32) -> i32 {
    let size = 1 << level;
    return (n + size - 1) >> level;
}

/// One axis of `pomkit_cell_at`: the cell index and its walls.
fn pomkit_cell_axis(p: f32, dp: f32, n: i32, level: u32, edges: u32) -> vec3<f32> {
    let size = 1 << level;
    let cells = pomkit_level_cells(n, level);
    // On a wall, the cell the ray enters (pomkit_core trace.rs `cell_at`).
    let fp = select(floor(p), ceil(p) - 1.0, dp < 0.0);
    if edges == POMKIT_WRAP {
        let tile = floor(fp / f32(n));
        let local = clamp(i32(fp - tile * f32(n)), 0, n - 1);
        let c = min(local >> level, cells - 1);
        let base = tile * f32(n);
        return vec3<f32>(f32(c), base + f32(c * size), base + f32(min((c + 1) * size, n)));
    }
    let local = i32(clamp(fp, 0.0, f32(n - 1)));
    let c = min(local >> level, cells - 1);
    var lo = f32(c * size);
    var hi = f32(min((c + 1) * size, n));
    if c == 0 {
        lo = -POMKIT_BIG;
    }
    if c == cells - 1 {
        hi = POMKIT_BIG;
    }
    return vec3<f32>(f32(c), lo, hi);
}

fn pomkit_cell_at(map: PomkitMap, level: u32, p: vec2<f32>, d: vec3<f32>) -> PomkitCell {
    let size = vec2<i32>(map.size);
    let ax = pomkit_cell_axis(p.x, d.x, size.x, level, map.edges);
    let ay = pomkit_cell_axis(p.y, d.y, size.y, level, map.edges);
    return PomkitCell(i32(ax.x), i32(ay.x), vec2<f32>(ax.y, ay.y), vec2<f32>(ax.z, ay.z));
}

/// Where the ray leaves cell `c`, no earlier than `t` and no later than `t1`.
fn pomkit_exit_time(c: PomkitCell, o: vec3<f32>, d: vec3<f32>, t: f32, t1: f32) -> f32 {
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

/// The cell of `level` the ray enters at `t`, with a probe point inside it and the time the ray
/// leaves it, strictly after `t` (trace.rs `entered_cell`); `ok` is false when no wall ahead can
/// be told from the current point in f32.
struct PomkitEntered {
    cell: PomkitCell,
    probe: vec2<f32>,
    t_exit: f32,
    ok: bool,
}

fn pomkit_entered_cell(map: PomkitMap, level: u32, o: vec3<f32>, d: vec3<f32>, t: f32, t1: f32) -> PomkitEntered {
    var probe = (o + d * t).xy;
    var c = pomkit_cell_at(map, level, probe, d);
    var t_exit = pomkit_exit_time(c, o, d, t, t1);
    if !(t_exit > t) && t < t1 {
        // Rounding put the point on the wrong side of a wall the ray is leaving: step half a
        // texel across it.
        if d.x > 0.0 && (c.hi.x - o.x) / d.x <= t {
            probe.x = c.hi.x + 0.5;
        } else if d.x < 0.0 && (c.lo.x - o.x) / d.x <= t {
            probe.x = c.lo.x - 0.5;
        }
        if d.y > 0.0 && (c.hi.y - o.y) / d.y <= t {
            probe.y = c.hi.y + 0.5;
        } else if d.y < 0.0 && (c.lo.y - o.y) / d.y <= t {
            probe.y = c.lo.y - 0.5;
        }
        c = pomkit_cell_at(map, level, probe, d);
        t_exit = pomkit_exit_time(c, o, d, t, t1);
        if !(t_exit > t) {
            return PomkitEntered(c, probe, t_exit, false);
        }
    }
    return PomkitEntered(c, probe, t_exit, true);
}

/// How many levels' cells the ray leaves when it leaves cell `c` of `level` at `t_exit` (before
/// the end of its segment): those of `level` and of every coarser level that shares the wall it
/// crosses. A wall at local texel index k (in 1..n-1) is a wall of level l's cells when 2^l
/// divides k; a tile's edges (k = 0 or n) are walls of every level (32 stands for all). `exits`
/// are the times the ray reaches the wall ahead on each axis (`pomkit_wall_times`): it crosses
/// that wall now if it reaches it at `t_exit`.
fn pomkit_levels_left(map: PomkitMap, c: PomkitCell, level: u32, d: vec3<f32>, exits: vec2<f32>, t_exit: f32) -> u32 {
    let n = vec2<i32>(map.size);
    let size = 1 << level;
    let index = vec2<i32>(c.ix, c.iy);
    let forward = d.xy > vec2<f32>(0.0);
    let k = select(index * size, min((index + 1) * size, n), forward);
    let crossed = (d.xy != vec2<f32>(0.0)) & (exits == vec2<f32>(t_exit));
    let levels = select(countTrailingZeros(vec2<u32>(k)), vec2<u32>(32u), (k <= vec2<i32>(0)) | (k >= n));
    let left = select(vec2<u32>(0u), levels, crossed);
    return max(left.x, left.y);
}

/// The times the ray `o + t d` reaches the walls of `c` ahead of it on each axis, `t1` on an
/// axis it does not move along: the expressions of `pomkit_exit_time`, so the least of them,
/// limited to `[t, t1]`, is the cell's exit time bit for bit.
fn pomkit_wall_times(c: PomkitCell, o: vec3<f32>, d: vec3<f32>, t1: f32) -> vec2<f32> {
    let wall = select(c.lo, c.hi, d.xy > vec2<f32>(0.0));
    return select(vec2<f32>(t1), (wall - o.xy) / d.xy, d.xy != vec2<f32>(0.0));
}

/// `seen` without the blocks of the levels below `left` (`pomkit_levels_left`): the ray has left
/// them.
fn pomkit_forget_blocks(seen: u32, left: u32) -> u32 {
    if left >= 32u {
        return 0u;
    }
    return seen & ~((1u << left) - 1u);
}

/// Depths of the four texels (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1) with the map's edge
/// mode, as x, y, z, w: the corners of one bilinear patch, read with one gather. `samp` addresses
/// the map as its edge mode does (repeat for wrap, clamp to edge for clamp: the sampler
/// `pomkit_trace` takes), so the gather reads texel (i mod w, j mod h) and its neighbours where
/// the map wraps, the nearest texels inside it where it clamps, as the CPU's `depth_at` does. Its
/// point is the patch's centre, the corner (i + 1, j + 1) the four texels share, half a texel
/// from any other footprint. One gather instead of four loads: the lanes of a SIMD group run
/// the patch code at every step of the walk, and on lavapipe the four loads were half its cost.
fn pomkit_patch_depths(heights: texture_2d<f32>, samp: sampler, map: PomkitMap, i: i32, j: i32) -> vec4<f32> {
    // Gather order: (i, j + 1), (i + 1, j + 1), (i + 1, j), (i, j).
    let g = textureGather(0, heights, samp, vec2<f32>(f32(i + 1), f32(j + 1)) / map.size);
    return vec4<f32>(g.w, g.z, g.x, g.y);
}

/// First t in [ta, tb] where the ray is at or below the bilinear patch holding the segment's
/// midpoint (trace.rs `patch_hit`); -1 when none.
fn pomkit_patch_hit(heights: texture_2d<f32>, samp: sampler, map: PomkitMap, state: ptr<function, PomkitWalkState>, o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32) -> f32 {
    let mid = o + d * (0.5 * (ta + tb));
    let i = floor(mid.x - 0.5);
    let j = floor(mid.y - 0.5);
    let key = vec2<i32>(i32(i), i32(j));
    if any(key != (*state).last_patch) {
        (*state).last_patch = key;
        (*state).fetches += 1u;
    }
    let corners = pomkit_patch_depths(heights, samp, map, key.x, key.y);
    let s00 = corners.x;
    let s10 = corners.y;
    let s01 = corners.z;
    let s11 = corners.w;
    let a = s00;
    let b = s10 - s00;
    let c = s01 - s00;
    let e = s00 - s10 - s01 + s11;
    // g relative to the segment's start, u = t - ta in [0, ub]: the ray's origin may lie
    // thousands of texels away, and f32 coefficients formed there cancel.
    let p0 = o + d * ta;
    let ub = tb - ta;
    let fx0 = p0.x - (i + 0.5);
    let fy0 = p0.y - (j + 0.5);
    // g(t) = z(t) - S(x(t), y(t)) = qa t^2 + qb t + qc; at or below the surface where g >= 0.
    let qa = -e * d.x * d.y;
    let qb = d.z - b * d.x - c * d.y - e * (fx0 * d.y + fy0 * d.x);
    let qc = p0.z - (a + b * fx0 + c * fy0 + e * fx0 * fy0);
    if qc >= 0.0 {
        return ta;
    }
    var best = POMKIT_BIG;
    let scale = max(max(abs(qb), abs(qc)), 1e-30);
    if abs(qa) <= 1e-6 * scale {
        if qb != 0.0 {
            let r = -qc / qb;
            if r > 0.0 && r <= ub {
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
            if r1 > 0.0 && r1 <= ub {
                best = min(best, r1);
            }
            if r2 > 0.0 && r2 <= ub {
                best = min(best, r2);
            }
        }
    }
    if best < POMKIT_BIG {
        return min(ta + best, tb);
    }
    if (qa * ub + qb) * ub + qc >= 0.0 {
        return tb;
    }
    return -1.0;
}

/// Where the ray's segment [ta, tb] inside level-0 cell `c` changes bilinear patch, ascending:
/// its crossings of the texel-centre lines strictly inside the segment (tb where there is none),
/// then tb itself.
fn pomkit_leaf_ends(map: PomkitMap, o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32, c: PomkitCell) -> vec3<f32> {
    var centre = c.lo + 0.5;
    if map.edges != POMKIT_WRAP {
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
    return vec3<f32>(min(cut0, cut1), max(cut0, cut1), tb);
}

/// The patches a ray crosses inside one texel footprint (trace.rs `leaf_hit`): split at the
/// texel-centre lines, at most three segments.
fn pomkit_leaf_hit(heights: texture_2d<f32>, samp: sampler, map: PomkitMap, state: ptr<function, PomkitWalkState>, o: vec3<f32>, d: vec3<f32>, ta: f32, tb: f32, c: PomkitCell) -> f32 {
    let cuts = pomkit_leaf_ends(map, o, d, ta, tb, c);
    let ends = array<f32, 3>(cuts.x, cuts.y, cuts.z);
    var start = ta;
    for (var k = 0u; k < 3u; k++) {
        let end = ends[k];
        if end <= start && !(end == tb && start == ta) {
            continue;
        }
        let h = pomkit_patch_hit(heights, samp, map, state, o, d, start, end);
        if h >= 0.0 {
            return h;
        }
        start = end;
    }
    return -1.0;
}

/// The first of a leaf's patch ends (`pomkit_leaf_ends`) past `t`: the end of the segment the
/// walk solves next, in the order `pomkit_leaf_hit` solves them.
fn pomkit_next_end(leaf: vec3<f32>, t: f32) -> f32 {
    var end = leaf.z;
    if leaf.y > t {
        end = leaf.y;
    }
    if leaf.x > t {
        end = leaf.x;
    }
    return end;
}

/// The level the walk starts at (trace.rs `start_level`): `floor(log2(travel)) - 3` for a
/// horizontal travel of at least 8 texels, else 0, and never above `top`. From the f32 travel,
/// so it can differ from the CPU's only for a travel within rounding of a power of two (the
/// fetches and steps then differ, not the hit).
fn pomkit_start_level(d: vec3<f32>, t0: f32, t1: f32, top: u32) -> u32 {
    let travel = length(d.xy) * (t1 - t0);
    if !(travel >= 8.0) {
        return 0u;
    }
    // 4294967040 is the largest f32 below 2^32: the conversion stays in range.
    let whole = u32(min(travel, 4294967040.0));
    return min(firstLeadingBit(whole) - 3u, top);
}

/// First t in [t0, t1] where the ray o + t d (texel x, y; depth z) is at or below the bilinear
/// surface of the mip-0 texels of `heights`; t = -1 when it stays above. `pyramid` holds the
/// least depth of each cell, level l in mip l (pomkit_gpu's `HeightMaps::pyramid`).
fn pomkit_exact_first_hit(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, map: PomkitMap, o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> PomkitWalk {
    let top = map.pyramid_levels - 1u;
    // Bit l: a cell of level l was read since the ray entered its current 2x2 sibling block
    // there, so the block's gather is held (the CPU keeps each level's last block; a ray
    // never comes back to a block it left, so a bit per level says the same, without an array
    // indexed by level, which costs a shader more than the rest of a step).
    var seen = 0u;
    var state = PomkitWalkState(0u, vec2<i32>(-2147483647));
    var t = t0;
    // A few levels above the finest, from the ray's travel (`pomkit_start_level`).
    var level = pomkit_start_level(d, t0, t1, top);
    // A level-0 cell being solved: where its patches end (`pomkit_leaf_ends`). Each step solves
    // one patch, so lanes of a SIMD group that are in a leaf and lanes still walking share a
    // step's cost, instead of every step paying for up to three patches.
    var leaf = vec3<f32>(0.0);
    var in_leaf = false;
    var leaf_left = 0u;
    // A probe moved across a wall that rounding put behind the point (`pomkit_entered_cell`'s
    // second try, taken at the next step so that a step computes one cell, not two: a SIMD
    // group runs every instruction of the loop body for every lane).
    var nudged = vec2<f32>(0.0);
    var has_nudge = false;
    for (var it = 0u; it < POMKIT_EXACT_MAX_STEPS; it++) {
        if !in_leaf {
            if t > t1 {
                break;
            }
            let probe = select((o + d * t).xy, nudged, has_nudge);
            let c = pomkit_cell_at(map, level, probe, d);
            let exits = pomkit_wall_times(c, o, d, t1);
            let t_exit = max(min(min(exits.x, exits.y), t1), t);
            if !(t_exit > t) && t < t1 {
                if has_nudge {
                    // No wall ahead can be told from the current point in f32.
                    break;
                }
                // Rounding put the point on the wrong side of a wall the ray is leaving: step
                // half a texel across it.
                let across = select(c.lo - 0.5, c.hi + 0.5, d.xy > vec2<f32>(0.0));
                nudged = select(probe, across, (d.xy != vec2<f32>(0.0)) & (exits <= vec2<f32>(t)));
                has_nudge = true;
                continue;
            }
            has_nudge = false;
            let bit = 1u << min(level, 31u);
            if (seen & bit) == 0u {
                seen |= bit;
                state.fetches += 1u;
            }
            let bound = textureLoad(pyramid, vec2<i32>(c.ix, c.iy), i32(level)).r;
            var deepest = o.z + d.z * t;
            if d.z >= 0.0 {
                deepest = o.z + d.z * t_exit;
            }
            // The levels whose cells the ray leaves at t_exit: for the climb and for the
            // blocks it forgets, whether it skips this cell or solves it as a leaf.
            let left = pomkit_levels_left(map, c, level, d, exits, t_exit);
            if deepest < bound {
                if t_exit >= t1 {
                    break;
                }
                seen = pomkit_forget_blocks(seen, left);
                // Climb only when the ray also leaves the parent cell (the wall it crosses is
                // the parent's too): inside the same parent, climbing would only descend again.
                if level < top && left > level {
                    level += 1u;
                }
                t = t_exit;
                continue;
            }
            // Going down, nothing is hit before the ray reaches the bound (used only when d.z > 0).
            let t_bound = max(t, (bound - o.z) / d.z);
            if bound >= 1.0 && d.z > 0.0 {
                // A flat floor: the cell's least depth is the deepest a map holds, so its
                // surface is the plane at depth 1, which the ray meets inside the cell (trace.rs
                // `exact_first_hit`, the same shortcut).
                return PomkitWalk(min(t_bound, t_exit), state.fetches);
            }
            if level > 0u {
                if d.z > 0.0 {
                    t = t_bound;
                }
                level -= 1u;
                continue;
            }
            // Level 0: the bilinear patches inside this texel footprint, one per step.
            leaf = pomkit_leaf_ends(map, o, d, t, t_exit, c);
            leaf_left = left;
            in_leaf = true;
        }
        let end = pomkit_next_end(leaf, t);
        let h = pomkit_patch_hit(heights, samp, map, &state, o, d, t, end);
        if h >= 0.0 {
            return PomkitWalk(h, state.fetches);
        }
        t = end;
        if end >= leaf.z {
            in_leaf = false;
            seen = pomkit_forget_blocks(seen, leaf_left);
            if end >= t1 {
                break;
            }
        }
    }
    return PomkitWalk(-1.0, state.fetches);
}

// ---------------------------------------------------------------------------------------------
// The walk on plane bounds per cell
// ---------------------------------------------------------------------------------------------

/// `seen` without the bits of the levels whose cells the ray leaves when it crosses a wall of
/// levels up to `left` (`pomkit_levels_left`): the plane walk's cells of levels 1 to `left` and
/// its 2x2 blocks of level 0. A wall of level 0 alone keeps everything.
fn pomkit_forget_cells(seen: u32, left: u32) -> u32 {
    if left == 0u {
        return seen;
    }
    if left >= 31u {
        return 0u;
    }
    return seen & ~((2u << left) - 1u);
}

/// The f16 whose bits are `bits` (finite: the planes hold no infinity or NaN), as an f32, with
/// integer operations: `unpack2x16float` needs a capability (naga's
/// `SHADER_FLOAT16_IN_FLOAT32`) that not every host's device has. Normal halves get the f32
/// exponent bias and a widened mantissa; subnormal ones are their mantissa times 2^-24.
fn pomkit_half(bits: u32) -> f32 {
    let magnitude = bits & 0x7fffu;
    let sign = (bits & 0x8000u) << 16u;
    let normal = bitcast<f32>(sign | ((magnitude + 0x1c000u) << 13u));
    let subnormal = bitcast<f32>(sign | bitcast<u32>(f32(magnitude) * 5.9604645e-8));
    return select(normal, subnormal, magnitude < 0x400u);
}

/// The two f16 of `packed`: the low half in x, the high half in y.
fn pomkit_halves(packed: u32) -> vec2<f32> {
    return vec2<f32>(pomkit_half(packed & 0xffffu), pomkit_half(packed >> 16u));
}

/// The centre of cell `c`'s texel range at `level`, in the ray's unbounded coordinates (moved by
/// the cell's tile where the edges wrap): the point a plane's depth is stored for.
fn pomkit_plane_centre(map: PomkitMap, c: PomkitCell, level: u32) -> vec2<f32> {
    let n = vec2<i32>(map.size);
    let index = vec2<i32>(c.ix, c.iy);
    let first = index << vec2<u32>(level);
    let centre = 0.5 * vec2<f32>(first + min((index + 1) << vec2<u32>(level), n));
    if map.edges == POMKIT_WRAP {
        return c.lo - vec2<f32>(first) + centre;
    }
    return centre;
}

/// The plane walk's tuning, as pomkit_core's `plane_walk` module: levels above
/// `pomkit_start_level` it starts at, the highest level it starts at, and the longest bracket,
/// in texels of travel, whose patches it solves at once.
const POMKIT_PLANES_START_UP: u32 = 2u;
const POMKIT_PLANES_START_CAP: u32 = 5u;
const POMKIT_PLANES_SOLVE_SPAN: f32 = 3.0;

/// `pomkit_exact_first_hit` for rays going down (`d.z > 0`) on plane bounds per pyramid cell
/// (pomkit_core trace/exact/plane_walk.rs, the twin: the same cells, patches and fetch counts).
/// `planes` is `Rgba32Uint`, mip `l - 1` holding pyramid level `l`'s cells (pomkit_gpu's
/// `PlaneBounds`): x = the cell's least depth (f32 bits), y = its plane's depth at the centre
/// of its texel range (f32 bits), z = the plane's slopes along x and y (two f16), w = how far the
/// surface reaches shallower and deeper than the plane over the cell (two f16). Level 0 reads
/// `pyramid` as `pomkit_exact_first_hit` does.
///
/// A step skips a cell the ray crosses above `plane - shallower` or above its least depth;
/// where the ray's depth reaches `plane + deeper` within `POMKIT_PLANES_SOLVE_SPAN` texels of
/// where it can first meet the surface, it solves the patches from there, one per step,
/// footprint by footprint up to the one holding that point (`solving`); otherwise it descends
/// straight to the level as wide as that bracket.
fn pomkit_planes_first_hit(heights: texture_2d<f32>, pyramid: texture_2d<f32>, planes: texture_2d<u32>, samp: sampler, map: PomkitMap, o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> PomkitWalk {
    let top = map.pyramid_levels - 1u;
    let travel = length(d.xy);
    // Bit l: at level 0 the 2x2 block of least depths is held, above it the cell's texel.
    var seen = 0u;
    var state = PomkitWalkState(0u, vec2<i32>(-2147483647));
    var t = t0;
    var level = min(min(pomkit_start_level(d, t0, t1, top) + POMKIT_PLANES_START_UP, POMKIT_PLANES_START_CAP), top);
    var leaf = vec3<f32>(0.0);
    var in_leaf = false;
    var leaf_left = 0u;
    // Solving a bracket of the cell at `level`: footprints up to the one holding `solve_end`,
    // within the cell, which the ray leaves at `cell_exit`, crossing walls up to `cell_left`.
    var solving = false;
    var solve_end = 0.0;
    var cell_exit = 0.0;
    var cell_left = 0u;
    var nudged = vec2<f32>(0.0);
    var has_nudge = false;
    for (var it = 0u; it < POMKIT_EXACT_MAX_STEPS; it++) {
        if !in_leaf {
            if t > t1 {
                break;
            }
            let cell_level = select(level, 0u, solving);
            let probe = select((o + d * t).xy, nudged, has_nudge);
            let c = pomkit_cell_at(map, cell_level, probe, d);
            let exits = pomkit_wall_times(c, o, d, t1);
            let t_exit = max(min(min(exits.x, exits.y), t1), t);
            if !(t_exit > t) && t < t1 {
                if has_nudge {
                    break;
                }
                let across = select(c.lo - 0.5, c.hi + 0.5, d.xy > vec2<f32>(0.0));
                nudged = select(probe, across, (d.xy != vec2<f32>(0.0)) & (exits <= vec2<f32>(t)));
                has_nudge = true;
                continue;
            }
            has_nudge = false;
            let left = pomkit_levels_left(map, c, cell_level, d, exits, t_exit);
            if solving {
                // The next footprint of the bracket: its patches, without its least depth.
                leaf = pomkit_leaf_ends(map, o, d, t, t_exit, c);
                leaf_left = left;
                in_leaf = true;
            } else {
                let bit = 1u << min(level, 31u);
                if (seen & bit) == 0u {
                    seen |= bit;
                    state.fetches += 1u;
                }
                var texel = vec4<u32>(0u);
                var bound: f32;
                if level > 0u {
                    texel = textureLoad(planes, vec2<i32>(c.ix, c.iy), i32(level - 1u));
                    bound = bitcast<f32>(texel.x);
                } else {
                    bound = textureLoad(pyramid, vec2<i32>(c.ix, c.iy), 0).r;
                }
                var skip = o.z + d.z * t_exit < bound;
                // Before t_lo the least depth keeps the ray above the surface.
                var t_lo = max(t, min((bound - o.z) / d.z, t_exit));
                var under = -1.0;
                if !skip && level > 0u && bound < 1.0 {
                    let slope = pomkit_halves(texel.z);
                    let widths = pomkit_halves(texel.w);
                    // The ray's depth minus the plane's, linear, formed at the ray's point at t.
                    let p = o + d * t;
                    let g0 = p.z - (bitcast<f32>(texel.y) + dot(slope, p.xy - pomkit_plane_centre(map, c, level)));
                    let g1 = d.z - dot(slope, d.xy);
                    let g_exit = g0 + g1 * (t_exit - t);
                    if max(g0 + g1 * (t_lo - t), g_exit) < -widths.x {
                        skip = true;
                    } else {
                        if g0 + g1 * (t_lo - t) < -widths.x {
                            t_lo = clamp(t + (-widths.x - g0) / g1, t_lo, t_exit);
                        }
                        if g0 + g1 * (t_lo - t) >= widths.y {
                            under = t_lo;
                        } else if g_exit >= widths.y {
                            under = clamp(t + (widths.y - g0) / g1, t_lo, t_exit);
                        }
                    }
                }
                if skip {
                    if t_exit >= t1 {
                        break;
                    }
                    seen = pomkit_forget_cells(seen, left);
                    if level < top && left > level {
                        level += 1u;
                    }
                    t = t_exit;
                    continue;
                }
                if bound >= 1.0 {
                    // A flat floor, as in `pomkit_exact_first_hit`.
                    return PomkitWalk(min(max(t, (1.0 - o.z) / d.z), t_exit), state.fetches);
                }
                if level > 0u {
                    let span = (under - t_lo) * travel;
                    if under >= 0.0 && span <= POMKIT_PLANES_SOLVE_SPAN {
                        solving = true;
                        solve_end = under;
                        cell_exit = t_exit;
                        cell_left = left;
                        t = t_lo;
                        continue;
                    }
                    t = t_lo;
                    var wide = level - 1u;
                    if under >= 0.0 {
                        wide = u32(floor(log2(max(span, 1.0))));
                    }
                    level = min(level - 1u, wide);
                    continue;
                }
                leaf = pomkit_leaf_ends(map, o, d, t, t_exit, c);
                leaf_left = left;
                in_leaf = true;
            }
        }
        let end = pomkit_next_end(leaf, t);
        let h = pomkit_patch_hit(heights, samp, map, &state, o, d, t, end);
        if h >= 0.0 {
            return PomkitWalk(h, state.fetches);
        }
        t = end;
        if end >= leaf.z {
            in_leaf = false;
            seen = pomkit_forget_cells(seen, leaf_left);
            if end >= t1 {
                break;
            }
            if solving && (end >= solve_end || end >= cell_exit) {
                solving = false;
                if end >= cell_exit && level < top && cell_left > level {
                    level += 1u;
                }
            }
        }
    }
    return PomkitWalk(-1.0, state.fetches);
}

// ===== module cone =====

// pomkit shader library: the `cone` technique's walk, the twin of pomkit_core cone/mod.rs
// `first_hit` (docs/REFERENCES.md: Dummer 2006; Bán et al. 2024 for cones that hold for the
// bilinear surface).
//
// The cone map lives in the pyramid texture's mip 0: red is each texel footprint's top (the
// least depth of the surface over it, the pyramid's level 0), green its cone ratio in texels per
// unit depth (pomkit_gpu's `HeightMaps::write_cones`). The cones were built for the depths before
// their rounding to f16, so the walk lowers each top by POMKIT_CONE_TOP_MARGIN, three times that
// rounding: the cones then hold for the surface sampled here. A ratio of 0 means the pyramid
// has no cones: the walk is then exact's.
//
// Above a footprint's top the ray advances by the longer of the cone step and the stretch over
// the footprint to its top or its far edge; at or below the top it solves the bilinear patches
// there (as exact does at level 0). Conservative cones skip only empty space: the hit is exact.
//
// A negative green marks relaxed cones (Policarpo and Oliveira 2007; `write_cones` with a map
// whose `relaxed()` is true), of ratio -green: they may hold surface, so after each cone step
// one bilinear read says whether the ray went under, and `binary_steps` halvings of that step
// find the crossing (relaxed cone stepping), as cone/mod.rs does for a map read from an image.


/// How far the walk lowers a cone's top: three times the largest rounding of a depth in [0, 1]
/// to f16 (2^-12), so that a cone built for f32 depths holds for the f16 surface.
const POMKIT_CONE_TOP_MARGIN: f32 = 0.000732421875;

/// The bilinear surface's depth at texel coordinates `p` (texel centres at half-integers), from
/// four mip-0 texels (cone/mod.rs `surface_depth`).
fn pomkit_surface_depth(heights: texture_2d<f32>, samp: sampler, map: PomkitMap, p: vec2<f32>) -> f32 {
    let s = p - 0.5;
    let f = floor(s);
    let w = s - f;
    let i = i32(f.x);
    let j = i32(f.y);
    let corners = pomkit_patch_depths(heights, samp, map, i, j);
    let d00 = corners.x;
    let d10 = corners.y;
    let d01 = corners.z;
    let d11 = corners.w;
    let top = d00 + (d10 - d00) * w.x;
    let bottom = d01 + (d11 - d01) * w.x;
    return top + (bottom - top) * w.y;
}

/// First t in [t0, t1] where the ray o + t d (texel x, y; depth z, going down) is at or below
/// the bilinear surface, by cone stepping on the cones in `pyramid`'s mip 0; t = -1 when none.
/// `binary_steps` halvings refine a crossing found after a relaxed cone's step.
fn pomkit_cone_first_hit(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, map: PomkitMap, o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32, binary_steps: u32) -> PomkitWalk {
    var state = PomkitWalkState(0u, vec2<i32>(-2147483647));
    let horizontal = length(d.xy);
    var t = t0;
    // A relaxed cone's step that went under the surface: [lo, hi] holds the crossing.
    var bracketed = false;
    var lo = 0.0;
    var hi = 0.0;
    for (var it = 0u; it < POMKIT_EXACT_MAX_STEPS; it++) {
        if t >= t1 {
            break;
        }
        let entered = pomkit_entered_cell(map, 0u, o, d, t, t1);
        if !entered.ok {
            break;
        }
        let c = entered.cell;
        let cone = textureLoad(pyramid, vec2<i32>(c.ix, c.iy), 0).rg;
        state.fetches += 1u;
        if cone.y == 0.0 {
            // No cone map here: exact's walk from this point on.
            let rest = pomkit_exact_first_hit(heights, pyramid, samp, map, o, d, t, t1);
            return PomkitWalk(rest.t, state.fetches + rest.fetches);
        }
        let relaxed = cone.y < 0.0;
        let top = cone.x - POMKIT_CONE_TOP_MARGIN;
        let z = o.z + d.z * t;
        if z < top {
            let step = (top - z) / (d.z + horizontal / abs(cone.y));
            let column = min((top - o.z) / d.z, entered.t_exit) - t;
            let next = min(t + max(step, column), t1);
            if relaxed && step > column {
                // The look after a relaxed step.
                state.fetches += 1u;
                let q = o + d * next;
                if pomkit_surface_depth(heights, samp, map, q.xy) <= q.z {
                    bracketed = true;
                    lo = t;
                    hi = next;
                    break;
                }
            }
            t = next;
            continue;
        }
        let h = pomkit_leaf_hit(heights, samp, map, &state, o, d, t, min(entered.t_exit, t1), c);
        if h >= 0.0 {
            return PomkitWalk(h, state.fetches);
        }
        t = entered.t_exit;
    }
    if !bracketed {
        return PomkitWalk(-1.0, state.fetches);
    }
    for (var k = 0u; k < binary_steps; k++) {
        let mid = 0.5 * (lo + hi);
        let q = o + d * mid;
        state.fetches += 1u;
        if pomkit_surface_depth(heights, samp, map, q.xy) <= q.z {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    return PomkitWalk(select(hi, 0.5 * (lo + hi), binary_steps > 0u), state.fetches);
}

// ===== module trace =====

// pomkit shader library: every tracing technique of docs/REFERENCES.md, the WGSL twins of
// pomkit_core's trace.rs (tests/library_rays.rs compares them ray by ray).
//
// Each technique is a function of the textures, the parameters, the entry UV and an entering
// unit direction in ray terms (from `pomkit_view_ray`), returning the hit UV, its depth and the
// fetches made. `pomkit_trace` picks one by `technique`: pass a constant or an `override` to
// compile only that technique's loop, or `params.technique` to choose at run time.


// ---------------------------------------------------------------------------------------------
// Shared pieces
// ---------------------------------------------------------------------------------------------

/// The point of the ray at a UV offset (trace.rs `hit_on_ray`); `head_on` is the depth used
/// when the ray has no UV extent.
fn pomkit_hit_on_ray(uv0: vec2<f32>, s: vec2<f32>, offset: vec2<f32>, head_on: f32, fetches: u32) -> PomkitHit {
    let len2 = dot(s, s);
    var z = head_on;
    if len2 > 1e-20 {
        z = dot(offset, s) / len2;
    }
    z = clamp(z, 0.0, 1.0);
    return PomkitHit(uv0 + s * z, z, fetches);
}

/// Intersection of the ray z = t with the line through (t0, d0) and (t1, d1).
fn pomkit_line_intersection(t0: f32, d0: f32, t1: f32, d1: f32) -> f32 {
    let a = d0 - t0;
    let b = t1 - d1;
    let denom = a + b;
    if denom > 0.0 {
        return t0 + (t1 - t0) * (a / denom);
    }
    return t1;
}

/// Tatarchuk 2006 eq. (1) with the erratum of docs/REFERENCES.md fixed: `n_max` samples at
/// grazing angles, `n_min` head-on.
fn pomkit_adaptive_samples(cos_view: f32, n_min: u32, n_max: u32) -> u32 {
    let c = clamp(cos_view, 0.0, 1.0);
    let n = f32(n_max) + (f32(n_min) - f32(n_max)) * c;
    return clamp(u32(round(n)), max(min(n_min, n_max), 1u), max(n_max, 1u));
}

/// The UV offset of the whole depth range along the ray: the ray is at depth z at uv0 + s * z.
fn pomkit_ray_extent(dir: vec3<f32>, depth_scale: f32) -> vec2<f32> {
    return dir.xy * (depth_scale / -dir.z);
}

/// How a marching technique reads the depth profile under its ray (pomkit_core trace.rs
/// `Profile`): the march runs over `tau` in [0, 1] along the straight ray to depth `t_end`, and
/// compares `(d + k * tau^2) / t_end` with `tau`. `pomkit_no_bend()` is the techniques' own flat
/// tangent plane (k = 0, t_end = 1: the same numbers as without it); silhouette.wesl bends the
/// ray under a curved surface. `exits` = 1 where the march ends at the ray's way out of the
/// relief, so reaching tau = 1 without a hit is a miss.
struct PomkitBend {
    /// Curvature along the ray: the curved surface lies c * t^2 below the tangent plane.
    c: f32,
    /// c * t_end^2.
    k: f32,
    /// The straight ray's depth at tau = 1.
    t_end: f32,
    exits: u32,
}

fn pomkit_no_bend() -> PomkitBend {
    return PomkitBend(0.0, 0.0, 1.0, 0u);
}

/// The depth a bent march compares with `tau` at `uv`.
fn pomkit_bent_depth(heights: texture_2d<f32>, samp: sampler, bend: PomkitBend, uv: vec2<f32>, tau: f32, lod: f32) -> f32 {
    return (pomkit_depth_at(heights, samp, uv, lod) + bend.k * tau * tau) / bend.t_end;
}

// ---------------------------------------------------------------------------------------------
// Parallax mapping with offset limiting (Kaneko 2001; Welsh 2004)
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_parallax(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    // Welsh drops the division by V.z: the shift never exceeds depth * depth_scale.
    let s = pomkit_ray_extent(dir, params.depth_scale);
    let d = pomkit_depth_at(heights, samp, uv0, lod);
    return pomkit_hit_on_ray(uv0, s, dir.xy * (d * params.depth_scale), d * -dir.z, 1u);
}

// ---------------------------------------------------------------------------------------------
// Iterative parallax (Lengyel, FGED 2, Listing 7.9, in the depth convention)
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_iterative(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    let s = pomkit_ray_extent(dir, params.depth_scale);
    let k = params.iterations;
    let step = dir.xy * (params.depth_scale / f32(k));
    var uv = uv0;
    var sum = 0.0;
    for (var i = 0u; i < k; i++) {
        let value = pomkit_parallax_at(heights, samp, uv, lod);
        sum += value;
        uv += step * value;
    }
    return pomkit_hit_on_ray(uv0, s, uv - uv0, sum / f32(k) * -dir.z, k);
}

// ---------------------------------------------------------------------------------------------
// Steep parallax (McGuire 2005). Erratum (docs/REFERENCES.md, Errata): the loop is capped; the
// plane at depth 1 is always at or below the surface and needs no fetch.
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_steep(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    return pomkit_march_steep(heights, samp, params, uv0, dir, lod, pomkit_no_bend());
}

fn pomkit_march_steep(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32, bend: PomkitBend) -> PomkitHit {
    let s = pomkit_ray_extent(dir, params.depth_scale) * bend.t_end;
    let n = params.samples;
    for (var i = 0u; i < n; i++) {
        let z = f32(i) / f32(n);
        if pomkit_bent_depth(heights, samp, bend, uv0 + s * z, z, lod) <= z {
            return PomkitHit(uv0 + s * z, z, i + 1u);
        }
    }
    return PomkitHit(uv0 + s, 1.0, n);
}

// ---------------------------------------------------------------------------------------------
// Parallax occlusion mapping, 2004 (Brawley & Tatarchuk, ShaderX3): 8 samples along the
// parallax vector with Brawley's perspective bias, line-line intersection. The article's
// ps_2_0 shader cannot branch, so all 8 samples are fetched.
//
// Brawley computes the parallax vector per vertex. Here it comes from the per-pixel view
// direction: tan(theta) is not linear across a triangle, and on large polygons the per-vertex
// version visibly bends the relief. The CPU twin does the same.
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_pom_classic(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    return pomkit_march_pom_classic(heights, samp, params, uv0, dir, lod, pomkit_no_bend());
}

fn pomkit_march_pom_classic(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32, bend: PomkitBend) -> PomkitHit {
    let cos = -dir.z;
    let pb = params.perspective_bias;
    let bias = max(pb + (1.0 - pb) * (2.0 * cos - 1.0), 0.0);
    let s = dir.xy * (params.depth_scale / -dir.z) * (bias * bend.t_end);
    var t_prev = 0.0;
    var d_prev = 0.0;
    var found = false;
    var z = 1.0;
    for (var i = 1u; i <= 8u; i++) {
        let t = f32(i) / 8.0;
        let d = pomkit_bent_depth(heights, samp, bend, uv0 + s * t, t, lod);
        if i == 1u {
            d_prev = d;
        }
        if !found && d <= t {
            z = pomkit_line_intersection(t_prev, max(d_prev, t_prev), t, d);
            found = true;
        }
        if !found {
            t_prev = t;
            d_prev = d;
        }
    }
    return PomkitHit(uv0 + s * z, z, 8u);
}

// ---------------------------------------------------------------------------------------------
// Parallax occlusion mapping (Zink 2008 / Tatarchuk 2006): adaptive sample count, early exit,
// piecewise-linear intersection, then optional secant refinement (as Unity HDRP).
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_pom(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    return pomkit_march_pom(heights, samp, params, uv0, dir, lod, pomkit_no_bend());
}

fn pomkit_march_pom(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32, bend: PomkitBend) -> PomkitHit {
    let s = pomkit_ray_extent(dir, params.depth_scale) * bend.t_end;
    let n = pomkit_adaptive_samples(-dir.z, params.min_samples, params.max_samples);
    let step = 1.0 / f32(n);
    var fetches = 1u;
    var a = vec2<f32>(0.0, pomkit_bent_depth(heights, samp, bend, uv0, 0.0, lod));
    if a.y <= 0.0 {
        return PomkitHit(uv0, 0.0, fetches);
    }
    var b = vec2<f32>(1.0, 1.0);
    var found = false;
    for (var i = 1u; i <= n; i++) {
        var t = f32(i) * step;
        if i == n {
            t = 1.0;
        }
        let d = pomkit_bent_depth(heights, samp, bend, uv0 + s * t, t, lod);
        fetches += 1u;
        if d <= t {
            b = vec2<f32>(t, d);
            found = true;
            break;
        }
        a = vec2<f32>(t, d);
    }
    if !found {
        return PomkitHit(uv0 + s, 1.0, fetches);
    }
    var z = pomkit_line_intersection(a.x, a.y, b.x, b.y);
    for (var i = 0u; i < params.refine; i++) {
        let d = pomkit_bent_depth(heights, samp, bend, uv0 + s * z, z, lod);
        fetches += 1u;
        if d > z {
            a = vec2<f32>(z, d);
        } else {
            b = vec2<f32>(z, d);
        }
        z = pomkit_line_intersection(a.x, a.y, b.x, b.y);
    }
    return PomkitHit(uv0 + s * z, z, fetches);
}

// ---------------------------------------------------------------------------------------------
// Relief mapping (Policarpo, Oliveira & Comba 2005): linear search, then binary refinement.
// ---------------------------------------------------------------------------------------------

fn pomkit_trace_relief(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    return pomkit_march_relief(heights, samp, params, uv0, dir, lod, pomkit_no_bend());
}

fn pomkit_march_relief(heights: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, lod: f32, bend: PomkitBend) -> PomkitHit {
    let s = pomkit_ray_extent(dir, params.depth_scale) * bend.t_end;
    let n = params.samples;
    var fetches = 0u;
    var lo = 0.0;
    var hi = 1.0;
    for (var i = 1u; i < n; i++) {
        let t = f32(i) / f32(n);
        fetches += 1u;
        if pomkit_bent_depth(heights, samp, bend, uv0 + s * t, t, lod) <= t {
            hi = t;
            break;
        }
        lo = t;
    }
    for (var i = 0u; i < params.binary_steps; i++) {
        let mid = 0.5 * (lo + hi);
        fetches += 1u;
        if pomkit_bent_depth(heights, samp, bend, uv0 + s * mid, mid, lod) <= mid {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    // Where the march ends at the ray's exit, a search that never found the surface is a miss.
    let missed = bend.exits != 0u && hi >= 1.0;
    var z = hi;
    if params.binary_steps > 0u && !missed {
        z = 0.5 * (lo + hi);
    }
    return PomkitHit(uv0 + s * z, z, fetches);
}

// ---------------------------------------------------------------------------------------------
// The exact tracer: the first intersection with the bilinear surface of the mip-0 texels
// (exact.wesl), found by a maximum-height pyramid walk. Needs the pyramid texture.
// ---------------------------------------------------------------------------------------------

/// With wrapping edges, texel coordinates relative to the entry point's tile keep f32 precise
/// for UVs far from 0 (the surface repeats, so the walk is the same). Clamped edges do not tile.
fn pomkit_entry_tile(uv: vec2<f32>, edges: u32) -> vec2<f32> {
    if edges == POMKIT_WRAP {
        return floor(uv);
    }
    return vec2<f32>(0.0);
}

fn pomkit_trace_exact(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>) -> PomkitHit {
    return pomkit_trace_walk(heights, pyramid, samp, params, uv0, dir, false);
}

/// Cone stepping (cone.wesl) on the cones in `pyramid`'s mip 0 (green), or exact's walk where
/// the pyramid has none: the exact hit either way.
fn pomkit_trace_cone(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>) -> PomkitHit {
    return pomkit_trace_walk(heights, pyramid, samp, params, uv0, dir, true);
}

fn pomkit_trace_walk(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, cones: bool) -> PomkitHit {
    let map = pomkit_map(heights, pyramid, params);
    let s = pomkit_ray_extent(dir, params.depth_scale);
    let tile = pomkit_entry_tile(uv0, map.edges);
    let o = vec3<f32>((uv0 - tile) * map.size, 0.0);
    let d = vec3<f32>(s * map.size, 1.0);
    var walk: PomkitWalk;
    if cones {
        walk = pomkit_cone_first_hit(heights, pyramid, samp, map, o, d, 0.0, 1.0, params.binary_steps);
    } else {
        walk = pomkit_exact_first_hit(heights, pyramid, samp, map, o, d, 0.0, 1.0);
    }
    var t = walk.t;
    if t < 0.0 {
        t = 1.0;
    }
    t = clamp(t, 0.0, 1.0);
    let p = o + d * t;
    return PomkitHit(tile + p.xy / map.size, t, walk.fetches);
}

/// `exact` (`pomkit_trace` with `POMKIT_EXACT`) on plane bounds per pyramid cell: the same hit
/// by `pomkit_planes_first_hit`'s walk, which reads fewer fetches where the relief slopes across
/// its cells (docs/ACCURACY.md, "Affine bounds per cell"). `planes` is pomkit_gpu's
/// `PlaneBounds` texture for this height map; `ray` comes from `pomkit_view_ray`, as for
/// `pomkit_trace`.
fn pomkit_trace_planes(heights: texture_2d<f32>, pyramid: texture_2d<f32>, planes: texture_2d<u32>, samp: sampler, params: PomkitParams, uv: vec2<f32>, ray: vec4<f32>) -> PomkitHit {
    if !(ray.w > 0.0) {
        return PomkitHit(uv, 0.0, 0u);
    }
    let tile = pomkit_entry_tile(uv, params.edges);
    let map = pomkit_map(heights, pyramid, params);
    let s = pomkit_ray_extent(ray.xyz, params.depth_scale);
    let o = vec3<f32>((uv - tile) * map.size, 0.0);
    let d = vec3<f32>(s * map.size, 1.0);
    let walk = pomkit_planes_first_hit(heights, pyramid, planes, samp, map, o, d, 0.0, 1.0);
    var t = walk.t;
    if t < 0.0 {
        t = 1.0;
    }
    t = clamp(t, 0.0, 1.0);
    let p = o + d * t;
    return PomkitHit(tile + p.xy / map.size, t, walk.fetches);
}

// ---------------------------------------------------------------------------------------------
// Dispatch
// ---------------------------------------------------------------------------------------------

/// Traces the view ray `ray` (from `pomkit_view_ray`) entering at `uv` with the technique
/// `technique` (`POMKIT_*`), reading heights at mip `lod` (`pomkit_mip_level`; `exact` always
/// reads mip 0). `pyramid` is read by `exact` only; other techniques accept any texture there.
/// A ray that does not enter (w = 0), and `flat` and `normal`, hit at `uv`, depth 0.
///
/// Where the edges wrap, `uv` is first reduced to its tile (exact in f32) and the tile added
/// back to the hit, as pomkit_core does: UVs many tiles from the origin trace as well as small
/// ones.
fn pomkit_trace(technique: u32, heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv: vec2<f32>, ray: vec4<f32>, lod: f32) -> PomkitHit {
    if !(ray.w > 0.0) {
        return PomkitHit(uv, 0.0, 0u);
    }
    let tile = pomkit_entry_tile(uv, params.edges);
    var hit = pomkit_trace_in_tile(technique, heights, pyramid, samp, params, uv - tile, ray.xyz, lod);
    hit.uv += tile;
    return hit;
}

fn pomkit_trace_in_tile(technique: u32, heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv: vec2<f32>, dir: vec3<f32>, lod: f32) -> PomkitHit {
    switch technique {
        case POMKIT_PARALLAX: {
            return pomkit_trace_parallax(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_ITERATIVE: {
            return pomkit_trace_iterative(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_STEEP: {
            return pomkit_trace_steep(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_POM_CLASSIC: {
            return pomkit_trace_pom_classic(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_POM: {
            return pomkit_trace_pom(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_RELIEF: {
            return pomkit_trace_relief(heights, samp, params, uv, dir, lod);
        }
        case POMKIT_EXACT: {
            return pomkit_trace_exact(heights, pyramid, samp, params, uv, dir);
        }
        case POMKIT_CONE: {
            return pomkit_trace_cone(heights, pyramid, samp, params, uv, dir);
        }
        default: {
            return PomkitHit(uv, 0.0, 0u);
        }
    }
}

/// The hit lifted onto the height surface sampled at mip `lod`: its depth becomes the smaller
/// of its own and the surface's at its UV (one fetch). `pomkit_shadow` lifts its receiver
/// itself; lift the hit you shade when the technique can stop below the surface (steep
/// parallax stops up to one layer deep), so that its depth output and shading sit on the
/// surface too.
fn pomkit_lift_to_surface(heights: texture_2d<f32>, samp: sampler, hit: PomkitHit, lod: f32) -> PomkitHit {
    let d = pomkit_depth_at(heights, samp, hit.uv, lod);
    return PomkitHit(hit.uv, min(hit.depth, d), hit.fetches + 1u);
}

/// The receiver pomkit's own renderers shade and shadow from (pomkit-cpu and `render.wgsl`
/// agree on it): `steep`'s hit lifted with `pomkit_lift_to_surface`, other techniques' hits
/// unchanged.
fn pomkit_receiver(technique: u32, heights: texture_2d<f32>, samp: sampler, hit: PomkitHit, lod: f32) -> PomkitHit {
    if technique != POMKIT_STEEP {
        return hit;
    }
    return pomkit_lift_to_surface(heights, samp, hit, lod);
}

// ===== module silhouette =====

// pomkit shader library: silhouettes, the twin of pomkit_core silhouette.rs (Oliveira &
// Policarpo 2005; docs/REFERENCES.md). The view ray is traced under the curved surface the
// mesh's normals describe, and a ray that comes back out of the relief without meeting it is
// reported as `left`: discard the fragment, and the mesh's outline becomes the displaced one.
//
// Per vertex, the host supplies the curvature form K = L * II in the vertex's (T, B) basis
// (pomkit_core::silhouette::vertex_curvature; pomkit_gpu's GpuMesh carries it). Per fragment,
// `pomkit_view_curvature` turns it and the view direction into c, the curvature along the ray:
// the curved surface lies c * t^2 below the tangent plane where the straight ray is at depth t.
// `pomkit_trace_curved` then marches the bent ray t - c t^2 with the technique's own loop.


/// The largest |c| used (pomkit_core `MAX_CURVATURE`).
const POMKIT_MAX_CURVATURE: f32 = 1e6;
/// The most chords `exact` bends its ray into, and the sag (in depth units) it aims for.
const POMKIT_MAX_CHORDS: u32 = 16u;
const POMKIT_CHORD_SAG: f32 = 1e-3;

/// A view trace under a curved surface.
struct PomkitCurvedHit {
    /// The hit: UV, depth below the curved surface (shade and shadow with it), fetches.
    hit: PomkitHit,
    /// How deep the hit lies along the straight view ray, below the tangent plane at the entry
    /// point, in depth units: pass it to `pomkit_hit_position` for pixel depth offset.
    ray_depth: f32,
    /// The ray left the relief without meeting it (or left a clamped chart): discard.
    left: bool,
}

/// The bent march for curvature `c` along the ray (pomkit_core `Bend::new`).
fn pomkit_bend(c_in: f32) -> PomkitBend {
    var c = 0.0;
    // NaN and infinities count as 0 (flat), as on the CPU.
    if abs(c_in) <= 3.4e38 {
        c = clamp(c_in, -POMKIT_MAX_CURVATURE, POMKIT_MAX_CURVATURE);
    }
    if 4.0 * c <= 1.0 {
        let t_end = 2.0 / (1.0 + sqrt(1.0 - 4.0 * c));
        return PomkitBend(c, c * t_end * t_end, t_end, 0u);
    }
    let t_end = 1.0 / c;
    return PomkitBend(c, t_end, t_end, 1u);
}

/// The curvature along a view ray: `view_ts` is the eye-to-point vector in the tangent frame
/// (T, B, N components), `curvature` the interpolated K = (K_tt, K_tb, K_bb). 0 for rays that
/// do not enter.
fn pomkit_view_curvature(view_ts: vec3<f32>, curvature: vec3<f32>, depth_scale: f32) -> f32 {
    let l2 = dot(view_ts, view_ts);
    if !(l2 > 0.0) {
        return 0.0;
    }
    let v = view_ts * inverseSqrt(l2);
    if !(v.z < 0.0) {
        return 0.0;
    }
    let vn = max(-v.z, POMKIT_MIN_COS);
    let w = v.xy / vn;
    let q = curvature.x * w.x * w.x + 2.0 * curvature.y * w.x * w.y + curvature.z * w.y * w.y;
    let c = 0.5 * depth_scale * q;
    if !(abs(c) <= 3.4e38) {
        return 0.0;
    }
    return clamp(c, -POMKIT_MAX_CURVATURE, POMKIT_MAX_CURVATURE);
}

/// `exact` along the bent ray: the parabola z = t - c t^2 as chords, each walked exactly (the
/// chords lie inside the parabola by at most |c| dt^2 / 4). The hit's `depth` and `ray_depth`
/// are its straight depth; `left` when the ray left without a hit.
fn pomkit_exact_curved(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv0: vec2<f32>, dir: vec3<f32>, bend: PomkitBend) -> PomkitCurvedHit {
    let map = pomkit_map(heights, pyramid, params);
    let s = pomkit_ray_extent(dir, params.depth_scale);
    let o = uv0 * map.size;
    let dxy = s * map.size;
    let c = bend.c;
    let t_end = bend.t_end;
    let chords = u32(clamp(ceil(sqrt(abs(c) * t_end * t_end / (4.0 * POMKIT_CHORD_SAG))), 1.0, f32(POMKIT_MAX_CHORDS)));
    var fetches = 0u;
    for (var j = 0u; j < chords; j++) {
        let ta = t_end * f32(j) / f32(chords);
        var tb = t_end * f32(j + 1u) / f32(chords);
        if j + 1u == chords {
            tb = t_end;
        }
        let za = ta - c * ta * ta;
        let zb = tb - c * tb * tb;
        let slope = (zb - za) / (tb - ta);
        let walk = pomkit_exact_first_hit(heights, pyramid, samp, map, vec3<f32>(o, za - slope * ta), vec3<f32>(dxy, slope), ta, tb);
        fetches += walk.fetches;
        if walk.t >= 0.0 {
            return PomkitCurvedHit(PomkitHit((o + dxy * walk.t) / map.size, walk.t, fetches), walk.t, false);
        }
    }
    return PomkitCurvedHit(PomkitHit(uv0 + s * t_end, t_end, fetches), t_end, bend.exits != 0u);
}

/// `pomkit_trace` under a surface of curvature `c` along the ray (`pomkit_view_curvature`;
/// 0 gives `pomkit_trace`'s hit). The marching techniques march the bent ray, `exact` walks it
/// as chords, `parallax` and `iterative` keep their offset and report `left` when it lies
/// beyond the ray's exit. With clamped edges a ray entering inside the unit UV square whose
/// hit lies outside it has left the chart.
fn pomkit_trace_curved(technique: u32, heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv: vec2<f32>, ray: vec4<f32>, lod: f32, c: f32) -> PomkitCurvedHit {
    let none = PomkitCurvedHit(PomkitHit(uv, 0.0, 0u), 0.0, false);
    if !(ray.w > 0.0) {
        return none;
    }
    let bend = pomkit_bend(c);
    let tile = pomkit_entry_tile(uv, params.edges);
    let uv0 = uv - tile;
    let dir = ray.xyz;
    var hit = PomkitHit(uv0, 0.0, 0u);
    var t = 0.0;
    var found = true;
    switch technique {
        case POMKIT_PARALLAX: {
            hit = pomkit_trace_parallax(heights, samp, params, uv0, dir, lod);
            t = hit.depth;
            found = t - bend.c * t * t >= 0.0;
        }
        case POMKIT_ITERATIVE: {
            hit = pomkit_trace_iterative(heights, samp, params, uv0, dir, lod);
            t = hit.depth;
            found = t - bend.c * t * t >= 0.0;
        }
        case POMKIT_STEEP, POMKIT_POM_CLASSIC, POMKIT_POM, POMKIT_RELIEF: {
            switch technique {
                case POMKIT_STEEP: {
                    hit = pomkit_march_steep(heights, samp, params, uv0, dir, lod, bend);
                }
                case POMKIT_POM_CLASSIC: {
                    hit = pomkit_march_pom_classic(heights, samp, params, uv0, dir, lod, bend);
                }
                case POMKIT_POM: {
                    hit = pomkit_march_pom(heights, samp, params, uv0, dir, lod, bend);
                }
                default: {
                    hit = pomkit_march_relief(heights, samp, params, uv0, dir, lod, bend);
                }
            }
            t = hit.depth * bend.t_end;
            found = !(bend.exits != 0u && hit.depth >= 1.0);
        }
        case POMKIT_CONE: {
            if bend.c == 0.0 {
                // A flat surface: the cones hold for this straight ray.
                hit = pomkit_trace_cone(heights, pyramid, samp, params, uv0, dir);
                t = hit.depth;
                found = true;
            } else {
                // The cones hold for straight rays only: walk the bent one as exact does.
                let r = pomkit_exact_curved(heights, pyramid, samp, params, uv0, dir, bend);
                hit = r.hit;
                t = r.ray_depth;
                found = !r.left;
            }
        }
        case POMKIT_EXACT: {
            let r = pomkit_exact_curved(heights, pyramid, samp, params, uv0, dir, bend);
            hit = r.hit;
            t = r.ray_depth;
            found = !r.left;
        }
        default: {
            return none;
        }
    }
    let inside_entry = all(uv0 >= vec2<f32>(0.0)) && all(uv0 <= vec2<f32>(1.0));
    let inside_hit = all(hit.uv >= vec2<f32>(0.0)) && all(hit.uv <= vec2<f32>(1.0));
    let off_chart = params.edges == POMKIT_CLAMP && inside_entry && !inside_hit;
    hit.uv += tile;
    hit.depth = clamp(t - bend.c * t * t, 0.0, 1.0);
    return PomkitCurvedHit(hit, max(t, 0.0), !found || off_chart);
}

// ===== module shadow =====

// pomkit shader library: self-shadowing of the traced point (Brawley & Tatarchuk 2004; McGuire
// 2005; Tatarchuk 2006 section 3.2; docs/REFERENCES.md), the twin of pomkit_core shadow.rs.
//
// Hard and soft shadows march from the traced point toward the light with pom's adaptive
// sample count; exact shadows run the exact walk (exact.wesl) and need the pyramid; depth
// shadows trace nothing: 1 - depth (McGuire 2005's fur and grass, after Lengyel et al. 2001).


/// Visibility of the light from the traced point (`uv`, `depth`), for `params.shadow_mode`.
/// `light` is the direction toward the light in ray terms (`pomkit_light_ray` of the
/// tangent-space light vector; any length, z > 0 above the surface). Samples are read at mip
/// `lod`, as the trace's. A zero or non-finite `light` gives 1; a light below the tangent plane
/// gives 0 with no fetch (Tatarchuk 2006 skips the trace there; test the geometric N.L yourself
/// to skip the call). `POMKIT_SHADOW_DEPTH` gives `1 - depth` with no fetch. Hard, soft and
/// exact shadows lift the receiver onto the surface first (one fetch), so any technique's hit
/// may be passed as it is.
fn pomkit_shadow(heights: texture_2d<f32>, pyramid: texture_2d<f32>, samp: sampler, params: PomkitParams, uv_in: vec2<f32>, depth_in: f32, light: vec3<f32>, lod: f32) -> PomkitShadow {
    let l = pomkit_unit(light);
    if !(dot(l, l) > 0.0) {
        return PomkitShadow(1.0, 0u);
    }
    if l.z <= 0.0 {
        return PomkitShadow(0.0, 0u);
    }
    let receiver_depth = clamp(depth_in, 0.0, 1.0);
    let mode = params.shadow_mode;
    if mode == POMKIT_SHADOW_NONE || receiver_depth <= 0.0 {
        // Nothing lies above the polygon's surface: a point on it is never self-shadowed.
        return PomkitShadow(1.0, 0u);
    }
    if mode == POMKIT_SHADOW_DEPTH {
        // No shadow ray: darker the deeper the point, from lit tips to a black skin.
        return PomkitShadow(1.0 - receiver_depth, 0u);
    }
    // The point in its own tile where the surface repeats (a visibility needs no tile back).
    let uv = uv_in - pomkit_entry_tile(uv_in, params.edges);
    // UV offset per unit of depth climbed toward the light.
    let s = l.xy * (params.depth_scale / max(l.z, POMKIT_MIN_COS));
    if mode == POMKIT_SHADOW_EXACT {
        let map = pomkit_map(heights, pyramid, params);
        // The receiver may lie below the exact surface (pom's linear segments cut under the
        // bilinear surface; coarser mips differ from mip 0): an exact ray from there shadows
        // itself in speckles. Lift it onto the exact surface (one fetch), then a hair above it
        // (1e-5 of the depth range, as the CPU).
        let on_surface = min(receiver_depth, pomkit_depth_at(heights, samp, uv, 0.0));
        if on_surface <= 0.0 {
            // Lifted onto the polygon's surface, which nothing rises above (a walk from there
            // would stop at once on the surface it starts on).
            return PomkitShadow(1.0, 1u);
        }
        let eps = 1e-5;
        let z0 = max(on_surface - eps, 0.0);
        let o = vec3<f32>(uv * map.size, z0);
        let d = vec3<f32>(s * map.size, -1.0);
        let walk = pomkit_exact_first_hit(heights, pyramid, samp, map, o, d, min(eps, z0), z0);
        return PomkitShadow(select(1.0, 0.0, walk.t >= 0.0), walk.fetches + 1u);
    }
    // Hard and soft: the receiver lifted onto the surface the march reads (one fetch). A hit
    // below it (steep parallax stops up to one layer deep, pom's linear segments cut under
    // convex slopes, the exact hit lies on mip 0 while the march reads mip `lod`) would start
    // the ray inside the relief and shadow itself in dashes along the tops.
    let depth = min(receiver_depth, pomkit_depth_at(heights, samp, uv, lod));
    if depth <= 0.0 {
        return PomkitShadow(1.0, 1u);
    }
    // Samples at climbed depths t_i = depth * i / n, i = 1 .. n - 1 (the last point lies on the
    // polygon's surface, which nothing rises above).
    let n = pomkit_adaptive_samples(l.z, params.min_samples, params.max_samples);
    let soft = mode == POMKIT_SHADOW_SOFT;
    let rho = max(params.softness, 1e-4);
    // The light's elevation above the tangent plane, and the horizontal distance (in depth
    // units) covered per unit climbed.
    let tan_theta = sqrt(max(1.0 - l.z * l.z, 0.0)) / l.z;
    let light_elevation = atan2(1.0, tan_theta);
    var fetches = 1u;
    // The steepest rise of the profile above the receiver per unit climbed: the visibility falls
    // as a sample's elevation seen from the receiver, atan2(depth - d, t * tan_theta), rises,
    // and that rises with the slope (depth - d) / t, so the darkest sample is the steepest and
    // one arctangent per ray serves (pomkit_core shadow.rs `soft_visibility`).
    var slope = -POMKIT_BIG;
    for (var i = 1u; i < n; i++) {
        let t = depth * f32(i) / f32(n);
        let d = pomkit_depth_at(heights, samp, uv + s * t, lod);
        fetches += 1u;
        if soft {
            slope = max(slope, (depth - d) / t);
        } else if d < depth - t - 1e-5 {
            return PomkitShadow(0.0, fetches);
        }
    }
    var visibility = 1.0;
    if soft && n > 1u {
        // The blocker's elevation against the light's: nearer blockers subtend more and darken
        // more.
        let elevation = atan2(slope, tan_theta);
        visibility = clamp(0.5 - (elevation - light_elevation) / (2.0 * rho), 0.0, 1.0);
    }
    return PomkitShadow(visibility, fetches);
}

// ===== module depth =====

// pomkit shader library: pixel depth offset. A traced pixel writes the depth of the point it
// hit, below the polygon, instead of the polygon's own depth: parallax-mapped objects then meet
// other geometry where displaced geometry would, and shadow maps see the relief.
//
// Writing `@builtin(frag_depth)` turns off early depth testing for the pipeline, so hosts keep
// a separate pipeline (or entry point) for materials that use it.

/// World position of the traced point: `depth` (in [0, 1], from `PomkitHit`) below the surface
/// point `world`, along the view ray. `to_eye` is the unit vector from `world` toward the eye,
/// `normal` the unit surface normal, `uv_scale` the world length of one UV unit along u and v
/// (as for `pomkit_view_ray`).
fn pomkit_hit_position(world: vec3<f32>, to_eye: vec3<f32>, normal: vec3<f32>, depth: f32, depth_scale: f32, uv_scale: vec2<f32>) -> vec3<f32> {
    let l_world = sqrt(max(uv_scale.x * uv_scale.y, 0.0));
    let down = depth * depth_scale * l_world;
    let cos = max(dot(to_eye, normal), 1e-3);
    return world - to_eye * (down / cos);
}

/// The depth-buffer value of the world point `p` under `view_proj`, never nearer than the
/// polygon's own `fragment_depth` (`@builtin(position).z`): with `reverse_z` (near = 1, far = 0,
/// compare `Greater`) nearer means larger. Returns `fragment_depth` where `p` is behind the eye.
fn pomkit_pixel_depth(p: vec3<f32>, view_proj: mat4x4<f32>, fragment_depth: f32, reverse_z: bool) -> f32 {
    let c = view_proj * vec4<f32>(p, 1.0);
    if !(c.w > 0.0) {
        return fragment_depth;
    }
    let z = c.z / c.w;
    if reverse_z {
        return clamp(min(z, fragment_depth), 0.0, 1.0);
    }
    return clamp(max(z, fragment_depth), 0.0, 1.0);
}
