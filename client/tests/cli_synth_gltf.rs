//! End to end: `crease train` on a bending tube, then `crease synth --gltf` bakes the predicted
//! frames into one animated GLB; read back with the `gltf` crate, every keyframe's mesh equals
//! the OBJ the same run wrote for that frame.

use std::path::Path;
use std::process::Command;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;

fn crease() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crease"))
}

const RINGS: usize = 8;
const AROUND: usize = 6;
/// Control points: a base vertex, two at mid height, two at the tip.
const CONTROLS: [usize; 5] = [0, 4 * AROUND, 4 * AROUND + 3, 7 * AROUND, 7 * AROUND + 3];

/// A tube along z from 0 to 7 (unit radius), `RINGS` rings of `AROUND` vertices.
fn tube() -> Mesh {
    let mut positions = Vec::new();
    for r in 0..RINGS {
        for a in 0..AROUND {
            let phi = std::f32::consts::TAU * a as f32 / AROUND as f32;
            positions.push(Vec3::new(phi.cos(), phi.sin(), r as f32));
        }
    }
    let mut triangles = Vec::new();
    for r in 0..RINGS - 1 {
        for a in 0..AROUND {
            let i0 = (r * AROUND + a) as u32;
            let i1 = (r * AROUND + (a + 1) % AROUND) as u32;
            let (j0, j1) = (i0 + AROUND as u32, i1 + AROUND as u32);
            triangles.push([i0, i1, j1]);
            triangles.push([i0, j1, j0]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// The tube with its upper half rotated by `angle` about the x axis through z = 3.5.
fn bent(rest: &Mesh, angle: f32) -> Mesh {
    let q = Quat::from_rotation_x(angle);
    let pivot = Vec3::new(0.0, 0.0, 3.5);
    Mesh {
        positions: rest
            .positions
            .iter()
            .map(|&p| {
                if p.z > pivot.z {
                    pivot + q * (p - pivot)
                } else {
                    p
                }
            })
            .collect(),
        triangles: rest.triangles.clone(),
    }
}

/// Writes the rest tube and six bent poses, trains a 2-bone global model on them and returns
/// the model's path.
fn train_model(dir: &Path) -> std::path::PathBuf {
    let examples = dir.join("examples");
    std::fs::create_dir_all(&examples).unwrap();
    let rest = tube();
    rest.write(examples.join("reference.obj")).unwrap();
    for k in 1..=6 {
        bent(&rest, 0.15 * k as f32)
            .write(examples.join(format!("pose{k}.obj")))
            .unwrap();
    }
    let model = dir.join("tube.crease");
    let controls = CONTROLS.map(|c| c.to_string()).join(",");
    let out = crease()
        .args(["train", "--examples"])
        .arg(&examples)
        .args([
            "--bones",
            "2",
            "--max-influences",
            "2",
            "--kc",
            "3",
            "--kp",
            "3",
        ])
        .args(["--method", "global", "--control-points", &controls, "--out"])
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "train failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    model
}

#[test]
fn synth_gltf_keyframes_match_the_obj_frames() {
    let dir = tempfile::tempdir().unwrap();
    let model = train_model(dir.path());
    // Control frames at bends between and beyond the training poses; the last one with the
    // second tip point occluded.
    let rest = tube();
    let mut csv = String::from("# x y z per control point\n");
    for (i, angle) in [0.05f32, 0.4, 0.75, 0.6].into_iter().enumerate() {
        let pose = bent(&rest, angle);
        let fields: Vec<String> = CONTROLS
            .iter()
            .enumerate()
            .flat_map(|(j, &c)| {
                let p = pose.positions[c];
                if i == 3 && j == 4 {
                    vec![String::new(); 3]
                } else {
                    vec![p.x.to_string(), p.y.to_string(), p.z.to_string()]
                }
            })
            .collect();
        csv += &fields.join(",");
        csv.push('\n');
    }
    let frames = 4;
    let controls = dir.path().join("controls.csv");
    std::fs::write(&controls, csv).unwrap();
    let out_dir = dir.path().join("frames");
    let glb = dir.path().join("anim.glb");
    let out = crease()
        .args(["synth", "--model"])
        .arg(&model)
        .arg("--controls")
        .arg(&controls)
        .arg("--out")
        .arg(&out_dir)
        .arg("--gltf")
        .arg(&glb)
        .args(["--fps", "10"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "synth failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (doc, buffers, _) = gltf::import(&glb).expect("the GLB loads");
    let mesh = doc.meshes().next().expect("one mesh");
    let prim = mesh.primitives().next().expect("one primitive");
    assert_eq!(prim.morph_targets().count(), frames, "one target per frame");
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let base: Vec<Vec3> = reader
        .read_positions()
        .unwrap()
        .map(Vec3::from_array)
        .collect();
    let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!(base.len(), rest.positions.len());

    let anim = doc.animations().next().expect("one animation");
    let channel = anim.channels().next().expect("one channel");
    assert_eq!(
        channel.target().property(),
        gltf::animation::Property::MorphTargetWeights
    );
    let node = channel.target().node();
    assert_eq!(node.mesh().map(|m| m.index()), Some(mesh.index()));
    assert_eq!(
        channel.sampler().input().count(),
        frames,
        "one keyframe per frame"
    );
    let anim_reader = channel.reader(|b| Some(&buffers[b.index()]));
    let times: Vec<f32> = anim_reader.read_inputs().unwrap().collect();
    for (i, t) in times.iter().enumerate() {
        assert!((t - i as f32 / 10.0).abs() < 1e-6, "keyframe {i} at {t} s");
    }
    let Some(gltf::animation::util::ReadOutputs::MorphTargetWeights(w)) =
        anim_reader.read_outputs()
    else {
        panic!("the channel animates morph-target weights");
    };
    let weights: Vec<f32> = w.into_f32().collect();
    assert_eq!(weights.len(), frames * frames);

    for (i, (targets, row)) in reader
        .read_morph_targets()
        .zip(weights.chunks_exact(frames))
        .enumerate()
    {
        // One-hot: at keyframe i only target i is shown.
        for (j, &w) in row.iter().enumerate() {
            assert_eq!(w, f32::from(i == j), "keyframe {i}, target {j}");
        }
        let obj = Mesh::read(out_dir.join(format!("frame_{i:05}.obj"))).unwrap();
        let flat: Vec<u32> = obj.triangles.iter().flatten().copied().collect();
        assert_eq!(indices, flat, "frame {i}: triangles");
        let displacements = targets.0.expect("POSITION displacements");
        let mut moved = 0.0f32;
        for (v, ((&b, d), &want)) in base
            .iter()
            .zip(displacements)
            .zip(&obj.positions)
            .enumerate()
        {
            let got = b + Vec3::from_array(d);
            assert!(
                (got - want).length() <= 1e-5 * want.length().max(1.0),
                "frame {i}, vertex {v}: glTF {got}, OBJ {want}"
            );
            moved = moved.max((want - b).length());
        }
        assert!(
            moved > 0.05,
            "frame {i} should be bent away from the rest pose"
        );
    }
}

#[test]
fn synth_without_out_or_gltf_names_both() {
    let dir = tempfile::tempdir().unwrap();
    let out = crease()
        .args(["synth", "--model"])
        .arg(dir.path().join("missing.crease"))
        .arg("--controls")
        .arg(dir.path().join("missing.csv"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--out") && stderr.contains("--gltf"),
        "{stderr}"
    );
}
