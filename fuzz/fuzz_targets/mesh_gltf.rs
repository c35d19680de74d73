//! glTF and GLB bytes (`core::mesh::gltf::parse_gltf`, no folder: external buffers refused).
#![no_main]
use libfuzzer_sys::fuzz_target;

// The reader catches the panics of `gltf-json` (a third-party parser) and calls the file malformed;
// libfuzzer-sys's panic hook would abort first, so it is replaced by a silent one. A panic the
// reader does not catch still ends the run as a crash (libfuzzer-sys aborts on it).
fuzz_target!(
    init: {
        std::panic::set_hook(Box::new(|_| {}));
    },
    |data: &[u8]| {
    if let Ok(mesh) = crease_core::mesh::gltf::parse_gltf(data, None) {
        let n = mesh.positions.len();
        assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(mesh.positions.iter().all(|p| p.is_finite()));
    }
    }
);
