// bevy_pomkit: the fragment stage of `ExtendedMaterial<StandardMaterial, Pomkit>`, for the forward
// pass, the prepass (depth, normals, deferred G-buffer) and the shadow passes. Tracing,
// self-shadows and pixel depth offset come from pomkit's shader library (the `pomkit::library`
// module); Bevy's PBR then shades the standard material sampled at the traced UV.
//
// Conventions (ARCHITECTURE.md, Conventions): depth d in [0, 1] below the polygon, the traced
// UV space is the material's after `uv_transform`, and `depth_scale` is in those UV units.
//
// Every option is a pipeline specialisation (src/material.rs, `PomkitKey`): the technique, the
// self-shadow mode, the height map's normals, the LOD band, the debug view, pixel depth offset
// and which of the standard material's textures exist. What is off is not in the shader at all:
// a GPU that executes both sides of a branch (Mesa's lavapipe does, for every branch) pays only
// for what the material uses (docs/BENCHMARKS.md, Bevy, what each part costs).

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
    POMKIT_SHADOW_NONE, pomkit_to_tangent, pomkit_view_curvature, pomkit_trace_curved,
}

#ifdef PREPASS_PIPELINE
#import bevy_pbr::{prepass_io::VertexOutput, pbr_prepass_functions}
#ifdef DEFERRED_PREPASS
#import bevy_pbr::pbr_deferred_functions::deferred_gbuffer_from_pbr_input
#endif
#else
#import bevy_pbr::{
    forward_io::VertexOutput,
    lighting,
    shadows,
    mesh_view_types,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    mesh_view_bindings::{lights, clustered_lights},
    clustered_forward as clustering,
    decal::clustered::apply_decals,
}
#endif

#ifdef POMKIT_BEVY_INPUT
#import bevy_pbr::pbr_fragment::pbr_input_from_standard_material
#else
#import bevy_pbr::pbr_fragment::pbr_input_from_vertex_output
#ifdef LIGHTMAP
#import bevy_pbr::lightmap::lightmap
#endif
#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
#import bevy_pbr::mesh_view_bindings::screen_space_ambient_occlusion_texture
#import bevy_pbr::ssao_utils::ssao_multibounce
#endif
#endif

struct PomkitMaterial {
    params: PomkitParams,
    // Bit 0: textures built and parameters valid.
    flags: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    // The colour seen from afar, linear RGBA (POMKIT_FAR_COLOR).
    far_color: vec4<f32>,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> pomkit: PomkitMaterial;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var pomkit_heights: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var pomkit_sampler: sampler;
@group(#{MATERIAL_BIND_GROUP}) @binding(103) var pomkit_pyramid: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(104) var pomkit_normals: texture_2d<f32>;

const FLAG_READY: u32 = 1u;

// The specialisation (src/material.rs, `PomkitKey::shader_defs`).
const TECHNIQUE: u32 = #{POMKIT_TECHNIQUE}u;
const SHADOW_MODE: u32 = #{POMKIT_SHADOW_MODE}u;
// 0 shaded, 1 hit UV, 2 fetches, 3 self-shadow.
const DEBUG: u32 = #{POMKIT_DEBUG}u;

/// The material's parameters with the specialised technique and shadow mode as constants, so
/// that the library's dispatch folds to the one technique and the one shadow mode.
fn params() -> PomkitParams {
    var p = pomkit.params;
    p.technique = TECHNIQUE;
    p.shadow_mode = SHADOW_MODE;
    return p;
}

fn displaces() -> bool {
    return TECHNIQUE != POMKIT_FLAT && TECHNIQUE != POMKIT_NORMAL;
}

/// The traced surface of one fragment.
struct Traced {
    /// The material is ready and the mesh has UVs, normals and tangents.
    ready: bool,
    /// The hit, in the material's UV space (after `uv_transform`), after the LOD band's blend.
    hit: PomkitHit,
    /// The entry UV in the same space.
    uv: vec2<f32>,
    /// Screen derivatives of the entry UV: every texture is sampled at the hit with these, the
    /// footprint of the pixel, not the derivatives of the hit UV (which jump where neighbouring
    /// pixels hit different features and would pick a far too coarse mip).
    duv_dx: vec2<f32>,
    duv_dy: vec2<f32>,
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
    /// The inverse of uv_transform's linear part, and its translation: mesh UV = minv * (uv - t).
    minv: mat2x2<f32>,
    translation: vec2<f32>,
    /// Texture reads of the trace.
    fetches: u32,
    /// How deep the hit lies along the straight view ray below the polygon, in depth units
    /// (what pixel depth offset moves the depth by): the hit's depth, except under a curved
    /// surface (silhouettes).
    ray_depth: f32,
    /// Silhouettes: the ray left the relief without meeting it, and the fragment is discarded.
    left: bool,
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

/// Traces the view ray of this fragment (for whichever view renders: camera or light).
/// `curvature` is the mesh's curvature form at the fragment (silhouettes; zero otherwise).
fn trace_fragment(in: VertexOutput, curvature: vec3<f32>) -> Traced {
    var s: Traced;
    s.ready = false;
    s.ray_depth = 0.0;
    s.left = false;
    s.weight = 0.0;
    s.lod = 0.0;
    s.fetches = 0u;
    s.n = vec3<f32>(0.0, 0.0, 1.0);
    s.to_eye = vec3<f32>(0.0, 0.0, 1.0);
    s.uv_scale = vec2<f32>(1.0);
    s.minv = mat2x2<f32>(1.0, 0.0, 0.0, 1.0);
    s.translation = vec2<f32>(0.0);
#ifdef VERTEX_UVS_A
    let m3 = pbr_bindings::material.uv_transform;
    let uv = (m3 * vec3<f32>(in.uv, 1.0)).xy;
    s.uv = uv;
    s.translation = m3[2].xy;
    s.hit = PomkitHit(uv, 0.0, 0u);
    // Gradients in uniform control flow, before any branch (HLSL's tex2Dgrad in the published
    // POM shaders, docs/REFERENCES.md).
    s.duv_dx = dpdx(uv);
    s.duv_dy = dpdy(uv);
#ifdef VERTEX_TANGENTS
#ifdef VERTEX_NORMALS
    let draw_dx = dpdx(in.uv);
    let draw_dy = dpdy(in.uv);
    let dw_dx = dpdx(in.world_position.xyz);
    let dw_dy = dpdy(in.world_position.xyz);
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
    if abs(dm) > 1e-30 {
        s.minv = mat2x2<f32>(m[1].y, -m[0].y, -m[1].x, m[0].x) * (1.0 / dm);
    }
    s.dpdu = du_raw * s.minv[0].x + dv_raw * s.minv[0].y;
    s.dpdv = du_raw * s.minv[1].x + dv_raw * s.minv[1].y;
    s.uv_scale = vec2<f32>(length(s.dpdu), length(s.dpdv));
    s.ready = (pomkit.flags & FLAG_READY) != 0u;
#ifdef POMKIT_PLAIN
    // A silhouette material on a mesh without the curvature attribute (reported by the plugin).
    s.ready = false;
#endif
    s.lod = pomkit_mip_level(pomkit_heights, s.duv_dx, s.duv_dy);
#ifdef POMKIT_LOD_FADE
    s.weight = pomkit_lod_weight(s.lod, pomkit.params.lod_threshold);
#else
    s.weight = 1.0;
#endif
#ifdef POMKIT_SILHOUETTE
    // The outline is decided wherever the mesh is drawn, beyond the LOD band too (the rim of
    // a curved mesh is where the mip level is highest).
    let trace = true;
#else
    let trace = s.weight > 0.0;
#endif
    if displaces() && s.ready && trace {
        let p = params();
        let ray = pomkit_view_ray(ray_terms(-s.to_eye, s), vec2<f32>(1.0));
#ifdef POMKIT_SILHOUETTE
        // The curvature along the ray, in the vertex's own frame (B = w cross(N, T), as the
        // plugin fitted it), with K's UV unit made the material's: uv_transform scales it by
        // 1 / sqrt(|det|).
        let k = curvature * inverseSqrt(max(abs(dm), 1e-30));
        let c = pomkit_view_curvature(pomkit_to_tangent(f, -s.to_eye), k, p.depth_scale);
        let curved = pomkit_trace_curved(TECHNIQUE, pomkit_heights, pomkit_pyramid, pomkit_sampler, p, uv, ray, s.lod, c);
        var hit = curved.hit;
        s.ray_depth = curved.ray_depth;
        s.left = curved.left;
#else
        var hit = pomkit_trace(TECHNIQUE, pomkit_heights, pomkit_pyramid, pomkit_sampler, p, uv, ray, s.lod);
        s.ray_depth = hit.depth;
#endif
        // Steep parallax stops up to one layer below the surface: the receiver of shading, the
        // depth self-shadow and the depth output is lifted onto it, as in pomkit's renderers,
        // and the point moves up the view ray by as much.
        let traced = hit.depth;
        hit = pomkit_receiver(TECHNIQUE, pomkit_heights, pomkit_sampler, hit, s.lod);
        s.ray_depth -= traced - hit.depth;
        s.fetches = hit.fetches;
#ifdef POMKIT_LOD_FADE
        // The LOD band shades once, at the hit moved toward the entry point by the fade weight
        // (and raised toward the polygon by it): the picture fades continuously to the
        // untraced surface, at the cost of one shading instead of two.
        hit = PomkitHit(mix(uv, hit.uv, s.weight), hit.depth * s.weight, hit.fetches);
        s.ray_depth *= s.weight;
#endif
        s.hit = hit;
    }
#endif
#endif
#endif
    return s;
}

/// The mesh UV of a point of the traced UV space (what Bevy's own functions sample through
/// `uv_transform`).
fn mesh_uv(s: Traced, uv: vec2<f32>) -> vec2<f32> {
    return s.minv * (uv - s.translation);
}

/// The world normal of the height map at the hit (pomkit's baked normals: x along +u, y up the
/// image, z out of the surface).
fn surface_normal(s: Traced) -> vec3<f32> {
    let nm = pomkit_safe_normalize(textureSampleGrad(pomkit_normals, pomkit_sampler, s.hit.uv, s.duv_dx, s.duv_dy).xyz, vec3<f32>(0.0, 0.0, 1.0));
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
    if s.ready && s.ray_depth > 0.0 {
        let p = pomkit_hit_position(in.world_position.xyz, s.to_eye, s.n, s.ray_depth, pomkit.params.depth_scale, s.uv_scale);
        // Bevy's depth buffers are reverse-Z (near = 1).
        return pomkit_pixel_depth(p, view.clip_from_world, polygon, true);
    }
#endif
    return polygon;
}

// ---------------------------------------------------------------------------------------------
// The standard material at the hit
// ---------------------------------------------------------------------------------------------

/// The standard material's inputs at the hit, every texture sampled with the entry UV's
/// gradients. The base colour, emissive, metallic-roughness, occlusion and normal-map textures
/// are read only where the material has them (POMKIT_TEX_*). Materials that use what this does
/// not read (clearcoat, anisotropy, transmission, specular textures, a second UV set) take
/// Bevy's own function at the hit (POMKIT_BEVY_INPUT), then the textures above again with the
/// entry UV's gradients.
fn standard_input(in: VertexOutput, is_front: bool, s: Traced) -> pbr_types::PbrInput {
    let m = pbr_bindings::material;
    let flags = m.flags;
    let double_sided = (flags & pbr_types::STANDARD_MATERIAL_FLAGS_DOUBLE_SIDED_BIT) != 0u;
    let uv = s.hit.uv;
#ifdef POMKIT_HIT_UV_DERIVATIVES
    // For comparison only (`Pomkit::entry_gradients` off): the hit UV's own derivatives, as
    // Bevy's parallax mapping samples.
    let ddx = dpdx(uv);
    let ddy = dpdy(uv);
#else
    let ddx = s.duv_dx;
    let ddy = s.duv_dy;
#endif
#ifdef POMKIT_BEVY_INPUT
    var vin = in;
#ifdef VERTEX_UVS_A
    vin.uv = mesh_uv(s, uv);
#endif
    var p = pbr_input_from_standard_material(vin, is_front);
    var base_color = vec4<f32>(1.0);
#ifdef VERTEX_COLORS
    base_color = in.color;
#endif
    p.material.base_color = base_color * m.base_color;
#else
    var p = pbr_input_from_vertex_output(in, is_front, double_sided);
    p.material.flags = flags;
    p.material.base_color *= m.base_color;
    p.material.deferred_lighting_pass_id = m.deferred_lighting_pass_id;
    p.material.uv_transform = m.uv_transform;
    p.material.alpha_cutoff = m.alpha_cutoff;
    p.material.ior = m.ior;
    p.material.attenuation_color = m.attenuation_color;
    p.material.attenuation_distance = m.attenuation_distance;
    p.material.reflectance = m.reflectance;
    p.material.clearcoat = m.clearcoat;
    p.material.clearcoat_perceptual_roughness = m.clearcoat_perceptual_roughness;
    p.material.specular_transmission = m.specular_transmission;
    p.material.thickness = m.thickness;
    p.material.diffuse_transmission = m.diffuse_transmission;
    p.N = normalize(p.world_normal);
    p.clearcoat_N = p.N;
#ifdef LIGHTMAP
    p.lightmap_light = lightmap(in.uv_b, m.lightmap_exposure, in.instance_index);
#endif
#endif
#ifdef POMKIT_TEX_BASE_COLOR
    var texel = textureSampleGrad(pbr_bindings::base_color_texture, pbr_bindings::base_color_sampler, uv, ddx, ddy);
#else
    var texel = vec4<f32>(1.0);
#endif
#ifdef POMKIT_FAR_COLOR
    // The LOD fade fades to the colour seen from afar instead of the texture's coarse mips.
    if s.ready {
        texel = mix(pomkit.far_color, texel, s.weight);
    }
#endif
    p.material.base_color *= texel;
#ifdef POMKIT_TEX_BASE_COLOR
#ifdef ALPHA_TO_COVERAGE
    if (flags & pbr_types::STANDARD_MATERIAL_FLAGS_ALPHA_MODE_RESERVED_BITS) == pbr_types::STANDARD_MATERIAL_FLAGS_ALPHA_MODE_ALPHA_TO_COVERAGE {
        // Sharpened alpha edges, as the standard material has them.
        p.material.base_color.a = (p.material.base_color.a - m.alpha_cutoff) / max(fwidth(p.material.base_color.a), 0.0001) + 0.5;
    }
#endif
#endif
    var emissive = m.emissive;
#ifdef POMKIT_TEX_EMISSIVE
    emissive = vec4<f32>(emissive.rgb * textureSampleGrad(pbr_bindings::emissive_texture, pbr_bindings::emissive_sampler, uv, ddx, ddy).rgb, emissive.a);
#endif
    p.material.emissive = emissive;
    var metallic = m.metallic;
    var perceptual_roughness = m.perceptual_roughness;
#ifdef POMKIT_TEX_METALLIC_ROUGHNESS
    // glTF's channels: roughness in green, metallic in blue.
    let mr = textureSampleGrad(pbr_bindings::metallic_roughness_texture, pbr_bindings::metallic_roughness_sampler, uv, ddx, ddy);
    metallic *= mr.b;
    perceptual_roughness *= mr.g;
#endif
    p.material.metallic = metallic;
    p.material.perceptual_roughness = perceptual_roughness;
    var diffuse_occlusion = vec3<f32>(1.0);
    var specular_occlusion = 1.0;
#ifdef POMKIT_TEX_OCCLUSION
    diffuse_occlusion *= textureSampleGrad(pbr_bindings::occlusion_texture, pbr_bindings::occlusion_sampler, uv, ddx, ddy).r;
#endif
#ifndef POMKIT_BEVY_INPUT
#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
    // Screen-space ambient occlusion as the standard material combines it, with specular
    // occlusion from Lagarde and de Rousiers 2014 (Moving Frostbite to PBR).
    let ssao = textureLoad(screen_space_ambient_occlusion_texture, vec2<i32>(in.position.xy), 0i).r;
    diffuse_occlusion = min(diffuse_occlusion, ssao_multibounce(ssao, p.material.base_color.rgb));
    let n_dot_v = max(dot(p.N, p.V), 0.0001);
    let roughness = perceptual_roughness * perceptual_roughness;
    specular_occlusion = saturate(pow(n_dot_v + ssao, exp2(-16.0 * roughness - 1.0)) - 1.0 + ssao);
#endif
    p.diffuse_occlusion = diffuse_occlusion;
    p.specular_occlusion = specular_occlusion;
#else
    p.diffuse_occlusion = min(p.diffuse_occlusion, diffuse_occlusion);
#endif
#ifdef STANDARD_MATERIAL_NORMAL_MAP
#ifdef VERTEX_TANGENTS
    let tbn = pbr_functions::calculate_tbn_mikktspace(p.world_normal, in.world_tangent);
    let nt = textureSampleGrad(pbr_bindings::normal_map_texture, pbr_bindings::normal_map_sampler, uv, ddx, ddy).rgb;
    p.N = pbr_functions::apply_normal_mapping(flags, tbn, double_sided, is_front, nt);
#endif
#endif
#ifdef POMKIT_NORMALS
    if s.ready {
        p.N = surface_normal(s);
#ifdef POMKIT_FAR_COLOR
        // Seen from afar, the strands' tips make a surface along the polygon: its normal fades
        // in with the far colour (the height map's normals, which have no mips, would alias).
        p.N = pomkit_safe_normalize(mix(s.n, p.N, s.weight), s.n);
#endif
    }
#endif
    return p;
}

#ifdef PREPASS_PIPELINE

struct PomkitPrepassOutput {
#ifdef NORMAL_PREPASS
    @location(0) normal: vec4<f32>,
#endif
#ifdef MOTION_VECTOR_PREPASS
    @location(1) motion_vector: vec2<f32>,
#endif
#ifdef DEFERRED_PREPASS
    @location(2) deferred: vec4<u32>,
    @location(3) deferred_lighting_pass_id: u32,
#endif
#ifdef POMKIT_FRAG_DEPTH
    @builtin(frag_depth) frag_depth: f32,
#endif
}

#ifdef POMKIT_CONSERVATIVE_DEPTH
@early_depth_test(less_equal)
#endif
@fragment
fn fragment(
    in: VertexOutput,
    @builtin(front_facing) is_front: bool,
#ifdef POMKIT_SILHOUETTE
    @location(10) curvature: vec3<f32>,
#endif
) -> PomkitPrepassOutput {
#ifdef POMKIT_SILHOUETTE
    let s = trace_fragment(in, curvature);
#else
    let s = trace_fragment(in, vec3<f32>(0.0));
#endif
    pbr_prepass_functions::prepass_alpha_discard(in);
    var out: PomkitPrepassOutput;
#ifdef POMKIT_FRAG_DEPTH
    out.frag_depth = traced_depth(in, s);
#endif
#ifdef DEFERRED_PREPASS
    var p = standard_input(in, is_front, s);
    p.material.base_color = pbr_functions::alpha_discard(p.material, p.material.base_color);
    out.deferred = deferred_gbuffer_from_pbr_input(p);
    out.deferred_lighting_pass_id = p.material.deferred_lighting_pass_id;
#ifdef NORMAL_PREPASS
    out.normal = vec4<f32>(p.N * 0.5 + vec3<f32>(0.5), 1.0);
#endif
#else
#ifdef NORMAL_PREPASS
    var n = s.n;
#ifdef NORMAL_PREPASS_OR_DEFERRED_PREPASS
    n = normalize(in.world_normal);
#endif
#ifdef POMKIT_NORMALS
    if s.ready {
        n = surface_normal(s);
    }
#endif
    out.normal = vec4<f32>(n * 0.5 + vec3<f32>(0.5), 1.0);
#endif
#endif
#ifdef MOTION_VECTOR_PREPASS
    out.motion_vector = pbr_prepass_functions::calculate_motion_vector(in.world_position, in.previous_world_position);
#endif
#ifdef POMKIT_SILHOUETTE
    if s.left {
        discard;
    }
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

/// Bevy's lighting input for `p`, as its own PBR lighting builds it.
fn lighting_input(p: pbr_types::PbrInput) -> lighting::LightingInput {
    let metallic = p.material.metallic;
    let perceptual_roughness = p.material.perceptual_roughness;
    let n_dot_v = max(dot(p.N, p.V), 0.0001);
    var li: lighting::LightingInput;
    li.layers[lighting::LAYER_BASE].NdotV = n_dot_v;
    li.layers[lighting::LAYER_BASE].N = p.N;
    li.layers[lighting::LAYER_BASE].R = reflect(-p.V, p.N);
    li.layers[lighting::LAYER_BASE].perceptual_roughness = perceptual_roughness;
    li.layers[lighting::LAYER_BASE].roughness = lighting::perceptualRoughnessToRoughness(perceptual_roughness);
    li.P = p.world_position.xyz;
    li.V = p.V;
    li.diffuse_color = pbr_functions::calculate_diffuse_color(
        p.material.base_color.rgb,
        metallic,
        p.material.specular_transmission,
        p.material.diffuse_transmission,
    );
    li.metallic = metallic;
    li.F0_dielectric = pbr_functions::calculate_F0_dielectric(p.material.reflectance);
    li.F0_metallic = p.material.base_color.rgb;
    li.F_ab = lighting::F_AB(perceptual_roughness, n_dot_v);
#ifdef STANDARD_MATERIAL_CLEARCOAT
    let cc_roughness = p.material.clearcoat_perceptual_roughness;
    li.layers[lighting::LAYER_CLEARCOAT].NdotV = max(dot(p.clearcoat_N, p.V), 0.0001);
    li.layers[lighting::LAYER_CLEARCOAT].N = p.clearcoat_N;
    li.layers[lighting::LAYER_CLEARCOAT].R = reflect(-p.V, p.clearcoat_N);
    li.layers[lighting::LAYER_CLEARCOAT].perceptual_roughness = cc_roughness;
    li.layers[lighting::LAYER_CLEARCOAT].roughness = lighting::perceptualRoughnessToRoughness(cc_roughness);
    li.clearcoat_strength = p.material.clearcoat;
#endif
#ifdef STANDARD_MATERIAL_ANISOTROPY
    li.anisotropy = p.anisotropy_strength;
    li.Ta = p.anisotropy_T;
    li.Ba = p.anisotropy_B;
#endif
    return li;
}

/// Light that lights `p` and reaches it: Bevy's PBR lighting with pomkit's self-shadow folded
/// into every directional, point and spot light's direct light.
struct Lit {
    color: vec4<f32>,
    /// Self-shadow visibility of the first directional light.
    visibility: f32,
    /// Texture reads of the shadow traces.
    fetches: u32,
}

/// What a light's self-shadow trace needs: the light's world direction at the receiver.
fn self_shadow(s: Traced, l_world: vec3<f32>) -> vec2<f32> {
    if SHADOW_MODE == POMKIT_SHADOW_NONE {
        return vec2<f32>(1.0, 0.0);
    }
    // A light below the polygon's plane lights none of the relief (Tatarchuk 2006 skips the
    // trace there); its direct light is zero on the geometric side anyway.
    if !(dot(s.n, l_world) > 0.0) || !s.ready || !displaces() {
        return vec2<f32>(select(1.0, 0.0, s.ready && displaces()), 0.0);
    }
    let sh = pomkit_shadow(pomkit_heights, pomkit_pyramid, pomkit_sampler, params(), s.hit.uv, s.hit.depth, pomkit_light_ray(ray_terms(l_world, s), vec2<f32>(1.0)), s.lod);
    return vec2<f32>(sh.visibility, f32(sh.fetches));
}

fn lit(in: VertexOutput, s: Traced, p: pbr_types::PbrInput) -> Lit {
    var out: Lit;
    out.visibility = 1.0;
    out.fetches = 0u;
    let unlit = (p.material.flags & pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT) != 0u;
    if unlit {
        out.color = p.material.base_color;
        return out;
    }
#if POMKIT_SHADOW_MODE == 0
    out.color = pbr_functions::apply_pbr_lighting(p);
#else
    let receiver = (p.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u;
#ifdef POMKIT_BEVY_SHADOW_MAPS
    // Bevy's lighting applies the shadow maps (transmitted light or contact shadows need them
    // there); each self-shadowed light's shadowed share is then taken back out, which reads its
    // shadow map a second time.
    out.color = pbr_functions::apply_pbr_lighting(p);
    let maps_applied = true;
#else
    // Bevy's lighting without shadow maps, then each light's share that its shadow map or the
    // self-shadow removes taken out: one shadow-map read per light, as without pomkit.
    var q = p;
    q.flags = p.flags & ~MESH_FLAGS_SHADOW_RECEIVER_BIT;
    out.color = pbr_functions::apply_pbr_lighting(q);
    let maps_applied = false;
#endif
    var li = lighting_input(p);
    let view_z = dot(vec4<f32>(
        view.view_from_world[0].z,
        view.view_from_world[1].z,
        view.view_from_world[2].z,
        view.view_from_world[3].z
    ), p.world_position);
    var removed = vec3<f32>(0.0);
    for (var i = 0u; i < lights.n_directional_lights; i++) {
        let light = &lights.directional_lights[i];
        let v = self_shadow(s, (*light).direction_to_light);
        out.fetches += u32(v.y);
        if i == 0u {
            // The debug view shows the first directional light's self-shadow.
            out.visibility = v.x;
        }
        var map = 1.0;
        if receiver && ((*light).flags & mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            map = shadows::fetch_directional_shadow(i, p.world_position, p.world_normal, view_z, p.frag_coord.xy);
        }
        // The share of this light's unshadowed direct light that the picture must not hold.
        let share = select(1.0 - map * v.x, map * (1.0 - v.x), maps_applied);
        if share > 0.0 {
#ifdef LIGHTMAP
            let enable_diffuse = ((*light).flags & mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_AFFECTS_LIGHTMAPPED_MESH_DIFFUSE_BIT) != 0u;
#else
            let enable_diffuse = true;
#endif
            removed += share * lighting::directional_light(i, &li, enable_diffuse);
        }
    }
#ifdef POMKIT_POINT_LIGHTS
    // Point and spot lights of the fragment's cluster, as Bevy's lighting visits them (only
    // where the world has any: a GPU that runs every loop at least once would pay for an empty
    // one).
    let cluster = clustering::view_fragment_cluster_index(p.frag_coord.xy, view_z, p.is_orthographic);
    let ranges = clustering::unpack_clusterable_object_index_ranges(cluster);
    for (var i = ranges.first_point_light_index_offset; i < ranges.first_reflection_probe_index_offset; i++) {
        let id = clustering::get_clusterable_object_id(i);
        let light = &clustered_lights.data[id];
        let spot = i >= ranges.first_spot_light_index_offset;
        let hit_world = pomkit_hit_position(p.world_position.xyz, s.to_eye, s.n, s.hit.depth, pomkit.params.depth_scale, s.uv_scale);
        let v = self_shadow(s, normalize((*light).position_radius.xyz - hit_world));
        out.fetches += u32(v.y);
        if lights.n_directional_lights == 0u && i == ranges.first_point_light_index_offset {
            // With no directional light, the debug view shows the cluster's first point or spot
            // light's.
            out.visibility = v.x;
        }
        var map = 1.0;
        if receiver && ((*light).flags & mesh_view_types::POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            if spot {
                map = shadows::fetch_spot_shadow(id, p.world_position, p.world_normal, (*light).shadow_map_near_z, p.frag_coord.xy);
            } else {
                map = shadows::fetch_point_shadow(id, p.world_position, p.world_normal, p.frag_coord.xy);
            }
        }
        let share = select(1.0 - map * v.x, map * (1.0 - v.x), maps_applied);
        if share > 0.0 {
#ifdef LIGHTMAP
            let enable_diffuse = ((*light).flags & mesh_view_types::POINT_LIGHT_FLAGS_AFFECTS_LIGHTMAPPED_MESH_DIFFUSE_BIT) != 0u;
#else
            let enable_diffuse = true;
#endif
            if spot {
                removed += share * lighting::spot_light(id, &li, enable_diffuse);
            } else {
                removed += share * lighting::point_light(id, &li, enable_diffuse, true);
            }
        }
    }
#endif
    out.color = vec4<f32>(max(out.color.rgb - view.exposure * removed, vec3<f32>(0.0)), out.color.a);
#endif
    return out;
}

#ifdef POMKIT_CONSERVATIVE_DEPTH
#ifdef POMKIT_PIXEL_DEPTH
@early_depth_test(less_equal)
#endif
#endif
@fragment
fn fragment(
    in: VertexOutput,
    @builtin(front_facing) is_front: bool,
#ifdef POMKIT_SILHOUETTE
    @location(10) curvature: vec3<f32>,
#endif
) -> PomkitFragmentOutput {
#ifdef POMKIT_SILHOUETTE
    let s = trace_fragment(in, curvature);
#else
    let s = trace_fragment(in, vec3<f32>(0.0));
#endif
    var out: PomkitFragmentOutput;
#ifdef POMKIT_PIXEL_DEPTH
    out.frag_depth = traced_depth(in, s);
#endif
    var p = standard_input(in, is_front, s);
    p.material.base_color = pbr_functions::alpha_discard(p.material, p.material.base_color);
    apply_decals(&p);
    let l = lit(in, s, p);
#if POMKIT_DEBUG == 1
    out.color = vec4<f32>(s.hit.uv, s.hit.depth, 1.0);
#else if POMKIT_DEBUG == 2
    out.color = vec4<f32>(f32(s.fetches + l.fetches) / 64.0, s.weight, s.lod / 16.0, 1.0);
#else if POMKIT_DEBUG == 3
    out.color = vec4<f32>(l.visibility, s.weight, 0.0, 1.0);
#else
    out.color = pbr_functions::main_pass_post_lighting_processing(p, l.color);
#endif
#ifdef POMKIT_SILHOUETTE
    // A ray that left the relief: what lies behind shows (discarded last, after every
    // derivative and implicit-gradient sample of the shading).
    if s.left {
        discard;
    }
#endif
    return out;
}

#endif // PREPASS_PIPELINE
