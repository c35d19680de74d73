//! The VMC maps (`crease_hand::vmc_map`, issue 39): fitted on the sweep hand's training poses,
//! checked on its sampled test poses (which no fit saw), and the committed maps of
//! `bench/mocap/vmc-*.toml` are what the fit writes (set `CREASE_WRITE_MAPS=1` to rewrite
//! them): per layout a right-hand map (Unity's `Right*` bones) and a left-hand one (`Left*`
//! bones onto the model mirrored across x, its landmarks' names mirrored).

use crate::fitted_maps::{CentreMaps, SEED, TEST, TRAIN, check_fitted_maps};
use crease_hand::dataset::Layout;
use crease_hand::vmc_map::{fit_vmc_map, vmc_markers, vmc_mix_errors};

#[test]
fn fitted_vmc_maps_put_the_landmarks_on_the_bones_of_unseen_poses() {
    check_fitted_maps(&CentreMaps {
        name: "vmc",
        fit: fit_vmc_map,
        errors: vmc_mix_errors,
        markers: vmc_markers,
        header,
        // VMC's bones are the performer's skeleton's: consistent already.
        bones: |_| Vec::new(),
    });
}

/// The map's header (the residuals are in BENCHMARKS.md, not in the VMC maps).
fn header(layout: Layout, side: &str, _residuals: &str) -> String {
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
