// The few protobuf messages the viewer reads off the WebSocket (`crease.v1.MeshFrame` of
// proto/crease/v1/crease.proto): a minimal reader of the protobuf wire format (varints and
// length-delimited fields; unknown fields are skipped, as protobuf requires). Two kinds of
// stream (proto Encoding): vertices (a Topology, then codec frames) and palette (a
// PaletteTopology, then palette frames, issue 18). A room of several actors (issue 38) sends
// one header per actor (`actor`, `actorIndex`, `actorCount`), then frames whose `actors` hold
// each actor's frame ({actor: index, data, held, placement}) instead of `data`.

class Reader {
  constructor(bytes) {
    this.b = bytes;
    this.pos = 0;
  }
  done() {
    return this.pos >= this.b.length;
  }
  varint() {
    // Up to 64 bits; numbers above 2^53 lose precision (sequence numbers never get there).
    let result = 0;
    let scale = 1;
    for (let i = 0; i < 10; i++) {
      if (this.pos >= this.b.length) throw new Error("protobuf: truncated varint");
      const byte = this.b[this.pos++];
      result += (byte & 0x7f) * scale;
      if (byte < 0x80) return result;
      scale *= 128;
    }
    throw new Error("protobuf: varint longer than 10 bytes");
  }
  bytes() {
    const len = this.varint();
    if (this.pos + len > this.b.length) throw new Error("protobuf: truncated field");
    const out = this.b.subarray(this.pos, this.pos + len);
    this.pos += len;
    return out;
  }
  skip(wire) {
    if (wire === 0) this.varint();
    else if (wire === 1) this.pos += 8;
    else if (wire === 2) this.bytes();
    else if (wire === 5) this.pos += 4;
    else throw new Error(`protobuf: wire type ${wire}`);
  }
  *fields() {
    while (!this.done()) {
      const key = this.varint();
      yield [Math.floor(key / 8), key & 7];
    }
  }
}

const text = new TextDecoder();

function readFloat(bytes) {
  return new DataView(bytes.buffer, bytes.byteOffset, 4).getFloat32(0, true);
}

function readVec3(bytes) {
  const r = new Reader(bytes);
  const v = [0, 0, 0];
  for (const [field, wire] of r.fields()) {
    if (wire === 5 && field >= 1 && field <= 3) {
      v[field - 1] = readFloat(r.b.subarray(r.pos, r.pos + 4));
      r.pos += 4;
    } else r.skip(wire);
  }
  return v;
}

function readBox(bytes) {
  const r = new Reader(bytes);
  const box = { min: [0, 0, 0], max: [0, 0, 0] };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 2) box.min = readVec3(r.bytes());
    else if (field === 2 && wire === 2) box.max = readVec3(r.bytes());
    else r.skip(wire);
  }
  return box;
}

function readTopology(bytes) {
  const r = new Reader(bytes);
  const t = { model: "", level: 0, vertexCount: 0, triangleCount: 0, indices: null, box: null, vertexOrder: [], bits: 0, actor: "", actorIndex: 0, actorCount: 0 };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 2) t.model = text.decode(r.bytes());
    else if (field === 2 && wire === 0) t.level = r.varint();
    else if (field === 3 && wire === 0) t.vertexCount = r.varint();
    else if (field === 4 && wire === 0) t.triangleCount = r.varint();
    else if (field === 5 && wire === 2) t.indices = r.bytes();
    else if (field === 6 && wire === 2) t.box = readBox(r.bytes());
    else if (field === 7 && wire === 2) {
      const packed = new Reader(r.bytes());
      const order = [];
      while (!packed.done()) order.push(packed.varint());
      t.vertexOrder = Uint32Array.from(order);
    } else if (field === 7 && wire === 0) t.vertexOrder.push(r.varint());
    else if (field === 8 && wire === 0) t.bits = r.varint();
    else if (field === 9 && wire === 2) t.actor = text.decode(r.bytes());
    else if (field === 10 && wire === 0) t.actorIndex = r.varint();
    else if (field === 11 && wire === 0) t.actorCount = r.varint();
    else r.skip(wire);
  }
  return t;
}

/** A Quat as [x, y, z, w]. */
function readQuat(bytes) {
  const r = new Reader(bytes);
  const q = [0, 0, 0, 0];
  for (const [field, wire] of r.fields()) {
    if (wire === 5 && field >= 1 && field <= 4) {
      q[field - 1] = readFloat(r.b.subarray(r.pos, r.pos + 4));
      r.pos += 4;
    } else r.skip(wire);
  }
  return q;
}

/** An ActorPlacement: {scale, translation: [x, y, z], rotation: [x, y, z, w]}. */
function readPlacement(bytes) {
  const r = new Reader(bytes);
  const p = { scale: 0, translation: [0, 0, 0], rotation: [0, 0, 0, 1] };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 5) {
      p.scale = readFloat(r.b.subarray(r.pos, r.pos + 4));
      r.pos += 4;
    } else if (field === 2 && wire === 2) p.translation = readVec3(r.bytes());
    else if (field === 3 && wire === 2) p.rotation = readQuat(r.bytes());
    else r.skip(wire);
  }
  return p;
}

/** One actor's mesh in a Frame (issue 38): {actor: its index, data, held, placement (where
 * its performer's capture puts it, or null)}. */
function readActorFrame(bytes) {
  const r = new Reader(bytes);
  const a = { actor: 0, data: new Uint8Array(0), held: false, placement: null };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 0) a.actor = r.varint();
    else if (field === 2 && wire === 2) a.data = r.bytes();
    else if (field === 3 && wire === 0) a.held = r.varint() !== 0;
    else if (field === 4 && wire === 2) a.placement = readPlacement(r.bytes());
    else r.skip(wire);
  }
  return a;
}

function readFrame(bytes) {
  const r = new Reader(bytes);
  const f = { seq: 0, captureTimeUs: 0, serverLatencyUs: 0, data: null, skipped: 0, actors: [] };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 0) f.seq = r.varint();
    else if (field === 2 && wire === 0) f.captureTimeUs = r.varint();
    else if (field === 3 && wire === 0) f.serverLatencyUs = r.varint();
    else if (field === 4 && wire === 2) f.data = r.bytes();
    else if (field === 5 && wire === 0) f.skipped = r.varint();
    else if (field === 6 && wire === 2) f.actors.push(readActorFrame(r.bytes()));
    else r.skip(wire);
  }
  return f;
}

/** A copy of `bytes` (any alignment) as little-endian elements of `Type`; throws unless the
 * byte length is a multiple of the element size. */
function littleEndian(bytes, Type, what) {
  const size = Type.BYTES_PER_ELEMENT;
  if (bytes.length % size !== 0) {
    throw new Error(`palette header: ${what} is ${bytes.length} bytes, not a multiple of ${size}`);
  }
  const out = new Type(bytes.length / size);
  if (size === 1) {
    out.set(bytes);
    return out;
  }
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const get = {
    2: Type === Int16Array ? (i) => dv.getInt16(i, true) : (i) => dv.getUint16(i, true),
    4: Type === Float32Array ? (i) => dv.getFloat32(i, true) : (i) => dv.getUint32(i, true),
  }[size];
  for (let i = 0; i < out.length; i++) out[i] = get(i * size);
  return out;
}

/**
 * Reads a `PaletteTopology` (issue 18; its detail part as issue 41 has it): the counts as
 * numbers, `detailStep` as the f32 sent, the byte arrays as they are (subarrays of the
 * message: `decodePaletteTopology` in palette.js checks and converts them), `detailBlocks` as
 * an array of them, `bounds` as {min, max}. The Loop steps and the drawn triangles are not on
 * the wire: palette.js rebuilds them from the base triangles (`indices`) with loop.js.
 */
export function readPaletteTopology(bytes) {
  const r = new Reader(bytes);
  const empty = new Uint8Array(0);
  const t = {
    model: "", level: 0, version: 0, vertexCount: 0, triangleCount: 0, indices: empty, bounds: null,
    bones: 0, baseVertices: 0, restPositions: empty, influences: 0, skinBones: empty, skinWeights: empty,
    examples: 0, actor: "", actorIndex: 0, actorCount: 0,
    subdivisionLevels: 0, detailStep: 0, detailBlocks: [], triangleTurns: empty,
  };
  for (const [field, wire] of r.fields()) {
    if (wire === 0) {
      const v = r.varint();
      const name = {
        2: "level", 3: "version", 4: "vertexCount", 5: "triangleCount", 8: "bones", 9: "baseVertices", 11: "influences",
        15: "examples", 19: "actorIndex", 20: "actorCount", 21: "subdivisionLevels",
      }[field];
      if (name) t[name] = v;
    } else if (wire === 2) {
      const b = r.bytes();
      if (field === 1) t.model = text.decode(b);
      else if (field === 18) t.actor = text.decode(b);
      else if (field === 7) t.bounds = readBox(b);
      else if (field === 23) t.detailBlocks.push(b);
      else {
        const name = { 6: "indices", 10: "restPositions", 12: "skinBones", 13: "skinWeights", 24: "triangleTurns" }[field];
        if (name) t[name] = b;
      }
    } else if (wire === 5 && field === 22) {
      if (r.pos + 4 > r.b.length) throw new Error("protobuf: truncated float");
      t.detailStep = readFloat(r.b.subarray(r.pos, r.pos + 4));
      r.pos += 4;
    } else r.skip(wire);
  }
  return t;
}

export { littleEndian };

/** Reads a `MeshFrame`: `{topology}`, `{frame}` or `{paletteTopology}`. */
export function readMeshFrame(bytes) {
  const r = new Reader(bytes);
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 2) return { topology: readTopology(r.bytes()) };
    if (field === 2 && wire === 2) return { frame: readFrame(r.bytes()) };
    if (field === 3 && wire === 2) return { paletteTopology: readPaletteTopology(r.bytes()) };
    r.skip(wire);
  }
  throw new Error("protobuf: a MeshFrame with neither topology, frame nor palette topology");
}

// The WebSocket subprotocols that carry a room's publish token (server/src/ws.rs, issue 21):
// "crease.v1", which the server selects, and "crease.token." + the token's UTF-8 bytes in
// unpadded base64url. The token never goes into a URL (proxies and access logs keep those).
export function socketProtocols(token) {
  if (!token) return ["crease.v1"];
  const bytes = new TextEncoder().encode(token);
  let binary = "";
  for (const b of bytes) binary += String.fromCharCode(b);
  const b64 = btoa(binary).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
  return ["crease.v1", `crease.token.${b64}`];
}
