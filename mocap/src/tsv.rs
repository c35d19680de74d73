//! Qualisys Track Manager's TSV export of 3D marker data.
//!
//! ```text
//! NO_OF_FRAMES    6000            header: KEY<TAB>value(s), one per line
//! NO_OF_MARKERS   21
//! FREQUENCY       100
//! MARKER_NAMES    hand_top  hand_left  ...
//! Frame  Time  hand_top X  hand_top Y  hand_top Z  ...       optional column header
//! 1      0.00000  110.406  135.075  460.584  ...             data, millimetres
//! ```
//!
//! Required keys: `NO_OF_FRAMES`, `NO_OF_MARKERS`, `FREQUENCY`, `MARKER_NAMES`. Data rows hold
//! `x y z` per marker, after optional `Frame` and `Time` columns (named by the column header,
//! or inferred from the column count when there is none). A gap is written as `nan` (or an
//! empty field), and by older exports as `0 0 0`; both read as invalid. QTM writes millimetres.

use std::path::Path;

use glam::Vec3;

use super::{MocapError, Recording};

/// Reads a Qualisys TSV file (module docs).
pub fn read(path: &Path) -> Result<Recording, MocapError> {
    let text = std::fs::read_to_string(path).map_err(|source| MocapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(path, &text)
}

/// Parses TSV text; `path` only names the source in errors.
pub fn parse(path: &Path, text: &str) -> Result<Recording, MocapError> {
    let err = |line: usize, msg: String| MocapError::format(path, format!("line {line}: {msg}"));
    let mut frames: Option<usize> = None;
    let mut markers: Option<usize> = None;
    let mut rate: Option<f64> = None;
    let mut names: Option<Vec<String>> = None;
    let mut lines = text.lines().enumerate().peekable();
    // Header: KEY<TAB>values until the first line that starts with a number or "Frame".
    while let Some(&(i, line)) = lines.peek() {
        let mut fields = line.trim_end_matches('\r').split('\t');
        let key = fields.next().unwrap_or("").trim();
        if key.is_empty() && line.trim().is_empty() {
            lines.next();
            continue;
        }
        if key.parse::<f64>().is_ok() || key == "Frame" {
            break;
        }
        let values: Vec<&str> = fields.collect();
        let first = || values.first().map(|v| v.trim()).unwrap_or("");
        let number = |what: &str| -> Result<f64, MocapError> {
            first().parse::<f64>().map_err(|_| {
                err(
                    i + 1,
                    format!("{what}: expected a number, got {:?}", first()),
                )
            })
        };
        match key {
            "NO_OF_FRAMES" => frames = Some(number(key)? as usize),
            "NO_OF_MARKERS" => markers = Some(number(key)? as usize),
            "FREQUENCY" => {
                let r = number(key)?;
                if !(r.is_finite() && r > 0.0) {
                    return Err(err(
                        i + 1,
                        format!("FREQUENCY: expected a positive rate, got {r}"),
                    ));
                }
                rate = Some(r);
            }
            "MARKER_NAMES" => {
                names = Some(
                    values
                        .iter()
                        .map(|v| v.trim().to_owned())
                        .filter(|v| !v.is_empty())
                        .collect(),
                );
            }
            "DATA_INCLUDED" if first() != "3D" => {
                return Err(err(
                    i + 1,
                    format!(
                        "DATA_INCLUDED: expected 3D marker data, got {:?} (export 3D data from QTM)",
                        first()
                    ),
                ));
            }
            _ => {}
        }
        lines.next();
    }
    let missing = |key: &str| MocapError::format(path, format!("header has no {key} line"));
    let frames = frames.ok_or_else(|| missing("NO_OF_FRAMES"))?;
    let markers = markers.ok_or_else(|| missing("NO_OF_MARKERS"))?;
    let rate = rate.ok_or_else(|| missing("FREQUENCY"))?;
    let names = names.ok_or_else(|| missing("MARKER_NAMES"))?;
    if names.len() != markers {
        return Err(MocapError::format(
            path,
            format!(
                "MARKER_NAMES lists {} names, NO_OF_MARKERS says {markers}",
                names.len()
            ),
        ));
    }
    // Optional column header: where the first X column is.
    let mut lead: Option<usize> = None;
    if let Some(&(i, line)) = lines.peek()
        && line.starts_with("Frame")
    {
        let cols: Vec<&str> = line.trim_end_matches('\r').split('\t').collect();
        let want = format!("{} X", names.first().map_or("", String::as_str));
        let at = cols.iter().position(|c| c.trim() == want).ok_or_else(|| {
            err(
                i + 1,
                format!("column header has no {want:?} column for the first marker"),
            )
        })?;
        lead = Some(at);
        lines.next();
    }
    // The header's counts size nothing until the rows confirm them: a corrupted NO_OF_FRAMES
    // must not become an allocation. A sample takes at least 6 bytes of text (`0\t0\t0\t`).
    let capacity = frames.saturating_mul(markers).min(text.len() / 6);
    let mut positions = Vec::with_capacity(capacity);
    let mut valid = Vec::with_capacity(capacity);
    let mut rows = 0usize;
    for (i, line) in lines {
        let line = line.trim_end_matches('\r');
        if line.trim().is_empty() {
            continue;
        }
        let cols: Vec<&str> = line.split('\t').collect();
        let lead = match lead {
            Some(l) => l,
            None => match cols.len().checked_sub(3 * markers) {
                Some(l @ 0..=2) => l,
                _ => {
                    return Err(err(
                        i + 1,
                        format!(
                            "{} columns, expected {} (x, y, z of {markers} markers) after up to 2 leading columns",
                            cols.len(),
                            3 * markers
                        ),
                    ));
                }
            },
        };
        if cols.len() < lead + 3 * markers {
            return Err(err(
                i + 1,
                format!(
                    "{} columns, expected {} ({lead} leading + x, y, z of {markers} markers)",
                    cols.len(),
                    lead + 3 * markers
                ),
            ));
        }
        for m in 0..markers {
            let mut xyz = [0.0f32; 3];
            let mut ok = true;
            for (k, v) in xyz.iter_mut().enumerate() {
                let field = cols[lead + 3 * m + k].trim();
                if field.is_empty() || field.eq_ignore_ascii_case("nan") {
                    ok = false;
                    continue;
                }
                *v = field.parse::<f32>().map_err(|_| {
                    err(
                        i + 1,
                        format!(
                            "{} {}: expected a number or nan, got {field:?}",
                            names[m],
                            ["X", "Y", "Z"][k]
                        ),
                    )
                })?;
            }
            let p = Vec3::from(xyz);
            // Older exports write a gap as exactly 0 0 0.
            let ok = ok && p.is_finite() && p != Vec3::ZERO;
            positions.push(p);
            valid.push(ok);
        }
        rows += 1;
    }
    if rows != frames {
        return Err(MocapError::format(
            path,
            format!("NO_OF_FRAMES says {frames}, the file has {rows} data rows (truncated?)"),
        ));
    }
    Ok(Recording::new(names, rate, "mm", positions, valid))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "NO_OF_FRAMES\t2\nNO_OF_CAMERAS\t7\nNO_OF_MARKERS\t2\nFREQUENCY\t50\n\
        DATA_INCLUDED\t3D\nMARKER_NAMES\ta\tb\n\
        Frame\tTime\ta X\ta Y\ta Z\tb X\tb Y\tb Z\n\
        1\t0.0\t1\t2\t3\tnan\tnan\tnan\n\
        2\t0.02\t4\t5\t6\t0.000\t0.000\t0.000\n";

    #[test]
    fn parses_header_columns_and_gaps() {
        let r = parse(Path::new("s.tsv"), SMALL).unwrap();
        assert_eq!(r.names, ["a", "b"]);
        assert_eq!(r.rate_hz, 50.0);
        assert_eq!(r.frame_count(), 2);
        assert_eq!(r.frame(1).positions[0], Vec3::new(4.0, 5.0, 6.0));
        assert_eq!(r.frame(0).valid, [true, false]);
        assert_eq!(r.frame(1).valid, [true, false], "0 0 0 is a gap");
    }

    #[test]
    fn rows_without_column_header() {
        let text = "NO_OF_FRAMES\t1\nNO_OF_MARKERS\t1\nFREQUENCY\t100\nMARKER_NAMES\tm\n7\t8\t9\n";
        let r = parse(Path::new("n.tsv"), text).unwrap();
        assert_eq!(r.frame(0).positions[0], Vec3::new(7.0, 8.0, 9.0));
    }

    #[test]
    fn errors_name_line_and_field() {
        let e = |t: &str| parse(Path::new("x.tsv"), t).unwrap_err().to_string();
        assert!(
            e(&SMALL.replace("\t5\t6", "\tfive\t6"))
                .contains("line 9: a Y: expected a number or nan, got \"five\"")
        );
        assert!(
            e(&SMALL.replace("NO_OF_FRAMES\t2", "NO_OF_FRAMES\t3"))
                .contains("NO_OF_FRAMES says 3, the file has 2")
        );
        assert!(
            e(&SMALL.replace("MARKER_NAMES\ta\tb", "MARKER_NAMES\ta"))
                .contains("lists 1 names, NO_OF_MARKERS says 2")
        );
        assert!(e(&SMALL.replace("FREQUENCY\t50\n", "")).contains("no FREQUENCY line"));
        assert!(
            e(&SMALL.replace("FREQUENCY\t50", "FREQUENCY\t-1"))
                .contains("line 4: FREQUENCY: expected a positive rate")
        );
        assert!(
            e(&SMALL.replace("\t4\t5\t6\t0.000\t0.000\t0.000", "\t4\t5"))
                .contains("line 9: 4 columns, expected 8")
        );
        assert!(
            e(&SMALL.replace("DATA_INCLUDED\t3D", "DATA_INCLUDED\t6D"))
                .contains("expected 3D marker data")
        );
    }
}
