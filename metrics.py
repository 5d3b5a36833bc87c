"""PSNR / SSIM / LPIPS of rendered test views against their ground truth, in the 3DGS format.

    python metrics.py -m output/            # every model directory below output/ with test/ours_N/renders

Writes `results.json` ({"ours_N": {"SSIM", "PSNR", "LPIPS", "LPIPS_variant"}}) and `per_view.json`
({"ours_N": {"SSIM": {"00000.png": ...}, "PSNR": {...}, "LPIPS": {...}}}) into each model directory and prints a
table. When `render.py --uncertainty` wrote maps (test/ours_N/uncertainty/KIND/*.npy), both files also get, for each
map kind, region (image, object) and metric (Spearman rank correlation of per-pixel uncertainty and absolute error;
AUSE_RMSE, AUSE_MAE, AUSE_RMSE_norm, AUSE_MAE_norm: sparsification areas, see utils/uncertainty_metrics.py; --ause
picks the variants) a key "METRIC/KIND/REGION", per view and mean, and results.json says how the object region was
defined ("uncertainty_object_region": the pixels where the ground truth or the render is not background, or the
whole image for a scene without alpha). LPIPS weights: --lpips_weights, else $LITEGS_LPIPS_WEIGHTS, else
the repository's weights/lpips_squeeze.pt, else torchvision's backbone if already in the torch hub cache; nothing is
downloaded. Without weights LPIPS is null.
"""
from __future__ import annotations

import argparse
import logging
import os

from utils.dir_lock import WAYS_OUT, writer_lock
from utils.errors import run_cli
from utils.io import write_json
from utils.lpips_loader import VARIANTS, default_weights_path, load_lpips
from utils.metrics_core import (REGIONS, UNCERTAINTY_KINDS, Lpips, evaluate_views, find_model_dirs, mean_metrics,
                                method_dirs, object_region, uncertainty_key, uncertainty_metric_names)
from utils.model_dir import PER_VIEW, RESULTS
from utils.uncertainty_metrics import AUSE_VARIANTS, parse_ause_variants



def evaluate(model_dirs: list[str | os.PathLike], lpips_weights: str | os.PathLike | None = None,
             lpips_net: str | None = None, device: str = "cpu", quiet: bool = False,
             ause_variants: tuple[str, ...] = tuple(AUSE_VARIANTS)) -> dict[str, dict]:
    """Evaluate every model directory found under `model_dirs` and write its results.json and per_view.json.

    Args:
        model_dirs: Paths searched recursively for `test/ours_N/renders/*.png`.
        lpips_weights: Full LPIPS state dict; None: $LITEGS_LPIPS_WEIGHTS or the shipped weights/lpips_squeeze.pt,
            else the torch hub cache.
        lpips_net: LPIPS variant; None: the one the weights hold (squeeze for the hub cache).
        device: Where images and LPIPS go.
        quiet: No progress bars.
        ause_variants: AUSE variants scored for uncertainty maps (`utils.uncertainty_metrics.AUSE_VARIANTS`).
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
        with writer_lock(model_dir, WAYS_OUT["metrics"]):  # no render.py / train.py writing it meanwhile
            for method_dir in method_dirs(model_dir):
                per_view = evaluate_views(method_dir, lpips, device, quiet, ause_variants)
                results[method_dir.name] = mean_metrics(per_view, lpips.variant if lpips else None,
                                                        object_region(method_dir))
                per_view_all[method_dir.name] = per_view
            write_json(model_dir / RESULTS, results)
            write_json(model_dir / PER_VIEW, per_view_all)
        summary[str(model_dir)] = {m: {**r, "num_views": len(per_view_all[m]["PSNR"])} for m, r in results.items()}
    return summary


def format_table(summary: dict[str, dict], ause_variants: tuple[str, ...] = tuple(AUSE_VARIANTS)) -> str:
    """A text table: model dir, method, #views, PSNR, SSIM, LPIPS (variant), from `evaluate`'s return value; then,
    when there are uncertainty maps, one row per model, method, map kind and region with Spearman and the AUSE
    variants."""
    rows = [("model", "method", "views", "PSNR", "SSIM", "LPIPS")]
    names = uncertainty_metric_names(ause_variants)
    urows = [("model", "method", "map kind", "region") + tuple(names)]
    regions = set()
    for model_dir, results in summary.items():
        for method, r in results.items():
            lp = f"{r['LPIPS']:.4f} ({r['LPIPS_variant']})" if r["LPIPS"] is not None else "unavailable"
            rows.append((model_dir, method, str(r["num_views"]), f"{r['PSNR']:.2f}", f"{r['SSIM']:.4f}", lp))
            for kind in UNCERTAINTY_KINDS:
                for region in REGIONS:
                    if uncertainty_key("Spearman", kind, region) in r:
                        urows.append((model_dir, method, kind, region)
                                     + tuple(_fmt(r.get(uncertainty_key(m, kind, region))) for m in names))
                        regions.add(r.get("uncertainty_object_region"))
    text = _table(rows)
    if len(urows) > 1:
        text += "\n\nuncertainty vs per-pixel |error| (object: " + "; ".join(sorted(map(str, regions))) + ")\n"
        text += _table(urows)
    return text


def _table(rows: list[tuple[str, ...]]) -> str:
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
    parser.add_argument("--ause", default=",".join(AUSE_VARIANTS),
                        help=f"comma-separated AUSE variants for uncertainty maps: {', '.join(AUSE_VARIANTS)} "
                             "(default: all)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--report", action="store_true",
                        help="also write each model directory's report.html (report.py; a few seconds each)")
    args = parser.parse_args(argv)
    variants = parse_ause_variants(args.ause)
    summary = evaluate(args.model_paths, args.lpips_weights, args.lpips_net, args.device, args.quiet, variants)
    print(format_table(summary, variants))
    if args.report:
        from reports import write_run_report
        for model_dir in summary:
            with writer_lock(model_dir, WAYS_OUT["metrics"]):
                print(f"report: {write_run_report(model_dir)}")


if __name__ == "__main__":
    run_cli(main)
