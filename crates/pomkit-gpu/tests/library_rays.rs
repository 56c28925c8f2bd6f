//! The shader library against pomkit-core, ray by ray: every technique's `pomkit_trace` and every
//! shadow mode's `pomkit_shadow`, run by `pomkit_gpu::probe` on lavapipe, against
//! `pomkit_core::trace::trace` and `pomkit_core::shadow::shadow` on the same surface
//! (docs/GPU.md, "The shader library against pomkit-core, ray by ray").
//!
//! The GPU stores depths as f16, so the CPU surface is built from the f16-rounded field: what is
//! left is f32 against f32 arithmetic in another order (marching techniques), the f16 parallax
//! map of `iterative`, and f32 against f64 (`exact`). Marching techniques compare a filtered
//! sample with a depth plane (`d <= t`); where the two sides' samples straddle the plane by an
//! ulp, one side stops a sample earlier. That flips a few rays in a hundred thousand, so the
//! assertions allow a stated tiny share of rays outside the tight tolerances, and no more.
//! `broken_library_is_caught` shows that the checks catch real bugs (a y flip, an off-by-one
//! sample, a miscounted fetch, a wrong patch offset, a shadow bias): each breaks them by far.
//!
//! Without a GPU adapter the tests print "skipping: ..." and pass, unless POMKIT_REQUIRE_GPU=1.

use std::fmt::Write as _;

use glam::{Vec2, Vec3};
use pomkit_core::accuracy::{SplitMix64, ray_set};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::shadow::{Shadow, ShadowMode, ShadowParams, shadow};
use pomkit_core::silhouette::trace_curved;
use pomkit_core::trace::{Hit, Ray, Surface, Technique, TraceParams, trace};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_gpu::GpuContext;
use pomkit_gpu::height::{HeightMaps, HeightPassOptions, HeightPasses};
use pomkit_gpu::library::PomkitParams;
use pomkit_gpu::planes::PlaneBounds;
use pomkit_gpu::probe::{ProbeError, ProbeRay, RayProbe, ShadowQuery};

/// Side of the maps traced.
const SIZE: u32 = 256;
/// Rays per view angle of the main sets.
const RAYS: usize = 4096;

/// The device, or `None` (after printing why) when there is none and none is required.
fn gpu() -> Option<GpuContext> {
    GpuContext::new().map_err(|e| pomkit_gpu::context::skip_without_gpu(&e)).ok()
}

/// The field with its depths rounded to f16: the surface the GPU actually has.
fn rounded(field: &HeightField) -> HeightField {
    pomkit_gpu::height::f16_surface(field)
}

/// The trace parameters: the defaults, with pom's secant refinement on so that it is compared too.
fn trace_params() -> TraceParams {
    TraceParams { refine: 3, ..TraceParams::default() }
}

/// One surface on both sides: the CPU's, from the f16-rounded field, and the GPU's textures.
struct Both {
    name: String,
    cpu: Surface,
    gpu: HeightMaps,
    params: TraceParams,
}

fn surface(ctx: &GpuContext, passes: &HeightPasses, pattern: Pattern, edges: EdgeMode) -> Both {
    let field = rounded(&generate(pattern, SIZE, SIZE));
    let params = trace_params();
    let depth_scale = pomkit_core::scene::Material::default().depth_scale;
    let maps = HeightMaps::new(ctx, SIZE, SIZE, pattern.name()).expect("a 256x256 map fits");
    maps.upload_depths(ctx, field.depths()).expect("one depth per texel");
    // The cones of the surface both sides trace: with wrap edges the CPU's, as the renderer
    // writes them; with clamp edges built on the GPU (HeightPassOptions::build_cones), as a
    // dynamic field gets them, so `cone`'s rays also check the GPU build.
    let cpu = Surface::new(field, edges, depth_scale);
    let build_cones = edges == EdgeMode::Clamp;
    if !build_cones {
        maps.write_cones(&ctx.queue, Some(cpu.cones())).expect("the cones fit");
    }
    let opts = HeightPassOptions { edges, depth_scale, build_cones, ..HeightPassOptions::default() };
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode(&ctx.device, &mut encoder, &maps, &opts, None);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().expect("device lost");
    Both { name: format!("{} {SIZE}x{SIZE} {edges:?}", pattern.name()), cpu, gpu: maps, params }
}

/// `f` over `items` on two threads (the CPU side of a comparison; the machine has 2 cores).
fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let half = items.len().div_ceil(2).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = items.chunks(half).map(|c| s.spawn(|| c.iter().map(&f).collect::<Vec<R>>())).collect();
        handles.into_iter().flat_map(|h| h.join().expect("CPU worker")).collect()
    })
}

// ---------------------------------------------------------------------------------------------
// Statistics and the criteria
// ---------------------------------------------------------------------------------------------

/// The hit-UV difference of two hits in texels: the larger of |du| and |dv| times the map's
/// size. With wrapping edges the difference is taken modulo the tile (a hit reported one tile
/// over is the same point of the surface); `tile_frame` checks separately that the hits are in
/// the same tile frame.
fn uv_texels(a: Vec2, b: Vec2, edges: EdgeMode) -> f64 {
    let axis = |x: f32, y: f32| {
        let d = f64::from(x) - f64::from(y);
        let d = if edges == EdgeMode::Wrap { d - d.round() } else { d };
        d.abs() * f64::from(SIZE)
    };
    axis(a.x, b.x).max(axis(a.y, b.y))
}

/// One technique on one ray set.
struct TraceStats {
    rays: usize,
    /// Hit-UV differences in texels, sorted.
    uv: Vec<f64>,
    /// Largest depth difference.
    depth: f64,
    /// Rays with equal fetch counts.
    equal_fetches: usize,
    gpu_fetches: u64,
    cpu_fetches: u64,
    /// Rays whose raw hit UVs lie a whole number of tiles apart (a lost or doubled tile offset).
    other_tile: usize,
    /// The worst ray: (difference, ray, GPU hit, CPU hit).
    worst: Option<(f64, Ray, Hit, Hit)>,
}

impl TraceStats {
    fn new(rays: &[Ray], gpu: &[Hit], cpu: &[Hit], edges: EdgeMode) -> Self {
        assert_eq!(gpu.len(), rays.len(), "one GPU hit per ray");
        let mut s = TraceStats {
            rays: rays.len(),
            uv: Vec::with_capacity(rays.len()),
            depth: 0.0,
            equal_fetches: 0,
            gpu_fetches: 0,
            cpu_fetches: 0,
            other_tile: 0,
            worst: None,
        };
        for ((ray, g), c) in rays.iter().zip(gpu).zip(cpu) {
            let e = uv_texels(g.uv, c.uv, edges);
            let e = if e.is_nan() { f64::INFINITY } else { e };
            s.uv.push(e);
            if s.worst.as_ref().is_none_or(|w| e > w.0) {
                s.worst = Some((e, *ray, *g, *c));
            }
            s.depth = s.depth.max(f64::from((g.depth - c.depth).abs()));
            s.equal_fetches += usize::from(g.fetches == c.fetches);
            s.gpu_fetches += u64::from(g.fetches);
            s.cpu_fetches += u64::from(c.fetches);
            // A whole number of tiles apart (and not merely far apart along a long ray).
            let raw = (g.uv - c.uv).as_dvec2();
            let whole = raw.round();
            let rest = (raw - whole).abs().max_element() * f64::from(SIZE);
            s.other_tile += usize::from(whole != glam::DVec2::ZERO && rest <= 1.0);
        }
        s.uv.sort_unstable_by(f64::total_cmp);
        s
    }

    fn quantile(&self, q: f64) -> f64 {
        if self.uv.is_empty() {
            return 0.0;
        }
        self.uv[((self.uv.len() as f64 * q).ceil() as usize).clamp(1, self.uv.len()) - 1]
    }

    fn share_equal_fetches(&self) -> f64 {
        self.equal_fetches as f64 / self.rays.max(1) as f64
    }

    fn share_over(&self, texels: f64) -> f64 {
        self.uv.iter().filter(|&&e| e > texels).count() as f64 / self.rays.max(1) as f64
    }

    fn fetch_ratio(&self) -> f64 {
        if self.cpu_fetches == 0 {
            return if self.gpu_fetches == 0 { 1.0 } else { f64::INFINITY };
        }
        self.gpu_fetches as f64 / self.cpu_fetches as f64
    }

    fn row(&self, set: &str, t: Technique) -> String {
        format!(
            "| {set} | {t} | {} | {:.5} | {:.4} | {:.3} | {:.3}% | {:.4}% | {:.4} |",
            self.rays,
            self.quantile(0.5),
            self.quantile(0.999),
            self.uv.last().copied().unwrap_or(0.0),
            100.0 * self.share_equal_fetches(),
            100.0 * self.share_over(1.0),
            self.fetch_ratio(),
        )
    }
}

/// Hit UVs of marching techniques agree within this many texels ...
const MARCH_UV: f64 = 0.05;
/// ... and their fetch counts exactly, on all rays but this share (rays whose sample straddles a
/// depth plane by an ulp).
const MARCH_SHARE: f64 = 0.001;
/// Marching techniques on rays flatter than MIN_COS (steepened to it): share of rays allowed
/// outside [`MARCH_UV`]. Such a ray crosses 100 tiles (25 600 texels) per unit of depth, and its
/// samples lie up to 100 tiles from the origin, where f32 positions are 0.001 texel apart: on a
/// slope that changes a sample's depth by up to 1e-3, which `pom-classic`'s and `pom`'s line
/// intersections carry 1:1 into the hit depth, and 4e-5 of depth is a texel along the ray. The
/// CPU is f32 there too; neither side is the truth. Fetch counts stay equal ([`MARCH_SHARE`]).
const STEEPENED_SHARE: f64 = 0.25;
/// `exact`'s hit UVs agree within one texel on all rays but this share (measured: every ray
/// within 0.006 texel).
const EXACT_SHARE: f64 = 0.001;
/// The same share on rays entering exactly on texel walls (far tiles).
const EXACT_SHARE_WALLS: f64 = EXACT_SHARE;
/// The same share on rays steepened to MIN_COS.
const EXACT_SHARE_STEEPENED: f64 = EXACT_SHARE;
/// `exact`'s fetch totals agree within this factor.
const EXACT_FETCHES: f64 = 0.03;
/// The same for `cone`: the GPU's cone tops lie `POMKIT_CONE_TOP_MARGIN` below the CPU's
/// (so that they hold for the f16 heights), which makes its steps a little shorter and its
/// leaves a little more frequent (measured: at most 1.046, on bricks at 85 to 89.5 degrees).
const CONE_FETCHES: f64 = 0.08;
/// Relaxed cone stepping: hit UVs within this many texels (measured: every ray within 0.055
/// texel on cobblestones at 30 to 85 degrees) ...
const RELAXED_UV: f64 = 0.1;
/// ... on all rays but this share,
const RELAXED_SHARE: f64 = 0.001;
/// and fetch totals within this factor (measured: at most 1.005).
const RELAXED_FETCHES: f64 = 0.03;

/// What the comparison of `t` on `set` breaks, if anything (empty when it passes).
fn trace_violations(t: Technique, s: &TraceStats, set: &RaySet) -> Vec<String> {
    let mut v = Vec::new();
    if s.other_tile > 0 {
        v.push(format!("{} hits a whole number of tiles off", s.other_tile));
    }
    let share = |x: f64| 100.0 * x;
    match t {
        Technique::Flat | Technique::Normal => {
            if s.quantile(1.0) > 0.0 || s.gpu_fetches > 0 || s.cpu_fetches > 0 || s.depth > 0.0 {
                v.push("flat/normal must hit at the entry point, depth 0, no fetch".into());
            }
        }
        // Both exact walks: the GPU's in f32 (cone's on tops lowered by the f16 margin), the
        // CPU's in f64, so the hits agree as exact's do and the fetch totals nearly.
        Technique::Exact | Technique::Cone => {
            let over = s.share_over(1.0 + set.uv_slack);
            if over > set.exact_share {
                v.push(format!(
                    "{:.4}% of hits more than a texel apart (allowed {}%)",
                    share(over),
                    share(set.exact_share)
                ));
            }
            let allowed = if t == Technique::Cone { CONE_FETCHES } else { EXACT_FETCHES };
            if (s.fetch_ratio() - 1.0).abs() > allowed {
                v.push(format!("fetch totals GPU/CPU {:.4} (allowed 1 +- {allowed})", s.fetch_ratio()));
            }
        }
        _ => {
            let allowed = set.march_share;
            let over = s.share_over(MARCH_UV + set.uv_slack);
            if over > allowed {
                v.push(format!(
                    "{:.4}% of hits more than {MARCH_UV} texel apart (allowed {}%)",
                    share(over),
                    share(allowed)
                ));
            }
            let unequal = 1.0 - s.share_equal_fetches();
            if unequal > MARCH_SHARE {
                v.push(format!(
                    "{:.4}% of rays with other fetch counts (allowed {}%)",
                    share(unequal),
                    share(MARCH_SHARE)
                ));
            }
        }
    }
    v
}

// ---------------------------------------------------------------------------------------------
// Ray sets
// ---------------------------------------------------------------------------------------------

/// A named set of view rays.
struct RaySet {
    name: String,
    rays: Vec<Ray>,
    /// Extra UV tolerance in texels: the spacing of f32 numbers at the set's UVs (far tiles),
    /// where the returned hit is rounded to what an f32 can hold.
    uv_slack: f64,
    /// Share of a marching technique's hits allowed more than [`MARCH_UV`] off.
    march_share: f64,
    /// Share of `exact`'s hits allowed more than a texel off.
    exact_share: f64,
}

fn angle_sets() -> Vec<RaySet> {
    [0.0f32, 45.0, 75.0, 85.0]
        .into_iter()
        .map(|a| RaySet {
            name: format!("{a} deg"),
            rays: ray_set(a, RAYS, 1),
            uv_slack: 0.0,
            march_share: MARCH_SHARE,
            exact_share: EXACT_SHARE,
        })
        .collect()
}

/// The 75-degree rays with direction vectors of lengths 1e-30 and 1e30: pomkit-core normalizes
/// any finite vector, and so must the library (its squared length would under- or overflow f32).
fn extreme_length_sets() -> Vec<RaySet> {
    [1e-30f32, 1e30]
        .into_iter()
        .map(|scale| RaySet {
            name: format!("75 deg, |dir| = {scale:e}"),
            rays: ray_set(75.0, RAYS / 2, 4).into_iter().map(|r| Ray::new(r.uv, r.dir * scale)).collect(),
            uv_slack: 0.0,
            march_share: MARCH_SHARE,
            exact_share: EXACT_SHARE,
        })
        .collect()
}

/// 85 to 89.5 degrees in steps of 0.5.
fn grazing_set() -> RaySet {
    let mut rays = Vec::new();
    for k in 0..=9 {
        rays.extend(ray_set(85.0 + 0.5 * k as f32, RAYS / 4, 10 + k));
    }
    RaySet { name: "85-89.5 deg".into(), rays, uv_slack: 0.0, march_share: MARCH_SHARE, exact_share: EXACT_SHARE }
}

/// 89.97 degrees: flatter than MIN_COS, steepened to it (the ray crosses 100 tiles per unit of
/// depth at depth scale 0.1).
fn steepened_set() -> RaySet {
    RaySet {
        name: "89.97 deg".into(),
        rays: ray_set(89.97, RAYS, 20),
        uv_slack: 0.0,
        march_share: STEEPENED_SHARE,
        exact_share: EXACT_SHARE_STEEPENED,
    }
}

/// Rays entering `offset` tiles from the origin (wrap). The hit is returned in that frame, so it
/// is rounded to f32's spacing there: one ulp of slack.
fn far_set(offset: Vec2, angle: f32) -> RaySet {
    let rays: Vec<Ray> = ray_set(angle, RAYS / 2, 3).into_iter().map(|r| Ray::new(r.uv + offset, r.dir)).collect();
    let ulp = |x: f32| f64::from(f32::from_bits(x.abs().to_bits() + 1) - x.abs());
    let slack = ulp(offset.x.abs().max(offset.y.abs()) + 1.0) * f64::from(SIZE);
    // Entry UVs this far out are multiples of 2 texels: rays start on texel walls.
    let exact_share = if offset.abs().max_element() >= 1e4 { EXACT_SHARE_WALLS } else { EXACT_SHARE };
    RaySet {
        name: format!("{angle} deg at ({}, {})", offset.x, offset.y),
        rays,
        uv_slack: slack,
        march_share: MARCH_SHARE,
        exact_share,
    }
}

/// Rays that do not enter: along the surface, upward, zero, and tiny or huge upward vectors.
fn non_entering() -> Vec<Ray> {
    let mut rays = ray_set(90.0, 256, 4);
    rays.extend(ray_set(120.0, 256, 5));
    rays.extend(ray_set(180.0, 16, 6));
    for uv in [Vec2::new(0.3, 0.7), Vec2::new(-2.25, 7.5), Vec2::ZERO] {
        for dir in [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.3, -0.4, 0.0),
            Vec3::Z,
            Vec3::new(1.0, 1.0, 1e-6),
            Vec3::new(0.0, -1.0, 1e3),
        ] {
            rays.push(Ray::new(uv, dir));
        }
    }
    rays
}

/// Clamped edges: rays entering near the border heading out of the map, and rays entering
/// outside it, at 60 to 88 degrees.
fn clamp_set() -> RaySet {
    let mut rng = SplitMix64::new(7);
    let mut rays = Vec::with_capacity(RAYS);
    for k in 0..RAYS {
        let along = rng.next_f32();
        let inset = rng.next_f32() * 0.06 - 0.02; // up to 0.02 outside the map, 0.04 inside
        let (uv, outward) = match k % 4 {
            0 => (Vec2::new(inset, along), std::f32::consts::PI),
            1 => (Vec2::new(1.0 - inset, along), 0.0),
            2 => (Vec2::new(along, inset), -std::f32::consts::FRAC_PI_2),
            _ => (Vec2::new(along, 1.0 - inset), std::f32::consts::FRAC_PI_2),
        };
        let azimuth = outward + (rng.next_f32() - 0.5) * 2.0;
        let angle = (60.0 + 28.0 * rng.next_f32()).to_radians();
        rays.push(Ray::at_angle(uv, angle, azimuth));
    }
    RaySet { name: "edges, leaving".into(), rays, uv_slack: 0.0, march_share: MARCH_SHARE, exact_share: EXACT_SHARE }
}

// ---------------------------------------------------------------------------------------------
// Running both sides
// ---------------------------------------------------------------------------------------------

/// The uniform of `s`'s surface and trace parameters, with no LOD fade.
fn pomkit_params(t: Technique, mode: ShadowMode, s: &Both) -> PomkitParams {
    let shadow = ShadowParams { mode, softness: 0.1 };
    PomkitParams::new(t, shadow, s.params, s.cpu.depth_scale(), s.cpu.edges(), f32::MAX).expect("valid parameters")
}

fn probe_rays(rays: &[Ray]) -> Vec<ProbeRay> {
    rays.iter().map(|r| ProbeRay::new(r, 0.0)).collect()
}

/// Both sides' hits of `t` for `rays` on `s`.
fn trace_both(ctx: &GpuContext, probe: &RayProbe, s: &Both, t: Technique, rays: &[Ray]) -> (Vec<Hit>, Vec<Hit>) {
    let gpu =
        probe.trace(ctx, &s.gpu, &pomkit_params(t, ShadowMode::None, s), &probe_rays(rays)).expect("the probe runs");
    let cpu = par_map(rays, |r| trace(&s.cpu, r, t, &s.params));
    (gpu, cpu)
}

/// Compares every technique on every set; returns the table rows and the violations found.
fn compare_sets(ctx: &GpuContext, probe: &RayProbe, s: &Both, sets: &[RaySet], table: &mut String) -> Vec<String> {
    let mut failures = Vec::new();
    for set in sets {
        for t in Technique::ALL {
            let start = std::time::Instant::now();
            let (gpu, cpu) = trace_both(ctx, probe, s, t, &set.rays);
            let stats = TraceStats::new(&set.rays, &gpu, &cpu, s.cpu.edges());
            let name = format!("{}, {}", s.name, set.name);
            writeln!(table, "{}", stats.row(&name, t)).unwrap();
            if std::env::var_os("PROBE_TIMES").is_some() {
                println!("{name} {t}: {:?}", start.elapsed());
            }
            for v in trace_violations(t, &stats, set) {
                let (e, ray, g, c) = stats.worst.expect("at least one ray");
                failures.push(format!("{name}, {t}: {v}; worst ray {ray:?}: GPU {g:?}, CPU {c:?} ({e:.4} texels)"));
            }
        }
    }
    failures
}

const HEADER: &str = "| surface, rays | technique | rays | median (texels) | p99.9 | worst | equal fetches | over 1 texel | fetches GPU/CPU |\n|---|---|---|---|---|---|---|---|---|";

#[test]
fn every_technique_traces_as_core_does() {
    let Some(ctx) = gpu() else { return };
    println!("adapter: {}", ctx.describe());
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut table = String::from(HEADER);
    table.push('\n');
    let mut failures = Vec::new();

    let bricks = surface(&ctx, &passes, Pattern::Bricks, EdgeMode::Wrap);
    let mut sets = angle_sets();
    sets.push(grazing_set());
    sets.push(steepened_set());
    sets.push(far_set(Vec2::new(1000.0, -3000.0), 75.0));
    sets.push(far_set(Vec2::new(1e5, -1e5), 75.0));
    sets.extend(extreme_length_sets());
    failures.extend(compare_sets(&ctx, &probe, &bricks, &sets, &mut table));

    let cobbles = surface(&ctx, &passes, Pattern::Cobblestones, EdgeMode::Wrap);
    let sets = vec![
        RaySet {
            name: "75 deg".into(),
            rays: ray_set(75.0, RAYS, 2),
            uv_slack: 0.0,
            march_share: MARCH_SHARE,
            exact_share: EXACT_SHARE,
        },
        grazing_set(),
        steepened_set(),
    ];
    failures.extend(compare_sets(&ctx, &probe, &cobbles, &sets, &mut table));

    let clamped = surface(&ctx, &passes, Pattern::Bricks, EdgeMode::Clamp);
    failures.extend(compare_sets(&ctx, &probe, &clamped, &[clamp_set()], &mut table));

    println!("{table}");
    assert!(failures.is_empty(), "the library differs from pomkit-core:\n{}", failures.join("\n"));
}

/// Curvatures along the rays of the silhouette comparison: concave, flat, convex rays that
/// reach the floor (c <= 1/4) and rays that leave the relief (c > 1/4).
const CURVATURES: [f32; 8] = [-2.0, -0.3, 0.0, 0.05, 0.2, 0.6, 2.0, 20.0];

/// `rays` with the curvatures of [`CURVATURES`] in turn.
fn curved_rays(rays: &[Ray]) -> Vec<(Ray, f32)> {
    rays.iter().enumerate().map(|(i, r)| (*r, CURVATURES[i % CURVATURES.len()])).collect()
}

/// What the comparison of `t`'s curved traces on `s` breaks: rays that leave on one side only,
/// no ray leaving at all, and the straight criteria on the hits of the rays kept.
fn curved_violations(
    ctx: &GpuContext,
    probe: &RayProbe,
    s: &Both,
    t: Technique,
    curved: &[(Ray, f32)],
    set: &RaySet,
    table: &mut String,
) -> Vec<String> {
    let mut failures = Vec::new();
    let pr: Vec<(ProbeRay, f32)> = curved.iter().map(|(r, c)| (ProbeRay::new(r, 0.0), *c)).collect();
    let gpu = probe.trace_curved(ctx, &s.gpu, &pomkit_params(t, ShadowMode::None, s), &pr).expect("the probe runs");
    let cpu = par_map(curved, |(r, c)| trace_curved(&s.cpu, r, t, &s.params, *c));
    let left_differs = gpu.iter().zip(&cpu).filter(|(g, c)| g.1 != c.left).count();
    let left = cpu.iter().filter(|c| c.left).count();
    let name = format!("{}, {}", s.name, set.name);
    // Curvatures above 1/4 make some rays leave.
    if t.displaces() && left == 0 {
        failures.push(format!("{name}, {t}: no ray left the relief"));
    }
    if left_differs as f64 > MARCH_SHARE * curved.len() as f64 {
        failures.push(format!("{name}, {t}: {left_differs} rays differ on leaving ({left} left on the CPU)"));
    }
    let kept: Vec<usize> = (0..curved.len()).filter(|&i| !gpu[i].1 && !cpu[i].left).collect();
    let kept_rays: Vec<Ray> = kept.iter().map(|&i| curved[i].0).collect();
    let g: Vec<Hit> = kept.iter().map(|&i| gpu[i].0).collect();
    let c: Vec<Hit> = kept.iter().map(|&i| cpu[i].hit).collect();
    let stats = TraceStats::new(&kept_rays, &g, &c, s.cpu.edges());
    writeln!(table, "{}", stats.row(&name, t)).unwrap();
    for v in trace_violations(t, &stats, set) {
        let (e, ray, g, c) = stats.worst.expect("at least one ray");
        failures.push(format!("{name}, {t}: {v}; worst ray {ray:?}: GPU {g:?}, CPU {c:?} ({e:.4} texels)"));
    }
    failures
}

/// `pomkit_trace_curved` against pomkit_core's `trace_curved`, ray by ray: whether the ray
/// left the relief agrees, and the hits of the rays kept agree as the straight traces do.
#[test]
fn every_technique_traces_curved_as_core_does() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut table = String::from(HEADER);
    table.push('\n');
    let mut failures = Vec::new();
    for (pattern, edges) in [(Pattern::Cobblestones, EdgeMode::Wrap), (Pattern::Bricks, EdgeMode::Clamp)] {
        let s = surface(&ctx, &passes, pattern, edges);
        for angle in [45.0f32, 75.0] {
            let rays = ray_set(angle, RAYS, 30);
            let set = RaySet {
                name: format!("{angle} deg, curved"),
                rays: rays.clone(),
                uv_slack: 0.0,
                march_share: MARCH_SHARE,
                exact_share: EXACT_SHARE,
            };
            for t in Technique::ALL {
                failures.extend(curved_violations(&ctx, &probe, &s, t, &curved_rays(&rays), &set, &mut table));
            }
        }
    }
    println!("{table}");
    assert!(failures.is_empty(), "the library's curved traces differ from pomkit-core:\n{}", failures.join("\n"));
}

#[test]
fn rays_that_do_not_enter_hit_at_their_entry_point() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let rays = non_entering();
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        let s = surface(&ctx, &passes, Pattern::Bricks, edges);
        for t in Technique::ALL {
            let (gpu, cpu) = trace_both(&ctx, &probe, &s, t, &rays);
            for ((r, g), c) in rays.iter().zip(&gpu).zip(&cpu) {
                let none = Hit { uv: r.uv, depth: 0.0, fetches: 0 };
                assert_eq!(*c, none, "{edges:?} {t}: CPU on {r:?}");
                assert_eq!(*g, none, "{edges:?} {t}: GPU on {r:?}");
            }
        }
    }
}

/// Receivers: the CPU's exact hits of view rays (45 and 75 degrees, and 75 degrees 1000 tiles
/// out), lit from random azimuths at 30 to 88 degrees from the normal; plus receivers on the
/// polygon's surface (depth 0: lit, no fetch).
fn shadow_queries(s: &Both) -> Vec<ShadowQuery> {
    let mut rng = SplitMix64::new(9);
    let mut rays = ray_set(45.0, RAYS / 2, 11);
    rays.extend(ray_set(75.0, RAYS / 2, 12));
    if s.cpu.edges() == EdgeMode::Wrap {
        rays.extend(
            ray_set(75.0, RAYS / 4, 13).into_iter().map(|r| Ray::new(r.uv + Vec2::new(1000.0, -3000.0), r.dir)),
        );
    } else {
        rays.extend(clamp_set().rays.into_iter().take(RAYS / 4));
    }
    let hits = par_map(&rays, |r| trace(&s.cpu, r, Technique::Exact, &s.params));
    let mut queries: Vec<ShadowQuery> = hits
        .iter()
        .enumerate()
        .map(|(k, h)| {
            let angle = [30.0f32, 60.0, 80.0, 88.0][k % 4].to_radians();
            let azimuth = rng.next_f32() * std::f32::consts::TAU;
            let light = Vec3::new(angle.sin() * azimuth.cos(), angle.sin() * azimuth.sin(), angle.cos());
            ShadowQuery { uv: h.uv, depth: h.depth, light, lod: 0.0 }
        })
        .collect();
    queries.extend((0..64).map(|k| ShadowQuery {
        uv: Vec2::new(k as f32 / 64.0, 0.5),
        depth: 0.0,
        light: Vec3::new(0.7, 0.1, 0.3),
        lod: 0.0,
    }));
    queries
}

/// Visibilities are "equal" within this (soft shadows' atan2 in f32 on both sides; hard and
/// exact are 0 or 1) ...
const VISIBILITY: f32 = 1e-3;
/// ... on all queries but this share (a sample or a patch root at the shadow threshold).
const SHADOW_SHARE: f64 = 0.002;
/// Exact shadows: visibility equal on all queries but this share, and fetch totals within
/// [`EXACT_SHADOW_FETCHES`]. Measured: every visibility equal, fetch totals within 0.01%.
const EXACT_SHADOW_SHARE: f64 = SHADOW_SHARE;
/// See [`EXACT_SHADOW_SHARE`].
const EXACT_SHADOW_FETCHES: f64 = 0.01;

#[test]
fn every_shadow_mode_shadows_as_core_does() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut failures = Vec::new();
    let mut table = String::from(
        "| surface | shadow | queries | equal visibility | equal fetches | fetches GPU/CPU |\n|---|---|---|---|---|---|\n",
    );
    for (pattern, edges) in
        [(Pattern::Bricks, EdgeMode::Wrap), (Pattern::Cobblestones, EdgeMode::Wrap), (Pattern::Bricks, EdgeMode::Clamp)]
    {
        let s = surface(&ctx, &passes, pattern, edges);
        let queries = shadow_queries(&s);
        for mode in [ShadowMode::Hard, ShadowMode::Soft, ShadowMode::Exact, ShadowMode::Depth] {
            let params = pomkit_params(Technique::Exact, mode, &s);
            let gpu = probe.shadow(&ctx, &s.gpu, &params, &queries).expect("the probe runs");
            let sp = ShadowParams { mode, softness: 0.1 };
            let cpu: Vec<Shadow> = par_map(&queries, |q| shadow(&s.cpu, q.uv, q.depth, q.light, &sp, &s.params));
            let n = queries.len() as f64;
            let equal = gpu.iter().zip(&cpu).filter(|(g, c)| (g.visibility - c.visibility).abs() <= VISIBILITY).count();
            let same_fetches = gpu.iter().zip(&cpu).filter(|(g, c)| g.fetches == c.fetches).count();
            let (gf, cf) = (
                gpu.iter().map(|x| u64::from(x.fetches)).sum::<u64>(),
                cpu.iter().map(|x| u64::from(x.fetches)).sum::<u64>(),
            );
            let ratio = gf as f64 / cf.max(1) as f64;
            writeln!(
                table,
                "| {} | {} | {} | {:.3}% | {:.3}% | {:.4} |",
                s.name,
                mode.name(),
                queries.len(),
                100.0 * equal as f64 / n,
                100.0 * same_fetches as f64 / n,
                ratio
            )
            .unwrap();
            let name = format!("{}, {} shadows", s.name, mode.name());
            let allowed = if mode == ShadowMode::Exact { EXACT_SHADOW_SHARE } else { SHADOW_SHARE };
            if 1.0 - equal as f64 / n > allowed {
                failures.push(format!("{name}: visibility equal on {equal} of {n} queries"));
            }
            let fetch_ok = if mode == ShadowMode::Exact {
                (ratio - 1.0).abs() <= EXACT_SHADOW_FETCHES
            } else {
                1.0 - same_fetches as f64 / n <= MARCH_SHARE
            };
            if !fetch_ok {
                failures
                    .push(format!("{name}: fetches equal on {same_fetches} of {n} queries, totals GPU/CPU {ratio:.4}"));
            }
            for (q, (g, c)) in queries.iter().zip(gpu.iter().zip(&cpu)) {
                if q.depth == 0.0 && (g.visibility != 1.0 || g.fetches != 0 || c.visibility != 1.0 || c.fetches != 0) {
                    failures.push(format!("{name}: a receiver on the surface {q:?}: GPU {g:?}, CPU {c:?}"));
                }
                // Depth shadows have an answer of their own: 1 - depth, no fetch.
                if mode == ShadowMode::Depth && ((g.visibility - (1.0 - q.depth)).abs() > 1e-6 || g.fetches != 0) {
                    failures.push(format!("{name}: {q:?} should see 1 - depth with no fetch: GPU {g:?}"));
                }
            }
        }
    }
    println!("{table}");
    assert!(failures.is_empty(), "the library's shadows differ from pomkit-core:\n{}", failures.join("\n"));
}

/// Bugs of the kinds the comparison exists to catch, planted in a copy of the library: each
/// must break the criteria that the shipped library meets.
#[test]
fn broken_library_is_caught() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let s = surface(&ctx, &passes, Pattern::Bricks, EdgeMode::Wrap);
    let set = RaySet {
        name: "75 deg".into(),
        rays: ray_set(75.0, 2048, 30),
        uv_slack: 0.0,
        march_share: MARCH_SHARE,
        exact_share: EXACT_SHARE,
    };
    let lib = pomkit_gpu::library::WGSL;
    let bugs: [(&str, &str, &str, &[Technique]); 5] = [
        // The light/view ray's v axis not flipped (tangent-space B is -v).
        ("y flip", "-ts.y * sqrt(s.x / s.y)", "ts.y * sqrt(s.x / s.y)", &[Technique::Pom, Technique::Exact]),
        // Steep parallax sampling one plane late.
        ("off-by-one sample", "let z = f32(i) / f32(n);", "let z = f32(i + 1u) / f32(n);", &[Technique::Steep]),
        // pom not counting its entry sample.
        (
            "fetch count",
            "var fetches = 1u;\n    var a = vec2<f32>",
            "var fetches = 0u;\n    var a = vec2<f32>",
            &[Technique::Pom],
        ),
        // exact's patches offset by a tenth of a texel.
        ("patch offset", "let fx0 = p0.x - (i + 0.5);", "let fx0 = p0.x - (i + 0.6);", &[Technique::Exact]),
        // relief's binary search keeping the wrong half.
        (
            "binary search",
            "if pomkit_bent_depth(heights, samp, bend, uv0 + s * mid, mid, lod) <= mid {",
            "if pomkit_bent_depth(heights, samp, bend, uv0 + s * mid, mid, lod) > mid {",
            &[Technique::Relief],
        ),
    ];
    for (name, from, to, techniques) in bugs {
        assert_eq!(lib.matches(from).count(), 1, "{name}: the library no longer holds {from:?}; update this test");
        let probe = RayProbe::with_library(&ctx.device, &lib.replace(from, to)).expect("the broken library compiles");
        for &t in techniques {
            let (gpu, cpu) = trace_both(&ctx, &probe, &s, t, &set.rays);
            let stats = TraceStats::new(&set.rays, &gpu, &cpu, EdgeMode::Wrap);
            let v = trace_violations(t, &stats, &set);
            println!("{name}, {t}: {v:?}");
            assert!(!v.is_empty(), "{name}: {t} still passes (median {} texels)", stats.quantile(0.5));
        }
    }
    // The bent march with the curvature term linear instead of quadratic in the ray parameter.
    let (from, to) = ("bend.k * tau * tau) / bend.t_end", "bend.k * tau) / bend.t_end");
    assert_eq!(lib.matches(from).count(), 1, "the library no longer holds {from:?}; update this test");
    let probe = RayProbe::with_library(&ctx.device, &lib.replace(from, to)).expect("the broken library compiles");
    let v = curved_violations(&ctx, &probe, &s, Technique::Pom, &curved_rays(&set.rays), &set, &mut String::new());
    println!("bent profile, pom: {v:?}");
    assert!(!v.is_empty(), "bent profile: pom still passes");
}

#[test]
fn non_finite_input_is_refused() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let s = surface(&ctx, &passes, Pattern::Bricks, EdgeMode::Wrap);
    let params = pomkit_params(Technique::Pom, ShadowMode::Hard, &s);
    let good = ProbeRay { uv: Vec2::splat(0.5), dir: Vec3::new(0.5, 0.0, -0.8), lod: 0.0 };
    let bad = ProbeRay { dir: Vec3::new(f32::NAN, 0.0, -1.0), ..good };
    let e = probe.trace(&ctx, &s.gpu, &params, &[good, bad]).unwrap_err();
    assert!(matches!(e, ProbeError::NotFinite { index: 1, field: "dir", .. }), "{e}");
    assert!(e.to_string().contains("ray 1: dir"), "{e}");
    let q = ShadowQuery { uv: Vec2::splat(0.5), depth: f32::INFINITY, light: Vec3::Z, lod: 0.0 };
    let e = probe.shadow(&ctx, &s.gpu, &params, &[q]).unwrap_err();
    assert!(matches!(e, ProbeError::NotFinite { index: 0, field: "depth", .. }), "{e}");
    assert!(probe.trace(&ctx, &s.gpu, &params, &[]).expect("an empty batch").is_empty());
}

/// Relaxed cone stepping: both sides walk relaxed cones (a map such as `pomkit bake cone
/// --relaxed` writes), the GPU's marked by their sign in the pyramid's green. The walk is not
/// exact (a look after each cone step, then `binary_steps` halvings of the step that went
/// under), and the GPU's tops lie `POMKIT_CONE_TOP_MARGIN` below the CPU's, so its steps end at
/// other points: where both bracket the same crossing, the halvings bring both within the last
/// halving's length of it.
#[test]
fn relaxed_cones_trace_as_core_does() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut s = surface(&ctx, &passes, Pattern::Cobblestones, EdgeMode::Wrap);
    let relaxed = std::sync::Arc::new(pomkit_core::cone::ConeMap::relaxed_cones(s.cpu.field(), s.cpu.edges()));
    s.cpu.set_cones(relaxed.clone()).expect("the cones fit");
    s.gpu.write_cones(&ctx.queue, Some(&relaxed)).expect("the cones fit");
    let opts = HeightPassOptions { edges: s.cpu.edges(), depth_scale: s.cpu.depth_scale(), ..Default::default() };
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode(&ctx.device, &mut encoder, &s.gpu, &opts, None);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().expect("device lost");
    let mut table = String::from(HEADER);
    let mut failures = Vec::new();
    for angle in [30.0, 60.0, 75.0, 85.0] {
        let rays = ray_set(angle, RAYS, 7);
        let (gpu, cpu) = trace_both(&ctx, &probe, &s, Technique::Cone, &rays);
        let stats = TraceStats::new(&rays, &gpu, &cpu, s.cpu.edges());
        let name = format!("{}, relaxed cones, {angle} deg", s.name);
        writeln!(table, "\n{}", stats.row(&name, Technique::Cone)).unwrap();
        let (over, ratio) = (stats.share_over(RELAXED_UV), stats.fetch_ratio());
        if over > RELAXED_SHARE || (ratio - 1.0).abs() > RELAXED_FETCHES {
            failures.push(format!(
                "{name}: {:.3}% of hits more than {RELAXED_UV} texel apart (allowed {}%), fetch totals GPU/CPU {ratio:.4}",
                100.0 * over,
                100.0 * RELAXED_SHARE
            ));
        }
    }
    println!("{table}");
    assert!(failures.is_empty(), "relaxed cone stepping differs:\n{}", failures.join("\n"));
}

/// `pomkit_trace_planes` (exact's walk on plane bounds per cell) against pomkit-core's `exact`
/// on a surface with plane bounds (`Surface::use_plane_bounds`), ray by ray: the hits agree as
/// `exact`'s do, and so do the fetches, ray by ray on all but [`PLANES_UNEQUAL`] of the rays
/// (the two walks count alike by construction; f32 against f64 moves a bracket or a skip on a
/// few rays). The least-depth walk's hits on the same rays are compared too, so the plane walk
/// is checked against the other walk's answer as well as its twin's.
#[test]
fn the_plane_walk_traces_as_core_does() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut table = String::from(HEADER);
    table.push('\n');
    let mut failures = Vec::new();
    let cases = [
        (Pattern::Waves, EdgeMode::Wrap),
        (Pattern::Cobblestones, EdgeMode::Wrap),
        (Pattern::Bricks, EdgeMode::Wrap),
        (Pattern::Fur, EdgeMode::Wrap),
        (Pattern::Bricks, EdgeMode::Clamp),
        (Pattern::Pyramids, EdgeMode::Clamp),
    ];
    for (pattern, edges) in cases {
        let plain = surface(&ctx, &passes, pattern, edges);
        let mut cpu = plain.cpu.clone();
        cpu.use_plane_bounds();
        let planes = PlaneBounds::new(&ctx.device, &ctx.queue, &cpu, pattern.name()).expect("the planes fit");
        let mut sets = angle_sets();
        sets.push(grazing_set());
        // Not fur on the steepened rays: there f32 cannot tell a graze of a strand from a miss
        // on 0.15% of the rays, for the least-depth walk as for this one.
        if edges == EdgeMode::Wrap && pattern != Pattern::Fur {
            sets.push(steepened_set());
        }
        if edges == EdgeMode::Wrap {
            sets.push(far_set(Vec2::new(1000.0, -3000.0), 75.0));
        } else {
            sets.push(clamp_set());
        }
        let params = pomkit_params(Technique::Exact, ShadowMode::None, &plain);
        for set in &sets {
            let gpu =
                probe.trace_exact(&ctx, &plain.gpu, Some(&planes), &params, &probe_rays(&set.rays)).expect("runs");
            let on_planes = par_map(&set.rays, |r| trace(&cpu, r, Technique::Exact, &plain.params));
            let least = par_map(&set.rays, |r| trace(&plain.cpu, r, Technique::Exact, &plain.params));
            for (name, want) in [("planes", &on_planes), ("least depths", &least)] {
                let stats = TraceStats::new(&set.rays, &gpu, want, edges);
                let label = format!("{}, {}, GPU planes vs CPU {name}", plain.name, set.name);
                writeln!(table, "{}", stats.row(&label, Technique::Exact)).unwrap();
                let mut found = Vec::new();
                if name == "planes" {
                    found = trace_violations(Technique::Exact, &stats, set);
                    let unequal = 1.0 - stats.share_equal_fetches();
                    if unequal > PLANES_UNEQUAL {
                        found.push(format!("{:.3}% of rays with other fetch counts", 100.0 * unequal));
                    }
                } else if stats.share_over(1.0 + set.uv_slack) > set.exact_share {
                    // The other walk's fetches differ by design; its hits must not.
                    found.push(format!("{:.4}% of hits more than a texel apart", 100.0 * stats.share_over(1.0)));
                }
                for v in found {
                    let (e, ray, g, c) = stats.worst.expect("at least one ray");
                    failures.push(format!("{label}: {v}; worst ray {ray:?}: GPU {g:?}, CPU {c:?} ({e:.4} texels)"));
                }
            }
        }
    }
    println!("{table}");
    assert!(failures.is_empty(), "the plane walk differs from pomkit-core:\n{}", failures.join("\n"));
}

/// Share of rays whose fetch counts may differ between the plane walks of the library and of
/// pomkit-core.
const PLANES_UNEQUAL: f64 = 0.002;

/// The cost of a ray on this device, the least-depth walk against the plane walk:
/// `cargo test --release -p pomkit-gpu --test library_rays plane_walk_timing -- --ignored --nocapture`
/// (docs/BENCHMARKS.md, "The plane walk on lavapipe"). Per map and angle, 512x512 rays entering
/// on a grid over the tile with one direction, as a frame's pixels on a flat quad do (neighbours
/// in a SIMD group walk alike); each walk's dispatch timed on the wall clock, upload and read
/// back included, the median of 7 after a warm-up, the walks taking turns.
#[test]
#[ignore = "a measurement for docs/BENCHMARKS.md, about 3 minutes on lavapipe"]
fn plane_walk_timing() {
    let Some(ctx) = gpu() else { return };
    println!("adapter: {}", ctx.describe());
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    println!("| map | angle | least depths (ms) | planes (ms) | planes / least | fetches per ray, least / planes |");
    println!("|---|--:|--:|--:|--:|--:|");
    for pattern in Pattern::ALL {
        let plain = surface(&ctx, &passes, pattern, EdgeMode::Wrap);
        let mut cpu = plain.cpu.clone();
        cpu.use_plane_bounds();
        let planes = PlaneBounds::new(&ctx.device, &ctx.queue, &cpu, pattern.name()).expect("the planes fit");
        let params = pomkit_params(Technique::Exact, ShadowMode::None, &plain);
        for angle in [60.0f32, 75.0, 85.0] {
            let n = 512;
            let rays: Vec<ProbeRay> = (0..n * n)
                .map(|k| {
                    let uv = Vec2::new((k % n) as f32 + 0.5, (k / n) as f32 + 0.5) / n as f32;
                    ProbeRay::new(&Ray::at_angle(uv, angle.to_radians(), 0.6), 0.0)
                })
                .collect();
            let mut times = [Vec::new(), Vec::new()];
            let mut fetches = [0u64; 2];
            for round in 0..8 {
                for (k, bounds) in [None, Some(&planes)].into_iter().enumerate() {
                    let start = std::time::Instant::now();
                    let hits = probe.trace_exact(&ctx, &plain.gpu, bounds, &params, &rays).expect("runs");
                    let elapsed = start.elapsed().as_secs_f64() * 1e3;
                    if round > 0 {
                        times[k].push(elapsed);
                    }
                    fetches[k] = hits.iter().map(|h| u64::from(h.fetches)).sum();
                }
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let (a, b) = (median(&mut times[0]), median(&mut times[1]));
            let per_ray = |f: u64| f as f64 / rays.len() as f64;
            println!(
                "| {} | {angle}° | {a:.1} | {b:.1} | {:.2} | {:.1} / {:.1} |",
                pattern.name(),
                b / a,
                per_ray(fetches[0]),
                per_ray(fetches[1])
            );
        }
    }
}
