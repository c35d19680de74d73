// The crease viewer: subscribes to a room over WebSocket (/ws/rooms/{id}), decodes the mesh
// frames (codec.js, meshoptimizer's decoder), renders them with three.js, and lets an animator
// drag the model's control points, publishing control frames into the room (HZY11 §7, FKY08 §7:
// the keyframe interface). State for tests and curious users: `window.crease`.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { decodeFrame, decodeIndices, ready } from "./codec.js";
import { readMeshFrame } from "./wire.js";

const params = new URLSearchParams(location.search);
const roomId = params.get("room") || "demo";
const level = params.get("level") === "detail" ? "detail" : "base";

const state = {
  connected: false,
  frames: 0,
  bytes: 0,
  vertexCount: 0,
  model: "",
  level,
  room: roomId,
  error: null,
  published: 0,
  acks: 0,
  handles: [],
};
window.crease = state;

// ---- UI ----------------------------------------------------------------------------------
const banner = document.getElementById("banner");
const stats = document.getElementById("stats");
const tokenInput = document.getElementById("token");
const detailBox = document.getElementById("detail");
const roomSelect = document.getElementById("room");
tokenInput.value = params.get("token") || sessionStorage.getItem(`crease-token-${roomId}`) || "";
tokenInput.addEventListener("change", () => {
  sessionStorage.setItem(`crease-token-${roomId}`, tokenInput.value);
  reconnect(); // the token travels in the WebSocket URL
});
detailBox.checked = level === "detail";
detailBox.addEventListener("change", () => {
  params.set("level", detailBox.checked ? "detail" : "base");
  location.search = params.toString();
});
roomSelect.addEventListener("change", () => {
  params.set("room", roomSelect.value);
  location.search = params.toString();
});

function showBanner(kind, text) {
  banner.className = kind || "";
  banner.textContent = text || "";
}

// ---- Scene -------------------------------------------------------------------------------
const canvas = document.getElementById("view");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
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
const material = new THREE.MeshStandardMaterial({ color: 0xd9a58c, roughness: 0.62, metalness: 0 });
let mesh = null;
let geometry = null;
const handleGroup = new THREE.Group();
scene.add(handleGroup);

function resize() {
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
addEventListener("resize", resize);
resize();

// ---- The room's model: control points --------------------------------------------------
let roomInfo = null; // /api/rooms/{id}
let streamIndex = null; // model vertex -> streamed vertex
let framed = false;

async function loadRoomInfo() {
  const list = await fetch("/api/rooms").then((r) => (r.ok ? r.json() : { rooms: [] }));
  // In a cluster (crease-server --nats) the list has every room of the cluster and its owner.
  const owners = new Map((list.cluster ?? []).map((r) => [r.room, r.owner]));
  const label = (id) => (owners.has(id) ? `${id} (on ${owners.get(id)})` : id);
  roomSelect.replaceChildren(
    ...[...new Set([roomId, ...list.rooms])].map((id) => new Option(label(id), id, false, id === roomId)),
  );
  const r = await fetch(`/api/rooms/${encodeURIComponent(roomId)}`);
  if (!r.ok) throw new Error(`room ${roomId}: ${(await r.text()).trim()}`);
  roomInfo = await r.json();
}

// ---- Stream ------------------------------------------------------------------------------
let ws = null;
let backoff = 500;
// The previous frame's lanes (deltas add to them), a spare lanes buffer to decode into (not the
// previous one: a delta adds to it), and the positions buffer; reused frame to frame.
let lanes = null;
let spare = null;
let positionsBuf = null;
let fpsWindow = { t: performance.now(), frames: 0, bytes: 0, latency: 0, fps: 0, bpf: 0, lat: 0 };

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const q = new URLSearchParams({ level });
  if (tokenInput.value) q.set("token", tokenInput.value);
  ws = new WebSocket(`${scheme}://${location.host}/ws/rooms/${encodeURIComponent(roomId)}?${q}`);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.connected = true;
    backoff = 500;
    if (!state.error) showBanner();
  };
  ws.onmessage = (e) => {
    if (typeof e.data === "string") return onAck(JSON.parse(e.data));
    const msg = readMeshFrame(new Uint8Array(e.data));
    if (msg.topology) onTopology(msg.topology);
    else if (msg.frame) onFrame(msg.frame);
  };
  ws.onclose = (e) => {
    state.connected = false;
    lanes = null;
    const wait = backoff;
    backoff = Math.min(backoff * 2, 10000);
    showBanner("warn", `disconnected${e.reason ? `: ${e.reason}` : ""} — reconnecting in ${(wait / 1000).toFixed(1)} s`);
    setTimeout(connect, wait);
  };
}

function reconnect() {
  if (ws) {
    ws.onclose = null;
    ws.close();
  }
  state.error = null;
  showBanner();
  connect();
}

function onTopology(t) {
  state.model = t.model;
  state.vertexCount = t.vertexCount;
  lanes = spare = positionsBuf = null;
  const index = decodeIndices(t.indices, t.triangleCount, t.vertexCount);
  if (geometry) geometry.dispose();
  geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * t.vertexCount), 3));
  geometry.setIndex(new THREE.BufferAttribute(index, 1));
  if (!mesh) {
    mesh = new THREE.Mesh(geometry, material);
    scene.add(mesh);
  } else mesh.geometry = geometry;
  // Control points index model vertices; the stream may be in its own order (base level).
  streamIndex = null;
  if (t.vertexOrder.length === t.vertexCount) {
    streamIndex = new Uint32Array(t.vertexCount);
    t.vertexOrder.forEach((model, i) => (streamIndex[model] = i));
  }
  buildHandles();
}

function onFrame(f) {
  let decoded;
  try {
    decoded = decodeFrame(f.data, lanes, { lanes: spare, positions: positionsBuf });
  } catch (err) {
    state.error = `frame ${f.seq}: ${err.message}`;
    showBanner("error", state.error);
    return;
  }
  spare = lanes;
  lanes = decoded.lanes;
  positionsBuf = decoded.positions;
  const attr = geometry.getAttribute("position");
  attr.array.set(decoded.positions);
  attr.needsUpdate = true;
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  if (!framed) frameCamera();
  state.frames += 1;
  state.bytes += f.data.length;
  fpsWindow.frames += 1;
  fpsWindow.bytes += f.data.length;
  fpsWindow.latency += f.serverLatencyUs;
}

function onAck(ack) {
  state.acks += 1;
  if (ack.error) {
    const bad = ack.error.code === 7;
    state.error = bad ? `publish refused: wrong or missing token` : `publish refused: ${ack.error.message}`;
    showBanner("error", state.error);
  }
}

function frameCamera() {
  // The model's rest box (every pose stays near it) rather than the first frame's pose, so the
  // framing does not depend on when the page joined; the first frame's sphere as a fallback.
  let center;
  let radius;
  if (roomInfo && roomInfo.bounds && level === "base") {
    const [lo, hi] = roomInfo.bounds.map((v) => new THREE.Vector3(...v));
    center = lo.clone().add(hi).multiplyScalar(0.5);
    radius = hi.distanceTo(lo) / 2;
  } else {
    const s = geometry.boundingSphere;
    if (!s || !Number.isFinite(s.radius) || s.radius === 0) return;
    center = s.center;
    radius = s.radius;
  }
  controls.target.copy(center);
  camera.position.copy(center).add(new THREE.Vector3(0.2, 0.15, 1).normalize().multiplyScalar(radius * 3.6));
  camera.near = radius / 100;
  camera.far = radius * 100;
  camera.updateProjectionMatrix();
  framed = true;
}

// ---- Control-point handles and dragging -----------------------------------------------
const handleMaterial = new THREE.MeshBasicMaterial({ color: 0xffd23f, depthTest: false });
const dragMaterial = new THREE.MeshBasicMaterial({ color: 0xff5a3c, depthTest: false });
let handleMeshes = [];

function buildHandles() {
  handleGroup.clear();
  handleMeshes = [];
  if (!roomInfo || level !== "base") return; // control points index the base mesh
  const [lo, hi] = roomInfo.bounds || [[0, 0, 0], [1, 1, 1]];
  const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  const geo = new THREE.SphereGeometry(size * 0.012, 12, 8);
  for (const c of roomInfo.control_points) {
    const m = new THREE.Mesh(geo, handleMaterial);
    m.renderOrder = 10;
    m.userData = c;
    handleGroup.add(m);
    handleMeshes.push(m);
  }
}

function vertexPosition(modelVertex, out) {
  const i = streamIndex ? streamIndex[modelVertex] : modelVertex;
  const a = geometry.getAttribute("position").array;
  return out.set(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
}

let drag = null; // {handle, plane, points: Vector3[] (the frame being posed)}
const raycaster = new THREE.Raycaster();
const pointer = new THREE.Vector2();

function toNdc(e) {
  const r = canvas.getBoundingClientRect();
  pointer.set(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
}

canvas.addEventListener("pointerdown", (e) => {
  if (!geometry || handleMeshes.length === 0) return;
  // The nearest handle within 20 px.
  let best = null;
  for (const h of state.handles) {
    const d = Math.hypot(h.x - e.clientX, h.y - e.clientY);
    if (d < 20 && (!best || d < best.d)) best = { ...h, d };
  }
  if (!best) return;
  const handle = handleMeshes.find((m) => m.userData.id === best.id);
  const points = roomInfo.control_points.map((c) => vertexPosition(c.vertex, new THREE.Vector3()));
  const normal = camera.getWorldDirection(new THREE.Vector3());
  drag = {
    handle,
    plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, handle.position),
    points,
    index: roomInfo.control_points.findIndex((c) => c.id === best.id),
  };
  handle.material = dragMaterial;
  controls.enabled = false;
  canvas.setPointerCapture(e.pointerId);
  e.preventDefault();
});

canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  toNdc(e);
  raycaster.setFromCamera(pointer, camera);
  const hit = raycaster.ray.intersectPlane(drag.plane, new THREE.Vector3());
  if (!hit) return;
  drag.points[drag.index].copy(hit);
  publish(drag.points);
});

function endDrag(e) {
  if (!drag) return;
  drag.handle.material = handleMaterial;
  drag = null;
  controls.enabled = true;
  if (e && canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId);
}
canvas.addEventListener("pointerup", endDrag);
canvas.addEventListener("pointercancel", endDrag);

let seq = 0;
function publish(points) {
  if (!ws || ws.readyState !== WebSocket.OPEN) return;
  if (!tokenInput.value) {
    state.error = "enter the room's publish token to drag control points";
    showBanner("error", state.error);
    return;
  }
  const positions = [];
  for (const p of points) positions.push(p.x, p.y, p.z);
  ws.send(JSON.stringify({ seq: seq++, capture_time_us: Date.now() * 1000, positions }));
  state.published += 1;
}

// ---- Render loop ---------------------------------------------------------------------------
const tmp = new THREE.Vector3();
function render() {
  requestAnimationFrame(render);
  controls.update();
  if (geometry && handleMeshes.length) {
    const r = canvas.getBoundingClientRect();
    state.handles = handleMeshes.map((m, k) => {
      if (drag && drag.handle === m) m.position.copy(drag.points[drag.index]);
      else vertexPosition(roomInfo.control_points[k].vertex, m.position);
      tmp.copy(m.position).project(camera);
      return {
        id: m.userData.id,
        name: m.userData.name,
        x: r.left + ((tmp.x + 1) / 2) * r.width,
        y: r.top + ((1 - tmp.y) / 2) * r.height,
      };
    });
  }
  renderer.render(scene, camera);
  const now = performance.now();
  if (now - fpsWindow.t >= 1000) {
    const s = (now - fpsWindow.t) / 1000;
    fpsWindow.fps = fpsWindow.frames / s;
    fpsWindow.bpf = fpsWindow.bytes / Math.max(fpsWindow.frames, 1);
    fpsWindow.lat = fpsWindow.latency / Math.max(fpsWindow.frames, 1);
    fpsWindow = { ...fpsWindow, t: now, frames: 0, bytes: 0, latency: 0 };
  }
  stats.textContent =
    `model ${state.model || "…"} · ${level}\n` +
    `${state.vertexCount.toLocaleString()} vertices\n` +
    `${fpsWindow.fps.toFixed(1)} frames/s · ${Math.round(fpsWindow.bpf).toLocaleString()} B/frame\n` +
    `server latency ${(fpsWindow.lat / 1000).toFixed(2)} ms\n` +
    `published ${state.published} · acks ${state.acks}`;
}

await ready;
try {
  await loadRoomInfo();
} catch (err) {
  state.error = String(err.message || err);
  showBanner("error", state.error);
}
connect();
render();
