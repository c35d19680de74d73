//! The house rules of ARCHITECTURE.md, checked so the map cannot drift from the code:
//!
//! - every crate's normal and build dependencies on crates of ours are among those its row of
//!   the "Crates" table allows (the table is read from ARCHITECTURE.md, the dependencies from
//!   `cargo metadata`);
//! - no dev-dependency of ours depends, transitively, on the crate under test;
//! - `crease-core` does not depend, even transitively, on tokio, tonic, axum or prost;
//! - no library source file (`*/src/**/*.rs`) is over 1,000 lines unless ARCHITECTURE.md's
//!   "Files kept whole" section names it;
//! - the fuzz workspace's own `Cargo.lock` is up to date with the crates it uses.

use crate::source_scan;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::PathBuf;
use std::sync::OnceLock;

use serde_json::Value;
use source_scan::{repo, rust_files};

/// The external crates `crease-core` must never reach (ARCHITECTURE.md, "Rules").
const CORE_NEVER: [&str; 4] = ["tokio", "tonic", "axum", "prost"];
/// Longest library source file the house allows without a stated reason.
const MAX_LINES: usize = 1000;

fn architecture() -> String {
    let path = repo().join("ARCHITECTURE.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The "Crates" table: crate name -> the crates of ours it may depend on.
fn allowed_from_table(doc: &str) -> BTreeMap<String, BTreeSet<String>> {
    let section = doc
        .split("\n## ")
        .find(|s| s.starts_with("Crates"))
        .expect("ARCHITECTURE.md: a \"## Crates\" section");
    let ticked = |cell: &str| -> BTreeSet<String> {
        cell.split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_owned)
            .collect()
    };
    let mut table = BTreeMap::new();
    for (n, line) in section.lines().enumerate() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // | crate | folder | responsibility | may depend on |  -> 6 pieces with the outer empties
        if cells.len() != 6 || !cells[1].starts_with("`crease-") {
            continue;
        }
        let name = ticked(cells[1]).into_iter().next().unwrap();
        let allowed = ticked(cells[4]);
        assert!(
            allowed.iter().all(|a| a.starts_with("crease-")) || cells[4] == "nothing",
            "ARCHITECTURE.md, Crates table line {}: the last column names crates of ours in \
             backticks, or says \"nothing\"; got {:?}",
            n + 1,
            cells[4]
        );
        table.insert(name, allowed);
    }
    assert!(
        table.len() >= 8,
        "ARCHITECTURE.md: expected a row per crate in the Crates table, found {table:?}"
    );
    table
}

/// The host's target triple (`rustc -vV`).
fn host_triple() -> String {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = std::process::Command::new(rustc)
        .arg("-vV")
        .output()
        .expect("rustc -vV runs");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: "))
        .expect("rustc -vV names the host")
        .to_owned()
}

/// `cargo metadata` of the workspace, for this host's platform, read once for all the tests (the rules are about what
/// builds here; other platforms' packages need not be downloaded).
fn metadata() -> &'static Value {
    static META: OnceLock<Value> = OnceLock::new();
    META.get_or_init(read_metadata)
}

/// Runs `cargo metadata` (once per test binary: [`metadata`] keeps it).
fn read_metadata() -> Value {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--locked"])
        .args(["--filter-platform", &host_triple()])
        .current_dir(repo())
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON")
}

/// One dependency edge of a workspace package, as its manifest declares it.
#[derive(Debug)]
struct Edge {
    from: String,
    to: String,
    /// `None` (normal), `Some("dev")` or `Some("build")`.
    kind: Option<String>,
}

fn workspace_edges(meta: &Value) -> (BTreeSet<String>, Vec<Edge>) {
    let members: BTreeSet<&str> = meta["workspace_members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap())
        .collect();
    let mut names = BTreeSet::new();
    let mut edges = Vec::new();
    for p in meta["packages"].as_array().unwrap() {
        if !members.contains(p["id"].as_str().unwrap()) {
            continue;
        }
        let from = p["name"].as_str().unwrap().to_owned();
        for d in p["dependencies"].as_array().unwrap() {
            edges.push(Edge {
                from: from.clone(),
                to: d["name"].as_str().unwrap().to_owned(),
                kind: d["kind"].as_str().map(str::to_owned),
            });
        }
        names.insert(from);
    }
    (names, edges)
}

/// The package names `start` reaches through normal and build dependencies in the resolved
/// graph (not itself).
fn reachable(meta: &Value, start: &str) -> BTreeSet<String> {
    let nodes = meta["resolve"]["nodes"].as_array().unwrap();
    let name_of = |id: &str| -> String {
        meta["packages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["id"] == id)
            .map(|p| p["name"].as_str().unwrap().to_owned())
            .unwrap()
    };
    let by_id: BTreeMap<&str, &Value> = nodes
        .iter()
        .map(|n| (n["id"].as_str().unwrap(), n))
        .collect();
    let start_id = by_id
        .keys()
        .find(|id| name_of(id) == start)
        .copied()
        .unwrap_or_else(|| panic!("{start} is not in the resolved graph"));
    let mut seen = BTreeSet::new();
    let mut queue = VecDeque::from([start_id]);
    while let Some(id) = queue.pop_front() {
        for d in by_id[id]["deps"].as_array().unwrap() {
            let runtime = d["dep_kinds"]
                .as_array()
                .unwrap()
                .iter()
                .any(|k| k["kind"].is_null() || k["kind"] == "build");
            let pkg = d["pkg"].as_str().unwrap();
            if runtime && seen.insert(pkg) {
                queue.push_back(pkg);
            }
        }
    }
    seen.into_iter().map(name_of).collect()
}

/// The violations of the table by the declared edges (separate from the test so the test of
/// the checker can feed it a forbidden edge).
fn table_violations(
    table: &BTreeMap<String, BTreeSet<String>>,
    ours: &BTreeSet<String>,
    edges: &[Edge],
) -> Vec<String> {
    let mut bad = Vec::new();
    for e in edges {
        if !ours.contains(&e.to) || e.kind.as_deref() == Some("dev") {
            continue;
        }
        match table.get(&e.from) {
            None => bad.push(format!(
                "{}: not in ARCHITECTURE.md's Crates table (add its row)",
                e.from
            )),
            Some(allowed) if !allowed.contains(&e.to) => bad.push(format!(
                "{} depends on {} ({} dependency), which ARCHITECTURE.md does not allow \
                 (allowed: {allowed:?})",
                e.from,
                e.to,
                e.kind.as_deref().unwrap_or("normal")
            )),
            Some(_) => {}
        }
    }
    bad
}

#[test]
fn crates_depend_only_on_what_architecture_md_allows() {
    let table = allowed_from_table(&architecture());
    let meta = metadata();
    let (ours, edges) = workspace_edges(meta);
    for name in &ours {
        assert!(
            table.contains_key(name),
            "{name}: a workspace crate without a row in ARCHITECTURE.md's Crates table"
        );
    }
    let bad = table_violations(&table, &ours, &edges);
    assert!(
        bad.is_empty(),
        "dependency rules broken:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_checker_catches_a_forbidden_edge() {
    // The same checker on the real table, plus one edge the table forbids: the server
    // library on the trainer (ARCHITECTURE.md: the demo crate wires training in instead).
    let table = allowed_from_table(&architecture());
    let meta = metadata();
    let (ours, mut edges) = workspace_edges(meta);
    assert!(table_violations(&table, &ours, &edges).is_empty());
    edges.push(Edge {
        from: "crease-server".into(),
        to: "crease-train".into(),
        kind: None,
    });
    let bad = table_violations(&table, &ours, &edges);
    assert_eq!(bad.len(), 1, "{bad:?}");
    assert!(
        bad[0].starts_with("crease-server depends on crease-train"),
        "{bad:?}"
    );
}

#[test]
fn dev_dependencies_do_not_loop_back() {
    let meta = metadata();
    let (ours, edges) = workspace_edges(meta);
    let mut bad = Vec::new();
    for e in &edges {
        if e.kind.as_deref() == Some("dev")
            && ours.contains(&e.to)
            && reachable(meta, &e.to).contains(&e.from)
        {
            bad.push(format!(
                "{} dev-depends on {}, which depends on {}",
                e.from, e.to, e.from
            ));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn core_stays_free_of_async_and_the_wire() {
    let meta = metadata();
    let reached = reachable(meta, "crease-core");
    let bad: Vec<&str> = CORE_NEVER
        .iter()
        .copied()
        .filter(|c| reached.contains(*c))
        .collect();
    assert!(
        bad.is_empty(),
        "crease-core reaches {bad:?} through its dependencies (ARCHITECTURE.md forbids it)"
    );
    // The check can see: the server does reach all four.
    let server = reachable(meta, "crease-server");
    assert!(CORE_NEVER.iter().all(|c| server.contains(*c)), "{server:?}");
}

#[test]
fn no_library_file_over_a_thousand_lines_without_a_reason() {
    let doc = architecture();
    let whole: String = doc
        .split("\n## ")
        .find(|s| s.starts_with("Files kept whole"))
        .unwrap_or_default()
        .to_owned();
    let root = repo();
    let meta = metadata();
    let mut long = Vec::new();
    for p in meta["packages"].as_array().unwrap() {
        let manifest = PathBuf::from(p["manifest_path"].as_str().unwrap());
        if !manifest.starts_with(&root) {
            continue;
        }
        let mut files = Vec::new();
        rust_files(&manifest.parent().unwrap().join("src"), &mut files);
        for f in files {
            let lines = std::fs::read_to_string(&f).unwrap().lines().count();
            let rel = f.strip_prefix(&root).unwrap().display().to_string();
            if lines > MAX_LINES && !whole.contains(&format!("`{rel}`")) {
                long.push(format!("{rel}: {lines} lines"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "library files over {MAX_LINES} lines (split them, or say why in ARCHITECTURE.md's \
         \"Files kept whole\"):\n{}",
        long.join("\n")
    );
}

/// The fuzz crate is its own workspace with its own `Cargo.lock`; CI checks it with `--locked`, so
/// a dependency added to a crate the fuzz targets use must be locked there too (`cargo update
/// --manifest-path fuzz/Cargo.toml --workspace`). `cargo metadata --locked` finds a stale lock
/// in a third of a second, without nightly and without compiling anything. It may need to
/// fetch the fuzz crate's own dependencies (`libfuzzer-sys`) once: offline and without them, the
/// check is skipped with the reason printed, as tests needing an external tool are.
#[test]
fn the_fuzz_workspace_lock_is_up_to_date() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--locked"])
        .args(["--manifest-path", "fuzz/Cargo.toml"])
        .current_dir(repo())
        .output()
        .expect("cargo metadata runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() && !stderr.contains("lock file") {
        eprintln!(
            "skipped: cargo metadata of fuzz/ failed for another reason than its lock:\n{stderr}"
        );
        return;
    }
    assert!(
        out.status.success(),
        "fuzz/Cargo.lock is stale; run `cargo update --manifest-path fuzz/Cargo.toml \
         --workspace` and commit it:\n{stderr}"
    );
}
