//! The chaos soak's clients, each a loop that outlives every fault: a room's publisher (gRPC,
//! through `crease_remote::publish`, to a random live replica, moving on when its stream fails
//! or no ack comes for a while), plain viewers (gRPC or WebSocket, vertex or palette frames,
//! reading bytes only), the checkers (one decoding gRPC viewer per room on each replica,
//! feeding their [`Watch`](super::accounting::Watch)), the NATS observer (every frame's epoch
//! into the [`EpochCheck`](super::accounting::EpochCheck)) and the RSS sampler.
//!
//! A paused replica accepts connections but answers nothing: every connect, subscribe and
//! read here has a timeout.

use std::ops::ControlFlow;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::Context as _;
use crease_core::codec::{FrameKind, parse_frame};
use crease_core::glam::Vec3;
use crease_proto::errors::ErrorCode;
use crease_proto::{Encoding, v1};
use futures_util::StreamExt as _;
use prost::Message as _;
use rand::Rng as _;
use tokio::time::{Instant, MissedTickBehavior};

use super::memory::Point;
use super::state::{Life, Shared, lock};
use crate::soak::probe;
use crease_remote::mesh_stream::{StreamReader, subscribe_encoded};
use crease_remote::publish::{PublishOptions, Sink, publish};
use crease_remote::{connect, unix_us};

/// Connecting and subscribing may take this long (a paused replica never answers).
const CONNECT: Duration = Duration::from_secs(5);
/// A publisher that gets no ack for this long drops its stream and goes elsewhere: a live
/// capture sends 60 frames a second and each is acked, so a second without one is a replica
/// that stopped (a paused process keeps its socket open; only the silence tells).
const PUBLISH_STALL: Duration = Duration::from_secs(1);
/// A plain viewer that gets no frame for this long goes elsewhere.
const VIEWER_IDLE: Duration = Duration::from_secs(5);

/// The publishers' motion: the model's control points at rest, moved on a slow circle.
#[derive(Debug)]
pub(super) struct Motion {
    /// The control points at rest.
    pub rest: Vec<Vec3>,
    /// The circle's radius.
    pub radius: f32,
    /// Between frames.
    pub period: Duration,
}

impl Motion {
    fn at(&self, room: usize, seq: u64) -> Vec<f32> {
        let t = seq as f32 / 60.0 + room as f32;
        let offset = Vec3::new(t.sin(), (0.7 * t).cos(), (1.3 * t).sin()) * self.radius;
        self.rest
            .iter()
            .flat_map(|p| (*p + offset).to_array())
            .collect()
    }
}

/// Milliseconds since the start.
fn now_ms(shared: &Shared) -> u64 {
    shared.started.elapsed().as_millis() as u64
}

/// Sleeps `d`, in slices, returning early once the soak stops.
async fn pause(shared: &Shared, d: Duration) {
    let until = Instant::now() + d;
    while Instant::now() < until && !shared.stopping() {
        tokio::time::sleep(Duration::from_millis(250).min(until - Instant::now())).await;
    }
}

/// Room `r`'s publisher: `--rate` frames a second through a random live replica; a new
/// stream (to another replica) when its stream fails, no ack comes for [`PUBLISH_STALL`], or
/// the `publisher` fault says so.
pub(super) async fn publisher(shared: Arc<Shared>, r: usize, motion: Arc<Motion>) {
    let ctl = &shared.publishers[r];
    let mut replica = shared.pick_live(None);
    while !shared.stopping() {
        let Some(k) = replica else {
            pause(&shared, Duration::from_millis(500)).await;
            replica = shared.pick_live(None);
            continue;
        };
        ctl.replica.store(k, Ordering::Relaxed);
        let moved = session(&shared, r, k, &motion).await;
        if shared.stopping() {
            break;
        }
        shared
            .counters
            .publisher_reconnects
            .fetch_add(1, Ordering::Relaxed);
        pause(&shared, Duration::from_millis(200)).await;
        replica = shared.pick_live(moved.then_some(k));
    }
}

/// One publishing stream of room `r` through replica `k`; whether it ended to move elsewhere
/// (a stall or the `publisher` fault).
async fn session(shared: &Arc<Shared>, r: usize, k: usize, motion: &Arc<Motion>) -> bool {
    let ctl = &shared.publishers[r];
    let url = &shared.replicas[k].url;
    let Ok(Ok(mut client)) = tokio::time::timeout(CONNECT, connect(url, None)).await else {
        return true;
    };
    let last_ack = AtomicU64::new(now_ms(shared));
    let mut acked = false;
    // Set when this session is over: its source stops sending. Dropping the publish loop does
    // not end a stream whose request is already in flight, and two streams of one room
    // (sharing its seqs) would interleave them.
    let over = Arc::new(AtomicBool::new(false));
    let source = {
        let (shared, motion, over) = (Arc::clone(shared), Arc::clone(motion), Arc::clone(&over));
        move |mut sink: Sink| async move {
            let ctl = &shared.publishers[r];
            let room = shared.rooms[r].id.clone();
            let mut ticker = tokio::time::interval(motion.period);
            ticker.set_missed_tick_behavior(MissedTickBehavior::Skip);
            loop {
                ticker.tick().await;
                if shared.stopping() || over.load(Ordering::Acquire) {
                    break;
                }
                let seq = ctl.seq.fetch_add(1, Ordering::Relaxed) + 1;
                let frame = crease_proto::control::control_frame_flat(
                    &room,
                    seq,
                    unix_us(),
                    motion.at(r, seq),
                );
                if sink.send(frame).await.is_err() {
                    break;
                }
                shared.counters.sent.fetch_add(1, Ordering::Relaxed);
            }
        }
    };
    let mut on_ack = |ack: v1::PublishAck| {
        last_ack.store(now_ms(shared), Ordering::Relaxed);
        if !acked {
            acked = true;
            ctl.sessions.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(e) = &ack.error {
            if ErrorCode::from_wire(e.code) == Some(ErrorCode::Aborted) {
                shared.counters.superseded.fetch_add(1, Ordering::Relaxed);
            } else {
                let why = e.message.split(':').next().unwrap_or("").to_owned();
                *lock(&shared.counters.refused).entry(why).or_default() += 1;
            }
        }
        ControlFlow::Continue(())
    };
    let options = PublishOptions {
        queue: 8,
        drain: Some(Duration::from_secs(1)),
    };
    let token = shared.rooms[r].token.clone();
    let watchdog = async {
        loop {
            tokio::time::sleep(Duration::from_millis(250)).await;
            if shared.stopping() {
                return false;
            }
            if ctl.drop_now.swap(false, Ordering::Relaxed) {
                return true;
            }
            let idle = now_ms(shared).saturating_sub(last_ack.load(Ordering::Relaxed));
            if idle > PUBLISH_STALL.as_millis() as u64 {
                shared
                    .counters
                    .publisher_stalls
                    .fetch_add(1, Ordering::Relaxed);
                return true;
            }
        }
    };
    // The stream ends on its own when it fails; the watchdog drops it (and stops its source)
    // when it stalls or must move.
    let moved = tokio::select! {
        _ = publish(&mut client, &token, options, source, &mut on_ack) => false,
        moved = watchdog => moved,
    };
    over.store(true, Ordering::Release);
    moved
}

/// A plain viewer of room `room`: watches through its home replica (`v` modulo the replicas)
/// until its connection fails or goes quiet, then through a random live one, and back home
/// once home is up again (so each replica serves the same viewers whenever it is up, and its
/// memory is judged at a steady load: `memory`).
pub(super) async fn viewer(shared: Arc<Shared>, v: usize, room: usize) {
    let (ws, palette) = {
        let mut rng = rand::rng();
        (rng.random_bool(0.5), rng.random_bool(0.3))
    };
    let encoding = if palette {
        Encoding::Palette
    } else {
        Encoding::Vertices
    };
    // Spread the first connections over two seconds.
    pause(&shared, Duration::from_millis((v as u64 * 37) % 2000)).await;
    let home = v % shared.replicas.len();
    let mut replica = Some(home);
    while !shared.stopping() {
        match replica {
            Some(k) if shared.replicas[k].life() == Life::Up => {
                let room = &shared.rooms[room].id;
                // Away from home: back as soon as home is up.
                let leave = || k != home && shared.replicas[home].life() == Life::Up;
                let viewers = &shared.replicas[k].viewers;
                viewers.fetch_add(1, Ordering::Relaxed);
                let _ = if ws {
                    watch_ws(&shared, k, room, encoding, leave).await
                } else {
                    watch_grpc(&shared, k, room, encoding, leave).await
                };
                viewers.fetch_sub(1, Ordering::Relaxed);
                if shared.stopping() {
                    break;
                }
                shared
                    .counters
                    .viewer_reconnects
                    .fetch_add(1, Ordering::Relaxed);
                let backoff = rand::rng().random_range(200..1000);
                pause(&shared, Duration::from_millis(backoff)).await;
            }
            _ => pause(&shared, Duration::from_millis(500)).await,
        }
        replica = if shared.replicas[home].life() == Life::Up {
            Some(home)
        } else {
            shared.pick_live(None)
        };
    }
}

async fn watch_grpc(
    shared: &Shared,
    k: usize,
    room: &str,
    encoding: Encoding,
    leave: impl Fn() -> bool,
) -> anyhow::Result<()> {
    let url = &shared.replicas[k].url;
    let subscribed = async {
        let mut client = connect(url, None).await?;
        subscribe_encoded(&mut client, room, v1::Level::Base, encoding).await
    };
    let mut sub = tokio::time::timeout(CONNECT, subscribed)
        .await
        .context("subscribing: timed out")??;
    let mut last = Instant::now();
    while !shared.stopping() && !leave() && last.elapsed() < VIEWER_IDLE {
        match tokio::time::timeout(Duration::from_secs(1), sub.next_frame()).await {
            Ok(Ok(Some(_))) => {
                last = Instant::now();
                shared
                    .counters
                    .viewer_frames
                    .fetch_add(1, Ordering::Relaxed);
            }
            Ok(Ok(None) | Err(_)) => break,
            Err(_) => {}
        }
    }
    Ok(())
}

async fn watch_ws(
    shared: &Shared,
    k: usize,
    room: &str,
    encoding: Encoding,
    leave: impl Fn() -> bool,
) -> anyhow::Result<()> {
    let url = format!(
        "ws://{}/ws/rooms/{room}?level=base&encoding={}",
        shared.replicas[k].http,
        encoding.name()
    );
    let (mut socket, _) = tokio::time::timeout(CONNECT, tokio_tungstenite::connect_async(url))
        .await
        .context("connecting: timed out")??;
    let mut last = Instant::now();
    while !shared.stopping() && !leave() && last.elapsed() < VIEWER_IDLE {
        match tokio::time::timeout(Duration::from_secs(1), socket.next()).await {
            Ok(Some(Ok(tokio_tungstenite::tungstenite::Message::Binary(b)))) => {
                if let Ok(v1::MeshFrame {
                    body: Some(v1::mesh_frame::Body::Frame(_)),
                }) = v1::MeshFrame::decode(b.as_ref())
                {
                    last = Instant::now();
                    shared
                        .counters
                        .viewer_frames
                        .fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(Some(Ok(_))) | Err(_) => {}
            Ok(None | Some(Err(_))) => break,
        }
    }
    let _ = tokio::time::timeout(Duration::from_secs(1), socket.close(None)).await;
    Ok(())
}

/// The checker of room `r` on replica `k`: a gRPC vertex subscription that decodes every frame
/// and records it in its watch; it subscribes again (to the same replica) whenever its stream
/// ends or fails, once the replica is up.
pub(super) async fn checker(shared: Arc<Shared>, r: usize, k: usize) {
    let room = shared.rooms[r].id.clone();
    let url = shared.replicas[k].url.clone();
    while !shared.stopping() {
        if shared.replicas[k].life() != Life::Up {
            pause(&shared, Duration::from_millis(100)).await;
            continue;
        }
        let subscribed = async {
            let mut client = connect(&url, None).await?;
            let sub =
                subscribe_encoded(&mut client, &room, v1::Level::Base, Encoding::Vertices).await?;
            let reader = StreamReader::new(&sub.first)?;
            anyhow::Ok((sub, reader))
        };
        let (mut sub, mut reader) = match tokio::time::timeout(CONNECT, subscribed).await {
            Ok(Ok(s)) => s,
            _ => {
                shared
                    .counters
                    .checker_refusals
                    .fetch_add(1, Ordering::Relaxed);
                pause(&shared, Duration::from_millis(250)).await;
                continue;
            }
        };
        shared.watch(r, k).subscribed();
        while !shared.stopping() {
            match tokio::time::timeout(Duration::from_secs(1), sub.next_frame()).await {
                Ok(Ok(Some(frame))) => {
                    let t = shared.now();
                    let key = parse_frame(&frame.data)
                        .is_ok_and(|(h, _)| matches!(h.kind, FrameKind::Key));
                    let decoded = reader.decode(&frame.data).is_ok();
                    let violation = shared.watch(r, k).frame(t, frame.seq, decoded, key);
                    if let Some(v) = violation {
                        eprintln!(
                            "chaos {t:7.1} s: ORDER room {room} on {}: seq {} after {} ({} behind)",
                            shared.replicas[k].id,
                            v.seq,
                            v.previous,
                            v.previous - v.seq
                        );
                    }
                }
                Ok(Ok(None) | Err(_)) => break,
                Err(_) => {}
            }
        }
    }
}

/// The NATS observer: every frame on `crease.frames.>`, its room and its owner and epoch
/// headers, into the epoch check. Reconnects on its own (async-nats) when NATS restarts.
pub(super) async fn observer(shared: Arc<Shared>, url: String) -> anyhow::Result<()> {
    let client = async_nats::ConnectOptions::new()
        .name("crease bench-net --chaos observer")
        .max_reconnects(None)
        .retry_on_initial_connect()
        .connect(&url)
        .await
        .with_context(|| format!("the NATS observer connecting to {url}"))?;
    let mut frames = client
        .subscribe("crease.frames.>")
        .await
        .context("the NATS observer subscribing to crease.frames.>")?;
    while !shared.stopping() {
        let msg = match tokio::time::timeout(Duration::from_secs(1), frames.next()).await {
            Ok(Some(msg)) => msg,
            Ok(None) => break,
            Err(_) => continue,
        };
        // crease.frames.<room>.<channel>
        let room = msg.subject.split('.').nth(2).unwrap_or("");
        let label = msg.headers.as_ref().and_then(|h| {
            let owner = h.get("Crease-Owner")?.as_str();
            let epoch = h.get("Crease-Epoch")?.as_str().parse().ok()?;
            Some((owner, epoch))
        });
        // The frame's seq tells a late frame (from before a hand-over) from split brain.
        // Decoded from the payload's own `Bytes`: the frame's data is a slice of it, not a copy.
        let seq = match v1::MeshFrame::decode(msg.payload.clone()) {
            Ok(v1::MeshFrame {
                body: Some(v1::mesh_frame::Body::Frame(f)),
            }) => Some(f.seq),
            _ => None,
        };
        let t = shared.now();
        let split = lock(&shared.epochs).frame(t, room, label, seq);
        if let Some(v) = split {
            eprintln!(
                "chaos {t:7.1} s: SPLIT BRAIN room {}: a frame of {} in epoch {} after epoch {} of {}",
                v.room, v.owner, v.epoch, v.newest, v.newest_owner
            );
        }
    }
    Ok(())
}

/// Every `every`, each live replica's RSS (and fds, threads, tasks: the soak's probe),
/// concurrently (a paused replica's `/metrics` times out).
pub(super) async fn sampler(shared: Arc<Shared>, every: Duration) {
    let mut ticker = tokio::time::interval(every);
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    while !shared.stopping() {
        ticker.tick().await;
        let probes = shared.replicas.iter().map(|r| {
            let pid = r.pid.load(Ordering::Relaxed);
            let (http, started) = (r.http, shared.started);
            async move {
                match pid {
                    0 => None,
                    pid => probe::sample(pid, http, started).await,
                }
            }
        });
        let samples = futures_util::future::join_all(probes).await;
        let rss: Vec<String> = samples
            .iter()
            .zip(&shared.replicas)
            .map(|(s, r)| match s {
                Some(s) => format!(
                    "{} {:.0} ({} threads, {} fds)",
                    r.id, s.rss_mib, s.threads, s.fds
                ),
                None => format!("{} -", r.id),
            })
            .collect();
        // The rooms each replica owns now: its RSS follows them (a pipeline per owned room).
        let (nats, split, owned) = {
            let e = lock(&shared.epochs);
            let mut owned = vec![0; shared.replicas.len()];
            for (_, owner) in e.owners() {
                if let Some(k) = shared.replica_of(owner) {
                    owned[k] += 1;
                }
            }
            (e.frames, e.split.len(), owned)
        };
        {
            let mut all = lock(&shared.memory);
            for (k, s) in samples.into_iter().enumerate() {
                if let (Some(s), Some(list)) = (s, all.get_mut(k)) {
                    list.push(Point {
                        t: s.t,
                        rss_mib: s.rss_mib,
                        owned: owned[k],
                        viewers: shared.replicas[k].viewers.load(Ordering::Relaxed),
                        life: shared.replicas[k].deaths.load(Ordering::Relaxed),
                    });
                }
            }
        }
        let (frames, order) = shared.checkers.iter().fold((0, 0), |(f, o), w| {
            let w = lock(w);
            (f + w.frames, o + w.out_of_order.len())
        });
        eprintln!(
            "chaos {:7.1} s: rss MiB {}; frames {frames} (checkers), {nats} (NATS); out of order {order}, split brain {split}",
            shared.now(),
            rss.join(", ")
        );
    }
}

/// The owner of room `room` as a live replica's `GetRoom` says.
pub(super) async fn owner_of(shared: &Shared, room: &str) -> Option<usize> {
    for _ in 0..3 {
        let k = shared.pick_live(None)?;
        let ask = async {
            let mut client = connect(&shared.replicas[k].url, None).await.ok()?;
            let info = crease_remote::get_room(&mut client, room).await.ok()?;
            shared.replica_of(&info.owner)
        };
        if let Ok(Some(owner)) = tokio::time::timeout(CONNECT, ask).await {
            return Some(owner);
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    None
}
