//! The MediaPipe Hands maps (`crease_hand::mediapipe_map`, issue 46): fitted on the sweep
//! hand's training poses, checked on its sampled test poses (which no fit saw), and the
//! committed maps of `bench/mocap/mediapipe-*.toml` are what the fit writes (set
//! `CREASE_WRITE_MAPS=1` to rewrite them): per layout a right-hand map and a left-hand one (the
//! same landmarks, which MediaPipe names alike for both hands, onto the model mirrored across
//! x, its landmarks' names mirrored).

use std::path::Path;

use crease_core::model::mirror_name;
use crease_hand::dataset::{Layout, dataset_poses};
use crease_hand::joint_map::{Mix, PosedHands, map_toml};
use crease_hand::mediapipe_map::{fit_mediapipe_map, mediapipe_markers, mediapipe_mix_errors};
use crease_hand::rig::HandRig;
use crease_hand::skeleton::HandPose;
use crease_hand::surface::Resolution;

/// The demo's recipe (crease-demo's hand_model): 12 training poses, seed 1.
const TRAIN: usize = 12;
const TEST: usize = 40;
const SEED: u64 = 1;

fn poses(list: &[crease_hand::dataset::DatasetPose]) -> Vec<HandPose> {
    list.iter().map(|p| p.pose).collect()
}

#[test]
fn fitted_mediapipe_maps_put_the_landmarks_on_the_joints_of_unseen_poses() {
    let rig = HandRig::build(Resolution::Base).unwrap();
    let (train, test) = dataset_poses(TRAIN, TEST, SEED);
    let fit_on = PosedHands::new(&rig, &poses(&train));
    let check_on = PosedHands::new(&rig, &poses(&test));
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for layout in [Layout::Back, Layout::Glove13] {
        let mixes = fit_mediapipe_map(layout, &rig, &fit_on);
        for m in &mixes {
            let sum: f32 = m.terms.iter().map(|t| t.1).sum();
            assert!((sum - 1.0).abs() < 1e-4, "{}: weights sum to {sum}", m.name);
        }
        let errors = mediapipe_mix_errors(&mixes, &check_on);
        let all: Vec<f32> = errors.iter().flatten().copied().collect();
        let rms = (all.iter().map(|e| e * e).sum::<f32>() / all.len() as f32).sqrt();
        let worst = all.iter().copied().fold(0.0f32, f32::max);
        // Per landmark, mean and max over the test poses, in mm (the maps' headers and
        // BENCHMARKS.md carry them).
        let per: Vec<String> = mixes
            .iter()
            .enumerate()
            .map(|(l, m)| {
                let e: Vec<f32> = errors.iter().map(|p| p[l]).collect();
                let mean = e.iter().sum::<f32>() / e.len() as f32;
                let max = e.iter().copied().fold(0.0f32, f32::max);
                format!("{} {:.1}/{:.1}", m.name, 1000.0 * mean, 1000.0 * max)
            })
            .collect();
        let mean = all.iter().sum::<f32>() / all.len() as f32;
        let residuals = format!(
            "Residuals on the {TEST} test poses, landmark to its mix: mean {:.1} mm, max {:.1} mm;
per landmark mean/max (mm): {}.",
            1000.0 * mean,
            1000.0 * worst,
            per.join(", ")
        );
        eprintln!(
            "mediapipe {}: {} landmarks over {TEST} test poses: RMS {:.2} mm, mean {:.2} mm, max {:.2} mm\n  {residuals}",
            layout.name(),
            mixes.len(),
            1000.0 * rms,
            1000.0 * mean,
            1000.0 * worst,
        );
        assert!(
            worst < 0.020 && rms < 0.008,
            "{}: {rms} RMS, max {worst}",
            layout.name()
        );

        // The committed maps are the fit's: the right hand's, and the left hand's (the same
        // mixes of the same landmarks under the mirrored model's landmark names).
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
                &mediapipe_markers(),
                &points,
                40,
                &header(layout, side, &residuals),
            );
            let path = root.join(format!(
                "bench/mocap/mediapipe-{}{}.toml",
                layout.name(),
                if side == "Left" { "-left" } else { "" }
            ));
            if std::env::var_os("CREASE_WRITE_MAPS").is_some() {
                std::fs::write(&path, &text).unwrap();
            }
            let committed = std::fs::read_to_string(&path).unwrap_or_default();
            assert!(
                committed == text,
                "{} is not what the fit writes (CREASE_WRITE_MAPS=1 cargo test -p crease-hand --features crease-core/test-meshes --test all mediapipe_map:: rewrites it); the fit:\n{text}",
                path.display()
            );
        }
    }
}

fn header(layout: Layout, side: &str, residuals: &str) -> String {
    let (whose, model) = if side == "Right" {
        ("right", "a hand trained on it (the demo hand for `back`)")
    } else {
        (
            "left",
            "such a hand mirrored across x = 0 (`crease model mirror --plane x`; its landmarks' names mirrored)",
        )
    };
    format!(
        "MediaPipe Hands (the viewer's camera source: its 21 world landmarks, wrist, thumb_cmc ...
pinky_tip, in metres) onto `crease handgen`'s `{name}` layout: the {whose} hand's landmarks onto
{model}.
Written by hand/tests/mediapipe_map.rs (crease_hand::mediapipe_map, which explains it): each
landmark is an affine mix of the joint centres around it, fitted on the sweep hand's {TRAIN}
training poses (seed {SEED}) and checked on {TEST} sampled test poses. MediaPipe gives joint
centres only, so the landmarks on the skin are reached through the joints around them. The
three back-of-hand points register the hand every frame; the tracked hand's size (MediaPipe's
estimate) is fitted over the first 40 frames.
{residuals}",
        name = layout.name(),
    )
}
