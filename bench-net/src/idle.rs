//! `--idle SECONDS` (issue 41, "nothing computed for nobody"): the embedded demo server
//! (`crease-server` with no `--models`) spawned with nobody connected, its CPU time read from
//! `/proc/PID/stat` over SECONDS after it settles (the goal: at most 0.5% of a core), then one
//! viewer per encoding subscribing to the demo room, timed from the subscribe call to its first
//! frame (the goal: within one frame period of the demo's 60 Hz, plus the header for a
//! palette viewer).

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use crease_proto::{Encoding, v1};
use crease_remote::client::get_room;
use crease_remote::connect;
use crease_remote::mesh_stream::subscribe_encoded;
use tokio::time::Instant;

use super::args::BenchNetArgs;
use super::server::{clock_ticks, cpu_seconds, free_address, random_token, rss_kib, server_binary};

/// The demo's room and model names (`crease_demo::DEMO_ROOM`; bench-net does not depend on
/// the demo crate).
const DEMO_ROOM: &str = "demo";
/// Seconds the server is left alone after it answers before the measurement starts.
const SETTLE_S: f64 = 5.0;

/// What one run measured.
#[derive(Debug, serde::Serialize)]
struct IdleReport {
    seconds: f64,
    cpu_seconds: f64,
    core_percent: f64,
    rss_mib: f64,
    /// Per viewer: its first messages' times.
    first_frames: Vec<FirstFrame>,
}

/// A new viewer's first messages, timed from its subscribe call.
#[derive(Debug, serde::Serialize)]
struct FirstFrame {
    level: String,
    encoding: String,
    /// When its header (topology) had arrived, ms.
    header_ms: f64,
    /// When its first frame arrived, ms.
    frame_ms: f64,
    header_bytes: usize,
}

/// Runs the idle measurement (module docs).
pub(crate) fn run(args: &BenchNetArgs, seconds: f64) -> anyhow::Result<()> {
    if !(seconds.is_finite() && seconds >= 1.0) {
        bail!("--idle must be at least 1 second, got {seconds}");
    }
    let bin = server_binary(args)?;
    let cache = args
        .model
        .parent()
        .filter(|d| d.join("demo-hand-v1.crease").is_file())
        .with_context(|| {
            format!(
                "--idle runs the embedded demo from its cache, and {} is not the demo hand \
                 (run `crease-server` once to build it, or pass --model PATH/demo-hand-v1.crease)",
                args.model.display()
            )
        })?
        .to_owned();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(measure(args, &bin, &cache, seconds))
}

async fn measure(
    args: &BenchNetArgs,
    bin: &Path,
    cache: &Path,
    seconds: f64,
) -> anyhow::Result<()> {
    let mut held = Vec::new();
    let grpc = free_address(&mut held)?.to_string();
    let http = free_address(&mut held)?.to_string();
    drop(held);
    let takes = std::env::temp_dir().join(format!("crease-idle-{}", &random_token()[..8]));
    let mut child = Command::new(bin)
        .arg("--cache")
        .arg(cache)
        .arg("--takes")
        .arg(&takes)
        .args(["--grpc", &grpc, "--http", &http])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let pid = child.id();
    let result = async {
        let url = format!("http://{grpc}");
        let deadline = Instant::now() + Duration::from_secs(120);
        let mut client = loop {
            if let Some(status) = child.try_wait()? {
                bail!("{} exited ({status}) before answering", bin.display());
            }
            if let Ok(mut c) = connect(&url, None).await
                && get_room(&mut c, DEMO_ROOM).await.is_ok()
            {
                break c;
            }
            if Instant::now() > deadline {
                bail!(
                    "{} did not open room {DEMO_ROOM:?} within 120 s",
                    bin.display()
                );
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        };
        eprintln!(
            "idle: {} (pid {pid}) serves the demo; {SETTLE_S} s to settle, then {seconds} s alone",
            bin.display()
        );
        tokio::time::sleep(Duration::from_secs_f64(SETTLE_S)).await;
        let hz = clock_ticks();
        let cpu0 = cpu_seconds(pid, hz).context("reading /proc/PID/stat (Linux only)")?;
        let t0 = Instant::now();
        tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
        let cpu1 = cpu_seconds(pid, hz).context("reading /proc/PID/stat")?;
        let elapsed = t0.elapsed().as_secs_f64();
        let cpu = cpu1 - cpu0;
        let rss_mib = rss_kib(pid).unwrap_or(0.0) / 1024.0;
        let mut first_frames = Vec::new();
        for (level, encoding) in [
            (v1::Level::Base, Encoding::Vertices),
            (v1::Level::Detail, Encoding::Palette),
            (v1::Level::Detail, Encoding::Vertices),
        ] {
            let start = Instant::now();
            let mut sub = subscribe_encoded(&mut client, DEMO_ROOM, level, encoding).await?;
            let header_ms = start.elapsed().as_secs_f64() * 1e3;
            tokio::time::timeout(Duration::from_secs(30), sub.next_frame())
                .await
                .context("no frame within 30 s")??
                .context("the stream ended before a frame")?;
            let frame_ms = start.elapsed().as_secs_f64() * 1e3;
            first_frames.push(FirstFrame {
                level: format!("{level:?}").to_lowercase(),
                encoding: encoding.name().to_owned(),
                header_ms,
                frame_ms,
                header_bytes: prost::Message::encoded_len(&sub.first),
            });
            drop(sub);
            // The viewer gone, the room pauses again before the next one comes.
            tokio::time::sleep(Duration::from_secs(1)).await;
        }
        Ok(IdleReport {
            seconds: elapsed,
            cpu_seconds: cpu,
            core_percent: 100.0 * cpu / elapsed,
            rss_mib,
            first_frames,
        })
    }
    .await;
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&takes);
    let report = result?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "idle demo server: {:.3} CPU s in {:.1} s = {:.2}% of a core (goal <= 0.5%); RSS {:.0} MiB",
            report.cpu_seconds, report.seconds, report.core_percent, report.rss_mib
        );
        for f in &report.first_frames {
            println!(
                "a new {} {} viewer: header ({} B) {:.1} ms after subscribing, first frame {:.1} ms ({:.1} ms after the header)",
                f.level,
                f.encoding,
                f.header_bytes,
                f.header_ms,
                f.frame_ms,
                f.frame_ms - f.header_ms
            );
        }
    }
    Ok(())
}
