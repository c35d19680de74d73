//! C3D point data through the `c3dio` crate.
//!
//! Labels come from `POINT:LABELS` (trimmed; a subject prefix such as `Human4:` stays, and
//! [`Recording::marker`] finds a label without it), the rate from the header, the unit from
//! `POINT:UNITS`. A sample is invalid when its residual word is negative (the C3D convention
//! for "not seen"), when it is exactly `0 0 0` (how some writers mark gaps), or when it is not
//! finite.
//!
//! `c3dio` scales a float file's residual by the (negative) `POINT:SCALE`, which flips its sign;
//! validity therefore looks at the residual's sign relative to the scale, i.e. at the residual
//! as stored in the file. The header is checked before `c3dio` sees the bytes (frame range and
//! data size against the file's length), so a corrupted file is an error, not an allocation of
//! whatever size a broken header claims.

use std::path::Path;

use glam::Vec3;

use super::{MocapError, Recording};

/// Reads a C3D file (module docs).
pub fn read(path: &Path) -> Result<Recording, MocapError> {
    let bytes = std::fs::read(path).map_err(|source| MocapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(path, &bytes)
}

/// Header fields, read by hand to vet the file before parsing it.
fn check_header(path: &Path, bytes: &[u8]) -> Result<(), MocapError> {
    let bad = |m: String| MocapError::format(path, m);
    if bytes.len() < 1024 {
        return Err(bad(format!(
            "{} bytes: a C3D file has at least a 512-byte header and a parameter block",
            bytes.len()
        )));
    }
    if bytes[1] != 0x50 {
        return Err(bad(format!(
            "header byte 2 is {:#04x}, expected 0x50 (not a C3D file)",
            bytes[1]
        )));
    }
    // The processor type sits in byte 4 of the first parameter block: 84 Intel, 85 DEC,
    // 86 MIPS (big-endian).
    let param_block = bytes[0] as usize;
    let proc_at = (param_block.max(1) - 1) * 512 + 3;
    let processor = *bytes.get(proc_at).ok_or_else(|| {
        bad(format!(
            "parameter block {param_block} lies past the end of the file"
        ))
    })?;
    let big = match processor {
        84 | 85 => false,
        86 => true,
        p => {
            return Err(bad(format!(
                "processor type {p}, expected 84 (Intel), 85 (DEC) or 86 (MIPS)"
            )));
        }
    };
    let word = |i: usize| -> u16 {
        let b = [bytes[2 * i], bytes[2 * i + 1]];
        if big {
            u16::from_be_bytes(b)
        } else {
            u16::from_le_bytes(b)
        }
    };
    let (points, first, last) = (word(1) as usize, word(3) as usize, word(4) as usize);
    if last < first {
        return Err(bad(format!(
            "header frame range {first}..={last} is empty or reversed"
        )));
    }
    let scale_bytes = [bytes[12], bytes[13], bytes[14], bytes[15]];
    let scale = if big {
        f32::from_be_bytes(scale_bytes)
    } else {
        f32::from_le_bytes(scale_bytes)
    };
    let per_point = if scale <= 0.0 { 16 } else { 8 };
    let analog_words = word(2) as usize;
    let data_block = word(8) as usize;
    let frame_bytes = points * per_point + analog_words * if scale <= 0.0 { 4 } else { 2 };
    let need = (data_block.max(1) - 1) * 512 + (last - first + 1) * frame_bytes;
    if need > bytes.len() {
        return Err(bad(format!(
            "header promises {} frames of {points} points from block {data_block} ({need} bytes), the file has {} bytes (truncated?)",
            last - first + 1,
            bytes.len()
        )));
    }
    Ok(())
}

/// Parses C3D bytes; `path` only names the source in errors.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Recording, MocapError> {
    check_header(path, bytes)?;
    // c3dio indexes slices it has not always bounds-checked; a panic there is a bad file.
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        c3dio::C3d::from_bytes(bytes).map_err(|e| e.to_string())
    }))
    .map_err(|_| MocapError::format(path, "malformed C3D (the c3dio parser gave up)"))?
    .map_err(|e| MocapError::format(path, format!("C3D: {e}")))?;
    let pts = &parsed.points;
    let (frames, markers) = (pts.rows(), pts.cols());
    let mut names: Vec<String> = pts.labels.iter().map(|l| l.trim().to_owned()).collect();
    if names.len() < markers {
        // Unlabelled points get C3D's customary names.
        names.extend((names.len()..markers).map(|i| format!("M{:03}", i + 1)));
    }
    names.truncate(markers);
    let rate = f64::from(pts.frame_rate);
    if !(rate.is_finite() && rate > 0.0) {
        return Err(MocapError::format(
            path,
            format!("POINT:RATE is {rate}, expected a positive frame rate"),
        ));
    }
    let units: String = pts.units.iter().collect::<String>().trim().to_owned();
    let scale_sign = if pts.scale_factor < 0.0 { -1.0 } else { 1.0 };
    let mut positions = Vec::with_capacity(frames * markers);
    let mut valid = Vec::with_capacity(frames * markers);
    for f in 0..frames {
        for m in 0..markers {
            let s = &pts[(f, m)];
            let p = Vec3::from(s.point);
            let seen = s.residual * scale_sign >= 0.0;
            valid.push(seen && p.is_finite() && p != Vec3::ZERO);
            positions.push(p);
        }
    }
    Ok(Recording::new(
        names,
        rate,
        if units.is_empty() { "mm".into() } else { units },
        positions,
        valid,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_garbage_and_truncation_without_panicking() {
        let p = Path::new("bad.c3d");
        assert!(
            parse(p, &[0u8; 10])
                .unwrap_err()
                .to_string()
                .contains("at least a 512-byte header")
        );
        let mut b = vec![0u8; 2048];
        assert!(
            parse(p, &b)
                .unwrap_err()
                .to_string()
                .contains("not a C3D file")
        );
        // A plausible header claiming 1000 frames of 50 points in a 2 KiB file.
        b[0] = 2;
        b[1] = 0x50;
        b[512 + 3] = 84;
        b[2..4].copy_from_slice(&50u16.to_le_bytes());
        b[6..8].copy_from_slice(&1u16.to_le_bytes());
        b[8..10].copy_from_slice(&1000u16.to_le_bytes());
        b[12..16].copy_from_slice(&(-0.1f32).to_le_bytes());
        b[16..18].copy_from_slice(&3u16.to_le_bytes());
        let e = parse(p, &b).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        b[6..8].copy_from_slice(&5u16.to_le_bytes());
        b[8..10].copy_from_slice(&2u16.to_le_bytes());
        let e = parse(p, &b).unwrap_err().to_string();
        assert!(e.contains("empty or reversed"), "{e}");
    }
}
