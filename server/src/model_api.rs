//! Models through the API (issue 39): `UploadModel`, `DeleteModel` and the cluster's models in
//! `ListModels`, so a model reaches a running server (and, in a cluster, every replica)
//! without a restart or a shared folder.
//!
//! **Upload.** The first chunk names the model and declares the file's size and SHA-256; the
//! chunks are gathered in memory up to the declared size (which the server caps,
//! `Limits::model_bytes`), then, on the blocking pool, hashed, parsed and checked as a model
//! file (`TrainedModel::from_bytes`: format, version, every array's size), written to a
//! temporary file beside its final place, flushed and renamed onto `NAME.crease`: a reader of
//! the folder sees the whole file or none. Whatever fails (a stream cut short, more bytes than
//! declared, another digest, not a model, a name taken by another model) is refused naming
//! why, and leaves no file. An upload of a model the server has with the same digest is
//! answered as a success without writing. The model is then in the registry (rooms can open
//! on it at once) and, in a cluster, offered to the object store, where other replicas fetch
//! it when a room on it comes their way (`crate::cluster::models`).
//!
//! **Delete.** Removes the model's file and its registry entry; refused while a room of this
//! server runs an actor on it (mirrored or not), and for models not from the folder (the
//! embedded demo's). The cluster's copy stays: rooms on other replicas may need it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crease_core::model::TrainedModel;
use crease_proto::v1;
use futures_util::{Stream, StreamExt};

use crate::registry::{LoadedModel, sha256_hex};
use crate::state::AppState;

/// Why a model operation was refused; `crate::status` says what each becomes on the wire.
#[derive(Debug, thiserror::Error)]
pub enum ModelOpError {
    /// The server was started without a models folder.
    #[error(
        "this server has no models folder (crease-server --models DIR): uploaded models have nowhere to go"
    )]
    NoFolder,
    /// The upload sent no chunk, or its first chunk lacks the name.
    #[error("ModelChunk.name: the first chunk must name the model and give its size and SHA-256")]
    NoName,
    /// Not a model name.
    #[error(
        "ModelChunk.name: {0:?} is not a model name (1-64 characters of A-Z, a-z, 0-9, _ and -)"
    )]
    BadName(String),
    /// Not a SHA-256 in hex.
    #[error("ModelChunk.sha256: {0:?} is not a SHA-256 (64 hex digits)")]
    BadDigest(String),
    /// Over the server's cap.
    #[error("ModelChunk.size: {size} bytes, over this server's cap of {cap} bytes")]
    TooLarge {
        /// The declared size.
        size: u64,
        /// The cap.
        cap: u64,
    },
    /// More bytes than declared.
    #[error("ModelChunk.data: more than the {size} bytes the first chunk declared")]
    TooLong {
        /// The declared size.
        size: u64,
    },
    /// The stream ended early.
    #[error(
        "model {name:?}: the upload ended after {got} of {size} bytes: truncated, nothing written"
    )]
    Truncated {
        /// The model.
        name: String,
        /// Bytes received.
        got: u64,
        /// Bytes declared.
        size: u64,
    },
    /// The bytes are not what was declared.
    #[error(
        "model {name:?}: the bytes have SHA-256 {got}, the upload declared {want}: refused, nothing written"
    )]
    Digest {
        /// The model.
        name: String,
        /// The bytes' digest.
        got: String,
        /// The declared one.
        want: String,
    },
    /// The bytes are not a model file.
    #[error("model {name:?}: not a crease model file: {reason}; nothing written")]
    NotAModel {
        /// The model.
        name: String,
        /// What the reader said.
        reason: String,
    },
    /// Another model of that name.
    #[error("model {name:?} exists with SHA-256 {has}: delete it first (crease model delete)")]
    Exists {
        /// The model.
        name: String,
        /// The digest of the one the server has.
        has: String,
    },
    /// No such model.
    #[error("model: no model {0:?}")]
    NoModel(String),
    /// Not from the folder.
    #[error(
        "model {0:?} is not a file of this server's models folder (the embedded demo's?): not deleted"
    )]
    NotInFolder(String),
    /// A room runs it.
    #[error("model {name:?} is in use by room{} {}: close {} first", if rooms.len() > 1 { "s" } else { "" }, rooms.join(", "), if rooms.len() > 1 { "them" } else { "it" })]
    InUse {
        /// The model.
        name: String,
        /// The rooms.
        rooms: Vec<String>,
    },
    /// The upload stream failed.
    #[error("the upload stream failed: {0}")]
    Stream(String),
    /// The folder could not be written.
    #[error("model {name:?}: {what} {}: {source}", path.display())]
    Io {
        /// The model.
        name: String,
        /// What was being done.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// Whether `name` is a model name: 1-64 characters of `[A-Za-z0-9_-]`.
fn valid_name(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// Receives an upload (module docs) and returns the model as loaded.
///
/// # Errors
/// [`ModelOpError`]: what was wrong with the upload, or the folder.
pub async fn upload<E: std::fmt::Display>(
    state: &Arc<AppState>,
    mut chunks: impl Stream<Item = Result<v1::ModelChunk, E>> + Unpin,
) -> Result<Arc<LoadedModel>, ModelOpError> {
    let folder = state
        .config()
        .models_dir
        .clone()
        .ok_or(ModelOpError::NoFolder)?;
    let stream_error = |e: E| ModelOpError::Stream(e.to_string());
    let first = chunks
        .next()
        .await
        .ok_or(ModelOpError::NoName)?
        .map_err(stream_error)?;
    if first.name.is_empty() {
        return Err(ModelOpError::NoName);
    }
    let name = first.name.clone();
    if !valid_name(&name) {
        return Err(ModelOpError::BadName(name));
    }
    let want = first.sha256.to_ascii_lowercase();
    if want.len() != 64 || !want.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(ModelOpError::BadDigest(first.sha256));
    }
    let (size, cap) = (first.size, state.config().limits.model_bytes);
    if size > cap {
        return Err(ModelOpError::TooLarge { size, cap });
    }
    if let Some(has) = state.models().get(&name)
        && has.sha256() != want
    {
        return Err(ModelOpError::Exists {
            name,
            has: has.sha256().to_owned(),
        });
    }
    // The declared size is capped: gathering up to it in memory is bounded.
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    let mut chunk = Some(first);
    loop {
        if let Some(c) = chunk.take() {
            if (bytes.len() + c.data.len()) as u64 > size {
                return Err(ModelOpError::TooLong { size });
            }
            bytes.extend_from_slice(&c.data);
        }
        match chunks.next().await {
            Some(c) => chunk = Some(c.map_err(stream_error)?),
            None => break,
        }
    }
    if (bytes.len() as u64) < size {
        return Err(ModelOpError::Truncated {
            name,
            got: bytes.len() as u64,
            size,
        });
    }
    if let Some(has) = state.models().get(&name) {
        // The same model again (the digest matched above): nothing to write.
        return Ok(has);
    }
    let (model, bytes) = tokio::task::spawn_blocking({
        let name = name.clone();
        move || store(&folder, &name, &want, bytes)
    })
    .await
    .map_err(|e| ModelOpError::Stream(format!("the upload's check failed: {e}")))??;
    let loaded = state.models().insert(&name, model);
    loaded.set_sha256_of(&bytes);
    tracing::info!(model = %name, bytes = bytes.len(), "model uploaded");
    if let Some(cluster) = state.cluster() {
        crate::cluster::models::offer(Arc::clone(cluster), vec![(Arc::clone(&loaded), bytes)])
            .await;
    }
    Ok(loaded)
}

/// Checks `bytes` against `want` and as a model file, then writes them to `folder/NAME.crease`
/// through a temporary file and a rename (blocking). Nothing is left behind on an error.
fn store(
    folder: &Path,
    name: &str,
    want: &str,
    bytes: Vec<u8>,
) -> Result<(TrainedModel, Vec<u8>), ModelOpError> {
    let got = sha256_hex(&bytes);
    if got != want {
        return Err(ModelOpError::Digest {
            name: name.to_owned(),
            got,
            want: want.to_owned(),
        });
    }
    let model = TrainedModel::from_bytes(&bytes).map_err(|e| ModelOpError::NotAModel {
        name: name.to_owned(),
        reason: e.to_string(),
    })?;
    let path = folder.join(format!("{name}.crease"));
    let partial = folder.join(format!(".{name}.crease.{}.upload", std::process::id()));
    let io = |what, path: &Path, source| ModelOpError::Io {
        name: name.to_owned(),
        what,
        path: path.to_path_buf(),
        source,
    };
    let written = (|| {
        use std::io::Write;
        let mut f = std::fs::File::create(&partial)?;
        f.write_all(&bytes)?;
        f.sync_all()
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&partial);
        return Err(io("writing", &partial, e));
    }
    if let Err(e) = std::fs::rename(&partial, &path) {
        let _ = std::fs::remove_file(&partial);
        return Err(io("renaming onto", &path, e));
    }
    Ok((model, bytes))
}

/// Deletes model `name` (module docs).
///
/// # Errors
/// [`ModelOpError`]: no folder, no such model, one not from the folder, one in use, or the
/// file not removable.
pub async fn delete(state: &Arc<AppState>, name: &str) -> Result<(), ModelOpError> {
    let folder = state
        .config()
        .models_dir
        .clone()
        .ok_or(ModelOpError::NoFolder)?;
    if !valid_name(name) || state.models().get(name).is_none() {
        return Err(ModelOpError::NoModel(name.to_owned()));
    }
    let path = folder.join(format!("{name}.crease"));
    if !path.is_file() {
        return Err(ModelOpError::NotInFolder(name.to_owned()));
    }
    let rooms = state.rooms_using(name);
    if !rooms.is_empty() {
        return Err(ModelOpError::InUse {
            name: name.to_owned(),
            rooms,
        });
    }
    tokio::fs::remove_file(&path)
        .await
        .map_err(|source| ModelOpError::Io {
            name: name.to_owned(),
            what: "removing",
            path,
            source,
        })?;
    state.models().remove(name);
    tracing::info!(model = %name, "model deleted");
    Ok(())
}

/// The cluster's models (its object store), if this server is in one: name, SHA-256, bytes.
pub async fn cluster_models(state: &Arc<AppState>) -> Vec<(String, String, u64)> {
    match state.cluster() {
        Some(cluster) => crate::cluster::models::stored(cluster).await,
        None => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked() {
        assert!(valid_name("hand_v2-left"));
        for bad in ["", "a/b", "../x", "hand.crease", &"x".repeat(65)] {
            assert!(!valid_name(bad), "{bad:?}");
        }
    }
}
