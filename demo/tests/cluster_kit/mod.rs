//! Shared by the cluster tests (`cluster.rs`, `cluster_trust.rs`): a `nats-server` child and
//! `crease-server` replicas as processes.
#![allow(dead_code)] // each test file uses its part

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{http_get, metric};
use crease_proto::v1::crease_client::CreaseClient;

/// The admin token every replica starts with.
pub(crate) const ADMIN: &str = "cluster-admin";

/// A port that was free a moment ago.
pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

pub(crate) fn nats_binary() -> Option<PathBuf> {
    [
        "/usr/sbin/nats-server",
        "/usr/bin/nats-server",
        "/usr/local/bin/nats-server",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.is_file())
    .or_else(|| {
        let out = Command::new("sh")
            .args(["-c", "command -v nats-server"])
            .output()
            .ok()?;
        let path = String::from_utf8(out.stdout).ok()?.trim().to_owned();
        (!path.is_empty()).then(|| PathBuf::from(path))
    })
}

/// A `nats-server` child with JetStream, on a fixed port and store (so it can be restarted);
/// with a configuration file when `config` is given (it names the port and store itself).
pub(crate) struct Nats {
    bin: PathBuf,
    pub(crate) port: u16,
    store: PathBuf,
    config: Option<PathBuf>,
    child: Child,
}

impl Nats {
    pub(crate) fn start(bin: &Path, port: u16, store: &Path) -> Nats {
        Nats::start_with(bin, port, store, None)
    }

    /// With a configuration file (TLS, users: `cluster_trust.rs`), whose `listen` is
    /// `127.0.0.1:port` and whose JetStream store is `store`.
    pub(crate) fn start_with(bin: &Path, port: u16, store: &Path, config: Option<&Path>) -> Nats {
        let mut cmd = Command::new(bin);
        match config {
            Some(c) => cmd.arg("-c").arg(c),
            None => cmd
                .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
                .arg(store),
        };
        // Its log beside the store, shown when it does not come up.
        let log = store.with_extension("log");
        let child = cmd
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(20);
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                Instant::now() < deadline,
                "nats-server did not listen on {port}:\n{}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        Nats {
            bin: bin.to_owned(),
            port,
            store: store.to_owned(),
            config: config.map(Path::to_owned),
            child,
        }
    }

    pub(crate) fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    pub(crate) fn restart(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
        let config = self.config.clone();
        *self = Nats::start_with(
            &self.bin.clone(),
            self.port,
            &self.store.clone(),
            config.as_deref(),
        );
    }
}

impl Drop for Nats {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `crease-server` replica.
pub(crate) struct Replica {
    pub(crate) id: String,
    pub(crate) child: Child,
    pub(crate) grpc: String,
    pub(crate) http: std::net::SocketAddr,
    log: PathBuf,
}

impl Replica {
    pub(crate) fn start(id: &str, models: &Path, nats: &str, dir: &Path) -> Replica {
        Replica::start_with(id, models, nats, dir, &[])
    }

    /// With `extra` arguments (credentials, TLS, the cluster key, the lease).
    pub(crate) fn start_with(
        id: &str,
        models: &Path,
        nats: &str,
        dir: &Path,
        extra: &[String],
    ) -> Replica {
        let (grpc, http) = (free_port(), free_port());
        let log = dir.join(format!("{id}.log"));
        let child = Command::new(env!("CARGO_BIN_EXE_crease-server"))
            .arg("--models")
            .arg(models)
            .args(["--nats", nats, "--replica-id", id])
            .args(["--grpc", &format!("127.0.0.1:{grpc}")])
            .args(["--http", &format!("127.0.0.1:{http}")])
            // Rooms predict by the regression alone, as `common::predicted` does, unless a
            // test's request asks for the refinement (the registry carries what a room runs).
            .args(["--refine", "off"])
            .args(extra)
            .env("CREASE_ADMIN_TOKEN", ADMIN)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        Replica {
            id: id.to_owned(),
            child,
            grpc: format!("http://127.0.0.1:{grpc}"),
            http: format!("127.0.0.1:{http}").parse().unwrap(),
            log,
        }
    }

    pub(crate) fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    pub(crate) async fn ready(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                panic!("replica {} exited ({status}):\n{}", self.id, self.log());
            }
            if std::net::TcpStream::connect(self.http).is_ok()
                && http_get(self.http, "/readyz").await.0 == 200
            {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "replica {} not ready:\n{}",
                self.id,
                self.log()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    pub(crate) async fn client(&self) -> CreaseClient<tonic::transport::Channel> {
        CreaseClient::connect(self.grpc.clone()).await.unwrap()
    }

    /// `/api/rooms` as JSON.
    pub(crate) async fn rooms(&self) -> serde_json::Value {
        let (status, body) = http_get(self.http, "/api/rooms").await;
        assert_eq!(status, 200, "{body}");
        serde_json::from_str(&body).unwrap()
    }

    /// The owner of `room` as this replica's `/api/rooms` says.
    pub(crate) async fn owner_of(&self, room: &str) -> Option<String> {
        let rooms = self.rooms().await;
        rooms["cluster"].as_array()?.iter().find_map(|r| {
            (r["room"] == room).then(|| r["owner"].as_str().unwrap_or_default().to_owned())
        })
    }

    pub(crate) async fn metric(&self, name: &str) -> f64 {
        let (_, body) = http_get(self.http, "/metrics").await;
        metric(&body, name)
    }

    pub(crate) fn kill9(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits until `f` holds, at most `limit` (then fails, saying `what`); returns how long it took.
pub(crate) async fn until<F: std::future::Future<Output = bool>>(
    limit: Duration,
    what: &str,
    mut f: impl FnMut() -> F,
) -> Duration {
    let start = Instant::now();
    while !f().await {
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    start.elapsed()
}

/// Sends `signal` (`-STOP`, `-CONT`) to `replica`'s process.
pub(crate) fn signal(replica: &Replica, signal: &str) {
    let pid = replica.child.id().to_string();
    let status = Command::new("kill").args([signal, &pid]).status().unwrap();
    assert!(status.success(), "kill {signal} {pid}");
}

/// Replicas A, B, C on `models` and `nats` with `args`, each ready.
pub(crate) async fn three_replicas(
    models: &Path,
    nats: &str,
    dir: &Path,
    args: &[String],
) -> Vec<Replica> {
    let mut replicas: Vec<Replica> = ["A", "B", "C"]
        .iter()
        .map(|id| Replica::start_with(id, models, nats, dir, args))
        .collect();
    for r in &mut replicas {
        r.ready().await;
    }
    replicas
}

/// Waits (30 s at most) for `replica` to exit, which it must do unsuccessfully, saying in its
/// log that NATS refused it; returns its log's last line.
pub(crate) async fn refused_by_nats(replica: &mut Replica) -> String {
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = replica.child.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "replica {} still running:\n{}",
            replica.id,
            replica.log()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    let log = replica.log();
    assert!(!status.success(), "replica {} exited 0:\n{log}", replica.id);
    assert!(
        log.to_lowercase().contains("authorization violation"),
        "replica {}'s log does not say NATS refused it:\n{log}",
        replica.id
    );
    log.lines().last().unwrap_or_default().to_owned()
}
