"""A training run's configuration: the config groups, train.py's parser, the flag checks and the run's selector."""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from active import Selector, build_selector_from, list_selectors
from active.registry import options_read_by, selector_options_dataclass, unread_options_note
from arguments import ActiveConfig, ModelConfig, PipelineConfig, RunConfig, add_config_args, config_from_args, config_to_dict
from scene.trained import raster_settings
from training.densify import DensifyConfig
from training.optim import OptimConfig
from utils.errors import UserError

SelectorOptions = selector_options_dataclass()  # one flag per option of the registered selectors (e.g. --eps)

# The config groups of a run, once: (attribute of TrainConfig, dataclass, --help section title).
CONFIG_GROUPS: tuple[tuple[str, type, str], ...] = (
    ("model", ModelConfig, "Model"),
    ("pipeline", PipelineConfig, "Pipeline"),
    ("optim", OptimConfig, "Optimization"),
    ("densify", DensifyConfig, "Densification"),
    ("active", ActiveConfig, "Active view selection"),
    ("selector", SelectorOptions, "Selector options (each used by the selectors named in brackets)"),
    ("run", RunConfig, "Run"),
)


@dataclass
class TrainConfig:
    """All config groups of one run (`CONFIG_GROUPS`)."""

    model: ModelConfig
    pipeline: PipelineConfig
    optim: OptimConfig
    densify: DensifyConfig
    active: ActiveConfig
    selector: Any  # SelectorOptions
    run: RunConfig

    def to_dict(self) -> dict[str, Any]:
        return {name: config_to_dict(getattr(self, name)) for name, _, _ in CONFIG_GROUPS}


# cfg_args entries that may differ between the starts of one run, or between the runs of one grid: paths, device,
# logging, restart and checkpoint-keeping flags (none changes what is trained)
NOT_COMPARED = frozenset({"source_path", "model_path", "device", "quiet", "resume", "overwrite", "keep_checkpoints"})


def config_difference(saved: dict[str, Any], current: dict[str, Any], method: str) -> tuple[str, Any, Any] | None:
    """The first field (name, saved value, current value) on which a run's recorded cfg_args (`saved`) and a config
    (`current`, `TrainConfig.to_dict()`) differ; None if none. Skipped: NOT_COMPARED, the selector options `method`
    does not read, and fields `saved` lacks (recorded before they existed)."""
    options_of_others = options_read_by(list_selectors()) - options_read_by([method] if method else [])
    for group, values in current.items():
        recorded = saved.get(group) if isinstance(saved.get(group), dict) else {}
        for name, value in values.items():
            if name in NOT_COMPARED or name in options_of_others or name not in recorded:
                continue
            if recorded[name] != value:
                return name, recorded[name], value
    return None


def build_parser(description: str | None = None) -> argparse.ArgumentParser:
    """train.py's parser: one --help section per config group, --method listing the registered selectors."""
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    for _, cls, title in CONFIG_GROUPS:
        add_config_args(parser, cls, title)
    for action in parser._actions:  # list the registered selectors in --method's help
        if action.dest == "method":
            action.help = f"view selector, one of {', '.join(list_selectors())}; empty = train on all training views"
    return parser


def parse_config(argv: list[str] | None = None, description: str | None = None, notes: bool = True) -> TrainConfig:
    """The validated config of train.py's flags `argv` (default: sys.argv[1:]); `notes` prints the one-line notes
    on flags the run ignores."""
    ns = build_parser(description).parse_args(argv)
    cfg = TrainConfig(**{name: config_from_args(cls, ns) for name, cls, _ in CONFIG_GROUPS})
    validate_config(cfg, notes)
    return cfg


def validate_config(cfg: TrainConfig, notes: bool = True) -> None:
    """Reject bad flag values with one clear line each (every selector option by the config that declares it), and
    with `notes` print one line naming the selector options set that the run's selectors do not read."""
    if not cfg.model.source_path:
        raise UserError("no dataset given: pass -s/--source_path DIR (e.g. data/builtin, made by `python -m scene.builtin data/builtin`)")
    if cfg.run.iterations <= 0:
        raise UserError(f"--iterations must be positive, got {cfg.run.iterations}")
    if cfg.model.num_random_points < 1:
        raise UserError(f"--num_random_points must be at least 1, got {cfg.model.num_random_points}")
    if cfg.model.device == "cuda" and not torch.cuda.is_available():
        raise UserError("--device cuda was asked for but torch sees no CUDA device; use --device cpu")
    raster_settings(cfg.pipeline)  # a bad or unavailable --raster_backend fails before anything is written
    if cfg.run.keep_checkpoints < 0:
        raise UserError(f"--keep_checkpoints must be >= 0 (0 keeps every checkpoint), got {cfg.run.keep_checkpoints}")
    a = cfg.active
    if a.stage_method and not a.method:
        raise UserError("--stage_method replaces --method at some acquisitions: pass --method too (the selector of "
                        "the others)")
    if a.method:
        names = [make_selector(cfg).name, *(selector.name for selector in stage_selectors(cfg).values())]
        runs = f"--method {a.method}" + (" and --stage_method" if a.stage_method else "")
        note = unread_options_note(config_to_dict(cfg.selector), names, runs)  # validates every option's value
        if note and notes:
            print(note)
        if a.sigma <= 0:
            raise UserError(f"--sigma must be positive, got {a.sigma}")


def make_selector(cfg: TrainConfig) -> Selector:
    """The run's selector, built from --method and the selector flags it declares (validated by its config)."""
    if cfg.active.method not in list_selectors():
        raise UserError(f"unknown --method {cfg.active.method!r}; choose one of: {', '.join(list_selectors())}")
    return build_selector_from(cfg.active.method, config_to_dict(cfg.selector))


def stage_selectors(cfg: TrainConfig) -> dict[int, Selector]:
    """--stage_method's selectors by acquisition stage (0 = the first), built like --method's from the same flags."""
    chosen: dict[int, Selector] = {}
    for entry in cfg.active.stage_method:
        stage, _, name = entry.partition(":")
        if not stage.isdigit() or not name:
            raise UserError(f"--stage_method takes STAGE:NAME with STAGE an acquisition number from 0 (e.g. "
                            f"1:coverage), got {entry!r}")
        if int(stage) in chosen:
            raise UserError(f"--stage_method names acquisition {int(stage)} twice; give each stage one selector")
        if name not in list_selectors():
            raise UserError(f"unknown selector {name!r} in --stage_method {entry}; choose one of: "
                            f"{', '.join(list_selectors())}")
        chosen[int(stage)] = build_selector_from(name, config_to_dict(cfg.selector))
    return chosen


def default_model_path(cfg: TrainConfig) -> str:
    """output/<scene>[_<method>] when no -m is given."""
    name = Path(cfg.model.source_path.rstrip("/")).name or "scene"
    return str(Path("output") / (f"{name}_{cfg.active.method}" if cfg.active.method else name))
