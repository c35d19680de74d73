//! Qualisys TSV marker recordings (`crease_mocap::tsv::parse`). An accepted recording's
//! frames all have one value per marker.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(rec) = crease_mocap::tsv::parse(Path::new("fuzz.tsv"), &text) {
        for frame in rec.frames() {
            assert_eq!(frame.positions.len(), rec.marker_count());
        }
    }
});
