//! Access and limits over real sockets (issue 21): the WebSocket publish token travels in
//! `Sec-WebSocket-Protocol` and is refused in the URL; a client address over its cap on
//! streams or connections is refused with a clear status while other addresses go on; an
//! oversized message is refused on gRPC and on the WebSocket and the room goes on.
//!
//! Other client addresses are other loopback addresses (127.0.0.2): the kernel routes all of
//! 127/8 to the loopback interface.

use std::net::{IpAddr, Ipv4Addr};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::Message;

use crease_core::model::TrainedModel;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_server::Limits;
use crease_server::admission::Caps;

use crate::common;
use common::*;

const ADMIN: &str = "admin-secret";
const ONE: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 1));
const TWO: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));

async fn serve(model: &TrainedModel, limits: Limits) -> Served {
    serve_model("tube", model, Some(ADMIN), limits).await
}

/// Opens room `r` and returns its publish token.
async fn open_room(client: &mut CreaseClient<tonic::transport::Channel>) -> String {
    client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "r".into(),
                model: "tube".into(),
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token
}

/// The next text message (an ack) on `ws`, as JSON.
async fn next_ack(
    ws: &mut tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>,
) -> serde_json::Value {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next())
            .await
            .expect("an ack within 10 s")
        {
            Some(Ok(Message::Text(t))) => return serde_json::from_str(&t).unwrap(),
            Some(Ok(_)) => {}
            other => panic!("the socket ended before an ack: {other:?}"),
        }
    }
}

/// Waits until `stream` delivers a frame of `seq` or later.
async fn frame_at_least(stream: &mut tonic::Streaming<v1::MeshFrame>, seq: u64) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        let msg = tokio::time::timeout_at(deadline, stream.message())
            .await
            .expect("a frame within 10 s")
            .unwrap()
            .expect("the stream goes on");
        if let Some(v1::mesh_frame::Body::Frame(f)) = msg.body
            && f.seq >= seq
        {
            return;
        }
    }
}

/// Publishes one frame over gRPC and returns its ack.
async fn publish_one(
    client: &mut CreaseClient<tonic::transport::Channel>,
    token: &str,
    frame: v1::ControlFrame,
) -> Result<v1::PublishAck, tonic::Status> {
    let mut acks = client
        .publish(authed(tokio_stream::iter(vec![frame]), token))
        .await?
        .into_inner();
    Ok(acks.message().await?.expect("an ack"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_publish_token_travels_in_the_subprotocol_and_is_refused_in_the_url() {
    let model = model();
    let running = serve(&model, Limits::default()).await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let token = open_room(&mut client).await;
    let url = format!("ws://{}/ws/rooms/r?subscribe=false", running.http);
    let json = |seq: u64| {
        let f = control_frame(&model, "", seq, 0.2);
        format!("{{\"seq\": {seq}, \"positions\": {:?}}}", f.positions)
    };

    // In the subprotocol: accepted, and the server selects crease.v1 (never echoes the token).
    let (mut ws, response) = ws_connect(&url, Some(&token), ONE).await.unwrap();
    let selected = response.headers().get("sec-websocket-protocol").unwrap();
    assert_eq!(selected, crease_server::ws::PROTOCOL);
    ws.send(Message::Text(json(1).into())).await.unwrap();
    let ack = next_ack(&mut ws).await;
    assert!(ack["error"].is_null(), "{ack}");
    assert_eq!(ack["seq"], 1);

    // A wrong token in the subprotocol: the frame is refused (PERMISSION_DENIED), socket open.
    let (mut ws, _) = ws_connect(&url, Some("not-the-token"), ONE).await.unwrap();
    ws.send(Message::Text(json(2).into())).await.unwrap();
    let ack = next_ack(&mut ws).await;
    assert_eq!(ack["error"]["code"], 7, "{ack}");

    // In the URL: refused before the upgrade, with the way to send it instead.
    let in_url = format!("{url}&token={token}");
    let err = ws_connect(&in_url, None, ONE).await.unwrap_err();
    let tokio_tungstenite::tungstenite::Error::Http(response) = &err else {
        panic!("a token in the URL: expected an HTTP refusal, got {err}");
    };
    assert_eq!(response.status(), 400);
    let body = String::from_utf8_lossy(response.body().as_deref().unwrap_or_default());
    assert!(body.contains("Sec-WebSocket-Protocol"), "{body}");
    assert!(
        !body.contains(&token),
        "the refusal repeats the token: {body}"
    );

    // A token entry that is not base64url, or offered without crease.v1: 400, naming why.
    use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
    for (protocols, want) in [
        ("crease.v1, crease.token.%%%", "base64url"),
        (&*crease_server::ws::token_protocol(&token), "crease.v1"),
    ] {
        let mut request = url.as_str().into_client_request().unwrap();
        request
            .headers_mut()
            .insert("sec-websocket-protocol", protocols.parse().unwrap());
        let socket = tcp_from(ONE, running.http).await;
        let err = tokio_tungstenite::client_async(request, socket)
            .await
            .unwrap_err();
        let tokio_tungstenite::tungstenite::Error::Http(response) = &err else {
            panic!("{protocols}: expected an HTTP refusal, got {err}");
        };
        assert_eq!(response.status(), 400, "{protocols}");
        let body = String::from_utf8_lossy(response.body().as_deref().unwrap_or_default());
        assert!(body.contains(want), "{protocols}: {body}");
    }
    running.shutdown(Duration::from_secs(2)).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_over_its_stream_cap_is_refused_while_others_go_on() {
    let model = model();
    let running = serve(
        &model,
        Limits {
            publish_hz: f64::INFINITY,
            streams: Caps {
                per_address: 2,
                total: 3,
            },
            ..Limits::default()
        },
    )
    .await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let token = open_room(&mut client).await;
    let req = || v1::SubscribeRequest {
        room: "r".into(),
        ..Default::default()
    };
    let ws_url = format!("ws://{}/ws/rooms/r", running.http);

    // 127.0.0.1 holds two streams: one gRPC subscriber, one WebSocket viewer.
    let mut first = client.subscribe(req()).await.unwrap().into_inner();
    let (_viewer, _) = ws_connect(&ws_url, None, ONE).await.unwrap();
    // Its third is refused on both transports, naming the address and the cap.
    let err = client.subscribe(req()).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::ResourceExhausted, "{err}");
    assert!(
        err.message().contains("too many streams from 127.0.0.1")
            && err.message().contains("it holds 2"),
        "{}",
        err.message()
    );
    let err = ws_connect(&ws_url, None, ONE).await.unwrap_err();
    let tokio_tungstenite::tungstenite::Error::Http(response) = &err else {
        panic!("expected an HTTP refusal, got {err}");
    };
    assert_eq!(response.status(), 429);
    // A publish stream is a stream too.
    let err = publish_one(&mut client, &token, control_frame(&model, "r", 1, 0.1))
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::ResourceExhausted, "{err}");

    // Another address goes on: it publishes over the WebSocket (the third stream, the total),
    // and 127.0.0.1's subscriber gets the frame.
    let (mut publisher, _) = ws_connect(&format!("{ws_url}?subscribe=false"), Some(&token), TWO)
        .await
        .unwrap();
    let f = control_frame(&model, "", 7, 0.3);
    let text = format!("{{\"seq\": 7, \"positions\": {:?}}}", f.positions);
    publisher.send(Message::Text(text.into())).await.unwrap();
    assert!(next_ack(&mut publisher).await["error"].is_null());
    frame_at_least(&mut first, 7).await;
    // Now the total is reached: 127.0.0.2's second stream is refused for the total.
    let err = ws_connect(&ws_url, None, TWO).await.unwrap_err();
    let tokio_tungstenite::tungstenite::Error::Http(response) = &err else {
        panic!("expected an HTTP refusal, got {err}");
    };
    assert_eq!(response.status(), 429);
    let body = String::from_utf8_lossy(response.body().as_deref().unwrap_or_default());
    assert!(body.contains("the server's cap"), "{body}");

    // A slot comes back when its stream ends.
    drop(first);
    let mut again = None;
    for _ in 0..100 {
        if let Ok(s) = client.subscribe(req()).await {
            again = Some(s);
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(
        again.is_some(),
        "the slot of an ended stream was not given back"
    );
    let (_, metrics) = http_get(running.http, "/metrics").await;
    let refused = metrics
        .lines()
        .find(|l| l.starts_with("crease_admission_refused_total{kind=\"streams\"}"))
        .unwrap_or_else(|| panic!("no streams refusal metric in\n{metrics}"));
    let refused: f64 = refused.rsplit(' ').next().unwrap().parse().unwrap();
    assert!(refused >= 4.0, "{refused}");
    running.shutdown(Duration::from_secs(2)).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_over_its_connection_cap_is_refused_while_others_go_on() {
    let model = model();
    let running = serve(
        &model,
        Limits {
            connections: Caps {
                per_address: 3,
                total: 16,
            },
            ..Limits::default()
        },
    )
    .await;
    // 127.0.0.1 holds three idle connections (two HTTP, one gRPC: they count together).
    let _held = [
        tcp_from(ONE, running.http).await,
        tcp_from(ONE, running.http).await,
        tcp_from(ONE, running.grpc).await,
    ];
    // Its fourth HTTP connection gets a 503 naming the cap, then is closed.
    let mut extra = tcp_from(ONE, running.http).await;
    extra
        .write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\n\r\n")
        .await
        .ok();
    let mut reply = String::new();
    tokio::time::timeout(Duration::from_secs(5), extra.read_to_string(&mut reply))
        .await
        .expect("the refused connection is closed")
        .ok();
    assert!(reply.starts_with("HTTP/1.1 503"), "{reply:?}");
    assert!(
        reply.contains("too many connections from 127.0.0.1"),
        "{reply}"
    );
    // Its fourth gRPC connection is closed at once.
    let mut extra = tcp_from(ONE, running.grpc).await;
    let mut buf = [0u8; 16];
    let n = tokio::time::timeout(Duration::from_secs(5), extra.read(&mut buf))
        .await
        .expect("the refused connection is closed")
        .unwrap_or(0);
    assert_eq!(n, 0, "a refused gRPC connection is closed without a reply");
    // Another address is served.
    let mut other = tcp_from(TWO, running.http).await;
    other
        .write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut reply = String::new();
    other.read_to_string(&mut reply).await.unwrap();
    assert!(reply.starts_with("HTTP/1.1 200"), "{reply}");
    // When 127.0.0.1 closes one, it may connect again.
    drop(_held);
    let mut served = false;
    for _ in 0..100 {
        let mut again = tcp_from(ONE, running.http).await;
        again
            .write_all(b"GET /healthz HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n")
            .await
            .ok();
        let mut reply = String::new();
        again.read_to_string(&mut reply).await.ok();
        if reply.starts_with("HTTP/1.1 200") {
            served = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(served, "closed connections were not given back");
    running.shutdown(Duration::from_secs(2)).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversized_messages_are_refused_on_both_transports_and_the_room_goes_on() {
    let model = model();
    const LIMIT: usize = 64 << 10;
    let running = serve(
        &model,
        Limits {
            message_bytes: LIMIT,
            publish_hz: f64::INFINITY,
            ..Limits::default()
        },
    )
    .await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let token = open_room(&mut client).await;
    let mut viewer = client
        .subscribe(v1::SubscribeRequest {
            room: "r".into(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut huge = control_frame(&model, "r", 1, 0.1);
    huge.positions = vec![0.5; LIMIT]; // 4 bytes each: four times the limit
    assert!(huge.encoded_len() > LIMIT);

    // gRPC: the publish stream ends with an error status naming the size.
    let err = publish_one(&mut client, &token, huge.clone())
        .await
        .unwrap_err();
    assert!(
        matches!(
            err.code(),
            tonic::Code::OutOfRange | tonic::Code::ResourceExhausted
        ),
        "{err}"
    );
    assert!(err.message().contains("too large"), "{}", err.message());
    // The room goes on: a normal frame is accepted and reaches the viewer.
    let ack = publish_one(&mut client, &token, control_frame(&model, "r", 2, 0.2))
        .await
        .unwrap();
    assert!(ack.error.is_none(), "{ack:?}");
    frame_at_least(&mut viewer, 2).await;

    // WebSocket: the oversized message closes that socket (1009, message too big).
    let url = format!("ws://{}/ws/rooms/r?subscribe=false", running.http);
    let (mut ws, _) = ws_connect(&url, Some(&token), ONE).await.unwrap();
    ws.send(Message::Binary(huge.encode_to_vec().into()))
        .await
        .ok();
    let mut closed = false;
    while let Ok(Some(m)) = tokio::time::timeout(Duration::from_secs(10), ws.next()).await {
        match m {
            Ok(Message::Close(frame)) => {
                if let Some(frame) = frame {
                    assert_eq!(u16::from(frame.code), 1009, "{frame:?}");
                }
                closed = true;
                break;
            }
            Ok(Message::Text(t)) => panic!("an oversized message was answered: {t}"),
            Ok(_) => {}
            Err(_) => {
                closed = true;
                break;
            }
        }
    }
    assert!(
        closed,
        "the socket that sent an oversized message stays open"
    );
    // The room goes on for others: a new socket publishes, the viewer gets the frame.
    let (mut ws, _) = ws_connect(&url, Some(&token), ONE).await.unwrap();
    ws.send(Message::Binary(
        control_frame(&model, "", 3, 0.3).encode_to_vec().into(),
    ))
    .await
    .unwrap();
    assert!(next_ack(&mut ws).await["error"].is_null());
    frame_at_least(&mut viewer, 3).await;
    running.shutdown(Duration::from_secs(2)).await.unwrap();
}

/// `Config::metrics` (`crease-server --metrics-addr`, issue 47): `/metrics` moves to its own
/// address and the public port answers 404 for it, while the rest of the public port stays.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_on_their_own_address_leave_the_public_port() {
    let model = model();
    let running = serve_config(
        [("tube", model)],
        crease_server::Config {
            admin_token: Some(ADMIN.into()),
            metrics: Some(std::net::SocketAddr::from(([127, 0, 0, 1], 0))),
            ..crease_server::Config::default()
        },
    )
    .await;
    let metrics = running.metrics.expect("a metrics address");
    assert_ne!(metrics, running.http);
    let (code, _) = http_get(running.http, "/metrics").await;
    assert_eq!(code, 404, "the public port serves no /metrics");
    let (code, _) = http_get(running.http, "/healthz").await;
    assert_eq!(code, 200, "the public port's /healthz");
    let (code, body) = http_get(metrics, "/metrics").await;
    assert_eq!(code, 200, "{body}");
    assert!(
        body.lines().any(|l| l.starts_with("crease_rooms ")),
        "no crease_rooms gauge in\n{body}"
    );
    let (code, _) = http_get(metrics, "/api/rooms").await;
    assert_eq!(
        code, 404,
        "the metrics address serves only /metrics and /healthz"
    );
    running.shutdown(Duration::from_secs(2)).await.unwrap();
}
