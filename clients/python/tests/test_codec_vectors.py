"""crease.codec against tests/vectors/codec-v1.json: the frames the Rust encoder wrote, decoded here
with meshopt from PyPI and NumPy, must give the vectors' lanes and positions bit for bit, the
triangles the index codec's, and every malformed frame an error."""

import json
import unittest
from pathlib import Path

import numpy as np

from crease import codec

VECTORS = Path(__file__).resolve().parents[3] / "tests" / "vectors" / "codec-v1.json"


def f32(values) -> np.ndarray:
    return np.array([float(v) for v in values], dtype=np.float32)


class CodecVectors(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.vectors = json.loads(VECTORS.read_text())
        assert cls.vectors["format_version"] == codec.VERSION
        assert cls.vectors["header_len"] == codec.HEADER_LEN

    def test_every_stream_decodes_to_its_lanes_and_positions_bit_for_bit(self) -> None:
        frames = 0
        for stream in self.vectors["streams"]:
            decoder = codec.LaneDecoder()
            for k, frame in enumerate(stream["frames"]):
                with self.subTest(stream=stream["name"], frame=k):
                    header, lanes = decoder.decode(bytes.fromhex(frame["frame_hex"]))
                    self.assertEqual(header.kind, frame["kind"])
                    self.assertEqual(header.seq, int(frame["seq"]))
                    self.assertEqual(header.base, int(frame["base"]))
                    self.assertEqual(header.vertex_count, stream["vertex_count"])
                    np.testing.assert_array_equal(lanes, np.array(frame["lanes"], dtype=np.uint16))
                    payload = codec.decode_payload(codec.parse_frame(bytes.fromhex(frame["frame_hex"]))[1], header.vertex_count)
                    np.testing.assert_array_equal(payload, np.array(frame["payload_lanes"], dtype=np.uint16))
                    want = np.array([f32(p) for p in frame["decoded_positions"]], dtype=np.float32)
                    got = codec.dequantise(lanes, header)
                    # Bit for bit: compare the f32 bit patterns.
                    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
                    if frame["decoded_normals"] is not None:
                        self.assertTrue(header.normals)
                        want_n = np.array([f32(n) for n in frame["decoded_normals"]], dtype=np.float32)
                        np.testing.assert_array_equal(codec.oct_decode(lanes[:, 3]).view(np.uint32), want_n.view(np.uint32))
                    frames += 1
        self.assertGreaterEqual(frames, 8)

    def test_the_table_dequantiser_equals_the_arithmetic_one_bit_for_bit(self) -> None:
        rng = np.random.default_rng(3)
        tables = codec.DequantTables()
        for stream in self.vectors["streams"]:
            header, lanes = codec.LaneDecoder().decode(bytes.fromhex(stream["frames"][0]["frame_hex"]))
            # Every 16-bit value on every axis, in this stream's box.
            lanes = np.zeros((65536, 4), dtype=np.uint16)
            lanes[:, :3] = np.arange(65536, dtype=np.uint16)[:, None]
            rng.shuffle(lanes)
            out = np.empty((65536, 3), dtype=np.float32)
            tables.positions_into(lanes, header, out)
            np.testing.assert_array_equal(out.view(np.uint32), codec.dequantise(lanes, header).view(np.uint32))

    def test_triangles_decode_as_the_index_codec_gives_them(self) -> None:
        for case in self.vectors["indices"]:
            with self.subTest(case=case["name"]):
                tris = codec.decode_indices(bytes.fromhex(case["encoded_hex"]), case["triangle_count"], case["vertex_count"])
                np.testing.assert_array_equal(tris, np.array(case["decoded_triangles"], dtype=np.uint32))
                with self.assertRaisesRegex(codec.CodecError, "indexes vertex"):
                    codec.decode_indices(bytes.fromhex(case["encoded_hex"]), case["triangle_count"], 2)
                with self.assertRaisesRegex(codec.CodecError, "truncated"):
                    codec.decode_indices(bytes.fromhex(case["encoded_hex"])[:10], case["triangle_count"], case["vertex_count"])

    def test_every_malformed_frame_is_refused(self) -> None:
        for case in self.vectors["malformed"]:
            with self.subTest(case=case["about"]):
                with self.assertRaises(codec.CodecError):
                    codec.LaneDecoder().decode(bytes.fromhex(case["frame_hex"]))

    def test_a_delta_needs_its_base(self) -> None:
        stream = next(s for s in self.vectors["streams"] if any(f["kind"] == "delta" for f in s["frames"]))
        delta = next(f for f in stream["frames"] if f["kind"] == "delta")
        with self.assertRaisesRegex(codec.CodecError, "without a base"):
            codec.LaneDecoder().decode(bytes.fromhex(delta["frame_hex"]))


if __name__ == "__main__":
    unittest.main()
