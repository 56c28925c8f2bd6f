//! ARCHITECTURE.md describes the tree as it is: every source file of every crate (Rust, WGSL
//! and WESL under `src/`) is named there, so a file added, moved or split without a line in the
//! map fails here.

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
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let module_of = |f: &Path| -> Option<String> {
        let first = f.strip_prefix(&src).ok()?.components().next()?.as_os_str().to_string_lossy().into_owned();
        (first != "lib.rs").then(|| first.trim_end_matches(".rs").to_owned())
    };
    let modules: BTreeSet<String> = files.iter().filter_map(|f| module_of(f)).collect();
    let mut graph: BTreeMap<String, BTreeSet<String>> = modules.iter().map(|m| (m.clone(), BTreeSet::new())).collect();
    for f in &files {
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
    for f in &files {
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
