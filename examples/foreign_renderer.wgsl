// uses: pomkit.wgsl
//
// The shader of examples/foreign_renderer.rs: a small renderer's own material shader (GGX +
// Lambert, a sun, hemisphere ambient, fog, reverse-Z) that imports pomkit's shader library for
// three things only: tracing the relief, its self-shadows and the pixel depth offset.
//
// The program loads it with `pomkit_gpu::library::compose(include_str!(...))`, which puts the
// library (crates/pomkit-gpu/shaders/pomkit.wgsl, every name `pomkit_*`) in front of this file.
// Everything below that is not called `pomkit_*` belongs to the host.

// ---------------------------------------------------------------------------------------------
// Bindings: the host's own frame uniform (group 0), and per material (group 1) the library's
// `PomkitParams`, the host's shading constants, the height textures and a sampler.
// ---------------------------------------------------------------------------------------------

struct Frame {
    view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    // Unit direction toward the sun, and its radiance (rgb).
    sun_dir: vec4<f32>,
    sun_color: vec4<f32>,
    // Hemisphere ambient: light from above and from below.
    sky_ambient: vec4<f32>,
    ground_ambient: vec4<f32>,
    // Fog / background colour (display-referred, the render pass's clear colour); a = density.
    fog: vec4<f32>,
    // An axis-aligned box that casts a sun shadow on the rest of the scene (the cube): stands in
    // for the shadow maps a real renderer has. w unused.
    occluder_min: vec4<f32>,
    occluder_max: vec4<f32>,
}

// The host's surface description. Albedo is procedural: a ramp between two colours by the
// height under the traced point (mortar low, brick faces high), so it is read at the traced UV
// like any texture would be.
struct Look {
    // rgb: linear albedo of the lowest points; a: their roughness.
    low: vec4<f32>,
    // rgb: linear albedo of the highest points; a: their roughness.
    high: vec4<f32>,
    // x, y: heights where the ramp starts and ends; z: metallic; w: unused.
    ramp: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
// The library's parameters (technique, shadow mode, depth scale, ...), written from Rust with
// `PomkitParams::to_bytes()`.
@group(1) @binding(0) var<uniform> params: PomkitParams;
@group(1) @binding(1) var<uniform> look: Look;
// R = depth (0 = the polygon's surface, 1 = deepest), G = parallax value; full mip chain.
@group(1) @binding(2) var heights: texture_2d<f32>;
// The maximum-height pyramid, read by the `exact` technique and exact shadows only.
@group(1) @binding(3) var pyramid: texture_2d<f32>;
// Trilinear, repeating (the library's POMKIT_WRAP edges).
@group(1) @binding(4) var samp: sampler;

// ---------------------------------------------------------------------------------------------
// Vertex stage: the host's own vertex format (glTF attributes), world-space vertices
// ---------------------------------------------------------------------------------------------

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // xyz along +u, w = handedness (glTF).
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec4<f32>,
    @location(3) uv: vec2<f32>,
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    return VertexOut(frame.view_proj * vec4<f32>(v.position, 1.0), v.position, v.normal, v.tangent, v.uv);
}

// ---------------------------------------------------------------------------------------------
// The host's shading
// ---------------------------------------------------------------------------------------------

const PI: f32 = 3.14159265;

/// Cook-Torrance: GGX distribution, Smith-Schlick visibility, Schlick Fresnel; Lambert diffuse.
/// Returns the reflected radiance for unit irradiance along `l`, times N.L.
fn brdf(albedo: vec3<f32>, roughness: f32, metallic: f32, n: vec3<f32>, v: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let n_l = max(dot(n, l), 0.0);
    let n_v = max(dot(n, v), 1e-4);
    let h = normalize(v + l);
    let n_h = max(dot(n, h), 0.0);
    let a2 = pow(roughness, 4.0);
    let d = a2 / (PI * pow(n_h * n_h * (a2 - 1.0) + 1.0, 2.0));
    let k = (roughness + 1.0) * (roughness + 1.0) / 8.0;
    let g = n_l / (n_l * (1.0 - k) + k) * n_v / (n_v * (1.0 - k) + k);
    let f0 = mix(vec3<f32>(0.04), albedo, metallic);
    let f = f0 + (1.0 - f0) * pow(1.0 - max(dot(v, h), 0.0), 5.0);
    let specular = d * g * f / max(4.0 * n_l * n_v, 1e-4);
    let diffuse = (1.0 - f) * (1.0 - metallic) * albedo / PI;
    return (diffuse + specular) * n_l;
}

/// The relief's normal at `uv`, by central differences of the depth at mip `lod`, in world
/// space. The surface lies `depth * depth_scale` UV units below the polygon, and one UV unit is
/// `uv_scale` world units long along u and v (pomkit_hit_position's convention).
fn relief_normal(f: PomkitFrame, uv: vec2<f32>, lod: f32, uv_scale: vec2<f32>) -> vec3<f32> {
    let texel = exp2(lod) / vec2<f32>(textureDimensions(heights, 0));
    let dx = vec2<f32>(texel.x, 0.0);
    let dy = vec2<f32>(0.0, texel.y);
    let dd_du = (pomkit_depth_at(heights, samp, uv + dx, lod) - pomkit_depth_at(heights, samp, uv - dx, lod)) / (2.0 * texel.x);
    let dd_dv = (pomkit_depth_at(heights, samp, uv + dy, lod) - pomkit_depth_at(heights, samp, uv - dy, lod)) / (2.0 * texel.y);
    // World depth per UV unit of depth, over the world length of a UV unit along u and v.
    let k = params.depth_scale * sqrt(uv_scale.x * uv_scale.y) / uv_scale;
    // Deeper toward +u tilts the normal toward +T; B points along -v, so the v slope flips.
    return normalize(f.t * (k.x * dd_du) - f.b * (k.y * dd_dv) + f.n);
}

/// 0 where the ray from `p` toward the sun enters the occluder box, else 1 (slab test).
fn occluder_visibility(p: vec3<f32>) -> f32 {
    let inv = 1.0 / frame.sun_dir.xyz;
    let t0 = (frame.occluder_min.xyz - p) * inv;
    let t1 = (frame.occluder_max.xyz - p) * inv;
    let enter = max(max(min(t0.x, t1.x), min(t0.y, t1.y)), min(t0.z, t1.z));
    let exit = min(min(max(t0.x, t1.x), max(t0.y, t1.y)), max(t0.z, t1.z));
    return select(1.0, 0.0, enter > 1e-3 && enter < exit);
}

// ---------------------------------------------------------------------------------------------
// Fragment stage
// ---------------------------------------------------------------------------------------------

struct FragmentOut {
    @location(0) color: vec4<f32>,
    // Pixel depth offset: the depth of the traced point, not of the polygon.
    @builtin(frag_depth) depth: f32,
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    // Screen-space derivatives first, in uniform control flow.
    let duv_dx = dpdx(in.uv);
    let duv_dy = dpdy(in.uv);
    // The world length of one UV unit along u and v: this host's vertices carry no such
    // attribute, so it comes from the derivatives (exact on flat triangles, which these are).
    let uv_scale = pomkit_uv_scale(dpdx(in.world), dpdy(in.world), duv_dx, duv_dy);

    let f = pomkit_tangent_frame(in.normal, in.tangent);
    let to_eye = normalize(frame.eye.xyz - in.world);
    let sun = frame.sun_dir.xyz;
    let technique = params.technique;

    // The height map's mip level, fixed for the whole trace, and the LOD fade: the full
    // technique up to mip `lod_threshold - 1`, fading to plain shading at `lod_threshold`.
    let lod = pomkit_mip_level(heights, duv_dx, duv_dy);
    let weight = pomkit_lod_weight(lod, params.lod_threshold);

    // Trace the view ray into the relief. The technique is a uniform: changing it is a
    // queue.write_buffer, no pipeline rebuild (a constant would compile only its own loop).
    var hit = PomkitHit(in.uv, 0.0, 0u);
    if weight > 0.0 {
        let ray = pomkit_view_ray(pomkit_to_tangent(f, in.world - frame.eye.xyz), uv_scale);
        hit = pomkit_trace(technique, heights, pyramid, samp, params, in.uv, ray, lod);
        // Lift the hit onto the surface (one fetch): steep parallax stops up to one layer
        // below it, and the lifted point shades there (pomkit_shadow lifts its own receiver).
        hit = pomkit_lift_to_surface(heights, samp, hit, lod);
        // Fade toward the untraced point.
        hit = PomkitHit(mix(in.uv, hit.uv, weight), hit.depth * weight, hit.fetches);
    }

    // Self-shadowing by the relief toward the sun (soft shadows with the default parameters);
    // no trace where the polygon itself faces away from the sun.
    var sun_visibility = select(0.0, 1.0, dot(f.n, sun) > 0.0);
    if sun_visibility > 0.0 && weight > 0.0 && technique != POMKIT_FLAT {
        let light = pomkit_light_ray(pomkit_to_tangent(f, sun), uv_scale);
        let s = pomkit_shadow(heights, pyramid, samp, params, hit.uv, hit.depth, light, lod);
        sun_visibility = mix(1.0, s.visibility, weight);
    }

    // The traced point in world space, and its reverse-Z depth (near = 1, far = 0): never
    // nearer than the polygon itself.
    let p = pomkit_hit_position(in.world, to_eye, f.n, hit.depth, params.depth_scale, uv_scale);
    let depth = pomkit_pixel_depth(p, frame.view_proj, in.clip.z, true);
    sun_visibility *= occluder_visibility(p);

    // The host's shading, at the traced UV. `flat` means no relief at all: the polygon's normal.
    var n = f.n;
    if technique != POMKIT_FLAT {
        n = relief_normal(f, hit.uv, lod, uv_scale);
    }
    let height = 1.0 - pomkit_depth_at(heights, samp, hit.uv, lod);
    let t = smoothstep(look.ramp.x, look.ramp.y, height);
    let albedo = mix(look.low.rgb, look.high.rgb, t);
    let roughness = mix(look.low.a, look.high.a, t);
    // Cheap cavity occlusion: deep points see less of the sky.
    let cavity = 1.0 - 0.6 * hit.depth;
    let ambient = mix(frame.ground_ambient.rgb, frame.sky_ambient.rgb, 0.5 + 0.5 * n.y) * albedo * cavity;
    let direct = brdf(albedo, roughness, look.ramp.z, n, to_eye, sun) * frame.sun_color.rgb * sun_visibility;
    let hdr = ambient + direct;

    // Tone mapping (Reinhard on luminance, which keeps hues), then distance fog toward the
    // background colour. The target is sRGB: the hardware encodes these linear values.
    let mapped = min(hdr / (1.0 + dot(hdr, vec3<f32>(0.2126, 0.7152, 0.0722))), vec3<f32>(1.0));
    let fog_depth = frame.fog.a * distance(p, frame.eye.xyz);
    let fog = 1.0 - exp(-fog_depth * fog_depth);
    return FragmentOut(vec4<f32>(mix(mapped, frame.fog.rgb, fog), 1.0), depth);
}
