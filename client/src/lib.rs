//! crease-cli: the `crease` command. Every subcommand is a module of [`commands`] with an
//! options struct (clap derive) and a `run` function, so the logic is testable without
//! spawning a process.
//!
//! Layout:
//! - [`commands::fit`]: `crease fit` — proxy bones and skinning weights from example meshes.
//! - [`commands::train`]: `crease train` — a whole model (bones, controls, regressors).
//! - [`commands::eval`]: `crease eval` — leave-one-out and test tables of every method.
//! - [`commands::model`]: `crease model mirror` — a model reflected (a left hand from a right).
//! - [`commands::synth`]: `crease synth` — control frames in, meshes out, here;
//!   [`commands::remote_synth`]: the same on a server (`--server`).
//! - [`commands::handgen`]: `crease handgen` — a generated hand data set; `crease pose`.
//! - [`commands::watch`], [`commands::stream`], [`commands::room`], [`commands::retarget`]:
//!   watching and publishing into rooms, managing them, marker recordings to control frames.
//! - [`commands::job`]: `crease job` — batch synthesis as jobs on a server (issue 45):
//!   submit, watch, get, list, cancel.
//! - [`commands::take`]: `crease take` — a room's recordings: start, stop, list, download,
//!   replay, export as glTF; [`commands::take_export`]: the export's work (the skinned
//!   recording, the detail layer re-predicted and baked into morph targets).
//! - [`commands::decode_stream`]: `crease decode-stream` — a recorded stream decoded by the
//!   core (the reference decoder other clients are checked against).
//! - [`commands::bridge`]: `crease bridge vmc|natnet` — the options of the capture bridges;
//!   the protocols and the bridges are `crease_bridge`'s.
//! - [`commands::bench_net`]: `crease bench-net` — runs the `crease-bench` binary beside
//!   `crease` (the network load benchmark and the soaks, package `crease-bench`), which the run
//!   command does not build.
//!
//! Shared by the commands (these use no command module):
//! - [`commands::common`]: example loading, control-point specs, progress display, the server
//!   flags, `crease_remote`'s connect and request helpers re-exported.
//! - [`commands::training_args`]: the training flags of `train` and `eval`, method and kernel
//!   names.
//! - [`commands::layers`]: base and detailed example sets and the detail layer's flags.
//! - [`commands::report`]: the HTML reports of `train --report` and `eval --report` (pages,
//!   plots, renders, the poses they show).
//!
//! From `crease_remote` (a client of a server, shared with the bridges and `crease-bench`):
//! connecting, the one publish loop every publishing command runs through, the mesh-stream
//! reader, control-frame files.
//!
//! No module cycles: `tests/module_cycles.rs` fails on any, in every workspace crate.

pub mod commands;

use clap::{Parser, Subcommand};

/// crease: learn how a mesh deforms from a few examples, then drive it live.
#[derive(Debug, Parser)]
#[command(name = "crease", version, about, long_about = None)]
pub struct Cli {
    /// More log output on stderr (-v: debug, -vv: trace). RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit proxy bones and skinning weights to example meshes and write a rig file.
    Fit(commands::fit::FitArgs),
    /// Train a model: bones, control points, rotation regressors, edge skin.
    Train(commands::train::TrainArgs),
    /// Synthesize meshes from a file of control frames.
    Synth(commands::synth::SynthArgs),
    /// Compare methods by leave-one-out and on held-out test poses.
    Eval(commands::eval::EvalArgs),
    /// Operate on a trained model file: `mirror` (a left hand from a right-hand model).
    Model(commands::model::ModelArgs),
    /// Generate a hand data set (LYK06 sweep hand): posed meshes at two resolutions, joint
    /// angles, control-point layouts, manifests for train/eval, and a contact sheet.
    Handgen(commands::handgen::HandgenArgs),
    /// Write one posed sweep hand (a named pose or joint angles) as a mesh.
    Pose(commands::handgen::PoseArgs),
    /// Watch a room on a server: decode its frames, report frames/s, bytes and latency.
    Watch(commands::watch::WatchArgs),
    /// Publish control frames into a room in real time: a CSV/JSON file of frames, or a
    /// Qualisys TSV / C3D marker recording retargeted through a marker map.
    Stream(commands::stream::StreamArgs),
    /// Turn a marker recording (Qualisys TSV, C3D) into control frames for a model, through a
    /// marker map (registration, gap filling); writes the CSV `synth` and `stream` read.
    Retarget(commands::retarget::RetargetArgs),
    /// Open, inspect or close rooms on a server.
    Room(commands::room::RoomArgs),
    /// Record a room's takes on a server; list, download, replay and export them (glTF).
    Take(commands::take::TakeArgs),
    /// Batch synthesis as jobs on a server (issue 45): submit a file of control frames, watch
    /// the progress from anywhere, fetch the frames later; list and cancel.
    Job(commands::job::JobArgs),
    /// Publish a live capture source (VMC over OSC, OptiTrack NatNet) into a retargeting room.
    Bridge(commands::bridge::BridgeArgs),
    /// Decode a recorded mesh stream (`watch --record`; vertex or palette) with the Rust core
    /// and write its last frame's mesh: the reference for other decoders.
    DecodeStream(commands::decode_stream::DecodeStreamArgs),
    /// Network load benchmark (issue 6) and soaks: rooms, publishers and subscribers on
    /// loopback; latency, server CPU and bytes per vertex per frame. Runs the `crease-bench`
    /// binary beside `crease` (`cargo build --release -p crease-bench`) with these arguments.
    BenchNet(commands::bench_net::BenchNetArgs),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Fit(args) => commands::fit::run(&args),
        Command::Train(args) => commands::train::run(&args),
        // Remote synthesis builds on local synthesis's arguments, so the choice is made here.
        Command::Synth(args) => match &args.server {
            Some(server) => commands::remote_synth::run(&args, server),
            None => commands::synth::run(&args),
        },
        Command::Eval(args) => commands::eval::run(&args),
        Command::Model(args) => commands::model::run(&args),
        Command::Handgen(args) => commands::handgen::run(&args),
        Command::Pose(args) => commands::handgen::run_pose(&args),
        Command::Watch(args) => commands::watch::run(&args),
        Command::Stream(args) => commands::stream::run(&args),
        Command::Room(args) => commands::room::run(&args),
        Command::Take(args) => commands::take::run(&args),
        Command::Job(args) => commands::job::run(&args),
        Command::Bridge(args) => commands::bridge::run(&args),
        Command::DecodeStream(args) => commands::decode_stream::run(&args),
        Command::Retarget(args) => commands::retarget::run(&args),
        Command::BenchNet(args) => commands::bench_net::run(&args),
    }
}

/// Logs to stderr; `RUST_LOG` wins over `-v`.
pub fn init_tracing(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
