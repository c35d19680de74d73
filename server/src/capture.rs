//! Capture input (issue 19): a retargeting room's raw markers become the model's control
//! points here, before the pipeline's filter and predictor. A room is opened with a
//! [`CaptureSpec`] (a marker map, HZY11 §7's correspondence, and the capture's marker names);
//! each frame's markers go through `crease_mocap`'s mixing, registration (a rigid transform
//! per frame, one scale fitted on the first frames) and gap filling (`Capture::read`).
//!
//! The publisher sends markers in the capture's units and frame; the control residual of its
//! acks is then reported in both the model's units and the capture's (divided by the fitted
//! scale).

use std::path::Path;

use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_mocap::map::{BoundMap, MarkerMap};
use crease_mocap::{Recording, Retarget};
use crease_proto::job::JobFrameError;
use crease_proto::{WireError, control_frame, read_marker_frame, v1};

/// Why a room's [`v1::Retarget`] was refused: names what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// Neither or both of `map_toml` and `map_name`, or a name with path characters.
    #[error("retarget: {0}")]
    Spec(String),
    /// The named map is not in the server's maps folder (or there is none).
    #[error("retarget.map_name: {0}")]
    NoMap(String),
    /// The map does not parse, or does not fit the markers or the model.
    #[error("retarget: {0}")]
    Map(String),
}

/// A retargeting room's map bound to its markers and model (module docs).
#[derive(Clone, Debug)]
pub struct CaptureSpec {
    /// As the opener sent it.
    wire: v1::Retarget,
    /// With the map's TOML filled in (what another replica rebuilds the room from).
    resolved: v1::Retarget,
    bound: BoundMap,
    rest: Vec<Vec3>,
}

impl CaptureSpec {
    /// Reads `wire`'s map (its TOML, or `map_name` from `maps`) and binds it to its markers and
    /// to `model`'s control points.
    ///
    /// # Errors
    /// [`CaptureError`] naming the field, the marker or the control point.
    pub fn new(
        wire: v1::Retarget,
        maps: Option<&Path>,
        model: &TrainedModel,
    ) -> Result<CaptureSpec, CaptureError> {
        let (source, text) = match (wire.map_toml.is_empty(), wire.map_name.is_empty()) {
            (false, true) => ("retarget.map_toml".to_owned(), wire.map_toml.clone()),
            (true, false) => {
                let name = &wire.map_name;
                if !name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
                    || name.starts_with('.')
                {
                    return Err(CaptureError::Spec(format!(
                        "map_name {name:?}: expected a file stem of A-Z, a-z, 0-9, '-', '_', '.'"
                    )));
                }
                let dir = maps.ok_or_else(|| {
                    CaptureError::NoMap(format!(
                        "{name:?}: this server has no maps folder (crease-server --maps DIR); send the map as map_toml"
                    ))
                })?;
                let path = dir.join(format!("{name}.toml"));
                let text = std::fs::read_to_string(&path).map_err(|e| {
                    CaptureError::NoMap(format!("{name:?}: {}: {e}", path.display()))
                })?;
                (path.display().to_string(), text)
            }
            _ => {
                return Err(CaptureError::Spec(
                    "give exactly one of map_toml and map_name".into(),
                ));
            }
        };
        if wire.markers.is_empty() {
            return Err(CaptureError::Spec(
                "markers: none declared (the capture's marker names, in frame order)".into(),
            ));
        }
        let map = MarkerMap::parse(Path::new(&source), &text)
            .map_err(|e| CaptureError::Map(e.to_string()))?;
        // The declared markers as a recording without frames: the map binds to its names.
        let names = Recording::new(
            wire.markers.clone(),
            0.0,
            wire.units.clone(),
            Vec::new(),
            Vec::new(),
        );
        let control_names: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
        let bound = map
            .bind(&names, &control_names)
            .map_err(|e| CaptureError::Map(format!("{source}: {e}")))?;
        // Every control point needs a source: an unmapped one would never be seen, and the
        // mesh would hold it at rest for the whole session.
        let unmapped: Vec<&str> = control_names
            .iter()
            .enumerate()
            .filter(|(i, _)| !bound.controls.iter().any(|(c, _)| c == i))
            .map(|(_, n)| n.as_str())
            .collect();
        if !unmapped.is_empty() {
            return Err(CaptureError::Map(format!(
                "{source}: [markers] gives no source for control point{} {} (every control point needs one; the model has {})",
                if unmapped.len() == 1 { "" } else { "s" },
                unmapped.join(", "),
                control_names.join(", ")
            )));
        }
        let rest = model
            .controls
            .iter()
            .map(|c| model.rig.rest.positions[c.vertex as usize])
            .collect();
        let resolved = crease_proto::room::resolved_retarget(&wire, text);
        Ok(CaptureSpec {
            wire,
            resolved,
            bound,
            rest,
        })
    }

    /// [`CaptureSpec::new`] on the blocking pool (it reads a map file and binds names), for
    /// the async callers: OpenRoom and a cluster's relays.
    ///
    /// # Errors
    /// [`CaptureError`]; a panicked task as [`CaptureError::Spec`].
    pub async fn build(
        wire: v1::Retarget,
        maps: Option<std::path::PathBuf>,
        model: std::sync::Arc<crate::registry::LoadedModel>,
    ) -> Result<CaptureSpec, CaptureError> {
        tokio::task::spawn_blocking(move || CaptureSpec::new(wire, maps.as_deref(), &model.model))
            .await
            .map_err(|e| CaptureError::Spec(format!("building the retarget: {e}")))?
    }

    /// The room's retarget as the wire carries it (`RoomInfo.retarget`).
    pub fn wire(&self) -> &v1::Retarget {
        &self.wire
    }

    /// The room's retarget with the map's TOML filled in: another replica of a cluster
    /// rebuilds the room from it without the owner's maps folder (`RoomEntry.retarget`).
    pub fn resolved(&self) -> &v1::Retarget {
        &self.resolved
    }

    /// Markers a frame carries.
    pub fn marker_count(&self) -> usize {
        self.wire.markers.len()
    }
    /// A whole recording's raw marker frames (a job's, `JobSpec.retarget`) retargeted as
    /// `crease retarget` does offline: the registration calibrated on the recording's first
    /// frames, then every frame through the map (mixing, registration, gap filling), into
    /// control frames numbered from 0 with each frame's capture time. Runs on the caller's
    /// thread (the blocking pool).
    ///
    /// # Errors
    /// The first frame whose markers do not fit (count, mask, a non-finite valid marker), by
    /// its index in the job.
    pub fn retarget_recording(
        &self,
        frames: &[v1::ControlFrame],
    ) -> Result<Vec<v1::ControlFrame>, JobFrameError> {
        let n = self.marker_count();
        let mut positions = Vec::with_capacity(frames.len() * n);
        let mut valid = Vec::with_capacity(frames.len() * n);
        let (mut markers, mut seen) = (vec![Vec3::ZERO; n], vec![false; n]);
        for (index, frame) in frames.iter().enumerate() {
            read_marker_frame(frame, &mut markers, &mut seen)
                .map_err(|error| JobFrameError { index, error })?;
            positions.extend_from_slice(&markers);
            valid.extend_from_slice(&seen);
        }
        let recording = Recording::new(
            self.wire.markers.clone(),
            0.0,
            self.wire.units.clone(),
            positions,
            valid,
        );
        let mut retarget = Retarget::new(self.bound.clone(), &self.rest);
        retarget.calibrate(&recording);
        let count = self.rest.len();
        let (mut controls, mut controls_valid) = (vec![Vec3::ZERO; count], vec![false; count]);
        let mut out = Vec::with_capacity(frames.len());
        for (k, (marker_frame, frame)) in recording.frames().zip(frames).enumerate() {
            retarget.frame(&marker_frame, &mut controls, &mut controls_valid);
            out.push(control_frame(
                "",
                k as u64,
                frame.capture_time_us,
                &controls,
                &controls_valid,
            ));
        }
        Ok(out)
    }
}

/// A retargeting room's per-frame state: the retarget (registration, gap offsets) and the
/// frame's markers (buffers reused, nothing allocated per frame).
#[derive(Debug)]
pub(crate) struct Capture {
    retarget: Retarget,
    markers: Vec<Vec3>,
    valid: Vec<bool>,
    index: usize,
}

impl Capture {
    /// The state of a room opened with `spec`.
    pub(crate) fn new(spec: &CaptureSpec) -> Capture {
        let n = spec.marker_count();
        Capture {
            retarget: Retarget::new(spec.bound.clone(), &spec.rest),
            markers: vec![Vec3::ZERO; n],
            valid: vec![false; n],
            index: 0,
        }
    }

    /// Checks `frame`'s markers without retargeting them (they are read again by
    /// [`Capture::read`] before any use).
    ///
    /// # Errors
    /// The frame's [`WireError`] (`read_marker_frame`).
    pub(crate) fn check(&mut self, frame: &v1::ControlFrame) -> Result<(), WireError> {
        read_marker_frame(frame, &mut self.markers, &mut self.valid)
    }

    /// Reads `frame`'s markers and retargets them into `controls` / `valid` (model order);
    /// returns the control points left invalid (missing, not estimated, or before the first
    /// registration).
    ///
    /// # Errors
    /// The frame's [`WireError`] (`read_marker_frame`); nothing changes then.
    pub(crate) fn read(
        &mut self,
        frame: &v1::ControlFrame,
        controls: &mut [Vec3],
        valid: &mut [bool],
    ) -> Result<usize, WireError> {
        read_marker_frame(frame, &mut self.markers, &mut self.valid)?;
        let marker_frame = crease_mocap::MarkerFrame {
            index: self.index,
            time: 0.0,
            positions: &self.markers,
            valid: &self.valid,
        };
        self.index += 1;
        self.retarget.frame(&marker_frame, controls, valid);
        Ok(valid.iter().filter(|v| !**v).count())
    }

    /// The current capture-to-model registration, and whether its scale is fixed
    /// (`crate::performer`).
    pub(crate) fn registration(&self) -> Option<(crease_mocap::register::Similarity, bool)> {
        let r = self.retarget.registration();
        r.transform().map(|t| (t, r.scale().is_some()))
    }

    /// The capture-to-model scale once the registration has one.
    pub(crate) fn scale(&self) -> Option<f32> {
        self.retarget
            .registration()
            .transform()
            .map(|t| t.scale)
            .or(self.retarget.registration().scale())
    }
}
