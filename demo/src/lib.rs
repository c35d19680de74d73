//! crease-demo: the embedded default of `crease-server` (DESIGN.md, "The product in one
//! paragraph"), and the launch of the server binary. With no model folder the server trains a
//! hand from the procedural sweep hand (LYK06) at two resolutions, so it has a detail layer
//! (HZY11), opens room `demo` and animates it through the named poses; a newcomer sees a moving
//! hand in the browser at once. Beside it, room `hands` takes WebXR hand tracking (the
//! viewer's "track my hands") and retargets it onto the same model.
//!
//! Layout:
//! - [`hand_model`]: the demo model, from the cache folder or trained and cached there.
//! - [`animation`]: the control points along a loop through the named poses, and the task that
//!   publishes them into the demo room through the server's publish path.
//! - [`launch`]: the binary's whole job as a library call: one [`launch::Config`] (models,
//!   demo, the server's own configuration) -> loaded models, the demo room, the listeners, and
//!   the lines a user needs (viewer URL, publish token, a `crease watch` command that runs).
//!
//! This crate, not the server library, depends on `crease-train` and `crease-hand`
//! (ARCHITECTURE.md, "Rules").

pub mod animation;
pub mod hand_model;
pub mod launch;

pub use animation::{ActorAnimation, DemoAnimation, drive};
pub use hand_model::{DemoError, default_cache_dir, demo_model};

/// The demo model's name (`GetModel`, `OpenRoom`).
pub const DEMO_MODEL: &str = "demo-hand";
/// The demo room's id.
pub const DEMO_ROOM: &str = "demo";
/// The demo's WebXR room: a retargeting room on the demo model that the viewer's "track my
/// hands" drives (issue 19), through [`WEBXR_MAP`] from the markers of
/// `crease_hand::webxr::capture_markers`.
pub const DEMO_HANDS_ROOM: &str = "hands";
/// The demo's room of two actors (issue 38): both hands of one performer, the demo hand as
/// trained (`right`) and mirrored across x (`left`), each through its own loop of the named
/// poses ([`PERFORMER_LEFT_POSES`] for the left), in one stream.
pub const DEMO_PERFORMER_ROOM: &str = "performer";
/// The left hand's loop in [`DEMO_PERFORMER_ROOM`]: the named poses in reverse, so the two
/// hands show different poses at once.
pub const PERFORMER_LEFT_POSES: [crease_hand::skeleton::NamedPose; 10] = {
    let all = crease_hand::skeleton::NamedPose::ALL;
    let mut out = all;
    let mut i = 0;
    while i < all.len() {
        out[i] = all[all.len() - 1 - i];
        i += 1;
    }
    out
};
/// The joint map of [`DEMO_HANDS_ROOM`]: WebXR joints onto the demo hand's `back` landmarks
/// (`bench/mocap/webxr-back.toml`, which says how it was built).
pub const WEBXR_MAP: &str = include_str!("../../bench/mocap/webxr-back.toml");
/// The demo's WebXR room of two actors (issue 38): the viewer's "track my hands" publishes both
/// tracked hands at once, the right onto the demo hand through [`WEBXR_MAP`], the left onto it
/// mirrored across x through [`WEBXR_LEFT_MAP`], one performer, one frame per XR frame.
pub const DEMO_BOTH_HANDS_ROOM: &str = "both-hands";
/// The joint map of [`DEMO_BOTH_HANDS_ROOM`]'s left actor: [`WEBXR_MAP`]'s mixes under the
/// mirrored model's landmark names (`bench/mocap/webxr-back-left.toml`).
pub const WEBXR_LEFT_MAP: &str = include_str!("../../bench/mocap/webxr-back-left.toml");
/// The demo's VMC room (issue 39): `crease bridge vmc --room vmc` drives it from any VMC
/// sender (VSeeFace, VirtualMotionCapture, Warudo, ...) with no map of the user's: both hands
/// of the sender's skeleton, the right onto the demo hand through [`VMC_MAP`], the left onto
/// it mirrored across x through [`VMC_LEFT_MAP`], one performer.
pub const DEMO_VMC_ROOM: &str = "vmc";
/// Unity's right-hand bones onto the demo hand's `back` landmarks
/// (`bench/mocap/vmc-back.toml`, written by hand/tests/vmc_map.rs).
pub const VMC_MAP: &str = include_str!("../../bench/mocap/vmc-back.toml");
/// Unity's left-hand bones onto the demo hand mirrored (`bench/mocap/vmc-back-left.toml`).
pub const VMC_LEFT_MAP: &str = include_str!("../../bench/mocap/vmc-back-left.toml");
/// The demo's camera room (issue 46): the viewer's "track my hands (camera)" publishes
/// MediaPipe Hands' landmarks of both hands, the right onto the demo hand through
/// [`MEDIAPIPE_MAP`], the left onto it mirrored across x through [`MEDIAPIPE_LEFT_MAP`].
pub const DEMO_CAMERA_ROOM: &str = "camera";
/// MediaPipe's right-hand landmarks onto the demo hand's `back` landmarks
/// (`bench/mocap/mediapipe-back.toml`, written by hand/tests/mediapipe_map.rs).
pub const MEDIAPIPE_MAP: &str = include_str!("../../bench/mocap/mediapipe-back.toml");
/// MediaPipe's left-hand landmarks onto the demo hand mirrored
/// (`bench/mocap/mediapipe-back-left.toml`).
pub const MEDIAPIPE_LEFT_MAP: &str = include_str!("../../bench/mocap/mediapipe-back-left.toml");
/// The demo room's beta: keyframe mode (HZY11 Fig. 11: about 3 for keyframing), so a dragged
/// control point is followed closely.
pub const DEMO_BETA: f32 = 3.0;
/// The refinement of [`DEMO_HANDS_ROOM`] (issue 20): 4 rounds at the strength of
/// BENCHMARKS.md's hand runs (the regression prior at 1/100 of each bone's data term at
/// confidence 1). The keyframed [`DEMO_ROOM`] replays poses near its examples and has none.
pub const DEMO_HANDS_REFINE: crease_core::predictor::Refinement =
    crease_core::predictor::Refinement {
        iterations: 4,
        strength: 0.01,
        from_rest: false,
    };
