//! The LYK06 palm-control surface (`crease_hand::palm`): exact rest reconstruction,
//! interpolation of the node vertices, a bulge that grows with MCP flexion, and no tearing
//! at the blend border.

use std::sync::OnceLock;
use std::time::Instant;

use crease_core::glam::{Vec2, Vec3};
use crease_core::mesh::Mesh;
use crease_hand::palm::{BULGE_HEIGHT, GRID_U, GRID_V, PalmSurface};
use crease_hand::skeleton::{Digit, Dof, DofKind, HandPose, HandSkeleton, NamedPose, PoseSampler};
use crease_hand::surface::{HandSurface, Resolution};
use crease_hand::sweeps::SweepHand;

struct Fixture {
    mesh: Mesh,
    hand: SweepHand,
    palm: PalmSurface,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let skeleton = HandSkeleton::adult_right();
        let mesh = HandSurface::build(Resolution::Base)
            .expect("base surface")
            .mesh;
        let hand = SweepHand::bind(&skeleton, &mesh);
        let palm = PalmSurface::bind(&skeleton, &mesh, &mesh.vertex_normals()).expect("palm");
        Fixture { mesh, hand, palm }
    })
}

fn sweep_only(pose: &HandPose) -> Vec<Vec3> {
    let f = fixture();
    let mut out = vec![Vec3::ZERO; f.hand.vertex_count()];
    f.hand.deform_into(pose, &mut out);
    out
}

fn with_palm(pose: &HandPose) -> Vec<Vec3> {
    let mut out = sweep_only(pose);
    fixture().palm.apply(pose, &mut out);
    out
}

/// Flexes the MCPs of the four fingers to `deg` degrees.
fn mcp_flexed(deg: f32) -> HandPose {
    let mut pose = HandPose::FLAT;
    for d in Digit::FINGERS {
        let dof = Dof::new(d.joints()[1], DofKind::Flexion).expect("MCP flexion");
        pose.set(dof, deg.to_radians());
    }
    pose
}

#[test]
fn binds_a_palm_with_moving_nodes() {
    let f = fixture();
    let n = f.palm.palm_vertices().count();
    assert!(n > 300, "{n} palm vertices");
    assert_eq!(f.palm.moving_nodes().count(), 10);
    // Interpolation vertices face palmar.
    let normals = f.mesh.vertex_normals();
    for &i in f.palm.nodes() {
        assert!(
            normals[i as usize].z < -0.3,
            "node {i} normal {}",
            normals[i as usize]
        );
    }
}

#[test]
fn rest_pose_reconstructs_rest_mesh() {
    let f = fixture();
    let out = with_palm(&HandPose::FLAT);
    let scale = f.mesh.bbox_diagonal_scale();
    let worst = out
        .iter()
        .zip(&f.mesh.positions)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5 * scale, "max error {worst} m (bbox {scale} m)");
}

#[test]
fn surface_interpolates_the_fixed_nodes() {
    let f = fixture();
    let moving: Vec<u32> = f.palm.moving_nodes().collect();
    let mut sampler = PoseSampler::new(7);
    for _ in 0..5 {
        let pose = sampler.sample();
        let swept = sweep_only(&pose);
        for b in 0..GRID_V {
            for a in 0..GRID_U {
                let node = f.palm.nodes()[a + GRID_U * b];
                if moving.contains(&node) {
                    continue;
                }
                let uv = Vec2::new(
                    a as f32 / (GRID_U - 1) as f32,
                    b as f32 / (GRID_V - 1) as f32,
                );
                let (s, n) = f.palm.surface_at(&pose, &swept, uv);
                let err = (s - swept[node as usize]).length();
                assert!(err < 2e-6, "node ({a}, {b}): surface misses it by {err} m");
                assert!((n.length() - 1.0).abs() < 1e-4);
            }
        }
    }
}

#[test]
fn palm_bulges_more_as_the_mcps_flex() {
    let f = fixture();
    let mut previous = -1.0;
    for deg in [0.0, 30.0, 60.0, 90.0] {
        let pose = mcp_flexed(deg);
        let swept = sweep_only(&pose);
        let palm = with_palm(&pose);
        // Bulge: how far the palm vertices moved out of the palm (along the surface normal).
        let mut bulge = 0.0f32;
        for i in f.palm.palm_vertices() {
            let i = i as usize;
            let (_, n) = f.palm.surface_at(&pose, &swept, Vec2::splat(0.5));
            bulge = bulge.max((palm[i] - swept[i]).dot(n));
        }
        eprintln!("MCP {deg}°: bulge {:.2} mm", bulge * 1e3);
        assert!(bulge > previous, "bulge {bulge} at {deg}° after {previous}");
        previous = bulge;
        if deg == 90.0 {
            assert!(
                (0.5 * BULGE_HEIGHT..2.0 * BULGE_HEIGHT).contains(&bulge),
                "bulge {bulge} m at 90°"
            );
        }
    }
}

#[test]
fn palm_layer_does_not_tear_the_skin() {
    let f = fixture();
    let mut edges = Vec::new();
    let palm: std::collections::HashSet<u32> = f.palm.palm_vertices().collect();
    for t in &f.mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a < b && (palm.contains(&a) || palm.contains(&b)) {
                edges.push((a as usize, b as usize));
            }
        }
    }
    for named in NamedPose::ALL {
        let pose = HandPose::named(named);
        let (s, p) = (sweep_only(&pose), with_palm(&pose));
        let ratio = |x: &[Vec3]| {
            edges
                .iter()
                .map(|&(a, b)| {
                    (x[a] - x[b]).length() / (f.mesh.positions[a] - f.mesh.positions[b]).length()
                })
                .fold(0.0f32, f32::max)
        };
        let (rs, rp) = (ratio(&s), ratio(&p));
        eprintln!("{named}: worst palm edge stretch sweep {rs:.2}, with palm {rp:.2}");
        assert!(rp < 1.5 * rs.max(1.0), "{named}: {rp} vs {rs}");
    }
}

#[test]
fn palm_layer_cost() {
    let f = fixture();
    let pose = HandPose::named(NamedPose::Fist);
    let mut out = sweep_only(&pose);
    let base = out.clone();
    let n = 200;
    let start = Instant::now();
    for _ in 0..n {
        out.copy_from_slice(&base);
        f.palm.apply(&pose, &mut out);
    }
    eprintln!(
        "palm apply: {:?} per frame ({} palm vertices; debug-free release)",
        start.elapsed() / n,
        f.palm.palm_vertices().count()
    );
    assert!(out.iter().all(|p| p.is_finite()));
}
