//! The library's top-level modules import each other one way only (the architecture rule "data flows one
//! way; no two modules import each other"): every `crate::<module>` path in a module's non-test source is an
//! edge, and the graph must have no cycle. A cycle is reported with its modules, e.g. `room_layout → gpu →
//! room_layout`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The `.rs` files under `dir`, recursively.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// A file's code without `//` comments (doc links are not imports) and without its `#[cfg(test)]` tail
/// (tests may reach anywhere).
fn code_of(text: &str) -> String {
    let body = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => text,
    };
    body.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// The top-level module names that `code` reaches through `crate::NAME`.
fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + "crate::".len()..];
        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if !name.is_empty() {
            names.insert(name);
        }
    }
    names
}

/// Edges of the module graph: top-level module → the top-level modules it imports.
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let relative = file.strip_prefix(src).unwrap();
        let top =
            relative.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        if top == "lib" || top == "main" || top == "cli" {
            continue; // the crate roots and the binary's commands sit above everything
        }
        let imports = crate_paths(&code_of(&std::fs::read_to_string(&file).unwrap()));
        let entry = graph.entry(top.clone()).or_default();
        entry.extend(imports.into_iter().filter(|name| *name != top));
    }
    graph
}

/// A cycle of `graph` as its modules in order (first repeated at the end), or `None`.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        done: &mut BTreeSet<String>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| n == node) {
            let mut cycle = path[at..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, graph, done, path) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|node| visit(node, graph, &mut done, &mut Vec::new()))
}

#[test]
fn the_cycle_finder_finds_a_constructed_cycle_and_accepts_a_chain() {
    let edges = |pairs: &[(&str, &str)]| {
        let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in pairs {
            graph.entry(a.to_string()).or_default().insert(b.to_string());
        }
        graph
    };
    assert_eq!(find_cycle(&edges(&[("frame", "geometry"), ("features", "frame"), ("gpu", "features")])), None);
    let cycle = find_cycle(&edges(&[("gpu", "room_layout"), ("room_layout", "features"), ("features", "gpu")]));
    assert_eq!(cycle.map(|c| c.len()), Some(4));
    assert_eq!(crate_paths(&code_of("use crate::frame::Frame; // crate::gpu\nlet x = crate::nms::nms(a);")), {
        ["frame", "nms"].iter().map(|s| s.to_string()).collect::<BTreeSet<_>>()
    });
}

#[test]
fn the_library_modules_import_each_other_one_way() {
    let graph = module_graph(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    assert!(graph.contains_key("features") && graph.contains_key("gpu") && graph.contains_key("room_layout"));
    if let Some(cycle) = find_cycle(&graph) {
        panic!("modules import each other: {}", cycle.join(" → "));
    }
}
