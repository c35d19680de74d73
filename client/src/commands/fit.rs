//! `crease fit`: proxy bones and skinning weights from example meshes (FKY08 §3, HZY11 §5.1).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use crease_core::model::{Rig, RigExample};
use crease_train::bones::{self, FitInput, FitOptions, IterationStat};

use super::common::Progress;

/// Options of `crease fit`.
#[derive(Clone, Debug, clap::Args)]
pub struct FitArgs {
    /// Example set: a folder of meshes (rest pose = `reference.*`, else the first in name
    /// order; sub-folders included) or a TOML manifest.
    #[arg(long, value_name = "DIR|MANIFEST")]
    pub examples: PathBuf,
    /// Number of proxy bones.
    #[arg(long, default_value_t = FitOptions::default().bones)]
    pub bones: usize,
    /// Most bones per vertex (K, 1..=8).
    #[arg(long, default_value_t = FitOptions::default().max_influences)]
    pub max_influences: usize,
    /// Cap on weight/transform alternations after clustering.
    #[arg(long, default_value_t = FitOptions::default().max_iterations)]
    pub max_iterations: usize,
    /// Stop when an alternation improves the RMS error by less than this fraction.
    #[arg(long, default_value_t = FitOptions::default().tolerance)]
    pub tolerance: f64,
    /// Write the rig here (crease rig file; written atomically).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Also write the rest mesh as a skinned glTF binary with one animation keyframe per example.
    #[arg(long, value_name = "FILE.glb")]
    pub export_gltf: Option<PathBuf>,
    /// Print one JSON object with the results on stdout (progress stays on stderr).
    #[arg(long)]
    pub json: bool,
}

/// The JSON printed by `--json`.
#[derive(Debug, serde::Serialize)]
struct FitSummary<'a> {
    examples: String,
    vertices: usize,
    frames: usize,
    bones_requested: usize,
    bones: usize,
    max_influences: usize,
    iterations: usize,
    /// RMS vertex error over all example frames but the rest pose, bbox largest side = 1.
    rms_normalized: f64,
    /// Seconds of fitting (clustering + alternation), loading excluded.
    seconds: f64,
    /// Seconds reading the example meshes.
    load_seconds: f64,
    stop: bones::StopReason,
    warnings: &'a [String],
    out: Option<String>,
    gltf: Option<String>,
    history: &'a [IterationStat],
}

/// Runs `crease fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let load_start = Instant::now();
    let set = super::common::load_examples(&args.examples)?;
    let load_seconds = load_start.elapsed().as_secs_f64();
    let frames: Vec<&[crease_core::glam::Vec3]> = set.frames();
    eprintln!(
        "read {} examples of {} vertices in {:.2} s (rest pose: {})",
        frames.len(),
        set.rest.vertex_count(),
        load_seconds,
        set.rest_name
    );

    let options = FitOptions {
        bones: args.bones,
        max_influences: args.max_influences,
        max_iterations: args.max_iterations,
        tolerance: args.tolerance,
        ..FitOptions::default()
    };
    let progress = Progress::new(options.max_iterations as u64);
    let input = FitInput {
        rest: &set.rest,
        frames: &frames,
        rest_frame: Some(0),
    };
    let result = bones::fit(input, &options, &mut |stat| progress.step(stat))
        .context("fitting proxy bones")?;
    progress.finish();
    let report = &result.report;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }

    let rig = Rig {
        rest: set.rest.clone(),
        bone_count: result.bone_count,
        skin: result.skin.clone(),
        examples: set
            .examples
            .iter()
            .zip(result.transforms)
            .map(|(e, transforms)| RigExample {
                name: e.name.clone(),
                transforms,
            })
            .collect(),
        fit_rms: Some(report.rms_normalized as f32),
    };
    if let Some(out) = &args.out {
        rig.save(out)
            .with_context(|| format!("writing rig {}", out.display()))?;
        eprintln!("wrote {}", out.display());
    }
    if let Some(glb) = &args.export_gltf {
        crease_core::model::export_rig_glb(&rig, glb)
            .with_context(|| format!("writing glTF {}", glb.display()))?;
        eprintln!("wrote {}", glb.display());
    }

    if args.json {
        let summary = FitSummary {
            examples: args.examples.display().to_string(),
            vertices: set.rest.vertex_count(),
            frames: frames.len(),
            bones_requested: report.bones_requested,
            bones: report.bones,
            max_influences: report.max_influences,
            iterations: report.iterations,
            rms_normalized: report.rms_normalized,
            seconds: report.seconds,
            load_seconds,
            stop: report.stop,
            warnings: &report.warnings,
            out: args.out.as_ref().map(|p| p.display().to_string()),
            gltf: args.export_gltf.as_ref().map(|p| p.display().to_string()),
            history: &report.history,
        };
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        println!(
            "{} bones (K = {}), {} iterations, rms_normalized {:.4e}, {:.2} s ({:?})",
            report.bones,
            report.max_influences,
            report.iterations,
            report.rms_normalized,
            report.seconds,
            report.stop
        );
    }
    Ok(())
}
