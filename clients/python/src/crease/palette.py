"""Palette streams (issue 18, ``Encoding.ENCODING_PALETTE``) decoded on the CPU with NumPy.

A palette stream sends the bones, not the vertices: first a ``crease.v1.PaletteTopology`` with
everything that never changes (the rest mesh, its skin, the base triangles, and at the detail
level the number of Loop levels and the detail regressor ``D``, ``b``), then ``core::codec``
frames (keyframes and deltas, read by :class:`crease.codec.LaneDecoder`) whose four ``u16`` lanes
per "vertex" hold (``core/src/codec/palette/mod.rs``, ``PaletteTopology.version`` 1)::

    lane vertex 2k       [a, b, c, i]      bone k's rotation, smallest three: i (0..=3) is the
                                           index of the largest component (dropped, rebuilt
                                           positive), a, b, c the others in order, each
                                           (x sqrt 2 + 1) / 2 * 65535
    lane vertex 2k + 1   [x, y, z, 0]      bone k's translation, min + q * step in the frame
                                           header's box
    lane vertex 2B + j   [lo, hi, lo, hi]  xi[2j], xi[2j + 1]: the halves of their f32 bits

The drawn mesh of a frame (``core::codec::palette::PaletteSynth``, the reference decoder)::

    base  = sum_k w_k (R_k rest + t_k)     linear blend skinning, FKY08 eq. 1
    high  = S_L ( ... S_1 (base))          the Loop steps in turn (detail level)
    h     = D xi + b                       HZY11 eq. 4, the decoded D and b
    out   = high + h n(high)               n: unit area-weighted vertex normals of ``high``

The detail header is small (issue 41, ~1.4 MB for the demo hand instead of 11.5 MB): the Loop
steps ``S_1 .. S_L`` and the drawn triangles are not sent but rebuilt here from the base
triangles by :func:`crease.loop.loop_steps`, with the Rust core's numbering and rounding (bit for
bit; the base triangles are first turned back to the model's corner order by
``triangle_turns``, since meshopt's index codec may start a triangle at another corner), and
``D``, ``b`` come as 16-bit multiples ``q`` of one ``detail_step`` in meshopt vertex-codec blocks
of two values per vertex.

Arithmetic follows the Rust decoder as built for x86-64: every value is ``float32``, every sum is
taken in the Rust loop's order (sequential, from +0.0; ``h`` from -0.0 as Rust's ``Sum``), so the
decoded bones, ``xi`` and the drawn vertices (of the same rebuilt steps and triangles) are the
reference's bit for bit (``clients/python/tests/test_palette_vectors.py``). The quaternion's normalisation is
glam's SSE2 form, ``q / sqrt((x^2 + z^2) + (y^2 + w^2))``; glam's NEON and scalar builds group that
sum and multiply by the reciprocal instead, so a Rust decoder on another architecture may differ
from this one (and from itself on x86-64) by an ulp there.

Usage::

    topology = crease_pb2.MeshFrame.FromString(first_message).palette_topology
    decoder = PaletteDecoder(topology)
    for frame in frames:                       # Frame.data, in stream order
        vertices = decoder.decode(frame.data)  # (vertex_count, 3) float32, model vertex order
        triangles = decoder.header.triangles   # (T, 3) uint32
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import meshopt
import numpy as np

from . import codec
from .loop import MAX_LEVELS as MAX_LOOP_LEVELS
from .loop import LoopError, LoopStep, loop_steps

__all__ = [
    "PALETTE_VERSION",
    "LEVEL_BASE",
    "LEVEL_DETAIL",
    "PaletteError",
    "PaletteHeader",
    "PaletteStep",
    "PaletteDecoder",
    "palette_vertex_count",
    "apply_triangle_turns",
]

#: The lane layout this module reads (``PaletteTopology.version``).
PALETTE_VERSION = 1
#: ``crease.v1.Level`` values (``LEVEL_UNSPECIFIED = 0`` reads as the base level).
LEVEL_BASE = 1
LEVEL_DETAIL = 2
#: Skin influences per base vertex allowed by the format.
MAX_INFLUENCES = 8
#: A quantised vertex's skin weights sum to exactly this.
WEIGHT_ONE = 65535
#: Stored detail values per meshopt block (``PaletteTopology.detail_blocks``): two int16 make the
#: 4-byte "vertex" meshopt's vertex codec takes.
BLOCK_VALUES = 2
#: meshopt's vertex codec, version 1: the first byte of every detail block.
_MESHOPT_VERTEX_V1 = 0xA1

_F32 = np.float32
# std::f32::consts::FRAC_1_SQRT_2 (the double below rounds to the same float32).
_FRAC_1_SQRT_2 = np.float32(0.7071067811865476)
# For a largest-component index i, the three stored components in order.
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], dtype=np.intp)


class PaletteError(ValueError):
    """A palette header or frame that is not what the format says, naming the field and what was
    expected against what was found."""


def palette_vertex_count(bones: int, examples: int) -> int:
    """Lane vertices of a palette frame: ``2 B + ceil(N / 2)``."""
    return 2 * bones + (examples + 1) // 2


def _err(field_name: str, message: str) -> PaletteError:
    return PaletteError(f"PaletteTopology.{field_name}: {message}")


def _read_le(field_name: str, data: bytes, count: int, dtype: str) -> np.ndarray:
    """``count`` little-endian values of ``dtype`` from field ``field_name``, its length checked."""
    size = np.dtype(dtype).itemsize
    if len(data) != count * size:
        raise _err(field_name, f"{len(data)} bytes, expected {count * size} ({count} values of {size} bytes)")
    return np.frombuffer(bytes(data), dtype=dtype).astype(np.dtype(dtype).newbyteorder("="))


class _RowSums:
    """Per-row sums of terms in CSR order, ``out[:, r] = sum_e weights[e] * source[:, index[e]]``
    over ``e`` in ``row_ptr[r] .. row_ptr[r + 1]``, each row's terms added one after the other
    from +0.0 in float32 as a Rust loop ``acc += term`` does (so the result is the reference's
    bit for bit, which no reduction with an order of its own, ``np.add.reduceat`` or
    ``np.bincount``, guarantees).

    Vectorised over rows: the rows sorted by term count, longest first, pass ``j`` adds term
    ``j`` of every row that has one (a prefix of that order). Loop steps have at most valence + 1
    terms per row, vertex normals one per incident triangle: a handful of passes. Terms past
    :attr:`MAX_PASSES` (only an odd mesh has them) go through ``np.add.at``, which also adds in
    order, only slower.
    """

    MAX_PASSES = 32

    def __init__(self, row_ptr: np.ndarray, index: np.ndarray, weights: np.ndarray | None = None) -> None:
        ptr = row_ptr.astype(np.int64)
        lengths = np.diff(ptr)
        rows = len(lengths)
        order = np.argsort(-lengths, kind="stable")
        self.rows = rows
        self.inverse = np.empty(rows, dtype=np.intp)
        self.inverse[order] = np.arange(rows, dtype=np.intp)
        longest = int(lengths[order[0]]) if rows else 0
        passes = min(longest, self.MAX_PASSES)
        # counts[j]: rows with more than j terms.
        fewer = np.cumsum(np.bincount(lengths, minlength=longest + 1))
        self.counts = [rows - int(fewer[j]) for j in range(passes)]
        self.offsets = np.concatenate([[0], np.cumsum(self.counts, dtype=np.int64)]).astype(np.intp)
        starts = ptr[order]
        entries = np.concatenate([starts[:c] + j for j, c in enumerate(self.counts)] + [np.zeros(0, dtype=np.int64)])
        index = index.astype(np.intp)
        self._index = index[entries]
        self._weights = None if weights is None else weights[entries]
        # The terms past the passes, row after row in entry order.
        long_rows = np.flatnonzero(lengths > passes)
        extra = lengths[long_rows] - passes
        first = np.repeat(ptr[long_rows] + passes - np.cumsum(extra) + extra, extra)
        tail = first + np.arange(int(extra.sum()), dtype=np.int64)
        self._tail_rows = self.inverse[np.repeat(long_rows, extra)]
        self._tail_index = index[tail]
        self._tail_weights = None if weights is None else weights[tail]

    def sum(self, source: np.ndarray) -> np.ndarray:
        """``(3, rows)`` float32 sums of ``(3, n)`` float32 ``source`` (rows in natural order)."""
        acc = np.zeros((3, self.rows), dtype=_F32)
        for j, c in enumerate(self.counts):
            s = slice(int(self.offsets[j]), int(self.offsets[j + 1]))
            term = np.take(source, self._index[s], axis=1)
            if self._weights is not None:
                term *= self._weights[s]
            acc[:, :c] += term
        if len(self._tail_rows):
            term = np.take(source, self._tail_index, axis=1)
            if self._tail_weights is not None:
                term *= self._tail_weights
            for k in range(3):
                np.add.at(acc[k], self._tail_rows, term[k])
        return np.take(acc, self.inverse, axis=1)


@dataclass(frozen=True, eq=False)
class PaletteStep(LoopStep):
    """One Loop subdivision step as the decoder applies it (a :class:`crease.loop.LoopStep`, rebuilt
    from the base triangles): new vertex ``r`` is ``sum_e weights[e] * old[cols[e]]`` over ``e`` in
    ``row_ptr[r] .. row_ptr[r + 1]``, summed in float32 in entry order (``SparseMatrix::apply``)."""

    _sums: _RowSums = field(repr=False)

    @classmethod
    def _build(
        cls, rows: int, columns: int, row_ptr: np.ndarray, cols: np.ndarray, weights: np.ndarray
    ) -> "PaletteStep":
        weights = np.asarray(weights, dtype=_F32)
        return cls(
            rows=rows,
            columns=columns,
            row_ptr=row_ptr,
            cols=cols,
            weights=weights,
            _sums=_RowSums(row_ptr, cols, weights),
        )

    @classmethod
    def from_loop(cls, step: LoopStep) -> "PaletteStep":
        """The step of :func:`crease.loop.loop_steps`, with its summation plan."""
        return cls._build(step.rows, step.columns, step.row_ptr, step.cols, step.weights)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``S x`` for ``(columns, 3)`` float32 ``x``: ``(rows, 3)`` float32, each row's products
        summed in entry order (``SparseMatrix::apply``)."""
        x = np.asarray(x, dtype=_F32)
        if x.shape != (self.columns, 3):
            raise PaletteError(f"subdivision step: input of shape {x.shape}, expected ({self.columns}, 3)")
        return np.ascontiguousarray(self._apply(np.ascontiguousarray(x.T)).T)

    def _apply(self, x: np.ndarray) -> np.ndarray:
        """:meth:`apply` on coordinates by row, ``(3, columns)`` to ``(3, rows)``: gathers of
        whole coordinate rows are several times faster than of ``(n, 3)`` points."""
        return self._sums.sum(x)


@dataclass(frozen=True, eq=False)
class PaletteHeader:
    """A palette stream's first message decoded and checked: everything that never changes, as
    NumPy arrays (``core::codec::palette::PaletteHeader`` plus the message's own fields), the
    detail level's Loop steps and drawn triangles rebuilt from the base triangles."""

    model: str
    #: :data:`LEVEL_BASE` or :data:`LEVEL_DETAIL` (an unspecified level reads as base).
    level: int
    #: The lane layout, :data:`PALETTE_VERSION`.
    version: int
    #: Drawn vertices: ``base_vertices``, or at the detail level the last step's rows.
    vertex_count: int
    #: ``(T, 3)`` uint32 triangles of the drawn mesh in model vertex ids: at the base level the
    #: base triangles as the index codec gives them back (it may rotate a triangle's corners;
    #: winding kept), at the detail level their Loop subdivision (``4^L`` per base triangle).
    triangles: np.ndarray
    bones: int
    base_vertices: int
    #: ``(base_vertices, 3)`` float32 rest positions.
    rest: np.ndarray
    #: ``(base_vertices, K)`` bone indices (intp), in the message's slot order.
    skin_bones: np.ndarray
    #: ``(base_vertices, K)`` float32 weights, ``float32(q) / 65535`` in float32 as Rust does.
    skin_weights: np.ndarray
    #: The Loop steps rebuilt from the base triangles, first level first (empty at the base
    #: level).
    steps: list[PaletteStep]
    #: N, the length of every frame's ``xi`` (0 at the base level).
    examples: int
    #: ``(vertex_count, N + 1)`` float32: row v of ``D``, then ``b_v``, each ``float32(q) *
    #: detail_step`` (the values the decoder uses); ``None`` at the base level.
    detail: np.ndarray | None
    actor: str
    actor_index: int
    actor_count: int
    #: K, skin influences per base vertex (1..=8).
    influences: int = 0
    #: ``(base_vertices, K)`` uint16 weights as sent (``q``; each row sums to 65535).
    skin_quantised: np.ndarray | None = None
    #: ``(vertex_count, N + 1)`` int16 detail values as sent (``q``), and their step (float32).
    detail_rows: np.ndarray | None = None
    detail_step: float = 0.0
    #: ``(2, 3)`` float32: the box of the model's poses, min then max (for framing a camera).
    bounds: np.ndarray | None = None
    #: L, the Loop levels from the base mesh to the drawn one (0 at the base level).
    levels: int = 0
    #: ``(T_base, 3)`` uint32 base triangles in model vertex ids: at the detail level in the
    #: model's own corner order (``triangle_turns`` applied), at the base level as decoded.
    base_triangles: np.ndarray | None = None

    @classmethod
    def from_message(cls, topology: Any) -> "PaletteHeader":
        """Decodes and checks a ``crease.v1.PaletteTopology`` (or a ``MeshFrame`` holding one):
        the version, every array's byte length against the counts, influences in 1..=8, bone
        indices below ``bones``, weight sums, the base triangles, and at the detail level the
        corner turns, the detail blocks, the Loop levels, the rebuilt mesh (manifold, its vertex
        count ``vertex_count``) and the detail step, as ``crease_proto::read_palette_topology``
        and ``PaletteHeader::validate`` do.

        Raises:
            PaletteError: the first problem found, naming the field.
        """
        if hasattr(topology, "WhichOneof") and hasattr(topology, "palette_topology"):
            body = topology.WhichOneof("body")
            if body != "palette_topology":
                raise PaletteError(f"MeshFrame: body is {body}, expected palette_topology")
            topology = topology.palette_topology
        t = topology
        if t.version != PALETTE_VERSION:
            raise _err("version", f"{t.version}, this decoder reads palette frames of version {PALETTE_VERSION}")
        if t.level in (0, LEVEL_BASE):
            level = LEVEL_BASE
        elif t.level == LEVEL_DETAIL:
            level = LEVEL_DETAIL
        else:
            raise _err("level", f"{t.level} is not a Level (0 unspecified, 1 base, 2 detail)")
        nb = int(t.base_vertices)
        k = int(t.influences)
        if not 1 <= k <= MAX_INFLUENCES:
            raise _err("influences", f"{k}, expected 1..={MAX_INFLUENCES}")
        rest = _read_le("rest_positions", t.rest_positions, nb * 3, "<f4").reshape(nb, 3)
        slots = nb * k
        narrow = t.bones <= 256
        skin_bones = _read_le("skin_bones", t.skin_bones, slots, "u1" if narrow else "<u2")
        quantised = _read_le("skin_weights", t.skin_weights, slots, "<u2")
        nv = int(t.vertex_count)
        # The base mesh's triangles at both levels.
        try:
            base_triangles = codec.decode_indices(bytes(t.indices), int(t.triangle_count), nb)
        except codec.CodecError as e:
            raise _err("indices", str(e)) from e

        # PaletteHeader::validate.
        bad = np.flatnonzero(~np.isfinite(rest).all(axis=1))
        if len(bad):
            raise _err("rest_positions", f"rest position {bad[0]} is not finite: {rest[bad[0]].tolist()}")
        bad = np.flatnonzero(skin_bones >= t.bones)
        if len(bad):
            raise _err("skin_bones", f"skin bone {bad[0]} is {skin_bones[bad[0]]}, expected < {t.bones}")
        sums = quantised.reshape(nb, k).sum(axis=1, dtype=np.int64)
        bad = np.flatnonzero(sums != WEIGHT_ONE)
        if len(bad):
            raise _err("skin_weights", f"the weights of vertex {bad[0]} sum to {sums[bad[0]]}, expected {WEIGHT_ONE}")

        steps: list[PaletteStep] = []
        examples = levels = 0
        detail = detail_rows = None
        detail_step = 0.0
        triangles = base_triangles
        if level == LEVEL_DETAIL:
            # As the Rust reader: at the base level the detail fields are not read.
            base_triangles = apply_triangle_turns(base_triangles, bytes(t.triangle_turns))
            examples = int(t.examples)
            width = examples + 1
            blocks = -(-width // BLOCK_VALUES)
            if len(t.detail_blocks) != blocks:
                raise _err(
                    "detail_blocks",
                    f"{len(t.detail_blocks)} blocks, expected {blocks} "
                    f"({width} values per row, {BLOCK_VALUES} per block)",
                )
            levels = int(t.subdivision_levels)
            if not 1 <= levels <= MAX_LOOP_LEVELS:
                raise _err("subdivision_levels", f"{levels}, expected 1..={MAX_LOOP_LEVELS} at the detail level")
            try:
                loop, triangles = loop_steps(nb, base_triangles, levels)
            except LoopError as e:
                raise _err("indices", f"the base triangles do not subdivide: {e}") from e
            if nv != loop[-1].rows:
                raise _err("vertex_count", f"{nv}, but {levels} Loop levels of the base mesh give {loop[-1].rows}")
            step = _F32(t.detail_step)
            if not (np.isfinite(step) and step > 0):
                raise _err("detail_step", f"{float(step)}, expected a finite value > 0")
            detail_rows = _read_blocks(t.detail_blocks, nv, width)
            detail_step = float(step)
            # PaletteDetail::value: f32::from(q) * quantum, in float32.
            detail = np.ascontiguousarray(detail_rows.astype(_F32) * step)
            steps = [PaletteStep.from_loop(s) for s in loop]
        elif nv != nb:
            raise _err("vertex_count", f"{nv}, expected {nb} (base_vertices)")

        bounds_min = bounds_max = (0.0, 0.0, 0.0)
        if hasattr(t, "HasField"):
            if not t.HasField("bounds"):
                raise _err("bounds", "missing")
            b = t.bounds
            if b.HasField("min"):
                bounds_min = (b.min.x, b.min.y, b.min.z)
            if b.HasField("max"):
                bounds_max = (b.max.x, b.max.y, b.max.z)

        return cls(
            model=str(t.model),
            level=level,
            version=int(t.version),
            vertex_count=nv,
            triangles=triangles,
            bones=int(t.bones),
            base_vertices=nb,
            rest=rest,
            skin_bones=skin_bones.astype(np.intp).reshape(nb, k),
            skin_weights=quantised.astype(_F32).reshape(nb, k) / _F32(WEIGHT_ONE),
            steps=steps,
            examples=examples,
            detail=detail,
            actor=str(t.actor),
            actor_index=int(t.actor_index),
            actor_count=int(t.actor_count),
            influences=k,
            skin_quantised=quantised.reshape(nb, k),
            detail_rows=detail_rows,
            detail_step=detail_step,
            bounds=np.array([bounds_min, bounds_max], dtype=_F32),
            levels=levels,
            base_triangles=base_triangles,
        )


def apply_triangle_turns(triangles: np.ndarray, turns: bytes) -> np.ndarray:
    """``triangles`` (as the index codec gives them back) each turned left by its entry of
    ``turns`` (``PaletteTopology.triangle_turns``, ``core::codec::apply_corner_turns``): per
    triangle ``k`` in 0..3, four to a byte, low bits first; turned left ``k`` times (``[b, c,
    a]`` for ``k = 1``, ``[c, a, b]`` for ``k = 2``) it is the model's triangle, whose first
    corner Loop's numbering depends on. Returns a new ``(T, 3)`` uint32 array.

    Raises:
        PaletteError: ``turns`` not ``ceil(T / 4)`` bytes, or an entry of 3 (naming the
            triangle).
    """
    count = len(triangles)
    expected = -(-count // 4)
    if len(turns) != expected:
        raise _err("triangle_turns", f"{len(turns)} bytes, expected {expected} (2 bits for each of {count} triangles)")
    packed = np.frombuffer(bytes(turns), dtype=np.uint8)
    k = ((packed[:, None] >> np.array([0, 2, 4, 6], dtype=np.uint8)) & 3).reshape(-1)[:count].astype(np.intp)
    bad = np.flatnonzero(k == 3)
    if len(bad):
        raise _err("triangle_turns", f"triangle {bad[0]}: turn 3, expected 0, 1 or 2")
    corner = (np.arange(3, dtype=np.intp)[None, :] + k[:, None]) % 3
    return np.ascontiguousarray(np.take_along_axis(triangles, corner, axis=1), dtype=np.uint32)


def _read_blocks(blocks: Any, count: int, width: int) -> np.ndarray:
    """``PaletteTopology.detail_blocks`` back to ``(count, width)`` int16: block ``j`` is
    ``count`` 4-byte vertices of meshopt's vertex codec (version 1), values ``2 j`` and ``2 j +
    1`` of every row (the second dropped past the row's end)."""
    rows = np.zeros((count, width), dtype=np.int16)
    for j, data in enumerate(blocks):
        name = f"detail_blocks[{j}]"
        data = bytes(data)
        if not data:
            raise _err(name, "empty, expected a meshopt vertex block")
        if data[0] != _MESHOPT_VERTEX_V1:
            raise _err(name, f"starts with {data[0]:#04x}, expected meshopt's vertex codec v1 header 0xa1")
        if count == 0:
            continue
        try:
            raw = meshopt.decode_vertex_buffer(data, count, 2 * BLOCK_VALUES)
        except (RuntimeError, ValueError) as e:
            raise _err(name, f"meshopt refused the block of {count} vertices: {e}") from e
        values = np.asarray(raw, dtype=np.uint8).reshape(count, 4).view("<i2").astype(np.int16)
        first = j * BLOCK_VALUES
        take = min(BLOCK_VALUES, width - first)
        rows[:, first : first + take] = values[:, :take]
    return rows


class PaletteDecoder:
    """One palette stream: the header, then frames in order (keyframes and deltas via
    :class:`crease.codec.LaneDecoder`: a delta needs the frame it was computed from).

    Allocates its per-frame plans once (subdivision and normal gathers); a frame is a few dozen
    NumPy passes over the drawn vertices.
    """

    header: PaletteHeader

    def __init__(self, topology: Any) -> None:
        """``topology``: a ``crease.v1.PaletteTopology`` (or a ``MeshFrame`` holding one).

        Raises:
            PaletteError: the header's first problem, naming the field.
        """
        self._setup(PaletteHeader.from_message(topology))

    @classmethod
    def from_header(cls, header: PaletteHeader) -> "PaletteDecoder":
        """A decoder of an already decoded (possibly modified) header."""
        self = cls.__new__(cls)
        self._setup(header)
        return self

    def _setup(self, header: PaletteHeader) -> None:
        # Inside, points are stored by coordinate, (3, n): NumPy gathers whole coordinate rows
        # several times faster than (n, 3) points.
        self.header = header
        self._lanes = codec.LaneDecoder()
        h = header
        # SkinWeights::new: each vertex's slots sorted by weight, heaviest first (stable), so the
        # LBS kernel's sum runs in that order and stops at the first zero weight.
        order = np.argsort(-h.skin_weights, axis=1, kind="stable")
        self._skin_bones = np.ascontiguousarray(np.take_along_axis(h.skin_bones, order, axis=1).T)
        self._skin_weights = np.ascontiguousarray(np.take_along_axis(h.skin_weights, order, axis=1).T)
        self._skin_used = self._skin_weights != 0
        self._rest = np.ascontiguousarray(h.rest.T)
        self._detail_t = None
        if h.detail is None:
            return
        # Vertex normals: per drawn vertex its triangle corners in triangle order (the order of
        # accumulate_face_normals' scatter), one pass per incident triangle.
        corners = h.triangles.reshape(-1).astype(np.intp)
        by_vertex = np.argsort(corners, kind="stable")
        ptr = np.zeros(h.vertex_count + 1, dtype=np.int64)
        np.cumsum(np.bincount(corners, minlength=h.vertex_count), out=ptr[1:])
        self._fan = _RowSums(ptr, by_vertex // 3)
        self._corners = [np.ascontiguousarray(h.triangles[:, k].astype(np.intp)) for k in range(3)]
        # D and b by column, contiguous, for the sum over j in order.
        self._detail_t = np.ascontiguousarray(h.detail.T)

    def decode_pose(self, frame: bytes) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """A palette frame's pose: ``(seq, rotations, translations, xi)``, rotations ``(B, 4)``
        unit quaternions ``x, y, z, w`` float32, translations ``(B, 3)`` float32, ``xi`` ``(N,)``
        float32 (``core::codec::palette::read_palette_lanes``).

        Raises:
            crease.codec.CodecError: a frame the codec refuses (a delta without its keyframe...).
            PaletteError: lanes that do not fit the header (count, quaternion index, ``xi``).
        """
        fh, lanes = self._lanes.decode(frame)
        b, n = self.header.bones, self.header.examples
        expected = palette_vertex_count(b, n)
        if len(lanes) != expected:
            raise PaletteError(
                f"palette frame {fh.seq}: {len(lanes)} lane vertices, expected {expected} ({b} bones, {n} xi values)"
            )
        rot = lanes[0 : 2 * b : 2]
        index = rot[:, 3]
        bad = np.flatnonzero(index > 3)
        if len(bad):
            raise PaletteError(
                f"palette frame {fh.seq}: bone {bad[0]}: quaternion index {index[bad[0]]}, expected 0..=3"
            )
        rotations = _from_smallest_three(index.astype(np.intp), rot[:, :3])
        translations = codec.dequantise(lanes[1 : 2 * b : 2], fh)
        pairs = lanes[2 * b :].astype(np.uint32)
        bits = np.stack([pairs[:, 0] | pairs[:, 1] << 16, pairs[:, 2] | pairs[:, 3] << 16], axis=1)
        xi = bits.reshape(-1)[:n].view(_F32).copy()
        bad = np.flatnonzero(~np.isfinite(xi))
        if len(bad):
            raise PaletteError(f"palette frame {fh.seq}: xi {bad[0]} is not finite")
        return fh.seq, rotations, translations, xi

    def decode(self, frame: bytes) -> np.ndarray:
        """The drawn mesh of the stream's next frame: ``(vertex_count, 3)`` float32 vertices in
        model vertex order (index them with ``header.triangles``).

        Raises:
            crease.codec.CodecError, PaletteError: as :meth:`decode_pose`.
        """
        _, rotations, translations, xi = self.decode_pose(frame)
        return self.synthesize(rotations, translations, xi)

    def synthesize(self, rotations: np.ndarray, translations: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """The drawn mesh of a pose (``PaletteSynth::synthesize``): ``rotations`` ``(B, 4)`` unit
        quaternions ``x, y, z, w``, ``translations`` ``(B, 3)``, ``xi`` ``(N,)`` (empty at the
        base level), all taken as float32. Returns ``(vertex_count, 3)`` float32.

        Raises:
            PaletteError: shapes that do not fit the header.
        """
        h = self.header
        rotations = np.asarray(rotations, dtype=_F32)
        translations = np.asarray(translations, dtype=_F32)
        xi = np.asarray(xi, dtype=_F32).reshape(-1)
        if rotations.shape != (h.bones, 4):
            raise PaletteError(f"rotations: shape {rotations.shape}, expected ({h.bones}, 4)")
        if translations.shape != (h.bones, 3):
            raise PaletteError(f"translations: shape {translations.shape}, expected ({h.bones}, 3)")
        if xi.shape != (h.examples,):
            raise PaletteError(f"xi: {xi.shape[0]} values, the header says {h.examples}")
        base = self._skin(_affine(rotations, translations))
        if self._detail_t is None:
            return np.ascontiguousarray(base.T)
        high = base
        for step in h.steps:
            high = step._apply(high)
        normals = self._normals(high)
        # HZY11 eq. 4: h_v = sum_j D_vj xi_j + b_v (PaletteDetail::displacements: the products
        # (q s) xi_j summed in order, then b_v added), and the drawn vertex high_v + h_v n_v.
        # Rust's f32 Sum starts from -0.0 (which keeps the sign of an all-zero sum).
        d = self._detail_t
        hv = np.full(h.vertex_count, -0.0, dtype=_F32)
        for j in range(h.examples):
            hv += d[j] * xi[j]
        hv += d[h.examples]
        normals *= hv
        normals += high
        return np.ascontiguousarray(normals.T)

    def _skin(self, m: np.ndarray) -> np.ndarray:
        """Linear blend skinning, FKY08 eq. 1 (``skin_lbs``): per base vertex the bones' 3x4
        matrices ``m`` (12, B: columns x, y, z, then the translation) blended with its weights
        in slot order (heaviest first, to the first zero), then applied to the rest position
        once. Returns (3, base_vertices)."""
        acc = np.zeros((12, self.header.base_vertices), dtype=_F32)
        for j in range(self.header.influences):
            term = np.take(m, self._skin_bones[j], axis=1)
            term *= self._skin_weights[j]
            acc = np.where(self._skin_used[j], acc + term, acc)
        p = self._rest
        # cx * p.x + cy * p.y + cz * p.z + ct, left to right.
        return acc[0:3] * p[0] + acc[3:6] * p[1] + acc[6:9] * p[2] + acc[9:12]

    def _normals(self, positions: np.ndarray) -> np.ndarray:
        """Unit area-weighted vertex normals (``scatter_normals``) of (3, n) ``positions``: per
        vertex the sum, in triangle order, of its triangles' ``(b - a) x (c - a)``, times ``1 /
        length`` (zero when that is not finite and positive, glam's ``normalize_or_zero``)."""
        a, b, c = self._corners
        pa = np.take(positions, a, axis=1)
        e1 = np.take(positions, b, axis=1)
        e1 -= pa
        e2 = np.take(positions, c, axis=1)
        e2 -= pa
        face = np.empty_like(e1)
        face[0] = e1[1] * e2[2] - e1[2] * e2[1]
        face[1] = e1[2] * e2[0] - e1[0] * e2[2]
        face[2] = e1[0] * e2[1] - e1[1] * e2[0]
        acc = self._fan.sum(face)
        x, y, z = acc
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rcp = _F32(1.0) / np.sqrt(x * x + y * y + z * z)
            ok = np.isfinite(rcp) & (rcp > 0)
            return np.where(ok, acc * rcp, _F32(0.0))


def _from_smallest_three(index: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(B, 4)`` ``x, y, z, w`` from their largest component's index and the
    other three's lanes (``from_smallest_three``), in float32 as Rust: each stored component
    ``(v / 65535 * 2 - 1) / sqrt 2``, the dropped one ``sqrt(max(1 - sum of squares, 0))`` with
    the squares summed in order, then glam's SSE2 ``normalize``."""
    x = (q.astype(_F32) / _F32(65535.0) * _F32(2.0) - _F32(1.0)) * _FRAC_1_SQRT_2
    total = np.zeros(len(q), dtype=_F32)
    for k in range(3):
        total = total + x[:, k] * x[:, k]
    c = np.zeros((len(q), 4), dtype=_F32)
    rows = np.arange(len(q))[:, None]
    c[rows, _OTHERS[index]] = x
    c[np.arange(len(q)), index] = np.sqrt(np.maximum(_F32(1.0) - total, _F32(0.0)))
    sq = c * c
    length = np.sqrt((sq[:, 0] + sq[:, 2]) + (sq[:, 1] + sq[:, 3]))
    return c / length[:, None]


def _affine(rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """Per bone the 3x4 matrix of ``(q, t)`` as ``(12, B)`` float32 rows: columns ``x, y, z`` of
    the rotation then ``t`` (glam's ``Affine3A::from_rotation_translation``, ``Mat3A::from_quat``)."""
    x, y, z, w = (rotations[:, i] for i in range(4))
    x2, y2, z2 = x + x, y + y, z + z
    xx, xy, xz = x * x2, x * y2, x * z2
    yy, yz, zz = y * y2, y * z2, z * z2
    wx, wy, wz = w * x2, w * y2, w * z2
    one = _F32(1.0)
    return np.stack(
        [
            one - (yy + zz), xy + wz, xz - wy,
            xy - wz, one - (xx + zz), yz + wx,
            xz + wy, yz - wx, one - (xx + yy),
            translations[:, 0], translations[:, 1], translations[:, 2],
        ]
    ).astype(_F32, copy=False)
