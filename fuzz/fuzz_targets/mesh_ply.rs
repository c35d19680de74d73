//! PLY, ASCII and binary (`core::mesh::ply::parse_ply`); an accepted mesh must be checked.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = crease_core::mesh::ply::parse_ply(data) {
        let n = mesh.positions.len();
        assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n));
        assert!(mesh.positions.iter().all(|p| p.is_finite()));
    }
});
