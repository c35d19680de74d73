//! Animated glTF 2.0 binaries (`.glb`) any viewer (three.js, Blender) can play: a [`Rig`] as a
//! skinned mesh ([`export_rig_glb`]; with any sequence of bone transforms as its keyframes,
//! [`skinned_animation_to_glb`], and a take's, [`skinned_recording_to_glb`], what
//! `crease take export` and the viewer's take download write), and a sequence of
//! synthesized meshes baked into morph targets ([`export_animation_glb`], what
//! `crease synth --gltf` writes).
//!
//! # Skinned rig
//!
//! What is written:
//! - one mesh (POSITION with min/max, u32 indices, `JOINTS_0`/`WEIGHTS_0` and, when k > 4,
//!   `JOINTS_1`/`WEIGHTS_1`; joints u16, weights f32, unused slots joint 0 weight 0). No NORMAL:
//!   glTF viewers then compute flat normals (glTF 2.0 §3.7.2.1).
//! - one joint node per proxy bone, all children of one identity root node `rig`, joint `i` at
//!   its bone's rest centre `c_i` (the weight-averaged rest position of the vertices it
//!   influences; the box centre for a bone without influence) with identity rotation;
//! - one skin whose inverse bind matrices are `translate(-c_i)`;
//! - one animation `examples` with one keyframe per example at `e * SECONDS_PER_EXAMPLE`
//!   (LINEAR, so a viewer morphs between examples), a translation and a rotation channel per
//!   joint.
//!
//! The animation reproduces the rig's LBS exactly at the keyframes. With the joint's rest global
//! matrix `J_i = translate(c_i)` and the bone's rigid transform `T_i = (q_i, t_i)` (rest ->
//! example), the skin matrix `G_i J_i⁻¹` must equal `T_i`, so the joint's animated global matrix
//! is `G_i = T_i J_i`: `x -> q_i (x + c_i) + t_i`, i.e. rotation `q_i` and translation
//! `q_i c_i + t_i`. The root is the identity, so these are also the joints' local transforms.
//!
//! # Baked vertex animation (morph targets)
//!
//! `F` frames of the same `n`-vertex, `t`-triangle mesh become one node `animation` holding one
//! mesh `rest`:
//! - base attribute POSITION = the rest positions (f32 VEC3, min/max), u32 indices; no NORMAL
//!   (viewers compute flat normals from the morphed positions, which stay right in every frame,
//!   where rest normals would not);
//! - morph target `i` (`0..F`): POSITION = `frame_i - rest` per vertex (f32 VEC3, with the
//!   min/max glTF 2.0 §3.7.2.2 requires of POSITION accessors), nothing else; mesh `weights` all
//!   0, so without the animation the rest mesh shows;
//! - one animation `frames` with one sampler and one channel (`weights` of the node): keyframe
//!   `i` at `i / fps` seconds, output one weight per target per keyframe (`F × F` floats),
//!   one-hot: at keyframe `i` target `i` has weight 1, all others 0, so the mesh is exactly
//!   `rest + (frame_i - rest) = frame_i` (up to f32 rounding). LINEAR: between keyframes `i` and
//!   `i + 1` the weights are `1 - s` and `s`, i.e. every vertex moves on the straight line
//!   between its two frame positions.
//!
//! Binary chunk, in this order, each a buffer view starting where the previous ends (all sizes
//! are multiples of 4, so no padding): rest positions (`12 n` bytes), indices (`12 t`), keyframe
//! times (`4 F`), weights (`4 F²`), then the displacements of frame 0, 1, ... (`12 n` each). The
//! GLB header stores the file length as a u32, so `12 n (F + 1) + 12 t + 4 F + 4 F²` plus the
//! JSON must stay below 4 GiB ([`check_animation_size`]). The binary chunk is streamed from the
//! caller's frames, never held in memory a second time by [`export_animation_glb`].

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Mat4, Vec3};
use gltf_json as json;
use json::validation::{Checked, USize64};

use super::ModelError;
use super::file::write_atomic;
use super::rig::Rig;
use crate::runtime::skin::{RigidTransform, Skinning};

/// Seconds between consecutive example keyframes: slow enough to see each pose in a viewer.
pub const SECONDS_PER_EXAMPLE: f32 = 1.0;

/// Writes `rig` to `path` as a skinned, animated GLB (atomically, like the model files).
pub fn export_rig_glb(rig: &Rig, path: impl AsRef<Path>) -> Result<(), ModelError> {
    let path = path.as_ref();
    let bytes = rig_to_glb(rig)?;
    write_atomic(path, &bytes).map_err(|error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// The rest centre of every bone: the rest positions of the vertices it influences, averaged
/// with its skin weights; the bounding-box centre for a bone that influences no vertex.
pub fn bone_centres(rig: &Rig) -> Vec<Vec3> {
    let mut sum = vec![Vec3::ZERO; rig.bone_count];
    let mut weight = vec![0.0f32; rig.bone_count];
    for (&p, (ii, ww)) in rig.rest.positions.iter().zip(rig.skin.iter()) {
        for (&b, &w) in ii.iter().zip(ww) {
            sum[b as usize] += w * p;
            weight[b as usize] += w;
        }
    }
    let (lo, hi) = rig.rest.bounding_box();
    let centre = 0.5 * (lo + hi);
    sum.iter()
        .zip(&weight)
        .map(|(&s, &w)| if w > 0.0 { s / w } else { centre })
        .collect()
}

/// The GLB bytes [`export_rig_glb`] writes.
pub fn rig_to_glb(rig: &Rig) -> Result<Vec<u8>, ModelError> {
    let times: Vec<f32> = (0..rig.examples.len())
        .map(|i| i as f32 * SECONDS_PER_EXAMPLE)
        .collect();
    let transforms: Vec<RigidTransform> = rig
        .examples
        .iter()
        .flat_map(|e| e.transforms.iter().copied())
        .collect();
    let part = SkinnedPart {
        name: None,
        rig,
        transforms: &transforms,
    };
    skinned_glb(&[part], "examples", &times)
}

/// `rig`'s mesh and joints (as [`rig_to_glb`]) with an animation `name` of one keyframe per
/// frame instead of the examples: keyframe `f` at `times[f]` seconds puts bone `b` at
/// `transforms[f * bones + b]` (what `crease take export` writes: a take's predicted bone
/// transforms, so the base layer exactly, at a few dozen bytes per bone per frame).
///
/// # Errors
/// [`ModelError::Export`] when `times` is empty, not strictly increasing or not finite, when
/// `transforms` is not `times.len()` frames of the rig's bones, or holds a non-finite value;
/// what [`rig_to_glb`] refuses.
pub fn skinned_animation_to_glb(
    rig: &Rig,
    name: &str,
    times: &[f32],
    transforms: &[RigidTransform],
) -> Result<Vec<u8>, ModelError> {
    check_keyframes(rig, times, transforms)?;
    skinned_glb(
        &[SkinnedPart {
            name: None,
            rig,
            transforms,
        }],
        name,
        times,
    )
}

/// What [`skinned_animation_to_glb`] refuses of `rig`'s keyframes.
fn check_keyframes(
    rig: &Rig,
    times: &[f32],
    transforms: &[RigidTransform],
) -> Result<(), ModelError> {
    let export = |m: String| Err(ModelError::Export(m));
    if times.is_empty() {
        return export("an animation needs at least one keyframe".into());
    }
    if !times.iter().all(|t| t.is_finite()) || !times.windows(2).all(|w| w[0] < w[1]) {
        return export("keyframe times must be finite and strictly increasing".into());
    }
    if transforms.len() != times.len() * rig.bone_count {
        return export(format!(
            "{} transforms for {} keyframes of {} bones: expected {}",
            transforms.len(),
            times.len(),
            rig.bone_count,
            times.len() * rig.bone_count
        ));
    }
    if let Some(i) = transforms
        .iter()
        .position(|t| !(t.rotation.is_finite() && t.translation.is_finite()))
    {
        return export(format!(
            "keyframe {} bone {}: a non-finite transform",
            i / rig.bone_count,
            i % rig.bone_count
        ));
    }
    Ok(())
}

/// One skinned mesh of a GLB with several (a room of actors' take, issue 38): its name, its
/// rig, and its keyframes' transforms (`times.len()` frames of `rig.bone_count`).
#[derive(Clone, Copy, Debug)]
pub struct SkinnedPart<'a> {
    /// The mesh's name (its nodes are `NAME`, `NAME_rig` and `NAME_bone_i`); `None`: the
    /// one mesh of a single-rig file (`rest`, `rig`, `bone_i`).
    pub name: Option<&'a str>,
    /// Its rig.
    pub rig: &'a Rig,
    /// Its keyframes.
    pub transforms: &'a [RigidTransform],
}

impl<'a> SkinnedPart<'a> {
    /// Actor `name`'s part on `model` (mirrored as its room ran it) with its `transforms`,
    /// and how it skins: `skinning` where its room chose, else the model's default. What
    /// [`skinned_parts_recording_to_glb`] takes per actor of a take.
    pub fn of(
        name: &'a str,
        model: &'a super::TrainedModel,
        skinning: Option<Skinning>,
        transforms: &'a [RigidTransform],
    ) -> (SkinnedPart<'a>, Skinning) {
        let part = SkinnedPart {
            name: Some(name),
            rig: &model.rig,
            transforms,
        };
        (part, skinning.unwrap_or(model.skinning))
    }
}

/// Several recordings of one take (a room of actors, issue 38) as one skinned glTF: one
/// skinned mesh per part, each with its own joints and skin, and one animation `name` whose
/// keyframes at `times` seconds move every part's joints. Each part is checked and refused as
/// [`skinned_recording_to_glb`] refuses a single one.
///
/// # Errors
/// [`ModelError::Export`] for no frames, dual-quaternion skinning, or a part's keyframes
/// that [`skinned_animation_to_glb`] would refuse.
pub fn skinned_parts_recording_to_glb(
    parts: &[(SkinnedPart<'_>, Skinning)],
    name: &str,
    times: &[f64],
) -> Result<Vec<u8>, ModelError> {
    if times.is_empty() {
        return Err(ModelError::Export("the take has no frames".into()));
    }
    let times: Vec<f32> = times.iter().map(|&t| t as f32).collect();
    for (part, skinning) in parts {
        let named = |e: ModelError| match (e, part.name) {
            (ModelError::Export(m), Some(n)) => ModelError::Export(format!("{n}: {m}")),
            (e, _) => e,
        };
        if *skinning == Skinning::Dqs {
            return Err(named(ModelError::Export(
                "skinned with dual quaternions, and glTF skins linearly".into(),
            )));
        }
        check_keyframes(part.rig, &times, part.transforms).map_err(named)?;
    }
    let parts: Vec<SkinnedPart<'_>> = parts.iter().map(|(p, _)| *p).collect();
    skinned_glb(&parts, name, &times)
}

/// A recording's predicted bone transforms (what a room's take holds) as a skinned glTF
/// animation: [`skinned_animation_to_glb`] with keyframe `f` at `times[f]` seconds, after
/// checking that the recording can be one. glTF skins linearly, so frames the room skinned
/// with dual quaternions ([`Skinning::Dqs`]) are refused: the file would not show the room's
/// meshes.
///
/// # Errors
/// [`ModelError::Export`] for no frames or dual-quaternion skinning; what
/// [`skinned_animation_to_glb`] refuses.
pub fn skinned_recording_to_glb(
    rig: &Rig,
    skinning: Skinning,
    name: &str,
    times: &[f64],
    transforms: &[RigidTransform],
) -> Result<Vec<u8>, ModelError> {
    if times.is_empty() {
        return Err(ModelError::Export("the take has no frames".into()));
    }
    if skinning == Skinning::Dqs {
        return Err(ModelError::Export(
            "the room skinned with dual quaternions and glTF skins linearly: the skinned \
             export would not be the room's meshes (export --level detail, or record an LBS \
             room)"
                .into(),
        ));
    }
    let times: Vec<f32> = times.iter().map(|&t| t as f32).collect();
    skinned_animation_to_glb(rig, name, &times, transforms)
}

/// The skinned GLB of `parts` (one skinned mesh each) with animation `name` (none when
/// `times` is empty); each part's `transforms` holds `times.len()` frames of its rig's bones.
fn skinned_glb(
    parts: &[SkinnedPart<'_>],
    name: &str,
    times: &[f32],
) -> Result<Vec<u8>, ModelError> {
    let mut root = json::Root::default();
    let mut bin = Vec::new();
    let mut scene_nodes = Vec::new();
    let mut joints_of = Vec::with_capacity(parts.len());
    for part in parts {
        let m = push_skinned_mesh(&mut root, &mut bin, part)?;
        scene_nodes.extend([m.skeleton, m.mesh_node]);
        joints_of.push((m.centres, m.joint_nodes));
    }
    let scene = root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("rig".into()),
        nodes: scene_nodes,
    });
    root.scene = Some(scene);

    if !times.is_empty() {
        let animated: Vec<AnimatedPart<'_>> = parts
            .iter()
            .zip(&joints_of)
            .map(|(p, (c, j))| (p.transforms, c.as_slice(), j.as_slice()))
            .collect();
        push_animation(&mut root, &mut bin, name, times, &animated);
    }

    root.asset = json::Asset {
        generator: Some(format!("crease {}", env!("CARGO_PKG_VERSION"))),
        version: "2.0".into(),
        ..Default::default()
    };
    root.push(json::Buffer {
        byte_length: USize64::from(bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let json_bytes = root
        .to_vec()
        .map_err(|e| ModelError::Export(e.to_string()))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: json_bytes.into(),
        bin: Some(bin.into()),
    };
    // `to_vec` computes the real length itself; the header's `length` is ignored when writing.
    glb.to_vec().map_err(|e| ModelError::Export(e.to_string()))
}

/// Pushes `part`'s skinned mesh (its rest mesh, joints, skin, skeleton): its skeleton node,
/// its mesh node, its joints' centres and nodes.
fn push_skinned_mesh(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    part: &SkinnedPart<'_>,
) -> Result<PushedMesh, ModelError> {
    let rig = part.rig;
    let (mesh_name, prefix) = match part.name {
        Some(n) => (n.to_owned(), format!("{n}_")),
        None => ("rest".to_owned(), String::new()),
    };
    rig.validate()?;
    let n = rig.rest.vertex_count();
    if n == 0 || rig.rest.triangles.is_empty() {
        return Err(ModelError::Export("the rest mesh has no triangles".into()));
    }
    if rig.bone_count == 0 || rig.bone_count > usize::from(u16::MAX) + 1 {
        return Err(ModelError::Export(format!(
            "{} bones; JOINTS_n are u16 here, so 1..=65536 bones can be exported",
            rig.bone_count
        )));
    }
    let slots = if rig.skin.k() <= 4 { 4 } else { 8 };
    let (joints, weights) = influences(rig, slots);
    let centres = bone_centres(rig);

    let (lo, hi) = rig.rest.bounding_box();
    let positions = flat_f32(rig.rest.positions.iter().flat_map(|p| p.to_array()));
    let pos = push_accessor(
        root,
        bin,
        &positions,
        n,
        F32,
        json::accessor::Type::Vec3,
        Some(VERTEX),
        Some((lo.to_array().to_vec(), hi.to_array().to_vec())),
    );
    let tri_bytes: Vec<u8> = rig
        .rest
        .triangles
        .iter()
        .flatten()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let indices = push_accessor(
        root,
        bin,
        &tri_bytes,
        3 * rig.rest.triangles.len(),
        U32,
        json::accessor::Type::Scalar,
        Some(INDEX),
        None,
    );

    let mut attributes = BTreeMap::new();
    attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), pos);
    for set in 0..slots / 4 {
        let j: Vec<u8> = joints
            .chunks_exact(slots)
            .flat_map(|c| &c[4 * set..4 * set + 4])
            .flat_map(|j| j.to_le_bytes())
            .collect();
        let w = flat_f32(
            weights
                .chunks_exact(slots)
                .flat_map(|c| c[4 * set..4 * set + 4].to_vec()),
        );
        let ja = push_accessor(
            root,
            bin,
            &j,
            n,
            U16,
            json::accessor::Type::Vec4,
            Some(VERTEX),
            None,
        );
        let wa = push_accessor(
            root,
            bin,
            &w,
            n,
            F32,
            json::accessor::Type::Vec4,
            Some(VERTEX),
            None,
        );
        attributes.insert(Checked::Valid(json::mesh::Semantic::Joints(set as u32)), ja);
        attributes.insert(
            Checked::Valid(json::mesh::Semantic::Weights(set as u32)),
            wa,
        );
    }
    let mesh = root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some(mesh_name.clone()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: None,
            mode: Checked::Valid(json::mesh::Mode::Triangles),
            targets: None,
        }],
        weights: None,
    });

    let joint_nodes: Vec<_> = centres
        .iter()
        .enumerate()
        .map(|(i, c)| {
            root.push(json::Node {
                name: Some(format!("{prefix}bone_{i}")),
                translation: Some(c.to_array()),
                ..Default::default()
            })
        })
        .collect();
    let skeleton = root.push(json::Node {
        name: Some(format!("{prefix}rig")),
        children: Some(joint_nodes.clone()),
        ..Default::default()
    });
    let ibm = flat_f32(
        centres
            .iter()
            .flat_map(|&c| Mat4::from_translation(-c).to_cols_array()),
    );
    let ibm = push_accessor(
        root,
        bin,
        &ibm,
        centres.len(),
        F32,
        json::accessor::Type::Mat4,
        None,
        None,
    );
    let skin = root.push(json::Skin {
        extensions: None,
        extras: Default::default(),
        inverse_bind_matrices: Some(ibm),
        joints: joint_nodes.clone(),
        name: Some("proxy_bones".into()),
        skeleton: Some(skeleton),
    });
    let mesh_node = root.push(json::Node {
        name: Some(mesh_name),
        mesh: Some(mesh),
        skin: Some(skin),
        ..Default::default()
    });
    Ok(PushedMesh {
        skeleton,
        mesh_node,
        centres,
        joint_nodes,
    })
}

/// One skinned mesh's part of an animation: its transforms (`times.len()` frames of its
/// bones), its joints' centres and nodes.
type AnimatedPart<'a> = (
    &'a [RigidTransform],
    &'a [Vec3],
    &'a [json::Index<json::Node>],
);

/// The skinned mesh [`push_skinned_mesh`] pushed: its skeleton and mesh nodes, its joints'
/// centres and nodes.
struct PushedMesh {
    skeleton: json::Index<json::Node>,
    mesh_node: json::Index<json::Node>,
    centres: Vec<Vec3>,
    joint_nodes: Vec<json::Index<json::Node>>,
}

/// The animation `name`: keyframes at `times` seconds; per part, per joint one translation
/// and one rotation sampler over the keyframes.
fn push_animation(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    name: &str,
    times: &[f32],
    parts: &[AnimatedPart<'_>],
) {
    let e = times.len();
    let (first, last) = (times[0], times[e - 1]);
    let input = push_accessor(
        root,
        bin,
        &flat_f32(times.iter().copied()),
        e,
        F32,
        json::accessor::Type::Scalar,
        None,
        Some((vec![first], vec![last])),
    );
    let joints: usize = parts.iter().map(|p| p.1.len()).sum();
    let mut samplers = Vec::with_capacity(2 * joints);
    let mut channels = Vec::with_capacity(2 * joints);
    for &(transforms, centres, joint_nodes) in parts {
        let bones = centres.len();
        for (b, (&c, &node)) in centres.iter().zip(joint_nodes).enumerate() {
            let mut translations = Vec::with_capacity(3 * e);
            let mut rotations = Vec::with_capacity(4 * e);
            let mut prev = glam::Quat::IDENTITY;
            for frame in transforms.chunks_exact(bones) {
                let t = frame[b];
                // Keep consecutive keys in one hemisphere so LINEAR slerps the short way; q and -q
                // are the same rotation, so the keyframes themselves are unchanged.
                let q = if t.rotation.dot(prev) < 0.0 {
                    -t.rotation
                } else {
                    t.rotation
                };
                prev = q;
                translations.extend((q * c + t.translation).to_array());
                rotations.extend(q.to_array());
            }
            for (values, ty, property) in [
                (
                    translations,
                    json::accessor::Type::Vec3,
                    json::animation::Property::Translation,
                ),
                (
                    rotations,
                    json::accessor::Type::Vec4,
                    json::animation::Property::Rotation,
                ),
            ] {
                let output = push_accessor(root, bin, &flat_f32(values), e, F32, ty, None, None);
                let sampler = json::Index::new(samplers.len() as u32);
                samplers.push(json::animation::Sampler {
                    extensions: None,
                    extras: Default::default(),
                    input,
                    interpolation: Checked::Valid(json::animation::Interpolation::Linear),
                    output,
                });
                channels.push(json::animation::Channel {
                    sampler,
                    target: json::animation::Target {
                        extensions: None,
                        extras: Default::default(),
                        node,
                        path: Checked::Valid(property),
                    },
                    extensions: None,
                    extras: Default::default(),
                });
            }
        }
    }
    root.push(json::Animation {
        extensions: None,
        extras: Default::default(),
        channels,
        name: Some(name.into()),
        samplers,
    });
}

/// Per vertex `slots` joints and weights: the vertex's non-zero influences with repeated bones
/// merged (glTF forbids a joint twice with non-zero weight), renormalised to sum to 1, padded
/// with joint 0 weight 0.
fn influences(rig: &Rig, slots: usize) -> (Vec<u16>, Vec<f32>) {
    let n = rig.skin.vertex_count();
    let mut joints = vec![0u16; n * slots];
    let mut weights = vec![0.0f32; n * slots];
    for (v, (ii, ww)) in rig.skin.iter().enumerate() {
        let (js, ws) = (
            &mut joints[v * slots..][..slots],
            &mut weights[v * slots..][..slots],
        );
        let mut used = 0;
        for (&b, &w) in ii.iter().zip(ww).filter(|(_, w)| **w > 0.0) {
            // bone_count <= 65536 was checked, so b fits in u16.
            let b = b as u16;
            match js[..used].iter().position(|&j| j == b) {
                Some(s) => ws[s] += w,
                None => {
                    js[used] = b;
                    ws[used] = w;
                    used += 1;
                }
            }
        }
        let sum: f32 = ws.iter().sum();
        ws.iter_mut().for_each(|w| *w /= sum);
    }
    (joints, weights)
}

/// Component-wise minimum and maximum (glTF accessor `min`/`max`) of a non-empty sequence.
fn min_max(values: impl Iterator<Item = Vec3>) -> (Vec3, Vec3) {
    values.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
        (lo.min(p), hi.max(p))
    })
}

/// Little-endian bytes of f32 values.
fn flat_f32(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

const F32: json::accessor::ComponentType = json::accessor::ComponentType::F32;
const U32: json::accessor::ComponentType = json::accessor::ComponentType::U32;
const U16: json::accessor::ComponentType = json::accessor::ComponentType::U16;
const VERTEX: json::buffer::Target = json::buffer::Target::ArrayBuffer;
const INDEX: json::buffer::Target = json::buffer::Target::ElementArrayBuffer;

/// Appends `bytes` to the binary chunk (4-byte aligned) as a new buffer view and returns an
/// accessor over all of it.
#[allow(clippy::too_many_arguments)]
fn push_accessor(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    bytes: &[u8],
    count: usize,
    component: json::accessor::ComponentType,
    ty: json::accessor::Type,
    target: Option<json::buffer::Target>,
    min_max: Option<(Vec<f32>, Vec<f32>)>,
) -> json::Index<json::Accessor> {
    bin.resize(bin.len().next_multiple_of(4), 0);
    let accessor = accessor_at(
        root,
        bin.len() as u64,
        bytes.len() as u64,
        count,
        component,
        ty,
        target,
        min_max,
    );
    bin.extend_from_slice(bytes);
    accessor
}

/// A new buffer view of `byte_length` bytes at `offset` in buffer 0 and an accessor over all of
/// it; the caller puts the bytes there.
#[allow(clippy::too_many_arguments)]
fn accessor_at(
    root: &mut json::Root,
    offset: u64,
    byte_length: u64,
    count: usize,
    component: json::accessor::ComponentType,
    ty: json::accessor::Type,
    target: Option<json::buffer::Target>,
    min_max: Option<(Vec<f32>, Vec<f32>)>,
) -> json::Index<json::Accessor> {
    let view = root.push(json::buffer::View {
        buffer: json::Index::new(0),
        byte_length: USize64::from(byte_length),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        name: None,
        target: target.map(Checked::Valid),
        extensions: None,
        extras: Default::default(),
    });
    let (min, max) = match min_max {
        Some((lo, hi)) => (Some(json::Value::from(lo)), Some(json::Value::from(hi))),
        None => (None, None),
    };
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Checked::Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Checked::Valid(ty),
        min,
        max,
        name: None,
        normalized: false,
        sparse: None,
    })
}

mod morph;

pub use morph::{GLB_MAX_BYTES, animation_to_glb, check_animation_size, export_animation_glb};

#[cfg(test)]
#[path = "gltf_export_tests.rs"]
mod tests;
