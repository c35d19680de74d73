//! Atomic file writes, shared by every writer of the workspace (meshes, model files, PNG
//! pictures, data sets).

use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temp files of concurrent writers within one process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `path` atomically: `write` fills a temporary file beside it (`.NAME.tmp-PID-N`, which
/// never carries a mesh extension, so folder scans skip it), the file is flushed with `fsync`,
/// renamed over `path`, and the directory flushed (best effort). On any error the temporary file
/// is removed and `path` is left as it was: readers, and a crash, see the old file or the new
/// one, never half of one.
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
