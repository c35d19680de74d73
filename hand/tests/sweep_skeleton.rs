//! The LYK06 hand skeleton (`crease_hand::skeleton`): proportions, limits, named poses,
//! the pose sampler, forward kinematics against independent computations, and pose JSON.

use crease_core::glam::{Mat3, Vec3};
use crease_hand::skeleton::{
    Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, JointFrame, JointLimits, NamedPose,
    PoseSampler, PosedSkeleton, SkeletonError,
};

fn deg(d: f32) -> f32 {
    d.to_radians()
}

fn dof(joint: Joint, kind: DofKind) -> Dof {
    Dof::new(joint, kind).expect("joint has this degree of freedom")
}

/// Mean of the CMC and MCP centres of the four fingers: a point in the middle of the palm.
fn palm_centre(posed: &PosedSkeleton) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for d in Digit::FINGERS {
        let j = d.joints();
        sum += posed.joint(j[0]).position + posed.joint(j[1]).position;
    }
    sum / 8.0
}

/// Poses for FK checks: the named poses, sampled poses, and wild poses far outside the limits.
fn many_poses() -> Vec<HandPose> {
    let mut poses: Vec<HandPose> = NamedPose::ALL.iter().map(|&p| HandPose::named(p)).collect();
    let mut sampler = PoseSampler::new(7);
    poses.extend((0..200).map(|_| sampler.sample()));
    // Unclamped: angles in (-3, 3) rad from a simple LCG, independent of the sampler.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for _ in 0..50 {
        let mut angles = [0.0f32; 24];
        for a in &mut angles {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *a = ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 6.0;
        }
        poses.push(HandPose::from_angles(angles));
    }
    poses
}

#[test]
fn flat_pose_has_adult_hand_length_and_fingers_ordered_along_x() {
    let posed = HandSkeleton::adult_right().pose(&HandPose::named(NamedPose::Flat));
    let length = posed
        .tip(Digit::Middle)
        .position
        .distance(posed.wrist().position);
    assert!((0.17..=0.21).contains(&length), "hand length {length} m");
    // Right hand, back towards +Z: thumb at -X, then index < middle < ring < little.
    for joint_index in 2..6 {
        let xs: Vec<f32> = Digit::FINGERS
            .iter()
            .map(|&d| posed.chain(d)[joint_index].position.x)
            .collect();
        assert!(
            xs.windows(2).all(|w| w[0] < w[1]),
            "frame {joint_index}: {xs:?}"
        );
    }
    assert!(posed.tip(Digit::Thumb).position.x < posed.tip(Digit::Index).position.x);
    // The middle finger is the longest and points along +Y.
    for d in Digit::ALL {
        assert!(posed.tip(d).position.y <= posed.tip(Digit::Middle).position.y + 1e-6);
    }
    let dir = posed.tip(Digit::Middle).axis();
    assert!(dir.abs_diff_eq(Vec3::Y, 1e-6), "{dir}");
}

#[test]
fn every_named_pose_is_finite_within_limits_and_parses_by_name() {
    let limits = JointLimits::adult();
    let skeleton = HandSkeleton::adult_right();
    for named in NamedPose::ALL {
        let pose = HandPose::named(named);
        assert!(pose.is_finite(), "{named}");
        assert!(pose.is_within(&limits), "{named}: {pose:?}");
        let posed = skeleton.pose(&pose);
        for d in Digit::ALL {
            for f in posed.chain(d) {
                assert!(f.position.is_finite() && f.rotation.is_finite(), "{named}");
            }
        }
        assert_eq!(named.name().parse::<NamedPose>(), Ok(named));
        assert_eq!(named.to_string(), named.name());
    }
    let names: Vec<&str> = NamedPose::ALL.iter().map(|p| p.name()).collect();
    assert_eq!(
        names,
        [
            "flat",
            "relaxed",
            "fist",
            "point",
            "victory",
            "pinch",
            "grasp",
            "spread",
            "thumbs-up",
            "ok"
        ]
    );
    assert_eq!("Thumbs_Up".parse::<NamedPose>(), Ok(NamedPose::ThumbsUp));
    assert!(matches!(
        "clenched".parse::<NamedPose>(),
        Err(SkeletonError::UnknownPose(_))
    ));
    // Distinct names give distinct poses.
    for (i, a) in NamedPose::ALL.iter().enumerate() {
        for b in &NamedPose::ALL[i + 1..] {
            assert_ne!(HandPose::named(*a), HandPose::named(*b), "{a} == {b}");
        }
    }
}

#[test]
fn fist_flexes_every_finger_and_brings_the_tips_to_the_palm() {
    let skeleton = HandSkeleton::adult_right();
    let fist = HandPose::named(NamedPose::Fist);
    for d in Digit::FINGERS {
        let j = d.joints();
        assert!(fist.flexion(j[1]) > deg(60.0), "{d:?} MCP");
        assert!(fist.flexion(j[2]) > deg(80.0), "{d:?} PIP");
        assert!(fist.flexion(j[3]) > deg(45.0), "{d:?} DIP");
    }
    let flat = skeleton.pose(&HandPose::FLAT);
    let closed = skeleton.pose(&fist);
    let (flat_palm, fist_palm) = (palm_centre(&flat), palm_centre(&closed));
    for d in Digit::ALL {
        let open = flat.tip(d).position.distance(flat_palm);
        let shut = closed.tip(d).position.distance(fist_palm);
        assert!(shut < open, "{d:?}: {shut} >= {open}");
    }
    for d in Digit::FINGERS {
        let tip = closed.tip(d).position;
        assert!(tip.distance(fist_palm) < 0.07, "{d:?} tip {tip}");
        assert!(tip.z < fist_palm.z, "{d:?} tip not on the palm side: {tip}");
    }
}

#[test]
fn sampled_poses_are_within_limits_deterministic_and_seed_dependent() {
    let limits = JointLimits::adult();
    let a: Vec<HandPose> = {
        let mut s = PoseSampler::new(42);
        (0..1000).map(|_| s.sample()).collect()
    };
    let b: Vec<HandPose> = {
        let mut s = PoseSampler::new(42);
        (0..1000).map(|_| s.sample()).collect()
    };
    let c: Vec<HandPose> = {
        let mut s = PoseSampler::new(43);
        (0..1000).map(|_| s.sample()).collect()
    };
    assert_eq!(a, b);
    assert!(a.iter().zip(&c).all(|(x, y)| x != y));
    for p in &a {
        assert!(p.is_finite() && p.is_within(&limits), "{p:?}");
    }
    // Consecutive samples differ: the sequence is not stuck.
    assert!(a.windows(2).all(|w| w[0] != w[1]));

    // Natural: finger flexions correlate (a shared grip), and DIP follows ~2/3 of PIP.
    let series = |joint: Joint| -> Vec<f32> { a.iter().map(|p| p.flexion(joint)).collect() };
    let corr = |x: &[f32], y: &[f32]| -> f32 {
        let n = x.len() as f32;
        let (mx, my) = (x.iter().sum::<f32>() / n, y.iter().sum::<f32>() / n);
        let sxy: f32 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
        let sxx: f32 = x.iter().map(|a| (a - mx).powi(2)).sum();
        let syy: f32 = y.iter().map(|b| (b - my).powi(2)).sum();
        sxy / (sxx * syy).sqrt()
    };
    let (index_pip, middle_pip, ring_pip) = (
        series(Joint::IndexPip),
        series(Joint::MiddlePip),
        series(Joint::RingPip),
    );
    assert!(corr(&middle_pip, &ring_pip) > 0.7);
    assert!(corr(&index_pip, &middle_pip) > 0.4);
    let middle_dip = series(Joint::MiddleDip);
    let (dip_sum, pip_sum): (f32, f32) = (middle_dip.iter().sum(), middle_pip.iter().sum());
    let ratio = dip_sum / pip_sum;
    assert!((0.55..0.78).contains(&ratio), "DIP/PIP {ratio}");
    // And varied: both open and closed hands occur.
    assert!(middle_pip.iter().any(|&x| x < deg(15.0)));
    assert!(middle_pip.iter().any(|&x| x > deg(90.0)));
}

#[test]
fn bone_lengths_are_preserved_and_frames_are_orthonormal_in_any_pose() {
    let skeleton = HandSkeleton::adult_right();
    let mut posed = PosedSkeleton::default();
    for pose in many_poses() {
        skeleton.pose_into(&pose, &mut posed);
        assert_eq!(posed, skeleton.pose(&pose));
        for d in Digit::ALL {
            let chain = posed.chain(d);
            assert_eq!(chain.len(), d.chain_len());
            let lengths = skeleton.bone_lengths(d);
            assert_eq!(lengths.len(), chain.len() - 2);
            let rest = std::iter::once(skeleton.base(d).length()).chain(lengths.iter().copied());
            for (k, rest_length) in rest.enumerate() {
                let got = chain[k].position.distance(chain[k + 1].position);
                assert!(
                    (got - rest_length).abs() < 1e-6,
                    "{d:?} bone {k}: {got} vs {rest_length}"
                );
                // Every joint frame's +Y points along its bone to the next frame.
                if k > 0 {
                    let along = (chain[k + 1].position - chain[k].position) / rest_length;
                    assert!(along.abs_diff_eq(chain[k].axis(), 1e-5), "{d:?} bone {k}");
                }
            }
            for f in chain {
                assert_orthonormal(f);
            }
            // The tip keeps the distal phalanx's orientation.
            assert_eq!(
                chain[chain.len() - 1].rotation,
                chain[chain.len() - 2].rotation
            );
        }
        assert_eq!(posed.joint(Joint::Wrist), posed.wrist());
        assert_eq!(posed.joint(Joint::RingPip), posed.chain(Digit::Ring)[3]);
    }
}

fn assert_orthonormal(f: &JointFrame) {
    let m = Mat3::from(f.to_affine().matrix3);
    let gram = m.transpose() * m;
    assert!(gram.abs_diff_eq(Mat3::IDENTITY, 1e-5), "{gram}");
    assert!((m.determinant() - 1.0).abs() < 1e-5);
    assert!((f.rotation.length() - 1.0).abs() < 1e-5);
}

#[test]
fn middle_finger_flexion_matches_planar_kinematics() {
    // The middle finger lies on the Y axis at rest, so flexing only it (no abduction) keeps it
    // in the YZ plane: each bone points along (0, cos a, -sin a) with a the summed flexion.
    let skeleton = HandSkeleton::adult_right();
    let flat = skeleton.pose(&HandPose::FLAT);
    let mcp = flat.joint(Joint::MiddleMcp).position;
    assert!(mcp.x.abs() < 1e-7 && mcp.z.abs() < 1e-7, "{mcp}");
    let [_, l1, l2, l3] = <[f32; 4]>::try_from(skeleton.bone_lengths(Digit::Middle)).unwrap();
    for (a, b, c) in [(0.3, 0.5, 0.2), (1.2, 1.5, 1.0), (-0.3, 0.0, 0.7)] {
        let mut pose = HandPose::FLAT;
        pose.set(dof(Joint::MiddleMcp, DofKind::Flexion), a);
        pose.set(dof(Joint::MiddlePip, DofKind::Flexion), b);
        pose.set(dof(Joint::MiddleDip, DofKind::Flexion), c);
        let bone = |angle: f32| Vec3::new(0.0, angle.cos(), -angle.sin());
        let expected = mcp + l1 * bone(a) + l2 * bone(a + b) + l3 * bone(a + b + c);
        let got = skeleton.pose(&pose).tip(Digit::Middle).position;
        assert!(got.abs_diff_eq(expected, 1e-6), "{got} vs {expected}");
    }
}

#[test]
fn sign_conventions_flexion_palmar_abduction_away_from_middle() {
    let skeleton = HandSkeleton::adult_right();
    let flat = skeleton.pose(&HandPose::FLAT);
    let posed_with = |dof: Dof, angle: f32| {
        let mut p = HandPose::FLAT;
        p.set(dof, angle);
        skeleton.pose(&p)
    };
    for d in Digit::FINGERS {
        let j = d.joints();
        // MCP flexion curls the finger towards the palm (-Z), and more flexion curls further.
        let bent = posed_with(dof(j[1], DofKind::Flexion), deg(40.0));
        let more = posed_with(dof(j[1], DofKind::Flexion), deg(80.0));
        assert!(bent.tip(d).position.z < -0.02, "{d:?}");
        assert!(more.tip(d).position.z < bent.tip(d).position.z, "{d:?}");
        let (at_rest, flexed) = (flat.joint(j[1]), bent.joint(j[1]));
        assert_eq!(
            flexed.position, at_rest.position,
            "the MCP centre stays put"
        );
        let turned = at_rest.axis().angle_between(flexed.axis());
        assert!((turned - deg(40.0)).abs() < 1e-4, "{d:?}: {turned}");
        // Hyperextension lifts it to the back.
        let lifted = posed_with(dof(j[1], DofKind::Flexion), deg(-20.0));
        assert!(lifted.tip(d).position.z > 0.01, "{d:?}");
        // PIP flexion too.
        let pip = posed_with(dof(j[2], DofKind::Flexion), deg(60.0));
        assert!(pip.tip(d).position.z < -0.01, "{d:?}");
        // Positive abduction moves the finger away from the middle finger's axis (x = 0).
        if d != Digit::Middle {
            let spread = posed_with(dof(j[1], DofKind::Abduction), deg(15.0));
            let (x0, x1) = (flat.tip(d).position.x, spread.tip(d).position.x);
            assert!(x1.abs() > x0.abs() + 0.01, "{d:?}: {x0} -> {x1}");
        }
    }
    // Middle finger positive abduction is radial (-X).
    let m = posed_with(dof(Joint::MiddleMcp, DofKind::Abduction), deg(10.0));
    assert!(m.tip(Digit::Middle).position.x < -0.01);
    // Thumb flexion carries it across the palm (+X); palmar abduction lifts it off the palm (-Z).
    let t0 = flat.tip(Digit::Thumb).position;
    let tf = posed_with(dof(Joint::ThumbCmc, DofKind::Flexion), deg(40.0));
    assert!(tf.tip(Digit::Thumb).position.x > t0.x + 0.02);
    let ta = posed_with(dof(Joint::ThumbCmc, DofKind::Abduction), deg(40.0));
    assert!(ta.tip(Digit::Thumb).position.z < t0.z - 0.02);
    // Cupping carries the little metacarpal head palmar and towards the thumb.
    let cup = posed_with(dof(Joint::LittleCmc, DofKind::Flexion), deg(15.0));
    let (h0, h1) = (
        flat.joint(Joint::LittleMcp).position,
        cup.joint(Joint::LittleMcp).position,
    );
    assert!(h1.z < h0.z - 0.005 && h1.x < h0.x, "{h0} -> {h1}");
    // Wrist flexion turns the whole hand palmar, rigidly.
    let w = posed_with(dof(Joint::Wrist, DofKind::Flexion), deg(30.0));
    assert!(w.tip(Digit::Middle).position.z < -0.05);
    for a in Digit::ALL {
        for b in Digit::ALL {
            let before = flat.tip(a).position.distance(flat.tip(b).position);
            let after = w.tip(a).position.distance(w.tip(b).position);
            assert!((before - after).abs() < 1e-6);
        }
    }
}

#[test]
fn clamp_projects_into_limits_and_keeps_valid_angles() {
    let limits = JointLimits::adult();
    let mut pose = HandPose::named(NamedPose::Relaxed);
    let pip = dof(Joint::IndexPip, DofKind::Flexion);
    let mcp = dof(Joint::IndexMcp, DofKind::Flexion);
    let abd = dof(Joint::LittleMcp, DofKind::Abduction);
    pose.set(pip, deg(170.0));
    pose.set(mcp, f32::NAN);
    pose.set(abd, f32::NEG_INFINITY);
    assert!(!pose.is_within(&limits));
    let clamped = pose.clamp(&limits);
    assert!(clamped.is_within(&limits));
    assert_eq!(clamped.get(pip), limits.range(pip).1);
    assert_eq!(clamped.get(mcp), 0.0);
    assert_eq!(clamped.get(abd), 0.0);
    let relaxed = HandPose::named(NamedPose::Relaxed);
    for d in Dof::all().filter(|&d| d != pip && d != mcp && d != abd) {
        assert_eq!(clamped.get(d), relaxed.get(d), "{}", d.name());
    }
    // A range that excludes 0: a NaN goes to the end nearest 0.
    let narrow = limits.clone().with_range(mcp, 0.2, 0.5).unwrap();
    assert_eq!(pose.clamp(&narrow).get(mcp), 0.2);
    assert!(limits.with_range(mcp, 0.5, 0.2).is_none());
}

#[test]
fn pose_json_round_trips_by_joint_name() {
    let mut sampler = PoseSampler::new(3);
    for _ in 0..20 {
        let pose = sampler.sample();
        let json = serde_json::to_string(&pose).unwrap();
        assert!(json.contains("\"index_mcp_flexion\""), "{json}");
        let back: HandPose = serde_json::from_str(&json).unwrap();
        assert_eq!(back, pose);
    }
    let partial: HandPose = serde_json::from_str(r#"{"middle_pip_flexion": 1.25}"#).unwrap();
    assert_eq!(partial.flexion(Joint::MiddlePip), 1.25);
    assert_eq!(partial.angles().iter().filter(|&&a| a != 0.0).count(), 1);
    let err = serde_json::from_str::<HandPose>(r#"{"middle_pap_flexion": 1.0}"#).unwrap_err();
    assert!(err.to_string().contains("middle_pap_flexion"), "{err}");
    let named: NamedPose = serde_json::from_str("\"thumbs-up\"").unwrap();
    assert_eq!(named, NamedPose::ThumbsUp);
}

#[test]
fn scaled_skeleton_scales_every_position() {
    let base = HandSkeleton::adult_right();
    let big = base.scaled(1.1);
    let pose = HandPose::named(NamedPose::Grasp);
    let (a, b) = (base.pose(&pose), big.pose(&pose));
    for d in Digit::ALL {
        for (fa, fb) in a.chain(d).iter().zip(b.chain(d)) {
            assert!((fa.position * 1.1).abs_diff_eq(fb.position, 1e-6));
            assert!(fa.rotation.abs_diff_eq(fb.rotation, 1e-6));
        }
    }
}

#[test]
fn pinch_and_ok_bring_thumb_and_index_tips_together() {
    let skeleton = HandSkeleton::adult_right();
    for named in [NamedPose::Pinch, NamedPose::Ok] {
        let posed = skeleton.pose(&HandPose::named(named));
        let gap = posed
            .tip(Digit::Thumb)
            .position
            .distance(posed.tip(Digit::Index).position);
        // The tip frames sit at the pulps' ends; touching pulps leave them about 1 cm apart.
        assert!(gap < 0.015, "{named}: {gap} m");
        let flat = skeleton.pose(&HandPose::FLAT);
        let open = flat
            .tip(Digit::Thumb)
            .position
            .distance(flat.tip(Digit::Index).position);
        assert!(gap < open / 3.0, "{named}");
    }
}
