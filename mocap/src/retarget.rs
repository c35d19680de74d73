//! [`Retarget`]: one recording frame in, one control frame (model order, validity per point)
//! out: mix markers by the map, register the hand, fill gaps.
//!
//! # Gaps (HZY11 §7: "markers drop out")
//!
//! A mapped control point whose markers are not all seen is filled according to the map:
//! - [`GapFill::Hold`]: sent invalid; the server's predictor holds its last valid position.
//!   Positions arrive registered, so that hold is in the hand frame: a finger whose marker
//!   vanishes keeps its pose relative to the back of the hand while the hand moves on.
//! - [`GapFill::Neighbour`] (the default): estimated as `p_n + (p_m - p_n)_last`, from the
//!   nearest mapped point `n` (rest-pose distance on the model, up to three tried in order) that
//!   is seen now and was seen together with `m` before; the two are assumed to move rigidly
//!   together while `m` is hidden. The estimate is sent as valid. When no neighbour qualifies,
//!   the point is sent invalid and held as above. BENCHMARKS.md ("Mocap gaps") compares the two
//!   on the Qualisys recording by hiding markers that were seen.
//!
//! A frame with fewer than three registration markers reuses the last transform; before any
//! frame has been registered, every point is sent invalid. No path produces a NaN: invalid
//! points are sent as zeros with the bit cleared.

use glam::Vec3;

use super::map::{BoundMap, GapFill, rebuild_bones};
use super::register::{Registered, Registration};
use super::{MarkerFrame, Recording};

/// Neighbours tried per point for [`GapFill::Neighbour`].
const NEIGHBOURS: usize = 3;

/// Counts over the frames a [`Retarget`] has processed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RetargetStats {
    /// Frames processed.
    pub frames: u64,
    /// Frames in which at least one mapped marker was missing.
    pub occluded_frames: u64,
    /// Mapped points missing, summed over frames.
    pub missing_points: u64,
    /// Of those, estimated from a neighbour.
    pub estimated_points: u64,
    /// Of those, sent invalid (held by the server).
    pub held_points: u64,
    /// Frames registered with the previous frame's transform.
    pub registration_held: u64,
    /// Frames before the first registration (all points sent invalid).
    pub unregistered: u64,
}

/// What happened to one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameReport {
    /// Registration outcome.
    pub registered: Registered,
    /// Mapped points missing in this frame.
    pub missing: usize,
    /// Of those, estimated.
    pub estimated: usize,
}

/// Map + registration + gap filling (module docs).
#[derive(Clone, Debug)]
pub struct Retarget {
    map: BoundMap,
    registration: Registration,
    /// Per mapped point (map order), neighbours in map order, nearest first.
    neighbours: Vec<Vec<usize>>,
    /// `offsets[i * NEIGHBOURS + k]`: point i minus its k-th neighbour, when last seen together.
    offsets: Vec<Option<Vec3>>,
    stats: RetargetStats,
    // Scratch, sized once.
    mixed: Vec<Vec3>,
    seen: Vec<bool>,
    reg_points: Vec<Vec3>,
    reg_seen: Vec<bool>,
    /// The frame's markers, rebuilt on the map's bones (empty without bones).
    rebuilt: Vec<Vec3>,
}

impl Retarget {
    /// A retarget for `map`, with `rest` the model's rest positions of all its control points
    /// (model order).
    ///
    /// # Panics
    /// If `rest` does not have one position per model control point.
    pub fn new(map: BoundMap, rest: &[Vec3]) -> Retarget {
        assert_eq!(
            rest.len(),
            map.control_count,
            "one rest position per control point"
        );
        let targets = map
            .registration
            .iter()
            .map(|&i| rest[map.controls[i].0])
            .collect();
        let registration = Registration::new(targets, map.spec.calibration_frames, map.spec.scale);
        let at = |i: usize| rest[map.controls[i].0];
        let n = map.controls.len();
        let neighbours = (0..n)
            .map(|i| {
                let mut others: Vec<usize> = (0..n).filter(|&j| j != i).collect();
                others.sort_by(|&a, &b| at(a).distance(at(i)).total_cmp(&at(b).distance(at(i))));
                others.truncate(NEIGHBOURS);
                others
            })
            .collect();
        let k = map.registration.len();
        Retarget {
            registration,
            neighbours,
            offsets: vec![None; n * NEIGHBOURS],
            stats: RetargetStats::default(),
            mixed: vec![Vec3::ZERO; n],
            seen: vec![false; n],
            reg_points: vec![Vec3::ZERO; k],
            reg_seen: vec![false; k],
            rebuilt: if map.bones.is_empty() {
                Vec::new()
            } else {
                vec![Vec3::ZERO; map.marker_count]
            },
            map,
        }
    }

    /// The counts so far.
    pub fn stats(&self) -> RetargetStats {
        self.stats
    }

    /// The registration (its scale and current transform).
    pub fn registration(&self) -> &Registration {
        &self.registration
    }

    /// Model control points a frame carries.
    pub fn control_count(&self) -> usize {
        self.map.control_count
    }

    /// Mixes the frame's markers (rebuilt on the map's bones, if it has any) into one point
    /// per mapped control point, and gathers the registration points' among them.
    fn mix(&mut self, frame: &MarkerFrame<'_>) {
        let positions = if self.map.bones.is_empty() {
            frame.positions
        } else {
            rebuild_bones(
                &self.map.bones,
                frame.positions,
                frame.valid,
                &mut self.rebuilt,
            );
            &self.rebuilt
        };
        for (i, (_, terms)) in self.map.controls.iter().enumerate() {
            let mut p = Vec3::ZERO;
            let mut ok = true;
            for &(m, w) in terms {
                ok &= frame.valid[m];
                p += w * positions[m];
            }
            self.mixed[i] = p;
            self.seen[i] = ok && p.is_finite();
        }
        for (k, &i) in self.map.registration.iter().enumerate() {
            self.reg_points[k] = self.mixed[i];
            self.reg_seen[k] = self.seen[i];
        }
    }

    /// Fits the scale over the recording's first registrable frames before playback, so
    /// every frame is registered with the final scale. Returns the frames used.
    pub fn calibrate(&mut self, recording: &Recording) -> usize {
        let want = self.map.spec.calibration_frames;
        let mut used = 0;
        for frame in recording.frames() {
            if used >= want || self.registration.scale().is_some() {
                break;
            }
            self.mix(&frame);
            used += usize::from(
                self.registration
                    .calibrate(&self.reg_points, &self.reg_seen),
            );
        }
        used
    }

    /// Retargets one frame into `positions` / `valid` (model order, one per control point).
    ///
    /// # Panics
    /// If the output slices do not have one entry per model control point.
    pub fn frame(
        &mut self,
        frame: &MarkerFrame<'_>,
        positions: &mut [Vec3],
        valid: &mut [bool],
    ) -> FrameReport {
        assert_eq!(positions.len(), self.map.control_count);
        assert_eq!(valid.len(), self.map.control_count);
        self.mix(frame);
        let registered = self.registration.update(&self.reg_points, &self.reg_seen);
        positions.fill(Vec3::ZERO);
        valid.fill(false);
        let missing = self.seen.iter().filter(|s| !**s).count();
        self.stats.frames += 1;
        self.stats.occluded_frames += u64::from(missing > 0);
        self.stats.missing_points += missing as u64;
        match registered {
            Registered::Held => self.stats.registration_held += 1,
            Registered::None => self.stats.unregistered += 1,
            Registered::Fitted => {}
        }
        let Some(t) = self.registration.transform() else {
            return FrameReport {
                registered,
                missing,
                estimated: 0,
            };
        };
        // Into the hand frame.
        for (p, s) in self.mixed.iter_mut().zip(&self.seen) {
            if *s {
                *p = t.apply(*p);
            }
        }
        let n = self.map.controls.len();
        let mut estimated = 0;
        for i in 0..n {
            let (cp, _) = self.map.controls[i];
            if self.seen[i] {
                positions[cp] = self.mixed[i];
                valid[cp] = true;
                for (k, &j) in self.neighbours[i].iter().enumerate() {
                    if self.seen[j] {
                        self.offsets[i * NEIGHBOURS + k] = Some(self.mixed[i] - self.mixed[j]);
                    }
                }
            } else if self.map.gaps == GapFill::Neighbour {
                let guess = self.neighbours[i].iter().enumerate().find_map(|(k, &j)| {
                    let offset = self.offsets[i * NEIGHBOURS + k]?;
                    self.seen[j].then(|| self.mixed[j] + offset)
                });
                if let Some(p) = guess.filter(|p| p.is_finite()) {
                    positions[cp] = p;
                    valid[cp] = true;
                    estimated += 1;
                }
            }
        }
        self.stats.estimated_points += estimated as u64;
        self.stats.held_points += (missing - estimated) as u64;
        FrameReport {
            registered,
            missing,
            estimated,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::map::MarkerMap;
    use super::super::register::Similarity;
    use super::*;
    use glam::Quat;
    use std::path::Path;

    const MAP: &str = r#"
[registration]
points = ["a", "b", "c"]
calibration_frames = 2
[markers]
a = "A"
b = "B"
c = "C"
tip = "T"
mid = "M"
"#;

    /// Model: five control points plus one unmapped; the recording sees them through a known
    /// similarity, with the finger points moving relative to the hand.
    #[test]
    fn registers_fills_gaps_and_never_emits_nan() {
        let names: Vec<String> = ["a", "b", "c", "mid", "tip", "unmapped"]
            .map(String::from)
            .to_vec();
        let rest = [
            Vec3::new(0.0, 0.05, 0.0),
            Vec3::new(-0.02, 0.0, 0.0),
            Vec3::new(0.02, 0.0, 0.0),
            Vec3::new(0.0, 0.09, 0.0),
            Vec3::new(0.0, 0.12, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
        ];
        let hand = Similarity {
            scale: 0.001,
            rotation: Quat::from_rotation_z(0.7) * Quat::from_rotation_x(0.3),
            translation: Vec3::new(0.3, -0.2, 0.1),
        };
        let to_rec = hand.inverse();
        let rec_names: Vec<String> = ["A", "B", "C", "M", "T"].map(String::from).to_vec();
        // Frame f: the finger (mid, tip) bends by f mm along z in the hand frame.
        let mut pos = Vec::new();
        let mut valid = Vec::new();
        let model_at = |f: usize| -> Vec<Vec3> {
            let bend = Vec3::new(0.0, 0.0, 0.001 * f as f32);
            vec![rest[0], rest[1], rest[2], rest[3] + bend, rest[4] + bend]
        };
        for f in 0..6 {
            for (k, p) in model_at(f).iter().enumerate() {
                pos.push(to_rec.apply(*p));
                // Frame 3: the tip is hidden. Frame 4: tip and mid hidden. Frame 5: a
                // registration marker hidden (transform held).
                valid.push(!matches!((f, k), (3, 4) | (4, 3) | (4, 4) | (5, 0)));
            }
        }
        let recording = Recording::new(rec_names, 100.0, "mm", pos, valid);
        let map = MarkerMap::parse(Path::new("m.toml"), MAP).unwrap();
        let bound = map.bind(&recording, &names).unwrap();
        let mut rt = Retarget::new(bound, &rest);
        assert_eq!(rt.calibrate(&recording), 2);
        assert!((rt.registration().scale().unwrap() - 0.001).abs() < 1e-7);
        let mut out = vec![Vec3::NAN; 6];
        let mut ok = vec![true; 6];
        for f in 0..6 {
            let report = rt.frame(&recording.frame(f), &mut out, &mut ok);
            assert!(out.iter().all(|p| p.is_finite()), "frame {f}: {out:?}");
            assert!(!ok[5], "unmapped points are invalid");
            let truth = model_at(f);
            match f {
                3 => {
                    // tip estimated from mid (its nearest neighbour): exact, since they move
                    // together.
                    assert_eq!(report.missing, 1);
                    assert_eq!(report.estimated, 1);
                    assert!(ok[4] && out[4].distance(truth[4]) < 1e-5, "{}", out[4]);
                }
                4 => {
                    // mid and tip both hidden: tip's neighbours are mid (hidden), then a/b/c
                    // (seen, offsets known): estimated from the hand, so it keeps the last
                    // offset to it (frame 2's bend, not frame 4's).
                    assert_eq!(report.missing, 2);
                    assert!(ok[4] && out[4].distance(model_at(2)[4]) < 1e-5);
                }
                5 => assert_eq!(report.registered, Registered::Held),
                _ => {
                    assert_eq!(report.registered, Registered::Fitted);
                    for k in 0..5 {
                        assert!(ok[k] && out[k].distance(truth[k]) < 1e-5, "{f} {k}");
                    }
                }
            }
        }
        let s = rt.stats();
        assert_eq!(s.frames, 6);
        assert_eq!(s.occluded_frames, 3);
        assert_eq!(s.registration_held, 1);
    }
}
