//! The JSON forms of the HTTP side, one serde mapping each: control frames a WebSocket
//! publisher sends as text ([`JsonControlFrame`]), the acks it gets back ([`JsonAck`]), and the
//! room documents of `GET /api/rooms` ([`RoomList`]) and `GET /api/rooms/{id}`
//! ([`RoomDocument`]), which the browser viewer reads; the takes of `GET /api/takes`
//! ([`TakeList`]), a take's frames for the viewer's player ([`TakeFrames`]) and its private
//! replay room ([`ReplayRoom`]); the batch jobs of `GET /api/jobs` ([`JobList`], issue 45).
//!
//! The shapes are frozen by the viewer (`web/viewer.js`) and the tests pinning them: the room
//! document's keys come in alphabetical order and its floats as the `f64` widening of the `f32`
//! (what these documents were when built through a `serde_json::Value`), an ack's floats as the
//! shortest `f32` form.

use serde::{Serialize, Serializer};

use crate::{WireError, encode_valid_mask, v1};

/// A control frame as JSON: `{"seq": 1, "capture_time_us": 0, "positions": [x, y, z, ...],
/// "valid": [true, ...]}`, `valid` optional (every point valid), `seq` and the time 0 when absent.
/// A room of several actors takes `"actors": [{"actor": "left", "positions": [...]}, ...]`
/// ([`JsonActorControls`], `ControlFrame.actors`) instead of the points.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, Serialize)]
pub struct JsonControlFrame {
    /// The publisher's sequence number.
    #[serde(default)]
    pub seq: u64,
    /// Capture time, microseconds since the Unix epoch.
    #[serde(default)]
    pub capture_time_us: i64,
    /// x, y, z of every control point (empty in a retargeting room).
    #[serde(default)]
    pub positions: Vec<f32>,
    /// One flag per control point.
    #[serde(default)]
    pub valid: Option<Vec<bool>>,
    /// A retargeting room's input (issue 19): x, y, z of every declared marker, in the
    /// capture's units.
    #[serde(default)]
    pub markers: Vec<f32>,
    /// One flag per marker.
    #[serde(default)]
    pub markers_valid: Option<Vec<bool>>,
    /// A room of several actors (issue 38): each actor's points or markers, by name; an actor
    /// left out holds its last pose.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub actors: Vec<JsonActorControls>,
}

/// One actor's part of a [`JsonControlFrame`]: `{"actor": "left", "positions": [...],
/// "valid": [...], "markers": [...], "markers_valid": [...]}` (`v1::ActorControls`).
#[derive(Clone, Debug, PartialEq, serde::Deserialize, Serialize)]
pub struct JsonActorControls {
    /// The actor's name.
    pub actor: String,
    /// As [`JsonControlFrame::positions`].
    #[serde(default)]
    pub positions: Vec<f32>,
    /// As [`JsonControlFrame::valid`].
    #[serde(default)]
    pub valid: Option<Vec<bool>>,
    /// As [`JsonControlFrame::markers`].
    #[serde(default)]
    pub markers: Vec<f32>,
    /// As [`JsonControlFrame::markers_valid`].
    #[serde(default)]
    pub markers_valid: Option<Vec<bool>>,
}

/// A validity mask from one flag per `x, y, z` triple of `values`; empty when `flags` is absent.
fn json_mask(
    field: &str,
    what: &str,
    flags: &Option<Vec<bool>>,
    values: &[f32],
) -> Result<Vec<u8>, WireError> {
    let mut out = Vec::new();
    if let Some(v) = flags {
        if v.len() * 3 != values.len() {
            return Err(WireError::new(
                "ControlFrame",
                field,
                format!(
                    "{} flags for {} {what} values (one flag per x, y, z triple)",
                    v.len(),
                    values.len()
                ),
            ));
        }
        encode_valid_mask(v, &mut out);
    }
    Ok(out)
}

impl JsonControlFrame {
    /// Parses a text message.
    ///
    /// # Errors
    /// A [`WireError`] naming `message` with serde's reason.
    pub fn parse(text: &str) -> Result<JsonControlFrame, WireError> {
        serde_json::from_str(text).map_err(|e| {
            WireError::new(
                "WebSocket",
                "message",
                format!("not a JSON control frame: {e}"),
            )
        })
    }

    /// The `ControlFrame` for room `room`.
    ///
    /// # Errors
    /// A [`WireError`] naming `valid` when its flags are not one per `x, y, z` triple.
    pub fn into_control_frame(self, room: &str) -> Result<v1::ControlFrame, WireError> {
        let valid = json_mask("valid", "position", &self.valid, &self.positions)?;
        let markers_valid = json_mask(
            "markers_valid",
            "marker",
            &self.markers_valid,
            &self.markers,
        )?;
        let actors = self
            .actors
            .into_iter()
            .enumerate()
            .map(|(i, a)| {
                let field = |f: &str| format!("actors[{i}].{f}");
                Ok(v1::ActorControls {
                    valid: json_mask(&field("valid"), "position", &a.valid, &a.positions)?,
                    markers_valid: json_mask(
                        &field("markers_valid"),
                        "marker",
                        &a.markers_valid,
                        &a.markers,
                    )?,
                    actor: a.actor,
                    positions: a.positions,
                    markers: a.markers,
                })
            })
            .collect::<Result<Vec<_>, WireError>>()?;
        Ok(v1::ControlFrame {
            room: room.to_owned(),
            seq: self.seq,
            capture_time_us: self.capture_time_us,
            positions: self.positions,
            valid,
            markers: self.markers,
            markers_valid,
            actors,
        })
    }
}

/// An ack as JSON: `{"seq": 1, "server_latency_us": 120, "held_controls": 0,
/// "control_residual": 0.002, "error": null}`, or with `"error": {"code": 3, "message": ...}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JsonAck {
    /// The frame's sequence number.
    pub seq: u64,
    /// Arrival to meshes ready, microseconds.
    pub server_latency_us: u32,
    /// Control points held.
    pub held_controls: u32,
    /// RMS distance of the valid control points to the mesh, model units.
    pub control_residual: f32,
    /// A retargeting room's residual in the capture's units (absent elsewhere).
    #[serde(skip_serializing_if = "is_zero")]
    pub control_residual_capture: f32,
    /// How far the frame lies from the model's training examples (`PublishAck.confidence`;
    /// absent when 0: at an example, and in acks of refused frames).
    #[serde(skip_serializing_if = "is_zero")]
    pub confidence: f32,
    /// Set when the frame was refused.
    pub error: Option<JsonError>,
    /// A room of several actors (issue 38): each actor's part (`PublishAck.actors`), in the
    /// room's order; absent in a one-actor room.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub actors: Vec<JsonActorAck>,
}

/// One actor's part of a [`JsonAck`]: `{"actor": "left", "held": false, "held_controls": 0,
/// "control_residual": 0.002}`, the capture residual and confidence as in the ack.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JsonActorAck {
    /// The actor's name.
    pub actor: String,
    /// The actor was missing from the frame and holds its last pose.
    pub held: bool,
    /// Its control points held.
    pub held_controls: u32,
    /// Its control residual, model units.
    pub control_residual: f32,
    /// In the capture's units (retargeting actors).
    #[serde(skip_serializing_if = "is_zero")]
    pub control_residual_capture: f32,
    /// Its distance from its model's examples.
    #[serde(skip_serializing_if = "is_zero")]
    pub confidence: f32,
}

impl From<v1::ActorAck> for JsonActorAck {
    fn from(a: v1::ActorAck) -> Self {
        Self {
            actor: a.actor,
            held: a.held,
            held_controls: a.held_controls,
            control_residual: a.control_residual,
            control_residual_capture: a.control_residual_capture,
            confidence: a.confidence,
        }
    }
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

/// A refused frame's error as JSON.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JsonError {
    /// google.rpc.Code ([`crate::errors::ErrorCode::wire`]).
    pub code: i32,
    /// What was wrong, naming the field.
    pub message: String,
}

impl From<v1::FrameError> for JsonError {
    fn from(e: v1::FrameError) -> Self {
        Self {
            code: e.code,
            message: e.message,
        }
    }
}

impl From<v1::PublishAck> for JsonAck {
    fn from(ack: v1::PublishAck) -> Self {
        Self {
            seq: ack.seq,
            server_latency_us: ack.server_latency_us,
            held_controls: ack.held_controls,
            control_residual: ack.control_residual,
            control_residual_capture: ack.control_residual_capture,
            confidence: ack.confidence,
            error: ack.error.map(JsonError::from),
            actors: ack.actors.into_iter().map(JsonActorAck::from).collect(),
        }
    }
}

impl JsonAck {
    /// The ack as a text message.
    pub fn to_text(&self) -> String {
        // Proven infallible: plain numbers, strings and an option, no maps with non-string keys.
        serde_json::to_string(self).expect("an ack always serialises")
    }
}

/// `GET /api/rooms`: `{"rooms": [ids, in order]}`; in a cluster also
/// `"cluster": [{"room", "model", "owner", "actors"}, ...]` and `"replica"` (the one that
/// answered).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomList {
    /// The open rooms' ids, sorted.
    pub rooms: Vec<String>,
    /// In a cluster: each room's model and owner replica, in the same order.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cluster: Vec<RoomOwner>,
    /// In a cluster: the replica that answered.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replica: Option<String>,
}

/// A cluster room in [`RoomList`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomOwner {
    /// The room id.
    pub room: String,
    /// Its model.
    pub model: String,
    /// The replica that predicts its frames.
    pub owner: String,
    /// A room of several actors (issue 38): the actors' names, in the room's order; absent
    /// in a one-actor room.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub actors: Vec<String>,
}

/// `f32`s as the `f64` they widen to (see the module docs).
fn widened<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(f64::from(*v))
}

/// `[f32; 3]`s as `f64`s.
fn widened3<S: Serializer>(v: &[f32; 3], s: S) -> Result<S::Ok, S::Error> {
    v.map(f64::from).serialize(s)
}

/// A box's corners as `f64`s.
fn widened_box<S: Serializer>(v: &Option<[[f32; 3]; 2]>, s: S) -> Result<S::Ok, S::Error> {
    v.map(|b| b.map(|c| c.map(f64::from))).serialize(s)
}

/// `GET /api/rooms/{id}`: what a viewer needs besides the stream. Keys in alphabetical order
/// (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomDocument {
    /// Vertices of the base mesh.
    pub base_vertices: u32,
    /// The room's translation-solve beta.
    #[serde(serialize_with = "widened")]
    pub beta: f32,
    /// The rest mesh's box, `[min, max]`.
    #[serde(serialize_with = "widened_box")]
    pub bounds: Option<[[f32; 3]; 2]>,
    /// A retargeting room's capture (issue 19): the marker names its frames carry, in order,
    /// and their units. Absent in other rooms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capture: Option<RoomCapture>,
    /// The model's control points.
    pub control_points: Vec<RoomControlPoint>,
    /// Vertices of the detail mesh (0: none).
    pub detail_vertices: u32,
    /// Whether the model has a detail layer.
    pub has_detail: bool,
    /// The model's name.
    pub model: String,
    /// The room id.
    pub room: String,
    /// `"dqs"` in a room that skins with dual quaternions (its palette streams are refused:
    /// the viewer asks for vertex frames); absent in LBS rooms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skinning: Option<String>,
    /// A room of several actors (issue 38): each actor, in the room's order (the fields above
    /// then describe the first). Absent in a one-actor room.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub actors: Vec<ActorDocument>,
}

/// One actor of a room of several in a [`RoomDocument`]: its name, side and performer, and the
/// document of its model (its control points' names as the actor's model has them: mirrored
/// models swap sides).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ActorDocument {
    /// The actor's name (`ActorFrame.actor` indexes the room's actors in this order).
    pub name: String,
    /// `left`, `right`, or absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub side: Option<String>,
    /// The performer it belongs to.
    pub performer: String,
    /// Its model, beta, capture and control points.
    #[serde(flatten)]
    pub room: RoomDocument,
}

/// A retargeting room's capture in a [`RoomDocument`] (`v1::Retarget`'s markers and units).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomCapture {
    /// The markers a frame carries (`ControlFrame.markers`), in frame order.
    pub markers: Vec<String>,
    /// Their units, as the room's opener gave them (may be empty).
    pub units: String,
}

/// A control point in a [`RoomDocument`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomControlPoint {
    /// Its position in every control frame.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// Its rest position.
    #[serde(serialize_with = "widened3")]
    pub rest: [f32; 3],
    /// The rest-mesh vertex it sits on.
    pub vertex: u32,
}

impl RoomDocument {
    /// The document of a room that skins with `skinning` (only DQS is named).
    pub fn with_skinning(mut self, skinning: crease_core::runtime::skin::Skinning) -> RoomDocument {
        self.skinning =
            (skinning == crease_core::runtime::skin::Skinning::Dqs).then(|| "dqs".to_owned());
        self
    }

    /// The document of room `room` on the model `info`, with the room's `beta` and, for a
    /// retargeting room, its `retarget`.
    pub fn new(
        room: &str,
        info: &v1::ModelInfo,
        beta: f32,
        has_detail: bool,
        retarget: Option<&v1::Retarget>,
    ) -> RoomDocument {
        let v3 = |v: Option<&v1::Vec3>| v.map_or([0.0; 3], |v| [v.x, v.y, v.z]);
        RoomDocument {
            base_vertices: info.base_vertices,
            beta,
            bounds: info
                .bounds
                .as_ref()
                .map(|b| [v3(b.min.as_ref()), v3(b.max.as_ref())]),
            capture: retarget.map(|r| RoomCapture {
                markers: r.markers.clone(),
                units: r.units.clone(),
            }),
            control_points: info
                .control_points
                .iter()
                .map(|c| RoomControlPoint {
                    id: c.id,
                    name: c.name.clone(),
                    rest: v3(c.rest.as_ref()),
                    vertex: c.vertex,
                })
                .collect(),
            detail_vertices: info.detail_vertices,
            has_detail,
            model: info.name.clone(),
            room: room.to_owned(),
            skinning: None,
            actors: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::errors::{ErrorCode, error_ack, frame_error};

    #[test]
    fn json_marker_frames_carry_markers_and_their_mask() {
        let f = JsonControlFrame::parse(
            r#"{"seq": 4, "markers": [1, 2, 3, 4, 5, 6], "markers_valid": [true, false]}"#,
        )
        .unwrap()
        .into_control_frame("cap")
        .unwrap();
        assert!(f.positions.is_empty() && f.valid.is_empty());
        assert_eq!(f.markers, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(f.markers_valid, [0b01]);
        let e = JsonControlFrame::parse(r#"{"markers": [1, 2, 3], "markers_valid": [true, true]}"#)
            .unwrap()
            .into_control_frame("cap")
            .unwrap_err();
        assert_eq!(e.field, "markers_valid");
        // A retargeting room's ack carries the capture-units residual; others stay as before.
        let ack = v1::PublishAck {
            seq: 1,
            control_residual: 0.01,
            control_residual_capture: 12.5,
            ..Default::default()
        };
        assert!(
            JsonAck::from(ack)
                .to_text()
                .contains(r#""control_residual_capture":12.5"#)
        );
    }

    #[test]
    fn acks_serialise_as_the_websocket_always_sent_them() {
        let ok = v1::PublishAck {
            seq: 1,
            server_latency_us: 120,
            held_controls: 2,
            error: None,
            control_residual: 0.002,
            ..Default::default()
        };
        assert_eq!(
            JsonAck::from(ok).to_text(),
            r#"{"seq":1,"server_latency_us":120,"held_controls":2,"control_residual":0.002,"error":null}"#
        );
        let refused = error_ack(
            7,
            frame_error(
                ErrorCode::PermissionDenied,
                "authorization: not the publish token",
            ),
        );
        assert_eq!(
            JsonAck::from(refused).to_text(),
            r#"{"seq":7,"server_latency_us":0,"held_controls":0,"control_residual":0.0,"error":{"code":7,"message":"authorization: not the publish token"}}"#
        );
    }

    #[test]
    fn room_documents_keep_their_keys_order_and_floats() {
        let info = v1::ModelInfo {
            name: "tube".into(),
            base_vertices: 10,
            detail_vertices: 0,
            control_points: vec![v1::ControlPoint {
                id: 0,
                name: "tip".into(),
                vertex: 4,
                rest: Some(v1::Vec3 {
                    x: 0.5,
                    y: 0.1,
                    z: -1.0,
                }),
            }],
            bounds: Some(crate::box3(
                crease_core::glam::Vec3::ZERO,
                crease_core::glam::Vec3::ONE,
            )),
            ..Default::default()
        };
        let doc = RoomDocument::new("r1", &info, 0.3, false, None);
        // 0.3f32 and 0.1f32 widened to f64, as a `serde_json::Value` holds them.
        assert_eq!(
            serde_json::to_string(&doc).unwrap(),
            concat!(
                r#"{"base_vertices":10,"beta":0.30000001192092896,"#,
                r#""bounds":[[0.0,0.0,0.0],[1.0,1.0,1.0]],"#,
                r#""control_points":[{"id":0,"name":"tip","rest":[0.5,0.10000000149011612,-1.0],"vertex":4}],"#,
                r#""detail_vertices":0,"has_detail":false,"model":"tube","room":"r1"}"#
            )
        );
        // A retargeting room names its markers, between the bounds and the control points.
        let retarget = v1::Retarget {
            markers: vec!["wrist".into(), "wrist/dorsal".into()],
            units: "m".into(),
            ..Default::default()
        };
        let text =
            serde_json::to_string(&RoomDocument::new("r1", &info, 0.3, false, Some(&retarget)))
                .unwrap();
        assert!(
            text.contains(
                r#"[1.0,1.0,1.0]],"capture":{"markers":["wrist","wrist/dorsal"],"units":"m"},"control_points""#
            ),
            "{text}"
        );
        let list = RoomList {
            rooms: vec!["a".into(), "b".into()],
            cluster: Vec::new(),
            replica: None,
        };
        assert_eq!(
            serde_json::to_string(&list).unwrap(),
            r#"{"rooms":["a","b"]}"#
        );
    }

    #[test]
    fn json_control_frames_parse_and_check_their_flags() {
        let f = JsonControlFrame::parse(
            r#"{"seq": 3, "positions": [1, 2, 3, 4, 5, 6], "valid": [true, false]}"#,
        )
        .unwrap()
        .into_control_frame("r")
        .unwrap();
        assert_eq!((f.room.as_str(), f.seq, f.capture_time_us), ("r", 3, 0));
        assert_eq!(f.positions, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(f.valid, [0b01]);
        let e = JsonControlFrame::parse(r#"{"positions": [1, 2, 3], "valid": [true, true]}"#)
            .unwrap()
            .into_control_frame("r")
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "ControlFrame.valid: 2 flags for 3 position values (one flag per x, y, z triple)"
        );
        // A frame of neither positions nor markers parses (a retargeting room's frames carry
        // markers only); the room then names the count it expected (`read_control_frame`).
        let f = JsonControlFrame::parse("{\"seq\": 1}").unwrap();
        assert!(f.positions.is_empty() && f.markers.is_empty());
        let e = JsonControlFrame::parse("{\"positions\": \"x\"}").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("WebSocket.message: not a JSON control frame: invalid type"),
            "{e}"
        );
    }

    #[test]
    fn json_frames_and_acks_of_a_room_of_actors() {
        let f = JsonControlFrame::parse(
            r#"{"seq": 9, "capture_time_us": 5, "actors": [
                {"actor": "right", "markers": [1, 2, 3], "markers_valid": [false]},
                {"actor": "left", "positions": [4, 5, 6, 7, 8, 9]}]}"#,
        )
        .unwrap()
        .into_control_frame("duo")
        .unwrap();
        assert!(f.positions.is_empty() && f.markers.is_empty());
        assert_eq!((f.seq, f.capture_time_us), (9, 5));
        assert_eq!(f.actors.len(), 2);
        assert_eq!(
            (f.actors[0].actor.as_str(), &f.actors[0].markers[..]),
            ("right", &[1.0, 2.0, 3.0][..])
        );
        assert_eq!(f.actors[0].markers_valid, [0]);
        assert_eq!(f.actors[1].actor, "left");
        assert_eq!(f.actors[1].positions, [4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        assert!(f.actors[1].valid.is_empty());
        // A mask of the wrong length names the actor's index and field.
        let e = JsonControlFrame::parse(
            r#"{"actors": [{"actor": "a"}, {"actor": "b", "positions": [1, 2, 3], "valid": []}]}"#,
        )
        .unwrap()
        .into_control_frame("duo")
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "ControlFrame.actors[1].valid: 0 flags for 3 position values (one flag per x, y, z triple)"
        );
        // The ack lists each actor's part; a one-actor room's ack has no "actors" key.
        let ack = v1::PublishAck {
            seq: 9,
            actors: vec![
                v1::ActorAck {
                    actor: "right".into(),
                    control_residual: 0.5,
                    control_residual_capture: 0.25,
                    ..Default::default()
                },
                v1::ActorAck {
                    actor: "left".into(),
                    held: true,
                    held_controls: 15,
                    ..Default::default()
                },
            ],
            ..Default::default()
        };
        let text = JsonAck::from(ack).to_text();
        assert!(
            text.ends_with(concat!(
                r#""error":null,"actors":[{"actor":"right","held":false,"held_controls":0,"#,
                r#""control_residual":0.5,"control_residual_capture":0.25},"#,
                r#"{"actor":"left","held":true,"held_controls":15,"control_residual":0.0}]}"#
            )),
            "{text}"
        );
    }
}

/// A take in [`TakeList`] (`v1::TakeInfo`, with the duration in seconds).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct TakeSummary {
    /// The take's id.
    pub take: String,
    /// The room it recorded.
    pub room: String,
    /// Its label.
    pub name: String,
    /// The room's model.
    pub model: String,
    /// The model's SHA-256 (hex).
    pub model_sha256: String,
    /// When recording began, microseconds since the Unix epoch.
    pub started_unix_us: i64,
    /// Whole frames.
    pub frames: u64,
    /// From its start to its last frame's arrival, seconds.
    pub duration_s: f64,
    /// The file's size.
    pub bytes: u64,
    /// Still recording.
    pub recording: bool,
    /// Ends in part of a frame (the server died while recording it).
    pub truncated: bool,
}

impl From<&v1::TakeInfo> for TakeSummary {
    fn from(t: &v1::TakeInfo) -> Self {
        TakeSummary {
            take: t.take.clone(),
            room: t.room.clone(),
            name: t.name.clone(),
            model: t.model.clone(),
            model_sha256: t.model_sha256.clone(),
            started_unix_us: t.started_unix_us,
            frames: t.frames,
            duration_s: t.duration_us as f64 * 1e-6,
            bytes: t.bytes,
            recording: t.recording,
            truncated: t.truncated,
        }
    }
}

/// `GET /api/jobs`: `{"jobs": [...]}`, newest first (issue 45; the viewer's job list).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct JobList {
    /// The jobs.
    pub jobs: Vec<JobSummary>,
}

/// A job in [`JobList`]: `JobInfo` with its state and level by name.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct JobSummary {
    /// The job's id.
    pub job: String,
    /// Its label.
    pub name: String,
    /// The model.
    pub model: String,
    /// `base` or `detail`.
    pub level: String,
    /// How its result's frames travel: `vertices` or `palette`.
    #[serde(default)]
    pub encoding: String,
    /// `queued`, `running`, `done`, `failed` or `cancelled`.
    pub state: String,
    /// Control frames in the job.
    pub frames_total: u64,
    /// Frames whose chunk is stored.
    pub frames_done: u64,
    /// Frames per second since the first chunk began.
    pub frames_per_second: f64,
    /// Seconds left at that rate (0 when unknown or ended).
    pub eta_seconds: f64,
    /// Why it failed or was cancelled.
    pub error: String,
    /// When it was submitted, microseconds since the Unix epoch.
    pub submitted_us: i64,
    /// When its result is deleted (0: not ended).
    pub expires_us: i64,
}

impl From<&crate::job::JobStatus> for JobSummary {
    fn from(s: &crate::job::JobStatus) -> Self {
        JobSummary {
            job: s.job.clone(),
            name: s.name.clone(),
            model: s.model.clone(),
            level: s.level.name().to_owned(),
            encoding: s.encoding.name().to_owned(),
            state: s.state.as_str().to_owned(),
            frames_total: s.frames_total,
            frames_done: s.frames_done,
            frames_per_second: s.frames_per_second,
            eta_seconds: s.eta_seconds,
            error: s.error.clone(),
            submitted_us: s.submitted_us,
            expires_us: s.expires_us,
        }
    }
}

/// `GET /api/takes[?room=ID]`: `{"takes": [...]}`, newest first.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct TakeList {
    /// The takes.
    pub takes: Vec<TakeSummary>,
}

/// `GET /api/takes/{id}/frames`: what the viewer's player publishes into its replay room:
/// every whole frame as the JSON control frame a WebSocket publisher sends, and its time in
/// seconds after the first (`take::keyframe_times`).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct TakeFrames {
    /// The take's id.
    pub take: String,
    /// The room it recorded, and its model.
    pub room: String,
    /// The model.
    pub model: String,
    /// The model's bones (a skinned export has one joint each).
    pub bones: u32,
    /// Seconds after the first frame, one per frame, strictly increasing.
    pub times: Vec<f64>,
    /// The frames, as recorded.
    pub frames: Vec<JsonControlFrame>,
}

impl TakeFrames {
    /// The JSON form of `take`.
    pub fn new(take: &crate::take::Take) -> TakeFrames {
        let header = take.header();
        let room = header.room.clone().unwrap_or_default();
        let controls = header.controls as usize;
        let markers = room.retarget.as_ref().map_or(0, |r| r.markers.len());
        let flags = |mask: &[u8], n: usize| {
            (!mask.is_empty()).then(|| (0..n).map(|i| crate::valid_bit(mask, i)).collect())
        };
        TakeFrames {
            take: header.take.clone(),
            room: room.room.clone(),
            model: room.model.clone(),
            bones: header.bones,
            times: crate::take::keyframe_times(take),
            frames: take
                .frames
                .iter()
                .map(|f| {
                    let c = f.frame.clone().unwrap_or_default();
                    let actors = c
                        .actors
                        .into_iter()
                        .map(|a| {
                            // The counts of the actor of that name (the room's order).
                            let at = header.actors.iter().position(|h| h.actor == a.actor);
                            let controls = at.map_or(0, |i| header.actors[i].controls as usize);
                            let markers = at
                                .and_then(|i| room.actors.get(i))
                                .and_then(|r| r.retarget.as_ref())
                                .map_or(0, |r| r.markers.len());
                            JsonActorControls {
                                valid: flags(&a.valid, controls),
                                markers_valid: flags(&a.markers_valid, markers),
                                actor: a.actor,
                                positions: a.positions,
                                markers: a.markers,
                            }
                        })
                        .collect();
                    JsonControlFrame {
                        seq: c.seq,
                        capture_time_us: c.capture_time_us,
                        valid: flags(&c.valid, controls),
                        markers_valid: flags(&c.markers_valid, markers),
                        positions: c.positions,
                        markers: c.markers,
                        actors,
                    }
                })
                .collect(),
        }
    }
}

/// `POST /api/takes/{id}/replay`: the private room opened to play the take back in, and its
/// publish token (the viewer publishes the take's frames into it).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct ReplayRoom {
    /// The room's id (not listed in `GET /api/rooms`).
    pub room: String,
    /// Its publish token.
    pub publish_token: String,
    /// The take.
    pub take: String,
}
