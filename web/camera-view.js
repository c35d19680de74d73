// The viewer's webcam source (issue 46): in a room whose markers are MediaPipe hand landmarks
// (the demo's `camera`), the "track my hands (camera)" button (#camera-row) opens the camera
// (getUserMedia), runs MediaPipe Hands on its frames in the page (web/node_modules, nothing
// fetched from elsewhere), and publishes each frame's hands as raw markers (camera.js) into
// the room, whose maps turn them into the model's control points. The camera image never
// leaves the page: only the landmarks go to the server, and the page says so. In a room of
// actors with sides each seen hand goes to the actor of its side (an actor whose hand is not
// seen holds its pose, flagged); in a one-actor room the right hand, or the left mirrored
// onto the right-hand model when only it is seen.
//
// A hand lost from the picture holds its last pose: an actor missing from a frame is held
// and flagged by the room; a one-actor room is sent the markers invalid (the room holds every
// point, its acks count them held). A preview in the corner shows the picture MediaPipe saw
// with each hand's landmarks.
//
// A test (or a page without a camera) can feed any video or canvas instead of the camera:
// `crease.camera.start(element)`; `crease.camera.hands` then holds the last frame's hands.

import { MIN_SCORE, fillLandmarks, handSides, landmarkPlan, placeHand } from "./camera.js";
import { markerMessage } from "./xr.js";

const SOLUTION = "node_modules/@mediapipe/hands/";

/** Loads MediaPipe's classic script once (it defines `window.Hands`). */
let loading = null;
function loadHands() {
  if (window.Hands) return Promise.resolve(window.Hands);
  loading ??= new Promise((resolve, reject) => {
    const script = document.createElement("script");
    script.src = `${SOLUTION}hands.js`;
    script.crossOrigin = "anonymous";
    script.onload = () => (window.Hands ? resolve(window.Hands) : reject(new Error("hands.js defined no Hands")));
    script.onerror = () => reject(new Error(`cannot load ${SOLUTION}hands.js (run npm ci in web/)`));
    document.head.append(script);
  });
  return loading;
}

/** The overlay's camera line: hands seen, inference time, detection rate, conversion time. */
export function cameraText(c) {
  const k = c.camera;
  const seen = k.hands.length ? k.hands.map((h) => `${h.side} ${h.score.toFixed(2)}`).join(", ") : `no hand${k.lost ? `: the room holds its last pose (${c.heldControls} control points held)` : ""}`;
  return `camera: ${seen} · inference ${k.inferenceMs.toFixed(0)} ms · found in ${(100 * k.detectionRate).toFixed(0)}% of frames · landmarks to frame ${k.convertMs.toFixed(2)} ms\n(only the hands' landmarks leave this page, never the image)`;
}

/** Each side's colour in the preview. */
const PREVIEW_COLOUR = { right: "#ffb347", left: "#5fd3ff" };

/** `elements` = {row, button, preview} (#camera-row, #camera, #camera-preview); `token()`
 * reads the publish token. */
export function createCamera(state, { connection, overlay, elements, token }) {
  const c = state.crease;
  const { row, button, preview } = elements;
  const k = c.camera;
  let session = null; // {hands (MediaPipe), video, stream, targets, stop}

  /** Where each side's hand goes: {right, left} of {actor, plan, mirror, markers}, or {error};
   * a one-actor room's also what its lost hand sends (`lost`: the markers, all invalid). */
  function targets() {
    const actors = state.room?.actors ?? [];
    if (actors.length === 0) {
      const { plan, error } = landmarkPlan(state.room?.capture?.markers);
      if (error) return { error };
      const markers = new Float32Array(3 * plan.length);
      return {
        right: { actor: null, plan, mirror: false, markers },
        left: { actor: null, plan, mirror: true, markers },
        lost: { actor: null, markers, lost: true },
        single: true,
      };
    }
    const out = {};
    for (const a of actors) {
      if (!a.side) continue;
      const { plan, error } = landmarkPlan(a.capture?.markers);
      if (error) return { error: `actor ${a.name}: ${error}` };
      out[a.side] = { actor: a.name, plan, mirror: false, markers: new Float32Array(3 * plan.length) };
    }
    return out.right || out.left ? out : { error: "no actor of this room has a side (left or right) for a hand" };
  }

  /** Shows the button in rooms whose markers are MediaPipe landmarks. */
  function updateControl() {
    const t = targets();
    row.hidden = !state.room?.capture || Boolean(t.error);
    button.disabled = !navigator.mediaDevices?.getUserMedia && !session;
    button.title = button.disabled ? "this browser cannot open a camera (it needs a secure page: https or localhost)" : "";
  }

  /** The preview: the picture MediaPipe saw, each hand's landmarks on it in its side's
   * colour (mirrored, as a selfie, for a camera). */
  function drawPreview(results, width) {
    const ctx = preview.getContext("2d");
    ctx.drawImage(results.image, 0, 0, preview.width, preview.height);
    const s = preview.width / width;
    for (const h of k.hands) {
      ctx.fillStyle = PREVIEW_COLOUR[h.side];
      for (const [x, y] of h.image) ctx.fillRect(x * s - 1.5, y * s - 1.5, 3, 3);
    }
  }

  /** One MediaPipe result: the hands published, the stats updated. */
  function onResults(results, width, height, started) {
    const t0 = performance.now();
    k.inferenceMs = t0 - started;
    k.frames += 1;
    const sides = handSides(results.multiHandedness).filter((h) => h.score >= MIN_SCORE);
    k.hands = sides.map((h) => ({
      side: h.side,
      score: h.score,
      image: results.multiHandLandmarks[h.index].map((p) => [p.x * width, p.y * height]),
    }));
    if (sides.length) k.detected += 1;
    k.detectionRate = k.detected / k.frames;
    const parts = [];
    const { targets: to } = session;
    // A one-actor room takes one hand: the right one, else the left mirrored.
    const first = (side) => sides.find((h) => h.side === side);
    const picked = to.single ? [first("right") ?? first("left")].filter(Boolean) : sides;
    // A one-actor room whose hand is lost is sent its markers invalid (below): the room holds
    // the last pose and its acks count the points held, as for occluded markers. (In a room
    // of actors, an actor missing from the frame holds, flagged in its frames.)
    k.lost = Boolean(to.single) && picked.length === 0 && k.published > 0;
    for (const h of picked) {
      const target = to[h.side];
      if (!target || parts.some((p) => p === target)) continue;
      const world = results.multiHandWorldLandmarks[h.index];
      const image = results.multiHandLandmarks[h.index];
      fillLandmarks(target.plan, world, placeHand(image, world, width, height), target.markers);
      if (target.mirror) for (let i = 0; i < target.markers.length; i += 3) target.markers[i] = -target.markers[i];
      parts.push(target);
    }
    if (k.lost) parts.push(to.lost);
    k.convertMs = performance.now() - t0;
    drawPreview(results, width);
    if (!parts.length || !connection.ready() || connection.backedUp()) return;
    const captureUs = Math.round((performance.timeOrigin + started) * 1000);
    k.seq = state.socket.seq;
    connection.send(markerMessage(state.socket.seq++, captureUs, parts));
    c.published += 1;
    k.published += 1;
  }

  /**
   * Starts tracking from `source`: a video or canvas element, or (when absent) the camera.
   * Resolves once MediaPipe is ready; rejects with the reason (no camera, denied, no token).
   */
  async function start(source) {
    if (session) return;
    if (!token()) throw new Error("enter the room's publish token to track your hands");
    const to = targets();
    if (to.error) throw new Error(to.error);
    let video = source;
    let stream = null;
    if (!video) {
      stream = await navigator.mediaDevices.getUserMedia({ video: { width: 640, height: 480 }, audio: false });
      video = document.createElement("video");
      video.muted = true;
      video.playsInline = true;
      video.srcObject = stream;
      await video.play();
    }
    const Hands = await loadHands();
    const hands = new Hands({ locateFile: (file) => `${SOLUTION}${file}` });
    hands.setOptions({ maxNumHands: 2, modelComplexity: 1, selfieMode: false, minDetectionConfidence: 0.5, minTrackingConfidence: 0.5 });
    let started = 0;
    const size = () => [video.videoWidth || video.width, video.videoHeight || video.height];
    hands.onResults((results) => {
      const [w, h] = size();
      if (session) onResults(results, w, h, started);
    });
    await hands.initialize();
    let running = true;
    session = { hands, video, stream, targets: to, stop: () => (running = false) };
    Object.assign(k, { active: true, frames: 0, detected: 0, published: 0, hands: [], lost: false });
    button.textContent = "stop the camera";
    preview.classList.toggle("mirror", Boolean(stream));
    preview.hidden = false;
    // One frame at a time: the next is read when MediaPipe has answered the last.
    (async () => {
      while (running) {
        started = performance.now();
        try {
          await hands.send({ image: video });
        } catch (err) {
          overlay.fail(`camera: ${err.message || err}`);
          break;
        }
        await new Promise((r) => (video.requestVideoFrameCallback ? video.requestVideoFrameCallback(() => r()) : requestAnimationFrame(() => r())));
      }
    })();
  }

  /** Stops tracking and closes the camera. */
  async function stop() {
    if (!session) return;
    const s = session;
    session = null;
    s.stop();
    for (const t of s.stream?.getTracks() ?? []) t.stop();
    await s.hands.close();
    k.active = false;
    preview.hidden = true;
    button.textContent = "track my hands (camera)";
    updateControl();
  }

  button.addEventListener("click", async () => {
    if (session) return stop();
    try {
      await start();
    } catch (err) {
      overlay.fail(`camera: ${err.message || err}`);
    }
  });

  /** The markers last published for `actor`'s hand (x, y, z each), for tests; null before. */
  const markers = (actor) => {
    const to = session?.targets;
    const t = to && Object.values(to).find((x) => x && x.actor === (actor ?? null));
    return t ? Array.from(t.markers) : null;
  };

  return { updateControl, start, stop, markers };
}
