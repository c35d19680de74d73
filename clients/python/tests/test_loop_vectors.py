"""crease.loop against tests/vectors/loop-v1.json (the Rust core's `loop_steps` of a few meshes:
every step's CSR and weights, and the subdivided triangles, equal bit for bit), against an
independent, deliberately plain port of the rules (ARCHITECTURE.md, "Palette streams": one
dictionary per row, one Python loop per vertex and edge) on meshes with boundaries, valences 2 to
8, an isolated vertex and an edge whose two opposite vertices coincide, and on what it must
refuse, with the Rust core's messages."""

import json
import re
import unittest
from collections import defaultdict
from pathlib import Path

import numpy as np

from crease import loop

VECTORS = Path(__file__).resolve().parents[3] / "tests" / "vectors" / "loop-v1.json"


def f32(values) -> np.ndarray:
    """Floats as the vectors write them (shortest decimals of exact f32s)."""
    return np.array(values, dtype=np.float64).astype(np.float32)


def bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def plain_level(n: int, triangles: list[list[int]]) -> tuple[list[dict[int, float]], list[list[int]]]:
    """One Loop level by the written rules, one row at a time: rows as {column: float64 weight}
    (a column met twice summed), and the new triangles. Assumes a valid manifold mesh."""
    opposite: dict[tuple[int, int], list[int]] = {}
    order: list[tuple[int, int]] = []
    for a, b, c in triangles:
        for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
            e = (min(u, v), max(u, v))
            if e not in opposite:
                opposite[e] = []
                order.append(e)
            opposite[e].append(w)
    neighbours: dict[int, set[int]] = defaultdict(set)
    for a, b in opposite:
        neighbours[a].add(b)
        neighbours[b].add(a)
    rows: list[dict[int, float]] = []
    for v in range(n):
        ring = neighbours[v]
        on_boundary = [u for u in ring if len(opposite[(min(u, v), max(u, v))]) == 1]
        row: dict[int, float] = defaultdict(float)
        if not ring:
            row[v] += 1.0
        elif not on_boundary:
            k = len(ring)
            beta = 3.0 / (8.0 * k) if k > 3 else 3.0 / 16.0
            row[v] += 1.0 - k * beta
            for u in ring:
                row[u] += beta
        else:
            assert len(on_boundary) == 2
            row[v] += 0.75
            for u in on_boundary:
                row[u] += 0.125
        rows.append(row)
    for a, b in order:
        row = defaultdict(float)
        ops = opposite[(a, b)]
        if len(ops) == 1:
            row[a] += 0.5
            row[b] += 0.5
        else:
            row[a] += 0.375
            row[b] += 0.375
            row[ops[0]] += 0.125
            row[ops[1]] += 0.125
        rows.append(row)
    rank = {e: i for i, e in enumerate(order)}
    mid = lambda u, v: n + rank[(min(u, v), max(u, v))]  # noqa: E731
    out = []
    for a, b, c in triangles:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
    return rows, out


def torus(m: int, k: int) -> tuple[int, np.ndarray]:
    """A closed m x k torus grid: valence 6 everywhere."""
    i, j = np.meshgrid(np.arange(m), np.arange(k), indexing="ij")
    v = lambda a, b: (a % m) * k + (b % k)  # noqa: E731
    t1 = np.stack([v(i, j), v(i + 1, j), v(i + 1, j + 1)], -1).reshape(-1, 3)
    t2 = np.stack([v(i, j), v(i + 1, j + 1), v(i, j + 1)], -1).reshape(-1, 3)
    return m * k, np.concatenate([t1, t2])


def grid(m: int, k: int) -> tuple[int, np.ndarray]:
    """An open (m + 1) x (k + 1) grid: boundary, corners of valence 2 and 3."""
    i, j = np.meshgrid(np.arange(m), np.arange(k), indexing="ij")
    v = lambda a, b: a * (k + 1) + b  # noqa: E731
    t1 = np.stack([v(i, j), v(i + 1, j), v(i + 1, j + 1)], -1).reshape(-1, 3)
    t2 = np.stack([v(i, j), v(i + 1, j + 1), v(i, j + 1)], -1).reshape(-1, 3)
    return (m + 1) * (k + 1), np.concatenate([t1, t2])


def shuffled(n: int, tris: np.ndarray, seed: int) -> tuple[int, np.ndarray]:
    """The same surface with its vertices renamed, its triangles reordered and each one's first
    corner moved (winding kept): first-appearance numbering must follow all of that."""
    rng = np.random.default_rng(seed)
    names = rng.permutation(n)
    tris = names[tris][rng.permutation(len(tris))]
    turn = rng.integers(0, 3, len(tris))
    corner = (np.arange(3)[None, :] + turn[:, None]) % 3
    return n, np.take_along_axis(tris, corner, axis=1)


MESHES = {
    "tetrahedron": (4, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])),
    "quad with an isolated vertex": (5, np.array([[0, 1, 2], [0, 2, 3]])),
    # Both triangles share all three edges: each edge's two opposite vertices coincide (a row
    # whose column appears twice), valence 2. (Its level 1 is no longer manifold: the two middle
    # triangles share all their edges with the corner ones; only one level here.)
    "pillow": (3, np.array([[0, 1, 2], [1, 0, 2]])),
    # An octahedron: valence 4; a fan of 8 around a centre: valence 8 inside, boundary outside.
    "octahedron": (
        6,
        np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]),
    ),
    "fan of 8": (9, np.array([[8, i, (i + 1) % 8] for i in range(8)])),
    "shuffled torus": shuffled(*torus(5, 7), seed=1),
    "shuffled grid": shuffled(*grid(4, 6), seed=2),
}


class LoopVectors(unittest.TestCase):
    def test_the_rust_cores_steps_bit_for_bit(self) -> None:
        vectors = json.loads(VECTORS.read_text())
        self.assertGreater(len(vectors["meshes"]), 0)
        for mesh in vectors["meshes"]:
            with self.subTest(mesh=mesh["name"]):
                tris = np.array(mesh["triangles"], dtype=np.uint32).reshape(-1, 3)
                steps, subdivided = loop.loop_steps(mesh["vertex_count"], tris, mesh["levels"])
                self.assertEqual(len(steps), len(mesh["steps"]))
                self.assertEqual(len(steps), mesh["levels"])
                for got, want in zip(steps, mesh["steps"]):
                    self.assertEqual((got.rows, got.columns), (want["rows"], want["columns"]))
                    dtypes = (got.row_ptr.dtype, got.cols.dtype, got.weights.dtype)
                    self.assertEqual(dtypes, (np.uint32, np.uint32, np.float32))
                    np.testing.assert_array_equal(got.row_ptr, want["row_ptr"])
                    np.testing.assert_array_equal(got.cols, want["cols"])
                    np.testing.assert_array_equal(bits(got.weights), bits(f32(want["weights"])))
                self.assertEqual(subdivided.dtype, np.uint32)
                np.testing.assert_array_equal(subdivided, np.array(mesh["subdivided_triangles"]).reshape(-1, 3))


class LoopAgainstThePlainRules(unittest.TestCase):
    def test_every_level_matches_the_plain_rules(self) -> None:
        for name, (n, tris) in MESHES.items():
            for levels in (1,) if name == "pillow" else (1, 2):
                with self.subTest(mesh=name, levels=levels):
                    steps, subdivided = loop.loop_steps(n, tris.astype(np.uint32), levels)
                    count, current = n, tris.tolist()
                    for step in steps:
                        rows, current = plain_level(count, current)
                        self.assertEqual((step.rows, step.columns), (len(rows), count))
                        want_ptr = np.concatenate([[0], np.cumsum([len(r) for r in rows])])
                        np.testing.assert_array_equal(step.row_ptr, want_ptr)
                        np.testing.assert_array_equal(step.cols, [c for r in rows for c in sorted(r)])
                        # Each weight rounded once from its float64 sum.
                        want_w = np.array([r[c] for r in rows for c in sorted(r)], dtype=np.float64).astype(np.float32)
                        np.testing.assert_array_equal(bits(step.weights), bits(want_w))
                        count = len(rows)
                    np.testing.assert_array_equal(subdivided, current)
                    self.assertEqual(subdivided.shape, (len(tris) * 4**levels, 3))

    def test_rows_are_affine_and_known_rows_have_their_weights(self) -> None:
        steps, _ = loop.loop_steps(*MESHES["pillow"], 1)
        s = steps[0]
        rows = np.repeat(np.arange(s.rows), np.diff(s.row_ptr.astype(np.int64)))
        np.testing.assert_allclose(np.bincount(rows, s.weights.astype(np.float64)), 1.0, rtol=0, atol=1e-7)
        # Vertex 0 of the pillow: interior, valence 2, beta = 3/16: 1 - 2 * 3/16 = 5/8.
        self.assertEqual(s.cols[s.row_ptr[0] : s.row_ptr[1]].tolist(), [0, 1, 2])
        self.assertEqual(s.weights[s.row_ptr[0] : s.row_ptr[1]].tolist(), [0.625, 0.1875, 0.1875])
        # Edge (0, 1), the first met: opposite 2 on both sides, 1/8 + 1/8 in one entry.
        self.assertEqual(s.cols[s.row_ptr[3] : s.row_ptr[4]].tolist(), [0, 1, 2])
        self.assertEqual(s.weights[s.row_ptr[3] : s.row_ptr[4]].tolist(), [0.375, 0.375, 0.25])
        # An octahedron vertex (valence 4, beta = 3/32): 1 - 4 * 3/32 = 5/8, four neighbours.
        s = loop.loop_steps(*MESHES["octahedron"], 1)[0][0]
        self.assertEqual(s.weights[s.row_ptr[0] : s.row_ptr[1]].tolist(), [0.625] + [0.09375] * 4)
        # The isolated vertex keeps its position at every level.
        for s in loop.loop_steps(*MESHES["quad with an isolated vertex"], 3)[0]:
            self.assertEqual((s.cols[s.row_ptr[4] : s.row_ptr[5]].tolist(), s.weights[s.row_ptr[4]]), ([4], 1.0))

    def test_what_the_rules_refuse_is_named_as_the_rust_core_names_it(self) -> None:
        two_tetrahedra = np.array(
            [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [0, 5, 4], [0, 4, 6], [0, 6, 5], [4, 5, 6]]
        )
        cases = [
            (4, MESHES["tetrahedron"][1], 0, "Loop subdivision: 0 levels requested, expected 1..=3"),
            (4, MESHES["tetrahedron"][1], 4, "Loop subdivision: 4 levels requested, expected 1..=3"),
            (3, np.array([[0, 1, 2], [1, 2, 7]]), 1, "Loop subdivision: triangle 1 refers to vertex 7, but there are only 3 vertices"),
            (4, np.array([[0, 1, 2], [1, 1, 2], [0, 9, 9]]), 1, "Loop subdivision: triangle 1 [1, 1, 2] is degenerate (repeats a vertex)"),
            (5, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]), 1, "Loop subdivision: edge (0, 1) is shared by 3 triangles (non-manifold edge; at most 2 allowed)"),
            # A bowtie: two triangles meeting at vertex 2.
            (5, np.array([[0, 1, 2], [2, 3, 4]]), 1, "Loop subdivision: vertex 2 has 4 boundary edges (non-manifold vertex; expected 0 or 2)"),
            # Two closed tetrahedra touching at vertex 0: no boundary, two fans.
            (7, two_tetrahedra, 2, "Loop subdivision: the triangles around vertex 0 form 2 separate fans (non-manifold vertex; expected 1)"),
            # An open fan and a closed tetrahedron at vertex 0: two boundary edges, two fans.
            (7, np.concatenate([[[0, 1, 2], [0, 2, 3]], two_tetrahedra[4:]]), 1, "Loop subdivision: the triangles around vertex 0 form 2 separate fans (non-manifold vertex; expected 1)"),
        ]  # fmt: skip
        for n, tris, levels, message in cases:
            with self.subTest(message=message), self.assertRaisesRegex(loop.LoopError, f"^{re.escape(message)}$"):
                loop.loop_steps(n, tris.astype(np.uint32), levels)
        # Nothing at all subdivides to itself: every vertex isolated.
        steps, tris = loop.loop_steps(3, np.zeros((0, 3), dtype=np.uint32), 2)
        self.assertEqual((steps[-1].rows, tris.shape), (3, (0, 3)))


if __name__ == "__main__":
    unittest.main()
