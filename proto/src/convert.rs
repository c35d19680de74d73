//! Every conversion between wire messages and core types: points, boxes, filters, levels,
//! control frames (read into caller buffers, no allocation per frame), topologies, mesh frames
//! and model descriptions. A conversion that fails names the message and the field
//! ([`WireError`]).

use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_core::runtime::filter::OneEuroParams;
use prost::bytes::Bytes;

use crate::v1;

/// A wire message that does not fit the model: the message, the field and what is wrong with it.
/// Shown as `ControlFrame.positions: 7 values, expected 45`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message_type}.{field}: {message}")]
pub struct WireError {
    /// The protobuf message the field belongs to, e.g. `ControlFrame`.
    pub message_type: &'static str,
    /// The offending field, e.g. `positions[7]` or `valid`.
    pub field: String,
    /// What was wrong: expected vs got.
    pub message: String,
}

impl WireError {
    /// An error in `field` of `message_type`.
    pub fn new(
        message_type: &'static str,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self {
            message_type,
            field: field.into(),
            message: message.into(),
        }
    }
}

impl From<WireError> for tonic::Status {
    fn from(e: WireError) -> Self {
        tonic::Status::invalid_argument(e.to_string())
    }
}

/// The wire form of a point.
impl From<Vec3> for v1::Vec3 {
    fn from(p: Vec3) -> Self {
        Self {
            x: p.x,
            y: p.y,
            z: p.z,
        }
    }
}

/// A wire point as a core point.
impl From<v1::Vec3> for Vec3 {
    fn from(p: v1::Vec3) -> Self {
        Vec3::new(p.x, p.y, p.z)
    }
}

/// The wire form of a room's control-point filter.
impl From<OneEuroParams> for v1::MarkerFilter {
    fn from(p: OneEuroParams) -> Self {
        Self {
            min_cutoff_hz: p.min_cutoff_hz,
            beta: p.beta,
            d_cutoff_hz: p.d_cutoff_hz,
        }
    }
}

/// A wire filter as core parameters (check [`OneEuroParams::is_valid`] before use).
impl From<v1::MarkerFilter> for OneEuroParams {
    fn from(f: v1::MarkerFilter) -> Self {
        Self {
            min_cutoff_hz: f.min_cutoff_hz,
            beta: f.beta,
            d_cutoff_hz: f.d_cutoff_hz,
        }
    }
}

/// A box from its corners.
pub fn box3(min: Vec3, max: Vec3) -> v1::Box3 {
    v1::Box3 {
        min: Some(min.into()),
        max: Some(max.into()),
    }
}

/// Whether bit `i` of a validity mask is set; an empty mask means every point is valid.
pub fn valid_bit(mask: &[u8], i: usize) -> bool {
    mask.is_empty() || mask.get(i / 8).is_some_and(|b| b & (1 << (i % 8)) != 0)
}

/// The validity bitmask of `valid` (bit `i` = `valid[i]`, least significant bit first), into
/// `out` (cleared first).
pub fn encode_valid_mask(valid: &[bool], out: &mut Vec<u8>) {
    out.clear();
    out.resize(valid.len().div_ceil(8), 0);
    for (i, _) in valid.iter().enumerate().filter(|(_, v)| **v) {
        out[i / 8] |= 1 << (i % 8);
    }
}

/// Reads a control frame for a model with `positions.len()` control points into `positions`
/// and `valid`, and returns how many points are invalid. A point marked invalid may carry any
/// value (it is held at its last valid position by the predictor); a valid one must be finite.
///
/// # Errors
/// A [`WireError`] naming `positions` (count), `positions[i]` (non-finite coordinate of a valid
/// point) or `valid` (mask length). Nothing is written on error.
pub fn read_control_frame(
    frame: &v1::ControlFrame,
    positions: &mut [Vec3],
    valid: &mut [bool],
) -> Result<usize, WireError> {
    let n = positions.len();
    assert_eq!(valid.len(), n, "one validity flag per control point");
    if frame.positions.len() != 3 * n {
        return Err(WireError::new(
            "ControlFrame",
            "positions",
            format!(
                "{} values, expected {} (x, y, z of {n} control points)",
                frame.positions.len(),
                3 * n
            ),
        ));
    }
    let mask = &frame.valid;
    if !mask.is_empty() && mask.len() != n.div_ceil(8) {
        return Err(WireError::new(
            "ControlFrame",
            "valid",
            format!(
                "{} bytes, expected {} (one bit per control point, {n} points) or none",
                mask.len(),
                n.div_ceil(8)
            ),
        ));
    }
    for (i, c) in frame.positions.chunks_exact(3).enumerate() {
        if valid_bit(mask, i) && !c.iter().all(|v| v.is_finite()) {
            return Err(WireError::new(
                "ControlFrame",
                format!("positions[{i}]"),
                format!(
                    "({}, {}, {}) is not finite; mark the point invalid in `valid` instead",
                    c[0], c[1], c[2]
                ),
            ));
        }
    }
    let mut invalid = 0;
    for (i, (c, (p, v))) in frame
        .positions
        .chunks_exact(3)
        .zip(positions.iter_mut().zip(valid.iter_mut()))
        .enumerate()
    {
        *v = valid_bit(mask, i);
        *p = if *v {
            Vec3::new(c[0], c[1], c[2])
        } else {
            invalid += 1;
            Vec3::NAN
        };
    }
    Ok(invalid)
}

/// A control frame for the wire: `positions` flattened to `x, y, z` (a point that is not
/// finite is sent as zeros; mark it invalid), and the validity mask, left empty when every
/// point is valid (which the server reads as "all valid").
pub fn control_frame(
    room: &str,
    seq: u64,
    capture_time_us: i64,
    positions: &[Vec3],
    valid: &[bool],
) -> v1::ControlFrame {
    let mut mask = Vec::new();
    if valid.iter().any(|v| !v) {
        encode_valid_mask(valid, &mut mask);
    }
    v1::ControlFrame {
        room: room.to_owned(),
        seq,
        capture_time_us,
        positions: positions
            .iter()
            .flat_map(|p| {
                if p.is_finite() {
                    p.to_array()
                } else {
                    [0.0; 3]
                }
            })
            .collect(),
        valid: mask,
    }
}

/// A mesh stream's topology, decoded (see `Topology` in `crease.proto`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StreamTopology {
    /// Vertices per frame.
    pub vertex_count: usize,
    /// Triangles in the streamed order (what a renderer draws the decoded frames with).
    pub triangles: Vec<[u32; 3]>,
    /// Streamed vertex `i` is model vertex `order[i]`; empty: the model's order.
    pub order: Vec<u32>,
    /// Quantisation bits per coordinate.
    pub bits: u32,
}

impl StreamTopology {
    /// `streamed` (a decoded frame's positions) in model vertex order, into `out` (resized).
    pub fn to_model_order(&self, streamed: &[Vec3], out: &mut Vec<Vec3>) {
        out.clear();
        if self.order.is_empty() {
            out.extend_from_slice(streamed);
            return;
        }
        out.resize(streamed.len(), Vec3::ZERO);
        for (&model, &p) in self.order.iter().zip(streamed) {
            out[model as usize] = p;
        }
    }

    /// The triangles in model vertex ids.
    pub fn model_triangles(&self) -> Vec<[u32; 3]> {
        if self.order.is_empty() {
            return self.triangles.clone();
        }
        let o = &self.order;
        self.triangles
            .iter()
            .map(|t| [o[t[0] as usize], o[t[1] as usize], o[t[2] as usize]])
            .collect()
    }
}

/// Reads a `Topology`: decodes the index buffer and checks the vertex order is a permutation of
/// `0..vertex_count`.
///
/// # Errors
/// [`WireError`] naming `indices` (the codec's error) or `vertex_order` (wrong length, an index
/// out of range, a repeated vertex).
pub fn read_topology(t: &v1::Topology) -> Result<StreamTopology, WireError> {
    let n = t.vertex_count as usize;
    let mut triangles = Vec::new();
    crease_core::codec::decode_indices(&t.indices, t.triangle_count as usize, n, &mut triangles)
        .map_err(|e| WireError::new("Topology", "indices", e.to_string()))?;
    if !t.vertex_order.is_empty() {
        if t.vertex_order.len() != n {
            return Err(WireError::new(
                "Topology",
                "vertex_order",
                format!(
                    "{} entries, expected {n} (vertex_count)",
                    t.vertex_order.len()
                ),
            ));
        }
        let mut seen = vec![false; n];
        for (i, &v) in t.vertex_order.iter().enumerate() {
            let slot = seen.get_mut(v as usize).ok_or_else(|| {
                WireError::new(
                    "Topology",
                    format!("vertex_order[{i}]"),
                    format!("{v}, expected < {n}"),
                )
            })?;
            if std::mem::replace(slot, true) {
                return Err(WireError::new(
                    "Topology",
                    format!("vertex_order[{i}]"),
                    format!("vertex {v} appears twice"),
                ));
            }
        }
    }
    Ok(StreamTopology {
        vertex_count: n,
        triangles,
        order: t.vertex_order.clone(),
        bits: t.bits,
    })
}

/// The public description of a trained model named `name`.
pub fn model_info(name: &str, model: &TrainedModel) -> v1::ModelInfo {
    let rest = &model.rig.rest;
    let (min, max) = rest.bounding_box();
    let (detail_vertices, detail_triangles) = match &model.detail {
        Some(d) => (
            d.regressor.vertex_count() as u32,
            (rest.triangles.len() << (2 * d.levels)) as u32,
        ),
        None => (0, 0),
    };
    v1::ModelInfo {
        name: name.to_owned(),
        base_vertices: rest.vertex_count() as u32,
        base_triangles: rest.triangles.len() as u32,
        detail_vertices,
        detail_triangles,
        control_points: model
            .controls
            .iter()
            .enumerate()
            .map(|(i, c)| v1::ControlPoint {
                id: i as u32,
                name: c.name.clone(),
                vertex: c.vertex,
                rest: Some(rest.positions[c.vertex as usize].into()),
            })
            .collect(),
        bounds: Some(box3(min, max)),
        method: model.method.clone(),
        default_beta: model.beta,
        bones: model.rig.bone_count as u32,
    }
}

/// Which mesh a stream carries: the domain side of `crease.v1.Level`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Level {
    /// The skinned base mesh.
    Base,
    /// The detail layer on top (models with one).
    Detail,
}

impl Level {
    /// Both levels, base first (an index per level: `level as usize`).
    pub const ALL: [Level; 2] = [Level::Base, Level::Detail];

    /// The level of a request's `level` field (`LEVEL_UNSPECIFIED` is the base mesh) in
    /// `message_type`.
    ///
    /// # Errors
    /// [`WireError`] naming `{message_type}.level` for a value that is not a `Level`.
    pub fn from_wire(message_type: &'static str, level: i32) -> Result<Level, WireError> {
        match v1::Level::try_from(level) {
            Ok(v1::Level::Unspecified | v1::Level::Base) => Ok(Level::Base),
            Ok(v1::Level::Detail) => Ok(Level::Detail),
            Err(_) => Err(WireError::new(
                message_type,
                "level",
                format!("{level} is not a Level (0 unspecified, 1 base, 2 detail)"),
            )),
        }
    }

    /// The level of a WebSocket's `?level=` query (`base` when absent).
    ///
    /// # Errors
    /// [`WireError`] naming `level` for anything but `base` or `detail`.
    pub fn from_query(level: Option<&str>) -> Result<Level, WireError> {
        match level {
            None | Some("base") => Ok(Level::Base),
            Some("detail") => Ok(Level::Detail),
            Some(other) => Err(WireError::new(
                "query",
                "level",
                format!("{other:?}, expected base or detail"),
            )),
        }
    }
}

impl From<Level> for v1::Level {
    fn from(level: Level) -> Self {
        match level {
            Level::Base => v1::Level::Base,
            Level::Detail => v1::Level::Detail,
        }
    }
}

/// What a mesh stream's first message says about its frames (see `Topology` in
/// `crease.proto`).
#[derive(Clone, Copy, Debug)]
pub struct TopologyParts<'a> {
    /// The model's name.
    pub model: &'a str,
    /// The stream's level.
    pub level: Level,
    /// Vertices per frame.
    pub vertex_count: usize,
    /// Triangles of the mesh.
    pub triangle_count: usize,
    /// The meshopt-encoded index buffer.
    pub indices: &'a [u8],
    /// The frames' quantisation box.
    pub qbox: &'a crease_core::codec::QuantBox,
    /// Streamed vertex `i` is model vertex `vertex_order[i]`; empty: the model's order.
    pub vertex_order: &'a [u32],
}

/// The first message of a mesh stream.
pub fn topology_message(t: TopologyParts<'_>) -> v1::MeshFrame {
    v1::MeshFrame {
        body: Some(v1::mesh_frame::Body::Topology(v1::Topology {
            model: t.model.to_owned(),
            level: v1::Level::from(t.level) as i32,
            vertex_count: t.vertex_count as u32,
            triangle_count: t.triangle_count as u32,
            indices: t.indices.to_vec(),
            quantization: Some(box3(t.qbox.min(), t.qbox.max())),
            vertex_order: t.vertex_order.to_vec(),
            bits: u32::from(t.qbox.bits()),
        })),
    }
}

/// One encoded mesh frame of a stream: `data` is shared, not copied.
pub fn frame_message(
    seq: u64,
    capture_time_us: i64,
    server_latency_us: u32,
    skipped: u32,
    data: Bytes,
) -> v1::MeshFrame {
    v1::MeshFrame {
        body: Some(v1::mesh_frame::Body::Frame(v1::Frame {
            seq,
            capture_time_us,
            server_latency_us,
            data,
            skipped,
        })),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(positions: Vec<f32>, valid: Vec<u8>) -> v1::ControlFrame {
        v1::ControlFrame {
            room: "r".into(),
            seq: 1,
            capture_time_us: 0,
            positions,
            valid,
        }
    }

    #[test]
    fn mask_round_trips_and_empty_means_all_valid() {
        let valid = [
            true, false, true, true, false, false, false, false, true, false,
        ];
        let mut mask = Vec::new();
        encode_valid_mask(&valid, &mut mask);
        assert_eq!(mask, [0b0000_1101, 0b0000_0001]);
        for (i, &v) in valid.iter().enumerate() {
            assert_eq!(valid_bit(&mask, i), v, "bit {i}");
        }
        assert!((0..20).all(|i| valid_bit(&[], i)));
    }

    #[test]
    fn control_frames_are_read_and_errors_name_the_field() {
        let mut p = [Vec3::ZERO; 2];
        let mut v = [false; 2];
        let f = frame(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], vec![]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(0));
        assert_eq!(p, [Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]);
        assert_eq!(v, [true, true]);
        // An occluded point may carry NaN.
        let f = frame(vec![f32::NAN, 0.0, 0.0, 4.0, 5.0, 6.0], vec![0b10]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(1));
        assert_eq!(v, [false, true]);
        // Errors name the field, and leave the buffers alone.
        let f = frame(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], vec![0b11]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(0));
        let before = (p, v);
        let e = read_control_frame(&frame(vec![1.0; 5], vec![]), &mut p, &mut v).unwrap_err();
        assert_eq!(e.field, "positions");
        assert!(e.message.contains("5 values, expected 6"), "{e}");
        assert!(
            e.to_string()
                .starts_with("ControlFrame.positions: 5 values, expected 6"),
            "{e}"
        );
        let e = read_control_frame(
            &frame(vec![0.0, 0.0, 0.0, 1.0, f32::INFINITY, 0.0], vec![]),
            &mut p,
            &mut v,
        )
        .unwrap_err();
        assert_eq!(e.field, "positions[1]");
        let e = read_control_frame(&frame(vec![0.0; 6], vec![1, 1]), &mut p, &mut v).unwrap_err();
        assert_eq!(e.field, "valid");
        assert_eq!((p, v), before);
        let status: tonic::Status = e.into();
        assert_eq!(status.code(), tonic::Code::InvalidArgument);
        assert!(status.message().starts_with("ControlFrame.valid: 2 bytes"));
    }

    #[test]
    fn control_frames_for_the_wire_read_back() {
        let points = [
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::NAN,
            Vec3::new(-1.0, 0.5, 9.0),
        ];
        let f = control_frame("r", 7, 11, &points, &[true, false, true]);
        assert_eq!((f.room.as_str(), f.seq, f.capture_time_us), ("r", 7, 11));
        assert_eq!(f.positions, [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, -1.0, 0.5, 9.0]);
        let (mut p, mut v) = ([Vec3::ZERO; 3], [true; 3]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(1));
        assert_eq!(v, [true, false, true]);
        assert_eq!((p[0], p[2]), (points[0], points[2]));
        // All valid: no mask at all.
        assert!(
            control_frame("r", 0, 0, &points[..1], &[true])
                .valid
                .is_empty()
        );
    }

    #[test]
    fn topology_round_trips_through_a_vertex_order() {
        // Two triangles on four vertices, streamed in the order [2, 0, 3, 1].
        let model_tris = [[0u32, 1, 2], [2, 1, 3]];
        let order = vec![2u32, 0, 3, 1];
        let mut inverse = [0u32; 4];
        for (i, &m) in order.iter().enumerate() {
            inverse[m as usize] = i as u32;
        }
        let streamed: Vec<[u32; 3]> = model_tris
            .iter()
            .map(|t| t.map(|v| inverse[v as usize]))
            .collect();
        let mut indices = Vec::new();
        crease_core::codec::encode_indices(&streamed, 4, &mut indices).unwrap();
        let mut topo = v1::Topology {
            vertex_count: 4,
            triangle_count: 2,
            indices,
            vertex_order: order,
            bits: 12,
            ..Default::default()
        };
        let t = read_topology(&topo).unwrap();
        let canonical = |t: &[u32; 3]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let got: Vec<_> = t.model_triangles().iter().map(canonical).collect();
        let want: Vec<_> = model_tris.iter().map(canonical).collect();
        assert_eq!(got, want);
        // Positions streamed in order come back in model order.
        let model_pos: Vec<Vec3> = (0..4).map(|i| Vec3::splat(i as f32)).collect();
        let streamed_pos: Vec<Vec3> = t.order.iter().map(|&m| model_pos[m as usize]).collect();
        let mut back = Vec::new();
        t.to_model_order(&streamed_pos, &mut back);
        assert_eq!(back, model_pos);
        // Bad orders name the field.
        topo.vertex_order = vec![2, 0, 2, 1];
        let e = read_topology(&topo).unwrap_err();
        assert_eq!(e.field, "vertex_order[2]");
        topo.vertex_order = vec![0, 1, 2];
        assert_eq!(read_topology(&topo).unwrap_err().field, "vertex_order");
        topo.vertex_order = vec![0, 1, 2, 9];
        assert_eq!(read_topology(&topo).unwrap_err().field, "vertex_order[3]");
        topo.indices = vec![1, 2, 3];
        assert_eq!(read_topology(&topo).unwrap_err().field, "indices");
    }

    #[test]
    fn levels_convert_both_ways_and_bad_ones_name_the_field() {
        assert_eq!(Level::from_wire("SubscribeRequest", 0), Ok(Level::Base));
        assert_eq!(Level::from_wire("SubscribeRequest", 1), Ok(Level::Base));
        assert_eq!(Level::from_wire("SubscribeRequest", 2), Ok(Level::Detail));
        let e = Level::from_wire("SynthesizeRequest", 7).unwrap_err();
        assert_eq!(
            e.to_string(),
            "SynthesizeRequest.level: 7 is not a Level (0 unspecified, 1 base, 2 detail)"
        );
        // The wire integers are the proto's: 1 base, 2 detail.
        assert_eq!(v1::Level::from(Level::Base) as i32, 1);
        assert_eq!(v1::Level::from(Level::Detail) as i32, 2);
        for l in Level::ALL {
            assert_eq!(Level::from_wire("X", v1::Level::from(l) as i32), Ok(l));
        }
        assert_eq!(Level::from_query(None), Ok(Level::Base));
        assert_eq!(Level::from_query(Some("base")), Ok(Level::Base));
        assert_eq!(Level::from_query(Some("detail")), Ok(Level::Detail));
        let e = Level::from_query(Some("Detail")).unwrap_err();
        assert_eq!(e.field, "level");
        assert!(e.message.contains("expected base or detail"), "{e}");
    }
}
