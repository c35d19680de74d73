//! From datagrams to control frames: the bridge's state (latest bone poses, root, trackers),
//! when a frame is complete, what each of the room's declared markers reads, and the UDP
//! receive loop that feeds a [`Sink`] (the publish loop's, or a test's channel).
//!
//! **Frames.** A bundle is one VMC frame (senders send one bundle per rendered frame): every
//! bundle that carries a bone of the bridged hand (the hand or a finger) yields one control
//! frame, built after the whole bundle (nested bundles included) is applied. Messages sent
//! loose, outside any bundle, accumulate until a loose `/VMC/Ext/OK`, which closes them into
//! a frame the same way. A marker is valid in a frame when it was received in it: a bone (tips:
//! their distal bone; the chain above the hand may be older) or a tracker (`/VMC/Ext/Tra/Pos`,
//! named by its serial). `capture_time_us` is the wall clock when the datagram arrived.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::bail;
use crease_proto::{encode_valid_mask, v1};
use crease_remote::publish::{SentLog, Sink, TrySendError};

use super::osc::{Datagram, Vmc, decode};
use super::skeleton::{Hand, Joints, Pose, Skeleton, TipLengths, is_humanoid_name};

/// Where a declared marker's position comes from.
#[derive(Clone, Debug, PartialEq)]
enum Source {
    /// A skeleton joint, by [`Skeleton::names`] index.
    Joint(usize),
    /// A tracker, by serial.
    Tracker(String),
}

/// One bridged hand: its actor (in a room of several), its skeleton, the latest local poses
/// and which of them came in the current frame, the markers its room (or actor) declares and
/// where each comes from, whether a bone of the hand came (in this bundle, or loose since the
/// last `/VMC/Ext/OK`), and its latest joints.
#[derive(Debug)]
struct HandPart {
    actor: Option<String>,
    hand: Hand,
    skeleton: Skeleton,
    locals: Vec<Option<Pose>>,
    fresh: Vec<bool>,
    declared: Vec<String>,
    sources: Vec<Source>,
    moved: bool,
    loose: bool,
    last: Joints,
}

impl HandPart {
    /// `hand` publishing `declared` (module docs of [`Bridge::new`] for the errors).
    fn new(
        room: &str,
        actor: Option<String>,
        hand: Hand,
        tips: TipLengths,
        declared: &[String],
    ) -> anyhow::Result<HandPart> {
        let skeleton = Skeleton::new(hand, tips);
        let mut sources = Vec::with_capacity(declared.len());
        let whose = actor
            .as_ref()
            .map_or(String::new(), |a| format!(" (actor {a:?})"));
        for name in declared {
            match skeleton.names().iter().position(|n| n == name) {
                Some(i) => sources.push(Source::Joint(i)),
                None if is_humanoid_name(name) => bail!(
                    "room {room:?}{whose} declares marker {name:?}, which a VMC stream of the {} hand does not carry{}; it carries {}, and trackers by serial",
                    hand.prefix().to_lowercase(),
                    if actor.is_none()
                        && name.starts_with(if hand == Hand::Right { "Left" } else { "Right" })
                    {
                        " (see --hand)"
                    } else {
                        ""
                    },
                    skeleton.names().join(", ")
                ),
                None => sources.push(Source::Tracker(name.clone())),
            }
        }
        let n = skeleton.names().len();
        Ok(HandPart {
            actor,
            hand,
            skeleton,
            locals: vec![None; n],
            fresh: vec![false; n],
            declared: declared.to_vec(),
            sources,
            moved: false,
            loose: false,
            last: Joints::default(),
        })
    }

    /// The hand's markers of this frame (solved from the latest poses) into `markers` and its
    /// validity mask (empty when every marker is valid).
    fn markers(
        &mut self,
        root: Option<Pose>,
        trackers: &BTreeMap<String, Pose>,
        fresh_trackers: &BTreeSet<String>,
    ) -> (Vec<f32>, Vec<u8>) {
        self.last = self.skeleton.solve(&self.locals, &self.fresh, root);
        let mut markers = Vec::with_capacity(3 * self.sources.len());
        let mut valid = Vec::with_capacity(self.sources.len());
        for s in &self.sources {
            let p = match s {
                Source::Joint(i) => self.last.valid[*i].then(|| self.last.positions[*i]),
                Source::Tracker(t) => fresh_trackers.contains(t).then(|| trackers[t].position),
            };
            match p.filter(|p| p.is_finite()) {
                Some(p) => {
                    markers.extend_from_slice(&p.to_array());
                    valid.push(true);
                }
                None => {
                    markers.extend_from_slice(&[0.0; 3]);
                    valid.push(false);
                }
            }
        }
        let mut mask = Vec::new();
        if valid.iter().any(|v| !v) {
            encode_valid_mask(&valid, &mut mask);
        }
        (markers, mask)
    }
}

/// The bridge's state between datagrams: one hand into a one-actor room, or a hand per actor
/// into a room of several (issue 38: both hands of one VMC skeleton), sharing the root, the
/// trackers and the sequence numbers.
#[derive(Debug)]
pub struct Bridge {
    room: String,
    parts: Vec<HandPart>,
    root: Option<Pose>,
    trackers: BTreeMap<String, Pose>,
    fresh_trackers: BTreeSet<String>,
    seq: u64,
    /// Every bone name received (for the no-hand warning).
    bones_seen: BTreeSet<String>,
}

/// What one datagram did.
#[derive(Debug, Default, PartialEq)]
pub struct Applied {
    /// The control frame it completed, if any.
    pub frame: Option<v1::ControlFrame>,
    /// Whether it was a bundle.
    pub bundle: bool,
}

impl Bridge {
    /// A bridge of `hand` publishing `declared` markers (the room's `Retarget.markers`, in
    /// order) into `room`.
    ///
    /// # Errors
    /// A declared name that is a humanoid bone or tip the stream does not carry (the other
    /// hand's, a leg's), naming it and listing what the stream carries. Other names are taken
    /// for tracker serials ([`Bridge::missing_trackers`]).
    pub fn new(
        room: &str,
        hand: Hand,
        tips: TipLengths,
        declared: &[String],
    ) -> anyhow::Result<Bridge> {
        Ok(Bridge::of(
            room,
            vec![HandPart::new(room, None, hand, tips, declared)?],
        ))
    }

    /// A bridge of both hands (issue 38) into a room of actors: per actor `(name, hand,
    /// declared markers)`, each actor's part of a frame its hand's markers. A frame holds the
    /// actors whose hand (or finger) bones came in it; the others hold their poses.
    ///
    /// # Errors
    /// No actor, two of the same hand, or [`Bridge::new`]'s errors, naming the actor.
    pub fn actors(
        room: &str,
        actors: &[(String, Hand, Vec<String>)],
        tips: TipLengths,
    ) -> anyhow::Result<Bridge> {
        if actors.is_empty() {
            bail!("room {room:?} has no actor with a side (left or right) for a VMC hand");
        }
        let mut parts = Vec::with_capacity(actors.len());
        for (name, hand, declared) in actors {
            if let Some(other) = parts.iter().find(|p: &&HandPart| p.hand == *hand) {
                bail!(
                    "room {room:?}: actors {:?} and {name:?} are both the {} hand of the VMC skeleton",
                    other.actor.as_deref().unwrap_or_default(),
                    hand.prefix().to_lowercase()
                );
            }
            parts.push(HandPart::new(
                room,
                Some(name.clone()),
                *hand,
                tips,
                declared,
            )?);
        }
        Ok(Bridge::of(room, parts))
    }

    fn of(room: &str, parts: Vec<HandPart>) -> Bridge {
        Bridge {
            room: room.to_owned(),
            parts,
            root: None,
            trackers: BTreeMap::new(),
            fresh_trackers: BTreeSet::new(),
            seq: 0,
            bones_seen: BTreeSet::new(),
        }
    }

    /// The (first) hand's marker names (joints and tips).
    pub fn joint_names(&self) -> &[String] {
        self.parts[0].skeleton.names()
    }

    /// The (first) hand's latest joints, in [`Bridge::joint_names`] order.
    pub fn joints(&self) -> &Joints {
        &self.parts[0].last
    }

    /// Declared markers taken for trackers whose serial has not been received.
    pub fn missing_trackers(&self) -> Vec<&str> {
        self.parts
            .iter()
            .flat_map(|p| &p.sources)
            .filter_map(|s| match s {
                Source::Tracker(t) if !self.trackers.contains_key(t) => Some(t.as_str()),
                _ => None,
            })
            .collect()
    }

    /// What the stream carries: the skeletons' names and the trackers received so far.
    pub fn carried(&self) -> String {
        let trackers: Vec<&str> = self.trackers.keys().map(String::as_str).collect();
        let names: Vec<&str> = self
            .parts
            .iter()
            .flat_map(|p| p.skeleton.names())
            .map(String::as_str)
            .collect();
        format!(
            "{}; trackers: {}",
            names.join(", "),
            if trackers.is_empty() {
                "none received".to_owned()
            } else {
                trackers.join(", ")
            }
        )
    }

    /// Every bone name received so far.
    pub fn bones_seen(&self) -> &BTreeSet<String> {
        &self.bones_seen
    }

    /// The bridged hand (the first, in a room of actors).
    pub fn hand(&self) -> Hand {
        self.parts[0].hand
    }

    /// The bridged hands: per hand its actor (`None` in a one-actor room) and side.
    pub fn hands(&self) -> Vec<(Option<&str>, Hand)> {
        self.parts
            .iter()
            .map(|p| (p.actor.as_deref(), p.hand))
            .collect()
    }

    /// Applies one decoded datagram received at `capture_time_us`; returns the frame it
    /// completes (module docs).
    pub fn apply(&mut self, d: &Datagram, capture_time_us: i64) -> Applied {
        if d.bundle {
            self.clear_fresh();
        }
        let mut ok = false;
        for m in &d.messages {
            match m {
                Vmc::Bone { name, pose } => {
                    if !self.bones_seen.contains(name) {
                        self.bones_seen.insert(name.clone());
                    }
                    for part in &mut self.parts {
                        if let Some(i) = part.skeleton.bone_index(name) {
                            part.locals[i] = Some(*pose);
                            part.fresh[i] = true;
                            part.moved |= part.skeleton.is_hand_bone(i);
                        }
                    }
                }
                Vmc::Root { pose } => self.root = Some(*pose),
                Vmc::Tracker { serial, pose } => {
                    self.trackers.insert(serial.clone(), *pose);
                    self.fresh_trackers.insert(serial.clone());
                }
                Vmc::Ok => ok = true,
                Vmc::Time(_) => {}
            }
        }
        // Which hands this datagram completes: in a bundle, those whose bones it carried;
        // loose messages accumulate until an OK.
        for part in &mut self.parts {
            if !d.bundle {
                part.loose |= std::mem::take(&mut part.moved);
                part.moved = ok && std::mem::take(&mut part.loose);
            }
        }
        let complete = self.parts.iter().any(|p| p.moved);
        let frame = complete.then(|| self.frame(capture_time_us));
        if frame.is_some() || (!d.bundle && ok) {
            self.clear_fresh();
        }
        Applied {
            frame,
            bundle: d.bundle,
        }
    }

    fn clear_fresh(&mut self) {
        for part in &mut self.parts {
            part.fresh.iter_mut().for_each(|f| *f = false);
            part.moved = false;
        }
        self.fresh_trackers.clear();
    }

    fn frame(&mut self, capture_time_us: i64) -> v1::ControlFrame {
        let seq = self.seq;
        self.seq += 1;
        let (root, trackers, fresh) = (self.root, &self.trackers, &self.fresh_trackers);
        let mut frame = v1::ControlFrame {
            room: self.room.clone(),
            seq,
            capture_time_us,
            ..Default::default()
        };
        for part in self.parts.iter_mut().filter(|p| p.moved) {
            let (markers, mask) = part.markers(root, trackers, fresh);
            match &part.actor {
                None => {
                    frame.markers = markers;
                    frame.markers_valid = mask;
                }
                Some(actor) => frame.actors.push(v1::ActorControls {
                    actor: actor.clone(),
                    markers,
                    markers_valid: mask,
                    ..Default::default()
                }),
            }
        }
        frame
    }

    /// The (first) hand's declared markers, in order.
    pub fn declared(&self) -> &[String] {
        &self.parts[0].declared
    }
}

/// Counters of a running bridge, shared by the receive loop, the publisher and the summary.
#[derive(Debug, Default)]
pub struct Stats {
    /// Datagrams received.
    pub datagrams: AtomicU64,
    /// Of them, bundles.
    pub bundles: AtomicU64,
    /// Malformed datagrams, dropped.
    pub dropped: AtomicU64,
    /// Control frames built.
    pub frames: AtomicU64,
    /// Frames handed to the publisher.
    pub published: AtomicU64,
    /// Frames dropped because the publisher was behind (a full channel).
    pub behind: AtomicU64,
    /// Acknowledged frames.
    pub acked: AtomicU64,
    /// Refused frames.
    pub refused: AtomicU64,
    /// The first malformed datagrams' reasons (a few, for the log).
    pub reasons: Mutex<Vec<String>>,
    /// Frames sent, by seq, with when their datagram arrived (for source-to-ack latency).
    pub sent_at: SentLog<Instant>,
    /// Source-to-ack latencies since the last summary, microseconds.
    pub latency_period: Mutex<Vec<u64>>,
    /// All source-to-ack latencies (the first million), microseconds.
    pub latency_all: Mutex<Vec<u64>>,
    /// Sum of squares and count of the acks' residuals in the capture's units
    /// (`PublishAck.control_residual_capture`, once the room's scale is known).
    pub residual: Mutex<(f64, u64)>,
}

/// Malformed datagrams whose reason is logged; the rest are counted.
const SHOWN_REASONS: usize = 5;
/// Sent frames remembered for latency (older ones are forgotten unacked).
const SENT_MEMORY: usize = 4096;
/// Latency samples kept for the final percentiles.
const LATENCY_MEMORY: usize = 1_000_000;

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Stats {
    fn count(c: &AtomicU64) -> u64 {
        c.load(Ordering::Relaxed)
    }

    /// Records an ack of `seq`: its source-to-ack latency, if the frame is remembered, and
    /// its residual in the capture's units (0: not known yet).
    pub fn ack(&self, seq: u64, refused: bool, residual_capture: f32) {
        if refused {
            self.refused.fetch_add(1, Ordering::Relaxed);
        } else {
            self.acked.fetch_add(1, Ordering::Relaxed);
            if residual_capture > 0.0 && residual_capture.is_finite() {
                let mut r = lock(&self.residual);
                r.0 += f64::from(residual_capture).powi(2);
                r.1 += 1;
            }
        }
        if let Some(at) = self.sent_at.take(seq) {
            let us = at.elapsed().as_micros() as u64;
            lock(&self.latency_period).push(us);
            let mut all = lock(&self.latency_all);
            if all.len() < LATENCY_MEMORY {
                all.push(us);
            }
        }
    }

    /// The one-line summary; `period` takes (and clears) the latencies since the last one,
    /// else the line covers the whole run (`vmc: done: ...`).
    pub fn summary(&self, period: bool) -> String {
        let mut l = if period {
            std::mem::take(&mut *lock(&self.latency_period))
        } else {
            lock(&self.latency_all).clone()
        };
        l.sort_unstable();
        let latency = if l.is_empty() {
            "no acks".to_owned()
        } else {
            format!(
                "p50 {:.1} ms p99 {:.1} ms",
                crease_remote::percentile(&l, 50.0) as f64 / 1e3,
                crease_remote::percentile(&l, 99.0) as f64 / 1e3
            )
        };
        let (sq, n) = *lock(&self.residual);
        let residual = if n == 0 {
            String::new()
        } else {
            format!(
                "; marker residual RMS {:.4} (capture units)",
                (sq / n as f64).sqrt()
            )
        };
        format!(
            "vmc: {}{} datagrams ({} bundles) in, {} frames built, {} published ({} acked, {} refused, {} dropped: publisher behind), {} malformed datagrams dropped; source-to-ack latency {latency}{residual}",
            if period { "" } else { "done: " },
            Self::count(&self.datagrams),
            Self::count(&self.bundles),
            Self::count(&self.frames),
            Self::count(&self.published),
            Self::count(&self.acked),
            Self::count(&self.refused),
            Self::count(&self.behind),
            Self::count(&self.dropped),
        )
    }
}

/// How the receive loop runs.
#[derive(Clone, Debug)]
pub struct LoopOptions {
    /// Warn when no bone of the hand arrived for this long; declared trackers not received
    /// by then are an error.
    pub warn_after: Duration,
    /// Return once the stream has been silent this long after its first datagram.
    pub idle_exit: Option<Duration>,
    /// Print [`Stats::summary`] this often.
    pub summary_every: Option<Duration>,
    /// Where the loop listens (for messages).
    pub listen: String,
}

/// Receives datagrams on `socket`, decodes them, and sends each completed frame to `out`
/// (without waiting: a full channel drops the frame, counted in [`Stats::behind`]). Returns
/// when `out` is closed, or after [`LoopOptions::idle_exit`] of silence.
///
/// # Errors
/// The socket failing, or declared trackers that never arrived ([`LoopOptions::warn_after`]
/// after the first datagram), naming them and listing what the stream carries.
pub async fn receive_loop(
    socket: tokio::net::UdpSocket,
    mut bridge: Bridge,
    out: impl Into<Sink>,
    stats: &Stats,
    opts: &LoopOptions,
) -> anyhow::Result<Bridge> {
    let out: Sink = out.into();
    let mut buf = vec![0u8; 65536];
    let start = Instant::now();
    let mut first: Option<Instant> = None;
    let mut last_datagram = start;
    let mut last_hand = start;
    let mut warned = false;
    let mut trackers_checked = false;
    let mut next_summary = opts.summary_every.map(|d| start + d);
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tokio::select! {
            r = socket.recv(&mut buf) => {
                let n = r.map_err(|e| anyhow::anyhow!("receiving on {}: {e}", opts.listen))?;
                let now = Instant::now();
                let capture = crease_remote::unix_us();
                first.get_or_insert(now);
                last_datagram = now;
                stats.datagrams.fetch_add(1, Ordering::Relaxed);
                let d = match decode(&buf[..n]) {
                    Ok(d) => d,
                    Err(why) => {
                        let k = stats.dropped.fetch_add(1, Ordering::Relaxed);
                        if (k as usize) < SHOWN_REASONS {
                            eprintln!("vmc: dropped a malformed datagram ({n} bytes): {why}");
                            lock(&stats.reasons).push(why);
                        } else if k as usize == SHOWN_REASONS {
                            eprintln!("vmc: further malformed datagrams are counted in the summary");
                        }
                        continue;
                    }
                };
                let applied = bridge.apply(&d, capture);
                if applied.bundle {
                    stats.bundles.fetch_add(1, Ordering::Relaxed);
                }
                let Some(frame) = applied.frame else { continue };
                last_hand = now;
                warned = false;
                stats.frames.fetch_add(1, Ordering::Relaxed);
                let seq = frame.seq;
                stats.sent_at.record(seq, now, Some(SENT_MEMORY));
                match out.try_send(frame) {
                    Ok(()) => {
                        stats.published.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(TrySendError::Full) => {
                        stats.behind.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(TrySendError::Ended) => return Ok(bridge),
                }
            }
            _ = tick.tick() => {
                let now = Instant::now();
                if out.is_ended() {
                    return Ok(bridge);
                }
                if let (Some(idle), Some(_)) = (opts.idle_exit, first)
                    && now - last_datagram >= idle
                {
                    return Ok(bridge);
                }
                if !warned && now - last_hand >= opts.warn_after {
                    warned = true;
                    eprintln!("{}", no_hand_warning(&bridge, stats, opts, now - last_hand));
                }
                if let Some(f) = first
                    && !trackers_checked
                    && now - f >= opts.warn_after
                {
                    trackers_checked = true;
                    let missing = bridge.missing_trackers();
                    if !missing.is_empty() {
                        bail!(
                            "the room declares marker{} {} that the VMC stream did not carry in {:.0} s (names that are not Unity bones are taken for tracker serials); it carries {}",
                            if missing.len() > 1 { "s" } else { "" },
                            missing.iter().map(|m| format!("{m:?}")).collect::<Vec<_>>().join(", "),
                            opts.warn_after.as_secs_f64(),
                            bridge.carried()
                        );
                    }
                }
                if let (Some(at), Some(every)) = (next_summary, opts.summary_every)
                    && now >= at
                {
                    eprintln!("{}", stats.summary(true));
                    next_summary = Some(at + every);
                }
            }
        }
    }
}

fn no_hand_warning(bridge: &Bridge, stats: &Stats, opts: &LoopOptions, silent: Duration) -> String {
    let side = bridge.hand().prefix();
    let datagrams = stats.datagrams.load(Ordering::Relaxed);
    if datagrams == 0 {
        return format!(
            "vmc: WARNING: no datagram received on {} in {:.0} s: is the VMC sender (VSeeFace, VirtualMotionCapture, Warudo, ...) sending to this machine and port?",
            opts.listen,
            silent.as_secs_f64()
        );
    }
    let seen = bridge.bones_seen();
    let other = if side == "Right" { "Left" } else { "Right" };
    let hint = if seen.iter().any(|b| b.starts_with(&format!("{other}Hand"))) {
        format!(
            " ({other}Hand arrives: try --hand {})",
            other.to_lowercase()
        )
    } else if seen.is_empty() {
        " (no /VMC/Ext/Bone/Pos at all: is the sender's bone output on?)".to_owned()
    } else {
        " (is the sender tracking hands?)".to_owned()
    };
    let shown: Vec<&str> = seen.iter().take(12).map(String::as_str).collect();
    format!(
        "vmc: WARNING: no {side}Hand or {side} finger bone in the last {:.0} s of the VMC stream{hint}: {datagrams} datagrams so far, {} malformed; bones seen: {}{}",
        silent.as_secs_f64(),
        stats.dropped.load(Ordering::Relaxed),
        if shown.is_empty() {
            "none".to_owned()
        } else {
            shown.join(", ")
        },
        if seen.len() > shown.len() {
            ", ..."
        } else {
            ""
        }
    )
}
