// The crease viewer: subscribes to a room over WebSocket (/ws/rooms/{id}), decodes the mesh
// frames, renders them with three.js, and lets an animator drag the model's control points,
// publishing control frames into the room (HZY11 §7, FKY08 §7: the keyframe interface). State
// for tests and curious users: `window.crease`.
//
// Two stream encodings (`?encoding=vertices|palette|auto`, default auto): vertices (every vertex
// of every frame, quantised: decoded in a worker, normals on the CPU) and palette (issue 18: the
// bones and the detail kernel vector per frame; palette.js skins, subdivides, displaces and
// computes the normals on the GPU). auto takes palette where the renderer has float render
// targets (WebGL2 + EXT_color_buffer_float), else vertices; the overlay says which and why.
//
// A retargeting room whose markers are WebXR joints (room `hands` of the demo) offers "track my
// hands" where the browser has an immersive XR device: xr-view.js publishes the tracked hand's
// joints every XR frame, the hand floats in front of the user, and the overlay (on the page
// and in the headset) shows the control residual and the capture-to-mesh latency.
//
// A room of several actors (issue 38: both hands of a performer, several performers) draws
// every actor, named, laid out in a row, each with its handles; "track my hands" publishes
// both hands at once into a room whose actors have sides.
//
// This file is the entry (issue 37): it reads the address, makes the one state object
// (state.js), the modules (web/README.md has the map) and wires them, then runs the render
// loop. Nothing here or in the modules keeps state outside that object.

import { ready } from "./codec.js";
import { createConnection } from "./connection.js";
import { createHandles } from "./handles.js";
import { createOverlay } from "./overlay.js";
import { chooseEncoding, createPaletteStream } from "./palette-stream.js";
import { createPanel } from "./panel.js";
import { createScene, layoutActors } from "./scene.js";
import { createState } from "./state.js";
import { listTakes, startPlayer } from "./takes.js";
import { followJobs } from "./jobs.js";
import { createVertexStream } from "./vertex-stream.js";
import { createXr } from "./xr-view.js";
import { createCamera } from "./camera-view.js";

const state = createState(new URLSearchParams(location.search));
const crease = state.crease;
window.crease = crease;

const $ = (id) => document.getElementById(id);
const overlay = createOverlay(state, { banner: $("banner"), stats: $("stats") });
const panel = createPanel(state, {
  elements: { token: $("token"), detail: $("detail"), room: $("room") },
  onToken: () => connection.reconnect(), // the token goes out when a socket opens
});
const view = createScene($("view"));
chooseEncoding(state, view.renderer);

// The socket hands each message to the stream of its kind; a new stream rebuilds the handles.
const streams = {
  vertices: createVertexStream(state, { view, overlay }),
  palette: createPaletteStream(state, { view, overlay }),
};
// Once a stream's headers came (one per actor): the actors laid out, their handles made.
const onHeader = () => {
  layoutActors(state, view);
  handles.build();
};
const connection = createConnection(state, { token: panel.token, streams, onHeader, overlay });
const handles = createHandles(state, { view, connection, overlay, token: panel.token, readback: streams.palette.readback });
const xr = createXr(state, {
  view,
  connection,
  overlay,
  elements: { row: $("xr-row"), button: $("xr"), hand: $("hand") },
  token: panel.token,
});

const camera = createCamera(state, {
  connection,
  overlay,
  elements: { row: $("camera-row"), button: $("camera"), preview: $("camera-preview") },
  token: panel.token,
});
crease.camera.start = camera.start;
crease.camera.stop = camera.stop;
crease.cameraMarkers = camera.markers;

crease.reconnect = connection.reconnect;
crease.publish = handles.publish;
crease.controlPositions = handles.controlPositions;
crease.xrMarkers = xr.markers;
crease.readback = handles.readback;

/** One redraw: the window's frames, or the XR session's while one runs (`frame` then). */
function render(time, frame) {
  xr.onFrame(time, frame);
  view.controls.update();
  if (state.stream) streams[state.stream].update();
  handles.update();
  view.renderer.render(view.scene, view.camera);
  overlay.update(performance.now());
}

await ready;
try {
  await panel.loadRoom();
} catch (err) {
  overlay.fail(String(err.message || err));
}
connection.connect();
xr.updateControl();
camera.updateControl();
if (crease.take.id) {
  startPlayer({ takeId: crease.take.id, root: $("player"), state: crease, send: handles.sendFrame, onError: overlay.fail });
} else {
  listTakes({ roomId: state.roomId, list: $("take-list"), state: crease, onError: overlay.fail }).catch((err) =>
    overlay.fail(`takes: ${err.message || err}`),
  );
}
followJobs({ details: $("jobs"), list: $("job-list"), state: crease, onError: overlay.fail });
view.renderer.setAnimationLoop(render);
