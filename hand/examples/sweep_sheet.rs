//! Renders the named poses of the sweep hand into a contact sheet (PNG).
//!
//! `cargo run --release -p crease-core --example sweep_sheet -- OUT.png [base|detailed] [TILE] [POSE,POSE,...]`

use crease_hand::render::{View, contact_sheet};
use crease_hand::rig::{HandRig, Layers};
use crease_hand::skeleton::{HandPose, NamedPose};
use crease_hand::surface::Resolution;

fn main() {
    let mut args = std::env::args().skip(1);
    let out = args.next().unwrap_or_else(|| "sheet.png".into());
    let resolution = match args.next().as_deref() {
        Some("detailed") => Resolution::Detailed,
        _ => Resolution::Base,
    };
    let tile: u32 = args.next().map_or(320, |t| t.parse().expect("tile size"));
    let poses: Vec<NamedPose> = args.next().map_or(NamedPose::ALL.to_vec(), |list| {
        list.split(',')
            .map(|p| p.parse().expect("pose name"))
            .collect()
    });
    let rig = HandRig::build(resolution).expect("rig");
    let meshes: Vec<_> = poses
        .iter()
        .map(|&n| {
            (
                n.name(),
                rig.posed_mesh(&HandPose::named(n), Layers::default()),
            )
        })
        .collect();
    let tiles: Vec<(&str, &_)> = meshes.iter().map(|(n, m)| (*n, m)).collect();
    let sheet = contact_sheet(&tiles, &[View::Palm, View::ThumbSide], tile, 4);
    sheet.write_png(&out).expect("png");
}
