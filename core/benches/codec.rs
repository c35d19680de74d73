//! `core::codec` on the horse gallop (8,431 vertices, 48 frames): encode and decode time per
//! frame, and bytes per vertex per frame for keyframes only vs keyframes + deltas, next to a
//! plain copy of the raw `f32` positions (12 bytes per vertex).
//!
//! Sizes count whole frames (52-byte header included) over one pass of the 48-frame loop, the
//! first frame a keyframe; the box is the rest pose's, padded by 25% of its largest side. Rows:
//! 16 bits key-only / every-30 keys (the default) / one key then deltas, with normals, in
//! meshopt's spatial vertex order (a one-off permutation a server could apply to the model), and
//! at 14, 13 and 12 bits.
//!
//! Times: `encode_*` is [`FrameEncoder::encode`] (quantise + meshopt encode + header) cycling
//! through the gallop; `decode_*` is [`FrameDecoder::decode`] plus dequantising into `Vec3`s;
//! `memcpy` copies the frame's raw `f32` positions. Without the data set a synthetic waving grid
//! of the same size is used (the bench says which).
//!
//! `cargo bench -p crease-core --bench codec -- --quick`. After criterion's groups it prints a
//! summary with medians (and minima) of its own timing loop.

mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::codec::{FrameDecoder, FrameEncoder, FrameKind, QuantBox};
use crease_core::glam::Vec3;
use crease_core::mesh::{ExampleSet, Mesh, compute_vertex_normals};
use criterion::{Criterion, Throughput};

/// Frames timed per summary figure.
const FRAMES: usize = 480;
/// Box margin: a quarter of the rest pose's largest side on every side.
const MARGIN: f32 = 0.25;

/// The gallop frames and the rest pose, or a synthetic stand-in with the reason.
fn frames() -> (Mesh, Vec<Mesh>, String) {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/horse");
    let rest = Mesh::read(format!("{root}/reference.obj"));
    let set = ExampleSet::load(format!("{root}/gallop"));
    if let (Ok(rest), Ok(set)) = (rest, set) {
        let frames = set.examples.into_iter().map(|e| e.mesh).collect();
        return (rest, frames, "horse gallop (48 frames)".into());
    }
    // 92 x 92 grid (8,464 vertices), a travelling wave.
    let side = 92;
    let grid = |t: f32| -> Vec<Vec3> {
        (0..side * side)
            .map(|i| {
                let (x, y) = (
                    (i % side) as f32 / side as f32,
                    (i / side) as f32 / side as f32,
                );
                Vec3::new(x, y, 0.1 * (6.0 * x + t).sin() * (4.0 * y + 0.5 * t).cos())
            })
            .collect()
    };
    let triangles = (0..(side - 1) * (side - 1))
        .flat_map(|c| {
            let v = ((c / (side - 1)) * side + c % (side - 1)) as u32;
            let s = side as u32;
            [[v, v + 1, v + s + 1], [v, v + s + 1, v + s]]
        })
        .collect::<Vec<_>>();
    let mesh = |t: f32| Mesh {
        positions: grid(t),
        triangles: triangles.clone(),
    };
    let frames = (0..48).map(|f| mesh(f as f32 * 0.13)).collect();
    (
        mesh(0.0),
        frames,
        format!("synthetic 92x92 waving grid (horse data not found under {root})"),
    )
}

/// Bytes per vertex per frame over one pass of `frames`, with the keyframe count.
fn bytes_per_vertex(
    frames: &[Vec<Vec3>],
    normals: Option<&[Vec<Vec3>]>,
    qbox: QuantBox,
    interval: u32,
) -> (f64, usize) {
    let n = frames[0].len();
    let mut enc = FrameEncoder::new(n, qbox, interval).expect("vertex count fits");
    let mut out = Vec::new();
    let (mut total, mut keys) = (0, 0);
    for (f, p) in frames.iter().enumerate() {
        let h = enc
            .encode(p, normals.map(|nn| &nn[f][..]), &mut out)
            .expect("sizes match");
        keys += usize::from(h.kind == FrameKind::Key);
        total += out.len();
    }
    (total as f64 / (n * frames.len()) as f64, keys)
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let (rest, meshes, source) = frames();
    let n = rest.vertex_count();
    let positions: Vec<Vec<Vec3>> = meshes.iter().map(|m| m.positions.clone()).collect();
    let normals: Vec<Vec<Vec3>> = meshes
        .iter()
        .map(|m| {
            let mut out = Vec::new();
            compute_vertex_normals(&m.positions, &m.triangles, &mut out);
            out
        })
        .collect();
    let (lo, hi) = rest.bounding_box();
    let qbox = |bits: u8| QuantBox::from_bounds(lo, hi, MARGIN, bits).expect("finite box");
    println!("codec bench: {n} vertices, {source}");

    // Sizes.
    let mut sizes = Vec::new();
    let nf = positions.len();
    let mut row = |label: String, (bpv, keys): (f64, usize)| {
        sizes.push(format!(
            "  {label:<46} {bpv:6.3} B/vertex/frame ({keys} keyframes in {nf} frames; \
             {:4.1}% of raw f32 positions)",
            bpv / 12.0 * 100.0
        ));
        bpv
    };
    let key_only = row(
        "16 bits, keyframes only".into(),
        bytes_per_vertex(&positions, None, qbox(16), 1),
    );
    row(
        "16 bits, keyframe every 30 (default)".into(),
        bytes_per_vertex(&positions, None, qbox(16), 30),
    );
    let delta = row(
        "16 bits, one keyframe then deltas".into(),
        bytes_per_vertex(&positions, None, qbox(16), 0),
    );
    row(
        "16 bits + normals, keyframes only".into(),
        bytes_per_vertex(&positions, Some(&normals), qbox(16), 1),
    );
    row(
        "16 bits + normals, one keyframe then deltas".into(),
        bytes_per_vertex(&positions, Some(&normals), qbox(16), 0),
    );
    // meshopt's spatial order (remap[old] = new), applied to every frame.
    let flat: Vec<f32> = rest.positions.iter().flat_map(|p| p.to_array()).collect();
    let adapter = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&flat), 12, 0)
        .expect("12-byte positions");
    let remap = meshopt::spatial_sort_remap(&adapter);
    let reordered: Vec<Vec<Vec3>> = positions
        .iter()
        .map(|p| {
            let mut out = vec![Vec3::ZERO; n];
            for (i, &q) in p.iter().enumerate() {
                out[remap[i] as usize] = q;
            }
            out
        })
        .collect();
    row(
        "16 bits, spatial vertex order, deltas".into(),
        bytes_per_vertex(&reordered, None, qbox(16), 0),
    );
    for bits in [14u8, 13, 12] {
        row(
            format!("{bits} bits, one keyframe then deltas"),
            bytes_per_vertex(&positions, None, qbox(bits), 0),
        );
    }
    row(
        "12 bits, spatial vertex order, deltas".into(),
        bytes_per_vertex(&reordered, None, qbox(12), 0),
    );

    // Pre-encoded streams for decoding: all keyframes, and one keyframe then deltas (cycling
    // back to the keyframe keeps the stream valid).
    let encode_all = |interval: u32, with_normals: bool| -> Vec<Vec<u8>> {
        let mut enc = FrameEncoder::new(n, qbox(16), interval).expect("vertex count fits");
        positions
            .iter()
            .zip(&normals)
            .map(|(p, nn)| {
                let mut out = Vec::new();
                enc.encode(p, with_normals.then_some(&nn[..]), &mut out)
                    .expect("sizes match");
                out
            })
            .collect()
    };
    let keys = encode_all(1, false);
    let deltas = encode_all(0, false);
    let deltas_normals = encode_all(0, true);

    let raw_bytes = n * 12;
    let raw: Vec<f32> = flat.clone();
    let mut copy = vec![0f32; raw.len()];
    let mut out = Vec::new();
    let mut decoded = Vec::new();

    type Case<'a> = (&'a str, u32, bool);
    let encode_cases: [Case; 3] = [
        ("encode_key", 1, false),
        ("encode_delta", 0, false),
        ("encode_delta_normals", 0, true),
    ];
    let decode_cases: [(&str, &[Vec<u8>]); 3] = [
        ("decode_key", &keys),
        ("decode_delta", &deltas),
        ("decode_delta_normals", &deltas_normals),
    ];

    let mut g = c.benchmark_group("codec");
    g.throughput(Throughput::Elements(n as u64));
    for (label, interval, with_normals) in encode_cases {
        let mut enc = FrameEncoder::new(n, qbox(16), interval).expect("vertex count fits");
        let mut f = 0;
        g.bench_function(label, |b| {
            b.iter(|| {
                let nn = with_normals.then_some(&normals[f][..]);
                enc.encode(black_box(&positions[f]), nn, &mut out)
                    .expect("sizes match");
                f = (f + 1) % nf;
                black_box(&out);
            })
        });
    }
    for (label, stream) in decode_cases {
        let mut dec = FrameDecoder::new(n);
        let mut f = 0;
        g.bench_function(label, |b| {
            b.iter(|| {
                dec.decode(black_box(&stream[f])).expect("valid stream");
                dec.positions(&mut decoded);
                f = (f + 1) % nf;
                black_box(&decoded);
            })
        });
    }
    g.throughput(Throughput::Bytes(raw_bytes as u64));
    g.bench_function("memcpy_f32_positions", |b| {
        b.iter(|| copy.copy_from_slice(black_box(&raw)));
        black_box(&copy);
    });
    g.finish();

    // Summary with our own timing loop.
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    let memcpy = timings(FRAMES * 10, || {
        copy.copy_from_slice(black_box(&raw));
        black_box(&copy);
    });
    let mut times = Vec::new();
    for (label, interval, with_normals) in encode_cases {
        let mut enc = FrameEncoder::new(n, qbox(16), interval).expect("vertex count fits");
        let mut f = 0;
        let t = timings(FRAMES, || {
            let nn = with_normals.then_some(&normals[f][..]);
            enc.encode(black_box(&positions[f]), nn, &mut out)
                .expect("sizes match");
            f = (f + 1) % nf;
            black_box(&out);
        });
        times.push((label, t));
    }
    for (label, stream) in decode_cases {
        let mut dec = FrameDecoder::new(n);
        let mut f = 0;
        let t = timings(FRAMES, || {
            dec.decode(black_box(&stream[f])).expect("valid stream");
            dec.positions(&mut decoded);
            f = (f + 1) % nf;
            black_box(&decoded);
        });
        times.push((label, t));
    }

    println!("\nsummary: {n} vertices, {source}, box margin {MARGIN}");
    println!("bytes per vertex per frame (whole frames; raw f32 positions are 12, 16-bit xyz 6):");
    for s in &sizes {
        println!("{s}");
    }
    println!(
        "  deltas vs keyframes only at 16 bits: {:.3} vs {:.3} B/vertex/frame ({:.0}% smaller)",
        delta,
        key_only,
        (1.0 - delta / key_only) * 100.0
    );
    println!(
        "times per frame, medians of {FRAMES} (minima); memcpy of {raw_bytes} bytes of f32 \
         positions: {:.1} µs ({:.1})",
        us(memcpy.0),
        us(memcpy.1)
    );
    for (label, t) in times {
        println!(
            "  {label:<22} {:7.1} µs ({:6.1}), {:5.1}x memcpy",
            us(t.0),
            us(t.1),
            us(t.0) / us(memcpy.0)
        );
    }
    c.final_summary();
}
