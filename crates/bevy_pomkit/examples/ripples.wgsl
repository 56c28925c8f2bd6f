// Rain on a pond: the height map of examples/ripples.rs, written by a compute shader every frame.
//
// Each of `drops` rain drops falls again and again, at a pseudo-random place each time, and
// sends out a ring: a few crests around a front that spreads at a constant speed, damped with
// age and spreading (the amplitude of a ring falls as 1 / sqrt(radius), as a circular wave's
// does). Everything follows from the time alone, so any frame can be drawn again. The pond
// tiles: distances wrap around the unit square.
//
// Output: height in [0, 1] (0.5 still water, white high) in an r32float storage texture, which
// bevy_pomkit's GPU height build (HeightBuild::GpuEveryFrame) then turns into depths, mips,
// normals and the maximum-height pyramid in the same frame.

struct Rain {
    /// Seconds since the rain began.
    time: f32,
    /// Side of the square height map in texels.
    size: u32,
    /// Drops falling at once.
    drops: u32,
    pad: u32,
}

@group(0) @binding(0) var heights: texture_storage_2d<r32float, write>;
@group(0) @binding(1) var<uniform> rain: Rain;

/// A hash of `n` in [0, 1).
fn hash(n: u32) -> f32 {
    var k = n * 747796405u + 2891336453u;
    k = ((k >> ((k >> 28u) + 4u)) ^ k) * 277803737u;
    k = (k >> 22u) ^ k;
    return f32(k >> 8u) / 16777216.0;
}

/// Speed of a ring's front, UV units per second.
const SPEED: f32 = 0.11;
/// Distance between crests, UV units.
const WAVELENGTH: f32 = 0.018;

@compute @workgroup_size(8, 8)
fn rain_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= rain.size || id.y >= rain.size {
        return;
    }
    let uv = (vec2<f32>(id.xy) + 0.5) / f32(rain.size);
    var h = 0.0;
    for (var i = 0u; i < rain.drops; i++) {
        // Drop i falls every `period` seconds, its own phase apart from the others.
        let period = 2.2 + 1.6 * hash(i * 7u + 1u);
        let t = rain.time + period * hash(i * 13u + 5u);
        let cycle = u32(floor(t / period));
        let age = t - f32(cycle) * period;
        let drop_key = i * 7919u + cycle * 104729u;
        let centre = vec2<f32>(hash(drop_key + 11u), hash(drop_key + 23u));
        // The shortest way to the centre on the tiling pond.
        let d = abs(uv - centre);
        let r = length(min(d, 1.0 - d));
        // Crests behind the front only, fading in over a wavelength ahead of it.
        let x = (r - SPEED * age) / WAVELENGTH;
        let envelope = exp(-0.06 * x * x) * select(exp(-2.0 * x * x), 1.0, x < 0.0);
        let strength = (0.55 + 0.45 * hash(drop_key + 37u)) * exp(-1.1 * age) / sqrt(1.0 + r / WAVELENGTH);
        h += strength * envelope * cos(6.2831853 * x);
    }
    textureStore(heights, vec2<i32>(id.xy), vec4<f32>(clamp(0.5 + 0.42 * h, 0.0, 1.0), 0.0, 0.0, 1.0));
}
