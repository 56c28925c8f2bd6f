//! ARCHITECTURE.md describes the tree as it is: every source file of every crate (Rust, WGSL
//! and WESL under `src/`) is named there, so a file added, moved or split without a line in the
//! map fails here. And what it names exists: the entries of its tree, and every path in it that
//! starts with `crates/`, `examples/` or `docs/`.

use std::collections::{BTreeMap, BTreeSet};
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

/// The source of a pomkit-core file without its comments and its `#[cfg(test)]` modules (tests
/// may use any module), one line per line of code.
fn code_lines(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let t = line.trim_start();
        if t.starts_with("//") {
            continue;
        }
        let opens_test_module = t.starts_with("#[cfg(test)]")
            && lines.peek().is_some_and(|next| {
                let n = next.trim_start();
                n.starts_with("mod ") || n.starts_with("pub(crate) mod ") || n.starts_with("pub mod ")
            });
        if opens_test_module && lines.peek().is_some_and(|next| next.trim_end().ends_with(';')) {
            // A test module in a file of its own (`test_only_files` leaves the file out).
            lines.next();
            continue;
        }
        if opens_test_module {
            // Skip to the brace that closes the module.
            let mut depth = 0i64;
            let mut opened = false;
            for l in lines.by_ref() {
                if l.trim_start().starts_with("//") {
                    continue;
                }
                for c in l.chars() {
                    match c {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if opened && depth <= 0 {
                    break;
                }
            }
            continue;
        }
        // A comment at the end of a line of code.
        out.push(line.split(" // ").next().unwrap_or(line).to_owned());
    }
    out
}

/// The files under `src` that hold test modules declared in a file of their own
/// (`#[cfg(test)]` then `mod name;`), and the files under them: test code, like the inline
/// `#[cfg(test)]` modules `code_lines` leaves out.
fn test_only_files(src: &Path) -> BTreeSet<PathBuf> {
    let mut files = Vec::new();
    sources(src, &mut files);
    let mut test_dirs = Vec::new();
    let mut out = BTreeSet::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("source file");
        let lines: Vec<&str> = text.lines().map(str::trim).collect();
        for pair in lines.windows(2) {
            let Some(name) = pair[1].strip_prefix("mod ").and_then(|rest| rest.strip_suffix(';')) else { continue };
            if pair[0] != "#[cfg(test)]" {
                continue;
            }
            // A crate root or mod.rs declares its children beside it, another file in a folder
            // of its own name.
            let stem = f.file_stem().unwrap().to_string_lossy();
            let dir = if matches!(&*stem, "lib" | "main" | "mod") {
                f.parent().unwrap().to_path_buf()
            } else {
                f.parent().unwrap().join(&*stem)
            };
            out.insert(dir.join(format!("{name}.rs")));
            test_dirs.push(dir.join(name));
        }
    }
    out.extend(files.into_iter().filter(|f| test_dirs.iter().any(|d| f.starts_with(d))));
    out
}

fn ident_at(s: &str) -> &str {
    let end = s.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(s.len());
    &s[..end]
}

/// The top-level modules that `code` names through `crate::name`, `crate::{name, ..}` or (from a
/// file directly in src/) `super::name`.
fn referenced_modules(code: &str, modules: &BTreeSet<String>, top_level_file: bool) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut prefixes = vec!["crate::"];
    if top_level_file {
        prefixes.push("super::");
    }
    for prefix in prefixes {
        for (at, _) in code.match_indices(prefix) {
            if code[..at].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == '$') {
                continue;
            }
            let rest = &code[at + prefix.len()..];
            let names: Vec<&str> = if let Some(group) = rest.strip_prefix('{') {
                // `crate::{a::X, b}`: the first name of every entry at the group's top level.
                let mut names = vec![ident_at(group.trim_start())];
                let mut depth = 0;
                for (i, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => names.push(ident_at(group[i + 1..].trim_start())),
                        _ => {}
                    }
                }
                names
            } else {
                vec![ident_at(rest)]
            };
            out.extend(names.into_iter().filter(|n| modules.contains(*n)).map(str::to_owned));
        }
    }
    out
}

/// pomkit-core's top-level modules (a folder module with its submodules counts as one) and the
/// modules each one's code (tests aside) refers to.
fn core_module_graph() -> BTreeMap<String, BTreeSet<String>> {
    module_graph(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"))
}

/// The module graph of the crate whose sources are in `src` (its root, lib.rs or main.rs,
/// left out).
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let src = src.to_path_buf();
    let mut files = Vec::new();
    sources(&src, &mut files);
    let module_of = |f: &Path| -> Option<String> {
        let first = f.strip_prefix(&src).ok()?.components().next()?.as_os_str().to_string_lossy().into_owned();
        (first != "lib.rs" && first != "main.rs").then(|| first.trim_end_matches(".rs").to_owned())
    };
    let modules: BTreeSet<String> = files.iter().filter_map(|f| module_of(f)).collect();
    let mut graph: BTreeMap<String, BTreeSet<String>> = modules.iter().map(|m| (m.clone(), BTreeSet::new())).collect();
    let tests = test_only_files(&src);
    for f in files.iter().filter(|f| !tests.contains(*f)) {
        let Some(module) = module_of(f) else { continue };
        let text = std::fs::read_to_string(f).expect("source file");
        let code = code_lines(&text).join("\n");
        let top_level_file = f.parent() == Some(src.as_path());
        let refs = referenced_modules(&code, &modules, top_level_file);
        graph.get_mut(&module).unwrap().extend(refs.into_iter().filter(|m| *m != module));
    }
    graph
}

/// A cycle of `graph` as the modules along it, if there is one.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        done: &mut BTreeSet<String>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut cycle = path[i..].to_vec();
            cycle.push(m.to_owned());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_owned());
        for next in graph.get(m).into_iter().flatten() {
            if let Some(c) = visit(next, graph, done, path) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|m| visit(m, graph, &mut done, &mut Vec::new()))
}

/// pomkit-core's modules import one another without a cycle: a module is understood, tested
/// and changed with what it imports, never with what imports it. The technique and shadow
/// choices (`modes`) and the parameter table (`table`) are leaves that the tracer, the shadows
/// and the scene all read.
#[test]
fn core_modules_import_one_another_without_a_cycle() {
    let graph = core_module_graph();
    for (m, uses) in &graph {
        println!("{m} -> {}", uses.iter().cloned().collect::<Vec<_>>().join(", "));
    }
    let edges: usize = graph.values().map(BTreeSet::len).sum();
    assert!(
        graph.len() > 15 && edges > 20 && graph["trace"].contains("heightfield") && graph["scene"].contains("trace"),
        "the module graph was not read: {graph:#?}"
    );
    if let Some(cycle) = find_cycle(&graph) {
        panic!("pomkit-core's modules import one another in a cycle: {}\ngraph: {graph:#?}", cycle.join(" -> "));
    }
    assert!(graph["modes"].is_empty(), "modes imports {:?}", graph["modes"]);
    assert!(graph["table"].iter().all(|m| m == "modes"), "table imports {:?}", graph["table"]);
}

/// The command line's modules too: the verbs build on shared pieces (job.rs, batch.rs,
/// technique.rs), never on one another in a ring.
#[test]
fn cli_modules_import_one_another_without_a_cycle() {
    let graph = module_graph(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../pomkit-cli/src"));
    assert!(
        graph.len() > 10 && graph["bake"].contains("job") && graph["bake_height"].contains("job"),
        "the command line's module graph was not read: {graph:#?}"
    );
    if let Some(cycle) = find_cycle(&graph) {
        panic!("pomkit-cli's modules import one another in a cycle: {}\ngraph: {graph:#?}", cycle.join(" -> "));
    }
}

#[test]
fn the_cycle_check_finds_a_cycle() {
    let modules: BTreeSet<String> = ["a", "b", "c"].map(str::to_owned).into();
    let code = "use crate::b::X;\n";
    assert_eq!(referenced_modules(code, &modules, true), ["b".to_owned()].into());
    let group = "use crate::{\n    c::Y,\n    b,\n};\nlet x = super::a::f();";
    assert_eq!(referenced_modules(group, &modules, true), ["a", "b", "c"].map(str::to_owned).into());
    assert!(referenced_modules(group, &modules, false).len() == 2);
    let tested = "use crate::a::X;\n#[cfg(test)]\nmod tests {\n    use crate::b::Y;\n    fn f() { let s = \"{}\"; }\n}\n// crate::c::Z\n";
    assert_eq!(code_lines(tested).join("\n"), "use crate::a::X;");
    let file_module = "use crate::a::X;\n#[cfg(test)]\nmod measured;\nuse crate::c::Z;\n";
    assert_eq!(code_lines(file_module).join("\n"), "use crate::a::X;\nuse crate::c::Z;");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    assert!(
        test_only_files(&src).contains(&src.join("trace/exact/affine_bounds.rs")),
        "the test module in a file of its own was not found: {:?}",
        test_only_files(&src)
    );
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    graph.insert("a".into(), ["b".to_owned()].into());
    graph.insert("b".into(), ["c".to_owned()].into());
    graph.insert("c".into(), BTreeSet::new());
    assert_eq!(find_cycle(&graph), None);
    graph.get_mut("c").unwrap().insert("a".into());
    assert_eq!(find_cycle(&graph).unwrap().join(" -> "), "a -> b -> c -> a");
}

/// pomkit-core does no I/O: files, the environment, processes, the network and the console
/// belong to pomkit-io and the binaries. The one exception is memory.rs's budget probe, which
/// reads `POMKIT_MEMORY_LIMIT` and the kernel's figures under /proc (ARCHITECTURE.md and the
/// crate's README say so).
#[test]
fn core_touches_the_environment_only_in_the_memory_budget_probe() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let forbidden = [
        "std::fs",
        "std::env",
        "std::io::stdin",
        "std::io::stdout",
        "std::io::stderr",
        "std::process",
        "std::net",
        "File::",
        "env::var",
        "println!",
        "eprintln!",
        "print!(",
        "eprint!(",
        "dbg!(",
    ];
    let mut found = Vec::new();
    let mut probe_reads = false;
    let tests = test_only_files(&src);
    for f in files.iter().filter(|f| !tests.contains(*f)) {
        let text = std::fs::read_to_string(f).expect("source file");
        let code = code_lines(&text).join("\n");
        if f.ends_with("memory.rs") {
            probe_reads = code.contains("std::env::var_os") && code.contains("std::fs::read_to_string");
            continue;
        }
        for pattern in forbidden {
            if code.contains(pattern) {
                found.push(format!("{}: {pattern}", f.strip_prefix(&src).unwrap_or(f).display()));
            }
        }
    }
    assert!(found.is_empty(), "pomkit-core does I/O outside memory.rs's budget probe: {found:#?}");
    assert!(probe_reads, "memory.rs no longer reads the environment: update this test and the docs that say it does");
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
    // A tree is a fenced block without a language; a tagged one (```text) is something else.
    let (mut in_fence, mut in_tree) = (false, false);
    let mut folders: Vec<(usize, String)> = Vec::new();
    for line in map.lines() {
        if line.starts_with("```") {
            in_tree = !in_fence && line.trim_end() == "```";
            in_fence = !in_fence;
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
    assert!(tree_entries("```text\nnot/a/tree\n```\n").is_empty());
}
