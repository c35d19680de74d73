//! The model file and what it stores.
//!
//! Layout:
//! - [`file`](mod@file): the container every model kind is stored in: magic, format version,
//!   kind, a checksummed section table, checksummed sections, atomic writes. Byte layout in its
//!   docs.
//! - [`rig`]: [`Rig`], a rest mesh with proxy bones, skin weights and one set of bone transforms
//!   per example pose; saved as container kind 1.
//! - [`trained`]: [`TrainedModel`], a rig plus control points, rotation regressors and edge
//!   weights: what `crease train` writes and the predictor loads; container kind 2.
//! - [`gltf_export`]: [`export_rig_glb`], a rig as a skinned, animated glTF 2.0 binary for any
//!   viewer.
//! - [`mirror`]: [`TrainedModel::mirrored`], a model reflected across a plane through the
//!   origin (a left hand from a right-hand model, issue 38).

use std::io;
use std::path::PathBuf;

use crate::runtime::skin::SkinError;

pub mod file;
pub mod gltf_export;
pub mod mirror;
pub mod rig;
pub mod trained;

pub use file::{FormatError, ModelKind};
pub use gltf_export::export_rig_glb;
pub use mirror::{MirrorPlane, MirrorPlaneError, mirror_name};
pub use rig::{Rig, RigExample};
pub use trained::{ControlPoint, DetailLayer, TrainedModel};

/// Errors from loading, saving, validating or exporting models.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// Reading or writing the file failed.
    // The OS error is in the message and not also the `source()`: an error chain printed
    // whole (`{:#}`) would say it twice.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: io::Error,
    },
    /// The bytes are not a valid container of the expected kind.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The skin weights are malformed or name bones that do not exist.
    #[error("skin weights: {0}")]
    Skin(#[from] SkinError),
    /// The model's parts disagree with each other or hold non-finite values.
    #[error("invalid rig: {0}")]
    InvalidRig(String),
    /// An example index beyond the rig's examples.
    #[error("example {index} requested, the rig has {count}")]
    NoSuchExample {
        /// The requested index.
        index: usize,
        /// Number of examples.
        count: usize,
    },
    /// The model cannot be expressed in the export format.
    #[error("glTF export: {0}")]
    Export(String),
}

/// Writes serialised model bytes to `path` atomically, naming the path on error.
pub(crate) fn save_bytes(path: &std::path::Path, bytes: &[u8]) -> Result<(), ModelError> {
    file::write_atomic(path, bytes).map_err(|error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// Reads a model file's bytes, naming the path on error.
pub(crate) fn read_bytes(path: &std::path::Path) -> Result<Vec<u8>, ModelError> {
    std::fs::read(path).map_err(|error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    })
}
