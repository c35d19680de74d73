//! Leave-one-out mesh error inside the training set (crease_train::select, one candidate:
//! Gaussian kernel, kappa 1e-3, given beta) for control-point sets given on the command line.
//!
//! `cargo run --release -p crease-train --example control_loo -- TRAIN BETA SET [SET ...]`,
//! each SET comma-separated vertex indices or `auto:N`.

use crease_core::mesh::examples::ExampleSet;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{KernelChoice, RegressOptions};
use crease_train::select::{self, SelectGrid};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let train = ExampleSet::load(&args[1]).expect("train");
    let beta: f32 = args[2].parse().expect("beta");
    let frames = train.frames();
    let names = train.names();
    let mut options = TrainOptions::default();
    options.fit.bones = 150;
    options.fit.max_influences = 8;
    let mut base = pipeline::train_base(
        TrainInput {
            rest: &train.rest,
            frames: &frames,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .unwrap();
    let grid = SelectGrid {
        kernels: vec![KernelChoice::Gaussian { scale: 1.0 }],
        kappas: vec![1e-3],
        betas: vec![beta],
    };
    for set in &args[3..] {
        let controls = match set.strip_prefix("auto:") {
            Some(n) => {
                let spec = ControlSpec::Auto(n.parse().unwrap());
                let ControlSpec::Auto(n) = spec else {
                    unreachable!()
                };
                crease_train::controls::auto_control_points(&train.rest, &frames, n).unwrap()
            }
            None => set.split(',').map(|v| v.parse().unwrap()).collect(),
        };
        base.example_controls = frames
            .iter()
            .map(|f| controls.iter().map(|&v: &u32| f[v as usize]).collect())
            .collect();
        base.control_vertices = controls.clone();
        let s = select::select(&base, &frames, &RegressOptions::default(), &grid).unwrap();
        println!("{controls:?}: loo {:.5}", s.best.rms);
    }
}
