//! End to end: `crease train` on a bending tube, then `crease synth --gltf` bakes the predicted
//! frames into one animated GLB; read back with the `gltf` crate, every keyframe's mesh equals
//! the OBJ the same run wrote for that frame.

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;

use crate::common;
use common::{CONTROLS, bent, crease, train_model, tube};

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
