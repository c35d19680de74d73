//! The fit-and-check of the marker maps over joint centres (VMC's, `vmc_map.rs`, and
//! MediaPipe's, `mediapipe_map.rs`): one body, each test naming its markers, fit and header.

use std::path::Path;

use crease_core::model::mirror_name;
use crease_hand::dataset::{Layout, dataset_poses};
use crease_hand::joint_map::{Mix, PosedHands, map_toml};
use crease_hand::rig::HandRig;
use crease_hand::skeleton::HandPose;
use crease_hand::surface::Resolution;

/// The demo's recipe (crease-demo's hand_model): 12 training poses, seed 1.
pub(crate) const TRAIN: usize = 12;
pub(crate) const TEST: usize = 40;
pub(crate) const SEED: u64 = 1;

/// One family of maps.
pub(crate) struct CentreMaps {
    /// The file prefix (`bench/mocap/NAME-*.toml`) and the test module (`NAME_map`).
    pub(crate) name: &'static str,
    /// The fit of a layout's landmarks.
    pub(crate) fit: fn(Layout, &HandRig, &PosedHands) -> Vec<Mix>,
    /// Each mix's distance to its landmark, per pose.
    pub(crate) errors: fn(&[Mix], &PosedHands) -> Vec<Vec<f32>>,
    /// The markers of one hand (`Right` or `Left`).
    pub(crate) markers: fn(&str) -> Vec<String>,
    /// The map's header for a layout, a side and the residuals' text.
    pub(crate) header: fn(Layout, &str, &str) -> String,
    /// The map's `[bones]` from the training poses (none for a measured skeleton).
    pub(crate) bones: fn(&PosedHands) -> Vec<(usize, usize, f32)>,
}

fn poses(list: &[crease_hand::dataset::DatasetPose]) -> Vec<HandPose> {
    list.iter().map(|p| p.pose).collect()
}

/// Fits `maps` on the training poses of the demo's recipe, checks them on the test poses
/// (weights summing to 1, under 20 mm at worst and 8 mm RMS), prints the residuals per
/// landmark, and checks that the committed `bench/mocap/NAME-LAYOUT[-left].toml` are what the
/// fit writes (`CREASE_WRITE_MAPS=1` rewrites them).
pub(crate) fn check_fitted_maps(maps: &CentreMaps) {
    let rig = HandRig::build(Resolution::Base).unwrap();
    let (train, test) = dataset_poses(TRAIN, TEST, SEED);
    let fit_on = PosedHands::new(&rig, &poses(&train));
    let check_on = PosedHands::new(&rig, &poses(&test));
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for layout in [Layout::Back, Layout::Glove13] {
        let mixes = (maps.fit)(layout, &rig, &fit_on);
        for m in &mixes {
            let sum: f32 = m.terms.iter().map(|t| t.1).sum();
            assert!((sum - 1.0).abs() < 1e-4, "{}: weights sum to {sum}", m.name);
        }
        let errors = (maps.errors)(&mixes, &check_on);
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
            "{} {}: {} landmarks over {TEST} test poses: RMS {:.2} mm, mean {:.2} mm, max {:.2} mm\n  {residuals}",
            maps.name,
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
        // mixes of the left hand's markers under the mirrored model's landmark names).
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
                &(maps.markers)(side),
                &points,
                40,
                &(maps.bones)(&fit_on),
                &(maps.header)(layout, side, &residuals),
            );
            let path = root.join(format!(
                "bench/mocap/{}-{}{}.toml",
                maps.name,
                layout.name(),
                if side == "Left" { "-left" } else { "" }
            ));
            assert_committed(&path, &text, &format!("{}_map::", maps.name));
        }
    }
}

/// Checks that the committed map at `path` is `text` (what the fit writes); with
/// `CREASE_WRITE_MAPS` set, writes it first. `tests` names the test filter that rewrites it.
pub(crate) fn assert_committed(path: &Path, text: &str, tests: &str) {
    if std::env::var_os("CREASE_WRITE_MAPS").is_some() {
        std::fs::write(path, text).unwrap();
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed == text,
        "{} is not what the fit writes (CREASE_WRITE_MAPS=1 cargo test -p crease-hand --features crease-core/test-meshes --test all {tests} rewrites it); the fit:\n{text}",
        path.display()
    );
}
