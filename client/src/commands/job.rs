//! `crease job submit|watch|get|list|cancel` (issue 45): batch synthesis handed to a server,
//! which runs it whether or not the client stays. `submit` and `cancel` need the admin token;
//! watching, listing and fetching are open. `get` writes the frames as `crease synth` does.

use std::path::PathBuf;

use anyhow::{Context, bail};
use crease_core::mesh::Mesh;
use crease_core::model::{Rig, gltf_export};
use crease_proto::job::JobState;
use crease_proto::v1;
use crease_remote::client::{
    JobRequest, cancel_job, get_model, job_result, list_jobs, submit_job, watch_job,
};
use crease_remote::control_file::{ControlFrame, read_control_frames};
use crease_remote::mesh_stream::PaletteReader;
use indicatif::{ProgressBar, ProgressStyle};
use tokio_stream::StreamExt as _;

use super::common::ServerArgs;
use super::retarget::{RecordingArgs, parse_rate};
use super::room::AdminArgs;

/// Options of `crease job`.
#[derive(Clone, Debug, clap::Args)]
pub struct JobArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: JobAction,
}

/// What to do with jobs.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum JobAction {
    /// Hand a file of control frames to the server as a job (admin token); prints its id.
    Submit(SubmitArgs),
    /// Show a job's progress (frames, rate, ETA) until it ends.
    Watch(IdArgs),
    /// Write a done job's frames, as `crease synth --out` does.
    Get(GetArgs),
    /// List the server's jobs, newest first.
    List(ListArgs),
    /// Cancel a queued or running job (admin token).
    Cancel(CancelArgs),
}

/// Options of `crease job submit`.
#[derive(Clone, Debug, clap::Args)]
pub struct SubmitArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The admin token.
    #[command(flatten)]
    pub admin: AdminArgs,
    /// The model's name on the server.
    #[arg(long, required_unless_present = "take", conflicts_with = "take")]
    pub model: Option<String>,
    /// Control frames: CSV or JSON, as `crease synth --controls` reads them.
    #[arg(long, value_name = "FILE", required_unless_present_any = ["take", "tsv", "c3d"], conflicts_with_all = ["tsv", "c3d"])]
    pub controls: Option<PathBuf>,
    /// A marker recording (`--tsv` or `--c3d`) and its marker map (`--map`): the markers are
    /// sent raw with the map, and the server retargets them onto the model's control points
    /// exactly as `crease retarget` does (registration, gap filling).
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// With a recording: resample it to this many frames per second (default: its own rate).
    #[arg(long, value_parser = parse_rate, requires = "map")]
    pub rate: Option<f64>,
    /// Synthesise a take recorded on the server instead (`crease take list`): its model, its
    /// room's beta, refinement and skinning, and the control points as its room used them.
    #[arg(long, value_name = "ID", conflicts_with_all = ["controls", "beta", "refine", "skinning"])]
    pub take: Option<String>,
    /// Synthesise the detailed meshes (the model must have a detail layer).
    #[arg(long)]
    pub detail: bool,
    /// Control-point weight of the translation solve (default: the model's).
    #[arg(long)]
    pub beta: Option<f32>,
    /// The refinement, `ITERATIONS,STRENGTH` or `off` (default: the server's).
    #[arg(long, value_name = "ITERATIONS,STRENGTH|off", value_parser = crease_proto::room::parse_refine_flag)]
    pub refine: Option<crease_proto::room::RefineFlag>,
    /// How to skin: `lbs` or `dqs` (default: the model's).
    #[arg(long, value_name = "lbs|dqs")]
    pub skinning: Option<crease_core::runtime::skin::Skinning>,
    /// A label shown by `crease job list`.
    #[arg(long, default_value = "")]
    pub name: String,
    /// How the result's frames are kept and sent: `vertices` (every vertex, quantised) or
    /// `palette` (the bone transforms, and the detail layer's kernel vector at the detail
    /// level: a few hundred bytes a frame; what `get --format gltf` makes a skinned glTF of;
    /// needs LBS skinning).
    #[arg(long, default_value = "vertices", value_parser = parse_encoding)]
    pub encoding: crease_proto::Encoding,
}

fn parse_encoding(s: &str) -> Result<crease_proto::Encoding, String> {
    crease_proto::Encoding::from_query(Some(s)).map_err(|e| e.message)
}

/// A job id on a server.
#[derive(Clone, Debug, clap::Args)]
pub struct IdArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
    /// The job's id (`crease job submit` printed it).
    pub job: String,
}

/// Options of `crease job get`.
#[derive(Clone, Debug, clap::Args)]
pub struct GetArgs {
    /// The job.
    #[command(flatten)]
    pub id: IdArgs,
    /// Output folder (created): `frame_00000.obj` ... as `crease synth` writes them; with
    /// `--format codec` or `gltf`, the file to write.
    #[arg(long, value_name = "DIR|FILE")]
    pub out: PathBuf,
    /// Mesh format of the frames (`obj`, `ply`); `gltf`: one animated glTF binary (.glb), a
    /// skinned mesh whose joints carry the frames' bone transforms for a palette job
    /// (`submit --encoding palette`: the base layer exactly, a few dozen bytes a bone a
    /// frame), or for a vertex job every frame baked into a morph target as
    /// `crease synth --gltf` writes (the first frame is the morph base); or `codec`: the
    /// stream as the server sent it (the topology or palette header, then every quantised
    /// frame, as `crease watch --record` writes a stream), decoded by `crease decode-stream`.
    #[arg(long, default_value = "obj", value_parser = ["obj", "ply", "gltf", "codec"])]
    pub format: String,
    /// Frames per second of the `gltf` animation (frame `i` at `i / fps` s).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
}

/// Options of `crease job list`.
#[derive(Clone, Debug, clap::Args)]
pub struct ListArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// Options of `crease job cancel`.
#[derive(Clone, Debug, clap::Args)]
pub struct CancelArgs {
    /// The job.
    #[command(flatten)]
    pub id: IdArgs,
    /// The admin token.
    #[command(flatten)]
    pub admin: AdminArgs,
}

/// Runs `crease job`.
pub fn run(args: &JobArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(async {
        match &args.action {
            JobAction::Submit(a) => submit(a).await,
            JobAction::Watch(a) => watch(a).await,
            JobAction::Get(a) => get(a).await,
            JobAction::List(a) => list(a).await,
            JobAction::Cancel(a) => cancel(a).await,
        }
    })
}

/// One line about a job.
fn describe(j: &v1::JobInfo) -> String {
    let level = if j.level == v1::Level::Detail as i32 {
        "detail"
    } else {
        "base"
    };
    let mut line = format!(
        "job {} ({}) on model {:?} at the {level} level: {} of {} frames, {} of {} chunks",
        j.job,
        JobState::from_wire(j.state).as_str(),
        j.model,
        j.frames_done,
        j.frames_total,
        j.chunks_done,
        j.chunks_total
    );
    if j.frames_per_second > 0.0 {
        line += &format!(", {:.1} frames/s", j.frames_per_second);
    }
    if j.encoding == v1::Encoding::Palette as i32 {
        line += ", palette";
    }
    if !j.name.is_empty() {
        line += &format!(", {:?}", j.name);
    }
    if !j.error.is_empty() {
        line += &format!(": {}", j.error);
    }
    line
}

async fn submit(args: &SubmitArgs) -> anyhow::Result<()> {
    if let Some(beta) = args.beta
        && !(beta.is_finite() && beta > 0.0)
    {
        bail!("--beta must be finite and > 0, got {beta}");
    }
    let mut client = args.server.connect().await?;
    let mut request = JobRequest {
        model: args.model.clone().unwrap_or_default(),
        detail: args.detail,
        beta: args.beta,
        refine: args.refine,
        skinning: args.skinning,
        name: args.name.clone(),
        take: args.take.clone(),
        encoding: args.encoding,
        retarget: None,
    };
    let job = match &args.model {
        Some(model) => {
            let info = get_model(&mut client, model)
                .await
                .with_context(|| format!("asking {} for model {model:?}", args.server.server))?;
            let (frames, source) = match &args.controls {
                Some(controls) => (
                    read_control_frames(controls, info.control_points.len())?,
                    controls.display().to_string(),
                ),
                None => {
                    // The recording's markers go raw, with the map: the server retargets
                    // them (`JobSpec.retarget`) as `crease retarget` does.
                    let path = args
                        .recording
                        .path()
                        .context("--controls, --tsv, --c3d or --take is needed")?
                        .display()
                        .to_string();
                    let map = args
                        .recording
                        .map
                        .as_ref()
                        .context("--map is needed with --tsv or --c3d")?;
                    let map_toml = std::fs::read_to_string(map)
                        .with_context(|| format!("reading the marker map {}", map.display()))?;
                    let (recording, rate) = (args.recording.clone(), args.rate);
                    let (recording, _) =
                        tokio::task::spawn_blocking(move || recording.read(rate)).await??;
                    request.retarget = Some(crease_proto::room::retarget(
                        map_toml,
                        recording.names.clone(),
                        recording.units.clone(),
                    ));
                    let frames = recording
                        .frames()
                        .map(|f| ControlFrame {
                            positions: f.positions.to_vec(),
                            valid: f.valid.to_vec(),
                        })
                        .collect();
                    (frames, path)
                }
            };
            submit_job(&mut client, &args.admin.admin_token, &request, &frames)
                .await
                .with_context(|| {
                    format!(
                        "submitting {} frames of {source} to {}",
                        frames.len(),
                        args.server.server
                    )
                })?
        }
        _ => {
            request.model.clear();
            let take = args.take.clone().unwrap_or_default();
            submit_job(&mut client, &args.admin.admin_token, &request, &[])
                .await
                .with_context(|| format!("submitting take {take:?} to {}", args.server.server))?
        }
    };
    eprintln!(
        "queued {} (crease job watch {} --server {})",
        describe(&job),
        job.job,
        args.server.server
    );
    println!("{}", job.job);
    Ok(())
}

async fn watch(args: &IdArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let mut updates = watch_job(&mut client, &args.job).await?;
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} frames, {per_sec}, ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let mut last = None;
    while let Some(update) = updates.next().await {
        let j = update.map_err(|s| anyhow::anyhow!("{}", s.message()))?;
        bar.set_length(j.frames_total);
        bar.set_position(j.frames_done);
        bar.set_message(format!(
            "job {} {}",
            j.job,
            JobState::from_wire(j.state).as_str()
        ));
        last = Some(j);
    }
    bar.finish_and_clear();
    let Some(j) = last else {
        bail!("job {}: the server sent no status", args.job);
    };
    println!("{}", describe(&j));
    match JobState::from_wire(j.state) {
        JobState::Done => Ok(()),
        JobState::Failed | JobState::Cancelled => bail!("job {} did not finish", j.job),
        JobState::Queued | JobState::Running => {
            bail!(
                "job {}: the server ended the watch before the job ended",
                j.job
            )
        }
    }
}

async fn get(args: &GetArgs) -> anyhow::Result<()> {
    if args.format == "gltf" && !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps must be > 0, got {}", args.fps);
    }
    let mut client = args.id.server.connect().await?;
    if args.format == "codec" {
        return get_codec(&mut client, args).await;
    }
    // The job's model and level say how many vertices a frame has.
    let job = watch_job(&mut client, &args.id.job)
        .await?
        .next()
        .await
        .context("the server sent no status")?
        .map_err(|s| anyhow::anyhow!("{}", s.message()))?;
    let total = job.frames_total as usize;
    let stream = job_result(&mut client, &job.job).await?;
    if job.encoding == v1::Encoding::Palette as i32 {
        let summary = get_palette(stream, args, total)
            .await
            .with_context(|| format!("fetching job {}", job.job))?;
        println!(
            "wrote {total} frames of job {} to {} ({summary})",
            job.job,
            args.out.display()
        );
        return Ok(());
    }
    let model = get_model(&mut client, &job.model)
        .await
        .with_context(|| format!("job {}", job.job))?;
    let (vertices, triangles) = if job.level == v1::Level::Detail as i32 {
        (model.detail_vertices, model.detail_triangles)
    } else {
        (model.base_vertices, model.base_triangles)
    };
    let vertices = vertices as usize;
    let summary = if args.format == "gltf" {
        gltf_export::check_animation_size(vertices, triangles as usize, total)
            .with_context(|| format!("writing {}", args.out.display()))?;
        let (triangles, frames) = super::remote_synth::collect_frames(stream, vertices, total)
            .await
            .with_context(|| format!("fetching job {}", job.job))?;
        let rest = &frames[..vertices.min(frames.len())];
        gltf_export::export_animation_glb(&args.out, &triangles, rest, &frames, args.fps)
            .with_context(|| format!("writing {}", args.out.display()))?;
        format!("{total} morph targets at {} frames/s", args.fps)
    } else {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
        super::remote_synth::write_frames(stream, &args.out, &args.format, vertices, total)
            .await
            .with_context(|| format!("fetching job {}", job.job))?
    };
    println!(
        "wrote {total} frames of job {} to {} ({summary})",
        job.job,
        args.out.display()
    );
    Ok(())
}

/// A palette job's result (`submit --encoding palette`): the palette header, then a palette
/// frame per control frame, decoded with the reference decoder (`core::codec::palette`).
/// `obj`/`ply`: each frame's drawn mesh (the detailed one at the detail level), as
/// `crease synth` writes them; `gltf`: the header's rest mesh and skin as a skinned glTF whose
/// joints carry every frame's decoded bones (`gltf_export::skinned_animation_to_glb`).
async fn get_palette<S>(mut stream: S, args: &GetArgs, total: usize) -> anyhow::Result<String>
where
    S: tokio_stream::Stream<Item = Result<v1::MeshFrame, tonic::Status>> + Unpin,
{
    use v1::mesh_frame::Body;
    let status = |s: tonic::Status| anyhow::anyhow!("{} ({:?})", s.message(), s.code());
    let header = match stream.next().await.transpose().map_err(status)? {
        Some(v1::MeshFrame {
            body: Some(Body::PaletteTopology(t)),
        }) => t,
        Some(_) => bail!("a palette job's result must start with its palette header"),
        None => bail!("the result ended before its palette header"),
    };
    let mut reader = PaletteReader::new(&header)?;
    let gltf = args.format == "gltf";
    if !gltf {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
    }
    let mut mesh = Mesh {
        positions: Vec::with_capacity(reader.vertex_count()),
        triangles: reader.synth().triangles().to_vec(),
    };
    let mut transforms = Vec::new();
    let (mut frames, mut bytes) = (0usize, 0u64);
    while let Some(message) = stream.next().await.transpose().map_err(status)? {
        let Some(Body::Frame(f)) = message.body else {
            bail!("frame {frames}: expected a palette frame");
        };
        if f.seq != frames as u64 {
            bail!("frame {frames}: the server sent frame seq {}", f.seq);
        }
        reader
            .decode(&f.data)
            .with_context(|| format!("decoding frame {frames}"))?;
        bytes += f.data.len() as u64;
        if gltf {
            transforms.extend_from_slice(&reader.frame().bones);
        } else {
            mesh.positions.clear();
            mesh.positions.extend_from_slice(reader.synth().output());
            let path = super::synth::frame_path(&args.out, frames, &args.format);
            mesh.write(&path)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        frames += 1;
    }
    if frames != total {
        bail!("the result ended after {frames} of {total} frames");
    }
    if !gltf {
        return Ok(format!(
            "{bytes} bytes of palette frames received, {:.1} bytes a frame",
            bytes as f64 / frames.max(1) as f64
        ));
    }
    let synth = reader.synth();
    let rig = Rig {
        rest: Mesh {
            positions: synth.rest().to_vec(),
            triangles: synth.base_triangles().to_vec(),
        },
        bone_count: transforms.len() / frames.max(1),
        skin: synth.skin().clone(),
        examples: Vec::new(),
        fit_rms: None,
    };
    let times: Vec<f32> = (0..frames).map(|f| f as f32 / args.fps).collect();
    let glb = gltf_export::skinned_animation_to_glb(&rig, "job", &times, &transforms)
        .with_context(|| format!("writing {}", args.out.display()))?;
    crease_core::model::file::write_atomic(&args.out, &glb)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if synth.detail().is_some() {
        eprintln!(
            "note: a skinned glTF carries the base layer; the detail layer is in --format obj|ply, or bake it with a vertices job and --format gltf"
        );
    }
    Ok(format!(
        "a skinned glTF of {} bones, {bytes} bytes of palette frames received",
        rig.bone_count
    ))
}

/// `get --format codec`: every message as it came, in `crease watch --record`'s file format.
async fn get_codec(
    client: &mut crease_proto::v1::crease_client::CreaseClient<tonic::transport::Channel>,
    args: &GetArgs,
) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut stream = job_result(client, &args.id.job).await?;
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut w = std::io::BufWriter::new(file);
    let (mut frames, mut bytes) = (0u64, 0u64);
    while let Some(message) = stream.next().await {
        let message = message.map_err(|s| anyhow::anyhow!("{}", s.message()))?;
        if matches!(message.body, Some(v1::mesh_frame::Body::Frame(_))) {
            frames += 1;
        }
        super::decode_stream::write_capture_message(&mut w, &message)
            .with_context(|| format!("writing {}", args.out.display()))?;
        bytes += 4 + prost::Message::encoded_len(&message) as u64;
    }
    w.flush()
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "wrote {frames} frames of job {} to {} ({bytes} bytes; crease decode-stream reads it)",
        args.id.job,
        args.out.display()
    );
    Ok(())
}

async fn list(args: &ListArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let jobs = list_jobs(&mut client).await?;
    if jobs.is_empty() {
        eprintln!("no jobs on {}", args.server.server);
    }
    for j in &jobs {
        println!("{}", describe(j));
    }
    Ok(())
}

async fn cancel(args: &CancelArgs) -> anyhow::Result<()> {
    let mut client = args.id.server.connect().await?;
    let j = cancel_job(&mut client, &args.admin.admin_token, &args.id.job).await?;
    println!("{}", describe(&j));
    Ok(())
}
