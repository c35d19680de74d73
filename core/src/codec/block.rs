//! Arrays that are not frames through meshopt's vertex codec (version 1): the palette header's
//! detail values (issue 41), as 4-byte "vertices" whose neighbours are similar. The encoder runs
//! once per model; the decoders are the frame decoders' (`meshopt_decodeVertexBuffer`, the
//! viewer's and the Python package's).

use super::CodecError;
use super::frame::MESHOPT_VERTEX_V1;
use super::meshopt_code;

/// meshopt's strongest vertex compression level: the header is encoded once per model.
const LEVEL: i32 = 3;

/// `values` through meshopt's vertex codec, version 1.
///
/// # Errors
/// [`CodecError::EncoderFailed`] when meshopt produces nothing (a bug).
pub fn encode_vertex_block(values: &[[u8; 4]]) -> Result<Vec<u8>, CodecError> {
    let out = meshopt::encode_vertex_buffer_level(values, LEVEL, Some(1))
        .map_err(|_| CodecError::EncoderFailed("vertex block"))?;
    if out.first() != Some(&MESHOPT_VERTEX_V1) {
        return Err(CodecError::EncoderFailed("vertex block"));
    }
    Ok(out)
}

/// `count` 4-byte values back from [`encode_vertex_block`]'s bytes.
///
/// # Errors
/// [`CodecError::PayloadEmpty`], [`CodecError::PayloadVersion`] or
/// [`CodecError::PayloadCorrupt`] for bytes that are not such a block of `count` values.
pub fn decode_vertex_block(data: &[u8], count: usize) -> Result<Vec<[u8; 4]>, CodecError> {
    decode_vertex_buffer_v1(data, count)
}

/// `count` vertices of type `T` from a meshopt vertex buffer of codec version 1 (a frame's
/// payload, a block): its header byte checked first, then meshopt's own checks.
pub(super) fn decode_vertex_buffer_v1<T: Clone + Default>(
    data: &[u8],
    count: usize,
) -> Result<Vec<T>, CodecError> {
    match data.first() {
        None => return Err(CodecError::PayloadEmpty),
        Some(&b) if b != MESHOPT_VERTEX_V1 => return Err(CodecError::PayloadVersion(b)),
        Some(_) => {}
    }
    meshopt::decode_vertex_buffer::<T>(data, count)
        .map_err(|e| CodecError::PayloadCorrupt(meshopt_code(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_block_round_trips_and_refuses_what_is_not_one() {
        let values: Vec<[u8; 4]> = (0..1000u32)
            .map(|i| ((i * 7) as i16 - 3000).to_le_bytes())
            .map(|[a, b]| [a, b, b, a])
            .collect();
        let data = encode_vertex_block(&values).unwrap();
        assert_eq!(decode_vertex_block(&data, values.len()).unwrap(), values);
        assert_eq!(decode_vertex_block(&[], 3), Err(CodecError::PayloadEmpty));
        assert_eq!(
            decode_vertex_block(&[0x42, 0, 0], 3),
            Err(CodecError::PayloadVersion(0x42))
        );
        assert!(matches!(
            decode_vertex_block(&data[..data.len() / 2], values.len()),
            Err(CodecError::PayloadCorrupt(_))
        ));
    }
}
