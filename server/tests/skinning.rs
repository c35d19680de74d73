//! Skinning chosen per model and per room (issue 22), end to end over a real socket: a room with
//! `skinning = dqs` streams meshes equal to `core::runtime::skin::skin_dqs` (Kavan et al. 2007's
//! dual quaternion linear blending) of the transforms the model predicts in-process, within the
//! codec's quantisation bound, while an LBS room on the same frames does not; the batch follows
//! its request; a model's default comes from its file; GetRoom reports the skinning; and a DQS
//! room refuses palette subscriptions (whose clients skin with LBS) on gRPC and WebSocket.

use std::sync::Arc;

use crease_core::codec::FrameDecoder;
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_core::runtime::skin::{BonePalette, Skinning, skin_dqs};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;

use crate::common;
use common::*;

const ADMIN: &str = "admin-secret";

/// The tube model as `tube` (LBS, the default) and as `tube-dqs` (the same model with DQS as
/// its default), with no publish rate limit.
async fn serve_both(model: &TrainedModel) -> Served {
    let dqs = TrainedModel {
        skinning: Skinning::Dqs,
        ..model.clone()
    };
    serve_models(
        [("tube", model.clone()), ("tube-dqs", dqs)],
        Some(ADMIN),
        unthrottled(),
    )
    .await
}

/// The frame's control points.
fn controls(frame: &v1::ControlFrame) -> Vec<Vec3> {
    frame
        .positions
        .chunks(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect()
}

/// The independent computation: the transforms the model predicts in-process for `frame` (an
/// LBS predictor: the transforms do not depend on the skinning), skinned by `skin_dqs` on the
/// rig's own weights, and by the plain LBS sum `sum_b w_b (R_b v + t_b)` (FKY08 §5) written
/// here.
fn wanted(model: &TrainedModel, frame: &v1::ControlFrame) -> (Vec<Vec3>, Vec<Vec3>) {
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    assert_eq!(predictor.skinning(), Skinning::Lbs);
    let mut ctx = predictor.new_context();
    predictor
        .predict_transforms(&mut ctx, &controls(frame), None)
        .unwrap();
    let rest = &model.rig.rest.positions;
    let mut dqs = vec![Vec3::ZERO; rest.len()];
    skin_dqs(
        rest,
        &model.rig.skin,
        &BonePalette::from_transforms(ctx.transforms()),
        &mut dqs,
    )
    .unwrap();
    let lbs = (0..rest.len())
        .map(|v| {
            let (bones, weights) = model.rig.skin.vertex(v);
            bones
                .iter()
                .zip(weights)
                .map(|(&b, &w)| w * ctx.transforms()[b as usize].transform_point(rest[v]))
                .sum()
        })
        .collect();
    (dqs, lbs)
}

/// The largest distance between two meshes' vertices.
fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

/// Decodes `data` (after every earlier frame of the stream) into model order.
fn decode(
    decoder: &mut FrameDecoder,
    topology: &crease_proto::StreamTopology,
    data: &[u8],
) -> (Vec<Vec3>, Vec3) {
    let header = decoder.decode(data).unwrap();
    let (mut streamed, mut got) = (Vec::new(), Vec::new());
    decoder.positions(&mut streamed);
    topology.to_model_order(&streamed, &mut got);
    (got, header.qbox.error_bound())
}

/// `got` equals `want` vertex by vertex within the quantisation `bound` (per axis).
fn assert_within(what: &str, got: &[Vec3], want: &[Vec3], bound: Vec3) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (*g - *w).abs().cmple(bound * 1.001 + 1e-6).all(),
            "{what}: vertex {i}: {g} vs {w} (bound {bound})"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dqs_rooms_stream_skin_dqs_of_the_predicted_transforms() {
    // The curled tube: its bones blend over the rings, where the bent tube's are rigid
    // segments (on which LBS and DQS agree).
    let model = model_of(curled);
    let control_frame = |model: &TrainedModel, room: &str, seq: u64, angle: f32| {
        control_frame_of(curled, model, room, seq, angle)
    };
    let running = serve_both(&model).await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let open = |room: &str, model: &str, skinning: i32| {
        authed(
            v1::OpenRoomRequest {
                room: room.into(),
                model: model.into(),
                skinning,
                ..Default::default()
            },
            ADMIN,
        )
    };
    let (lbs, dqs) = (v1::Skinning::Lbs as i32, v1::Skinning::Dqs as i32);

    // A value that is not a Skinning names the field.
    let err = client.open_room(open("bad", "tube", 7)).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::InvalidArgument);
    assert_eq!(
        err.message(),
        "OpenRoomRequest.skinning: 7 is not a Skinning (0 unspecified, 1 lbs, 2 dqs)"
    );

    // The models report their defaults; rooms report what they use: the option, else the
    // model's default.
    for (name, default) in [("tube", lbs), ("tube-dqs", dqs)] {
        let info = client
            .get_model(v1::GetModelRequest { model: name.into() })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(info.skinning, default, "{name}");
    }
    let mut tokens = std::collections::BTreeMap::new();
    for (room, model_name, asked, used) in [
        ("dqs", "tube", dqs, dqs),
        ("lbs", "tube", lbs, lbs),
        ("default", "tube", 0, lbs),
        ("model-dqs", "tube-dqs", 0, dqs),
        ("model-dqs-lbs", "tube-dqs", lbs, lbs),
    ] {
        let opened = client
            .open_room(open(room, model_name, asked))
            .await
            .unwrap()
            .into_inner();
        tokens.insert(room, opened.publish_token);
        let info = client
            .get_room(v1::GetRoomRequest { room: room.into() })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(info.skinning, used, "room {room}");
    }

    // A DQS room refuses palette streams, naming the room and its skinning; an LBS room
    // serves them.
    for room in ["dqs", "model-dqs"] {
        let err = client
            .subscribe(v1::SubscribeRequest {
                room: room.into(),
                level: v1::Level::Base as i32,
                encoding: v1::Encoding::Palette as i32,
            })
            .await
            .unwrap_err();
        assert_eq!(err.code(), tonic::Code::FailedPrecondition, "{room}");
        assert!(
            err.message()
                .starts_with(&format!("room {room:?}: encoding: "))
                && err.message().contains("skins with dqs"),
            "{room}: {}",
            err.message()
        );
    }
    let mut palette = client
        .subscribe(v1::SubscribeRequest {
            room: "lbs".into(),
            level: v1::Level::Base as i32,
            encoding: v1::Encoding::Palette as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let first = palette.message().await.unwrap().unwrap();
    assert!(matches!(
        first.body,
        Some(v1::mesh_frame::Body::PaletteTopology(_))
    ));
    drop(palette);

    // The same on the WebSocket: 409 before the upgrade, with gRPC's message; the vertex
    // stream of the same room upgrades.
    let url = |room: &str, query: &str| format!("ws://{}/ws/rooms/{room}{query}", running.http);
    match tokio_tungstenite::connect_async(url("dqs", "?encoding=palette")).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => {
            assert_eq!(response.status().as_u16(), 409);
            let body = String::from_utf8(response.body().clone().unwrap_or_default()).unwrap();
            assert!(
                body.starts_with("room \"dqs\": encoding: ") && body.contains("skins with dqs"),
                "{body}"
            );
        }
        other => panic!("a palette WebSocket on a DQS room: {other:?}"),
    }
    let (ws, _) = tokio_tungstenite::connect_async(url("dqs", ""))
        .await
        .unwrap();
    drop(ws);

    // Frames across the training span (0 to 1.25 rad; beyond it the prediction leaves the
    // stream's quantisation box, where frames clamp), one at a time, each read back from every
    // room's vertex stream.
    let rooms = ["dqs", "lbs", "default", "model-dqs"];
    let mut subs = Vec::new();
    for room in rooms {
        let mut sub = client
            .subscribe(v1::SubscribeRequest {
                room: room.into(),
                level: v1::Level::Base as i32,
                ..Default::default()
            })
            .await
            .unwrap()
            .into_inner();
        let first = sub.message().await.unwrap().unwrap();
        let Some(v1::mesh_frame::Body::Topology(topo)) = first.body else {
            panic!("{room}: the first message is not the topology: {first:?}");
        };
        let topology = crease_proto::read_topology(&topo).unwrap();
        let decoder = FrameDecoder::new(topology.vertex_count);
        subs.push((sub, topology, decoder));
    }
    let mut lbs_vs_dqs: f32 = 0.0;
    for (seq, angle) in [(1u64, 0.3f32), (2, 0.8), (3, 1.1), (4, 1.25)] {
        let frame = |room: &str| control_frame(&model, room, seq, angle);
        let (want_dqs, want_lbs) = wanted(&model, &frame(""));
        for ((room, (sub, topology, decoder)), skinning) in rooms.iter().zip(&mut subs).zip([
            Skinning::Dqs,
            Skinning::Lbs,
            Skinning::Lbs,
            Skinning::Dqs,
        ]) {
            let mut acks = client
                .publish(authed(tokio_stream::iter(vec![frame(room)]), &tokens[room]))
                .await
                .unwrap()
                .into_inner();
            let ack = acks.message().await.unwrap().unwrap();
            assert!(ack.error.is_none(), "{room} seq {seq}: {ack:?}");
            let (got, bound) = loop {
                let msg = sub.message().await.unwrap().unwrap();
                let Some(v1::mesh_frame::Body::Frame(f)) = msg.body else {
                    panic!("{room}: expected a frame, got {msg:?}");
                };
                let decoded = decode(decoder, topology, &f.data);
                if f.seq == seq {
                    break decoded;
                }
            };
            let (want, other) = match skinning {
                Skinning::Dqs => (&want_dqs, &want_lbs),
                Skinning::Lbs => (&want_lbs, &want_dqs),
            };
            let what = format!("room {room}, bend {angle} rad");
            assert_within(&what, &got, want, bound);
            // The other skinning is far outside the bound: the comparison can fail.
            let apart = max_distance(&got, other);
            assert!(
                angle < 0.5 || apart > 10.0 * bound.max_element(),
                "{what}: {apart} from the other skinning (bound {bound})"
            );
            lbs_vs_dqs = lbs_vs_dqs.max(apart);
        }
    }
    eprintln!("largest LBS vs DQS vertex distance: {lbs_vs_dqs} (tube radius 1)");

    // A batch skins as its request says, else as the model's default.
    for (model_name, asked, skinning) in [
        ("tube", dqs, Skinning::Dqs),
        ("tube-dqs", 0, Skinning::Dqs),
        ("tube-dqs", lbs, Skinning::Lbs),
    ] {
        let frames: Vec<v1::ControlFrame> = (0..3)
            .map(|k| control_frame(&model, "", k, 0.5 + 0.5 * k as f32))
            .collect();
        let mut s = client
            .synthesize(v1::SynthesizeRequest {
                model: model_name.into(),
                frames: frames.clone(),
                skinning: asked,
                ..Default::default()
            })
            .await
            .unwrap()
            .into_inner();
        let first = s.message().await.unwrap().unwrap();
        let Some(v1::mesh_frame::Body::Topology(topo)) = first.body else {
            panic!("the batch's first message is not the topology: {first:?}");
        };
        let topology = crease_proto::read_topology(&topo).unwrap();
        let mut decoder = FrameDecoder::new(topology.vertex_count);
        for frame in &frames {
            let msg = s.message().await.unwrap().unwrap();
            let Some(v1::mesh_frame::Body::Frame(f)) = msg.body else {
                panic!("expected a frame, got {msg:?}");
            };
            let (got, bound) = decode(&mut decoder, &topology, &f.data);
            let (want_dqs, want_lbs) = wanted(&model, frame);
            let want = if skinning == Skinning::Dqs {
                want_dqs
            } else {
                want_lbs
            };
            assert_within(
                &format!("batch on {model_name} ({skinning}), frame {}", f.seq),
                &got,
                &want,
                bound,
            );
        }
    }
    let err = client
        .synthesize(v1::SynthesizeRequest {
            model: "tube".into(),
            frames: vec![control_frame(&model, "", 0, 0.1)],
            skinning: 3,
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::InvalidArgument);
    assert!(
        err.message().starts_with("SynthesizeRequest.skinning: 3"),
        "{}",
        err.message()
    );
    running
        .shutdown(std::time::Duration::from_secs(2))
        .await
        .unwrap();
}

/// The model file keeps the default skinning, and stays what it was for LBS models: no
/// `skinning` key (so files written before issue 22, which have none, load as LBS, and an LBS
/// model's file is byte for byte the old layout).
#[test]
fn the_model_file_keeps_the_default_skinning_and_old_files_load_as_lbs() {
    let lbs = model();
    assert_eq!(lbs.skinning, Skinning::Lbs);
    let bytes = lbs.to_bytes().unwrap();
    let needle = b"\"skinning\"";
    assert!(
        !bytes.windows(needle.len()).any(|w| w == needle),
        "an LBS model's file names its skinning"
    );
    assert_eq!(TrainedModel::from_bytes(&bytes).unwrap(), lbs);
    let dqs = TrainedModel {
        skinning: Skinning::Dqs,
        ..lbs.clone()
    };
    let bytes = dqs.to_bytes().unwrap();
    assert!(
        bytes
            .windows(b"\"skinning\":\"dqs\"".len())
            .any(|w| w == b"\"skinning\":\"dqs\""),
        "a DQS model's file does not say so"
    );
    let loaded = TrainedModel::from_bytes(&bytes).unwrap();
    assert_eq!(loaded.skinning, Skinning::Dqs);
    assert_eq!(loaded, dqs);
    // A predictor starts with the model's default.
    assert_eq!(
        Predictor::new(Arc::new(loaded), None).unwrap().skinning(),
        Skinning::Dqs
    );
}
