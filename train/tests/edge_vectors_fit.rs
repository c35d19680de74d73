//! The vector edge skin (`e_k = sum_b R_b a_kb`, `crease_train::edges::fit_edge_vectors`)
//! against independent computations: vectors that generated the data are recovered; a fixed
//! ridge gives the dense nalgebra solution of the regularised least-squares problem written
//! out from its definition; an infinite ridge gives the endpoints' blend; and the
//! cross-validation prefers the vectors over the scalar blend when the data has stretch the
//! blend cannot express.

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::skin::SkinWeights;
use crease_train::edges::{EDGE_RIDGES, EdgeWeightError, fit_edge_vectors};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng, rngs::StdRng};

fn random_rotation(rng: &mut StdRng) -> Quat {
    let axis = Vec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    Quat::from_axis_angle(axis.normalize_or(Vec3::Z), rng.random_range(-2.5..2.5))
}

fn random_vec(rng: &mut StdRng) -> Vec3 {
    Vec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
}

/// `m` separate edges (vertices `2i`, `2i + 1`); vertex `2i` on bones `(a, b)` with weights
/// `(0.6, 0.4)`, vertex `2i + 1` on bone `a` alone: each edge's support is `{a, b}`.
struct Rig {
    rest: Vec<Vec3>,
    edges: Vec<[u32; 2]>,
    skin: SkinWeights,
    /// Per edge, its two bones.
    pairs: Vec<[u32; 2]>,
}

fn rig(rng: &mut StdRng, m: usize, bones: u32) -> Rig {
    let mut rest = Vec::new();
    let mut edges = Vec::new();
    let mut indices = Vec::new();
    let mut weights = Vec::new();
    let mut pairs = Vec::new();
    for i in 0..m {
        let a = rng.random_range(0..bones);
        let b = (a + 1 + rng.random_range(0..bones - 1)) % bones;
        let p = random_vec(rng) * 3.0;
        rest.push(p + random_vec(rng));
        rest.push(p);
        edges.push([2 * i as u32, 2 * i as u32 + 1]);
        indices.extend([a, b, a, b]);
        weights.extend([0.6, 0.4, 1.0, 0.0]);
        pairs.push([a, b]);
    }
    Rig {
        rest,
        edges,
        skin: SkinWeights::new(2, indices, weights).unwrap(),
        pairs,
    }
}

/// Frames where edge `i` is exactly `sum_b R_b^j a_ib` (vertex `2i+1` at the origin).
fn frames_from_vectors(rig: &Rig, rotations: &[Vec<Quat>], a: &[[Vec3; 2]]) -> Vec<Vec<Vec3>> {
    rotations
        .iter()
        .map(|rot| {
            let mut f = vec![Vec3::ZERO; rig.rest.len()];
            for (i, pair) in rig.pairs.iter().enumerate() {
                f[2 * i] = rot[pair[0] as usize] * a[i][0] + rot[pair[1] as usize] * a[i][1];
            }
            f
        })
        .collect()
}

/// The fitted vector of `bone` on edge `e`.
fn vector_of(skin: &crease_core::runtime::edge_skin::EdgeSkin, e: usize, bone: u32) -> Vec3 {
    let (idx, v) = skin.edge(e);
    idx.iter()
        .zip(v)
        .filter(|(b, _)| **b == bone)
        .map(|(_, v)| *v)
        .sum()
}

#[test]
fn generating_vectors_are_recovered() {
    let mut rng = StdRng::seed_from_u64(11);
    let bones = 4u32;
    let rig = rig(&mut rng, 20, bones);
    let a: Vec<[Vec3; 2]> = (0..20)
        .map(|_| [random_vec(&mut rng), random_vec(&mut rng)])
        .collect();
    let rotations: Vec<Vec<Quat>> = (0..12)
        .map(|_| (0..bones).map(|_| random_rotation(&mut rng)).collect())
        .collect();
    let frames = frames_from_vectors(&rig, &rotations, &a);
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let (skin, report) = fit_edge_vectors(
        &rig.rest,
        &rig.edges,
        &refs,
        &rotations,
        &rig.skin,
        2,
        Some(0.0),
    )
    .unwrap();
    assert_eq!(report.ridge, 0.0);
    for (i, pair) in rig.pairs.iter().enumerate() {
        for (s, &bone) in pair.iter().enumerate() {
            let got = vector_of(&skin, i, bone);
            assert!(
                (got - a[i][s]).length() < 1e-4,
                "edge {i} bone {bone}: {got} vs {}",
                a[i][s]
            );
        }
    }
}

#[test]
fn fixed_ridge_matches_dense_regularised_least_squares() {
    let mut rng = StdRng::seed_from_u64(12);
    let bones = 3u32;
    let rig = rig(&mut rng, 6, bones);
    let nf = 5;
    let rotations: Vec<Vec<Quat>> = (0..nf)
        .map(|_| (0..bones).map(|_| random_rotation(&mut rng)).collect())
        .collect();
    // Arbitrary frames: no vector model fits them exactly.
    let frames: Vec<Vec<Vec3>> = (0..nf)
        .map(|_| (0..rig.rest.len()).map(|_| random_vec(&mut rng)).collect())
        .collect();
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let ridge = 0.3;
    let (skin, _) = fit_edge_vectors(
        &rig.rest,
        &rig.edges,
        &refs,
        &rotations,
        &rig.skin,
        2,
        Some(ridge),
    )
    .unwrap();
    for (i, pair) in rig.pairs.iter().enumerate() {
        // Unknowns [a_0; a_1]; rows: 3 per frame (R_0 a_0 + R_1 a_1 = e^j), then the ridge
        // rows sqrt(lambda) (a_b - w_b e^0) with the endpoints' averaged weights (0.8, 0.2).
        let e0 = rig.rest[2 * i] - rig.rest[2 * i + 1];
        let lambda = ridge * nf as f64;
        let mut m = DMatrix::<f64>::zeros(3 * nf + 6, 6);
        let mut y = DVector::<f64>::zeros(3 * nf + 6);
        for j in 0..nf {
            let e = frames[j][2 * i] - frames[j][2 * i + 1];
            for (s, &bone) in pair.iter().enumerate() {
                let r = crease_core::glam::Mat3::from_quat(rotations[j][bone as usize]);
                for row in 0..3 {
                    for col in 0..3 {
                        m[(3 * j + row, 3 * s + col)] = r.col(col)[row] as f64;
                    }
                }
            }
            for row in 0..3 {
                y[3 * j + row] = e[row] as f64;
            }
        }
        let prior = [e0 * 0.8, e0 * 0.2];
        for s in 0..2 {
            for c in 0..3 {
                m[(3 * nf + 3 * s + c, 3 * s + c)] = lambda.sqrt();
                y[3 * nf + 3 * s + c] = lambda.sqrt() * prior[s][c] as f64;
            }
        }
        let want = m.svd(true, true).solve(&y, 1e-12).unwrap();
        for (s, &bone) in pair.iter().enumerate() {
            let got = vector_of(&skin, i, bone);
            for c in 0..3 {
                assert!(
                    (got[c] as f64 - want[3 * s + c]).abs() < 1e-4,
                    "edge {i} bone {bone}: {got} vs dense {:?}",
                    &want.as_slice()[3 * s..3 * s + 3]
                );
            }
        }
    }
}

#[test]
fn infinite_ridge_is_the_endpoint_blend_and_cv_prefers_vectors_on_stretch() {
    let mut rng = StdRng::seed_from_u64(13);
    let bones = 4u32;
    let rig = rig(&mut rng, 40, bones);
    // Edges that stretch with the pose: vectors of different lengths per bone.
    let a: Vec<[Vec3; 2]> = (0..40)
        .map(|_| [random_vec(&mut rng) * 2.0, random_vec(&mut rng) * 0.5])
        .collect();
    let rotations: Vec<Vec<Quat>> = (0..15)
        .map(|_| (0..bones).map(|_| random_rotation(&mut rng)).collect())
        .collect();
    let mut frames = frames_from_vectors(&rig, &rotations, &a);
    for f in &mut frames {
        for p in f.iter_mut() {
            *p += random_vec(&mut rng) * 0.01;
        }
    }
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();

    let (blend, _) = fit_edge_vectors(
        &rig.rest,
        &rig.edges,
        &refs,
        &rotations,
        &rig.skin,
        2,
        Some(f64::INFINITY),
    )
    .unwrap();
    for (i, pair) in rig.pairs.iter().enumerate() {
        let e0 = rig.rest[2 * i] - rig.rest[2 * i + 1];
        assert!((vector_of(&blend, i, pair[0]) - e0 * 0.8).length() < 1e-5);
        assert!((vector_of(&blend, i, pair[1]) - e0 * 0.2).length() < 1e-5);
    }

    let (_, report) =
        fit_edge_vectors(&rig.rest, &rig.edges, &refs, &rotations, &rig.skin, 2, None).unwrap();
    assert_eq!(report.cv.len(), EDGE_RIDGES.len());
    let at = |r: f64| report.cv.iter().find(|c| c.0 == r).unwrap().1;
    assert!(report.ridge.is_finite(), "{report:?}");
    assert!(
        at(report.ridge) < 0.5 * at(f64::INFINITY),
        "vectors should beat the blend on held-out frames: {report:?}"
    );
    assert!(report.cv.iter().all(|c| c.1 >= at(report.ridge)));
}

#[test]
fn bad_ridge_and_sizes_are_errors() {
    let mut rng = StdRng::seed_from_u64(14);
    let rig = rig(&mut rng, 3, 3);
    let rotations = vec![vec![Quat::IDENTITY; 3]; 2];
    let frames = [rig.rest.clone(), rig.rest.clone()];
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let e = fit_edge_vectors(
        &rig.rest,
        &rig.edges,
        &refs,
        &rotations,
        &rig.skin,
        2,
        Some(-1.0),
    )
    .unwrap_err();
    assert!(e.to_string().contains("ridge"), "{e}");
    let e = fit_edge_vectors(
        &rig.rest,
        &rig.edges,
        &refs[..1],
        &rotations,
        &rig.skin,
        2,
        None,
    )
    .unwrap_err();
    assert!(matches!(e, EdgeWeightError::Size { .. }), "{e}");
}
