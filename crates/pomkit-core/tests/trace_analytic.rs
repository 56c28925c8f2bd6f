//! Every technique against analytic height fields with known answers, the exact tracer against
//! an independent brute-force search, property tests over random rays, shadows and the LOD fade.

use pomkit_core::glam::{Vec2, Vec3};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::shadow::{ShadowMode, ShadowParams, lod_weight, shadow};
use pomkit_core::trace::{Hit, Ray, Surface, Technique, TraceParams, adaptive_samples, trace};
use pomkit_core::{EdgeMode, HeightField};
use proptest::prelude::*;

const N: u32 = 64;

fn surface(f: HeightField, edges: EdgeMode) -> Surface {
    Surface::new(f, edges, 0.1)
}

/// `surface` twice: `exact`'s walk on the least depths alone, and with plane bounds
/// (`Surface::use_plane_bounds`); the exact tests hold for both.
fn both_walks(f: HeightField, edges: EdgeMode, depth_scale: f32) -> [Surface; 2] {
    let plain = Surface::new(f, edges, depth_scale);
    let mut planes = plain.clone();
    planes.use_plane_bounds();
    [plain, planes]
}

/// Texel distance between two UVs on an N x N field.
fn texels(a: Vec2, b: Vec2) -> f32 {
    ((a - b) * N as f32).length()
}

/// Independent truth: pomkit_core::accuracy::brute_force_depth.
fn brute_force(f: &HeightField, edges: EdgeMode, ray: &Ray, depth_scale: f64) -> f64 {
    pomkit_core::accuracy::brute_force_depth(f, edges, ray, depth_scale)
}

/// The point of the ray at depth z.
fn on_ray(ray: &Ray, z: f64, depth_scale: f32) -> Vec2 {
    let d = ray.dir.normalize();
    ray.uv + Vec2::new(d.x, d.y) * (depth_scale / -d.z) * z as f32
}

fn rays_over(count: usize, angle_deg: f32, seed: u32) -> Vec<Ray> {
    (0..count)
        .map(|k| {
            let h = (k as u32).wrapping_mul(2_654_435_761) ^ seed.wrapping_mul(40_503);
            let u = (h % 1000) as f32 / 1000.0;
            let v = ((h / 1000) % 1000) as f32 / 1000.0;
            let az = (h % 6283) as f32 / 1000.0;
            Ray::at_angle(Vec2::new(u, v), angle_deg.to_radians(), az)
        })
        .collect()
}

/// Analytic fields with their names (pomkit_core::accuracy::analytic_fields).
fn analytic_fields() -> Vec<(&'static str, HeightField)> {
    pomkit_core::accuracy::analytic_fields(N)
}

#[test]
fn exact_matches_brute_force_on_analytic_fields_at_every_angle() {
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        for (name, f) in analytic_fields() {
            for (walk, s) in both_walks(f.clone(), edges, 0.1).iter().enumerate() {
                for angle in [0.0f32, 30.0, 60.0, 75.0, 85.0, 89.0] {
                    for ray in rays_over(24, angle, 7) {
                        let hit = trace(s, &ray, Technique::Exact, &TraceParams::default());
                        let truth = brute_force(&f, edges, &ray, 0.1);
                        let err = texels(hit.uv, on_ray(&ray, truth, 0.1));
                        assert!(
                            err < 1e-3,
                            "{name} {edges:?} walk {walk} {angle}deg {ray:?}: exact depth {} vs brute {truth}: {err} texels",
                            hit.depth
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn flat_field_gives_each_technique_its_stated_error() {
    let c = 0.4f32; // depth
    let s = surface(HeightField::constant(N, N, c), EdgeMode::Wrap);
    for angle in [0.0f32, 30.0, 60.0, 75.0] {
        for ray in rays_over(8, angle, 3) {
            let truth = on_ray(&ray, f64::from(c), 0.1);
            let p = TraceParams::default();
            let len = (on_ray(&ray, 1.0, 0.1) - ray.uv).length() * N as f32; // texels per unit depth
            let err = |t| texels(trace(&s, &ray, t, &p).uv, truth);
            // Linear profiles are found exactly by the piecewise-linear intersection.
            assert!(err(Technique::Exact) < 1e-3);
            assert!(err(Technique::Pom) < 1e-3, "pom {angle}");
            assert!(err(Technique::PomClassic) < 1e-3, "pom-classic {angle}");
            // Plane marching: within one plane spacing; relief within the binary step.
            assert!(err(Technique::Steep) <= len / p.samples as f32 + 1e-3, "steep {angle}");
            assert!(err(Technique::Relief) <= len / (p.samples as f32 * 64.0) + 1e-3, "relief {angle}");
            // Offset limiting shortens the shift by cos(theta): error c * len * (1 - cos).
            let limited = c * len * (1.0 - angle.to_radians().cos());
            assert!((err(Technique::Parallax) - limited).abs() < 1e-2, "parallax {angle}");
            assert!((err(Technique::Iterative) - limited).abs() < 1e-2, "iterative {angle}");
            // No offset at all: the whole shift c * len.
            assert!((err(Technique::Normal) - c * len).abs() < 1e-2);
            assert_eq!(trace(&s, &ray, Technique::Flat, &p).fetches, 0);
        }
    }
}

#[test]
fn tilted_plane_is_found_exactly_by_linear_intersections() {
    // A plane in u: the bilinear surface equals it away from the wrap seam; use clamp.
    let f = HeightField::from_height_fn(N, N, |x, _| 0.1 + 0.8 * x as f32 / (N - 1) as f32);
    let [s, planes] = both_walks(f.clone(), EdgeMode::Clamp, 0.1);
    let p = TraceParams::default();
    for angle in [0.0f32, 30.0, 60.0] {
        for ray in rays_over(16, angle, 11) {
            let ray = Ray { uv: ray.uv * 0.6 + 0.2, ..ray };
            let truth = on_ray(&ray, brute_force(&f, EdgeMode::Clamp, &ray, 0.1), 0.1);
            let exact = trace(&s, &ray, Technique::Exact, &p);
            assert!(texels(exact.uv, truth) < 1e-3);
            // The field is its own plane in every cell: the plane walk brackets the hit at once.
            let on_planes = trace(&planes, &ray, Technique::Exact, &p);
            assert!(texels(on_planes.uv, truth) < 1e-3, "planes {angle} {ray:?}");
            assert!(on_planes.fetches <= exact.fetches, "planes {angle} {ray:?}: {on_planes:?} vs {exact:?}");
            // Inside the texel-centre range the profile is linear: pom is exact there.
            let pom = trace(&s, &ray, Technique::Pom, &p);
            let inside = |uv: Vec2| uv.x > 0.5 / N as f32 && uv.x < 1.0 - 0.5 / N as f32;
            if inside(truth) && inside(ray.uv) {
                assert!(texels(pom.uv, truth) < 1e-2, "pom {angle} {ray:?}");
            }
        }
    }
}

#[test]
fn sampling_techniques_stay_within_a_step_on_smooth_fields() {
    // On the sphere cap and the pyramid, steep and pom err by at most about one sample spacing;
    // check the mean, which also shows the ordering steep > pom > exact.
    for (name, f) in analytic_fields().into_iter().filter(|(n, _)| *n == "sphere cap" || *n == "pyramid") {
        let s = surface(f.clone(), EdgeMode::Wrap);
        let p = TraceParams::default();
        let rays = rays_over(64, 60.0, 5);
        let mean = |t: Technique| {
            rays.iter().map(|r| texels(trace(&s, r, t, &p).uv, trace(&s, r, Technique::Exact, &p).uv)).sum::<f32>()
                / rays.len() as f32
        };
        let spacing = 0.1 * 60f32.to_radians().tan() * N as f32 / p.samples as f32;
        let (steep, pom) = (mean(Technique::Steep), mean(Technique::Pom));
        assert!(steep <= spacing, "{name}: steep {steep} vs spacing {spacing}");
        assert!(pom < steep, "{name}: pom {pom} should beat steep {steep}");
        assert!(mean(Technique::Relief) < steep, "{name}: relief should beat steep");
    }
}

#[test]
fn exact_finds_the_one_texel_spike_at_85_degrees_where_pom_misses() {
    let f = generate(Pattern::Spike, N, N);
    let [s, planes] = both_walks(f.clone(), EdgeMode::Wrap, 0.1);
    let p = TraceParams { min_samples: 32, max_samples: 32, ..TraceParams::default() };
    // The spike's centre is texel (32, 32): aim rays along +u to pass over it at depths around
    // a half, and count how many each technique sees.
    let centre = Vec2::splat((N / 2) as f32 + 0.5) / N as f32;
    let dir = Ray::at_angle(Vec2::ZERO, 85f32.to_radians(), 0.0).dir;
    let per_depth = on_ray(&Ray::new(Vec2::ZERO, dir), 1.0, 0.1);
    let (mut exact_hits, mut pom_hits) = (0, 0);
    for k in 0..20 {
        let z = 0.3 + 0.02 * k as f32;
        let ray = Ray::new(centre - per_depth * z, dir);
        let truth = brute_force(&f, EdgeMode::Wrap, &ray, 0.1);
        assert!(truth < 0.9, "the spike is in this ray's path (depth {truth})");
        let exact = trace(&s, &ray, Technique::Exact, &p);
        assert!(texels(exact.uv, on_ray(&ray, truth, 0.1)) < 1e-3);
        let on_planes = trace(&planes, &ray, Technique::Exact, &p);
        assert!(texels(on_planes.uv, on_ray(&ray, truth, 0.1)) < 1e-3, "planes {ray:?}");
        exact_hits += usize::from(exact.depth < 0.9);
        pom_hits += usize::from(trace(&s, &ray, Technique::Pom, &p).depth < 0.9);
    }
    assert_eq!(exact_hits, 20);
    assert!(pom_hits <= 10, "pom with 32 samples should miss the spike on most of these rays ({pom_hits}/20 seen)");
}

#[test]
fn exact_ends_on_a_floor_at_depth_one_without_descending_to_its_patches() {
    // A cell whose least depth is 1, the deepest a field holds, is a flat floor: the walk meets
    // it where the ray reaches depth 1, without a fetch per level down to level 0 and a patch.
    // The same floor a little higher (depth 1 - 2^-10) must be descended to, so every ray takes
    // more fetches there; both hits are where the ray reaches the floor's depth.
    let n = 512;
    let higher = 1.0 - 1.0 / 1024.0;
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        let [floor, floor_planes] = both_walks(HeightField::constant(n, n, 1.0), edges, 0.1);
        let raised = Surface::new(HeightField::constant(n, n, higher), edges, 0.1);
        for angle in [0.0f32, 30.0, 60.0, 75.0, 85.0, 89.0] {
            for ray in rays_over(24, angle, 11) {
                let p = TraceParams::default();
                let (a, b) = (trace(&floor, &ray, Technique::Exact, &p), trace(&raised, &ray, Technique::Exact, &p));
                // The plane walk takes the same shortcut (its fetches differ: it starts higher).
                let c = trace(&floor_planes, &ray, Technique::Exact, &p);
                for (hit, z) in [(a, 1.0f32), (b, higher), (c, 1.0)] {
                    let texels = ((hit.uv - on_ray(&ray, f64::from(z), 0.1)) * n as f32).length();
                    assert!((hit.depth - z).abs() < 1e-5 && texels < 1e-3, "{edges:?} {angle}deg {ray:?}: {hit:?}");
                }
                assert!(a.fetches < b.fetches, "{edges:?} {angle}deg {ray:?}: {} vs {} fetches", a.fetches, b.fetches);
            }
        }
    }
}

#[test]
fn adaptive_sample_count_grows_toward_grazing() {
    assert_eq!(adaptive_samples(1.0, 8, 32), 8);
    assert_eq!(adaptive_samples(0.0, 8, 32), 32);
    assert_eq!(adaptive_samples(0.5, 8, 32), 20);
    assert!(adaptive_samples(0.2, 8, 50) > adaptive_samples(0.8, 8, 50));
    assert_eq!(adaptive_samples(f32::NAN, 8, 32), 32);
}

#[test]
fn refinement_reduces_pom_error() {
    let f = generate(Pattern::Cobblestones, N, N);
    let s = surface(f, EdgeMode::Wrap);
    let rays = rays_over(200, 75.0, 9);
    let mean = |refine: u32| {
        let p = TraceParams { refine, ..TraceParams::default() };
        rays.iter()
            .map(|r| texels(trace(&s, r, Technique::Pom, &p).uv, trace(&s, r, Technique::Exact, &p).uv))
            .sum::<f32>()
    };
    assert!(mean(2) < mean(0), "secant steps should help on average");
}

#[test]
fn back_facing_and_degenerate_rays_return_the_entry_point() {
    let s = surface(generate(Pattern::Bricks, N, N), EdgeMode::Wrap);
    let p = TraceParams::default();
    for dir in
        [Vec3::new(0.3, 0.0, 0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::ZERO, Vec3::NAN, Vec3::new(0.0, 0.0, f32::INFINITY)]
    {
        for t in Technique::ALL {
            let hit = trace(&s, &Ray::new(Vec2::new(0.3, 0.4), dir), t, &p);
            assert_eq!(hit, Hit { uv: Vec2::new(0.3, 0.4), depth: 0.0, fetches: 0 }, "{t} {dir}");
        }
    }
}

#[test]
fn parameters_are_validated_and_sanitized() {
    let bad = [
        TraceParams { perspective_bias: f32::INFINITY, ..Default::default() },
        TraceParams { min_samples: 40, max_samples: 8, ..Default::default() },
    ];
    for p in bad {
        assert!(p.validate().is_err(), "{p:?}");
    }
    for bad in [0.0, -1.0, f32::NAN] {
        assert!(pomkit_core::trace::check_depth_scale(bad).is_err(), "{bad}");
    }
    // Huge and zero counts are clamped, never hang.
    let s = surface(generate(Pattern::Waves, 16, 16), EdgeMode::Wrap);
    let p =
        TraceParams { samples: u32::MAX, max_samples: u32::MAX, min_samples: 0, iterations: 0, ..Default::default() };
    let ray = Ray::at_angle(Vec2::splat(0.5), 1.0, 0.3);
    for t in Technique::ALL {
        let hit = trace(&s, &ray, t, &p);
        assert!(hit.fetches <= t.fetch_bound(&p, &s), "{t}");
    }
    assert!("pom-classic".parse::<Technique>().is_ok());
    assert!("POM".parse::<Technique>().is_ok());
    assert_eq!("cone".parse::<Technique>(), Ok(Technique::Cone));
    assert!("cones".parse::<Technique>().unwrap_err().to_string().contains("pom-classic"));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    #[test]
    fn random_rays_give_finite_hits_on_the_segment(
        u in -2.0f32..3.0, v in -2.0f32..3.0,
        dx in -1.0f32..1.0, dy in -1.0f32..1.0, dz in prop_oneof![Just(0.0f32), Just(-1e-7f32), Just(-1.0f32), -1.0f32..0.2],
        seed in 0u32..4, wrap in any::<bool>(), scale in 0.01f32..0.5,
    ) {
        let pattern = [Pattern::Cobblestones, Pattern::Spike, Pattern::Text, Pattern::Bricks][seed as usize];
        let edges = if wrap { EdgeMode::Wrap } else { EdgeMode::Clamp };
        let s = Surface::new(generate(pattern, 24, 17), edges, scale);
        let p = TraceParams::default();
        let ray = Ray::new(Vec2::new(u, v), Vec3::new(dx, dy, dz));
        for t in Technique::ALL {
            let hit = trace(&s, &ray, t, &p);
            prop_assert!(hit.uv.is_finite() && hit.depth.is_finite(), "{t}: {hit:?}");
            prop_assert!((0.0..=1.0).contains(&hit.depth), "{t}: depth {}", hit.depth);
            prop_assert!(hit.fetches <= t.fetch_bound(&p, &s), "{t}: {} fetches", hit.fetches);
            // The hit lies on the traced segment (pom-classic's may be shortened by its bias,
            // which is 1 here, so it too lies on the ray).
            if dz < 0.0 && (dx != 0.0 || dy != 0.0 || dz != 0.0) {
                let d = ray.dir.normalize();
                if -d.z >= pomkit_core::trace::MIN_COS {
                    let expect = ray.uv + Vec2::new(d.x, d.y) * (scale / -d.z) * hit.depth;
                    let tol = 1e-4 * (1.0 + (expect - ray.uv).length());
                    prop_assert!((hit.uv - expect).length() <= tol, "{t}: {:?} vs {expect:?}", hit.uv);
                }
            }
        }
    }
}

// ---- shadows ----

/// Depth 1 everywhere except a wall of columns 30..34 at depth 0 (height 1).
fn wall() -> HeightField {
    HeightField::from_height_fn(N, N, |x, _| if (30..34).contains(&x) { 1.0 } else { 0.0 })
}

#[test]
fn a_point_behind_a_wall_is_shadowed_and_one_in_front_is_lit() {
    let s = surface(wall(), EdgeMode::Clamp);
    let p = TraceParams::default();
    // Receiver at depth 1, 6 texels left of the wall; light low from +u (behind the wall) or
    // from -u (in front).
    let uv = Vec2::new(24.5 / N as f32, 0.5);
    let from_behind = Vec3::new(0.8, 0.0, 0.3);
    let from_front = Vec3::new(-0.8, 0.0, 0.3);
    for mode in [ShadowMode::Hard, ShadowMode::Soft, ShadowMode::Exact] {
        let sp = ShadowParams { mode, softness: 0.05 };
        let behind = shadow(&s, uv, 1.0, from_behind, &sp, &p);
        let front = shadow(&s, uv, 1.0, from_front, &sp, &p);
        assert!(behind.visibility < 0.05, "{mode:?}: {behind:?}");
        assert!(front.visibility > 0.95, "{mode:?}: {front:?}");
        assert!(behind.fetches > 0);
        // Facing away from the light: no trace, no light.
        assert_eq!(shadow(&s, uv, 1.0, Vec3::new(0.0, 0.0, -1.0), &sp, &p).fetches, 0);
        assert_eq!(shadow(&s, uv, 1.0, Vec3::new(0.0, 0.0, -1.0), &sp, &p).visibility, 0.0);
        // On top of the wall (depth 0) nothing can shadow.
        assert_eq!(shadow(&s, Vec2::new(31.5 / N as f32, 0.5), 0.0, from_behind, &sp, &p).visibility, 1.0);
    }
}

#[test]
fn soft_shadow_lies_in_unit_range_and_lightens_with_blocker_distance() {
    let s = surface(wall(), EdgeMode::Clamp);
    let p = TraceParams { min_samples: 64, max_samples: 64, ..TraceParams::default() };
    let sp = ShadowParams { mode: ShadowMode::Soft, softness: 0.3 };
    // Light from +u at 45 degrees; receivers at depth 1 farther and farther left of the wall.
    let light = Vec3::new(1.0, 0.0, 1.0);
    let mut last = -1.0f32;
    let mut values = vec![];
    for dist in [1.0f32, 2.0, 4.0, 6.0, 8.0, 10.0, 14.0] {
        let uv = Vec2::new((30.0 - dist) / N as f32, 0.5);
        let v = shadow(&s, uv, 1.0, light, &sp, &p).visibility;
        assert!((0.0..=1.0).contains(&v));
        assert!(v >= last - 1e-6, "visibility should not drop as the blocker recedes: {values:?} then {v}");
        last = v;
        values.push(v);
    }
    assert!(values[0] < 0.1 && *values.last().unwrap() > 0.9, "{values:?}");
    assert!(values.iter().any(|&v| v > 0.1 && v < 0.9), "a penumbra between: {values:?}");
}

#[test]
fn exact_shadow_agrees_with_brute_force_over_random_points() {
    let f = generate(Pattern::Cobblestones, N, N);
    let s = surface(f.clone(), EdgeMode::Wrap);
    let p = TraceParams::default();
    let sp = ShadowParams { mode: ShadowMode::Exact, ..Default::default() };
    let light = Vec3::new(0.7, -0.3, 0.5);
    let mut disagreements = 0;
    for ray in rays_over(150, 40.0, 21) {
        let hit = trace(&s, &ray, Technique::Exact, &p);
        let vis = shadow(&s, hit.uv, hit.depth, light, &sp, &p).visibility;
        // Brute force: march toward the light in tiny steps; shadowed if clearly below.
        let l = light.normalize();
        let step = Vec2::new(l.x, l.y) * (0.1 / l.z);
        let mut blocked = false;
        for k in 1..4000 {
            let t = hit.depth * k as f32 / 4000.0;
            let z = hit.depth - t;
            if s.field().sample_bilinear(hit.uv + step * t, EdgeMode::Wrap) < z - 1e-3 {
                blocked = true;
                break;
            }
        }
        if blocked != (vis == 0.0) {
            disagreements += 1;
        }
    }
    // Grazing contacts within the 1e-3 tolerance may legitimately differ.
    assert!(disagreements <= 2, "{disagreements} disagreements");
}

#[test]
fn lod_weight_fades_continuously_over_the_last_level() {
    let th = 4.0;
    assert_eq!(lod_weight(0.0, th), 1.0);
    assert_eq!(lod_weight(3.0, th), 1.0);
    assert_eq!(lod_weight(3.25, th), 0.75);
    assert_eq!(lod_weight(4.0, th), 0.0);
    assert_eq!(lod_weight(9.0, th), 0.0);
    let mut x = 0.0f32;
    while x < 8.0 {
        let d = 1e-3;
        assert!((lod_weight(x + d, th) - lod_weight(x, th)).abs() <= d * 1.01 + 1e-6, "jump at {x}");
        x += 0.01;
    }
    assert_eq!(lod_weight(f32::NAN, th), 1.0);
}

#[test]
fn one_sample_techniques_are_continuous_at_normal_incidence() {
    let s = surface(generate(Pattern::Pyramids, N, N), EdgeMode::Wrap);
    let p = TraceParams::default();
    let uv = Vec2::new(0.3, 0.3);
    for t in [Technique::Parallax, Technique::Iterative, Technique::Exact, Technique::Pom] {
        let straight = trace(&s, &Ray::new(uv, Vec3::new(0.0, 0.0, -1.0)), t, &p);
        let tilted = trace(&s, &Ray::new(uv, Vec3::new(1e-3, 0.0, -1.0)), t, &p);
        assert!((straight.depth - tilted.depth).abs() < 1e-3, "{t}: {} vs {}", straight.depth, tilted.depth);
        assert!(straight.depth > 0.1, "{t}: the pyramids are not at the surface here");
    }
}

// ---- hardening: huge UVs, any direction length, bounded parameters, bounded loops ----

/// The cobblestones of a reported hang's repro: `builtin:cobblestones:64x64`.
fn cobblestones() -> HeightField {
    generate(Pattern::Cobblestones, N, N)
}

#[test]
fn huge_uvs_with_wrapping_edges_trace_as_the_same_ray_in_the_first_tile() {
    // The reported ray: u = 1e15 spun forever in `exact`. f32(1e15) = 999999986991104 is a whole
    // number of tiles (f32 spacing there is 2^26), so with wrapping edges the ray meets the
    // surface exactly as the same ray entering at u = 0 does: the independent truth is the
    // brute-force search on that ray, and the hit's u is the entry's, to f32 precision.
    let f = cobblestones();
    let s = surface(f.clone(), EdgeMode::Wrap);
    let p = TraceParams::default();
    let dir = Vec3::new(0.5, 0.2, -0.6);
    for u in [1e15f32, 3e14, -1e15, 1e30, f32::MAX] {
        let ray = Ray::new(Vec2::new(u, 0.3), dir);
        let reduced = Ray::new(Vec2::new(0.0, 0.3), dir);
        let truth = brute_force(&f, EdgeMode::Wrap, &reduced, 0.1);
        for t in Technique::ALL {
            let hit = trace(&s, &ray, t, &p);
            let small = trace(&s, &reduced, t, &p);
            assert!(hit.uv.is_finite() && (0.0..=1.0).contains(&hit.depth), "{t} at u = {u}: {hit:?}");
            assert_eq!((hit.depth, hit.fetches), (small.depth, small.fetches), "{t} at u = {u}");
            assert_eq!(hit.uv.y, small.uv.y, "{t} at u = {u}");
            // The hit u is the entry tile plus the reduced hit, rounded once to f32.
            let expect = (f64::from(u) + f64::from(small.uv.x)) as f32;
            assert_eq!(hit.uv.x, expect, "{t} at u = {u}");
            assert!((f64::from(hit.uv.x) - f64::from(u)).abs() <= f64::from(u.abs()) * 1e-7, "{t} at u = {u}");
        }
        let exact = trace(&s, &ray, Technique::Exact, &p);
        assert!((f64::from(exact.depth) - truth).abs() < 1e-4, "exact at u = {u}: {} vs {truth}", exact.depth);
    }
    // A tile offset that f32 still resolves: the hit is the reduced hit moved by whole tiles.
    for (u, v) in [(4096.3f32, -77.6f32), (-3.7, 12.25), (1.0e6 + 0.5, 0.3)] {
        let ray = Ray::new(Vec2::new(u, v), dir);
        let (ku, kv) = (f64::from(u).floor(), f64::from(v).floor());
        let reduced = Ray::new(Vec2::new((f64::from(u) - ku) as f32, (f64::from(v) - kv) as f32), dir);
        let truth = brute_force(&f, EdgeMode::Wrap, &reduced, 0.1);
        let hit = trace(&s, &ray, Technique::Exact, &p);
        assert!((f64::from(hit.depth) - truth).abs() < 1e-4, "({u}, {v}): {} vs {truth}", hit.depth);
        let on = on_ray(&reduced, truth, 0.1);
        let expect = Vec2::new((f64::from(on.x) + ku) as f32, (f64::from(on.y) + kv) as f32);
        let tol = 2.0 * f32::EPSILON * u.abs().max(v.abs()).max(1.0) + 1e-4 / N as f32;
        assert!((hit.uv - expect).abs().max_element() <= tol, "({u}, {v}): {:?} vs {expect:?}", hit.uv);
    }
}

#[test]
fn exact_handles_rays_along_texel_walls_and_through_corners() {
    // Rays entering exactly on texel boundaries and creeping along them (the walk's cell
    // choice on a wall), against the brute-force truth.
    let f = cobblestones();
    for (edges, s) in
        [EdgeMode::Wrap, EdgeMode::Clamp].into_iter().flat_map(|e| both_walks(f.clone(), e, 0.1).map(|s| (e, s)))
    {
        let p = TraceParams::default();
        for (uv, dir) in [
            (Vec2::new(0.3, 0.5), Vec3::new(0.5, -1e-7, -0.6)),
            (Vec2::new(0.5, 0.3), Vec3::new(-1e-7, 0.5, -0.6)),
            (Vec2::new(0.25, 0.5), Vec3::new(-0.5, -0.5, -0.3)),
            (Vec2::new(0.25, 0.5), Vec3::new(0.5, 0.5, -0.3)),
            (Vec2::new(0.125, 0.75), Vec3::new(0.0, -1.0, -0.2)),
        ] {
            let ray = Ray::new(uv, dir);
            let hit = trace(&s, &ray, Technique::Exact, &p);
            let truth = brute_force(&f, edges, &ray, 0.1);
            let walk = if s.plane_bounds().is_some() { "planes" } else { "least depths" };
            assert!(
                texels(hit.uv, on_ray(&ray, truth, 0.1)) < 1e-3,
                "{edges:?} {walk} {ray:?}: {hit:?} vs depth {truth}"
            );
            assert!(hit.fetches <= Technique::Exact.fetch_bound(&p, &s));
        }
    }
}

#[test]
fn direction_length_does_not_matter() {
    // The help promises that directions need not be unit length: (1e20, 1e20, -1e20) and
    // (1e-30, 1e-30, -1e-30) overflowed or underflowed f32 normalization and returned the entry
    // point with no fetch. Scaled by a power of two the direction is exactly the same ray.
    let s = surface(cobblestones(), EdgeMode::Wrap);
    let p = TraceParams::default();
    let uv = Vec2::new(0.3, 0.4);
    for unit in [Vec3::new(1.0, 1.0, -1.0), Vec3::new(0.5, 0.2, -0.6), Vec3::new(-0.9, 0.1, -0.05)] {
        for t in Technique::ALL {
            let want = trace(&s, &Ray::new(uv, unit), t, &p);
            for scale in [2f32.powi(100), 2f32.powi(-100), 2f32.powi(-140)] {
                let got = trace(&s, &Ray::new(uv, unit * scale), t, &p);
                if (unit * scale).abs().max_element() > 0.0 && (unit * scale / scale) == unit {
                    assert_eq!(got, want, "{t} {unit} x {scale:e}");
                }
            }
            // Decimal scalings round each component: the same ray to f32 precision.
            for scale in [1e20f32, 1e-30, 1e30] {
                let got = trace(&s, &Ray::new(uv, unit * scale), t, &p);
                assert_eq!(got.fetches > 0, want.fetches > 0, "{t} {unit} x {scale:e}");
                assert!(texels(got.uv, want.uv) < 0.05, "{t} {unit} x {scale:e}: {got:?} vs {want:?}");
            }
        }
    }
    // The reported directions, as written.
    for dir in [Vec3::new(1e20, 1e20, -1e20), Vec3::new(1e-30, 1e-30, -1e-30)] {
        let got = trace(&s, &Ray::new(uv, dir), Technique::Exact, &p);
        let want = trace(&s, &Ray::new(uv, Vec3::new(1.0, 1.0, -1.0)), Technique::Exact, &p);
        assert_eq!(got, want, "{dir}");
        assert!(got.fetches > 0 && got.depth > 0.0);
    }
    // Zero and non-entering directions keep their documented result: the entry point.
    for dir in [Vec3::ZERO, Vec3::new(1e-30, 0.0, 1e-30), Vec3::new(1e20, 0.0, 0.0)] {
        assert_eq!(trace(&s, &Ray::new(uv, dir), Technique::Pom, &p), Hit { uv, depth: 0.0, fetches: 0 });
    }
    // Lights too: a huge or tiny light vector is the same light.
    let sp = ShadowParams { mode: ShadowMode::Exact, ..Default::default() };
    let hit = trace(&s, &Ray::new(uv, Vec3::new(0.5, 0.2, -0.6)), Technique::Exact, &p);
    let light = Vec3::new(-0.5, 0.25, 0.5);
    let want = shadow(&s, hit.uv, hit.depth, light, &sp, &p);
    for scale in [2f32.powi(100), 2f32.powi(-120)] {
        assert_eq!(shadow(&s, hit.uv, hit.depth, light * scale, &sp, &p), want);
    }
}

#[test]
fn depth_scale_and_perspective_bias_are_bounded() {
    use pomkit_core::trace::{MAX_DEPTH_SCALE, MAX_PERSPECTIVE_BIAS, MIN_PERSPECTIVE_BIAS, TraceParamError};
    use pomkit_core::trace::{check_depth_scale, sanitized_depth_scale};
    let ok = |p: TraceParams| p.validate().is_ok();
    assert!(check_depth_scale(MAX_DEPTH_SCALE).is_ok());
    assert!(check_depth_scale(1e-6).is_ok());
    for bad in [16.001f32, 1e4, 1e14, 1e20, 1e30, f32::INFINITY] {
        let e = check_depth_scale(bad).unwrap_err();
        assert_eq!(e, TraceParamError::DepthScale(bad));
        assert!(e.to_string().contains("depth_scale") && e.to_string().contains("at most 16"), "{e}");
    }
    assert!(ok(TraceParams { perspective_bias: MIN_PERSPECTIVE_BIAS, ..Default::default() }));
    assert!(ok(TraceParams { perspective_bias: MAX_PERSPECTIVE_BIAS, ..Default::default() }));
    assert!(ok(TraceParams { perspective_bias: 0.5, ..Default::default() }));
    for bad in [-1.0f32, -1e-6, 1.0001, 1.5, 1e30, f32::NAN] {
        let e = TraceParams { perspective_bias: bad, ..Default::default() }.validate().unwrap_err();
        assert!(matches!(e, TraceParamError::PerspectiveBias(_)), "{bad}: {e}");
        assert!(e.to_string().contains("perspective_bias") && e.to_string().contains("[0, 1]"), "{e}");
    }
    // Sanitizing clamps to the same bounds, so a library caller who skips validation still
    // gets a bounded trace.
    let p = TraceParams { perspective_bias: 1e30, ..Default::default() }.sanitized();
    assert_eq!(p.perspective_bias, MAX_PERSPECTIVE_BIAS);
    assert_eq!(sanitized_depth_scale(1e30), MAX_DEPTH_SCALE);
    // A surface is built for the sanitized depth scale whatever it is given; the default (the
    // parameter table's) stands in for values that are no depth at all.
    let field = generate(Pattern::Waves, 8, 8);
    for (given, used) in [(1e30, MAX_DEPTH_SCALE), (f32::INFINITY, 0.1), (f32::NAN, 0.1), (-2.0, 0.1), (0.25, 0.25)] {
        assert_eq!(Surface::new(field.clone(), EdgeMode::Wrap, given).depth_scale(), used, "{given}");
    }
    let p = TraceParams { perspective_bias: -1.0, ..Default::default() }.sanitized();
    assert_eq!(p.perspective_bias, MIN_PERSPECTIVE_BIAS);
}

#[test]
fn exact_at_the_largest_depth_scale_still_matches_brute_force() {
    // The deepest relief accepted, at a grazing 85 degrees: the ray crosses about 180 tiles.
    let f = cobblestones();
    let depth = pomkit_core::trace::MAX_DEPTH_SCALE;
    let p = TraceParams::default();
    for s in both_walks(f.clone(), EdgeMode::Wrap, depth) {
        for ray in rays_over(3, 85.0, 13) {
            let hit = trace(&s, &ray, Technique::Exact, &p);
            let truth = brute_force(&f, EdgeMode::Wrap, &ray, f64::from(depth));
            assert!((f64::from(hit.depth) - truth).abs() < 1e-5, "{ray:?}: {} vs {truth}", hit.depth);
            assert!(hit.fetches <= Technique::Exact.fetch_bound(&p, &s));
        }
    }
}

/// Directions of every length and slant: unit-ish, grazing, huge and tiny.
fn any_direction() -> impl Strategy<Value = Vec3> {
    let c = prop_oneof![Just(0.0f32), -1.0f32..1.0, Just(1e-38), Just(-1e-30)];
    let len = prop_oneof![Just(1.0f32), Just(1e30), Just(1e20), Just(1e-30), Just(1e-40), 1e-3f32..1e3];
    let dz = prop_oneof![Just(-1e-7f32), Just(-1e-4), Just(0.0), -1.0f32..0.1];
    (c.clone(), c, dz, len).prop_map(|(x, y, z, l)| Vec3::new(x, y, z) * l)
}

/// UV coordinates from the first tile up to 1e30 and beyond, of either sign.
fn any_coordinate() -> impl Strategy<Value = f32> {
    prop_oneof![
        -2.0f32..3.0,
        (1.0f32..1e30).prop_map(|x| x),
        (1.0f32..1e30).prop_map(|x| -x),
        Just(3e14f32),
        Just(1e15),
        Just(f32::MAX),
        Just(-f32::MAX),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 160, ..ProptestConfig::default() })]
    #[test]
    fn every_technique_and_shadow_mode_is_finite_and_within_its_fetch_bound(
        u in any_coordinate(), v in any_coordinate(), dir in any_direction(), light in any_direction(),
        pattern in 0usize..4, wrap in any::<bool>(), planes in any::<bool>(),
        depth_scale in prop_oneof![0.001f32..0.5, Just(16.0f32), Just(1e30), Just(1e-30)],
        bias in prop_oneof![Just(1.0f32), Just(0.0), Just(-1.0), Just(1e30), 0.0f32..1.0],
    ) {
        let pattern = [Pattern::Cobblestones, Pattern::Spike, Pattern::Text, Pattern::Bricks][pattern];
        let edges = if wrap { EdgeMode::Wrap } else { EdgeMode::Clamp };
        let mut s = Surface::new(generate(pattern, 24, 17), edges, depth_scale);
        if planes {
            s.use_plane_bounds();
        }
        let p = TraceParams { perspective_bias: bias, ..Default::default() };
        let ray = Ray::new(Vec2::new(u, v), dir);
        // The light as a direction toward it: flip the view-style z so most rays go up.
        let light = Vec3::new(light.x, light.y, -light.z);
        for t in Technique::ALL {
            let hit = trace(&s, &ray, t, &p);
            prop_assert!(hit.uv.is_finite() && hit.depth.is_finite(), "{t}: {hit:?}");
            prop_assert!((0.0..=1.0).contains(&hit.depth), "{t}: depth {}", hit.depth);
            prop_assert!(hit.fetches <= t.fetch_bound(&p, &s), "{t}: {} fetches", hit.fetches);
            for mode in ShadowMode::ALL {
                let sp = ShadowParams { mode, softness: 0.1 };
                let sh = shadow(&s, hit.uv, hit.depth, light, &sp, &p);
                prop_assert!((0.0..=1.0).contains(&sh.visibility), "{t} {mode:?}: {sh:?}");
                prop_assert!(sh.fetches <= mode.fetch_bound(&p, &s), "{t} {mode:?}: {} fetches", sh.fetches);
            }
        }
    }
}

#[test]
fn cone_matches_brute_force_on_analytic_fields_at_every_angle() {
    // With the conservative cones pomkit builds, cone stepping skips only empty space and solves
    // the bilinear patches where it cannot skip: the hit is the exact one.
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        for (name, f) in analytic_fields() {
            let s = surface(f.clone(), edges);
            for angle in [0.0f32, 30.0, 60.0, 75.0, 85.0, 89.0] {
                for ray in rays_over(24, angle, 7) {
                    let hit = trace(&s, &ray, Technique::Cone, &TraceParams::default());
                    let truth = brute_force(&f, edges, &ray, 0.1);
                    let err = texels(hit.uv, on_ray(&ray, truth, 0.1));
                    assert!(
                        err < 1e-3,
                        "{name} {edges:?} {angle}deg {ray:?}: cone depth {} vs brute {truth}: {err} texels",
                        hit.depth
                    );
                }
            }
        }
    }
}

#[test]
fn cone_finds_what_exact_finds_on_the_built_in_maps_at_grazing_angles() {
    // The two walks share nothing but the patch solver: a pyramid against cones.
    for (pattern, edges) in
        [(Pattern::Bricks, EdgeMode::Wrap), (Pattern::Cobblestones, EdgeMode::Clamp), (Pattern::Text, EdgeMode::Wrap)]
    {
        let s = Surface::new(generate(pattern, 128, 128), edges, 0.1);
        let p = TraceParams::default();
        for angle in [75.0f32, 85.0, 89.0] {
            for ray in rays_over(300, angle, 11) {
                let (a, b) = (trace(&s, &ray, Technique::Cone, &p), trace(&s, &ray, Technique::Exact, &p));
                let err = ((a.uv - b.uv) * 128.0).length();
                assert!(
                    err < 1e-3,
                    "{pattern:?} {edges:?} {angle}deg {ray:?}: cone {} exact {}: {err} texels",
                    a.depth,
                    b.depth
                );
                assert!(
                    a.fetches <= Technique::Cone.fetch_bound(&p, &s),
                    "{pattern:?} {angle}deg: {} fetches",
                    a.fetches
                );
            }
        }
    }
}

#[test]
fn a_baked_cone_map_read_back_gives_the_same_hits() {
    // A map read from its 16-bit image counts as relaxed (the tracer looks after each cone step);
    // its quantized cones are still conservative, so the hits stay exact.
    let f = generate(Pattern::Cobblestones, 96, 96);
    let built = Surface::new(f.clone(), EdgeMode::Wrap, 0.1);
    let samples = built.cones().to_gray_alpha16();
    let mut read = Surface::new(f, EdgeMode::Wrap, 0.1);
    read.set_cones(pomkit_core::cone::ConeMap::from_gray_alpha16(96, 96, EdgeMode::Wrap, &samples).unwrap()).unwrap();
    assert!(read.cones().relaxed() && !built.cones().relaxed());
    let p = TraceParams::default();
    let (mut looked, mut plain) = (0, 0);
    for angle in [30.0f32, 75.0, 89.0] {
        for ray in rays_over(200, angle, 3) {
            let (a, b) = (trace(&read, &ray, Technique::Cone, &p), trace(&built, &ray, Technique::Exact, &p));
            assert!(((a.uv - b.uv) * 96.0).length() < 1e-3, "{angle}deg {ray:?}: read {} exact {}", a.depth, b.depth);
            looked += a.fetches;
            plain += trace(&built, &ray, Technique::Cone, &p).fetches;
        }
    }
    assert!(looked > plain, "the relaxed reading looks after its cone steps ({looked} vs {plain} fetches)");
    // A map of another size is refused, naming both sizes.
    let other = pomkit_core::cone::ConeMap::from_gray_alpha16(2, 1, EdgeMode::Wrap, &[0; 4]).unwrap();
    let err = Surface::new(generate(Pattern::Cobblestones, 8, 8), EdgeMode::Wrap, 0.1).set_cones(other).unwrap_err();
    assert!(err.to_string().contains("2x1") && err.to_string().contains("8x8"), "{err}");
}

#[test]
fn directional_cones_keep_cone_exact_and_cost_fewer_fetches() {
    // Cones per direction quadrant ignore the surface behind and beside the ray: wider, and
    // still never skipping surface, so the hits stay exact's.
    for (pattern, edges) in [(Pattern::Cobblestones, EdgeMode::Wrap), (Pattern::Bricks, EdgeMode::Clamp)] {
        let f = generate(pattern, 128, 128);
        let plain = Surface::new(f.clone(), edges, 0.1);
        let mut ahead = Surface::new(f.clone(), edges, 0.1);
        ahead.set_cones(pomkit_core::cone::ConeMap::directional(&f, edges)).unwrap();
        let p = TraceParams::default();
        let (mut a_fetches, mut p_fetches) = (0, 0);
        for angle in [30.0f32, 75.0, 85.0, 89.0] {
            for ray in rays_over(300, angle, 13) {
                let (a, e) = (trace(&ahead, &ray, Technique::Cone, &p), trace(&plain, &ray, Technique::Exact, &p));
                let err = ((a.uv - e.uv) * 128.0).length();
                assert!(
                    err < 1e-3,
                    "{pattern:?} {edges:?} {angle}deg {ray:?}: {} vs exact {}: {err} texels",
                    a.depth,
                    e.depth
                );
                a_fetches += a.fetches;
                p_fetches += trace(&plain, &ray, Technique::Cone, &p).fetches;
            }
        }
        eprintln!("{pattern:?}: directional {a_fetches} isotropic {p_fetches}");
        assert!(a_fetches < p_fetches, "{pattern:?}: directional {a_fetches} vs isotropic {p_fetches} fetches");
    }
}

/// docs/ACCURACY.md's directional-cone row: mean fetches per ray of pom (8 to 50 samples),
/// exact, and cone on isotropic and on directional cones, on every built-in map at 512x512,
/// over `pomkit compare`'s ray sets.
#[test]
#[ignore = "a measurement (a minute in release): cargo test --release -p pomkit-core --test trace_analytic cone_fetch_table -- --ignored --nocapture"]
fn cone_fetch_table() {
    use pomkit_core::accuracy::ray_set;
    println!("| map | angle | pom | exact | cone | cone, directional |");
    println!("|---|--:|--:|--:|--:|--:|");
    for pattern in [
        Pattern::Cobblestones,
        Pattern::Bricks,
        Pattern::Pyramids,
        Pattern::Text,
        Pattern::Waves,
        Pattern::Fur,
        Pattern::Grass,
    ] {
        let f = generate(pattern, 512, 512);
        let plain = Surface::new(f.clone(), EdgeMode::Wrap, 0.1);
        let mut ahead = Surface::new(f.clone(), EdgeMode::Wrap, 0.1);
        ahead.set_cones(pomkit_core::cone::ConeMap::directional(&f, EdgeMode::Wrap)).unwrap();
        let p = TraceParams { max_samples: 50, ..TraceParams::default() };
        for angle in [75.0f32, 85.0] {
            let rays = ray_set(angle, 2000, 1);
            let mean = |s: &Surface, t: Technique| {
                rays.iter().map(|r| f64::from(trace(s, r, t, &p).fetches)).sum::<f64>() / rays.len() as f64
            };
            println!(
                "| {} | {angle}° | {:.1} | {:.1} | {:.1} | {:.1} |",
                pattern.name(),
                mean(&plain, Technique::Pom),
                mean(&plain, Technique::Exact),
                mean(&plain, Technique::Cone),
                mean(&ahead, Technique::Cone)
            );
        }
    }
}

#[test]
fn relaxed_cones_are_wider_and_cone_on_them_stays_close_to_exact() {
    // Relaxed cones (a look after each step, a binary search in the step that went under) on
    // cobblestones, whose stones' front faces they may reach into: wider than conservative
    // cones, and hits close to the exact ones (they may step over a thin feature). Their
    // fetches are printed, not asserted: docs/ACCURACY.md compares them.
    let f = generate(Pattern::Cobblestones, 128, 128);
    let exact = Surface::new(f.clone(), EdgeMode::Wrap, 0.1);
    let mut relaxed = Surface::new(f.clone(), EdgeMode::Wrap, 0.1);
    let cones = pomkit_core::cone::ConeMap::relaxed_cones(&f, EdgeMode::Wrap);
    let (mut wider, mut n) = (0.0, 0.0);
    for j in 0..128 {
        for i in 0..128 {
            wider += f64::from(cones.ratio(i, j)) / f64::from(exact.cones().ratio(i, j)).max(1e-9);
            n += 1.0;
        }
    }
    assert!(wider / n > 1.5, "relaxed cones only {:.2} times as wide on average", wider / n);
    relaxed.set_cones(cones).unwrap();
    let p = TraceParams { binary_steps: 8, ..TraceParams::default() };
    for angle in [60.0f32, 75.0, 85.0] {
        let rays = rays_over(1000, angle, 17);
        let (mut fetches_r, mut fetches_c, mut over) = (0, 0, 0);
        for ray in &rays {
            let r = trace(&relaxed, ray, Technique::Cone, &p);
            let e = trace(&exact, ray, Technique::Exact, &p);
            fetches_r += r.fetches;
            fetches_c += trace(&exact, ray, Technique::Cone, &p).fetches;
            over += usize::from(((r.uv - e.uv) * 128.0).length() > 0.5);
        }
        println!("{angle}deg: relaxed {fetches_r} conservative {fetches_c} fetches, {over} rays over half a texel");
        assert!(over <= rays.len() / 50, "{angle}deg: {over} of {} rays over half a texel from exact", rays.len());
    }
}
