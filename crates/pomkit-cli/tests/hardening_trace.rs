//! Hardening of tracing: huge UVs with wrapping edges finish and give
//! the hit of the same ray in the first tile; directions of any length are the same ray; the
//! depth scale and the perspective bias are bounded on every verb and in scene files; the CPU
//! renderer draws meshes whose UVs are about 1e15.

mod support;

use std::path::Path;
use std::sync::Arc;

use pomkit_core::glam::{Mat4, Vec2, Vec3};
use pomkit_core::mesh::Mesh;
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::scene::{Camera, Light, Material, Object, Scene};
use pomkit_core::shadow::{ShadowMode, ShadowParams};
use pomkit_core::trace::{MAX_DEPTH_SCALE, Technique};
use pomkit_core::{EdgeMode, HeightField};
use pomkit_cpu::{CpuRenderer, RenderOptions};
use support::{pomkit, refuses, stderr};

const HEIGHT: &str = "builtin:cobblestones:64x64";

/// One line of a hits file: `u,v,depth,fetches`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HitLine {
    u: f32,
    v: f32,
    depth: f32,
    fetches: u32,
}

/// Traces `rays` (the body of a rays file, without its header) with `args` in `dir` and returns
/// the hits, asserting a clean exit.
fn trace_rays(dir: &Path, rays: &str, args: &[&str]) -> Vec<HitLine> {
    std::fs::write(dir.join("r.csv"), format!("u,v,dx,dy,dz\n{rays}")).expect("write rays");
    let _ = std::fs::remove_file(dir.join("hits.csv"));
    let mut all = vec!["trace", "--height", HEIGHT, "--rays", "r.csv", "-o", "hits.csv"];
    all.extend_from_slice(args);
    let out = pomkit(&all, dir);
    assert!(out.status.success(), "{all:?} failed: {}", stderr(&out));
    let text = std::fs::read_to_string(dir.join("hits.csv")).expect("hits written");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("u,v,depth,fetches"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 4, "{l}");
            HitLine {
                u: f[0].parse().expect("u"),
                v: f[1].parse().expect("v"),
                depth: f[2].parse().expect("depth"),
                fetches: f[3].parse().expect("fetches"),
            }
        })
        .collect()
}

#[test]
fn exact_with_huge_uvs_and_wrapping_edges_finishes_with_the_first_tiles_hit() {
    // A reported hang: exact spun forever here (u >= 3e14). f32(1e15) = 999999986991104 and f32(3e14) are
    // whole numbers of tiles, so with wrapping edges the truth is the same ray entering at u = 0
    // (a tile away from any f32 rounding): same depth, same v, same fetches, and the hit's u is
    // the entry's, to the f32 spacing there (2^26 at 1e15).
    let dir = tempfile::tempdir().expect("temp dir");
    for technique in ["exact", "pom", "relief", "steep", "pom-classic", "iterative", "parallax"] {
        let hits = trace_rays(
            dir.path(),
            "1e15,0.3,0.5,0.2,-0.6\n0,0.3,0.5,0.2,-0.6\n3e14,0.3,0.5,0.2,-0.6\n-1e15,0.3,0.5,0.2,-0.6\n",
            &["--technique", technique],
        );
        let (huge, first) = (hits[0], hits[1]);
        assert!(first.depth > 0.0 && first.depth <= 1.0 && first.fetches > 0, "{technique}: {first:?}");
        for (k, (u, hit)) in [(1e15f32, huge), (3e14, hits[2]), (-1e15, hits[3])].into_iter().enumerate() {
            assert!(hit.u.is_finite() && (0.0..=1.0).contains(&hit.depth), "{technique} ray {k}: {hit:?}");
            assert_eq!((hit.depth, hit.v, hit.fetches), (first.depth, first.v, first.fetches), "{technique} {u}");
            // The hit u is in the ray's own tile frame: u plus the small hit's offset, which f32
            // cannot resolve there.
            let spacing = f64::from(u.abs()) * f64::from(f32::EPSILON);
            let offset = f64::from(hit.u) - (f64::from(u) + f64::from(first.u));
            assert!(offset.abs() <= spacing, "{technique}: hit u {} for entry {u} (spacing {spacing})", hit.u);
        }
    }
    // With clamped edges the same rays finish too (they sample the border texels).
    let hits = trace_rays(dir.path(), "1e15,0.3,0.5,0.2,-0.6\n", &["--technique", "exact", "--edges", "clamp"]);
    assert!(hits[0].u.is_finite() && (0.0..=1.0).contains(&hits[0].depth));
}

#[test]
fn huge_depth_scales_are_refused_naming_the_flag_and_the_limit() {
    // Unbounded, compare --depth-scale 1e14 would hang (even with --techniques pom, since exact
    // is the truth).
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("r.csv"), "u,v,dx,dy,dz\n0.3,0.4,0.5,0.2,-0.6\n").expect("write rays");
    for scale in ["1e14", "1e20", "1e30", "1e4", "16.01", "inf"] {
        refuses(
            &["compare", "--height", HEIGHT, "--depth-scale", scale, "--techniques", "pom", "-o", "t.md"],
            dir.path(),
            &["--depth-scale", "at most 16"],
        );
        refuses(
            &[
                "trace",
                "--height",
                HEIGHT,
                "--depth-scale",
                scale,
                "--technique",
                "exact",
                "--rays",
                "r.csv",
                "-o",
                "h.csv",
            ],
            dir.path(),
            &["--depth-scale", "at most 16"],
        );
    }
}

#[test]
fn the_largest_depth_scale_still_finishes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let max = MAX_DEPTH_SCALE.to_string();
    let args =
        ["compare", "--height", HEIGHT, "--depth-scale", &max, "--rays", "200", "--format", "csv", "-o", "t.csv"];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    let table = std::fs::read_to_string(dir.path().join("t.csv")).expect("table written");
    let rows: Vec<Vec<&str>> = table.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 10 * 5, "every technique at every default angle");
    for r in &rows {
        let mean: f64 = r[3].parse().expect("mean error");
        assert!(mean.is_finite() && mean >= 0.0, "{r:?}");
        if r[0] == "exact" {
            assert_eq!(mean, 0.0);
            assert!(r[7].parse::<u32>().expect("max fetches") > 0);
        }
    }
    // The trace verb accepts it too, and its hit is the ray's (depth in [0, 1]).
    let hits = trace_rays(dir.path(), "0.3,0.4,0.5,0.2,-0.6\n", &["--technique", "exact", "--depth-scale", &max]);
    assert!(hits[0].depth > 0.0 && hits[0].depth <= 1.0 && hits[0].fetches > 0, "{:?}", hits[0]);
}

#[test]
fn long_and_short_directions_give_the_unit_directions_hit() {
    // (1e20, 1e20, -1e20) and (1e-30, 1e-30, -1e-30) returned the entry point with 0 fetches.
    // They are the direction (1, 1, -1) exactly (same ratios), so the hits must be identical.
    let dir = tempfile::tempdir().expect("temp dir");
    for technique in ["exact", "pom", "relief", "parallax"] {
        let hits = trace_rays(
            dir.path(),
            "0.3,0.4,1,1,-1\n0.3,0.4,1e20,1e20,-1e20\n0.3,0.4,1e-30,1e-30,-1e-30\n0.3,0.4,1e38,1e38,-1e38\n",
            &["--technique", technique],
        );
        assert!(hits[0].fetches > 0 && hits[0].depth > 0.0, "{technique}: {:?}", hits[0]);
        for h in &hits[1..] {
            assert_eq!(*h, hits[0], "{technique}");
        }
    }
    // A zero direction and one that leaves the surface keep their documented result: the entry
    // point, depth 0, no fetch.
    let hits = trace_rays(dir.path(), "0.3,0.4,0,0,0\n0.3,0.4,1e-30,0,1e-30\n", &["--technique", "exact"]);
    for h in hits {
        assert_eq!(h, HitLine { u: 0.3, v: 0.4, depth: 0.0, fetches: 0 });
    }
}

#[test]
fn perspective_bias_outside_zero_to_one_is_refused_naming_the_flag() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("r.csv"), "u,v,dx,dy,dz\n0.3,0.4,0.5,0.2,-0.6\n").expect("write rays");
    for bias in ["-1", "1e30", "1.5", "-0.001"] {
        refuses(
            &[
                "trace",
                "--height",
                HEIGHT,
                "--technique",
                "pom-classic",
                "--perspective-bias",
                bias,
                "--rays",
                "r.csv",
                "-o",
                "h.csv",
            ],
            dir.path(),
            &["--perspective-bias", "[0, 1]"],
        );
        refuses(
            &["compare", "--height", HEIGHT, "--perspective-bias", bias, "--rays", "10", "-o", "t.md"],
            dir.path(),
            &["--perspective-bias", "[0, 1]"],
        );
    }
    // The ends of the range are accepted.
    for bias in ["0", "1"] {
        let hits = trace_rays(
            dir.path(),
            "0.3,0.4,0.5,0.2,-0.6\n",
            &["--technique", "pom-classic", "--perspective-bias", bias],
        );
        assert!((0.0..=1.0).contains(&hits[0].depth));
    }
}

/// A one-plane scene with one material whose technique options end with `extra`.
fn scene_text(extra: &str) -> String {
    format!(
        "[camera]\neye = [0.0, 2.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\n\n\
         [[material]]\nname = \"m\"\nheight = \"builtin:cobblestones:64x64\"\ntechnique = \"pom-classic\"\n{extra}\n\n\
         [[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
    )
}

#[test]
fn scene_files_with_out_of_range_depth_scale_or_bias_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (extra, needles) in [
        ("depth_scale = 1e4", ["depth_scale", "at most 16"]),
        ("depth_scale = 1e30", ["depth_scale", "at most 16"]),
        ("perspective_bias = -1.0", ["perspective_bias", "[0, 1]"]),
        ("perspective_bias = 1e30", ["perspective_bias", "[0, 1]"]),
    ] {
        std::fs::write(dir.path().join("s.toml"), scene_text(extra)).expect("write scene");
        for backend in ["cpu", "auto"] {
            refuses(
                &["render", "s.toml", "--backend", backend, "--size", "16x16", "-o", "out.png"],
                dir.path(),
                &["s.toml", needles[0], needles[1]],
            );
        }
    }
    // The limit itself renders.
    std::fs::write(dir.path().join("s.toml"), scene_text("depth_scale = 16.0\nperspective_bias = 0.0")).expect("scene");
    let out = pomkit(&["render", "s.toml", "--backend", "cpu", "--size", "16x16", "-o", "out.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("out.png").is_file());
}

#[test]
fn cpu_renderer_draws_uvs_of_1e15_with_exact() {
    // A mesh whose UVs are about 1e15 must not hang the CPU renderer with `exact` (and exact
    // shadows).
    let mut plane = Mesh::plane(Vec2::splat(2.0), 1);
    for uv in &mut plane.uvs {
        *uv += Vec2::new(1e15, -1e15);
    }
    let field: HeightField = generate(Pattern::Cobblestones, 64, 64);
    let scene = Scene {
        camera: Camera { eye: Vec3::new(0.0, 1.5, 1.5), target: Vec3::ZERO, ..Camera::default() },
        lights: vec![Light::Directional { direction: Vec3::new(0.3, 1.0, 0.2), color: Vec3::ONE, intensity: 1.0 }],
        materials: vec![Material {
            height: Some(Arc::new(field)),
            technique: Technique::Exact,
            depth_scale: 0.1,
            edges: EdgeMode::Wrap,
            shadow: ShadowParams { mode: ShadowMode::Exact, ..Default::default() },
            ..Material::default()
        }],
        objects: vec![Object { name: "plane".into(), mesh: Arc::new(plane), material: 0, transform: Mat4::IDENTITY }],
        ambient: Vec3::splat(0.05),
        background: Vec3::ZERO,
    };
    let opts = RenderOptions { width: 24, height: 24, aovs: true, ..Default::default() };
    let out = CpuRenderer::new().render(&scene, &opts, &|_, _| {}).expect("renders");
    assert!(out.color.iter().all(|c| c.is_finite()), "a non-finite pixel");
    // The plane fills the middle of the view: those pixels are drawn (not background).
    let centre = out.color[(12 * 24 + 12) as usize];
    assert!(centre.max_element() > 0.0, "the plane is drawn: {centre}");
}
