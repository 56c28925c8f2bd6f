//! bevy_pomkit rendered by Bevy with no window (lavapipe on CI), checked against independent
//! answers: pomkit-core's CPU tracer for the same camera rays, the analytic intersection with a
//! displaced plane, the sign of a lit bump's slopes, and the plain StandardMaterial.
//!
//! All tests share one lock: each builds a Bevy app with its own GPU device.

#[path = "support/examples.rs"]
mod examples;
#[path = "../examples/support/headless.rs"]
mod headless;
#[path = "../examples/support/probe.rs"]
mod probe;

use std::sync::Mutex;
use std::time::Duration;

use bevy::asset::RenderAssetUsages;
use bevy::camera::Hdr;
use bevy::camera::RenderTarget;
use bevy::core_pipeline::prepass::{DeferredPrepass, DepthPrepass};
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::math::Affine2;
use bevy::pbr::DefaultOpaqueRendererMethod;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy_pomkit::height::depth_image;
use bevy_pomkit::{HeightMaps, MapKind, Pomkit, PomkitDebug, PomkitMaterial, ShadowMode, ShadowParams, Technique};
use headless::{Frame, Headless};
use pomkit_core::EdgeMode;
use pomkit_core::heightfield::{HeightField, mip_level_from_gradients};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::trace::{Ray, Surface, TraceParams, trace};
use probe::{Tangents, hit_plane, quad, quad_uv};

static GPU: Mutex<()> = Mutex::new(());

const W: u32 = 160;
const H: u32 = 120;
const TIMEOUT: Duration = Duration::from_secs(300);

const ALL_TANGENTS: [Tangents; 3] = [Tangents::Imported, Tangents::Flipped, Tangents::Generated];

fn tangent_w(mesh: &Mesh) -> f32 {
    match mesh.attribute(Mesh::ATTRIBUTE_TANGENT) {
        Some(bevy::mesh::VertexAttributeValues::Float32x4(t)) => t[0][3],
        _ => panic!("no tangents"),
    }
}

struct Setup {
    field: HeightField,
    technique: Technique,
    depth_scale: f32,
    tangents: Tangents,
    debug: PomkitDebug,
    uv_transform: Affine2,
    camera: Transform,
    prepass: bool,
}

impl Setup {
    fn new(field: HeightField, technique: Technique) -> Self {
        Self {
            field,
            technique,
            depth_scale: 0.1,
            tangents: Tangents::Imported,
            debug: PomkitDebug::HitUv,
            uv_transform: Affine2::IDENTITY,
            camera: Transform::from_xyz(0.0, 1.3, 1.6).looking_at(Vec3::new(0.0, -0.1, 0.0), Vec3::Y),
            prepass: false,
        }
    }
}

/// A raw (unlit, untonemapped, half-float) camera for debug outputs.
fn spawn_camera(app: &mut Headless, transform: Transform, prepass: bool) -> Entity {
    let target = RenderTarget::Image(app.target().into());
    let mut e = app.world().spawn((Camera3d::default(), Hdr, Tonemapping::None, Msaa::Off, transform, target));
    if prepass {
        e.insert(DepthPrepass);
    }
    e.id()
}

fn pomkit_material(app: &mut Headless, s: &Setup, base: StandardMaterial) -> Handle<PomkitMaterial> {
    let heights = app.world().resource_mut::<Assets<Image>>().add(depth_image(&s.field));
    let mut ext = Pomkit::new(heights).with_technique(s.technique).with_depth_scale(s.depth_scale);
    ext.map_kind = MapKind::Depth;
    ext.debug = s.debug;
    ext.lod_threshold = f32::MAX;
    app.world()
        .resource_mut::<Assets<PomkitMaterial>>()
        .add(PomkitMaterial { base: StandardMaterial { uv_transform: s.uv_transform, ..base }, extension: ext })
}

/// Renders the quad with `s`; returns the frame and, for each pixel, the camera ray.
fn render(s: &Setup) -> (Frame, Vec<Ray3d>) {
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(s.tangents));
    let material = pomkit_material(&mut app, s, StandardMaterial::default());
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    let camera = spawn_camera(&mut app, s.camera, s.prepass);
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    (frame, rays)
}

fn camera_rays(app: &mut Headless, camera: Entity) -> Vec<Ray3d> {
    let world = app.world();
    let (cam, gt) = world.query::<(&Camera, &GlobalTransform)>().get(world, camera).expect("camera");
    let mut rays = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            rays.push(cam.viewport_to_world(gt, p).expect("a ray through every pixel"));
        }
    }
    rays
}

/// The pixels whose entry point lies on the quad, `margin` UV units inside its edges.
fn inside(rays: &[Ray3d], margin: f32) -> Vec<(usize, Vec2)> {
    rays.iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let uv = quad_uv(hit_plane(*r, 0.0)?);
            (uv.min_element() > margin && uv.max_element() < 1.0 - margin).then_some((k, uv))
        })
        .collect()
}

fn rg(frame: &Frame, k: usize) -> Vec2 {
    let p = frame.pixels[k];
    Vec2::new(p[0], p[1])
}

/// The CPU tracer's hit for the pixel `k` of the quad: the same ray in pomkit-core's ray terms
/// (u along +x, v along +z, z up; 2 world units per UV unit on both axes, so the direction
/// needs no stretch), at the mip level the pixel's UV footprint selects.
fn cpu_hit(surface: &Surface, rays: &[Ray3d], k: usize, technique: Technique) -> Option<Vec2> {
    let ray = rays[k];
    let uv0 = quad_uv(hit_plane(ray, 0.0)?);
    let d = ray.direction.as_vec3();
    let dir = Vec3::new(d.x, d.z, d.y).normalize();
    let (x, y) = ((k as u32) % W, (k as u32) / W);
    let neighbour = |dx: u32, dy: u32| -> Option<Vec2> {
        let (nx, ny) = ((x + dx).min(W - 1), (y + dy).min(H - 1));
        Some(quad_uv(hit_plane(rays[(ny * W + nx) as usize], 0.0)?))
    };
    let duv_dx = neighbour(1, 0)? - uv0;
    let duv_dy = neighbour(0, 1)? - uv0;
    let size = surface.field().size_f32();
    let lod = mip_level_from_gradients(
        pomkit_core::glam::Vec2::new(duv_dx.x, duv_dx.y),
        pomkit_core::glam::Vec2::new(duv_dy.x, duv_dy.y),
        size,
        surface.mips().max_level(),
    );
    let params = TraceParams { lod, ..TraceParams::default() };
    let hit = trace(
        surface,
        &Ray::new(pomkit_core::glam::Vec2::new(uv0.x, uv0.y), pomkit_core::glam::Vec3::new(dir.x, dir.y, dir.z)),
        technique,
        &params,
    );
    Some(Vec2::new(hit.uv.x, hit.uv.y))
}

/// Quantiles of the errors, in texels of a `size`-texel map.
fn quantile(mut errors: Vec<f32>, q: f32) -> f32 {
    errors.sort_by(f32::total_cmp);
    errors[((errors.len() - 1) as f32 * q) as usize]
}

#[test]
fn hit_uv_agrees_with_pomkit_core_for_the_same_rays() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let field = generate(Pattern::Pyramids, 64, 64);
    let surface = Surface::new(field.clone(), EdgeMode::Wrap, 0.1);
    for technique in [Technique::Exact, Technique::Cone, Technique::Pom, Technique::Relief] {
        let s = Setup::new(field.clone(), technique);
        let (frame, rays) = render(&s);
        let pixels = inside(&rays, 0.02);
        assert!(pixels.len() > (W * H / 3) as usize, "the quad covers too little of the frame: {}", pixels.len());
        let errors: Vec<f32> = pixels
            .iter()
            .filter_map(|&(k, _)| Some((rg(&frame, k) - cpu_hit(&surface, &rays, k, technique)?).length() * 64.0))
            .collect();
        let (median, p90) = (quantile(errors.clone(), 0.5), quantile(errors.clone(), 0.9));
        let far = errors.iter().filter(|&&e| e > 1.0).count() as f32 / errors.len() as f32;
        eprintln!(
            "{}: {} pixels, median {median:.4} texel, p90 {p90:.4}, {:.2}% over 1 texel",
            technique.name(),
            errors.len(),
            far * 100.0
        );
        // The same rays give the same hits: half-float output (~0.03 texel here) and the GPU's
        // 2x2 derivatives against the CPU's one-pixel differences (pom and relief pick their mip
        // level from them) are the only differences, except where a ray grazes an edge.
        assert!(median < 0.1, "{}: median error {median} texels", technique.name());
        assert!(far < 0.02, "{}: {:.2}% of pixels more than 1 texel off", technique.name(), far * 100.0);
    }
}

#[test]
fn offset_follows_the_displaced_plane_for_every_tangent_kind() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // Both handednesses must trace the same way (the shader orients B by the UV derivatives).
    assert_eq!(tangent_w(&quad(Tangents::Imported)), 1.0);
    assert_eq!(tangent_w(&quad(Tangents::Flipped)), -1.0);
    eprintln!("Bevy's generated tangents on the quad: w = {}", tangent_w(&quad(Tangents::Generated)));
    // A field at depth 1 everywhere is the plane lowered by depth_scale UV units = 2 * 0.1
    // world units: every technique's hit is where the eye ray meets that plane.
    let field = HeightField::constant(32, 32, 1.0);
    for tangents in ALL_TANGENTS {
        for (uv_transform, name) in [
            (Affine2::IDENTITY, "identity"),
            (
                Affine2::from_scale_angle_translation(
                    Vec2::splat(2.0),
                    std::f32::consts::FRAC_PI_2,
                    Vec2::new(0.3, -0.2),
                ),
                "scaled, turned",
            ),
        ] {
            let mut s = Setup::new(field.clone(), Technique::Pom);
            s.tangents = tangents;
            s.uv_transform = uv_transform;
            let (frame, rays) = render(&s);
            // depth_scale is in the material's (transformed) UV units: 2 world units per mesh
            // UV unit over the transform's scale 2 gives 1 world unit per transformed unit.
            let world_per_unit = 2.0 / uv_transform.matrix2.x_axis.length();
            let lowered = -0.1 * world_per_unit;
            let mut worst = 0.0f32;
            let mut n = 0;
            for (k, _) in inside(&rays, 0.02) {
                let Some(p) = hit_plane(rays[k], lowered) else { continue };
                let want = uv_transform.transform_point2(quad_uv(p));
                worst = worst.max((rg(&frame, k) - want).length());
                n += 1;
            }
            eprintln!("{tangents:?}, {name}: {n} pixels, worst {worst:.5} UV");
            assert!(n > 1000);
            assert!(worst < 2e-3, "{tangents:?}, {name}: hit {worst} UV from the displaced plane");
        }
    }
}

/// Mean brightness over the pixels whose entry UV lies within `r` of `centre`.
fn mean_near(frame: &Frame, rays: &[Ray3d], centre: Vec2, r: f32) -> f32 {
    let mut sum = 0.0;
    let mut n = 0;
    for (k, uv) in inside(rays, 0.0) {
        if (uv - centre).length() < r {
            let p = frame.pixels[k];
            sum += p[0] + p[1] + p[2];
            n += 1;
        }
    }
    assert!(n > 10, "too few pixels near {centre}");
    sum / n as f32
}

#[test]
fn a_bump_is_brighter_on_the_side_of_the_light_for_every_tangent_kind() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // A round bump in the middle of the map (white high).
    let n = 64;
    let field = HeightField::from_height_fn(n, n, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / n as f32 - 0.5, (y as f32 + 0.5) / n as f32 - 0.5);
        (-(u * u + v * v) / (2.0 * 0.12f32.powi(2))).exp()
    });
    // Light from +x (+u), then from -z (up the image, -v): the slope facing it is brighter.
    let cases = [(Vec3::new(1.0, 0.5, 0.0), Vec2::new(0.1, 0.0)), (Vec3::new(0.0, 0.5, -1.0), Vec2::new(0.0, -0.1))];
    for tangents in ALL_TANGENTS {
        for (to_light, side) in cases {
            let mut s = Setup::new(field.clone(), Technique::Pom);
            s.tangents = tangents;
            s.debug = PomkitDebug::Off;
            s.camera = Transform::from_xyz(0.0, 3.0, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z);
            let mut app = Headless::new(W, H);
            let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(tangents));
            let base = StandardMaterial { perceptual_roughness: 1.0, reflectance: 0.0, ..default() };
            let material = pomkit_material(&mut app, &s, base);
            app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
            app.world().spawn((
                DirectionalLight { illuminance: 2000.0, shadow_maps_enabled: false, ..default() },
                Transform::default().looking_to(-to_light, Vec3::Y),
            ));
            app.world().insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
            let camera = spawn_camera(&mut app, s.camera, false);
            let frame = app.frame(TIMEOUT).expect("frame");
            let rays = camera_rays(&mut app, camera);
            let centre = Vec2::splat(0.5);
            let lit = mean_near(&frame, &rays, centre + side, 0.03);
            let away = mean_near(&frame, &rays, centre - side, 0.03);
            eprintln!("{tangents:?}, light {to_light}: facing {lit:.4}, away {away:.4}");
            assert!(
                lit > away * 1.3,
                "{tangents:?}, light {to_light}: the slope facing the light ({lit}) is not brighter than the other ({away})"
            );
        }
    }
}

/// Makes `camera` draw opaque materials with Bevy's deferred renderer: G-buffer prepass, then
/// the lighting pass.
fn make_deferred(app: &mut Headless, camera: Entity) {
    app.world().entity_mut(camera).insert((DepthPrepass, DeferredPrepass));
    app.world().insert_resource(DefaultOpaqueRendererMethod::deferred());
}

/// The POM quad over a constant-depth field (its traced floor 0.2 below the polygon) and a red
/// plain square 0.1 below it: with pixel depth offset the square shows through.
fn pdo_frame(pixel_depth: bool, prepass: bool, deferred: bool) -> (Frame, Vec<Ray3d>) {
    let mut s = Setup::new(HeightField::constant(16, 16, 1.0), Technique::Pom);
    s.debug = PomkitDebug::Off;
    s.prepass = prepass;
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let blue = StandardMaterial { base_color: Color::srgb(0.0, 0.0, 1.0), unlit: true, ..default() };
    let material = pomkit_material(&mut app, &s, blue);
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
        m.extension.pixel_depth_offset = pixel_depth;
    }
    app.world().spawn((Mesh3d(mesh.clone()), MeshMaterial3d(material)));
    let red = app.world().resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        base_color: Color::srgb(1.0, 0.0, 0.0),
        unlit: true,
        ..default()
    });
    app.world().spawn((
        Mesh3d(mesh),
        MeshMaterial3d(red),
        Transform::from_xyz(0.0, -0.1, 0.0).with_scale(Vec3::splat(0.4)),
    ));
    let camera = spawn_camera(&mut app, s.camera, prepass);
    if deferred {
        make_deferred(&mut app, camera);
    }
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    (frame, rays)
}

#[test]
fn pixel_depth_offset_shows_in_the_main_pass_the_depth_prepass_and_the_g_buffer() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // (prepass, deferred): forward, forward with a depth prepass, deferred (whose G-buffer
    // prepass writes the depth).
    for (prepass, deferred) in [(false, false), (true, false), (true, true)] {
        for pixel_depth in [false, true] {
            let (frame, rays) = pdo_frame(pixel_depth, prepass, deferred);
            // Pixels whose ray meets the red square's plane well inside it.
            let mut red = 0;
            let mut n = 0;
            for (k, r) in rays.iter().enumerate() {
                let Some(p) = hit_plane(*r, -0.1) else { continue };
                if p.x.abs() < 0.3 && p.z.abs() < 0.3 {
                    n += 1;
                    let c = frame.pixels[k];
                    if c[0] > 0.5 && c[2] < 0.5 {
                        red += 1;
                    }
                }
            }
            eprintln!("prepass {prepass}, deferred {deferred}, pixel depth {pixel_depth}: {red} of {n} red");
            assert!(n > 500);
            if pixel_depth {
                assert!(
                    red as f32 > 0.99 * n as f32,
                    "prepass {prepass}, deferred {deferred}: the square should show through the traced floor"
                );
            } else {
                assert_eq!(red, 0, "prepass {prepass}, deferred {deferred}: the polygon should hide the square");
            }
        }
    }
}

#[test]
fn bad_inputs_draw_the_plain_material_and_say_why() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let lit_scene = |app: &mut Headless| {
        app.world().spawn((
            DirectionalLight { illuminance: 3000.0, shadow_maps_enabled: false, ..default() },
            Transform::default().looking_to(Vec3::new(-1.0, -1.0, -0.5), Vec3::Y),
        ));
        spawn_camera(app, Setup::new(HeightField::constant(2, 2, 0.0), Technique::Pom).camera, false);
    };
    let base = StandardMaterial { base_color: Color::srgb(0.8, 0.6, 0.3), ..default() };
    // The reference: the plain standard material.
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let plain = app.world().resource_mut::<Assets<StandardMaterial>>().add(base.clone());
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(plain)));
    lit_scene(&mut app);
    let reference = app.frame(TIMEOUT).expect("frame");

    let field = generate(Pattern::Bricks, 32, 32);
    // An integer image, a NaN depth scale, and a mesh without tangents.
    let integer = Image::new_fill(
        bevy::render::render_resource::Extent3d { width: 4, height: 4, depth_or_array_layers: 1 },
        bevy::render::render_resource::TextureDimension::D2,
        &[7, 0, 0, 0],
        bevy::render::render_resource::TextureFormat::Rgba8Uint,
        RenderAssetUsages::MAIN_WORLD,
    );
    for case in ["format", "depth scale", "tangents"] {
        let mut app = Headless::new(W, H);
        let mut mesh = quad(Tangents::Imported);
        if case == "tangents" {
            mesh.remove_attribute(Mesh::ATTRIBUTE_TANGENT);
        }
        let mesh = app.world().resource_mut::<Assets<Mesh>>().add(mesh);
        let image = if case == "format" { integer.clone() } else { depth_image(&field) };
        let heights = app.world().resource_mut::<Assets<Image>>().add(image);
        let mut ext = Pomkit::new(heights);
        if case == "depth scale" {
            ext.depth_scale = f32::NAN;
        }
        let material = app
            .world()
            .resource_mut::<Assets<PomkitMaterial>>()
            .add(PomkitMaterial { base: base.clone(), extension: ext });
        app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
        lit_scene(&mut app);
        let frame = app.frame(TIMEOUT).expect("frame");
        let worst = frame.max_difference(&reference);
        let reports = app.world().resource::<HeightMaps>().reports();
        eprintln!("{case}: worst difference from the plain material {worst}; reports {reports:?}");
        assert!(worst < 2e-3, "{case}: not the plain material's look (difference {worst})");
        let expect = match case {
            "format" => "Rgba8Uint",
            "depth scale" => "depth_scale is NaN",
            _ => "no TANGENT",
        };
        assert!(reports.iter().any(|r| r.contains(expect)), "{case}: no report naming the problem in {reports:?}");
    }
}

/// A mesh whose vertex data Bevy keeps in the render world only (`RenderAssetUsages::RENDER_WORLD`,
/// as static meshes often are) has no attributes left in the main world once drawn: a second
/// entity drawn with it later is checked without a panic and drawn like the first.
#[test]
fn a_mesh_kept_in_the_render_world_only_is_drawn_again_without_a_panic() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = Setup::new(generate(Pattern::Bricks, 32, 32), Technique::Pom);
    let mut app = Headless::new(W, H);
    let mut mesh = quad(Tangents::Imported);
    mesh.asset_usage = RenderAssetUsages::RENDER_WORLD;
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(mesh);
    let material = pomkit_material(&mut app, &s, StandardMaterial::default());
    spawn_camera(&mut app, s.camera, false);
    app.world().spawn((Mesh3d(mesh.clone()), MeshMaterial3d(material.clone()), Transform::from_xyz(-5.0, 0.0, 0.0)));
    app.frame(TIMEOUT).expect("frame");
    app.frame(TIMEOUT).expect("frame");
    let extracted = app.world().resource::<Assets<Mesh>>().get(&mesh).expect("the mesh asset");
    assert!(
        extracted.try_contains_attribute(Mesh::ATTRIBUTE_POSITION).is_err(),
        "the mesh data stayed in the main world"
    );
    // The second entity, in view: drawn (the debug view of the hit UV), with no report.
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    let frame = app.frame(TIMEOUT).expect("frame");
    let covered = frame.pixels.iter().filter(|p| p[0] > 0.0 || p[1] > 0.0).count();
    assert!(covered > (W * H / 4) as usize, "the quad is not drawn: {covered} pixels");
    let reports = app.world().resource::<HeightMaps>().reports();
    assert!(reports.is_empty(), "{reports:?}");
}

/// A material asset replaced by a copy without the textures the plugin built (`Assets::insert`
/// with the same id, as an app or an asset reload does) is built again and traced, not left
/// plain because its inputs did not change.
#[test]
fn a_material_replaced_by_a_copy_is_traced_again() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = Setup::new(generate(Pattern::Bricks, 32, 32), Technique::Pom);
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let material = pomkit_material(&mut app, &s, StandardMaterial::default());
    spawn_camera(&mut app, s.camera, false);
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
    let traced = app.frame(TIMEOUT).expect("frame");
    let copy = {
        let materials = app.world().resource::<Assets<PomkitMaterial>>();
        let m = materials.get(&material).expect("the material");
        assert!(m.extension.is_ready(), "not built");
        let mut extension = Pomkit::new(m.extension.height_map.clone());
        let e = &m.extension;
        (extension.technique, extension.depth_scale, extension.map_kind) = (e.technique, e.depth_scale, e.map_kind);
        (extension.debug, extension.lod_threshold) = (e.debug, e.lod_threshold);
        PomkitMaterial { base: m.base.clone(), extension }
    };
    assert!(!copy.extension.is_ready());
    app.world().resource_mut::<Assets<PomkitMaterial>>().insert(&material, copy).expect("replaced");
    let again = app.frame(TIMEOUT).expect("frame");
    // The debug view's blue is the hit's depth: the mortar lies deep where the quad is traced.
    let deep = traced.pixels.iter().filter(|p| p[2] > 0.05).count();
    assert!(deep > 200, "the first frame is not traced: {deep} deep pixels");
    assert_eq!(again.pixels, traced.pixels, "the replaced material is not traced as before");
}

#[test]
fn a_height_map_that_changes_is_rebuilt() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let s = Setup::new(HeightField::constant(16, 16, 1.0), Technique::Pom);
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let material = pomkit_material(&mut app, &s, StandardMaterial::default());
    let heights =
        app.world().resource::<Assets<PomkitMaterial>>().get(&material).expect("material").extension.height_map.clone();
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    let camera = spawn_camera(&mut app, s.camera, false);
    let before = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    let pixels = inside(&rays, 0.05);
    // Deepest everywhere: the hits lie on the plane 0.2 below.
    let off_plane = |frame: &Frame, y: f32, transform: bool| {
        pixels
            .iter()
            .filter_map(|&(k, uv)| {
                let want = if transform { quad_uv(hit_plane(rays[k], y)?) } else { uv };
                Some((rg(frame, k) - want).length())
            })
            .fold(0.0f32, f32::max)
    };
    assert!(off_plane(&before, -0.2, true) < 2e-3);
    // The map changes to the surface itself: every hit is its entry point.
    *app.world().resource_mut::<Assets<Image>>().get_mut(&heights).expect("height map") =
        depth_image(&HeightField::constant(16, 16, 0.0));
    let mut worst = f32::MAX;
    for _ in 0..5 {
        let after = app.frame(TIMEOUT).expect("frame");
        worst = off_plane(&after, 0.0, false);
        if worst < 2e-3 {
            break;
        }
    }
    assert!(worst < 2e-3, "after the change, hits are {worst} UV from their entry points");
}

/// The mean brightness of the white floor seen through the POM quad, and outside it (see
/// `shadow_maps_see_the_traced_depth`).
fn floor_under_and_outside(shadow_pixel_depth: bool) -> (f32, f32) {
    let mut s = Setup::new(HeightField::constant(16, 16, 1.0), Technique::Pom);
    s.debug = PomkitDebug::Off;
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let material = pomkit_material(&mut app, &s, StandardMaterial { base_color: Color::BLACK, ..default() });
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
        m.extension.shadow_pixel_depth = shadow_pixel_depth;
    }
    app.world().spawn((Mesh3d(mesh.clone()), MeshMaterial3d(material)));
    let white = app.world().resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        perceptual_roughness: 1.0,
        reflectance: 0.0,
        ..default()
    });
    app.world().spawn((
        Mesh3d(mesh),
        MeshMaterial3d(white),
        Transform::from_xyz(0.0, -0.1, 0.0).with_scale(Vec3::splat(3.0)),
    ));
    app.world().spawn((
        DirectionalLight { illuminance: 3000.0, shadow_maps_enabled: true, ..default() },
        Transform::default().looking_to(Vec3::NEG_Y, Vec3::Z),
    ));
    app.world().insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    let camera = spawn_camera(&mut app, s.camera, false);
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    let (mut under, mut outside) = (Vec::new(), Vec::new());
    for (k, r) in rays.iter().enumerate() {
        let Some(p) = hit_plane(*r, -0.1) else { continue };
        let Some(q) = hit_plane(*r, 0.0) else { continue };
        let c = frame.pixels[k];
        let lum = c[0] + c[1] + c[2];
        if q.x.abs() < 0.8 && q.z.abs() < 0.8 && p.x.abs() < 0.8 && p.z.abs() < 0.8 {
            under.push(lum);
        } else if (q.x.abs() > 1.1 || q.z.abs() > 1.1) && p.x.abs() < 2.5 && p.z.abs() < 2.5 {
            outside.push(lum);
        }
    }
    assert!(under.len() > 500 && outside.len() > 500);
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    (mean(&under), mean(&outside))
}

#[test]
fn shadow_maps_see_the_traced_depth() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // The POM quad's traced floor lies 0.2 below it, under a lit white floor 0.1 below it; the
    // sun is straight above, with no ambient light. With pixel depth offset the camera sees
    // the white floor through the quad. With `shadow_pixel_depth` the shadow map, traced too,
    // puts the quad's surface below that floor, which is lit as the floor outside (up to
    // Burley diffuse's dependence on the view angle); without it, the shadow map holds the
    // polygon, above the floor, which it shadows black.
    let (u, o) = floor_under_and_outside(true);
    eprintln!("shadow_pixel_depth on: floor under the quad {u:.4}, outside {o:.4}");
    assert!(o > 0.1, "the floor outside the quad is not lit");
    assert!(
        u > 0.8 * o,
        "the floor seen through the quad is {u}, outside {o}: the shadow map holds the polygon's depth"
    );
    let (u, o) = floor_under_and_outside(false);
    eprintln!("shadow_pixel_depth off: floor under the quad {u:.4}, outside {o:.4}");
    assert!(u < 0.05 * o, "without shadow_pixel_depth the polygon should shadow the floor ({u} against {o})");
}

/// A textured brick quad traced with `pom` under a sun (no self-shadows, which Bevy's deferred
/// lighting pass cannot apply), drawn forward or deferred.
fn bricks_frame(technique: Technique, deferred: bool) -> Frame {
    let field = generate(Pattern::Bricks, 128, 128);
    let mut s = Setup::new(field.clone(), technique);
    s.debug = PomkitDebug::Off;
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    // An albedo that shows where the traced UV lands: red mortar, pale bricks.
    let albedo: Vec<u8> = (0..field.width() * field.height())
        .flat_map(|i| {
            let d = field.depth_at(i64::from(i % field.width()), i64::from(i / field.width()), EdgeMode::Wrap);
            if d > 0.5 { [160, 40, 30, 255] } else { [220, 200, 170, 255] }
        })
        .collect();
    let albedo = Image::new(
        Extent3d { width: field.width(), height: field.height(), depth_or_array_layers: 1 },
        TextureDimension::D2,
        albedo,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    );
    let albedo = app.world().resource_mut::<Assets<Image>>().add(albedo);
    let base = StandardMaterial { base_color_texture: Some(albedo), perceptual_roughness: 0.6, ..default() };
    let material = pomkit_material(&mut app, &s, base);
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    TestLight::Sun.spawn(&mut app);
    app.world().insert_resource(GlobalAmbientLight { brightness: 200.0, ..default() });
    let camera = spawn_camera(&mut app, s.camera, false);
    if deferred {
        make_deferred(&mut app, camera);
    }
    app.frame(TIMEOUT).expect("frame")
}

/// The share of pixels of `a` and `b` whose channels differ by more than 5% (of the brighter
/// channel of `a`, at least 0.05), and the brightest channel of `a`.
fn share_off(a: &Frame, b: &Frame) -> (f32, f32) {
    let (mut off, mut brightest) = (0, 0.0f32);
    for (f, d) in a.pixels.iter().zip(&b.pixels) {
        let diff = (0..3).map(|c| (f[c] - d[c]).abs()).fold(0.0f32, f32::max);
        let level = f[0].max(f[1]).max(f[2]);
        brightest = brightest.max(level);
        off += usize::from(diff > 0.05 * level.max(0.05));
    }
    (off as f32 / a.pixels.len() as f32, brightest)
}

/// The traced UV shades Bevy's G-buffer: the deferred picture is the forward one, up to the
/// G-buffer's packing (8-bit colour, packed normals), and the depth offset reaches the depth
/// buffer (`pixel_depth_offset_shows_in_the_main_pass_the_depth_prepass_and_the_g_buffer`).
/// The comparison can tell a traced picture from an untraced one: the same bricks with normal
/// mapping only differ on many pixels.
#[test]
fn deferred_rendering_draws_the_forward_picture() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let forward = bricks_frame(Technique::Pom, false);
    let (share, brightest) = share_off(&forward, &bricks_frame(Technique::Pom, true));
    let (untraced, _) = share_off(&forward, &bricks_frame(Technique::Normal, true));
    eprintln!(
        "forward against deferred: {:.2}% of pixels off by over 5%; against deferred normal mapping {:.2}%",
        share * 100.0,
        untraced * 100.0
    );
    assert!(brightest > 0.1, "the forward picture is dark");
    assert!(untraced > 0.1, "normal mapping looks like pom here ({:.2}% differ): the test is blind", untraced * 100.0);
    assert!(share < 0.01, "{:.2}% of the deferred picture's pixels differ from the forward one", share * 100.0);
}

/// A light of the self-shadow tests: where it is, seen from the quad.
#[derive(Clone, Copy, Debug)]
enum TestLight {
    /// A sun 30 degrees above the horizon, from +x and a little -z.
    Sun,
    /// A point light 1.5 above the quad, 3 toward +x: 20 to 37 degrees above the horizon over
    /// the quad.
    Point,
    /// A spot light there, aimed at the quad's centre with a cone wide enough for all of it.
    Spot,
}

const LIGHT_POSITION: Vec3 = Vec3::new(3.0, 1.5, -0.5);

impl TestLight {
    /// The world direction toward the light from the world point `p`.
    fn toward(self, p: Vec3) -> Vec3 {
        match self {
            Self::Sun => Vec3::new(1.0, 0.62, -0.3).normalize(),
            Self::Point | Self::Spot => (LIGHT_POSITION - p).normalize(),
        }
    }

    fn spawn(self, app: &mut Headless) {
        let world = app.world();
        match self {
            Self::Sun => world.spawn((
                DirectionalLight { illuminance: 1000.0, shadow_maps_enabled: false, ..default() },
                Transform::default().looking_to(-self.toward(Vec3::ZERO), Vec3::Y),
            )),
            Self::Point => world.spawn((
                PointLight { intensity: 2.0e6, range: 20.0, radius: 0.0, shadow_maps_enabled: false, ..default() },
                Transform::from_translation(LIGHT_POSITION),
            )),
            Self::Spot => world.spawn((
                SpotLight {
                    intensity: 2.0e6,
                    range: 20.0,
                    radius: 0.0,
                    outer_angle: 0.9,
                    inner_angle: 0.8,
                    shadow_maps_enabled: false,
                    ..default()
                },
                Transform::from_translation(LIGHT_POSITION).looking_at(Vec3::ZERO, Vec3::Y),
            )),
        };
    }
}

/// The exact-traced pyramids quad lit by `light` alone (no ambient light), drawn with
/// self-shadows `mode` and the debug output `debug`; with the camera rays.
fn shadow_frame(light: TestLight, mode: ShadowMode, debug: PomkitDebug) -> (Frame, Vec<Ray3d>) {
    let mut s = Setup::new(generate(Pattern::Pyramids, 64, 64), Technique::Exact);
    s.debug = debug;
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let material = pomkit_material(&mut app, &s, StandardMaterial { perceptual_roughness: 1.0, ..default() });
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
        m.extension.shadow.mode = mode;
    }
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    light.spawn(&mut app);
    app.world().insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    let camera = spawn_camera(&mut app, s.camera, false);
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    (frame, rays)
}

/// pomkit-core's exact hit for the camera ray `ray` and its self-shadow toward `light` (the
/// light's direction taken at the hit's world point, in ray terms: u along +x, v along +z, up).
fn cpu_visibility(surface: &Surface, ray: Ray3d, light: TestLight, mode: ShadowMode) -> f32 {
    let d = ray.direction.as_vec3();
    let uv0 = quad_uv(hit_plane(ray, 0.0).expect("inside"));
    let traced =
        Ray::new(pomkit_core::glam::Vec2::new(uv0.x, uv0.y), pomkit_core::glam::Vec3::new(d.x, d.z, d.y).normalize());
    let params = TraceParams::default();
    let hit = trace(surface, &traced, Technique::Exact, &params);
    // The hit's world point: 2 world units per UV unit, `depth * depth_scale` UV units down.
    let world = Vec3::new(2.0 * hit.uv.x - 1.0, -2.0 * hit.depth * surface.depth_scale(), 2.0 * hit.uv.y - 1.0);
    let l = light.toward(world);
    let l = pomkit_core::glam::Vec3::new(l.x, l.z, l.y);
    pomkit_core::shadow(surface, hit.uv, hit.depth, l, &ShadowParams { mode, softness: 0.1 }, &params).visibility
}

#[test]
fn self_shadows_agree_with_pomkit_core() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let surface = Surface::new(generate(Pattern::Pyramids, 64, 64), EdgeMode::Wrap, 0.1);
    for light in [TestLight::Sun, TestLight::Point, TestLight::Spot] {
        for mode in [ShadowMode::Hard, ShadowMode::Exact] {
            let (frame, rays) = shadow_frame(light, mode, PomkitDebug::Shadow);
            let (mut n, mut differ, mut shadowed) = (0, 0, 0);
            for (k, _) in inside(&rays, 0.02) {
                let want = cpu_visibility(&surface, rays[k], light, mode);
                let got = frame.pixels[k][0];
                n += 1;
                shadowed += usize::from(want < 0.5);
                differ += usize::from((got - want).abs() > 0.5);
            }
            let share = differ as f32 / n as f32;
            let what = format!("{light:?} {}", mode.name());
            eprintln!("{what}: {n} pixels, {shadowed} shadowed by pomkit-core, {:.2}% disagree", share * 100.0);
            assert!(shadowed > n / 10, "{what}: the test light casts too little shadow ({shadowed} of {n})");
            // Only where a shadow edge passes within a hair of the hit (f32 against f64,
            // half-float hit UVs) may the two differ.
            assert!(share < 0.03, "{what}: {:.2}% of pixels disagree with pomkit-core", share * 100.0);
        }
    }
}

/// A self-shadowed pixel loses the whole of that light's direct light, as Bevy's own lighting
/// computes it (its attenuation with distance, a spot light's cone): lit by one light and no
/// ambient light, the pixels pomkit-core finds self-shadowed are black, and those it finds lit
/// are not.
#[test]
fn a_self_shadow_takes_out_the_lights_own_contribution() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let surface = Surface::new(generate(Pattern::Pyramids, 64, 64), EdgeMode::Wrap, 0.1);
    for light in [TestLight::Sun, TestLight::Point, TestLight::Spot] {
        let (frame, rays) = shadow_frame(light, ShadowMode::Hard, PomkitDebug::Off);
        let (mut dark, mut lit) = (Vec::new(), Vec::new());
        for (k, _) in inside(&rays, 0.02) {
            let c = frame.pixels[k];
            let lum = c[0] + c[1] + c[2];
            match cpu_visibility(&surface, rays[k], light, ShadowMode::Hard) {
                0.0 => dark.push(lum),
                1.0 => lit.push(lum),
                _ => {}
            }
        }
        dark.sort_by(f32::total_cmp);
        lit.sort_by(f32::total_cmp);
        let (dark_median, lit_median) = (dark[dark.len() / 2], lit[lit.len() / 2]);
        eprintln!(
            "{light:?}: shadowed median {dark_median:.4} ({} px), lit median {lit_median:.4} ({} px)",
            dark.len(),
            lit.len()
        );
        assert!(
            dark.len() > 300 && lit.len() > 300,
            "{light:?}: too few pixels ({} dark, {} lit)",
            dark.len(),
            lit.len()
        );
        assert!(lit_median > 0.05, "{light:?}: the light does not reach the quad ({lit_median})");
        assert!(
            dark_median < 0.02 * lit_median,
            "{light:?}: shadowed pixels keep light: {dark_median} against {lit_median}"
        );
    }
}

#[test]
fn the_lod_fade_follows_the_height_map_mip_level() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    // A grazing view over a fine map: mip levels from 0 near the camera to over 3 at the back.
    let field = generate(Pattern::Bricks, 256, 256);
    let mut s = Setup::new(field, Technique::Pom);
    s.debug = PomkitDebug::Fetches;
    s.camera = Transform::from_xyz(0.0, 0.35, 1.3).looking_at(Vec3::new(0.0, 0.0, -0.6), Vec3::Y);
    let mut app = Headless::new(W, H);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let material = pomkit_material(&mut app, &s, StandardMaterial::default());
    let threshold = 2.0;
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
        m.extension.lod_threshold = threshold;
    }
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    let camera = spawn_camera(&mut app, s.camera, false);
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = camera_rays(&mut app, camera);
    let mut errors = Vec::new();
    let (mut full, mut none) = (0, 0);
    for (k, uv0) in inside(&rays, 0.02) {
        let (x, y) = ((k as u32) % W, (k as u32) / W);
        if x + 1 >= W || y + 1 >= H {
            continue;
        }
        let at = |k: usize| hit_plane(rays[k], 0.0).map(quad_uv);
        let (Some(right), Some(below)) = (at(k + 1), at(k + W as usize)) else { continue };
        let level = mip_level_from_gradients(
            pomkit_core::glam::Vec2::new(right.x - uv0.x, right.y - uv0.y),
            pomkit_core::glam::Vec2::new(below.x - uv0.x, below.y - uv0.y),
            pomkit_core::glam::Vec2::splat(256.0),
            8.0,
        );
        let want = (threshold - level).clamp(0.0, 1.0);
        let got = frame.pixels[k][1];
        full += usize::from(want >= 1.0);
        none += usize::from(want <= 0.0);
        errors.push((got - want).abs());
    }
    let (median, p95) = (quantile(errors.clone(), 0.5), quantile(errors.clone(), 0.95));
    eprintln!("{} pixels ({full} full, {none} faded out): weight error median {median:.4}, p95 {p95:.4}", errors.len());
    assert!(full > 100 && none > 100, "the view does not span the fade ({full} full, {none} out)");
    // The GPU takes one derivative per 2x2 quad, the test one pixel's differences.
    assert!(median < 0.02 && p95 < 0.25, "LOD weight off: median {median}, p95 {p95}");
}

/// An albedo that shows which mip level was read: levels 0 to 3 white, coarser levels black
/// (the mip chain of a `size`-texel texture). A pixel reads level 3 or finer unless its texture
/// gradients claim a footprint of over 8 texels; on the tests' quad at 160 x 120 the real
/// footprint is under 3 texels of a 128-texel map everywhere, so black marks a mip level picked
/// far too coarse.
fn mip_marker(size: u32) -> Image {
    let (mut side, mut level, mut data) = (size, 0, Vec::new());
    while side >= 1 {
        let v = if level < 4 { 240 } else { 10 };
        data.extend(std::iter::repeat_n([v, v, v, 255], (side * side) as usize).flatten());
        level += 1;
        side /= 2;
    }
    let mut image = Image::new(
        Extent3d { width: size, height: size, depth_or_array_layers: 1 },
        TextureDimension::D2,
        data[..(size * size * 4) as usize].to_vec(),
        TextureFormat::Rgba8Unorm,
        RenderAssetUsages::default(),
    );
    // Every level after the first, in order (Bevy uploads the levels of a layer one after
    // another).
    image.data = Some(data);
    image.texture_descriptor.mip_level_count = level;
    image.sampler = bevy::image::ImageSampler::linear();
    image
}

/// The steep brick relief with the mip-marking albedo, unlit (the albedo at the hit as it is),
/// traced with `pom`, drawn at `scale` times the tests' resolution. `hit_derivatives` turns
/// `entry_gradients` off: the hit UV's own derivatives pick the mip level, as in Bevy's own
/// parallax mapping (and in the plugin before it sampled with the entry UV's gradients).
fn streak_frame(scale: u32, hit_derivatives: bool) -> (Frame, Option<Vec<Ray3d>>) {
    let mut s = Setup::new(generate(Pattern::Bricks, 128, 128), Technique::Pom);
    s.debug = PomkitDebug::Off;
    s.camera = Transform::from_xyz(0.0, 1.0, 1.7).looking_at(Vec3::new(0.0, -0.1, -0.1), Vec3::Y);
    let mut app = Headless::new(W * scale, H * scale);
    let mesh = app.world().resource_mut::<Assets<Mesh>>().add(quad(Tangents::Imported));
    let albedo = app.world().resource_mut::<Assets<Image>>().add(mip_marker(128));
    let base = StandardMaterial { base_color_texture: Some(albedo), unlit: true, ..default() };
    let material = pomkit_material(&mut app, &s, base);
    if let Some(mut m) = app.world().resource_mut::<Assets<PomkitMaterial>>().get_mut(&material) {
        m.extension.entry_gradients = !hit_derivatives;
    }
    app.world().spawn((Mesh3d(mesh), MeshMaterial3d(material)));
    let camera = spawn_camera(&mut app, s.camera, false);
    let frame = app.frame(TIMEOUT).expect("frame");
    let rays = (scale == 1).then(|| camera_rays(&mut app, camera));
    (frame, rays)
}

/// Pixels of `frame` among `pixels` whose colour differs by more than 0.15 (linear, any
/// channel) from the `scale` x `scale` box average of the supersampled `reference`.
fn off_reference(frame: &Frame, reference: &Frame, scale: u32, pixels: &[(usize, Vec2)]) -> usize {
    let mut off = 0;
    for &(k, _) in pixels {
        let (x, y) = (k as u32 % frame.width, k as u32 / frame.width);
        {
            let mut mean = [0.0f32; 3];
            for sy in 0..scale {
                for sx in 0..scale {
                    let p = reference.at(x * scale + sx, y * scale + sy);
                    for k in 0..3 {
                        mean[k] += p[k] / (scale * scale) as f32;
                    }
                }
            }
            let p = frame.at(x, y);
            off += usize::from((0..3).any(|k| (p[k] - mean[k]).abs() > 0.15));
        }
    }
    off
}

/// The standard material's textures are sampled at the hit with the entry UV's gradients: the
/// thin dark streaks at the feet of steep features, where the hit UV jumps between neighbouring
/// pixels and its own derivatives pick a far too coarse mip, are gone. Each picture is set
/// against a 4x4 supersampled render of itself (the edges of the relief differ in both); the
/// pixels over the threshold are counted with the entry UV's gradients and with the hit UV's
/// derivatives (Bevy's own sampling, `entry_gradients` off). `POMKIT_PICTURES=DIR` writes the
/// pictures (three times the size).
#[test]
fn textures_at_the_hit_have_no_streaks_at_the_feet_of_steep_features() {
    let _gpu = GPU.lock().unwrap_or_else(|e| e.into_inner());
    let mut counts = Vec::new();
    for hit_derivatives in [true, false] {
        let (frame, rays) = streak_frame(1, hit_derivatives);
        let (reference, _) = streak_frame(4, hit_derivatives);
        // The quad's inside: its outline against the background is aliased in any picture.
        let pixels = inside(&rays.expect("the camera's rays"), 0.02);
        let off = off_reference(&frame, &reference, 4, &pixels);
        let name = if hit_derivatives { "hit-uv-derivatives" } else { "entry-uv-gradients" };
        eprintln!("{name}: {off} of {} pixels off the supersampled picture", pixels.len());
        if let Some(dir) = std::env::var_os("POMKIT_PICTURES") {
            let path = std::path::Path::new(&dir).join(format!("bevy-streaks-{name}.png"));
            // Three times the size, each pixel a 3 x 3 block, so that one-pixel streaks show.
            let picture = image::RgbaImage::from_raw(W, H, frame.to_srgb8()).expect("a whole frame");
            image::imageops::resize(&picture, 3 * W, 3 * H, image::imageops::FilterType::Nearest)
                .save(&path)
                .expect("write the picture");
        }
        counts.push(off);
    }
    let (before, after) = (counts[0], counts[1]);
    assert!(before > 100, "the hit UV's derivatives draw no streaks here ({before} pixels): the test is blind");
    assert!(after * 10 < before, "{after} pixels off with the entry UV's gradients, {before} with the hit UV's");
}

/// The headless example, run where `XDG_RUNTIME_DIR` is unset (a container, CI), writes its
/// picture and logs no error and no warning of its own making: not Mesa's runtime-directory
/// line (without `pomkit_gpu::util::ensure_runtime_dir`), and not Bevy's "Failed to send
/// readback result", which an app dropped with a frame copy still in flight logs at exit. (Bevy's warning that lavapipe renders in software is the machine's, and stays.)
/// `cargo test` builds the examples beside the tests; a run of this file alone may not have it.
#[test]
fn the_headless_example_exits_without_errors_or_warnings() {
    let _gpu = GPU.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let Some(picture) = examples::picture_of("headless", &["--width", "64", "--height", "36", "--technique", "pom"])
    else {
        return;
    };
    assert_eq!(picture.dimensions(), (64, 36));
}
