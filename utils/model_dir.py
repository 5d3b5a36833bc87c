"""The file names of a model directory (what train.py, render.py and metrics.py write there), known only here.

    <model>/cfg_args                                  the run's config (JSON), written first
    <model>/run_status.json                           running / complete, progress while training
    <model>/cameras.json                              every camera of the run
    <model>/input.ply                                 the initial Gaussians
    <model>/selection.json                            active runs: every acquisition stage
    <model>/point_cloud/iteration_N/point_cloud.ply   the trained Gaussians
    <model>/checkpoints/chkpnt_NNNNNNN.pt             the resumable checkpoints
    <model>/{train,test}/ours_N/                      render.py's images (renders/, gt/)
    <model>/results.json, per_view.json               metrics.py's tables
    <model>/.lock                                     while a writer runs: its pid and command (utils/dir_lock.py)
"""
from __future__ import annotations

import re
from pathlib import Path

CFG_ARGS = "cfg_args"
RUN_STATUS = "run_status.json"
CAMERAS = "cameras.json"
INPUT_PLY = "input.ply"
SELECTION = "selection.json"
RESULTS = "results.json"
PER_VIEW = "per_view.json"
POINT_CLOUD_DIR = "point_cloud"
CHECKPOINTS_DIR = "checkpoints"
POINT_CLOUD_PLY = "point_cloud.ply"  # in point_cloud/iteration_N/
LOCK_FILE = ".lock"  # the writer lock of a model directory (utils/dir_lock.py); deleted when its writer ends
METHOD_PATTERN = re.compile(r"ours_(\d+)")  # `method_name`: render folders and results.json keys


def folder_lock_file(folder: Path) -> Path:
    """The writer lock of a folder that is replaced whole (recommend.py's output): `.NAME.lock` beside it."""
    folder = Path(folder)
    return folder.parent / f".{folder.name}{LOCK_FILE}"


def iteration_dir_name(iteration: int) -> str:
    """point_cloud/<this>: iteration_N."""
    return f"iteration_{iteration}"


def point_cloud_ply(model_dir: Path, iteration: int) -> Path:
    """<model>/point_cloud/iteration_N/point_cloud.ply."""
    return Path(model_dir) / POINT_CLOUD_DIR / iteration_dir_name(iteration) / POINT_CLOUD_PLY


def checkpoint_file(model_dir: Path, iteration: int) -> Path:
    """<model>/checkpoints/chkpnt_NNNNNNN.pt (zero-padded, so names sort by iteration)."""
    return Path(model_dir) / CHECKPOINTS_DIR / f"chkpnt_{iteration:07d}.pt"


def method_name(iteration: int) -> str:
    """ours_N: the folder of render.py's images at iteration N and its key in results.json / per_view.json."""
    return f"ours_{iteration}"


def render_dir(model_dir: Path, split: str, iteration: int) -> Path:
    """<model>/<split>/ours_N: render.py's images of one split at one iteration."""
    return Path(model_dir) / split / method_name(iteration)

# render.py --uncertainty_kind: one folder `uncertainty/KIND/` per kind -> what the map shows (colour bar label)
UNCERTAINTY_KINDS = {  # --uncertainty_kind -> what the map shows (the colour bar's label)
    "position_variance": "positional variance",
    "fisherrf": "FisherRF colour information x depth (training views)",
    "fisherrf_view": "FisherRF information x depth (the view itself)",
}
