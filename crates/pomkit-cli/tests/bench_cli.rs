//! `pomkit bench` end to end: the CSV table has the promised header and one row per technique
//! with sane numbers, fetches agree with what the techniques are (normal mapping reads no
//! heights), and bad input fails with a clear message before any work (DESIGN section 6).
//!
//! Sizes: at 64x36 the demo's textures are minified so far (mip level above 5) that every
//! material takes its LOD fallback to normal mapping, and pom fetches nothing either. 160x90 is
//! the smallest cheap size where pom traces most covered pixels.

use std::process::{Command, Output};

const HEADER: &str = "technique,width,height,runs,median_ms,mpix_per_s,fetches_per_pixel";

fn pomkit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_pomkit")).args(args).output().expect("pomkit runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// One CSV row.
#[derive(Debug)]
struct Row {
    technique: String,
    width: u32,
    height: u32,
    runs: u32,
    median_ms: f64,
    mpix_per_s: f64,
    fetches_per_pixel: f64,
}

/// Parses the CSV table, checking the header.
fn parse(text: &str) -> Vec<Row> {
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(HEADER), "header of:\n{text}");
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 7, "row '{l}'");
            Row {
                technique: f[0].to_owned(),
                width: f[1].parse().unwrap(),
                height: f[2].parse().unwrap(),
                runs: f[3].parse().unwrap(),
                median_ms: f[4].parse().unwrap(),
                mpix_per_s: f[5].parse().unwrap(),
                fetches_per_pixel: f[6].parse().unwrap(),
            }
        })
        .collect()
}

#[test]
fn csv_has_one_row_per_technique_and_normal_mapping_fetches_nothing() {
    let out = pomkit(&["bench", "--size", "160x90", "--runs", "1", "--techniques", "pom,normal", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = parse(&stdout(&out));
    let names: Vec<&str> = rows.iter().map(|r| r.technique.as_str()).collect();
    assert_eq!(names, ["pom", "normal"]);
    for r in &rows {
        assert_eq!((r.width, r.height, r.runs), (160, 90, 1), "{r:?}");
        assert!(r.median_ms.is_finite() && r.median_ms > 0.0, "{r:?}");
        assert!(r.mpix_per_s.is_finite() && r.mpix_per_s > 0.0, "{r:?}");
        // Megapixels per second is the frame's pixels over the median time.
        let expected = 160.0 * 90.0 / (r.median_ms / 1e3) / 1e6;
        assert!((r.mpix_per_s - expected).abs() <= 1e-6 * expected, "{r:?}: expected {expected} Mpix/s");
        assert!(r.fetches_per_pixel.is_finite() && r.fetches_per_pixel >= 0.0, "{r:?}");
    }
    // Independent truth: normal mapping reads the normal map only, never the heights (its hit
    // is the polygon's surface, where no shadow trace can find an occluder); pom traces.
    assert_eq!(rows[1].fetches_per_pixel, 0.0, "normal: {:?}", rows[1]);
    assert!(rows[0].fetches_per_pixel > 1.0, "pom: {:?}", rows[0]);
}

#[test]
fn material_means_each_material_s_own_technique_pom_in_the_demo() {
    // The demo's materials all use pom with their own parameters, which `pom` keeps: the two
    // frames are the same, so are their fetches.
    let out = pomkit(&["bench", "--size", "160x90", "--runs", "1", "--techniques", "material,pom", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let rows = parse(&stdout(&out));
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].technique, "material");
    assert!(rows[0].fetches_per_pixel > 1.0, "{:?}", rows[0]);
    assert_eq!(rows[0].fetches_per_pixel, rows[1].fetches_per_pixel, "{rows:?}");
}

#[test]
fn markdown_is_the_default_and_progress_goes_to_stderr() {
    let out = pomkit(&["bench", "--size", "32x18", "--runs", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(
        text.contains("| technique | size | runs | median ms/frame | Mpix/s | fetches per covered pixel |"),
        "{text}"
    );
    assert!(text.contains("| pom | 32x18 | 2 |"), "{text}");
    assert_eq!(text.lines().filter(|l| l.starts_with("| pom")).count(), 1, "{text}");
    assert!(stderr(&out).contains("pom: run 2/2"), "{}", stderr(&out));
}

#[test]
fn help_says_what_is_measured() {
    let out = pomkit(&["bench", "--help"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    for needle in ["warm-up", "median", "--displaced", "fetches", HEADER] {
        assert!(text.contains(needle), "--help lacks '{needle}':\n{text}");
    }
}

#[test]
fn bad_input_fails_with_a_clear_message() {
    let cases: [(&[&str], &[&str]); 6] = [
        (&["--runs", "0"], &["--runs 0", "between 1 and"]),
        (&["--size", "0x5"], &["--size", "'0x5'", "between 1 and 16384"]),
        (&["--size", "64"], &["--size", "not WxH"]),
        (&["--techniques", "pom,bogus"], &["unknown technique 'bogus'", "pom-classic", "material"]),
        (&["--techniques", "pom,,normal"], &["empty name"]),
        (&["--techniques", "displaced"], &["--displaced"]),
    ];
    for (args, needles) in cases {
        let mut all = vec!["bench"];
        all.extend_from_slice(args);
        let out = pomkit(&all);
        assert!(!out.status.success(), "{all:?} succeeded");
        let err = stderr(&out);
        for n in needles {
            assert!(err.contains(n), "{all:?}: stderr lacks '{n}':\n{err}");
        }
        assert!(stdout(&out).is_empty(), "{all:?} wrote a table:\n{}", stdout(&out));
    }
}
