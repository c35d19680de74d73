//! `crease eval`: leave-one-out and held-out test errors of every method, with the oracle rows
//! that show each layer's floor (HZY11 Table 2 protocol).

use std::path::PathBuf;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_train::eval::{self, EvalOptions, EvalTable, HeldOut, ROWS};
use crease_train::pipeline::TrainInput;
use crease_train::regress::{KernelChoice, Method};

use super::common::{self, Progress};
use super::train::RegressArgs;

/// Options of `crease eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// Training examples: a folder of meshes or a TOML manifest.
    #[arg(long, value_name = "DIR|MANIFEST")]
    pub examples: PathBuf,
    /// Leave-one-out over the training examples (rest pose excluded); refits the bones per fold.
    #[arg(long)]
    pub loo: bool,
    /// Held-out test examples (same topology, never trained on): every mesh of this set,
    /// its rest pose included, is evaluated.
    #[arg(long, value_name = "DIR|MANIFEST")]
    pub test: Option<PathBuf>,
    /// Methods to compare (comma-separated); default all.
    #[arg(long, value_delimiter = ',', value_parser = super::train::parse_method)]
    pub methods: Vec<Method>,
    /// Shared regression options.
    #[command(flatten)]
    pub regress: RegressArgs,
    /// Print `{"loo": {METHOD: {...}}, "test": {METHOD: {...}}}` on stdout.
    #[arg(long)]
    pub json: bool,
    /// Also write the table to this file (`.csv` or `.json`).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// Runs `crease eval`.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    if !args.loo && args.test.is_none() {
        bail!("nothing to evaluate: give --loo, --test TEST, or both");
    }
    let set = common::load_examples(&args.examples)?;
    let methods = if args.methods.is_empty() {
        Method::ALL.to_vec()
    } else {
        args.methods.clone()
    };
    let options = EvalOptions {
        train: args.regress.train_options(Method::Global, &set)?,
        methods,
        beta: args.regress.beta,
    };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let progress = Progress::new(options.train.fit.max_iterations as u64);

    let mut results = serde_json::Map::new();
    let mut tables: Vec<(&str, EvalTable)> = Vec::new();
    if let Some(test_path) = &args.test {
        let test = common::load_examples(test_path)?;
        if test.rest.vertex_count() != set.rest.vertex_count()
            || test.rest.triangles != set.rest.triangles
        {
            bail!(
                "{}: the test meshes do not share the training topology ({} vertices / {} triangles vs {} / {})",
                test_path.display(),
                test.rest.vertex_count(),
                test.rest.triangles.len(),
                set.rest.vertex_count(),
                set.rest.triangles.len()
            );
        }
        let tf: Vec<&[Vec3]> = test.frames();
        let tn: Vec<String> = test.names();
        let table = eval::evaluate_test(
            input,
            HeldOut {
                names: &tn,
                frames: &tf,
            },
            &options,
            &mut |s| progress.step(s),
        )
        .context("test evaluation")?;
        tables.push(("test", table));
    }
    if args.loo {
        let table = eval::evaluate_loo(input, &options, &mut |i, n| {
            progress.line(
                "loo",
                None,
                &format!("fold {i}/{n}"),
                &format!("leave-one-out fold {i}/{n}"),
            )
        })
        .context("leave-one-out evaluation")?;
        tables.push(("loo", table));
    }
    progress.finish();

    let mut csv = String::from("protocol,method,rms_mean,rms_max,us_per_frame,frames\n");
    for (protocol, table) in &tables {
        println_table(protocol, table, args.json);
        let mut obj = serde_json::Map::new();
        for row in ROWS {
            if let Some(s) = table.get(row) {
                obj.insert(row.to_string(), serde_json::to_value(s)?);
                csv.push_str(&format!(
                    "{protocol},{row},{:.6e},{:.6e},{:.1},{}\n",
                    s.rms_mean,
                    s.rms_max,
                    s.us_per_frame,
                    s.frames.len()
                ));
            }
        }
        results.insert(protocol.to_string(), serde_json::Value::Object(obj));
    }
    let json = serde_json::Value::Object(results);
    if args.json {
        println!("{json}");
    }
    if let Some(out) = &args.out {
        let text = if out
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        {
            serde_json::to_string_pretty(&json)?
        } else {
            csv
        };
        std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}

/// The human table (to stderr when stdout carries JSON).
fn println_table(protocol: &str, table: &EvalTable, to_stderr: bool) {
    let mut text = format!("{protocol}: RMS vertex error, rest bbox largest side = 1\n");
    text.push_str(&format!(
        "  {:<18} {:>10} {:>10} {:>10} {:>7}\n",
        "method", "rms_mean", "rms_max", "us/frame", "frames"
    ));
    for row in ROWS {
        if let Some(s) = table.get(row) {
            text.push_str(&format!(
                "  {:<18} {:>10.4e} {:>10.4e} {:>10.1} {:>7}\n",
                row,
                s.rms_mean,
                s.rms_max,
                s.us_per_frame,
                s.frames.len()
            ));
        }
    }
    for row in ROWS {
        if let Some(s) = table.get(row).filter(|s| !s.selected.is_empty()) {
            let picks: Vec<String> = s
                .selected
                .iter()
                .map(|c| {
                    format!(
                        "{} kappa {:e} beta {} (loo {:.4e})",
                        kernel_name(&c.kernel),
                        c.kappa,
                        c.beta,
                        c.rms
                    )
                })
                .collect();
            text.push_str(&format!("  selected for {row}: {}\n", picks.join("; ")));
        }
    }
    if to_stderr {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
}

/// `gaussian*1.4`, `gaussian*1+linear:0.1`, `poly:2`: how a selected kernel is printed.
pub fn kernel_name(k: &KernelChoice) -> String {
    match k {
        KernelChoice::Gaussian { scale } => format!("gaussian*{scale}"),
        KernelChoice::GaussianLinear { scale, gamma } => format!("gaussian*{scale}+linear:{gamma}"),
        KernelChoice::Polynomial { degree, .. } => format!("poly:{degree}"),
    }
}
