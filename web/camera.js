// A webcam as a capture source (issue 46): MediaPipe Hands' landmarks as a room's raw markers.
// Everything here is plain arithmetic on MediaPipe's results, kept apart from the page
// (camera-view.js) so that a test can run it on known landmarks.
//
// MediaPipe Hands (the legacy `@mediapipe/hands` solution, web/node_modules, Apache-2.0) gives
// per hand 21 landmarks in two forms:
// - image landmarks: x, y in [0, 1] of the image's width and height (y down), z a relative
//   depth at the wrist's scale;
// - world landmarks: metres, centred near the hand's middle, axes x right and y down as in
//   the image and z away from the camera (a right-handed frame, so a right hand stays right).
// The room's markers are the 21 names of crease_hand::mediapipe_map::mediapipe_markers
// (MediaPipe's HandLandmark names, lower case). The map fitted for them
// (bench/mocap/mediapipe-back*.toml) registers each frame onto the model's hand rigidly with
// one scale, so only the hand's shape matters to the prediction; where the hand is matters to
// how two hands sit beside each other, and that comes from the image:
//
// The hand's place. World landmarks are hand-centred: the camera's distance is unknown. It is
// estimated from the hand's size: the palm's reference lengths (wrist to each finger's MCP,
// MCP to MCP across the palm) in metres (world) against the same lengths in pixels (image);
// with a focal length f in pixels, depth = f x metres / pixels, and the wrist's image point
// at that depth gives its camera-space position, which the world landmarks are moved to.
// What it cannot know: the camera's field of view (assumed, HORIZONTAL_FOV_DEG, unless the
// page is told), and how far the palm is turned away from the camera (a palm seen edge-on
// looks smaller, so it is placed too far: the longest of the reference lengths is used,
// which a turn shortens least). MediaPipe's metric scale is itself an estimate from a
// typical hand; the room fits the performer's own scale over its first frames.

/** MediaPipe's 21 hand landmarks, in its order (HandLandmark), lower case. */
export const LANDMARKS = [
  "wrist",
  "thumb_cmc", "thumb_mcp", "thumb_ip", "thumb_tip",
  "index_finger_mcp", "index_finger_pip", "index_finger_dip", "index_finger_tip",
  "middle_finger_mcp", "middle_finger_pip", "middle_finger_dip", "middle_finger_tip",
  "ring_finger_mcp", "ring_finger_pip", "ring_finger_dip", "ring_finger_tip",
  "pinky_mcp", "pinky_pip", "pinky_dip", "pinky_tip",
];

/** The horizontal field of view assumed for a webcam whose own is unknown (degrees). */
export const HORIZONTAL_FOV_DEG = 60;

/** Below this handedness score a hand is not published (its actor holds its pose). */
export const MIN_SCORE = 0.5;

/** The palm's reference lengths, landmark pairs (module notes). */
const PALM = [[0, 5], [0, 9], [0, 13], [0, 17], [5, 17]];

/**
 * How to fill a room's declared markers from the 21 landmarks: an Int32Array (per marker its
 * landmark index), or `{error}` naming the first marker that is not a MediaPipe landmark.
 */
export function landmarkPlan(names) {
  if (!names || names.length === 0) return { error: "this room takes control points, not a capture (open room camera)" };
  const plan = new Int32Array(names.length);
  for (let i = 0; i < names.length; i++) {
    const j = LANDMARKS.indexOf(names[i]);
    if (j < 0) return { error: `marker ${JSON.stringify(names[i])} of this room is not a MediaPipe hand landmark (expected e.g. "index_finger_tip")` };
    plan[i] = j;
  }
  return { plan };
}

/**
 * The hand's wrist in camera space (metres; x right, y down, z away), from its `image` and
 * `world` landmarks (21 {x, y, z} each), the image's size in pixels and the horizontal field
 * of view in degrees (module notes). `null` when the hand's image is degenerate.
 */
export function placeHand(image, world, width, height, fovDeg = HORIZONTAL_FOV_DEG) {
  const f = width / 2 / Math.tan((fovDeg * Math.PI) / 360);
  let best = 0;
  let ratio = 0;
  for (const [a, b] of PALM) {
    const metres = Math.hypot(world[a].x - world[b].x, world[a].y - world[b].y, world[a].z - world[b].z);
    const pixels = Math.hypot((image[a].x - image[b].x) * width, (image[a].y - image[b].y) * height);
    // The longest reference in the image, the one a turn of the palm shortens least.
    if (pixels > best && metres > 0) {
      best = pixels;
      ratio = metres / pixels;
    }
  }
  if (!(best > 1) || !Number.isFinite(ratio)) return null;
  const depth = f * ratio;
  const u = (image[0].x - 0.5) * width;
  const v = (image[0].y - 0.5) * height;
  return { x: (u * depth) / f, y: (v * depth) / f, z: depth };
}

/**
 * Fills `out` (x, y, z per declared marker, metres, camera space) from one hand's `world`
 * landmarks moved so that its wrist sits at `wrist` (placeHand; the world landmarks as they
 * are when null).
 */
export function fillLandmarks(plan, world, wrist, out) {
  const dx = wrist ? wrist.x - world[0].x : 0;
  const dy = wrist ? wrist.y - world[0].y : 0;
  const dz = wrist ? wrist.z - world[0].z : 0;
  for (let i = 0; i < plan.length; i++) {
    const p = world[plan[i]];
    out[3 * i] = p.x + dx;
    out[3 * i + 1] = p.y + dy;
    out[3 * i + 2] = p.z + dz;
  }
}

/**
 * The user's side of each hand MediaPipe found in `results` (its multiHandedness), as
 * [{index, side: "right" | "left", score}], `index` into its multiHandLandmarks. MediaPipe
 * labels hands as if the image were mirrored (a selfie); the camera's frames are not
 * (selfieMode off, so that the world landmarks keep the hand's chirality), so its "Left" is
 * the user's right hand. A handedness' own `index` is its label's class (0 Left, 1 Right),
 * not the hand's place among the landmarks, whatever its typings say (MediaPipe issues
 * #1586, #4610; the closed-loop test swapped two hands by it): the arrays are parallel.
 */
export function handSides(multiHandedness) {
  return (multiHandedness || []).map((h, k) => ({
    index: k,
    side: h.label === "Left" ? "right" : "left",
    score: h.score,
  }));
}
