//! The codec's frame decoder (`core::codec::FrameDecoder`) on a sequence of frames: the first
//! two bytes give the vertex count, then frames each prefixed by a little-endian `u16` length.
//! Keyframes and deltas in any order, truncated, with any header.
#![no_main]
use crease_core::codec::FrameDecoder;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((count, mut rest)) = data.split_first_chunk::<2>() else {
        return;
    };
    let vertex_count = usize::from(u16::from_le_bytes(*count));
    let mut decoder = FrameDecoder::new(vertex_count);
    while let Some((len, tail)) = rest.split_first_chunk::<2>() {
        let len = usize::from(u16::from_le_bytes(*len)).min(tail.len());
        let (frame, tail) = tail.split_at(len);
        rest = tail;
        if decoder.decode(frame).is_ok() {
            assert_eq!(decoder.lanes().len(), vertex_count);
        }
    }
});
