//! The HZY11 §5.2 detail regressor (`crease_train::detail::regress`): the collapsed matrix
//! `D xi(c) + b` equals per-vertex 1-D KCCA fits made one vertex at a time, training poses are
//! reproduced, held-out poses are predicted better than by the static detail, and bad input
//! is refused with the field named.

use std::time::Instant;

use crease_core::runtime::kernel::Kernel;
use crease_train::detail::regress::{self, DetailFitError, DetailInput, DetailRegressor};
use crease_train::kcca::{KccaOptions, fit_kcca};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// `n` random control vectors of dimension `d` and, per example, `v` displacements that are
/// smooth nonlinear functions of them (a crease deepening with a "joint angle" x0, a bulge
/// with x1 * x2, and a static texture).
fn data(n: usize, d: usize, v: usize, seed: u64) -> (Vec<f32>, Vec<Vec<f32>>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let x: Vec<f32> = (0..n * d).map(|_| rng.random_range(-1.0..1.0)).collect();
    let h = (0..n)
        .map(|l| {
            let c = &x[l * d..(l + 1) * d];
            (0..v)
                .map(|k| {
                    let t = k as f32 / v as f32;
                    let crease = (1.0 - (t - 0.3).abs() * 8.0).max(0.0) * (c[0] + 1.0).powi(2);
                    let bulge = (t * 6.0).sin() * c[1] * c[2];
                    let texture = 0.05 * (k as f32 * 1.7).sin();
                    1e-3 * (crease + bulge + texture)
                })
                .collect()
        })
        .collect();
    (x, h)
}

#[test]
fn collapsed_matrix_equals_one_vertex_at_a_time() {
    let (n, d, v) = (12, 6, 40);
    let (x, h) = data(n, d, v, 1);
    let kernel = Kernel::Gaussian { sigma: 1.1 };
    let opts = KccaOptions::default();
    let model = regress::fit(DetailInput::Controls, &x, d, &h, Some(kernel), &opts).unwrap();
    assert_eq!(model.vertex_count(), v);
    let mut xi = vec![0.0; n];
    let mut out = vec![0.0; v];
    let (probe, _) = data(3, d, v, 99);
    for c in probe.chunks(d) {
        model.predict(c, &mut xi, &mut out);
        for k in 0..v {
            // The same vertex fitted alone, through the general multi-output entry point.
            let column: Vec<f32> = h.iter().map(|hl| hl[k]).collect();
            let single = fit_kcca(
                &x,
                d,
                &column,
                kernel,
                &KccaOptions {
                    n_bases: 1,
                    ..opts.clone()
                },
            );
            let mut xk = vec![0.0; n];
            kernel.kernel_vector(c, &x, d, &mut xk);
            let mut one = [0.0];
            single.predict(&xk, &mut one);
            assert!(
                (out[k] - one[0]).abs() <= 1e-6 * (1.0 + one[0].abs()),
                "vertex {k}: {} vs {}",
                out[k],
                one[0]
            );
        }
    }
}

#[test]
fn training_poses_are_reproduced_and_held_out_beats_static() {
    let (n, d, v) = (14, 6, 60);
    let (x, h) = data(n, d, v, 2);
    let opts = KccaOptions {
        kappa: 1e-6,
        ..KccaOptions::default()
    };
    let model = regress::fit(DetailInput::Controls, &x, d, &h, None, &opts).unwrap();
    let mut xi = vec![0.0; n];
    let mut out = vec![0.0; v];
    let scale = h.iter().flatten().fold(0.0f32, |m, &a| m.max(a.abs()));
    for (l, hl) in h.iter().enumerate() {
        model.predict(&x[l * d..(l + 1) * d], &mut xi, &mut out);
        let err = out
            .iter()
            .zip(hl)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(
            err < 0.02 * scale,
            "example {l}: error {err} (scale {scale})"
        );
    }
    // Held out: pose-dependent vs static (the rest's displacements everywhere).
    let fixed = DetailRegressor::fixed(DetailInput::Controls, d, h[0].clone());
    let (tx, th) = data(20, d, v, 3);
    let rms = |m: &DetailRegressor| {
        let mut xi = vec![0.0; m.example_count()];
        let mut o = vec![0.0; v];
        let mut s = 0.0f64;
        for (l, hl) in th.iter().enumerate() {
            m.predict(&tx[l * d..(l + 1) * d], &mut xi, &mut o);
            s += o
                .iter()
                .zip(hl)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum::<f64>();
        }
        (s / (th.len() * v) as f64).sqrt()
    };
    let (pd, st) = (rms(&model), rms(&fixed));
    eprintln!("held-out RMS: pose-dependent {pd:.3e}, static {st:.3e}");
    assert!(pd < 0.8 * st, "pose-dependent {pd} vs static {st}");
}

#[test]
fn bad_input_is_refused() {
    let (x, mut h) = data(5, 3, 10, 4);
    h[2].pop();
    let err = regress::fit(
        DetailInput::Controls,
        &x,
        3,
        &h,
        None,
        &KccaOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(err, DetailFitError::Shape(ref m) if m.contains("example 2")),
        "{err}"
    );
    let (mut x, h) = data(5, 3, 10, 4);
    x[7] = f32::NAN;
    let err = regress::fit(
        DetailInput::Controls,
        &x,
        3,
        &h,
        None,
        &KccaOptions::default(),
    )
    .unwrap_err();
    assert_eq!(
        err,
        DetailFitError::NotFinite {
            what: "input",
            index: 7
        }
    );
}

/// Fit and per-frame cost at the hand's size: 14 examples, 45 control coordinates, 151K
/// vertices. `cargo test --release -p crease-train --test all -- --ignored --nocapture
/// detail_regress::hand_sized`
#[test]
#[ignore = "timing"]
fn hand_sized_fit_and_predict_timing() {
    let (n, d, v) = (14, 45, 151_328);
    let (x, h) = data(n, d, v, 5);
    let start = Instant::now();
    let model = regress::fit(
        DetailInput::Controls,
        &x,
        d,
        &h,
        None,
        &KccaOptions::default(),
    )
    .unwrap();
    eprintln!("fit: {:?} for {v} vertices x {n} examples", start.elapsed());
    let mut xi = vec![0.0; n];
    let mut out = vec![0.0; v];
    let frames = 50;
    let start = Instant::now();
    for l in 0..frames {
        let k = l % n;
        model.predict(&x[k * d..(k + 1) * d], &mut xi, &mut out);
    }
    eprintln!(
        "predict h = D xi + b: {:?} per frame",
        start.elapsed() / frames as u32
    );
}
