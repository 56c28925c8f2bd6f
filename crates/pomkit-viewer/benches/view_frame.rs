//! One viewer frame of the default scene (brick plane, pom with soft shadows) at 950x738, the
//! 3D view's size in a 1280x800 window: after an edit (the scene is prepared again: uploads,
//! height passes, draw, readback, overlay) and while orbiting (the prepared scene is reused,
//! only the camera moves). Run with `cargo bench -p pomkit-viewer --bench view_frame`; figures
//! go in docs/BENCHMARKS.md. Without a GPU adapter it prints why and measures nothing.

use criterion::{Criterion, criterion_group, criterion_main};
use pomkit_core::glam::Vec3;
use pomkit_viewer::doc::SceneDoc;
use pomkit_viewer::view::{ViewRenderer, ViewRequest};
use std::hint::black_box;

fn request(doc: SceneDoc) -> ViewRequest {
    ViewRequest::new(doc, 950, 738)
}

fn bench_view(c: &mut Criterion) {
    let ctx = match pomkit_gpu::GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => {
            eprintln!("skipping the viewer benchmark: {e}");
            return;
        }
    };
    eprintln!("adapter: {}", ctx.describe());
    let mut renderer = ViewRenderer::new(ctx);
    let mut group = c.benchmark_group("view_frame_950x738");
    group.sample_size(10);
    let base = SceneDoc::default();
    // An edit: alternate the depth scale so every frame prepares the scene again.
    let mut k = 0u32;
    group.bench_function("after_an_edit", |b| {
        b.iter(|| {
            k += 1;
            let mut doc = base.clone();
            doc.set_material_field("depth_scale", Some(toml::Value::Float(0.05 + f64::from(k % 2) * 0.01)));
            black_box(renderer.render(&request(doc)).images.is_ok())
        });
    });
    // Orbiting: only the camera moves between frames.
    let mut angle = 0.0f32;
    group.bench_function("orbiting", |b| {
        b.iter(|| {
            angle += 0.05;
            let mut doc = base.clone();
            doc.set_camera(Vec3::new(2.9 * angle.sin(), 1.45, 2.9 * angle.cos()), Vec3::ZERO);
            let ok = renderer.render(&request(doc)).images.is_ok();
            black_box(ok && renderer.reused())
        });
    });
    group.finish();
}

criterion_group!(benches, bench_view);
criterion_main!(benches);
