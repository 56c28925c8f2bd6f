// pomkit's import pass: a host program's height texture -> mip 0 of pomkit's `heights` texture
// (crates/pomkit-gpu/src/host.rs, `HeightResource`).
//
// Reads one channel (or the Rec. 709 luma of R, G and B) of the host texture's mip 0 with
// `textureLoad` (no sampler, so any colour format whose samples are floats works: unorm, snorm,
// float, sRGB, filterable or not), turns it into pomkit's depth d in [0, 1] (0 = the polygon's
// surface, 1 = the deepest point; ARCHITECTURE.md, Conventions), and writes R = d,
// G = B = A = 0. `HeightPasses::encode` (height.wgsl) then derives G (the parallax value), the
// mips, the normals and the pyramid.
//
// Same rules as `HeightMaps::upload_depths` on the CPU: values outside [0, 1] are clamped, NaN
// becomes 1 (the deepest point), and the depth is rounded to the nearest f16 (ties to even). Infinities clamp like any other value. NaN and infinity
// are recognised from the bits, because WGSL lets a compiler assume float arithmetic never
// produces or meets them.

/// `Params::encoding`: the texture holds heights (white = high): d = 1 - value.
const ENCODING_HEIGHT: u32 = 0u;
/// `Params::encoding`: the texture holds depths (white = deep): d = value.
const ENCODING_DEPTH: u32 = 1u;

/// `Params::channel`: the Rec. 709 luma of R, G and B, `0.2126 R + 0.7152 G + 0.0722 B` (for
/// formats with all three; pomkit's command line and bevy_pomkit read colour height maps so).
const CHANNEL_LUMA: u32 = 4u;

struct Params {
    /// Texels to write (the host texture's mip 0 size, equal to `heights` mip 0's).
    size: vec2<u32>,
    /// Which channel holds the heights: 0 = R, 1 = G, 2 = B, 3 = A, or CHANNEL_LUMA.
    channel: u32,
    /// `ENCODING_HEIGHT` or `ENCODING_DEPTH`.
    encoding: u32,
}

@group(0) @binding(0) var source: texture_2d<f32>;
@group(0) @binding(1) var heights: texture_storage_2d<rgba16float, write>;
@group(0) @binding(2) var<uniform> params: Params;

/// `v` clamped to [0, 1], with NaN given as `nan_value`, decided on the bits.
fn clamp_unit(v: f32, nan_value: f32) -> f32 {
    let bits = bitcast<u32>(v);
    let magnitude = bits & 0x7fffffffu;
    if magnitude > 0x7f800000u {
        return nan_value;
    }
    if magnitude == 0x7f800000u {
        // +infinity -> 1, -infinity -> 0.
        return select(1.0, 0.0, (bits >> 31u) == 1u);
    }
    return clamp(v, 0.0, 1.0);
}

/// `x` rounded to the nearest f16 value (ties to even), still as f32: height.wgsl's
/// `f16_nearest` for one value. How a shader's f32 becomes f16 when stored to an rgba16float
/// texture is up to the implementation (lavapipe truncates toward zero); storing a value that
/// is exactly an f16 makes every GPU store the bits `HeightMaps::upload_depths` uploads.
fn f16_nearest(x: f32) -> f32 {
    let b = bitcast<u32>(x);
    let odd = (b >> 13u) & 1u;
    let normal = bitcast<f32>((b + 0xfffu + odd) & 0xffffe000u);
    let subnormal = round(x * 16777216.0) / 16777216.0;
    return select(normal, subnormal, abs(x) < 6.103515625e-5);
}

@compute @workgroup_size(8, 8)
fn import_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.size.x || id.y >= params.size.y {
        return;
    }
    let texel = textureLoad(source, vec2<i32>(id.xy), 0);
    var value = texel[min(params.channel, 3u)];
    if params.channel == CHANNEL_LUMA {
        value = 0.2126 * texel.r + 0.7152 * texel.g + 0.0722 * texel.b;
    }
    var depth: f32;
    if params.encoding == ENCODING_DEPTH {
        // NaN is the deepest point: depth 1.
        depth = clamp_unit(value, 1.0);
    } else {
        // NaN is the deepest point: height 0.
        depth = 1.0 - clamp_unit(value, 0.0);
    }
    textureStore(heights, vec2<i32>(id.xy), vec4<f32>(f16_nearest(depth), 0.0, 0.0, 0.0));
}
