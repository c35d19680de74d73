//! Displacement extraction of the base/detail split (`crease_train::detail`, HZY11 §4):
//! a target built as `v + h n` gives back `h`; concentric spheres give the radius difference
//! within the target's tessellation sag; where the normal misses an open target the value is
//! the closest point's offset, checked against a brute-force closest point over every target
//! triangle; the maximum distance is respected; bad input is refused by index; and the base
//! sweep hand measured against the detailed one gives sub-millimetre displacements (timed).

use crate::common;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_hand::rig::{HandRig, Layers};
use crease_hand::skeleton::{HandPose, NamedPose};
use crease_hand::surface::Resolution;
use crease_train::detail::{
    DetailError, DetailExample, DisplacementSource, DisplacementTarget, ExtractStats, extract_all,
};

/// The unit icosphere of `common` as positions and triangles.
fn icosphere(level: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let m = common::icosphere(level);
    (m.positions, m.triangles)
}

/// A UV sphere of `radius`: `slices` around z, `stacks` rows from the north pole down to the
/// polar angle `stacks / full_stacks * pi` (the whole sphere when equal, the northern
/// hemisphere, open at the equator, when `stacks = full_stacks / 2`). Outward triangles.
fn uv_sphere(
    radius: f32,
    slices: u32,
    stacks: u32,
    full_stacks: u32,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = vec![Vec3::Z * radius];
    for i in 1..=stacks.min(full_stacks - 1) {
        let theta = std::f32::consts::PI * i as f32 / full_stacks as f32;
        for j in 0..slices {
            let phi = std::f32::consts::TAU * j as f32 / slices as f32;
            p.push(
                radius
                    * Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ),
            );
        }
    }
    let ring = |i: u32, j: u32| 1 + (i - 1) * slices + j % slices;
    let mut t = Vec::new();
    for j in 0..slices {
        t.push([0, ring(1, j), ring(1, j + 1)]);
    }
    let rows = stacks.min(full_stacks - 1);
    for i in 1..rows {
        for j in 0..slices {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            t.push([a, c, d]);
            t.push([a, d, b]);
        }
    }
    if stacks == full_stacks {
        p.push(-Vec3::Z * radius);
        let south = (p.len() - 1) as u32;
        for j in 0..slices {
            t.push([south, ring(rows, j + 1), ring(rows, j)]);
        }
    }
    (p, t)
}

/// Closest point to `p` on triangle `abc` (Ericson, Real-Time Collision Detection §5.1.5),
/// in f64.
fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (p, a, b, c) = (p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a.as_vec3();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b.as_vec3();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (a + ab * (d1 / (d1 - d3))).as_vec3();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c.as_vec3();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (a + ac * (d2 / (d2 - d6))).as_vec3();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))).as_vec3();
    }
    let denom = 1.0 / (va + vb + vc);
    (a + ab * (vb * denom) + ac * (vc * denom)).as_vec3()
}

/// Brute-force closest point on a triangle soup.
fn closest_on_mesh(p: Vec3, positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec3 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|k| positions[k as usize]);
            closest_on_triangle(p, a, b, c)
        })
        .min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p)))
        .expect("non-empty mesh")
}

/// How far inside its circumscribed sphere a polyhedron with vertices on a sphere of radius
/// `radius` about the origin dips: `radius` minus the smallest distance from the origin to a
/// triangle's plane (bounds the distance from any surface point to the origin from below).
fn sag(radius: f32, positions: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    let min_plane = triangles
        .iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|k| positions[k as usize].as_dvec3());
            let n = (b - a).cross(c - a).try_normalize()?;
            Some(n.dot(a).abs())
        })
        .fold(f64::INFINITY, f64::min);
    radius - min_plane as f32
}

fn displacements(
    target: &DisplacementTarget,
    points: &[Vec3],
    normals: &[Vec3],
    max_distance: f32,
) -> (Vec<f32>, ExtractStats) {
    let mut h = vec![f32::NAN; points.len()];
    let stats = target
        .displacements(points, normals, max_distance, &mut h)
        .expect("valid input");
    (h, stats)
}

/// A smooth displacement field on the unit sphere, about ±4 % of the radius.
fn h_field(d: Vec3) -> f32 {
    0.03 * ((3.0 * d.x + 1.0).sin() * (2.0 * d.y).cos() + 0.5 * d.z * d.z - 0.2)
}

#[test]
fn target_built_as_point_plus_h_normal_gives_h_back() {
    let radius = 0.7;
    let (dirs, triangles) = icosphere(4);
    let points: Vec<Vec3> = dirs.iter().map(|&d| d * radius).collect();
    let h_true: Vec<f32> = dirs.iter().map(|&d| radius * h_field(d)).collect();
    let target_positions: Vec<Vec3> = points
        .iter()
        .zip(&dirs)
        .zip(&h_true)
        .map(|((&p, &n), &h)| p + h * n)
        .collect();
    assert!(
        h_true.iter().any(|&h| h > 0.02 * radius) && h_true.iter().any(|&h| h < -0.02 * radius)
    );

    let target = DisplacementTarget::new(&target_positions, &triangles).unwrap();
    let (h, stats) = displacements(&target, &points, &dirs, 0.2 * radius);
    assert_eq!(stats.hits, points.len());
    assert_eq!(stats.fallbacks, 0);
    let worst = h
        .iter()
        .zip(&h_true)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    println!(
        "exact displaced icosphere: {} vertices, max |h - h_true| = {:.2e} R",
        points.len(),
        worst / radius
    );
    assert!(worst <= 1e-5 * radius, "max error {worst}");
    let max_true = h_true.iter().map(|h| h.abs()).fold(0.0, f32::max);
    assert!((stats.max_abs - max_true).abs() <= 1e-5 * radius);
}

#[test]
fn concentric_spheres_give_the_radius_difference_within_the_sag() {
    let radius = 1.0;
    let (dirs, _) = icosphere(3);
    let points: Vec<Vec3> = dirs.iter().map(|&d| d * radius).collect();
    for delta in [0.03f32, -0.03] {
        let (tp, tt) = uv_sphere(radius + delta, 48, 24, 24);
        let sag = sag(radius + delta, &tp, &tt);
        assert!(sag > 0.0 && sag < delta.abs() / 5.0, "sag {sag}");
        let target = DisplacementTarget::new(&tp, &tt).unwrap();
        let (h, stats) = displacements(&target, &points, &dirs, 0.2);
        assert_eq!((stats.hits, stats.fallbacks), (points.len(), 0));
        let (lo, hi) = h
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        println!(
            "concentric delta {delta:+}: h in [{lo:.5}, {hi:.5}], allowed [{:.5}, {delta:.5}] (sag {sag:.5})",
            delta - sag
        );
        // A ray from radius R along the radial direction meets the inscribed polyhedron at a
        // point whose distance from the centre is between R + delta - sag and R + delta.
        for (i, &x) in h.iter().enumerate() {
            assert!(
                x >= delta - sag - 1e-5 && x <= delta + 1e-5,
                "vertex {i}: h = {x}, delta {delta}, sag {sag}"
            );
        }
    }
}

#[test]
fn rays_that_miss_an_open_target_fall_back_to_the_closest_point() {
    let (radius, delta, max_distance) = (1.0, 0.1, 0.3);
    let (dirs, _) = icosphere(3);
    let points: Vec<Vec3> = dirs.iter().map(|&d| d * radius).collect();
    // The northern half of a sphere of radius R + delta, open at the equator.
    let (tp, tt) = uv_sphere(radius + delta, 40, 10, 20);
    let sag = sag(radius + delta, &tp, &tt);
    let target = DisplacementTarget::new(&tp, &tt).unwrap();
    let (h, stats) = displacements(&target, &points, &dirs, max_distance);
    assert_eq!(stats.hits + stats.fallbacks, points.len());

    let mut fallbacks = 0;
    let mut worst: f32 = 0.0;
    for (i, (&p, &n)) in points.iter().zip(&dirs).enumerate() {
        let one = target.displacement(p, n, max_distance).unwrap();
        assert_eq!(
            one.h.to_bits(),
            h[i].to_bits(),
            "vertex {i}: batch vs single"
        );
        assert!(h[i].is_finite());
        if p.z > 0.05 {
            assert_eq!(
                one.source,
                DisplacementSource::Ray,
                "vertex {i} at z = {}",
                p.z
            );
            assert!(h[i] >= delta - sag - 1e-5 && h[i] <= delta + 1e-5);
        }
        if p.z < -0.05 {
            assert_eq!(
                one.source,
                DisplacementSource::Closest,
                "vertex {i} at z = {}",
                p.z
            );
        }
        if one.source == DisplacementSource::Closest {
            fallbacks += 1;
            let expected = (closest_on_mesh(p, &tp, &tt) - p).dot(n);
            worst = worst.max((h[i] - expected).abs());
            assert!(
                (h[i] - expected).abs() <= 1e-5 * radius,
                "vertex {i}: h = {}, brute force {expected}",
                h[i]
            );
        }
    }
    println!(
        "hemisphere target: {} of {} vertices fell back, max |h - brute force| = {worst:.2e}",
        stats.fallbacks,
        points.len()
    );
    assert_eq!(stats.fallbacks, fallbacks);
    assert!(fallbacks >= points.iter().filter(|p| p.z < -0.05).count());
    assert!(fallbacks > points.len() / 3 && fallbacks < 2 * points.len() / 3);
}

#[test]
fn max_distance_is_respected() {
    let (radius, delta) = (1.0, 0.1);
    let (dirs, _) = icosphere(2);
    let points: Vec<Vec3> = dirs.iter().map(|&d| d * radius).collect();
    let (tp, tt) = uv_sphere(radius + delta, 32, 16, 16);
    let target = DisplacementTarget::new(&tp, &tt).unwrap();

    // Every hit lies between delta - sag and delta: a search shorter than that finds none.
    let (h, stats) = displacements(&target, &points, &dirs, 0.05);
    assert_eq!((stats.hits, stats.fallbacks), (0, points.len()));
    for (i, (&p, &n)) in points.iter().zip(&dirs).enumerate() {
        let expected = (closest_on_mesh(p, &tp, &tt) - p).dot(n);
        assert!(
            (h[i] - expected).abs() <= 1e-5,
            "vertex {i}: {} vs {expected}",
            h[i]
        );
    }
    // Long enough, or unbounded: all hit.
    for max_distance in [0.2, f32::INFINITY] {
        let (_, stats) = displacements(&target, &points, &dirs, max_distance);
        assert_eq!((stats.hits, stats.fallbacks), (points.len(), 0));
    }
    // The far side (about 2R + delta away along -n) is not reached with 0.3 even when the near
    // side is excluded; a point outside the target shows it: along -n the near wall is at
    // 0.4, the far wall at 2.6.
    let outside = target.displacement(Vec3::X * 1.5, Vec3::X, 0.3).unwrap();
    assert_eq!(outside.source, DisplacementSource::Closest);
    let reached = target.displacement(Vec3::X * 1.5, Vec3::X, 0.45).unwrap();
    assert_eq!(reached.source, DisplacementSource::Ray);
    assert!(reached.h < -0.39 && reached.h > -0.41, "{reached:?}");
}

#[test]
fn bad_input_is_refused_by_index() {
    let (dirs, triangles) = icosphere(1);
    let target = DisplacementTarget::new(&dirs, &triangles).unwrap();
    let mut out = vec![0.0; dirs.len()];

    let mut points = dirs.clone();
    points[7].y = f32::NAN;
    let err = target
        .displacements(&points, &dirs, 1.0, &mut out)
        .unwrap_err();
    assert_eq!(
        err,
        DetailError::NotFinite {
            what: "point",
            index: 7
        }
    );
    assert_eq!(err.to_string(), "point 7 is not finite");
    assert!(out.iter().all(|&x| x == 0.0), "nothing written on error");

    let mut normals = dirs.clone();
    normals[11] = Vec3::new(0.0, f32::INFINITY, 0.0);
    let err = target
        .displacements(&dirs, &normals, 1.0, &mut out)
        .unwrap_err();
    assert_eq!(err.to_string(), "normal 11 is not finite");

    let err = target
        .displacements(&dirs, &dirs, f32::NAN, &mut out)
        .unwrap_err();
    assert!(matches!(err, DetailError::MaxDistance(x) if x.is_nan()));
    let err = target
        .displacements(&dirs, &dirs, 1.0, &mut out[1..])
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "out vs points: expected {}, got {}",
            dirs.len(),
            dirs.len() - 1
        )
    );

    let mut bad_target = dirs.clone();
    bad_target[2].z = f32::NAN;
    let good = DetailExample {
        points: &dirs,
        normals: &dirs,
        target_positions: &dirs,
        target_triangles: &triangles,
    };
    let bad = DetailExample {
        target_positions: &bad_target,
        ..good
    };
    let mut seen = Vec::new();
    let err = extract_all(&[good, bad, good], 1.0, |p| seen.push(p.example)).unwrap_err();
    assert_eq!(err.to_string(), "example 1: target vertex 2 is not finite");
    assert_eq!(seen, [0]);
    let empty = DetailExample {
        target_triangles: &[],
        ..good
    };
    let err = extract_all(&[empty], 1.0, |_| {}).unwrap_err();
    assert_eq!(
        err.to_string(),
        "example 0: target mesh has no non-degenerate triangles"
    );
}

#[test]
fn extract_all_matches_one_example_at_a_time() {
    let (dirs, triangles) = icosphere(2);
    let points: Vec<Vec3> = dirs.iter().map(|&d| d * 0.9).collect();
    let (tp, tt) = uv_sphere(1.0, 24, 12, 12);
    let examples = [
        DetailExample {
            points: &points,
            normals: &dirs,
            target_positions: &tp,
            target_triangles: &tt,
        },
        DetailExample {
            points: &dirs,
            normals: &dirs,
            target_positions: &points,
            target_triangles: &triangles,
        },
    ];
    let mut seen = Vec::new();
    let all = extract_all(&examples, 0.5, |p| seen.push((p.example, p.total, p.stats))).unwrap();
    assert_eq!(all.len(), 2);
    for (k, ex) in examples.iter().enumerate() {
        let target = DisplacementTarget::new(ex.target_positions, ex.target_triangles).unwrap();
        let (h, stats) = displacements(&target, ex.points, ex.normals, 0.5);
        assert_eq!(all[k].h, h);
        assert_eq!(all[k].stats, stats);
        assert_eq!(seen[k], (k, 2, stats));
    }
    // The second target is the first's points shrunk to 0.9: h = -0.1 exactly at vertices.
    assert!(all[1].h.iter().all(|h| (h + 0.1).abs() < 1e-5));
}

/// Brute-force nearest signed ray hit along `+n` / `-n` within `max_distance` over every
/// triangle (Möller-Trumbore in f64, a point on an edge or vertex counts), or `None`.
fn ray_brute(
    p: Vec3,
    n: Vec3,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    max_distance: f32,
) -> Option<f32> {
    let (o, n) = (p.as_dvec3(), n.as_dvec3());
    let mut best: Option<f64> = None;
    for t in triangles {
        let [a, b, c] = t.map(|k| positions[k as usize].as_dvec3());
        let (e1, e2) = (b - a, c - a);
        let det = -n.dot(e1.cross(e2));
        if det == 0.0 {
            continue;
        }
        // o + t n = a + u e1 + v e2, by Cramer's rule.
        let s = o - a;
        let t = s.dot(e1.cross(e2)) / det;
        let u = -n.dot(s.cross(e2)) / det;
        let v = -n.dot(e1.cross(s)) / det;
        let inside = u >= -1e-9 && v >= -1e-9 && u + v <= 1.0 + 1e-9;
        if inside
            && t.abs() < max_distance as f64
            && best.is_none_or(|b| t.abs() < b.abs() || (t.abs() == b.abs() && t > b))
        {
            best = Some(t);
        }
    }
    best.map(|t| t as f32)
}

/// Percentile of sorted values (nearest rank).
fn percentile(sorted: &[f32], q: f32) -> f32 {
    sorted[((q * (sorted.len() - 1) as f32).round() as usize).min(sorted.len() - 1)]
}

/// The real case (DESIGN.md data flow step 2 on the generated hand): the base sweep hand's
/// vertices measured against the detailed sweep hand in the same pose. Both polygonise the
/// same implicit surface (grid spacing 2.5 mm vs 0.6 mm), so `h` is the polygonisation
/// difference plus the detailed hand's creases, and where the collision layer pushes skin
/// out of contact, its (resolution-dependent) push-out. Every hit of a sample, and every
/// outlier, is checked against a brute-force ray cast or closest point over the whole target.
/// Timings: run with `RAYON_NUM_THREADS=1` for single-thread numbers.
#[test]
fn base_hand_against_detailed_hand_is_sub_millimetre() {
    let t0 = Instant::now();
    let base = HandRig::build(Resolution::Base).expect("base hand");
    let detailed = HandRig::build(Resolution::Detailed).expect("detailed hand");
    println!(
        "hands built in {:.1} s: base {} vertices, detailed {} vertices",
        t0.elapsed().as_secs_f32(),
        base.vertex_count(),
        detailed.vertex_count()
    );
    // Two base grid cells: far beyond the polygonisation difference, well under a finger's
    // radius (about 8 mm), so a ray does not reach the far side of a finger.
    let max_distance = 0.005;
    for (name, pose, creases) in [
        ("relaxed", NamedPose::Relaxed, true),
        ("fist", NamedPose::Fist, true),
        ("fist, detailed without creases", NamedPose::Fist, false),
    ] {
        let pose = HandPose::named(pose);
        let b = base.posed_mesh(&pose, Layers::default());
        let layers = Layers {
            creases,
            ..Layers::default()
        };
        let d = detailed.posed_mesh(&pose, layers);
        let normals = b.vertex_normals();

        let t = Instant::now();
        let target = DisplacementTarget::new(&d.positions, &d.triangles).unwrap();
        let build = t.elapsed();
        let t = Instant::now();
        let (h, stats) = displacements(&target, &b.positions, &normals, max_distance);
        let query = t.elapsed();
        let (_, short) = displacements(&target, &b.positions, &normals, 0.002);

        let mut abs: Vec<f32> = h.iter().map(|x| x.abs()).collect();
        abs.sort_by(f32::total_cmp);
        let mm = |x: f32| x * 1e3;
        let over_1mm = abs.iter().filter(|&&x| x > 1e-3).count();
        println!(
            "{name}: {} hits, {} fallbacks ({} with max_distance 2 mm); |h| mm: median {:.3}, \
             p90 {:.3}, p99 {:.3}, p99.9 {:.3}, max {:.3}; {over_1mm} over 1 mm; signed mean \
             {:+.4} mm; BVH build {:.1} ms, {} vertices {:.1} ms ({:.2} us/vertex)",
            stats.hits,
            stats.fallbacks,
            short.fallbacks,
            mm(percentile(&abs, 0.5)),
            mm(percentile(&abs, 0.9)),
            mm(percentile(&abs, 0.99)),
            mm(percentile(&abs, 0.999)),
            mm(stats.max_abs),
            mm(h.iter().sum::<f32>() / h.len() as f32),
            build.as_secs_f64() * 1e3,
            h.len(),
            query.as_secs_f64() * 1e3,
            query.as_secs_f64() * 1e6 / h.len() as f64,
        );

        // Independently, by brute force over every target triangle: a sample of vertices and
        // every outlier (|h| > 1 mm or a fallback).
        let step = h.len() / 24;
        let mut checked = 0;
        for i in 0..h.len() {
            let one = target
                .displacement(b.positions[i], normals[i], max_distance)
                .unwrap();
            assert_eq!(one.h.to_bits(), h[i].to_bits(), "{name}: vertex {i}");
            let outlier = abs_gt(h[i], 1e-3) || one.source == DisplacementSource::Closest;
            if i % step != 0 && !outlier {
                continue;
            }
            checked += 1;
            let (p, n) = (b.positions[i], normals[i]);
            match ray_brute(p, n, &d.positions, &d.triangles, max_distance) {
                Some(expected) => {
                    assert_eq!(one.source, DisplacementSource::Ray, "{name}: vertex {i}");
                    assert!(
                        (h[i] - expected).abs() < 1e-6,
                        "{name}: vertex {i}: {} vs {expected}",
                        h[i]
                    );
                }
                None => {
                    assert_eq!(
                        one.source,
                        DisplacementSource::Closest,
                        "{name}: vertex {i}"
                    );
                    let expected = (closest_on_mesh(p, &d.positions, &d.triangles) - p).dot(n);
                    assert!(
                        (h[i] - expected).abs() < 1e-6,
                        "{name}: vertex {i}: {} vs {expected}",
                        h[i]
                    );
                }
            }
            if outlier {
                println!(
                    "  outlier vertex {i} (rest {:.4?}): h {:+.3} mm ({:?})",
                    base.rest().positions[i].to_array(),
                    mm(h[i]),
                    one.source
                );
            }
        }
        println!("{name}: {checked} vertices checked by brute force");

        if name == "relaxed" {
            // Production size: the detailed vertices (as many as a twice-subdivided base)
            // measured against the base mesh.
            let target = DisplacementTarget::new(&b.positions, &b.triangles).unwrap();
            let t = Instant::now();
            let (_, stats) =
                displacements(&target, &d.positions, &d.vertex_normals(), max_distance);
            println!(
                "{name}, reversed: {} detailed vertices onto the base mesh in {:.1} ms: {stats:?}",
                d.positions.len(),
                t.elapsed().as_secs_f64() * 1e3
            );
        }
        assert!(stats.fallbacks * 200 < h.len(), "{name}: {stats:?}");
        assert!(percentile(&abs, 0.5) < 0.05e-3, "{name}: median |h|");
        assert!(percentile(&abs, 0.99) < 1e-3, "{name}: p99 |h|");
    }
}

fn abs_gt(x: f32, limit: f32) -> bool {
    x.abs() > limit
}
