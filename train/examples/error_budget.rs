//! Probe of where the held-out error of a trained model comes from: rotation prediction versus
//! the translation solve (FKY08 eq. 11). Prints, over the test frames, the mean rotation angle
//! error of the global predictor against the oracle rotations (fitted to the truth), and the
//! mesh error of eq. 11 with (a) the oracle rotations, (b) the predicted rotations, (c) the
//! per-bone average of the two training examples nearest in control space (or, with
//! `TIME_NEIGHBOURS=1` on the horse gallop split, of the test frame's two time neighbours).
//!
//! First it reports how well edge models reproduce the mesh edges (relative error
//! `sqrt(sum |e^s - e|^2 / sum |e|^2)`) on the training frames: no rotation, the best rotation
//! per vertex (one-ring Kabsch, edge = mean of its endpoints' rotations), FKY08 eq. 10 scalar
//! weights, and the model's vector edge skin (also on the test frames, with fitted rotations).
//!
//! `cargo run --release -p crease-train --example error_budget -- TRAIN TEST [BONES] [K] [BETA]`
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::sync::Arc;

use crease_core::glam::{Mat3, Quat, Vec3, Vec4};
use crease_core::mesh::examples::ExampleSet;
use crease_core::predictor::Predictor;
use crease_core::runtime::edge_skin::EdgeSkin;
use crease_train::eval::{oracle_transforms, rms_normalized};
use crease_train::pipeline::{self, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let train = ExampleSet::load(&args[1]).expect("train");
    let test = ExampleSet::load(&args[2]).expect("test");
    let bones: usize = args.get(3).map_or(150, |s| s.parse().unwrap());
    let k: usize = args.get(4).map_or(8, |s| s.parse().unwrap());
    let beta: f32 = args.get(5).map_or(1.0, |s| s.parse().unwrap());
    let mut options = TrainOptions::default();
    options.fit.bones = bones;
    options.fit.max_influences = k;
    let frames = train.frames();
    let names = train.names();
    let base = pipeline::train_base(
        TrainInput {
            rest: &train.rest,
            frames: &frames,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .unwrap();
    let rest = &base.rig.rest;
    let scale = rest.bbox_diagonal_scale();
    let nb = base.rig.bone_count;
    let model = base.model(
        &RegressOptions {
            method: Method::Global,
            ..RegressOptions::default()
        },
        beta,
    );
    let predictor = Predictor::new(Arc::new(model), Some(beta)).unwrap();
    let mut ctx = predictor.new_context();
    let mut scratch = Default::default();
    let mut pred = vec![Quat::IDENTITY; nb];
    let mut sums = [0.0f64; 4];
    let mut per_bone = vec![0.0f64; nb];
    let mut region_sums = [0.0f64; 5];
    let n = test.examples.len();
    edge_report(&base, &frames, &test.frames(), k);
    let test_names = test.names();
    for (fi, f) in test.frames().into_iter().enumerate() {
        let controls: Vec<Vec3> = base
            .control_vertices
            .iter()
            .map(|&v| f[v as usize])
            .collect();
        let oracle: Vec<Quat> = oracle_transforms(rest, &base.rig.skin, nb, f)
            .iter()
            .map(|t| t.rotation)
            .collect();
        predictor
            .model()
            .rotations
            .predict(&controls, &mut scratch, &mut pred);
        let angle: f64 = oracle
            .iter()
            .zip(&pred)
            .map(|(a, b)| a.angle_between(*b) as f64)
            .sum::<f64>()
            / nb as f64;
        sums[0] += angle.to_degrees();
        for (b, (a, p)) in oracle.iter().zip(&pred).enumerate() {
            per_bone[b] += a.angle_between(*p) as f64;
        }
        let mut mesh_err = |rot: &[Quat]| {
            predictor
                .solve_with_rotations(&mut ctx, rot, &controls)
                .unwrap();
            predictor.skin(&mut ctx).unwrap();
            rms_normalized(ctx.positions(), f, scale)
        };
        let e_oracle = mesh_err(&oracle);
        let e_pred = mesh_err(&pred);

        // Two nearest training examples in control space, equal blend.
        let mut d: Vec<(f32, usize)> = base
            .example_controls
            .iter()
            .enumerate()
            .map(|(i, c)| {
                (
                    c.iter()
                        .zip(&controls)
                        .map(|(a, b)| a.distance_squared(*b))
                        .sum(),
                    i,
                )
            })
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut i, mut j) = (d[0].1, d[1].1);
        if let Ok(fname) = std::env::var("TIME_NEIGHBOURS") {
            // gallop/00KK.obj: neighbours KK-1, KK+1 (mod 24) among the training names.
            let _ = fname;
            let k: usize = test_names[fi][test_names[fi].len() - 8..test_names[fi].len() - 4]
                .parse()
                .unwrap();
            let find = |t: usize| {
                let want = format!("gallop/{:04}.obj", t);
                names.iter().position(|n| n.ends_with(&want)).unwrap()
            };
            i = find(k - 1);
            j = find(if k == 24 { 1 } else { k + 1 });
        }
        let blend: Vec<Quat> = (0..nb)
            .map(|b| {
                let qa = Vec4::from(base.rotations[i][b]);
                let mut qb = Vec4::from(base.rotations[j][b]);
                if qa.dot(qb) < 0.0 {
                    qb = -qb;
                }
                Quat::from_vec4(qa + qb).normalize()
            })
            .collect();
        let e_blend = mesh_err(&blend);
        {
            // Where the predicted mesh's squared error sits (rest-pose regions).
            predictor
                .solve_with_rotations(&mut ctx, &pred, &controls)
                .unwrap();
            predictor.skin(&mut ctx).unwrap();
            let got = ctx.positions();
            let mut parts = [0.0f64; 5];
            for (v, (g, t)) in got.iter().zip(f.iter()).enumerate() {
                let p = rest.positions[v];
                let e = (*g - *t).length_squared() as f64;
                let r = if p.y < 0.15 {
                    0 // hooves
                } else if p.y < 0.6 {
                    1 // legs
                } else if p.z < -0.6 {
                    2 // tail
                } else if p.z > 0.45 {
                    3 // neck and head
                } else {
                    4 // body
                };
                parts[r] += e;
            }
            let tot: f64 = parts.iter().sum();
            region_sums
                .iter_mut()
                .zip(parts)
                .for_each(|(a, b)| *a += b / tot);
        }
        sums[1] += e_oracle;
        sums[2] += e_pred;
        sums[3] += e_blend;
        println!(
            "angle err {angle:.4} rad; mesh: oracle-rot {e_oracle:.5} predicted {e_pred:.5} nearest-2 blend {e_blend:.5} ({}, {})",
            names[i], names[j]
        );
    }
    let n = n as f64;
    println!(
        "share of squared error: hooves {:.2} legs {:.2} tail {:.2} neck+head {:.2} body {:.2}",
        region_sums[0] / n,
        region_sums[1] / n,
        region_sums[2] / n,
        region_sums[3] / n,
        region_sums[4] / n
    );
    // Per bone: mean angle error, weight mass, weighted centre.
    let mut mass = vec![0.0f64; nb];
    let mut centre = vec![Vec3::ZERO; nb];
    for (v, (idx, w)) in base.rig.skin.iter().enumerate() {
        for (&b, &x) in idx.iter().zip(w) {
            mass[b as usize] += x as f64;
            centre[b as usize] += rest.positions[v] * x;
        }
    }
    let mut order: Vec<usize> = (0..nb).collect();
    order.sort_by(|&a, &b| per_bone[b].total_cmp(&per_bone[a]));
    for &b in order.iter().take(25) {
        println!(
            "bone {b:3}: angle err {:.1} deg, mass {:.0}, centre {:.2?}",
            (per_bone[b] / n).to_degrees(),
            mass[b],
            centre[b] / mass[b].max(1e-9) as f32
        );
    }
    println!(
        "mean: angle {:.2} deg; oracle-rot {:.5}; predicted {:.5}; nearest-2 blend {:.5}",
        sums[0] / n,
        sums[1] / n,
        sums[2] / n,
        sums[3] / n
    );
}

/// Relative edge errors of several edge models (see the module docs).
fn edge_report(base: &pipeline::TrainedBase, frames: &[&[Vec3]], test: &[&[Vec3]], k: usize) {
    let rest = &base.rig.rest.positions;
    let edges = &base.edges;
    let rel = |pred: &dyn Fn(usize, usize) -> Vec3, fr: &[&[Vec3]]| -> f64 {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for (j, f) in fr.iter().enumerate() {
            for (e, &[a, b]) in edges.iter().enumerate() {
                let t = f[a as usize] - f[b as usize];
                num += (pred(j, e) - t).length_squared() as f64;
                den += t.length_squared() as f64;
            }
        }
        (num / den).sqrt()
    };
    let e0 = |e: usize| rest[edges[e][0] as usize] - rest[edges[e][1] as usize];
    let adj = base.rig.rest.vertex_adjacency();
    let field: Vec<Vec<Quat>> = frames
        .iter()
        .map(|f| {
            (0..rest.len())
                .map(|v| {
                    let ring: Vec<usize> = std::iter::once(v)
                        .chain(adj.neighbors(v).iter().map(|&x| x as usize))
                        .collect();
                    kabsch(
                        &ring.iter().map(|&i| rest[i]).collect::<Vec<_>>(),
                        &ring.iter().map(|&i| f[i]).collect::<Vec<_>>(),
                    )
                })
                .collect()
        })
        .collect();
    let scalar = crease_train::edges::try_fit_edge_weights(
        rest,
        edges,
        frames,
        &base.rotations,
        &base.rig.skin,
        k,
    )
    .and_then(|w| Ok(EdgeSkin::from_weights(rest, edges, &w)?))
    .expect("scalar edge weights");
    let test_rot: Vec<Vec<Quat>> = test
        .iter()
        .map(|f| {
            oracle_transforms(&base.rig.rest, &base.rig.skin, base.rig.bone_count, f)
                .iter()
                .map(|t| t.rotation)
                .collect()
        })
        .collect();
    println!("relative edge error on the training frames:");
    println!(
        "  no rotation                  {:.4}",
        rel(&|_, e| e0(e), frames)
    );
    println!(
        "  one-ring rotation per vertex {:.4}",
        rel(
            &|j, e| {
                let [a, b] = edges[e].map(|v| v as usize);
                ((Mat3::from_quat(field[j][a]) + Mat3::from_quat(field[j][b])) * 0.5) * e0(e)
            },
            frames
        )
    );
    println!(
        "  eq. 10 scalar weights        {:.4}",
        rel(&|j, e| scalar.predict(e, &base.rotations[j]), frames)
    );
    println!(
        "  vector edge skin (model)     {:.4}",
        rel(
            &|j, e| base.edge_skin.predict(e, &base.rotations[j]),
            frames
        )
    );
    println!("on the test frames, rotations fitted to the truth:");
    println!(
        "  eq. 10 scalar weights        {:.4}",
        rel(&|j, e| scalar.predict(e, &test_rot[j]), test)
    );
    println!(
        "  vector edge skin (model)     {:.4}",
        rel(&|j, e| base.edge_skin.predict(e, &test_rot[j]), test)
    );
}

/// The rotation best mapping `p` onto `q` (centred Kabsch via nalgebra's SVD).
fn kabsch(p: &[Vec3], q: &[Vec3]) -> Quat {
    let n = p.len() as f32;
    let (cp, cq) = (p.iter().sum::<Vec3>() / n, q.iter().sum::<Vec3>() / n);
    let mut h = nalgebra::Matrix3::<f64>::zeros();
    for (a, b) in p.iter().zip(q) {
        let (a, b) = (*a - cp, *b - cq);
        h += nalgebra::Vector3::new(b.x as f64, b.y as f64, b.z as f64)
            * nalgebra::Vector3::new(a.x as f64, a.y as f64, a.z as f64).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = nalgebra::Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    let m = Mat3::from_cols_array(&[
        r[(0, 0)] as f32,
        r[(1, 0)] as f32,
        r[(2, 0)] as f32,
        r[(0, 1)] as f32,
        r[(1, 1)] as f32,
        r[(2, 1)] as f32,
        r[(0, 2)] as f32,
        r[(1, 2)] as f32,
        r[(2, 2)] as f32,
    ]);
    Quat::from_mat3(&m).normalize()
}
