"""Paired comparisons of two selectors over the seeds they share.

Two selectors run with the same seed share the seed views, the initial points and the training noise, so the
per-seed difference a - b removes what the seeds have in common and is the quantity to test: a lead of 0.4 dB
between two means whose seeds each spread by 1 dB can still hold in every seed, or flip sign from seed to seed.

    diff = paired_difference({0: 25.4, 1: 25.2, 2: 23.8}, {0: 25.1, 1: 25.5, 2: 24.3})
    diff.mean, diff.low, diff.high, diff.wins, diff.losses, diff.resolved

The interval is Student's t interval of the mean difference (n - 1 degrees of freedom); a difference is *resolved*
when the interval excludes zero. With 3 seeds t = 4.30, so only differences far larger than their spread resolve.
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass
from statistics import mean, stdev

from scipy.stats import t as student_t

LEVEL = 0.95


@dataclass(frozen=True)
class PairedDifference:
    """a - b over the seeds both have."""
    n: int  # shared seeds
    mean: float  # mean difference
    low: float  # LEVEL t interval of the mean difference (nan for n < 2)
    high: float
    wins: int  # seeds with a > b
    losses: int  # seeds with a < b

    @property
    def resolved(self) -> bool:
        """The interval excludes zero (False when it is undefined)."""
        return self.low > 0 or self.high < 0


def paired_difference(a: dict[int, float], b: dict[int, float], level: float = LEVEL) -> PairedDifference:
    """Seed -> value maps of two selectors -> their paired difference over the shared seeds (ValueError if none)."""
    seeds = sorted(set(a) & set(b))
    if not seeds:
        raise ValueError("the two selectors share no seed")
    diffs = [a[s] - b[s] for s in seeds]
    centre = mean(diffs)
    if len(diffs) < 2:
        low = high = math.nan
    else:
        half = student_t.ppf(0.5 + level / 2, len(diffs) - 1) * stdev(diffs) / math.sqrt(len(diffs))
        low, high = centre - half, centre + half
    return PairedDifference(len(diffs), centre, low, high, sum(d > 0 for d in diffs), sum(d < 0 for d in diffs))


def seed_values(row: dict) -> dict[int, float]:
    """A `seed_rows` / summary.csv per-seed row -> {seed: value} (empty cells left out)."""
    return {int(key[5:]): float(value) for key, value in row.items()
            if key.startswith("seed_") and value not in (None, "")}


def against_leader(rows: list[dict], metric: str = "PSNR") -> list[dict]:
    """Per (setup, scene) of `seed_rows`-style rows: every other setting against the setting with the best mean.
    Each row: setup, scene, leader, method, seeds, diff (method - leader, mean), low, high, wins, losses, resolved."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for row in rows:
        groups[(row["setup"], row["scene"])].append(row)
    out = []
    for (setup, scene), group in groups.items():
        leader = max(group, key=lambda r: float(r[f"{metric}_mean"]))
        for row in group:
            if row is leader:
                continue
            d = paired_difference(seed_values(row), seed_values(leader))
            out.append({"setup": setup, "scene": scene, "leader": leader["method"], "method": row["method"],
                        "seeds": d.n, "diff": d.mean, "low": d.low, "high": d.high, "wins": d.wins,
                        "losses": d.losses, "resolved": d.resolved})
    return out


def difference_cells(d: PairedDifference, digits: int = 2) -> list[str]:
    """Table cells of a paired difference: seeds, mean, LEVEL interval ("–" for one seed), seeds above / below,
    resolved."""
    interval = "–" if d.n < 2 else f"[{d.low:+.{digits}f}, {d.high:+.{digits}f}]"
    return [str(d.n), f"{d.mean:+.{digits}f}", interval, f"{d.wins} / {d.losses}", "yes" if d.resolved else "no"]


def leader_table(rows: list[dict], digits: int = 2) -> str:
    """`against_leader` rows as one markdown table (difference to the leader, its interval, seeds above / below)."""
    if not rows:
        return "(none)\n"
    head = ["setup", "scene", "method", "leader", "seeds", "method − leader", f"{LEVEL:.0%} interval",
            "seeds above / below", "resolved"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        d = PairedDifference(r["seeds"], r["diff"], r["low"], r["high"], r["wins"], r["losses"])
        cells = [r["setup"], r["scene"], r["method"], r["leader"]] + difference_cells(d, digits)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
