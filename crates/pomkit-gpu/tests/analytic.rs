//! The GPU's `exact` and `cone` against the brute-force truth on the analytic height fields, at
//! 0 to 89 degrees with wrap and clamp edges: the check pomkit-core's `tests/trace_analytic.rs`
//! makes of the CPU's tracers, made of the shader library (`pomkit_trace`, run by
//! `pomkit_gpu::probe` on lavapipe) on the f16 depths the GPU samples. `cone` walks the CPU's
//! cones with wrap edges and cones built on the GPU (`HeightPassOptions::build_cones`) with
//! clamp edges, so both builds' cones are checked to hold on surfaces whose cones the slope
//! bound decides (the plane, the pyramid, the cap). `exact` runs on plane bounds too
//! (`pomkit_trace_planes`).
//!
//! Without a GPU adapter the test prints "skipping: ..." and passes, unless POMKIT_REQUIRE_GPU=1.

use glam::Vec2;
use pomkit_core::accuracy::{analytic_fields, brute_force_depth, ray_set};
use pomkit_core::cone::ConeMap;
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{Ray, Surface, Technique, TraceParams};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_gpu::GpuContext;
use pomkit_gpu::height::{HeightMaps, HeightPassOptions, HeightPasses, f16_surface};
use pomkit_gpu::library::PomkitParams;
use pomkit_gpu::planes::PlaneBounds;
use pomkit_gpu::probe::{ProbeRay, RayProbe};

/// Side of the analytic fields, as in pomkit-core's test.
const N: u32 = 64;
const DEPTH_SCALE: f32 = 0.1;
/// The hit may lie this many texels from the truth: the GPU walks in f32, the truth is f64
/// (pomkit-core's f64 walk is held to 1e-3). At 89 degrees a ray travels 360 texels per unit
/// of depth, so an f32 depth step of 1e-6 moves the hit some 4e-4 texel.
const TOLERANCE: f64 = 0.01;

fn gpu() -> Option<GpuContext> {
    GpuContext::new().map_err(|e| pomkit_gpu::context::skip_without_gpu(&e)).ok()
}

/// The heights of `field` on the GPU, with their derived maps and cones (the CPU's, or built
/// on the GPU).
fn upload(
    ctx: &GpuContext,
    passes: &HeightPasses,
    field: &HeightField,
    edges: EdgeMode,
    gpu_cones: bool,
) -> HeightMaps {
    let maps = HeightMaps::new(ctx, N, N, "analytic").expect("a 64x64 map fits");
    maps.upload_depths(ctx, field.depths()).expect("one depth per texel");
    if !gpu_cones {
        maps.write_cones(&ctx.queue, Some(&ConeMap::conservative(field, edges))).expect("the cones fit");
    }
    let opts = HeightPassOptions { edges, depth_scale: DEPTH_SCALE, build_cones: gpu_cones, ..Default::default() };
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    passes.encode(&ctx.device, &mut encoder, &maps, &opts, None);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().expect("device lost");
    maps
}

/// The point of the ray at depth `z`.
fn on_ray(ray: &Ray, z: f64) -> Vec2 {
    let d = ray.dir.normalize();
    ray.uv + Vec2::new(d.x, d.y) * (DEPTH_SCALE / -d.z) * z as f32
}

#[test]
fn exact_and_cone_on_the_gpu_match_brute_force_on_analytic_fields_at_every_angle() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let probe = RayProbe::new(&ctx.device).expect("the probe compiles");
    let mut failures = Vec::new();
    let mut worst = [0.0f64; 3];
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        for (name, field) in analytic_fields(N) {
            let field = f16_surface(&field);
            let maps = upload(&ctx, &passes, &field, edges, edges == EdgeMode::Clamp);
            // `exact` on plane bounds too (`pomkit_trace_planes`), built for the same heights.
            let mut surface = Surface::new(field.clone(), edges, DEPTH_SCALE);
            surface.use_plane_bounds();
            let planes = PlaneBounds::new(&ctx.device, &ctx.queue, &surface, name).expect("the planes fit");
            for angle in [0.0f32, 30.0, 60.0, 75.0, 85.0, 89.0] {
                let rays = ray_set(angle, 24, 7);
                let truth: Vec<f64> =
                    rays.iter().map(|r| brute_force_depth(&field, edges, r, f64::from(DEPTH_SCALE))).collect();
                let probe_rays: Vec<ProbeRay> = rays.iter().map(|r| ProbeRay::new(r, 0.0)).collect();
                for (k, t) in [Technique::Exact, Technique::Cone, Technique::Exact].into_iter().enumerate() {
                    let shadow = ShadowParams { mode: ShadowMode::None, softness: 0.1 };
                    let params = PomkitParams::new(t, shadow, TraceParams::default(), DEPTH_SCALE, edges, f32::MAX)
                        .expect("valid parameters");
                    let hits = if k == 2 {
                        probe.trace_exact(&ctx, &maps, Some(&planes), &params, &probe_rays)
                    } else {
                        probe.trace(&ctx, &maps, &params, &probe_rays)
                    };
                    let hits = hits.expect("the probe runs");
                    let t = if k == 2 { "exact on plane bounds".to_owned() } else { t.to_string() };
                    for ((ray, hit), &z) in rays.iter().zip(&hits).zip(&truth) {
                        let err = f64::from(((hit.uv - on_ray(ray, z)) * N as f32).length());
                        let err = if err.is_nan() { f64::INFINITY } else { err };
                        worst[k] = worst[k].max(err);
                        if err > TOLERANCE {
                            failures.push(format!(
                                "{t} {name} {edges:?} {angle} deg {ray:?}: GPU depth {} vs brute force {z}: {err:.4} texels",
                                hit.depth
                            ));
                        }
                    }
                }
            }
        }
    }
    println!(
        "worst hit against brute force: exact {:.5} texel, cone {:.5} texel, exact on plane bounds {:.5} texel",
        worst[0], worst[1], worst[2]
    );
    assert!(failures.is_empty(), "{} rays off:\n{}", failures.len(), failures.join("\n"));
}
