//! Atomic file writes, shared by every writer of the workspace (meshes, model files, PNG
//! pictures, data sets).

use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temp files of concurrent writers within one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Removes the temporary files a killed writer of `name` left in `dir`: `.NAME.tmp-PID-N` whose
/// process `PID` is gone (`/proc/PID` absent; Linux only, elsewhere nothing is removed). A
/// writer that is still running keeps its file. Best effort: errors are ignored.
fn remove_stale_temps(dir: &Path, name: &str) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let prefix = format!(".{name}.tmp-");
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(rest) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Writes `path` atomically: `write` fills a temporary file beside it (`.NAME.tmp-PID-N`, which
/// never carries a mesh extension, so folder scans skip it), the file is flushed with `fsync`,
/// renamed over `path`, and the directory flushed (best effort). On any error the temporary file
/// is removed and `path` is left as it was: readers, and a crash, see the old file or the new
/// one, never half of one. Temporary files of writers that were killed before they finished
/// are removed on the next write of the same file.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "path does not name a file"))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    remove_stale_temps(dir, &name.to_string_lossy());
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{n}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        let mut out = BufWriter::new(f);
        write(&mut out)?;
        let f = out.into_inner().map_err(io::IntoInnerError::into_error)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        // The temp file may not exist (open failed); nothing more to do either way.
        let _ = fs::remove_file(&tmp);
        return result;
    }
    // Persist the rename itself. Some platforms and file systems refuse to fsync a directory;
    // the new file is already in place, so that is not worth failing the write for.
    #[cfg(unix)]
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_removes_the_temporary_files_of_dead_writers_only() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.crease");
        // PIDs are below 2^22 on Linux: 999999999 was never a process. PID 1 is alive.
        let dead = dir.path().join(".m.crease.tmp-999999999-0");
        let alive = dir.path().join(".m.crease.tmp-1-0");
        let ours = dir
            .path()
            .join(format!(".m.crease.tmp-{}-999", std::process::id()));
        let other_file = dir.path().join(".n.crease.tmp-999999999-0");
        for p in [&dead, &alive, &ours, &other_file] {
            fs::write(p, b"half").unwrap();
        }
        write_atomic_with(&path, |w| w.write_all(b"whole")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"whole");
        if Path::new("/proc/self").exists() {
            assert!(!dead.exists(), "a dead writer's temporary file stays");
        }
        assert!(alive.exists() && ours.exists() && other_file.exists());
    }
}
