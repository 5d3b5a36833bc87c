"""PSNR / SSIM / LPIPS of rendered test views against ground truth, in the 3DGS format.

    python metrics.py -m output/            # every model directory below output/ that has test renders

Writes `results.json` and `per_view.json` into each model directory and prints a table.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from tqdm import tqdm

from utils.errors import UserError, run_cli
from utils.image import psnr
from utils.io import write_json
from utils.losses import ssim
from utils.lpips_loader import load_lpips


def find_model_dirs(roots: list[str]) -> list[Path]:
    """Directories (searched recursively) holding `test/ours_N/renders`."""
    found = set()
    for root in roots:
        root_path = Path(root)
        if not root_path.exists():
            raise UserError(f"{root} does not exist; pass model directories written by train.py and render.py")
        for renders in root_path.rglob("renders"):
            if renders.parent.name.startswith("ours_") and renders.parent.parent.name == "test":
                found.add(renders.parent.parent.parent)
    if not found:
        raise UserError(f"no rendered test views under {', '.join(roots)} (looked for test/ours_N/renders/*.png); "
                        "run render.py -m MODEL first (and train with --eval so there is a test split)")
    return sorted(found)


def _read(path: Path) -> torch.Tensor:
    with Image.open(path) as im:
        return torch.from_numpy(np.asarray(im.convert("RGB"), dtype=np.float32) / 255.0).permute(2, 0, 1)


LPIPS_MIN_SIZE = 32  # the LPIPS backbones downsample 4-5 times; smaller images have no valid deepest features


def lpips_distance(model, render: torch.Tensor, gt: torch.Tensor) -> float | None:
    """LPIPS of [3, H, W] images in [0, 1]; None without a model or for images too small for the network."""
    if model is None or min(render.shape[-2:]) < LPIPS_MIN_SIZE:
        return None
    return float(model(render[None] * 2 - 1, gt[None] * 2 - 1).item())


@torch.no_grad()
def evaluate_method(method_dir: Path, lpips_model, quiet: bool = False) -> dict[str, dict[str, float | None]]:
    """Per-view metrics of one `test/ours_N` directory: {"PSNR": {name: v}, "SSIM": ..., "LPIPS": ...}."""
    renders, gts = method_dir / "renders", method_dir / "gt"
    names = sorted(p.name for p in renders.glob("*.png"))
    if not names or names != sorted(p.name for p in gts.glob("*.png")):
        raise UserError(f"{method_dir}: renders/ and gt/ hold different files; rerun render.py for this model")
    per_view: dict[str, dict[str, float | None]] = {"PSNR": {}, "SSIM": {}, "LPIPS": {}}
    for name in tqdm(names, desc=f"metrics {method_dir.parent.parent.name}/{method_dir.name}", disable=quiet):
        render, gt = _read(renders / name), _read(gts / name)
        if render.shape != gt.shape:
            raise UserError(f"{method_dir}: {name} has size {tuple(render.shape)} but its ground truth "
                            f"{tuple(gt.shape)}; rerun render.py")
        per_view["PSNR"][name] = float(psnr(render, gt))
        per_view["SSIM"][name] = float(ssim(render, gt))
        per_view["LPIPS"][name] = lpips_distance(lpips_model, render, gt)
    return per_view


def evaluate(model_dirs: list[str], lpips_weights: str | None = None, quiet: bool = False) -> dict[str, dict]:
    """Evaluate every model directory found under `model_dirs`; returns {model_dir: results}."""
    found = find_model_dirs(model_dirs)
    loaded = load_lpips(lpips_weights)
    lpips_model, variant = loaded if loaded is not None else (None, None)
    all_results = {}
    for model_dir in found:
        results, per_view_all = {}, {}
        for method_dir in sorted((model_dir / "test").glob("ours_*")):
            per_view = evaluate_method(method_dir, lpips_model, quiet)
            mean = lambda d: float(np.mean(list(d.values()))) if d and None not in d.values() else None
            results[method_dir.name] = {"SSIM": mean(per_view["SSIM"]), "PSNR": mean(per_view["PSNR"]),
                                        "LPIPS": mean(per_view["LPIPS"]), "LPIPS_variant": variant,
                                        "num_views": len(per_view["PSNR"])}
            per_view_all[method_dir.name] = per_view
        write_json(model_dir / "results.json", results)
        write_json(model_dir / "per_view.json", per_view_all)
        all_results[str(model_dir)] = results
    return all_results


def format_table(all_results: dict[str, dict]) -> str:
    rows = [("model", "method", "views", "PSNR", "SSIM", "LPIPS")]
    for model_dir, results in all_results.items():
        for method, r in results.items():
            lp = f"{r['LPIPS']:.4f} ({r['LPIPS_variant']})" if r["LPIPS"] is not None else "unavailable"
            rows.append((model_dir, method, str(r["num_views"]), f"{r['PSNR']:.2f}", f"{r['SSIM']:.4f}", lp))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)) for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_paths", nargs="+", required=True, help="model directories (searched recursively)")
    parser.add_argument("--lpips_weights", default=None,
                        help="full LPIPS state dict (default: $LITEGS_LPIPS_WEIGHTS or ../shared/weights/lpips_squeeze.pt)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args()
    print(format_table(evaluate(args.model_paths, args.lpips_weights, args.quiet)))


if __name__ == "__main__":
    run_cli(main)
