"""Plots of experiment runs (matplotlib, Agg): PSNR vs views, oracle counts vs K, the eps trade-off, and the
camera positions each method chose. Each function takes runs from scripts/summarize.py and writes one PNG."""
from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from statistics import mean

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def _oracles_per_step(run, kind: str = "conservative") -> int:
    counts = [s["oracle_calls"][kind] for s in run.stages]
    return math.ceil(sum(counts) / len(counts)) if counts else 0


def psnr_vs_views(runs, path: Path) -> Path | None:
    """Test PSNR against the number of training views, one line per (setup, method setting)."""
    curves: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in runs:
        points = [(len(s["train_views"]), s["test_psnr"]) for s in r.stages]
        if r.final:
            points.append((len(r.final["train_views"]), r.final["test_psnr"]))
        for views, value in points:
            if value is not None:
                curves[f"{r.setup}: {r.setting}"][views].append(value)
    if not curves:
        return None
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for label, pts in sorted(curves.items()):
        xs = sorted(pts)
        ax.plot(xs, [mean(pts[x]) for x in xs], marker="o", label=label)
    ax.set_xlabel("training views")
    ax.set_ylabel("test PSNR (dB)")
    ax.set_title("Test PSNR during acquisition (last point: after refinement)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def oracles_vs_k(runs, path: Path) -> Path | None:
    """Conservative oracle evaluations per step against K for pop_gs and lite_gs (eps = 0.1)."""
    series: dict[str, dict[int, int]] = defaultdict(dict)
    for r in runs:
        if r.method == "pop_gs" or (r.method == "lite_gs" and abs(r.eps - 0.1) < 1e-9):
            series[r.method][r.k] = max(series[r.method].get(r.k, 0), _oracles_per_step(r))
    if not any(len(v) > 1 for v in series.values()):
        return None
    fig, ax = plt.subplots(figsize=(5, 3.8))
    for method, pts in sorted(series.items()):
        ks = sorted(pts)
        ax.plot(ks, [pts[k] for k in ks], marker="o", label=method)
    ax.set_xlabel("views per step K")
    ax.set_ylabel("oracle evaluations per step")
    ax.set_title("Oracle cost vs K (lite_gs: eps = 0.1)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def eps_tradeoff(runs, path: Path) -> Path | None:
    """lite_gs/ssg: oracle evaluations per step against final test PSNR, labelled by eps."""
    pts: dict[tuple, list] = defaultdict(list)
    for r in runs:
        if r.method in ("lite_gs", "ssg") and r.results:
            pts[(r.method, r.k, r.eps)].append((_oracles_per_step(r), r.results["PSNR"]))
    if len({key[2] for key in pts}) < 2:
        return None
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for (method, k, eps), values in sorted(pts.items()):
        x, y = mean(v[0] for v in values), mean(v[1] for v in values)
        ax.scatter([x], [y], marker="o" if method == "lite_gs" else "s", label=f"{method} K={k} eps={eps:g}")
        ax.annotate(f"{eps:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("oracle evaluations per step (conservative)")
    ax.set_ylabel("test PSNR (dB)")
    ax.set_title("eps trade-off")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def chosen_cameras(runs, path: Path) -> Path | None:
    """Top-down view of the camera centres: candidates grey, seed views black, picks coloured by stage.
    One panel per method setting, for the first scene and seed found."""
    with_cams = [r for r in runs if r.cameras and r.stages]
    if not with_cams:
        return None
    scene, setup = with_cams[0].scene, with_cams[0].setup
    chosen = {}
    for r in sorted(with_cams, key=lambda r: r.seed):
        if r.scene == scene and r.setup == setup:
            chosen.setdefault(r.setting, r)
    fig, axes = plt.subplots(1, len(chosen), figsize=(3.6 * len(chosen), 3.8), squeeze=False)
    cmap = plt.get_cmap("viridis")
    for ax, (setting, r) in zip(axes[0], sorted(chosen.items())):
        pos = {c["id"]: c["position"] for c in r.cameras}
        ax.scatter([p[0] for p in pos.values()], [p[1] for p in pos.values()], c="lightgrey", s=12, label="candidates")
        seeds = r.stages[0]["train_views"]
        ax.scatter([pos[v][0] for v in seeds], [pos[v][1] for v in seeds], c="black", marker="*", s=90, label="seed")
        for i, stage in enumerate(r.stages):
            color = cmap(i / max(1, len(r.stages) - 1))
            ax.scatter([pos[v][0] for v in stage["selected"]], [pos[v][1] for v in stage["selected"]],
                       color=color, s=40, label=f"step {i + 1}")
        ax.set_title(f"{setting}\nseed {r.seed}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"Chosen cameras, {setup} / {scene} (top view)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def write_all(runs, out: Path) -> list[Path]:
    """Every plot that the runs support; returns the files written."""
    written = [psnr_vs_views(runs, out / "psnr_vs_views.png"), oracles_vs_k(runs, out / "oracles_vs_k.png"),
               eps_tradeoff(runs, out / "eps_tradeoff.png"), chosen_cameras(runs, out / "chosen_cameras.png")]
    return [p for p in written if p is not None]
