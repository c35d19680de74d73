//! `crease eval --report DIR` and `crease train --report DIR`: an HTML page (`DIR/index.html`)
//! with the results table, error heat maps of the worst poses, per-bone rotation errors, the
//! model-selection grid, the control-point layout and the stage timings, its pictures beside
//! it.
//!
//! Layout:
//! - `html`: the page, and the tables written from the same JSON value `--json` prints;
//! - `plots`: SVG plots through `plotters`;
//! - `renders`: PNG pictures of meshes through the project's rasteriser
//!   (`crease_hand::render`): heat maps from per-vertex error, the control points;
//! - `poses`: the predictions the pictures show, recomputed for the poses drawn (the evaluation
//!   keeps per-frame errors only).

mod html;
mod plots;
mod poses;
mod renders;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use crease_core::glam::{Quat, Vec3};
use crease_core::model::TrainedModel;
use crease_core::predictor::Predictor;
use crease_train::eval::{self, EvalOptions, EvalTable, HeldOut, LooFold};
use crease_train::pipeline::{TrainInput, TrainReport};
use crease_train::regress::{Method, RegressOptions};
use crease_train::select;
use crease_train::selection::Candidate;

use super::common::Progress;
use super::training_args::kernel_name;
use poses::Pose;

/// How many of the worst poses get a heat map.
const WORST: usize = 3;

/// What an evaluation report is written from.
#[derive(Debug)]
pub struct EvalReport<'a> {
    /// What was evaluated (the examples' path, or the generated hand's protocol).
    pub source: String,
    /// The training examples.
    pub train: TrainInput<'a>,
    /// The held-out test examples, when evaluated.
    pub test: Option<HeldOut<'a>>,
    /// The evaluation's options.
    pub options: &'a EvalOptions,
    /// `(protocol, table)`: `test` and/or `loo`.
    pub tables: &'a [(&'a str, EvalTable)],
    /// The `--json` output: `{PROTOCOL: {ROW: stats}}`.
    pub json: &'a serde_json::Value,
    /// Stage timings so far, seconds.
    pub timings: &'a [(String, f64)],
}

/// What a training report is written from.
#[derive(Debug)]
pub struct TrainReportInput<'a> {
    /// The examples' path.
    pub source: String,
    /// The training examples.
    pub train: TrainInput<'a>,
    /// The trained model.
    pub model: &'a TrainedModel,
    /// The training report.
    pub report: &'a TrainReport,
    /// The `--json` output (the training report as JSON).
    pub json: &'a serde_json::Value,
}

/// Creates `dir` and returns the path of its `index.html`.
fn prepare(dir: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("--report {}: cannot create the folder", dir.display()))?;
    Ok(dir.join("index.html"))
}

/// The command line, for the page's header.
fn command_line() -> String {
    let args: Vec<String> = std::env::args().collect();
    let mut out = String::from("crease");
    for a in args.iter().skip(1) {
        out.push(' ');
        out.push_str(a);
    }
    out
}

/// The lowest `rms_mean` among the evaluated methods: the row the pictures show.
fn shown_method(table: &EvalTable, methods: &[Method]) -> Option<Method> {
    methods
        .iter()
        .copied()
        .filter(|m| table.contains_key(m.name()))
        .min_by(|a, b| {
            table[a.name()]
                .rms_mean
                .total_cmp(&table[b.name()].rms_mean)
        })
}

/// The control points' `(vertex, name)`: the given names when there is one per point.
fn named_controls(vertices: &[u32], names: Option<&[String]>) -> Vec<(u32, String)> {
    vertices
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let name = names
                .filter(|n| n.len() == vertices.len())
                .map_or_else(|| format!("c{i}"), |n| n[i].clone());
            (v, name)
        })
        .collect()
}

/// Writes the heat maps of `poses` (file names `{stem}-{k}.png`) on one shared colour scale and
/// returns their figures.
fn heat_maps(
    dir: &Path,
    stem: &str,
    triangles: &[[u32; 3]],
    poses: &[Pose],
    what: &str,
    evaluated: &[f64],
) -> anyhow::Result<String> {
    let top = poses::scale_max(poses);
    let mut html = String::new();
    for (k, pose) in poses.iter().enumerate() {
        let file = format!("{stem}-{}.png", k + 1);
        let title = format!("{}  rms {:.3e}", short_name(&pose.name), pose.rms);
        renders::heat_map(
            &dir.join(&file),
            triangles,
            &pose.truth,
            &pose.predicted,
            &pose.vertex_error,
            top,
            &title,
        )?;
        let max = pose.vertex_error.iter().copied().fold(0.0f32, f32::max);
        let agrees = evaluated
            .get(k)
            .is_none_or(|e| (e - pose.rms).abs() <= 1e-9 * e.abs().max(1e-12));
        let note = match evaluated.get(k) {
            Some(e) if !agrees => {
                format!(" (the evaluation measured {e:.4e}; this retraining differs in rounding)")
            }
            _ => String::new(),
        };
        html.push_str(&html::figure(
            &file,
            &format!("error heat map of {}", pose.name),
            &format!(
                "{what} #{}: <b>{}</b>, RMS {:.4e}{note}, largest vertex error {:.3e}. Left: the true shape; middle and right: the prediction, coloured by per-vertex error (colour scale shared by these pictures, top at {:.3e}).",
                k + 1,
                html::escape(&short_name(&pose.name)),
                pose.rms,
                max,
                top
            ),
        ));
    }
    Ok(html)
}

/// The per-bone rotation error plot of `poses` (mean over them, the maximum as dots).
fn bone_plot(path: &Path, title: &str, poses: &[&Pose]) -> anyhow::Result<()> {
    let bones = poses.first().map_or(0, |p| p.bone_error_deg.len());
    let mean: Vec<f64> = (0..bones)
        .map(|b| poses.iter().map(|p| p.bone_error_deg[b]).sum::<f64>() / poses.len() as f64)
        .collect();
    let max: Vec<f64> = (0..bones)
        .map(|b| {
            poses
                .iter()
                .map(|p| p.bone_error_deg[b])
                .fold(0.0, f64::max)
        })
        .collect();
    let labels: Vec<String> = (0..bones).map(|b| b.to_string()).collect();
    plots::bars(
        path,
        title,
        ("bone", "rotation error, degrees"),
        &labels,
        &mean,
        (poses.len() > 1).then_some(max.as_slice()),
    )
}

/// The selection grid of `table` (candidates in grid order) as a heat-map figure.
fn grid_figure(dir: &Path, file: &str, table: &[Candidate], what: &str) -> anyhow::Result<String> {
    let mut kernels: Vec<String> = Vec::new();
    let mut kappas: Vec<f64> = Vec::new();
    let mut betas: Vec<f32> = Vec::new();
    for c in table {
        let k = kernel_name(&c.kernel);
        if !kernels.contains(&k) {
            kernels.push(k);
        }
        if !kappas.contains(&c.kappa) {
            kappas.push(c.kappa);
        }
        if !betas.contains(&c.beta) {
            betas.push(c.beta);
        }
    }
    let mut values = vec![vec![vec![f64::NAN; betas.len()]; kappas.len()]; kernels.len()];
    for c in table {
        let k = kernels.iter().position(|k| *k == kernel_name(&c.kernel));
        let a = kappas.iter().position(|&x| x == c.kappa);
        let b = betas.iter().position(|&x| x == c.beta);
        if let (Some(k), Some(a), Some(b)) = (k, a, b) {
            values[k][a][b] = c.rms;
        }
    }
    let best = table
        .iter()
        .filter(|c| c.rms.is_finite())
        .min_by(|a, b| a.rms.total_cmp(&b.rms));
    plots::selection_grid(
        &dir.join(file),
        "leave-one-out RMS of every candidate",
        &kernels,
        &kappas,
        &betas,
        &values,
    )?;
    Ok(html::figure(
        file,
        "model-selection grid",
        &format!(
            "Model selection ({what}): mean leave-one-out mesh RMS inside the training set for every kernel (rows) x kappa (columns) x beta (panels), {} candidates; log colour scale, the lowest outlined{}.",
            table.len(),
            best.map_or(String::new(), |b| format!(
                ": {} kappa {:e} beta {} ({:.4e})",
                kernel_name(&b.kernel),
                b.kappa,
                b.beta,
                b.rms
            ))
        ),
    ))
}

/// The control-point layout figure.
fn controls_figure(
    dir: &Path,
    rest: &crease_core::mesh::Mesh,
    controls: &[(u32, String)],
) -> anyhow::Result<String> {
    let file = "controls.png";
    renders::control_layout(&dir.join(file), &rest.positions, &rest.triangles, controls)?;
    let list: Vec<String> = controls
        .iter()
        .map(|(v, n)| format!("{n} = vertex {v}"))
        .collect();
    Ok(html::figure(
        file,
        "control points on the rest mesh",
        &format!(
            "The {} control points on the rest mesh, front and side (hollow where the mesh hides them): {}.",
            controls.len(),
            html::escape(&list.join(", "))
        ),
    ))
}

/// The stage timings figure.
fn timings_figure(dir: &Path, items: &[(String, f64)], what: &str) -> anyhow::Result<String> {
    let file = "timings.svg";
    plots::hbars(&dir.join(file), "stage timings", "seconds", items, &|s| {
        format!("{s:.2} s")
    })?;
    let list: Vec<String> = items.iter().map(|(k, s)| format!("{k} {s:.2} s")).collect();
    Ok(html::figure(
        file,
        "stage timings",
        &format!("{what}: {}.", html::escape(&list.join("; "))),
    ))
}

/// Writes the evaluation report into `dir` and returns the page's path.
pub fn write_eval(dir: &Path, r: &EvalReport<'_>, progress: &Progress) -> anyhow::Result<PathBuf> {
    let start = Instant::now();
    let index = prepare(dir)?;
    let rest = r.train.rest;
    let options = r.options;
    let mut sections = vec![html::section(
        "run",
        "Run",
        &html::facts(&[
            ("command".into(), command_line()),
            ("examples".into(), r.source.clone()),
            (
                "training poses".into(),
                format!("{} (rest pose first)", r.train.frames.len()),
            ),
            (
                "test poses".into(),
                r.test.map_or("none".into(), |t| t.frames.len().to_string()),
            ),
            (
                "mesh".into(),
                format!(
                    "{} vertices, {} triangles",
                    rest.vertex_count(),
                    rest.triangles.len()
                ),
            ),
            (
                "methods".into(),
                options
                    .methods
                    .iter()
                    .map(|m| m.name())
                    .collect::<Vec<_>>()
                    .join(", "),
            ),
            ("bones asked".into(), options.train.fit.bones.to_string()),
            (
                "errors".into(),
                "RMS vertex distance, the rest mesh's largest bounding-box side = 1".into(),
            ),
        ]),
    )];
    // The first trained model's base and a pose set, for the control layout and the grid.
    let mut first: Option<(crease_train::base::TrainedBase, Vec<&[Vec3]>, Method)> = None;
    let mut report_timings: Vec<(String, f64)> = Vec::new();
    for (protocol, table) in r.tables {
        let Some(method) = shown_method(table, &options.methods) else {
            continue;
        };
        let stats = &table[method.name()];
        let rows = eval::rows(table);
        let mut body = html::eval_table(protocol, &r.json[*protocol], &rows, method.name());
        let (what, names): (&str, Vec<String>) = match *protocol {
            "test" => (
                "held-out test pose",
                r.test.map_or_else(Vec::new, |t| t.names.to_vec()),
            ),
            _ => ("leave-one-out fold", r.train.names[1..].to_vec()),
        };
        // Per-frame errors of the oracle rows and every method.
        let mut series = Vec::new();
        for row in rows.iter().filter(|row| {
            ["oracle", "oracle-rotations"].contains(row)
                || options.methods.iter().any(|m| m.name() == **row)
        }) {
            let pts = table[*row]
                .frames
                .iter()
                .enumerate()
                .map(|(i, &e)| (i as f64, e))
                .collect();
            series.push((row.to_string(), pts));
        }
        let file = format!("{protocol}-frames.svg");
        plots::lines(
            &dir.join(&file),
            &format!("{protocol}: RMS error per pose"),
            ("pose (index below)", "RMS error"),
            &series,
            true,
        )?;
        body.push_str(&html::figure(
            &file,
            "per-pose error",
            &format!(
                "RMS error of every {what} by row (log scale). Pose indices: {}.",
                html::escape(
                    &names
                        .iter()
                        .enumerate()
                        .map(|(i, n)| format!("{i} {}", short_name(n)))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            ),
        ));

        let worst = poses::worst(&stats.frames, WORST);
        let t = Instant::now();
        progress.line(
            "report",
            None,
            protocol,
            &format!(
                "report: {protocol}: predicting the {} worst poses of {}",
                worst.len(),
                method.name()
            ),
        );
        let had_first = first.is_some();
        let (shown, bones_title, bones_caption): (Vec<Pose>, String, String) = match *protocol {
            "test" => {
                let test = r.test.context("a test table without test frames")?;
                let fitted = poses::fit(r.train, options, method, stats.selected.first())?;
                let controls = fitted.base.control_vertices.clone();
                let mut all = Vec::with_capacity(test.frames.len());
                for (name, frame) in test.names.iter().zip(test.frames) {
                    let oracle = poses::oracle_rotations(&fitted.base, frame);
                    all.push(poses::predict(
                        &fitted.predictor,
                        &controls,
                        name,
                        frame,
                        &oracle,
                    )?);
                }
                let file = format!("{protocol}-bones.svg");
                let refs: Vec<&Pose> = all.iter().collect();
                bone_plot(
                    &dir.join(&file),
                    &format!("{}: per-bone rotation error, test poses", method.name()),
                    &refs,
                )?;
                let caption = format!(
                    "Per-bone rotation error of <b>{}</b> on the {} test poses: the angle between each predicted bone rotation and the oracle's (the bone transforms fitted to the true pose with the rig's weights), mean as bars, maximum as dots.",
                    method.name(),
                    all.len()
                );
                let mut by_frame: Vec<Option<Pose>> = all.into_iter().map(Some).collect();
                let shown = worst
                    .iter()
                    .filter_map(|&k| by_frame.get_mut(k).and_then(Option::take))
                    .collect();
                if first.is_none() {
                    first = Some((fitted.base, r.train.frames.to_vec(), method));
                }
                (shown, file, caption)
            }
            _ => {
                let mut shown = Vec::new();
                let n = r.train.frames.len();
                for &k in &worst {
                    let held = k + 1;
                    progress.line(
                        "report",
                        None,
                        &format!("fold {held}"),
                        &format!("report: retraining leave-one-out fold {held}/{}", n - 1),
                    );
                    // The fold `crease eval --loo` trained (crease_train::eval's).
                    let fold = LooFold::new(r.train, held);
                    let fitted =
                        poses::fit(fold.input(rest), options, method, stats.selected.get(k))?;
                    let frame = r.train.frames[held];
                    let oracle = poses::oracle_rotations(&fitted.base, frame);
                    let controls = fitted.base.control_vertices.clone();
                    shown.push(poses::predict(
                        &fitted.predictor,
                        &controls,
                        &r.train.names[held],
                        frame,
                        &oracle,
                    )?);
                    if first.is_none() {
                        first = Some((fitted.base, fold.frames.clone(), method));
                    }
                }
                let file = format!("{protocol}-bones.svg");
                let worst_pose: Vec<&Pose> = shown.iter().take(1).collect();
                bone_plot(
                    &dir.join(&file),
                    &format!("{}: per-bone rotation error, worst fold", method.name()),
                    &worst_pose,
                )?;
                let caption = format!(
                    "Per-bone rotation error of <b>{}</b> on the worst leave-one-out fold ({}; each fold fits its own bones, so bones do not correspond across folds): the angle between each predicted bone rotation and the oracle's.",
                    method.name(),
                    html::escape(
                        &worst_pose
                            .first()
                            .map_or(String::new(), |p| short_name(&p.name))
                    )
                );
                (shown, file, caption)
            }
        };
        report_timings.push((
            format!("report: {protocol} poses (retraining)"),
            t.elapsed().as_secs_f64(),
        ));
        if let (false, Some((base, _, _))) = (had_first, &first) {
            let f = &base.report;
            let model = if *protocol == "test" {
                ""
            } else {
                ", 1st fold"
            };
            report_timings.extend([
                (format!("  of which: bone fit{model}"), f.fit.seconds),
                (
                    format!("  of which: control points{model}"),
                    f.controls_seconds,
                ),
                (format!("  of which: edge skin{model}"), f.edges_seconds),
            ]);
        }
        let evaluated: Vec<f64> = worst.iter().map(|&k| stats.frames[k]).collect();
        body.push_str(&format!(
            "<h3>The {} worst {what}s of {}</h3>\n",
            shown.len(),
            html::escape(method.name())
        ));
        body.push_str(&heat_maps(
            dir,
            &format!("{protocol}-worst"),
            &rest.triangles,
            &shown,
            what,
            &evaluated,
        )?);
        body.push_str(&html::figure(
            &bones_title,
            "per-bone rotation error",
            &bones_caption,
        ));
        let title = match *protocol {
            "test" => "Held-out test set",
            _ => "Leave-one-out",
        };
        sections.push(html::section(protocol, title, &body));
    }

    if let Some((base, frames, method)) = &first {
        let mut body = String::new();
        if let Some(grid) = &options.train.select {
            let t = Instant::now();
            progress.line(
                "report",
                None,
                "selection grid",
                "report: scoring the selection grid",
            );
            let regress = RegressOptions {
                method: *method,
                ..options.train.regress.clone()
            };
            let s = select::select(base, frames, &regress, grid)
                .context("scoring the selection grid for the report")?;
            report_timings.push(("report: selection grid".into(), t.elapsed().as_secs_f64()));
            body.push_str(&grid_figure(
                dir,
                "selection.svg",
                &s.table,
                &format!("{}, the report's first model", method.name()),
            )?);
        } else {
            body.push_str("<p>No model selection in this run (give <code>--select</code> to score kernel x kappa x beta).</p>\n");
        }
        sections.push(html::section("selection", "Model selection", &body));
        let controls = named_controls(
            &base.control_vertices,
            options.train.control_names.as_deref(),
        );
        sections.push(html::section(
            "controls",
            "Control points",
            &controls_figure(dir, rest, &controls)?,
        ));
    }
    let mut items: Vec<(String, f64)> = r.timings.to_vec();
    items.extend(report_timings);
    items.push(("report total".into(), start.elapsed().as_secs_f64()));
    sections.push(html::section(
        "timings",
        "Stage timings",
        &timings_figure(dir, &items, "Wall-clock seconds of each stage of this run")?,
    ));
    let page = html::page(&format!("crease eval report: {}", r.source), &sections);
    std::fs::write(&index, page).with_context(|| format!("writing {}", index.display()))?;
    Ok(index)
}

/// Writes the training report into `dir` and returns the page's path.
pub fn write_train(
    dir: &Path,
    r: &TrainReportInput<'_>,
    progress: &Progress,
) -> anyhow::Result<PathBuf> {
    let start = Instant::now();
    let index = prepare(dir)?;
    let model = r.model;
    let rig = &model.rig;
    let rest = r.train.rest;
    let report = r.report;
    let mut sections = vec![html::section(
        "run",
        "Run",
        &html::facts(&[
            ("command".into(), command_line()),
            ("examples".into(), r.source.clone()),
            (
                "training poses".into(),
                format!("{} (rest pose first)", r.train.frames.len()),
            ),
            (
                "mesh".into(),
                format!(
                    "{} vertices, {} triangles",
                    rest.vertex_count(),
                    rest.triangles.len()
                ),
            ),
            ("method".into(), model.method.clone()),
            ("bones".into(), rig.bone_count.to_string()),
            ("beta".into(), model.beta.to_string()),
        ]),
    )];
    sections.push(html::section(
        "results",
        "Training report (the --json output)",
        &html::json_table(r.json),
    ));

    // The model on its own training poses.
    progress.line(
        "report",
        None,
        "poses",
        "report: predicting the training poses",
    );
    let t = Instant::now();
    let predictor = Predictor::new(Arc::new(model.clone()), None).context("the model")?;
    let controls: Vec<u32> = model.controls.iter().map(|c| c.vertex).collect();
    let mut all = Vec::new();
    for (k, frame) in r.train.frames.iter().enumerate().skip(1) {
        let reference: Vec<Quat> = rig
            .examples
            .get(k)
            .map(|e| e.transforms.iter().map(|t| t.rotation).collect())
            .unwrap_or_default();
        all.push(poses::predict(
            &predictor,
            &controls,
            &r.train.names[k],
            frame,
            &reference,
        )?);
    }
    let pose_seconds = t.elapsed().as_secs_f64();
    let mut body = String::new();
    let errors: Vec<f64> = all.iter().map(|p| p.rms).collect();
    let items: Vec<(String, f64)> = all.iter().map(|p| (short_name(&p.name), p.rms)).collect();
    plots::hbars(
        &dir.join("poses.svg"),
        "the model's RMS error on each training pose",
        "RMS error",
        &items,
        &|e| format!("{e:.3e}"),
    )?;
    body.push_str(&html::figure(
        "poses.svg",
        "error per training pose",
        "The trained model predicting each of its own training poses from their control points (a fit error, not a generalisation error: run <code>crease eval --loo</code> or <code>--test</code> for that).",
    ));
    let worst = poses::worst(&errors, WORST);
    let mut by_pose: Vec<Option<Pose>> = Vec::new();
    let refs: Vec<&Pose> = all
        .iter()
        .filter(|p| !p.bone_error_deg.is_empty())
        .collect();
    if !refs.is_empty() {
        bone_plot(
            &dir.join("bones.svg"),
            "per-bone rotation error, training poses",
            &refs,
        )?;
        body.push_str(&html::figure(
            "bones.svg",
            "per-bone rotation error",
            &format!(
                "Per-bone rotation error on the {} training poses: the angle between the regressed rotation and the bone fit's, mean as bars, maximum as dots.",
                refs.len()
            ),
        ));
    }
    by_pose.extend(all.into_iter().map(Some));
    let shown: Vec<Pose> = worst
        .iter()
        .filter_map(|&k| by_pose.get_mut(k).and_then(Option::take))
        .collect();
    body.push_str(&format!(
        "<h3>The {} worst training poses</h3>\n",
        shown.len()
    ));
    body.push_str(&heat_maps(
        dir,
        "train-worst",
        &rest.triangles,
        &shown,
        "training pose",
        &[],
    )?);
    sections.push(html::section("poses", "Training poses", &body));

    let history = &report.fit.history;
    let mut phases: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for (step, h) in history.iter().enumerate() {
        match phases.iter_mut().find(|p| p.0 == h.phase) {
            Some(p) => p.1.push((step as f64, h.rms_normalized)),
            None => phases.push((h.phase.to_owned(), vec![(step as f64, h.rms_normalized)])),
        }
    }
    let mut body = String::new();
    if !history.is_empty() {
        plots::lines(
            &dir.join("fit.svg"),
            "bone fit: RMS error per step",
            ("step", "RMS error"),
            &phases,
            true,
        )?;
        body.push_str(&html::figure(
            "fit.svg",
            "bone fit convergence",
            &format!(
                "The proxy-bone fit's RMS error per step (clustering rounds, then alternations), log scale; it stopped: {}, {} bones.",
                r.json["fit"]["stop"].as_str().unwrap_or("?"),
                report.fit.bones
            ),
        ));
    }
    sections.push(html::section("fit", "Bone fit", &body));

    let mut body = String::new();
    match &report.selection {
        Some(s) => body.push_str(&grid_figure(dir, "selection.svg", &s.table, "this model")?),
        None => body.push_str("<p>No model selection in this run (give <code>--select</code> to score kernel x kappa x beta).</p>\n"),
    }
    if let Some(c) = &report.control_selection {
        let pts: Vec<(f64, f64)> = c
            .errors
            .iter()
            .enumerate()
            .map(|(i, &e)| (i as f64, e))
            .collect();
        plots::lines(
            &dir.join("control-selection.svg"),
            "control-point swaps: leave-one-out RMS",
            ("accepted swaps", "RMS error"),
            &[("select".to_owned(), pts)],
            false,
        )?;
        body.push_str(&html::figure(
            "control-selection.svg",
            "control-point selection",
            &format!(
                "Control-point selection: the leave-one-out error of the starting set, then after each of the {} accepted swaps (pool of {}).",
                c.swaps.len(),
                c.pool.len()
            ),
        ));
    }
    sections.push(html::section("selection", "Model selection", &body));
    let names: Vec<String> = model.controls.iter().map(|c| c.name.clone()).collect();
    let mut body = controls_figure(dir, rest, &named_controls(&controls, Some(&names)))?;
    if let Some(c) = &report.coverage {
        body.push_str(&coverage_figures(dir, rest, &controls, c)?);
    }
    sections.push(html::section("controls", "Control points", &body));

    let mut items = vec![("bone fit".to_owned(), report.fit.seconds)];
    if let Some(g) = &report.group_rig {
        items.push((format!("grouping rig ({} bones)", g.bones), g.seconds));
    }
    if let Some(c) = &report.control_selection {
        items.push(("control-point selection".into(), c.seconds));
    }
    items.push(("control points".into(), report.controls_seconds));
    if let Some(c) = &report.coverage {
        items.push(("control-point curve, undetermined bones".into(), c.seconds));
    }
    items.push(("edge skin".into(), report.edges_seconds));
    match &report.selection {
        Some(s) => {
            items.push(("model selection".into(), s.seconds));
            items.push((
                "regressors (after selection)".into(),
                (report.regress_seconds - s.seconds).max(0.0),
            ));
        }
        None => items.push(("regressors".into(), report.regress_seconds)),
    }
    if let Some(d) = &report.detail {
        items.push(("detail: resampling".into(), d.extract_seconds));
        items.push(("detail: regression".into(), d.fit_seconds));
    }
    items.push(("training total".into(), report.seconds));
    items.push(("report: training poses".into(), pose_seconds));
    items.push(("report total".into(), start.elapsed().as_secs_f64()));
    sections.push(html::section(
        "timings",
        "Stage timings",
        &timings_figure(
            dir,
            &items,
            "Wall-clock seconds of each training stage (from the training report) and of this report",
        )?,
    ));
    let page = html::page(&format!("crease train report: {}", r.source), &sections);
    std::fs::write(&index, page).with_context(|| format!("writing {}", index.display()))?;
    Ok(index)
}

/// The control-point curve and the undetermined regions (issue 42, `crate::coverage` of the
/// training report) as figures.
fn coverage_figures(
    dir: &Path,
    rest: &crease_core::mesh::Mesh,
    controls: &[u32],
    c: &crease_train::selection::ControlCoverage,
) -> anyhow::Result<String> {
    let mut body = String::new();
    if !c.curve.is_empty() {
        let pts: Vec<(f64, f64)> = c.curve.iter().map(|p| (p.count as f64, p.rms)).collect();
        plots::lines(
            &dir.join("control-curve.svg"),
            "leave-one-out RMS by number of automatic control points",
            ("control points", "RMS error"),
            &[("automatic".to_owned(), pts)],
            false,
        )?;
        let table: Vec<String> = c
            .curve
            .iter()
            .map(|p| format!("{}: {:.4e}", p.count, p.rms))
            .collect();
        body.push_str(&html::figure(
            "control-curve.svg",
            "control-point curve",
            &format!(
                "How the error falls with the number of control points: for each count, the automatic points (FKY08 &sect;3) and the leave-one-out mesh error inside the training set (each non-rest pose held out, the rotations regressed from the others, eq. 11, LBS; the bones fitted on every pose). {}. This model has {} points.{}",
                table.join(", "),
                controls.len(),
                c.curve_stopped
                    .as_ref()
                    .map_or(String::new(), |w| format!(" The curve stops: {}.", html::escape(w)))
            ),
        ));
    }
    let regions = &c.bones.regions;
    if regions.is_empty() {
        body.push_str("<p>Every bone the examples move is predicted from these control points within half its movement (leave-one-out): no region is left undetermined.</p>\n");
        return Ok(body);
    }
    let vertex_sets: Vec<&[u32]> = regions.iter().map(|r| r.vertices.as_slice()).collect();
    renders::undetermined_regions(
        &dir.join("undetermined.png"),
        &rest.positions,
        &rest.triangles,
        &vertex_sets,
        controls,
    )?;
    let legend: Vec<String> = regions
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let [red, green, blue] = renders::marker_color(k);
            format!(
                "<span style=\"color: rgb({red},{green},{blue})\">&#9632;</span> region {}: {} bones, {} vertices around ({:.3}, {:.3}, {:.3}), turned {:.1}&deg; by the examples, predicted {:.1}&deg; off",
                k + 1,
                r.bones.len(),
                r.vertices.len(),
                r.centroid[0],
                r.centroid[1],
                r.centroid[2],
                r.spread_deg,
                r.error_deg
            )
        })
        .collect();
    body.push_str(&html::figure(
        "undetermined.png",
        "regions the control points leave undetermined",
        &format!(
            "<b>Warning: the control points leave {} region(s) undetermined</b> (coloured; the control points are the black dots): bones the examples turn by at least {}&deg; on average whose leave-one-out rotation error is at least {} of that, so a new pose there is guessed, not followed. A control point in a region would constrain it.<br>{}",
            regions.len(),
            crease_train::coverage::MIN_SPREAD_DEG,
            crease_train::coverage::UNDETERMINED_RATIO,
            legend.join("<br>")
        ),
    ));
    Ok(body)
}

/// A pose name without its folders and extension, for axis labels.
fn short_name(name: &str) -> String {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name);
    let stem = base.rsplit_once('.').map_or(base, |(s, _)| s);
    let parent = name
        .rsplit(['/', '\\'])
        .nth(1)
        .map_or(String::new(), |p| format!("{p}/"));
    format!("{parent}{stem}")
}
