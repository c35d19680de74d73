//! Admission: how much one client address, and all clients together, may hold open (issue 21).
//!
//! Two counters, each with a cap per address and a cap in total:
//! - **connections**: TCP connections on the gRPC and the HTTP listener ([`AdmittedListener`]
//!   for HTTP, [`incoming`] for gRPC). Over a cap the socket is closed at once (on HTTP after a
//!   `503` naming the cap), so one address opening thousands of sockets cannot starve others.
//! - **streams**: long-lived calls: gRPC `Publish`, `Subscribe` and `Synthesize`, and
//!   WebSocket sessions. Over a cap the call is refused with a clear status (gRPC
//!   `RESOURCE_EXHAUSTED`, HTTP `429` before the WebSocket upgrade) naming the address, what it
//!   holds and the cap; everyone else goes on.
//!
//! A [`Permit`] holds one slot and gives it back when dropped: it lives as long as the
//! connection or the stream (inside the stream's future or the socket wrapper).
//!
//! Addresses are the TCP peer's: behind a proxy every client is the proxy, so set the per-address
//! caps to the totals there (`crease-server --max-connections-per-address`).

use std::collections::HashMap;
use std::fmt;
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// A cap per client address and a cap in total.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Caps {
    /// Most held open by one address.
    pub per_address: usize,
    /// Most held open by everyone together.
    pub total: usize,
}

/// One kind of thing admitted (connections or streams), counted per address.
#[derive(Debug)]
pub struct Admission {
    kind: &'static str,
    caps: Caps,
    counts: Mutex<Counts>,
    refused: prometheus_client::metrics::counter::Counter,
}

#[derive(Debug, Default)]
struct Counts {
    total: usize,
    by_address: HashMap<IpAddr, usize>,
}

/// Why a client was not admitted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Refused {
    /// The address holds `open` already, its cap.
    Address {
        /// What was refused: `connections` or `streams`.
        kind: &'static str,
        /// The client's address.
        ip: IpAddr,
        /// How many it holds.
        open: usize,
    },
    /// Everyone together holds `open`, the total cap.
    Total {
        /// What was refused: `connections` or `streams`.
        kind: &'static str,
        /// How many are open.
        open: usize,
    },
}

impl fmt::Display for Refused {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Refused::Address { kind, ip, open } => write!(
                f,
                "too many {kind} from {ip}: it holds {open}, the cap per address (close one and retry)"
            ),
            Refused::Total { kind, open } => write!(
                f,
                "too many {kind}: {open} open, the server's cap (retry later or on another replica)"
            ),
        }
    }
}

impl std::error::Error for Refused {}

impl Admission {
    /// A counter of `kind` (`connections`, `streams`) under `caps`.
    pub fn new(kind: &'static str, caps: Caps) -> Arc<Admission> {
        Arc::new(Admission {
            kind,
            caps,
            counts: Mutex::new(Counts::default()),
            refused: prometheus_client::metrics::counter::Counter::default(),
        })
    }

    /// The caps.
    pub fn caps(&self) -> Caps {
        self.caps
    }

    /// How many `ip` holds, and how many are open in total.
    pub fn open(&self, ip: IpAddr) -> (usize, usize) {
        let counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        (
            counts.by_address.get(&ip).copied().unwrap_or(0),
            counts.total,
        )
    }

    /// Refusals so far (the `crease_admission_refused_total` metric).
    pub fn refused_counter(&self) -> prometheus_client::metrics::counter::Counter {
        self.refused.clone()
    }

    /// One slot for `ip`, or why not.
    ///
    /// # Errors
    /// [`Refused`] when `ip` or everyone holds the cap already; nothing is counted then.
    pub fn admit(self: &Arc<Self>, ip: IpAddr) -> Result<Permit, Refused> {
        let mut counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        let held = counts.by_address.get(&ip).copied().unwrap_or(0);
        let refused = if held >= self.caps.per_address {
            Some(Refused::Address {
                kind: self.kind,
                ip,
                open: held,
            })
        } else if counts.total >= self.caps.total {
            Some(Refused::Total {
                kind: self.kind,
                open: counts.total,
            })
        } else {
            None
        };
        if let Some(refused) = refused {
            drop(counts);
            self.refused.inc();
            tracing::debug!(%refused, "not admitted");
            return Err(refused);
        }
        counts.total += 1;
        *counts.by_address.entry(ip).or_insert(0) += 1;
        Ok(Permit {
            admission: Arc::clone(self),
            ip,
        })
    }
}

/// One admitted connection or stream; dropping it gives the slot back.
#[derive(Debug)]
pub struct Permit {
    admission: Arc<Admission>,
    ip: IpAddr,
}

impl Drop for Permit {
    fn drop(&mut self) {
        let mut counts = self
            .admission
            .counts
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        counts.total -= 1;
        if let Some(n) = counts.by_address.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                counts.by_address.remove(&self.ip);
            }
        }
    }
}

/// A TCP stream with its connection permit (Nagle off: frames are small and latency-bound).
#[derive(Debug)]
pub struct AdmittedStream {
    stream: TcpStream,
    _permit: Permit,
}

impl AsyncRead for AdmittedStream {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for AdmittedStream {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.get_mut().stream).poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().stream).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.get_mut().stream).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.get_mut().stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }
}

impl tonic::transport::server::Connected for AdmittedStream {
    type ConnectInfo = tonic::transport::server::TcpConnectInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.stream.connect_info()
    }
}

/// Accepts the next connection `admission` admits. A refused one is closed at once; with
/// `refusal` (HTTP) it is first sent that response, without waiting on the client.
async fn accept(
    listener: &TcpListener,
    admission: &Arc<Admission>,
    refusal: Option<fn(&Refused) -> String>,
) -> (AdmittedStream, SocketAddr) {
    loop {
        let (stream, addr) = match listener.accept().await {
            Ok(accepted) => accepted,
            Err(e) => {
                // Out of descriptors, or a connection reset before it was accepted: wait a
                // little rather than spin (as hyper's and axum's accept loops do).
                tracing::warn!(error = %e, "accept failed");
                tokio::time::sleep(std::time::Duration::from_millis(20)).await;
                continue;
            }
        };
        match admission.admit(addr.ip()) {
            Ok(permit) => {
                let _ = stream.set_nodelay(true);
                return (
                    AdmittedStream {
                        stream,
                        _permit: permit,
                    },
                    addr,
                );
            }
            Err(refused) => {
                if let Some(response) = refusal {
                    let text = response(&refused);
                    tokio::spawn(async move {
                        let mut stream = stream;
                        // Answer, then read what the client sends until it closes (1 s at
                        // most): closing with its request unread would reset the connection,
                        // and the client could lose the answer.
                        let _ = tokio::time::timeout(std::time::Duration::from_secs(1), async {
                            stream.write_all(text.as_bytes()).await?;
                            stream.shutdown().await?;
                            let mut sink = [0u8; 1024];
                            while stream.read(&mut sink).await? > 0 {}
                            std::io::Result::Ok(())
                        })
                        .await;
                    });
                }
            }
        }
    }
}

/// The HTTP listener under the connection caps (for `axum::serve`).
#[derive(Debug)]
pub struct AdmittedListener {
    listener: TcpListener,
    admission: Arc<Admission>,
}

impl AdmittedListener {
    /// `listener` admitting connections through `admission`.
    pub fn new(listener: TcpListener, admission: Arc<Admission>) -> Self {
        Self {
            listener,
            admission,
        }
    }
}

/// The `503` a refused HTTP connection gets.
fn http_refusal(refused: &Refused) -> String {
    let body = format!("{refused}\n");
    format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: text/plain; charset=utf-8\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    )
}

impl axum::serve::Listener for AdmittedListener {
    type Io = AdmittedStream;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        accept(&self.listener, &self.admission, Some(http_refusal)).await
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.listener.local_addr()
    }
}

/// The HTTPS listener's connections under the connection caps (issue 40): axum-server's accept
/// loop hands each TCP connection here before its TLS handshake (the inner acceptor of its
/// `RustlsAcceptor`). A refused one is closed at once: a TLS client cannot be answered in
/// HTTP before its handshake, and a handshake is what a flood would make the server pay for.
#[derive(Clone, Debug)]
pub struct AdmissionAcceptor {
    admission: Arc<Admission>,
}

impl AdmissionAcceptor {
    /// Connections admitted through `admission`.
    pub fn new(admission: Arc<Admission>) -> Self {
        Self { admission }
    }
}

impl<S> axum_server::accept::Accept<TcpStream, S> for AdmissionAcceptor {
    type Stream = AdmittedStream;
    type Service = S;
    type Future = std::future::Ready<std::io::Result<(AdmittedStream, S)>>;

    fn accept(&self, stream: TcpStream, service: S) -> Self::Future {
        let admitted = stream.peer_addr().and_then(|addr| {
            self.admission.admit(addr.ip()).map_err(|refused| {
                std::io::Error::new(std::io::ErrorKind::ConnectionRefused, refused.to_string())
            })
        });
        std::future::ready(admitted.map(|permit| {
            let _ = stream.set_nodelay(true);
            (
                AdmittedStream {
                    stream,
                    _permit: permit,
                },
                service,
            )
        }))
    }
}

/// The client's address, as the HTTP handlers see it (`ConnectInfo<Peer>`), from either HTTP
/// server (plain: [`AdmittedListener`]; TLS: axum-server's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Peer(pub SocketAddr);

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, AdmittedListener>>
    for Peer
{
    fn connect_info(stream: axum::serve::IncomingStream<'_, AdmittedListener>) -> Self {
        Peer(*stream.remote_addr())
    }
}

impl axum::extract::connect_info::Connected<SocketAddr> for Peer {
    fn connect_info(addr: SocketAddr) -> Self {
        Peer(addr)
    }
}

/// The gRPC listener's connections under the connection caps, for tonic's
/// `serve_with_incoming`.
pub fn incoming(
    listener: TcpListener,
    admission: Arc<Admission>,
) -> impl tokio_stream::Stream<Item = std::io::Result<AdmittedStream>> + Send + 'static {
    futures_util::stream::unfold((listener, admission), |(listener, admission)| async move {
        let (stream, _) = accept(&listener, &admission, None).await;
        Some((Ok(stream), (listener, admission)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permits_count_per_address_and_in_total_and_come_back_when_dropped() {
        let a = Admission::new(
            "streams",
            Caps {
                per_address: 2,
                total: 3,
            },
        );
        let x: IpAddr = "10.0.0.1".parse().unwrap();
        let y: IpAddr = "10.0.0.2".parse().unwrap();
        let p1 = a.admit(x).unwrap();
        let _p2 = a.admit(x).unwrap();
        assert_eq!(
            a.admit(x).unwrap_err(),
            Refused::Address {
                kind: "streams",
                ip: x,
                open: 2
            }
        );
        let _p3 = a.admit(y).unwrap();
        assert_eq!(
            a.admit(y).unwrap_err(),
            Refused::Total {
                kind: "streams",
                open: 3
            }
        );
        assert_eq!(a.open(x), (2, 3));
        drop(p1);
        assert_eq!(a.open(x), (1, 2));
        let _p4 = a.admit(y).unwrap();
        assert_eq!(a.open(y), (2, 3));
        assert_eq!(a.refused_counter().get(), 2);
        let text = Refused::Address {
            kind: "streams",
            ip: x,
            open: 2,
        }
        .to_string();
        assert!(text.contains("10.0.0.1") && text.contains("2"), "{text}");
    }
}
