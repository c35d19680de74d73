//! What `crease bench-net` reports: latency percentiles, spreads over rooms and subscribers,
//! CPU, bytes per vertex per frame, per scenario and for the whole run (JSON with `--json`),
//! and the table printed otherwise.

use serde::Serialize;

use crease_remote::percentile;

/// Percentiles of a latency sample, microseconds (nearest rank).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Percentiles {
    /// Values in the sample.
    pub count: usize,
    /// Median.
    pub p50: u32,
    /// 90th percentile.
    pub p90: u32,
    /// 99th percentile.
    pub p99: u32,
    /// Largest value.
    pub max: u32,
    /// Mean.
    pub mean: f64,
}

impl Percentiles {
    /// Sorts `values` and summarises them (all zero when empty).
    pub fn of(values: &mut [u32]) -> Percentiles {
        if values.is_empty() {
            return Percentiles::default();
        }
        values.sort_unstable();
        let rank = |p: f64| percentile(values, p);
        Percentiles {
            count: values.len(),
            p50: rank(50.0),
            p90: rank(90.0),
            p99: rank(99.0),
            max: values[values.len() - 1],
            mean: values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64,
        }
    }
}

/// Minimum, mean and maximum of a count over rooms or subscribers.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Spread {
    /// Smallest.
    pub min: u64,
    /// Mean.
    pub mean: f64,
    /// Largest.
    pub max: u64,
}

impl Spread {
    pub(super) fn of(values: impl IntoIterator<Item = u64>) -> Spread {
        let (mut min, mut max, mut sum, mut n) = (u64::MAX, 0, 0, 0u64);
        for v in values {
            min = min.min(v);
            max = max.max(v);
            sum += v;
            n += 1;
        }
        if n == 0 {
            return Spread::default();
        }
        Spread {
            min,
            mean: sum as f64 / n as f64,
            max,
        }
    }
}

/// CPU used during the measured window.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Cpu {
    /// CPU seconds per second of the window (cores kept busy).
    pub cores: f64,
    /// CPU milliseconds per control frame published in the window (all rooms).
    pub ms_per_frame: f64,
}

/// Bytes per vertex per frame of one kind of frame.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FrameBytes {
    /// Frames received.
    pub frames: u64,
    /// Their bytes (whole codec frames, header included).
    pub bytes: u64,
    /// bytes / (frames x vertices).
    pub bytes_per_vertex: f64,
}

impl FrameBytes {
    pub(super) fn new(frames: u64, bytes: u64, vertices: usize) -> FrameBytes {
        FrameBytes {
            frames,
            bytes,
            bytes_per_vertex: bytes as f64 / (frames.max(1) as f64 * vertices.max(1) as f64),
        }
    }
}

/// What one scenario measured (the window only, unless a field says otherwise).
#[derive(Clone, Debug, Serialize)]
pub struct ScenarioReport {
    /// `one-room`, `many-rooms` or `custom`.
    pub name: String,
    /// How the subscribers connected: `grpc` or `websocket`.
    pub transport: String,
    /// Rooms.
    pub rooms: usize,
    /// Subscribers per room.
    pub subscribers_per_room: usize,
    /// Control frames per second per room asked for.
    pub rate_hz: f64,
    /// Length of the measured window, seconds.
    pub seconds: f64,
    /// Control frames sent in the window, all rooms.
    pub frames_published: u64,
    /// Control frames sent in the window, per room.
    pub published_per_room: Spread,
    /// Frames the server refused (whole run; should be 0).
    pub frames_refused: u64,
    /// The first refusal's message.
    pub first_refusal: Option<String>,
    /// Mesh frames received in the window, all subscribers.
    pub frames_received: u64,
    /// Mesh frames received in the window, per subscriber.
    pub received_per_subscriber: Spread,
    /// Frames the server skipped for a slow subscriber (`Frame.skipped`), summed.
    pub frames_skipped: u64,
    /// `Frame.server_latency_us`: control frame received -> mesh frame handed to the
    /// subscriber's stream, over every received frame.
    pub server_latency_us: Percentiles,
    /// Control frame captured (publisher) -> mesh frame read by the subscriber, on this
    /// machine's clock: the server's figure plus HTTP/2 both ways and client scheduling.
    pub client_latency_us: Percentiles,
    /// `PublishAck.server_latency_us`: control frame received -> mesh predicted, encoded and
    /// handed to the room's channel.
    pub ack_latency_us: Percentiles,
    /// Per frame, its server latency less its ack's: the wait from the mesh being ready to
    /// this subscriber's stream task taking it (the fan-out; 0 when it took it first).
    pub fan_out_us: Percentiles,
    /// Per frame, client less server latency: time outside the server's measure (the control
    /// frame's trip in, the mesh frame's HTTP/2 encoding and trip out, the client's scheduling).
    pub outside_server_us: Percentiles,
    /// The server's CPU (`None`: not measurable, e.g. not Linux or no --server-pid).
    pub server_cpu: Option<Cpu>,
    /// The server's CPU per mesh frame received by a subscriber, µs: everything the server
    /// did in the window (predictions included) over the viewer-frames it served.
    pub server_cpu_us_per_viewer_frame: Option<f64>,
    /// This machine's floor for the same fan-out, measured after the window.
    pub floor: Floor,
    /// `server_cpu_us_per_viewer_frame / floor.cpu_us_per_write` (goal ≤ 2, issue 41).
    pub floor_ratio: Option<f64>,
    /// This process's CPU (publishers and subscribers).
    pub client_cpu: Option<Cpu>,
    /// Every received frame.
    pub all_frames: FrameBytes,
    /// Keyframes among them (the room's periodic ones and those of skipping subscribers).
    pub keyframes: FrameBytes,
    /// Deltas among them.
    pub deltas: FrameBytes,
    /// Mesh bytes received per second, all subscribers (codec frames, no gRPC framing).
    pub bytes_per_second: f64,
    /// Frames decoded by the first subscriber of each room (whole run).
    pub decoded_frames: u64,
    /// Frames that failed to decode (whole run; must be 0).
    pub decode_errors: u64,
    /// The first decode error.
    pub first_decode_error: Option<String>,
    /// With --replicas: each replica's subscribers' figures and its CPU (the first is the
    /// rooms' owner).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub replicas: Vec<ReplicaFigures>,
    /// With --replicas: bytes the owner published into NATS per control frame (every level,
    /// every room), from its `crease_cluster_nats_bytes_out_total`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nats_bytes_per_frame: Option<f64>,
}

/// This machine's floor for a scenario's fan-out (`floor`): one thread writing one message
/// of the scenario's mean frame size to each of as many loopback sockets as it has
/// subscribers, per frame period.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Floor {
    /// Sockets written (the scenario's subscribers, all rooms).
    pub sockets: usize,
    /// Bytes per write (the scenario's mean mesh frame).
    pub bytes: usize,
    /// Writes measured.
    pub writes: u64,
    /// The writing thread's CPU per write, µs (`/proc/thread-self/stat`); `None` when the
    /// run was too short for its clock ticks to measure it.
    pub cpu_us_per_write: Option<f64>,
    /// Its wall time in the write loops per write, µs.
    pub wall_us_per_write: f64,
}

/// One replica of a cluster scenario.
#[derive(Clone, Debug, Serialize)]
pub struct ReplicaFigures {
    /// Its index (`r0` owns the rooms).
    pub replica: usize,
    /// Subscribers connected to it.
    pub subscribers: usize,
    /// Their server latency (on a relay: the owner's, plus the relay's), µs.
    pub server_latency_us: Percentiles,
    /// Their client latency (capture -> frame read here), µs.
    pub client_latency_us: Percentiles,
    /// Its CPU over the window, per control frame published.
    pub cpu: Option<Cpu>,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// The model file.
    pub model: String,
    /// Its base vertices.
    pub vertices: usize,
    /// Its control points.
    pub control_points: usize,
    /// Where the control frames come from, and how many (looped).
    pub controls: String,
    /// The rooms' refinement as asked (`off` or `ITERATIONS,STRENGTH`).
    pub refine: String,
    /// The server under test.
    pub server: String,
    /// Logical CPUs of this machine (client and server share them).
    pub cpus: usize,
    /// The scenarios, in order.
    pub scenarios: Vec<ScenarioReport>,
}

/// A readable table on stdout: one column per scenario.
pub(super) fn print_table(report: &BenchReport) {
    println!(
        "model {} ({} vertices, {} control points), control frames {}, refinement {}",
        report.model, report.vertices, report.control_points, report.controls, report.refine
    );
    println!(
        "server {}; {} CPUs shared by the server and the clients (this process)",
        report.server, report.cpus
    );
    println!();
    let s = &report.scenarios;
    let header: Vec<String> = s
        .iter()
        .map(|r| {
            format!(
                "{} ({} x {}, {})",
                r.name, r.rooms, r.subscribers_per_room, r.transport
            )
        })
        .collect();
    println!("| | {} |", header.join(" | "));
    println!("|---|{}", "---|".repeat(s.len()));
    let row = |label: &str, cell: &dyn Fn(&ScenarioReport) -> String| {
        let cells: Vec<String> = s.iter().map(cell).collect();
        println!("| {label} | {} |", cells.join(" | "));
    };
    let pct = |p: &Percentiles| format!("{} / {} / {} / {}", p.p50, p.p90, p.p99, p.max);
    let cpu = |c: &Option<Cpu>| match c {
        Some(c) => format!("{:.2} cores, {:.3} ms/frame", c.cores, c.ms_per_frame),
        None => "n/a".to_owned(),
    };
    row("window s", &|r| format!("{:.2}", r.seconds));
    row("control frames published (per room)", &|r| {
        format!("{} ({:.1})", r.frames_published, r.published_per_room.mean)
    });
    row("refused", &|r| r.frames_refused.to_string());
    row(
        "mesh frames received (per subscriber min / mean / max)",
        &|r| {
            let p = &r.received_per_subscriber;
            format!(
                "{} ({} / {:.1} / {})",
                r.frames_received, p.min, p.mean, p.max
            )
        },
    );
    row("skipped", &|r| r.frames_skipped.to_string());
    row("server latency µs p50 / p90 / p99 / max", &|r| {
        pct(&r.server_latency_us)
    });
    row("client latency µs p50 / p90 / p99 / max", &|r| {
        pct(&r.client_latency_us)
    });
    row(
        "publish ack µs (predict + encode) p50 / p90 / p99 / max",
        &|r| pct(&r.ack_latency_us),
    );
    row(
        "fan-out µs (mesh ready -> this subscriber's task) p50 / p90 / p99 / max",
        &|r| pct(&r.fan_out_us),
    );
    row(
        "outside the server µs (client - server) p50 / p90 / p99 / max",
        &|r| pct(&r.outside_server_us),
    );
    row("server CPU", &|r| cpu(&r.server_cpu));
    row(
        "server CPU per viewer-frame µs / floor µs per write (ratio)",
        &|r| {
            let us = |v: Option<f64>| v.map_or("n/a".to_owned(), |v| format!("{v:.2}"));
            format!(
                "{} / {} ({}x)",
                us(r.server_cpu_us_per_viewer_frame),
                us(r.floor.cpu_us_per_write),
                us(r.floor_ratio)
            )
        },
    );
    row("client CPU (this process)", &|r| cpu(&r.client_cpu));
    row("bytes / vertex / frame, all", &|r| {
        format!("{:.3}", r.all_frames.bytes_per_vertex)
    });
    row("keyframes (count)", &|r| {
        format!(
            "{:.3} ({})",
            r.keyframes.bytes_per_vertex, r.keyframes.frames
        )
    });
    row("deltas (count)", &|r| {
        format!("{:.3} ({})", r.deltas.bytes_per_vertex, r.deltas.frames)
    });
    row("mesh bytes / s out", &|r| {
        format!("{:.2} MB/s", r.bytes_per_second / 1e6)
    });
    row("decoded / decode errors", &|r| {
        format!("{} / {}", r.decoded_frames, r.decode_errors)
    });
    for r in s.iter().filter(|r| !r.replicas.is_empty()) {
        println!();
        println!(
            "{}: per replica (r0 owns the room){}",
            r.name,
            r.nats_bytes_per_frame.map_or(String::new(), |b| format!(
                "; NATS {b:.0} bytes per published frame"
            ))
        );
        println!(
            "| replica | subscribers | server latency µs p50 / p99 | client latency µs p50 / p99 | CPU |"
        );
        println!("|---|---|---|---|---|");
        for f in &r.replicas {
            println!(
                "| r{} | {} | {} / {} | {} / {} | {} |",
                f.replica,
                f.subscribers,
                f.server_latency_us.p50,
                f.server_latency_us.p99,
                f.client_latency_us.p50,
                f.client_latency_us.p99,
                cpu(&f.cpu)
            );
        }
    }
    println!();
    println!(
        "server latency: control frame received -> mesh frame handed to the subscriber's stream \
         (Frame.server_latency_us); client latency: capture -> frame read here (same clock)."
    );
    for r in s {
        if let Some(e) = &r.first_refusal {
            println!("{}: first refused frame: {e}", r.name);
        }
        if let Some(e) = &r.first_decode_error {
            println!("{}: first decode error: {e}", r.name);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let mut v: Vec<u32> = (1..=100).rev().collect();
        let p = Percentiles::of(&mut v);
        assert_eq!((p.p50, p.p90, p.p99, p.max), (50, 90, 99, 100));
        assert!((p.mean - 50.5).abs() < 1e-9);
        let p = Percentiles::of(&mut [7]);
        assert_eq!((p.count, p.p50, p.p99, p.max), (1, 7, 7, 7));
        let p = Percentiles::of(&mut []);
        assert_eq!((p.count, p.p99), (0, 0));
    }
}
