//! The models a server hosts: every `*.crease` file of a model directory, loaded and validated
//! once at start, and (in a cluster) models fetched from the cluster's store later; rooms hold
//! an `Arc` of theirs. Each model carries the SHA-256 of its serialised form, which names it
//! across replicas (`crate::cluster`).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock, RwLock};

use crease_core::codec::palette::PaletteHeader;
use crease_core::codec::spatial_order;
use crease_core::glam::Vec3;
use crease_core::mesh::subdivision::LoopSubdivision;
use crease_core::model::{MirrorPlane, ModelError, TrainedModel};
use crease_core::runtime::skin::{BonePalette, skin_lbs};
use crease_proto::{Level, PaletteParts, model_info, palette_topology_message, v1};
use prost::Message as _;
use prost::bytes::Bytes;

/// One loaded model.
#[derive(Debug)]
pub struct LoadedModel {
    /// Its name: the file stem.
    pub name: String,
    /// The model.
    pub model: Arc<TrainedModel>,
    /// Its public description (`GetModel`).
    pub info: v1::ModelInfo,
    /// SHA-256 of the model's serialised form (`TrainedModel::to_bytes`), hex: the same model
    /// has the same digest on every replica, whatever file it was read from. Only a cluster
    /// needs it: computed when it joins (or known when a model is fetched), never on a single
    /// server's start-up ([`LoadedModel::sha256`]).
    sha256: OnceLock<String>,
    /// The box around the rest pose and every training pose (skinned by the rig): where the
    /// model's meshes live, the basis of the streams' quantisation box.
    pub pose_bounds: (Vec3, Vec3),
    /// The base mesh's spatial streaming order, computed on first use and shared by every room
    /// (and batch) on this model.
    spatial: OnceLock<SpatialStream>,
    /// The same for the detail layer's mesh (`None`: no detail layer, or its subdivision
    /// cannot be built, which the predictor then reports).
    detail_spatial: OnceLock<Option<SpatialStream>>,
    /// The first message of a palette stream per level, built on first need and shared by
    /// every room and subscriber on this model.
    palette: [OnceLock<Result<PaletteMessage, String>>; 2],
}

/// A palette stream's first message, and the same encoded: the WebSocket sends the bytes (a
/// detail header is 11.5 MB on the demo hand: encoding it per subscriber made RSS swing by
/// tens of MiB under the soak), gRPC the message (its arrays are `Bytes`, so clones share).
#[derive(Clone, Debug)]
struct PaletteMessage {
    message: v1::MeshFrame,
    encoded: Bytes,
}

/// A mesh (the base, or the detail layer's) in a spatial streaming order
/// (`core::codec::spatial_order`).
#[derive(Debug)]
pub struct SpatialStream {
    /// Streamed vertex `i` is model vertex `order[i]`.
    pub order: Vec<u32>,
    /// The mesh's triangles in the streamed order.
    pub triangles: Vec<[u32; 3]>,
}

impl SpatialStream {
    /// The spatial order of a mesh's vertices and its triangles renumbered into it.
    fn of(positions: &[Vec3], triangles: &[[u32; 3]]) -> SpatialStream {
        let order = spatial_order(positions);
        let mut inverse = vec![0u32; order.len()];
        for (i, &m) in order.iter().enumerate() {
            inverse[m as usize] = i as u32;
        }
        let triangles = triangles
            .iter()
            .map(|t| t.map(|v| inverse[v as usize]))
            .collect();
        SpatialStream { order, triangles }
    }
}

impl LoadedModel {
    /// The model's digest (the field's docs); serialises the model the first time (blocking:
    /// a cluster sets it off the async threads before it is read there).
    pub fn sha256(&self) -> &str {
        self.sha256.get_or_init(|| {
            self.model
                .to_bytes()
                .map(|b| sha256_hex(&b))
                .unwrap_or_default()
        })
    }

    /// Sets the digest from `bytes`, the model's serialised form, unless it is set already.
    pub(crate) fn set_sha256_of(&self, bytes: &[u8]) {
        self.sha256.get_or_init(|| sha256_hex(bytes));
    }

    /// Sets the digest (of the bytes the model was just read from), unless it is set already.
    pub(crate) fn set_sha256(&self, hex: String) {
        let _ = self.sha256.set(hex);
    }

    /// The base mesh's spatial streaming order (computed once).
    pub fn spatial(&self) -> &SpatialStream {
        self.spatial.get_or_init(|| {
            let rest = &self.model.rig.rest;
            SpatialStream::of(&rest.positions, &rest.triangles)
        })
    }

    /// The detail mesh's spatial streaming order (computed once, from the subdivided rest
    /// mesh; detail frames keep the subdivision's triangles, renumbered).
    pub fn detail_spatial(&self) -> Option<&SpatialStream> {
        self.detail_spatial
            .get_or_init(|| {
                let layer = self.model.detail.as_ref()?;
                let rest = &self.model.rig.rest;
                let subdivided = LoopSubdivision::new(rest, layer.levels)
                    .and_then(|s| s.mesh(&rest.positions))
                    .ok()?;
                Some(SpatialStream::of(
                    &subdivided.positions,
                    &subdivided.triangles,
                ))
            })
            .as_ref()
    }
}

impl LoadedModel {
    /// The first message of a palette stream of `level` (issue 18): the rest mesh, the skin
    /// and, at the detail level, the subdivision steps and the quantised detail regressor.
    /// Built once (blocking: the detail level subdivides the mesh and quantises `D`; callers
    /// run the first call on the blocking pool), then shared.
    ///
    /// # Errors
    /// A message saying why the header cannot be built (no detail layer, a subdivision or a
    /// regressor that does not fit the mesh).
    pub fn palette_topology(&self, level: Level) -> Result<v1::MeshFrame, String> {
        self.palette_message(level).map(|p| p.message.clone())
    }

    /// [`LoadedModel::palette_topology`] as protobuf bytes, encoded once with it and shared.
    ///
    /// # Errors
    /// As [`LoadedModel::palette_topology`].
    pub fn palette_topology_encoded(&self, level: Level) -> Result<Bytes, String> {
        self.palette_message(level).map(|p| p.encoded.clone())
    }

    /// The header of `level` and its encoding, built (and encoded) by the first call.
    fn palette_message(&self, level: Level) -> Result<&PaletteMessage, String> {
        self.palette[level as usize]
            .get_or_init(|| {
                let m = &self.model;
                let rest = &m.rig.rest;
                let header = PaletteHeader::base(
                    &rest.positions,
                    &rest.triangles,
                    &m.rig.skin,
                    m.rig.bone_count,
                )
                .map_err(|e| e.to_string())?;
                let header = match level {
                    Level::Base => header,
                    Level::Detail => {
                        let layer = m
                            .detail
                            .as_ref()
                            .ok_or_else(|| format!("model {:?} has no detail layer", self.name))?;
                        let subdivision = LoopSubdivision::new(rest, layer.levels)
                            .map_err(|e| format!("detail layer: {e}"))?;
                        header
                            .with_detail(&subdivision, &layer.regressor)
                            .map_err(|e| e.to_string())?
                    }
                };
                let message = palette_topology_message(PaletteParts {
                    model: &self.name,
                    level,
                    bounds: self.pose_bounds,
                    header: &header,
                })
                .map_err(|e| format!("palette header: {e}"))?;
                let encoded = Bytes::from(message.encode_to_vec());
                Ok(PaletteMessage { message, encoded })
            })
            .as_ref()
            .map_err(Clone::clone)
    }
}

/// The box around the rest mesh and the rig's training poses.
fn pose_bounds(model: &TrainedModel) -> (Vec3, Vec3) {
    let rest = &model.rig.rest;
    let (mut lo, mut hi) = rest.bounding_box();
    let mut posed = vec![Vec3::ZERO; rest.vertex_count()];
    for example in &model.rig.examples {
        let palette = BonePalette::from_transforms(&example.transforms);
        if skin_lbs(&rest.positions, &model.rig.skin, &palette, &mut posed).is_ok() {
            for p in posed.iter().filter(|p| p.is_finite()) {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
    }
    (lo, hi)
}

/// Errors loading the model directory.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    /// The directory could not be read.
    #[error("model directory {path}: {source}")]
    Io {
        /// The directory.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// A model file is invalid.
    #[error("model {path}: {source}")]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: crease_core::model::ModelError,
    },
}

/// The hosted models, by name. Models can be added while the server runs (a cluster replica
/// fetches the models of rooms it relays or adopts), so the map sits behind a lock; lookups
/// hand out `Arc`s.
#[derive(Debug, Default)]
pub struct ModelRegistry {
    models: RwLock<BTreeMap<String, Arc<LoadedModel>>>,
    /// Mirrored variants (issue 38: a left-hand actor on a right-hand model), built on first
    /// need and kept while their model is: by model name and plane. Not listed.
    mirrored: RwLock<HashMap<(String, String), Arc<LoadedModel>>>,
}

/// SHA-256 of `bytes`, lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

impl ModelRegistry {
    /// Loads every `*.crease` file of `dir` (not recursive), in name order.
    pub fn load_dir(dir: &Path) -> Result<Self, RegistryError> {
        let io = |source| RegistryError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "crease") && p.is_file())
            .collect();
        paths.sort();
        let registry = Self::default();
        for path in paths {
            let model = TrainedModel::load(&path).map_err(|source| RegistryError::Model {
                path: path.clone(),
                source,
            })?;
            let name = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            registry.insert(&name, model);
        }
        Ok(registry)
    }

    /// Adds (or replaces) a model under `name` (and forgets its mirrored variants).
    pub fn insert(&self, name: &str, model: TrainedModel) -> Arc<LoadedModel> {
        let loaded = Self::loaded(name, model);
        self.write().insert(name.to_owned(), Arc::clone(&loaded));
        (self.mirrored.write().unwrap_or_else(|e| e.into_inner()))
            .retain(|(model, _), _| model != name);
        loaded
    }

    /// Forgets model `name` (and its mirrored variants); rooms holding it keep their copy.
    pub fn remove(&self, name: &str) -> Option<Arc<LoadedModel>> {
        (self.mirrored.write().unwrap_or_else(|e| e.into_inner()))
            .retain(|(model, _), _| model != name);
        self.write().remove(name)
    }

    /// The model named `name` mirrored across `plane` (`TrainedModel::mirrored`), built on the
    /// first call and shared after. Named `name~mirror-PLANE` in its `ModelInfo` and streams;
    /// never listed. Blocking (a copy of the model, and its detail layer's subdivision): call
    /// it on the blocking pool.
    ///
    /// # Errors
    /// `None` inside when there is no such model; the mirror's [`ModelError`] otherwise.
    pub fn mirrored(
        &self,
        name: &str,
        plane: &MirrorPlane,
    ) -> Option<Result<Arc<LoadedModel>, ModelError>> {
        let key = (name.to_owned(), plane.to_string());
        let cached = (self.mirrored.read().unwrap_or_else(|e| e.into_inner()))
            .get(&key)
            .cloned();
        if let Some(m) = cached {
            return Some(Ok(m));
        }
        let original = self.get(name)?;
        let model = match original.model.mirrored(plane) {
            Ok(m) => m,
            Err(e) => return Some(Err(e)),
        };
        let loaded = Self::loaded(&format!("{name}~mirror-{plane}"), model);
        let mut map = self.mirrored.write().unwrap_or_else(|e| e.into_inner());
        // Two first calls at once: both built it, the first one in is shared.
        Some(Ok(Arc::clone(map.entry(key).or_insert(loaded))))
    }

    fn loaded(name: &str, model: TrainedModel) -> Arc<LoadedModel> {
        Arc::new(LoadedModel {
            name: name.to_owned(),
            info: model_info(name, &model),
            pose_bounds: pose_bounds(&model),
            sha256: OnceLock::new(),
            spatial: OnceLock::new(),
            detail_spatial: OnceLock::new(),
            palette: [OnceLock::new(), OnceLock::new()],
            model: Arc::new(model),
        })
    }

    fn write(&self) -> std::sync::RwLockWriteGuard<'_, BTreeMap<String, Arc<LoadedModel>>> {
        self.models.write().unwrap_or_else(|e| e.into_inner())
    }

    fn read(&self) -> std::sync::RwLockReadGuard<'_, BTreeMap<String, Arc<LoadedModel>>> {
        self.models.read().unwrap_or_else(|e| e.into_inner())
    }

    /// The model named `name`.
    pub fn get(&self, name: &str) -> Option<Arc<LoadedModel>> {
        self.read().get(name).cloned()
    }

    /// Every model, in name order.
    pub fn list(&self) -> Vec<Arc<LoadedModel>> {
        self.read().values().cloned().collect()
    }

    /// Number of models.
    pub fn len(&self) -> usize {
        self.read().len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.read().is_empty()
    }
}
