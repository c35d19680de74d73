//! The NatNet bridge (`crease bridge natnet`, issue 19): connects to an OptiTrack NatNet server (Motive), reads
//! its labelled markers and publishes them into a retargeting room as marker frames
//! (`ControlFrame.markers` / `markers_valid`, in the room's declared marker order).
//!
//! - [`wire`]: the NatNet decoder (3.0-4.1; our own, bounds-checked, never panics);
//! - [`encode`]: requests, and synthetic server messages for fixtures and test servers.
//!
//! The session: NAT_CONNECT on the command port (1510) until NAT_SERVERINFO names the server's
//! NatNet version (one not read is refused, naming it), NAT_REQUEST_MODELDEF for the marker
//! set and rigid body names, then frames of data on the data port (1511, unicast, or the
//! multicast group) and on the command socket (where a unicast server may send them).
//!
//! Names: a room marker is `Set:Marker` (a marker set's marker, or a rigid body's marker by
//! its name, NatNet 4.0 on) or a bare marker name found in exactly one marker set (the "all"
//! set aside). A marker of a set that has a rigid body of the same name (Motive streams one
//! per body) is read from the labelled markers (id = body id << 16 | 1-based index): invalid
//! when occluded or absent. Others are read from the marker set, invalid when absent or not
//! finite. An invalid marker carries its last valid position.

pub mod encode;
pub mod wire;

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::ops::ControlFlow;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use crease_proto::control::encode_valid_mask;
use crease_proto::v1;
use tokio::net::UdpSocket;

use self::wire::{DataDescriptions, FrameOfData, NAT_MODELDEF, NAT_SERVERINFO};
use self::wire::{ServerInfo, Version};
use crease_proto::v1::crease_client::CreaseClient;
use crease_remote::publish::{PublishError, PublishOptions, SentLog, Sink, publish};
use crease_remote::{get_room, percentile, unix_us};
use tonic::transport::Channel;

/// What a NatNet bridge publishes, where, and how it reaches the NatNet server.
#[derive(Clone, Debug)]
pub struct NatnetOptions {
    /// The retargeting room to publish into.
    pub room: String,
    /// The room's publish token.
    pub token: String,
    /// How to reach the NatNet server.
    pub source: SourceOptions,
    /// Time between summary lines.
    pub summary_every: Duration,
    /// Stop after publishing this many frames (default: run until interrupted).
    pub frames: Option<u64>,
}

/// Where a room marker is read in a frame.
#[derive(Clone, Debug, PartialEq)]
struct MarkerSource {
    /// The room's name for it.
    name: String,
    /// Marker set name and index in it, when it is a marker set's marker.
    set: Option<(String, usize)>,
    /// Labelled marker id, when the set has a rigid body of the same name (or the marker is a
    /// rigid body's).
    label: Option<i32>,
}

/// The room's declared markers resolved against the NatNet server's data descriptions.
#[derive(Clone, Debug)]
pub struct MarkerSources {
    sources: Vec<MarkerSource>,
}

/// Motive's marker set of every labelled marker: not searched for bare names.
const ALL_SET: &str = "all";

fn label_id(body: i32, index: usize) -> i32 {
    (body << 16) | ((index as i32 + 1) & 0xffff)
}

impl MarkerSources {
    /// Resolves every declared name (see the module's doc for the forms).
    ///
    /// # Errors
    /// An unknown or ambiguous name, naming it and what the server describes.
    pub fn resolve(declared: &[String], dd: &DataDescriptions) -> anyhow::Result<Self> {
        if declared.is_empty() {
            bail!("the room declares no markers (RoomInfo.retarget.markers is empty)");
        }
        let mut sources = Vec::with_capacity(declared.len());
        for name in declared {
            sources.push(Self::resolve_one(name, dd)?);
        }
        Ok(Self { sources })
    }

    /// The declared names, in order.
    pub fn names(&self) -> Vec<&str> {
        self.sources.iter().map(|s| s.name.as_str()).collect()
    }

    /// Candidate sources of `set:marker`.
    fn qualified(set: &str, marker: &str, dd: &DataDescriptions) -> Option<MarkerSource> {
        let body = dd.rigid_bodies.iter().find(|b| b.name == set);
        if let Some(ms) = dd.marker_sets.iter().find(|s| s.name == set)
            && let Some(i) = ms.markers.iter().position(|m| m == marker)
        {
            // The body's marker of the same name (4.0 on), else the same index when the body
            // has as many markers as the set (3.x descriptions carry no names).
            let label = body.and_then(|b| {
                b.markers
                    .iter()
                    .position(|m| m.name == marker)
                    .or((b.markers.len() == ms.markers.len()
                        && b.markers.iter().all(|m| m.name.is_empty()))
                    .then_some(i))
                    .map(|j| label_id(b.id, j))
            });
            return Some(MarkerSource {
                name: String::new(),
                set: Some((set.to_owned(), i)),
                label,
            });
        }
        let b = body?;
        let j = b
            .markers
            .iter()
            .position(|m| !m.name.is_empty() && m.name == marker)?;
        Some(MarkerSource {
            name: String::new(),
            set: None,
            label: Some(label_id(b.id, j)),
        })
    }

    fn resolve_one(name: &str, dd: &DataDescriptions) -> anyhow::Result<MarkerSource> {
        let mut found: Vec<(String, MarkerSource)> = Vec::new();
        if let Some((set, marker)) = name.split_once(':')
            && let Some(s) = Self::qualified(set, marker, dd)
        {
            found.push((name.to_owned(), s));
        }
        if found.is_empty() {
            let mut sets: Vec<&str> = dd
                .marker_sets
                .iter()
                .filter(|s| s.name != ALL_SET && s.markers.iter().any(|m| m == name))
                .map(|s| s.name.as_str())
                .collect();
            for b in &dd.rigid_bodies {
                if !sets.contains(&b.name.as_str()) && b.markers.iter().any(|m| m.name == name) {
                    sets.push(&b.name);
                }
            }
            for set in sets {
                if let Some(s) = Self::qualified(set, name, dd) {
                    found.push((format!("{set}:{name}"), s));
                }
            }
        }
        match found.len() {
            1 => {
                let mut s = found.remove(0).1;
                s.name = name.to_owned();
                Ok(s)
            }
            0 => {
                let mut known: Vec<String> = Vec::new();
                for s in &dd.marker_sets {
                    known.extend(s.markers.iter().map(|m| format!("{}:{m}", s.name)));
                }
                for b in &dd.rigid_bodies {
                    known.extend(
                        b.markers
                            .iter()
                            .filter(|m| !m.name.is_empty())
                            .map(|m| format!("{}:{}", b.name, m.name)),
                    );
                }
                known.truncate(40);
                bail!(
                    "room marker {name:?} is not among the NatNet server's markers (marker set \
                     or rigid body markers, as Set:Marker or a bare name): {}",
                    if known.is_empty() {
                        "it describes none".to_owned()
                    } else {
                        known.join(", ")
                    }
                )
            }
            _ => bail!(
                "room marker {name:?} is ambiguous: it is {}; declare it as Set:Marker",
                found
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(" and ")
            ),
        }
    }
}

/// One frame's markers in the room's order, with their validity.
#[derive(Clone, Debug, PartialEq)]
pub struct Markers {
    /// x, y, z per declared marker.
    pub positions: Vec<f32>,
    /// Whether each marker was seen.
    pub valid: Vec<bool>,
}

/// Turns decoded frames into marker frames, holding each marker's last valid position.
#[derive(Clone, Debug)]
pub struct Converter {
    map: MarkerSources,
    last: Vec<[f32; 3]>,
}

impl Converter {
    /// A converter for `map`.
    pub fn new(map: MarkerSources) -> Self {
        let n = map.sources.len();
        Self {
            map,
            last: vec![[0.0; 3]; n],
        }
    }

    /// The frame's markers in the room's order.
    pub fn markers(&mut self, f: &FrameOfData) -> Markers {
        let labels: HashMap<i32, &wire::LabeledMarker> =
            f.labeled_markers.iter().map(|m| (m.id, m)).collect();
        let n = self.map.sources.len();
        let mut positions = Vec::with_capacity(3 * n);
        let mut valid = Vec::with_capacity(n);
        for (i, s) in self.map.sources.iter().enumerate() {
            let in_set = s.set.as_ref().and_then(|(set, k)| {
                f.marker_sets
                    .iter()
                    .find(|m| &m.name == set)
                    .and_then(|m| m.markers.get(*k).copied())
            });
            let (p, ok) = match s.label {
                Some(id) => match labels.get(&id) {
                    Some(m) => (Some(m.position), !m.occluded()),
                    None => (in_set, false),
                },
                None => (in_set, in_set.is_some()),
            };
            let ok = ok && p.is_some_and(|p| p.iter().all(|x| x.is_finite()));
            if ok && let Some(p) = p {
                self.last[i] = p;
            }
            positions.extend_from_slice(&self.last[i]);
            valid.push(ok);
        }
        Markers { positions, valid }
    }
}

/// What became of one datagram.
#[derive(Debug)]
pub enum Outcome {
    /// A frame of data, as a control frame for the room.
    Frame(Box<v1::ControlFrame>, usize),
    /// Malformed: dropped (the error says where).
    Dropped(wire::DecodeError),
    /// A well-formed message that is not a frame (server info, descriptions, text).
    Ignored(u16),
}

/// Counters of a bridge run.
#[derive(Clone, Debug, Default)]
pub struct Counters {
    /// Frames of data decoded.
    pub frames_in: u64,
    /// Control frames handed to the publisher.
    pub published: u64,
    /// Acks without an error.
    pub acked: u64,
    /// Acks with an error.
    pub refused: u64,
    /// Malformed datagrams dropped.
    pub dropped: u64,
    /// Other messages ignored.
    pub ignored: u64,
    /// Invalid markers in published frames.
    pub invalid_markers: u64,
    /// Capture to ack, microseconds, since the last summary.
    pub latency_us: Vec<i64>,
}

/// The datagram-to-control-frame step of the bridge.
#[derive(Debug)]
pub struct Bridge {
    version: Version,
    clock_frequency: Option<u64>,
    room: String,
    converter: Converter,
    seq: u64,
    /// Counters (shared with the ack reader).
    pub counters: Arc<Mutex<Counters>>,
    last_error: Option<String>,
}

impl Bridge {
    /// A bridge for frames of NatNet `version` into `room`.
    pub fn new(
        version: Version,
        info: Option<&ServerInfo>,
        room: &str,
        map: MarkerSources,
    ) -> Self {
        Self {
            version,
            clock_frequency: info.and_then(|i| i.clock_frequency).filter(|f| *f > 0),
            room: room.to_owned(),
            converter: Converter::new(map),
            seq: 0,
            counters: Arc::default(),
            last_error: None,
        }
    }

    fn counters(&self) -> std::sync::MutexGuard<'_, Counters> {
        self.counters.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Decodes one datagram received at `received_us` (Unix µs). A frame becomes a control
    /// frame (the next seq; capture time = arrival less the server's mid-exposure to transmit
    /// time, when its clock frequency is known); anything malformed is counted and dropped.
    pub fn datagram(&mut self, bytes: &[u8], received_us: i64) -> Outcome {
        match wire::decode(bytes, self.version) {
            Err(e) => {
                self.counters().dropped += 1;
                self.last_error = Some(e.to_string());
                Outcome::Dropped(e)
            }
            Ok(wire::Message::Frame(f)) => {
                let m = self.converter.markers(&f);
                let capture_time_us = received_us - self.source_latency_us(&f);
                let mut mask = Vec::new();
                if !m.valid.iter().all(|v| *v) {
                    encode_valid_mask(&m.valid, &mut mask);
                }
                let invalid = m.valid.iter().filter(|v| !**v).count();
                let frame = v1::ControlFrame {
                    room: self.room.clone(),
                    seq: self.seq,
                    capture_time_us,
                    markers: m.positions,
                    markers_valid: mask,
                    ..v1::ControlFrame::default()
                };
                self.seq += 1;
                let mut c = self.counters();
                c.frames_in += 1;
                c.invalid_markers += invalid as u64;
                drop(c);
                Outcome::Frame(Box::new(frame), invalid)
            }
            Ok(other) => {
                self.counters().ignored += 1;
                Outcome::Ignored(match other {
                    wire::Message::ServerInfo(_) => NAT_SERVERINFO,
                    wire::Message::Descriptions(_) => NAT_MODELDEF,
                    wire::Message::Other(id) => id,
                    _ => wire::NAT_MESSAGESTRING,
                })
            }
        }
    }

    /// The last decode error, for the summary.
    pub fn last_error(&self) -> Option<&str> {
        self.last_error.as_deref()
    }

    fn source_latency_us(&self, f: &FrameOfData) -> i64 {
        let t = &f.timing;
        match self.clock_frequency {
            Some(freq) if t.transmit >= t.camera_mid_exposure && t.camera_mid_exposure > 0 => {
                let us = (t.transmit - t.camera_mid_exposure) as f64 / freq as f64 * 1e6;
                // A second or more is a clock that does not tick as described: ignored.
                if us < 1e6 { us as i64 } else { 0 }
            }
            _ => 0,
        }
    }
}

/// How to reach a NatNet server.
#[derive(Clone, Debug)]
pub struct SourceOptions {
    /// Command address.
    pub command: SocketAddr,
    /// Local interface.
    pub local: Ipv4Addr,
    /// Multicast group, if any.
    pub multicast: Option<Ipv4Addr>,
    /// Data port (0 = any, unicast only).
    pub data_port: u16,
    /// How long to wait for each answer of the handshake.
    pub timeout: Duration,
}

/// A connected NatNet server: its version, descriptions, and the sockets frames come on.
#[derive(Debug)]
pub struct Source {
    command: UdpSocket,
    data: UdpSocket,
    server: SocketAddr,
    /// The server's NAT_SERVERINFO.
    pub info: ServerInfo,
    /// Its data descriptions.
    pub descriptions: DataDescriptions,
    last_keep_alive: Instant,
    buf: Vec<u8>,
    buf2: Vec<u8>,
}

/// Largest UDP payload.
const DATAGRAM: usize = 65536;

/// Waits up to `timeout` for a datagram of message `id` from the server on `sock`, sending
/// `request` now and again every second; other datagrams are skipped.
async fn ask(
    sock: &UdpSocket,
    server: SocketAddr,
    request: &[u8],
    id: u16,
    timeout: Duration,
    what: &str,
) -> anyhow::Result<Vec<u8>> {
    let start = Instant::now();
    let mut buf = vec![0u8; DATAGRAM];
    while start.elapsed() < timeout {
        sock.send_to(request, server)
            .await
            .with_context(|| format!("sending {what} to {server}"))?;
        let round = Instant::now();
        while round.elapsed() < Duration::from_secs(1) {
            let left = Duration::from_secs(1).saturating_sub(round.elapsed());
            match tokio::time::timeout(left, sock.recv_from(&mut buf)).await {
                Ok(Ok((n, _))) if wire::header(&buf[..n]).is_ok_and(|(i, _)| i == id) => {
                    return Ok(buf[..n].to_vec());
                }
                Ok(Ok(_)) => {}
                // A refused port on loopback shows as an error on the next receive.
                Ok(Err(_)) => tokio::time::sleep(Duration::from_millis(50)).await,
                Err(_) => break,
            }
        }
    }
    bail!(
        "no answer to {what} from the NatNet server at {server} in {:.0} s (is Motive streaming, \
         with this command port?)",
        timeout.as_secs_f64()
    )
}

impl Source {
    /// The handshake: NAT_CONNECT until NAT_SERVERINFO (refusing versions not read), then the
    /// model definitions; opens the data socket.
    ///
    /// # Errors
    /// Sockets that cannot be opened, a silent server, an unsupported version (named), or
    /// descriptions that do not decode.
    pub async fn connect(opts: &SourceOptions) -> anyhow::Result<Self> {
        let command = UdpSocket::bind(SocketAddr::new(IpAddr::V4(opts.local), 0))
            .await
            .context("opening the NatNet command socket")?;
        let data = match opts.multicast {
            Some(group) => {
                if opts.data_port == 0 {
                    bail!("--multicast needs the server's data port (--data-port)");
                }
                let s = UdpSocket::bind(SocketAddr::new(
                    IpAddr::V4(Ipv4Addr::UNSPECIFIED),
                    opts.data_port,
                ))
                .await
                .with_context(|| format!("binding the data port {}", opts.data_port))?;
                s.join_multicast_v4(group, opts.local)
                    .with_context(|| format!("joining the multicast group {group}"))?;
                s
            }
            None => UdpSocket::bind(SocketAddr::new(IpAddr::V4(opts.local), opts.data_port))
                .await
                .with_context(|| format!("binding the data port {}", opts.data_port))?,
        };
        let server = opts.command;
        let reply = ask(
            &command,
            server,
            &encode::connect(Version::new(4, 1)),
            NAT_SERVERINFO,
            opts.timeout,
            "NAT_CONNECT",
        )
        .await?;
        let info = wire::decode_server_info(&reply)
            .with_context(|| format!("the NAT_SERVERINFO of {server}"))?;
        if !info.natnet.is_supported() {
            bail!(
                "the NatNet server at {server} ({} {}) streams NatNet {}; crease bridge natnet reads {}",
                info.name,
                info.app_version.map(|b| b.to_string()).join("."),
                info.natnet,
                wire::SUPPORTED
            );
        }
        let reply = ask(
            &command,
            server,
            &encode::request_model_def(),
            NAT_MODELDEF,
            opts.timeout,
            "NAT_REQUEST_MODELDEF",
        )
        .await?;
        let descriptions = wire::decode_descriptions(&reply, info.natnet)
            .with_context(|| format!("the data descriptions of {server}"))?;
        Ok(Self {
            command,
            data,
            server,
            info,
            descriptions,
            last_keep_alive: Instant::now(),
            buf: vec![0u8; DATAGRAM],
            buf2: vec![0u8; DATAGRAM],
        })
    }

    /// The local address frames of data are received on (unicast).
    pub fn data_addr(&self) -> std::io::Result<SocketAddr> {
        self.data.local_addr()
    }

    /// The next datagram from the data socket or the command socket (a unicast server may
    /// send frames there), with a keep-alive every second on the command socket.
    ///
    /// # Errors
    /// A socket error.
    pub async fn next(&mut self) -> std::io::Result<Vec<u8>> {
        loop {
            if self.last_keep_alive.elapsed() >= Duration::from_secs(1) {
                self.last_keep_alive = Instant::now();
                // Best effort: a lost keep-alive is sent again a second later.
                let _ = self
                    .command
                    .send_to(&encode::keep_alive(), self.server)
                    .await;
            }
            let got = tokio::select! {
                r = self.data.recv_from(&mut self.buf) => r.map(|(n, _)| self.buf[..n].to_vec()),
                r = self.command.recv_from(&mut self.buf2) => r.map(|(n, _)| self.buf2[..n].to_vec()),
                () = tokio::time::sleep(Duration::from_secs(1)) => continue,
            };
            match got {
                Ok(d) => return Ok(d),
                // ICMP port unreachable from an earlier send: not a datagram.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(e),
            }
        }
    }
}

/// Receives datagrams from `source` into `bridge` and sends each frame into `sink` (recording
/// its capture time in `sent_at`, if given), until `frames` are sent (if given) or the stream
/// ends.
///
/// # Errors
/// A socket error.
pub async fn pump(
    source: &mut Source,
    bridge: &mut Bridge,
    sink: &mut Sink,
    frames: Option<u64>,
    sent_at: Option<&SentLog<i64>>,
) -> anyhow::Result<()> {
    let mut sent = 0u64;
    while frames.is_none_or(|n| sent < n) {
        let d = source
            .next()
            .await
            .context("receiving from the NatNet server")?;
        if let Outcome::Frame(f, _) = bridge.datagram(&d, unix_us()) {
            if let Some(log) = sent_at {
                log.record(f.seq, f.capture_time_us, None);
            }
            if sink.send(*f).await.is_err() {
                break;
            }
            bridge.counters().published += 1;
            sent += 1;
        }
    }
    Ok(())
}

/// The command address: `HOST[:PORT]`, port 1510 by default.
///
/// # Errors
/// Not a host and port, or no IPv4 address for the host.
pub fn command_addr(s: &str) -> anyhow::Result<SocketAddr> {
    use std::net::ToSocketAddrs;
    let with_port = if s.parse::<SocketAddr>().is_ok()
        || s.rsplit_once(':')
            .is_some_and(|(h, p)| !h.contains(':') && p.parse::<u16>().is_ok())
    {
        s.to_owned()
    } else {
        format!("{s}:1510")
    };
    with_port
        .to_socket_addrs()
        .with_context(|| format!("--natnet {s:?}: not a HOST[:PORT]"))?
        .find(SocketAddr::is_ipv4)
        .with_context(|| format!("--natnet {s:?}: no IPv4 address"))
}

fn summary(c: &mut Counters, last_error: Option<&str>) -> String {
    c.latency_us.sort_unstable();
    let line = format!(
        "natnet: {} frames in, {} published ({} acked, {} refused), {} dropped (malformed), {} other messages; {} invalid markers; source-to-ack p50 {} µs p99 {} µs{}",
        c.frames_in,
        c.published,
        c.acked,
        c.refused,
        c.dropped,
        c.ignored,
        c.invalid_markers,
        percentile(&c.latency_us, 50.0),
        percentile(&c.latency_us, 99.0),
        last_error.map_or(String::new(), |e| format!("; last malformed: {e}"))
    );
    c.latency_us.clear();
    line
}

/// Runs the bridge: resolves the room's declared markers against the NatNet server's
/// descriptions, then publishes its frames into the room through the publish loop until
/// `frames` are sent or interrupted (Ctrl-C), with summary lines on stderr and the last one on
/// stdout.
///
/// # Errors
/// A room that does not retarget, the NatNet handshake's errors, unknown or ambiguous marker
/// names, a refused Publish stream, or a socket error.
pub async fn run(client: &mut CreaseClient<Channel>, opts: NatnetOptions) -> anyhow::Result<()> {
    let room = get_room(client, &opts.room).await?;
    let declared = room
        .retarget
        .as_ref()
        .map(|r| r.markers.clone())
        .with_context(|| {
            format!(
                "room {:?} is not a retargeting room (no RoomInfo.retarget): open it with a marker map",
                opts.room
            )
        })?;
    let mut source = Source::connect(&opts.source).await?;
    let map = MarkerSources::resolve(&declared, &source.descriptions)
        .with_context(|| format!("room {:?}", opts.room))?;
    eprintln!(
        "natnet: {} ({}) streams NatNet {}; {} room markers mapped{}",
        opts.source.command,
        source.info.name,
        source.info.natnet,
        declared.len(),
        source
            .descriptions
            .stopped_at
            .map_or(String::new(), |t| format!(
                " (descriptions read up to one of type {t})"
            ))
    );
    let mut bridge = Bridge::new(source.info.natnet, Some(&source.info), &opts.room, map);
    let counters = Arc::clone(&bridge.counters);
    // seq -> capture time, for the latency at the ack.
    let sent_at = Arc::new(SentLog::<i64>::default());
    let (every, frames) = (opts.summary_every, opts.frames);
    let pumping = {
        let (counters, sent_at) = (Arc::clone(&counters), Arc::clone(&sent_at));
        move |mut sink: Sink| async move {
            let mut ticker = tokio::time::interval(every);
            ticker.tick().await;
            let pumped = {
                let run = pump(&mut source, &mut bridge, &mut sink, frames, Some(&sent_at));
                tokio::pin!(run);
                loop {
                    tokio::select! {
                        r = &mut run => break r,
                        _ = ticker.tick() => {
                            let line = summary(&mut counters.lock().unwrap_or_else(|e| e.into_inner()), None);
                            eprintln!("{line}");
                        }
                        _ = tokio::signal::ctrl_c() => break Ok(()),
                    }
                }
            };
            (pumped, bridge.last_error().map(str::to_owned))
        }
    };
    let mut shown = 0;
    let mut on_ack = |ack: v1::PublishAck| {
        let capture = sent_at.take(ack.seq);
        let mut c = counters.lock().unwrap_or_else(|e| e.into_inner());
        match ack.error {
            Some(e) => {
                c.refused += 1;
                if shown < 10 {
                    shown += 1;
                    eprintln!(
                        "frame {}: refused (code {}): {}",
                        ack.seq, e.code, e.message
                    );
                }
            }
            None => {
                c.acked += 1;
                if let Some(t) = capture {
                    c.latency_us.push(unix_us() - t);
                }
            }
        }
        ControlFlow::Continue(())
    };
    let options = PublishOptions {
        queue: 64,
        // The last acks, briefly.
        drain: Some(Duration::from_secs(2)),
    };
    let published = publish(client, &opts.token, options, pumping, &mut on_ack)
        .await
        .map_err(|e| match e {
            PublishError::Open(s) => {
                anyhow::Error::new(s).context(format!("publishing into room {:?}", opts.room))
            }
            e => e.into_anyhow("--token", "publishing", "the bridge"),
        })?;
    let (pumped, last_error) = published.output;
    let line = summary(
        &mut counters.lock().unwrap_or_else(|e| e.into_inner()),
        last_error.as_deref(),
    );
    println!("{line}");
    pumped
}
