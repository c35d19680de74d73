//! What it takes to open a room, as one value: [`RoomSpec`], built once from whatever asks for
//! a room (an `OpenRoomRequest`, a cluster's `RoomEntry`, a take's header) with every wire
//! field checked here, so the server validates a room's options in one place. Also the room's
//! settings back on the wire ([`room_settings`]: what a take's header keeps) and the options
//! a room is built with ([`RoomOptions`], [`StreamSettings`]), which the server re-exports.

use crease_core::codec::DEFAULT_KEYFRAME_INTERVAL;
use crease_core::model::MirrorPlane;
use crease_core::predictor::Refinement;
use crease_core::runtime::filter::OneEuroParams;
use crease_core::runtime::skin::Skinning;

use crate::convert::skinning_from_wire;
use crate::errors::WireError;
use crate::v1;

/// What a room's opener chooses about its prediction (`OpenRoomRequest`'s beta, filter,
/// refine and skinning; the streaming side is the server's [`StreamSettings`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RoomOptions {
    /// Translation-solve beta; the model's default when `None`.
    pub beta: Option<f32>,
    /// Smooth the control points with a One Euro filter (mocap rooms); `None` passes them
    /// through, as UI rooms need. Must be [valid](OneEuroParams::is_valid).
    pub filter: Option<OneEuroParams>,
    /// Issue 20's bone-level refinement after the regression, resolved: `None` = the
    /// regression alone. A request that leaves it unset gets the server's default
    /// ([`Refinement::ROOM_DEFAULT`] unless `crease-server --refine` says otherwise, issue 42);
    /// `Refine.iterations = 0` turns it off. Must [validate](Refinement::validate).
    pub refine: Option<Refinement>,
    /// How the room skins (issue 22); the model's default (`TrainedModel::skinning`) when
    /// `None`. A DQS room streams vertices only (the server's `Pipeline::check_encoding`).
    pub skinning: Option<Skinning>,
}

/// How a room's meshes are streamed: quantisation bits per level and the vertex order.
///
/// Live rooms default to 12 bits for the base mesh: its half-step error (1/8190 of the padded
/// box, ~2e-4 of the model's size) is ~50x below the horse's prediction error (9.3e-3 RMS,
/// BENCHMARKS.md) and invisible at any viewing distance, and it brings the gallop to ~1.5
/// bytes per vertex per frame where 16 bits need ~3 (meshopt's vertex codec stores the low bits
/// of every moving vertex nearly verbatim: each bit costs ~3/8 byte per vertex). The detail
/// mesh carries wrinkles a few 1e-3 deep, so it keeps 14 bits. Batches (`Synthesize`) are for
/// pipelines and default to the full 16.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamSettings {
    /// Bits per coordinate of base frames, 1..=16.
    pub base_bits: u8,
    /// Bits per coordinate of detail frames, 1..=16.
    pub detail_bits: u8,
    /// Stream vertices in a spatial order (`Topology.vertex_order`): 7-10% smaller frames.
    pub spatial_order: bool,
    /// A keyframe every this many frames (0: only the first). Live rooms need few: a
    /// subscriber without the base of a delta (joined late, skipped frames) gets a keyframe of
    /// that frame on demand (the server's `MeshUpdate::frame_for`), so periodic keyframes only
    /// bound how long a client that lost its state by itself waits.
    pub keyframe_interval: u32,
}

impl Default for StreamSettings {
    fn default() -> Self {
        Self {
            base_bits: 12,
            detail_bits: 14,
            spatial_order: true,
            // 10 s at 60 Hz: +0.1% bytes on the horse gallop, where every 30 frames costs +1%.
            keyframe_interval: 600,
        }
    }
}

impl StreamSettings {
    /// Full 16-bit precision at both levels (batches).
    pub fn full() -> Self {
        Self {
            base_bits: 16,
            detail_bits: 16,
            keyframe_interval: DEFAULT_KEYFRAME_INTERVAL,
            ..Self::default()
        }
    }

    /// The stream settings a cluster's [`v1::RoomEntry`] names (bits clamped to 16).
    pub fn from_entry(entry: &v1::RoomEntry) -> Self {
        Self {
            base_bits: entry.base_bits.min(16) as u8,
            detail_bits: entry.detail_bits.min(16) as u8,
            spatial_order: entry.spatial_order,
            keyframe_interval: entry.keyframe_interval,
        }
    }
}

/// A room's publish token at open.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum RoomToken {
    /// A fresh random token (every room opened by a request).
    #[default]
    Random,
    /// An operator's fixed token (`--demo-token`).
    Fixed(String),
    /// Only the token's SHA-256 (a room opened on another replica of a cluster).
    Digest([u8; 32]),
}

/// Where a room lives, which the server's `AppState::open_room` acts on.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Placement {
    /// The server's room: in a cluster the cluster's (registered, predicted here), else this
    /// server's (an `OpenRoomRequest`).
    #[default]
    Shared,
    /// This server's alone, never registered in a cluster (the demo's rooms, a take's replay).
    Local,
    /// A relay of a cluster's room, as the registry held it at `revision`.
    Relay {
        /// The registry's entry.
        entry: Box<v1::RoomEntry>,
        /// Its revision.
        revision: u64,
    },
}

/// Everything needed to open a room (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoomSpec {
    /// The room id (the server checks its form when it opens the room).
    pub id: String,
    /// The model's name.
    pub model: String,
    /// The model's SHA-256 (hex) the room must run on: a cluster's relay fetches or checks it.
    pub model_sha256: Option<String>,
    /// Beta, filter, refinement and skinning, checked.
    pub options: RoomOptions,
    /// A retargeting room's map and markers (issue 19), as sent; the server resolves the map.
    pub retarget: Option<v1::Retarget>,
    /// The publish token.
    pub token: RoomToken,
    /// How the room streams; `None`: the server's settings.
    pub stream: Option<StreamSettings>,
    /// A private room: open to whoever knows its id, not listed (a take's replay).
    pub private: bool,
    /// Where the room lives.
    pub placement: Placement,
    /// A room of several actors (issue 38), checked: then `model`, `options` and `retarget`
    /// above are unset, each actor has its own. Empty for a one-actor room, which the fields
    /// above describe and which streams as rooms always did.
    pub actors: Vec<ActorSpec>,
}

/// Which side of its performer an actor is (`Actor.side`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Side {
    /// No side (a body, a prop).
    #[default]
    None,
    /// The performer's left.
    Left,
    /// The performer's right.
    Right,
}

impl Side {
    /// Its name on the wire: `left`, `right`, or empty.
    pub fn as_str(self) -> &'static str {
        match self {
            Side::None => "",
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// One actor of a room (`v1::Actor`), checked: a name unique in its room, its model, side,
/// mirror plane, performer and options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ActorSpec {
    /// 1 to [`ACTOR_NAME_MAX`] characters of `[A-Za-z0-9_-]`.
    pub name: String,
    /// The model's name.
    pub model: String,
    /// Which side of its performer.
    pub side: Side,
    /// The plane the model is mirrored across before use (`crease_core::model::mirror`).
    pub mirror: Option<MirrorPlane>,
    /// The performer it belongs to (its own name when the wire leaves it empty).
    pub performer: String,
    /// Beta, filter, refinement and skinning, checked.
    pub options: RoomOptions,
    /// A retargeting actor's map and markers, as sent.
    pub retarget: Option<v1::Retarget>,
    /// The SHA-256 (hex) of the model file as trained, which a cluster's relay fetches or
    /// checks (`RoomEntry.actors`); `None` in a request.
    pub model_sha256: Option<String>,
}

impl ActorSpec {
    /// What `RoomInfo.actors` lists of this actor: [`ActorSpec::running`], and its `model` as
    /// the actor uses it (mirrored: its control points' names swapped).
    pub fn info(&self, beta: f32, skinning: Skinning, model: v1::ModelInfo) -> v1::ActorInfo {
        v1::ActorInfo {
            actor: Some(self.running(beta, skinning)),
            model: Some(model),
        }
    }

    /// The actor as it runs: this spec with the `beta` and `skinning` in use (what
    /// `ActorInfo.actor` and a take's header carry). A performer of its own is left empty.
    pub fn running(&self, beta: f32, skinning: Skinning) -> v1::Actor {
        let o = &self.options;
        v1::Actor {
            name: self.name.clone(),
            model: self.model.clone(),
            side: self.side.as_str().to_owned(),
            mirror: self.mirror.map(|m| m.to_string()).unwrap_or_default(),
            performer: if self.performer == self.name {
                String::new()
            } else {
                self.performer.clone()
            },
            beta,
            filter: o.filter.map(v1::MarkerFilter::from),
            retarget: self.retarget.clone(),
            refine: o.refine.map(v1::Refine::from),
            skinning: v1::Skinning::from(skinning) as i32,
        }
    }
}

/// The longest actor or performer name.
pub const ACTOR_NAME_MAX: usize = 32;

impl ActorSpec {
    /// Actor `index` of a request, checked, an unset refinement taking `refine_default`;
    /// errors name the actor and the field.
    fn from_wire(
        index: usize,
        a: &v1::Actor,
        refine_default: Option<Refinement>,
    ) -> Result<ActorSpec, SpecError> {
        let label = if a.name.is_empty() {
            format!("#{index}")
        } else {
            format!("{:?}", a.name)
        };
        let bad = |field: &'static str, message: String| SpecError::Actor {
            actor: label.clone(),
            field,
            message,
        };
        check_identifier(&a.name, ACTOR_NAME_MAX).map_err(|m| bad("name", m))?;
        if !a.performer.is_empty() {
            check_identifier(&a.performer, ACTOR_NAME_MAX).map_err(|m| bad("performer", m))?;
        }
        if a.model.is_empty() {
            return Err(bad(
                "model",
                "is empty: name the model the actor runs on".into(),
            ));
        }
        let side = match a.side.to_ascii_lowercase().as_str() {
            "" => Side::None,
            "left" => Side::Left,
            "right" => Side::Right,
            other => {
                return Err(bad(
                    "side",
                    format!("{other:?} is not a side (\"left\", \"right\" or empty)"),
                ));
            }
        };
        let mirror = match a.mirror.trim() {
            "" => None,
            m => Some(MirrorPlane::parse(m).map_err(|e| bad("mirror", e.to_string()))?),
        };
        let options = options(
            "Actor",
            (a.beta != 0.0).then_some(a.beta),
            a.filter,
            a.refine,
            a.skinning,
            refine_default,
        )
        .map_err(|e| bad("options", e.to_string()))?;
        Ok(ActorSpec {
            name: a.name.clone(),
            model: a.model.clone(),
            side,
            mirror,
            performer: if a.performer.is_empty() {
                a.name.clone()
            } else {
                a.performer.clone()
            },
            options,
            retarget: a.retarget.clone(),
            model_sha256: None,
        })
    }
}

/// The server's one rule for the names it keeps (room and take ids, actor and performer names):
/// 1 to `max` characters of `[A-Za-z0-9_-]`, so a name is also a plain file name. The error
/// says what is wrong with `name`.
///
/// # Errors
/// The length, or the first character outside the set.
pub fn check_identifier(name: &str, max: usize) -> Result<(), String> {
    if name.is_empty() || name.len() > max {
        return Err(format!(
            "{name:?} has {} characters, expected 1 to {max}",
            name.len()
        ));
    }
    match name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-'))
    {
        Some(c) => Err(format!(
            "{name:?} holds {c:?}; only A-Z a-z 0-9 _ - are allowed"
        )),
        None => Ok(()),
    }
}

/// A request's actors, checked: each one, names unique, and the request's own model and
/// options unset beside them.
fn actors(
    r: &v1::OpenRoomRequest,
    refine_default: Option<Refinement>,
) -> Result<Vec<ActorSpec>, SpecError> {
    if r.actors.is_empty() {
        return Ok(Vec::new());
    }
    let beside = [
        ("model", !r.model.is_empty()),
        ("beta", r.beta != 0.0),
        ("filter", r.filter.is_some()),
        ("retarget", r.retarget.is_some()),
        ("refine", r.refine.is_some()),
        ("skinning", r.skinning != 0),
    ];
    if let Some((field, _)) = beside.iter().find(|(_, set)| *set) {
        return Err(SpecError::ActorsAndRoomField(field));
    }
    let mut out: Vec<ActorSpec> = Vec::with_capacity(r.actors.len());
    for (i, a) in r.actors.iter().enumerate() {
        let actor = ActorSpec::from_wire(i, a, refine_default)?;
        if let Some(j) = out.iter().position(|b| b.name == actor.name) {
            return Err(SpecError::Actor {
                actor: format!("{:?}", actor.name),
                field: "name",
                message: format!("actors {j} and {i} share it; names are unique in a room"),
            });
        }
        out.push(actor);
    }
    Ok(out)
}

/// Why a wire message does not describe a room that can be opened: names the field.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// The One Euro filter's cutoffs or beta are out of range.
    #[error(
        "filter: cutoffs must be positive and beta non-negative, got min_cutoff_hz {} beta {} d_cutoff_hz {}",
        .0.min_cutoff_hz, .0.beta, .0.d_cutoff_hz
    )]
    Filter(OneEuroParams),
    /// The refinement is out of range.
    #[error("refine: {0}")]
    Refine(String),
    /// A field that is not what its type allows (the skinning).
    #[error(transparent)]
    Wire(#[from] WireError),
    /// A registry entry's token digest is not a SHA-256.
    #[error("token digest has {0} bytes, a SHA-256 has 32")]
    TokenDigest(usize),
    /// An actor's field is wrong (issue 38).
    #[error("actor {actor}: {field}: {message}")]
    Actor {
        /// The actor's name (quoted), or `#index` when it has none.
        actor: String,
        /// The field.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A request lists actors and also sets a field each actor has its own of.
    #[error("OpenRoomRequest.{0} is set beside actors: with actors, each actor has its own {0}")]
    ActorsAndRoomField(&'static str),
}

/// The wire's filter, refinement and skinning of a room in `message_type`, checked; an
/// unset refinement takes `refine_default` (see [`refinement`]).
fn options(
    message_type: &'static str,
    beta: Option<f32>,
    filter: Option<v1::MarkerFilter>,
    refine: Option<v1::Refine>,
    skinning: i32,
    refine_default: Option<Refinement>,
) -> Result<RoomOptions, SpecError> {
    let filter = filter.map(OneEuroParams::from);
    if let Some(f) = filter
        && !f.is_valid()
    {
        return Err(SpecError::Filter(f));
    }
    Ok(RoomOptions {
        beta,
        filter,
        refine: refinement(refine, refine_default)?,
        skinning: skinning_from_wire(message_type, skinning)?,
    })
}

/// A request's refinement, checked and resolved (issue 42): unset takes `default` (the
/// server's, for a request; `None` for what a room recorded: a take's header, a registry
/// entry, where unset has always meant off); `iterations = 0` is off; anything else must
/// [validate](Refinement::validate) (`refine: ...` names the field in the error).
///
/// # Errors
/// [`SpecError::Refine`].
pub fn refinement(
    wire: Option<v1::Refine>,
    default: Option<Refinement>,
) -> Result<Option<Refinement>, SpecError> {
    match wire {
        None => Ok(default),
        Some(v1::Refine { iterations: 0, .. }) => Ok(None),
        Some(w) => {
            let refine = Refinement::from(w);
            refine.validate().map_err(SpecError::Refine)?;
            Ok(Some(refine))
        }
    }
}

/// The wire form of a resolved refinement a client asks for explicitly: `None` (off) is
/// `iterations = 0`, which [`refinement`] reads back as off whatever the server's default.
pub fn refine_wire(refine: Option<Refinement>) -> v1::Refine {
    refine.map_or(
        v1::Refine {
            iterations: 0,
            strength: 0.0,
        },
        v1::Refine::from,
    )
}

/// A `--refine` flag's value (`crease-server`, `crease synth`, `crease room open`): `off`, or
/// `ITERATIONS,STRENGTH` (e.g. `8,0.01`) that [validates](Refinement::validate).
///
/// # Errors
/// What is wrong, naming the part, for clap to print.
pub fn parse_refine_flag(text: &str) -> Result<RefineFlag, String> {
    if text.trim().eq_ignore_ascii_case("off") {
        return Ok(RefineFlag(None));
    }
    let refine = parse_iterations_strength(text)
        .map_err(|e| e.replace("expected ITERATIONS", "expected `off` or ITERATIONS"))?;
    refine.validate()?;
    Ok(RefineFlag(Some(refine)))
}

/// `ITERATIONS,STRENGTH` as written (e.g. `8,0.01`), parsed but not checked: what every
/// `--refine` reads ([`parse_refine_flag`], and `crease eval`'s, which also takes strength 0).
///
/// # Errors
/// The part that does not parse, named.
pub fn parse_iterations_strength(text: &str) -> Result<Refinement, String> {
    let (it, strength) = text
        .split_once(',')
        .ok_or_else(|| format!("{text:?}: expected ITERATIONS,STRENGTH (e.g. 8,0.01)"))?;
    let iterations: usize = it
        .trim()
        .parse()
        .map_err(|e| format!("iterations {it:?}: {e}"))?;
    let strength: f32 = strength
        .trim()
        .parse()
        .map_err(|e| format!("strength {strength:?}: {e}"))?;
    Ok(Refinement {
        iterations,
        strength,
        from_rest: false,
    })
}

/// A parsed `--refine` flag ([`parse_refine_flag`]): `None` is `off`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineFlag(pub Option<Refinement>);

impl std::fmt::Display for RefineFlag {
    /// As the flag is written: `off` or `ITERATIONS,STRENGTH`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            None => f.write_str("off"),
            Some(r) => write!(f, "{},{}", r.iterations, r.strength),
        }
    }
}

impl RoomSpec {
    /// The room an `OpenRoomRequest` asks for (a fresh token, the server's stream settings,
    /// shared in a cluster), the room or each actor taking `refine_default` when the request
    /// leaves its refinement unset (the server's `Config::refine`).
    ///
    /// # Errors
    /// [`SpecError`] naming the field (filter, refine, `OpenRoomRequest.skinning`).
    pub fn from_request(
        r: &v1::OpenRoomRequest,
        refine_default: Option<Refinement>,
    ) -> Result<RoomSpec, SpecError> {
        Ok(RoomSpec {
            id: r.room.clone(),
            model: r.model.clone(),
            options: options(
                "OpenRoomRequest",
                (r.beta != 0.0).then_some(r.beta),
                r.filter,
                r.refine,
                r.skinning,
                refine_default,
            )?,
            retarget: r.retarget.clone(),
            actors: actors(r, refine_default)?,
            ..RoomSpec::default()
        })
    }

    /// A private replay room `id` of a take recorded with `header`'s room settings: this
    /// server's alone, refined as recorded (an unset refinement was off, whatever the server's
    /// default now).
    ///
    /// # Errors
    /// [`SpecError`], as [`RoomSpec::from_request`].
    pub fn from_take(id: &str, header: &v1::TakeHeader) -> Result<RoomSpec, SpecError> {
        let settings = header.room.clone().unwrap_or_default();
        Ok(RoomSpec {
            id: id.to_owned(),
            private: true,
            placement: Placement::Local,
            ..RoomSpec::from_request(&settings, None)?
        })
    }

    /// A relay of the cluster's room `id` as the registry's `entry` at `revision` describes
    /// it: its model by digest, the token's digest, the owner's stream settings, the resolved
    /// map (an adopter then retargets the publishers' markers as the owner did).
    ///
    /// # Errors
    /// [`SpecError`]: an entry no replica writes (a server bug or a foreign writer).
    pub fn from_entry(
        id: &str,
        entry: &v1::RoomEntry,
        revision: u64,
    ) -> Result<RoomSpec, SpecError> {
        // Unspecified skinning (an entry of a replica older than issue 22): the model's
        // default, which is what that owner skinned with.
        let options = options(
            "RoomEntry",
            Some(entry.beta),
            entry.filter,
            entry.refine,
            entry.skinning,
            None,
        )?;
        let digest = <[u8; 32]>::try_from(entry.token_sha256.as_slice())
            .map_err(|_| SpecError::TokenDigest(entry.token_sha256.len()))?;
        Ok(RoomSpec {
            id: id.to_owned(),
            model: entry.model.clone(),
            model_sha256: Some(entry.model_sha256.clone()),
            options,
            retarget: entry.retarget.clone(),
            token: RoomToken::Digest(digest),
            stream: Some(StreamSettings::from_entry(entry)),
            private: false,
            placement: Placement::Relay {
                entry: Box::new(entry.clone()),
                revision,
            },
            actors: entry
                .actors
                .iter()
                .enumerate()
                .map(|(i, e)| {
                    let a = e.actor.as_ref().ok_or_else(|| SpecError::Actor {
                        actor: format!("#{i}"),
                        field: "actor",
                        message: "missing from the registry entry".into(),
                    })?;
                    Ok(ActorSpec {
                        model_sha256: Some(e.model_sha256.clone()),
                        ..ActorSpec::from_wire(i, a, None)?
                    })
                })
                .collect::<Result<_, SpecError>>()?,
        })
    }
}

/// What a live room runs with, for [`room_settings`] and [`crate::cluster::room_entry`].
#[derive(Clone, Copy, Debug)]
pub struct RoomSettings<'a> {
    /// The room id.
    pub room: &'a str,
    /// The model's name.
    pub model: &'a str,
    /// The beta in use.
    pub beta: f32,
    /// The filter, if the room filters.
    pub filter: Option<OneEuroParams>,
    /// The retarget (as sent for [`room_settings`]; resolved for a registry entry).
    pub retarget: Option<&'a v1::Retarget>,
    /// The refinement, when on.
    pub refine: Option<Refinement>,
    /// The skinning in use.
    pub skinning: Skinning,
}

/// A room's settings as the request that would open it again (no token): what a take's
/// header keeps.
pub fn room_settings(s: RoomSettings<'_>) -> v1::OpenRoomRequest {
    v1::OpenRoomRequest {
        room: s.room.to_owned(),
        model: s.model.to_owned(),
        beta: s.beta,
        filter: s.filter.map(v1::MarkerFilter::from),
        retarget: s.retarget.cloned(),
        refine: s.refine.map(v1::Refine::from),
        skinning: v1::Skinning::from(s.skinning) as i32,
        actors: Vec::new(),
    }
}

/// An actor `name` on `model`, mirrored across x when `mirrored` (a left hand on a right-hand
/// model), with the server's default options: what the bench and the demo open rooms of.
pub fn actor(name: &str, model: &str, mirrored: bool) -> v1::Actor {
    v1::Actor {
        name: name.to_owned(),
        model: model.to_owned(),
        mirror: if mirrored {
            "x".to_owned()
        } else {
            String::new()
        },
        ..Default::default()
    }
}

/// A room of several actors' settings as the request that would open it again (no token):
/// its id and its `actors` as they run (what a take's header keeps).
pub fn actors_room_settings(room: &str, actors: Vec<v1::Actor>) -> v1::OpenRoomRequest {
    v1::OpenRoomRequest {
        room: room.to_owned(),
        actors,
        ..Default::default()
    }
}

/// A retarget of `markers` (the capture's names, in frame order, in `units`) through the
/// marker map `map_toml` (the demo's WebXR room).
pub fn retarget(map_toml: String, markers: Vec<String>, units: String) -> v1::Retarget {
    v1::Retarget {
        map_toml,
        markers,
        units,
        ..Default::default()
    }
}

/// `wire` with its map given as `map_toml` (a map named from a maps folder, resolved so that
/// another replica can rebuild the room without that folder).
pub fn resolved_retarget(wire: &v1::Retarget, map_toml: String) -> v1::Retarget {
    v1::Retarget {
        map_toml,
        ..wire.clone()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_checked_once_naming_the_field() {
        let ok = v1::OpenRoomRequest {
            room: "r".into(),
            model: "m".into(),
            beta: 2.0,
            ..Default::default()
        };
        let spec = RoomSpec::from_request(&ok, None).unwrap();
        assert_eq!((spec.id.as_str(), spec.options.beta), ("r", Some(2.0)));
        assert_eq!(spec.placement, Placement::Shared);
        let bad_filter = v1::OpenRoomRequest {
            filter: Some(v1::MarkerFilter {
                min_cutoff_hz: -1.0,
                beta: 0.0,
                d_cutoff_hz: 1.0,
            }),
            ..ok.clone()
        };
        let e = RoomSpec::from_request(&bad_filter, None).unwrap_err();
        assert!(e.to_string().starts_with("filter: "), "{e}");
        let bad_skinning = v1::OpenRoomRequest {
            skinning: 7,
            ..ok.clone()
        };
        assert_eq!(
            RoomSpec::from_request(&bad_skinning, None)
                .unwrap_err()
                .to_string(),
            "OpenRoomRequest.skinning: 7 is not a Skinning (0 unspecified, 1 lbs, 2 dqs)"
        );
        let bad_refine = v1::OpenRoomRequest {
            refine: Some(v1::Refine {
                iterations: 33,
                strength: 0.01,
            }),
            ..ok
        };
        assert_eq!(
            RoomSpec::from_request(&bad_refine, None)
                .unwrap_err()
                .to_string(),
            "refine: iterations must be 1 to 32, got 33"
        );
    }

    #[test]
    fn an_unset_refinement_takes_the_servers_default_and_zero_iterations_turn_it_off() {
        let default = Some(Refinement::ROOM_DEFAULT);
        let asked = Refinement {
            iterations: 3,
            strength: 0.5,
            from_rest: false,
        };
        let room = |refine: Option<v1::Refine>| v1::OpenRoomRequest {
            room: "r".into(),
            model: "m".into(),
            refine,
            ..Default::default()
        };
        let spec = |r: &v1::OpenRoomRequest, d| RoomSpec::from_request(r, d).unwrap();
        assert_eq!(spec(&room(None), default).options.refine, default);
        assert_eq!(spec(&room(None), None).options.refine, None);
        let off = Some(refine_wire(None));
        assert_eq!(spec(&room(off), default).options.refine, None);
        let on = Some(refine_wire(Some(asked)));
        assert_eq!(spec(&room(on), default).options.refine, Some(asked));
        // Each actor resolves its own.
        let actors = v1::OpenRoomRequest {
            room: "r".into(),
            actors: vec![
                actor("a", "m"),
                v1::Actor {
                    refine: off,
                    ..actor("b", "m")
                },
            ],
            ..Default::default()
        };
        let a = spec(&actors, default).actors;
        assert_eq!((a[0].options.refine, a[1].options.refine), (default, None));
        // What a room recorded (a take's header) reads unset as off, whatever the default.
        let header = v1::TakeHeader {
            room: Some(room(None)),
            ..Default::default()
        };
        assert_eq!(
            RoomSpec::from_take("replay", &header)
                .unwrap()
                .options
                .refine,
            None
        );
        // The flag's forms.
        let flag = |t: &str| parse_refine_flag(t).map(|f| f.0);
        assert_eq!(flag("off"), Ok(None));
        assert_eq!(flag("3, 0.5"), Ok(Some(asked)));
        assert_eq!(parse_refine_flag("3,0.5").unwrap().to_string(), "3,0.5");
        assert_eq!(RefineFlag(None).to_string(), "off");
        assert_eq!(
            flag("0,0.01"),
            Err("iterations must be 1 to 32, got 0".to_owned())
        );
        assert!(
            flag("8")
                .unwrap_err()
                .contains("expected `off` or ITERATIONS,STRENGTH")
        );
    }

    fn actor(name: &str, model: &str) -> v1::Actor {
        v1::Actor {
            name: name.into(),
            model: model.into(),
            ..Default::default()
        }
    }

    #[test]
    fn actors_are_checked_naming_the_actor_and_the_field() {
        let two = v1::OpenRoomRequest {
            room: "performer".into(),
            actors: vec![
                v1::Actor {
                    side: "right".into(),
                    performer: "ana".into(),
                    beta: 2.5,
                    ..actor("right", "hand")
                },
                v1::Actor {
                    side: "Left".into(),
                    mirror: "x".into(),
                    performer: "ana".into(),
                    ..actor("left", "hand")
                },
            ],
            ..Default::default()
        };
        let spec = RoomSpec::from_request(&two, None).unwrap();
        assert_eq!(spec.actors.len(), 2);
        let (r, l) = (&spec.actors[0], &spec.actors[1]);
        assert_eq!(
            (r.side, r.mirror, r.options.beta),
            (Side::Right, None, Some(2.5))
        );
        assert_eq!(
            (l.side, l.mirror, l.options.beta),
            (Side::Left, Some(MirrorPlane::X), None)
        );
        assert_eq!((r.performer.as_str(), l.performer.as_str()), ("ana", "ana"));
        // A one-actor room of today has no actors; an actor without a performer is its own.
        assert!(
            RoomSpec::from_request(&v1::OpenRoomRequest::default(), None)
                .unwrap()
                .actors
                .is_empty()
        );
        let alone = v1::OpenRoomRequest {
            actors: vec![actor("prop", "m")],
            ..Default::default()
        };
        assert_eq!(
            RoomSpec::from_request(&alone, None).unwrap().actors[0].performer,
            "prop"
        );

        let with = |f: &dyn Fn(&mut v1::OpenRoomRequest)| {
            let mut r = two.clone();
            f(&mut r);
            RoomSpec::from_request(&r, None).unwrap_err().to_string()
        };
        assert_eq!(
            with(&|r| r.actors[1].side = "middle".into()),
            "actor \"left\": side: \"middle\" is not a side (\"left\", \"right\" or empty)"
        );
        assert_eq!(
            with(&|r| r.actors[1].name = "right".into()),
            "actor \"right\": name: actors 0 and 1 share it; names are unique in a room"
        );
        assert!(
            with(&|r| r.actors[0].name = String::new()).starts_with("actor #0: name: \"\" has 0"),
        );
        assert!(with(&|r| r.actors[0].name = "a b".into()).contains("holds ' '"));
        assert!(with(&|r| r.actors[0].name = "x".repeat(33)).contains("expected 1 to 32"));
        assert_eq!(
            with(&|r| r.actors[1].model = String::new()),
            "actor \"left\": model: is empty: name the model the actor runs on"
        );
        assert!(
            with(&|r| r.actors[1].mirror = "0,0,0".into()).starts_with("actor \"left\": mirror: ")
        );
        assert!(
            with(&|r| r.actors[0].performer = "a/b".into())
                .starts_with("actor \"right\": performer: ")
        );
        assert_eq!(
            with(&|r| r.actors[0].skinning = 9),
            "actor \"right\": options: Actor.skinning: 9 is not a Skinning (0 unspecified, 1 lbs, 2 dqs)"
        );
        assert_eq!(
            with(&|r| r.model = "hand".into()),
            "OpenRoomRequest.model is set beside actors: with actors, each actor has its own model"
        );
        assert_eq!(
            with(&|r| r.beta = 1.0),
            "OpenRoomRequest.beta is set beside actors: with actors, each actor has its own beta"
        );
    }

    #[test]
    fn an_entry_is_a_relay_with_the_owners_digest_and_settings() {
        let entry = v1::RoomEntry {
            model: "m".into(),
            model_sha256: "ab".into(),
            beta: 3.0,
            token_sha256: vec![7; 32],
            base_bits: 40,
            detail_bits: 14,
            ..Default::default()
        };
        let spec = RoomSpec::from_entry("r", &entry, 5).unwrap();
        assert_eq!(spec.token, RoomToken::Digest([7; 32]));
        assert_eq!(spec.stream.unwrap().base_bits, 16);
        assert!(matches!(
            spec.placement,
            Placement::Relay { revision: 5, .. }
        ));
        let short = v1::RoomEntry {
            token_sha256: vec![1; 3],
            ..entry
        };
        assert_eq!(
            RoomSpec::from_entry("r", &short, 1).unwrap_err(),
            SpecError::TokenDigest(3)
        );
    }
}
