//! Control frames, the one message a publisher sends per frame: read into the model's control
//! points (caller buffers, no allocation per frame, every field checked and named when wrong),
//! built for the wire by publishers, and their validity bit mask.

use crease_core::glam::Vec3;

use crate::errors::WireError;
use crate::v1;

/// Whether bit `i` of a validity mask is set; an empty mask means every point is valid.
pub fn valid_bit(mask: &[u8], i: usize) -> bool {
    mask.is_empty() || mask.get(i / 8).is_some_and(|b| b & (1 << (i % 8)) != 0)
}

/// The validity bitmask of `valid` (bit `i` = `valid[i]`, least significant bit first), into
/// `out` (cleared first).
pub fn encode_valid_mask(valid: &[bool], out: &mut Vec<u8>) {
    out.clear();
    out.resize(valid.len().div_ceil(8), 0);
    for (i, _) in valid.iter().enumerate().filter(|(_, v)| **v) {
        out[i / 8] |= 1 << (i % 8);
    }
}

/// Reads a retargeting room's marker frame (`ControlFrame.markers` / `markers_valid`, issue 19)
/// into `positions` and `valid`, one per marker the room declared (`Retarget.markers`).
///
/// # Errors
/// A [`WireError`] naming `positions` (a frame of control points, not markers), `markers`
/// (count), `markers[i]` (a non-finite coordinate of a valid marker) or `markers_valid` (mask
/// length). Nothing is written on error.
pub fn read_marker_frame(
    frame: &v1::ControlFrame,
    positions: &mut [Vec3],
    valid: &mut [bool],
) -> Result<(), WireError> {
    let n = positions.len();
    assert_eq!(valid.len(), n, "one validity flag per marker");
    if !frame.positions.is_empty() {
        return Err(WireError::new(
            "ControlFrame",
            "positions",
            format!(
                "{} values: a retargeting room takes the capture's markers (ControlFrame.markers), not control points",
                frame.positions.len()
            ),
        ));
    }
    if frame.markers.len() != 3 * n {
        return Err(WireError::new(
            "ControlFrame",
            "markers",
            format!(
                "{} values, expected {} (x, y, z of the room's {n} markers, Retarget.markers)",
                frame.markers.len(),
                3 * n
            ),
        ));
    }
    let mask = &frame.markers_valid;
    if !mask.is_empty() && mask.len() != n.div_ceil(8) {
        return Err(WireError::new(
            "ControlFrame",
            "markers_valid",
            format!(
                "{} bytes, expected {} (one bit per marker, {n} markers) or none",
                mask.len(),
                n.div_ceil(8)
            ),
        ));
    }
    for (i, c) in frame.markers.chunks_exact(3).enumerate() {
        if valid_bit(mask, i) && !c.iter().all(|v| v.is_finite()) {
            return Err(WireError::new(
                "ControlFrame",
                format!("markers[{i}]"),
                format!(
                    "({}, {}, {}) is not finite; mark the marker invalid in `markers_valid` instead",
                    c[0], c[1], c[2]
                ),
            ));
        }
    }
    for (i, (c, (p, ok))) in frame
        .markers
        .chunks_exact(3)
        .zip(positions.iter_mut().zip(valid.iter_mut()))
        .enumerate()
    {
        *ok = valid_bit(mask, i);
        *p = if *ok {
            Vec3::new(c[0], c[1], c[2])
        } else {
            Vec3::ZERO
        };
    }
    Ok(())
}

/// Reads a control frame for a model with `positions.len()` control points into `positions`
/// and `valid`, and returns how many points are invalid. A point marked invalid may carry any
/// value (it is held at its last valid position by the predictor); a valid one must be finite.
///
/// # Errors
/// A [`WireError`] naming `positions` (count), `positions[i]` (non-finite coordinate of a valid
/// point), `valid` (mask length), or `markers` (a control frame that carries markers: only a
/// retargeting room reads them). Nothing is written on error.
pub fn read_control_frame(
    frame: &v1::ControlFrame,
    positions: &mut [Vec3],
    valid: &mut [bool],
) -> Result<usize, WireError> {
    let n = positions.len();
    assert_eq!(valid.len(), n, "one validity flag per control point");
    if !frame.markers.is_empty() {
        return Err(WireError::new(
            "ControlFrame",
            "markers",
            format!(
                "{} values: this room takes control points; markers need a room opened with a Retarget",
                frame.markers.len()
            ),
        ));
    }
    if frame.positions.len() != 3 * n {
        return Err(WireError::new(
            "ControlFrame",
            "positions",
            format!(
                "{} values, expected {} (x, y, z of {n} control points)",
                frame.positions.len(),
                3 * n
            ),
        ));
    }
    let mask = &frame.valid;
    if !mask.is_empty() && mask.len() != n.div_ceil(8) {
        return Err(WireError::new(
            "ControlFrame",
            "valid",
            format!(
                "{} bytes, expected {} (one bit per control point, {n} points) or none",
                mask.len(),
                n.div_ceil(8)
            ),
        ));
    }
    for (i, c) in frame.positions.chunks_exact(3).enumerate() {
        if valid_bit(mask, i) && !c.iter().all(|v| v.is_finite()) {
            return Err(WireError::new(
                "ControlFrame",
                format!("positions[{i}]"),
                format!(
                    "({}, {}, {}) is not finite; mark the point invalid in `valid` instead",
                    c[0], c[1], c[2]
                ),
            ));
        }
    }
    let mut invalid = 0;
    for (i, (c, (p, v))) in frame
        .positions
        .chunks_exact(3)
        .zip(positions.iter_mut().zip(valid.iter_mut()))
        .enumerate()
    {
        *v = valid_bit(mask, i);
        *p = if *v {
            Vec3::new(c[0], c[1], c[2])
        } else {
            invalid += 1;
            Vec3::NAN
        };
    }
    Ok(invalid)
}

/// A control frame for the wire whose `positions` are flattened already (`x, y, z` per
/// control point, all valid): a publisher that fills one buffer per frame.
pub fn control_frame_flat(
    room: &str,
    seq: u64,
    capture_time_us: i64,
    positions: Vec<f32>,
) -> v1::ControlFrame {
    v1::ControlFrame {
        room: room.to_owned(),
        seq,
        capture_time_us,
        positions,
        ..Default::default()
    }
}

/// `frame` as a frame of a room of several actors: its room, sequence number and capture
/// time, and `parts` (its own points and masks dropped).
pub fn with_actors(frame: v1::ControlFrame, parts: Vec<v1::ActorControls>) -> v1::ControlFrame {
    v1::ControlFrame {
        room: frame.room,
        seq: frame.seq,
        capture_time_us: frame.capture_time_us,
        actors: parts,
        ..Default::default()
    }
}

/// Actor `actor`'s part of a control frame of a room of several actors: `frame`'s points (or
/// markers) and masks, moved, not copied (its room, sequence number and time belong to the
/// frame that carries the part).
pub fn actor_controls(actor: &str, frame: v1::ControlFrame) -> v1::ActorControls {
    v1::ActorControls {
        actor: actor.to_owned(),
        positions: frame.positions,
        valid: frame.valid,
        markers: frame.markers,
        markers_valid: frame.markers_valid,
    }
}

/// A control frame for the wire: `positions` flattened to `x, y, z` (a point that is not
/// finite is sent as zeros; mark it invalid), and the validity mask, left empty when every
/// point is valid (which the server reads as "all valid").
pub fn control_frame(
    room: &str,
    seq: u64,
    capture_time_us: i64,
    positions: &[Vec3],
    valid: &[bool],
) -> v1::ControlFrame {
    let mut mask = Vec::new();
    if valid.iter().any(|v| !v) {
        encode_valid_mask(valid, &mut mask);
    }
    v1::ControlFrame {
        room: room.to_owned(),
        seq,
        capture_time_us,
        positions: positions
            .iter()
            .flat_map(|p| {
                if p.is_finite() {
                    p.to_array()
                } else {
                    [0.0; 3]
                }
            })
            .collect(),
        valid: mask,
        ..Default::default()
    }
}

/// A retargeting input frame ([`v1::Retarget`]): `markers` and their mask laid out as
/// [`control_frame`] lays out control points, in the `markers` fields.
pub fn marker_frame(
    room: &str,
    seq: u64,
    capture_time_us: i64,
    markers: &[Vec3],
    valid: &[bool],
) -> v1::ControlFrame {
    let mut frame = control_frame(room, seq, capture_time_us, markers, valid);
    frame.markers = std::mem::take(&mut frame.positions);
    frame.markers_valid = std::mem::take(&mut frame.valid);
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(positions: Vec<f32>, valid: Vec<u8>) -> v1::ControlFrame {
        v1::ControlFrame {
            room: "r".into(),
            seq: 1,
            capture_time_us: 0,
            positions,
            valid,
            ..Default::default()
        }
    }

    #[test]
    fn mask_round_trips_and_empty_means_all_valid() {
        let valid = [
            true, false, true, true, false, false, false, false, true, false,
        ];
        let mut mask = Vec::new();
        encode_valid_mask(&valid, &mut mask);
        assert_eq!(mask, [0b0000_1101, 0b0000_0001]);
        for (i, &v) in valid.iter().enumerate() {
            assert_eq!(valid_bit(&mask, i), v, "bit {i}");
        }
        assert!((0..20).all(|i| valid_bit(&[], i)));
    }

    #[test]
    fn control_frames_are_read_and_errors_name_the_field() {
        let mut p = [Vec3::ZERO; 2];
        let mut v = [false; 2];
        let f = frame(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], vec![]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(0));
        assert_eq!(p, [Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)]);
        assert_eq!(v, [true, true]);
        // An occluded point may carry NaN.
        let f = frame(vec![f32::NAN, 0.0, 0.0, 4.0, 5.0, 6.0], vec![0b10]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(1));
        assert_eq!(v, [false, true]);
        // Errors name the field, and leave the buffers alone.
        let f = frame(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], vec![0b11]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(0));
        let before = (p, v);
        let e = read_control_frame(&frame(vec![1.0; 5], vec![]), &mut p, &mut v).unwrap_err();
        assert_eq!(e.field, "positions");
        assert!(e.message.contains("5 values, expected 6"), "{e}");
        assert!(
            e.to_string()
                .starts_with("ControlFrame.positions: 5 values, expected 6"),
            "{e}"
        );
        let e = read_control_frame(
            &frame(vec![0.0, 0.0, 0.0, 1.0, f32::INFINITY, 0.0], vec![]),
            &mut p,
            &mut v,
        )
        .unwrap_err();
        assert_eq!(e.field, "positions[1]");
        let e = read_control_frame(&frame(vec![0.0; 6], vec![1, 1]), &mut p, &mut v).unwrap_err();
        assert_eq!(e.field, "valid");
        assert_eq!((p, v), before);
        let status: tonic::Status = e.into();
        assert_eq!(status.code(), tonic::Code::InvalidArgument);
        assert!(status.message().starts_with("ControlFrame.valid: 2 bytes"));
    }

    #[test]
    fn control_frames_for_the_wire_read_back() {
        let points = [
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::NAN,
            Vec3::new(-1.0, 0.5, 9.0),
        ];
        let f = control_frame("r", 7, 11, &points, &[true, false, true]);
        assert_eq!((f.room.as_str(), f.seq, f.capture_time_us), ("r", 7, 11));
        assert_eq!(f.positions, [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, -1.0, 0.5, 9.0]);
        let (mut p, mut v) = ([Vec3::ZERO; 3], [true; 3]);
        assert_eq!(read_control_frame(&f, &mut p, &mut v), Ok(1));
        assert_eq!(v, [true, false, true]);
        assert_eq!((p[0], p[2]), (points[0], points[2]));
        // All valid: no mask at all.
        assert!(
            control_frame("r", 0, 0, &points[..1], &[true])
                .valid
                .is_empty()
        );
    }
}
