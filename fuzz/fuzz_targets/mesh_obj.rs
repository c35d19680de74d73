//! OBJ text (`core::mesh::obj::parse_obj`): any bytes, read as UTF-8 with replacement as the
//! file reader would refuse them; the mesh must be checked (indices in range, finite).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(mesh) = crease_core::mesh::obj::parse_obj(&text) {
        check(&mesh);
    }
});

fn check(mesh: &crease_core::mesh::Mesh) {
    let n = mesh.positions.len();
    assert!(mesh.triangles.iter().flatten().all(|&i| (i as usize) < n));
    assert!(mesh.positions.iter().all(|p| p.is_finite()));
}
