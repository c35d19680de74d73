//! Both layers' examples for `train` and `eval`: the base set and, when there is one, the
//! detailed version of every example, from the manifest's `detailed` key (`crease handgen`
//! writes it) or from an automatic split of single-resolution examples (`--base-vertices`:
//! a meshopt vertex subset of the rest pose, Laplacian-smoothed, as the base; the full meshes as
//! the detail; HZY11 §4, DESIGN.md step 2).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use crease_core::glam::Vec3;
use crease_core::mesh::examples::{ExampleSet, NamedMesh};
use crease_core::mesh::subdivision::subdivided_vertex_count;
use crease_train::base::ControlSpec;
use crease_train::detail::layer::{DetailFrames, DetailOptions};
use crease_train::detail::{BaseSubset, Smoothing};

use super::common;

/// Detailed frames and their shared triangles, as [`Layers::detail_frames`] lends them.
pub type FramesParts<'a> = (Vec<&'a [Vec3]>, &'a [[u32; 3]]);

/// Options of the detail layer shared by `train` and `eval`.
#[derive(Clone, Debug, clap::Args)]
pub struct DetailArgs {
    /// Split single-resolution examples: the base is a subset of about N vertices of the rest
    /// pose (meshopt's simplifier), the same subset of every example Laplacian-smoothed, and the
    /// detail layer learns the full meshes (HZY11 §4). Control points given as full-mesh
    /// vertices move to the nearest base vertex.
    #[arg(long, value_name = "N")]
    pub base_vertices: Option<usize>,
    /// Loop subdivision levels of the detail layer (1 to 3). Default: the level whose vertex
    /// count is closest to the detailed examples'.
    #[arg(long, value_name = "LEVELS")]
    pub detail_levels: Option<u32>,
    /// Ray search distance of the displacement extraction, as a fraction of the rest mesh's
    /// largest bounding-box side; rays finding nothing fall back to the closest point.
    #[arg(long, default_value_t = DetailOptions::default().max_distance, value_name = "FRACTION")]
    pub detail_ray: f32,
    /// Train and evaluate the base layer only, even when detailed examples are present (with
    /// --base-vertices the base is still the subset).
    #[arg(long)]
    pub no_detail: bool,
}

/// The examples of both layers.
#[derive(Debug)]
pub struct Layers {
    /// The base examples (what the bones and regressors train on).
    pub base: ExampleSet,
    /// The detailed version of every base example, in the same order.
    pub detailed: Option<ExampleSet>,
    /// The vertex subset, when the base was split off automatically.
    pub subset: Option<BaseSubset>,
    /// Whether the detail layer trains (`--no-detail` says no; the examples as read stay in
    /// `detailed` after a split, for the control points' mapping).
    pub train_detail: bool,
}

impl Layers {
    /// `--control-points` for these layers ([`common::control_spec`] on the base): vertex
    /// indices given on the command line name vertices of the examples as read, so with an
    /// automatic split (`--base-vertices`) they move to the nearest base vertex at rest, as the
    /// manifest's list does.
    pub fn control_spec(&self, arg: Option<&str>) -> anyhow::Result<ControlSpec> {
        let spec = common::control_spec(arg, &self.base)?;
        let (Some(_), ControlSpec::Vertices(given), Some(subset), Some(full)) =
            (arg, &spec, &self.subset, &self.detailed)
        else {
            return Ok(spec);
        };
        let n = full.rest.vertex_count();
        if let Some(&v) = given.iter().find(|&&v| v as usize >= n) {
            bail!(
                "--control-points: vertex {v} is out of range: the examples ({}) have {n} vertices",
                full.rest_name
            );
        }
        Ok(ControlSpec::Vertices(
            given
                .iter()
                .map(|&v| nearest_subset_vertex(subset, &full.rest.positions, v))
                .collect(),
        ))
    }

    /// The detailed frames for the detail layer's training, if any.
    pub fn detail_frames(&self) -> Option<FramesParts<'_>> {
        self.detailed
            .as_ref()
            .filter(|_| self.train_detail)
            .map(|d| (d.frames(), d.rest.triangles.as_slice()))
    }
}

/// Borrows `frames` as [`DetailFrames`].
pub fn frames<'a>(parts: &'a FramesParts<'a>) -> DetailFrames<'a> {
    DetailFrames {
        frames: &parts.0,
        triangles: parts.1,
    }
}

/// Loads the examples at `path` with their detailed version (module docs). `subset`: split
/// with this subset (the training set's, for a test set) instead of simplifying again.
pub fn load(path: &Path, args: &DetailArgs, subset: Option<&BaseSubset>) -> anyhow::Result<Layers> {
    let set = common::load_examples(path)?;
    if args.no_detail && args.base_vertices.is_none() {
        return Ok(Layers {
            base: set,
            detailed: None,
            subset: None,
            train_detail: false,
        });
    }
    let Some(target) = args.base_vertices else {
        let detailed = set.load_detailed().with_context(|| {
            format!("reading the detailed examples named by {}", path.display())
        })?;
        if let Some(d) = &detailed {
            eprintln!(
                "read {} detailed examples of {} vertices",
                d.examples.len(),
                d.rest.vertex_count()
            );
        }
        return Ok(Layers {
            base: set,
            detailed,
            subset: None,
            train_detail: true,
        });
    };
    if set.detailed.is_some() {
        bail!(
            "{}: --base-vertices splits single-resolution examples, but this manifest already names detailed examples",
            path.display()
        );
    }
    let start = Instant::now();
    let subset = match subset {
        Some(s) => {
            if s.full_vertex_count() != set.rest.vertex_count() {
                bail!(
                    "{}: {} vertices, the training examples had {}",
                    path.display(),
                    set.rest.vertex_count(),
                    s.full_vertex_count()
                );
            }
            s.clone()
        }
        None => BaseSubset::simplify(&set.rest, target)
            .with_context(|| format!("simplifying the rest pose of {}", path.display()))?,
    };
    let smoothing = Smoothing::default();
    let examples = set
        .examples
        .iter()
        .map(|e| {
            Ok(NamedMesh {
                name: e.name.clone(),
                mesh: subset.base_mesh(&e.mesh.positions, &smoothing)?,
            })
        })
        .collect::<Result<Vec<_>, crease_train::detail::SplitError>>()?;
    // Control points move to the nearest subset vertex at rest.
    let control_points = set.control_points.as_ref().map(|cps| {
        cps.iter()
            .map(|&c| nearest_subset_vertex(&subset, &set.rest.positions, c))
            .collect::<Vec<u32>>()
    });
    let base = ExampleSet {
        rest: examples[0].mesh.clone(),
        rest_name: set.rest_name.clone(),
        examples,
        control_points,
        control_point_names: set.control_point_names.clone(),
        root: set.root.clone(),
        detailed: None,
    };
    eprintln!(
        "split {} vertices into a base of {} (meshopt subset, {} Laplacian steps of {}) in {:.2} s; the full meshes are the detail",
        set.rest.vertex_count(),
        subset.vertex_count(),
        smoothing.iterations,
        smoothing.lambda,
        start.elapsed().as_secs_f64()
    );
    Ok(Layers {
        base,
        detailed: Some(set),
        subset: Some(subset),
        train_detail: !args.no_detail,
    })
}

/// The base vertex nearest (at rest) to full vertex `v`: itself when it is in the subset.
fn nearest_subset_vertex(subset: &BaseSubset, rest: &[Vec3], v: u32) -> u32 {
    let p = rest[v as usize];
    let mut best = (f32::INFINITY, 0u32);
    for (k, &full) in subset.vertices().iter().enumerate() {
        let d = rest[full as usize].distance_squared(p);
        if d < best.0 {
            best = (d, k as u32);
        }
    }
    best.1
}

/// The detail options of `args` for these layers: the levels (given, or the one whose vertex
/// count is closest, in ratio, to the detailed examples': HZY11 §4 subdivides "to retrieve
/// the resolution of the original mesh") and the ray distance.
pub fn detail_options(args: &DetailArgs, layers: &Layers) -> anyhow::Result<DetailOptions> {
    if !(args.detail_ray.is_finite() && args.detail_ray > 0.0) {
        bail!("--detail-ray must be > 0, got {}", args.detail_ray);
    }
    let levels = match (args.detail_levels, &layers.detailed) {
        (Some(l), _) if !(1..=3).contains(&l) => bail!("--detail-levels must be 1 to 3, got {l}"),
        (Some(l), _) => l,
        (None, None) => DetailOptions::default().levels,
        (None, Some(d)) => {
            let want = d.rest.vertex_count() as f64;
            (1..=3u32)
                .min_by(|&a, &b| {
                    let off = |l| {
                        (subdivided_vertex_count(&layers.base.rest, l) as f64 / want)
                            .ln()
                            .abs()
                    };
                    off(a).total_cmp(&off(b))
                })
                .unwrap_or(1)
        }
    };
    Ok(DetailOptions {
        levels,
        max_distance: args.detail_ray,
        ..DetailOptions::default()
    })
}
