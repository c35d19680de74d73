//! `crease train`: bones, control points, rotation regressors and the edge skin in one model
//! file (FKY08 §3–5, HZY11 §5.1), and the detail layer when the examples are detailed
//! (HZY11 §4, §5.2).

use std::path::PathBuf;

use anyhow::Context;
use crease_train::pipeline::{self, TrainInput};
use crease_train::regress::Method;

use super::common::Progress;
use super::layers;
use super::training_args::{RegressArgs, kernel_name, parse_method};

/// Options of `crease train`.
#[derive(Clone, Debug, clap::Args)]
pub struct TrainArgs {
    /// Example set: a folder of meshes or a TOML manifest (see `crease fit --help`).
    #[arg(long, value_name = "DIR|MANIFEST")]
    pub examples: PathBuf,
    /// Predictor: global (FKY08), local-geometry, local-pose, local (HZY11), rbf.
    #[arg(long, default_value = "global", value_parser = parse_method)]
    pub method: Method,
    /// Shared regression options.
    #[command(flatten)]
    pub regress: RegressArgs,
    /// Detail layer options.
    #[command(flatten)]
    pub detail: layers::DetailArgs,
    /// Where to write the model (atomically).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also write the trained model's rig (rest mesh, bones, weights, one keyframe per
    /// example) as a skinned glTF binary, as `crease fit --export-gltf` does for a fitted rig:
    /// the same rig the model predicts with, not a new fit.
    #[arg(long, value_name = "FILE.glb")]
    pub export_gltf: Option<PathBuf>,
    /// The model's default skinning, `lbs` or `dqs` (issue 22; stored in the model file):
    /// what rooms on it and `crease synth` use unless they choose. The bones are fitted for
    /// LBS either way; DQS (Kavan et al. 2007) keeps the volume at twisting joints. A DQS room
    /// refuses palette subscriptions (their clients skin with LBS).
    #[arg(long, value_name = "lbs|dqs", default_value_t)]
    pub skinning: crease_core::runtime::skin::Skinning,
    /// Measure the control points inside the training set (issue 42): the leave-one-out error
    /// with this many automatic control points each (the control-point curve, in the output,
    /// `--json` and the report), and the bones the model's own points leave undetermined
    /// (moved by the examples, not predicted from the points; a warning names where).
    /// `none` skips both.
    #[arg(long, value_name = "N,N,...|none", default_value = "4,8,12,16", value_parser = parse_curve)]
    pub control_curve: CurveCounts,
    /// Print one JSON object with the training report on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write an HTML report into this folder (`DIR/index.html`, pictures beside it): the
    /// training report's numbers (those of --json), the model's error on its training poses
    /// with heat maps of the 3 worst (front and side), per-bone rotation errors, the bone fit's
    /// convergence, the selection grid with --select, the control points and the stage
    /// timings.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
}

/// Runs `crease train`.
pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let layers = layers::load(&args.examples, &args.detail, None)?;
    let set = &layers.base;
    let mut options = args.regress.train_options(args.method, &layers)?;
    options.detail = layers::detail_options(&args.detail, &layers)?;
    if let Some(counts) = &args.control_curve.0 {
        options.coverage = true;
        options.control_curve.clone_from(counts);
    }
    let frames: Vec<&[crease_core::glam::Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let progress = Progress::new(options.fit.max_iterations as u64);
    let detail_parts = layers.detail_frames();
    let input = TrainInput {
        rest: &set.rest,
        frames: &frames,
        names: &names,
    };
    let (mut model, report) = pipeline::train_layers_with(
        input,
        detail_parts.as_ref().map(layers::frames),
        &options,
        pipeline::TrainProgress {
            fit: &mut |s| progress.step(s),
            detail: &mut |done, total| {
                progress.line(
                    "detail",
                    None,
                    &format!("resampled {done}/{total}"),
                    &format!("detail layer: resampled detailed example {done}/{total}"),
                )
            },
            select: &|done, folds| {
                progress.count(
                    "select",
                    done as u64,
                    folds as u64,
                    &format!("model selection: leave-one-out fold {done}/{folds} scored"),
                )
            },
        },
    )
    .context("training")?;
    progress.finish();
    for w in &report.fit.warnings {
        eprintln!("warning: {w}");
    }
    model.skinning = args.skinning;
    model.save(&args.out).context("writing the model")?;
    eprintln!(
        "wrote {}: {} bones, {} control points (vertices {:?}), method {}, skinning {}",
        args.out.display(),
        model.rig.bone_count,
        model.controls.len(),
        model.controls.iter().map(|c| c.vertex).collect::<Vec<_>>(),
        model.method,
        model.skinning
    );
    if let Some(glb) = &args.export_gltf {
        crease_core::model::export_rig_glb(&model.rig, glb)
            .with_context(|| format!("writing glTF {}", glb.display()))?;
        eprintln!("wrote {}", glb.display());
    }
    if let Some(c) = &report.control_selection {
        eprintln!(
            "control points by leave-one-out: {:?} (swaps {:?}; LOO {:.4e} -> {:.4e}; {:.1} s)",
            c.chosen,
            c.swaps,
            c.errors.first().copied().unwrap_or(f64::NAN),
            c.errors.last().copied().unwrap_or(f64::NAN),
            c.seconds
        );
    }
    if let Some(s) = &report.selection {
        eprintln!(
            "selected by leave-one-out: {} kappa {:e} beta {} (LOO {:.4e}; {:.1} s)",
            kernel_name(&s.best.kernel),
            s.best.kappa,
            s.best.beta,
            s.best.rms,
            s.seconds
        );
    }
    if let Some(c) = &report.coverage {
        print_coverage(c, &model);
    }
    if let Some(d) = &report.detail {
        eprintln!(
            "detail layer: {} levels, {} vertices; rays {} hits, {} closest-point fallbacks (max |h| {:.3e}); resampling {:.1} s, regression {:.1} s",
            d.levels,
            d.vertices,
            d.hits,
            d.fallbacks,
            d.max_abs_h,
            d.extract_seconds,
            d.fit_seconds
        );
    }
    if let Some(dir) = &args.report {
        let json = serde_json::to_value(&report)?;
        let progress = Progress::new(0);
        let page = super::report::write_train(
            dir,
            &super::report::TrainReportInput {
                source: args.examples.display().to_string(),
                train: input,
                model: &model,
                report: &report,
                json: &json,
            },
            &progress,
        )?;
        progress.finish();
        eprintln!("wrote {}", page.display());
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "trained in {:.2} s (bones {:.2} s, rms {:.4e}{}; controls {:.2} s; regressors {:.2} s; edge skin {:.2} s{})",
            report.seconds,
            report.fit.seconds,
            report.fit.rms_normalized,
            report.group_rig.as_ref().map_or(String::new(), |g| format!(
                "; grouping rig of {} bones {:.2} s, rms {:.4e}",
                g.bones, g.seconds, g.fit_rms
            )),
            report.controls_seconds,
            report.regress_seconds,
            report.edges_seconds,
            report
                .edge_vectors
                .as_ref()
                .map_or(String::new(), |v| format!(", vector ridge {:e}", v.ridge))
        );
    }
    Ok(())
}

/// `--control-curve`'s counts; `None` for `none`.
#[derive(Clone, Debug)]
pub struct CurveCounts(pub Option<Vec<usize>>);

fn parse_curve(text: &str) -> Result<CurveCounts, String> {
    if text.trim() == "none" {
        return Ok(CurveCounts(None));
    }
    let mut counts = Vec::new();
    for field in text.split(',') {
        let n: usize = field
            .trim()
            .parse()
            .map_err(|_| format!("`{field}` is not a count of control points (N,N,... or none)"))?;
        if n == 0 {
            return Err("a count of control points must be at least 1".into());
        }
        counts.push(n);
    }
    counts.sort_unstable();
    counts.dedup();
    Ok(CurveCounts(Some(counts)))
}

/// The control-point curve and the undetermined regions, on stderr (warnings for the regions).
fn print_coverage(
    c: &crease_train::selection::ControlCoverage,
    model: &crease_core::model::TrainedModel,
) {
    if !c.curve.is_empty() {
        let points: Vec<String> = c
            .curve
            .iter()
            .map(|p| format!("{}: {:.4e}", p.count, p.rms))
            .collect();
        eprintln!(
            "control-point curve (leave-one-out inside the training set, automatic points; this model has {}): {}{}",
            model.controls.len(),
            points.join(", "),
            c.curve_stopped
                .as_ref()
                .map_or(String::new(), |why| format!(" (stopped: {why})"))
        );
    }
    for r in &c.bones.regions {
        eprintln!(
            "warning: the control points leave {} bone(s) undetermined around ({:.3}, {:.3}, {:.3}) \
             ({} vertices): the examples turn them by {:.1} deg on average, and leave-one-out \
             predicts them {:.1} deg off; a control point there would constrain them (bones {:?})",
            r.bones.len(),
            r.centroid[0],
            r.centroid[1],
            r.centroid[2],
            r.vertices.len(),
            r.spread_deg,
            r.error_deg,
            r.bones
        );
    }
}
