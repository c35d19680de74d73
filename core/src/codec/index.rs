//! Topology: triangle lists through meshopt's index codec (version 1), sent once at the start
//! of a subscription. The counts travel beside the bytes (in the subscription's first message).
//!
//! The round trip keeps the triangle order and each triangle's winding, but meshopt's encoder may
//! start a triangle at another corner (`[a, b, c]` can come back as `[b, c, a]`): it rotates
//! triangles to match edges it has seen, which is where its compression comes from. Renderers do
//! not care; code that compares triangle lists should compare rotations.

use super::{CodecError, meshopt_code};

/// The first byte of a meshopt index buffer of codec version 1 (`0xE0 | version`).
const MESHOPT_INDEX_V1: u8 = 0xE1;

/// The smallest encoded size meshopt accepts for `triangles` triangles: a header byte, one code
/// byte per triangle, and a 16-byte table.
fn min_encoded_len(triangles: usize) -> usize {
    triangles.saturating_add(17)
}

/// Encodes `triangles` (indices into `vertex_count` vertices) with meshopt's index codec into
/// `out` (cleared first). Compresses best after vertex-cache optimisation.
///
/// # Errors
/// [`CodecError::IndexOutOfRange`] for an index `>= vertex_count` (checked first: meshopt sizes
/// its output by the vertex count).
pub fn encode_indices(
    triangles: &[[u32; 3]],
    vertex_count: usize,
    out: &mut Vec<u8>,
) -> Result<(), CodecError> {
    for (t, tri) in triangles.iter().enumerate() {
        if let Some(&index) = tri.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(CodecError::IndexOutOfRange {
                triangle: t,
                index,
                vertex_count,
            });
        }
    }
    let bytes = meshopt::encode_index_buffer(bytemuck::cast_slice(triangles), vertex_count)
        .map_err(|_| CodecError::EncoderFailed("index buffer"))?;
    // meshopt 1.3 writes index codec version 1 by default; its setter is `unsafe`, so check.
    if bytes.first() != Some(&MESHOPT_INDEX_V1) {
        return Err(CodecError::EncoderFailed("index buffer"));
    }
    out.clear();
    out.extend_from_slice(&bytes);
    Ok(())
}

/// `triangle` turned left `k` times (`[b, c, a]` for `k = 1`): the same triangle, same winding.
fn turn_left(t: [u32; 3], k: u8) -> [u32; 3] {
    let k = usize::from(k % 3);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// The corner turns that bring `decoded` (what [`decode_indices`] gave back of `sent`) back to
/// `sent`: per triangle `k` in `0..3` with `decoded` turned left `k` times equal to `sent`,
/// four per byte, low bits first (the palette header's `triangle_turns`, issue 41: Loop's
/// vertex numbering depends on each triangle's first corner). `None` when a triangle is not a
/// rotation of the one sent.
pub fn corner_turns(sent: &[[u32; 3]], decoded: &[[u32; 3]]) -> Option<Vec<u8>> {
    if sent.len() != decoded.len() {
        return None;
    }
    let mut out = vec![0u8; sent.len().div_ceil(4)];
    for (t, (s, d)) in sent.iter().zip(decoded).enumerate() {
        let k = (0..3u8).find(|&k| turn_left(*d, k) == *s)?;
        out[t / 4] |= k << (2 * (t % 4));
    }
    Some(out)
}

/// Turns each of `triangles` left by its entry of `turns` ([`corner_turns`]).
///
/// # Errors
/// [`CodecError::Length`] when `turns` is not `ceil(triangles / 4)` bytes, and
/// [`CodecError::CornerTurn`] for an entry of 3.
pub fn apply_corner_turns(triangles: &mut [[u32; 3]], turns: &[u8]) -> Result<(), CodecError> {
    if turns.len() != triangles.len().div_ceil(4) {
        return Err(CodecError::Length {
            what: "triangle corner turns (bytes)",
            expected: triangles.len().div_ceil(4),
            found: turns.len(),
        });
    }
    for (t, tri) in triangles.iter_mut().enumerate() {
        let k = (turns[t / 4] >> (2 * (t % 4))) & 3;
        if k == 3 {
            return Err(CodecError::CornerTurn { triangle: t });
        }
        *tri = turn_left(*tri, k);
    }
    Ok(())
}

/// A spatial streaming order of `positions`: `order[i]` is the vertex to stream `i`-th, so that
/// vertices near in space are near in the buffer (meshopt's `spatial_sort_remap`, a Morton-order
/// sort). meshopt's vertex codec predicts each vertex from the one before it, so frames in this
/// order are smaller: 7-9% on the horse gallop (BENCHMARKS.md, "Frame codec"). Non-finite
/// positions are sorted as if at the origin.
pub fn spatial_order(positions: &[glam::Vec3]) -> Vec<u32> {
    let flat: Vec<f32> = positions
        .iter()
        .flat_map(|p| {
            let p = if p.is_finite() { *p } else { glam::Vec3::ZERO };
            p.to_array()
        })
        .collect();
    let Ok(adapter) = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&flat), 12, 0) else {
        return (0..positions.len() as u32).collect();
    };
    // remap[old] = new; the order is its inverse.
    let remap = meshopt::spatial_sort_remap(&adapter);
    let mut order = vec![0u32; positions.len()];
    for (old, &new) in remap.iter().enumerate() {
        order[new as usize] = old as u32;
    }
    order
}

/// Decodes `triangle_count` triangles from meshopt's index codec into `out` (cleared first; left
/// empty on error) and checks every index is below `vertex_count`. Triangles may come back
/// rotated (see the module docs). Never panics; memory is bounded by the input's
/// length (meshopt needs at least one byte per triangle).
///
/// # Errors
/// [`CodecError::IndexTruncated`], [`CodecError::IndexVersion`], [`CodecError::IndexCorrupt`],
/// [`CodecError::IndexOutOfRange`].
pub fn decode_indices(
    bytes: &[u8],
    triangle_count: usize,
    vertex_count: usize,
    out: &mut Vec<[u32; 3]>,
) -> Result<(), CodecError> {
    let needed = min_encoded_len(triangle_count);
    if bytes.len() < needed {
        return Err(CodecError::IndexTruncated {
            len: bytes.len(),
            triangles: triangle_count,
            needed,
        });
    }
    if bytes[0] != MESHOPT_INDEX_V1 {
        return Err(CodecError::IndexVersion(bytes[0]));
    }
    // triangle_count < bytes.len(), so the product cannot overflow.
    let flat = meshopt::decode_index_buffer::<u32>(bytes, triangle_count * 3)
        .map_err(|e| CodecError::IndexCorrupt(meshopt_code(e)))?;
    out.clear();
    out.extend(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
    for (t, tri) in out.iter().enumerate() {
        if let Some(&index) = tri.iter().find(|&&i| i as usize >= vertex_count) {
            out.clear();
            return Err(CodecError::IndexOutOfRange {
                triangle: t,
                index,
                vertex_count,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod order_tests {
    use super::spatial_order;
    use glam::Vec3;

    #[test]
    fn spatial_order_is_a_permutation_that_groups_neighbours() {
        // Points on two far-apart clusters, interleaved: a spatial order must not interleave them.
        let positions: Vec<Vec3> = (0..64)
            .map(|i| {
                let cluster = if i % 2 == 0 { 0.0 } else { 100.0 };
                Vec3::new(cluster + (i / 2) as f32 * 0.01, 0.0, 0.0)
            })
            .collect();
        let order = spatial_order(&positions);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..64).collect::<Vec<u32>>());
        let switches = order
            .windows(2)
            .filter(|w| (w[0] % 2) != (w[1] % 2))
            .count();
        assert_eq!(switches, 1, "clusters interleaved: {order:?}");
        // Non-finite positions do not break it.
        let order = spatial_order(&[Vec3::NAN, Vec3::ONE, Vec3::ZERO]);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, [0, 1, 2]);
    }
}

#[cfg(test)]
mod turn_tests {
    use super::*;

    #[test]
    fn corner_turns_bring_the_decoded_triangles_back_to_the_sent_ones() {
        // A strip of triangles meshopt is free to rotate.
        let sent: Vec<[u32; 3]> = (0..40u32)
            .map(|i| {
                if i % 2 == 0 {
                    [i, i + 1, i + 2]
                } else {
                    [i + 1, i, i + 2]
                }
            })
            .collect();
        let mut bytes = Vec::new();
        encode_indices(&sent, 42, &mut bytes).unwrap();
        let mut decoded = Vec::new();
        decode_indices(&bytes, sent.len(), 42, &mut decoded).unwrap();
        let turns = corner_turns(&sent, &decoded).unwrap();
        assert_eq!(turns.len(), 10);
        apply_corner_turns(&mut decoded, &turns).unwrap();
        assert_eq!(decoded, sent);
        // By hand: [b, c, a] needs two left turns to be [a, b, c].
        assert_eq!(corner_turns(&[[1, 2, 3]], &[[2, 3, 1]]).unwrap(), vec![2]);
        assert_eq!(
            corner_turns(&[[1, 2, 3]], &[[1, 3, 2]]),
            None,
            "winding differs"
        );
        let mut t = vec![[2, 3, 1]];
        assert_eq!(
            apply_corner_turns(&mut t, &[3]),
            Err(CodecError::CornerTurn { triangle: 0 })
        );
        assert!(matches!(
            apply_corner_turns(&mut t, &[]),
            Err(CodecError::Length { .. })
        ));
    }
}
