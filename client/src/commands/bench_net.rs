//! `crease bench-net`: the network load benchmark and the soaks, which are the `crease-bench`
//! binary's (package `crease-bench`, folder `bench-net/`). This command runs that binary from
//! beside `crease` with the same arguments, so the benchmark's commands in BENCHMARKS.md and
//! RELIABILITY.md read `crease bench-net ...` while the run command (`cargo build -p
//! crease-demo -p crease-cli`) does not build the benchmark (issue 41: nothing the server does
//! not need built by the run command).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;

/// The binary this command runs, beside `crease`.
pub const BENCH_BINARY: &str = "crease-bench";

/// `crease bench-net ARGS`: every argument goes to `crease-bench` unchanged
/// (`crease bench-net --help` prints its options).
#[derive(Debug, Args)]
#[command(disable_help_flag = true)]
pub struct BenchNetArgs {
    /// `crease-bench`'s arguments (`crease bench-net --help` lists them).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
    pub args: Vec<OsString>,
}

/// Where `crease-bench` is expected: the folder of the running `crease`.
pub fn bench_binary() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("finding the running crease binary")?;
    Ok(beside(&exe))
}

fn beside(exe: &Path) -> PathBuf {
    exe.with_file_name(format!("{BENCH_BINARY}{}", std::env::consts::EXE_SUFFIX))
}

/// Runs `crease-bench` with `args`' arguments: on Unix it replaces this process (signals such
/// as Ctrl-C reach the benchmark itself, which stops its servers); elsewhere it waits for it
/// and fails with its exit status.
pub fn run(args: &BenchNetArgs) -> anyhow::Result<()> {
    let bin = bench_binary()?;
    if !bin.is_file() {
        bail!(
            "`crease bench-net` runs the {BENCH_BINARY} binary, and there is none at {}: build it \
             with `cargo build --release -p crease-bench` (it is not part of the run command's \
             build), then run `crease bench-net` again or {BENCH_BINARY} itself",
            bin.display()
        );
    }
    let mut command = std::process::Command::new(&bin);
    command.args(&args.args);
    exec(command, &bin)
}

#[cfg(unix)]
fn exec(mut command: std::process::Command, bin: &Path) -> anyhow::Result<()> {
    use std::os::unix::process::CommandExt;
    // Returns only when the exec failed.
    let err = command.exec();
    Err(err).with_context(|| format!("running {}", bin.display()))
}

#[cfg(not(unix))]
fn exec(mut command: std::process::Command, bin: &Path) -> anyhow::Result<()> {
    let status = command
        .status()
        .with_context(|| format!("running {}", bin.display()))?;
    if !status.success() {
        bail!("{} ended with {status}", bin.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_benchmark_is_looked_for_beside_crease() {
        let exe = Path::new("/opt/crease/bin/crease");
        assert_eq!(
            beside(exe),
            Path::new("/opt/crease/bin")
                .join(format!("crease-bench{}", std::env::consts::EXE_SUFFIX))
        );
    }
}
