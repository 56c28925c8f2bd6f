//! `pomkit compare --yardstick` end to end: the yardstick table in md, csv and json is what
//! pomkit-core's `accuracy::yardstick` computes for the same rays, it parses, the accuracy table
//! is unchanged with and without the flag (ARCHITECTURE.md, Stable interfaces), "not reached"
//! is said, and bad flags fail clearly and leave no file behind.

mod support;

use std::path::Path;

use pomkit_core::EdgeMode;
use pomkit_core::accuracy::{self, YardstickOptions};
use pomkit_core::procedural::{self, Pattern};
use pomkit_core::trace::{Surface, TraceParams};
use support::{pomkit, stderr, stdout};

fn run(args: &[&str], dir: &Path) -> String {
    let out = pomkit(args, dir);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    stdout(&out)
}

/// The accuracy table's header (the stable one) and the yardstick's, written out here rather
/// than taken from the binary's source.
const CSV_HEADER: &str = "technique,angle,rays,mean_error,p95_error,share_over_1,mean_fetches,max_fetches";
const YARDSTICK_HEADER: &str = "angle,rays,max_share,cap,pom_samples,pom_mean_fetches,pom_max_fetches,\
pom_share_over_1,pom_mean_error,pom_p95_error,pom_share_below,refine,refined_samples,refined_mean_fetches,\
refined_max_fetches,refined_share_over_1,refined_mean_error,refined_p95_error,refined_share_below,\
exact_mean_fetches,exact_max_fetches,ratio";

const BASE: [&str; 7] = ["compare", "--height", "builtin:cobblestones:64x64", "--rays", "300", "--angles", "60,80"];

/// Parses a CSV table into its header and rows of fields (no quoting: every field is a number,
/// a name or empty).
fn parse_csv(text: &str) -> (String, Vec<Vec<String>>) {
    let mut lines = text.lines();
    let header = lines.next().expect("a header").to_owned();
    let rows = lines.map(|l| l.split(',').map(str::to_owned).collect()).collect();
    (header, rows)
}

#[test]
fn without_the_flag_the_accuracy_table_is_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let md = run(&BASE, dir.path());
    assert!(!md.contains("yardstick"), "no yardstick without the flag:\n{md}");
    assert!(
        md.contains("| technique | angle | mean error (texels) | p95 | share > 1 texel | mean fetches | max fetches |")
    );
    // With the flag, md prints the same accuracy table first, then the yardstick.
    let both = run(&[&BASE[..], &["--yardstick"]].concat(), dir.path());
    let rest = both.strip_prefix(&md).unwrap_or_else(|| panic!("the accuracy table changed:\n{both}"));
    assert!(rest.starts_with("\nThe honest yardstick on builtin:cobblestones:64x64 (64x64"), "{rest}");
    let csv = run(&[&BASE[..], &["--format", "csv"]].concat(), dir.path());
    let (header, rows) = parse_csv(&csv);
    assert_eq!(header, CSV_HEADER);
    assert_eq!(rows.len(), 2 * 10, "ten techniques at two angles");
    assert!(rows.iter().all(|r| r.len() == 8));
    let json = run(&[&BASE[..], &["--format", "json"]].concat(), dir.path());
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut keys: Vec<&str> = value[0].as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    let mut want: Vec<&str> = CSV_HEADER.split(',').collect();
    want.sort_unstable();
    assert_eq!(keys, want);
}

#[test]
fn the_yardstick_in_csv_and_json_is_core_s() {
    let dir = tempfile::tempdir().unwrap();
    let csv = run(&[&BASE[..], &["--yardstick", "--format", "csv"]].concat(), dir.path());
    let (header, rows) = parse_csv(&csv);
    assert_eq!(header, YARDSTICK_HEADER, "csv and json hold the yardstick table alone");
    assert_eq!(rows.len(), 2);
    let keys: Vec<&str> = YARDSTICK_HEADER.split(',').collect();
    // Independent path: core's yardstick on the same map, rays and defaults.
    let surface = Surface::new(procedural::generate(Pattern::Cobblestones, 64, 64), EdgeMode::Wrap, 0.1);
    let want = accuracy::yardstick(
        &surface,
        &[60.0, 80.0],
        &TraceParams::default(),
        300,
        accuracy::DEFAULT_SEED,
        &YardstickOptions::default(),
        &|_| {},
    );
    for (row, w) in rows.iter().zip(&want) {
        assert_eq!(row.len(), keys.len());
        let field = |k: &str| row[keys.iter().position(|&x| x == k).unwrap()].as_str();
        let num = |k: &str| field(k).parse::<f64>().unwrap_or_else(|_| panic!("{k}: {:?}", field(k)));
        assert_eq!(num("angle"), f64::from(w.angle_deg));
        assert_eq!((field("rays"), field("max_share"), field("cap"), field("refine")), ("300", "0.001", "1024", "2"));
        for (prefix, search) in [("pom", &w.plain), ("refined", &w.refined)] {
            let n = search.samples().expect("reached on cobblestones at 64x64");
            assert_eq!(field(&format!("{prefix}_samples")), n.to_string());
            assert_eq!(num(&format!("{prefix}_mean_fetches")), search.row().mean_fetches);
            assert_eq!(num(&format!("{prefix}_share_over_1")), search.row().share_over_1);
            assert!(num(&format!("{prefix}_share_over_1")) <= 0.001);
            assert_eq!(num(&format!("{prefix}_mean_error")), search.row().mean_error);
            if n > 8 {
                assert!(num(&format!("{prefix}_share_below")) > 0.001, "N-1 fails");
            }
        }
        assert_eq!(num("exact_mean_fetches"), w.exact.mean_fetches);
        assert_eq!(num("ratio"), w.ratio().unwrap());
    }
    // exact's fetches are the accuracy table's on the same rays.
    let (_, table) = parse_csv(&run(&[&BASE[..], &["--techniques", "exact", "--format", "csv"]].concat(), dir.path()));
    for (row, exact) in rows.iter().zip(&table) {
        assert_eq!(row[keys.iter().position(|&x| x == "exact_mean_fetches").unwrap()], exact[6]);
    }
    // json: the same fields as numbers, keyed by the header.
    let json = run(&[&BASE[..], &["--yardstick", "--format", "json"]].concat(), dir.path());
    let value: serde_json::Value = serde_json::from_str(&json).expect("valid JSON");
    let objects = value.as_array().unwrap();
    assert_eq!(objects.len(), 2);
    for (obj, row) in objects.iter().zip(&rows) {
        let obj = obj.as_object().unwrap();
        assert_eq!(obj.len(), keys.len());
        for (k, v) in keys.iter().zip(row) {
            // serde_json's float parsing (without its float_roundtrip feature) may be off in
            // the last bit.
            let (got, want) = (obj[*k].as_f64().unwrap(), v.parse::<f64>().unwrap());
            assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0), "{k}: {got} != {want}");
        }
    }
    // A nonzero --refine is the refined search's; --min-samples and --max-samples are not used.
    let csv = run(
        &[&BASE[..], &["--yardstick", "--format", "csv", "--refine", "3", "--min-samples", "4", "--max-samples", "9"]]
            .concat(),
        dir.path(),
    );
    let (_, rows3) = parse_csv(&csv);
    let k = |name: &str| keys.iter().position(|&x| x == name).unwrap();
    for (r3, r2) in rows3.iter().zip(&rows) {
        assert_eq!(r3[k("refine")], "3");
        assert_eq!(r3[k("pom_samples")], r2[k("pom_samples")], "the plain search does not depend on --refine");
    }
}

#[test]
fn not_reached_is_said() {
    let dir = tempfile::tempdir().unwrap();
    // At 80 degrees eight samples miss a share of the cobblestones far above 0.1%.
    let args = [&BASE[..], &["--yardstick", "--yardstick-cap", "8"]].concat();
    let md = run(&args, dir.path());
    assert!(md.contains("| 80° | not reached at N=8 |"), "{md}");
    let (_, rows) = parse_csv(&run(&[&args[..], &["--format", "csv"]].concat(), dir.path()));
    let keys: Vec<&str> = YARDSTICK_HEADER.split(',').collect();
    let row = &rows[1];
    let field = |k: &str| row[keys.iter().position(|&x| x == k).unwrap()].as_str();
    assert_eq!((field("angle"), field("cap"), field("pom_samples")), ("80", "8", ""));
    assert!(field("pom_share_over_1").parse::<f64>().unwrap() > 0.001, "the cap's row, failing");
    assert_eq!(field("pom_share_below"), "");
    let json = run(&[&args[..], &["--format", "json"]].concat(), dir.path());
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(value[1]["pom_samples"].is_null());
}

#[test]
fn bad_yardstick_flags_fail_clearly_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let h = ["compare", "--height", "builtin:pyramids:16x16", "--rays", "10", "-o", "t.csv"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> { [&h[..], extra].concat() };
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (with(&["--yardstick", "--yardstick-share", "1.5"]), vec!["--yardstick-share", "1.5"]),
        (with(&["--yardstick", "--yardstick-share", "-0.1"]), vec!["--yardstick-share"]),
        (with(&["--yardstick", "--yardstick-share", "NaN"]), vec!["--yardstick-share"]),
        (with(&["--yardstick", "--yardstick-cap", "7"]), vec!["--yardstick-cap", "7", "8", "1024"]),
        (with(&["--yardstick", "--yardstick-cap", "1025"]), vec!["--yardstick-cap", "1025"]),
        (with(&["--yardstick-cap", "64"]), vec!["--yardstick"]),
        (with(&["--yardstick-share", "0.01"]), vec!["--yardstick"]),
    ];
    for (args, needles) in &cases {
        support::refuses(args, dir.path(), needles);
    }
    let text = run(&["compare", "--help"], dir.path());
    for needle in ["--yardstick", "--yardstick-share", "--yardstick-cap", "not reached at N=1024", YARDSTICK_HEADER] {
        assert!(text.contains(needle), "compare --help lacks {needle}");
    }
}
