//! `crease take export`'s work: a take as glTF with the user's copy of its model. The skinned
//! level writes the recorded bone transforms as a skinned animation
//! (`core::model::gltf_export::skinned_recording_to_glb`, what the viewer's download serves
//! too); the detail level re-runs the predictor's detail layer (HZY11 eq. 4) on every `every`-th
//! recorded frame and bakes the meshes into morph targets. The take file's wire types stay in
//! `crease_proto::take`, which unpacks their frames; running the predictor is ours.

use std::sync::Arc;

use anyhow::{Context, anyhow, bail};
use crease_core::glam::Vec3;
use crease_core::model::{TrainedModel, gltf_export};
use crease_core::predictor::Predictor;
use crease_proto::take::{self, Take};

/// The take as a skinned glTF animation: the model's rest mesh and skin, one joint per bone,
/// one keyframe per frame at [`take::keyframe_times`] holding the recorded bone transforms, so
/// a glTF viewer's skinning reproduces the room's base meshes.
///
/// # Errors
/// A take without frames or recorded with dual-quaternion skinning; a frame's shape; the
/// writer's.
pub fn skinned_glb(take: &Take, model: &TrainedModel) -> anyhow::Result<Vec<u8>> {
    let transforms = take::all_transforms(take)?;
    Ok(gltf_export::skinned_recording_to_glb(
        &model.rig,
        take::take_skinning(take, model),
        "take",
        &take::keyframe_times(take),
        &transforms,
    )?)
}

/// A take of a room of several actors as one glTF (issue 38): a skinned mesh per actor
/// (`gltf_export::skinned_parts_recording_to_glb`), every actor on `model` (the user's copy
/// of the model they share), mirrored where the actor was, as the room ran it: the bytes the
/// server's download writes.
///
/// # Errors
/// An actor's mirror or frames; the writer's.
pub fn actors_glb(take: &Take, model: &TrainedModel) -> anyhow::Result<Vec<u8>> {
    let recordings = take::actor_recordings(take)?;
    let models = recordings
        .iter()
        .map(|r| match &r.mirror {
            None => Ok(std::borrow::Cow::Borrowed(model)),
            Some(plane) => model
                .mirrored(plane)
                .map(std::borrow::Cow::Owned)
                .with_context(|| format!("actor {:?}: mirror", r.name)),
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let parts: Vec<_> = recordings
        .iter()
        .zip(&models)
        .map(|(r, m)| gltf_export::SkinnedPart::of(&r.name, m, r.skinning, &r.transforms))
        .collect();
    Ok(gltf_export::skinned_parts_recording_to_glb(
        &parts,
        "take",
        &take::keyframe_times(take),
    )?)
}

/// The take's detail layer as a morph-target animation (`core::model::gltf_export`'s baked
/// vertex animation): every `every`-th frame's detail mesh (HZY11 eq. 4 on the recorded
/// frame's base mesh), at the take's mean frame rate; the first exported frame is the base
/// shape.
///
/// # Errors
/// A model without a detail layer or a take without frames; a frame's shape; the predictor's
/// and the writer's.
pub fn detail_glb(take: &Take, model: Arc<TrainedModel>, every: usize) -> anyhow::Result<Vec<u8>> {
    let every = every.max(1);
    let skinning = take::take_skinning(take, &model);
    let mut predictor = Predictor::new(model, None).map_err(|e| anyhow!("predictor: {e}"))?;
    predictor.set_skinning(skinning);
    let triangles = predictor
        .detail_triangles()
        .ok_or_else(|| anyhow!("the model has no detail layer"))?
        .to_vec();
    let picked: Vec<usize> = (0..take.frames.len()).step_by(every).collect();
    let (Some(&first), Some(&last)) = (picked.first(), picked.last()) else {
        bail!("the take has no frames");
    };
    let times = take::keyframe_times(take);
    let span = times[last] - times[first];
    let fps = if picked.len() > 1 && span > 0.0 {
        ((picked.len() - 1) as f64 / span) as f32
    } else {
        1.0
    };
    let vertices = predictor.detail_vertex_count().unwrap_or(0);
    gltf_export::check_animation_size(vertices, triangles.len(), picked.len())?;
    let mut ctx = predictor.new_context();
    let (mut controls, mut transforms) = (Vec::new(), Vec::new());
    let mut meshes: Vec<Vec3> = Vec::with_capacity(vertices * picked.len());
    for &i in &picked {
        take::frame_controls(take, i, &mut controls)?;
        take::frame_transforms(take, i, &mut transforms)?;
        let frame = || format!("frame {i}");
        predictor
            .load_frame(&mut ctx, &controls, &transforms)
            .with_context(frame)?;
        predictor.skin(&mut ctx).with_context(frame)?;
        meshes.extend_from_slice(predictor.predict_detail(&mut ctx).with_context(frame)?);
    }
    let rest = meshes[..vertices].to_vec();
    Ok(gltf_export::animation_to_glb(
        &triangles, &rest, &meshes, fps,
    )?)
}
