//! The cluster's room registry: the JetStream key-value bucket `crease-rooms` (room id -> its
//! `RoomEntry`), this replica's view of it ([`Known`], followed by a watch), registering a
//! room this replica opens, and closing a room in the whole cluster.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use async_nats::jetstream::{self, kv};
use crease_proto::cluster::{EntryParts, actor_entry, room_entry};
use crease_proto::v1;
use futures_util::StreamExt;
use prost::Message as _;

use super::{Cluster, ClusterError, Host, ROOMS_BUCKET, RegistryError, RoomLink, lock};
use crate::pipeline::StreamSettings;
use crate::room::Room;

/// What the registry says of a room, as this replica's watch last saw it.
#[derive(Clone, Debug)]
pub struct Known {
    /// The entry.
    pub entry: v1::RoomEntry,
    /// Its revision.
    pub revision: u64,
    /// When this replica saw that revision (leases go by this clock, not the owner's).
    pub(super) seen: Instant,
}

/// The registry's bucket, made if it is not there yet.
pub(super) async fn open_kv(js: &jetstream::Context) -> Result<kv::Store, ClusterError> {
    if let Ok(store) = js.get_key_value(ROOMS_BUCKET).await {
        return Ok(store);
    }
    // The bucket's stream, as `create_key_value` would make it (history 1). Made directly:
    // `create_key_value` first reads the account's info, which async-nats 0.51 cannot parse
    // from nats-server 2.9 (Debian's), while the stream calls work with both.
    let created = js
        .create_stream(jetstream::stream::Config {
            name: format!("KV_{ROOMS_BUCKET}"),
            description: Some("crease rooms: id -> RoomEntry (crease.v1, cluster.proto)".into()),
            subjects: vec![format!("$KV.{ROOMS_BUCKET}.>")],
            max_messages_per_subject: 1,
            allow_rollup: true,
            deny_delete: true,
            allow_direct: true,
            discard: jetstream::stream::DiscardPolicy::New,
            num_replicas: 1,
            ..Default::default()
        })
        .await;
    let created = created.map_err(|e| e.to_string());
    // Made here, or by another replica at the same time.
    js.get_key_value(ROOMS_BUCKET)
        .await
        .map_err(|e| ClusterError::Bucket {
            bucket: ROOMS_BUCKET,
            message: created.err().unwrap_or_else(|| e.to_string()),
        })
}

/// Now, milliseconds since the Unix epoch (an entry's `renewed_unix_ms`: for people).
pub(super) fn now_unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

impl Cluster {
    /// The cluster's rooms as this replica's registry watch sees them, by id.
    pub fn rooms(&self) -> BTreeMap<String, Known> {
        lock(&self.directory).clone()
    }

    /// What the registry says of room `id`.
    pub fn known(&self, id: &str) -> Option<Known> {
        lock(&self.directory).get(id).cloned()
    }

    /// The replica that owns room `id`, as the registry says.
    pub fn owner_of(&self, id: &str) -> Option<String> {
        lock(&self.directory).get(id).map(|k| k.entry.owner.clone())
    }

    pub(super) fn note(&self, id: &str, entry: v1::RoomEntry, revision: u64) {
        lock(&self.directory).insert(
            id.to_owned(),
            Known {
                entry,
                revision,
                seen: Instant::now(),
            },
        );
    }

    /// Registers `room`, just built here with `link` as its fan-out, as the cluster's, owned
    /// by this replica: the compare-and-set create makes the id the cluster's (a room of that
    /// id anywhere is [`RegistryError::Exists`]).
    ///
    /// # Errors
    /// [`RegistryError`]: the id taken, NATS unavailable.
    pub async fn register(
        &self,
        room: &Room,
        stream: StreamSettings,
        link: &RoomLink,
    ) -> Result<(), RegistryError> {
        let id = room.id.as_str();
        let actors: Vec<v1::ActorEntry> = room
            .actors()
            .iter()
            .filter_map(|a| {
                let p = a.pipeline();
                let mut actor = a.spec()?.running(p.beta(), p.skinning());
                // Another replica has no maps folder: the map goes in resolved.
                actor.retarget = p.capture().map(|c| c.resolved().clone());
                Some(actor_entry(actor, a.source().sha256()))
            })
            .collect();
        let mut entry = room_entry(EntryParts {
            settings: room.settings_parts(true),
            model_sha256: room.model.sha256(),
            owner: &self.replica,
            token_sha256: room.session().token_sha256(),
            stream,
            lease_ms: self.lease.as_millis() as u32,
            renewed_unix_ms: now_unix_ms(),
            actors: &actors,
        });
        self.seal(id, &mut entry);
        let revision = self
            .rooms_kv
            .create(id, entry.encode_to_vec().into())
            .await
            .map_err(|e| match e.kind() {
                kv::CreateErrorKind::AlreadyExists => RegistryError::Exists(id.to_owned()),
                _ => RegistryError::Unavailable(e.to_string()),
            })?;
        link.set_entry(entry.clone(), revision);
        self.note(id, entry, revision);
        Ok(())
    }

    /// Closes room `id` in the whole cluster (every replica's watch then closes it locally);
    /// `here`: whether `host` has a room of that id.
    ///
    /// # Errors
    /// [`RegistryError::NotFound`], or [`RegistryError::Unavailable`] when the registry cannot
    /// be written.
    pub async fn close_room(
        &self,
        host: Arc<dyn Host>,
        id: &str,
        here: bool,
    ) -> Result<(), RegistryError> {
        if self.known(id).is_none() && !here {
            return Err(RegistryError::NotFound(id.to_owned()));
        }
        self.rooms_kv
            .delete(id)
            .await
            .map_err(|e| RegistryError::Unavailable(e.to_string()))?;
        lock(&self.directory).remove(id);
        self.close_local(host.as_ref(), id);
        Ok(())
    }

    /// Follows the registry into [`Cluster::rooms`]: new rooms, renewals, new owners (a local
    /// owner that sees another owner yields), closed rooms (closed here too). The watch is
    /// re-made if it ends.
    pub(super) async fn watch_registry(self: Arc<Self>, host: Arc<dyn Host>) {
        loop {
            match self.rooms_kv.watch_with_history(">").await {
                Ok(mut watch) => {
                    while let Some(entry) = watch.next().await {
                        match entry {
                            Ok(entry) => self.apply(&host, entry),
                            Err(e) => {
                                tracing::warn!("registry watch: {e}");
                                break;
                            }
                        }
                    }
                }
                Err(e) => tracing::warn!("registry watch: {e}"),
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
    }

    fn apply(&self, host: &Arc<dyn Host>, e: kv::Entry) {
        match e.operation {
            kv::Operation::Put => {
                let Ok(entry) = v1::RoomEntry::decode(e.value.as_ref()) else {
                    tracing::warn!(room = %e.key, "registry: not a RoomEntry, ignored");
                    return;
                };
                if !self.believed(&e.key, &entry) {
                    self.metrics.refused_entries.inc();
                    tracing::warn!(room = %e.key, owner = %entry.owner, revision = e.revision, "registry: an entry without the cluster key's seal, ignored");
                    return;
                }
                if let Some(link) = self.link(&e.key) {
                    let (_, mine) = link.entry();
                    if e.revision >= mine {
                        if link.is_owner() && entry.owner != self.replica {
                            link.yield_ownership();
                        }
                        link.set_entry(entry.clone(), e.revision);
                    }
                }
                self.note(&e.key, entry, e.revision);
            }
            kv::Operation::Delete | kv::Operation::Purge => {
                lock(&self.directory).remove(&e.key);
                self.close_local(host.as_ref(), &e.key);
            }
        }
    }
}
