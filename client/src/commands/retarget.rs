//! `crease retarget`: a marker recording (Qualisys TSV, C3D) through a marker map onto a model's
//! control points, written as a control-frame CSV that `crease synth --controls` and
//! `crease stream --frames` read. The same steps feed `crease stream --tsv/--c3d` live.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_mocap::map::MarkerMap;
use crease_mocap::{Recording, Retarget, RetargetStats};
use crease_proto::v1;

use crease_remote::control_file::{ControlFrame, write_csv};

/// A recording and its marker map (shared by `stream` and `retarget`).
#[derive(Clone, Debug, clap::Args)]
pub struct RecordingArgs {
    /// A Qualisys TSV marker recording (with --map, or into a room that retargets).
    #[arg(long, value_name = "FILE", conflicts_with = "c3d")]
    pub tsv: Option<PathBuf>,
    /// A C3D marker recording (with --map, or into a room that retargets).
    #[arg(long, value_name = "FILE")]
    pub c3d: Option<PathBuf>,
    /// Marker map (TOML): recording markers -> the model's control points, registration, gap
    /// filling, applied here. Examples: bench/mocap/*.toml. Not for a room opened with a map
    /// (`crease room open --map`): that room retargets the raw markers itself.
    #[arg(long, value_name = "FILE")]
    pub map: Option<PathBuf>,
}

/// Parses `--rate`: frames per second, in (0, 10000].
pub fn parse_rate(s: &str) -> Result<f64, String> {
    let rate: f64 = s
        .parse()
        .map_err(|_| format!("expected frames per second, got {s:?}"))?;
    if rate.is_finite() && rate > 0.0 && rate <= 10_000.0 {
        Ok(rate)
    } else {
        Err(format!(
            "must be in (0, 10000] frames per second, got {rate}"
        ))
    }
}

/// A model's control points: names and rest positions, model order.
#[derive(Clone, Debug)]
pub struct ModelControls {
    /// The model's name.
    pub model: String,
    /// Control point names.
    pub names: Vec<String>,
    /// Rest positions.
    pub rest: Vec<Vec3>,
}

impl ModelControls {
    /// From a server's model description.
    pub fn from_info(info: &v1::ModelInfo) -> ModelControls {
        ModelControls {
            model: info.name.clone(),
            names: info.control_points.iter().map(|c| c.name.clone()).collect(),
            rest: info
                .control_points
                .iter()
                .map(|c| c.rest.map_or(Vec3::ZERO, Vec3::from))
                .collect(),
        }
    }

    /// From a trained model.
    pub fn from_model(name: &str, model: &TrainedModel) -> ModelControls {
        ModelControls {
            model: name.to_owned(),
            names: model.controls.iter().map(|c| c.name.clone()).collect(),
            rest: model
                .controls
                .iter()
                .map(|c| model.rig.rest.positions[c.vertex as usize])
                .collect(),
        }
    }
}

/// Control frames made from a recording.
#[derive(Clone, Debug)]
pub struct Retargeted {
    /// One frame per (resampled) recording frame, model order.
    pub frames: Vec<ControlFrame>,
    /// Their rate, Hz.
    pub rate: f64,
    /// Model units per recording unit.
    pub scale: Option<f32>,
    /// The recording's length unit.
    pub units: String,
    /// Occlusion and registration counts.
    pub stats: Option<RetargetStats>,
}

impl RecordingArgs {
    /// The recording file given (`--tsv` or `--c3d`).
    pub fn path(&self) -> Option<&Path> {
        self.tsv.as_deref().or(self.c3d.as_deref())
    }

    /// Reads the recording and resamples it to `rate` when given, reporting on stderr.
    pub(crate) fn read(&self, rate: Option<f64>) -> anyhow::Result<(Recording, f64)> {
        let path = self.path().context("--tsv or --c3d is needed")?;
        let start = Instant::now();
        let mut recording = Recording::read(path)?;
        eprintln!(
            "read {}: {} frames at {} Hz, {} markers ({}) in {:.2} s",
            path.display(),
            recording.frame_count(),
            recording.rate_hz,
            recording.marker_count(),
            recording.units,
            start.elapsed().as_secs_f64()
        );
        if recording.frame_count() == 0 {
            bail!("{}: no frames", path.display());
        }
        let rate = rate.unwrap_or(recording.rate_hz);
        if (rate - recording.rate_hz).abs() > 1e-9 {
            recording = recording.resampled(rate);
            eprintln!("resampled to {rate} Hz: {} frames", recording.frame_count());
        }
        Ok((recording, rate))
    }

    /// The recording's raw markers for a room that retargets (issue 19): per frame, the
    /// positions and validity of the room's declared markers (`Retarget.markers`), in that
    /// order, in the recording's units.
    ///
    /// # Errors
    /// A declared marker the recording does not have (named, with those it has); `--map`
    /// given (the room has its own).
    pub fn raw_markers(
        &self,
        declared: &[String],
        rate: Option<f64>,
    ) -> anyhow::Result<Retargeted> {
        if let Some(map) = &self.map {
            bail!(
                "--map {}: this room retargets with its own map (crease room open --map); send it the raw markers without --map",
                map.display()
            );
        }
        let (recording, rate) = self.read(rate)?;
        let index = declared
            .iter()
            .map(|name| {
                recording.marker(name).with_context(|| {
                    format!(
                        "the room expects marker {name:?}, the recording has none (it has {})",
                        recording.names.join(", ")
                    )
                })
            })
            .collect::<anyhow::Result<Vec<usize>>>()?;
        let frames = recording
            .frames()
            .map(|f| ControlFrame {
                positions: index.iter().map(|&m| f.positions[m]).collect(),
                valid: index.iter().map(|&m| f.valid[m]).collect(),
            })
            .collect();
        Ok(Retargeted {
            frames,
            rate,
            scale: None,
            units: recording.units,
            stats: None,
        })
    }

    /// Reads the recording, resamples it to `rate` when given, and retargets every frame onto
    /// `controls`, reporting on stderr.
    pub fn retarget(
        &self,
        controls: &ModelControls,
        rate: Option<f64>,
    ) -> anyhow::Result<Retargeted> {
        let map_path = self.map.as_deref().context(
            "--map is required with a recording (unless the room retargets: crease room open --map)",
        )?;
        let (recording, rate) = self.read(rate)?;
        let map = MarkerMap::read(map_path)?;
        let bound = map.bind(&recording, &controls.names).with_context(|| {
            format!(
                "binding {} to model {:?}",
                map_path.display(),
                controls.model
            )
        })?;
        let mut retarget = Retarget::new(bound, &controls.rest);
        let used = retarget.calibrate(&recording);
        match retarget.registration().scale() {
            Some(s) if used == 0 => eprintln!(
                "registration: scale {s:.6} model units per {} (fixed by the map)",
                recording.units
            ),
            Some(s) => eprintln!(
                "registration: scale {s:.6} model units per {} (fitted on {used} frames)",
                recording.units
            ),
            None => eprintln!(
                "registration: only {used} calibration frames; the scale adapts while playing"
            ),
        }
        let n = retarget.control_count();
        let mut frames = Vec::with_capacity(recording.frame_count());
        for frame in recording.frames() {
            let mut positions = vec![Vec3::ZERO; n];
            let mut valid = vec![false; n];
            retarget.frame(&frame, &mut positions, &mut valid);
            frames.push(ControlFrame { positions, valid });
        }
        let stats = retarget.stats();
        eprintln!(
            "retargeted {} frames: {} with missing markers ({} points: {} estimated from neighbours, {} sent invalid); registration held in {} frames",
            stats.frames,
            stats.occluded_frames,
            stats.missing_points,
            stats.estimated_points,
            stats.held_points,
            stats.registration_held
        );
        Ok(Retargeted {
            frames,
            rate,
            scale: retarget.registration().scale(),
            units: recording.units,
            stats: Some(stats),
        })
    }
}

/// Options of `crease retarget`.
#[derive(Clone, Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["tsv", "c3d"])))]
pub struct RetargetArgs {
    /// The recording to read and how (file, map, rate).
    #[command(flatten)]
    pub recording: RecordingArgs,
    /// The trained model whose control points the map names.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// Resample the recording to this rate first (Hz).
    #[arg(long, value_parser = parse_rate)]
    pub rate: Option<f64>,
    /// Control-frame CSV to write (one frame per line; an invalid point is `nan,nan,nan`).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Runs `crease retarget`.
pub fn run(args: &RetargetArgs) -> anyhow::Result<()> {
    let model = TrainedModel::load(&args.model)
        .with_context(|| format!("reading model {}", args.model.display()))?;
    let name = args
        .model
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    let controls = ModelControls::from_model(&name, &model);
    let out = args.recording.retarget(&controls, args.rate)?;
    write_csv(&args.out, &controls.names, &out.frames)?;
    println!(
        "wrote {}: {} frames at {} Hz for {} control points",
        args.out.display(),
        out.frames.len(),
        out.rate,
        controls.names.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates() {
        assert_eq!(parse_rate("60"), Ok(60.0));
        assert_eq!(parse_rate("10000"), Ok(10_000.0));
        for bad in ["0", "-1", "NaN", "inf", "10001", "fast"] {
            assert!(parse_rate(bad).is_err(), "{bad}");
        }
    }
}
