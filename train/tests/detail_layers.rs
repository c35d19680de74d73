//! Both layers end to end on the real cactus set split automatically (a ~1,200-vertex meshopt
//! base, Laplacian-smoothed; the full 5,261-vertex meshes as the detail): `train_layers` writes a
//! model whose detail layer survives the file round trip, `Predictor::predict_detail` equals the
//! detail synthesis recomputed independently (subdivided mesh, area-weighted normals, one kernel
//! row per vertex), training poses come back closer to their detailed truth with detail than
//! without, and the evaluation's detail rows are complete and consistent.

use std::sync::Arc;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::mesh::examples::ExampleSet;
use crease_core::mesh::subdivision::LoopSubdivision;
use crease_core::model::TrainedModel;
use crease_core::predictor::{PredictError, Predictor};
use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
use crease_train::bones::FitOptions;
use crease_train::detail::layer::{self, DetailFrames, DetailOptions};
use crease_train::detail::{BaseSubset, Smoothing};
use crease_train::eval::{self, DetailEval, EvalOptions};
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

const BASE_VERTICES: usize = 1200;

struct Split {
    full: ExampleSet,
    base: Vec<Mesh>,
}

fn cactus_split() -> Option<Split> {
    let dir = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/cactus"
    ));
    if !dir.is_dir() {
        eprintln!("skipping: {} is absent", dir.display());
        return None;
    }
    let full = ExampleSet::load(dir).unwrap();
    let subset = BaseSubset::simplify(&full.rest, BASE_VERTICES).unwrap();
    let base = full
        .examples
        .iter()
        .map(|e| {
            subset
                .base_mesh(&e.mesh.positions, &Smoothing::default())
                .unwrap()
        })
        .collect();
    Some(Split { full, base })
}

fn options() -> TrainOptions {
    TrainOptions {
        fit: FitOptions {
            bones: 16,
            max_influences: 4,
            max_iterations: 15,
            ..FitOptions::default()
        },
        controls: ControlSpec::Auto(6),
        regress: RegressOptions {
            method: Method::Local,
            ..RegressOptions::default()
        },
        detail: DetailOptions {
            levels: 1,
            // The cactus's bbox is ~2 units; its detail over the smoothed base is ~1% of that.
            max_distance: 0.05,
            ..DetailOptions::default()
        },
        ..TrainOptions::default()
    }
}

/// RMS distance between two point lists.
fn rms(a: &[Vec3], b: &[Vec3]) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| f64::from(p.distance_squared(*q)))
        .sum();
    (s / a.len() as f64).sqrt()
}

#[test]
fn both_layers_train_round_trip_and_synthesise_as_computed_by_hand() {
    let Some(split) = cactus_split() else { return };
    let rest = &split.base[0];
    let frames: Vec<&[Vec3]> = split.base.iter().map(|m| m.positions.as_slice()).collect();
    let names: Vec<String> = (0..frames.len()).map(|i| format!("f{i}")).collect();
    let detailed = split.full.frames();
    let dframes = DetailFrames {
        frames: &detailed,
        triangles: &split.full.rest.triangles,
    };
    let input = TrainInput {
        rest,
        frames: &frames,
        names: &names,
    };
    let (model, report) = pipeline::train_layers(
        input,
        Some(dframes),
        &options(),
        &mut |_| {},
        &mut |_, _| {},
    )
    .unwrap();
    let d = report.detail.as_ref().expect("detail report");
    let s = LoopSubdivision::new(rest, 1).unwrap();
    assert_eq!(d.vertices, s.vertex_count());
    assert!(
        d.hits > d.fallbacks,
        "{} hits, {} fallbacks",
        d.hits,
        d.fallbacks
    );
    let layer = model.detail.as_ref().expect("detail layer");
    assert_eq!(layer.regressor.vertex_count(), s.vertex_count());
    assert_eq!(layer.regressor.example_count(), frames.len());

    // The file keeps the detail layer exactly; a model whose D lost a row is refused by name.
    let bytes = model.to_bytes().unwrap();
    assert_eq!(TrainedModel::from_bytes(&bytes).unwrap(), model);
    let mut broken = model.clone();
    let r = &mut broken.detail.as_mut().unwrap().regressor;
    r.operator.rows -= 1;
    r.operator.b.pop();
    let n = r.operator.cols;
    r.operator.m.truncate(r.operator.m.len() - n);
    let err = broken.to_bytes().unwrap_err().to_string();
    assert!(err.contains("displacement rows"), "{err}");

    // predict_detail against an independent computation for a training pose's controls.
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    let mut ctx = predictor.new_context();
    let k = frames.len() / 2;
    let controls: Vec<Vec3> = model
        .controls
        .iter()
        .map(|c| frames[k][c.vertex as usize])
        .collect();
    let base = predictor
        .predict(&mut ctx, &controls, None)
        .unwrap()
        .to_vec();
    let got = predictor.predict_detail(&mut ctx).unwrap().to_vec();
    let high = s.mesh(&base).unwrap();
    let normals = high.vertex_normals();
    let x: Vec<f32> = controls.iter().flat_map(|p| p.to_array()).collect();
    let r = &layer.regressor;
    let xi: Vec<f32> = r
        .examples
        .chunks(r.d_in)
        .map(|xl| r.kernel.eval(&x, xl))
        .collect();
    let scale = rest.bbox_diagonal_scale();
    for v in 0..high.vertex_count() {
        let row = &r.operator.m[v * xi.len()..(v + 1) * xi.len()];
        let h: f32 = row.iter().zip(&xi).map(|(a, b)| a * b).sum::<f32>() + r.operator.b[v];
        let want = high.positions[v] + h * normals[v];
        assert!(
            (got[v] - want).length() < 1e-5 * scale,
            "vertex {v}: {} vs {want}",
            got[v]
        );
    }

    // Training poses on their true base: the regressed h reproduces the resampled detailed
    // truth (S B + h n) to a tenth of the detail's own size (kappa regularises, so not exactly).
    let mut synth = crease_core::runtime::detail::DetailSynth::from_mesh(rest, 1).unwrap();
    let (h, _) = layer::resample(
        &mut synth,
        &frames,
        dframes,
        options().detail.max_distance * scale,
        |_, _| {},
    )
    .unwrap();
    let nv = s.vertex_count();
    let (mut truth, mut out, mut hp) = (vec![Vec3::ZERO; nv], vec![Vec3::ZERO; nv], vec![0.0; nv]);
    let mut xi = vec![0.0; r.example_count()];
    for (k, f) in frames.iter().enumerate() {
        let x: Vec<f32> = model
            .controls
            .iter()
            .flat_map(|cp| f[cp.vertex as usize].to_array())
            .collect();
        r.predict(&x, &mut xi, &mut hp);
        synth.synthesize(f, &h[k], &mut truth).unwrap();
        synth.synthesize(f, &hp, &mut out).unwrap();
        let size = (h[k].iter().map(|v| f64::from(v * v)).sum::<f64>() / nv as f64).sqrt();
        let err = rms(&out, &truth);
        assert!(
            err < 0.1 * size,
            "pose {k}: detail reproduced to {err:.3e}, the detail's RMS is {size:.3e}"
        );
    }

    // Another regressor of the wrong shape is refused by name; the cascaded shape works.
    let wrong = DetailRegressor::fixed(DetailInput::Controls, 3, vec![0.0; 7]);
    assert!(matches!(
        predictor.predict_detail_with(&mut ctx, &wrong),
        Err(PredictError::DetailRegressor(m)) if m.contains("7 displacement rows")
    ));
    let cascaded = DetailRegressor::fixed(
        DetailInput::Rotations,
        4 * model.rig.bone_count,
        vec![0.0; s.vertex_count()],
    );
    let flat = predictor
        .predict_detail_with(&mut ctx, &cascaded)
        .unwrap()
        .to_vec();
    assert!(rms(&flat, &s.mesh(ctx.positions()).unwrap().positions) < 1e-6 * f64::from(scale));
}

#[test]
fn evaluation_detail_rows_are_complete_and_consistent() {
    let Some(split) = cactus_split() else { return };
    let frames: Vec<&[Vec3]> = split.base.iter().map(|m| m.positions.as_slice()).collect();
    let names: Vec<String> = (0..frames.len()).map(|i| format!("f{i}")).collect();
    let detailed = split.full.frames();
    // Train on the first 12 poses, test on the rest.
    let (train, test) = frames.split_at(12);
    let (dtrain, dtest) = detailed.split_at(12);
    let opts = options();
    let eval_opts = EvalOptions {
        train: opts.clone(),
        methods: vec![Method::Global, Method::Local],
        beta: 1.0,
        refine: None,
    };
    let table = eval::evaluate_test_layers(
        TrainInput {
            rest: &split.base[0],
            frames: train,
            names: &names[..12],
        },
        eval::HeldOut {
            names: &names[12..],
            frames: test,
        },
        Some(DetailEval {
            train: DetailFrames {
                frames: dtrain,
                triangles: &split.full.rest.triangles,
            },
            test: Some(DetailFrames {
                frames: dtest,
                triangles: &split.full.rest.triangles,
            }),
            options: &opts.detail,
        }),
        &eval_opts,
        &mut |_| {},
    )
    .unwrap();
    for row in [
        "global",
        "local",
        "static-detail",
        "cascaded-detail",
        "true-base",
        "true-base-static",
    ] {
        let s = table
            .get(row)
            .unwrap_or_else(|| panic!("row {row} missing"));
        assert_eq!(s.detail_frames.len(), test.len(), "{row}");
        for v in [
            s.base_rms_mean,
            s.detail_rms_mean,
            s.crease_rms_mean,
            s.crease_h_rms_mean,
        ] {
            assert!(v.is_some_and(f64::is_finite), "{row}: {v:?}");
        }
    }
    // The baselines share the local base; the true base is nearer the truth than any
    // prediction; the pose-dependent and static rows on the true base differ only in h.
    let local = &table["local"];
    assert_eq!(table["static-detail"].rms_mean, local.rms_mean);
    assert_eq!(table["cascaded-detail"].rms_mean, local.rms_mean);
    assert_eq!(local.base_rms_mean, Some(local.rms_mean));
    for row in ["global", "local"] {
        assert!(table["true-base"].detail_rms_mean < table[row].detail_rms_mean);
    }
    assert_eq!(
        table["local"].crease_h_rms_mean,
        table["true-base"].crease_h_rms_mean
    );
}
