// The few protobuf messages the viewer reads off the WebSocket (`crease.v1.MeshFrame` of
// proto/crease/v1/crease.proto): a minimal reader of the protobuf wire format (varints and
// length-delimited fields; unknown fields are skipped, as protobuf requires).

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
  const t = { model: "", level: 0, vertexCount: 0, triangleCount: 0, indices: null, box: null, vertexOrder: [], bits: 0 };
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
    else r.skip(wire);
  }
  return t;
}

function readFrame(bytes) {
  const r = new Reader(bytes);
  const f = { seq: 0, captureTimeUs: 0, serverLatencyUs: 0, data: null, skipped: 0 };
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 0) f.seq = r.varint();
    else if (field === 2 && wire === 0) f.captureTimeUs = r.varint();
    else if (field === 3 && wire === 0) f.serverLatencyUs = r.varint();
    else if (field === 4 && wire === 2) f.data = r.bytes();
    else if (field === 5 && wire === 0) f.skipped = r.varint();
    else r.skip(wire);
  }
  return f;
}

/** Reads a `MeshFrame`: `{topology}` or `{frame}`. */
export function readMeshFrame(bytes) {
  const r = new Reader(bytes);
  for (const [field, wire] of r.fields()) {
    if (field === 1 && wire === 2) return { topology: readTopology(r.bytes()) };
    if (field === 2 && wire === 2) return { frame: readFrame(r.bytes()) };
    r.skip(wire);
  }
  throw new Error("protobuf: a MeshFrame with neither topology nor frame");
}
