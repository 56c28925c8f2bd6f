// bevy_pomkit: the fragment stage of `ExtendedMaterial<StandardMaterial, Pomkit>`, for the main
// (forward) pass, the prepass and the shadow passes. Tracing, self-shadows and pixel depth
// offset come from pomkit's shader library (the `pomkit::library` module); Bevy's PBR shading
// then samples every texture of the standard material at the traced UV.
//
// Conventions (ARCHITECTURE.md, Conventions): depth d in [0, 1] below the polygon, the traced
// UV space is the material's after `uv_transform`, and `depth_scale` is in those UV units.

#import bevy_pbr::{
    pbr_bindings,
    pbr_functions,
    pbr_types,
    mesh_view_bindings::view,
}
#import pomkit::library::{
    PomkitParams, PomkitHit, pomkit_tangent_frame, pomkit_uv_scale, pomkit_view_ray, pomkit_light_ray,
    pomkit_mip_level, pomkit_lod_weight, pomkit_trace, pomkit_receiver, pomkit_shadow,
    pomkit_hit_position, pomkit_pixel_depth, pomkit_safe_normalize, POMKIT_FLAT, POMKIT_NORMAL,
    POMKIT_SHADOW_NONE,
}

#ifdef PREPASS_PIPELINE
#import bevy_pbr::{prepass_io::VertexOutput, pbr_prepass_functions}
#else
#import bevy_pbr::{
    forward_io::VertexOutput,
    pbr_fragment::pbr_input_from_standard_material,
    lighting,
    shadows,
    mesh_view_types,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    mesh_view_bindings::lights,
}
#endif

struct PomkitMaterial {
    params: PomkitParams,
    // Bit 0: textures built and parameters valid; bit 1: shade with the height map's normals;
    // bit 2: pixel depth offset.
    flags: u32,
    // 0 shaded, 1 hit UV, 2 fetches, 3 self-shadow.
    debug: u32,
    pad0: u32,
    pad1: u32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> pomkit: PomkitMaterial;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var pomkit_heights: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var pomkit_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var pomkit_pyramid: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var pomkit_normals: texture_2d<f32>;

const FLAG_READY: u32 = 1u;
const FLAG_NORMALS: u32 = 2u;
const FLAG_PIXEL_DEPTH: u32 = 4u;

/// The traced surface of one fragment.
struct Traced {
    /// The material is ready and the mesh has UVs, normals and tangents.
    ready: bool,
    /// A displacing technique traced the view ray (ready, and LOD weight above 0).
    traced: bool,
    /// The hit, in the material's UV space (after `uv_transform`).
    hit: PomkitHit,
    /// The entry UV in the same space.
    uv: vec2<f32>,
    /// The hit in the mesh's own UV space (what Bevy's standard material samples through its
    /// `uv_transform`).
    raw_uv: vec2<f32>,
    /// LOD fade weight of the full technique, and the height map's mip level.
    weight: f32,
    lod: f32,
    /// Unit geometric normal, and the world vectors dP/du, dP/dv of the traced UV space.
    n: vec3<f32>,
    dpdu: vec3<f32>,
    dpdv: vec3<f32>,
    /// World length of one UV unit along u and v.
    uv_scale: vec2<f32>,
    /// Unit vector from the surface toward the eye.
    to_eye: vec3<f32>,
}

/// A world vector in the library's ray terms, as the tangent-space vector that
/// `pomkit_light_ray(_, vec2(1.0))` and `pomkit_view_ray(_, vec2(1.0))` expect: its tangent-plane
/// part written in the (possibly stretched or skewed) basis dP/du, dP/dv, scaled to the mean UV
/// length, with B up the image (-v). For an unstretched, unskewed mapping this is exactly the
/// tangent-space vector with the UV scale applied (docs/EMBEDDING.md).
fn ray_terms(w: vec3<f32>, s: Traced) -> vec3<f32> {
    let g00 = dot(s.dpdu, s.dpdu);
    let g01 = dot(s.dpdu, s.dpdv);
    let g11 = dot(s.dpdv, s.dpdv);
    let r0 = dot(w, s.dpdu);
    let r1 = dot(w, s.dpdv);
    let det = g00 * g11 - g01 * g01;
    if !(det > 0.0) {
        return vec3<f32>(0.0, 0.0, dot(w, s.n));
    }
    let a = (r0 * g11 - r1 * g01) / det;
    let b = (r1 * g00 - r0 * g01) / det;
    let l = sqrt(s.uv_scale.x * s.uv_scale.y);
    return vec3<f32>(a * l, -b * l, dot(w, s.n));
}

fn displaces(technique: u32) -> bool {
    return technique != POMKIT_FLAT && technique != POMKIT_NORMAL;
}

/// Traces the view ray of this fragment (for whichever view renders: camera or light).
fn trace_fragment(in: VertexOutput) -> Traced {
    var s: Traced;
    s.ready = false;
    s.traced = false;
    s.weight = 0.0;
    s.lod = 0.0;
    s.n = vec3<f32>(0.0, 0.0, 1.0);
    s.to_eye = vec3<f32>(0.0, 0.0, 1.0);
    s.uv_scale = vec2<f32>(1.0);
#ifdef VERTEX_UVS_A
    let m3 = pbr_bindings::material.uv_transform;
    let uv = (m3 * vec3<f32>(in.uv, 1.0)).xy;
    s.uv = uv;
    s.raw_uv = in.uv;
    s.hit = PomkitHit(uv, 0.0, 0u);
    // Gradients in uniform control flow, before any branch (HLSL's tex2Dgrad in the published POM shaders, docs/REFERENCES.md).
    let duv_dx = dpdx(uv);
    let duv_dy = dpdy(uv);
    let draw_dx = dpdx(in.uv);
    let draw_dy = dpdy(in.uv);
    let dw_dx = dpdx(in.world_position.xyz);
    let dw_dy = dpdy(in.world_position.xyz);
#ifdef VERTEX_TANGENTS
    let is_orthographic = view.clip_from_view[3].w == 1.0;
    s.to_eye = pbr_functions::calculate_view(in.world_position, is_orthographic);
    let f = pomkit_tangent_frame(in.world_normal, in.world_tangent);
    s.n = f.n;
    // Orient the bitangent up the image (-v) whatever the tangent's w says: tangents from
    // different sources disagree on its sign (docs/EMBEDDING.md, Tangent handedness).
    var b = f.b;
    let det = draw_dx.x * draw_dy.y - draw_dx.y * draw_dy.x;
    if abs(det) > 1e-30 {
        let dp_dv = (dw_dy * draw_dx.x - dw_dx * draw_dy.x) / det;
        if dot(b, dp_dv) > 0.0 {
            b = -b;
        }
    }
    // World vectors of the mesh's UV axes: directions from the (smooth) vertex frame, lengths
    // from the (per-triangle) derivatives, then through the inverse of uv_transform.
    let s_raw = pomkit_uv_scale(dw_dx, dw_dy, draw_dx, draw_dy);
    let du_raw = f.t * s_raw.x;
    let dv_raw = -b * s_raw.y;
    let m = mat2x2<f32>(m3[0].xy, m3[1].xy);
    let dm = determinant(m);
    var minv = mat2x2<f32>(1.0, 0.0, 0.0, 1.0);
    if abs(dm) > 1e-30 {
        minv = mat2x2<f32>(m[1].y, -m[0].y, -m[1].x, m[0].x) * (1.0 / dm);
    }
    s.dpdu = du_raw * minv[0].x + dv_raw * minv[0].y;
    s.dpdv = du_raw * minv[1].x + dv_raw * minv[1].y;
    s.uv_scale = vec2<f32>(length(s.dpdu), length(s.dpdv));
    if (pomkit.flags & FLAG_READY) == 0u {
        return s;
    }
    s.ready = true;
    s.lod = pomkit_mip_level(pomkit_heights, duv_dx, duv_dy);
    s.weight = pomkit_lod_weight(s.lod, pomkit.params.lod_threshold);
    if s.weight > 0.0 && displaces(pomkit.params.technique) {
        s.traced = true;
        let ray = pomkit_view_ray(ray_terms(-s.to_eye, s), vec2<f32>(1.0));
        var hit = pomkit_trace(pomkit.params.technique, pomkit_heights, pomkit_pyramid, pomkit_sampler, pomkit.params, uv, ray, s.lod);
        hit = pomkit_receiver(pomkit.params.technique, pomkit_heights, pomkit_sampler, hit, s.lod);
        s.hit = hit;
        s.raw_uv = minv * (hit.uv - m3[2].xy);
    }
#endif
#endif
    return s;
}

/// The world normal of the height map at the hit (pomkit's baked normals: x along +u, y up the
/// image, z out of the surface).
fn surface_normal(s: Traced, uv: vec2<f32>) -> vec3<f32> {
    let nm = pomkit_safe_normalize(textureSampleLevel(pomkit_normals, pomkit_sampler, uv, 0.0).xyz, vec3<f32>(0.0, 0.0, 1.0));
    let t = pomkit_safe_normalize(s.dpdu, vec3<f32>(1.0, 0.0, 0.0));
    let b = pomkit_safe_normalize(-s.dpdv, vec3<f32>(0.0, 1.0, 0.0));
    return pomkit_safe_normalize(t * nm.x + b * nm.y + s.n * nm.z, s.n);
}

/// The depth-buffer value of the traced point, where this pass writes it (POMKIT_PIXEL_DEPTH:
/// pixel depth offset on, and not a directional shadow map without `shadow_pixel_depth`), else
/// the polygon's.
fn traced_depth(in: VertexOutput, s: Traced) -> f32 {
#ifdef UNCLIPPED_DEPTH_ORTHO_EMULATION
    let polygon = in.unclipped_depth;
#else
    let polygon = in.position.z;
#endif
#ifdef POMKIT_PIXEL_DEPTH
    if s.traced && (pomkit.flags & FLAG_PIXEL_DEPTH) != 0u && s.hit.depth > 0.0 {
        let p = pomkit_hit_position(in.world_position.xyz, s.to_eye, s.n, s.hit.depth, pomkit.params.depth_scale, s.uv_scale);
        // Bevy's depth buffers are reverse-Z (near = 1).
        return pomkit_pixel_depth(p, view.clip_from_world, polygon, true);
    }
#endif
    return polygon;
}

#ifdef PREPASS_PIPELINE

struct PomkitPrepassOutput {
#ifdef NORMAL_PREPASS
    @location(0) normal: vec4<f32>,
#endif
#ifdef MOTION_VECTOR_PREPASS
    @location(1) motion_vector: vec2<f32>,
#endif
    @builtin(frag_depth) frag_depth: f32,
}

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> PomkitPrepassOutput {
    let s = trace_fragment(in);
    pbr_prepass_functions::prepass_alpha_discard(in);
    var out: PomkitPrepassOutput;
    out.frag_depth = traced_depth(in, s);
#ifdef NORMAL_PREPASS
    var n = s.n;
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    n = normalize(in.world_normal);
#endif
    if s.ready && (pomkit.flags & FLAG_NORMALS) != 0u {
        n = surface_normal(s, s.hit.uv);
    }
    out.normal = vec4<f32>(n * 0.5 + vec3<f32>(0.5), 1.0);
#endif
#ifdef MOTION_VECTOR_PREPASS
    out.motion_vector = pbr_prepass_functions::calculate_motion_vector(in.world_position, in.previous_world_position);
#endif
    return out;
}

#else // PREPASS_PIPELINE

struct PomkitFragmentOutput {
    @location(0) color: vec4<f32>,
#ifdef POMKIT_PIXEL_DEPTH
    @builtin(frag_depth) frag_depth: f32,
#endif
}

/// A fragment shaded by `lit`.
struct Lit {
    /// The lit colour, before post-processing.
    color: vec4<f32>,
    pbr_input: pbr_types::PbrInput,
    /// Visibility of the first directional light.
    visibility: f32,
    /// Fetches of the shadow traces.
    fetches: u32,
}

/// Bevy's PBR shading of the standard material at the traced hit (`traced`) or at the polygon,
/// with pomkit's self-shadows applied to each directional light's direct light.
fn lit(in: VertexOutput, is_front: bool, s: Traced, traced: bool) -> Lit {
    var vin = in;
    var hit = PomkitHit(s.uv, 0.0, 0u);
#ifdef VERTEX_UVS_A
    if traced {
        vin.uv = s.raw_uv;
        hit = s.hit;
    }
#endif
    var pbr_input = pbr_input_from_standard_material(vin, is_front);
    pbr_input.material.base_color = pbr_functions::alpha_discard(pbr_input.material, pbr_input.material.base_color);
    if s.ready && (pomkit.flags & FLAG_NORMALS) != 0u {
        pbr_input.N = surface_normal(s, hit.uv);
    }
    var out: Lit;
    out.visibility = 1.0;
    out.fetches = 0u;
    let unlit = (pbr_input.material.flags & pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT) != 0u;
    var color = pbr_input.material.base_color;
    if !unlit {
        color = pbr_functions::apply_pbr_lighting(pbr_input);
    }
    if traced && !unlit && pomkit.params.shadow_mode != POMKIT_SHADOW_NONE {
        // Each directional light's direct contribution, as Bevy's lighting computes it, scaled
        // by pomkit's self-shadow: color -= exposure * (1 - visibility) * contribution.
        let metallic = pbr_input.material.metallic;
        let perceptual_roughness = pbr_input.material.perceptual_roughness;
        let NdotV = max(dot(pbr_input.N, pbr_input.V), 0.0001);
        var li: lighting::LightingInput;
        li.layers[lighting::LAYER_BASE].NdotV = NdotV;
        li.layers[lighting::LAYER_BASE].N = pbr_input.N;
        li.layers[lighting::LAYER_BASE].R = reflect(-pbr_input.V, pbr_input.N);
        li.layers[lighting::LAYER_BASE].perceptual_roughness = perceptual_roughness;
        li.layers[lighting::LAYER_BASE].roughness = lighting::perceptualRoughnessToRoughness(perceptual_roughness);
        li.P = pbr_input.world_position.xyz;
        li.V = pbr_input.V;
        li.diffuse_color = pbr_functions::calculate_diffuse_color(
            pbr_input.material.base_color.rgb,
            metallic,
            pbr_input.material.specular_transmission,
            pbr_input.material.diffuse_transmission,
        );
        li.metallic = metallic;
        li.F0_dielectric = pbr_functions::calculate_F0_dielectric(pbr_input.material.reflectance);
        li.F0_metallic = pbr_input.material.base_color.rgb;
        li.F_ab = lighting::F_AB(perceptual_roughness, NdotV);
        let view_z = dot(vec4<f32>(
            view.view_from_world[0].z,
            view.view_from_world[1].z,
            view.view_from_world[2].z,
            view.view_from_world[3].z
        ), pbr_input.world_position);
        let n_lights = lights.n_directional_lights;
        for (var i = 0u; i < n_lights; i++) {
            let l_world = lights.directional_lights[i].direction_to_light;
            var vis = 0.0;
            if dot(s.n, l_world) > 0.0 {
                let sh = pomkit_shadow(pomkit_heights, pomkit_pyramid, pomkit_sampler, pomkit.params, hit.uv, hit.depth, pomkit_light_ray(ray_terms(l_world, s), vec2<f32>(1.0)), s.lod);
                vis = sh.visibility;
                out.fetches += sh.fetches;
            }
            if i == 0u {
                out.visibility = vis;
            }
            if vis < 1.0 {
                var shadow_map = 1.0;
                if (pbr_input.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u
                        && (lights.directional_lights[i].flags & mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
                    shadow_map = shadows::fetch_directional_shadow(i, pbr_input.world_position, pbr_input.world_normal, view_z, pbr_input.frag_coord.xy);
                }
                let direct = lighting::directional_light(i, &li, true) * shadow_map;
                color = vec4<f32>(max(color.rgb - view.exposure * (1.0 - vis) * direct, vec3<f32>(0.0)), color.a);
            }
        }
    }
    out.color = color;
    out.pbr_input = pbr_input;
    return out;
}

@fragment
fn fragment(in: VertexOutput, @builtin(front_facing) is_front: bool) -> PomkitFragmentOutput {
    let s = trace_fragment(in);
    var out: PomkitFragmentOutput;
#ifdef POMKIT_PIXEL_DEPTH
    out.frag_depth = traced_depth(in, s);
#endif
    let traced = s.traced;
    let hit = s.hit;
    let full = lit(in, is_front, s, traced);
    var color = full.color;
    if traced && s.weight < 1.0 {
        // The LOD fade blends the shaded colours of the full technique and the plain surface,
        // as pomkit's own renderers do.
        let plain = lit(in, is_front, s, false);
        color = mix(plain.color, full.color, s.weight);
    }
    switch pomkit.debug {
        case 1u: {
            out.color = vec4<f32>(hit.uv, hit.depth, 1.0);
        }
        case 2u: {
            out.color = vec4<f32>(f32(hit.fetches + full.fetches) / 64.0, s.weight, s.lod / 16.0, 1.0);
        }
        case 3u: {
            out.color = vec4<f32>(full.visibility, s.weight, 0.0, 1.0);
        }
        default: {
            out.color = pbr_functions::main_pass_post_lighting_processing(full.pbr_input, color);
        }
    }
    return out;
}

#endif // PREPASS_PIPELINE
