//! The issue-18 exactness check, shared by the server's tube test and the demo crate's hand
//! and horse tests: a live room streamed to four subscribers at once (base and detail, each as
//! vertex frames and as palette frames), the same control frames published, and every frame
//! seen in both encodings compared: the palette stream decoded by `core`'s reference decoder
//! (`PaletteSynth`), the vertex stream by the codec, and both against the predictor's own mesh
//! computed here, each within its quantisation bound, vertex by vertex.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use crease_core::codec::FrameDecoder;
use crease_core::codec::palette::{
    PaletteFrame, PaletteSynth, palette_vertex_count, read_palette_lanes, vertex_error_bound,
};
use crease_core::glam::Vec3;
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use tonic::transport::Channel;

/// What one comparison measured.
#[derive(Debug, Default)]
pub(crate) struct PaletteReport {
    /// Frames compared per level (base, detail).
    pub frames: [usize; 2],
    /// The largest |palette - exact| and |palette - vertex| per level.
    pub palette_error: [f32; 2],
    pub palette_vs_vertex: [f32; 2],
    /// The largest error / bound ratio per level.
    pub worst_ratio: [f32; 2],
    /// Mean bytes per frame per level, palette then vertex.
    pub palette_bytes: [f64; 2],
    pub vertex_bytes: [f64; 2],
    /// The palette headers' sizes per level.
    pub header_bytes: [usize; 2],
    /// Milliseconds from the palette subscription to its header read, per level.
    pub header_ms: [f64; 2],
}

async fn open_stream(
    client: &mut CreaseClient<Channel>,
    room: &str,
    level: v1::Level,
    encoding: v1::Encoding,
) -> (v1::MeshFrame, tonic::Streaming<v1::MeshFrame>) {
    let mut s = client
        .subscribe(v1::SubscribeRequest {
            room: room.into(),
            level: level as i32,
            encoding: encoding as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let first = s.message().await.unwrap().unwrap();
    (first, s)
}

/// Reads frames until `last_seq` arrives (or 20 s pass).
async fn frames_until(s: &mut tonic::Streaming<v1::MeshFrame>, last_seq: u64) -> Vec<v1::Frame> {
    let mut out = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while let Ok(Ok(Some(msg))) = tokio::time::timeout_at(deadline, s.message()).await {
        if let Some(v1::mesh_frame::Body::Frame(f)) = msg.body {
            let seq = f.seq;
            out.push(f);
            if seq >= last_seq {
                break;
            }
        }
    }
    out
}

/// The bound of one skinned vertex between the model's exact transforms and weights and the
/// palette's decoded ones: the transforms' quantisation (`vertex_error_bound`) plus the
/// weights' (`sum_k |dw_k| |T_k p - v|`, module docs of `core::codec::palette::header`).
pub(crate) fn base_bound(
    model: &TrainedModel,
    synth: &PaletteSynth,
    frame: &PaletteFrame,
    v: usize,
    skinned: Vec3,
) -> f32 {
    let p = model.rig.rest.positions[v];
    let (ids, ws) = model.rig.skin.vertex(v);
    let exact: Vec<(u32, f32)> = ids.iter().copied().zip(ws.iter().copied()).collect();
    let (qids, qws) = synth.skin().vertex(v);
    let mut weight_part = 0.0f32;
    for (&b, &w) in qids.iter().zip(qws) {
        let w_exact: f32 = exact.iter().filter(|e| e.0 == b).map(|e| e.1).sum();
        let t = frame.bones[b as usize].transform_point(p);
        weight_part += (w - w_exact).abs() * t.distance(skinned);
    }
    for &(b, w) in &exact {
        if !qids.iter().zip(qws).any(|(&q, &qw)| q == b && qw > 0.0) && w > 0.0 {
            weight_part += w * frame.bones[b as usize].transform_point(p).distance(skinned);
        }
    }
    vertex_error_bound(frame, p, &exact) + weight_part
}

/// A bound on how far the unit area-weighted normal at each vertex of `high` turns when every
/// vertex moves by at most `eps`: each edge vector from the vertex moves by `2 eps`, so each
/// cross product by `2 eps (|e1| + |e2|) + 4 eps^2`, and a unit vector `s/|s|` by at most
/// `2 |ds| / |s|` (at most 2).
fn normal_bounds(high: &[Vec3], triangles: &[[u32; 3]], eps: f32) -> Vec<f32> {
    let mut s = vec![Vec3::ZERO; high.len()];
    let mut ds = vec![0.0f32; high.len()];
    for t in triangles {
        for k in 0..3 {
            let (v, a, b) = (
                t[k] as usize,
                t[(k + 1) % 3] as usize,
                t[(k + 2) % 3] as usize,
            );
            let (e1, e2) = (high[a] - high[v], high[b] - high[v]);
            s[v] += e1.cross(e2);
            ds[v] += 2.0 * eps * (e1.length() + e2.length()) + 4.0 * eps * eps;
        }
    }
    s.iter()
        .zip(&ds)
        .map(|(s, d)| (2.0 * d / s.length().max(1e-30)).min(2.0))
        .collect()
}

/// The check (module docs): opens `room` on `model_name` with the admin token, publishes
/// `frames` one by one (each after the previous one's ack, so that every subscriber gets every
/// frame), and compares.
pub(crate) async fn compare_encodings(
    url: &str,
    admin: &str,
    model_name: &str,
    model: &TrainedModel,
    frames: Vec<v1::ControlFrame>,
) -> PaletteReport {
    let mut client = CreaseClient::connect(url.to_owned())
        .await
        .unwrap()
        .max_decoding_message_size(256 << 20);
    let room = "palette-check";
    let open = v1::OpenRoomRequest {
        room: room.into(),
        model: model_name.into(),
        ..Default::default()
    };
    let token = client
        .open_room(super::authed(open, admin))
        .await
        .unwrap()
        .into_inner()
        .publish_token;
    let levels: Vec<v1::Level> = if model.detail.is_some() {
        vec![v1::Level::Base, v1::Level::Detail]
    } else {
        vec![v1::Level::Base]
    };
    let mut streams = Vec::new();
    let mut header_ms = [0.0; 2];
    for (li, &level) in levels.iter().enumerate() {
        for encoding in [v1::Encoding::Vertices, v1::Encoding::Palette] {
            let started = std::time::Instant::now();
            let opened = open_stream(&mut client, room, level, encoding).await;
            if encoding == v1::Encoding::Palette {
                header_ms[li] = started.elapsed().as_secs_f64() * 1e3;
            }
            streams.push((level, encoding, opened));
        }
    }
    let last_seq = frames.last().unwrap().seq;
    let mut got = Vec::new();
    let mut readers = Vec::new();
    for (level, encoding, (first, mut s)) in streams {
        readers.push((level, encoding, first));
        got.push(tokio::spawn(
            async move { frames_until(&mut s, last_seq).await },
        ));
    }
    // One frame at a time, each after the previous one's ack and a pause, so that every
    // subscriber (latest wins) gets every frame.
    let (tx, rx) = tokio::sync::mpsc::channel(1);
    let mut publish = client
        .publish(super::authed(
            tokio_stream::wrappers::ReceiverStream::new(rx),
            &token,
        ))
        .await
        .unwrap()
        .into_inner();
    for f in frames.clone() {
        tx.send(f).await.unwrap();
        let ack = publish.message().await.unwrap().unwrap();
        assert!(ack.error.is_none(), "{:?}", ack.error);
        tokio::time::sleep(Duration::from_millis(40)).await;
    }
    drop(tx);
    let mut received = Vec::new();
    for g in got {
        received.push(g.await.unwrap());
    }

    // The exact meshes, computed here with the same predictor.
    let predictor = Predictor::new(Arc::new(model.clone()), None).unwrap();
    let mut ctx = predictor.new_context();
    let mut exact: BTreeMap<u64, (Vec<Vec3>, Vec<Vec3>)> = BTreeMap::new();
    for f in &frames {
        let c: Vec<Vec3> = f
            .positions
            .chunks(3)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect();
        let base = predictor.predict(&mut ctx, &c, None).unwrap().to_vec();
        let detail = if model.detail.is_some() {
            predictor.predict_detail(&mut ctx).unwrap().to_vec()
        } else {
            Vec::new()
        };
        exact.insert(f.seq, (base, detail));
    }

    let mut report = PaletteReport {
        header_ms,
        ..PaletteReport::default()
    };
    for (li, &level) in levels.iter().enumerate() {
        let (vi, pi) = (2 * li, 2 * li + 1);
        let Some(v1::mesh_frame::Body::Topology(topo)) = &readers[vi].2.body else {
            panic!("the vertex stream starts with its topology");
        };
        let Some(v1::mesh_frame::Body::PaletteTopology(ptopo)) = &readers[pi].2.body else {
            panic!("the palette stream starts with its header");
        };
        report.header_bytes[li] = prost::Message::encoded_len(&readers[pi].2);
        let topology = crease_proto::read_topology(topo).unwrap();
        let palette = crease_proto::read_palette_topology(ptopo).unwrap();
        let (bones, xi) = (palette.header.bones, palette.header.xi_len());
        let mut synth = PaletteSynth::new(palette.header).unwrap();
        let mut vdec = FrameDecoder::new(topology.vertex_count);
        let mut pdec = FrameDecoder::new(palette_vertex_count(bones, xi));
        let mut vertex_frames: BTreeMap<u64, Vec<Vec3>> = BTreeMap::new();
        let (mut vbytes, mut vcount) = (0usize, 0usize);
        let mut vbound = Vec3::ZERO;
        for f in &received[vi] {
            let h = vdec.decode(&f.data).unwrap();
            vbound = h.qbox.error_bound();
            let (mut streamed, mut model_order) = (Vec::new(), Vec::new());
            vdec.positions(&mut streamed);
            topology.to_model_order(&streamed, &mut model_order);
            vertex_frames.insert(f.seq, model_order);
            vbytes += f.data.len();
            vcount += 1;
        }
        let (mut pbytes, mut pcount) = (0usize, 0usize);
        let mut frame = PaletteFrame::default();
        for f in &received[pi] {
            let h = pdec.decode(&f.data).unwrap();
            read_palette_lanes(pdec.lanes(), &h.qbox, bones, xi, &mut frame).unwrap();
            let got = synth.synthesize(&frame).unwrap().to_vec();
            pbytes += f.data.len();
            pcount += 1;
            let (Some(vertex), Some((ebase, edetail))) =
                (vertex_frames.get(&f.seq), exact.get(&f.seq))
            else {
                continue;
            };
            report.frames[li] += 1;
            // Each base vertex's palette bound; at the detail level, carried through S (Loop
            // weights are a convex combination) as the largest one, plus the displacement's.
            let base_bounds: Vec<f32> = synth
                .base()
                .iter()
                .enumerate()
                .map(|(v, &s)| base_bound(model, &synth, &frame, v, s) + 1e-5 * (1.0 + s.length()))
                .collect();
            let (want, bounds): (&[Vec3], Vec<f32>) = match level {
                v1::Level::Detail => {
                    let eps = base_bounds.iter().fold(0.0f32, |m, &b| m.max(b));
                    let dn = normal_bounds(synth.high(), synth.triangles(), eps);
                    let d = synth.detail().unwrap();
                    let h = synth.displacements();
                    let b = (0..got.len())
                        .map(|v| eps + d.displacement_error(&frame.xi) + h[v].abs() * dn[v] + 1e-5)
                        .collect();
                    (edetail, b)
                }
                _ => (ebase, base_bounds),
            };
            assert_eq!(got.len(), want.len());
            for (v, ((g, w), b)) in got.iter().zip(want).zip(&bounds).enumerate() {
                let err = g.distance(*w);
                assert!(
                    err <= *b,
                    "{level:?} frame {}: vertex {v}: palette {g} vs exact {w}: {err} over {b}",
                    f.seq
                );
                report.palette_error[li] = report.palette_error[li].max(err);
                report.worst_ratio[li] = report.worst_ratio[li].max(err / b);
                // The vertex stream within its own half step of the exact mesh, so the two
                // encodings within the sum of their bounds.
                let vb = vbound.length() * 1.001 + 1e-6;
                let ve = vertex[v].distance(*w);
                assert!(
                    ve <= vb,
                    "{level:?} frame {}: vertex {v}: vertex stream {ve} over {vb}",
                    f.seq
                );
                let pv = g.distance(vertex[v]);
                assert!(
                    pv <= *b + vb,
                    "{level:?} frame {}: vertex {v}: palette vs vertex {pv}",
                    f.seq
                );
                report.palette_vs_vertex[li] = report.palette_vs_vertex[li].max(pv);
            }
        }
        report.palette_bytes[li] = pbytes as f64 / pcount.max(1) as f64;
        report.vertex_bytes[li] = vbytes as f64 / vcount.max(1) as f64;
        assert!(
            report.frames[li] >= frames.len() / 2,
            "{level:?}: only {} frames in both encodings",
            report.frames[li]
        );
    }
    report
}
