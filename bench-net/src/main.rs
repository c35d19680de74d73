//! `crease-bench`: the network load benchmark and the soak (`crease bench-net` is the same).

use clap::Parser;

/// crease-bench: network load benchmark (issue 6) and soak (issue 21) of a crease server.
#[derive(Debug, Parser)]
#[command(name = "crease-bench", version, about, long_about = None)]
struct Cli {
    /// The benchmark's options.
    #[command(flatten)]
    args: crease_bench::BenchNetArgs,
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    match crease_bench::run(&cli.args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
