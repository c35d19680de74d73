"""Decodes the NatNet fixtures (tests/fixtures/natnet/*.bin) with NaturalPoint's own sample
decoder (PyPI natnetsdk 4.1.1, NatNetClient.py) and prints what it read as JSON, for
bridge/tests/natnet.rs to compare with crease's decoder.

Usage: python natnet_reference.py FIXTURE_DIR > reference.json

The sample's unpacking functions are private methods of NatNetClient; they are called on the
fixture bytes directly (no sockets). A file's NatNet version is in its name (frame-4.1-0.bin).
"""

import contextlib
import io
import json
import pathlib
import re
import sys

from natnetsdk.NatNetClient import NatNetClient


def f(x):
    return float(x)


def vec(v):
    return [f(c) for c in v]


def frame(client, data, major, minor):
    size = int.from_bytes(data[2:4], "little")
    _, m = client._NatNetClient__unpack_mocap_data(data[4:], size, major, minor)
    out = {
        "frame_number": m.prefix_data.frame_number,
        "marker_sets": [
            {"name": d.model_name.decode("utf-8"), "markers": [vec(p) for p in d.marker_pos_list]}
            for d in m.marker_set_data.marker_data_list
        ],
        "other_markers": [vec(p) for p in m.legacy_other_markers.marker_pos_list],
        "rigid_bodies": [
            {
                "id": b.id_num,
                "position": vec(b.pos),
                "orientation": vec(b.rot),
                "mean_error": f(b.error),
                "tracking_valid": bool(b.tracking_valid),
            }
            for b in m.rigid_body_data.rigid_body_list
        ],
        "skeletons": [
            {"id": s.id_num, "bones": [b.id_num for b in s.rigid_body_list]}
            for s in m.skeleton_data.skeleton_list
        ],
        "labeled_markers": [
            {
                "id": lm.id_num,
                "model_id": lm.id_num >> 16,
                "marker_id": lm.id_num & 0xFFFF,
                "position": vec(lm.pos),
                "size": f(lm.size),
                "params": lm.param & 0xFFFF,
                "occluded": bool(lm.param & 0x01),
                # The sample scales the residual to mm.
                "residual_mm": f(lm.residual),
            }
            for lm in m.labeled_marker_data.labeled_marker_list
        ],
        "force_plates": [
            {"id": p.id_num, "channels": [[f(v[0]) for v in c.frame_list] for c in p.channel_data_list]}
            for p in m.force_plate_data.force_plate_list
        ],
        "devices": [
            {"id": d.id_num, "channels": [[f(v[0]) for v in c.frame_list] for c in d.channel_data_list]}
            for d in m.device_data.device_list
        ],
        "timecode": m.suffix_data.timecode,
        "timecode_sub": m.suffix_data.timecode_sub,
        "timestamp": f(m.suffix_data.timestamp),
        "camera_mid_exposure": m.suffix_data.stamp_camera_mid_exposure,
        "camera_data_received": m.suffix_data.stamp_data_received,
        "transmit": m.suffix_data.stamp_transmit,
        "params": m.suffix_data.param & 0xFFFF,
    }
    if m.asset_data is not None:
        out["assets"] = len(m.asset_data.asset_list)
    return out


def descriptions(client, data, major, minor):
    size = int.from_bytes(data[2:4], "little")
    _, d = client._NatNetClient__unpack_data_descriptions(data[4:], size, major, minor)
    return {
        "marker_sets": [
            {"name": s.marker_set_name.decode("utf-8"), "markers": [n.decode("utf-8") for n in s.marker_names_list]}
            for s in d.marker_set_list
        ],
        "rigid_bodies": [
            {
                "name": b.sz_name.decode("utf-8"),
                "id": b.id_num,
                "parent_id": b.parent_id,
                "markers": [m.marker_name for m in b.rb_marker_list],
            }
            for b in d.rigid_body_list
        ],
    }


def server_info(client, data):
    size = int.from_bytes(data[2:4], "little")
    client._NatNetClient__unpack_server_info(data[4:], size, 0, 0)
    return {
        "name": client.get_application_name(),
        "natnet": list(client.get_nat_net_version_server()),
        "app_version": list(client.get_server_version()),
    }


def main():
    folder = pathlib.Path(sys.argv[1])
    out = {}
    for path in sorted(folder.glob("*.bin")):
        data = path.read_bytes()
        m = re.search(r"-(\d+)\.(\d+)", path.name)
        major, minor = int(m.group(1)), int(m.group(2))
        client = NatNetClient()
        # The sample prints as it decodes: keep stdout for the JSON.
        with contextlib.redirect_stdout(io.StringIO()):
            if path.name.startswith("frame-"):
                out[path.name] = frame(client, data, major, minor)
            elif path.name.startswith("modeldef-"):
                out[path.name] = descriptions(client, data, major, minor)
            elif path.name.startswith("serverinfo-"):
                out[path.name] = server_info(client, data)
    json.dump(out, sys.stdout, indent=1, sort_keys=True)
    print()


if __name__ == "__main__":
    main()
