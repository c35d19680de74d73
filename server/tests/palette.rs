//! Palette frames against the predictor (issue 18, first part): a trained model's bone
//! transforms for a frame, sent as a palette frame (`core::codec::palette`) and skinned on the
//! receiving side, give the predictor's own base mesh within the palette's error bound, vertex
//! by vertex. This is the CPU half of the exactness check for the base level.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

mod common;

use std::sync::Arc;

use common::{control_frame, model};
use crease_core::codec::palette::{
    PaletteFrame, decode_palette_frame, encode_palette_frame, palette_frame_len, vertex_error_bound,
};
use crease_core::glam::Vec3;
use crease_core::predictor::Predictor;
use crease_core::runtime::skin::{BonePalette, skin_lbs};

#[test]
fn a_decoded_palette_frame_skins_to_the_predicted_base_mesh_within_its_bound() {
    let model = model();
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    let mut ctx = predictor.new_context();
    let rest = &model.rig.rest.positions;
    let bones = model.rig.examples[0].transforms.len();
    let mut bytes = Vec::new();
    let mut frame = PaletteFrame::default();
    let mut skinned = vec![Vec3::ZERO; rest.len()];
    let mut worst = 0.0f32;
    for (seq, angle) in [0.0f32, 0.3, 0.7, 1.1, 1.4].into_iter().enumerate() {
        let f = control_frame(&model, "p", seq as u64, angle);
        let c: Vec<Vec3> = f
            .positions
            .chunks(3)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect();
        let predicted = predictor.predict(&mut ctx, &c, None).unwrap().to_vec();
        bytes.clear();
        encode_palette_frame(seq as u32, ctx.transforms(), &[], &mut bytes).unwrap();
        assert_eq!(bytes.len(), palette_frame_len(bones, 0));
        decode_palette_frame(&bytes, bones, 0, &mut frame).unwrap();
        let palette = BonePalette::from_transforms(&frame.bones);
        skin_lbs(rest, &model.rig.skin, &palette, &mut skinned).unwrap();
        for (v, (p, s)) in predicted.iter().zip(&skinned).enumerate() {
            let (idx, w) = model.rig.skin.vertex(v);
            let weights: Vec<(u32, f32)> = idx.iter().copied().zip(w.iter().copied()).collect();
            // f32 rounding of the two skinnings, relative to the mesh's size (~8 units).
            let bound = vertex_error_bound(&frame, rest[v], &weights) + 1e-5;
            let err = p.distance(*s);
            assert!(err <= bound, "frame {seq}, vertex {v}: {err} over {bound}");
            worst = worst.max(err);
        }
    }
    eprintln!(
        "{} bones: {} bytes per palette frame ({} vertices); worst vertex error {worst:.2e}",
        bones,
        palette_frame_len(bones, 0),
        rest.len()
    );
    assert!(
        worst > 0.0,
        "the palette is quantised: some error is expected"
    );
}
