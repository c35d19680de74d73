//! Leases and failover: the owner renews its rooms' entries (a compare-and-set on the
//! revision) every quarter lease; a replica that sees no new revision of a room for a whole
//! lease, and has (or can fetch) its model, adopts it by a compare-and-set from the revision
//! it saw, so exactly one wins. A replica back from a partition renews before it publishes
//! again; if another adopted its room meanwhile, the renewal fails and it yields.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use async_nats::jetstream::kv;
use crease_proto::v1;
use prost::Message as _;

use super::registry::{Known, now_unix_ms};
use super::{Cluster, Host, RoomLink, lock};

impl Cluster {
    /// Renews this replica's leases, and adopts rooms whose owner went silent for a lease.
    pub(super) async fn keep_leases(self: Arc<Self>, host: Arc<dyn Host>) {
        let mut tick = tokio::time::interval(self.lease / 8);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut renewed: BTreeMap<String, Instant> = BTreeMap::new();
        loop {
            tick.tick().await;
            if !self.is_connected() {
                continue;
            }
            let local = self.links();
            for link in local.iter().filter(|l| l.is_owner()) {
                let due = renewed
                    .get(link.room())
                    .is_none_or(|t| t.elapsed() >= self.lease / 4);
                if due || !link.is_confirmed() {
                    renewed.insert(link.room().to_owned(), Instant::now());
                    self.renew(link).await;
                }
            }
            renewed.retain(|id, _| local.iter().any(|l| l.room() == id));
            if lock(&self.connected_at).elapsed() < self.lease {
                continue;
            }
            // Silent for a whole lease and not owned here (a replica restarted under the same
            // id reclaims what it owned before).
            let owned_here = |id: &str| local.iter().any(|l| l.room() == id && l.is_owner());
            let expired: Vec<(String, Known)> = lock(&self.directory)
                .iter()
                .filter(|(id, k)| k.seen.elapsed() >= self.lease && !owned_here(id))
                .map(|(id, k)| (id.clone(), k.clone()))
                .collect();
            for (id, known) in expired {
                self.adopt(&host, &id, known).await;
            }
        }
    }

    /// Renews `link`'s lease: a compare-and-set on the revision this replica last wrote. A
    /// failed compare means another replica adopted the room: this one yields.
    async fn renew(&self, link: &Arc<RoomLink>) {
        let (mut entry, revision) = link.entry();
        entry.renewed_unix_ms = now_unix_ms();
        self.seal(link.room(), &mut entry);
        match self
            .rooms_kv
            .update(link.room(), entry.encode_to_vec().into(), revision)
            .await
        {
            Ok(rev) => {
                link.set_entry(entry, rev);
                link.set_confirmed(true);
                link.renewed();
            }
            Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => {
                // Written over by something that cannot seal it (with a cluster key): the
                // lease is still this replica's; it writes its own entry back over the forgery.
                if let Some(forged) = self.forged_revision(link.room()).await {
                    match self
                        .rooms_kv
                        .update(link.room(), entry.encode_to_vec().into(), forged)
                        .await
                    {
                        Ok(rev) => {
                            tracing::warn!(room = %link.room(), "an unsealed entry overwrote this replica's: written back");
                            link.set_entry(entry, rev);
                            link.set_confirmed(true);
                            link.renewed();
                        }
                        Err(e) => {
                            tracing::debug!(room = %link.room(), "lease renewal over a forgery: {e}")
                        }
                    }
                    return;
                }
                tracing::warn!(room = %link.room(), "lease lost: {e}");
                link.yield_ownership();
            }
            Err(e) => tracing::debug!(room = %link.room(), "lease renewal: {e}"),
        }
    }

    /// The revision of room `id`'s current entry when it is one this replica does not believe
    /// (no or a bad seal, with a cluster key): a forgery to write over. None otherwise.
    async fn forged_revision(&self, id: &str) -> Option<u64> {
        self.key.as_ref()?;
        let current = self.rooms_kv.entry(id).await.ok()??;
        if current.operation != kv::Operation::Put {
            return None;
        }
        match v1::RoomEntry::decode(current.value.as_ref()) {
            Ok(entry) if self.believed(id, &entry) => None,
            _ => Some(current.revision),
        }
    }

    /// Adopts room `id`, whose owner was silent for a lease, if this replica has or can fetch
    /// its model: a compare-and-set from the revision seen, so that one replica wins.
    async fn adopt(self: &Arc<Self>, host: &Arc<dyn Host>, id: &str, known: Known) {
        if let Err(e) = Arc::clone(self).local_room(Arc::clone(host), id).await {
            tracing::debug!(room = %id, "cannot adopt: {e}");
            return;
        }
        let Some(link) = self.link(id) else {
            return;
        };
        let mut entry = known.entry.clone();
        let previous = std::mem::replace(&mut entry.owner, self.replica.clone());
        entry.adoptions += 1;
        // A new ownership epoch (entries before issue 40 have none: 0 counts as 1).
        entry.epoch = entry.epoch.max(1) + 1;
        entry.renewed_unix_ms = now_unix_ms();
        self.seal(id, &mut entry);
        let silent = known.seen.elapsed();
        let mut result = self
            .rooms_kv
            .update(id, entry.encode_to_vec().into(), known.revision)
            .await;
        // An unsealed entry on top of the last believed one (with a cluster key) does not hold
        // the room: adopt over it.
        if result
            .as_ref()
            .is_err_and(|e| e.kind() == kv::UpdateErrorKind::WrongLastRevision)
            && let Some(forged) = self.forged_revision(id).await
        {
            result = self
                .rooms_kv
                .update(id, entry.encode_to_vec().into(), forged)
                .await;
        }
        match result {
            Ok(revision) => {
                self.note(id, entry.clone(), revision);
                link.become_owner(host, entry, revision);
                self.metrics.adoptions.inc();
                tracing::warn!(room = %id, from = %previous, silent_ms = silent.as_millis() as u64, "adopted room");
            }
            Err(e) => tracing::debug!(room = %id, "adoption lost: {e}"),
        }
    }
}
