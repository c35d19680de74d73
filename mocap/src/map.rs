//! Marker maps: which recording markers drive which control points of a model.
//!
//! ```toml
//! # The Qualisys glove recording onto a glove13 hand.
//! [registration]
//! points = ["hand_top", "hand_left", "hand_right"]  # control points that register the hand
//! calibration_frames = 100                          # frames the scale is fitted over
//! # scale = 0.001                                   # or a fixed scale (model units per file unit)
//!
//! [markers]              # control point = source
//! hand_top = "hand_top"                             # one marker
//! index_middle = ["RIFI", "RIFM"]                   # the mean of several markers
//! hand_left = { RHAN = 0.8, RIFI = 0.2 }            # a weighted mix (weights sum to 1)
//!
//! [gaps]
//! fill = "neighbour"     # or "hold" (module docs of `Retarget`)
//!
//! [bones]                # optional: a marker = its parent and the bone's length (file units)
//! RIFM = { parent = "RIFI", length = 42.0 }
//! ```
//!
//! Mixes serve HZY11 §7's first problem: markers rarely sit where a model's control points
//! are, and joint-centre data (C3D from a body tracker) has no marker on the back of the hand
//! at all. A source is valid in a frame only when every marker it mixes is.
//!
//! `[bones]` serves markers that are an estimated skeleton's joints rather than measured
//! points (a camera's hand landmarks, `crease_hand::mediapipe_map`): such an estimate gets
//! the joints' directions right more often than its bone lengths, which vary from frame to
//! frame more than a hand's can. Each frame is rebuilt from its roots out: every bone keeps
//! its direction in that frame and takes the map's length, so the mixes see one consistent
//! skeleton of the model's proportions whose joints only turn (`crate::retarget`). A bone
//! whose marker or parent is not seen keeps the marker as it is.
//!
//! [`MarkerMap::bind`] checks the map against a recording (markers by name) and a model
//! (control points by name) and gives a [`BoundMap`] of indices.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;
use serde::Deserialize;

use super::{MocapError, Recording};

/// How a missing marker is filled before it is sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GapFill {
    /// Send it invalid: the server holds its last valid position (in the hand frame, since the
    /// positions it receives are registered).
    Hold,
    /// Estimate it from its nearest valid neighbour (rest-pose distance) and the offset between
    /// the two when both were last seen; hold when no neighbour qualifies.
    #[default]
    Neighbour,
}

/// One source: a marker name, several (averaged), or weights per marker.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Source {
    /// One marker.
    One(String),
    /// The mean of these markers.
    Mean(Vec<String>),
    /// A weighted sum (weights must sum to 1).
    Weighted(BTreeMap<String, f32>),
}

impl Source {
    fn terms(&self) -> Vec<(String, f32)> {
        match self {
            Source::One(m) => vec![(m.clone(), 1.0)],
            Source::Mean(ms) => ms
                .iter()
                .map(|m| (m.clone(), 1.0 / ms.len().max(1) as f32))
                .collect(),
            Source::Weighted(w) => w.iter().map(|(m, x)| (m.clone(), *x)).collect(),
        }
    }
}

/// The `[registration]` table.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegistrationSpec {
    /// Control points (at least three, not collinear on the model) whose markers register the
    /// hand every frame.
    pub points: Vec<String>,
    /// Registrable frames the scale is fitted over.
    #[serde(default = "default_calibration")]
    pub calibration_frames: usize,
    /// A fixed scale instead of a fitted one.
    pub scale: Option<f32>,
}

fn default_calibration() -> usize {
    100
}

/// The `[gaps]` table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GapSpec {
    /// How missing markers are filled.
    #[serde(default)]
    pub fill: GapFill,
}

/// One entry of the `[bones]` table: the marker's parent and the bone's length.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoneSpec {
    /// The marker the bone starts at.
    pub parent: String,
    /// The bone's length, in the recording's units.
    pub length: f32,
}

/// A marker map file (module docs).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerMap {
    /// Registration.
    pub registration: RegistrationSpec,
    /// Control point name -> source.
    pub markers: BTreeMap<String, Source>,
    /// Gap filling.
    #[serde(default)]
    pub gaps: GapSpec,
    /// Marker name -> its bone (module docs); empty for measured markers.
    #[serde(default)]
    pub bones: BTreeMap<String, BoneSpec>,
}

/// One bound bone: `(marker, parent, length)`, marker indices in the recording.
pub type Bone = (usize, usize, f32);

/// A map bound to one recording and one model: indices instead of names.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundMap {
    /// Per mapped control point: its index in the model, and `(marker index, weight)` terms.
    pub controls: Vec<(usize, Vec<(usize, f32)>)>,
    /// Per registration point: the position in `controls` of its source.
    pub registration: Vec<usize>,
    /// The registration settings.
    pub spec: RegistrationSpec,
    /// Gap filling.
    pub gaps: GapFill,
    /// Model control points in total (a frame carries all of them).
    pub control_count: usize,
    /// The skeleton's bones, every parent's before its children's (module docs).
    pub bones: Vec<Bone>,
    /// Markers in the recording (what a frame carries).
    pub marker_count: usize,
}

impl MarkerMap {
    /// Parses a map from TOML text; `path` names the source in errors.
    pub fn parse(path: &Path, text: &str) -> Result<MarkerMap, MocapError> {
        toml::from_str(text).map_err(|e| MocapError::format(path, e.to_string()))
    }

    /// Reads a map file.
    pub fn read(path: impl AsRef<Path>) -> Result<MarkerMap, MocapError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| MocapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(path, &text)
    }

    /// The capture markers the map reads (its `[markers]` sources), each once: what a
    /// publisher must send a room that retargets through it.
    pub fn marker_names(&self) -> std::collections::BTreeSet<String> {
        self.markers
            .values()
            .flat_map(Source::terms)
            .map(|(m, _)| m)
            .collect()
    }

    /// Resolves names against `recording` and the model's control point names (in model order).
    pub fn bind(
        &self,
        recording: &Recording,
        control_names: &[String],
    ) -> Result<BoundMap, MocapError> {
        let err = |m: String| MocapError::Map(m);
        let mut controls = Vec::with_capacity(self.markers.len());
        for (cp, source) in &self.markers {
            let index = control_names.iter().position(|n| n == cp).ok_or_else(|| {
                err(format!(
                    "[markers] {cp}: the model has no control point {cp:?} (it has {})",
                    control_names.join(", ")
                ))
            })?;
            let terms = source.terms();
            if terms.is_empty() {
                return Err(err(format!("[markers] {cp}: no marker given")));
            }
            let total: f32 = terms.iter().map(|t| t.1).sum();
            if !terms.iter().all(|t| t.1.is_finite()) || (total - 1.0).abs() > 1e-3 {
                return Err(err(format!(
                    "[markers] {cp}: weights sum to {total}, expected 1"
                )));
            }
            let mut bound = Vec::with_capacity(terms.len());
            for (marker, w) in terms {
                let m = recording.marker(&marker).ok_or_else(|| {
                    err(format!(
                        "[markers] {cp}: the recording has no marker {marker:?} (it has {})",
                        recording.names.join(", ")
                    ))
                })?;
                bound.push((m, w));
            }
            controls.push((index, bound));
        }
        let spec = &self.registration;
        if spec.points.len() < 3 {
            return Err(err(format!(
                "[registration] points: {} given, at least 3 needed",
                spec.points.len()
            )));
        }
        if let Some(s) = spec.scale
            && !(s.is_finite() && s > 0.0)
        {
            return Err(err(format!(
                "[registration] scale: {s}, expected a positive number"
            )));
        }
        let mut registration = Vec::with_capacity(spec.points.len());
        for p in &spec.points {
            let at = self.markers.keys().position(|k| k == p).ok_or_else(|| {
                err(format!(
                    "[registration] points: {p:?} is not a control point in [markers]"
                ))
            })?;
            registration.push(at);
        }
        Ok(BoundMap {
            controls,
            registration,
            spec: spec.clone(),
            gaps: self.gaps.fill,
            control_count: control_names.len(),
            bones: self.bind_bones(recording)?,
            marker_count: recording.names.len(),
        })
    }

    /// The `[bones]` table as recording indices, parents first (a bone is placed once every
    /// bone above it is).
    fn bind_bones(&self, recording: &Recording) -> Result<Vec<Bone>, MocapError> {
        let index = |marker: &str, what: &str| {
            recording.marker(marker).ok_or_else(|| {
                MocapError::Map(format!(
                    "[bones] {what}: the recording has no marker {marker:?} (it has {})",
                    recording.names.join(", ")
                ))
            })
        };
        let mut pending = Vec::with_capacity(self.bones.len());
        for (marker, bone) in &self.bones {
            if !(bone.length.is_finite() && bone.length > 0.0) {
                return Err(MocapError::Map(format!(
                    "[bones] {marker}: length {}, expected a positive number",
                    bone.length
                )));
            }
            pending.push((
                index(marker, marker)?,
                index(&bone.parent, &format!("{marker}.parent"))?,
                bone.length,
            ));
        }
        // Parents first: take the bones whose parent is no pending bone's marker, repeatedly.
        let mut ordered = Vec::with_capacity(pending.len());
        while !pending.is_empty() {
            let (ready, rest): (Vec<Bone>, Vec<Bone>) = pending
                .iter()
                .partition(|(_, parent, _)| !pending.iter().any(|(m, _, _)| m == parent));
            if ready.is_empty() {
                let names: Vec<&str> = rest
                    .iter()
                    .map(|(m, _, _)| recording.names[*m].as_str())
                    .collect();
                return Err(MocapError::Map(format!(
                    "[bones]: {} form a loop (every marker's parent chain must end at a marker without a bone)",
                    names.join(", ")
                )));
            }
            ordered.extend(ready);
            pending = rest;
        }
        Ok(ordered)
    }
}

/// Rebuilds one frame's skeleton (module docs: `[bones]`): `out` is `positions`, but each
/// bone's marker (seen, as its parent) moved to its parent's rebuilt place plus the bone's
/// direction in `positions` at the bone's length. `bones` parents first, as bound.
pub fn rebuild_bones(bones: &[Bone], positions: &[Vec3], valid: &[bool], out: &mut [Vec3]) {
    out.copy_from_slice(positions);
    for &(marker, parent, length) in bones {
        if !(valid[marker] && valid[parent]) {
            continue;
        }
        let d = positions[marker] - positions[parent];
        let norm = d.length();
        if norm > 0.0 && norm.is_finite() {
            out[marker] = out[parent] + d * (length / norm);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn recording() -> Recording {
        let names: Vec<String> = ["S:A", "S:B", "S:C", "S:D"].map(String::from).to_vec();
        Recording::new(names, 60.0, "mm", vec![Vec3::ONE; 4], vec![true; 4])
    }

    const MAP: &str = r#"
[registration]
points = ["top", "left", "right"]
[markers]
top = "A"
left = ["A", "B"]
right = { C = 0.25, D = 0.75 }
[gaps]
fill = "hold"
"#;

    #[test]
    fn binds_names_mixes_and_registration() {
        let map = MarkerMap::parse(Path::new("m.toml"), MAP).unwrap();
        let names: Vec<String> = ["x", "right", "left", "top"].map(String::from).to_vec();
        let b = map.bind(&recording(), &names).unwrap();
        assert_eq!(b.gaps, GapFill::Hold);
        assert_eq!(b.control_count, 4);
        assert_eq!(b.spec.calibration_frames, 100);
        // BTreeMap order: left, right, top.
        assert_eq!(b.controls[0], (2, vec![(0, 0.5), (1, 0.5)]));
        assert_eq!(b.controls[1], (1, vec![(2, 0.25), (3, 0.75)]));
        assert_eq!(b.controls[2], (3, vec![(0, 1.0)]));
        assert_eq!(b.registration, vec![2, 0, 1]);
    }

    const BONES: &str = r#"
[bones]
D = { parent = "C", length = 2.0 }
B = { parent = "A", length = 1.0 }
C = { parent = "B", length = 3.0 }
"#;

    #[test]
    fn bones_bind_parents_first_and_rebuild_at_their_lengths() {
        let map = MarkerMap::parse(Path::new("m.toml"), &format!("{MAP}{BONES}")).unwrap();
        let names: Vec<String> = ["right", "left", "top"].map(String::from).to_vec();
        let b = map.bind(&recording(), &names).unwrap();
        // A chain A -> B -> C -> D, whatever the table's order.
        assert_eq!(b.bones, vec![(1, 0, 1.0), (2, 1, 3.0), (3, 2, 2.0)]);
        assert_eq!(b.marker_count, 4);
        // Directions kept, lengths the map's: an analytic chain of wrong lengths.
        let a = Vec3::new(1.0, 2.0, 3.0);
        let positions = [
            a,
            a + 5.0 * Vec3::X,
            a + 5.0 * Vec3::X + 0.5 * Vec3::Y,
            Vec3::ZERO,
        ];
        let mut out = [Vec3::NAN; 4];
        rebuild_bones(&b.bones, &positions, &[true, true, true, true], &mut out);
        assert_eq!(out[0], a, "a root stays");
        assert!(out[1].distance(a + Vec3::X) < 1e-6, "{}", out[1]);
        assert!(
            out[2].distance(a + Vec3::X + 3.0 * Vec3::Y) < 1e-6,
            "{}",
            out[2]
        );
        // D sat on A's origin side: its direction from C, at length 2.
        let dir = (positions[3] - positions[2]).normalize();
        assert!(out[3].distance(out[2] + 2.0 * dir) < 1e-5, "{}", out[3]);
        // A marker not seen, and its child: kept as they are.
        rebuild_bones(&b.bones, &positions, &[true, true, false, true], &mut out);
        assert_eq!(&out[2..], &positions[2..]);
    }

    #[test]
    fn errors_name_the_problem() {
        let names: Vec<String> = ["right", "left", "top"].map(String::from).to_vec();
        let e = |text: &str| {
            MarkerMap::parse(Path::new("m.toml"), text)
                .and_then(|m| m.bind(&recording(), &names))
                .unwrap_err()
                .to_string()
        };
        assert!(e(&MAP.replace("top = \"A\"", "top = \"Q\"")).contains("no marker \"Q\""));
        assert!(e(&MAP.replace("top = \"A\"", "tip = \"A\"")).contains("no control point \"tip\""));
        assert!(e(&MAP.replace("C = 0.25", "C = 0.5")).contains("weights sum to 1.25"));
        assert!(e(&MAP.replace("\"top\", ", "")).contains("2 given, at least 3"));
        assert!(e(&MAP.replace("fill = \"hold\"", "fill = \"guess\"")).contains("m.toml"));
        assert!(e(&MAP.replace("points", "pts")).contains("m.toml"));
        let bones = |b: &str| {
            e(&format!(
                "{MAP}{}",
                BONES.replace("B = { parent = \"A\", length = 1.0 }", b)
            ))
        };
        assert!(
            bones("B = { parent = \"Q\", length = 1.0 }")
                .contains("[bones] B.parent: the recording has no marker \"Q\"")
        );
        assert!(
            bones("B = { parent = \"A\", length = -1.0 }")
                .contains("[bones] B: length -1, expected a positive")
        );
        assert!(bones("B = { parent = \"D\", length = 1.0 }").contains("form a loop"));
    }
}
