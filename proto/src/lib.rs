//! crease-proto: the one wire contract, `proto/crease/v1/crease.proto` (package `crease.v1`),
//! compiled from `build.rs` with protox + tonic-prost-build (no system `protoc`), plus every
//! wire shape the server speaks: the conversions between wire and core types, the JSON of the
//! HTTP side, and the per-frame error codes. Conversions that can fail name the message and
//! the field and say what was expected and what came ([`WireError`]).
//!
//! Layout:
//! - [`v1`]: the generated messages, the `Crease` client and server, and the encoded file
//!   descriptor set for gRPC reflection ([`v1::FILE_DESCRIPTOR_SET`]).
//! - [`control`]: the control frame a publisher sends: [`read_control_frame`] (into caller
//!   buffers, no allocation per frame), [`control_frame`], the validity mask
//!   ([`encode_valid_mask`], [`valid_bit`]).
//! - [`mesh`]: the mesh stream a subscriber gets: [`topology_message`], [`frame_message`], and
//!   [`read_topology`] / [`StreamTopology`] for clients.
//! - [`palette`]: the palette stream's first message (issue 18): [`palette_topology_message`]
//!   and [`read_palette_topology`] / [`StreamPalette`].
//! - [`convert`]: the small wire <-> core conversions: points, boxes, the One Euro filter,
//!   [`Level`], [`Encoding`], [`model_info`].
//! - [`room`]: what it takes to open a room, checked once: [`room::RoomSpec`] from an
//!   `OpenRoomRequest`, a cluster's `RoomEntry` or a take's header; a room's settings back on
//!   the wire; [`room::RoomOptions`] and [`room::StreamSettings`].
//! - [`cluster`]: the messages replicas exchange: a room's registry entry, a relay's interest,
//!   a forwarded control frame.
//! - [`json`]: the JSON the WebSocket and `/api/rooms` speak: control frames in, acks out,
//!   room documents, one serde mapping each.
//! - [`take`]: take files (issue 22; `take.proto`): writing a room's recorded frames, reading
//!   them back up to the last whole frame, and unpacking their frames into core types.
//! - [`take_info`]: a take's header and summary as the server builds them.
//! - [`job`]: batch jobs (issue 45): a job's frames checked and cut into chunks that carry the
//!   held state at their start, its id, and its status as `JobInfo`.
//! - [`errors`]: [`WireError`] (message, field, expected vs got), [`errors::ErrorCode`], the named codes of `FrameError` (google.rpc.Code
//!   integers), error acks, and the batch error status that names its frame in a field.

pub mod cluster;
pub mod control;
pub mod convert;
pub mod errors;
pub mod job;
pub mod json;
pub mod mesh;
pub mod palette;
pub mod room;
pub mod take;
pub mod take_info;

pub use control::{
    control_frame, encode_valid_mask, marker_frame, read_control_frame, read_marker_frame,
    valid_bit,
};
pub use convert::{Encoding, Level, box3, model_info};
pub use errors::WireError;
pub use mesh::{
    ActorPlace, StreamTopology, TopologyParts, actor_frame, actors_frame_message, frame_message,
    name_actor, read_topology, topology_message,
};
pub use palette::{PaletteParts, StreamPalette, palette_topology_message, read_palette_topology};
pub use room::{RoomOptions, RoomSpec, StreamSettings};

/// The WebSocket subprotocol of `/ws/rooms/{id}` (the server selects it when the client
/// offers it; a publish token travels beside it as `crease.token.<base64url>`).
pub const WS_PROTOCOL: &str = "crease.v1";

/// The generated `crease.v1` package.
#[allow(missing_docs, clippy::all, missing_debug_implementations)]
pub mod v1 {
    tonic::include_proto!("crease.v1");

    /// The encoded `FileDescriptorSet` of `crease.proto`, for server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("crease_descriptor");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptor_set_names_the_service() {
        use prost::Message;
        let fds = String::from_utf8_lossy(v1::FILE_DESCRIPTOR_SET);
        assert!(fds.contains("crease.v1"), "package missing");
        assert!(fds.contains("Crease"), "service missing");
        // Decodes as a protobuf message at all.
        assert!(EmptyMessage::decode(v1::FILE_DESCRIPTOR_SET).is_ok());
    }

    /// An empty message: decoding any valid protobuf into it skips every field.
    #[derive(Clone, PartialEq, prost::Message)]
    struct EmptyMessage {}
}
