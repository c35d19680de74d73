//! What recording a take costs a room per frame (`server::takes::Recorder::record` minus the
//! channel send): `take::fill_frame` (the control frame, the controls used and the bone
//! transforms into the reused record) and `take::encode_record` (protobuf + CRC-32 into a reused
//! buffer), for the demo hand's size (40 bones, 16 control points) and the horse's (150 bones,
//! 8 points); next to a plain copy of the transforms (the floor: the bytes must be moved once).
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p crease-proto --bench take -- --quick`

use std::hint::black_box;

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::skin::RigidTransform;
use crease_proto::take::{encode_record, fill_frame};
use crease_proto::v1;
use criterion::{Criterion, criterion_group, criterion_main};

fn case(c: &mut Criterion, name: &str, bones: usize, controls: usize) {
    let transforms: Vec<RigidTransform> = (0..bones)
        .map(|b| RigidTransform {
            rotation: Quat::from_rotation_y(0.01 * b as f32),
            translation: Vec3::new(b as f32, 0.5, -1.0),
        })
        .collect();
    let points: Vec<Vec3> = (0..controls).map(|i| Vec3::splat(i as f32 * 0.1)).collect();
    let frame = v1::ControlFrame {
        room: "demo".into(),
        seq: 7,
        capture_time_us: 1_700_000_000_000_000,
        positions: points.iter().flat_map(|p| p.to_array()).collect(),
        ..Default::default()
    };
    let mut record = v1::TakeFrame::default();
    let mut buf = Vec::new();
    c.bench_function(&format!("take_record/{name}"), |b| {
        b.iter(|| {
            fill_frame(&mut record, black_box(&frame), 1234, &points, &transforms);
            encode_record(&record, &mut buf);
            black_box(buf.len())
        })
    });
    let mut copy: Vec<RigidTransform> = Vec::with_capacity(bones);
    c.bench_function(&format!("take_copy_floor/{name}"), |b| {
        b.iter(|| {
            copy.clear();
            copy.extend_from_slice(black_box(&transforms));
            black_box(copy.len())
        })
    });
    fill_frame(&mut record, &frame, 1234, &points, &transforms);
    encode_record(&record, &mut buf);
    println!(
        "{name}: {bones} bones, {controls} controls: {} bytes a record",
        buf.len()
    );
}

fn benches(c: &mut Criterion) {
    case(c, "hand", 40, 16);
    case(c, "horse", 150, 8);
}

criterion_group!(take, benches);
criterion_main!(take);
