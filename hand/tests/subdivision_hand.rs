//! Loop subdivision (`crease_core::mesh::subdivision`) and the detail synthesis of HZY11 eq. 4
//! (`crease_core::runtime::detail`) on the base sweep hand: the tests of core's subdivision that
//! need a real hand mesh, which lives in this crate (core may not depend on it).
//!
//! Expected values come from independent computations here (f64 normals by a plain loop, exact
//! point-to-triangle distances), never from the code under test.

use crate::common;

use std::collections::HashMap;
use std::sync::OnceLock;

use crease_core::glam::{DVec3, Vec3};
use crease_core::mesh::Mesh;
use crease_core::runtime::detail::{DetailSynth, scatter_normals};
use crease_hand::surface::{HandSurface, Resolution};

use common::mesh_checks::{
    METHODS, assert_close, assert_closed_oriented_manifold, euler, reference_normals, subdivided,
};

fn base_hand() -> &'static HandSurface {
    static BASE: OnceLock<HandSurface> = OnceLock::new();
    BASE.get_or_init(|| HandSurface::build(Resolution::Base).expect("base surface builds"))
}

/// Closest point on triangle `abc` to `p` (Ericson, Real-Time Collision Detection, 5.1.5).
fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Distances from `points` to the triangle mesh `m`, exact as long as they stay below the cell
/// size `cell` (each point searches the 27 cells around it, and a triangle is filed in
/// every cell its bounding box touches). Panics if some point finds nothing that close.
fn distances_to_mesh(points: &[Vec3], m: &Mesh, cell: f64) -> Vec<f64> {
    let key = |p: DVec3| (p / cell).floor().as_ivec3();
    let mut cells: HashMap<_, Vec<usize>> = HashMap::new();
    for (ti, t) in m.triangles.iter().enumerate() {
        let q = t.map(|i| m.positions[i as usize].as_dvec3());
        let (lo, hi) = (key(q[0].min(q[1]).min(q[2])), key(q[0].max(q[1]).max(q[2])));
        for x in lo.x..=hi.x {
            for y in lo.y..=hi.y {
                for z in lo.z..=hi.z {
                    cells.entry((x, y, z)).or_default().push(ti);
                }
            }
        }
    }
    let mut out = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        let p = p.as_dvec3();
        let k = key(p);
        let mut best = f64::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(list) = cells.get(&(k.x + dx, k.y + dy, k.z + dz)) else {
                        continue;
                    };
                    for &ti in list {
                        let q = m.triangles[ti].map(|i| m.positions[i as usize].as_dvec3());
                        best = best.min((closest_on_triangle(p, q[0], q[1], q[2]) - p).length());
                    }
                }
            }
        }
        assert!(best < cell, "vertex {i}: nothing within {cell} m");
        out.push(best);
    }
    out
}

#[test]
fn base_hand_two_levels_is_closed_manifold_near_the_base_surface() {
    let hand = &base_hand().mesh;
    let spacing = base_hand().spacing as f64;
    let (v, f) = (hand.vertex_count(), hand.triangles.len());
    let (s, high) = subdivided(hand, 2);
    assert_eq!(s.triangles().len(), 16 * f);
    assert_eq!(
        euler(s.vertex_count(), s.triangles()),
        euler(v, &hand.triangles)
    );
    assert_closed_oriented_manifold(s.triangles());
    // Loop's limit point of a valence-6 vertex is v + L / 2, L the umbrella vector (mean of the
    // neighbours - v), and |L| ≈ h² / (2 r) for a spacing h on a surface of curvature radius r:
    // a distance of about h² / (4 r). Surface Nets cannot resolve radii below about the
    // spacing, so r ≥ h gives a bound of h / 4 (0.63 mm); the flat palm and the ~8 mm fingers
    // stay far below it, which the mean shows.
    let mut d = distances_to_mesh(&high, hand, 2.0 * spacing);
    d.sort_by(f64::total_cmp);
    let worst = d[d.len() - 1];
    let p99 = d[d.len() * 99 / 100];
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    println!(
        "base hand: {v} vertices, {f} triangles -> {} vertices, {} triangles; largest distance \
         of a subdivided vertex to the base surface {:.4} mm (99th percentile {:.4} mm, mean \
         {:.4} mm; spacing {:.2} mm)",
        s.vertex_count(),
        s.triangles().len(),
        worst * 1e3,
        p99 * 1e3,
        mean * 1e3,
        spacing * 1e3
    );
    assert!(worst < 0.25 * spacing, "{:.4} mm", worst * 1e3);
}

#[test]
fn synthesize_with_zero_displacement_is_s_times_base() {
    let hand = &base_hand().mesh;
    let synth = DetailSynth::from_mesh(hand, 2).unwrap();
    let n = synth.vertex_count();
    let mut want = vec![Vec3::ZERO; n];
    synth
        .subdivision()
        .matrix()
        .apply(&hand.positions, &mut want)
        .unwrap();
    for method in METHODS {
        let mut synth = synth.clone().with_normals_method(method);
        let mut out = vec![Vec3::NAN; n];
        synth
            .synthesize(&hand.positions, &vec![0.0; n], &mut out)
            .unwrap();
        // The synthesis applies the one-level matrices in turn, `want` the composed S: equal
        // up to f32 rounding (the hand is ~0.2 m; one f32 ulp there is ~1.5e-8).
        for (i, (o, w)) in out.iter().zip(&want).enumerate() {
            assert!(
                (*o - *w).length() < 1e-7,
                "{method:?} vertex {i}: {o} vs {w}"
            );
        }
        // The normals it used (scatter, or gather possibly on the pool) are those of the mesh it
        // produced (h = 0: `out` is `S · base`), computed independently.
        let reference = reference_normals(&out, synth.subdivision().triangles());
        let mut scatter = vec![Vec3::ZERO; n];
        scatter_normals(&out, synth.subdivision().triangles(), &mut scatter).unwrap();
        for i in 0..n {
            let got = Vec3::from(synth.normals()[i]);
            assert!((got - scatter[i]).length() < 1e-5, "{method:?} vertex {i}");
            assert_close(got, reference[i], 1e-5, &format!("{method:?} normal {i}"));
        }
    }
}
