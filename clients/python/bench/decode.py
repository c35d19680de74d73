"""Benchmark: the Python package's per-frame decode of recorded mesh streams (`crease watch
--record`), against its floor, meshopt's decode of the same payloads alone (figures in
BENCHMARKS.md, "The Python package").

    target/crease-py/bin/python clients/python/bench/decode.py CAPTURE [CAPTURE ...]

Per capture: the median time per frame of `MeshStream.push` (header parse, meshopt, deltas,
dequantisation or CPU skinning, the vertex order undone) and of `meshopt.decode_vertex_buffer`
alone on each frame's payload, over 5 passes; one thread (NumPy's own, which these loops do
not use).
"""

import statistics
import sys
import time

import meshopt

import crease
from crease import codec


def main() -> None:
    for path in sys.argv[1:]:
        messages = crease.read_capture(path)
        frames = [m for m in messages if m.WhichOneof("body") == "frame"]
        full, floor = [], []
        for _ in range(5):
            stream = crease.MeshStream()
            for m in messages[: len(messages) - len(frames)]:
                stream.push(m)
            t = time.perf_counter()
            for m in frames:
                stream.push(m)
            full.append((time.perf_counter() - t) / len(frames))
            t = time.perf_counter()
            for m in frames:
                header, payload = codec.parse_frame(m.frame.data)
                meshopt.decode_vertex_buffer(bytes(payload), header.vertex_count, codec.VERTEX_SIZE)
            floor.append((time.perf_counter() - t) / len(frames))
        top = stream.topologies[0]
        f, fl = statistics.median(full), statistics.median(floor)
        print(f"{path}: {top.level} {top.encoding}, {len(frames)} frames of {top.vertex_count} vertices: "
              f"{f * 1e3:.3f} ms/frame, meshopt alone {fl * 1e3:.3f} ms/frame ({f / fl:.1f}x)")


if __name__ == "__main__":
    main()
