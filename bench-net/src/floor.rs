//! This machine's floor for a fan-out (issue 41): what the least a server could spend to hand
//! one frame to each of N viewers costs here, measured in the same run as the fan-out it is
//! compared with. One thread writes one message of the frame's size to each of N loopback TCP
//! sockets per frame period (a plain blocking `write`, no framing, no tasks, no copies), while
//! tasks on the benchmark's runtime read the other ends as the viewers do; the figure is the
//! writing thread's CPU per write, from `/proc/thread-self/stat`. A server's CPU per
//! viewer-frame (`ScenarioReport::server_cpu_us_per_viewer_frame`) over it is the fan-out's
//! ratio to its floor.

use std::io::Write as _;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use tokio::io::AsyncReadExt as _;
use tokio::net::TcpListener;

use super::report::Floor;
use super::server::clock_ticks;

/// The fewest clock ticks of CPU a floor is given from (a 5% figure at most one tick off).
const MIN_TICKS: f64 = 20.0;

/// CPU seconds of the calling thread so far (utime + stime of `/proc/thread-self/stat`).
fn thread_cpu_seconds(hz: f64) -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    Some(super::server::stat_ticks(&stat)? as f64 / hz)
}

/// Measures the floor for `sockets` viewers of `bytes`-long frames at `rate` frames per
/// second, over `seconds` (module docs).
///
/// # Errors
/// A socket that cannot be opened (e.g. too few file descriptors for `sockets` pairs), a write
/// that fails, or no per-thread CPU figure on this system.
pub(super) async fn measure(
    sockets: usize,
    bytes: usize,
    rate: f64,
    seconds: f64,
) -> anyhow::Result<Floor> {
    let bytes = bytes.max(1);
    let listener = TcpListener::bind("127.0.0.1:0")
        .await
        .context("the floor: binding a loopback listener")?;
    let addr = listener.local_addr()?;
    let mut writers = Vec::with_capacity(sockets);
    let mut readers = tokio::task::JoinSet::new();
    for k in 0..sockets {
        let (connected, accepted) = tokio::join!(tokio::net::TcpStream::connect(addr), async {
            listener.accept().await
        });
        let connected =
            connected.with_context(|| format!("the floor: connecting socket {k} of {sockets}"))?;
        let (mut viewer, _) =
            accepted.with_context(|| format!("the floor: accepting socket {k} of {sockets}"))?;
        connected.set_nodelay(true)?;
        let writer = connected.into_std()?;
        writer.set_nonblocking(false)?;
        writers.push(writer);
        // The viewer's end reads until the writer closes.
        readers.spawn(async move {
            let mut buf = vec![0u8; 64 * 1024];
            let mut read = 0u64;
            while let Ok(n) = viewer.read(&mut buf).await {
                if n == 0 {
                    break;
                }
                read += n as u64;
            }
            read
        });
    }
    let frames = (rate * seconds).ceil().max(1.0) as u64;
    let period = Duration::from_secs_f64(1.0 / rate);
    let message = vec![0x5au8; bytes];
    let hz = clock_ticks();
    let writing = tokio::task::spawn_blocking(move || -> anyhow::Result<(f64, f64)> {
        let cpu0 = thread_cpu_seconds(hz).context("the floor: no /proc/thread-self/stat")?;
        let (mut busy, start) = (Duration::ZERO, Instant::now());
        for frame in 0..frames {
            let tick = start + period.mul_f64(frame as f64);
            if let Some(wait) = tick.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            let t = Instant::now();
            for w in &mut writers {
                w.write_all(&message)?;
            }
            busy += t.elapsed();
        }
        let cpu = thread_cpu_seconds(hz).context("the floor: no /proc/thread-self/stat")? - cpu0;
        drop(writers);
        Ok((cpu, busy.as_secs_f64()))
    });
    let (cpu, busy) = writing.await.context("the floor's writing thread")??;
    let mut received = 0u64;
    while let Some(read) = readers.join_next().await {
        received += read.context("a floor reader")?;
    }
    let writes = frames * sockets as u64;
    anyhow::ensure!(
        received == writes * bytes as u64,
        "the floor: the readers got {received} bytes of {}",
        writes * bytes as u64
    );
    // /proc counts CPU in clock ticks (10 ms here): a figure from fewer than MIN_TICKS is
    // noise, and none is given.
    let measured = cpu * hz >= MIN_TICKS;
    Ok(Floor {
        sockets,
        bytes,
        writes,
        cpu_us_per_write: measured.then(|| cpu * 1e6 / writes as f64),
        wall_us_per_write: busy * 1e6 / writes as f64,
    })
}
