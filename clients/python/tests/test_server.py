"""The crease package against a real server: the demo server tests/python/run.sh starts (with an
admin token, a models folder and a takes folder), the `crease` CLI beside it as the reference.

Environment (set by tests/python/run.sh; without CREASE_GRPC every test here is skipped):
  CREASE_GRPC, CREASE_HTTP   the server's addresses (host:port)
  CREASE_ADMIN_TOKEN         its admin token
  CREASE_CLI                 the `crease` binary
  CREASE_WORK                a scratch folder
  CREASE_GLOVE_MODEL         a glove13 hand (crease handgen + crease train), not on the server
  CREASE_QUALISYS_CSV        the Qualisys recording retargeted onto it (crease retarget)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import unittest
from pathlib import Path

import numpy as np

import crease

GRPC = os.environ.get("CREASE_GRPC")
HERE = Path(__file__).resolve().parent
EXAMPLE = HERE.parent / "examples" / "qualisys_room.py"


def env(name: str) -> str:
    value = os.environ.get(name)
    if not value:
        raise unittest.SkipTest(f"{name} is not set (tests/python/run.sh sets it)")
    return value


def cli(*args: str, timeout: float = 120) -> str:
    r = subprocess.run([env("CREASE_CLI"), *args], capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        raise AssertionError(f"crease {' '.join(args)} exited {r.returncode}:\n{r.stdout}\n{r.stderr}")
    return r.stdout


def decode_stream_every_frame(capture: Path, out: Path) -> tuple[list[int], np.ndarray]:
    """`crease decode-stream --every-frame`: the Rust core's decode of every frame of a capture."""
    summary = json.loads(cli("decode-stream", "--every-frame", "--out", str(out), str(capture)).strip().splitlines()[-1])
    seqs = summary["seqs"]
    vertices = np.fromfile(out, dtype="<f4").reshape(len(seqs), summary["vertex_count"], 3)
    return seqs, vertices


@unittest.skipUnless(GRPC, "CREASE_GRPC is not set: no server to test against (tests/python/run.sh starts one)")
class AgainstTheDemoServer(unittest.TestCase):
    client: crease.Client

    @classmethod
    def setUpClass(cls) -> None:
        cls.client = crease.Client(f"http://{GRPC}", token=env("CREASE_ADMIN_TOKEN"), http=f"http://{env('CREASE_HTTP')}")
        crease.wait_ready(cls.client)
        cls.work = Path(env("CREASE_WORK"))
        cls.work.mkdir(parents=True, exist_ok=True)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.client.close()

    def test_models_come_as_arrays_and_errors_carry_the_servers_code(self) -> None:
        names = [m.name for m in self.client.models()]
        self.assertIn("demo-hand", names)
        m = self.client.model("demo-hand")
        self.assertEqual(m.control_rest.shape, (len(m.control_names), 3))
        self.assertEqual(m.control_rest.dtype, np.float32)
        self.assertGreater(m.base_vertices, 1000)
        # Every control point's rest position lies in the rest mesh's box.
        self.assertTrue(np.all(m.control_rest >= m.bounds[0] - 1e-6) and np.all(m.control_rest <= m.bounds[1] + 1e-6))
        with self.assertRaises(crease.CreaseError) as e:
            self.client.model("no-such-model")
        self.assertEqual(e.exception.code, "NOT_FOUND")
        self.assertIn("no-such-model", e.exception.message)
        with self.assertRaises(crease.CreaseError) as e:
            crease.Client(f"http://{GRPC}").open_room("py-no-token", "demo-hand")
        self.assertIn(e.exception.code, ("UNAUTHENTICATED", "PERMISSION_DENIED"))

    def test_upload_list_and_delete_a_model(self) -> None:
        glove = Path(env("CREASE_GLOVE_MODEL"))
        name = "py-upload"
        with self.assertRaises(crease.CreaseError) as e:
            self.client.upload_model(name, glove.read_bytes()[:1000] + b"garbage")
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT", e.exception)
        self.assertNotIn(name, [m.name for m in self.client.models()])
        info = self.client.upload_model(name, glove)
        self.assertEqual(len(info.control_names), 13)
        self.assertIn(name, [m.name for m in self.client.models()])
        room = self.client.open_room("py-upload-room", name)
        with self.assertRaises(crease.CreaseError) as e:
            self.client.delete_model(name)
        self.assertEqual(e.exception.code, "FAILED_PRECONDITION", e.exception)
        self.client.close_room(room.room)
        self.client.delete_model(name)
        self.assertNotIn(name, [m.name for m in self.client.models()])
        self.assertEqual(self.client.cluster_models(), [])  # one server: no object store

    def test_the_readme_example_reads_back_what_crease_watch_records(self) -> None:
        """The README's example (examples/qualisys_room.py, run as it is) publishes the retargeted
        Qualisys frames; a `crease watch --record` of the same room is decoded by
        `crease decode-stream`: every frame both saw must be equal within the quantisation."""
        frames = 240
        out = self.work / "example.npz"
        capture = self.work / "qualisys.capture"
        room = "py-qualisys"
        example = subprocess.Popen(
            [sys.executable, str(EXAMPLE), "--server", f"http://{GRPC}", "--token", env("CREASE_ADMIN_TOKEN"),
             "--model-file", env("CREASE_GLOVE_MODEL"), "--model", "py-glove13", "--controls", env("CREASE_QUALISYS_CSV"),
             "--room", room, "--frames", str(frames), "--fps", "100", "--watchers", "1", "--out", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 60
            while True:
                try:
                    self.client.room(room)
                    break
                except crease.CreaseError:
                    if time.monotonic() > deadline or example.poll() is not None:
                        self.fail(f"the example never opened its room: {example.communicate()[0]}")
                    time.sleep(0.05)
            watch = subprocess.run(
                [env("CREASE_CLI"), "watch", "--server", f"http://{GRPC}", "--room", room, "--record", str(capture)],
                capture_output=True, text=True, timeout=120,
            )  # fmt: skip
            output, _ = example.communicate(timeout=120)
        finally:
            example.kill()
        self.assertEqual(example.returncode, 0, output)
        print(f"\n  example: {output.strip()}\n  crease watch: {watch.stdout.strip().splitlines()[-1:]}", file=sys.stderr)
        ours = np.load(out)
        seqs, reference = decode_stream_every_frame(capture, self.work / "qualisys.f32")
        common = sorted(set(seqs) & set(ours["seqs"].tolist()))
        self.assertGreaterEqual(len(common), frames * 0.9, f"python saw {len(ours['seqs'])}, crease watch {len(seqs)}")
        at = {s: i for i, s in enumerate(seqs)}
        mine = {s: i for i, s in enumerate(ours["seqs"].tolist())}
        a = ours["vertices"][[mine[s] for s in common]]
        b = reference[[at[s] for s in common]]
        # Both decode the same 16-bit frames; allow half a quantisation step of the pose box.
        half_step = float(np.max(np.ptp(b.reshape(-1, 3), axis=0))) / 65535 / 2 * 4  # box is padded: generous
        diff = float(np.max(np.abs(a - b)))
        print(f"  {len(common)} frames compared, max |python - decode-stream| = {diff:.3g} (bound {half_step:.3g})", file=sys.stderr)
        self.assertLessEqual(diff, half_step)
        # And the meshes moved: the recording is a hand grasping, not a still.
        self.assertGreater(float(np.max(np.abs(a[-1] - a[0]))), 1e-3)

    def check_capture(self, level: str, encoding: str, tolerance: float) -> None:
        capture = self.work / f"demo-{level}-{encoding}.capture"
        # 50 frames at the demo's 60 Hz span more than one held pose (demo/src/animation.rs,
        # HOLD_S = 0.7 s): the demo pauses while nobody watches and resumes where it left off, so
        # where in its loop a capture starts depends on what watched before, and 20 frames could
        # fall inside one hold (the "all the same" check below failed so).
        args = ["watch", "--server", f"http://{GRPC}", "--room", "demo", "--frames", "50", "--encoding", encoding, "--record", str(capture)]
        if level == "detail":
            args.append("--detail")
        cli(*args)
        seqs, reference = decode_stream_every_frame(capture, self.work / f"demo-{level}-{encoding}.f32")
        decoded = list(crease.decode_messages(crease.read_capture(capture)))
        self.assertEqual([s for s, _ in decoded], seqs)
        ours = np.stack([v for _, v in decoded])
        self.assertEqual(ours.shape, reference.shape)
        diff = float(np.max(np.abs(ours - reference)))
        print(f"\n  {level} {encoding}: {len(seqs)} frames of {ours.shape[1]} vertices, max |python - decode-stream| = {diff:.3g}", file=sys.stderr)
        self.assertLessEqual(diff, tolerance)
        # Not one frame repeated: the demo room's hand moves (it holds each pose a while).
        self.assertGreater(float(np.max(np.abs(ours - ours[0]))), 1e-6, "the frames are all the same")

    def test_vertex_captures_decode_as_crease_decode_stream(self) -> None:
        self.check_capture("base", "vertices", 0.0)  # the same dequantisation, bit for bit
        self.check_capture("detail", "vertices", 0.0)

    def test_palette_captures_are_skinned_on_the_cpu_as_crease_decode_stream(self) -> None:
        # f32 sums in another order than the Rust synthesis: a few ulps of the hand's ~0.2 units.
        self.check_capture("base", "palette", 1e-5)
        self.check_capture("detail", "palette", 1e-5)

    def test_subscribe_yields_arrays_at_both_levels_and_encodings(self) -> None:
        m = self.client.model("demo-hand")
        for level, count in (("base", m.base_vertices), ("detail", m.detail_vertices)):
            for encoding in ("vertices", "palette"):
                with self.subTest(level=level, encoding=encoding), self.client.subscribe("demo", level, encoding) as sub:
                    got = []
                    for seq, vertices in sub:
                        got.append(seq)
                        self.assertEqual(vertices.shape, (count, 3))
                        self.assertEqual(vertices.dtype, np.float32)
                        self.assertTrue(np.all(np.isfinite(vertices)))
                        if len(got) == 3:
                            break
                    self.assertEqual(got, sorted(got))
                    self.assertEqual(sub.topology.vertex_count, count)
                    self.assertLess(int(sub.topology.triangles.max()), count)

    def test_synthesize_matches_crease_synth_and_carries_held_points_across_requests(self) -> None:
        m = self.client.model("demo-hand")
        rng = np.random.default_rng(7)
        controls = m.control_rest[None] + rng.normal(0, 0.004, (40, len(m.control_names), 3)).astype(np.float32)
        controls[5:9, 2] = np.nan  # an occluded point, held
        controls[20, 0] = np.nan  # occluded on a later request's first frame
        whole = self.client.synthesize("demo-hand", controls)
        self.assertEqual(whole.shape, (40, m.base_vertices, 3))
        chunked = self.client.synthesize("demo-hand", controls, chunk_frames=4)
        np.testing.assert_array_equal(chunked, whole)
        # The same frames through `crease synth --server` (CSV in, OBJ out).
        csv = self.work / "synth.csv"
        np.savetxt(csv, controls.reshape(len(controls), -1), delimiter=",", fmt="%.9g")
        cli("synth", "--server", f"http://{GRPC}", "--model", "demo-hand", "--controls", str(csv), "--out", str(self.work / "synth"))
        for i in (0, 7, 20, 39):
            obj = [line.split()[1:] for line in (self.work / "synth" / f"frame_{i:05d}.obj").read_text().splitlines() if line.startswith("v ")]
            np.testing.assert_allclose(whole[i], np.array(obj, dtype=np.float32), atol=1e-6)
        # A frame of the wrong shape names its index in the batch.
        bad = np.zeros((3, len(m.control_names) - 1, 3), dtype=np.float32)
        with self.assertRaises(crease.CreaseError) as e:
            self.client.synthesize("demo-hand", bad)
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")

    def test_a_job_equals_synthesize_and_refuses_a_bad_frame_by_index(self) -> None:
        m = self.client.model("demo-hand")
        rng = np.random.default_rng(11)
        controls = m.control_rest[None] + rng.normal(0, 0.004, (30, len(m.control_names), 3)).astype(np.float32)
        controls[4:9, 1] = np.nan
        job = self.client.submit_job("demo-hand", controls, name="python")
        self.assertEqual((job.frames_total, job.name), (30, "python"))
        states = [s.state for s in self.client.watch_job(job.job)]
        self.assertEqual(states[-1], "done", states)
        np.testing.assert_array_equal(self.client.job_result(job.job), self.client.synthesize("demo-hand", controls))
        self.assertIn(job.job, [j.job for j in self.client.jobs()])
        with self.assertRaises(crease.CreaseError) as e:
            self.client.cancel_job(job.job)
        self.assertEqual(e.exception.code, "FAILED_PRECONDITION")
        # The same frames kept as bones (palette): skinned here on the CPU, the same meshes within
        # the palette's quantisation (rotations to ~2e-5 rad, translations to 16 bits).
        palette = self.client.submit_job("demo-hand", controls, encoding="palette")
        self.assertEqual(palette.encoding, "palette")
        self.assertEqual([s.state for s in self.client.watch_job(palette.job)][-1], "done")
        vertices = self.client.job_result(job.job)
        np.testing.assert_allclose(self.client.job_result(palette.job), vertices, atol=5e-4)
        # Raw markers through a map that does not name them: refused at submit, naming the map.
        with self.assertRaises(crease.CreaseError) as e:
            self.client.submit_job(
                "demo-hand",
                markers=np.zeros((2, 2, 3), dtype=np.float32),
                marker_names=["a", "b"],
                marker_map=(HERE.parents[2] / "bench" / "mocap" / "webxr-back.toml").read_text(),
            )
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertIn("JobSpec.retarget", str(e.exception))
        with self.assertRaises(ValueError):
            self.client.submit_job("demo-hand", controls, take="x")
        # A point short in every frame: refused at its first frame, nothing queued.
        before = len(self.client.jobs())
        with self.assertRaises(crease.CreaseError) as e:
            self.client.submit_job("demo-hand", controls[:, :-1])
        self.assertEqual(e.exception.code, "INVALID_ARGUMENT")
        self.assertEqual(e.exception.frame, 0)
        self.assertEqual(len(self.client.jobs()), before)

    def test_publish_acks_every_frame_and_refuses_a_bad_one_by_index(self) -> None:
        m = self.client.model("demo-hand")
        room = self.client.open_room("py-publish", "demo-hand")
        try:
            take = self.client.start_take(room.room, "python")
            frames = np.repeat(m.control_rest[None], 10, axis=0)
            frames[:, 0, 1] += np.linspace(0, 0.01, 10, dtype=np.float32)
            acks = self.client.publish(room.room, frames)
            self.assertEqual([a.seq for a in acks], list(range(10)))
            self.assertTrue(all(a.error is None for a in acks))
            self.assertLess(max(a.control_residual for a in acks), 0.01)
            # A generator of frames, one with a point missing: refused, by index, the room goes on.
            def live():
                yield m.control_rest
                yield m.control_rest[:-1]
                yield m.control_rest
            with self.assertRaises(crease.FrameRejected) as e:
                self.client.publish(room.room, live(), first_seq=10)
            self.assertEqual((e.exception.frame, e.exception.seq, e.exception.code), (1, 11, "INVALID_ARGUMENT"))
            done = self.client.stop_take(room.room)
            self.assertEqual(done.take, take.take)
            recorded = self.client.take_frames(take.take)
            self.assertEqual(recorded.seq.tolist(), list(range(10)) + [10, 12])
            np.testing.assert_array_equal(recorded.controls[:10], frames)
            self.assertEqual(recorded.transforms.shape, (12, m.bones, 7))
            self.assertIn(take.take, [t.take for t in self.client.takes(room.room)])
            glb = self.client.take_glb(take.take)
            self.assertEqual(glb[:4], b"glTF")
            # The take as a job: its own model, settings and recorded control points (the
            # refused frame was never recorded), the same meshes as a job of those points.
            from_take = self.client.submit_job(take=take.take)
            self.assertEqual(from_take.frames_total, 12)
            self.assertEqual([s.state for s in self.client.watch_job(from_take.job)][-1], "done")
            same = self.client.submit_job("demo-hand", recorded.controls)
            self.assertEqual([s.state for s in self.client.watch_job(same.job)][-1], "done")
            np.testing.assert_array_equal(self.client.job_result(from_take.job), self.client.job_result(same.job))
        finally:
            self.client.close_room(room.room)


if __name__ == "__main__":
    unittest.main()
