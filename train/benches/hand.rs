//! Both layers on the generated hand (issue 5): `crease handgen --train 14 --test 40 --seed 1`,
//! back-side 15 control points, 40 proxy bones (K = 4), local method (HZY11) with the kernel,
//! kappa and beta chosen by leave-one-out (`--select`), detail layer 2 Loop levels (151,298
//! vertices). Training both layers is timed once (printed); then per frame, over the 40 test
//! poses' control points:
//!
//! - `base/frame`: controls -> rotations -> translations -> skinned base ([`Predictor::predict`]);
//! - `base/transforms`, `base/skin`: its two halves;
//! - `detail/frame`: the detail layer on that base ([`Predictor::predict_detail`]: `h = D xi + b`,
//!   `S · base`, normals, `+ h n`);
//! - `detail/regress`: `h = D xi + b` alone; `detail/synth`: `S · base`, normals, `+ h n` alone;
//! - `memcpy`: a plain copy of the detailed output's bytes.
//!
//! The data set is read from `$CREASE_HANDGEN` or generated once into `target/bench-handgen`
//! (~10 s, 374 MB). Single thread: `RAYON_NUM_THREADS=1 cargo bench -p crease-train --bench
//! hand -- --quick`. After criterion's groups it prints medians (and minima) of its own timing
//! loop.

#[path = "../../core/benches/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::timings;
use crease_core::glam::Vec3;
use crease_core::mesh::examples::ExampleSet;
use crease_core::predictor::Predictor;
use crease_core::runtime::detail::DetailSynth;
use crease_hand::dataset::write_dataset;
use crease_hand::surface::Resolution;
use crease_train::bones::FitOptions;
use crease_train::detail::layer::DetailFrames;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};
use crease_train::select::SelectGrid;
use criterion::Criterion;

const FRAMES: usize = 200;

fn data_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("CREASE_HANDGEN") {
        return PathBuf::from(d);
    }
    let dir = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../target/bench-handgen"
    ));
    if !dir.join("handgen.json").is_file() {
        eprintln!("generating the hand data set into {}", dir.display());
        write_dataset(
            &dir,
            14,
            40,
            1,
            &[Resolution::Base, Resolution::Detailed],
            |_| {},
        )
        .expect("crease handgen");
    }
    dir
}

fn main() {
    let dir = data_dir();
    let train = ExampleSet::load(dir.join("train-back.toml")).expect("train set");
    let detailed = train
        .load_detailed()
        .expect("detailed train set")
        .expect("the manifest names its detailed set");
    let test = ExampleSet::load(dir.join("test.toml")).expect("test set");
    let options = TrainOptions {
        fit: FitOptions {
            bones: 40,
            max_influences: 4,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(train.control_points.clone().expect("control points")),
        regress: RegressOptions {
            method: Method::Local,
            ..RegressOptions::default()
        },
        select: Some(SelectGrid::default()),
        ..TrainOptions::default()
    };
    let frames = train.frames();
    let names = train.names();
    let dframes = detailed.frames();
    let t = Instant::now();
    let (model, report) = pipeline::train_layers(
        TrainInput {
            rest: &train.rest,
            frames: &frames,
            names: &names,
        },
        Some(DetailFrames {
            frames: &dframes,
            triangles: &detailed.rest.triangles,
        }),
        &options,
        &mut |_| {},
        &mut |_, _| {},
    )
    .expect("training");
    let d = report.detail.as_ref().expect("detail report");
    println!(
        "training, both layers, {} examples: {:.1} s wall (bones {:.1} s, regressors + selection {:.1} s, edge skin {:.1} s, detail resampling {:.1} s, detail regression {:.1} s); {}",
        frames.len(),
        t.elapsed().as_secs_f64(),
        report.fit.seconds,
        report.regress_seconds,
        report.edges_seconds,
        d.extract_seconds,
        d.fit_seconds,
        threads()
    );
    let predictor = Predictor::new(Arc::new(model), None).expect("predictor");
    let controls: Vec<Vec<Vec3>> = test
        .examples
        .iter()
        .map(|e| {
            predictor
                .model()
                .controls
                .iter()
                .map(|c| e.mesh.positions[c.vertex as usize])
                .collect()
        })
        .collect();
    let nv = predictor.detail_vertex_count().expect("detail layer");
    let regressor = &predictor.model().detail.as_ref().expect("detail").regressor;
    let mut ctx = predictor.new_context();
    let mut k = 0;
    let mut next = || {
        k = (k + 1) % controls.len();
        &controls[k]
    };

    let mut c = Criterion::default()
        .configure_from_args()
        .measurement_time(Duration::from_secs(3));
    let mut g = c.benchmark_group("hand");
    g.bench_function("base/frame", |b| {
        b.iter(|| {
            let c = next();
            black_box(predictor.predict(&mut ctx, c, None).expect("frame")[0])
        })
    });
    g.bench_function("detail/frame", |b| {
        b.iter(|| black_box(predictor.predict_detail(&mut ctx).expect("detail")[0]))
    });
    g.finish();
    c.final_summary();

    // Own timing loops: medians and minima of each stage.
    let mut summary = Vec::new();
    let mut row = |name: &str, (median, min): (Duration, Duration)| {
        summary.push(format!(
            "{name:<16} median {:>8.1} µs  min {:>8.1} µs",
            median.as_secs_f64() * 1e6,
            min.as_secs_f64() * 1e6
        ));
    };
    let mut k = 0;
    row(
        "base/frame",
        timings(FRAMES, || {
            k = (k + 1) % controls.len();
            black_box(
                predictor
                    .predict(&mut ctx, &controls[k], None)
                    .expect("frame")[0],
            );
        }),
    );
    row(
        "base/transforms",
        timings(FRAMES, || {
            k = (k + 1) % controls.len();
            predictor
                .predict_transforms(&mut ctx, &controls[k], None)
                .expect("transforms");
        }),
    );
    row(
        "base/skin",
        timings(FRAMES, || predictor.skin(&mut ctx).expect("skin")),
    );
    row(
        "detail/frame",
        timings(FRAMES, || {
            black_box(predictor.predict_detail(&mut ctx).expect("detail")[0]);
        }),
    );
    let x: Vec<f32> = ctx.controls().iter().flat_map(|p| p.to_array()).collect();
    let mut xi = vec![0.0; regressor.example_count()];
    let mut h = vec![0.0; nv];
    row(
        "detail/regress",
        timings(FRAMES, || regressor.predict(&x, &mut xi, &mut h)),
    );
    let mut synth = DetailSynth::from_mesh(&predictor.model().rig.rest, 2).expect("synth");
    let mut out = vec![Vec3::ZERO; nv];
    let base = ctx.positions().to_vec();
    row(
        "detail/synth",
        timings(FRAMES, || {
            synth.synthesize(&base, &h, &mut out).expect("synth")
        }),
    );
    let src = out.clone();
    row(
        "memcpy",
        timings(FRAMES, || {
            out.copy_from_slice(black_box(&src));
            black_box(&out);
        }),
    );
    println!(
        "hand, {} base / {nv} detailed vertices, {} bones, {}:",
        predictor.model().rig.rest.vertex_count(),
        predictor.model().rig.bone_count,
        threads()
    );
    for line in summary {
        println!("  {line}");
    }
}

fn threads() -> String {
    format!("{} rayon threads", rayon_threads())
}

#[cfg(feature = "parallel")]
fn rayon_threads() -> usize {
    rayon::current_num_threads()
}

#[cfg(not(feature = "parallel"))]
fn rayon_threads() -> usize {
    1
}
