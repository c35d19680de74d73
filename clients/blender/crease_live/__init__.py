"""crease live link for Blender: watch a crease room on a mesh object, record it into shape keys,
import a take as a skinned armature animation.

Needs the ``crease`` Python package (clients/python) importable by Blender's own Python: install
it for Blender's Python version into Blender's user modules folder (clients/blender/README.md).

Network work never runs on Blender's UI thread: a watcher's thread reads the room's stream
(``crease.Client.subscribe``) and keeps only the latest decoded frame; a ``bpy.app.timers``
function (``tick``) copies that frame into the mesh's vertices 60 times a second at most, and
returns at once when nothing new came.
"""

from __future__ import annotations

import math
import tempfile
import threading
from pathlib import Path

import bpy
from bpy.props import EnumProperty, PointerProperty, StringProperty

bl_info = {
    "name": "crease live link",
    "author": "crease",
    "version": (0, 3, 0),
    "blender": (3, 4, 0),
    "location": "3D Viewport > Sidebar > crease",
    "description": "Watch a crease room live on a mesh, record it into shape keys, import takes",
    "category": "Animation",
}

#: How often the timer looks for a new frame, seconds.
TICK = 1.0 / 60.0


def crease_module():
    """The crease package, or an error saying how to install it for this Blender."""
    try:
        import crease
    except ImportError as e:
        import sys

        v = f"{sys.version_info.major}.{sys.version_info.minor}"
        raise RuntimeError(
            f"the crease Python package is not importable by Blender's Python {v} ({e}); install it with "
            f"`python{v} -m pip install --target {bpy.utils.user_resource('SCRIPTS', path='modules')} ./clients/python`"
        ) from None
    return crease


class Watcher:
    """One room watched on one object: a thread reads frames, ``tick`` applies the latest."""

    def __init__(self, server: str, token: str, room: str, level: str, encoding: str, object_name: str) -> None:
        crease = crease_module()
        self.client = crease.Client(server, token=token or None)
        self.room, self.level, self.encoding = room, level, encoding
        self.object_name = object_name
        self.lock = threading.Lock()
        self.topology = None
        self.latest: tuple[int, object] | None = None
        self.error: str | None = None
        self.received = 0
        self.applied = 0
        self.applied_seq: int | None = None
        self.recording: list[tuple[int, object]] | None = None
        self.subscription = self.client.subscribe(room, level, encoding)
        self.thread = threading.Thread(target=self._run, name=f"crease watch {room}", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            topology = self.subscription.wait_topology()[0]
            with self.lock:
                self.topology = topology
            for seq, vertices in self.subscription:
                if isinstance(vertices, dict):  # a room of several actors: its first actor
                    vertices = next(iter(vertices.values()))
                with self.lock:
                    self.latest = (seq, vertices)
                    self.received += 1
        except Exception as e:  # noqa: BLE001 - shown in the panel, the thread ends
            with self.lock:
                self.error = str(e)

    def stop(self) -> None:
        self.subscription.cancel()
        self.thread.join(timeout=2)
        self.client.close()

    def tick(self) -> None:
        """Applies the latest frame to the object (creating it on the first), on Blender's thread."""
        with self.lock:
            topology, latest = self.topology, self.latest
            self.latest = None
        if topology is None:
            return
        obj = bpy.data.objects.get(self.object_name)
        if obj is None:
            obj = make_object(self.object_name, topology)
        if latest is None:
            return
        seq, vertices = latest
        mesh = obj.data
        if len(mesh.vertices) != len(vertices):
            with self.lock:
                self.error = f"object {obj.name!r} has {len(mesh.vertices)} vertices, the stream {len(vertices)}"
            return
        mesh.vertices.foreach_set("co", vertices.reshape(-1))
        mesh.update()
        self.applied += 1
        self.applied_seq = seq
        if self.recording is not None:
            self.recording.append((seq, vertices))


def make_object(name: str, topology) -> bpy.types.Object:
    """A mesh object of the stream's topology (vertices at the origin until the first frame),
    turned from the model's Y-up to Blender's Z-up as the glTF importer does."""
    import numpy as np

    tris = np.asarray(topology.triangles, dtype=np.int32)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(topology.vertex_count)
    mesh.loops.add(3 * len(tris))
    mesh.polygons.add(len(tris))
    mesh.loops.foreach_set("vertex_index", tris.reshape(-1))
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * len(tris), 3, dtype=np.int32))
    try:
        mesh.polygons.foreach_set("loop_total", np.full(len(tris), 3, dtype=np.int32))
    except (AttributeError, TypeError, RuntimeError):
        pass  # Blender 4: loop_total follows from loop_start
    mesh.update()
    mesh.validate()
    obj = bpy.data.objects.new(name, mesh)
    obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(obj)
    return obj


_watchers: dict[str, Watcher] = {}


def tick() -> float | None:
    """The timer: every watcher's latest frame onto its object; unregistered when none is left."""
    for w in list(_watchers.values()):
        w.tick()
    # The panel's frame count: redraw the 3D viewports' sidebars too (the viewport itself
    # redraws on the mesh's update).
    for window in bpy.context.window_manager.windows if bpy.context.window_manager else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
    return TICK if _watchers else None


def record_to_shape_keys(obj: bpy.types.Object, frames: list, start: int) -> bpy.types.Object | None:
    """Recorded frames as a new object beside ``obj`` (its mesh copied; the live object keeps no
    shape keys, which would hide the frames written into its vertices), with a shape key per
    frame keyed to 1 on its scene frame (``start`` + its index) and 0 on the frames beside it."""
    if not frames:
        return None
    rec = obj.copy()
    rec.data = obj.data.copy()
    rec.name = rec.data.name = f"{obj.name} recording"
    for collection in obj.users_collection:
        collection.objects.link(rec)
    rec.shape_key_add(name="Basis", from_mix=False)
    for i, (seq, vertices) in enumerate(frames):
        key = rec.shape_key_add(name=f"crease {seq}", from_mix=False)
        key.data.foreach_set("co", vertices.reshape(-1))
        f = start + i
        for frame, value in ((f - 1, 0.0), (f, 1.0), (f + 1, 0.0)):
            key.value = value
            key.keyframe_insert("value", frame=frame)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = start, start + len(frames) - 1
    return rec


class CreaseSettings(bpy.types.PropertyGroup):
    server: StringProperty(name="Server", description="The server's gRPC address", default="http://127.0.0.1:50051")
    http: StringProperty(name="HTTP", description="The server's HTTP address (room list, takes as glTF)", default="http://127.0.0.1:8080")
    token: StringProperty(name="Token", description="The server's admin token (takes)", subtype="PASSWORD")
    room: StringProperty(name="Room", default="demo")
    level: EnumProperty(name="Level", items=[("base", "Base", "The skinned mesh"), ("detail", "Detail", "The subdivided mesh with wrinkles")])
    encoding: EnumProperty(
        name="Encoding",
        items=[("vertices", "Vertices", "Every vertex, quantised"), ("palette", "Palette", "Bones, skinned here on the CPU")],
    )
    take: StringProperty(name="Take", description="A take's id (crease take list)")
    status: StringProperty(name="Status", default="")


def settings(context) -> CreaseSettings:
    return context.scene.crease


def object_name(s: CreaseSettings) -> str:
    return f"crease {s.room}"


def client_of(s: CreaseSettings):
    """The crease client for the panel's server, HTTP address and token."""
    return crease_module().Client(s.server, token=s.token or None, http=s.http)


def cancelled(op: bpy.types.Operator, e: Exception) -> set:
    """Says what went wrong in Blender's status bar, and cancels the operator."""
    op.report({"ERROR"}, str(e))
    return {"CANCELLED"}


class CREASE_OT_pick_room(bpy.types.Operator):
    """Pick one of the server's rooms"""

    bl_idname = "crease.pick_room"
    bl_label = "Pick room"
    bl_property = "room"

    def rooms(self, context):
        return [(r, r, "") for r in CREASE_OT_pick_room.cache]

    cache: list[str] = []
    room: EnumProperty(items=rooms)

    def invoke(self, context, event):
        s = settings(context)
        try:
            CREASE_OT_pick_room.cache = client_of(s).rooms()
        except Exception as e:  # noqa: BLE001
            return cancelled(self, e)
        context.window_manager.invoke_search_popup(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        settings(context).room = self.room
        return {"FINISHED"}


class CREASE_OT_watch(bpy.types.Operator):
    """Watch the room live on a mesh object (its vertices follow every frame)"""

    bl_idname = "crease.watch"
    bl_label = "Watch"

    def execute(self, context):
        s = settings(context)
        name = object_name(s)
        if name in _watchers:
            self.report({"INFO"}, f"already watching {s.room}")
            return {"CANCELLED"}
        try:
            _watchers[name] = Watcher(s.server, s.token, s.room, s.level, s.encoding, name)
        except Exception as e:  # noqa: BLE001
            return cancelled(self, e)
        if not bpy.app.timers.is_registered(tick):
            bpy.app.timers.register(tick, first_interval=TICK, persistent=True)
        s.status = f"watching {s.room} ({s.level}, {s.encoding})"
        return {"FINISHED"}


class CREASE_OT_stop(bpy.types.Operator):
    """Stop watching the room"""

    bl_idname = "crease.stop"
    bl_label = "Stop"

    def execute(self, context):
        s = settings(context)
        w = _watchers.pop(object_name(s), None)
        if w is None:
            return {"CANCELLED"}
        w.stop()
        s.status = f"stopped: {w.applied} frames shown"
        return {"FINISHED"}


class CREASE_OT_record(bpy.types.Operator):
    """Start recording what the object shows; press again to stop and keep it as shape keys"""

    bl_idname = "crease.record"
    bl_label = "Record"

    def execute(self, context):
        s = settings(context)
        w = _watchers.get(object_name(s))
        if w is None:
            self.report({"ERROR"}, "watch a room first")
            return {"CANCELLED"}
        if w.recording is None:
            w.recording = []
            s.status = f"recording {s.room}"
            return {"FINISHED"}
        frames, w.recording = w.recording, None
        obj = bpy.data.objects[object_name(s)]
        rec = record_to_shape_keys(obj, frames, context.scene.frame_current)
        s.status = f"recorded {len(frames)} frames as shape keys of {rec.name!r}" if rec else "recorded nothing"
        return {"FINISHED"}


class CREASE_OT_import_take(bpy.types.Operator):
    """Import a take as a skinned armature animation (the server's glTF export of it)"""

    bl_idname = "crease.import_take"
    bl_label = "Import take"

    def execute(self, context):
        s = settings(context)
        take = s.take.strip()
        try:
            client = client_of(s)
            if not take:
                takes = client.takes(s.room)
                if not takes:
                    raise RuntimeError(f"room {s.room!r} has no takes")
                take = takes[0].take
            glb = client.take_glb(take)
        except Exception as e:  # noqa: BLE001
            return cancelled(self, e)
        path = Path(tempfile.mkdtemp(prefix="crease-take-")) / f"{take}.glb"
        path.write_bytes(glb)
        result = bpy.ops.import_scene.gltf(filepath=str(path))
        if "FINISHED" not in result:
            self.report({"ERROR"}, f"Blender's glTF importer refused {path}")
            return {"CANCELLED"}
        s.status = f"imported take {take}"
        return {"FINISHED"}


class VIEW3D_PT_crease(bpy.types.Panel):
    bl_label = "crease live link"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "crease"

    def draw(self, context):
        s = settings(context)
        layout = self.layout
        col = layout.column(align=True)
        col.prop(s, "server")
        col.prop(s, "http")
        col.prop(s, "token")
        row = layout.row(align=True)
        row.prop(s, "room")
        row.operator("crease.pick_room", text="", icon="VIEWZOOM")
        layout.row().prop(s, "level", expand=True)
        layout.row().prop(s, "encoding", expand=True)
        w = _watchers.get(object_name(s))
        row = layout.row(align=True)
        if w is None:
            row.operator("crease.watch", icon="PLAY")
        else:
            row.operator("crease.stop", icon="PAUSE")
            row.operator("crease.record", text="Stop recording" if w.recording is not None else "Record", icon="REC")
            layout.label(text=f"{w.applied} frames shown, seq {w.applied_seq}")
            if w.error:
                layout.label(text=w.error, icon="ERROR")
        layout.separator()
        row = layout.row(align=True)
        row.prop(s, "take")
        row.operator("crease.import_take", text="", icon="IMPORT")
        if s.status:
            layout.label(text=s.status)


classes = (CreaseSettings, CREASE_OT_pick_room, CREASE_OT_watch, CREASE_OT_stop, CREASE_OT_record, CREASE_OT_import_take, VIEW3D_PT_crease)


def register() -> None:
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.crease = PointerProperty(type=CreaseSettings)


def unregister() -> None:
    for w in list(_watchers.values()):
        w.stop()
    _watchers.clear()
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
    del bpy.types.Scene.crease
    for c in reversed(classes):
        bpy.utils.unregister_class(c)


# Kept for the tests and scripts: what a timer would run, and the watchers by object name.
__all__ = ["Watcher", "make_object", "record_to_shape_keys", "tick", "_watchers"]
