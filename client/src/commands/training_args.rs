//! Training options on the command line, shared by `crease train` and `crease eval`: the
//! bone, control-point and regression flags ([`RegressArgs`]) turned into
//! [`TrainOptions`], and how methods and kernels are named.

use anyhow::bail;
use crease_train::bones::FitOptions;
use crease_train::kcca::KccaOptions;
use crease_train::pipeline::{EdgeModel, TrainOptions};
use crease_train::regress::{KernelChoice, Method, RegressOptions};
use crease_train::select::SelectGrid;

/// Regression options shared by `train` and `eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct RegressArgs {
    /// Number of proxy bones.
    #[arg(long, default_value_t = FitOptions::default().bones)]
    pub bones: usize,
    /// Local methods: give each bone the control points of the bone it falls in of a coarse
    /// rig fitted beside the --bones rig, instead of its own k_c nearest (issue 23: with
    /// hundreds of bones trained from a few examples, per-bone sets make neighbouring bones'
    /// regressors disagree). `auto`: a rig of 150 bones (the default rig size) when --bones
    /// exceeds it, else off; `off`; or the coarse rig's bone count N (used when below --bones).
    #[arg(long, value_name = "auto|off|N", default_value = "auto")]
    pub group_bones: String,
    /// Most bones per vertex (K, 1..=8).
    #[arg(long, default_value_t = 8)]
    pub max_influences: usize,
    /// Control points: `auto:N` (PCA + varimax), `auto` (= auto:8), `select:N` (auto:N improved by
    /// swaps with 2N PCA + varimax representatives, scored by leave-one-out inside the training
    /// set), or vertex indices `12,400,7` of the examples as read (with --base-vertices they
    /// move to the nearest base vertex). Default: the manifest's list, else auto:8.
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

/// The coarse rig size `--group-bones auto` picks: the default rig's.
pub const AUTO_GROUP_BONES: usize = 150;

impl RegressArgs {
    /// The coarse rig that groups the bones (`--group-bones`), for a run whose methods include
    /// a geometry-local one when `geometry_local` (the others do not use it: no rig is fitted).
    pub fn group_bones(&self, geometry_local: bool) -> anyhow::Result<Option<usize>> {
        let count = match self.group_bones.as_str() {
            "off" => None,
            "auto" => (self.bones > AUTO_GROUP_BONES).then_some(AUTO_GROUP_BONES),
            n => match n.parse::<usize>() {
                Ok(n) if n >= 1 => Some(n),
                _ => bail!("--group-bones {n}: expected auto, off or a bone count >= 1"),
            },
        };
        Ok(count.filter(|&n| geometry_local && n < self.bones))
    }

    /// Training options for `method`.
    pub fn train_options(
        &self,
        method: Method,
        layers: &super::layers::Layers,
    ) -> anyhow::Result<TrainOptions> {
        let set = &layers.base;
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
            controls: layers.control_spec(self.control_points.as_deref())?,
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
            group_bones: self.group_bones(method.geometry_local())?,
            // `crease train --control-curve` turns these on.
            coverage: false,
            control_curve: Vec::new(),
        })
    }
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

/// `gaussian*1.4`, `gaussian*1+linear:0.1`, `poly:2`: how a selected kernel is printed.
pub fn kernel_name(k: &KernelChoice) -> String {
    match k {
        KernelChoice::Gaussian { scale } => format!("gaussian*{scale}"),
        KernelChoice::GaussianLinear { scale, gamma } => format!("gaussian*{scale}+linear:{gamma}"),
        KernelChoice::Polynomial { degree, .. } => format!("poly:{degree}"),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check
    use super::*;
    use clap::Parser;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        regress: RegressArgs,
    }

    fn args(a: &[&str]) -> RegressArgs {
        Cli::parse_from(std::iter::once("crease").chain(a.iter().copied())).regress
    }

    #[test]
    fn group_bones_auto_fits_the_default_rig_only_beneath_a_larger_one_for_local_methods() {
        let grouped = |a: &[&str], local| args(a).group_bones(local).unwrap();
        assert_eq!(grouped(&["--bones", "1355"], true), Some(AUTO_GROUP_BONES));
        assert_eq!(grouped(&["--bones", "150"], true), None);
        assert_eq!(grouped(&["--bones", "1355"], false), None);
        assert_eq!(
            grouped(&["--bones", "1355", "--group-bones", "off"], true),
            None
        );
        assert_eq!(
            grouped(&["--bones", "1355", "--group-bones", "40"], true),
            Some(40)
        );
        // Not below the rig: nothing to group by.
        assert_eq!(
            grouped(&["--bones", "30", "--group-bones", "40"], true),
            None
        );
        for bad in ["0", "1.5", "many"] {
            let e = args(&["--bones", "1355", "--group-bones", bad])
                .group_bones(true)
                .unwrap_err()
                .to_string();
            assert!(e.contains("--group-bones") && e.contains(bad), "{bad}: {e}");
        }
    }
}
