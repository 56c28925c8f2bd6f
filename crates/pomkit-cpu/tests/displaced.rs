//! The streamed `displaced` reference against independent truths: the full subdivision it
//! coarsens (the picture within 40 dB, as docs/BENCHMARKS.md measures on the demo), and a
//! height field lit straight from above, which can cast no shadow on itself.

use std::sync::Arc;

use pomkit_core::compose::psnr;
use pomkit_core::demo::demo_scene_sized;
use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};

fn render(scene: &Scene, opts: &RenderOptions) -> RenderOutput {
    let out = CpuRenderer::new().render(scene, opts, &|_, _| {}).expect("renders");
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite pixel");
    out
}

fn srgb(out: &RenderOutput) -> Vec<u8> {
    out.to_srgb8().into_iter().flatten().collect()
}

/// One material on a plane seen at a grazing angle, lit by one directional light.
fn plane_scene(field: HeightField, depth_scale: f32, shadow: ShadowMode, light: Vec3, eye: Vec3) -> Scene {
    let material = Material {
        height: Some(Arc::new(field)),
        depth_scale,
        edges: EdgeMode::Wrap,
        shadow: ShadowParams { mode: shadow, ..ShadowParams::default() },
        ..Material::default()
    };
    let mesh = Mesh::plane(Vec2::splat(4.0), 1).scale_uvs(Vec2::splat(4.0));
    Scene {
        camera: Camera { eye, target: Vec3::new(0.0, 0.0, -0.5), up: Vec3::Y, fov_y_deg: 45.0, ..Camera::default() },
        lights: vec![Light::Directional { direction: light, color: Vec3::ONE, intensity: 2.0 }],
        materials: vec![material],
        objects: vec![Object { name: "plane".into(), mesh: Arc::new(mesh), material: 0, transform: Mat4::IDENTITY }],
        ambient: Vec3::splat(0.1),
        background: Vec3::ZERO,
    }
}

#[test]
fn the_coarsened_reference_agrees_with_the_full_subdivision_within_40_db() {
    let grazing = plane_scene(
        generate(Pattern::Cobblestones, 128, 128),
        0.06,
        ShadowMode::Soft,
        Vec3::new(0.5, 0.4, 0.3),
        Vec3::new(0.0, 0.35, 2.0),
    );
    for (name, scene, size) in [("demo", demo_scene_sized(256), (640, 360)), ("grazing", grazing, (480, 270))] {
        let opts = RenderOptions { width: size.0, height: size.1, mode: Mode::Displaced, ..Default::default() };
        let full = render(&scene, &RenderOptions { displaced_tolerance: 0.0, ..opts });
        let coarse = render(&scene, &opts);
        let db = psnr(&srgb(&coarse), &srgb(&full), 255.0);
        eprintln!("{name}: coarsened against the full subdivision {db:.1} dB");
        assert!(db >= 40.0, "{name}: {db:.1} dB");
        // And a coarser tolerance shows: the test can tell.
        let rough = render(&scene, &RenderOptions { displaced_tolerance: 8.0, ..opts });
        let rough_db = psnr(&srgb(&rough), &srgb(&full), 255.0);
        assert!(rough_db < db - 3.0, "{name}: a tolerance of 8 samples gave {rough_db:.1} dB, 1/8 gave {db:.1}");
    }
}

#[test]
fn a_height_field_lit_from_straight_above_casts_no_shadow_on_itself() {
    // Every point of a height field sees straight up, so with the light along the normal every
    // covered pixel is fully lit, whatever the tessellation: the triangles are chords of the
    // surface, and the shadow rays must start on the surface, not on the chords under ridges.
    // (Texels larger than pixels: the shadow rays trace the full-resolution surface.)
    for pattern in [Pattern::Waves, Pattern::Cobblestones] {
        for edge_texels in [1.0, 4.0] {
            let mut scene =
                plane_scene(generate(pattern, 16, 16), 0.02, ShadowMode::Hard, Vec3::Y, Vec3::new(0.0, 2.5, 2.0));
            scene.objects[0].mesh = Arc::new(Mesh::plane(Vec2::splat(4.0), 1));
            let opts = RenderOptions {
                width: 160,
                height: 90,
                mode: Mode::Displaced,
                aovs: true,
                displaced_edge_texels: edge_texels,
                ..Default::default()
            };
            let out = render(&scene, &opts);
            let aovs = out.aovs.as_ref().unwrap();
            let covered: Vec<f32> =
                aovs.uv.iter().zip(&aovs.shadow).filter(|(uv, _)| **uv != Vec2::ZERO).map(|(_, &s)| s).collect();
            assert!(covered.len() > 5000, "{} pixels covered", covered.len());
            let dark = covered.iter().filter(|&&s| s < 1.0).count();
            assert_eq!(dark, 0, "{pattern:?}, {edge_texels} texels: {dark} of {} pixels in shadow", covered.len());
        }
    }
}

/// Culling the streamed blocks (occlusion by what a tile already holds, bounds from each block's
/// prism instead of its made vertices, back faces before set-up) leaves the picture and every
/// AOV as drawing every block gives them, bit for bit: on the demo (a closed cube and sphere in
/// front of a floor that reaches behind the camera), from behind its sign (back faces facing
/// the camera), and on the one-fragment-at-a-time path, whose depth test reads shaded samples.
#[test]
fn culling_the_blocks_changes_no_sample() {
    let mut behind = demo_scene_sized(128);
    behind.camera.eye = Vec3::new(0.6, 1.4, -4.0);
    behind.camera.target = Vec3::new(0.0, 0.8, 0.0);
    for (name, scene) in [("demo", demo_scene_sized(128)), ("behind", behind)] {
        for simd in [pomkit_cpu::Simd8::detect(), pomkit_cpu::Simd8::unpacked()] {
            let opts =
                RenderOptions { width: 320, height: 180, mode: Mode::Displaced, aovs: true, ..Default::default() };
            let draw = |cull: bool| {
                let out = CpuRenderer::with_simd(simd)
                    .with_block_culling(cull)
                    .render(&scene, &opts, &|_, _| {})
                    .expect("renders");
                let aovs = out.aovs.expect("AOVs asked for");
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                (
                    out.color.iter().flat_map(|c| c.to_array()).map(f32::to_bits).collect::<Vec<_>>(),
                    aovs.uv.iter().flat_map(|c| c.to_array()).map(f32::to_bits).collect::<Vec<_>>(),
                    [bits(&aovs.depth), bits(&aovs.shadow), bits(&aovs.fetches), bits(&aovs.lod)],
                    out.covered,
                )
            };
            let (culled, all) = (draw(true), draw(false));
            assert!(culled.3 > 10_000, "{name}: {} pixels covered", culled.3);
            assert_eq!(culled.0, all.0, "{name}, {simd:?}: colour");
            assert_eq!(culled.1, all.1, "{name}, {simd:?}: uv");
            assert_eq!(culled.2, all.2, "{name}, {simd:?}: depth, shadow, fetches, lod");
        }
    }
}
