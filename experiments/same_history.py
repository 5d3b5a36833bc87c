"""Paired differences of two selectors from the acquisition where their runs part: a natural experiment in grid runs.

Two runs of one seed that picked the same views at their first s acquisitions hold the same model there (same
seed views, initial points and training noise; the same machine replays the same floats), so what differs after
is caused by the picks from acquisition s on. For two method folders of one grid scene (ROOT/SETUP/SCENE/METHOD),
the seeds are grouped by the acquisition where the picks first differ, and for each group the paired difference
a - b of the test PSNR is given at every later view count and at the end, with its Student-t interval
(`experiments.paired`). CLI: scripts/same_history.py.
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from experiments.paired import PairedDifference, difference_cells, paired_difference
from utils.errors import UserError
from utils.io import read_json


def run_records(method_dir: Path) -> dict[int, dict]:
    """{seed: selection.json content} of the finished runs (a `final` record) under ROOT/SETUP/SCENE/METHOD."""
    records = {}
    for path in sorted(method_dir.glob("seed*/selection.json")):
        record = read_json(path, what="selection record", fix="pass the method folder of a finished grid")
        if record.get("final"):
            records[int(path.parent.name[4:])] = record
    if not records:
        raise UserError(f"{method_dir} holds no finished run (SEED/selection.json with a final record); pass "
                        "ROOT/SETUP/SCENE/METHOD of a finished grid")
    return records


def parting_stage(a: dict, b: dict) -> int:
    """The first acquisition at which the two runs picked different views (len(stages) if none did)."""
    for stage, (x, y) in enumerate(zip(a["stages"], b["stages"])):
        if x["selected"] != y["selected"]:
            return stage
    return min(len(a["stages"]), len(b["stages"]))


def psnr_after(record: dict) -> dict[int, float]:
    """{views: test PSNR} at each acquisition after the first (before its picks) and at the end (the final views)."""
    values = {len(stage["train_views"]): stage["test_psnr"] for stage in record["stages"][1:]}
    values[len(record["final"]["train_views"])] = record["final"]["test_psnr"]
    return values


def same_history(a_dir: Path, b_dir: Path) -> list[dict]:
    """One row per (parting acquisition, view count after it): the paired difference a - b over the seeds that part
    there, and the largest |a - b| of the test PSNR at the parting acquisition (0: the same model)."""
    a_runs, b_runs = run_records(a_dir), run_records(b_dir)
    seeds = sorted(set(a_runs) & set(b_runs))
    if not seeds:
        raise UserError(f"{a_dir} and {b_dir} share no finished seed")
    groups: dict[int, list[int]] = defaultdict(list)
    for seed in seeds:
        groups[parting_stage(a_runs[seed], b_runs[seed])].append(seed)
    rows = []
    for stage, members in sorted(groups.items()):
        at_parting = [abs(a_runs[s]["stages"][stage]["test_psnr"] - b_runs[s]["stages"][stage]["test_psnr"])
                      for s in members if stage < len(a_runs[s]["stages"])]
        parted_views = len(a_runs[members[0]]["stages"][stage]["train_views"]) if at_parting else None
        a_after = {s: psnr_after(a_runs[s]) for s in members}
        b_after = {s: psnr_after(b_runs[s]) for s in members}
        for views in sorted(a_after[members[0]]):
            if parted_views is not None and views <= parted_views:
                continue
            a_vals = {s: values[views] for s, values in a_after.items() if views in values}
            b_vals = {s: values[views] for s, values in b_after.items() if views in values}
            rows.append({"parting_stage": stage, "parting_views": parted_views, "seeds": members,
                         "model_gap": max(at_parting, default=0.0), "views": views,
                         "difference": paired_difference(a_vals, b_vals)})
    return rows


def history_table(rows: list[dict], a_name: str, b_name: str) -> str:
    """Markdown of `same_history` rows."""
    lines = [f"| picks part at (views) | max \\|{a_name} − {b_name}\\| there (dB) | at views | seeds | "
             f"{a_name} − {b_name} (mean) | 95% interval | seeds above / below | resolved |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        d: PairedDifference = row["difference"]
        parted = "never" if row["parting_views"] is None else f"acquisition {row['parting_stage']} " \
                                                                f"({row['parting_views']})"
        lines.append(f"| {parted} | {row['model_gap']:.4f} | {row['views']} | "
                     + " | ".join(difference_cells(d)) + " |")
    return "\n".join(lines)
