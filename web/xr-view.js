// The viewer's WebXR hands (issue 19; issue 37's module): in a room whose markers are WebXR
// joints, the "track my hands" button (#xr-row), the session (xr.js HandTracker) publishing
// the chosen hand's joints every XR frame, the stage placed in front of the user at the
// first XR frame, and the overlay's panel (overlay.js) above the hand while tracking. In a
// room of several actors with sides (issue 38: the demo's `both-hands`) it publishes both
// hands at once, each to the actor of its side, and the hand picker is hidden.

import * as THREE from "three";
import { HandTracker, markerMessage, markerPlan } from "./xr.js";

/** `elements` = {row, button, hand} (#xr-row, #xr, #hand); `token()` reads the publish token. */
export function createXr(state, { view, connection, overlay, elements, token }) {
  const c = state.crease;
  const x = state.xr;
  const { row, button, hand } = elements;

  /** Publishes one XR frame's tracked hands; false when the socket is not ready or backed up. */
  function sendMarkers(captureUs, parts) {
    if (!connection.ready()) return false;
    // Latest wins: a frame queued behind 64 KB would only arrive late.
    if (connection.backedUp()) {
      c.xr.dropped += 1;
      return false;
    }
    if (x.tracker.firstCaptureUs === undefined) x.tracker.firstCaptureUs = captureUs;
    c.xr.seq = state.socket.seq;
    connection.send(markerMessage(state.socket.seq++, captureUs, parts));
    c.published += 1;
    c.xr.published += 1;
    return true;
  }

  /**
   * The hands a session publishes: in a room of several actors each actor with a side and a
   * capture (its hand as tracked), else the picked hand (a left one mirrored onto the
   * right-hand model); or {error} naming what cannot be tracked.
   */
  function handsToTrack() {
    const actors = state.room?.actors ?? [];
    if (actors.length === 0) {
      const plan = markerPlan(state.room?.capture?.markers);
      return plan.error ? { error: plan.error } : { hands: [{ actor: null, handedness: hand.value, plan, mirror: hand.value === "left" }] };
    }
    const hands = [];
    for (const a of actors) {
      if (!a.side) continue;
      const plan = markerPlan(a.capture?.markers);
      if (plan.error) return { error: `actor ${a.name}: ${plan.error}` };
      hands.push({ actor: a.name, handedness: a.side, plan, mirror: false });
    }
    return hands.length ? { hands } : { error: "no actor of this room has a side (left or right) for a tracked hand" };
  }

  /** Shows "track my hands" in rooms whose markers are WebXR joints; enabled where XR is. */
  async function updateControl() {
    const plan = handsToTrack();
    // A room of other markers (the camera's MediaPipe landmarks) has its own control.
    row.hidden = !state.room?.capture || /is not a WebXR joint/.test(plan.error || "");
    if (row.hidden) {
      c.xr.reason = "";
      return;
    }
    // A room of actors with sides tracks both hands: nothing to pick.
    hand.hidden = Boolean(state.room.actors?.length);
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

  /** Shows or hides every actor's handles (hidden while tracking). */
  const showHandles = (visible) => {
    for (const slot of state.actors) if (slot.handleGroup) slot.handleGroup.visible = visible;
  };

  button.addEventListener("click", async () => {
    if (x.tracker) return x.tracker.stop();
    if (!token()) return overlay.fail("enter the room's publish token to track your hands");
    const { hands, error } = handsToTrack();
    if (error) return overlay.fail(`WebXR: ${error}`);
    const t = new HandTracker({ renderer: view.renderer, hands, send: sendMarkers, onEnd: end });
    x.tracker = t;
    try {
      await t.start();
    } catch (err) {
      x.tracker = null;
      return overlay.fail(`WebXR: ${err.message || err}`);
    }
    c.xr.active = true;
    c.xr.hand = hands.map((h) => h.handedness).join(" and ");
    button.textContent = "stop tracking";
    showHandles(false);
    x.placed = false;
    view.scene.add(overlay.panel);
  });

  function end() {
    x.tracker = null;
    c.xr.active = false;
    c.xr.tracked = false;
    button.textContent = "track my hands";
    showHandles(true);
    view.stage.position.set(0, 0, 0);
    view.stage.quaternion.identity();
    view.stage.scale.setScalar(1);
    view.scene.remove(overlay.panel);
    updateControl();
  }

  /** Puts the actors 45 cm in front of where the user looked at the first XR frame, 10 cm
   * below eye level, turned to face them, the first actor about 22 cm across whatever its
   * units (a hand at about its size). */
  function placeStage() {
    const first = state.actors[0]?.room?.bounds;
    if (x.placed || !x.tracker.viewer || !state.bounds || !first) return;
    const { stage } = view;
    const panel = overlay.panel;
    const [lo, hi] = state.bounds.map((v) => new THREE.Vector3(...v));
    const centre = lo.clone().add(hi).multiplyScalar(0.5);
    const [flo, fhi] = first.map((v) => new THREE.Vector3(...v));
    const size = Math.max(fhi.x - flo.x, fhi.y - flo.y, fhi.z - flo.z) || 1;
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
    c.xr.hands = x.tracker.hands.map((h) => ({ actor: h.actor, hand: h.handedness, tracked: h.tracked }));
    placeStage();
  }

  /** The markers the tracker last published for `actor`'s hand (the first hand's when
   * absent; x, y, z each), for tests. */
  const markers = (actor) => {
    const m = x.tracker ? x.tracker.markersOf(actor) : null;
    return m ? Array.from(m) : null;
  };

  return { updateControl, onFrame, markers };
}
