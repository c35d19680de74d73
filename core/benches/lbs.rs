//! Per-frame skinning cost on the horse (8,431 vertices, 150 proxy bones as in FKY08 Table 1),
//! k = 4 and k = 8, next to a plain memory copy of the same number of bytes in the same run.
//!
//! The rig is synthetic until the fitter exists: 150 random rigid transforms, each vertex bound
//! to k distinct random bones with random normalised weights (seeded). Only the vertex positions
//! come from the data set; without it, 8,431 random points are used (the bench says which).
//!
//! Bytes per frame (what `Throughput::Bytes` and the copy use): rest positions read (12 B per
//! vertex) + bone indices and weights read (8k B per vertex) + output written (12 B per vertex).
//! The 150-bone palette (~14 KB) stays in L1 and is not counted. The copy moves that many bytes
//! (reading them once and writing them once).
//!
//! `cargo bench -p crease-core --bench lbs -- --quick`; single-threaded: `RAYON_NUM_THREADS=1`,
//! or `--no-default-features` for the build without rayon. After criterion's groups it prints
//! one summary line per k with medians of its own timing loop.

mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::skin::{BonePalette, RigidTransform, SkinWeights, skin_dqs, skin_lbs};
use criterion::{Criterion, Throughput};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Proxy bones on the horse in FKY08 Table 1.
const BONES: usize = 150;
/// Frames timed per summary figure.
const FRAMES: usize = 500;
/// Vertices of the horse, used for the random fallback.
const HORSE_VERTICES: usize = 8431;

/// The horse's rest positions (`v` lines of the OBJ), or random points when the data is absent.
fn rest_positions() -> (Vec<Vec3>, String) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/horse/reference.obj"
    );
    if let Ok(text) = std::fs::read_to_string(path) {
        let pos: Vec<Vec3> = text
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .filter_map(|l| {
                let mut f = l.split_whitespace().map(|x| x.parse::<f32>());
                match (f.next(), f.next(), f.next()) {
                    (Some(Ok(x)), Some(Ok(y)), Some(Ok(z))) => Some(Vec3::new(x, y, z)),
                    _ => None,
                }
            })
            .collect();
        if !pos.is_empty() {
            return (pos, "horse/reference.obj".into());
        }
    }
    let mut rng = StdRng::seed_from_u64(1);
    let pos = (0..HORSE_VERTICES)
        .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    (
        pos,
        format!("{HORSE_VERTICES} random points (horse data not found at {path})"),
    )
}

/// The synthetic rig: `BONES` random rigid transforms and k distinct random bones per vertex.
fn synthetic(n: usize, k: usize) -> (SkinWeights, Vec<RigidTransform>) {
    let mut rng = StdRng::seed_from_u64(k as u64);
    let bones = (0..BONES)
        .map(|_| {
            let axis = Vec3::new(rng.random(), rng.random(), rng.random::<f32>() + 0.1);
            RigidTransform::new(
                Quat::from_axis_angle(axis.normalize(), rng.random_range(-3.0..3.0)),
                Vec3::new(rng.random(), rng.random(), rng.random()),
            )
        })
        .collect();
    let mut indices = Vec::with_capacity(n * k);
    let mut weights = Vec::with_capacity(n * k);
    for _ in 0..n {
        let start = indices.len();
        while indices.len() < start + k {
            let b = rng.random_range(0..BONES as u32);
            if !indices[start..].contains(&b) {
                indices.push(b);
            }
        }
        let w: Vec<f32> = (0..k).map(|_| rng.random::<f32>() + 0.01).collect();
        let s: f32 = w.iter().sum();
        weights.extend(w.iter().map(|x| x / s));
    }
    let skin = SkinWeights::new(k, indices, weights).expect("normalised random weights");
    (skin, bones)
}

/// Bytes a frame reads and writes (see the module docs).
fn bytes_per_frame(n: usize, k: usize) -> usize {
    n * (12 + 8 * k + 12)
}

/// One frame: palette from the bones, then skinning (both are per-frame work).
fn frame(
    dqs: bool,
    rest: &[Vec3],
    skin: &SkinWeights,
    bones: &[RigidTransform],
    palette: &mut BonePalette,
    out: &mut [Vec3],
) {
    palette.update(black_box(bones));
    let r = if dqs {
        skin_dqs(black_box(rest), skin, palette, out)
    } else {
        skin_lbs(black_box(rest), skin, palette, out)
    };
    r.expect("sizes checked at setup");
    black_box(out);
}

fn threads() -> String {
    #[cfg(feature = "parallel")]
    return format!(
        "parallel feature on, {} rayon threads",
        rayon::current_num_threads()
    );
    #[cfg(not(feature = "parallel"))]
    return "parallel feature off".to_string();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let (rest, source) = rest_positions();
    let n = rest.len();
    println!(
        "lbs bench: {n} vertices from {source}, {BONES} bones, {}",
        threads()
    );
    let mut summary = Vec::new();
    for k in [4, 8] {
        let (skin, bones) = synthetic(n, k);
        let mut palette = BonePalette::new();
        let mut out = vec![Vec3::ZERO; n];
        let bytes = bytes_per_frame(n, k);
        let src = vec![1u8; bytes];
        let mut dst = vec![0u8; bytes];

        let mut g = c.benchmark_group(format!("skin_k{k}"));
        g.throughput(Throughput::Bytes(bytes as u64));
        g.bench_function("lbs", |b| {
            b.iter(|| frame(false, &rest, &skin, &bones, &mut palette, &mut out))
        });
        g.bench_function("dqs", |b| {
            b.iter(|| frame(true, &rest, &skin, &bones, &mut palette, &mut out))
        });
        g.bench_function("memcpy", |b| {
            b.iter(|| dst.copy_from_slice(black_box(&src)));
            black_box(&dst);
        });
        g.finish();

        let lbs = timings(FRAMES, || {
            frame(false, &rest, &skin, &bones, &mut palette, &mut out)
        });
        let dqs = timings(FRAMES, || {
            frame(true, &rest, &skin, &bones, &mut palette, &mut out)
        });
        let copy = timings(FRAMES, || {
            dst.copy_from_slice(black_box(&src));
            black_box(&dst);
        });
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        let line = |name: &str, (med, min): (Duration, Duration)| {
            format!(
                "{name} k={k}: {:.1} µs/frame, memcpy of {bytes} bytes: {:.1} µs, ratio {:.1} \
                 (min: {:.1} µs, {:.1} µs, ratio {:.1})",
                us(med),
                us(copy.0),
                us(med) / us(copy.0),
                us(min),
                us(copy.1),
                us(min) / us(copy.1),
            )
        };
        summary.push(line("lbs", lbs));
        summary.push(line("dqs", dqs));
    }
    println!(
        "\nsummary ({n} vertices, {BONES} bones, {}; medians (and minima) of {FRAMES} frames)",
        threads()
    );
    for s in summary {
        println!("{s}");
    }
    c.final_summary();
}
