//! Edge skinning weights (FKY08 eq. 10) against cases with a known answer: a rig whose bones
//! all share one rotation per frame (any weights fit exactly), an edge generated from known
//! weights (recovered), a zero-length edge (endpoint blend), and random data where the fit must
//! beat the endpoints' averaged weights. The objective is recomputed here from its definition.

use crate::common;
use crease_core::glam::{DVec3, Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::runtime::skin::SkinWeights;
use crease_train::edges::{EdgeWeightError, fit_edge_weights, try_fit_edge_weights};
use rand::{Rng, SeedableRng, rngs::StdRng};

fn random_rotation(rng: &mut StdRng) -> Quat {
    let axis = Vec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    Quat::from_axis_angle(axis.normalize_or(Vec3::Z), rng.random_range(-2.5..2.5))
}

/// `k` distinct random bones per vertex with random weights.
fn random_skin(rng: &mut StdRng, n: usize, k: usize, bones: u32) -> SkinWeights {
    let mut indices = Vec::new();
    let mut weights = Vec::new();
    for _ in 0..n {
        let mut picked: Vec<u32> = Vec::new();
        while picked.len() < k {
            let b = rng.random_range(0..bones);
            if !picked.contains(&b) {
                picked.push(b);
            }
        }
        let w: Vec<f32> = (0..k).map(|_| rng.random::<f32>() + 0.05).collect();
        let s: f32 = w.iter().sum();
        indices.extend(picked);
        weights.extend(w.iter().map(|x| x / s));
    }
    SkinWeights::new(k, indices, weights).unwrap()
}

/// Eq. 10 for one edge and one weight row, straight from the definition, in f64.
fn edge_error(
    rest: &[Vec3],
    frames: &[Vec<Vec3>],
    rotations: &[Vec<Quat>],
    edge: [u32; 2],
    bones: &[u32],
    weights: &[f64],
) -> f64 {
    let [a, b] = edge.map(|v| v as usize);
    let e0 = (rest[a] - rest[b]).as_dvec3();
    let mut err = 0.0;
    for (frame, rot) in frames.iter().zip(rotations) {
        let ej = (frame[a] - frame[b]).as_dvec3();
        let mut pred = DVec3::ZERO;
        for (&bone, &w) in bones.iter().zip(weights) {
            pred += w * (rot[bone as usize].as_dquat() * e0);
        }
        err += (ej - pred).length_squared();
    }
    err
}

/// The endpoints' averaged weights as (bones, weights).
fn averaged(skin: &SkinWeights, edge: [u32; 2]) -> (Vec<u32>, Vec<f64>) {
    let mut bones: Vec<u32> = Vec::new();
    let mut w: Vec<f64> = Vec::new();
    for v in edge {
        let (idx, ws) = skin.vertex(v as usize);
        for (&b, &x) in idx.iter().zip(ws) {
            if x > 0.0 {
                match bones.iter().position(|&c| c == b) {
                    Some(p) => w[p] += 0.5 * x as f64,
                    None => {
                        bones.push(b);
                        w.push(0.5 * x as f64);
                    }
                }
            }
        }
    }
    (bones, w)
}

/// Non-negative, sums to one, at most `k` non-zero, only bones of the endpoints.
fn check_constraints(skin: &SkinWeights, edge_skin: &SkinWeights, edges: &[[u32; 2]], k: usize) {
    assert_eq!(edge_skin.vertex_count(), edges.len());
    assert_eq!(edge_skin.k(), k);
    for (e, &edge) in edges.iter().enumerate() {
        let (idx, w) = edge_skin.vertex(e);
        let sum: f32 = w.iter().sum();
        assert!((sum - 1.0).abs() < 1e-5, "edge {e}: sum {sum}");
        assert!(w.iter().all(|&x| x >= 0.0), "edge {e}: {w:?}");
        assert!(w.iter().filter(|&&x| x > 0.0).count() <= k);
        let (cands, _) = averaged(skin, edge);
        for (&b, &x) in idx.iter().zip(w) {
            if x > 0.0 {
                assert!(
                    cands.contains(&b),
                    "edge {e}: bone {b} not on its endpoints {cands:?}"
                );
            }
        }
    }
}

fn frame_refs(frames: &[Vec<Vec3>]) -> Vec<&[Vec3]> {
    frames.iter().map(|f| f.as_slice()).collect()
}

fn weighted(edge_skin: &SkinWeights, e: usize) -> (Vec<u32>, Vec<f64>) {
    let (idx, w) = edge_skin.vertex(e);
    (idx.to_vec(), w.iter().map(|&x| x as f64).collect())
}

#[test]
fn shared_rotation_per_frame_is_fitted_exactly() {
    let mut rng = StdRng::seed_from_u64(1);
    let mesh = common::tube(6, 8, 2.0);
    let edges = mesh.edges();
    let bones = 5;
    let skin = random_skin(&mut rng, mesh.vertex_count(), 2, bones);
    let mut frames = Vec::new();
    let mut rotations = Vec::new();
    for _ in 0..5 {
        let r = random_rotation(&mut rng);
        let t = Vec3::new(rng.random(), rng.random(), rng.random());
        frames.push(
            mesh.positions
                .iter()
                .map(|&p| r * p + t)
                .collect::<Vec<_>>(),
        );
        rotations.push(vec![r; bones as usize]);
    }
    let edge_skin = fit_edge_weights(&mesh, &edges, &frame_refs(&frames), &rotations, &skin, 2);
    check_constraints(&skin, &edge_skin, &edges, 2);
    for (e, &edge) in edges.iter().enumerate() {
        let (b, w) = weighted(&edge_skin, e);
        let err = edge_error(&mesh.positions, &frames, &rotations, edge, &b, &w);
        assert!(err < 1e-9, "edge {e}: residual {err}");
    }
}

#[test]
fn weights_that_generated_an_edge_are_recovered() {
    // Two vertices, one edge; the edge moves by known weights over bones 0, 1, 2 (bones of its
    // endpoints), the endpoints themselves are placed arbitrarily.
    let mut rng = StdRng::seed_from_u64(2);
    let rest = vec![Vec3::new(0.3, -0.2, 0.1), Vec3::new(1.0, 0.4, -0.5)];
    let mesh = Mesh {
        positions: rest.clone(),
        triangles: Vec::new(),
    };
    let skin = SkinWeights::new(2, vec![0, 1, 1, 2], vec![0.6, 0.4, 0.7, 0.3]).unwrap();
    let truth = [(0u32, 0.2f64), (1, 0.5), (2, 0.3)];
    let e0 = (rest[0] - rest[1]).as_dvec3();
    let mut frames = Vec::new();
    let mut rotations = Vec::new();
    for _ in 0..6 {
        let rot: Vec<Quat> = (0..4).map(|_| random_rotation(&mut rng)).collect();
        let e: DVec3 = truth
            .iter()
            .map(|&(b, w)| w * (rot[b as usize].as_dquat() * e0))
            .sum();
        let v0 = Vec3::new(rng.random(), rng.random(), rng.random());
        frames.push(vec![v0, v0 - e.as_vec3()]);
        rotations.push(rot);
    }
    let edges = [[0u32, 1]];
    let edge_skin = fit_edge_weights(&mesh, &edges, &frame_refs(&frames), &rotations, &skin, 3);
    check_constraints(&skin, &edge_skin, &edges, 3);
    let (idx, w) = edge_skin.vertex(0);
    for &(b, want) in &truth {
        let got: f32 = idx
            .iter()
            .zip(w)
            .filter(|(i, _)| **i == b)
            .map(|(_, w)| *w)
            .sum();
        assert!(
            (got as f64 - want).abs() < 1e-4,
            "bone {b}: {got} vs {want}"
        );
    }
}

#[test]
fn fit_beats_the_endpoint_blend_on_random_data() {
    let mut rng = StdRng::seed_from_u64(3);
    let mesh = common::tube(8, 10, 2.0);
    let edges = mesh.edges();
    let bones = 6u32;
    let skin = random_skin(&mut rng, mesh.vertex_count(), 2, bones);
    let mut frames = Vec::new();
    let mut rotations = Vec::new();
    for _ in 0..7 {
        let rot: Vec<Quat> = (0..bones).map(|_| random_rotation(&mut rng)).collect();
        frames.push(
            mesh.positions
                .iter()
                .map(|&p| rot[0] * p + 0.2 * Vec3::new(rng.random(), rng.random(), rng.random()))
                .collect::<Vec<_>>(),
        );
        rotations.push(rot);
    }
    let refs = frame_refs(&frames);
    // K = 4 admits the blend of two 2-bone endpoints, so the fit may never be worse.
    let edge_skin = fit_edge_weights(&mesh, &edges, &refs, &rotations, &skin, 4);
    check_constraints(&skin, &edge_skin, &edges, 4);
    let mut better = 0;
    for (e, &edge) in edges.iter().enumerate() {
        let (b, w) = weighted(&edge_skin, e);
        let fit = edge_error(&mesh.positions, &frames, &rotations, edge, &b, &w);
        let (ab, aw) = averaged(&skin, edge);
        let blend = edge_error(&mesh.positions, &frames, &rotations, edge, &ab, &aw);
        assert!(
            fit <= blend * (1.0 + 1e-5) + 1e-9,
            "edge {e}: fit {fit} > blend {blend}"
        );
        if fit < 0.9 * blend {
            better += 1;
        }
    }
    assert!(
        better * 2 > edges.len(),
        "the QP improved only {better} of {} edges",
        edges.len()
    );

    // K = 1: one bone per edge, still one of the endpoints'.
    let one = fit_edge_weights(&mesh, &edges, &refs, &rotations, &skin, 1);
    check_constraints(&skin, &one, &edges, 1);
}

#[test]
fn zero_length_edge_gets_the_endpoint_blend() {
    let mut rng = StdRng::seed_from_u64(4);
    let mut mesh = common::tube(4, 6, 2.0);
    mesh.positions[1] = mesh.positions[0];
    let edges = vec![[0u32, 1], [1, 2]];
    let skin = random_skin(&mut rng, mesh.vertex_count(), 2, 4);
    let mut frames = Vec::new();
    let mut rotations = Vec::new();
    for _ in 0..3 {
        let rot: Vec<Quat> = (0..4).map(|_| random_rotation(&mut rng)).collect();
        frames.push(
            mesh.positions
                .iter()
                .map(|&p| rot[1] * p)
                .collect::<Vec<_>>(),
        );
        rotations.push(rot);
    }
    let edge_skin = fit_edge_weights(&mesh, &edges, &frame_refs(&frames), &rotations, &skin, 4);
    check_constraints(&skin, &edge_skin, &edges, 4);
    let (ab, aw) = averaged(&skin, [0, 1]);
    let (idx, w) = edge_skin.vertex(0);
    for (&b, &want) in ab.iter().zip(&aw) {
        let p = idx.iter().position(|&i| i == b).unwrap();
        assert!(
            (w[p] as f64 - want).abs() < 1e-6,
            "bone {b}: {} vs {want}",
            w[p]
        );
    }
}

#[test]
fn inconsistent_inputs_are_errors() {
    let mut rng = StdRng::seed_from_u64(5);
    let mesh = common::tube(3, 4, 2.0);
    let n = mesh.vertex_count();
    let edges = mesh.edges();
    let skin = random_skin(&mut rng, n, 2, 3);
    let frames = vec![mesh.positions.clone(); 2];
    let rotations = vec![vec![Quat::IDENTITY; 3]; 2];
    let refs = frame_refs(&frames);
    let p = &mesh.positions;

    let e = try_fit_edge_weights(p, &edges, &refs, &rotations[..1], &skin, 2).unwrap_err();
    assert!(e.to_string().contains("expected 2, got 1"), "{e}");

    let short = [p.as_slice(), &p[..5]];
    let e = try_fit_edge_weights(p, &edges, &short, &rotations, &skin, 2).unwrap_err();
    assert!(e.to_string().starts_with("frame 1 vertices"), "{e}");

    let few_bones = vec![vec![Quat::IDENTITY; 2]; 2];
    let e = try_fit_edge_weights(p, &edges, &refs, &few_bones, &skin, 2).unwrap_err();
    assert!(matches!(e, EdgeWeightError::Skin(_)), "{e}");

    let bad_edges = [[0u32, 99]];
    assert_eq!(
        try_fit_edge_weights(p, &bad_edges, &refs, &rotations, &skin, 2),
        Err(EdgeWeightError::EdgeOutOfRange {
            edge: 0,
            vertex: 99,
            vertex_count: n
        })
    );

    for k in [0, 9] {
        assert_eq!(
            try_fit_edge_weights(p, &edges, &refs, &rotations, &skin, k),
            Err(EdgeWeightError::BadK { k })
        );
    }

    let mut nan = frames.clone();
    nan[1][3].z = f32::NAN;
    let e = try_fit_edge_weights(p, &edges, &frame_refs(&nan), &rotations, &skin, 2).unwrap_err();
    assert!(e.to_string().contains("frame 1 vertex 3"), "{e}");
}
