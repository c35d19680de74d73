//! Control-frame files (CSV and JSON, `crease synth`/`stream`/`bench-net` inputs): the first
//! byte picks the format and the control-point count.
#![no_main]
use crease_remote::control_file::{parse_csv, parse_json};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let text = String::from_utf8_lossy(bytes);
    let count = usize::from(pick >> 1) % 16 + 1;
    let frames = if pick & 1 == 0 {
        parse_csv(&text, count)
    } else {
        parse_json(&text, count)
    };
    if let Ok(frames) = frames {
        for f in frames {
            assert_eq!(f.positions.len(), count);
            assert_eq!(f.valid.len(), count);
        }
    }
});
