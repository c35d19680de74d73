"""Benchmark: `Client.synthesize` of 2,000 demo-hand frames against `crease synth --server` of the
same frames, alternating on one server (figures in BENCHMARKS.md, "The Python package").

    target/crease-py/bin/python clients/python/bench/synthesize.py --server http://127.0.0.1:50051 \\
        --token ADMIN --crease target/release/crease [--rounds 5]

The frames: a 2.5 s take of the demo room (its animated poses), repeated to 2,000 frames. Prints
each round's wall times and the medians: Python's (arrays in memory), `crease synth --server
--out DIR` (the CLI's way of giving the same meshes: one OBJ per frame) and `crease synth
--server --gltf FILE` (one animated glTF). Needs a server started with --takes and
--admin-token (and the demo).
"""

import argparse
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import crease


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--server", required=True)
    p.add_argument("--token", required=True)
    p.add_argument("--crease", required=True, help="the crease CLI")
    p.add_argument("--frames", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=5)
    args = p.parse_args()
    client = crease.Client(args.server, token=args.token)
    client.start_take("demo", "synthesize benchmark")
    time.sleep(2.5)
    take = client.take_frames(client.stop_take("demo").take)
    controls = np.resize(take.controls, (args.frames,) + take.controls.shape[1:])
    tmp = Path(tempfile.mkdtemp(prefix="crease-synth-bench-"))
    csv = tmp / "controls.csv"
    np.savetxt(csv, controls.reshape(len(controls), -1), delimiter=",", fmt="%.9g")
    times: dict[str, list[float]] = {"python": [], "crease --out": [], "crease --gltf": []}
    for r in range(args.rounds):
        t = time.perf_counter()
        out = client.synthesize("demo-hand", controls)
        times["python"].append(time.perf_counter() - t)
        for name, extra in (("crease --out", ["--out", str(tmp / "objs")]), ("crease --gltf", ["--gltf", str(tmp / "out.glb")])):
            t = time.perf_counter()
            subprocess.run([args.crease, "synth", "--server", args.server, "--model", "demo-hand", "--controls", str(csv), *extra],
                           check=True, capture_output=True)  # fmt: skip
            times[name].append(time.perf_counter() - t)
        print(f"round {r + 1}: " + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in times.items()), flush=True)
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"{args.frames} frames of {out.shape[1]} vertices, medians of {args.rounds} rounds: " + ", ".join(f"{k} {v:.2f} s" for k, v in med.items()))
    print(f"python / crease --out = {med['python'] / med['crease --out']:.2f}, python / crease --gltf = {med['python'] / med['crease --gltf']:.2f}")


if __name__ == "__main__":
    main()
