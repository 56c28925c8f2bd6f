//! The entry points of the fuzz targets (docs/FUZZING.md), shared with the test that replays
//! the saved corpora (`tests/fuzz_corpus.rs`) so that the two cannot drift apart.
//!
//! Each entry feeds arbitrary bytes to one loader under a fixed input name and checks the bad
//! input contract: any error message must name the input. A panic (in the loader, or from that
//! check) is a failure; so is a hang or an allocation blow-up, which the fuzzer catches with
//! `-timeout` and `-rss_limit_mb`.
//!
//! Not a stable API: it exists for the fuzz crate and the tests.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::{Channel, HeightLoadOptions};

/// One fuzz target: its name (the file in `fuzz/fuzz_targets/` and the folder in
/// `fuzz/corpus/`), the name its input goes by in error messages, and its entry point.
pub struct Target {
    /// `fuzz/fuzz_targets/<name>.rs`, `fuzz/corpus/<name>/`, `fuzz/regressions/<name>/`.
    pub name: &'static str,
    /// What every error message must contain.
    pub input: &'static str,
    /// Feeds the bytes to the loader; panics on a contract violation.
    pub run: fn(&[u8]) -> Outcome,
}

/// What an entry made of its input.
#[derive(Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The input loaded.
    Loaded,
    /// The input was refused with this message (which names the input).
    Refused(String),
    /// The input was not passed to the loader (see the entry's documentation); the fuzz
    /// targets keep such inputs out of the corpus.
    Skipped,
}

/// Every target, in the order of docs/FUZZING.md.
pub const TARGETS: &[Target] = &[
    Target { name: "height_image", input: HEIGHT_INPUT, run: height_image },
    Target { name: "normal_map", input: NORMAL_INPUT, run: normal_map },
    Target { name: "scene", input: SCENE_INPUT, run: scene },
    Target { name: "obj", input: OBJ_INPUT, run: obj },
    Target { name: "gltf", input: GLTF_INPUT, run: gltf },
    Target { name: "rays", input: RAYS_INPUT, run: rays },
    Target { name: "batch_config", input: CONFIG_INPUT, run: batch_config },
];

const HEIGHT_INPUT: &str = "fuzz-height-input";
const NORMAL_INPUT: &str = "fuzz-normal-input";
const SCENE_INPUT: &str = "fuzz-scene.toml";
const OBJ_INPUT: &str = "fuzz-mesh.obj";
const GLTF_INPUT: &str = "fuzz-mesh.gltf";
const RAYS_INPUT: &str = "fuzz-rays.csv";
const CONFIG_INPUT: &str = "fuzz-rules.toml";

/// The outcome of a load; panics when an error's message does not name `input`.
fn check<T, E: std::fmt::Display>(result: Result<T, E>, input: &str) -> Outcome {
    match result {
        Ok(_) => Outcome::Loaded,
        Err(e) => {
            let message = e.to_string();
            assert!(message.contains(input), "the error does not name the input {input:?}: {message}");
            Outcome::Refused(message)
        }
    }
}

/// Height image loader: the first byte picks the options (bits 0-2 the channel, modulo 5;
/// bit 3 depth map; bit 4 normalize), the rest is the image file.
pub fn height_image(data: &[u8]) -> Outcome {
    let Some((&head, bytes)) = data.split_first() else { return Outcome::Skipped };
    let opts = HeightLoadOptions {
        channel: Channel::ALL[usize::from(head & 7) % Channel::ALL.len()],
        depth_map: head & 8 != 0,
        normalize: head & 16 != 0,
    };
    check(crate::decode_height_field(bytes, Path::new(HEIGHT_INPUT), &opts), HEIGHT_INPUT)
}

/// Normal map loader: bit 0 of the first byte is `y_down`, the rest is the image file.
pub fn normal_map(data: &[u8]) -> Outcome {
    let Some((&head, bytes)) = data.split_first() else { return Outcome::Skipped };
    check(crate::scene::decode_normal_map(bytes, Path::new(NORMAL_INPUT), head & 1 != 0), NORMAL_INPUT)
}

/// Scene parser: the bytes are the scene text (skipped unless UTF-8, as `load_scene` refuses
/// other bytes before parsing). Relative file names resolve in a folder holding one valid
/// 4x4 height map, `h.png`, so that most references fail fast.
///
/// Scenes that ask for costly work within the documented limits are skipped: a built-in map
/// of more than 512x512 texels, or a count (segments, samples...) above 256. Their cost is
/// bounded by the limits themselves, not by the parser (docs/FUZZING.md).
pub fn scene(data: &[u8]) -> Outcome {
    let Ok(text) = std::str::from_utf8(data) else { return Outcome::Skipped };
    if costly(text) {
        return Outcome::Skipped;
    }
    check(crate::scene::parse_scene_named(text, Path::new(SCENE_INPUT), scene_base()), SCENE_INPUT)
}

/// OBJ loader.
pub fn obj(data: &[u8]) -> Outcome {
    check(crate::mesh::decode_mesh(data, Path::new(OBJ_INPUT)), OBJ_INPUT)
}

/// glTF loader (`.gltf` JSON or the `.glb` container: the parser tells them apart by their
/// first bytes). External buffers resolve in the same folder as the scene target's files.
pub fn gltf(data: &[u8]) -> Outcome {
    let path = scene_base().join(GLTF_INPUT);
    check(crate::mesh::decode_mesh(data, &path), GLTF_INPUT)
}

/// Rays CSV reader: the first byte sets the reader's buffer size (1 to 256 bytes, so that lines
/// straddle buffer refills), the rest is the file. Every ray read must be finite, and the whole
/// text must read the same through [`crate::rays::parse_rays`] (one buffer).
pub fn rays(data: &[u8]) -> Outcome {
    let Some((&head, bytes)) = data.split_first() else { return Outcome::Skipped };
    let reader = std::io::BufReader::with_capacity(usize::from(head) + 1, bytes);
    let streamed: Result<Vec<_>, _> =
        crate::rays::RayReader::new(reader, RAYS_INPUT).and_then(|r| r.collect::<Result<Vec<_>, _>>());
    if let Ok(rays) = &streamed {
        for ray in rays {
            assert!(ray.uv.is_finite() && ray.dir.is_finite(), "a ray read is not finite: {ray:?}");
        }
    }
    if let Ok(text) = std::str::from_utf8(bytes) {
        let whole = crate::rays::parse_rays(text, RAYS_INPUT);
        let same = match (&streamed, &whole) {
            (Ok(a), Ok(b)) => a == b,
            (Err(a), Err(b)) => a.to_string() == b.to_string(),
            _ => false,
        };
        assert!(same, "streamed and whole reads differ: {streamed:?} vs {whole:?}");
    }
    check(streamed, RAYS_INPUT)
}

/// The folder scene and glTF inputs resolve relative names in: a temporary folder, made once
/// per process, holding a 4x4 grey PNG `h.png`.
fn scene_base() -> &'static Path {
    static BASE: OnceLock<PathBuf> = OnceLock::new();
    BASE.get_or_init(|| {
        let dir = tempfile::Builder::new().prefix("pomkit-fuzz-").tempdir().expect("a temporary folder");
        let img = image::GrayImage::from_fn(4, 4, |x, y| image::Luma([(x * 60 + y * 5) as u8]));
        img.save(dir.path().join("h.png")).expect("a 4x4 PNG in the temporary folder");
        dir.keep()
    })
}

/// Whether a scene asks for a built-in map over 512x512 texels or has an integer above 256
/// that the documented limits still allow (see [`scene`]).
fn costly(text: &str) -> bool {
    fn walk(v: &toml::Value) -> bool {
        match v {
            toml::Value::Integer(n) => (257..=i64::from(pomkit_core::mesh::MAX_SEGMENTS)).contains(n),
            toml::Value::String(s) => s.contains("builtin:") && builtin_area(s) > 512 * 512,
            toml::Value::Array(a) => a.iter().any(walk),
            toml::Value::Table(t) => t.values().any(walk),
            _ => false,
        }
    }
    toml::from_str::<toml::Table>(text).is_ok_and(|t| t.values().any(walk))
}

/// Texels of the `WxH` at the end of a `builtin:` reference (0 without one or when invalid).
fn builtin_area(s: &str) -> u64 {
    let Some((_, size)) = s.rsplit_once(':') else { return 0 };
    let Some((w, h)) = size.split_once(['x', 'X']) else { return 0 };
    match (w.trim().parse::<u64>(), h.trim().parse::<u64>()) {
        (Ok(w), Ok(h))
            if w <= u64::from(crate::scene::MAX_BUILTIN_SIZE) && h <= u64::from(crate::scene::MAX_BUILTIN_SIZE) =>
        {
            w * h
        }
        _ => 0,
    }
}

/// The rules file of a batch bake (`bake --config`): the bytes are its text (skipped unless
/// UTF-8, as `load_config` refuses other bytes before parsing).
pub fn batch_config(data: &[u8]) -> Outcome {
    let Ok(text) = std::str::from_utf8(data) else { return Outcome::Skipped };
    check(crate::batch_config::parse_config(text, Path::new(CONFIG_INPUT)), CONFIG_INPUT)
}
