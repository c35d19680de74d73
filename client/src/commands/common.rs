//! Pieces shared by the subcommands: loading example sets, parsing control-point specs,
//! progress display, connecting to a server, the requests' small pieces (rooms, tokens, clocks)
//! and percentiles.

use std::io::IsTerminal;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::mesh::examples::ExampleSet;
use crease_core::predictor::Refinement;
use crease_train::bones::IterationStat;
use crease_train::pipeline::ControlSpec;
use indicatif::{ProgressBar, ProgressStyle};

/// Loads an example set and says so on stderr.
pub fn load_examples(path: &Path) -> anyhow::Result<ExampleSet> {
    let start = Instant::now();
    let set = ExampleSet::load(path)
        .with_context(|| format!("reading examples from {}", path.display()))?;
    eprintln!(
        "read {} examples of {} vertices from {} in {:.2} s (rest pose: {})",
        set.examples.len(),
        set.rest.vertex_count(),
        path.display(),
        start.elapsed().as_secs_f64(),
        set.rest_name
    );
    Ok(set)
}

/// Parses `--control-points`: `auto`, `auto:N`, `select:N`, or a comma-separated list of vertex
/// indices.
/// Without the option, the set's manifest list wins, else `auto:8`.
pub fn control_spec(arg: Option<&str>, set: &ExampleSet) -> anyhow::Result<ControlSpec> {
    match arg {
        None => Ok(match &set.control_points {
            Some(v) => ControlSpec::Vertices(v.clone()),
            None => ControlSpec::Auto(8),
        }),
        Some("auto") => Ok(ControlSpec::Auto(8)),
        Some(s) if s.starts_with("select:") => {
            let n: usize = s[7..]
                .parse()
                .with_context(|| format!("--control-points {s}: expected select:N"))?;
            if n == 0 {
                bail!("--control-points {s}: need at least one control point");
            }
            Ok(ControlSpec::Select(n))
        }
        Some(s) if s.starts_with("auto:") => {
            let n: usize = s[5..]
                .parse()
                .with_context(|| format!("--control-points {s}: expected auto:N"))?;
            if n == 0 {
                bail!("--control-points {s}: need at least one control point");
            }
            Ok(ControlSpec::Auto(n))
        }
        Some(s) => {
            let v: Result<Vec<u32>, _> = s.split(',').map(|x| x.trim().parse::<u32>()).collect();
            let v = v.with_context(|| {
                format!(
                    "--control-points {s}: expected auto, auto:N or vertex indices like 12,400,7"
                )
            })?;
            Ok(ControlSpec::Vertices(v))
        }
    }
}

/// A progress bar on a terminal, plain lines otherwise.
#[derive(Debug)]
pub struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A bar of `len` steps (the fit's iteration cap).
    pub fn new(len: u64) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(len);
            bar.set_style(
                ProgressStyle::with_template(
                    "{spinner} {prefix:>8} [{bar:30}] {pos}/{len} {msg} ({elapsed})",
                )
                .expect("static template")
                .progress_chars("=> "),
            );
            // The spinner and the clock move during long steps that report nothing.
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            bar
        });
        Self { bar }
    }

    /// Reports one fitting step.
    pub fn step(&self, stat: &IterationStat) {
        let line = format!(
            "{:>7} {:>3}: {:>4} bones, rms {:.4e}, {:.2} s",
            stat.phase, stat.iteration, stat.bones, stat.rms_normalized, stat.seconds
        );
        self.line(
            stat.phase,
            if stat.phase == "fit" {
                Some(stat.iteration as u64)
            } else {
                None
            },
            &format!("rms {:.4e}", stat.rms_normalized),
            &line,
        );
    }

    /// Reports a step of anything: prefix, position, short message, full line.
    pub fn line(&self, prefix: &str, pos: Option<u64>, msg: &str, line: &str) {
        match &self.bar {
            Some(bar) => {
                bar.set_prefix(prefix.to_string());
                if let Some(p) = pos {
                    bar.set_position(p);
                }
                bar.set_message(msg.to_string());
                bar.println(line);
            }
            None => eprintln!("{line}"),
        }
    }

    /// Reports `done` of `total` steps of a counted phase (leave-one-out folds, selection
    /// folds): on a terminal the bar takes that length and position, otherwise `line` is
    /// printed.
    pub fn count(&self, prefix: &str, done: u64, total: u64, line: &str) {
        match &self.bar {
            Some(bar) => {
                bar.set_prefix(prefix.to_string());
                bar.set_length(total);
                bar.set_position(done);
                bar.set_message(String::new());
            }
            None => eprintln!("{line}"),
        }
    }

    /// Moves the bar (prefix, position, short message) without printing a line; nothing
    /// without a terminal.
    pub fn set(&self, prefix: &str, pos: u64, msg: &str) {
        if let Some(bar) = &self.bar {
            bar.set_prefix(prefix.to_string());
            bar.set_position(pos);
            bar.set_message(msg.to_string());
        }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// Largest response message the network commands accept (a 16-bit keyframe of a 151K-vertex
/// detail mesh is ~1.2 MB; batches stream one frame per message).
pub const MAX_RESPONSE_BYTES: usize = 256 << 20;

/// How long to wait for a connection before calling the server unreachable.
const CONNECT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// A gRPC client of the crease server at `server` (`http://` or `https://`). Over https the
/// server's certificate is checked against `ca` (a PEM file, for self-signed or private CAs)
/// or else the Mozilla roots (webpki-roots).
///
/// # Errors
/// A URL that does not parse, an unreadable `ca`, or a server that cannot be reached, each
/// naming what it was.
pub async fn connect(
    server: &str,
    ca: Option<&Path>,
) -> anyhow::Result<crease_proto::v1::crease_client::CreaseClient<tonic::transport::Channel>> {
    use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};
    let mut endpoint = Endpoint::from_shared(server.to_owned())
        .with_context(|| {
            format!("--server {server:?} is not a URL (expected e.g. http://127.0.0.1:50051)")
        })?
        .connect_timeout(CONNECT_TIMEOUT);
    if server.starts_with("https://") {
        let tls = match ca {
            Some(path) => {
                let pem = std::fs::read(path)
                    .with_context(|| format!("reading --ca {}", path.display()))?;
                ClientTlsConfig::new().ca_certificate(Certificate::from_pem(pem))
            }
            None => ClientTlsConfig::new().with_webpki_roots(),
        };
        endpoint = endpoint
            .tls_config(tls)
            .with_context(|| format!("TLS settings for {server}"))?;
    } else if ca.is_some() {
        bail!("--ca applies to https:// servers, got {server}");
    }
    let channel = endpoint
        .connect()
        .await
        .with_context(|| format!("cannot reach the crease server at {server}"))?;
    Ok(crease_proto::v1::crease_client::CreaseClient::new(channel)
        .max_decoding_message_size(MAX_RESPONSE_BYTES))
}

/// Where the network commands find the server.
#[derive(Clone, Debug, clap::Args)]
pub struct ServerArgs {
    /// The server's gRPC address, e.g. `http://localhost:50051` (`https://` for TLS).
    #[arg(long, default_value = "http://localhost:50051")]
    pub server: String,
    /// With an `https://` server: its CA certificate (PEM), e.g. the server's own self-signed
    /// certificate. Default: the Mozilla root certificates.
    #[arg(long, value_name = "FILE")]
    pub ca: Option<std::path::PathBuf>,
}

impl ServerArgs {
    /// A client of the server ([`connect`]).
    pub async fn connect(
        &self,
    ) -> anyhow::Result<crease_proto::v1::crease_client::CreaseClient<tonic::transport::Channel>>
    {
        connect(&self.server, self.ca.as_deref()).await
    }
}

/// The server's description of `room` (its model, settings and counters).
///
/// # Errors
/// The server's refusal (no such room), naming the room.
pub async fn get_room(
    client: &mut crease_proto::v1::crease_client::CreaseClient<tonic::transport::Channel>,
    room: &str,
) -> anyhow::Result<crease_proto::v1::RoomInfo> {
    client
        .get_room(crease_proto::v1::GetRoomRequest {
            room: room.to_owned(),
        })
        .await
        .map(tonic::Response::into_inner)
        .map_err(|s| anyhow::anyhow!("room {room:?}: {}", s.message()))
}

/// `msg` with `authorization: Bearer <token>` metadata (admin and publish tokens).
///
/// # Errors
/// A token that is not a valid header value.
pub fn authorized<T>(msg: T, token: &str) -> anyhow::Result<tonic::Request<T>> {
    let mut req = tonic::Request::new(msg);
    req.metadata_mut().insert(
        "authorization",
        format!("Bearer {token}")
            .parse()
            .context("the token is not a valid header value")?,
    );
    Ok(req)
}

/// Wall clock, microseconds since the Unix epoch (the wire's capture clock).
pub fn unix_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

/// Percentile `p` (0..=100) of sorted values by nearest rank: the smallest value with at least
/// `p`% of the sample at or below it; the default value when empty.
pub fn percentile<T: Copy + Default>(sorted: &[T], p: f64) -> T {
    if sorted.is_empty() {
        return T::default();
    }
    let k = (p / 100.0 * sorted.len() as f64).ceil() as usize;
    sorted[k.clamp(1, sorted.len()) - 1]
}

/// `ITERATIONS,STRENGTH` of a `--refine` option (issue 20's bone-level refinement, e.g.
/// `4,0.01`). `crease eval` also takes a strength of 0 (no prior); a room refuses it.
pub fn parse_refinement(text: &str) -> Result<Refinement, String> {
    let (it, strength) = text
        .split_once(',')
        .ok_or_else(|| format!("{text:?}: expected ITERATIONS,STRENGTH (e.g. 4,0.01)"))?;
    let iterations: usize = it
        .trim()
        .parse()
        .map_err(|e| format!("iterations {it:?}: {e}"))?;
    let strength: f32 = strength
        .trim()
        .parse()
        .map_err(|e| format!("strength {strength:?}: {e}"))?;
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(format!("strength {strength}: expected a number >= 0"));
    }
    Ok(Refinement {
        iterations,
        strength,
        from_rest: false,
    })
}

/// How `crease room open|info` print a room's refinement.
pub fn print_refinement(refine: Option<&crease_proto::v1::Refine>) -> String {
    refine.map_or_else(
        || "off".to_owned(),
        |r| format!("{} iterations at strength {}", r.iterations, r.strength),
    )
}

/// A `--skinning` option on the wire: `SKINNING_UNSPECIFIED` (the model's default) when absent.
pub fn skinning_wire(skinning: Option<crease_core::runtime::skin::Skinning>) -> i32 {
    skinning.map_or(0, |s| crease_proto::v1::Skinning::from(s) as i32)
}

/// How `crease room open|info` and `crease models` print a wire skinning: `lbs`, `dqs`.
pub fn print_skinning(skinning: i32) -> String {
    use crease_proto::v1::Skinning;
    match Skinning::try_from(skinning) {
        Ok(Skinning::Lbs) => "lbs".to_owned(),
        Ok(Skinning::Dqs) => "dqs".to_owned(),
        Ok(Skinning::Unspecified) => "the model's default".to_owned(),
        Err(_) => format!("unknown ({skinning})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<u32> = (1..=100).collect();
        assert_eq!(percentile(&v, 50.0), 50);
        assert_eq!(percentile(&v, 99.0), 99);
        assert_eq!(percentile(&v, 100.0), 100);
        assert_eq!(percentile(&v, 0.0), 1);
        assert_eq!(percentile(&[7i64], 99.0), 7);
        assert_eq!(percentile::<u64>(&[], 50.0), 0);
        // Four values: the median is the second (half of them at or below it).
        assert_eq!(percentile(&[1, 2, 3, 4], 50.0), 2);
    }
}
