"""Everything a run report shows, read from a model directory (no HTML here).

A model directory (train.py / render.py / metrics.py) holds cfg_args, cameras.json, selection.json (active runs),
run_status.json, point_cloud/iteration_N/point_cloud.ply, test/ours_N/{renders,gt}, test/ours_N/uncertainty/KIND/
(render.py --uncertainty: NNNNN.png maps and colorbar.png per map kind), results.json and per_view.json. Whatever is absent is listed in `RunData.absent` and the report says so.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from reports import colors
from reports.cameras import CameraView, camera_from_entry, read_cameras_json
from utils.errors import UserError
from utils.io import read_json
from utils.model_dir import (CAMERAS, CFG_ARGS, INPUT_PLY, PER_VIEW, POINT_CLOUD_DIR, POINT_CLOUD_PLY, RESULTS, RUN_STATUS,
                             SELECTION)

MAX_POINTS = 4000      # Gaussian centres drawn (uniform subsample of the opaque ones)
MAX_GALLERY = 24       # test views in the gallery (evenly spaced when there are more)
C0 = 0.28209479177387814  # SH degree-0 constant: rgb = C0 * f_dc + 0.5
_ITER = re.compile(r"(?:iteration|ours)_(\d+)")


@dataclass
class GalleryItem:
    """One test view: file paths of ground truth, render and (render.py --uncertainty) uncertainty maps."""
    name: str
    gt: Path
    render: Path
    uncertainty: dict[str, Path | None]  # map kind -> its PNG of this view (None: not written)
    psnr: float | None


@dataclass
class RunData:
    """What a run report draws; fields are None / empty where the model directory lacks the file."""
    model_dir: Path
    cfg: dict[str, Any] | None
    selection: dict[str, Any] | None
    status: dict[str, Any] | None
    results: dict[str, Any] | None      # the last ours_N entry of results.json
    method_key: str | None              # that ours_N
    cameras: list[CameraView]
    points: np.ndarray                  # Gaussian centres [M, 3]
    point_colors: np.ndarray            # [M, 3] uint8
    points_note: str
    gallery: list[GalleryItem]
    gallery_note: str
    colorbars: dict[str, Path | None]   # map kind -> its colour bar (render.py --uncertainty), kinds in gallery order
    absent: list[str] = field(default_factory=list)
    incomplete: str | None = None

    @property
    def stages(self) -> list[dict[str, Any]]:
        """selection.json's stage records (empty without selection.json)."""
        return list((self.selection or {}).get("stages", []))

    def psnr_curve(self) -> list[tuple[int, float, str]]:
        """(number of training views, test PSNR, where measured) per stage, then the final value."""
        points = [(len(s["train_views"]), float(s["test_psnr"]), f"stage {s['stage']} (train.py)")
                  for s in self.stages if s.get("test_psnr") is not None]
        final = (self.selection or {}).get("final")
        views = len(final["train_views"]) if final else None
        if views is None and self.status and self.status.get("train_views") is not None:
            views = len(self.status["train_views"])
        if views is None and self.cfg and not self.selection:
            views = self.cfg.get("dataset", {}).get("num_train")
        if self.results is not None and views is not None:
            points.append((views, float(self.results["PSNR"]), f"final ({self.method_key}, metrics.py)"))
        elif final and final.get("test_psnr") is not None:
            points.append((views, float(final["test_psnr"]), "final (train.py)"))
        return points


def latest(paths: list[Path]) -> Path | None:
    """The path whose name carries the largest iteration number (iteration_N / ours_N), None if none."""
    numbered = [(int(m.group(1)), p) for p in paths if (m := _ITER.fullmatch(p.name))]
    return max(numbered)[1] if numbered else None


def run_cameras(entries: list[dict], num_test: int, selection: dict | None) -> list[CameraView]:
    """Group the cameras.json entries (test cameras first, then training view v at index num_test + v).

    With selection.json: seed views, each stage's picks numbered in pick order (coloured by stage), the candidates
    never picked; without: every training view as one group.
    """
    test = [camera_from_entry(e, "test cameras", colors.TEST) for e in entries[:num_test]]
    train = entries[num_test:]
    if not train:  # no cameras.json (or no training views in it): nothing to draw
        return test
    named = [v for s in (selection or {}).get("stages", []) for v in s["train_views"] + s["selected"]]
    if named and max(named) >= len(train):
        raise UserError(f"{SELECTION} names training view {max(named)} but {CAMERAS} has {len(train)} "
                        "training views; the files are from different runs")
    if not selection or not selection.get("stages"):
        return test + [camera_from_entry(e, "training views", colors.TRAIN, info={"view": v})
                       for v, e in enumerate(train)]
    stages = selection["stages"]
    cams, used, pick = [], set(), 0
    for v in stages[0]["train_views"]:
        cams.append(camera_from_entry(train[v], "seed views", colors.SEED, info={"view": v}))
        used.add(v)
    for s in stages:
        for v, gain in zip(s["selected"], s.get("gains", [None] * len(s["selected"]))):
            pick += 1
            cams.append(camera_from_entry(train[v], f"stage {s['stage']} picks", colors.stage_color(s["stage"]),
                                          label=str(pick), gain=gain,
                                          info={"view": v, "pick": pick, "stage": s["stage"]}))
            used.add(v)
    cams += [camera_from_entry(e, "candidates not picked", colors.CANDIDATE, info={"view": v})
             for v, e in enumerate(train) if v not in used]
    return test + cams


def gaussian_points(ply: Path, max_points: int = MAX_POINTS, seed: int = 0) -> tuple[np.ndarray, np.ndarray, int]:
    """Subsampled centres and degree-0 colours of a 3DGS PLY: the Gaussians with opacity >= 0.1 (all when none
    are), far outliers (beyond 3x the 95th-percentile distance from the median) dropped.

    Returns:
        (xyz [M, 3] float32, rgb [M, 3] uint8, number of Gaussians in the file)
    """
    from plyfile import PlyData  # plyfile reads only the columns used here

    try:
        vertex = PlyData.read(str(ply))["vertex"]
        xyz = np.stack([np.asarray(vertex[k], dtype=np.float32) for k in ("x", "y", "z")], axis=1)
        names = {p.name for p in vertex.properties}
        if {"f_dc_0", "f_dc_1", "f_dc_2"} <= names:
            dc = np.stack([np.asarray(vertex[f"f_dc_{i}"], dtype=np.float32) for i in range(3)], axis=1)
            rgb = np.clip(C0 * dc + 0.5, 0.0, 1.0)
        else:  # SfM / input points: red green blue bytes
            rgb = np.stack([np.asarray(vertex[k], dtype=np.float32) for k in ("red", "green", "blue")], 1) / 255
        opacity = (1 / (1 + np.exp(-np.asarray(vertex["opacity"], dtype=np.float32)))
                   if "opacity" in names else np.ones(len(xyz), np.float32))
    except (OSError, ValueError, KeyError, IndexError) as exc:
        raise UserError(f"cannot read {ply} ({type(exc).__name__}: {exc}); the file is damaged") from None
    keep = np.flatnonzero((opacity >= 0.1) & np.isfinite(xyz).all(axis=1))
    if not len(keep):
        keep = np.flatnonzero(np.isfinite(xyz).all(axis=1))
    dist = np.linalg.norm(xyz[keep] - np.median(xyz[keep], axis=0), axis=1) if len(keep) else np.zeros(0)
    if len(keep):
        keep = keep[dist <= 3 * np.percentile(dist, 95) + 1e-9]
    if len(keep) > max_points:
        keep = np.sort(np.random.default_rng(seed).choice(keep, max_points, replace=False))
    return xyz[keep], (rgb[keep] * 255 + 0.5).astype(np.uint8), len(xyz)


def uncertainty_kinds(method_dir: Path) -> list[str]:
    """The map kinds render.py --uncertainty wrote: the folders of `method_dir/uncertainty/` holding PNG maps
    (object_mask/ is the metrics' region, not a map), sorted by name."""
    folder = method_dir / "uncertainty"
    return sorted(d.name for d in folder.glob("*") if d.is_dir() and d.name != "object_mask" and any(d.glob("*.png")))


def uncertainty_keys(results: dict[str, Any] | None) -> list[tuple[str, str, str, float]]:
    """(metric, kind, region, value) of the METRIC/KIND/REGION keys of a results.json entry, in its order."""
    return [(*key.split("/"), float(v)) for key, v in (results or {}).items()
            if key.count("/") == 2 and isinstance(v, (int, float))]


def gallery_items(method_dir: Path, per_view: dict | None, kinds: list[str],
                  limit: int = MAX_GALLERY) -> list[GalleryItem]:
    """The rendered test views of test/ours_N (evenly spaced subset of at most `limit`) with the maps of `kinds`."""
    names = sorted(p.name for p in (method_dir / "renders").glob("*.png") if (method_dir / "gt" / p.name).is_file())
    if len(names) > limit:
        names = [names[i] for i in np.linspace(0, len(names) - 1, limit).round().astype(int)]
    psnr = (per_view or {}).get("PSNR", {})
    items = []
    for n in names:
        maps = {k: method_dir / "uncertainty" / k / n for k in kinds}
        items.append(GalleryItem(n, method_dir / "gt" / n, method_dir / "renders" / n,
                                 {k: p if p.is_file() else None for k, p in maps.items()}, psnr.get(n)))
    return items


def gather_run(model_dir: str | Path) -> RunData:
    """Read a model directory for `reports.run_report`.

    Raises:
        UserError: not a model directory (no cfg_args and no cameras.json), damaged JSON or PLY.
    """
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise UserError(f"{model_dir} is not a directory; pass -m MODEL_DIR written by train.py")
    cfg = read_json(model_dir / CFG_ARGS, missing="none")
    cam_entries = read_cameras_json(model_dir / CAMERAS) if (model_dir / CAMERAS).is_file() else None
    if cfg is None and cam_entries is None:
        raise UserError(f"{model_dir} holds neither {CFG_ARGS} nor {CAMERAS}, so it is not a model directory "
                        "written by train.py; pass -m MODEL_DIR")
    absent: list[str] = []
    if cfg is None:
        absent.append(f"{CFG_ARGS} (the run's settings)")
    selection = read_json(model_dir / SELECTION, missing="none")
    if selection is None:
        absent.append(f"{SELECTION} (no active selection: a run trained on all its views, or a run stopped "
                      "before its first acquisition)")
    status = read_json(model_dir / RUN_STATUS, missing="none")
    num_test = int((cfg or {}).get("dataset", {}).get("num_test", 0))
    if cam_entries is None:
        absent.append(f"{CAMERAS} (no cameras drawn)")
    cameras = run_cameras(cam_entries or [], num_test, selection)

    ply = latest([p for p in (model_dir / POINT_CLOUD_DIR).glob("iteration_*") if (p / POINT_CLOUD_PLY).is_file()])
    if ply is not None:
        xyz, rgb, n = gaussian_points(ply / POINT_CLOUD_PLY)
        note = f"{len(xyz)} of {n} Gaussian centres ({ply.name}), colours from SH degree 0"
    elif (model_dir / INPUT_PLY).is_file():
        xyz, rgb, n = gaussian_points(model_dir / INPUT_PLY)
        note = f"{len(xyz)} of {n} initial points ({INPUT_PLY}): no trained Gaussians were saved"
        absent.append(f"{POINT_CLOUD_DIR}/iteration_N/{POINT_CLOUD_PLY} (trained Gaussians)")
    else:
        xyz, rgb, note = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), "no points"
        absent.append(f"{POINT_CLOUD_DIR}/ and {INPUT_PLY} (no points drawn)")

    results_all = read_json(model_dir / RESULTS, missing="none")
    per_view_all = read_json(model_dir / PER_VIEW, missing="none") or {}
    method_dir = latest([d for d in (model_dir / "test").glob("ours_*") if (d / "renders").is_dir()])
    method_key = method_dir.name if method_dir is not None else None
    results = None
    if results_all:
        key = method_key if method_key in results_all else latest([Path(k) for k in results_all]).name
        method_key, results = key, results_all[key]
    else:
        absent.append(f"{RESULTS} (run metrics.py -m MODEL_DIR for PSNR / SSIM / LPIPS)")
    gallery, colorbars = [], {}
    if method_dir is None:
        absent.append("test/ours_N/renders (run render.py -m MODEL_DIR for the gallery)")
        gallery_note = ""
    else:
        kinds = uncertainty_kinds(method_dir)
        gallery = gallery_items(method_dir, per_view_all.get(method_dir.name), kinds)
        total = len(list((method_dir / "renders").glob("*.png")))
        gallery_note = f"{len(gallery)} of {total} test views ({method_dir.name})"
        if not kinds:
            absent.append("uncertainty maps (render.py --uncertainty writes them)")
        colorbars = {k: cb if (cb := method_dir / "uncertainty" / k / "colorbar.png").is_file() else None
                     for k in kinds}

    incomplete = None
    if status is None:
        incomplete = f"{RUN_STATUS} is absent: the run may not have started or finished"
    elif status.get("status") != "complete":
        done = status.get("iteration")
        total = status.get("total_iterations", (cfg or {}).get("total_iterations"))
        incomplete = (f"incomplete: {RUN_STATUS} says '{status.get('status')}'"
                      + (f" at iteration {done} of {total}" if done is not None else "")
                      + f"; this report shows what finished ({len((selection or {}).get('stages', []))} "
                        "acquisition stages recorded)")
    return RunData(model_dir, cfg, selection, status, results, method_key, cameras, xyz, rgb, note, gallery,
                   gallery_note, colorbars, absent, incomplete)
