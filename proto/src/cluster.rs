//! The messages replicas of a cluster exchange (`cluster.proto`): a room's registry entry
//! ([`room_entry`]), a relay's interest in a channel ([`interest`]) and a control frame
//! forwarded to a room's owner ([`forwarded_control`], [`read_forwarded_control`]).

use crate::convert::{Encoding, Level};
use crate::errors::WireError;
use crate::room::{RoomSettings, StreamSettings};
use crate::v1;

/// What the registry records of a room besides its settings.
#[derive(Clone, Copy, Debug)]
pub struct EntryParts<'a> {
    /// The room's settings (the retarget resolved: another replica has no maps folder).
    pub settings: RoomSettings<'a>,
    /// The model's SHA-256, hex.
    pub model_sha256: &'a str,
    /// The replica that predicts the room.
    pub owner: &'a str,
    /// The publish token's SHA-256.
    pub token_sha256: &'a [u8; 32],
    /// How the room streams.
    pub stream: StreamSettings,
    /// The owner's lease, milliseconds.
    pub lease_ms: u32,
    /// When the owner wrote it, its clock.
    pub renewed_unix_ms: i64,
    /// A room of several actors: each actor's entry ([`actor_entry`]); empty otherwise.
    pub actors: &'a [v1::ActorEntry],
}

/// An actor's registry entry: `actor` as it runs (its retarget resolved) on the model file of
/// SHA-256 `model_sha256`.
pub fn actor_entry(actor: v1::Actor, model_sha256: &str) -> v1::ActorEntry {
    v1::ActorEntry {
        actor: Some(actor),
        model_sha256: model_sha256.to_owned(),
    }
}

/// A room's registry entry (never the token: its digest), no adoptions yet.
pub fn room_entry(p: EntryParts<'_>) -> v1::RoomEntry {
    let s = p.settings;
    v1::RoomEntry {
        model: s.model.to_owned(),
        model_sha256: p.model_sha256.to_owned(),
        beta: s.beta,
        filter: s.filter.map(v1::MarkerFilter::from),
        owner: p.owner.to_owned(),
        token_sha256: p.token_sha256.to_vec(),
        base_bits: u32::from(p.stream.base_bits),
        detail_bits: u32::from(p.stream.detail_bits),
        spatial_order: p.stream.spatial_order,
        keyframe_interval: p.stream.keyframe_interval,
        lease_ms: p.lease_ms,
        renewed_unix_ms: p.renewed_unix_ms,
        adoptions: 0,
        epoch: 1,
        tag: Vec::new(),
        retarget: s.retarget.cloned(),
        refine: s.refine.map(v1::Refine::from),
        skinning: v1::Skinning::from(s.skinning) as i32,
        actors: p.actors.to_vec(),
    }
}

/// `replica`'s interest in `level` in `encoding` of a room, for `ttl_ms`.
pub fn interest(replica: &str, level: Level, encoding: Encoding, ttl_ms: u32) -> v1::Interest {
    v1::Interest {
        replica: replica.to_owned(),
        level: v1::Level::from(level) as i32,
        ttl_ms,
        encoding: v1::Encoding::from(encoding) as i32,
    }
}

/// `frame`, forwarded by `replica` to the room's owner.
pub fn forwarded_control(frame: v1::ControlFrame, replica: &str) -> v1::ForwardedControl {
    v1::ForwardedControl {
        frame: Some(frame),
        replica: replica.to_owned(),
    }
}

/// The control frame of a forwarded one.
///
/// # Errors
/// [`WireError`] naming `ForwardedControl.frame` when it is missing.
pub fn read_forwarded_control(f: v1::ForwardedControl) -> Result<v1::ControlFrame, WireError> {
    f.frame
        .ok_or_else(|| WireError::new("ForwardedControl", "frame", "missing"))
}
