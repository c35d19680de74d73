//! NatNet messages as they come off the wire, decoded: the version handshake (NAT_CONNECT /
//! NAT_SERVERINFO, ids 0 and 1), data descriptions (NAT_MODELDEF, id 5: marker set and rigid
//! body names) and frames of data (NAT_FRAMEOFDATA, id 7), for NatNet 3.0, 3.1, 4.0 and 4.1.
//!
//! Every read is bounds-checked and every count is checked against the bytes left before
//! anything is allocated, so no input panics; an error names the field and its byte offset
//! in the datagram. The layouts follow NaturalPoint's own sample decoder (`natnetsdk` 4.1.1,
//! `NatNetClient.py`), with one correction: the precision timestamp of the frame suffix is
//! read from 4.1 on, not from 4.0 (the sample reads it on 4.0 too, and mis-reads 4.0 frames).
//!
//! Frame of data, by version (`[4.1]` = a section byte count after the section's count):
//! ```text
//! i32 frame number
//! i32 marker sets [4.1]      : cstr name, i32 n, n x f32[3]
//! i32 unlabelled markers [4.1]: f32[3]
//! i32 rigid bodies [4.1]     : i32 id, f32[3] pos, f32[4] quat xyzw, f32 mean error, u16 params
//! i32 skeletons [4.1]        : i32 id, i32 n, n x rigid body
//! i32 assets (4.1 only) [4.1]: i32 id, i32 n, n x rigid body, i32 m, m x labelled marker
//! i32 labelled markers [4.1] : i32 id (model << 16 | marker), f32[3] pos, f32 size, u16 params,
//!                              f32 residual
//! i32 force plates [4.1]     : i32 id, i32 channels, per channel i32 n, n x f32
//! i32 devices [4.1]          : as force plates
//! u32 timecode, u32 subframe, f64 timestamp, u64 mid-exposure, u64 data received, u64 transmit,
//! (4.1) u32 precision seconds, u32 precision fraction, u16 params, [i32 end of data = 0]
//! ```

use std::fmt;

/// NAT_CONNECT: a client's hello on the command port.
pub const NAT_CONNECT: u16 = 0;
/// NAT_SERVERINFO: the server's answer to NAT_CONNECT (its name and NatNet version).
pub const NAT_SERVERINFO: u16 = 1;
/// NAT_REQUEST: a text command.
pub const NAT_REQUEST: u16 = 2;
/// NAT_RESPONSE: the answer to a NAT_REQUEST.
pub const NAT_RESPONSE: u16 = 3;
/// NAT_REQUEST_MODELDEF: asks for the data descriptions.
pub const NAT_REQUEST_MODELDEF: u16 = 4;
/// NAT_MODELDEF: the data descriptions.
pub const NAT_MODELDEF: u16 = 5;
/// NAT_FRAMEOFDATA: one frame of data.
pub const NAT_FRAMEOFDATA: u16 = 7;
/// NAT_MESSAGESTRING: a text message from the server.
pub const NAT_MESSAGESTRING: u16 = 8;
/// NAT_KEEPALIVE: keeps a unicast subscription alive.
pub const NAT_KEEPALIVE: u16 = 10;

/// Labelled marker parameter bit: occluded (not seen this frame; the position is a guess).
pub const MARKER_OCCLUDED: u16 = 0x01;
/// Labelled marker parameter bit: solved from the point cloud.
pub const MARKER_POINT_CLOUD_SOLVED: u16 = 0x02;
/// Labelled marker parameter bit: solved from the model.
pub const MARKER_MODEL_SOLVED: u16 = 0x04;

/// A NatNet version, `major.minor.build.revision`, as the four bytes of NAT_SERVERINFO.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Version {
    /// Major version.
    pub major: u8,
    /// Minor version.
    pub minor: u8,
    /// Build.
    pub build: u8,
    /// Revision.
    pub revision: u8,
}

impl Version {
    /// `major.minor.0.0`.
    pub const fn new(major: u8, minor: u8) -> Self {
        Self {
            major,
            minor,
            build: 0,
            revision: 0,
        }
    }

    /// Whether this is at least `major.minor`.
    pub const fn at_least(self, major: u8, minor: u8) -> bool {
        self.major > major || (self.major == major && self.minor >= minor)
    }

    /// Whether this decoder reads this version's layout (3.0, 3.1, 4.0, 4.1).
    pub const fn is_supported(self) -> bool {
        matches!((self.major, self.minor), (3, 0 | 1) | (4, 0 | 1))
    }

    /// Sections carry a byte count after their count (4.1 on).
    const fn sized(self) -> bool {
        self.at_least(4, 1)
    }
}

impl fmt::Display for Version {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}.{}.{}.{}",
            self.major, self.minor, self.build, self.revision
        )
    }
}

/// The versions [`decode`] reads, for messages.
pub const SUPPORTED: &str = "3.0, 3.1, 4.0 and 4.1";

/// Why a datagram did not decode: the field, its byte offset in the datagram, the problem.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DecodeError {
    /// The field being read, with the section and entry it belongs to.
    pub field: String,
    /// Byte offset of the field in the datagram (header included).
    pub offset: usize,
    /// What was wrong.
    pub problem: String,
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} at byte {}: {}",
            self.field, self.offset, self.problem
        )
    }
}

impl std::error::Error for DecodeError {}

/// Result of a decode.
pub type Result<T> = std::result::Result<T, DecodeError>;

/// A bounds-checked little-endian reader over a datagram, with the section and entry being
/// read for error messages.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    section: &'static str,
    entry: Option<usize>,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8], pos: usize) -> Self {
        Self {
            buf,
            pos,
            section: "",
            entry: None,
        }
    }

    fn err(&self, field: &str, offset: usize, problem: impl Into<String>) -> DecodeError {
        let mut name = String::new();
        if !self.section.is_empty() {
            name.push_str(self.section);
            if let Some(i) = self.entry {
                name.push_str(&format!(" {i}"));
            }
            name.push_str(": ");
        }
        name.push_str(field);
        DecodeError {
            field: name,
            offset,
            problem: problem.into(),
        }
    }

    fn left(&self) -> usize {
        self.buf.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if self.left() < n {
            return Err(self.err(
                field,
                self.pos,
                format!(
                    "needs {n} bytes, the datagram has {} left of {}",
                    self.left(),
                    self.buf.len()
                ),
            ));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N]> {
        let s = self.take(N, field)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    fn u8(&mut self, field: &str) -> Result<u8> {
        Ok(self.array::<1>(field)?[0])
    }
    fn u16(&mut self, field: &str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array(field)?))
    }
    fn i32(&mut self, field: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(field)?))
    }
    fn u32(&mut self, field: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }
    fn u64(&mut self, field: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(field)?))
    }
    fn f32(&mut self, field: &str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array(field)?))
    }
    fn f64(&mut self, field: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(field)?))
    }
    fn vec3(&mut self, field: &str) -> Result<[f32; 3]> {
        Ok([self.f32(field)?, self.f32(field)?, self.f32(field)?])
    }
    fn quat(&mut self, field: &str) -> Result<[f32; 4]> {
        Ok([
            self.f32(field)?,
            self.f32(field)?,
            self.f32(field)?,
            self.f32(field)?,
        ])
    }

    /// A NUL-terminated string (lossy UTF-8).
    fn cstr(&mut self, field: &str) -> Result<String> {
        let rest = &self.buf[self.pos.min(self.buf.len())..];
        let Some(end) = rest.iter().position(|&b| b == 0) else {
            return Err(self.err(field, self.pos, "string without its terminating NUL"));
        };
        let s = String::from_utf8_lossy(&rest[..end]).into_owned();
        self.pos += end + 1;
        Ok(s)
    }

    /// A fixed-size NUL-padded string field of `n` bytes.
    fn fixed_str(&mut self, n: usize, field: &str) -> Result<String> {
        let s = self.take(n, field)?;
        let end = s.iter().position(|&b| b == 0).unwrap_or(s.len());
        Ok(String::from_utf8_lossy(&s[..end]).into_owned())
    }

    /// A count of entries of at least `min_entry` bytes each: not negative, and not more
    /// than the bytes left could hold.
    fn count(&mut self, field: &str, min_entry: usize) -> Result<usize> {
        let at = self.pos;
        let n = self.i32(field)?;
        if n < 0 {
            return Err(self.err(field, at, format!("negative count {n}")));
        }
        let n = n as usize;
        if n.saturating_mul(min_entry.max(1)) > self.left() {
            return Err(self.err(
                field,
                at,
                format!(
                    "count {n} needs at least {} bytes, {} left",
                    n.saturating_mul(min_entry.max(1)),
                    self.left()
                ),
            ));
        }
        Ok(n)
    }
}

/// The 4-byte header of every NatNet message: id and payload size.
///
/// # Errors
/// A datagram shorter than the header, or whose size field claims more than it holds.
pub fn header(datagram: &[u8]) -> Result<(u16, &[u8])> {
    let mut r = Reader::new(datagram, 0);
    let id = r.u16("message id")?;
    let size = r.u16("packet size")? as usize;
    if size > r.left() {
        return Err(r.err(
            "packet size",
            2,
            format!(
                "says {size} bytes of payload, the datagram holds {}",
                r.left()
            ),
        ));
    }
    // The size field is 16 bits; a larger frame's datagram is longer than it says.
    Ok((id, &datagram[4..]))
}

/// NAT_SERVERINFO: who the server is and which NatNet version it streams.
#[derive(Clone, Debug, PartialEq)]
pub struct ServerInfo {
    /// Application name (e.g. "Motive").
    pub name: String,
    /// Application version.
    pub app_version: [u8; 4],
    /// NatNet stream version.
    pub natnet: Version,
    /// High-resolution clock ticks per second (of the frame's timestamps), when sent.
    pub clock_frequency: Option<u64>,
    /// The data port, when sent.
    pub data_port: Option<u16>,
    /// Whether the server streams multicast, when sent.
    pub multicast: Option<bool>,
    /// The multicast group, when sent.
    pub multicast_group: Option<[u8; 4]>,
}

/// Decodes a NAT_SERVERINFO datagram (header included).
///
/// # Errors
/// Another message id or too few bytes, naming the field.
pub fn decode_server_info(datagram: &[u8]) -> Result<ServerInfo> {
    let (id, _) = header(datagram)?;
    if id != NAT_SERVERINFO {
        return Err(wrong_id(id, NAT_SERVERINFO));
    }
    let mut r = Reader::new(datagram, 4);
    r.section = "server info";
    let name = r.fixed_str(256, "application name")?;
    let app_version = r.array::<4>("application version")?;
    let v = r.array::<4>("NatNet version")?;
    let natnet = Version {
        major: v[0],
        minor: v[1],
        build: v[2],
        revision: v[3],
    };
    // The connection info (NatNet 3.0 on) is optional: older senders stop here.
    let mut info = ServerInfo {
        name,
        app_version,
        natnet,
        clock_frequency: None,
        data_port: None,
        multicast: None,
        multicast_group: None,
    };
    if r.left() >= 15 {
        info.clock_frequency = Some(r.u64("high-resolution clock frequency")?);
        info.data_port = Some(r.u16("data port")?);
        info.multicast = Some(r.u8("multicast flag")? != 0);
        info.multicast_group = Some(r.array::<4>("multicast group")?);
    }
    Ok(info)
}

fn wrong_id(id: u16, want: u16) -> DecodeError {
    DecodeError {
        field: "message id".into(),
        offset: 0,
        problem: format!("is {id}, expected {want}"),
    }
}

/// A marker set's markers in a frame, in its description's order.
#[derive(Clone, Debug, PartialEq)]
pub struct MarkerSet {
    /// The marker set's name.
    pub name: String,
    /// Marker positions.
    pub markers: Vec<[f32; 3]>,
}

/// A rigid body's pose in a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidBody {
    /// Streaming id (as in its description).
    pub id: i32,
    /// Position.
    pub position: [f32; 3],
    /// Orientation quaternion, x y z w.
    pub orientation: [f32; 4],
    /// Mean marker error.
    pub mean_error: f32,
    /// Parameters: bit 0 = tracking valid.
    pub params: u16,
}

impl RigidBody {
    /// Whether the body was tracked this frame.
    pub const fn tracking_valid(&self) -> bool {
        self.params & 1 != 0
    }
}

/// A skeleton's bones in a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    /// Streaming id.
    pub id: i32,
    /// The bones' poses.
    pub bones: Vec<RigidBody>,
}

/// An asset's rigid bodies and markers (NatNet 4.1).
#[derive(Clone, Debug, PartialEq)]
pub struct Asset {
    /// Streaming id.
    pub id: i32,
    /// Rigid bodies.
    pub rigid_bodies: Vec<RigidBody>,
    /// Markers.
    pub markers: Vec<LabeledMarker>,
}

/// A labelled marker in a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LabeledMarker {
    /// `model id << 16 | marker id`.
    pub id: i32,
    /// Position.
    pub position: [f32; 3],
    /// Marker size.
    pub size: f32,
    /// Parameter bits ([`MARKER_OCCLUDED`], ...).
    pub params: u16,
    /// Residual (metres in the stream; the sample decoder prints it in mm).
    pub residual: f32,
}

impl LabeledMarker {
    /// The model (rigid body or asset streaming id; 0 = unlabelled).
    pub const fn model_id(&self) -> i32 {
        self.id >> 16
    }
    /// The marker's id within its model (1-based for a rigid body's markers).
    pub const fn marker_id(&self) -> i32 {
        self.id & 0xffff
    }
    /// Whether the marker was occluded this frame.
    pub const fn occluded(&self) -> bool {
        self.params & MARKER_OCCLUDED != 0
    }
}

/// A force plate's or device's analog channels in a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Analog {
    /// Streaming id.
    pub id: i32,
    /// Per channel, its samples this frame.
    pub channels: Vec<Vec<f32>>,
}

/// The frame's clocks.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timing {
    /// SMPTE timecode.
    pub timecode: u32,
    /// Timecode subframe.
    pub timecode_sub: u32,
    /// Seconds since the take started.
    pub timestamp: f64,
    /// High-resolution clock at mid-exposure.
    pub camera_mid_exposure: u64,
    /// High-resolution clock when the camera data was received.
    pub camera_data_received: u64,
    /// High-resolution clock when the frame was sent.
    pub transmit: u64,
    /// Precision timestamp, seconds (4.1; 0 otherwise).
    pub precision_secs: u32,
    /// Precision timestamp, fractional seconds (4.1; 0 otherwise).
    pub precision_frac: u32,
}

/// NAT_FRAMEOFDATA, decoded.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameOfData {
    /// Frame number.
    pub frame_number: i32,
    /// Marker sets.
    pub marker_sets: Vec<MarkerSet>,
    /// Unlabelled ("other", legacy) markers.
    pub other_markers: Vec<[f32; 3]>,
    /// Rigid bodies.
    pub rigid_bodies: Vec<RigidBody>,
    /// Skeletons.
    pub skeletons: Vec<Skeleton>,
    /// Assets (4.1).
    pub assets: Vec<Asset>,
    /// Labelled markers.
    pub labeled_markers: Vec<LabeledMarker>,
    /// Force plates.
    pub force_plates: Vec<Analog>,
    /// Devices.
    pub devices: Vec<Analog>,
    /// Clocks.
    pub timing: Timing,
    /// Frame parameters: bit 0 recording, bit 1 tracked models changed.
    pub params: u16,
}

/// Rigid body entry bytes: id, position, quaternion, error, params.
pub(crate) const RIGID_BODY_BYTES: usize = 4 + 12 + 16 + 4 + 2;
/// Labelled marker entry bytes: id, position, size, params, residual.
pub(crate) const LABELED_MARKER_BYTES: usize = 4 + 12 + 4 + 2 + 4;

/// Reads a section's header: its count and, on 4.1, its byte count; returns the count and
/// where the section must end (4.1).
fn section(
    r: &mut Reader<'_>,
    name: &'static str,
    version: Version,
    min_entry: usize,
) -> Result<(usize, Option<usize>)> {
    r.section = name;
    r.entry = None;
    let n = r.count("count", min_entry)?;
    let end = byte_count(r, version)?;
    Ok((n, end))
}

/// From 4.1 on, the byte count before a section or a description: where it must end (checked
/// against the bytes left); `None` before 4.1, which has no counts.
fn byte_count(r: &mut Reader<'_>, version: Version) -> Result<Option<usize>> {
    if !version.sized() {
        return Ok(None);
    }
    let at = r.pos;
    let size = r.i32("byte count")?;
    if size < 0 || size as usize > r.left() {
        return Err(r.err(
            "byte count",
            at,
            format!("{size} does not fit the {} bytes left", r.left()),
        ));
    }
    Ok(Some(r.pos + size as usize))
}

/// Ends a 4.1 section: an overrun is an error, unread bytes (a newer server's additions) are
/// skipped.
fn end_section(r: &mut Reader<'_>, end: Option<usize>) -> Result<()> {
    r.entry = None;
    if let Some(end) = end {
        if r.pos > end {
            return Err(r.err(
                "entries",
                end,
                format!("run {} bytes past the section's byte count", r.pos - end),
            ));
        }
        r.pos = end;
    }
    Ok(())
}

fn rigid_body(r: &mut Reader<'_>) -> Result<RigidBody> {
    Ok(RigidBody {
        id: r.i32("id")?,
        position: r.vec3("position")?,
        orientation: r.quat("orientation")?,
        mean_error: r.f32("mean marker error")?,
        params: r.u16("params")?,
    })
}

fn labeled_marker(r: &mut Reader<'_>) -> Result<LabeledMarker> {
    Ok(LabeledMarker {
        id: r.i32("id")?,
        position: r.vec3("position")?,
        size: r.f32("size")?,
        params: r.u16("params")?,
        residual: r.f32("residual")?,
    })
}

fn analog(r: &mut Reader<'_>) -> Result<Analog> {
    let id = r.i32("id")?;
    let nc = r.count("channel count", 4)?;
    let mut channels = Vec::with_capacity(nc);
    for _ in 0..nc {
        let nf = r.count("channel frame count", 4)?;
        let mut v = Vec::with_capacity(nf);
        for _ in 0..nf {
            v.push(r.f32("channel value")?);
        }
        channels.push(v);
    }
    Ok(Analog { id, channels })
}

/// Decodes the entries of one section with `entry`.
fn entries<T>(
    r: &mut Reader<'_>,
    name: &'static str,
    version: Version,
    min_entry: usize,
    mut entry: impl FnMut(&mut Reader<'_>) -> Result<T>,
) -> Result<Vec<T>> {
    let (n, end) = section(r, name, version, min_entry)?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        r.entry = Some(i);
        out.push(entry(r)?);
    }
    end_section(r, end)?;
    Ok(out)
}

/// Decodes a NAT_FRAMEOFDATA datagram (header included) of NatNet `version`.
///
/// # Errors
/// An unsupported version, another message id, or a field that does not fit, named with its
/// byte offset.
pub fn decode_frame(datagram: &[u8], version: Version) -> Result<FrameOfData> {
    if !version.is_supported() {
        return Err(unsupported(version));
    }
    let (id, _) = header(datagram)?;
    if id != NAT_FRAMEOFDATA {
        return Err(wrong_id(id, NAT_FRAMEOFDATA));
    }
    let mut r = Reader::new(datagram, 4);
    let v = version;
    r.section = "frame";
    let frame_number = r.i32("frame number")?;
    let marker_sets = entries(&mut r, "marker set", v, 5, |r| {
        let name = r.cstr("name")?;
        let n = r.count("marker count", 12)?;
        let mut markers = Vec::with_capacity(n);
        for _ in 0..n {
            markers.push(r.vec3("marker position")?);
        }
        Ok(MarkerSet { name, markers })
    })?;
    let other_markers = entries(&mut r, "unlabelled marker", v, 12, |r| r.vec3("position"))?;
    let rigid_bodies = entries(&mut r, "rigid body", v, RIGID_BODY_BYTES, rigid_body)?;
    let skeletons = entries(&mut r, "skeleton", v, 8, |r| {
        let id = r.i32("id")?;
        let n = r.count("rigid body count", RIGID_BODY_BYTES)?;
        let mut bones = Vec::with_capacity(n);
        for _ in 0..n {
            bones.push(rigid_body(r)?);
        }
        Ok(Skeleton { id, bones })
    })?;
    let assets = if v.at_least(4, 1) {
        entries(&mut r, "asset", v, 12, |r| {
            let id = r.i32("id")?;
            let n = r.count("rigid body count", RIGID_BODY_BYTES)?;
            let mut rigid_bodies = Vec::with_capacity(n);
            for _ in 0..n {
                rigid_bodies.push(rigid_body(r)?);
            }
            let m = r.count("marker count", LABELED_MARKER_BYTES)?;
            let mut markers = Vec::with_capacity(m);
            for _ in 0..m {
                markers.push(labeled_marker(r)?);
            }
            Ok(Asset {
                id,
                rigid_bodies,
                markers,
            })
        })?
    } else {
        Vec::new()
    };
    let labeled_markers = entries(
        &mut r,
        "labelled marker",
        v,
        LABELED_MARKER_BYTES,
        labeled_marker,
    )?;
    let force_plates = entries(&mut r, "force plate", v, 8, analog)?;
    let devices = entries(&mut r, "device", v, 8, analog)?;
    r.section = "frame suffix";
    r.entry = None;
    let mut timing = Timing {
        timecode: r.u32("timecode")?,
        timecode_sub: r.u32("timecode subframe")?,
        timestamp: r.f64("timestamp")?,
        camera_mid_exposure: r.u64("camera mid-exposure timestamp")?,
        camera_data_received: r.u64("camera data received timestamp")?,
        transmit: r.u64("transmit timestamp")?,
        ..Timing::default()
    };
    if v.at_least(4, 1) {
        timing.precision_secs = r.u32("precision timestamp seconds")?;
        timing.precision_frac = r.u32("precision timestamp fraction")?;
    }
    let params = r.u16("frame params")?;
    // An end-of-data tag (i32 0) may follow; nothing after the params is read.
    Ok(FrameOfData {
        frame_number,
        marker_sets,
        other_markers,
        rigid_bodies,
        skeletons,
        assets,
        labeled_markers,
        force_plates,
        devices,
        timing,
        params,
    })
}

fn unsupported(version: Version) -> DecodeError {
    DecodeError {
        field: "NatNet version".into(),
        offset: 0,
        problem: format!("{version} is not read (supported: {SUPPORTED})"),
    }
}

/// A marker set's description: its name and its markers' names, in frame order.
#[derive(Clone, Debug, PartialEq)]
pub struct MarkerSetDesc {
    /// Name.
    pub name: String,
    /// Marker names.
    pub markers: Vec<String>,
}

/// One marker of a rigid body's description.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidBodyMarkerDesc {
    /// Offset from the body's origin.
    pub offset: [f32; 3],
    /// Active label.
    pub active_label: i32,
    /// Name (NatNet 4.0 on; empty before).
    pub name: String,
}

/// A rigid body's description.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidBodyDesc {
    /// Name.
    pub name: String,
    /// Streaming id (the frame's rigid body id, and a labelled marker's model id).
    pub id: i32,
    /// Parent's id (-1 none).
    pub parent_id: i32,
    /// Offset from the parent.
    pub offset: [f32; 3],
    /// Markers, in the order of their 1-based labelled marker ids.
    pub markers: Vec<RigidBodyMarkerDesc>,
}

/// A skeleton's description.
#[derive(Clone, Debug, PartialEq)]
pub struct SkeletonDesc {
    /// Name.
    pub name: String,
    /// Streaming id.
    pub id: i32,
    /// Bones.
    pub bones: Vec<RigidBodyDesc>,
}

/// NAT_MODELDEF, as far as the bridge needs it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DataDescriptions {
    /// Marker sets.
    pub marker_sets: Vec<MarkerSetDesc>,
    /// Rigid bodies.
    pub rigid_bodies: Vec<RigidBodyDesc>,
    /// Skeletons.
    pub skeletons: Vec<SkeletonDesc>,
    /// Descriptions of other types (force plates, devices, cameras, assets) skipped, by type.
    pub skipped: Vec<i32>,
    /// Before 4.1 a description of a type not read here cannot be skipped (it has no byte
    /// count): the type at which reading stopped.
    pub stopped_at: Option<i32>,
}

/// Description type ids.
pub const DESC_MARKER_SET: i32 = 0;
/// Rigid body description.
pub const DESC_RIGID_BODY: i32 = 1;
/// Skeleton description.
pub const DESC_SKELETON: i32 = 2;

fn rigid_body_desc(r: &mut Reader<'_>, v: Version) -> Result<RigidBodyDesc> {
    let name = r.cstr("name")?;
    let id = r.i32("id")?;
    let parent_id = r.i32("parent id")?;
    let offset = r.vec3("offset")?;
    let n = r.count("marker count", 16)?;
    let mut offsets = Vec::with_capacity(n);
    for _ in 0..n {
        offsets.push(r.vec3("marker offset")?);
    }
    let mut labels = Vec::with_capacity(n);
    for _ in 0..n {
        labels.push(r.i32("marker active label")?);
    }
    let mut markers = Vec::with_capacity(n);
    for (offset, active_label) in offsets.into_iter().zip(labels) {
        let name = if v.major >= 4 {
            r.cstr("marker name")?
        } else {
            String::new()
        };
        markers.push(RigidBodyMarkerDesc {
            offset,
            active_label,
            name,
        });
    }
    Ok(RigidBodyDesc {
        name,
        id,
        parent_id,
        offset,
        markers,
    })
}

/// Decodes a NAT_MODELDEF datagram (header included) of NatNet `version`: marker sets, rigid
/// bodies and skeletons; other descriptions are skipped on 4.1 (by their byte count) and end
/// the reading before (see [`DataDescriptions::stopped_at`]).
///
/// # Errors
/// An unsupported version, another message id, or a field that does not fit.
pub fn decode_descriptions(datagram: &[u8], version: Version) -> Result<DataDescriptions> {
    if !version.is_supported() {
        return Err(unsupported(version));
    }
    let (id, _) = header(datagram)?;
    if id != NAT_MODELDEF {
        return Err(wrong_id(id, NAT_MODELDEF));
    }
    let mut r = Reader::new(datagram, 4);
    r.section = "data descriptions";
    let n = r.count("count", 8)?;
    let mut out = DataDescriptions::default();
    for i in 0..n {
        r.section = "data description";
        r.entry = Some(i);
        let kind = r.i32("type")?;
        let end = byte_count(&mut r, version)?;
        match kind {
            DESC_MARKER_SET => {
                let name = r.cstr("marker set name")?;
                let m = r.count("marker count", 1)?;
                let mut markers = Vec::with_capacity(m);
                for _ in 0..m {
                    markers.push(r.cstr("marker name")?);
                }
                out.marker_sets.push(MarkerSetDesc { name, markers });
            }
            DESC_RIGID_BODY => out.rigid_bodies.push(rigid_body_desc(&mut r, version)?),
            DESC_SKELETON => {
                let name = r.cstr("skeleton name")?;
                let id = r.i32("skeleton id")?;
                let b = r.count("bone count", 28)?;
                let mut bones = Vec::with_capacity(b);
                for _ in 0..b {
                    bones.push(rigid_body_desc(&mut r, version)?);
                }
                out.skeletons.push(SkeletonDesc { name, id, bones });
            }
            other => {
                if end.is_none() {
                    out.stopped_at = Some(other);
                    return Ok(out);
                }
                out.skipped.push(other);
            }
        }
        end_section(&mut r, end)?;
    }
    Ok(out)
}

/// A datagram decoded by its id.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// NAT_SERVERINFO.
    ServerInfo(ServerInfo),
    /// NAT_MODELDEF.
    Descriptions(DataDescriptions),
    /// NAT_FRAMEOFDATA.
    Frame(Box<FrameOfData>),
    /// NAT_MESSAGESTRING or NAT_RESPONSE text.
    Text(String),
    /// Another message, by id (not read here).
    Other(u16),
}

/// Decodes any datagram of NatNet `version`.
///
/// # Errors
/// As the message's decoder.
pub fn decode(datagram: &[u8], version: Version) -> Result<Message> {
    let (id, payload) = header(datagram)?;
    Ok(match id {
        NAT_SERVERINFO => Message::ServerInfo(decode_server_info(datagram)?),
        NAT_MODELDEF => Message::Descriptions(decode_descriptions(datagram, version)?),
        NAT_FRAMEOFDATA => Message::Frame(Box::new(decode_frame(datagram, version)?)),
        NAT_MESSAGESTRING | NAT_RESPONSE => {
            let end = payload
                .iter()
                .position(|&b| b == 0)
                .unwrap_or(payload.len());
            Message::Text(String::from_utf8_lossy(&payload[..end]).into_owned())
        }
        other => Message::Other(other),
    })
}
