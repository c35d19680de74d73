//! What the house-rule tests share (`house_rules.rs`, `module_cycles.rs`, `wire_shapes.rs`,
//! `layouts.rs`): the workspace's members and files, and a source scanner: Rust source as
//! tokens, with comments, strings and char literals dropped, and the `#[cfg(test)]` module
//! blocks taken out. A text scan, no parser: enough to follow paths and braces.
#![allow(dead_code)] // each test binary uses its own part

use std::path::{Path, PathBuf};

/// A token of the stripped source: an identifier or keyword, or one punctuation mark (`::` is
/// one token).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Tok {
    Ident(String),
    Punct(&'static str),
    Other,
}

/// Tokens of `src` with comments, strings and char literals dropped.
pub(crate) fn tokens(src: &str) -> Vec<Tok> {
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
        } else if (c == b'-' || c == b'=') && b.get(i + 1) == Some(&b'>') {
            out.push(Tok::Punct(if c == b'-' { "->" } else { "=>" }));
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
                b'=' => Tok::Punct("="),
                b'|' => Tok::Punct("|"),
                b'&' => Tok::Punct("&"),
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
pub(crate) fn matching_brace(toks: &[Tok], open: usize) -> usize {
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
pub(crate) fn drop_test_modules(toks: Vec<Tok>) -> Vec<Tok> {
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

/// Every path in `toks` from `i` on that continues a path prefix: `a::b::c`, groups
/// `a::{b, c::d}` expanded. Returns the paths (identifiers after the prefix) and the index
/// after the path.
pub(crate) fn paths_from(toks: &[Tok], mut i: usize) -> (Vec<Vec<String>>, usize) {
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

/// The repository's root (the workspace), from this crate's manifest folder.
pub(crate) fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("client/ sits in the workspace root")
        .to_path_buf()
}

/// The workspace's member folders, read from the root `Cargo.toml`'s `members = [...]`.
pub(crate) fn workspace_members(root: &Path) -> Vec<String> {
    let manifest = root.join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest)
        .unwrap_or_else(|e| panic!("reading {}: {e}", manifest.display()));
    let list = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("members = ["))
        .unwrap_or_else(|| panic!("{}: no `members = [...]` line", manifest.display()));
    let members: Vec<String> = list
        .split('"')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect();
    assert!(
        members.len() >= 8,
        "{}: expected the workspace's members, got {members:?}",
        manifest.display()
    );
    members
}

/// Every `.rs` file under `dir`, appended to `out`.
pub(crate) fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
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

/// `path` relative to `root`, `/`-separated.
pub(crate) fn relative(root: &Path, path: &Path) -> String {
    let parts: Vec<String> = path
        .strip_prefix(root)
        .expect("a path below the root")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    parts.join("/")
}
