//! MediaPipe Hands maps (issue 46): the 21 landmarks MediaPipe Hands finds per hand, published
//! by the viewer's camera source as raw markers, and the marker maps that put a control-point
//! layout's landmarks on them, fitted on the sweep hand as the WebXR and VMC maps are
//! (`crate::joint_map`, `crate::vmc_map`).
//!
//! # The markers
//!
//! MediaPipe Hands (Zhang et al. 2020, "MediaPipe Hands: On-device Real-time Hand Tracking")
//! reports per hand 21 landmarks in its `HandLandmark` order ([`mediapipe_markers`], its names
//! in lower case): `wrist`, then per digit base first `thumb_cmc`, `thumb_mcp`, `thumb_ip`,
//! `thumb_tip`; `index_finger_mcp`, `_pip`, `_dip`, `_tip`; the same for `middle_finger`,
//! `ring_finger` and `pinky`. Its "world" landmarks are metric and centred on the hand; they
//! carry no joint radius, so (as with VMC) there are no skin points and every mix is of joint
//! centres. On the sweep hand ([`mediapipe_virtual_markers`]) they are the WebXR joint centres
//! of [`crate::joint_map::PosedHands`] without the four finger metacarpals: the wrist, the
//! thumb's CMC (`thumb-metacarpal`), MCP and IP, a finger's MCP (`*-phalanx-proximal`), PIP and
//! DIP, and every `*-tip`. That is VMC's order and its joints, but for the tip, which here is
//! the fingertip joint itself (VMC's is extrapolated by the bridge), so the candidates of each
//! landmark are VMC's (`crate::vmc_map::fit_chain_map`).
//!
//! # Fitting
//!
//! As `crate::vmc_map`: an affine mix per landmark, least squares with a small ridge over the
//! data set's training poses, checked on sampled test poses no fit saw
//! (`hand/tests/mediapipe_map.rs`, which writes `bench/mocap/mediapipe-*.toml`).
//!
//! # Bones
//!
//! MediaPipe estimates each frame's world landmarks afresh, and its bone lengths vary from
//! frame to frame far more than a hand's can: on `crease handgen`'s rendered training poses
//! (tests/browser/camera.test.mjs) from 0.2 to 1.7 times the true length, most where fingers
//! curl towards the camera. Mixes of such a hand are targets no model can reach (the room's
//! mesh missed them by up to 26 mm). So the maps carry `[bones]` ([`mediapipe_bones`]): the
//! sweep hand's bone lengths along MediaPipe's tree ([`PARENTS`]), on which the room rebuilds
//! every frame (`crease_mocap::map`): MediaPipe's directions, the model's proportions. The
//! rebuilt hand is then the sweep hand's size, so the maps register at scale 1 rather than
//! fitting MediaPipe's estimate of the hand's size (which the palm's shape skews: a 5% larger
//! hand on those poses, fingers the model's bones cannot reach).

use glam::Vec3;

use crate::dataset::Layout;
use crate::joint_map::{Mix, PosedHands, errors_over};
use crate::rig::HandRig;
use crate::vmc_map::{chain_hands, chain_markers, fit_chain_map};

/// Landmarks of one hand.
pub const MEDIAPIPE_MARKERS: usize = 21;
/// MediaPipe's names of the digits (`HandLandmark`), lower case.
const DIGITS: [&str; 5] = [
    "thumb",
    "index_finger",
    "middle_finger",
    "ring_finger",
    "pinky",
];
/// The thumb's four landmarks, base first.
const THUMB: [&str; 4] = ["cmc", "mcp", "ip", "tip"];
/// A finger's four landmarks, base first.
const FINGER: [&str; 4] = ["mcp", "pip", "dip", "tip"];

/// Each landmark's parent in MediaPipe's hand tree (`HAND_CONNECTIONS`: the wrist to each
/// digit's base, then along the digit); the wrist, the root, is its own.
pub const PARENTS: [usize; MEDIAPIPE_MARKERS] = [
    0, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19,
];

/// The bones of MediaPipe's tree on the sweep hand, `(landmark, parent, length)` in
/// [`mediapipe_markers`]' order, parents first: each length the mean over the poses of `hands`
/// (the bones along a digit are rigid; those from the wrist vary a little as the palm cups).
pub fn mediapipe_bones(hands: &PosedHands) -> Vec<(usize, usize, f32)> {
    let posed = mediapipe_hands(hands);
    (1..MEDIAPIPE_MARKERS)
        .map(|m| {
            let parent = PARENTS[m];
            let sum: f32 = posed.iter().map(|p| p[m].distance(p[parent])).sum();
            (m, parent, sum / posed.len().max(1) as f32)
        })
        .collect()
}

/// The landmarks of one hand, in MediaPipe's order (either hand: MediaPipe names them alike).
pub fn mediapipe_markers() -> Vec<String> {
    std::iter::once("wrist".to_owned())
        .chain(DIGITS.iter().enumerate().flat_map(|(d, name)| {
            let joints = if d == 0 { THUMB } else { FINGER };
            joints.into_iter().map(move |j| format!("{name}_{j}"))
        }))
        .collect()
}

/// The MediaPipe landmarks of one posed sweep hand from its WebXR joint centres
/// (`webxr_centres`, `crate::joint_map::virtual_markers`' first 25).
pub fn mediapipe_virtual_markers(webxr_centres: &[Vec3]) -> Vec<Vec3> {
    chain_markers(webxr_centres, None)
}

/// Per pose of `hands`, [`mediapipe_virtual_markers`].
pub fn mediapipe_hands(hands: &PosedHands) -> Vec<Vec<Vec3>> {
    chain_hands(hands, None)
}

/// The mixes of `layout`'s landmarks (on `rig`'s rest mesh) over MediaPipe landmarks, fitted
/// on `hands` (module docs).
pub fn fit_mediapipe_map(layout: Layout, rig: &HandRig, hands: &PosedHands) -> Vec<Mix> {
    fit_chain_map(layout, rig, &mediapipe_hands(hands), hands)
}

/// Distances of each MediaPipe mix to its landmark vertex, per pose of `hands`:
/// `[pose][landmark]`.
pub fn mediapipe_mix_errors(mixes: &[Mix], hands: &PosedHands) -> Vec<Vec<f32>> {
    errors_over(mixes, &mediapipe_hands(hands), &hands.meshes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_are_mediapipes_hand_landmarks_in_order() {
        let m = mediapipe_markers();
        assert_eq!(m.len(), MEDIAPIPE_MARKERS);
        // MediaPipe's HandLandmark indices: WRIST 0, THUMB_CMC 1, THUMB_TIP 4,
        // INDEX_FINGER_MCP 5, MIDDLE_FINGER_PIP 10, RING_FINGER_DIP 15, PINKY_TIP 20.
        let at = [
            (0, "wrist"),
            (1, "thumb_cmc"),
            (4, "thumb_tip"),
            (5, "index_finger_mcp"),
            (10, "middle_finger_pip"),
            (15, "ring_finger_dip"),
            (20, "pinky_tip"),
        ];
        for (i, name) in at {
            assert_eq!(m[i], name);
        }
    }

    #[test]
    fn the_tips_are_the_fingertip_joints() {
        // Every WebXR centre on the x axis at its index: the index tip is WebXR joint 9, the
        // thumb's CMC joint 1, the index MCP joint 6 (its metacarpal, 5, has no landmark).
        let centres: Vec<Vec3> = (0..75).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
        let m = mediapipe_virtual_markers(&centres);
        assert_eq!(m[8], centres[9], "index_finger_tip");
        assert_eq!(m[1], centres[1], "thumb_cmc");
        assert_eq!(m[5], centres[6], "index_finger_mcp");
        assert_eq!(m[20], centres[24], "pinky_tip");
    }
}
