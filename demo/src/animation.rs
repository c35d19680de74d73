//! The demo room's animation: [`DemoAnimation`], the control points along a loop through the
//! named poses (hold, then an eased blend of the joint angles to the next pose), sampled once at
//! start and interpolated between samples at play time; and [`drive`], which publishes it into a
//! room at a fixed rate through the same path as a gRPC publisher
//! ([`crease_server::ingest::publish`]), until the server shuts down.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::skeleton::{HandPose, NamedPose};
use crease_hand::surface::Resolution;
use crease_server::AppState;
use crease_server::room::Room;

use crate::hand_model::DemoError;

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
        Self::of_poses(model, &NamedPose::ALL)
    }

    /// The animation of `model`'s control points through `poses` in a loop (as [`Self::new`]
    /// does through every named pose), on the base sweep hand.
    ///
    /// # Errors
    /// As [`Self::new`]; also with no poses.
    pub fn of_poses(model: &TrainedModel, poses: &[NamedPose]) -> Result<Self, DemoError> {
        if poses.is_empty() {
            return Err(DemoError::Hand(
                "an animation needs at least one pose".into(),
            ));
        }
        let rig = HandRig::build(Resolution::Base).map_err(|e| DemoError::Hand(e.to_string()))?;
        let n = rig.vertex_count();
        if let Some(c) = model.controls.iter().find(|c| c.vertex as usize >= n) {
            return Err(DemoError::Hand(format!(
                "control point {:?} is vertex {}, the hand has {n}",
                c.name, c.vertex
            )));
        }
        // The first pose first: the loop starts and ends there (the rest pose for `new`).
        let cycle: Vec<HandPose> = poses.iter().map(|&p| HandPose::named(p)).collect();
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

/// What [`drive`] plays into one actor of a room: the actor's name (`None`: a room opened
/// without actors, the frame's own fields), its animation, and whether its model is mirrored
/// across x (a left hand on the right-hand model: its control points are reflected too).
#[derive(Clone, Debug)]
pub struct ActorAnimation {
    /// The actor, in a room of several actors.
    pub actor: Option<String>,
    /// Its loop.
    pub animation: DemoAnimation,
    /// Whether the actor's model is the demo model mirrored across x.
    pub mirrored: bool,
}

impl ActorAnimation {
    /// A one-actor room's animation.
    pub fn single(animation: DemoAnimation) -> Vec<ActorAnimation> {
        vec![ActorAnimation {
            actor: None,
            animation,
            mirrored: false,
        }]
    }
}

/// How long the animation pauses after someone else published into the demo room (an animator
/// dragging a control point in the viewer), so the two do not fight over the hand.
const YIELD_S: f64 = 3.0;

/// How often a paused animation looks whether the room is watched again, besides waking on
/// every local subscription ([`Room::joins`]): another replica's viewers reach the room as
/// interest announcements only.
const IDLE_CHECK: Duration = Duration::from_millis(250);

/// Publishes `animation` into `room` at `rate_hz` until the server shuts down: the frames go
/// through [`crease_server::ingest::publish`] with the room's token, as a remote publisher's would
/// (metrics, acks, latency), one at a time; a tick missed while a frame was still being
/// predicted is skipped, not queued. When another publisher's frames arrive, the animation
/// pauses until none came for `YIELD_S` seconds, and resumes where it left off. While nobody
/// watches the room ([`Room::watched`]) it pauses too, ticking no timer, and resumes where
/// it left off the moment a viewer subscribes (issue 41): its first frame goes out at once,
/// and the viewer's first frame is a keyframe (the codec's on-demand keyframes).
pub async fn drive(
    state: Arc<AppState>,
    room: Arc<Room>,
    animations: Vec<ActorAnimation>,
    rate_hz: f64,
) {
    let period = Duration::from_secs_f64(1.0 / rate_hz.clamp(1.0, 1000.0));
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let closing = state.closing();
    tokio::pin!(closing);
    let token = room.token().unwrap_or_default().to_owned();
    let mut positions = Vec::new();
    // Animation time (it stands still while others publish), and what the room had counted
    // after our last frame.
    let (mut t, mut last_tick) = (0.0f64, Instant::now());
    let (mut ours, mut others_at) = (room.published(), None::<Instant>);
    let mut joins = room.joins();
    for seq in 0u64.. {
        tokio::select! {
            _ = tick.tick() => {}
            () = &mut closing => return,
        }
        if state.room(&room.id).is_none() {
            tracing::info!(room = %room.id, "demo room closed: the animation stops");
            return;
        }
        if !room.watched() {
            tracing::debug!(room = %room.id, "nobody watches: the animation pauses");
            joins.mark_unchanged();
            while !room.watched() {
                tokio::select! {
                    _ = joins.changed() => {}
                    () = tokio::time::sleep(IDLE_CHECK) => {}
                    () = &mut closing => return,
                }
                if state.room(&room.id).is_none() {
                    return;
                }
            }
            tracing::debug!(room = %room.id, "watched: the animation resumes");
            last_tick = Instant::now();
            tick.reset();
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
        let frame = frame_at(&room.id, seq, t, &animations, &mut positions);
        let outcome = crease_server::ingest::publish(&state, Some(&token), frame).await;
        ours = room.published();
        if let Err(e) = outcome {
            tracing::warn!(code = e.code().wire(), message = %e, "demo frame refused");
        }
    }
}

/// The control frame of animation time `t` into room `room`: one actor's points in the
/// frame's own fields, or every actor's in `actors` (reflected across x for mirrored ones).
fn frame_at(
    room: &str,
    seq: u64,
    t: f64,
    animations: &[ActorAnimation],
    positions: &mut Vec<f32>,
) -> crease_proto::v1::ControlFrame {
    use crease_proto::control::{actor_controls, control_frame_flat, with_actors};
    let now = now_us();
    let mut points = |a: &ActorAnimation| {
        a.animation.controls_at(t, positions);
        if a.mirrored {
            positions.chunks_exact_mut(3).for_each(|p| p[0] = -p[0]);
        }
        std::mem::take(positions)
    };
    match animations {
        [single] if single.actor.is_none() => control_frame_flat(room, seq, now, points(single)),
        _ => {
            let parts = animations
                .iter()
                .map(|a| {
                    let part = control_frame_flat(room, seq, now, points(a));
                    actor_controls(a.actor.as_deref().unwrap_or_default(), part)
                })
                .collect();
            with_actors(control_frame_flat(room, seq, now, Vec::new()), parts)
        }
    }
}

/// Microseconds since the Unix epoch.
fn now_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}
