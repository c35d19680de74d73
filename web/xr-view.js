// The viewer's WebXR hands (issue 19; issue 37's module): in a room whose markers are WebXR
// joints, the "track my hands" button (#xr-row), the session (xr.js HandTracker) publishing
// the chosen hand's joints every XR frame, the stage placed in front of the user at the
// first XR frame, and the overlay's panel (overlay.js) above the hand while tracking.

import * as THREE from "three";
import { HandTracker, markerMessage, markerPlan } from "./xr.js";

/** `elements` = {row, button, hand} (#xr-row, #xr, #hand); `token()` reads the publish token. */
export function createXr(state, { view, connection, overlay, elements, token }) {
  const c = state.crease;
  const x = state.xr;
  const { row, button, hand } = elements;

  /** Publishes one XR frame's markers; false when the socket is not ready or backed up. */
  function sendMarkers(captureUs, markers) {
    if (!connection.ready()) return false;
    // Latest wins: a frame queued behind 64 KB would only arrive late.
    if (connection.backedUp()) {
      c.xr.dropped += 1;
      return false;
    }
    if (x.tracker.firstCaptureUs === undefined) x.tracker.firstCaptureUs = captureUs;
    c.xr.seq = state.socket.seq;
    connection.send(markerMessage(state.socket.seq++, captureUs, markers));
    c.published += 1;
    c.xr.published += 1;
    return true;
  }

  /** Shows "track my hands" in rooms whose markers are WebXR joints; enabled where XR is. */
  async function updateControl() {
    row.hidden = !state.room?.capture;
    if (row.hidden) return;
    const plan = markerPlan(state.room.capture.markers);
    let supported = false;
    try {
      supported = Boolean(navigator.xr) && (await navigator.xr.isSessionSupported("immersive-vr"));
    } catch {
      supported = false;
    }
    c.xr.supported = supported;
    c.xr.reason = plan.error || (!navigator.xr ? "this browser has no WebXR" : supported ? "" : "no immersive XR device");
    button.disabled = Boolean(c.xr.reason) && !x.tracker;
    button.title = c.xr.reason;
  }
  navigator.xr?.addEventListener?.("devicechange", updateControl);

  button.addEventListener("click", async () => {
    if (x.tracker) return x.tracker.stop();
    if (!token()) return overlay.fail("enter the room's publish token to track your hands");
    const plan = markerPlan(state.room.capture.markers);
    const t = new HandTracker({ renderer: view.renderer, handedness: hand.value, plan, send: sendMarkers, onEnd: end });
    x.tracker = t;
    try {
      await t.start();
    } catch (err) {
      x.tracker = null;
      return overlay.fail(`WebXR: ${err.message || err}`);
    }
    c.xr.active = true;
    c.xr.hand = hand.value;
    button.textContent = "stop tracking";
    view.handleGroup.visible = false;
    x.placed = false;
    view.scene.add(overlay.panel);
  });

  function end() {
    x.tracker = null;
    c.xr.active = false;
    c.xr.tracked = false;
    button.textContent = "track my hands";
    view.handleGroup.visible = true;
    view.stage.position.set(0, 0, 0);
    view.stage.quaternion.identity();
    view.stage.scale.setScalar(1);
    view.scene.remove(overlay.panel);
    updateControl();
  }

  /** Puts the model 45 cm in front of where the user looked at the first XR frame, 10 cm below
   * eye level, turned to face them, about 22 cm across whatever its units. */
  function placeStage() {
    if (x.placed || !x.tracker.viewer || !state.room?.bounds) return;
    const { stage } = view;
    const panel = overlay.panel;
    const [lo, hi] = state.room.bounds.map((v) => new THREE.Vector3(...v));
    const centre = lo.clone().add(hi).multiplyScalar(0.5);
    const size = Math.max(hi.x - lo.x, hi.y - lo.y, hi.z - lo.z) || 1;
    const { position: p, orientation: o } = x.tracker.viewer;
    const look = new THREE.Vector3(0, 0, -1).applyQuaternion(new THREE.Quaternion(o.x, o.y, o.z, o.w));
    const yaw = Math.atan2(-look.x, -look.z);
    const forward = new THREE.Vector3(-Math.sin(yaw), 0, -Math.cos(yaw));
    const at = new THREE.Vector3(p.x, p.y - 0.1, p.z).addScaledVector(forward, 0.45);
    stage.scale.setScalar(0.22 / size);
    stage.quaternion.setFromAxisAngle(new THREE.Vector3(0, 1, 0), yaw);
    stage.position.copy(at).sub(centre.multiplyScalar(0.22 / size).applyQuaternion(stage.quaternion));
    panel.position.copy(at).add(new THREE.Vector3(0, 0.17, 0));
    panel.quaternion.copy(stage.quaternion);
    x.placed = true;
  }

  /** At a redraw inside a session (`frame`: the XRFrame): reads and publishes the hand. */
  function onFrame(time, frame) {
    if (!frame || !x.tracker) return;
    x.tracker.onFrame(time, frame);
    c.xr.tracked = x.tracker.tracked;
    placeStage();
  }

  /** The markers the tracker last published (x, y, z each), for tests. */
  const markers = () => (x.tracker ? Array.from(x.tracker.markers) : null);

  return { updateControl, onFrame, markers };
}
