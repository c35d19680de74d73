//! Fuzz findings (`fuzz/regressions/`, README there), replayed on the stable toolchain: each
//! input once crashed a parser; now it is refused with an error.

use std::path::Path;

use crease_core::mesh::gltf::parse_gltf;
use crease_core::mesh::subdivision::{CsrError, SparseMatrix};

fn finding(target: &str, name: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions")
        .join(target)
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The subdivision step inside `mesh_stream/csr-offsets-out-of-order`, reduced: the second
/// row offset is past the two entries, the third back at 2.
#[test]
fn mesh_stream_csr_offsets_out_of_order() {
    let err = SparseMatrix::from_csr(2, vec![0, u32::MAX - 19, 2], vec![0, 1], vec![1.0, 1.0])
        .unwrap_err();
    assert!(
        matches!(
            err,
            CsrError::RowPtr {
                row: 2,
                value: 2,
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn mesh_gltf_position_accessor_missing() {
    let bytes = finding("mesh_gltf", "position-accessor-missing.gltf");
    let err = parse_gltf(&bytes, None).unwrap_err().to_string();
    assert!(err.contains("not a valid glTF file"), "{err}");
}

/// A POSITION accessor of count 0 whose triangles (two indices) name vertices it lacks.
#[test]
fn mesh_gltf_position_count_zero() {
    let bytes = finding("mesh_gltf", "position-count-zero.gltf");
    let err = parse_gltf(&bytes, None).unwrap_err().to_string();
    assert!(err.contains("POSITION accessor 0: count is 0"), "{err}");
}

/// `v x y z w` with a tiny (subnormal) weight: each coordinate was finite when read and
/// infinite once divided by `w`.
#[test]
fn mesh_obj_weight_divides_to_infinity() {
    let text = String::from_utf8(finding("mesh_obj", "weight-divides-to-infinity.obj")).unwrap();
    let err = crease_core::mesh::obj::parse_obj(&text)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("line 1") && err.contains("not finite"),
        "{err}"
    );
}

/// A face before its vertices (a forward reference) whose later corners reach further than
/// the first late one: only the first was checked, so corner 4 of 3 vertices went through.
#[test]
fn mesh_obj_forward_index_past_the_first_late_corner() {
    let text = String::from_utf8(finding(
        "mesh_obj",
        "forward-index-past-the-first-late-corner.obj",
    ))
    .unwrap();
    let err = crease_core::mesh::obj::parse_obj(&text)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("line 1") && err.contains("vertex 3, but there are only 3"),
        "{err}"
    );
}
