"""Loop subdivision of a fixed topology as sparse matrices, rebuilt from the base triangles with
NumPy (``core::mesh::subdivision::loop_steps``; issue 41).

A detail-level palette header does not carry the Loop steps ``S_1 .. S_L`` nor the drawn
(subdivided) triangles: every decoder rebuilds them from the base mesh's triangles, with one
numbering and one rounding, so that all of them (the Rust core, the viewer's ``web/loop.js``,
this module) get the same matrices bit for bit (``tests/vectors/loop-v1.json``). The rules
(ARCHITECTURE.md, "Palette streams"; Loop 1987 with Warren's beta, boundary rules of Hoppe et
al. 1994 without creases or corners):

- the vertices of a level: the coarser level's first, same ids; then one per edge, in the order
  the edges are first met walking the triangles in order, each triangle ``[a, b, c]`` along
  ``ab``, ``bc``, ``ca``;
- the triangles: each ``[a, b, c]`` becomes ``[a, ab, ca]``, ``[ab, b, bc]``, ``[ca, bc, c]``,
  ``[ab, bc, ca]``, in place;
- the rows, each weight computed in float64 and rounded once to float32, a row's entries sorted
  by column, a column met twice (an edge whose two opposite vertices coincide) summed in float64
  before the rounding: an interior even vertex of valence ``n``: itself ``1 - n beta``, each
  neighbour ``beta`` (``beta = 3 / (8 n)`` for ``n > 3``, ``3/16`` otherwise); a boundary even
  vertex (exactly two boundary edges): itself 3/4, its two boundary neighbours 1/8 each; an
  isolated vertex: itself 1; an interior edge ``(a, b)`` with opposite vertices ``c``, ``d``:
  3/8, 3/8, 1/8, 1/8; a boundary edge: 1/2, 1/2.

The mesh must be edge- and vertex-manifold without degenerate triangles; anything else is a
:class:`LoopError` naming the triangle, edge or vertex, with the Rust core's message. The
several-fans check of ``count_fans`` (two cones touching at their tips) is ported too, as a
connected-components count over each vertex's link, so a mesh is refused here exactly when the
Rust decoder refuses it, and with the same first error.

Everything is vectorised (one sort of the half-edges per level, ``bincount``, fancy indexing):
the demo hand (9,458 base vertices, 18.9k triangles, 2 levels, 151,298 drawn vertices) takes a
fraction of a second.

Usage (``crease.palette`` does this for a detail-level header, and applies the steps in float32
as the Rust decoder does: ``PaletteStep``)::

    steps, drawn = loop_steps(base_vertices, base_triangles, levels)
    high = base                                  # (base_vertices, 3)
    for s in steps:                              # new vertex r = sum_e weights[e] * old[cols[e]]
        rows = np.repeat(np.arange(s.rows), np.diff(s.row_ptr.astype(np.int64)))
        new = np.zeros((s.rows, 3))
        np.add.at(new, rows, s.weights[:, None] * high[s.cols])
        high = new                               # drawn mesh: high, drawn
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MAX_LEVELS", "LoopError", "LoopStep", "loop_steps"]

#: Most Loop levels accepted (``core::mesh::subdivision::MAX_LEVELS``): each level multiplies the
#: triangle count by 4, and the hand at 3 levels is already ~600K vertices, far beyond a frame.
MAX_LEVELS = 3
#: Vertex ids are u32 on the wire and in the Rust core: a subdivided mesh may not exceed them.
_U32_MAX = 0xFFFF_FFFF
#: Marks the missing second opposite vertex of a boundary edge (as the Rust core's ``NONE``).
_NONE = -1


class LoopError(ValueError):
    """A topology Loop subdivision refuses (or a level count outside ``1..=MAX_LEVELS``), with
    ``core::mesh::subdivision::SubdivisionError``'s message: the triangle, edge or vertex."""


@dataclass(frozen=True, eq=False)
class LoopStep:
    """One Loop level as a sparse matrix in CSR form: new vertex ``r`` is ``sum_e weights[e] *
    old[cols[e]]`` over ``e`` in ``row_ptr[r] .. row_ptr[r + 1]`` (``SparseMatrix``)."""

    #: The new level's vertex count.
    rows: int
    #: The previous level's vertex count.
    columns: int
    #: ``rows + 1`` uint32 offsets into ``cols`` and ``weights``, from 0.
    row_ptr: np.ndarray
    #: One uint32 old vertex per entry, ascending and unique within a row.
    cols: np.ndarray
    #: One float32 weight per entry (built in float64, rounded once).
    weights: np.ndarray


def loop_steps(vertex_count: int, triangles: np.ndarray, levels: int) -> tuple[list[LoopStep], np.ndarray]:
    """The one-level matrices ``S_1 .. S_levels`` of ``levels`` Loop subdivisions of a topology
    (``vertex_count`` vertices, ``(T, 3)`` ``triangles``) and the subdivided triangles
    ``(T * 4^levels, 3)`` uint32: what a palette decoder rebuilds from the base triangles,
    bit for bit ``core::mesh::subdivision::loop_steps`` (module docs for the rules).

    Raises:
        LoopError: ``levels`` outside ``1..=MAX_LEVELS``, an index out of range, a degenerate
            triangle, an edge shared by more than two triangles, a vertex with other than 0 or 2
            boundary edges or whose triangles form several fans, a result past u32 ids; the
            first found, as the Rust core reports it.
    """
    if not 1 <= levels <= MAX_LEVELS:
        raise LoopError(f"Loop subdivision: {levels} levels requested, expected 1..={MAX_LEVELS}")
    tris = np.asarray(triangles)
    if tris.ndim != 2 or tris.shape[1] != 3 or (len(tris) and not np.issubdtype(tris.dtype, np.integer)):
        raise LoopError(
            f"Loop subdivision: triangles of shape {tris.shape} and type {tris.dtype}, expected (T, 3) integers"
        )
    tris = tris.astype(np.int64)
    n = int(vertex_count)
    if n < 0:
        raise LoopError(f"Loop subdivision: {n} vertices")
    steps: list[LoopStep] = []
    for _ in range(levels):
        step, tris = _level(n, tris)
        steps.append(step)
        n = step.rows
    return steps, tris.astype(np.uint32)


def _level(n: int, t: np.ndarray) -> tuple[LoopStep, np.ndarray]:
    """One level (``Level::build``): ``n`` vertices, ``(T, 3)`` int64 triangles, checked."""
    nt = len(t)
    # Triangles in order; within one, an index out of range before a repeated vertex.
    out_of_range = (t >= n) | (t < 0)
    bad_index = out_of_range.any(axis=1)
    degenerate = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 2] == t[:, 0])
    bad = np.flatnonzero(bad_index | degenerate)
    if len(bad):
        i = int(bad[0])
        if bad_index[i]:
            index = int(t[i, np.flatnonzero(out_of_range[i])[0]])
            raise LoopError(
                f"Loop subdivision: triangle {i} refers to vertex {index}, but there are only {n} vertices"
            )
        raise LoopError(f"Loop subdivision: triangle {i} {t[i].tolist()} is degenerate (repeats a vertex)")

    # Half-edge i = 3 t + k runs from t[k] to t[k + 1]; its opposite corner is t[k + 2].
    src = t.reshape(-1)
    dst = t[:, [1, 2, 0]].reshape(-1)
    opp = t[:, [2, 0, 1]].reshape(-1)
    lo = np.minimum(src, dst)
    hi = np.maximum(src, dst)
    key = lo * n + hi
    perm = np.argsort(key)
    sorted_key = key[perm]
    new_group = np.empty(len(perm), dtype=bool)
    new_group[:1] = True
    np.not_equal(sorted_key[1:], sorted_key[:-1], out=new_group[1:])
    starts = np.flatnonzero(new_group)
    counts = np.diff(np.append(starts, len(perm)))
    # Edge ids in key order (lo, hi ascending, as the Rust core's sorted half-edges).
    many = np.flatnonzero(counts > 2)
    if len(many):
        e = starts[many[0]]
        a, b = int(lo[perm[e]]), int(hi[perm[e]])
        raise LoopError(
            f"Loop subdivision: edge ({a}, {b}) is shared by {int(counts[many[0]])} triangles "
            "(non-manifold edge; at most 2 allowed)"
        )
    ne = len(starts)
    if n + ne > _U32_MAX:
        raise LoopError(f"Loop subdivision: {n + ne} vertices after subdivision exceed u32 indices")
    edge_of_sorted = np.cumsum(new_group) - 1
    # Each edge's first half-edge in triangle order: its first appearance walking the
    # triangles, which is the new vertices' order.
    first = np.minimum.reduceat(perm, starts) if ne else perm[:0]
    order = np.argsort(first)
    rank = np.empty(ne, dtype=np.int64)
    rank[order] = np.arange(ne, dtype=np.int64)
    edge = np.empty(len(perm), dtype=np.int64)
    edge[perm] = rank[edge_of_sorted]  # per half-edge, its edge in the new vertices' order
    e_lo = lo[first][order]
    e_hi = hi[first][order]
    # The opposite corners (c, d): their order does not matter (a row is sorted by column).
    e_c = opp[perm[starts]][order]
    second = np.where(counts == 2, starts + 1, starts)
    e_d = np.where(counts == 2, opp[perm[second]], _NONE)[order]
    boundary = e_d == _NONE

    # Each edge seen from each end: node 2 e is (e_lo -> e_hi) at e_lo, 2 e + 1 the other way.
    owner = np.empty(2 * ne, dtype=np.int64)
    owner[0::2], owner[1::2] = e_lo, e_hi
    neighbour = np.empty(2 * ne, dtype=np.int64)
    neighbour[0::2], neighbour[1::2] = e_hi, e_lo
    node_boundary = np.repeat(boundary, 2)
    valence = np.bincount(owner, minlength=n)
    boundary_edges = np.bincount(owner[node_boundary], minlength=n)
    fans = _fans(n, ne, src, dst, edge, (perm[starts], perm[second]), owner)

    isolated = valence == 0
    wrong_boundary = ~isolated & (boundary_edges != 0) & (boundary_edges != 2)
    several = ~isolated & ~wrong_boundary & (fans != 1)
    bad = np.flatnonzero(wrong_boundary | several)
    if len(bad):
        v = int(bad[0])
        if wrong_boundary[v]:
            raise LoopError(
                f"Loop subdivision: vertex {v} has {int(boundary_edges[v])} boundary edges "
                "(non-manifold vertex; expected 0 or 2)"
            )
        raise LoopError(
            f"Loop subdivision: the triangles around vertex {v} form {int(fans[v])} separate fans "
            "(non-manifold vertex; expected 1)"
        )

    # Even rows (Warren's beta; Hoppe's boundary rule), in float64.
    nv = valence.astype(np.float64)
    with np.errstate(divide="ignore"):
        beta = np.where(valence > 3, 3.0 / (8.0 * nv), 3.0 / 16.0)
    interior = boundary_edges == 0
    self_weight = np.where(isolated, 1.0, np.where(interior, 1.0 - nv * beta, 0.75))
    keep = interior[owner] | node_boundary
    node_weight = np.where(interior[owner], beta[owner], 0.125)
    verts = np.arange(n, dtype=np.int64)
    # Odd rows, one per edge: a, b, then c, d of an interior edge.
    odd_row = n + np.arange(ne, dtype=np.int64)
    inner = ~boundary
    rows = np.concatenate([verts, owner[keep], odd_row, odd_row, odd_row[inner], odd_row[inner]])
    cols = np.concatenate([verts, neighbour[keep], e_lo, e_hi, e_c[inner], e_d[inner]])
    side = np.where(boundary, 0.5, 0.375)
    vals = np.concatenate(
        [self_weight, node_weight[keep], side, side, np.full(int(inner.sum()), 0.125), np.full(int(inner.sum()), 0.125)]
    )
    # Sorted by row, then column; a column met twice in a row summed (in float64) before rounding.
    width = max(n, 1)
    entry_key = rows * width + cols
    # Keys repeat only for c == d, whose values are equal: no stable sort needed.
    by_key = np.argsort(entry_key)
    entry_key = entry_key[by_key]
    vals = vals[by_key]
    fresh = np.empty(len(entry_key), dtype=bool)
    fresh[:1] = True
    np.not_equal(entry_key[1:], entry_key[:-1], out=fresh[1:])
    heads = np.flatnonzero(fresh)
    if len(heads) != len(entry_key):
        vals = np.add.reduceat(vals, heads)
        entry_key = entry_key[heads]
    out_rows = entry_key // width
    out_cols = entry_key - out_rows * width
    row_ptr = np.zeros(n + ne + 1, dtype=np.int64)
    np.cumsum(np.bincount(out_rows, minlength=n + ne), out=row_ptr[1:])
    step = LoopStep(
        rows=n + ne,
        columns=n,
        row_ptr=row_ptr.astype(np.uint32),
        cols=out_cols.astype(np.uint32),
        weights=vals.astype(np.float32),
    )

    # [a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca] in place.
    mid = (n + edge).reshape(nt, 3)
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    children = np.empty((nt, 4, 3), dtype=np.int64)
    for k, corners in enumerate(((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))):
        for j, corner in enumerate(corners):
            children[:, k, j] = corner
    return step, children.reshape(4 * nt, 3)


def _fans(
    n: int,
    ne: int,
    src: np.ndarray,
    dst: np.ndarray,
    edge: np.ndarray,
    halves: tuple[np.ndarray, np.ndarray],
    owner: np.ndarray,
) -> np.ndarray:
    """Per vertex, the separate fans of triangles around it (``count_fans``): the connected
    components of its link, whose nodes are its edges (seen from it) and whose links are its
    triangles (joining the triangle's two edges at the vertex). The Rust core counts them by
    walking the link; here all links at once by min-label propagation with pointer jumping (a
    node has one link per triangle of its edge, so at most two: ``halves`` gives per edge its
    two half-edges, the same one twice on the boundary; the rounds grow with the longest link,
    a handful at ordinary valences)."""
    if ne == 0:
        return np.zeros(n, dtype=np.int64)
    # Half-edge i's node at its start (src) and at its end (dst).
    at_src = 2 * edge + (src > dst)
    at_dst = 2 * edge + (dst > src)
    # The corner at a half-edge's start joins it to the half-edge before it in its triangle
    # (which arrives there); the corner at its end, to the half-edge after it.
    before = at_dst.reshape(-1, 3)[:, [2, 0, 1]].reshape(-1)
    after = at_src.reshape(-1, 3)[:, [1, 2, 0]].reshape(-1)
    partner = []
    for h in halves:
        # Each half-edge of edge e touches both of e's nodes: one link for each.
        other = np.empty(2 * ne, dtype=np.int64)
        other[at_src[h]] = before[h]
        other[at_dst[h]] = after[h]
        partner.append(other)
    first, last = partner
    label = np.arange(2 * ne, dtype=np.int64)
    while True:
        nxt = np.minimum(label, np.minimum(label[first], label[last]))
        nxt = nxt[nxt]
        if np.array_equal(nxt, label):
            break
        label = nxt
    roots = label == np.arange(2 * ne)
    return np.bincount(owner[roots], minlength=n)
