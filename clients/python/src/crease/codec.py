"""crease's frame codec (``core::codec``, format version 1) decoded with NumPy and meshopt.

A frame is a 52-byte header and a payload of meshoptimizer's vertex codec (version 1) holding
four little-endian ``u16`` lanes per vertex: ``x, y, z`` quantised in the header's box and ``w``
an optional octahedral normal. A keyframe's lanes stand alone; a delta's add to the previous
frame's, modulo 2**16. The layout, byte by byte, is in ``core/src/codec/mod.rs``; the test
vectors ``tests/vectors/codec-v1.json`` pin it and ``tests/test_vectors.py`` checks this
module against them bit for bit.

The meshopt payloads (vertex and index codec) are decoded by the ``meshopt`` package from PyPI,
a binding of meshoptimizer 1.3's own C++ decoder.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

import meshopt
import numpy as np

#: Bytes before the payload.
HEADER_LEN = 52
#: The first four bytes of every frame.
MAGIC = b"CRSF"
#: The frame format version this module reads.
VERSION = 1
#: Bytes per vertex once the payload is decoded: four ``u16`` lanes.
VERTEX_SIZE = 8
_HEADER = struct.Struct("<4sBBBBB3sIII3f3fI")
_MESHOPT_VERTEX_V1 = 0xA1
_MESHOPT_INDEX_V1 = 0xE1


class CodecError(ValueError):
    """A frame or an index buffer that is not what the format says, naming what is wrong."""


@dataclass(frozen=True)
class FrameHeader:
    """A parsed frame header (``core::codec::FrameHeader``)."""

    kind: Literal["key", "delta"]
    #: Lane ``w`` holds octahedral normals.
    normals: bool
    bits: int
    vertex_count: int
    seq: int
    #: For a delta, the sequence number of the frame it applies to; for a keyframe, ``seq``.
    base: int
    #: The quantisation box: ``min`` and ``step`` as float32 (3,).
    min: np.ndarray
    step: np.ndarray
    payload_len: int


def parse_frame(frame: bytes) -> tuple[FrameHeader, memoryview]:
    """Checks a frame's header and splits off its payload (as ``core::codec::parse_frame``).

    Raises:
        CodecError: the first problem found, in header order.
    """
    if len(frame) < HEADER_LEN:
        raise CodecError(f"frame truncated: {len(frame)} bytes, the header alone needs {HEADER_LEN}")
    (magic, version, kind, flags, vsize, bits, reserved, count, seq, base, *box, payload_len) = _HEADER.unpack_from(
        frame
    )
    if magic != MAGIC:
        raise CodecError(f"bad magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise CodecError(f"unsupported frame version {version}, expected {VERSION}")
    if kind not in (0, 1):
        raise CodecError(f"unknown frame kind {kind} (0 keyframe, 1 delta)")
    if flags & ~1:
        raise CodecError(f"unknown flags {flags:#04x}")
    if vsize != VERTEX_SIZE:
        raise CodecError(f"vertex size {vsize}, expected {VERTEX_SIZE}")
    if not 1 <= bits <= 16:
        raise CodecError(f"quantisation bits {bits}, expected 1..=16")
    if reserved != b"\0\0\0":
        raise CodecError(f"reserved header bytes 9..12 are {reserved.hex()}, expected zero")
    lo = np.array(box[:3], dtype=np.float32)
    step = np.array(box[3:], dtype=np.float32)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(step)) and np.all(step > 0)):
        raise CodecError(f"invalid quantisation box: min {lo.tolist()}, step {step.tolist()}")
    if kind == 0 and base != seq:
        raise CodecError(f"a keyframe's base must be its own seq: seq {seq}, base {base}")
    payload = memoryview(frame)[HEADER_LEN:]
    if payload_len != len(payload):
        raise CodecError(f"payload length: the header declares {payload_len} bytes, the frame carries {len(payload)}")
    header = FrameHeader(
        kind="key" if kind == 0 else "delta",
        normals=bool(flags & 1),
        bits=bits,
        vertex_count=count,
        seq=seq,
        base=base,
        min=lo,
        step=step,
        payload_len=payload_len,
    )
    return header, payload


def decode_payload(payload: bytes | memoryview, vertex_count: int) -> np.ndarray:
    """A frame's payload as its ``(vertex_count, 4)`` u16 lanes (a delta's: the differences)."""
    if vertex_count == 0:
        return np.zeros((0, 4), dtype=np.uint16)
    if len(payload) == 0 or payload[0] != _MESHOPT_VERTEX_V1:
        first = f"{payload[0]:#04x}" if len(payload) else "nothing"
        raise CodecError(f"payload starts with {first}, expected meshopt's vertex codec v1 header 0xa1")
    try:
        rows = meshopt.decode_vertex_buffer(bytes(payload), vertex_count, VERTEX_SIZE)
    except (RuntimeError, ValueError) as e:
        raise CodecError(f"meshopt refused the payload of {vertex_count} vertices: {e}") from e
    return rows.view("<u2").reshape(vertex_count, 4)


def dequantise(lanes: np.ndarray, header: FrameHeader) -> np.ndarray:
    """Positions from lanes: ``fround(min + q * step)`` per axis, bit for bit as the Rust decoder
    (the product and sum in float64, rounded once to float32)."""
    q = lanes[:, :3].astype(np.float64)
    return (header.min.astype(np.float64) + q * header.step.astype(np.float64)).astype(np.float32)


class DequantTables:
    """``dequantise`` by table: per axis the 65,536 values ``fround(min + q * step)`` of a box,
    computed once per box (a stream's box is fixed), then a gather per frame. Equal to
    ``dequantise`` bit for bit, several times faster on large meshes."""

    def __init__(self) -> None:
        self._key: tuple[bytes, bytes] | None = None
        self._tables = np.empty((3, 0), dtype=np.float32)

    def positions_into(self, lanes: np.ndarray, header: FrameHeader, out: np.ndarray) -> None:
        """Writes the lanes' positions into ``out`` (``(n, 3)`` float32)."""
        key = (header.min.tobytes(), header.step.tobytes())
        if key != self._key:
            q = np.arange(65536, dtype=np.float64)
            lo = header.min.astype(np.float64)[:, None]
            step = header.step.astype(np.float64)[:, None]
            self._tables = (lo + q[None, :] * step).astype(np.float32)
            self._key = key
        for k in range(3):
            np.take(self._tables[k], lanes[:, k], out=out[:, k])


def oct_decode(w: np.ndarray) -> np.ndarray:
    """Unit normals from ``w`` lanes (u in the low byte, v in the high, each an i8 of c * 127), as
    ``core::codec::oct_decode`` (float64, rounded to float32 at the end)."""
    w = np.asarray(w, dtype=np.uint16)
    u = np.maximum((w & 0xFF).astype(np.uint8).view(np.int8).astype(np.float64) / 127.0, -1.0)
    v = np.maximum((w >> 8).astype(np.uint8).view(np.int8).astype(np.float64) / 127.0, -1.0)
    z = 1.0 - np.abs(u) - np.abs(v)
    fold = z < 0.0
    fu = (1.0 - np.abs(v)) * np.where(u < 0.0, -1.0, 1.0)
    fv = (1.0 - np.abs(u)) * np.where(v < 0.0, -1.0, 1.0)
    u, v = np.where(fold, fu, u), np.where(fold, fv, v)
    length = np.sqrt(u * u + v * v + z * z)
    return np.stack([u / length, v / length, z / length], axis=-1).astype(np.float32)


class LaneDecoder:
    """Keyframes and deltas of one stream back to lanes (``core::codec::FrameDecoder``).

    A delta applies only to the frame it was computed from: after a skipped or failed frame the
    decoder refuses deltas until the next keyframe.
    """

    def __init__(self) -> None:
        self._lanes: np.ndarray | None = None
        self._seq: int | None = None

    def decode(self, frame: bytes) -> tuple[FrameHeader, np.ndarray]:
        """The frame's header and its ``(n, 4)`` u16 lanes (read-only; valid for good)."""
        header, payload = parse_frame(frame)
        try:
            lanes = decode_payload(payload, header.vertex_count)
            if header.kind == "delta":
                if self._lanes is None or self._seq is None:
                    raise CodecError(f"delta frame {header.seq} without a base (waiting for a keyframe)")
                if self._seq != header.base:
                    raise CodecError(f"delta frame {header.seq} applies to frame {header.base}, the decoder holds {self._seq}")
                if len(self._lanes) != header.vertex_count:
                    raise CodecError(
                        f"delta frame {header.seq}: {header.vertex_count} vertices, its base has {len(self._lanes)}"
                    )
                lanes = self._lanes + lanes  # u16 arithmetic wraps modulo 2**16
        except CodecError:
            self._lanes, self._seq = None, None
            raise
        self._lanes, self._seq = lanes, header.seq
        # The decoder's own lanes, read-only: the next delta makes a new array from them.
        view = lanes.view()
        view.flags.writeable = False
        return header, view


def decode_indices(data: bytes, triangle_count: int, vertex_count: int) -> np.ndarray:
    """Triangles from meshopt's index codec (version 1) as ``(triangle_count, 3)`` uint32, every
    index checked against ``vertex_count`` (``core::codec::decode_indices``)."""
    if triangle_count == 0:
        return np.zeros((0, 3), dtype=np.uint32)
    # meshopt's index codec: a header byte, a byte per triangle, and a 16-byte tail at least.
    needed = 1 + triangle_count + 16
    if len(data) < needed:
        raise CodecError(f"index buffer truncated: {len(data)} bytes for {triangle_count} triangles, needs {needed}")
    if data[0] != _MESHOPT_INDEX_V1:
        raise CodecError(f"index buffer starts with {data[0]:#04x}, expected meshopt's index codec v1 header 0xe1")
    try:
        flat = meshopt.decode_index_buffer(bytes(data), triangle_count * 3, 4)
    except (RuntimeError, ValueError) as e:
        raise CodecError(f"meshopt refused the index buffer of {triangle_count} triangles: {e}") from e
    tris = np.asarray(flat, dtype=np.uint32).reshape(triangle_count, 3)
    bad = np.argwhere(tris >= vertex_count)
    if len(bad):
        t, k = bad[0]
        raise CodecError(f"triangle {t} indexes vertex {tris[t, k]}, the mesh has {vertex_count}")
    return tris
