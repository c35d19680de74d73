//! Models across replicas: a replica can relay or adopt only rooms whose model it has. Every
//! replica offers its models to the cluster's object store (`crease-models`, the model's
//! SHA-256 in the object's metadata); one that lacks a room's model fetches it, checks the
//! digest against the room's registry entry, and loads it on the blocking pool. A model that
//! is absent, or whose copy fails its digest, is never used: the room is refused here (and so
//! never adopted here).

use std::collections::HashMap;
use std::sync::Arc;

use async_nats::jetstream;
use async_nats::jetstream::object_store::ObjectMetadata;
use crease_core::model::TrainedModel;
use tokio::io::AsyncReadExt;

use super::{Cluster, ClusterError, MODELS_BUCKET};
use crate::registry::{LoadedModel, ModelRegistry, sha256_hex};

/// The metadata key of an object's SHA-256.
const SHA256: &str = "sha256";

/// Serialises every local model once, on the blocking pool: sets its digest (so that nothing
/// on the async threads computes one) and returns the bytes to [`offer`].
pub(crate) async fn serialise_local(models: &ModelRegistry) -> Vec<(Arc<LoadedModel>, Vec<u8>)> {
    let models = models.list();
    let serialised = tokio::task::spawn_blocking(move || {
        models
            .into_iter()
            .filter_map(|m| match m.model.to_bytes() {
                Ok(bytes) => {
                    m.set_sha256_of(&bytes);
                    Some((m, bytes))
                }
                Err(e) => {
                    tracing::warn!(model = %m.name, "cannot serialise: {e}");
                    None
                }
            })
            .collect()
    })
    .await;
    serialised.unwrap_or_else(|e| {
        tracing::warn!("serialising the models: {e}");
        Vec::new()
    })
}

/// Offers every local model (`serialised`, from [`serialise_local`]) the store lacks (a model
/// of the same name with another digest is left alone, with a warning: rooms name models by
/// digest too).
pub(crate) async fn offer(cluster: Arc<Cluster>, serialised: Vec<(Arc<LoadedModel>, Vec<u8>)>) {
    for (model, bytes) in serialised {
        let store = &cluster.models_store;
        let ours = model.sha256();
        match store.info(&model.name).await {
            Ok(info) if info.metadata.get(SHA256).map(String::as_str) == Some(ours) => continue,
            Ok(info) => {
                tracing::warn!(
                    model = %model.name,
                    ours,
                    cluster = ?info.metadata.get(SHA256),
                    "the cluster's model of this name differs: not replaced"
                );
                continue;
            }
            Err(_) => {}
        }
        let meta = ObjectMetadata {
            name: model.name.clone(),
            description: Some(format!("crease model {}", model.info.method)),
            metadata: HashMap::from([(SHA256.to_owned(), ours.to_owned())]),
            ..Default::default()
        };
        match store.put(meta, &mut bytes.as_slice()).await {
            Ok(_) => {
                tracing::info!(model = %model.name, bytes = bytes.len(), "model offered to the cluster")
            }
            Err(e) => tracing::warn!(model = %model.name, "offering the model: {e}"),
        }
    }
}

/// The model `name` with digest `sha256`: the local one, or fetched from the cluster, checked
/// and loaded.
///
/// # Errors
/// What stops this replica from using it: a local model of that name with another digest, no
/// copy in the cluster, a copy failing its digest or not loading.
pub(crate) async fn ensure(
    models: &ModelRegistry,
    cluster: &Cluster,
    name: &str,
    sha256: &str,
) -> Result<Arc<LoadedModel>, String> {
    if let Some(model) = models.get(name) {
        return if model.sha256() == sha256 {
            Ok(model)
        } else {
            Err(format!(
                "model {name:?}: this replica's has SHA-256 {}, the room's is {sha256}",
                model.sha256()
            ))
        };
    }
    let mut object = cluster
        .models_store
        .get(name)
        .await
        .map_err(|e| format!("model {name:?}: not in the cluster's store ({e})"))?;
    let mut bytes = Vec::new();
    object
        .read_to_end(&mut bytes)
        .await
        .map_err(|e| format!("model {name:?}: reading the cluster's copy: {e}"))?;
    let got = sha256_hex(&bytes);
    if got != sha256 {
        return Err(format!(
            "model {name:?}: the cluster's copy has SHA-256 {got}, expected {sha256}: refused"
        ));
    }
    // The copy's bytes are the offering replica's `to_bytes`, so the digest read here is the
    // model's digest: inserted with it (no second serialisation).
    let model = tokio::task::spawn_blocking(move || TrainedModel::from_bytes(&bytes))
        .await
        .map_err(|e| format!("model {name:?}: loading: {e}"))?
        .map_err(|e| format!("model {name:?}: the cluster's copy: {e}"))?;
    let loaded = models.insert(name, model);
    loaded.set_sha256(got);
    tracing::info!(model = %name, "model fetched from the cluster");
    Ok(loaded)
}

/// The models' object store, made if it is not there yet.
pub(super) async fn open_object_store(
    js: &jetstream::Context,
) -> Result<jetstream::object_store::ObjectStore, ClusterError> {
    if let Ok(store) = js.get_object_store(MODELS_BUCKET).await {
        return Ok(store);
    }
    let created = js
        .create_object_store(jetstream::object_store::Config {
            bucket: MODELS_BUCKET.into(),
            description: Some(
                "crease models: name -> .crease file (sha256 in its metadata)".into(),
            ),
            ..Default::default()
        })
        .await;
    match created {
        Ok(store) => Ok(store),
        Err(e) => js
            .get_object_store(MODELS_BUCKET)
            .await
            .map_err(|_| ClusterError::Bucket {
                bucket: MODELS_BUCKET,
                message: e.to_string(),
            }),
    }
}

/// The model `name`: the local one, or the store's copy of that name, fetched as [`ensure`]
/// does against the digest in the store's metadata; `None` when neither has it.
///
/// # Errors
/// A copy without a digest, or [`ensure`]'s.
pub(crate) async fn named(
    models: &ModelRegistry,
    cluster: &Cluster,
    name: &str,
) -> Result<Option<Arc<LoadedModel>>, String> {
    if let Some(model) = models.get(name) {
        return Ok(Some(model));
    }
    let Ok(info) = cluster.models_store.info(name).await else {
        return Ok(None);
    };
    let sha256 = info
        .metadata
        .get(SHA256)
        .cloned()
        .ok_or_else(|| format!("model {name:?}: the cluster's copy has no SHA-256: refused"))?;
    ensure(models, cluster, name, &sha256).await.map(Some)
}

/// Every model of the cluster's object store: name, SHA-256 (from its metadata; empty when
/// missing) and size, by name. A store that cannot be listed lists nothing (logged).
pub(crate) async fn stored(cluster: &Cluster) -> Vec<(String, String, u64)> {
    use futures_util::StreamExt;
    let mut out = Vec::new();
    match cluster.models_store.list().await {
        Ok(mut list) => {
            while let Some(item) = list.next().await {
                match item {
                    Ok(info) if !info.deleted => out.push((
                        info.name.clone(),
                        info.metadata.get(SHA256).cloned().unwrap_or_default(),
                        info.size as u64,
                    )),
                    Ok(_) => {}
                    Err(e) => tracing::warn!("listing the cluster's models: {e}"),
                }
            }
        }
        Err(e) => tracing::warn!("listing the cluster's models: {e}"),
    }
    out.sort();
    out
}
