//! The MediaPipe Hands maps (`crease_hand::mediapipe_map`, issue 46): fitted on the sweep
//! hand's training poses, checked on its sampled test poses (which no fit saw), and the
//! committed maps of `bench/mocap/mediapipe-*.toml` are what the fit writes (set
//! `CREASE_WRITE_MAPS=1` to rewrite them): per layout a right-hand map and a left-hand one (the
//! same landmarks, which MediaPipe names alike for both hands, onto the model mirrored across
//! x, its landmarks' names mirrored).

use crate::fitted_maps::{CentreMaps, SEED, TEST, TRAIN, check_fitted_maps};
use crease_hand::dataset::Layout;
use crease_hand::mediapipe_map::{
    fit_mediapipe_map, mediapipe_bones, mediapipe_markers, mediapipe_mix_errors,
};

#[test]
fn fitted_mediapipe_maps_put_the_landmarks_on_the_joints_of_unseen_poses() {
    check_fitted_maps(&CentreMaps {
        name: "mediapipe",
        fit: fit_mediapipe_map,
        errors: mediapipe_mix_errors,
        // MediaPipe names both hands' landmarks alike.
        markers: |_| mediapipe_markers(),
        header,
        bones: mediapipe_bones,
    });
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
three back-of-hand points register the hand every frame. MediaPipe's bone lengths vary from frame
to frame, so each frame is rebuilt on [bones] (the sweep hand's, mean over the training poses):
MediaPipe's directions at the model's lengths, so the hand is the model's size (scale 1).
{residuals}",
        name = layout.name(),
    )
}
