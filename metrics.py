"""PSNR / SSIM / LPIPS of rendered test views against their ground truth, in the 3DGS format.

    python metrics.py -m output/            # every model directory below output/ with test/ours_N/renders

Writes `results.json` ({"ours_N": {"SSIM", "PSNR", "LPIPS", "LPIPS_variant"}}) and `per_view.json`
({"ours_N": {"SSIM": {"00000.png": ...}, "PSNR": {...}, "LPIPS": {...}}}) into each model directory and prints a
table. When `render.py --uncertainty` wrote maps (test/ours_N/uncertainty/*.npy), both files also get "Spearman"
(rank correlation of per-pixel uncertainty and absolute error) and "AUSE" (RMSE sparsification, see
utils/uncertainty_metrics.py), per view and mean. LPIPS weights: --lpips_weights, else $LITEGS_LPIPS_WEIGHTS, else
the repository's weights/lpips_squeeze.pt, else torchvision's backbone if already in the torch hub cache; nothing is
downloaded. Without weights LPIPS is null.
"""
from __future__ import annotations

import argparse
import logging
import os

from utils.errors import run_cli
from utils.io import write_json
from utils.lpips_loader import VARIANTS, default_weights_path, load_lpips
from utils.metrics_core import Lpips, evaluate_views, find_model_dirs, mean_metrics, method_dirs
from utils.model_dir import PER_VIEW, RESULTS


def evaluate(model_dirs: list[str | os.PathLike], lpips_weights: str | os.PathLike | None = None,
             lpips_net: str | None = None, device: str = "cpu", quiet: bool = False) -> dict[str, dict]:
    """Evaluate every model directory found under `model_dirs` and write its results.json and per_view.json.

    Args:
        model_dirs: Paths searched recursively for `test/ours_N/renders/*.png`.
        lpips_weights: Full LPIPS state dict; None: $LITEGS_LPIPS_WEIGHTS or the shipped weights/lpips_squeeze.pt,
            else the torch hub cache.
        lpips_net: LPIPS variant; None: the one the weights hold (squeeze for the hub cache).
        device: Where images and LPIPS go.
        quiet: No progress bars.
    Returns:
        {model_dir: {"ours_N": results.json entry plus "num_views"}}.
    Raises:
        UserError: nothing rendered under the paths, renders/gt mismatches, LPIPS variant mismatch.
    """
    found = find_model_dirs(list(model_dirs))
    weights = lpips_weights if lpips_weights is not None else default_weights_path(lpips_net)
    loaded = load_lpips(lpips_net, weights, device)
    lpips = Lpips(*loaded) if loaded is not None else None
    summary: dict[str, dict] = {}
    for model_dir in found:
        results, per_view_all = {}, {}
        for method_dir in method_dirs(model_dir):
            per_view = evaluate_views(method_dir, lpips, device, quiet)
            results[method_dir.name] = mean_metrics(per_view, lpips.variant if lpips else None)
            per_view_all[method_dir.name] = per_view
        write_json(model_dir / RESULTS, results)
        write_json(model_dir / PER_VIEW, per_view_all)
        summary[str(model_dir)] = {m: {**r, "num_views": len(per_view_all[m]["PSNR"])} for m, r in results.items()}
    return summary


def format_table(summary: dict[str, dict]) -> str:
    """A text table: model dir, method, #views, PSNR, SSIM, LPIPS (variant), from `evaluate`'s return value."""
    with_uncertainty = any("AUSE" in r for results in summary.values() for r in results.values())
    header = ("model", "method", "views", "PSNR", "SSIM", "LPIPS")
    rows = [header + (("Spearman", "AUSE") if with_uncertainty else ())]
    for model_dir, results in summary.items():
        for method, r in results.items():
            lp = f"{r['LPIPS']:.4f} ({r['LPIPS_variant']})" if r["LPIPS"] is not None else "unavailable"
            extra = (_fmt(r.get("Spearman")), _fmt(r.get("AUSE"))) if with_uncertainty else ()
            rows.append((model_dir, method, str(r["num_views"]), f"{r['PSNR']:.2f}", f"{r['SSIM']:.4f}", lp) + extra)
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def main(argv: list[str] | None = None) -> None:
    """Parse the command line, evaluate, print the table."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-m", "--model_paths", nargs="+", required=True,
                        help="model directories or folders above them (searched recursively)")
    parser.add_argument("--lpips_weights", default=None,
                        help="full LPIPS state dict (default: $LITEGS_LPIPS_WEIGHTS or the shipped weights/lpips_squeeze.pt)")
    parser.add_argument("--lpips_net", choices=VARIANTS, default=None,
                        help="LPIPS variant; must match the weights (default: the variant the weights hold)")
    parser.add_argument("--device", default="cpu", help="torch device for the metrics (default: cpu)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    print(format_table(evaluate(args.model_paths, args.lpips_weights, args.lpips_net, args.device, args.quiet)))


if __name__ == "__main__":
    run_cli(main)
