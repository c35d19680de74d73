//! Rooms across replicas, end to end (issue 17): a real `nats-server` with JetStream on a free
//! loopback port and a temporary store, and three `crease-server` processes A, B, C joined to
//! it (A and B hold the tube model; C starts with an empty model folder and fetches it). A room
//! opened on A is listed on B and C; viewers on A (gRPC), B (gRPC) and C (WebSocket) decode the
//! same frames, which match the in-process prediction within the quantisation bound; a
//! publisher on C drives the room, with acks; detail interest from C alone makes A synthesise
//! detail, and it stops when C's detail viewer leaves; `kill -9` of A: B or C adopts the room
//! (the time is printed), C's viewer gets frames again and the publisher goes on; a NATS
//! restart: the replicas reconnect and the room goes on; a room whose model's cluster copy is
//! corrupt, or absent, is never adopted by a replica that lacks it.
//!
//! Skips, saying why, when `nats-server` is not installed (`.ci/run` installs it).

use crate::cluster_kit;
use crate::common;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::{authed, bent, check_decoded, control_frame, http_get, model_with_detail, predicted};
use crease_core::codec::FrameDecoder;
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use futures_util::StreamExt;
use prost::Message;

use cluster_kit::{ADMIN, Nats, Replica, free_port, nats_binary, until};

/// What a viewer decoded: per publisher seq, whether the frame matched the prediction.
#[derive(Default)]
struct Seen {
    frames: BTreeMap<u64, usize>,
    decode_errors: usize,
    topology: Option<crease_proto::StreamTopology>,
}

type Shared = Arc<Mutex<Seen>>;

/// The expected mesh of a frame of the test's publisher: seq k bends the tube by angle(k).
fn angle(seq: u64) -> f32 {
    0.1 + 0.05 * (seq % 20) as f32
}

/// The second actor's bend in a room of two actors (`duo`): another pose than the first's.
fn left_angle(seq: u64) -> f32 {
    angle(seq + 7)
}

/// The reflection across x = 0 (the `left` actor's mirror plane).
fn mirror_x(p: Vec3) -> Vec3 {
    Vec3::new(-p.x, p.y, p.z)
}

/// Decodes every message of a mesh stream into `seen`, checking each frame (base level)
/// against the in-process prediction of its control frame. A room of actors (issue 38)
/// streams one topology per actor and every actor's frame in `Frame.actors`: actor 0 is
/// checked as a one-actor room's frame, actor 1 (mirrored across x) against the original
/// model's prediction at [`left_angle`], reflected.
fn watch(
    model: Arc<TrainedModel>,
    room: &'static str,
    check: bool,
    seen: Shared,
    mut messages: impl futures_util::Stream<Item = v1::MeshFrame> + Unpin + Send + 'static,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut decoders: Vec<(FrameDecoder, crease_proto::StreamTopology)> = Vec::new();
        while let Some(msg) = messages.next().await {
            match msg.body {
                Some(v1::mesh_frame::Body::Topology(t)) => {
                    if t.actor_index == 0 {
                        decoders.clear();
                    }
                    let t = crease_proto::read_topology(&t).unwrap();
                    decoders.push((FrameDecoder::new(t.vertex_count), t.clone()));
                    seen.lock().unwrap().topology = Some(t);
                }
                Some(v1::mesh_frame::Body::Frame(f)) => {
                    let mut s = seen.lock().unwrap();
                    assert!(!decoders.is_empty(), "a frame before the topology");
                    let parts: Vec<&[u8]> = if f.actors.is_empty() {
                        vec![&f.data]
                    } else {
                        assert_eq!(f.actors.len(), decoders.len(), "every actor's frame");
                        f.actors.iter().map(|a| a.data.as_ref()).collect()
                    };
                    let mut failed = false;
                    for (k, (data, (d, t))) in parts.iter().zip(&mut decoders).enumerate() {
                        if check {
                            let bend = if k == 0 {
                                angle(f.seq)
                            } else {
                                left_angle(f.seq)
                            };
                            let mut want =
                                predicted(&model, &control_frame(&model, room, f.seq, bend));
                            if k == 1 {
                                want.iter_mut().for_each(|p| *p = mirror_x(*p));
                            }
                            check_decoded(d, t, data, &want);
                        } else if d.decode(data).is_err() {
                            failed = true;
                        }
                    }
                    if failed {
                        s.decode_errors += 1;
                        continue;
                    }
                    *s.frames.entry(f.seq).or_default() += 1;
                }
                Some(v1::mesh_frame::Body::PaletteTopology(_)) => {
                    panic!("a palette header on a vertex stream")
                }
                None => {}
            }
        }
    })
}

/// A gRPC viewer of `room` at `level` on `replica`.
async fn grpc_viewer(
    replica: &Replica,
    model: &Arc<TrainedModel>,
    room: &'static str,
    level: v1::Level,
) -> (Shared, tokio::task::JoinHandle<()>) {
    let stream = replica
        .client()
        .await
        .subscribe(v1::SubscribeRequest {
            room: room.into(),
            level: level as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner()
        .filter_map(|m| async move { m.ok() });
    let seen = Shared::default();
    let task = watch(
        Arc::clone(model),
        room,
        level == v1::Level::Base,
        Arc::clone(&seen),
        Box::pin(stream),
    );
    (seen, task)
}

/// A gRPC viewer of `room`'s base level as palette frames on `replica`: each frame decoded
/// by core's reference decoder and checked against the in-process prediction within the
/// palette's bound (`common::palette_check::base_bound`).
async fn palette_viewer(
    replica: &Replica,
    model: &Arc<TrainedModel>,
    room: &'static str,
) -> (Shared, tokio::task::JoinHandle<()>) {
    use crease_core::codec::palette::{
        PaletteFrame, PaletteSynth, palette_vertex_count, read_palette_lanes,
    };
    let mut stream = replica
        .client()
        .await
        .subscribe(v1::SubscribeRequest {
            room: room.into(),
            level: v1::Level::Base as i32,
            encoding: v1::Encoding::Palette as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let seen = Shared::default();
    let (model, out) = (Arc::clone(model), Arc::clone(&seen));
    let task = tokio::spawn(async move {
        let first = stream.message().await.unwrap().unwrap();
        let Some(v1::mesh_frame::Body::PaletteTopology(t)) = first.body else {
            panic!("a palette stream starts with its header");
        };
        let palette = crease_proto::read_palette_topology(&t).unwrap();
        let bones = palette.header.bones;
        let mut synth = PaletteSynth::new(palette.header).unwrap();
        let mut decoder = FrameDecoder::new(palette_vertex_count(bones, 0));
        let mut frame = PaletteFrame::default();
        while let Ok(Some(msg)) = stream.message().await {
            let Some(v1::mesh_frame::Body::Frame(f)) = msg.body else {
                continue;
            };
            let mut s = out.lock().unwrap();
            let Ok(h) = decoder.decode(&f.data) else {
                s.decode_errors += 1;
                continue;
            };
            read_palette_lanes(decoder.lanes(), &h.qbox, bones, 0, &mut frame).unwrap();
            let got = synth.synthesize(&frame).unwrap().to_vec();
            let want = predicted(&model, &control_frame(&model, room, f.seq, angle(f.seq)));
            for (v, (g, w)) in got.iter().zip(&want).enumerate() {
                let bound = common::palette_check::base_bound(&model, &synth, &frame, v, *g) + 1e-5;
                assert!(
                    g.distance(*w) <= bound,
                    "palette frame {}: vertex {v}: {g} vs {w}",
                    f.seq
                );
            }
            *s.frames.entry(f.seq).or_default() += 1;
        }
    });
    (seen, task)
}

/// A WebSocket viewer of `room` at `level` on `replica`.
async fn ws_viewer(
    replica: &Replica,
    model: &Arc<TrainedModel>,
    room: &'static str,
    level: &str,
) -> (Shared, tokio::task::JoinHandle<()>) {
    let url = format!("ws://{}/ws/rooms/{room}?level={level}", replica.http);
    let (socket, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let stream = socket.filter_map(|m| async move {
        match m.ok()? {
            tokio_tungstenite::tungstenite::Message::Binary(b) => {
                v1::MeshFrame::decode(b.as_ref()).ok()
            }
            _ => None,
        }
    });
    let seen = Shared::default();
    let task = watch(
        Arc::clone(model),
        room,
        level == "base",
        Arc::clone(&seen),
        Box::pin(stream),
    );
    (seen, task)
}

/// A publisher of `room` on a replica: frames with seq from `first`, at ~50 Hz, each ack
/// awaited; returns the acks' errors (code, message) by seq.
struct Publisher {
    tx: tokio::sync::mpsc::Sender<v1::ControlFrame>,
    acks: tokio::task::JoinHandle<Vec<v1::PublishAck>>,
    model: Arc<TrainedModel>,
    room: &'static str,
    seq: u64,
    /// A room of two actors (`right`, and `left` mirrored across x): each frame carries both,
    /// the left one's points reflected, at [`left_angle`].
    actors: bool,
}

impl Publisher {
    async fn new(
        replica: &Replica,
        model: &Arc<TrainedModel>,
        room: &'static str,
        token: &str,
    ) -> Publisher {
        let (tx, rx) = tokio::sync::mpsc::channel(16);
        let mut acks = replica
            .client()
            .await
            .publish(authed(
                tokio_stream::wrappers::ReceiverStream::new(rx),
                token,
            ))
            .await
            .unwrap()
            .into_inner();
        let acks = tokio::spawn(async move {
            let mut all = Vec::new();
            while let Ok(Some(ack)) = acks.message().await {
                all.push(ack);
            }
            all
        });
        Publisher {
            tx,
            acks,
            model: Arc::clone(model),
            room,
            seq: 0,
            actors: false,
        }
    }

    /// This publisher as one of a room of two actors (`right`, `left` mirrored across x).
    fn of_actors(mut self) -> Publisher {
        self.actors = true;
        self
    }

    /// Sends `n` frames at ~50 Hz.
    async fn send(&mut self, n: u64) {
        for _ in 0..n {
            self.seq += 1;
            let f = control_frame(&self.model, self.room, self.seq, angle(self.seq));
            let f = if self.actors {
                let mut left = control_frame(&self.model, "", self.seq, left_angle(self.seq));
                left.positions
                    .chunks_exact_mut(3)
                    .for_each(|p| p[0] = -p[0]);
                let parts = vec![
                    crease_proto::control::actor_controls("right", f.clone()),
                    crease_proto::control::actor_controls("left", left),
                ];
                crease_proto::control::with_actors(f, parts)
            } else {
                f
            };
            self.tx.send(f).await.unwrap();
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Sends frames at ~50 Hz until `done` holds (checked after each), up to `limit`; the
    /// time it took.
    async fn send_until(
        &mut self,
        limit: Duration,
        what: &str,
        done: impl Fn() -> bool,
    ) -> Duration {
        let start = Instant::now();
        while !done() {
            assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
            self.send(1).await;
        }
        start.elapsed()
    }

    async fn finish(self) -> Vec<v1::PublishAck> {
        drop(self.tx);
        self.acks.await.unwrap()
    }
}

/// Polls `f` until it is true, up to `limit`; the time it took.
fn frames(seen: &Shared) -> usize {
    seen.lock().unwrap().frames.len()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rooms_across_three_replicas_relay_forward_adopt_and_survive_a_nats_restart() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut nats = Nats::start(&nats_bin, free_port(), &dir.path().join("js"));
    let model = Arc::new(model_with_detail());
    let (models_ab, models_c) = (dir.path().join("models-ab"), dir.path().join("models-c"));
    std::fs::create_dir_all(&models_ab).unwrap();
    std::fs::create_dir_all(&models_c).unwrap();
    model.save(models_ab.join("tube.crease")).unwrap();
    // A second and third model only A and B have: their rooms test refused adoptions.
    model.save(models_ab.join("tube2.crease")).unwrap();
    model.save(models_ab.join("tube3.crease")).unwrap();
    let mut a = Replica::start("A", &models_ab, &nats.url(), dir.path());
    let mut b = Replica::start("B", &models_ab, &nats.url(), dir.path());
    let mut c = Replica::start("C", &models_c, &nats.url(), dir.path());
    for r in [&mut a, &mut b, &mut c] {
        r.ready().await;
    }

    // Issue 39: a model uploaded to C (written into C's folder, offered to the cluster) opens
    // a room on A, which never had it; ListModels on B lists it among the cluster's.
    let bytes = common::model().to_bytes().unwrap();
    let sha = crease_server::registry::sha256_hex(&bytes);
    let mut first = v1::ModelChunk {
        name: "uploaded".into(),
        size: bytes.len() as u64,
        sha256: sha.clone(),
        ..Default::default()
    };
    first.data = bytes[..bytes.len() / 2].to_vec();
    let rest = v1::ModelChunk {
        data: bytes[bytes.len() / 2..].to_vec(),
        ..Default::default()
    };
    c.client()
        .await
        .upload_model(authed(tokio_stream::iter(vec![first, rest]), ADMIN))
        .await
        .unwrap();
    assert!(models_c.join("uploaded.crease").is_file());
    assert!(!models_ab.join("uploaded.crease").exists());
    a.client()
        .await
        .open_room(authed(
            v1::OpenRoomRequest {
                room: "on-upload".into(),
                model: "uploaded".into(),
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap();
    let listed = b
        .client()
        .await
        .list_models(v1::ListModelsRequest {})
        .await
        .unwrap()
        .into_inner();
    assert!(
        listed
            .cluster
            .iter()
            .any(|m| m.name == "uploaded" && m.sha256 == sha && m.bytes == bytes.len() as u64),
        "{:?}",
        listed.cluster
    );
    a.client()
        .await
        .close_room(authed(
            v1::CloseRoomRequest {
                room: "on-upload".into(),
            },
            ADMIN,
        ))
        .await
        .unwrap();

    // A room opened on A is listed, with its owner, on B and C.
    let open = v1::OpenRoomRequest {
        room: "r".into(),
        model: "tube".into(),
        beta: 0.0,
        filter: None,
        ..Default::default()
    };
    let token = a
        .client()
        .await
        .open_room(authed(open.clone(), ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    for r in [&b, &c] {
        until(
            Duration::from_secs(5),
            "the room listed on every replica",
            || async { r.owner_of("r").await.as_deref() == Some("A") },
        )
        .await;
    }
    let again = b
        .client()
        .await
        .open_room(authed(open, ADMIN))
        .await
        .unwrap_err();
    assert_eq!(again.code(), tonic::Code::AlreadyExists, "{again:?}");

    // A room of two actors (issue 38) on A too: the tube as trained and mirrored across x,
    // both hands of one performer in one stream; listed on B and C with both actors.
    let duo = v1::OpenRoomRequest {
        room: "duo".into(),
        actors: vec![
            crease_proto::room::actor("right", "tube", false),
            crease_proto::room::actor("left", "tube", true),
        ],
        ..Default::default()
    };
    let duo_token = a
        .client()
        .await
        .open_room(authed(duo, ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    for r in [&b, &c] {
        until(
            Duration::from_secs(5),
            "the room of actors listed",
            || async { r.owner_of("duo").await.as_deref() == Some("A") },
        )
        .await;
    }

    // Viewers on A (gRPC), B (gRPC) and C (WebSocket; C fetches the model from the cluster).
    let (on_a, _ta) = grpc_viewer(&a, &model, "r", v1::Level::Base).await;
    let (on_b, _tb) = grpc_viewer(&b, &model, "r", v1::Level::Base).await;
    let (on_c, _tc) = ws_viewer(&c, &model, "r", "base").await;
    // Relays announce their interest within a second.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let mut publisher = Publisher::new(&c, &model, "r", &token).await;
    publisher
        .send_until(Duration::from_secs(10), "40 frames on A, B and C", || {
            [&on_a, &on_b, &on_c].iter().all(|s| frames(s) >= 40)
        })
        .await;
    // The room of actors relayed: both actors' meshes in every frame, on B and on C (which
    // mirrors the model it fetched), each checked against its own prediction.
    let (duo_b, _tdb) = grpc_viewer(&b, &model, "duo", v1::Level::Base).await;
    let (duo_c, _tdc) = grpc_viewer(&c, &model, "duo", v1::Level::Base).await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let mut duo_publisher = Publisher::new(&b, &model, "duo", &duo_token)
        .await
        .of_actors();
    duo_publisher
        .send_until(
            Duration::from_secs(10),
            "20 frames of both actors on B and C",
            || [&duo_b, &duo_c].iter().all(|s| frames(s) >= 20),
        )
        .await;
    let relayed = c
        .client()
        .await
        .get_room(v1::GetRoomRequest { room: "duo".into() })
        .await
        .unwrap()
        .into_inner();
    let names: Vec<(String, String)> = relayed
        .actors
        .iter()
        .map(|a| {
            let actor = a.actor.clone().unwrap();
            (actor.name, actor.mirror)
        })
        .collect();
    assert_eq!(
        names,
        [
            ("right".to_owned(), String::new()),
            ("left".to_owned(), "x".to_owned())
        ],
        "C's relay runs the registry's actors"
    );
    let listed = c.rooms().await;
    let duo_listed = listed["cluster"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["room"] == "duo")
        .cloned()
        .unwrap_or_default();
    assert_eq!(
        duo_listed["actors"],
        serde_json::json!(["right", "left"]),
        "/api/rooms on C lists the cluster room's actors: {listed}"
    );
    // A viewer joining B late, while B relays: its first frame is a keyframe made on B from
    // the lanes B decoded (the owner is not asked), and it matches the prediction.
    let (late_b, _tl) = grpc_viewer(&b, &model, "r", v1::Level::Base).await;
    publisher
        .send_until(
            Duration::from_secs(5),
            "frames of the late viewer on B",
            || frames(&late_b) >= 10,
        )
        .await;
    // A palette viewer on B (issue 18): B relays the owner's palette frames (codec frames of
    // bone lanes) and they skin to the predicted mesh within the palette's bound.
    let (palette_b, palette_task) = palette_viewer(&b, &model, "r").await;
    publisher
        .send_until(Duration::from_secs(5), "palette frames on B", || {
            frames(&palette_b) >= 10
        })
        .await;
    assert_eq!(palette_b.lock().unwrap().decode_errors, 0);
    assert!(
        !palette_task.is_finished(),
        "the palette viewer's checks failed"
    );
    palette_task.abort();
    let detail_before = a.metric("crease_detail_frames_total").await;
    publisher.send(20).await;
    assert_eq!(
        a.metric("crease_detail_frames_total").await,
        detail_before,
        "A synthesised detail while nobody watched it"
    );
    // Detail interest from C alone.
    let (detail_c, detail_task) = ws_viewer(&c, &model, "r", "detail").await;
    publisher
        .send_until(Duration::from_secs(5), "detail frames on C", || {
            frames(&detail_c) >= 10
        })
        .await;
    assert_eq!(detail_c.lock().unwrap().decode_errors, 0);
    assert!(a.metric("crease_detail_frames_total").await >= detail_before + 10.0);
    detail_task.abort();
    drop(detail_task);
    // The interest lapses (3 s) and C stops relaying (2 s after its last viewer).
    tokio::time::sleep(Duration::from_secs(6)).await;
    let idle = a.metric("crease_detail_frames_total").await;
    publisher.send(20).await;
    assert_eq!(
        a.metric("crease_detail_frames_total").await,
        idle,
        "detail after C's viewer left"
    );
    // Every frame so far went C -> A and back (the acks are read at the end).
    assert_eq!(
        c.metric("crease_cluster_forwarded_controls_total").await,
        publisher.seq as f64
    );

    // kill -9 of A: B or C adopts the room.
    let killed = Instant::now();
    a.kill9();
    // The publisher goes on through the failover: refused as unavailable until the adoption.
    publisher.send(25).await;
    let adopted = until(Duration::from_secs(10), "adoption", || async {
        b.owner_of("r").await.is_some_and(|o| o != "A")
    })
    .await;
    let new_owner = b.owner_of("r").await.unwrap();
    eprintln!(
        "room \"r\" adopted by {new_owner} {} ms after kill -9 of its owner",
        killed.elapsed().as_millis()
    );
    assert!(killed.elapsed() < Duration::from_secs(10));
    let _ = adopted;
    let before = frames(&on_c);
    publisher
        .send_until(
            Duration::from_secs(5),
            "C's viewer after the adoption",
            || frames(&on_c) >= before + 20,
        )
        .await;
    eprintln!(
        "C's viewer had 20 new frames {} ms after the kill",
        killed.elapsed().as_millis()
    );
    // The room of actors is adopted too, and goes on with both actors.
    until(
        Duration::from_secs(10),
        "the room of actors adopted",
        || async { c.owner_of("duo").await.is_some_and(|o| o != "A") },
    )
    .await;
    let before = (frames(&duo_b), frames(&duo_c));
    duo_publisher
        .send_until(
            Duration::from_secs(10),
            "both actors on B and C after the adoption",
            || frames(&duo_b) >= before.0 + 20 && frames(&duo_c) >= before.1 + 20,
        )
        .await;
    eprintln!(
        "room \"duo\" (two actors) adopted by {}; both viewers had 20 new frames {} ms after the kill",
        c.owner_of("duo").await.unwrap_or_default(),
        killed.elapsed().as_millis()
    );
    let duo_acks = duo_publisher.finish().await;
    assert!(
        duo_acks.iter().filter(|a| a.error.is_none()).count() >= 40,
        "{:?}",
        duo_acks.iter().find_map(|a| a.error.as_ref())
    );

    // A NATS restart: the replicas reconnect, the room goes on under the same owner.
    nats.restart();
    for r in [&b, &c] {
        until(Duration::from_secs(15), "reconnected", || async {
            http_get(r.http, "/readyz").await.0 == 200
        })
        .await;
    }
    let before = (frames(&on_b), frames(&on_c));
    publisher
        .send_until(
            Duration::from_secs(10),
            "frames after the NATS restart",
            || frames(&on_b) >= before.0 + 20 && frames(&on_c) >= before.1 + 20,
        )
        .await;
    assert_eq!(
        b.owner_of("r").await.as_deref(),
        Some(new_owner.as_str()),
        "ownership moved on a NATS restart"
    );
    let publisher_sent = publisher.seq;
    let acks = publisher.finish().await;
    let ok = acks.iter().filter(|a| a.error.is_none()).count();
    let unavailable = acks
        .iter()
        .filter(|a| a.error.as_ref().is_some_and(|e| e.code == 14))
        .count();
    eprintln!(
        "publisher on C: {} acks, {ok} accepted, {unavailable} unavailable during failover",
        acks.len()
    );
    assert_eq!(acks.len() as u64, publisher_sent, "an ack per frame");
    assert_eq!(
        ok + unavailable,
        acks.len(),
        "other refusals: {:?}",
        acks.iter()
            .filter_map(|a| a.error.as_ref())
            .find(|e| e.code != 14)
    );
    assert!(
        unavailable > 0,
        "frames sent while the owner was dead were accepted"
    );
    assert!(ok >= 100, "{ok} accepted");

    // Rooms on tube2 and tube3 owned by B; C lacks both models. tube2's cluster copy is
    // corrupted and tube3's removed: when B dies, C never adopts either.
    let mut bc = b.client().await;
    for (room, model_name) in [("q2", "tube2"), ("q3", "tube3")] {
        bc.open_room(authed(
            v1::OpenRoomRequest {
                room: room.into(),
                model: model_name.into(),
                beta: 0.0,
                filter: None,
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap();
    }
    let store = async_nats::jetstream::new(async_nats::connect(nats.url()).await.unwrap())
        .get_object_store("crease-models")
        .await
        .unwrap();
    let info = store.info("tube2").await.unwrap();
    let mut bytes = model.to_bytes().unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    store
        .put(
            async_nats::jetstream::object_store::ObjectMetadata {
                name: "tube2".into(),
                metadata: info.metadata.clone(),
                ..Default::default()
            },
            &mut bytes.as_slice(),
        )
        .await
        .unwrap();
    store.delete("tube3").await.unwrap();
    for room in ["q2", "q3"] {
        until(Duration::from_secs(5), "listed on C", || async {
            c.owner_of(room).await.as_deref() == Some("B")
        })
        .await;
    }
    b.kill9();
    if new_owner == "B" {
        // C adopts "r" (it holds tube, fetched earlier).
        until(Duration::from_secs(10), "C adopts r", || async {
            c.owner_of("r").await.as_deref() == Some("C")
        })
        .await;
    }
    tokio::time::sleep(Duration::from_secs(6)).await;
    for room in ["q2", "q3"] {
        assert_eq!(
            c.owner_of(room).await.as_deref(),
            Some("B"),
            "C adopted {room} without its model"
        );
        let (status, body) = http_get(c.http, &format!("/api/rooms/{room}")).await;
        assert_eq!(status, 503, "{body}");
        eprintln!("C on {room}: {}", body.trim());
    }
    let (_, body) = http_get(c.http, "/api/rooms/q2").await;
    assert!(body.contains("SHA-256"), "{body}");
}

/// A TCP forwarder from a loopback port to `to` that can cut every connection and refuse new
/// ones (a network partition between one replica and NATS), and heal.
struct Partition {
    port: u16,
    cut: Arc<std::sync::atomic::AtomicBool>,
    /// Bumped on every cut: live connections end when they see it change.
    epoch: Arc<tokio::sync::watch::Sender<u64>>,
}

impl Partition {
    async fn forward_to(to: u16) -> Partition {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let port = listener.local_addr().unwrap().port();
        let cut = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let epoch = Arc::new(tokio::sync::watch::channel(0u64).0);
        let (c, e) = (Arc::clone(&cut), Arc::clone(&epoch));
        tokio::spawn(async move {
            loop {
                let Ok((mut inbound, _)) = listener.accept().await else {
                    return;
                };
                if c.load(std::sync::atomic::Ordering::SeqCst) {
                    continue; // dropped: refused while cut
                }
                let mut cut_seen = e.subscribe();
                tokio::spawn(async move {
                    let Ok(mut outbound) = tokio::net::TcpStream::connect(("127.0.0.1", to)).await
                    else {
                        return;
                    };
                    tokio::select! {
                        _ = tokio::io::copy_bidirectional(&mut inbound, &mut outbound) => {}
                        _ = cut_seen.changed() => {}
                    }
                });
            }
        });
        Partition { port, cut, epoch }
    }

    fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    fn cut(&self) {
        self.cut.store(true, std::sync::atomic::Ordering::SeqCst);
        self.epoch.send_modify(|e| *e += 1);
    }

    fn heal(&self) {
        self.cut.store(false, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Fencing: an owner cut off from NATS keeps serving its own clients, another replica adopts
/// the room, and when the partition heals the old owner yields (its renewal's compare-and-set
/// fails) and relays the new owner's frames: never two owners publishing into one room.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_partitioned_owner_serves_its_own_clients_then_yields_to_the_adopter() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let nats = Nats::start(&nats_bin, free_port(), &dir.path().join("js"));
    let partition = Partition::forward_to(nats.port).await;
    let model = Arc::new(model_with_detail());
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    model.save(models.join("tube.crease")).unwrap();
    let mut d = Replica::start("D", &models, &partition.url(), dir.path());
    let mut e = Replica::start("E", &models, &nats.url(), dir.path());
    d.ready().await;
    e.ready().await;
    let open = v1::OpenRoomRequest {
        room: "p".into(),
        model: "tube".into(),
        beta: 0.0,
        filter: None,
        ..Default::default()
    };
    let token = d
        .client()
        .await
        .open_room(authed(open, ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    until(Duration::from_secs(5), "the room listed on E", || async {
        e.owner_of("p").await.as_deref() == Some("D")
    })
    .await;
    let (on_d, _td) = grpc_viewer(&d, &model, "p", v1::Level::Base).await;
    let (on_e, _te) = grpc_viewer(&e, &model, "p", v1::Level::Base).await;
    let mut publisher = Publisher::new(&d, &model, "p", &token).await;
    publisher
        .send_until(Duration::from_secs(10), "frames on D and E", || {
            frames(&on_d) >= 20 && frames(&on_e) >= 20
        })
        .await;

    // The partition: D keeps its own publisher and viewer; E adopts the room.
    partition.cut();
    let cut = Instant::now();
    let before = frames(&on_d);
    publisher
        .send_until(
            Duration::from_secs(10),
            "E adopts while D is cut off",
            || {
                // `owner_of` is async: E's view is polled below; here D's local service.
                frames(&on_d) >= before + 20
            },
        )
        .await;
    until(Duration::from_secs(10), "adoption by E", || async {
        e.owner_of("p").await.as_deref() == Some("E")
    })
    .await;
    eprintln!(
        "E adopted the room {} ms after the partition",
        cut.elapsed().as_millis()
    );
    assert_eq!(
        http_get(d.http, "/readyz").await.0,
        503,
        "D is unready without NATS"
    );
    let before = frames(&on_d);
    publisher
        .send_until(
            Duration::from_secs(5),
            "D's own viewer while cut off",
            || frames(&on_d) >= before + 10,
        )
        .await;

    // Healed: D's renewal fails, it yields and relays E's frames; only E publishes.
    partition.heal();
    until(Duration::from_secs(15), "D reconnected", || async {
        http_get(d.http, "/readyz").await.0 == 200
    })
    .await;
    until(Duration::from_secs(5), "D sees E as the owner", || async {
        d.owner_of("p").await.as_deref() == Some("E")
    })
    .await;
    let (d0, e0) = (
        d.metric("crease_cluster_nats_frames_out_total").await,
        e.metric("crease_cluster_nats_frames_out_total").await,
    );
    let before = (frames(&on_d), frames(&on_e));
    publisher
        .send_until(
            Duration::from_secs(10),
            "frames on both after the heal",
            || frames(&on_d) >= before.0 + 20 && frames(&on_e) >= before.1 + 20,
        )
        .await;
    assert_eq!(
        d.metric("crease_cluster_nats_frames_out_total").await,
        d0,
        "D published into the cluster after yielding"
    );
    assert!(
        e.metric("crease_cluster_nats_frames_out_total").await > e0,
        "E relays to D"
    );
    assert!(d.metric("crease_cluster_forwarded_controls_total").await > 0.0);
    assert_eq!(e.owner_of("p").await.as_deref(), Some("E"));
    drop(publisher);
}

/// A retargeting room (issue 19) in a cluster: opened on A with a marker map, published to
/// through B (forwarded to A, which retargets the raw markers), then adopted by B after kill -9
/// of A: B rebuilt the room's map from the registry, so the same marker frames go on being
/// acknowledged with a capture-units residual. The room refines and skins with DQS: B's relay
/// and then B as the adopter report both from the registry's entry.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_retargeting_room_is_forwarded_and_survives_its_owner() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let refine = v1::Refine {
        iterations: 3,
        strength: 0.02,
    };
    let dir = tempfile::tempdir().unwrap();
    let _nats = Nats::start(&nats_bin, free_port(), &dir.path().join("js"));
    let model = Arc::new(common::model());
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    model.save(models.join("tube.crease")).unwrap();
    let mut a = Replica::start("A", &models, &_nats.url(), dir.path());
    let mut b = Replica::start("B", &models, &_nats.url(), dir.path());
    for r in [&mut a, &mut b] {
        r.ready().await;
    }
    let names: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    let mut toml = format!(
        "[registration]\npoints = [{}]\ncalibration_frames = 2\n[markers]\n",
        names
            .iter()
            .map(|n| format!("{n:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (i, n) in names.iter().enumerate() {
        toml += &format!("{n} = \"M{i}\"\n");
    }
    let open = v1::OpenRoomRequest {
        room: "mocap".into(),
        model: "tube".into(),
        retarget: Some(v1::Retarget {
            map_toml: toml,
            markers: (0..names.len()).map(|i| format!("M{i}")).collect(),
            units: "mm".into(),
            ..Default::default()
        }),
        // Refining, as the demo's hands room: the adopter must refine as the owner did.
        refine: Some(refine),
        // Skinning with dual quaternions, which the model's default (LBS) is not: the
        // adopter must skin as the owner did (issue 22).
        skinning: v1::Skinning::Dqs as i32,
        ..Default::default()
    };
    let token = a
        .client()
        .await
        .open_room(authed(open, ADMIN))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    until(Duration::from_secs(5), "the room listed on B", || async {
        b.owner_of("mocap").await.as_deref() == Some("A")
    })
    .await;
    // Marker frames in millimetres, sent to B one at a time.
    let frame = |seq: u64| {
        let p = bent(&model.rig.rest, angle(seq));
        v1::ControlFrame {
            room: "mocap".into(),
            seq,
            markers: model
                .controls
                .iter()
                .flat_map(|c| (p[c.vertex as usize] * 1000.0).to_array())
                .collect(),
            ..Default::default()
        }
    };
    let send = |seq: u64| {
        let (b_client, token) = (b.client(), token.clone());
        async move {
            let mut client = b_client.await;
            let mut acks = client
                .publish(authed(tokio_stream::iter(vec![frame(seq)]), &token))
                .await
                .unwrap()
                .into_inner();
            acks.message().await.unwrap().unwrap()
        }
    };
    for seq in 0..10 {
        let ack = send(seq).await;
        assert!(
            ack.error.is_none(),
            "frame {seq} through B: {:?}",
            ack.error
        );
        assert!(
            seq < 2 || ack.control_residual_capture > 0.0 || ack.control_residual == 0.0,
            "frame {seq}: {ack:?}"
        );
    }
    let room_on_b = || async {
        b.client()
            .await
            .get_room(v1::GetRoomRequest {
                room: "mocap".into(),
            })
            .await
            .unwrap()
            .into_inner()
    };
    let relayed = room_on_b().await;
    assert_eq!(
        relayed.refine,
        Some(refine),
        "B's relay reads the registry's refine"
    );
    assert_eq!(
        relayed.skinning,
        v1::Skinning::Dqs as i32,
        "B's relay reads the registry's skinning"
    );
    a.kill9();
    until(Duration::from_secs(10), "B adopts the room", || async {
        b.owner_of("mocap").await.as_deref() == Some("B")
    })
    .await;
    let mut ok = 0;
    for seq in 10..200 {
        let ack = send(seq).await;
        if ack.error.is_none() {
            ok += 1;
            if ok >= 10 {
                break;
            }
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(
        ok >= 10,
        "B acknowledged only {ok} marker frames after the adoption"
    );
    let info = room_on_b().await;
    assert_eq!(info.retarget.unwrap().markers.len(), names.len());
    assert_eq!(
        info.refine,
        Some(refine),
        "the adopter refines as the owner did"
    );
    assert_eq!(
        info.skinning,
        v1::Skinning::Dqs as i32,
        "the adopter skins as the owner did"
    );
    // And so refuses palette streams, as the owner did.
    let err = b
        .client()
        .await
        .subscribe(v1::SubscribeRequest {
            room: "mocap".into(),
            encoding: v1::Encoding::Palette as i32,
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::FailedPrecondition, "{err:?}");
}
