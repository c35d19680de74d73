//! Takes under chaos: a take is started (`StartTake`) in a few rooms at the beginning, on each
//! room's owner, and stopped at the end on the room's current owner; then each take is read
//! back (`ListTakes`, `GetTake`) from the replica that recorded it and checked: its bytes
//! must parse as the take layout (`proto/crease/v1/take.proto`, `crease_proto::take::scan`)
//! to their last whole record, and a take whose replica was never killed must not be
//! truncated. A killed owner's take may be truncated; an adopter records nothing of it.

use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::{Context as _, bail};
use crease_proto::v1;
use futures_util::StreamExt as _;

use super::clients::owner_of;
use super::state::Shared;
use crease_remote::{authorized, connect};

/// Each take RPC may take this long.
const RPC: Duration = Duration::from_secs(10);

/// A take the soak started.
#[derive(Clone, Debug)]
pub(super) struct Started {
    /// The room, the take's id and the replica recording it.
    pub room: usize,
    /// See `room`.
    pub take: String,
    /// See `room`.
    pub replica: usize,
}

/// A take checked at the end.
#[derive(Clone, Debug, serde::Serialize)]
pub(super) struct TakeCheck {
    /// The room, the take and the replica that recorded it.
    pub room: String,
    /// See `room`.
    pub take: String,
    /// See `room`.
    pub replica: String,
    /// Whether `StopTake` on the room's owner at the end stopped it (not when the room was
    /// adopted meanwhile: the take stays on the replica that recorded it).
    pub stopped: bool,
    /// Whole frames read back, and bytes.
    pub frames: u64,
    /// See `frames`.
    pub bytes: u64,
    /// `TakeInfo.truncated` as `ListTakes` reports it.
    pub truncated: bool,
    /// Whether its replica was killed during the soak.
    pub replica_killed: bool,
    /// Why it is bad; `None` when it reads back whole.
    pub bad: Option<String>,
}

async fn client(
    shared: &Shared,
    k: usize,
) -> anyhow::Result<v1::crease_client::CreaseClient<tonic::transport::Channel>> {
    tokio::time::timeout(RPC, connect(&shared.replicas[k].url, None))
        .await
        .with_context(|| format!("connecting to {}: timed out", shared.replicas[k].id))?
}

/// Starts a take in each of `rooms` on its owner.
pub(super) async fn start(shared: &Shared, rooms: &[usize]) -> (Vec<Started>, Vec<String>) {
    let (mut started, mut problems) = (Vec::new(), Vec::new());
    for &r in rooms {
        let id = &shared.rooms[r].id;
        let mut last = String::new();
        for _ in 0..5 {
            let result = async {
                let owner = owner_of(shared, id)
                    .await
                    .with_context(|| format!("the owner of room {id}"))?;
                let request = v1::StartTakeRequest {
                    room: id.clone(),
                    name: "chaos".to_owned(),
                };
                let mut c = client(shared, owner).await?;
                let info = tokio::time::timeout(
                    RPC,
                    c.start_take(authorized(request, &shared.admin_token)?),
                )
                .await
                .context("StartTake: timed out")??
                .into_inner();
                anyhow::Ok(Started {
                    room: r,
                    take: info.take,
                    replica: owner,
                })
            };
            match result.await {
                Ok(s) => {
                    eprintln!(
                        "chaos: take {} started in room {id} on {}",
                        s.take, shared.replicas[s.replica].id
                    );
                    started.push(s);
                    last.clear();
                    break;
                }
                Err(e) => {
                    last = format!("{e:#}");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        }
        if !last.is_empty() {
            problems.push(format!("could not start a take in room {id}: {last}"));
        }
    }
    (started, problems)
}

/// Stops the takes (on each room's owner) and reads each back from its replica.
pub(super) async fn check(shared: &Shared, started: &[Started]) -> Vec<TakeCheck> {
    let mut checks = Vec::new();
    for s in started {
        let room = shared.rooms[s.room].id.clone();
        let stopped = stop(shared, &room, &s.take).await;
        let replica = &shared.replicas[s.replica];
        let mut check = TakeCheck {
            room,
            take: s.take.clone(),
            replica: replica.id.clone(),
            stopped,
            frames: 0,
            bytes: 0,
            truncated: false,
            replica_killed: replica.deaths.load(Ordering::Relaxed) > 0,
            bad: None,
        };
        if let Err(e) = read_back(shared, s, &mut check).await {
            check.bad = Some(format!("{e:#}"));
        }
        checks.push(check);
    }
    checks
}

/// `StopTake` on the room's current owner (a few tries); whether it stopped take `take`.
async fn stop(shared: &Shared, room: &str, take: &str) -> bool {
    for _ in 0..3 {
        let result = async {
            let owner = owner_of(shared, room).await.context("the room's owner")?;
            let mut c = client(shared, owner).await?;
            let request = v1::StopTakeRequest {
                room: room.to_owned(),
            };
            let info =
                tokio::time::timeout(RPC, c.stop_take(authorized(request, &shared.admin_token)?))
                    .await
                    .context("StopTake: timed out")??
                    .into_inner();
            anyhow::Ok(info.take)
        };
        match result.await {
            Ok(stopped) => return stopped == take,
            Err(e) => {
                // Not recording on the owner: the room was adopted, the take is elsewhere.
                if format!("{e:#}").contains("not recording") {
                    return false;
                }
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
        }
    }
    false
}

/// Lists take `s` on its replica and reads its bytes back, filling `check`.
async fn read_back(shared: &Shared, s: &Started, check: &mut TakeCheck) -> anyhow::Result<()> {
    let mut c = client(shared, s.replica).await?;
    let listed = tokio::time::timeout(
        RPC,
        c.list_takes(v1::ListTakesRequest {
            room: check.room.clone(),
        }),
    )
    .await
    .context("ListTakes: timed out")??
    .into_inner();
    let info = listed
        .takes
        .into_iter()
        .find(|t| t.take == s.take)
        .with_context(|| format!("take {} not listed on {}", s.take, check.replica))?;
    check.truncated = info.truncated;
    let bytes = tokio::time::timeout(RPC, async {
        let mut stream = c
            .get_take(v1::GetTakeRequest {
                take: s.take.clone(),
            })
            .await?
            .into_inner();
        let mut bytes = Vec::new();
        while let Some(chunk) = stream.next().await {
            bytes.extend_from_slice(&chunk?.data);
        }
        anyhow::Ok(bytes)
    })
    .await
    .context("GetTake: timed out")?
    .context("GetTake")?;
    check.bytes = bytes.len() as u64;
    let scan = crease_proto::take::scan(bytes.as_slice(), |_| Ok(()))
        .context("its bytes do not parse as a take")?;
    check.frames = scan.frames;
    if scan.truncated {
        bail!(
            "GetTake's bytes end in part of a record (after {} whole frames)",
            scan.frames
        );
    }
    if scan.header.take != s.take {
        bail!("its header names take {:?}", scan.header.take);
    }
    if info.truncated && !check.replica_killed {
        bail!(
            "truncated, though {} was never killed ({} frames)",
            check.replica,
            scan.frames
        );
    }
    if !info.recording && scan.frames < info.frames {
        bail!(
            "{} whole frames read back, ListTakes says {}",
            scan.frames,
            info.frames
        );
    }
    Ok(())
}
