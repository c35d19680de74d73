//! The mesh stream a subscriber receives: its topology message (the streamed vertex order, the
//! meshopt-encoded triangles, the quantisation box) and its frame messages, built by the
//! server; and the topology read back by clients ([`StreamTopology`]), with the scatter from the
//! streamed order back to model vertex ids.

use crease_core::glam::Vec3;
use prost::bytes::Bytes;

use crate::convert::{Level, box3};
use crate::errors::WireError;
use crate::v1;

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
            // A one-actor room's stream (issue 38's rooms of actors name theirs).
            actor: String::new(),
            actor_index: 0,
            actor_count: 0,
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
            actors: Vec::new(),
        })),
    }
}

/// Names the actor of a stream's first message (a `Topology` or a `PaletteTopology`) in a room
/// of several actors (issue 38): its name, its index (`ActorFrame.actor`) and how many first
/// messages the stream sends. Other messages are left as they are.
pub fn name_actor(message: &mut v1::MeshFrame, actor: &str, index: usize, count: usize) {
    let (name, i, n) = match &mut message.body {
        Some(v1::mesh_frame::Body::Topology(t)) => {
            (&mut t.actor, &mut t.actor_index, &mut t.actor_count)
        }
        Some(v1::mesh_frame::Body::PaletteTopology(p)) => {
            (&mut p.actor, &mut p.actor_index, &mut p.actor_count)
        }
        _ => return,
    };
    actor.clone_into(name);
    *i = index as u32;
    *n = count as u32;
}

/// Actor `index`'s part of a room of several actors' frame: its encoded frame (shared, not
/// copied), and whether it `held` its pose (missing from the control frame).
pub fn actor_frame(
    index: usize,
    data: Bytes,
    held: bool,
    placement: Option<ActorPlace>,
) -> v1::ActorFrame {
    v1::ActorFrame {
        actor: index as u32,
        data,
        held,
        placement: placement.map(|p| p.to_wire()),
    }
}

/// Where an actor's mesh sits in its performer's frame (`v1::ActorPlacement`, issue 38):
/// `x -> scale * rotation * x + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActorPlace {
    /// Uniform scale.
    pub scale: f32,
    /// Rotation.
    pub rotation: crease_core::glam::Quat,
    /// Translation.
    pub translation: crease_core::glam::Vec3,
}

impl ActorPlace {
    /// Maps a point of the actor's model frame.
    pub fn apply(&self, p: crease_core::glam::Vec3) -> crease_core::glam::Vec3 {
        self.scale * (self.rotation * p) + self.translation
    }

    /// The wire form.
    pub fn to_wire(&self) -> v1::ActorPlacement {
        let q = self.rotation;
        v1::ActorPlacement {
            scale: self.scale,
            translation: Some(self.translation.into()),
            rotation: Some(v1::Quat {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            }),
        }
    }

    /// Reads the wire form: `None` for a scale that is not positive and finite, a rotation
    /// that is not a unit quaternion (within 1e-3), or anything not finite.
    pub fn from_wire(p: &v1::ActorPlacement) -> Option<ActorPlace> {
        let t = p.translation.as_ref().map_or([0.0; 3], |v| [v.x, v.y, v.z]);
        let q = p.rotation.as_ref()?;
        let rotation = crease_core::glam::Quat::from_xyzw(q.x, q.y, q.z, q.w);
        let place = ActorPlace {
            scale: p.scale,
            rotation,
            translation: crease_core::glam::Vec3::from_array(t),
        };
        (p.scale.is_finite()
            && p.scale > 0.0
            && place.translation.is_finite()
            && rotation.is_finite()
            && (rotation.length() - 1.0).abs() < 1e-3)
            .then_some(place)
    }
}

/// A room of several actors' frame: every actor's encoded frame of one instant (`data` shared,
/// not copied), in the room's actor order, under one sequence number and capture time.
pub fn actors_frame_message(
    seq: u64,
    capture_time_us: i64,
    server_latency_us: u32,
    skipped: u32,
    actors: Vec<v1::ActorFrame>,
) -> v1::MeshFrame {
    v1::MeshFrame {
        body: Some(v1::mesh_frame::Body::Frame(v1::Frame {
            seq,
            capture_time_us,
            server_latency_us,
            data: Bytes::new(),
            skipped,
            actors,
        })),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
