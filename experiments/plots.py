"""Plots of experiment runs (matplotlib, Agg backend): test PSNR vs views, oracle evaluations vs K, the eps
trade-off, and the cameras each method chose. Each function takes the `Run` records of experiments/summary.py
(attributes: setup, scene, method, k, options, options_label, seed, setting, stages, final, results, cameras),
writes one PNG and returns its path, or returns None when the runs hold nothing to plot. No selector names here:
series are labelled by method and options as the runs record them."""
from __future__ import annotations

import textwrap
from collections import defaultdict
from pathlib import Path
from statistics import mean

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from active.oracle_counts import mean_rounded_up  # noqa: E402


def _per_step(runs, kind: str = "conservative") -> int | None:
    """Oracle evaluations per step over all steps of `runs`, rounded up."""
    counts = [s["oracle_calls"][kind] for r in runs for s in r.stages if "oracle_calls" in s]
    return mean_rounded_up(counts) if counts else None


def _label_axes(ax, xlabel: str, ylabel: str, title: str, legend_size: int) -> None:
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=legend_size, loc="upper left", bbox_to_anchor=(0.0, -0.2), frameon=False)  # below the axes


def _line_plot(series: dict[str, dict], path: Path, figsize: tuple[float, float], xlabel: str, ylabel: str,
               title: str, legend_size: int) -> Path:
    """One line with markers per label of `series` ({label: {x: y}}), labels sorted, x ascending."""
    fig, ax = plt.subplots(figsize=figsize)
    for label, pts in sorted(series.items()):
        xs = sorted(pts)
        ax.plot(xs, [pts[x] for x in xs], marker="o", label=label)
    _label_axes(ax, xlabel, ylabel, title, legend_size)
    return _save(fig, path)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120, bbox_inches="tight")  # keeps a legend placed outside the axes
    plt.close(fig)
    return path


def psnr_vs_views(runs, path: Path) -> Path | None:
    """Test PSNR against the number of training views, one line per (setup, method setting), mean over runs.
    Stage points are measured before each acquisition; the last point is after the final stage."""
    curves: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in runs:
        for views, value in r.psnr_points():
            curves[f"{r.setup}: {r.setting}"][views].append(value)
    if not curves:
        return None
    means = {label: {views: mean(values) for views, values in pts.items()} for label, pts in curves.items()}
    return _line_plot(means, path, (6.5, 4.2), "training views", "test PSNR (dB)", "Test PSNR during acquisition", 7)


def oracles_vs_k(runs, path: Path) -> Path | None:
    """Conservative oracle evaluations per step against K, one line per (method, options) that calls the oracle and
    was run at two or more K (exhaustive greedy grows with K, the stochastic selectors do not)."""
    groups: dict[str, dict[int, list]] = defaultdict(lambda: defaultdict(list))
    for r in runs:
        if any(s.get("oracle_calls", {}).get("conservative") for s in r.stages):
            groups[f"{r.method} {r.options_label}".strip()][r.k].append(r)
    series = {label: {k: _per_step(rs) for k, rs in by_k.items()} for label, by_k in groups.items()}
    series = {label: pts for label, pts in series.items() if len(pts) > 1}
    if not series:
        return None
    return _line_plot(series, path, (5, 3.8), "views per step K", "oracle evaluations per step", "Oracle cost vs K", 8)


def eps_tradeoff(runs, path: Path) -> Path | None:
    """Selectors with an `eps` option: conservative oracle evaluations per step against mean final test PSNR, one
    point per (method, K, eps), annotated with eps; needs at least two eps values."""
    groups: dict[tuple, list] = defaultdict(list)
    for r in runs:
        if "eps" in r.options and r.results is not None and r.stages:
            groups[(r.method, r.k, float(r.options["eps"]))].append(r)
    if len({key[2] for key in groups}) < 2:
        return None
    markers = dict(zip(sorted({key[0] for key in groups}), "os^Dvp*"))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for (method, k, eps), group in sorted(groups.items()):
        x, y = _per_step(group), mean(float(r.results["PSNR"]) for r in group)
        ax.scatter([x], [y], marker=markers.get(method, "o"), label=f"{method} K={k} eps={eps:g}")
        ax.annotate(f"{eps:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    _label_axes(ax, "oracle evaluations per step (conservative)", "test PSNR (dB)", "eps trade-off", 7)
    return _save(fig, path)


def top_down(positions: np.ndarray) -> np.ndarray:
    """Camera centres [C,3] -> [C,2] coordinates in their principal plane (the two directions of largest spread:
    the ground plane of a hemisphere or ring of cameras, whatever the dataset's up axis)."""
    centred = positions - positions.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return centred @ vt[:2].T


def chosen_cameras(runs, path: Path) -> Path | None:
    """Top-down camera centres of one scene: candidates grey, seed views black stars, picks coloured by step.
    One panel per method setting (lowest seed), for the (setup, scene) with cameras.json and the most settings."""
    with_cams = [r for r in runs if r.cameras and r.stages]
    if not with_cams:
        return None
    settings: dict[tuple, set] = defaultdict(set)
    for r in with_cams:
        settings[(r.setup, r.scene)].add(r.setting)
    setup, scene = max(sorted(settings), key=lambda key: len(settings[key]))
    chosen = {}
    for r in sorted(with_cams, key=lambda r: r.seed):
        if (r.setup, r.scene) == (setup, scene):
            chosen.setdefault(r.setting, r)
    fig, axes = plt.subplots(1, len(chosen), figsize=(3.6 * len(chosen), 3.9), squeeze=False)
    cmap = plt.get_cmap("viridis")
    for ax, (setting, r) in zip(axes[0], sorted(chosen.items())):
        # cameras.json lists test cameras first (as 3DGS does): training view v is entry len(test) + v.
        first = r.stages[0]
        num_test = max(0, len(r.cameras) - len(first.get("train_views", [])) - first.get("candidates", 0))
        train_cams = r.cameras[num_test:]
        ids = list(range(len(train_cams)))
        xy = dict(zip(ids, top_down(np.array([c["position"] for c in train_cams], dtype=float))))

        def scatter(views, **kw):
            pts = np.array([xy[v] for v in views if v in xy]).reshape(-1, 2)
            ax.scatter(pts[:, 0], pts[:, 1], **kw)

        scatter(ids, c="lightgrey", s=12, label="candidates")
        scatter(r.stages[0].get("train_views", []), c="black", marker="*", s=90, label="seed")
        for i, stage in enumerate(r.stages):
            scatter(stage.get("selected", []), color=cmap(i / max(1, len(r.stages) - 1)), s=40, label=f"step {i + 1}")
        title = "\n".join(textwrap.wrap(setting, 34, break_on_hyphens=False)) + f"\nseed {r.seed}"
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    axes[0][-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle(f"Chosen cameras, {setup} / {scene} (top-down)")
    return _save(fig, path)


def write_all(runs, out: Path) -> list[Path]:
    """Every plot the runs support, written into `out`; returns the files written."""
    written = [psnr_vs_views(runs, out / "psnr_vs_views.png"), oracles_vs_k(runs, out / "oracles_vs_k.png"),
               eps_tradeoff(runs, out / "eps_tradeoff.png"), chosen_cameras(runs, out / "chosen_cameras.png")]
    return [p for p in written if p is not None]
