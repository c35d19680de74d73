//! Automatic control points (FKY08 §3): on a synthetic sheet where only two separate regions
//! move, and on the horse (skipped when the data is absent).

use std::path::Path;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::mesh::test_meshes::unit_grid;
use crease_train::controls::{ControlError, auto_control_points};
use rand::{Rng, SeedableRng, rngs::StdRng};

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data");

/// Smooth bump of radius `r` around `c`, exactly zero outside.
fn bump(p: Vec3, c: Vec3, r: f32) -> f32 {
    let t = p.distance(c) / r;
    if t >= 1.0 { 0.0 } else { (1.0 - t * t).powi(2) }
}

/// Region A around (6, 6) and region B around (22, 20) on a 30 x 30 sheet, each with two
/// independent random modes per example (a lift and a tilt); everything else is still.
fn two_region_frames(rest: &Mesh, examples: usize, seed: u64) -> Vec<Vec<Vec3>> {
    let (ca, cb) = (Vec3::new(6.0, 6.0, 0.0), Vec3::new(22.0, 20.0, 0.0));
    let mut rng = StdRng::seed_from_u64(seed);
    let mut frames = vec![rest.positions.clone()];
    for _ in 0..examples {
        let [a1, a2, b1, b2]: [f32; 4] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
        frames.push(
            rest.positions
                .iter()
                .map(|&p| {
                    let (wa, wb) = (bump(p, ca, 4.5), bump(p, cb, 4.5));
                    p + Vec3::Z * (wa * (a1 + a2 * (p.x - ca.x) / 4.5))
                        + Vec3::new(0.3, 0.0, 1.0) * (wb * (b1 + b2 * (p.y - cb.y) / 4.5))
                })
                .collect(),
        );
    }
    frames
}

#[test]
fn control_points_land_in_both_moving_regions() {
    let rest = unit_grid(30);
    let frames = two_region_frames(&rest, 12, 29);
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let moving = |v: u32| {
        let p = rest.positions[v as usize];
        (
            bump(p, Vec3::new(6.0, 6.0, 0.0), 4.5) > 0.0,
            bump(p, Vec3::new(22.0, 20.0, 0.0), 4.5) > 0.0,
        )
    };
    for count in [2, 4, 6] {
        let chosen = auto_control_points(&rest, &refs, count).unwrap();
        println!("count {count}: {chosen:?}");
        assert_eq!(chosen.len(), count);
        let mut sorted = chosen.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), count, "duplicates in {chosen:?}");
        let (mut in_a, mut in_b) = (0, 0);
        for &v in &chosen {
            let (a, b) = moving(v);
            assert!(
                a || b,
                "vertex {v} at {} does not move",
                rest.positions[v as usize]
            );
            in_a += usize::from(a);
            in_b += usize::from(b);
        }
        assert!(in_a >= 1 && in_b >= 1, "count {count}: A {in_a}, B {in_b}");
        // Deterministic.
        assert_eq!(auto_control_points(&rest, &refs, count).unwrap(), chosen);
    }
}

#[test]
fn more_points_than_components_fill_by_motion() {
    // One region with one mode: PCA has rank 1, so after its two representatives the rest come
    // from the fill step; they must still be moving vertices, spread apart.
    let rest = unit_grid(20);
    let c = Vec3::new(10.0, 10.0, 0.0);
    let frames: Vec<Vec<Vec3>> = (0..4)
        .map(|t| {
            rest.positions
                .iter()
                .map(|&p| p + Vec3::Z * (t as f32 * bump(p, c, 6.0)))
                .collect()
        })
        .collect();
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let chosen = auto_control_points(&rest, &refs, 5).unwrap();
    assert_eq!(chosen.len(), 5);
    for &v in &chosen {
        assert!(bump(rest.positions[v as usize], c, 6.0) > 0.0, "{v}");
    }
    // The first is the peak of the bump.
    assert_eq!(rest.positions[chosen[0] as usize], c);
}

#[test]
fn bad_inputs_are_errors() {
    let rest = unit_grid(4);
    let moved: Vec<Vec3> = rest.positions.iter().map(|&p| p + Vec3::X).collect();
    let ok: Vec<&[Vec3]> = vec![&rest.positions, &moved];
    assert!(matches!(
        auto_control_points(&rest, &ok, 0),
        Err(ControlError::BadCount { count: 0, .. })
    ));
    assert!(matches!(
        auto_control_points(&rest, &ok, 17),
        Err(ControlError::BadCount {
            count: 17,
            vertices: 16
        })
    ));
    assert!(matches!(
        auto_control_points(&rest, &ok[..1], 2),
        Err(ControlError::TooFewFrames(1))
    ));
    let same: Vec<&[Vec3]> = vec![&rest.positions, &rest.positions];
    assert!(matches!(
        auto_control_points(&rest, &same, 2),
        Err(ControlError::NoMotion)
    ));
    let short = &moved[..10];
    assert!(matches!(
        auto_control_points(&rest, &[&rest.positions, short], 2),
        Err(ControlError::VertexCount {
            frame: 1,
            got: 10,
            ..
        })
    ));
    let mut nan = moved.clone();
    nan[3].y = f32::NAN;
    assert!(matches!(
        auto_control_points(&rest, &[&rest.positions, &nan], 2),
        Err(ControlError::NonFinite {
            frame: 1,
            vertex: 3
        })
    ));
    // A rigid translation is motion: every vertex moves alike, and all 16 can be chosen.
    let all = auto_control_points(&rest, &ok, 16).unwrap();
    let mut sorted = all.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..16).collect::<Vec<u32>>());
}

#[test]
fn horse_control_points_are_distinct_and_on_moving_parts() {
    let dir = Path::new(DATA).join("horse");
    if !dir.join("reference.obj").exists() {
        println!("skipped: horse data not found under {}", dir.display());
        return;
    }
    let rest = Mesh::read(dir.join("reference.obj")).unwrap();
    // The rest pose, one gallop cycle (frames 25..48 repeat 1..24) and the assorted poses.
    let mut frames = vec![rest.positions.clone()];
    for k in 1..=24 {
        frames.push(
            Mesh::read(dir.join(format!("gallop/{k:04}.obj")))
                .unwrap()
                .positions,
        );
    }
    for k in 1..=10 {
        frames.push(
            Mesh::read(dir.join(format!("poses/{k}.obj")))
                .unwrap()
                .positions,
        );
    }
    let refs: Vec<&[Vec3]> = frames.iter().map(|f| f.as_slice()).collect();
    let t = std::time::Instant::now();
    let chosen = auto_control_points(&rest, &refs, 8).unwrap();
    println!(
        "horse: {} frames, 8 control points in {:.2?}",
        frames.len(),
        t.elapsed()
    );

    // Displacement RMS of each vertex about its mean position across the examples.
    let n = frames.len() as f32;
    let rms: Vec<f32> = (0..rest.vertex_count())
        .map(|v| {
            let mean = frames.iter().map(|f| f[v]).sum::<Vec3>() / n;
            (frames
                .iter()
                .map(|f| f[v].distance_squared(mean))
                .sum::<f32>()
                / n)
                .sqrt()
        })
        .collect();
    let mut sorted_rms = rms.clone();
    sorted_rms.sort_by(f32::total_cmp);
    let median = sorted_rms[sorted_rms.len() / 2];
    println!("median displacement RMS {median:.4}");
    for &v in &chosen {
        let p = rest.positions[v as usize];
        println!(
            "  vertex {v:5} at ({:+.3}, {:+.3}, {:+.3}), displacement RMS {:.4}",
            p.x, p.y, p.z, rms[v as usize]
        );
        assert!(
            rms[v as usize] > median,
            "vertex {v} moves less than the median"
        );
    }
    let mut unique = chosen.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), 8, "{chosen:?}");
}
