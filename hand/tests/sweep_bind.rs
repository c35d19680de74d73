//! The LYK06 control sweeps and skin binding (`crease_hand::sweeps`): rest
//! reconstruction, sampled poses, a local MCP bend, weights, cross-section area and sweep
//! curve continuity.

use std::sync::OnceLock;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_hand::skeleton::{Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, PoseSampler};
use crease_hand::surface::{HandSurface, Resolution};
use crease_hand::sweeps::{Sweep, SweepHand};

struct Fixture {
    skeleton: HandSkeleton,
    mesh: Mesh,
    hand: SweepHand,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let skeleton = HandSkeleton::adult_right();
        let mesh = HandSurface::build(Resolution::Base)
            .expect("base surface")
            .mesh;
        let start = Instant::now();
        let hand = SweepHand::bind(&skeleton, &mesh);
        eprintln!(
            "bind: {} vertices in {:?}",
            mesh.positions.len(),
            start.elapsed()
        );
        Fixture {
            skeleton,
            mesh,
            hand,
        }
    })
}

fn dof(joint: Joint, kind: DofKind) -> Dof {
    Dof::new(joint, kind).expect("joint has this degree of freedom")
}

fn deform(pose: &HandPose) -> Vec<Vec3> {
    let f = fixture();
    let mut out = vec![Vec3::ZERO; f.hand.vertex_count()];
    f.hand.deform_into(pose, &mut out);
    out
}

/// Weight of `digit` at vertex `i`.
fn weight_of(i: usize, digit: Digit) -> f32 {
    fixture()
        .hand
        .influences(i)
        .filter(|inf| inf.digit == digit)
        .map(|inf| inf.weight)
        .sum()
}

#[test]
fn rest_pose_reconstructs_rest_mesh() {
    let f = fixture();
    let out = deform(&HandPose::FLAT);
    let (lo, hi) = f.mesh.bounding_box();
    let diag = (hi - lo).length();
    let err = out
        .iter()
        .zip(&f.mesh.positions)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0f32, f32::max);
    assert!(
        err < 1e-5 * diag,
        "max rest error {err} m vs bbox diagonal {diag} m"
    );
}

#[test]
fn weights_are_non_negative_and_normalised() {
    let f = fixture();
    let mut multi = 0;
    for i in 0..f.hand.vertex_count() {
        let mut sum = 0.0;
        let mut count = 0;
        for inf in f.hand.influences(i) {
            assert!(inf.weight >= 0.0 && inf.weight.is_finite(), "vertex {i}");
            assert!((0.0..=1.0).contains(&inf.t), "vertex {i}: t = {}", inf.t);
            sum += inf.weight;
            count += 1;
        }
        assert!((sum - 1.0).abs() < 1e-5, "vertex {i}: weights sum to {sum}");
        if count > 1 {
            multi += 1;
        }
    }
    eprintln!(
        "{multi} of {} vertices blend several sweeps",
        f.hand.vertex_count()
    );
    // The palm and back blend several sweeps; the digits do not.
    assert!(
        multi > f.hand.vertex_count() / 20,
        "{multi} blended vertices"
    );
    let tip = f.skeleton.pose(&HandPose::FLAT).tip(Digit::Index).position;
    for (i, p) in f.mesh.positions.iter().enumerate() {
        if (*p - tip).length() < 0.015 {
            assert_eq!(weight_of(i, Digit::Index), 1.0, "index tip vertex {i}");
        }
    }
}

#[test]
fn sampled_poses_give_finite_meshes() {
    let f = fixture();
    let mut sampler = PoseSampler::new(7);
    let mut out = vec![Vec3::ZERO; f.hand.vertex_count()];
    let (lo, hi) = f.mesh.bounding_box();
    let reach = (hi - lo).length() * 2.0;
    let start = Instant::now();
    for _ in 0..200 {
        let pose = sampler.sample();
        f.hand.deform_into(&pose, &mut out);
        for p in &out {
            assert!(p.is_finite() && p.length() < reach, "vertex at {p}");
        }
    }
    eprintln!(
        "deform_into: {:?} per frame ({} vertices)",
        start.elapsed() / 200,
        out.len()
    );
}

#[test]
fn index_mcp_bend_is_local_and_palmar() {
    let f = fixture();
    let rest_posed = f.skeleton.pose(&HandPose::FLAT);
    let tip = rest_posed.tip(Digit::Index).position;
    for degrees in [60.0f32, 90.0] {
        let mut pose = HandPose::FLAT;
        pose.set(dof(Joint::IndexMcp, DofKind::Flexion), degrees.to_radians());
        let out = deform(&pose);
        let posed_tip = f.skeleton.pose(&pose).tip(Digit::Index).position;
        let mut tip_n = 0;
        for (i, (p, r)) in out.iter().zip(&f.mesh.positions).enumerate() {
            if (*r - tip).length() < 0.012 {
                tip_n += 1;
                // Towards the palm side (-Z) by several centimetres, following the skeleton.
                assert!(p.z < r.z - 0.02, "tip vertex {i}: z {} -> {}", r.z, p.z);
                assert!(
                    (*p - posed_tip).length() < 0.02,
                    "tip vertex {i} {p} far from the posed tip {posed_tip}"
                );
            }
            if r.y < 0.05 {
                assert!(
                    (*p - *r).length() < 1e-3,
                    "wrist-side vertex {i} moved {} m",
                    (*p - *r).length()
                );
            }
        }
        assert!(tip_n > 20, "{tip_n} tip vertices");
    }
}

/// Area of the section of the index finger's skin by the plane through `c` with normal `n`:
/// triangles bound to the index sweep alone, within 2 cm of `c`.
fn section_area(positions: &[Vec3], c: Vec3, n: Vec3) -> f32 {
    let f = fixture();
    let mut area = 0.0;
    for tri in &f.mesh.triangles {
        let idx = tri.map(|i| i as usize);
        if idx.iter().any(|&i| weight_of(i, Digit::Index) < 0.999) {
            continue;
        }
        let p = idx.map(|i| positions[i]);
        if p.iter().any(|q| (*q - c).length() > 0.02) {
            continue;
        }
        let s = p.map(|q| (q - c).dot(n));
        let mut pts = [Vec3::ZERO; 2];
        let mut k = 0;
        for e in 0..3 {
            let (a, b) = (e, (e + 1) % 3);
            if (s[a] < 0.0) != (s[b] < 0.0) && k < 2 {
                let u = s[a] / (s[a] - s[b]);
                pts[k] = p[a] + (p[b] - p[a]) * u;
                k += 1;
            }
        }
        if k != 2 {
            continue;
        }
        // Orient the segment consistently with the outward triangle normal.
        let normal = (p[1] - p[0]).cross(p[2] - p[0]);
        let dir = n.cross(normal);
        let (a, b) = if (pts[1] - pts[0]).dot(dir) >= 0.0 {
            (pts[0], pts[1])
        } else {
            (pts[1], pts[0])
        };
        area += 0.5 * (a - c).cross(b - c).dot(n);
    }
    area.abs()
}

#[test]
fn bent_finger_keeps_cross_section_area() {
    let f = fixture();
    let mut pose = HandPose::FLAT;
    pose.set(dof(Joint::IndexMcp, DofKind::Flexion), 90f32.to_radians());
    pose.set(dof(Joint::IndexPip, DofKind::Flexion), 90f32.to_radians());
    let out = deform(&pose);
    let section = |pose: &HandPose, positions: &[Vec3]| {
        let posed = f.skeleton.pose(pose);
        let (mcp, pip) = (posed.joint(Joint::IndexMcp), posed.joint(Joint::IndexPip));
        section_area(positions, (mcp.position + pip.position) * 0.5, mcp.axis())
    };
    let rest = section(&HandPose::FLAT, &f.mesh.positions);
    let bent = section(&pose, &out);
    eprintln!("index proximal section: rest {rest:.3e} m², bent {bent:.3e} m²");
    // A finger ~1.6-2 cm across: a section of 1.5..4 cm².
    assert!((1.5e-4..4e-4).contains(&rest), "rest section {rest} m²");
    assert!(
        (bent - rest).abs() < 0.15 * rest,
        "section {rest} m² at rest, {bent} m² bent 90°"
    );
    // Through the bent PIP knuckle itself, in the plane bisecting the two phalanges (the
    // sweep's cross-section at the joint): no candy-wrapper collapse either.
    let knuckle = |pose: &HandPose, positions: &[Vec3]| {
        let posed = f.skeleton.pose(pose);
        let (mcp, pip) = (posed.joint(Joint::IndexMcp), posed.joint(Joint::IndexPip));
        let n = (mcp.axis() + pip.axis()).normalize();
        section_area(positions, pip.position, n)
    };
    let rest_k = knuckle(&HandPose::FLAT, &f.mesh.positions);
    let bent_k = knuckle(&pose, &out);
    eprintln!("index PIP section: rest {rest_k:.3e} m², bent {bent_k:.3e} m²");
    assert!(rest_k > 1e-4, "rest PIP section {rest_k} m²");
    assert!(
        (bent_k - rest_k).abs() < 0.15 * rest_k,
        "PIP section {rest_k} m² at rest, {bent_k} m² bent 90°"
    );
}

#[test]
fn sweep_is_continuous_and_hits_the_joints() {
    let f = fixture();
    let mut pose = HandPose::FLAT;
    pose.set(dof(Joint::IndexMcp, DofKind::Flexion), 90f32.to_radians());
    pose.set(dof(Joint::IndexPip, DofKind::Flexion), 60f32.to_radians());
    let posed = f.skeleton.pose(&pose);
    for digit in Digit::ALL {
        let sweep = Sweep::of_digit(&posed, digit);
        let chain = posed.chain(digit);
        assert!((sweep.frame_at(0.0).position - chain[0].position).length() < 1e-6);
        let end = sweep.frame_at(1.0);
        assert!((end.position - chain[chain.len() - 1].position).length() < 1e-6);
        assert!(end.rotation.angle_between(chain[chain.len() - 2].rotation) < 1e-3);
        let n = 2000;
        let step = sweep.length() / n as f32;
        let mut prev = sweep.frame_at(0.0);
        for k in 1..=n {
            let cur = sweep.frame_at(k as f32 / n as f32);
            // Chord-length parameter: the curve moves at about unit speed, never jumps.
            assert!(
                (cur.position - prev.position).length() < 1.6 * step,
                "{digit:?} jump at {k}"
            );
            assert!(
                cur.rotation.angle_between(prev.rotation) < 0.02,
                "{digit:?} twist at {k}"
            );
            prev = cur;
        }
        // The sweep passes through every joint centre.
        for frame in chain {
            let (_, d) = sweep.project(frame.position);
            assert!(
                d < 1e-5,
                "{digit:?}: joint {} off the sweep by {d}",
                frame.position
            );
        }
    }
}

#[test]
fn knuckle_region_blends_neighbouring_sweeps() {
    let f = fixture();
    let rest = f.skeleton.pose(&HandPose::FLAT);
    let mid = (rest.joint(Joint::IndexMcp).position + rest.joint(Joint::MiddleMcp).position) * 0.5;
    let mut pose = HandPose::FLAT;
    pose.set(dof(Joint::IndexMcp, DofKind::Flexion), 60f32.to_radians());
    let out = deform(&pose);
    let (mcp0, mcp1) = (
        rest.joint(Joint::IndexMcp),
        f.skeleton.pose(&pose).joint(Joint::IndexMcp),
    );
    let turn = mcp1.rotation * mcp0.rotation.inverse();
    let mut blended = 0;
    for (i, r) in f.mesh.positions.iter().enumerate() {
        if (*r - mid).length() < 0.012 {
            let (wi, wm) = (weight_of(i, Digit::Index), weight_of(i, Digit::Middle));
            if wi > 0.1 && wm > 0.1 {
                blended += 1;
            }
            // Between the knuckles the skin follows the index at most as far as the index's
            // own skin would go (rigidly turned 60° about the MCP).
            let rigid = mcp1.position + turn * (*r - mcp0.position);
            let moved = (out[i] - *r).length();
            assert!(
                moved <= (rigid - *r).length() + 1e-3,
                "vertex {i} moved {moved} m"
            );
        }
    }
    assert!(
        blended > 5,
        "{blended} blended vertices between index and middle knuckles"
    );
}
