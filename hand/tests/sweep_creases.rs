//! Creases of the detailed sweep hand (`crease_hand::creases`): each crease's depth,
//! measured on the deformed mesh's geometry, follows its driving joints monotonically
//! (palm lines and palmar flexion creases deepen with flexion, dorsal wrinkles smooth out).
//!
//! Depth is measured two independent ways: for palm lines as the valley depth (how far a
//! crease vertex lies below the mean of the vertices just outside the groove, along the
//! skin's normal), for digit creases as how much closer to the posed joint centre the crease
//! vertex lies — the valley measure fails there at a sharp bend, where the fold fix presses
//! the palmar skin into the joint plane and its normal degenerates.
//! Both subtract the same pose deformed without creases.

use crease_core::glam::Vec3;
use crease_hand::creases::CreaseKind;
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::skeleton::{HandPose, JointLimits};
use crease_hand::surface::Resolution;

/// A crease vertex and the rest vertices around it just outside the groove.
struct Probe {
    centre: usize,
    ring: Vec<usize>,
}

/// Valley depth at a probe: how far the centre lies below the mean of its ring along the
/// outward normal `n`.
fn valley(positions: &[Vec3], probe: &Probe, n: Vec3) -> f32 {
    let mean = probe.ring.iter().map(|&j| positions[j]).sum::<Vec3>() / probe.ring.len() as f32;
    (mean - positions[probe.centre]).dot(n)
}

/// Area-weighted normal from the triangles `around` a vertex (outward).
fn normal_at(positions: &[Vec3], tris: &[[u32; 3]], around: &[usize]) -> Vec3 {
    around
        .iter()
        .map(|&t| {
            let [a, b, c] = tris[t].map(|k| positions[k as usize]);
            (b - a).cross(c - a)
        })
        .sum::<Vec3>()
        .normalize_or_zero()
}

#[test]
fn crease_depths_follow_their_joints_monotonically() {
    let rig = HandRig::build(Resolution::Detailed).expect("detailed hand");
    let creases = rig.creases().expect("the detailed hand has creases");
    let rest = rig.rest();
    let limits = JointLimits::adult();
    let mut scratch = RigScratch::new();
    let mut with = vec![Vec3::ZERO; rig.vertex_count()];
    let mut without = vec![Vec3::ZERO; rig.vertex_count()];
    let layers = Layers::default();
    let plain = Layers {
        creases: false,
        ..layers
    };
    // Triangles around each vertex (for normals of the crease-free mesh).
    let mut around: Vec<Vec<usize>> = vec![Vec::new(); rig.vertex_count()];
    for (t, tri) in rest.triangles.iter().enumerate() {
        for &k in tri {
            around[k as usize].push(t);
        }
    }
    for (c, def) in creases.defs().iter().enumerate() {
        // Up to 12 central vertices of the crease, spread along it.
        let mut central: Vec<usize> = creases
            .vertices(c)
            .filter(|&(_, g)| g > 0.9)
            .map(|(v, _)| v as usize)
            .collect();
        assert!(!central.is_empty(), "{}: no central vertices", def.name);
        let step = (central.len() / 12).max(1);
        central = central.into_iter().step_by(step).take(12).collect();
        let probes: Vec<Probe> = central
            .iter()
            .map(|&i| {
                let p = rest.positions[i];
                let (lo, hi) = (2.5 * def.width, 3.5 * def.width);
                let ring: Vec<usize> = (0..rest.positions.len())
                    .filter(|&j| (lo..hi).contains(&rest.positions[j].distance(p)))
                    .collect();
                Probe { centre: i, ring }
            })
            .filter(|p| p.ring.len() >= 6)
            .collect();
        assert!(!probes.is_empty(), "{}: no probe has a ring", def.name);
        let mut depths = Vec::new();
        for a in [0.0, 0.25, 0.5, 0.75, 1.0] {
            let mut pose = HandPose::FLAT;
            for &d in &def.drivers {
                pose.set(d, a * limits.range(d).1);
            }
            rig.deform(&pose, layers, &mut scratch, &mut with);
            rig.deform(&pose, plain, &mut scratch, &mut without);
            // Depth = valley with creases - valley without (removes the skin's own curvature).
            let centre = def.centre(&rig.skeleton().pose(&pose));
            let depth = probes
                .iter()
                .map(|p| match centre {
                    Some(c) => without[p.centre].distance(c) - with[p.centre].distance(c),
                    None => {
                        let n = normal_at(&without, &rest.triangles, &around[p.centre]);
                        valley(&with, p, n) - valley(&without, p, n)
                    }
                })
                .sum::<f32>()
                / probes.len() as f32;
            depths.push(depth);
        }
        eprintln!(
            "{:>28} ({:?}): depth mm at 0, 25, 50, 75, 100% of the limit: {:?}",
            def.name,
            def.kind,
            depths
                .iter()
                .map(|d| (d * 1e5).round() / 100.0)
                .collect::<Vec<_>>()
        );
        let max = def.max_depth;
        match def.kind {
            CreaseKind::PalmLine | CreaseKind::Flexion => {
                assert!(depths[0].abs() < 0.05 * max, "{}: {depths:?}", def.name);
                for w in depths.windows(2) {
                    assert!(
                        w[1] > w[0] + 1e-6,
                        "{}: not increasing: {depths:?}",
                        def.name
                    );
                }
                assert!(
                    depths[4] > 0.4 * max,
                    "{}: shallow at the limit: {depths:?}",
                    def.name
                );
            }
            CreaseKind::Dorsal => {
                assert!(
                    depths[0] > 0.4 * max,
                    "{}: shallow when straight: {depths:?}",
                    def.name
                );
                for w in depths.windows(2) {
                    assert!(
                        w[1] <= w[0] + 1e-6,
                        "{}: not decreasing: {depths:?}",
                        def.name
                    );
                }
                assert!(
                    depths[2] < 0.05 * max,
                    "{}: still deep bent: {depths:?}",
                    def.name
                );
            }
        }
    }
}
