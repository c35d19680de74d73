//! The chaos soak's bookkeeping, free of I/O so that it is unit-tested: what one checker saw
//! ([`Watch`]: frames, the gaps between new frames, ordering, decode failures and the
//! keyframes that heal them), what the NATS observer saw ([`EpochCheck`]: split brain), how
//! gaps are attributed to the faults ([`attribute`], [`uncovered`]) and summarised per fault
//! kind ([`recoveries`], [`Recovery`]), and when the next fault is due ([`next_gap`]).
//!
//! Times are seconds since the soak started.

use std::collections::{BTreeMap, HashMap};

/// A kind of fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum FaultKind {
    /// A replica killed and restarted.
    Kill,
    /// A room's owner paused past its lease.
    Pause,
    /// NATS restarted.
    Nats,
    /// A publisher moved to another replica.
    Publisher,
}

impl FaultKind {
    pub(super) const ALL: [FaultKind; 4] = [
        FaultKind::Kill,
        FaultKind::Pause,
        FaultKind::Nats,
        FaultKind::Publisher,
    ];

    pub(super) fn name(self) -> &'static str {
        match self {
            FaultKind::Kill => "kill",
            FaultKind::Pause => "pause",
            FaultKind::Nats => "nats",
            FaultKind::Publisher => "publisher",
        }
    }
}

/// A checker that sees no new frame for longer than this saw its room's frames stop (a gap).
pub(super) const STOPPED_S: f64 = 0.5;
/// A gap that begins within this long after a fault ended is still that fault's (NATS
/// reconnections, an adoption after a resumed owner's lease).
pub(super) const GRACE_S: f64 = 10.0;

/// A stretch in which a checker saw no new frame of its room, longer than [`STOPPED_S`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub(super) struct Gap {
    /// The last new frame before (the checker's start when it had seen none yet).
    pub from: f64,
    /// The first new frame after (the end of the run when none came: `open`).
    pub to: f64,
    /// No frame came before the end of the run.
    pub open: bool,
}

impl Gap {
    pub(super) fn seconds(&self) -> f64 {
        self.to - self.from
    }
}

/// A frame that came with a seq at or below the previous one on the same subscription.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub(super) struct OutOfOrder {
    /// When it came.
    pub t: f64,
    /// The previous frame's seq and this one's.
    pub previous: u64,
    /// See `previous`.
    pub seq: u64,
}

/// What one checker (a room's decoding viewer on one replica) saw.
#[derive(Clone, Debug)]
pub(super) struct Watch {
    /// The highest seq this checker has seen, over all its subscriptions: a frame above it is
    /// new (a resubscription may start with a frame already seen).
    newest: Option<u64>,
    /// When the last new frame came (the checker's start before the first).
    last_new: f64,
    /// The previous frame's seq on the current subscription.
    previous: Option<u64>,
    /// A decode failure not yet healed by a keyframe on its subscription: when it happened.
    unhealed: Option<f64>,
    /// `--chaos-max-gap`: how long a decode failure may go without a keyframe, and how long
    /// the wait for the first frame may be before it counts as a gap.
    max_gap: f64,
    /// Frames received.
    pub frames: u64,
    /// Gaps longer than [`STOPPED_S`].
    pub gaps: Vec<Gap>,
    /// Ordering violations.
    pub out_of_order: Vec<OutOfOrder>,
    /// Frames that did not decode.
    pub decode_errors: u64,
    /// Decode failures that no keyframe followed within `max_gap` on their subscription.
    pub unhealed_decodes: u64,
    /// Subscriptions (the first and every resubscription).
    pub subscriptions: u64,
}

impl Watch {
    /// A checker started at `t`; a decode failure must be healed by a keyframe within
    /// `max_gap` seconds, and the first frame must come within `max_gap` (the wait for it
    /// is not a gap otherwise: the publishers are starting).
    pub(super) fn new(t: f64, max_gap: f64) -> Watch {
        Watch {
            newest: None,
            last_new: t,
            previous: None,
            unhealed: None,
            max_gap,
            frames: 0,
            gaps: Vec::new(),
            out_of_order: Vec::new(),
            decode_errors: 0,
            unhealed_decodes: 0,
            subscriptions: 0,
        }
    }

    /// A new subscription: ordering starts again, and its first frame is a keyframe (a new
    /// decoder), so a failure on the old one is not held against the new.
    pub(super) fn subscribed(&mut self) {
        self.previous = None;
        self.unhealed = None;
        self.subscriptions += 1;
    }

    /// Whether this checker has seen a frame.
    pub(super) fn seen_any(&self) -> bool {
        self.newest.is_some()
    }

    /// A frame of seq `seq` came at `t`; `decoded`: it decoded; `key`: it is a keyframe.
    /// Returns the ordering violation, if it is one.
    pub(super) fn frame(
        &mut self,
        t: f64,
        seq: u64,
        decoded: bool,
        key: bool,
    ) -> Option<OutOfOrder> {
        self.frames += 1;
        let mut violation = None;
        if let Some(previous) = self.previous
            && seq <= previous
        {
            let v = OutOfOrder { t, previous, seq };
            self.out_of_order.push(v.clone());
            violation = Some(v);
        }
        self.previous = Some(seq);
        if self.newest.is_none_or(|n| seq > n) {
            if t - self.last_new > self.stopped() {
                self.gaps.push(Gap {
                    from: self.last_new,
                    to: t,
                    open: false,
                });
            }
            self.last_new = t;
            self.newest = Some(seq);
        }
        if !decoded {
            self.decode_errors += 1;
            self.unhealed.get_or_insert(t);
        } else if key {
            self.unhealed = None;
        }
        if let Some(since) = self.unhealed
            && t - since > self.max_gap
        {
            self.unhealed_decodes += 1;
            self.unhealed = None;
        }
        violation
    }

    /// How long without a new frame is a gap now.
    fn stopped(&self) -> f64 {
        if self.newest.is_some() {
            STOPPED_S
        } else {
            self.max_gap
        }
    }

    /// The run ended at `t`: a gap still open is recorded (`open`), as is a decode failure
    /// still unhealed after `max_gap`.
    pub(super) fn finish(&mut self, t: f64) {
        if t - self.last_new > self.stopped() {
            self.gaps.push(Gap {
                from: self.last_new,
                to: t,
                open: true,
            });
            self.last_new = t;
        }
        if let Some(since) = self.unhealed.take()
            && t - since > self.max_gap
        {
            self.unhealed_decodes += 1;
        }
    }
}

/// A fault as the accounting sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Span {
    /// What it was.
    pub kind: FaultKind,
    /// The replica it struck (killed, paused), if one.
    pub replica: Option<usize>,
    /// When it began and ended (the replica answering again, SIGCONT, NATS listening, the
    /// publisher's new stream acked).
    pub start: f64,
    /// See `start`.
    pub end: f64,
}

/// The fault `gap` is attributed to: the last that began before the gap ended and ended (with
/// [`GRACE_S`]) after the gap began.
pub(super) fn attribute(gap: &Gap, faults: &[Span]) -> Option<usize> {
    faults
        .iter()
        .rposition(|f| f.start < gap.to && gap.from < f.end + GRACE_S)
}

/// How long `gap` lasted after every fault that began before its end had ended: a room that
/// sees no frame for longer than `--chaos-max-gap` after a fault ended (or with no fault at
/// all) fails the soak.
pub(super) fn uncovered(gap: &Gap, faults: &[Span]) -> f64 {
    let ended = faults
        .iter()
        .filter(|f| f.start < gap.to)
        .map(|f| f.end)
        .fold(gap.from, f64::max);
    (gap.to - ended).max(0.0)
}

/// Per fault kind, the recovery of every (fault, room) whose frames stopped on some checker
/// during the fault: the longest gap of the room attributed to the fault. `checkers` are
/// (room, replica, watch); the checkers on the replica a kill or pause struck are left out
/// (that replica was not there to serve them: its downtime is not the cluster's recovery).
pub(super) fn recoveries<'a>(
    checkers: impl IntoIterator<Item = (usize, usize, &'a Watch)>,
    faults: &[Span],
) -> BTreeMap<FaultKind, Vec<f64>> {
    // (fault, room) -> the longest attributed gap.
    let mut worst: HashMap<(usize, usize), f64> = HashMap::new();
    for (room, replica, watch) in checkers {
        for gap in &watch.gaps {
            let Some(f) = attribute(gap, faults) else {
                continue;
            };
            let fault = &faults[f];
            let struck = matches!(fault.kind, FaultKind::Kill | FaultKind::Pause)
                && fault.replica == Some(replica);
            if struck {
                continue;
            }
            let w = worst.entry((f, room)).or_insert(0.0);
            *w = w.max(gap.seconds());
        }
    }
    let mut by_kind: BTreeMap<FaultKind, Vec<f64>> = BTreeMap::new();
    let mut keys: Vec<_> = worst.into_iter().collect();
    keys.sort_by_key(|a| a.0);
    for ((f, _), seconds) in keys {
        by_kind.entry(faults[f].kind).or_default().push(seconds);
    }
    by_kind
}

/// A fault kind's recoveries, seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub(super) struct Recovery {
    /// (fault, room) pairs whose frames stopped.
    pub count: usize,
    /// Nearest-rank percentiles and the largest.
    pub p50: f64,
    /// See `p50`.
    pub p99: f64,
    /// See `p50`.
    pub max: f64,
}

impl Recovery {
    pub(super) fn of(mut seconds: Vec<f64>) -> Recovery {
        seconds.sort_by(f64::total_cmp);
        Recovery {
            count: seconds.len(),
            p50: crease_remote::percentile(&seconds, 50.0),
            p99: crease_remote::percentile(&seconds, 99.0),
            max: seconds.last().copied().unwrap_or(0.0),
        }
    }
}

/// A frame on NATS whose epoch is older than one the room's frames already carried (or an
/// epoch two owners claimed): two owners at once.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub(super) struct SplitBrain {
    /// When it was seen.
    pub t: f64,
    /// The room.
    pub room: String,
    /// The frame's owner and epoch.
    pub owner: String,
    /// See `owner`.
    pub epoch: u64,
    /// The newest epoch seen of the room before it, and its owner.
    pub newest: u64,
    /// See `newest`.
    pub newest_owner: String,
}

/// What the NATS observer saw: per room, the owner of every epoch and the lowest seq seen in
/// it.
///
/// A frame of an older epoch than one already seen is one of two things. Split brain: the old
/// owner predicted it from a control the new owner handles too (its seq is at or above the
/// first seq of some newer epoch). Or a *late* frame: published before the hand-over and held
/// in the paused owner's NATS client (its outgoing queue) until it resumed, below every newer
/// epoch's first seq; the relays drop it by its epoch (`crease_cluster_refused_stale_frames_total`)
/// and the checkers would see it out of order if one got through. Late frames are counted, not
/// violations.
#[derive(Debug, Default)]
pub(super) struct EpochCheck {
    rooms: HashMap<String, BTreeMap<u64, Epoch>>,
    /// Frames seen.
    pub frames: u64,
    /// Frames without a readable owner or epoch header.
    pub unlabelled: u64,
    /// Split-brain frames.
    pub split: Vec<SplitBrain>,
    /// Late frames (see the type's docs).
    pub late: u64,
    /// Ownership changes seen on NATS (a room's frames moving to a newer epoch).
    pub handovers: u64,
}

/// One ownership epoch of a room as the observer saw it.
#[derive(Debug)]
struct Epoch {
    owner: String,
    /// The lowest seq seen in it (`u64::MAX` while none was readable).
    first_seq: u64,
}

impl EpochCheck {
    /// Per room, the owner of its newest epoch seen.
    pub(super) fn owners(&self) -> impl Iterator<Item = (&str, &str)> {
        self.rooms.iter().filter_map(|(room, epochs)| {
            epochs
                .last_key_value()
                .map(|(_, e)| (room.as_str(), e.owner.as_str()))
        })
    }

    /// A frame of `room` from `owner` in `epoch` (`label` `None`: headers missing) with `seq`
    /// (`None`: the payload did not decode) seen at `t`; returns the violation, if it is one.
    pub(super) fn frame(
        &mut self,
        t: f64,
        room: &str,
        label: Option<(&str, u64)>,
        seq: Option<u64>,
    ) -> Option<SplitBrain> {
        self.frames += 1;
        let Some((owner, epoch)) = label else {
            self.unlabelled += 1;
            return None;
        };
        let seq_or_top = seq.unwrap_or(u64::MAX);
        let epochs = self.rooms.entry(room.to_owned()).or_default();
        let Some((&newest, newest_e)) = epochs.last_key_value() else {
            epochs.insert(
                epoch,
                Epoch {
                    owner: owner.to_owned(),
                    first_seq: seq_or_top,
                },
            );
            return None;
        };
        let newest_owner = newest_e.owner.clone();
        if let Some(e) = epochs.get_mut(&epoch) {
            if e.owner != owner {
                return Some(self.split_brain(t, room, owner, epoch, newest, newest_owner));
            }
            e.first_seq = e.first_seq.min(seq_or_top);
            if epoch == newest {
                return None;
            }
        }
        if epoch < newest {
            // Late if below the first seq of every newer epoch (an unreadable seq is not).
            let newer_first = epochs
                .range(epoch + 1..)
                .map(|(_, e)| e.first_seq)
                .min()
                .unwrap_or(u64::MAX);
            return match seq {
                Some(seq) if seq < newer_first => {
                    self.late += 1;
                    None
                }
                _ => Some(self.split_brain(t, room, owner, epoch, newest, newest_owner)),
            };
        }
        self.handovers += 1;
        epochs.insert(
            epoch,
            Epoch {
                owner: owner.to_owned(),
                first_seq: seq_or_top,
            },
        );
        None
    }

    fn split_brain(
        &mut self,
        t: f64,
        room: &str,
        owner: &str,
        epoch: u64,
        newest: u64,
        newest_owner: String,
    ) -> SplitBrain {
        let v = SplitBrain {
            t,
            room: room.to_owned(),
            owner: owner.to_owned(),
            epoch,
            newest,
            newest_owner,
        };
        self.split.push(v.clone());
        v
    }
}

/// Seconds to the next fault after one began at `now` (seconds since the start): random in
/// [20, 40) (`draw`, in [0, 1)), shortened so that `needed` more faults fit before
/// `last_start` (faults after the last are not needed), never below 5 s.
pub(super) fn next_gap(draw: f64, now: f64, last_start: f64, needed: usize) -> f64 {
    let gap = 20.0 + 20.0 * draw.clamp(0.0, 1.0);
    if needed == 0 {
        return gap;
    }
    let budget = (last_start - now) / needed as f64;
    gap.min(budget).max(5.0)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check

    use super::*;

    fn span(kind: FaultKind, replica: Option<usize>, start: f64, end: f64) -> Span {
        Span {
            kind,
            replica,
            start,
            end,
        }
    }

    /// Frames at 60 Hz from `from` to `to` (exclusive), seqs from `seq`.
    fn stream(w: &mut Watch, from: f64, to: f64, seq: &mut u64) {
        let mut t = from;
        while t < to {
            *seq += 1;
            w.frame(t, *seq, true, false);
            t += 1.0 / 60.0;
        }
    }

    #[test]
    fn a_steady_stream_has_no_gap_and_no_violation() {
        let mut w = Watch::new(0.0, 10.0);
        w.subscribed();
        let mut seq = 0;
        stream(&mut w, 0.1, 30.0, &mut seq);
        w.finish(30.0);
        assert!(w.gaps.is_empty(), "{:?}", w.gaps);
        assert!(w.out_of_order.is_empty());
        assert_eq!(w.frames, seq);
    }

    #[test]
    fn a_seq_at_or_below_the_previous_is_out_of_order_unless_resubscribed() {
        let mut w = Watch::new(0.0, 10.0);
        w.subscribed();
        assert!(w.frame(1.0, 10, true, true).is_none());
        assert!(w.frame(1.1, 12, true, false).is_none(), "skipping is fine");
        let v = w.frame(1.2, 12, true, false).unwrap();
        assert_eq!((v.previous, v.seq), (12, 12));
        assert!(w.frame(1.3, 11, true, false).is_some());
        assert_eq!(w.out_of_order.len(), 2);
        // A new subscription may start below what the old one ended on.
        w.subscribed();
        assert!(w.frame(1.4, 9, true, true).is_none());
        assert!(w.frame(1.5, 13, true, false).is_none());
        assert_eq!(w.out_of_order.len(), 2);
    }

    #[test]
    fn gaps_count_new_frames_only_and_an_open_gap_is_closed_at_the_end() {
        let mut w = Watch::new(0.0, 10.0);
        w.subscribed();
        w.frame(1.0, 5, true, true);
        // Resubscribed: the same frame again is not new, the gap goes on.
        w.subscribed();
        w.frame(3.0, 5, true, true);
        w.frame(4.0, 6, true, false);
        assert_eq!(
            w.gaps,
            vec![Gap {
                from: 1.0,
                to: 4.0,
                open: false
            }]
        );
        w.finish(20.0);
        assert_eq!(w.gaps.len(), 2);
        assert!(w.gaps[1].open);
        assert_eq!(w.gaps[1].seconds(), 16.0);
        // The wait for the first frame is a gap only when longer than the max gap.
        let mut first = Watch::new(0.0, 10.0);
        first.frame(2.0, 1, true, true);
        assert!(first.gaps.is_empty());
        let mut late = Watch::new(0.0, 10.0);
        late.frame(12.0, 1, true, true);
        assert_eq!(late.gaps[0].seconds(), 12.0);
        let mut never = Watch::new(0.0, 10.0);
        never.finish(30.0);
        assert!(never.gaps[0].open && !never.seen_any());
    }

    #[test]
    fn a_decode_failure_is_healed_by_a_keyframe_or_a_resubscription() {
        let mut w = Watch::new(0.0, 2.0);
        w.frame(1.0, 1, true, true);
        w.frame(1.1, 2, false, false);
        w.frame(1.2, 3, false, false);
        w.frame(1.5, 4, true, true);
        assert_eq!((w.decode_errors, w.unhealed_decodes), (2, 0));
        // Deltas that decode (wrongly) do not heal it: a keyframe must come.
        w.frame(2.0, 5, false, false);
        w.frame(3.0, 6, true, false);
        w.frame(4.5, 7, true, false);
        assert_eq!(w.unhealed_decodes, 1);
        w.frame(5.0, 8, false, false);
        w.subscribed();
        w.finish(20.0);
        assert_eq!(w.unhealed_decodes, 1, "the resubscription healed it");
        w.frame(21.0, 9, false, false);
        w.finish(30.0);
        assert_eq!(w.unhealed_decodes, 2, "still failing at the end");
    }

    #[test]
    fn gaps_are_attributed_to_the_fault_in_progress() {
        let faults = [
            span(FaultKind::Kill, Some(1), 20.0, 32.0),
            span(FaultKind::Nats, None, 55.0, 56.0),
        ];
        // Frames stopped just before the kill (the last frame came before it).
        let g = Gap {
            from: 19.99,
            to: 23.0,
            open: false,
        };
        assert_eq!(attribute(&g, &faults), Some(0));
        assert_eq!(uncovered(&g, &faults), 0.0);
        // After NATS came back, within the grace.
        let g = Gap {
            from: 57.0,
            to: 60.0,
            open: false,
        };
        assert_eq!(attribute(&g, &faults), Some(1));
        assert_eq!(uncovered(&g, &faults), 3.0);
        // Long after any fault: nobody's, and all of it uncovered.
        let g = Gap {
            from: 80.0,
            to: 95.0,
            open: false,
        };
        assert_eq!(attribute(&g, &faults), None);
        assert_eq!(uncovered(&g, &faults), 15.0);
        // A room that came back 12 s after the kill ended: 12 s uncovered.
        let g = Gap {
            from: 19.99,
            to: 44.0,
            open: false,
        };
        assert_eq!(uncovered(&g, &faults), 12.0);
    }

    #[test]
    fn recovery_per_kind_is_the_worst_checker_of_each_room_without_the_struck_replica() {
        let faults = [
            span(FaultKind::Kill, Some(0), 20.0, 30.0),
            span(FaultKind::Pause, Some(2), 50.0, 55.0),
        ];
        let gap = |from: f64, to: f64| {
            let mut w = Watch::new(0.0, 10.0);
            w.gaps.push(Gap {
                from,
                to,
                open: false,
            });
            w
        };
        let watches = [
            (0, 0, gap(20.0, 31.0)), // the killed replica's own checker: left out
            (0, 1, gap(20.0, 23.0)),
            (0, 2, gap(20.0, 24.5)),
            (1, 1, gap(20.0, 21.0)),
            (1, 0, gap(50.0, 53.0)),
            (1, 2, gap(50.0, 56.0)), // the paused replica's: left out
        ];
        let r = recoveries(watches.iter().map(|(a, b, w)| (*a, *b, w)), &faults);
        assert_eq!(r[&FaultKind::Kill], vec![4.5, 1.0]);
        assert_eq!(r[&FaultKind::Pause], vec![3.0]);
        let s = Recovery::of(r[&FaultKind::Kill].clone());
        assert_eq!((s.count, s.p50, s.p99, s.max), (2, 1.0, 4.5, 4.5));
        assert_eq!(Recovery::of(Vec::new()), Recovery::default());
    }

    #[test]
    fn percentiles_by_nearest_rank() {
        let s = Recovery::of((1..=100).rev().map(f64::from).collect());
        assert_eq!((s.p50, s.p99, s.max, s.count), (50.0, 99.0, 100.0, 100));
    }

    #[test]
    fn an_older_epoch_after_a_newer_ones_frame_is_split_brain_unless_it_is_late() {
        let mut e = EpochCheck::default();
        assert!(e.frame(1.0, "a", Some(("r0", 1)), Some(10)).is_none());
        assert!(e.frame(1.1, "b", Some(("r1", 1)), Some(10)).is_none());
        assert!(e.frame(1.2, "a", Some(("r0", 1)), Some(11)).is_none());
        // Adopted: a newer epoch from seq 200, then the paused owner's old one.
        assert!(e.frame(5.0, "a", Some(("r2", 2)), Some(200)).is_none());
        assert!(e.frame(5.1, "a", Some(("r2", 2)), Some(201)).is_none());
        // Seq 12 was published before the hand-over and held in r0's queue: late.
        assert!(e.frame(5.5, "a", Some(("r0", 1)), Some(12)).is_none());
        assert_eq!((e.late, e.split.len()), (1, 0));
        // Seq 202 is one the new owner handles too: split brain; so is a seq unread.
        let v = e.frame(6.0, "a", Some(("r0", 1)), Some(202)).unwrap();
        assert_eq!((v.epoch, v.newest, v.newest_owner.as_str()), (1, 2, "r2"));
        assert!(e.frame(6.0, "a", Some(("r0", 1)), None).is_some());
        // Seq 150 (below epoch 2's first) is late even though it is above epoch 1's.
        assert!(e.frame(6.05, "a", Some(("r0", 1)), Some(150)).is_none());
        // Room b is another room: its epoch 1 is fine.
        assert!(e.frame(6.1, "b", Some(("r1", 1)), Some(300)).is_none());
        // Two owners claiming one epoch, whatever the seq.
        assert!(e.frame(7.0, "a", Some(("r1", 2)), Some(5)).is_some());
        assert!(e.frame(8.0, "a", None, Some(400)).is_none());
        assert_eq!(
            (e.frames, e.unlabelled, e.split.len(), e.late),
            (12, 1, 3, 2)
        );
        assert_eq!(e.handovers, 1);
        // A third epoch whose first seq is lower than the second's (its frames came late):
        // the old epoch's frame is late only below both.
        assert!(e.frame(9.0, "a", Some(("r1", 3)), Some(190)).is_none());
        assert!(e.frame(9.1, "a", Some(("r0", 1)), Some(195)).is_some());
        assert!(e.frame(9.2, "a", Some(("r0", 1)), Some(189)).is_none());
        let mut owners: Vec<_> = e.owners().collect();
        owners.sort_unstable();
        assert_eq!(owners, vec![("a", "r1"), ("b", "r1")]);
    }

    #[test]
    fn faults_fit_the_run() {
        // 3 minutes, 6 faults, the last by 155 s: every gap is short enough.
        let mut now = 0.0;
        let mut starts = Vec::new();
        for k in 0..6 {
            now += next_gap(0.999, now, 155.0, 6 - k);
            starts.push(now);
        }
        assert!(*starts.last().unwrap() <= 155.0, "{starts:?}");
        assert!(starts.windows(2).all(|w| w[1] - w[0] >= 5.0));
        // A long run draws from [20, 40).
        assert_eq!(next_gap(0.0, 0.0, 10_000.0, 10), 20.0);
        assert_eq!(next_gap(0.5, 0.0, 10_000.0, 10), 30.0);
        assert_eq!(next_gap(0.5, 0.0, 100.0, 0), 30.0);
        // Never below 5 s, even when behind.
        assert_eq!(next_gap(0.5, 100.0, 101.0, 3), 5.0);
    }
}
