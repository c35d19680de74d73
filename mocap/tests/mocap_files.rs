//! The recording readers on the real files in ../shared/data/mocap, checked against values read
//! independently: the header facts and first rows as printed by a Python reading of the files,
//! and for C3D a direct byte-offset read of frame 1 done here.

use std::path::{Path, PathBuf};

use crease_core::glam::Vec3;
use crease_mocap::{MocapError, Recording, c3d};

#[path = "../../core/tests/common/mod.rs"]
mod common;

fn data(file: &str) -> Option<PathBuf> {
    common::shared_data(&format!("mocap/{file}"))
}

const QUALISYS: &str = "qualisys-hand-glove-recording.tsv";
const ART: &str = "ART-Human_hands_real_no6dof.c3d";

#[test]
fn qualisys_tsv_reads_header_rows_and_gaps() {
    let Some(path) = data(QUALISYS) else { return };
    let r = Recording::read(&path).expect("reads");
    assert_eq!(r.frame_count(), 6000);
    assert_eq!(r.rate_hz, 100.0);
    assert_eq!(r.units, "mm");
    let names = [
        "hand_top",
        "hand_left",
        "hand_right",
        "thumb_tip",
        "thumb_middle",
        "little_tip",
        "little_middle",
        "ring_tip",
        "ring_middle",
        "middle_middle",
        "middle_tip",
        "index_tip",
        "index_middle",
        "right_elbow",
        "back_top",
        "back_left",
        "back_right",
        "right_shoulder",
        "pillow_top",
        "pillow_left",
        "pillow_right",
    ];
    assert_eq!(r.names, names);
    // Row "1  0.00000  110.406  135.075  460.584  62.382 ..." and the last row.
    let f = r.frame(0);
    assert_eq!(f.positions[0], Vec3::new(110.406, 135.075, 460.584));
    assert_eq!(f.positions[1], Vec3::new(62.382, 161.390, 450.921));
    assert_eq!(f.positions[20], Vec3::new(371.959, 289.915, 223.330));
    assert!(f.valid.iter().all(|v| *v));
    let last = r.frame(5999);
    assert!((last.time - 59.99).abs() < 1e-9);
    assert_eq!(
        last.positions[0],
        Vec3::new(305.536, 206.987, last.positions[0].z)
    );
    // Gaps among the 13 hand markers, counted from the file's `nan` fields: thumb_tip 493
    // frames, middle_tip 78, ring_tip 42, the others none; row 886 (t = 8.85 s) has thumb_tip
    // missing.
    let gaps = r.gaps_per_marker();
    let want = [0, 0, 0, 493, 0, 0, 0, 42, 0, 0, 78, 0, 0];
    assert_eq!(gaps[..13], want);
    assert!(!r.frame(885).valid[3]);
    assert_eq!(
        r.frame(885).positions[3],
        Vec3::ZERO,
        "gaps are zero, never NaN"
    );
    assert!(r.frame(885).valid[4]);
}

#[test]
fn art_c3d_reads_labels_rate_and_frame_one() {
    let Some(path) = data(ART) else { return };
    let r = Recording::read(&path).expect("reads");
    assert_eq!(r.marker_count(), 61);
    assert_eq!(r.frame_count(), 969);
    assert_eq!(r.rate_hz, 60.0);
    assert_eq!(r.units, "mm");
    assert_eq!(r.names[0], "Human4:PELV");
    assert_eq!(r.names[42], "Human4:RTTI");
    assert_eq!(r.names[60], "Human4:RFOO");
    assert_eq!(
        r.marker("RTTI"),
        Some(42),
        "found without the subject prefix"
    );
    // Finger joints: 4 per digit, 5 digits, 2 hands.
    let fingers = r
        .names
        .iter()
        .filter(|n| {
            let n = n.trim_start_matches("Human4:");
            n.len() == 4
                && (n.starts_with('L') || n.starts_with('R'))
                && [
                    "IF", "TI", "TM", "TO", "TT", "MF", "RF", "PI", "PM", "PO", "PT",
                ]
                .iter()
                .any(|p| n[1..].starts_with(p))
        })
        .count();
    assert_eq!(fingers, 40);
    // Frame 1 as the Python reading printed it.
    let f = r.frame(0);
    assert_eq!(f.positions[0], Vec3::new(93.646_94, 158.843_72, 861.751_65));
    assert_eq!(
        f.positions[42],
        Vec3::new(-344.316_68, -343.261_6, 1_358.369_8)
    );
    // And every point of frame 1 against a direct read: Intel floats, data from block 9,
    // 16 bytes (x, y, z, residual word) per point.
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes[512 + 3], 84, "Intel processor");
    let block = u16::from_le_bytes([bytes[16], bytes[17]]) as usize;
    for m in 0..61 {
        let at = (block - 1) * 512 + 16 * m;
        let v =
            |k: usize| f32::from_le_bytes(bytes[at + 4 * k..at + 4 * k + 4].try_into().unwrap());
        assert_eq!(f.positions[m], Vec3::new(v(0), v(1), v(2)), "point {m}");
    }
    assert_eq!(
        r.gaps_per_marker().iter().sum::<usize>(),
        0,
        "the sample has no gaps"
    );
}

/// Invalid samples as C3D encodes them: a negative residual word, or a point at 0 0 0.
#[test]
fn c3d_invalid_samples_are_gaps() {
    let Some(path) = data(ART) else { return };
    let mut bytes = std::fs::read(&path).unwrap();
    let frame_bytes = 61 * 16;
    let point = |f: usize, m: usize| 8 * 512 + f * frame_bytes + 16 * m;
    // Frame 10, point RTTI: residual -1 (not seen). Frame 11, point RIFT: 0 0 0.
    let at = point(10, 42) + 12;
    bytes[at..at + 4].copy_from_slice(&(-1.0f32).to_le_bytes());
    let at = point(11, 38);
    bytes[at..at + 12].copy_from_slice(&[0u8; 12]);
    let r = c3d::parse(Path::new("edited.c3d"), &bytes).expect("reads");
    assert!(!r.frame(10).valid[42]);
    assert_eq!(r.frame(10).positions[42], Vec3::ZERO);
    assert!(!r.frame(11).valid[38]);
    assert!(r.frame(10).valid[41] && r.frame(11).valid[42]);
    assert_eq!(r.gaps_per_marker().iter().sum::<usize>(), 2);

    // A file cut short is an error naming it, not a panic.
    let cut = &bytes[..bytes.len() / 2];
    let e = c3d::parse(Path::new("cut.c3d"), cut).unwrap_err();
    assert!(matches!(e, MocapError::Format { .. }));
    assert!(
        e.to_string().contains("cut.c3d") && e.to_string().contains("truncated"),
        "{e}"
    );
}

#[test]
fn unknown_extensions_and_missing_files_are_named() {
    let e = Recording::read("take.bvh").unwrap_err().to_string();
    assert!(
        e.contains("take.bvh") && e.contains(".tsv (Qualisys) or .c3d"),
        "{e}"
    );
    let e = Recording::read("/nonexistent/take.tsv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/take.tsv"), "{e}");
}

/// Corrupted copies of the real files (random bytes overwritten, truncated, a huge count in
/// the header) read as an error or as a recording, never a panic or an abort.
#[test]
fn corrupted_recordings_are_errors_not_crashes() {
    use rand::{Rng, SeedableRng, rngs::StdRng};
    let mut rng = StdRng::seed_from_u64(8);
    if let Some(path) = data(QUALISYS) {
        let text = std::fs::read_to_string(&path).unwrap();
        // Only the header and the first rows, to keep the test quick.
        let head: String = text.lines().take(60).map(|l| format!("{l}\n")).collect();
        let e = crease_mocap::tsv::parse(
            Path::new("h.tsv"),
            &head.replace("NO_OF_FRAMES\t6000", "NO_OF_FRAMES\t999999999999999999"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("the file has 48 data rows"), "{e}");
        for _ in 0..300 {
            let mut bytes = head.clone().into_bytes();
            for _ in 0..rng.random_range(1..8) {
                let at = rng.random_range(0..bytes.len());
                bytes[at] = *b"\t\n0.9-xnaNE ".get(rng.random_range(0..12)).unwrap();
            }
            let cut = rng.random_range(0..=bytes.len());
            let t = String::from_utf8_lossy(&bytes[..cut]).into_owned();
            if let Ok(r) = crease_mocap::tsv::parse(Path::new("m.tsv"), &t) {
                assert!(
                    r.frames()
                        .all(|f| f.positions.iter().all(|p| p.is_finite()))
                );
            }
        }
    }
    if let Some(path) = data(ART) {
        let bytes = std::fs::read(&path).unwrap();
        for _ in 0..100 {
            let mut b = bytes.clone();
            // Mostly the header and parameter blocks, where the structure is.
            for _ in 0..rng.random_range(1..6) {
                let at = rng.random_range(0..4096);
                b[at] = rng.random();
            }
            let cut = if rng.random_bool(0.3) {
                rng.random_range(0..b.len())
            } else {
                b.len()
            };
            if let Ok(r) = c3d::parse(Path::new("m.c3d"), &b[..cut]) {
                assert!(
                    r.frames()
                        .all(|f| f.positions.iter().all(|p| p.is_finite()))
                );
            }
        }
    }
}
