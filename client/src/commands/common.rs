//! Pieces shared by the subcommands: loading example sets, parsing control-point specs,
//! progress display, the server flags, and (from `crease_remote`) connecting to a server, the
//! requests' small pieces (rooms, tokens, clocks) and percentiles.

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

pub use crease_remote::{MAX_RESPONSE_BYTES, authorized, connect, get_room, percentile, unix_us};

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

/// `ITERATIONS,STRENGTH` of a `--refine` option (issue 20's bone-level refinement, e.g.
/// `4,0.01`). `crease eval` also takes a strength of 0 (no prior); a room refuses it.
pub fn parse_refinement(text: &str) -> Result<Refinement, String> {
    let refine = crease_proto::room::parse_iterations_strength(text)?;
    if !(refine.strength.is_finite() && refine.strength >= 0.0) {
        return Err(format!(
            "strength {}: expected a number >= 0",
            refine.strength
        ));
    }
    Ok(refine)
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
