//! `crease bench-net`: the network load benchmark of issue 6. Publishers send control frames
//! into rooms at a fixed rate over gRPC, subscribers (one connection each, like separate
//! viewers) read the encoded meshes, and the report gives the server's latency from control
//! frame received to mesh frame handed to each subscriber's stream (`Frame.server_latency_us`),
//! the server's CPU, and bytes per vertex per frame.
//!
//! The server under test is by default the real `crease-server` binary, spawned as a child
//! process on two free loopback ports so that its CPU (`/proc/PID/stat`) is measured apart from
//! the clients; `--server URL` benches a running one instead. The clients run in this process on
//! tokio's multi-thread runtime, on the same machine as the server: they compete with it for
//! the cores, and the report says how much CPU they used.
//!
//! Control frames are the model's control vertices on each mesh of a sequence (the horse
//! gallop by default), looped, or a control file (`--controls`, as `crease synth` reads it).

use std::collections::hash_map::RandomState;
use std::fs::File;
use std::hash::BuildHasher;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use crease_core::codec::{FrameDecoder, FrameKind, parse_frame};
use crease_core::mesh::ExampleSet;
use crease_core::model::TrainedModel;
use crease_proto::v1::crease_client::CreaseClient;
use crease_proto::{control_frame, read_topology, v1};
use serde::Serialize;
use tokio::task::JoinSet;
use tokio::time::{Instant, MissedTickBehavior};
use tonic::transport::{Channel, Endpoint};

use super::common::{authorized, unix_us};
use super::synth::read_control_frames;

/// The horse gallop beside the checkout (`../shared/data`), as the core benches find it.
const DEFAULT_GALLOP: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/horse/gallop"
);

/// Issue 6's first scenario: one room watched by 100 viewers (the p99 target is set for it).
const ONE_ROOM: (usize, usize) = (1, 100);
/// Issue 6's second scenario: 20 rooms of 5 viewers (as many streams, 20x the predictions).
const MANY_ROOMS: (usize, usize) = (20, 5);
/// How long the spawned server may take to load its model and listen: the horse loads in
/// about a second; a debug build on a busy machine takes much longer.
const SERVER_START: Duration = Duration::from_secs(60);
/// Control frames queued per publisher before it waits: a few periods, so a slow ack stream
/// shows up as late sends instead of a growing queue.
const PUBLISH_QUEUE: usize = 8;

const AFTER_HELP: &str = "\
The issue 6 figures use the horse of BENCHMARKS.md (issue 3 split, 150 bones, K = 8, 8 automatic
control points, global predictor), trained and benched with release builds:

  cargo build --release -p crease-cli -p crease-server
  target/release/crease train --examples bench/horse/train.toml --bones 150 --max-influences 8 \\
      --out /tmp/horse.crease
  RAYON_NUM_THREADS=1 target/release/crease bench-net --model /tmp/horse.crease

The server binary is looked up beside this `crease` (or --server-bin); build it with
`cargo build --release -p crease-server`. Latency is the server's own figure
(Frame.server_latency_us: control frame received -> mesh frame handed to the subscriber's
stream); the client-side figure (capture time -> frame read by the client, one clock, one
machine) adds HTTP/2 and the clients' own scheduling.";

/// Which of issue 6's scenarios to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ScenarioChoice {
    /// 1 room x 100 subscribers.
    OneRoom,
    /// 20 rooms x 5 subscribers.
    ManyRooms,
    /// Both, one after the other.
    Both,
}

/// Options of `crease bench-net`.
#[derive(Clone, Debug, clap::Args)]
#[command(after_long_help = AFTER_HELP)]
pub struct BenchNetArgs {
    /// The trained model (the horse for issue 6's figures: see --help).
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// Folder of meshes (the model's topology) whose control vertices make the control frames,
    /// looped. Default: the horse gallop in ../shared/data beside the checkout.
    #[arg(long, value_name = "DIR", conflicts_with = "controls")]
    pub gallop: Option<PathBuf>,
    /// Control frames from a CSV or JSON file (as `crease synth --controls` reads them), looped,
    /// instead of --gallop.
    #[arg(long, value_name = "FILE")]
    pub controls: Option<PathBuf>,
    /// Scenarios: one-room (1 x 100 subscribers), many-rooms (20 x 5) or both.
    #[arg(long, value_enum, default_value = "both")]
    pub scenario: ScenarioChoice,
    /// Rooms of one custom scenario instead of --scenario (with --subscribers).
    #[arg(long, value_name = "N", requires = "subscribers")]
    pub rooms: Option<usize>,
    /// Subscribers per room of the custom scenario (with --rooms).
    #[arg(long, value_name = "M", requires = "rooms")]
    pub subscribers: Option<usize>,
    /// Control frames per second, per room.
    #[arg(long, default_value_t = 60.0)]
    pub rate: f64,
    /// The measured window, seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Seconds of traffic before the window (not recorded).
    #[arg(long, default_value_t = 2.0)]
    pub warmup: f64,
    /// Bench a running server (its gRPC URL, e.g. http://127.0.0.1:50051) instead of spawning
    /// one; it must host the model and have an admin token.
    #[arg(long, value_name = "URL")]
    pub server: Option<String>,
    /// With --server: its process id, to measure its CPU (Linux /proc).
    #[arg(long, value_name = "PID", requires = "server")]
    pub server_pid: Option<u32>,
    /// With --server: its admin token (opens the rooms). Also read from CREASE_ADMIN_TOKEN.
    /// A spawned server gets a fresh random one.
    #[arg(long, env = "CREASE_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,
    /// With --server: the model's name there. Default: the model file's stem.
    #[arg(long, value_name = "NAME", requires = "server")]
    pub model_name: Option<String>,
    /// The crease-server binary to spawn. Default: `crease-server` beside this `crease`.
    #[arg(long, value_name = "PATH", conflicts_with = "server")]
    pub server_bin: Option<PathBuf>,
    /// Print one JSON object on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// One load shape: rooms, each with its publisher and subscribers.
#[derive(Clone, Debug)]
struct Scenario {
    name: String,
    rooms: usize,
    subscribers: usize,
}

fn scenarios(args: &BenchNetArgs) -> Vec<Scenario> {
    let named = |name: &str, (rooms, subscribers): (usize, usize)| Scenario {
        name: name.to_owned(),
        rooms,
        subscribers,
    };
    if let (Some(rooms), Some(subscribers)) = (args.rooms, args.subscribers) {
        return vec![named("custom", (rooms, subscribers))];
    }
    match args.scenario {
        ScenarioChoice::OneRoom => vec![named("one-room", ONE_ROOM)],
        ScenarioChoice::ManyRooms => vec![named("many-rooms", MANY_ROOMS)],
        ScenarioChoice::Both => vec![named("one-room", ONE_ROOM), named("many-rooms", MANY_ROOMS)],
    }
}

/// Percentiles of a latency sample, microseconds (nearest rank).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Percentiles {
    /// Values in the sample.
    pub count: usize,
    /// Median.
    pub p50: u32,
    /// 90th percentile.
    pub p90: u32,
    /// 99th percentile.
    pub p99: u32,
    /// Largest value.
    pub max: u32,
    /// Mean.
    pub mean: f64,
}

impl Percentiles {
    /// Sorts `values` and summarises them (all zero when empty).
    pub fn of(values: &mut [u32]) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        values.sort_unstable();
        // Nearest rank: the smallest value with at least p% of the sample at or below it.
        let rank = |p: f64| {
            let k = (p / 100.0 * values.len() as f64).ceil() as usize;
            values[k.clamp(1, values.len()) - 1]
        };
        Percentiles {
            count: values.len(),
            p50: rank(50.0),
            p90: rank(90.0),
            p99: rank(99.0),
            max: values[values.len() - 1],
            mean: values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64,
        }
    }
}

/// Minimum, mean and maximum of a count over rooms or subscribers.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Spread {
    /// Smallest.
    pub min: u64,
    /// Mean.
    pub mean: f64,
    /// Largest.
    pub max: u64,
}

impl Spread {
    fn of(values: impl IntoIterator<Item = u64>) -> Spread {
        let (mut min, mut max, mut sum, mut n) = (u64::MAX, 0, 0, 0u64);
        for v in values {
            min = min.min(v);
            max = max.max(v);
            sum += v;
            n += 1;
        }
        if n == 0 {
            return Spread::default();
        }
        Spread {
            min,
            mean: sum as f64 / n as f64,
            max,
        }
    }
}

/// CPU used during the measured window.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Cpu {
    /// CPU seconds per second of the window (cores kept busy).
    pub cores: f64,
    /// CPU milliseconds per control frame published in the window (all rooms).
    pub ms_per_frame: f64,
}

/// Bytes per vertex per frame of one kind of frame.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FrameBytes {
    /// Frames received.
    pub frames: u64,
    /// Their bytes (whole codec frames, header included).
    pub bytes: u64,
    /// bytes / (frames x vertices).
    pub bytes_per_vertex: f64,
}

impl FrameBytes {
    fn new(frames: u64, bytes: u64, vertices: usize) -> FrameBytes {
        FrameBytes {
            frames,
            bytes,
            bytes_per_vertex: bytes as f64 / (frames.max(1) as f64 * vertices.max(1) as f64),
        }
    }
}

/// What one scenario measured (the window only, unless a field says otherwise).
#[derive(Clone, Debug, Serialize)]
pub struct ScenarioReport {
    /// `one-room`, `many-rooms` or `custom`.
    pub name: String,
    /// Rooms.
    pub rooms: usize,
    /// Subscribers per room.
    pub subscribers_per_room: usize,
    /// Control frames per second per room asked for.
    pub rate_hz: f64,
    /// Length of the measured window, seconds.
    pub seconds: f64,
    /// Control frames sent in the window, all rooms.
    pub frames_published: u64,
    /// Control frames sent in the window, per room.
    pub published_per_room: Spread,
    /// Frames the server refused (whole run; should be 0).
    pub frames_refused: u64,
    /// The first refusal's message.
    pub first_refusal: Option<String>,
    /// Mesh frames received in the window, all subscribers.
    pub frames_received: u64,
    /// Mesh frames received in the window, per subscriber.
    pub received_per_subscriber: Spread,
    /// Frames the server skipped for a slow subscriber (`Frame.skipped`), summed.
    pub frames_skipped: u64,
    /// `Frame.server_latency_us`: control frame received -> mesh frame handed to the
    /// subscriber's stream, over every received frame.
    pub server_latency_us: Percentiles,
    /// Control frame captured (publisher) -> mesh frame read by the subscriber, on this
    /// machine's clock: the server's figure plus HTTP/2 both ways and client scheduling.
    pub client_latency_us: Percentiles,
    /// `PublishAck.server_latency_us`: control frame received -> mesh predicted, encoded and
    /// handed to the room's channel.
    pub ack_latency_us: Percentiles,
    /// Per frame, its server latency less its ack's: the wait from the mesh being ready to
    /// this subscriber's stream task taking it (the fan-out; 0 when it took it first).
    pub fan_out_us: Percentiles,
    /// Per frame, client less server latency: time outside the server's measure (the control
    /// frame's trip in, the mesh frame's HTTP/2 encoding and trip out, the client's scheduling).
    pub outside_server_us: Percentiles,
    /// The server's CPU (`None`: not measurable, e.g. not Linux or no --server-pid).
    pub server_cpu: Option<Cpu>,
    /// This process's CPU (publishers and subscribers).
    pub client_cpu: Option<Cpu>,
    /// Every received frame.
    pub all_frames: FrameBytes,
    /// Keyframes among them (the room's periodic ones and those of skipping subscribers).
    pub keyframes: FrameBytes,
    /// Deltas among them.
    pub deltas: FrameBytes,
    /// Mesh bytes received per second, all subscribers (codec frames, no gRPC framing).
    pub bytes_per_second: f64,
    /// Frames decoded by the first subscriber of each room (whole run).
    pub decoded_frames: u64,
    /// Frames that failed to decode (whole run; must be 0).
    pub decode_errors: u64,
    /// The first decode error.
    pub first_decode_error: Option<String>,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// The model file.
    pub model: String,
    /// Its base vertices.
    pub vertices: usize,
    /// Its control points.
    pub control_points: usize,
    /// Where the control frames come from, and how many (looped).
    pub controls: String,
    /// The server under test.
    pub server: String,
    /// Logical CPUs of this machine (client and server share them).
    pub cpus: usize,
    /// The scenarios, in order.
    pub scenarios: Vec<ScenarioReport>,
}

/// Runs `crease bench-net`.
pub fn run(args: &BenchNetArgs) -> anyhow::Result<()> {
    if !(args.rate.is_finite() && args.rate > 0.0 && args.rate <= 1000.0) {
        bail!(
            "--rate must be in (0, 1000] frames per second, got {}",
            args.rate
        );
    }
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        bail!("--seconds must be > 0, got {}", args.seconds);
    }
    if !(args.warmup.is_finite() && args.warmup >= 0.0) {
        bail!("--warmup must be >= 0, got {}", args.warmup);
    }
    if args.rooms == Some(0) || args.subscribers == Some(0) {
        bail!("--rooms and --subscribers must be at least 1");
    }
    if args.server.is_some() && args.admin_token.is_none() {
        bail!("--server needs the server's --admin-token (to open the rooms)");
    }
    let model = TrainedModel::load(&args.model)
        .with_context(|| format!("loading model {}", args.model.display()))?;
    let (frames, source) = control_frames(args, &model)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    let report = runtime.block_on(bench(args, &model, frames, source))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

/// The control frames to loop (room and seq filled in when sent), and where they come from.
fn control_frames(
    args: &BenchNetArgs,
    model: &TrainedModel,
) -> anyhow::Result<(Vec<v1::ControlFrame>, String)> {
    if let Some(path) = &args.controls {
        let read = read_control_frames(path, model.controls.len())?;
        let frames = read
            .iter()
            .map(|f| control_frame("", 0, 0, &f.positions, &f.valid))
            .collect::<Vec<_>>();
        let source = format!("{} ({} frames)", path.display(), frames.len());
        return Ok((frames, source));
    }
    let dir = args
        .gallop
        .clone()
        .unwrap_or_else(|| PathBuf::from(DEFAULT_GALLOP));
    let set = ExampleSet::load(&dir).with_context(|| {
        format!(
            "reading the control sequence {} (--gallop DIR, or --controls FILE)",
            dir.display()
        )
    })?;
    let vertices = model.rig.rest.vertex_count();
    if set.rest.vertex_count() != vertices {
        bail!(
            "{}: meshes of {} vertices, the model has {vertices}",
            dir.display(),
            set.rest.vertex_count()
        );
    }
    // Every mesh has the rest's vertex count (ExampleSet checks), the model's (checked above),
    // and the model's control vertices are below it (TrainedModel::load validates).
    let valid = vec![true; model.controls.len()];
    let frames = set
        .examples
        .iter()
        .map(|e| {
            let points: Vec<crease_core::glam::Vec3> = model
                .controls
                .iter()
                .map(|c| e.mesh.positions[c.vertex as usize])
                .collect();
            control_frame("", 0, 0, &points, &valid)
        })
        .collect::<Vec<_>>();
    let source = format!("{} ({} frames)", dir.display(), frames.len());
    Ok((frames, source))
}

/// A `crease-server` child process and its scratch folder (model link, log); killed and
/// removed when dropped.
#[derive(Debug)]
struct SpawnedServer {
    child: Child,
    dir: PathBuf,
}

impl SpawnedServer {
    /// The last lines of its log, for error messages.
    fn log_tail(&self) -> String {
        let log = std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }
}

impl Drop for SpawnedServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The server under test.
#[derive(Debug)]
struct Target {
    url: String,
    admin_token: String,
    model: String,
    pid: Option<u32>,
    description: String,
    spawned: Option<SpawnedServer>,
}

/// 128 random bits, hex (std's per-map random SipHash keys: no extra dependency).
fn random_token() -> String {
    (0..2)
        .map(|_| format!("{:016x}", RandomState::new().hash_one(0u8)))
        .collect()
}

/// A loopback address with a port that was free a moment ago.
fn free_address(held: &mut Vec<std::net::TcpListener>) -> anyhow::Result<std::net::SocketAddr> {
    let listener =
        std::net::TcpListener::bind("127.0.0.1:0").context("finding a free loopback port")?;
    let addr = listener.local_addr()?;
    // Held until both ports are chosen, so they differ; dropped before the server binds.
    held.push(listener);
    Ok(addr)
}

/// Spawns `crease-server` on the model and waits until it answers.
async fn spawn_server(args: &BenchNetArgs) -> anyhow::Result<Target> {
    let bin = match &args.server_bin {
        Some(bin) => bin.clone(),
        None => std::env::current_exe()
            .context("locating the crease executable")?
            .with_file_name(format!("crease-server{}", std::env::consts::EXE_SUFFIX)),
    };
    if !bin.is_file() {
        bail!(
            "{}: no crease-server binary (build it with `cargo build --release -p crease-server`, or pass --server-bin PATH or --server URL)",
            bin.display()
        );
    }
    let model = args
        .model
        .file_stem()
        .and_then(|s| s.to_str())
        .context("--model: the file name is not valid UTF-8")?
        .to_owned();
    let dir = std::env::temp_dir().join(format!(
        "crease-bench-net-{}-{}",
        std::process::id(),
        &random_token()[..8]
    ));
    let models = dir.join("models");
    std::fs::create_dir_all(&models).with_context(|| format!("creating {}", models.display()))?;
    let link = models.join(format!("{model}.crease"));
    let source =
        std::fs::canonicalize(&args.model).with_context(|| format!("{}", args.model.display()))?;
    #[cfg(unix)]
    std::os::unix::fs::symlink(&source, &link)
        .with_context(|| format!("linking {}", link.display()))?;
    #[cfg(not(unix))]
    std::fs::copy(&source, &link).with_context(|| format!("copying to {}", link.display()))?;
    let log = File::create(dir.join("server.log")).context("creating the server log")?;
    let mut held = Vec::new();
    let grpc = free_address(&mut held)?;
    let http = free_address(&mut held)?;
    drop(held);
    let admin_token = random_token();
    let child = Command::new(&bin)
        .arg("--models")
        .arg(&models)
        .args(["--grpc", &grpc.to_string(), "--http", &http.to_string()])
        .env("CREASE_ADMIN_TOKEN", &admin_token)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let mut server = SpawnedServer { child, dir };
    let url = format!("http://{grpc}");
    let deadline = Instant::now() + SERVER_START;
    loop {
        if let Some(status) = server.child.try_wait()? {
            bail!(
                "{} exited ({status}) before answering:\n{}",
                bin.display(),
                server.log_tail()
            );
        }
        if let Ok(mut client) = connect(&url).await
            && client.list_models(v1::ListModelsRequest {}).await.is_ok()
        {
            break;
        }
        if Instant::now() > deadline {
            bail!(
                "{} did not answer on {url} within {SERVER_START:?}:\n{}",
                bin.display(),
                server.log_tail()
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    Ok(Target {
        description: format!("{} (spawned, pid {})", bin.display(), server.child.id()),
        pid: Some(server.child.id()),
        url,
        admin_token,
        model,
        spawned: Some(server),
    })
}

/// A client on its own connection.
async fn connect(url: &str) -> anyhow::Result<CreaseClient<Channel>> {
    let channel = Endpoint::from_shared(url.to_owned())
        .with_context(|| format!("{url}: not a valid server URL"))?
        .connect()
        .await
        .with_context(|| format!("connecting to {url}"))?;
    Ok(CreaseClient::new(channel))
}

/// `USER_HZ`, the unit of `/proc/PID/stat`'s times: `getconf CLK_TCK`, else Linux's 100.
fn clock_ticks() -> f64 {
    Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|&hz| hz > 0.0)
        .unwrap_or(100.0)
}

/// CPU seconds (user + system, every thread, living or ended) of process `pid` so far, from
/// `/proc/PID/stat`; `None` off Linux.
fn cpu_seconds(pid: u32, hz: f64) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    Some(stat_ticks(&stat)? as f64 / hz)
}

/// utime + stime, in clock ticks, of a `/proc/PID/stat` line.
fn stat_ticks(stat: &str) -> Option<u64> {
    // Field 2 (the command name, in parentheses) may hold spaces and parentheses: count from
    // after its last `)`.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // `rest` starts at field 3; utime and stime are fields 14 and 15 (proc(5)).
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

/// When frames count: from `start` (after the warm-up) to `end`.
#[derive(Clone, Copy, Debug)]
struct Window {
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
    let mut client = connect(&url).await?;
    let (tx, rx) = tokio::sync::mpsc::channel(PUBLISH_QUEUE);
    let sender = tokio::spawn(async move {
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
            if tx.send(frame).await.is_err() {
                break;
            }
            sent_in_window += u64::from(window.contains(Instant::now()));
        }
        sent_in_window
    });
    let req = authorized(tokio_stream::wrappers::ReceiverStream::new(rx), &token)?;
    let mut acks = client
        .publish(req)
        .await
        .context("publishing")?
        .into_inner();
    let mut stats = PublisherStats::default();
    // The ack stream ends when the sender stops and the server has answered every frame.
    while let Some(ack) = acks.message().await.context("reading acks")? {
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
    }
    stats.sent_in_window = sender.await.context("the publisher task")?;
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
    // Holds the connection for the stream's life.
    _client: CreaseClient<Channel>,
    stream: tonic::Streaming<v1::MeshFrame>,
    vertices: usize,
}

/// Connects on its own connection and subscribes to `room`'s base mesh.
async fn subscribe(url: String, room: String, check: bool) -> anyhow::Result<Subscribed> {
    let mut client = connect(&url).await?;
    let (stream, topology) = super::common::subscribe(&mut client, &room, v1::Level::Base).await?;
    if check {
        read_topology(&topology).with_context(|| format!("room {room:?}: Topology"))?;
    }
    Ok(Subscribed {
        _client: client,
        stream,
        vertices: topology.vertex_count as usize,
    })
}

/// Reads frames until the window ends, recording those that arrive inside it; decodes every
/// frame when `decode`.
async fn read_frames(
    mut sub: Subscribed,
    decode: bool,
    window: Window,
) -> anyhow::Result<SubscriberStats> {
    let mut decoder = decode.then(|| FrameDecoder::new(sub.vertices));
    let mut stats = SubscriberStats::default();
    loop {
        let msg = tokio::select! {
            msg = sub.stream.message() => msg.context("reading mesh frames")?,
            () = tokio::time::sleep_until(window.end) => break,
        };
        let Some(msg) = msg else {
            break;
        };
        let now = Instant::now();
        let now_us = unix_us();
        let Some(v1::mesh_frame::Body::Frame(f)) = msg.body else {
            continue;
        };
        if let Some(decoder) = &mut decoder {
            match decoder.decode(&f.data) {
                Ok(_) => stats.decoded += 1,
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
        let len = f.data.len() as u64;
        match parse_frame(&f.data).map(|(h, _)| h.kind) {
            Ok(FrameKind::Key) => stats.key = (stats.key.0 + 1, stats.key.1 + len),
            Ok(FrameKind::Delta) => stats.delta = (stats.delta.0 + 1, stats.delta.1 + len),
            Err(e) => bail!("frame {}: not a codec frame: {e}", f.seq),
        }
    }
    Ok(stats)
}

/// Opens the rooms, connects the subscribers, publishes for warm-up + window, and summarises.
async fn run_scenario(
    target: &Target,
    sc: &Scenario,
    frames: &Arc<Vec<v1::ControlFrame>>,
    args: &BenchNetArgs,
) -> anyhow::Result<ScenarioReport> {
    let mut admin = connect(&target.url).await?;
    let tag = &random_token()[..6];
    let mut rooms = Vec::with_capacity(sc.rooms);
    for k in 0..sc.rooms {
        let id = format!("bench-{tag}-{}-{k}", sc.name);
        let open = v1::OpenRoomRequest {
            room: id.clone(),
            model: target.model.clone(),
            beta: 0.0,
            filter: None,
        };
        let opened = admin
            .open_room(authorized(open, &target.admin_token)?)
            .await
            .with_context(|| format!("opening room {id:?} on model {:?}", target.model))?
            .into_inner();
        rooms.push((id, opened.publish_token));
    }
    let result = drive(target, sc, frames, args, &rooms).await;
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
    target: &Target,
    sc: &Scenario,
    frames: &Arc<Vec<v1::ControlFrame>>,
    args: &BenchNetArgs,
    rooms: &[(String, String)],
) -> anyhow::Result<ScenarioReport> {
    // Every subscriber on its own connection, subscribed before the first frame.
    let mut connecting = JoinSet::new();
    for (r, (id, _)) in rooms.iter().enumerate() {
        for s in 0..sc.subscribers {
            let (url, id) = (target.url.clone(), id.clone());
            connecting.spawn(async move { (r, s, subscribe(url, id, s == 0).await) });
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
        readers.spawn(async move { (r, s, read_frames(sub, s == 0, window).await) });
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
    let (server0, client0, wall0) = (sample(target.pid), sample(Some(me)), Instant::now());
    tokio::time::sleep_until(window.end).await;
    let (server1, client1, wall1) = (sample(target.pid), sample(Some(me)), Instant::now());
    let seconds = (wall1 - wall0).as_secs_f64();

    // Publishers by room index; subscribers with their room's.
    let mut pubs: Vec<PublisherStats> = rooms.iter().map(|_| PublisherStats::default()).collect();
    while let Some(done) = publishers.join_next().await {
        let (k, stats) = done.context("a publisher task")?;
        pubs[k] = stats.with_context(|| format!("publisher of room {k}"))?;
    }
    let mut subs = Vec::with_capacity(rooms.len() * sc.subscribers);
    while let Some(done) = readers.join_next().await {
        let (r, s, stats) = done.context("a subscriber task")?;
        subs.push((
            r,
            stats.with_context(|| format!("subscriber {s} of room {r}"))?,
        ));
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
    Ok(ScenarioReport {
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
        server_cpu: cpu(server0, server1),
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

async fn bench(
    args: &BenchNetArgs,
    model: &TrainedModel,
    frames: Vec<v1::ControlFrame>,
    source: String,
) -> anyhow::Result<BenchReport> {
    let mut target = match &args.server {
        Some(url) => Target {
            url: url.clone(),
            admin_token: args.admin_token.clone().unwrap_or_default(),
            model: match &args.model_name {
                Some(name) => name.clone(),
                None => args
                    .model
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .context("--model: the file name is not valid UTF-8 (give --model-name)")?
                    .to_owned(),
            },
            pid: args.server_pid,
            description: match args.server_pid {
                Some(pid) => format!("{url} (pid {pid})"),
                None => format!("{url} (no --server-pid: no CPU figure)"),
            },
            spawned: None,
        },
        None => spawn_server(args).await?,
    };
    let frames = Arc::new(frames);
    let mut reports = Vec::new();
    for sc in scenarios(args) {
        eprintln!(
            "{}: {} room(s) x {} subscriber(s), {} Hz, {} s warm-up + {} s",
            sc.name, sc.rooms, sc.subscribers, args.rate, args.warmup, args.seconds
        );
        let report = run_scenario(&target, &sc, &frames, args).await;
        if let Some(server) = &mut target.spawned
            && let Some(status) = server.child.try_wait()?
        {
            bail!(
                "the server exited ({status}) during {}:\n{}",
                sc.name,
                server.log_tail()
            );
        }
        reports.push(report?);
    }
    Ok(BenchReport {
        model: args.model.display().to_string(),
        vertices: model.rig.rest.vertex_count(),
        control_points: model.controls.len(),
        controls: source,
        server: target.description.clone(),
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        scenarios: reports,
    })
}

/// A readable table on stdout: one column per scenario.
fn print_table(report: &BenchReport) {
    println!(
        "model {} ({} vertices, {} control points), control frames {}",
        report.model, report.vertices, report.control_points, report.controls
    );
    println!(
        "server {}; {} CPUs shared by the server and the clients (this process)",
        report.server, report.cpus
    );
    println!();
    let s = &report.scenarios;
    let header: Vec<String> = s
        .iter()
        .map(|r| format!("{} ({} x {})", r.name, r.rooms, r.subscribers_per_room))
        .collect();
    println!("| | {} |", header.join(" | "));
    println!("|---|{}", "---|".repeat(s.len()));
    let row = |label: &str, cell: &dyn Fn(&ScenarioReport) -> String| {
        let cells: Vec<String> = s.iter().map(cell).collect();
        println!("| {label} | {} |", cells.join(" | "));
    };
    let pct = |p: &Percentiles| format!("{} / {} / {} / {}", p.p50, p.p90, p.p99, p.max);
    let cpu = |c: &Option<Cpu>| match c {
        Some(c) => format!("{:.2} cores, {:.3} ms/frame", c.cores, c.ms_per_frame),
        None => "n/a".to_owned(),
    };
    row("window s", &|r| format!("{:.2}", r.seconds));
    row("control frames published (per room)", &|r| {
        format!("{} ({:.1})", r.frames_published, r.published_per_room.mean)
    });
    row("refused", &|r| r.frames_refused.to_string());
    row(
        "mesh frames received (per subscriber min / mean / max)",
        &|r| {
            let p = &r.received_per_subscriber;
            format!(
                "{} ({} / {:.1} / {})",
                r.frames_received, p.min, p.mean, p.max
            )
        },
    );
    row("skipped", &|r| r.frames_skipped.to_string());
    row("server latency µs p50 / p90 / p99 / max", &|r| {
        pct(&r.server_latency_us)
    });
    row("client latency µs p50 / p90 / p99 / max", &|r| {
        pct(&r.client_latency_us)
    });
    row(
        "publish ack µs (predict + encode) p50 / p90 / p99 / max",
        &|r| pct(&r.ack_latency_us),
    );
    row(
        "fan-out µs (mesh ready -> this subscriber's task) p50 / p90 / p99 / max",
        &|r| pct(&r.fan_out_us),
    );
    row(
        "outside the server µs (client - server) p50 / p90 / p99 / max",
        &|r| pct(&r.outside_server_us),
    );
    row("server CPU", &|r| cpu(&r.server_cpu));
    row("client CPU (this process)", &|r| cpu(&r.client_cpu));
    row("bytes / vertex / frame, all", &|r| {
        format!("{:.3}", r.all_frames.bytes_per_vertex)
    });
    row("keyframes (count)", &|r| {
        format!(
            "{:.3} ({})",
            r.keyframes.bytes_per_vertex, r.keyframes.frames
        )
    });
    row("deltas (count)", &|r| {
        format!("{:.3} ({})", r.deltas.bytes_per_vertex, r.deltas.frames)
    });
    row("mesh bytes / s out", &|r| {
        format!("{:.2} MB/s", r.bytes_per_second / 1e6)
    });
    row("decoded / decode errors", &|r| {
        format!("{} / {}", r.decoded_frames, r.decode_errors)
    });
    println!();
    println!(
        "server latency: control frame received -> mesh frame handed to the subscriber's stream \
         (Frame.server_latency_us); client latency: capture -> frame read here (same clock)."
    );
    for r in s {
        if let Some(e) = &r.first_refusal {
            println!("{}: first refused frame: {e}", r.name);
        }
        if let Some(e) = &r.first_decode_error {
            println!("{}: first decode error: {e}", r.name);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let mut v: Vec<u32> = (1..=100).rev().collect();
        let p = Percentiles::of(&mut v);
        assert_eq!((p.p50, p.p90, p.p99, p.max), (50, 90, 99, 100));
        assert!((p.mean - 50.5).abs() < 1e-9);
        let p = Percentiles::of(&mut [7]);
        assert_eq!((p.count, p.p50, p.p99, p.max), (1, 7, 7, 7));
        let p = Percentiles::of(&mut []);
        assert_eq!((p.count, p.p99), (0, 0));
    }

    #[test]
    fn proc_stat_with_spaces_and_parentheses_in_the_name() {
        // The kernel's format: pid (comm) state ppid ... utime stime ...
        let stat = "42 (a (b) c) S 1 42 42 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 3 0\n";
        assert_eq!(stat_ticks(stat), Some(300));
        assert_eq!(stat_ticks("42 (x) S 1 2"), None);
        assert_eq!(stat_ticks("no parenthesis"), None);
    }

    #[test]
    fn cpu_of_this_process_is_measured_on_linux() {
        let hz = clock_ticks();
        assert!(hz > 0.0);
        if cfg!(target_os = "linux") {
            let a = cpu_seconds(std::process::id(), hz).unwrap();
            let mut x = 0u64;
            let t = std::time::Instant::now();
            while t.elapsed() < Duration::from_millis(50) {
                x = x.wrapping_add(std::hint::black_box(1));
            }
            let b = cpu_seconds(std::process::id(), hz).unwrap();
            assert!(b >= a && x > 0);
        }
    }

    #[test]
    fn random_tokens_differ() {
        let (a, b) = (random_token(), random_token());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
    }
}
