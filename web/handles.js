// Control-point handles and dragging (issue 37): a sphere per control point of the room's
// model (base level only: control points index the base mesh) kept on its vertex of the mesh
// shown, their screen positions (window.crease.handles), dragging one in the plane facing the
// camera, and publishing the posed control points into the room as JSON control frames
// (HZY11 §7, FKY08 §7: the keyframe interface); also a take's frames (takes.js).

import * as THREE from "three";

/** How near a press must be to a handle to grab it (CSS pixels). */
const GRAB_PX = 20;
const HANDLE_COLOR = 0xffd23f;
const DRAG_COLOR = 0xff5a3c;

/** The handles over `view`; publishes through `connection`; `token()` reads the publish token. */
export function createHandles(state, { view, connection, overlay, token }) {
  const c = state.crease;
  const h = state.handles;
  const { canvas, camera, controls, handleGroup } = view;
  const handleMaterial = new THREE.MeshBasicMaterial({ color: HANDLE_COLOR, depthTest: false });
  const dragMaterial = new THREE.MeshBasicMaterial({ color: DRAG_COLOR, depthTest: false });
  // Scratch objects, overwritten at every use (no state: nothing survives a call).
  const scratch = { ndc: new THREE.Vector3(), pointer: new THREE.Vector2(), raycaster: new THREE.Raycaster() };

  /** Makes the handles for the room's control points (after every stream header). */
  function build() {
    handleGroup.clear();
    h.meshes = [];
    if (!state.room || state.level !== "base") return; // control points index the base mesh
    const [lo, hi] = state.room.bounds || [[0, 0, 0], [1, 1, 1]];
    const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    const geo = new THREE.SphereGeometry(size * 0.012, 12, 8);
    for (const cp of state.room.control_points) {
      const m = new THREE.Mesh(geo, handleMaterial);
      m.renderOrder = 10;
      m.userData = cp;
      handleGroup.add(m);
      h.meshes.push(m);
    }
  }

  /** Model vertex `modelVertex` of the mesh shown, into `out` (a Vector3). */
  function vertexPosition(modelVertex, out) {
    if (state.stream === "palette") return state.palette.synth.skinVertex(modelVertex, out);
    const i = state.mesh.streamIndex ? state.mesh.streamIndex[modelVertex] : modelVertex;
    const a = state.mesh.geometry.getAttribute("position").array;
    return out.set(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
  }

  /** The control vertices of the mesh shown (model units, model order), or null. */
  function controlPositions() {
    return state.room && state.mesh.geometry && state.stream
      ? state.room.control_points.map((cp) => vertexPosition(cp.vertex, new THREE.Vector3()).toArray())
      : null;
  }

  /** At a redraw: puts the handles on their vertices and notes their screen positions. */
  function update() {
    if (!state.mesh.geometry || !state.stream || !h.meshes.length || state.xr.tracker) return;
    const r = canvas.getBoundingClientRect();
    const drag = h.drag;
    c.handles = h.meshes.map((m, k) => {
      if (drag && drag.handle === m) m.position.copy(drag.points[drag.index]);
      else vertexPosition(state.room.control_points[k].vertex, m.position);
      const p = scratch.ndc.copy(m.position).project(camera);
      return {
        id: m.userData.id,
        name: m.userData.name,
        x: r.left + ((p.x + 1) / 2) * r.width,
        y: r.top + ((1 - p.y) / 2) * r.height,
      };
    });
  }

  /** Publishes control points (Vector3s or {x, y, z}, model order) as one control frame. */
  function publish(points) {
    if (!connection.ready()) return;
    if (!token()) {
      overlay.fail("enter the room's publish token to drag control points");
      return;
    }
    const positions = [];
    for (const p of points) positions.push(p.x, p.y, p.z);
    connection.send(JSON.stringify({ seq: state.socket.seq++, capture_time_us: Date.now() * 1000, positions }));
    c.published += 1;
  }

  /** Publishes control points (x, y, z each, model order) as a drag would: for scripts and tests. */
  function publishFlat(flat) {
    const points = [];
    for (let i = 0; i + 2 < flat.length; i += 3) points.push({ x: flat[i], y: flat[i + 1], z: flat[i + 2] });
    publish(points);
  }

  /** Sends one JSON control frame as it is (a take's, takes.js); false when it cannot. */
  function sendFrame(frame) {
    if (!connection.ready() || !token()) return false;
    connection.send(JSON.stringify(frame));
    c.published += 1;
    return true;
  }

  canvas.addEventListener("pointerdown", (e) => {
    if (!state.mesh.geometry || !state.stream || h.meshes.length === 0) return;
    // The nearest handle within GRAB_PX.
    let best = null;
    for (const s of c.handles) {
      const d = Math.hypot(s.x - e.clientX, s.y - e.clientY);
      if (d < GRAB_PX && (!best || d < best.d)) best = { ...s, d };
    }
    if (!best) return;
    const handle = h.meshes.find((m) => m.userData.id === best.id);
    const points = state.room.control_points.map((cp) => vertexPosition(cp.vertex, new THREE.Vector3()));
    const normal = camera.getWorldDirection(new THREE.Vector3());
    h.drag = {
      handle,
      plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, handle.position),
      points,
      index: state.room.control_points.findIndex((cp) => cp.id === best.id),
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
    drag.points[drag.index].copy(hit);
    publish(drag.points);
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

  return { build, update, vertexPosition, controlPositions, publish: publishFlat, sendFrame };
}
