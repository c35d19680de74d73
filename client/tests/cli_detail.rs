//! End to end on the real cactus set split by `--base-vertices`: `crease train` stores a detail
//! layer, `crease synth --detail` writes subdivided meshes (base vertices + edges after one Loop
//! level), and `crease eval --json` carries `base_rms_mean` and `detail_rms_mean` for every
//! predictor and the `static-detail` and `cascaded-detail` rows.

use crate::common;

use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;

use common::{crease, run_ok, shared_data};

const COMMON: [&str; 8] = [
    "--base-vertices",
    "1200",
    "--bones",
    "12",
    "--max-influences",
    "4",
    "--detail-ray",
    "0.05",
];

#[test]
fn train_synth_and_eval_with_the_detail_layer() {
    let Some(dir) = shared_data("cactus") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let model_path = tmp.path().join("cactus.crease");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&dir)
            .args(COMMON)
            .args(["--control-points", "auto:6", "--method", "local", "--out"])
            .arg(&model_path),
    );
    let model = TrainedModel::load(&model_path).unwrap();
    let layer = model.detail.as_ref().expect("a detail layer");
    // One level (the count closest to the 5,261 detailed vertices): V + E of the base.
    assert_eq!(layer.levels, 1);
    let rest = &model.rig.rest;
    assert!(
        (1176..=1224).contains(&rest.vertex_count()),
        "{}",
        rest.vertex_count()
    );
    let high = rest.vertex_count() + rest.edges().len();
    assert_eq!(layer.regressor.vertex_count(), high);

    // Two frames: the rest controls and the same, one point occluded.
    let rest_controls: Vec<String> = model
        .controls
        .iter()
        .map(|c| {
            let p = rest.positions[c.vertex as usize];
            format!("{},{},{}", p.x, p.y, p.z)
        })
        .collect();
    let mut occluded = rest_controls.clone();
    occluded[0] = ",,".into();
    let csv = tmp.path().join("controls.csv");
    std::fs::write(
        &csv,
        format!("{}\n{}\n", rest_controls.join(","), occluded.join(",")),
    )
    .unwrap();
    let out = tmp.path().join("frames");
    run_ok(
        crease()
            .args(["synth", "--detail", "--model"])
            .arg(&model_path)
            .arg("--controls")
            .arg(&csv)
            .arg("--out")
            .arg(&out),
    );
    for f in ["frame_00000.obj", "frame_00001.obj"] {
        let m = Mesh::read(out.join(f)).unwrap();
        assert_eq!(m.vertex_count(), high, "{f}");
        assert_eq!(m.triangles.len(), 4 * rest.triangles.len(), "{f}");
        assert!(m.positions.iter().all(|p| p.is_finite()), "{f}");
    }

    // A base-only model refuses --detail with a clear message.
    let base_only = tmp.path().join("base.crease");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&dir)
            .args(COMMON)
            .args(["--no-detail", "--control-points", "auto:6", "--out"])
            .arg(&base_only),
    );
    let refused = crease()
        .args(["synth", "--detail", "--model"])
        .arg(&base_only)
        .arg("--controls")
        .arg(&csv)
        .arg("--out")
        .arg(tmp.path().join("none"))
        .output()
        .unwrap();
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("detail layer"));

    // Leave-one-out with the detail rows.
    let json = run_ok(
        crease()
            .args(["eval", "--loo", "--json", "--examples"])
            .arg(&dir)
            .args(COMMON)
            .args(["--control-points", "auto:6", "--methods", "global,local"]),
    );
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let loo = &v["loo"];
    for row in ["global", "local", "static-detail", "cascaded-detail"] {
        for field in ["base_rms_mean", "detail_rms_mean", "crease_rms_mean"] {
            let x = loo[row][field].as_f64();
            assert!(
                x.is_some_and(f64::is_finite),
                "{row}.{field}: {:?}",
                loo[row]
            );
        }
    }
    assert_eq!(
        loo["static-detail"]["base_rms_mean"],
        loo["local"]["base_rms_mean"]
    );
}

/// `--control-points` indices name vertices of the examples as read: with `--base-vertices`
/// they move to the nearest base vertex at rest (as the manifest's list does), and one beyond
/// the examples' vertex count is refused with that count.
#[test]
fn command_line_control_points_move_to_the_base() {
    let Some(dir) = shared_data("cactus") else {
        return;
    };
    let full = crease_core::mesh::examples::ExampleSet::load(&dir).unwrap();
    let n = full.rest.vertex_count();
    let given = [n as u32 - 1, 17, (n / 2) as u32];
    let tmp = tempfile::tempdir().unwrap();
    let model_path = tmp.path().join("cactus.crease");
    let list = given.map(|v| v.to_string()).join(",");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&dir)
            .args(COMMON)
            .args(["--control-points", &list, "--out"])
            .arg(&model_path),
    );
    let model = TrainedModel::load(&model_path).unwrap();
    let base = &model.rig.rest;
    let bbox = full.rest.bbox_diagonal_scale();
    for (c, &v) in model.controls.iter().zip(&given) {
        assert!((c.vertex as usize) < base.vertex_count());
        // The base is a Laplacian-smoothed subset of about 1,200 of the 5,261 vertices: the
        // nearest one lies within a few average edge lengths (a few % of the size).
        let d = base.positions[c.vertex as usize].distance(full.rest.positions[v as usize]);
        assert!(
            d < 0.05 * bbox,
            "control at full vertex {v}: base vertex {} is {d} away",
            c.vertex
        );
    }
    let out = crease()
        .args(["train", "--examples"])
        .arg(&dir)
        .args(COMMON)
        .args(["--control-points", &format!("3,{n}"), "--out"])
        .arg(tmp.path().join("never.crease"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains(&format!("vertex {n} is out of range"))
            && stderr.contains(&format!("have {n} vertices")),
        "{stderr}"
    );
}

/// `--base-vertices N --no-detail`: the base is still the N-vertex subset (it was the full mesh:
/// the split was skipped with the detail layer), and the model has no detail layer.
#[test]
fn no_detail_still_splits_the_base() {
    let Some(dir) = shared_data("cactus") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let model_path = tmp.path().join("cactus.crease");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&dir)
            .args(COMMON)
            .args(["--no-detail", "--control-points", "auto:6", "--out"])
            .arg(&model_path),
    );
    let model = TrainedModel::load(&model_path).unwrap();
    assert!(model.detail.is_none());
    let n = model.rig.rest.vertex_count();
    assert!((1176..=1224).contains(&n), "{n} base vertices");
}
