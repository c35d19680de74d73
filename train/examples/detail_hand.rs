//! The detail layer alone on a `crease handgen` hand (issue 5, first figures): the true base
//! meshes are subdivided twice (S), each detailed example is resampled onto S·base by ray
//! casting (h), the per-vertex detail regressor is fitted on the training poses' control
//! points, and held-out poses are synthesised as S·base_true + h(c) n — so the table isolates
//! the detail layer from the base layer's error. Rows: static detail (the rest's h in every
//! pose, HZY11 Fig. 8a), pose-dependent detail (HZY11 §5.2), and no detail (S·base only).
//! RMS over all subdivided vertices and over the crease regions (the 5% of vertices whose h
//! varies most across the training poses), bounding box = 1.
//!
//! Then the whole pipeline: a base model (global and local, BONES proxy bones, K = 4) trained
//! on the base training meshes with the layout's control points predicts each held-out base
//! from the true control points, and the detail layer adds S and h(c): the full detailed
//! output `S·base_pred + h(c) n` against the detailed truth `S·base_true + h_true n`, with
//! base RMS beside it.
//!
//! `cargo run --release -p crease-train --example detail_hand -- HANDGEN_DIR [LAYOUT] [MAX_TEST] [BONES]`

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::{ExampleSet, Mesh};
use crease_core::runtime::detail::DetailSynth;
use crease_core::runtime::predictor::Predictor;
use crease_train::detail::DisplacementTarget;
use crease_train::detail::regress::{self, DetailInput, DetailRegressor};
use crease_train::kcca::KccaOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

/// Ray search distance (metres). 5 mm let rays reach neighbouring skin where fingertips press
/// into the palm (h outliers of 3-4 mm that swamped the creases: pose-dependent then lost to
/// static); creases are ~1 mm deep, so 1.5 mm keeps them and sends the rest to the
/// closest-point fallback.
const MAX_DISTANCE: f32 = 0.0015;

fn main() {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .expect("usage: detail_hand HANDGEN_DIR [LAYOUT] [MAX_TEST]"),
    );
    let layout = args.next().unwrap_or_else(|| "back".into());
    let max_test: usize = args.next().map_or(40, |s| s.parse().expect("MAX_TEST"));
    let bones: usize = args.next().map_or(40, |s| s.parse().expect("BONES"));
    let t0 = Instant::now();
    let train = ExampleSet::load(dir.join(format!("train-{layout}.toml"))).expect("train");
    let test = ExampleSet::load(dir.join("test.toml")).expect("test");
    let dtrain = ExampleSet::load(dir.join("detailed/train.toml")).expect("detailed train");
    let dtest = ExampleSet::load(dir.join("detailed/test.toml")).expect("detailed test");
    let cps = train.control_points.clone().expect("control points");
    let mut synth = DetailSynth::from_mesh(&train.rest, 2).expect("subdivision");
    let nv = synth.vertex_count();
    eprintln!(
        "[{:.1}s] base {} -> subdivided {nv} vertices; {} train, {} test poses",
        t0.elapsed().as_secs_f32(),
        train.rest.vertex_count(),
        train.examples.len(),
        test.examples.len().min(max_test)
    );
    // Per example: S·B, its normals, h.
    let mut resample = |base: &Mesh, detailed: &Mesh| -> (Vec<Vec3>, Vec<Vec3>, Vec<f32>) {
        let zero = vec![0.0; nv];
        let mut high = vec![Vec3::ZERO; nv];
        synth
            .synthesize(&base.positions, &zero, &mut high)
            .expect("synth");
        let normals = synth.normals().to_vec();
        let target =
            DisplacementTarget::new(&detailed.positions, &detailed.triangles).expect("bvh");
        let mut h = vec![0.0; nv];
        target
            .displacements(&high, &normals, MAX_DISTANCE, &mut h)
            .expect("extract");
        (high, normals, h)
    };
    let controls = |m: &Mesh| -> Vec<f32> {
        cps.iter()
            .flat_map(|&i| m.positions[i as usize].to_array())
            .collect()
    };
    let mut x = Vec::new();
    let mut h_train = Vec::new();
    for (b, d) in train.examples.iter().zip(&dtrain.examples) {
        let (_, _, h) = resample(&b.mesh, &d.mesh);
        x.extend(controls(&b.mesh));
        h_train.push(h);
    }
    eprintln!(
        "[{:.1}s] training displacements extracted",
        t0.elapsed().as_secs_f32()
    );
    let d_in = cps.len() * 3;
    let detail_model = regress::fit(
        DetailInput::Controls,
        &x,
        d_in,
        &h_train,
        None,
        &KccaOptions::default(),
    )
    .expect("fit");
    let fixed = DetailRegressor::fixed(DetailInput::Controls, d_in, h_train[0].clone());
    // Crease regions: the 5% of vertices whose h varies most over the training poses.
    let mut spread: Vec<(f32, usize)> = (0..nv)
        .map(|v| {
            let (lo, hi) = h_train
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, u), h| {
                    (l.min(h[v]), u.max(h[v]))
                });
            (hi - lo, v)
        })
        .collect();
    spread.sort_by(|a, b| b.0.total_cmp(&a.0));
    let crease: Vec<usize> = spread[..nv / 20].iter().map(|&(_, v)| v).collect();
    let (lo, hi) = train.rest.bounding_box();
    let scale = (hi - lo).max_element();
    let mut sums = [[0.0f64; 2]; 3];
    let mut xi = vec![0.0; detail_model.example_count()];
    let mut hp = vec![0.0; nv];
    let n_test = test.examples.len().min(max_test);
    let mut test_h = Vec::with_capacity(n_test);
    for (b, d) in test.examples.iter().zip(&dtest.examples).take(n_test) {
        let (_, _, h_true) = resample(&b.mesh, &d.mesh);
        let c = controls(&b.mesh);
        for (row, m) in [Some(&detail_model), Some(&fixed), None]
            .into_iter()
            .enumerate()
        {
            match m {
                Some(m) => m.predict(&c, &mut xi, &mut hp),
                None => hp.iter_mut().for_each(|v| *v = 0.0),
            }
            // out - truth = (h_pred - h_true) n: the error is |h_pred - h_true| per vertex.
            let err = |v: usize| f64::from((hp[v] - h_true[v]) / scale).powi(2);
            sums[row][0] += (0..nv).map(err).sum::<f64>() / nv as f64;
            sums[row][1] += crease.iter().map(|&v| err(v)).sum::<f64>() / crease.len() as f64;
        }
        test_h.push(h_true);
    }
    eprintln!(
        "[{:.1}s] {n_test} test poses evaluated",
        t0.elapsed().as_secs_f32()
    );
    println!(
        "detail layer on the true base, {layout} controls ({} points), {n_test} held-out poses, bbox = 1:",
        cps.len()
    );
    println!(
        "{:>16} {:>14} {:>16}",
        "method", "RMS all", "RMS creases 5%"
    );
    for (name, s) in ["pose-dependent", "static", "none"].iter().zip(&sums) {
        println!(
            "{name:>16} {:>14.3e} {:>16.3e}",
            (s[0] / n_test as f64).sqrt(),
            (s[1] / n_test as f64).sqrt()
        );
    }

    // The whole pipeline: predicted base + detail.
    let frames = train.frames();
    let names = train.names();
    let options = TrainOptions {
        controls: ControlSpec::Vertices(cps.clone()),
        ..TrainOptions::default()
    };
    let mut options = options;
    options.fit.bones = bones;
    options.fit.max_influences = 4;
    let base = pipeline::train_base(
        TrainInput {
            rest: &train.rest,
            frames: &frames,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .expect("base training");
    eprintln!(
        "[{:.1}s] base layer trained ({bones} bones)",
        t0.elapsed().as_secs_f32()
    );
    let mut truth = vec![Vec3::ZERO; nv];
    let mut out = vec![Vec3::ZERO; nv];
    println!();
    println!(
        "whole pipeline ({bones} bones, K = 4, beta 1): predicted base + detail vs the detailed truth, bbox = 1:"
    );
    println!(
        "{:>8} {:>16} {:>12} {:>14} {:>16}",
        "method", "detail", "base RMS", "detailed RMS", "creases 5% RMS"
    );
    for method in [Method::Global, Method::Local] {
        let model = base.model(
            &RegressOptions {
                method,
                ..RegressOptions::default()
            },
            1.0,
        );
        let predictor = Predictor::new(Arc::new(model), None).expect("predictor");
        let mut ctx = predictor.new_context();
        for (dname, dm) in [("pose-dependent", &detail_model), ("static", &fixed)] {
            let (mut sb, mut sd, mut sc) = (0.0f64, 0.0f64, 0.0f64);
            for (k, b) in test.examples.iter().take(n_test).enumerate() {
                let c = controls(&b.mesh);
                let cv: Vec<Vec3> = c.chunks(3).map(Vec3::from_slice).collect();
                let pred = predictor
                    .predict(&mut ctx, &cv, None)
                    .expect("predict")
                    .to_vec();
                sb += pred
                    .iter()
                    .zip(&b.mesh.positions)
                    .map(|(p, q)| f64::from(p.distance_squared(*q) / (scale * scale)))
                    .sum::<f64>()
                    / pred.len() as f64;
                dm.predict(&c, &mut xi, &mut hp);
                synth.synthesize(&pred, &hp, &mut out).expect("synth");
                synth
                    .synthesize(&b.mesh.positions, &test_h[k], &mut truth)
                    .expect("synth");
                let e: Vec<f64> = out
                    .iter()
                    .zip(&truth)
                    .map(|(p, q)| f64::from(p.distance_squared(*q) / (scale * scale)))
                    .collect();
                sd += e.iter().sum::<f64>() / nv as f64;
                sc += crease.iter().map(|&v| e[v]).sum::<f64>() / crease.len() as f64;
            }
            let n = n_test as f64;
            println!(
                "{:>8} {dname:>16} {:>12.3e} {:>14.3e} {:>16.3e}",
                method.name(),
                (sb / n).sqrt(),
                (sd / n).sqrt(),
                (sc / n).sqrt()
            );
        }
    }
}
