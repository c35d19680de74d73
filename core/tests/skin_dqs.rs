//! Dual quaternion skinning against analytically known cases.

use crease_core::glam::{EulerRot, Quat, Vec3};
use crease_core::runtime::skin::{BonePalette, RigidTransform, SkinWeights, skin_dqs, skin_lbs};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn points(rng: &mut StdRng, n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
            )
        })
        .collect()
}

/// Every vertex blends bones 0..k with random weights.
fn blend_all(rng: &mut StdRng, n: usize, k: usize) -> SkinWeights {
    let mut w = Vec::new();
    for _ in 0..n {
        let raw: Vec<f32> = (0..k).map(|_| rng.random::<f32>() + 0.05).collect();
        let s: f32 = raw.iter().sum();
        w.extend(raw.iter().map(|x| x / s));
    }
    SkinWeights::new(k, (0..n).flat_map(|_| 0..k as u32).collect(), w).unwrap()
}

fn assert_close(got: &[Vec3], want: impl Iterator<Item = Vec3>, tol: f32) {
    for (v, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (*g - w).length() <= tol * (1.0 + w.length()),
            "vertex {v}: {g} vs {w}"
        );
    }
}

#[test]
fn dqs_of_one_shared_rotation_is_that_rotation() {
    let mut rng = StdRng::seed_from_u64(1);
    let n = 1500;
    let rest = points(&mut rng, n);
    let q = Quat::from_axis_angle(Vec3::new(0.3, -0.8, 0.5).normalize(), 2.4);
    let bones = [RigidTransform::new(q, Vec3::ZERO); 4];
    let skin = blend_all(&mut rng, n, 4);
    let mut out = vec![Vec3::ZERO; n];
    skin_dqs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut out,
    )
    .unwrap();
    assert_close(&out, rest.iter().map(|&p| q * p), 1e-5);
}

#[test]
fn dqs_single_bone_per_vertex_is_rigid() {
    let mut rng = StdRng::seed_from_u64(2);
    let rest = points(&mut rng, 64);
    let t = RigidTransform::new(
        Quat::from_euler(EulerRot::XYZ, 0.4, -1.9, 2.8),
        Vec3::new(5.0, -1.0, 0.25),
    );
    let skin = SkinWeights::new(1, vec![0; rest.len()], vec![1.0; rest.len()]).unwrap();
    let mut out = vec![Vec3::ZERO; rest.len()];
    skin_dqs(&rest, &skin, &BonePalette::from_transforms(&[t]), &mut out).unwrap();
    assert_close(&out, rest.iter().map(|&p| t.transform_point(p)), 1e-5);
}

#[test]
fn dqs_is_sign_invariant_per_bone() {
    // Bones 0 and 1 hold the same rotation as q and -q. Without the hemisphere fix their blend
    // would cancel; with it the result is the rotation itself.
    let mut rng = StdRng::seed_from_u64(3);
    let n = 200;
    let rest = points(&mut rng, n);
    let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 1.3);
    let t = Vec3::new(0.5, -0.25, 2.0);
    let bones = [RigidTransform::new(q, t), RigidTransform::new(-q, t)];
    // Weights (0.5, 0.5) exactly: the case where naive blending gives a zero quaternion.
    let skin = SkinWeights::new(2, [0, 1].repeat(n), vec![0.5; 2 * n]).unwrap();
    let mut out = vec![Vec3::ZERO; n];
    skin_dqs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut out,
    )
    .unwrap();
    assert_close(&out, rest.iter().map(|&p| q * p + t), 1e-5);

    // Mixed weights where the negated bone carries the most weight (it becomes the pivot).
    let skin = blend_all(&mut rng, n, 2);
    skin_dqs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut out,
    )
    .unwrap();
    assert_close(&out, rest.iter().map(|&p| q * p + t), 1e-5);
}

#[test]
fn dqs_blends_coaxial_rotations_by_normalised_quaternion_blend() {
    // Two rotations about one axis through the origin, angles a and b, weights w and 1 - w. The
    // blended unit quaternion is a rotation about the same axis by
    // 2 atan2(w sin(a/2) + (1-w) sin(b/2), w cos(a/2) + (1-w) cos(b/2)).
    let axis = Vec3::new(-0.2, 0.9, 0.4).normalize();
    let (a, b) = (0.3f32, 2.9f32);
    let bones = [
        RigidTransform::new(Quat::from_axis_angle(axis, a), Vec3::ZERO),
        RigidTransform::new(Quat::from_axis_angle(axis, b), Vec3::ZERO),
    ];
    let p = Vec3::new(1.0, 0.5, -2.0);
    for w in [0.0f32, 0.1, 0.25, 0.5, 0.8, 1.0] {
        let skin = SkinWeights::new(2, vec![0, 1], vec![w, 1.0 - w]).unwrap();
        let mut out = [Vec3::ZERO];
        skin_dqs(&[p], &skin, &BonePalette::from_transforms(&bones), &mut out).unwrap();
        let s = w * (a / 2.0).sin() + (1.0 - w) * (b / 2.0).sin();
        let c = w * (a / 2.0).cos() + (1.0 - w) * (b / 2.0).cos();
        let want = Quat::from_axis_angle(axis, 2.0 * s.atan2(c)) * p;
        assert!(
            (out[0] - want).length() < 1e-5,
            "w {w}: {} vs {want}",
            out[0]
        );
    }
}

#[test]
fn dqs_of_pure_translations_is_their_weighted_mean() {
    let mut rng = StdRng::seed_from_u64(4);
    let n = 300;
    let rest = points(&mut rng, n);
    let bones: Vec<RigidTransform> = (0..3)
        .map(|i| {
            RigidTransform::new(
                Quat::IDENTITY,
                Vec3::new(i as f32, 2.0 - i as f32, 0.5 * i as f32),
            )
        })
        .collect();
    let skin = blend_all(&mut rng, n, 3);
    let mut out = vec![Vec3::ZERO; n];
    skin_dqs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut out,
    )
    .unwrap();
    let want = (0..n).map(|v| {
        let (ii, ww) = skin.vertex(v);
        rest[v]
            + ii.iter()
                .zip(ww)
                .map(|(&b, &w)| w * bones[b as usize].translation)
                .sum::<Vec3>()
    });
    assert_close(&out, want, 1e-5);
    // LBS agrees on pure translations.
    let mut lbs = vec![Vec3::ZERO; n];
    skin_lbs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut lbs,
    )
    .unwrap();
    assert_close(&out, lbs.into_iter(), 1e-5);
}

#[test]
fn dqs_preserves_distance_to_a_shared_rotation_centre() {
    // Bones rotating about one common centre c by different rotations: DQS blends to another
    // rotation about c, so |p' - c| = |p - c| (LBS would shrink it: the candy-wrapper effect).
    let mut rng = StdRng::seed_from_u64(5);
    let c = Vec3::new(1.0, -1.0, 2.0);
    let bones: Vec<RigidTransform> = (0..4)
        .map(|i| {
            let q = Quat::from_axis_angle(
                Vec3::new(1.0, i as f32, 0.5).normalize(),
                0.7 * i as f32 + 0.2,
            );
            RigidTransform::new(q, c - q * c)
        })
        .collect();
    let n = 400;
    let rest = points(&mut rng, n);
    let skin = blend_all(&mut rng, n, 4);
    let mut out = vec![Vec3::ZERO; n];
    skin_dqs(
        &rest,
        &skin,
        &BonePalette::from_transforms(&bones),
        &mut out,
    )
    .unwrap();
    for (o, r) in out.iter().zip(&rest) {
        assert!(
            ((*o - c).length() - (*r - c).length()).abs() < 1e-4,
            "{o} {r}"
        );
    }
}
