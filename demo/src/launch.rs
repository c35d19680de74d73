//! The `crease-server` binary's job as one library call: [`run`] (or [`start`], for callers
//! that stop the server themselves) takes a [`Config`], loads the models, trains or loads the
//! demo hand off the async threads, opens and animates room `demo`, binds the listeners, and
//! tells the user where to look.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use crease_core::model::MirrorPlane;
use crease_proto::room::{ActorSpec, Placement, RoomOptions, RoomSpec, RoomToken, Side};
use crease_server::registry::{ModelRegistry, RegistryError};
use crease_server::{AppState, OpenRoomError, Running};

use crate::animation::{ActorAnimation, DemoAnimation, drive};
use crate::hand_model::{DemoError, default_cache_dir, demo_model};
use crate::{
    DEMO_BETA, DEMO_BOTH_HANDS_ROOM, DEMO_CAMERA_ROOM, DEMO_HANDS_REFINE, DEMO_HANDS_ROOM,
    DEMO_MODEL, DEMO_PERFORMER_ROOM, DEMO_ROOM, DEMO_VMC_ROOM, MEDIAPIPE_LEFT_MAP, MEDIAPIPE_MAP,
    PERFORMER_LEFT_POSES, VMC_LEFT_MAP, VMC_MAP, WEBXR_LEFT_MAP, WEBXR_MAP,
};

/// Everything `crease-server` is told: what to serve and how.
#[derive(Clone, Debug)]
pub struct Config {
    /// The server library's configuration: addresses, admin token, limits, TLS, web folder.
    pub server: crease_server::Config,
    /// Folder of `*.crease` model files; `None` serves only the demo.
    pub models: Option<PathBuf>,
    /// Run the demo next to `models` too (always on when `models` is `None`).
    pub demo: bool,
    /// Where the demo model is cached; `None`: [`default_cache_dir`].
    pub cache: Option<PathBuf>,
    /// The demo room's publish token; `None`: a random one, printed at start.
    pub demo_token: Option<String>,
    /// Frames per second of the demo animation.
    pub demo_rate: f64,
    /// How long in-flight calls may finish after shutdown starts.
    pub drain: Duration,
    /// Join this cluster (`--nats`); the demo room, if any, stays local to this replica.
    pub cluster: Option<crease_server::cluster::ClusterOptions>,
    /// [`run`] writes its banner and progress lines as `info` events (target
    /// `crease_demo::banner`) rather than plain lines on stderr: with `--log-format json`,
    /// stderr stays one JSON object per line.
    pub banner_in_log: bool,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            server: crease_server::Config::default(),
            models: None,
            demo: false,
            cache: None,
            demo_token: None,
            // A display's refresh rate: the hand moves smoothly in the viewer.
            demo_rate: 60.0,
            // Long enough for an ack in flight, short enough for a container's grace period.
            drain: Duration::from_secs(5),
            cluster: None,
            banner_in_log: false,
        }
    }
}

impl Config {
    /// Whether this configuration runs the demo.
    pub fn runs_demo(&self) -> bool {
        self.models.is_none() || self.demo
    }
}

/// The `web/` folder of the source tree this binary was built from, if it exists (the default
/// of `--web`).
pub fn source_tree_web() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../web");
    dir.is_dir().then_some(dir)
}

/// Where [`start`] reports progress (one line each), from any thread.
pub type Progress = Arc<dyn Fn(&str) + Send + Sync>;

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// The model folder could not be read, or a model in it not loaded.
    #[error(transparent)]
    Models(#[from] RegistryError),
    /// The model folder holds no model and the demo is off.
    #[error("{0}: no *.crease model files (train one with `crease train`, or add --demo)")]
    NoModels(PathBuf),
    /// The demo model could not be built.
    #[error(transparent)]
    Demo(#[from] DemoError),
    /// The demo room could not be opened.
    #[error("the demo room: {0}")]
    Room(#[from] OpenRoomError),
    /// The room of two actors could not be opened.
    #[error("the demo's room of actors {DEMO_PERFORMER_ROOM:?}: {0}")]
    Performer(String),
    /// The WebXR room could not be opened (its joint map does not bind to the demo model).
    #[error("the demo's WebXR room {DEMO_HANDS_ROOM:?}: {0}")]
    Hands(String),
    /// Binding a listener, or the TLS files.
    #[error("serving: {0}")]
    Io(#[from] std::io::Error),
    /// The demo's training task panicked.
    #[error("the demo model's training task: {0}")]
    Join(#[from] tokio::task::JoinError),
    /// The cluster could not be joined.
    #[error("joining the cluster: {0}")]
    Cluster(#[from] crease_server::cluster::ClusterError),
}

/// A started server.
#[derive(Debug)]
pub struct Started {
    /// The listeners; [`Running::shutdown`] stops them.
    pub running: Running,
    /// The demo room's publish token, when the demo runs.
    pub demo_token: Option<String>,
    /// Whether the listeners speak TLS.
    pub tls: bool,
}

impl Started {
    /// The lines that tell a user where things are: the listeners, and with the demo the
    /// viewer URL, a `crease watch` command that runs from here, and the publish token (unless
    /// the operator chose it).
    pub fn banner(&self, token_chosen: bool) -> Vec<String> {
        let (grpc, http) = (self.running.grpc, self.running.http);
        let (metrics_here, metrics_apart) = match self.running.metrics {
            None => (" /metrics", String::new()),
            Some(addr) => ("", format!(", metrics on {addr} (/metrics)")),
        };
        let mut lines = vec![format!(
            "crease-server: gRPC on {grpc}, HTTP on {http} (/healthz /readyz{metrics_here} /ws/rooms/ROOM){metrics_apart}"
        )];
        let Some(token) = &self.demo_token else {
            return lines;
        };
        let scheme = if self.tls { "https" } else { "http" };
        let host = |addr: SocketAddr| {
            if addr.ip().is_unspecified() {
                "localhost".to_owned()
            } else {
                addr.ip().to_string()
            }
        };
        lines.push(format!(
            "demo: room {DEMO_ROOM:?} is live. Open {scheme}://{}:{}/?room={DEMO_ROOM} or run \
             `{} watch --server {scheme}://{}:{} --room {DEMO_ROOM}`",
            host(http),
            http.port(),
            crease_command(),
            host(grpc),
            grpc.port()
        ));
        lines.push(format!(
            "demo: room {DEMO_HANDS_ROOM:?} follows a tracked hand: open {scheme}://{}:{}/?room={DEMO_HANDS_ROOM} \
             in a WebXR browser with hand tracking (Quest, visionOS) and press \"track my hands\"",
            host(http),
            http.port(),
        ));
        lines.push(format!(
            "demo: room {DEMO_PERFORMER_ROOM:?} holds both hands of a performer, one stream \
             ({scheme}://{}:{}/?room={DEMO_PERFORMER_ROOM}); room {DEMO_BOTH_HANDS_ROOM:?} \
             takes both of your tracked hands at once",
            host(http),
            http.port(),
        ));
        lines.push(format!(
            "demo: room {DEMO_VMC_ROOM:?} takes a VMC sender's hands (VSeeFace, VirtualMotionCapture, \
             Warudo): `{} bridge vmc --server {scheme}://{}:{} --room {DEMO_VMC_ROOM} --token TOKEN`",
            crease_command(),
            host(grpc),
            grpc.port()
        ));
        lines.push(format!(
            "demo: room {DEMO_CAMERA_ROOM:?} follows your hands on a webcam: open {scheme}://{}:{}/?room={DEMO_CAMERA_ROOM} \
             and press \"track my hands (camera)\" (only the hands' landmarks leave the page)",
            host(http),
            http.port(),
        ));
        if !token_chosen {
            lines.push(format!(
                "demo: publish token {token} (enter it in the viewer to drag control points)"
            ));
        }
        lines
    }
}

/// How to run `crease` from the working directory: the binary built beside this one (`cargo
/// build --release` puts both in `target/release`), relative to the working directory when it
/// is below it; else `cargo run --release -p crease-cli --`, which builds it first.
pub fn crease_command() -> String {
    let beside = std::env::current_exe()
        .ok()
        .map(|exe| exe.with_file_name(format!("crease{}", std::env::consts::EXE_SUFFIX)))
        .filter(|p| p.is_file());
    match beside {
        Some(path) => {
            let cwd = std::env::current_dir().unwrap_or_default();
            match path.strip_prefix(&cwd) {
                Ok(rel) => format!("./{}", rel.display()),
                Err(_) => path.display().to_string(),
            }
        }
        None => "cargo run --release -p crease-cli --".to_owned(),
    }
}

/// Loads the models, builds the demo (off the async threads), opens and animates room `demo`,
/// and binds the listeners. `progress` gets the demo's training progress and warnings, as they
/// happen.
///
/// # Errors
/// [`LaunchError`]: the model folder, the demo, or binding.
pub async fn start(config: Config, progress: Progress) -> Result<Started, LaunchError> {
    let models = match &config.models {
        Some(dir) => {
            let models = ModelRegistry::load_dir(dir)?;
            // A cluster replica may start with none: it fetches its rooms' models.
            if models.is_empty() && !config.demo && config.cluster.is_none() {
                return Err(LaunchError::NoModels(dir.clone()));
            }
            models
        }
        None => ModelRegistry::default(),
    };
    let demo = if config.runs_demo() {
        let cache = config.cache.clone().unwrap_or_else(default_cache_dir);
        let say = Arc::clone(&progress);
        // Training and sampling the animation take seconds: the blocking pool, not the executor.
        let (model, animation, left) = tokio::task::spawn_blocking(move || {
            let model = demo_model(&cache, &mut |line| say(&format!("demo: {line}")))?;
            let animation = DemoAnimation::new(&model)?;
            let left = DemoAnimation::of_poses(&model, &PERFORMER_LEFT_POSES)?;
            Ok::<_, DemoError>((model, animation, left))
        })
        .await??;
        Some((models.insert(DEMO_MODEL, model), animation, left))
    } else {
        None
    };
    for m in models.list() {
        tracing::info!(model = %m.name, vertices = m.info.base_vertices, detail = m.info.detail_vertices, "loaded");
    }
    if let Some(dir) = &config.server.web
        && !dir.join("node_modules/three").is_dir()
    {
        progress(&format!(
            "warning: {} has no node_modules: the viewer needs three.js and meshoptimizer \
             (run `npm ci --prefix {}`)",
            dir.display(),
            dir.display()
        ));
    }
    let tls = config.server.tls.is_some();
    let mut server = config.server;
    // Uploads go into the folder the models came from (issue 39).
    if server.models_dir.is_none() {
        server.models_dir = config.models.clone();
    }
    // Takes go to the cache folder's `takes/` unless the operator chose a folder.
    if server.takes.is_none() {
        server.takes = Some(
            config
                .cache
                .clone()
                .unwrap_or_else(default_cache_dir)
                .join("takes"),
        );
    }
    // Job results likewise, in `jobs/` (issue 45).
    if server.jobs.dir.is_none() {
        server.jobs.dir = Some(
            config
                .cache
                .clone()
                .unwrap_or_else(default_cache_dir)
                .join("jobs"),
        );
    }
    let state = AppState::new(models, server);
    if let Some(options) = config.cluster {
        crease_server::join_cluster(&state, options).await?;
        // This replica pulls the cluster's job chunks from now on (issue 45).
        crease_server::job_service::start_cluster_worker(&state);
    }
    let mut demo_token = None;
    if let Some((model, animation, left)) = demo {
        // Keyframe mode: the control points are followed closely (HZY11 Fig. 11: beta ~3).
        // The demo's rooms are this replica's alone, in a cluster too.
        let spec = RoomSpec {
            id: DEMO_ROOM.into(),
            model: model.name.clone(),
            options: RoomOptions {
                beta: Some(DEMO_BETA),
                ..RoomOptions::default()
            },
            token: config
                .demo_token
                .clone()
                .map_or(RoomToken::Random, RoomToken::Fixed),
            placement: Placement::Local,
            ..RoomSpec::default()
        };
        let room = state.open_room(spec).await?;
        let token = room.token().unwrap_or_default().to_owned();
        tokio::spawn(drive(
            Arc::clone(&state),
            room,
            ActorAnimation::single(animation.clone()),
            config.demo_rate,
        ));
        state
            .open_room(hands_room(&model, &token))
            .await
            .map_err(|e| LaunchError::Hands(e.to_string()))?;
        state
            .open_room(both_hands_room(&model, &token))
            .await
            .map_err(|e| LaunchError::Hands(e.to_string()))?;
        state
            .open_room(vmc_room(&model, &token))
            .await
            .map_err(|e| LaunchError::Hands(e.to_string()))?;
        state
            .open_room(camera_room(&model, &token))
            .await
            .map_err(|e| LaunchError::Hands(e.to_string()))?;
        let performer = state
            .open_room(performer_room(&model, &token))
            .await
            .map_err(|e| LaunchError::Performer(e.to_string()))?;
        let actors = vec![
            ActorAnimation {
                actor: Some("right".into()),
                animation,
                mirrored: false,
            },
            ActorAnimation {
                actor: Some("left".into()),
                animation: left,
                mirrored: true,
            },
        ];
        tokio::spawn(drive(
            Arc::clone(&state),
            performer,
            actors,
            config.demo_rate,
        ));
        demo_token = Some(token);
    }
    let running = crease_server::serve(state).await?;
    Ok(Started {
        running,
        demo_token,
        tls,
    })
}

/// The WebXR room [`DEMO_HANDS_ROOM`] on the demo model, with the demo room's `token`: it
/// retargets the viewer's WebXR joints through [`WEBXR_MAP`], in metres, with the demo's beta
/// and no filter (headset runtimes smooth their hand tracking already, and every filtered
/// frame would add latency).
fn hands_room(model: &crease_server::registry::LoadedModel, token: &str) -> RoomSpec {
    RoomSpec {
        id: DEMO_HANDS_ROOM.into(),
        model: model.name.clone(),
        options: hands_options(),
        retarget: Some(webxr_retarget(WEBXR_MAP)),
        token: RoomToken::Fixed(token.to_owned()),
        placement: Placement::Local,
        ..RoomSpec::default()
    }
}

/// The retargeting of WebXR's joints (the markers of `crease_hand::joint_map::capture_markers`,
/// in metres) through the joint map `map`.
fn webxr_retarget(map: &str) -> crease_proto::v1::Retarget {
    crease_proto::room::retarget(
        map.to_owned(),
        crease_hand::joint_map::capture_markers(),
        "m".into(),
    )
}

/// The options of a room (or actor) a tracked hand drives: the demo's beta, no filter
/// (headset runtimes smooth their hand tracking already, and every filtered frame would add
/// latency), and the refinement: a performer's hands leave the training poses, and it holds
/// the fingers to the tracked joints where the regression extrapolates (issue 20;
/// BENCHMARKS.md "Beyond the examples": half the regression's error on hands far from the
/// examples). Skinning is the model's default (the demo hand is trained with LBS): the viewer
/// may subscribe with palette frames, which it skins with LBS, and a DQS room refuses those.
fn hands_options() -> RoomOptions {
    RoomOptions {
        beta: Some(DEMO_BETA),
        filter: None,
        refine: Some(DEMO_HANDS_REFINE),
        skinning: None,
    }
}

/// The WebXR room of two actors [`DEMO_BOTH_HANDS_ROOM`] on the demo model (issue 38): `right`
/// through [`WEBXR_MAP`], `left` on the model mirrored across x through [`WEBXR_LEFT_MAP`], one
/// performer, as [`DEMO_HANDS_ROOM`] otherwise.
fn both_hands_room(model: &crease_server::registry::LoadedModel, token: &str) -> RoomSpec {
    let actor = |name: &str, side, mirror, map| ActorSpec {
        name: name.into(),
        model: model.name.clone(),
        side,
        mirror,
        performer: "you".into(),
        options: hands_options(),
        retarget: Some(webxr_retarget(map)),
        model_sha256: None,
    };
    RoomSpec {
        id: DEMO_BOTH_HANDS_ROOM.into(),
        actors: vec![
            actor("right", Side::Right, None, WEBXR_MAP),
            actor("left", Side::Left, Some(MirrorPlane::X), WEBXR_LEFT_MAP),
        ],
        token: RoomToken::Fixed(token.to_owned()),
        placement: Placement::Local,
        ..RoomSpec::default()
    }
}

/// The VMC room [`DEMO_VMC_ROOM`] on the demo model (issue 39): both hands of a VMC sender's
/// skeleton (`crease bridge vmc` sends Unity's bone names, in metres), `right` through
/// [`VMC_MAP`], `left` on the model mirrored across x through [`VMC_LEFT_MAP`], one
/// performer, as [`DEMO_HANDS_ROOM`] otherwise.
fn vmc_room(model: &crease_server::registry::LoadedModel, token: &str) -> RoomSpec {
    use crease_hand::vmc_map::vmc_markers;
    two_hands_room(
        model,
        token,
        DEMO_VMC_ROOM,
        "vmc",
        [
            (VMC_MAP, vmc_markers("Right")),
            (VMC_LEFT_MAP, vmc_markers("Left")),
        ],
        hands_options(),
    )
}

/// The camera room [`DEMO_CAMERA_ROOM`] on the demo model (issue 46): the viewer's "track my
/// hands (camera)" publishes MediaPipe Hands' 21 world landmarks per hand (metres), the right
/// hand onto the demo hand through [`MEDIAPIPE_MAP`], the left onto it mirrored across x
/// through [`MEDIAPIPE_LEFT_MAP`], one performer, as [`DEMO_HANDS_ROOM`] otherwise but for the
/// One Euro filter (its defaults, for metres): MediaPipe estimates every frame afresh, and
/// nothing smooths its landmarks before the room does (a headset's runtime and a VMC sender
/// smooth their own).
fn camera_room(model: &crease_server::registry::LoadedModel, token: &str) -> RoomSpec {
    use crease_hand::mediapipe_map::mediapipe_markers;
    two_hands_room(
        model,
        token,
        DEMO_CAMERA_ROOM,
        "camera",
        [
            (MEDIAPIPE_MAP, mediapipe_markers()),
            (MEDIAPIPE_LEFT_MAP, mediapipe_markers()),
        ],
        RoomOptions {
            filter: Some(crease_core::runtime::filter::OneEuroParams::default()),
            ..hands_options()
        },
    )
}

/// A room of two actors on the demo model driven by one performer's tracked hands (marker
/// positions in metres): `right` as trained, `left` mirrored across x, each through its map
/// of the markers named, with `options` (the hands rooms', [`hands_options`], or those with a
/// filter).
fn two_hands_room(
    model: &crease_server::registry::LoadedModel,
    token: &str,
    id: &str,
    performer: &str,
    [right, left]: [(&str, Vec<String>); 2],
    options: RoomOptions,
) -> RoomSpec {
    let actor = |name: &str, side, mirror, (map, markers): (&str, Vec<String>)| ActorSpec {
        name: name.into(),
        model: model.name.clone(),
        side,
        mirror,
        performer: performer.into(),
        options,
        retarget: Some(crease_proto::room::retarget(
            map.to_owned(),
            markers,
            "m".into(),
        )),
        model_sha256: None,
    };
    RoomSpec {
        id: id.into(),
        actors: vec![
            actor("right", Side::Right, None, right),
            actor("left", Side::Left, Some(MirrorPlane::X), left),
        ],
        token: RoomToken::Fixed(token.to_owned()),
        placement: Placement::Local,
        ..RoomSpec::default()
    }
}

/// The room of two actors [`DEMO_PERFORMER_ROOM`] on the demo model (issue 38): `right` as
/// trained, `left` mirrored across x, one performer, keyframe beta, the demo room's `token`.
fn performer_room(model: &crease_server::registry::LoadedModel, token: &str) -> RoomSpec {
    let actor = |name: &str, side, mirror| ActorSpec {
        name: name.into(),
        model: model.name.clone(),
        side,
        mirror,
        performer: "demo".into(),
        options: RoomOptions {
            beta: Some(DEMO_BETA),
            ..RoomOptions::default()
        },
        retarget: None,
        model_sha256: None,
    };
    RoomSpec {
        id: DEMO_PERFORMER_ROOM.into(),
        actors: vec![
            actor("right", Side::Right, None),
            actor("left", Side::Left, Some(MirrorPlane::X)),
        ],
        token: RoomToken::Fixed(token.to_owned()),
        placement: Placement::Local,
        ..RoomSpec::default()
    }
}

/// [`start`], the banner on stderr, then serving until `shutdown` resolves (the binary passes
/// [`shutdown_signal`]), then a graceful stop within the configured drain.
///
/// # Errors
/// [`LaunchError`] from [`start`], or a transport error while stopping.
pub async fn run(
    config: Config,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let token_chosen = config.demo_token.is_some();
    let drain = config.drain;
    let say: Progress = if config.banner_in_log {
        Arc::new(|line: &str| tracing::info!(target: "crease_demo::banner", "{line}"))
    } else {
        Arc::new(|line: &str| eprintln!("{line}"))
    };
    let started = start(config, Arc::clone(&say)).await?;
    // Armed before the banner tells anyone the server is up: `shutdown_signal` installs its
    // handlers when first polled, and a SIGTERM between the banner and that poll took the
    // default action (the process killed, not stopped; RELIABILITY.md).
    let mut shutdown = std::pin::pin!(shutdown);
    let signalled = tokio::select! {
        biased;
        () = &mut shutdown => true,
        () = std::future::ready(()) => false,
    };
    for line in started.banner(token_chosen) {
        say(&line);
    }
    if !signalled {
        shutdown.await;
    }
    say("shutting down");
    started.running.shutdown(drain).await?;
    Ok(())
}

/// The binary's whole life: [`run`] until [`shutdown_signal`], on `runtime`. Not generic, so
/// the async code it drives (the server's, async-nats's, hyper's) is compiled here and in the
/// crates that define it, not once more in the binary: a `block_on` of the generic [`run`] in
/// `main.rs` instantiated all of it there, 44 s of the binary's compile (issue 41).
pub fn run_until_signal(
    runtime: &tokio::runtime::Runtime,
    config: Config,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    runtime.block_on(run(config, shutdown_signal()))
}

/// Resolves on Ctrl-C, or on SIGTERM (what container runtimes send) on Unix; also when the
/// signal handlers cannot be installed (the server then stops rather than run unstoppable).
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        let Ok(mut term) =
            tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        else {
            return;
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = tokio::signal::ctrl_c().await;
}
