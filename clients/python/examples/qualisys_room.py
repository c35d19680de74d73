"""The README's example: a real optical-mocap recording, retargeted to a hand's control points by
`crease retarget`, published into a room from Python, and the room's meshes read back as arrays.

    python clients/python/examples/qualisys_room.py --server http://127.0.0.1:50051 \\
        --token ADMIN --model-file glove13.crease --controls qualisys.csv --out meshes.npz

Uploads the model (unless the server has it), opens a room on it, subscribes, publishes the
frames at the recording's rate and saves what came back: ``seqs`` (N,) and ``vertices``
(N, V, 3) float32 in the model's vertex order, with the room's ``triangles``. The test suite runs
this file as it is (clients/python/tests/test_server.py) and compares its arrays with
`crease watch --record` + `crease decode-stream` of the same frames.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path

import numpy as np

import crease


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--server", default="http://127.0.0.1:50051", help="the server's gRPC address")
    p.add_argument("--token", required=True, help="the server's admin token")
    p.add_argument("--model-file", type=Path, required=True, help="the hand the map was made for (crease train --out)")
    p.add_argument("--model", default="glove13", help="the name to upload it as")
    p.add_argument("--controls", type=Path, required=True, help="control frames (crease retarget --out)")
    p.add_argument("--room", default="qualisys")
    p.add_argument("--frames", type=int, default=0, help="publish only the first N frames (0: all)")
    p.add_argument("--fps", type=float, default=100.0, help="publishing rate (the recording's: 100 Hz)")
    p.add_argument("--watchers", type=int, default=0, help="wait for N other subscribers before publishing")
    p.add_argument("--out", type=Path, required=True, help="where to save the meshes (.npz)")
    args = p.parse_args()

    client = crease.Client(args.server, token=args.token)
    if args.model not in [m.name for m in client.models()]:
        model = client.upload_model(args.model, args.model_file)
        print(f"uploaded {model.name}: {model.base_vertices} vertices, {len(model.control_names)} control points")

    controls = crease.read_controls_csv(args.controls)  # (F, C, 3), NaN where occluded
    if args.frames:
        controls = controls[: args.frames]
    room = client.open_room(args.room, args.model)

    # Read the room's meshes on a thread while this one publishes.
    meshes: dict[int, np.ndarray] = {}
    subscription = client.subscribe(room.room)
    topology = subscription.wait_topology()[0]

    def read() -> None:
        for seq, vertices in subscription:
            meshes[seq] = vertices
            if seq == len(controls) - 1:
                break

    reader = threading.Thread(target=read)
    reader.start()
    while client.room(room.room).subscribers < 1 + args.watchers:
        time.sleep(0.05)

    acks = client.publish(room.room, controls, fps=args.fps)
    reader.join(timeout=10)
    subscription.cancel()
    client.close_room(room.room)

    residual = np.array([a.control_residual for a in acks])
    seqs = np.array(sorted(meshes), dtype=np.int64)
    np.savez(args.out, seqs=seqs, vertices=np.stack([meshes[s] for s in seqs]), triangles=topology.triangles)
    print(
        f"published {len(acks)} frames into {room.room!r}; read back {len(seqs)} meshes of "
        f"{topology.vertex_count} vertices; control residual RMS {np.sqrt(np.mean(residual**2)):.5f} model units; "
        f"wrote {args.out}"
    )


if __name__ == "__main__":
    main()
