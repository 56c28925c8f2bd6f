//! Writes the seed corpora of the fuzz targets: small valid files of every format each loader
//! reads (docs/FUZZING.md). Run with a stable toolchain from `fuzz/`:
//! `cargo run --example make_seeds -- <out-dir>`; it writes `<out-dir>/<target>/<file>`.

use std::path::Path;

use image::{DynamicImage, ImageFormat};

fn save(dir: &Path, target: &str, name: &str, bytes: &[u8]) {
    let d = dir.join(target);
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(d.join(name), bytes).unwrap();
}

/// The image encoded as `format`, behind an options byte (height and normal targets).
fn encode(img: &DynamicImage, format: ImageFormat, head: u8) -> Option<Vec<u8>> {
    let mut out = std::io::Cursor::new(vec![head]);
    out.set_position(1);
    img.write_to(&mut out, format).ok()?;
    Some(out.into_inner())
}

fn images() -> Vec<(&'static str, DynamicImage)> {
    let (w, h) = (8, 6);
    let g8 = image::GrayImage::from_fn(w, h, |x, y| image::Luma([(x * 30 + y * 7) as u8]));
    let g16 =
        image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, y| image::Luma([(x * 8000 + y * 900) as u16]));
    let ga8 = image::GrayAlphaImage::from_fn(w, h, |x, y| image::LumaA([(x * 30) as u8, (y * 40) as u8]));
    let rgb8 = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 30) as u8, (y * 40) as u8, 200]));
    let rgba8 = image::RgbaImage::from_fn(w, h, |x, y| image::Rgba([128, 128, 255, (x * 30 + y) as u8]));
    let rgb16 = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(w, h, |x, y| {
        image::Rgb([(x * 8000) as u16, (y * 9000) as u16, 65535])
    });
    let rgba16 = image::ImageBuffer::<image::Rgba<u16>, _>::from_fn(w, h, |x, y| {
        image::Rgba([32768, 32768, 65535, (x * 8000 + y * 100) as u16])
    });
    let rgbf = image::Rgb32FImage::from_fn(w, h, |x, y| image::Rgb([x as f32 / 8.0, y as f32 / 6.0, 0.5]));
    let rgbf_wide = image::Rgb32FImage::from_fn(w, h, |x, y| image::Rgb([x as f32 * 3.0 - 5.0, y as f32, 1.0]));
    let rgbaf = image::Rgba32FImage::from_fn(w, h, |x, y| image::Rgba([0.1, x as f32 / 8.0, 0.9, y as f32 / 6.0]));
    vec![
        ("g8", g8.into()),
        ("g16", DynamicImage::ImageLuma16(g16)),
        ("ga8", ga8.into()),
        ("rgb8", rgb8.into()),
        ("rgba8", rgba8.into()),
        ("rgb16", DynamicImage::ImageRgb16(rgb16)),
        ("rgba16", DynamicImage::ImageRgba16(rgba16)),
        ("rgbf", rgbf.into()),
        ("rgbf_wide", rgbf_wide.into()),
        ("rgbaf", rgbaf.into()),
    ]
}

fn main() {
    let out = std::env::args().nth(1).expect("usage: make_seeds <out-dir>");
    let out = Path::new(&out);
    let formats = [
        (ImageFormat::Png, "png"),
        (ImageFormat::OpenExr, "exr"),
        (ImageFormat::Tiff, "tiff"),
        (ImageFormat::Jpeg, "jpg"),
    ];
    for (name, img) in images() {
        for (format, ext) in formats {
            // Height: luma / channel a with normalize / depth map; normal: y up and y down.
            for head in [0u8, 3 | 16, 8] {
                if let Some(b) = encode(&img, format, head) {
                    save(out, "height_image", &format!("{name}_{head}.{ext}"), &b);
                }
            }
            for head in [0u8, 1] {
                if let Some(b) = encode(&img, format, head) {
                    save(out, "normal_map", &format!("{name}_{head}.{ext}"), &b);
                }
            }
        }
    }
    // What the image crate does not read but the height loader does: a single-channel EXR and
    // a float TIFF.
    let heights: Vec<f32> = (0..48).map(|i| (i % 8) as f32 / 8.0 + (i / 8) as f32 * 0.01).collect();
    let single = {
        use exr::prelude::*;
        let channel = AnyChannel::new("Y", FlatSamples::F32(heights.clone()));
        let layer = Layer::new(
            (8, 6),
            LayerAttributes::named("height"),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(vec![channel])),
        );
        let mut out = std::io::Cursor::new(Vec::new());
        Image::from_layer(layer).write().to_buffered(&mut out).unwrap();
        out.into_inner()
    };
    let mut tiff_f32 = std::io::Cursor::new(Vec::new());
    let mut enc = tiff::encoder::TiffEncoder::new(&mut tiff_f32).unwrap();
    enc.write_image::<tiff::encoder::colortype::Gray32Float>(8, 6, &heights).unwrap();
    for head in [0u8, 16, 8] {
        save(out, "height_image", &format!("y_{head}.exr"), &[&[head][..], &single].concat());
        save(out, "height_image", &format!("gray32f_{head}.tiff"), &[&[head][..], tiff_f32.get_ref()].concat());
    }
    // A two-channel normal map (blue zero everywhere).
    let rg = image::RgbImage::from_fn(4, 4, |x, y| image::Rgb([(x * 60) as u8, (y * 60) as u8, 0]));
    save(out, "normal_map", "rg8_0.png", &encode(&rg.into(), ImageFormat::Png, 0).unwrap());

    for f in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/scenes")).unwrap() {
        let f = f.unwrap().path();
        save(out, "scene", &f.file_name().unwrap().to_string_lossy(), &std::fs::read(&f).unwrap());
    }
    for (name, text) in SCENES {
        save(out, "scene", name, text.as_bytes());
    }
    for (name, text) in OBJS {
        save(out, "obj", name, text.as_bytes());
    }
    let tri = gltf_triangle(false);
    save(out, "gltf", "tri.gltf", embedded(&tri).as_bytes());
    save(out, "gltf", "tri.glb", &glb(&tri));
    let indexed = gltf_triangle(true);
    save(out, "gltf", "indexed.gltf", embedded(&indexed).as_bytes());
    save(out, "gltf", "indexed.glb", &glb(&indexed));
    // Rays: an options byte (the reader's buffer size - 1), then the CSV.
    for (name, head, text) in RAYS {
        save(out, "rays", name, &[&[*head][..], text.as_bytes()].concat());
    }
}

const RAYS: &[(&str, u8, &str)] = &[
    ("plain.csv", 255, "u,v,dx,dy,dz\n0.5,0.5,0.3,0.1,-0.9\n0.1,0.9,-0.5,0.2,-0.6\n"),
    ("crlf_bom.csv", 7, "\u{feff}u, v, dx, dy, dz\r\n0.25,0.75,0,0,-1\r\n\r\n1e-3,2.5e1,-0.5,0.5,-0.01\r\n"),
    ("no_final_newline.csv", 0, "u,v,dx,dy,dz\n-3.5,1e15,1,1,-1"),
    ("bad_field.csv", 16, "u,v,dx,dy,dz\n0,0,0,0,-1\n0,0,x,0,-1\n"),
];

const SCENES: &[(&str, &str)] = &[
    (
        "smallest.toml",
        r#"[camera]
eye = [0.0, 2.0, 4.0]
target = [0.0, 0.0, 0.0]

[[material]]
name = "bricks"
albedo = "builtin:bricks:32x32"
height = "builtin:bricks:32x32"

[[object]]
mesh = "plane"
material = "bricks"
"#,
    ),
    (
        "every_field.toml",
        r#"background = [0.02, 0.02, 0.03]
ambient = [0.05, 0.05, 0.06]

[camera]
eye = [0.0, 2.0, 4.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 45.0
near = 0.05
far = 100.0

[[light]]
type = "directional"
direction = [0.0, 1.0, 0.0]
color = [1.0, 1.0, 1.0]
intensity = 1.0

[[light]]
type = "point"
position = [0.0, 4.0, 0.0]
color = [1.0, 1.0, 1.0]
intensity = 1.0

[[material]]
name = "file"
albedo = "h.png"
height = "h.png"
depth_map = true
channel = "r"
normalize = true
base_color = [0.8, 0.8, 0.8]
technique = "pom"
depth_scale = 0.1
min_samples = 8
max_samples = 32
refine = 2
edges = "clamp"
shadow = "soft"
softness = 0.1
lod_threshold = 4.0
specular = 0.25
shininess = 32.0
pixel_depth_offset = true

[[material]]
name = "relief"
height = "builtin:waves:16x16"
normal = "missing_normal.png"
normal_y_down = true
technique = "relief"
samples = 16
binary_steps = 4

[[material]]
name = "classic"
height = "builtin:pyramids:8x8"
technique = "pom-classic"
perspective_bias = 0.5
shadow = "exact"

[[object]]
name = "floor"
mesh = "plane"
material = "file"
size = [4.0, 4.0]
segments = 2
uv_repeat = [2.0, 2.0]
position = [0.0, 0.0, 0.0]
rotation = [0.0, 45.0, 0.0]
scale = [1.0, 1.0, 1.0]

[[object]]
mesh = "sphere"
radius = 0.5
rings = 4
segments = 6
material = "classic"

[[object]]
mesh = "torus"
tube_radius = 0.2
segments = 6
tube_segments = 4
material = "classic"

[[object]]
mesh = "cube"
material = "classic"

[[object]]
mesh = "cylinder"
height = 1.0
segments = 5
material = "classic"

[[object]]
mesh = "disc"
segments = 5
material = "classic"

[[object]]
mesh = "quad"
material = "classic"

[[object]]
mesh = "model.obj"
material = "classic"
"#,
    ),
];

const OBJS: &[(&str, &str)] = &[
    (
        "cube.obj",
        "# a unit cube\nv -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 -1\nvn 0 0 1\nvn -1 0 0\nvn 1 0 0\nvn 0 -1 0\nvn 0 1 0\n\
o cube\ng sides\nf 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/2 6/2/2 7/3/2 8/4/2\nf 1/1/3 5/2/3 8/3/3 4/4/3\n\
g rest\nf 2/1/4 3/2/4 7/3/4 6/4/4\nf 1/1/5 2/2/5 6/3/5 5/4/5\nf 4/1/6 8/2/6 7/3/6 3/4/6\n",
    ),
    (
        "quad.obj",
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n",
    ),
    (
        "no_normals.obj",
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\ns 1\nf -3/-3 -2/-2 -1/-1\nl 1 2\np 3\n",
    ),
];

/// One triangle (optionally indexed, with tangents): the JSON with a `{URI}` placeholder in
/// its buffer, and the buffer.
fn gltf_triangle(indexed: bool) -> (String, Vec<u8>) {
    let floats: Vec<f32> = [
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0][..],
        &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        &[0.0, 1.0, 1.0, 1.0, 0.0, 0.0],
        &[1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0],
    ]
    .concat();
    let mut bin: Vec<u8> = floats.iter().flat_map(|v| v.to_le_bytes()).collect();
    if indexed {
        bin.extend([0u16, 1, 2, 0].iter().flat_map(|v| v.to_le_bytes()));
    }
    let (indices_view, indices_acc, indices_attr) = if indexed {
        (
            r#", {"buffer": 0, "byteOffset": 132, "byteLength": 6}"#,
            r#", {"bufferView": 4, "componentType": 5123, "count": 3, "type": "SCALAR"}"#,
            r#", "indices": 4, "mode": 4"#,
        )
    } else {
        ("", "", "")
    };
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
"nodes": [{{"children": [1], "translation": [1, 2, 3]}}, {{"mesh": 0, "scale": [1, -1, 1]}}],
"meshes": [{{"name": "tri", "primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TANGENT": 3}}{indices_attr}}}]}}],
"buffers": [{{"byteLength": {len}{{URI}}}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 36}},
  {{"buffer": 0, "byteOffset": 72, "byteLength": 24}}, {{"buffer": 0, "byteOffset": 96, "byteLength": 36}}{indices_view}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
  {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}},
  {{"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"}},
  {{"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC4"}}{indices_acc}]}}"#,
        len = bin.len()
    );
    (json, bin)
}

fn embedded((json, bin): &(String, Vec<u8>)) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut b64 = String::new();
    for chunk in bin.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            b64.push(if k <= chunk.len() { ABC[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    json.replace("{URI}", &format!(r#", "uri": "data:application/octet-stream;base64,{b64}""#))
}

fn glb((json, bin): &(String, Vec<u8>)) -> Vec<u8> {
    let mut json = json.replace("{URI}", "").into_bytes();
    let mut bin = bin.clone();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}
