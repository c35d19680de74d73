//! The detail layer on the generated hand, end to end except the base predictor: Loop
//! subdivision of the base hand, displacements resampled from the detailed hand by ray
//! casting, the per-vertex regressor fitted on six poses' back-side control points, and
//! synthesis. A training pose is reproduced: `S·B_i + h(c_i) n` matches the resampled truth
//! `S·B_i + h_i n` to 0.05 mm, and the truth itself lies on the detailed mesh where its rays hit.

use crease_core::glam::Vec3;
use crease_core::runtime::detail::DetailSynth;
use crease_hand::dataset::{Layout, landmarks};
use crease_hand::rig::{HandRig, Layers};
use crease_hand::skeleton::{HandPose, NamedPose, PoseSampler};
use crease_hand::surface::Resolution;
use crease_train::detail::regress::{self, DetailInput};
use crease_train::detail::{DisplacementSource, DisplacementTarget};
use crease_train::kcca::KccaOptions;

#[test]
fn training_poses_reproduce_their_detailed_meshes() {
    let base = HandRig::build(Resolution::Base).expect("base hand");
    let detailed = HandRig::build(Resolution::Detailed).expect("detailed hand");
    let mut poses: Vec<HandPose> = [
        NamedPose::Flat,
        NamedPose::Fist,
        NamedPose::Point,
        NamedPose::Relaxed,
    ]
    .map(HandPose::named)
    .to_vec();
    let mut sampler = PoseSampler::new(11);
    poses.extend((0..2).map(|_| sampler.sample()));
    let normals = base.rest().vertex_normals();
    let cps = landmarks(Layout::Back, base.skeleton(), base.rest(), &normals);
    let mut synth = DetailSynth::from_mesh(base.rest(), 2).expect("subdivision");
    let nv = synth.vertex_count();
    assert!(nv >= 150_000, "{nv} subdivided vertices");
    let zero = vec![0.0; nv];
    let mut high = vec![Vec3::ZERO; nv];
    let mut x = Vec::new();
    let mut h = Vec::new();
    let mut bases = Vec::new();
    for pose in &poses {
        let b = base.posed_mesh(pose, Layers::default());
        let d = detailed.posed_mesh(pose, Layers::default());
        synth.synthesize(&b.positions, &zero, &mut high).unwrap();
        let n: Vec<Vec3> = synth.normals().iter().map(|&n| n.into()).collect();
        let target = DisplacementTarget::new(&d.positions, &d.triangles).unwrap();
        let mut hi = vec![0.0; nv];
        let stats = target.displacements(&high, &n, 0.0015, &mut hi).unwrap();
        assert!(stats.fallbacks < nv / 100, "{} fallbacks", stats.fallbacks);
        // Where a ray hit, the truth vertex lies on the detailed surface: a zero-length ray
        // from it along its normal finds the surface at distance ~0 (checked on a sample).
        for v in (0..nv).step_by(997) {
            let p = high[v] + hi[v] * n[v];
            let back = target.displacement(p, n[v], 1e-4).unwrap();
            if back.source == DisplacementSource::Ray {
                assert!(
                    back.h.abs() < 1e-5,
                    "vertex {v}: truth {} m off the surface",
                    back.h
                );
            }
        }
        x.extend(
            cps.iter()
                .flat_map(|l| b.positions[l.vertex as usize].to_array()),
        );
        h.push(hi);
        bases.push(b);
    }
    let opts = KccaOptions {
        kappa: 1e-7,
        ..KccaOptions::default()
    };
    let model = regress::fit(DetailInput::Controls, &x, cps.len() * 3, &h, None, &opts).unwrap();
    let d_in = cps.len() * 3;
    let mut xi = vec![0.0; poses.len()];
    let mut hp = vec![0.0; nv];
    let (mut out, mut truth) = (vec![Vec3::ZERO; nv], vec![Vec3::ZERO; nv]);
    let mut worst = 0.0f32;
    for (i, b) in bases.iter().enumerate() {
        model.predict(&x[i * d_in..(i + 1) * d_in], &mut xi, &mut hp);
        synth.synthesize(&b.positions, &hp, &mut out).unwrap();
        synth.synthesize(&b.positions, &h[i], &mut truth).unwrap();
        let e = out
            .iter()
            .zip(&truth)
            .map(|(p, q)| p.distance(*q))
            .fold(0.0f32, f32::max);
        eprintln!(
            "training pose {i}: max distance to the resampled truth {:.3} µm",
            e * 1e6
        );
        worst = worst.max(e);
    }
    assert!(worst < 5e-5, "training poses reproduced only to {worst} m");
}
