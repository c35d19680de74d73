//! crease-bridge: live capture sources that do not speak crease's gRPC, received on UDP and
//! published into a retargeting room (issue 19) as marker frames (`ControlFrame.markers`),
//! through the tree's one publish loop (`crease_remote::publish`). The `crease bridge`
//! command parses its arguments and calls [`vmc::run`] or [`natnet::run`].
//!
//! Layout:
//! - [`vmc`]: the VMC protocol (OSC over UDP: VSeeFace, VirtualMotionCapture, Warudo, ...):
//!   OSC decoding, Unity's humanoid skeleton, frames and the receive loop.
//! - [`natnet`]: OptiTrack's NatNet (Motive's stream of labelled markers and rigid bodies):
//!   the wire decoder, its encoder for fixtures, the room's markers resolved to their NatNet
//!   sources, the session with a NatNet server.
//!
//! A malformed datagram is counted and dropped, never fatal. Marker names are the room's
//! (`RoomInfo.retarget.markers`); which marker drives which control point is the room's marker
//! map (`crease_mocap::map::MarkerMap`), applied by the server, not here.

pub mod natnet;
pub mod vmc;
