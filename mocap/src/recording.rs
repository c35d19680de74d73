//! A marker recording in memory ([`Recording`], one frame of it a [`MarkerFrame`]) and the
//! crate's error ([`MocapError`]); the readers ([`crate::tsv`], [`crate::c3d`]) build it, and
//! `Recording::read` (in `lib.rs`) picks the reader by extension.

use std::path::{Path, PathBuf};

use glam::Vec3;

/// An error reading a recording or a marker map. Messages name the file, the line or field,
/// and what was expected versus found.
#[derive(Debug, thiserror::Error)]
pub enum MocapError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file's content is not what its format requires.
    #[error("{}: {message}", path.display())]
    Format {
        /// The file (and line, for text formats, in the message).
        path: PathBuf,
        /// What was wrong, where, expected versus found.
        message: String,
    },
    /// A marker map names something the recording or the model lacks, or is inconsistent.
    #[error("marker map: {0}")]
    Map(String),
}

impl MocapError {
    pub(crate) fn format(path: &Path, message: impl Into<String>) -> Self {
        MocapError::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// A marker recording: `frames × markers` positions with a validity flag each.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// Marker names as the file spells them (C3D labels keep their subject prefix, e.g.
    /// `Human4:RTTI`; [`Recording::marker`] also finds them without it).
    pub names: Vec<String>,
    /// Frames per second.
    pub rate_hz: f64,
    /// Length unit of the positions as the file states it (`mm`).
    pub units: String,
    /// Positions, frame-major: `positions[f * markers + m]`. Invalid samples hold zero.
    positions: Vec<Vec3>,
    /// Validity per sample, same layout.
    valid: Vec<bool>,
}

/// One frame of a [`Recording`].
#[derive(Clone, Copy, Debug)]
pub struct MarkerFrame<'a> {
    /// Frame index in the recording (0-based).
    pub index: usize,
    /// Seconds since the first frame.
    pub time: f64,
    /// One position per marker (zero where invalid).
    pub positions: &'a [Vec3],
    /// Whether each marker was seen in this frame.
    pub valid: &'a [bool],
}

impl Recording {
    /// A recording from frame-major samples; a sample that is invalid or not finite is stored
    /// as invalid with a zero position.
    ///
    /// # Panics
    /// If the sample counts are not `frames × names.len()` for one whole number of frames.
    pub fn new(
        names: Vec<String>,
        rate_hz: f64,
        units: impl Into<String>,
        mut positions: Vec<Vec3>,
        mut valid: Vec<bool>,
    ) -> Recording {
        let n = names.len().max(1);
        assert_eq!(positions.len(), valid.len(), "one flag per sample");
        assert_eq!(positions.len() % n, 0, "whole frames");
        for (p, v) in positions.iter_mut().zip(valid.iter_mut()) {
            if !*v || !p.is_finite() {
                *v = false;
                *p = Vec3::ZERO;
            }
        }
        Recording {
            names,
            rate_hz,
            units: units.into(),
            positions,
            valid,
        }
    }

    /// Number of markers.
    pub fn marker_count(&self) -> usize {
        self.names.len()
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.positions
            .len()
            .checked_div(self.names.len())
            .unwrap_or(0)
    }

    /// Duration from the first to the last frame, seconds.
    pub fn duration(&self) -> f64 {
        self.frame_count().saturating_sub(1) as f64 / self.rate_hz
    }

    /// Index of the marker called `name`: an exact match, or else the one label whose part
    /// after the last `:` (a C3D subject prefix) is `name`.
    pub fn marker(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name).or_else(|| {
            let mut hits = self
                .names
                .iter()
                .enumerate()
                .filter(|(_, n)| n.rsplit(':').next() == Some(name));
            match (hits.next(), hits.next()) {
                (Some((i, _)), None) => Some(i),
                _ => None,
            }
        })
    }

    /// Frame `index`.
    ///
    /// # Panics
    /// If `index >= frame_count()`.
    pub fn frame(&self, index: usize) -> MarkerFrame<'_> {
        let n = self.names.len();
        MarkerFrame {
            index,
            time: index as f64 / self.rate_hz,
            positions: &self.positions[index * n..(index + 1) * n],
            valid: &self.valid[index * n..(index + 1) * n],
        }
    }

    /// The frames in order.
    pub fn frames(&self) -> impl ExactSizeIterator<Item = MarkerFrame<'_>> + '_ {
        (0..self.frame_count()).map(|i| self.frame(i))
    }

    /// Invalid samples per marker.
    pub fn gaps_per_marker(&self) -> Vec<usize> {
        let n = self.names.len();
        let mut out = vec![0; n];
        for (i, v) in self.valid.iter().enumerate() {
            if !v {
                out[i % n] += 1;
            }
        }
        out
    }

    /// The recording linearly resampled to `rate_hz` over the same time span. A marker is valid
    /// at a new frame when both source frames around it are (or the new time falls exactly on
    /// a valid source frame); otherwise it is invalid. Resampling never invents data across a
    /// gap.
    pub fn resampled(&self, rate_hz: f64) -> Recording {
        assert!(
            rate_hz.is_finite() && rate_hz > 0.0,
            "rate must be positive"
        );
        let n = self.names.len();
        let frames = (self.duration() * rate_hz + 1e-9).floor() as usize + 1;
        let frames = if self.frame_count() == 0 { 0 } else { frames };
        let mut positions = Vec::with_capacity(frames * n);
        let mut valid = Vec::with_capacity(frames * n);
        let last = self.frame_count().saturating_sub(1);
        for k in 0..frames {
            let s = k as f64 * self.rate_hz / rate_hz;
            // A new frame within 1e-6 frames of a source frame is that frame.
            let exact = (s - s.round()).abs() < 1e-6;
            let s = if exact { s.round() } else { s };
            let i = (s.floor() as usize).min(last);
            let j = (i + 1).min(last);
            let w = (s - i as f64).clamp(0.0, 1.0) as f32;
            let (a, b) = (self.frame(i), self.frame(j));
            for m in 0..n {
                let ok = a.valid[m] && (exact || b.valid[m]);
                valid.push(ok);
                positions.push(if !ok {
                    Vec3::ZERO
                } else if exact {
                    a.positions[m]
                } else {
                    a.positions[m].lerp(b.positions[m], w)
                });
            }
        }
        Recording::new(
            self.names.clone(),
            rate_hz,
            self.units.clone(),
            positions,
            valid,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> Recording {
        // Two markers, 5 frames at 100 Hz: marker 0 moves 1 unit/frame in x, marker 1 has a
        // gap at frame 2.
        let mut p = Vec::new();
        let mut v = Vec::new();
        for f in 0..5 {
            p.push(Vec3::new(f as f32, 0.0, 0.0));
            v.push(true);
            p.push(Vec3::new(0.0, f as f32, 0.0));
            v.push(f != 2);
        }
        Recording::new(vec!["a".into(), "s:b".into()], 100.0, "mm", p, v)
    }

    #[test]
    fn frames_names_and_gaps() {
        let r = ramp();
        assert_eq!(r.frame_count(), 5);
        assert_eq!(r.marker("a"), Some(0));
        assert_eq!(r.marker("b"), Some(1));
        assert_eq!(r.marker("s:b"), Some(1));
        assert_eq!(r.marker("c"), None);
        assert_eq!(r.gaps_per_marker(), vec![0, 1]);
        let f = r.frame(3);
        assert_eq!(f.positions[0], Vec3::new(3.0, 0.0, 0.0));
        assert!((f.time - 0.03).abs() < 1e-12);
        assert!(!r.frame(2).valid[1]);
        assert_eq!(r.frame(2).positions[1], Vec3::ZERO);
        assert!((r.duration() - 0.04).abs() < 1e-12);
    }

    #[test]
    fn non_finite_samples_become_invalid() {
        let r = Recording::new(
            vec!["a".into()],
            10.0,
            "mm",
            vec![Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE],
            vec![true, true],
        );
        assert!(!r.frame(0).valid[0]);
        assert_eq!(r.frame(0).positions[0], Vec3::ZERO);
        assert!(r.frame(1).valid[0]);
    }

    #[test]
    fn resampling_interpolates_and_respects_gaps() {
        let r = ramp().resampled(200.0);
        // 0.04 s at 200 Hz: 9 frames.
        assert_eq!(r.frame_count(), 9);
        assert_eq!(r.rate_hz, 200.0);
        // Frame 3 is at t = 0.015 s, halfway between source frames 1 and 2.
        let f = r.frame(3);
        assert!((f.positions[0].x - 1.5).abs() < 1e-6);
        assert!(!f.valid[1], "straddles the gap");
        // Frame 6 is source frame 3 exactly: valid although frame 2 is not.
        assert!(r.frame(6).valid[1]);
        assert_eq!(r.frame(6).positions[1].y, 3.0);
        // Downsampling to 50 Hz takes every other frame.
        let d = ramp().resampled(50.0);
        assert_eq!(d.frame_count(), 3);
        assert_eq!(d.frame(2).positions[0].x, 4.0);
        assert!(!d.frame(1).valid[1], "source frame 2 is a gap");
    }
}
