//! `crease take start|stop|list|get|replay|export` (issue 22): a room's recordings on a server.
//! `start` and `stop` need the server's admin token; reading is open. A TAKE argument is a take
//! file on disk (`crease take get`'s, or the server's takes folder) or a take id on the server.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use crease_core::model::TrainedModel;
use crease_proto::errors::ErrorCode;
use crease_proto::take::{self, Take};
use crease_proto::v1;
use tokio_stream::StreamExt as _;

use super::common::{ServerArgs, authorized};
use super::room::AdminArgs;
use super::take_export;
use crease_remote::publish::{PublishError, PublishOptions, Sink, publish};

/// Options of `crease take`.
#[derive(Clone, Debug, clap::Args)]
pub struct TakeArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: TakeAction,
}

/// What to do with takes.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum TakeAction {
    /// Start recording a room (admin token); prints the take's id.
    Start(StartArgs),
    /// Stop a room's take (admin token); prints the take's id.
    Stop(StopArgs),
    /// List the server's takes, newest first.
    List(ListArgs),
    /// Download a take file.
    Get(GetArgs),
    /// Publish a take's frames into a room at their original timing (or faster).
    Replay(ReplayArgs),
    /// Export a take as a skinned glTF animation (or, at the detail level, morph targets).
    Export(ExportArgs),
}

/// Options of `crease take start`.
#[derive(Clone, Debug, clap::Args)]
pub struct StartArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The admin token.
    #[command(flatten)]
    pub admin: AdminArgs,
    /// The room to record.
    #[arg(long)]
    pub room: String,
    /// A label for people (at most 200 bytes).
    #[arg(long, default_value = "")]
    pub name: String,
}

/// Options of `crease take stop`.
#[derive(Clone, Debug, clap::Args)]
pub struct StopArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The admin token.
    #[command(flatten)]
    pub admin: AdminArgs,
    /// The room whose take stops.
    #[arg(long)]
    pub room: String,
}

/// Options of `crease take list`.
#[derive(Clone, Debug, clap::Args)]
pub struct ListArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Only this room's takes.
    #[arg(long)]
    pub room: Option<String>,
    /// Print `{"takes": [...]}` (the shape of `GET /api/takes`) instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Options of `crease take get`.
#[derive(Clone, Debug, clap::Args)]
pub struct GetArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The take's id.
    pub take: String,
    /// Where to write it. Default: `TAKE.take` here.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// Options of `crease take replay`.
#[derive(Clone, Debug, clap::Args)]
pub struct ReplayArgs {
    /// The server to talk to (and, for a take id, to download it from).
    #[command(flatten)]
    pub server: ServerArgs,
    /// A take file, or a take id on the server.
    pub take: String,
    /// The room to publish into. With --token it must be open; without, it is opened (admin
    /// token) with the take's settings (model, beta, filter, retargeting, refinement).
    #[arg(long)]
    pub room: String,
    /// The room's publish token (publish into an open room).
    #[arg(long, env = "CREASE_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The admin token that opens the room (without --token). Also read from
    /// CREASE_ADMIN_TOKEN.
    #[arg(long, env = "CREASE_ADMIN_TOKEN", hide_env_values = true)]
    pub admin_token: Option<String>,
    /// Playback speed: 1 = the original timing, 2 = twice as fast; `max` sends each frame when
    /// the previous one's ack came (every frame predicted, none superseded).
    #[arg(long, default_value = "1", value_parser = parse_speed)]
    pub speed: Speed,
}

/// Options of `crease take export`.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// The server to download a take id from.
    #[command(flatten)]
    pub server: ServerArgs,
    /// A take file, or a take id on the server.
    pub take: String,
    /// The model file the take was recorded on (checked by SHA-256).
    #[arg(long, value_name = "FILE.crease")]
    pub model: PathBuf,
    /// The glTF binary to write.
    #[arg(long, value_name = "FILE.glb")]
    pub out: PathBuf,
    /// `base`: a skinned mesh, one joint per bone, the recorded bone transforms as keyframes
    /// (exactly the room's base meshes under glTF skinning; tens of bytes per bone per frame).
    /// `detail`: the detail mesh of every --every-th frame as morph targets (12 bytes per
    /// vertex per frame).
    #[arg(long, default_value = "base", value_parser = ["base", "detail"])]
    pub level: String,
    /// With --level detail: export every N-th frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub every: u32,
}

/// `--speed`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Speed {
    /// A factor on the original timing.
    Times(f64),
    /// One frame per ack.
    Lockstep,
}

/// Parses `--speed`: a positive number or `max`.
pub fn parse_speed(s: &str) -> Result<Speed, String> {
    if s == "max" {
        return Ok(Speed::Lockstep);
    }
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(Speed::Times(x)),
        _ => Err(format!("expected a positive number or `max`, got {s:?}")),
    }
}

/// Runs `crease take`.
pub fn run(args: &TakeArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(async {
        match &args.action {
            TakeAction::Start(a) => start(a).await,
            TakeAction::Stop(a) => stop(a).await,
            TakeAction::List(a) => list(a).await,
            TakeAction::Get(a) => get(a).await,
            TakeAction::Replay(a) => replay(a).await,
            TakeAction::Export(a) => export(a).await,
        }
    })
}

/// A status as an error carrying its message.
fn status(s: tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("{}", s.message())
}

/// One line about a take.
fn describe(t: &v1::TakeInfo) -> String {
    format!(
        "take {} of room {:?} on model {:?}: {} frames, {:.1} s, {} bytes{}{}",
        t.take,
        t.room,
        t.model,
        t.frames,
        t.duration_us as f64 * 1e-6,
        t.bytes,
        if t.recording { ", recording" } else { "" },
        if t.truncated {
            ", truncated (the server stopped while recording it)"
        } else {
            ""
        }
    )
}

async fn start(args: &StartArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let request = v1::StartTakeRequest {
        room: args.room.clone(),
        name: args.name.clone(),
    };
    let info = client
        .start_take(authorized(request, &args.admin.admin_token)?)
        .await
        .map_err(status)
        .with_context(|| format!("starting a take of room {:?}", args.room))?
        .into_inner();
    eprintln!("recording {}", describe(&info));
    println!("{}", info.take);
    Ok(())
}

async fn stop(args: &StopArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let request = v1::StopTakeRequest {
        room: args.room.clone(),
    };
    let info = client
        .stop_take(authorized(request, &args.admin.admin_token)?)
        .await
        .map_err(status)
        .with_context(|| format!("stopping the take of room {:?}", args.room))?
        .into_inner();
    eprintln!("stopped {}", describe(&info));
    println!("{}", info.take);
    Ok(())
}

async fn list(args: &ListArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let takes = client
        .list_takes(v1::ListTakesRequest {
            room: args.room.clone().unwrap_or_default(),
        })
        .await
        .map_err(status)
        .context("listing takes")?
        .into_inner()
        .takes;
    if args.json {
        let list = crease_proto::json::TakeList {
            takes: takes
                .iter()
                .map(crease_proto::json::TakeSummary::from)
                .collect(),
        };
        println!("{}", serde_json::to_string_pretty(&list)?);
        return Ok(());
    }
    if takes.is_empty() {
        eprintln!("no takes");
    }
    println!(
        "{:<40} {:<16} {:<16} {:>8} {:>9} {:>11}  state",
        "take", "room", "model", "frames", "seconds", "bytes"
    );
    for t in &takes {
        let state = match (t.recording, t.truncated) {
            (true, _) => "recording",
            (false, true) => "truncated",
            (false, false) => "complete",
        };
        println!(
            "{:<40} {:<16} {:<16} {:>8} {:>9.1} {:>11}  {state}",
            t.take,
            t.room,
            t.model,
            t.frames,
            t.duration_us as f64 * 1e-6,
            t.bytes
        );
    }
    Ok(())
}

/// Take `id`'s file from the server.
async fn download(server: &ServerArgs, id: &str) -> anyhow::Result<Vec<u8>> {
    let mut client = server.connect().await?;
    let mut chunks = client
        .get_take(v1::GetTakeRequest {
            take: id.to_owned(),
        })
        .await
        .map_err(status)
        .with_context(|| format!("downloading take {id:?}"))?
        .into_inner();
    let mut bytes = Vec::new();
    while let Some(chunk) = chunks.next().await {
        bytes.extend_from_slice(&chunk.map_err(status)?.data);
    }
    Ok(bytes)
}

async fn get(args: &GetArgs) -> anyhow::Result<()> {
    let bytes = download(&args.server, &args.take).await?;
    let take = take::read_take(bytes.as_slice())
        .with_context(|| format!("take {:?} as the server sent it", args.take))?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.take", args.take)));
    crease_core::model::file::write_atomic(&out, &bytes)
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!(
        "wrote {} ({} frames, {} bytes)",
        out.display(),
        take.frames.len(),
        bytes.len()
    );
    Ok(())
}

/// The take named by `arg`: a file when one is there (or the name ends in `.take`), else an id
/// on the server. Says so when it is truncated.
async fn load(server: &ServerArgs, arg: &str) -> anyhow::Result<Take> {
    let path = Path::new(arg);
    let take = if path.is_file() || arg.ends_with(".take") {
        let file = std::fs::File::open(path).with_context(|| format!("take {arg}"))?;
        take::read_take(std::io::BufReader::new(file)).with_context(|| format!("take {arg}"))?
    } else {
        let bytes = download(server, arg).await?;
        take::read_take(bytes.as_slice()).with_context(|| format!("take {arg:?}"))?
    };
    if take.scan.truncated {
        eprintln!(
            "take {arg}: ends in part of a frame (the server stopped while recording it); using its {} whole frames",
            take.frames.len()
        );
    }
    if take.frames.is_empty() {
        bail!("take {arg}: no frames");
    }
    Ok(take)
}

async fn replay(args: &ReplayArgs) -> anyhow::Result<()> {
    let take = load(&args.server, &args.take).await?;
    let mut client = args.server.connect().await?;
    let token = match (&args.token, &args.admin_token) {
        (Some(token), _) => token.clone(),
        (None, Some(admin)) => {
            let mut request = take.header().room.clone().unwrap_or_default();
            request.room = args.room.clone();
            let opened = client
                .open_room(authorized(request.clone(), admin)?)
                .await
                .map_err(status)
                .with_context(|| {
                    format!(
                        "opening room {:?} on model {:?} for the replay",
                        args.room, request.model
                    )
                })?
                .into_inner();
            eprintln!(
                "opened room {:?} on model {:?} with the take's settings",
                opened.room, request.model
            );
            opened.publish_token
        }
        (None, None) => bail!(
            "give --token (publish into an open room) or --admin-token (open --room with the take's settings)"
        ),
    };
    let times = take::keyframe_times(&take);
    let frames: Vec<v1::ControlFrame> = take
        .frames
        .iter()
        .map(|f| v1::ControlFrame {
            room: args.room.clone(),
            ..f.frame.clone().unwrap_or_default()
        })
        .collect();
    let n = frames.len();
    let started = tokio::time::Instant::now();
    let lockstep = args.speed == Speed::Lockstep;
    let (ack_tx, mut ack_rx) = tokio::sync::mpsc::unbounded_channel::<()>();
    let speed = args.speed;
    let source = move |mut sink: Sink| async move {
        for (i, frame) in frames.into_iter().enumerate() {
            match speed {
                Speed::Times(x) => {
                    let at = started + Duration::from_secs_f64(times[i] / x);
                    tokio::select! {
                        () = tokio::time::sleep_until(at) => {}
                        () = sink.ended() => return,
                    }
                }
                Speed::Lockstep if i > 0 => {
                    tokio::select! {
                        got = ack_rx.recv() => if got.is_none() { return },
                        () = sink.ended() => return,
                    }
                }
                Speed::Lockstep => {}
            }
            if sink.send(frame).await.is_err() {
                return;
            }
        }
    };
    let (mut predicted, mut superseded, mut refused) = (0u64, 0u64, 0u64);
    let mut first_refusal = None;
    let mut on_ack = |ack: v1::PublishAck| {
        match ack.error {
            Some(e) if ErrorCode::from_wire(e.code) == Some(ErrorCode::Aborted) => superseded += 1,
            Some(e) => {
                refused += 1;
                first_refusal.get_or_insert(format!("frame {}: {}", ack.seq, e.message));
            }
            None => predicted += 1,
        }
        if lockstep {
            let _ = ack_tx.send(());
        }
        // Every frame answered: the replay is done.
        if predicted + superseded + refused < n as u64 {
            ControlFlow::Continue(())
        } else {
            ControlFlow::Break(())
        }
    };
    let options = PublishOptions {
        queue: 16,
        drain: None,
    };
    let published = publish(&mut client, &token, options, source, &mut on_ack)
        .await
        .map_err(|e| match e {
            PublishError::Open(s) => {
                status(s).context(format!("publishing into room {:?}", args.room))
            }
            e => e.into_anyhow("--token", "publishing", "the replay's sender"),
        })?;
    if let Some(s) = published.status {
        return Err(status(s).context("the publish stream"));
    }
    eprintln!(
        "replayed {n} frames of take {} into room {:?} in {:.2} s: {predicted} predicted, {superseded} superseded, {refused} refused",
        take.header().take,
        args.room,
        started.elapsed().as_secs_f64()
    );
    if let Some(why) = first_refusal {
        bail!("the room refused frames; the first: {why}");
    }
    Ok(())
}

/// SHA-256 of `bytes`, lowercase hex (the server's model digest).
fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest as _;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

async fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let take = load(&args.server, &args.take).await?;
    let bytes =
        std::fs::read(&args.model).with_context(|| format!("--model {}", args.model.display()))?;
    let model = TrainedModel::from_bytes(&bytes)
        .with_context(|| format!("--model {}", args.model.display()))?;
    let sha256 = sha256_hex(&bytes);
    take::check_model(&take, &model, &sha256)
        .with_context(|| format!("--model {}", args.model.display()))?;
    let started = std::time::Instant::now();
    let actors = &take.header().actors;
    let glb = match args.level.as_str() {
        _ if !actors.is_empty() => {
            // A room of several actors (issue 38): every actor on this model file, mirrored
            // where the actor was.
            if let Some(other) = actors
                .iter()
                .find(|a| !a.model_sha256.eq_ignore_ascii_case(&sha256))
            {
                bail!(
                    "--model {}: actor {:?} of the take was recorded on another model file (SHA-256 {}); crease take export writes takes whose actors share one model",
                    args.model.display(),
                    other.actor,
                    other.model_sha256
                );
            }
            if args.level == "detail" {
                bail!("--level detail: a take of a room of actors exports its skinned level only");
            }
            take_export::actors_glb(&take, &model)?
        }
        "detail" => take_export::detail_glb(&take, Arc::new(model), args.every as usize)?,
        _ => take_export::skinned_glb(&take, &model)?,
    };
    crease_core::model::file::write_atomic(&args.out, &glb)
        .with_context(|| format!("--out {}", args.out.display()))?;
    let times = take::keyframe_times(&take);
    eprintln!(
        "wrote {}: {} frames over {:.2} s at the {} level, {} bytes, in {:.2} s",
        args.out.display(),
        take.frames.len(),
        times.last().copied().unwrap_or(0.0),
        args.level,
        glb.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
