//! Training, prediction, model files and evaluation on the real cactus set (19 poses), and
//! issue 20's refinement and confidence on it.

use std::sync::Arc;

use crease_core::glam::Vec3;
use crease_core::mesh::examples::ExampleSet;
use crease_core::model::TrainedModel;
use crease_core::predictor::{Predictor, Refinement};
use crease_train::bones::FitOptions;
use crease_train::eval::{self, EvalOptions, HeldOut};
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

fn options(method: Method) -> TrainOptions {
    TrainOptions {
        fit: FitOptions {
            bones: 16,
            max_influences: 4,
            max_iterations: 15,
            ..FitOptions::default()
        },
        controls: ControlSpec::Auto(6),
        regress: RegressOptions {
            method,
            ..RegressOptions::default()
        },
        ..TrainOptions::default()
    }
}

#[test]
fn every_method_reproduces_training_poses_and_survives_occlusion() {
    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let base = pipeline::train_base(input, &options(Method::Global), &mut |_| {}).unwrap();
    let scale = set.rest.bbox_diagonal_scale();
    for method in Method::ALL {
        let model = base.model(
            &RegressOptions {
                method,
                ..RegressOptions::default()
            },
            1.0,
        );
        // Model files round-trip exactly and reject corruption.
        let bytes = model.to_bytes().unwrap();
        assert_eq!(TrainedModel::from_bytes(&bytes).unwrap(), model);
        for at in [40usize, bytes.len() / 2, bytes.len() - 3] {
            let mut bad = bytes.clone();
            bad[at] ^= 0x10;
            assert!(
                TrainedModel::from_bytes(&bad).is_err(),
                "{method:?}: flipped byte {at} accepted"
            );
        }
        // Predicting a training pose's own control points reproduces its rotations closely.
        let (mean_angle, worst_angle) = training_rotation_error(&base, &model);
        eprintln!(
            "{method:?}: training rotations mean error {mean_angle:.4} rad, worst {worst_angle:.4} rad"
        );
        assert!(
            mean_angle < 0.03 && worst_angle < 0.3,
            "{method:?}: training rotations off: mean {mean_angle}, worst {worst_angle} rad"
        );
        let predictor = Predictor::new(Arc::new(model), None).unwrap();
        let mut ctx = predictor.new_context();
        // A frame with occluded (and NaN) markers still yields a finite mesh.
        let f = frames[5];
        let mut controls: Vec<Vec3> = base
            .control_vertices
            .iter()
            .map(|&v| f[v as usize])
            .collect();
        controls[0] = Vec3::NAN;
        let valid: Vec<bool> = (0..controls.len()).map(|i| i % 2 == 1).collect();
        let got = predictor
            .predict(&mut ctx, &controls, Some(&valid))
            .unwrap();
        assert!(
            got.iter().all(|p| p.is_finite()),
            "{method:?}: non-finite vertex"
        );
        assert_eq!(ctx.held_controls(), controls.len().div_ceil(2));
        let rms = eval::rms_normalized(ctx.positions(), f, scale);
        assert!(rms < 0.2, "{method:?}: occluded frame far off: {rms}");
    }
}

#[test]
fn cactus_leave_one_out_and_test_tables() {
    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    // Train on the even poses, test on the odd ones; leave-one-out over the training poses.
    let (train_idx, test_idx): (Vec<usize>, Vec<usize>) =
        (0..frames.len()).partition(|i| i % 2 == 0);
    let tf: Vec<&[Vec3]> = train_idx.iter().map(|&i| frames[i]).collect();
    let tn: Vec<String> = train_idx.iter().map(|&i| names[i].clone()).collect();
    let hf: Vec<&[Vec3]> = test_idx.iter().map(|&i| frames[i]).collect();
    let hn: Vec<String> = test_idx.iter().map(|&i| names[i].clone()).collect();
    let input = TrainInput {
        rest: &set.rest,
        frames: &tf,
        names: &tn,
    };
    let opts = EvalOptions {
        train: options(Method::Global),
        methods: Method::ALL.to_vec(),
        beta: 1.0,
        refine: None,
    };
    let test = eval::evaluate_test(
        input,
        HeldOut {
            names: &hn,
            frames: &hf,
        },
        &opts,
        &mut |_| {},
    )
    .unwrap();
    let loo = eval::evaluate_loo(input, &opts, &mut |_, _| {}).unwrap();
    for (name, table) in [("test", &test), ("loo", &loo)] {
        // Every base row (the detail rows need detailed examples).
        for row in eval::ROWS
            .iter()
            .filter(|r| !r.contains("detail") && !r.starts_with("true-base"))
        {
            let s = &table[*row];
            eprintln!(
                "cactus {name} {row:<17} {:.4e} (max {:.4e})",
                s.rms_mean, s.rms_max
            );
            assert!(s.rms_mean.is_finite());
        }
        // The floors are floors, well below not deforming at all.
        assert!(table["oracle"].rms_mean <= table["oracle-rotations"].rms_mean);
        assert!(table["oracle-rotations"].rms_mean < table["rest"].rms_mean / 2.0);
    }
    // Poses between training poses (the held-out odd ones) are predicted better than rest.
    assert!(
        test["global"].rms_mean < test["rest"].rms_mean,
        "global no better than rest on test"
    );
    assert_eq!(test["rest"].frames.len(), hf.len());
    assert_eq!(loo["rest"].frames.len(), tf.len() - 1);
}

#[test]
fn selection_scores_equal_an_independent_leave_one_out() {
    use crease_core::model::ControlPoint;
    use crease_train::regress::{self, KernelChoice, RegressInput};
    use crease_train::select::{self, SelectGrid};

    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let base = pipeline::train_base(input, &options(Method::Global), &mut |_| {}).unwrap();
    let grid = SelectGrid {
        kernels: vec![
            KernelChoice::Gaussian { scale: 1.0 },
            KernelChoice::Polynomial { c: 1.0, degree: 2 },
        ],
        kappas: vec![1e-3],
        betas: vec![1.0, 3.0],
    };
    let regress = RegressOptions::default();
    let sel = select::select(&base, &frames, &regress, &grid).unwrap();
    assert_eq!(sel.table.len(), 4);
    let min = sel
        .table
        .iter()
        .map(|c| c.rms)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(sel.best.rms, min);

    // Each candidate again, through the public run-time path: a model without the held-out
    // example, a Predictor, its predicted mesh against the example.
    let scale = set.rest.bbox_diagonal_scale();
    for cand in &sel.table {
        let o = RegressOptions {
            kernel: cand.kernel,
            kcca: crease_train::kcca::KccaOptions {
                kappa: cand.kappa,
                ..Default::default()
            },
            ..regress.clone()
        };
        let mut sum = 0.0;
        for held in 1..frames.len() {
            let keep: Vec<usize> = (0..frames.len()).filter(|&i| i != held).collect();
            let controls: Vec<Vec<Vec3>> = keep
                .iter()
                .map(|&i| base.example_controls[i].clone())
                .collect();
            let rotations: Vec<_> = keep.iter().map(|&i| base.rotations[i].clone()).collect();
            let rotation_model = regress::build_rotation_model(
                RegressInput {
                    rest: &base.rig.rest,
                    skin: &base.rig.skin,
                    bone_count: base.rig.bone_count,
                    control_vertices: &base.control_vertices,
                    controls: &controls,
                    rotations: &rotations,
                    group_rig: None,
                },
                &o,
            );
            let model = TrainedModel {
                rig: base.rig.clone(),
                controls: base
                    .control_vertices
                    .iter()
                    .map(|&vertex| ControlPoint {
                        vertex,
                        name: String::new(),
                    })
                    .collect(),
                method: "global".into(),
                rotations: rotation_model,
                edges: base.edges.clone(),
                edge_skin: base.edge_skin.clone(),
                beta: cand.beta,
                detail: None,
                skinning: Default::default(),
            };
            let predictor = Predictor::new(Arc::new(model), None).unwrap();
            let mut ctx = predictor.new_context();
            let got = predictor
                .predict(&mut ctx, &base.example_controls[held], None)
                .unwrap();
            sum += eval::rms_normalized(got, frames[held], scale);
        }
        let want = sum / (frames.len() - 1) as f64;
        assert!(
            (cand.rms - want).abs() <= 1e-6 * want,
            "{cand:?}: independent leave-one-out gives {want}"
        );
    }
}

#[test]
fn control_swap_search_never_gets_worse_and_stays_in_the_pool() {
    use crease_train::select;

    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let mut options = options(Method::Global);
    options.controls = ControlSpec::Select(3);
    let base = pipeline::train_base(input, &options, &mut |_| {}).unwrap();
    let sel = base
        .report
        .control_selection
        .clone()
        .expect("selection report");
    let start = crease_train::controls::auto_control_points(&set.rest, &frames, 3).unwrap();
    assert_eq!(sel.pool.len(), 6);
    assert_eq!(base.control_vertices, sel.chosen);
    assert_eq!(sel.chosen.len(), 3);
    eprintln!("control selection on the cactus: {sel:?}");
    // Replaying the accepted swaps on the PCA + varimax start gives the result.
    let mut replay = start.clone();
    for &(out, inn) in &sel.swaps {
        let slot = replay
            .iter()
            .position(|&v| v == out)
            .expect("swapped-out member");
        assert!(sel.pool.contains(&inn) && !replay.contains(&inn));
        replay[slot] = inn;
    }
    assert_eq!(replay, sel.chosen);
    // Each accepted swap lowered the leave-one-out error.
    assert_eq!(sel.errors.len(), sel.swaps.len() + 1);
    assert!(
        sel.errors.windows(2).all(|w| w[1] < w[0]),
        "{:?}",
        sel.errors
    );
    // The example controls follow the chosen vertices.
    for (f, c) in frames.iter().zip(&base.example_controls) {
        for (&v, p) in sel.chosen.iter().zip(c) {
            assert_eq!(f[v as usize], *p);
        }
    }
    // The reported final error is the selection's score of the chosen set.
    let grid = select::SelectGrid {
        kernels: vec![options.regress.kernel],
        kappas: vec![options.regress.kcca.kappa],
        betas: vec![options.beta],
    };
    let again = select::select(&base, &frames, &options.regress, &grid).unwrap();
    assert!((again.best.rms - sel.errors.last().unwrap()).abs() < 1e-12);
}

const REFINE: Refinement = Refinement {
    iterations: 4,
    strength: 0.1,
    from_rest: false,
};

/// Issue 20: the bone-level refinement leaves every training pose as the regression predicts it
/// (bit for bit), the confidence is 0 at the examples and grows along a path leaving them, and
/// on a frame outside the training span the refinement pulls the control vertices closer to
/// the control points than the regression alone.
#[test]
fn refinement_keeps_the_examples_and_confidence_measures_the_distance_to_them() {
    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let options = options(Method::Global);
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

/// Issue 23's grouping: with a coarse rig beside the fine one, each fine bone belongs to the
/// coarse bone sharing most of its weight, and sees that coarse bone's control points.
#[test]
fn a_group_rig_gives_each_bone_the_control_points_of_its_coarse_bone() {
    let Some(set) = cactus() else { return };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let mut o = options(Method::Local);
    o.fit.bones = 24;
    o.controls = ControlSpec::Auto(8);
    o.group_bones = Some(5);
    let base = pipeline::train_base(input, &o, &mut |_| {}).unwrap();
    let g = base.group_rig.as_ref().expect("a group rig of 5 bones");
    assert_eq!((g.bone_count, g.of_bone.len()), (5, base.rig.bone_count));
    assert_eq!(base.report.group_rig.as_ref().unwrap().bones, 5);

    // The assignment against a dense overlap matrix.
    let mut dense = vec![[0.0f64; 5]; base.rig.bone_count];
    for v in 0..set.rest.vertex_count() {
        let (fb, fw) = base.rig.skin.vertex(v);
        let (cb, cw) = g.skin.vertex(v);
        for (&b, &wb) in fb.iter().zip(fw) {
            for (&c, &wc) in cb.iter().zip(cw) {
                dense[b as usize][c as usize] += f64::from(wb) * f64::from(wc);
            }
        }
    }
    for (b, row) in dense.iter().enumerate() {
        let best = (0..5).fold(0, |m, c| if row[c] > row[m] { c } else { m });
        if row[best] > 0.0 {
            assert_eq!(g.of_bone[b] as usize, best, "fine bone {b}: {row:?}");
        }
    }

    // Control sets: those the coarse rig's own bones get (a model of the coarse rig alone).
    let regress = RegressOptions {
        method: Method::Local,
        kc: 3,
        ..RegressOptions::default()
    };
    let model = base.model(&regress, 1.0);
    model.validate().unwrap();
    let coarse_rotations = vec![vec![crease_core::glam::Quat::IDENTITY; 5]; frames.len()];
    let coarse = crease_train::regress::build_rotation_model(
        crease_train::regress::RegressInput {
            rest: &set.rest,
            skin: &g.skin,
            bone_count: 5,
            control_vertices: &base.control_vertices,
            controls: &base.example_controls,
            rotations: &coarse_rotations,
            group_rig: None,
        },
        &regress,
    );
    let set_of = |groups: &[crease_core::runtime::predict::ControlGroup], bone: u32| {
        groups
            .iter()
            .find(|grp| grp.bones.contains(&bone))
            .map(|grp| grp.controls.clone())
            .unwrap()
    };
    assert!(model.rotations.groups.len() <= 5);
    for b in 0..base.rig.bone_count as u32 {
        assert_eq!(
            set_of(&model.rotations.groups, b),
            set_of(&coarse.groups, g.of_bone[b as usize]),
            "fine bone {b}"
        );
    }
    // Every bone keeps its own regressor: the training poses' rotations come back as well as
    // with each bone's own control points.
    let (mean, worst) = training_rotation_error(&base, &model);
    let mut own = base.clone();
    own.group_rig = None;
    let (own_mean, own_worst) = training_rotation_error(&base, &own.model(&regress, 1.0));
    eprintln!(
        "training rotations: grouped mean {mean} worst {worst}, own points mean {own_mean} \
         worst {own_worst} rad"
    );
    // A bone fitted to another bone's rotations would be off by far more (the cactus's bones
    // turn by up to ~1 rad between poses).
    assert!(
        mean < 1.5 * own_mean && worst < 1.5 * own_worst,
        "training rotations: grouped mean {mean} worst {worst}, own points mean {own_mean} \
         worst {own_worst} rad"
    );
}

/// Mean and worst angle between the rotations `model` predicts from each training example's
/// control points and the rig's rotations of that example.
fn training_rotation_error(base: &pipeline::TrainedBase, model: &TrainedModel) -> (f32, f32) {
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    let mut ctx = predictor.new_context();
    let (mut worst, mut sum, mut count) = (0.0f32, 0.0f32, 0usize);
    for (e, controls) in base.example_controls.iter().enumerate() {
        predictor
            .predict_transforms(&mut ctx, controls, None)
            .unwrap();
        for (t, want) in ctx.transforms().iter().zip(&base.rotations[e]) {
            let a = t.rotation.angle_between(*want);
            worst = worst.max(a);
            sum += a;
            count += 1;
        }
    }
    (sum / count as f32, worst)
}
