//! The chaos soak's cluster as processes: a `nats-server` with JetStream on a fixed port and
//! store ([`Nats`], so that it can be killed and started again as it was) and `crease-server`
//! replicas on fixed ports with fixed arguments ([`Replica`]: killed with SIGKILL and started
//! again the same, paused with SIGSTOP and resumed). The bench's `server` module spawns
//! servers on fresh ports each time and removes their folder when they end; the soak needs
//! them back where they were, with their logs and takes kept, so it has its own.
//!
//! Every child is killed when its handle is dropped (a paused one too).

use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::time::Instant;

/// How long a replica may take to load its model and answer `/readyz` (three replicas load at
/// once on a small machine).
const REPLICA_START: Duration = Duration::from_secs(120);
/// How long `nats-server` may take to listen.
const NATS_START: Duration = Duration::from_secs(20);

/// `n` loopback addresses whose ports were free a moment ago (all different).
pub(super) fn free_addresses(n: usize) -> anyhow::Result<Vec<SocketAddr>> {
    let held = (0..n)
        .map(|_| std::net::TcpListener::bind("127.0.0.1:0"))
        .collect::<Result<Vec<_>, _>>()
        .context("finding free loopback ports")?;
    held.iter()
        .map(|l| l.local_addr().context("a free port's address"))
        .collect()
}

/// A log file opened for appending, with a line saying what starts now.
fn append_log(path: &Path, what: &str) -> anyhow::Result<File> {
    let mut file = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    writeln!(file, "==== crease bench-net --chaos: {what} ====")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(file)
}

/// Sends `signal` (`STOP`, `CONT`) to process `pid` with kill(1) (the crate forbids unsafe
/// code, so no libc call).
pub(super) fn signal(pid: u32, signal: &str) -> anyhow::Result<()> {
    let status = Command::new("kill")
        .arg(format!("-{signal}"))
        .arg(pid.to_string())
        .stderr(Stdio::null())
        .status()
        .with_context(|| format!("running kill -{signal} {pid}"))?;
    if !status.success() {
        bail!("kill -{signal} {pid}: {status}");
    }
    Ok(())
}

/// `nats-server -js` on a fixed port and store, restartable.
#[derive(Debug)]
pub(super) struct Nats {
    bin: PathBuf,
    port: u16,
    store: PathBuf,
    /// Its stderr.
    pub(super) log: PathBuf,
    child: Option<Child>,
    /// Times started.
    pub(super) starts: u32,
}

impl Nats {
    /// Starts it and waits until it listens.
    pub(super) async fn start(
        bin: PathBuf,
        port: u16,
        store: PathBuf,
        log: PathBuf,
    ) -> anyhow::Result<Nats> {
        let mut nats = Nats {
            bin,
            port,
            store,
            log,
            child: None,
            starts: 0,
        };
        nats.spawn().await?;
        Ok(nats)
    }

    /// Its client URL.
    pub(super) fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    async fn spawn(&mut self) -> anyhow::Result<()> {
        self.starts += 1;
        let log = append_log(&self.log, &format!("start {}", self.starts))?;
        let child = Command::new(&self.bin)
            .args([
                "-js",
                "-a",
                "127.0.0.1",
                "-p",
                &self.port.to_string(),
                "-sd",
            ])
            .arg(&self.store)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .with_context(|| format!("starting {}", self.bin.display()))?;
        self.child = Some(child);
        let deadline = Instant::now() + NATS_START;
        while tokio::net::TcpStream::connect(("127.0.0.1", self.port))
            .await
            .is_err()
        {
            if let Some(status) = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten())
            {
                bail!(
                    "{} exited ({status}) before listening on {} (log: {})",
                    self.bin.display(),
                    self.port,
                    self.log.display()
                );
            }
            if Instant::now() > deadline {
                bail!(
                    "{} did not listen on port {} within {NATS_START:?} (log: {})",
                    self.bin.display(),
                    self.port,
                    self.log.display()
                );
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok(())
    }

    fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Kills it (SIGKILL) and starts it again on the same port and store.
    pub(super) async fn restart(&mut self) -> anyhow::Result<()> {
        self.kill();
        self.spawn().await
    }
}

impl Drop for Nats {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A `crease-server` replica with fixed ports and arguments, restartable.
#[derive(Debug)]
pub(super) struct Replica {
    /// Its replica id (`r0`, ...).
    pub(super) id: String,
    bin: PathBuf,
    args: Vec<String>,
    admin_token: String,
    /// Its gRPC URL and HTTP address.
    pub(super) url: String,
    /// See `url`.
    pub(super) http: SocketAddr,
    /// Its stderr (every start appended).
    pub(super) log: PathBuf,
    child: Option<Child>,
    /// Times started.
    pub(super) starts: u32,
}

impl Replica {
    /// A replica `id` of `bin` with `args` (everything but the admin token, passed in the
    /// environment), not started.
    pub(super) fn new(
        id: String,
        bin: PathBuf,
        args: Vec<String>,
        admin_token: String,
        grpc: SocketAddr,
        http: SocketAddr,
        log: PathBuf,
    ) -> Replica {
        Replica {
            id,
            bin,
            args,
            admin_token,
            url: format!("http://{grpc}"),
            http,
            log,
            child: None,
            starts: 0,
        }
    }

    /// Starts the process (not waiting for it: [`Replica::ready`]).
    pub(super) fn spawn(&mut self) -> anyhow::Result<()> {
        self.starts += 1;
        let log = append_log(&self.log, &format!("start {} of {}", self.starts, self.id))?;
        let mut command = Command::new(&self.bin);
        command
            .args(&self.args)
            .env("CREASE_ADMIN_TOKEN", &self.admin_token)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log);
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "info");
        }
        let child = command
            .spawn()
            .with_context(|| format!("starting {} ({})", self.bin.display(), self.id))?;
        self.child = Some(child);
        Ok(())
    }

    /// Its process id while it runs.
    pub(super) fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    /// Whether it exited (on its own: it is reaped here), and how.
    pub(super) fn exited(&mut self) -> Option<std::process::ExitStatus> {
        let status = self.child.as_mut()?.try_wait().ok().flatten()?;
        self.child = None;
        Some(status)
    }

    /// Waits until it answers `/readyz` with 200.
    pub(super) async fn ready(&mut self) -> anyhow::Result<()> {
        let deadline = Instant::now() + REPLICA_START;
        loop {
            if let Some(status) = self.exited() {
                bail!(
                    "replica {} exited ({status}) before it was ready:\n{}",
                    self.id,
                    self.log_tail()
                );
            }
            if http_status(self.http, "/readyz").await == Some(200) {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!(
                    "replica {} not ready within {REPLICA_START:?}:\n{}",
                    self.id,
                    self.log_tail()
                );
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Kills it with SIGKILL (`kill -9`).
    pub(super) fn kill9(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Its whole log.
    pub(super) fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The last lines of its log.
    pub(super) fn log_tail(&self) -> String {
        let log = self.log_text();
        let lines: Vec<&str> = log.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        self.kill9();
    }
}

/// The status code of `GET path` on `http` (plain HTTP/1.1), `None` when it does not answer
/// within 2 s.
pub(super) async fn http_status(http: SocketAddr, path: &str) -> Option<u16> {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let exchange = async {
        let mut s = tokio::net::TcpStream::connect(http).await.ok()?;
        let request = format!("GET {path} HTTP/1.1\r\nhost: chaos\r\nconnection: close\r\n\r\n");
        s.write_all(request.as_bytes()).await.ok()?;
        let mut head = vec![0u8; 64];
        let n = s.read(&mut head).await.ok()?;
        let line = String::from_utf8_lossy(&head[..n]).into_owned();
        line.split_whitespace().nth(1)?.parse().ok()
    };
    tokio::time::timeout(Duration::from_secs(2), exchange)
        .await
        .ok()
        .flatten()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check

    use super::*;

    #[test]
    fn free_addresses_differ() {
        let a = free_addresses(4).unwrap();
        let mut ports: Vec<u16> = a.iter().map(SocketAddr::port).collect();
        ports.sort_unstable();
        ports.dedup();
        assert_eq!(ports.len(), 4);
    }

    #[test]
    fn signalling_a_process_that_is_gone_fails() {
        let mut child = Command::new("true").spawn().unwrap();
        let pid = child.id();
        child.wait().unwrap();
        assert!(signal(pid, "CONT").is_err());
    }
}
