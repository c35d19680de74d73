//! What the chaos soak's tasks share ([`Shared`]): the replicas as the clients see them
//! (address, up / down / paused, pid), the rooms, every checker's [`Watch`], the NATS
//! observer's [`EpochCheck`], the publishers' controls (the `publisher` fault) and the
//! counters.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use rand::Rng as _;
use tokio::time::Instant;

use super::accounting::{EpochCheck, Watch};
use super::memory::Point;

/// The replicas of the soak's cluster.
pub(super) const REPLICAS: usize = 3;

/// A replica's state as the clients see it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Life {
    /// Running and answering.
    Up = 0,
    /// Killed, not yet back.
    Down = 1,
    /// Stopped (SIGSTOP).
    Paused = 2,
}

/// A replica as the clients see it.
#[derive(Debug)]
pub(super) struct ReplicaView {
    /// Its id (`r0`, ...).
    pub id: String,
    /// Its gRPC URL and HTTP address (the same across restarts).
    pub url: String,
    /// See `url`.
    pub http: SocketAddr,
    life: AtomicU8,
    /// Its process id (0 while down).
    pub pid: AtomicU32,
    /// Times it died (killed by a fault or on its own).
    pub deaths: AtomicU32,
    /// Times it exited on its own.
    pub crashes: AtomicU32,
    /// The plain viewers streaming through it now (connecting included): its load besides
    /// the rooms it owns (`memory`).
    pub viewers: AtomicUsize,
}

impl ReplicaView {
    pub(super) fn new(id: String, url: String, http: SocketAddr, pid: u32) -> ReplicaView {
        ReplicaView {
            id,
            url,
            http,
            life: AtomicU8::new(Life::Up as u8),
            pid: AtomicU32::new(pid),
            deaths: AtomicU32::new(0),
            crashes: AtomicU32::new(0),
            viewers: AtomicUsize::new(0),
        }
    }

    pub(super) fn life(&self) -> Life {
        match self.life.load(Ordering::Acquire) {
            0 => Life::Up,
            1 => Life::Down,
            _ => Life::Paused,
        }
    }

    pub(super) fn set_life(&self, life: Life) {
        self.life.store(life as u8, Ordering::Release);
    }
}

/// A room of the soak.
#[derive(Clone, Debug)]
pub(super) struct Room {
    /// Its id (`chaos-K`).
    pub id: String,
    /// Its publish token.
    pub token: String,
}

/// A publisher's controls and figures.
#[derive(Debug, Default)]
pub(super) struct PublisherCtl {
    /// Set by the `publisher` fault: drop the stream, reconnect to another replica.
    pub drop_now: AtomicBool,
    /// Streams that got at least one ack.
    pub sessions: AtomicU64,
    /// The replica it publishes through now.
    pub replica: AtomicUsize,
    /// The next seq (kept across reconnections, so the room's seqs only increase).
    pub seq: AtomicU64,
}

/// What the soak counted; shared by its tasks.
#[derive(Debug, Default)]
pub(super) struct Counters {
    /// Control frames sent.
    pub sent: AtomicU64,
    /// Acks with an error other than "superseded", by reason (the message up to its ':').
    pub refused: Mutex<BTreeMap<String, u64>>,
    /// ABORTED acks (a newer frame won: latest wins).
    pub superseded: AtomicU64,
    /// Publisher streams ended (a failure, a stall, the `publisher` fault) and opened again.
    pub publisher_reconnects: AtomicU64,
    /// Publisher streams dropped because no ack came for a while.
    pub publisher_stalls: AtomicU64,
    /// Frames the plain viewers read.
    pub viewer_frames: AtomicU64,
    /// Viewer connections ended and made again.
    pub viewer_reconnects: AtomicU64,
    /// Checker subscriptions that failed (a replica down, a room not known yet).
    pub checker_refusals: AtomicU64,
}

/// Everything the soak's tasks share.
#[derive(Debug)]
pub(super) struct Shared {
    /// When the clients started: times are seconds since.
    pub started: Instant,
    /// Set at the end: every task returns within a second or so.
    pub stop: AtomicBool,
    /// The replicas.
    pub replicas: Vec<ReplicaView>,
    /// The rooms.
    pub rooms: Vec<Room>,
    /// The admin token (every replica's).
    pub admin_token: String,
    /// Per room and replica (`room * REPLICAS + replica`), its checker's record.
    pub checkers: Vec<Mutex<Watch>>,
    /// What the NATS observer saw.
    pub epochs: Mutex<EpochCheck>,
    /// Per room, its publisher's controls.
    pub publishers: Vec<PublisherCtl>,
    /// Per replica, its RSS samples with the rooms it owned at each (as NATS frames' owner
    /// headers say) and its life then.
    pub memory: Mutex<Vec<Vec<Point>>>,
    /// The counters.
    pub counters: Counters,
}

/// `m` locked, even if a task panicked holding it (the data is counters and records).
pub(super) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Shared {
    /// Seconds since the start.
    pub(super) fn now(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    pub(super) fn stopping(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// The checker of `room` on `replica`.
    pub(super) fn watch(&self, room: usize, replica: usize) -> MutexGuard<'_, Watch> {
        lock(&self.checkers[room * REPLICAS + replica])
    }

    /// A random replica that is up, other than `other` when another is up; `None` when none
    /// is.
    pub(super) fn pick_live(&self, other: Option<usize>) -> Option<usize> {
        let up: Vec<usize> = (0..self.replicas.len())
            .filter(|&k| self.replicas[k].life() == Life::Up)
            .collect();
        let preferred: Vec<usize> = up.iter().copied().filter(|&k| Some(k) != other).collect();
        let from = if preferred.is_empty() {
            &up
        } else {
            &preferred
        };
        if from.is_empty() {
            return None;
        }
        Some(from[rand::rng().random_range(0..from.len())])
    }

    /// The replica of id `id`.
    pub(super) fn replica_of(&self, id: &str) -> Option<usize> {
        self.replicas.iter().position(|r| r.id == id)
    }
}
