//! `crease bridge`: live capture sources that do not speak crease's gRPC, received on UDP and
//! published into a retargeting room (issue 19) as marker frames (`ControlFrame.markers`):
//! - `vmc`: the VMC protocol (OSC over UDP: VSeeFace, VirtualMotionCapture, Warudo, ...);
//! - `natnet`: OptiTrack's NatNet (Motive's stream of labelled markers and rigid bodies).
//!
//! The protocols, and the bridges that publish them, are `crease_bridge`'s; here are the
//! options and their checks.

use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use crease_bridge::natnet::{self, NatnetOptions, SourceOptions};
use crease_bridge::vmc::frames::LoopOptions;
use crease_bridge::vmc::skeleton::{Hand, TipLengths};
use crease_bridge::vmc::{self, VmcOptions};

use super::common::ServerArgs;

/// Options of `crease bridge`.
#[derive(Clone, Debug, clap::Args)]
pub struct BridgeArgs {
    /// The capture protocol.
    #[command(subcommand)]
    pub capture: Capture,
}

/// The capture protocols `crease bridge` reads.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum Capture {
    /// Receive VMC (OSC over UDP) bone poses and trackers and publish them as markers.
    Vmc(VmcArgs),
    /// Connect to an OptiTrack NatNet server and publish its labelled markers.
    Natnet(NatnetArgs),
}

/// Runs `crease bridge`.
pub fn run(args: &BridgeArgs) -> anyhow::Result<()> {
    match &args.capture {
        Capture::Vmc(a) => run_vmc(a),
        Capture::Natnet(a) => run_natnet(a),
    }
}

/// Options of `crease bridge vmc`.
#[derive(Clone, Debug, clap::Args)]
pub struct VmcArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The UDP address to receive VMC on (VMC's usual port is 39539).
    #[arg(long, default_value = "0.0.0.0:39539")]
    pub listen: String,
    /// The retargeting room to publish into (opened with a marker map).
    #[arg(long)]
    pub room: String,
    /// The room's publish token (from `crease room open`). Also read from CREASE_TOKEN.
    #[arg(long, env = "CREASE_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Which hand's bones to publish into a one-actor room. A room of actors (issue 38) takes
    /// both: each hand drives the actor of its side (`crease room open --actors`).
    #[arg(long, value_enum, default_value = "right")]
    pub hand: Hand,
    /// Fingertip lengths (TOML: `[tip_ratio]` / `[tip_length]` per digit; see the docs of
    /// `TipLengths::read`). Default: 0.8 of the segment before each distal joint.
    #[arg(long, value_name = "FILE")]
    pub bones: Option<PathBuf>,
    /// Seconds without the hand's bones before a warning (and after which declared trackers
    /// that never arrived are an error).
    #[arg(long, default_value_t = 5.0)]
    pub warn_after: f64,
    /// Seconds between summary lines (0: only at the end).
    #[arg(long, default_value_t = 5.0)]
    pub summary_every: f64,
    /// Stop after this many seconds without a datagram, once the stream has started.
    #[arg(long, value_name = "SECONDS")]
    pub idle_exit: Option<f64>,
}

fn seconds(name: &str, v: f64, zero_ok: bool) -> anyhow::Result<Duration> {
    if !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0))) {
        bail!("--{name} must be a positive number of seconds, got {v}");
    }
    Ok(Duration::from_secs_f64(v))
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")
}

/// Runs `crease bridge vmc`.
pub fn run_vmc(args: &VmcArgs) -> anyhow::Result<()> {
    let tips = match &args.bones {
        Some(p) => TipLengths::read(p)?,
        None => TipLengths::default(),
    };
    let summary = seconds("summary-every", args.summary_every, true)?;
    let receive = LoopOptions {
        warn_after: seconds("warn-after", args.warn_after, false)?,
        idle_exit: args
            .idle_exit
            .map(|s| seconds("idle-exit", s, false))
            .transpose()?,
        summary_every: (!summary.is_zero()).then_some(summary),
        listen: args.listen.clone(),
    };
    let opts = VmcOptions {
        room: args.room.clone(),
        token: args.token.clone(),
        hand: args.hand,
        tips,
        receive,
    };
    runtime()?.block_on(async {
        let mut client = args.server.connect().await?;
        vmc::run(&mut client, opts).await
    })
}

/// Options of `crease bridge natnet`.
#[derive(Clone, Debug, clap::Args)]
pub struct NatnetArgs {
    /// The crease server (gRPC) to publish into.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The NatNet server's command address, `HOST[:PORT]` (port 1510 by default).
    #[arg(long, value_name = "ADDR")]
    pub natnet: String,
    /// The local interface to use (IPv4 address). Default: any.
    #[arg(long, value_name = "ADDR")]
    pub local: Option<Ipv4Addr>,
    /// Receive frames from this multicast group (e.g. 239.255.42.99) instead of unicast.
    #[arg(long, value_name = "GROUP")]
    pub multicast: Option<Ipv4Addr>,
    /// The data port (frames of data); 0 = any free port (unicast only).
    #[arg(long, default_value_t = 1511)]
    pub data_port: u16,
    /// The room to publish into (a retargeting room: `crease room open --map ... --markers ...`).
    #[arg(long)]
    pub room: String,
    /// The room's publish token. Also read from CREASE_TOKEN.
    #[arg(long, env = "CREASE_TOKEN", hide_env_values = true)]
    pub token: String,
    /// Seconds to wait for the NatNet server's answers to NAT_CONNECT and the model request.
    #[arg(long, default_value_t = 10.0)]
    pub connect_timeout: f64,
    /// Seconds between summary lines.
    #[arg(long, default_value_t = 5.0)]
    pub summary_every: f64,
    /// Stop after publishing this many frames (default: run until interrupted).
    #[arg(long)]
    pub frames: Option<u64>,
}

/// Runs `crease bridge natnet`.
pub fn run_natnet(args: &NatnetArgs) -> anyhow::Result<()> {
    if !(args.summary_every.is_finite() && args.summary_every > 0.0) {
        bail!("--summary-every must be a positive number of seconds");
    }
    if !(args.connect_timeout.is_finite() && args.connect_timeout > 0.0) {
        bail!("--connect-timeout must be a positive number of seconds");
    }
    runtime()?.block_on(async {
        let mut client = args.server.connect().await?;
        let opts = NatnetOptions {
            room: args.room.clone(),
            token: args.token.clone(),
            source: SourceOptions {
                command: natnet::command_addr(&args.natnet)?,
                local: args.local.unwrap_or(Ipv4Addr::UNSPECIFIED),
                multicast: args.multicast,
                data_port: args.data_port,
                timeout: Duration::from_secs_f64(args.connect_timeout),
            },
            summary_every: Duration::from_secs_f64(args.summary_every),
            frames: args.frames,
        };
        natnet::run(&mut client, opts).await
    })
}
