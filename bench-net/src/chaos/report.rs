//! The chaos soak's report ([`ChaosReport`], `--json`) and its table: the faults by kind, the
//! recovery per kind, what the checkers and the NATS observer saw, the takes, each replica's
//! RSS, and the violations that fail the run.

use std::collections::BTreeMap;
use std::io::Write;

use super::accounting::{Recovery, SplitBrain};
use super::faults::Fault;
use super::memory::Stretch;
use super::takes::TakeCheck;

/// Ordering violations, split-brain frames and gap violations listed in full at most.
pub(super) const LISTED: usize = 20;

/// A replica's memory over the soak.
#[derive(Clone, Debug, serde::Serialize)]
pub(super) struct ReplicaRss {
    /// Its id.
    pub replica: String,
    /// Times it died (killed, or on its own): its RSS starts again then.
    pub deaths: u32,
    /// The first and last samples, MiB.
    pub start_mib: f64,
    /// See `start_mib`.
    pub end_mib: f64,
    /// Its steady stretches, each judged on its own (`memory::steady`).
    pub stretches: Vec<Stretch>,
}

/// A room's longest stretch without a new frame, on any of its checkers.
#[derive(Clone, Debug, serde::Serialize)]
pub(super) struct RoomGap {
    /// The room.
    pub room: String,
    /// The replica whose checker saw it.
    pub replica: String,
    /// How long, seconds, and when it began.
    pub seconds: f64,
    /// See `seconds`.
    pub from_s: f64,
    /// The fault it is attributed to (its number, from 1, and kind).
    pub fault: Option<String>,
}

/// The chaos soak's report.
#[derive(Debug, serde::Serialize)]
pub(super) struct ChaosReport {
    /// Minutes asked for, and seconds run.
    pub minutes: f64,
    /// See `minutes`.
    pub duration_s: f64,
    /// The model.
    pub model: String,
    /// Replicas, rooms, viewers (besides the checkers), the publishers' rate and the lease.
    pub replicas: usize,
    /// See `replicas`.
    pub rooms: usize,
    /// See `replicas`.
    pub viewers: usize,
    /// See `replicas`.
    pub rate_hz: f64,
    /// See `replicas`.
    pub lease_ms: u64,
    /// The longest a room may go without a frame after a fault ended, seconds.
    pub max_gap_s: f64,
    /// The soak's folder (logs, takes, the NATS store) and its logs.
    pub dir: String,
    /// See `dir`.
    pub logs: Vec<String>,
    /// Faults the run must have (MINUTES x 2), and those it had, by kind and in order.
    pub faults_required: usize,
    /// See `faults_required`.
    pub faults_by_kind: BTreeMap<String, usize>,
    /// See `faults_required`.
    pub faults: Vec<Fault>,
    /// Per fault kind, the recovery of each (fault, room) whose frames stopped.
    pub recovery: BTreeMap<String, Recovery>,
    /// Frames the checkers received (three per room), and decode failures (those no
    /// keyframe healed among them).
    pub frames_seen: u64,
    /// See `frames_seen`.
    pub decode_errors: u64,
    /// See `frames_seen`.
    pub unhealed_decodes: u64,
    /// Frames the plain viewers read.
    pub viewer_frames: u64,
    /// Frames seen on NATS, without owner/epoch headers, and ownership changes seen there.
    pub nats_frames: u64,
    /// See `nats_frames`.
    pub nats_unlabelled: u64,
    /// See `nats_frames`.
    pub handovers: u64,
    /// Frames of an older epoch published before the hand-over and delivered after it (held
    /// in a paused owner's NATS client): the relays drop them; not split brain.
    pub nats_late: u64,
    /// Frames at or below the previous seq on a subscription, and the first of them.
    pub ordering_violations: usize,
    /// See `ordering_violations`.
    pub ordering_listed: Vec<String>,
    /// Frames on NATS of an older epoch than one already seen for their room, and the first.
    pub split_brain_frames: usize,
    /// See `split_brain_frames`.
    pub split_brain_listed: Vec<SplitBrain>,
    /// Per room, its longest gap.
    pub longest_gaps: Vec<RoomGap>,
    /// Gaps that no fault explains (none is a violation unless longer than the max gap).
    pub stalls_without_fault: usize,
    /// The takes, checked and bad.
    pub takes_checked: usize,
    /// See `takes_checked`.
    pub takes_bad: usize,
    /// See `takes_checked`.
    pub takes: Vec<TakeCheck>,
    /// Per replica, its RSS.
    pub rss: Vec<ReplicaRss>,
    /// Control frames sent; acks: superseded, refused (by reason).
    pub control_frames_sent: u64,
    /// See `control_frames_sent`.
    pub superseded: u64,
    /// See `control_frames_sent`.
    pub refused: BTreeMap<String, u64>,
    /// Publisher streams opened again, and of those dropped for want of acks.
    pub publisher_reconnects: u64,
    /// See `publisher_reconnects`.
    pub publisher_stalls: u64,
    /// Viewer connections made again; checker subscriptions refused or failed.
    pub viewer_reconnects: u64,
    /// See `viewer_reconnects`.
    pub checker_refusals: u64,
    /// Panics in the replicas' logs.
    pub panics: usize,
    /// Why it failed; empty when it passed.
    pub violations: Vec<String>,
}

/// The table, on `out`.
pub(super) fn print_table(r: &ChaosReport, out: &mut impl Write) -> std::io::Result<()> {
    writeln!(
        out,
        "chaos: {:.1} min ({:.0} s), {} replicas (lease {} ms), {} rooms at {} Hz, {} viewers, model {}",
        r.minutes, r.duration_s, r.replicas, r.lease_ms, r.rooms, r.rate_hz, r.viewers, r.model
    )?;
    let kinds: Vec<String> = r
        .faults_by_kind
        .iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect();
    writeln!(
        out,
        "  faults                 {} (at least {}): {}",
        r.faults.len(),
        r.faults_required,
        kinds.join(", ")
    )?;
    for (i, f) in r.faults.iter().enumerate() {
        writeln!(
            out,
            "    {:>3}  {:7.1} s - {:7.1} s  {:<9} {}",
            i + 1,
            f.start_s,
            f.end_s,
            f.kind.name(),
            f.target
        )?;
    }
    writeln!(
        out,
        "  recovery (s)           kind        rooms    p50     p99     max"
    )?;
    for (kind, s) in &r.recovery {
        writeln!(
            out,
            "                         {kind:<10} {:>6} {:>6.2}  {:>6.2}  {:>6.2}",
            s.count, s.p50, s.p99, s.max
        )?;
    }
    writeln!(
        out,
        "  frames                 {} seen by the checkers ({} decode failures, {} not healed by a keyframe); {} by the viewers",
        r.frames_seen, r.decode_errors, r.unhealed_decodes, r.viewer_frames
    )?;
    writeln!(
        out,
        "  NATS                   {} frames observed ({} without owner/epoch), {} ownership changes, {} late frames of an older epoch from before a hand-over (relays drop them)",
        r.nats_frames, r.nats_unlabelled, r.handovers, r.nats_late
    )?;
    writeln!(out, "  ordering violations    {}", r.ordering_violations)?;
    for o in &r.ordering_listed {
        writeln!(out, "    {o}")?;
    }
    writeln!(out, "  split-brain frames     {}", r.split_brain_frames)?;
    for s in &r.split_brain_listed {
        writeln!(
            out,
            "    {:7.1} s room {}: {} in epoch {} after epoch {} of {}",
            s.t, s.room, s.owner, s.epoch, s.newest, s.newest_owner
        )?;
    }
    let worst = r
        .longest_gaps
        .iter()
        .max_by(|a, b| a.seconds.total_cmp(&b.seconds));
    if let Some(g) = worst {
        writeln!(
            out,
            "  longest gap            {:.2} s (room {} on {}, from {:.1} s, {}); {} gaps no fault explains",
            g.seconds,
            g.room,
            g.replica,
            g.from_s,
            g.fault.as_deref().unwrap_or("no fault"),
            r.stalls_without_fault
        )?;
    }
    writeln!(
        out,
        "  takes                  {} checked, {} bad",
        r.takes_checked, r.takes_bad
    )?;
    for t in &r.takes {
        writeln!(
            out,
            "    {} on {}: {} frames, {} bytes{}{}{}: {}",
            t.take,
            t.replica,
            t.frames,
            t.bytes,
            if t.stopped { ", stopped" } else { "" },
            if t.truncated { ", truncated" } else { "" },
            if t.replica_killed {
                ", its replica was killed"
            } else {
                ""
            },
            t.bad.as_deref().unwrap_or("reads back whole")
        )?;
    }
    writeln!(
        out,
        "  RSS (MiB)              replica deaths  start    end   steady stretches judged: life, rooms owned and viewers (most), seconds, first -> last minute's peak, growth"
    )?;
    for m in &r.rss {
        let judged: Vec<String> = m
            .stretches
            .iter()
            .filter_map(|x| {
                let g = x.growth_percent?;
                Some(format!(
                    "{}:{} rooms {} viewers {:.0}-{:.0} s {:.1}->{:.1} {g:+.1}%",
                    x.life + 1,
                    x.rooms,
                    x.viewers,
                    x.from,
                    x.to,
                    x.first_peak_mib.unwrap_or(0.0),
                    x.last_peak_mib.unwrap_or(0.0)
                ))
            })
            .collect();
        writeln!(
            out,
            "                         {:<7} {:>6} {:>6.1} {:>6.1}   {}",
            m.replica,
            m.deaths,
            m.start_mib,
            m.end_mib,
            if judged.is_empty() {
                "none long enough".to_owned()
            } else {
                judged.join("; ")
            }
        )?;
    }
    writeln!(
        out,
        "  publishers             {} control frames sent, {} superseded, {} refused; {} reconnections ({} for want of acks)",
        r.control_frames_sent,
        r.superseded,
        r.refused.values().sum::<u64>(),
        r.publisher_reconnects,
        r.publisher_stalls
    )?;
    for (why, n) in &r.refused {
        writeln!(out, "    refused              {n} x {why:?}")?;
    }
    writeln!(
        out,
        "  viewers                {} reconnections; checkers {} failed subscriptions",
        r.viewer_reconnects, r.checker_refusals
    )?;
    writeln!(out, "  panics                 {}", r.panics)?;
    writeln!(out, "  logs                   {}", r.dir)?;
    for l in &r.logs {
        writeln!(out, "    {l}")?;
    }
    if r.violations.is_empty() {
        writeln!(out, "  PASS")?;
    } else {
        for v in &r.violations {
            writeln!(out, "  FAIL {v}")?;
        }
    }
    Ok(())
}
