// uses: pomkit.wgsl
//
// pomkit's own material: Blinn-Phong shading with up to four lights, AOVs and the LOD tint
// view, drawn with the shader library (crates/pomkit-gpu/shaders/pomkit/, docs/EMBEDDING.md)
// for the tracing, the self-shadows, the LOD fade and the pixel depth offset. The library is
// composed in front of this file (`pomkit_gpu::library::compose`); this file is one user of it,
// as a host renderer's shader would be.
//
// The technique is a pipeline-overridable constant, so each pipeline variant compiles only its
// own loop (wgpu examples' style: `override` constants before any shader composer).

/// Which technique this pipeline runs (the library's `POMKIT_*` values).
override TECHNIQUE: u32 = 6u;
/// Reverse-Z depth (near = 1, far = 0, compare `Greater`): pixel depth offset moves depths
/// toward 0 instead of 1.
override REVERSE_Z: bool = false;

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
    // The library's tracing parameters (technique, shadow mode, samples, depth scale, ...).
    params: PomkitParams,
    base_color: vec4<f32>,
    specular: f32,
    shininess: f32,
    has_height: u32,
    has_normals: u32,
    albedo_size: vec2<f32>,
    albedo_max_level: f32,
    pixel_depth_offset: u32,
    // 1 when `planes` holds the height map's plane bounds: `exact` then walks on them.
    plane_bounds: u32,
}

struct Object {
    model: mat4x4<f32>,
    // Cofactor matrix of the model's linear part (normals), sign-corrected for mirrors; its
    // last element is the sign of the determinant (-1 for a mirror).
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
// The plane bounds per pyramid cell (pomkit_gpu::planes::PlaneBounds), or a 1x1 texture never
// read when `material.plane_bounds` is 0.
@group(1) @binding(6) var planes: texture_2d<u32>;
@group(2) @binding(0) var<uniform> object: Object;

// ---------------------------------------------------------------------------------------------
// Vertex stage: world position, tangent frame, tangent-space view and light vectors
// ---------------------------------------------------------------------------------------------

// pomkit's own vertex layout (`GpuMesh`).
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    // World length of one UV unit along u and v (mesh.rs `uv_scale`).
    @location(4) uv_scale: vec2<f32>,
    // Depth of the vertex below the polygon (non-zero only for `displaced` geometry).
    @location(5) depth: f32,
    // The surface's curvature form K = L * II in the vertex's (T, B) basis, for silhouettes
    // (pomkit_core::silhouette::vertex_curvature); zero where the mesh carries none.
    @location(6) curvature: vec3<f32>,
}

// A host's vertices with a UV scale and a displacement depth but no curvature.
struct VertexDepth {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: vec2<f32>,
    @location(5) depth: f32,
}

// A host's vertices with a UV scale and a curvature but no displacement depth.
struct VertexScaledCurved {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: vec2<f32>,
    @location(6) curvature: vec3<f32>,
}

// A host's vertices (`VertexLayout`): no UV scale, which the fragment stage then derives from
// screen-space derivatives (exact on flat triangles), and no displacement depth.
struct VertexBasic {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
}

// A host's vertices with a UV scale but no displacement depth.
struct VertexScaled {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) uv_scale: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
    // 0 when the vertices carry none (`vs_basic`).
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
    // K = L * II, interpolated (rotation and uniform scale leave it unchanged).
    @location(11) curvature: vec3<f32>,
}

fn light_vector(i: u32, world: vec3<f32>) -> vec3<f32> {
    let l = frame.lights[i].vector;
    if l.w > 0.5 {
        return l.xyz - world;
    }
    return l.xyz;
}

fn vertex(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let world = (object.model * vec4<f32>(v.position, 1.0)).xyz;
    let m3 = mat3x3<f32>(object.model[0].xyz, object.model[1].xyz, object.model[2].xyz);
    let nm3 = mat3x3<f32>(object.normal_matrix[0].xyz, object.normal_matrix[1].xyz, object.normal_matrix[2].xyz);
    let normal = pomkit_safe_normalize(nm3 * v.normal, v.normal);
    let t_world = m3 * v.tangent.xyz;
    // A mirror maps the bitangent to minus the cross product of the mapped normal and tangent:
    // the handedness flips with the determinant's sign.
    let f = pomkit_tangent_frame(normal, vec4<f32>(t_world, v.tangent.w * object.normal_matrix[3][3]));
    out.clip = frame.view_proj * vec4<f32>(world, 1.0);
    out.world = world;
    out.normal = f.n;
    out.tangent = vec4<f32>(f.t, f.sign);
    out.uv = v.uv;
    // The model's stretch along T and B changes the world length of a UV unit.
    let b_obj = cross(v.normal, v.tangent.xyz) * f.sign;
    let stretch = vec2<f32>(
        length(m3 * pomkit_safe_normalize(v.tangent.xyz, f.t)),
        length(m3 * pomkit_safe_normalize(b_obj, f.b)),
    );
    out.uv_scale = v.uv_scale * stretch;
    out.depth = v.depth;
    out.curvature = v.curvature;
    out.view_ts = pomkit_to_tangent(f, world - frame.eye.xyz);
    var ls = array<vec3<f32>, 4>();
    for (var i = 0u; i < MAX_LIGHTS; i++) {
        ls[i] = pomkit_to_tangent(f, light_vector(i, world));
    }
    out.light_ts0 = ls[0];
    out.light_ts1 = ls[1];
    out.light_ts2 = ls[2];
    out.light_ts3 = ls[3];
    return out;
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    return vertex(v);
}

@vertex
fn vs_depth(v: VertexDepth) -> VertexOut {
    return vertex(VertexIn(v.position, v.normal, v.tangent, v.uv, v.uv_scale, v.depth, vec3<f32>(0.0)));
}

@vertex
fn vs_basic(v: VertexBasic) -> VertexOut {
    return vertex(VertexIn(v.position, v.normal, v.tangent, v.uv, vec2<f32>(0.0), 0.0, vec3<f32>(0.0)));
}

@vertex
fn vs_scaled(v: VertexScaled) -> VertexOut {
    return vertex(VertexIn(v.position, v.normal, v.tangent, v.uv, v.uv_scale, 0.0, vec3<f32>(0.0)));
}

@vertex
fn vs_scaled_curved(v: VertexScaledCurved) -> VertexOut {
    return vertex(VertexIn(v.position, v.normal, v.tangent, v.uv, v.uv_scale, 0.0, v.curvature));
}

// ---------------------------------------------------------------------------------------------
// Fragment stage: trace, shade (Blinn-Phong with the normal map), shadows, LOD fade, AOVs
// ---------------------------------------------------------------------------------------------

struct Shaded {
    color: vec3<f32>,
    vis: f32,
    fetches: u32,
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

fn lit(in: VertexOut, f: PomkitFrame, to_eye: vec3<f32>, uv_scale: vec2<f32>, hit: PomkitHit, with_shadows: bool, lod: f32, albedo_lod: f32) -> Shaded {
    let uv = hit.uv;
    let base = textureSampleLevel(albedo, samp, uv, albedo_lod).rgb * material.base_color.rgb;
    var shading_n = f.n;
    if material.has_normals != 0u && TECHNIQUE != POMKIT_FLAT {
        let nm = pomkit_safe_normalize(textureSampleLevel(normals, samp, uv, 0.0).xyz, vec3<f32>(0.0, 0.0, 1.0));
        shading_n = pomkit_safe_normalize(f.t * nm.x + f.b * nm.y + f.n * nm.z, f.n);
    }
    var c = frame.ambient.rgb * base;
    var first_vis = 1.0;
    var fetches = 0u;
    for (var i = 0u; i < min(frame.light_count, MAX_LIGHTS); i++) {
        let light = frame.lights[i];
        var l = pomkit_safe_normalize(light.vector.xyz, vec3<f32>(0.0, 1.0, 0.0));
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
        if with_shadows && n_dot_l > 0.0 && material.params.shadow_mode != POMKIT_SHADOW_NONE && material.has_height != 0u {
            let s = pomkit_shadow(heights, pyramid, samp, material.params, uv, hit.depth, pomkit_light_ray(light_ts(in, i), uv_scale), lod);
            vis = s.visibility;
            fetches += s.fetches;
        }
        if i == 0u {
            first_vis = vis;
        }
        let diffuse = max(dot(shading_n, l), 0.0);
        let h = pomkit_safe_normalize(l + to_eye, shading_n);
        var spec = 0.0;
        if diffuse > 0.0 {
            spec = material.specular * pow(max(dot(shading_n, h), 0.0), material.shininess);
        }
        c += (base * diffuse + vec3<f32>(spec)) * radiance * vis;
    }
    return Shaded(c, first_vis, fetches);
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
    // A silhouette ray that left the relief: the entry point discards the fragment.
    left: bool,
}

fn displaces() -> bool {
    return TECHNIQUE != POMKIT_FLAT && TECHNIQUE != POMKIT_NORMAL;
}

/// Screen-space derivatives, taken in uniform control flow at the top of the fragment stage
/// (HLSL's tex2Dgrad in the published POM shaders): the mip levels and, for host vertices, the UV scale come from them.
struct Gradients {
    duv_dx: vec2<f32>,
    duv_dy: vec2<f32>,
    dworld_dx: vec3<f32>,
    dworld_dy: vec3<f32>,
}

fn gradients(in: VertexOut) -> Gradients {
    return Gradients(dpdx(in.uv), dpdy(in.uv), dpdx(in.world), dpdy(in.world));
}

/// `silhouette` is a constant at each entry point: without it the curved trace is compiled out.
fn shade(in: VertexOut, g: Gradients, silhouette: bool) -> Shading {
    let f = pomkit_tangent_frame(in.normal, in.tangent);
    let to_eye = pomkit_safe_normalize(frame.eye.xyz - in.world, f.n);
    var uv_scale = in.uv_scale;
    if !(uv_scale.x > 0.0 && uv_scale.y > 0.0) {
        uv_scale = pomkit_uv_scale(g.dworld_dx, g.dworld_dy, g.duv_dx, g.duv_dy);
    }
    // Mip level of the height map from the quad's UV gradients, fixed before any loop.
    var weight = 0.0;
    var lod = 0.0;
    if material.has_height != 0u {
        lod = pomkit_mip_level(heights, g.duv_dx, g.duv_dy);
        weight = pomkit_lod_weight(lod, material.params.lod_threshold);
    }
    var hit = PomkitHit(in.uv, in.depth, 0u);
    if in.depth > 0.0 && material.has_height != 0u {
        // Displaced geometry: a triangle is a chord of the surface; where it passes under it
        // (over a ridge) the shadow rays would start inside the relief, so the receiver is
        // lifted onto the surface (one fetch), as pomkit-cpu does.
        hit = PomkitHit(in.uv, min(in.depth, pomkit_depth_at(heights, samp, in.uv, 0.0)), 1u);
    }
    // How deep the hit lies along the view ray (pixel depth offset): its depth, except under a
    // curved surface.
    var ray_depth = in.depth;
    var left = false;
    // With silhouettes the ray is traced even where the LOD fade shows normal mapping only: the
    // outline is decided there too (pomkit-cpu does the same).
    if material.has_height != 0u && (weight > 0.0 || silhouette) && displaces() {
        let ray = pomkit_view_ray(in.view_ts, uv_scale);
        if silhouette {
            let c = pomkit_view_curvature(in.view_ts, in.curvature, material.params.depth_scale);
            let curved = pomkit_trace_curved(TECHNIQUE, heights, pyramid, samp, material.params, in.uv, ray, lod, c);
            hit = curved.hit;
            ray_depth = curved.ray_depth;
            left = curved.left;
        } else if TECHNIQUE == POMKIT_EXACT && material.plane_bounds != 0u {
            hit = pomkit_trace_planes(heights, pyramid, planes, samp, material.params, in.uv, ray);
            ray_depth = hit.depth;
        } else {
            hit = pomkit_trace(TECHNIQUE, heights, pyramid, samp, material.params, in.uv, ray, lod);
            ray_depth = hit.depth;
        }
        let traced = hit.depth;
        hit = pomkit_receiver(TECHNIQUE, heights, samp, hit, lod);
        // The receiver's lift moves the point up the view ray as well.
        if silhouette {
            ray_depth -= traced - hit.depth;
        } else {
            ray_depth = hit.depth;
        }
    }
    let albedo_lod = pomkit_mip_level_sized(g.duv_dx, g.duv_dy, material.albedo_size, material.albedo_max_level);
    let shadows = displaces() || (material.has_height != 0u && TECHNIQUE != POMKIT_FLAT);
    let full = lit(in, f, to_eye, uv_scale, hit, shadows && weight > 0.0, lod, albedo_lod);
    var color = full.color;
    if weight < 1.0 && material.has_height != 0u {
        let simple = lit(in, f, to_eye, uv_scale, PomkitHit(in.uv, in.depth, 0u), false, lod, albedo_lod);
        color = mix(simple.color, full.color, weight);
    }
    if frame.lod_tint != 0u && material.has_height != 0u {
        let tint = mix(vec3<f32>(1.0, 0.25, 0.2), vec3<f32>(0.25, 1.0, 0.3), weight);
        color = color * 0.5 + tint * 0.5 * max(length(color), 0.05);
    }
    var z = in.clip.z;
    // Pixel depth offset: move the depth to the traced point along the view ray.
    if material.pixel_depth_offset != 0u && ray_depth > 0.0 && weight > 0.0 && displaces() {
        let p = pomkit_hit_position(in.world, to_eye, f.n, ray_depth, material.params.depth_scale, uv_scale);
        z = pomkit_pixel_depth(p, frame.depth_proj, in.clip.z, REVERSE_Z);
    }
    var out: FragmentOut;
    out.color = vec4<f32>(color, 1.0);
    out.aov0 = vec4<f32>(hit.uv, hit.depth, full.vis);
    out.aov1 = vec4<f32>(f32(hit.fetches + full.fetches), lod, 1.0, 0.0);
    return Shading(out, z, left);
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    return shade(in, gradients(in), false).out;
}

/// Materials with silhouettes: a ray that leaves the relief discards the fragment (a separate
/// entry point, so that pipelines without silhouettes have no `discard`, which can turn off
/// early depth testing).
@fragment
fn fs_silhouette(in: VertexOut) -> FragmentOut {
    let s = shade(in, gradients(in), true);
    if s.left {
        discard;
    }
    return s.out;
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
    let s = shade(in, gradients(in), false);
    return FragmentOutDepth(s.out.color, s.out.aov0, s.out.aov1, s.z);
}

/// Silhouettes with pixel depth offset: discarded fragments write no depth.
@fragment
fn fs_silhouette_depth(in: VertexOut) -> FragmentOutDepth {
    let s = shade(in, gradients(in), true);
    if s.left {
        discard;
    }
    return FragmentOutDepth(s.out.color, s.out.aov0, s.out.aov1, s.z);
}
