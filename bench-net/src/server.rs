//! The server under test: a `crease-server` child process spawned on free loopback ports (its
//! scratch folder, log and clean-up), or a running one; and the CPU time of a process, read from
//! `/proc/PID/stat`, so the server's CPU is measured apart from the clients'.

use std::collections::hash_map::RandomState;
use std::fs::File;
use std::hash::BuildHasher;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::time::Instant;

use super::args::BenchNetArgs;
use crease_remote::client::list_models;
use crease_remote::connect;

/// How long the spawned server may take to load its model and listen: the horse loads in
/// about a second; a debug build on a busy machine takes much longer.
const SERVER_START: Duration = Duration::from_secs(60);
/// A `crease-server` child process and its scratch folder (model link, log); killed and
/// removed when dropped.
#[derive(Debug)]
pub(super) struct SpawnedServer {
    pub(super) child: Child,
    dir: PathBuf,
}

impl SpawnedServer {
    /// Its whole log (stderr).
    pub(super) fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default()
    }

    /// The last lines of its log, for error messages.
    pub(super) fn log_tail(&self) -> String {
        let log = self.log();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }
}

impl Drop for SpawnedServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The server under test.
#[derive(Debug)]
pub(super) struct Target {
    /// Its gRPC URL.
    pub(super) url: String,
    /// Its admin token (opens and closes the rooms).
    pub(super) admin_token: String,
    /// The model's name there.
    pub(super) model: String,
    /// Its process, to measure its CPU.
    pub(super) pid: Option<u32>,
    /// For the report.
    pub(super) description: String,
    /// The child process, when spawned here.
    pub(super) spawned: Option<SpawnedServer>,
    /// Its HTTP address (`/metrics`), when spawned here.
    pub(super) http: Option<std::net::SocketAddr>,
}

/// 128 random bits, hex (std's per-map random SipHash keys: no extra dependency).
pub(super) fn random_token() -> String {
    (0..2)
        .map(|_| format!("{:016x}", RandomState::new().hash_one(0u8)))
        .collect()
}

/// A loopback address with a port that was free a moment ago.
pub(super) fn free_address(
    held: &mut Vec<std::net::TcpListener>,
) -> anyhow::Result<std::net::SocketAddr> {
    let listener =
        std::net::TcpListener::bind("127.0.0.1:0").context("finding a free loopback port")?;
    let addr = listener.local_addr()?;
    // Held until both ports are chosen, so they differ; dropped before the server binds.
    held.push(listener);
    Ok(addr)
}

/// Spawns `crease-server` on the model and waits until it answers.
pub(super) async fn spawn_server(args: &BenchNetArgs) -> anyhow::Result<Target> {
    // The rate limit counts actors x frames (issue 38): room for every actor at the bench's
    // rate, with the default's headroom.
    let hz = (args.rate * f64::from(args.actors) * 4.0).max(240.0);
    // Every subscriber comes from this one address: the caps on what one address may hold,
    // and on a room's subscribers, are raised as the soak raises them.
    let mut extra = vec![
        "--max-publish-hz".to_owned(),
        hz.to_string(),
        "--max-actors".to_owned(),
        args.actors.max(8).to_string(),
        "--max-subscribers".to_owned(),
        "100000".to_owned(),
    ];
    extra.extend(SOAK_LIMITS[..8].iter().map(|s| (*s).to_owned()));
    spawn_server_with(args, &extra, &random_token()).await
}

/// The limits a soak raises: every one of its clients comes from one address.
pub(super) const SOAK_LIMITS: [&str; 10] = [
    "--max-connections-per-address",
    "100000",
    "--max-connections",
    "100000",
    "--max-streams-per-address",
    "100000",
    "--max-streams",
    "100000",
    "--max-publish-hz",
    "1000",
];

/// The `crease-server` binary: `--server-bin`, else the one beside this executable.
pub(super) fn server_binary(args: &BenchNetArgs) -> anyhow::Result<PathBuf> {
    let bin = match &args.server_bin {
        Some(bin) => bin.clone(),
        None => std::env::current_exe()
            .context("locating the crease executable")?
            .with_file_name(format!("crease-server{}", std::env::consts::EXE_SUFFIX)),
    };
    if !bin.is_file() {
        bail!(
            "{}: no crease-server binary (build it with `cargo build --release -p crease-demo`, or pass --server-bin PATH)",
            bin.display()
        );
    }
    Ok(bin)
}

/// [`spawn_server`] with `extra` arguments (a cluster's `--nats`, a soak's limits) and admin
/// token `admin`.
pub(super) async fn spawn_server_with(
    args: &BenchNetArgs,
    extra: &[String],
    admin_token: &str,
) -> anyhow::Result<Target> {
    let bin = server_binary(args)?;
    let model = args
        .model
        .file_stem()
        .and_then(|s| s.to_str())
        .context("--model: the file name is not valid UTF-8")?
        .to_owned();
    let dir = std::env::temp_dir().join(format!(
        "crease-bench-net-{}-{}",
        std::process::id(),
        &random_token()[..8]
    ));
    let models = dir.join("models");
    std::fs::create_dir_all(&models).with_context(|| format!("creating {}", models.display()))?;
    let link = models.join(format!("{model}.crease"));
    let source =
        std::fs::canonicalize(&args.model).with_context(|| format!("{}", args.model.display()))?;
    #[cfg(unix)]
    std::os::unix::fs::symlink(&source, &link)
        .with_context(|| format!("linking {}", link.display()))?;
    #[cfg(not(unix))]
    std::fs::copy(&source, &link).with_context(|| format!("copying to {}", link.display()))?;
    let log = File::create(dir.join("server.log")).context("creating the server log")?;
    let mut held = Vec::new();
    let grpc = free_address(&mut held)?;
    let http = free_address(&mut held)?;
    drop(held);
    let admin_token = admin_token.to_owned();
    let child = Command::new(&bin)
        .arg("--models")
        .arg(&models)
        .args(["--grpc", &grpc.to_string(), "--http", &http.to_string()])
        .args(extra)
        .env("CREASE_ADMIN_TOKEN", &admin_token)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let mut server = SpawnedServer { child, dir };
    let url = format!("http://{grpc}");
    let deadline = Instant::now() + SERVER_START;
    loop {
        if let Some(status) = server.child.try_wait()? {
            bail!(
                "{} exited ({status}) before answering:\n{}",
                bin.display(),
                server.log_tail()
            );
        }
        if let Ok(mut client) = connect(&url, None).await
            && list_models(&mut client).await.is_ok()
        {
            break;
        }
        if Instant::now() > deadline {
            bail!(
                "{} did not answer on {url} within {SERVER_START:?}:\n{}",
                bin.display(),
                server.log_tail()
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    Ok(Target {
        description: format!("{} (spawned, pid {})", bin.display(), server.child.id()),
        pid: Some(server.child.id()),
        url,
        admin_token,
        model,
        spawned: Some(server),
        http: Some(http),
    })
}

/// A `nats-server` child (JetStream on, a scratch store), killed and its store removed when
/// dropped.
#[derive(Debug)]
pub(super) struct SpawnedNats {
    child: Child,
    dir: PathBuf,
    /// Its client URL.
    pub(super) url: String,
}

impl Drop for SpawnedNats {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The `nats-server` binary: `--nats-bin`, else Debian's or one on the PATH.
pub(super) fn nats_binary(args: &BenchNetArgs) -> anyhow::Result<PathBuf> {
    if let Some(bin) = &args.nats_bin {
        return Ok(bin.clone());
    }
    let on_path = std::env::var_os("PATH")
        .map(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join("nats-server"))
                .collect::<Vec<_>>()
        })
        .unwrap_or_default();
    [
        PathBuf::from("/usr/sbin/nats-server"),
        PathBuf::from("/usr/bin/nats-server"),
        PathBuf::from("/usr/local/bin/nats-server"),
    ]
    .into_iter()
    .chain(on_path)
    .find(|p| p.is_file())
    .context("no nats-server binary (apt-get install -y nats-server, or --nats-bin PATH)")
}

/// A local cluster: `nats-server` with JetStream and `n` `crease-server` replicas joined to
/// it (ids `r0`, `r1`, ...), each hosting the model; the first is where rooms are opened.
pub(super) async fn spawn_cluster(
    args: &BenchNetArgs,
    n: usize,
) -> anyhow::Result<(SpawnedNats, Vec<Target>)> {
    let bin = nats_binary(args)?;
    let dir = std::env::temp_dir().join(format!(
        "crease-bench-nats-{}-{}",
        std::process::id(),
        &random_token()[..8]
    ));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut held = Vec::new();
    let port = free_address(&mut held)?.port();
    drop(held);
    let child = Command::new(&bin)
        .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
        .arg(dir.join("js"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let nats = SpawnedNats {
        child,
        dir,
        url: format!("nats://127.0.0.1:{port}"),
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    while tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .is_err()
    {
        if Instant::now() > deadline {
            bail!("{} did not listen on port {port}", bin.display());
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let admin = random_token();
    let mut replicas = Vec::with_capacity(n);
    for r in 0..n {
        let extra = [
            "--nats".to_owned(),
            nats.url.clone(),
            "--replica-id".to_owned(),
            format!("r{r}"),
        ];
        replicas.push(spawn_server_with(args, &extra, &admin).await?);
    }
    Ok((nats, replicas))
}

/// `USER_HZ`, the unit of `/proc/PID/stat`'s times: `getconf CLK_TCK`, else Linux's 100.
pub(super) fn clock_ticks() -> f64 {
    Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|&hz| hz > 0.0)
        .unwrap_or(100.0)
}

/// CPU seconds (user + system, every thread, living or ended) of process `pid` so far, from
/// `/proc/PID/stat`; `None` off Linux.
pub(super) fn cpu_seconds(pid: u32, hz: f64) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    Some(stat_ticks(&stat)? as f64 / hz)
}

/// The number after `name` (e.g. `VmRSS:`, in kB) in the text of `/proc/PID/status`.
pub(super) fn status_field(status: &str, name: &str) -> Option<f64> {
    status
        .lines()
        .find(|l| l.starts_with(name))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// Process `pid`'s resident set in KiB (`VmRSS` of `/proc/PID/status`); `None` once it is gone.
pub(super) fn rss_kib(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status_field(&status, "VmRSS:")
}

/// utime + stime, in clock ticks, of a `/proc/PID/stat` line.
pub(super) fn stat_ticks(stat: &str) -> Option<u64> {
    // Field 2 (the command name, in parentheses) may hold spaces and parentheses: count from
    // after its last `)`.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // `rest` starts at field 3; utime and stime are fields 14 and 15 (proc(5)).
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_stat_with_spaces_and_parentheses_in_the_name() {
        // The kernel's format: pid (comm) state ppid ... utime stime ...
        let stat = "42 (a (b) c) S 1 42 42 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 3 0\n";
        assert_eq!(stat_ticks(stat), Some(300));
        assert_eq!(stat_ticks("42 (x) S 1 2"), None);
        assert_eq!(stat_ticks("no parenthesis"), None);
    }

    #[test]
    fn cpu_of_this_process_is_measured_on_linux() {
        let hz = clock_ticks();
        assert!(hz > 0.0);
        if cfg!(target_os = "linux") {
            let a = cpu_seconds(std::process::id(), hz).unwrap();
            let mut x = 0u64;
            let t = std::time::Instant::now();
            while t.elapsed() < Duration::from_millis(50) {
                x = x.wrapping_add(std::hint::black_box(1));
            }
            let b = cpu_seconds(std::process::id(), hz).unwrap();
            assert!(b >= a && x > 0);
        }
    }

    #[test]
    fn random_tokens_differ() {
        let (a, b) = (random_token(), random_token());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
    }
}
