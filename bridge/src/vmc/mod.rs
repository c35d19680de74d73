//! The VMC bridge (`crease bridge vmc`, issue 19): receives the VMC protocol (OSC over UDP, as VSeeFace,
//! VirtualMotionCapture or Warudo send it) and publishes one hand's joints and the trackers
//! into a retargeting room as marker frames (`ControlFrame.markers`); into a room of actors
//! (issue 38) both hands of the skeleton, each to the actor of its side, in one frame
//! (`ControlFrame.actors`).
//!
//! - [`osc`]: VMC messages out of OSC datagrams; malformed ones are refused whole.
//! - [`skeleton`]: Unity's humanoid chain, the left- to right-handed mirror, forward
//!   kinematics and the fingertips (the conventions are documented there).
//! - [`frames`]: the bridge's state, when a frame is complete (one per bundle that carries the
//!   hand's bones), the declared markers, and the UDP receive loop feeding a channel.
//!
//! Here: the bridge's options, the room (`GetRoom`: its `Retarget.markers` are what every
//! frame carries, in order), and [`run`]: the receive loop as the source of the tree's one
//! publish loop (`crease_remote::publish`), its acks and the final summary.

pub mod frames;
pub mod osc;
pub mod skeleton;

use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_remote::get_room;
use crease_remote::publish::{End, PublishOptions, Sink, publish};
use tonic::transport::Channel;

use frames::{Bridge, LoopOptions, Stats, receive_loop};
use skeleton::{Hand, TipLengths};

/// Frames that may wait for the Publish stream before new ones are dropped (about 0.5 s at
/// 60 Hz: a live source is better dropped than delayed).
const QUEUE: usize = 32;
/// Refused frames reported one by one before the rest are only counted.
const SHOWN_REFUSALS: u64 = 10;

/// What a VMC bridge publishes, and where.
#[derive(Clone, Debug)]
pub struct VmcOptions {
    /// The retargeting room to publish into.
    pub room: String,
    /// The room's publish token.
    pub token: String,
    /// Which hand's bones to publish.
    pub hand: Hand,
    /// Fingertip lengths.
    pub tips: TipLengths,
    /// The receive loop's settings (the UDP address included).
    pub receive: LoopOptions,
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

/// A room of actors' hands (issue 38): per actor with a side (`left`, `right`) its name, the
/// VMC hand of that side, and the markers its retarget declares. `--hand` does not apply: the
/// actors' sides say which hand drives which actor.
///
/// # Errors
/// No actor with a side, or one with a side that does not retarget markers, naming it.
pub fn hand_actors(
    room: &str,
    info: &crease_proto::v1::RoomInfo,
) -> anyhow::Result<Vec<(String, Hand, Vec<String>)>> {
    let mut out = Vec::new();
    for a in &info.actors {
        let Some(actor) = &a.actor else { continue };
        let hand = match actor.side.as_str() {
            "right" => Hand::Right,
            "left" => Hand::Left,
            _ => continue,
        };
        let declared = match &actor.retarget {
            Some(r) if !r.markers.is_empty() => r.markers.clone(),
            _ => bail!(
                "room {room:?}: actor {:?} ({} hand) does not retarget markers: crease bridge publishes capture markers, so give the actor a marker map",
                actor.name,
                actor.side
            ),
        };
        out.push((actor.name.clone(), hand, declared));
    }
    if out.is_empty() {
        bail!(
            "room {room:?} has {} actors, none with a side (left or right): a VMC hand drives the actor of its side",
            info.actors.len()
        );
    }
    Ok(out)
}

/// Runs the bridge: reads the room's declared markers, listens for VMC, and publishes every
/// frame into the room through the publish loop until interrupted (Ctrl-C), idle
/// ([`LoopOptions::idle_exit`]) or ended by the server, printing summaries on stderr.
///
/// # Errors
/// A room that does not retarget, a socket that cannot be bound, the receive loop's errors,
/// a refused or failed Publish stream, or a server that does not end it in 10 s.
pub async fn run(client: &mut CreaseClient<Channel>, opts: VmcOptions) -> anyhow::Result<()> {
    let VmcOptions {
        room,
        token,
        hand,
        tips,
        receive,
    } = opts;
    let info = get_room(client, &room).await?;
    let (bridge, what) = if info.actors.is_empty() {
        let declared = declared_markers(&room, &info)?;
        let what = format!(
            "the {} hand; publishing {} markers into room {room:?} ({})",
            hand.prefix().to_lowercase(),
            declared.len(),
            declared.join(", ")
        );
        (Bridge::new(&room, hand, tips, &declared)?, what)
    } else {
        let actors = hand_actors(&room, &info)?;
        let what = format!(
            "{} into room {room:?} (one frame per bundle holds every hand it moved)",
            actors
                .iter()
                .map(|(name, hand, declared)| format!(
                    "the {} hand as actor {name:?} ({} markers)",
                    hand.prefix().to_lowercase(),
                    declared.len()
                ))
                .collect::<Vec<_>>()
                .join(" and ")
        );
        (Bridge::actors(&room, &actors, tips)?, what)
    };
    let socket = tokio::net::UdpSocket::bind(&receive.listen)
        .await
        .with_context(|| format!("--listen {}: cannot bind UDP", receive.listen))?;
    eprintln!(
        "vmc: listening on {} for {what}",
        socket
            .local_addr()
            .map_or(receive.listen.clone(), |a| a.to_string()),
    );
    let stats = Arc::new(Stats::default());
    let source = {
        let stats = Arc::clone(&stats);
        move |sink: Sink| async move {
            tokio::select! {
                r = receive_loop(socket, bridge, sink, &stats, &receive) => r.map(|_| ()),
                _ = tokio::signal::ctrl_c() => Ok(()),
            }
        }
    };
    let mut on_ack = |ack: v1::PublishAck| {
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
        ControlFlow::Continue(())
    };
    let options = PublishOptions {
        queue: QUEUE,
        // The receive loop's end ends the Publish stream, and its acks drain.
        drain: Some(Duration::from_secs(10)),
    };
    let published = publish(client, &token, options, source, &mut on_ack).await;
    eprintln!("{}", stats.summary(false));
    let published = published.map_err(|e| e.into_anyhow("--token", "publishing", "the bridge"))?;
    let ack_error = published
        .status
        .map(|s| anyhow::Error::new(s).context("the Publish stream"));
    match published.end {
        // The server ended the Publish stream (a refused token, a closed room).
        End::ServerEnded => match ack_error {
            Some(e) => Err(e),
            None => bail!("the server ended the Publish stream"),
        },
        End::DrainTimedOut => {
            published.output?;
            bail!("the server did not end the Publish stream in 10 s")
        }
        End::Answered | End::Stopped => {
            published.output?;
            ack_error.map_or(Ok(()), Err)
        }
    }
}
