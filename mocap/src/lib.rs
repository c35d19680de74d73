//! crease-mocap: marker recordings driving a model: what a motion-capture room needs between a capture system
//! and a room's control frames (HZY11 §7, "Performance-driven animation").
//!
//! ```text
//! recording (TSV | C3D) -> marker map -> registration (rigid + scale) -> control frame
//!   tsv, c3d: Recording      map: MarkerMap    register: Registration     (valid bits kept)
//!                                              (the room: crease_core::runtime::filter)
//! ```
//!
//! Layout:
//! - [`recording`]: a [`Recording`] (marker names, a frame rate, and per frame a position and a
//!   validity flag per marker) and the crate's [`MocapError`]; `Recording::read` picks the
//!   reader by the file's extension.
//! - [`tsv`], [`c3d`]: the readers: Qualisys TSV exports, and C3D through the `c3dio` crate. Positions stay in the file's units (both samples are millimetres); gaps
//!   (`nan` in TSV, a negative residual or an all-zero point in C3D) are invalid, never NaN
//!   positions downstream.
//! - [`map`]: [`map::MarkerMap`], which recording markers (or weighted mixes of markers, for
//!   points a marker does not sit on) drive which of the model's control points, by name, and
//!   which markers register the hand.
//! - [`register`]: [`register::Registration`], per frame, the rigid transform that puts the
//!   back-of-hand markers onto the model's rest positions of those control points, with one
//!   uniform scale fitted on the first calibration frames; every marker is expressed in that
//!   hand frame.
//! - `retarget`: [`Retarget`], the three together, one recording frame in, one control frame
//!   out.
//!
//! The One Euro filter a room applies to the control points is the runtime's
//! (`crease_core::runtime::filter`): it runs in the server, not on the publisher.

pub mod c3d;
pub mod map;
pub mod recording;
pub mod register;
mod retarget;
pub mod tsv;

use std::path::Path;

pub use recording::{MarkerFrame, MocapError, Recording};
pub use retarget::{Retarget, RetargetStats};

// The one place that knows every reader, so `recording` stays below them.
impl Recording {
    /// Reads a `.tsv` (Qualisys) or `.c3d` file, chosen by extension.
    pub fn read(path: impl AsRef<Path>) -> Result<Recording, MocapError> {
        let path = path.as_ref();
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("tsv") => tsv::read(path),
            Some("c3d") => c3d::read(path),
            other => Err(MocapError::format(
                path,
                format!(
                    "unknown recording format {:?}: expected a .tsv (Qualisys) or .c3d file",
                    other.unwrap_or("")
                ),
            )),
        }
    }
}
