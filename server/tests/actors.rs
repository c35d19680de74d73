//! Rooms of several actors (issue 38) end to end over a real socket: a room of two actors on
//! the tube (`right` as trained, `left` mirrored across x) streams one topology per actor, then
//! frames holding both actors' meshes under one sequence number, each decoding to an
//! independent prediction (the left one: the original model's, reflected); an actor missing
//! from a frame holds its pose and is flagged in the frame and the ack; a frame that names an
//! unknown actor, or whose actor part does not fit, is refused naming the actor and field,
//! and changes nothing; GetRoom and `/api/rooms/{id}` list the actors.

use crease_core::codec::FrameDecoder;
use crease_core::codec::palette::{
    PaletteFrame, PaletteSynth, palette_vertex_count, read_palette_lanes,
};
use crease_core::glam::Vec3;
use crease_core::model::{MirrorPlane, TrainedModel};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_server::Limits;

const ADMIN: &str = "admin-secret";
use crate::common;
use common::*;

/// The reflection across x = 0.
fn mirror(p: Vec3) -> Vec3 {
    Vec3::new(-p.x, p.y, p.z)
}

/// Actor `name`'s part of a control frame: the tube bent by `angle`, reflected for the
/// mirrored (`left`) actor.
fn part(model: &TrainedModel, name: &str, angle: f32) -> v1::ActorControls {
    let frame = control_frame(model, "", 0, angle);
    let positions = frame
        .positions
        .chunks(3)
        .flat_map(|c| {
            let p = Vec3::from_slice(c);
            if name == "left" { mirror(p) } else { p }.to_array()
        })
        .collect();
    v1::ActorControls {
        actor: name.into(),
        positions,
        ..Default::default()
    }
}

/// What actor `name`'s mesh should be for the tube bent by `angle`: the original model's
/// prediction, reflected for the left actor (the mirror's exactness is `train/tests/mirror.rs`'s).
fn want(model: &TrainedModel, name: &str, angle: f32) -> Vec<Vec3> {
    let p = predicted(model, &control_frame(model, "", 0, angle));
    if name == "left" {
        p.into_iter().map(mirror).collect()
    } else {
        p
    }
}

fn frame(seq: u64, parts: Vec<v1::ActorControls>) -> v1::ControlFrame {
    v1::ControlFrame {
        room: "performer".into(),
        seq,
        capture_time_us: 1_000 * seq as i64,
        actors: parts,
        ..Default::default()
    }
}

async fn next_frame(sub: &mut tonic::Streaming<v1::MeshFrame>) -> v1::Frame {
    match sub.message().await.unwrap().unwrap().body {
        Some(v1::mesh_frame::Body::Frame(f)) => f,
        other => panic!("expected a frame, got {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_room_of_two_actors_streams_both_in_one_frame_and_holds_a_missing_one() {
    let model = model();
    let running = serve_model(
        "tube",
        &model,
        Some(ADMIN),
        Limits {
            publish_hz: f64::INFINITY,
            actors_per_room: 2,
            ..Limits::default()
        },
    )
    .await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let actor = |name: &str, mirror: &str| v1::Actor {
        name: name.into(),
        model: "tube".into(),
        side: name.into(),
        mirror: mirror.into(),
        performer: "ana".into(),
        ..Default::default()
    };
    let opened = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "performer".into(),
                actors: vec![actor("right", ""), actor("left", "x")],
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner();
    let token = opened.publish_token;

    // GetRoom lists both actors as they run, each with its model (the left one mirrored).
    let info = client
        .get_room(v1::GetRoomRequest {
            room: "performer".into(),
        })
        .await
        .unwrap()
        .into_inner();
    let names: Vec<(&str, &str, &str)> = info
        .actors
        .iter()
        .map(|a| {
            let actor = a.actor.as_ref().unwrap();
            (
                actor.name.as_str(),
                actor.mirror.as_str(),
                a.model.as_ref().unwrap().name.as_str(),
            )
        })
        .collect();
    assert_eq!(
        names,
        [("right", "", "tube"), ("left", "x", "tube~mirror-x")]
    );
    let (status, body) = http_get(running.http, "/api/rooms/performer").await;
    assert_eq!(status, 200, "{body}");
    let doc: serde_json::Value = serde_json::from_str(&body).unwrap();
    let actors = doc["actors"].as_array().unwrap();
    assert_eq!(actors.len(), 2);
    assert_eq!(actors[1]["name"], "left");
    assert_eq!(actors[1]["side"], "left");
    assert_eq!(actors[1]["performer"], "ana");
    assert_eq!(actors[1]["model"], "tube~mirror-x");
    // The left actor's control points sit on the reflected rest mesh.
    let rest = model.rig.rest.positions[model.controls[0].vertex as usize];
    let left0 = &actors[1]["control_points"][0]["rest"];
    assert!((left0[0].as_f64().unwrap() + f64::from(rest.x)).abs() < 1e-5);

    // One topology per actor, named, then frames holding both.
    let mut sub = client
        .subscribe(v1::SubscribeRequest {
            room: "performer".into(),
            level: v1::Level::Base as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let mut topologies = Vec::new();
    for i in 0..2 {
        let Some(v1::mesh_frame::Body::Topology(t)) = sub.message().await.unwrap().unwrap().body
        else {
            panic!("topology {i} missing");
        };
        assert_eq!((t.actor_index, t.actor_count), (i, 2));
        topologies.push(t);
    }
    assert_eq!(topologies[0].actor, "right");
    assert_eq!(topologies[1].actor, "left");
    assert_eq!(topologies[1].model, "tube~mirror-x");
    let topologies: Vec<_> = topologies
        .iter()
        .map(|t| crease_proto::read_topology(t).unwrap())
        .collect();
    let mut decoders: Vec<FrameDecoder> = topologies
        .iter()
        .map(|t| FrameDecoder::new(t.vertex_count))
        .collect();

    let frames = vec![
        // 1: both actors, different poses.
        frame(
            1,
            vec![part(&model, "left", 0.9), part(&model, "right", 0.3)],
        ),
        // 2: the right hand only: the left one holds its pose.
        frame(2, vec![part(&model, "right", 0.6)]),
        // 3: an unknown actor: refused, naming it.
        frame(3, vec![part(&model, "nobody", 0.6)]),
        // 4: the right part fits, the left part does not: refused, nothing changes (the
        // right hand stays at 0.6).
        frame(
            4,
            vec![
                part(&model, "right", 1.2),
                v1::ActorControls {
                    actor: "left".into(),
                    positions: vec![0.0; 5],
                    ..Default::default()
                },
            ],
        ),
        // 5: top-level positions in a room of actors: refused.
        v1::ControlFrame {
            positions: vec![0.0; 9],
            ..frame(5, Vec::new())
        },
        // 6: the left hand only: the right one holds 0.6.
        frame(6, vec![part(&model, "left", 0.2)]),
    ];
    let mut acks = Vec::new();
    let mut s = client
        .publish(authed(tokio_stream::iter(frames), &token))
        .await
        .unwrap()
        .into_inner();
    while let Some(a) = s.message().await.unwrap() {
        acks.push(a);
    }
    assert_eq!(acks.len(), 6);
    for k in [0, 1, 5] {
        assert!(acks[k].error.is_none(), "frame {}: {:?}", k + 1, acks[k]);
        let names: Vec<&str> = acks[k].actors.iter().map(|a| a.actor.as_str()).collect();
        assert_eq!(
            names,
            ["right", "left"],
            "acks list actors in the room's order"
        );
    }
    assert!(!acks[0].actors[0].held && !acks[0].actors[1].held);
    assert!(!acks[1].actors[0].held && acks[1].actors[1].held);
    assert!(acks[5].actors[0].held && !acks[5].actors[1].held);
    let error = |k: usize| acks[k].error.as_ref().unwrap().message.clone();
    assert_eq!(acks[2].error.as_ref().unwrap().code, 3);
    assert!(
        error(2).starts_with(
            "ControlFrame.actors[0].actor: \"nobody\" is not an actor of room \"performer\" (right, left)"
        ),
        "{}",
        error(2)
    );
    assert!(
        error(3).starts_with("ControlFrame.actors[\"left\"].positions: 5 values, expected 9"),
        "{}",
        error(3)
    );
    assert!(
        error(4).starts_with("ControlFrame.positions: room \"performer\" is a room of actors"),
        "{}",
        error(4)
    );

    // The frames: both actors' meshes under one sequence number, each the independent
    // prediction; a held actor flagged, its pose unchanged.
    let expect = [
        (1, [("right", 0.3, false), ("left", 0.9, false)]),
        (2, [("right", 0.6, false), ("left", 0.9, true)]),
        (6, [("right", 0.6, true), ("left", 0.2, false)]),
    ];
    for (seq, actors) in expect {
        // Latest wins: a frame the subscriber was too slow for may be skipped; decode it all.
        let f = loop {
            let f = next_frame(&mut sub).await;
            assert!(
                f.data.is_empty(),
                "a room of actors sends its frames in actors"
            );
            assert_eq!(f.actors.len(), 2);
            if f.seq >= seq {
                break f;
            }
            for (a, d) in f.actors.iter().zip(&mut decoders) {
                d.decode(&a.data).unwrap();
            }
        };
        assert_eq!(f.seq, seq, "refused frames publish nothing");
        assert_eq!(f.capture_time_us, 1_000 * seq as i64);
        for (k, (name, angle, held)) in actors.into_iter().enumerate() {
            let a = &f.actors[k];
            assert_eq!(a.actor as usize, k);
            assert_eq!(a.held, held, "seq {seq} actor {name}");
            check_decoded(
                &mut decoders[k],
                &topologies[k],
                &a.data,
                &want(&model, name, angle),
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_room_of_actors_streams_palettes_per_actor_and_refuses_one_actor_frames() {
    let model = model();
    let running = serve_model("tube", &model, Some(ADMIN), unthrottled()).await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let actor = |name: &str, mirror: &str| v1::Actor {
        name: name.into(),
        model: "tube".into(),
        mirror: mirror.into(),
        ..Default::default()
    };
    let token = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "performer".into(),
                actors: vec![actor("a", ""), actor("b", "z"), actor("c", "")],
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let mut sub = client
        .subscribe(v1::SubscribeRequest {
            room: "performer".into(),
            level: v1::Level::Base as i32,
            encoding: v1::Encoding::Palette as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let mut synths = Vec::new();
    for i in 0..3u32 {
        let Some(v1::mesh_frame::Body::PaletteTopology(p)) =
            sub.message().await.unwrap().unwrap().body
        else {
            panic!("palette header {i} missing");
        };
        assert_eq!((p.actor_index, p.actor_count), (i, 3));
        assert_eq!(p.actor, ["a", "b", "c"][i as usize]);
        let header = crease_proto::read_palette_topology(&p).unwrap().header;
        let lanes = (header.bones, header.xi_len());
        synths.push((PaletteSynth::new(header).unwrap(), lanes));
    }
    let mirrored = model.mirrored(&MirrorPlane::parse("z").unwrap()).unwrap();
    let models = [&model, &mirrored, &model];
    let parts = |seq| {
        frame(
            seq,
            ["a", "b", "c"]
                .iter()
                .map(|n| v1::ActorControls {
                    actor: (*n).into(),
                    ..part(&model, "right", 0.1 * seq as f32)
                })
                .collect(),
        )
    };
    // A one-actor frame (its own positions, no actors) is refused in a room of actors.
    let one = control_frame(&model, "performer", 1, 0.3);
    let mut s = client
        .publish(authed(tokio_stream::iter(vec![one, parts(2)]), &token))
        .await
        .unwrap()
        .into_inner();
    let refused = s.message().await.unwrap().unwrap();
    assert_eq!(refused.error.unwrap().code, 3);
    let ok = s.message().await.unwrap().unwrap();
    assert!(ok.error.is_none(), "{ok:?}");
    let f = next_frame(&mut sub).await;
    assert_eq!(f.seq, 2);
    assert_eq!(f.actors.len(), 3);
    // Each actor's palette frame decodes (core's reference decoder) to its own model's
    // prediction, within the palette's bound.
    let sent = parts(2);
    for (k, a) in f.actors.iter().enumerate() {
        let m = models[k];
        let (synth, (bones, xi)) = &mut synths[k];
        let (bones, xi) = (*bones, *xi);
        let mut decoder = FrameDecoder::new(palette_vertex_count(bones, xi));
        let h = decoder.decode(&a.data).unwrap();
        let mut pf = PaletteFrame::default();
        read_palette_lanes(decoder.lanes(), &h.qbox, bones, xi, &mut pf).unwrap();
        let got = synth.synthesize(&pf).unwrap().to_vec();
        let one = v1::ControlFrame {
            positions: sent.actors[k].positions.clone(),
            ..Default::default()
        };
        let want = predicted(m, &one);
        for (v, (g, w)) in got.iter().zip(&want).enumerate() {
            let bound = palette_check::base_bound(m, synth, &pf, v, *g);
            assert!(
                g.distance(*w) <= bound * 1.001 + 1e-5,
                "actor {k} vertex {v}: {g} vs {w} (bound {bound})"
            );
        }
    }

    // A one-actor room refuses a frame with actors.
    let solo = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "solo".into(),
                model: "tube".into(),
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let with_actors = v1::ControlFrame {
        room: "solo".into(),
        ..parts(3)
    };
    let mut s = client
        .publish(authed(tokio_stream::iter(vec![with_actors]), &solo))
        .await
        .unwrap()
        .into_inner();
    let e = s.message().await.unwrap().unwrap().error.unwrap();
    assert_eq!(e.code, 3);
    assert!(
        e.message
            .starts_with("ControlFrame.actors: 3 actors: room \"solo\" was opened without actors"),
        "{}",
        e.message
    );
}

/// The positions of every actor of every frame `sub` streams, decoded, in model order, by
/// sequence number, until `last` arrives.
async fn decoded_until(
    sub: &mut tonic::Streaming<v1::MeshFrame>,
    last: u64,
) -> std::collections::BTreeMap<u64, Vec<(Vec<Vec3>, f32)>> {
    let mut readers = Vec::new();
    let mut out = std::collections::BTreeMap::new();
    loop {
        match sub.message().await.unwrap().unwrap().body {
            Some(v1::mesh_frame::Body::Topology(t)) => {
                let t = crease_proto::read_topology(&t).unwrap();
                readers.push((FrameDecoder::new(t.vertex_count), t));
            }
            Some(v1::mesh_frame::Body::Frame(f)) => {
                let mut meshes = Vec::new();
                for (a, (d, t)) in f.actors.iter().zip(&mut readers) {
                    let h = d.decode(&a.data).unwrap();
                    let (mut streamed, mut model) = (Vec::new(), Vec::new());
                    d.positions(&mut streamed);
                    t.to_model_order(&streamed, &mut model);
                    meshes.push((model, h.qbox.error_bound().max_element()));
                }
                out.insert(f.seq, meshes);
                if f.seq >= last {
                    return out;
                }
            }
            _ => {}
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_take_of_a_room_of_actors_records_every_actor_and_replays_into_a_fresh_room() {
    let model = model();
    let takes = tempfile::tempdir().unwrap();
    let registry = crease_server::registry::ModelRegistry::default();
    registry.insert("tube", model.clone());
    let loopback = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let state = crease_server::AppState::new(
        registry,
        crease_server::Config {
            grpc: loopback,
            http: loopback,
            admin_token: Some(ADMIN.into()),
            limits: unthrottled(),
            takes: Some(takes.path().to_owned()),
            ..crease_server::Config::default()
        },
    );
    let running = crease_server::serve(state).await.unwrap();
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let open = |room: &str| v1::OpenRoomRequest {
        room: room.into(),
        actors: vec![
            crease_proto::room::actor("right", "tube", false),
            crease_proto::room::actor("left", "tube", true),
        ],
        ..Default::default()
    };
    let token = client
        .open_room(authed(open("performer"), ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let subscribe = |room: &str| v1::SubscribeRequest {
        room: room.into(),
        level: v1::Level::Base as i32,
        ..Default::default()
    };
    let mut sub = client
        .subscribe(subscribe("performer"))
        .await
        .unwrap()
        .into_inner();
    client
        .start_take(authed(
            v1::StartTakeRequest {
                room: "performer".into(),
                name: "two hands".into(),
            },
            ADMIN,
        ))
        .await
        .unwrap();
    // Ten frames, both hands in different poses; the left one missing from frame 4.
    let frames: Vec<v1::ControlFrame> = (1..=10u64)
        .map(|seq| {
            let mut parts = vec![part(&model, "right", 0.1 * seq as f32)];
            if seq != 4 {
                parts.push(part(&model, "left", 1.0 - 0.07 * seq as f32));
            }
            frame(seq, parts)
        })
        .collect();
    let publish = |client: &mut CreaseClient<tonic::transport::Channel>,
                   token: &str,
                   frames: Vec<v1::ControlFrame>| {
        let request = authed(tokio_stream::iter(frames), token);
        let mut client = client.clone();
        async move {
            let mut acks = client.publish(request).await.unwrap().into_inner();
            while let Some(a) = acks.message().await.unwrap() {
                assert!(a.error.is_none(), "{a:?}");
            }
        }
    };
    // One at a time, so that every frame is streamed (latest wins would skip some).
    for f in &frames {
        publish(&mut client, &token, vec![f.clone()]).await;
    }
    let original = decoded_until(&mut sub, 10).await;
    let info = client
        .stop_take(authed(
            v1::StopTakeRequest {
                room: "performer".into(),
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.frames, 10);

    // The file: the room's actors in the header, each actor's digest, bones and controls; per
    // frame the control frame with every actor's part, and each actor's pose.
    let file = std::fs::File::open(takes.path().join(format!("{}.take", info.take))).unwrap();
    let take = crease_proto::take::read_take(std::io::BufReader::new(file)).unwrap();
    let header = take.header();
    let room = header.room.clone().unwrap();
    assert!(
        room.model.is_empty(),
        "a room of actors names no model of its own"
    );
    let names: Vec<(&str, &str)> = room
        .actors
        .iter()
        .map(|a| (a.name.as_str(), a.mirror.as_str()))
        .collect();
    assert_eq!(names, [("right", ""), ("left", "x")]);
    assert_eq!(header.actors.len(), 2);
    for a in &header.actors {
        assert_eq!(a.bones as usize, model.rig.bone_count);
        assert_eq!(a.controls as usize, model.controls.len());
        assert_eq!(a.model_sha256.len(), 64);
    }
    assert_eq!(header.actors[0].model_sha256, header.actors[1].model_sha256);
    assert_eq!(take.frames.len(), 10);
    for (k, f) in take.frames.iter().enumerate() {
        assert_eq!(f.actors.len(), 2, "frame {k}: every actor's pose");
        for pose in &f.actors {
            assert_eq!(pose.transforms.len(), 7 * model.rig.bone_count);
            assert_eq!(pose.controls.len(), 3 * model.controls.len());
        }
        let parts = f.frame.as_ref().unwrap().actors.len();
        assert_eq!(
            parts,
            if k == 3 { 1 } else { 2 },
            "frame {k}'s parts as sent"
        );
    }
    // The left hand's recorded controls at frame 4 are its held ones (frame 3's).
    assert_eq!(
        take.frames[3].actors[1].controls,
        take.frames[2].actors[1].controls
    );

    // Replayed into a fresh room opened with the take's settings, the recorded control frames
    // give every actor's meshes again, within the stream's quantisation.
    let replay_token = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "replay".into(),
                ..room
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let mut replay = client
        .subscribe(subscribe("replay"))
        .await
        .unwrap()
        .into_inner();
    for f in &take.frames {
        let mut control = f.frame.clone().unwrap();
        control.room = "replay".into();
        publish(&mut client, &replay_token, vec![control]).await;
    }
    let replayed = decoded_until(&mut replay, 10).await;
    // Latest wins: a subscriber may skip a frame; those both streams carried are compared
    // (the last one always is).
    let mut compared = 0;
    for (seq, meshes) in &original {
        let Some(again) = replayed.get(seq) else {
            continue;
        };
        compared += 1;
        assert_eq!(again.len(), 2);
        for (k, ((a, bound), (b, _))) in meshes.iter().zip(again).enumerate() {
            let d = a
                .iter()
                .zip(b)
                .map(|(p, q)| (*p - *q).abs().max_element())
                .fold(0.0f32, f32::max);
            assert!(
                d <= 2.0 * bound * 1.001 + 1e-6,
                "frame {seq} actor {k}: replayed {d} from the original (bound {bound})"
            );
        }
    }
    assert!(
        compared >= 1 && replayed.contains_key(&10),
        "{compared} frames compared"
    );
    drop(running);
}

/// A retargeting actor's map for the tube: control point `c` is marker `{prefix}{i}`, every
/// control point registers, the scale is fitted over three frames.
fn tube_map(model: &TrainedModel, prefix: &str) -> (String, Vec<String>) {
    let names: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    let quoted: Vec<String> = names.iter().map(|n| format!("{n:?}")).collect();
    let mut toml = format!(
        "[registration]\npoints = [{}]\ncalibration_frames = 3\n[markers]\n",
        quoted.join(", ")
    );
    let markers: Vec<String> = (0..names.len()).map(|i| format!("{prefix}{i}")).collect();
    for (n, m) in names.iter().zip(&markers) {
        toml += &format!("{n} = {m:?}\n");
    }
    (toml, markers)
}

/// A similarity from a model frame into the capture's (millimetres): `1000 R x + t`.
fn capture_of(angle: f32, t: Vec3) -> impl Fn(Vec3) -> Vec3 {
    move |p| crease_core::glam::Quat::from_rotation_y(angle) * (1000.0 * p) + t
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_performers_hands_are_placed_where_the_capture_put_them() {
    // Two retargeting actors of one performer, the left hand on the mirrored tube: each
    // registers its own markers onto its model (what it predicts from), and each frame places
    // its mesh by the performer's registration (the right hand's, fixed once its scale is)
    // after the inverse of its own (crease_server::performer).
    let model = model();
    let mirrored = model.mirrored(&MirrorPlane::X).unwrap();
    let running = serve_model(
        "tube",
        &model,
        Some(ADMIN),
        Limits {
            publish_hz: f64::INFINITY,
            ..Limits::default()
        },
    )
    .await;
    let mut client = CreaseClient::connect(format!("http://{}", running.grpc))
        .await
        .unwrap();
    let (right_map, right_markers) = tube_map(&model, "R");
    let (left_map, left_markers) = tube_map(&mirrored, "L");
    let actor = |name: &str, mirror: &str, map: &str, markers: &[String]| v1::Actor {
        name: name.into(),
        model: "tube".into(),
        side: name.into(),
        mirror: mirror.into(),
        performer: "ana".into(),
        retarget: Some(v1::Retarget {
            map_toml: map.into(),
            markers: markers.to_vec(),
            units: "mm".into(),
            ..Default::default()
        }),
        ..Default::default()
    };
    let token = client
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "stage".into(),
                actors: vec![
                    actor("right", "", &right_map, &right_markers),
                    actor("left", "x", &left_map, &left_markers),
                ],
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let mut sub = client
        .subscribe(v1::SubscribeRequest {
            room: "stage".into(),
            level: v1::Level::Base as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    for _ in 0..2 {
        let m = sub.message().await.unwrap().unwrap();
        assert!(matches!(m.body, Some(v1::mesh_frame::Body::Topology(_))));
    }

    // The capture: the right hand here, the left hand 300 mm to its side, turned; later the
    // right hand moves 40 mm.
    let right_at = capture_of(0.3, Vec3::new(100.0, 50.0, 900.0));
    let left_at = capture_of(-0.8, Vec3::new(-200.0, 60.0, 880.0));
    let right_moved = capture_of(0.3, Vec3::new(140.0, 50.0, 900.0));
    let rest = |m: &TrainedModel| -> Vec<Vec3> {
        m.controls
            .iter()
            .map(|c| m.rig.rest.positions[c.vertex as usize])
            .collect()
    };
    let (right_rest, left_rest) = (rest(&model), rest(&mirrored));
    let markers = |at: &dyn Fn(Vec3) -> Vec3, points: &[Vec3]| -> Vec<f32> {
        points.iter().flat_map(|p| at(*p).to_array()).collect()
    };
    let part = |name: &str, m: Vec<f32>| v1::ActorControls {
        actor: name.into(),
        markers: m,
        ..Default::default()
    };
    let frames: Vec<v1::ControlFrame> = (0..8u64)
        .map(|seq| {
            let right: &dyn Fn(Vec3) -> Vec3 = if seq < 6 { &right_at } else { &right_moved };
            v1::ControlFrame {
                room: "stage".into(),
                seq,
                actors: vec![
                    part("right", markers(right, &right_rest)),
                    part("left", markers(&left_at, &left_rest)),
                ],
                ..Default::default()
            }
        })
        .collect();
    let (calibrated, moved) = (frames[5].clone(), frames[7].clone());
    let publish = |frames: Vec<v1::ControlFrame>| {
        let mut client = client.clone();
        let token = token.clone();
        async move {
            let mut acks = client
                .publish(authed(tokio_stream::iter(frames), &token))
                .await
                .unwrap()
                .into_inner();
            while let Some(a) = acks.message().await.unwrap() {
                assert!(a.error.is_none(), "{a:?}");
            }
        }
    };
    /// The placements of the frame with sequence number `seq`.
    async fn placements_of(
        sub: &mut tonic::Streaming<v1::MeshFrame>,
        seq: u64,
    ) -> Vec<Option<crease_proto::ActorPlace>> {
        loop {
            let f = next_frame(sub).await;
            if f.seq == seq {
                return f
                    .actors
                    .iter()
                    .map(|a| {
                        a.placement
                            .as_ref()
                            .map(|p| crease_proto::ActorPlace::from_wire(p).unwrap())
                    })
                    .collect();
            }
        }
    }
    publish(frames[..6].to_vec()).await;
    let placed = placements_of(&mut sub, calibrated.seq).await;
    // Where the capture put each control point, through the performer's registration (the
    // right hand's: the capture -> its model, as it was when fixed).
    let into_performer = |q: Vec3| {
        let inv = crease_core::glam::Quat::from_rotation_y(0.3).inverse();
        inv * (q - Vec3::new(100.0, 50.0, 900.0)) / 1000.0
    };
    let check = |place: crease_proto::ActorPlace,
                 points: &[Vec3],
                 at: &dyn Fn(Vec3) -> Vec3,
                 what: &str| {
        for p in points {
            let want = into_performer(at(*p));
            let got = place.apply(*p);
            assert!(
                (got - want).length() < 1e-4,
                "{what}: model point {p} placed at {got}, the capture put it at {want}"
            );
        }
    };
    check(
        placed[0].expect("the right hand is placed"),
        &right_rest,
        &right_at,
        "right",
    );
    check(
        placed[1].expect("the left hand is placed"),
        &left_rest,
        &left_at,
        "left",
    );
    let apart = placed[1].unwrap().apply(left_rest[0]) - placed[0].unwrap().apply(right_rest[0]);
    assert!(
        apart.length() > 0.25,
        "the hands are 300 mm apart in the capture: {apart}"
    );
    // The right hand moves in the capture: its mesh moves with it, the left stays.
    publish(frames[6..].to_vec()).await;
    let placed = placements_of(&mut sub, moved.seq).await;
    check(
        placed[0].unwrap(),
        &right_rest,
        &right_moved,
        "right, moved",
    );
    check(placed[1].unwrap(), &left_rest, &left_at, "left, still");
}
