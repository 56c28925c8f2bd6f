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

/// A lone triangle (too few neighbours to estimate a curvature) and a sphere whose normals are
/// zero (repaired to the geometric ones, then fitted or flat) both render with silhouettes
/// without a NaN pixel; with wrapping edges the lone triangle is the flat chart it is, so the
/// picture equals the one without silhouettes.
#[test]
fn a_lone_triangle_and_degenerate_normals_give_the_flat_chart_and_finite_pixels() {
    use pomkit_core::mesh::Mesh;
    use pomkit_core::tangent::TangentMethod;
    let tri = Mesh::new(
        vec![Vec3::new(-1.5, -1.0, 0.0), Vec3::new(1.5, -1.0, 0.0), Vec3::new(0.0, 1.5, 0.0)],
        // Smooth normals that disagree: a fit would find a strong curvature.
        Some(vec![Vec3::new(-0.6, -0.3, 1.0), Vec3::new(0.6, -0.3, 1.0), Vec3::new(0.0, 0.7, 1.0)]),
        vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(0.5, 0.0)],
        vec![0, 1, 2],
        TangentMethod::default(),
    )
    .expect("a valid triangle");
    let with_mesh = |mesh: Mesh, silhouette: bool| {
        let mut s = scene(Shape::CobblestoneSphere, Technique::Pom, silhouette, 64);
        s.objects[0].mesh = Arc::new(mesh);
        s.camera.eye = Vec3::new(0.3, 0.4, 3.0);
        s
    };
    let opts = RenderOptions { width: 96, height: 96, ..Default::default() };
    let r = |s| CpuRenderer::new().render(&s, &opts, &|_, _| {}).expect("renders");
    let (on, off) = (r(with_mesh(tri.clone(), true)), r(with_mesh(tri, false)));
    assert!(on.color.iter().all(|c| c.is_finite()));
    assert!(on.covered > 1000, "the triangle is drawn: {} pixels", on.covered);
    assert_eq!(on.color, off.color, "a lone triangle is flat: silhouettes change nothing with wrapping edges");

    let sphere = Mesh::uv_sphere(1.0, 16, 32);
    let zero = Mesh::new(
        sphere.positions.clone(),
        Some(vec![Vec3::ZERO; sphere.positions.len()]),
        sphere.uvs.clone(),
        sphere.indices.clone(),
        TangentMethod::default(),
    )
    .expect("zero normals are replaced by geometric ones");
    let out = r(with_mesh(zero, true));
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite pixel");
    assert!(out.covered > 1000);
}
