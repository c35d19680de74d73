//! A recorded mesh stream as a client reads it (`crease decode-stream`): length-prefixed
//! `MeshFrame` messages, the first a `Topology` (indices, vertex order, box) or a
//! `PaletteTopology` (skin, base triangles rebuilt into Loop steps, detail regressor), then
//! frames decoded in order (codec frames of vertices, or palette lanes synthesised into a mesh).
#![no_main]
use crease_cli::commands::decode_stream::read_capture;
use crease_remote::mesh_stream::StreamReader;
use crease_proto::v1;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(messages) = read_capture(data) else {
        return;
    };
    let Some((first, rest)) = messages.split_first() else {
        return;
    };
    let Ok(mut reader) = StreamReader::new(first) else {
        return;
    };
    let mut out = Vec::new();
    for msg in rest {
        if let Some(v1::mesh_frame::Body::Frame(f)) = &msg.body {
            if reader.decode(&f.data).is_ok() {
                reader.model_positions(&mut out);
                assert_eq!(out.len(), reader.vertex_count());
            }
        }
    }
});
