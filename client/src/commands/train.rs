//! `crease train`: bones, control points, rotation regressors and the edge skin in one model
//! file (FKY08 §3–5, HZY11 §5.1), and the detail layer when the examples are detailed
//! (HZY11 §4, §5.2).

use std::path::PathBuf;

use anyhow::{Context, bail};
use crease_train::bones::FitOptions;
use crease_train::kcca::KccaOptions;
use crease_train::pipeline::{self, EdgeModel, TrainInput, TrainOptions};
use crease_train::regress::{KernelChoice, Method, RegressOptions};
use crease_train::select::SelectGrid;

use super::common::{self, Progress};
use super::layers;

/// Regression options shared by `train` and `eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct RegressArgs {
    /// Number of proxy bones.
    #[arg(long, default_value_t = FitOptions::default().bones)]
    pub bones: usize,
    /// Most bones per vertex (K, 1..=8).
    #[arg(long, default_value_t = 8)]
    pub max_influences: usize,
    /// Control points: `auto:N` (PCA + varimax), `auto` (= auto:8), `select:N` (auto:N improved by
    /// swaps with 2N PCA + varimax representatives, scored by leave-one-out inside the training
    /// set), or vertex
    /// indices `12,400,7`. Default: the manifest's list, else auto:8.
    #[arg(long, value_name = "SPEC")]
    pub control_points: Option<String>,
    /// Control points per bone for the geometry-local methods (HZY11 k_c).
    #[arg(long, default_value_t = 7)]
    pub kc: usize,
    /// Poses per local model and blended at run time (HZY11 k_p).
    #[arg(long, default_value_t = 7)]
    pub kp: usize,
    /// Regression kernel: `gaussian` (width from --sigma-scale), `gaussian+linear:G` (plus a
    /// linear part of weight G) or `poly:D` (inhomogeneous polynomial of degree D, FKY08 §7).
    #[arg(long, default_value = "gaussian", value_name = "KERNEL")]
    pub kernel: String,
    /// Gaussian kernel width as a multiple of the RMS spread of the training control vectors.
    #[arg(long, default_value_t = 1.0)]
    pub sigma_scale: f32,
    /// KCCA regularisation kappa, relative to the kernel matrix's largest eigenvalue.
    #[arg(long, default_value_t = 1e-3)]
    pub kappa: f64,
    /// Choose kernel, width, kappa and beta by leave-one-out inside the training examples
    /// (overrides --kernel, --sigma-scale, --kappa and --beta).
    #[arg(long)]
    pub select: bool,
    /// Control-point weight of the translation solve (FKY08 eq. 11; ~3 keyframing, ~0.3 mocap).
    #[arg(long, default_value_t = 1.0)]
    pub beta: f32,
    /// Edge skin of the translation solve: `vector` (per-bone edge vectors, ridge chosen by
    /// cross-validation) or `scalar` (FKY08 eq. 10 weights).
    #[arg(long, default_value = "vector", value_parser = ["vector", "scalar"])]
    pub edge_skin: String,
    /// Ridge of the vector edge skin instead of cross-validating it (`inf` = scalar weights).
    #[arg(long, value_name = "RIDGE")]
    pub edge_ridge: Option<f64>,
}

impl RegressArgs {
    /// Training options for `method`.
    pub fn train_options(
        &self,
        method: Method,
        set: &crease_core::mesh::ExampleSet,
    ) -> anyhow::Result<TrainOptions> {
        if !(self.beta.is_finite() && self.beta > 0.0) {
            bail!("--beta must be > 0, got {}", self.beta);
        }
        if !(self.sigma_scale.is_finite() && self.sigma_scale > 0.0) {
            bail!("--sigma-scale must be > 0, got {}", self.sigma_scale);
        }
        if !(self.kappa.is_finite() && self.kappa >= 0.0) {
            bail!("--kappa must be >= 0, got {}", self.kappa);
        }
        let kernel = match self.kernel.as_str() {
            "gaussian" => KernelChoice::Gaussian {
                scale: self.sigma_scale,
            },
            k => match (
                k.strip_prefix("poly:").map(str::parse::<u32>),
                k.strip_prefix("gaussian+linear:").map(str::parse::<f32>),
            ) {
                (Some(Ok(degree)), _) if (1..=8).contains(&degree) => {
                    KernelChoice::Polynomial { c: 1.0, degree }
                }
                (_, Some(Ok(gamma))) if gamma.is_finite() && gamma >= 0.0 => {
                    KernelChoice::GaussianLinear {
                        scale: self.sigma_scale,
                        gamma,
                    }
                }
                _ => bail!(
                    "--kernel {k}: expected gaussian, gaussian+linear:G (G >= 0) or poly:D (D in 1..=8)"
                ),
            },
        };
        if let Some(r) = self.edge_ridge.filter(|r| r.is_nan() || *r < 0.0) {
            bail!("--edge-ridge must be >= 0, got {r}");
        }
        let edge_model = match self.edge_skin.as_str() {
            "scalar" => {
                if self.edge_ridge.is_some() {
                    bail!("--edge-ridge applies to --edge-skin vector only");
                }
                EdgeModel::Scalar
            }
            _ => EdgeModel::Vector {
                ridge: self.edge_ridge,
            },
        };
        Ok(TrainOptions {
            fit: FitOptions {
                bones: self.bones,
                max_influences: self.max_influences,
                ..FitOptions::default()
            },
            controls: common::control_spec(self.control_points.as_deref(), set)?,
            // The manifest's names go with the manifest's points.
            control_names: self
                .control_points
                .is_none()
                .then(|| set.control_point_names.clone())
                .flatten(),
            regress: RegressOptions {
                method,
                kc: self.kc,
                kp: self.kp,
                kernel,
                kcca: KccaOptions {
                    kappa: self.kappa,
                    ..KccaOptions::default()
                },
                ..RegressOptions::default()
            },
            edge_influences: None,
            edge_model,
            beta: self.beta,
            select: self.select.then(SelectGrid::default),
            detail: Default::default(),
        })
    }
}

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
    /// Print one JSON object with the training report on stdout.
    #[arg(long)]
    pub json: bool,
}

/// clap value parser for [`Method`].
pub fn parse_method(s: &str) -> Result<Method, String> {
    Method::parse(s).ok_or_else(|| {
        format!(
            "unknown method {s:?}; one of: {}",
            Method::ALL.map(|m| m.name()).join(", ")
        )
    })
}

/// Runs `crease train`.
pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let layers = layers::load(&args.examples, &args.detail, None)?;
    let set = &layers.base;
    let mut options = args.regress.train_options(args.method, set)?;
    options.detail = layers::detail_options(&args.detail, &layers)?;
    let frames: Vec<&[crease_core::glam::Vec3]> = set.frames();
    let names: Vec<String> = set.names();
    let progress = Progress::new(options.fit.max_iterations as u64);
    let detail_parts = layers.detail_frames();
    let (model, report) = pipeline::train_layers(
        TrainInput {
            rest: &set.rest,
            frames: &frames,
            names: &names,
        },
        detail_parts.as_ref().map(layers::frames),
        &options,
        &mut |s| progress.step(s),
        &mut |done, total| {
            progress.line(
                "detail",
                None,
                &format!("resampled {done}/{total}"),
                &format!("detail layer: resampled detailed example {done}/{total}"),
            )
        },
    )
    .context("training")?;
    progress.finish();
    for w in &report.fit.warnings {
        eprintln!("warning: {w}");
    }
    model
        .save(&args.out)
        .with_context(|| format!("writing model {}", args.out.display()))?;
    eprintln!(
        "wrote {}: {} bones, {} control points (vertices {:?}), method {}",
        args.out.display(),
        model.rig.bone_count,
        model.controls.len(),
        model.controls.iter().map(|c| c.vertex).collect::<Vec<_>>(),
        model.method
    );
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
            super::eval::kernel_name(&s.best.kernel),
            s.best.kappa,
            s.best.beta,
            s.best.rms,
            s.seconds
        );
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
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "trained in {:.2} s (bones {:.2} s, rms {:.4e}; controls {:.2} s; regressors {:.2} s; edge skin {:.2} s{})",
            report.seconds,
            report.fit.seconds,
            report.fit.rms_normalized,
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
