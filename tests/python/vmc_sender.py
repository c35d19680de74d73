#!/usr/bin/env python3
"""A third-party VMC sender for `crease bridge vmc`'s tests (client/tests/bridge_vmc.rs).

Builds VMC (OSC) bundles with python-osc -- not with our code -- for a right hand whose five
fingers curl from straight to 90 degrees per joint over --seconds, at --rate bundles per
second, and sends them to 127.0.0.1:--port. Between them it sends junk datagrams the bridge
must count and drop: bytes that are not OSC, a bone with too few arguments, a string where a
number goes, a NaN coordinate, a truncated bundle.

The motion, in Unity's frame (left-handed, Y up, metres), which the Rust test recomputes:
- /VMC/Ext/Root/Pos "root" at ROOT, identity; Hips at HIPS (local), identity;
- RightHand local to Hips at HAND, identity (the arm is not sent: the chain skips it);
- each finger's Proximal local to the hand at BASE[finger], its Intermediate and Distal at
  (SEG[finger][0], 0, 0) and (SEG[finger][1], 0, 0) local to the bone before; every finger
  bone rotated by theta about Unity's Z, theta = (pi / 2) * k / (frames - 1) in bundle k;
- a tracker /VMC/Ext/Tra/Pos "frame-counter" at (k / 1000, 0, 0), so each frame names its
  bundle;
- plus /VMC/Ext/Blend/Val (ignored by the bridge), /VMC/Ext/T and /VMC/Ext/OK in each bundle.
Every fifth bundle nests the finger bones in an inner bundle.

Prints one JSON line: bundles and junk datagrams sent.
"""

import argparse
import json
import math
import socket
import time

from pythonosc import osc_bundle_builder, osc_message_builder, udp_client

ROOT = (0.5, 0.0, 0.25)
HIPS = (0.0, 1.0, 0.0)
HAND = (0.35, 0.45, 0.05)
FINGERS = ["Thumb", "Index", "Middle", "Ring", "Little"]
BASE = {
    "Thumb": (0.03, -0.01, 0.04),
    "Index": (0.09, 0.0, 0.03),
    "Middle": (0.095, 0.0, 0.01),
    "Ring": (0.09, 0.0, -0.01),
    "Little": (0.08, 0.0, -0.03),
}
SEG = {
    "Thumb": (0.035, 0.03),
    "Index": (0.045, 0.025),
    "Middle": (0.05, 0.03),
    "Ring": (0.045, 0.028),
    "Little": (0.035, 0.022),
}


def message(address, *args):
    m = osc_message_builder.OscMessageBuilder(address=address)
    for a in args:
        if isinstance(a, float):
            m.add_arg(a, "f")
        else:
            m.add_arg(a)
    return m.build()


def pose(address, name, p, q):
    return message(address, name, *(float(v) for v in p), *(float(v) for v in q))


def bundle(contents):
    b = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)
    for c in contents:
        b.add_content(c)
    return b.build()


def frame(k, frames, nested):
    theta = (math.pi / 2) * k / max(frames - 1, 1)
    curl = (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))
    ident = (0.0, 0.0, 0.0, 1.0)
    body = [
        pose("/VMC/Ext/Root/Pos", "root", ROOT, ident),
        pose("/VMC/Ext/Bone/Pos", "Hips", HIPS, ident),
        pose("/VMC/Ext/Bone/Pos", "RightHand", HAND, ident),
    ]
    fingers = []
    for f in FINGERS:
        fingers.append(pose("/VMC/Ext/Bone/Pos", f"Right{f}Proximal", BASE[f], curl))
        fingers.append(pose("/VMC/Ext/Bone/Pos", f"Right{f}Intermediate", (SEG[f][0], 0, 0), curl))
        fingers.append(pose("/VMC/Ext/Bone/Pos", f"Right{f}Distal", (SEG[f][1], 0, 0), curl))
    tail = [
        pose("/VMC/Ext/Tra/Pos", "frame-counter", (k / 1000.0, 0.0, 0.0), ident),
        message("/VMC/Ext/Blend/Val", "Joy", 0.5),
        message("/VMC/Ext/T", float(k) / 60.0),
        message("/VMC/Ext/OK", 1),
    ]
    if nested:
        return bundle(body + [bundle(fingers)] + tail)
    return bundle(body + fingers + tail)


def junk(i):
    kind = i % 5
    if kind == 0:
        return b"definitely not OSC \x00\x01\x02"
    if kind == 1:
        return message("/VMC/Ext/Bone/Pos", "RightHand", 0.0, 0.0).dgram
    if kind == 2:
        return message("/VMC/Ext/Bone/Pos", "RightHand", "x", 0.0, 0.0, 0.0, 0.0, 0.0, 1.0).dgram
    if kind == 3:
        return bundle([pose("/VMC/Ext/Bone/Pos", "RightHand", (float("nan"), 0, 0), (0, 0, 0, 1))]).dgram
    good = frame(0, 2, False).dgram
    return good[: len(good) // 2 + 3]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--rate", type=float, default=60.0)
    ap.add_argument("--junk-every", type=int, default=12, help="a junk datagram after every N bundles")
    args = ap.parse_args()
    frames = max(int(round(args.seconds * args.rate)), 2)
    client = udp_client.UDPClient("127.0.0.1", args.port)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    period = 1.0 / args.rate
    start = time.monotonic()
    junk_sent = 0
    for k in range(frames):
        client.send(frame(k, frames, nested=(k % 5 == 4)))
        if args.junk_every > 0 and k % args.junk_every == args.junk_every - 1:
            raw.sendto(junk(junk_sent), ("127.0.0.1", args.port))
            junk_sent += 1
        # Paced on the clock, not on sleeps, so the motion lasts --seconds.
        delay = start + (k + 1) * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    print(json.dumps({"bundles": frames, "junk": junk_sent, "seconds": time.monotonic() - start}))


if __name__ == "__main__":
    main()
