//! What the server's end-to-end tests share (and `demo/tests/cluster.rs`, through `#[path]`):
//! a model trained in-process on a bending tube (with a fixed detail layer on request), the
//! in-process prediction a decoded frame is checked against, control frames, and small HTTP
//! and metrics helpers.
#![allow(dead_code, clippy::unwrap_used)] // each test binary uses some of these

pub(crate) mod palette_check;

use std::sync::Arc;

use crease_core::codec::FrameDecoder;
use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_proto::v1;
use crease_train::bones::FitOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use tonic::Request;

pub(crate) const RINGS: usize = 8;
pub(crate) const AROUND: usize = 6;

pub(crate) fn tube() -> Mesh {
    let mut positions = Vec::new();
    for r in 0..RINGS {
        for a in 0..AROUND {
            let phi = std::f32::consts::TAU * a as f32 / AROUND as f32;
            positions.push(Vec3::new(phi.cos(), phi.sin(), r as f32));
        }
    }
    let mut triangles = Vec::new();
    for r in 0..RINGS - 1 {
        for a in 0..AROUND {
            let i0 = (r * AROUND + a) as u32;
            let i1 = (r * AROUND + (a + 1) % AROUND) as u32;
            let (j0, j1) = (i0 + AROUND as u32, i1 + AROUND as u32);
            triangles.push([i0, i1, j1]);
            triangles.push([i0, j1, j0]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

pub(crate) fn bent(rest: &Mesh, angle: f32) -> Vec<Vec3> {
    let q = Quat::from_rotation_x(angle);
    let pivot = Vec3::new(0.0, 0.0, 3.5);
    rest.positions
        .iter()
        .map(|&p| {
            if p.z > pivot.z {
                pivot + q * (p - pivot)
            } else {
                p
            }
        })
        .collect()
}

/// The tube curled: the ring at height `z` turned about the x axis through the origin by
/// `angle * z / (RINGS - 1)`, a bend whose rotation grows along the tube. Its fitted bones
/// blend over the rings (where [`bent`]'s are rigid segments), so LBS and DQS differ on it.
pub(crate) fn curled(rest: &Mesh, angle: f32) -> Vec<Vec3> {
    rest.positions
        .iter()
        .map(|&p| Quat::from_rotation_x(angle * p.z / (RINGS - 1) as f32) * p)
        .collect()
}

pub(crate) fn model() -> TrainedModel {
    model_of(bent)
}

/// The tube model trained on `deform` at 0 to 1.25 rad.
pub(crate) fn model_of(deform: fn(&Mesh, f32) -> Vec<Vec3>) -> TrainedModel {
    let rest = tube();
    let frames: Vec<Vec<Vec3>> = (0..6).map(|k| deform(&rest, 0.25 * k as f32)).collect();
    let refs: Vec<&[Vec3]> = frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = (0..frames.len()).map(|k| format!("f{k}")).collect();
    let options = TrainOptions {
        fit: FitOptions {
            bones: 4,
            max_influences: 2,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(vec![0, 45, 42]),
        ..TrainOptions::default()
    };
    pipeline::train(
        TrainInput {
            rest: &rest,
            frames: &refs,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .unwrap()
    .0
}

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

/// A server on free loopback ports hosting `model` as `name`, with admin token `admin` and no
/// publish rate limit (the tests publish as fast as the room predicts).
pub(crate) async fn serve_model(
    name: &str,
    model: &TrainedModel,
    admin: &str,
) -> crease_server::Running {
    let limits = crease_server::Limits {
        publish_hz: f64::INFINITY,
        ..crease_server::Limits::default()
    };
    serve_with_limits(name, model, admin, limits).await
}

/// [`serve_model`] under `limits`.
pub(crate) async fn serve_with_limits(
    name: &str,
    model: &TrainedModel,
    admin: &str,
    limits: crease_server::Limits,
) -> crease_server::Running {
    let registry = crease_server::registry::ModelRegistry::default();
    registry.insert(name, model.clone());
    let state = crease_server::AppState::new(
        registry,
        crease_server::Config {
            grpc: "127.0.0.1:0".parse().unwrap(),
            http: "127.0.0.1:0".parse().unwrap(),
            admin_token: Some(admin.into()),
            limits,
            ..crease_server::Config::default()
        },
    );
    crease_server::serve(state).await.unwrap()
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

/// The tube model with a fixed detail layer (one Loop level, a displacement per detail vertex
/// that does not depend on the controls): detail frames are checkable in-process.
pub(crate) fn model_with_detail() -> TrainedModel {
    use crease_core::mesh::subdivision::subdivided_vertex_count;
    use crease_core::model::DetailLayer;
    use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
    let mut model = model();
    let n = subdivided_vertex_count(&model.rig.rest, 1);
    let h: Vec<f32> = (0..n)
        .map(|i| 0.02 * ((i * 7919) % 13) as f32 / 13.0)
        .collect();
    model.detail = Some(DetailLayer {
        levels: 1,
        regressor: DetailRegressor::fixed(DetailInput::Controls, 3 * model.controls.len(), h),
    });
    model
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
