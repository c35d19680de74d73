//! `crease stream`: publish control frames into a room in real time over gRPC: a file of
//! control frames (CSV/JSON), or a marker recording (Qualisys TSV, C3D) retargeted onto the
//! room's model through a marker map (`crease_mocap`). Prints refused frames as they come
//! and at the end acks, latency, invalid markers and how closely the mesh followed them.
//!
//! With `--check` (or `--strip`) it also subscribes to the room and decodes every mesh the
//! frames produce, checking each is finite; `--strip` renders the hand every `--strip-every`
//! seconds of the recording into one PNG.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use crease_core::mesh::Mesh;
use crease_hand::render::{View, contact_sheet};
use crease_mocap::RetargetStats;
use crease_proto::control::actor_controls;
use crease_proto::errors::ErrorCode;
use crease_proto::{control_frame, v1};
use serde::Serialize;

use super::retarget::{ModelControls, RecordingArgs, Retargeted, parse_rate};
use crease_remote::control_file::{ControlFrame, read_control_frames};
use crease_remote::mesh_stream::{self, MeshReader, Subscription};
use crease_remote::publish::{PublishOptions, SentLog, Sink, publish};
use crease_remote::{get_room, percentile, unix_us};

/// Options of `crease stream`.
#[derive(Clone, Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["frames", "tsv", "c3d"])))]
pub struct StreamArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: super::common::ServerArgs,
    /// The room to publish into.
    #[arg(long, default_value = "demo")]
    pub room: String,
    /// The room's publish token (from `crease room open`). Also read from CREASE_TOKEN.
    #[arg(long, env = "CREASE_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Control frames: CSV or JSON, as `crease synth --controls` reads them.
    #[arg(long, value_name = "FILE")]
    pub frames: Option<PathBuf>,
    /// The recording to read and how (file, map, rate).
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// Frames per second. A recording plays at its own rate unless this is given, and is then
    /// resampled to it (e.g. 100 Hz to a 60 Hz room). Control-frame files default to 60.
    #[arg(long, value_parser = parse_rate)]
    pub rate: Option<f64>,
    /// Play again and again until interrupted.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Play this many times faster than real time (the frames stay the same; capture times
    /// are wall-clock send times, so a room's filter sees the faster clock too).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Subscribe too, decode every mesh the frames produce, and check that each is finite.
    #[arg(long)]
    pub check: bool,
    /// Render the mesh every --strip-every seconds into this PNG (implies --check).
    #[arg(long, value_name = "PNG")]
    pub strip: Option<PathBuf>,
    /// Seconds between the strip's pictures.
    #[arg(long, default_value_t = 10.0)]
    pub strip_every: f64,
    /// Write the summary as JSON.
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
}

/// Runs `crease stream`.
pub fn run(args: &StreamArgs) -> anyhow::Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0) {
        bail!("--speed must be a positive factor, got {}", args.speed);
    }
    if !(args.strip_every.is_finite() && args.strip_every > 0.0) {
        bail!(
            "--strip-every must be a positive number of seconds, got {}",
            args.strip_every
        );
    }
    if args.recording.map.is_some() && args.frames.is_some() {
        bail!("--map applies to --tsv and --c3d recordings, not to --frames");
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(stream(args))
}

/// Refused frames reported one by one before the rest are only counted.
const SHOWN_REFUSALS: u64 = 10;

/// Summary of a run (`--report`).
#[derive(Debug, Default, Serialize)]
struct Report {
    frames_sent: u64,
    acknowledged: u64,
    refused: u64,
    /// Frames another publisher's newer frame superseded while they waited for the room's
    /// pipeline (ABORTED acks: latest wins); neither acknowledged nor refused.
    superseded: u64,
    rate_hz: f64,
    seconds: f64,
    server_latency_us_p50: u32,
    server_latency_us_p99: u32,
    round_trip_us_p50: u64,
    round_trip_us_p99: u64,
    held_controls: u64,
    invalid_in_frames: u64,
    frames_with_invalid: u64,
    control_residual_rms_model: f64,
    control_residual_rms_recording_units: Option<f64>,
    scale: Option<f32>,
    retarget: Option<RetargetStats>,
    meshes: Option<MeshCheck>,
    strip: Option<String>,
    /// A room of several actors: each actor's residuals.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    actors: Vec<ActorReport>,
}

/// One actor's part of a [`Report`] (a room of several actors).
#[derive(Debug, Default, Serialize)]
struct ActorReport {
    name: String,
    control_residual_rms_model: f64,
    control_residual_rms_recording_units: f64,
    /// Frames the actor was missing from (none, from a recording).
    held_frames: u64,
}

/// What `--check` saw on the subscription.
#[derive(Clone, Debug, Default, Serialize)]
struct MeshCheck {
    received: u64,
    skipped: u64,
    non_finite: u64,
    decode_errors: u64,
    latency_us_p50: i64,
    latency_us_p99: i64,
    #[serde(skip)]
    strip: Vec<(String, Mesh)>,
}

async fn stream(args: &StreamArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let room = get_room(&mut client, &args.room).await?;
    let model = room
        .model
        .clone()
        .context("the server sent a room without a model")?;
    let n = model.control_points.len();
    // A room of several actors (issue 38): each actor retargets the recording's markers its
    // map reads; a frame carries every actor's.
    let actors: Vec<(String, v1::Retarget)> = room
        .actors
        .iter()
        .filter_map(|i| i.actor.as_ref())
        .map(|a| match &a.retarget {
            Some(rt) => Ok((a.name.clone(), rt.clone())),
            None => bail!(
                "room {:?}: actor {:?} takes control points, not markers: crease stream drives rooms of actors from a recording through each actor's map (crease room open --actors FILE --markers-from RECORDING)",
                args.room,
                a.name
            ),
        })
        .collect::<anyhow::Result<_>>()?;
    if !actors.is_empty() && args.frames.is_some() {
        bail!(
            "--frames: room {:?} is a room of actors: stream a recording (--c3d or --tsv) into it",
            args.room
        );
    }
    let mut parts: Vec<Vec<ControlFrame>> = Vec::new();
    for (_, rt) in actors.iter().skip(1) {
        parts.push(args.recording.raw_markers(&rt.markers, args.rate)?.frames);
    }
    let prepared = match (&args.frames, actors.first()) {
        (_, Some((_, rt))) => args.recording.raw_markers(&rt.markers, args.rate)?,
        (Some(path), None) => Retargeted {
            frames: read_control_frames(path, n).with_context(|| {
                format!(
                    "{}: frames for model {:?} ({n} control points)",
                    path.display(),
                    model.name
                )
            })?,
            rate: args.rate.unwrap_or(60.0),
            scale: None,
            units: "model units".into(),
            stats: None,
        },
        (None, None) => match &room.retarget {
            // The room retargets: it gets the raw markers (issue 19).
            Some(rt) => args.recording.raw_markers(&rt.markers, args.rate)?,
            None => {
                let controls = ModelControls::from_info(&model);
                args.recording.retarget(&controls, args.rate)?
            }
        },
    };
    let raw_markers = (room.retarget.is_some() || !actors.is_empty()) && args.frames.is_none();
    if prepared.frames.is_empty() {
        bail!("nothing to send: no frames");
    }
    // Actor 0's frames first, then the others'; every actor's frame `i` goes out together.
    parts.insert(0, prepared.frames);
    let pass = parts.iter().map(Vec::len).min().unwrap_or(0);
    let names: Vec<String> = actors.iter().map(|(n, _)| n.clone()).collect();
    let frames = Arc::new(parts);
    let total = if args.repeat { u64::MAX } else { pass as u64 };
    let rate = prepared.rate;
    let start_us = unix_us();

    // The checker subscribes before the first frame goes out.
    let want_check = args.check || args.strip.is_some();
    let checker = if want_check {
        let sub = mesh_stream::subscribe(&mut client, &args.room, v1::Level::Base).await?;
        let reader = sub.readers()?;
        let plan = CheckPlan {
            start_us,
            last_seq: total.saturating_sub(1),
            // The strip covers the first pass (with --loop the stream never ends).
            pass: pass as u64,
            rate,
            strip_every: args.strip.is_some().then_some(args.strip_every),
            // Give up on a silent stream after three frame periods, at least 5 s.
            patience: Duration::from_secs_f64((3.0 / (rate * args.speed)).max(5.0)),
        };
        Some(tokio::spawn(check_meshes(sub, reader, plan)))
    } else {
        None
    };

    let period = Duration::from_secs_f64(1.0 / (rate * args.speed));
    let sent_at = Arc::new(SentLog::<Instant>::default());
    let room_id = args.room.clone();
    let start = Instant::now();
    // The sender counts invalid points as it goes (`--loop` never ends, so not up front).
    let source = {
        let frames = Arc::clone(&frames);
        let sent_at = Arc::clone(&sent_at);
        let names = names.clone();
        move |mut sink: Sink| async move {
            let (mut invalid_points, mut invalid_frames) = (0u64, 0u64);
            let mut ticker = tokio::time::interval(period);
            ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
            for seq in 0..total {
                ticker.tick().await;
                let i = (seq % pass as u64) as usize;
                let now = unix_us();
                let wire = |f: &ControlFrame| {
                    let mut frame = control_frame(&room_id, seq, now, &f.positions, &f.valid);
                    if raw_markers {
                        frame.markers = std::mem::take(&mut frame.positions);
                        frame.markers_valid = std::mem::take(&mut frame.valid);
                    }
                    frame
                };
                let frame = if names.is_empty() {
                    wire(&frames[0][i])
                } else {
                    let mut frame = wire(&ControlFrame::default());
                    frame.actors = names
                        .iter()
                        .zip(frames.iter())
                        .map(|(name, part)| actor_controls(name, wire(&part[i])))
                        .collect();
                    frame
                };
                let invalid = frames
                    .iter()
                    .take(names.len().max(1))
                    .map(|part| part[i].valid.iter().filter(|v| !**v).count() as u64)
                    .sum::<u64>();
                invalid_points += invalid;
                invalid_frames += u64::from(invalid > 0);
                sent_at.record(seq, Instant::now(), None);
                if sink.send(frame).await.is_err() {
                    break;
                }
            }
            (invalid_points, invalid_frames)
        }
    };
    let mut report = Report {
        rate_hz: rate,
        scale: prepared.scale,
        retarget: prepared.stats,
        ..Report::default()
    };
    let mut latencies = Vec::new();
    let mut round_trips = Vec::new();
    let mut residual_sq = 0.0f64;
    let mut capture_sq = 0.0f64;
    // Per actor: squared residuals (model units, capture units) and frames it was held.
    let mut actor_sums = vec![(0.0f64, 0.0f64, 0u64); names.len()];
    let mut on_ack = |ack: v1::PublishAck| {
        if let Some(at) = sent_at.take(ack.seq) {
            round_trips.push(at.elapsed().as_micros() as u64);
        }
        match ack.error {
            // Superseded by another publisher's newer frame (latest wins), not refused.
            Some(e) if ErrorCode::from_wire(e.code) == Some(ErrorCode::Aborted) => {
                report.superseded += 1;
            }
            Some(e) => {
                report.refused += 1;
                // The first refusals say why; a flood of the same (a rate limit) is counted.
                if report.refused <= SHOWN_REFUSALS {
                    eprintln!(
                        "frame {}: refused (code {}): {}",
                        ack.seq, e.code, e.message
                    );
                } else if report.refused == SHOWN_REFUSALS + 1 {
                    eprintln!("further refusals are counted in the summary");
                }
            }
            None => {
                report.acknowledged += 1;
                report.held_controls += u64::from(ack.held_controls);
                latencies.push(ack.server_latency_us);
                residual_sq += f64::from(ack.control_residual).powi(2);
                capture_sq += f64::from(ack.control_residual_capture).powi(2);
                for (sums, a) in actor_sums.iter_mut().zip(&ack.actors) {
                    sums.0 += f64::from(a.control_residual).powi(2);
                    sums.1 += f64::from(a.control_residual_capture).powi(2);
                    sums.2 += u64::from(a.held);
                }
            }
        }
        ControlFlow::Continue(())
    };
    let options = PublishOptions {
        queue: 8,
        drain: None,
    };
    let published = publish(&mut client, &args.token, options, source, &mut on_ack)
        .await
        .map_err(|e| e.into_anyhow("--token", "publishing", "the sender stopped"))?;
    if let Some(status) = published.status {
        return Err(status.into());
    }
    report.seconds = start.elapsed().as_secs_f64();
    report.frames_sent = report.acknowledged + report.refused + report.superseded;
    (report.invalid_in_frames, report.frames_with_invalid) = published.output;
    latencies.sort_unstable();
    round_trips.sort_unstable();
    report.server_latency_us_p50 = percentile(&latencies, 50.0);
    report.server_latency_us_p99 = percentile(&latencies, 99.0);
    report.round_trip_us_p50 = percentile(&round_trips, 50.0);
    report.round_trip_us_p99 = percentile(&round_trips, 99.0);
    report.control_residual_rms_model = (residual_sq / report.acknowledged.max(1) as f64).sqrt();
    report.control_residual_rms_recording_units = if raw_markers {
        // The room reports the residual in the capture's units itself.
        Some((capture_sq / report.acknowledged.max(1) as f64).sqrt())
    } else {
        prepared
            .scale
            .map(|s| report.control_residual_rms_model / f64::from(s))
    };
    println!(
        "{} frames in {:.2} s ({:.1} frames/s): {} acknowledged, {} refused, {} superseded; server latency p50 {} µs p99 {} µs, round trip p50 {} µs p99 {} µs",
        report.frames_sent,
        report.seconds,
        report.frames_sent as f64 / report.seconds.max(1e-9),
        report.acknowledged,
        report.refused,
        report.superseded,
        report.server_latency_us_p50,
        report.server_latency_us_p99,
        report.round_trip_us_p50,
        report.round_trip_us_p99
    );
    println!(
        "invalid control points: {} in {} frames (server held {}); control residual RMS {:.3e} model units{}",
        report.invalid_in_frames,
        report.frames_with_invalid,
        report.held_controls,
        report.control_residual_rms_model,
        report
            .control_residual_rms_recording_units
            .map_or(String::new(), |r| format!(" = {r:.2} {}", prepared.units))
    );
    let acked = report.acknowledged.max(1) as f64;
    report.actors = names
        .iter()
        .zip(&actor_sums)
        .map(|(name, (model, capture, held))| ActorReport {
            name: name.clone(),
            control_residual_rms_model: (model / acked).sqrt(),
            control_residual_rms_recording_units: (capture / acked).sqrt(),
            held_frames: *held,
        })
        .collect();
    for a in &report.actors {
        println!(
            "actor {:?}: control residual RMS {:.3e} model units = {:.2} {}; held in {} frames",
            a.name,
            a.control_residual_rms_model,
            a.control_residual_rms_recording_units,
            prepared.units,
            a.held_frames
        );
    }
    if let Some(checker) = checker {
        let mut check = checker.await.context("the mesh checker stopped")?;
        println!(
            "meshes: {} received for {} frames sent ({} skipped by the room's latest-wins fan-out), {} not finite, {} undecodable; capture -> mesh received p50 {} µs p99 {} µs",
            check.received,
            report.frames_sent,
            check.skipped,
            check.non_finite,
            check.decode_errors,
            check.latency_us_p50,
            check.latency_us_p99
        );
        if let Some(path) = &args.strip {
            if check.strip.is_empty() {
                bail!("--strip: no mesh was received to render");
            }
            let tiles: Vec<(&str, &Mesh)> =
                check.strip.iter().map(|(l, m)| (l.as_str(), m)).collect();
            let sheet = contact_sheet(
                &tiles,
                &[View::ThumbSide, View::Palm],
                220,
                tiles.len() as u32,
            );
            sheet
                .write_png(path)
                .with_context(|| format!("writing {}", path.display()))?;
            println!("wrote {} ({} pictures)", path.display(), tiles.len());
            report.strip = Some(path.display().to_string());
        }
        check.strip.clear();
        let bad = check.non_finite + check.decode_errors;
        report.meshes = Some(check);
        if bad > 0 {
            write_report(args, &report)?;
            bail!("{bad} meshes were not finite or could not be decoded");
        }
    }
    write_report(args, &report)?;
    if report.acknowledged == 0 {
        bail!("no frame was accepted");
    }
    Ok(())
}

/// What [`check_meshes`] needs to know of the run.
#[derive(Clone, Copy, Debug)]
struct CheckPlan {
    /// Frames captured before this (an earlier run into the room) are not counted.
    start_us: i64,
    /// The sequence number of the last frame to be sent.
    last_seq: u64,
    /// Frames in one pass over the source (the strip covers the first pass).
    pass: u64,
    /// Frames per second of the source.
    rate: f64,
    /// Seconds between the strip's pictures, with `--strip`.
    strip_every: Option<f64>,
    /// How long a silent stream is waited for.
    patience: Duration,
}

/// Decodes every mesh of the subscription until the last frame sent, checking each is finite
/// and keeping the strip's pictures.
async fn check_meshes(
    mut sub: Subscription,
    mut readers: Vec<MeshReader>,
    plan: CheckPlan,
) -> MeshCheck {
    let CheckPlan {
        start_us,
        last_seq,
        pass,
        rate,
        strip_every,
        patience,
    } = plan;
    let triangles = readers[0].topology().model_triangles();
    let mut check = MeshCheck::default();
    let mut model_order = Vec::new();
    let mut latencies = Vec::new();
    let mut next_strip = 0.0f64;
    loop {
        let f = match tokio::time::timeout(patience, sub.next_frame()).await {
            Ok(Ok(Some(f))) => f,
            _ => break,
        };
        // Keep the codec state, count only this run's frames. A room of several actors
        // sends each actor's frame in `actors` (decoded by that actor's reader).
        let decoded: Vec<bool> = if f.actors.is_empty() {
            vec![readers[0].decode(&f.data).is_ok()]
        } else {
            f.actors
                .iter()
                .map(|a| {
                    readers
                        .get_mut(a.actor as usize)
                        .is_some_and(|r| r.decode(&a.data).is_ok())
                })
                .collect()
        };
        if f.capture_time_us < start_us {
            continue;
        }
        check.received += 1;
        check.skipped += u64::from(f.skipped);
        latencies.push(unix_us() - f.capture_time_us);
        if decoded.len() != readers.len() || decoded.contains(&false) {
            check.decode_errors += 1;
            continue;
        }
        if !readers
            .iter_mut()
            .all(|r| r.streamed().iter().all(|p| p.is_finite()))
        {
            check.non_finite += 1;
        }
        let reader = &mut readers[0];
        if let Some(every) = strip_every {
            let t = f.seq as f64 / rate;
            if t + 0.5 / rate >= next_strip && f.seq < pass {
                reader.model_positions(&mut model_order);
                check.strip.push((
                    format!("t = {t:.1} s"),
                    Mesh {
                        positions: model_order.clone(),
                        triangles: triangles.clone(),
                    },
                ));
                next_strip = (t / every + 1e-9).floor() * every + every;
            }
        }
        if f.seq >= last_seq {
            break;
        }
    }
    latencies.sort_unstable();
    check.latency_us_p50 = percentile(&latencies, 50.0);
    check.latency_us_p99 = percentile(&latencies, 99.0);
    check
}

fn write_report(args: &StreamArgs, report: &Report) -> anyhow::Result<()> {
    if let Some(path) = &args.report {
        let text = serde_json::to_string_pretty(report).context("report")?;
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
