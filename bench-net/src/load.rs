//! The load of `crease bench-net`: per scenario, the rooms opened, one publisher per room
//! sending control frames at a fixed rate, subscribers each on its own connection reading (and
//! the first of each room decoding) the mesh frames, and what they saw summarised into a
//! [`ScenarioReport`].

use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use crease_core::codec::{FrameKind, parse_frame};
use crease_proto::v1::crease_client::CreaseClient;
use crease_proto::{Encoding, v1};
use tokio::task::JoinSet;
use tokio::time::{Instant, MissedTickBehavior};
use tonic::transport::Channel;

use super::args::{BenchNetArgs, Scenario, Transport};
use super::floor;
use super::report::{Cpu, FrameBytes, Percentiles, ReplicaFigures, ScenarioReport, Spread};
use super::server::{Target, clock_ticks, cpu_seconds, random_token};
use crease_remote::mesh_stream::{self, StreamReader, Subscription};
use crease_remote::publish::{PublishOptions, Sink, publish};
use crease_remote::{authorized, connect, unix_us};

/// The longest the floor is measured for (its figure settles within a second or two).
const FLOOR_SECONDS: f64 = 5.0;

/// Control frames queued per publisher before it waits: a few periods, so a slow ack stream
/// shows up as late sends instead of a growing queue.
const PUBLISH_QUEUE: usize = 8;

/// When frames count: from `start` (after the warm-up) to `end`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Window {
    start: Instant,
    end: Instant,
}

impl Window {
    fn contains(&self, t: Instant) -> bool {
        self.start <= t && t < self.end
    }
}

/// What a publisher saw.
#[derive(Debug, Default)]
struct PublisherStats {
    sent_in_window: u64,
    refused: u64,
    first_refusal: Option<String>,
    /// (seq, `PublishAck.server_latency_us`) of the acks read in the window.
    acks: Vec<(u64, u32)>,
}

/// Publishes `frames` (looped) into `room` at `rate` from `first_tick` until the window ends,
/// reading the acks.
async fn publisher(
    url: String,
    room: String,
    token: String,
    frames: Arc<Vec<v1::ControlFrame>>,
    period: Duration,
    first_tick: Instant,
    window: Window,
) -> anyhow::Result<PublisherStats> {
    let mut client = connect(&url, None).await?;
    let source = move |mut sink: Sink| async move {
        let mut ticker = tokio::time::interval_at(first_tick, period);
        // A late tick is dropped, not made up by a burst that would distort the latency.
        ticker.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut sent_in_window = 0u64;
        for seq in 0u64.. {
            if ticker.tick().await >= window.end {
                break;
            }
            let mut frame = frames[(seq % frames.len() as u64) as usize].clone();
            frame.room.clone_from(&room);
            frame.seq = seq;
            frame.capture_time_us = unix_us();
            if sink.send(frame).await.is_err() {
                break;
            }
            sent_in_window += u64::from(window.contains(Instant::now()));
        }
        sent_in_window
    };
    let mut stats = PublisherStats::default();
    let mut on_ack = |ack: v1::PublishAck| {
        match ack.error {
            Some(e) => {
                stats.refused += 1;
                stats.first_refusal.get_or_insert_with(|| {
                    format!("frame {} (code {}): {}", ack.seq, e.code, e.message)
                });
            }
            None if window.contains(Instant::now()) => {
                stats.acks.push((ack.seq, ack.server_latency_us));
            }
            None => {}
        }
        ControlFlow::Continue(())
    };
    let options = PublishOptions {
        queue: PUBLISH_QUEUE,
        drain: None,
    };
    // The ack stream ends when the source stops and the server has answered every frame.
    let published = publish(&mut client, &token, options, source, &mut on_ack)
        .await
        .map_err(|e| e.into_anyhow("the room's token", "publishing", "the publisher task"))?;
    if let Some(status) = published.status {
        return Err(anyhow::Error::new(status).context("reading acks"));
    }
    stats.sent_in_window = published.output;
    Ok(stats)
}

/// What a subscriber saw.
#[derive(Debug, Default)]
struct SubscriberStats {
    frames: u64,
    skipped: u64,
    key: (u64, u64),
    delta: (u64, u64),
    /// Per frame read in the window: (seq, server latency, client latency), microseconds.
    latency: Vec<(u64, u32, u32)>,
    decoded: u64,
    decode_errors: u64,
    first_decode_error: Option<String>,
}

/// A subscribed stream, its topology read.
struct Subscribed {
    // Holds a gRPC subscriber's connection for the stream's life.
    _client: Option<CreaseClient<Channel>>,
    sub: Subscription,
    /// The decoders (one per actor) of the subscriber that checks its room's frames.
    readers: Vec<StreamReader>,
    /// Vertices per frame, every actor's.
    vertices: usize,
}

/// Connects on its own connection and subscribes to `room`'s `level` in `encoding`; with
/// `check`, reads the first message to decode the frames (the other subscribers only count
/// bytes).
async fn subscribe(
    target: (String, Option<std::net::SocketAddr>),
    transport: Transport,
    room: String,
    check: bool,
    level: v1::Level,
    encoding: Encoding,
) -> anyhow::Result<Subscribed> {
    let (url, http) = target;
    let (client, sub) = match transport {
        Transport::Grpc => {
            let mut client = connect(&url, None).await?;
            let sub = mesh_stream::subscribe_encoded(&mut client, &room, level, encoding).await?;
            (Some(client), sub)
        }
        Transport::WebSocket => {
            let http = http.with_context(|| {
                format!("{url}: no HTTP address for --transport ws (give --server-http)")
            })?;
            let sub = mesh_stream::subscribe_ws(&http.to_string(), &room, level, encoding).await?;
            (None, sub)
        }
    };
    let readers = if check {
        sub.stream_readers()
            .with_context(|| format!("room {room:?}: first message"))?
    } else {
        Vec::new()
    };
    Ok(Subscribed {
        _client: client,
        vertices: sub.vertex_count() * sub.actors.len().max(1),
        sub,
        readers,
    })
}

/// Reads frames until the window ends, recording those that arrive inside it; decodes every
/// frame when the subscriber checks them.
async fn read_frames(mut sub: Subscribed, window: Window) -> anyhow::Result<SubscriberStats> {
    let mut stats = SubscriberStats::default();
    loop {
        let f = tokio::select! {
            f = sub.sub.next_frame() => f.context("reading mesh frames")?,
            () = tokio::time::sleep_until(window.end) => break,
        };
        let Some(f) = f else {
            break;
        };
        let now = Instant::now();
        let now_us = unix_us();
        if !sub.readers.is_empty() {
            let decoded = if f.actors.is_empty() {
                sub.readers[0].decode(&f.data)
            } else {
                f.actors
                    .iter()
                    .try_for_each(|a| match sub.readers.get_mut(a.actor as usize) {
                        Some(r) => r.decode(&a.data),
                        None => bail!("actor {} of {}", a.actor, sub.readers.len()),
                    })
            };
            match decoded {
                Ok(()) => stats.decoded += 1,
                Err(e) => {
                    stats.decode_errors += 1;
                    stats
                        .first_decode_error
                        .get_or_insert_with(|| format!("frame {}: {e}", f.seq));
                }
            }
        }
        if !window.contains(now) {
            continue;
        }
        stats.frames += 1;
        stats.skipped += u64::from(f.skipped);
        let client_us = (now_us - f.capture_time_us).clamp(0, i64::from(u32::MAX)) as u32;
        stats.latency.push((f.seq, f.server_latency_us, client_us));
        // A room of several actors: every actor's bytes; a keyframe when actor 0's is one.
        let len = (f.data.len() + f.actors.iter().map(|a| a.data.len()).sum::<usize>()) as u64;
        let first = f.actors.first().map_or(&f.data, |a| &a.data);
        match parse_frame(first).map(|(h, _)| h.kind) {
            Ok(FrameKind::Key) => stats.key = (stats.key.0 + 1, stats.key.1 + len),
            Ok(FrameKind::Delta) => stats.delta = (stats.delta.0 + 1, stats.delta.1 + len),
            Err(e) => bail!("frame {}: not a codec frame: {e}", f.seq),
        }
    }
    Ok(stats)
}

/// A metric's value from a server's `/metrics` (a plain HTTP/1.1 GET), if it has it.
async fn metric(http: std::net::SocketAddr, name: &str) -> Option<f64> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(http).await.ok()?;
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: bench\r\nConnection: close\r\n\r\n")
        .await
        .ok()?;
    let mut text = String::new();
    s.read_to_string(&mut text).await.ok()?;
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' '))
        .and_then(|v| v.trim().parse().ok())
}

/// Actor `k`'s name in a room of several actors (`--actors`).
fn actor_name(k: u32) -> String {
    format!("a{k}")
}

/// `frames` as frames of a room of `actors` actors (`--actors`): each frame's points as every
/// actor's part, reflected across x for the odd (mirrored) ones. One actor: `frames` as they are.
pub(super) fn actor_frames(frames: &[v1::ControlFrame], actors: u32) -> Vec<v1::ControlFrame> {
    if actors <= 1 {
        return frames.to_vec();
    }
    frames
        .iter()
        .map(|f| {
            let parts = (0..actors)
                .map(|k| {
                    let mut part = f.clone();
                    if k % 2 == 1 {
                        part.positions
                            .chunks_exact_mut(3)
                            .for_each(|p| p[0] = -p[0]);
                    }
                    crease_proto::control::actor_controls(&actor_name(k), part)
                })
                .collect();
            crease_proto::control::with_actors(f.clone(), parts)
        })
        .collect()
}

/// The owner's NATS bytes so far (cluster scenarios).
const NATS_BYTES: &str = "crease_cluster_nats_bytes_out_total";

/// Opens the rooms (on the first server), connects the subscribers (spread over the first
/// `sc.spread` servers), publishes for warm-up + window, and summarises.
pub(super) async fn run_scenario(
    targets: &[Target],
    sc: &Scenario,
    frames: &Arc<Vec<v1::ControlFrame>>,
    args: &BenchNetArgs,
) -> anyhow::Result<ScenarioReport> {
    let target = &targets[0];
    let mut admin = connect(&target.url, None).await?;
    let tag = &random_token()[..6];
    let mut rooms = Vec::with_capacity(sc.rooms);
    for k in 0..sc.rooms {
        let id = format!("bench-{tag}-{}-{k}", sc.name);
        let open = if args.actors > 1 {
            v1::OpenRoomRequest {
                room: id.clone(),
                actors: (0..args.actors)
                    .map(|k| v1::Actor {
                        refine: Some(crease_proto::room::refine_wire(args.refine.0)),
                        ..crease_proto::room::actor(&actor_name(k), &target.model, k % 2 == 1)
                    })
                    .collect(),
                ..Default::default()
            }
        } else {
            v1::OpenRoomRequest {
                room: id.clone(),
                model: target.model.clone(),
                beta: 0.0,
                filter: None,
                refine: Some(crease_proto::room::refine_wire(args.refine.0)),
                ..Default::default()
            }
        };
        let opened = admin
            .open_room(authorized(open, &target.admin_token)?)
            .await
            .with_context(|| format!("opening room {id:?} on model {:?}", target.model))?
            .into_inner();
        rooms.push((id, opened.publish_token));
    }
    // The other replicas learn of the rooms through the registry.
    for other in &targets[1..sc.spread.min(targets.len())] {
        let mut client = connect(&other.url, None).await?;
        let deadline = Instant::now() + Duration::from_secs(10);
        for (id, _) in &rooms {
            while client
                .get_room(v1::GetRoomRequest { room: id.clone() })
                .await
                .is_err()
            {
                if Instant::now() > deadline {
                    bail!("{}: room {id:?} not known there after 10 s", other.url);
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
    let result = drive(targets, sc, frames, args, &rooms).await;
    for (id, _) in &rooms {
        let close = v1::CloseRoomRequest { room: id.clone() };
        // The rooms die with a spawned server anyway; a running one keeps what fails here.
        if let Err(e) = admin
            .close_room(authorized(close, &target.admin_token)?)
            .await
        {
            eprintln!("closing room {id:?}: {}", e.message());
        }
    }
    result
}

async fn drive(
    targets: &[Target],
    sc: &Scenario,
    frames: &Arc<Vec<v1::ControlFrame>>,
    args: &BenchNetArgs,
    rooms: &[(String, String)],
) -> anyhow::Result<ScenarioReport> {
    // Every subscriber on its own connection, subscribed before the first frame.
    let target = &targets[0];
    let spread = sc.spread.clamp(1, targets.len());
    let replica_of = |s: usize| s % spread;
    let level = match args.level.as_str() {
        "detail" => v1::Level::Detail,
        _ => v1::Level::Base,
    };
    let encoding = Encoding::from_query(Some(&args.encoding))?;
    let mut connecting = JoinSet::new();
    for (r, (id, _)) in rooms.iter().enumerate() {
        for s in 0..sc.subscribers {
            let to = &targets[replica_of(s)];
            let (to, id) = ((to.url.clone(), to.http), id.clone());
            // One checking (decoding) subscriber per room and replica.
            let check = s < spread;
            let (level, encoding, transport) = (level, encoding, sc.transport);
            connecting.spawn(async move {
                let sub = subscribe(to, transport, id, check, level, encoding).await;
                (r, s, sub)
            });
        }
    }
    let mut subscribed = Vec::with_capacity(rooms.len() * sc.subscribers);
    while let Some(done) = connecting.join_next().await {
        let (r, s, sub) = done.context("a subscriber task")?;
        subscribed.push((
            r,
            s,
            sub.with_context(|| format!("subscriber {s} of room {r}"))?,
        ));
    }
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let t0 = Instant::now();
    let start = t0 + Duration::from_secs_f64(args.warmup);
    let window = Window {
        start,
        end: start + Duration::from_secs_f64(args.seconds),
    };
    let mut readers = JoinSet::new();
    let mut vertices = 0;
    for (r, s, sub) in subscribed {
        vertices = sub.vertices;
        readers.spawn(async move { (r, s, read_frames(sub, window).await) });
    }
    let mut publishers = JoinSet::new();
    for (k, (id, token)) in rooms.iter().enumerate() {
        // Rooms publish at evenly spread phases of the period, as independent publishers would
        // rather than all on the same tick.
        let first_tick = t0 + period.mul_f64(k as f64 / rooms.len() as f64);
        let task = publisher(
            target.url.clone(),
            id.clone(),
            token.clone(),
            Arc::clone(frames),
            period,
            first_tick,
            window,
        );
        publishers.spawn(async move { (k, task.await) });
    }
    // CPU of the server and of this process over the window.
    let hz = clock_ticks();
    let me = std::process::id();
    let sample = |pid: Option<u32>| pid.and_then(|p| cpu_seconds(p, hz));
    tokio::time::sleep_until(window.start).await;
    let nats_bytes = || async {
        match target.http {
            Some(http) if spread > 1 => metric(http, NATS_BYTES).await,
            _ => None,
        }
    };
    let nats0 = nats_bytes().await;
    let replicas0: Vec<Option<f64>> = targets[..spread].iter().map(|t| sample(t.pid)).collect();
    let (server0, client0, wall0) = (sample(target.pid), sample(Some(me)), Instant::now());
    tokio::time::sleep_until(window.end).await;
    let (server1, client1, wall1) = (sample(target.pid), sample(Some(me)), Instant::now());
    let replicas1: Vec<Option<f64>> = targets[..spread].iter().map(|t| sample(t.pid)).collect();
    let nats1 = nats_bytes().await;
    let seconds = (wall1 - wall0).as_secs_f64();

    // Publishers by room index; subscribers with their room's.
    let mut pubs: Vec<PublisherStats> = rooms.iter().map(|_| PublisherStats::default()).collect();
    while let Some(done) = publishers.join_next().await {
        let (k, stats) = done.context("a publisher task")?;
        pubs[k] = stats.with_context(|| format!("publisher of room {k}"))?;
    }
    let mut subs = Vec::with_capacity(rooms.len() * sc.subscribers);
    let mut by_replica: Vec<Vec<Vec<(u32, u32)>>> = vec![Vec::new(); spread];
    while let Some(done) = readers.join_next().await {
        let (r, s, stats) = done.context("a subscriber task")?;
        let stats = stats.with_context(|| format!("subscriber {s} of room {r}"))?;
        by_replica[replica_of(s)].push(
            stats
                .latency
                .iter()
                .map(|&(_, server, client)| (server, client))
                .collect::<Vec<_>>(),
        );
        subs.push((r, stats));
    }
    let frames_published: u64 = pubs.iter().map(|p| p.sent_in_window).sum();
    let cpu = |a: Option<f64>, b: Option<f64>| {
        let used = b? - a?;
        Some(Cpu {
            cores: used / seconds,
            ms_per_frame: used * 1e3 / frames_published.max(1) as f64,
        })
    };
    let mut server_latency: Vec<u32> = Vec::new();
    let mut client_latency: Vec<u32> = Vec::new();
    let mut fan_out: Vec<u32> = Vec::new();
    let mut outside: Vec<u32> = Vec::new();
    for (r, sub) in &subs {
        let acks = &pubs[*r].acks;
        for &(seq, server, client) in &sub.latency {
            server_latency.push(server);
            client_latency.push(client);
            outside.push(client.saturating_sub(server));
            // Acks come in seq order.
            if let Ok(k) = acks.binary_search_by_key(&seq, |a| a.0) {
                fan_out.push(server.saturating_sub(acks[k].1));
            }
        }
    }
    let mut ack_latency: Vec<u32> = pubs
        .iter()
        .flat_map(|p| p.acks.iter().map(|a| a.1))
        .collect();
    let (key, delta) = subs.iter().fold(((0, 0), (0, 0)), |(k, d), (_, s)| {
        (
            (k.0 + s.key.0, k.1 + s.key.1),
            (d.0 + s.delta.0, d.1 + s.delta.1),
        )
    });
    let frames_received = key.0 + delta.0;
    // The floor of this fan-out, measured now on the same machine: a write per viewer-frame.
    let sockets = rooms.len() * sc.subscribers;
    let mean_bytes = ((key.1 + delta.1) / frames_received.max(1)) as usize;
    let floor = floor::measure(
        sockets,
        mean_bytes,
        args.rate,
        args.seconds.min(FLOOR_SECONDS),
    )
    .await
    .context("measuring the fan-out's floor")?;
    let server_cpu = cpu(server0, server1);
    let server_us_per_viewer_frame = match (server0, server1) {
        (Some(a), Some(b)) if frames_received > 0 => Some((b - a) * 1e6 / frames_received as f64),
        _ => None,
    };
    let replicas = if spread > 1 {
        by_replica
            .iter()
            .enumerate()
            .map(|(k, subs)| {
                let mut server: Vec<u32> = subs.iter().flatten().map(|l| l.0).collect();
                let mut client: Vec<u32> = subs.iter().flatten().map(|l| l.1).collect();
                ReplicaFigures {
                    replica: k,
                    subscribers: subs.len(),
                    server_latency_us: Percentiles::of(&mut server),
                    client_latency_us: Percentiles::of(&mut client),
                    cpu: cpu(replicas0[k], replicas1[k]),
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    let nats_bytes_per_frame = match (nats0, nats1) {
        (Some(a), Some(b)) => Some((b - a) / frames_published.max(1) as f64),
        _ => None,
    };
    Ok(ScenarioReport {
        replicas,
        nats_bytes_per_frame,
        name: sc.name.clone(),
        rooms: sc.rooms,
        subscribers_per_room: sc.subscribers,
        rate_hz: args.rate,
        seconds,
        frames_published,
        published_per_room: Spread::of(pubs.iter().map(|p| p.sent_in_window)),
        frames_refused: pubs.iter().map(|p| p.refused).sum(),
        first_refusal: pubs.iter().find_map(|p| p.first_refusal.clone()),
        frames_received,
        received_per_subscriber: Spread::of(subs.iter().map(|(_, s)| s.frames)),
        frames_skipped: subs.iter().map(|(_, s)| s.skipped).sum(),
        server_latency_us: Percentiles::of(&mut server_latency),
        client_latency_us: Percentiles::of(&mut client_latency),
        ack_latency_us: Percentiles::of(&mut ack_latency),
        fan_out_us: Percentiles::of(&mut fan_out),
        outside_server_us: Percentiles::of(&mut outside),
        server_cpu,
        transport: sc.transport.name().to_owned(),
        server_cpu_us_per_viewer_frame: server_us_per_viewer_frame,
        floor_ratio: server_us_per_viewer_frame
            .zip(floor.cpu_us_per_write)
            .map(|(us, f)| us / f),
        floor,
        client_cpu: cpu(client0, client1),
        all_frames: FrameBytes::new(frames_received, key.1 + delta.1, vertices),
        keyframes: FrameBytes::new(key.0, key.1, vertices),
        deltas: FrameBytes::new(delta.0, delta.1, vertices),
        bytes_per_second: (key.1 + delta.1) as f64 / seconds,
        decoded_frames: subs.iter().map(|(_, s)| s.decoded).sum(),
        decode_errors: subs.iter().map(|(_, s)| s.decode_errors).sum(),
        first_decode_error: subs.iter().find_map(|(_, s)| s.first_decode_error.clone()),
    })
}
