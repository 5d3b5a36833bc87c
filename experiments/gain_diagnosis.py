"""Where a candidate's log-det (pop_gs, D-optimal) first-pick gain comes from: its per-Gaussian terms, broken down.

    diag = diagnose(gaussians, cameras, train_ids, candidate_ids, background, settings)   # pure, testable
    run(model_dir, candidates, out_dir)                     # diagnosis.json, diagnosis.md, gain_overlay.png

The per-Gaussian terms are the Fisher oracle's own (`FisherOracle.build` prior from the captured views,
`BlockInformation.gain_terms` of each candidate's `ViewFactors`): the first-pick gain of a candidate is their sum.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from active.cover_oracle import CoverageOracle, frustum_directions, pixel_coordinates
from active.fisher import FisherOracle, candidate_target, source_and_prior
from active.gain_weights import area_weights
from active.logdet import BlockInformation
from active.variance_oracle import RenderVarianceInformation
from arguments import FisherSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from utils.uncertainty_metrics import spearman

OPACITY_BINS = (0.05, 0.3, 0.7)  # edges: <0.05, 0.05-0.3, 0.3-0.7, >0.7
FAR_FACTOR = 2.0  # far: distance from the scene centre > FAR_FACTOR x the median Gaussian distance


def gaussian_groups(gaussians: GaussianModel, cameras: list[Camera], train_ids: list[int],
                    prior_seen: torch.Tensor) -> dict[str, dict[str, torch.Tensor]]:
    """Boolean masks [N] per breakdown: seen by the prior or not, opacity bins, inside a captured frustum or not,
    near or far from the centre (the mean of the Gaussian centres), and the quarters of the area shares
    (`active.gain_weights.area_weights`: the densest quarter is where densification packed Gaussians)."""
    means = gaussians.means.detach().double().cpu()
    opacity = gaussians.opacities.detach().double().cpu().reshape(-1)
    inside = torch.zeros(means.shape[0], dtype=torch.bool)
    for v in train_ids:
        inside |= frustum_directions(means, cameras[v])[0]
    dist = (means - means.mean(0)).norm(dim=-1)
    far = dist > FAR_FACTOR * dist.median()
    a, b, c = OPACITY_BINS
    area = area_weights(means)
    low, high = torch.quantile(area, torch.tensor([0.25, 0.75], dtype=torch.float64))
    return {
        "prior": {"seen": prior_seen, "unseen": ~prior_seen},
        "opacity": {f"<{a}": opacity < a, f"{a}-{b}": (opacity >= a) & (opacity < b),
                    f"{b}-{c}": (opacity >= b) & (opacity < c), f">{c}": opacity >= c},
        "frustum": {"inside": inside, "outside": ~inside},
        "distance": {"near": ~far, "far": far},
        "spacing": {"densest 25%": area <= low, "middle 50%": (area > low) & (area < high), "sparsest 25%": area >= high},
    }


def fractions(terms: torch.Tensor, groups: dict[str, dict[str, torch.Tensor]]) -> dict[str, dict[str, float]]:
    """The share of sum(terms) [N] in each group's bins (0 for a zero total)."""
    total = float(terms.sum())
    return {key: {k: (float(terms[m].sum()) / total if total > 0 else 0.0) for k, m in masks.items()}
            for key, masks in groups.items()}


def per_gaussian_gains(oracle: FisherOracle, view_id: int) -> torch.Tensor:
    """The oracle's log-det terms of one candidate scattered to every Gaussian (0 where it sees none). [N] float64"""
    info = oracle.information
    view = info.view(oracle.view_blocks(view_id))
    out = torch.zeros(info.num_gaussians, dtype=torch.float64)
    out[view.indices.cpu()] = info.gain_terms(view).cpu()
    return out


def _rank_correlation(x: list[float], y: list[float]) -> float:
    """Spearman's rank correlation (`utils.uncertainty_metrics.spearman`); NaN where undefined (a constant list)."""
    rho = spearman(np.asarray(x), np.asarray(y))
    return float("nan") if rho is None else rho


def diagnose(gaussians: GaussianModel, cameras: list[Camera], train_ids: list[int], candidate_ids: list[int],
             background: torch.Tensor, settings: Any, *, fisher: FisherSettings = FisherSettings(), top: int = 8,
             names: dict[int, str] | None = None) -> dict[str, Any]:
    """The breakdown of every candidate's first-pick log-det gain (and render-variance gain) over its Gaussians, the
    spread of the gains, and the rank correlation with the opacity-weighted, render-variance and COVER gains.
    Returns a JSON-able dict; the per-Gaussian gains of the top pick are under the private key "_top_terms"
    ([N] tensor)."""
    source, prior_blocks = source_and_prior(gaussians, cameras, train_ids, background, settings, fisher)
    ridge = {"delta_rel": fisher.delta_rel, "delta_abs": fisher.delta_abs}
    # one source for both criteria: each candidate's Fisher pass is made once (cached by the variance's target)
    variance = FisherOracle(RenderVarianceInformation(prior_blocks, candidate_target(source, train_ids), **ridge),
                            source)
    oracle = FisherOracle(BlockInformation(prior_blocks, **ridge), source)
    prior = oracle.information.prior_matrix  # H0 + ridge [N, P, P]
    diag_max = torch.diagonal(prior, dim1=-2, dim2=-1).amax(-1).cpu()
    prior_seen = diag_max > fisher.delta_abs * (1 + 1e-6) + 1e-300  # an all-zero prior block holds only the ridge
    groups = gaussian_groups(gaussians, cameras, train_ids, prior_seen)
    opacity = gaussians.opacities.detach().double().cpu().reshape(-1)
    area = area_weights(gaussians.means)
    cover = CoverageOracle.for_model(gaussians, cameras, train_ids)
    rows, terms_of = [], {}
    for v in candidate_ids:
        t = per_gaussian_gains(oracle, v)
        gain = float(t.sum())
        row: dict[str, Any] = {"id": v, "name": (names or {}).get(v, str(v)), "gain": gain,
                               "gain_opacity": float((t * opacity).sum()), "gain_area": float((t * area).sum()),
                               "gain_cover": cover.gain(v),
                               "visible": int((t > 0).sum())}
        row.update(fractions(t, groups))
        tv = per_gaussian_gains(variance, v)
        row["gain_variance"], row["variance"] = float(tv.sum()), fractions(tv, groups)
        nz = t[t > 0]
        row["median_term"] = float(nz.median()) if nz.numel() else 0.0
        if nz.numel():
            k = max(1, math.ceil(0.01 * nz.numel()))
            row["top1pct_share"] = float(torch.topk(nz, k).values.sum()) / gain
        else:
            row["top1pct_share"] = 0.0
        rows.append(row)
        terms_of[v] = t
    rows.sort(key=lambda r: -r["gain"])
    gains = [r["gain"] for r in rows]
    g_max = max(gains) if gains else 0.0
    top_rows = rows[:top]
    summary = {}
    for key, masks in groups.items():  # over all candidates: mean of the fractions, and fraction of the summed gains
        total = sum(gains)
        summary[key] = {k: {"mean_fraction": sum(r[key][k] for r in rows) / len(rows),
                            "pooled_fraction": sum(r[key][k] * r["gain"] for r in rows) / total if total else 0.0,
                            "gaussians": int(m.sum())} for k, m in masks.items()}
    summary_variance = {key: {k: sum(r["variance"][key][k] for r in rows) / len(rows) for k in masks}
                        for key, masks in groups.items()}  # mean fraction of the render-variance gain
    by_id = {r["id"]: r for r in rows}
    ids = [r["id"] for r in rows]
    x = [by_id[i]["gain"] for i in ids]
    per_visible = [by_id[i]["gain"] / max(by_id[i]["visible"], 1) for i in ids]  # the gain per Gaussian it sees
    result = {
        "num_gaussians": gaussians.num_gaussians, "num_candidates": len(rows), "train_ids": list(train_ids),
        "top": top_rows, "candidates": rows, "summary": summary, "summary_variance": summary_variance,
        "spread": {"min": min(gains), "max": g_max,
                   "min_pct_of_max": 100 * min(gains) / g_max if g_max else 0.0,
                   "top8_range_pct": 100 * (top_rows[0]["gain"] - top_rows[-1]["gain"]) / g_max if g_max else 0.0},
        "median_term_all": sum(r["median_term"] for r in rows) / len(rows),
        "top1pct_share_mean": sum(r["top1pct_share"] for r in rows) / len(rows),
        "rank_correlation": {
            "logdet_vs_opacity": _rank_correlation(x, [by_id[i]["gain_opacity"] for i in ids]),
            "logdet_vs_area": _rank_correlation(x, [by_id[i]["gain_area"] for i in ids]),
            "logdet_vs_cover": _rank_correlation(x, [by_id[i]["gain_cover"] for i in ids]),
            "opacity_vs_cover": _rank_correlation([by_id[i]["gain_opacity"] for i in ids], [by_id[i]["gain_cover"] for i in ids]),
            "logdet_vs_variance": _rank_correlation(x, [by_id[i]["gain_variance"] for i in ids]),
            "logdet_vs_per_visible": _rank_correlation(x, per_visible),
        },
        "visible_share": {"min": min(r["visible"] for r in rows) / gaussians.num_gaussians,
                          "max": max(r["visible"] for r in rows) / gaussians.num_gaussians},
        "top_picks": {"logdet": [by_id[i]["name"] for i in ids[:4]],
                      "opacity": [r["name"] for r in sorted(rows, key=lambda r: -r["gain_opacity"])[:4]],
                      "area": [r["name"] for r in sorted(rows, key=lambda r: -r["gain_area"])[:4]],
                      "cover": [r["name"] for r in sorted(rows, key=lambda r: -r["gain_cover"])[:4]],
                      "render_variance": [r["name"] for r in sorted(rows, key=lambda r: -r["gain_variance"])[:4]]},
        "_top_terms": terms_of[rows[0]["id"]] if rows else None,
    }
    return result


def markdown(d: dict[str, Any], title: str) -> str:
    """The diagnosis as Markdown tables."""
    pct = lambda f: f"{100 * f:.1f}"
    keys = [(k, list(d["summary"][k])) for k in d["summary"]]
    head = ["candidate", "gain", "visible"] + [f"{k}:{b}" for k, bins in keys for b in bins] + ["top1% share"]
    lines = [f"# Gain diagnosis: {title}", "",
             f"{d['num_gaussians']} Gaussians, {d['num_candidates']} candidates, captured views {d['train_ids']}.", "",
             "## Top picks: fraction of the first-pick log-det gain (%)", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in d["top"]:
        cells = [r["name"], f"{r['gain']:.1f}", str(r["visible"])]
        cells += [pct(r[k][b]) for k, bins in keys for b in bins] + [pct(r["top1pct_share"])]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "## All candidates (mean fraction % / pooled fraction % / Gaussians in the group; last column: mean "
              "fraction % of the render-variance gain)", "",
              "| group | bin | mean % | pooled % | Gaussians | render variance mean % |", "|---|---|---|---|---|---|"]
    for k, bins in keys:
        for b in bins:
            s = d["summary"][k][b]
            lines.append(f"| {k} | {b} | {pct(s['mean_fraction'])} | {pct(s['pooled_fraction'])} | {s['gaussians']} | "
                         f"{pct(d['summary_variance'][k][b])} |")
    sp, rc = d["spread"], d["rank_correlation"]
    lines += ["", "## Spread and concentration", "",
              f"- first-pick gains: min {sp['min']:.1f}, max {sp['max']:.1f} (min = {sp['min_pct_of_max']:.1f} % of max); "
              f"top-8 range {sp['top8_range_pct']:.1f} % of max",
              f"- median per-Gaussian term (visible Gaussians, mean over candidates): {d['median_term_all']:.3g}",
              f"- share of the gain held by the top 1 % of a candidate's Gaussians (mean): "
              f"{100 * d['top1pct_share_mean']:.1f} %", "",
              "## Rank correlation of candidates (Spearman)", "",
              f"- log-det vs opacity-weighted log-det: {rc['logdet_vs_opacity']:.3f}",
              f"- log-det vs area-weighted log-det: {rc['logdet_vs_area']:.3f}",
              f"- log-det vs cover: {rc['logdet_vs_cover']:.3f}",
              f"- opacity-weighted vs cover: {rc['opacity_vs_cover']:.3f}",
              f"- log-det vs render variance: {rc['logdet_vs_variance']:.3f}",
              f"- log-det vs log-det per visible Gaussian: {rc['logdet_vs_per_visible']:.3f} (a candidate sees "
              f"{pct(d['visible_share']['min'])}-{pct(d['visible_share']['max'])} % of the Gaussians)", "",
              "Top-4 by criterion: " + "; ".join(f"{k}: {', '.join(v)}" for k, v in d["top_picks"].items()), "",
              "## Picks vs training length", "",
              "Train the same captured views for N iterations (train.py -s DATA -r 4 --eval -w -q --num_random_points "
              "3000 --densify_from_iter 100 --densification_interval 50 --max_gaussians 20000 --iterations N -m "
              "MODEL_N), then `recommend.py -m MODEL_N --candidates CANDIDATES -k 4 --method pop_gs -o DIR --quiet "
              "--no_previews` and `scripts/diagnose_gain.py -m MODEL_N --candidates CANDIDATES -o OUT_N` for each N.", ""]
    return "\n".join(lines)


def overlay(image: torch.Tensor, terms: torch.Tensor, gaussians: GaussianModel, camera: Camera, path: Path,
            title: str) -> None:
    """The render [3, H, W] with the per-Gaussian gain splatted at the projected centres, blurred, as a heat map."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    u, v, inside = pixel_coordinates(gaussians.means.detach().double().cpu(), camera)
    u, v = u.floor().long(), v.floor().long()
    w, h = camera.width, camera.height
    ok = inside & (terms > 0)
    heat = torch.zeros(h * w, dtype=torch.float64)
    heat.index_add_(0, (v[ok] * w + u[ok]), terms[ok])
    heat = heat.reshape(1, 1, h, w)
    s = max(1.0, 0.01 * max(h, w))
    r = int(3 * s)
    k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=torch.float64) / s) ** 2)
    k = k / k.sum()
    heat = torch.nn.functional.conv2d(heat, k.reshape(1, 1, 1, -1), padding=(0, r))
    heat = torch.nn.functional.conv2d(heat, k.reshape(1, 1, -1, 1), padding=(r, 0))[0, 0].numpy()
    img = image.detach().clamp(0, 1).permute(1, 2, 0).cpu().numpy()
    fig, ax = plt.subplots(1, 2, figsize=(10, 5))
    ax[0].imshow(img)
    ax[0].set_title("render")
    ax[1].imshow(img)
    im = ax[1].imshow(np.ma.masked_less_equal(heat, heat.max() * 1e-3), cmap="inferno", alpha=0.7)
    ax[1].set_title(f"log-det gain per pixel (sum {float(terms.sum()):.1f})")
    fig.colorbar(im, ax=ax[1], fraction=0.046)
    for a in ax:
        a.axis("off")
    fig.suptitle(title)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def run(model: str | Path, candidates: str, out: str | Path, *, top: int = 8, width: int | None = None) -> dict:
    """Load a model directory (or PLY) as recommend.py does, diagnose its candidates, write OUT/diagnosis.json,
    OUT/diagnosis.md and OUT/gain_overlay.png; returns the diagnosis (without the per-Gaussian terms)."""
    from gaussian_renderer import render
    from recommender.pipeline import candidate_cameras, load_model, make_pool
    from utils.io import write_json
    loaded = load_model(model)
    pool = make_pool(loaded, candidate_cameras(candidates, loaded), width)
    d = diagnose(loaded.gaussians, pool.cameras, pool.train_ids, pool.candidate_ids, loaded.background,
                 loaded.settings, fisher=loaded.fisher, top=top, names=pool.names)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    terms = d.pop("_top_terms")
    d["model"], d["candidates_file"] = str(model), str(candidates)
    write_json(out / "diagnosis.json", d)
    (out / "diagnosis.md").write_text(markdown(d, str(model)))
    best = pool.cameras[d["top"][0]["id"]]
    with torch.no_grad():
        image = render(best, loaded.gaussians, loaded.background, loaded.settings).image
    overlay(image, terms, loaded.gaussians, best, out / "gain_overlay.png", f"top pick {d['top'][0]['name']}")
    return d
