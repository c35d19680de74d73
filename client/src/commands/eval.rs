//! `crease eval`: leave-one-out and held-out test errors of every method, with the oracle rows
//! that show each layer's floor (HZY11 Table 2 protocol); with detailed examples, the detail
//! layer's errors beside the base's, and the static- and cascaded-detail rows (HZY11 Figs. 5,
//! 8).

use std::path::PathBuf;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_core::predictor::Refinement;
use crease_train::eval::{self, DetailEval, EvalOptions, EvalTable, HeldOut};
use crease_train::pipeline::TrainInput;
use crease_train::regress::Method;

use super::common::Progress;
use super::layers;
use super::training_args::{RegressArgs, kernel_name, parse_method};

/// Options of `crease eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct EvalArgs {
    /// Training examples: a folder of meshes or a TOML manifest.
    #[arg(long, value_name = "DIR|MANIFEST", required_unless_present = "hands")]
    pub examples: Option<PathBuf>,
    /// A generated-hand protocol instead of --examples and --test (issue 20), at the base
    /// resolution: `extrapolation` trains on the named poses only (`flat` and the 9 named
    /// ones) and tests on sampled poses no example is near; `in-span` trains on those and 4
    /// sampled poses (`crease handgen`'s default 14) and tests on the same sampled poses.
    #[arg(long, value_name = "PROTOCOL", value_parser = ["extrapolation", "in-span"], conflicts_with_all = ["examples", "test"])]
    pub hands: Option<String>,
    /// The control-point layout of --hands: `back` (15 dorsal points, like HZY11's mocap
    /// markers), `palm` (17) or `glove13` (the glove recording's 13).
    #[arg(long, default_value = "back", value_parser = ["back", "palm", "glove13"], requires = "hands")]
    pub hand_layout: String,
    /// Sampled test poses of --hands.
    #[arg(long, default_value_t = 40, requires = "hands")]
    pub hand_test: usize,
    /// Seed of --hands' pose sampler (`crease handgen --seed`).
    #[arg(long, default_value_t = 1, requires = "hands")]
    pub hand_seed: u64,
    /// Leave-one-out over the training examples (rest pose excluded); refits the bones per fold.
    #[arg(long)]
    pub loo: bool,
    /// Held-out test examples (same topology, never trained on): every mesh of this set,
    /// its rest pose included, is evaluated.
    #[arg(long, value_name = "DIR|MANIFEST")]
    pub test: Option<PathBuf>,
    /// Methods to compare (comma-separated); default all.
    #[arg(long, value_delimiter = ',', value_parser = parse_method)]
    pub methods: Vec<Method>,
    /// Shared regression options.
    #[command(flatten)]
    pub regress: RegressArgs,
    /// Detail layer options (used when the examples are detailed).
    #[command(flatten)]
    pub detail: layers::DetailArgs,
    /// Issue 20's bone-level refinement after the regression, `ITERATIONS,STRENGTH` (e.g.
    /// `4,0.1`): adds a `METHOD+refine` row per method and a `refine-from-rest` row (the
    /// control points alone, no regression prior).
    #[arg(long, value_name = "ITERATIONS,STRENGTH", value_parser = super::common::parse_refinement)]
    pub refine: Option<Refinement>,
    /// Print `{"loo": {METHOD: {...}}, "test": {METHOD: {...}}}` on stdout.
    #[arg(long)]
    pub json: bool,
    /// Also write the table to this file (`.csv` or `.json`).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Write an HTML report into this folder (`DIR/index.html`, pictures beside it): the
    /// results tables, error heat maps of the 3 worst poses of the best method (front and
    /// side), per-bone rotation errors, the selection grid with --select, the control points
    /// and the stage timings. Its numbers are the --json output's.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
}

/// Runs `crease eval`.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    if !args.loo && args.test.is_none() && args.hands.is_none() {
        bail!("nothing to evaluate: give --loo, --test TEST, or both");
    }
    let (layers, hand_test) = match (&args.hands, &args.examples) {
        (Some(protocol), _) => {
            let (train, test) = hand_sets(args, protocol)?;
            let layers = |base| layers::Layers {
                base,
                detailed: None,
                subset: None,
                train_detail: false,
            };
            (layers(train), Some(layers(test)))
        }
        (None, Some(examples)) => (layers::load(examples, &args.detail, None)?, None),
        (None, None) => bail!("give --examples DIR|MANIFEST or --hands PROTOCOL"),
    };
    let set = &layers.base;
    let detail_options = layers::detail_options(&args.detail, &layers)?;
    let train_detail = layers.detail_frames();
    let methods = if args.methods.is_empty() {
        Method::ALL.to_vec()
    } else {
        args.methods.clone()
    };
    let mut train = args.regress.train_options(Method::Global, &layers)?;
    train.group_bones = args
        .regress
        .group_bones(methods.iter().any(|m| m.geometry_local()))?;
    let options = EvalOptions {
        train,
        methods,
        beta: args.regress.beta,
        refine: args.refine,
    };
    let frames: Vec<&[Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let progress = Progress::new(options.train.fit.max_iterations as u64);
    let mut timings: Vec<(String, f64)> = Vec::new();
    let source = match (&args.hands, &args.examples) {
        (Some(protocol), _) => format!("generated hand, {protocol}, layout {}", args.hand_layout),
        (_, Some(path)) => path.display().to_string(),
        _ => String::new(),
    };

    let mut results = serde_json::Map::new();
    let mut tables: Vec<(&str, EvalTable)> = Vec::new();
    let test_set = match (&args.test, hand_test) {
        (Some(path), _) => Some((
            path.clone(),
            layers::load(path, &args.detail, layers.subset.as_ref())?,
        )),
        (None, Some(hands)) => Some((PathBuf::from("generated-hand/test"), hands)),
        (None, None) => None,
    };
    if let Some((test_path, test_layers)) = &test_set {
        let test = &test_layers.base;
        if layers.detailed.is_some() != test_layers.detailed.is_some() {
            bail!(
                "{}: the training examples {} detailed versions and the test examples {}",
                test_path.display(),
                if layers.detailed.is_some() {
                    "have"
                } else {
                    "have no"
                },
                if test_layers.detailed.is_some() {
                    "do"
                } else {
                    "do not"
                }
            );
        }
        let test_detail = test_layers.detail_frames();
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
        let detail = train_detail.as_ref().map(|t| DetailEval {
            train: layers::frames(t),
            test: test_detail.as_ref().map(layers::frames),
            options: &detail_options,
        });
        if let Some(d) = &detail {
            eprintln!(
                "detail layer: {} Loop levels; resampling {} training and {} test detailed examples",
                d.options.levels,
                frames.len(),
                tf.len()
            );
        }
        let t = std::time::Instant::now();
        let table = eval::evaluate_test_layers(
            input,
            HeldOut {
                names: &tn,
                frames: &tf,
            },
            detail,
            &options,
            &mut |s| progress.step(s),
        )
        .context("test evaluation")?;
        timings.push(("test evaluation".into(), t.elapsed().as_secs_f64()));
        tables.push(("test", table));
    }
    if args.loo {
        let detail = train_detail.as_ref().map(|t| DetailEval {
            train: layers::frames(t),
            test: None,
            options: &detail_options,
        });
        if let Some(d) = &detail {
            eprintln!(
                "detail layer: {} Loop levels; resampling {} training detailed examples",
                d.options.levels,
                frames.len()
            );
        }
        let t = std::time::Instant::now();
        let table = eval::evaluate_loo_layers(input, detail, &options, &mut |i, n| {
            progress.count(
                "loo",
                i as u64 - 1,
                n as u64,
                &format!("leave-one-out fold {i}/{n}"),
            )
        })
        .context("leave-one-out evaluation")?;
        timings.push(("leave-one-out".into(), t.elapsed().as_secs_f64()));
        tables.push(("loo", table));
    }
    progress.finish();

    let mut csv = String::from(
        "protocol,method,rms_mean,rms_max,us_per_frame,frames,base_rms_mean,detail_rms_mean,crease_rms_mean,crease_h_rms_mean\n",
    );
    for (protocol, table) in &tables {
        println_table(protocol, table, args.json);
        let mut obj = serde_json::Map::new();
        for row in eval::rows(table) {
            if let Some(s) = table.get(row) {
                obj.insert(row.to_string(), serde_json::to_value(s)?);
                let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6e}"));
                csv.push_str(&format!(
                    "{protocol},{row},{:.6e},{:.6e},{:.1},{},{},{},{},{}\n",
                    s.rms_mean,
                    s.rms_max,
                    s.us_per_frame,
                    s.frames.len(),
                    opt(s.base_rms_mean),
                    opt(s.detail_rms_mean),
                    opt(s.crease_rms_mean),
                    opt(s.crease_h_rms_mean)
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
    if let Some(dir) = &args.report {
        let progress = Progress::new(0);
        let test = test_set
            .as_ref()
            .map(|(_, t)| (t.base.frames(), t.base.names()));
        let page = super::report::write_eval(
            dir,
            &super::report::EvalReport {
                source,
                train: input,
                test: test
                    .as_ref()
                    .map(|(frames, names)| HeldOut { names, frames }),
                options: &options,
                tables: &tables,
                json: &json,
                timings: &timings,
            },
            &progress,
        )?;
        progress.finish();
        eprintln!("wrote {}", page.display());
    }
    Ok(())
}

/// The training and test sets of `--hands PROTOCOL` (module docs of `crease_hand::dataset`).
fn hand_sets(
    args: &EvalArgs,
    protocol: &str,
) -> anyhow::Result<(
    crease_core::mesh::examples::ExampleSet,
    crease_core::mesh::examples::ExampleSet,
)> {
    use crease_hand::dataset::{Layout, example_sets};
    use crease_hand::skeleton::NamedPose;
    // `flat` (the rest pose) and the named poses; in-span adds crease handgen's 4 sampled.
    let named = NamedPose::ALL.len();
    let train = if protocol == "in-span" {
        named + 4
    } else {
        named
    };
    let layout = Layout::from_name(&args.hand_layout)
        .with_context(|| format!("--hand-layout {}: unknown layout", args.hand_layout))?;
    let start = std::time::Instant::now();
    let (train_set, test_set) = example_sets(train, args.hand_test, args.hand_seed, layout)
        .context("generating the hand examples")?;
    eprintln!(
        "generated hand, {protocol}: {} training poses ({}), {} sampled test poses, {} control points ({}), {} vertices, {:.1} s",
        train_set.examples.len(),
        train_set
            .examples
            .iter()
            .map(|e| e.name.trim_start_matches("train/").trim_end_matches(".ply"))
            .collect::<Vec<_>>()
            .join(", "),
        test_set.examples.len(),
        train_set.control_points.as_ref().map_or(0, Vec::len),
        layout.name(),
        train_set.rest.vertex_count(),
        start.elapsed().as_secs_f64()
    );
    Ok((train_set, test_set))
}

/// The human table (to stderr when stdout carries JSON).
fn println_table(protocol: &str, table: &EvalTable, to_stderr: bool) {
    let mut text = format!("{protocol}: RMS vertex error, rest bbox largest side = 1\n");
    let detailed = table.values().any(|s| s.detail_rms_mean.is_some());
    text.push_str(&format!(
        "  {:<22} {:>10} {:>10} {:>10} {:>7}",
        "method", "rms_mean", "rms_max", "us/frame", "frames"
    ));
    if detailed {
        text.push_str(&format!(
            " {:>11} {:>11} {:>11}",
            "detail_rms", "crease_rms", "crease_h"
        ));
    }
    text.push('\n');
    for row in eval::rows(table) {
        if let Some(s) = table.get(row) {
            text.push_str(&format!(
                "  {:<22} {:>10.4e} {:>10.4e} {:>10.1} {:>7}",
                row,
                s.rms_mean,
                s.rms_max,
                s.us_per_frame,
                s.frames.len()
            ));
            if let (Some(d), Some(c), Some(h)) =
                (s.detail_rms_mean, s.crease_rms_mean, s.crease_h_rms_mean)
            {
                text.push_str(&format!(" {d:>11.4e} {c:>11.4e} {h:>11.4e}"));
            }
            text.push('\n');
        }
    }
    if detailed {
        text.push_str(&format!(
            "  detail_rms: the detailed output against the detailed truth; crease_rms: the same on the {}% of detailed vertices whose displacement varies most over the training poses; crease_h: the displacements' own error there; true-base rows: the true base mesh with detail\n",
            eval::CREASE_FRACTION * 100.0
        ));
    }
    for row in eval::rows(table) {
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
