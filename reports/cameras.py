"""Cameras as the reports and the viewer draw them: pose, intrinsics, group, colour, label; frustum geometry."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from utils.errors import UserError
from utils.io import read_json


@dataclass
class CameraView:
    """One camera to draw. `rotation` is camera-to-world (OpenCV axes: x right, y down, z forward)."""
    name: str
    group: str            # legend entry, e.g. "seed views", "stage 1 picks", "test cameras"
    color: str            # '#rrggbb'
    position: np.ndarray  # camera centre [3]
    rotation: np.ndarray | None  # camera-to-world rotation [3, 3]; None: a marker without a frustum
    fx: float = 0.0
    fy: float = 0.0
    width: int = 0
    height: int = 0
    label: str = ""       # text drawn at the camera (pick number)
    gain: float | None = None  # oracle gain where evaluated
    info: dict = field(default_factory=dict)  # extra hover lines (stage, view id, ...)


def read_cameras_json(path: Path) -> list[dict]:
    """The entries of a 3DGS cameras.json (id, img_name, width, height, position, rotation, fx, fy).

    Raises:
        UserError: a missing or damaged file (not a JSON list) or entries without a pose.
    """
    entries = read_json(path, kind=list, fix="rerun train.py to rewrite it")
    try:
        for e in entries:
            e["position"] = np.asarray(e["position"], dtype=np.float64).reshape(3)
            e["rotation"] = np.asarray(e["rotation"], dtype=np.float64).reshape(3, 3)
    except (ValueError, KeyError, TypeError) as exc:
        raise UserError(f"cannot read {path} ({type(exc).__name__}: {exc}); rerun train.py to rewrite it") from None
    return entries


def camera_from_entry(entry: dict, group: str, color: str, **extra) -> CameraView:
    """A `CameraView` from a cameras.json entry (`read_cameras_json`)."""
    return CameraView(name=str(entry.get("img_name", entry.get("id", ""))), group=group, color=color,
                      position=entry["position"], rotation=entry["rotation"], fx=float(entry["fx"]),
                      fy=float(entry["fy"]), width=int(entry["width"]), height=int(entry["height"]), **extra)


def frustum_corners(cam: CameraView, depth: float) -> np.ndarray:
    """World positions of the image corners at camera depth `depth` (principal point at the image centre). [4, 3]

    Order: top-left, top-right, bottom-right, bottom-left as seen in the image.
    """
    w, h = cam.width / 2.0, cam.height / 2.0
    local = np.array([[-w / cam.fx, -h / cam.fy, 1.0], [w / cam.fx, -h / cam.fy, 1.0],
                      [w / cam.fx, h / cam.fy, 1.0], [-w / cam.fx, h / cam.fy, 1.0]]) * depth  # [4, 3]
    return local @ cam.rotation.T + cam.position


def frustum_segments(cams: list[CameraView], depth: float) -> np.ndarray:
    """Line strips of every frustum (apex to the 4 corners, the image rectangle), NaN rows between strips.

    Returns:
        [12 per camera with a rotation, 3]: per camera the strip apex c0 c1 apex c2 c3 apex c0 c3 c2 c1 (all 8 edges), a NaN row.
    """
    rows = []
    for cam in (c for c in cams if c.rotation is not None and c.fx > 0 and c.fy > 0):
        c = frustum_corners(cam, depth)
        a = cam.position
        rows += [a, c[0], c[1], a, c[2], c[3], a, c[0], c[3], c[2], c[1], [np.nan] * 3]
    return np.asarray(rows, dtype=np.float64).reshape(-1, 3)  # [0, 3] without frusta


def frustum_depth(cams: list[CameraView], center: np.ndarray) -> float:
    """A frustum size that reads well: 12 % of the median camera distance to `center` [3] (1 without cameras)."""
    if not cams:
        return 1.0
    dist = np.linalg.norm(np.stack([c.position for c in cams]) - center, axis=1)
    return float(max(np.median(dist), 1e-6) * 0.12)
