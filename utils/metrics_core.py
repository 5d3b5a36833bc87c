"""The pieces of metrics.py: finding rendered test views, per-view PSNR / SSIM / LPIPS, means in the 3DGS format.

A model directory holds `test/ours_N/{renders,gt}/*.png` (written by render.py); each `ours_N` is one "method"
(the Gaussians of iteration N). Images are read as 3DGS does: the first three channels of the PNG, in [0, 1].
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from utils.errors import UserError
from utils.image import load_rgba
from utils.losses import psnr, ssim
from utils.lpips_loader import LPIPS_MIN_SIDE, lpips_distance
from utils.model_dir import METHOD_PATTERN
from utils.uncertainty_metrics import ause, spearman

log = logging.getLogger(__name__)

LOOKED_FOR = "test/ours_N/renders/*.png"


def method_dirs(model_dir: Path) -> list[Path]:
    """The `test/ours_N` directories of a model directory that hold rendered PNGs, by increasing N."""
    found = [d for d in (model_dir / "test").glob("ours_*")
             if METHOD_PATTERN.fullmatch(d.name) and any((d / "renders").glob("*.png"))]
    return sorted(found, key=lambda d: int(METHOD_PATTERN.fullmatch(d.name).group(1)))


def find_model_dirs(roots: list[str | Path]) -> list[Path]:
    """Model directories holding `test/ours_N/renders/*.png`, searched recursively under each root.

    Raises:
        UserError: a root does not exist, or no such model directory is found.
    """
    found: dict[Path, Path] = {}  # resolved -> as reached from the given root
    for root in map(Path, roots):
        if not root.exists():
            raise UserError(f"{root} does not exist; pass model directories written by train.py and render.py")
        candidates = [root] if root.is_dir() else []
        candidates += [t.parent for t in root.rglob("test") if t.is_dir()]
        found.update((d.resolve(), d) for d in candidates if method_dirs(d))
    if not found:
        raise UserError(f"no rendered test views under {', '.join(map(str, roots))} (looked for {LOOKED_FOR}); "
                        "run render.py -m MODEL first (train with --eval so there is a test split)")
    return [found[k] for k in sorted(found)]


def view_names(method_dir: Path) -> list[str]:
    """The PNG names shared by `renders/` and `gt/`, sorted.

    Raises:
        UserError: the two folders hold different file names.
    """
    renders = {p.name for p in (method_dir / "renders").glob("*.png")}
    gts = {p.name for p in (method_dir / "gt").glob("*.png")}
    if renders != gts:
        only = sorted(renders - gts)[:1] or sorted(gts - renders)[:1]
        where = "renders/" if only[0] in renders else "gt/"
        raise UserError(f"{method_dir}: renders/ has {len(renders)} PNGs and gt/ {len(gts)}, {only[0]} only in "
                        f"{where}; rerun render.py for this model")
    return sorted(renders)


def read_rgb(path: Path) -> torch.Tensor:
    """The first three channels of an image file, float32 in [0, 1] (as 3DGS reads renders). [3, H, W]"""
    return load_rgba(path)[:3]


@dataclass
class Lpips:
    """A loaded LPIPS network and its variant name (see utils.lpips_loader.load_lpips)."""
    model: torch.nn.Module
    variant: str


@torch.no_grad()
def evaluate_views(method_dir: Path, lpips: Lpips | None, device: str | torch.device = "cpu",
                   quiet: bool = False) -> dict[str, dict[str, float | None]]:
    """Per-view metrics of one `test/ours_N` directory: {"SSIM": {name: v}, "PSNR": {...}, "LPIPS": {...}}, plus
    "Spearman" and "AUSE" (uncertainty vs per-pixel error, `uncertainty_scores`) when render.py --uncertainty wrote
    `uncertainty/*.npy`.

    LPIPS values are None without a network, or for images smaller than its backbone accepts (logged once).

    Raises:
        UserError: renders/ and gt/ differ in file names or in the size of an image; an uncertainty map is missing
            or of another size.
    """
    per_view: dict[str, dict[str, float | None]] = {"SSIM": {}, "PSNR": {}, "LPIPS": {}}
    with_uncertainty = (method_dir / "uncertainty").is_dir()
    if with_uncertainty:
        per_view.update({"Spearman": {}, "AUSE": {}})
    too_small = False
    names = view_names(method_dir)
    label = f"{method_dir.parent.parent.name}/{method_dir.name}"
    for name in tqdm(names, desc=f"metrics {label}", unit="view", disable=quiet):
        render = read_rgb(method_dir / "renders" / name).to(device)  # [3, H, W]
        gt = read_rgb(method_dir / "gt" / name).to(device)  # [3, H, W]
        if render.shape != gt.shape:
            raise UserError(f"{method_dir}: renders/{name} is {render.shape[2]}x{render.shape[1]} px but gt/{name} "
                            f"is {gt.shape[2]}x{gt.shape[1]}; rerun render.py for this model")
        per_view["SSIM"][name] = ssim(render, gt).item()
        per_view["PSNR"][name] = psnr(render, gt).item()
        distance = lpips_distance(lpips.model, lpips.variant, render, gt) if lpips is not None else None
        too_small |= lpips is not None and distance is None
        per_view["LPIPS"][name] = None if distance is None else distance.item()
        if with_uncertainty:
            per_view["Spearman"][name], per_view["AUSE"][name] = uncertainty_scores(method_dir, name, render, gt)
    if too_small:
        log.warning("%s: LPIPS null for images under %d px (the smallest side LPIPS-%s accepts)", label,
                    LPIPS_MIN_SIDE[lpips.variant], lpips.variant)
    return per_view


def uncertainty_scores(method_dir: Path, name: str, render: torch.Tensor,
                       gt: torch.Tensor) -> tuple[float | None, float]:
    """(Spearman, AUSE) of `uncertainty/<stem>.npy` against the per-pixel absolute error, averaged over RGB.

    Raises:
        UserError: the map is missing or not the size of the image.
    """
    path = method_dir / "uncertainty" / (Path(name).stem + ".npy")
    if not path.is_file():
        raise UserError(f"{method_dir}: uncertainty/ has no {path.name}; rerun render.py --uncertainty for this model")
    values = np.load(path)  # [H, W]
    errors = (render - gt).abs().mean(0).cpu().numpy()  # [H, W]
    if values.shape != errors.shape:
        raise UserError(f"{method_dir}: uncertainty/{path.name} is {values.shape[1]}x{values.shape[0]} but "
                        f"renders/{name} is {errors.shape[1]}x{errors.shape[0]}; rerun render.py --uncertainty")
    return spearman(values, errors), ause(values, errors)


def mean_metrics(per_view: dict[str, dict[str, float | None]], lpips_variant: str | None) -> dict:
    """One `results.json` entry: {"SSIM", "PSNR", "LPIPS", "LPIPS_variant"}, plus "Spearman" and "AUSE" when the
    views have uncertainty maps; LPIPS (and its variant) is None unless every view has a value, and so is Spearman
    unless every view's is defined."""
    def mean(values: dict[str, float | None]) -> float | None:
        vals = list(values.values())
        return math.fsum(vals) / len(vals) if vals and None not in vals else None

    lpips_mean = mean(per_view["LPIPS"])
    result = {"SSIM": mean(per_view["SSIM"]), "PSNR": mean(per_view["PSNR"]), "LPIPS": lpips_mean,
              "LPIPS_variant": lpips_variant if lpips_mean is not None else None}
    if "Spearman" in per_view:
        result.update({"Spearman": mean(per_view["Spearman"]), "AUSE": mean(per_view["AUSE"])})
    return result
