//! The bone-level refinement (`runtime::refine`, issue 20) against a dense evaluation of its
//! energy (every edge, control and prior term summed from the skinned vertices in f64): the
//! energy never rises over the iterations on random frames, the refinement without a prior
//! finds a rigid pose from the control points alone, and an infinitely trusted prior moves
//! nothing.

use crease_core::glam::{DMat3, DVec3, Quat, Vec3};
use crease_core::runtime::refine::BoneRefiner;
use crease_core::runtime::translations::TranslationSolver;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::common;
use common::rig::{Problem, dense_weights, problem, random_point, random_rotation};

fn refiner(pb: &Problem, beta: f32) -> BoneRefiner {
    BoneRefiner::new(
        &pb.mesh.positions,
        &pb.edges,
        &pb.skin,
        &pb.edge_skin,
        &pb.controls,
        pb.bones,
        beta,
    )
}

/// `refine.refine` from `start` (its own prior), `iterations` rounds: the rotations and
/// translations.
fn refined(
    refine: &BoneRefiner,
    solver: &TranslationSolver,
    start: &[Quat],
    strength: f64,
    controls: &[Vec3],
    iterations: usize,
) -> (Vec<Quat>, Vec<Vec3>) {
    let mut r = start.to_vec();
    let mut t = vec![Vec3::ZERO; start.len()];
    refine
        .refine(
            solver,
            &mut r,
            None,
            strength,
            controls,
            iterations,
            &mut refine.scratch(),
            &mut t,
        )
        .unwrap();
    (r, t)
}

fn mat(q: Quat) -> DMat3 {
    DMat3::from_quat(q.as_dquat().normalize())
}

/// `E(R, t)` summed term by term (module docs of `runtime::refine`), `lambda_b` given.
fn dense_energy(
    pb: &Problem,
    beta: f64,
    rotations: &[Quat],
    translations: &[Vec3],
    controls: &[Vec3],
    prior: &[Quat],
    lambda: &[f64],
) -> f64 {
    let r: Vec<DMat3> = rotations.iter().map(|q| mat(*q)).collect();
    let t: Vec<DVec3> = translations.iter().map(|v| v.as_dvec3()).collect();
    let skinned = |i: usize| -> DVec3 {
        let w = dense_weights(&pb.skin, i, pb.bones);
        let p = pb.mesh.positions[i].as_dvec3();
        (0..pb.bones).map(|b| w[b] * (r[b] * p + t[b])).sum()
    };
    let mut e = 0.0;
    for (k, &[i0, i1]) in pb.edges.iter().enumerate() {
        let (bones, vectors) = pb.edge_skin.edge(k);
        let skin: DVec3 = bones
            .iter()
            .zip(vectors)
            .map(|(&b, a)| r[b as usize] * a.as_dvec3())
            .sum();
        e += (skinned(i0 as usize) - skinned(i1 as usize) - skin).length_squared();
    }
    for (l, &i) in pb.controls.iter().enumerate() {
        e += beta * (skinned(i as usize) - controls[l].as_dvec3()).length_squared();
    }
    for b in 0..pb.bones {
        let d = r[b] - mat(prior[b]);
        e += lambda[b]
            * (d.x_axis.length_squared() + d.y_axis.length_squared() + d.z_axis.length_squared());
    }
    e
}

#[test]
fn the_energy_never_rises_over_the_iterations() {
    for seed in 0..6u64 {
        let pb = problem(100 + seed, 6, 6);
        let beta = [0.3f32, 3.0][seed as usize % 2];
        let solver = pb.solver(beta);
        let refine = refiner(&pb, beta);
        let mut rng = StdRng::seed_from_u64(seed);
        // The regression's rotations: a shared rotation, each bone perturbed; the controls
        // where a different pose would put them.
        let base = random_rotation(&mut rng);
        let prior: Vec<Quat> = (0..pb.bones)
            .map(|_| {
                let axis = random_point(&mut rng, 1.0).normalize_or(Vec3::X);
                (Quat::from_axis_angle(axis, rng.random_range(-0.6..0.6)) * base).normalize()
            })
            .collect();
        let controls: Vec<Vec3> = pb
            .controls
            .iter()
            .map(|&i| base * pb.mesh.positions[i as usize] + random_point(&mut rng, 0.4))
            .collect();
        for strength in [0.0, 0.05, 1.0] {
            let lambda: Vec<f64> = (0..pb.bones)
                .map(|b| refine.prior_weight(b, strength))
                .collect();
            let mut energies = Vec::new();
            for iterations in 0..10 {
                let (r, t) = refined(&refine, &solver, &prior, strength, &controls, iterations);
                energies.push(dense_energy(
                    &pb,
                    beta as f64,
                    &r,
                    &t,
                    &controls,
                    &prior,
                    &lambda,
                ));
            }
            for (i, w) in energies.windows(2).enumerate() {
                // f32 rotations and translations between the steps: a relative 1e-5 of slack.
                assert!(
                    w[1] <= w[0] * (1.0 + 1e-5) + 1e-9,
                    "seed {seed} beta {beta} strength {strength}: iteration {} raised the energy {} -> {}\n{energies:?}",
                    i + 1,
                    w[0],
                    w[1]
                );
            }
            assert!(
                energies[9] < 0.9 * energies[0],
                "seed {seed} strength {strength}: the refinement barely moved: {energies:?}"
            );
        }
    }
}

#[test]
fn without_a_prior_the_control_points_alone_find_a_rigid_pose() {
    // Every vertex moved by one rigid motion: the controls say so, the refinement starts from
    // the rest rotations and may not look at any regression. The problem's edge skin sums to
    // the rest edges, so the shared motion is a zero of the energy.
    let pb = problem(7, 5, 5);
    let beta = 3.0;
    let solver = pb.solver(beta);
    let refine = refiner(&pb, beta);
    let motion = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
    let shift = Vec3::new(0.3, -0.2, 0.5);
    let controls: Vec<Vec3> = pb
        .controls
        .iter()
        .map(|&i| motion * pb.mesh.positions[i as usize] + shift)
        .collect();
    let rest = vec![Quat::IDENTITY; pb.bones];
    let energy = |r: &[Quat], t: &[Vec3]| {
        dense_energy(
            &pb,
            beta as f64,
            r,
            t,
            &controls,
            &rest,
            &vec![0.0; pb.bones],
        )
    };
    let (r0, t0) = refined(&refine, &solver, &rest, 0.0, &controls, 0);
    let (r, t) = refined(&refine, &solver, &rest, 0.0, &controls, 60);
    let (before, after) = (energy(&r0, &t0), energy(&r, &t));
    assert!(
        after < 1e-3 * before,
        "energy {before} from rest, {after} after 60 iterations"
    );
    for (b, q) in r.iter().enumerate() {
        assert!(
            q.angle_between(motion) < 0.05,
            "bone {b}: {:.3} rad from the motion",
            q.angle_between(motion)
        );
    }
}

#[test]
fn a_fully_trusted_prior_moves_nothing() {
    // A huge prior weight: the rotations stay the regression's, and the translations are eq.
    // 11's for them.
    let pb = problem(8, 5, 5);
    let solver = pb.solver(1.0);
    let refine = refiner(&pb, 1.0);
    let mut rng = StdRng::seed_from_u64(8);
    let prior: Vec<Quat> = (0..pb.bones).map(|_| random_rotation(&mut rng)).collect();
    let controls: Vec<Vec3> = (0..pb.controls.len())
        .map(|_| random_point(&mut rng, 1.0))
        .collect();
    let mut want = vec![Vec3::ZERO; pb.bones];
    solver
        .solve(&prior, &controls, &mut solver.scratch(), &mut want)
        .unwrap();
    let (r, t) = refined(&refine, &solver, &prior, 1e9, &controls, 5);
    for b in 0..pb.bones {
        // f32's acos resolves angles near 0 to ~1e-3 rad.
        let off = r[b].angle_between(prior[b]);
        assert!(off < 2e-3, "bone {b}: {off} rad from the prior");
        assert!(
            (t[b] - want[b]).length() < 1e-3,
            "bone {b}: {} vs {}",
            t[b],
            want[b]
        );
    }
}

#[test]
fn moving_the_mesh_and_its_controls_moves_the_result_and_turns_no_rotation() {
    // Each bone turns about its own pivot (module docs), so where the mesh lies does not
    // change the iterates: the same problem 40 units away gives the same rotations and
    // translations that carry the pivots to the same places, moved by the offset. (About the
    // origin, the far copy's bones could barely turn in a local step: its rotations stayed
    // near the start.)
    let near = problem(21, 6, 6);
    let offset = Vec3::new(40.0, -30.0, 25.0);
    let mut far = near.clone();
    for p in &mut far.mesh.positions {
        *p += offset;
    }
    let beta = 3.0;
    let mut rng = StdRng::seed_from_u64(21);
    let motion = Quat::from_axis_angle(Vec3::new(0.2, 1.0, 0.4).normalize(), 0.9);
    let start: Vec<Quat> = (0..near.bones)
        .map(|_| {
            let axis = random_point(&mut rng, 1.0).normalize_or(Vec3::X);
            Quat::from_axis_angle(axis, rng.random_range(-0.3..0.3))
        })
        .collect();
    let bend: Vec<Vec3> = (0..near.controls.len())
        .map(|_| random_point(&mut rng, 0.2))
        .collect();
    let controls = |pb: &Problem, o: Vec3| -> Vec<Vec3> {
        pb.controls
            .iter()
            .zip(&bend)
            .map(|(&i, d)| motion * (pb.mesh.positions[i as usize] - o) + o + *d)
            .collect()
    };
    let (near_c, far_c) = (controls(&near, Vec3::ZERO), controls(&far, offset));
    let run = |pb: &Problem, c: &[Vec3]| {
        refined(&refiner(pb, beta), &pb.solver(beta), &start, 0.01, c, 8)
    };
    let ((rn, tn), (rf, tf)) = (run(&near, &near_c), run(&far, &far_c));
    let moved_from_start = rn
        .iter()
        .zip(&start)
        .map(|(a, b)| a.angle_between(*b))
        .fold(0.0f32, f32::max);
    assert!(
        moved_from_start > 0.3,
        "the refinement did not turn the bones ({moved_from_start} rad): nothing is tested"
    );
    for b in 0..near.bones {
        let turn = rn[b].angle_between(rf[b]);
        assert!(
            turn < 2e-3,
            "bone {b}: the far copy's rotation is {turn} rad off"
        );
        // x -> R x + t near is x -> R (x - o) + t + o far: t_far = t_near + o - R o.
        let want = tn[b] + offset - rn[b] * offset;
        assert!(
            (tf[b] - want).length() < 0.1,
            "bone {b}: translation {} against {want}",
            tf[b]
        );
    }
}
