//! The whole sweep hand (`crease_hand::rig::HandRig`: sweeps, palm surface, folds and
//! collisions) on the base resolution: the flat pose is the rest mesh, and 1,000 sampled
//! poses give finite meshes of a hand's size.

use crease_core::glam::Vec3;
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::skeleton::{HandPose, PoseSampler};
use crease_hand::surface::Resolution;

#[test]
fn flat_pose_is_the_rest_mesh_with_every_layer() {
    let rig = HandRig::build(Resolution::Base).expect("base hand");
    let mut scratch = RigScratch::new();
    let mut out = vec![Vec3::ZERO; rig.vertex_count()];
    rig.deform(&HandPose::FLAT, Layers::default(), &mut scratch, &mut out);
    let scale = rig.rest().bbox_diagonal_scale();
    let worst = out
        .iter()
        .zip(&rig.rest().positions)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5 * scale, "max error {worst} m");
    assert!(scratch.contacts().is_empty(), "{:?}", scratch.contacts());
}

#[test]
fn thousand_sampled_poses_give_finite_hands() {
    let rig = HandRig::build(Resolution::Base).expect("base hand");
    let mut scratch = RigScratch::new();
    let mut out = vec![Vec3::ZERO; rig.vertex_count()];
    let mut sampler = PoseSampler::new(2026);
    let mut contacts = 0;
    for k in 0..1000 {
        let pose = sampler.sample();
        rig.deform(&pose, Layers::default(), &mut scratch, &mut out);
        for (i, p) in out.iter().enumerate() {
            // Everything stays within a hand's reach of the wrist (0.19 m + margin).
            assert!(
                p.is_finite() && p.length() < 0.3,
                "pose {k}, vertex {i}: {p}"
            );
        }
        contacts += scratch.contacts().len();
    }
    eprintln!("1,000 poses: {contacts} contacts resolved");
}
