//! The chaos soak's faults, one at a time: every 20-40 s (random, shortened when needed so
//! that MINUTES x 2 of them fit the run) one of
//!
//! - `kill`: a random replica gets SIGKILL and is started again (same id, ports and
//!   arguments) 5-15 s later; the fault ends when it answers `/readyz`;
//! - `pause`: the owner of a random room gets SIGSTOP for 2.5 leases, then SIGCONT;
//! - `nats`: `nats-server` is killed and started again on the same port and store; the fault
//!   ends when it listens;
//! - `publisher`: a random room's publisher drops its stream and publishes through another
//!   replica; the fault ends when the new stream's first ack comes.
//!
//! A fault starts only once the previous one has ended (a killed replica is back), and none
//! starts in the run's last 25 s. Between faults the replicas are watched: one that exits on
//! its own is a violation, and it is started again.

use std::sync::atomic::Ordering;
use std::time::Duration;

use rand::Rng as _;
use rand::seq::IndexedRandom as _;
use tokio::time::Instant;

use super::accounting::next_gap;
use super::clients::owner_of;
use super::cluster::{Nats, Replica, signal};
use super::state::{Life, Shared};

/// No fault starts this close to the end (the last one's recovery is watched).
const TAIL_S: f64 = 25.0;
/// At least this long between one fault's end and the next one's start.
const QUIET_S: f64 = 5.0;

// The kinds of fault live with the accounting that sorts recoveries by them.
pub(super) use super::accounting::FaultKind;

/// A fault injected.
#[derive(Clone, Debug, serde::Serialize)]
pub(super) struct Fault {
    /// What it was.
    pub kind: FaultKind,
    /// What it struck, in words (`r1`, `r2 (owner of chaos-3)`, `nats`, ...).
    pub target: String,
    /// The replica it struck (kill, pause).
    #[serde(skip)]
    pub replica: Option<usize>,
    /// When it began and ended, seconds since the start.
    pub start_s: f64,
    /// See `start_s`.
    pub end_s: f64,
}

/// The cluster's processes, which only the fault injector touches once the soak runs.
#[derive(Debug)]
pub(super) struct Processes {
    /// `nats-server`.
    pub nats: Nats,
    /// The replicas, in the order of `Shared::replicas`.
    pub replicas: Vec<Replica>,
}

/// What the injector did and found.
#[derive(Debug, Default)]
pub(super) struct Injected {
    /// The faults, in order.
    pub faults: Vec<Fault>,
    /// Violations it found (a replica that exited on its own or did not come back).
    pub problems: Vec<String>,
}

/// Injects faults until `end_s` (seconds since the start), `required` of them if time allows.
pub(super) async fn inject(
    procs: &mut Processes,
    shared: &Shared,
    lease: Duration,
    end_s: f64,
    required: usize,
) -> Injected {
    let mut out = Injected::default();
    let last_start = end_s - TAIL_S;
    let mut next = next_gap(rand::rng().random(), 0.0, last_start, required);
    // Once a replica cannot be brought back, no more faults (the soak would test nothing).
    let mut broken = false;
    while shared.now() < end_s {
        watch_exits(procs, shared, &mut out.problems).await;
        if broken || shared.now() < next || next > last_start {
            tokio::time::sleep(Duration::from_millis(250)).await;
            continue;
        }
        let kind = *FaultKind::ALL
            .choose(&mut rand::rng())
            .unwrap_or(&FaultKind::Nats);
        let start_s = shared.now();
        let done = match kind {
            FaultKind::Kill => kill(procs, shared).await,
            FaultKind::Pause => pause(procs, shared, lease).await,
            FaultKind::Nats => nats(procs).await,
            FaultKind::Publisher => publisher(shared).await,
        };
        let (target, replica) = match done {
            Ok(Some(struck)) => struck,
            // Nothing struck (a room whose owner is not known just now): try again soon.
            Ok(None) => {
                next = shared.now() + 1.0;
                continue;
            }
            Err(e) => {
                let what = format!("{} fault at {start_s:.1} s: {e:#}", kind.name());
                eprintln!("chaos: {what}");
                out.problems.push(what);
                broken = true;
                continue;
            }
        };
        let fault = Fault {
            kind,
            target,
            replica,
            start_s,
            end_s: shared.now(),
        };
        eprintln!(
            "chaos {:7.1} s: fault {} {} {} ({:.1} s)",
            fault.end_s,
            out.faults.len() + 1,
            kind.name(),
            fault.target,
            fault.end_s - fault.start_s
        );
        let needed = required.saturating_sub(out.faults.len() + 1);
        next = (start_s + next_gap(rand::rng().random(), start_s, last_start, needed))
            .max(fault.end_s + QUIET_S);
        out.faults.push(fault);
    }
    out
}

/// Replicas that exited without a fault: a violation each; they are started again.
async fn watch_exits(procs: &mut Processes, shared: &Shared, problems: &mut Vec<String>) {
    for (k, replica) in procs.replicas.iter_mut().enumerate() {
        let Some(status) = replica.exited() else {
            continue;
        };
        let view = &shared.replicas[k];
        view.set_life(Life::Down);
        view.pid.store(0, Ordering::Relaxed);
        view.deaths.fetch_add(1, Ordering::Relaxed);
        view.crashes.fetch_add(1, Ordering::Relaxed);
        let what = format!(
            "replica {} exited on its own ({status}) at {:.1} s; its log ends:\n{}",
            replica.id,
            shared.now(),
            replica.log_tail()
        );
        eprintln!("chaos: {what}");
        problems.push(what);
        if let Err(e) = restart(replica, shared, k).await {
            problems.push(format!("{e:#}"));
        }
    }
}

/// Starts replica `k` again and waits until it is ready (three tries).
async fn restart(replica: &mut Replica, shared: &Shared, k: usize) -> anyhow::Result<()> {
    let mut last = None;
    for _ in 0..3 {
        let started = match replica.spawn() {
            Ok(()) => replica.ready().await,
            Err(e) => Err(e),
        };
        match started {
            Ok(()) => {
                let view = &shared.replicas[k];
                view.pid
                    .store(replica.pid().unwrap_or(0), Ordering::Relaxed);
                view.set_life(Life::Up);
                return Ok(());
            }
            Err(e) => {
                replica.kill9();
                last = Some(e);
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
    Err(last
        .unwrap_or_else(|| anyhow::anyhow!("no try"))
        .context(format!("replica {} did not come back", replica.id)))
}

/// The rooms whose publisher publishes through replica `k` now, in words (empty: none).
fn publishers_through(shared: &Shared, k: usize) -> String {
    let rooms: Vec<&str> = shared
        .publishers
        .iter()
        .zip(&shared.rooms)
        .filter(|(p, _)| p.replica.load(Ordering::Relaxed) == k)
        .map(|(_, r)| r.id.as_str())
        .collect();
    if rooms.is_empty() {
        String::new()
    } else {
        format!("; publishers of {} through it", rooms.join(" "))
    }
}

/// What a fault struck (in words, and the replica), `None` when it struck nothing.
type Struck = anyhow::Result<Option<(String, Option<usize>)>>;

async fn kill(procs: &mut Processes, shared: &Shared) -> Struck {
    let k = rand::rng().random_range(0..procs.replicas.len());
    let down = Duration::from_secs_f64(rand::rng().random_range(5.0..15.0));
    let view = &shared.replicas[k];
    let through = publishers_through(shared, k);
    view.set_life(Life::Down);
    view.pid.store(0, Ordering::Relaxed);
    view.deaths.fetch_add(1, Ordering::Relaxed);
    let replica = &mut procs.replicas[k];
    replica.kill9();
    tokio::time::sleep(down).await;
    restart(replica, shared, k).await?;
    Ok(Some((
        format!("{} (down {:.1} s{through})", replica.id, down.as_secs_f64()),
        Some(k),
    )))
}

async fn pause(procs: &mut Processes, shared: &Shared, lease: Duration) -> Struck {
    let r = rand::rng().random_range(0..shared.rooms.len());
    let room = &shared.rooms[r].id;
    let Some(k) = owner_of(shared, room).await else {
        eprintln!("chaos: pause: no replica says who owns room {room} now; another fault");
        return Ok(None);
    };
    let replica = &procs.replicas[k];
    let pid = replica
        .pid()
        .ok_or_else(|| anyhow::anyhow!("{} is not running", replica.id))?;
    let view = &shared.replicas[k];
    let through = publishers_through(shared, k);
    view.set_life(Life::Paused);
    signal(pid, "STOP")?;
    tokio::time::sleep(lease.mul_f64(2.5)).await;
    let resumed = signal(pid, "CONT");
    view.set_life(Life::Up);
    resumed?;
    Ok(Some((
        format!("{} (owner of {room}{through})", replica.id),
        Some(k),
    )))
}

async fn nats(procs: &mut Processes) -> Struck {
    procs.nats.restart().await?;
    Ok(Some(("nats-server".to_owned(), None)))
}

async fn publisher(shared: &Shared) -> Struck {
    let r = rand::rng().random_range(0..shared.rooms.len());
    let ctl = &shared.publishers[r];
    let before = ctl.sessions.load(Ordering::Relaxed);
    let from = ctl.replica.load(Ordering::Relaxed);
    ctl.drop_now.store(true, Ordering::Relaxed);
    let deadline = Instant::now() + Duration::from_secs(10);
    while ctl.sessions.load(Ordering::Relaxed) <= before && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let to = ctl.replica.load(Ordering::Relaxed);
    let name = |k: usize| shared.replicas.get(k).map_or("?", |v| v.id.as_str());
    let acked = if ctl.sessions.load(Ordering::Relaxed) > before {
        ""
    } else {
        ", no ack within 10 s"
    };
    Ok(Some((
        format!(
            "publisher of {} ({} -> {}{acked})",
            shared.rooms[r].id,
            name(from),
            name(to)
        ),
        None,
    )))
}
