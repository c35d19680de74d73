//! A [`Rig`] as a skinned, animated glTF 2.0 binary (`.glb`), so any glTF viewer (three.js,
//! Blender) can show the proxy bones driving the rest mesh through the examples.
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

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Mat4, Vec3};
use gltf_json as json;
use json::validation::{Checked, USize64};

use super::ModelError;
use super::file::write_atomic;
use super::rig::Rig;

/// Seconds between consecutive example keyframes: slow enough to see each pose in a viewer.
pub const SECONDS_PER_EXAMPLE: f32 = 1.0;

/// Writes `rig` to `path` as a skinned, animated GLB (atomically, like the model files).
pub fn export_rig_glb(rig: &Rig, path: impl AsRef<Path>) -> Result<(), ModelError> {
    let path = path.as_ref();
    let bytes = rig_to_glb(rig)?;
    write_atomic(path, &bytes).map_err(|source| ModelError::Io {
        path: path.to_path_buf(),
        source,
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

    let mut root = json::Root::default();
    let mut bin = Vec::new();

    let (lo, hi) = rig.rest.bounding_box();
    let positions = flat_f32(rig.rest.positions.iter().flat_map(|p| p.to_array()));
    let pos = push_accessor(
        &mut root,
        &mut bin,
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
        &mut root,
        &mut bin,
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
            &mut root,
            &mut bin,
            &j,
            n,
            U16,
            json::accessor::Type::Vec4,
            Some(VERTEX),
            None,
        );
        let wa = push_accessor(
            &mut root,
            &mut bin,
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
        name: Some("rest".into()),
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
                name: Some(format!("bone_{i}")),
                translation: Some(c.to_array()),
                ..Default::default()
            })
        })
        .collect();
    let skeleton = root.push(json::Node {
        name: Some("rig".into()),
        children: Some(joint_nodes.clone()),
        ..Default::default()
    });
    let ibm = flat_f32(
        centres
            .iter()
            .flat_map(|&c| Mat4::from_translation(-c).to_cols_array()),
    );
    let ibm = push_accessor(
        &mut root,
        &mut bin,
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
        name: Some("rest".into()),
        mesh: Some(mesh),
        skin: Some(skin),
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("rig".into()),
        nodes: vec![skeleton, mesh_node],
    });
    root.scene = Some(scene);

    if !rig.examples.is_empty() {
        push_animation(&mut root, &mut bin, rig, &centres, &joint_nodes);
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

/// The example animation: per joint one translation and one rotation sampler, keyframe `e` at
/// `e * SECONDS_PER_EXAMPLE`.
fn push_animation(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    rig: &Rig,
    centres: &[Vec3],
    joint_nodes: &[json::Index<json::Node>],
) {
    let e = rig.examples.len();
    let times: Vec<f32> = (0..e).map(|i| i as f32 * SECONDS_PER_EXAMPLE).collect();
    let last = times[e - 1];
    let input = push_accessor(
        root,
        bin,
        &flat_f32(times),
        e,
        F32,
        json::accessor::Type::Scalar,
        None,
        Some((vec![0.0], vec![last])),
    );
    let mut samplers = Vec::with_capacity(2 * centres.len());
    let mut channels = Vec::with_capacity(2 * centres.len());
    for (b, (&c, &node)) in centres.iter().zip(joint_nodes).enumerate() {
        let mut translations = Vec::with_capacity(3 * e);
        let mut rotations = Vec::with_capacity(4 * e);
        let mut prev = glam::Quat::IDENTITY;
        for ex in &rig.examples {
            let t = ex.transforms[b];
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
    root.push(json::Animation {
        extensions: None,
        extras: Default::default(),
        channels,
        name: Some("examples".into()),
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
    let view = root.push(json::buffer::View {
        buffer: json::Index::new(0),
        byte_length: USize64::from(bytes.len()),
        byte_offset: Some(USize64::from(bin.len())),
        byte_stride: None,
        name: None,
        target: target.map(Checked::Valid),
        extensions: None,
        extras: Default::default(),
    });
    bin.extend_from_slice(bytes);
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
