//! The index-buffer decoder (`core::codec::decode_indices`): counts from the first bytes, the
//! rest the encoded buffer. Every decoded index must be in range.
#![no_main]
use crease_core::codec::decode_indices;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((counts, bytes)) = data.split_first_chunk::<4>() else {
        return;
    };
    let triangles = usize::from(u16::from_le_bytes([counts[0], counts[1]]));
    let vertices = usize::from(u16::from_le_bytes([counts[2], counts[3]]));
    let mut out = Vec::new();
    if decode_indices(bytes, triangles, vertices, &mut out).is_ok() {
        assert_eq!(out.len(), triangles);
        assert!(out.iter().flatten().all(|&i| (i as usize) < vertices));
    }
});
