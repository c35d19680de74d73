//! The Python the VMC tests send with: a venv under `target/vmc-venv` with python-osc 1.10.2
//! (`tests/python/requirements-vmc.txt`), made on first use (a third-party OSC sender, so the
//! bridge is checked against bundles our code did not build).

use std::path::{Path, PathBuf};
use std::process::Command;

/// The venv's Python under `repo` (the checkout's root), made and filled on first use.
///
/// # Errors
/// What failed making the venv or installing python-osc (the caller skips with it).
pub fn python_osc(repo: &Path) -> Result<PathBuf, String> {
    let venv = repo.join("target/vmc-venv");
    let python = venv.join("bin/python");
    let ok = |py: &Path| {
        Command::new(py)
            .args([
                "-c",
                "import importlib.metadata as m; assert m.version('python-osc') == '1.10.2'",
            ])
            .status()
            .is_ok_and(|s| s.success())
    };
    if ok(&python) {
        return Ok(python);
    }
    let run = |cmd: &mut Command| -> Result<(), String> {
        let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "{cmd:?}: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ))
        }
    };
    run(Command::new("python3").args(["-m", "venv"]).arg(&venv))?;
    run(Command::new(venv.join("bin/pip"))
        .args(["install", "-q", "-r"])
        .arg(repo.join("tests/python/requirements-vmc.txt")))?;
    if ok(&python) {
        Ok(python)
    } else {
        Err("python-osc 1.10.2 is not importable after installing it".into())
    }
}
