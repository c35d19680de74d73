//! NatNet messages encoded: the client's requests (NAT_CONNECT, NAT_REQUEST_MODELDEF,
//! NAT_KEEPALIVE) and, for fixtures and the loopback test server, synthetic NAT_SERVERINFO,
//! NAT_MODELDEF and NAT_FRAMEOFDATA datagrams in the layouts [`super::wire`] reads.

use super::wire::{
    Analog, DESC_MARKER_SET, DESC_RIGID_BODY, DESC_SKELETON, DataDescriptions, FrameOfData,
    LabeledMarker, NAT_CONNECT, NAT_FRAMEOFDATA, NAT_KEEPALIVE, NAT_MODELDEF, NAT_REQUEST_MODELDEF,
    NAT_SERVERINFO, RigidBody, RigidBodyDesc, ServerInfo, Version,
};

/// A little-endian byte writer.
#[derive(Debug, Default)]
struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn u16(&mut self, v: u16) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn floats(&mut self, v: &[f32]) {
        for x in v {
            self.f32(*x);
        }
    }
    /// A NUL-terminated string (an interior NUL would end it early: dropped).
    fn cstr(&mut self, s: &str) {
        self.buf.extend(s.bytes().filter(|&b| b != 0));
        self.buf.push(0);
    }
    fn len_i32(n: usize) -> i32 {
        i32::try_from(n).unwrap_or(i32::MAX)
    }
    fn count(&mut self, n: usize) {
        self.i32(Self::len_i32(n));
    }
    /// Starts a 4.1 byte count: its place, to [`Self::end_size`].
    fn begin_size(&mut self, v: Version) -> Option<usize> {
        v.at_least(4, 1).then(|| {
            let at = self.buf.len();
            self.i32(0);
            at
        })
    }
    fn end_size(&mut self, at: Option<usize>) {
        if let Some(at) = at {
            let size = Self::len_i32(self.buf.len() - at - 4);
            self.buf[at..at + 4].copy_from_slice(&size.to_le_bytes());
        }
    }
    /// A whole message: id, payload size (saturating at the field's 16 bits), payload.
    fn message(id: u16, payload: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(payload.len() + 4);
        out.extend_from_slice(&id.to_le_bytes());
        out.extend_from_slice(
            &u16::try_from(payload.len())
                .unwrap_or(u16::MAX)
                .to_le_bytes(),
        );
        out.extend_from_slice(payload);
        out
    }
}

/// NAT_CONNECT asking for `version`, as the SDK's sample sends it: "Ping", zeros to byte 264,
/// the four version bytes at 265..269, and a trailing NUL.
pub fn connect(version: Version) -> Vec<u8> {
    let mut p = vec![0u8; 271];
    p[..4].copy_from_slice(b"Ping");
    p[265..269].copy_from_slice(&[
        version.major,
        version.minor,
        version.build,
        version.revision,
    ]);
    Writer::message(NAT_CONNECT, &p)
}

/// NAT_REQUEST_MODELDEF.
pub fn request_model_def() -> Vec<u8> {
    let mut m = Writer::message(NAT_REQUEST_MODELDEF, &[]);
    m.push(0);
    m
}

/// NAT_KEEPALIVE.
pub fn keep_alive() -> Vec<u8> {
    let mut m = Writer::message(NAT_KEEPALIVE, &[]);
    m.push(0);
    m
}

/// NAT_SERVERINFO with the connection info (clock, data port, multicast) when set.
pub fn server_info(info: &ServerInfo) -> Vec<u8> {
    let mut w = Writer::default();
    let mut name = [0u8; 256];
    let bytes = info.name.as_bytes();
    let n = bytes.len().min(255);
    name[..n].copy_from_slice(&bytes[..n]);
    w.buf.extend_from_slice(&name);
    w.buf.extend_from_slice(&info.app_version);
    let v = info.natnet;
    w.buf
        .extend_from_slice(&[v.major, v.minor, v.build, v.revision]);
    if let Some(f) = info.clock_frequency {
        w.u64(f);
        w.u16(info.data_port.unwrap_or(1511));
        w.u8(u8::from(info.multicast.unwrap_or(false)));
        w.buf
            .extend_from_slice(&info.multicast_group.unwrap_or([239, 255, 42, 99]));
    }
    Writer::message(NAT_SERVERINFO, &w.buf)
}

fn rigid_body(w: &mut Writer, b: &RigidBody) {
    w.i32(b.id);
    w.floats(&b.position);
    w.floats(&b.orientation);
    w.f32(b.mean_error);
    w.u16(b.params);
}

fn labeled_marker(w: &mut Writer, m: &LabeledMarker) {
    w.i32(m.id);
    w.floats(&m.position);
    w.f32(m.size);
    w.u16(m.params);
    w.f32(m.residual);
}

fn analog(w: &mut Writer, a: &Analog) {
    w.i32(a.id);
    w.count(a.channels.len());
    for c in &a.channels {
        w.count(c.len());
        w.floats(c);
    }
}

/// Writes one section: count, (4.1) byte count, entries.
fn section<T>(w: &mut Writer, v: Version, items: &[T], mut entry: impl FnMut(&mut Writer, &T)) {
    w.count(items.len());
    let at = w.begin_size(v);
    for it in items {
        entry(w, it);
    }
    w.end_size(at);
}

/// NAT_FRAMEOFDATA of NatNet `version` (assets only on 4.1, the precision timestamp only on
/// 4.1), ending with the end-of-data tag (i32 0) as Motive sends it.
pub fn frame(f: &FrameOfData, v: Version) -> Vec<u8> {
    let mut w = Writer::default();
    w.i32(f.frame_number);
    section(&mut w, v, &f.marker_sets, |w, s| {
        w.cstr(&s.name);
        w.count(s.markers.len());
        for m in &s.markers {
            w.floats(m);
        }
    });
    section(&mut w, v, &f.other_markers, |w, m| w.floats(m));
    section(&mut w, v, &f.rigid_bodies, rigid_body);
    section(&mut w, v, &f.skeletons, |w, s| {
        w.i32(s.id);
        w.count(s.bones.len());
        for b in &s.bones {
            rigid_body(w, b);
        }
    });
    if v.at_least(4, 1) {
        section(&mut w, v, &f.assets, |w, a| {
            w.i32(a.id);
            w.count(a.rigid_bodies.len());
            for b in &a.rigid_bodies {
                rigid_body(w, b);
            }
            w.count(a.markers.len());
            for m in &a.markers {
                labeled_marker(w, m);
            }
        });
    }
    section(&mut w, v, &f.labeled_markers, labeled_marker);
    section(&mut w, v, &f.force_plates, analog);
    section(&mut w, v, &f.devices, analog);
    let t = &f.timing;
    w.u32(t.timecode);
    w.u32(t.timecode_sub);
    w.f64(t.timestamp);
    w.u64(t.camera_mid_exposure);
    w.u64(t.camera_data_received);
    w.u64(t.transmit);
    if v.at_least(4, 1) {
        w.u32(t.precision_secs);
        w.u32(t.precision_frac);
    }
    w.u16(f.params);
    w.i32(0);
    Writer::message(NAT_FRAMEOFDATA, &w.buf)
}

fn rigid_body_desc(w: &mut Writer, d: &RigidBodyDesc, v: Version) {
    w.cstr(&d.name);
    w.i32(d.id);
    w.i32(d.parent_id);
    w.floats(&d.offset);
    w.count(d.markers.len());
    for m in &d.markers {
        w.floats(&m.offset);
    }
    for m in &d.markers {
        w.i32(m.active_label);
    }
    if v.major >= 4 {
        for m in &d.markers {
            w.cstr(&m.name);
        }
    }
}

/// NAT_MODELDEF of NatNet `version`: marker sets, then rigid bodies, then skeletons (the
/// skipped types are not written).
pub fn descriptions(d: &DataDescriptions, v: Version) -> Vec<u8> {
    let mut w = Writer::default();
    w.count(d.marker_sets.len() + d.rigid_bodies.len() + d.skeletons.len());
    for s in &d.marker_sets {
        w.i32(DESC_MARKER_SET);
        let at = w.begin_size(v);
        w.cstr(&s.name);
        w.count(s.markers.len());
        for m in &s.markers {
            w.cstr(m);
        }
        w.end_size(at);
    }
    for b in &d.rigid_bodies {
        w.i32(DESC_RIGID_BODY);
        let at = w.begin_size(v);
        rigid_body_desc(&mut w, b, v);
        w.end_size(at);
    }
    for s in &d.skeletons {
        w.i32(DESC_SKELETON);
        let at = w.begin_size(v);
        w.cstr(&s.name);
        w.i32(s.id);
        w.count(s.bones.len());
        for b in &s.bones {
            rigid_body_desc(&mut w, b, v);
        }
        w.end_size(at);
    }
    Writer::message(NAT_MODELDEF, &w.buf)
}
