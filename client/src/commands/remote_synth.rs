//! `crease synth --server URL`: the control frames go to a server's `Synthesize` RPC in
//! requests of bounded size; each answer is a `Topology` and one codec frame per control frame
//! (16-bit positions, spatial vertex order), decoded and written in the model's vertex order,
//! named and formatted as local synthesis writes them.
//!
//! Every request is a fresh batch on the server (its own predictor context, control points at
//! rest), while local synthesis holds an occluded point at its last valid position across the
//! whole file. So the first frame of every later request carries, for each point it occludes,
//! that point's last valid position marked valid: the server's held state then equals the local
//! one (the predictor keeps no other state between frames) and the meshes match frame for frame.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, anyhow, bail};
use crease_core::codec::FrameHeader;
use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::gltf_export;
use crease_proto::v1::mesh_frame::Body;
use crease_proto::{StreamTopology, control_frame, v1};
use tokio_stream::{Stream, StreamExt};

use super::synth::{SynthArgs, frame_path};
use crease_remote::client::frames_per_message;
use crease_remote::control_file::{ControlFrame, read_control_frames};
use crease_remote::mesh_stream::MeshReader;

/// Runs `crease synth --server URL` (the rest of `args` as for local synthesis; `--model` is a
/// model name).
pub fn run(args: &SynthArgs, server: &str) -> anyhow::Result<()> {
    args.check()?;
    if args.chunk_frames == 0 {
        bail!("--chunk-frames must be at least 1");
    }
    // On the wire 0 means "the model's default", so a bad value is refused here.
    if let Some(beta) = args.beta
        && !(beta.is_finite() && beta > 0.0)
    {
        bail!("--beta must be finite and > 0, got {beta}");
    }
    let Some(name) = args.model.to_str() else {
        bail!(
            "--model {}: with --server, a model name (UTF-8) the server hosts",
            args.model.display()
        );
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(synth(args, server, name))
}

async fn synth(args: &SynthArgs, server: &str, name: &str) -> anyhow::Result<()> {
    let mut client = super::common::connect(server, args.ca.as_deref()).await?;
    let info = client
        .get_model(v1::GetModelRequest {
            model: name.to_owned(),
        })
        .await
        .map_err(|s| status_error(&s, 0))
        .with_context(|| format!("asking {server} for model {name:?}"))?
        .into_inner();
    let count = info.control_points.len();
    let frames = read_control_frames(&args.controls, count)?;
    let (level, vertices, triangles) = if args.detail {
        if info.detail_vertices == 0 {
            bail!(
                "model {name:?} on {server}: --detail needs a model with a detail layer (train it on detailed examples: a manifest with `detailed`, or --base-vertices)"
            );
        }
        (
            v1::Level::Detail,
            info.detail_vertices,
            info.detail_triangles,
        )
    } else {
        (v1::Level::Base, info.base_vertices, info.base_triangles)
    };
    let vertices = vertices as usize;
    if let Some(path) = &args.gltf {
        gltf_export::check_animation_size(vertices, triangles as usize, frames.len())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    }
    let request = |frames: Vec<v1::ControlFrame>| v1::SynthesizeRequest {
        model: name.to_owned(),
        level: level as i32,
        beta: args.beta.unwrap_or(0.0),
        refine: args.refine.map(|f| crease_proto::room::refine_wire(f.0)),
        skinning: super::common::skinning_wire(args.skinning),
        frames,
    };
    // The glTF's rest mesh: the server's prediction at the rest controls (a request of its own,
    // so it leaves the batch's held controls alone).
    let rest = match &args.gltf {
        Some(_) => {
            let mut sink = Sink::new(None, &args.format, vertices, true, false);
            let stream = client
                .synthesize(request(vec![rest_frame(&info)?]))
                .await
                .map_err(|s| status_error(&s, 0))
                .with_context(|| format!("synthesising the rest mesh of {name:?} on {server}"))?
                .into_inner();
            sink.receive(stream, 1, 1)
                .await
                .with_context(|| format!("synthesising the rest mesh of {name:?} on {server}"))?;
            Some((sink.mesh.triangles, sink.animation))
        }
        None => None,
    };

    let per_request = frames_per_message(count, args.chunk_frames);
    let requests = frames.len().div_ceil(per_request);
    eprintln!(
        "synthesising {} frames of model {name:?} on {server} ({vertices} vertices, {requests} request{} of at most {per_request} frames)",
        frames.len(),
        if requests == 1 { "" } else { "s" }
    );
    let start = Instant::now();
    let mut sink = Sink::new(
        args.out.as_deref(),
        &args.format,
        vertices,
        args.gltf.is_some(),
        true,
    );
    let mut last_valid = vec![None; count];
    for first in (0..frames.len()).step_by(per_request) {
        let chunk = &frames[first..(first + per_request).min(frames.len())];
        let what = || {
            format!(
                "synthesising frames {first}..{} of {name:?} on {server}",
                first + chunk.len()
            )
        };
        let stream = client
            .synthesize(request(wire_frames(chunk, first, &mut last_valid)))
            .await
            .map_err(|s| status_error(&s, first))
            .with_context(what)?
            .into_inner();
        sink.receive(stream, chunk.len(), frames.len())
            .await
            .with_context(what)?;
    }
    let secs = start.elapsed().as_secs_f64();
    if let (Some(path), Some((triangles, rest))) = (&args.gltf, &rest) {
        gltf_export::export_animation_glb(path, triangles, rest, &sink.animation, args.fps)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if sink.edge_frames > 0 {
        eprintln!(
            "warning: {} frames have vertices on the edge of the quantisation box: positions outside it were clamped to it and may be off by more than the bound",
            sink.edge_frames
        );
    }
    let held: usize = frames
        .iter()
        .map(|f| f.valid.iter().filter(|v| !**v).count())
        .sum();
    let targets: Vec<String> = [args.out.as_ref(), args.gltf.as_ref()]
        .into_iter()
        .flatten()
        .map(|p| p.display().to_string())
        .collect();
    println!(
        "wrote {} frames to {} in {secs:.2} s ({:.1} frames/s from {server}, {requests} request{}; {} bytes received, {:.2} bytes/vertex/frame; error ≤ {:.2e} per coordinate; {held} occluded control values held)",
        sink.frames,
        targets.join(" and "),
        sink.frames as f64 / secs.max(1e-9),
        if requests == 1 { "" } else { "s" },
        sink.bytes,
        sink.bytes as f64 / (sink.frames.max(1) * vertices.max(1)) as f64,
        sink.error_bound.max_element()
    );
    Ok(())
}

/// Writes a whole mesh stream of `total` frames (a `GetJobResult`: the topology, then frames
/// numbered from 0) into `out` as `crease synth` names and formats them; returns a summary
/// (bytes received, the quantisation bound).
///
/// # Errors
/// A refused or broken stream, a frame out of order, a file that cannot be written.
pub(crate) async fn write_frames<S>(
    stream: S,
    out: &Path,
    format: &str,
    vertices: usize,
    total: usize,
) -> anyhow::Result<String>
where
    S: Stream<Item = Result<v1::MeshFrame, tonic::Status>> + Unpin,
{
    let mut sink = Sink::new(Some(out), format, vertices, false, true);
    sink.receive(stream, total, total).await?;
    Ok(format!(
        "{} bytes received, {:.2} bytes/vertex/frame; error ≤ {:.2e} per coordinate",
        sink.bytes,
        sink.bytes as f64 / (sink.frames.max(1) * vertices.max(1)) as f64,
        sink.error_bound.max_element()
    ))
}

/// Reads a whole vertex stream of `total` frames (a `GetJobResult`) into memory for a glTF
/// animation: the mesh's triangles and every frame's positions (model order), one frame
/// after another; progress on stderr.
///
/// # Errors
/// A refused or broken stream, a frame out of order.
pub(crate) async fn collect_frames<S>(
    stream: S,
    vertices: usize,
    total: usize,
) -> anyhow::Result<(Vec<[u32; 3]>, Vec<Vec3>)>
where
    S: Stream<Item = Result<v1::MeshFrame, tonic::Status>> + Unpin,
{
    let mut sink = Sink::new(None, "obj", vertices, true, true);
    sink.receive(stream, total, total).await?;
    Ok((sink.mesh.triangles, sink.animation))
}

/// A status from the server as an error: its message (which names the field) and code, with a
/// batch's refused frame (counted within its request) renumbered to the control file's frame.
fn status_error(status: &tonic::Status, first: usize) -> anyhow::Error {
    let message = status.message();
    match renumber(status, first) {
        Some(m) => anyhow!("the server refused {m} ({:?})", status.code()),
        None => anyhow!("{message} ({:?})", status.code()),
    }
}

/// `frames[first + k].<field>: ...` for a batch status whose details name frame `k`
/// (`FrameError.frame`); `None` for any other status.
fn renumber(status: &tonic::Status, first: usize) -> Option<String> {
    let e = crease_proto::errors::batch_frame_error(status)?;
    Some(format!(
        "frames[{}].{}",
        first + e.frame? as usize,
        e.message
    ))
}

/// The wire frames of `chunk`, whose first frame is the control file's frame `first`:
/// positions flattened, occluded points sent as 0 with their validity bit cleared, `seq` the
/// frame's index in the file. `last_valid` (one entry per control point, carried from request to
/// request) fills the occluded points of the chunk's first frame (module docs).
fn wire_frames(
    chunk: &[ControlFrame],
    first: usize,
    last_valid: &mut [Option<Vec3>],
) -> Vec<v1::ControlFrame> {
    let mut valid = Vec::with_capacity(last_valid.len());
    chunk
        .iter()
        .enumerate()
        .map(|(k, frame)| {
            let mut points = Vec::with_capacity(last_valid.len());
            valid.clear();
            for ((&p, &seen), held) in frame.positions.iter().zip(&frame.valid).zip(&*last_valid) {
                let (p, seen) = match (seen, held) {
                    (true, _) => (p, true),
                    (false, Some(h)) if k == 0 => (*h, true),
                    (false, _) => (Vec3::ZERO, false),
                };
                points.push(p);
                valid.push(seen);
            }
            for (held, (&p, &seen)) in last_valid
                .iter_mut()
                .zip(frame.positions.iter().zip(&frame.valid))
            {
                if seen {
                    *held = Some(p);
                }
            }
            control_frame("", (first + k) as u64, 0, &points, &valid)
        })
        .collect()
}

/// A frame of every control point at its rest position (the model's `ControlPoint.rest`).
fn rest_frame(info: &v1::ModelInfo) -> anyhow::Result<v1::ControlFrame> {
    let n = info.control_points.len();
    let mut positions = vec![0.0; 3 * n];
    for c in &info.control_points {
        let id = c.id as usize;
        let rest = c
            .rest
            .with_context(|| format!("ModelInfo.control_points[{id}].rest: missing"))?;
        positions
            .get_mut(3 * id..3 * id + 3)
            .with_context(|| {
                format!("ModelInfo.control_points: id {id}, expected < {n} (the point count)")
            })?
            .copy_from_slice(&[rest.x, rest.y, rest.z]);
    }
    Ok(v1::ControlFrame {
        positions,
        ..Default::default()
    })
}

/// Where decoded frames go: one mesh file per frame, the glTF animation, and the counts of the
/// summary. Frames are numbered on across requests.
#[derive(Debug)]
struct Sink<'a> {
    /// Folder of the mesh files, if any.
    out: Option<&'a Path>,
    /// Their format (extension).
    format: &'a str,
    /// Vertices per frame, as the model info says.
    vertices: usize,
    /// The first request's topology; later ones must send the same.
    topology: Option<StreamTopology>,
    /// The frame being written: model triangles, positions in model order.
    mesh: Mesh,
    /// Every frame's positions (model order), frame after frame, when `keep` is set.
    animation: Vec<Vec3>,
    keep: bool,
    /// Frames received so far: the next frame's index.
    frames: usize,
    /// Codec bytes received.
    bytes: u64,
    /// The largest quantisation error bound of any frame, per axis.
    error_bound: Vec3,
    /// Frames with a vertex on the quantisation box's faces (maybe clamped).
    edge_frames: usize,
    /// Frames/s on stderr about once a second: since when, and the frame count then.
    progress: Option<(Instant, usize)>,
}

impl<'a> Sink<'a> {
    fn new(
        out: Option<&'a Path>,
        format: &'a str,
        vertices: usize,
        keep: bool,
        progress: bool,
    ) -> Self {
        Self {
            out,
            format,
            vertices,
            topology: None,
            mesh: Mesh {
                positions: Vec::with_capacity(vertices),
                triangles: Vec::new(),
            },
            animation: Vec::new(),
            keep,
            frames: 0,
            bytes: 0,
            error_bound: Vec3::ZERO,
            edge_frames: 0,
            progress: progress.then(|| (Instant::now(), 0)),
        }
    }

    /// Takes one `Synthesize` answer: the topology, then `count` frames (of `total` in all),
    /// then the end of the stream.
    async fn receive<S>(&mut self, mut stream: S, count: usize, total: usize) -> anyhow::Result<()>
    where
        S: Stream<Item = Result<v1::MeshFrame, tonic::Status>> + Unpin,
    {
        let first = self.frames;
        let topology = match stream.next().await {
            None => bail!(
                "the stream ended after {first} of {total} frames (before this request's topology)"
            ),
            Some(Err(s)) => return Err(status_error(&s, first)),
            Some(Ok(v1::MeshFrame {
                body: Some(Body::Topology(t)),
            })) => t,
            Some(Ok(_)) => bail!("the server sent a frame before the topology"),
        };
        let mut reader = MeshReader::new(&topology)?;
        let topology = reader.topology();
        if topology.vertex_count != self.vertices {
            bail!(
                "the topology has {} vertices, the model info said {}",
                topology.vertex_count,
                self.vertices
            );
        }
        match &self.topology {
            Some(t) if t != topology => {
                bail!("the server's topology changed between requests (at frame {first})")
            }
            Some(_) => {}
            None => {
                self.mesh.triangles = topology.model_triangles();
                self.topology = Some(topology.clone());
            }
        }
        while self.frames < first + count {
            let frame = match stream.next().await {
                None => bail!("the stream ended after {} of {total} frames", self.frames),
                Some(Err(s)) => {
                    return Err(status_error(&s, first))
                        .with_context(|| format!("after {} of {total} frames", self.frames));
                }
                Some(Ok(v1::MeshFrame {
                    body: Some(Body::Frame(f)),
                })) => f,
                Some(Ok(_)) => bail!("frame {}: expected a mesh frame", self.frames),
            };
            if frame.seq != self.frames as u64 {
                bail!(
                    "frame {}: the server answered with frame seq {}",
                    self.frames,
                    frame.seq
                );
            }
            let header = reader
                .decode(&frame.data)
                .with_context(|| format!("decoding frame {}", self.frames))?;
            self.take(&mut reader, &header, frame.data.len())?;
        }
        match stream.next().await {
            None => Ok(()),
            Some(Err(s)) => Err(status_error(&s, first)),
            Some(Ok(_)) => bail!("the server sent more than the {count} frames asked for"),
        }
    }

    /// The decoder's frame: back in model order, counted, written.
    fn take(
        &mut self,
        reader: &mut MeshReader,
        header: &FrameHeader,
        bytes: usize,
    ) -> anyhow::Result<()> {
        reader.model_positions(&mut self.mesh.positions);
        self.bytes += bytes as u64;
        self.error_bound = self.error_bound.max(header.qbox.error_bound());
        let top = header.qbox.max_level();
        if reader
            .decoder()
            .lanes()
            .iter()
            .any(|l| l[..3].iter().any(|&q| q == 0 || q == top))
        {
            self.edge_frames += 1;
        }
        if self.keep {
            self.animation.extend_from_slice(&self.mesh.positions);
        }
        if let Some(out) = self.out {
            let path = frame_path(out, self.frames, self.format);
            self.mesh
                .write(&path)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        self.frames += 1;
        if let Some((since, at)) = &mut self.progress {
            let secs = since.elapsed().as_secs_f64();
            if secs >= 1.0 {
                eprintln!(
                    "{} frames, {:.1} frames/s",
                    self.frames,
                    (self.frames - *at) as f64 / secs
                );
                *since = Instant::now();
                *at = self.frames;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crease_core::codec::{FrameEncoder, QuantBox, encode_indices};

    #[test]
    fn batch_errors_name_the_file_frame() {
        let refused = |k, field: &str, what: &str| {
            let e = crease_proto::WireError::new("ControlFrame", field, what);
            crease_proto::errors::batch_status(k, &e)
        };
        assert_eq!(
            renumber(
                &refused(3, "positions[1]", "(1, inf, 0) is not finite"),
                2000
            )
            .as_deref(),
            Some("frames[2003].positions[1]: (1, inf, 0) is not finite")
        );
        let plain = |m: &str| tonic::Status::invalid_argument(m);
        assert_eq!(renumber(&plain("model: no model \"x\""), 5), None);
        // The index is read from the details, never parsed out of the message.
        assert_eq!(renumber(&plain("frames[1].valid"), 5), None);
        let s = refused(0, "valid", "3 bytes");
        let e = status_error(&s, 7).to_string();
        assert!(
            e.contains("frames[7].valid: 3 bytes") && e.contains("InvalidArgument"),
            "{e}"
        );
    }

    #[test]
    fn requests_stay_under_the_message_limit() {
        assert_eq!(frames_per_message(5, 2000), 2000);
        assert_eq!(frames_per_message(5, 7), 7);
        // 100k control points: ~1.2 MB a frame, two frames a request.
        let n = frames_per_message(100_000, 2000);
        assert_eq!(n, 2);
        // A frame alone over the budget still goes (the server then names the limit).
        assert_eq!(frames_per_message(1_000_000, 2000), 1);
    }

    #[test]
    fn later_requests_start_from_the_held_controls() {
        let p = |x: f32| Vec3::new(x, 0.0, 0.0);
        let frame = |points: [Option<f32>; 2]| ControlFrame {
            positions: points.iter().map(|v| v.map_or(Vec3::NAN, p)).collect(),
            valid: points.iter().map(Option::is_some).collect(),
        };
        let frames = [
            frame([Some(1.0), None]),
            frame([Some(2.0), Some(5.0)]),
            frame([None, None]),
            frame([None, Some(6.0)]),
        ];
        let mut held = vec![None; 2];
        // First request: point 1 never seen, so sent as 0 and invalid.
        let a = wire_frames(&frames[..2], 0, &mut held);
        assert_eq!(a[0].positions, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(a[0].valid, [0b01]);
        assert_eq!((a[0].seq, a[1].seq), (0, 1));
        assert!(a[1].valid.is_empty(), "all valid: empty mask");
        // Second request: its first frame carries the held positions as valid; later frames
        // occlude normally.
        let b = wire_frames(&frames[2..], 2, &mut held);
        assert_eq!(b[0].positions, [2.0, 0.0, 0.0, 5.0, 0.0, 0.0]);
        assert!(b[0].valid.is_empty());
        assert_eq!(b[1].positions, [0.0, 0.0, 0.0, 6.0, 0.0, 0.0]);
        assert_eq!(b[1].valid, [0b10]);
        assert_eq!((b[0].seq, b[1].seq), (2, 3));
        assert_eq!(held, [Some(p(2.0)), Some(p(6.0))]);
    }

    /// A topology message and `frames` encoded frames (streamed order `[2, 0, 3, 1]`) of four
    /// vertices whose model-order positions are `model(f)`.
    fn batch(frames: usize, model: impl Fn(usize) -> [Vec3; 4]) -> Vec<v1::MeshFrame> {
        let order = [2u32, 0, 3, 1];
        let mut inverse = [0u32; 4];
        for (i, &m) in order.iter().enumerate() {
            inverse[m as usize] = i as u32;
        }
        let tris: Vec<[u32; 3]> = [[0u32, 1, 2], [2, 1, 3]]
            .iter()
            .map(|t| t.map(|v| inverse[v as usize]))
            .collect();
        let mut indices = Vec::new();
        encode_indices(&tris, 4, &mut indices).unwrap();
        let qbox = QuantBox::from_bounds(Vec3::splat(-2.0), Vec3::splat(2.0), 0.0, 16).unwrap();
        let mut msgs = vec![v1::MeshFrame {
            body: Some(Body::Topology(v1::Topology {
                vertex_count: 4,
                triangle_count: 2,
                indices,
                vertex_order: order.to_vec(),
                bits: 16,
                ..Default::default()
            })),
        }];
        // Keyframes only, so a test can drop frames.
        let mut encoder = FrameEncoder::new(4, qbox, 1).unwrap();
        for f in 0..frames {
            let m = model(f);
            let streamed: Vec<Vec3> = order.iter().map(|&i| m[i as usize]).collect();
            let mut data = Vec::new();
            encoder.encode(&streamed, None, &mut data).unwrap();
            msgs.push(v1::MeshFrame {
                body: Some(Body::Frame(v1::Frame {
                    seq: f as u64,
                    data: data.into(),
                    ..Default::default()
                })),
            });
        }
        msgs
    }

    fn block_on<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap()
            .block_on(f)
    }

    #[test]
    fn frames_come_back_in_model_order() {
        let model = |f: usize| {
            let t = f as f32 * 0.1;
            [
                Vec3::new(-1.0, t, 0.5),
                Vec3::new(1.0, 0.3, -t),
                Vec3::new(0.25, 1.5, t),
                Vec3::new(t, -1.75, 0.0),
            ]
        };
        let mut sink = Sink::new(None, "obj", 4, true, false);
        block_on(sink.receive(
            tokio_stream::iter(batch(3, model).into_iter().map(Ok)),
            3,
            3,
        ))
        .unwrap();
        assert_eq!(sink.frames, 3);
        // 16 bits over a box of side 4: half a step is 4 / 65535 / 2.
        let bound = 2.0 / 65535.0 + 1e-6;
        assert!(sink.error_bound.max_element() <= bound);
        for f in 0..3 {
            for (i, (got, want)) in sink.animation[4 * f..4 * f + 4]
                .iter()
                .zip(model(f))
                .enumerate()
            {
                assert!(
                    (*got - want).abs().max_element() <= bound,
                    "frame {f} vertex {i}: {got} vs {want}"
                );
            }
        }
        // Triangles in model ids, up to the index codec's corner rotation.
        let canonical = |t: &[u32; 3]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let got: Vec<_> = sink.mesh.triangles.iter().map(canonical).collect();
        assert_eq!(got, [[0, 1, 2], [1, 3, 2]]);
    }

    #[test]
    fn a_short_stream_says_how_many_frames_came() {
        let model = |_| [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        // A second request of 3 frames after 2 already received: only 2 of its frames come.
        let mut sink = Sink::new(None, "obj", 4, false, false);
        sink.frames = 2;
        let mut msgs = batch(4, model);
        msgs.drain(1..3); // seq 2 and 3 remain
        let e =
            block_on(sink.receive(tokio_stream::iter(msgs.into_iter().map(Ok)), 3, 5)).unwrap_err();
        assert!(e.to_string().contains("ended after 4 of 5 frames"), "{e:#}");
        // An error status mid-stream is passed on, renumbered.
        let mut sink = Sink::new(None, "obj", 4, false, false);
        let mut msgs: Vec<Result<_, tonic::Status>> = batch(1, model).into_iter().map(Ok).collect();
        let e = crease_proto::WireError::new("ControlFrame", "positions", "3 values, expected 12");
        msgs.push(Err(crease_proto::errors::batch_status(1, &e)));
        let e = block_on(sink.receive(tokio_stream::iter(msgs), 3, 3)).unwrap_err();
        let e = format!("{e:#}");
        assert!(
            e.contains("after 1 of 3 frames") && e.contains("frames[1].positions: 3 values"),
            "{e}"
        );
        // A frame before the topology, and a wrong vertex count.
        let mut sink = Sink::new(None, "obj", 4, false, false);
        let msgs = batch(1, model).split_off(1);
        assert!(
            block_on(sink.receive(tokio_stream::iter(msgs.into_iter().map(Ok)), 1, 1)).is_err()
        );
        let mut sink = Sink::new(None, "obj", 5, false, false);
        let e = block_on(sink.receive(
            tokio_stream::iter(batch(1, model).into_iter().map(Ok)),
            1,
            1,
        ))
        .unwrap_err();
        assert!(e.to_string().contains("4 vertices"), "{e}");
    }
}
