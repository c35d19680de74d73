//! C3D marker recordings (`crease_mocap::c3d::parse`, on the `c3dio` crate).
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

// The reader catches the panics of `c3dio` (a third-party parser) and calls the file malformed;
// libfuzzer-sys's panic hook would abort first, so it is replaced by a silent one. A panic the
// reader does not catch still ends the run as a crash (libfuzzer-sys aborts on it).
fuzz_target!(
    init: {
        std::panic::set_hook(Box::new(|_| {}));
    },
    |data: &[u8]| {
    if let Ok(rec) = crease_mocap::c3d::parse(Path::new("fuzz.c3d"), data) {
        for frame in rec.frames() {
            assert_eq!(frame.positions.len(), rec.marker_count());
        }
    }
    }
);
