//! The skinned GLB export, read back with the `gltf` crate: the skin and the animation, applied
//! as a glTF viewer would, reproduce the rig's LBS at every example keyframe.

use crease_core::glam::{Mat4, Quat, Vec3, Vec4};
use crease_core::mesh::Mesh;
use crease_core::model::gltf_export::{SECONDS_PER_EXAMPLE, export_rig_glb, rig_to_glb};
use crease_core::model::{ModelError, Rig, RigExample};
use crease_core::runtime::skin::{RigidTransform, SkinWeights};
use gltf::animation::util::ReadOutputs;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// A rig whose vertices carry `k` slots with some zero weights and some repeated bones.
fn synthetic_rig(seed: u64, n: usize, bones: usize, k: usize, examples: usize) -> Rig {
    let mut rng = StdRng::seed_from_u64(seed);
    let positions: Vec<Vec3> = (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(0.0..3.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    let triangles = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    let mut indices = Vec::new();
    let mut weights = Vec::new();
    for _ in 0..n {
        let mut w: Vec<f32> = (0..k)
            .map(|_| {
                if rng.random_range(0..4) == 0 {
                    0.0
                } else {
                    rng.random::<f32>() + 0.01
                }
            })
            .collect();
        w[0] += 0.1;
        let s: f32 = w.iter().sum();
        weights.extend(w.iter().map(|x| x / s));
        let mut ii: Vec<u32> = (0..k).map(|_| rng.random_range(0..bones as u32)).collect();
        if k > 1 && rng.random_range(0..6) == 0 {
            ii[1] = ii[0];
        }
        indices.extend(ii);
    }
    let examples = (0..examples)
        .map(|e| RigExample {
            name: format!("e{e}"),
            transforms: (0..bones)
                .map(|_| {
                    let axis = Vec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        0.3,
                    )
                    .normalize();
                    RigidTransform::new(
                        Quat::from_axis_angle(axis, rng.random_range(-3.0..3.0)),
                        Vec3::new(
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                        ),
                    )
                })
                .collect(),
        })
        .collect();
    Rig {
        rest: Mesh {
            positions,
            triangles,
        },
        bone_count: bones,
        skin: SkinWeights::new(k, indices, weights).unwrap(),
        examples,
        fit_rms: None,
    }
}

/// Reads the GLB back and checks structure and skinned positions against `Rig::skin_example`.
fn check_round_trip(rig: &Rig) {
    let bytes = rig_to_glb(rig).unwrap();
    // `from_slice` validates the JSON against the glTF schema rules the crate knows.
    let doc = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = doc.blob.clone().unwrap();
    let get = |_: gltf::Buffer<'_>| Some(&blob[..]);
    let n = rig.rest.vertex_count();
    let b = rig.bone_count;

    let skin = doc.skins().next().unwrap();
    let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
    assert_eq!(joints.len(), b);
    let ibm: Vec<Mat4> = skin
        .reader(get)
        .read_inverse_bind_matrices()
        .unwrap()
        .map(|m| Mat4::from_cols_array_2d(&m))
        .collect();
    assert_eq!(ibm.len(), b);

    let mesh = doc.meshes().next().unwrap();
    let prim = mesh.primitives().next().unwrap();
    let reader = prim.reader(get);
    let pos: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    assert_eq!(pos, rig.rest.positions);
    let tris: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!(tris.len(), 3 * rig.rest.triangles.len());
    let sets = if rig.skin.k() > 4 { 2 } else { 1 };
    assert!(reader.read_joints(sets).is_none());
    let mut vj = vec![Vec::new(); n];
    let mut vw = vec![Vec::new(); n];
    for set in 0..sets {
        for (v, (j, w)) in reader
            .read_joints(set)
            .unwrap()
            .into_u16()
            .zip(reader.read_weights(set).unwrap().into_f32())
            .enumerate()
        {
            vj[v].extend(j);
            vw[v].extend(w);
        }
    }
    for v in 0..n {
        let sum: f32 = vw[v].iter().sum();
        assert!((sum - 1.0).abs() < 1e-6, "vertex {v}: weights sum to {sum}");
        let nonzero: Vec<u16> = vj[v]
            .iter()
            .zip(&vw[v])
            .filter(|(_, w)| **w > 0.0)
            .map(|(j, _)| *j)
            .collect();
        assert!(nonzero.len() <= rig.skin.k(), "vertex {v}: {nonzero:?}");
        let mut uniq = nonzero.clone();
        uniq.sort();
        uniq.dedup();
        assert_eq!(
            uniq.len(),
            nonzero.len(),
            "vertex {v}: repeated joint {nonzero:?}"
        );
        assert!(vj[v].iter().zip(&vw[v]).all(|(j, w)| *w > 0.0 || *j == 0));
    }

    let anim = doc.animations().next().unwrap();
    // Per joint node: keyframe translations and rotations.
    let mut tr = vec![Vec::new(); doc.nodes().len()];
    let mut rot = vec![Vec::new(); doc.nodes().len()];
    let mut channels = 0;
    for ch in anim.channels() {
        let r = ch.reader(get);
        let times: Vec<f32> = r.read_inputs().unwrap().collect();
        assert_eq!(times.len(), rig.examples.len(), "one keyframe per example");
        for (e, t) in times.iter().enumerate() {
            assert!((t - e as f32 * SECONDS_PER_EXAMPLE).abs() < 1e-6);
        }
        let node = ch.target().node().index();
        match r.read_outputs().unwrap() {
            ReadOutputs::Translations(t) => tr[node] = t.map(Vec3::from).collect(),
            ReadOutputs::Rotations(q) => rot[node] = q.into_f32().map(Quat::from_array).collect(),
            _ => panic!("unexpected channel"),
        }
        channels += 1;
    }
    assert_eq!(channels, 2 * b);

    // Parents of the joints: the root's global transform multiplies every joint.
    let root_global = {
        let root = doc
            .nodes()
            .find(|nd| nd.children().any(|c| c.index() == joints[0]))
            .unwrap();
        Mat4::from_cols_array_2d(&root.transform().matrix())
    };
    let mut want = vec![Vec3::ZERO; n];
    for e in 0..rig.examples.len() {
        rig.skin_example(e, &mut want).unwrap();
        let skin_mats: Vec<Mat4> = joints
            .iter()
            .zip(&ibm)
            .map(|(&j, ib)| {
                root_global * Mat4::from_rotation_translation(rot[j][e], tr[j][e]) * *ib
            })
            .collect();
        let scale = 1.0 + rig.rest.bbox_diagonal_scale();
        for v in 0..n {
            let p = Vec4::from((pos[v], 1.0));
            let got: Vec3 = vj[v]
                .iter()
                .zip(&vw[v])
                .map(|(&j, &w)| w * (skin_mats[j as usize] * p).truncate())
                .sum();
            assert!(
                (got - want[v]).length() < 1e-4 * scale,
                "example {e} vertex {v}: {got} vs {}",
                want[v]
            );
        }
    }
}

#[test]
fn glb_round_trip_k4() {
    check_round_trip(&synthetic_rig(1, 300, 12, 4, 5));
}

#[test]
fn glb_round_trip_k6_uses_two_joint_sets() {
    check_round_trip(&synthetic_rig(2, 200, 9, 6, 3));
}

#[test]
fn glb_round_trip_k1_single_example() {
    check_round_trip(&synthetic_rig(3, 50, 3, 1, 1));
}

#[test]
fn glb_without_examples_has_no_animation() {
    let rig = synthetic_rig(4, 20, 2, 2, 0);
    let doc = gltf::Gltf::from_slice(&rig_to_glb(&rig).unwrap()).unwrap();
    assert_eq!(doc.animations().count(), 0);
    assert_eq!(doc.skins().count(), 1);
}

#[test]
fn export_writes_a_file_and_rejects_what_glb_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rig.glb");
    let rig = synthetic_rig(5, 40, 4, 4, 2);
    export_rig_glb(&rig, &path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), rig_to_glb(&rig).unwrap());

    let mut empty = rig.clone();
    empty.rest.triangles.clear();
    assert!(matches!(rig_to_glb(&empty), Err(ModelError::Export(_))));
}

/// The horse with a synthetic rig (real geometry, bone centres spread over a real shape).
#[test]
fn glb_round_trip_on_horse_geometry() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/horse/reference.obj"
    );
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("skipping: {path} not found (data set absent)");
        return;
    };
    let positions: Vec<Vec3> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let f: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            Vec3::new(f[0], f[1], f[2])
        })
        .collect();
    let triangles = text
        .lines()
        .filter_map(|l| l.strip_prefix("f "))
        .map(|l| {
            let f: Vec<u32> = l
                .split_whitespace()
                .map(|x| x.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                .collect();
            [f[0], f[1], f[2]]
        })
        .collect();
    // Random skin and transforms over the real vertices and triangles.
    let mut rig = synthetic_rig(7, positions.len(), 40, 4, 3);
    rig.rest = Mesh {
        positions,
        triangles,
    };
    check_round_trip(&rig);
}
