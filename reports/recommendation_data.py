"""A recommend.py output folder (recommendations.json, previews/), read for the recommendation report.

Fields read (docs/reports.md; every one optional except `picks`):
    picks[]            rank, name, candidate, gain, c2w (4x4 OpenCV camera-to-world; or w2c), fx, fy, width, height,
                       preview, uncertainty_map (image paths relative to the folder)
    candidate_gains[]  candidate, name, gain (null: not evaluated), rank (null: not picked), position [3] (or a
                       c2w/w2c pose with fx, fy, width, height for a frustum)
    captured[]         name, c2w/w2c, fx, fy, width, height; without it: prior.view_ids and the model directory's
                       cameras.json (`model`)
    model              the model directory or PLY (its Gaussians are drawn)
    oracle_calls {conservative, evaluated}, fisher_views_computed, seconds {...}, selector, selector_options, k,
    k_taken, settings {...}, notes [...]
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from reports import colors
from reports.cameras import CameraView, camera_from_entry, read_cameras_json
from reports.run_data import gaussian_points, latest
from utils.errors import UserError
from utils.io import read_json
from utils.model_dir import CAMERAS, CFG_ARGS, POINT_CLOUD_DIR, POINT_CLOUD_PLY

FILE = "recommendations.json"


@dataclass
class RecommendationData:
    """What the recommendation report draws."""
    folder: Path
    record: dict[str, Any]
    cameras: list[CameraView]
    points: np.ndarray        # [M, 3]
    point_colors: np.ndarray  # [M, 3] uint8
    points_note: str
    previews: list[tuple[int, Path | None, Path | None]]  # (rank, preview, uncertainty map)
    absent: list[str]


def pose_camera(entry: dict[str, Any], group: str, color: str, **extra) -> CameraView:
    """A camera from a record with a c2w or w2c 4x4 pose (OpenCV axes) or only a `position` [3].

    Raises:
        UserError: the entry has neither a pose nor a position.
    """
    if "c2w" in entry or "w2c" in entry:
        c2w = np.asarray(entry["c2w"] if "c2w" in entry else np.linalg.inv(np.asarray(entry["w2c"], np.float64)),
                         np.float64).reshape(4, 4)
        position, rotation = c2w[:3, 3], c2w[:3, :3]
    elif "position" in entry:
        position, rotation = np.asarray(entry["position"], np.float64).reshape(3), None
    else:
        raise UserError(f"{FILE}: entry {entry.get('name', entry.get('candidate', '?'))} has no c2w, w2c or "
                        "position; regenerate it with recommend.py")
    return CameraView(name=str(entry.get("name", entry.get("candidate", ""))), group=group, color=color,
                      position=position, rotation=rotation, fx=float(entry.get("fx", 0.0)),
                      fy=float(entry.get("fy", 0.0)), width=int(entry.get("width", 0)),
                      height=int(entry.get("height", 0)), **extra)


def captured_cameras(record: dict[str, Any], absent: list[str]) -> list[CameraView]:
    """`captured[]` when recorded, else the prior views of the model directory's cameras.json."""
    if record.get("captured"):
        return [pose_camera(e, "captured views", colors.SEED) for e in record["captured"]]
    model = Path(str(record.get("model", "")))
    ids = (record.get("prior") or {}).get("view_ids")
    if ids and (model / CAMERAS).is_file():
        num_test = int(((read_json(model / CFG_ARGS, missing="none") or {}).get("dataset") or {}).get("num_test", 0))
        entries = read_cameras_json(model / CAMERAS)
        return [camera_from_entry(entries[num_test + v], "captured views", colors.SEED, info={"view": v})
                for v in ids if num_test + v < len(entries)]
    absent.append(f"captured camera poses (neither captured[] nor a model directory with {CAMERAS})")
    return []


def model_points(record: dict[str, Any], absent: list[str]) -> tuple[np.ndarray, np.ndarray, str]:
    """Subsampled Gaussian centres of the recommended-on model (a model directory's last PLY, or a PLY file)."""
    model = Path(str(record.get("model", "")))
    ply = None
    if model.is_file():
        ply = model
    elif model.is_dir():
        it = latest([p for p in (model / POINT_CLOUD_DIR).glob("iteration_*") if (p / POINT_CLOUD_PLY).is_file()])
        ply = it / POINT_CLOUD_PLY if it is not None else None
    if ply is None:
        absent.append(f"the model's Gaussians ({record.get('model', 'no model path recorded')} is not readable here)")
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), "no points"
    xyz, rgb, n = gaussian_points(ply)
    return xyz, rgb, f"{len(xyz)} of {n} Gaussian centres ({ply})"


def gather_recommendation(folder: str | Path) -> RecommendationData:
    """Read a recommend.py output folder.

    Raises:
        UserError: no recommendations.json, damaged JSON, or picks without poses.
    """
    folder = Path(folder)
    record = read_json(folder / FILE, missing="none")
    if not isinstance(record, dict) or not isinstance(record.get("picks"), list):
        raise UserError(f"{folder / FILE} is absent or has no 'picks' list; pass an output folder of recommend.py")
    absent: list[str] = []
    cams = captured_cameras(record, absent)
    picked = set()
    for p in sorted(record["picks"], key=lambda p: p.get("rank", 0)):
        rank = p.get("rank")
        cams.append(pose_camera(p, "picks", colors.stage_color(2), label=str(rank), gain=p.get("gain"),
                                info={"rank": rank, "candidate": p.get("candidate")}))
        picked.add(p.get("candidate", p.get("name")))
    for c in record.get("candidate_gains", []):
        if c.get("rank") is not None or c.get("candidate", c.get("name")) in picked:
            continue
        evaluated = c.get("gain") is not None
        cams.append(pose_camera(c, "candidates (by gain)" if evaluated else "candidates not evaluated",
                                colors.CANDIDATE, gain=c.get("gain"), info={"candidate": c.get("candidate")}))
    xyz, rgb, note = model_points(record, absent)
    previews = []
    for p in record["picks"]:
        files = [folder / p[k] if p.get(k) and (folder / p[k]).is_file() else None
                 for k in ("preview", "uncertainty_map")]
        previews.append((p.get("rank"), *files))
    if not any(f for _, *fs in previews for f in fs):
        absent.append("previews (no preview PNGs in the folder)")
    return RecommendationData(folder, record, cams, xyz, rgb, note, previews, absent)
