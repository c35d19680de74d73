//! Per-frame cost of the LYK06 sweep hand (`crease_hand`), single thread, at both
//! resolutions, stage by stage:
//!
//! - `sample`: pose the skeleton and sample the five sweeps (160 frames each);
//! - `skin`: reconstruct every vertex from the samples (LYK06 eq. 1, blended);
//! - `palm`: the palm-control surface (LYK06 eq. 2, 54 nodes, bulge);
//! - `folds`: the self-intersection fix at IP/PIP/DIP only;
//! - `collide`: folds + digit-digit + digit-palm collisions with push-out;
//! - `creases`: the crease displacements (detailed only);
//! - `frame`: the whole frame (all layers the resolution has);
//! - `memcpy`: a copy of the output positions (12 B per vertex), for scale.
//!
//! Poses: the fist (the worst case for collisions) and `relaxed`.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p crease-hand --bench sweep -- --quick`. After criterion's
//! groups it prints one summary line per case with medians and minima of its own timing loop.

#[path = "../../core/benches/common/mod.rs"]
mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::glam::Vec3;
use crease_hand::collide::CollideOptions;
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::skeleton::{HandPose, NamedPose};
use crease_hand::surface::Resolution;
use crease_hand::sweeps::SweepSamples;
use criterion::Criterion;

/// Frames timed per summary figure (base; the detailed hand uses a tenth).
const FRAMES: usize = 400;

fn folds_only() -> CollideOptions {
    CollideOptions {
        fix_folds: true,
        digits: false,
        palm: false,
        object: None,
        ..CollideOptions::default()
    }
}

fn main() {
    let mut c = Criterion::default()
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500))
        .configure_from_args();
    let mut summary = Vec::new();
    for resolution in [Resolution::Base, Resolution::Detailed] {
        let rig = HandRig::build(resolution).expect("rig");
        let n = rig.vertex_count();
        let frames = if resolution == Resolution::Base {
            FRAMES
        } else {
            FRAMES / 10
        };
        for named in [NamedPose::Fist, NamedPose::Relaxed] {
            let pose = HandPose::named(named);
            let case = format!("{resolution:?}/{}", named.name()).to_lowercase();
            let mut scratch = RigScratch::new();
            let mut out = vec![Vec3::ZERO; n];
            let mut samples = SweepSamples::new();
            rig.sweeps().sample(&pose, &mut samples);
            rig.sweeps().skin_into(&samples, &mut out);
            let swept = out.clone();
            let sweeps_only = Layers::SWEEPS_ONLY;
            let palm = Layers {
                palm: true,
                ..sweeps_only
            };
            let palm_folds = Layers {
                collide: Some(folds_only()),
                ..palm
            };
            let all = Layers::default();
            let mut group = c.benchmark_group(format!("sweep/{case}"));
            group.sample_size(if resolution == Resolution::Base {
                50
            } else {
                10
            });
            let mut record = |name: &str, f: &mut dyn FnMut()| {
                group.bench_function(name, |b| b.iter(&mut *f));
                let (median, min) = timings(frames, &mut *f);
                summary.push(format!(
                    "{case:>16} {name:>22}: median {:>9.1} µs, min {:>9.1} µs",
                    median.as_secs_f64() * 1e6,
                    min.as_secs_f64() * 1e6
                ));
            };
            record("sample", &mut || {
                rig.sweeps().sample(black_box(&pose), &mut samples)
            });
            record("skin", &mut || rig.sweeps().skin_into(&samples, &mut out));
            if let Some(p) = rig.palm() {
                record("palm", &mut || {
                    out.copy_from_slice(&swept);
                    p.apply(&pose, &mut out)
                });
            }
            record("frame (sweeps only)", &mut || {
                rig.deform(&pose, sweeps_only, &mut scratch, &mut out)
            });
            record("frame (+palm)", &mut || {
                rig.deform(&pose, palm, &mut scratch, &mut out)
            });
            record("frame (+palm +folds)", &mut || {
                rig.deform(&pose, palm_folds, &mut scratch, &mut out)
            });
            record("frame (all layers)", &mut || {
                rig.deform(&pose, all, &mut scratch, &mut out)
            });
            let mut copy = vec![Vec3::ZERO; n];
            record("memcpy", &mut || copy.copy_from_slice(black_box(&out)));
            group.finish();
        }
    }
    c.final_summary();
    println!("\nsweep hand per frame (single thread unless RAYON_NUM_THREADS says otherwise):");
    for line in summary {
        println!("{line}");
    }
}
