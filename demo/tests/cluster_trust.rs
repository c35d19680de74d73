//! A cluster that trusts only its own (issue 40), end to end with a real `nats-server`:
//!
//! - `nats_with_tls_and_a_password_and_a_cluster_key_keep_out_everyone_else`: NATS requires
//!   mutual TLS (a CA made here with rcgen) and a password; two replicas with both and the
//!   cluster key serve a room across them; a replica without the password, or with a wrong
//!   one, is refused by NATS and says so in its log; a process with NATS access but not the
//!   cluster key forges frames (a bad tag, no tag) and room entries (a new room, an existing
//!   room handed to another owner): no viewer receives a forged frame, no replica lists or
//!   adopts a forged entry, and the refusals are counted in `/metrics`.
//! - `a_paused_owner_gets_no_frame_to_a_viewer_after_the_adopters_first`: ten times, the
//!   room's owner is stopped (SIGSTOP) for twice its lease while a publisher on another replica
//!   goes on; another adopts the room; the owner resumes (SIGCONT). Viewers on every replica
//!   must see the publisher's seq only increase (a frame of the paused owner after the
//!   adopter's would go back in seq), and see frames again after each pause; a frame forged
//!   with the first owner's stale epoch is dropped by the relays and counted.
//!
//! Skips, saying why, when `nats-server` is not installed (`.ci/run` installs it).

use crate::cluster_kit;
use crate::common;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cluster_kit::{
    ADMIN, Nats, Replica, free_port, nats_binary, refused_by_nats, signal, three_replicas, until,
};
use common::{authed, control_frame, model_with_detail};
use crease_core::codec::FrameDecoder;
use crease_core::model::TrainedModel;
use crease_proto::v1;
use futures_util::StreamExt;
use prost::Message;

/// The files of a test PKI: a CA, the NATS server's certificate, a replica's client certificate.
struct Pki {
    ca: PathBuf,
    server_cert: PathBuf,
    server_key: PathBuf,
    client_cert: PathBuf,
    client_key: PathBuf,
}

fn pki(dir: &Path) -> Pki {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair,
    };
    let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca_params
        .distinguished_name
        .push(DnType::CommonName, "crease test CA");
    let ca = CertifiedIssuer::self_signed(ca_params, KeyPair::generate().unwrap()).unwrap();
    let write = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let leaf = |sans: Vec<String>, purpose: ExtendedKeyUsagePurpose| {
        let key = KeyPair::generate().unwrap();
        let mut params = CertificateParams::new(sans).unwrap();
        params.extended_key_usages = vec![purpose];
        let cert = params.signed_by(&key, &ca).unwrap();
        (cert.pem(), key.serialize_pem())
    };
    let (server_cert, server_key) = leaf(
        vec!["localhost".into(), "127.0.0.1".into()],
        ExtendedKeyUsagePurpose::ServerAuth,
    );
    let (client_cert, client_key) = leaf(
        vec!["crease-replica".into()],
        ExtendedKeyUsagePurpose::ClientAuth,
    );
    Pki {
        ca: write("ca.pem", ca.pem()),
        server_cert: write("server.pem", server_cert),
        server_key: write("server-key.pem", server_key),
        client_cert: write("client.pem", client_cert),
        client_key: write("client-key.pem", client_key),
    }
}

/// The replicas' NATS user, as deploy/k8s/cluster-secrets.example.yaml names it.
const USER: &str = "crease-replica";
const PASSWORD: &str = "correct horse battery staple";
const OBSERVER: &str = "crease-observer";
const OBSERVER_PASSWORD: &str = "watch only";

/// The `authorization` block of the shipped NATS configuration
/// (deploy/k8s/cluster-secrets.example.yaml: its users and their subject permissions), with
/// this test's passwords for the bcrypt placeholders: the cluster runs under the permissions
/// the deployment ships.
fn shipped_authorization() -> String {
    let example = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/k8s/cluster-secrets.example.yaml"),
    )
    .unwrap();
    let conf: String = example
        .lines()
        .skip_while(|l| !l.trim_start().starts_with("nats.conf: |"))
        .skip(1)
        .take_while(|l| l.starts_with("    ") || l.trim().is_empty())
        .map(|l| format!("{}\n", l.get(4..).unwrap_or("")))
        .collect();
    let at = conf
        .find("authorization {")
        .expect("an authorization block");
    let block = &conf[at..];
    let replaced = block
        .replace(
            "\"$2a$11$REPLACE.WITH.A.BCRYPT.HASH.OF.THE.REPLICAS.PASSWORD\"",
            &format!("\"{PASSWORD}\""),
        )
        .replace(
            "\"$2a$11$REPLACE.WITH.A.BCRYPT.HASH.OF.THE.OBSERVERS.PASSWORD\"",
            &format!("\"{OBSERVER_PASSWORD}\""),
        );
    assert!(
        replaced.contains(USER) && replaced.contains(OBSERVER),
        "{replaced}"
    );
    assert!(!replaced.contains("REPLACE"), "{replaced}");
    replaced
}

/// A nats-server configuration: JetStream, mutual TLS, the shipped users and permissions.
fn nats_config(dir: &Path, port: u16, pki: &Pki) -> PathBuf {
    let conf = format!(
        r#"
listen: "127.0.0.1:{port}"
jetstream {{ store_dir: "{store}" }}
tls {{
  cert_file: "{cert}"
  key_file: "{key}"
  ca_file: "{ca}"
  verify: true
  timeout: 3
}}
{authorization}
"#,
        store = dir.join("js").display(),
        cert = pki.server_cert.display(),
        key = pki.server_key.display(),
        ca = pki.ca.display(),
        authorization = shipped_authorization(),
    );
    let path = dir.join("nats.conf");
    std::fs::write(&path, conf).unwrap();
    path
}

/// An insider: a NATS client with the cluster's NATS credentials, without its key.
async fn insider(nats: &Nats, pki: &Pki, user: &str, password: &str) -> async_nats::Client {
    async_nats::ConnectOptions::new()
        .user_and_password(user.into(), password.into())
        .add_root_certificates(pki.ca.clone())
        .add_client_certificate(pki.client_cert.clone(), pki.client_key.clone())
        .require_tls(true)
        .connect(nats.url())
        .await
        .unwrap()
}

/// Every frame seq a viewer received, in order, with decode failures.
#[derive(Debug, Default)]
struct Seen {
    seqs: Vec<u64>,
    decode_errors: usize,
}

type Shared = Arc<Mutex<Seen>>;

/// A gRPC viewer of `room` (base level) on `replica`, re-subscribing if its stream ends.
fn viewer(replica: &Replica, room: &'static str) -> (Shared, tokio::task::JoinHandle<()>) {
    let seen = Shared::default();
    let url = replica.grpc.clone();
    let s = Arc::clone(&seen);
    let task = tokio::spawn(async move {
        loop {
            let Ok(mut client) = v1::crease_client::CreaseClient::connect(url.clone()).await else {
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            };
            let request = v1::SubscribeRequest {
                room: room.into(),
                level: v1::Level::Base as i32,
                encoding: v1::Encoding::Vertices as i32,
            };
            let Ok(stream) = client.subscribe(request).await else {
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            };
            let mut stream = stream.into_inner();
            let mut decoder = None;
            while let Some(Ok(msg)) = stream.next().await {
                match msg.body {
                    Some(v1::mesh_frame::Body::Topology(t)) => {
                        decoder = Some(FrameDecoder::new(t.vertex_count as usize));
                    }
                    Some(v1::mesh_frame::Body::Frame(f)) => {
                        let mut seen = s.lock().unwrap();
                        match decoder.as_mut().map(|d| d.decode(&f.data)) {
                            Some(Ok(_)) => seen.seqs.push(f.seq),
                            _ => seen.decode_errors += 1,
                        }
                    }
                    _ => {}
                }
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    (seen, task)
}

/// A publisher of `room` on `replica` at ~50 Hz from seq `first` until aborted; the next seq
/// it would send is in `next`.
fn publisher(
    replica: &Replica,
    model: &Arc<TrainedModel>,
    room: &'static str,
    token: &str,
    next: Arc<Mutex<u64>>,
) -> tokio::task::JoinHandle<()> {
    let url = replica.grpc.clone();
    let (model, token) = (Arc::clone(model), token.to_owned());
    tokio::spawn(async move {
        let mut client = v1::crease_client::CreaseClient::connect(url).await.unwrap();
        let (tx, rx) = tokio::sync::mpsc::channel(64);
        let mut acks = client
            .publish(authed(
                tokio_stream::wrappers::ReceiverStream::new(rx),
                &token,
            ))
            .await
            .unwrap()
            .into_inner();
        tokio::spawn(async move { while let Ok(Some(_)) = acks.message().await {} });
        let mut tick = tokio::time::interval(Duration::from_millis(20));
        loop {
            tick.tick().await;
            let seq = {
                let mut n = next.lock().unwrap();
                *n += 1;
                *n - 1
            };
            let angle = (seq as f32 * 0.05).sin() * 0.6;
            if tx
                .try_send(control_frame(&model, room, seq, angle))
                .is_err()
            {
                // The replica is not reading (paused): this frame is lost, as a live one is.
            }
        }
    })
}

async fn open_room(replica: &Replica, room: &str) -> String {
    replica
        .client()
        .await
        .open_room(authed(
            v1::OpenRoomRequest {
                room: room.into(),
                model: "tube".into(),
                ..Default::default()
            },
            ADMIN,
        ))
        .await
        .unwrap()
        .into_inner()
        .publish_token
}

/// Whether `seqs` only increase.
fn increasing(seqs: &[u64]) -> Result<(), String> {
    match seqs.windows(2).position(|w| w[1] <= w[0]) {
        None => Ok(()),
        Some(i) => Err(format!(
            "seq went from {} to {} (frame {} of {})",
            seqs[i],
            seqs[i + 1],
            i + 1,
            seqs.len()
        )),
    }
}

fn models_dir(dir: &Path, model: &TrainedModel) -> PathBuf {
    let models = dir.join("models");
    std::fs::create_dir_all(&models).unwrap();
    model.save(models.join("tube.crease")).unwrap();
    models
}

/// A plain cluster (no credentials, no key) of replicas A, B, C with `args`, and room `room`
/// opened on A and listed on all three; what the tests hold while they run.
struct RoomOnThree {
    _dir: tempfile::TempDir,
    nats: Nats,
    model: Arc<TrainedModel>,
    replicas: Vec<Replica>,
    /// The room's publish token.
    token: String,
}

/// [`RoomOnThree`]; `None` (the test skips, saying why) without a nats-server binary.
async fn room_on_three(room: &'static str, args: &[String]) -> Option<RoomOnThree> {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return None;
    };
    let dir = tempfile::tempdir().unwrap();
    let nats = Nats::start(&nats_bin, free_port(), &dir.path().join("js"));
    let model = Arc::new(model_with_detail());
    let models = models_dir(dir.path(), &model);
    let replicas = three_replicas(&models, &nats.url(), dir.path(), args).await;
    let token = open_room(&replicas[0], room).await;
    for r in &replicas {
        until(Duration::from_secs(10), "room listed", || async {
            r.owner_of(room).await.is_some()
        })
        .await;
    }
    Some(RoomOnThree {
        _dir: dir,
        nats,
        model,
        replicas,
        token,
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nats_with_tls_and_a_password_and_a_cluster_key_keep_out_everyone_else() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pki = pki(dir.path());
    let port = free_port();
    let config = nats_config(dir.path(), port, &pki);
    let nats = Nats::start_with(&nats_bin, port, &dir.path().join("js"), Some(&config));
    let model = Arc::new(model_with_detail());
    let models = models_dir(dir.path(), &model);
    let key = dir.path().join("cluster.key");
    std::fs::write(&key, format!("{}\n", "5a".repeat(32))).unwrap();
    let password = dir.path().join("nats.password");
    std::fs::write(&password, format!("{PASSWORD}\n")).unwrap();
    let wrong = dir.path().join("wrong.password");
    std::fs::write(&wrong, "guess\n").unwrap();
    let tls = |args: &mut Vec<String>| {
        args.extend([
            "--nats-tls-ca".into(),
            pki.ca.display().to_string(),
            "--nats-tls-cert".into(),
            pki.client_cert.display().to_string(),
            "--nats-tls-key".into(),
            pki.client_key.display().to_string(),
        ]);
    };
    let mut trusted = vec![
        "--nats-user".to_owned(),
        USER.into(),
        "--nats-password-file".into(),
        password.display().to_string(),
        "--cluster-key-file".into(),
        key.display().to_string(),
    ];
    tls(&mut trusted);

    // Without the password, or with a wrong one: refused by NATS, and the log says so.
    let mut none = Vec::new();
    tls(&mut none);
    let mut bad = vec![
        "--nats-user".to_owned(),
        USER.into(),
        "--nats-password-file".into(),
        wrong.display().to_string(),
    ];
    tls(&mut bad);
    for (id, args) in [("nopass", none), ("wrongpass", bad)] {
        let mut r = Replica::start_with(id, &models, &nats.url(), dir.path(), &args);
        eprintln!("replica {id} refused: {}", refused_by_nats(&mut r).await);
    }

    // Two trusted replicas serve a room across them.
    // B has no model of its own: it fetches the room's from the cluster's object store, under
    // the shipped permissions.
    let empty = dir.path().join("models-b");
    std::fs::create_dir_all(&empty).unwrap();
    let mut a = Replica::start_with("A", &models, &nats.url(), dir.path(), &trusted);
    let mut b = Replica::start_with("B", &empty, &nats.url(), dir.path(), &trusted);
    a.ready().await;
    b.ready().await;
    assert!(a.log().contains("mutual TLS"), "{}", a.log());
    let token = open_room(&a, "trusted").await;
    until(Duration::from_secs(10), "room listed on B", || async {
        b.owner_of("trusted").await.as_deref() == Some("A")
    })
    .await;
    let (seen_b, viewer_b) = viewer(&b, "trusted");
    let next = Arc::new(Mutex::new(0u64));
    let publishing = publisher(&a, &model, "trusted", &token, Arc::clone(&next));
    until(Duration::from_secs(20), "frames relayed to B", || async {
        seen_b.lock().unwrap().seqs.len() >= 20
    })
    .await;

    // Issue 45: a batch job under the shipped permissions and the key: submitted to A, run
    // by both, watched and fetched on B.
    let frames: Vec<v1::ControlFrame> = (0..200)
        .map(|i| control_frame(&model, "", i, 0.005 * i as f32))
        .collect();
    let job = crate::cluster_jobs::submit(&mut a.client().await, &frames).await;
    let mut on_b = b.client().await;
    let last = crate::cluster_jobs::watch_to_end(&mut on_b, &job.job).await;
    assert_eq!(
        last.state,
        v1::JobState::Done as i32,
        "{last:?}\n{}",
        a.log()
    );
    let got = crate::cluster_jobs::result(&mut on_b, &job.job).await;
    assert_eq!(got.len(), 201, "the topology, then 200 frames");

    // An insider: NATS access, no cluster key.
    let mallory = insider(&nats, &pki, USER, PASSWORD).await;
    // A job chunk of the insider's: no tag, dropped by the replica that pulls it.
    let refused_before = a.metric("crease_cluster_refused_job_chunks_total").await
        + b.metric("crease_cluster_refused_job_chunks_total").await;
    let js = async_nats::jetstream::new(mallory.clone());
    js.publish(
        crease_server::cluster::work::subject("forgedjob123"),
        v1::JobChunk {
            job: "forgedjob123".into(),
            chunk: 0,
            frames: Vec::new(),
        }
        .encode_to_vec()
        .into(),
    )
    .await
    .unwrap()
    .await
    .unwrap();
    until(
        Duration::from_secs(20),
        "the forged chunk refused",
        || async {
            a.metric("crease_cluster_refused_job_chunks_total").await
                + b.metric("crease_cluster_refused_job_chunks_total").await
                > refused_before
        },
    )
    .await;
    let mut sniff = mallory.subscribe("crease.frames.trusted.>").await.unwrap();
    let real = sniff.next().await.unwrap();
    drop(sniff);
    let headers = real.headers.clone().unwrap();
    assert!(headers.get("Crease-Tag").is_some(), "{headers:?}");
    // (1) A real frame with its seq rewritten, headers kept: the tag no longer holds.
    let mut msg = v1::MeshFrame::decode(real.payload.as_ref()).unwrap();
    let Some(v1::mesh_frame::Body::Frame(f)) = msg.body.as_mut() else {
        panic!("not a frame")
    };
    const FORGED_SEQ: u64 = 9_000_000;
    f.seq = FORGED_SEQ;
    let forged = msg.encode_to_vec();
    let before = b.metric("crease_cluster_refused_forged_frames_total").await;
    for _ in 0..5 {
        mallory
            .publish_with_headers(real.subject.clone(), headers.clone(), forged.clone().into())
            .await
            .unwrap();
        // (2) And with no headers at all.
        mallory
            .publish(real.subject.clone(), forged.clone().into())
            .await
            .unwrap();
    }
    mallory.flush().await.unwrap();
    until(
        Duration::from_secs(5),
        "the forged frames counted on B",
        || async { b.metric("crease_cluster_refused_forged_frames_total").await >= before + 10.0 },
    )
    .await;

    // An observer (the shipped read-only user) may watch frames but NATS refuses its
    // publications: the server closes nothing, the frames never reach a replica.
    let observer = insider(&nats, &pki, OBSERVER, OBSERVER_PASSWORD).await;
    let mut watched = observer.subscribe("crease.frames.trusted.>").await.unwrap();
    tokio::time::timeout(Duration::from_secs(5), watched.next())
        .await
        .expect("the observer sees frames")
        .unwrap();
    let relayed = b.metric("crease_cluster_relayed_frames_total").await;
    let refused = b.metric("crease_cluster_refused_forged_frames_total").await;
    for _ in 0..5 {
        let _ = observer
            .publish(real.subject.clone(), forged.clone().into())
            .await;
    }
    let _ = observer.flush().await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        b.metric("crease_cluster_refused_forged_frames_total").await,
        refused,
        "the observer's frames reached B (NATS should refuse its publications)"
    );
    assert!(b.metric("crease_cluster_relayed_frames_total").await > relayed);

    // (3) A forged registry entry for a new room, and one handing room `trusted` to mallory.
    let js = async_nats::jetstream::new(mallory.clone());
    let kv = js.get_key_value("crease-rooms").await.unwrap();
    let current = kv.entry("trusted").await.unwrap().unwrap();
    let mut stolen = v1::RoomEntry::decode(current.value.as_ref()).unwrap();
    stolen.owner = "mallory".into();
    stolen.epoch += 10;
    stolen.tag.clear();
    kv.put("trusted", stolen.encode_to_vec().into())
        .await
        .unwrap();
    let mut fake = stolen.clone();
    fake.epoch = 1;
    kv.put("forged", fake.encode_to_vec().into()).await.unwrap();
    until(
        Duration::from_secs(5),
        "the forged entries refused on A and B",
        || async {
            a.metric("crease_cluster_refused_entries_total").await >= 2.0
                && b.metric("crease_cluster_refused_entries_total").await >= 2.0
        },
    )
    .await;
    // Frames go on, the room stays A's (A writes its entry back over the forgery), and no
    // replica lists the forged room.
    let n = seen_b.lock().unwrap().seqs.len();
    until(
        Duration::from_secs(10),
        "frames after the forgeries",
        || async { seen_b.lock().unwrap().seqs.len() >= n + 50 },
    )
    .await;
    for r in [&a, &b] {
        assert_eq!(
            r.owner_of("trusted").await.as_deref(),
            Some("A"),
            "{}",
            r.id
        );
        assert_eq!(r.owner_of("forged").await, None, "{}", r.id);
    }
    let entry =
        v1::RoomEntry::decode(kv.entry("trusted").await.unwrap().unwrap().value.as_ref()).unwrap();
    assert_eq!(entry.owner, "A", "the registry's entry is A's again");
    assert!(!entry.tag.is_empty());

    publishing.abort();
    viewer_b.abort();
    let (seqs, decode_errors) = {
        let seen = seen_b.lock().unwrap();
        (seen.seqs.clone(), seen.decode_errors)
    };
    assert!(
        !seqs.contains(&FORGED_SEQ),
        "a forged frame reached the viewer on B"
    );
    increasing(&seqs).unwrap();
    assert_eq!(decode_errors, 0);
    eprintln!(
        "B's viewer: {} frames, none forged; B refused {} forged frames, A and B {} and {} forged entries",
        seqs.len(),
        b.metric("crease_cluster_refused_forged_frames_total").await,
        a.metric("crease_cluster_refused_entries_total").await,
        b.metric("crease_cluster_refused_entries_total").await,
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_owner_gets_no_frame_to_a_viewer_after_the_adopters_first() {
    const LEASE_MS: u64 = 1000;
    let args = vec!["--lease-ms".to_owned(), LEASE_MS.to_string()];
    let Some(RoomOnThree {
        _dir,
        nats,
        model,
        replicas,
        token,
    }) = room_on_three("paused", &args).await
    else {
        return;
    };
    let viewers: Vec<_> = replicas.iter().map(|r| viewer(r, "paused")).collect();
    let next = Arc::new(Mutex::new(0u64));
    let mut publishing: Option<tokio::task::JoinHandle<()>> = None;
    let mut stale_checked = false;
    for run in 0..10 {
        let owner = replicas[0].owner_of("paused").await.unwrap();
        let p = replicas.iter().position(|r| r.id == owner).unwrap();
        let other = (p + 1) % replicas.len();
        if let Some(t) = publishing.take() {
            t.abort();
        }
        publishing = Some(publisher(
            &replicas[other],
            &model,
            "paused",
            &token,
            Arc::clone(&next),
        ));
        let counts = |viewers: &[(Shared, _)]| -> Vec<usize> {
            viewers
                .iter()
                .map(|(s, _)| s.lock().unwrap().seqs.len())
                .collect()
        };
        let before = counts(&viewers);
        until(
            Duration::from_secs(10),
            "frames before the pause",
            || async {
                counts(&viewers)
                    .iter()
                    .zip(&before)
                    .all(|(n, b)| *n >= b + 10)
            },
        )
        .await;
        signal(&replicas[p], "-STOP");
        tokio::time::sleep(Duration::from_millis(2 * LEASE_MS)).await;
        // Adopted by another replica meanwhile.
        let adopter = replicas[other].owner_of("paused").await.unwrap_or_default();
        signal(&replicas[p], "-CONT");
        assert_ne!(
            adopter, owner,
            "run {run}: nobody adopted the room of paused {owner}"
        );
        // Every viewer sees frames again.
        let resumed = counts(&viewers);
        let took = until(
            Duration::from_secs(15),
            "frames after the pause",
            || async {
                counts(&viewers)
                    .iter()
                    .zip(&resumed)
                    .all(|(n, b)| *n >= b + 10)
            },
        )
        .await;
        eprintln!(
            "run {run}: paused {owner} for {:?}, adopted by {adopter}, every viewer had 10 new frames {:?} after it resumed",
            Duration::from_millis(2 * LEASE_MS),
            took
        );
        // Once: a frame with the first owner's stale epoch and a seq far ahead, on the frames
        // subject, without a cluster key (this cluster has none): the relays drop it.
        if !stale_checked {
            stale_checked = true;
            let client = async_nats::connect(nats.url()).await.unwrap();
            let mut sniff = client.subscribe("crease.frames.paused.>").await.unwrap();
            let real = tokio::time::timeout(Duration::from_secs(5), sniff.next())
                .await
                .unwrap()
                .unwrap();
            let mut msg = v1::MeshFrame::decode(real.payload.as_ref()).unwrap();
            if let Some(v1::mesh_frame::Body::Frame(f)) = msg.body.as_mut() {
                f.seq = 8_000_000;
            }
            let mut headers = async_nats::HeaderMap::new();
            headers.insert("Crease-Owner", owner.as_str());
            headers.insert("Crease-Epoch", "1");
            let stale_before: f64 = {
                let mut sum = 0.0;
                for r in &replicas {
                    sum += r.metric("crease_cluster_refused_stale_frames_total").await;
                }
                sum
            };
            for _ in 0..5 {
                client
                    .publish_with_headers(
                        real.subject.clone(),
                        headers.clone(),
                        msg.encode_to_vec().into(),
                    )
                    .await
                    .unwrap();
            }
            client.flush().await.unwrap();
            until(
                Duration::from_secs(5),
                "the stale frames counted",
                || async {
                    let mut sum = 0.0;
                    for r in &replicas {
                        sum += r.metric("crease_cluster_refused_stale_frames_total").await;
                    }
                    sum >= stale_before + 5.0
                },
            )
            .await;
        }
    }
    if let Some(t) = publishing.take() {
        t.abort();
    }
    let mut fenced = 0.0;
    for r in &replicas {
        fenced += r.metric("crease_cluster_fenced_frames_total").await;
    }
    for (r, (seen, task)) in replicas.iter().zip(viewers) {
        task.abort();
        let seen = seen.lock().unwrap();
        increasing(&seen.seqs).unwrap_or_else(|e| panic!("viewer on {}: {e}", r.id));
        assert!(
            !seen.seqs.contains(&8_000_000),
            "a stale-epoch frame reached the viewer on {}",
            r.id
        );
        eprintln!(
            "viewer on {}: {} frames, seq only increasing; {} frames failed to decode",
            r.id,
            seen.seqs.len(),
            seen.decode_errors
        );
    }
    eprintln!("frames held back by paused owners (fenced): {fenced}");
}

/// A JWT of NATS's decentralised auth (nats-io/jwt v2 claims): `nats` is the claims' `nats`
/// object, signed by `issuer` (an operator signs accounts and itself, an account its users).
fn nats_jwt(issuer: &nkeys::KeyPair, subject: &str, name: &str, nats: serde_json::Value) -> String {
    use base64::Engine as _;
    let b64 = base64::engine::general_purpose::URL_SAFE_NO_PAD;
    let header = b64.encode(br#"{"typ":"JWT","alg":"ed25519-nkey"}"#);
    let iat = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    let claims = serde_json::json!({
        "jti": format!("{name}-{iat}"),
        "iat": iat,
        "iss": issuer.public_key(),
        "name": name,
        "sub": subject,
        "nats": nats,
    });
    let body = b64.encode(claims.to_string());
    let signed = format!("{header}.{body}");
    let signature = issuer.sign(signed.as_bytes()).unwrap();
    format!("{signed}.{}", b64.encode(signature))
}

/// A user's credentials file (as `nsc` writes it): its JWT, signed by `account`, and its seed.
fn creds_file(path: &Path, account: &nkeys::KeyPair, name: &str) {
    let user = nkeys::KeyPair::new_user();
    let jwt = nats_jwt(
        account,
        &user.public_key(),
        name,
        serde_json::json!({"type": "user", "version": 2, "pub": {}, "sub": {},
            "subs": -1, "data": -1, "payload": -1}),
    );
    let seed = user.seed().unwrap();
    std::fs::write(
        path,
        format!(
            "-----BEGIN NATS USER JWT-----\n{jwt}\n------END NATS USER JWT------\n\n\
             -----BEGIN USER NKEY SEED-----\n{seed}\n------END USER NKEY SEED------\n"
        ),
    )
    .unwrap();
}

/// `--nats-creds`: NATS in operator mode (an operator, an account with JetStream, its users'
/// JWTs made here with nkeys); a replica with a user's credentials file of that account joins
/// and serves a room across to another; one whose user is signed by an account NATS does not
/// know is refused and says so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nats_credentials_files_of_an_operators_account_admit_replicas() {
    let Some(nats_bin) = nats_binary() else {
        eprintln!("skipping: no nats-server binary (apt-get install -y nats-server)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let operator = nkeys::KeyPair::new_operator();
    let account = nkeys::KeyPair::new_account();
    let op_jwt = nats_jwt(
        &operator,
        &operator.public_key(),
        "crease-operator",
        serde_json::json!({"type": "operator", "version": 2}),
    );
    let limits = serde_json::json!({
        "subs": -1, "data": -1, "payload": -1, "imports": -1, "exports": -1,
        "wildcards": true, "conn": -1, "leaf": -1,
        "mem_storage": -1, "disk_storage": -1, "streams": -1, "consumer": -1,
    });
    let acc_jwt = nats_jwt(
        &operator,
        &account.public_key(),
        "crease",
        serde_json::json!({"type": "account", "version": 2, "limits": limits}),
    );
    // JetStream needs a system account.
    let system = nkeys::KeyPair::new_account();
    let sys_jwt = nats_jwt(
        &operator,
        &system.public_key(),
        "SYS",
        serde_json::json!({"type": "account", "version": 2}),
    );
    let port = free_port();
    let conf = format!(
        "listen: \"127.0.0.1:{port}\"\njetstream {{ store_dir: \"{store}\" }}\noperator: \"{op_jwt}\"\n\
         system_account: {sys}\nresolver: MEMORY\n\
         resolver_preload: {{\n  {acc}: \"{acc_jwt}\"\n  {sys}: \"{sys_jwt}\"\n}}\n",
        store = dir.path().join("js").display(),
        acc = account.public_key(),
        sys = system.public_key(),
    );
    let config = dir.path().join("nats.conf");
    std::fs::write(&config, conf).unwrap();
    let nats = Nats::start_with(&nats_bin, port, &dir.path().join("js"), Some(&config));
    let model = Arc::new(model_with_detail());
    let models = models_dir(dir.path(), &model);
    let (good, stranger) = (
        dir.path().join("replica.creds"),
        dir.path().join("stranger.creds"),
    );
    creds_file(&good, &account, "replica");
    creds_file(&stranger, &nkeys::KeyPair::new_account(), "stranger");
    let args = |creds: &Path| vec!["--nats-creds".to_owned(), creds.display().to_string()];

    let mut refused = Replica::start_with("S", &models, &nats.url(), dir.path(), &args(&stranger));
    eprintln!("replica S refused: {}", refused_by_nats(&mut refused).await);

    let mut a = Replica::start_with("A", &models, &nats.url(), dir.path(), &args(&good));
    let mut b = Replica::start_with("B", &models, &nats.url(), dir.path(), &args(&good));
    a.ready().await;
    b.ready().await;
    assert!(a.log().contains("credentials"), "{}", a.log());
    let token = open_room(&a, "creds").await;
    until(Duration::from_secs(10), "room listed on B", || async {
        b.owner_of("creds").await.as_deref() == Some("A")
    })
    .await;
    let (seen_b, viewer_b) = viewer(&b, "creds");
    let publishing = publisher(&a, &model, "creds", &token, Arc::new(Mutex::new(0)));
    until(Duration::from_secs(20), "frames relayed to B", || async {
        seen_b.lock().unwrap().seqs.len() >= 20
    })
    .await;
    publishing.abort();
    viewer_b.abort();
}

/// A relay stopped with a publisher's frames in its socket (SIGSTOP), whose publisher moves to
/// another replica and goes on: when the relay resumes it must not forward what it read from
/// before (the owner would predict frames older than the ones it has since, and every viewer
/// would see the room jump back). Found by the chaos soak (`crease bench-net --chaos`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resumed_relay_forwards_nothing_from_before_its_pause() {
    let Some(RoomOnThree {
        _dir,
        nats: _nats,
        model,
        replicas,
        token,
    }) = room_on_three("resumed", &[]).await
    else {
        return;
    };
    let viewers: Vec<_> = [&replicas[0], &replicas[2]]
        .iter()
        .map(|r| viewer(r, "resumed"))
        .collect();
    let next = Arc::new(Mutex::new(0u64));
    let counts = || -> Vec<usize> {
        viewers
            .iter()
            .map(|(s, _)| s.lock().unwrap().seqs.len())
            .collect()
    };
    for run in 0..3 {
        // The publisher goes through B (a relay; A owns the room).
        let through_b = publisher(&replicas[1], &model, "resumed", &token, Arc::clone(&next));
        let before = counts();
        until(Duration::from_secs(10), "frames through B", || async {
            counts().iter().zip(&before).all(|(n, b)| *n >= b + 20)
        })
        .await;
        signal(&replicas[1], "-STOP");
        // Frames keep going into B's socket for a while, then the publisher moves to C.
        tokio::time::sleep(Duration::from_millis(1500)).await;
        through_b.abort();
        let through_c = publisher(&replicas[2], &model, "resumed", &token, Arc::clone(&next));
        tokio::time::sleep(Duration::from_millis(1500)).await;
        signal(&replicas[1], "-CONT");
        let resumed = counts();
        until(
            Duration::from_secs(10),
            "frames after B resumed",
            || async { counts().iter().zip(&resumed).all(|(n, b)| *n >= b + 50) },
        )
        .await;
        through_c.abort();
        eprintln!(
            "run {run}: B paused 3 s with its publisher's frames buffered; B did not forward {} of them",
            replicas[1]
                .metric("crease_cluster_stale_forwards_total")
                .await
        );
    }
    for ((seen, task), id) in viewers.into_iter().zip(["A", "C"]) {
        task.abort();
        let seqs = seen.lock().unwrap().seqs.clone();
        increasing(&seqs).unwrap_or_else(|e| panic!("viewer on {id}: {e}"));
        eprintln!("viewer on {id}: {} frames, seq only increasing", seqs.len());
    }
}
