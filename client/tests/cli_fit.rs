//! End to end: the real `crease` binary fits a rig from example files, writes the rig and a
//! skinned glTF, and prints the JSON summary the issue specifies.

use crate::common;

use std::path::Path;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::model::Rig;

use common::crease;

/// A bent bar: two rigid halves rotating about the middle, written as OBJ files.
fn write_examples(dir: &Path) -> usize {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let (nx, ny) = (20, 4);
    for i in 0..nx {
        for j in 0..ny {
            positions.push(Vec3::new(i as f32 * 0.5, j as f32 * 0.3, 0.0));
        }
    }
    for i in 0..nx - 1 {
        for j in 0..ny - 1 {
            let a = (i * ny + j) as u32;
            triangles.push([a, a + ny as u32, a + 1]);
            triangles.push([a + 1, a + ny as u32, a + ny as u32 + 1]);
        }
    }
    let rest = Mesh {
        positions,
        triangles,
    };
    rest.write(dir.join("reference.obj")).unwrap();
    let poses = 6;
    for k in 1..=poses {
        let q = Quat::from_rotation_y(0.2 * k as f32);
        let pivot = Vec3::new(4.75, 0.0, 0.0);
        let moved = Mesh {
            positions: rest
                .positions
                .iter()
                .map(|&p| {
                    if p.x > pivot.x {
                        pivot + q * (p - pivot)
                    } else {
                        p
                    }
                })
                .collect(),
            triangles: rest.triangles.clone(),
        };
        moved.write(dir.join(format!("pose{k}.obj"))).unwrap();
    }
    poses + 1
}

#[test]
fn fit_writes_rig_gltf_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let frames = write_examples(dir.path());
    let rig_path = dir.path().join("bar.rig");
    let glb_path = dir.path().join("bar.glb");
    let out = crease()
        .args(["fit", "--examples"])
        .arg(dir.path())
        .args(["--bones", "2", "--max-influences", "4", "--json", "--out"])
        .arg(&rig_path)
        .arg("--export-gltf")
        .arg(&glb_path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("stdout is one JSON object");
    assert_eq!(json["bones"], 2);
    assert_eq!(json["max_influences"], 4);
    assert_eq!(json["frames"], frames);
    assert!(json["iterations"].as_u64().unwrap() >= 1);
    assert!(json["seconds"].as_f64().unwrap() >= 0.0);
    // Two rigid parts and two bones: the fit is (nearly) exact.
    let rms = json["rms_normalized"].as_f64().unwrap();
    assert!(rms < 1e-4, "rms_normalized {rms}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("fit") && stderr.contains("rms"),
        "per-iteration progress on stderr: {stderr}"
    );

    let rig = Rig::load(&rig_path).expect("rig file loads");
    assert_eq!(rig.bone_count, 2);
    assert_eq!(rig.examples.len(), frames);
    assert_eq!(rig.examples[0].name, "reference.obj");

    let (doc, _, _) = gltf::import(&glb_path).expect("glb loads");
    let skin = doc.skins().next().expect("one skin");
    assert_eq!(skin.joints().count(), 2);
    let anim = doc.animations().next().expect("one animation");
    let channel = anim.channels().next().unwrap();
    assert_eq!(
        channel.sampler().input().count(),
        frames,
        "one keyframe per example"
    );
}

/// `crease train --export-gltf` writes the trained model's own rig (not a new fit): the GLB is
/// the one `export_rig_glb` makes from the rig inside the saved model, byte for byte, and
/// loads with the `gltf` crate with one joint per bone.
#[test]
fn train_exports_the_models_rig_as_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let frames = write_examples(dir.path());
    let model_path = dir.path().join("bar.crease");
    let glb_path = dir.path().join("bar-train.glb");
    common::run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(dir.path())
            .args(["--bones", "2", "--control-points", "0,79,40", "--no-detail"])
            .arg("--out")
            .arg(&model_path)
            .arg("--export-gltf")
            .arg(&glb_path),
    );
    let model = crease_core::model::TrainedModel::load(&model_path).unwrap();
    let again = dir.path().join("again.glb");
    crease_core::model::export_rig_glb(&model.rig, &again).unwrap();
    assert_eq!(
        std::fs::read(&glb_path).unwrap(),
        std::fs::read(&again).unwrap(),
        "the exported GLB is not the model's rig"
    );
    let (doc, _, _) = gltf::import(&glb_path).expect("glb loads");
    let skin = doc.skins().next().expect("one skin");
    assert_eq!(skin.joints().count(), model.rig.bone_count);
    let anim = doc.animations().next().expect("one animation");
    assert_eq!(
        anim.channels().next().unwrap().sampler().input().count(),
        frames
    );
}

#[test]
fn fit_errors_name_the_problem() {
    let out = crease()
        .args(["fit", "--examples", "/nonexistent/crease-examples"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("/nonexistent/crease-examples"), "{stderr}");

    let dir = tempfile::tempdir().unwrap();
    write_examples(dir.path());
    let out = crease()
        .args(["fit", "--max-influences", "9", "--examples"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("max-influences") && stderr.contains("9"),
        "{stderr}"
    );
}
