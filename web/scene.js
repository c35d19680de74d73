// The scene (issue 37): three.js's renderer, camera, orbit controls and lights; the stage (the
// model's frame: identity on the page, placed in front of the user in an XR session) with the
// mesh and the handles' group; the shared material; showing a stream's mesh and framing the
// camera on the room's rest box.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

/** The mesh's material parameters: both encodings shade alike (palette.js patches a copy). */
export const MATERIAL_PARAMS = Object.freeze({ color: 0xd9a58c, roughness: 0.62, metalness: 0 });

/**
 * Makes the renderer on `canvas` and the scene; resizes with the window. Returns the three.js
 * objects (made once, never replaced): {canvas, renderer, scene, camera, controls, material,
 * stage, handleGroup}.
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
  const handleGroup = new THREE.Group();
  stage.add(handleGroup);

  const resize = () => {
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  };
  addEventListener("resize", resize);
  resize();
  return { canvas, renderer, scene, camera, controls, material, stage, handleGroup };
}

/** Shows `geo` with `mat` (creating the mesh on the first header); disposes the geometry before. */
export function showMesh(state, view, geo, mat) {
  const m = state.mesh;
  if (m.geometry && m.geometry !== geo) m.geometry.dispose();
  m.geometry = geo;
  if (!m.mesh) {
    m.mesh = new THREE.Mesh(geo, mat);
    view.stage.add(m.mesh);
  } else {
    m.mesh.geometry = geo;
    m.mesh.material = mat;
  }
  return m.mesh;
}

/**
 * Frames the camera on the model's rest box (every pose stays near it) rather than the first
 * frame's pose, so the framing does not depend on when the page joined; the first frame's
 * bounding sphere as a fallback. The same at both levels and in both encodings, so the same
 * frame looks the same.
 */
export function frameCamera(state, view) {
  let center;
  let radius;
  if (state.room && state.room.bounds) {
    const [lo, hi] = state.room.bounds.map((v) => new THREE.Vector3(...v));
    center = lo.clone().add(hi).multiplyScalar(0.5);
    radius = hi.distanceTo(lo) / 2;
  } else {
    const s = state.mesh.geometry && state.mesh.geometry.boundingSphere;
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
