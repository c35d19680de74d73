//! The rig file: exact round trips, and every kind of damage rejected with a clear error.

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::model::file::{Container, ContainerWriter, FormatError, ModelKind, Tag};
use crease_core::model::{ModelError, Rig, RigExample};
use crease_core::runtime::skin::{RigidTransform, SkinWeights};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn synthetic_rig(seed: u64, n: usize, bones: usize, k: usize, examples: usize) -> Rig {
    let mut rng = StdRng::seed_from_u64(seed);
    let positions: Vec<Vec3> = (0..n)
        .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let triangles = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    let mut indices = Vec::new();
    let mut weights = Vec::new();
    for _ in 0..n {
        let w: Vec<f32> = (0..k).map(|_| rng.random::<f32>() + 0.01).collect();
        let s: f32 = w.iter().sum();
        weights.extend(w.iter().map(|x| x / s));
        indices.extend((0..k).map(|_| rng.random_range(0..bones as u32)));
    }
    let examples = (0..examples)
        .map(|e| RigExample {
            name: format!("pose {e} ✓"),
            transforms: (0..bones)
                .map(|_| {
                    let axis = Vec3::new(rng.random(), rng.random(), rng.random::<f32>() + 0.1)
                        .normalize();
                    RigidTransform::new(
                        Quat::from_axis_angle(axis, rng.random_range(-3.0..3.0)),
                        Vec3::new(rng.random(), rng.random(), rng.random()),
                    )
                })
                .collect(),
        })
        .collect();
    Rig {
        rest: Mesh {
            positions,
            triangles,
        },
        bone_count: bones,
        skin: SkinWeights::new(k, indices, weights).unwrap(),
        examples,
        fit_rms: Some(0.0125),
    }
}

#[test]
fn save_load_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    for (k, examples) in [(1, 0), (4, 3), (8, 5)] {
        let rig = synthetic_rig(k as u64, 200, 17, k, examples);
        let path = dir.path().join(format!("k{k}.rig"));
        rig.save(&path).unwrap();
        let back = Rig::load(&path).unwrap();
        // PartialEq on f32 fields: bit-exact (no NaNs in a valid rig).
        assert_eq!(back, rig);
        assert_eq!(Rig::from_bytes(&rig.to_bytes().unwrap()).unwrap(), rig);
    }
}

#[test]
fn skin_example_matches_transforms_for_rigidly_bound_vertices() {
    let mut rig = synthetic_rig(9, 50, 3, 1, 2);
    rig.fit_rms = None;
    let mut out = vec![Vec3::ZERO; 50];
    rig.skin_example(1, &mut out).unwrap();
    for (v, o) in out.iter().enumerate() {
        let b = rig.skin.vertex(v).0[0] as usize;
        let want = rig.examples[1].transforms[b].transform_point(rig.rest.positions[v]);
        assert!((*o - want).length() < 1e-5);
    }
    assert!(matches!(
        rig.skin_example(2, &mut out),
        Err(ModelError::NoSuchExample { index: 2, count: 2 })
    ));
}

#[test]
fn flipped_byte_in_any_section_names_that_section() {
    let bytes = synthetic_rig(1, 60, 5, 4, 2).to_bytes().unwrap();
    let entries = Container::parse(&bytes).unwrap().entries().to_vec();
    assert_eq!(entries.len(), 6);
    for e in &entries {
        for at in [e.offset, e.offset + e.len / 2, e.offset + e.len - 1] {
            let mut b = bytes.clone();
            b[at as usize] ^= 0x01;
            let err = Rig::from_bytes(&b).unwrap_err();
            let msg = err.to_string();
            assert!(
                matches!(&err, ModelError::Format(FormatError::Checksum { .. }))
                    && msg.contains(&format!("section {}", e.tag)),
                "byte {at} in {}: {msg}",
                e.tag
            );
        }
    }
}

#[test]
fn flipped_byte_in_header_or_table_is_a_checksum_error() {
    let bytes = synthetic_rig(2, 30, 4, 2, 1).to_bytes().unwrap();
    let table_end = 32 + 24 * 6;
    // Bytes 0..8 are the magic, which gets its own error.
    for at in 8..table_end {
        let mut b = bytes.clone();
        b[at] ^= 0x80;
        let msg = Rig::from_bytes(&b).unwrap_err().to_string();
        let want = if at < 32 {
            "checksum mismatch in header"
        } else {
            "checksum mismatch in section table"
        };
        assert!(msg.contains(want), "byte {at}: {msg}");
    }
    for at in 0..8 {
        let mut b = bytes.clone();
        b[at] ^= 0x04;
        let msg = Rig::from_bytes(&b).unwrap_err().to_string();
        assert!(msg.starts_with("not a crease file"), "byte {at}: {msg}");
    }
}

#[test]
fn truncated_files_are_rejected_with_the_missing_range() {
    let bytes = synthetic_rig(3, 80, 6, 4, 2).to_bytes().unwrap();
    let entries = Container::parse(&bytes).unwrap().entries().to_vec();
    let skbw = entries.iter().find(|e| e.tag == Tag(*b"SKBW")).unwrap();
    let cut = (skbw.offset + 10) as usize;
    let msg = Rig::from_bytes(&bytes[..cut]).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!(
            "truncated: section SKBW needs bytes {}..{}, file has {cut}",
            skbw.offset,
            skbw.offset + skbw.len
        )
    );
    // Every length short of the full file fails cleanly (and never panics).
    for len in 0..bytes.len() {
        match Rig::from_bytes(&bytes[..len]) {
            Err(ModelError::Format(FormatError::Truncated { .. })) => {}
            other => panic!("length {len}: {other:?}"),
        }
    }
}

/// Rewrites a u32 header field and fixes the preamble checksum, as a different writer would.
fn with_header_field(bytes: &[u8], at: usize, value: u32) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[at..at + 4].copy_from_slice(&value.to_le_bytes());
    let crc = crc32fast::hash(&b[..28]);
    b[28..32].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn other_versions_and_kinds_are_rejected() {
    let bytes = synthetic_rig(4, 20, 2, 1, 1).to_bytes().unwrap();
    let msg = Rig::from_bytes(&with_header_field(&bytes, 8, 3))
        .unwrap_err()
        .to_string();
    assert_eq!(msg, "file format version 3, this build reads 1");
    assert!(Rig::from_bytes(&with_header_field(&bytes, 8, 0)).is_err());
    let msg = Rig::from_bytes(&with_header_field(&bytes, 12, 7))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("unknown model kind 7"), "{msg}");
}

#[test]
fn not_a_crease_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let msg = Rig::load(&path).unwrap_err().to_string();
    assert!(msg.starts_with("not a crease file"), "{msg}");
    let missing = dir.path().join("nope.rig");
    let msg = Rig::load(&missing).unwrap_err().to_string();
    assert!(msg.contains("nope.rig"), "{msg}");
}

/// Re-packs a valid rig file's sections through `edit`, so the checksums are valid and only
/// the content is wrong.
fn repack(bytes: &[u8], edit: impl Fn(Tag, &[u8]) -> Option<Vec<u8>>) -> Vec<u8> {
    let c = Container::parse(bytes).unwrap();
    let mut w = ContainerWriter::new(ModelKind::Rig);
    for e in c.entries() {
        if let Some(new) = edit(e.tag, c.section(e.tag).unwrap()) {
            w.add(e.tag, new);
        }
    }
    w.to_bytes()
}

#[test]
fn missing_section_is_named() {
    let bytes = synthetic_rig(5, 20, 3, 2, 2).to_bytes().unwrap();
    let b = repack(&bytes, |t, s| (t != Tag(*b"XFRM")).then(|| s.to_vec()));
    assert_eq!(
        Rig::from_bytes(&b).unwrap_err().to_string(),
        "missing section XFRM"
    );
}

#[test]
fn section_sizes_must_match_metadata() {
    let bytes = synthetic_rig(6, 25, 3, 4, 2).to_bytes().unwrap();
    let b = repack(&bytes, |t, s| {
        Some(if t == Tag(*b"SKBW") {
            s[..s.len() - 4].to_vec()
        } else {
            s.to_vec()
        })
    });
    let msg = Rig::from_bytes(&b).unwrap_err().to_string();
    assert_eq!(
        msg,
        "section SKBW is 396 bytes, expected 400 (f32 x 4 influences x 25 vertices)"
    );

    // A META claiming more vertices than VPOS holds.
    let b = repack(&bytes, |t, s| {
        Some(if t == Tag(*b"META") {
            String::from_utf8(s.to_vec())
                .unwrap()
                .replace("\"vertex_count\":25", "\"vertex_count\":26")
                .into_bytes()
        } else {
            s.to_vec()
        })
    });
    let msg = Rig::from_bytes(&b).unwrap_err().to_string();
    assert!(
        msg.starts_with("section VPOS is 300 bytes, expected 312"),
        "{msg}"
    );

    // Absurd counts overflow instead of allocating.
    let b = repack(&bytes, |t, s| {
        Some(if t == Tag(*b"META") {
            String::from_utf8(s.to_vec())
                .unwrap()
                .replace(
                    "\"vertex_count\":25",
                    "\"vertex_count\":18446744073709551615",
                )
                .into_bytes()
        } else {
            s.to_vec()
        })
    });
    assert!(Rig::from_bytes(&b).is_err());
}

#[test]
fn invalid_content_with_valid_checksums_is_rejected() {
    let bytes = synthetic_rig(7, 20, 3, 2, 1).to_bytes().unwrap();
    // A bone index past bone_count.
    let b = repack(&bytes, |t, s| {
        let mut s = s.to_vec();
        if t == Tag(*b"SKBI") {
            s[8..12].copy_from_slice(&3u32.to_le_bytes());
        }
        Some(s)
    });
    let msg = Rig::from_bytes(&b).unwrap_err().to_string();
    assert!(msg.contains("vertex 1") && msg.contains("bone 3"), "{msg}");
    // A non-unit quaternion.
    let b = repack(&bytes, |t, s| {
        let mut s = s.to_vec();
        if t == Tag(*b"XFRM") {
            s[12..16].copy_from_slice(&0.5f32.to_le_bytes());
        }
        Some(s)
    });
    let msg = Rig::from_bytes(&b).unwrap_err().to_string();
    assert!(msg.contains("not a unit quaternion"), "{msg}");
    // Weights that do not sum to one.
    let b = repack(&bytes, |t, s| {
        let mut s = s.to_vec();
        if t == Tag(*b"SKBW") {
            s[0..4].copy_from_slice(&2.0f32.to_le_bytes());
        }
        Some(s)
    });
    let msg = Rig::from_bytes(&b).unwrap_err().to_string();
    assert!(msg.contains("vertex 0: weights sum to"), "{msg}");
}

fn dir_entries(dir: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn atomic_save_leaves_no_temp_file_and_keeps_old_file_on_failure() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.rig");
    let good = synthetic_rig(8, 40, 4, 4, 2);
    good.save(&path).unwrap();
    good.save(&path).unwrap(); // overwrite an existing file
    assert_eq!(dir_entries(dir.path()), ["model.rig"]);
    let before = std::fs::read(&path).unwrap();

    // Serialisation fails (validation): the old file is untouched, no temp file appears.
    let mut bad = good.clone();
    bad.examples[1].transforms[2].translation.y = f32::NAN;
    let msg = bad.save(&path).unwrap_err().to_string();
    assert!(msg.contains("example 1") && msg.contains("bone 2"), "{msg}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
    assert_eq!(dir_entries(dir.path()), ["model.rig"]);

    // The final rename fails (the target is a non-empty directory): the temp file is removed.
    let blocker = dir.path().join("blocked.rig");
    std::fs::create_dir(&blocker).unwrap();
    std::fs::write(blocker.join("x"), b"x").unwrap();
    let err = good.save(&blocker).unwrap_err();
    assert!(matches!(err, ModelError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("blocked.rig"), "{err}");
    assert_eq!(dir_entries(dir.path()), ["blocked.rig", "model.rig"]);

    // A missing directory is an I/O error naming the path.
    let err = good.save(dir.path().join("no/such/dir.rig")).unwrap_err();
    assert!(err.to_string().contains("dir.rig"), "{err}");
}

#[test]
fn validate_reports_mismatched_parts() {
    let rig = synthetic_rig(10, 30, 4, 2, 2);
    let mut r = rig.clone();
    r.examples[0].transforms.pop();
    assert!(
        r.validate()
            .unwrap_err()
            .to_string()
            .contains("has 3 transforms, expected 4")
    );
    let mut r = rig.clone();
    r.rest.triangles.push([0, 1, 30]);
    assert!(
        r.validate()
            .unwrap_err()
            .to_string()
            .contains("names vertex 30")
    );
    let mut r = rig.clone();
    r.rest.positions.push(Vec3::ZERO);
    assert!(
        r.validate()
            .unwrap_err()
            .to_string()
            .contains("skin weights cover 30 vertices")
    );
    let mut r = rig.clone();
    r.bone_count = 2;
    r.examples.iter_mut().for_each(|e| e.transforms.truncate(2));
    assert!(matches!(r.validate(), Err(ModelError::Skin(_))));
    let mut r = rig;
    r.rest.positions[3].x = f32::INFINITY;
    assert!(
        r.validate()
            .unwrap_err()
            .to_string()
            .contains("rest vertex 3")
    );
}
