//! `crease bench-net --chaos MINUTES`: a cluster held under load while faults strike it
//! (issue 40, item 4). One process orchestrates:
//!
//! - **the cluster** (`cluster`): `nats-server -js` on a fixed port and store (in a folder of
//!   its own under the temp dir) and three `crease-server` replicas `r0 r1 r2` joined to it
//!   (`--nats`, `--replica-id`, `--lease-ms` = `--chaos-lease-ms`, an admin token, the soak's
//!   raised limits, `--takes` a folder each), all on one `--models` folder holding the model
//!   (`--model`, default the demo hand in the demo's cache). Logs go to that folder.
//! - **rooms and clients** (`clients`): `--chaos-rooms` rooms (20), opened on the replicas
//!   in turn, each with one publisher at `--rate` (60 Hz) through a random live replica;
//!   `--chaos-viewers` (200) viewers spread over the replicas, gRPC and WebSocket, vertex and
//!   palette frames, reading bytes only. Publishers move to a random live replica when their
//!   connection fails or no ack comes for a second; viewers when theirs fails or goes quiet,
//!   and back to their home replica once it is up again.
//! - **faults** (`faults`): every 20-40 s one of `kill` (SIGKILL a replica, restart it 5-15 s
//!   later), `pause` (SIGSTOP a room's owner for 2.5 leases), `nats` (restart NATS) or
//!   `publisher` (move a publisher); one at a time, MINUTES x 2 of them.
//! - **checks** (`accounting`, fed by `clients`): per room one decoding gRPC checker on each
//!   replica records every frame: gaps without a new frame (attributed to the fault in
//!   progress: the recovery per fault kind), ordering (a seq at or below the previous on one
//!   subscription), decode failures (healed by a keyframe or not). A NATS observer reads every
//!   frame's `Crease-Epoch` on `crease.frames.>`: an older epoch after a newer one's frame is
//!   split brain. Takes (`takes`) started in two rooms are stopped and read back at the end.
//!   Every 5 s each replica's RSS (`soak`'s probe) with the rooms it owns, judged over the
//!   stretches of steady load (`memory`).
//!
//! The report (`report`) fails the run (exit status 1) on an ordering violation, a
//! split-brain frame, a room without a frame for longer than `--chaos-max-gap` (10 s) after a
//! fault ended (or with no fault), a decode failure no keyframe healed, a bad take, RSS growth
//! over 5% across a steady stretch of a replica's life (one high-water of rooms owned and of
//! viewers served: the peak of its first settled minute to its last minute's), a run of 10 minutes or more that
//! judged RSS over less than half its length, a replica that exited on its own or panicked,
//! and fewer than MINUTES x 2 faults.
//!
//! This file: the options' checks, the set-up, the run and the report's figures.

mod accounting;
mod clients;
mod cluster;
mod faults;
mod memory;
mod report;
mod state;
mod takes;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context as _, bail};
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use tokio::task::JoinSet;
use tokio::time::Instant;

use super::args::{BenchNetArgs, demo_model};
use super::server::{SOAK_LIMITS, nats_binary, random_token, server_binary};
use accounting::{Recovery, STOPPED_S, Span, Watch, attribute, recoveries, uncovered};
use clients::Motion;
use cluster::{Nats, Replica, free_addresses};
use crease_remote::{authorized, connect};
use faults::{FaultKind, Processes};
use report::{ChaosReport, LISTED, ReplicaRss, RoomGap};
use state::{Counters, PublisherCtl, REPLICAS, ReplicaView, Room, Shared, lock};

/// Seconds between samples of the replicas.
const SAMPLE_EVERY: Duration = Duration::from_secs(5);
/// Rooms recording a take.
const TAKE_ROOMS: usize = 2;
/// RSS growth over a steady stretch that fails the run, percent.
const RSS_GROWTH: f64 = 5.0;
/// A run this long (seconds) must judge RSS over at least half its length, summed over the
/// replicas' steady stretches.
const MEMORY_JUDGED_AFTER_S: f64 = 600.0;

/// Runs the chaos soak (from `bench_net::run`).
pub(super) fn run(args: &BenchNetArgs, minutes: f64) -> anyhow::Result<()> {
    if !(minutes.is_finite() && minutes > 0.0) {
        bail!("--chaos must be a positive number of minutes, got {minutes}");
    }
    if !(args.rate.is_finite() && args.rate > 0.0 && args.rate <= 1000.0) {
        bail!(
            "--rate must be in (0, 1000] frames per second, got {}",
            args.rate
        );
    }
    if args.chaos_rooms == 0 {
        bail!("--chaos-rooms must be at least 1");
    }
    if !(100..=60_000).contains(&args.chaos_lease_ms) {
        bail!(
            "--chaos-lease-ms must be 100 to 60000, got {}",
            args.chaos_lease_ms
        );
    }
    if !(args.chaos_max_gap.is_finite() && args.chaos_max_gap > STOPPED_S) {
        bail!(
            "--chaos-max-gap must be more than {STOPPED_S} s, got {}",
            args.chaos_max_gap
        );
    }
    let model_path = args.model.clone();
    if !model_path.is_file() && model_path == demo_model() {
        bail!(
            "no --model, and no demo hand at {} (run `crease-server` once, which trains and caches it in about 15 s, or pass --model FILE)",
            model_path.display()
        );
    }
    let model = TrainedModel::load(&model_path)
        .with_context(|| format!("loading model {}", model_path.display()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    let report = runtime.block_on(chaos(args, &model_path, &model, minutes))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        report::print_table(&report, &mut std::io::stderr())?;
    } else {
        report::print_table(&report, &mut std::io::stdout())?;
    }
    if !report.violations.is_empty() {
        bail!(
            "the chaos soak failed: {} violation(s) (see the table; logs in {})",
            report.violations.len(),
            report.dir
        );
    }
    Ok(())
}

/// The model linked into a fresh models folder under `dir`; its name there.
fn models_folder(dir: &Path, model: &Path) -> anyhow::Result<(PathBuf, String)> {
    let name = model
        .file_stem()
        .and_then(|s| s.to_str())
        .context("--model: the file name is not valid UTF-8")?
        .to_owned();
    let models = dir.join("models");
    std::fs::create_dir_all(&models).with_context(|| format!("creating {}", models.display()))?;
    let source = std::fs::canonicalize(model).with_context(|| format!("{}", model.display()))?;
    let link = models.join(format!("{name}.crease"));
    #[cfg(unix)]
    std::os::unix::fs::symlink(&source, &link)
        .with_context(|| format!("linking {}", link.display()))?;
    #[cfg(not(unix))]
    std::fs::copy(&source, &link).with_context(|| format!("copying to {}", link.display()))?;
    Ok((models, name))
}

/// Starts NATS and the replicas, and waits until every replica is ready.
async fn start_cluster(
    args: &BenchNetArgs,
    dir: &Path,
    models: &Path,
    admin: &str,
) -> anyhow::Result<Processes> {
    let bin = server_binary(args)?;
    let addresses = free_addresses(1 + 2 * REPLICAS)?;
    let nats = Nats::start(
        nats_binary(args)?,
        addresses[0].port(),
        dir.join("js"),
        dir.join("nats.log"),
    )
    .await?;
    let mut replicas = Vec::with_capacity(REPLICAS);
    for k in 0..REPLICAS {
        let (grpc, http) = (addresses[1 + 2 * k], addresses[2 + 2 * k]);
        let id = format!("r{k}");
        let takes = dir.join(format!("takes-{id}"));
        let mut argv: Vec<String> = vec![
            "--models".into(),
            models.display().to_string(),
            "--grpc".into(),
            grpc.to_string(),
            "--http".into(),
            http.to_string(),
            "--nats".into(),
            nats.url(),
            "--replica-id".into(),
            id.clone(),
            "--lease-ms".into(),
            args.chaos_lease_ms.to_string(),
            "--takes".into(),
            takes.display().to_string(),
        ];
        argv.extend(SOAK_LIMITS.iter().map(|s| (*s).to_owned()));
        let log = dir.join(format!("{id}.log"));
        let mut replica = Replica::new(id, bin.clone(), argv, admin.to_owned(), grpc, http, log);
        replica.spawn()?;
        replicas.push(replica);
    }
    for replica in &mut replicas {
        replica.ready().await?;
    }
    Ok(Processes { nats, replicas })
}

/// Opens the rooms, room `r` on replica `r % REPLICAS`, and waits until every replica knows
/// them all.
async fn open_rooms(
    procs: &Processes,
    count: usize,
    model: &str,
    admin: &str,
) -> anyhow::Result<Vec<Room>> {
    let mut rooms = Vec::with_capacity(count);
    for r in 0..count {
        let replica = &procs.replicas[r % REPLICAS];
        let id = format!("chaos-{r}");
        let mut client = connect(&replica.url, None).await?;
        let open = v1::OpenRoomRequest {
            room: id.clone(),
            model: model.to_owned(),
            ..Default::default()
        };
        let opened = client
            .open_room(authorized(open, admin)?)
            .await
            .with_context(|| format!("opening room {id:?} on {}", replica.id))?
            .into_inner();
        rooms.push(Room {
            id,
            token: opened.publish_token,
        });
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    for replica in &procs.replicas {
        let mut client = connect(&replica.url, None).await?;
        for room in &rooms {
            while crease_remote::get_room(&mut client, &room.id)
                .await
                .is_err()
            {
                if Instant::now() > deadline {
                    bail!(
                        "{}: room {:?} not known there after 30 s",
                        replica.id,
                        room.id
                    );
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
    Ok(rooms)
}

/// The publishers' motion: the model's control points at rest on a circle of 2% of the rest
/// pose's diagonal.
fn motion(model: &TrainedModel, rate: f64) -> Motion {
    let p = &model.rig.rest.positions;
    let lo = p.iter().fold(Vec3::splat(f32::INFINITY), |a, &b| a.min(b));
    let hi = p
        .iter()
        .fold(Vec3::splat(f32::NEG_INFINITY), |a, &b| a.max(b));
    Motion {
        rest: model
            .controls
            .iter()
            .map(|c| p[c.vertex as usize])
            .collect(),
        radius: (hi - lo).length() * 0.02,
        period: Duration::from_secs_f64(1.0 / rate),
    }
}

async fn chaos(
    args: &BenchNetArgs,
    model_path: &Path,
    model: &TrainedModel,
    minutes: f64,
) -> anyhow::Result<ChaosReport> {
    let dir = std::env::temp_dir().join(format!(
        "crease-chaos-{}-{}",
        std::process::id(),
        &random_token()[..8]
    ));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    eprintln!("chaos: folder {}", dir.display());
    let (models, model_name) = models_folder(&dir, model_path)?;
    let admin = random_token();
    let mut procs = start_cluster(args, &dir, &models, &admin).await?;
    let rooms = open_rooms(&procs, args.chaos_rooms, &model_name, &admin).await?;
    eprintln!(
        "chaos: {} replicas ready, {} rooms open; clients start",
        REPLICAS,
        rooms.len()
    );
    let max_gap = args.chaos_max_gap;
    let shared = Arc::new(Shared {
        started: Instant::now(),
        stop: Default::default(),
        replicas: procs
            .replicas
            .iter()
            .map(|r| ReplicaView::new(r.id.clone(), r.url.clone(), r.http, r.pid().unwrap_or(0)))
            .collect(),
        checkers: (0..rooms.len() * REPLICAS)
            .map(|_| Mutex::new(Watch::new(0.0, max_gap)))
            .collect(),
        publishers: (0..rooms.len()).map(|_| PublisherCtl::default()).collect(),
        rooms,
        admin_token: admin,
        epochs: Default::default(),
        memory: Mutex::new(vec![Vec::new(); REPLICAS]),
        counters: Counters::default(),
    });
    let mut tasks: JoinSet<anyhow::Result<()>> = JoinSet::new();
    {
        let (shared, url) = (Arc::clone(&shared), procs.nats.url());
        tasks.spawn(clients::observer(shared, url));
    }
    for r in 0..shared.rooms.len() {
        for k in 0..REPLICAS {
            let shared = Arc::clone(&shared);
            tasks.spawn(async move {
                clients::checker(shared, r, k).await;
                Ok(())
            });
        }
    }
    let motion = Arc::new(motion(model, args.rate));
    for r in 0..shared.rooms.len() {
        let (shared, motion) = (Arc::clone(&shared), Arc::clone(&motion));
        tasks.spawn(async move {
            clients::publisher(shared, r, motion).await;
            Ok(())
        });
    }
    for v in 0..args.chaos_viewers {
        let shared = Arc::clone(&shared);
        let room = v % shared.rooms.len();
        tasks.spawn(async move {
            clients::viewer(shared, v, room).await;
            Ok(())
        });
    }
    {
        let shared = Arc::clone(&shared);
        tasks.spawn(async move {
            clients::sampler(shared, SAMPLE_EVERY).await;
            Ok(())
        });
    }
    // Takes start once frames flow (every checker has one, or 20 s).
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline && !shared.checkers.iter().all(|w| lock(w).seen_any()) {
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let take_rooms: Vec<usize> = (0..TAKE_ROOMS.min(shared.rooms.len())).collect();
    let (started_takes, mut violations) = takes::start(&shared, &take_rooms).await;

    let end_s = minutes * 60.0;
    let required = (minutes * 2.0).ceil() as usize;
    let lease = Duration::from_millis(args.chaos_lease_ms);
    let injected = faults::inject(&mut procs, &shared, lease, end_s, required).await;
    let duration_s = shared.now();
    for w in &shared.checkers {
        lock(w).finish(duration_s);
    }
    let take_checks = takes::check(&shared, &started_takes).await;
    shared.stop.store(true, Ordering::Relaxed);
    let drain = tokio::time::timeout(Duration::from_secs(20), async {
        while let Some(done) = tasks.join_next().await {
            match done {
                Ok(Err(e)) => eprintln!("chaos: a task ended with: {e:#}"),
                Err(e) if e.is_panic() => {
                    violations.push(format!("a client task panicked: {e}"));
                }
                _ => {}
            }
        }
    })
    .await;
    if drain.is_err() {
        eprintln!("chaos: tasks still running 20 s after the end; aborted");
        tasks.abort_all();
    }
    violations.extend(injected.problems.iter().cloned());
    let panics: usize = procs
        .replicas
        .iter()
        .map(|r| r.log_text().matches("panicked").count())
        .sum();
    let mut logs = vec![procs.nats.log.display().to_string()];
    logs.extend(procs.replicas.iter().map(|r| r.log.display().to_string()));
    let report = summarise(
        args,
        &shared,
        Summary {
            model: model_path.display().to_string(),
            minutes,
            duration_s,
            required,
            faults: injected.faults,
            takes: take_checks,
            panics,
            dir: dir.display().to_string(),
            logs,
            violations,
        },
    );
    drop(procs);
    if report.violations.is_empty() {
        // The NATS store is of no use once the run passed; the logs and takes stay.
        let _ = std::fs::remove_dir_all(dir.join("js"));
    }
    Ok(report)
}

/// What the run gathered besides the shared state.
struct Summary {
    model: String,
    minutes: f64,
    duration_s: f64,
    required: usize,
    faults: Vec<faults::Fault>,
    takes: Vec<takes::TakeCheck>,
    panics: usize,
    dir: String,
    logs: Vec<String>,
    violations: Vec<String>,
}

/// The report: the figures, and every violation.
fn summarise(args: &BenchNetArgs, shared: &Shared, s: Summary) -> ChaosReport {
    let mut violations = s.violations;
    let spans: Vec<Span> = s
        .faults
        .iter()
        .map(|f| Span {
            kind: f.kind,
            replica: f.replica,
            start: f.start_s,
            end: f.end_s,
        })
        .collect();
    let watches: Vec<(usize, usize, Watch)> = (0..shared.rooms.len())
        .flat_map(|r| (0..REPLICAS).map(move |k| (r, k)))
        .map(|(r, k)| (r, k, shared.watch(r, k).clone()))
        .collect();
    let fault_name = |i: usize| format!("fault {} ({})", i + 1, s.faults[i].kind.name());

    // Ordering.
    let mut ordering = Vec::new();
    for (r, k, w) in &watches {
        for o in &w.out_of_order {
            ordering.push(format!(
                "{:7.1} s room {} on {}: seq {} after {}",
                o.t, shared.rooms[*r].id, shared.replicas[*k].id, o.seq, o.previous
            ));
        }
    }
    ordering.sort();
    if !ordering.is_empty() {
        violations.push(format!(
            "{} frames out of order on a subscription (first: {})",
            ordering.len(),
            ordering[0].trim()
        ));
    }
    // Split brain.
    let epochs = lock(&shared.epochs);
    if let Some(first) = epochs.split.first() {
        violations.push(format!(
            "{} split-brain frames on NATS (first at {:.1} s: room {}, {} in epoch {} after epoch {} of {})",
            epochs.split.len(),
            first.t,
            first.room,
            first.owner,
            first.epoch,
            first.newest,
            first.newest_owner
        ));
    }
    // Gaps: the longest per room, the unexplained, and those too long after a fault.
    let mut longest: BTreeMap<usize, RoomGap> = BTreeMap::new();
    let mut stalls = 0;
    let mut gap_violations = Vec::new();
    for (r, k, w) in &watches {
        for gap in &w.gaps {
            let fault = attribute(gap, &spans);
            stalls += usize::from(fault.is_none());
            let entry = RoomGap {
                room: shared.rooms[*r].id.clone(),
                replica: shared.replicas[*k].id.clone(),
                seconds: gap.seconds(),
                from_s: gap.from,
                fault: fault.map(fault_name),
            };
            if longest.get(r).is_none_or(|g| g.seconds < entry.seconds) {
                longest.insert(*r, entry);
            }
            let after = uncovered(gap, &spans);
            if after > args.chaos_max_gap {
                gap_violations.push(format!(
                    "room {} on {}: no new frame for {after:.1} s after {} (from {:.1} s to {:.1} s{})",
                    shared.rooms[*r].id,
                    shared.replicas[*k].id,
                    fault.map_or("the start, with no fault".to_owned(), fault_name),
                    gap.from,
                    gap.to,
                    if gap.open { ", the end" } else { "" }
                ));
            }
        }
    }
    let gap_count = gap_violations.len();
    violations.extend(gap_violations.into_iter().take(LISTED));
    if gap_count > LISTED {
        violations.push(format!(
            "... and {} more rooms without frames",
            gap_count - LISTED
        ));
    }
    let unhealed: u64 = watches.iter().map(|(_, _, w)| w.unhealed_decodes).sum();
    if unhealed > 0 {
        violations.push(format!(
            "{unhealed} decode failures that no keyframe healed within {} s",
            args.chaos_max_gap
        ));
    }
    // Recovery per kind.
    // Every kind that struck is listed (0 rooms: no room's frames stopped).
    let mut recovery: BTreeMap<String, Recovery> = s
        .faults
        .iter()
        .map(|f| (f.kind.name().to_owned(), Recovery::default()))
        .collect();
    for (kind, seconds) in recoveries(watches.iter().map(|(r, k, w)| (*r, *k, w)), &spans) {
        recovery.insert(kind.name().to_owned(), Recovery::of(seconds));
    }
    // Takes.
    let takes_bad = s.takes.iter().filter(|t| t.bad.is_some()).count();
    for t in &s.takes {
        if let Some(why) = &t.bad {
            violations.push(format!("take {} on {}: {why}", t.take, t.replica));
        }
    }
    // RSS, over each replica's steady stretches (`memory`).
    let memory = lock(&shared.memory);
    let rss: Vec<ReplicaRss> = shared
        .replicas
        .iter()
        .zip(memory.iter())
        .map(|(view, points)| ReplicaRss {
            replica: view.id.clone(),
            deaths: view.deaths.load(Ordering::Relaxed),
            start_mib: points.first().map_or(0.0, |x| x.rss_mib),
            end_mib: points.last().map_or(0.0, |x| x.rss_mib),
            stretches: memory::steady(points),
        })
        .collect();
    for m in &rss {
        for x in &m.stretches {
            if let Some(g) = x.growth_percent
                && g > RSS_GROWTH
            {
                violations.push(format!(
                    "replica {} RSS grew {g:.1}% at a steady load ({:.1} -> {:.1} MiB, peaks of the first and last minute of {:.0}-{:.0} s in its life {} with at most {} rooms owned and {} viewers)",
                    m.replica,
                    x.first_peak_mib.unwrap_or(0.0),
                    x.last_peak_mib.unwrap_or(0.0),
                    x.from + memory::SETTLE_S,
                    x.to,
                    x.life + 1,
                    x.rooms,
                    x.viewers
                ));
            }
        }
    }
    // A run long enough to judge must judge some memory (else the check is blind).
    let judged_s: f64 = rss
        .iter()
        .flat_map(|m| &m.stretches)
        .map(memory::Stretch::judged_s)
        .sum();
    if s.duration_s >= MEMORY_JUDGED_AFTER_S && judged_s < s.duration_s / 2.0 {
        violations.push(format!(
            "RSS judged over {judged_s:.0} s of steady load in all (summed over the replicas), under half the run's {:.0} s: too few steady stretches to tell a leak",
            s.duration_s
        ));
    }
    if s.panics > 0 {
        violations.push(format!("{} panic(s) in the replicas' logs", s.panics));
    }
    if s.faults.len() < s.required {
        violations.push(format!(
            "{} faults injected, fewer than the {} required ({} minutes x 2)",
            s.faults.len(),
            s.required,
            s.minutes
        ));
    }
    let mut by_kind: BTreeMap<String, usize> = FaultKind::ALL
        .iter()
        .map(|k| (k.name().to_owned(), 0))
        .collect();
    for f in &s.faults {
        *by_kind.entry(f.kind.name().to_owned()).or_default() += 1;
    }
    let c = &shared.counters;
    let get = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed);
    ChaosReport {
        minutes: s.minutes,
        duration_s: s.duration_s,
        model: s.model,
        replicas: REPLICAS,
        rooms: shared.rooms.len(),
        viewers: args.chaos_viewers,
        rate_hz: args.rate,
        lease_ms: args.chaos_lease_ms,
        max_gap_s: args.chaos_max_gap,
        dir: s.dir,
        logs: s.logs,
        faults_required: s.required,
        faults_by_kind: by_kind,
        faults: s.faults,
        recovery,
        frames_seen: watches.iter().map(|(_, _, w)| w.frames).sum(),
        decode_errors: watches.iter().map(|(_, _, w)| w.decode_errors).sum(),
        unhealed_decodes: unhealed,
        viewer_frames: get(&c.viewer_frames),
        nats_frames: epochs.frames,
        nats_unlabelled: epochs.unlabelled,
        handovers: epochs.handovers,
        nats_late: epochs.late,
        ordering_violations: ordering.len(),
        ordering_listed: ordering.into_iter().take(LISTED).collect(),
        split_brain_frames: epochs.split.len(),
        split_brain_listed: epochs.split.iter().take(LISTED).cloned().collect(),
        longest_gaps: longest.into_values().collect(),
        stalls_without_fault: stalls,
        takes_checked: s.takes.len(),
        takes_bad,
        takes: s.takes,
        rss,
        control_frames_sent: get(&c.sent),
        superseded: get(&c.superseded),
        refused: lock(&c.refused).clone(),
        publisher_reconnects: get(&c.publisher_reconnects),
        publisher_stalls: get(&c.publisher_stalls),
        viewer_reconnects: get(&c.viewer_reconnects),
        checker_refusals: get(&c.checker_refusals),
        panics: s.panics,
        violations,
    }
}
