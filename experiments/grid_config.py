"""A validated grid command line (`GridConfig`) and the job of each of its runs (`job_spec`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from experiments.jobs import JobSpec
from experiments.protocols import PROTOCOLS, RunScale, RunSpec

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class SlurmOptions:
    """Resources of one Slurm job (array task)."""

    partition: str | None = None
    gpus_per_job: int = 0
    cpus_per_job: int = 2
    time_min: int = 1440  # also the local launcher's per-job limit


@dataclass(frozen=True)
class GridConfig:
    """A validated grid command line."""

    setup: str
    data: Path
    out: Path  # OUT; runs go to OUT/<setup>/...
    runs: tuple[RunSpec, ...]
    scale: RunScale
    device: str  # auto | cpu | cuda
    extra_args: tuple[str, ...]  # appended to every train.py call
    launcher: str  # local | slurm | inline
    max_parallel: int
    threads: int  # per job (OMP/MKL/numba)
    python: str  # interpreter of the jobs' CLI calls
    slurm: SlurmOptions = field(default_factory=SlurmOptions)
    dry_run: bool = False
    uncertainty: bool = False  # render.py --uncertainty in every job
    report: bool = False  # write the grid report (reports.write_grid_report) after the summary
    progress_every_s: float = 300.0  # a line per running job (its run_status.json progress) this often

    @property
    def setup_dir(self) -> Path:
        return self.out / self.setup

    def record(self) -> dict[str, Any]:
        """The flags that change results (grid.json): runs made with other values are never mixed."""
        return {"resolution": self.scale.resolution, "iter_scale": self.scale.iter_scale,
                "stage_scale": self.scale.stage_scale,
                "num_points": self.scale.num_points, "train_args": list(self.extra_args)}


def job_spec(cfg: GridConfig, run: RunSpec) -> JobSpec:
    """The job of one run: train.py flags, log path, interpreter and thread count."""
    model = cfg.setup_dir / run.key
    scene_dir = cfg.data / run.scene
    train_args = ["-s", str(scene_dir), "-m", str(model), "--eval", "-r", str(cfg.scale.resolution)]
    if (scene_dir / "transforms_train.json").is_file():
        train_args.append("--white_background")  # Blender scenes: RGBA on white
    train_args += run.schedule_args(PROTOCOLS[cfg.setup], cfg.scale) + ["--quiet", *cfg.extra_args]
    return JobSpec(key=run.key, model_dir=str(model), log_path=str(cfg.setup_dir / "logs" / f"{run.key}.log"),
                   python=cfg.python, root=str(ROOT), train_args=tuple(train_args), device=cfg.device,
                   threads=cfg.threads, uncertainty=cfg.uncertainty)
