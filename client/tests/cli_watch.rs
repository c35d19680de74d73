//! `crease watch` against a real server (in this process, port 0): a publisher streams control
//! frames into a room; `crease watch --frames 5 --dump DIR` decodes five frames, prints the
//! summary line and writes five OBJ meshes with the model's topology.

use crate::common;

use std::time::Duration;

use common::{CONTROLS, bent, crease, open_room, serve_tube, train_model, tube};
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;

#[test]
fn watch_decodes_frames_prints_a_summary_and_dumps_meshes() {
    let tmp = tempfile::tempdir().unwrap();
    let model = TrainedModel::load(train_model(tmp.path())).unwrap();
    let vertices = model.rig.rest.vertex_count();
    let rest_mesh = model.rig.rest.clone();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (addr, token, _served) = runtime.block_on(async {
        let served = serve_tube(model, Some("admin")).await;
        let addr = served.grpc;
        let open = v1::OpenRoomRequest {
            room: "r1".into(),
            model: "tube".into(),
            beta: 0.0,
            filter: None,
            ..Default::default()
        };
        (addr, open_room(addr, "admin", open).await, served)
    });
    // A publisher: a frame every 20 ms until the test ends.
    let rest = tube();
    let publish_token = token.clone();
    runtime.spawn(async move {
        let mut client = CreaseClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        let frames = async_frames(rest);
        let mut req = tonic::Request::new(frames);
        req.metadata_mut()
            .insert("authorization", format!("Bearer {token}").parse().unwrap());
        let mut acks = client.publish(req).await.unwrap().into_inner();
        while let Ok(Some(_)) = acks.message().await {}
    });

    // `crease CMD --server <this server> --room ROOM`.
    let on_server = |cmd: &str, room: &str| {
        let mut c = crease();
        c.args([cmd, "--server", &format!("http://{addr}"), "--room", room]);
        c
    };
    let dump = tmp.path().join("dump");
    let out = on_server("watch", "r1")
        .args(["--frames", "5", "--dump"])
        .arg(&dump)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "watch failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.starts_with("5 frames in "), "{stdout}");
    assert!(
        stdout.contains("bytes/vertex") && stdout.contains("p99"),
        "{stdout}"
    );
    for k in 0..5 {
        let m = Mesh::read(dump.join(format!("frame_{k:05}.obj"))).unwrap();
        assert_eq!(m.vertex_count(), vertices);
        // In the model's vertex order (the stream's spatial order undone): the same triangles
        // (up to meshopt's corner rotation), and the rings below the bend where they rest.
        let canonical = |t: &[u32; 3]| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let got: Vec<_> = m.triangles.iter().map(canonical).collect();
        let want: Vec<_> = rest_mesh.triangles.iter().map(canonical).collect();
        assert_eq!(got, want, "frame {k}: triangles not in model order");
        for (i, (p, r)) in m.positions.iter().zip(&rest_mesh.positions).enumerate() {
            if r.z < 3.0 {
                assert!(
                    p.distance(*r) < 0.1,
                    "frame {k} vertex {i}: {p} vs rest {r}"
                );
            }
        }
    }

    // `crease stream`: ten frames from a CSV (one with an occluded point) at 100 Hz.
    let csv = tmp.path().join("frames.csv");
    let mut text = String::new();
    for k in 0..10 {
        let pose = bent(&tube(), 0.05 * k as f32);
        let mut fields: Vec<String> = CONTROLS
            .iter()
            .flat_map(|&c| pose.positions[c].to_array())
            .map(|v| v.to_string())
            .collect();
        if k == 3 {
            fields[0..3].iter_mut().for_each(|f| f.clear());
        }
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    std::fs::write(&csv, text).unwrap();
    let out = on_server("stream", "r1")
        .args(["--token", &publish_token, "--rate", "50", "--frames"])
        .arg(&csv)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "stream failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Latest wins on the way in (server::mailbox): on a busy machine a frame that waited while
    // a stalled one ran can be superseded by the next (counted apart, never refused).
    let superseded: usize = stdout
        .split(" superseded")
        .next()
        .and_then(|s| s.rsplit(", ").next())
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or(0);
    assert!(
        stdout.starts_with("10 frames in ")
            && stdout.contains(&format!("{} acknowledged, 0 refused", 10 - superseded))
            && stdout.contains("invalid control points: 1 in 1 frames"),
        "{stdout}"
    );
    if superseded == 0 {
        assert!(stdout.contains("(server held 1)"), "{stdout}");
    }
    // A wrong token: every frame refused, and the command says so.
    let out = on_server("stream", "r1")
        .args(["--token", "wrong", "--frames"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not the publish token"));

    // An unknown room is a clear error.
    let out = on_server("watch", "none").output().unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no room"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Control frames of the tube bending back and forth, one every 20 ms, forever.
fn async_frames(rest: Mesh) -> impl tokio_stream::Stream<Item = v1::ControlFrame> + Send + 'static {
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    tokio::spawn(async move {
        for seq in 0u64.. {
            let pose = bent(&rest, 0.6 * (seq as f32 * 0.2).sin().abs());
            let frame = v1::ControlFrame {
                room: "r1".into(),
                seq,
                capture_time_us: 0,
                positions: CONTROLS
                    .iter()
                    .flat_map(|&c| pose.positions[c].to_array())
                    .collect(),
                valid: Vec::new(),
                ..Default::default()
            };
            if tx.send(frame).await.is_err() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    tokio_stream::wrappers::ReceiverStream::new(rx)
}
