//! A fixed number of calls of one per-frame kernel, for instruction counts that do not depend
//! on the machine's load (issue 23):
//!
//! ```sh
//! cargo build --release -p crease-core --example kernel_counts
//! RAYON_NUM_THREADS=1 valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.out \
//!     --toggle-collect='crease_core::runtime::skin::packed::skin_lbs_packed_with' \
//!     target/release/examples/kernel_counts lbs fma 20
//! # valgrind prints "Collected : I", the instructions of the 20 calls: divide by 20
//! ```
//!
//! Kernels: `lbs` (the packed LBS on a horse-sized synthetic rig: 8,431 vertices, 150 bones,
//! k = 8, every slot used; `portable` or `fma`; run with `RAYON_NUM_THREADS=1`, else the work
//! runs on rayon's threads, outside the toggled function), `operator` (`LinearOperator::apply`,
//! 600 rows of 23 columns: the horse's rotation regressor; `CREASE_SIMD=portable` for the
//! portable loop). `apply` is inlined into its caller, so count it as the whole run with N calls
//! minus the whole run with 0 calls (no `--toggle-collect`), divided by N.
#![allow(clippy::unwrap_used)] // a measuring tool: a failed unwrap names its line

use std::hint::black_box;

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::predict::LinearOperator;
use crease_core::runtime::skin::{
    BonePalette, PackedKernel, PackedSkin, RigidTransform, SkinWeights, skin_lbs_packed_with,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: kernel_counts lbs portable|fma CALLS | kernel_counts operator CALLS";
    let mut rng = StdRng::seed_from_u64(23);
    match args.get(1).map(String::as_str) {
        Some("lbs") => {
            let kernel = match args.get(2).map(String::as_str) {
                Some("portable") => PackedKernel::Portable,
                Some("fma") if PackedKernel::Fma.available() => PackedKernel::Fma,
                Some("fma") => panic!("this CPU lacks AVX2 + FMA"),
                _ => panic!("{usage}"),
            };
            let calls: usize = args.get(3).expect(usage).parse().unwrap();
            let (n, k, bones) = (8431, 8, 150u32);
            let rest: Vec<Vec3> = (0..n)
                .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
                .collect();
            let mut indices = Vec::new();
            let mut weights = Vec::new();
            for _ in 0..n {
                let w: Vec<f32> = (0..k).map(|_| rng.random::<f32>() + 0.01).collect();
                let s: f32 = w.iter().sum();
                weights.extend(w.iter().map(|x| x / s));
                indices.extend((0..k).map(|_| rng.random_range(0..bones)));
            }
            let skin = SkinWeights::new(k, indices, weights).unwrap();
            let packed = PackedSkin::new(&skin).unwrap();
            let transforms: Vec<RigidTransform> = (0..bones)
                .map(|_| {
                    RigidTransform::new(
                        Quat::from_rotation_y(rng.random_range(-3.0..3.0)),
                        Vec3::new(rng.random(), rng.random(), rng.random()),
                    )
                })
                .collect();
            let palette = BonePalette::from_transforms(&transforms);
            let mut out = vec![Vec3::ZERO; n];
            for _ in 0..calls {
                skin_lbs_packed_with(kernel, black_box(&rest), &packed, &palette, &mut out)
                    .unwrap();
                black_box(&out);
            }
            println!(
                "{calls} calls of crease_core::runtime::skin::packed::skin_lbs_packed_with \
                 ({kernel:?}, {n} vertices, k = {k}, {bones} bones)"
            );
        }
        Some("operator") => {
            let calls: usize = args.get(2).expect(usage).parse().unwrap();
            let (rows, cols) = (600, 23);
            let op = LinearOperator {
                rows,
                cols,
                m: (0..rows * cols)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect(),
                b: (0..rows).map(|_| rng.random_range(-1.0..1.0)).collect(),
            };
            let xi: Vec<f32> = (0..cols).map(|_| rng.random()).collect();
            let mut out = vec![0.0; rows];
            for _ in 0..calls {
                op.apply(black_box(&xi), &mut out);
                black_box(&out);
            }
            println!(
                "{calls} calls of crease_core::runtime::predict::LinearOperator::apply \
                 ({rows} x {cols}; CREASE_SIMD={})",
                std::env::var("CREASE_SIMD").unwrap_or_default()
            );
        }
        _ => panic!("{usage}"),
    }
}
