//! The WebSocket publisher's JSON text (`crease_proto::json::JsonControlFrame`): parsed, turned
//! into a `ControlFrame` and read as the room reads it, as control points and as markers.
#![no_main]
use crease_core::glam::Vec3;
use crease_proto::json::JsonControlFrame;
use crease_proto::{read_control_frame, read_marker_frame};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(json) = JsonControlFrame::parse(text) else {
        return;
    };
    let Ok(frame) = json.into_control_frame("room") else {
        return;
    };
    for n in [1, 3, 8, 75] {
        let mut positions = vec![Vec3::ZERO; n];
        let mut valid = vec![false; n];
        if read_control_frame(&frame, &mut positions, &mut valid).is_ok() {
            assert!(
                positions
                    .iter()
                    .zip(&valid)
                    .all(|(p, &v)| !v || p.is_finite())
            );
        }
        if read_marker_frame(&frame, &mut positions, &mut valid).is_ok() {
            assert!(
                positions
                    .iter()
                    .zip(&valid)
                    .all(|(p, &v)| !v || p.is_finite())
            );
        }
    }
});
