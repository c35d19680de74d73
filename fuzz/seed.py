#!/usr/bin/env python3
"""Seed corpora for the fuzz targets (issue 21), written under fuzz/seeds/<target>/.

From ../shared/data (real meshes and recordings, cut down where large so a run stays fast), the
codec and palette test vectors (tests/vectors), the NatNet fixtures (tests/fixtures/natnet), the
repository's marker maps and manifests, and small hand-made inputs in each target's own framing
(see the target's doc comment). Nothing here is committed: the seeds are rebuilt by fuzz/run.sh.

Usage: python3 fuzz/seed.py [SHARED_DATA]   (default ../shared/data beside the repository)
"""
import json
import os
import struct
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "fuzz" / "seeds"
DATA = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "data"


def put(target, name, data):
    d = OUT / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())


# --- protobuf by hand (field numbers from proto/crease/v1/crease.proto) ---
def varint(n):
    out = bytearray()
    n &= (1 << 64) - 1
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def field(num, wire, payload):
    key = varint((num << 3) | wire)
    if wire == 0:
        return key + varint(payload)
    if wire == 2:
        return key + varint(len(payload)) + payload
    if wire == 5:
        return key + payload
    raise ValueError(wire)


def floats(values):
    return b"".join(struct.pack("<f", v) for v in values)


def control_frame(room="r", seq=1, positions=(), valid=b"", markers=(), markers_valid=b""):
    m = field(1, 2, room.encode()) + field(2, 0, seq) + field(3, 0, 123456)
    if positions:
        m += field(4, 2, floats(positions))
    if valid:
        m += field(5, 2, valid)
    if markers:
        m += field(6, 2, floats(markers))
    if markers_valid:
        m += field(7, 2, markers_valid)
    return m


def vec3(x, y, z):
    return field(1, 5, struct.pack("<f", x)) + field(2, 5, struct.pack("<f", y)) + field(3, 5, struct.pack("<f", z))


def capture(messages):
    return b"".join(struct.pack("<I", len(m)) + m for m in messages)


def frame_message(seq, data):
    return field(2, 2, field(1, 0, seq) + field(4, 2, data))


# --- meshes ---
def read_ply_ascii(path, keep):
    """The first `keep` vertices of an ASCII PLY and the faces among them."""
    lines = path.read_text().splitlines()
    end = lines.index("end_header")
    header = lines[:end]
    nv = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
    verts = [tuple(map(float, l.split()[:3])) for l in lines[end + 1 : end + 1 + nv]]
    faces = []
    for l in lines[end + 1 + nv :]:
        p = l.split()
        if len(p) >= 4 and int(p[0]) == 3:
            f = tuple(int(x) for x in p[1:4])
            if max(f) < keep:
                faces.append(f)
    return verts[:keep], faces


def ply_text(verts, faces):
    s = f"ply\nformat ascii 1.0\nelement vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(faces)}\nproperty list uchar int vertex_index\nend_header\n"
    s += "".join(f"{x} {y} {z}\n" for x, y, z in verts)
    s += "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    return s


def ply_binary(verts, faces, endian="<", fmt="binary_little_endian"):
    h = f"ply\nformat {fmt} 1.0\nelement vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(faces)}\nproperty list uchar uint vertex_indices\nend_header\n".encode()
    body = b"".join(struct.pack(endian + "3f", *v) for v in verts)
    body += b"".join(struct.pack(endian + "B3I", 3, *f) for f in faces)
    return h + body


def obj_text(verts, faces):
    return "".join(f"v {x} {y} {z}\n" for x, y, z in verts) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces
    )


def read_obj(path, keep):
    verts, faces = [], []
    for l in path.read_text().splitlines():
        p = l.split()
        if not p:
            continue
        if p[0] == "v":
            verts.append(tuple(map(float, p[1:4])))
        elif p[0] == "f":
            f = [int(x.split("/")[0]) - 1 for x in p[1:]]
            for k in range(1, len(f) - 1):
                t = (f[0], f[k], f[k + 1])
                if max(t) < keep:
                    faces.append(t)
    return verts[:keep], faces


TET_V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
TET_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def meshes():
    put("mesh_obj", "tet.obj", obj_text(TET_V, TET_F))
    put("mesh_obj", "quads.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nf 1/1/1 2/1/1 3/1/1 4/1/1\n")
    put("mesh_ply", "tet-ascii.ply", ply_text(TET_V, TET_F))
    put("mesh_ply", "tet-le.ply", ply_binary(TET_V, TET_F))
    put("mesh_ply", "tet-be.ply", ply_binary(TET_V, TET_F, ">", "binary_big_endian"))
    cactus = DATA / "cactus" / "cactus0.ply"
    if cactus.exists():
        v, f = read_ply_ascii(cactus, 200)
        put("mesh_ply", "cactus0-200.ply", ply_text(v, f))
        put("mesh_ply", "cactus0-200-le.ply", ply_binary(v, f))
        put("mesh_obj", "cactus0-200.obj", obj_text(v, f))
    horse = DATA / "horse" / "reference.obj"
    if horse.exists():
        v, f = read_obj(horse, 300)
        put("mesh_obj", "horse-300.obj", obj_text(v, f))
        put("mesh_ply", "horse-300.ply", ply_text(v, f))
    for glb in sorted((DATA / "hand").glob("*.glb")):
        put("mesh_gltf", glb.name, glb.read_bytes())
    # A minimal glTF with an embedded base64 buffer (one triangle).
    import base64

    buf = floats([0, 0, 0, 1, 0, 0, 0, 1, 0]) + struct.pack("<3H", 0, 1, 2) + b"\0\0"
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    }
    put("mesh_gltf", "triangle.gltf", json.dumps(doc))


def models():
    # Models and rigs come from the release build's own writer when present (fuzz/run.sh
    # trains one); any *.crease / *.rig under target/fuzz-models is used.
    for p in sorted((ROOT / "target" / "fuzz-models").glob("*")):
        if p.suffix in (".crease", ".rig"):
            put("model_file", p.name, p.read_bytes())
    put("model_file", "empty", b"")


def codec():
    vec = json.loads((ROOT / "tests" / "vectors" / "codec-v1.json").read_text())
    for s in vec["streams"]:
        frames = [bytes.fromhex(f["frame_hex"]) for f in s["frames"]]
        data = struct.pack("<H", s["vertex_count"]) + b"".join(struct.pack("<H", len(f)) + f for f in frames)
        put("codec_frames", s["name"], data)
    for m in vec["malformed"]:
        f = bytes.fromhex(m["frame_hex"])
        put("codec_frames", "malformed-" + m["error"], struct.pack("<HH", m["vertex_count"], len(f)) + f)
    for i in vec["indices"]:
        e = bytes.fromhex(i["encoded_hex"])
        put("codec_indices", i["name"], struct.pack("<HH", i["triangle_count"], i["vertex_count"]) + e)
    # Vertex streams as captures: a Topology then the stream's frames.
    by_count = {i["vertex_count"]: i for i in vec["indices"]}
    for s in vec["streams"]:
        n = s["vertex_count"]
        idx = by_count.get(n)
        tris = idx["triangle_count"] if idx else 0
        enc = bytes.fromhex(idx["encoded_hex"]) if idx else b""
        lo = [float(x) for x in s["box"]["min"]]
        step = [float(x) for x in s["box"]["step"]]
        hi = [a + b * 65535 for a, b in zip(lo, step)]
        topo = (
            field(1, 2, b"fuzz")
            + field(3, 0, n)
            + field(4, 0, tris)
            + field(5, 2, enc)
            + field(6, 2, field(1, 2, vec3(*lo)) + field(2, 2, vec3(*hi)))
            + field(7, 2, b"".join(varint(k) for k in range(n)))
            + field(8, 0, s["box"]["bits"])
        )
        msgs = [field(1, 2, topo)] + [
            frame_message(k, bytes.fromhex(f["frame_hex"])) for k, f in enumerate(s["frames"])
        ]
        put("mesh_stream", "vertices-" + s["name"], capture(msgs))
    pal = json.loads((ROOT / "tests" / "vectors" / "palette-v1.json").read_text())
    msgs = [bytes.fromhex(pal["header_hex"])] + [
        frame_message(k, bytes.fromhex(f["frame_hex"])) for k, f in enumerate(pal["frames"])
    ]
    put("mesh_stream", "palette-v1", capture(msgs))


def control():
    seeds = {
        "three-points": control_frame(positions=[0.1, 0.2, 0.3, 1, 2, 3, -1, 0, 1]),
        "with-mask": control_frame(positions=[0.1, 0.2, 0.3, 1, 2, 3, -1, 0, 1], valid=b"\x05"),
        "nan": control_frame(positions=[float("nan"), 0, 0], valid=b"\x00"),
        "markers": control_frame(markers=[0.0] * 30, markers_valid=b"\xff\x03"),
        "empty": b"",
    }
    for name, frame in seeds.items():
        for sizes in (0x00, 0x12, 0x27, 0xF2):
            put("control_frame", f"{name}-{sizes:02x}", bytes([sizes]) + frame)
    json_seeds = {
        "points": '{"seq": 3, "capture_time_us": 17, "positions": [0.1, 0.2, 0.3]}',
        "mask": '{"seq": 4, "positions": [0,0,0, 1,1,1, 2,2,2], "valid": [true, false, true]}',
        "markers": '{"seq": 5, "markers": [0,0,0,1,1,1,2,2,2], "markers_valid": [true,true,false]}',
        "null": '{"seq": 6, "positions": [null, 1e39, -0.0]}',
        "nested": '{"seq": 1, "positions": [[1,2,3]]}',
    }
    for name, text in json_seeds.items():
        put("json_control", name, text)
    put("control_file", "csv", b"\x04" + b"x0,y0,z0,x1,y1,z1,x2,y2,z2\n0,0,0,1,1,1,2,2,2\n0.5;nan;1;2\t3;4;5;6;7\n")
    put("control_file", "json-points", b"\x05" + b"[[[0,0,0],[1,1,1],null],[[0,0,1],null,[2,2,2]]]")
    put("control_file", "json-flat", b"\x03" + b"[[0,0,0,1,1,1],[1,2,3,4,5,6]]")


def mocap():
    for toml in sorted((ROOT / "bench" / "mocap").glob("*.toml")):
        put("marker_map", toml.name, toml.read_bytes())
    put("marker_map", "small.toml", '[registration]\npoints = ["a", "b", "c"]\n\n[markers]\nc0 = "a"\nc1 = { b = 0.5, c = 0.5 }\nwrist = ["a", "d"]\n')
    tsv = DATA / "mocap" / "qualisys-hand-glove-recording.tsv"
    if tsv.exists():
        lines = tsv.read_text(errors="replace").splitlines(keepends=True)
        head = [l for l in lines[:40] if not l[:1].isdigit() and not l[:1] == "-"]
        body = [l for l in lines[:200] if l[:1].isdigit() or l[:1] == "-"][:40]
        text = "".join(head + body)
        # The header's frame count must match the rows kept.
        text = "\n".join(
            ("NO_OF_FRAMES\t%d" % len(body)) if l.startswith("NO_OF_FRAMES") else l
            for l in text.split("\n")
        )
        put("mocap_tsv", "qualisys-40-frames.tsv", text)
    c3d = DATA / "mocap" / "ART-Human_hands_real_no6dof.c3d"
    if c3d.exists():
        put("mocap_c3d", c3d.name, c3d.read_bytes())
    for name, text in manifests().items():
        put("manifest", name, text)


def manifests():
    return {
        "plain.toml": 'rest = "rest.obj"\nexamples = ["a.obj", "b.obj"]\n',
        "glob.toml": 'rest = "rest.obj"\nexamples = ["*.obj"]\ncontrol_points = [0, 3]\ncontrol_point_names = ["tip", "heel"]\n',
        "detailed.toml": 'rest = "rest.obj"\nexamples = ["[ab].obj"]\ndetailed = "."\n',
    }


def natnet():
    fix = ROOT / "tests" / "fixtures" / "natnet"
    for p in sorted(fix.glob("*.bin")):
        version = {"3.1": 1, "4.1": 3}.get(p.stem.split("-")[-1] if p.stem.startswith(("serverinfo", "modeldef")) else p.stem.split("-")[1], 3)
        put("natnet", p.stem, bytes([version]) + p.read_bytes())


def osc_string(s):
    b = s.encode() + b"\0"
    return b + b"\0" * (-len(b) % 4)


def osc_message(address, *args):
    tags = "," + "".join("s" if isinstance(a, str) else "i" if isinstance(a, int) else "f" for a in args)
    body = b""
    for a in args:
        if isinstance(a, str):
            body += osc_string(a)
        elif isinstance(a, int):
            body += struct.pack(">i", a)
        else:
            body += struct.pack(">f", a)
    return osc_string(address) + osc_string(tags) + body


def osc_bundle(*messages):
    out = osc_string("#bundle") + struct.pack(">Q", 1)
    for m in messages:
        out += struct.pack(">i", len(m)) + m
    return out


def vmc():
    bones = [
        osc_message("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        osc_message("/VMC/Ext/Bone/Pos", "RightHand", 0.3, 1.2, 0.1, 0.0, 0.0, 0.0, 1.0),
        osc_message("/VMC/Ext/Bone/Pos", "RightIndexProximal", 0.05, 0.0, 0.0, 0.0, 0.1, 0.0, 0.995),
        osc_message("/VMC/Ext/Bone/Pos", "RightIndexIntermediate", 0.03, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        osc_message("/VMC/Ext/Bone/Pos", "RightIndexDistal", 0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
        osc_message("/VMC/Ext/Tra/Pos", "tracker-7", 0.3, 1.0, 0.2, 0.0, 0.0, 0.0, 1.0),
        osc_message("/VMC/Ext/OK", 1),
        osc_message("/VMC/Ext/T", 12.5),
    ]
    frame = osc_bundle(*bones)
    datagrams = [frame, osc_bundle(osc_bundle(*bones[:3]), *bones[3:]), bones[1]]
    put("vmc_osc", "frames", b"".join(struct.pack("<H", len(d)) + d for d in datagrams))
    put("vmc_osc", "one", struct.pack("<H", len(frame)) + frame)


def main():
    if not DATA.exists():
        print(f"seed.py: {DATA} is absent: seeds from the shared data are left out", file=sys.stderr)
    meshes()
    models()
    codec()
    control()
    mocap()
    natnet()
    vmc()
    for d in sorted(OUT.iterdir()):
        n = len(list(d.iterdir()))
        print(f"{d.name:16} {n:3} seeds")


if __name__ == "__main__":
    main()
