//! Reaching a server: the one gRPC [`connect`] (plain or TLS), a room's description, bearer
//! tokens on requests, and the wire's capture clock.

use std::path::Path;

use anyhow::{Context, bail};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use tonic::transport::Channel;

/// Largest response message the network commands accept (a 16-bit keyframe of a 151K-vertex
/// detail mesh is ~1.2 MB; batches stream one frame per message).
pub const MAX_RESPONSE_BYTES: usize = 256 << 20;

/// How long to wait for a connection before calling the server unreachable.
const CONNECT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// A gRPC client of the crease server at `server` (`http://` or `https://`). Over https the
/// server's certificate is checked against `ca` (a PEM file, for self-signed or private CAs)
/// or else the Mozilla roots (webpki-roots).
///
/// # Errors
/// A URL that does not parse, an unreadable `ca`, or a server that cannot be reached, each
/// naming what it was.
pub async fn connect(server: &str, ca: Option<&Path>) -> anyhow::Result<CreaseClient<Channel>> {
    use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};
    let mut endpoint = Endpoint::from_shared(server.to_owned())
        .with_context(|| {
            format!("--server {server:?} is not a URL (expected e.g. http://127.0.0.1:50051)")
        })?
        .connect_timeout(CONNECT_TIMEOUT);
    if server.starts_with("https://") {
        let tls = match ca {
            Some(path) => {
                let pem = std::fs::read(path)
                    .with_context(|| format!("reading --ca {}", path.display()))?;
                ClientTlsConfig::new().ca_certificate(Certificate::from_pem(pem))
            }
            None => ClientTlsConfig::new().with_webpki_roots(),
        };
        endpoint = endpoint
            .tls_config(tls)
            .with_context(|| format!("TLS settings for {server}"))?;
    } else if ca.is_some() {
        bail!("--ca applies to https:// servers, got {server}");
    }
    let channel = endpoint
        .connect()
        .await
        .with_context(|| format!("cannot reach the crease server at {server}"))?;
    Ok(CreaseClient::new(channel).max_decoding_message_size(MAX_RESPONSE_BYTES))
}

/// The models the server hosts (`ListModels`).
///
/// # Errors
/// The server's refusal or an unreachable server.
pub async fn list_models(client: &mut CreaseClient<Channel>) -> anyhow::Result<Vec<v1::ModelInfo>> {
    client
        .list_models(v1::ListModelsRequest {})
        .await
        .map(|r| r.into_inner().models)
        .map_err(|s| anyhow::anyhow!("listing the models: {}", s.message()))
}

/// Bytes per `ModelChunk` of an upload (the server takes messages up to 4 MiB).
pub const MODEL_CHUNK_BYTES: usize = 1 << 20;

/// Uploads a model file's `bytes` as model `name` (`UploadModel`, issue 39; admin `token`):
/// the first chunk names it and declares its size and SHA-256 (`sha256`, hex; the file's
/// own unless a caller tests the server's check), then the bytes in chunks of
/// [`MODEL_CHUNK_BYTES`]. Returns the model as the server loaded it.
///
/// # Errors
/// The server's refusal (its message names what was wrong), or an unreachable server.
pub async fn upload_model(
    client: &mut CreaseClient<Channel>,
    token: &str,
    name: &str,
    bytes: Vec<u8>,
    sha256: &str,
) -> anyhow::Result<v1::ModelInfo> {
    let size = bytes.len() as u64;
    let mut chunks: Vec<v1::ModelChunk> = bytes
        .chunks(MODEL_CHUNK_BYTES)
        .map(|c| v1::ModelChunk {
            data: c.to_vec(),
            ..Default::default()
        })
        .collect();
    if chunks.is_empty() {
        chunks.push(v1::ModelChunk::default());
    }
    chunks[0].name = name.to_owned();
    chunks[0].size = size;
    chunks[0].sha256 = sha256.to_owned();
    client
        .upload_model(authorized(tokio_stream::iter(chunks), token)?)
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("uploading model {name:?}: {}", s.message()))
}

/// Deletes model `name` from the server (`DeleteModel`, admin `token`).
///
/// # Errors
/// The server's refusal (in use by a room, no such model), or an unreachable server.
pub async fn delete_model(
    client: &mut CreaseClient<Channel>,
    token: &str,
    name: &str,
) -> anyhow::Result<()> {
    client
        .delete_model(authorized(
            v1::DeleteModelRequest {
                model: name.to_owned(),
            },
            token,
        )?)
        .await
        .map(|_| ())
        .map_err(|s| anyhow::anyhow!("deleting model {name:?}: {}", s.message()))
}

/// The server's models and, in a cluster, the cluster's stored ones (`ListModels`).
///
/// # Errors
/// The server's refusal or an unreachable server.
pub async fn list_all_models(
    client: &mut CreaseClient<Channel>,
) -> anyhow::Result<v1::ListModelsResponse> {
    client
        .list_models(v1::ListModelsRequest {})
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("listing the models: {}", s.message()))
}

/// The server's description of `room` (its model, settings and counters).
///
/// # Errors
/// The server's refusal (no such room), naming the room.
pub async fn get_room(
    client: &mut CreaseClient<Channel>,
    room: &str,
) -> anyhow::Result<v1::RoomInfo> {
    client
        .get_room(v1::GetRoomRequest {
            room: room.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("room {room:?}: {}", s.message()))
}

/// `msg` with `authorization: Bearer <token>` metadata (admin and publish tokens).
///
/// # Errors
/// A token that is not a valid header value.
pub fn authorized<T>(msg: T, token: &str) -> anyhow::Result<tonic::Request<T>> {
    let mut req = tonic::Request::new(msg);
    req.metadata_mut().insert(
        "authorization",
        bearer(token).context("the token is not a valid header value")?,
    );
    Ok(req)
}

/// The `authorization` header's value for `token` (`Bearer <token>`), for every authorised
/// call: [`authorized`]'s and the publish loop's.
///
/// # Errors
/// When the token holds characters a header cannot carry.
pub fn bearer(
    token: &str,
) -> Result<
    tonic::metadata::MetadataValue<tonic::metadata::Ascii>,
    tonic::metadata::errors::InvalidMetadataValue,
> {
    format!("Bearer {token}").parse()
}

/// Wall clock, microseconds since the Unix epoch (the wire's capture clock).
pub fn unix_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

/// One model the server hosts (`GetModel`).
///
/// # Errors
/// No such model (named), or an unreachable server.
pub async fn get_model(
    client: &mut CreaseClient<Channel>,
    model: &str,
) -> anyhow::Result<v1::ModelInfo> {
    client
        .get_model(v1::GetModelRequest {
            model: model.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("{}", s.message()))
}

/// A refusal of a job call as an error: the server's message (it names the field or the job)
/// and the code.
fn refused(s: &tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("{} ({:?})", s.message(), s.code())
}

/// What a batch job synthesises (issue 45), as `crease job submit` takes it.
#[derive(Clone, Debug, Default)]
pub struct JobRequest {
    /// The model's name on the server.
    pub model: String,
    /// The detail level instead of the base mesh.
    pub detail: bool,
    /// Translation-solve beta; `None`: the model's default.
    pub beta: Option<f32>,
    /// The refinement asked for; `None`: the server's default (`Some(RefineFlag(None))` is
    /// off).
    pub refine: Option<crease_proto::room::RefineFlag>,
    /// The skinning; `None`: the model's default.
    pub skinning: Option<crease_core::runtime::skin::Skinning>,
    /// A label for `crease job list`.
    pub name: String,
    /// The control frames of this take on the server instead of frames sent (its model and
    /// settings are the take's; `model`, `beta`, `refine` and `skinning` are ignored).
    pub take: Option<String>,
    /// How the result's frames travel: every vertex, or the palette (bone transforms).
    pub encoding: crease_proto::Encoding,
    /// A marker recording sent raw: the frames are then markers (in `Retarget.markers`'
    /// order), retargeted by the server through the map (`JobSpec.retarget`).
    pub retarget: Option<v1::Retarget>,
}

/// Most bytes of control frames per request or message (`Synthesize`, `SubmitJob`): 1 MiB
/// below the 4 MiB message limit that crease-server enforces by default
/// (`Limits::message_bytes`, gRPC's usual default), leaving room for the other fields.
pub const MESSAGE_BYTES: usize = 3 << 20;

/// Control frames of `points` points per request or message: at most `max_frames`, and at
/// most [`MESSAGE_BYTES`] of frames (never fewer than one).
pub fn frames_per_message(points: usize, max_frames: usize) -> usize {
    // An upper bound of one encoded `ControlFrame`: the packed positions, the mask, `seq` (at
    // most 10 bytes) and the tags and lengths around them and the frame.
    let frame_bytes = 12 * points + points.div_ceil(8) + 32;
    max_frames.min(MESSAGE_BYTES / frame_bytes).max(1)
}

/// Submits a batch job (admin token): the spec, then `frames` (one per control frame, the
/// points, or with `job.retarget` the markers, and their validity as read from a file) in
/// messages of at most [`MESSAGE_BYTES`].
/// Returns the job as the server accepted it.
///
/// # Errors
/// The server's refusal (it names a refused frame by its index in the job), or a bad token.
pub async fn submit_job(
    client: &mut CreaseClient<Channel>,
    admin_token: &str,
    job: &JobRequest,
    frames: &[crate::control_file::ControlFrame],
) -> anyhow::Result<v1::JobInfo> {
    use v1::submit_job_request::Part;
    let spec = v1::JobSpec {
        model: job.model.clone(),
        level: if job.detail {
            v1::Level::Detail
        } else {
            v1::Level::Base
        } as i32,
        beta: job.beta.unwrap_or(0.0),
        refine: job.refine.map(|f| crease_proto::room::refine_wire(f.0)),
        skinning: job.skinning.map_or(0, |s| v1::Skinning::from(s) as i32),
        take: job.take.clone().unwrap_or_default(),
        name: job.name.clone(),
        encoding: v1::Encoding::from(job.encoding) as i32,
        retarget: job.retarget.clone(),
    };
    let raw = job.retarget.is_some();
    let points = frames.first().map_or(0, |f| f.positions.len());
    let per_message = frames_per_message(points, usize::MAX);
    let mut messages = vec![v1::SubmitJobRequest {
        part: Some(Part::Spec(spec)),
    }];
    for chunk in frames.chunks(per_message) {
        messages.push(v1::SubmitJobRequest {
            part: Some(Part::Frames(v1::JobFrames {
                frames: chunk
                    .iter()
                    .enumerate()
                    .map(|(k, f)| {
                        let frame = if raw {
                            crease_proto::control::marker_frame
                        } else {
                            crease_proto::control::control_frame
                        };
                        frame("", k as u64, 0, &f.positions, &f.valid)
                    })
                    .collect(),
            })),
        });
    }
    client
        .submit_job(authorized(tokio_stream::iter(messages), admin_token)?)
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| refused(&s))
}

/// A job's progress: its status now, then each change until it ends.
///
/// # Errors
/// No such job, or an unreachable server.
pub async fn watch_job(
    client: &mut CreaseClient<Channel>,
    job: &str,
) -> anyhow::Result<tonic::Streaming<v1::JobInfo>> {
    client
        .watch_job(v1::WatchJobRequest {
            job: job.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| refused(&s))
}

/// A done job's meshes: a topology message, then one frame per control frame in order.
///
/// # Errors
/// No such job, one not done (running, failed, cancelled), or one whose result expired.
pub async fn job_result(
    client: &mut CreaseClient<Channel>,
    job: &str,
) -> anyhow::Result<tonic::Streaming<v1::MeshFrame>> {
    client
        .get_job_result(v1::GetJobResultRequest {
            job: job.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| refused(&s))
}

/// The server's jobs, newest first.
///
/// # Errors
/// An unreachable server.
pub async fn list_jobs(client: &mut CreaseClient<Channel>) -> anyhow::Result<Vec<v1::JobInfo>> {
    client
        .list_jobs(v1::ListJobsRequest {})
        .await
        .map(|r| r.into_inner().jobs)
        .map_err(|s| refused(&s))
}

/// Cancels a queued or running job (admin token).
///
/// # Errors
/// No such job, one already ended (the server says how), or a bad token.
pub async fn cancel_job(
    client: &mut CreaseClient<Channel>,
    admin_token: &str,
    job: &str,
) -> anyhow::Result<v1::JobInfo> {
    client
        .cancel_job(authorized(
            v1::CancelJobRequest {
                job: job.to_owned(),
            },
            admin_token,
        )?)
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| refused(&s))
}
