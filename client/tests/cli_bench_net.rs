//! `crease bench-net` runs the `crease-bench` binary beside `crease` with its arguments (the
//! benchmark itself is tested in `bench-net/tests/cli.rs`): its help and errors come through
//! when it is built there, and a `crease` without it says how to build it.

use crate::common::crease;

use std::path::Path;

#[test]
fn bench_net_runs_crease_bench_beside_crease() {
    let bench = Path::new(env!("CARGO_BIN_EXE_crease"))
        .with_file_name(format!("crease-bench{}", std::env::consts::EXE_SUFFIX));
    if !bench.is_file() {
        // `cargo test -p crease-cli` builds only this package's binaries; a workspace test run
        // (or `cargo build -p crease-bench`) puts the benchmark beside `crease`.
        eprintln!("skipped: {} is not built", bench.display());
        return;
    }
    // --help reaches crease-bench (not crease's own help for the subcommand).
    let out = crease().args(["bench-net", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{help}");
    assert!(
        help.contains("crease-bench") && help.contains("--chaos") && help.contains("--idle"),
        "{help}"
    );
    // Its errors and exit status come through unchanged.
    let out = crease()
        .args(["bench-net", "--chaos", "1", "--chaos-lease-ms", "50"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("--chaos-lease-ms must be 100 to 60000, got 50"),
        "{err}"
    );
}

#[test]
fn bench_net_without_crease_bench_says_how_to_build_it() {
    // A copy of `crease` alone in a folder (a copy, not a link: the binary finds its folder
    // from its own path, which the kernel resolves through links).
    let dir = tempfile::tempdir().unwrap();
    let lone = dir
        .path()
        .join(format!("crease{}", std::env::consts::EXE_SUFFIX));
    std::fs::copy(env!("CARGO_BIN_EXE_crease"), &lone).unwrap();
    let out = std::process::Command::new(&lone)
        .args(["bench-net", "--rooms", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("crease-bench")
            && err.contains("cargo build --release -p crease-bench")
            && err.contains(&dir.path().display().to_string()),
        "{err}"
    );
}
