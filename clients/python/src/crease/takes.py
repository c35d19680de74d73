"""Take files (``proto/crease/v1/take.proto``) as NumPy arrays.

A take is what a room recorded: an 8-byte magic ``CRTAKE\\0\\1``, then records of ``u32`` length,
``u32`` CRC-32 (zlib's) and payload, all little-endian; record 0 a ``TakeHeader``, the rest
``TakeFrame``s. A server that died while recording leaves the last record partial: reading stops
at the first short record or bad CRC and marks the take truncated (as the Rust reader does).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from .v1 import take_pb2

MAGIC = b"CRTAKE\x00\x01"


class TakeError(ValueError):
    """A take file that is not one (wrong magic, no header, a header that does not parse)."""


@dataclass
class ActorTake:
    """One actor's part of a take: arrays with a row per frame."""

    name: str
    #: ``(F, C, 3)`` control points as the prediction used them (model units).
    controls: np.ndarray
    #: ``(F, B, 7)`` per bone ``qx, qy, qz, qw, tx, ty, tz`` (FKY08 eq. 11's solve's output).
    transforms: np.ndarray


@dataclass
class Take:
    """A take's frames as arrays (``Client.take_frames``)."""

    header: take_pb2.TakeHeader
    #: ``(F,)`` each frame's publisher sequence number and capture time (microseconds).
    seq: np.ndarray
    capture_time_us: np.ndarray
    #: ``(F,)`` arrival, microseconds after the take began.
    received_us: np.ndarray
    #: The room's actors, in order (a one-actor room: one, named after the room's model).
    actors: list[ActorTake] = field(default_factory=list)
    #: The file ended in a partial record.
    truncated: bool = False

    @property
    def controls(self) -> np.ndarray:
        """The first actor's ``(F, C, 3)`` controls."""
        return self.actors[0].controls

    @property
    def transforms(self) -> np.ndarray:
        """The first actor's ``(F, B, 7)`` bone transforms."""
        return self.actors[0].transforms


def parse_take(data: bytes) -> Take:
    """A take file's bytes as arrays.

    Raises:
        TakeError: not a take file, or its header record is missing or broken.
    """
    if data[: len(MAGIC)] != MAGIC:
        raise TakeError(f"not a take file: starts with {data[:8]!r}, expected {MAGIC!r}")
    records: list[bytes] = []
    at = len(MAGIC)
    truncated = False
    while at < len(data):
        if at + 8 > len(data):
            truncated = True
            break
        n, crc = struct.unpack_from("<II", data, at)
        payload = data[at + 8 : at + 8 + n]
        if len(payload) < n or zlib.crc32(payload) != crc:
            truncated = True
            break
        records.append(payload)
        at += 8 + n
    if not records:
        raise TakeError("a take file without its header record")
    header = take_pb2.TakeHeader.FromString(records[0])
    frames = [take_pb2.TakeFrame.FromString(r) for r in records[1:]]
    if header.actors:
        shapes = [(a.actor, a.controls, a.bones) for a in header.actors]
    else:
        shapes = [(header.room.model, header.controls, header.bones)]
    actors = []
    for k, (name, controls, bones) in enumerate(shapes):
        c = np.zeros((len(frames), controls, 3), dtype=np.float32)
        t = np.zeros((len(frames), bones, 7), dtype=np.float32)
        for i, f in enumerate(frames):
            pose = f.actors[k] if header.actors else f
            if len(pose.controls) != 3 * controls or len(pose.transforms) != 7 * bones:
                raise TakeError(
                    f"frame {i}, actor {name!r}: {len(pose.controls)} control values and "
                    f"{len(pose.transforms)} transform values, the header says {3 * controls} and {7 * bones}"
                )
            c[i] = np.asarray(pose.controls, dtype=np.float32).reshape(controls, 3)
            t[i] = np.asarray(pose.transforms, dtype=np.float32).reshape(bones, 7)
        actors.append(ActorTake(name, c, t))
    return Take(
        header=header,
        seq=np.array([f.frame.seq for f in frames], dtype=np.uint64),
        capture_time_us=np.array([f.frame.capture_time_us for f in frames], dtype=np.int64),
        received_us=np.array([f.received_us for f in frames], dtype=np.int64),
        actors=actors,
        truncated=truncated,
    )
