"""The Blender add-on (clients/blender/crease_live) headless, against a running demo server:

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon.py

run by tests/blender/run.sh, which starts the server and installs the crease package for
Blender's Python. Environment: CREASE_BLENDER_SITE (the package's --target folder),
CREASE_GRPC and CREASE_HTTP (host:port), CREASE_ADMIN_TOKEN, CREASE_OUT (where the render goes).

Checks: the add-on enables; Watch on room `demo` makes a mesh of the room's topology whose
vertices, after each of the add-on's timer ticks, equal the frame the Python client decoded for
the same seq on a subscription of its own (both levels of checks on the vertex and the palette
stream); Record keeps the frames it saw as shape keys equal to those frames; the live hand is
rendered with Workbench; a take of the room imports as an armature with an animation of the
take's frames, skinning a mesh.
"""

import os
import sys
import threading
import time
import traceback
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, os.environ["CREASE_BLENDER_SITE"])
sys.path.insert(0, str(REPO / "clients" / "blender"))

import addon_utils  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402

import crease  # noqa: E402

GRPC = f"http://{os.environ['CREASE_GRPC']}"
HTTP = f"http://{os.environ['CREASE_HTTP']}"
TOKEN = os.environ["CREASE_ADMIN_TOKEN"]
OUT = Path(os.environ.get("CREASE_OUT", "."))


def check(condition: bool, message: str) -> None:
    if not condition:
        raise AssertionError(message)


class Reference:
    """The Python client's own subscription to the room: every decoded frame by seq."""

    def __init__(self, room: str, level: str, encoding: str) -> None:
        self.frames: dict[int, np.ndarray] = {}
        self.client = crease.Client(GRPC)
        self.sub = self.client.subscribe(room, level, encoding)
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        for seq, vertices in self.sub:
            self.frames[seq] = vertices

    def stop(self) -> None:
        self.sub.cancel()
        self.thread.join(timeout=5)
        self.client.close()


def coords(obj) -> np.ndarray:
    mesh = obj.data
    out = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


def run_ticks(addon, seconds: float, on_tick=None) -> None:
    """What Blender's event loop would do: the add-on's registered timer every 1/60 s. A
    background Blender has no event loop while a script runs, so the test calls it."""
    check(bpy.app.timers.is_registered(addon.tick), "the add-on's timer is not registered")
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        addon.tick()
        if on_tick:
            on_tick()
        time.sleep(addon.TICK)


def watch_and_compare(addon, s, level: str, encoding: str, seconds: float) -> dict:
    s.level, s.encoding = level, encoding
    ref = Reference(s.room, level, encoding)
    time.sleep(0.3)  # the reference subscribes first, so it has every frame the add-on shows
    check(bpy.ops.crease.watch() == {"FINISHED"}, "crease.watch did not finish")
    name = addon.object_name(s)
    watcher = addon._watchers[name]
    samples: list[tuple[int, np.ndarray]] = []

    def sample() -> None:
        obj = bpy.data.objects.get(name)
        if obj is not None and watcher.applied_seq is not None and (not samples or samples[-1][0] != watcher.applied_seq):
            samples.append((watcher.applied_seq, coords(obj)))

    run_ticks(addon, seconds, sample)
    time.sleep(0.2)
    ref.stop()
    check(watcher.error is None, f"watcher error: {watcher.error}")
    obj = bpy.data.objects[name]
    check(len(obj.data.polygons) > 1000, f"{len(obj.data.polygons)} faces")
    compared = [(seq, c) for seq, c in samples if seq in ref.frames]
    check(len(samples) >= 20, f"only {len(samples)} frames shown in {seconds} s ({level}, {encoding})")
    check(len(compared) >= 0.9 * len(samples), f"{len(compared)} of {len(samples)} shown frames in the reference")
    worst = max(float(np.max(np.abs(c - ref.frames[seq]))) for seq, c in compared)
    check(worst == 0.0, f"{level} {encoding}: the object's vertices differ from the client's decode by {worst}")
    moved = max(float(np.max(np.abs(c - compared[0][1]))) for _, c in compared)
    check(moved > 1e-6, "the object never moved")
    print(f"blender: {level} {encoding}: {len(samples)} frames shown in {seconds} s, {len(compared)} compared with the Python client's decode: equal", flush=True)
    return {"name": name, "ref": ref, "watcher": watcher}


def render(obj, path: Path) -> None:
    """The live hand through a camera framing it, Workbench, to a PNG."""
    scene = bpy.context.scene
    bpy.context.view_layer.update()
    m = np.array(obj.matrix_world)
    corners = coords(obj) @ m[:3, :3].T + m[:3, 3]
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    center, size = (lo + hi) / 2, float(np.max(hi - lo))
    cam_data = bpy.data.cameras.new("crease camera")
    cam = bpy.data.objects.new("crease camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (center[0] + 0.9 * size, center[1] - 1.6 * size, center[2] + 0.7 * size)
    direction = np.array(center) - np.array(cam.location)
    import mathutils

    cam.rotation_euler = mathutils.Vector(direction.tolist()).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "SINGLE"
    scene.display.shading.single_color = (0.85, 0.62, 0.5)
    scene.display.shading.show_cavity = True
    scene.render.resolution_x, scene.render.resolution_y = 800, 600
    scene.render.film_transparent = False
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    check(path.is_file() and path.stat().st_size > 10_000, f"no render at {path}")
    print(f"blender: rendered {path}", flush=True)


def main() -> None:
    module = addon_utils.enable("crease_live", default_set=True, handle_error=None)
    check(module is not None, "addon_utils.enable('crease_live') failed")
    check("crease_live" in bpy.context.preferences.addons, "the add-on is not enabled")
    import crease_live as addon

    s = bpy.context.scene.crease
    s.server, s.http, s.token, s.room = GRPC, HTTP, TOKEN, "demo"
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)

    # The vertex stream, then the palette stream skinned on the CPU.
    w = watch_and_compare(addon, s, "base", "palette", 2.0)
    check(bpy.ops.crease.stop() == {"FINISHED"}, "crease.stop")
    bpy.data.objects.remove(bpy.data.objects[w["name"]])
    w = watch_and_compare(addon, s, "base", "vertices", 3.0)
    name, watcher = w["name"], w["watcher"]

    # Record one second into shape keys; each key equals the frame the Python client decoded.
    ref = Reference(s.room, "base", "vertices")
    time.sleep(0.3)
    check(bpy.ops.crease.record() == {"FINISHED"}, "crease.record (start)")
    run_ticks(addon, 1.5)
    check(bpy.ops.crease.record() == {"FINISHED"}, "crease.record (stop)")
    time.sleep(0.2)
    ref.stop()
    obj = bpy.data.objects[name]
    check(obj.data.shape_keys is None, "the live object got shape keys (they would hide its frames)")
    rec = bpy.data.objects[f"{name} recording"]
    keys = rec.data.shape_keys.key_blocks
    recorded = [k for k in keys if k.name.startswith("crease ")]
    check(len(recorded) >= 30, f"{len(recorded)} shape keys recorded in 1.5 s")
    compared = 0
    for k in recorded[:: max(1, len(recorded) // 10)]:
        seq = int(k.name.split()[1])
        if seq not in ref.frames:
            continue
        co = np.empty(len(k.data) * 3, dtype=np.float32)
        k.data.foreach_get("co", co)
        check(np.array_equal(co.reshape(-1, 3), ref.frames[seq]), f"shape key {k.name} differs from frame {seq}")
        compared += 1
    check(compared >= 5, f"only {compared} shape keys compared")
    check(rec.data.shape_keys.animation_data.action is not None, "the shape keys are not animated")
    print(f"blender: recorded {len(recorded)} frames as shape keys; {compared} compared with the client's decode: equal", flush=True)

    # The live hand, rendered (the README's picture).
    bpy.data.objects.remove(rec)
    run_ticks(addon, 0.5)
    render(obj, OUT / "blender-live-hand.png")
    # The scene, for tests/blender/screenshot.py (the panel beside the live hand, in Blender's UI).
    bpy.ops.wm.save_as_mainfile(filepath=str(OUT / "live.blend"))
    check(bpy.ops.crease.stop() == {"FINISHED"}, "crease.stop")
    check(watcher.applied > 0, "nothing applied")

    # A take of the room, imported as a skinned armature animation.
    admin = crease.Client(GRPC, token=TOKEN)
    admin.start_take("demo", "blender test")
    time.sleep(1.5)
    take = admin.stop_take("demo")
    s.take = take.take
    before = set(bpy.data.objects)
    check(bpy.ops.crease.import_take() == {"FINISHED"}, "crease.import_take")
    new = [o for o in bpy.data.objects if o not in before]
    arm = [o for o in new if o.type == "ARMATURE"]
    meshes = [o for o in new if o.type == "MESH"]
    check(len(arm) == 1, f"imported objects: {[(o.name, o.type) for o in new]}")
    action = arm[0].animation_data.action if arm[0].animation_data else None
    check(action is not None, "the armature has no action")
    start, end = action.frame_range
    check(len(arm[0].data.bones) > 10, f"{len(arm[0].data.bones)} bones")
    check(any(m.find_armature() == arm[0] for m in meshes), "no mesh skinned by the armature")
    print(
        f"blender: imported take {take.take} ({take.frames} frames): armature of {len(arm[0].data.bones)} bones, "
        f"action over frames {start:.0f}..{end:.0f}, {len(meshes)} skinned mesh",
        flush=True,
    )
    addon_utils.disable("crease_live", default_set=True)
    print("blender: all checks passed", flush=True)


try:
    main()
except Exception:
    traceback.print_exc()
    sys.stdout.flush()
    os._exit(1)
