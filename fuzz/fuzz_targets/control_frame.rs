//! A `ControlFrame` as the gRPC ingest reads it: protobuf decoding (prost), then
//! `read_control_frame` for a room of N control points and `read_marker_frame` for a
//! retargeting room of M markers (N and M from the first byte). Accepted values are finite.
#![no_main]
use crease_core::glam::Vec3;
use crease_proto::{read_control_frame, read_marker_frame, v1};
use libfuzzer_sys::fuzz_target;
use prost::Message as _;

fuzz_target!(|data: &[u8]| {
    let Some((&sizes, bytes)) = data.split_first() else {
        return;
    };
    let Ok(frame) = v1::ControlFrame::decode(bytes) else {
        return;
    };
    let n = usize::from(sizes & 0x0f) + 1;
    let mut positions = vec![Vec3::ZERO; n];
    let mut valid = vec![false; n];
    if let Ok(invalid) = read_control_frame(&frame, &mut positions, &mut valid) {
        assert!(invalid <= n);
        assert!(
            positions
                .iter()
                .zip(&valid)
                .all(|(p, &v)| !v || p.is_finite())
        );
    }
    let m = usize::from(sizes >> 4) * 5 + 1;
    let mut markers = vec![Vec3::ZERO; m];
    let mut valid = vec![false; m];
    if read_marker_frame(&frame, &mut markers, &mut valid).is_ok() {
        assert!(
            markers
                .iter()
                .zip(&valid)
                .all(|(p, &v)| !v || p.is_finite())
        );
    }
});
