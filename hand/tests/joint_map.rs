//! The WebXR joint maps (`crease_hand::joint_map`): fitted on the sweep hand's training poses,
//! checked on its sampled test poses (which no fit saw), and the committed maps of
//! `bench/mocap/` are what the fit writes (set `CREASE_WRITE_MAPS=1` to rewrite them). The
//! dorsal layouts only: on the `palm` layout the palmar points of the finger bases sit in the
//! flexion folds, where no joint's palmar point follows them (measured 16-19 mm RMS, 32 mm at
//! worst), so it gets no map.

use std::path::Path;

use crate::fitted_maps::assert_committed;
use crease_core::model::mirror_name;
use crease_hand::dataset::{Layout, dataset_poses};
use crease_hand::joint_map::{
    PosedHands, Side, capture_markers, fit_joint_map, joint_map_toml, mix_errors,
};
use crease_hand::rig::HandRig;
use crease_hand::skeleton::HandPose;
use crease_hand::surface::Resolution;
use crease_hand::webxr::JOINT_NAMES;

/// The demo's recipe (crease-demo's hand_model): 12 training poses, seed 1.
const TRAIN: usize = 12;
const TEST: usize = 40;
const SEED: u64 = 1;

fn poses(list: &[crease_hand::dataset::DatasetPose]) -> Vec<HandPose> {
    list.iter().map(|p| p.pose).collect()
}

#[test]
fn capture_markers_are_centres_then_dorsal_then_palmar_points() {
    let m = capture_markers();
    assert_eq!(m.len(), 75);
    for (j, name) in JOINT_NAMES.iter().enumerate() {
        assert_eq!(m[Side::Centre.marker(j)], *name);
        assert_eq!(m[Side::Dorsal.marker(j)], format!("{name}/dorsal"));
        assert_eq!(m[Side::Palmar.marker(j)], format!("{name}/palmar"));
    }
}

#[test]
fn fitted_maps_put_the_landmarks_on_the_joints_of_unseen_poses() {
    let rig = HandRig::build(Resolution::Base).unwrap();
    let (train, test) = dataset_poses(TRAIN, TEST, SEED);
    let fit_on = PosedHands::new(&rig, &poses(&train));
    let check_on = PosedHands::new(&rig, &poses(&test));
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for (layout, registration) in [
        (Layout::Back, ["hand_top", "hand_left", "hand_right"]),
        (Layout::Glove13, ["hand_top", "hand_left", "hand_right"]),
    ] {
        let mixes = fit_joint_map(layout, &rig, &fit_on);
        for m in &mixes {
            let sum: f32 = m.terms.iter().map(|t| t.1).sum();
            assert!((sum - 1.0).abs() < 1e-4, "{}: weights sum to {sum}", m.name);
        }
        // On poses the fit never saw: every landmark within 10 mm of its mix, RMS under 4 mm (the
        // base mesh's vertices are 2-3 mm apart, and each virtual marker is one of them).
        let errors = mix_errors(&mixes, &check_on);
        let all: Vec<f32> = errors.iter().flatten().copied().collect();
        let rms = (all.iter().map(|e| e * e).sum::<f32>() / all.len() as f32).sqrt();
        let (worst_pose, worst) = errors
            .iter()
            .enumerate()
            .flat_map(|(p, e)| e.iter().enumerate().map(move |(l, d)| (p, l, *d)))
            .max_by(|a, b| a.2.total_cmp(&b.2))
            .map(|(p, l, d)| (p, (mixes[l].name.clone(), d)))
            .unwrap();
        eprintln!(
            "{}: {} landmarks over {} test poses: RMS {:.2} mm, max {:.2} mm ({} in {})",
            layout.name(),
            mixes.len(),
            TEST,
            1000.0 * rms,
            1000.0 * worst.1,
            worst.0,
            test[worst_pose].name
        );
        let per: Vec<String> = mixes
            .iter()
            .enumerate()
            .map(|(l, m)| {
                let e: Vec<f32> = errors.iter().map(|p| p[l]).collect();
                let r = (e.iter().map(|x| x * x).sum::<f32>() / e.len() as f32).sqrt();
                format!("{} {:.1}", m.name, 1000.0 * r)
            })
            .collect();
        eprintln!("  RMS per landmark (mm): {}", per.join(", "));
        assert!(
            worst.1 < 0.010 && rms < 0.004,
            "{}: {rms} RMS, {worst:?}",
            layout.name()
        );

        // The committed map is the fit's.
        let text = joint_map_toml(&mixes, &registration, 40, &map_header(layout));
        let path = root.join(format!("bench/mocap/webxr-{}.toml", layout.name()));
        assert_committed(&path, &text, "joint_map::");

        // The left hand on the model mirrored across x (issue 38: room `both-hands`): WebXR's
        // joints have no side, and a tracked left hand is the mirror image of a right one, so
        // each landmark takes the same mix; only the landmarks' names follow the mirrored
        // model's (`hand_left` on the right hand is `hand_right` on its mirror).
        if layout == Layout::Back {
            let left: Vec<_> = mixes
                .iter()
                .map(|m| crease_hand::joint_map::Mix {
                    name: mirror_name(&m.name),
                    ..m.clone()
                })
                .collect();
            let points: Vec<String> = registration.iter().map(|p| mirror_name(p)).collect();
            let points: Vec<&str> = points.iter().map(String::as_str).collect();
            let text = joint_map_toml(&left, &points, 40, &left_map_header());
            let path = root.join("bench/mocap/webxr-back-left.toml");
            assert_committed(&path, &text, "joint_map::");
        }
    }
}

fn left_map_header() -> String {
    "WebXR hand tracking of a LEFT hand onto the demo hand mirrored across x = 0 (`crease model
mirror --plane x`; the left actor of the demo's room `both-hands`, issue 38). Written by
hand/tests/joint_map.rs beside webxr-back.toml: the same mixes (WebXR's joints have no side,
and a left hand is the mirror image of a right one), each landmark under the mirrored model's
name (mirroring swaps `left` and `right` in names: `hand_left` is `hand_right` here). The
viewer sends a left hand's joints as tracked, not mirrored, to an actor whose side is left."
        .to_owned()
}

fn map_header(layout: Layout) -> String {
    format!(
        "WebXR hand tracking (the viewer's \"track my hands\") onto a hand trained on `crease handgen`'s
`{name}` layout{demo}. Written by hand/tests/joint_map.rs (crease_hand::joint_map, which explains
it): the viewer publishes per WebXR joint its centre, `<joint>/dorsal` and `<joint>/palmar` (the
centre plus or minus the joint's radius along its +Y axis, out of the back of the hand), and each
landmark is an affine mix of the same-side points of a few joints, fitted on the sweep hand's
{TRAIN} training poses (seed {SEED}); on its {TEST} sampled test poses the mixes land within 10 mm
of the landmarks (RMS under 4 mm). The three back-of-hand points register the hand every frame, which takes the
wrist's motion through the room out; the tracked hand's size is fitted over the first 40 frames
(half a second at a headset's 72-90 Hz).",
        name = layout.name(),
        demo = if layout == Layout::Back {
            ": the demo hand (room `hands`), and any `train-back.toml` model"
        } else {
            ""
        },
    )
}
