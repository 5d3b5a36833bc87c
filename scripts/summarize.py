"""Aggregate experiment runs into paper-style tables (summary.md, summary.csv) and plots.

    python scripts/summarize.py output/experiments/setup1 [more roots...] [--out DIR]

A run is a model directory with `selection.json`; its setup and scene are read from the layout the experiment
scripts write (OUT/<setup>/<scene>/<tag>/seed<S>), its method, K and eps from its selection.json.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from statistics import mean, pstdev

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from utils.errors import UserError, run_cli  # noqa: E402
from utils.io import atomic_write  # noqa: E402


@dataclass
class Run:
    path: Path
    setup: str
    scene: str
    method: str
    k: int
    eps: float
    seed: int
    stages: list[dict]
    final: dict | None
    results: dict | None  # the newest ours_N of results.json
    cameras: list[dict] = field(default_factory=list)

    @property
    def setting(self) -> str:
        """Method label with the settings that vary within a setup."""
        label = f"{self.method} K={self.k}"
        return label + (f" eps={self.eps:g}" if self.method in ("lite_gs", "ssg") else "")


def _read_json(path: Path, what: str):
    try:
        return json.loads(path.read_text())
    except ValueError:
        raise UserError(f"{path} is truncated or not valid JSON; rerun that {what} (delete the file to skip it)") from None


def load_run(selection_file: Path) -> Run:
    model = selection_file.parent
    sel = _read_json(selection_file, "training run")
    if not isinstance(sel, dict) or "config" not in sel or "stages" not in sel:
        raise UserError(f"{selection_file} lacks 'config'/'stages'; it was not written by train.py")
    cfg = sel["config"]
    parts = model.parts
    setup_idx = next((i for i in range(len(parts) - 1, -1, -1)
                      if re.fullmatch(r"setup\d+|ablation_\w+", parts[i])), None)
    setup = parts[setup_idx] if setup_idx is not None else model.parent.name
    scene = parts[setup_idx + 1] if setup_idx is not None and setup_idx + 1 < len(parts) else "scene"
    results = None
    if (model / "results.json").is_file():
        all_results = _read_json(model / "results.json", "metrics.py")
        if all_results:
            newest = max(all_results, key=lambda k: int(k.split("_")[-1]))
            results = all_results[newest]
    cameras = _read_json(model / "cameras.json", "training run") if (model / "cameras.json").is_file() else []
    return Run(model, setup, scene, cfg["method"], int(cfg["views_per_step"]), float(cfg["eps"]),
               int(cfg.get("seed", 0)), sel["stages"], sel.get("final"), results, cameras)


def find_runs(roots: list[str]) -> list[Run]:
    files = []
    for root in roots:
        if not Path(root).exists():
            raise UserError(f"{root} does not exist; pass the output root of an experiment script")
        files += sorted(Path(root).rglob("selection.json"))
    if not files:
        raise UserError(f"no runs (selection.json) under {', '.join(roots)}; run an experiment script first")
    return [load_run(f) for f in files]


def per_step_oracles(run: Run, kind: str) -> int:
    """Oracle evaluations per acquisition step, averaged over steps and rounded up (as the paper reports)."""
    counts = [s["oracle_calls"][kind] for s in run.stages]
    return math.ceil(sum(counts) / len(counts)) if counts else 0


def _fmt(values: list[float], digits: int) -> str:
    if not values:
        return "n/a"
    return f"{mean(values):.{digits}f} ± {pstdev(values):.{digits}f}" if len(values) > 1 else f"{values[0]:.{digits}f}"


def quality_rows(runs: list[Run]) -> list[dict]:
    groups: dict[tuple, list[Run]] = defaultdict(list)
    for r in runs:
        groups[(r.setup, r.setting)].append(r)
    rows = []
    for (setup, setting), group in sorted(groups.items()):
        done = [r for r in group if r.results]
        lpips = [r.results["LPIPS"] for r in done if r.results.get("LPIPS") is not None]
        variant = next((r.results.get("LPIPS_variant") for r in done if r.results.get("LPIPS_variant")), None)
        rows.append({
            "setup": setup, "method": setting, "runs": len(done), "incomplete": len(group) - len(done),
            "scenes": " ".join(sorted({r.scene for r in group})),
            "PSNR": _fmt([r.results["PSNR"] for r in done], 2), "SSIM": _fmt([r.results["SSIM"] for r in done], 4),
            "LPIPS": _fmt(lpips, 4) + (f" ({variant})" if lpips else ""),
            "select_s": _fmt([sum(s["select_seconds"] for s in r.stages) for r in group], 1),
            "fisher_s": _fmt([sum(s["fisher_seconds"] for s in r.stages) for r in group], 1),
        })
    return rows


def oracle_rows(runs: list[Run]) -> list[dict]:
    """Setup x (K, eps): per-step oracle counts of every oracle-based method, and lite_gs's reduction vs pop_gs."""
    groups: dict[tuple, dict[str, list[Run]]] = defaultdict(lambda: defaultdict(list))
    for r in runs:
        if r.method != "random":
            key_eps = r.eps if r.method in ("lite_gs", "ssg") else None
            groups[(r.setup, r.k)][(r.method, key_eps)].append(r)
    rows = []
    for (setup, k), by_method in sorted(groups.items()):
        pop = by_method.get(("pop_gs", None), [])
        pop_cons = max((per_step_oracles(r, "conservative") for r in pop), default=None)
        for (method, eps), group in sorted(by_method.items(), key=lambda kv: (kv[0][0], kv[0][1] or 0)):
            cons = max(per_step_oracles(r, "conservative") for r in group)
            ev = max(per_step_oracles(r, "evaluated") for r in group)
            rows.append({
                "setup": setup, "K": k, "method": method, "eps": "" if eps is None else f"{eps:g}",
                "conservative": cons, "evaluated": ev,
                "reduction_vs_pop_gs_%": "" if pop_cons in (None, 0) or method == "pop_gs"
                else f"{100 * (1 - cons / pop_cons):.2f}",
            })
    return rows


def markdown_table(rows: list[dict]) -> str:
    if not rows:
        return "(none)\n"
    cols = list(rows[0])
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def write_outputs(runs: list[Run], out: Path) -> list[Path]:
    from utils import plots

    out.mkdir(parents=True, exist_ok=True)
    quality, oracles = quality_rows(runs), oracle_rows(runs)
    md = ["# Summary", "", f"{len(runs)} runs from {len({r.setup for r in runs})} setup(s).", "",
          "## Quality (test views, mean ± std over seeds and scenes)", "", markdown_table(quality),
          "## Oracle evaluations per acquisition step (averaged over steps, rounded up)", "",
          markdown_table(oracles)]
    atomic_write(out / "summary.md", lambda tmp: Path(tmp).write_text("\n".join(md)))

    def write_csv(tmp: str) -> None:
        with open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(["table"] + list(quality[0]) if quality else ["table"])
            for row in quality:
                writer.writerow(["quality"] + list(row.values()))
            if oracles:
                writer.writerow(["table"] + list(oracles[0]))
                for row in oracles:
                    writer.writerow(["oracles"] + list(row.values()))
    atomic_write(out / "summary.csv", write_csv)
    return [out / "summary.md", out / "summary.csv"] + plots.write_all(runs, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("roots", nargs="+", help="experiment output roots (searched recursively)")
    parser.add_argument("--out", default=None, help="where to write summary.md/csv and plots (default: first root)")
    args = parser.parse_args()
    runs = find_runs(args.roots)
    written = write_outputs(runs, Path(args.out or args.roots[0]))
    print(Path(written[0]).read_text())
    print("wrote " + ", ".join(str(p) for p in written))


if __name__ == "__main__":
    run_cli(main)
