"""The report of one run (model directory): scene and cameras in 3D, stages, PSNR vs views, metrics, gallery,
settings. `write_run_report(model_dir, out=None) -> Path` (default MODEL_DIR/report.html)."""
from __future__ import annotations

import json
import os
from pathlib import Path

from reports.figures import psnr_views_figure, scene_figure
from reports.images import data_uri, error_map, file_uri, open_rgb
from reports.page import Page, esc, image_cell
from reports.run_data import RunData, gather_run, uncertainty_keys
from utils.model_dir import CFG_ARGS, RESULTS, SELECTION

REPORT_NAME = "report.html"


def _fmt(value: object, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def settings_rows(run: RunData) -> list[tuple[str, str]]:
    """(setting, value) rows from cfg_args and selection.json; keys a run did not record say so."""
    cfg = run.cfg or {}
    model, active, pipeline = cfg.get("model", {}), cfg.get("active", {}), cfg.get("pipeline", {})
    sel_cfg = (run.selection or {}).get("config", {})
    method = sel_cfg.get("method", active.get("method"))
    options = sel_cfg.get("selector_options")
    rows = [("method", f"{method}" + (f" {json.dumps(options)}" if options else "") if run.selection
             else f"{method or '–'} (no {SELECTION}: no active selection recorded)")]
    if active:
        rows.append(("schedule", f"{active.get('num_init_views')} seed views, {active.get('views_per_step')} per "
                                 f"step, up to {active.get('max_views')} views, {active.get('iters_per_view')} "
                                 f"iterations per view; {cfg.get('total_iterations', '–')} iterations in all"))
    width = {(c.width, c.height) for c in run.cameras}
    size = ", ".join(f"{w}×{h}" for w, h in sorted(width)) or "–"
    rows += [("resolution", f"-r {model.get('resolution', '–')} → {size} px"),
             ("rasterizer backend", f"{pipeline.get('raster_backend', '–')} on {model.get('device', '–')}"),
             ("seed", _fmt(cfg.get("run", {}).get("seed"))),
             ("dataset", f"{model.get('source_path', '–')} ({json.dumps(cfg.get('dataset', {}))})")]
    for key in ("commit", "machine"):
        rows.append((key, _fmt(cfg.get(key)) if key in cfg else f"not recorded in {CFG_ARGS}"))
    return rows


def stage_rows(run: RunData) -> list[list[str]]:
    """One row per acquisition stage: stage, iteration, views before, picks (view:gain), oracle counts, seconds."""
    rows = []
    for s in run.stages:
        picks = ", ".join(f"{v} ({g:.3g})" if g is not None else str(v)
                          for v, g in zip(s["selected"], s.get("gains") or [None] * len(s["selected"])))
        calls = s.get("oracle_calls", {})
        rows.append([s["stage"], s.get("iteration", "–"), len(s.get("train_views", [])), s.get("candidates", "–"),
                     picks, _fmt(calls.get("conservative")), _fmt(calls.get("evaluated")),
                     _fmt(s.get("fisher_views_computed")), f"{s.get('fisher_seconds', 0.0):.2f}",
                     f"{s.get('select_seconds', 0.0):.2f}", _fmt(s.get("test_psnr"))])
    return rows


def gallery_html(run: RunData) -> str:
    """Header row plus per test view: ground truth | render | error | one uncertainty map per kind, each clickable."""
    heads = ["ground truth", "render", "|error| (0–0.25)"] + [f"uncertainty: {k}" for k in run.colorbars]
    cells = [f"<div class='head'>{esc(h)}</div>" for h in heads]
    for item in run.gallery:
        gt, render = open_rgb(item.gt), open_rgb(item.render)
        psnr = f", PSNR {item.psnr:.2f} dB" if item.psnr is not None else ""
        cells += [image_cell(data_uri(gt), f"{item.name} ground truth"),
                  image_cell(data_uri(render), f"{item.name} render{psnr}")]
        cells.append(image_cell(data_uri(error_map(gt, render)), f"{item.name} |error|")
                     if gt.shape == render.shape else "<figure>size mismatch</figure>")
        cells += [image_cell(file_uri(path), f"{item.name} uncertainty: {kind}") if path
                  else "<figure class='small'>not rendered</figure>" for kind, path in item.uncertainty.items()]
    style = f" style='grid-template-columns: repeat({len(heads)},minmax(0,1fr))'"
    return f"<div class='gallery'{style}>{''.join(cells)}</div>"


def build_run_page(run: RunData) -> Page:
    """The page of `run` (see the module docstring)."""
    page = Page(f"Run report: {run.model_dir.name or run.model_dir}")
    page.paragraph(str(run.model_dir.resolve()), "small")
    if run.incomplete:
        page.box(run.incomplete, "warn")
    page.absent(run.absent)

    page.scene(f"{run.points_note}; {len(run.cameras)} cameras. Picks are numbered in pick order and coloured by "
               "stage; drag to rotate, scroll to zoom, click a legend entry to hide a group.",
               scene_figure(run.points, run.point_colors, run.cameras))
    if run.selection:
        page.paragraph(f"{SELECTION} records the gains of the picks only; candidates not picked are grey.", "small")

    if run.stages:
        page.heading("Acquisition stages")
        page.table(["stage", "iteration", "views", "candidates", "picks (gain)", "oracle conservative",
                    "oracle evaluated", "Fisher views", "Fisher s", "select s", "test PSNR"], stage_rows(run))
    curve = run.psnr_curve()
    if curve:
        page.heading("Test PSNR vs number of views")
        page.figure(psnr_views_figure(curve), "psnr_views")
    page.heading("Final metrics")
    if run.results:
        r = run.results
        lp = f"{r['LPIPS']:.4f} ({r.get('LPIPS_variant')})" if r.get("LPIPS") is not None else "unavailable"
        headers, row = ["iteration", "PSNR", "SSIM", "LPIPS (variant)"], [run.method_key, f"{r['PSNR']:.2f}",
                                                                          f"{r['SSIM']:.4f}", lp]
        page.table(headers, [row])
        unc = uncertainty_keys(r)
        if unc:
            page.heading("Uncertainty vs error (metrics.py)")
            page.table(["metric", "map kind", "region", "value"], [[m, k, g, f"{v:.4f}"] for m, k, g, v in unc])
    else:
        page.paragraph(f"no {RESULTS} (run metrics.py -m MODEL_DIR)")

    if run.gallery:
        page.heading("Test views")
        page.paragraph(f"{run.gallery_note}; click an image to enlarge.", "small")
        page.add(gallery_html(run))
        for kind, bar in run.colorbars.items():
            if bar:
                page.add(image_cell(file_uri(bar, "PNG", 600), f"uncertainty colour bar: {kind} (log10)"))
    page.heading("Settings")
    page.table(["setting", "value"], settings_rows(run))
    if run.cfg:
        page.add(f"<details><summary>{CFG_ARGS}</summary><pre>{esc(json.dumps(run.cfg, indent=1))}</pre></details>")
    return page


def write_run_report(model_dir: str | os.PathLike, out: str | os.PathLike | None = None) -> Path:
    """Write the report of a model directory (default MODEL_DIR/report.html) and return its path.

    Raises:
        UserError: not a model directory, damaged files, or the report path cannot be written.
    """
    run = gather_run(model_dir)
    return build_run_page(run).write(out if out is not None else Path(model_dir) / REPORT_NAME)
