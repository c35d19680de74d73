//! `crease watch`: subscribe to a room over gRPC, decode every frame, and report frames per
//! second, bytes per frame and latency percentiles; optionally dump frames as OBJ. A room of
//! several actors (issue 38) is watched whole: every actor's part of each frame decoded with
//! its own reader, its bytes counted, its mesh dumped beside the others'.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use crease_core::mesh::Mesh;
use crease_proto::v1;

use super::common::percentile;
use super::decode_stream::write_capture_message;
use crease_remote::mesh_stream;

/// Options of `crease watch`.
#[derive(Clone, Debug, clap::Args)]
pub struct WatchArgs {
    /// The server to talk to.
    #[command(flatten)]
    pub server: super::common::ServerArgs,
    /// The room to watch.
    #[arg(long, default_value = "demo")]
    pub room: String,
    /// Watch the detail layer instead of the base mesh.
    #[arg(long)]
    pub detail: bool,
    /// How the frames travel: `vertices` (every vertex, quantised) or `palette` (the bone
    /// transforms and the detail kernel vector; this command skins and synthesises the detail
    /// layer on the CPU, as a viewer's GPU would).
    #[arg(long, default_value = "vertices", value_parser = ["vertices", "palette"])]
    pub encoding: String,
    /// Stop after this many frames and print a one-line summary.
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
    /// Write every received frame as `DIR/frame_00000.obj`, ... (a room of actors:
    /// `DIR/frame_00000_ACTOR.obj` per actor)
    #[arg(long, value_name = "DIR")]
    pub dump: Option<PathBuf>,
    /// Record the stream as it arrives (its first message, then every frame) to FILE, the
    /// capture `crease decode-stream` reads.
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
}

/// Runs `crease watch`.
pub fn run(args: &WatchArgs) -> anyhow::Result<()> {
    if args.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the network runtime")?;
    runtime.block_on(watch(args))
}

async fn watch(args: &WatchArgs) -> anyhow::Result<()> {
    let mut client = args.server.connect().await?;
    let level = if args.detail {
        v1::Level::Detail
    } else {
        v1::Level::Base
    };
    let encoding = crease_proto::Encoding::from_query(Some(&args.encoding))?;
    let header_start = Instant::now();
    let mut sub = mesh_stream::subscribe_encoded(&mut client, &args.room, level, encoding).await?;
    let header_secs = header_start.elapsed().as_secs_f64();
    let mut readers = sub.stream_readers()?;
    let names = sub.actor_names();
    let n: usize = readers.iter().map(|r| r.vertex_count()).sum();
    let triangles: Vec<Vec<[u32; 3]>> = readers.iter().map(|r| r.model_triangles()).collect();
    let first_bytes = prost::Message::encoded_len(&sub.first)
        + sub
            .actors
            .iter()
            .skip(1)
            .map(prost::Message::encoded_len)
            .sum::<usize>();
    let what = if names.is_empty() {
        format!(
            "model {:?}, {} vertices, {} triangles",
            sub.model(),
            n,
            triangles[0].len()
        )
    } else {
        let actors: Vec<String> = names
            .iter()
            .zip(&readers)
            .map(|(a, r)| format!("{a}: {} vertices", r.vertex_count()))
            .collect();
        format!("{} actors: {}", names.len(), actors.join(", "))
    };
    eprintln!(
        "watching room {:?} ({what}, {} encoding; first message{} {first_bytes} bytes in {header_secs:.3} s)",
        args.room,
        encoding.name(),
        if names.is_empty() { "" } else { "s" },
    );
    if !names.is_empty() && args.record.is_some() {
        bail!(
            "--record: room {:?} has {} actors, and `crease decode-stream` reads one actor's stream; record a take instead (`crease take start`)",
            args.room,
            names.len()
        );
    }
    if let Some(dir) = &args.dump {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut record = match &args.record {
        Some(path) => {
            let file = std::fs::File::create(path)
                .with_context(|| format!("creating {}", path.display()))?;
            let mut w = std::io::BufWriter::new(file);
            write_capture_message(&mut w, &sub.first)
                .with_context(|| format!("writing {}", path.display()))?;
            Some((w, path))
        }
        None => None,
    };
    // The dumped meshes, one per actor, in model vertex order: the topology once, each
    // frame's positions decoded and put back in model order into it.
    let mut meshes: Vec<Mesh> = triangles
        .into_iter()
        .map(|triangles| Mesh {
            positions: Vec::new(),
            triangles,
        })
        .collect();
    let (mut frames, mut bytes, mut skipped) = (0u64, 0u64, 0u64);
    let mut latencies: Vec<u32> = Vec::new();
    let start = Instant::now();
    let mut window = (Instant::now(), 0u64, 0u64);
    while let Some(f) = sub.next_frame().await? {
        let mut size = f.data.len();
        if f.actors.is_empty() {
            readers[0]
                .decode(&f.data)
                .with_context(|| format!("decoding frame {}", f.seq))?;
        } else {
            for a in &f.actors {
                let reader = readers.get_mut(a.actor as usize).with_context(|| {
                    format!(
                        "frame {}: actor {}, of {} actors",
                        f.seq,
                        a.actor,
                        names.len()
                    )
                })?;
                reader
                    .decode(&a.data)
                    .with_context(|| format!("decoding frame {} of actor {}", f.seq, a.actor))?;
                size += a.data.len();
            }
        }
        if let Some((w, path)) = &mut record {
            let msg = v1::MeshFrame {
                body: Some(v1::mesh_frame::Body::Frame(f.clone())),
            };
            write_capture_message(w, &msg)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        frames += 1;
        bytes += size as u64;
        skipped += u64::from(f.skipped);
        latencies.push(f.server_latency_us);
        if let Some(dir) = &args.dump {
            for (k, (reader, mesh)) in readers.iter_mut().zip(&mut meshes).enumerate() {
                reader.model_positions(&mut mesh.positions);
                let path = match names.get(k) {
                    Some(actor) => dir.join(format!("frame_{:05}_{actor}.obj", frames - 1)),
                    None => dir.join(format!("frame_{:05}.obj", frames - 1)),
                };
                mesh.write(&path)
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
        window.1 += 1;
        window.2 += size as u64;
        if window.0.elapsed() >= Duration::from_secs(1) {
            let secs = window.0.elapsed().as_secs_f64();
            eprintln!(
                "{:.1} frames/s, {:.0} bytes/frame ({:.2} bytes/vertex), server latency p50 {} µs",
                window.1 as f64 / secs,
                window.2 as f64 / window.1.max(1) as f64,
                window.2 as f64 / (window.1.max(1) * n.max(1) as u64) as f64,
                f.server_latency_us
            );
            window = (Instant::now(), 0, 0);
        }
        if args.frames.is_some_and(|limit| frames >= limit) {
            break;
        }
    }
    if let Some((mut w, path)) = record {
        std::io::Write::flush(&mut w).with_context(|| format!("writing {}", path.display()))?;
    }
    latencies.sort_unstable();
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{frames} frames in {secs:.2} s ({:.1} frames/s), {:.0} bytes/frame ({:.2} bytes/vertex), {skipped} skipped, server latency p50 {} µs p99 {} µs",
        frames as f64 / secs.max(1e-9),
        bytes as f64 / frames.max(1) as f64,
        bytes as f64 / (frames.max(1) * n.max(1) as u64) as f64,
        percentile(&latencies, 50.0),
        percentile(&latencies, 99.0)
    );
    if args.frames.is_some_and(|limit| frames < limit) {
        bail!("the stream ended after {frames} frames");
    }
    Ok(())
}
