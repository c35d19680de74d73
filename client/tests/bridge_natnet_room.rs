//! `crease bridge natnet` end to end (issue 19): a loopback NatNet test server replays the
//! committed 3.1 and 4.1 fixtures (tests/fixtures/natnet/, with junk datagrams between them)
//! over UDP to the real `crease` binary, which publishes them into a retargeting room of a
//! crease server running in this process; a subscriber decodes the room's base meshes and
//! checks that every frame was acknowledged and that the mesh follows the markers.

use crate::common;

use std::collections::BTreeMap;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crease_bridge::natnet::wire::{self, Version};
use crease_bridge::natnet::{Converter, MarkerSources};
use crease_core::codec::FrameDecoder;
use crease_core::glam::Vec3;
use crease_proto::v1;

const FRAMES: usize = 3;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("tests/fixtures/natnet")
}

fn fixture(name: &str) -> Vec<u8> {
    let path = fixtures().join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The room's declared markers: the NatNet names the bridge publishes (five fingertips of
/// marker set "hand", two wrist markers of "wrist").
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

/// The tube's five control points (a base vertex, two at mid height, two at the tip), in
/// order, driven by these markers: of the assignments of the fixture's markers, the one a
/// similarity puts closest to the rest tube's control points (RMS 1.01 model units; the
/// fixture's markers are not a tube, so no assignment does much better).
const DRIVERS: [&str; 5] = [
    "wrist:ulna",
    "index_tip",
    "hand:thumb_tip",
    "pinky_tip",
    "ring_tip",
];

fn map_toml(controls: &[String]) -> String {
    let mut map = format!(
        "[registration]\npoints = [{}]\ncalibration_frames = 3\n[markers]\n",
        controls
            .iter()
            .map(|c| format!("{c:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (c, m) in controls.iter().zip(DRIVERS) {
        map += &format!("{c} = {m:?}\n");
    }
    map
}

/// The replay: frames 0, 1, 2 then a junk datagram, four times, then frame 0 again (so every
/// junk datagram is received before the last frame). Returns the datagrams and the fixture
/// frame index of each frame in order.
fn replay(t: &str) -> (Vec<Vec<u8>>, Vec<usize>) {
    let junk: Vec<Vec<u8>> = vec![
        vec![1, 2],
        b"\x07\x00\x10\x00not a frame".to_vec(),
        vec![0xff; 300],
        fixture(&format!("frame-{t}-0.bin"))[..40].to_vec(),
    ];
    let (mut datagrams, mut order) = (Vec::new(), Vec::new());
    for bad in junk {
        for k in 0..FRAMES {
            datagrams.push(fixture(&format!("frame-{t}-{k}.bin")));
            order.push(k);
        }
        datagrams.push(bad);
    }
    datagrams.push(fixture(&format!("frame-{t}-0.bin")));
    order.push(0);
    (datagrams, order)
}

/// A NatNet test server on 127.0.0.1 answering from the fixtures: NAT_CONNECT gets
/// serverinfo-T.bin, NAT_REQUEST_MODELDEF gets modeldef-T.bin, and the first model request
/// starts the replay to the address it came from (the bridge's command socket: with
/// `--data-port 0` its data port is not known here, and a unicast server may send frames to the
/// command socket). Keep-alives and repeated requests are answered or ignored.
async fn natnet_server(t: String, datagrams: Vec<Vec<u8>>) -> std::net::SocketAddr {
    let sock = tokio::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .await
        .unwrap();
    let addr = sock.local_addr().unwrap();
    let info = fixture(&format!("serverinfo-{t}.bin"));
    let modeldef = fixture(&format!("modeldef-{t}.bin"));
    tokio::spawn(async move {
        let mut buf = vec![0u8; 65536];
        let mut replayed = false;
        loop {
            let Ok((n, from)) = sock.recv_from(&mut buf).await else {
                // ICMP port unreachable once the bridge has gone.
                continue;
            };
            match wire::header(&buf[..n]).map(|h| h.0) {
                Ok(wire::NAT_CONNECT) => {
                    let _ = sock.send_to(&info, from).await;
                }
                Ok(wire::NAT_REQUEST_MODELDEF) => {
                    let _ = sock.send_to(&modeldef, from).await;
                    if !replayed {
                        replayed = true;
                        // Give the bridge time to open its publish stream.
                        tokio::time::sleep(Duration::from_millis(300)).await;
                        for d in &datagrams {
                            sock.send_to(d, from).await.unwrap();
                            tokio::time::sleep(Duration::from_millis(20)).await;
                        }
                    }
                }
                _ => {}
            }
        }
    });
    addr
}

/// Decoded base meshes of `room` (model vertex order) by seq, until `last` arrives.
async fn meshes(
    addr: std::net::SocketAddr,
    room: &str,
) -> (
    tokio::sync::oneshot::Receiver<BTreeMap<u64, Vec<Vec3>>>,
    tokio::sync::watch::Sender<Option<u64>>,
) {
    let mut client =
        crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
    let mut sub = client
        .subscribe(v1::SubscribeRequest {
            room: room.into(),
            level: v1::Level::Base as i32,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let first = sub.message().await.unwrap().unwrap();
    let Some(v1::mesh_frame::Body::Topology(topo)) = first.body else {
        panic!("first message is not the topology: {first:?}");
    };
    let topology = crease_proto::read_topology(&topo).unwrap();
    let (done_tx, done_rx) = tokio::sync::oneshot::channel();
    let (last_tx, mut last_rx) = tokio::sync::watch::channel(None::<u64>);
    tokio::spawn(async move {
        let mut decoder = FrameDecoder::new(topology.vertex_count);
        let mut out = BTreeMap::new();
        let (mut streamed, mut model) = (Vec::new(), Vec::new());
        loop {
            let last = *last_rx.borrow();
            if last.is_some_and(|l| out.contains_key(&l)) {
                break;
            }
            let msg = tokio::select! {
                m = sub.message() => m,
                _ = last_rx.changed() => continue,
            };
            let Ok(Some(msg)) = msg else { break };
            let Some(v1::mesh_frame::Body::Frame(f)) = msg.body else {
                continue;
            };
            decoder
                .decode(&f.data)
                .unwrap_or_else(|e| panic!("frame {}: {e}", f.seq));
            decoder.positions(&mut streamed);
            topology.to_model_order(&streamed, &mut model);
            out.insert(f.seq, model.clone());
        }
        let _ = done_tx.send(out);
    });
    (done_rx, last_tx)
}

fn rms(a: &[Vec3], b: &[Vec3]) -> f32 {
    (a.iter()
        .zip(b)
        .map(|(p, q)| p.distance_squared(*q))
        .sum::<f32>()
        / a.len() as f32)
        .sqrt()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crease_bridge_natnet_replayed_fixtures_drive_a_retargeting_rooms_mesh() {
    let tmp = tempfile::tempdir().unwrap();
    let model = crease_core::model::TrainedModel::load(common::train_model(tmp.path())).unwrap();
    let controls: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    assert_eq!(controls.len(), DRIVERS.len());
    let rest: Vec<Vec3> = model
        .controls
        .iter()
        .map(|c| model.rig.rest.positions[c.vertex as usize])
        .collect();
    let vertices: Vec<usize> = model.controls.iter().map(|c| c.vertex as usize).collect();
    let served = common::serve_tube(model, Some("admin")).await;
    let addr = served.grpc;
    let map = map_toml(&controls);

    for v in [Version::new(3, 1), Version::new(4, 1)] {
        let t = format!("{}.{}", v.major, v.minor);
        let room = format!("natnet-{}-{}", v.major, v.minor);
        let token = common::open_room(
            addr,
            "admin",
            v1::OpenRoomRequest {
                room: room.clone(),
                model: "tube".into(),
                retarget: Some(v1::Retarget {
                    map_toml: map.clone(),
                    markers: declared(),
                    units: "m".into(),
                    ..Default::default()
                }),
                ..Default::default()
            },
        )
        .await;
        let (datagrams, order) = replay(&t);
        let n = order.len() as u64;
        let (got, last_tx) = meshes(addr, &room).await;
        let natnet = natnet_server(t.clone(), datagrams).await;
        let out = tokio::task::spawn_blocking({
            let (room, token) = (room.clone(), token.clone());
            move || {
                common::crease()
                    .args(["bridge", "natnet", "--server", &format!("http://{addr}")])
                    .args(["--room", &room, "--token", &token])
                    .args(["--natnet", &natnet.to_string(), "--data-port", "0"])
                    .args(["--local", "127.0.0.1", "--frames", &n.to_string()])
                    .args(["--connect-timeout", "10", "--summary-every", "1"])
                    .output()
                    .unwrap()
            }
        });
        let out = tokio::time::timeout(Duration::from_secs(60), out)
            .await
            .expect("the bridge ends within 60 s")
            .unwrap();
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        println!("NatNet {t}: bridge stderr:\n{stderr}\nstdout:\n{stdout}");
        assert!(out.status.success(), "crease bridge natnet failed");
        let done = stdout
            .lines()
            .rev()
            .find(|l| l.starts_with("natnet: "))
            .unwrap();
        assert!(
            done.contains(&format!(
                "natnet: {n} frames in, {n} published ({n} acked, 0 refused), 4 dropped (malformed)"
            )),
            "NatNet {t}: every replayed frame acknowledged, the junk counted: {done}"
        );
        // Invalid markers: the middle finger in frame 1 and the pinky in frame 2, four times.
        assert!(done.contains("8 invalid markers"), "{done}");
        let mut client =
            crease_proto::v1::crease_client::CreaseClient::connect(format!("http://{addr}"))
                .await
                .unwrap();
        let info = client
            .get_room(v1::GetRoomRequest { room: room.clone() })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(info.published, n, "NatNet {t}: GetRoom's published count");

        last_tx.send(Some(n - 1)).unwrap();
        let meshes = tokio::time::timeout(Duration::from_secs(20), got)
            .await
            .expect("the last mesh arrives")
            .unwrap();
        assert!(
            meshes.contains_key(&(n - 1)),
            "NatNet {t}: the last frame's mesh"
        );

        // What the room received, recomputed: the bridge's marker mapping (the code the binary
        // runs) over the replayed fixtures, registered here by crease-mocap as the room does.
        let descriptions =
            wire::decode_descriptions(&fixture(&format!("modeldef-{t}.bin")), v).unwrap();
        let mut converter =
            Converter::new(MarkerSources::resolve(&declared(), &descriptions).unwrap());
        let mocap_map =
            crease_mocap::map::MarkerMap::parse(Path::new("natnet.toml"), &map).unwrap();
        let recording = crease_mocap::Recording::new(declared(), 0.0, "m", Vec::new(), Vec::new());
        let bound = mocap_map.bind(&recording, &controls).unwrap();
        let mut local = crease_mocap::Retarget::new(bound, &rest);
        let mut sent: Vec<Vec<f32>> = Vec::new();
        let mut registered: Vec<(Vec<Vec3>, Vec<bool>)> = Vec::new();
        for (i, &k) in order.iter().enumerate() {
            let f = wire::decode_frame(&fixture(&format!("frame-{t}-{k}.bin")), v).unwrap();
            let m = converter.markers(&f);
            let positions: Vec<Vec3> = m
                .positions
                .chunks(3)
                .map(|p| Vec3::new(p[0], p[1], p[2]))
                .collect();
            let (mut c, mut ok) = (vec![Vec3::ZERO; rest.len()], vec![false; rest.len()]);
            local.frame(
                &crease_mocap::MarkerFrame {
                    index: i,
                    time: 0.0,
                    positions: &positions,
                    valid: &m.valid,
                },
                &mut c,
                &mut ok,
            );
            sent.push(m.positions);
            registered.push((c, ok));
        }
        let scale = local.registration().scale().unwrap();

        // The mesh follows: received meshes of frames whose markers differ differ.
        let seqs: Vec<u64> = meshes.keys().copied().collect();
        println!(
            "NatNet {t}: {} of {n} meshes received (seqs {seqs:?}); registration scale {scale}",
            meshes.len()
        );
        let mut compared = 0;
        for w in seqs.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            let moved = meshes[&w[0]]
                .iter()
                .zip(&meshes[&w[1]])
                .map(|(p, q)| p.distance(*q))
                .fold(0.0f32, f32::max);
            println!(
                "NatNet {t}: seq {a} (fixture frame {}) -> {b} (frame {}): mesh moved up to {moved:.4}",
                order[a], order[b]
            );
            if sent[a] != sent[b] {
                compared += 1;
                assert!(
                    moved > 1e-3,
                    "NatNet {t}: the markers changed from seq {a} to {b} but the mesh did not"
                );
            }
        }
        assert!(
            compared >= 1,
            "NatNet {t}: meshes of differing markers to compare"
        );

        // The last mesh's control vertices are near the registered markers.
        let last = &meshes[&(n - 1)];
        let (want, ok) = &registered[(n - 1) as usize];
        assert!(
            ok.iter().all(|o| *o),
            "every control point valid in the last frame"
        );
        let got: Vec<Vec3> = vertices.iter().map(|&i| last[i]).collect();
        let residual = rms(&got, want);
        let worst = got
            .iter()
            .zip(want)
            .map(|(p, q)| p.distance(*q))
            .fold(0.0f32, f32::max);
        let rest_residual = rms(&rest, want);
        println!(
            "NatNet {t}: last mesh control vertices vs registered markers: RMS {residual:.4}, max \
             {worst:.4} model units ({:.2} mm in the capture); the rest pose's RMS {rest_residual:.4}",
            1000.0 * residual / scale
        );
        // The same frames published straight into a twin room: its acks' residual (the
        // room's own measure of how closely the mesh follows) is the one computed here, so the
        // local registration is the room's.
        let twin = format!("{room}-twin");
        let twin_token = common::open_room(
            addr,
            "admin",
            v1::OpenRoomRequest {
                room: twin.clone(),
                model: "tube".into(),
                retarget: Some(v1::Retarget {
                    map_toml: map.clone(),
                    markers: declared(),
                    units: "m".into(),
                    ..Default::default()
                }),
                ..Default::default()
            },
        )
        .await;
        let frames: Vec<v1::ControlFrame> = sent
            .iter()
            .enumerate()
            .map(|(i, m)| v1::ControlFrame {
                room: twin.clone(),
                seq: i as u64,
                markers: m.clone(),
                ..Default::default()
            })
            .collect();
        let mut req = tonic::Request::new(tokio_stream::iter(frames));
        req.metadata_mut().insert(
            "authorization",
            format!("Bearer {twin_token}").parse().unwrap(),
        );
        let mut acks = client.publish(req).await.unwrap().into_inner();
        let mut last_ack = None;
        while let Some(a) = acks.message().await.unwrap() {
            assert!(a.error.is_none(), "{a:?}");
            last_ack = Some(a);
        }
        let ack = last_ack.unwrap();
        println!(
            "NatNet {t}: the twin room's last ack: residual {:.4} model units, {:.2} mm in the \
             capture",
            ack.control_residual,
            1000.0 * ack.control_residual_capture
        );
        // 12-bit quantisation of a box a few units wide: well under 0.01.
        assert!(
            (ack.control_residual - residual).abs() < 0.01,
            "NatNet {t}: the room's residual {} vs {residual} here",
            ack.control_residual
        );
        // The tube is 7 units long, radius 1; the best any similarity does putting these
        // markers on its rest control points is 1.01 RMS (the markers are not a tube) and the
        // 2-bone model can only bend. The mesh stays within that floor plus a quarter unit,
        // and no further than the rest pose plus a quarter unit.
        assert!(
            residual < 1.25 && residual < rest_residual + 0.25,
            "NatNet {t}: control vertices {residual} (RMS) from the registered markers"
        );
    }
}
