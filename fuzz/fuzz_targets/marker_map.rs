//! Marker maps (TOML, `crease_mocap::map::MarkerMap`), as a room's `Retarget.map_toml`: parsed,
//! then bound to a capture's marker names and a model's control points as the server does.
#![no_main]
use crease_mocap::Recording;
use crease_mocap::map::MarkerMap;
use libfuzzer_sys::fuzz_target;
use std::path::Path;

/// Capture markers of the seeds (glove13, the ART sample, hand-made); control points are the
/// same names from the fourth on.
const NAMES: [&str; 14] = [
    "a",
    "b",
    "c",
    "hand_top",
    "hand_left",
    "hand_right",
    "thumb_tip",
    "thumb_middle",
    "index_tip",
    "RHAN",
    "RMFI",
    "RTOU",
    "c0",
    "c1",
];

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(map) = MarkerMap::parse(Path::new("fuzz.toml"), text) else {
        return;
    };
    let names: Vec<String> = NAMES.iter().map(|s| (*s).to_owned()).collect();
    let recording = Recording::new(names, 0.0, "m".to_owned(), Vec::new(), Vec::new());
    let controls: Vec<String> = NAMES[3..].iter().map(|s| (*s).to_owned()).collect();
    let _ = map.bind(&recording, &controls);
});
