//! The shared fixture meshes against what their docs promise, computed independently here:
//! the tube's rings, radius, heights and outward triangles, the grid's order and winding, the
//! bend's rigid halves.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::collections::HashMap;

use crease_core::glam::Vec3;
use crease_testkit::mesh::{bend, grid, tetrahedron, tube, unit_grid};

/// The unit normal of triangle `t` of `positions`.
fn normal(positions: &[Vec3], t: [u32; 3]) -> Vec3 {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    (b - a).cross(c - a).normalize()
}

#[test]
fn tube_rings_sit_on_the_unit_cylinder_at_their_heights() {
    let (rings, around, length) = (5, 7, 3.0);
    let m = tube(rings, around, length);
    assert_eq!(m.vertex_count(), rings * around);
    for (i, p) in m.positions.iter().enumerate() {
        let (r, a) = (i / around, i % around);
        assert!(
            (p.truncate().length() - 1.0).abs() < 1e-6,
            "vertex {i}: {p}"
        );
        assert!((p.z - length * r as f32 / (rings - 1) as f32).abs() < 1e-6);
        let angle = p.y.atan2(p.x).rem_euclid(std::f32::consts::TAU);
        let want = std::f32::consts::TAU * a as f32 / around as f32;
        assert!(
            (angle - want).abs() < 1e-5,
            "vertex {i}: angle {angle} vs {want}"
        );
    }
    m.validate().unwrap();
}

#[test]
fn tube_triangles_face_out_and_close_every_ring() {
    let (rings, around) = (4, 6);
    let m = tube(rings, around, 2.0);
    assert_eq!(m.triangles.len(), 2 * (rings - 1) * around);
    for &t in &m.triangles {
        let centroid = t.map(|i| m.positions[i as usize]).iter().sum::<Vec3>() / 3.0;
        let out = centroid.truncate().extend(0.0).normalize();
        assert!(normal(&m.positions, t).dot(out) > 0.5, "{t:?} faces in");
    }
    // Open only at the two end rings: every other edge is shared by exactly two triangles.
    let mut uses: HashMap<(u32, u32), usize> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let end_ring = |v: u32| (v as usize) < around || (v as usize) >= (rings - 1) * around;
    for ((a, b), n) in uses {
        let boundary = end_ring(a) && end_ring(b) && (a as usize / around == b as usize / around);
        assert_eq!(n, if boundary { 1 } else { 2 }, "edge {a}-{b}");
    }
}

#[test]
fn grid_calls_at_in_index_order_and_winds_counter_clockwise() {
    let mut calls = Vec::new();
    let m = grid(4, 3, |i, j| {
        calls.push((i, j));
        Vec3::new(i as f32, j as f32, 0.0)
    });
    let want: Vec<(u32, u32)> = (0..3).flat_map(|j| (0..4).map(move |i| (i, j))).collect();
    assert_eq!(calls, want);
    assert_eq!(m.triangles.len(), 2 * 3 * 2);
    for &t in &m.triangles {
        assert!((normal(&m.positions, t) - Vec3::Z).length() < 1e-6, "{t:?}");
    }
    assert_eq!(m.triangles[0], [0, 1, 5]);
    assert_eq!(m.triangles[1], [0, 5, 4]);
}

#[test]
fn unit_grid_is_the_flat_grid_at_unit_spacing() {
    let m = unit_grid(5);
    assert_eq!(m, grid(5, 5, |i, j| Vec3::new(i as f32, j as f32, 0.0)));
    assert_eq!(m.positions[7], Vec3::new(2.0, 1.0, 0.0));
}

#[test]
fn bend_turns_the_upper_part_rigidly_and_leaves_the_rest() {
    let rest = tube(9, 8, 8.0);
    let pivot = 4.0;
    let bent = bend(&rest, pivot, 0.7);
    let centre = Vec3::new(0.0, 0.0, pivot);
    for (p, q) in rest.positions.iter().zip(&bent) {
        if p.z > pivot {
            assert!(((*q - centre).length() - (*p - centre).length()).abs() < 1e-5);
            assert!((q.x - p.x).abs() < 1e-6, "a turn about x keeps x");
            assert_ne!(p, q);
        } else {
            assert_eq!(p, q);
        }
    }
    assert_eq!(bend(&rest, pivot, 0.0), rest.positions);
}

#[test]
fn the_tetrahedron_is_regular() {
    let m = tetrahedron();
    m.validate().unwrap();
    let edge = (m.positions[0] - m.positions[1]).length();
    for t in &m.triangles {
        for k in 0..3 {
            let d = (m.positions[t[k] as usize] - m.positions[t[(k + 1) % 3] as usize]).length();
            assert!((d - edge).abs() < 1e-6);
        }
    }
}
