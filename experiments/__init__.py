"""Experiments over many runs of the project's CLIs.

- Grids (CLI scripts/grid.py): the paper's protocols as data (`protocols.py`), one job per run (`jobs.py`,
  `grid_config.py`, `grid_args.py`, `flags.py`), a runner over submitit (`runner.py`, `launchers.py`,
  `progress.py`) and the summary tables and plots (`summary.py`, `plots.py`; CLI scripts/summarize.py).
- Recommend then train (`recommend_train_loop.py`, CLI scripts/recommend_then_train.py): recommend from poses
  alone, continue the seed model on the picks, against random and coverage picks.
- The closed capture loop on the built-in scene (`closed_capture_loop.py`, CLI scripts/capture_loop.py).
"""
