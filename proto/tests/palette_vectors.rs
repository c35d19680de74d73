//! The palette test vectors, `tests/vectors/palette-v1.json` (issue 18): palette frames (a
//! keyframe and a delta of bone lanes through the codec) and a palette header of a small
//! detailed mesh, as bytes and as what they decode to, so that any palette decoder (the Rust
//! one, the viewer's) can be checked against them byte for byte. Checked by
//! `cargo test -p crease-proto --test palette_vectors`; regenerated, after a deliberate format
//! change only, by `cargo test -p crease-proto --test palette_vectors -- --ignored regenerate`.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use crease_core::codec::palette::{
    PaletteFrame, PaletteHeader, PaletteSynth, ROTATION_ERROR, palette_lanes, palette_vertex_count,
    read_palette_lanes, translation_box,
};
use crease_core::codec::{FrameDecoder, FrameEncoder, decode_indices};
use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::mesh::subdivision::LoopSubdivision;
use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
use crease_core::runtime::kernel::Kernel;
use crease_core::runtime::predict::LinearOperator;
use crease_core::runtime::skin::{RigidTransform, SkinWeights};
use crease_proto::{Level, PaletteParts, palette_topology_message, read_palette_topology, v1};
use prost::Message;
use serde_json::{Value, json};

const VECTORS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/vectors/palette-v1.json"
);

/// A float as a string holding its shortest round-trip decimal (as codec-v1.json).
fn jf(x: f32) -> Value {
    Value::String(format!("{x:?}"))
}

fn jfs(v: &[f32]) -> Value {
    Value::Array(v.iter().map(|&x| jf(x)).collect())
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

fn bones_json(bones: &[RigidTransform]) -> Value {
    Value::Array(
        bones
            .iter()
            .map(|b| {
                json!({
                    "rotation_xyzw": jfs(&b.rotation.to_array()),
                    "translation": jfs(&b.translation.to_array()),
                })
            })
            .collect(),
    )
}

/// A tetrahedron skinned to two bones, one Loop level, a detail regressor of two examples.
fn header() -> PaletteHeader {
    let mesh = Mesh {
        positions: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
        triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    };
    let skin = SkinWeights::new(
        2,
        vec![0, 1, 0, 1, 1, 0, 1, 0],
        vec![1.0, 0.0, 0.7, 0.3, 0.6, 0.4, 0.9, 0.1],
    )
    .unwrap();
    let subdivision = LoopSubdivision::new(&mesh, 1).unwrap();
    let n = subdivision.vertex_count();
    let regressor = DetailRegressor {
        input: DetailInput::Controls,
        kernel: Kernel::Gaussian { sigma: 1.0 },
        d_in: 3,
        examples: vec![0.0, 0.0, 0.0, 1.0, 0.5, 0.0],
        operator: LinearOperator {
            rows: n,
            cols: 2,
            m: (0..2 * n).map(|i| 0.01 * (i as f32 - 9.5)).collect(),
            b: (0..n).map(|i| 0.002 * i as f32).collect(),
        },
    };
    PaletteHeader::base(&mesh.positions, &mesh.triangles, &skin, 2)
        .unwrap()
        .with_detail(&subdivision, &regressor)
        .unwrap()
}

fn build_vectors() -> Value {
    let frames_in = [
        (
            vec![
                RigidTransform::new(Quat::IDENTITY, Vec3::new(0.25, -0.5, 0.125)),
                RigidTransform::new(Quat::from_rotation_z(0.4), Vec3::new(-0.3, 0.2, 0.9)),
            ],
            vec![0.75f32, 0.125],
        ),
        (
            vec![
                RigidTransform::new(Quat::from_rotation_x(-0.05), Vec3::new(0.26, -0.5, 0.125)),
                RigidTransform::new(Quat::from_rotation_z(0.45), Vec3::new(-0.3, 0.21, 0.9)),
            ],
            vec![0.7f32, 0.2],
        ),
    ];
    let h = header();
    let qbox = translation_box(Vec3::splat(-1.0), Vec3::splat(2.0), &h.rest).unwrap();
    let n = palette_vertex_count(2, 2);
    let mut enc = FrameEncoder::new(n, qbox, 0).unwrap();
    let mut dec = FrameDecoder::new(n);
    let mut synth = PaletteSynth::new(h.clone()).unwrap();
    let mut frame = PaletteFrame::default();
    let mut frames = Vec::new();
    for (bones, xi) in &frames_in {
        let mut lanes = Vec::new();
        palette_lanes(bones, xi, &qbox, &mut lanes).unwrap();
        let mut bytes = Vec::new();
        let header = enc
            .encode_lanes(|l| l.extend_from_slice(&lanes), &mut bytes)
            .unwrap();
        let got = dec.decode(&bytes).unwrap();
        read_palette_lanes(dec.lanes(), &got.qbox, 2, 2, &mut frame).unwrap();
        let out: Vec<Value> = synth
            .synthesize(&frame)
            .unwrap()
            .iter()
            .map(|p| jfs(&p.to_array()))
            .collect();
        frames.push(json!({
            "bones": bones_json(bones),
            "xi": jfs(xi),
            "kind": format!("{:?}", header.kind),
            "lanes": lanes,
            "frame_hex": hex(&bytes),
            "decoded_bones": bones_json(&frame.bones),
            "decoded_xi": jfs(&frame.xi),
            "synthesized": out,
        }));
    }
    let msg = palette_topology_message(PaletteParts {
        model: "tetra",
        level: Level::Detail,
        bounds: (Vec3::splat(-1.0), Vec3::splat(2.0)),
        header: &h,
    })
    .unwrap();
    let d = h.detail.as_ref().unwrap();
    let Some(v1::mesh_frame::Body::PaletteTopology(t)) = &msg.body else {
        unreachable!("a palette topology message");
    };
    // What the index codec gives back (it may rotate a triangle's corners, winding kept),
    // before the header's corner turns put them back.
    let mut decoded_triangles = Vec::new();
    decode_indices(
        &t.indices,
        h.triangles.len(),
        h.rest.len(),
        &mut decoded_triangles,
    )
    .unwrap();
    let steps: Vec<Value> = d
        .steps
        .iter()
        .map(|s| {
            json!({
                "columns": s.columns(),
                "row_ptr": s.row_ptr(),
                "cols": s.cols(),
                "weights": jfs(s.vals()),
            })
        })
        .collect();
    let rest: Vec<Value> = h.rest.iter().map(|p| jfs(&p.to_array())).collect();
    json!({
        "about": "crease palette v1 test vectors (core::codec::palette, crease-proto::palette): a PaletteTopology of a tetrahedron (2 bones, K = 2, one Loop level, N = 2) as an encoded MeshFrame (header_hex) with its decoded arrays (the base triangles as the index codec gives them back and after the header's corner turns, the Loop steps and drawn triangles a decoder rebuilds from them, the detail values q with their step), then two palette frames (a keyframe, a delta) as core::codec frames of lanes (frame_hex) with their inputs, lanes, decoded bones and xi, and the mesh core's reference decoder synthesises from them (synthesized, drawn vertices in order). Floats are strings: shortest decimals of exact f32s. Regenerate with `cargo test -p crease-proto --test palette_vectors -- --ignored regenerate`.",
        "version": 1,
        "header_hex": hex(&msg.encode_to_vec()),
        "header": {
            "bones": h.bones,
            "rest": rest,
            "influences": h.skin.influences,
            "skin_bones": h.skin.bones,
            "skin_weights": h.skin.weights,
            "triangles": h.triangles,
            "decoded_triangles": decoded_triangles,
            "triangle_turns": t.triangle_turns.to_vec(),
            "levels": d.levels,
            "steps": steps,
            "drawn_triangles": d.triangles,
            "examples": d.examples,
            "detail_step": jf(d.quantum),
            "detail_rows": d.rows,
        },
        "frames": frames,
    })
}

#[test]
#[ignore = "writes tests/vectors/palette-v1.json: run only after a deliberate format change"]
fn regenerate() {
    let text = serde_json::to_string_pretty(&build_vectors()).unwrap();
    std::fs::write(VECTORS, text + "\n").unwrap();
    println!("wrote {VECTORS}");
}

#[test]
fn test_vectors_match() {
    let text = std::fs::read_to_string(VECTORS).expect("tests/vectors/palette-v1.json");
    let file: Value = serde_json::from_str(&text).unwrap();
    // The encoder and the header builder still write exactly these bytes.
    assert_eq!(
        file,
        build_vectors(),
        "regenerate only after a deliberate format change"
    );
    // And the decoders read the file's bytes back to the file's values, on their own: the
    // header...
    let bytes = unhex(file["header_hex"].as_str().unwrap());
    let msg = v1::MeshFrame::decode(bytes.as_slice()).unwrap();
    let Some(v1::mesh_frame::Body::PaletteTopology(t)) = msg.body else {
        panic!("header_hex is not a PaletteTopology");
    };
    let read = read_palette_topology(&t).unwrap();
    let want = &file["header"];
    let d = read.header.detail.as_ref().unwrap();
    assert_eq!(json!(read.header.skin.weights), want["skin_weights"]);
    assert_eq!(json!(read.header.skin.bones), want["skin_bones"]);
    assert_eq!(json!(d.rows), want["detail_rows"]);
    assert_eq!(jf(d.quantum), want["detail_step"]);
    // The base triangles come back exactly as sent (corner turns applied), and the steps and
    // drawn triangles rebuilt from them are the subdivision's own.
    assert_eq!(json!(read.header.triangles), want["triangles"]);
    let subdivision = LoopSubdivision::new(
        &Mesh {
            positions: read.header.rest.clone(),
            triangles: read.header.triangles.clone(),
        },
        1,
    )
    .unwrap();
    assert_eq!(d.steps, subdivision.steps());
    assert_eq!(d.triangles, subdivision.triangles());
    assert_eq!(json!(d.triangles), want["drawn_triangles"]);
    assert_eq!(json!(d.steps[0].cols()), want["steps"][0]["cols"]);
    assert_eq!(d.triangles.len(), 16);
    // The index codec may rotate a triangle's corners but keeps each one and its winding.
    let rotations = |t: [u32; 3]| [t, [t[1], t[2], t[0]], [t[2], t[0], t[1]]];
    let input: Vec<[u32; 3]> = serde_json::from_value(want["triangles"].clone()).unwrap();
    let raw: Vec<[u32; 3]> = serde_json::from_value(want["decoded_triangles"].clone()).unwrap();
    for (got, t) in raw.iter().zip(&input) {
        assert!(
            rotations(*t).contains(got),
            "{got:?} is not a rotation of {t:?}"
        );
    }
    // ... and the frames, in order.
    let mut dec = FrameDecoder::new(palette_vertex_count(2, 2));
    let mut frame = PaletteFrame::default();
    for f in file["frames"].as_array().unwrap() {
        let got = dec
            .decode(&unhex(f["frame_hex"].as_str().unwrap()))
            .unwrap();
        let lanes: Vec<[u16; 4]> = serde_json::from_value(f["lanes"].clone()).unwrap();
        assert_eq!(dec.lanes(), lanes.as_slice());
        read_palette_lanes(dec.lanes(), &got.qbox, 2, 2, &mut frame).unwrap();
        assert_eq!(bones_json(&frame.bones), f["decoded_bones"]);
        assert_eq!(jfs(&frame.xi), f["decoded_xi"]);
        // The decoded bones are the inputs within the format's bounds, xi exactly.
        assert_eq!(f["decoded_xi"], f["xi"]);
        let num = |v: &Value| -> Vec<f32> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_str().unwrap().parse().unwrap())
                .collect()
        };
        for (b, input) in frame.bones.iter().zip(f["bones"].as_array().unwrap()) {
            let q = Quat::from_slice(&num(&input["rotation_xyzw"])).normalize();
            let t = Vec3::from_slice(&num(&input["translation"]));
            let dq = (b.rotation - q).length().min((b.rotation + q).length());
            assert!(dq <= ROTATION_ERROR, "rotation error {dq}");
            let dt = (b.translation - t).abs();
            assert!(
                dt.cmple(frame.translation_error() * 1.001 + 1e-7).all(),
                "translation error {dt}"
            );
        }
    }
    let kinds: Vec<&str> = file["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["Key", "Delta"]);
}
