//! Every WGSL file in the repository parses and validates with naga (docs/GPU.md). A file whose
//! first line is `// uses: pomkit.wgsl` is validated with the shader library composed in front
//! of it, as the program that loads it does. Bevy's shaders (`#import` lines, composed by
//! naga_oil at run time) are left to bevy_pomkit's tests, which draw with them.

use std::path::{Path, PathBuf};

fn wgsl_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            if name != "target" && !name.starts_with('.') {
                wgsl_files(&p, out);
            }
        } else if p.extension().is_some_and(|x| x == "wgsl") {
            out.push(p);
        }
    }
}

#[test]
fn every_wgsl_file_validates() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut files = Vec::new();
    for dir in ["crates", "examples"] {
        wgsl_files(&root.join(dir), &mut files);
    }
    assert!(
        files.iter().any(|f| f.ends_with("pomkit-gpu/src/material/render.wgsl")),
        "no shaders found under {} (found {files:?}): the test would prove nothing",
        root.display()
    );
    let mut failures = Vec::new();
    for f in &files {
        let own = std::fs::read_to_string(f).expect("readable shader");
        if own.lines().any(|l| l.starts_with("#import ")) {
            continue;
        }
        let src = if own.starts_with("// uses: pomkit.wgsl") { pomkit_gpu::library::compose(&own) } else { own };
        let module = match naga::front::wgsl::parse_str(&src) {
            Ok(m) => m,
            Err(e) => {
                failures.push(format!("{}: {}", f.display(), e.emit_to_string(&src)));
                continue;
            }
        };
        let mut v =
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty());
        if let Err(e) = v.validate(&module) {
            failures.push(format!("{}: {}", f.display(), e.emit_to_string(&src)));
        }
    }
    println!("validated {} WGSL files", files.len());
    assert!(failures.is_empty(), "invalid shaders:\n{}", failures.join("\n"));
}
