//! Opening a cluster's room here: a room a replica touches (a viewer, a publisher, an
//! adoption) is opened locally as a full room whose fan-out is its [`RoomLink`], from the
//! registry's entry (`RoomSpec::from_entry`) and through the server's one way of opening a
//! room ([`Host::open_relay`]), its model fetched from the cluster if this replica lacks it.
//! A room whose model cannot be had here is refused, and not tried again for
//! [`REFUSAL_BACKOFF`].

use std::sync::Arc;
use std::time::{Duration, Instant};

use crease_proto::room::RoomSpec;
use crease_proto::v1;

use super::{Cluster, Host, LinkFrames, LookupError, RoomLink, lock, models};
use crate::fanout::Channel;
use crate::registry::{LoadedModel, ModelRegistry};
use crate::room::Room;

/// How long a room whose model could not be had is left alone before trying again.
pub const REFUSAL_BACKOFF: Duration = Duration::from_secs(5);

impl Cluster {
    /// Room `id` as a local room: `host`'s open one, or (when the registry has it) a relay of
    /// it opened now, its model fetched from the cluster if this replica lacks it.
    ///
    /// # Errors
    /// [`LookupError::NoRoom`] when the cluster has no such room; [`LookupError::Unavailable`]
    /// when its model cannot be had here (absent, or failing its checksum).
    pub async fn local_room(
        self: Arc<Self>,
        host: Arc<dyn Host>,
        id: &str,
    ) -> Result<Arc<Room>, LookupError> {
        if let Some(room) = host.room(id) {
            return Ok(room);
        }
        let _opening = self.opening.lock().await;
        if let Some(room) = host.room(id) {
            return Ok(room);
        }
        let known = self
            .known(id)
            .ok_or_else(|| LookupError::NoRoom(id.to_owned()))?;
        if let Some((why, at)) = lock(&self.refused).get(id)
            && at.elapsed() < REFUSAL_BACKOFF
        {
            return Err(LookupError::Unavailable(why.clone()));
        }
        let spec = RoomSpec::from_entry(id, &known.entry, known.revision)
            .map_err(|e| LookupError::Internal(format!("room {id:?}: the registry's {e}")))?;
        let opened = host.open_relay(spec).await;
        match &opened {
            Ok(_) => tracing::info!(room = %id, owner = %known.entry.owner, "relaying room"),
            Err(LookupError::Unavailable(why)) => {
                lock(&self.refused).insert(id.to_owned(), (why.clone(), Instant::now()));
            }
            Err(_) => {}
        }
        opened
    }

    /// The model `name` with digest `sha256` for a relay: `models`' own, or fetched from the
    /// cluster's store, checked and loaded into `models`.
    ///
    /// # Errors
    /// Why this replica cannot use it ([`models`]).
    pub async fn ensure_model(
        &self,
        models: &ModelRegistry,
        name: &str,
        sha256: &str,
    ) -> Result<Arc<LoadedModel>, String> {
        models::ensure(models, self, name, sha256).await
    }

    /// The model `name` for a room opened here: `models`' own, or (issue 39: uploaded to
    /// another replica) the cluster store's copy of that name, checked against the digest
    /// the store holds for it and loaded into `models`; `None` when neither has it.
    ///
    /// # Errors
    /// A copy this replica cannot use ([`models`]).
    pub async fn named_model(
        &self,
        models: &ModelRegistry,
        name: &str,
    ) -> Result<Option<Arc<LoadedModel>>, String> {
        models::named(models, self, name).await
    }

    /// The cluster side of room `id` on `models` (one per actor), which becomes the room's fan-out: as
    /// `owner` or relay, at registry `revision` with `entry` (a new room's is written whole by
    /// [`Cluster::register`]). [`Cluster::attach`] starts it once the room is in the server's
    /// table.
    pub fn new_link(
        self: &Arc<Self>,
        id: &str,
        models: &[&LoadedModel],
        entry: v1::RoomEntry,
        owner: bool,
        revision: u64,
    ) -> (Arc<RoomLink>, LinkFrames) {
        let vertices: Vec<[usize; Channel::COUNT]> = models
            .iter()
            .map(|m| Channel::ALL.map(|c| crate::pipeline::frame_vertices(&m.model, c)))
            .collect();
        RoomLink::new(self, id, &vertices, entry, owner, revision)
    }

    /// Starts the cluster side of `room`, now in `host`'s table.
    pub fn attach(&self, host: Arc<dyn Host>, room: &Room, link: Arc<RoomLink>, rx: LinkFrames) {
        lock(&self.links).insert(room.id.clone(), Arc::clone(&link));
        link.start(&host, rx);
    }

    /// Removes room `id` from this replica (closed in the cluster), and stops its link.
    pub(super) fn close_local(&self, host: &dyn Host, id: &str) {
        host.close_local(id);
        if let Some(link) = lock(&self.links).remove(id) {
            link.shutdown();
        }
    }
}
