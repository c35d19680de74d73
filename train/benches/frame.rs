//! Per-frame synthesis on the horse (issue 3): predict rotations, solve translations, skin.
//! Trains the 150-bone, 8-control-point global model of the split once (about 10 s),
//! then times each stage and the whole frame on the 12 test poses' control points.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p crease-train --bench frame -- --quick`
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::path::Path;
use std::sync::Arc;

use crease_core::glam::Vec3;
use crease_core::mesh::examples::ExampleSet;
use crease_core::predictor::{Predictor, Refinement};
use crease_train::bones::FitOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../bench/horse"));
    let data = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/horse"
    ));
    if !data.is_dir() {
        eprintln!("skipping the frame benchmark: {} is absent", data.display());
        return;
    }
    let train = ExampleSet::load(root.join("train.toml")).expect("train set");
    let test = ExampleSet::load(root.join("test.toml")).expect("test set");
    let frames: Vec<&[Vec3]> = train.frames();
    let names: Vec<String> = train.names();
    let options = TrainOptions {
        fit: FitOptions {
            bones: 150,
            max_influences: 8,
            ..FitOptions::default()
        },
        controls: ControlSpec::Auto(8),
        regress: RegressOptions::default(),
        ..TrainOptions::default()
    };
    let base = pipeline::train_base(
        TrainInput {
            rest: &train.rest,
            frames: &frames,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .expect("training");
    let inputs: Vec<Vec<Vec3>> = test
        .examples
        .iter()
        .map(|e| {
            base.control_vertices
                .iter()
                .map(|&v| e.mesh.positions[v as usize])
                .collect()
        })
        .collect();
    for method in [Method::Global, Method::Local] {
        let model = Arc::new(base.model(
            &RegressOptions {
                method,
                ..RegressOptions::default()
            },
            1.0,
        ));
        let predictor = Predictor::new(model.clone(), None).expect("predictor");
        let mut ctx = predictor.new_context();
        let mut g = c.benchmark_group(format!("horse_150_bones_{}", method.name()));
        let mut i = 0;
        g.bench_function("predict_rotations", |b| {
            let mut scratch = Default::default();
            let mut out = vec![Default::default(); model.rig.bone_count];
            b.iter(|| {
                i = (i + 1) % inputs.len();
                model.rotations.predict(&inputs[i], &mut scratch, &mut out);
            })
        });
        g.bench_function("rotations_and_translations", |b| {
            b.iter(|| {
                i = (i + 1) % inputs.len();
                predictor
                    .predict_transforms(&mut ctx, &inputs[i], None)
                    .unwrap();
            })
        });
        g.bench_function("skin", |b| b.iter(|| predictor.skin(&mut ctx).unwrap()));
        g.bench_function("whole_frame", |b| {
            b.iter(|| {
                i = (i + 1) % inputs.len();
                predictor.predict(&mut ctx, &inputs[i], None).unwrap();
            })
        });
        // Issue 20's bone-level refinement on top of the transforms (test frames lie off the
        // examples, so every one is refined).
        if method == Method::Global {
            for iterations in [1usize, 4, 8, 20] {
                let mut refined = Predictor::new(model.clone(), None).expect("predictor");
                refined.set_refinement(Some(Refinement {
                    iterations,
                    strength: 0.01,
                    from_rest: false,
                }));
                let mut ctx = refined.new_context();
                g.bench_function(format!("transforms_refined_{iterations}"), |b| {
                    b.iter(|| {
                        i = (i + 1) % inputs.len();
                        refined
                            .predict_transforms(&mut ctx, &inputs[i], None)
                            .unwrap();
                    })
                });
            }
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
