"""Break down each candidate's log-det (pop_gs) first-pick gain over its Gaussians (experiments/gain_diagnosis.py).

    python scripts/diagnose_gain.py -m output/lego --candidates candidates.json -o output/diag_lego
"""
from __future__ import annotations

import argparse

from experiments.gain_diagnosis import run
from utils.errors import run_cli


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-m", "--model", required=True, help="train.py model directory (or a PLY)")
    p.add_argument("--candidates", required=True, help="candidate pose file (as recommend.py --candidates)")
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--top", type=int, default=8, help="top picks to tabulate")
    p.add_argument("--width", type=int, default=None, help="camera width in px (default: recommend.py's)")
    a = p.parse_args(argv)
    d = run(a.model, a.candidates, a.out, top=a.top, width=a.width)
    print(f"{a.out}/diagnosis.md: top pick {d['top'][0]['name']} gain {d['top'][0]['gain']:.1f}")


if __name__ == "__main__":
    run_cli(main)
