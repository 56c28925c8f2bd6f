//! The CPU renderer against independent truths: the bump test (ARCHITECTURE.md, Conventions) on a plane, a
//! cube face and a sphere; mirrored UVs; parallax against real displaced geometry.

use std::sync::Arc;

use pomkit_core::compose::{Image, difference};
use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{Technique, TraceParams};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_cpu::{CpuRenderer, Mode, RenderOptions, RenderOutput};

const W: u32 = 160;

/// A raised Gaussian bump at UV (0.5, 0.5) on a flat field.
fn bump_field() -> HeightField {
    let n = 64;
    HeightField::from_height_fn(n, n, |x, y| {
        let d2 = ((x as f32 + 0.5) / n as f32 - 0.5).powi(2) + ((y as f32 + 0.5) / n as f32 - 0.5).powi(2);
        (-d2 / (2.0 * 0.06f32.powi(2))).exp()
    })
}

fn material(field: HeightField, technique: Technique, depth_scale: f32) -> Material {
    Material {
        height: Some(Arc::new(field)),
        technique,
        base_color: Vec3::ONE,
        specular: 0.0,
        depth_scale,
        edges: EdgeMode::Clamp,
        trace: TraceParams { min_samples: 32, max_samples: 96, refine: 3, ..Default::default() },
        shadow: ShadowParams { mode: ShadowMode::None, ..Default::default() },
        ..Material::default()
    }
}

fn scene(mesh: Mesh, transform: Mat4, mat: Material, camera: Camera, light: Vec3) -> Scene {
    Scene {
        camera,
        lights: vec![Light::Directional { direction: light, color: Vec3::ONE, intensity: 1.0 }],
        materials: vec![mat],
        objects: vec![Object { name: "test".into(), mesh: Arc::new(mesh), material: 0, transform }],
        ambient: Vec3::ZERO,
        background: Vec3::ZERO,
    }
}

fn render(scene: &Scene, mode: Mode, size: u32) -> RenderOutput {
    let opts =
        RenderOptions { width: size, height: size, mode, aovs: true, displaced_edge_texels: 0.5, ..Default::default() };
    let out = CpuRenderer::new().render(scene, &opts, &|_, _| {}).expect("renders");
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite pixel");
    out
}

/// Luminance at the screen projection of world point `p`.
fn brightness_at(out: &RenderOutput, cam: &Camera, p: Vec3) -> f32 {
    let vp = cam.projection(1.0) * cam.view();
    let c = vp * p.extend(1.0);
    let (x, y) = ((c.x / c.w * 0.5 + 0.5) * out.width as f32, (0.5 - c.y / c.w * 0.5) * out.height as f32);
    let i = (y as u32).min(out.height - 1) * out.width + (x as u32).min(out.width - 1);
    out.color[i as usize].dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// The surface point with texture coordinate `uv` (the first triangle containing it), in
/// world space: position, normal, tangent and uv scale, interpolated barycentrically.
fn frame_at(mesh: &Mesh, uv: Vec2) -> (Vec3, Vec3, Vec3, Vec2) {
    for tri in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (ua, ub, uc) = (mesh.uvs[a], mesh.uvs[b], mesh.uvs[c]);
        let area = (ub - ua).perp_dot(uc - ua);
        if area.abs() < 1e-12 {
            continue;
        }
        let wb = (uv - ua).perp_dot(uc - ua) / area;
        let wc = (ub - ua).perp_dot(uv - ua) / area;
        let wa = 1.0 - wb - wc;
        if wa >= -1e-4 && wb >= -1e-4 && wc >= -1e-4 {
            let mix3 = |v: &[Vec3]| v[a] * wa + v[b] * wb + v[c] * wc;
            let t: Vec<Vec3> = mesh.tangents.iter().map(|t| t.truncate()).collect();
            let scale = mesh.uv_scale[a] * wa + mesh.uv_scale[b] * wb + mesh.uv_scale[c] * wc;
            return (mix3(&mesh.positions), mix3(&mesh.normals).normalize(), mix3(&t).normalize(), scale);
        }
    }
    panic!("no triangle has uv {uv}");
}

/// Lit from the surface's +T side, the bump is brighter on its +T side than its -T side; lit
/// from up the image (+B), brighter on its +B side.
fn bump_test(mesh: Mesh, uv: Vec2, what: &str) {
    let (p, n, t, scale) = frame_at(&mesh, uv);
    let b = n.cross(t); // w = +1 on these meshes
    let cam = Camera { eye: p + n * 2.0, target: p, up: b, fov_y_deg: 30.0, ..Camera::default() };
    let offset = 0.05 * scale.x;
    for technique in [Technique::Normal, Technique::Pom] {
        for (axis, name) in [(t, "+T"), (b, "+B")] {
            let s = scene(mesh.clone(), Mat4::IDENTITY, material(bump_field(), technique, 0.05), cam, axis + n * 0.4);
            let out = render(&s, Mode::Material, W);
            let plus = brightness_at(&out, &cam, p + axis * offset);
            let minus = brightness_at(&out, &cam, p - axis * offset);
            assert!(plus > minus + 0.1, "{what} {technique} lit from {name}: {plus} vs {minus}");
        }
    }
}

#[test]
fn bump_test_on_a_plane() {
    bump_test(Mesh::quad(Vec2::splat(2.0)), Vec2::splat(0.5), "quad");
}

#[test]
fn bump_test_on_a_cube_face() {
    // Every face of the cube carries the full texture; test two faces with different frames.
    let cube = Mesh::cube(2.0);
    bump_test(cube.clone(), Vec2::splat(0.5), "cube");
    // The face whose normal is +X.
    let i = (0..cube.positions.len()).find(|&i| cube.normals[i].x > 0.9).unwrap();
    let face: Vec<usize> = (0..cube.positions.len()).filter(|&k| cube.normals[k].x > 0.9).collect();
    assert!(face.contains(&i));
    let centre = face.iter().map(|&k| cube.positions[k]).sum::<Vec3>() / face.len() as f32;
    let t = cube.tangents[i].truncate();
    let n = Vec3::X;
    let cam = Camera { eye: centre + n * 3.0, target: centre, up: n.cross(t), fov_y_deg: 40.0, ..Camera::default() };
    let s = scene(cube.clone(), Mat4::IDENTITY, material(bump_field(), Technique::Pom, 0.05), cam, t + n * 0.4);
    let out = render(&s, Mode::Material, W);
    let plus = brightness_at(&out, &cam, centre + t * 0.1);
    let minus = brightness_at(&out, &cam, centre - t * 0.1);
    assert!(plus > minus + 0.1, "+X face: {plus} vs {minus}");
}

#[test]
fn bump_test_on_a_sphere() {
    bump_test(Mesh::uv_sphere(1.0, 48, 96), Vec2::new(0.5, 0.5), "sphere");
}

/// A quad with its UVs mirrored along one axis, lit from world `+axis`: the bump must be
/// brighter on its world `+axis` side.
fn mirrored_bump_test(mirror_u: bool, axis: Vec3) {
    let mut mesh = Mesh::quad(Vec2::splat(2.0));
    for uv in &mut mesh.uvs {
        if mirror_u {
            uv.x = 1.0 - uv.x;
        } else {
            uv.y = 1.0 - uv.y;
        }
    }
    let mesh = Mesh::new(mesh.positions, Some(mesh.normals), mesh.uvs, mesh.indices, Default::default()).unwrap();
    assert!(mesh.tangents.iter().all(|t| t.w < 0.0), "a mirrored quad has w = -1");
    let cam = Camera { eye: Vec3::new(0.0, 0.0, 2.0), target: Vec3::ZERO, fov_y_deg: 30.0, ..Camera::default() };
    for technique in [Technique::Normal, Technique::Pom] {
        let m = material(bump_field(), technique, 0.05);
        let s = scene(mesh.clone(), Mat4::IDENTITY, m, cam, axis + Vec3::Z * 0.4);
        let out = render(&s, Mode::Material, W);
        let plus = brightness_at(&out, &cam, axis * 0.1);
        let minus = brightness_at(&out, &cam, -axis * 0.1);
        assert!(plus > minus + 0.1, "mirror_u {mirror_u}, {technique}: {plus} vs {minus}");
    }
}

#[test]
fn mirrored_uvs_light_the_world_side_facing_the_light() {
    // u mirrored: the tangent points along -X and w = -1; lit from world +X.
    mirrored_bump_test(true, Vec3::X);
}

#[test]
fn uvs_mirrored_in_v_use_the_handedness_for_the_bitangent() {
    // v mirrored: T stays +X but w = -1 and B = w cross(N, T) = -Y. Lit from world +Y, the bump
    // must be brighter on its world +Y side; a renderer that ignored w would flip it.
    mirrored_bump_test(false, Vec3::Y);
}

/// A plane of cobblestones seen at `angle` degrees from its normal, rendered in each mode.
fn plane_at(angle: f32, technique: Technique) -> (Scene, Camera) {
    let field = generate(Pattern::Cobblestones, 64, 64);
    let mut m = material(field, technique, 0.06);
    m.edges = EdgeMode::Wrap;
    m.albedo = None;
    m.lod_threshold = 99.0;
    let a = angle.to_radians();
    let target = Vec3::ZERO;
    let cam =
        Camera { eye: Vec3::new(0.0, 2.0 * a.cos(), 2.0 * a.sin()), target, fov_y_deg: 30.0, ..Camera::default() };
    let mesh = Mesh::plane(Vec2::splat(6.0), 1).scale_uvs(Vec2::splat(3.0));
    (scene(mesh, Mat4::IDENTITY, m, cam, Vec3::new(0.5, 0.8, 0.3)), cam)
}

fn image(out: &RenderOutput) -> Image {
    Image::from(out)
}

#[test]
fn pom_and_exact_match_displaced_geometry_away_from_silhouettes() {
    let (s, _) = plane_at(45.0, Technique::Pom);
    let displaced = image(&render(&s, Mode::Displaced, 200));
    let pom = image(&render(&s, Mode::Technique(Technique::Pom), 200));
    let exact = image(&render(&s, Mode::Technique(Technique::Exact), 200));
    let normal = image(&render(&s, Mode::Technique(Technique::Normal), 200));
    let d = |img: &Image| difference(img, &displaced, 16, None);
    let (dp, de, dn) = (d(&pom), d(&exact), d(&normal));
    eprintln!(
        "PSNR vs displaced at 45 deg: pom {:.1} dB, exact {:.1} dB, normal {:.1} dB",
        dp.psnr_db, de.psnr_db, dn.psnr_db
    );
    assert!(de.psnr_db > 30.0, "exact: {de:?}");
    assert!(dp.psnr_db > 28.0, "pom: {dp:?}");
    assert!(dn.psnr_db < dp.psnr_db - 3.0, "normal mapping should be clearly worse: {dn:?}");
}

/// Mean distance in texels between each pixel's hit UV and the displaced geometry's UV there
/// (the `uv` AOV of `displaced` is the true visible surface point), over pixels both cover
/// where the height map is not minified (mip level < 1.5), so aliasing of the far field does
/// not drown the comparison.
fn uv_error_texels(img: &RenderOutput, truth: &RenderOutput, texels: f32) -> f32 {
    let (a, t) = (img.aovs.as_ref().unwrap(), truth.aovs.as_ref().unwrap());
    let (mut sum, mut n) = (0.0f64, 0usize);
    for i in 0..a.uv.len() {
        if t.uv[i] != Vec2::ZERO && a.uv[i] != Vec2::ZERO && t.lod[i] < 1.5 {
            sum += f64::from((a.uv[i] - t.uv[i]).length() * texels);
            n += 1;
        }
    }
    assert!(n > 1000, "too few comparable pixels: {n}");
    (sum / n as f64) as f32
}

#[test]
fn error_grows_in_the_expected_order_at_70_degrees() {
    let (s, _) = plane_at(70.0, Technique::Pom);
    let truth = render(&s, Mode::Displaced, 200);
    // The plane's UVs run 0..3 (the 64-texel map repeated): one UV unit is 64 texels.
    let texels = 64.0;
    let mut report = vec![];
    for t in [Technique::Normal, Technique::Parallax, Technique::Steep, Technique::Pom, Technique::Exact] {
        let err = uv_error_texels(&render(&s, Mode::Technique(t), 200), &truth, texels);
        report.push((t, err));
    }
    eprintln!("mean hit error in texels vs displaced at 70 degrees: {report:?}");
    for w in report.windows(2) {
        assert!(w[1].1 < w[0].1, "{} should err less than {}: {report:?}", w[1].0, w[0].0);
    }
    // The exact tracer agrees with the tessellated truth (half-texel triangles) to a small
    // fraction of a texel.
    assert!(report[4].1 < 0.1, "{report:?}");
}

/// Pixel depth offset: a small green plate just below the polygon of a flat-bottomed parallax
/// floor lies *above* the displaced surface, so with the offset written to the depth buffer the
/// plate shows; without it the undisplaced polygon hides the plate.
#[test]
fn pixel_depth_offset_lets_displaced_surfaces_intersect_geometry() {
    // Floor: UV 0..1 over 2 world units (L = 2), depth 0.5 everywhere, depth_scale 0.1: the
    // displaced surface lies 0.5 * 0.1 * 2 = 0.1 below the polygon.
    let floor = material(HeightField::constant(16, 16, 0.5), Technique::Pom, 0.1);
    let plate = Material { technique: Technique::Flat, base_color: Vec3::new(0.0, 1.0, 0.0), ..Material::default() };
    let cam = Camera { eye: Vec3::new(0.0, 1.5, 1.5), target: Vec3::ZERO, fov_y_deg: 40.0, ..Camera::default() };
    let green_pixels = |pdo: bool| {
        let mut floor = floor.clone();
        floor.base_color = Vec3::new(1.0, 0.0, 0.0);
        floor.pixel_depth_offset = pdo;
        let s = Scene {
            camera: cam,
            lights: vec![Light::Directional { direction: Vec3::Y, color: Vec3::ONE, intensity: 1.0 }],
            materials: vec![floor, plate.clone()],
            objects: vec![
                Object {
                    name: "floor".into(),
                    mesh: Arc::new(Mesh::plane(Vec2::splat(2.0), 1)),
                    material: 0,
                    transform: Mat4::IDENTITY,
                },
                Object {
                    name: "plate".into(),
                    mesh: Arc::new(Mesh::plane(Vec2::splat(0.5), 1)),
                    material: 1,
                    transform: Mat4::from_translation(Vec3::new(0.0, -0.05, 0.0)),
                },
            ],
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        };
        let out = render(&s, Mode::Material, 128);
        out.color.iter().filter(|c| c.y > 0.5 && c.x < 0.1).count()
    };
    let (with, without) = (green_pixels(true), green_pixels(false));
    assert!(without == 0, "without the offset the polygon hides the plate: {without} green pixels");
    assert!(with > 200, "with the offset the plate shows above the displaced floor: {with} green pixels");
}

#[test]
fn supersampling_averages_toward_the_same_picture() {
    let (s, _) = plane_at(45.0, Technique::Pom);
    let one = render(&s, Mode::Material, 64);
    let four = CpuRenderer::new()
        .render(&s, &RenderOptions { width: 64, height: 64, supersample: 2, ..Default::default() }, &|_, _| {})
        .unwrap();
    assert!(four.color.iter().all(|c| c.is_finite()));
    let d = difference(&image(&one), &image(&four), 48, None);
    // Same scene, smoother edges: close overall, not identical.
    assert!(d.psnr_db > 20.0 && d.psnr_db.is_finite(), "{d:?}");
}

#[test]
fn point_lights_fall_off_with_the_square_of_distance() {
    let lit = |height: f32| {
        let mut m = material(HeightField::constant(4, 4, 0.0), Technique::Normal, 0.05);
        m.lod_threshold = 99.0;
        let cam = Camera { eye: Vec3::new(0.0, 3.0, 0.01), target: Vec3::ZERO, fov_y_deg: 20.0, ..Camera::default() };
        let mut s = scene(Mesh::plane(Vec2::splat(2.0), 1), Mat4::IDENTITY, m, cam, Vec3::Y);
        s.lights = vec![Light::Point { position: Vec3::new(0.0, height, 0.0), color: Vec3::ONE, intensity: 1.0 }];
        let out = render(&s, Mode::Material, 32);
        out.color[(16 * 32 + 16) as usize].x
    };
    let (near, far) = (lit(1.0), lit(2.0));
    // Straight below the light N.L = 1: radiance ratio 4, before the tone curve's shoulder
    // (x / (1 + x / 4)) which is applied only on output, so compare the linear colours.
    assert!((near / far - 4.0).abs() < 0.2, "{near} / {far}");
}

#[test]
fn lod_tint_marks_near_pixels_green_and_far_pixels_red() {
    let (mut s, _) = plane_at(75.0, Technique::Pom);
    // A low threshold so the far part of the plane is past it at this size.
    s.materials[0].lod_threshold = 1.5;
    let opts = RenderOptions { width: 96, height: 96, lod_tint: true, aovs: true, ..Default::default() };
    let out = CpuRenderer::new().render(&s, &opts, &|_, _| {}).unwrap();
    let aovs = out.aovs.as_ref().unwrap();
    let (mut near, mut far) = ((0.0f32, 0usize), (0.0f32, 0usize));
    for (i, c) in out.color.iter().enumerate() {
        if aovs.uv[i] == Vec2::ZERO {
            continue;
        }
        // Green minus red, normalized by brightness.
        let g = (c.y - c.x) / (c.length() + 1e-4);
        if aovs.lod[i] < 0.5 {
            near = (near.0 + g, near.1 + 1);
        } else if aovs.lod[i] > 1.5 {
            far = (far.0 + g, far.1 + 1);
        }
    }
    assert!(near.1 > 50 && far.1 > 50, "both regions present: {near:?} {far:?}");
    let (near, far) = (near.0 / near.1 as f32, far.0 / far.1 as f32);
    assert!(near > 0.1 && far < -0.1, "near green {near}, far red {far}");
}
