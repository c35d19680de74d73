"""A mesh stream's messages back to vertex arrays: the decoder behind ``Client.subscribe`` and
``Client.synthesize``, usable alone on a capture (``crease watch --record``, ``read_capture``).

A stream starts with what its frames index into: a ``Topology`` (a vertex stream: every vertex
quantised, ``crease.codec``) or a ``PaletteTopology`` (a palette stream: the bones and the detail
kernel vector, skinned here on the CPU, ``crease.palette``); a room of several actors sends one
per actor first. Then ``Frame`` messages, each decoded to ``(V, 3)`` float32 positions in the
model's own vertex order (a vertex stream's spatial ``vertex_order`` undone).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import codec
from .v1 import crease_pb2 as pb


class StreamError(ValueError):
    """A stream whose messages are out of order or do not fit together."""


@dataclass(frozen=True)
class Topology:
    """What one actor's frames index into."""

    model: str
    #: "base" or "detail".
    level: str
    #: "vertices" or "palette".
    encoding: str
    vertex_count: int
    #: ``(T, 3)`` uint32 triangles in model vertex ids.
    triangles: np.ndarray
    #: The actor's name ("" in a one-actor room).
    actor: str


_LEVELS = {pb.LEVEL_UNSPECIFIED: "base", pb.LEVEL_BASE: "base", pb.LEVEL_DETAIL: "detail"}


class _VertexActor:
    """One actor's vertex stream."""

    def __init__(self, t: pb.Topology) -> None:
        tris = codec.decode_indices(t.indices, t.triangle_count, t.vertex_count)
        order = np.asarray(t.vertex_order, dtype=np.int64)
        if len(order) and (len(order) != t.vertex_count or not np.array_equal(np.sort(order), np.arange(t.vertex_count))):
            raise StreamError(f"Topology.vertex_order: {len(order)} entries, not a permutation of {t.vertex_count} vertices")
        # Streamed vertex i is model vertex order[i]: model vertex v is streamed vertex inv[v].
        self.inv = np.argsort(order) if len(order) else None
        # The triangles index the streamed order; in model ids they are order[tris].
        triangles = order[tris].astype(np.uint32) if len(order) else tris
        self.topology = Topology(t.model, _LEVELS.get(t.level, "base"), "vertices", t.vertex_count, triangles, t.actor)
        self.lanes = codec.LaneDecoder()
        self.tables = codec.DequantTables()

    def decode_into(self, data: bytes, out: np.ndarray) -> None:
        header, lanes = self.lanes.decode(data)
        if header.vertex_count != self.topology.vertex_count:
            raise StreamError(f"frame {header.seq}: {header.vertex_count} vertices, the topology has {self.topology.vertex_count}")
        if self.inv is not None:
            lanes = lanes[self.inv]  # model vertex order
        self.tables.positions_into(lanes, header, out)


class _PaletteActor:
    """One actor's palette stream, skinned on the CPU."""

    def __init__(self, t: pb.PaletteTopology) -> None:
        from .palette import PaletteDecoder

        self.decoder = PaletteDecoder(t)
        h = self.decoder.header
        self.topology = Topology(t.model, _LEVELS.get(t.level, "base"), "palette", h.vertex_count, h.triangles, t.actor)

    def decode_into(self, data: bytes, out: np.ndarray) -> None:
        out[:] = self.decoder.decode(data)


class MeshStream:
    """Decodes one mesh stream: feed it every message in order (``push``); frames come back as
    ``(seq, vertices)``, ``vertices`` a ``(V, 3)`` float32 array, or for a room of several actors
    a dict of them by actor name (an actor held this instant keeps its last mesh)."""

    def __init__(self) -> None:
        self.actors: list[_VertexActor | _PaletteActor] = []
        self._expected = 0
        self._meshes: list[np.ndarray] = []

    @property
    def ready(self) -> bool:
        """Every topology has arrived: frames can be decoded."""
        return bool(self.actors) and len(self.actors) == self._expected

    @property
    def topologies(self) -> list[Topology]:
        return [a.topology for a in self.actors]

    def _add(self, actor: _VertexActor | _PaletteActor, index: int, count: int) -> None:
        if self.ready:
            raise StreamError("a topology after the stream's topologies were complete")
        if index != len(self.actors):
            raise StreamError(f"topology of actor index {index} arrived as topology {len(self.actors)}")
        self._expected = max(count, 1)
        self.actors.append(actor)
        self._meshes.append(np.zeros((actor.topology.vertex_count, 3), dtype=np.float32))

    def push(self, message: pb.MeshFrame) -> tuple[int, np.ndarray | dict[str, np.ndarray]] | None:
        """Takes the stream's next message; returns the decoded frame for a ``Frame``, else None.

        Raises:
            StreamError, codec.CodecError, palette.PaletteError: a message that does not fit.
        """
        body = message.WhichOneof("body")
        if body == "topology":
            t = message.topology
            self._add(_VertexActor(t), t.actor_index, t.actor_count)
            return None
        if body == "palette_topology":
            t = message.palette_topology
            self._add(_PaletteActor(t), t.actor_index, t.actor_count)
            return None
        if body != "frame":
            raise StreamError("an empty MeshFrame")
        if not self.ready:
            raise StreamError(f"frame {message.frame.seq} before the stream's topology")
        frame = message.frame
        if len(self.actors) == 1 and not frame.actors:
            # A fresh array per frame (the caller may keep it), written whole.
            mesh = np.empty_like(self._meshes[0])
            self.actors[0].decode_into(frame.data, mesh)
            return frame.seq, mesh
        for part in frame.actors:
            if part.actor >= len(self.actors):
                raise StreamError(f"frame {frame.seq}: actor index {part.actor}, the room has {len(self.actors)}")
            if part.data:
                self.actors[part.actor].decode_into(part.data, self._meshes[part.actor])
        return frame.seq, {a.topology.actor: m.copy() for a, m in zip(self.actors, self._meshes)}

    def decode_into(self, message: pb.MeshFrame, out: np.ndarray) -> int:
        """A one-actor stream's ``Frame`` decoded straight into ``out`` (``(V, 3)`` float32,
        written whole): no copy. Returns the frame's seq."""
        if not self.ready or len(self.actors) != 1:
            raise StreamError("decode_into needs a one-actor stream whose topology has arrived")
        if message.WhichOneof("body") != "frame":
            raise StreamError(f"expected a Frame, got {message.WhichOneof('body')}")
        self.actors[0].decode_into(message.frame.data, out)
        return message.frame.seq


def read_capture(path: str | Path) -> list[pb.MeshFrame]:
    """The messages of a capture file (``crease watch --record``): each a ``MeshFrame`` prefixed by
    its length as a little-endian u32."""
    data = Path(path).read_bytes()
    out: list[pb.MeshFrame] = []
    at = 0
    while at < len(data):
        if at + 4 > len(data):
            raise StreamError(f"{path}: byte {at}: a truncated length prefix ({len(data) - at} bytes left)")
        (n,) = struct.unpack_from("<I", data, at)
        if at + 4 + n > len(data):
            raise StreamError(f"{path}: byte {at}: message {len(out)} claims {n} bytes, {len(data) - at - 4} remain")
        out.append(pb.MeshFrame.FromString(data[at + 4 : at + 4 + n]))
        at += 4 + n
    return out


def decode_messages(messages: Iterable[pb.MeshFrame]) -> Iterator[tuple[int, np.ndarray | dict[str, np.ndarray]]]:
    """Every frame of a stream's messages, decoded in order."""
    stream = MeshStream()
    for m in messages:
        out = stream.push(m)
        if out is not None:
            yield out
