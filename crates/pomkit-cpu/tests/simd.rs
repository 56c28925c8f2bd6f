//! The packets of eight fragments against the single fragments: every technique, every shadow
//! mode, the LOD fade, the pixel depth offset and point lights give the same frame, bit for bit,
//! on the SIMD level this machine has, on the scalar fallback (`POMKIT_SIMD=scalar`) and one
//! fragment at a time ([`Simd8::unpacked`], the scalar code the packets mirror).

use pomkit_core::demo::demo_scene_sized;
use pomkit_core::glam::Vec3;
use pomkit_core::scene::{Light, Scene};
use pomkit_core::shadow::ShadowMode;
use pomkit_core::trace::Technique;
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput, Simd8};

fn render(scene: &Scene, mode: Mode, simd: Simd8) -> RenderOutput {
    let opts = RenderOptions { width: 96, height: 54, mode, aovs: true, ..Default::default() };
    CpuRenderer::with_simd(simd).render(scene, &opts, &|_, _| {}).expect("renders")
}

/// Panics unless the two frames are the same, colour and every AOV, pixel for pixel.
fn assert_same(a: &RenderOutput, b: &RenderOutput, what: &str) {
    assert_eq!(a.covered, b.covered, "{what}: covered pixels");
    for (i, (x, y)) in a.color.iter().zip(&b.color).enumerate() {
        assert_eq!(x, y, "{what}: colour of pixel {i}");
    }
    let (a, b) = (a.aovs.as_ref().unwrap(), b.aovs.as_ref().unwrap());
    assert_eq!(a.uv, b.uv, "{what}: uv");
    assert_eq!(a.depth, b.depth, "{what}: depth");
    assert_eq!(a.shadow, b.shadow, "{what}: shadow");
    assert_eq!(a.fetches, b.fetches, "{what}: fetches");
    assert_eq!(a.lod, b.lod, "{what}: lod");
}

/// The demo scene with every material in `shadow` mode, a point light besides the sun, the LOD
/// fade early (so the fade's blend shows) and, with `offsets`, a pixel depth offset on every
/// other material (without, the packets shade each tile's visible fragments after finding them,
/// rather than fragments as they arrive).
fn variant(shadow: ShadowMode, offsets: bool) -> Scene {
    let mut scene = demo_scene_sized(64);
    for (i, m) in scene.materials.iter_mut().enumerate() {
        m.shadow.mode = shadow;
        m.lod_threshold = 2.5;
        m.pixel_depth_offset = offsets && i % 2 == 0;
    }
    scene.lights.push(Light::Point {
        position: Vec3::new(0.5, 1.2, 1.5),
        color: Vec3::new(1.0, 0.8, 0.6),
        intensity: 2.0,
    });
    scene
}

#[test]
fn packets_render_what_single_fragments_render_on_every_level() {
    let levels = [("detected", Simd8::detect()), ("scalar", Simd8::scalar())];
    let mut shaded = 0;
    for (shadow, offsets) in ShadowMode::ALL.into_iter().flat_map(|s| [(s, false), (s, true)]) {
        let scene = variant(shadow, offsets);
        let modes = Technique::ALL.into_iter().map(Mode::Technique).chain([Mode::Material, Mode::Displaced]);
        for mode in modes {
            let reference = render(&scene, mode, Simd8::unpacked());
            assert!(reference.covered > 1000, "{mode:?}: the scene is on screen");
            for (name, simd) in levels {
                let got = render(&scene, mode, simd);
                assert_same(
                    &got,
                    &reference,
                    &format!("{mode:?}, {} shadows, {name} ({})", shadow.name(), simd.name()),
                );
            }
            shaded += 1;
        }
    }
    assert_eq!(shaded, 2 * ShadowMode::ALL.len() * (Technique::ALL.len() + 2));
}
