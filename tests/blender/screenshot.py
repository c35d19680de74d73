"""The README's picture of the add-on: Blender's window (under Xvfb, software OpenGL) with the
crease panel in the 3D viewport's sidebar and the demo room's hand live in the viewport.

    xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup --enable-event-simulate \\
        OUT/live.blend --python tests/blender/screenshot.py

run by tests/blender/run.sh after test_addon.py (which saves OUT/live.blend: opening a file skips
the splash screen). Environment as test_addon.py's; writes OUT/blender-panel.png and quits.
Blender 3.4 has no API to pick a sidebar tab: this script unregisters the built-in sidebar panels
that Python defines (this session only) and switches from the one left (Item) to crease with a
simulated ctrl + wheel; the crease panel is drawn by the add-on's own code, live.
"""

import os
import sys
import traceback
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, os.environ["CREASE_BLENDER_SITE"])
sys.path.insert(0, str(REPO / "clients" / "blender"))

import addon_utils  # noqa: E402
import bpy  # noqa: E402

OUT = Path(os.environ.get("CREASE_OUT", "."))
state = {"step": 0}


def fail() -> None:
    traceback.print_exc()
    sys.stdout.flush()
    os._exit(1)


def setup() -> None:
    try:
        addon_utils.enable("crease_live", default_set=True)
        for cls in list(bpy.types.Panel.__subclasses__()):
            if getattr(cls, "bl_space_type", "") == "VIEW_3D" and getattr(cls, "bl_region_type", "") == "UI" and getattr(cls, "bl_category", "") != "crease":
                try:
                    bpy.utils.unregister_class(cls)
                except RuntimeError:
                    pass
        s = bpy.context.scene.crease
        s.server, s.http, s.room = f"http://{os.environ['CREASE_GRPC']}", f"http://{os.environ['CREASE_HTTP']}", "demo"
        s.token = os.environ["CREASE_ADMIN_TOKEN"]
        for obj in [o for o in bpy.data.objects if o.type == "CAMERA"]:
            bpy.data.objects.remove(obj)
        bpy.ops.crease.watch()
        obj = bpy.data.objects["crease demo"]
        for o in bpy.context.view_layer.objects:
            o.select_set(o == obj)
        bpy.context.view_layer.objects.active = obj
        for area in bpy.context.screen.areas:
            if area.type == "VIEW_3D":
                space = area.spaces.active
                space.show_region_ui = True
                space.overlay.show_floor = False
                space.overlay.show_axis_x = space.overlay.show_axis_y = False
    except Exception:
        fail()


def frame_hand() -> None:
    """The viewport framed on the live hand, with room for the fingers' travel."""
    for area in bpy.context.screen.areas:
        if area.type == "VIEW_3D":
            region = next(r for r in area.regions if r.type == "WINDOW")
            with bpy.context.temp_override(area=area, region=region):
                bpy.ops.view3d.view_selected()
            area.spaces.active.region_3d.view_distance *= 1.5


def show_crease_tab() -> None:
    """Ctrl + wheel over the sidebar switches its tab (Blender 3.4 has no API for it): simulated
    events (blender --enable-event-simulate), one notch from Item to crease."""
    win = bpy.context.window
    for area in bpy.context.screen.areas:
        if area.type == "VIEW_3D":
            ui = next(r for r in area.regions if r.type == "UI")
            x, y = ui.x + ui.width // 2, ui.y + ui.height // 2
            win.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
            win.event_simulate(type="WHEELDOWNMOUSE", value="PRESS", x=x, y=y, ctrl=True)


def step() -> float | None:
    try:
        state["step"] += 1
        if state["step"] == 1:
            setup()
            return 1.0
        if state["step"] == 2:
            frame_hand()
            show_crease_tab()
            return 2.0  # frames flow for a while
        bpy.ops.screen.screenshot(filepath=str(OUT / "blender-panel.png"))
        print(f"blender: screenshot {OUT / 'blender-panel.png'}", flush=True)
        bpy.ops.wm.quit_blender()
    except Exception:
        fail()
    return None


bpy.app.timers.register(step, first_interval=1.0)
