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
//! ancestor or descendant is no edge (a child using its parent is the usual Rust layering).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates checked, by folder under the workspace root.
const CRATES: [&str; 9] = [
    "core", "hand", "mocap", "train", "proto", "server", "demo", "client", "testkit",
];

/// Cycles found and not yet broken, each with why it is still here. The test fails on any
/// other cycle, and on one of these once it is gone (so the list only shrinks).
const KNOWN_CYCLES: [(&str, &str); 0] = [];

/// A module path from the crate root (`[]` is the root).
type ModPath = Vec<String>;

/// A token of the stripped source: an identifier or keyword, or one punctuation mark (`::` is
/// one token).
#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    Punct(&'static str),
    Other,
}

/// Tokens of `src` with comments, strings and char literals dropped.
fn tokens(src: &str) -> Vec<Tok> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if c == b'/' && b.get(i + 1) == Some(&b'*') {
            // Block comments nest in Rust.
            let mut depth = 0;
            while i < b.len() {
                if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == b'*' && b.get(i + 1) == Some(&b'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if c == b'"' {
            i = skip_string(b, i + 1);
        } else if (c == b'r' || c == b'b')
            && let Some(end) = raw_or_byte_string(b, i)
        {
            i = end;
        } else if c == b'\'' {
            // A char literal ('x', '\n', '\u{1F600}') or a lifetime ('a): a lifetime has no
            // closing quote right after its first character.
            if b.get(i + 1) == Some(&b'\\') {
                i += 2;
                while i < b.len() && b[i] != b'\'' {
                    i += 1;
                }
                i += 1;
            } else {
                let ch = src[i + 1..].chars().next().map_or(1, char::len_utf8);
                if b.get(i + 1 + ch) == Some(&b'\'') {
                    i += ch + 2;
                } else {
                    i += 1;
                }
            }
            out.push(Tok::Other);
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Tok::Ident(src[start..i].to_owned()));
        } else if c == b':' && b.get(i + 1) == Some(&b':') {
            out.push(Tok::Punct("::"));
            i += 2;
        } else {
            out.push(match c {
                b'{' => Tok::Punct("{"),
                b'}' => Tok::Punct("}"),
                b',' => Tok::Punct(","),
                b'#' => Tok::Punct("#"),
                b'[' => Tok::Punct("["),
                b']' => Tok::Punct("]"),
                b'(' => Tok::Punct("("),
                b')' => Tok::Punct(")"),
                b';' => Tok::Punct(";"),
                b'*' => Tok::Punct("*"),
                _ if c.is_ascii_whitespace() => {
                    i += 1;
                    continue;
                }
                _ => Tok::Other,
            });
            i += 1;
        }
    }
    out
}

/// The index after the closing quote of a string whose body starts at `i`.
fn skip_string(b: &[u8], mut i: usize) -> usize {
    while i < b.len() {
        match b[i] {
            b'\\' => i += 2,
            b'"' => return i + 1,
            _ => i += 1,
        }
    }
    i
}

/// The end of a raw or byte string starting at `i` (`r"..."`, `r#"..."#`, `b"..."`,
/// `br#"..."#`), `None` when `i` starts an identifier instead.
fn raw_or_byte_string(b: &[u8], i: usize) -> Option<usize> {
    if i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_') {
        return None;
    }
    let mut j = i;
    if b[j] == b'b' {
        j += 1;
        if b.get(j) == Some(&b'"') {
            return Some(skip_string(b, j + 1));
        }
    }
    if b.get(j) != Some(&b'r') {
        return None;
    }
    j += 1;
    let hashes = b[j..].iter().take_while(|&&c| c == b'#').count();
    j += hashes;
    if b.get(j) != Some(&b'"') {
        return None;
    }
    j += 1;
    while j < b.len() {
        if b[j] == b'"'
            && b[j + 1..]
                .iter()
                .take(hashes)
                .filter(|&&c| c == b'#')
                .count()
                == hashes
        {
            return Some(j + 1 + hashes);
        }
        j += 1;
    }
    Some(j)
}

/// The index after the `}` matching the `{` at `open`.
fn matching_brace(toks: &[Tok], open: usize) -> usize {
    let mut depth = 0;
    for (k, t) in toks.iter().enumerate().skip(open) {
        match t {
            Tok::Punct("{") => depth += 1,
            Tok::Punct("}") => {
                depth -= 1;
                if depth == 0 {
                    return k + 1;
                }
            }
            _ => {}
        }
    }
    toks.len()
}

/// `toks` without the items marked `#[cfg(test)]` that are `mod` blocks (the unit tests).
fn drop_test_modules(toks: Vec<Tok>) -> Vec<Tok> {
    let cfg_test = [
        Tok::Punct("#"),
        Tok::Punct("["),
        Tok::Ident("cfg".into()),
        Tok::Punct("("),
        Tok::Ident("test".into()),
        Tok::Punct(")"),
        Tok::Punct("]"),
    ];
    let mut out = Vec::with_capacity(toks.len());
    let mut i = 0;
    while i < toks.len() {
        if toks[i..].starts_with(&cfg_test) {
            // Skip further attributes, then `mod name {...}` (or `mod name;`) goes.
            let mut j = i + cfg_test.len();
            while toks.get(j) == Some(&Tok::Punct("#")) {
                j = toks[j..]
                    .iter()
                    .position(|t| *t == Tok::Punct("]"))
                    .map_or(toks.len(), |k| j + k + 1);
            }
            if toks.get(j) == Some(&Tok::Ident("pub".into())) {
                j += 1;
            }
            if toks.get(j) == Some(&Tok::Ident("mod".into())) {
                match toks.get(j + 2) {
                    Some(Tok::Punct("{")) => {
                        i = matching_brace(&toks, j + 2);
                        continue;
                    }
                    Some(Tok::Punct(";")) => {
                        i = j + 3;
                        continue;
                    }
                    _ => {}
                }
            }
        }
        out.push(toks[i].clone());
        i += 1;
    }
    out
}

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

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let path = e.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|x| x == "rs") {
            out.push(path);
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

/// Every path in `toks` from `i` on that continues a path prefix: `a::b::c`, groups
/// `a::{b, c::d}` expanded. Returns the paths (identifiers after the prefix) and the index
/// after the path.
fn paths_from(toks: &[Tok], mut i: usize) -> (Vec<Vec<String>>, usize) {
    let mut path = Vec::new();
    loop {
        match toks.get(i) {
            Some(Tok::Ident(s)) => {
                path.push(s.clone());
                i += 1;
            }
            Some(Tok::Punct("{")) => {
                let mut all = Vec::new();
                i += 1;
                loop {
                    match toks.get(i) {
                        Some(Tok::Punct("}")) | None => {
                            i += 1;
                            break;
                        }
                        Some(Tok::Punct(",")) => i += 1,
                        _ => {
                            let (inner, next) = paths_from(toks, i);
                            for p in inner {
                                all.push(path.iter().cloned().chain(p).collect());
                            }
                            // Skip what the inner path did not take (`as x`, `*`).
                            i = next;
                            while !matches!(
                                toks.get(i),
                                Some(Tok::Punct(",") | Tok::Punct("}")) | None
                            ) {
                                i += 1;
                            }
                        }
                    }
                }
                return (all, i);
            }
            _ => return (vec![path], i),
        }
        if toks.get(i) == Some(&Tok::Punct("::")) {
            i += 1;
        } else {
            return (vec![path], i);
        }
    }
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
    raw.into_iter()
        .map(|(from, mut to)| {
            // The deepest module the path names (the rest are items in it).
            while !to.is_empty() && !known.contains(&to) {
                to.pop();
            }
            (from, to)
        })
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
    for name in CRATES {
        let src = root.join(name).join("src");
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
