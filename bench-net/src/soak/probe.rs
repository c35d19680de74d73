//! The soak's view of the server process: RSS, fds and threads from `/proc`, tasks,
//! subscriptions and predicted frames from `/metrics`, and the wait for it to settle.

use std::time::Duration;

use tokio::time::Instant;

use crate::server::status_field;

/// How long the server has, once every client left, to come back to its baseline's fds and
/// tasks (a blocking-pool thread idles out in 10 s).
pub(super) const SETTLE: Duration = Duration::from_secs(30);
/// Above the baseline, what a settled server may still hold: the sampler's own `/metrics`
/// connection and its tasks, a closing connection or two.
const FD_SLACK: usize = 4;
/// See [`FD_SLACK`].
const TASK_SLACK: u64 = 16;

/// RSS is compared as the peak over this many seconds (`SoakReport::rss_warm_mib`).
const RSS_WINDOW_S: f64 = 60.0;

/// One sample of the server.
#[derive(Clone, Debug, serde::Serialize)]
pub(crate) struct Sample {
    /// Seconds since the soak started.
    pub t: f64,
    /// Resident set, MiB.
    pub rss_mib: f64,
    /// Open file descriptors.
    pub fds: usize,
    /// OS threads.
    pub threads: usize,
    /// Alive tasks on its runtime (`crease_tasks`).
    pub tasks: Option<u64>,
    /// Live mesh subscriptions (`crease_subscribers`): the viewers watching and the checkers,
    /// if none outlives its client.
    pub subscribers: Option<u64>,
    /// Control frames the server predicted so far (`crease_frames_published_total`): its
    /// throughput between samples.
    pub published: Option<u64>,
}

/// The highest RSS of the samples in the minute up to `t` seconds (0 with none).
pub(super) fn rss_peak(samples: &[Sample], t: f64) -> f64 {
    samples
        .iter()
        .filter(|s| s.t > t - RSS_WINDOW_S && s.t <= t)
        .map(|s| s.rss_mib)
        .fold(0.0, f64::max)
}

impl Sample {
    /// Whether this sample holds no more fds and tasks than `baseline` (with the slack).
    pub(super) fn within(&self, baseline: &Sample) -> bool {
        self.fds <= baseline.fds + FD_SLACK
            && match (self.tasks, baseline.tasks) {
                (Some(t), Some(b)) => t <= b + TASK_SLACK,
                _ => true,
            }
    }
}

/// Samples the server once a second until it is back within its `baseline`, or [`SETTLE`]
/// has passed; the last sample (`None` once the server is gone).
pub(super) async fn settle(
    pid: u32,
    http: std::net::SocketAddr,
    started: Instant,
    baseline: &Sample,
) -> Option<Sample> {
    let deadline = Instant::now() + SETTLE;
    loop {
        let s = sample(pid, http, started).await?;
        if s.within(baseline) || Instant::now() >= deadline {
            return Some(s);
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// The server's RSS, fds and threads (`/proc`) and tasks (`/metrics`); `None` once it is gone.
pub(crate) async fn sample(
    pid: u32,
    http: std::net::SocketAddr,
    started: Instant,
) -> Option<Sample> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    // A zombie (exited, not yet reaped) has no VmRSS.
    let rss_kib = status_field(&status, "VmRSS:")?;
    let threads = status_field(&status, "Threads:").unwrap_or(0.0) as usize;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count());
    let metrics = metrics(http).await.unwrap_or_default();
    Some(Sample {
        t: started.elapsed().as_secs_f64(),
        rss_mib: rss_kib / 1024.0,
        fds,
        threads,
        tasks: metric(&metrics, "crease_tasks"),
        subscribers: metric(&metrics, "crease_subscribers"),
        published: metric(&metrics, "crease_frames_published_total"),
    })
}

/// One value of a `/metrics` text.
fn metric(body: &str, name: &str) -> Option<u64> {
    body.lines()
        .find(|l| l.starts_with(name) && l[name.len()..].starts_with(' '))?
        .rsplit(' ')
        .next()?
        .parse::<f64>()
        .ok()
        .map(|v| v as u64)
}

/// The server's `/metrics` text (plain HTTP/1.1 GET).
async fn metrics(http: std::net::SocketAddr) -> Option<String> {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let mut s = tokio::net::TcpStream::connect(http).await.ok()?;
    s.write_all(b"GET /metrics HTTP/1.1\r\nhost: x\r\nconnection: close\r\n\r\n")
        .await
        .ok()?;
    let mut body = String::new();
    tokio::time::timeout(Duration::from_secs(5), s.read_to_string(&mut body))
        .await
        .ok()?
        .ok()?;
    Some(body)
}
