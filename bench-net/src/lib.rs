//! crease-bench: the network load benchmark of issue 6 and the soak of issue 21, run as
//! `crease-bench` (this crate's binary) or `crease bench-net` (the same options, a call into
//! [`run`]). Publishers send control frames
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
//!
//! Every publisher (the benchmark's and the soak's) runs through the tree's one publish loop,
//! `crease_remote::publish`; subscriptions are `crease_remote::mesh_stream`'s.
//!
//! Layout (private modules):
//! - `load`: publishers, subscribers, one scenario's run;
//! - `server`: the spawned or running server under test, CPU from `/proc`;
//! - `report`: the figures and the table (its types re-exported here);
//! - `soak`: `--soak MINUTES`, the server held under churn and faults (and its `/proc` probe).
//!
//! This module has the options, the control frames and the run over the scenarios.

mod load;
mod report;
mod server;
mod soak;

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, bail};
use crease_core::mesh::ExampleSet;
use crease_core::model::TrainedModel;
use crease_proto::{control_frame, v1};

use crease_remote::control_file::read_control_frames;
pub use report::{
    BenchReport, Cpu, FrameBytes, Percentiles, ReplicaFigures, ScenarioReport, Spread,
};
use server::Target;

/// The horse gallop beside the checkout (`../shared/data`), as the core benches find it.
const DEFAULT_GALLOP: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/horse/gallop"
);

/// Issue 6's first scenario: one room watched by 100 viewers (the p99 target is set for it).
const ONE_ROOM: (usize, usize) = (1, 100);
/// Issue 6's second scenario: 20 rooms of 5 viewers (as many streams, 20x the predictions).
const MANY_ROOMS: (usize, usize) = (20, 5);
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
    /// The level the subscribers watch: `base` or `detail` (a model with a detail layer).
    #[arg(long, default_value = "base", value_parser = ["base", "detail"])]
    pub level: String,
    /// How the subscribers receive frames: `vertices` or `palette` (issue 18: the bones and
    /// the detail kernel vector; the checking subscriber decodes them on the CPU).
    #[arg(long, default_value = "vertices", value_parser = ["vertices", "palette"])]
    pub encoding: String,
    /// Bench a cluster instead: a local `nats-server` (JetStream) and this many `crease-server`
    /// replicas joined to it; one room, opened on the first replica (its owner), its
    /// --subscribers (default 300) spread over the replicas, and the same count / replicas
    /// on the owner alone for comparison. Reports each replica's latency and CPU and the NATS
    /// bytes per published frame.
    #[arg(long, value_name = "N", conflicts_with = "server")]
    pub replicas: Option<usize>,
    /// The `nats-server` binary for --replicas. Default: /usr/sbin/nats-server (Debian's) or
    /// one on the PATH.
    #[arg(long, value_name = "PATH", requires = "replicas")]
    pub nats_bin: Option<PathBuf>,
    /// Soak instead of bench: MINUTES of churn and faults against a spawned server (rooms,
    /// reconnecting publishers with malformed frames, viewers over gRPC and WebSocket that
    /// join, stall and leave, rooms opened and closed), sampling its RSS, fds and tasks; fails
    /// on a panic, a non-finite mesh, a stuck room or memory growth (issue 21, RELIABILITY.md).
    #[arg(long, value_name = "MINUTES", conflicts_with_all = ["server", "replicas"])]
    pub soak: Option<f64>,
    /// Soak: base rooms.
    #[arg(long, default_value_t = 20, requires = "soak")]
    pub soak_rooms: usize,
    /// Soak: rooms whose viewers watch the detail level (a model with a detail layer).
    #[arg(long, default_value_t = 2, requires = "soak")]
    pub soak_detail_rooms: usize,
    /// Soak: viewers (besides one checking viewer per room).
    #[arg(long, default_value_t = 200, requires = "soak")]
    pub soak_viewers: usize,
    /// Soak: seconds between samples of the server.
    #[arg(long, default_value_t = 5.0, requires = "soak")]
    pub sample_seconds: f64,
}

/// One load shape: rooms, each with its publisher and subscribers.
#[derive(Clone, Debug)]
struct Scenario {
    /// `one-room`, `many-rooms`, `custom`, `cluster` or `owner-only`.
    name: String,
    /// Rooms.
    rooms: usize,
    /// Subscribers per room.
    subscribers: usize,
    /// The subscribers are spread round-robin over the first this many servers (1: all on
    /// the one where the rooms are opened).
    spread: usize,
}

/// Viewers of the cluster scenario when --subscribers is not given (issue 17).
const CLUSTER_VIEWERS: usize = 300;

fn scenarios(args: &BenchNetArgs) -> Vec<Scenario> {
    let named = |name: &str, (rooms, subscribers): (usize, usize)| Scenario {
        name: name.to_owned(),
        rooms,
        subscribers,
        spread: 1,
    };
    if let Some(n) = args.replicas {
        let viewers = args.subscribers.unwrap_or(CLUSTER_VIEWERS);
        return vec![
            Scenario {
                spread: n,
                ..named("cluster", (1, viewers))
            },
            named("owner-only", (1, viewers.div_ceil(n))),
        ];
    }
    if let (Some(rooms), Some(subscribers)) = (args.rooms, args.subscribers) {
        return vec![named("custom", (rooms, subscribers))];
    }
    match args.scenario {
        ScenarioChoice::OneRoom => vec![named("one-room", ONE_ROOM)],
        ScenarioChoice::ManyRooms => vec![named("many-rooms", MANY_ROOMS)],
        ScenarioChoice::Both => vec![named("one-room", ONE_ROOM), named("many-rooms", MANY_ROOMS)],
    }
}

/// Runs `crease bench-net`.
pub fn run(args: &BenchNetArgs) -> anyhow::Result<()> {
    if let Some(minutes) = args.soak {
        return soak::run(args, minutes);
    }
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
    if args.replicas.is_some_and(|n| !(2..=16).contains(&n)) {
        bail!("--replicas must be 2 to 16");
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
        report::print_table(&report);
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

async fn bench(
    args: &BenchNetArgs,
    model: &TrainedModel,
    frames: Vec<v1::ControlFrame>,
    source: String,
) -> anyhow::Result<BenchReport> {
    let mut nats = None;
    let mut targets = match &args.server {
        _ if args.replicas.is_some() => {
            let (n, replicas) = server::spawn_cluster(args, args.replicas.unwrap_or(2)).await?;
            nats = Some(n);
            replicas
        }
        Some(url) => vec![Target {
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
            http: None,
        }],
        None => vec![server::spawn_server(args).await?],
    };
    let frames = Arc::new(frames);
    let mut reports = Vec::new();
    for sc in scenarios(args) {
        eprintln!(
            "{}: {} room(s) x {} subscriber(s), {} Hz, {} s warm-up + {} s",
            sc.name, sc.rooms, sc.subscribers, args.rate, args.warmup, args.seconds
        );
        let report = load::run_scenario(&targets, &sc, &frames, args).await;
        for target in &mut targets {
            if let Some(server) = &mut target.spawned
                && let Some(status) = server.child.try_wait()?
            {
                bail!(
                    "the server exited ({status}) during {}:\n{}",
                    sc.name,
                    server.log_tail()
                );
            }
        }
        reports.push(report?);
    }
    drop(nats);
    Ok(BenchReport {
        model: args.model.display().to_string(),
        vertices: model.rig.rest.vertex_count(),
        control_points: model.controls.len(),
        controls: source,
        server: targets
            .iter()
            .map(|t| t.description.as_str())
            .collect::<Vec<_>>()
            .join("; "),
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        scenarios: reports,
    })
}
