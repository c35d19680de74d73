//! The options of `crease bench-net` / `crease-bench` ([`BenchNetArgs`]) and the load shapes
//! they choose ([`Scenario`]): what every other module of the crate reads, so it sits below
//! them all.

use std::path::PathBuf;

/// The horse gallop beside the checkout (`../shared/data`), as the core benches find it.
pub(crate) const DEFAULT_GALLOP: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/horse/gallop"
);

/// The demo hand's file (`crease_demo::hand_model::CACHE_FILE`) in the demo's cache folder,
/// found as `crease_demo::hand_model::default_cache_dir` finds it: `$CREASE_CACHE_DIR`, else
/// `$XDG_CACHE_HOME/crease`, else `$HOME/.cache/crease`, else `.crease-cache`. The chaos
/// soak's model when --model is not given.
pub(crate) fn demo_model() -> PathBuf {
    let env = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
    let dir = if let Some(dir) = env("CREASE_CACHE_DIR") {
        PathBuf::from(dir)
    } else if let Some(dir) = env("XDG_CACHE_HOME") {
        PathBuf::from(dir).join("crease")
    } else if let Some(home) = env("HOME") {
        PathBuf::from(home).join(".cache").join("crease")
    } else {
        PathBuf::from(".crease-cache")
    };
    dir.join("demo-hand-v1.crease")
}

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

/// How the subscribers of the benchmark connect.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum TransportChoice {
    /// The gRPC `Subscribe` RPC, one HTTP/2 connection per subscriber.
    Grpc,
    /// The WebSocket endpoint browsers use (`/ws/rooms/{id}`), one socket per subscriber.
    Ws,
    /// Every scenario twice in one run: gRPC, then WebSocket.
    Both,
}

/// Options of `crease bench-net`.
#[derive(Clone, Debug, clap::Args)]
#[command(after_long_help = AFTER_HELP)]
#[command(group(clap::ArgGroup::new("spawns_nats").args(["replicas", "chaos"]).multiple(true)))]
pub struct BenchNetArgs {
    /// The trained model (the horse for issue 6's figures: see --help). Default: the demo hand
    /// in the demo's cache folder (`crease-server` leaves it there on its first start), the
    /// model of --chaos and --idle.
    #[arg(
        long,
        value_name = "FILE",
        required_unless_present_any = ["chaos", "idle"],
        default_value_os_t = demo_model(),
        hide_default_value = true
    )]
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
    /// Actors per room (issue 38): 1 opens rooms on the model as always; N opens rooms of N
    /// actors on it, every odd one mirrored across x (a left hand beside each right), all
    /// driven by the same control frames (reflected for the mirrored ones), each frame
    /// carrying every actor's. The server's rate limit counts actors x frames: a spawned server gets
    /// --max-publish-hz 4 x rate x N (a --server one needs it above rate x N).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub actors: u32,
    /// The rooms' bone-level refinement, asked for explicitly: `off` (the regression alone,
    /// as every figure before issue 42) or `ITERATIONS,STRENGTH` (`8,0.01` is what a server
    /// gives rooms that do not choose).
    #[arg(long, value_name = "ITERATIONS,STRENGTH|off", default_value = "off", value_parser = crease_proto::room::parse_refine_flag)]
    pub refine: crease_proto::room::RefineFlag,
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
    /// How the subscribers connect: `grpc`, `ws` (the WebSocket endpoint browsers use) or
    /// `both` (each scenario on gRPC, then on WebSocket). Every scenario also measures this
    /// machine's floor for its fan-out: one thread writing one frame-sized message to each of
    /// as many loopback sockets per frame (issue 41).
    #[arg(long, value_enum, default_value = "grpc")]
    pub transport: TransportChoice,
    /// With --server: its HTTP address (host:port), which --transport ws connects to.
    #[arg(long, value_name = "ADDR", requires = "server")]
    pub server_http: Option<std::net::SocketAddr>,
    /// Bench a cluster instead: a local `nats-server` (JetStream) and this many `crease-server`
    /// replicas joined to it; one room, opened on the first replica (its owner), its
    /// --subscribers (default 300) spread over the replicas, and the same count / replicas
    /// on the owner alone for comparison. Reports each replica's latency and CPU and the NATS
    /// bytes per published frame.
    #[arg(long, value_name = "N", conflicts_with = "server")]
    pub replicas: Option<usize>,
    /// The `nats-server` binary for --replicas and --chaos. Default: /usr/sbin/nats-server
    /// (Debian's) or one on the PATH.
    #[arg(long, value_name = "PATH", requires = "spawns_nats")]
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
    /// Chaos soak instead of bench (issue 40): MINUTES of a spawned cluster (`nats-server`
    /// with JetStream and three replicas) under load while a fault is injected every 20-40 s
    /// (a replica killed and restarted, a room's owner paused past its lease, NATS restarted,
    /// a publisher moved); checks frame order, split brain (NATS epochs), recovery gaps, takes
    /// and RSS growth, and fails on any violation or on fewer than MINUTES x 2 faults.
    #[arg(long, value_name = "MINUTES", conflicts_with_all = ["server", "replicas", "soak"])]
    pub chaos: Option<f64>,
    /// Chaos: rooms (opened on the replicas in turn, one publisher each).
    #[arg(long, default_value_t = 20, requires = "chaos")]
    pub chaos_rooms: usize,
    /// Chaos: viewers spread over the replicas (besides three checkers per room).
    #[arg(long, default_value_t = 200, requires = "chaos")]
    pub chaos_viewers: usize,
    /// Chaos: the replicas' lease (`crease-server --lease-ms`); a pause lasts 2.5 leases. A
    /// room whose owner dies comes back after about a lease and an eighth (the adopter's
    /// check) plus the hand-over, so the 3 s bar wants less than the server's default
    /// 2 s on a loaded machine (RELIABILITY.md, "The chaos soak").
    #[arg(long, value_name = "MS", default_value_t = 1500, requires = "chaos")]
    pub chaos_lease_ms: u64,
    /// Chaos: the longest a room may go without a frame once a fault has ended, seconds.
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = 10.0,
        requires = "chaos"
    )]
    pub chaos_max_gap: f64,
    /// Idle measurement instead of bench (issue 41): the embedded demo server (the cache
    /// folder of --model, the demo hand by default) spawned with nobody connected, its CPU
    /// over SECONDS from `/proc/PID/stat` (goal: at most 0.5% of a core), then the time from
    /// subscribing to the first frame for a new viewer of each encoding.
    #[arg(long, value_name = "SECONDS", conflicts_with_all = ["server", "replicas", "soak", "chaos"])]
    pub idle: Option<f64>,
}

/// One load shape: rooms, each with its publisher and subscribers.
#[derive(Clone, Debug)]
pub(crate) struct Scenario {
    /// `one-room`, `many-rooms`, `custom`, `cluster` or `owner-only`.
    pub(crate) name: String,
    /// Rooms.
    pub(crate) rooms: usize,
    /// Subscribers per room.
    pub(crate) subscribers: usize,
    /// The subscribers are spread round-robin over the first this many servers (1: all on
    /// the one where the rooms are opened).
    pub(crate) spread: usize,
    /// How the subscribers connect.
    pub(crate) transport: Transport,
}

/// How one scenario's subscribers connect.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Transport {
    /// The gRPC `Subscribe` RPC.
    Grpc,
    /// `GET /ws/rooms/{id}`, as the browser viewer subscribes.
    WebSocket,
}

impl Transport {
    /// As the report names it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Transport::Grpc => "grpc",
            Transport::WebSocket => "websocket",
        }
    }
}

/// Viewers of the cluster scenario when --subscribers is not given (issue 17).
const CLUSTER_VIEWERS: usize = 300;

/// The scenarios of a run, each on every transport --transport names.
pub(crate) fn scenarios(args: &BenchNetArgs) -> Vec<Scenario> {
    let transports: &[Transport] = match args.transport {
        TransportChoice::Grpc => &[Transport::Grpc],
        TransportChoice::Ws => &[Transport::WebSocket],
        TransportChoice::Both => &[Transport::Grpc, Transport::WebSocket],
    };
    shapes(args)
        .into_iter()
        .flat_map(|sc| {
            transports.iter().map(move |&transport| Scenario {
                transport,
                ..sc.clone()
            })
        })
        .collect()
}

/// The load shapes of a run (on gRPC; [`scenarios`] sets the transport).
fn shapes(args: &BenchNetArgs) -> Vec<Scenario> {
    let named = |name: &str, (rooms, subscribers): (usize, usize)| Scenario {
        name: name.to_owned(),
        rooms,
        subscribers,
        spread: 1,
        transport: Transport::Grpc,
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
