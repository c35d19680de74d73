"""Control-frame files as arrays: the CSV ``crease retarget`` writes and ``crease synth`` reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_controls_csv(path: str | Path) -> np.ndarray:
    """An ``(F, C, 3)`` float32 array from a control-frame CSV: one frame per line, ``x, y, z`` of
    every control point in model order; an empty or ``nan`` field marks an occluded point (NaN
    here, which ``Client.publish`` and ``Client.synthesize`` send as not seen); ``#`` comments and
    a header line are skipped."""
    rows: list[list[float]] = []
    for n, line in enumerate(Path(path).read_text().splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")]
        try:
            values = [float(f) if f else float("nan") for f in fields]
        except ValueError:
            if not rows:
                continue  # a header line
            raise ValueError(f"{path}:{n}: not a number in {line[:60]!r}") from None
        if len(values) % 3:
            raise ValueError(f"{path}:{n}: {len(values)} values, expected x, y, z per control point")
        if rows and len(values) != len(rows[0]):
            raise ValueError(f"{path}:{n}: {len(values) // 3} control points, the first frame has {len(rows[0]) // 3}")
        rows.append(values)
    if not rows:
        raise ValueError(f"{path}: no control frames")
    return np.array(rows, dtype=np.float32).reshape(len(rows), -1, 3)
