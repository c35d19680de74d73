//! `crease synth`: a batch of control frames in, one mesh per frame out: predicted here, or by a
//! server's `Synthesize` RPC with `--server` ([`super::remote_synth`], which builds on this
//! module's [`SynthArgs`] and [`frame_path`]; the crate root picks one of the two).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::mesh::Mesh;
use crease_core::model::{TrainedModel, gltf_export};
use crease_core::predictor::{Predictor, Refinement};

use crease_remote::control_file::read_control_frames;

/// Default most control frames per request (`--chunk-frames`): bounds one request's server
/// work and what a failed request throws away; ~160 KB of request for a 5-point model.
pub const CHUNK_FRAMES: usize = 2000;

/// Options of `crease synth`.
#[derive(Clone, Debug, clap::Args)]
#[command(group(
    clap::ArgGroup::new("output").required(true).multiple(true).args(["out", "gltf"])
))]
pub struct SynthArgs {
    /// Trained model (`crease train --out`); with `--server`, the NAME of a model the server
    /// hosts.
    #[arg(long, value_name = "FILE|NAME")]
    pub model: PathBuf,
    /// Synthesise on this crease server (gRPC, e.g. `http://127.0.0.1:50051`) instead of here.
    /// The frames are sent in requests of at most `--chunk-frames` frames (and 3 MiB, under the
    /// server's 4 MiB message limit) and written with continuous numbering; positions come back
    /// quantised to 16 bits in the model's pose box (a half-step error, given in the summary).
    #[arg(long, value_name = "URL")]
    pub server: Option<String>,
    /// With an `https://` --server: its CA certificate (PEM), e.g. the server's own self-signed
    /// certificate. Default: the Mozilla root certificates.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<PathBuf>,
    /// With `--server`: most control frames per request.
    #[arg(long, value_name = "N", default_value_t = CHUNK_FRAMES)]
    pub chunk_frames: usize,
    /// Control frames: CSV (one frame per line, x y z of every control point in model order;
    /// an empty or `nan` field marks an occluded point; `#` comments and a header line are
    /// skipped) or JSON (an array of frames, each an array of `[x, y, z]` or `null` per point,
    /// or of 3 numbers per point).
    #[arg(long, value_name = "FILE")]
    pub controls: PathBuf,
    /// Output folder (created); one mesh per frame, `frame_00000.obj` ... (`--out`, `--gltf`
    /// or both).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Also or instead write every frame into one animated glTF binary (.glb): the rest mesh
    /// with one morph target per frame and an animation showing frame `i` at `i / fps` s.
    /// With `--server`, the rest mesh is the server's prediction at the rest controls.
    #[arg(long, value_name = "FILE")]
    pub gltf: Option<PathBuf>,
    /// Frames per second of the `--gltf` animation.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
    /// Mesh format of the frames.
    #[arg(long, default_value = "obj", value_parser = ["obj", "ply"])]
    pub format: String,
    /// Control-point weight of the translation solve (default: the model's).
    #[arg(long)]
    pub beta: Option<f32>,
    /// Write the detailed meshes (the detail layer on the subdivided base, HZY11 eq. 4)
    /// instead of the base meshes; the model must have a detail layer.
    #[arg(long)]
    pub detail: bool,
    /// Refine every frame's bone rotations against the control points, `ITERATIONS,STRENGTH`
    /// (issue 20; e.g. `4,0.01`), or `off` for the regression alone. Default: 8,0.01 here (as
    /// rooms, issue 42), the server's with `--server`.
    #[arg(long, value_name = "ITERATIONS,STRENGTH|off", value_parser = crease_proto::room::parse_refine_flag)]
    pub refine: Option<crease_proto::room::RefineFlag>,
    /// How to skin: `lbs` or `dqs` (issue 22; default: the model's, `crease train
    /// --skinning`), locally or on the server.
    #[arg(long, value_name = "lbs|dqs")]
    pub skinning: Option<crease_core::runtime::skin::Skinning>,
}

impl SynthArgs {
    /// Refuses what neither local nor remote synthesis can do: nothing to write, a bad `--fps`.
    pub fn check(&self) -> anyhow::Result<()> {
        if self.out.is_none() && self.gltf.is_none() {
            bail!("nothing to write: give --out DIR (one mesh per frame), --gltf FILE, or both");
        }
        if self.gltf.is_some() && !(self.fps.is_finite() && self.fps > 0.0) {
            bail!("--fps must be > 0, got {}", self.fps);
        }
        Ok(())
    }
}

/// Runs `crease synth` here (the crate root hands `--server` to [`super::remote_synth::run`]).
pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    args.check()?;
    if let Some(server) = &args.server {
        bail!("--server {server}: local synthesis got a remote request (see remote_synth::run)");
    }
    let model = TrainedModel::load(&args.model)
        .with_context(|| format!("loading model {}", args.model.display()))?;
    let frames = read_control_frames(&args.controls, model.controls.len())?;
    if args.detail && model.detail.is_none() {
        bail!(
            "{}: --detail needs a model with a detail layer (train it on detailed examples: a manifest with `detailed`, or --base-vertices)",
            args.model.display()
        );
    }
    let mut predictor =
        Predictor::new(Arc::new(model), args.beta).context("preparing the predictor")?;
    predictor.set_refinement(args.refine.map_or(Some(Refinement::ROOM_DEFAULT), |f| f.0));
    if let Some(skinning) = args.skinning {
        predictor.set_skinning(skinning);
    }
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    }
    let mut ctx = predictor.new_context();
    // The output mesh at rest: the base rest mesh, or the detail layer at the rest pose.
    let rest = if args.detail {
        let controls = ctx.controls().to_vec();
        predictor.predict(&mut ctx, &controls, None)?;
        Mesh {
            positions: predictor.predict_detail(&mut ctx)?.to_vec(),
            triangles: predictor.detail_triangles().unwrap_or_default().to_vec(),
        }
    } else {
        predictor.model().rig.rest.clone()
    };
    // Every frame's positions, frame after frame, for the glTF; checked to fit one GLB before
    // any frame is computed.
    let mut animation = match &args.gltf {
        Some(path) => {
            gltf_export::check_animation_size(
                rest.vertex_count(),
                rest.triangles.len(),
                frames.len(),
            )
            .with_context(|| format!("writing {}", path.display()))?;
            Vec::with_capacity(frames.len() * rest.vertex_count())
        }
        None => Vec::new(),
    };
    let mut mesh = Mesh {
        positions: Vec::new(),
        triangles: rest.triangles.clone(),
    };
    let start = Instant::now();
    let mut compute = 0.0;
    let mut held = 0;
    for (i, f) in frames.iter().enumerate() {
        let t = Instant::now();
        predictor.predict(&mut ctx, &f.positions, Some(&f.valid))?;
        if args.detail {
            predictor.predict_detail(&mut ctx)?;
        }
        compute += t.elapsed().as_secs_f64();
        held += ctx.held_controls();
        let positions = if args.detail {
            ctx.detail_positions()
        } else {
            ctx.positions()
        };
        if args.gltf.is_some() {
            animation.extend_from_slice(positions);
        }
        if let Some(out) = &args.out {
            mesh.positions.clear();
            mesh.positions.extend_from_slice(positions);
            let path = frame_path(out, i, &args.format);
            mesh.write(&path)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    if let Some(path) = &args.gltf {
        gltf_export::export_animation_glb(
            path,
            &rest.triangles,
            &rest.positions,
            &animation,
            args.fps,
        )
        .with_context(|| format!("writing {}", path.display()))?;
    }
    let targets: Vec<String> = [args.out.as_ref(), args.gltf.as_ref()]
        .into_iter()
        .flatten()
        .map(|p| p.display().to_string())
        .collect();
    eprintln!(
        "wrote {} frames to {} in {:.2} s ({:.1} µs/frame synthesis; {held} occluded control values held)",
        frames.len(),
        targets.join(" and "),
        start.elapsed().as_secs_f64(),
        1e6 * compute / frames.len().max(1) as f64
    );
    Ok(())
}

/// The file of frame `i` in `out`: `frame_00000.obj`, ... (local and remote synthesis).
pub fn frame_path(out: &Path, i: usize, format: &str) -> PathBuf {
    out.join(format!("frame_{i:05}.{format}"))
}
