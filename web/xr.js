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
// Positions are metres in the session's `local` reference space. In a one-actor room a left
// hand is mirrored (x -> -x) onto the right-hand models the maps are written for: the room's
// registration is a rotation, which cannot turn a left hand into a right one. In a room of
// several actors (issue 38) each actor with a side takes that hand as tracked (a left actor
// runs on a left-hand model: the right-hand one mirrored, with its own map), and one message
// carries every tracked hand of an XR frame.

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

/**
 * A JSON marker frame (metres to 10 µm: ~1.8 KB for 75 markers per hand) of `parts`, each
 * {actor, markers}: a one-actor room's (actor null) carries its markers, a room of several
 * actors' each tracked hand's under its actor's name.
 */
export function markerMessage(seq, captureTimeUs, parts) {
  const list = (markers) => {
    let text = "";
    for (let i = 0; i < markers.length; i++) text += (i ? "," : "") + markers[i].toFixed(5);
    return `[${text}]`;
  };
  const head = `{"seq":${seq},"capture_time_us":${captureTimeUs}`;
  if (parts.length === 1 && parts[0].actor == null) {
    // A one-actor room's hand lost: every marker sent invalid, the room holds its pose.
    const lost = parts[0].lost ? `,"markers_valid":[${Array(parts[0].markers.length / 3).fill("false").join(",")}]` : "";
    return `${head},"markers":${list(parts[0].markers)}${lost}}`;
  }
  return `${head},"actors":[${parts.map((p) => `{"actor":${JSON.stringify(p.actor)},"markers":${list(p.markers)}}`).join(",")}]}`;
}

/** One tracked hand of a session: which input source, its actor, its plan and buffers. */
class TrackedHand {
  constructor({ actor, handedness, plan, mirror }) {
    this.actor = actor; // the actor's name, or null in a one-actor room
    this.handedness = handedness;
    this.plan = plan;
    this.mirror = mirror;
    this.spaces = null; // the hand's 25 joint spaces, in JOINTS order
    this.poses = new Float32Array(16 * JOINTS.length);
    this.radii = new Float32Array(JOINTS.length);
    this.markers = new Float32Array(3 * plan.joint.length);
    this.tracked = false; // tracked in the last XR frame
  }

  /** The hand among the session's input sources, and its joint spaces. */
  find(session) {
    for (const source of session.inputSources) {
      if (source.hand && source.handedness === this.handedness) {
        this.spaces = JOINTS.map((name) => source.hand.get(name));
        return;
      }
    }
  }

  /** Reads the hand's joints in `frame` into its markers; whether it was tracked. */
  read(session, frame, space) {
    if (!this.spaces) this.find(session);
    this.tracked =
      Boolean(this.spaces) &&
      this.spaces.every(Boolean) &&
      frame.fillPoses(this.spaces, space, this.poses) &&
      frame.fillJointRadii(this.spaces, this.radii);
    if (this.tracked) fillMarkers(this.plan, this.poses, this.radii, this.mirror, this.markers);
    return this.tracked;
  }
}

/**
 * One hand-tracking session. `renderer` is the viewer's three.js renderer (xr enabled),
 * `hands` the hands to publish, each {actor (null in a one-actor room), handedness "right" or
 * "left", plan (a markerPlan), mirror (negate x)}, `send(captureTimeUs, parts)` publishes
 * ([{actor, markers}] of the hands tracked), `onEnd()` runs when the session ends (by the
 * user or the runtime).
 */
export class HandTracker {
  constructor({ renderer, hands, send, onEnd }) {
    this.renderer = renderer;
    this.hands = hands.map((h) => new TrackedHand(h));
    this.send = send;
    this.onEnd = onEnd;
    this.session = null;
    this.parts = []; // the last frame's tracked hands, reused
    this.tracked = false; // a hand was tracked in the last XR frame
    this.published = 0;
    this.viewer = null; // the viewer's pose at the first frame: {position, orientation}
  }

  /** Starts the immersive session (rejects with the runtime's reason). */
  async start() {
    const session = await navigator.xr.requestSession("immersive-vr", {
      optionalFeatures: ["hand-tracking"],
    });
    this.session = session;
    const forget = () => {
      for (const h of this.hands) h.spaces = null; // found again at the next frame
    };
    session.addEventListener("end", () => {
      this.session = null;
      forget();
      this.onEnd();
    });
    session.addEventListener("inputsourceschange", forget);
    this.renderer.xr.setReferenceSpaceType("local");
    await this.renderer.xr.setSession(session);
  }

  /** Ends the session. */
  async stop() {
    if (this.session) await this.session.end();
  }

  /** The markers `actor`'s hand (the first hand when absent) last published, or null. */
  markersOf(actor) {
    const hand = actor == null ? this.hands[0] : this.hands.find((h) => h.actor === actor);
    return hand ? hand.markers : null;
  }

  /**
   * Called with every XR frame (time in the performance clock, ms): reads the hands' joints
   * and publishes the tracked ones in one message. Sends nothing while no hand is tracked (an
   * actor whose hand is not seen holds its pose).
   */
  onFrame(time, frame) {
    const space = this.renderer.xr.getReferenceSpace();
    if (!this.viewer) {
      const pose = frame.getViewerPose(space);
      if (pose) this.viewer = { position: pose.transform.position, orientation: pose.transform.orientation };
    }
    this.parts.length = 0;
    for (const h of this.hands) if (h.read(this.session, frame, space)) this.parts.push(h);
    this.tracked = this.parts.length > 0;
    if (!this.tracked) return;
    const captureUs = Math.round((performance.timeOrigin + time) * 1000);
    if (this.send(captureUs, this.parts)) this.published += 1;
  }
}
