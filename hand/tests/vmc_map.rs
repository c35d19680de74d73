//! The VMC maps (`crease_hand::vmc_map`, issue 39): fitted on the sweep hand's training poses,
//! checked on its sampled test poses (which no fit saw), and the committed maps of
//! `bench/mocap/vmc-*.toml` are what the fit writes (set `CREASE_WRITE_MAPS=1` to rewrite
//! them): per layout a right-hand map (Unity's `Right*` bones) and a left-hand one (`Left*`
//! bones onto the model mirrored across x, its landmarks' names mirrored).

use std::path::Path;

use crease_core::model::mirror_name;
use crease_hand::dataset::{Layout, dataset_poses};
use crease_hand::joint_map::{Mix, PosedHands, map_toml};
use crease_hand::rig::HandRig;
use crease_hand::skeleton::HandPose;
use crease_hand::surface::Resolution;
use crease_hand::vmc_map::{fit_vmc_map, vmc_markers, vmc_mix_errors};

/// The demo's recipe (crease-demo's hand_model): 12 training poses, seed 1.
const TRAIN: usize = 12;
const TEST: usize = 40;
const SEED: u64 = 1;

fn poses(list: &[crease_hand::dataset::DatasetPose]) -> Vec<HandPose> {
    list.iter().map(|p| p.pose).collect()
}

#[test]
fn fitted_vmc_maps_put_the_landmarks_on_the_bones_of_unseen_poses() {
    let rig = HandRig::build(Resolution::Base).unwrap();
    let (train, test) = dataset_poses(TRAIN, TEST, SEED);
    let fit_on = PosedHands::new(&rig, &poses(&train));
    let check_on = PosedHands::new(&rig, &poses(&test));
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for layout in [Layout::Back, Layout::Glove13] {
        let mixes = fit_vmc_map(layout, &rig, &fit_on);
        for m in &mixes {
            let sum: f32 = m.terms.iter().map(|t| t.1).sum();
            assert!((sum - 1.0).abs() < 1e-4, "{}: weights sum to {sum}", m.name);
        }
        let errors = vmc_mix_errors(&mixes, &check_on);
        let all: Vec<f32> = errors.iter().flatten().copied().collect();
        let rms = (all.iter().map(|e| e * e).sum::<f32>() / all.len() as f32).sqrt();
        let worst = all.iter().copied().fold(0.0f32, f32::max);
        let per: Vec<String> = mixes
            .iter()
            .enumerate()
            .map(|(l, m)| {
                let e: Vec<f32> = errors.iter().map(|p| p[l]).collect();
                let r = (e.iter().map(|x| x * x).sum::<f32>() / e.len() as f32).sqrt();
                format!("{} {:.1}", m.name, 1000.0 * r)
            })
            .collect();
        eprintln!(
            "vmc {}: {} landmarks over {TEST} test poses: RMS {:.2} mm, max {:.2} mm\n  RMS per landmark (mm): {}",
            layout.name(),
            mixes.len(),
            1000.0 * rms,
            1000.0 * worst,
            per.join(", ")
        );
        assert!(
            worst < 0.020 && rms < 0.008,
            "{}: {rms} RMS, max {worst}",
            layout.name()
        );

        // The committed maps are the fit's: the right hand's, and the left hand's (the same
        // mixes of the Left* bones under the mirrored model's landmark names).
        let registration = ["hand_top", "hand_left", "hand_right"];
        for side in ["Right", "Left"] {
            let (mixes, points): (Vec<Mix>, Vec<String>) = if side == "Right" {
                (
                    mixes.clone(),
                    registration.iter().map(|p| (*p).to_owned()).collect(),
                )
            } else {
                (
                    mixes
                        .iter()
                        .map(|m| Mix {
                            name: mirror_name(&m.name),
                            ..m.clone()
                        })
                        .collect(),
                    registration.iter().map(|p| mirror_name(p)).collect(),
                )
            };
            let points: Vec<&str> = points.iter().map(String::as_str).collect();
            let text = map_toml(
                &mixes,
                &vmc_markers(side),
                &points,
                40,
                &header(layout, side),
            );
            let path = root.join(format!(
                "bench/mocap/vmc-{}{}.toml",
                layout.name(),
                if side == "Left" { "-left" } else { "" }
            ));
            if std::env::var_os("CREASE_WRITE_MAPS").is_some() {
                std::fs::write(&path, &text).unwrap();
            }
            let committed = std::fs::read_to_string(&path).unwrap_or_default();
            assert!(
                committed == text,
                "{} is not what the fit writes (CREASE_WRITE_MAPS=1 cargo test -p crease-hand --features crease-core/test-meshes --test all vmc_map:: rewrites it); the fit:\n{text}",
                path.display()
            );
        }
    }
}

fn header(layout: Layout, side: &str) -> String {
    let (whose, model) = if side == "Right" {
        ("right", "a hand trained on it (the demo hand for `back`)")
    } else {
        (
            "left",
            "such a hand mirrored across x = 0 (`crease model mirror --plane x`; its landmarks' names mirrored)",
        )
    };
    format!(
        "VMC (`crease bridge vmc`: VSeeFace, VirtualMotionCapture, Warudo, ...) onto `crease handgen`'s
`{name}` layout: the {whose} hand's Unity humanoid bones ({side}Hand, {side}<Digit>Proximal, ...
Intermediate, ...Distal and the bridge's ...Tip) onto {model}.
Written by hand/tests/vmc_map.rs (crease_hand::vmc_map, which explains it): each landmark is
an affine mix of the joint centres around it, fitted on the sweep hand's {TRAIN} training poses
(seed {SEED}) and checked on {TEST} sampled test poses. VMC sends joint centres only, so the
landmarks on the skin are reached through the joints around them. The three back-of-hand
points register the hand every frame; the sender's hand size is fitted over the first 40
frames.",
        name = layout.name(),
    )
}
