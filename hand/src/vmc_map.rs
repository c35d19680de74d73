//! VMC maps (issue 39): a VMC sender's humanoid hand bones as `crease bridge vmc` publishes
//! them, and the marker maps that put a control-point layout's landmarks on them, fitted on
//! the sweep hand as the WebXR maps are (`crate::joint_map`).
//!
//! # The markers
//!
//! Per hand ([`vmc_markers`]): `{Side}Hand`, then per digit (thumb, index, middle, ring,
//! little) `{Side}{Digit}Proximal`, `...Intermediate`, `...Distal` and `...Tip` (21): the
//! joint centres of Unity's `HumanBodyBones` chain, and the bridge's fingertip. VMC sends no
//! joint radius, so there are no skin points: every mix is of joint centres. On the sweep
//! hand ([`vmc_virtual_markers`], from the WebXR centres of [`PosedHands`]):
//! - `Hand` is the wrist; a finger's `Proximal` bone starts at its MCP joint, `Intermediate`
//!   at the PIP, `Distal` at the DIP; Unity calls the thumb's metacarpal its `Proximal`, so
//!   the thumb's are the CMC, MCP and IP;
//! - `Tip` is the bridge's (`crease_bridge::vmc::skeleton`, default ratio 0.8): the distal
//!   joint plus 0.8 of the intermediate segment's length along the distal phalanx.
//!
//! # Fitting
//!
//! As `crate::joint_map` (an affine mix per landmark, least squares with a small ridge over
//! the data set's training poses), with these candidates: a landmark on a bone, the chain's
//! joints around it that VMC has (two on each side: a straight finger's joints are collinear,
//! so a mix of only the two ends cannot leave the bone's axis, which the skin landmarks do);
//! a palm landmark, the wrist, the four fingers' MCP and PIP joints and the thumb's CMC. The
//! landmarks sit on the skin and the markers inside the hand: how far a mix lands from its
//! landmark is what `hand/tests/vmc_map.rs` measures on poses the fit never saw.

use glam::Vec3;

use crate::dataset::{LandmarkAnchor, Layout};
use crate::joint_map::{Mix, PosedHands, Side, errors_over, fit_mixes};
use crate::rig::HandRig;
use crate::skeleton::Digit;
use crate::webxr::webxr_index;

/// Unity's names of a digit (`HumanBodyBones`: `LeftThumbProximal`, ...).
const DIGITS: [&str; 5] = ["Thumb", "Index", "Middle", "Ring", "Little"];
/// A digit's markers, base first.
const SEGMENTS: [&str; 4] = ["Proximal", "Intermediate", "Distal", "Tip"];
/// Markers of one hand: the hand and four per digit.
pub const VMC_MARKERS: usize = 1 + 4 * 5;
/// The bridge's default fingertip: this share of the intermediate segment past the distal
/// joint (`crease_bridge::vmc::skeleton::TipLengths::default`).
pub const TIP_RATIO: f32 = 0.8;

/// The markers of one hand (`side`: `Right` or `Left`, as Unity prefixes them), in order.
pub fn vmc_markers(side: &str) -> Vec<String> {
    std::iter::once(format!("{side}Hand"))
        .chain(
            DIGITS
                .iter()
                .flat_map(|d| SEGMENTS.iter().map(move |s| format!("{side}{d}{s}"))),
        )
        .collect()
}

/// Marker index of `digit`'s segment `s` (0 Proximal .. 3 Tip); the hand is 0.
const fn marker(digit: Digit, s: usize) -> usize {
    1 + 4 * digit.index() + s
}

/// The sweep hand's chain slot of `digit`'s VMC segment `s` (0..3: Proximal, Intermediate,
/// Distal; 3, the tip, is the chain's last slot, extended by the bridge's rule).
const fn chain_slot(digit: Digit, s: usize) -> usize {
    match digit {
        Digit::Thumb => 1 + s,
        _ => 2 + s,
    }
}

/// The VMC markers of one posed sweep hand from its WebXR joint centres (`webxr_centres`,
/// `crate::joint_map::virtual_markers`' first 25), as the bridge would publish them.
pub fn vmc_virtual_markers(webxr_centres: &[Vec3]) -> Vec<Vec3> {
    chain_markers(webxr_centres, Some(TIP_RATIO))
}

/// The 21 centre markers of one posed sweep hand in the order VMC and MediaPipe Hands share
/// (the wrist, then per digit base first: a finger's MCP, PIP, DIP and tip, the thumb's CMC,
/// MCP, IP and tip), from its WebXR joint centres. The tip: with `extend_tip`, the bridge's
/// (the distal joint plus that share of the intermediate segment along the distal phalanx);
/// without, the WebXR tip joint (MediaPipe's `*_TIP`, at the fingertip).
pub(crate) fn chain_markers(webxr_centres: &[Vec3], extend_tip: Option<f32>) -> Vec<Vec3> {
    let at = |d: Digit, slot: usize| webxr_centres[Side::Centre.marker(webxr_index(d, slot))];
    let mut out = vec![Vec3::ZERO; VMC_MARKERS];
    out[0] = webxr_centres[Side::Centre.marker(0)];
    for d in Digit::ALL {
        for s in 0..3 {
            out[marker(d, s)] = at(d, chain_slot(d, s));
        }
        let (inter, distal, tip) = (
            at(d, chain_slot(d, 1)),
            at(d, chain_slot(d, 2)),
            at(d, d.chain_len() - 1),
        );
        out[marker(d, 3)] = match extend_tip {
            Some(ratio) => {
                let along = (tip - distal).normalize_or_zero();
                distal + ratio * distal.distance(inter) * along
            }
            None => tip,
        };
    }
    out
}

/// Per pose of `hands`, [`vmc_virtual_markers`].
pub fn vmc_hands(hands: &PosedHands) -> Vec<Vec<Vec3>> {
    chain_hands(hands, Some(TIP_RATIO))
}

/// Per pose of `hands`, [`chain_markers`] with `extend_tip`.
pub(crate) fn chain_hands(hands: &PosedHands, extend_tip: Option<f32>) -> Vec<Vec<Vec3>> {
    hands
        .markers
        .iter()
        .map(|m| chain_markers(m, extend_tip))
        .collect()
}

/// The VMC markers of chain slot `slot` of `digit` (0: the hand), if VMC has one there.
fn vmc_at(digit: Digit, slot: usize) -> Option<usize> {
    if slot == 0 {
        return Some(0);
    }
    (0..4)
        .find(|&s| chain_slot(digit, s) == slot || (s == 3 && slot == digit.chain_len() - 1))
        .map(|s| marker(digit, s))
}

/// The candidate markers of a landmark (module docs), indices of [`chain_markers`].
fn candidates(anchor: LandmarkAnchor) -> Vec<usize> {
    let mut c: Vec<usize> = match anchor {
        LandmarkAnchor::Bone { digit, from } => (from.saturating_sub(1)..=from + 2)
            .filter(|&slot| slot < digit.chain_len())
            .filter_map(|slot| vmc_at(digit, slot))
            .collect(),
        LandmarkAnchor::Palm => {
            let mut c = vec![0, marker(Digit::Thumb, 0)];
            for d in Digit::FINGERS {
                c.push(marker(d, 0));
                c.push(marker(d, 1));
            }
            c
        }
    };
    c.sort_unstable();
    c.dedup();
    c
}

/// The mixes of `layout`'s landmarks (on `rig`'s rest mesh) over VMC markers, fitted on
/// `hands` (module docs).
pub fn fit_vmc_map(layout: Layout, rig: &HandRig, hands: &PosedHands) -> Vec<Mix> {
    fit_chain_map(layout, rig, &vmc_hands(hands), hands)
}

/// Distances of each VMC mix to its landmark vertex, per pose of `hands`: `[pose][landmark]`.
pub fn vmc_mix_errors(mixes: &[Mix], hands: &PosedHands) -> Vec<Vec<f32>> {
    errors_over(mixes, &vmc_hands(hands), &hands.meshes)
}

/// The mixes of `layout`'s landmarks over `markers` ([`chain_hands`] of `hands`), each over
/// its [`candidates`]: VMC's maps and MediaPipe's.
pub(crate) fn fit_chain_map(
    layout: Layout,
    rig: &HandRig,
    markers: &[Vec<Vec3>],
    hands: &PosedHands,
) -> Vec<Mix> {
    fit_mixes(layout, rig, markers, &hands.meshes, |anchor, _| {
        candidates(anchor)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markers_are_the_hand_then_four_per_digit() {
        let m = vmc_markers("Right");
        assert_eq!(m.len(), VMC_MARKERS);
        assert_eq!(m[0], "RightHand");
        assert_eq!(m[marker(Digit::Thumb, 0)], "RightThumbProximal");
        assert_eq!(m[marker(Digit::Little, 3)], "RightLittleTip");
        assert_eq!(
            vmc_markers("Left")[marker(Digit::Index, 2)],
            "LeftIndexDistal"
        );
    }

    #[test]
    fn a_straight_finger_tip_extends_its_distal_phalanx() {
        // A synthetic hand: every WebXR centre on the x axis at its index (10 cm apart).
        let centres: Vec<Vec3> = (0..75)
            .map(|i| Vec3::new(i as f32 * 0.1, 0.0, 0.0))
            .collect();
        let m = vmc_virtual_markers(&centres);
        // Index: PIP is WebXR 7, DIP 8, tip 9: the tip marker is DIP + 0.8 * 0.1 along +x.
        let tip = m[marker(Digit::Index, 3)];
        assert!(
            (tip - Vec3::new(0.8 + 0.08, 0.0, 0.0)).length() < 1e-6,
            "{tip}"
        );
        // The thumb's Proximal is its CMC (WebXR 1), a finger's its MCP (WebXR 6).
        assert_eq!(m[marker(Digit::Thumb, 0)], centres[1]);
        assert_eq!(m[marker(Digit::Index, 0)], centres[6]);
    }
}
