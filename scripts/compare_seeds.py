"""Paired per-seed differences between selectors, from committed grid summaries (summary.csv per-seed rows).

    python scripts/compare_seeds.py docs/results/setup1_paper_stages_6seeds/summary.csv \
        --pairs cover_pool:lite_gs cover_pool:coverage

Prints one markdown table: for every scene both selectors ran on, the mean of a - b (test PSNR, dB) over their
shared seeds, its 95 % Student-t interval, the seeds where a is above / below b, and whether the interval excludes
zero (experiments/paired.py).
A selector is named by its method (the first word of the summary's setting label) or by the whole label when a scene
has several settings of one method. Several files are merged per (setup, scene, setting); a seed may appear once.
"""
from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

from experiments.paired import LEVEL, difference_cells, paired_difference, seed_values
from utils.errors import UserError, run_cli

Key = tuple[str, str]  # (setup, scene)


def read_seeds(paths: list[Path]) -> dict[Key, dict[str, dict[int, float]]]:
    """(setup, scene) -> setting label -> {seed: test PSNR} from the per_seed rows of summary.csv files."""
    table: dict[Key, dict[str, dict[int, float]]] = defaultdict(lambda: defaultdict(dict))
    for path in paths:
        if not path.is_file():
            raise UserError(f"{path} not found; pass the summary.csv of a grid (scripts/grid.py or "
                            "scripts/summarize.py writes it)")
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("table") == "per_seed"]
        if not rows or "PSNR_mean" not in rows[0]:
            raise UserError(f"{path} has no per-seed PSNR rows; is it a grid summary.csv?")
        for row in rows:
            seeds = table[(row["setup"], row["scene"])][row["method"]]
            for seed, value in seed_values(row).items():
                if seed in seeds and seeds[seed] != value:
                    raise UserError(f"{row['method']} seed {seed} on {row['scene']} has two values in the files "
                                    f"({seeds[seed]:.4f} and {value:.4f}); pass each grid once")
                seeds[seed] = value
    return table


def resolve(name: str, settings: dict[str, dict[int, float]], scene: str) -> str | None:
    """The setting label `name` stands for in one scene: the label itself, or the only setting of method `name`."""
    if name in settings:
        return name
    matches = [label for label in settings if label.split()[0] == name]
    if len(matches) > 1:
        raise UserError(f"{name!r} is ambiguous on {scene}: name one of the settings "
                        + "; ".join(repr(m) for m in sorted(matches)))
    return matches[0] if matches else None


def parse_pair(text: str) -> tuple[str, str]:
    a, sep, b = text.partition(":")
    if not sep or not a or not b or a == b:
        raise UserError(f"--pairs {text!r}: write two different selectors as A:B (e.g. cover_pool:lite_gs)")
    return a, b


def comparison_table(table: dict[Key, dict[str, dict[int, float]]], pairs: list[tuple[str, str]],
                     digits: int = 2) -> str:
    """One markdown row per pair and scene where both selectors ran on a shared seed."""
    head = ["setup", "scene", "a", "b", "seeds", "a − b (mean)", f"{LEVEL:.0%} interval", "seeds a above / below b",
            "resolved"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for a, b in pairs:
        for (setup, scene), settings in table.items():
            la, lb = resolve(a, settings, scene), resolve(b, settings, scene)
            if la is None or lb is None or not set(settings[la]) & set(settings[lb]):
                continue
            d = paired_difference(settings[la], settings[lb])
            lines.append("| " + " | ".join([setup, scene, la, lb] + difference_cells(d, digits)) + " |")
    if len(lines) == 2:
        raise UserError("no scene has both selectors of any pair on a shared seed; check the names against the "
                        "summary's method column")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("summaries", nargs="+", type=Path, help="summary.csv files of grids")
    parser.add_argument("--pairs", nargs="+", required=True, help="selectors to compare, each as A:B (A - B)")
    args = parser.parse_args()
    pairs = [parse_pair(p) for p in args.pairs]
    print(comparison_table(read_seeds(args.summaries), pairs), end="")


if __name__ == "__main__":
    run_cli(main)
