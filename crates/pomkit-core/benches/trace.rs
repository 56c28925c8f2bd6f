//! Rays per second per technique at 30 and 80 degrees from the normal, on a 512x512
//! procedural cobblestone field with depth_scale 0.1 (pom: 8..50 samples). Run with
//! `cargo bench -p pomkit-core --bench trace`; figures go in docs/BENCHMARKS.md.
//!
//! Each iteration traces the same fixed set of 1024 rays, so time per iteration / 1024 is the
//! time per ray; criterion's throughput line gives rays per second directly. A second group
//! traces pom on the field at 256 to 4096 texels a side (the texture's size against its layout
//! in the caches).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use pomkit_core::EdgeMode;
use pomkit_core::glam::Vec2;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::trace::{Ray, Surface, Technique, TraceParams, trace};
use std::hint::black_box;

fn rays(angle_deg: f32) -> Vec<Ray> {
    (0..1024u32)
        .map(|k| {
            let h = k.wrapping_mul(2_654_435_761);
            let uv = Vec2::new((h % 1000) as f32 / 1000.0, ((h / 1000) % 1000) as f32 / 1000.0);
            Ray::at_angle(uv, angle_deg.to_radians(), (h % 6283) as f32 / 1000.0)
        })
        .collect()
}

fn bench_trace(c: &mut Criterion) {
    let surface = Surface::new(generate(Pattern::Cobblestones, 512, 512), EdgeMode::Wrap, 0.1);
    let params = TraceParams { min_samples: 8, max_samples: 50, ..Default::default() };
    let mut group = c.benchmark_group("trace_512_cobblestones");
    group.sample_size(20);
    for angle in [30.0f32, 80.0] {
        let set = rays(angle);
        group.throughput(Throughput::Elements(set.len() as u64));
        for t in Technique::ALL.into_iter().filter(|t| t.displaces()) {
            group.bench_with_input(BenchmarkId::new(t.name(), format!("{angle}deg")), &set, |b, set| {
                b.iter(|| {
                    let mut sum = 0.0f32;
                    for r in set {
                        sum += trace(&surface, r, t, &params).depth;
                    }
                    black_box(sum)
                });
            });
        }
    }
    group.finish();
}

/// pom at 30 degrees on the same cobblestones at 256 to 4096 texels a side, the same rays in
/// UV (about the same fetches per ray at every size): the time per ray shows what the texture's
/// size, and so its row-major layout in the caches, costs (from 256 KiB, inside a core's L2, to
/// 64 MiB, far beyond the L3).
fn bench_texture_size(c: &mut Criterion) {
    let params = TraceParams { min_samples: 8, max_samples: 50, ..Default::default() };
    let set = rays(30.0);
    let mut group = c.benchmark_group("trace_pom_texture_size");
    group.sample_size(20);
    group.throughput(Throughput::Elements(set.len() as u64));
    for size in [256u32, 1024, 4096] {
        let surface = Surface::new(generate(Pattern::Cobblestones, size, size), EdgeMode::Wrap, 0.1);
        group.bench_with_input(BenchmarkId::new("pom_30deg", size), &set, |b, set| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for r in set {
                    sum += trace(&surface, r, Technique::Pom, &params).depth;
                }
                black_box(sum)
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_trace, bench_texture_size);
criterion_main!(benches);
