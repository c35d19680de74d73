//! What the server's end-to-end tests share (and `demo/tests/cluster.rs`, through `#[path]`):
//! crease-testkit's tube model and in-process server (below), the in-process prediction a
//! decoded frame is checked against, control frames, and small HTTP and metrics helpers.
#![allow(dead_code)] // each test binary uses some of these

pub(crate) mod palette_check;

// crease-testkit's model and server, compiled in by path: the kit depends on crease-server, so
// the server's own tests cannot take it as a dev-dependency (ARCHITECTURE.md's rule); both
// files name only other crates for this reason.
#[allow(unreachable_pub)]
#[path = "../../../testkit/src/model.rs"]
mod kit_model;
#[allow(unreachable_pub)]
#[path = "../../../testkit/src/server.rs"]
mod kit_server;

#[allow(unused_imports)] // each test binary uses some of these
pub(crate) use kit_model::{AROUND, RINGS, bent, curled, model, model_of, model_with_detail, tube};
#[allow(unused_imports)] // each test binary uses some of these
pub(crate) use kit_server::{Served, serve_config, serve_model, serve_models, unthrottled};

use std::sync::Arc;

use crease_core::codec::FrameDecoder;
use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_proto::v1;
use tonic::Request;

/// A plain HTTP/1.1 GET: status code and body.
pub(crate) async fn http_get(addr: std::net::SocketAddr, path: &str) -> (u16, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(
        format!("GET {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n").as_bytes(),
    )
    .await
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).await.unwrap();
    let status = text[9..12].parse().unwrap();
    let body = text
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_owned();
    (status, body)
}

/// The value of a metric line `name value` in a Prometheus exposition.
pub(crate) fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|r| r.strip_prefix(' ')))
        .unwrap_or_else(|| panic!("{name} missing from:\n{text}"))
        .trim()
        .parse()
        .unwrap()
}

/// The in-process prediction of `frame` on a fresh context.
pub(crate) fn predicted(model: &TrainedModel, frame: &v1::ControlFrame) -> Vec<Vec3> {
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    let mut ctx = predictor.new_context();
    let c: Vec<Vec3> = frame
        .positions
        .chunks(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect();
    predictor.predict(&mut ctx, &c, None).unwrap().to_vec()
}

/// Decodes `data` with `decoder` and checks it, put back in model order through `topology`,
/// against `want` within the frame's quantisation bound. Returns the frame's bits.
pub(crate) fn check_decoded(
    decoder: &mut FrameDecoder,
    topology: &crease_proto::StreamTopology,
    data: &[u8],
    want: &[Vec3],
) -> u8 {
    let header = decoder.decode(data).unwrap();
    let (mut streamed, mut got) = (Vec::new(), Vec::new());
    decoder.positions(&mut streamed);
    topology.to_model_order(&streamed, &mut got);
    let bound = header.qbox.error_bound();
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let d = (*g - *w).abs();
        assert!(
            d.cmple(bound * 1.001 + 1e-6).all(),
            "vertex {i}: {g} vs {w} (bound {bound})"
        );
    }
    header.qbox.bits()
}

pub(crate) fn authed<T>(msg: T, token: &str) -> Request<T> {
    let mut r = Request::new(msg);
    r.metadata_mut()
        .insert("authorization", format!("Bearer {token}").parse().unwrap());
    r
}

pub(crate) fn control_frame(
    model: &TrainedModel,
    room: &str,
    seq: u64,
    angle: f32,
) -> v1::ControlFrame {
    control_frame_of(bent, model, room, seq, angle)
}

/// [`control_frame`] of the tube deformed by `deform`.
pub(crate) fn control_frame_of(
    deform: fn(&Mesh, f32) -> Vec<Vec3>,
    model: &TrainedModel,
    room: &str,
    seq: u64,
    angle: f32,
) -> v1::ControlFrame {
    let p = deform(&model.rig.rest, angle);
    v1::ControlFrame {
        room: room.into(),
        seq,
        capture_time_us: 0,
        positions: model
            .controls
            .iter()
            .flat_map(|c| p[c.vertex as usize].to_array())
            .collect(),
        valid: Vec::new(),
        ..Default::default()
    }
}

/// A WebSocket on `url`, from the local address `from` (any loopback address: the server counts
/// per client address), offering the publish `token` in `Sec-WebSocket-Protocol` when given.
#[allow(dead_code)] // not every test binary uses it
pub(crate) async fn ws_connect(
    url: &str,
    token: Option<&str>,
    from: std::net::IpAddr,
) -> Result<
    (
        tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>,
        tokio_tungstenite::tungstenite::handshake::client::Response,
    ),
    tokio_tungstenite::tungstenite::Error,
> {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
    let mut request = url.into_client_request().unwrap();
    if let Some(token) = token {
        let protocols = format!(
            "{}, {}",
            crease_server::ws::PROTOCOL,
            crease_server::ws::token_protocol(token)
        );
        request
            .headers_mut()
            .insert("sec-websocket-protocol", protocols.parse().unwrap());
    }
    let host = request.uri().authority().unwrap().as_str().to_owned();
    let socket = tcp_from(from, host.parse().unwrap()).await;
    tokio_tungstenite::client_async(request, socket).await
}

/// A TCP connection to `to` from the local address `from`.
#[allow(dead_code)] // not every test binary uses it
pub(crate) async fn tcp_from(
    from: std::net::IpAddr,
    to: std::net::SocketAddr,
) -> tokio::net::TcpStream {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(std::net::SocketAddr::new(from, 0)).unwrap();
    socket.connect(to).await.unwrap()
}
