//! Issue 20 on the real cactus set: the bone-level refinement leaves every training pose as
//! the regression predicts it (bit for bit), the confidence is 0 at the examples and grows
//! along a path leaving them, and on a frame outside the training span the refinement pulls
//! the control vertices closer to the control points than the regression alone.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::sync::Arc;

use crease_core::glam::Vec3;
use crease_core::mesh::examples::ExampleSet;
use crease_core::predictor::{Predictor, Refinement};
use crease_train::bones::FitOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

fn cactus() -> Option<ExampleSet> {
    let dir = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/cactus"
    ));
    if !dir.is_dir() {
        eprintln!("skipping: {} is absent", dir.display());
        return None;
    }
    Some(ExampleSet::load(dir).unwrap())
}

const REFINE: Refinement = Refinement {
    iterations: 4,
    strength: 0.1,
    from_rest: false,
};

#[test]
fn refinement_keeps_the_examples_and_confidence_measures_the_distance_to_them() {
    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let options = TrainOptions {
        fit: FitOptions {
            bones: 16,
            max_influences: 4,
            max_iterations: 15,
            ..FitOptions::default()
        },
        controls: ControlSpec::Auto(6),
        regress: RegressOptions {
            method: Method::Global,
            ..RegressOptions::default()
        },
        ..TrainOptions::default()
    };
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let base = pipeline::train_base(input, &options, &mut |_| {}).unwrap();
    let model = Arc::new(base.model(&options.regress, 1.0));
    let plain = Predictor::new(Arc::clone(&model), None).unwrap();
    let mut refined = Predictor::new(Arc::clone(&model), None).unwrap();
    refined.set_refinement(Some(REFINE));
    let (mut a, mut b) = (plain.new_context(), refined.new_context());
    let controls_of = |f: &[Vec3]| -> Vec<Vec3> {
        model
            .controls
            .iter()
            .map(|c| f[c.vertex as usize])
            .collect()
    };

    // At every example: confidence 0 and the refined frame is the regression's, bit for bit.
    for (e, f) in frames.iter().enumerate() {
        let c = controls_of(f);
        let p = plain.predict(&mut a, &c, None).unwrap().to_vec();
        let r = refined.predict(&mut b, &c, None).unwrap().to_vec();
        assert_eq!(b.confidence(), 0.0, "example {e}");
        assert!(p == r, "example {e}: the refinement moved a training pose");
    }

    // Along a path leaving an example (away from the examples' mean control vector), the
    // confidence grows, passing 1 (as far out as the training set is spread).
    let mean: Vec<Vec3> = (0..model.controls.len())
        .map(|k| frames.iter().map(|f| controls_of(f)[k]).sum::<Vec3>() / frames.len() as f32)
        .collect();
    let start = controls_of(frames[frames.len() - 1]);
    let mut previous = -1.0f32;
    let mut last = 0.0;
    for step in 0..=20 {
        let s = step as f32 * 0.15;
        let c: Vec<Vec3> = start
            .iter()
            .zip(&mean)
            .map(|(&p, &m)| p + s * (p - m))
            .collect();
        plain.predict(&mut a, &c, None).unwrap();
        let conf = a.confidence();
        assert!(
            conf > previous || (step > 0 && conf >= previous && conf > 1.0),
            "step {step}: confidence {conf} after {previous}"
        );
        previous = conf;
        last = conf;
    }
    assert!(last > 1.0, "the path ends at confidence {last}");

    // Outside the span the constraints pull: the control vertices end closer to the controls.
    let far: Vec<Vec3> = start
        .iter()
        .zip(&mean)
        .map(|(&p, &m)| p + 0.6 * (p - m))
        .collect();
    let residual = |positions: &[Vec3]| -> f32 {
        model
            .controls
            .iter()
            .zip(&far)
            .map(|(c, &t)| positions[c.vertex as usize].distance_squared(t))
            .sum::<f32>()
            .sqrt()
    };
    let p = residual(plain.predict(&mut a, &far, None).unwrap());
    let r = residual(refined.predict(&mut b, &far, None).unwrap());
    eprintln!(
        "confidence {:.2}: control residual {p:.4} regression, {r:.4} refined",
        b.confidence()
    );
    assert!(r < p, "refined {r} vs regression {p}");
}
