//! `crease bridge`: live capture sources that do not speak crease's gRPC, received on UDP and
//! published into a retargeting room (issue 19) as marker frames (`ControlFrame.markers`):
//! - [`vmc`]: the VMC protocol (OSC over UDP: VSeeFace, VirtualMotionCapture, Warudo, ...);
//! - [`natnet`]: OptiTrack's NatNet (Motive's stream of labelled markers and rigid bodies).
//!
//! A malformed datagram is counted and dropped, never fatal.

pub mod natnet;
pub mod vmc;

/// Options of `crease bridge`.
#[derive(Clone, Debug, clap::Args)]
pub struct BridgeArgs {
    /// The capture protocol.
    #[command(subcommand)]
    pub source: Source,
}

/// The capture protocols `crease bridge` reads.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum Source {
    /// Receive VMC (OSC over UDP) bone poses and trackers and publish them as markers.
    Vmc(vmc::VmcArgs),
    /// Connect to an OptiTrack NatNet server and publish its labelled markers.
    Natnet(natnet::NatnetArgs),
}

/// Runs `crease bridge`.
pub fn run(args: &BridgeArgs) -> anyhow::Result<()> {
    match &args.source {
        Source::Vmc(a) => vmc::run(a),
        Source::Natnet(a) => natnet::run(a),
    }
}
