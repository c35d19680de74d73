//! `crease bench-net --soak MINUTES`: the server held under churn and faults for a long time
//! (issue 21). Against a spawned `crease-server` (limits raised so one address may hold them
//! all):
//!
//! - **rooms**: `--soak-rooms` base rooms (20) and `--soak-detail-rooms` (2) whose viewers
//!   watch the detail level (a model with a detail layer), one publisher each at `--rate`
//!   (60 Hz) over gRPC; every publisher drops its stream and reconnects every 10-40 s; about 1
//!   frame in 100 is malformed (a wrong count, a NaN in a valid point) and must be refused. One
//!   more room is opened and closed again every 15 s.
//! - **viewers**: `--soak-viewers` (200), each a loop: join a random room over gRPC or the
//!   WebSocket, in vertex or palette frames, watch 5-40 s (stalling, reading nothing, for 1-8 s
//!   now and then), leave, wait up to 2 s, join again.
//! - **checkers**: one gRPC viewer per room that decodes every frame it receives
//!   (`mesh_stream::StreamReader`) and checks the mesh is finite; a room whose checker sees no
//!   frame for 5 s while its publisher is sending is stuck.
//! - **samples**: every `--sample-seconds` (5) the server's RSS, open file descriptors and
//!   threads (`/proc`) and its runtime's alive tasks (`crease_tasks` in `/metrics`).
//!
//! It fails (the report says why, the exit status is 1) on a server panic or exit, a non-finite
//! mesh, a stuck room, a malformed frame accepted, RSS growth over 5% from the minute that
//! ends one sixth of the run (5 minutes of a 30-minute run) to the last minute (peaks
//! compared), or a server that still holds more file descriptors or tasks than before the
//! clients came, 30 s after they all left (a session that outlives its client).

use std::ops::ControlFlow;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_proto::errors::ErrorCode;
use crease_proto::{Encoding, v1};
use futures_util::StreamExt as _;
use prost::Message as _;
use rand::Rng as _;
use tokio::task::JoinSet;
use tokio::time::{Instant, MissedTickBehavior};

use super::args::BenchNetArgs;
use super::server::{SOAK_LIMITS, Target, random_token, spawn_server_with};
use crease_remote::mesh_stream::{StreamReader, subscribe_encoded};
use crease_remote::publish::{PublishError, PublishOptions, Sink, publish};
use crease_remote::{authorized, connect, unix_us};

// The chaos soak samples its replicas with the same probe.
pub(crate) mod probe;

pub(super) use probe::Sample;
use probe::{SETTLE, rss_peak, sample, settle};

/// A checker that sees no frame for this long, while its room's publisher sends, is stuck.
const STUCK: Duration = Duration::from_secs(5);
/// One frame in this many is malformed.
const MALFORMED_EVERY: u64 = 100;
/// What the soak counted; shared by its tasks.
#[derive(Debug, Default)]
struct Counters {
    joins: AtomicU64,
    leaves: AtomicU64,
    join_refused: AtomicU64,
    frames_seen: AtomicU64,
    frames_decoded: AtomicU64,
    decode_errors: AtomicU64,
    non_finite: AtomicU64,
    sent: AtomicU64,
    malformed_sent: AtomicU64,
    malformed_refused: AtomicU64,
    malformed_accepted: AtomicU64,
    good_refused: AtomicU64,
    superseded: AtomicU64,
    reconnects: AtomicU64,
    rooms_opened: AtomicU64,
    rooms_closed: AtomicU64,
    stalls: AtomicU64,
    stuck: AtomicU64,
    /// Why well-formed frames were refused: the ack's message up to its first ':' (the field
    /// or limit it names), and how often.
    refusals: std::sync::Mutex<std::collections::BTreeMap<String, u64>>,
}

/// The soak's report (`--json`).
#[derive(Debug, serde::Serialize)]
pub(super) struct SoakReport {
    /// Minutes run.
    pub minutes: f64,
    /// The model.
    pub model: String,
    /// Base rooms, detail rooms.
    pub rooms: (usize, usize),
    /// Viewers (not counting the checkers).
    pub viewers: usize,
    /// Viewer joins and leaves, and joins the server refused.
    pub joins: u64,
    /// See `joins`.
    pub leaves: u64,
    /// See `joins`.
    pub joins_refused: u64,
    /// Viewers that stalled (stopped reading) for a while.
    pub stalls: u64,
    /// Mesh frames the viewers and checkers received.
    pub frames_received: u64,
    /// Of those, decoded and checked by the checkers.
    pub frames_decoded: u64,
    /// Frames a checker could not decode.
    pub decode_errors: u64,
    /// Decoded meshes with a non-finite coordinate.
    pub non_finite: u64,
    /// Control frames sent, malformed ones among them, and what became of those.
    pub control_frames_sent: u64,
    /// See `control_frames_sent`.
    pub malformed_sent: u64,
    /// See `control_frames_sent`.
    pub malformed_refused: u64,
    /// See `control_frames_sent`.
    pub malformed_accepted: u64,
    /// Well-formed frames refused (rate limits after a reconnection burst, ...).
    pub good_refused: u64,
    /// Why those were refused (the ack message's first part) and how often.
    pub good_refused_why: std::collections::BTreeMap<String, u64>,
    /// Frames a newer one of their room superseded while they waited for the pipeline
    /// (ABORTED acks; latest wins when the server cannot keep up).
    pub superseded: u64,
    /// Publisher reconnections.
    pub publisher_reconnects: u64,
    /// Churn rooms opened and closed.
    pub rooms_opened: u64,
    /// See `rooms_opened`.
    pub rooms_closed: u64,
    /// Checker stalls of 5 s or more while the room's publisher sent.
    pub stuck: u64,
    /// Server panics (in its log) and whether it exited.
    pub panics: usize,
    /// See `panics`.
    pub server_exited: bool,
    /// The highest RSS over the minute that ends the warm-up (one sixth of the run: 5 minutes
    /// of 30) and over the run's last minute, MiB. Peaks, not single samples: a detail
    /// palette header is an 11.5 MB message, so RSS swings by tens of MiB between samples as
    /// viewers join and leave; what must not grow is the envelope.
    pub rss_warm_mib: f64,
    /// See `rss_warm_mib`.
    pub rss_end_mib: f64,
    /// From `rss_warm_mib` to `rss_end_mib`, percent.
    pub rss_growth_percent: f64,
    /// The server with its rooms open, before any client.
    pub baseline: Sample,
    /// The server once every client left (up to [`SETTLE`] later); `None` if it exited.
    pub settled: Option<Sample>,
    /// The samples.
    pub samples: Vec<Sample>,
    /// Why it failed; empty when it passed.
    pub failures: Vec<String>,
}

/// The control frames of a soak room: the model's control points at rest, moved on a slow
/// circle (a live stream that never repeats exactly).
fn control_at(rest: &[Vec3], room: usize, seq: u64, scale: f32) -> Vec<f32> {
    let t = seq as f32 / 60.0 + room as f32;
    let offset = Vec3::new(t.sin(), (0.7 * t).cos(), (1.3 * t).sin()) * scale;
    rest.iter().flat_map(|p| (*p + offset).to_array()).collect()
}

/// Runs the soak (from `bench_net::run`).
pub(super) fn run(args: &BenchNetArgs, minutes: f64) -> anyhow::Result<()> {
    if !(minutes.is_finite() && minutes > 0.0) {
        bail!("--soak must be a positive number of minutes, got {minutes}");
    }
    let model = TrainedModel::load(&args.model)
        .with_context(|| format!("loading model {}", args.model.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    let report = runtime.block_on(soak(args, &model, minutes))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report);
    }
    if !report.failures.is_empty() {
        bail!("the soak failed: {}", report.failures.join("; "));
    }
    Ok(())
}

async fn soak(
    args: &BenchNetArgs,
    model: &TrainedModel,
    minutes: f64,
) -> anyhow::Result<SoakReport> {
    let extra: Vec<String> = SOAK_LIMITS.iter().map(|s| (*s).to_owned()).collect();
    let target = Arc::new(spawn_server_with(args, &extra, &random_token()).await?);
    let pid = target.pid.context("the spawned server's pid")?;
    let http = target.http.context("the spawned server's HTTP address")?;
    let detail_rooms = if model.detail.is_some() {
        args.soak_detail_rooms
    } else {
        if args.soak_detail_rooms > 0 {
            eprintln!("soak: the model has no detail layer: no detail rooms");
        }
        0
    };
    let base_rooms = args.soak_rooms;
    let mut admin = connect(&target.url, None).await?;
    let mut rooms = Vec::new();
    for k in 0..base_rooms + detail_rooms {
        let id = format!("soak-{k}");
        let opened = admin
            .open_room(authorized(
                v1::OpenRoomRequest {
                    room: id.clone(),
                    model: target.model.clone(),
                    ..Default::default()
                },
                &target.admin_token,
            )?)
            .await
            .with_context(|| format!("opening room {id:?}"))?
            .into_inner();
        rooms.push((id, opened.publish_token, k >= base_rooms));
    }
    let rooms = Arc::new(rooms);
    let rest: Arc<Vec<Vec3>> = Arc::new(
        model
            .controls
            .iter()
            .map(|c| model.rig.rest.positions[c.vertex as usize])
            .collect(),
    );
    // The circle's radius: 2% of the rest pose's diagonal.
    let radius = {
        let p = &model.rig.rest.positions;
        let lo = p.iter().fold(Vec3::splat(f32::INFINITY), |a, &b| a.min(b));
        let hi = p
            .iter()
            .fold(Vec3::splat(f32::NEG_INFINITY), |a, &b| a.max(b));
        (hi - lo).length() * 0.02
    };
    let counters = Arc::new(Counters::default());
    let stop = Arc::new(AtomicBool::new(false));
    let started = Instant::now();
    // The server with its rooms open and no client yet: what it must come back to.
    let baseline = sample(pid, http, started)
        .await
        .context("sampling the server before the clients start")?;
    let end = started + Duration::from_secs_f64(minutes * 60.0);
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let mut tasks = JoinSet::new();
    // Per room: when its publisher last sent (ms since `started`), for the stuck check.
    let last_sent: Arc<Vec<AtomicU64>> =
        Arc::new((0..rooms.len()).map(|_| AtomicU64::new(0)).collect());

    for (r, (id, token, _)) in rooms.iter().enumerate() {
        let (url, id, token) = (target.url.clone(), id.clone(), token.clone());
        let (rest, counters, stop, last_sent) = (
            Arc::clone(&rest),
            Arc::clone(&counters),
            Arc::clone(&stop),
            Arc::clone(&last_sent),
        );
        tasks.spawn(async move {
            publisher(
                url, id, token, r, rest, radius, period, counters, stop, started, last_sent,
            )
            .await
        });
    }
    for (r, (id, _, detail)) in rooms.iter().enumerate() {
        let (url, id) = (target.url.clone(), id.clone());
        let level = if *detail {
            v1::Level::Detail
        } else {
            v1::Level::Base
        };
        let (counters, stop, last_sent) = (
            Arc::clone(&counters),
            Arc::clone(&stop),
            Arc::clone(&last_sent),
        );
        tasks.spawn(
            async move { checker(url, id, level, r, counters, stop, started, last_sent).await },
        );
    }
    for v in 0..args.soak_viewers {
        let (url, rooms, counters, stop) = (
            target.url.clone(),
            Arc::clone(&rooms),
            Arc::clone(&counters),
            Arc::clone(&stop),
        );
        tasks.spawn(async move { viewer(v, url, http, rooms, counters, stop).await });
    }
    {
        let (target, counters, stop) = (
            Arc::clone(&target),
            Arc::clone(&counters),
            Arc::clone(&stop),
        );
        tasks.spawn(async move { churn(target, counters, stop).await });
    }

    // Samples until the end, or until the server dies.
    let mut samples = Vec::new();
    let mut ticker = tokio::time::interval(Duration::from_secs_f64(args.sample_seconds.max(1.0)));
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut exited = false;
    while Instant::now() < end {
        ticker.tick().await;
        let Some(sample) = sample(pid, http, started).await else {
            exited = true;
            break;
        };
        eprintln!(
            "soak {:6.0} s: rss {:.1} MiB, {} fds, {} threads, tasks {}, subscribers {} (watching {}), predicted {}, frames {}, joins {}, malformed refused {}/{}, superseded {}",
            sample.t,
            sample.rss_mib,
            sample.fds,
            sample.threads,
            sample.tasks.map_or("?".to_owned(), |t| t.to_string()),
            sample.subscribers.map_or("?".to_owned(), |t| t.to_string()),
            {
                let leaves = counters.leaves.load(Ordering::Relaxed);
                counters
                    .joins
                    .load(Ordering::Relaxed)
                    .saturating_sub(leaves)
            },
            sample.published.map_or("?".to_owned(), |t| t.to_string()),
            counters.frames_seen.load(Ordering::Relaxed),
            counters.joins.load(Ordering::Relaxed),
            counters.malformed_refused.load(Ordering::Relaxed),
            counters.malformed_sent.load(Ordering::Relaxed),
            counters.superseded.load(Ordering::Relaxed),
        );
        samples.push(sample);
    }
    stop.store(true, Ordering::Relaxed);
    // Every task checks `stop` at least once a second.
    let drain = tokio::time::timeout(Duration::from_secs(30), async {
        while let Some(done) = tasks.join_next().await {
            if let Ok(Err(e)) = done {
                eprintln!("soak: a task ended with: {e:#}");
            }
        }
    })
    .await;
    if drain.is_err() {
        eprintln!("soak: tasks still running 30 s after the end; aborted");
        tasks.abort_all();
    }
    // Every client has left: the server must give back what their sessions held.
    let settled = if exited {
        None
    } else {
        settle(pid, http, started, &baseline).await
    };
    let log = target.spawned.as_ref().map(|s| s.log()).unwrap_or_default();
    let panics = log.matches("panicked").count();
    let rss_warm_mib = rss_peak(&samples, warm_up_s(minutes));
    let rss_end_mib = rss_peak(&samples, samples.last().map_or(0.0, |s| s.t));
    let rss_growth_percent = if rss_warm_mib > 0.0 {
        100.0 * (rss_end_mib - rss_warm_mib) / rss_warm_mib
    } else {
        0.0
    };
    let c = &counters;
    let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
    let mut failures = Vec::new();
    if exited {
        failures.push(format!("the server exited:\n{}", tail(&log)));
    }
    if panics > 0 {
        failures.push(format!("{panics} panic(s) in the server's log"));
    }
    if get(&c.non_finite) > 0 {
        failures.push(format!("{} non-finite meshes", get(&c.non_finite)));
    }
    if get(&c.decode_errors) > 0 {
        failures.push(format!("{} frames did not decode", get(&c.decode_errors)));
    }
    if get(&c.stuck) > 0 {
        failures.push(format!("{} stuck-room episodes", get(&c.stuck)));
    }
    if get(&c.malformed_accepted) > 0 {
        failures.push(format!(
            "{} malformed frames accepted",
            get(&c.malformed_accepted)
        ));
    }
    if let Some(s) = &settled
        && !s.within(&baseline)
    {
        failures.push(format!(
            "{} fds and {} tasks held {SETTLE:?} after every client left (before the clients: {} fds, {} tasks): sessions leak",
            s.fds,
            s.tasks.map_or("?".to_owned(), |t| t.to_string()),
            baseline.fds,
            baseline.tasks.map_or("?".to_owned(), |t| t.to_string()),
        ));
    }
    if rss_growth_percent > 5.0 {
        failures.push(format!(
            "RSS grew {rss_growth_percent:.1}% after the warm-up"
        ));
    }
    Ok(SoakReport {
        minutes,
        model: args.model.display().to_string(),
        rooms: (base_rooms, detail_rooms),
        viewers: args.soak_viewers,
        joins: get(&c.joins),
        leaves: get(&c.leaves),
        joins_refused: get(&c.join_refused),
        stalls: get(&c.stalls),
        frames_received: get(&c.frames_seen),
        frames_decoded: get(&c.frames_decoded),
        decode_errors: get(&c.decode_errors),
        non_finite: get(&c.non_finite),
        control_frames_sent: get(&c.sent),
        malformed_sent: get(&c.malformed_sent),
        malformed_refused: get(&c.malformed_refused),
        malformed_accepted: get(&c.malformed_accepted),
        good_refused: get(&c.good_refused),
        good_refused_why: c.refusals.lock().unwrap_or_else(|e| e.into_inner()).clone(),
        superseded: get(&c.superseded),
        publisher_reconnects: get(&c.reconnects),
        rooms_opened: get(&c.rooms_opened),
        rooms_closed: get(&c.rooms_closed),
        stuck: get(&c.stuck),
        panics,
        server_exited: exited,
        rss_warm_mib,
        rss_end_mib,
        rss_growth_percent,
        baseline,
        settled,
        samples,
        failures,
    })
}

/// The end of the warm-up, seconds: one sixth of a run of `minutes` (5 minutes of 30).
fn warm_up_s(minutes: f64) -> f64 {
    minutes * 60.0 / 6.0
}

fn tail(log: &str) -> String {
    let lines: Vec<&str> = log.lines().collect();
    lines[lines.len().saturating_sub(20)..].join("\n")
}

/// A room's publisher: `rate` frames a second, reconnecting every 10-40 s, one malformed frame
/// in [`MALFORMED_EVERY`].
#[allow(clippy::too_many_arguments)]
async fn publisher(
    url: String,
    room: String,
    token: String,
    r: usize,
    rest: Arc<Vec<Vec3>>,
    radius: f32,
    period: Duration,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    started: Instant,
    last_sent: Arc<Vec<AtomicU64>>,
) -> anyhow::Result<()> {
    let mut seq = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let session = Duration::from_secs_f64(rand::rng().random_range(10.0..40.0));
        let until = Instant::now() + session;
        let mut client = match connect(&url, None).await {
            Ok(c) => c,
            Err(_) => {
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            }
        };
        // Which seqs were sent malformed: the acks say whether each was refused.
        let malformed = Arc::new(std::sync::Mutex::new(std::collections::HashSet::new()));
        let source = {
            let (counters, malformed) = (Arc::clone(&counters), Arc::clone(&malformed));
            let (room, rest, stop, last_sent) = (
                room.clone(),
                Arc::clone(&rest),
                Arc::clone(&stop),
                Arc::clone(&last_sent),
            );
            move |mut sink: Sink| async move {
                let mut ticker = tokio::time::interval(period);
                ticker.set_missed_tick_behavior(MissedTickBehavior::Skip);
                while Instant::now() < until && !stop.load(Ordering::Relaxed) {
                    ticker.tick().await;
                    seq += 1;
                    let mut positions = control_at(&rest, r, seq, radius);
                    let bad = seq.is_multiple_of(MALFORMED_EVERY);
                    if bad {
                        if seq.is_multiple_of(2 * MALFORMED_EVERY) {
                            positions.pop(); // a wrong count
                        } else {
                            positions[0] = f32::NAN; // a NaN in a valid point
                        }
                        malformed
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .insert(seq);
                        counters.malformed_sent.fetch_add(1, Ordering::Relaxed);
                    }
                    let frame = v1::ControlFrame {
                        room: room.clone(),
                        seq,
                        capture_time_us: unix_us(),
                        positions,
                        ..Default::default()
                    };
                    if sink.send(frame).await.is_err() {
                        break;
                    }
                    counters.sent.fetch_add(1, Ordering::Relaxed);
                    last_sent[r].store(started.elapsed().as_millis() as u64, Ordering::Relaxed);
                }
                seq
            }
        };
        let mut on_ack = |ack: v1::PublishAck| {
            let was_bad = malformed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .remove(&ack.seq);
            // ABORTED: a newer frame of the room won while this one waited (latest
            // wins, the server's `mailbox`); neither accepted nor refused.
            if ack
                .error
                .as_ref()
                .is_some_and(|e| ErrorCode::from_wire(e.code) == Some(ErrorCode::Aborted))
            {
                counters.superseded.fetch_add(1, Ordering::Relaxed);
                return ControlFlow::Continue(());
            }
            match (was_bad, ack.error.is_some()) {
                (true, true) => counters.malformed_refused.fetch_add(1, Ordering::Relaxed),
                (true, false) => counters.malformed_accepted.fetch_add(1, Ordering::Relaxed),
                (false, true) => {
                    let why = ack.error.as_ref().map_or("", |e| e.message.as_str());
                    let why = why.split(':').next().unwrap_or(why).to_owned();
                    *counters
                        .refusals
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .entry(why)
                        .or_default() += 1;
                    counters.good_refused.fetch_add(1, Ordering::Relaxed)
                }
                (false, false) => 0,
            };
            ControlFlow::Continue(())
        };
        let options = PublishOptions {
            queue: 8,
            // The acks of what was sent, then a new connection.
            drain: Some(Duration::from_secs(5)),
        };
        // A stream that fails or is refused ends the session (the next one reconnects); the
        // soak counts what the acks said.
        match publish(&mut client, &token, options, source, &mut on_ack).await {
            Ok(published) => seq = published.output,
            Err(PublishError::Token(_)) => bail!("the room's token is not a valid header value"),
            Err(_) => {}
        }
        drop(client);
        counters.reconnects.fetch_add(1, Ordering::Relaxed);
    }
    Ok(())
}

/// A room's checker: a long-lived gRPC subscriber that decodes and checks every frame.
#[allow(clippy::too_many_arguments)]
async fn checker(
    url: String,
    room: String,
    level: v1::Level,
    r: usize,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    started: Instant,
    last_sent: Arc<Vec<AtomicU64>>,
) -> anyhow::Result<()> {
    let mut positions = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        // A refused or failed subscription is retried: the checker must outlive the faults.
        let subscribed = async {
            let mut client = connect(&url, None).await?;
            let sub = subscribe_encoded(&mut client, &room, level, Encoding::Vertices).await?;
            let reader = StreamReader::new(&sub.first)?;
            anyhow::Ok((sub, reader))
        };
        let (mut sub, mut reader) = match subscribed.await {
            Ok(s) => s,
            Err(e) => {
                eprintln!("soak: room {room}: the checker could not subscribe ({e:#}); retrying");
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        let mut last_frame = Instant::now();
        let mut stuck_now = false;
        loop {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            match tokio::time::timeout(Duration::from_secs(1), sub.next_frame()).await {
                Ok(Ok(Some(frame))) => {
                    last_frame = Instant::now();
                    stuck_now = false;
                    counters.frames_seen.fetch_add(1, Ordering::Relaxed);
                    match reader.decode(&frame.data) {
                        Ok(()) => {
                            counters.frames_decoded.fetch_add(1, Ordering::Relaxed);
                            reader.model_positions(&mut positions);
                            if positions.iter().any(|p| !p.is_finite()) {
                                counters.non_finite.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                        Err(e) => {
                            counters.decode_errors.fetch_add(1, Ordering::Relaxed);
                            eprintln!(
                                "soak: room {room}: frame {} did not decode: {e:#}",
                                frame.seq
                            );
                        }
                    }
                }
                Ok(Ok(None)) | Ok(Err(_)) => break, // resubscribe
                Err(_) => {
                    // No frame this second: stuck if the publisher sent within the window.
                    let sent_ms = last_sent[r].load(Ordering::Relaxed);
                    let sent_ago = started.elapsed().as_millis() as u64
                        - sent_ms.min(started.elapsed().as_millis() as u64);
                    if !stuck_now && last_frame.elapsed() >= STUCK && sent_ago < 1000 {
                        stuck_now = true;
                        counters.stuck.fetch_add(1, Ordering::Relaxed);
                        eprintln!(
                            "soak: room {room}: no frame for {:?} while its publisher sends",
                            last_frame.elapsed()
                        );
                    }
                }
            }
        }
    }
    Ok(())
}

/// A viewer: joins random rooms over gRPC or WebSocket, watches, stalls, leaves, again.
async fn viewer(
    v: usize,
    url: String,
    http: std::net::SocketAddr,
    rooms: Arc<Vec<(String, String, bool)>>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    // Spread the first joins over two seconds.
    tokio::time::sleep(Duration::from_millis((v as u64 * 10) % 2000)).await;
    while !stop.load(Ordering::Relaxed) {
        let (room, level, ws, palette, watch) = {
            let mut rng = rand::rng();
            let (id, _, detail) = &rooms[rng.random_range(0..rooms.len())];
            (
                id.clone(),
                if *detail {
                    v1::Level::Detail
                } else {
                    v1::Level::Base
                },
                rng.random_bool(0.5),
                rng.random_bool(0.3),
                Duration::from_secs_f64(rng.random_range(5.0..40.0)),
            )
        };
        let encoding = if palette {
            Encoding::Palette
        } else {
            Encoding::Vertices
        };
        counters.joins.fetch_add(1, Ordering::Relaxed);
        let until = Instant::now() + watch;
        let watched = if ws {
            watch_ws(http, &room, level, encoding, until, &counters, &stop).await
        } else {
            watch_grpc(&url, &room, level, encoding, until, &counters, &stop).await
        };
        if watched.is_err() {
            counters.join_refused.fetch_add(1, Ordering::Relaxed);
        }
        counters.leaves.fetch_add(1, Ordering::Relaxed);
        let pause = Duration::from_millis(rand::rng().random_range(0..2000));
        tokio::time::sleep(pause).await;
    }
    Ok(())
}

/// Whether to stall now (called per frame read or idle second: about once in 20 s at 60 Hz),
/// and for how long.
fn maybe_stall(counters: &Counters) -> Option<Duration> {
    let mut rng = rand::rng();
    rng.random_bool(0.0008).then(|| {
        counters.stalls.fetch_add(1, Ordering::Relaxed);
        Duration::from_secs_f64(rng.random_range(1.0..8.0))
    })
}

async fn watch_grpc(
    url: &str,
    room: &str,
    level: v1::Level,
    encoding: Encoding,
    until: Instant,
    counters: &Counters,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let mut client = connect(url, None).await?;
    let mut sub = subscribe_encoded(&mut client, room, level, encoding).await?;
    while Instant::now() < until && !stop.load(Ordering::Relaxed) {
        if let Some(pause) = maybe_stall(counters) {
            tokio::time::sleep(pause).await;
        }
        match tokio::time::timeout(Duration::from_secs(1), sub.next_frame()).await {
            Ok(Ok(Some(_))) => {
                counters.frames_seen.fetch_add(1, Ordering::Relaxed);
            }
            Ok(Ok(None) | Err(_)) => break,
            Err(_) => {}
        }
    }
    Ok(())
}

async fn watch_ws(
    http: std::net::SocketAddr,
    room: &str,
    level: v1::Level,
    encoding: Encoding,
    until: Instant,
    counters: &Counters,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let level = if level == v1::Level::Detail {
        "detail"
    } else {
        "base"
    };
    let url = format!(
        "ws://{http}/ws/rooms/{room}?level={level}&encoding={}",
        encoding.name()
    );
    let (mut socket, _) = tokio_tungstenite::connect_async(url).await?;
    while Instant::now() < until && !stop.load(Ordering::Relaxed) {
        if let Some(pause) = maybe_stall(counters) {
            tokio::time::sleep(pause).await;
        }
        match tokio::time::timeout(Duration::from_secs(1), socket.next()).await {
            Ok(Some(Ok(tokio_tungstenite::tungstenite::Message::Binary(b)))) => {
                if let Ok(v1::MeshFrame {
                    body: Some(v1::mesh_frame::Body::Frame(_)),
                }) = v1::MeshFrame::decode(b.as_ref())
                {
                    counters.frames_seen.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(Some(Ok(_))) | Err(_) => {}
            Ok(None | Some(Err(_))) => break,
        }
    }
    let _ = socket.close(None).await;
    Ok(())
}

/// Opens a room and closes it again, every 15 s.
async fn churn(
    target: Arc<Target>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let mut admin = connect(&target.url, None).await?;
    for k in 0u64.. {
        for _ in 0..15 {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
        let id = format!("soak-churn-{k}");
        let open = v1::OpenRoomRequest {
            room: id.clone(),
            model: target.model.clone(),
            ..Default::default()
        };
        admin
            .open_room(authorized(open, &target.admin_token)?)
            .await?;
        counters.rooms_opened.fetch_add(1, Ordering::Relaxed);
        tokio::time::sleep(Duration::from_secs(5)).await;
        let close = v1::CloseRoomRequest { room: id };
        admin
            .close_room(authorized(close, &target.admin_token)?)
            .await?;
        counters.rooms_closed.fetch_add(1, Ordering::Relaxed);
    }
    Ok(())
}

fn print_report(r: &SoakReport) {
    let first = r.samples.first();
    let last = r.samples.last();
    println!("soak: {:.1} min, model {}", r.minutes, r.model);
    println!(
        "  rooms                  {} base + {} detail (+{} opened and {} closed)",
        r.rooms.0, r.rooms.1, r.rooms_opened, r.rooms_closed
    );
    println!(
        "  viewers                {} (joins {}, leaves {}, refused {}, stalls {})",
        r.viewers, r.joins, r.leaves, r.joins_refused, r.stalls
    );
    println!(
        "  frames                 {} received, {} decoded and checked",
        r.frames_received, r.frames_decoded
    );
    println!(
        "  control frames         {} sent, {} reconnections, {} superseded (latest wins)",
        r.control_frames_sent, r.publisher_reconnects, r.superseded
    );
    println!(
        "  malformed              {} sent, {} refused, {} accepted; {} good ones refused",
        r.malformed_sent, r.malformed_refused, r.malformed_accepted, r.good_refused
    );
    for (why, n) in &r.good_refused_why {
        println!("    good ones refused    {n} x {why:?}");
    }
    println!(
        "  panics {}, non-finite {}, decode errors {}, stuck {}",
        r.panics, r.non_finite, r.decode_errors, r.stuck
    );
    println!(
        "  RSS (peak of a minute) {:.1} MiB at {:.0} s (warm), {:.1} MiB at the end: {:+.1}%",
        r.rss_warm_mib,
        warm_up_s(r.minutes),
        r.rss_end_mib,
        r.rss_growth_percent
    );
    if let (Some(a), Some(b)) = (first, last) {
        println!(
            "  fds                    {} -> {}; threads {} -> {}; tasks {:?} -> {:?}",
            a.fds, b.fds, a.threads, b.threads, a.tasks, b.tasks
        );
    }
    let counts = |s: &Sample| {
        format!(
            "{} fds, {} threads, {} tasks, {:.1} MiB",
            s.fds,
            s.threads,
            s.tasks.map_or("?".to_owned(), |t| t.to_string()),
            s.rss_mib
        )
    };
    println!("  before the clients     {}", counts(&r.baseline));
    if let Some(s) = &r.settled {
        println!("  after they left        {} ({:.0} s)", counts(s), s.t);
    }
    if r.failures.is_empty() {
        println!("  PASS");
    } else {
        for f in &r.failures {
            println!("  FAIL {f}");
        }
    }
}
