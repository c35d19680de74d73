//! A room's session: who may publish (the token), what it allows (the publish rate's token
//! bucket, the subscriber limit) and its live subscribers. The first thing a control frame
//! meets after the room lookup ([`crate::ingest`]), entered once per frame
//! ([`Session::enter`]: the token, then the rate), so refused frames cost nothing further.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The room is full: its subscriber limit is reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("room is full: {0} subscribers, the limit")]
pub struct RoomFull(pub usize);

/// Who sends a control frame into a session ([`Session::enter`]).
#[derive(Clone, Copy, Debug)]
pub enum Publisher<'a> {
    /// A publisher, with the token it presented (if any).
    Token(Option<&'a str>),
    /// Another replica of a cluster, forwarding a frame whose token it checked.
    Forwarded,
}

/// Why a session refused a control frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Not the room's publish token (or none).
    Token,
    /// Over the room's publish rate.
    Rate,
}

/// A token bucket: `tokens` frames may be published now; it refills at the rate limit, up to a
/// quarter second's worth.
#[derive(Debug)]
struct Budget {
    tokens: f64,
    at: Instant,
}

/// A room's token, limits and counters (module docs). The session keeps the SHA-256 of the
/// publish token and compares digests; the token itself only where the room was opened (a
/// cluster's other replicas know the digest alone, `crate::cluster`).
#[derive(Debug)]
pub struct Session {
    token: Option<String>,
    token_sha256: [u8; 32],
    budget: Mutex<Budget>,
    /// Live subscriptions of both levels (the subscriber limit).
    subscribers: Arc<AtomicUsize>,
}

/// Whether `id` is a valid room id: 1-64 characters of `[A-Za-z0-9_-]`.
pub fn valid_room_id(id: &str) -> bool {
    crease_proto::room::check_identifier(id, 64).is_ok()
}

/// A random 128-bit token, hex.
pub fn new_token() -> String {
    let bytes: [u8; 16] = rand::random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of a publish token.
pub fn token_sha256(token: &str) -> [u8; 32] {
    use sha2::Digest;
    sha2::Sha256::digest(token.as_bytes()).into()
}

/// Whether `presented` is `expected` (the admin token), compared by their SHA-256 digests in
/// constant time: a string `==` returns at the first byte that differs, which a client can
/// time to guess a token byte by byte.
pub(crate) fn same_token(presented: &str, expected: &str) -> bool {
    constant_time_eq(&token_sha256(presented), &token_sha256(expected))
}

/// Compares without an early exit, so the time taken does not tell how much of a guessed token
/// was right.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Holds one unit of a counter while it lives.
#[derive(Debug)]
pub(crate) struct CountGuard(Arc<AtomicUsize>);

impl CountGuard {
    /// Counts one more on `counter` until dropped.
    pub(crate) fn new(counter: &Arc<AtomicUsize>) -> CountGuard {
        counter.fetch_add(1, Ordering::Relaxed);
        CountGuard(Arc::clone(counter))
    }
}

impl Drop for CountGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

impl Session {
    /// A session with a fresh random token.
    pub(crate) fn new() -> Session {
        let token = new_token();
        Session {
            token_sha256: token_sha256(&token),
            token: Some(token),
            budget: Mutex::new(Budget {
                tokens: f64::INFINITY,
                at: Instant::now(),
            }),
            subscribers: Arc::new(AtomicUsize::new(0)),
        }
    }

    /// The publish token, where the room was opened on this replica.
    pub fn token(&self) -> Option<&str> {
        self.token.as_deref()
    }

    /// The publish token's SHA-256.
    pub fn token_sha256(&self) -> &[u8; 32] {
        &self.token_sha256
    }

    /// Replaces the publish token.
    pub(crate) fn set_token(&mut self, token: &str) {
        self.token_sha256 = token_sha256(token);
        self.token = Some(token.to_owned());
    }

    /// Replaces the publish token by its digest alone (a room opened on another replica).
    pub(crate) fn set_token_sha256(&mut self, digest: [u8; 32]) {
        self.token = None;
        self.token_sha256 = digest;
    }

    /// Whether `presented` is this room's publish token: its digest is compared with the
    /// token's, in constant time.
    pub fn accepts(&self, presented: Option<&str>) -> bool {
        presented.is_some_and(|p| constant_time_eq(&token_sha256(p), &self.token_sha256))
    }

    /// Whether one more frame may be published now under a limit of `rate_hz` frames per
    /// second (bursts up to a quarter second's worth, at least one frame). Counts the frame.
    pub fn admit(&self, rate_hz: f64) -> bool {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return true;
        }
        let burst = (rate_hz / 4.0).max(1.0);
        let mut b = self.budget.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        b.tokens = (b.tokens + now.duration_since(b.at).as_secs_f64() * rate_hz).min(burst);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// The one check of a control frame (module docs): `who`'s token, then, when `rate_hz`
    /// is given, the publish rate ([`Session::admit`]; a relay leaves the rate to the room's
    /// owner, which applies it to the forwarded frame).
    ///
    /// # Errors
    /// [`Refusal`]: not the token, or over the rate.
    pub fn enter(&self, who: Publisher<'_>, rate_hz: Option<f64>) -> Result<(), Refusal> {
        if let Publisher::Token(token) = who
            && !self.accepts(token)
        {
            return Err(Refusal::Token);
        }
        match rate_hz {
            Some(hz) if !self.admit(hz) => Err(Refusal::Rate),
            _ => Ok(()),
        }
    }

    /// Live subscriptions (both levels).
    pub fn subscriber_count(&self) -> usize {
        self.subscribers.load(Ordering::Relaxed)
    }

    /// A subscriber slot, held while the guard lives, if fewer than `max` are taken.
    ///
    /// # Errors
    /// [`RoomFull`] at `max` live subscriptions.
    pub(crate) fn take_slot(&self, max: usize) -> Result<CountGuard, RoomFull> {
        self.subscribers
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            })
            .map_err(RoomFull)?;
        Ok(CountGuard(Arc::clone(&self.subscribers)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_ids_and_tokens() {
        assert!(valid_room_id("demo"));
        assert!(valid_room_id("a-b_C9"));
        assert!(!valid_room_id(""));
        assert!(!valid_room_id("a b"));
        assert!(!valid_room_id(&"x".repeat(65)));
        let (a, b) = (new_token(), new_token());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
        assert!(constant_time_eq(a.as_bytes(), a.as_bytes()));
        assert!(!constant_time_eq(a.as_bytes(), b.as_bytes()));
        assert!(!constant_time_eq(b"ab", b"abc"));
        assert!(same_token("admin-secret", "admin-secret"));
        assert!(!same_token("admin-secreT", "admin-secret"));
        assert!(!same_token("admin-secret ", "admin-secret"));
        assert!(!same_token("", "admin-secret"));
    }

    #[test]
    fn tokens_slots_and_the_rate_bucket() {
        let mut s = Session::new();
        s.set_token("secret");
        assert!(s.accepts(Some("secret")));
        assert!(!s.accepts(Some("secreT")) && !s.accepts(None));
        // Knowing only the digest accepts the same tokens.
        let digest = *s.token_sha256();
        let mut relay = Session::new();
        relay.set_token_sha256(digest);
        assert_eq!(relay.token(), None);
        assert!(relay.accepts(Some("secret")) && !relay.accepts(Some("secret ")));
        // Two slots: a third is refused until one is given back.
        let a = s.take_slot(2).unwrap();
        let _b = s.take_slot(2).unwrap();
        assert_eq!(s.take_slot(2).unwrap_err(), RoomFull(2));
        drop(a);
        assert_eq!(s.subscriber_count(), 1);
        assert!(s.take_slot(2).is_ok());
        // 8 Hz: a burst of 2 (a quarter second), then refused; no limit admits everything.
        assert!(s.admit(8.0) && s.admit(8.0));
        assert!(!s.admit(8.0));
        assert!((0..100).all(|_| s.admit(0.0)));
    }
}
