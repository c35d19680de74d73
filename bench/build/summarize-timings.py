#!/usr/bin/env python3
"""Summarises a `cargo build --timings` report (its HTML) as text: the build's wall time, the
CPU time of every unit summed, the workspace's share, the units by CPU time (per crate, every
target), and the last units to finish (the build's tail). Issue 41 commits this text instead of
the HTML.

    python3 bench/build/summarize-timings.py target/cargo-timings/cargo-timing.html [TOP]
"""
import json
import re
import sys


def main() -> None:
    path = sys.argv[1]
    top = int(sys.argv[2]) if len(sys.argv) > 2 else 30
    html = open(path, encoding="utf-8").read()
    match = re.search(r"const UNIT_DATA = (\[.*?\]);\n", html, re.S)
    if match is None:
        sys.exit(f"{path}: no UNIT_DATA (not a cargo --timings report?)")
    units = json.loads(match.group(1))
    wall = max(u["start"] + u["duration"] for u in units)
    total = sum(u["duration"] for u in units)
    ours = [u for u in units if u["name"].startswith("crease")]
    print(f"units {len(units)}; wall {wall:.0f} s; unit times summed {total:.0f} s "
          f"(parallelism {total / wall:.2f})")
    print(f"workspace crates: {sum(u['duration'] for u in ours):.0f} s of it")
    print()
    print("| unit time, s | share | crate |")
    print("|---:|---:|---|")
    by_crate: dict[str, float] = {}
    for u in units:
        by_crate[u["name"]] = by_crate.get(u["name"], 0.0) + u["duration"]
    for name, seconds in sorted(by_crate.items(), key=lambda kv: -kv[1])[:top]:
        print(f"| {seconds:.1f} | {100 * seconds / total:.1f}% | {name} |")
    print()
    print("The workspace's units (start, time, and for a library its front end / code generation):")
    print()
    print("| start, s | time, s | front end / codegen, s | unit |")
    print("|---:|---:|---|---|")
    for u in sorted(ours, key=lambda u: u["start"]):
        sections = dict((k, v["end"] - v["start"]) for k, v in (u.get("sections") or []))
        split = (f"{sections['frontend']:.1f} / {sections['codegen']:.1f}"
                 if "frontend" in sections and "codegen" in sections else "")
        target = u["target"].strip() or "lib"
        print(f"| {u['start']:.0f} | {u['duration']:.1f} | {split} | {u['name']} {target} |")


if __name__ == "__main__":
    main()
