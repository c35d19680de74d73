// WebXR hands (issue 19): "track my hands" starts an immersive session with hand tracking and
// publishes the chosen hand's joints every XR frame into a retargeting room, whose joint map
// turns them into the model's control points (bench/mocap/webxr-*.toml).
//
// The markers a room declares (GET /api/rooms/{id} -> capture.markers) are WebXR joint names
// (W3C WebXR Hand Input Module, "Skeleton Joints": 25 per hand) in three forms
// (crease_hand::joint_map::capture_markers):
// - `index-finger-tip`: the joint's centre (its pose's position);
// - `index-finger-tip/dorsal`: the centre plus the joint's radius along the pose's +Y axis,
//   which the specification points out of the back of the hand: a point on the skin over the
//   joint, where a glove's marker would sit;
// - `index-finger-tip/palmar`: the centre minus the radius along +Y, on the palm side.
// Positions are metres in the session's `local` reference space. A left hand is mirrored
// (x -> -x) onto the right-hand models the maps are written for: the room's registration is a
// rotation, which cannot turn a left hand into a right one.

/** The WebXR joints in the specification's order (also XRHand's iteration order). */
export const JOINTS = [
  "wrist",
  "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip",
  "index-finger-metacarpal", "index-finger-phalanx-proximal", "index-finger-phalanx-intermediate",
  "index-finger-phalanx-distal", "index-finger-tip",
  "middle-finger-metacarpal", "middle-finger-phalanx-proximal", "middle-finger-phalanx-intermediate",
  "middle-finger-phalanx-distal", "middle-finger-tip",
  "ring-finger-metacarpal", "ring-finger-phalanx-proximal", "ring-finger-phalanx-intermediate",
  "ring-finger-phalanx-distal", "ring-finger-tip",
  "pinky-finger-metacarpal", "pinky-finger-phalanx-proximal", "pinky-finger-phalanx-intermediate",
  "pinky-finger-phalanx-distal", "pinky-finger-tip",
];
export const DORSAL_SUFFIX = "/dorsal";
export const PALMAR_SUFFIX = "/palmar";

/**
 * How to fill a room's declared markers from the 25 joints: `{joint: Int32Array, side:
 * Int8Array}` (per marker its joint index and its side: 0 the centre, 1 dorsal, -1 palmar), or
 * `{error}` naming the first marker that is not a WebXR joint marker.
 */
export function markerPlan(names) {
  if (!names || names.length === 0) return { error: "this room takes control points, not a capture (open room hands, or a room opened with a WebXR joint map)" };
  const joint = new Int32Array(names.length);
  const side = new Int8Array(names.length);
  for (let i = 0; i < names.length; i++) {
    let name = names[i];
    for (const [suffix, s] of [[DORSAL_SUFFIX, 1], [PALMAR_SUFFIX, -1]]) {
      if (name.endsWith(suffix)) {
        name = name.slice(0, -suffix.length);
        side[i] = s;
      }
    }
    const j = JOINTS.indexOf(name);
    if (j < 0) return { error: `marker ${JSON.stringify(names[i])} of this room is not a WebXR joint (expected e.g. "index-finger-tip", "index-finger-tip${DORSAL_SUFFIX}" or "index-finger-tip${PALMAR_SUFFIX}")` };
    joint[i] = j;
  }
  return { joint, side };
}

/**
 * Fills `out` (x, y, z per marker) from `poses` (16 floats per joint, column-major, as
 * XRFrame.fillPoses writes them) and `radii` (XRFrame.fillJointRadii); `mirror` negates x.
 */
export function fillMarkers(plan, poses, radii, mirror, out) {
  const sx = mirror ? -1 : 1;
  for (let i = 0; i < plan.joint.length; i++) {
    const m = 16 * plan.joint[i];
    const r = plan.side[i] * radii[plan.joint[i]];
    // Column 1 (elements 4..6) is the joint's +Y axis; column 3 (12..14) its position.
    out[3 * i] = sx * (poses[m + 12] + r * poses[m + 4]);
    out[3 * i + 1] = poses[m + 13] + r * poses[m + 5];
    out[3 * i + 2] = poses[m + 14] + r * poses[m + 6];
  }
}

/** A JSON marker frame (metres to 10 µm: ~1.8 KB for 75 markers). */
export function markerMessage(seq, captureTimeUs, markers) {
  let text = `{"seq":${seq},"capture_time_us":${captureTimeUs},"markers":[`;
  for (let i = 0; i < markers.length; i++) text += (i ? "," : "") + markers[i].toFixed(5);
  return `${text}]}`;
}

/**
 * One hand-tracking session. `renderer` is the viewer's three.js renderer (xr enabled),
 * `handedness` "right" or "left", `plan` a markerPlan, `send(captureTimeUs, markers)`
 * publishes, `onEnd()` runs when the session ends (by the user or the runtime).
 */
export class HandTracker {
  constructor({ renderer, handedness, plan, send, onEnd }) {
    this.renderer = renderer;
    this.handedness = handedness;
    this.plan = plan;
    this.send = send;
    this.onEnd = onEnd;
    this.session = null;
    this.spaces = null; // the tracked hand's 25 joint spaces, in JOINTS order
    this.source = null;
    this.poses = new Float32Array(16 * JOINTS.length);
    this.radii = new Float32Array(JOINTS.length);
    this.markers = new Float32Array(3 * plan.joint.length);
    this.tracked = false; // the hand was tracked in the last XR frame
    this.published = 0;
    this.viewer = null; // the viewer's pose at the first frame: {position, orientation}
  }

  /** Starts the immersive session (rejects with the runtime's reason). */
  async start() {
    const session = await navigator.xr.requestSession("immersive-vr", {
      optionalFeatures: ["hand-tracking"],
    });
    this.session = session;
    session.addEventListener("end", () => {
      this.session = null;
      this.spaces = null;
      this.source = null;
      this.onEnd();
    });
    session.addEventListener("inputsourceschange", () => {
      this.spaces = null; // found again at the next frame
      this.source = null;
    });
    this.renderer.xr.setReferenceSpaceType("local");
    await this.renderer.xr.setSession(session);
  }

  /** Ends the session. */
  async stop() {
    if (this.session) await this.session.end();
  }

  /** The hand to track among the session's input sources, and its joint spaces. */
  findHand() {
    for (const source of this.session.inputSources) {
      if (source.hand && source.handedness === this.handedness) {
        this.source = source;
        this.spaces = JOINTS.map((name) => source.hand.get(name));
        return;
      }
    }
  }

  /**
   * Called with every XR frame (time in the performance clock, ms): reads the hand's joints
   * and publishes them. Sends nothing while the hand is not tracked (the room holds its pose).
   */
  onFrame(time, frame) {
    const space = this.renderer.xr.getReferenceSpace();
    if (!this.viewer) {
      const pose = frame.getViewerPose(space);
      if (pose) this.viewer = { position: pose.transform.position, orientation: pose.transform.orientation };
    }
    if (!this.spaces) this.findHand();
    this.tracked =
      Boolean(this.spaces) &&
      this.spaces.every(Boolean) &&
      frame.fillPoses(this.spaces, space, this.poses) &&
      frame.fillJointRadii(this.spaces, this.radii);
    if (!this.tracked) return;
    fillMarkers(this.plan, this.poses, this.radii, this.handedness === "left", this.markers);
    const captureUs = Math.round((performance.timeOrigin + time) * 1000);
    if (this.send(captureUs, this.markers)) this.published += 1;
  }
}
