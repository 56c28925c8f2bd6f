//! `pomkit trace` and `pomkit compare` end to end: hits equal what core computes for the same
//! rays, the table formats are what the README and ARCHITECTURE.md promise, and bad input fails with a clear
//! message and leaves no file behind (docs/LIMITS.md).

use std::path::Path;
use std::process::{Command, Output};

use pomkit_core::EdgeMode;
use pomkit_core::accuracy;
use pomkit_core::glam::{Vec2, Vec3};
use pomkit_core::procedural::{self, Pattern};
use pomkit_core::scene::Material;
use pomkit_core::trace::{Ray, Surface, Technique, TraceParams, trace};

fn pomkit(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).current_dir(dir).output().expect("pomkit runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Files in `dir`, sorted, to prove nothing partial was left.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// A small set of rays: ordinary, non-unit, head-on, grazing, outside the tile, and ones that
/// do not enter (dz >= 0, zero direction).
fn sample_rays() -> Vec<Ray> {
    let mut rays = vec![
        Ray::new(Vec2::new(0.5, 0.5), Vec3::new(0.5, 0.0, -1.0)),
        Ray::new(Vec2::new(0.1, 0.2), Vec3::new(0.3, 0.4, -0.5)),
        Ray::new(Vec2::new(0.9, 0.05), Vec3::new(-2.0, 1.0, -0.7)),
        Ray::new(Vec2::new(0.3, 0.7), Vec3::new(0.0, 0.0, -1.0)),
        Ray::new(Vec2::new(0.25, 0.75), Vec3::new(1.0, -1.0, -0.01)),
        Ray::new(Vec2::new(1.7, -0.4), Vec3::new(0.2, 0.1, -0.3)),
        Ray::new(Vec2::new(0.4, 0.4), Vec3::new(0.2, 0.1, 0.3)),
        Ray::new(Vec2::new(0.4, 0.4), Vec3::new(0.0, 0.0, 0.0)),
    ];
    rays.extend(accuracy::ray_set(70.0, 40, 3));
    rays
}

fn rays_csv(rays: &[Ray]) -> String {
    let mut s = String::from("u,v,dx,dy,dz\n");
    for r in rays {
        s += &format!("{},{},{},{},{}\n", r.uv.x, r.uv.y, r.dir.x, r.dir.y, r.dir.z);
    }
    s
}

/// Parses a hits file into (u, v, depth, fetches), checking the header.
fn parse_hits(text: &str) -> Vec<(f32, f32, f32, u32)> {
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("u,v,depth,fetches"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 4, "line {l:?}");
            (f[0].parse().unwrap(), f[1].parse().unwrap(), f[2].parse().unwrap(), f[3].parse().unwrap())
        })
        .collect()
}

#[test]
fn trace_gives_exactly_what_core_gives() {
    let dir = tempfile::tempdir().unwrap();
    let rays = sample_rays();
    std::fs::write(dir.path().join("rays.csv"), rays_csv(&rays)).unwrap();
    let field = procedural::generate(Pattern::Pyramids, 64, 64);
    // Default options, then changed ones: every option must reach the tracer.
    let d = Material::default();
    let defaults = (TraceParams::default(), d.depth_scale, d.edges);
    let changed = TraceParams {
        min_samples: 5,
        max_samples: 17,
        samples: 11,
        iterations: 3,
        binary_steps: 4,
        refine: 2,
        perspective_bias: 0.5,
        ..TraceParams::default()
    };
    let changed = (changed, 0.06, EdgeMode::Clamp);
    let changed_flags = [
        "--depth-scale",
        "0.06",
        "--min-samples",
        "5",
        "--max-samples",
        "17",
        "--samples",
        "11",
        "--iterations",
        "3",
        "--binary-steps",
        "4",
        "--refine",
        "2",
        "--perspective-bias",
        "0.5",
        "--edges",
        "clamp",
    ];
    for ((params, depth_scale, edges), extra) in [(defaults, &[][..]), (changed, &changed_flags[..])] {
        let surface = Surface::new(field.clone(), edges, depth_scale);
        for technique in Technique::ALL {
            let mut args = vec![
                "trace",
                "--height",
                "builtin:pyramids:64x64",
                "--technique",
                technique.name(),
                "--rays",
                "rays.csv",
            ];
            args.extend_from_slice(&["-o", "hits.csv"]);
            args.extend_from_slice(extra);
            let out = pomkit(&args, dir.path());
            assert!(out.status.success(), "{args:?}: {}", stderr(&out));
            assert!(out.stdout.is_empty(), "trace printed to stdout: {}", stdout(&out));
            let text = std::fs::read_to_string(dir.path().join("hits.csv")).unwrap();
            assert_eq!(text.lines().count(), rays.len() + 1);
            let hits = parse_hits(&text);
            for (i, (ray, got)) in rays.iter().zip(&hits).enumerate() {
                let want = trace(&surface, ray, technique, &params);
                assert_eq!(*got, (want.uv.x, want.uv.y, want.depth, want.fetches), "{technique} ray {i} {extra:?}");
            }
            // Rays that do not enter give the entry point at depth 0.
            for &(u, v, depth, fetches) in &hits[6..8] {
                assert_eq!((u, v, depth, fetches), (0.4, 0.4, 0.0, 0), "{technique}");
            }
        }
    }
}

#[test]
fn trace_writes_headers_only_for_no_rays_and_can_use_stdout() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("none.csv"), "u,v,dx,dy,dz\n").unwrap();
    let base = ["trace", "--height", "builtin:bricks:32x32", "--technique", "pom"];
    let out = pomkit(&[&base[..], &["--rays", "none.csv", "-o", "h.csv"]].concat(), dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(dir.path().join("h.csv")).unwrap(), "u,v,depth,fetches\n");

    std::fs::write(dir.path().join("r.csv"), rays_csv(&sample_rays())).unwrap();
    let out = pomkit(&[&base[..], &["--rays", "r.csv", "-o", "h.csv"]].concat(), dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let file = std::fs::read_to_string(dir.path().join("h.csv")).unwrap();
    let out = pomkit(&[&base[..], &["--rays", "r.csv", "-o", "-"]].concat(), dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out), file, "-o - writes the same CSV to stdout");
    assert_eq!(listing(dir.path()), ["h.csv", "none.csv", "r.csv"]);
}

#[test]
fn bad_trace_input_fails_clearly_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = "u,v,dx,dy,dz\n0.5,0.5,0.1,0,-1\n";
    std::fs::write(dir.path().join("good.csv"), good).unwrap();
    std::fs::write(dir.path().join("header.csv"), "u,v,dx,dy\n0.5,0.5,0.1,0\n").unwrap();
    std::fs::write(dir.path().join("word.csv"), "u,v,dx,dy,dz\n0.5,0.5,0.1,0,-1\n0.5,0.5,abc,0,-1\n").unwrap();
    std::fs::write(dir.path().join("short.csv"), "u,v,dx,dy,dz\n0.5,0.5,0.1,-1\n").unwrap();
    std::fs::write(dir.path().join("nan.csv"), "u,v,dx,dy,dz\n0.5,0.5,0.1,0,-1\n1,1,1,1,-1\nNaN,0.5,0.1,0,-1\n")
        .unwrap();
    std::fs::write(dir.path().join("inf.csv"), "u,v,dx,dy,dz\n0.5,0.5,inf,0,-1\n").unwrap();
    std::fs::write(dir.path().join("empty.csv"), "").unwrap();
    let before = listing(dir.path());

    let h = ["trace", "--height", "builtin:pyramids:32x32", "--technique", "pom", "-o", "out.csv"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> { [&h[..], extra].concat() };
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (with(&["--rays", "header.csv"]), vec!["header.csv", "line 1", "u,v,dx,dy,dz"]),
        (with(&["--rays", "word.csv"]), vec!["word.csv", "line 3", "abc", "not a number"]),
        (with(&["--rays", "short.csv"]), vec!["short.csv", "line 2", "expected 5 values"]),
        (with(&["--rays", "nan.csv"]), vec!["nan.csv", "line 4", "not finite"]),
        (with(&["--rays", "inf.csv"]), vec!["inf.csv", "line 2", "not finite"]),
        (with(&["--rays", "empty.csv"]), vec!["empty.csv", "empty"]),
        (with(&["--rays", "missing.csv"]), vec!["missing.csv"]),
        (with(&["--rays", "good.csv", "--depth-scale", "0"]), vec!["--depth-scale"]),
        (with(&["--rays", "good.csv", "--depth-scale", "NaN"]), vec!["--depth-scale"]),
        (with(&["--rays", "good.csv", "--depth-scale", "-0.1"]), vec!["--depth-scale"]),
        (with(&["--rays", "good.csv", "--perspective-bias", "inf"]), vec!["--perspective-bias"]),
        (with(&["--rays", "good.csv", "--min-samples", "40"]), vec!["--min-samples", "--max-samples"]),
        (with(&["--rays", "good.csv", "--edges", "mirror"]), vec!["--edges", "wrap", "clamp"]),
        (
            vec!["trace", "--height", "missing.png", "--technique", "pom", "--rays", "good.csv", "-o", "out.csv"],
            vec!["missing.png"],
        ),
        (
            vec![
                "trace",
                "--height",
                "builtin:pyramids:32x32",
                "--technique",
                "pomm",
                "--rays",
                "good.csv",
                "-o",
                "o.csv",
            ],
            vec!["pomm", "flat", "parallax", "iterative", "steep", "pom-classic", "relief", "exact"],
        ),
        (
            vec![
                "trace",
                "--height",
                "builtin:pyramids:8x8",
                "--technique",
                "pom",
                "--rays",
                "good.csv",
                "-o",
                "no/dir/o.csv",
            ],
            vec!["does not exist"],
        ),
    ];
    for (args, needles) in &cases {
        let out = pomkit(args, dir.path());
        assert!(!out.status.success(), "{args:?} should fail");
        let msg = stderr(&out);
        for needle in needles {
            assert!(msg.contains(needle), "{args:?}: message {msg:?} should mention {needle:?}");
        }
        assert!(!msg.contains("panicked"), "{args:?} panicked: {msg}");
        assert_eq!(listing(dir.path()), before, "{args:?} left a file behind");
    }
}

const CSV_HEADER: &str = "technique,angle,rays,mean_error,p95_error,share_over_1,mean_fetches,max_fetches";

#[test]
fn compare_csv_has_one_row_per_technique_and_angle() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["compare", "--height", "builtin:pyramids:64x64", "--rays", "300", "--format", "csv"];
    let out = pomkit(&args, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let angles = ["0", "30", "60", "75", "85"];
    assert_eq!(rows.len(), Technique::ALL.len() * angles.len());
    for angle in angles {
        let names: Vec<&str> = rows.iter().filter(|r| r[1] == angle).map(|r| r[0]).collect();
        assert_eq!(names, Technique::ALL.map(Technique::name), "angle {angle}");
    }
    // Independent path: core's table for the same defaults.
    let params = TraceParams::default();
    let d = Material::default();
    let surface = Surface::new(procedural::generate(Pattern::Pyramids, 64, 64), d.edges, d.depth_scale);
    let want = accuracy::compare(
        &surface,
        &Technique::ALL,
        &[0.0, 30.0, 60.0, 75.0, 85.0],
        &params,
        300,
        accuracy::DEFAULT_SEED,
        &|_| {},
    );
    for (r, w) in rows.iter().zip(&want) {
        assert_eq!(r.len(), 8);
        assert_eq!(r[0], w.technique.name());
        assert_eq!(r[2], "300");
        let num = |s: &str| s.parse::<f64>().unwrap();
        assert_eq!(num(r[3]), w.mean_error);
        assert_eq!(num(r[4]), w.p95_error);
        assert_eq!(num(r[5]), w.share_over_1);
        assert!((0.0..=1.0).contains(&num(r[5])));
        assert_eq!(num(r[6]), w.mean_fetches);
        assert_eq!(r[7].parse::<u32>().unwrap(), w.max_fetches);
    }
    // The same seed gives the same table; another seed another.
    assert_eq!(stdout(&pomkit(&args, dir.path())), text);
    let other = pomkit(&[&args[..], &["--seed", "99"]].concat(), dir.path());
    assert_ne!(stdout(&other), text);
    // A chosen list keeps its order and gains the exact row.
    let out = pomkit(
        &["compare", "--height", "builtin:waves:32x32", "--rays", "50", "--format", "csv"]
            .into_iter()
            .chain(["--techniques", "relief,pom", "--angles", "10,45.5"])
            .collect::<Vec<_>>(),
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let keys: Vec<String> =
        stdout(&out).lines().skip(1).map(|l| l.split(',').take(2).collect::<Vec<_>>().join(" ")).collect();
    assert_eq!(keys, ["relief 10", "pom 10", "exact 10", "relief 45.5", "pom 45.5", "exact 45.5"]);
}

#[test]
fn compare_json_and_markdown() {
    let dir = tempfile::tempdir().unwrap();
    let base = ["compare", "--height", "builtin:bricks:64x32", "--rays", "200", "--angles", "20,70"];
    let out = pomkit(&[&base[..], &["--format", "json", "-o", "table.json"]].concat(), dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(out.stdout.is_empty());
    let text = std::fs::read_to_string(dir.path().join("table.json")).unwrap();
    let value: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let rows = value.as_array().expect("an array");
    assert_eq!(rows.len(), 2 * Technique::ALL.len());
    for row in rows {
        let obj = row.as_object().unwrap();
        let keys: Vec<&str> = obj.keys().map(String::as_str).collect();
        let mut want: Vec<&str> = CSV_HEADER.split(',').collect();
        want.sort_unstable();
        let mut keys = keys;
        keys.sort_unstable();
        assert_eq!(keys, want);
        assert!(obj["technique"].as_str().unwrap().parse::<Technique>().is_ok());
        for k in ["angle", "mean_error", "p95_error", "share_over_1", "mean_fetches"] {
            assert!(obj[k].as_f64().unwrap().is_finite(), "{k}");
        }
        assert_eq!(obj["rays"].as_u64(), Some(200));
        assert!(obj["max_fetches"].as_u64().is_some());
    }

    let out = pomkit(&base, dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let md = stdout(&out);
    assert!(
        md.contains("| technique | angle | mean error (texels) | p95 | share > 1 texel | mean fetches | max fetches |")
    );
    for t in Technique::ALL {
        assert!(md.contains(&format!("| {} | 20° |", t.name())), "{t} at 20° missing:\n{md}");
        assert!(md.contains(&format!("| {} | 70° |", t.name())), "{t} at 70° missing:\n{md}");
    }
    assert_eq!(listing(dir.path()), ["table.json"]);
}

#[test]
fn bad_compare_input_fails_clearly_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let h = ["compare", "--height", "builtin:pyramids:16x16", "-o", "t.md"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> { [&h[..], extra].concat() };
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (with(&["--angles", "0,90"]), vec!["--angles", "90"]),
        (with(&["--angles", "-5"]), vec!["--angles", "-5"]),
        (with(&["--angles", "10,x"]), vec!["--angles", "'x'"]),
        (with(&["--angles", "NaN"]), vec!["--angles"]),
        (with(&["--techniques", "pom,foo"]), vec!["foo", "pom-classic", "relief", "exact"]),
        (with(&["--techniques", "pom,,steep"]), vec!["--techniques"]),
        (with(&["--rays", "0"]), vec!["--rays"]),
        (with(&["--depth-scale", "inf"]), vec!["--depth-scale"]),
        (with(&["--format", "xml"]), vec!["--format", "md", "csv", "json"]),
        (vec!["compare", "--height", "nothing.png"], vec!["nothing.png"]),
    ];
    for (args, needles) in &cases {
        let out = pomkit(args, dir.path());
        assert!(!out.status.success(), "{args:?} should fail");
        let msg = stderr(&out);
        for needle in needles {
            assert!(msg.contains(needle), "{args:?}: message {msg:?} should mention {needle:?}");
        }
        assert!(!msg.contains("panicked"), "{args:?} panicked: {msg}");
        assert!(listing(dir.path()).is_empty(), "{args:?} left a file behind");
    }
}

#[test]
fn trace_and_compare_help_list_every_technique_option() {
    let dir = tempfile::tempdir().unwrap();
    let options = [
        "--min-samples",
        "--max-samples",
        "--samples",
        "--iterations",
        "--binary-steps",
        "--refine",
        "--perspective-bias",
        "--edges",
        "--depth-scale",
        "--height",
        "--depth-map",
        "--channel",
    ];
    for verb in ["trace", "compare"] {
        let out = pomkit(&[verb, "--help"], dir.path());
        assert!(out.status.success(), "{verb}");
        let text = stdout(&out);
        assert!(text.contains("Usage"));
        for flag in options {
            assert!(text.contains(flag), "{verb} --help lacks {flag}");
        }
        for t in Technique::ALL {
            assert!(text.contains(t.name()), "{verb} --help lacks technique {t}");
        }
    }
    let text = stdout(&pomkit(&["trace", "--help"], dir.path()));
    for needle in ["--technique", "--rays", "u,v,dx,dy,dz", "u,v,depth,fetches", "dz >= 0"] {
        assert!(text.contains(needle), "trace --help lacks {needle}");
    }
    let text = stdout(&pomkit(&["compare", "--help"], dir.path()));
    for needle in ["--angles", "--techniques", "--rays", "--seed", "--format", CSV_HEADER] {
        assert!(text.contains(needle), "compare --help lacks {needle}");
    }
}

/// `--cone-map`: a map baked by `pomkit bake cone` is read back and stepped on as relaxed
/// cones; its quantized cones are still conservative, so the hits are exact's (the exact
/// tracer's, an independent walk), with a look after each cone step.
#[test]
fn trace_steps_on_a_baked_cone_map() {
    let dir = tempfile::tempdir().expect("temp dir");
    let height = "builtin:cobblestones:64x64";
    let out = pomkit(&["bake", "cone", height, "-o", "cones.png"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let rays = sample_rays();
    std::fs::write(dir.path().join("rays.csv"), rays_csv(&rays)).unwrap();
    let run = |extra: &[&str], output: &str| {
        let mut args = vec!["trace", "--height", height, "--technique", "cone", "--rays", "rays.csv", "-o", output];
        args.extend_from_slice(extra);
        let out = pomkit(&args, dir.path());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        parse_hits(&std::fs::read_to_string(dir.path().join(output)).unwrap())
    };
    let read = run(&["--cone-map", "cones.png"], "read.csv");
    let built = run(&[], "built.csv");
    let surface = Surface::new(procedural::generate(Pattern::Cobblestones, 64, 64), EdgeMode::Wrap, 0.1);
    let (mut read_fetches, mut built_fetches) = (0, 0);
    for ((ray, r), b) in rays.iter().zip(&read).zip(&built) {
        let exact = trace(&surface, ray, Technique::Exact, &TraceParams::default());
        for (name, h) in [("read", r), ("built", b)] {
            let err = (Vec2::new(h.0, h.1) - exact.uv).length() * 64.0;
            assert!(err < 1e-3, "{name} cones, {ray:?}: {h:?} against exact {exact:?}");
        }
        read_fetches += r.3;
        built_fetches += b.3;
    }
    assert!(read_fetches > built_fetches, "read cones look after each step: {read_fetches} vs {built_fetches}");
}

/// A cone map of another size, an image that is not a cone map, and a missing file: each
/// fails naming the file and the problem, and leaves no hits file.
#[test]
fn bad_cone_maps_fail_clearly_and_leave_no_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("rays.csv"), rays_csv(&sample_rays())).unwrap();
    let ok = |args: &[&str]| assert!(pomkit(args, dir.path()).status.success(), "{args:?}");
    ok(&["bake", "cone", "builtin:bricks:32x32", "-o", "small_cones.png"]);
    ok(&["generate", "bricks", "--size", "64x64", "-o", "height.png"]);
    std::fs::write(dir.path().join("junk.png"), b"not an image").unwrap();
    let trace_with = |cones: &str, output: &str| {
        let args = [
            "trace",
            "--height",
            "height.png",
            "--technique",
            "cone",
            "--cone-map",
            cones,
            "--rays",
            "rays.csv",
            "-o",
            output,
        ];
        (pomkit(&args, dir.path()), format!("{args:?}"))
    };
    for (cones, needles) in [
        ("small_cones.png", &["small_cones.png", "32x32", "64x64", "bake cone"][..]),
        ("height.png", &["height.png", "not a cone map", "16-bit grey + alpha"][..]),
        ("junk.png", &["junk.png"][..]),
        ("missing.png", &["missing.png"][..]),
    ] {
        let (out, args) = trace_with(cones, "hits.csv");
        assert!(!out.status.success(), "{args}");
        for n in needles {
            assert!(stderr(&out).contains(n), "{args}: stderr lacks '{n}':\n{}", stderr(&out));
        }
        assert!(!dir.path().join("hits.csv").exists(), "{args} left a hits file");
    }
    // The hits file may not overwrite the cone map.
    let (out, _) = trace_with("small_cones.png", "small_cones.png");
    assert!(!out.status.success() && stderr(&out).contains("small_cones.png"), "{}", stderr(&out));
}
