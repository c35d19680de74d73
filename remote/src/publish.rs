//! The one publish loop: control frames out on a `Publish` stream, acks in. Every publisher
//! of the tree runs through [`publish`]: `crease stream`, `crease take replay`, both capture
//! bridges, `bench-net`'s publishers and the soak's.
//!
//! What differs between them is given, not copied:
//! - **what is sent and when** (a ticker, a take's timing or one frame per ack, a UDP source)
//!   is the `source`: a closure given a [`Sink`], run on its own task, whose result comes back
//!   in [`Published::output`];
//! - **what an ack means** (counts, latencies, a window, malformed frames expected refused) is
//!   the [`Acks`] handler, called on the caller's task for every ack in order; it may stop the
//!   loop early ([`ControlFlow::Break`]);
//! - **how long the last acks are waited for** once the source is done, and the queue between
//!   source and stream, are [`PublishOptions`].
//!
//! The loop adds no copy and no allocation per frame: the source's frames are moved into the
//! stream's channel, and acks are handed over by value. [`SentLog`] is the seq -> send time
//! (or capture time) record that publishers measuring round trips share between source and
//! handler.

use std::collections::VecDeque;
use std::future::Future;
use std::ops::ControlFlow;
use std::sync::Mutex;
use std::time::Duration;

use crease_proto::v1;
use crease_proto::v1::crease_client::CreaseClient;
use tokio::sync::{mpsc, watch};
use tonic::transport::Channel;

/// The queue between a source and its stream, and how long the last acks are waited for.
#[derive(Clone, Copy, Debug)]
pub struct PublishOptions {
    /// Control frames queued before the source waits ([`Sink::send`]) or drops
    /// ([`Sink::try_send`]).
    pub queue: usize,
    /// After the source is done, how long to wait for the server to answer the rest; `None`:
    /// until the server ends the stream.
    pub drain: Option<Duration>,
}

/// Where a source puts its frames: the `Publish` stream's queue. Once the stream has ended
/// (the server ended it, the handler stopped, or it could not be opened) every send fails.
#[derive(Debug)]
pub struct Sink {
    tx: mpsc::Sender<v1::ControlFrame>,
    ended: Option<watch::Receiver<bool>>,
}

/// The stream has ended: the frame was not sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ended;

/// Why [`Sink::try_send`] did not send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrySendError {
    /// The queue is full (the stream is behind).
    Full,
    /// The stream has ended.
    Ended,
}

impl From<mpsc::Sender<v1::ControlFrame>> for Sink {
    /// A sink on a plain channel (tests, fixtures): ended when its receiver is dropped.
    fn from(tx: mpsc::Sender<v1::ControlFrame>) -> Self {
        Self { tx, ended: None }
    }
}

impl Sink {
    /// Whether the stream has ended.
    pub fn is_ended(&self) -> bool {
        self.tx.is_closed() || self.ended.as_ref().is_some_and(|e| *e.borrow())
    }

    /// Sends `frame`, waiting for room in the queue.
    ///
    /// # Errors
    /// [`Ended`] when the stream has ended (before or while waiting).
    pub async fn send(&mut self, frame: v1::ControlFrame) -> Result<(), Ended> {
        match &mut self.ended {
            None => self.tx.send(frame).await.map_err(|_| Ended),
            Some(ended) => {
                if *ended.borrow() {
                    return Err(Ended);
                }
                tokio::select! {
                    biased;
                    r = self.tx.send(frame) => r.map_err(|_| Ended),
                    _ = ended.wait_for(|e| *e) => Err(Ended),
                }
            }
        }
    }

    /// Sends `frame` if the queue has room (a live source drops rather than delays).
    ///
    /// # Errors
    /// [`TrySendError::Full`] or [`TrySendError::Ended`].
    pub fn try_send(&self, frame: v1::ControlFrame) -> Result<(), TrySendError> {
        if self.ended.as_ref().is_some_and(|e| *e.borrow()) {
            return Err(TrySendError::Ended);
        }
        self.tx.try_send(frame).map_err(|e| match e {
            mpsc::error::TrySendError::Full(_) => TrySendError::Full,
            mpsc::error::TrySendError::Closed(_) => TrySendError::Ended,
        })
    }

    /// Resolves once the stream has ended (for a source waiting on something else: a timer,
    /// a socket).
    pub async fn ended(&mut self) {
        match &mut self.ended {
            Some(ended) => {
                // An error: the loop is gone, which is an end too.
                let _ = ended.wait_for(|e| *e).await;
            }
            None => self.tx.closed().await,
        }
    }
}

/// What a publisher does with each ack.
pub trait Acks {
    /// Handles one ack; [`ControlFlow::Break`] ends the loop (the source is told the stream
    /// ended).
    fn ack(&mut self, ack: v1::PublishAck) -> ControlFlow<()>;
}

impl<F: FnMut(v1::PublishAck) -> ControlFlow<()>> Acks for F {
    fn ack(&mut self, ack: v1::PublishAck) -> ControlFlow<()> {
        self(ack)
    }
}

/// How the ack stream ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// The source was done and the server answered (ended the stream) within the drain time.
    Answered,
    /// The server ended the stream (or it failed) while the source was still sending.
    ServerEnded,
    /// The ack handler stopped the loop.
    Stopped,
    /// The source was done but the server did not end the stream within
    /// [`PublishOptions::drain`].
    DrainTimedOut,
}

/// A finished publish.
#[derive(Debug)]
pub struct Published<T> {
    /// What the source returned.
    pub output: T,
    /// How the ack stream ended.
    pub end: End,
    /// The error status that ended the ack stream, if one did.
    pub status: Option<tonic::Status>,
}

/// Why [`publish`] did not run.
#[derive(Debug)]
pub enum PublishError {
    /// The token is not a valid header value.
    Token(tonic::metadata::errors::InvalidMetadataValue),
    /// The server refused to open the stream.
    Open(tonic::Status),
    /// The source's task panicked or was cancelled.
    Source(tokio::task::JoinError),
}

impl std::fmt::Display for PublishError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Token(_) => f.write_str("the token is not a valid header value"),
            Self::Open(s) => write!(f, "{s}"),
            Self::Source(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for PublishError {}

impl PublishError {
    /// As an error with `open` as the context of a refused stream (its status kept whole, as
    /// the caller would have had it from the `Publish` call), `token` of a bad token, and
    /// `source` of a failed source.
    pub fn into_anyhow(self, token: &str, open: &str, source: &str) -> anyhow::Error {
        match self {
            Self::Token(e) => anyhow::Error::new(e)
                .context("the token is not a valid header value")
                .context(token.to_owned()),
            Self::Open(s) => anyhow::Error::new(s).context(open.to_owned()),
            Self::Source(e) => anyhow::Error::new(e).context(source.to_owned()),
        }
    }
}

/// Publishes the frames `source` sends into the room `token` opens, handing every ack to
/// `acks`, until the server ends the stream (after the source is done and has been answered,
/// or earlier), the handler stops, or the drain time after the source runs out.
///
/// The source runs on its own task from before the stream is opened; it is told the stream
/// ended through its [`Sink`], and its output is awaited before this returns.
///
/// # Errors
/// A token that is not a header value, a stream the server refuses to open, or a source that
/// panicked. An error ending the ack stream is not one: it is in [`Published::status`].
pub async fn publish<F, Fut, A>(
    client: &mut CreaseClient<Channel>,
    token: &str,
    options: PublishOptions,
    source: F,
    acks: &mut A,
) -> Result<Published<Fut::Output>, PublishError>
where
    F: FnOnce(Sink) -> Fut,
    Fut: Future + Send + 'static,
    Fut::Output: Send + 'static,
    A: Acks + ?Sized,
{
    let bearer = crate::client::bearer(token).map_err(PublishError::Token)?;
    let (tx, rx) = mpsc::channel(options.queue);
    let (end_tx, end_rx) = watch::channel(false);
    let mut task = tokio::spawn(source(Sink {
        tx,
        ended: Some(end_rx),
    }));
    let mut request = tonic::Request::new(tokio_stream::wrappers::ReceiverStream::new(rx));
    request.metadata_mut().insert("authorization", bearer);
    let mut stream = match client.publish(request).await {
        Ok(r) => r.into_inner(),
        Err(status) => {
            let _ = end_tx.send(true);
            task.abort();
            return Err(PublishError::Open(status));
        }
    };
    let mut output = None;
    let mut deadline: Option<tokio::time::Instant> = None;
    let mut status = None;
    let end = loop {
        tokio::select! {
            msg = stream.message() => match msg {
                Ok(Some(ack)) => {
                    if acks.ack(ack).is_break() {
                        break End::Stopped;
                    }
                }
                Ok(None) => break if output.is_some() { End::Answered } else { End::ServerEnded },
                Err(s) => {
                    status = Some(s);
                    break if output.is_some() { End::Answered } else { End::ServerEnded };
                }
            },
            out = &mut task, if output.is_none() => {
                output = Some(out.map_err(PublishError::Source)?);
                deadline = options.drain.map(|d| tokio::time::Instant::now() + d);
            }
            () = sleep_until(deadline), if deadline.is_some() => break End::DrainTimedOut,
        }
    };
    let _ = end_tx.send(true);
    let output = match output {
        Some(o) => o,
        None => task.await.map_err(PublishError::Source)?,
    };
    Ok(Published {
        output,
        end,
        status,
    })
}

async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// Sent frames by seq, with a time each (when it was sent, or its capture time), so that an
/// ack finds its frame's time: shared by a source (which records) and an ack handler (which
/// takes). Acks come in seq order; a frame never acked is forgotten when a later one is.
#[derive(Debug)]
pub struct SentLog<T> {
    sent: Mutex<VecDeque<(u64, T)>>,
}

impl<T> Default for SentLog<T> {
    fn default() -> Self {
        Self {
            sent: Mutex::new(VecDeque::new()),
        }
    }
}

impl<T> SentLog<T> {
    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<(u64, T)>> {
        self.sent
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Records frame `seq` with `at`; with `memory`, the oldest frames beyond that many are
    /// forgotten.
    pub fn record(&self, seq: u64, at: T, memory: Option<usize>) {
        let mut q = self.lock();
        q.push_back((seq, at));
        if memory.is_some_and(|m| q.len() > m) {
            q.pop_front();
        }
    }

    /// The time of frame `seq`, forgetting it and every earlier frame; `None` when it is not
    /// remembered.
    pub fn take(&self, seq: u64) -> Option<T> {
        let mut q = self.lock();
        while let Some((s, at)) = q.pop_front() {
            if s == seq {
                return Some(at);
            }
            if s > seq {
                q.push_front((s, at));
                return None;
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sent_log_finds_acked_frames_in_order() {
        let log = SentLog::default();
        for seq in 0..5u64 {
            log.record(seq, seq * 10, Some(3));
        }
        // 0 and 1 were forgotten (memory 3).
        assert_eq!(log.take(0), None);
        assert_eq!(log.take(3), Some(30));
        assert_eq!(log.take(2), None);
        assert_eq!(log.take(4), Some(40));
        assert_eq!(log.take(5), None);
    }
}
