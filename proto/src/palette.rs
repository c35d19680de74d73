//! The palette stream a subscriber gets with `Encoding::Palette` (issue 18): its first message,
//! `PaletteTopology`, built from a [`PaletteHeader`] by [`palette_topology_message`] and read
//! back by [`read_palette_topology`]; its frames are `Frame`s whose data is a palette frame
//! (`crease_core::codec::palette`). The byte layouts are those `crease.proto` documents.

use crease_core::codec::palette::{PALETTE_VERSION, PaletteDetail, PaletteHeader, PaletteSkin};
use crease_core::codec::{
    CodecError, apply_corner_turns, corner_turns, decode_indices, decode_vertex_block,
    encode_indices, encode_vertex_block,
};
use crease_core::glam::Vec3;
use crease_core::mesh::subdivision::{MAX_LEVELS, subdivided_count};
use prost::bytes::Bytes;

use crate::convert::{Level, box3};
use crate::errors::WireError;
use crate::v1;

/// What a palette stream's first message says (see `PaletteTopology` in `crease.proto`).
#[derive(Clone, Copy, Debug)]
pub struct PaletteParts<'a> {
    /// The model's name.
    pub model: &'a str,
    /// The stream's level.
    pub level: Level,
    /// The box of the model's poses.
    pub bounds: (Vec3, Vec3),
    /// The header.
    pub header: &'a PaletteHeader,
}

/// A palette stream's first message, read back (see [`read_palette_topology`]).
#[derive(Clone, Debug, PartialEq)]
pub struct StreamPalette {
    /// The model's name.
    pub model: String,
    /// The stream's level.
    pub level: Level,
    /// The box of the model's poses.
    pub bounds: (Vec3, Vec3),
    /// The header, [validated](PaletteHeader::validate).
    pub header: PaletteHeader,
}

fn le_bytes<T: Copy, const N: usize>(values: &[T], to: impl Fn(T) -> [u8; N]) -> Bytes {
    let mut out = Vec::with_capacity(values.len() * N);
    for &v in values {
        out.extend_from_slice(&to(v));
    }
    Bytes::from(out)
}

/// Stored detail values per meshopt block (`PaletteTopology.detail_blocks`).
const BLOCK_VALUES: usize = 2;

/// The first message of a palette stream.
///
/// # Errors
/// The index codec's, if a triangle indexes past the base mesh; meshopt's, if it refuses the
/// detail values.
pub fn palette_topology_message(p: PaletteParts<'_>) -> Result<v1::MeshFrame, CodecError> {
    let h = p.header;
    let mut indices = Vec::new();
    encode_indices(&h.triangles, h.rest.len(), &mut indices)?;
    let narrow = h.bones <= 256;
    let skin_bones = if narrow {
        Bytes::from(h.skin.bones.iter().map(|&b| b as u8).collect::<Vec<u8>>())
    } else {
        le_bytes(&h.skin.bones, u16::to_le_bytes)
    };
    let rest: Vec<f32> = h.rest.iter().flat_map(|p| p.to_array()).collect();
    let (levels, examples, detail_step, detail_blocks, triangle_turns) = match &h.detail {
        Some(d) => {
            let mut decoded = Vec::new();
            decode_indices(&indices, h.triangles.len(), h.rest.len(), &mut decoded)?;
            let turns = corner_turns(&h.triangles, &decoded).ok_or(CodecError::EncoderFailed(
                "index buffer (a triangle came back changed)",
            ))?;
            (
                d.levels,
                d.examples as u32,
                d.quantum,
                detail_blocks(&d.rows, d.examples + 1)?,
                Bytes::from(turns),
            )
        }
        None => (0, 0, 0.0, Vec::new(), Bytes::new()),
    };
    Ok(v1::MeshFrame {
        body: Some(v1::mesh_frame::Body::PaletteTopology(v1::PaletteTopology {
            model: p.model.to_owned(),
            level: v1::Level::from(p.level) as i32,
            version: u32::from(PALETTE_VERSION),
            vertex_count: h.vertex_count() as u32,
            triangle_count: h.triangles.len() as u32,
            indices: Bytes::from(indices),
            bounds: Some(box3(p.bounds.0, p.bounds.1)),
            bones: h.bones as u32,
            base_vertices: h.rest.len() as u32,
            rest_positions: le_bytes(&rest, f32::to_le_bytes),
            influences: h.skin.influences as u32,
            skin_bones,
            skin_weights: le_bytes(&h.skin.weights, u16::to_le_bytes),
            examples,
            actor: String::new(),
            actor_index: 0,
            actor_count: 0,
            subdivision_levels: levels,
            detail_step,
            detail_blocks,
            triangle_turns,
        })),
    })
}

/// The detail values (`width` per row) as meshopt blocks of [`BLOCK_VALUES`] values per row
/// (the proto's `detail_blocks`): neighbouring vertices have similar values, and meshopt's
/// byte deltas pack small ones into a few bits.
fn detail_blocks(rows: &[i16], width: usize) -> Result<Vec<Bytes>, CodecError> {
    let count = rows.len() / width.max(1);
    let mut block = vec![[0u8; 4]; count];
    let mut out = Vec::with_capacity(width.div_ceil(BLOCK_VALUES));
    for first in (0..width).step_by(BLOCK_VALUES) {
        for (v, slot) in block.iter_mut().enumerate() {
            let row = &rows[v * width..(v + 1) * width];
            let [a0, a1] = row[first].to_le_bytes();
            let [b0, b1] = row.get(first + 1).copied().unwrap_or(0).to_le_bytes();
            *slot = [a0, a1, b0, b1];
        }
        out.push(Bytes::from(encode_vertex_block(&block)?));
    }
    Ok(out)
}

/// Reads `count` little-endian values of `N` bytes from field `field`.
fn read_le<T, const N: usize>(
    field: &str,
    bytes: &[u8],
    count: usize,
    from: impl Fn([u8; N]) -> T,
) -> Result<Vec<T>, WireError> {
    let expected = count.checked_mul(N);
    if expected != Some(bytes.len()) {
        return Err(WireError::new(
            "PaletteTopology",
            field,
            format!(
                "{} bytes, expected {} ({count} values of {N} bytes)",
                bytes.len(),
                expected.map_or_else(|| "too many".to_owned(), |e| e.to_string())
            ),
        ));
    }
    Ok(bytes
        .chunks_exact(N)
        .map(|c| from(c.try_into().expect("chunks of N")))
        .collect())
}

/// An index array stored as u8 when `narrow`, else u16.
fn read_narrow(
    field: &str,
    bytes: &[u8],
    count: usize,
    narrow: bool,
) -> Result<Vec<u16>, WireError> {
    if narrow {
        read_le(field, bytes, count, |[b]| u16::from(b))
    } else {
        read_le(field, bytes, count, u16::from_le_bytes)
    }
}

/// Reads a `PaletteTopology`: decodes every array, and checks that they fit each other
/// ([`PaletteHeader::validate`]) and the frame format version this build reads.
///
/// # Errors
/// [`WireError`] naming the field (a length, an index out of range, a non-finite value, an
/// unknown version).
pub fn read_palette_topology(t: &v1::PaletteTopology) -> Result<StreamPalette, WireError> {
    let err = |field: &str, message: String| WireError::new("PaletteTopology", field, message);
    if t.version != u32::from(PALETTE_VERSION) {
        return Err(err(
            "version",
            format!(
                "{}, this decoder reads palette frames of version {PALETTE_VERSION}",
                t.version
            ),
        ));
    }
    let level = Level::from_wire("PaletteTopology", t.level)?;
    let nb = t.base_vertices as usize;
    let k = t.influences as usize;
    if !(1..=8).contains(&k) {
        return Err(err("influences", format!("{k}, expected 1..=8")));
    }
    let rest = read_le(
        "rest_positions",
        &t.rest_positions,
        nb.saturating_mul(3),
        f32::from_le_bytes,
    )?;
    let slots = nb.saturating_mul(k);
    let skin = PaletteSkin {
        influences: k,
        bones: read_narrow("skin_bones", &t.skin_bones, slots, t.bones <= 256)?,
        weights: read_le("skin_weights", &t.skin_weights, slots, u16::from_le_bytes)?,
    };
    let nv = t.vertex_count as usize;
    let mut triangles = Vec::new();
    decode_indices(&t.indices, t.triangle_count as usize, nb, &mut triangles)
        .map_err(|e| err("indices", e.to_string()))?;
    let detail = match level {
        Level::Base => None,
        Level::Detail => {
            apply_corner_turns(&mut triangles, &t.triangle_turns)
                .map_err(|e| err("triangle_turns", e.to_string()))?;
            let n = t.examples as usize;
            let width = n.saturating_add(1);
            let blocks = width.div_ceil(BLOCK_VALUES);
            if t.detail_blocks.len() != blocks {
                return Err(err(
                    "detail_blocks",
                    format!(
                        "{} blocks, expected {blocks} ({width} values per row, {BLOCK_VALUES} per block)",
                        t.detail_blocks.len()
                    ),
                ));
            }
            let levels = t.subdivision_levels;
            if !(1..=MAX_LEVELS).contains(&levels) {
                return Err(err(
                    "subdivision_levels",
                    format!("{levels}, expected 1..={MAX_LEVELS} at the detail level"),
                ));
            }
            let expected = subdivided_count(nb, &triangles, levels);
            if expected != Some(nv) {
                return Err(err(
                    "vertex_count",
                    format!(
                        "{nv}, but {levels} Loop levels of the base mesh give {}",
                        expected.map_or_else(|| "no mesh".to_owned(), |v| v.to_string())
                    ),
                ));
            }
            let mut rows = vec![0i16; nv * width];
            for (j, data) in t.detail_blocks.iter().enumerate() {
                let block = decode_vertex_block(data, nv)
                    .map_err(|e| err(&format!("detail_blocks[{j}]"), e.to_string()))?;
                for (row, [a0, a1, b0, b1]) in rows.chunks_exact_mut(width).zip(block) {
                    row[j * BLOCK_VALUES] = i16::from_le_bytes([a0, a1]);
                    if let Some(second) = row.get_mut(j * BLOCK_VALUES + 1) {
                        *second = i16::from_le_bytes([b0, b1]);
                    }
                }
            }
            Some(
                PaletteDetail::rebuild(nb, &triangles, levels, n, rows, t.detail_step)
                    .map_err(|e| err("indices", e.to_string()))?,
            )
        }
    };
    let header = PaletteHeader {
        bones: t.bones as usize,
        rest: rest.chunks_exact(3).map(Vec3::from_slice).collect(),
        skin,
        triangles,
        detail,
    };
    if header.vertex_count() != nv {
        return Err(err(
            "vertex_count",
            format!("{nv}, the header's arrays give {}", header.vertex_count()),
        ));
    }
    header
        .validate()
        .map_err(|e| err("header", e.to_string()))?;
    let bounds = t
        .bounds
        .as_ref()
        .ok_or_else(|| err("bounds", "missing".into()))?;
    let v = |p: &Option<v1::Vec3>| p.as_ref().map_or(Vec3::ZERO, |p| Vec3::new(p.x, p.y, p.z));
    Ok(StreamPalette {
        model: t.model.clone(),
        level,
        bounds: (v(&bounds.min), v(&bounds.max)),
        header,
    })
}
