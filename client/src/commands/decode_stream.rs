//! `crease decode-stream`: decodes a recorded mesh stream (`crease watch --record`, or any
//! client's capture) with the Rust core and writes its last frame's mesh: the reference a
//! viewer's own decoder is checked against (the browser test compares the viewer's GPU
//! synthesis of a palette frame with this).
//!
//! A capture is the stream's messages in order, each a protobuf `crease.v1.MeshFrame` prefixed
//! by its length as a little-endian `u32`: the first a `Topology` or a `PaletteTopology`, then
//! `Frame`s. Every frame is decoded in order (a vertex stream's deltas need their bases).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_proto::v1;
use prost::Message as _;

use crease_remote::mesh_stream::StreamReader;

/// Options of `crease decode-stream`.
#[derive(Clone, Debug, clap::Args)]
pub struct DecodeStreamArgs {
    /// The capture: length-prefixed `MeshFrame` messages (module docs).
    pub capture: PathBuf,
    /// Where to write the last frame's positions: x, y, z per vertex as little-endian f32, in
    /// model vertex order; a `.obj` file name writes a mesh instead.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Write every frame, not only the last: `--out` gets frame after frame (x, y, z per vertex
    /// as little-endian f32, model vertex order; a one-actor stream only), and the summary
    /// lists their `seqs`: the reference another decoder's frames are compared with.
    #[arg(long)]
    pub every_frame: bool,
}

/// The messages of a capture (module docs).
///
/// # Errors
/// A truncated length or message, naming its byte offset.
pub fn read_capture(bytes: &[u8]) -> anyhow::Result<Vec<v1::MeshFrame>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let Some(len) = bytes.get(at..at + 4) else {
            bail!(
                "byte {at}: a truncated length prefix ({} bytes left)",
                bytes.len() - at
            );
        };
        let len = u32::from_le_bytes(len.try_into().expect("4 bytes")) as usize;
        let Some(msg) = bytes.get(at + 4..at + 4 + len) else {
            bail!(
                "byte {at}: message {} claims {len} bytes, {} remain",
                out.len(),
                bytes.len() - at - 4
            );
        };
        out.push(
            v1::MeshFrame::decode(msg)
                .with_context(|| format!("byte {at}: message {} is not a MeshFrame", out.len()))?,
        );
        at += 4 + len;
    }
    Ok(out)
}

/// Appends `msg` to a capture.
pub fn write_capture_message(out: &mut impl Write, msg: &v1::MeshFrame) -> std::io::Result<()> {
    let bytes = msg.encode_to_vec();
    out.write_all(&(bytes.len() as u32).to_le_bytes())?;
    out.write_all(&bytes)
}

/// Runs `crease decode-stream`.
pub fn run(args: &DecodeStreamArgs) -> anyhow::Result<()> {
    let bytes = std::fs::read(&args.capture)
        .with_context(|| format!("reading {}", args.capture.display()))?;
    let messages = read_capture(&bytes).with_context(|| format!("{}", args.capture.display()))?;
    let (first, rest) = messages
        .split_first()
        .with_context(|| format!("{}: an empty capture", args.capture.display()))?;
    let mut reader = StreamReader::new(first)?;
    let mut frames = 0usize;
    let mut seq = 0u64;
    let mut every = Vec::new();
    let mut seqs = Vec::new();
    let mut positions = Vec::new();
    if args.every_frame
        && args
            .out
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("obj"))
    {
        bail!("--every-frame writes raw f32 positions: give --out a name that is not .obj");
    }
    for (k, msg) in rest.iter().enumerate() {
        let Some(v1::mesh_frame::Body::Frame(f)) = &msg.body else {
            bail!("message {}: not a Frame", k + 1);
        };
        reader
            .decode(&f.data)
            .with_context(|| format!("message {} (frame seq {})", k + 1, f.seq))?;
        frames += 1;
        seq = f.seq;
        if args.every_frame {
            reader.model_positions(&mut positions);
            every.extend(positions.iter().flat_map(|p| p.to_array()));
            seqs.push(f.seq);
        }
    }
    if frames == 0 {
        bail!(
            "{}: no frames after the first message",
            args.capture.display()
        );
    }
    reader.model_positions(&mut positions);
    if args.every_frame {
        let bytes: Vec<u8> = every.iter().flat_map(|c: &f32| c.to_le_bytes()).collect();
        std::fs::write(&args.out, bytes)
            .with_context(|| format!("writing {}", args.out.display()))?;
    } else {
        write_positions(&args.out, &positions, &reader)?;
    }
    let level = match &first.body {
        Some(v1::mesh_frame::Body::Topology(t)) => t.level,
        Some(v1::mesh_frame::Body::PaletteTopology(t)) => t.level,
        _ => 0,
    };
    let level = crease_proto::Level::from_wire("MeshFrame", level)?;
    println!(
        "{}",
        serde_json::json!({
            "encoding": reader.encoding().name(),
            "level": level.name(),
            "frames": frames,
            "seq": seq,
            "vertex_count": positions.len(),
            "seqs": if args.every_frame { Some(&seqs) } else { None },
        })
    );
    Ok(())
}

fn write_positions(path: &Path, positions: &[Vec3], reader: &StreamReader) -> anyhow::Result<()> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"))
    {
        let mesh = crease_core::mesh::Mesh {
            positions: positions.to_vec(),
            triangles: reader.model_triangles(),
        };
        return mesh
            .write(path)
            .with_context(|| format!("writing {}", path.display()));
    }
    let mut bytes = Vec::with_capacity(positions.len() * 12);
    for p in positions {
        for c in p.to_array() {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_capture_reads_back_and_a_truncated_one_names_its_offset() {
        let msgs = [
            v1::MeshFrame {
                body: Some(v1::mesh_frame::Body::Frame(v1::Frame {
                    seq: 3,
                    ..Default::default()
                })),
            },
            v1::MeshFrame {
                body: Some(v1::mesh_frame::Body::Frame(v1::Frame {
                    seq: 4,
                    data: vec![1u8, 2, 3].into(),
                    ..Default::default()
                })),
            },
        ];
        let mut bytes = Vec::new();
        for m in &msgs {
            write_capture_message(&mut bytes, m).unwrap();
        }
        assert_eq!(read_capture(&bytes).unwrap(), msgs);
        let e = read_capture(&bytes[..bytes.len() - 1])
            .unwrap_err()
            .to_string();
        assert!(e.contains("message 1 claims"), "{e}");
        let e = read_capture(&bytes[..2]).unwrap_err().to_string();
        assert!(e.contains("byte 0: a truncated length prefix"), "{e}");
    }
}
