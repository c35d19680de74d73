//! Per-frame skinning cost on the horse (8,431 vertices, 150 proxy bones as in FKY08 Table 1),
//! k = 4 and k = 8, next to a plain memory copy of the same number of bytes in the same run.
//!
//! The rig is synthetic: 150 random rigid transforms, each vertex bound to k distinct random
//! bones with random normalised weights (seeded), so every slot is used (the worst case; the
//! fitted horse uses all 8 on 80% of its vertices). Only the vertex positions come from the data
//! set; without it, 8,431 random points are used (the bench says which). Set `CREASE_LBS_MODEL`
//! to a trained `.crease` model to add a case with its rig (rest mesh, weights, and the first
//! example's bone transforms).
//!
//! Functions per case: `lbs` ([`skin_lbs`]), `lbs_packed` ([`skin_lbs_packed_with`] on a
//! [`PackedSkin`] built once, portable kernel), `lbs_packed_fma` (the AVX2 + FMA kernel, where
//! the CPU has it: what `skin_lbs_packed` picks), `dqs`, and `memcpy` / `memcpy_packed`: a copy of as many bytes as
//! the reference / packed layout reads and writes per frame.
//!
//! Bytes per frame (what `Throughput::Bytes` and the copies use): rest positions read (12 B per
//! vertex) + output written (12 B per vertex) + the influences read: bone indices and weights,
//! 8 B per slot for `SkinWeights` (k slots per vertex), 5 B per slot plus 1 B per vertex of block
//! offsets for a `PackedSkin` with `u8` indices. The 150-bone palette (~14 KB, ~16 KB of rows)
//! stays in L1 and is not counted. A copy moves that many bytes (reading them once and writing
//! them once).
//!
//! `cargo bench -p crease-core --bench lbs -- --quick`; single-threaded: `RAYON_NUM_THREADS=1`,
//! or `--no-default-features` for the build without rayon. After criterion's groups it prints
//! one summary line per case and function with medians of its own timing loop.

mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::glam::{Quat, Vec3};
use crease_core::model::TrainedModel;
use crease_core::runtime::skin::{
    BonePalette, PackedKernel, PackedSkin, RigidTransform, SkinWeights, skin_dqs, skin_lbs,
    skin_lbs_packed_with,
};
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

/// Bytes a frame reads and writes with `SkinWeights` (see the module docs).
fn bytes_per_frame(n: usize, k: usize) -> usize {
    n * (12 + 8 * k + 12)
}

/// Bytes a frame reads and writes with a `PackedSkin` (`u8` indices; see the module docs).
fn packed_bytes_per_frame(n: usize, packed: &PackedSkin) -> usize {
    n * (12 + 1 + 12) + 5 * packed.slot_count()
}

/// Which skinning a frame runs.
#[derive(Clone, Copy)]
enum Method {
    Lbs,
    LbsPacked(PackedKernel),
    Dqs,
}

/// One frame: palette from the bones, then skinning (both are per-frame work).
fn frame(
    method: Method,
    rest: &[Vec3],
    skin: &SkinWeights,
    packed: &PackedSkin,
    bones: &[RigidTransform],
    palette: &mut BonePalette,
    out: &mut [Vec3],
) {
    palette.update(black_box(bones));
    let r = match method {
        Method::Lbs => skin_lbs(black_box(rest), skin, palette, out),
        Method::LbsPacked(kernel) => {
            skin_lbs_packed_with(kernel, black_box(rest), packed, palette, out)
        }
        Method::Dqs => skin_dqs(black_box(rest), skin, palette, out),
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

/// The trained model's rig named by `CREASE_LBS_MODEL`, if set: rest positions, weights and
/// the first example's transforms.
fn model_case() -> Option<(Vec<Vec3>, SkinWeights, Vec<RigidTransform>, String)> {
    let path = std::env::var("CREASE_LBS_MODEL").ok()?;
    let model =
        TrainedModel::load(&path).unwrap_or_else(|e| panic!("CREASE_LBS_MODEL={path}: {e}"));
    let rig = model.rig;
    let bones = rig.examples.first()?.transforms.clone();
    let used: usize = rig
        .skin
        .iter()
        .map(|(_, w)| w.iter().filter(|&&x| x != 0.0).count())
        .sum();
    let label = format!(
        "model {path}: {} vertices, k = {}, {} bones, {:.2} non-zero influences per vertex",
        rig.skin.vertex_count(),
        rig.skin.k(),
        rig.bone_count,
        used as f64 / rig.skin.vertex_count() as f64
    );
    Some((rig.rest.positions, rig.skin, bones, label))
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let (rest, source) = rest_positions();
    let n = rest.len();
    println!(
        "lbs bench: {n} vertices from {source}, {BONES} bones, {}",
        threads()
    );
    let mut cases: Vec<(String, Vec<Vec3>, SkinWeights, Vec<RigidTransform>)> = [4, 8]
        .into_iter()
        .map(|k| {
            let (skin, bones) = synthetic(n, k);
            (format!("k{k}"), rest.clone(), skin, bones)
        })
        .collect();
    if let Some((rest, skin, bones, label)) = model_case() {
        println!("{label}");
        cases.push(("model".into(), rest, skin, bones));
    }
    let mut summary = Vec::new();
    for (name, rest, skin, bones) in &cases {
        let (n, k) = (rest.len(), skin.k());
        let packed = PackedSkin::new(skin).expect("bone indices fit");
        let mut palette = BonePalette::new();
        let mut out = vec![Vec3::ZERO; n];
        let bytes = bytes_per_frame(n, k);
        let packed_bytes = packed_bytes_per_frame(n, &packed);
        let src = vec![1u8; bytes];
        let mut dst = vec![0u8; bytes];
        let mut methods = vec![
            ("lbs", Method::Lbs, bytes),
            (
                "lbs_packed",
                Method::LbsPacked(PackedKernel::Portable),
                packed_bytes,
            ),
        ];
        if PackedKernel::Fma.available() {
            methods.push((
                "lbs_packed_fma",
                Method::LbsPacked(PackedKernel::Fma),
                packed_bytes,
            ));
        } else {
            println!("lbs_packed_fma: not run, this CPU lacks AVX2 + FMA");
        }
        methods.push(("dqs", Method::Dqs, bytes));

        let mut g = c.benchmark_group(format!("skin_{name}"));
        for &(label, method, b) in &methods {
            g.throughput(Throughput::Bytes(b as u64));
            g.bench_function(label, |bch| {
                bch.iter(|| frame(method, rest, skin, &packed, bones, &mut palette, &mut out))
            });
        }
        for (label, b) in [("memcpy", bytes), ("memcpy_packed", packed_bytes)] {
            g.throughput(Throughput::Bytes(b as u64));
            g.bench_function(label, |bch| {
                bch.iter(|| dst[..b].copy_from_slice(black_box(&src[..b])));
                black_box(&dst);
            });
        }
        g.finish();

        let us = |d: Duration| d.as_secs_f64() * 1e6;
        for (label, method, b) in methods {
            let t = timings(FRAMES, || {
                frame(method, rest, skin, &packed, bones, &mut palette, &mut out)
            });
            let copy = timings(FRAMES, || {
                dst[..b].copy_from_slice(black_box(&src[..b]));
                black_box(&dst);
            });
            summary.push(format!(
                "{label} {name} (k={k}): {:.1} µs/frame, memcpy of {b} bytes: {:.1} µs, ratio \
                 {:.1} (min: {:.1} µs, {:.1} µs, ratio {:.1})",
                us(t.0),
                us(copy.0),
                us(t.0) / us(copy.0),
                us(t.1),
                us(copy.1),
                us(t.1) / us(copy.1),
            ));
        }
    }
    println!(
        "\nsummary ({BONES}-bone synthetic rigs on {n} vertices, {}; medians (and minima) of \
         {FRAMES} frames, palette update included)",
        threads()
    );
    for s in summary {
        println!("{s}");
    }
    c.final_summary();
}
