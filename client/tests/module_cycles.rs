//! No import cycles among a crate's modules (issue 16): for every workspace crate, the modules
//! that share a parent must use each other one way only, so each can be read, tested and moved
//! knowing only what it points at.
//!
//! A text scan, no parser: every `.rs` file under `src/` is a module (`lib.rs` the root,
//! `a.rs` and `a/mod.rs` = `a`, `a/b.rs` = `a::b`), with inline `mod x { ... }` blocks as
//! child modules. Comments, strings and `#[cfg(test)] mod` blocks are dropped; then every path
//! that starts with `crate::`, `super::` or `self::` (in a `use` or in code, `{...}` groups
//! expanded) is an edge from the module it is written in to the deepest known module it names.
//! An edge `a::x -> a::y` is the sibling edge `x -> y` inside `a`; a module using its own
//! ancestor or descendant is no edge (a child using its parent is the usual Rust layering),
//! with one exception: the items written in `lib.rs` itself are a node of their own, the
//! [`ROOT_ITEMS`] (issue 37). A module naming `crate::AppState` has an edge to it, and `lib.rs`
//! naming a module (`use room::Room;`, `crate::cluster::Cluster`) has an edge from it, so an
//! `AppState` in `lib.rs` that holds the cluster while the cluster names `crate::AppState` is a
//! cycle, as it is for a reader. A re-export (`pub use state::AppState;`) is the crate's
//! façade, not a use: elsewhere `crate::AppState` is an edge to `state`.
//!
//! The crates checked are the workspace's members, read from the root `Cargo.toml`.

use crate::source_scan;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use source_scan::{
    Tok, drop_test_modules, matching_brace, paths_from, rust_files, tokens, workspace_members,
};

/// The node that stands for the items written in a crate's `lib.rs` (a name no module can
/// have).
const ROOT_ITEMS: &str = "(crate root)";

/// Cycles found and not yet broken, each with why it is still here. The test fails on any
/// other cycle, and on one of these once it is gone (so the list only shrinks).
const KNOWN_CYCLES: [(&str, &str); 0] = [];

/// A module path from the crate root (`[]` is the root).
type ModPath = Vec<String>;

/// One file's module and its stripped tokens.
struct Source {
    module: ModPath,
    toks: Vec<Tok>,
}

/// The module path of `file` (under `src`), `None` for files that are no module of the library
/// (a binary's `main.rs` beside a `lib.rs`, `src/bin/`).
fn module_of(src: &Path, file: &Path, has_lib: bool) -> Option<ModPath> {
    let rel = file.strip_prefix(src).ok()?;
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop()?;
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    match last.as_str() {
        "lib.rs" if parts.is_empty() => Some(parts),
        "main.rs" if parts.is_empty() => (!has_lib).then_some(parts),
        "mod.rs" => Some(parts),
        name => {
            parts.push(name.strip_suffix(".rs")?.to_owned());
            Some(parts)
        }
    }
}

/// The sources of a crate: `(file module, file contents)` pairs, read from `src`.
fn read_crate(src: &Path) -> Vec<(ModPath, String)> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    files.sort();
    let has_lib = src.join("lib.rs").is_file();
    files
        .iter()
        .filter_map(|f| {
            let module = module_of(src, f, has_lib)?;
            let text = std::fs::read_to_string(f)
                .unwrap_or_else(|e| panic!("reading {}: {e}", f.display()));
            Some((module, text))
        })
        .collect()
}

/// The module edges `(from, to)` of one crate's sources (to: the deepest known module a path
/// names).
fn edges(sources: &[(ModPath, String)]) -> BTreeSet<(ModPath, ModPath)> {
    let parsed: Vec<Source> = sources
        .iter()
        .map(|(module, text)| Source {
            module: module.clone(),
            toks: drop_test_modules(tokens(text)),
        })
        .collect();
    // Known modules: the files, and inline `mod x {` blocks (found with their nesting below).
    let mut known: BTreeSet<ModPath> = parsed.iter().map(|s| s.module.clone()).collect();
    let mut raw: Vec<(ModPath, ModPath)> = Vec::new();
    // `pub use` in lib.rs: the name it re-exports at the root -> the path it stands for.
    let mut reexports: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for s in &parsed {
        // The module each token is in: the file's, deeper inside inline `mod x { ... }`.
        let mut stack: Vec<(ModPath, usize)> = vec![(s.module.clone(), s.toks.len())];
        let mut i = 0;
        while i < s.toks.len() {
            while stack.len() > 1 && stack.last().is_some_and(|(_, end)| i >= *end) {
                stack.pop();
            }
            let here = stack.last().map(|(m, _)| m.clone()).unwrap_or_default();
            if let (Some(Tok::Ident(m)), Some(Tok::Ident(name)), Some(Tok::Punct("{"))) =
                (s.toks.get(i), s.toks.get(i + 1), s.toks.get(i + 2))
                && m == "mod"
            {
                let mut inner = here.clone();
                inner.push(name.clone());
                known.insert(inner.clone());
                stack.push((inner, matching_brace(&s.toks, i + 2)));
                i += 3;
                continue;
            }
            // A re-export in `lib.rs` (`pub use state::AppState;`) is the crate's façade, not
            // a use by the root's items: `crate::AppState` elsewhere names `state`.
            if here.is_empty()
                && s.toks[i] == Tok::Ident("use".into())
                && i > 0
                && matches!(&s.toks[i - 1], Tok::Ident(k) if k == "pub")
                    | (s.toks[i - 1] == Tok::Punct(")"))
            {
                let (paths, next) = paths_from(&s.toks, i + 1);
                for mut p in paths {
                    if p.first().is_some_and(|f| f == "crate" || f == "self") {
                        p.remove(0);
                    }
                    if let Some(name) = p.last() {
                        reexports.insert(name.clone(), p.clone());
                    }
                }
                i = next.max(i + 1);
                continue;
            }
            // In `lib.rs` a bare path may start at a module of the root (`use room::Room;`).
            if here.is_empty()
                && let Tok::Ident(name) = &s.toks[i]
                && (i == 0 || s.toks[i - 1] != Tok::Punct("::"))
                && s.toks.get(i + 1) == Some(&Tok::Punct("::"))
                && known.contains(&vec![name.clone()])
            {
                let (paths, next) = paths_from(&s.toks, i);
                for p in paths {
                    raw.push((Vec::new(), p));
                }
                i = next.max(i + 1);
                continue;
            }
            let start = match &s.toks[i] {
                Tok::Ident(k) if k == "crate" => Some(Vec::new()),
                Tok::Ident(k) if k == "self" => Some(here.clone()),
                Tok::Ident(k) if k == "super" => {
                    let mut base = here.clone();
                    base.pop();
                    Some(base)
                }
                _ => None,
            };
            // A path's first segment only (not `a::self` of a group, nor `super` after `::`).
            let first = i == 0 || s.toks[i - 1] != Tok::Punct("::");
            let (Some(mut base), true) = (start, first) else {
                i += 1;
                continue;
            };
            if s.toks.get(i + 1) != Some(&Tok::Punct("::")) {
                i += 1;
                continue;
            }
            // `super::super::x`
            let mut j = i + 2;
            while s.toks.get(j) == Some(&Tok::Ident("super".into()))
                && s.toks.get(j + 1) == Some(&Tok::Punct("::"))
            {
                base.pop();
                j += 2;
            }
            let (paths, next) = paths_from(&s.toks, j);
            for p in paths {
                let mut target = base.clone();
                target.extend(p);
                raw.push((here.clone(), target));
            }
            i = next.max(i + 1);
        }
    }
    let root_items = vec![ROOT_ITEMS.to_owned()];
    raw.into_iter()
        .map(|(from, mut to)| {
            // A name the root re-exports stands for its path; a re-exported crate that is
            // not ours is no edge.
            if let Some(path) = to.first().and_then(|n| reexports.get(n)) {
                if !path
                    .first()
                    .is_some_and(|m| known.contains(&vec![m.clone()]))
                {
                    return (from.clone(), from);
                }
                to.splice(..1, path.iter().cloned());
            }
            // The deepest module the path names (the rest are items in it).
            let named_an_item = !to.is_empty() && !known.contains(&to);
            while !to.is_empty() && !known.contains(&to) {
                to.pop();
            }
            // An item of `lib.rs` (not a module) is the root-items node; so is the code of
            // `lib.rs` that names a module.
            if to.is_empty() && named_an_item {
                to = root_items.clone();
            }
            let from = if from.is_empty() {
                root_items.clone()
            } else {
                from
            };
            (from, to)
        })
        .filter(|(from, to)| from != to)
        .collect()
}

/// The sibling graphs: per parent module, `child -> children it uses`.
fn sibling_graphs(
    edges: &BTreeSet<(ModPath, ModPath)>,
) -> BTreeMap<ModPath, BTreeMap<String, BTreeSet<String>>> {
    let mut graphs: BTreeMap<ModPath, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (from, to) in edges {
        let common = from.iter().zip(to).take_while(|(a, b)| a == b).count();
        // An ancestor or descendant: the usual parent/child layering, no edge.
        if common == from.len() || common == to.len() {
            continue;
        }
        graphs
            .entry(from[..common].to_vec())
            .or_default()
            .entry(from[common].clone())
            .or_default()
            .insert(to[common].clone());
    }
    graphs
}

/// The cycles of each sibling graph, one per strongly connected component of more than one
/// module (or a module using itself through a sibling path), written `a::x -> a::y -> a::x`.
fn cycles(edges: &BTreeSet<(ModPath, ModPath)>) -> Vec<String> {
    let mut found = Vec::new();
    for (parent, graph) in sibling_graphs(edges) {
        let prefix: String = parent.iter().map(|p| format!("{p}::")).collect();
        let mut reported: BTreeSet<String> = BTreeSet::new();
        for start in graph.keys() {
            if reported.contains(start) {
                continue;
            }
            // The shortest cycle back to `start`, by breadth-first search.
            let mut came_from: BTreeMap<&str, &str> = BTreeMap::new();
            let mut queue = std::collections::VecDeque::from([start.as_str()]);
            let mut closing = None;
            while let Some(m) = queue.pop_front() {
                for n in graph.get(m).into_iter().flatten() {
                    if n == start {
                        closing = Some(m);
                        break;
                    }
                    if !came_from.contains_key(n.as_str()) {
                        came_from.insert(n, m);
                        queue.push_back(n);
                    }
                }
                if closing.is_some() {
                    break;
                }
            }
            let Some(mut m) = closing else { continue };
            // Back from the module that closes the cycle to `start`, then forwards.
            let mut cycle = vec![m];
            while m != start {
                m = came_from[m];
                cycle.push(m);
            }
            cycle.reverse();
            cycle.push(start.as_str());
            reported.extend(cycle.iter().map(|s| s.to_string()));
            let names: Vec<String> = cycle.iter().map(|c| format!("{prefix}{c}")).collect();
            found.push(names.join(" -> "));
        }
    }
    found
}

#[test]
fn no_import_cycles_in_any_workspace_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut found = Vec::new();
    for name in workspace_members(&root) {
        let src = root.join(&name).join("src");
        let sources = read_crate(&src);
        assert!(!sources.is_empty(), "{}: no sources", src.display());
        for cycle in cycles(&edges(&sources)) {
            found.push(format!("{name}: {cycle}"));
        }
    }
    let known: Vec<&str> = KNOWN_CYCLES.iter().map(|(c, _)| *c).collect();
    let new: Vec<&String> = found
        .iter()
        .filter(|c| !known.contains(&c.as_str()))
        .collect();
    assert!(
        new.is_empty(),
        "import cycles among modules (move the shared pieces into a module both use):\n  {}",
        new.iter()
            .map(|c| c.as_str())
            .collect::<Vec<_>>()
            .join("\n  ")
    );
    for (cycle, why) in KNOWN_CYCLES {
        assert!(
            found.iter().any(|c| c == cycle),
            "{cycle} is gone: remove it from KNOWN_CYCLES ({why})"
        );
    }
}

/// A crate of `(file module, text)` pairs, the module written `a::b`.
fn fake(files: &[(&str, &str)]) -> Vec<(ModPath, String)> {
    files
        .iter()
        .map(|(m, text)| {
            let module = m
                .split("::")
                .filter(|s| !s.is_empty())
                .map(str::to_owned)
                .collect();
            (module, (*text).to_owned())
        })
        .collect()
}

#[test]
fn a_three_module_cycle_is_named() {
    let sources = fake(&[
        ("", "pub mod eval; pub mod pipeline; pub mod select;"),
        ("eval", "use crate::pipeline::{self, TrainInput};"),
        ("pipeline", "use crate::select::{self, Grid};"),
        ("select", "fn f() { crate::eval::rms(); }"),
    ]);
    assert_eq!(
        cycles(&edges(&sources)),
        ["eval -> pipeline -> select -> eval"]
    );
}

#[test]
fn super_paths_resolve_from_the_file_and_nest_inside_a_parent() {
    let sources = fake(&[
        ("", "mod commands;"),
        ("commands", "pub mod eval; pub mod train;"),
        ("commands::eval", "use super::train::RegressArgs;"),
        (
            "commands::train",
            "fn f() -> String { super::eval::kernel_name() }",
        ),
    ]);
    assert_eq!(
        cycles(&edges(&sources)),
        ["commands::eval -> commands::train -> commands::eval"]
    );
}

#[test]
fn parents_children_tests_comments_and_strings_are_no_cycle() {
    let sources = fake(&[
        ("", "pub mod a; pub mod b; use crate::a::Thing;"),
        // A parent using its child and the child its parent.
        ("a", "pub mod inner; use self::inner::X; pub struct Thing;"),
        ("a::inner", "use super::Thing; use crate::a::Thing as T2;"),
        // One way only: b -> a (also through a child of a).
        ("b", "use crate::a::inner::X; fn f() { crate::a::g() }"),
        // a -> b would close a cycle: none in comments, strings, char literals or tests.
        (
            "a::more",
            r##"// crate::b is mentioned in a comment: use crate::b; crate::b::x
            /* and crate::b::y in /* a nested */ block */
            const S: &str = "crate::b::z \" crate::b::q"; const R: &str = r#"crate::b::w"#;
            fn f<'a>(x: &'a str) -> char { '"' }
            fn g() -> char { '\'' }
            #[cfg(test)]
            #[allow(unused)]
            mod tests { use crate::b::Y; }
            pub fn after() {}"##,
        ),
    ]);
    let e = edges(&sources);
    assert!(cycles(&e).is_empty(), "{:?}", cycles(&e));
    assert!(e.contains(&(vec!["b".into()], vec!["a".into(), "inner".into()])));
    // The test block and comments gave no b -> b or a -> b edge.
    assert!(
        !e.iter()
            .any(|(from, to)| from.first().is_some_and(|f| f == "a")
                && to.first().is_some_and(|t| t == "b"))
    );
}

#[test]
fn a_loop_through_the_items_of_lib_rs_is_a_cycle() {
    // AppState written in lib.rs holds the cluster, and the cluster names crate::AppState.
    let sources = fake(&[
        (
            "",
            "pub mod cluster; pub mod room; use room::Room; \
             pub struct AppState { cluster: cluster::Cluster, rooms: Vec<Room> }",
        ),
        ("cluster", "use crate::AppState; pub struct Cluster;"),
        // room names lib.rs's items too, but lib.rs naming room closes its loop as well.
        ("room", "pub struct Room { limits: crate::Limits }"),
    ]);
    let e = edges(&sources);
    assert!(e.contains(&(vec![ROOT_ITEMS.into()], vec!["cluster".into()])));
    assert!(e.contains(&(vec!["cluster".into()], vec![ROOT_ITEMS.into()])));
    let mut found = cycles(&e);
    found.sort();
    assert_eq!(
        found,
        [
            format!("{ROOT_ITEMS} -> cluster -> {ROOT_ITEMS}"),
            format!("room -> {ROOT_ITEMS} -> room"),
        ]
    );

    // The same crate with AppState in a module of its own that the cluster does not name,
    // lib.rs only declaring and re-exporting: no cycle.
    let sources = fake(&[
        (
            "",
            "pub mod cluster; pub mod state; pub use state::AppState;",
        ),
        (
            "state",
            "use crate::cluster::Cluster; pub struct AppState(Cluster);",
        ),
        ("cluster", "pub struct Cluster;"),
    ]);
    let e = edges(&sources);
    assert!(!e.iter().any(|(from, _)| from[0] == ROOT_ITEMS));
    assert!(cycles(&e).is_empty(), "{:?}", cycles(&e));

    // ... but a module naming the re-export through the root names `state`, and closes the
    // loop state -> cluster -> state.
    let sources = fake(&[
        (
            "",
            "pub mod cluster; pub mod state; pub use state::AppState;",
        ),
        (
            "state",
            "use crate::cluster::Cluster; pub struct AppState(Cluster);",
        ),
        (
            "cluster",
            "pub struct Cluster; fn f(s: &crate::AppState) {}",
        ),
    ]);
    assert_eq!(cycles(&edges(&sources)), ["cluster -> state -> cluster"]);
    // A re-exported crate that is not ours is no edge.
    let sources = fake(&[
        (
            "",
            "pub mod mesh; pub use glam; pub struct Model(mesh::Mesh);",
        ),
        ("mesh", "pub struct Mesh(crate::glam::Vec3);"),
    ]);
    assert!(cycles(&edges(&sources)).is_empty());
}

#[test]
fn file_paths_map_to_module_paths() {
    let src = Path::new("/x/src");
    let m = |f: &str, lib| module_of(src, &src.join(f), lib);
    assert_eq!(m("lib.rs", true), Some(vec![]));
    assert_eq!(m("main.rs", true), None);
    assert_eq!(m("main.rs", false), Some(vec![]));
    assert_eq!(m("a.rs", true), Some(vec!["a".to_owned()]));
    assert_eq!(m("a/mod.rs", true), Some(vec!["a".to_owned()]));
    assert_eq!(
        m("a/b.rs", true),
        Some(vec!["a".to_owned(), "b".to_owned()])
    );
    assert_eq!(m("bin/tool.rs", true), None);
}
