//! The accuracy of `bake height` (docs/ACCURACY.md, "Height from a normal map"): built-in
//! height maps baked to normals and integrated back, compared with the true heights.
//!
//! `cargo run --release -p pomkit-core --example height_accuracy [SIZE [MAPS [SCALE]]]` (default
//! 512, every map, 8) prints one Markdown table row per map, case and method: Pearson's r and
//! the RMS error, in units of the map's height range (heights in [0, 1]), after the unknown
//! constant is taken out. MAPS is a comma-separated list of built-in names and `square` (a
//! raised square, its sides from 0.3 to 0.7 of the tile rising over 1/128 of it). The normals
//! go through RGB8 (as a PNG holds them) at the slope scale SCALE.
//!
//! Cases:
//! - `wrap`: the tile baked by `bake normal` (central differences, `--edges wrap`), integrated
//!   with `--edges wrap`: the CLI round trip.
//! - `clamp`: a window of the tile that does not tile (columns and rows from 0.13 to 0.83 of
//!   the tile), baked and integrated with `--edges clamp`.
//! - `indep`: an independent pair: the map generated at 4 times the size, its normals baked
//!   there (central differences) and averaged over 4x4 blocks (renormalized), the true heights
//!   the 4x4 block means; the clamp window of that, integrated with `--edges clamp`.

use std::time::Instant;

use pomkit_core::bake::{NormalBakeOptions, bake_normals};
use pomkit_core::glam::Vec3;
use pomkit_core::integrate::{IntegrateMethod, IntegrateOptions, integrate_normals};
use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::{EdgeMode, HeightField};

/// The slope scale the normals are baked at (texel widths of the full height range), the third
/// argument, `bake normal`'s default 8 without one.
fn scale() -> f32 {
    std::env::args().nth(3).and_then(|v| v.parse().ok()).unwrap_or(8.0)
}

/// The normals through RGB8, as `bake normal` writes them to a PNG and `bake height` reads them.
fn q8(v: Vec<Vec3>) -> Vec<Vec3> {
    v.into_iter().map(|n| pomkit_core::bake::decode_rgb8(pomkit_core::bake::encode_rgb8(n))).collect()
}

fn main() {
    let size: u32 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(512);
    let patterns: Vec<Option<Pattern>> = match std::env::args().nth(2).filter(|s| !s.is_empty()) {
        Some(names) => names
            .split(',')
            .map(|n| if n == "square" { None } else { Some(n.parse().expect("a pattern name")) })
            .collect(),
        None => vec![
            Some(Pattern::Bricks),
            Some(Pattern::Cobblestones),
            Some(Pattern::Pyramids),
            Some(Pattern::Text),
            Some(Pattern::Waves),
            None,
        ],
    };
    println!("| map | case | method | r | RMS error | iterations | seconds |");
    println!("|---|---|---|---|---|---|---|");
    for pattern in patterns {
        for case in ["wrap", "clamp", "indep"] {
            let (truth, normals, w, h, edges) = pair(pattern, size, case);
            for method in [IntegrateMethod::Poisson, IntegrateMethod::Weighted] {
                let opts = IntegrateOptions { edges, method, ..Default::default() };
                let t0 = Instant::now();
                let out = integrate_normals(w, h, &normals, &opts, &|_| {}).expect("integrates");
                let secs = t0.elapsed().as_secs_f64();
                let got: Vec<f32> = out.heights().iter().map(|z| z / scale()).collect();
                let (r, rms) = pomkit_core::integrate::height_agreement(&got, &truth);
                println!(
                    "| {} | {case} | {} | {r:.4} | {rms:.4} | {} | {secs:.2} |",
                    pattern.map_or("square", Pattern::name),
                    method.name(),
                    out.iterations()
                );
            }
        }
    }
}

/// True heights (in [0, 1]) and normals of one case, with the size and edges.
fn make(pattern: Option<Pattern>, w: u32, h: u32) -> HeightField {
    match pattern {
        Some(p) => generate(p, w, h),
        // A raised square, its sides from 0.3 to 0.7 of the tile, rising over 1/128 of the tile.
        None => HeightField::from_height_fn(w, h, |x, y| {
            let f = |t: u32, n: u32| {
                let u = (t as f32 + 0.5) / n as f32;
                let d = (u - 0.3).min(0.7 - u);
                (d * 128.0 + 0.5).clamp(0.0, 1.0)
            };
            f(x, w).min(f(y, h))
        }),
    }
}

fn pair(pattern: Option<Pattern>, size: u32, case: &str) -> (Vec<f32>, Vec<Vec3>, u32, u32, EdgeMode) {
    let window = |n: u32| ((n as f32 * 0.13) as u32, (n as f32 * 0.83) as u32);
    match case {
        "wrap" => {
            let field = make(pattern, size, size);
            let normals = bake_normals(&field, &NormalBakeOptions { scale: scale(), ..Default::default() }).unwrap();
            (field.heights(), q8(normals), size, size, EdgeMode::Wrap)
        }
        "clamp" => {
            let full = make(pattern, size, size);
            let (a, b) = window(size);
            let crop = crop(&full, a, b);
            let opts = NormalBakeOptions { scale: scale(), edges: EdgeMode::Clamp, ..Default::default() };
            let normals = bake_normals(&crop, &opts).unwrap();
            (crop.heights(), q8(normals), b - a, b - a, EdgeMode::Clamp)
        }
        _ => {
            let k = 4u32;
            let fine = make(pattern, size * k, size * k);
            let (a, b) = window(size);
            let fine = crop(&fine, a * k, b * k);
            let opts = NormalBakeOptions { scale: scale() * k as f32, edges: EdgeMode::Clamp, ..Default::default() };
            let fine_normals = bake_normals(&fine, &opts).unwrap();
            let fine_heights = fine.heights();
            let (n, fw) = ((b - a) as usize, ((b - a) * k) as usize);
            let mut truth = vec![0.0f32; n * n];
            let mut normals = vec![Vec3::ZERO; n * n];
            for y in 0..n {
                for x in 0..n {
                    let (mut hs, mut ns) = (0.0, Vec3::ZERO);
                    for j in 0..k as usize {
                        for i in 0..k as usize {
                            let f = (y * k as usize + j) * fw + x * k as usize + i;
                            hs += fine_heights[f];
                            ns += fine_normals[f];
                        }
                    }
                    truth[y * n + x] = hs / (k * k) as f32;
                    normals[y * n + x] = ns.normalize();
                }
            }
            (truth, q8(normals), n as u32, n as u32, EdgeMode::Clamp)
        }
    }
}

/// The square window `[a, b)` of a field, in both directions.
fn crop(field: &HeightField, a: u32, b: u32) -> HeightField {
    let w = field.width();
    let h = field.heights();
    HeightField::from_height_fn(b - a, b - a, |x, y| h[((y + a) * w + x + a) as usize])
}
