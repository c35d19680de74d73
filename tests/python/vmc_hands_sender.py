#!/usr/bin/env python3
"""A VSeeFace-like VMC sender for the demo's room `vmc` (issue 39; demo/tests/vmc.rs).

Builds VMC (OSC) bundles with python-osc -- not with our code -- of a humanoid skeleton the
way VSeeFace and VirtualMotionCapture send a VRM avatar: /VMC/Ext/Root/Pos, then
/VMC/Ext/Bone/Pos for the trunk, both arms and every finger bone of both hands, each bone's
pose local to its parent (Unity's frame: left-handed, Y up, Z forward, metres), and
/VMC/Ext/OK. The avatar's proportions are a typical adult humanoid's (a 1.7 m figure, a hand
of about 19 cm from the wrist to the middle fingertip), not the sweep hand's. Its rest pose is
VRM's normalised T-pose (every rest rotation identity): arms along +X (right) and -X (left),
palms down, fingers straight along the arm, thumbs forward (+Z) and down.

Hand poses (--pose): `relaxed` (every finger joint 15 degrees, the thumb 10), `fist`
(fingers 80 / 95 / 60 degrees at MCP / PIP / DIP, the thumb across the palm) and `point`
(the index straight, the rest as the fist). A finger flexes about the hand's Z axis towards
the palm (-Y); the thumb about Y then Z, across the palm. The left hand is the right mirrored
across Unity's x = 0.

Sends --frames bundles at --rate per second to 127.0.0.1:--port (the wrists swaying a little,
so that each bundle differs), and prints one JSON line: bundles sent.
"""

import argparse
import json
import math
import socket
import time

from pythonosc import osc_bundle_builder, osc_message_builder

HIPS = (0.0, 0.95, 0.0)
TRUNK = [("Spine", (0.0, 0.1, 0.0)), ("Chest", (0.0, 0.12, 0.0)), ("UpperChest", (0.0, 0.12, 0.0))]
# Right side (the left mirrors x): shoulder, upper arm, lower arm, hand, local offsets.
ARM = [
    ("Shoulder", (0.03, 0.12, 0.0)),
    ("UpperArm", (0.1, 0.0, 0.0)),
    ("LowerArm", (0.27, 0.0, 0.0)),
    ("Hand", (0.25, 0.0, 0.0)),
]
# Per finger: the proximal bone's offset from the hand, then the intermediate's and the
# distal's along the finger (typical adult proportions; the middle finger ~10 cm long).
FINGERS = {
    "Thumb": ((0.025, -0.012, 0.03), (0.04, 0.032)),
    "Index": ((0.095, 0.0, 0.026), (0.042, 0.026)),
    "Middle": ((0.098, 0.0, 0.005), (0.047, 0.029)),
    "Ring": ((0.094, 0.0, -0.014), (0.044, 0.027)),
    "Little": ((0.085, -0.002, -0.032), (0.034, 0.022)),
}
# The thumb's bones leave the hand diagonally, forward and out.
THUMB_DIRECTION = (0.72, -0.2, 0.66)

POSES = {
    "relaxed": {"finger": (15, 15, 15), "index": (15, 15, 15), "thumb": (10, 10, 10)},
    "fist": {"finger": (80, 95, 60), "index": (80, 95, 60), "thumb": (35, 40, 40)},
    "point": {"finger": (80, 95, 60), "index": (5, 5, 5), "thumb": (35, 40, 40)},
}


def message(address, *args):
    m = osc_message_builder.OscMessageBuilder(address=address)
    for a in args:
        m.add_arg(float(a) if isinstance(a, float) else a, "f" if isinstance(a, float) else None)
    return m.build()


def pose(address, name, p, q):
    return message(address, name, *(float(v) for v in p), *(float(v) for v in q))


def about(axis, degrees):
    """A unit quaternion (x, y, z, w) of `degrees` about `axis` (Unity's convention)."""
    n = math.sqrt(sum(a * a for a in axis))
    h = math.radians(degrees) / 2
    s = math.sin(h) / n
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(h))


def mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


IDENT = (0.0, 0.0, 0.0, 1.0)


def mirror_x(p):
    return (-p[0], p[1], p[2])


def mirror_q(q):
    # A rotation mirrored across x = 0: its axis (a pseudovector) becomes (x, -y, -z).
    return (q[0], -q[1], -q[2], q[3])


def hand_bones(side, hand_pose):
    """(name, local position, local rotation) of one hand's finger bones."""
    bones = []
    for finger, (base, (inter, distal)) in FINGERS.items():
        angles = hand_pose["thumb" if finger == "Thumb" else "index" if finger == "Index" else "finger"]
        if finger == "Thumb":
            d = THUMB_DIRECTION
            # Across the palm: about the hand's Y (forward to back), then down.
            rotations = [mul(about((0, 1, 0), a), about((0, 0, 1), -0.5 * a)) for a in angles]
            offsets = [base, tuple(inter * c for c in d), tuple(distal * c for c in d)]
        else:
            rotations = [about((0, 0, 1), -a) for a in angles]
            offsets = [base, (inter, 0.0, 0.0), (distal, 0.0, 0.0)]
        for segment, p, q in zip(["Proximal", "Intermediate", "Distal"], offsets, rotations):
            if side == "Left":
                p, q = mirror_x(p), mirror_q(q)
            bones.append((f"{side}{finger}{segment}", p, q))
    return bones


def frame(k, hand_pose):
    sway = about((0, 1, 0), 4 * math.sin(k / 9.0))
    b = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)
    b.add_content(pose("/VMC/Ext/Root/Pos", "root", (0.0, 0.0, 0.0), IDENT))
    b.add_content(pose("/VMC/Ext/Bone/Pos", "Hips", HIPS, IDENT))
    for name, p in TRUNK:
        b.add_content(pose("/VMC/Ext/Bone/Pos", name, p, IDENT))
    for side in ["Right", "Left"]:
        for name, p in ARM:
            q = sway if name == "Hand" else IDENT
            if side == "Left":
                p, q = mirror_x(p), mirror_q(q)
            b.add_content(pose("/VMC/Ext/Bone/Pos", f"{side}{name}", p, q))
        for name, p, q in hand_bones(side, hand_pose):
            b.add_content(pose("/VMC/Ext/Bone/Pos", name, p, q))
    b.add_content(message("/VMC/Ext/OK", 1))
    return b.build().dgram


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--pose", choices=sorted(POSES), required=True)
    ap.add_argument("--frames", type=int, default=90)
    ap.add_argument("--rate", type=float, default=60.0)
    args = ap.parse_args()
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    start = time.monotonic()
    for k in range(args.frames):
        s.sendto(frame(k, POSES[args.pose]), ("127.0.0.1", args.port))
        wait = start + (k + 1) / args.rate - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    print(json.dumps({"bundles": args.frames, "pose": args.pose}))


if __name__ == "__main__":
    main()
