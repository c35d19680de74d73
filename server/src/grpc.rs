//! The `crease.v1.Crease` gRPC service (tonic), plus grpc.health.v1 and server reflection so
//! generic gRPC tools work.

use std::net::IpAddr;
use std::pin::Pin;
use std::sync::Arc;

use crease_proto::v1::crease_server::{Crease, CreaseServer};
use crease_proto::{Encoding, Level, v1};
use tokio::sync::mpsc;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

use crease_proto::room::{RoomSpec, refinement};

use crate::admission::Permit;
use crate::fanout::Channel;
use crate::ingest::{self, PublishError};
use crate::room::{Room, RoomOptions};
use crate::state::{AppState, OpenRoomError};
use crate::status;
use crate::take_service as takes;

/// The largest message the server sends: what it sends is its own (a limit on requests,
/// `limits.message_bytes`, protects it from clients), and a detail palette header is one
/// message of several MB (11.5 MB for the demo hand's 151K-vertex detail layer).
pub const MAX_SENT_MESSAGE_BYTES: usize = 256 << 20;

/// The largest chunk of a `GetTake` stream.
const TAKE_CHUNK_BYTES: usize = 1 << 20;

/// Frames buffered per response stream before the sender waits (acks, batch frames).
const STREAM_BUFFER: usize = 4;

/// The service over shared state.
#[derive(Clone, Debug)]
pub struct CreaseService {
    state: Arc<AppState>,
}

/// The tonic router: the Crease service, health (SERVING for `crease.v1.Crease`) and reflection.
/// With `tls` (PEM certificate chain and key), gRPC is served over TLS (rustls).
pub fn router(
    state: Arc<AppState>,
    tls: Option<&crate::config::TlsPem>,
) -> std::io::Result<tonic::transport::server::Router> {
    let max = state.config().limits.message_bytes;
    let (reporter, health) = tonic_health::server::health_reporter();
    let reflection = || {
        tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(v1::FILE_DESCRIPTOR_SET)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
    };
    // Both reflection versions: grpcurl and newer tools speak v1, grpcio-reflection's Python
    // client and older tools v1alpha.
    let reflection_v1 = reflection().build_v1().map_err(std::io::Error::other)?;
    let reflection_v1alpha = reflection()
        .build_v1alpha()
        .map_err(std::io::Error::other)?;
    let service = CreaseServer::new(CreaseService { state })
        .max_decoding_message_size(max)
        .max_encoding_message_size(MAX_SENT_MESSAGE_BYTES);
    tokio::spawn(async move {
        reporter.set_serving::<CreaseServer<CreaseService>>().await;
    });
    let mut builder = tonic::transport::Server::builder();
    if let Some(tls) = tls {
        builder = builder
            .tls_config(
                tonic::transport::ServerTlsConfig::new()
                    .identity(tonic::transport::Identity::from_pem(&tls.cert, &tls.key)),
            )
            .map_err(std::io::Error::other)?;
    }
    Ok(builder
        .add_service(health)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .add_service(service))
}

/// The bearer token of a request's `authorization` metadata.
fn bearer<T>(req: &Request<T>) -> Option<String> {
    let v = req.metadata().get("authorization")?.to_str().ok()?;
    v.strip_prefix("Bearer ").map(|t| t.trim().to_owned())
}

impl CreaseService {
    fn require_admin<T>(&self, req: &Request<T>) -> Result<(), Status> {
        let Some(admin) = &self.state.config().admin_token else {
            return Err(Status::permission_denied(
                "this server has no admin token: rooms are opened at start only",
            ));
        };
        match bearer(req) {
            Some(t) if crate::session::same_token(&t, admin) => Ok(()),
            Some(_) => Err(Status::permission_denied("wrong admin token")),
            None => Err(Status::unauthenticated(
                "missing `authorization: Bearer <admin token>`",
            )),
        }
    }

    /// As [`Self::require_admin`], for the model operations (issue 39).
    fn require_models_admin<T>(&self, req: &Request<T>) -> Result<(), Status> {
        if self.state.config().admin_token.is_none() {
            return Err(Status::permission_denied(
                "this server has no admin token: its models come from its folder at start only",
            ));
        }
        self.require_admin(req)
    }

    /// As [`Self::require_admin`], for batch jobs (issue 45).
    fn require_jobs_admin<T>(&self, req: &Request<T>) -> Result<(), Status> {
        if self.state.config().admin_token.is_none() {
            return Err(Status::permission_denied(
                "this server has no admin token: it takes no batch jobs (start it with --admin-token)",
            ));
        }
        self.require_admin(req)
    }

    /// A stream slot for the request's client address (`Limits::streams`), or
    /// RESOURCE_EXHAUSTED naming the address and the cap.
    fn admit<T>(&self, req: &Request<T>) -> Result<Permit, Status> {
        let ip = req
            .remote_addr()
            .map_or(IpAddr::V4(std::net::Ipv4Addr::UNSPECIFIED), |a| a.ip());
        self.state
            .streams()
            .admit(ip)
            .map_err(|e| Status::resource_exhausted(e.to_string()))
    }

    async fn room(&self, id: &str) -> Result<Arc<Room>, Status> {
        self.state
            .find_room(id)
            .await
            .map_err(|e| status::publish(&PublishError::from(e)))
    }
}

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send + 'static>>;

#[tonic::async_trait]
impl Crease for CreaseService {
    async fn list_models(
        &self,
        _req: Request<v1::ListModelsRequest>,
    ) -> Result<Response<v1::ListModelsResponse>, Status> {
        Ok(Response::new(v1::ListModelsResponse {
            models: self
                .state
                .models()
                .list()
                .iter()
                .map(|m| m.info.clone())
                .collect(),
            cluster: crate::model_api::cluster_models(&self.state)
                .await
                .into_iter()
                .map(|(name, sha256, bytes)| v1::StoredModel {
                    name,
                    sha256,
                    bytes,
                })
                .collect(),
        }))
    }

    async fn upload_model(
        &self,
        req: Request<tonic::Streaming<v1::ModelChunk>>,
    ) -> Result<Response<v1::ModelInfo>, Status> {
        self.require_models_admin(&req)?;
        let model = crate::model_api::upload(&self.state, req.into_inner())
            .await
            .map_err(|e| status::model_op(&e))?;
        Ok(Response::new(model.info.clone()))
    }

    async fn delete_model(
        &self,
        req: Request<v1::DeleteModelRequest>,
    ) -> Result<Response<v1::DeleteModelResponse>, Status> {
        self.require_models_admin(&req)?;
        crate::model_api::delete(&self.state, &req.get_ref().model)
            .await
            .map_err(|e| status::model_op(&e))?;
        Ok(Response::new(v1::DeleteModelResponse {}))
    }

    async fn get_model(
        &self,
        req: Request<v1::GetModelRequest>,
    ) -> Result<Response<v1::ModelInfo>, Status> {
        let name = &req.get_ref().model;
        self.state
            .models()
            .get(name)
            .map(|m| Response::new(m.info.clone()))
            .ok_or_else(|| Status::not_found(format!("model: no model {name:?}")))
    }

    async fn open_room(
        &self,
        req: Request<v1::OpenRoomRequest>,
    ) -> Result<Response<v1::OpenRoomResponse>, Status> {
        self.require_admin(&req)?;
        let spec = RoomSpec::from_request(req.get_ref(), self.state.config().refine)
            .map_err(|e| status::open(&OpenRoomError::from(e)))?;
        let room = self
            .state
            .open_room(spec)
            .await
            .map_err(|e| status::open(&e))?;
        let response = v1::OpenRoomResponse {
            room: room.id.clone(),
            publish_token: room.token().unwrap_or_default().to_owned(),
            model: Some(room.model.info.clone()),
        };
        Ok(Response::new(response))
    }

    async fn get_room(
        &self,
        req: Request<v1::GetRoomRequest>,
    ) -> Result<Response<v1::RoomInfo>, Status> {
        let room = self.room(&req.get_ref().room).await?;
        let (owner, replica) = match self.state.cluster() {
            Some(cluster) => (
                cluster.owner_of(&room.id).unwrap_or_default(),
                cluster.replica.clone(),
            ),
            None => (String::new(), String::new()),
        };
        Ok(Response::new(v1::RoomInfo {
            room: room.id.clone(),
            model: Some(room.model.info.clone()),
            beta: room.beta(),
            filter: room.filter().map(v1::MarkerFilter::from),
            subscribers: room.subscriber_count() as u32,
            published: room.published(),
            owner,
            replica,
            retarget: room.pipeline().capture().map(|c| c.wire().clone()),
            refine: room.refinement().map(v1::Refine::from),
            skinning: v1::Skinning::from(room.skinning()) as i32,
            actors: room.actors().iter().filter_map(|a| a.info()).collect(),
        }))
    }

    async fn close_room(
        &self,
        req: Request<v1::CloseRoomRequest>,
    ) -> Result<Response<v1::CloseRoomResponse>, Status> {
        self.require_admin(&req)?;
        self.state
            .close_room(&req.get_ref().room)
            .await
            .map_err(|e| status::open(&e))?;
        Ok(Response::new(v1::CloseRoomResponse {}))
    }

    type PublishStream = BoxStream<v1::PublishAck>;

    async fn publish(
        &self,
        req: Request<Streaming<v1::ControlFrame>>,
    ) -> Result<Response<Self::PublishStream>, Status> {
        let permit = self.admit(&req)?;
        let token = bearer(&req);
        let mut frames = req.into_inner();
        let state = Arc::clone(&self.state);
        let (tx, rx) = mpsc::channel(STREAM_BUFFER);
        tokio::spawn(async move {
            let _permit = permit;
            loop {
                let frame = match frames.message().await {
                    Ok(Some(frame)) => frame,
                    Ok(None) => break,
                    // A message the server will not read (over `limits.message_bytes`, not a
                    // ControlFrame): the client's stream ends with why, not silently.
                    Err(status) => {
                        let _ = tx.send(Err(status)).await;
                        break;
                    }
                };
                let seq = frame.seq;
                let ack = ingest::ack(seq, &ingest::publish(&state, token.as_deref(), frame).await);
                if tx.send(Ok(ack)).await.is_err() {
                    break;
                }
            }
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    type SubscribeStream = BoxStream<v1::MeshFrame>;

    async fn subscribe(
        &self,
        req: Request<v1::SubscribeRequest>,
    ) -> Result<Response<Self::SubscribeStream>, Status> {
        let permit = self.admit(&req)?;
        let r = req.into_inner();
        let level = Level::from_wire("SubscribeRequest", r.level)?;
        let encoding = Encoding::from_wire("SubscribeRequest", r.encoding)?;
        let room = self.room(&r.room).await?;
        check_level(&room, level)?;
        let channel = Channel::new(level, encoding);
        room.check_channel(channel)
            .map_err(|e| status::channel(&e))?;
        let subscription = room
            .subscribe(channel, self.state.config().limits.subscribers_per_room)
            .map_err(|e| Status::resource_exhausted(format!("room {:?}: {e}", room.id)))?;
        Ok(Response::new(holding(
            permit,
            crate::stream::subscribe(Arc::clone(&self.state), room, channel, subscription),
        )))
    }

    type SynthesizeStream = BoxStream<v1::MeshFrame>;

    async fn synthesize(
        &self,
        req: Request<v1::SynthesizeRequest>,
    ) -> Result<Response<Self::SynthesizeStream>, Status> {
        let permit = self.admit(&req)?;
        let r = req.into_inner();
        let level = Level::from_wire("SynthesizeRequest", r.level)?;
        let options = self.batch_options("SynthesizeRequest", &r)?;
        let room = self
            .state
            .batch_room(&r.model, options)
            .await
            .map_err(|e| status::open(&e))?;
        check_level(&room, level)?;
        Ok(Response::new(holding(
            permit,
            crate::stream::batch(
                Arc::clone(&self.state),
                room,
                Channel::vertices(level),
                r.frames,
            ),
        )))
    }

    async fn submit_job(
        &self,
        req: Request<Streaming<v1::SubmitJobRequest>>,
    ) -> Result<Response<v1::JobInfo>, Status> {
        self.require_jobs_admin(&req)?;
        self.submit(req.into_inner()).await.map(Response::new)
    }

    type WatchJobStream = BoxStream<v1::JobInfo>;

    async fn watch_job(
        &self,
        req: Request<v1::WatchJobRequest>,
    ) -> Result<Response<Self::WatchJobStream>, Status> {
        let permit = self.admit(&req)?;
        let updates = crate::job_service::watch(&self.state, &req.get_ref().job)
            .await
            .map_err(|e| status::job(&e))?;
        // The status now, then each change, ending after the job's last.
        Ok(Response::new(Box::pin(tokio_stream::StreamExt::map(
            updates,
            move |status| {
                let _held = &permit;
                Ok(v1::JobInfo::from(&status))
            },
        ))))
    }

    type GetJobResultStream = BoxStream<v1::MeshFrame>;

    async fn get_job_result(
        &self,
        req: Request<v1::GetJobResultRequest>,
    ) -> Result<Response<Self::GetJobResultStream>, Status> {
        let permit = self.admit(&req)?;
        let result = crate::job_service::result(&self.state, &req.get_ref().job)
            .await
            .map_err(|e| status::job(&e))?;
        Ok(Response::new(Box::pin(tokio_stream::StreamExt::map(
            result,
            move |item| {
                let _held = &permit;
                item.map_err(|e| status::job(&e))
            },
        ))))
    }

    async fn list_jobs(
        &self,
        _req: Request<v1::ListJobsRequest>,
    ) -> Result<Response<v1::ListJobsResponse>, Status> {
        let jobs = crate::job_service::list(&self.state)
            .await
            .map_err(|e| status::job(&e))?;
        Ok(Response::new(v1::ListJobsResponse {
            jobs: jobs.iter().map(v1::JobInfo::from).collect(),
        }))
    }

    async fn cancel_job(
        &self,
        req: Request<v1::CancelJobRequest>,
    ) -> Result<Response<v1::JobInfo>, Status> {
        self.require_jobs_admin(&req)?;
        crate::job_service::cancel(&self.state, &req.get_ref().job)
            .await
            .map(|s| Response::new(v1::JobInfo::from(&s)))
            .map_err(|e| status::job(&e))
    }

    async fn start_take(
        &self,
        req: Request<v1::StartTakeRequest>,
    ) -> Result<Response<v1::TakeInfo>, Status> {
        self.require_admin(&req)?;
        let r = req.into_inner();
        takes::start(&self.state, &r.room, r.name)
            .await
            .map(Response::new)
            .map_err(|e| status::take(&e))
    }

    async fn stop_take(
        &self,
        req: Request<v1::StopTakeRequest>,
    ) -> Result<Response<v1::TakeInfo>, Status> {
        self.require_admin(&req)?;
        takes::stop(&self.state, &req.get_ref().room)
            .await
            .map(Response::new)
            .map_err(|e| status::take(&e))
    }

    async fn list_takes(
        &self,
        req: Request<v1::ListTakesRequest>,
    ) -> Result<Response<v1::ListTakesResponse>, Status> {
        let takes = takes::list(&self.state, req.into_inner().room)
            .await
            .map_err(|e| status::take(&e))?;
        Ok(Response::new(v1::ListTakesResponse { takes }))
    }

    type GetTakeStream = BoxStream<v1::TakeChunk>;

    async fn get_take(
        &self,
        req: Request<v1::GetTakeRequest>,
    ) -> Result<Response<Self::GetTakeStream>, Status> {
        let bytes = takes::bytes(&self.state, req.into_inner().take)
            .await
            .map_err(|e| status::take(&e))?;
        let bytes = prost::bytes::Bytes::from(bytes);
        let chunks: Vec<Result<v1::TakeChunk, Status>> = (0..bytes.len())
            .step_by(TAKE_CHUNK_BYTES)
            .map(|at| {
                Ok(v1::TakeChunk {
                    data: bytes
                        .slice(at..(at + TAKE_CHUNK_BYTES).min(bytes.len()))
                        .to_vec(),
                })
            })
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }
}

impl CreaseService {
    /// A batch's options (`Synthesize`, a job's spec), checked: the refinement resolved with
    /// the server's default, the skinning named in `message_type`.
    fn batch_options(
        &self,
        message_type: &'static str,
        r: &v1::SynthesizeRequest,
    ) -> Result<RoomOptions, Status> {
        let spec_error = |e| status::open(&OpenRoomError::Spec(e));
        Ok(RoomOptions {
            beta: (r.beta != 0.0).then_some(r.beta),
            filter: None,
            refine: refinement(r.refine, self.state.config().refine).map_err(spec_error)?,
            skinning: crease_proto::convert::skinning_from_wire(message_type, r.skinning)?,
        })
    }

    /// `SubmitJob`'s stream read and checked (issue 45): the spec, then the frames (at most
    /// the job cap), every frame against the model (a refused one names its index in the
    /// job), cut into chunks off the executor, and queued.
    async fn submit(
        &self,
        mut stream: Streaming<v1::SubmitJobRequest>,
    ) -> Result<v1::JobInfo, Status> {
        use crease_proto::job::{chunk_frames, spec_as_batch};
        use v1::submit_job_request::Part;
        let spec = match stream.message().await?.and_then(|m| m.part) {
            Some(Part::Spec(spec)) => spec,
            Some(Part::Frames(_)) => {
                return Err(Status::invalid_argument(
                    "SubmitJob: the first message must be a JobSpec, got frames",
                ));
            }
            None => {
                return Err(Status::invalid_argument(
                    "SubmitJob: the stream ended before its JobSpec",
                ));
            }
        };
        let level = Level::from_wire("JobSpec", spec.level)?;
        let encoding = Encoding::from_wire("JobSpec", spec.encoding)?;
        let settings = self.state.jobs().settings().clone();
        let check_level = |model: &crate::registry::LoadedModel| {
            if level == Level::Detail && model.info.detail_vertices == 0 {
                return Err(Status::failed_precondition(format!(
                    "JobSpec.level: model {:?} has no detail layer",
                    model.name
                )));
            }
            Ok(())
        };
        let (model, options, frames) = if spec.take.is_empty() {
            let model = crate::job_service::model(&self.state, &spec.model)
                .await
                .map_err(|e| status::job(&e))?
                .ok_or_else(|| {
                    Status::not_found(format!("JobSpec.model: no model {:?}", spec.model))
                })?;
            check_level(&model)?;
            let options = self.batch_options("JobSpec", &spec_as_batch(&spec))?;
            let frames = read_job_frames(&mut stream, settings.max_frames).await?;
            let frames = match spec.retarget.clone() {
                Some(wire) => self.retarget_job(wire, &model, frames).await?,
                None => frames,
            };
            (model, options, frames)
        } else {
            if spec.retarget.is_some() {
                return Err(Status::invalid_argument(
                    "JobSpec.retarget: a job from a take (JobSpec.take) has its control points already; send one or the other",
                ));
            }
            // The take's own frames, model and settings (JobSpec: the other fields but the
            // level and the name are ignored); frames sent after the spec are refused.
            if read_job_frames(&mut stream, 0).await.is_err() {
                return Err(Status::invalid_argument(
                    "SubmitJob: a job from a take (JobSpec.take) takes no frames after its spec",
                ));
            }
            crate::take_service::job_source(&self.state, spec.take.clone())
                .await
                .map_err(|e| match e {
                    crate::take_service::TakeOpError::Take(
                        crate::takes::TakeError::NoTake(_),
                    ) => Status::not_found(format!(
                        "JobSpec.take: no take {:?} on this server (a take lives on the server that recorded it: crease take list)",
                        spec.take
                    )),
                    e => status::take(&e),
                })?
        };
        check_level(&model)?;
        if encoding == Encoding::Palette
            && options.skinning.unwrap_or(model.model.skinning)
                == crease_core::runtime::skin::Skinning::Dqs
        {
            return Err(Status::failed_precondition(format!(
                "JobSpec.encoding: a palette job's frames are skinned by the client with LBS, and this job skins model {:?} with DQS: submit with encoding vertices, or with skinning lbs",
                model.name
            )));
        }
        if frames.is_empty() {
            return Err(Status::invalid_argument(if spec.take.is_empty() {
                "SubmitJob: no frames after the JobSpec".to_owned()
            } else {
                format!("JobSpec.take {:?}: the take has no frames", spec.take)
            }));
        }
        if frames.len() > settings.max_frames {
            return Err(Status::resource_exhausted(format!(
                "SubmitJob.frames: {} frames, at most {} per job (--max-job-frames)",
                frames.len(),
                settings.max_frames
            )));
        }
        let count = model.info.control_points.len();
        // Sizing the chunks reads every frame too: off the executor with the checks.
        let state = Arc::clone(&self.state);
        let chunks = tokio::task::spawn_blocking(move || {
            let chunk = crate::job_service::chunk_frames(&state, &frames);
            chunk_frames(&frames, count, chunk)
        })
        .await
        .map_err(|e| Status::internal(format!("checking the job's frames: {e}")))?
        .map_err(|e| crease_proto::errors::job_frame_status(e.index, &e.error))?;
        let plan = crate::jobs::JobPlan {
            model: model.name.clone(),
            level,
            options,
            name: spec.name.clone(),
            encoding,
        };
        let status = crate::job_service::submit(&self.state, plan, &model, chunks)
            .await
            .map_err(|e| status::job(&e))?;
        tracing::info!(job = %status.job, model = %status.model, frames = status.frames_total, chunks = status.chunks_total, "job queued");
        Ok(v1::JobInfo::from(&status))
    }

    /// A job's raw marker frames retargeted through `wire`'s map onto `model`'s control points
    /// (`crate::capture`), off the executor.
    async fn retarget_job(
        &self,
        wire: v1::Retarget,
        model: &Arc<crate::registry::LoadedModel>,
        frames: Vec<v1::ControlFrame>,
    ) -> Result<Vec<v1::ControlFrame>, Status> {
        let maps = self.state.config().maps.clone();
        let capture = crate::capture::CaptureSpec::build(wire, maps, Arc::clone(model))
            .await
            .map_err(|e| Status::invalid_argument(format!("JobSpec.{e}")))?;
        tokio::task::spawn_blocking(move || capture.retarget_recording(&frames))
            .await
            .map_err(|e| Status::internal(format!("retargeting the job's markers: {e}")))?
            .map_err(|e| crease_proto::errors::job_frame_status(e.index, &e.error))
    }
}

/// The `JobFrames` that follow a job's spec, at most `max` frames (more: RESOURCE_EXHAUSTED,
/// naming the cap); a second spec is refused.
async fn read_job_frames(
    stream: &mut Streaming<v1::SubmitJobRequest>,
    max: usize,
) -> Result<Vec<v1::ControlFrame>, Status> {
    use v1::submit_job_request::Part;
    let mut frames: Vec<v1::ControlFrame> = Vec::new();
    while let Some(message) = stream.message().await? {
        match message.part {
            Some(Part::Frames(f)) => {
                if frames.len() + f.frames.len() > max {
                    return Err(Status::resource_exhausted(format!(
                        "SubmitJob.frames: more than {max} frames, the most a job may hold (--max-job-frames)"
                    )));
                }
                frames.extend(f.frames);
            }
            Some(Part::Spec(_)) => {
                return Err(Status::invalid_argument(
                    "SubmitJob: a second JobSpec; a job has one, first",
                ));
            }
            None => {}
        }
    }
    Ok(frames)
}

/// `stream`, holding `permit` (a stream slot) until it is dropped, its error as a status.
fn holding<T: Send + 'static>(
    permit: Permit,
    stream: impl Stream<Item = Result<T, crate::stream::StreamError>> + Send + 'static,
) -> BoxStream<T> {
    Box::pin(tokio_stream::StreamExt::map(stream, move |item| {
        let _held = &permit;
        item.map_err(|e| status::stream(&e))
    }))
}

/// Detail streams need a model with a detail layer.
fn check_level(room: &Room, level: Level) -> Result<(), Status> {
    if level == Level::Detail && !room.has_detail() {
        return Err(Status::failed_precondition(format!(
            "level: model {:?} has no detail layer",
            room.model.name
        )));
    }
    Ok(())
}
