"""Shared fixtures of the scarp Python tests."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Optional

import numpy as np
import pytest

#: The repository root (python/tests/ → ../..).
REPO = Path(__file__).resolve().parents[2]
#: Real RGB-D fixtures beside the repository (never copied into it); absent on some machines.
SHARED_REAL = REPO.parent / "shared" / "data" / "real"


def scarp_binary() -> Optional[Path]:
    """The `scarp` CLI: $SCARP_BIN, else target/{release,debug}/scarp, else one on PATH."""
    env = os.environ.get("SCARP_BIN")
    if env:
        return Path(env)
    for profile in ("release", "debug"):
        candidate = REPO / "target" / profile / "scarp"
        if candidate.is_file():
            return candidate
    found = shutil.which("scarp")
    return Path(found) if found else None


def box_mesh(sx: float, sy: float, sz: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed box centred on the z axis, standing on z = 0, faces wound outwards."""
    x, y = sx / 2, sy / 2
    v = np.array(
        [[-x, -y, 0], [x, -y, 0], [x, y, 0], [-x, y, 0], [-x, -y, sz], [x, -y, sz], [x, y, sz], [-x, y, sz]],
        dtype=np.float64,
    )
    t = np.array(
        [
            [0, 2, 1], [0, 3, 2],  # bottom (normal −z)
            [4, 5, 6], [4, 6, 7],  # top (+z)
            [0, 1, 5], [0, 5, 4],  # −y
            [1, 2, 6], [1, 6, 5],  # +x
            [2, 3, 7], [2, 7, 6],  # +y
            [3, 0, 4], [3, 4, 7],  # −x
        ],
        dtype=np.int64,
    )
    return v, t


@pytest.fixture
def plane_frames():
    """Three 160×120 frames (f = 100 px) of a fronto-parallel plane 2 m ahead of cameras moved
    sideways by −5, 0, +5 cm: (depth, color, world_from_camera) triples."""
    h, w = 120, 160
    frames = []
    for i, dx in enumerate((-0.05, 0.0, 0.05)):
        pose = np.eye(4)
        pose[0, 3] = dx
        depth = np.full((h, w), 2.0, np.float32)
        # A checkerboard texture, shifted with the camera, so colours are not all alike.
        u = np.arange(w)[None, :] + int(round(dx * 100 / 2.0))
        v = np.arange(h)[:, None]
        checker = (((u // 8) + (v // 8)) % 2).astype(np.uint8)
        color = np.stack([checker * 200 + 20, np.full((h, w), 90, np.uint8), 255 - checker * 200], axis=-1)
        frames.append((depth, np.ascontiguousarray(color, dtype=np.uint8), pose))
    return frames
