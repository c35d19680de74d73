//! Kernel CCA regression (FKY08 §4) and the RBF baseline against independent computations:
//! a least-squares linear fit, an explicit centred-kernel prediction, a bordered RBF solve, and
//! analytically known degenerate cases.

use crease_core::runtime::kernel::Kernel;
use crease_train::kcca::{
    KccaOptions, LinearModel, default_sigma, fit_kcca, fit_kcca_per_block,
    fit_kcca_per_block_centred, fit_rbf,
};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng, rngs::StdRng};

/// `n` random 2-D inputs in `[-r, r]^2`, row-major.
fn inputs(rng: &mut StdRng, n: usize, r: f32) -> Vec<f32> {
    (0..2 * n).map(|_| rng.random_range(-r..r)).collect()
}

/// Applies `f` to each 2-D row.
fn outputs<const D: usize>(x: &[f32], f: impl Fn(f32, f32) -> [f32; D]) -> Vec<f32> {
    x.chunks_exact(2).flat_map(|p| f(p[0], p[1])).collect()
}

/// Predicts every row of `x` (dimension `d_in`) through the core kernel vector.
fn predict_all(model: &LinearModel, kernel: Kernel, train_x: &[f32], x: &[f32]) -> Vec<f32> {
    let d_in = model.d_in;
    let mut xi = vec![0.0f32; model.n];
    let mut out = vec![0.0f32; model.d_out];
    let mut all = Vec::new();
    for row in x.chunks_exact(d_in) {
        kernel.kernel_vector(row, train_x, d_in, &mut xi);
        model.predict(&xi, &mut out);
        all.extend_from_slice(&out);
    }
    all
}

fn rms(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let ss: f64 = a
        .iter()
        .zip(b)
        .map(|(&p, &q)| (f64::from(p) - f64::from(q)).powi(2))
        .sum();
    (ss / a.len() as f64).sqrt()
}

/// The best affine least-squares map `y = A x + c`, fitted and applied here, independently of
/// the crate.
fn linear_fit_predict(x: &[f32], y: &[f32], d_out: usize, test_x: &[f32]) -> Vec<f32> {
    let n = x.len() / 2;
    let a = DMatrix::from_fn(
        n,
        3,
        |i, j| {
            if j < 2 { f64::from(x[2 * i + j]) } else { 1.0 }
        },
    );
    let b = DMatrix::from_fn(n, d_out, |i, j| f64::from(y[i * d_out + j]));
    let coef = (a.transpose() * &a)
        .lu()
        .solve(&(a.transpose() * b))
        .unwrap();
    test_x
        .chunks_exact(2)
        .flat_map(|p| {
            let row = DMatrix::from_row_slice(1, 3, &[f64::from(p[0]), f64::from(p[1]), 1.0]);
            (row * &coef).iter().map(|&v| v as f32).collect::<Vec<_>>()
        })
        .collect()
}

fn nonlinear(x0: f32, x1: f32) -> [f32; 3] {
    [(2.0 * x0).sin(), (1.5 * x1).cos(), x0 * x1]
}

#[test]
fn kcca_beats_linear_fit_on_a_nonlinear_map() {
    let mut rng = StdRng::seed_from_u64(7);
    let train_x = inputs(&mut rng, 80, 1.5);
    let test_x = inputs(&mut rng, 300, 1.4);
    let train_y = outputs(&train_x, nonlinear);
    let test_y = outputs(&test_x, nonlinear);
    let kernel = Kernel::Gaussian {
        sigma: default_sigma(&train_x, 2),
    };

    let kcca = fit_kcca(&train_x, 2, &train_y, kernel, &KccaOptions::default());
    let kcca_rms = rms(&predict_all(&kcca, kernel, &train_x, &test_x), &test_y);
    let per_output = fit_kcca_per_block(&train_x, 2, &train_y, 1, kernel, &KccaOptions::default());
    let per_output_rms = rms(
        &predict_all(&per_output, kernel, &train_x, &test_x),
        &test_y,
    );
    let rbf = fit_rbf(&train_x, 2, &train_y, 3, kernel, 1e-6);
    let rbf_rms = rms(&predict_all(&rbf, kernel, &train_x, &test_x), &test_y);
    let linear_rms = rms(&linear_fit_predict(&train_x, &train_y, 3, &test_x), &test_y);
    println!(
        "held-out RMS: kcca {kcca_rms:.5}, kcca per output {per_output_rms:.5}, rbf {rbf_rms:.5}, \
         linear {linear_rms:.5}"
    );
    assert!(
        kcca_rms < 0.2 * linear_rms,
        "{kcca_rms} vs linear {linear_rms}"
    );
    assert!(
        per_output_rms < 0.2 * linear_rms,
        "{per_output_rms} vs linear {linear_rms}"
    );
    assert!(
        rbf_rms < 0.2 * linear_rms,
        "{rbf_rms} vs linear {linear_rms}"
    );
}

#[test]
fn kcca_reproduces_training_outputs_with_full_bases_and_tiny_regularisation() {
    let mut rng = StdRng::seed_from_u64(11);
    let x = inputs(&mut rng, 25, 1.0);
    let y = outputs(&x, |a, b| [a.exp(), (3.0 * b).sin(), a * a - b, 0.5]);
    let kernel = Kernel::Gaussian {
        sigma: default_sigma(&x, 2),
    };
    let opts = KccaOptions {
        n_bases: 4,
        kappa: 1e-12,
        ..KccaOptions::default()
    };
    let model = fit_kcca(&x, 2, &y, kernel, &opts);
    let fitted = predict_all(&model, kernel, &x, &x);
    let err = rms(&fitted, &y);
    println!("training RMS with kappa = 1e-12: {err:.2e}");
    assert!(err < 1e-3, "{err}");
    // The constant column stays constant (its whitening direction is regularised, not NaN).
    assert!(fitted.chunks_exact(4).all(|r| (r[3] - 0.5).abs() < 1e-5));
}

#[test]
fn folded_model_equals_explicit_centred_kernel_prediction() {
    let mut rng = StdRng::seed_from_u64(3);
    let x = inputs(&mut rng, 15, 1.0);
    let y = outputs(&x, |a, b| {
        [a.sin(), b * b, a + b, a * b, b.cos(), a.cos(), 1.0 - a, b]
    });
    let kernel = Kernel::Gaussian { sigma: 0.8 };
    let opts = KccaOptions::default();
    let centred = fit_kcca_per_block_centred(&x, 2, &y, 4, kernel, &opts);
    let folded = fit_kcca_per_block(&x, 2, &y, 4, kernel, &opts);
    assert_eq!((folded.d_in, folded.d_out, folded.n), (2, 8, 15));
    assert_eq!(folded.m.len(), 8 * 15);

    // Centred kernel vectors by the textbook formula, element by element:
    // xi~_j = k(x, x_j) - mean_l k(x, x_l) - mean_l k(x_l, x_j) + mean_{l,m} k(x_l, x_m).
    let n = 15;
    let row = |i: usize| &x[2 * i..2 * i + 2];
    let k = DMatrix::from_fn(n, n, |i, j| kernel.eval_f64(row(i), row(j)));
    let k_all_mean = k.mean();
    for probe in inputs(&mut rng, 10, 1.2).chunks_exact(2) {
        let xi: Vec<f64> = (0..n).map(|j| kernel.eval_f64(probe, row(j))).collect();
        let xi_mean = xi.iter().sum::<f64>() / n as f64;
        let xi_c = DVector::from_fn(n, |j, _| xi[j] - xi_mean - k.column(j).mean() + k_all_mean);
        let expected = &centred.mean_y + &centred.m * xi_c;

        let xi32: Vec<f32> = xi.iter().map(|&v| v as f32).collect();
        let mut got = vec![0.0f32; 8];
        folded.predict(&xi32, &mut got);
        for (g, e) in got.iter().zip(expected.iter()) {
            assert!((f64::from(*g) - e).abs() < 1e-4, "{g} vs {e}");
        }
    }
    // Folding the centring makes every row annihilate constant kernel vectors.
    for r in folded.m.chunks_exact(n) {
        assert!(r.iter().map(|&v| f64::from(v)).sum::<f64>().abs() < 1e-4);
    }
}

#[test]
fn per_block_fit_stacks_independent_fits() {
    let mut rng = StdRng::seed_from_u64(5);
    let x = inputs(&mut rng, 20, 1.0);
    let y = outputs(&x, |a, b| {
        [a, b, a * b, 1.0, a.sin(), b.sin(), (a - b).cos(), a * a]
    });
    let kernel = Kernel::Gaussian { sigma: 0.7 };
    let opts = KccaOptions::default();
    let stacked = fit_kcca_per_block(&x, 2, &y, 4, kernel, &opts);
    for blk in 0..2 {
        let y_blk: Vec<f32> = y
            .chunks_exact(8)
            .flat_map(|r| r[4 * blk..4 * blk + 4].iter().copied())
            .collect();
        let single = fit_kcca(&x, 2, &y_blk, kernel, &opts);
        let rows = &stacked.m[4 * blk * 20..(4 * blk + 4) * 20];
        let max_m = rows
            .iter()
            .zip(&single.m)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(max_m < 1e-5, "block {blk}: {max_m}");
        for (a, b) in stacked.b[4 * blk..4 * blk + 4].iter().zip(&single.b) {
            assert!((a - b).abs() < 1e-5);
        }
    }
}

#[test]
fn polynomial_kernel_recovers_a_polynomial_target() {
    let mut rng = StdRng::seed_from_u64(13);
    let train_x = inputs(&mut rng, 40, 1.0);
    let test_x = inputs(&mut rng, 200, 1.0);
    // Every output is a degree-2 polynomial: linear in the features of (x.y + 1)^2.
    let f = |a: f32, b: f32| [a * a - b, a * b + 0.5 * a, 2.0 * b * b - 1.0];
    let train_y = outputs(&train_x, f);
    let test_y = outputs(&test_x, f);
    let kernel = Kernel::Polynomial { c: 1.0, degree: 2 };
    let opts = KccaOptions {
        kappa: 1e-9,
        ..KccaOptions::default()
    };
    let model = fit_kcca(&train_x, 2, &train_y, kernel, &opts);
    let err = rms(&predict_all(&model, kernel, &train_x, &test_x), &test_y);
    let linear = rms(&linear_fit_predict(&train_x, &train_y, 3, &test_x), &test_y);
    println!("polynomial target, held-out RMS: kcca (poly 2) {err:.2e}, linear {linear:.4}");
    assert!(err < 1e-3, "{err}");
}

#[test]
fn constant_outputs_give_a_constant_prediction() {
    let mut rng = StdRng::seed_from_u64(17);
    let x = inputs(&mut rng, 12, 1.0);
    let y: Vec<f32> = (0..12).flat_map(|_| [0.25f32, -3.0, 0.0, 1.0]).collect();
    for kernel in [
        Kernel::Gaussian { sigma: 0.5 },
        Kernel::Polynomial { c: 1.0, degree: 5 },
    ] {
        let model = fit_kcca_per_block(&x, 2, &y, 4, kernel, &KccaOptions::default());
        let rbf = fit_rbf(&x, 2, &y, 4, kernel, 0.0);
        for m in [&model, &rbf] {
            assert!(m.m.iter().chain(&m.b).all(|v| v.is_finite()));
            for p in predict_all(m, kernel, &x, &inputs(&mut rng, 5, 3.0)).chunks_exact(4) {
                for (a, b) in p.iter().zip([0.25f32, -3.0, 0.0, 1.0]) {
                    assert!((a - b).abs() < 1e-5, "{p:?}");
                }
            }
        }
    }
}

#[test]
fn identical_inputs_predict_the_mean_output() {
    let x = [0.5f32, -0.5].repeat(6);
    let y: Vec<f32> = (0..6).flat_map(|i| [i as f32, 2.0 * i as f32]).collect();
    let kernel = Kernel::Gaussian { sigma: 1.0 };
    let model = fit_kcca(&x, 2, &y, kernel, &KccaOptions::default());
    let p = predict_all(&model, kernel, &x, &[0.5, -0.5, 3.0, 1.0]);
    for r in p.chunks_exact(2) {
        assert!(
            (r[0] - 2.5).abs() < 1e-5 && (r[1] - 5.0).abs() < 1e-5,
            "{r:?}"
        );
    }
}

#[test]
fn one_example_predicts_its_output_everywhere() {
    let kernel = Kernel::Gaussian { sigma: 1.0 };
    let x = [0.3f32, 0.7, -0.1];
    let y = [1.0f32, 0.0, 0.0, 0.0];
    let model = fit_kcca_per_block(&x, 3, &y, 4, kernel, &KccaOptions::default());
    let rbf = fit_rbf(&x, 3, &y, 4, kernel, 1e-6);
    for m in [&model, &rbf] {
        assert_eq!((m.n, m.d_out), (1, 4));
        for probe in [[0.3f32, 0.7, -0.1], [5.0, -2.0, 1.0]] {
            let p = predict_all(m, kernel, &x, &probe);
            assert_eq!(p, y);
        }
    }
}

#[test]
fn two_examples_reproduce_both_outputs() {
    let kernel = Kernel::Gaussian { sigma: 1.0 };
    let x = [0.0f32, 0.0, 1.0, 0.5];
    let y = [1.0f32, 0.0, 0.0, 0.0, 0.8, 0.6, 0.0, 0.0];
    let model = fit_kcca_per_block(&x, 2, &y, 4, kernel, &KccaOptions::default());
    let p = predict_all(&model, kernel, &x, &x);
    assert!(rms(&p, &y) < 1e-4, "{p:?}");
    let mid = predict_all(&model, kernel, &x, &[0.5, 0.25]);
    assert!(mid.iter().all(|v| v.is_finite()));
    // Halfway between, by symmetry of the Gaussian kernel, the prediction is the mean.
    for (m, e) in mid.iter().zip([0.9f32, 0.3, 0.0, 0.0]) {
        assert!((m - e).abs() < 1e-5, "{mid:?}");
    }
}

#[test]
fn rbf_with_zero_ridge_equals_the_bordered_interpolation_system() {
    let mut rng = StdRng::seed_from_u64(19);
    let n = 12;
    let x = inputs(&mut rng, n, 1.0);
    let y = outputs(&x, |a, b| [a.sin() + b, a * b]);
    let kernel = Kernel::Gaussian { sigma: 0.6 };
    let model = fit_rbf(&x, 2, &y, 2, kernel, 0.0);
    // [K 1; 1^T 0] [alpha; b] = [y; 0], solved here directly.
    let row = |i: usize| &x[2 * i..2 * i + 2];
    let a = DMatrix::from_fn(n + 1, n + 1, |i, j| match (i < n, j < n) {
        (true, true) => kernel.eval_f64(row(i), row(j)),
        (true, false) | (false, true) => 1.0,
        (false, false) => 0.0,
    });
    let rhs = DMatrix::from_fn(
        n + 1,
        2,
        |i, j| if i < n { f64::from(y[2 * i + j]) } else { 0.0 },
    );
    let sol = a.lu().solve(&rhs).unwrap();
    for j in 0..2 {
        for l in 0..n {
            let got = f64::from(model.m[j * n + l]);
            assert!(
                (got - sol[(l, j)]).abs() < 2e-3 * (1.0 + sol[(l, j)].abs()),
                "{got} vs {}",
                sol[(l, j)]
            );
        }
        assert!((f64::from(model.b[j]) - sol[(n, j)]).abs() < 1e-3);
    }
    assert!(rms(&predict_all(&model, kernel, &x, &x), &y) < 1e-3);
}
