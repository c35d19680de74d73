//! The embedded default: what `crease-server` serves with no arguments (DESIGN.md, "The product
//! in one paragraph"). A hand model trained from the procedural sweep hand (LYK06, issue 4) at
//! two resolutions, so it has a detail layer (HZY11), and room `demo` driven by a built-in
//! animation through the named poses.
//!
//! - [`demo_model`]: the model, from the cache folder when a previous start left it there,
//!   else generated and trained (about 12 s on one core: 12 training poses at ~9.5K and ~180K
//!   vertices, 40 bones, the 15 dorsal landmarks of `crease handgen`'s `back` layout as control
//!   points, HZY11's local method, a two-level detail layer) and saved there.
//! - [`DemoAnimation`]: the control points along a loop through the named poses (hold, then an
//!   eased blend of the joint angles to the next pose), sampled once at start and interpolated
//!   between samples at play time.
//! - [`drive`]: publishes the animation into a room at a fixed rate through the same path as a
//!   gRPC publisher ([`crate::grpc::publish_one`]), until the server shuts down.
//!
//! This module is why `crease-server` depends on `crease-train` (ARCHITECTURE.md, "Rules").

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::mesh::subdivision::subdivided_vertex_count;
use crease_core::model::TrainedModel;
use crease_core::sweep::dataset::{Layout, dataset_poses, landmarks};
use crease_core::sweep::rig::{HandRig, Layers, RigScratch};
use crease_core::sweep::skeleton::{HandPose, NamedPose};
use crease_core::sweep::surface::Resolution;
use crease_proto::v1;
use crease_train::bones::FitOptions;
use crease_train::detail::layer::{DetailFrames, DetailOptions};
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

use crate::AppState;
use crate::room::Room;

/// The demo model's name (`GetModel`, `OpenRoom`).
pub const DEMO_MODEL: &str = "demo-hand";
/// The demo room's id.
pub const DEMO_ROOM: &str = "demo";
/// The demo room's beta: keyframe mode (HZY11 Fig. 11: about 3 for keyframing), so a dragged
/// control point is followed closely.
pub const DEMO_BETA: f32 = 3.0;
/// The cached model's file name. The version changes whenever the recipe below does, so a
/// stale cache is never served.
const CACHE_FILE: &str = "demo-hand-v1.crease";
/// Training poses: the flat rest pose, the nine other named poses, two sampled ones.
const TRAIN_POSES: usize = 12;
/// Seed of the pose sampler (as `crease handgen --seed 1`).
const SEED: u64 = 1;

/// Errors of building the demo.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The sweep hand could not be built.
    #[error("building the sweep hand: {0}")]
    Hand(String),
    /// Training failed.
    #[error("training the demo hand: {0}")]
    Train(String),
    /// The cache folder could not be written.
    #[error("caching the demo model in {path}: {message}")]
    Cache {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// The cache folder: `$CREASE_CACHE_DIR`, else `$XDG_CACHE_HOME/crease`, else
/// `$HOME/.cache/crease`, else `.crease-cache` in the working directory.
pub fn default_cache_dir() -> PathBuf {
    let env = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
    if let Some(dir) = env("CREASE_CACHE_DIR") {
        return PathBuf::from(dir);
    }
    if let Some(dir) = env("XDG_CACHE_HOME") {
        return PathBuf::from(dir).join("crease");
    }
    if let Some(home) = env("HOME") {
        return PathBuf::from(home).join(".cache").join("crease");
    }
    PathBuf::from(".crease-cache")
}

/// The demo model: loaded from `cache_dir` if a valid one is there, else built, trained and
/// saved there (atomically; a failed save is reported, the model still returned). `progress`
/// gets one line per stage.
///
/// # Errors
/// [`DemoError`] when the hand cannot be built or trained.
pub fn demo_model(
    cache_dir: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<TrainedModel, DemoError> {
    let path = cache_dir.join(CACHE_FILE);
    match TrainedModel::load(&path) {
        Ok(model) => {
            progress(&format!("loaded the demo model from {}", path.display()));
            return Ok(model);
        }
        Err(e) if path.exists() => {
            progress(&format!("{}: {e}; training it again", path.display()));
        }
        Err(_) => {}
    }
    let model = train_demo_model(progress)?;
    let saved = std::fs::create_dir_all(cache_dir)
        .map_err(|e| e.to_string())
        .and_then(|()| model.save(&path).map_err(|e| e.to_string()));
    match saved {
        Ok(()) => progress(&format!("cached the demo model in {}", path.display())),
        Err(message) => progress(&format!(
            "{}",
            DemoError::Cache {
                path: path.clone(),
                message
            }
        )),
    }
    Ok(model)
}

/// Generates the training poses at both resolutions and trains the model (module docs).
fn train_demo_model(progress: &mut dyn FnMut(&str)) -> Result<TrainedModel, DemoError> {
    let start = Instant::now();
    let mut say =
        |what: &str| progress(&format!("[{:5.1}s] {what}", start.elapsed().as_secs_f32()));
    let (poses, _) = dataset_poses(TRAIN_POSES, 0, SEED);
    say("building the sweep hand (base and detailed)");
    let base = HandRig::build(Resolution::Base).map_err(|e| DemoError::Hand(e.to_string()))?;
    let detailed =
        HandRig::build(Resolution::Detailed).map_err(|e| DemoError::Hand(e.to_string()))?;
    say(&format!(
        "posing {} training hands ({} and {} vertices)",
        poses.len(),
        base.vertex_count(),
        detailed.vertex_count()
    ));
    let pose_all = |rig: &HandRig| -> Vec<Vec<Vec3>> {
        let mut scratch = RigScratch::new();
        poses
            .iter()
            .map(|p| {
                let mut out = vec![Vec3::ZERO; rig.vertex_count()];
                rig.deform(&p.pose, Layers::default(), &mut scratch, &mut out);
                out
            })
            .collect()
    };
    let base_frames = pose_all(&base);
    let detailed_frames = pose_all(&detailed);
    // The rest pose is the first training pose (flat), as in `crease handgen`'s manifests.
    let rest = Mesh {
        positions: base_frames[0].clone(),
        triangles: base.rest().triangles.clone(),
    };
    let marks = landmarks(
        Layout::Back,
        base.skeleton(),
        base.rest(),
        &base.rest().vertex_normals(),
    );
    let want = detailed.vertex_count() as f64;
    let levels = (1..=3u32)
        .min_by(|&a, &b| {
            let off = |l| (subdivided_vertex_count(&rest, l) as f64 / want).ln().abs();
            off(a).total_cmp(&off(b))
        })
        .unwrap_or(1);
    let options = TrainOptions {
        fit: FitOptions {
            bones: 40,
            max_influences: 4,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(marks.iter().map(|m| m.vertex).collect()),
        control_names: Some(marks.iter().map(|m| m.name.clone()).collect()),
        regress: RegressOptions {
            method: Method::Local,
            ..RegressOptions::default()
        },
        detail: DetailOptions {
            levels,
            ..DetailOptions::default()
        },
        ..TrainOptions::default()
    };
    say(&format!(
        "training: 40 bones, {} control points, local regressors, {levels}-level detail layer",
        marks.len()
    ));
    let frames: Vec<&[Vec3]> = base_frames.iter().map(Vec::as_slice).collect();
    let detail: Vec<&[Vec3]> = detailed_frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = poses.iter().map(|p| p.name.clone()).collect();
    let (model, _) = pipeline::train_layers(
        TrainInput {
            rest: &rest,
            frames: &frames,
            names: &names,
        },
        Some(DetailFrames {
            frames: &detail,
            triangles: &detailed.rest().triangles,
        }),
        &options,
        &mut |_| {},
        &mut |_, _| {},
    )
    .map_err(|e| DemoError::Train(e.to_string()))?;
    say("trained");
    Ok(model)
}

/// Seconds a named pose is held.
const HOLD_S: f32 = 0.7;
/// Seconds of the blend to the next pose.
const BLEND_S: f32 = 1.1;
/// Samples of the control points per second of animation (interpolated between at play time).
const SAMPLES_PER_S: f32 = 20.0;

/// The demo's control points along a loop through the named poses (module docs).
#[derive(Clone, Debug)]
pub struct DemoAnimation {
    /// Control-point positions per sample, `SAMPLES_PER_S` samples per second, looping.
    samples: Vec<Vec<Vec3>>,
}

impl DemoAnimation {
    /// The animation of `model`'s control points on the base sweep hand. The control points
    /// must be vertices of the base hand (the demo model's are).
    ///
    /// # Errors
    /// [`DemoError::Hand`] if the hand cannot be built or a control point is not one of its
    /// vertices.
    pub fn new(model: &TrainedModel) -> Result<Self, DemoError> {
        let rig = HandRig::build(Resolution::Base).map_err(|e| DemoError::Hand(e.to_string()))?;
        let n = rig.vertex_count();
        if let Some(c) = model.controls.iter().find(|c| c.vertex as usize >= n) {
            return Err(DemoError::Hand(format!(
                "control point {:?} is vertex {}, the hand has {n}",
                c.name, c.vertex
            )));
        }
        // Flat first: the loop starts and ends at the rest pose.
        let cycle: Vec<HandPose> = NamedPose::ALL.iter().map(|&p| HandPose::named(p)).collect();
        let per_pose = ((HOLD_S + BLEND_S) * SAMPLES_PER_S).round() as usize;
        let hold = (HOLD_S * SAMPLES_PER_S).round() as usize;
        let mut scratch = RigScratch::new();
        let mut mesh = vec![Vec3::ZERO; n];
        let mut samples = Vec::with_capacity(cycle.len() * per_pose);
        for (k, pose) in cycle.iter().enumerate() {
            let next = &cycle[(k + 1) % cycle.len()];
            for s in 0..per_pose {
                let t = s.saturating_sub(hold) as f32 / (per_pose - hold) as f32;
                // Smoothstep: starts and stops at rest in joint space.
                let eased = t * t * (3.0 - 2.0 * t);
                let posed = pose.lerp(next, eased);
                rig.deform(&posed, Layers::default(), &mut scratch, &mut mesh);
                samples.push(
                    model
                        .controls
                        .iter()
                        .map(|c| mesh[c.vertex as usize])
                        .collect(),
                );
            }
        }
        Ok(Self { samples })
    }

    /// Length of one loop.
    pub fn period(&self) -> Duration {
        Duration::from_secs_f32(self.samples.len() as f32 / SAMPLES_PER_S)
    }

    /// The control points at `t` seconds (looping), linearly interpolated between samples,
    /// written as flat `x, y, z` into `out` (cleared first).
    pub fn controls_at(&self, t: f64, out: &mut Vec<f32>) {
        out.clear();
        let n = self.samples.len();
        let x = (t * f64::from(SAMPLES_PER_S)).rem_euclid(n as f64);
        let i = (x as usize).min(n - 1);
        let f = (x - i as f64) as f32;
        let (a, b) = (&self.samples[i], &self.samples[(i + 1) % n]);
        out.extend(a.iter().zip(b).flat_map(|(p, q)| p.lerp(*q, f).to_array()));
    }
}

/// How long the animation pauses after someone else published into the demo room (an animator
/// dragging a control point in the viewer), so the two do not fight over the hand.
const YIELD_S: f64 = 3.0;

/// Publishes `animation` into `room` at `rate_hz` until the server shuts down: the frames go
/// through [`crate::grpc::publish_one`] with the room's token, as a remote publisher's would
/// (metrics, acks, latency), one at a time; a tick missed while a frame was still being
/// predicted is skipped, not queued. When another publisher's frames arrive, the animation
/// pauses until none came for `YIELD_S` seconds, and resumes where it left off.
pub async fn drive(state: Arc<AppState>, room: Arc<Room>, animation: DemoAnimation, rate_hz: f64) {
    let period = Duration::from_secs_f64(1.0 / rate_hz.clamp(1.0, 1000.0));
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let closing = state.closing();
    tokio::pin!(closing);
    let token = room.token().to_owned();
    let mut positions = Vec::new();
    // Animation time (it stands still while others publish), and what the room had counted
    // after our last frame.
    let (mut t, mut last_tick) = (0.0f64, Instant::now());
    let (mut ours, mut others_at) = (room.published(), None::<Instant>);
    for seq in 0u64.. {
        tokio::select! {
            _ = tick.tick() => {}
            () = &mut closing => return,
        }
        if state.room(&room.id).is_none() {
            tracing::info!(room = %room.id, "demo room closed: the animation stops");
            return;
        }
        let now = Instant::now();
        if room.published() > ours {
            others_at = Some(now);
            ours = room.published();
        }
        if others_at.is_some_and(|at| now.duration_since(at).as_secs_f64() < YIELD_S) {
            last_tick = now;
            continue;
        }
        t += now.duration_since(last_tick).as_secs_f64();
        last_tick = now;
        animation.controls_at(t, &mut positions);
        let frame = v1::ControlFrame {
            room: room.id.clone(),
            seq,
            capture_time_us: now_us(),
            positions: std::mem::take(&mut positions),
            valid: Vec::new(),
        };
        let ack = crate::grpc::publish_one(&state, Some(&token), frame).await;
        ours = room.published();
        if let Some(e) = ack.error {
            tracing::warn!(code = e.code, message = %e.message, "demo frame refused");
        }
    }
}

/// Microseconds since the Unix epoch.
fn now_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}
