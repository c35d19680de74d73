//! A room's per-frame work: control points through the One Euro filter (mocap rooms), the
//! predictor, and one encoder per channel (`crate::fanout::Channel`: a level in an
//! encoding), once per frame for every subscriber of that channel.
//!
//! What a frame computes depends on who watches (issue 18):
//! - always the bone transforms (rotations, then the translation solve), and the base
//!   palette frame (a few hundred bytes, so a palette viewer that joins gets the current pose
//!   at once);
//! - the detail palette frame (the kernel vector `xi`, no synthesis) while someone watches it;
//! - the skinned base mesh and its vertex frame while someone watches vertex frames, or
//!   nobody watches palette frames (a vertex viewer that joins an idle room then gets the
//!   current pose at once, as before palettes existed);
//! - the detail layer's synthesis and its vertex frame while someone watches it.
//!
//! So with palette viewers alone a frame is prediction and translation solve only: no
//! skinning, no detail synthesis, no vertex encode. A channel the pipeline stops computing is
//! cleared, so that a viewer who comes later waits for its next frame instead of an old
//! pose. Everything here is blocking: building a pipeline factorises the predictor's sparse
//! system, and `Pipeline::run` predicts and encodes a frame (`Pipeline::frames` then hands
//! its frames to the pools); callers run them on the blocking pool (`spawn_blocking`), never
//! on the async executor.
//!
//! While the room records a take (`crate::takes`), the room records every frame that
//! predicted once it is through: the control frame, and each actor's controls used and bone
//! transforms (`Pipeline::pose`).
//!
//! Frames are handed to the fan-out as [`MeshUpdate`]s taken from a small pool per level
//! (`crate::frames`): after warm-up a frame allocates nothing, even while a slow subscriber
//! still holds an older frame.

use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use crease_core::codec::palette::{
    PaletteError, palette_lanes, palette_vertex_count, translation_box,
};
use crease_core::codec::{CodecError, FrameEncoder, FrameHeader, QuantBox, encode_indices};
use crease_core::glam::Vec3;
use crease_core::model::{ControlPoint, TrainedModel};
use crease_core::predictor::{FrameContext, PredictError, Predictor, Refinement};
use crease_core::runtime::filter::{OneEuro, OneEuroParams};
use crease_core::runtime::skin::{RigidTransform, Skinning};
use crease_proto::{Encoding, Level, WireError, read_control_frame, v1};
use prost::bytes::Bytes;

pub use crease_proto::room::{RoomOptions, StreamSettings};

use crate::capture::{Capture, CaptureSpec};
use crate::fanout::{Channel, Fanout};
use crate::frames::{FramePool, MeshUpdate};
use crate::registry::LoadedModel;

/// Quantisation box margin around the box of the model's training poses, as a fraction of its
/// largest side: new poses leave it a little (a position outside the box is clamped to it).
const BOX_MARGIN: f32 = 0.25;

/// What publishing one frame did (in a room of several actors: summed over its actors, the
/// worst residual and confidence, and each actor's part in `actors`).
#[derive(Clone, Debug, PartialEq)]
pub struct Published {
    /// Control points held (invalid or occluded).
    pub held: u32,
    /// Microseconds from arrival to the meshes being handed to the subscribers.
    pub latency_us: u32,
    /// RMS distance between the frame's valid control points (as received, before any
    /// filter) and the predicted mesh's control vertices, model units; 0 with none valid.
    pub control_rms: f32,
    /// Whether the detail layer was synthesised (someone, here or on another replica,
    /// watches it).
    pub detail: bool,
    /// A retargeting room's `control_rms` in the capture's units (0 before its scale is known,
    /// and in other rooms).
    pub control_rms_capture: f32,
    /// How far the frame lies from the model's training examples
    /// (`FrameContext::confidence`).
    pub confidence: f32,
    /// A room of several actors: each actor's part, in the room's actor order. Empty in a
    /// one-actor room.
    pub actors: Vec<ActorPublished>,
}

/// One actor's part of a [`Published`].
#[derive(Clone, Debug, PartialEq)]
pub struct ActorPublished {
    /// The actor's name.
    pub name: Arc<str>,
    /// The actor was missing from the frame and held its last pose.
    pub held: bool,
    /// Its frame (its own `actors` empty).
    pub published: Published,
}

/// Why a frame was not published (the room is unchanged but for the encoders' state).
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The control frame does not fit the model.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// The predictor refused the controls.
    #[error("prediction: {0}")]
    Predict(#[from] PredictError),
    /// A mesh could not be encoded (a server bug: the sizes are fixed at open).
    #[error("encoding: {0}")]
    Codec(#[from] CodecError),
    /// A palette frame could not be encoded (a non-finite transform: a server bug).
    #[error("palette encoding: {0}")]
    Palette(#[from] PaletteError),
    /// The pipeline panicked on this frame (a server bug; the room goes on).
    #[error("the pipeline panicked: {0}")]
    Panicked(String),
    /// A room of several actors: actor `actor`'s pipeline refused the frame (a wire error
    /// names the actor in its field instead: `PipelineError::in_actor`).
    #[error("actor {actor:?}: {error}")]
    Actor {
        /// The actor's name.
        actor: String,
        /// Why.
        error: Box<PipelineError>,
    },
}

impl PipelineError {
    /// This error as actor `actor`'s: a wire error's field becomes
    /// `actors["NAME"].FIELD`, anything else is wrapped in [`PipelineError::Actor`].
    pub(crate) fn in_actor(self, actor: &str) -> PipelineError {
        match self {
            PipelineError::Wire(mut e) => {
                e.field = format!("actors[{actor:?}].{}", e.field);
                PipelineError::Wire(e)
            }
            error => PipelineError::Actor {
                actor: actor.to_owned(),
                error: Box::new(error),
            },
        }
    }
}

/// Errors of building a pipeline.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// The model's meshes cannot be encoded (a degenerate box, too many vertices).
    #[error("frame encoder: {0}")]
    Codec(#[from] CodecError),
    /// The predictor could not be built (e.g. beta out of range).
    #[error(transparent)]
    Predictor(#[from] PredictError),
}

/// What a frame changes: the predictor's context, the filters, the encoders and pools.
struct State {
    ctx: FrameContext,
    controls: Vec<Vec3>,
    valid: Vec<bool>,
    /// The encoders, per channel (a palette stream is a codec stream of lanes,
    /// `core::codec::palette`).
    encoders: [FrameEncoder; Channel::COUNT],
    /// A palette frame's lanes (reused per frame).
    lanes: Vec<[u16; 4]>,
    /// The frame pools, per channel.
    pools: [FramePool; Channel::COUNT],
    /// A level's mesh in the streamed order (reused per frame).
    streamed: Vec<Vec3>,
    /// Each channel's encoded frame of the last run, and its header until it is handed to the
    /// pool ([`Pipeline::frames`]); buffers reused per frame.
    encoded: [Vec<u8>; Channel::COUNT],
    ready: [Option<FrameHeader>; Channel::COUNT],
    /// Whether the last run held the last pose (the actor was missing from the frame).
    held: bool,
    /// Where [`Pipeline::check`] reads a frame it only checks.
    scratch: (Vec<Vec3>, Vec<bool>),
    /// The last detail kernel vector (palette detail frames).
    xi: Vec<f32>,
    /// A retargeting room's capture state (issue 19), and the frame's retargeted points.
    capture: Option<Capture>,
    targets: Vec<Vec3>,
    /// One filter per control point (empty when the room does not filter).
    filters: Vec<OneEuro>,
    /// The previous frame's capture time and arrival, for the filter's time step.
    last_time: Option<(i64, Instant)>,
}

/// A room's filter, predictor and encoders (module docs).
pub struct Pipeline {
    model: Arc<LoadedModel>,
    predictor: Predictor,
    /// Each channel's quantisation box (a palette channel's: its translations').
    qboxes: [QuantBox; Channel::COUNT],
    /// Whether vertices stream in the model's spatial orders.
    spatial: bool,
    filter: Option<OneEuroParams>,
    state: Mutex<State>,
    /// Each level's index buffer, meshopt-encoded once on first need.
    indices: [OnceLock<Result<Bytes, CodecError>>; 2],
    /// A retargeting room's map and markers (issue 19).
    capture: Option<Arc<CaptureSpec>>,
}

impl std::fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("model", &self.model.name)
            .field("beta", &self.predictor.beta())
            .field("filter", &self.filter)
            .finish_non_exhaustive()
    }
}

/// Vertices of `channel`'s frames for `model`: a level's mesh, or a palette frame's lane
/// vertices (`core::codec::palette`).
pub(crate) fn frame_vertices(model: &TrainedModel, channel: Channel) -> usize {
    let xi = model
        .detail
        .as_ref()
        .map_or(0, |d| d.regressor.example_count());
    match (channel.level, channel.encoding) {
        (Level::Base, Encoding::Vertices) => model.rig.rest.vertex_count(),
        (Level::Detail, Encoding::Vertices) => model.detail_vertex_count().unwrap_or(0),
        (Level::Base, Encoding::Palette) => palette_vertex_count(model.rig.bone_count, 0),
        (Level::Detail, Encoding::Palette) => palette_vertex_count(model.rig.bone_count, xi),
    }
}

/// What a room's frame computes, decided once per frame from who watches (module docs) and
/// the same for every actor of the room ([`Demand::of`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Demand {
    /// The skinned base mesh and its vertex frame.
    pub base_vertices: bool,
    /// The detail layer's synthesis and its vertex frame.
    pub detail_vertices: bool,
    /// The detail palette frame (`xi`).
    pub detail_palette: bool,
    /// Channels whose next frame is a keyframe (a networked fan-out's far end lost one).
    pub keyframe: [bool; Channel::COUNT],
}

impl Demand {
    /// What `fanout`'s subscribers ask for, where the room's models have a detail layer
    /// (`has_detail`); asks the fan-out once for keyframes (it clears the request).
    pub(crate) fn of(fanout: &dyn Fanout, has_detail: bool) -> Demand {
        let watched = |level, encoding| fanout.interest(Channel::new(level, encoding));
        let detail_vertices = has_detail && watched(Level::Detail, Encoding::Vertices);
        let detail_palette = has_detail && watched(Level::Detail, Encoding::Palette);
        let base_vertices = watched(Level::Base, Encoding::Vertices)
            || !(watched(Level::Base, Encoding::Palette) || detail_palette);
        Demand {
            base_vertices,
            detail_vertices,
            detail_palette,
            keyframe: Channel::ALL.map(|c| fanout.wants_keyframe(c)),
        }
    }

    /// Whether `channel` is computed this frame (the base palette always is).
    pub(crate) fn computes(&self, channel: Channel) -> bool {
        match (channel.level, channel.encoding) {
            (Level::Base, Encoding::Palette) => true,
            (Level::Detail, Encoding::Palette) => self.detail_palette,
            (Level::Base, Encoding::Vertices) => self.base_vertices,
            (Level::Detail, Encoding::Vertices) => self.detail_vertices,
        }
    }
}

/// RMS over the valid control points of the distance between the target of point `i`
/// (`target(i)`: the frame's wire position, or a retargeting room's retargeted point) and the
/// predicted position of control vertex `i` (`predicted(vertex)`); 0 when none is valid.
fn control_residual(
    controls: &[ControlPoint],
    predicted: impl Fn(usize) -> Vec3,
    target: impl Fn(usize) -> Vec3,
    valid: &[bool],
) -> f32 {
    let (sum, n) = controls
        .iter()
        .zip(valid)
        .enumerate()
        .filter(|(_, (_, ok))| **ok)
        .fold((0.0f64, 0usize), |(s, n), (i, (c, _))| {
            let d = predicted(c.vertex as usize).distance_squared(target(i));
            (s + f64::from(d), n + 1)
        });
    if n == 0 {
        0.0
    } else {
        (sum / n as f64).sqrt() as f32
    }
}

impl Pipeline {
    /// Builds the predictor (a sparse factorisation, and the refinement's pass over the
    /// edges when on: blocking, run it on the blocking pool) and the encoders for `model`
    /// with `options`, streaming as `settings` says.
    ///
    /// # Errors
    /// [`BuildError`]: the predictor's or the encoder's.
    ///
    /// # Panics
    /// If `options.filter` is not [valid](OneEuroParams::is_valid) or `options.refine` does
    /// not [validate](Refinement::validate) (callers check what users send).
    pub fn build(
        model: Arc<LoadedModel>,
        options: RoomOptions,
        settings: StreamSettings,
    ) -> Result<Pipeline, BuildError> {
        let RoomOptions {
            beta,
            filter,
            refine,
            skinning,
        } = options;
        assert!(
            filter.is_none_or(|p| p.is_valid()),
            "invalid filter {filter:?}"
        );
        assert!(
            refine.is_none_or(|r| r.validate().is_ok()),
            "invalid refinement {refine:?}"
        );
        let mut predictor = Predictor::new(Arc::clone(&model.model), beta)?;
        predictor.set_refinement(refine);
        if let Some(skinning) = skinning {
            predictor.set_skinning(skinning);
        }
        let ctx = predictor.new_context();
        let n = model.model.controls.len();
        let (lo, hi) = model.pose_bounds;
        let base_qbox = QuantBox::from_bounds(lo, hi, BOX_MARGIN, settings.base_bits)?;
        let detail_qbox = QuantBox::from_bounds(lo, hi, BOX_MARGIN, settings.detail_bits)?;
        let encoder =
            |vertices, qbox| FrameEncoder::new(vertices, qbox, settings.keyframe_interval);
        let count = |c| frame_vertices(&model.model, c);
        let base = encoder(count(Channel::vertices(Level::Base)), base_qbox)?;
        let detail = encoder(count(Channel::vertices(Level::Detail)), detail_qbox)?;
        let palette_qbox = translation_box(
            base_qbox.min(),
            base_qbox.max(),
            &model.model.rig.rest.positions,
        )?;
        let base_palette = encoder(count(Channel::palette(Level::Base)), palette_qbox)?;
        let detail_palette = encoder(count(Channel::palette(Level::Detail)), palette_qbox)?;
        Ok(Pipeline {
            predictor,
            qboxes: [base_qbox, detail_qbox, palette_qbox, palette_qbox],
            spatial: settings.spatial_order,
            filter,
            state: Mutex::new(State {
                ctx,
                controls: vec![Vec3::ZERO; n],
                valid: vec![true; n],
                encoders: [base, detail, base_palette, detail_palette],
                pools: std::array::from_fn(|_| FramePool::default()),
                streamed: Vec::new(),
                encoded: std::array::from_fn(|_| Vec::new()),
                ready: [None; Channel::COUNT],
                held: false,
                scratch: (vec![Vec3::ZERO; n], vec![true; n]),
                xi: Vec::new(),
                lanes: Vec::new(),
                capture: None,
                targets: Vec::new(),
                filters: filter.map_or_else(Vec::new, |p| vec![OneEuro::new(p); n]),
                last_time: None,
            }),
            model,
            indices: [OnceLock::new(), OnceLock::new()],
            capture: None,
        })
    }

    /// Makes this a retargeting room (issue 19): its frames carry `spec`'s markers.
    pub(crate) fn set_capture(&mut self, spec: Arc<CaptureSpec>) {
        let state = self.state.get_mut().unwrap_or_else(|e| e.into_inner());
        state.capture = Some(Capture::new(&spec));
        self.capture = Some(spec);
    }

    /// A retargeting room's current capture-to-model registration and whether its scale is
    /// fixed (`crate::performer`); `None` before its first registered frame, and elsewhere.
    pub(crate) fn registration(&self) -> Option<(crease_mocap::register::Similarity, bool)> {
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.capture.as_ref().and_then(Capture::registration)
    }

    /// A retargeting room's map and markers.
    pub fn capture(&self) -> Option<&CaptureSpec> {
        self.capture.as_deref()
    }

    /// Hands the last frame's pose to `f`: the control points the prediction used and the
    /// bone transforms it predicted (what a take records, `crate::takes`).
    pub(crate) fn pose<T>(&self, f: impl FnOnce(&[Vec3], &[RigidTransform]) -> T) -> T {
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        f(state.ctx.controls(), state.ctx.transforms())
    }

    /// The control-point filter.
    pub fn filter(&self) -> Option<OneEuroParams> {
        self.filter
    }

    /// The translation-solve beta.
    pub fn beta(&self) -> f32 {
        self.predictor.beta()
    }

    /// The bone-level refinement, when on.
    pub fn refinement(&self) -> Option<Refinement> {
        self.predictor.refinement()
    }

    /// How the room skins (the option, else the model's default).
    pub fn skinning(&self) -> Skinning {
        self.predictor.skinning()
    }

    /// Whether the room can stream `encoding`: a palette stream ships the bone transforms and
    /// its client skins them with LBS (the browser viewer on its GPU, `crease watch`), so a DQS
    /// room refuses it rather than stream meshes other than its own.
    ///
    /// # Errors
    /// What is wrong, naming the encoding and the room's skinning.
    pub fn check_encoding(&self, encoding: Encoding) -> Result<(), String> {
        match (encoding, self.skinning()) {
            (Encoding::Palette, Skinning::Dqs) => Err(format!(
                "encoding: palette streams are skinned by the client with LBS, and this room skins with {}: subscribe with encoding vertices, or open the room with skinning lbs",
                Skinning::Dqs
            )),
            _ => Ok(()),
        }
    }

    /// The quantisation box of `level`'s frames.
    pub fn qbox(&self, level: Level) -> &QuantBox {
        &self.qboxes[Channel::vertices(level).index()]
    }

    /// Whether the model has a detail layer.
    pub fn has_detail(&self) -> bool {
        self.model.model.detail.is_some()
    }

    /// Streamed vertex `i` of `level` is model vertex `order[i]`; empty: the model's order.
    pub fn vertex_order(&self, level: Level) -> &[u32] {
        match level {
            Level::Base if self.spatial => &self.model.spatial().order,
            Level::Detail if self.spatial => self
                .model
                .detail_spatial()
                .map_or(&[], |s| s.order.as_slice()),
            Level::Base | Level::Detail => &[],
        }
    }

    /// Vertices of `level`'s mesh.
    pub fn vertex_count(&self, level: Level) -> usize {
        match level {
            Level::Base => self.model.model.rig.rest.vertex_count(),
            Level::Detail => self.model.model.detail_vertex_count().unwrap_or(0),
        }
    }

    /// The triangles of `level`'s mesh, in the streamed vertex order.
    pub fn triangles(&self, level: Level) -> &[[u32; 3]] {
        match level {
            Level::Base if self.spatial => &self.model.spatial().triangles,
            Level::Base => &self.model.model.rig.rest.triangles,
            Level::Detail => match self.model.detail_spatial() {
                Some(s) if self.spatial => &s.triangles,
                _ => self.predictor.detail_triangles().unwrap_or_default(),
            },
        }
    }

    /// `level`'s triangles through meshopt's index codec (encoded once, then shared).
    ///
    /// # Errors
    /// The codec's, if a triangle indexes past the vertex count.
    pub fn encoded_indices(&self, level: Level) -> Result<Bytes, CodecError> {
        self.indices[level as usize]
            .get_or_init(|| {
                let mut out = Vec::new();
                encode_indices(self.triangles(level), self.vertex_count(level), &mut out)
                    .map(|()| Bytes::from(out))
            })
            .clone()
    }

    /// Checks `frame` against this actor's model without changing anything: what
    /// [`Pipeline::run`] would refuse before predicting (a room of several actors checks
    /// every actor's part before any runs, so a bad frame changes nothing).
    ///
    /// # Errors
    /// The frame's [`WireError`] (count, non-finite valid point, mask length, markers).
    pub(crate) fn check(&self, frame: &v1::ControlFrame) -> Result<(), WireError> {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let state = &mut *guard;
        match &mut state.capture {
            Some(capture) => capture.check(frame),
            None => {
                let (controls, valid) = &mut state.scratch;
                read_control_frame(frame, controls, valid).map(|_| ())
            }
        }
    }

    /// Filters, predicts and encodes one control frame into each channel `demand` asks for,
    /// ready for [`Pipeline::frames`]; `None`: the actor was missing from its room's frame and
    /// holds its last pose (its controls as they were, the filter not stepped). Blocking: run
    /// it on the blocking pool. A bad frame changes nothing.
    ///
    /// # Errors
    /// [`PipelineError`]: the frame's [`WireError`] (count, non-finite valid point, mask
    /// length), the predictor's, the encoder's.
    pub(crate) fn run(
        &self,
        frame: Option<&v1::ControlFrame>,
        received: Instant,
        demand: &Demand,
    ) -> Result<Published, PipelineError> {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let state = &mut *guard;
        state.ready = [None; Channel::COUNT];
        let held = match frame {
            Some(frame) => {
                let held = self.read(state, frame, received)?;
                state.held = false;
                held
            }
            None => {
                state.held = true;
                state.valid.iter().filter(|v| !**v).count()
            }
        };
        self.predictor
            .predict_transforms(&mut state.ctx, &state.controls, Some(&state.valid))?;
        let detail_vertices = self.has_detail() && demand.detail_vertices;
        let detail_palette = self.has_detail() && demand.detail_palette;
        let base_vertices = demand.base_vertices;
        // A held actor has no new targets: no residual.
        let valid: &[bool] = if frame.is_some() { &state.valid } else { &[] };
        let targets = &state.targets;
        let target = |i: usize| match (&state.capture, frame) {
            (Some(_), _) => targets[i],
            (None, Some(frame)) => Vec3::from_slice(&frame.positions[3 * i..3 * i + 3]),
            (None, None) => Vec3::ZERO,
        };
        let controls = &self.model.model.controls;
        let control_rms = if base_vertices || detail_vertices {
            self.predictor.skin(&mut state.ctx)?;
            let predicted = state.ctx.positions();
            control_residual(controls, |v| predicted[v], target, valid)
        } else {
            // Only the control vertices are skinned (a palette-only room skins nothing else).
            let ctx = &state.ctx;
            control_residual(
                controls,
                |v| self.predictor.skin_vertex(ctx, v),
                target,
                valid,
            )
        };
        // In the capture's units: model units divided by the capture-to-model scale.
        let control_rms_capture = state
            .capture
            .as_ref()
            .and_then(Capture::scale)
            .filter(|s| *s > 0.0)
            .map_or(0.0, |s| control_rms / s);
        // The palette frames: the bones (always), and `xi` while the detail channel is watched.
        for level in Level::ALL {
            let channel = Channel::palette(level);
            let xi: &[f32] = match level {
                Level::Base => &[],
                Level::Detail if detail_palette => {
                    let xi = self.predictor.predict_detail_xi(&mut state.ctx)?;
                    state.xi.clear();
                    state.xi.extend_from_slice(xi);
                    &state.xi
                }
                Level::Detail => continue,
            };
            let qbox = &self.qboxes[channel.index()];
            palette_lanes(state.ctx.transforms(), xi, qbox, &mut state.lanes)?;
            let encoder = &mut state.encoders[channel.index()];
            if demand.keyframe[channel.index()] {
                encoder.force_keyframe();
            }
            let lanes = &state.lanes;
            let header = encoder.encode_lanes(
                |l| l.extend_from_slice(lanes),
                &mut state.encoded[channel.index()],
            )?;
            state.ready[channel.index()] = Some(header);
        }
        // The vertex frames.
        let encode = |state: &mut State, level: Level, detail: bool| -> Result<(), CodecError> {
            let channel = Channel::vertices(level);
            let order = self.vertex_order(level);
            let mesh = if detail {
                state.ctx.detail_positions()
            } else {
                state.ctx.positions()
            };
            state.streamed.clear();
            if order.is_empty() {
                state.streamed.extend_from_slice(mesh);
            } else {
                state
                    .streamed
                    .extend(order.iter().map(|&m| mesh[m as usize]));
            }
            let encoder = &mut state.encoders[channel.index()];
            if demand.keyframe[channel.index()] {
                encoder.force_keyframe();
            }
            let header =
                encoder.encode(&state.streamed, None, &mut state.encoded[channel.index()])?;
            state.ready[channel.index()] = Some(header);
            Ok(())
        };
        if base_vertices {
            encode(state, Level::Base, false)?;
        }
        let mut detail = detail_palette;
        if detail_vertices && self.predictor.predict_detail(&mut state.ctx).is_ok() {
            encode(state, Level::Detail, true)?;
            detail = true;
        }
        Ok(Published {
            held: held as u32,
            latency_us: received.elapsed().as_micros().min(u32::MAX as u128) as u32,
            control_rms,
            detail,
            control_rms_capture,
            confidence: state.ctx.confidence(),
            actors: Vec::new(),
        })
    }

    /// Reads `frame` into the controls (a retargeting room's markers retargeted to them) and
    /// steps the filter; returns the control points held.
    fn read(
        &self,
        state: &mut State,
        frame: &v1::ControlFrame,
        received: Instant,
    ) -> Result<usize, WireError> {
        let held = match &mut state.capture {
            Some(capture) => {
                let held = capture.read(frame, &mut state.controls, &mut state.valid)?;
                // The retargeted points, before the filter: what the residual measures.
                state.targets.clear();
                state.targets.extend_from_slice(&state.controls);
                held
            }
            None => read_control_frame(frame, &mut state.controls, &mut state.valid)?,
        };
        if !state.filters.is_empty() {
            // The time step: capture times when the publisher sends increasing ones, else
            // arrival times.
            let dt = match state.last_time {
                Some((t, _)) if frame.capture_time_us > t => {
                    (frame.capture_time_us - t) as f32 * 1e-6
                }
                Some((_, at)) => received.duration_since(at).as_secs_f32(),
                None => 0.0,
            };
            state.last_time = Some((frame.capture_time_us, received));
            for ((f, p), ok) in state
                .filters
                .iter_mut()
                .zip(state.controls.iter_mut())
                .zip(&state.valid)
            {
                if *ok {
                    *p = f.filter(*p, dt);
                } else {
                    f.reset();
                }
            }
        }
        Ok(held)
    }

    /// Hands each channel the last [`Pipeline::run`] encoded to its pool, once: `out[c]` is
    /// channel `c`'s frame to publish, `None` where it was not computed. `stamp` fills in the
    /// room's part (sequence number, times, the other actors' frames); the frame's `held` is
    /// this actor's.
    pub(crate) fn frames(
        &self,
        out: &mut [Option<Arc<MeshUpdate>>; Channel::COUNT],
        stamp: impl Fn(Channel, &mut MeshUpdate),
    ) {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let state = &mut *guard;
        for channel in Channel::ALL {
            let i = channel.index();
            out[i] = state.ready[i].take().map(|header| {
                let encoder = &state.encoders[i];
                state.pools[i].fill(*encoder.qbox(), &state.encoded[i], encoder.lanes(), |u| {
                    stamp(channel, u);
                    u.held = state.held;
                    u.set_codec_header(&header);
                })
            });
        }
    }
}
