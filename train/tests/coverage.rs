//! `crease_train::coverage` (issue 42) on a shape built to trigger it: a tube whose two ends
//! bend independently (the top about x, the bottom about y, each example its own pair of
//! angles). Control points on the top end alone leave the bottom's bones undetermined, and
//! the coverage names that region (and nothing at the top); control points on both ends leave
//! nothing undetermined; the control-point curve falls once the points reach both ends.

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::mesh::test_meshes::tube;
use crease_train::bones::FitOptions;
use crease_train::coverage::{self, MIN_SPREAD_DEG};
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::RegressOptions;

const RINGS: usize = 17;
const AROUND: usize = 8;
const LENGTH: f32 = 8.0;

/// The top (z > 6) turned about x through z = 6 by `top`, the bottom (z < 2) about y through
/// z = 2 by `bottom`; the middle stays.
fn pose(rest: &Mesh, top: f32, bottom: f32) -> Vec<Vec3> {
    let (qt, qb) = (Quat::from_rotation_x(top), Quat::from_rotation_y(bottom));
    let (pt, pb) = (Vec3::new(0.0, 0.0, 6.0), Vec3::new(0.0, 0.0, 2.0));
    rest.positions
        .iter()
        .map(|&p| {
            if p.z > 6.0 {
                qt * (p - pt) + pt
            } else if p.z < 2.0 {
                qb * (p - pb) + pb
            } else {
                p
            }
        })
        .collect()
}

/// The rest tube and 11 examples whose two angles do not follow each other.
fn examples() -> (Mesh, Vec<Vec<Vec3>>) {
    let rest = tube(RINGS, AROUND, LENGTH);
    let mut frames = vec![rest.positions.clone()];
    for k in 1..=11 {
        // Two unrelated sequences in [-0.9, 0.9].
        let top = 0.9 * ((k * 7 % 11) as f32 / 5.0 - 1.0);
        let bottom = 0.9 * ((k * 4 % 13) as f32 / 6.0 - 1.0);
        frames.push(pose(&rest, top, bottom));
    }
    (rest, frames)
}

fn vertex(ring: usize, around: usize) -> u32 {
    (ring * AROUND + around) as u32
}

fn trained(controls: ControlSpec) -> (Mesh, Vec<Vec<Vec3>>, crease_train::base::TrainedBase) {
    let (rest, frames) = examples();
    let refs: Vec<&[Vec3]> = frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = (0..refs.len()).map(|k| format!("f{k}")).collect();
    let options = TrainOptions {
        fit: FitOptions {
            bones: 8,
            max_influences: 2,
            ..FitOptions::default()
        },
        controls,
        ..TrainOptions::default()
    };
    let base = pipeline::train_base(
        TrainInput {
            rest: &rest,
            frames: &refs,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .unwrap();
    (rest, frames, base)
}

#[test]
fn control_points_on_one_end_leave_the_other_end_undetermined() {
    let top_only = ControlSpec::Vertices(vec![vertex(16, 0), vertex(16, 4), vertex(14, 2)]);
    let (rest, _, base) = trained(top_only);
    let cov = coverage::undetermined(&base, &RegressOptions::default()).unwrap();
    for r in &cov.regions {
        eprintln!(
            "region: bones {:?}, {} vertices, centroid {:?}, spread {:.1} deg, error {:.1} deg",
            r.bones,
            r.vertices.len(),
            r.centroid,
            r.spread_deg,
            r.error_deg
        );
    }
    assert!(
        !cov.regions.is_empty(),
        "no region flagged: spread {:?} error {:?}",
        cov.spread_deg,
        cov.error_deg
    );
    for r in &cov.regions {
        // Every flagged region lies in the bottom (z < 2 turns; its bones reach a little
        // past it), and its bones moved in the examples but were not predicted.
        assert!(r.centroid[2] < 3.0, "a region at the top: {r:?}");
        assert!(r.spread_deg >= MIN_SPREAD_DEG, "{r:?}");
        assert!(r.error_deg >= 0.5 * r.spread_deg, "{r:?}");
        for &v in &r.vertices {
            assert!(rest.positions[v as usize].z < 4.0, "vertex {v} of {r:?}");
        }
    }
    // The bottom end's vertices are covered by the regions.
    let flagged: std::collections::HashSet<u32> = cov
        .regions
        .iter()
        .flat_map(|r| r.vertices.iter().copied())
        .collect();
    let bottom: Vec<u32> = (0..2 * AROUND as u32).collect();
    assert!(
        bottom.iter().all(|v| flagged.contains(v)),
        "the bottom ring is not flagged: {:?}",
        cov.regions
    );
}

#[test]
fn control_points_on_both_ends_leave_nothing_undetermined() {
    let both = ControlSpec::Vertices(vec![
        vertex(16, 0),
        vertex(16, 4),
        vertex(14, 2),
        vertex(0, 0),
        vertex(0, 4),
        vertex(2, 2),
    ]);
    let (_, _, base) = trained(both);
    let cov = coverage::undetermined(&base, &RegressOptions::default()).unwrap();
    assert!(
        cov.regions.is_empty(),
        "regions flagged: {:?}\nspread {:?}\nerror {:?}",
        cov.regions,
        cov.spread_deg,
        cov.error_deg
    );
    // The ends did move: the check above had something to find.
    assert!(cov.spread_deg.iter().any(|&s| s > 4.0 * MIN_SPREAD_DEG));
}

#[test]
fn the_control_point_curve_falls_once_the_points_reach_both_ends() {
    let (_, frames, base) = trained(ControlSpec::Auto(2));
    let refs: Vec<&[Vec3]> = frames.iter().map(Vec::as_slice).collect();
    let (curve, stopped) =
        coverage::control_curve(&base, &refs, &RegressOptions::default(), 1.0, &[1, 2, 4]);
    assert!(stopped.is_none(), "{stopped:?}");
    assert_eq!(curve.len(), 3);
    eprintln!(
        "curve: {:?}",
        curve.iter().map(|p| (p.count, p.rms)).collect::<Vec<_>>()
    );
    for p in &curve {
        assert_eq!(p.controls.len(), p.count, "{p:?}");
        assert!(p.rms.is_finite() && p.rms > 0.0, "{p:?}");
    }
    // One point cannot say both angles; four (two components, two representatives each)
    // can, up to the leave-one-out's own error.
    assert!(
        curve[2].rms < 0.5 * curve[0].rms,
        "{:?}",
        curve.iter().map(|p| (p.count, p.rms)).collect::<Vec<_>>()
    );
}
