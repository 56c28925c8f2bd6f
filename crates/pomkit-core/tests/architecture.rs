//! ARCHITECTURE.md describes the tree as it is: every source file of every crate (Rust, WGSL
//! and WESL under `src/`) is named there, so a file added, moved or split without a line in the
//! map fails here. And what it names exists: the entries of its tree, and every path in it that
//! starts with `crates/`, `examples/` or `docs/`.

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

/// The paths ARCHITECTURE.md names that start with `crates/`, `examples/` or `docs/`, each with
/// the crate whose section of the tree it is written in (`None` outside a crate's section).
/// Glob-like and placeholder mentions (`*`, `?`, `[`, `{`, `<`) are not paths and are left out.
fn named_paths(map: &str) -> Vec<(String, Option<String>)> {
    let mut paths = Vec::new();
    let mut in_tree = false;
    let mut krate: Option<String> = None;
    for line in map.lines() {
        if line.starts_with("```") {
            in_tree = !in_tree;
            krate = None;
            continue;
        }
        if in_tree {
            let indent = line.len() - line.trim_start().len();
            let first = line.split_whitespace().next().unwrap_or("");
            if indent == 0 && !line.is_empty() {
                krate = None;
            } else if indent == 2 && first.ends_with('/') {
                krate = Some(first.trim_end_matches('/').to_owned());
            }
        }
        for prefix in ["crates/", "examples/", "docs/"] {
            for (at, _) in line.match_indices(prefix) {
                let boundary = line[..at].chars().next_back().is_none_or(|c| " \t(`'\",".contains(c));
                if !boundary {
                    continue;
                }
                let token: String =
                    line[at..].chars().take_while(|c| c.is_ascii_alphanumeric() || "_-./*?[{<".contains(*c)).collect();
                let token = token.trim_end_matches(['.', ',', ':', ';']);
                if token.contains(['*', '?', '[', '{', '<']) {
                    continue;
                }
                paths.push((token.to_owned(), if in_tree { krate.clone() } else { None }));
            }
        }
    }
    paths
}

#[test]
fn every_path_architecture_names_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let map = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let paths = named_paths(&map);
    assert!(paths.len() > 10, "found only {} paths: {paths:?}", paths.len());
    // In a crate's section of the tree, `examples/...` may be the crate's own folder.
    let missing: Vec<String> = paths
        .into_iter()
        .filter(|(path, krate)| {
            !root.join(path).exists()
                && !krate.as_ref().is_some_and(|k| root.join("crates").join(k).join(path).exists())
        })
        .map(|(path, krate)| match krate {
            Some(k) => format!("{path} (in the section of {k})"),
            None => path,
        })
        .collect();
    assert!(missing.is_empty(), "ARCHITECTURE.md names paths that do not exist: {missing:#?}");
}

#[test]
fn named_paths_skip_globs_and_know_their_crate() {
    let map = "See docs/A.md, and crates/x/src/*.rs.\n```\ncrates/\n  pomkit-core/   core\n    examples/e.rs  one\ndocs/\n```\n";
    let paths = named_paths(map);
    assert_eq!(
        paths,
        [
            ("docs/A.md".to_owned(), None),
            ("crates/".to_owned(), None),
            ("examples/e.rs".to_owned(), Some("pomkit-core".to_owned())),
            ("docs/".to_owned(), None),
        ]
    );
}

/// The entries of ARCHITECTURE.md's tree (the first word of a line indented by at most six
/// spaces; deeper lines continue a description) as paths from the repository's root: a folder
/// entry (`src/host/`) is the parent of the entries indented under it. `src/probe.rs/.wgsl`
/// names two files. Glob-like entries (`tests/*.rs`) are left out.
fn tree_entries(map: &str) -> Vec<String> {
    let mut entries = Vec::new();
    let mut in_tree = false;
    let mut folders: Vec<(usize, String)> = Vec::new();
    for line in map.lines() {
        if line.starts_with("```") {
            in_tree = !in_tree;
            folders.clear();
            continue;
        }
        let indent = line.len() - line.trim_start().len();
        let Some(word) = line.split_whitespace().next() else { continue };
        if !in_tree || indent > 6 || word.starts_with('(') {
            continue;
        }
        while folders.last().is_some_and(|(i, _)| *i >= indent) {
            folders.pop();
        }
        let path = format!("{}{word}", folders.last().map_or("", |(_, p)| p.as_str()));
        if word.ends_with('/') {
            folders.push((indent, path.clone()));
        }
        if word.contains(['*', '?', '[', '{', '<']) {
            continue;
        }
        match path.split_once("/.") {
            Some((file, other_ext)) => {
                let stem = file.rsplit_once('.').map_or(file, |(stem, _)| stem);
                entries.push(file.to_owned());
                entries.push(format!("{stem}.{other_ext}"));
            }
            None => entries.push(path),
        }
    }
    entries
}

#[test]
fn every_entry_of_the_tree_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let map = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let entries = tree_entries(&map);
    assert!(entries.len() > 50, "found only {} entries: {entries:?}", entries.len());
    let missing: Vec<&String> = entries.iter().filter(|e| !root.join(e).exists()).collect();
    assert!(missing.is_empty(), "ARCHITECTURE.md's tree names paths that do not exist: {missing:#?}");
}

#[test]
fn tree_entries_are_paths_from_the_root() {
    let map = "```\nCargo.toml      x\ncrates/\n  a/            a crate\n    src/p.rs/.wgsl  two\n    tests/*.rs    glob\n                          src/not_an_entry.rs\n    src/m/        folder\n  b/\ndocs/\n  X.md\n```\n";
    assert_eq!(
        tree_entries(map),
        [
            "Cargo.toml",
            "crates/",
            "crates/a/",
            "crates/a/src/p.rs",
            "crates/a/src/p.wgsl",
            "crates/a/src/m/",
            "crates/b/",
            "docs/",
            "docs/X.md"
        ]
    );
}
