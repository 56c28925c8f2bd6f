// uses: pomkit.wgsl
//
// pomkit_gpu::probe: the shader library's `pomkit_trace` and `pomkit_shadow`, one invocation per
// ray, for comparing them with pomkit_core ray by ray (tests/library_rays.rs) and for measuring
// them. Composed behind the plain-WGSL library (pomkit_gpu::library::compose).
//
// Directions come in pomkit_core's ray terms (u, v, depth), as `Ray::dir` and `shadow`'s light.
// They are turned back into tangent space (T, B, N) = (x, -y, z) and set up by the library's own
// `pomkit_view_ray` / `pomkit_light_ray` (UV scale 1), so those functions are on trial too.

/// One ray: a = (u, v, lod, receiver depth), b = (direction in ray terms, curvature along the
/// ray for `curved_main`).
struct ProbeIn {
    a: vec4<f32>,
    b: vec4<f32>,
}

/// One result: the hit UV (a shadow query's own UV), depth or visibility, fetches.
struct ProbeOut {
    uv: vec2<f32>,
    value: f32,
    fetches: u32,
}

@group(0) @binding(0) var probe_heights: texture_2d<f32>;
@group(0) @binding(1) var probe_pyramid: texture_2d<f32>;
@group(0) @binding(2) var probe_sampler: sampler;
@group(0) @binding(3) var<uniform> probe_params: PomkitParams;
@group(0) @binding(4) var<storage, read> probe_in: array<ProbeIn>;
@group(0) @binding(5) var<storage, read_write> probe_out: array<ProbeOut>;
@group(0) @binding(6) var probe_planes: texture_2d<u32>;

/// A direction in ray terms (u, v, depth) as a tangent-space vector (T, B, N): B points along -v.
fn probe_tangent(d: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(d.x, -d.y, d.z);
}

@compute @workgroup_size(64)
fn trace_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_in) {
        return;
    }
    let r = probe_in[i];
    let ray = pomkit_view_ray(probe_tangent(r.b.xyz), vec2<f32>(1.0));
    let hit = pomkit_trace(probe_params.technique, probe_heights, probe_pyramid, probe_sampler, probe_params, r.a.xy, ray, r.a.z);
    probe_out[i] = ProbeOut(hit.uv, hit.depth, hit.fetches);
}

/// `pomkit_trace_curved`: the value is the hit's depth below the curved surface; the fetches'
/// top bit says the ray left the relief.
@compute @workgroup_size(64)
fn curved_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_in) {
        return;
    }
    let r = probe_in[i];
    let ray = pomkit_view_ray(probe_tangent(r.b.xyz), vec2<f32>(1.0));
    let c = pomkit_trace_curved(probe_params.technique, probe_heights, probe_pyramid, probe_sampler, probe_params, r.a.xy, ray, r.a.z, r.b.w);
    probe_out[i] = ProbeOut(c.hit.uv, c.hit.depth, c.hit.fetches | select(0u, 0x80000000u, c.left));
}

@compute @workgroup_size(64)
fn shadow_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_in) {
        return;
    }
    let r = probe_in[i];
    let light = pomkit_light_ray(probe_tangent(r.b.xyz), vec2<f32>(1.0));
    let s = pomkit_shadow(probe_heights, probe_pyramid, probe_sampler, probe_params, r.a.xy, r.a.w, light, r.a.z);
    probe_out[i] = ProbeOut(r.a.xy, s.visibility, s.fetches);
}

/// `exact` by the least-depth walk, called directly (no technique dispatch).
@compute @workgroup_size(64)
fn exact_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_in) {
        return;
    }
    let r = probe_in[i];
    let ray = pomkit_view_ray(probe_tangent(r.b.xyz), vec2<f32>(1.0));
    var hit = PomkitHit(r.a.xy, 0.0, 0u);
    if ray.w > 0.0 {
        let tile = pomkit_entry_tile(r.a.xy, probe_params.edges);
        hit = pomkit_trace_exact(probe_heights, probe_pyramid, probe_sampler, probe_params, r.a.xy - tile, ray.xyz);
        hit.uv += tile;
    }
    probe_out[i] = ProbeOut(hit.uv, hit.depth, hit.fetches);
}

/// `exact` by the walk on plane bounds per cell (`pomkit_trace_planes`).
@compute @workgroup_size(64)
fn planes_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&probe_in) {
        return;
    }
    let r = probe_in[i];
    let ray = pomkit_view_ray(probe_tangent(r.b.xyz), vec2<f32>(1.0));
    let hit = pomkit_trace_planes(probe_heights, probe_pyramid, probe_planes, probe_sampler, probe_params, r.a.xy, ray);
    probe_out[i] = ProbeOut(hit.uv, hit.depth, hit.fetches);
}
