//! Baking a 4096x4096 normal map, next to a plain copy of the same bytes; cone maps of 256x256
//! built-in maps; and the plane bounds of the pyramid's cells, next to the pyramid itself.
//!
//! The copy reads the height field's 64 MiB of f32 depths and writes them to a second buffer;
//! the bake reads the same depths and writes 48 MiB of RGB8 normals. Run with
//! `cargo bench -p pomkit-core --bench bake`; figures go in docs/BENCHMARKS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use pomkit_core::EdgeMode;
use pomkit_core::bake::{NormalBakeOptions, NormalFilter, bake_normals_rgb8};
use pomkit_core::cone::ConeMap;
use pomkit_core::planes::CellPlanes;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::pyramid::MaxHeightPyramid;
use std::hint::black_box;

fn bench_bake(c: &mut Criterion) {
    let size = 4096;
    let field = generate(Pattern::Cobblestones, size, size);
    let texels = field.depths().len();
    let mut group = c.benchmark_group("bake_4096");
    group.sample_size(10);
    let mut copy = vec![0.0f32; texels];
    group.bench_function("memcpy_f32_depths", |b| {
        b.iter(|| {
            copy.copy_from_slice(black_box(field.depths()));
            black_box(&copy);
        });
    });
    let mut out = vec![[0u8; 3]; texels];
    for filter in [NormalFilter::Central, NormalFilter::Sobel] {
        let opts = NormalBakeOptions { filter, ..Default::default() };
        group.bench_function(format!("normal_rgb8_{filter:?}").to_lowercase(), |b| {
            b.iter(|| {
                bake_normals_rgb8(black_box(&field), &opts, &mut out, &|_| {}).expect("valid options");
                black_box(&out);
            });
        });
    }
    group.finish();
}

/// Conservative cone maps (`pomkit_core::cone`) of 256x256 built-in maps, wrap edges: the
/// branch and bound's cost depends on the relief (smooth slopes cost the most).
fn bench_cones(c: &mut Criterion) {
    let mut group = c.benchmark_group("cone_256");
    group.sample_size(10);
    for pattern in [Pattern::Cobblestones, Pattern::Bricks, Pattern::Waves] {
        let field = generate(pattern, 256, 256);
        group.bench_function(pattern.name(), |b| {
            b.iter(|| black_box(ConeMap::conservative(black_box(&field), EdgeMode::Wrap)));
        });
    }
    group.finish();
}

/// `CellPlanes::new` (pomkit-core's planes.rs) of cobblestones at 512x512 and 2048x2048, wrap
/// edges, next to the `MaxHeightPyramid::new` it is built beside.
fn bench_planes(c: &mut Criterion) {
    let mut group = c.benchmark_group("planes");
    group.sample_size(10);
    for size in [512, 2048] {
        let field = generate(Pattern::Cobblestones, size, size);
        let pyramid = MaxHeightPyramid::new(&field, EdgeMode::Wrap);
        group.bench_function(format!("pyramid_{size}"), |b| {
            b.iter(|| black_box(MaxHeightPyramid::new(black_box(&field), EdgeMode::Wrap)));
        });
        group.bench_function(format!("cell_planes_{size}"), |b| {
            b.iter(|| black_box(CellPlanes::new(black_box(&field), &pyramid, EdgeMode::Wrap)));
        });
    }
    group.finish();
}

criterion_group!(benches, bench_bake, bench_cones, bench_planes);
criterion_main!(benches);
