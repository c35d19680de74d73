//! crease-proto: the one wire contract, `proto/crease/v1/crease.proto` (package `crease.v1`),
//! compiled from `build.rs` with protox + tonic-prost-build (no system `protoc`), plus every
//! conversion between wire and core types. Conversions that can fail name the field and say
//! what was expected and what came ([`WireError`]); they become `InvalidArgument` statuses.
//!
//! - [`v1`]: the generated messages, the `Crease` client and server, and the encoded file
//!   descriptor set for gRPC reflection ([`v1::FILE_DESCRIPTOR_SET`]).
//! - [`read_control_frame`]: a `ControlFrame` into caller buffers (positions + validity), no
//!   allocation per frame.
//! - [`model_info`]: a trained model's public description.
//! - [`encode_valid_mask`] / [`valid_bit`]: the validity bitmask; [`control_frame`]: points
//!   and flags into a `ControlFrame`.
//! - [`read_topology`]: a mesh stream's `Topology` into triangles in model vertex ids and the
//!   streamed vertex order ([`StreamTopology::to_model_order`] puts decoded frames back).

use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_core::runtime::filter::OneEuroParams;

/// The generated `crease.v1` package.
#[allow(missing_docs, clippy::all, missing_debug_implementations)]
pub mod v1 {
    tonic::include_proto!("crease.v1");

    /// The encoded `FileDescriptorSet` of `crease.proto`, for server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("crease_descriptor");
}

/// A wire message that does not fit the model: the field and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct WireError {
    /// The offending field, e.g. `positions[7]` or `valid`.
    pub field: String,
    /// What was wrong: expected vs got.
    pub message: String,
}

impl WireError {
    fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
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
        .map_err(|e| WireError::new("indices", e.to_string()))?;
    if !t.vertex_order.is_empty() {
        if t.vertex_order.len() != n {
            return Err(WireError::new(
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
                WireError::new(format!("vertex_order[{i}]"), format!("{v}, expected < {n}"))
            })?;
            if std::mem::replace(slot, true) {
                return Err(WireError::new(
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
        assert!(status.message().starts_with("valid: 2 bytes"));
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
