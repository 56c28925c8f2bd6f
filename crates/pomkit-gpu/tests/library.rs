//! The shader library's two forms: the plain-WGSL file in the repository is the flattened WESL
//! modules, and both validate.

use std::path::Path;

#[test]
fn plain_wgsl_file_is_the_flattened_modules() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders/pomkit.wgsl");
    let want = pomkit_gpu::library::flatten();
    if std::env::var_os("UPDATE_SHADERS").is_some() {
        std::fs::write(&path, &want).expect("write shaders/pomkit.wgsl");
    }
    let have = std::fs::read_to_string(&path).expect("shaders/pomkit.wgsl exists");
    assert!(
        have == want,
        "{} is not the flattened WESL modules: run `UPDATE_SHADERS=1 cargo test -p pomkit-gpu --test library`",
        path.display()
    );
}

/// naga's view of a struct: (member name, byte offset) in order.
fn wgsl_struct(module: &naga::Module, name: &str) -> Vec<(String, usize)> {
    let ty = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name));
    let Some((_, ty)) = ty else { panic!("struct {name} not found in the WGSL") };
    let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("{name} is not a struct") };
    members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect()
}

fn parse(src: &str) -> naga::Module {
    naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{}", e.emit_to_string(src)))
}

fn assert_layout(what: &str, wgsl: &[(String, usize)], rust: &[(&'static str, usize)]) {
    let rust: Vec<(String, usize)> = rust.iter().map(|(n, o)| ((*n).to_owned(), *o)).collect();
    assert_eq!(wgsl, rust.as_slice(), "{what}: the WGSL struct (left) and the Rust writer (right) disagree");
}

/// The uniform structs the Rust side writes have the members, order and offsets naga computes
/// for the WGSL structs.
#[test]
fn uniform_layouts_match_the_wgsl_structs() {
    let library = parse(pomkit_gpu::library::WGSL);
    assert_layout("PomkitParams", &wgsl_struct(&library, "PomkitParams"), &pomkit_gpu::library::PomkitParams::layout());
    let render = parse(&pomkit_gpu::library::compose(pomkit_gpu::material::RENDER_WGSL));
    assert_layout("Material", &wgsl_struct(&render, "Material"), &pomkit_gpu::material::material_layout());
    assert_layout("Frame", &wgsl_struct(&render, "Frame"), &pomkit_gpu::material::frame_layout());
    let params = pomkit_gpu::library::PomkitParams::from_material(
        &pomkit_core::scene::Material::default(),
        pomkit_core::trace::Technique::Pom,
    );
    assert_eq!(params.to_bytes().len(), pomkit_gpu::library::PomkitParams::SIZE as usize);
}

/// The library's `PomkitParams` carries exactly the parameter table's uniform members
/// (`pomkit_core::params`, `Param::uniform`), besides padding.
#[test]
fn the_uniform_carries_the_parameter_tables_members() {
    let library = parse(pomkit_gpu::library::WGSL);
    let mut wgsl: Vec<String> =
        wgsl_struct(&library, "PomkitParams").into_iter().map(|(n, _)| n).filter(|n| !n.starts_with("pad")).collect();
    let mut table: Vec<String> = pomkit_core::params::all().filter_map(|p| p.uniform).map(str::to_owned).collect();
    wgsl.sort();
    table.sort();
    assert_eq!(wgsl, table, "PomkitParams (left) and the parameter table's uniform members (right) disagree");
}

fn constant(module: &naga::Module, name: &str) -> naga::Literal {
    let (_, c) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("constant {name} not found in the WGSL"));
    match module.global_expressions[c.init] {
        naga::Expression::Literal(l) => l,
        ref e => panic!("{name} is not a literal: {e:?}"),
    }
}

/// Every technique, shadow mode and edge mode of pomkit-core has a WGSL constant of the same
/// value as the Rust side writes, named after it; and the shared limits agree.
#[test]
fn technique_and_shadow_constants_match_the_rust_side() {
    use pomkit_core::shadow::ShadowMode;
    use pomkit_core::trace::Technique;
    let m = parse(pomkit_gpu::library::WGSL);
    let wgsl_name = |prefix: &str, name: &str| format!("{prefix}{}", name.to_uppercase().replace('-', "_"));
    for t in Technique::ALL {
        let name = wgsl_name("POMKIT_", t.name());
        assert_eq!(constant(&m, &name), naga::Literal::U32(pomkit_gpu::library::technique_index(t)), "{name}");
    }
    for s in ShadowMode::ALL {
        let name = wgsl_name("POMKIT_SHADOW_", s.name());
        assert_eq!(constant(&m, &name), naga::Literal::U32(pomkit_gpu::library::shadow_index(s)), "{name}");
    }
    for (name, e) in [("POMKIT_WRAP", pomkit_core::EdgeMode::Wrap), ("POMKIT_CLAMP", pomkit_core::EdgeMode::Clamp)] {
        assert_eq!(constant(&m, name), naga::Literal::U32(pomkit_gpu::library::edges_index(e)), "{name}");
    }
    assert_eq!(constant(&m, "POMKIT_MIN_COS"), naga::Literal::F32(pomkit_core::trace::MIN_COS));
}

/// The WESL form compiles with the `wesl` crate (the compiler Bevy 0.20 uses) when a host
/// module imports the library from a folder of its package, and the result validates.
#[test]
fn wesl_modules_compile_when_a_host_imports_them() {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("wesl-package");
    let lib = root.join("pomkit");
    std::fs::create_dir_all(&lib).expect("temp dir");
    for (name, source) in pomkit_gpu::library::MODULES {
        std::fs::write(lib.join(format!("{name}.wesl")), source).expect("write module");
    }
    let host = r"
import package::pomkit::common::{PomkitParams, pomkit_view_ray, pomkit_light_ray};
import package::pomkit::trace::{pomkit_trace, pomkit_receiver};
import package::pomkit::shadow::pomkit_shadow;
import package::pomkit::lod::{pomkit_mip_level, pomkit_lod_weight};
import package::pomkit::depth::{pomkit_hit_position, pomkit_pixel_depth};

@group(0) @binding(0) var<uniform> params: PomkitParams;
@group(0) @binding(1) var heights: texture_2d<f32>;
@group(0) @binding(2) var pyramid: texture_2d<f32>;
@group(0) @binding(3) var samp: sampler;

struct Out {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

@fragment
fn fs(@builtin(position) pos: vec4<f32>, @location(0) uv: vec2<f32>, @location(1) view_ts: vec3<f32>, @location(2) world: vec3<f32>) -> Out {
    let lod = pomkit_mip_level(heights, dpdx(uv), dpdy(uv));
    let weight = pomkit_lod_weight(lod, params.lod_threshold);
    var hit = pomkit_trace(params.technique, heights, pyramid, samp, params, uv, pomkit_view_ray(view_ts, vec2(1.0)), lod);
    hit = pomkit_receiver(params.technique, heights, samp, hit, lod);
    let sun = pomkit_shadow(heights, pyramid, samp, params, hit.uv, hit.depth, pomkit_light_ray(vec3(0.3, 0.2, 1.0), vec2(1.0)), lod);
    let p = pomkit_hit_position(world, vec3(0.0, 0.0, 1.0), vec3(0.0, 0.0, 1.0), hit.depth, params.depth_scale, vec2(1.0));
    let z = pomkit_pixel_depth(p, mat4x4<f32>(), pos.z, true);
    return Out(vec4(hit.uv, sun.visibility, weight), z);
}
";
    std::fs::write(root.join("main.wesl"), host).expect("write host");
    let compiled = wesl::Wesl::new(&root)
        .compile(&"package::main".parse().expect("module path"))
        .unwrap_or_else(|e| panic!("WESL error: {e}"))
        .to_string();
    let module = parse(&compiled);
    let mut v = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty());
    v.validate(&module).unwrap_or_else(|e| panic!("{}", e.emit_to_string(&compiled)));
    // The walk of the exact tracer came along through trace.wesl's import of exact.wesl.
    assert!(
        module.functions.iter().any(|(_, f)| f.name.as_deref().is_some_and(|n| n.contains("pomkit_exact_first_hit")))
    );
    assert!(module.entry_points.iter().any(|e| e.name == "fs"));
}
