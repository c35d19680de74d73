//! `crease train`'s control-point measurements (issue 42): the control-point curve in the
//! output, `--json` and the report, and the warning for a region the control points leave
//! undetermined, on a tube whose two ends bend independently with control points on one end
//! only (the library's own checks are `train/tests/coverage.rs`); `--control-curve none` skips
//! both.

use crate::common::crease;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_testkit::mesh::tube;
use serde_json::Value;

/// The rest tube (17 rings of 8, z from 0 to 8) and 11 poses: the top (z > 6) turned about x,
/// the bottom (z < 2) about y, by angles that do not follow each other.
fn write_examples(dir: &std::path::Path) {
    let rest = tube(17, 8, 8.0);
    rest.write(dir.join("reference.obj")).unwrap();
    for k in 1..=11usize {
        let top = 0.9 * ((k * 7 % 11) as f32 / 5.0 - 1.0);
        let bottom = 0.9 * ((k * 4 % 13) as f32 / 6.0 - 1.0);
        let (qt, qb) = (Quat::from_rotation_x(top), Quat::from_rotation_y(bottom));
        let (pt, pb) = (Vec3::new(0.0, 0.0, 6.0), Vec3::new(0.0, 0.0, 2.0));
        let positions = rest
            .positions
            .iter()
            .map(|&p| match p.z {
                z if z > 6.0 => qt * (p - pt) + pt,
                z if z < 2.0 => qb * (p - pb) + pb,
                _ => p,
            })
            .collect();
        Mesh {
            positions,
            triangles: rest.triangles.clone(),
        }
        .write(dir.join(format!("pose{k:02}.obj")))
        .unwrap();
    }
}

#[test]
fn train_warns_of_an_undetermined_end_and_reports_the_curve() {
    let tmp = tempfile::tempdir().unwrap();
    let examples = tmp.path().join("examples");
    std::fs::create_dir_all(&examples).unwrap();
    write_examples(&examples);
    let train = |extra: &[&str]| {
        let mut cmd = crease();
        cmd.args(["train", "--examples"])
            .arg(&examples)
            .args(["--bones", "8", "--max-influences", "2"])
            // The top ring's two sides and one point below it: the top end only.
            .args(["--control-points", "128,132,114", "--out"])
            .arg(tmp.path().join("tube.crease"))
            .args(extra);
        cmd.output().unwrap()
    };
    let report = tmp.path().join("report");
    let out = train(&["--json", "--report", report.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: the control points leave")
            && stderr.contains("undetermined around"),
        "{stderr}"
    );
    assert!(stderr.contains("control-point curve"), "{stderr}");
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    let coverage = &json["coverage"];
    let regions = coverage["bones"]["regions"].as_array().unwrap();
    assert!(!regions.is_empty(), "{coverage}");
    for r in regions {
        // The undetermined region is the bottom end, far from the points at the top.
        let z = r["centroid"][2].as_f64().unwrap();
        assert!(z < 3.0, "{r}");
    }
    // The default counts, each with its own automatic points.
    let curve = coverage["curve"].as_array().unwrap();
    let counts: Vec<u64> = curve.iter().map(|p| p["count"].as_u64().unwrap()).collect();
    assert_eq!(counts[..2], [4, 8], "{coverage}");
    for p in curve {
        assert_eq!(
            p["controls"].as_array().unwrap().len() as u64,
            p["count"].as_u64().unwrap()
        );
    }
    let page = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(page.contains("control-curve.svg") && page.contains("undetermined.png"));
    assert!(page.contains("Warning: the control points leave"));
    assert!(
        report.join("control-curve.svg").is_file() && report.join("undetermined.png").is_file()
    );

    // --control-curve none: neither measurement, no warning.
    let out = train(&["--json", "--control-curve", "none"]);
    assert!(out.status.success());
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json["coverage"].is_null(), "{}", json["coverage"]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("undetermined"));
    // A bad count says what is wrong.
    let out = train(&["--control-curve", "4,x"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("`x` is not a count"));
}
