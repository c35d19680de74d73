//! Per-frame cost of the detail layer (HZY11 eq. 4, DESIGN step 9) on the base hand subdivided
//! twice (`HandSurface::build(Resolution::Base)`, ~9.5K vertices -> ~151K), next to a plain
//! memory copy of the output bytes in the same run.
//!
//! Functions:
//! - `subdivide`: `high = S · base` with the composed 2-level matrix ([`DetailSynth::subdivide`]);
//! - `subdivide_factored`: the same product as two 1-level matrices applied in turn
//!   (`S2 · (S1 · base)`, through a ~38K-vertex intermediate), for comparison;
//! - `normals`: area-weighted vertex normals of `high` by gather ([`VertexFans::normals`]);
//! - `normals_scatter`: the same by a scatter pass over the triangles ([`scatter_normals`]);
//! - `displace`: `high += h ⊙ n` ([`displace`]);
//! - `whole`: all three ([`DetailSynth::synthesize`], [`NormalsMethod::Auto`]: scatter on one
//!   thread, gather on several), with the normalisation fused into the displacement pass;
//! - `whole_scatter`, `whole_gather`: the same with the normals method forced;
//! - `memcpy`: a copy of the output positions' bytes (12 B per subdivided vertex).
//!
//! `h` is random (seeded, ±0.5 mm); the base is the rest hand (the cost does not depend on the
//! pose). `cargo bench -p crease-hand --bench detail -- --quick`; single-threaded:
//! `RAYON_NUM_THREADS=1`, or `--no-default-features`. After criterion's groups it prints one
//! summary line per function with medians (and minima) of its own timing loop.

#[path = "../../core/benches/common/mod.rs"]
mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::mesh::subdivision::LoopSubdivision;
use crease_core::runtime::detail::{DetailSynth, NormalsMethod, displace, scatter_normals};
use crease_hand::surface::{HandSurface, Resolution};
use criterion::{Criterion, Throughput};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Subdivision levels: DESIGN step 2 allows 1–2; 2 is the one that reaches ≥ 150K vertices.
const LEVELS: u32 = 2;
/// Frames timed per summary figure.
const FRAMES: usize = 300;

fn threads() -> String {
    #[cfg(feature = "parallel")]
    return format!(
        "parallel feature on, {} rayon threads",
        rayon::current_num_threads()
    );
    #[cfg(not(feature = "parallel"))]
    return "parallel feature off".to_string();
}

/// Everything a frame needs, built once.
struct Fixture {
    base: Vec<Vec3>,
    synth: DetailSynth,
    synth_scatter: DetailSynth,
    synth_gather: DetailSynth,
    /// 1-level matrices for the factored comparison: base -> level 1, level 1 -> level 2.
    s1: LoopSubdivision,
    s2: LoopSubdivision,
    h: Vec<f32>,
    high: Vec<Vec3>,
    mid: Vec<Vec3>,
    normals: Vec<Vec3>,
    out: Vec<Vec3>,
    src: Vec<u8>,
    dst: Vec<u8>,
}

impl Fixture {
    fn new(hand: &Mesh) -> Fixture {
        let synth = DetailSynth::from_mesh(hand, LEVELS).expect("the hand is manifold");
        let n = synth.vertex_count();
        let s1 = LoopSubdivision::new(hand, 1).expect("manifold");
        let level1 = s1.mesh(&hand.positions).expect("sizes match");
        let s2 = LoopSubdivision::new(&level1, 1).expect("manifold");
        let mut rng = StdRng::seed_from_u64(5);
        let h = (0..n).map(|_| rng.random_range(-5e-4..5e-4)).collect();
        let mut high = vec![Vec3::ZERO; n];
        synth.subdivide(&hand.positions, &mut high).expect("sizes");
        let bytes = n * std::mem::size_of::<Vec3>();
        Fixture {
            base: hand.positions.clone(),
            mid: vec![Vec3::ZERO; s1.vertex_count()],
            s1,
            s2,
            h,
            normals: vec![Vec3::ZERO; n],
            out: vec![Vec3::ZERO; n],
            high,
            synth_scatter: synth.clone().with_normals_method(NormalsMethod::Scatter),
            synth_gather: synth.clone().with_normals_method(NormalsMethod::Gather),
            synth,
            src: vec![1u8; bytes],
            dst: vec![0u8; bytes],
        }
    }

    fn run(&mut self, f: Func) {
        match f {
            Func::Subdivide => self
                .synth
                .subdivide(black_box(&self.base), &mut self.out)
                .expect("sizes"),
            Func::SubdivideFactored => {
                let base = black_box(&self.base);
                self.s1.matrix().apply(base, &mut self.mid).expect("sizes");
                self.s2
                    .matrix()
                    .apply(&self.mid, &mut self.out)
                    .expect("sizes");
            }
            Func::Normals => self
                .synth
                .fans()
                .normals(black_box(&self.high), &mut self.normals)
                .expect("sizes"),
            Func::NormalsScatter => scatter_normals(
                black_box(&self.high),
                self.synth.subdivision().triangles(),
                &mut self.normals,
            )
            .expect("sizes"),
            // Displaces `out` again every frame: the cost is the same, the values drift.
            Func::Displace => {
                displace(&mut self.out, black_box(&self.normals), &self.h).expect("sizes")
            }
            Func::Whole => self
                .synth
                .synthesize(black_box(&self.base), &self.h, &mut self.out)
                .expect("sizes"),
            Func::WholeScatter => self
                .synth_scatter
                .synthesize(black_box(&self.base), &self.h, &mut self.out)
                .expect("sizes"),
            Func::WholeGather => self
                .synth_gather
                .synthesize(black_box(&self.base), &self.h, &mut self.out)
                .expect("sizes"),
            Func::Memcpy => self.dst.copy_from_slice(black_box(&self.src)),
        }
        black_box(&self.out);
        black_box(&self.normals);
        black_box(&self.dst);
    }
}

/// The functions timed (module docs).
#[derive(Clone, Copy, Debug)]
enum Func {
    Subdivide,
    SubdivideFactored,
    Normals,
    NormalsScatter,
    Displace,
    Whole,
    WholeScatter,
    WholeGather,
    Memcpy,
}

const FUNCS: [(&str, Func); 9] = [
    ("subdivide", Func::Subdivide),
    ("subdivide_factored", Func::SubdivideFactored),
    ("normals", Func::Normals),
    ("normals_scatter", Func::NormalsScatter),
    ("displace", Func::Displace),
    ("whole", Func::Whole),
    ("whole_scatter", Func::WholeScatter),
    ("whole_gather", Func::WholeGather),
    ("memcpy", Func::Memcpy),
];

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let hand = HandSurface::build(Resolution::Base)
        .expect("base hand builds")
        .mesh;
    let mut fx = Fixture::new(&hand);
    let n = fx.synth.vertex_count();
    let s = fx.synth.subdivision().matrix();
    println!(
        "detail bench: base hand {} vertices, {} triangles -> {LEVELS} levels: {n} vertices, {} \
         triangles; S has {} entries ({:.2} per row, {:.1} MB), factored 1-level matrices {} + \
         {} entries; {}",
        hand.vertex_count(),
        hand.triangles.len(),
        fx.synth.subdivision().triangles().len(),
        s.nnz(),
        s.nnz() as f64 / n as f64,
        (s.nnz() * 8 + (n + 1) * 4) as f64 / 1e6,
        fx.s1.matrix().nnz(),
        fx.s2.matrix().nnz(),
        threads()
    );

    let mut g = c.benchmark_group(format!("detail_{n}"));
    g.throughput(Throughput::Elements(n as u64));
    for (label, f) in FUNCS {
        g.bench_function(label, |b| b.iter(|| fx.run(f)));
    }
    g.finish();

    let us = |d: Duration| d.as_secs_f64() * 1e6;
    let copy = timings(FRAMES, || fx.run(Func::Memcpy));
    println!(
        "\nsummary ({n} vertices, {}; medians (and minima) of {FRAMES} frames; memcpy of the \
         {} output bytes: {:.1} µs ({:.1} µs))",
        threads(),
        fx.src.len(),
        us(copy.0),
        us(copy.1)
    );
    for (label, f) in FUNCS {
        let t = timings(FRAMES, || fx.run(f));
        println!(
            "{label}: {:.1} µs/frame ({:.1} µs), {:.1} ns/vertex, {:.1}x memcpy",
            us(t.0),
            us(t.1),
            t.0.as_secs_f64() * 1e9 / n as f64,
            us(t.0) / us(copy.0)
        );
    }
    c.final_summary();
}
