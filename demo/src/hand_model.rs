//! The demo model: a hand trained from the procedural sweep hand (LYK06) at two resolutions,
//! so it has a detail layer (HZY11), loaded from the cache folder when a previous start left it
//! there, else generated and trained (about 12 s on one core: 12 training poses at ~9.5K and
//! ~180K vertices, 40 bones, the 15 dorsal landmarks of `crease handgen`'s `back` layout as
//! control points, HZY11's local method, a two-level detail layer) and saved there.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::mesh::subdivision::subdivided_vertex_count;
use crease_core::model::TrainedModel;
use crease_hand::dataset::{Layout, dataset_poses, landmarks};
use crease_hand::rig::{HandRig, Layers, RigScratch};
use crease_hand::surface::Resolution;
use crease_train::bones::FitOptions;
use crease_train::detail::layer::{DetailFrames, DetailOptions};
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};
use crease_train::regress::{Method, RegressOptions};

/// The cached model's file name in the cache folder. The version changes whenever the recipe
/// below does, so a stale cache is never served.
pub const CACHE_FILE: &str = "demo-hand-v1.crease";
/// Training poses: the flat rest pose, the nine other named poses, two sampled ones.
const TRAIN_POSES: usize = 12;
/// Seed of the pose sampler (as `crease handgen --seed 1`).
const SEED: u64 = 1;

/// Errors of building the demo.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The sweep hand could not be built.
    #[error("building the sweep hand: {0}")]
    Hand(String),
    /// Training failed.
    #[error("training the demo hand: {0}")]
    Train(String),
    /// The cache folder could not be written.
    #[error("caching the demo model in {path}: {message}")]
    Cache {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// The cache folder: `$CREASE_CACHE_DIR`, else `$XDG_CACHE_HOME/crease`, else
/// `$HOME/.cache/crease`, else `.crease-cache` in the working directory.
pub fn default_cache_dir() -> PathBuf {
    let env = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty());
    if let Some(dir) = env("CREASE_CACHE_DIR") {
        return PathBuf::from(dir);
    }
    if let Some(dir) = env("XDG_CACHE_HOME") {
        return PathBuf::from(dir).join("crease");
    }
    if let Some(home) = env("HOME") {
        return PathBuf::from(home).join(".cache").join("crease");
    }
    PathBuf::from(".crease-cache")
}

/// The demo model: loaded from `cache_dir` if a valid one is there, else built, trained and
/// saved there (atomically; a failed save is reported, the model still returned). `progress`
/// gets one line per stage.
///
/// # Errors
/// [`DemoError`] when the hand cannot be built or trained.
pub fn demo_model(
    cache_dir: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<TrainedModel, DemoError> {
    let path = cache_dir.join(CACHE_FILE);
    match TrainedModel::load(&path) {
        Ok(model) => {
            progress(&format!("loaded the demo model from {}", path.display()));
            return Ok(model);
        }
        Err(e) if path.exists() => {
            progress(&format!("{}: {e}; training it again", path.display()));
        }
        Err(_) => {}
    }
    let model = train_demo_model(progress)?;
    match save_cache(cache_dir, &model) {
        Ok(path) => progress(&format!("cached the demo model in {}", path.display())),
        Err(e) => progress(&e.to_string()),
    }
    Ok(model)
}

/// Saves `model` as the demo model's cache in `cache_dir` (created if missing), atomically: a
/// process killed while saving leaves the previous cache or this one, whole
/// (`core::atomic`; `demo/tests/crash_safe_cache.rs` kills it). Returns the file's path.
///
/// # Errors
/// [`DemoError::Cache`], naming the file and the cause (a full disk, no permission).
pub fn save_cache(cache_dir: &Path, model: &TrainedModel) -> Result<PathBuf, DemoError> {
    let path = cache_dir.join(CACHE_FILE);
    std::fs::create_dir_all(cache_dir)
        .map_err(|e| e.to_string())
        .and_then(|()| model.save(&path).map_err(|e| e.to_string()))
        .map_err(|message| DemoError::Cache {
            path: path.clone(),
            message,
        })?;
    Ok(path)
}

/// Generates the training poses at both resolutions and trains the model (module docs).
fn train_demo_model(progress: &mut dyn FnMut(&str)) -> Result<TrainedModel, DemoError> {
    let start = Instant::now();
    let mut say =
        |what: &str| progress(&format!("[{:5.1}s] {what}", start.elapsed().as_secs_f32()));
    let (poses, _) = dataset_poses(TRAIN_POSES, 0, SEED);
    say("building the sweep hand (base and detailed)");
    let base = HandRig::build(Resolution::Base).map_err(|e| DemoError::Hand(e.to_string()))?;
    let detailed =
        HandRig::build(Resolution::Detailed).map_err(|e| DemoError::Hand(e.to_string()))?;
    say(&format!(
        "posing {} training hands ({} and {} vertices)",
        poses.len(),
        base.vertex_count(),
        detailed.vertex_count()
    ));
    let pose_all = |rig: &HandRig| -> Vec<Vec<Vec3>> {
        let mut scratch = RigScratch::new();
        poses
            .iter()
            .map(|p| {
                let mut out = vec![Vec3::ZERO; rig.vertex_count()];
                rig.deform(&p.pose, Layers::default(), &mut scratch, &mut out);
                out
            })
            .collect()
    };
    let base_frames = pose_all(&base);
    let detailed_frames = pose_all(&detailed);
    // The rest pose is the first training pose (flat), as in `crease handgen`'s manifests.
    let rest = Mesh {
        positions: base_frames[0].clone(),
        triangles: base.rest().triangles.clone(),
    };
    let marks = landmarks(
        Layout::Back,
        base.skeleton(),
        base.rest(),
        &base.rest().vertex_normals(),
    );
    let want = detailed.vertex_count() as f64;
    let levels = (1..=3u32)
        .min_by(|&a, &b| {
            let off = |l| (subdivided_vertex_count(&rest, l) as f64 / want).ln().abs();
            off(a).total_cmp(&off(b))
        })
        .unwrap_or(1);
    let options = TrainOptions {
        fit: FitOptions {
            bones: 40,
            max_influences: 4,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(marks.iter().map(|m| m.vertex).collect()),
        control_names: Some(marks.iter().map(|m| m.name.clone()).collect()),
        regress: RegressOptions {
            method: Method::Local,
            ..RegressOptions::default()
        },
        detail: DetailOptions {
            levels,
            ..DetailOptions::default()
        },
        ..TrainOptions::default()
    };
    say(&format!(
        "training: 40 bones, {} control points, local regressors, {levels}-level detail layer",
        marks.len()
    ));
    let frames: Vec<&[Vec3]> = base_frames.iter().map(Vec::as_slice).collect();
    let detail: Vec<&[Vec3]> = detailed_frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = poses.iter().map(|p| p.name.clone()).collect();
    let (model, _) = pipeline::train_layers(
        TrainInput {
            rest: &rest,
            frames: &frames,
            names: &names,
        },
        Some(DetailFrames {
            frames: &detail,
            triangles: &detailed.rest().triangles,
        }),
        &options,
        &mut |_| {},
        &mut |_, _| {},
    )
    .map_err(|e| DemoError::Train(e.to_string()))?;
    say("trained");
    Ok(model)
}
