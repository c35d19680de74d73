//! Control-frame files: the CSV and JSON files of control points per frame that
//! `crease synth --controls`, `crease stream --frames` and `crease bench-net --controls` read,
//! and the CSV that `crease retarget` writes (its header names the points; `nan` marks an
//! invalid one).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;

/// One frame of control points with its validity mask.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ControlFrame {
    /// Positions (occluded ones are NaN).
    pub positions: Vec<Vec3>,
    /// `false` where occluded.
    pub valid: Vec<bool>,
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

/// Writes frames as the CSV `crease synth --controls` reads: a header of point names, then
/// `x,y,z` per point per line (`nan` for invalid points).
pub fn write_csv(path: &Path, names: &[String], frames: &[ControlFrame]) -> anyhow::Result<()> {
    let mut text = String::with_capacity(frames.len() * names.len() * 30 + 256);
    let header: Vec<String> = names
        .iter()
        .flat_map(|n| ["x", "y", "z"].map(|a| format!("{n}_{a}")))
        .collect();
    text.push_str(&header.join(","));
    text.push('\n');
    for f in frames {
        for (i, (p, ok)) in f.positions.iter().zip(&f.valid).enumerate() {
            if i > 0 {
                text.push(',');
            }
            if *ok {
                let _ = write!(text, "{},{},{}", p.x, p.y, p.z);
            } else {
                text.push_str("nan,nan,nan");
            }
        }
        text.push('\n');
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
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

    #[test]
    fn written_csv_reads_back_with_invalid_points() {
        let frames = vec![
            ControlFrame {
                positions: vec![Vec3::new(1.5, -2.0, 0.25), Vec3::NAN],
                valid: vec![true, false],
            },
            ControlFrame {
                positions: vec![Vec3::new(0.0, 1e-7, 3.0), Vec3::new(4.0, 5.0, 6.0)],
                valid: vec![true, true],
            },
        ];
        let dir = std::env::temp_dir().join(format!("crease-control-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("frames.csv");
        write_csv(&path, &["wrist".into(), "tip".into()], &frames).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.starts_with("wrist_x,wrist_y,wrist_z,tip_x,tip_y,tip_z\n"),
            "{text}"
        );
        let back = read_control_frames(&path, 2).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back[0].valid, frames[0].valid);
        assert_eq!(back[0].positions[0], frames[0].positions[0]);
        assert!(back[0].positions[1].is_nan());
        assert_eq!(back[1], frames[1]);
    }
}
