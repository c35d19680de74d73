//! `core::codec`: quantisation bound, clamping, octahedral normals, keyframes and deltas on the
//! horse gallop, malformed frames, the index codec, and the test vectors in
//! `tests/vectors/codec-v1.json` (repository root).
//!
//! The vectors are regenerated (after a deliberate format change only) with
//! `cargo test -p crease-core --test all -- --ignored codec::regenerate_test_vectors`;
//! `test_vectors_match` re-encodes the file's inputs and decodes its bytes.

use std::fmt::Write as _;
use std::path::Path;

use crease_core::codec::{
    CodecError, FrameDecoder, FrameEncoder, FrameHeader, FrameKind, HEADER_LEN, OCT_MAX_ERROR_DEG,
    QuantBox, decode_indices, decode_keyframe, encode_indices, encode_keyframe,
    encode_keyframe_from_lanes, oct_decode, oct_encode, parse_frame,
};
use crease_core::glam::{DVec3, Vec3};
use crease_core::mesh::{ExampleSet, Mesh, compute_vertex_normals};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::{Value, json};

const HORSE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/horse");
const VECTORS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/vectors/codec-v1.json"
);

/// The horse's rest pose and gallop, or `None` (with the reason printed) when the data is absent.
fn horse() -> Option<(Mesh, Vec<Mesh>)> {
    let rest = Mesh::read(format!("{HORSE}/reference.obj"));
    let gallop = ExampleSet::load(format!("{HORSE}/gallop"));
    match (rest, gallop) {
        (Ok(rest), Ok(set)) => Some((rest, set.examples.into_iter().map(|e| e.mesh).collect())),
        (r, g) => {
            eprintln!(
                "skipped: horse data not found under {HORSE} ({:?} / {:?})",
                r.err(),
                g.err()
            );
            None
        }
    }
}

/// The largest per-axis error allowed for a decoded position of `p` (computed in f64 by the
/// caller): half a step, plus one f32 rounding of the result.
fn tolerance(qbox: &QuantBox, p: Vec3) -> DVec3 {
    qbox.error_bound().as_dvec3() + (p.abs().as_dvec3() + qbox.step().as_dvec3()) * 2f64.powi(-24)
}

/// The angle between two directions in degrees, in f64 (atan2 of |a x b| and a . b).
fn angle_deg(a: Vec3, b: Vec3) -> f64 {
    let (a, b) = (a.as_dvec3(), b.as_dvec3());
    a.cross(b).length().atan2(a.dot(b)).to_degrees()
}

fn check_within_bound(qbox: &QuantBox, original: &[Vec3], decoded: &[Vec3], what: &str) {
    assert_eq!(original.len(), decoded.len());
    for (i, (p, d)) in original.iter().zip(decoded).enumerate() {
        let err = (d.as_dvec3() - p.as_dvec3()).abs();
        let tol = tolerance(qbox, *p);
        assert!(
            err.cmple(tol).all(),
            "{what}: vertex {i}: {p} decoded as {d}, error {err} > bound {tol}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Quantisation and normals

#[test]
fn quantisation_error_is_at_most_half_a_step_at_16_and_12_bits() {
    let mut rng = StdRng::seed_from_u64(6);
    for bits in [16u8, 12, 1] {
        let (lo, hi) = (Vec3::new(-0.21, -0.008, -0.92), Vec3::new(0.21, 1.51, 0.81));
        let qbox = QuantBox::from_bounds(lo, hi, 0.25, bits).unwrap();
        // The independent expectation: the step is the padded extent over 2^bits - 1.
        let pad = 0.25 * f64::from((hi - lo).max_element());
        let extent = f64::from(hi.y - lo.y) + 2.0 * pad;
        let step = extent / f64::from((1u32 << bits) - 1);
        assert!(
            (f64::from(qbox.step().y) - step).abs() <= step * 1e-6,
            "bits {bits}"
        );
        let points: Vec<Vec3> = (0..20_000)
            .map(|_| {
                let t = Vec3::new(rng.random(), rng.random(), rng.random());
                qbox.min() + t * (qbox.max() - qbox.min())
            })
            .collect();
        let decoded: Vec<Vec3> = points
            .iter()
            .map(|&p| qbox.dequantise(qbox.quantise(p)))
            .collect();
        check_within_bound(&qbox, &points, &decoded, &format!("{bits} bits"));
    }
}

#[test]
fn out_of_box_values_clamp_and_nan_maps_to_the_centre() {
    let qbox = QuantBox::from_bounds(Vec3::ZERO, Vec3::new(1.0, 2.0, 4.0), 0.0, 16).unwrap();
    let positions = [
        Vec3::new(5.0, -3.0, 4.5),
        Vec3::new(f32::INFINITY, f32::NEG_INFINITY, f32::NAN),
        Vec3::splat(f32::NAN),
        Vec3::new(f32::MAX, -f32::MAX, 1e-30),
    ];
    let mut frame = Vec::new();
    encode_keyframe(&qbox, 0, &positions, None, &mut frame).unwrap();
    let mut decoded = Vec::new();
    decode_keyframe(&frame, positions.len(), &mut decoded, None).unwrap();
    let (lo, hi) = (qbox.min(), qbox.max());
    // Out of box: the nearest face. NaN: min + 32768 * step, the centre to within half a step.
    let centre = qbox.min() + qbox.step() * 32768.0;
    assert_eq!(decoded[0], Vec3::new(hi.x, lo.y, hi.z));
    assert_eq!(decoded[1], Vec3::new(hi.x, lo.y, centre.z));
    assert_eq!(decoded[2], centre);
    assert_eq!(decoded[3], Vec3::new(hi.x, lo.y, lo.z));
    assert!(
        (centre - Vec3::new(0.5, 1.0, 2.0))
            .abs()
            .cmple(qbox.step())
            .all()
    );
}

#[test]
fn octahedral_normals_are_within_the_stated_angle() {
    // A Fibonacci sphere (dense, even) plus axes, octahedron face diagonals and near-edge cases.
    let n = 200_000;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut dirs: Vec<Vec3> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3()
        })
        .collect();
    for s in [-1.0f32, 1.0] {
        dirs.extend([Vec3::X * s, Vec3::Y * s, Vec3::Z * s]);
        dirs.extend([Vec3::new(1.0, 1.0, 1e-7 * s), Vec3::new(-1.0, 1e-7, s)]);
        dirs.push(Vec3::new(s, s, s).normalize());
    }
    let mut worst = 0f64;
    let mut sum = 0f64;
    for &d in &dirs {
        let back = oct_decode(oct_encode(d));
        assert!((back.length() - 1.0).abs() < 1e-6, "{d} -> {back}");
        let a = angle_deg(d, back);
        worst = worst.max(a);
        sum += a;
    }
    println!(
        "octahedral 8+8 bits: max {worst:.3} deg, mean {:.3} deg over {} directions",
        sum / dirs.len() as f64,
        dirs.len()
    );
    assert!(worst <= OCT_MAX_ERROR_DEG, "max error {worst} deg");
    // Scale does not matter; zero and NaN are +Z.
    assert_eq!(
        oct_encode(Vec3::new(0.0, 3.0, 4.0)),
        oct_encode(Vec3::new(0.0, 0.6, 0.8))
    );
    assert_eq!(oct_decode(oct_encode(Vec3::splat(f32::NAN))), Vec3::Z);
}

// ---------------------------------------------------------------------------------------------
// Streams on the horse

#[test]
fn horse_gallop_keys_and_deltas_stay_within_the_bound_without_drift() {
    let Some((rest, gallop)) = horse() else {
        return;
    };
    let (lo, hi) = rest.bounding_box();
    let qbox = QuantBox::from_bounds(lo, hi, 0.25, 16).unwrap();
    let n = rest.vertex_count();
    let mut normals: Vec<Vec3> = Vec::new();
    for with_normals in [false, true] {
        // Twice round the loop, a keyframe every 20 frames: long runs of deltas.
        let mut enc = FrameEncoder::new(n, qbox, 20).unwrap();
        let mut dec = FrameDecoder::new(n);
        let (mut frame, mut positions, mut decoded_normals) = (Vec::new(), Vec::new(), Vec::new());
        let (mut keys, mut deltas) = (0, 0);
        for (f, mesh) in gallop.iter().chain(&gallop).enumerate() {
            compute_vertex_normals(&mesh.positions, &mesh.triangles, &mut normals);
            let h = enc
                .encode(
                    &mesh.positions,
                    with_normals.then_some(&normals[..]),
                    &mut frame,
                )
                .unwrap();
            assert_eq!(h.kind == FrameKind::Key, f % 20 == 0, "frame {f}");
            match h.kind {
                FrameKind::Key => keys += 1,
                FrameKind::Delta => deltas += 1,
            }
            assert_eq!(dec.decode(&frame).unwrap(), h);
            assert_eq!(dec.lanes(), enc.lanes(), "frame {f}: decoder out of sync");
            dec.positions(&mut positions);
            check_within_bound(&qbox, &mesh.positions, &positions, &format!("frame {f}"));
            assert_eq!(dec.normals(&mut decoded_normals), with_normals);
            for (i, (a, b)) in normals.iter().zip(&decoded_normals).enumerate() {
                let e = angle_deg(*a, *b);
                assert!(
                    e <= OCT_MAX_ERROR_DEG,
                    "frame {f} vertex {i}: normal off by {e} deg"
                );
            }
        }
        assert_eq!((keys, deltas), (5, 91));
    }
}

#[test]
fn deltas_are_smaller_than_keyframes_on_the_gallop() {
    let Some((rest, gallop)) = horse() else {
        return;
    };
    let (lo, hi) = rest.bounding_box();
    let qbox = QuantBox::from_bounds(lo, hi, 0.25, 16).unwrap();
    let n = rest.vertex_count();
    let total = |interval: u32| -> usize {
        let mut enc = FrameEncoder::new(n, qbox, interval).unwrap();
        let mut frame = Vec::new();
        gallop
            .iter()
            .map(|m| {
                enc.encode(&m.positions, None, &mut frame).unwrap();
                frame.len()
            })
            .sum()
    };
    let per_vertex = |bytes: usize| bytes as f64 / (n * gallop.len()) as f64;
    let (key_only, with_deltas) = (per_vertex(total(1)), per_vertex(total(0)));
    println!("gallop: key-only {key_only:.3} B/vertex/frame, key + deltas {with_deltas:.3}");
    // Raw 16-bit lanes are 8 bytes; both must compress, deltas must pay.
    assert!(key_only < 6.0, "{key_only}");
    assert!(with_deltas < 0.8 * key_only, "{with_deltas} vs {key_only}");
}

#[test]
fn keyframe_schedule_follows_interval_force_and_normals() {
    let pts: Vec<Vec3> = (0..10).map(|i| Vec3::splat(i as f32 * 0.1)).collect();
    let qbox = QuantBox::from_positions(&pts, 0.25, 16).unwrap();
    let kinds = |interval: u32, script: &[(&str, bool)]| -> String {
        let mut enc = FrameEncoder::new(pts.len(), qbox, interval).unwrap();
        let mut frame = Vec::new();
        let mut s = String::new();
        for &(action, normals) in script {
            if action == "force" {
                enc.force_keyframe();
            }
            let h = enc
                .encode(&pts, normals.then_some(&pts[..]), &mut frame)
                .unwrap();
            s.push(if h.kind == FrameKind::Key { 'K' } else { 'D' });
        }
        s
    };
    let plain = [("", false); 7];
    assert_eq!(kinds(3, &plain), "KDDKDDK");
    assert_eq!(kinds(1, &plain), "KKKKKKK");
    assert_eq!(kinds(0, &plain), "KDDDDDD");
    let script = [
        ("", false),
        ("", false),
        ("force", false),
        ("", false),
        ("", true),
        ("", true),
        ("", false),
    ];
    assert_eq!(kinds(0, &script), "KDKDKDK");
}

#[test]
fn a_keyframe_from_the_encoders_lanes_is_the_keyframe_of_its_positions() {
    // A mesh moving through the box, half the frames deltas: after each frame, the keyframe of
    // the encoder's lanes is byte for byte the stateless keyframe of the same positions (which
    // quantises them itself), at 12 and 16 bits.
    let pts: Vec<Vec3> = (0..40)
        .map(|i| Vec3::new((i as f32 * 0.37).sin(), i as f32 * 0.05, (i as f32).cos()))
        .collect();
    for bits in [12u8, 16] {
        let qbox = QuantBox::from_positions(&pts, 0.25, bits).unwrap();
        let mut enc = FrameEncoder::new(pts.len(), qbox, 0).unwrap();
        let (mut frame, mut from_lanes, mut stateless) = (Vec::new(), Vec::new(), Vec::new());
        for f in 0..5 {
            let moved: Vec<Vec3> = pts
                .iter()
                .map(|p| *p + Vec3::X * (0.03 * f as f32))
                .collect();
            let h = enc.encode(&moved, None, &mut frame).unwrap();
            encode_keyframe_from_lanes(&qbox, h.seq, enc.lanes(), false, &mut from_lanes).unwrap();
            encode_keyframe(&qbox, h.seq, &moved, None, &mut stateless).unwrap();
            assert_eq!(from_lanes, stateless, "{bits} bits, frame {f}");
        }
    }
}

#[test]
fn a_delta_without_its_base_is_refused() {
    let pts: Vec<Vec3> = (0..50).map(|i| Vec3::new(i as f32, 0.0, 1.0)).collect();
    let qbox = QuantBox::from_positions(&pts, 0.25, 16).unwrap();
    let mut enc = FrameEncoder::new(pts.len(), qbox, 0).unwrap();
    let frames: Vec<Vec<u8>> = (0..4)
        .map(|f| {
            let moved: Vec<Vec3> = pts.iter().map(|p| *p + Vec3::Y * f as f32).collect();
            let mut out = Vec::new();
            enc.encode(&moved, None, &mut out).unwrap();
            out
        })
        .collect();
    // Joined mid-stream: no frame yet.
    let mut late = FrameDecoder::new(pts.len());
    assert_eq!(
        late.decode(&frames[2]),
        Err(CodecError::MissingBase { seq: 2, base: 1 })
    );
    assert!(late.lanes().is_empty());
    let mut out = Vec::new();
    late.positions(&mut out);
    assert!(out.is_empty());
    // Stateless keyframe decoding refuses deltas the same way.
    assert_eq!(
        decode_keyframe(&frames[1], pts.len(), &mut out, None),
        Err(CodecError::MissingBase { seq: 1, base: 0 })
    );
    // Skipped a frame: base mismatch, and the decoder keeps its frame.
    let mut skipper = FrameDecoder::new(pts.len());
    skipper.decode(&frames[0]).unwrap();
    let held = skipper.lanes().to_vec();
    assert_eq!(
        skipper.decode(&frames[2]),
        Err(CodecError::BaseMismatch {
            seq: 2,
            base: 1,
            have: 0
        })
    );
    assert_eq!(skipper.lanes(), &held[..]);
    // The server's remedy: the latest frame's lanes again as a keyframe, then the shared deltas.
    let mut key = Vec::new();
    let h = encode_keyframe_from_lanes(&qbox, 3, enc.lanes(), false, &mut key).unwrap();
    assert_eq!((h.kind, h.seq), (FrameKind::Key, 3));
    let mut next = Vec::new();
    let moved: Vec<Vec3> = pts.iter().map(|p| *p + Vec3::Y * 7.0).collect();
    enc.encode(&moved, None, &mut next).unwrap();
    for d in [&mut late, &mut skipper] {
        d.decode(&key).unwrap();
        d.decode(&next).unwrap();
        assert_eq!(d.lanes(), enc.lanes());
    }
    // A delta from another box or with normals added does not apply.
    let other = QuantBox::from_positions(&pts, 0.5, 16).unwrap();
    let mut enc2 = FrameEncoder::new(pts.len(), other, 0).unwrap();
    let (mut k2, mut d2) = (Vec::new(), Vec::new());
    enc2.encode(&pts, None, &mut k2).unwrap();
    enc2.encode(&pts, None, &mut d2).unwrap();
    let mut dec = FrameDecoder::new(pts.len());
    dec.decode(&frames[0]).unwrap();
    assert_eq!(
        dec.decode(&d2),
        Err(CodecError::BaseIncompatible {
            seq: 1,
            what: "quantisation box"
        })
    );
    // A keyframe from lanes decodes to exactly those lanes, normals flag included.
    let lanes = [[1u16, 2, 3, 0x7f80], [65535, 0, 7, 0x0180]];
    let h = encode_keyframe_from_lanes(&qbox, 9, &lanes, true, &mut key).unwrap();
    assert!(h.normals && h.kind == FrameKind::Key && h.base_seq == 9);
    let mut fresh = FrameDecoder::new(2);
    assert_eq!(fresh.decode(&key).unwrap().seq, 9);
    assert_eq!(fresh.lanes(), &lanes[..]);
    dec.reset();
    assert!(matches!(
        dec.decode(&next),
        Err(CodecError::MissingBase { .. })
    ));
}

#[test]
fn inputs_of_the_wrong_length_are_refused() {
    let pts = vec![Vec3::ONE; 5];
    let qbox = QuantBox::from_positions(&pts, 0.25, 16).unwrap();
    let mut enc = FrameEncoder::new(5, qbox, 0).unwrap();
    let mut out = Vec::new();
    assert_eq!(
        enc.encode(&pts[..4], None, &mut out),
        Err(CodecError::Length {
            what: "positions",
            expected: 5,
            found: 4
        })
    );
    assert_eq!(
        enc.encode(&pts, Some(&pts[..3]), &mut out),
        Err(CodecError::Length {
            what: "normals",
            expected: 5,
            found: 3
        })
    );
    assert_eq!(enc.next_seq(), 0);
    // An empty mesh is fine.
    let mut empty = FrameEncoder::new(0, qbox, 0).unwrap();
    empty.encode(&[], None, &mut out).unwrap();
    let mut dec = FrameDecoder::new(0);
    dec.decode(&out).unwrap();
}

// ---------------------------------------------------------------------------------------------
// Malformed frames

/// A keyframe and a delta with normals, 300 vertices (two meshopt blocks).
fn sample_frames() -> (usize, Vec<u8>, Vec<u8>) {
    let n = 300;
    let pts: Vec<Vec3> = (0..n)
        .map(|i| {
            let t = i as f32 * 0.05;
            Vec3::new(t.cos(), t.sin(), t * 0.1)
        })
        .collect();
    let qbox = QuantBox::from_positions(&pts, 0.25, 16).unwrap();
    let mut enc = FrameEncoder::new(n, qbox, 0).unwrap();
    let (mut key, mut delta) = (Vec::new(), Vec::new());
    enc.encode(&pts, Some(&pts), &mut key).unwrap();
    let moved: Vec<Vec3> = pts.iter().map(|p| *p * 1.01).collect();
    enc.encode(&moved, Some(&moved), &mut delta).unwrap();
    (n, key, delta)
}

#[test]
fn frames_truncated_at_every_length_are_refused_by_name() {
    let (n, key, delta) = sample_frames();
    for frame in [&key, &delta] {
        let mut base = FrameDecoder::new(n);
        base.decode(&key).unwrap();
        for len in 0..frame.len() {
            let cut = &frame[..len];
            let expected = if len < HEADER_LEN {
                CodecError::Truncated { len }
            } else {
                CodecError::PayloadLength {
                    declared: (frame.len() - HEADER_LEN) as u32,
                    actual: len - HEADER_LEN,
                }
            };
            assert_eq!(parse_frame(cut).err(), Some(expected.clone()), "len {len}");
            let mut dec = base.clone();
            assert_eq!(dec.decode(cut), Err(expected), "len {len}");
            assert_eq!(dec.lanes(), base.lanes());
        }
        let mut long = frame.clone();
        long.push(0);
        assert!(matches!(
            parse_frame(&long),
            Err(CodecError::PayloadLength { .. })
        ));
    }
}

#[test]
fn each_header_field_names_its_error() {
    let (n, key, _) = sample_frames();
    let with = |at: usize, bytes: &[u8]| {
        let mut f = key.clone();
        f[at..at + bytes.len()].copy_from_slice(bytes);
        f
    };
    let mut dec = FrameDecoder::new(n);
    let mut check = |frame: Vec<u8>, expected: CodecError| {
        assert_eq!(dec.decode(&frame), Err(expected));
    };
    check(with(0, b"CRSG"), CodecError::BadMagic { found: *b"CRSG" });
    check(with(4, &[2]), CodecError::UnsupportedVersion(2));
    check(with(5, &[2]), CodecError::UnknownKind(2));
    check(with(6, &[3]), CodecError::UnknownFlags(3));
    check(with(7, &[12]), CodecError::VertexSize(12));
    check(with(8, &[17]), CodecError::Bits(17));
    check(with(8, &[0]), CodecError::Bits(0));
    check(with(10, &[1]), CodecError::Reserved([0, 1, 0]));
    check(
        with(24, &f32::NAN.to_le_bytes()),
        CodecError::InvalidBox("min is not finite"),
    );
    check(
        with(40, &0f32.to_le_bytes()),
        CodecError::InvalidBox("step must be finite and positive"),
    );
    check(
        with(20, &9u32.to_le_bytes()),
        CodecError::KeyframeBase { seq: 0, base: 9 },
    );
    check(
        with(12, &301u32.to_le_bytes()),
        CodecError::VertexCount {
            expected: 300,
            found: 301,
        },
    );
    check(with(HEADER_LEN, &[0xA0]), CodecError::PayloadVersion(0xA0));
    // A payload cut short but with a matching declared length: meshopt says truncated/corrupt.
    let mut short = key[..key.len() - 40].to_vec();
    let len = (short.len() - HEADER_LEN) as u32;
    short[48..52].copy_from_slice(&len.to_le_bytes());
    check(short, CodecError::PayloadCorrupt(-2));
    let mut empty = key[..HEADER_LEN].to_vec();
    empty[48..52].copy_from_slice(&0u32.to_le_bytes());
    check(empty, CodecError::PayloadEmpty);
    // Messages name the problem.
    let msg = CodecError::PayloadLength {
        declared: 10,
        actual: 3,
    }
    .to_string();
    assert!(msg.contains("payload length") && msg.contains("10") && msg.contains('3'));
}

#[test]
fn corrupted_frames_never_panic() {
    let (n, key, delta) = sample_frames();
    let mut base = FrameDecoder::new(n);
    base.decode(&key).unwrap();
    let mut rng = StdRng::seed_from_u64(7);
    let (mut ok, mut err) = (0, 0);
    for frame in [&key, &delta] {
        // Every byte flipped, then random multi-byte damage.
        let mut cases: Vec<Vec<u8>> = (0..frame.len())
            .map(|i| {
                let mut f = frame.clone();
                f[i] ^= 0xFF;
                f
            })
            .collect();
        for _ in 0..2000 {
            let mut f = frame.clone();
            for _ in 0..rng.random_range(1..8) {
                let i = rng.random_range(HEADER_LEN..f.len());
                f[i] = rng.random();
            }
            cases.push(f);
        }
        for f in cases {
            let mut dec = base.clone();
            match dec.decode(&f) {
                Ok(_) => ok += 1,
                Err(_) => {
                    err += 1;
                    assert_eq!(dec.lanes(), base.lanes());
                }
            }
        }
    }
    println!("corrupted frames: {ok} decoded (garbage in, garbage out), {err} refused");
    assert!(err > 0);
}

// ---------------------------------------------------------------------------------------------
// Index buffers

/// A triangle rotated to start at its smallest index (the winding is kept).
fn canonical(t: [u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap();
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

#[test]
fn index_codec_round_trip_is_exact_up_to_corner_rotation() {
    let mesh = match horse() {
        Some((rest, _)) => rest,
        None => Mesh {
            positions: vec![Vec3::ZERO; 6],
            triangles: vec![[0, 1, 2], [2, 1, 3], [3, 4, 5], [5, 0, 3]],
        },
    };
    let n = mesh.vertex_count();
    let mut bytes = Vec::new();
    encode_indices(&mesh.triangles, n, &mut bytes).unwrap();
    println!(
        "index codec: {} triangles in {} bytes ({:.2} bytes/triangle)",
        mesh.triangles.len(),
        bytes.len(),
        bytes.len() as f64 / mesh.triangles.len() as f64
    );
    let mut back = Vec::new();
    decode_indices(&bytes, mesh.triangles.len(), n, &mut back).unwrap();
    // Triangle order and winding are kept; meshopt may start a triangle at another corner.
    assert_eq!(back.len(), mesh.triangles.len());
    let rotated = back
        .iter()
        .zip(&mesh.triangles)
        .filter(|(b, t)| b != t)
        .inspect(|(b, t)| assert_eq!(canonical(**b), canonical(**t)))
        .count();
    println!("  {rotated} triangles came back rotated (same corners, same winding)");
    // Out of range on either side, truncated, wrong header.
    assert_eq!(
        encode_indices(&[[0, 1, 2], [2, 9, 1]], 9, &mut bytes),
        Err(CodecError::IndexOutOfRange {
            triangle: 1,
            index: 9,
            vertex_count: 9
        })
    );
    encode_indices(&mesh.triangles, n, &mut bytes).unwrap();
    assert!(matches!(
        decode_indices(&bytes, mesh.triangles.len(), 3, &mut back),
        Err(CodecError::IndexOutOfRange { .. })
    ));
    let t = mesh.triangles.len();
    assert_eq!(
        decode_indices(&bytes[..t], t, n, &mut back),
        Err(CodecError::IndexTruncated {
            len: t,
            triangles: t,
            needed: t + 17
        })
    );
    // A huge claimed count is refused before anything is allocated.
    assert!(matches!(
        decode_indices(&bytes, usize::MAX / 2, n, &mut back),
        Err(CodecError::IndexTruncated { .. })
    ));
    let mut bad = bytes.clone();
    bad[0] = 0xE0 | 0x0F;
    assert_eq!(
        decode_indices(&bad, t, n, &mut back),
        Err(CodecError::IndexVersion(0xEF))
    );
    for len in 0..bytes.len() {
        assert!(decode_indices(&bytes[..len], t, n, &mut back).is_err());
    }
}

// ---------------------------------------------------------------------------------------------
// Test vectors

/// A float as JSON: a string holding the shortest decimal that reads back as the same f32, both
/// parsed as f32 and parsed as an f64 then rounded to f32 (what JS's `Math.fround(Number(s))`
/// does; checked here), or "NaN", "Infinity", "-Infinity". Strings, because JSON numbers go
/// through parsers that need not round correctly.
fn jf(x: f32) -> Value {
    let s = if x.is_nan() {
        "NaN".to_string()
    } else if x.is_infinite() {
        (if x > 0.0 { "Infinity" } else { "-Infinity" }).to_string()
    } else {
        let s = format!("{x:?}");
        assert_eq!(s.parse::<f32>().unwrap().to_bits(), x.to_bits(), "{s}");
        assert_eq!(
            (s.parse::<f64>().unwrap() as f32).to_bits(),
            x.to_bits(),
            "{s}"
        );
        s
    };
    Value::String(s)
}

fn jv3(v: &[Vec3]) -> Value {
    Value::Array(
        v.iter()
            .map(|p| Value::Array(p.to_array().map(jf).to_vec()))
            .collect(),
    )
}

fn pf(v: &Value) -> f32 {
    match v {
        Value::String(s) if s == "NaN" => f32::NAN,
        Value::String(s) if s == "Infinity" => f32::INFINITY,
        Value::String(s) if s == "-Infinity" => f32::NEG_INFINITY,
        Value::String(s) => s.parse().unwrap_or_else(|_| panic!("float {s:?}")),
        v => panic!("expected a float string, got {v}"),
    }
}

fn pv3(v: &Value) -> Vec<Vec3> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let a = p.as_array().unwrap();
            Vec3::new(pf(&a[0]), pf(&a[1]), pf(&a[2]))
        })
        .collect()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        .collect()
}

/// One frame of a vector stream: inputs and what to do before encoding it.
struct VFrame {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    force_keyframe: bool,
}

/// The vector streams' inputs (edit here, then regenerate).
fn vector_inputs() -> Vec<(&'static str, &'static str, QuantBox, u32, Vec<VFrame>)> {
    let tetra = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
    ];
    let tetra_box = QuantBox::from_positions(&tetra, 0.25, 16).unwrap();
    let moved = |by: Vec3| -> Vec<Vec3> { tetra.iter().map(|p| *p + by * p.length()).collect() };
    let outward = |pts: &[Vec3]| -> Vec<Vec3> {
        pts.iter()
            .map(|p| (*p - Vec3::splat(0.25)).normalize())
            .collect()
    };
    let plain = |positions: Vec<Vec3>| VFrame {
        positions,
        normals: None,
        force_keyframe: false,
    };
    let with_normals = |positions: Vec<Vec3>| VFrame {
        normals: Some(outward(&positions)),
        positions,
        force_keyframe: false,
    };
    let grid = |t: f32| -> Vec<Vec3> {
        (0..25)
            .map(|i| {
                let (x, y) = ((i % 5) as f32 * 0.25, (i / 5) as f32 * 0.25);
                Vec3::new(x, y, 0.1 * (4.0 * x + t).sin() * (3.0 * y).cos())
            })
            .collect()
    };
    let grid_box = QuantBox::from_bounds(
        Vec3::new(0.0, 0.0, -0.1),
        Vec3::new(1.0, 1.0, 0.1),
        0.25,
        12,
    )
    .unwrap();
    let wild = vec![
        Vec3::new(2.5, 0.5, 0.5),
        Vec3::new(f32::NEG_INFINITY, 0.5, f32::INFINITY),
        Vec3::new(0.5, f32::NAN, 0.5),
        Vec3::new(-0.75, 1.25, 0.0),
    ];
    let unit_box = QuantBox::from_bounds(Vec3::ZERO, Vec3::ONE, 0.0, 16).unwrap();
    vec![
        (
            "tetra",
            "4 vertices, 16 bits, no normals: a keyframe then two deltas",
            tetra_box,
            0,
            vec![
                plain(tetra.clone()),
                plain(moved(Vec3::new(0.01, 0.0, -0.02))),
                plain(moved(Vec3::new(0.03, 0.01, -0.05))),
            ],
        ),
        (
            "tetra-normals",
            "4 vertices, 16 bits, octahedral normals in lane w: a keyframe then a delta",
            tetra_box,
            0,
            vec![
                with_normals(tetra.clone()),
                with_normals(moved(Vec3::new(-0.02, 0.04, 0.0))),
            ],
        ),
        (
            "grid-12bit",
            "5x5 grid, 12 bits, keyframe interval 2: key, delta, key, then a forced key",
            grid_box,
            2,
            vec![
                plain(grid(0.0)),
                plain(grid(0.3)),
                plain(grid(0.6)),
                VFrame {
                    force_keyframe: true,
                    ..plain(grid(0.9))
                },
            ],
        ),
        (
            "clamp-nan",
            "unit box without margin: values outside clamp to the faces, NaN to level 32768",
            unit_box,
            0,
            vec![
                plain(wild.clone()),
                plain(wild.iter().map(|p| *p * 0.5).collect()),
            ],
        ),
    ]
}

fn build_vectors() -> Value {
    let mut streams = Vec::new();
    for (name, about, qbox, interval, frames) in vector_inputs() {
        let n = frames[0].positions.len();
        let mut enc = FrameEncoder::new(n, qbox, interval).unwrap();
        let mut dec = FrameDecoder::new(n);
        let mut out = Vec::new();
        let mut jframes = Vec::new();
        for f in &frames {
            if f.force_keyframe {
                enc.force_keyframe();
            }
            let h = enc
                .encode(&f.positions, f.normals.as_deref(), &mut out)
                .unwrap();
            let (_, payload) = parse_frame(&out).unwrap();
            let payload_lanes = meshopt::decode_vertex_buffer::<[u16; 4]>(payload, n).unwrap();
            dec.decode(&out).unwrap();
            let (mut p, mut nn) = (Vec::new(), Vec::new());
            dec.positions(&mut p);
            let has_normals = dec.normals(&mut nn);
            jframes.push(json!({
                "positions": jv3(&f.positions),
                "normals": f.normals.as_deref().map(jv3),
                "force_keyframe": f.force_keyframe,
                "kind": if h.kind == FrameKind::Key { "key" } else { "delta" },
                "seq": h.seq,
                "base": h.base_seq,
                "frame_hex": hex(&out),
                "payload_lanes": payload_lanes,
                "lanes": dec.lanes(),
                "decoded_positions": jv3(&p),
                "decoded_normals": has_normals.then(|| jv3(&nn)),
            }));
        }
        streams.push(json!({
            "name": name,
            "about": about,
            "vertex_count": n,
            "box": {
                "min": jv3(&[qbox.min()])[0],
                "step": jv3(&[qbox.step()])[0],
                "bits": qbox.bits(),
            },
            "keyframe_interval": interval,
            "frames": jframes,
        }));
    }
    let mut indices = Vec::new();
    let tetra_tris: Vec<[u32; 3]> = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let grid_tris: Vec<[u32; 3]> = (0..16)
        .flat_map(|c| {
            let (x, y) = (c % 4, c / 4);
            let v = y * 5 + x;
            [[v, v + 1, v + 6], [v, v + 6, v + 5]]
        })
        .collect();
    for (name, n, tris) in [("tetra", 4usize, tetra_tris), ("grid", 25, grid_tris)] {
        let mut bytes = Vec::new();
        encode_indices(&tris, n, &mut bytes).unwrap();
        let mut decoded = Vec::new();
        decode_indices(&bytes, tris.len(), n, &mut decoded).unwrap();
        indices.push(json!({
            "name": name,
            "vertex_count": n,
            "triangle_count": tris.len(),
            "triangles": tris,
            "encoded_hex": hex(&bytes),
            "decoded_triangles": decoded,
        }));
    }
    // Malformed frames, derived from the first tetra keyframe, and the error each must give.
    let key = unhex(streams[0]["frames"][0]["frame_hex"].as_str().unwrap());
    let delta = unhex(streams[0]["frames"][1]["frame_hex"].as_str().unwrap());
    let patched = |at: usize, b: &[u8]| {
        let mut f = key.clone();
        f[at..at + b.len()].copy_from_slice(b);
        f
    };
    let mut malformed = Vec::new();
    for (about, frame, error) in [
        ("header cut at 20 bytes", key[..20].to_vec(), "Truncated"),
        ("magic CRSX", patched(0, b"CRSX"), "BadMagic"),
        ("format version 2", patched(4, &[2]), "UnsupportedVersion"),
        ("kind 7", patched(5, &[7]), "UnknownKind"),
        ("vertex size 12", patched(7, &[12]), "VertexSize"),
        (
            "last payload byte missing",
            key[..key.len() - 1].to_vec(),
            "PayloadLength",
        ),
        (
            "vertex count 5 for a 4-vertex decoder",
            patched(12, &5u32.to_le_bytes()),
            "VertexCount",
        ),
        ("a delta to a fresh decoder", delta, "MissingBase"),
    ] {
        malformed.push(json!({
            "about": about,
            "vertex_count": 4,
            "frame_hex": hex(&frame),
            "error": error,
        }));
    }
    json!({
        "about": "crease codec v1 test vectors (core::codec). Frames: 52-byte header + meshopt \
                  vertex codec v1 payload of u16 lanes [x, y, z, w]; a delta's lanes add to the \
                  previous frame's mod 2^16. Floats are strings holding the shortest decimal \
                  of the exact f32 (Math.fround(Number(s)) in JS), or NaN / Infinity / -Infinity. \
                  meshopt's index codec may rotate a triangle's corners (winding kept): \
                  decoded_triangles is what decoding gives. Positions decode bit-exactly as \
                  fround(min + q * step); normals as core::codec::oct_decode. Regenerate with \
                  `cargo test -p crease-core --test all -- --ignored codec::regenerate_test_vectors`.",
        "format_version": 1,
        "header_len": HEADER_LEN,
        "streams": streams,
        "indices": indices,
        "malformed": malformed,
    })
}

/// JSON with objects indented and arrays of numbers kept on one line.
fn pretty(v: &Value, indent: usize, out: &mut String) {
    let pad = "  ".repeat(indent + 1);
    match v {
        Value::Object(m) => {
            out.push_str("{\n");
            for (i, (k, v)) in m.iter().enumerate() {
                let _ = write!(out, "{pad}{}: ", Value::String(k.clone()));
                pretty(v, indent + 1, out);
                out.push_str(if i + 1 < m.len() { ",\n" } else { "\n" });
            }
            let _ = write!(out, "{}}}", "  ".repeat(indent));
        }
        Value::Array(a) if a.iter().any(Value::is_object) => {
            out.push_str("[\n");
            for (i, v) in a.iter().enumerate() {
                out.push_str(&pad);
                pretty(v, indent + 1, out);
                out.push_str(if i + 1 < a.len() { ",\n" } else { "\n" });
            }
            let _ = write!(out, "{}]", "  ".repeat(indent));
        }
        v => out.push_str(&v.to_string()),
    }
}

#[test]
#[ignore = "rewrites tests/vectors/codec-v1.json; run after a deliberate format change"]
fn regenerate_test_vectors() {
    let mut text = String::new();
    pretty(&build_vectors(), 0, &mut text);
    text.push('\n');
    std::fs::create_dir_all(Path::new(VECTORS).parent().unwrap()).unwrap();
    std::fs::write(VECTORS, text).unwrap();
    println!("wrote {VECTORS}");
}

#[test]
fn test_vectors_match() {
    let text = std::fs::read_to_string(VECTORS).expect("tests/vectors/codec-v1.json");
    let v: Value = serde_json::from_str(&text).unwrap();
    let u = |v: &Value| v.as_u64().unwrap();
    let lanes = |v: &Value| -> Vec<[u16; 4]> { serde_json::from_value(v.clone()).unwrap() };
    let mut frames_checked = 0;
    for s in v["streams"].as_array().unwrap() {
        let name = s["name"].as_str().unwrap();
        let n = u(&s["vertex_count"]) as usize;
        let b = &s["box"];
        let qbox = QuantBox::from_min_step(
            pv3(&json!([b["min"]]))[0],
            pv3(&json!([b["step"]]))[0],
            u(&b["bits"]) as u8,
        )
        .unwrap();
        let mut enc = FrameEncoder::new(n, qbox, u(&s["keyframe_interval"]) as u32).unwrap();
        let mut dec = FrameDecoder::new(n);
        let mut out = Vec::new();
        for (i, f) in s["frames"].as_array().unwrap().iter().enumerate() {
            let what = format!("{name} frame {i}");
            let positions = pv3(&f["positions"]);
            let normals = (!f["normals"].is_null()).then(|| pv3(&f["normals"]));
            if f["force_keyframe"].as_bool().unwrap() {
                enc.force_keyframe();
            }
            // Re-encode the inputs: the same bytes.
            let h: FrameHeader = enc
                .encode(&positions, normals.as_deref(), &mut out)
                .unwrap();
            let bytes = unhex(f["frame_hex"].as_str().unwrap());
            assert_eq!(hex(&out), hex(&bytes), "{what}: encoded bytes differ");
            assert_eq!(
                (h.seq, h.base_seq),
                (u(&f["seq"]) as u32, u(&f["base"]) as u32),
                "{what}"
            );
            // Decode the file's bytes: the file's values, bit for bit.
            let dh = dec.decode(&bytes).unwrap();
            let kind = if dh.kind == FrameKind::Key {
                "key"
            } else {
                "delta"
            };
            assert_eq!(kind, f["kind"].as_str().unwrap(), "{what}");
            let (_, payload) = parse_frame(&bytes).unwrap();
            let raw = meshopt::decode_vertex_buffer::<[u16; 4]>(payload, n).unwrap();
            assert_eq!(raw, lanes(&f["payload_lanes"]), "{what}: payload lanes");
            assert_eq!(dec.lanes(), &lanes(&f["lanes"])[..], "{what}: lanes");
            let (mut p, mut nn) = (Vec::new(), Vec::new());
            dec.positions(&mut p);
            let expect_p = pv3(&f["decoded_positions"]);
            for (a, e) in p.iter().zip(&expect_p) {
                assert_eq!(
                    a.to_array().map(f32::to_bits),
                    e.to_array().map(f32::to_bits),
                    "{what}"
                );
            }
            assert_eq!(p.len(), expect_p.len());
            let has = dec.normals(&mut nn);
            assert_eq!(has, !f["decoded_normals"].is_null(), "{what}");
            if has {
                let expect_n = pv3(&f["decoded_normals"]);
                assert_eq!(nn, expect_n, "{what}: normals");
            }
            frames_checked += 1;
        }
    }
    for ix in v["indices"].as_array().unwrap() {
        let n = u(&ix["vertex_count"]) as usize;
        let tris: Vec<[u32; 3]> = serde_json::from_value(ix["triangles"].clone()).unwrap();
        let bytes = unhex(ix["encoded_hex"].as_str().unwrap());
        let mut out = Vec::new();
        encode_indices(&tris, n, &mut out).unwrap();
        assert_eq!(out, bytes, "index vector {}", ix["name"]);
        let mut back = Vec::new();
        decode_indices(&bytes, u(&ix["triangle_count"]) as usize, n, &mut back).unwrap();
        let expected: Vec<[u32; 3]> =
            serde_json::from_value(ix["decoded_triangles"].clone()).unwrap();
        assert_eq!(back, expected, "index vector {}", ix["name"]);
        let canon = |t: &[[u32; 3]]| t.iter().map(|&t| canonical(t)).collect::<Vec<_>>();
        assert_eq!(canon(&back), canon(&tris), "index vector {}", ix["name"]);
    }
    for m in v["malformed"].as_array().unwrap() {
        let mut dec = FrameDecoder::new(u(&m["vertex_count"]) as usize);
        let err = dec
            .decode(&unhex(m["frame_hex"].as_str().unwrap()))
            .unwrap_err();
        let name = format!("{err:?}");
        assert!(
            name.starts_with(m["error"].as_str().unwrap()),
            "{}: got {name}",
            m["about"]
        );
    }
    assert!(frames_checked >= 10);
    // The file is what the generator writes today (inputs and all).
    let mut regenerated = String::new();
    pretty(&build_vectors(), 0, &mut regenerated);
    regenerated.push('\n');
    assert!(
        regenerated == text,
        "tests/vectors/codec-v1.json differs from what regenerate_test_vectors writes"
    );
}
