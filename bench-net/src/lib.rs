//! crease-bench: the network load benchmark of issue 6 and the soak of issue 21, run as
//! `crease-bench` (this crate's binary) or `crease bench-net` (the same options, a call into
//! [`run`]). Publishers send control frames
//! into rooms at a fixed rate over gRPC, subscribers (one connection each, like separate
//! viewers, over gRPC or the browsers' WebSocket: `--transport`) read the encoded meshes, and
//! the report gives the server's latency from control frame received to mesh frame handed to
//! each subscriber's stream (`Frame.server_latency_us`), the server's CPU (also per
//! viewer-frame, beside this machine's floor for the same fan-out measured in the same run),
//! and bytes per vertex per frame.
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
//! - `args`: the options ([`BenchNetArgs`]) and the scenarios they choose;
//! - `load`: publishers, subscribers, one scenario's run;
//! - `floor`: this machine's floor for a fan-out (one write per viewer-frame to loopback
//!   sockets), measured beside each scenario;
//! - `server`: the spawned or running server under test, CPU from `/proc`;
//! - `report`: the figures and the table (its types re-exported here);
//! - `soak`: `--soak MINUTES`, the server held under churn and faults (and its `/proc` probe);
//! - `chaos`: `--chaos MINUTES`, a spawned cluster (NATS and three replicas) under load while
//!   replicas are killed and paused, NATS restarted and publishers moved (issue 40);
//! - `idle`: `--idle SECONDS`, the embedded demo server's CPU with nobody connected, and the
//!   time to a new viewer's first frame (issue 41).
//!
//! This module has the control frames and the run over the scenarios.

mod args;
mod chaos;
mod floor;
mod idle;
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

pub use args::{BenchNetArgs, ScenarioChoice, TransportChoice};
use args::{DEFAULT_GALLOP, scenarios};
use crease_remote::control_file::read_control_frames;
pub use report::{
    BenchReport, Cpu, Floor, FrameBytes, Percentiles, ReplicaFigures, ScenarioReport, Spread,
};
use server::Target;

/// Runs `crease bench-net`.
pub fn run(args: &BenchNetArgs) -> anyhow::Result<()> {
    if let Some(minutes) = args.soak {
        return soak::run(args, minutes);
    }
    if let Some(minutes) = args.chaos {
        return chaos::run(args, minutes);
    }
    if let Some(seconds) = args.idle {
        return idle::run(args, seconds);
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
            http: args.server_http,
        }],
        None => vec![server::spawn_server(args).await?],
    };
    let frames = Arc::new(load::actor_frames(&frames, args.actors));
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
        refine: args.refine.to_string(),
        server: targets
            .iter()
            .map(|t| t.description.as_str())
            .collect::<Vec<_>>()
            .join("; "),
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        scenarios: reports,
    })
}
