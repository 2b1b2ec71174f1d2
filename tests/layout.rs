//! The source tree's layout rules: no library source file over 800 lines
//! (unit tests in a sibling `tests.rs` aside), and no import cycle between
//! sibling modules of any crate.
//!
//! A module's imports are the `crate::` and `super::` paths its code (not
//! its comments or unit tests) names, whole: the deepest module each
//! names. A path to a name the crate root
//! re-exports counts as a path to the module the name comes from. An import
//! from inside sibling `a` into sibling `b` (or anything inside `b`) is an
//! edge `a -> b`; a child naming its parent's items is not an edge, but a
//! child that imports all of them (`use super::*;`) gets every sibling
//! the parent imports from (`use b::...;`, glob or not): an edge to each.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Module = Vec<String>;

const MAX_LINES: usize = 800;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every crate's source directory and root file.
fn crates() -> Vec<(PathBuf, PathBuf)> {
    // The programs' shared code; `main.rs` and `bin/` are programs of their
    // own on top of it.
    let mut out = vec![(root().join("src"), root().join("src/lib.rs"))];
    for e in std::fs::read_dir(root().join("crates")).unwrap() {
        let src = e.unwrap().path().join("src");
        if src.join("lib.rs").exists() {
            out.push((src.clone(), src.join("lib.rs")));
        }
    }
    out.sort();
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p == root().join("src/main.rs") || p == root().join("src/bin") {
            continue;
        }
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `src/a/b.rs` and `src/a/b/mod.rs` are module `a::b`; the root is `[]`.
fn module_of(src: &Path, file: &Path) -> Module {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut m: Module = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(m.last().map(String::as_str), Some("mod" | "lib" | "main")) {
        m.pop();
    }
    m
}

/// The code of a file without comments, string contents aside, and without
/// an inline `#[cfg(test)] mod tests { ... }` at its end.
fn code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &text[..i],
        None => text,
    };
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Every whole path that follows `prefix` (`crate::` or `super::`), its
/// segments, looking into `{a, b::{c, d}}` groups at any depth:
/// `crate::m::{x::X, y}` gives `[m, x, X]` and `[m, y]`.
fn paths_after(code: &str, prefix: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find(prefix) {
        let before_ok = i == 0 || !rest[..i].ends_with(is_ident);
        rest = &rest[i + prefix.len()..];
        if before_ok {
            use_tree(rest, Vec::new(), &mut out);
        }
    }
    out
}

/// The paths of the use tree `text` begins with, each after `head`.
fn use_tree(text: &str, head: Vec<String>, out: &mut Vec<Vec<String>>) {
    let text = text.trim_start();
    if let Some(group) = text.strip_prefix('{') {
        // The group's parts, split at its top-level commas.
        let (mut depth, mut start) = (0usize, 0usize);
        for (i, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    use_tree(&group[start..i], head.clone(), out);
                    return;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    use_tree(&group[start..i], head.clone(), out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        return;
    }
    let name: String = text.chars().take_while(|&c| is_ident(c)).collect();
    if name.is_empty() {
        if !head.is_empty() {
            out.push(head);
        }
        return;
    }
    let mut path = head;
    path.push(name.clone());
    match text[name.len()..].strip_prefix("::") {
        Some(more) => use_tree(more, path, out),
        None => out.push(path),
    }
}

/// The longest prefix of `path` (after `base`) that is one of `modules`.
fn module_in(
    modules: &BTreeMap<Module, PathBuf>,
    base: &[String],
    path: &[String],
) -> Option<Module> {
    (1..=path.len()).rev().find_map(|n| {
        let mut m = base.to_vec();
        m.extend_from_slice(&path[..n]);
        modules.contains_key(&m).then_some(m)
    })
}

/// The names the crate root re-exports (`pub use m::{A, B};`), by module.
fn reexports(root_code: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for stmt in root_code.split(';') {
        let Some(i) = stmt.find("pub use ") else {
            continue;
        };
        let path = stmt[i + "pub use ".len()..].trim();
        let Some((module, names)) = path.split_once("::") else {
            continue;
        };
        if !module.chars().all(is_ident) {
            continue;
        }
        for name in names
            .split(|c: char| !is_ident(c))
            .filter(|n| !n.is_empty())
        {
            out.insert(name.to_string(), module.to_string());
        }
    }
    out
}

/// Whether the code imports all of its parent's names: `use super::*;`.
fn globs_parent(code: &str) -> bool {
    code.split(';').any(|stmt| {
        let t: String = stmt.split_whitespace().collect();
        t.ends_with("usesuper::*")
    })
}

/// The first segments of the module's own `use` paths (`use a::B;`, `pub use
/// self::a::*;`, `use {a::B, c::D};`), not those through `crate::` or
/// `super::`: the child modules (or crates) it imports from.
fn imported_modules(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for stmt in code.split(';') {
        let t = stmt.trim_start();
        let t = t.strip_prefix("pub(crate) ").unwrap_or(t);
        let t = t.strip_prefix("pub(super) ").unwrap_or(t);
        let t = t.strip_prefix("pub ").unwrap_or(t);
        let Some(path) = t.strip_prefix("use ") else {
            continue;
        };
        let path = path.trim().strip_prefix("self::").unwrap_or(path.trim());
        let parts: Vec<&str> = match path.strip_prefix('{') {
            Some(group) => group.split(',').collect(),
            None => vec![path],
        };
        for part in parts {
            let part = part.trim();
            let part = part.strip_prefix("self::").unwrap_or(part);
            if part.starts_with("crate::") || part.starts_with("super::") {
                continue;
            }
            let name: String = part.chars().take_while(|&c| is_ident(c)).collect();
            if !name.is_empty() && part[name.len()..].starts_with("::") {
                out.insert(name);
            }
        }
    }
    out
}

/// Edges between siblings: `(parent, a) -> (parent, b)`.
fn sibling_edges(src: &Path, root_file: &Path) -> BTreeMap<Module, BTreeSet<Module>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeMap<Module, PathBuf> = files
        .iter()
        .map(|f| (module_of(src, f), f.clone()))
        .collect();
    let exported = reexports(&code(&std::fs::read_to_string(root_file).unwrap()));
    let mut edges: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for (m, file) in &modules {
        if m.is_empty() || m.last().is_some_and(|n| n == "tests") {
            continue;
        }
        let c = code(&std::fs::read_to_string(file).unwrap());
        let mut targets: BTreeSet<Module> = BTreeSet::new();
        for path in paths_after(&c, "crate::") {
            if let Some(t) = module_in(&modules, &[], &path) {
                targets.insert(t);
            } else if let Some(module) = exported.get(&path[0]) {
                targets.insert(vec![module.clone()]);
            }
        }
        let parent = &m[..m.len() - 1];
        if globs_parent(&c) {
            let parent_file = &modules[&parent.to_vec()];
            let parent_code = code(&std::fs::read_to_string(parent_file).unwrap());
            for name in imported_modules(&parent_code) {
                let mut sibling = parent.to_vec();
                sibling.push(name);
                if modules.contains_key(&sibling) && &sibling != m {
                    targets.insert(sibling);
                }
            }
        }
        for path in paths_after(&c, "super::") {
            if let Some(t) = module_in(&modules, parent, &path) {
                targets.insert(t);
            }
        }
        for t in targets {
            let common = m.iter().zip(&t).take_while(|(a, b)| a == b).count();
            if common >= m.len() || common >= t.len() {
                continue; // an ancestor or a descendant
            }
            edges
                .entry(m[..=common].to_vec())
                .or_default()
                .insert(t[..=common].to_vec());
        }
    }
    edges
}

/// A cycle through `start`, if any: the path back to it.
fn cycle_from(edges: &BTreeMap<Module, BTreeSet<Module>>, start: &Module) -> Option<Vec<Module>> {
    let mut stack = vec![(start.clone(), vec![start.clone()])];
    let mut seen = BTreeSet::new();
    while let Some((at, path)) = stack.pop() {
        for next in edges.get(&at).into_iter().flatten() {
            if next == start {
                return Some(path.clone());
            }
            if seen.insert(next.clone()) {
                let mut p = path.clone();
                p.push(next.clone());
                stack.push((next.clone(), p));
            }
        }
    }
    None
}

#[test]
fn no_import_cycles_between_sibling_modules() {
    let mut cycles = Vec::new();
    for (src, root_file) in crates() {
        let edges = sibling_edges(&src, &root_file);
        for m in edges.keys() {
            if let Some(c) = cycle_from(&edges, m) {
                let names: Vec<String> = c.iter().map(|m| m.join("::")).collect();
                cycles.push(format!("{}: {}", src.display(), names.join(" -> ")));
            }
        }
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

#[test]
fn the_checker_sees_a_cycle() {
    // Two modules naming each other, one through a root re-export.
    let dir = std::env::temp_dir().join(format!("wisplight-layout-{}", std::process::id()));
    let src = dir.join("src");
    std::fs::create_dir_all(&src).unwrap();
    std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\npub use b::B;\n").unwrap();
    std::fs::write(src.join("a.rs"), "use crate::B;\npub struct A;\n").unwrap();
    std::fs::write(
        src.join("b.rs"),
        "// crate::c in a comment\npub struct B(crate::a::A);\n",
    )
    .unwrap();
    let edges = sibling_edges(&src, &src.join("lib.rs"));
    let a = vec!["a".to_string()];
    assert_eq!(
        cycle_from(&edges, &a),
        Some(vec![a.clone(), vec!["b".to_string()]])
    );
    std::fs::write(src.join("b.rs"), "pub struct B;\n").unwrap();
    assert_eq!(
        cycle_from(&sibling_edges(&src, &src.join("lib.rs")), &a),
        None
    );
    // A cycle hidden by glob imports: the parent imports both children's
    // items, and each child imports all of the parent's.
    let m = src.join("m");
    std::fs::create_dir_all(&m).unwrap();
    std::fs::write(src.join("lib.rs"), "mod m;\n").unwrap();
    std::fs::write(
        m.join("mod.rs"),
        "mod x;\nmod y;\nuse x::*;\nuse y::{Y, y_too};\n",
    )
    .unwrap();
    std::fs::write(m.join("x.rs"), "use super::*;\npub struct X(Y);\n").unwrap();
    std::fs::write(m.join("y.rs"), "use super::*;\npub struct Y(X);\n").unwrap();
    let x = vec!["m".to_string(), "x".to_string()];
    let y = vec!["m".to_string(), "y".to_string()];
    assert_eq!(
        cycle_from(&sibling_edges(&src, &src.join("lib.rs")), &x),
        Some(vec![x.clone(), y.clone()])
    );
    // A child that names what it takes breaks it.
    std::fs::write(m.join("y.rs"), "pub struct Y;\n").unwrap();
    assert_eq!(
        cycle_from(&sibling_edges(&src, &src.join("lib.rs")), &x),
        None
    );
    // A cycle through whole paths: each child names the other's item by
    // its path from the crate's root, through groups.
    std::fs::write(m.join("mod.rs"), "mod x;\nmod y;\n").unwrap();
    std::fs::write(m.join("x.rs"), "use crate::m::y::Y;\npub struct X(Y);\n").unwrap();
    std::fs::write(
        m.join("y.rs"),
        "use crate::{m::{x::X}, other};\npub struct Y(X);\n",
    )
    .unwrap();
    assert_eq!(
        cycle_from(&sibling_edges(&src, &src.join("lib.rs")), &x),
        Some(vec![x.clone(), y.clone()])
    );
    std::fs::write(m.join("y.rs"), "pub struct Y;\n").unwrap();
    assert_eq!(
        cycle_from(&sibling_edges(&src, &src.join("lib.rs")), &x),
        None
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn no_library_source_file_is_over_800_lines() {
    let mut long = Vec::new();
    for (src, _) in crates() {
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        for f in files {
            if f.file_name().is_some_and(|n| n == "tests.rs") {
                continue;
            }
            let lines = std::fs::read_to_string(&f).unwrap().lines().count();
            if lines > MAX_LINES {
                long.push(format!("{} ({lines} lines)", f.display()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "over {MAX_LINES} lines: {}",
        long.join(", ")
    );
}

/// The `.rs` names ARCHITECTURE.md's code map gives under each crate's
/// heading (`### crates/NAME: ...` or `### src: ...`): the source folder,
/// and the names (a path from it, or a bare file name after a path in the
/// same cell, `scene/hair.rs`, `lights.rs`, taken in that folder).
fn code_map() -> Vec<(PathBuf, Vec<String>)> {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let mut out: Vec<(PathBuf, Vec<String>)> = Vec::new();
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("### ") {
            let dir = h.split(':').next().unwrap().trim();
            let src = if dir == "src" {
                root().join("src")
            } else {
                root().join(dir).join("src")
            };
            out.push((src, Vec::new()));
            continue;
        }
        if line.starts_with("## ") && !out.is_empty() {
            break;
        }
        let Some((_, names)) = out.last_mut() else {
            continue;
        };
        // A table row's first cell: a bare name follows the folder of the
        // path before it.
        if !line.starts_with('|') {
            continue;
        }
        if let Some(cell) = line.split('|').nth(1) {
            let mut folder = String::new();
            for span in cell.split('`').skip(1).step_by(2) {
                for word in span.split([',', ' ']) {
                    let word = word.trim();
                    if !word.ends_with(".rs") {
                        continue;
                    }
                    if let Some((dir, _)) = word.rsplit_once('/') {
                        folder = format!("{dir}/");
                        names.push(word.to_string());
                    } else {
                        names.push(format!("{folder}{word}"));
                    }
                }
            }
        }
    }
    out
}

#[test]
fn the_code_map_names_every_source_file_and_only_files_that_exist() {
    let map = code_map();
    assert!(map.len() >= 8, "crate headings found: {}", map.len());
    let (mut missing, mut unnamed) = (Vec::new(), Vec::new());
    for (src, names) in &map {
        for n in names {
            // A crate's build script stands beside its src.
            if !src.join(n).is_file() && !src.join("..").join(n).is_file() {
                missing.push(format!("{}/{n}", src.display()));
            }
        }
        let mut files = Vec::new();
        rust_files(src, &mut files);
        if src == &root().join("src") {
            files.push(root().join("src/main.rs"));
            files.push(root().join("src/bin/wisplight-bench.rs"));
        }
        for f in files {
            let rel = f.strip_prefix(src).unwrap().display().to_string();
            // Unit tests beside the code are named by their module, and a
            // crate's root by its heading.
            if rel.ends_with("tests.rs") || rel.contains("/tests/") || rel == "lib.rs" {
                continue;
            }
            if !names.contains(&rel) {
                unnamed.push(format!("{}/{rel}", src.display()));
            }
        }
    }
    assert!(
        missing.is_empty() && unnamed.is_empty(),
        "ARCHITECTURE.md names files that do not exist: {missing:#?}\nand does not name: {unnamed:#?}"
    );
}
