"""Branch finished grid runs at one acquisition: the same model, another selector's picks there.

A run saves its checkpoint right after each acquisition; the one of acquisition S holds the model trained on the
views before S (an acquisition adds views and writes the record; it leaves the model and optimiser alone unless
`--stage_reset`). With that acquisition undone, train.py resumes the checkpoint with the other selector making
acquisition S's picks (`--stage_method S:NAME`) and the run's own selector the later ones: every branch of a run
picks from the identical model and trains on from the identical random state, so the difference of the final test
PSNRs is that one pick's doing (with what it changes in the later picks), at the cost of the training after S. A
branch with the run's own (deterministic) selector reproduces the run (tested). Runs keep their newest two
checkpoints, which covers the last acquisition (the default) and usually the one before; train.py's
`--keep_checkpoints 0` keeps every one. CLI: scripts/branch_pick.py.

Layout: OUT/SCENE/METHOD/SPEC/SEED for the last acquisition, OUT/SCENE/METHOD/SPEC@S/SEED for acquisition S
(METHOD: the runs' own), a train.py model directory each, its `cfg_args` naming the run it branched from.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from experiments.method_spec import method_flags
from experiments.paired import PairedDifference, difference_cells, paired_difference
from experiments.replay import check_grid_run, logged_config
from training.engine import training
from utils.checkpoint import RunDirectory, load_checkpoint
from utils.errors import UserError
from utils.io import read_json, write_json
from utils.model_dir import CFG_ARGS, SELECTION, checkpoint_file


def undo_last_acquisition(ckpt: dict[str, Any]) -> dict[str, Any]:
    """The checkpoint as it was just before its last acquisition: that stage's picks and record removed."""
    stages = ckpt["stages"]
    if not stages or ckpt["stage"] != len(stages) or stages[-1]["iteration"] != ckpt["iteration"]:
        raise UserError(f"the checkpoint at iteration {ckpt['iteration']} was not written by an acquisition; "
                        "branch a run whose newest checkpoint is its last acquisition's (a grid run of train.py)")
    if ckpt["config"]["active"].get("stage_reset"):
        raise UserError("the run resets the model at each acquisition (--stage_reset), so its checkpoint no longer "
                        "holds the model the picks were made from; branch a run trained without --stage_reset")
    picked = set(stages[-1]["selected"])
    return {**ckpt, "stage": ckpt["stage"] - 1, "stages": stages[:-1], "view_stack": [],
            "train_views": [v for v in ckpt["train_views"] if v not in picked]}


def check_branchable(run_dir: Path) -> None:
    """One error line unless `run_dir` is a grid run with a checkpoint (checked before any branch trains)."""
    check_grid_run(run_dir)
    if not RunDirectory(run_dir).checkpoints():
        raise UserError(f"{run_dir} has no checkpoint to branch from; pass a finished grid run (ROOT/SETUP/SCENE/"
                        "METHOD/SEED)")


def acquisition_checkpoint(run_dir: Path, stage: int | None = None) -> dict[str, Any]:
    """The checkpoint a finished run wrote at acquisition `stage` (0 = the first; None: its last one)."""
    check_branchable(run_dir)
    if stage is None:
        return load_checkpoint(RunDirectory(run_dir).checkpoints()[-1][1])
    stages = read_json(run_dir / SELECTION, what="selection record", fix="branch a finished grid run")["stages"]
    if not 0 <= stage < len(stages):
        raise UserError(f"--stage {stage}: {run_dir} made acquisitions 0 to {len(stages) - 1}")
    path = checkpoint_file(run_dir, stages[stage]["iteration"])
    if not path.is_file():
        raise UserError(f"{run_dir} kept no checkpoint of acquisition {stage} (iteration "
                        f"{stages[stage]['iteration']}): "
                        "runs keep their newest two; train it again with train.py --keep_checkpoints 0 (grid.py: "
                        "flags after --) to branch there")
    return load_checkpoint(path)


def branch_dir(out: Path, run_dir: Path, spec: str, stage: int | None = None) -> Path:
    """OUT/SCENE/METHOD/SPEC[@STAGE]/SEED for a grid run ROOT/SETUP/SCENE/METHOD/SEED."""
    name = spec if stage is None else f"{spec}@{stage}"
    return out / run_dir.parents[1].name / run_dir.parent.name / name / run_dir.name


def stage_flags(spec: str, stage: int) -> list[str]:
    """train.py's flags for `spec` making acquisition `stage`'s picks: --stage_method STAGE:NAME and the spec's options
    (which the run's own selector takes too, where it has them)."""
    flags = method_flags(spec)
    return ["--stage_method", f"{stage}:{flags[1]}", *flags[2:]]


def run_branch(run_dir: Path, spec: str, out: Path, train_args: tuple[str, ...] = (), stage: int | None = None) -> Path:
    """Train the branch of `run_dir` whose picks at acquisition `stage` (None: the last) are `spec`'s, with
    `train_args` (extra train.py flags, e.g. --exclude_views) after the run's own (resumed if it was interrupted,
    skipped if done); returns its model directory. A branch folder made with other `train_args` is refused (one --out
    per set of extra flags)."""
    check_branchable(run_dir)
    target = branch_dir(out, run_dir, spec, stage)
    earlier = read_json(target / CFG_ARGS, missing="none", damaged="none")
    if earlier is not None and earlier.get("branch_train_args", []) != list(train_args):
        raise UserError(f"{target} was branched with train.py flags {earlier.get('branch_train_args', [])}, not "
                        f"{list(train_args)}; give these flags their own --out")
    ckpt = acquisition_checkpoint(run_dir, stage)
    undone = ckpt["stage"] - 1  # the acquisition the branch makes again
    cfg = logged_config(run_dir, target, (*train_args, *stage_flags(spec, undone)))
    if not RunDirectory(target).checkpoints():
        start = undo_last_acquisition(ckpt)
        target.mkdir(parents=True, exist_ok=True)
        write_json(target / CFG_ARGS, {**cfg.to_dict(), "branch_of": str(run_dir), "branch_iteration":
                                       start["iteration"], "branch_train_args": list(train_args)})
        RunDirectory(target).save_checkpoint({**start, "config": cfg.to_dict()})
    training(cfg)
    return target


def final_psnr(model_dir: Path) -> float:
    """The final test PSNR a finished run recorded in selection.json."""
    record = read_json(model_dir / SELECTION, what="selection record", fix="finish the run first")
    if not record.get("final"):
        raise UserError(f"{model_dir} has not finished (no final record in {SELECTION}); run it again to resume")
    return record["final"]["test_psnr"]


def branch_rows(runs: list[Path], specs: list[str], out: Path, train_args: tuple[str, ...] = (),
                stage: int | None = None) -> list[dict]:
    """Per scene, method the runs came from, and spec: the finished branches' (at acquisition `stage`, None: the
    last) final PSNRs by seed and the runs' own (JSON-ready but for the integer seed keys; `rows_from_json` reads
    them back)."""
    groups: dict[tuple[str, str], list[Path]] = {}
    for run in runs:
        groups.setdefault((run.parents[1].name, run.parent.name), []).append(run)
    rows = []
    for (scene, method), members in sorted(groups.items()):
        sources = {int(r.name[4:]): final_psnr(r) for r in members}
        for spec in specs:
            done = {int(r.name[4:]): final_psnr(branch_dir(out, r, spec, stage)) for r in members
                    if RunDirectory(branch_dir(out, r, spec, stage)).is_complete()}
            if done:
                rows.append({"scene": scene, "source_method": method, "spec": spec, "train_args": " ".join(train_args),
                             "stage": stage, "psnr": done, "source": sources})
    return rows


def rows_from_json(rows: list[dict]) -> list[dict]:
    """`branch_rows` read back from JSON (whose object keys, the seeds, are strings)."""
    return [{**row, "psnr": {int(s): v for s, v in row["psnr"].items()},
             "source": {int(s): v for s, v in row["source"].items()}} for row in rows]


def short_flags(flags: str, longest: int = 4) -> str:
    """Flags for a table cell: a run of more than `longest` numbers becomes "(N ids)"."""
    out, numbers = [], []
    for word in [*flags.split(), ""]:  # "" ends the last run of numbers
        if word.isdigit():
            numbers.append(word)
            continue
        out += numbers if len(numbers) <= longest else [f"({len(numbers)} ids)"]
        numbers = []
        if word:
            out.append(word)
    return " ".join(out)


def branch_table(rows: list[dict]) -> str:
    """Markdown of `branch_rows`: each branch's mean final PSNR and its paired difference to the run it branched
    (its pick at the runs' last acquisition unless the cell names one)."""
    lines = ["| scene | runs of | pick by | final PSNR | the runs' (same seeds) | seeds | pick − run (mean) | "
             "95% interval | seeds above / below | resolved |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        d: PairedDifference = paired_difference(row["psnr"], row["source"])
        seeds = sorted(row["psnr"])
        mean_branch = sum(row["psnr"][s] for s in seeds) / len(seeds)
        mean_source = sum(row["source"][s] for s in seeds) / len(seeds)
        pick = " ".join(filter(None, (row["spec"], short_flags(row.get("train_args", "")),
                                      row.get("stage") is not None and f"at acquisition {row['stage']}")))
        lines.append(f"| {row['scene']} | {row['source_method']} | {pick} | {mean_branch:.2f} | {mean_source:.2f} | "
                     + " | ".join(difference_cells(d)) + " |")
    return "\n".join(lines)
