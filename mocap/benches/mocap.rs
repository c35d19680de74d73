//! `core::mocap` on the real recordings: reading, retargeting and filtering costs per frame, and
//! how well the two gap fillers guess a marker that was seen (`GapFill::Hold` vs
//! `GapFill::Neighbour`, see `core::mocap::retarget`).
//!
//! The gap study hides each of the ten finger markers of the Qualisys glove recording in
//! half-second windows (50 frames, one window every 5 s, only where the marker was seen for the
//! whole window), retargets onto the glove13 landmarks of the sweep hand's rest mesh with each
//! filler, and compares what each sends for the hidden marker with where the marker really was
//! (the unmodified run), in the hand frame, in recording millimetres. Hold's guess is the last
//! position sent before the gap (what the server then holds).
//!
//! `cargo bench -p crease-mocap --bench mocap`. Needs ../shared/data/mocap; says so and stops
//! without it.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

#[path = "../../core/benches/common/mod.rs"]
mod common;
use common::timings;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::runtime::filter::{OneEuro, OneEuroParams};
use crease_hand::dataset::{Layout, landmarks};
use crease_hand::rig::HandRig;
use crease_hand::surface::Resolution;
use crease_mocap::map::{GapFill, MarkerMap};
use crease_mocap::{Recording, Retarget};

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/mocap");
const MAP: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../bench/mocap/qualisys-glove13.toml"
);
/// Hidden window length and spacing, frames (100 Hz).
const WINDOW: usize = 50;
const EVERY: usize = 500;

/// Runs the whole recording through a retarget; per frame the control positions and validity.
fn run(
    recording: &Recording,
    map: &MarkerMap,
    names: &[String],
    rest: &[Vec3],
) -> (Vec<Vec<(Vec3, bool)>>, f32) {
    let bound = map.bind(recording, names).expect("map binds");
    let mut rt = Retarget::new(bound, rest);
    rt.calibrate(recording);
    let n = names.len();
    let (mut p, mut v) = (vec![Vec3::ZERO; n], vec![false; n]);
    let out = recording
        .frames()
        .map(|f| {
            rt.frame(&f, &mut p, &mut v);
            p.iter().copied().zip(v.iter().copied()).collect()
        })
        .collect();
    (out, rt.registration().scale().unwrap_or(1.0))
}

/// The recording with marker `m` invalid in `windows`.
fn hide(recording: &Recording, m: usize, windows: &[usize]) -> Recording {
    let mut positions = Vec::new();
    let mut valid = Vec::new();
    for f in recording.frames() {
        let hidden = windows.iter().any(|&s| (s..s + WINDOW).contains(&f.index));
        positions.extend_from_slice(f.positions);
        valid.extend(
            f.valid
                .iter()
                .enumerate()
                .map(|(k, v)| *v && !(hidden && k == m)),
        );
    }
    Recording::new(
        recording.names.clone(),
        recording.rate_hz,
        recording.units.clone(),
        positions,
        valid,
    )
}

fn main() {
    let tsv = Path::new(DATA).join("qualisys-hand-glove-recording.tsv");
    let c3d = Path::new(DATA).join("ART-Human_hands_real_no6dof.c3d");
    if !tsv.exists() {
        println!(
            "mocap bench: {} not found, nothing to measure",
            tsv.display()
        );
        return;
    }
    let (read_tsv, _) = timings(5, || {
        black_box(Recording::read(&tsv).unwrap());
    });
    let recording = Recording::read(&tsv).unwrap();
    let (read_c3d, _) = timings(5, || {
        black_box(Recording::read(&c3d).unwrap());
    });
    println!(
        "read: TSV {} frames in {:.1} ms ({:.2} µs/frame); C3D 969 frames in {:.1} ms",
        recording.frame_count(),
        read_tsv.as_secs_f64() * 1e3,
        read_tsv.as_secs_f64() * 1e6 / recording.frame_count() as f64,
        read_c3d.as_secs_f64() * 1e3
    );

    // glove13 landmarks on the sweep hand's rest mesh: names and rest positions.
    let rig = HandRig::build(Resolution::Base).expect("sweep hand");
    let normals = rig.rest().vertex_normals();
    let marks = landmarks(Layout::Glove13, rig.skeleton(), rig.rest(), &normals);
    let names: Vec<String> = marks.iter().map(|l| l.name.clone()).collect();
    let rest: Vec<Vec3> = marks
        .iter()
        .map(|l| rig.rest().positions[l.vertex as usize])
        .collect();
    let mut map = MarkerMap::read(MAP).unwrap();

    // Per-frame costs.
    let bound = map.bind(&recording, &names).unwrap();
    let mut rt = Retarget::new(bound, &rest);
    rt.calibrate(&recording);
    let (mut p, mut v) = (vec![Vec3::ZERO; names.len()], vec![false; names.len()]);
    let frames = recording.frame_count();
    let (per_pass, best) = timings(20, || {
        for f in recording.frames() {
            rt.frame(&f, &mut p, &mut v);
        }
        black_box(&p);
    });
    let mut filters = vec![OneEuro::new(OneEuroParams::default()); names.len()];
    let (filter_pass, _) = timings(20, || {
        for f in recording.frames() {
            for (k, flt) in filters.iter_mut().enumerate() {
                black_box(flt.filter(f.positions[k] * 0.001, 0.01));
            }
        }
    });
    println!(
        "retarget (mix + register + gap fill), 13 points: {:.2} µs/frame median, {:.2} min; One Euro on 13 points: {:.3} µs/frame",
        per_pass.as_secs_f64() * 1e6 / frames as f64,
        best.as_secs_f64() * 1e6 / frames as f64,
        filter_pass.as_secs_f64() * 1e6 / frames as f64
    );

    // The gap study.
    let start = Instant::now();
    let (truth, scale) = run(&recording, &map, &names, &rest);
    let mut table = Vec::new();
    for fill in [GapFill::Hold, GapFill::Neighbour] {
        map.gaps.fill = fill;
        let (mut sum, mut count, mut unfilled) = (0.0f64, 0usize, 0usize);
        let mut per_marker = Vec::new();
        for (cp, name) in names.iter().enumerate().skip(3) {
            let m = recording.marker(name).expect("marker");
            let windows: Vec<usize> = (EVERY..frames - WINDOW)
                .step_by(EVERY)
                .filter(|&s| (s - 1..s + WINDOW).all(|f| recording.frame(f).valid[m]))
                .collect();
            let hidden = hide(&recording, m, &windows);
            let (got, _) = run(&hidden, &map, &names, &rest);
            let (mut s, mut c) = (0.0f64, 0usize);
            for &w in &windows {
                let last = got[w - 1][cp].0;
                for f in w..w + WINDOW {
                    let (p, ok) = got[f][cp];
                    let guess = if ok { p } else { last };
                    unfilled += usize::from(!ok);
                    let d = f64::from(guess.distance(truth[f][cp].0) / scale);
                    s += d * d;
                    c += 1;
                }
            }
            sum += s;
            count += c;
            per_marker.push(format!("{name} {:.1}", (s / c.max(1) as f64).sqrt()));
        }
        table.push(format!(
            "{fill:?}: RMS {:.1} mm over {count} hidden samples ({unfilled} left to the server's hold) | {}",
            (sum / count.max(1) as f64).sqrt(),
            per_marker.join(", ")
        ));
    }
    println!(
        "gap study ({WINDOW}-frame windows every {EVERY} frames, each finger marker in turn, {:.1} s):",
        start.elapsed().as_secs_f64()
    );
    for row in table {
        println!("  {row}");
    }
}
