// The scene (issue 37): three.js's renderer, camera, orbit controls and lights; the stage (the
// room's frame: identity on the page, placed in front of the user in an XR session) with a
// group per actor (its mesh, its handles' group, its name); the shared material; showing an
// actor's mesh, laying several actors out (issue 38), and framing the camera on their rest
// boxes.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

/** The mesh's material parameters: both encodings shade alike (palette.js patches a copy). */
export const MATERIAL_PARAMS = Object.freeze({ color: 0xd9a58c, roughness: 0.62, metalness: 0 });

/**
 * Makes the renderer on `canvas` and the scene; resizes with the window. Returns the three.js
 * objects (made once, never replaced): {canvas, renderer, scene, camera, controls, material,
 * stage}.
 */
export function createScene(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
  renderer.xr.enabled = true; // draws as before until a session starts
  renderer.setPixelRatio(Math.min(devicePixelRatio, 2));
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x1d2025);
  const camera = new THREE.PerspectiveCamera(35, 1, 0.001, 100);
  const controls = new OrbitControls(camera, canvas);
  controls.enableDamping = true;
  scene.add(new THREE.HemisphereLight(0xdfe8ff, 0x3a3028, 0.9));
  const key = new THREE.DirectionalLight(0xffffff, 1.8);
  key.position.set(1, 2, 1.5);
  scene.add(key);
  const rim = new THREE.DirectionalLight(0xa8c0ff, 0.7);
  rim.position.set(-1.5, 0.5, -1);
  scene.add(rim);
  const material = new THREE.MeshStandardMaterial(MATERIAL_PARAMS);
  const stage = new THREE.Group();
  scene.add(stage);

  const resize = () => {
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  };
  addEventListener("resize", resize);
  resize();
  return { canvas, renderer, scene, camera, controls, material, stage };
}

/** The actor's group in the stage (made once per slot): its mesh, handles and label go in it. */
export function actorGroup(slot, view) {
  if (!slot.group) {
    slot.group = new THREE.Group();
    slot.handleGroup = new THREE.Group();
    slot.group.add(slot.handleGroup);
    view.stage.add(slot.group);
  }
  return slot.group;
}

/** Takes an actor's slot off the stage (a new stream with fewer actors). */
export function removeActor(slot) {
  if (slot.group) slot.group.removeFromParent();
  if (slot.geometry) slot.geometry.dispose();
}

/** Shows `geo` with `mat` as the actor's mesh (made at its first header); disposes the
 * geometry before. */
export function showMesh(slot, view, geo, mat) {
  if (slot.geometry && slot.geometry !== geo) slot.geometry.dispose();
  slot.geometry = geo;
  if (!slot.mesh) {
    slot.mesh = new THREE.Mesh(geo, mat);
    actorGroup(slot, view).add(slot.mesh);
  } else {
    slot.mesh.geometry = geo;
    slot.mesh.material = mat;
  }
  return slot.mesh;
}

/** Side order of the row actors are laid out in: left hands on the left (-x). */
const SIDE_ORDER = { left: 0, right: 2 };

/**
 * Places the actors (issue 38) and sets `state.bounds`, the box they occupy. One actor stays
 * where its model puts it. Several are laid out in a row along x, left sides first, in the
 * room's order otherwise, each rest box 15% of the widest apart: a performer's two hands on
 * models in their own frames (the demo's right hand and its mirror) would otherwise overlap.
 * Each actor's name floats over its box. A frame that places an actor (its performer's
 * capture, `placeActor`) overrides this.
 */
export function layoutActors(state, view) {
  const slots = state.actors.filter((a) => a.room && a.room.bounds);
  if (slots.length === 0) {
    state.bounds = state.room?.bounds ?? null;
    return;
  }
  const boxes = slots.map((a) => a.room.bounds.map((v) => new THREE.Vector3(...v)));
  for (const a of slots) {
    // Unplaced until a frame says where its performer's capture puts it (placeActor).
    actorGroup(a, view).quaternion.identity();
    a.group.scale.setScalar(1);
  }
  if (slots.length === 1) {
    actorGroup(slots[0], view).position.set(0, 0, 0);
    state.bounds = slots[0].room.bounds;
    return;
  }
  const order = slots.map((_, i) => i).sort((i, j) => (SIDE_ORDER[slots[i].side] ?? 1) - (SIDE_ORDER[slots[j].side] ?? 1) || i - j);
  const gap = 0.15 * Math.max(...boxes.map(([lo, hi]) => hi.x - lo.x));
  const lo = new THREE.Vector3(Infinity, Infinity, Infinity);
  const hi = new THREE.Vector3(-Infinity, -Infinity, -Infinity);
  let cursor = boxes[order[0]][0].x;
  for (const i of order) {
    const [blo, bhi] = boxes[i];
    const dx = cursor - blo.x;
    actorGroup(slots[i], view).position.set(dx, 0, 0);
    lo.min(blo.clone().setX(blo.x + dx));
    hi.max(bhi.clone().setX(bhi.x + dx));
    cursor = bhi.x + dx + gap;
    labelActor(slots[i], blo, bhi);
  }
  state.bounds = [lo.toArray(), hi.toArray()];
}

/**
 * Places an actor where its performer's capture put it (`slot.placement`, from its frames:
 * `x -> scale * rotation x + translation`, crease_server::performer), instead of the row
 * layout. The first placement of the stream recomputes `state.bounds` (the placed rest boxes)
 * and has the camera framed again.
 */
export function placeActor(state, slot) {
  const p = slot.placement;
  if (!p || !slot.group || !(p.scale > 0)) return;
  slot.group.position.fromArray(p.translation);
  slot.group.quaternion.fromArray(p.rotation);
  slot.group.scale.setScalar(p.scale);
  if (slot.placed) return;
  slot.placed = true;
  if (state.crease.actors[slot.index]) state.crease.actors[slot.index].placed = true;
  const lo = new THREE.Vector3(Infinity, Infinity, Infinity);
  const hi = new THREE.Vector3(-Infinity, -Infinity, -Infinity);
  for (const a of state.actors) {
    if (!a.group || !a.room?.bounds) continue;
    a.group.updateMatrix();
    const [blo, bhi] = a.room.bounds;
    for (let k = 0; k < 8; k++) {
      const corner = new THREE.Vector3(k & 1 ? bhi[0] : blo[0], k & 2 ? bhi[1] : blo[1], k & 4 ? bhi[2] : blo[2]).applyMatrix4(a.group.matrix);
      lo.min(corner);
      hi.max(corner);
    }
  }
  state.bounds = [lo.toArray(), hi.toArray()];
  state.mesh.framed = false;
}

/** The actor's name over its rest box (a sprite: it faces the camera). */
function labelActor(slot, lo, hi) {
  if (slot.label) slot.label.removeFromParent();
  const canvas = document.createElement("canvas");
  [canvas.width, canvas.height] = [256, 64];
  const g = canvas.getContext("2d");
  g.font = "bold 40px system-ui, sans-serif";
  g.fillStyle = "#e8e8e8";
  g.textAlign = "center";
  g.textBaseline = "middle";
  g.fillText(slot.name, 128, 32);
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(canvas), depthTest: false, transparent: true }));
  const width = 0.5 * (hi.x - lo.x);
  sprite.scale.set(width, width / 4, 1);
  sprite.position.set((lo.x + hi.x) / 2, hi.y + 0.08 * (hi.y - lo.y), (lo.z + hi.z) / 2);
  sprite.renderOrder = 15;
  slot.label = sprite;
  slot.group.add(sprite);
}

/**
 * Frames the camera on the actors' rest boxes as laid out (every pose stays near them) rather
 * than the first frame's pose, so the framing does not depend on when the page joined; the
 * first actor's first frame's bounding sphere as a fallback. The same at both levels and in
 * both encodings, so the same frame looks the same.
 */
export function frameCamera(state, view) {
  let center;
  let radius;
  if (state.bounds) {
    const [lo, hi] = state.bounds.map((v) => new THREE.Vector3(...v));
    center = lo.clone().add(hi).multiplyScalar(0.5);
    radius = hi.distanceTo(lo) / 2;
  } else {
    const s = state.actors[0]?.geometry?.boundingSphere;
    if (!s || !Number.isFinite(s.radius) || s.radius === 0) return;
    center = s.center;
    radius = s.radius;
  }
  const { camera, controls } = view;
  controls.target.copy(center);
  camera.position.copy(center).add(new THREE.Vector3(0.2, 0.15, 1).normalize().multiplyScalar(radius * 3.6));
  camera.near = radius / 100;
  camera.far = radius * 100;
  camera.updateProjectionMatrix();
  state.mesh.framed = true;
}
