//! `crease synth`: a batch of control frames in, one mesh per frame out: predicted here, or by a
//! server's `Synthesize` RPC with `--server` ([`super::remote_synth`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::{TrainedModel, gltf_export};
use crease_core::runtime::predictor::Predictor;

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
    #[arg(long, value_name = "N", default_value_t = super::remote_synth::CHUNK_FRAMES)]
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
}

/// One frame of control points with its validity mask.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlFrame {
    /// Positions (occluded ones are NaN).
    pub positions: Vec<Vec3>,
    /// `false` where occluded.
    pub valid: Vec<bool>,
}

/// Runs `crease synth`.
pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    if args.out.is_none() && args.gltf.is_none() {
        bail!("nothing to write: give --out DIR (one mesh per frame), --gltf FILE, or both");
    }
    if args.gltf.is_some() && !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps must be > 0, got {}", args.fps);
    }
    if let Some(server) = &args.server {
        return super::remote_synth::run(args, server);
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
    let predictor =
        Predictor::new(Arc::new(model), args.beta).context("preparing the predictor")?;
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

/// Reads control frames from CSV or JSON (by extension) for a model with `count` control points.
pub fn read_control_frames(path: &Path, count: usize) -> anyhow::Result<Vec<ControlFrame>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let frames = if is_json {
        parse_json(&text, count)
    } else {
        parse_csv(&text, count)
    }
    .with_context(|| format!("{}", path.display()))?;
    if frames.is_empty() {
        bail!("{}: no control frames", path.display());
    }
    Ok(frames)
}

fn frame_from_values(values: &[Option<f32>]) -> ControlFrame {
    let mut positions = Vec::with_capacity(values.len() / 3);
    let mut valid = Vec::with_capacity(values.len() / 3);
    for c in values.chunks_exact(3) {
        match (c[0], c[1], c[2]) {
            (Some(x), Some(y), Some(z)) if x.is_finite() && y.is_finite() && z.is_finite() => {
                positions.push(Vec3::new(x, y, z));
                valid.push(true);
            }
            _ => {
                positions.push(Vec3::NAN);
                valid.push(false);
            }
        }
    }
    ControlFrame { positions, valid }
}

/// CSV: one frame per line, `3 * count` fields.
pub fn parse_csv(text: &str, count: usize) -> anyhow::Result<Vec<ControlFrame>> {
    let mut frames = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split([',', ';', '\t']).map(str::trim).collect();
        let parsed: Vec<Result<Option<f32>, _>> = fields
            .iter()
            .map(|f| {
                if f.is_empty() || f.eq_ignore_ascii_case("nan") {
                    Ok(None)
                } else {
                    f.parse::<f32>().map(Some)
                }
            })
            .collect();
        if frames.is_empty()
            && parsed.iter().any(|p| p.is_err())
            && line.chars().any(|c| c.is_ascii_alphabetic())
        {
            continue; // header
        }
        if fields.len() != 3 * count {
            bail!(
                "line {}: {} fields, expected {} (x, y, z of {count} control points)",
                n + 1,
                fields.len(),
                3 * count
            );
        }
        let mut values = Vec::with_capacity(fields.len());
        for (i, p) in parsed.into_iter().enumerate() {
            values.push(p.with_context(|| {
                format!(
                    "line {}, field {}: {:?} is not a number",
                    n + 1,
                    i + 1,
                    fields[i]
                )
            })?);
        }
        frames.push(frame_from_values(&values));
    }
    Ok(frames)
}

/// JSON: an array of frames; each frame an array of `count` points (`[x, y, z]` or `null`) or
/// of `3 * count` numbers.
pub fn parse_json(text: &str, count: usize) -> anyhow::Result<Vec<ControlFrame>> {
    let value: serde_json::Value = serde_json::from_str(text).context("not valid JSON")?;
    let Some(frames) = value.as_array() else {
        bail!("expected a JSON array of frames")
    };
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let Some(items) = f.as_array() else {
                bail!("frame {i}: expected an array")
            };
            let mut values = Vec::with_capacity(3 * count);
            if items.len() == count && items.iter().all(|p| p.is_array() || p.is_null()) {
                for (j, p) in items.iter().enumerate() {
                    match p.as_array() {
                        None => values.extend([None, None, None]),
                        Some(xyz) if xyz.len() == 3 => {
                            values.extend(xyz.iter().map(|v| v.as_f64().map(|x| x as f32)))
                        }
                        Some(xyz) => bail!(
                            "frame {i}, point {j}: {} coordinates, expected 3",
                            xyz.len()
                        ),
                    }
                }
            } else if items.len() == 3 * count {
                values.extend(items.iter().map(|v| v.as_f64().map(|x| x as f32)));
            } else {
                bail!(
                    "frame {i}: {} entries, expected {count} points or {} numbers",
                    items.len(),
                    3 * count
                );
            }
            Ok(frame_from_values(&values))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_with_header_comments_and_occlusion() {
        let text = "# frames\nx0,y0,z0,x1,y1,z1\n1,2,3,4,5,6\n1,2,3,,nan,6\n";
        let f = parse_csv(text, 2).unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(
            f[0].positions,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]
        );
        assert_eq!(f[1].valid, vec![true, false]);
        let err = parse_csv("1,2,3\n", 2).unwrap_err().to_string();
        assert!(
            err.contains("line 1") && err.contains("expected 6"),
            "{err}"
        );
        let err = parse_csv("1,2,3,4,5,6\n1,2,x,4,5,6\n", 2).unwrap_err();
        assert!(format!("{err:#}").contains("line 2, field 3"), "{err:#}");
    }

    #[test]
    fn json_points_null_and_flat() {
        let f = parse_json("[[[1,2,3],null],[1,2,3,4,5,6]]", 2).unwrap();
        assert_eq!(f[0].valid, vec![true, false]);
        assert_eq!(f[1].positions[1], Vec3::new(4.0, 5.0, 6.0));
        assert!(
            parse_json("[[1,2]]", 2)
                .unwrap_err()
                .to_string()
                .contains("frame 0")
        );
        assert!(parse_json("{}", 2).is_err());
    }
}
