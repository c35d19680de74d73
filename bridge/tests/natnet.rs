//! `crease bridge natnet`: the NatNet decoder against committed fixtures and NaturalPoint's own
//! sample decoder (PyPI `natnetsdk`), its robustness on damaged input, the marker mapping, and
//! a loopback NatNet server replaying the fixtures (and junk) to the bridge.
//!
//! Fixtures (tests/fixtures/natnet/) are written by this file's encoder calls: run
//! `NATNET_WRITE_FIXTURES=1 cargo test -p crease-bridge --test natnet` to rewrite them, then
//! `target/natnet-venv/bin/python tests/python/natnet_reference.py tests/fixtures/natnet >
//! tests/fixtures/natnet/reference.json` to refresh the reference.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::net::{Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::time::Duration;

use crease_bridge::natnet::wire::{
    self, Analog, DataDescriptions, FrameOfData, LabeledMarker, MarkerSet, MarkerSetDesc,
    RigidBody, RigidBodyDesc, RigidBodyMarkerDesc, ServerInfo, Skeleton, Timing, Version,
};
use crease_bridge::natnet::{
    Bridge, Converter, MarkerSources, Outcome, Source, SourceOptions, encode, pump,
};
use serde_json::Value;

const FINGERS: [&str; 5] = [
    "thumb_tip",
    "index_tip",
    "middle_tip",
    "ring_tip",
    "pinky_tip",
];
const HAND_ID: i32 = 1;
const FRAMES: usize = 3;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("tests/fixtures/natnet")
}

fn server_info(v: Version) -> ServerInfo {
    ServerInfo {
        name: "Motive".into(),
        app_version: if v.at_least(4, 1) {
            [3, 1, 0, 0]
        } else {
            [2, 3, 0, 0]
        },
        natnet: v,
        clock_frequency: Some(10_000_000),
        data_port: Some(1511),
        multicast: Some(false),
        multicast_group: Some([239, 255, 42, 99]),
    }
}

fn descriptions(v: Version) -> DataDescriptions {
    let names = |v: Version, n: &str| {
        if v.major >= 4 {
            n.to_owned()
        } else {
            String::new()
        }
    };
    DataDescriptions {
        marker_sets: vec![
            MarkerSetDesc {
                name: "hand".into(),
                markers: FINGERS.iter().map(|s| (*s).to_owned()).collect(),
            },
            MarkerSetDesc {
                name: "wrist".into(),
                markers: vec!["ulna".into(), "radius".into()],
            },
            MarkerSetDesc {
                name: "all".into(),
                markers: (1..=7).map(|i| format!("all_{i}")).collect(),
            },
        ],
        rigid_bodies: vec![RigidBodyDesc {
            name: "hand".into(),
            id: HAND_ID,
            parent_id: -1,
            offset: [0.0, 0.0, 0.0],
            markers: FINGERS
                .iter()
                .enumerate()
                .map(|(i, n)| RigidBodyMarkerDesc {
                    offset: [0.01 * i as f32, 0.02, -0.005 * i as f32],
                    active_label: 0,
                    name: names(v, n),
                })
                .collect(),
        }],
        ..DataDescriptions::default()
    }
}

/// The position of finger `i` in frame `k` (metres, Motive's Y up).
fn finger(k: usize, i: usize) -> [f32; 3] {
    [
        0.1 + 0.02 * i as f32 + 0.001 * k as f32,
        1.2 - 0.003 * k as f32,
        -0.25 + 0.0125 * i as f32,
    ]
}

/// Frame `k`: all fingers in marker set "hand"; labelled markers of the hand's rigid body,
/// with the middle finger occluded in frame 1 and the pinky missing in frame 2; the wrist
/// marker set; an unlabelled marker; one rigid body, one skeleton, a force plate, a device.
fn frame(k: usize, v: Version) -> FrameOfData {
    let wrist = [[0.05, 1.1, -0.3], [0.15 + 0.001 * k as f32, 1.1, -0.3]];
    let mut labeled: Vec<LabeledMarker> = (0..5)
        .filter(|&i| !(k == 2 && i == 4))
        .map(|i| LabeledMarker {
            id: (HAND_ID << 16) | (i as i32 + 1),
            position: finger(k, i),
            size: 0.012,
            params: if k == 1 && i == 2 {
                wire::MARKER_OCCLUDED | wire::MARKER_MODEL_SOLVED
            } else {
                wire::MARKER_POINT_CLOUD_SOLVED
            },
            residual: 0.0004 + 0.0001 * i as f32,
        })
        .collect();
    labeled.push(LabeledMarker {
        id: 77,
        position: [0.5, 0.5, 0.5],
        size: 0.01,
        params: 0x10,
        residual: 0.0,
    });
    let all: Vec<[f32; 3]> = (0..5).map(|i| finger(k, i)).chain(wrist).collect();
    let hand_body = RigidBody {
        id: HAND_ID,
        position: [0.2, 1.2 - 0.003 * k as f32, -0.22],
        orientation: [0.0, 0.38268343, 0.0, 0.9238795],
        mean_error: 0.0003,
        params: 1,
    };
    FrameOfData {
        frame_number: 1000 + k as i32,
        marker_sets: vec![
            MarkerSet {
                name: "hand".into(),
                markers: (0..5).map(|i| finger(k, i)).collect(),
            },
            MarkerSet {
                name: "wrist".into(),
                markers: wrist.to_vec(),
            },
            MarkerSet {
                name: "all".into(),
                markers: all,
            },
        ],
        other_markers: vec![[0.5, 0.5, 0.5]],
        rigid_bodies: vec![hand_body],
        skeletons: vec![Skeleton {
            id: 2,
            bones: vec![RigidBody {
                id: (2 << 16) | 1,
                ..hand_body
            }],
        }],
        assets: Vec::new(),
        labeled_markers: labeled,
        force_plates: vec![Analog {
            id: 5,
            channels: vec![vec![1.5, 2.5], vec![-3.0, 4.0]],
        }],
        devices: vec![Analog {
            id: 6,
            channels: vec![vec![0.25]],
        }],
        timing: Timing {
            timecode: 0,
            timecode_sub: 0,
            timestamp: 12.5 + k as f64 / 120.0,
            camera_mid_exposure: 1_000_000_000 + 83_333 * k as u64,
            camera_data_received: 1_000_020_000 + 83_333 * k as u64,
            transmit: 1_000_030_000 + 83_333 * k as u64,
            precision_secs: if v.at_least(4, 1) { 1_700_000_000 } else { 0 },
            precision_frac: if v.at_least(4, 1) {
                12345 + k as u32
            } else {
                0
            },
        },
        params: 0,
    }
}

const VERSIONS: [Version; 2] = [Version::new(3, 1), Version::new(4, 1)];

fn tag(v: Version) -> String {
    format!("{}.{}", v.major, v.minor)
}

/// Every fixture: file name and bytes.
fn fixture_set() -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for v in VERSIONS {
        out.push((
            format!("serverinfo-{}.bin", tag(v)),
            encode::server_info(&server_info(v)),
        ));
        out.push((
            format!("modeldef-{}.bin", tag(v)),
            encode::descriptions(&descriptions(v), v),
        ));
        for k in 0..FRAMES {
            out.push((
                format!("frame-{}-{k}.bin", tag(v)),
                encode::frame(&frame(k, v), v),
            ));
        }
    }
    out
}

#[test]
fn fixtures_are_what_the_encoder_writes() {
    let dir = fixtures();
    let write = std::env::var_os("NATNET_WRITE_FIXTURES").is_some();
    for (name, bytes) in fixture_set() {
        let path = dir.join(&name);
        if write {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(&path, &bytes).unwrap();
        }
        let committed = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(
            committed, bytes,
            "{name}: the committed fixture differs from the encoder"
        );
    }
}

#[test]
fn decodes_what_it_encodes() {
    for v in [
        Version::new(3, 0),
        Version::new(3, 1),
        Version::new(4, 0),
        Version::new(4, 1),
    ] {
        for k in 0..FRAMES {
            let f = frame(k, v);
            let d = wire::decode_frame(&encode::frame(&f, v), v).unwrap();
            assert_eq!(d, f, "NatNet {v} frame {k}");
        }
        let mut dd = descriptions(v);
        if v.major < 4 {
            for m in &mut dd.rigid_bodies[0].markers {
                m.name.clear();
            }
        }
        let d = wire::decode_descriptions(&encode::descriptions(&dd, v), v).unwrap();
        assert_eq!(d, dd, "NatNet {v} descriptions");
        let info = server_info(v);
        assert_eq!(
            wire::decode_server_info(&encode::server_info(&info)).unwrap(),
            info
        );
    }
}

/// The committed fixtures decoded by our decoder, as the reference script writes them.
fn ours(name: &str, bytes: &[u8]) -> Value {
    use serde_json::json;
    let v = if name.contains("-3.1") {
        Version::new(3, 1)
    } else {
        Version::new(4, 1)
    };
    if name.starts_with("serverinfo-") {
        let i = wire::decode_server_info(bytes).unwrap();
        let n = i.natnet;
        return json!({"name": i.name, "natnet": [n.major, n.minor, n.build, n.revision],
                      "app_version": i.app_version});
    }
    if name.starts_with("modeldef-") {
        let d = wire::decode_descriptions(bytes, v).unwrap();
        return json!({
            "marker_sets": d.marker_sets.iter().map(|s| json!({"name": s.name, "markers": s.markers})).collect::<Vec<_>>(),
            "rigid_bodies": d.rigid_bodies.iter().map(|b| json!({"name": b.name, "id": b.id, "parent_id": b.parent_id,
                "markers": b.markers.iter().map(|m| m.name.clone()).collect::<Vec<_>>()})).collect::<Vec<_>>(),
        });
    }
    let f = wire::decode_frame(bytes, v).unwrap();
    let vec3 = |p: &[f32]| p.iter().map(|x| f64::from(*x)).collect::<Vec<_>>();
    let analog = |a: &[Analog]| {
        a.iter()
            .map(|d| json!({"id": d.id, "channels": d.channels.iter().map(|c| vec3(c)).collect::<Vec<_>>()}))
            .collect::<Vec<_>>()
    };
    let mut out = json!({
        "frame_number": f.frame_number,
        "marker_sets": f.marker_sets.iter().map(|s| json!({"name": s.name,
            "markers": s.markers.iter().map(|p| vec3(p)).collect::<Vec<_>>()})).collect::<Vec<_>>(),
        "other_markers": f.other_markers.iter().map(|p| vec3(p)).collect::<Vec<_>>(),
        "rigid_bodies": f.rigid_bodies.iter().map(|b| json!({"id": b.id, "position": vec3(&b.position),
            "orientation": vec3(&b.orientation), "mean_error": f64::from(b.mean_error),
            "tracking_valid": b.tracking_valid()})).collect::<Vec<_>>(),
        "skeletons": f.skeletons.iter().map(|s| json!({"id": s.id,
            "bones": s.bones.iter().map(|b| b.id).collect::<Vec<_>>()})).collect::<Vec<_>>(),
        "labeled_markers": f.labeled_markers.iter().map(|m| json!({"id": m.id, "model_id": m.model_id(),
            "marker_id": m.marker_id(), "position": vec3(&m.position), "size": f64::from(m.size),
            "params": m.params, "occluded": m.occluded(),
            "residual_mm": f64::from(m.residual) * 1000.0})).collect::<Vec<_>>(),
        "force_plates": analog(&f.force_plates),
        "devices": analog(&f.devices),
        "timecode": f.timing.timecode,
        "timecode_sub": f.timing.timecode_sub,
        "timestamp": f.timing.timestamp,
        "camera_mid_exposure": f.timing.camera_mid_exposure,
        "camera_data_received": f.timing.camera_data_received,
        "transmit": f.timing.transmit,
        "params": f.params,
    });
    if v.at_least(4, 1) {
        out["assets"] = json!(f.assets.len());
    }
    out
}

/// Compares two JSON values, numbers within `tol` relative (the sample's residual is scaled
/// by 1000 in double precision).
fn same(a: &Value, b: &Value, path: &str, tol: f64) -> Result<(), String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (x - y).abs() <= tol * x.abs().max(y.abs()) {
                Ok(())
            } else {
                Err(format!("{path}: {x} vs {y}"))
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            if x.len() != y.len() {
                return Err(format!("{path}: {} vs {} entries", x.len(), y.len()));
            }
            x.iter()
                .zip(y)
                .enumerate()
                .try_for_each(|(i, (x, y))| same(x, y, &format!("{path}[{i}]"), tol))
        }
        (Value::Object(x), Value::Object(y)) => {
            let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            keys.into_iter()
                .try_for_each(|k| match (x.get(k), y.get(k)) {
                    (Some(x), Some(y)) => same(x, y, &format!("{path}.{k}"), tol),
                    _ => Err(format!("{path}.{k}: only on one side")),
                })
        }
        _ if a == b => Ok(()),
        _ => Err(format!("{path}: {a} vs {b}")),
    }
}

fn committed_reference() -> Value {
    let path = fixtures().join("reference.json");
    serde_json::from_str(
        &std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap()
}

#[test]
fn decoder_agrees_with_the_committed_reference() {
    let reference = committed_reference();
    let mut compared = 0;
    for (name, bytes) in fixture_set() {
        let theirs = reference
            .get(&name)
            .unwrap_or_else(|| panic!("reference.json has no {name}"));
        if let Err(e) = same(&ours(&name, &bytes), theirs, &name, 1e-9) {
            panic!("our decoder and natnetsdk disagree on {e}");
        }
        compared += 1;
    }
    assert_eq!(compared, 2 * (2 + FRAMES));
}

/// A python with natnetsdk: target/natnet-venv, made if missing (None, with the reason, when
/// python3, venv or pip are unavailable, e.g. without a network).
fn reference_python() -> Result<PathBuf, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let venv = root.join("target/natnet-venv");
    let py = venv.join("bin/python");
    let has_sdk = |py: &Path| {
        std::process::Command::new(py)
            .args(["-c", "import natnetsdk.NatNetClient"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if has_sdk(&py) {
        return Ok(py);
    }
    let made = std::process::Command::new("python3")
        .args(["-m", "venv"])
        .arg(&venv)
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    if !made.status.success() {
        return Err(format!(
            "python3 -m venv: {}",
            String::from_utf8_lossy(&made.stderr)
        ));
    }
    let pip = std::process::Command::new(venv.join("bin/pip"))
        .args(["install", "-q", "-r"])
        .arg(root.join("tests/python/requirements-natnet.txt"))
        .output()
        .map_err(|e| format!("pip: {e}"))?;
    if !pip.status.success() || !has_sdk(&py) {
        return Err(format!(
            "pip install natnetsdk: {}",
            String::from_utf8_lossy(&pip.stderr)
        ));
    }
    Ok(py)
}

#[test]
fn decoder_agrees_with_natnetsdk_run_now() {
    let py = match reference_python() {
        Ok(p) => p,
        Err(why) => {
            println!(
                "skipped: no natnetsdk to run ({why}); the committed reference.json is still checked"
            );
            return;
        }
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = std::process::Command::new(py)
        .arg(root.join("tests/python/natnet_reference.py"))
        .arg(fixtures())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "natnet_reference.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let now: Value = serde_json::from_slice(&out.stdout).unwrap();
    same(&now, &committed_reference(), "reference", 0.0).unwrap_or_else(|e| {
        panic!("natnetsdk's output differs from the committed reference.json: {e}")
    });
    for (name, bytes) in fixture_set() {
        same(&ours(&name, &bytes), &now[&name], &name, 1e-9)
            .unwrap_or_else(|e| panic!("our decoder and natnetsdk disagree on {e}"));
    }
}

#[test]
fn damaged_datagrams_are_errors_not_panics() {
    for (name, bytes) in fixture_set() {
        let v = if name.contains("-3.1") {
            Version::new(3, 1)
        } else {
            Version::new(4, 1)
        };
        // Every truncation fails, naming a field and an offset inside the datagram.
        let whole_suffix = if name.starts_with("frame-") { 4 } else { 0 };
        for n in 0..bytes.len().saturating_sub(whole_suffix) {
            if let Err(e) = wire::decode(&bytes[..n], v) {
                assert!(
                    e.offset <= n,
                    "{name}[..{n}]: offset {} past the end",
                    e.offset
                );
                assert!(!e.field.is_empty());
            } else if name.starts_with("frame-") {
                panic!("{name} cut to {n} of {} bytes decoded", bytes.len());
            }
        }
        // Every single-byte corruption decodes or fails, never panics.
        for i in 0..bytes.len() {
            for x in [0x00, 0xff, 0x80, 0x7f] {
                let mut b = bytes.clone();
                b[i] = x;
                let _ = wire::decode(&b, v);
            }
        }
    }
    let e = wire::decode_frame(
        &encode::frame(&frame(0, Version::new(4, 1)), Version::new(4, 1)),
        Version::new(2, 9),
    )
    .unwrap_err();
    assert!(e.to_string().contains("2.9.0.0"), "{e}");
    // A labelled marker count larger than the datagram could hold is refused before allocating.
    let mut b = encode::frame(&frame(0, Version::new(3, 1)), Version::new(3, 1));
    let e = wire::decode_frame(&b[..30], Version::new(3, 1)).unwrap_err();
    assert!(e.to_string().contains("at byte"), "{e}");
    b[8..12].copy_from_slice(&i32::MAX.to_le_bytes());
    let e = wire::decode_frame(&b, Version::new(3, 1)).unwrap_err();
    assert_eq!(e.offset, 8, "{e}");
    assert!(
        e.field.contains("marker set") && e.field.contains("count"),
        "{e}"
    );
}

fn declared() -> Vec<String> {
    [
        "hand:thumb_tip",
        "index_tip",
        "middle_tip",
        "ring_tip",
        "pinky_tip",
        "wrist:ulna",
        "radius",
    ]
    .iter()
    .map(|s| (*s).to_owned())
    .collect()
}

#[test]
fn markers_map_by_name_with_occlusion_and_missing() {
    for v in VERSIONS {
        let map = MarkerSources::resolve(&declared(), &descriptions(v)).unwrap();
        let mut c = Converter::new(map);
        for k in 0..FRAMES {
            let m = c.markers(&frame(k, v));
            let mut want_valid = vec![true; 7];
            if k == 1 {
                want_valid[2] = false;
            }
            if k == 2 {
                want_valid[4] = false;
            }
            assert_eq!(m.valid, want_valid, "NatNet {v} frame {k}");
            for (i, ok) in want_valid.iter().take(5).enumerate() {
                // An occluded or missing marker holds its last valid position.
                let want = if *ok { finger(k, i) } else { finger(k - 1, i) };
                assert_eq!(
                    m.positions[3 * i..3 * i + 3],
                    want,
                    "NatNet {v} frame {k} marker {i}"
                );
            }
            assert_eq!(m.positions[15..18], frame(k, v).marker_sets[1].markers[0]);
        }
    }
    let dd = descriptions(Version::new(4, 1));
    let e = MarkerSources::resolve(&["hand:nail".to_owned()], &dd)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("\"hand:nail\"") && e.contains("hand:thumb_tip"),
        "{e}"
    );
    let e = MarkerSources::resolve(&["elbow".to_owned()], &dd)
        .unwrap_err()
        .to_string();
    assert!(e.contains("\"elbow\""), "{e}");
    let mut twice = dd.clone();
    twice.marker_sets[1].markers.push("thumb_tip".into());
    let e = MarkerSources::resolve(&["thumb_tip".to_owned()], &twice)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ambiguous") && e.contains("hand:thumb_tip") && e.contains("wrist:thumb_tip"),
        "{e}"
    );
}

#[test]
fn bridge_frames_carry_markers_valid_and_count_junk() {
    let v = Version::new(4, 1);
    let map = MarkerSources::resolve(&declared(), &descriptions(v)).unwrap();
    let mut b = Bridge::new(v, Some(&server_info(v)), "room", map);
    let mut seqs = Vec::new();
    for k in 0..FRAMES {
        match b.datagram(&encode::frame(&frame(k, v), v), 1_000_000) {
            Outcome::Frame(f, invalid) => {
                assert_eq!(f.room, "room");
                assert_eq!(f.markers.len(), 21);
                assert!(f.positions.is_empty());
                // 3 ms from mid-exposure to transmit at 10 MHz.
                assert_eq!(f.capture_time_us, 1_000_000 - 3000);
                assert_eq!(f.markers_valid.is_empty(), invalid == 0);
                seqs.push(f.seq);
            }
            o => panic!("frame {k}: {o:?}"),
        }
    }
    assert_eq!(seqs, [0, 1, 2]);
    assert!(matches!(
        b.datagram(b"\x07\x00\xff\xff", 0),
        Outcome::Dropped(_)
    ));
    assert!(matches!(
        b.datagram(&[7, 0, 4, 0, 1, 2, 3, 4], 0),
        Outcome::Dropped(_)
    ));
    assert!(matches!(
        b.datagram(&encode::server_info(&server_info(v)), 0),
        Outcome::Ignored(1)
    ));
    let c = b.counters.lock().unwrap();
    assert_eq!(
        (c.frames_in, c.dropped, c.ignored, c.invalid_markers),
        (3, 2, 1, 2)
    );
}

/// A NatNet test server on 127.0.0.1: answers NAT_CONNECT and NAT_REQUEST_MODELDEF, then
/// replays `datagrams` to the client's data address `data` once it has asked for models.
async fn test_server(
    v: Version,
    datagrams: Vec<Vec<u8>>,
) -> (
    SocketAddr,
    tokio::sync::oneshot::Sender<SocketAddr>,
    tokio::task::JoinHandle<()>,
) {
    let sock = tokio::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .await
        .unwrap();
    let addr = sock.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<SocketAddr>();
    let task = tokio::spawn(async move {
        let mut buf = vec![0u8; 65536];
        let mut rx = Some(rx);
        loop {
            let (n, from) = sock.recv_from(&mut buf).await.unwrap();
            match wire::header(&buf[..n]).map(|h| h.0) {
                Ok(wire::NAT_CONNECT) => {
                    // The client asks for 4.1 in bytes 265..269 of its payload.
                    assert_eq!(&buf[4..8], b"Ping");
                    assert_eq!(buf[4 + 265], 4);
                    sock.send_to(&encode::server_info(&server_info(v)), from)
                        .await
                        .unwrap();
                }
                Ok(wire::NAT_REQUEST_MODELDEF) => {
                    sock.send_to(&encode::descriptions(&descriptions(v), v), from)
                        .await
                        .unwrap();
                    let data = rx.take().unwrap().await.unwrap();
                    for d in &datagrams {
                        sock.send_to(d, data).await.unwrap();
                        tokio::time::sleep(Duration::from_millis(2)).await;
                    }
                }
                _ => {}
            }
        }
    });
    (addr, tx, task)
}

#[tokio::test]
async fn loopback_natnet_server_to_control_frames() {
    for v in VERSIONS {
        let t = tag(v);
        let dir = fixtures();
        let mut datagrams = Vec::new();
        let junk: Vec<Vec<u8>> = vec![
            vec![1, 2],
            b"\x07\x00\x10\x00not a frame".to_vec(),
            vec![0xff; 300],
            // A frame cut short.
            std::fs::read(dir.join(format!("frame-{t}-0.bin"))).unwrap()[..40].to_vec(),
        ];
        let mut frames = 0;
        for bad in &junk {
            for k in 0..FRAMES {
                datagrams.push(std::fs::read(dir.join(format!("frame-{t}-{k}.bin"))).unwrap());
                frames += 1;
            }
            datagrams.push(bad.clone());
        }
        // The last datagram is a frame, so every junk datagram is received before it.
        datagrams.push(std::fs::read(dir.join(format!("frame-{t}-0.bin"))).unwrap());
        frames += 1;
        let (addr, data_tx, server) = test_server(v, datagrams).await;
        let opts = SourceOptions {
            command: addr,
            local: Ipv4Addr::LOCALHOST,
            multicast: None,
            data_port: 0,
            timeout: Duration::from_secs(5),
        };
        let mut source = Source::connect(&opts).await.unwrap();
        assert_eq!(source.info.natnet, v);
        assert_eq!(source.descriptions.marker_sets.len(), 3);
        data_tx.send(source.data_addr().unwrap()).unwrap();
        let map = MarkerSources::resolve(&declared(), &source.descriptions).unwrap();
        let mut bridge = Bridge::new(v, Some(&source.info), "r", map);
        let (tx, mut rx) = tokio::sync::mpsc::channel(256);
        let mut sink = tx.into();
        tokio::time::timeout(
            Duration::from_secs(20),
            pump(&mut source, &mut bridge, &mut sink, Some(frames), None),
        )
        .await
        .expect("every frame arrives")
        .unwrap();
        drop(sink);
        let mut got = Vec::new();
        while let Some(f) = rx.recv().await {
            got.push(f);
        }
        server.abort();
        assert_eq!(got.len() as u64, frames, "NatNet {v}");
        for (i, f) in got.iter().enumerate() {
            assert_eq!(f.seq, i as u64, "NatNet {v}: in order");
            let k = i % FRAMES;
            let k = if i as u64 == frames - 1 { 0 } else { k };
            // Marker 0 (hand:thumb_tip) is always seen: its position is frame k's.
            assert_eq!(f.markers[..3], finger(k, 0), "NatNet {v} frame {i}");
            assert_eq!(f.markers_valid.is_empty(), k == 0, "NatNet {v} frame {i}");
        }
        let c = bridge.counters.lock().unwrap();
        assert_eq!(c.frames_in, frames);
        assert_eq!(c.published, frames);
        assert_eq!(c.dropped, 4, "NatNet {v}: the junk datagrams are counted");
    }
}
