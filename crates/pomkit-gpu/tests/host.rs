//! `HeightResource` (pomkit_gpu::host): pomkit's maps from a host program's own texture equal
//! the maps from the same `HeightField`, texel by texel; a texture changed at run time is
//! re-imported; bad textures give the right `HostError`, never a wgpu validation error.
//!
//! Truth: the host texture holds a pomkit_core procedural map quantized to its format (8-bit
//! unorm, f16 or f32), and the field given to `from_field` is that same quantized map, so both
//! paths describe one surface. The import's mip 0 depth is also checked against the CPU's
//! `f16(1 - value)` directly, and the runtime change against pomkit_core's `MaxHeightPyramid`.
//! Both paths round the depth to f16 once (the CPU upload rounds to nearest; the GPU storage
//! write converts), so mip 0 may differ by one f16 step at a texel; everything derived from it
//! may then differ by what one such step changes (see `Tolerance`).
//!
//! Without a GPU adapter the tests print "skipping: ..." and pass, unless POMKIT_REQUIRE_GPU=1.

use pomkit_core::procedural::{Pattern, generate};
use pomkit_core::{EdgeMode, HeightField, MaxHeightPyramid};
use pomkit_gpu::GpuContext;
use pomkit_gpu::height::HeightPasses;
use pomkit_gpu::host::{HeightBindings, HeightEncoding, HeightResource, HeightResourceOptions, HostError};

/// The device, or `None` (after printing why) when there is none and none is required.
fn gpu() -> Option<GpuContext> {
    GpuContext::new().map_err(|e| pomkit_gpu::context::skip_without_gpu(&e)).ok()
}

/// `x` rounded to f16 and back.
fn f16r(x: f32) -> f32 {
    half::f16::from_f32(x).to_f32()
}

/// One f16 step (unit in the last place) at `v`.
fn f16_ulp(v: f32) -> f32 {
    let v = v.abs().max(1.0 / 16384.0);
    2f32.powi(v.log2().floor() as i32 - 10)
}

/// How a host texture stores a value, and how large its texels are.
#[derive(Clone, Copy, Debug)]
enum HostFormat {
    /// `R8Unorm`, the value in R.
    R8,
    /// `Rgba16Float`, the value in G (channel 1); R = 1 - value, B = 0.5, A = NaN, so a wrong
    /// channel shows.
    Rgba16G,
    /// `R32Float`, the value in R.
    R32,
}

impl HostFormat {
    fn format(self) -> wgpu::TextureFormat {
        match self {
            HostFormat::R8 => wgpu::TextureFormat::R8Unorm,
            HostFormat::Rgba16G => wgpu::TextureFormat::Rgba16Float,
            HostFormat::R32 => wgpu::TextureFormat::R32Float,
        }
    }

    fn channel(self) -> u32 {
        match self {
            HostFormat::Rgba16G => 1,
            _ => 0,
        }
    }

    fn bytes_per_texel(self) -> u32 {
        match self {
            HostFormat::R8 => 1,
            HostFormat::Rgba16G => 8,
            HostFormat::R32 => 4,
        }
    }

    /// `v` as the format stores it (what the shader reads back).
    fn quantize(self, v: f32) -> f32 {
        match self {
            HostFormat::R8 => (v * 255.0).round() / 255.0,
            HostFormat::Rgba16G => f16r(v),
            HostFormat::R32 => v,
        }
    }

    /// The texel bytes of `values` (already quantized).
    fn bytes(self, values: &[f32]) -> Vec<u8> {
        match self {
            HostFormat::R8 => values.iter().map(|&v| (v * 255.0).round() as u8).collect(),
            HostFormat::Rgba16G => values
                .iter()
                .flat_map(|&v| [1.0 - v, v, 0.5, f32::NAN])
                .flat_map(|c| half::f16::from_f32(c).to_bits().to_le_bytes())
                .collect(),
            HostFormat::R32 => values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }
}

/// A host texture (`TEXTURE_BINDING | COPY_DST`) holding `values` in `format`.
fn host_texture(ctx: &GpuContext, label: &str, format: HostFormat, w: u32, h: u32, values: &[f32]) -> wgpu::Texture {
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: format.format(),
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    write_host(ctx, &texture, format, values);
    texture
}

/// Writes `values` into all of `texture` with `queue.write_texture`.
fn write_host(ctx: &GpuContext, texture: &wgpu::Texture, format: HostFormat, values: &[f32]) {
    let (w, h) = (texture.width(), texture.height());
    ctx.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        &format.bytes(values),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(w * format.bytes_per_texel()),
            rows_per_image: None,
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
}

/// Everything a resource holds, read back: heights mips (RGBA), normals (RGBA), pyramid
/// levels (only their valid cells).
struct Readback {
    heights: Vec<Vec<f32>>,
    normals: Vec<f32>,
    pyramid: Vec<Vec<f32>>,
}

fn read_back(ctx: &GpuContext, r: &HeightResource) -> Readback {
    ctx.wait().expect("device lost");
    let maps = r.maps();
    let heights = (0..maps.height_levels()).map(|k| ctx.read_texture(&maps.heights, k).unwrap()).collect();
    let normals = ctx.read_texture(&maps.normals, 0).unwrap();
    let pyramid = (0..maps.pyramid_levels)
        .map(|l| {
            let texels = ctx.read_texture(&maps.pyramid, l).unwrap();
            let stride = (maps.pyramid.width() >> l).max(1) as usize;
            let (cw, ch) = maps.pyramid_level_size(l);
            // Red holds the bound, green the cones (none here).
            (0..ch as usize)
                .flat_map(|y| (0..cw as usize).map(move |x| (y, x)))
                .map(|(y, x)| texels[2 * (y * stride + x)])
                .collect()
        })
        .collect();
    Readback { heights, normals, pyramid }
}

/// What one f16 step of difference in a mip-0 depth may change downstream.
struct Tolerance {
    /// Normals (and, through `n_z`, parallax values): one step of depth at Lengyel's scale
    /// `depth_scale * width` moves a central-difference slope by `scale * step / 2`; the
    /// normal moves by at most that much.
    normal: f32,
}

/// Largest differences found, and how many texels differed at all.
#[derive(Debug, Default)]
struct Diff {
    depth: f32,
    parallax: f32,
    normal: f32,
    pyramid: f32,
    differing_texels: usize,
}

/// Asserts `|a - b| <= tol(b)` element by element; returns the largest difference and how many
/// elements differ.
fn compare(what: &str, a: &[f32], b: &[f32], tol: impl Fn(f32) -> f32) -> (f32, usize) {
    assert_eq!(a.len(), b.len(), "{what}: sizes");
    assert!(!a.is_empty(), "{what}: nothing compared");
    let mut worst = 0.0f32;
    let mut differing = 0;
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        let err = (x - y).abs();
        assert!(err <= tol(y), "{what}: element {i}: {x} vs {y} (difference {err}, tolerance {})", tol(y));
        worst = worst.max(err);
        differing += usize::from(err > 0.0);
    }
    (worst, differing)
}

/// Channel `c` of 4-channel texels.
fn channel_of(texels: &[f32], c: usize) -> Vec<f32> {
    texels.chunks_exact(4).map(|t| t[c]).collect()
}

/// Asserts that two resources' maps agree within `tol`.
fn compare_maps(case: &str, a: &Readback, b: &Readback, tol: &Tolerance) -> Diff {
    let mut d = Diff::default();
    assert_eq!(a.heights.len(), b.heights.len(), "{case}: mip count");
    for (k, (x, y)) in a.heights.iter().zip(&b.heights).enumerate() {
        // Mip 0 by one step at most; coarser mips average steps of up to 2^-11 (depths < 1),
        // then round once more.
        let (e, n) = compare(&format!("{case}: heights mip {k} R"), &channel_of(x, 0), &channel_of(y, 0), |v| {
            if k == 0 { f16_ulp(v) } else { 1.0 / 2048.0 + f16_ulp(v) }
        });
        d.depth = d.depth.max(e);
        d.differing_texels += n;
        let (e, n) = compare(&format!("{case}: heights mip {k} G"), &channel_of(x, 1), &channel_of(y, 1), |v| {
            tol.normal + f16_ulp(v)
        });
        d.parallax = d.parallax.max(e);
        d.differing_texels += n;
        for c in [2, 3] {
            compare(&format!("{case}: heights mip {k} channel {c}"), &channel_of(x, c), &channel_of(y, c), |_| 0.0);
        }
    }
    let (e, n) = compare(&format!("{case}: normals"), &a.normals, &b.normals, |v| tol.normal + f16_ulp(v));
    d.normal = e;
    d.differing_texels += n;
    assert_eq!(a.pyramid.len(), b.pyramid.len(), "{case}: pyramid levels");
    for (l, (x, y)) in a.pyramid.iter().zip(&b.pyramid).enumerate() {
        // Interpolated between texels whose depths may each be one step (up to 2^-11) off.
        let (e, n) = compare(&format!("{case}: pyramid level {l}"), x, y, |_| 1.0 / 2048.0);
        d.pyramid = d.pyramid.max(e);
        d.differing_texels += n;
    }
    d
}

/// Encodes `r`'s rebuild, submits and waits.
fn rebuild(ctx: &GpuContext, passes: &HeightPasses, r: &HeightResource) {
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    r.encode_rebuild(&ctx.device, passes, &mut encoder);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait().expect("device lost");
}

/// Runs `f` inside a validation error scope and asserts wgpu reported nothing.
fn no_validation_error<T>(ctx: &GpuContext, what: &str, f: impl FnOnce() -> T) -> T {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let error = pollster::block_on(scope.pop());
    assert!(error.is_none(), "{what}: wgpu validation error: {}", error.map(|e| e.to_string()).unwrap_or_default());
    out
}

#[test]
fn texture_import_equals_field_upload() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (37, 29);
    let base = generate(Pattern::Cobblestones, w, h);
    let heights = base.heights();
    let depth_scale = 0.1;
    let tol = Tolerance { normal: depth_scale * w as f32 / 2048.0 / 2.0 + 1e-5 };
    let mut worst = Diff::default();
    let mut pyramids_by_edges: Vec<(EdgeMode, Vec<Vec<f32>>)> = Vec::new();
    for format in [HostFormat::R8, HostFormat::Rgba16G, HostFormat::R32] {
        for encoding in [HeightEncoding::Height, HeightEncoding::Depth] {
            for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
                let case = format!("{format:?} {encoding:?} {edges:?}");
                let label = format!("host {case}");
                // What the texture holds, and the depths it stands for.
                let (values, depths): (Vec<f32>, Vec<f32>) = match encoding {
                    HeightEncoding::Height => {
                        let v: Vec<f32> = heights.iter().map(|&x| format.quantize(x)).collect();
                        let d = v.iter().map(|&x| 1.0 - x).collect();
                        (v, d)
                    }
                    HeightEncoding::Depth => {
                        let v: Vec<f32> = heights.iter().map(|&x| format.quantize(1.0 - x)).collect();
                        (v.clone(), v)
                    }
                };
                let field = HeightField::from_depths(w, h, depths.clone()).unwrap();
                let opts = HeightResourceOptions {
                    encoding,
                    channel: format.channel(),
                    edges,
                    depth_scale,
                    ..Default::default()
                };
                let (from_texture, from_field) = no_validation_error(&ctx, &case, || {
                    let texture = host_texture(&ctx, &label, format, w, h, &values);
                    let t = HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &opts, &label)
                        .unwrap_or_else(|e| panic!("{case}: {e}"));
                    let f = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &field, &opts, &label)
                        .unwrap_or_else(|e| panic!("{case}: {e}"));
                    (t, f)
                });
                assert!(from_texture.is_from_texture() && !from_field.is_from_texture());
                assert_eq!((from_texture.width(), from_texture.height()), (w, h));
                assert_eq!(from_texture.edges(), edges);
                let a = read_back(&ctx, &from_texture);
                let b = read_back(&ctx, &from_field);
                // The import itself against the CPU: f16(depth), within one step.
                let truth: Vec<f32> = depths.iter().map(|&d| f16r(d)).collect();
                // Float formats: the same f32 arithmetic and the same rounding (to nearest) give
                // the same bits. Unorm: the GPU's 8-bit decode may differ from k / 255 by a hair,
                // which can move the rounding by one f16 step.
                let exact = !matches!(format, HostFormat::R8);
                let import_tol = |v: f32| if exact { 0.0 } else { f16_ulp(v) };
                compare(&format!("{case}: imported mip 0 vs CPU"), &channel_of(&a.heights[0], 0), &truth, import_tol);
                // The upload is exact.
                compare(&format!("{case}: uploaded mip 0 vs CPU"), &channel_of(&b.heights[0], 0), &truth, |_| 0.0);
                let d = compare_maps(&case, &a, &b, &tol);
                println!("{case}: {d:?}");
                if exact {
                    assert_eq!(d.differing_texels, 0, "{case}: same depths, same passes, same bits: {d:?}");
                }
                worst.depth = worst.depth.max(d.depth);
                worst.parallax = worst.parallax.max(d.parallax);
                worst.normal = worst.normal.max(d.normal);
                worst.pyramid = worst.pyramid.max(d.pyramid);
                worst.differing_texels += d.differing_texels;
                if matches!(format, HostFormat::R32) && encoding == HeightEncoding::Height {
                    pyramids_by_edges.push((edges, b.pyramid.clone()));
                }
            }
        }
    }
    println!("worst over all cases: {worst:?}");
    // The edge mode reaches the passes: the border cells of the pyramid differ.
    let [(e0, p0), (e1, p1)] = &pyramids_by_edges[..] else { panic!("two edge modes") };
    assert_ne!(e0, e1);
    assert_ne!(p0[0], p1[0], "the pyramid does not depend on the edge mode");
}

#[test]
fn height_and_depth_encodings_agree() {
    // Height encoding of h and Depth encoding of 1 - h describe one surface.
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (24, 20);
    let heights = generate(Pattern::Text, w, h).heights();
    let depths: Vec<f32> = heights.iter().map(|&x| HostFormat::R8.quantize(1.0 - x)).collect();
    let heights: Vec<f32> = heights.iter().map(|&x| HostFormat::R8.quantize(x)).collect();
    let (a, b) = no_validation_error(&ctx, "encodings", || {
        let th = host_texture(&ctx, "as heights", HostFormat::R8, w, h, &heights);
        let td = host_texture(&ctx, "as depths", HostFormat::R8, w, h, &depths);
        let oh = HeightResourceOptions::default();
        let od = HeightResourceOptions { encoding: HeightEncoding::Depth, ..oh };
        let a = HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &th, &oh, "as heights").unwrap();
        let b = HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &td, &od, "as depths").unwrap();
        (a, b)
    });
    let tol = Tolerance { normal: 0.1 * w as f32 / 2048.0 / 2.0 + 1e-5 };
    let d = compare_maps("Height of h vs Depth of 1 - h", &read_back(&ctx, &a), &read_back(&ctx, &b), &tol);
    println!("Height of h vs Depth of 1 - h (R8Unorm): {d:?}");
}

#[test]
fn nan_infinity_and_out_of_range_values_are_clamped() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let values = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.5, 1.5, 0.25, 0.0, 1.0];
    // NaN is the deepest point in either encoding (as `upload_depths`); the rest clamp.
    let as_height = [1.0, 0.0, 1.0, 1.0, 0.0, 0.75, 1.0, 0.0];
    let as_depth = [1.0, 1.0, 0.0, 0.0, 1.0, 0.25, 0.0, 1.0];
    for (encoding, expected) in [(HeightEncoding::Height, as_height), (HeightEncoding::Depth, as_depth)] {
        let r = no_validation_error(&ctx, "special values", || {
            let texture = host_texture(&ctx, "special", HostFormat::R32, 8, 1, &values);
            let opts = HeightResourceOptions { encoding, edges: EdgeMode::Clamp, ..Default::default() };
            HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &opts, "special").unwrap()
        });
        let mip0 = read_back(&ctx, &r).heights.swap_remove(0);
        assert_eq!(channel_of(&mip0, 0), expected, "{encoding:?}: depths of {values:?}");
    }
}

/// Heights of a second field for the runtime tests: pyramids squeezed into [0.25, 0.75], so its
/// least depth (0.25) differs from the first field's.
fn second_field(w: u32, h: u32) -> HeightField {
    let p = generate(Pattern::Pyramids, w, h);
    HeightField::from_depths(w, h, p.depths().iter().map(|&d| 0.25 + 0.5 * d).collect()).unwrap()
}

/// The top of the CPU pyramid of `field` rounded to f16 (its least depth).
fn cpu_pyramid_top(field: &HeightField, edges: EdgeMode) -> f32 {
    let rounded =
        HeightField::from_depths(field.width(), field.height(), field.depths().iter().map(|&d| f16r(d)).collect())
            .unwrap();
    let p = MaxHeightPyramid::new(&rounded, edges);
    p.min_depth(p.len() - 1, 0, 0)
}

#[test]
fn texture_changed_at_run_time_is_reimported() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (40, 33);
    let first = generate(Pattern::Cobblestones, w, h);
    let second = second_field(w, h);
    let opts = HeightResourceOptions::default();
    let texture = host_texture(&ctx, "live", HostFormat::R32, w, h, &first.heights());
    let live = HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &opts, "live").unwrap();
    let before = read_back(&ctx, &live);
    let top = |r: &Readback| *r.pyramid.last().unwrap().first().unwrap();
    let (top_first, top_second) = (cpu_pyramid_top(&first, opts.edges), cpu_pyramid_top(&second, opts.edges));
    assert!((top_second - top_first).abs() > 0.1, "the fields must differ at the top: {top_first} {top_second}");
    assert!((top(&before) - top_first).abs() <= 1e-6, "before: top {} vs CPU {top_first}", top(&before));

    // New texels, then the rebuild.
    write_host(&ctx, &texture, HostFormat::R32, &second.heights());
    no_validation_error(&ctx, "encode_rebuild", || rebuild(&ctx, &passes, &live));
    let after = read_back(&ctx, &live);
    assert!((top(&after) - top_second).abs() <= 1e-6, "after: top {} vs CPU {top_second}", top(&after));
    let truth: Vec<f32> = second.depths().iter().map(|&d| f16r(d)).collect();
    compare("after: mip 0 vs the new field", &channel_of(&after.heights[0], 0), &truth, f16_ulp);

    // And everything equals the maps of the new field.
    let reference = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &second, &opts, "reference").unwrap();
    let tol = Tolerance { normal: 0.1 * w as f32 / 2048.0 / 2.0 + 1e-5 };
    let d = compare_maps("re-imported vs new field", &after, &read_back(&ctx, &reference), &tol);
    println!("re-imported vs new field: {d:?}");

    // A texture-built resource refuses update_field.
    let err = live.update_field(&ctx.queue, &second).unwrap_err();
    assert!(matches!(err, HostError::NotFromField { .. }), "{err:?}");
    assert!(err.to_string().contains("\"live\""), "{err}");
}

#[test]
fn update_field_replaces_the_depths() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (32, 32);
    let first = generate(Pattern::Bricks, w, h);
    let second = second_field(w, h);
    let opts = HeightResourceOptions { edges: EdgeMode::Clamp, ..Default::default() };
    let r = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &first, &opts, "field").unwrap();
    no_validation_error(&ctx, "update_field", || {
        r.update_field(&ctx.queue, &second).unwrap();
        rebuild(&ctx, &passes, &r);
    });
    let reference = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &second, &opts, "reference").unwrap();
    let tol = Tolerance { normal: 0.0 };
    let d = compare_maps("updated vs new field", &read_back(&ctx, &r), &read_back(&ctx, &reference), &tol);
    assert_eq!(d.differing_texels, 0, "the same upload and passes give the same bits: {d:?}");
    let top = *read_back(&ctx, &r).pyramid.last().unwrap().first().unwrap();
    assert!((top - cpu_pyramid_top(&second, opts.edges)).abs() <= 1e-6, "pyramid top {top}");

    let small = HeightField::constant(16, 16, 0.5);
    let err = r.update_field(&ctx.queue, &small).unwrap_err();
    assert_eq!(err, HostError::SizeMismatch { label: "field".into(), expected: (w, h), found: (16, 16) });
    assert!(err.to_string().contains("\"field\"") && err.to_string().contains("16x16"), "{err}");
}

#[test]
fn bind_group_entries_bind_the_maps_and_the_edge_mode() {
    // A compute shader of the "host" declares pomkit's three bindings at 3, 5, 7 next to its
    // own buffer at 0, samples `heights` on the left border and loads the pyramid: the layout
    // and entries fit, and the sampler wraps or clamps as asked.
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (16, 8);
    let field = generate(Pattern::Cobblestones, w, h);
    let bindings = HeightBindings { heights: 3, pyramid: 5, sampler: 7 };
    let shader = r"
        @group(0) @binding(0) var<storage, read_write> out: array<vec2<f32>>;
        @group(0) @binding(3) var heights: texture_2d<f32>;
        @group(0) @binding(5) var pyramid: texture_2d<f32>;
        @group(0) @binding(7) var samp: sampler;
        @compute @workgroup_size(1)
        fn main(@builtin(global_invocation_id) id: vec3<u32>) {
            let size = vec2<f32>(textureDimensions(heights, 0));
            // u = 0: halfway between the last column and the first when wrapping.
            let uv = vec2<f32>(0.0, (f32(id.x) + 0.5) / size.y);
            let d = textureSampleLevel(heights, samp, uv, 0.0).r;
            out[id.x] = vec2<f32>(d, textureLoad(pyramid, vec2<u32>(0u, id.x), 0).r);
        }
    ";
    for edges in [EdgeMode::Wrap, EdgeMode::Clamp] {
        let opts = HeightResourceOptions { edges, ..Default::default() };
        let r = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &field, &opts, "bound").unwrap();
        let out = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: u64::from(h) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: u64::from(h) * 8,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        no_validation_error(&ctx, "host bind group", || {
            let mut layout_entries = vec![wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: false },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }];
            layout_entries.extend(HeightResource::layout_entries(bindings, wgpu::ShaderStages::COMPUTE));
            let layout = ctx
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: None, entries: &layout_entries });
            let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: out.as_entire_binding() }];
            entries.extend(r.bind_group_entries(bindings));
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &layout,
                entries: &entries,
            });
            let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: None,
                source: wgpu::ShaderSource::Wgsl(shader.into()),
            });
            let pipeline_layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: None,
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: None,
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(h, 1, 1);
            }
            encoder.copy_buffer_to_buffer(&out, 0, &readback, 0, u64::from(h) * 8);
            ctx.queue.submit([encoder.finish()]);
        });
        let bytes = ctx.read_buffer(&readback).unwrap();
        let got: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        let pyramid = MaxHeightPyramid::new(
            &HeightField::from_depths(w, h, field.depths().iter().map(|&d| f16r(d)).collect()).unwrap(),
            edges,
        );
        for y in 0..h {
            let first = f16r(field.depths()[(y * w) as usize]);
            let last = f16r(field.depths()[(y * w + w - 1) as usize]);
            let expected = match edges {
                EdgeMode::Wrap => 0.5 * (first + last),
                EdgeMode::Clamp => first,
            };
            let (d, p) = (got[2 * y as usize], got[2 * y as usize + 1]);
            // Filtering hardware keeps a few bits of weight precision: 1e-3 of the depth range.
            assert!((d - expected).abs() <= 1e-3, "{edges:?} row {y}: sampled {d}, expected {expected}");
            let cpu = pyramid.min_depth(0, 0, y);
            assert!((p - cpu).abs() <= 1e-6, "{edges:?} row {y}: pyramid {p}, CPU {cpu}");
        }
    }
}

/// The description of a texture for the bad-input tests (labelled by `make_texture`).
fn desc(
    size: (u32, u32, u32),
    dimension: wgpu::TextureDimension,
    format: wgpu::TextureFormat,
    sample_count: u32,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureDescriptor<'static> {
    wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: size.2 },
        mip_level_count: 1,
        sample_count,
        dimension,
        format,
        usage,
        view_formats: &[],
    }
}

/// A texture labelled `label`.
fn make_texture(ctx: &GpuContext, label: &str, desc: &wgpu::TextureDescriptor<'_>) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor { label: Some(label), ..desc.clone() })
}

#[test]
fn bad_textures_give_the_right_error() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let d2 = wgpu::TextureDimension::D2;
    let sampled = wgpu::TextureUsages::TEXTURE_BINDING;
    let render = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::RENDER_ATTACHMENT;
    use wgpu::TextureFormat as F;
    let limit = ctx.device.limits().max_texture_dimension_2d;
    type Check = fn(&HostError) -> bool;
    let cases: [(&str, wgpu::TextureDescriptor<'static>, u32, Check); 8] = [
        (
            "depth32",
            desc((8, 8, 1), d2, F::Depth32Float, 1, render),
            0,
            |e| matches!(e, HostError::Format { why, .. } if why.contains("depth")),
        ),
        (
            "rgba8uint",
            desc((8, 8, 1), d2, F::Rgba8Uint, 1, sampled),
            0,
            |e| matches!(e, HostError::Format { why, .. } if why.contains("integer")),
        ),
        ("no-binding", desc((8, 8, 1), d2, F::R8Unorm, 1, wgpu::TextureUsages::COPY_DST), 0, |e| {
            matches!(e, HostError::Usage { .. })
        }),
        ("msaa", desc((8, 8, 1), d2, F::Rgba8Unorm, 4, render), 0, |e| {
            matches!(e, HostError::Samples { samples: 4, .. })
        }),
        ("volume", desc((8, 8, 4), wgpu::TextureDimension::D3, F::R8Unorm, 1, sampled), 0, |e| {
            matches!(e, HostError::Dimension { .. })
        }),
        ("array", desc((8, 8, 3), d2, F::R8Unorm, 1, sampled), 0, |e| matches!(e, HostError::Layers { layers: 3, .. })),
        ("r8-alpha", desc((8, 8, 1), d2, F::R8Unorm, 1, sampled), 3, |e| {
            matches!(e, HostError::Channel { channel: 3, components: 1, .. })
        }),
        ("rgba8-channel-7", desc((8, 8, 1), d2, F::Rgba8Unorm, 1, sampled), 7, |e| {
            matches!(e, HostError::Channel { channel: 7, components: 4, .. })
        }),
    ];
    for (label, desc, channel, check) in cases {
        let opts = HeightResourceOptions { channel, ..Default::default() };
        let err = no_validation_error(&ctx, label, || {
            let texture = make_texture(&ctx, label, &desc);
            match HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &opts, label) {
                Ok(_) => panic!("{label}: accepted"),
                Err(e) => e,
            }
        });
        println!("{label}: {err}");
        assert!(check(&err), "{label}: wrong error {err:?}");
        assert!(err.to_string().contains(&format!("\"{label}\"")), "{label}: message does not name it: {err}");
    }

    // A field wider than the device allows, refused before any wgpu call.
    let wide = HeightField::constant(limit + 1, 1, 0.5);
    let err = no_validation_error(&ctx, "wide field", || {
        HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &wide, &Default::default(), "wide").unwrap_err()
    });
    assert!(matches!(err, HostError::TooLarge { .. }) && err.to_string().contains("\"wide\""), "{err:?}");

    // Textures wgpu refuses to create (invalid textures, their error caught here) that still
    // report their requested size: pomkit refuses them without another wgpu error.
    for (label, size, check) in [
        ("empty", (0, 0), (|e| matches!(e, HostError::Empty { width: 0, height: 0, .. })) as Check),
        ("too-wide", (limit + 1, 1), |e| matches!(e, HostError::TooLarge { .. })),
    ] {
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let texture = make_texture(&ctx, label, &desc((size.0, size.1, 1), d2, F::R8Unorm, 1, sampled));
        assert!(pollster::block_on(scope.pop()).is_some(), "wgpu accepted {label} texture {size:?}");
        let err = no_validation_error(&ctx, label, || {
            HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &Default::default(), label)
                .unwrap_err()
        });
        println!("{label}: {err}");
        assert!(check(&err), "{label}: wrong error {err:?}");
        assert!(err.to_string().contains(&format!("\"{label}\"")), "{label}: message does not name it: {err}");
    }
}

#[test]
fn texture_of_another_device_is_an_error_not_a_panic() {
    let Some(ctx) = gpu() else { return };
    let Some(other) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let texture = host_texture(&other, "foreign", HostFormat::R8, 8, 8, &[0.5; 64]);
    let err = no_validation_error(&ctx, "foreign", || {
        HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &Default::default(), "foreign")
            .unwrap_err()
    });
    println!("foreign: {err}");
    assert!(matches!(err, HostError::Device { .. }) && err.to_string().contains("\"foreign\""), "{err:?}");
}

/// One texel of `format` with `v` in channel `channel` and other values in the other
/// channels, and the value the shader reads for `v` (the format's quantization).
fn texel(format: wgpu::TextureFormat, channel: usize, v: f32) -> (Vec<u8>, f32) {
    use wgpu::TextureFormat as F;
    let unorm8 = |x: f32| (x * 255.0).round() as u8;
    match format {
        F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Rg8Unorm => {
            let n = if format == F::Rg8Unorm { 2 } else { 4 };
            // Bgra8Unorm keeps B, G, R, A in memory; the shader sees R, G, B, A.
            let slot = if format == F::Bgra8Unorm { [2, 1, 0, 3][channel] } else { channel };
            let mut t = vec![200u8; n];
            t[slot] = unorm8(v);
            (t, f32::from(unorm8(v)) / 255.0)
        }
        F::R8Snorm => {
            let k = (v * 127.0).round() as i8;
            (k.to_le_bytes().to_vec(), f32::from(k) / 127.0)
        }
        F::Rgba32Float => {
            let mut t = [0.3f32; 4];
            t[channel] = v;
            (t.iter().flat_map(|x| x.to_le_bytes()).collect(), v)
        }
        F::R16Float => (half::f16::from_f32(v).to_bits().to_le_bytes().to_vec(), f16r(v)),
        f => panic!("no texel packing for {f:?}"),
    }
}

#[test]
fn other_float_formats_are_read_by_channel() {
    // sRGB (whose alpha is linear), BGRA (channel order), two channels, snorm, 32-bit float x4,
    // f16: each holds a ramp in one channel and other values in the rest.
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    use wgpu::TextureFormat as F;
    let (w, h) = (8, 8);
    for (format, channel) in [
        (F::Rgba8UnormSrgb, 3),
        (F::Bgra8Unorm, 2),
        (F::Rg8Unorm, 1),
        (F::R8Snorm, 0),
        (F::Rgba32Float, 3),
        (F::R16Float, 0),
    ] {
        let label = format!("{format:?}");
        let texels: Vec<(Vec<u8>, f32)> = (0..w * h).map(|i| texel(format, channel, i as f32 / 63.0)).collect();
        let bytes: Vec<u8> = texels.iter().flat_map(|t| t.0.clone()).collect();
        let r = no_validation_error(&ctx, &label, || {
            let texture = make_texture(
                &ctx,
                &label,
                &desc(
                    (w, h, 1),
                    wgpu::TextureDimension::D2,
                    format,
                    1,
                    wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                ),
            );
            ctx.queue.write_texture(
                texture.as_image_copy(),
                &bytes,
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(bytes.len() as u32 / h),
                    rows_per_image: None,
                },
                texture.size(),
            );
            let opts = HeightResourceOptions { channel: channel as u32, ..Default::default() };
            HeightResource::from_texture(&ctx.device, &ctx.queue, &passes, &texture, &opts, &label)
                .unwrap_or_else(|e| panic!("{label}: {e}"))
        });
        let truth: Vec<f32> = texels.iter().map(|t| f16r(1.0 - t.1)).collect();
        let mip0 = read_back(&ctx, &r).heights.swap_remove(0);
        // 8-bit decodes may differ from k / 255 by a hair: one f16 step.
        let (e, n) = compare(&format!("{label} channel {channel}"), &channel_of(&mip0, 0), &truth, f16_ulp);
        println!("{label} channel {channel}: largest difference {e}, {n} texels differ");
    }
}

#[test]
fn a_resource_with_cones_rebuilds_them_with_its_heights() {
    let Some(ctx) = gpu() else { return };
    let passes = HeightPasses::new(&ctx.device);
    let (w, h) = (24, 16);
    let (first, second) = (generate(Pattern::Bricks, w, h), second_field(w, h));
    let opts = HeightResourceOptions { edges: EdgeMode::Clamp, cones: true, ..Default::default() };
    let r = HeightResource::from_field(&ctx.device, &ctx.queue, &passes, &first, &opts, "coned").unwrap();
    // The cones in the pyramid's level 0 (green), against the CPU's for the f16 heights.
    let check = |field: &HeightField, case: &str| {
        let texels = ctx.read_texture(&r.maps().pyramid, 0).unwrap();
        let stride = r.maps().pyramid.width();
        let f16: Vec<f32> = field.depths().iter().map(|&d| half::f16::from_f32(d).to_f32()).collect();
        let cpu = pomkit_core::cone::ConeMap::conservative(&HeightField::from_depths(w, h, f16).unwrap(), opts.edges);
        let (mut g, mut c) = (0.0f64, 0.0f64);
        for y in 0..h {
            for x in 0..w {
                g += f64::from(texels[2 * (y * stride + x) as usize + 1]);
                c += f64::from(cpu.ratio(x, y));
            }
        }
        assert!(c > 0.0 && (g / c - 1.0).abs() < 0.03, "{case}: GPU cones are {} of the CPU's on average", g / c);
    };
    check(&first, "built");
    r.update_field(&ctx.queue, &second).unwrap();
    rebuild(&ctx, &passes, &r);
    check(&second, "rebuilt for new heights");
}
