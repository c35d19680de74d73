//! `SkinWeights::new` rejects every constraint violation and names the vertex.

use crease_core::runtime::skin::{SkinError, SkinWeights};

#[test]
fn accepts_valid_weights_and_exposes_them() {
    let s = SkinWeights::new(2, vec![0, 3, 2, 2], vec![0.25, 0.75, 1.0, 0.0]).unwrap();
    assert_eq!(s.k(), 2);
    assert_eq!(s.vertex_count(), 2);
    assert_eq!(s.vertex(1), (&[2u32, 2][..], &[1.0f32, 0.0][..]));
    // Slots come back heaviest first.
    assert_eq!(s.indices(), &[3, 0, 2, 2]);
    assert_eq!(s.weights(), &[0.75, 0.25, 1.0, 0.0]);
    assert_eq!(s.max_bone_index(), Some(3));
    assert_eq!(s.iter().len(), 2);
}

#[test]
fn rejects_weights_not_summing_to_one() {
    let e = SkinWeights::new(2, vec![0, 1, 0, 1], vec![0.5, 0.5, 0.5, 0.4]).unwrap_err();
    assert!(matches!(e, SkinError::WeightSum { vertex: 1, .. }), "{e:?}");
    assert!(e.to_string().contains("vertex 1"), "{e}");
    // Just outside and just inside the tolerance.
    assert!(SkinWeights::new(1, vec![0], vec![1.0 + 2e-4]).is_err());
    assert!(SkinWeights::new(1, vec![0], vec![1.0 + 5e-5]).is_ok());
    // All zero.
    assert!(matches!(
        SkinWeights::new(3, vec![0; 3], vec![0.0; 3]),
        Err(SkinError::WeightSum { vertex: 0, .. })
    ));
}

#[test]
fn rejects_negative_and_non_finite_weights() {
    let e = SkinWeights::new(3, vec![0; 6], vec![1.0, 0.0, 0.0, 1.5, -0.5, 0.0]).unwrap_err();
    assert!(
        matches!(
            e,
            SkinError::NegativeWeight {
                vertex: 1,
                slot: 1,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains(">= 0"), "{e}");
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let e = SkinWeights::new(2, vec![0; 4], vec![1.0, 0.0, bad, 1.0]).unwrap_err();
        assert!(
            matches!(
                e,
                SkinError::NonFiniteWeight {
                    vertex: 1,
                    slot: 0,
                    ..
                }
            ),
            "{e:?}"
        );
    }
}

#[test]
fn rejects_bad_k_and_lengths() {
    assert_eq!(
        SkinWeights::new(0, vec![], vec![]).unwrap_err(),
        SkinError::BadK { k: 0 }
    );
    assert_eq!(
        SkinWeights::new(9, vec![0; 9], vec![1.0 / 9.0; 9]).unwrap_err(),
        SkinError::BadK { k: 9 }
    );
    assert!(matches!(
        SkinWeights::new(4, vec![0; 6], vec![0.25; 6]),
        Err(SkinError::BadLength { .. })
    ));
    assert!(matches!(
        SkinWeights::new(1, vec![0; 2], vec![1.0; 3]),
        Err(SkinError::BadLength { .. })
    ));
}

#[test]
fn validate_bones_names_the_slot() {
    let s = SkinWeights::new(2, vec![0, 1, 4, 0], vec![0.5, 0.5, 0.0, 1.0]).unwrap();
    assert!(s.validate_bones(5).is_ok());
    // Zero-weight slots count too: a shader reads them.
    let e = s.validate_bones(4).unwrap_err();
    // Slot 1: the zero-weight slot sorts after the weight-1 slot.
    assert_eq!(
        e,
        SkinError::BoneOutOfRange {
            vertex: 1,
            slot: 1,
            bone: 4,
            bone_count: 4
        }
    );
    assert!(e.to_string().contains("vertex 1"), "{e}");
}

#[test]
fn slots_are_sorted_heaviest_first_and_stable_on_ties() {
    let s = SkinWeights::new(
        4,
        vec![1, 2, 3, 4, 5, 6, 7, 8],
        vec![0.1, 0.2, 0.3, 0.4, 0.0, 0.5, 0.0, 0.5],
    )
    .unwrap();
    assert_eq!(
        s.vertex(0),
        (&[4u32, 3, 2, 1][..], &[0.4f32, 0.3, 0.2, 0.1][..])
    );
    assert_eq!(
        s.vertex(1),
        (&[6u32, 8, 5, 7][..], &[0.5f32, 0.5, 0.0, 0.0][..])
    );
}
