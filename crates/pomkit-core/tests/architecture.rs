//! ARCHITECTURE.md describes the tree as it is: every source file of every crate (Rust, WGSL
//! and WESL under `src/`) is named there, so a file added, moved or split without a line in the
//! map fails here.

use std::path::{Path, PathBuf};

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let path = e.path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|x| x == "rs" || x == "wgsl" || x == "wesl") {
            out.push(path);
        }
    }
}

#[test]
fn architecture_names_every_source_file() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let map = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut files = Vec::new();
    for krate in std::fs::read_dir(root.join("crates")).expect("crates/").flatten() {
        sources(&krate.path().join("src"), &mut files);
    }
    assert!(files.len() > 50, "found only {} source files", files.len());
    let mut missing = Vec::new();
    for f in &files {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let stem = f.file_stem().unwrap().to_string_lossy().into_owned();
        let named = if name == "mod.rs" || name == "lib.rs" || name == "main.rs" {
            // A module folder is named by its path ("src/cone/", "cone/mod.rs"); a crate root
            // by its crate's entry.
            let parent = f.parent().unwrap().file_name().unwrap().to_string_lossy().into_owned();
            map.contains(&format!("{parent}/")) || map.contains(&format!("src/{name}"))
        } else {
            map.contains(&name) || map.contains(&format!("{stem}.rs/.")) || map.contains(&format!("{stem}.wgsl/."))
        };
        if !named {
            missing.push(f.strip_prefix(&root).unwrap_or(f).display().to_string());
        }
    }
    assert!(missing.is_empty(), "ARCHITECTURE.md does not name: {missing:#?}");
}
