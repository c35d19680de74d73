//! The maps are checked (issue 37): every workspace crate's `lib.rs` opens with a `//!` Layout,
//! a bullet list whose entries each start with the module they describe, and this test keeps
//! that list and the code in step:
//!
//! - every module declared in `lib.rs` (`pub`, `pub(crate)` or private; not `#[cfg(test)]`) is
//!   named somewhere in the list, as `` [`name`] `` or, for a private module rustdoc cannot
//!   link, as `` `name` `` (a deeper path such as `` [`commands::fit`] `` names it too);
//! - every entry's first code span is a module of the crate (`` - [`room`]: ... ``,
//!   `` - [`commands::fit`]: ... ``), never a module that is gone or a type;
//! - an entry one level down (`commands::fit`) means the list walks that parent's children, so
//!   each of the parent's modules is named in it;
//! - a file the crate docs name (`` `client/tests/house_rules.rs` ``) exists.
//!
//! The crates are the workspace's members, read from the root `Cargo.toml`.

use crate::source_scan;

use std::collections::BTreeSet;

use source_scan::{relative, repo, rust_files, workspace_members};

/// A module path from the crate root, `a::b`.
type ModPath = String;

/// What a crate's `lib.rs` says and declares.
#[derive(Debug, Default)]
struct Crate {
    /// The `//!` lines, the `//!` and one space taken off.
    doc: Vec<String>,
    /// The modules `lib.rs` declares (`mod x;` or an inline `mod x {`), test modules left out.
    root_modules: BTreeSet<String>,
    /// Every module path of the crate: the root's, then one per file below `src/`.
    modules: BTreeSet<ModPath>,
}

/// Reads `lib.rs` (`text`) and the module files below `src` (`files`, relative paths).
fn read_crate(text: &str, files: &[String]) -> Crate {
    let mut c = Crate::default();
    let mut after_cfg_test = false;
    for line in text.lines() {
        let t = line.trim();
        if let Some(d) = t.strip_prefix("//!") {
            c.doc.push(d.strip_prefix(' ').unwrap_or(d).to_owned());
            continue;
        }
        if t.starts_with("#[cfg(test)]") {
            after_cfg_test = true;
            continue;
        }
        // A declaration starts the line (no indentation: inline modules' own children are
        // files' business, and `lib.rs` keeps its declarations at the top level).
        let decl = line
            .strip_prefix("pub(crate) mod ")
            .or_else(|| line.strip_prefix("pub mod "))
            .or_else(|| line.strip_prefix("mod "));
        if let Some(rest) = decl {
            let name: String = rest
                .chars()
                .take_while(|ch| ch.is_ascii_alphanumeric() || *ch == '_')
                .collect();
            if !after_cfg_test && !name.is_empty() {
                c.root_modules.insert(name);
            }
        }
        if !t.starts_with("#[") && !t.is_empty() {
            after_cfg_test = false;
        }
    }
    c.modules.extend(c.root_modules.iter().cloned());
    for f in files {
        let mut parts: Vec<&str> = f.split('/').collect();
        let Some(last) = parts.pop() else { continue };
        if parts.first() == Some(&"bin") {
            continue;
        }
        match last {
            "lib.rs" | "main.rs" if parts.is_empty() => continue,
            "mod.rs" => {}
            name => match name.strip_suffix(".rs") {
                Some(stem) => parts.push(stem),
                None => continue,
            },
        }
        if !parts.is_empty() {
            c.modules.insert(parts.join("::"));
        }
    }
    c
}

/// The code spans of `text` (`` `x` `` and `` [`x`] `` alike), in order.
fn code_spans(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(|s| s.trim().trim_end_matches("()").to_owned())
        .collect()
}

/// The Layout's entries: each bullet (`- ...` and its indented continuation lines) as one
/// string.
fn entries(doc: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut open = false;
    for line in doc {
        if let Some(rest) = line.strip_prefix("- ") {
            out.push(rest.to_owned());
            open = true;
        } else if open && line.starts_with("  ") {
            let last = out.last_mut().unwrap();
            last.push(' ');
            last.push_str(line.trim());
        } else {
            open = false;
        }
    }
    out
}

/// What is wrong with one crate's Layout (empty: nothing), `name` its folder.
fn layout_errors(name: &str, c: &Crate, exists: impl Fn(&str) -> bool) -> Vec<String> {
    let mut errors = Vec::new();
    let entries = entries(&c.doc);
    if entries.is_empty() {
        errors.push(format!(
            "{name}/src/lib.rs: no Layout (a `//! - [`module`]: ...` list)"
        ));
    }
    // Every code span that is a module path, and every prefix of one.
    let mut named: BTreeSet<ModPath> = BTreeSet::new();
    let mut walked_parents: BTreeSet<ModPath> = BTreeSet::new();
    for entry in &entries {
        let spans = code_spans(entry);
        match spans.first() {
            Some(first) if c.modules.contains(first) => {
                if let Some((parent, _)) = first.rsplit_once("::") {
                    walked_parents.insert(parent.to_owned());
                }
            }
            first => errors.push(format!(
                "{name}/src/lib.rs Layout: the entry \"- {}\" starts with {first:?}, which is \
                 no module of the crate (modules: {:?})",
                entry.chars().take(60).collect::<String>(),
                c.modules
            )),
        }
        for span in spans {
            let segments: Vec<&str> = span.split("::").collect();
            for k in 1..=segments.len() {
                let prefix = segments[..k].join("::");
                if c.modules.contains(&prefix) {
                    named.insert(prefix);
                }
            }
        }
    }
    for m in &c.root_modules {
        if !named.contains(m) {
            errors.push(format!(
                "{name}/src/lib.rs: module `{m}` is declared but the Layout does not name it"
            ));
        }
    }
    for parent in &walked_parents {
        let prefix = format!("{parent}::");
        for m in &c.modules {
            let child = m
                .strip_prefix(&prefix)
                .is_some_and(|rest| !rest.contains("::"));
            if child && !named.contains(m) {
                errors.push(format!(
                    "{name}/src/lib.rs: the Layout lists the modules of `{parent}` but not `{m}`"
                ));
            }
        }
    }
    for span in code_spans(&c.doc.join("\n")) {
        let looks_like_file = span.contains('/')
            && !span.contains(' ')
            && [".rs", ".md", ".toml", ".proto", ".sh"]
                .iter()
                .any(|x| span.ends_with(x));
        if looks_like_file && !exists(&span) {
            errors.push(format!(
                "{name}/src/lib.rs: the docs name `{span}`, which is neither in {name}/ nor in \
                 the repository root"
            ));
        }
    }
    errors
}

#[test]
fn every_crate_layout_names_its_modules_and_only_its_modules() {
    let root = repo();
    let mut errors = Vec::new();
    let mut checked = 0;
    for name in workspace_members(&root) {
        let src = root.join(&name).join("src");
        let Ok(lib) = std::fs::read_to_string(src.join("lib.rs")) else {
            continue;
        };
        let mut paths = Vec::new();
        rust_files(&src, &mut paths);
        let files: Vec<String> = paths.iter().map(|p| relative(&src, p)).collect();
        let c = read_crate(&lib, &files);
        let crate_dir = root.join(&name);
        errors.extend(layout_errors(&name, &c, |f| {
            crate_dir.join(f).exists() || root.join(f).exists()
        }));
        checked += 1;
    }
    assert!(checked >= 8, "only {checked} crates with a lib.rs found");
    assert!(
        errors.is_empty(),
        "the Layouts in lib.rs do not match the modules:\n  {}",
        errors.join("\n  ")
    );
}

/// A crate of one `lib.rs` and module files, for the checks below.
fn fake(lib: &str, files: &[&str]) -> Crate {
    let files: Vec<String> = files.iter().map(|f| (*f).to_owned()).collect();
    read_crate(lib, &files)
}

#[test]
fn a_module_missing_from_the_layout_and_an_entry_with_no_module_are_named() {
    let c = fake(
        "//! Layout:\n\
         //! - [`room`]: a live room, with its\n\
         //!   [`session`] (continued on the next line).\n\
         //! - [`gone`]: a module that was removed.\n\
         //! - [`Thing`]: a type where a module belongs.\n\
         pub mod room;\npub mod session;\npub(crate) mod mailbox;\n\
         #[cfg(test)]\nmod tests;\n",
        &["room.rs", "session.rs", "mailbox.rs", "tests.rs"],
    );
    let errors = layout_errors("server", &c, |_| true);
    assert_eq!(errors.len(), 3, "{errors:#?}");
    assert!(
        errors[0].contains("starts with Some(\"gone\")"),
        "{}",
        errors[0]
    );
    assert!(
        errors[1].contains("starts with Some(\"Thing\")"),
        "{}",
        errors[1]
    );
    assert!(errors[2].contains("module `mailbox`"), "{}", errors[2]);
}

#[test]
fn a_layout_one_level_down_names_every_child_and_private_modules_count_unlinked() {
    let lib = "//! Layout:\n\
               //! - [`commands::fit`]: crease fit.\n\
               //! - [`commands::train`]: crease train.\n\
               //! - `secret`: private, so not a link.\n\
               pub mod commands;\nmod secret;\n";
    let files = [
        "commands/mod.rs",
        "commands/fit.rs",
        "commands/train.rs",
        "commands/bridge/mod.rs",
        "commands/bridge/vmc.rs",
        "secret.rs",
    ];
    let errors = layout_errors("client", &fake(lib, &files), |_| true);
    // bridge is missing; bridge::vmc is not (the list walks commands' children only).
    assert_eq!(
        errors,
        [
            "client/src/lib.rs: the Layout lists the modules of `commands` but not \
          `commands::bridge`"
        ]
    );
    let complete = lib.replace(
        "pub mod commands;",
        "//! - [`commands::bridge`]: the bridges.\npub mod commands;",
    );
    assert!(layout_errors("client", &fake(&complete, &files), |_| true).is_empty());
}

#[test]
fn a_file_the_docs_name_must_exist() {
    let c = fake(
        "//! Checked by `tests/dependency_rules.rs` and `client/tests/house_rules.rs`.\n\
         //! - [`a`]: a.\npub mod a;\n",
        &["a.rs"],
    );
    let errors = layout_errors("core", &c, |f| f == "client/tests/house_rules.rs");
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert!(
        errors[0].contains("`tests/dependency_rules.rs`"),
        "{}",
        errors[0]
    );
}
