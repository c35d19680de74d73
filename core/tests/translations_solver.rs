//! The Poisson translation solver (FKY08 eq. 11) against an independent dense least-squares
//! solve (the full `3 (n_e + n_c) x 3 n_b` system assembled edge by edge and solved by SVD in
//! f64), an analytically known rigid case, and its input checks. The edge skin is a general
//! vector skin (`e_k^s = sum_b R_b a_kb`), not just FKY08's scalar weights.

use crease_core::glam::{Mat3A, Quat, Vec3};
use crease_core::runtime::skin::RigidTransform;
use crease_core::runtime::translations::{TranslationError, TranslationSolver};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::common;
use common::rig::{Problem, dense_weights, problem, random_point, random_rotation};

fn rotation_f64(q: Quat) -> nalgebra::Matrix3<f64> {
    let m = Mat3A::from_quat(q).to_cols_array();
    nalgebra::Matrix3::from_column_slice(&m.map(|x| x as f64))
}

fn v64(p: Vec3) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::new(p.x as f64, p.y as f64, p.z as f64)
}

impl Problem {
    /// Dense eq. 11 from scratch: unknown `x[3 b + c]`, three rows per edge and per control,
    /// solved by SVD (minimum-norm least squares). Returns the translations and the objective.
    fn dense_solve(&self, rotations: &[Quat], controls: &[Vec3], beta: f64) -> Vec<Vec3> {
        let nb = self.bones;
        let rows = 3 * (self.edges.len() + self.controls.len());
        let mut a = DMatrix::<f64>::zeros(rows, 3 * nb);
        let mut t = DVector::<f64>::zeros(rows);
        let rot: Vec<_> = rotations.iter().map(|&q| rotation_f64(q)).collect();
        let p = &self.mesh.positions;
        for (k, &[i0, i1]) in self.edges.iter().enumerate() {
            let w0 = dense_weights(&self.skin, i0 as usize, nb);
            let w1 = dense_weights(&self.skin, i1 as usize, nb);
            let (v0, v1) = (v64(p[i0 as usize]), v64(p[i1 as usize]));
            // (v0^s - v1^s) - e^s = sum_b (w0 - w1) t_b + [sum_b R_b (w0 v0 - w1 v1) - R_b a_kb]
            let mut known = nalgebra::Vector3::zeros();
            for b in 0..nb {
                known += rot[b] * (w0[b] * v0 - w1[b] * v1);
            }
            let (eb, ea) = self.edge_skin.edge(k);
            for (&b, &a) in eb.iter().zip(ea) {
                known -= rot[b as usize] * v64(a);
            }
            for c in 0..3 {
                for b in 0..nb {
                    a[(3 * k + c, 3 * b + c)] = w0[b] - w1[b];
                }
                t[3 * k + c] = -known[c];
            }
        }
        let base = 3 * self.edges.len();
        let sb = beta.sqrt();
        for (l, &i) in self.controls.iter().enumerate() {
            let w = dense_weights(&self.skin, i as usize, nb);
            let v = v64(p[i as usize]);
            let mut known = nalgebra::Vector3::zeros();
            for b in 0..nb {
                known += rot[b] * (w[b] * v);
            }
            for c in 0..3 {
                for b in 0..nb {
                    a[(base + 3 * l + c, 3 * b + c)] = sb * w[b];
                }
                t[base + 3 * l + c] = sb * (controls[l][c] as f64 - known[c]);
            }
        }
        let svd = a.svd(true, true);
        let eps = 1e-9 * svd.singular_values.max();
        let x = svd.solve(&t, eps).unwrap();
        (0..nb)
            .map(|b| Vec3::new(x[3 * b] as f32, x[3 * b + 1] as f32, x[3 * b + 2] as f32))
            .collect()
    }
}

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f32::max)
}

fn max_norm(a: &[Vec3]) -> f32 {
    a.iter().map(|x| x.abs().max_element()).fold(0.0, f32::max)
}

fn random_frame(rng: &mut StdRng, bones: usize, controls: usize) -> (Vec<Quat>, Vec<Vec3>) {
    let rotations = (0..bones).map(|_| random_rotation(rng)).collect();
    let controls = (0..controls).map(|_| random_point(rng, 2.0)).collect();
    (rotations, controls)
}

#[test]
fn sparse_solve_matches_dense_least_squares() {
    for (seed, beta) in [(1u64, 0.3f32), (2, 3.0)] {
        let pb = problem(seed, 5, 5);
        let solver = pb.solver(beta);
        let mut scratch = solver.scratch();
        let mut rng = StdRng::seed_from_u64(seed + 100);
        for frame in 0..3 {
            let (rot, ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
            let mut out = vec![Vec3::ZERO; pb.bones];
            solver.solve(&rot, &ctl, &mut scratch, &mut out).unwrap();
            let want = pb.dense_solve(&rot, &ctl, beta as f64);
            let tol = 1e-4 * (1.0 + max_norm(&want));
            let err = max_diff(&out, &want);
            assert!(
                err <= tol,
                "beta {beta}, frame {frame}: max |t - t_dense| = {err} > {tol}\n{out:?}\n{want:?}"
            );
        }
    }
}

#[test]
fn unused_bones_get_zero_translation_and_the_rest_match_dense() {
    // Bones 4 and 5 influence nothing: their columns of A are zero.
    let pb = problem(3, 6, 4);
    let solver = pb.solver(1.0);
    let mut rng = StdRng::seed_from_u64(33);
    let (rot, ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
    let mut out = vec![Vec3::splat(9.0); pb.bones];
    solver
        .solve(&rot, &ctl, &mut solver.scratch(), &mut out)
        .unwrap();
    let want = pb.dense_solve(&rot, &ctl, 1.0);
    assert_eq!(
        want[4],
        Vec3::ZERO,
        "dense min-norm leaves unused bones at 0"
    );
    assert!(max_diff(&out, &want) <= 1e-4 * (1.0 + max_norm(&want)));
    assert!(out[4].abs().max_element() < 1e-6 && out[5].abs().max_element() < 1e-6);
}

#[test]
fn beta_zero_gives_the_minimum_norm_solution() {
    // Without controls the global translation is free; the ridge picks (nearly) the
    // minimum-norm solution, which the SVD computes exactly.
    let pb = problem(4, 5, 5);
    let solver = pb.solver(0.0);
    let mut rng = StdRng::seed_from_u64(44);
    let (rot, ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
    let mut out = vec![Vec3::ZERO; pb.bones];
    solver
        .solve(&rot, &ctl, &mut solver.scratch(), &mut out)
        .unwrap();
    let want = pb.dense_solve(&rot, &ctl, 0.0);
    let err = max_diff(&out, &want);
    assert!(
        err <= 1e-4 * (1.0 + max_norm(&want)),
        "{err}\n{out:?}\n{want:?}"
    );
}

#[test]
fn set_beta_changes_the_result_and_matches_dense_at_the_new_beta() {
    let pb = problem(5, 5, 5);
    let mut solver = pb.solver(0.3);
    let mut scratch = solver.scratch();
    let mut rng = StdRng::seed_from_u64(55);
    let (rot, ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
    let mut before = vec![Vec3::ZERO; pb.bones];
    solver.solve(&rot, &ctl, &mut scratch, &mut before).unwrap();
    solver.set_beta(3.0).unwrap();
    assert_eq!(solver.beta(), 3.0);
    let mut after = vec![Vec3::ZERO; pb.bones];
    solver.solve(&rot, &ctl, &mut scratch, &mut after).unwrap();
    assert!(
        max_diff(&before, &after) > 1e-2,
        "beta had no effect: {before:?} vs {after:?}"
    );
    let want = pb.dense_solve(&rot, &ctl, 3.0);
    assert!(max_diff(&after, &want) <= 1e-4 * (1.0 + max_norm(&want)));
    // A rejected beta leaves the solver as it was.
    assert_eq!(
        solver.set_beta(-1.0),
        Err(TranslationError::BadBeta { beta: -1.0 })
    );
    let mut again = vec![Vec3::ZERO; pb.bones];
    solver.solve(&rot, &ctl, &mut scratch, &mut again).unwrap();
    assert_eq!(again, after);
}

#[test]
fn shared_rigid_transform_is_recovered_exactly() {
    // Every bone moves by the same (R, t): t_b = t makes every residual of eq. 11 zero, whatever
    // the (normalised) edge weights.
    let pb = problem(6, 5, 5);
    let mut rng = StdRng::seed_from_u64(66);
    let r = random_rotation(&mut rng);
    let t = Vec3::new(0.7, -1.3, 2.1);
    let rot = vec![r; pb.bones];
    let ctl: Vec<Vec3> = pb
        .controls
        .iter()
        .map(|&i| r * pb.mesh.positions[i as usize] + t)
        .collect();
    for beta in [0.3, 3.0] {
        let solver = pb.solver(beta);
        let mut out = vec![Vec3::ZERO; pb.bones];
        solver
            .solve(&rot, &ctl, &mut solver.scratch(), &mut out)
            .unwrap();
        for (b, tb) in out.iter().enumerate() {
            assert!(
                (*tb - t).abs().max_element() < 1e-5,
                "beta {beta} bone {b}: {tb} vs {t}"
            );
        }
    }
    // beta = 0: determined up to a common offset, so all bones must agree with each other.
    let solver = pb.solver(0.0);
    let mut out = vec![Vec3::ZERO; pb.bones];
    solver
        .solve(&rot, &ctl, &mut solver.scratch(), &mut out)
        .unwrap();
    for tb in &out {
        assert!((*tb - out[0]).abs().max_element() < 1e-5, "{out:?}");
    }
}

#[test]
fn unnormalised_rotations_and_apply_agree_with_solve() {
    let pb = problem(7, 5, 5);
    let solver = pb.solver(1.0);
    let mut scratch = solver.scratch();
    let mut rng = StdRng::seed_from_u64(77);
    let (rot, ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
    let mut a = vec![Vec3::ZERO; pb.bones];
    solver.solve(&rot, &ctl, &mut scratch, &mut a).unwrap();
    // The solve is against the independent dense least squares, not only against itself.
    let want = pb.dense_solve(&rot, &ctl, 1.0);
    let tol = 1e-4 * (1.0 + max_norm(&want));
    assert!(max_diff(&a, &want) <= tol, "{a:?}\n{want:?}");
    // `solve` normalises its quaternions: the same rotations scaled by different non-unit
    // factors give the same translations.
    let scaled: Vec<Quat> = rot
        .iter()
        .enumerate()
        .map(|(i, &q)| q * (0.5 + i as f32))
        .collect();
    let mut b = vec![Vec3::ZERO; pb.bones];
    solver.solve(&scaled, &ctl, &mut scratch, &mut b).unwrap();
    assert!(max_diff(&a, &b) < 1e-5);
    let mut bones: Vec<RigidTransform> = rot
        .iter()
        .map(|&q| RigidTransform::new(q, Vec3::splat(5.0)))
        .collect();
    solver.apply(&mut bones, &ctl, &mut scratch).unwrap();
    for (bone, (t, q)) in bones.iter().zip(a.iter().zip(&rot)) {
        assert_eq!(bone.translation, *t);
        assert_eq!(bone.rotation, *q);
    }
    // A fresh default scratch works too (it sizes itself on first use).
    let mut c = vec![Vec3::ZERO; pb.bones];
    solver
        .solve(&rot, &ctl, &mut Default::default(), &mut c)
        .unwrap();
    assert_eq!(a, c);
}

#[test]
fn construction_rejects_inconsistent_inputs() {
    let pb = problem(8, 5, 5);
    let p = &pb.mesh.positions;
    let err = |r: Result<TranslationSolver, TranslationError>| r.unwrap_err();

    let e = err(TranslationSolver::new(
        &p[..50],
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        5,
        1.0,
    ));
    assert!(
        matches!(
            e,
            TranslationError::Size {
                expected: 50,
                got: 100,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("expected 50, got 100"), "{e}");

    let e = err(TranslationSolver::new(
        p,
        &pb.edges[1..],
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        5,
        1.0,
    ));
    assert!(matches!(e, TranslationError::Size { .. }), "{e}");

    let mut edges = pb.edges.clone();
    edges[7] = [3, 100];
    let e = err(TranslationSolver::new(
        p,
        &edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        5,
        1.0,
    ));
    assert_eq!(
        e,
        TranslationError::IndexOutOfRange {
            what: "edge",
            item: 7,
            index: 100,
            limit: 100
        }
    );

    let e = err(TranslationSolver::new(
        p,
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &[1, 200],
        5,
        1.0,
    ));
    assert!(
        matches!(
            e,
            TranslationError::IndexOutOfRange {
                what: "control point",
                item: 1,
                index: 200,
                ..
            }
        ),
        "{e}"
    );

    let e = err(TranslationSolver::new(
        p,
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        3,
        1.0,
    ));
    assert!(matches!(e, TranslationError::Skin(_)), "{e}");

    for beta in [-0.5, f32::NAN, f32::INFINITY] {
        let e = err(TranslationSolver::new(
            p,
            &pb.edges,
            &pb.skin,
            &pb.edge_skin,
            &pb.controls,
            5,
            beta,
        ));
        assert!(matches!(e, TranslationError::BadBeta { .. }), "{e}");
    }

    let mut bad = p.clone();
    bad[9].y = f32::NAN;
    let e = err(TranslationSolver::new(
        &bad,
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        5,
        1.0,
    ));
    assert_eq!(
        e,
        TranslationError::NonFinite {
            what: "rest position",
            index: 9
        }
    );

    let e = err(TranslationSolver::new(
        p,
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        0,
        1.0,
    ));
    assert_eq!(e, TranslationError::NoBones);
}

#[test]
fn per_frame_size_mismatches_are_errors() {
    let pb = problem(9, 5, 5);
    let solver = pb.solver(1.0);
    let mut scratch = solver.scratch();
    let rot = vec![Quat::IDENTITY; 5];
    let ctl = vec![Vec3::ZERO; 5];
    let mut out = vec![Vec3::ZERO; 5];

    let e = solver
        .solve(&rot[..4], &ctl, &mut scratch, &mut out)
        .unwrap_err();
    assert!(
        e.to_string().starts_with("rotations") && e.to_string().contains("expected 5, got 4"),
        "{e}"
    );
    let e = solver
        .solve(&rot, &ctl[..3], &mut scratch, &mut out)
        .unwrap_err();
    assert!(
        e.to_string().starts_with("controls") && e.to_string().contains("expected 5, got 3"),
        "{e}"
    );
    let e = solver
        .solve(&rot, &ctl, &mut scratch, &mut out[..2])
        .unwrap_err();
    assert!(
        e.to_string().starts_with("output") && e.to_string().contains("expected 5, got 2"),
        "{e}"
    );
}

#[test]
fn nan_control_or_rotation_is_an_error_and_leaves_the_output_alone() {
    let pb = problem(10, 5, 5);
    let solver = pb.solver(1.0);
    let mut scratch = solver.scratch();
    let mut rng = StdRng::seed_from_u64(1010);
    let (rot, mut ctl) = random_frame(&mut rng, pb.bones, pb.controls.len());
    let mut out = vec![Vec3::ZERO; pb.bones];
    solver.solve(&rot, &ctl, &mut scratch, &mut out).unwrap();
    let previous = out.clone();

    ctl[2].x = f32::NAN;
    assert_eq!(
        solver.solve(&rot, &ctl, &mut scratch, &mut out),
        Err(TranslationError::NonFinite {
            what: "control",
            index: 2
        })
    );
    assert_eq!(out, previous);
    ctl[2].x = 0.0;

    let mut bad_rot = rot.clone();
    bad_rot[1] = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0); // cannot be normalised
    assert_eq!(
        solver.solve(&bad_rot, &ctl, &mut scratch, &mut out),
        Err(TranslationError::NonFinite {
            what: "rotation",
            index: 1
        })
    );
    bad_rot[1] = Quat::from_xyzw(f32::INFINITY, 0.0, 0.0, 1.0);
    assert!(
        solver
            .solve(&bad_rot, &ctl, &mut scratch, &mut out)
            .is_err()
    );
    assert_eq!(out, previous);

    // And the solver still works afterwards.
    solver.solve(&rot, &ctl, &mut scratch, &mut out).unwrap();
    assert!(out.iter().all(|t| t.is_finite()));
}
