"""The report of a recommendation (recommend.py output folder): captured cameras, candidates coloured by gain,
picks numbered, previews, oracle counts, seconds, settings. `write_recommendation_report(out_dir, out=None) -> Path`
(default OUT_DIR/report.html)."""
from __future__ import annotations

import json
import os
from pathlib import Path

from reports.figures import scene_figure
from reports.images import file_uri
from reports.page import Page, esc, image_cell
from reports.recommendation_data import gather_recommendation

REPORT_NAME = "report.html"


def write_recommendation_report(out_dir: str | os.PathLike, out: str | os.PathLike | None = None) -> Path:
    """Write the report of a recommend.py output folder and return its path.

    Raises:
        UserError: no readable recommendations.json, or the report path cannot be written.
    """
    data = gather_recommendation(out_dir)
    rec = data.record
    page = Page(f"Recommendation: {rec.get('selector', '?')}, {rec.get('k_taken', len(rec['picks']))} picks")
    page.paragraph(f"{data.folder.resolve()}; model {rec.get('model', '–')}", "small")
    for note in rec.get("notes") or []:
        page.box(str(note), "note")
    page.absent(data.absent)
    page.scene(f"{data.points_note}; picks numbered by rank; candidates coloured by their evaluated gain (grey: not "
               "evaluated).", scene_figure(data.points, data.point_colors, data.cameras))

    page.heading("Picks")
    rows = [[p.get("rank", "–"), p.get("name", "–"), p.get("candidate", "–"),
             f"{p['gain']:.4g}" if p.get("gain") is not None else "–", p.get("visible_gaussians", "–")]
            for p in sorted(rec["picks"], key=lambda p: p.get("rank", 0))]
    page.table(["rank", "name", "candidate", "gain", "visible Gaussians"], rows)
    calls = rec.get("oracle_calls", {})
    seconds = rec.get("seconds", {})
    page.table(["oracle conservative", "oracle evaluated", "Fisher views"] + [f"{k} s" for k in seconds],
               [[calls.get("conservative", "–"), calls.get("evaluated", "–"), rec.get("fisher_views_computed", "–")]
                + [f"{v:.2f}" if isinstance(v, (int, float)) else v for v in seconds.values()]])
    if any(f for _, *fs in data.previews for f in fs):
        page.heading("Previews")
        cells = ["<div class='head'>render at the pick</div>", "<div class='head'>uncertainty</div>"]
        for rank, preview, unc in data.previews:
            cells += [image_cell(file_uri(f), f"pick {rank} {what}") if f else "<figure class='small'>absent</figure>"
                      for f, what in ((preview, "preview"), (unc, "uncertainty"))]
        page.add(f"<div class='gallery' style='grid-template-columns:repeat(2,minmax(0,320px))'>{''.join(cells)}</div>")
    page.heading("Settings")
    settings = {k: rec[k] for k in ("selector", "selector_options", "k", "candidates", "prior", "iteration",
                                   "num_gaussians", "settings") if k in rec}
    page.table(["setting", "value"], [(k, json.dumps(v) if not isinstance(v, str) else v) for k, v in settings.items()])
    page.add(f"<details><summary>{esc('recommendations.json')} (without per-candidate gains)</summary><pre>"
             f"{esc(json.dumps({k: v for k, v in rec.items() if k != 'candidate_gains'}, indent=1))}</pre></details>")
    return page.write(out if out is not None else data.folder / REPORT_NAME)
