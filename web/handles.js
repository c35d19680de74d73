// Control-point handles and dragging (issue 37): a sphere per control point of each actor's
// model (base level only: control points index the base mesh) kept on its vertex of the mesh
// shown, their screen positions (window.crease.handles), dragging one in the plane facing the
// camera, and publishing the posed control points into the room as JSON control frames
// (HZY11 §7, FKY08 §7: the keyframe interface); also a take's frames (takes.js). In a room of
// several actors (issue 38) every actor has its handles, in its group (scene.js places it):
// a drag publishes that actor's points alone (`actors: [{actor, positions}]`; the others hold
// their poses).

import * as THREE from "three";

/** How near a press must be to a handle to grab it (CSS pixels). */
const GRAB_PX = 20;
const HANDLE_COLOR = 0xffd23f;
const DRAG_COLOR = 0xff5a3c;

/** The handles over `view`; publishes through `connection`; `token()` reads the publish token. */
export function createHandles(state, { view, connection, overlay, token, readback }) {
  const c = state.crease;
  const h = state.handles;
  const { canvas, camera, controls } = view;
  const handleMaterial = new THREE.MeshBasicMaterial({ color: HANDLE_COLOR, depthTest: false });
  const dragMaterial = new THREE.MeshBasicMaterial({ color: DRAG_COLOR, depthTest: false });
  // Scratch objects, overwritten at every use (no state: nothing survives a call).
  const scratch = { ndc: new THREE.Vector3(), pointer: new THREE.Vector2(), raycaster: new THREE.Raycaster() };

  /** Makes the handles for every actor's control points (after every stream's headers). */
  function build() {
    for (const slot of state.actors) {
      if (slot.handleGroup) slot.handleGroup.clear();
      slot.handles = [];
      if (!slot.room || !slot.handleGroup || state.level !== "base") continue; // control points index the base mesh
      const [lo, hi] = slot.room.bounds || [[0, 0, 0], [1, 1, 1]];
      const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
      const geo = new THREE.SphereGeometry(size * 0.012, 12, 8);
      for (const cp of slot.room.control_points) {
        const m = new THREE.Mesh(geo, handleMaterial);
        m.renderOrder = 10;
        m.userData = cp;
        slot.handleGroup.add(m);
        slot.handles.push(m);
      }
    }
  }

  /** Model vertex `modelVertex` of the actor's mesh shown (its model's frame), into `out`. */
  function vertexPosition(slot, modelVertex, out) {
    if (state.stream === "palette") return slot.palette.synth.skinVertex(modelVertex, out);
    const i = slot.streamIndex ? slot.streamIndex[modelVertex] : modelVertex;
    const a = slot.geometry.getAttribute("position").array;
    return out.set(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
  }

  /** The actor named `actor` (the first when absent), or undefined. */
  const actorNamed = (actor) => (actor == null ? state.actors[0] : state.actors.find((a) => a.name === actor));

  /** The control vertices of actor `actor`'s mesh shown (model units, model order), in its
   * model's frame, or with `world` where the page draws them (the actor placed or laid out,
   * the stage moved in an XR session); null when there is no mesh. */
  function controlPositions(actor, world = false) {
    const slot = actorNamed(actor);
    if (!(slot && slot.room && slot.geometry && state.stream)) return null;
    if (world) view.stage.updateMatrixWorld();
    return slot.room.control_points.map((cp) => {
      const v = vertexPosition(slot, cp.vertex, new THREE.Vector3());
      return (world ? v.applyMatrix4(slot.handleGroup.matrixWorld) : v).toArray();
    });
  }

  /** At a redraw: puts the handles on their vertices and notes their screen positions. */
  function update() {
    if (!state.stream || state.xr.tracker || !state.actors.some((a) => a.handles.length && a.geometry)) return;
    const r = canvas.getBoundingClientRect();
    const drag = h.drag;
    view.stage.updateMatrixWorld();
    const out = [];
    for (const slot of state.actors) {
      if (!slot.geometry) continue;
      slot.handles.forEach((m, k) => {
        if (drag && drag.handle === m) m.position.copy(drag.points[drag.index]);
        else vertexPosition(slot, slot.room.control_points[k].vertex, m.position);
        const p = scratch.ndc.copy(m.position).applyMatrix4(slot.handleGroup.matrixWorld).project(camera);
        out.push({
          id: m.userData.id,
          name: m.userData.name,
          actor: slot.name,
          x: r.left + ((p.x + 1) / 2) * r.width,
          y: r.top + ((1 - p.y) / 2) * r.height,
        });
      });
    }
    c.handles = out;
  }

  /** Publishes actor `slot`'s control points (Vector3s or {x, y, z}, model order) as one
   * control frame: its part alone in a room of several actors. */
  function publish(slot, points) {
    if (!connection.ready()) return;
    if (!token()) {
      overlay.fail("enter the room's publish token to drag control points");
      return;
    }
    const positions = [];
    for (const p of points) positions.push(p.x, p.y, p.z);
    const frame = { seq: state.socket.seq++, capture_time_us: Date.now() * 1000 };
    if (state.room?.actors?.length) frame.actors = [{ actor: slot.name, positions }];
    else frame.positions = positions;
    connection.send(JSON.stringify(frame));
    c.published += 1;
  }

  /** Publishes control points (x, y, z each, model order) of actor `actor` (the first when
   * absent) as a drag would: for scripts and tests. */
  function publishFlat(flat, actor) {
    const slot = actorNamed(actor);
    if (!slot) return overlay.fail(`no actor ${JSON.stringify(actor)} in this room`);
    const points = [];
    for (let i = 0; i + 2 < flat.length; i += 3) points.push({ x: flat[i], y: flat[i + 1], z: flat[i + 2] });
    publish(slot, points);
  }

  /** Sends one JSON control frame as it is (a take's, takes.js); false when it cannot. */
  function sendFrame(frame) {
    if (!connection.ready() || !token()) return false;
    connection.send(JSON.stringify(frame));
    c.published += 1;
    return true;
  }

  canvas.addEventListener("pointerdown", (e) => {
    if (!state.stream || c.handles.length === 0) return;
    // The nearest handle within GRAB_PX, of any actor.
    let best = null;
    for (const s of c.handles) {
      const d = Math.hypot(s.x - e.clientX, s.y - e.clientY);
      if (d < GRAB_PX && (!best || d < best.d)) best = { ...s, d };
    }
    if (!best) return;
    const slot = actorNamed(best.actor);
    const handle = slot.handles.find((m) => m.userData.id === best.id);
    const points = slot.room.control_points.map((cp) => vertexPosition(slot, cp.vertex, new THREE.Vector3()));
    const normal = camera.getWorldDirection(new THREE.Vector3());
    h.drag = {
      slot,
      handle,
      plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, handle.getWorldPosition(new THREE.Vector3())),
      points,
      index: slot.room.control_points.findIndex((cp) => cp.id === best.id),
    };
    handle.material = dragMaterial;
    controls.enabled = false;
    canvas.setPointerCapture(e.pointerId);
    e.preventDefault();
  });

  canvas.addEventListener("pointermove", (e) => {
    const drag = h.drag;
    if (!drag) return;
    const rect = canvas.getBoundingClientRect();
    scratch.pointer.set(((e.clientX - rect.left) / rect.width) * 2 - 1, -((e.clientY - rect.top) / rect.height) * 2 + 1);
    scratch.raycaster.setFromCamera(scratch.pointer, camera);
    const hit = scratch.raycaster.ray.intersectPlane(drag.plane, new THREE.Vector3());
    if (!hit) return;
    // The plane is in the world; the actor's points are in its model's frame.
    drag.points[drag.index].copy(drag.slot.handleGroup.worldToLocal(hit));
    publish(drag.slot, drag.points);
  });

  function endDrag(e) {
    if (!h.drag) return;
    h.drag.handle.material = handleMaterial;
    h.drag = null;
    controls.enabled = true;
    if (e && canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId);
  }
  canvas.addEventListener("pointerup", endDrag);
  canvas.addEventListener("pointercancel", endDrag);

  /** Actor `actor`'s drawn mesh in palette mode (x, y, z per vertex, model order), or null. */
  const readbackOf = (actor) => readback(actorNamed(actor));

  return { build, update, controlPositions, publish: publishFlat, sendFrame, readback: readbackOf };
}
