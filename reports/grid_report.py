"""The report of a grid (scripts/grid.py output OUT/<setup>): per scene the methods side by side (PSNR vs views
with mean ± std bands over seeds, final metrics, oracle counts, selection seconds), linking to each run's report.
`write_grid_report(setup_dir, out=None, run_reports=True) -> Path` (default OUT/<setup>/report.html)."""
from __future__ import annotations

import os
from collections import defaultdict
from pathlib import Path

from tqdm import tqdm

from reports.figures import band_figure
from reports.grid_data import GridRun, find_runs, mean_curve, mean_std
from reports.page import Page, esc
from reports.run_report import REPORT_NAME, write_run_report


def _pm(stats: tuple[float, float, int] | None, fmt: str) -> str:
    if stats is None:
        return "–"
    mean, std, n = stats
    return f"{mean:{fmt}} ± {std:{fmt}}" if n > 1 else f"{mean:{fmt}}"


def method_row(tag: str, runs: list[GridRun], page_dir: Path) -> list[str]:
    """Table row of one method on one scene (cells are HTML: the seed links)."""
    res = [r.results or {} for r in runs]
    variants = sorted({x.get("LPIPS_variant") for x in res if x.get("LPIPS_variant")})
    links = " ".join(
        f"<a href='{esc(os.path.relpath(r.path / REPORT_NAME, page_dir))}'>seed{r.seed}</a>"
        + ("" if r.complete else " (incomplete)") for r in runs)
    return [esc(tag), f"{sum(r.complete for r in runs)}/{len(runs)}",
            _pm(mean_std([x.get("PSNR") for x in res]), ".2f"), _pm(mean_std([x.get("SSIM") for x in res]), ".4f"),
            _pm(mean_std([x.get("LPIPS") for x in res]), ".4f") + (f" ({esc(', '.join(variants))})" if variants else ""),
            _pm(mean_std([r.oracle_conservative for r in runs]), ".0f"),
            _pm(mean_std([r.oracle_evaluated for r in runs]), ".0f"),
            _pm(mean_std([r.fisher_seconds for r in runs]), ".1f"), _pm(mean_std([r.select_seconds for r in runs]), ".1f"),
            links]


def write_grid_report(setup_dir: str | os.PathLike, out: str | os.PathLike | None = None,
                      run_reports: bool = True) -> Path:
    """Write the grid report (and, with `run_reports`, every run's report.html it links to); return its path.

    Raises:
        UserError: no runs under `setup_dir`, damaged run files, or a report path that cannot be written.
    """
    setup_dir = Path(setup_dir)
    runs = find_runs(setup_dir)
    out = Path(out) if out is not None else setup_dir / REPORT_NAME
    if run_reports:
        for run in tqdm(runs, desc="run reports", unit="run"):
            write_run_report(run.path)
    page = Page(f"Grid report: {setup_dir.name}")
    page.paragraph(f"{setup_dir.resolve()}: {len(runs)} runs, {sum(r.complete for r in runs)} complete.", "small")
    by_scene: dict[str, dict[str, list[GridRun]]] = defaultdict(lambda: defaultdict(list))
    for run in runs:
        by_scene[run.scene][run.tag].append(run)
    for i, (scene, methods) in enumerate(by_scene.items()):
        page.heading(f"Scene {scene}")
        series = {tag: (*mean_curve([r.curve for r in rs]), len(rs)) for tag, rs in methods.items()
                  if any(r.curve for r in rs)}
        if series:
            page.figure(band_figure(series, f"{scene}: test PSNR vs training views"), f"psnr_{i}")
        page.table(["method", "complete", "PSNR", "SSIM", "LPIPS (variant)", "oracle conservative",
                    "oracle evaluated", "Fisher s", "select s", "run reports"],
                   [method_row(tag, rs, out.parent) for tag, rs in methods.items()], raw=True)
    page.paragraph("PSNR vs views: test PSNR train.py measured at each acquisition, then the final metrics.py PSNR; "
                   "± is the standard deviation over seeds; oracle counts and seconds are summed over stages.",
                   "small")
    return page.write(out)
