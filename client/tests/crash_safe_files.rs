//! Crash-safe model files (issue 21): `crease train --out` killed with SIGKILL at random
//! moments, many times, always leaves the old model or the new one, whole, never a corrupt or
//! missing file; on a full disk it fails with an error naming the file and the old model stays.
//!
//! The examples are a bending tube of 4800 vertices (a model of about 800 KB, so its write
//! takes milliseconds). The old model (A) and the new one (B) are trained once in full first.
//! Then, per kill, B's training starts again over A: a third of the kills land at a uniformly
//! random moment of the run; the others wait for the writer's temporary file to appear and kill
//! it a random fraction of a write later, so most of those land inside the write itself. The
//! figures printed say how many kills left a temporary file (landed mid-write).
//!
//! `CREASE_KILLS` sets the number of kills (default 100). The full-disk case mounts a small
//! tmpfs, which needs root (CAP_SYS_ADMIN); without it, it is skipped with the reason printed.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{crease, run_ok};
use crease_core::model::TrainedModel;

/// A tube of 200 rings of 24 vertices bent by 0.2 k radians beyond its middle, k = 0..6, as
/// OBJ files, and its manifest.
fn tube_examples(dir: &Path) -> PathBuf {
    const RINGS: usize = 200;
    let set = dir.join("tube");
    std::fs::create_dir_all(&set).unwrap();
    // The shared tube, ring `r` at z = `r`; OBJ indices count from 1.
    let tube = crease_testkit::mesh::tube(RINGS, 24, (RINGS - 1) as f32);
    let mut faces = String::new();
    for [a, b, c] in &tube.triangles {
        faces.push_str(&format!("f {} {} {}\n", a + 1, b + 1, c + 1));
    }
    let pivot = RINGS as f32 / 2.0;
    let mut names = Vec::new();
    for k in 0..6 {
        let angle = 0.2 * k as f32;
        let mut text = String::new();
        for p in &tube.positions {
            let (x, mut y, mut z) = (p.x, p.y, p.z);
            if z > pivot {
                let (dy, dz) = (y, z - pivot);
                y = dy * angle.cos() - dz * angle.sin();
                z = pivot + dy * angle.sin() + dz * angle.cos();
            }
            text.push_str(&format!("v {x} {y} {z}\n"));
        }
        text.push_str(&faces);
        let name = format!("pose{k}.obj");
        std::fs::write(set.join(&name), text).unwrap();
        names.push(format!("\"{name}\""));
    }
    let manifest = set.join("train.toml");
    std::fs::write(
        &manifest,
        format!(
            "rest = \"pose0.obj\"\nexamples = [{}]\ncontrol_points = [0, 2400, 4799]\n",
            names[1..].join(", ")
        ),
    )
    .unwrap();
    manifest
}

fn train(examples: &Path, bones: u32, out: &Path) -> Command {
    let mut cmd = crease();
    cmd.args(["train", "--examples"])
        .arg(examples)
        .args([
            "--bones",
            &bones.to_string(),
            "--max-influences",
            "4",
            "--no-detail",
            "--out",
        ])
        .arg(out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    cmd
}

/// xorshift64*: reproducible kill times without a dependency.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Temporary files of `name`'s writers in `dir` (`.NAME.tmp-*`, `core::atomic`).
fn temps(dir: &Path, name: &str) -> Vec<PathBuf> {
    let prefix = format!(".{name}.tmp-");
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .collect()
}

#[test]
fn killed_writers_leave_the_old_model_or_the_new_one() {
    let kills: usize = std::env::var("CREASE_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    let dir = tempfile::tempdir().unwrap();
    let examples = tube_examples(dir.path());
    let a_path = dir.path().join("a.crease");
    let b_path = dir.path().join("b.crease");
    run_ok(&mut train(&examples, 3, &a_path));
    let start = Instant::now();
    run_ok(&mut train(&examples, 6, &b_path));
    let full = start.elapsed();
    let old = std::fs::read(&a_path).unwrap();
    let new = std::fs::read(&b_path).unwrap();
    assert_ne!(
        old, new,
        "A and B must differ for the check to mean anything"
    );
    // Both are valid models (independently: the reader checks every section's CRC).
    TrainedModel::from_bytes(&old).unwrap();
    TrainedModel::from_bytes(&new).unwrap();
    // How long a write of B takes here, to spread the kills over it.
    let start = Instant::now();
    crease_core::model::file::write_atomic(&dir.path().join("probe.crease"), &new).unwrap();
    let write = start.elapsed().max(Duration::from_micros(200));

    let target_dir = dir.path().join("out");
    std::fs::create_dir_all(&target_dir).unwrap();
    let target = target_dir.join("model.crease");
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut kept_old, mut got_new, mut mid_write) = (0, 0, 0);
    for k in 0..kills {
        std::fs::write(&target, &old).unwrap();
        let mut child = train(&examples, 6, &target).spawn().unwrap();
        let when = if k.is_multiple_of(3) {
            let at = full.mul_f64(rng.unit());
            std::thread::sleep(at);
            format!("{:.0} ms into the run", at.as_secs_f64() * 1e3)
        } else {
            // Until the temporary file appears (or the writer exits), then up to two writes.
            let deadline = Instant::now() + full * 4;
            while temps(&target_dir, "model.crease").is_empty()
                && child.try_wait().unwrap().is_none()
                && Instant::now() < deadline
            {
                std::thread::sleep(Duration::from_micros(100));
            }
            let after = write.mul_f64(2.0 * rng.unit());
            std::thread::sleep(after);
            format!("{:.2} ms after its write began", after.as_secs_f64() * 1e3)
        };
        let _ = child.kill(); // SIGKILL; an error means it had exited already
        child.wait().unwrap();
        if !temps(&target_dir, "model.crease").is_empty() {
            mid_write += 1;
        }
        let bytes = std::fs::read(&target)
            .unwrap_or_else(|e| panic!("kill {k}, {when}: the model is missing: {e}"));
        if bytes == old {
            kept_old += 1;
        } else if bytes == new {
            got_new += 1;
        } else {
            panic!(
                "kill {k}, {when}: the file is neither model ({} bytes, old {} new {})",
                bytes.len(),
                old.len(),
                new.len()
            );
        }
    }
    // A later write removes a killed writer's temporary file.
    run_ok(&mut train(&examples, 6, &target));
    assert!(
        temps(&target_dir, "model.crease").is_empty(),
        "temporary files of killed writers remain: {:?}",
        temps(&target_dir, "model.crease")
    );
    println!(
        "crease train --out: {kills} kills over a {:.2} s run writing {} bytes in {:.1} ms: old model {kept_old}, new model {got_new}, corrupt or missing 0; {mid_write} killed while the temporary file existed",
        full.as_secs_f64(),
        new.len(),
        write.as_secs_f64() * 1e3
    );
    assert_eq!(kept_old + got_new, kills);
}

/// Mounts a `size` tmpfs at `at`, or says why not.
fn mount_tmpfs(at: &Path, size: &str) -> Result<(), String> {
    std::fs::create_dir_all(at).map_err(|e| e.to_string())?;
    let out = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(at)
        .output()
        .map_err(|e| format!("mount: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).trim().to_owned())
    }
}

struct Unmount(PathBuf);

impl Drop for Unmount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_gives_a_clear_error_and_keeps_the_old_model() {
    let dir = tempfile::tempdir().unwrap();
    let examples = tube_examples(dir.path());
    let a_path = dir.path().join("a.crease");
    run_ok(&mut train(&examples, 3, &a_path));
    let old = std::fs::read(&a_path).unwrap();
    // A disk the old model fits on, with 8 KiB to spare: not enough for a new one.
    let size = old.len() + 8192;
    let disk = dir.path().join("disk");
    if let Err(why) = mount_tmpfs(&disk, &size.to_string()) {
        println!(
            "SKIP the full-disk case: cannot mount a tmpfs ({why}); run as root to include it"
        );
        return;
    }
    let _unmount = Unmount(disk.clone());
    let target = disk.join("model.crease");
    std::fs::write(&target, &old).unwrap();
    let out = train(&examples, 6, &target)
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "crease train on a full disk succeeded: {stderr}"
    );
    assert!(
        stderr.contains("model.crease") && stderr.contains("No space left on device"),
        "the error names neither the file nor the cause: {stderr}"
    );
    assert_eq!(
        stderr.matches("No space left").count(),
        1,
        "the cause is said once: {stderr}"
    );
    assert_eq!(
        std::fs::read(&target).unwrap(),
        old,
        "the old model changed"
    );
    assert!(
        temps(&disk, "model.crease").is_empty(),
        "a temporary file was left on the full disk"
    );
    println!(
        "full disk ({size}-byte tmpfs, old model {} bytes): crease train --out failed with: {}",
        old.len(),
        stderr.lines().last().unwrap_or("").trim()
    );
}
