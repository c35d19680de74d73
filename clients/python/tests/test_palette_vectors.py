"""crease.palette against tests/vectors/palette-v1.json: the PaletteTopology the Rust encoder wrote
must decode to the vectors' header arrays exactly (the base triangles turned back to the model's
corners, the Loop steps and drawn triangles rebuilt from them, the detail values from their meshopt
blocks), each palette frame to the vectors' decoded bones and xi bit for bit, and the drawn mesh to
what the Rust reference decoder (PaletteSynth) synthesised, bit for bit. Broken headers and frames
must be refused, naming what is wrong."""

import json
import math
import re
import struct
import unittest
from pathlib import Path

import meshopt
import numpy as np

from crease import codec, palette
from crease.v1 import crease_pb2

VECTORS = Path(__file__).resolve().parents[3] / "tests" / "vectors" / "palette-v1.json"

#: core::codec::palette::ROTATION_ERROR: a bound on |q' - q| for a stored unit quaternion.
ROTATION_ERROR = 4.0 * (math.sqrt(0.5) / 65535.0)


def f32(values) -> np.ndarray:
    """Floats as the vectors write them (shortest decimals of exact f32s), nested lists kept."""
    return np.array(values, dtype=np.float64).astype(np.float32)


def bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def keyframe(lanes: np.ndarray, like: codec.FrameHeader, seq: int) -> bytes:
    """A core::codec keyframe of ``lanes`` in ``like``'s box (core/src/codec/mod.rs layout)."""
    lanes = np.ascontiguousarray(lanes, dtype="<u2")
    payload = meshopt.encode_vertex_buffer(lanes.view(np.uint8).reshape(len(lanes), 8))
    head = struct.pack(
        "<4sBBBBB3sIII3f3fI", b"CRSF", 1, 0, 0, 8, like.bits, b"\0\0\0", len(lanes), seq, seq,
        *like.min.tolist(), *like.step.tolist(), len(payload),
    )  # fmt: skip
    return head + payload


class PaletteVectors(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.vectors = json.loads(VECTORS.read_text())
        assert cls.vectors["version"] == palette.PALETTE_VERSION
        message = crease_pb2.MeshFrame.FromString(bytes.fromhex(cls.vectors["header_hex"]))
        assert message.WhichOneof("body") == "palette_topology"
        cls.topology = message.palette_topology
        cls.want = cls.vectors["header"]

    def decoder(self) -> palette.PaletteDecoder:
        return palette.PaletteDecoder(self.topology)

    def test_the_header_decodes_to_the_vectors_arrays_exactly(self) -> None:
        h = self.decoder().header
        w = self.want
        self.assertEqual((h.model, h.level, h.version), ("tetra", palette.LEVEL_DETAIL, 1))
        self.assertEqual(h.bones, w["bones"])
        self.assertEqual(h.influences, w["influences"])
        self.assertEqual(h.base_vertices, len(w["rest"]))
        self.assertEqual(h.examples, w["examples"])
        self.assertEqual(h.levels, w["levels"])
        self.assertEqual((h.actor, h.actor_index, h.actor_count), ("", 0, 0))
        np.testing.assert_array_equal(bits(h.rest), bits(f32(w["rest"])))
        k = w["influences"]
        np.testing.assert_array_equal(h.skin_bones, np.array(w["skin_bones"]).reshape(-1, k))
        q = np.array(w["skin_weights"], dtype=np.uint16).reshape(-1, k)
        np.testing.assert_array_equal(h.skin_quantised, q)
        self.assertEqual(h.skin_weights.dtype, np.float32)
        # w = q / 65535 divided in float32, as SkinWeights gets it from PaletteHeader::skin_weights.
        np.testing.assert_array_equal(bits(h.skin_weights), bits(q.astype(np.float32) / np.float32(65535)))
        np.testing.assert_array_equal(h.skin_quantised.sum(axis=1), 65535)
        # The Loop steps rebuilt from the base triangles are the Rust core's, bit for bit.
        self.assertEqual(len(h.steps), len(w["steps"]))
        self.assertEqual(len(h.steps), w["levels"])
        columns = h.base_vertices
        for step, ws in zip(h.steps, w["steps"]):
            self.assertEqual(step.columns, ws["columns"])
            self.assertEqual(step.columns, columns)
            self.assertEqual(step.rows, len(ws["row_ptr"]) - 1)
            np.testing.assert_array_equal(step.row_ptr, ws["row_ptr"])
            np.testing.assert_array_equal(step.cols, ws["cols"])
            np.testing.assert_array_equal(bits(step.weights), bits(f32(ws["weights"])))
            columns = step.rows
        self.assertEqual(h.vertex_count, columns)
        self.assertEqual(h.vertex_count, self.topology.vertex_count)
        n = w["examples"]
        rows = np.array(w["detail_rows"], dtype=np.int16).reshape(-1, n + 1)
        step = f32(w["detail_step"])
        self.assertEqual(rows.shape[0], h.vertex_count)
        np.testing.assert_array_equal(h.detail_rows, rows)
        self.assertEqual(np.float32(h.detail_step).view(np.uint32), step.view(np.uint32))
        # D and b as the decoder uses them: float32(q) * step, one float32 product.
        self.assertEqual((h.detail.shape, h.detail.dtype), ((h.vertex_count, n + 1), np.float32))
        np.testing.assert_array_equal(bits(h.detail), bits(rows.astype(np.float32) * step))
        np.testing.assert_array_equal(h.bounds, [[-1, -1, -1], [2, 2, 2]])

    def test_triangles_are_turned_back_and_subdivided_as_the_model_has_them(self) -> None:
        h = self.decoder().header
        w = self.want
        self.assertEqual(self.topology.triangle_count, len(w["triangles"]))
        self.assertEqual(bytes(self.topology.triangle_turns), bytes(w["triangle_turns"]))
        self.assertEqual(len(w["triangle_turns"]), -(-len(w["triangles"]) // 4))
        # What the index codec gives back: each one a rotation of the model's (corners and
        # winding kept), and the turns make it the model's again.
        raw = codec.decode_indices(bytes(self.topology.indices), self.topology.triangle_count, h.base_vertices)
        np.testing.assert_array_equal(raw, np.array(w["decoded_triangles"], dtype=np.uint32))
        for got, t in zip(raw.tolist(), w["triangles"]):
            self.assertIn(got, [t, t[1:] + t[:1], t[2:] + t[:2]])
        self.assertEqual(h.base_triangles.dtype, np.uint32)
        np.testing.assert_array_equal(h.base_triangles, np.array(w["triangles"], dtype=np.uint32))
        np.testing.assert_array_equal(palette.apply_triangle_turns(raw, bytes(w["triangle_turns"])), w["triangles"])
        # The drawn triangles: the Loop subdivision of the model's, 4^L each, in place.
        self.assertEqual(h.triangles.dtype, np.uint32)
        np.testing.assert_array_equal(h.triangles, np.array(w["drawn_triangles"], dtype=np.uint32))
        self.assertEqual(len(h.triangles), len(w["triangles"]) * 4 ** w["levels"])

    def test_turns_by_hand(self) -> None:
        tris = np.array([[1, 2, 3]] * 5, dtype=np.uint32)
        # Triangles 0..3 in byte 0 (turns 0, 1, 2, 0, low bits first), triangle 4 in byte 1 (2).
        got = palette.apply_triangle_turns(tris, bytes([0b00_10_01_00, 0b10]))
        np.testing.assert_array_equal(got, [[1, 2, 3], [2, 3, 1], [3, 1, 2], [1, 2, 3], [3, 1, 2]])
        with self.assertRaisesRegex(palette.PaletteError, r"triangle_turns: triangle 3: turn 3"):
            palette.apply_triangle_turns(tris, bytes([0b11_00_00_00, 0]))
        with self.assertRaisesRegex(palette.PaletteError, r"triangle_turns: 1 bytes, expected 2"):
            palette.apply_triangle_turns(tris, bytes([0]))

    def test_frames_decode_to_the_vectors_bones_and_xi_bit_for_bit(self) -> None:
        decoder = self.decoder()
        lanes = codec.LaneDecoder()
        for k, frame in enumerate(self.vectors["frames"]):
            with self.subTest(frame=k, kind=frame["kind"]):
                data = bytes.fromhex(frame["frame_hex"])
                fh, got_lanes = lanes.decode(data)
                self.assertEqual(fh.kind, frame["kind"].lower())
                np.testing.assert_array_equal(got_lanes, np.array(frame["lanes"], dtype=np.uint16))
                seq, rotations, translations, xi = decoder.decode_pose(data)
                self.assertEqual(seq, fh.seq)
                want_r = f32([b["rotation_xyzw"] for b in frame["decoded_bones"]])
                want_t = f32([b["translation"] for b in frame["decoded_bones"]])
                # Bit for bit (not merely within an ulp): the same float32 operations in the same
                # order as from_smallest_three and glam's SSE2 Quat::normalize.
                np.testing.assert_array_equal(bits(rotations), bits(want_r))
                np.testing.assert_array_equal(bits(translations), bits(want_t))
                np.testing.assert_array_equal(bits(xi), bits(f32(frame["decoded_xi"])))
                # xi travels exactly; the bones within the format's bounds of the encoder's input.
                np.testing.assert_array_equal(bits(xi), bits(f32(frame["xi"])))
                for got, want in zip(rotations.astype(np.float64), frame["bones"]):
                    q = np.array(want["rotation_xyzw"], dtype=np.float64)
                    q /= np.linalg.norm(q)
                    self.assertLessEqual(min(np.linalg.norm(got - q), np.linalg.norm(got + q)), ROTATION_ERROR)
                error = f32([b["translation"] for b in frame["bones"]]) - translations
                self.assertTrue(np.all(np.abs(error) <= fh.step * 0.5 * 1.001 + 1e-7), error)

    def test_the_drawn_mesh_is_the_reference_decoders(self) -> None:
        # The vectors' `synthesized` comes from PaletteSynth built on the encoder's header; the
        # decoder rebuilds the same drawn triangles (the corner turns undo the index codec's
        # rotations) and the same steps, so the result is the same bit for bit.
        decoder = self.decoder()
        h = decoder.header
        for k, frame in enumerate(self.vectors["frames"]):
            with self.subTest(frame=k, kind=frame["kind"]):
                got = decoder.decode(bytes.fromhex(frame["frame_hex"]))
                self.assertEqual((got.shape, got.dtype), ((h.vertex_count, 3), np.float32))
                np.testing.assert_array_equal(bits(got), bits(f32(frame["synthesized"])))

    def test_synthesize_of_a_decoded_pose_is_decode(self) -> None:
        a, b = self.decoder(), self.decoder()
        for frame in self.vectors["frames"]:
            data = bytes.fromhex(frame["frame_hex"])
            _, rotations, translations, xi = a.decode_pose(data)
            np.testing.assert_array_equal(bits(a.synthesize(rotations, translations, xi)), bits(b.decode(data)))
        with self.assertRaisesRegex(palette.PaletteError, "xi"):
            a.synthesize(rotations, translations, xi[:1])
        with self.assertRaisesRegex(palette.PaletteError, "rotations"):
            a.synthesize(rotations[:1], translations, xi)

    def test_a_delta_without_its_keyframe_is_refused(self) -> None:
        delta = next(f for f in self.vectors["frames"] if f["kind"] == "Delta")
        with self.assertRaisesRegex(codec.CodecError, "without a base"):
            self.decoder().decode(bytes.fromhex(delta["frame_hex"]))

    def test_lanes_that_do_not_fit_the_header_are_refused(self) -> None:
        frame = self.vectors["frames"][0]
        like, _ = codec.parse_frame(bytes.fromhex(frame["frame_hex"]))
        lanes = np.array(frame["lanes"], dtype=np.uint16)
        self.decoder().decode(keyframe(lanes, like, 7))  # the re-encoded keyframe itself reads
        bad_index = lanes.copy()
        bad_index[2, 3] = 4
        nan = np.array([np.nan], dtype=np.float32).view(np.uint32)[0]
        bad_xi = lanes.copy()
        bad_xi[4, 2:] = [nan & 0xFFFF, nan >> 16]
        for what, broken, pattern in [
            ("count", lanes[:4], "4 lane vertices, expected 5"),
            ("index", bad_index, "bone 1: quaternion index 4"),
            ("xi", bad_xi, "xi 1 is not finite"),
        ]:
            with self.subTest(what=what), self.assertRaisesRegex(palette.PaletteError, pattern):
                self.decoder().decode(keyframe(broken, like, 7))

    def test_broken_header_fields_are_refused_naming_the_field(self) -> None:
        def set_byte(field: str, at: int, value: int):
            def edit(t):
                data = bytearray(getattr(t, field))
                data[at] = value
                setattr(t, field, bytes(data))

            return edit

        def truncate(field: str):
            return lambda t: setattr(t, field, getattr(t, field)[:-1])

        def block(j: int, edit):
            def apply(t):
                blocks = [edit(bytes(b)) if i == j else bytes(b) for i, b in enumerate(t.detail_blocks)]
                del t.detail_blocks[:]
                t.detail_blocks.extend(blocks)

            return apply

        nan = struct.pack("<f", float("nan"))
        # The tetrahedron with a fifth triangle on its edge (0, 1): 5 triangles, 2 turn bytes.
        five = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [0, 1, 2]], dtype=np.uint32)

        def non_manifold(t):
            t.triangle_count = len(five)
            t.indices = meshopt.encode_index_buffer(five.reshape(-1))
            t.triangle_turns = bytes(2)

        cases = [
            ("version", lambda t: setattr(t, "version", 2)),
            ("level", lambda t: setattr(t, "level", 7)),
            ("influences", lambda t: setattr(t, "influences", 0)),
            ("influences", lambda t: setattr(t, "influences", 9)),
            ("rest_positions", truncate("rest_positions")),
            ("rest_positions", lambda t: setattr(t, "rest_positions", nan + t.rest_positions[4:])),
            ("skin_bones", truncate("skin_bones")),
            ("skin_bones", set_byte("skin_bones", 3, 2)),  # bone 2 of 2
            ("skin_weights", truncate("skin_weights")),
            ("skin_weights", set_byte("skin_weights", 0, 0)),  # vertex 0's weights no longer sum to 65535
            ("indices", truncate("indices")),
            ("indices", lambda t: setattr(t, "triangle_count", t.triangle_count + 1)),
            ("indices", set_byte("indices", 0, 0)),
            ("indices", non_manifold),  # edge (0, 1) in three triangles
            ("triangle_turns", lambda t: setattr(t, "triangle_turns", b"")),
            ("triangle_turns", lambda t: setattr(t, "triangle_turns", t.triangle_turns + b"\0")),
            ("triangle_turns", lambda t: setattr(t, "triangle_turns", bytes([t.triangle_turns[0] | 0b11]))),  # turn 3
            ("detail_blocks", lambda t: t.detail_blocks.pop()),
            ("detail_blocks", lambda t: t.detail_blocks.append(t.detail_blocks[0])),
            ("detail_blocks", lambda t: setattr(t, "examples", t.examples + 2)),  # 5 values a row: 3 blocks
            ("detail_blocks[0]", block(0, lambda b: b[: len(b) // 2])),  # meshopt refuses it
            ("detail_blocks[1]", block(1, lambda b: b"")),
            ("detail_blocks[1]", block(1, lambda b: b"\xa0" + b[1:])),  # not the vertex codec's version 1
            ("subdivision_levels", lambda t: setattr(t, "subdivision_levels", 0)),
            ("subdivision_levels", lambda t: setattr(t, "subdivision_levels", 4)),
            # One Loop level of the tetrahedron: 4 + 6 = 10 vertices; two: 10 + 24 = 34.
            ("vertex_count", lambda t: setattr(t, "vertex_count", t.vertex_count + 1)),
            ("vertex_count", lambda t: setattr(t, "subdivision_levels", 2)),
            ("detail_step", lambda t: setattr(t, "detail_step", 0.0)),
            ("detail_step", lambda t: setattr(t, "detail_step", float("nan"))),
            # At the base level the drawn mesh is the base mesh: 4 vertices, not 10.
            ("vertex_count", lambda t: setattr(t, "level", crease_pb2.LEVEL_BASE)),
            ("bounds", lambda t: t.ClearField("bounds")),
        ]
        for field, edit in cases:
            with self.subTest(field=field):
                t = crease_pb2.PaletteTopology()
                t.CopyFrom(self.topology)
                edit(t)
                with self.assertRaisesRegex(palette.PaletteError, re.escape(f"PaletteTopology.{field}:")):
                    palette.PaletteDecoder(t)
        # Unchanged, it reads; and a MeshFrame whose body is something else is refused.
        palette.PaletteDecoder(crease_pb2.MeshFrame(palette_topology=self.topology))
        with self.assertRaisesRegex(palette.PaletteError, "body"):
            palette.PaletteDecoder(crease_pb2.MeshFrame(frame=crease_pb2.Frame()))

    def test_at_the_base_level_the_drawn_mesh_is_the_skinned_rest_mesh(self) -> None:
        # The vectors' header read as a base-level stream: the rest tetrahedron, its skin, no
        # detail fields read; frames of bones alone (2 B lane vertices). Checked against LBS in
        # float64 (FKY08 eq. 1): float32 rounding of unit-sized values, a few 1e-7. Both frames,
        # each re-encoded as a keyframe of its bone lanes.
        t = crease_pb2.PaletteTopology()
        t.CopyFrom(self.topology)
        t.level = crease_pb2.LEVEL_BASE
        t.vertex_count = len(self.want["rest"])
        tetra = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.uint32)
        t.triangle_count = len(tetra)
        t.indices = meshopt.encode_index_buffer(tetra.reshape(-1))
        decoder = palette.PaletteDecoder(t)
        h = decoder.header
        self.assertEqual(
            (h.level, h.vertex_count, h.examples, h.levels, h.steps, h.detail), (palette.LEVEL_BASE, 4, 0, 0, [], None)
        )
        # At the base level the drawn triangles are the base ones, as the index codec gives them.
        np.testing.assert_array_equal(h.triangles, h.base_triangles)
        np.testing.assert_array_equal(h.triangles, codec.decode_indices(t.indices, 4, 4))
        rest = f32(self.want["rest"]).astype(np.float64)
        k = self.want["influences"]
        bones = np.array(self.want["skin_bones"]).reshape(-1, k)
        weights = np.array(self.want["skin_weights"], dtype=np.float64).reshape(-1, k) / 65535.0
        for n, frame in enumerate(self.vectors["frames"]):
            like, _ = codec.parse_frame(bytes.fromhex(frame["frame_hex"]))
            lanes = np.array(frame["lanes"], dtype=np.uint16)[: 2 * h.bones]
            got = decoder.decode(keyframe(lanes, like, n))
            want = np.zeros_like(rest)
            rotations = f32([b["rotation_xyzw"] for b in frame["decoded_bones"]]).astype(np.float64)
            translations = f32([b["translation"] for b in frame["decoded_bones"]]).astype(np.float64)
            for v in range(len(rest)):
                for slot in range(k):
                    x, y, z, w = rotations[bones[v, slot]]
                    r = np.array(
                        [
                            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
                        ]
                    )
                    want[v] += weights[v, slot] * (r @ rest[v] + translations[bones[v, slot]])
            self.assertEqual((got.shape, got.dtype), ((4, 3), np.float32))
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
        # A detail-level frame (it carries xi) does not fit a base-level stream.
        with self.assertRaisesRegex(palette.PaletteError, "5 lane vertices, expected 4"):
            palette.PaletteDecoder(t).decode(bytes.fromhex(self.vectors["frames"][0]["frame_hex"]))

    def test_long_rows_sum_in_order_past_the_vectorised_passes(self) -> None:
        # A step with rows of up to 90 entries (past _RowSums.MAX_PASSES), an empty row, and
        # weights and values of mixed magnitude: each row must be the float32 sequential sum.
        rng = np.random.default_rng(18)
        columns = 120
        lengths = [0, 3, 90, 1, 40, 7, 33, 0, 2]
        cols = np.concatenate([np.sort(rng.choice(columns, n, replace=False)) for n in lengths]).astype(np.uint32)
        row_ptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.uint32)
        table = (rng.standard_normal(17) * 10.0 ** rng.integers(-4, 4, 17)).astype(np.float32)
        weights = table[rng.integers(0, len(table), len(cols))]
        step = palette.PaletteStep._build(len(lengths), columns, row_ptr, cols, weights)
        x = (rng.standard_normal((columns, 3)) * 10.0 ** rng.integers(-3, 3, (columns, 1))).astype(np.float32)
        got = step.apply(x)
        want = np.zeros((len(lengths), 3), dtype=np.float32)
        for r in range(len(lengths)):
            for e in range(row_ptr[r], row_ptr[r + 1]):
                want[r] = want[r] + x[cols[e]] * weights[e]
        np.testing.assert_array_equal(bits(got), bits(want))


if __name__ == "__main__":
    unittest.main()
