"""Self-contained HTML reports (plotly, offline): a run, a grid of runs, a recommendation.

`write_run_report(model_dir)`, `write_grid_report(setup_dir)`, `write_recommendation_report(out_dir)`; the CLI is
report.py. Data gathering (`run_data`, `grid_data`, `recommendation_data`) is separate from the page building
(`figures`, `page`, `images`).
"""
from reports.grid_report import write_grid_report
from reports.recommendation_report import write_recommendation_report
from reports.run_report import write_run_report

__all__ = ["write_run_report", "write_grid_report", "write_recommendation_report"]
