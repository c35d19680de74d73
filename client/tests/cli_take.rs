//! Takes end to end (issue 22) against the `crease-server` binary (built beside `crease` by a
//! workspace test run; skipped with a note otherwise): a take recorded from a live room fed by
//! a gRPC publisher, a second take cut by `kill -9`, both read back after a restart; the first
//! replayed into a fresh room reproduces the recorded meshes, and its skinned glTF export,
//! skinned here from the file's own joints and weights, matches the room's meshes frame by
//! frame.

use crate::common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{CONTROLS, bent, crease, run_ok, train_model, tube};
use crease_core::glam::{Mat4, Quat, Vec3, Vec4};
use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use crease_remote::mesh_stream::StreamReader;
use gltf::animation::util::ReadOutputs;
use tokio_stream::StreamExt as _;

const ADMIN: &str = "take-admin";

/// A running `crease-server` and its addresses; its stderr is drained by a thread.
struct Server {
    child: Child,
    grpc: String,
}

impl Drop for Server {
    /// A failed check must not leave the server running (it holds the test's output pipe).
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn server_binary() -> Option<PathBuf> {
    let bin = Path::new(env!("CARGO_BIN_EXE_crease"))
        .with_file_name(format!("crease-server{}", std::env::consts::EXE_SUFFIX));
    bin.is_file().then_some(bin)
}

fn spawn_server(bin: &Path, models: &Path, takes: &Path, cache: &Path) -> Server {
    let mut child = Command::new(bin)
        .args(["--grpc", "127.0.0.1:0", "--http", "127.0.0.1:0"])
        .arg("--models")
        .arg(models)
        .arg("--takes")
        .arg(takes)
        .arg("--cache")
        .arg(cache)
        .args(["--admin-token", ADMIN])
        .env("RUST_LOG", "warn")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    let grpc = loop {
        line.clear();
        assert!(
            stderr.read_line(&mut line).unwrap() > 0,
            "the server ended before its banner"
        );
        if let Some(rest) = line.strip_prefix("crease-server: gRPC on ") {
            break rest.split(',').next().unwrap().trim().to_owned();
        }
    };
    std::thread::spawn(move || {
        let mut sink = String::new();
        while stderr.read_line(&mut sink).is_ok_and(|n| n > 0) {
            eprint!("server: {sink}");
            sink.clear();
        }
    });
    Server {
        child,
        grpc: format!("http://{grpc}"),
    }
}

/// The tube's control points bent by `angle`, flat xyz.
fn controls_at(angle: f32) -> Vec<f32> {
    let mesh = bent(&tube(), angle);
    CONTROLS
        .iter()
        .flat_map(|&c| mesh.positions[c].to_array())
        .collect()
}

/// The bend of frame `i`: a swing through the training range and a little beyond.
fn angle(i: u64) -> f32 {
    0.5 + 0.45 * (i as f32 * 0.13).sin()
}

/// Room `room`'s base meshes (model vertex order) by seq while `run` runs, and the bound of
/// the stream's quantisation (half a step along every axis).
async fn watch_while<F: std::future::Future<Output = ()>>(
    server: &str,
    room: &str,
    run: F,
) -> (BTreeMap<u64, Vec<Vec3>>, f32) {
    let mut client = CreaseClient::connect(server.to_owned()).await.unwrap();
    let mut stream = client
        .subscribe(v1::SubscribeRequest {
            room: room.to_owned(),
            level: v1::Level::Base as i32,
            encoding: v1::Encoding::Vertices as i32,
        })
        .await
        .unwrap()
        .into_inner();
    let first = stream.next().await.unwrap().unwrap();
    let Some(v1::mesh_frame::Body::Topology(t)) = &first.body else {
        panic!("no topology first");
    };
    let q = t.quantization.unwrap();
    let (lo, hi) = (q.min.unwrap(), q.max.unwrap());
    let side = (hi.x - lo.x).max(hi.y - lo.y).max(hi.z - lo.z);
    let half_step = 0.5 * side / ((1u32 << t.bits) - 1) as f32;
    let bound = half_step * 3f32.sqrt();
    let mut reader = StreamReader::new(&first).unwrap();
    let meshes = tokio::sync::Mutex::new(BTreeMap::new());
    let collect = async {
        while let Some(Ok(m)) = stream.next().await {
            if let Some(v1::mesh_frame::Body::Frame(f)) = m.body {
                reader.decode(&f.data).unwrap();
                let mut pos = Vec::new();
                reader.model_positions(&mut pos);
                meshes.lock().await.insert(f.seq, pos);
            }
        }
    };
    tokio::select! {
        () = collect => {}
        () = async {
            run.await;
            // The last frames' way to this subscriber.
            tokio::time::sleep(Duration::from_millis(500)).await;
        } => {}
    }
    (meshes.into_inner(), bound)
}

/// Publishes frames `seqs` into `room` at `hz`; the seqs the room predicted (acked without
/// error). With `stop_after`, returns once that many were predicted (the stream stays open).
async fn publish(
    server: &str,
    room: &str,
    token: &str,
    seqs: std::ops::Range<u64>,
    hz: f64,
    stop_after: Option<usize>,
) -> Vec<u64> {
    let mut client = CreaseClient::connect(server.to_owned()).await.unwrap();
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    let mut req = tonic::Request::new(tokio_stream::wrappers::ReceiverStream::new(rx));
    req.metadata_mut()
        .insert("authorization", format!("Bearer {token}").parse().unwrap());
    let mut acks = client.publish(req).await.unwrap().into_inner();
    let room = room.to_owned();
    let n = seqs.end - seqs.start;
    let sender = tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / hz));
        for seq in seqs {
            tick.tick().await;
            let frame = v1::ControlFrame {
                room: room.clone(),
                seq,
                capture_time_us: 1_000_000 + 10_000 * seq as i64,
                positions: controls_at(angle(seq)),
                ..Default::default()
            };
            if tx.send(frame).await.is_err() {
                return;
            }
        }
        // Keep the stream open until the acks are in.
        tokio::time::sleep(Duration::from_secs(3600)).await;
    });
    let mut predicted = Vec::new();
    for _ in 0..n {
        let Some(Ok(ack)) = acks.next().await else {
            break;
        };
        if ack.error.is_none() {
            predicted.push(ack.seq);
        }
        if stop_after.is_some_and(|k| predicted.len() >= k) {
            std::mem::forget(sender);
            return predicted;
        }
    }
    sender.abort();
    predicted
}

/// `crease` with the admin token in its environment.
fn cli() -> Command {
    let mut c = crease();
    c.env("CREASE_ADMIN_TOKEN", ADMIN);
    c.env_remove("CREASE_TOKEN");
    c
}

/// `crease take list --json`'s takes by id.
fn listed(server: &Server) -> BTreeMap<String, serde_json::Value> {
    let out = run_ok(cli().args(["take", "list", "--json", "--server", &server.grpc]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    v["takes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["take"].as_str().unwrap().to_owned(), t.clone()))
        .collect()
}

/// The glTF's rest positions skinned with its own joints, weights, inverse bind matrices and
/// keyframe `k` of its animation, as a glTF viewer does (glTF 2.0 §3.7.3).
pub(crate) fn gltf_skinned(doc: &gltf::Gltf, k: usize) -> Vec<Vec3> {
    let blob = doc.blob.clone().unwrap();
    let get = |_: gltf::Buffer<'_>| Some(&blob[..]);
    let skin = doc.skins().next().unwrap();
    let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
    let ibm: Vec<Mat4> = skin
        .reader(get)
        .read_inverse_bind_matrices()
        .unwrap()
        .map(|m| Mat4::from_cols_array_2d(&m))
        .collect();
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(get);
    let pos: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    let mut vj = vec![Vec::new(); pos.len()];
    let mut vw = vec![Vec::new(); pos.len()];
    for set in 0..2 {
        let (Some(j), Some(w)) = (reader.read_joints(set), reader.read_weights(set)) else {
            break;
        };
        for (v, (j, w)) in j.into_u16().zip(w.into_f32()).enumerate() {
            vj[v].extend(j);
            vw[v].extend(w);
        }
    }
    let anim = doc.animations().next().unwrap();
    let n = doc.nodes().len();
    let (mut tr, mut rot) = (vec![Vec3::ZERO; n], vec![Quat::IDENTITY; n]);
    for ch in anim.channels() {
        let r = ch.reader(get);
        let node = ch.target().node().index();
        match r.read_outputs().unwrap() {
            ReadOutputs::Translations(mut t) => tr[node] = Vec3::from(t.nth(k).unwrap()),
            ReadOutputs::Rotations(q) => rot[node] = Quat::from_array(q.into_f32().nth(k).unwrap()),
            _ => panic!("unexpected channel"),
        }
    }
    let root = doc
        .nodes()
        .find(|nd| nd.children().any(|c| c.index() == joints[0]))
        .unwrap();
    let root = Mat4::from_cols_array_2d(&root.transform().matrix());
    let mats: Vec<Mat4> = joints
        .iter()
        .zip(&ibm)
        .map(|(&j, ib)| root * Mat4::from_rotation_translation(rot[j], tr[j]) * *ib)
        .collect();
    pos.iter()
        .enumerate()
        .map(|(v, &p)| {
            vj[v]
                .iter()
                .zip(&vw[v])
                .map(|(&j, &w)| w * (mats[j as usize] * Vec4::from((p, 1.0))).truncate())
                .sum()
        })
        .collect()
}

pub(crate) fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| x.distance(*y))
        .fold(0.0, f32::max)
}

#[test]
fn takes_record_survive_a_kill_replay_and_export() {
    let Some(bin) = server_binary() else {
        eprintln!(
            "skipped: crease-server is not built beside crease (a workspace test run builds it)"
        );
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    let model = train_model(tmp.path());
    let model_file = models.join("tube.crease");
    std::fs::rename(&model, &model_file).unwrap();
    let takes = tmp.path().join("takes");
    let cache = tmp.path().join("cache");
    let rt = tokio::runtime::Runtime::new().unwrap();

    let server = spawn_server(&bin, &models, &takes, &cache);
    let g = server.grpc.clone();
    let token = run_ok(cli().args([
        "room", "open", "--room", "live", "--model", "tube", "--server", &g,
    ]));
    let token = token.trim().to_owned();
    let take1 = run_ok(cli().args([
        "take", "start", "--room", "live", "--name", "first", "--server", &g,
    ]));
    let take1 = take1.trim().to_owned();
    // Take 1: 60 frames at 100 Hz while a subscriber records the room's meshes.
    let (live, bound) = rt.block_on(watch_while(&g, "live", async {
        let predicted = publish(&g, "live", &token, 0..60, 100.0, None).await;
        assert!(
            predicted.len() >= 30,
            "only {} of 60 predicted",
            predicted.len()
        );
    }));
    let stopped = run_ok(cli().args(["take", "stop", "--room", "live", "--server", &g]));
    assert_eq!(stopped.trim(), take1);

    // Take 2, cut by kill -9 after 100 predicted frames.
    let take2 = run_ok(cli().args(["take", "start", "--room", "live", "--server", &g]));
    let take2 = take2.trim().to_owned();
    let acked = rt.block_on(publish(&g, "live", &token, 1000..1400, 100.0, Some(100)));
    drop(server); // SIGKILL

    // Read both files as they are on disk.
    let read = |id: &str| {
        let f = std::fs::File::open(takes.join(format!("{id}.take"))).unwrap();
        crease_proto::take::read_take(BufReader::new(f)).unwrap()
    };
    let t1 = read(&take1);
    assert!(!t1.scan.truncated, "take 1 was stopped cleanly");
    let seqs1: Vec<u64> = t1
        .frames
        .iter()
        .map(|f| f.frame.as_ref().unwrap().seq)
        .collect();
    assert!(seqs1.len() >= 30 && seqs1.len() <= 60, "{seqs1:?}");
    assert!(seqs1.windows(2).all(|w| w[0] < w[1]), "{seqs1:?}");
    assert!(seqs1.iter().all(|&s| s < 60));
    let t2 = read(&take2);
    let seqs2: Vec<u64> = t2
        .frames
        .iter()
        .map(|f| f.frame.as_ref().unwrap().seq)
        .collect();
    // Every frame the file holds is whole (CRC-checked) and one the room predicted, in order;
    // the kill lost at most the last second (100 frames at 100 Hz) of those acked.
    assert!(
        seqs2
            .iter()
            .all(|s| acked.contains(s) || *s >= *acked.last().unwrap()),
        "{seqs2:?}"
    );
    assert!(seqs2.windows(2).all(|w| w[0] < w[1]));
    let acked_recorded = acked.iter().filter(|s| seqs2.contains(s)).count();
    assert!(
        acked_recorded + 100 >= acked.len(),
        "take 2 kept {acked_recorded} of the {} acked frames",
        acked.len()
    );
    let on_disk = std::fs::metadata(takes.join(format!("{take2}.take")))
        .unwrap()
        .len();
    assert!(t2.scan.whole_bytes <= on_disk);
    assert_eq!(t2.scan.truncated, t2.scan.whole_bytes < on_disk);
    eprintln!(
        "take 2: {} acked before the kill, {} frames whole on disk, {} bytes of {} whole",
        acked.len(),
        seqs2.len(),
        t2.scan.whole_bytes,
        on_disk
    );

    // A write the kill tore in half looks like this: the first bytes of one more record. The
    // readers keep the whole frames before it and say the take is truncated.
    let torn = tmp.path().join("torn.take");
    let mut bytes = std::fs::read(takes.join(format!("{take2}.take"))).unwrap();
    bytes.truncate(t2.scan.whole_bytes as usize);
    bytes.extend_from_slice(&[40, 0, 0, 0, 1, 2]);
    std::fs::write(&torn, &bytes).unwrap();
    let t3 = crease_proto::take::read_take(bytes.as_slice()).unwrap();
    assert!(t3.scan.truncated);
    assert_eq!(t3.frames, t2.frames);
    let torn_id = format!("{take2}-torn");
    std::fs::rename(&torn, takes.join(format!("{torn_id}.take"))).unwrap();

    // A restarted server lists them all.
    let server = spawn_server(&bin, &models, &takes, &cache);
    let g = server.grpc.clone();
    let list = listed(&server);
    assert_eq!(list[&take1]["frames"].as_u64().unwrap(), seqs1.len() as u64);
    assert_eq!(list[&take1]["name"], "first");
    assert_eq!(list[&take1]["recording"], false);
    assert_eq!(list[&take1]["truncated"], false);
    assert_eq!(list[&take2]["frames"].as_u64().unwrap(), seqs2.len() as u64);
    assert_eq!(list[&take2]["truncated"], t2.scan.truncated);
    assert_eq!(
        list[&torn_id]["frames"].as_u64().unwrap(),
        seqs2.len() as u64
    );
    assert_eq!(list[&torn_id]["truncated"], true);
    // `take get` downloads the file as it is.
    let got = tmp.path().join("got.take");
    run_ok(
        cli()
            .args(["take", "get", &take1, "--server", &g, "--out"])
            .arg(&got),
    );
    assert_eq!(
        std::fs::read(&got).unwrap(),
        std::fs::read(takes.join(format!("{take1}.take"))).unwrap()
    );

    // The recorded frames changed the mesh by more than the bound, so the comparisons below
    // could fail.
    let recorded: Vec<(u64, &Vec<Vec3>)> = seqs1
        .iter()
        .filter_map(|s| live.get(s).map(|m| (*s, m)))
        .collect();
    assert!(
        recorded.len() >= 10,
        "the subscriber saw {} of the take's frames",
        recorded.len()
    );
    let moved = recorded
        .windows(2)
        .map(|w| max_distance(w[0].1, w[1].1))
        .fold(0.0, f32::max);
    assert!(
        moved > 20.0 * bound,
        "frames move {moved}, the bound is {bound}"
    );

    // Replay take 1 into a fresh room: the same meshes.
    let token2 = run_ok(cli().args([
        "room", "open", "--room", "again", "--model", "tube", "--server", &g,
    ]));
    let token2 = token2.trim().to_owned();
    let (replayed, _) = rt.block_on(watch_while(&g, "again", async {
        let (take1, g, token2) = (take1.clone(), g.clone(), token2.clone());
        let out = tokio::task::spawn_blocking(move || {
            crease()
                .args([
                    "take", "replay", &take1, "--room", "again", "--speed", "max",
                ])
                .args(["--server", &g, "--token", &token2])
                .env_remove("CREASE_ADMIN_TOKEN")
                .output()
                .unwrap()
        })
        .await
        .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }));
    let mut compared = 0;
    for (seq, mesh) in &recorded {
        if let Some(again) = replayed.get(seq) {
            let d = max_distance(mesh, again);
            assert!(
                d <= 2.0 * bound,
                "frame {seq}: replay differs by {d} (bound {bound})"
            );
            compared += 1;
        }
    }
    assert!(compared >= 5, "only {compared} replayed frames compared");

    // Export take 1 as a skinned glTF and skin it from the file alone.
    let glb = tmp.path().join("take1.glb");
    run_ok(
        cli()
            .args(["take", "export", &take1, "--server", &g, "--model"])
            .arg(&model_file)
            .arg("--out")
            .arg(&glb),
    );
    let doc = gltf::Gltf::from_slice(&std::fs::read(&glb).unwrap()).unwrap();
    let keys = doc.animations().next().unwrap().channels().next().unwrap();
    let blob = doc.blob.clone().unwrap();
    let times: Vec<f32> = keys
        .reader(|_| Some(&blob[..]))
        .read_inputs()
        .unwrap()
        .collect();
    assert_eq!(times.len(), seqs1.len(), "one keyframe per recorded frame");
    // Capture times are 10 ms apart per seq.
    for (t, s) in times.iter().zip(&seqs1) {
        assert!(
            (t - (s - seqs1[0]) as f32 * 0.01).abs() < 1e-4,
            "{t} for seq {s}"
        );
    }
    let mut exported = 0;
    for (k, seq) in seqs1.iter().enumerate() {
        let Some(mesh) = live.get(seq) else { continue };
        let skinned = gltf_skinned(&doc, k);
        let d = max_distance(mesh, &skinned);
        assert!(
            d <= bound + 1e-4,
            "frame {seq}: the glTF differs by {d} (bound {bound})"
        );
        exported += 1;
    }
    assert!(exported >= 10);

    // A batch job from take 1 (issue 45): its meshes are a local `crease synth` of the control
    // points the take recorded (as its room used them), within the 16-bit bound of batches.
    let csv: String = t1
        .frames
        .iter()
        .map(|f| {
            let row: Vec<String> = f.controls.iter().map(|v| format!("{v}")).collect();
            row.join(",") + "\n"
        })
        .collect();
    let csv_path = tmp.path().join("take1.csv");
    std::fs::write(&csv_path, csv).unwrap();
    let local = tmp.path().join("take1-local");
    run_ok(
        crease()
            .args(["synth", "--model"])
            .arg(&model_file)
            .arg("--controls")
            .arg(&csv_path)
            .arg("--out")
            .arg(&local),
    );
    let job = run_ok(cli().args(["job", "submit", "--take", &take1, "--server", &g]));
    let job = job.trim().to_owned();
    let watched = run_ok(cli().args(["job", "watch", &job, "--server", &g]));
    assert!(watched.contains("(done)"), "{watched}");
    let fetched = tmp.path().join("take1-job");
    run_ok(
        cli()
            .args(["job", "get", &job, "--server", &g, "--out"])
            .arg(&fetched),
    );
    let addr: std::net::SocketAddr = g.trim_start_matches("http://").parse().unwrap();
    let bound = rt.block_on(crate::cli_synth_remote::batch_bound(addr));
    for i in 0..t1.frames.len() {
        let name = format!("frame_{i:05}.obj");
        let want = crease_core::mesh::Mesh::read(local.join(&name)).unwrap();
        let got = crease_core::mesh::Mesh::read(fetched.join(&name)).unwrap();
        crate::cli_synth_remote::assert_close(&format!("take job frame {i}"), &got, &want, bound);
    }
    // A take the server does not have is named.
    let out = cli()
        .args(["job", "submit", "--take", "nosuch", "--server", &g])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no take \"nosuch\" on this server"), "{err}");
    // A model that is not the take's is refused, naming both digests.
    let other = tmp.path().join("other.crease");
    let mut bytes = std::fs::read(&model_file).unwrap();
    bytes.push(0);
    std::fs::write(&other, &bytes).unwrap();
    let out = cli()
        .args(["take", "export", &take1, "--server", &g, "--model"])
        .arg(&other)
        .arg("--out")
        .arg(tmp.path().join("x.glb"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && (err.contains("SHA-256") || err.contains("other.crease")),
        "{err}"
    );
}

/// `crease take export --level detail` on a detailed model (the real cactus, split by
/// `--base-vertices`): a take written here from predicted frames, exported as morph targets;
/// every exported frame (the base shape plus its target) equals the detail layer predicted
/// straight from that frame's control points (`Predictor::predict` + `predict_detail`), not
/// from the recorded transforms the export loads.
#[test]
fn a_detail_export_holds_each_frames_detail_mesh() {
    use crease_core::model::TrainedModel;
    use crease_core::predictor::Predictor;
    use sha2::Digest as _;
    let Some(dir) = common::shared_data("cactus") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let model_path = tmp.path().join("cactus.crease");
    run_ok(
        crease()
            .args(["train", "--examples"])
            .arg(&dir)
            .args([
                "--base-vertices",
                "1200",
                "--bones",
                "12",
                "--max-influences",
                "4",
            ])
            .args([
                "--detail-ray",
                "0.05",
                "--control-points",
                "auto:6",
                "--method",
                "local",
                "--out",
            ])
            .arg(&model_path),
    );
    let bytes = std::fs::read(&model_path).unwrap();
    let sha: String = sha2::Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let model = std::sync::Arc::new(TrainedModel::from_bytes(&bytes).unwrap());
    let predictor = Predictor::new(std::sync::Arc::clone(&model), None).unwrap();
    let mut ctx = predictor.new_context();
    let (lo, hi) = model.rig.rest.bounding_box();
    let size = (hi - lo).length();
    // Five frames: the rest control points swaying sideways.
    let frames: Vec<Vec<Vec3>> = (0..5)
        .map(|f| {
            model
                .controls
                .iter()
                .map(|c| {
                    let p = model.rig.rest.positions[c.vertex as usize];
                    p + Vec3::X * (0.02 * size * f as f32 * (p.y - lo.y) / (hi.y - lo.y))
                })
                .collect()
        })
        .collect();
    let mut file = Vec::new();
    crease_proto::take::write_header(
        &mut file,
        &v1::TakeHeader {
            take: "cactus-take".into(),
            room: Some(v1::OpenRoomRequest {
                room: "r".into(),
                model: "cactus".into(),
                ..Default::default()
            }),
            model_sha256: sha,
            bones: model.rig.bone_count as u32,
            controls: model.controls.len() as u32,
            ..Default::default()
        },
    )
    .unwrap();
    let mut want = Vec::new();
    let (mut record, mut buf) = (v1::TakeFrame::default(), Vec::new());
    for (f, controls) in frames.iter().enumerate() {
        predictor.predict(&mut ctx, controls, None).unwrap();
        let control = v1::ControlFrame {
            seq: f as u64,
            capture_time_us: 40_000 * f as i64,
            positions: controls.iter().flat_map(|p| p.to_array()).collect(),
            ..Default::default()
        };
        crease_proto::take::fill_frame(&mut record, &control, 0, ctx.controls(), ctx.transforms());
        crease_proto::take::encode_record(&record, &mut buf);
        file.extend_from_slice(&buf);
        want.push(predictor.predict_detail(&mut ctx).unwrap().to_vec());
    }
    let take_path = tmp.path().join("cactus.take");
    std::fs::write(&take_path, &file).unwrap();
    let glb = tmp.path().join("detail.glb");
    run_ok(
        crease()
            .args(["take", "export"])
            .arg(&take_path)
            .arg("--model")
            .arg(&model_path)
            .args(["--level", "detail", "--out"])
            .arg(&glb),
    );
    let doc = gltf::Gltf::from_slice(&std::fs::read(&glb).unwrap()).unwrap();
    let blob = doc.blob.clone().unwrap();
    let get = |_: gltf::Buffer<'_>| Some(&blob[..]);
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(get);
    let base: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    let targets: Vec<Vec<Vec3>> = reader
        .read_morph_targets()
        .map(|(p, _, _)| p.unwrap().map(Vec3::from).collect())
        .collect();
    assert_eq!(targets.len(), frames.len(), "a morph target per frame");
    assert_eq!(base.len(), want[0].len(), "the detail mesh's vertices");
    let mut spread = 0.0f32;
    for (f, (target, want)) in targets.iter().zip(&want).enumerate() {
        let got: Vec<Vec3> = base.iter().zip(target).map(|(b, d)| *b + *d).collect();
        let d = max_distance(&got, want);
        assert!(d < 1e-5 * size, "frame {f}: the export differs by {d}");
        spread = spread.max(max_distance(want, &frames_detail_first(&targets, &base)));
    }
    // The frames differ from each other by far more than the tolerance.
    assert!(spread > 1e-3 * size, "the frames move {spread}");
}

/// The first exported frame's detail mesh.
fn frames_detail_first(targets: &[Vec<Vec3>], base: &[Vec3]) -> Vec<Vec3> {
    base.iter().zip(&targets[0]).map(|(b, d)| *b + *d).collect()
}
