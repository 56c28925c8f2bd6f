//! The scene loader against the parameter table (`pomkit_core::params`): the `[[material]]`
//! table accepts exactly the table's keys and the file keys, every key set to a value other
//! than its default reaches the material, the defaults are the table's, and values outside a
//! number's range are refused naming the key. docs/SCENES.md holds the table as generated, and its
//! complete example scene writes every parameter at the table's default. A parameter added to the table but not to the
//! loader (or the other way round) fails here.

use std::collections::BTreeSet;
use std::path::Path;

use pomkit_core::params::{self, Kind, Value};
use pomkit_io::scene::parse_scene;
use pomkit_io::{Channel, PixelLayout, Pixels, write_image};

/// A scene with one material holding a height image file and a normal-map file, plus `extra`.
fn scene(extra: &str) -> String {
    format!(
        "[camera]\neye = [0.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n\n[[material]]\nname = \"m\"\n\
         height = \"h.png\"\nnormal = \"n.png\"\n{extra}\n\n[[object]]\nmesh = \"plane\"\nmaterial = \"m\"\n"
    )
}

fn assets(dir: &Path) {
    write_image(&dir.join("h.png"), 2, 2, PixelLayout::Gray8, Pixels::U8(&[255, 0, 0, 255])).unwrap();
    write_image(&dir.join("n.png"), 1, 1, PixelLayout::Rgb8, Pixels::U8(&[128, 128, 255])).unwrap();
}

/// A valid value of `p` other than its default.
fn other_value(p: &params::Param) -> Value {
    match (p.kind, p.default) {
        (Kind::Float { slider: (lo, hi), .. }, Value::Float(d)) => {
            let v = lo + 0.37 * (hi - lo);
            Value::Float(if (v - d).abs() < 1e-3 { lo + 0.61 * (hi - lo) } else { v })
        }
        (Kind::Int { slider: (_, hi), .. }, Value::Int(d)) => Value::Int(if d < hi { d + 1 } else { d - 1 }),
        (Kind::Bool, Value::Bool(b)) => Value::Bool(!b),
        (Kind::Choice(names), Value::Name(d)) => Value::Name(names.iter().copied().find(|n| *n != d).unwrap()),
        (Kind::Color, _) => Value::Color([0.5, 0.25, 0.125]),
        (k, d) => panic!("{}: default {d:?} does not fit {k:?}", p.key),
    }
}

fn same(a: Value, b: Value) -> bool {
    match (a, b) {
        (Value::Float(x), Value::Float(y)) => (x - y).abs() <= 1e-6 * y.abs().max(1.0),
        (Value::Color(x), Value::Color(y)) => x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-6),
        _ => a == b,
    }
}

#[test]
fn the_loader_accepts_exactly_the_tables_keys() {
    let dir = tempfile::tempdir().unwrap();
    assets(dir.path());
    let err = parse_scene(&scene("no_such_key = 1"), dir.path()).unwrap_err().to_string();
    let (_, expected) = err.split_once("expected one of").unwrap_or_else(|| panic!("no key list in: {err}"));
    let listed: BTreeSet<&str> = expected.split('`').skip(1).step_by(2).collect();
    let table: BTreeSet<&str> = params::all().map(|p| p.key).chain(params::FILE_KEYS).collect();
    assert_eq!(listed, table, "the loader's [[material]] keys differ from the parameter table's");
}

#[test]
fn every_key_reaches_the_material() {
    let dir = tempfile::tempdir().unwrap();
    assets(dir.path());
    let defaults = parse_scene(&scene(""), dir.path()).unwrap();
    for p in params::all() {
        if !p.reads_input() {
            let got = params::value_of(&defaults.materials[0], p.key).unwrap();
            assert!(same(got, p.default), "{}: left out, the loader gives {got:?}, the table {:?}", p.key, p.default);
        }
        let v = other_value(p);
        let loaded = parse_scene(&scene(&format!("{} = {}", p.key, v.toml())), dir.path())
            .unwrap_or_else(|e| panic!("{} = {}: {e}", p.key, v.toml()));
        if p.reads_input() {
            continue; // applied to the image as it is read; tested with the images themselves
        }
        let got = params::value_of(&loaded.materials[0], p.key).unwrap();
        assert!(same(got, v), "{} = {}: the material has {got:?}", p.key, v.toml());
    }
}

#[test]
fn numbers_outside_the_tables_range_are_refused_by_key() {
    let dir = tempfile::tempdir().unwrap();
    assets(dir.path());
    for p in params::all() {
        let Kind::Float { min, min_exclusive, max, .. } = p.kind else { continue };
        let below = if min_exclusive { min } else { min - 1.0 };
        let mut bad = vec![below, f64::NAN];
        if max.is_finite() {
            bad.push(max + 1.0);
        }
        for v in bad {
            let text = if v.is_nan() { "nan".to_owned() } else { Value::Float(v).toml() };
            let err = parse_scene(&scene(&format!("{} = {text}", p.key)), dir.path())
                .err()
                .unwrap_or_else(|| panic!("{} = {text} was accepted", p.key));
            assert!(err.to_string().contains(p.key), "{} = {text}: the error does not name the key: {err}", p.key);
        }
    }
}

#[test]
fn the_channel_choices_are_the_loaders() {
    let Kind::Choice(names) = params::CHANNEL.kind else { panic!("channel is a choice") };
    let table: BTreeSet<&str> = names.iter().copied().collect();
    let loader: BTreeSet<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
    assert_eq!(table, loader);
}

fn scenes_md() -> (std::path::PathBuf, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/SCENES.md");
    let text = std::fs::read_to_string(&path).expect("docs/SCENES.md");
    (path, text)
}

#[test]
fn scenes_md_holds_the_generated_table() {
    let (path, text) = scenes_md();
    let begin = text.find("<!-- params:begin").expect("SCENES.md has the params:begin marker");
    let body = begin + text[begin..].find("-->").expect("the marker closes") + 3;
    let end = text.find("<!-- params:end -->").expect("SCENES.md has the params:end marker");
    let want = format!("\n{}", params::markdown_table());
    if std::env::var_os("UPDATE_DOCS").is_some() {
        let updated = format!("{}{want}{}", &text[..body], &text[end..]);
        std::fs::write(&path, updated).expect("write docs/SCENES.md");
        return;
    }
    assert!(
        text[body..end] == want,
        "docs/SCENES.md's parameter table is not the table's: run `UPDATE_DOCS=1 cargo test -p pomkit-io --test \
         params_table`"
    );
}

/// The complete scene of SCENES.md writes every parameter, at the table's default.
#[test]
fn the_complete_example_writes_every_default() {
    let (_, text) = scenes_md();
    let start = text.find("## A complete scene").expect("the complete scene section");
    let block = &text[start..];
    let block = &block[block.find("```toml\n").unwrap() + 8..];
    let block = &block[..block.find("```").unwrap()];
    let doc: toml::Table = block.parse().expect("the complete scene is TOML");
    let material = doc["material"].as_array().unwrap()[0].as_table().unwrap();
    for p in params::all() {
        let v = material.get(p.key).unwrap_or_else(|| panic!("the complete scene leaves {} out", p.key));
        let want: toml::Value = format!("v = {}", p.default.toml()).parse::<toml::Table>().unwrap()["v"].clone();
        assert_eq!(v, &want, "the complete scene's {} is not the table's default", p.key);
    }
}
