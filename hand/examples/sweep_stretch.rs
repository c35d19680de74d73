//! Diagnostic: how much the sweep hand stretches or compresses its edges in the named poses
//! (the ratio of a deformed edge's length to its rest length, worst and 99th percentile).
//!
//! `cargo run --release -p crease-core --example sweep_stretch`

use crease_core::glam::Vec3;
use crease_hand::palm::PalmSurface;
use crease_hand::skeleton::{HandPose, HandSkeleton, NamedPose};
use crease_hand::surface::{HandSurface, Resolution};
use crease_hand::sweeps::SweepHand;

fn main() {
    let surface = HandSurface::build(Resolution::Base).expect("base surface");
    let rest = &surface.mesh;
    let hand = SweepHand::bind(&HandSkeleton::adult_right(), rest);
    let normals = rest.vertex_normals();
    let palm = PalmSurface::bind(&HandSkeleton::adult_right(), rest, &normals).expect("palm");
    println!(
        "palm: {} vertices bound, moving nodes {:?}",
        palm.palm_vertices().count(),
        palm.moving_nodes().collect::<Vec<_>>()
    );
    let mut edges = Vec::new();
    for t in &rest.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a < b {
                edges.push((a as usize, b as usize));
            }
        }
    }
    let mut out = vec![Vec3::ZERO; rest.positions.len()];
    println!("{} vertices, {} edges", rest.positions.len(), edges.len());
    for named in NamedPose::ALL {
        hand.deform_into(&HandPose::named(named), &mut out);
        let before = out.clone();
        palm.apply(&HandPose::named(named), &mut out);
        let moved = out
            .iter()
            .zip(&before)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max);
        print!("palm moved <= {:.1} mm; ", moved * 1e3);
        let mut ratios: Vec<(f32, usize)> = edges
            .iter()
            .enumerate()
            .map(|(e, &(a, b))| {
                let r = (rest.positions[a] - rest.positions[b]).length();
                ((out[a] - out[b]).length() / r, e)
            })
            .collect();
        ratios.sort_by(|x, y| x.0.total_cmp(&y.0));
        let n = ratios.len();
        let (worst, e) = ratios[n - 1];
        let (a, _) = edges[e];
        println!(
            "{:>10}: min {:.2} p1 {:.2} p99 {:.2} max {:.2} (at rest {:.3?})",
            named.name(),
            ratios[0].0,
            ratios[n / 100].0,
            ratios[n - n / 100].0,
            worst,
            rest.positions[a]
        );
    }
}
