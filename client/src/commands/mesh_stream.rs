//! Reading mesh streams, the one way every command does it: a subscription to a room
//! ([`subscribe`]: the `Subscribe` RPC, whose first message is the topology) and the decoding
//! of its frames ([`MeshReader`]: the codec's [`FrameDecoder`] on the stream's topology,
//! positions put back in the model's vertex order). `crease watch`, `stream --check` and
//! `bench-net` read subscriptions; `synth --server` reads `Synthesize` answers, which have the
//! same shape.

use anyhow::{Context, bail};
use crease_core::codec::{CodecError, FrameDecoder, FrameHeader};
use crease_core::glam::Vec3;
use crease_proto::v1::crease_client::CreaseClient;
use crease_proto::{StreamTopology, read_topology, v1};
use tonic::transport::Channel;

/// Decodes the frames of one stream: its topology (vertex count, spatial vertex order), the
/// codec state between frames, and a buffer of the last frame's positions in streamed order.
#[derive(Debug)]
pub struct MeshReader {
    topology: StreamTopology,
    decoder: FrameDecoder,
    streamed: Vec<Vec3>,
}

impl MeshReader {
    /// A reader of the frames that follow `topology`.
    ///
    /// # Errors
    /// A topology message that does not decode (the error names its field).
    pub fn new(topology: &v1::Topology) -> anyhow::Result<MeshReader> {
        let topology = read_topology(topology).context("reading the topology")?;
        let decoder = FrameDecoder::new(topology.vertex_count);
        Ok(MeshReader {
            topology,
            decoder,
            streamed: Vec::new(),
        })
    }

    /// The stream's topology.
    pub fn topology(&self) -> &StreamTopology {
        &self.topology
    }

    /// The codec state: the last frame's quantised lanes, its header.
    pub fn decoder(&self) -> &FrameDecoder {
        &self.decoder
    }

    /// Decodes one codec frame (a keyframe, or a delta on the frames before it).
    ///
    /// # Errors
    /// The codec's, for a frame that is not valid on this stream.
    pub fn decode(&mut self, data: &[u8]) -> Result<FrameHeader, CodecError> {
        self.decoder.decode(data)
    }

    /// The last decoded frame's positions in streamed (spatial) order.
    pub fn streamed(&mut self) -> &[Vec3] {
        self.decoder.positions(&mut self.streamed);
        &self.streamed
    }

    /// The last decoded frame's positions in the model's vertex order, into `out`.
    pub fn model_positions(&mut self, out: &mut Vec<Vec3>) {
        self.decoder.positions(&mut self.streamed);
        self.topology.to_model_order(&self.streamed, out);
    }
}

/// A room's mesh stream: the topology it started with, then its frames.
#[derive(Debug)]
pub struct Subscription {
    /// The stream's first message.
    pub topology: v1::Topology,
    stream: tonic::Streaming<v1::MeshFrame>,
}

impl Subscription {
    /// The next mesh frame (other messages are skipped); `None` when the stream ends.
    ///
    /// Cancel-safe (as `tonic::Streaming::message`), so it can race a deadline.
    ///
    /// # Errors
    /// The server's error status ending the stream.
    pub async fn next_frame(&mut self) -> anyhow::Result<Option<v1::Frame>> {
        while let Some(msg) = self.stream.message().await? {
            if let Some(v1::mesh_frame::Body::Frame(f)) = msg.body {
                return Ok(Some(f));
            }
        }
        Ok(None)
    }

    /// A reader of this stream's frames ([`MeshReader::new`] on its topology).
    ///
    /// # Errors
    /// A topology that does not decode.
    pub fn reader(&self) -> anyhow::Result<MeshReader> {
        MeshReader::new(&self.topology)
    }
}

/// Subscribes to `room` at `level` and reads the stream's first message, the topology.
///
/// # Errors
/// The server's refusal, or a stream that ends or starts with something else.
pub async fn subscribe(
    client: &mut CreaseClient<Channel>,
    room: &str,
    level: v1::Level,
) -> anyhow::Result<Subscription> {
    let mut stream = client
        .subscribe(v1::SubscribeRequest {
            room: room.to_owned(),
            level: level as i32,
        })
        .await
        .with_context(|| format!("subscribing to room {room:?}"))?
        .into_inner();
    let first = stream
        .message()
        .await?
        .context("the server closed the stream before the topology")?;
    let Some(v1::mesh_frame::Body::Topology(topology)) = first.body else {
        bail!("room {room:?}: the first message is not the topology");
    };
    Ok(Subscription { topology, stream })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crease_core::codec::{FrameEncoder, QuantBox, encode_indices};

    #[test]
    fn frames_decode_into_model_order_and_a_bad_topology_is_named() {
        // Streamed order [2, 0, 3, 1]: streamed vertex i is model vertex order[i].
        let order = [2u32, 0, 3, 1];
        let mut indices = Vec::new();
        encode_indices(&[[1, 3, 0], [0, 3, 2]], 4, &mut indices).unwrap();
        let topology = v1::Topology {
            vertex_count: 4,
            triangle_count: 2,
            indices,
            vertex_order: order.to_vec(),
            bits: 16,
            ..Default::default()
        };
        let mut reader = MeshReader::new(&topology).unwrap();
        assert_eq!(reader.topology().vertex_count, 4);
        let model = [
            Vec3::new(-1.0, 0.5, 0.0),
            Vec3::new(1.0, 0.25, -0.5),
            Vec3::new(0.25, 1.5, 0.75),
            Vec3::new(0.5, -1.75, 0.0),
        ];
        let streamed: Vec<Vec3> = order.iter().map(|&m| model[m as usize]).collect();
        let qbox = QuantBox::from_bounds(Vec3::splat(-2.0), Vec3::splat(2.0), 0.0, 16).unwrap();
        let mut encoder = FrameEncoder::new(4, qbox, 1).unwrap();
        let mut data = Vec::new();
        encoder.encode(&streamed, None, &mut data).unwrap();
        reader.decode(&data).unwrap();
        // 16 bits over a box of side 4: half a step is 4 / 65535 / 2.
        let bound = 2.0 / 65535.0 + 1e-6;
        for (got, want) in reader.streamed().iter().zip(&streamed) {
            assert!(
                (*got - *want).abs().max_element() <= bound,
                "{got} vs {want}"
            );
        }
        let mut out = Vec::new();
        reader.model_positions(&mut out);
        for (v, (got, want)) in out.iter().zip(model).enumerate() {
            assert!(
                (*got - want).abs().max_element() <= bound,
                "vertex {v}: {got} vs {want}"
            );
        }
        // A truncated frame is the codec's error, not a panic.
        assert!(reader.decode(&data[..data.len() / 2]).is_err());
        let bad = v1::Topology {
            vertex_order: vec![0, 0, 1, 2],
            ..topology
        };
        let e = MeshReader::new(&bad).unwrap_err();
        let e = format!("{e:#}");
        assert!(
            e.contains("reading the topology") && e.contains("vertex_order[1]"),
            "{e}"
        );
    }
}
