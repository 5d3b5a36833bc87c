"""Aggregate experiment runs into paper-style tables (summary.md, summary.csv) and plots (PNG); the library behind
scripts/summarize.py and the summary `scripts/grid.py` writes at the end of a grid.

    runs = find_runs([root]); write_outputs(runs, out_dir); check_readable(runs)

A run is a model directory holding selection.json, run_status.json or cfg_args. Its setup and scene come from the
layout the experiment scripts write (OUT/<setup>/<scene>/<tag>/seed<S>); its method, K, selector options (e.g. eps)
and seed from selection.json (or cfg_args before the first acquisition step). A run without results.json is listed
as incomplete. Nothing here knows selector names: a method's setting is its name, K and the options its
selection.json records.
"""
from __future__ import annotations

import csv
import math
import re
import shlex
from collections import defaultdict
from dataclasses import dataclass, field
from itertools import groupby
from pathlib import Path
from statistics import mean, stdev
from typing import Any

from active.oracle_counts import exhaustive_count, mean_rounded_up
from experiments.flags import RECORD as GRID_RECORD
from experiments.jobs import recorded_job_seconds
from experiments.paired import against_leader, leader_table
from experiments.progress import STATUS as GRID_STATUS
from utils.errors import UserError
from utils.io import atomic_write, read_json
from utils.model_dir import CAMERAS, CFG_ARGS, METHOD_PATTERN, RESULTS, RUN_STATUS, SELECTION

MARKERS = (SELECTION, RUN_STATUS, CFG_ARGS)  # any of these makes a directory a run


@dataclass
class Run:
    """One model directory, as far as it could be read."""
    path: Path
    setup: str
    scene: str
    method: str
    k: int
    options: dict  # the selector's own options, as selection.json records them (e.g. {"eps": 0.1})
    seed: int
    stages: list[dict] = field(default_factory=list)  # selection.json "stages"
    final: dict | None = None  # selection.json "final" (train_views, test_psnr after the last stage)
    results: dict | None = None  # the newest ours_N entry of results.json
    cameras: list[dict] = field(default_factory=list)  # cameras.json (test cameras, then train cameras)
    problem: str = ""  # why the run has no results yet ("" when complete)
    sessions: list[dict] = field(default_factory=list)  # selection.json "sessions": code, machine, date per start
    job_seconds: float | None = None  # train + render + metrics wall time of its grid jobs (JOB_TIMES, else
    # grid_status.json's last invocation)
    protocol: str = ""  # the run's departures from the setup's protocol that change its views ('' for none)

    @property
    def options_label(self) -> str:
        """The selector options as 'name=value' words ('' for a selector without options); an option set to "none"
        is off (e.g. gain_weight=none, the paper's criterion) and is left out, so labels stay as they were before
        such an option existed."""
        return " ".join(f"{name}={value:g}" if isinstance(value, float) else f"{name}={value}"
                        for name, value in sorted(self.options.items()) if value != "none")

    def psnr_points(self) -> list[tuple[int, float]]:
        """(training views, test PSNR) as the run acquired: each stage's value, measured before its acquisition,
        then the final one after the last stage; non-finite or missing values left out."""
        points = [(len(s.get("train_views", [])), s.get("test_psnr")) for s in self.stages]
        if isinstance(self.final, dict):
            points.append((len(self.final.get("train_views", [])), self.final.get("test_psnr")))
        return [(views, float(value)) for views, value in points
                if isinstance(value, (int, float)) and math.isfinite(value)]

    @property
    def setting(self) -> str:
        """Method label with the settings that vary within a setup: K, the selector's options and the protocol's
        departures (so runs with other seed views or another selector at some acquisition are never pooled)."""
        return " ".join(part for part in (self.method, f"K={self.k}", self.options_label, self.protocol) if part)


def protocol_label(cfg: dict) -> str:
    """'seed_start=random' and 'stage_method=S:NAME,...' where a run's recorded config departs from the default
    seed views or has another selector at some acquisition ('' for neither)."""
    words = []
    if cfg.get("seed_start", "first") != "first":
        words.append(f"seed_start={cfg['seed_start']}")
    if cfg.get("stage_method"):
        words.append("stage_method=" + ",".join(cfg["stage_method"]))
    return " ".join(words)


def _read_json(path: Path, kind: type = dict) -> Any:
    """A run's or grid's file, None when it is missing or damaged (then with a warning): a summary skips it."""
    return read_json(path, missing="none", damaged="warn", kind=kind)


def _layout(model: Path) -> tuple[str, str]:
    """(setup, scene) from OUT/<setup>/<scene>/<tag>/seed<S>; falls back to the directory's ancestors."""
    parts = model.resolve().parts
    for i in range(len(parts) - 2, -1, -1):
        if re.fullmatch(r"setup\d+|ablation_\w+", parts[i]):
            return parts[i], parts[i + 1]
    return (parts[-4] if len(parts) >= 4 else "-"), (parts[-3] if len(parts) >= 3 else "-")


def load_run(model: Path) -> Run:
    """Read one model directory; never raises for missing or unreadable pieces (they become `problem`)."""
    setup, scene = _layout(model)
    sel = _read_json(model / SELECTION)
    cfg_args = _read_json(model / CFG_ARGS)
    if isinstance(sel, dict) and isinstance(sel.get("config"), dict):
        cfg = sel["config"]
    elif isinstance(cfg_args, dict):
        cfg = {**cfg_args.get("active", {}), **cfg_args.get("run", {})}
    else:
        cfg = {}
    options = cfg.get("selector_options")
    run = Run(model, setup, scene, str(cfg.get("method") or "?"), int(cfg.get("views_per_step", 0)),
              options if isinstance(options, dict) else {}, int(cfg.get("seed", -1)), protocol=protocol_label(cfg))
    if isinstance(sel, dict):
        run.stages = [s for s in sel.get("stages", []) if isinstance(s, dict)]
        run.final = sel.get("final")
        sessions = sel.get("sessions")
        run.sessions = [s for s in sessions if isinstance(s, dict)] if isinstance(sessions, list) else []
    run.cameras = _read_json(model / CAMERAS, list) or []
    results = _read_json(model / RESULTS)
    entries = {k: v for k, v in (results or {}).items() if METHOD_PATTERN.fullmatch(k) and isinstance(v, dict)}
    if (model / SELECTION).is_file() and not isinstance(sel, dict):
        run.problem = "no readable selection.json (truncated or not valid JSON)"
    elif entries:
        run.results = entries[max(entries, key=lambda k: int(k.split("_")[1]))]
    elif not cfg:
        run.problem = "no readable selection.json or cfg_args"
    else:
        status = _read_json(model / RUN_STATUS)
        run.problem = f"no results.json ({_training_state(status, len(run.stages))})"
    return run


def _training_state(status: object, steps_done: int) -> str:
    """What run_status.json says of an unfinished run. "running" is only the last record: the process may have
    stopped since, so the time of that record is given instead of a claim that it is still running."""
    if not isinstance(status, dict):
        return f"no run_status.json, {steps_done} step(s) done"
    state = status.get("status", "?")
    if state == "complete":
        return "training complete: render + metrics missing"
    if state != "running":
        return f"training {state}, {steps_done} step(s) done"
    total = status.get("total_iterations", "?")
    progress = f", iteration {status['iteration']}/{total}" if "iteration" in status else ""
    when = f" at {status['updated']}" if "updated" in status else ""
    return f"training unfinished: {steps_done} step(s) done{progress}, last progress recorded{when}"


def find_runs(roots: list[str]) -> list[Run]:
    """Every run below the roots (searched recursively), each once, in path order."""
    dirs: set[Path] = set()
    for root in roots:
        if not Path(root).is_dir():
            raise UserError(f"{root} is not a directory; pass the output root of an experiment script")
        for marker in MARKERS:
            dirs.update(p.parent.resolve() for p in Path(root).rglob(marker))
    if not dirs:
        raise UserError(f"no runs (selection.json / run_status.json) under {', '.join(roots)}; "
                        "run an experiment script first")
    runs = [load_run(d) for d in sorted(dirs)]
    seconds: dict[Path, float] = {}  # every grid's finished jobs, read once per grid
    for grid_dir in {d for r in runs if (d := grid_dir_of(r)) is not None}:
        seconds.update(done_job_seconds(_grid_status(grid_dir)))
    for run in runs:  # the run's own record of every invocation, else its grid's last invocation
        recorded = recorded_job_seconds(run.path)
        run.job_seconds = recorded if recorded is not None else seconds.get(run.path.resolve())
    return runs


def grid_dir_of(run: Run) -> Path | None:
    """OUT/<setup> of a run made by scripts/grid.py (the directory holding grid.json), else None."""
    parents = run.path.resolve().parents
    return parents[2] if len(parents) > 2 and (parents[2] / GRID_RECORD).is_file() else None


def _grid_status(grid_dir: Path) -> dict:
    """grid_status.json of a grid ({} when it is missing or unreadable)."""
    return _read_json(grid_dir / GRID_STATUS) or {}


def done_job_seconds(status: dict) -> dict[Path, float]:
    """Model directory -> wall seconds of each job a grid's last invocation ran to the end (`_grid_status`)."""
    return {Path(str(j.get("model_dir"))).resolve(): float(j["seconds"]) for j in status.get("jobs", [])
            if isinstance(j, dict) and j.get("state") == "done" and isinstance(j.get("seconds"), (int, float))}


def mean_std(values: list[float]) -> tuple[float | None, float | None]:
    """(mean, sample standard deviation); std is None for fewer than two values, both None for none."""
    if not values:
        return None, None
    return mean(values), (stdev(values) if len(values) > 1 else None)


def per_step_count(runs: list[Run], kind: str) -> int | None:
    """Oracle evaluations per acquisition step, averaged over all steps of the runs, rounded up (the paper's way)."""
    counts = [s["oracle_calls"][kind] for r in runs for s in r.stages if "oracle_calls" in s]
    return mean_rounded_up(counts) if counts else None


def quality_rows(runs: list[Run]) -> list[dict]:
    """Setup x method setting: PSNR / SSIM / LPIPS mean and std over the complete runs (seeds and scenes), and the
    uncertainty metrics when some run has them (render.py --uncertainty): Spearman and AUSE_MAE_norm of every map
    kind over the image and the object (results.json keys "METRIC/KIND/REGION", see metrics.py)."""
    metrics = ("PSNR", "SSIM", "LPIPS")
    found = {k for r in runs if r.results is not None for k in r.results if k.count("/") == 2}
    metrics += tuple(sorted((k for k in found if k.split("/")[0] in ("Spearman", "AUSE_MAE_norm")),
                            key=lambda k: (k.split("/")[1], k.split("/")[2], k.split("/")[0] != "Spearman")))
    groups: dict[tuple, list[Run]] = defaultdict(list)
    for r in runs:
        groups[(r.setup, r.setting)].append(r)
    rows = []
    for (setup, setting), group in sorted(groups.items()):
        done = [r.results for r in group if r.results is not None]
        row = {"setup": setup, "method": setting, "scenes": " ".join(sorted({r.scene for r in group})),
               "runs": len(done), "incomplete": len(group) - len(done)}
        for metric in metrics:
            values = [float(d[metric]) for d in done if isinstance(d.get(metric), (int, float))]
            row[f"{metric}_mean"], row[f"{metric}_std"] = mean_std(values)
        row["LPIPS_variant"] = next((d["LPIPS_variant"] for d in done
                                     if d.get("LPIPS") is not None and d.get("LPIPS_variant")), "")
        rows.append(row)
    return rows


def seed_rows(runs: list[Run], metric: str = "PSNR") -> list[dict]:
    """Setup x scene x method setting: `metric` of every complete seed (columns seed_<S>), mean and std over them,
    and the orderings per seed, not averaged away: `first_in` = seeds in which the setting has the scene's best
    value (ties count for each), `above_random_in` = seeds in which it beats the scene's `random` run of the same
    seed ("" for random itself, or when the scene has no random run)."""
    complete = [r for r in runs if r.results is not None and isinstance(r.results.get(metric), (int, float))]
    scenes: dict[tuple, dict[str, dict[int, float]]] = defaultdict(lambda: defaultdict(dict))
    for r in complete:
        scenes[(r.setup, r.scene)][r.setting][r.seed] = float(r.results[metric])
    rows = []
    for (setup, scene), by_setting in sorted(scenes.items()):
        seeds = sorted({seed for values in by_setting.values() for seed in values})
        best = {seed: max(v[seed] for v in by_setting.values() if seed in v) for seed in seeds}
        random_runs = next((v for setting, v in by_setting.items() if setting.split()[0] == "random"), None)
        for setting, values in sorted(by_setting.items()):
            row = {"setup": setup, "scene": scene, "method": setting}
            row.update({f"seed_{seed}": values.get(seed) for seed in seeds})
            row[f"{metric}_mean"], row[f"{metric}_std"] = mean_std(list(values.values()))
            row["first_in"] = f"{sum(values[s] == best[s] for s in values)}/{len(values)}"
            shared = [s for s in values if random_runs is not None and s in random_runs]
            row["above_random_in"] = ("" if random_runs is None or values is random_runs or not shared
                                      else f"{sum(values[s] > random_runs[s] for s in shared)}/{len(shared)}")
            rows.append(row)
    return rows


def views_rows(runs: list[Run]) -> list[dict]:
    """Setup x scene x method setting: test PSNR mean and std over seeds at each number of training views
    (columns views_<N>), from the runs' stage records (`Run.psnr_points`): where along the acquisition a selector gains
    or loses, which the final value alone does not say. Complete runs only, as in the other tables."""
    groups: dict[tuple, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in (r for r in runs if r.results is not None):
        for views, value in r.psnr_points():
            groups[(r.setup, r.scene, r.setting)][views].append(value)
    rows = []
    for (setup, scene, setting), by_views in sorted(groups.items()):
        row = {"setup": setup, "scene": scene, "method": setting}
        for views in sorted(by_views):
            row[f"views_{views}_mean"], row[f"views_{views}_std"] = mean_std(by_views[views])
        rows.append(row)
    return rows


def views_tables(rows: list[dict]) -> str:
    """`views_rows` as one markdown table per setup and scene (their view counts differ), mean ± std per cell."""
    parts = []
    for (setup, scene), group in groupby(rows, key=lambda row: (row["setup"], row["scene"])):
        group = list(group)
        counts = sorted({int(c.split("_")[1]) for row in group for c in row if c.endswith("_mean")})
        cells = [{"method": row["method"], **{f"{n} views_mean": row.get(f"views_{n}_mean") for n in counts},
                  **{f"{n} views_std": row.get(f"views_{n}_std") for n in counts}} for row in group]
        parts.append(f"### {setup}, {scene}\n\n" + markdown_table(cells, {}))
    return "\n".join(parts) if parts else "(none)\n"


def seed_tables(rows: list[dict], digits: int = 2) -> str:
    """`seed_rows` as one markdown table per setup and scene, the best value of each seed in bold."""
    parts = []
    for key in dict.fromkeys((r["setup"], r["scene"]) for r in rows):
        group = [r for r in rows if (r["setup"], r["scene"]) == key]
        seed_cols = sorted({c for r in group for c in r if c.startswith("seed_")}, key=lambda c: int(c[5:]))
        best = {c: max(r[c] for r in group if r.get(c) is not None) for c in seed_cols}
        metric = next(c for c in group[0] if c.endswith("_mean"))

        def seed_cell(row: dict, col: str) -> str:
            value = row.get(col)
            if value is None:
                return "–"
            return f"**{value:.{digits}f}**" if value == best[col] else f"{value:.{digits}f}"
        head = ["method"] + [c.replace("_", " ") for c in seed_cols] + [metric[:-5] + " mean ± std", "first in",
                                                                         "above random in"]
        lines = [f"### {key[0]}, {key[1]}", "", "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head)
                 + "|"]
        for r in group:
            cells = [r["method"]] + [seed_cell(r, c) for c in seed_cols] + [_cell(r, metric, digits), r["first_in"],
                                                                            r["above_random_in"] or "–"]
            lines.append("| " + " | ".join(cells) + " |")
        parts.append("\n".join(lines) + "\n")
    return "\n".join(parts) if parts else "(none)\n"


def stage_exhaustive_count(stage: dict) -> int:
    """What exhaustive greedy (every remaining candidate at every pick) evaluates in a step: sum_{j<k} (M - j)."""
    return exhaustive_count(int(stage.get("candidates", 0)), len(stage.get("selected", [])))


def oracle_rows(runs: list[Run]) -> list[dict]:
    """Setup x scene x K x (method, options): oracle evaluations per step and the reduction relative to exhaustive
    greedy on the same steps (sum_j (M - j) per step, averaged and rounded up like the counts)."""
    groups: dict[tuple, dict[tuple, list[Run]]] = defaultdict(lambda: defaultdict(list))
    for r in runs:
        if any(s.get("oracle_calls", {}).get("conservative") for s in r.stages):
            groups[(r.setup, r.scene, r.k)][(r.method, r.options_label)].append(r)
    rows = []
    for (setup, scene, k), by_method in sorted(groups.items()):
        for (method, options), group in sorted(by_method.items()):
            cons, evaluated = per_step_count(group, "conservative"), per_step_count(group, "evaluated")
            steps = [stage_exhaustive_count(s) for r in group for s in r.stages if "oracle_calls" in s]
            exhaustive = mean_rounded_up(steps) if steps else None
            reduction = 100.0 * (1.0 - cons / exhaustive) if exhaustive and cons is not None else None
            rows.append({"setup": setup, "scene": scene, "K": k, "method": method, "options": options,
                         "runs": len(group), "steps": sum(len(r.stages) for r in group), "conservative": cons,
                         "evaluated": evaluated, "exhaustive": exhaustive, "reduction_%": reduction})
    return rows


def time_rows(runs: list[Run]) -> list[dict]:
    """Setup x method setting: selection wall time (select_seconds, which includes the Fisher blocks) and the
    Fisher part, per run and per acquisition step."""
    groups: dict[tuple, list[Run]] = defaultdict(list)
    for r in runs:
        if r.stages:
            groups[(r.setup, r.setting)].append(r)
    rows = []
    for (setup, setting), group in sorted(groups.items()):
        steps = [s for r in group for s in r.stages]
        row = {"setup": setup, "method": setting, "runs": len(group), "steps": len(steps)}
        row["select_s_per_run_mean"], row["select_s_per_run_std"] = mean_std(
            [sum(float(s.get("select_seconds", 0.0)) for s in r.stages) for r in group])
        row["fisher_s_per_run_mean"], row["fisher_s_per_run_std"] = mean_std(
            [sum(float(s.get("fisher_seconds", 0.0)) for s in r.stages) for r in group])
        row["select_s_per_step"] = mean(float(s.get("select_seconds", 0.0)) for s in steps)
        jobs = [r.job_seconds / 60 for r in group if r.job_seconds is not None]
        row["job_min_mean"], row["job_min_std"] = mean_std(jobs) if jobs else (None, None)
        rows.append(row)
    return rows


def provenance_lines(runs: list[Run]) -> list[str]:
    """Markdown bullets: the machines, thread counts, dates and code commits the runs were trained with (from the
    sessions train.py records), each with its number of runs; a run resumed under other code shows 'A then B'."""
    def count(label: str, values: list[str]) -> str:
        tally = defaultdict(int)
        for value in values:
            tally[value] += 1
        return f"- {label}: " + "; ".join(f"{value} ({n} run{'s' if n > 1 else ''})" for value, n in tally.items())

    recorded = [r for r in runs if r.sessions]
    if not recorded:
        return ["- not recorded (runs trained before train.py wrote sessions into selection.json)"]

    def joined(run: Run, key: str) -> str:  # one value, or 'A then B' when a resume changed it
        return " then ".join(dict.fromkeys(str(s.get(key, "?")) for s in run.sessions))

    starts = sorted(str(s.get("started", "?")) for r in recorded for s in r.sessions)
    machines = [f"{joined(r, 'machine')}, {joined(r, 'cpus')} x {joined(r, 'cpu')}, torch {joined(r, 'torch')}, "
                f"{joined(r, 'device')}" for r in recorded]
    lines = [count("machine", machines),
             count("threads per process", [joined(r, "threads") for r in recorded]),
             f"- trained between {starts[0].replace('T', ' ')} and {starts[-1].replace('T', ' ')} (session starts)",
             count("code", [joined(r, "code") for r in recorded])]
    if len(recorded) < len(runs):
        lines.append(f"- {len(runs) - len(recorded)} run(s) without a record (trained before sessions were written)")
    return lines


def grid_lines(runs: list[Run]) -> list[str]:
    """Markdown bullets, one per grid the runs came from: its scale flags (grid.json) and the wall time of its
    last invocation with the job time spent in it (grid_status.json)."""
    lines = []
    for grid_dir in sorted({d for r in runs if (d := grid_dir_of(r)) is not None}):
        record = _read_json(grid_dir / GRID_RECORD) or {}
        scale = ", ".join(f"--{k} {record[k]}" for k in ("resolution", "iter_scale", "stage_scale", "num_points")
                          if record.get(k) is not None)
        extra = shlex.join(record.get("train_args") or []) or "none"
        line = f"- grid `{grid_dir.name}`: {scale}; train.py flags after `--`: {extra}"
        status = _grid_status(grid_dir)
        if status:
            done = list(done_job_seconds(status).values())
            line += (f"; its last invocation (started {status.get('started', '?')}, {status.get('max_parallel', '?')} "
                     f"job(s) at a time, {status.get('threads_per_job', '?')} thread(s) each) ran {len(done)} job(s) "
                     f"in {float(status.get('elapsed_s', 0)) / 60:.0f} min wall, {sum(done) / 3600:.2f} h of job time")
        lines.append(line)
    return lines


def _cell(row: dict, col: str, digits: int) -> str:
    """Markdown cell: 'mean ± std' for a *_mean column (std omitted when undefined), plain value otherwise."""
    value = row[col]
    if value is None:
        return "n/a"
    if isinstance(value, float):
        text = f"{value:.{digits}f}"
        std = row.get(col[:-5] + "_std") if col.endswith("_mean") else None
        return text + (f" ± {std:.{digits}f}" if std is not None else "")
    return str(value)


def markdown_table(rows: list[dict], digits: dict[str, int]) -> str:
    """Rows as a markdown table; *_std columns fold into their *_mean column, headers lose the _mean suffix."""
    if not rows:
        return "(none)\n"
    cols = [c for c in rows[0] if not c.endswith("_std")]
    head = [c[:-5] if c.endswith("_mean") else c for c in cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(_cell(row, c, digits.get(c.split("/")[0].split("_")[0], 2)) for c in cols)
                     + " |")
    return "\n".join(lines) + "\n"


def write_outputs(runs: list[Run], out: Path) -> list[Path]:
    """Write summary.md, summary.csv and the plots into `out`; returns the files written."""
    from experiments.plots import write_all  # matplotlib: imported only when plotting

    out.mkdir(parents=True, exist_ok=True)
    quality, oracles, times = quality_rows(runs), oracle_rows(runs), time_rows(runs)
    per_seed, views = seed_rows(runs), views_rows(runs)
    paired = against_leader(per_seed)
    digits = {"PSNR": 2, "SSIM": 4, "LPIPS": 4, "Spearman": 3, "AUSE": 4, "select": 1, "fisher": 1, "reduction": 2,
              "job": 1}
    incomplete = [r for r in runs if r.results is None]
    md = ["# Summary", "",
          f"{len(runs)} runs ({len(incomplete)} incomplete) from {len({r.setup for r in runs})} setup(s). "
          "mean ± std: sample standard deviation over seeds and scenes (no ± for a single run).", "",
          "## Quality on the test views", "", markdown_table(quality, digits),
          "## Per scene and seed", "",
          "Test PSNR of every seed, the best of each seed in bold; first in: seeds in which the method is best on "
          "the scene (ties count for each); above random in: seeds in which it beats random's run of the same seed.",
          "", seed_tables(per_seed),
          "## Test PSNR along the acquisition", "",
          "Mean ± std over seeds at each number of training views: the stage values are measured just before each "
          "acquisition (so the value at N views shows the picks that brought the run to N), the last after the "
          "final stage.", "", views_tables(views),
          "## Paired differences against the best mean", "",
          "Per scene, every method's test PSNR minus that of the method with the best mean, over the seeds both ran "
          "(a seed shares seed views and initial points between methods, so the per-seed difference is the one to "
          "test); 95 % Student-t interval of the mean difference; resolved: the interval excludes zero "
          "(experiments/paired.py).", "", leader_table(paired),
          "## Oracle evaluations per acquisition step", "",
          "Averaged over steps (and seeds), rounded up, as the paper reports. conservative: every sampled candidate "
          "counts; evaluated: gains actually computed. exhaustive: what exhaustive greedy evaluates on the "
          "same steps, sum_j (M - j); reduction: conservative count relative to it.", "",
          markdown_table(oracles, digits),
          "## Selection wall time (seconds)", "",
          "select_s = selection time per acquisition step including the Fisher blocks; fisher_s = the Fisher part; "
          "job_min = wall minutes of the run's grid jobs (train, render, metrics; every invocation that worked on it, "
          "or its grid's last invocation for runs made before grid_job_seconds.json).",
          "", markdown_table(times, digits),
          "## Provenance", "",
          "Code commit (+changes: tracked files differed from it), machine and date of every run, as train.py "
          "recorded them; float sums differ across machines and thread counts.", ""]
    md += provenance_lines(runs) + grid_lines(runs) + [""]
    if incomplete:
        md += ["## Incomplete runs", ""] + [f"- `{r.path}`: {r.problem}" for r in incomplete] + [""]
    atomic_write(out / "summary.md", lambda tmp: Path(tmp).write_text("\n".join(md)))

    tables = [("quality", quality), ("per_seed", per_seed), ("views", views), ("paired", paired),
              ("oracles", oracles), ("time", times)]
    columns = ["table"] + list(dict.fromkeys(c for _, rows in tables for row in rows for c in row))

    def write_csv(tmp: str) -> None:
        with open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=columns, restval="")
            writer.writeheader()
            for name, rows in tables:
                for row in rows:
                    writer.writerow({"table": name, **{c: "" if v is None else v for c, v in row.items()}})
    atomic_write(out / "summary.csv", write_csv)
    return [out / "summary.md", out / "summary.csv"] + write_all(runs, out)


def check_readable(runs: list[Run]) -> None:
    """Raise UserError naming the first run whose selection.json is truncated (the summary lists them as
    incomplete; call this after `write_outputs`)."""
    broken = [r for r in runs if r.problem and "truncated" in r.problem]
    if broken:
        raise UserError(f"{broken[0].path / SELECTION} is truncated or not valid JSON ({len(broken)} run(s) "
                        "affected, listed as incomplete in the summary); rerun those runs or delete their directories")
