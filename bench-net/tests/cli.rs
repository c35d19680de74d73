//! `crease-bench` (also `crease bench-net`) on the tiny tube model of crease-testkit: a short
//! run against a real server in this process (port 0), checked through its JSON report; the
//! spawned-server path when the `crease-server` binary has been built beside `crease-bench` (a
//! workspace build); clear errors for a missing server binary, a running server without an
//! admin token, and bad options.
//!
//! The server runs in the test process because crease-server is only a dev-dependency here (its
//! library, not its binary): `--server URL --server-pid <this process>` drives the same rooms,
//! publishers, subscribers and CPU reading as a spawned server.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::path::{Path, PathBuf};
use std::process::Command;

use crease_core::model::TrainedModel;
use crease_testkit::model::{bent_mesh as bent, tube};
use crease_testkit::server::serve_model;
use serde_json::Value;

/// The tube model's control points (crease-testkit's `model`).
const CONTROLS: [usize; 3] = [0, 45, 42];

fn bench() -> Command {
    Command::new(env!("CARGO_BIN_EXE_crease-bench"))
}

/// crease-testkit's tube model, written as `tube.crease` (the benchmark names rooms' model by
/// the file's stem).
fn train_model(dir: &Path) -> PathBuf {
    let model = crease_testkit::model::model();
    let path = dir.join("tube.crease");
    model.save(&path).unwrap();
    path
}

/// A CSV of control frames: the tube bending forth and back, 12 frames.
fn write_controls(dir: &Path) -> PathBuf {
    let csv = dir.join("controls.csv");
    let mut text = String::from("# x,y,z of the tube's control points\n");
    for k in 0..12 {
        let angle = 0.08 * (6 - (k - 6i32).abs()) as f32;
        let pose = bent(&tube(), angle);
        let fields: Vec<String> = CONTROLS
            .iter()
            .flat_map(|&c| pose.positions[c].to_array())
            .map(|v| v.to_string())
            .collect();
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    std::fs::write(&csv, text).unwrap();
    csv
}

/// The arguments of a short run: 2 rooms x 3 subscribers, 30 Hz, 0.5 s + 1 s, JSON.
const SHORT_RUN: [&str; 11] = [
    "--rooms",
    "2",
    "--subscribers",
    "3",
    "--seconds",
    "1",
    "--warmup",
    "0.5",
    "--rate",
    "30",
    "--json",
];

fn u(v: &Value) -> u64 {
    v.as_u64()
        .unwrap_or_else(|| panic!("{v} is not an unsigned integer"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

/// Percentiles that are positive and ordered.
fn check_percentiles(p: &Value, what: &str) {
    let (p50, p90, p99, max) = (u(&p["p50"]), u(&p["p90"]), u(&p["p99"]), u(&p["max"]));
    assert!(
        0 < p50 && p50 <= p90 && p90 <= p99 && p99 <= max,
        "{what}: {p}"
    );
    assert!(u(&p["count"]) > 0, "{what}: {p}");
}

/// What every short run must show, whichever server ran it: one scenario per transport, in
/// `transports`' order.
fn check_short_run(stdout: &[u8], transports: &[&str]) -> Value {
    let report: Value = serde_json::from_slice(stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(stdout)));
    assert_eq!(u(&report["vertices"]), tube().vertex_count() as u64);
    assert_eq!(u(&report["control_points"]), CONTROLS.len() as u64);
    let scenarios = report["scenarios"].as_array().unwrap();
    assert_eq!(scenarios.len(), transports.len(), "{report}");
    for (s, transport) in scenarios.iter().zip(transports) {
        assert_eq!(s["transport"], *transport, "{s}");
        check_scenario(s);
    }
    report
}

/// One scenario of a short run (2 rooms x 3 subscribers).
fn check_scenario(s: &Value) {
    assert_eq!((u(&s["rooms"]), u(&s["subscribers_per_room"])), (2, 3));
    assert_eq!(u(&s["frames_refused"]), 0, "{s}");
    assert_eq!(u(&s["decode_errors"]), 0, "{s}");
    assert!(u(&s["decoded_frames"]) > 0, "{s}");

    // Every subscriber received frames, about as many as its room published in the window:
    // never more (bar the window's two edges), and skips (latest-wins) may make them fewer.
    let published = &s["published_per_room"];
    let received = &s["received_per_subscriber"];
    assert!(u(&published["min"]) > 0, "{s}");
    assert!(
        u(&received["min"]) > 0,
        "a subscriber received nothing: {s}"
    );
    assert!(u(&received["max"]) <= u(&published["max"]) + 2, "{s}");
    assert!(2 * u(&received["min"]) >= u(&published["min"]), "{s}");
    assert_eq!(
        u(&s["frames_received"]),
        u(&s["keyframes"]["frames"]) + u(&s["deltas"]["frames"])
    );
    assert_eq!(u(&s["frames_received"]), u(&s["all_frames"]["frames"]));

    check_percentiles(&s["server_latency_us"], "server latency");
    check_percentiles(&s["client_latency_us"], "client latency");
    check_percentiles(&s["ack_latency_us"], "ack latency");
    // Per frame, the client's span (capture -> read) contains the server's (received ->
    // handed to the stream), so every order statistic of the same frames does too.
    for k in ["p50", "p90", "p99", "max"] {
        assert!(
            u(&s["client_latency_us"][k]) + 1 >= u(&s["server_latency_us"][k]),
            "{k}: client {} < server {}",
            s["client_latency_us"],
            s["server_latency_us"]
        );
    }
    // A codec frame of 48 vertices: more than nothing, less than a 16-bit keyframe's
    // 4 lanes x 2 bytes per vertex plus its 52-byte header.
    let bpv = f(&s["all_frames"]["bytes_per_vertex"]);
    let header = 52.0 / tube().vertex_count() as f64;
    assert!(bpv > 0.0 && bpv < 8.0 + header, "bytes/vertex {bpv}");
    assert!(f(&s["bytes_per_second"]) > 0.0);
    if cfg!(target_os = "linux") {
        let cpu = &s["server_cpu"];
        assert!(
            f(&cpu["cores"]) >= 0.0 && f(&cpu["ms_per_frame"]) >= 0.0,
            "{s}"
        );
    }
    // The floor wrote a frame-sized message to as many sockets as there were subscribers,
    // at the run's rate over its window (1 s at 30 Hz); its CPU is too little for /proc's
    // ticks, so only the wall time is given, and no ratio.
    let floor = &s["floor"];
    assert_eq!(u(&floor["sockets"]), 6, "{s}");
    assert_eq!(u(&floor["writes"]), 6 * 30, "{s}");
    let mean = u(&s["all_frames"]["bytes"]) / u(&s["all_frames"]["frames"]);
    assert_eq!(u(&floor["bytes"]), mean.max(1), "{s}");
    assert!(f(&floor["wall_us_per_write"]) > 0.0, "{s}");
    if floor["cpu_us_per_write"].is_null() {
        assert!(s["floor_ratio"].is_null(), "{s}");
    }
}

#[test]
fn bench_net_against_a_server_in_this_process() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = train_model(tmp.path());
    let controls = write_controls(tmp.path());
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let served = runtime.block_on(async {
        serve_model(
            "tube",
            &TrainedModel::load(&model_path).unwrap(),
            Some("admin"),
            crease_server::Limits::default(),
        )
        .await
    });
    let addr = served.grpc;
    let out = bench()
        .arg("--model")
        .arg(&model_path)
        .arg("--controls")
        .arg(&controls)
        .args([
            "--server",
            &format!("http://{addr}"),
            "--admin-token",
            "admin",
        ])
        .args(["--server-pid", &std::process::id().to_string()])
        .args(["--server-http", &served.http.to_string()])
        .args(["--transport", "both"])
        .args(SHORT_RUN)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "bench-net failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The same rooms and frames over gRPC, then over the browsers' WebSocket.
    let report = check_short_run(&out.stdout, &["grpc", "websocket"]);
    assert!(
        report["server"]
            .as_str()
            .unwrap()
            .contains(&addr.to_string()),
        "{report}"
    );
}

#[test]
fn bench_net_spawns_the_server_binary_when_it_is_built() {
    let bin = Path::new(env!("CARGO_BIN_EXE_crease-bench"))
        .with_file_name(format!("crease-server{}", std::env::consts::EXE_SUFFIX));
    if !bin.is_file() {
        // `cargo test -p crease-bench` builds only this package's binaries; a workspace test
        // run (or `cargo build -p crease-server`) puts the server beside `crease-bench`.
        eprintln!("skipped: {} is not built", bin.display());
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let model_path = train_model(tmp.path());
    let controls = write_controls(tmp.path());
    let out = bench()
        .arg("--model")
        .arg(&model_path)
        .arg("--controls")
        .arg(&controls)
        .env_remove("CREASE_ADMIN_TOKEN")
        .args(SHORT_RUN)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "bench-net failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = check_short_run(&out.stdout, &["grpc"]);
    assert!(report["server"].as_str().unwrap().contains("spawned"));
    if cfg!(target_os = "linux") {
        // The child's own CPU is measured (it is null for a server in another process). It
        // may read 0: /proc counts in 10 ms ticks, and a one-second run on a small tube can
        // use less than one.
        let cpu = &report["scenarios"][0]["server_cpu"];
        assert!(
            cpu.is_object(),
            "no server CPU for a spawned server: {report}"
        );
        let ms = f(&cpu["ms_per_frame"]);
        assert!(ms.is_finite() && ms >= 0.0, "{report}");
    }
}

#[test]
fn bench_net_says_how_to_build_a_missing_server_and_needs_an_admin_token() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = train_model(tmp.path());
    let controls = write_controls(tmp.path());
    let run = |extra: &[&str]| {
        let out = bench()
            .arg("--model")
            .arg(&model_path)
            .arg("--controls")
            .arg(&controls)
            .env_remove("CREASE_ADMIN_TOKEN")
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let missing = tmp.path().join("no-such-server");
    let err = run(&["--server-bin", missing.to_str().unwrap()]);
    assert!(
        err.contains("no crease-server binary")
            && err.contains("cargo build --release -p crease-demo"),
        "{err}"
    );
    let err = run(&["--server", "http://127.0.0.1:9"]);
    assert!(err.contains("--admin-token"), "{err}");
    // The chaos soak's options are checked before anything starts.
    let err = run(&["--chaos", "1", "--chaos-lease-ms", "50"]);
    assert!(
        err.contains("--chaos-lease-ms must be 100 to 60000, got 50"),
        "{err}"
    );
    // --nats-bin means nothing without a run that starts NATS.
    let err = run(&["--nats-bin", "/usr/sbin/nats-server"]);
    assert!(
        err.contains("--replicas") && err.contains("--chaos"),
        "{err}"
    );
    // The control file must fit the model's five control points.
    let bad = tmp.path().join("bad.csv");
    std::fs::write(&bad, "1,2,3\n").unwrap();
    let out = bench()
        .arg("--model")
        .arg(&model_path)
        .arg("--controls")
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("expected 9"), "{err}");
}
