//! `crease bridge vmc` (issue 19): receives the VMC protocol (OSC over UDP, as VSeeFace,
//! VirtualMotionCapture or Warudo send it) and publishes one hand's joints and the trackers
//! into a retargeting room as marker frames (`ControlFrame.markers`).
//!
//! - [`osc`]: VMC messages out of OSC datagrams; malformed ones are refused whole.
//! - [`skeleton`]: Unity's humanoid chain, the left- to right-handed mirror, forward
//!   kinematics and the fingertips (the conventions are documented there).
//! - [`frames`]: the bridge's state, when a frame is complete (one per bundle that carries the
//!   hand's bones), the declared markers, and the UDP receive loop feeding a channel.
//!
//! Here: the options, the room (`GetRoom`: its `Retarget.markers` are what every frame
//! carries, in order), and the Publish stream with its acks and periodic summary.

pub mod frames;
pub mod osc;
pub mod skeleton;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};

use super::super::common::{ServerArgs, authorized, get_room};
use frames::{Bridge, LoopOptions, Stats, receive_loop};
use skeleton::{Hand, TipLengths};

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
    /// Which hand's bones to publish.
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

/// Frames that may wait for the Publish stream before new ones are dropped (about 0.5 s at
/// 60 Hz: a live source is better dropped than delayed).
const QUEUE: usize = 32;
/// Refused frames reported one by one before the rest are only counted.
const SHOWN_REFUSALS: u64 = 10;

fn seconds(name: &str, v: f64, zero_ok: bool) -> anyhow::Result<Duration> {
    if !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0))) {
        bail!("--{name} must be a positive number of seconds, got {v}");
    }
    Ok(Duration::from_secs_f64(v))
}

/// Runs `crease bridge vmc`.
pub fn run(args: &VmcArgs) -> anyhow::Result<()> {
    let tips = match &args.bones {
        Some(p) => TipLengths::read(p)?,
        None => TipLengths::default(),
    };
    let summary = seconds("summary-every", args.summary_every, true)?;
    let opts = LoopOptions {
        warn_after: seconds("warn-after", args.warn_after, false)?,
        idle_exit: args
            .idle_exit
            .map(|s| seconds("idle-exit", s, false))
            .transpose()?,
        summary_every: (!summary.is_zero()).then_some(summary),
        listen: args.listen.clone(),
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(bridge(args, tips, &opts))
}

/// The room's declared markers: `RoomInfo.retarget.markers`.
///
/// # Errors
/// A room that does not retarget, or declares no markers.
pub fn declared_markers(
    room: &str,
    info: &crease_proto::v1::RoomInfo,
) -> anyhow::Result<Vec<String>> {
    let Some(r) = &info.retarget else {
        bail!(
            "room {room:?} does not retarget markers: crease bridge publishes capture markers, so open the room with a marker map (OpenRoomRequest.retarget)"
        );
    };
    if r.markers.is_empty() {
        bail!("room {room:?} declares no markers (Retarget.markers is empty)");
    }
    Ok(r.markers.clone())
}

async fn bridge(args: &VmcArgs, tips: TipLengths, opts: &LoopOptions) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let info = get_room(&mut client, &args.room).await?;
    let declared = declared_markers(&args.room, &info)?;
    let bridge = Bridge::new(&args.room, args.hand, tips, &declared)?;
    let socket = tokio::net::UdpSocket::bind(&args.listen)
        .await
        .with_context(|| format!("--listen {}: cannot bind UDP", args.listen))?;
    eprintln!(
        "vmc: listening on {} for the {} hand; publishing {} markers into room {:?} ({})",
        socket
            .local_addr()
            .map_or(args.listen.clone(), |a| a.to_string()),
        args.hand.prefix().to_lowercase(),
        declared.len(),
        args.room,
        declared.join(", ")
    );
    let stats = Arc::new(Stats::default());
    let (tx, rx) = tokio::sync::mpsc::channel(QUEUE);
    let req = authorized(tokio_stream::wrappers::ReceiverStream::new(rx), &args.token)
        .context("--token")?;
    let acks = {
        let stats = Arc::clone(&stats);
        tokio::spawn(async move {
            let mut acks = client
                .publish(req)
                .await
                .context("publishing")?
                .into_inner();
            while let Some(ack) = acks.message().await.context("the Publish stream")? {
                stats.ack(ack.seq, ack.error.is_some(), ack.control_residual_capture);
                if let Some(e) = ack.error {
                    let refused = stats.refused.load(std::sync::atomic::Ordering::Relaxed);
                    if refused <= SHOWN_REFUSALS {
                        eprintln!(
                            "vmc: frame {} refused (code {}): {}",
                            ack.seq, e.code, e.message
                        );
                    } else if refused == SHOWN_REFUSALS + 1 {
                        eprintln!("vmc: further refusals are counted in the summary");
                    }
                }
            }
            anyhow::Ok(())
        })
    };
    let mut acks = acks;
    let received = tokio::select! {
        r = receive_loop(socket, bridge, tx, &stats, opts) => r.map(|_| ()),
        a = &mut acks => {
            // The server ended the Publish stream (a refused token, a closed room).
            eprintln!("{}", stats.summary(false));
            a.context("the ack reader stopped")??;
            bail!("the server ended the Publish stream");
        }
        _ = tokio::signal::ctrl_c() => Ok(()),
    };
    // The receive loop's end dropped the sender: the Publish stream ends and its acks drain.
    let published = match tokio::time::timeout(Duration::from_secs(10), acks).await {
        Ok(r) => r.context("the ack reader stopped")?,
        Err(_) => Err(anyhow::anyhow!(
            "the server did not end the Publish stream in 10 s"
        )),
    };
    eprintln!("{}", stats.summary(false));
    received?;
    published?;
    Ok(())
}
