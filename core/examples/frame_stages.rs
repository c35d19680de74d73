//! Per-frame stages of a trained model, single thread, each beside its floor measured in the
//! same run (issue 23): the papers' scale is a 49K-vertex base, ~1,300 bones and a 195K-vertex
//! detail layer.
//!
//! ```sh
//! cargo build --release -p crease-core --example frame_stages
//! RAYON_NUM_THREADS=1 target/release/examples/frame_stages MODEL.crease TEST_MANIFEST [V1,V2,..]
//! ```
//!
//! The control frames are the test manifest's poses read at the vertices `V1,V2,..` (of the
//! test meshes: with a model trained by `--base-vertices`, the full-mesh vertices its
//! `--control-points` named), or at the model's own control vertices when none are given.
//! Stages, each timed over `FRAMES` frames (200; the environment's `FRAMES` overrides it, e.g.
//! a few for instruction counts under callgrind; median and minimum):
//!
//! - `rotations`: the regression (`RotationModel::predict`);
//! - `transforms`: rotations, the confidence and the eq. 11 translation solve
//!   (`Predictor::predict_transforms`); `translations` is the difference of the two;
//! - `skin`: packed LBS of the base (`Predictor::skin`);
//! - `detail regress`: `h = D xi + b` (`D` in the frame's blocks of rows); `detail synth`:
//!   `S · base`, normals, `+ h n`; `detail frame`: both as `Predictor::predict_detail` runs
//!   them, the regression fused into the synthesis's last pass;
//! - `encode base` / `encode detail`: the vertex codec (16 bits, a keyframe every 30).
//!
//! Floors: memory-bound stages against `memcpy` of the bytes they read and write at least (the
//! skin: rest positions, the non-zero weights as 6-byte slots, the output; detail regress: `D`,
//! `b` and `h`; detail synth: base, `h` and the output, stencils not counted; encode: the
//! positions); compute-bound ones (rotations, translations) against their multiply-adds at this
//! core's measured fused multiply-add rate (AVX2 + FMA: 8 f32 or 4 f64 lanes, eight independent
//! chains), which no kernel with loads in its loop reaches.
#![allow(clippy::unwrap_used, clippy::expect_used)] // a measuring tool: a failure names its line

#[path = "../benches/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crease_core::codec::{FrameEncoder, QuantBox};
use crease_core::glam::Vec3;
use crease_core::mesh::ExampleSet;
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_core::runtime::detail::DetailSynth;
use crease_core::runtime::displacement::BlockedRows;
use crease_core::runtime::predict::GroupRegression;

use common::timings;

/// Frames per figure: the environment's `FRAMES`, else 200.
fn frames_per_figure() -> usize {
    std::env::var("FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(200)
}

/// A copy of `bytes` bytes, as a floor's timing.
fn memcpy(bytes: usize) -> (Duration, Duration) {
    let src = vec![1u8; bytes];
    let mut dst = vec![0u8; bytes];
    timings(frames_per_figure(), || {
        dst.copy_from_slice(black_box(&src));
        black_box(&dst);
    })
}

/// Fused multiply-adds per second of this core (f32, f64): eight independent chains of 8-wide
/// f32 / 4-wide f64 fused multiply-adds with AVX2 + FMA where the CPU has them (the kernels'
/// instructions), else of lane arrays in portable code.
fn fma_rates() -> (f64, f64) {
    let n = 4_000_000usize;
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return (
            simd.vectorize(Chains {
                simd,
                n,
                f64: false,
            }),
            simd.vectorize(Chains { simd, n, f64: true }),
        );
    }
    fn rate<const L: usize, T: Copy + std::ops::Mul<Output = T> + std::ops::Add<Output = T>>(
        one: T,
        k: T,
        n: usize,
    ) -> f64 {
        let mut acc = [[one; L]; 8];
        let t = Instant::now();
        for _ in 0..n {
            for a in acc.iter_mut() {
                for x in a.iter_mut() {
                    *x = *x * k + k;
                }
            }
            black_box(&acc);
        }
        (n * 8 * L) as f64 / t.elapsed().as_secs_f64()
    }
    (
        rate::<8, f32>(1.0, 0.999_99, n),
        rate::<4, f64>(1.0, 0.999_99, n),
    )
}

/// Eight independent chains of `n` 8-wide f32 (or 4-wide f64) fused multiply-adds; the rate.
/// A struct, not a closure, so that pulp's AVX2 + FMA context inlines its body (as
/// `runtime::simd`'s kernels: a closure's body was compiled without the features, its
/// intrinsics as calls).
#[cfg(target_arch = "x86_64")]
struct Chains {
    simd: pulp::x86::V3,
    n: usize,
    f64: bool,
}

#[cfg(target_arch = "x86_64")]
impl pulp::NullaryFnOnce for Chains {
    type Output = f64;

    #[inline(always)]
    fn call(self) -> f64 {
        let Chains { simd, n, f64 } = self;
        let t = Instant::now();
        let lanes = if f64 {
            let k = simd.avx._mm256_set1_pd(0.999_99);
            let mut acc = [simd.avx._mm256_set1_pd(1.0); 8];
            for _ in 0..n {
                for a in acc.iter_mut() {
                    *a = simd.fma._mm256_fmadd_pd(*a, k, k);
                }
            }
            black_box(&acc);
            4
        } else {
            let k = simd.avx._mm256_set1_ps(0.999_99);
            let mut acc = [simd.avx._mm256_set1_ps(1.0); 8];
            for _ in 0..n {
                for a in acc.iter_mut() {
                    *a = simd.fma._mm256_fmadd_ps(*a, k, k);
                }
            }
            black_box(&acc);
            8
        };
        (n * 8 * lanes) as f64 / t.elapsed().as_secs_f64()
    }
}

/// The 16-bit box around `p`, padded by a quarter of its largest side (the codec bench's).
fn quant_box(p: &[Vec3]) -> QuantBox {
    let lo = p.iter().fold(Vec3::INFINITY, |a, &b| a.min(b));
    let hi = p.iter().fold(Vec3::NEG_INFINITY, |a, &b| a.max(b));
    QuantBox::from_bounds(lo, hi, 0.25, 16).unwrap()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: frame_stages MODEL.crease TEST_MANIFEST [V1,V2,..]";
    let model = Arc::new(TrainedModel::load(args.get(1).expect(usage)).expect("model"));
    let test = ExampleSet::load(args.get(2).expect(usage)).expect("test manifest");
    let vertices: Vec<usize> = match args.get(3) {
        Some(list) => list
            .split(',')
            .map(|v| v.trim().parse().expect("vertex index"))
            .collect(),
        // The model's own control vertices (a model trained on the test meshes' topology).
        None => model.controls.iter().map(|c| c.vertex as usize).collect(),
    };
    assert_eq!(
        vertices.len(),
        model.controls.len(),
        "one vertex per control point"
    );
    let frames: Vec<Vec<Vec3>> = test
        .examples
        .iter()
        .map(|e| vertices.iter().map(|&v| e.mesh.positions[v]).collect())
        .collect();
    let predictor = Predictor::new(model.clone(), None).expect("predictor");
    let mut ctx = predictor.new_context();
    let n = model.rig.rest.vertex_count();
    let bones = model.rig.bone_count;
    let mut k = 0;
    let mut next = || {
        k = (k + 1) % frames.len();
        k
    };
    let mut rows: Vec<(String, (Duration, Duration), String)> = Vec::new();

    // Compute floors: multiply-adds per frame at the measured rate.
    let (f32_rate, f64_rate) = fma_rates();
    let rot_fmas: usize = model
        .rotations
        .groups
        .iter()
        .map(|g| match &g.regression {
            GroupRegression::Global(op) => op.m.len(),
            GroupRegression::PoseLocal(models) => {
                let per = models.first().map_or(0, |m| m.operator.m.len());
                per * model.rotations.blend_poses.min(models.len())
            }
        })
        .sum();
    let solver = predictor.translation_solver();
    let trans_fmas = 9 * solver.rotation_operator_len() + 2 * 3 * solver.factor_len();
    let floor = |fmas: usize, rate: f64| Duration::from_secs_f64(fmas as f64 / rate);

    let mut scratch = Default::default();
    let mut rot = vec![Default::default(); bones];
    let r = timings(frames_per_figure(), || {
        let i = next();
        model.rotations.predict(&frames[i], &mut scratch, &mut rot);
    });
    rows.push((
        "rotations".into(),
        r,
        format!(
            "{rot_fmas} f32 FMAs: {:.1} us at this core's rate",
            floor(rot_fmas, f32_rate).as_secs_f64() * 1e6
        ),
    ));
    let t = timings(frames_per_figure(), || {
        let i = next();
        predictor
            .predict_transforms(&mut ctx, &frames[i], None)
            .unwrap();
    });
    rows.push(("transforms".into(), t, String::new()));
    rows.push((
        "  translations".into(),
        (t.0.saturating_sub(r.0), t.1.saturating_sub(r.1)),
        format!(
            "{trans_fmas} f64 FMAs (K {} entries x 9, factor {} x 2 passes x 3): {:.1} us",
            solver.rotation_operator_len(),
            solver.factor_len(),
            floor(trans_fmas, f64_rate).as_secs_f64() * 1e6
        ),
    ));
    let skin = timings(frames_per_figure(), || predictor.skin(&mut ctx).unwrap());
    let slots: usize = (0..n)
        .map(|v| {
            model
                .rig
                .skin
                .vertex(v)
                .1
                .iter()
                .filter(|&&w| w > 0.0)
                .count()
        })
        .sum();
    let skin_bytes = 12 * n + 6 * slots + 12 * n;
    rows.push((
        "skin".into(),
        skin,
        format!("{} KB read + written", skin_bytes / 1024),
    ));
    rows.push(("  memcpy".into(), memcpy(skin_bytes), String::new()));
    let base_frame = timings(frames_per_figure(), || {
        let i = next();
        black_box(predictor.predict(&mut ctx, &frames[i], None).unwrap()[0]);
    });
    rows.push(("base frame".into(), base_frame, String::new()));

    let qbox = quant_box(&model.rig.rest.positions);
    let mut enc = FrameEncoder::new(n, qbox, 30).unwrap();
    let mut out = Vec::new();
    let base = ctx.positions().to_vec();
    rows.push((
        "encode base".into(),
        timings(frames_per_figure(), || {
            enc.encode(&base, None, &mut out).unwrap();
        }),
        format!("{} bytes a frame", out.len()),
    ));
    rows.push(("  memcpy".into(), memcpy(12 * n), String::new()));

    if let Some(detail) = &model.detail {
        let nv = detail.regressor.vertex_count();
        let ex = detail.regressor.example_count();
        let x: Vec<f32> = ctx.controls().iter().flat_map(|p| p.to_array()).collect();
        let mut xi = vec![0.0; ex];
        let mut h = vec![0.0; nv];
        // The frame's form of D (blocks of eight rows, `BlockedRows`), alone.
        let blocked = BlockedRows::new(&detail.regressor);
        rows.push((
            "detail regress".into(),
            timings(frames_per_figure(), || {
                detail.regressor.kernel_vector(&x, &mut xi);
                blocked.apply_rows(&xi, 0, &mut h);
            }),
            format!("D {nv} x {ex}"),
        ));
        rows.push((
            "  memcpy".into(),
            memcpy(4 * nv * ex + 8 * nv),
            String::new(),
        ));
        let mut synth = DetailSynth::from_mesh(&model.rig.rest, detail.levels).unwrap();
        let mut high = vec![Vec3::ZERO; nv];
        rows.push((
            "detail synth".into(),
            timings(frames_per_figure(), || {
                synth.synthesize(&base, &h, &mut high).unwrap()
            }),
            format!("{nv} vertices"),
        ));
        rows.push((
            "  memcpy".into(),
            memcpy(12 * n + 4 * nv + 12 * nv),
            String::new(),
        ));
        rows.push((
            "detail frame".into(),
            timings(frames_per_figure(), || {
                black_box(predictor.predict_detail(&mut ctx).unwrap()[0]);
            }),
            String::new(),
        ));
        let qbox = quant_box(&high);
        let mut enc = FrameEncoder::new(nv, qbox, 30).unwrap();
        rows.push((
            "encode detail".into(),
            timings(frames_per_figure(), || {
                enc.encode(&high, None, &mut out).unwrap();
            }),
            format!("{} bytes a frame", out.len()),
        ));
        rows.push(("  memcpy".into(), memcpy(12 * nv), String::new()));
    }

    println!(
        "{} base vertices, {bones} bones, {} controls, {} test frames; single thread unless \
         RAYON_NUM_THREADS says otherwise; FMA rate {:.2} G f32/s, {:.2} G f64/s",
        n,
        model.controls.len(),
        frames.len(),
        f32_rate / 1e9,
        f64_rate / 1e9
    );
    println!("| stage | median µs | min µs | note |");
    println!("|---|---|---|---|");
    for (name, (median, min), note) in rows {
        println!(
            "| {name} | {:.1} | {:.1} | {note} |",
            median.as_secs_f64() * 1e6,
            min.as_secs_f64() * 1e6
        );
    }
}
