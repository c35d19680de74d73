//! A cluster that trusts only its own (issue 40): how a replica proves to NATS who it is
//! ([`NatsAuth`]: a credentials file, a user and password, TLS and mutual TLS), and how
//! replicas tell each other's messages from a forger's ([`ClusterKey`], an HMAC-SHA256 key all
//! replicas share, `--cluster-key-file`).
//!
//! With a key, every message a replica relies on carries a tag over what it says:
//!
//! - **Frames** (`crease.frames.<room>.<channel>`): the owner's id and its ownership *epoch*
//!   (the room entry's `epoch`: 1 at open, +1 per adoption) travel in NATS headers
//!   ([`OWNER`], [`EPOCH`], [`TAG`]), the tag over the subject, both and the payload. A relay
//!   drops (and counts) a frame with no tag or a bad one, and, key or not, a frame of an epoch
//!   older than one it has seen for the room (a paused owner that woke after it was adopted:
//!   [`EpochGate`]).
//! - **Forwarded controls and their acks** (`crease.control.<room>`): the request is tagged by
//!   the relay, the reply by the owner with its epoch; either side drops an untagged or
//!   forged one.
//! - **Room entries** (the registry's values): sealed ([`ClusterKey::seal_entry`]) over the
//!   room id and the entry; a replica ignores an entry whose seal does not hold, so a process
//!   that can write the bucket cannot hand a room to an owner of its choosing.
//!
//! Without a key the epochs still fence paused owners, but anything that can reach NATS can
//! speak for a replica: deploy/README.md says how to restrict NATS itself (accounts, TLS, and
//! subject permissions).

use std::path::{Path, PathBuf};

use async_nats::HeaderMap;
use crease_proto::v1;
use hmac::{Hmac, Mac};
use prost::Message as _;
use sha2::Sha256;

/// Header: the replica that sent a frame or an ack.
pub const OWNER: &str = "Crease-Owner";
/// Header: the sender's ownership epoch of the room.
pub const EPOCH: &str = "Crease-Epoch";
/// Header: the HMAC-SHA256 tag, hex.
pub const TAG: &str = "Crease-Tag";
/// Header: the relay that forwarded a control frame.
pub const RELAY: &str = "Crease-Relay";

/// The fewest bytes of key material a key file may hold.
pub const MIN_KEY_BYTES: usize = 32;

/// How a replica authenticates to NATS (all optional; async-nats' options underneath).
#[derive(Clone, Debug, Default)]
pub struct NatsAuth {
    /// A NATS credentials file (decentralised JWT + nkey seed, `nsc` makes them).
    pub creds: Option<PathBuf>,
    /// A user name; its password is [`NatsAuth::password`] or read from
    /// [`NatsAuth::password_file`].
    pub user: Option<String>,
    /// The password (from the environment, `CREASE_NATS_PASSWORD`: never a command line).
    pub password: Option<String>,
    /// A file holding the password (its first line).
    pub password_file: Option<PathBuf>,
    /// The CA that signed the NATS server's certificate (PEM); setting it requires TLS.
    pub tls_ca: Option<PathBuf>,
    /// This replica's client certificate and key (PEM) for mutual TLS.
    pub tls_client: Option<(PathBuf, PathBuf)>,
}

impl NatsAuth {
    /// `options` with this authentication applied.
    ///
    /// # Errors
    /// A credentials file that cannot be read or parsed, naming it.
    pub async fn apply(
        &self,
        mut options: async_nats::ConnectOptions,
    ) -> Result<async_nats::ConnectOptions, String> {
        if let Some(path) = &self.creds {
            options = options
                .credentials_file(path)
                .await
                .map_err(|e| format!("--nats-creds {}: {e}", path.display()))?;
        }
        if let Some(user) = &self.user {
            let password = match (&self.password, &self.password_file) {
                (_, Some(path)) => std::fs::read_to_string(path)
                    .map_err(|e| format!("--nats-password-file {}: {e}", path.display()))?
                    .lines()
                    .next()
                    .unwrap_or_default()
                    .to_owned(),
                (Some(p), None) => p.clone(),
                (None, None) => {
                    return Err(format!(
                        "--nats-user {user}: no password (set CREASE_NATS_PASSWORD or --nats-password-file)"
                    ));
                }
            };
            options = options.user_and_password(user.clone(), password);
        }
        if let Some(ca) = &self.tls_ca {
            options = options.add_root_certificates(ca.clone()).require_tls(true);
        }
        if let Some((cert, key)) = &self.tls_client {
            options = options
                .add_client_certificate(cert.clone(), key.clone())
                .require_tls(true);
        }
        Ok(options)
    }

    /// What the log may say about it (never a secret).
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if let Some(p) = &self.creds {
            parts.push(format!("credentials {}", p.display()));
        }
        if let Some(user) = &self.user {
            parts.push(format!("user {user}"));
        }
        if self.tls_client.is_some() {
            parts.push("mutual TLS".into());
        } else if self.tls_ca.is_some() {
            parts.push("TLS".into());
        }
        if parts.is_empty() {
            "no credentials".into()
        } else {
            parts.join(", ")
        }
    }
}

/// The cluster's shared HMAC-SHA256 key (module docs).
#[derive(Clone)]
pub struct ClusterKey {
    key: Vec<u8>,
}

impl std::fmt::Debug for ClusterKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ClusterKey(..)")
    }
}

/// Why a key file was refused.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// The file could not be read.
    #[error("cluster key {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Too little key material.
    #[error(
        "cluster key {path}: {got} bytes of key material, at least {MIN_KEY_BYTES} needed (e.g. `openssl rand -hex 32 > FILE`)"
    )]
    Short {
        /// The file.
        path: String,
        /// What it held.
        got: usize,
    },
}

impl ClusterKey {
    /// A key from its bytes.
    ///
    /// # Errors
    /// Fewer than [`MIN_KEY_BYTES`] bytes.
    pub fn new(key: &[u8]) -> Result<ClusterKey, KeyError> {
        if key.len() < MIN_KEY_BYTES {
            return Err(KeyError::Short {
                path: "(bytes)".into(),
                got: key.len(),
            });
        }
        Ok(ClusterKey { key: key.to_vec() })
    }

    /// The key in `path`: hex digits (surrounding whitespace ignored) or, failing that, the
    /// file's bytes as they are; at least [`MIN_KEY_BYTES`] bytes either way.
    ///
    /// # Errors
    /// [`KeyError`], naming the file.
    pub fn from_file(path: &Path) -> Result<ClusterKey, KeyError> {
        let bytes = std::fs::read(path).map_err(|source| KeyError::Read {
            path: path.display().to_string(),
            source,
        })?;
        let text = String::from_utf8_lossy(&bytes);
        let trimmed = text.trim();
        let key = hex_decode(trimmed).unwrap_or(bytes);
        if key.len() < MIN_KEY_BYTES {
            return Err(KeyError::Short {
                path: path.display().to_string(),
                got: key.len(),
            });
        }
        Ok(ClusterKey { key })
    }

    fn mac(&self, parts: &[&[u8]]) -> Hmac<Sha256> {
        #[allow(clippy::expect_used)] // HMAC takes a key of any length
        let mut mac = Hmac::<Sha256>::new_from_slice(&self.key).expect("any key length");
        // Each part length-prefixed: no two different lists of parts read the same.
        for p in parts {
            mac.update(&(p.len() as u64).to_le_bytes());
            mac.update(p);
        }
        mac
    }

    /// The tag of `parts`, hex.
    pub fn tag(&self, parts: &[&[u8]]) -> String {
        hex_encode(&self.mac(parts).finalize().into_bytes())
    }

    /// Whether `tag` (hex) is the tag of `parts` (compared in constant time).
    pub fn verify(&self, parts: &[&[u8]], tag: &str) -> bool {
        hex_decode(tag).is_some_and(|t| self.mac(parts).verify_slice(&t).is_ok())
    }

    /// Seals room `id`'s entry: its `tag` over the id and the entry (tag cleared).
    pub fn seal_entry(&self, id: &str, entry: &mut v1::RoomEntry) {
        entry.tag.clear();
        let bytes = entry.encode_to_vec();
        entry.tag = self
            .mac(&[b"entry", id.as_bytes(), &bytes])
            .finalize()
            .into_bytes()
            .to_vec();
    }

    /// Seals job `id`'s record (issue 45, `cluster::work`): its `tag` over the id and the
    /// record (tag cleared), as [`ClusterKey::seal_entry`] seals a room's entry.
    pub fn seal_job(&self, id: &str, record: &mut v1::JobRecord) {
        record.tag.clear();
        let bytes = record.encode_to_vec();
        record.tag = self
            .mac(&[b"job", id.as_bytes(), &bytes])
            .finalize()
            .into_bytes()
            .to_vec();
    }

    /// Whether job `id`'s record carries a seal of this key.
    pub fn check_job(&self, id: &str, record: &v1::JobRecord) -> bool {
        let mut unsealed = record.clone();
        let tag = std::mem::take(&mut unsealed.tag);
        let bytes = unsealed.encode_to_vec();
        self.mac(&[b"job", id.as_bytes(), &bytes])
            .verify_slice(&tag)
            .is_ok()
    }

    /// Whether room `id`'s entry carries a seal of this key.
    pub fn check_entry(&self, id: &str, entry: &v1::RoomEntry) -> bool {
        let mut unsealed = entry.clone();
        let tag = std::mem::take(&mut unsealed.tag);
        let bytes = unsealed.encode_to_vec();
        self.mac(&[b"entry", id.as_bytes(), &bytes])
            .verify_slice(&tag)
            .is_ok()
    }
}

/// Why a message from NATS was not believed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// No tag, or a tag that does not hold (with a key), or headers missing.
    Forged,
    /// An epoch older than one already seen for the room.
    Stale,
}

/// The headers of a frame the owner `owner` publishes on `subject` in ownership `epoch`.
pub fn frame_headers(
    key: Option<&ClusterKey>,
    subject: &str,
    owner: &str,
    epoch: u64,
    payload: &[u8],
) -> HeaderMap {
    owned_headers(b"frame", key, subject, owner, epoch, payload)
}

/// A frame's owner and epoch, if its headers hold (module docs): the tag, with a key.
///
/// # Errors
/// [`Refusal::Forged`].
pub fn check_frame(
    key: Option<&ClusterKey>,
    subject: &str,
    headers: Option<&HeaderMap>,
    payload: &[u8],
) -> Result<(String, u64), Refusal> {
    check_owned(b"frame", key, subject, headers, payload)
}

/// Owner and epoch headers, tagged (with a key) under `domain` (`frame`, `ack`): a tag made
/// for one kind of message never holds for another.
fn owned_headers(
    domain: &[u8],
    key: Option<&ClusterKey>,
    subject: &str,
    owner: &str,
    epoch: u64,
    payload: &[u8],
) -> HeaderMap {
    let mut h = HeaderMap::new();
    h.insert(OWNER, owner);
    h.insert(EPOCH, epoch.to_string().as_str());
    if let Some(key) = key {
        let e = epoch.to_le_bytes();
        h.insert(
            TAG,
            key.tag(&[domain, subject.as_bytes(), owner.as_bytes(), &e, payload])
                .as_str(),
        );
    }
    h
}

/// The owner and epoch of headers made by [`owned_headers`] under `domain`, if they hold.
fn check_owned(
    domain: &[u8],
    key: Option<&ClusterKey>,
    subject: &str,
    headers: Option<&HeaderMap>,
    payload: &[u8],
) -> Result<(String, u64), Refusal> {
    let h = headers.ok_or(Refusal::Forged)?;
    let owner = h
        .get(OWNER)
        .map(|v| v.as_str().to_owned())
        .ok_or(Refusal::Forged)?;
    let epoch: u64 = h
        .get(EPOCH)
        .and_then(|v| v.as_str().parse().ok())
        .ok_or(Refusal::Forged)?;
    if let Some(key) = key {
        let tag = h.get(TAG).map(|v| v.as_str()).ok_or(Refusal::Forged)?;
        let e = epoch.to_le_bytes();
        if !key.verify(
            &[domain, subject.as_bytes(), owner.as_bytes(), &e, payload],
            tag,
        ) {
            return Err(Refusal::Forged);
        }
    }
    Ok((owner, epoch))
}

/// The headers of a control frame relay `relay` forwards on `subject`.
pub fn control_headers(
    key: Option<&ClusterKey>,
    subject: &str,
    relay: &str,
    payload: &[u8],
) -> HeaderMap {
    let mut h = HeaderMap::new();
    h.insert(RELAY, relay);
    if let Some(key) = key {
        h.insert(
            TAG,
            key.tag(&[b"control", subject.as_bytes(), relay.as_bytes(), payload])
                .as_str(),
        );
    }
    h
}

/// Whether a forwarded control frame's headers hold (always, without a key).
pub fn check_control(
    key: Option<&ClusterKey>,
    subject: &str,
    headers: Option<&HeaderMap>,
    payload: &[u8],
) -> bool {
    let Some(key) = key else {
        return true;
    };
    let Some(h) = headers else {
        return false;
    };
    let (Some(relay), Some(tag)) = (h.get(RELAY), h.get(TAG)) else {
        return false;
    };
    key.verify(
        &[
            b"control",
            subject.as_bytes(),
            relay.as_str().as_bytes(),
            payload,
        ],
        tag.as_str(),
    )
}

/// The headers of the owner's ack to a control frame forwarded on `subject`.
pub fn ack_headers(
    key: Option<&ClusterKey>,
    subject: &str,
    owner: &str,
    epoch: u64,
    payload: &[u8],
) -> HeaderMap {
    owned_headers(b"ack", key, subject, owner, epoch, payload)
}

/// An ack's owner and epoch, if its headers hold.
///
/// # Errors
/// [`Refusal::Forged`].
pub fn check_ack(
    key: Option<&ClusterKey>,
    subject: &str,
    headers: Option<&HeaderMap>,
    payload: &[u8],
) -> Result<(String, u64), Refusal> {
    check_owned(b"ack", key, subject, headers, payload)
}

/// The newest ownership epoch a replica has seen of a room: from the registry and from frames
/// whose tag held. Frames of older epochs are refused ([`Refusal::Stale`]).
#[derive(Debug, Default)]
pub struct EpochGate {
    seen: std::sync::atomic::AtomicU64,
}

impl EpochGate {
    /// Notes `epoch` (from the registry or a believed frame).
    pub fn note(&self, epoch: u64) {
        self.seen
            .fetch_max(epoch, std::sync::atomic::Ordering::AcqRel);
    }

    /// Admits a frame of `epoch` (noting it) unless an older epoch than one seen.
    ///
    /// # Errors
    /// [`Refusal::Stale`].
    pub fn admit(&self, epoch: u64) -> Result<(), Refusal> {
        let seen = self
            .seen
            .fetch_max(epoch, std::sync::atomic::Ordering::AcqRel);
        if epoch < seen {
            Err(Refusal::Stale)
        } else {
            Ok(())
        }
    }

    /// The newest epoch seen.
    pub fn seen(&self) -> u64 {
        self.seen.load(std::sync::atomic::Ordering::Acquire)
    }
}

fn hex_encode(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    bytes
        .iter()
        .fold(String::with_capacity(2 * bytes.len()), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}

fn hex_decode(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key() -> ClusterKey {
        ClusterKey::new(&[7u8; 32]).unwrap()
    }

    #[test]
    fn a_frame_tag_holds_only_for_what_it_was_made_over() {
        let k = key();
        let h = frame_headers(Some(&k), "crease.frames.r.base", "a", 3, b"payload");
        assert_eq!(
            check_frame(Some(&k), "crease.frames.r.base", Some(&h), b"payload"),
            Ok(("a".to_owned(), 3))
        );
        // Another payload, subject, key, or an epoch rewritten: forged.
        for (subject, payload) in [
            ("crease.frames.r.base", &b"payloaD"[..]),
            ("crease.frames.s.base", b"payload"),
        ] {
            assert_eq!(
                check_frame(Some(&k), subject, Some(&h), payload),
                Err(Refusal::Forged)
            );
        }
        let other = ClusterKey::new(&[8u8; 32]).unwrap();
        assert_eq!(
            check_frame(Some(&other), "crease.frames.r.base", Some(&h), b"payload"),
            Err(Refusal::Forged)
        );
        let mut bumped = h.clone();
        bumped.insert(EPOCH, "4");
        assert_eq!(
            check_frame(Some(&k), "crease.frames.r.base", Some(&bumped), b"payload"),
            Err(Refusal::Forged)
        );
        // Untagged: forged with a key, believed without one.
        let plain = frame_headers(None, "crease.frames.r.base", "a", 3, b"payload");
        assert_eq!(
            check_frame(Some(&k), "crease.frames.r.base", Some(&plain), b"payload"),
            Err(Refusal::Forged)
        );
        assert!(check_frame(None, "crease.frames.r.base", Some(&plain), b"payload").is_ok());
        assert_eq!(check_frame(None, "x", None, b""), Err(Refusal::Forged));
    }

    #[test]
    fn the_tag_is_hmac_sha256_of_the_length_prefixed_parts() {
        // An independent computation: RFC 4231 test case 2's key and message through the same
        // HMAC, the message as one part behind its 8-byte length.
        let k = ClusterKey {
            key: b"Jefe".to_vec(),
        };
        let msg = b"what do ya want for nothing?";
        let mut framed = (msg.len() as u64).to_le_bytes().to_vec();
        framed.extend_from_slice(msg);
        let mut mac = Hmac::<Sha256>::new_from_slice(b"Jefe").unwrap();
        mac.update(&framed);
        assert_eq!(k.tag(&[msg]), hex_encode(&mac.finalize().into_bytes()));
        // And the HMAC itself is RFC 4231's (the message unframed).
        let mut mac = Hmac::<Sha256>::new_from_slice(b"Jefe").unwrap();
        mac.update(msg);
        assert_eq!(
            hex_encode(&mac.finalize().into_bytes()),
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
    }

    #[test]
    fn a_sealed_entry_holds_under_its_id_only_and_any_change_breaks_it() {
        let k = key();
        let mut e = v1::RoomEntry {
            model: "m".into(),
            owner: "a".into(),
            epoch: 2,
            ..Default::default()
        };
        k.seal_entry("room", &mut e);
        assert!(k.check_entry("room", &e));
        assert!(!k.check_entry("other", &e));
        let mut moved = e.clone();
        moved.owner = "forger".into();
        assert!(!k.check_entry("room", &moved));
        let mut unsealed = e.clone();
        unsealed.tag.clear();
        assert!(!k.check_entry("room", &unsealed));
    }

    #[test]
    fn controls_and_acks_are_tagged_both_ways() {
        let k = key();
        let h = control_headers(Some(&k), "crease.control.r", "b", b"frame");
        assert!(check_control(
            Some(&k),
            "crease.control.r",
            Some(&h),
            b"frame"
        ));
        assert!(!check_control(
            Some(&k),
            "crease.control.r",
            Some(&h),
            b"framE"
        ));
        assert!(!check_control(Some(&k), "crease.control.r", None, b"frame"));
        assert!(check_control(None, "crease.control.r", None, b"frame"));
        let a = ack_headers(Some(&k), "crease.control.r", "a", 5, b"ack");
        assert_eq!(
            check_ack(Some(&k), "crease.control.r", Some(&a), b"ack"),
            Ok(("a".to_owned(), 5))
        );
        assert_eq!(
            check_ack(Some(&k), "crease.control.r", Some(&a), b"acK"),
            Err(Refusal::Forged)
        );
        // An ack's tag is not a frame's.
        assert_eq!(
            check_frame(Some(&k), "crease.control.r", Some(&a), b"ack"),
            Err(Refusal::Forged)
        );
    }

    #[test]
    fn the_gate_refuses_older_epochs_once_a_newer_one_was_seen() {
        let g = EpochGate::default();
        assert_eq!(g.admit(1), Ok(()));
        assert_eq!(g.admit(1), Ok(()));
        g.note(2);
        assert_eq!(g.admit(1), Err(Refusal::Stale));
        assert_eq!(g.admit(3), Ok(()));
        assert_eq!(g.admit(2), Err(Refusal::Stale));
        assert_eq!(g.seen(), 3);
    }

    #[test]
    fn key_files_take_hex_or_raw_bytes_and_refuse_short_keys() {
        let dir = tempfile::tempdir().unwrap();
        let hex = dir.path().join("hex");
        std::fs::write(&hex, format!("{}\n", "ab".repeat(32))).unwrap();
        assert_eq!(ClusterKey::from_file(&hex).unwrap().key, vec![0xab; 32]);
        let raw = dir.path().join("raw");
        std::fs::write(&raw, [1u8; 40]).unwrap();
        assert_eq!(ClusterKey::from_file(&raw).unwrap().key, vec![1u8; 40]);
        let short = dir.path().join("short");
        std::fs::write(&short, "abcd").unwrap();
        let e = ClusterKey::from_file(&short).unwrap_err().to_string();
        assert!(e.contains("at least 32"), "{e}");
    }
}
