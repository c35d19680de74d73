//! `crease stream`: publish a file of control frames into a room at a fixed rate over gRPC,
//! printing refused frames as they come and a summary of acks and latency at the end.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use crease_proto::{control_frame, v1};

use super::synth::read_control_frames;

/// Options of `crease stream`.
#[derive(Clone, Debug, clap::Args)]
pub struct StreamArgs {
    #[command(flatten)]
    pub server: super::common::ServerArgs,
    /// The room to publish into.
    #[arg(long, default_value = "demo")]
    pub room: String,
    /// The room's publish token (from OpenRoom). Also read from CREASE_TOKEN.
    #[arg(long, env = "CREASE_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Control frames: CSV or JSON, as `crease synth --controls` reads them.
    #[arg(long, value_name = "FILE")]
    pub frames: PathBuf,
    /// Frames per second (30, 60, 100, ...).
    #[arg(long, default_value_t = 60.0)]
    pub rate: f64,
    /// Play the file again and again until interrupted.
    #[arg(long = "loop")]
    pub repeat: bool,
}

/// Runs `crease stream`.
pub fn run(args: &StreamArgs) -> anyhow::Result<()> {
    if !(args.rate.is_finite() && args.rate > 0.0 && args.rate <= 10_000.0) {
        bail!(
            "--rate must be in (0, 10000] frames per second, got {}",
            args.rate
        );
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(stream(args))
}

async fn stream(args: &StreamArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let model = client
        .list_models(v1::ListModelsRequest {})
        .await
        .context("listing models")?
        .into_inner();
    // Rooms are not listed, so the file must fit one of the server's models: the first
    // control-point count that parses it wins, and the server checks it against the room.
    let mut counts: Vec<usize> = model
        .models
        .iter()
        .map(|m| m.control_points.len())
        .collect();
    counts.sort_unstable();
    counts.dedup();
    let frames = counts
        .iter()
        .find_map(|&n| read_control_frames(&args.frames, n).ok())
        .with_context(|| {
            format!(
                "{}: no frame layout of the server's models fits ({counts:?} control points)",
                args.frames.display()
            )
        })?;
    let total = if args.repeat {
        u64::MAX
    } else {
        frames.len() as u64
    };
    let period = Duration::from_secs_f64(1.0 / args.rate);
    let room = args.room.clone();
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let start = Instant::now();
    tokio::spawn(async move {
        let mut ticker = tokio::time::interval(period);
        for seq in 0..total {
            ticker.tick().await;
            let f = &frames[(seq % frames.len() as u64) as usize];
            let capture_time_us = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_micros() as i64);
            let frame = control_frame(&room, seq, capture_time_us, &f.positions, &f.valid);
            if tx.send(frame).await.is_err() {
                break;
            }
        }
    });
    let mut req = tonic::Request::new(tokio_stream::wrappers::ReceiverStream::new(rx));
    req.metadata_mut().insert(
        "authorization",
        format!("Bearer {}", args.token)
            .parse()
            .context("--token: not a valid header value")?,
    );
    let mut acks = client
        .publish(req)
        .await
        .context("publishing")?
        .into_inner();
    let (mut ok, mut refused, mut held) = (0u64, 0u64, 0u64);
    let mut latencies = Vec::new();
    while let Some(ack) = acks.message().await? {
        match ack.error {
            Some(e) => {
                refused += 1;
                eprintln!(
                    "frame {}: refused (code {}): {}",
                    ack.seq, e.code, e.message
                );
            }
            None => {
                ok += 1;
                held += u64::from(ack.held_controls);
                latencies.push(ack.server_latency_us);
            }
        }
    }
    latencies.sort_unstable();
    let pct = |p: f64| {
        latencies
            .get(((latencies.len().max(1) - 1) as f64 * p).round() as usize)
            .copied()
            .unwrap_or(0)
    };
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{} frames in {secs:.2} s ({:.1} frames/s): {ok} acknowledged, {refused} refused, {held} occluded control points held, server latency p50 {} µs p99 {} µs",
        ok + refused,
        (ok + refused) as f64 / secs.max(1e-9),
        pct(0.5),
        pct(0.99)
    );
    if ok == 0 {
        bail!("no frame was accepted");
    }
    Ok(())
}
