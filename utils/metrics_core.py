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
from active.uncertainty import UNCERTAINTY_KINDS  # render.py --uncertainty_kind: one folder per kind
from utils.model_dir import METHOD_PATTERN
from utils.uncertainty_metrics import AUSE_VARIANTS, ause, spearman

log = logging.getLogger(__name__)

REGIONS = ("image", "object")
NO_ALPHA = "whole image (the scene has no alpha; object = image)"
WITH_ALPHA = "pixels where the ground truth or the render differs from the background"


def uncertainty_key(metric: str, kind: str, region: str) -> str:
    """The results.json / per_view.json key of one uncertainty number, e.g. "AUSE_MAE_norm/fisherrf/object"."""
    return f"{metric}/{kind}/{region}"


def uncertainty_metric_names(variants: tuple[str, ...] = tuple(AUSE_VARIANTS)) -> list[str]:
    """Spearman and the AUSE variants' names: "AUSE_RMSE", "AUSE_MAE_norm", ..."""
    return ["Spearman"] + ["AUSE_" + v.upper().replace("_NORM", "_norm") for v in variants]
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


def uncertainty_kinds(method_dir: Path) -> list[str]:
    """The map kinds render.py --uncertainty wrote under `method_dir/uncertainty/`, in UNCERTAINTY_KINDS order."""
    return [k for k in UNCERTAINTY_KINDS if any((method_dir / "uncertainty" / k).glob("*.npy"))]


@torch.no_grad()
def evaluate_views(method_dir: Path, lpips: Lpips | None, device: str | torch.device = "cpu",
                   quiet: bool = False, ause_variants: tuple[str, ...] = tuple(AUSE_VARIANTS)
                   ) -> dict[str, dict[str, float | None]]:
    """Per-view metrics of one `test/ours_N` directory: {"SSIM": {name: v}, "PSNR": {...}, "LPIPS": {...}}, plus,
    for each map kind render.py --uncertainty wrote (`uncertainty/KIND/*.npy`), Spearman and the `ause_variants`
    over the image and over the object (`uncertainty_scores`), keyed `uncertainty_key(metric, kind, region)`.

    LPIPS values are None without a network, or for images smaller than its backbone accepts (logged once).

    Raises:
        UserError: renders/ and gt/ differ in file names or in the size of an image; an uncertainty map is missing
            or of another size.
    """
    per_view: dict[str, dict[str, float | None]] = {"SSIM": {}, "PSNR": {}, "LPIPS": {}}
    kinds = uncertainty_kinds(method_dir)
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
        for kind in kinds:
            for key, value in uncertainty_scores(method_dir, kind, name, render, gt, ause_variants).items():
                per_view.setdefault(key, {})[name] = value
    if too_small:
        log.warning("%s: LPIPS null for images under %d px (the smallest side LPIPS-%s accepts)", label,
                    LPIPS_MIN_SIDE[lpips.variant], lpips.variant)
    return per_view


def object_region(method_dir: Path) -> str:
    """How the "object" region of `method_dir`'s uncertainty metrics is defined (WITH_ALPHA or NO_ALPHA)."""
    return WITH_ALPHA if (method_dir / "uncertainty" / "object_mask").is_dir() else NO_ALPHA


def uncertainty_scores(method_dir: Path, kind: str, name: str, render: torch.Tensor, gt: torch.Tensor,
                       ause_variants: tuple[str, ...] = tuple(AUSE_VARIANTS)) -> dict[str, float | None]:
    """Spearman and the AUSE variants of `uncertainty/KIND/<stem>.npy` against the per-pixel absolute error
    (averaged over RGB), over the image and over the object (`uncertainty/object_mask/<name>`; the whole image when
    the scene has no alpha and render.py wrote no mask). {uncertainty_key(metric, kind, region): value}

    Raises:
        UserError: the map or the mask is missing or not the size of the image.
    """
    path = method_dir / "uncertainty" / kind / (Path(name).stem + ".npy")
    if not path.is_file():
        raise UserError(f"{method_dir}: uncertainty/{kind}/ has no {path.name}; rerun render.py --uncertainty for "
                        "this model")
    values = np.load(path)  # [H, W]
    errors = (render - gt).abs().mean(0).cpu().numpy()  # [H, W]
    if values.shape != errors.shape:
        raise UserError(f"{method_dir}: uncertainty/{kind}/{path.name} is {values.shape[1]}x{values.shape[0]} but "
                        f"renders/{name} is {errors.shape[1]}x{errors.shape[0]}; rerun render.py --uncertainty")
    mask_path = method_dir / "uncertainty" / "object_mask" / name
    if object_region(method_dir) == WITH_ALPHA:
        if not mask_path.is_file():
            raise UserError(f"{method_dir}: uncertainty/object_mask/ has no {name}; rerun render.py --uncertainty")
        mask = read_rgb(mask_path)[0].numpy() > 0.5  # [H, W]
        if mask.shape != errors.shape:
            raise UserError(f"{method_dir}: uncertainty/object_mask/{name} is not the size of renders/{name}; rerun "
                            "render.py --uncertainty")
    else:
        mask = np.ones(errors.shape, dtype=bool)
    out: dict[str, float | None] = {}
    for region, keep in (("image", np.ones(errors.shape, dtype=bool)), ("object", mask)):
        u, e = values[keep], errors[keep]
        names = uncertainty_metric_names(ause_variants)
        scores = [spearman(u, e) if e.size else None]
        scores += [ause(u, e, variant=v) if e.size else None for v in ause_variants]
        out.update({uncertainty_key(m, kind, region): s for m, s in zip(names, scores)})
    return out


def mean_metrics(per_view: dict[str, dict[str, float | None]], lpips_variant: str | None,
                 object_region_text: str | None = None) -> dict:
    """One `results.json` entry: {"SSIM", "PSNR", "LPIPS", "LPIPS_variant"}, plus the mean of every uncertainty key
    (and "uncertainty_object_region", `object_region_text`) when the views have uncertainty maps; LPIPS (and its
    variant) is None unless every view has a value, and so is an uncertainty mean unless every view's is defined."""
    def mean(values: dict[str, float | None]) -> float | None:
        vals = list(values.values())
        return math.fsum(vals) / len(vals) if vals and None not in vals else None

    lpips_mean = mean(per_view["LPIPS"])
    result = {"SSIM": mean(per_view["SSIM"]), "PSNR": mean(per_view["PSNR"]), "LPIPS": lpips_mean,
              "LPIPS_variant": lpips_variant if lpips_mean is not None else None}
    keys = [k for k in per_view if k not in ("SSIM", "PSNR", "LPIPS")]
    result.update({k: mean(per_view[k]) for k in keys})
    if keys:
        result["uncertainty_object_region"] = object_region_text
    return result
