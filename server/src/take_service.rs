//! The take operations both transports call (gRPC `StartTake` / `StopTake` / `ListTakes` /
//! `GetTake`, HTTP `/api/takes...`): each looks the room or take up, does its file work on the
//! blocking pool, and fails with one [`TakeOpError`] (its gRPC and HTTP status are
//! `crate::status`'s). A replay room opens as every room does, through
//! `AppState::open_room`, from the take's header (`RoomSpec::from_take`).

use std::sync::Arc;
use std::time::Duration;

use crease_core::model::gltf_export;
use crease_proto::json::{ReplayRoom, TakeFrames};
use crease_proto::{take, v1};

use crease_proto::room::RoomSpec;

use crate::ingest::PublishError;
use crate::room::Room;
use crate::state::AppState;
use crate::takes::TakeError;

/// Most private replay rooms open at once (each also counts against `Limits::rooms`).
pub const MAX_REPLAY_ROOMS: usize = 8;

/// A replay room nobody watched for this long is closed.
pub const REPLAY_IDLE: Duration = Duration::from_secs(30);

/// Why a take operation failed.
#[derive(Debug, thiserror::Error)]
pub enum TakeOpError {
    /// The take's or the folder's.
    #[error(transparent)]
    Take(#[from] TakeError),
    /// The room's lookup.
    #[error(transparent)]
    Room(#[from] PublishError),
    /// The take's model is not here, or not the one it was recorded on.
    #[error("{0}")]
    Model(String),
    /// The replay room could not be opened.
    #[error("replay room: {0}")]
    Open(String),
    /// Too many replay rooms.
    #[error("replay rooms: {0} open, the limit; try again when one closes")]
    Replays(usize),
    /// The blocking task panicked (a server bug).
    #[error("take: {0}")]
    Panicked(String),
}

/// Runs `f` on the blocking pool.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, TakeOpError> + Send + 'static,
) -> Result<T, TakeOpError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| TakeOpError::Panicked(e.to_string()))?
}

/// The room `id`, predicted here (in a cluster, a room another replica owns records there).
async fn local_room(state: &Arc<AppState>, id: &str) -> Result<Arc<Room>, TakeOpError> {
    let room = state.find_room(id).await.map_err(PublishError::from)?;
    if room.relays() {
        let owner = state
            .cluster()
            .and_then(|c| c.owner_of(id))
            .unwrap_or_default();
        return Err(TakeError::Elsewhere {
            room: id.to_owned(),
            owner,
        }
        .into());
    }
    Ok(room)
}

/// Starts recording room `id` (labelled `name`).
///
/// # Errors
/// [`TakeOpError`]: no such room, no takes folder, a take running, the file.
pub async fn start(
    state: &Arc<AppState>,
    id: &str,
    name: String,
) -> Result<v1::TakeInfo, TakeOpError> {
    let room = local_room(state, id).await?;
    if let Some(take) = room.take_id() {
        return Err(TakeError::Recording {
            room: room.id.clone(),
            take,
        }
        .into());
    }
    let state = Arc::clone(state);
    blocking(move || {
        let takes = state.takes()?;
        // The first actor's model (a one-actor room's), and in a room of several every
        // actor's (`TakeHeader.actors`).
        let m = &room.actors()[0];
        let recorder = takes.start(
            room.settings(),
            &name,
            m.source().sha256(),
            m.model.model.rig.bone_count,
            m.model.model.controls.len(),
            room.take_actors(),
        )?;
        let info = recorder.info();
        match room.start_take(recorder) {
            Ok(()) => {
                tracing::info!(room = %room.id, take = %info.take, "take started");
                Ok(info)
            }
            // Another StartTake won the race: this one's file goes.
            Err(recorder) => {
                (*recorder).discard();
                Err(TakeError::Recording {
                    room: room.id.clone(),
                    take: room.take_id().unwrap_or_default(),
                }
                .into())
            }
        }
    })
    .await
}

/// Stops room `id`'s take and returns it.
///
/// # Errors
/// [`TakeOpError`]: no such room, nothing recording, the file.
pub async fn stop(state: &Arc<AppState>, id: &str) -> Result<v1::TakeInfo, TakeOpError> {
    let room = local_room(state, id).await?;
    let recorder = room
        .stop_take()
        .ok_or_else(|| TakeError::NotRecording(id.to_owned()))?;
    let info = blocking(move || Ok(recorder.finish()?)).await?;
    tracing::info!(room = %id, take = %info.take, frames = info.frames, "take stopped");
    Ok(info)
}

/// The takes of room `room` (every take when empty), newest first.
///
/// # Errors
/// [`TakeError::NoFolder`].
pub async fn list(state: &Arc<AppState>, room: String) -> Result<Vec<v1::TakeInfo>, TakeOpError> {
    let state = Arc::clone(state);
    blocking(move || {
        let recording = state.recording_takes();
        let room = (!room.is_empty()).then_some(room.as_str());
        Ok(state.takes()?.list(room, &recording))
    })
    .await
}

/// Take `id`'s file up to its last whole record.
///
/// # Errors
/// [`TakeError::NoTake`], the file's.
pub async fn bytes(state: &Arc<AppState>, id: String) -> Result<Vec<u8>, TakeOpError> {
    let state = Arc::clone(state);
    blocking(move || Ok(state.takes()?.bytes(&id)?)).await
}

/// Take `id`'s frames as the viewer's player wants them.
///
/// # Errors
/// [`TakeError::NoTake`], the file's.
pub async fn frames(state: &Arc<AppState>, id: String) -> Result<TakeFrames, TakeOpError> {
    let state = Arc::clone(state);
    blocking(move || Ok(TakeFrames::new(&state.takes()?.read(&id)?))).await
}

/// Take `id` read whole, with its model (loaded here, and the one it was recorded on).
fn take_and_model(
    state: &AppState,
    id: &str,
) -> Result<(take::Take, Arc<crate::registry::LoadedModel>), TakeOpError> {
    let take = state.takes()?.read(id)?;
    let header = take.header();
    if let Some(room) = header.room.as_ref().filter(|r| !r.actors.is_empty()) {
        // A room of several actors: every actor's model here and as recorded (a mirrored
        // actor's is its model file mirrored); the take's first actor's model is returned.
        let mut first = None;
        for (a, recorded) in room.actors.iter().zip(&header.actors) {
            let model = state.models().get(&a.model).ok_or_else(|| {
                TakeOpError::Model(format!(
                    "take {id:?}: actor {:?} was recorded on model {:?}, which this server has not loaded",
                    a.name, a.model
                ))
            })?;
            if model.sha256() != recorded.model_sha256 {
                return Err(TakeOpError::Model(format!(
                    "take {id:?}: actor {:?}'s model {:?} is not the one recorded (SHA-256 {} here, {} in the take)",
                    a.name,
                    a.model,
                    model.sha256(),
                    recorded.model_sha256
                )));
            }
            first.get_or_insert(model);
        }
        let model =
            first.ok_or_else(|| TakeOpError::Model(format!("take {id:?}: no actor recorded")))?;
        return Ok((take, model));
    }
    let name = take
        .header()
        .room
        .as_ref()
        .map(|r| r.model.clone())
        .unwrap_or_default();
    let model = state.models().get(&name).ok_or_else(|| {
        TakeOpError::Model(format!(
            "take {id:?} was recorded on model {name:?}, which this server has not loaded"
        ))
    })?;
    take::check_model(&take, &model.model, model.sha256())
        .map_err(|e| TakeOpError::Model(format!("take {id:?}: {e}")))?;
    Ok((take, model))
}

/// Take `id` as a batch job's source (issue 45, `JobSpec.take`): its model (here, and the one
/// it was recorded on), its room's options as recorded (beta, refinement, skinning; no
/// filter: the recorded control points are already filtered or retargeted) and one control
/// frame per recorded frame, every point as the prediction used it (occluded points held), so
/// the job's meshes are the take's.
///
/// # Errors
/// [`TakeError::NoTake`] (named), the model missing or changed, a take of several actors (not
/// a job's source yet), the file's.
pub async fn job_source(
    state: &Arc<AppState>,
    id: String,
) -> Result<
    (
        Arc<crate::registry::LoadedModel>,
        crease_proto::room::RoomOptions,
        Vec<v1::ControlFrame>,
    ),
    TakeOpError,
> {
    let state = Arc::clone(state);
    blocking(move || {
        let (take, model) = take_and_model(&state, &id)?;
        if !take.header().actors.is_empty() {
            return Err(TakeOpError::Model(format!(
                "take {id:?} is of a room of several actors: a job runs one model; replay it into a room instead (crease take replay)"
            )));
        }
        let spec = RoomSpec::from_take(&id, take.header())
            .map_err(|e| TakeOpError::Open(format!("take {id:?}'s room settings: {e}")))?;
        let options = crease_proto::room::RoomOptions {
            filter: None,
            ..spec.options
        };
        let frames = take
            .frames
            .into_iter()
            .enumerate()
            .map(|(i, f)| {
                crease_proto::control::control_frame_flat("", i as u64, f.received_us, f.controls)
            })
            .collect();
        Ok((model, options, frames))
    })
    .await
}

/// Take `id` as a skinned glTF animation ([`gltf_export::skinned_recording_to_glb`]) with the
/// server's copy of its model.
///
/// # Errors
/// [`TakeError::NoTake`], the model missing or changed, the export's.
pub async fn glb(state: &Arc<AppState>, id: String) -> Result<Vec<u8>, TakeOpError> {
    let state = Arc::clone(state);
    blocking(move || {
        let (take, model) = take_and_model(&state, &id)?;
        let export = |e: &dyn std::fmt::Display| TakeOpError::Model(format!("take {id:?}: {e}"));
        if !take.header().actors.is_empty() {
            return actors_glb(&state, &take).map_err(|e| export(&e));
        }
        let transforms = take::all_transforms(&take).map_err(|e| export(&e))?;
        gltf_export::skinned_recording_to_glb(
            &model.model.rig,
            take::take_skinning(&take, &model.model),
            "take",
            &take::keyframe_times(&take),
            &transforms,
        )
        .map_err(|e| export(&format!("export: {e}")))
    })
    .await
}

/// A take of a room of several actors as one glTF (issue 38): a skinned mesh per actor
/// (`gltf_export::skinned_parts_recording_to_glb`) on the server's copy of its model,
/// mirrored where the actor was (`ModelRegistry::mirrored`, as the room ran it). Blocking.
///
/// # Errors
/// What is wrong, as text: an actor's model (absent, or not mirrorable), its frames, the
/// export's.
fn actors_glb(state: &AppState, take: &take::Take) -> Result<Vec<u8>, String> {
    let recordings = take::actor_recordings(take).map_err(|e| e.to_string())?;
    let mut models = Vec::with_capacity(recordings.len());
    for r in &recordings {
        let model = match &r.mirror {
            None => state.models().get(&r.model),
            Some(plane) => state
                .models()
                .mirrored(&r.model, plane)
                .transpose()
                .map_err(|e| format!("actor {:?}: mirror: {e}", r.name))?,
        };
        models.push(model.ok_or_else(|| format!("actor {:?}: no model {:?}", r.name, r.model))?);
    }
    let parts: Vec<_> = recordings
        .iter()
        .zip(&models)
        .map(|(r, m)| gltf_export::SkinnedPart::of(&r.name, &m.model, r.skinning, &r.transforms))
        .collect();
    gltf_export::skinned_parts_recording_to_glb(&parts, "take", &take::keyframe_times(take))
        .map_err(|e| format!("export: {e}"))
}

/// Opens a private room (`replay-<random>`) with take `id`'s settings for a viewer to play the
/// take back in; closed once nobody watched it for [`REPLAY_IDLE`].
///
/// # Errors
/// [`TakeError::NoTake`], the model missing or changed, [`TakeOpError::Replays`], the room's.
pub async fn open_replay(state: &Arc<AppState>, id: String) -> Result<ReplayRoom, TakeOpError> {
    let replays = state.private_rooms();
    if replays >= MAX_REPLAY_ROOMS {
        return Err(TakeOpError::Replays(replays));
    }
    let (take, _) = {
        let state = Arc::clone(state);
        let id = id.clone();
        blocking(move || take_and_model(&state, &id)).await?
    };
    let room_id = format!("replay-{}", &crate::session::new_token()[..12]);
    let spec = RoomSpec::from_take(&room_id, take.header())
        .map_err(|e| TakeOpError::Open(e.to_string()))?;
    let room = state
        .open_room(spec)
        .await
        .map_err(|e| TakeOpError::Open(e.to_string()))?;
    tracing::info!(room = %room.id, take = %id, "replay room opened");
    close_when_idle(Arc::downgrade(state), room.id.clone());
    Ok(ReplayRoom {
        room: room.id.clone(),
        publish_token: room.token().unwrap_or_default().to_owned(),
        take: id,
    })
}

/// Closes private room `id` once it had no subscriber for [`REPLAY_IDLE`].
fn close_when_idle(state: std::sync::Weak<AppState>, id: String) {
    const TICK: Duration = Duration::from_secs(1);
    tokio::spawn(async move {
        let mut idle = Duration::ZERO;
        loop {
            tokio::time::sleep(TICK).await;
            let Some(state) = state.upgrade() else { return };
            let Some(room) = state.room(&id) else { return };
            idle = if room.subscriber_count() == 0 {
                idle + TICK
            } else {
                Duration::ZERO
            };
            if idle >= REPLAY_IDLE || state.is_closing() {
                let _ = state.close_room(&id).await;
                tracing::info!(room = %id, "replay room closed: nobody watched it");
                return;
            }
        }
    });
}
