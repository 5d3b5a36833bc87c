"""Train a 3D Gaussian Splatting model, optionally with active view selection.

    python train.py -s data/lego -r 8 --eval                          # all training views
    python train.py -s data/lego -r 8 --eval --method NAME              # active: seed views + K per step

--method takes any registered selector (listed under --method below); its own options (e.g. --eps) are in the
"Selector options" group.

Every acquisition stage ends with a checkpoint; rerunning the same command resumes from the newest one.
The engine is `training.engine` (this file parses the flags and reports bad input as one `error:` line).
"""
from __future__ import annotations

if __name__ == "__main__":  # a second writer into a directory being written is refused before the slow imports
    from utils.dir_lock import WAYS_OUT, refuse_if_locked
    refuse_if_locked(("-m", "--model_path"), WAYS_OUT["train"])

import logging

import torch

from training.config import parse_config
from training.engine import training
from utils.errors import run_cli


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cfg = parse_config(description=__doc__)
    torch.set_num_threads(torch.get_num_threads())
    training(cfg)


if __name__ == "__main__":
    run_cli(main)
