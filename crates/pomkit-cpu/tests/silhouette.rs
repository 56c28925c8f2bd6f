//! Silhouettes on the CPU renderer, against the displaced truth: with `silhouette = true` the
//! outline of a curved mesh disagrees with the real displaced outline on at least 70% fewer
//! pixels than the plain technique's; discarded pixels show what lies behind them.

#[path = "support/silhouettes.rs"]
mod silhouettes;

use std::sync::Arc;

use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::scene::{Material, Object};
use pomkit_core::trace::Technique;
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};
use silhouettes::{Shape, coverage, disagreement, scene};

const SIZE: u32 = 400;

fn render(s: &pomkit_core::scene::Scene, mode: Mode) -> RenderOutput {
    let opts = RenderOptions { width: SIZE, height: SIZE, mode, displaced_edge_texels: 1.0, ..Default::default() };
    let out = CpuRenderer::new().render(s, &opts, &|_, _| {}).expect("renders");
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite pixel");
    out
}

#[test]
fn silhouettes_cut_the_outline_disagreement_with_the_displaced_truth_by_70_percent() {
    for shape in [Shape::CobblestoneSphere, Shape::PyramidTorus] {
        let truth = coverage(&render(&scene(shape, Technique::Pom, false, 256), Mode::Displaced));
        for technique in [Technique::Pom, Technique::Exact] {
            let before = disagreement(&coverage(&render(&scene(shape, technique, false, 256), Mode::Material)), &truth);
            let after = disagreement(&coverage(&render(&scene(shape, technique, true, 256), Mode::Material)), &truth);
            eprintln!("{shape:?} {technique}: {before} -> {after} pixels disagree with the displaced outline");
            // The plain outline is the mesh's: thousands of pixels off on these shapes.
            assert!(before > 4000, "{shape:?} {technique}: only {before} pixels disagree without silhouettes");
            assert!(
                (after as f64) <= 0.3 * before as f64,
                "{shape:?} {technique}: {before} -> {after} pixels disagree, less than a 70% drop"
            );
        }
    }
}

#[test]
fn discarded_pixels_show_what_lies_behind_them() {
    let shape = Shape::CobblestoneSphere;
    let wall = |mut s: pomkit_core::scene::Scene| {
        let m = s.materials.len();
        s.materials.push(Material {
            name: "wall".into(),
            base_color: Vec3::new(0.1, 0.6, 0.2),
            technique: Technique::Flat,
            ..Material::default()
        });
        let quad = Mesh::quad(Vec2::splat(8.0));
        let behind = Mat4::from_translation(Vec3::new(0.0, 0.0, -1.5));
        s.objects.push(Object { name: "wall".into(), mesh: Arc::new(quad), material: m, transform: behind });
        s
    };
    let plain = coverage(&render(&scene(shape, Technique::Pom, false, 128), Mode::Material));
    let cut = coverage(&render(&scene(shape, Technique::Pom, true, 128), Mode::Material));
    let mut only_wall = wall(scene(shape, Technique::Pom, true, 128));
    only_wall.objects.remove(0);
    let wall_alone = render(&only_wall, Mode::Material);
    let both = render(&wall(scene(shape, Technique::Pom, true, 128)), Mode::Material);
    let mut discarded = 0;
    for i in 0..plain.len() {
        if plain[i] && !cut[i] {
            discarded += 1;
            assert_eq!(both.color[i], wall_alone.color[i], "pixel {i}: a discarded pixel hides the wall");
        }
    }
    assert!(discarded > 1000, "{discarded} pixels discarded");
}
