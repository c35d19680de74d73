//! Reading mesh streams, the one way every command does it: a subscription to a room
//! ([`subscribe`]: the `Subscribe` RPC, whose first message is the topology) and the decoding
//! of its frames ([`MeshReader`]: the codec's [`FrameDecoder`] on the stream's topology,
//! positions put back in the model's vertex order). A palette stream (issue 18) starts with a
//! palette header instead and its frames are skinned and detailed on the CPU
//! ([`PaletteReader`], `core::codec::palette`'s reference decoder); [`StreamReader`] reads
//! either. `crease watch`, `stream --check` and
//! `bench-net` read subscriptions; `synth --server` reads `Synthesize` answers, which have the
//! same shape. A subscription comes over gRPC ([`subscribe_encoded`]) or over the WebSocket
//! endpoint browsers use ([`subscribe_ws`]: each binary message one `MeshFrame`, the same
//! messages in the same order), and reads the same either way.

use anyhow::{Context, bail};
use crease_core::codec::palette::{PaletteFrame, PaletteSynth, read_palette_lanes};
use crease_core::codec::{CodecError, FrameDecoder, FrameHeader};
use crease_core::glam::Vec3;
use crease_proto::v1::crease_client::CreaseClient;
use crease_proto::{Encoding, StreamTopology, read_palette_topology, read_topology, v1};
use futures_util::StreamExt as _;
use prost::Message as _;
use tokio_tungstenite::tungstenite;
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

/// Decodes the frames of a palette stream on the CPU: its header's rest mesh, skin and detail
/// layer, and the last frame's bones.
#[derive(Debug)]
pub struct PaletteReader {
    synth: PaletteSynth,
    decoder: FrameDecoder,
    frame: PaletteFrame,
    bones: usize,
    xi: usize,
    vertex_count: usize,
    decoded: bool,
}

impl PaletteReader {
    /// A reader of the frames that follow the palette header `t`.
    ///
    /// # Errors
    /// A header that does not decode or hold together (the error names its field).
    pub fn new(t: &v1::PaletteTopology) -> anyhow::Result<PaletteReader> {
        let palette = read_palette_topology(t).context("reading the palette header")?;
        let (bones, xi, vertex_count) = (
            palette.header.bones,
            palette.header.xi_len(),
            palette.header.vertex_count(),
        );
        Ok(PaletteReader {
            synth: PaletteSynth::new(palette.header).context("reading the palette header")?,
            decoder: FrameDecoder::new(crease_core::codec::palette::palette_vertex_count(
                bones, xi,
            )),
            frame: PaletteFrame::default(),
            bones,
            xi,
            vertex_count,
            decoded: false,
        })
    }

    /// Decodes one palette frame (a codec frame of lanes, keyframe or delta) and synthesises
    /// its mesh.
    ///
    /// # Errors
    /// The codec's or the palette's, for a frame that is not valid on this stream.
    pub fn decode(&mut self, data: &[u8]) -> anyhow::Result<()> {
        let header = self.decoder.decode(data)?;
        read_palette_lanes(
            self.decoder.lanes(),
            &header.qbox,
            self.bones,
            self.xi,
            &mut self.frame,
        )?;
        self.synth.synthesize(&self.frame)?;
        self.decoded = true;
        Ok(())
    }

    /// The last decoded frame.
    pub fn frame(&self) -> &PaletteFrame {
        &self.frame
    }

    /// The CPU decoder (its skinned base mesh, subdivided mesh, displacements).
    pub fn synth(&self) -> &PaletteSynth {
        &self.synth
    }

    /// Vertices of the drawn mesh.
    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }
}

/// Either kind of stream's reader, chosen by its first message.
#[derive(Debug)]
pub enum StreamReader {
    /// A vertex stream.
    Vertices(MeshReader),
    /// A palette stream.
    Palette(Box<PaletteReader>),
}

impl StreamReader {
    /// The reader for the stream whose first message is `first`.
    ///
    /// # Errors
    /// A first message that is neither a topology nor a palette header, or does not decode.
    pub fn new(first: &v1::MeshFrame) -> anyhow::Result<StreamReader> {
        match &first.body {
            Some(v1::mesh_frame::Body::Topology(t)) => {
                Ok(StreamReader::Vertices(MeshReader::new(t)?))
            }
            Some(v1::mesh_frame::Body::PaletteTopology(t)) => {
                Ok(StreamReader::Palette(Box::new(PaletteReader::new(t)?)))
            }
            _ => bail!("the stream's first message is neither a topology nor a palette header"),
        }
    }

    /// The stream's encoding.
    pub fn encoding(&self) -> Encoding {
        match self {
            StreamReader::Vertices(_) => Encoding::Vertices,
            StreamReader::Palette(_) => Encoding::Palette,
        }
    }

    /// Vertices per frame.
    pub fn vertex_count(&self) -> usize {
        match self {
            StreamReader::Vertices(r) => r.topology().vertex_count,
            StreamReader::Palette(r) => r.vertex_count(),
        }
    }

    /// The triangles in model vertex ids.
    pub fn model_triangles(&self) -> Vec<[u32; 3]> {
        match self {
            StreamReader::Vertices(r) => r.topology().model_triangles(),
            StreamReader::Palette(r) => r.synth().triangles().to_vec(),
        }
    }

    /// Decodes one frame's data.
    ///
    /// # Errors
    /// The codec's or the palette decoder's.
    pub fn decode(&mut self, data: &[u8]) -> anyhow::Result<()> {
        match self {
            StreamReader::Vertices(r) => r.decode(data).map(|_| ()).map_err(Into::into),
            StreamReader::Palette(r) => r.decode(data),
        }
    }

    /// The last decoded frame's positions in model vertex order, into `out` (empty before the
    /// first frame).
    pub fn model_positions(&mut self, out: &mut Vec<Vec3>) {
        match self {
            StreamReader::Vertices(r) => r.model_positions(out),
            StreamReader::Palette(r) => {
                out.clear();
                if r.decoded {
                    out.extend_from_slice(r.synth.output());
                }
            }
        }
    }
}

/// A room's mesh stream: the message it started with, then its frames.
#[derive(Debug)]
pub struct Subscription {
    /// The stream's first message: a topology, or a palette header (a room of several
    /// actors': the first actor's).
    pub first: v1::MeshFrame,
    /// A room of several actors (issue 38): every actor's first message, in the room's actor
    /// order (`ActorFrame.actor` indexes them); empty in a one-actor room.
    pub actors: Vec<v1::MeshFrame>,
    stream: Source,
}

/// A WebSocket to the server's `/ws/rooms/{id}` endpoint.
type WebSocket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Where a subscription's messages come from.
enum Source {
    /// The `Subscribe` RPC's response stream.
    Grpc(Box<tonic::Streaming<v1::MeshFrame>>),
    /// `GET /ws/rooms/{id}`: each binary message is one `MeshFrame`.
    WebSocket(Box<WebSocket>),
}

impl std::fmt::Debug for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Source::Grpc(_) => "Source::Grpc",
            Source::WebSocket(_) => "Source::WebSocket",
        })
    }
}

impl Source {
    /// The next message; `None` when the stream ends. Cancel-safe (both sources are).
    async fn message(&mut self) -> anyhow::Result<Option<v1::MeshFrame>> {
        match self {
            Source::Grpc(stream) => Ok(stream.message().await?),
            Source::WebSocket(ws) => loop {
                match ws.next().await {
                    None | Some(Ok(tungstenite::Message::Close(_))) => return Ok(None),
                    Some(Ok(tungstenite::Message::Binary(bytes))) => {
                        let msg = v1::MeshFrame::decode(bytes)
                            .context("a WebSocket message is not a crease.v1.MeshFrame")?;
                        return Ok(Some(msg));
                    }
                    // Text messages are acks of what this socket published (it publishes
                    // nothing); pings are answered by tungstenite.
                    Some(Ok(_)) => {}
                    Some(Err(e)) => return Err(anyhow::Error::new(e).context("the WebSocket")),
                }
            },
        }
    }
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

    /// A reader of this vertex stream's frames ([`MeshReader::new`] on its topology).
    ///
    /// # Errors
    /// A topology that does not decode, or a palette stream.
    pub fn reader(&self) -> anyhow::Result<MeshReader> {
        match &self.first.body {
            Some(v1::mesh_frame::Body::Topology(t)) => MeshReader::new(t),
            _ => bail!("not a vertex stream: the first message is not a topology"),
        }
    }

    /// A reader of this stream's frames, whatever its encoding.
    ///
    /// # Errors
    /// A first message that does not decode.
    pub fn stream_reader(&self) -> anyhow::Result<StreamReader> {
        StreamReader::new(&self.first)
    }

    /// A reader per actor of a room of several actors' vertex stream (one, of `first`, in a
    /// one-actor room): decode `ActorFrame.data` of actor `i` with reader `i`.
    ///
    /// # Errors
    /// A topology that does not decode, or a palette stream.
    pub fn readers(&self) -> anyhow::Result<Vec<MeshReader>> {
        if self.actors.is_empty() {
            return Ok(vec![self.reader()?]);
        }
        self.actors
            .iter()
            .map(|m| match &m.body {
                Some(v1::mesh_frame::Body::Topology(t)) => MeshReader::new(t),
                _ => bail!("not a vertex stream: an actor's first message is not a topology"),
            })
            .collect()
    }

    /// A reader per actor of this stream's frames, whatever its encoding (one, of `first`, in a
    /// one-actor room).
    ///
    /// # Errors
    /// A first message that does not decode.
    pub fn stream_readers(&self) -> anyhow::Result<Vec<StreamReader>> {
        if self.actors.is_empty() {
            return Ok(vec![self.stream_reader()?]);
        }
        self.actors.iter().map(StreamReader::new).collect()
    }

    /// The actors' names of a room of several actors (empty in a one-actor room).
    pub fn actor_names(&self) -> Vec<String> {
        self.actors
            .iter()
            .map(|m| match &m.body {
                Some(v1::mesh_frame::Body::Topology(t)) => t.actor.clone(),
                Some(v1::mesh_frame::Body::PaletteTopology(t)) => t.actor.clone(),
                _ => String::new(),
            })
            .collect()
    }

    /// Vertices per frame, as the stream's first message says.
    pub fn vertex_count(&self) -> usize {
        match &self.first.body {
            Some(v1::mesh_frame::Body::Topology(t)) => t.vertex_count as usize,
            Some(v1::mesh_frame::Body::PaletteTopology(t)) => t.vertex_count as usize,
            _ => 0,
        }
    }

    /// The model the stream's first message names.
    pub fn model(&self) -> &str {
        match &self.first.body {
            Some(v1::mesh_frame::Body::Topology(t)) => &t.model,
            Some(v1::mesh_frame::Body::PaletteTopology(t)) => &t.model,
            _ => "",
        }
    }
}

/// Subscribes to `room` at `level` (vertex frames) and reads the stream's first message, the
/// topology.
///
/// # Errors
/// The server's refusal, or a stream that ends or starts with something else.
pub async fn subscribe(
    client: &mut CreaseClient<Channel>,
    room: &str,
    level: v1::Level,
) -> anyhow::Result<Subscription> {
    subscribe_encoded(client, room, level, Encoding::Vertices).await
}

/// Subscribes to `room` at `level` in `encoding` and reads the stream's first message (a
/// topology, or a palette header).
///
/// # Errors
/// The server's refusal, or a stream that ends or starts with something else.
pub async fn subscribe_encoded(
    client: &mut CreaseClient<Channel>,
    room: &str,
    level: v1::Level,
    encoding: Encoding,
) -> anyhow::Result<Subscription> {
    let stream = client
        .subscribe(v1::SubscribeRequest {
            room: room.to_owned(),
            level: level as i32,
            encoding: v1::Encoding::from(encoding) as i32,
        })
        .await
        .with_context(|| format!("subscribing to room {room:?}"))?
        .into_inner();
    first_messages(Source::Grpc(Box::new(stream)), room, encoding).await
}

/// Subscribes to `room` at `level` in `encoding` over the WebSocket endpoint browsers use,
/// `ws://{http}/ws/rooms/{room}` (`http`: the server's HTTP address, `host:port`), and reads
/// the stream's first message as [`subscribe_encoded`] does.
///
/// # Errors
/// The server's refusal (its HTTP status and message), or a stream that ends or starts with
/// something else.
pub async fn subscribe_ws(
    http: &str,
    room: &str,
    level: v1::Level,
    encoding: Encoding,
) -> anyhow::Result<Subscription> {
    use tungstenite::client::IntoClientRequest as _;
    // `?level=` spells it as the domain level names it.
    let level = crease_proto::Level::from_wire("level", level as i32)
        .map_or("base", crease_proto::Level::name);
    let url = format!(
        "ws://{http}/ws/rooms/{room}?level={level}&encoding={}",
        encoding.name()
    );
    let mut request = url
        .as_str()
        .into_client_request()
        .with_context(|| format!("{url}: not a WebSocket URL"))?;
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        tungstenite::http::HeaderValue::from_static(crease_proto::WS_PROTOCOL),
    );
    let (ws, _) = match tokio_tungstenite::connect_async(request).await {
        Ok(done) => done,
        Err(tungstenite::Error::Http(response)) => {
            let body = response
                .body()
                .as_deref()
                .map(String::from_utf8_lossy)
                .unwrap_or_default();
            bail!(
                "{url}: the server refused the WebSocket ({}): {}",
                response.status(),
                body.trim()
            );
        }
        Err(e) => return Err(anyhow::Error::new(e).context(format!("{url}: connecting"))),
    };
    first_messages(Source::WebSocket(Box::new(ws)), room, encoding).await
}

/// Reads a new subscription's first message (and every actor's in a room of several actors).
async fn first_messages(
    mut stream: Source,
    room: &str,
    encoding: Encoding,
) -> anyhow::Result<Subscription> {
    let first = stream
        .message()
        .await?
        .context("the server closed the stream before its first message")?;
    let expected = match (&first.body, encoding) {
        (Some(v1::mesh_frame::Body::Topology(_)), Encoding::Vertices)
        | (Some(v1::mesh_frame::Body::PaletteTopology(_)), Encoding::Palette) => None,
        (_, Encoding::Vertices) => Some("the topology"),
        (_, Encoding::Palette) => Some("the palette header"),
    };
    if let Some(what) = expected {
        bail!("room {room:?}: the first message is not {what}");
    }
    // A room of several actors sends one first message per actor (each names its index and
    // how many there are).
    let count = match &first.body {
        Some(v1::mesh_frame::Body::Topology(t)) => t.actor_count,
        Some(v1::mesh_frame::Body::PaletteTopology(t)) => t.actor_count,
        _ => 0,
    };
    let mut actors = Vec::new();
    if count > 0 {
        actors.push(first.clone());
        for i in 1..count {
            let next = stream.message().await?.with_context(|| {
                format!("room {room:?}: the stream ended before actor {i}'s first message")
            })?;
            actors.push(next);
        }
    }
    Ok(Subscription {
        first,
        actors,
        stream,
    })
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
