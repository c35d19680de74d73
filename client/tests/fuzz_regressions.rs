//! Fuzz findings of the client-side targets (`fuzz/regressions/`, README there), replayed on
//! the stable toolchain as the fuzz target reads them: every one is refused with an error.

use std::path::{Path, PathBuf};

use crease_cli::commands::decode_stream::read_capture;
use crease_proto::v1;
use crease_remote::mesh_stream::StreamReader;

fn findings(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "{}: no findings", dir.display());
    files
}

/// What the `mesh_stream` target does with an input, up to the first error.
fn decode(bytes: &[u8]) -> anyhow::Result<()> {
    let messages = read_capture(bytes)?;
    let (first, rest) = messages
        .split_first()
        .ok_or_else(|| anyhow::anyhow!("empty"))?;
    let mut reader = StreamReader::new(first)?;
    for msg in rest {
        if let Some(v1::mesh_frame::Body::Frame(f)) = &msg.body {
            reader.decode(&f.data)?;
        }
    }
    Ok(())
}

#[test]
fn mesh_stream_findings_are_refused_without_a_panic() {
    for file in findings("mesh_stream") {
        let bytes = std::fs::read(&file).unwrap();
        let err = decode(&bytes).expect_err("a finding decodes");
        println!("{}: {err:#}", file.display());
    }
}
