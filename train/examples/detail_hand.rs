//! The detail layer alone on a `crease handgen` hand (issue 5, first figures): the true base
//! meshes are subdivided twice (S), each detailed example is resampled onto S·base by ray
//! casting (h), the per-vertex detail regressor is fitted on the training poses' control
//! points, and held-out poses are synthesised as S·base_true + h(c) n — so the table isolates
//! the detail layer from the base layer's error. Rows: static detail (the rest's h in every
//! pose, HZY11 Fig. 8a), pose-dependent detail (HZY11 §5.2), and no detail (S·base only).
//! RMS over all subdivided vertices and over the crease regions (the 5% of vertices whose h
//! varies most across the training poses), bounding box = 1.
//!
//! `cargo run --release -p crease-train --example detail_hand -- HANDGEN_DIR [LAYOUT] [MAX_TEST]`

use std::path::PathBuf;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::{ExampleSet, Mesh};
use crease_core::runtime::detail::DetailSynth;
use crease_train::detail::DisplacementTarget;
use crease_train::detail::regress::{DetailInput, DetailModel};
use crease_train::kcca::KccaOptions;

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
    let model = DetailModel::fit(
        DetailInput::Controls,
        &x,
        d_in,
        &h_train,
        None,
        &KccaOptions::default(),
    )
    .expect("fit");
    let fixed = DetailModel::fixed(DetailInput::Controls, d_in, &h_train[0]);
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
    let mut xi = vec![0.0; model.example_count()];
    let mut hp = vec![0.0; nv];
    let n_test = test.examples.len().min(max_test);
    for (b, d) in test.examples.iter().zip(&dtest.examples).take(n_test) {
        let (_, _, h_true) = resample(&b.mesh, &d.mesh);
        let c = controls(&b.mesh);
        for (row, m) in [Some(&model), Some(&fixed), None].into_iter().enumerate() {
            match m {
                Some(m) => m.predict(&c, &mut xi, &mut hp),
                None => hp.iter_mut().for_each(|v| *v = 0.0),
            }
            // out - truth = (h_pred - h_true) n: the error is |h_pred - h_true| per vertex.
            let err = |v: usize| f64::from((hp[v] - h_true[v]) / scale).powi(2);
            sums[row][0] += (0..nv).map(err).sum::<f64>() / nv as f64;
            sums[row][1] += crease.iter().map(|&v| err(v)).sum::<f64>() / crease.len() as f64;
        }
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
}
