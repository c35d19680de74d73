//! Linear blend skinning against an independent per-vertex computation in f64 with 4x4
//! homogeneous matrices (blending transformed points, not matrices).

use crease_core::glam::{DMat4, DVec3, Quat, Vec3};
use crease_core::runtime::skin::{BonePalette, RigidTransform, SkinWeights, skin_lbs};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn random_transform(rng: &mut StdRng) -> RigidTransform {
    let axis = loop {
        let a = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if a.length() > 0.1 {
            break a.normalize();
        }
    };
    RigidTransform::new(
        Quat::from_axis_angle(axis, rng.random_range(-3.1..3.1)),
        Vec3::new(
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
            rng.random_range(-2.0..2.0),
        ),
    )
}

/// `n` vertices with `k` random bones each (repeats allowed) and random weights, one slot in
/// five forced to zero weight.
fn random_skin(rng: &mut StdRng, n: usize, k: usize, bones: u32) -> SkinWeights {
    let mut indices = Vec::with_capacity(n * k);
    let mut weights = Vec::with_capacity(n * k);
    for _ in 0..n {
        let mut w: Vec<f32> = (0..k)
            .map(|_| {
                if rng.random_range(0..5) == 0 {
                    0.0
                } else {
                    rng.random::<f32>() + 0.01
                }
            })
            .collect();
        if w.iter().all(|&x| x == 0.0) {
            w[0] = 1.0;
        }
        let s: f32 = w.iter().sum();
        weights.extend(w.iter().map(|x| x / s));
        indices.extend((0..k).map(|_| rng.random_range(0..bones)));
    }
    SkinWeights::new(k, indices, weights).unwrap()
}

/// Independent LBS: sum_j w_j (M_j p) in f64.
fn reference_lbs(rest: &[Vec3], skin: &SkinWeights, bones: &[RigidTransform]) -> Vec<DVec3> {
    let mats: Vec<DMat4> = bones
        .iter()
        .map(|b| {
            DMat4::from_rotation_translation(
                b.rotation.as_dquat().normalize(),
                b.translation.as_dvec3(),
            )
        })
        .collect();
    rest.iter()
        .enumerate()
        .map(|(v, p)| {
            let (ii, ww) = skin.vertex(v);
            ii.iter()
                .zip(ww)
                .map(|(&b, &w)| w as f64 * mats[b as usize].transform_point3(p.as_dvec3()))
                .sum()
        })
        .collect()
}

#[test]
fn lbs_matches_reference_for_every_k() {
    let mut rng = StdRng::seed_from_u64(7);
    // More vertices than one parallel chunk, and not a multiple of it.
    let n = 2500;
    let bones: Vec<RigidTransform> = (0..37).map(|_| random_transform(&mut rng)).collect();
    let rest: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            )
        })
        .collect();
    let palette = BonePalette::from_transforms(&bones);
    for k in 1..=8 {
        let skin = random_skin(&mut rng, n, k, bones.len() as u32);
        let mut out = vec![Vec3::splat(f32::NAN); n];
        skin_lbs(&rest, &skin, &palette, &mut out).unwrap();
        let want = reference_lbs(&rest, &skin, &bones);
        for (v, (got, want)) in out.iter().zip(&want).enumerate() {
            let err = (got.as_dvec3() - *want).length();
            assert!(
                err < 2e-5 * (1.0 + want.length()),
                "k {k} vertex {v}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn lbs_with_identity_bones_returns_rest() {
    let mut rng = StdRng::seed_from_u64(3);
    let rest: Vec<Vec3> = (0..100)
        .map(|i| Vec3::new(i as f32, -(i as f32), 0.5))
        .collect();
    let skin = random_skin(&mut rng, rest.len(), 4, 5);
    let palette = BonePalette::from_transforms(&[RigidTransform::IDENTITY; 5]);
    let mut out = vec![Vec3::ZERO; rest.len()];
    skin_lbs(&rest, &skin, &palette, &mut out).unwrap();
    for (o, r) in out.iter().zip(&rest) {
        assert!(
            (*o - *r).length() <= 1e-5 * (1.0 + r.length()),
            "{o} vs {r}"
        );
    }
}

#[test]
fn palette_update_reuses_and_replaces() {
    let mut rng = StdRng::seed_from_u64(11);
    let rest = vec![Vec3::new(1.0, 2.0, 3.0)];
    let skin = SkinWeights::new(1, vec![1], vec![1.0]).unwrap();
    let mut palette = BonePalette::new();
    let mut out = [Vec3::ZERO];
    for _ in 0..3 {
        let bones = [random_transform(&mut rng), random_transform(&mut rng)];
        palette.update(&bones);
        assert_eq!(palette.len(), 2);
        skin_lbs(&rest, &skin, &palette, &mut out).unwrap();
        assert!((out[0] - bones[1].transform_point(rest[0])).length() < 1e-5);
    }
}
