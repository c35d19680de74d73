//! Self-intersections and collisions of the sweep hand (`crease_hand::collide`, LYK06
//! "Handling self-intersections and collisions"): joint folds, digit-digit and digit-palm
//! contacts, an external ball, and sampled poses. Every check recomputes what it checks from
//! the public sweep API (posed sweeps, influences) by brute force, not from the collider.

use std::sync::OnceLock;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_hand::collide::{
    Ball, CollideError, CollideOptions, Contact, ContactKind, HandCollider,
};
use crease_hand::skeleton::{
    Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, JointLimits, NamedPose, PoseSampler,
    PosedSkeleton,
};
use crease_hand::surface::{HandSurface, Resolution};
use crease_hand::sweeps::{Sweep, SweepHand};

struct Fixture {
    skeleton: HandSkeleton,
    mesh: Mesh,
    hand: SweepHand,
    collider: HandCollider,
    /// Per vertex: dominant digit and rest arc, when beyond that digit's MCP.
    digit_of: Vec<Option<(Digit, f32)>>,
    /// Per vertex: dominant digit and rest arc (any arc).
    dominant: Vec<(Digit, f32)>,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let skeleton = HandSkeleton::adult_right();
        let mesh = HandSurface::build(Resolution::Base)
            .expect("base surface")
            .mesh;
        let hand = SweepHand::bind(&skeleton, &mesh);
        let start = Instant::now();
        let collider = HandCollider::build(&hand, &mesh).expect("collider");
        eprintln!(
            "collider: {} spheres, {} palm planes, {} fold tests, built in {:?}",
            collider.spheres().len(),
            collider.palm_planes().len(),
            collider.fold_tests(),
            start.elapsed()
        );
        let rest = skeleton.pose(&HandPose::FLAT);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&rest, d));
        let dominant: Vec<(Digit, f32)> = (0..hand.vertex_count())
            .map(|i| {
                let inf = hand
                    .influences(i)
                    .max_by(|a, b| a.weight.total_cmp(&b.weight))
                    .expect("every vertex has an influence");
                (inf.digit, inf.t * sweeps[inf.digit.index()].length())
            })
            .collect();
        let digit_of = dominant
            .iter()
            .map(|&(d, arc)| (arc > sweeps[d.index()].joint_arc(2)).then_some((d, arc)))
            .collect();
        Fixture {
            skeleton,
            mesh,
            hand,
            collider,
            digit_of,
            dominant,
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

/// The collision spheres re-posed independently: `(digit, centre, radius)` with the centre
/// on the posed sweep at the sphere's arc.
fn posed_spheres(posed: &PosedSkeleton) -> Vec<(Digit, Vec3, f32)> {
    let sweeps = Digit::ALL.map(|d| Sweep::of_digit(posed, d));
    fixture()
        .collider
        .spheres()
        .iter()
        .map(|s| {
            (
                s.digit,
                sweeps[s.digit.index()].frame_at_arc(s.arc).position,
                s.radius,
            )
        })
        .collect()
}

/// Brute force: vertices of one digit more than `tol` inside a sphere of another digit shrunk
/// by `shrink[k]`, and the deepest penetration.
fn digit_penetrations(
    positions: &[Vec3],
    spheres: &[(Digit, Vec3, f32)],
    shrink: &[f32],
    tol: f32,
) -> (usize, f32) {
    let f = fixture();
    let mut count = 0;
    let mut deepest = 0.0f32;
    for (v, class) in positions.iter().zip(&f.digit_of) {
        let Some((digit, _)) = *class else { continue };
        let mut inside = false;
        for (&(d, c, r), s) in spheres.iter().zip(shrink) {
            let pen = r - s - (*v - c).length();
            if d != digit && pen > tol {
                inside = true;
                deepest = deepest.max(pen);
            }
        }
        count += usize::from(inside);
    }
    (count, deepest)
}

/// Brute force: overlapping sphere pairs of different digits.
fn sphere_overlaps(spheres: &[(Digit, Vec3, f32)]) -> Vec<(usize, usize, f32)> {
    let mut out = Vec::new();
    for (i, a) in spheres.iter().enumerate() {
        for (j, b) in spheres.iter().enumerate().skip(i + 1) {
            let depth = a.2 + b.2 - (a.1 - b.1).length();
            if a.0 != b.0 && depth > 0.0 {
                out.push((i, j, depth));
            }
        }
    }
    out
}

/// The fold check of LYK06 "Folding at joints" by brute force: vertices whose dominant
/// influence is `digit` on the wrong side of the plane of chain joint `j` (`t < t_J` distal
/// of it, or `t > t_J` proximal), among those with a rest arc in `window`.
fn folded(
    positions: &[Vec3],
    posed: &PosedSkeleton,
    digit: Digit,
    j: usize,
    window: (f32, f32),
) -> usize {
    let sweep = Sweep::of_digit(posed, digit);
    let s_j = sweep.joint_arc(j);
    let frame = sweep.frame_at_arc(s_j);
    let normal = frame.rotation * Vec3::Y;
    positions
        .iter()
        .zip(&fixture().dominant)
        .filter(|&(v, &(d, arc))| {
            let h = normal.dot(*v - frame.position);
            d == digit
                && arc > window.0
                && arc < window.1
                && ((arc < s_j && h > 1e-6) || (arc > s_j && h < -1e-6))
        })
        .count()
}

#[test]
fn joint_at_its_limit_has_no_fold_after_the_fix() {
    let f = fixture();
    let limits = JointLimits::adult();
    let options = CollideOptions {
        digits: false,
        palm: false,
        ..CollideOptions::default()
    };
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    // One interphalangeal joint at a time at its flexion limit, every other angle zero: every
    // vertex bound to the digit is checked (nothing else bends, so nothing else may cross).
    let mut total_before = 0;
    for digit in Digit::ALL {
        for (k, &joint) in digit.joints().iter().enumerate().skip(2) {
            let d = dof(joint, DofKind::Flexion);
            let mut pose = HandPose::FLAT;
            pose.set(d, limits.range(d).1);
            let posed = f.skeleton.pose(&pose);
            let mut out = deform(&pose);
            let j = k + 1;
            let all = (f32::NEG_INFINITY, f32::INFINITY);
            let before = folded(&out, &posed, digit, j, all);
            let stats = collider.apply(&posed, &mut out, &options, &mut contacts);
            let after = folded(&out, &posed, digit, j, all);
            eprintln!(
                "{joint} at {:.0}°: {before} folded vertices before, {after} after ({} projections)",
                limits.range(d).1.to_degrees(),
                stats.folded
            );
            assert_eq!(after, 0, "{joint}: folded vertices left");
            assert!(
                stats.folded >= before,
                "{joint}: projected fewer than folded"
            );
            total_before += before;
        }
    }
    // The PIP of the brief: the index PIP at its limit does fold the palmar skin.
    assert!(
        total_before > 0,
        "no joint at its limit folds: the check is vacuous"
    );
    // Every PIP and DIP at its limit together: the fingertip now curls back across the PIP
    // plane without being folded, so only the two bones adjacent to each joint are checked.
    let mut pose = HandPose::FLAT;
    for digit in Digit::ALL {
        for &joint in &digit.joints()[2..] {
            let d = dof(joint, DofKind::Flexion);
            pose.set(d, limits.range(d).1);
        }
    }
    let posed = f.skeleton.pose(&pose);
    let mut out = deform(&pose);
    let raw = out.clone();
    collider.apply(&posed, &mut out, &options, &mut contacts);
    for digit in Digit::ALL {
        let sweep = Sweep::of_digit(&posed, digit);
        for j in 3..digit.chain_len() - 1 {
            let window = (sweep.joint_arc(j - 1), sweep.joint_arc(j + 1));
            let before = folded(&raw, &posed, digit, j, window);
            let after = folded(&out, &posed, digit, j, window);
            eprintln!("all at limits, {digit:?} joint {j}: {before} folded before, {after} after");
            assert_eq!(after, 0, "{digit:?} joint {j}: folded vertices left");
        }
    }
}

#[test]
fn fist_digits_leave_each_others_spheres() {
    let f = fixture();
    let pose = HandPose::named(NamedPose::Fist);
    let posed = f.skeleton.pose(&pose);
    let raw = deform(&pose);
    let spheres = posed_spheres(&posed);
    let zero = vec![0.0; spheres.len()];
    let (before, deepest) = digit_penetrations(&raw, &spheres, &zero, 1e-6);
    eprintln!("fist: {before} digit vertices inside other digits' spheres, deepest {deepest} m");
    assert!(
        before > 0,
        "the fist has no interpenetration: the check is vacuous"
    );

    // Detection: exactly the overlapping pairs found by brute force.
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    let full = CollideOptions {
        share: 0.0,
        ..CollideOptions::default()
    };
    let mut out = raw.clone();
    let stats = collider.apply(&posed, &mut out, &full, &mut contacts);
    let overlaps = sphere_overlaps(&spheres);
    let mut found: Vec<(usize, usize, f32)> = contacts
        .iter()
        .filter_map(|c| match c.kind {
            ContactKind::DigitDigit { a, b } => Some((a.min(b), a.max(b), c.depth)),
            _ => None,
        })
        .collect();
    found.sort_by_key(|x| (x.0, x.1));
    assert_eq!(found.len(), overlaps.len(), "digit-digit contacts");
    for (x, y) in found.iter().zip(&overlaps) {
        assert_eq!((x.0, x.1), (y.0, y.1));
        assert!((x.2 - y.2).abs() < 1e-6, "depth {} vs {}", x.2, y.2);
    }
    for c in &contacts {
        if let ContactKind::DigitDigit { a, b } = c.kind {
            // The middle of the overlap on the line of centres.
            let (ca, ra) = (spheres[a].1, spheres[a].2);
            assert!(((c.point - ca).length() - (ra - 0.5 * c.depth)).abs() < 1e-5);
            assert!((c.normal - (spheres[b].1 - ca).normalize()).length() < 1e-5);
        }
    }
    let palm = contacts
        .iter()
        .filter(|c| matches!(c.kind, ContactKind::DigitPalm { .. }))
        .count();
    let (after, left) = digit_penetrations(&out, &spheres, &zero, 1e-6);
    eprintln!(
        "fist, share 0: {} digit-digit and {palm} digit-palm contacts, {} vertices pushed, \
         {after} left inside (deepest {left} m)",
        overlaps.len(),
        stats.pushed
    );
    assert_eq!(after, 0, "vertices left inside other digits' spheres");

    // Split push (share 0.5, digits only): every digit vertex is outside (to 0.1 mm) every
    // other digit's sphere shrunk by half its deepest overlap, and at least half of the worst overlap was
    // resolved.
    let mut shrink = zero.clone();
    for &(i, j, depth) in &overlaps {
        shrink[i] = f32::max(shrink[i], 0.5 * depth);
        shrink[j] = f32::max(shrink[j], 0.5 * depth);
    }
    let mut out = raw.clone();
    let split = CollideOptions {
        fix_folds: false,
        palm: false,
        ..CollideOptions::default()
    };
    let stats = collider.apply(&posed, &mut out, &split, &mut contacts);
    // Pushes in the wedge between two touching primitives converge geometrically; the
    // MAX_PUSHES pushes leave a few vertices tens of micrometres deep.
    let (after, over) = digit_penetrations(&out, &spheres, &shrink, 1e-4);
    let (inside_full, left) = digit_penetrations(&out, &spheres, &zero, 1e-6);
    eprintln!(
        "fist, share 0.5: {} pushed, {inside_full} still inside the full spheres (deepest {left} m)",
        stats.pushed
    );
    assert_eq!(
        after, 0,
        "vertices left inside the shrunk spheres, deepest {over} m"
    );
    let max_overlap = overlaps.iter().map(|o| o.2).fold(0.0f32, f32::max);
    assert!(
        left <= 0.5 * max_overlap + 1e-6,
        "{left} > half of {max_overlap}"
    );

    // The contact list keeps its capacity: the same frame again does not grow it.
    let capacity = contacts.capacity();
    let mut again = raw.clone();
    collider.apply(&posed, &mut again, &split, &mut contacts);
    assert_eq!(contacts.capacity(), capacity);
}

#[test]
fn flat_and_spread_hands_have_no_contact() {
    let f = fixture();
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    for named in [NamedPose::Flat, NamedPose::Spread] {
        let pose = HandPose::named(named);
        let raw = deform(&pose);
        let mut out = raw.clone();
        let stats = collider.apply_pose(&pose, &mut out, &CollideOptions::default(), &mut contacts);
        assert_eq!(stats.contacts, 0, "{named}: {contacts:?}");
        assert_eq!(stats.folded, 0, "{named}");
        assert_eq!(stats.pushed, 0, "{named}");
        assert_eq!(out, raw, "{named}: the skin moved");
    }
}

#[test]
fn ball_pushes_the_skin_out() {
    let f = fixture();
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    let pose = HandPose::named(NamedPose::Relaxed);
    let posed = f.skeleton.pose(&pose);
    let raw = deform(&pose);
    // The most palmar skin point near (x, y): where a ball below the hand first touches it.
    let palmar = |x: f32, y: f32| {
        raw.iter()
            .filter(|v| (v.x - x).abs() < 0.008 && (v.y - y).abs() < 0.008)
            .map(|v| v.z)
            .fold(f32::INFINITY, f32::min)
    };
    for (name, ball) in [
        (
            "palm",
            Ball {
                center: Vec3::new(0.0, 0.05, palmar(0.0, 0.05) - 0.025 + 0.006),
                radius: 0.025,
            },
        ),
        (
            "palm and fingers",
            Ball {
                center: Vec3::new(0.005, 0.095, palmar(0.005, 0.095) - 0.03 + 0.01),
                radius: 0.03,
            },
        ),
    ] {
        let inside = |p: &[Vec3]| {
            p.iter()
                .filter(|v| (**v - ball.center).length() < ball.radius - 1e-6)
                .count()
        };
        let before = inside(&raw);
        let options = CollideOptions {
            object: Some(ball),
            ..CollideOptions::default()
        };
        let mut out = raw.clone();
        let stats = collider.apply(&posed, &mut out, &options, &mut contacts);
        let object: Vec<&Contact> = contacts
            .iter()
            .filter(|c| {
                matches!(
                    c.kind,
                    ContactKind::ObjectDigit { .. } | ContactKind::ObjectPalm { .. }
                )
            })
            .collect();
        let on_digits = object
            .iter()
            .filter(|c| matches!(c.kind, ContactKind::ObjectDigit { .. }))
            .count();
        let after = inside(&out);
        eprintln!(
            "ball ({name}): {before} vertices inside before, {} contacts ({on_digits} on \
             digits), {} pushed, {after} inside after",
            object.len(),
            stats.pushed
        );
        assert!(before > 0, "{name}: the ball misses the hand");
        assert!(!object.is_empty(), "{name}: no contact");
        for c in &object {
            let r = (c.point - ball.center).length();
            assert!(
                (r - ball.radius).abs() < 1e-5,
                "{name}: contact {r} m from the centre"
            );
            assert!(c.depth > 0.0 && (c.normal.length() - 1.0).abs() < 1e-5);
        }
        assert_eq!(after, 0, "{name}: skin left inside the ball");
    }
}

#[test]
fn sampled_poses_stay_finite_and_resolved() {
    let f = fixture();
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    let mut sampler = PoseSampler::new(0x5eed_c011);
    let mut out = vec![Vec3::ZERO; f.hand.vertex_count()];
    let mut posed = PosedSkeleton::default();
    let full = CollideOptions {
        share: 0.0,
        ..CollideOptions::default()
    };
    let (mut folded, mut touching, mut pushed, mut checked) = (0, 0, 0, 0);
    for k in 0..1000 {
        let pose = sampler.sample();
        f.skeleton.pose_into(&pose, &mut posed);
        f.hand.deform_into(&pose, &mut out);
        let options = if k % 2 == 0 {
            CollideOptions {
                object: Some(Ball {
                    center: Vec3::new(0.0, 0.07, -0.045),
                    radius: 0.03,
                }),
                ..CollideOptions::default()
            }
        } else {
            full
        };
        let stats = collider.apply(&posed, &mut out, &options, &mut contacts);
        assert!(
            out.iter().all(|v| v.is_finite()),
            "pose {k}: non-finite position"
        );
        assert!(
            contacts
                .iter()
                .all(|c| c.point.is_finite() && c.normal.is_finite() && c.depth.is_finite())
        );
        folded += stats.folded;
        pushed += stats.pushed;
        touching += usize::from(stats.contacts > 0);
        // Every 10th full-push frame: no digit vertex is left in another digit's spheres.
        if k % 20 == 1 {
            let spheres = posed_spheres(&posed);
            let (inside, deepest) =
                digit_penetrations(&out, &spheres, &vec![0.0; spheres.len()], 1e-6);
            assert_eq!(
                inside, 0,
                "pose {k}: {inside} vertices left, deepest {deepest} m"
            );
            checked += 1;
        }
    }
    eprintln!(
        "1000 poses: {touching} with contacts, {folded} projections, {pushed} vertices pushed, \
         {checked} checked by brute force"
    );
}

/// Per-frame cost of `apply` in the fist (single thread; `deform_into` is not parallel).
/// `cargo test --release -p crease-hand --test all -- --ignored --nocapture sweep_collide::apply_timing`
#[test]
#[ignore = "timing, not a check"]
fn apply_timing() {
    let f = fixture();
    let mut collider = f.collider.clone();
    let mut contacts = Vec::new();
    for named in [NamedPose::Fist, NamedPose::Flat, NamedPose::Grasp] {
        let pose = HandPose::named(named);
        let posed = f.skeleton.pose(&pose);
        let raw = deform(&pose);
        let mut out = raw.clone();
        let frames = 2000;
        let time = |f: &mut dyn FnMut()| {
            for _ in 0..100 {
                f();
            }
            let start = Instant::now();
            for _ in 0..frames {
                f();
            }
            start.elapsed().as_secs_f64() * 1e6 / frames as f64
        };
        let copy = time(&mut || out.copy_from_slice(&raw));
        let apply = time(&mut || {
            out.copy_from_slice(&raw);
            collider.apply(&posed, &mut out, &CollideOptions::default(), &mut contacts);
        });
        let folds_only = CollideOptions {
            digits: false,
            palm: false,
            ..CollideOptions::default()
        };
        let folds = time(&mut || {
            out.copy_from_slice(&raw);
            collider.apply(&posed, &mut out, &folds_only, &mut contacts);
        });
        let detect_only = CollideOptions {
            resolve: false,
            ..CollideOptions::default()
        };
        let detect = time(&mut || {
            out.copy_from_slice(&raw);
            collider.apply(&posed, &mut out, &detect_only, &mut contacts);
        });
        let deform = time(&mut || f.hand.deform_into(&pose, &mut out));
        eprintln!(
            "{named}: apply {:.1} µs (folds only {:.1}, folds + detection {:.1}; copy \
             {copy:.1} µs subtracted), deform_into {deform:.1} µs, {} vertices, {} contacts",
            apply - copy,
            folds - copy,
            detect - copy,
            raw.len(),
            contacts.len()
        );
    }
}

#[test]
fn wrong_mesh_is_an_error() {
    let f = fixture();
    let mut mesh = f.mesh.clone();
    mesh.positions.pop();
    assert!(matches!(
        HandCollider::build(&f.hand, &mesh),
        Err(CollideError::VertexCount { .. })
    ));
}
