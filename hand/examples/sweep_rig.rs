//! Builds the sweep hand at both resolutions, times each stage, and writes posed meshes.
//!
//! `cargo run --release -p crease-core --example sweep_rig -- [OUT_DIR]`

use std::time::Instant;

use crease_core::glam::Vec3;
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::skeleton::{HandPose, NamedPose};
use crease_hand::surface::Resolution;

fn main() {
    let out_dir = std::env::args().nth(1);
    for resolution in [Resolution::Base, Resolution::Detailed] {
        let start = Instant::now();
        let rig = HandRig::build(resolution).expect("rig");
        println!(
            "{resolution:?}: {} vertices, built and bound in {:?}; palm {} vertices, crease entries {}",
            rig.vertex_count(),
            start.elapsed(),
            rig.palm().map_or(0, |p| p.palm_vertices().count()),
            rig.creases().map_or(0, |c| c.entry_count()),
        );
        let mut scratch = RigScratch::new();
        let mut out = vec![Vec3::ZERO; rig.vertex_count()];
        let pose = HandPose::named(NamedPose::Fist);
        let n = if resolution == Resolution::Base {
            500
        } else {
            20
        };
        let start = Instant::now();
        for _ in 0..n {
            rig.deform(&pose, Layers::default(), &mut scratch, &mut out);
        }
        println!("  deform (all layers): {:?} per frame", start.elapsed() / n);
        if let Some(dir) = &out_dir {
            for named in NamedPose::ALL {
                let mesh = rig.posed_mesh(&HandPose::named(named), Layers::default());
                let path = format!("{dir}/{resolution:?}-{}.obj", named.name());
                mesh.write(&path).expect("write");
            }
        }
    }
}
