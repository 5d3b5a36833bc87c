"""Configuration dataclasses and the one helper that turns their fields into argparse options and back.

Each group is a frozen dataclass with typed fields and a default; the CLI is generated from the fields
(`add_config_args`) and read back explicitly (`config_from_args`). Resolved configs are saved as JSON.
Optimisation and densification configs live next to the code that uses them
(`training.optim.OptimConfig`, `training.densify.DensifyConfig`) and are exposed here the same way.
"""
from __future__ import annotations

import argparse
import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

T = TypeVar("T")


def _flag(short: str | None = None, help: str = "", choices: tuple | None = None) -> dict:
    return {"short": short, "help": help, "choices": choices}


@dataclass(frozen=True)
class ModelConfig:
    """Where the data and the outputs are, and how the scene is loaded."""

    source_path: str = field(default="", metadata=_flag("-s", "dataset directory (Blender, nerfstudio transforms.json or COLMAP layout)"))
    model_path: str = field(default="", metadata=_flag(
        "-m", "output directory (default output/<scene name>; output/<scene name>_<method> for an active run)"))
    images: str = field(default="images", metadata=_flag("-i", "COLMAP image folder name"))
    resolution: int = field(default=-1, metadata=_flag(
        "-r", "1/2/4/8 = downscale factor, other >0 = target width, -1 = as is up to --cpu_max_width on the CPU, "
        "1600 px on CUDA"))
    white_background: bool = field(default=False, metadata=_flag("-w", "composite RGBA on white (Blender)"))
    eval: bool = field(default=False, metadata=_flag(None, "hold out test views (COLMAP, transforms.json: every 8th; Blender: transforms_test)"))
    sh_degree: int = field(default=3, metadata=_flag(None, "maximum spherical-harmonics degree"))
    num_random_points: int = field(default=3_000, metadata=_flag(None, "random initial points when the dataset has none (Blender; transforms.json without a point file); 10,000 ruined 11-view lego runs (14 dB against 25)"))
    init_ply: str = field(default="", metadata=_flag(
        None, "start from the Gaussians of a 3DGS PLY (e.g. a trained model's point_cloud.ply, to continue it on more "
        "views) instead of the dataset's initial points"))
    device: str = field(default="cpu", metadata=_flag(None, "torch device", ("cpu", "cuda")))
    cpu_max_width: int = field(default=200, metadata=_flag(
        None, "without -r, a CPU run trains on images at most this many px wide (downscale 2/4/8, else this width)"))
    skip_missing_images: bool = field(default=False, metadata=_flag(None, "train on the listed frames whose image exists (default: error when any is missing)"))
    ignore_distortion: bool = field(default=False, metadata=_flag(None, "treat distorted lenses as pinholes instead of undistorting the images (for comparisons)"))


@dataclass(frozen=True)
class PipelineConfig:
    """Rasterizer settings."""

    tile_size: int = field(default=4, metadata=_flag(None, "rasterizer tile size in pixels"))
    raster_backend: str = field(default="auto", metadata=_flag(
        None, "rasterizer: compiled numba CPU kernels, pure torch, or auto (compiled when numba imports; CUDA: torch)",
        ("auto", "compiled", "torch")))


@dataclass(frozen=True)
class FisherSettings:
    """The Fisher oracle's options: one object from train.py's flags down to the view blocks.

    The defaults are stated here only: `ActiveConfig` takes these fields by name (`same_field`), and a signature that
    needs one default refers to it as a class attribute (e.g. `sigma: float = FisherSettings.sigma`).
    """

    sigma: float = field(default=1.0, metadata=_flag(None, "pixel noise std in the Fisher model H = J^T J / sigma^2"))
    delta_rel: float = field(default=1e-6, metadata=_flag(
        None, "relative ridge: delta_i = delta_rel * max diag of the prior block"))
    delta_abs: float = field(default=1e-8, metadata=_flag(None, "absolute ridge floor added to every prior block"))
    fisher_params: str = field(default="default", metadata=_flag(None, "Fisher parameter groups",
                                                                 ("default", "full_sh")))
    fisher_mode: str = field(default="cached", metadata=_flag(
        None, "cached: keep view blocks per stage; streaming: recompute", ("cached", "streaming")))
    fisher_cache_mb: int = field(default=0, metadata=_flag(None, "cache bound in MB (0 = a quarter of available RAM)"))

    @property
    def streaming(self) -> bool:
        """Whether the oracle starts in streaming mode (recompute a view's information at every oracle)."""
        return self.fisher_mode == "streaming"

    @classmethod
    def from_active(cls, active: Any) -> "FisherSettings":
        """From an `ActiveConfig` (or anything with these field names), or from a mapping of them such as a model
        directory's recorded "active" config (a missing name takes the default, other names are ignored)."""
        if isinstance(active, Mapping):
            return config_from_dict(cls, active)
        return cls(**{f.name: getattr(active, f.name) for f in dataclasses.fields(cls)})


def same_field(cls: type, name: str) -> Any:
    """A dataclass field with the default and the CLI metadata of field `name` of dataclass `cls` (stated there)."""
    source = next(f for f in dataclasses.fields(cls) if f.name == name)
    return field(default=source.default, metadata=source.metadata)


@dataclass(frozen=True)
class ActiveConfig:
    """Active view selection: which selector, the acquisition schedule and the Fisher oracle."""

    method: str = field(default="", metadata=_flag(None, "view selector; empty = train on all training views"))
    num_init_views: int = field(default=2, metadata=_flag(None, "seed views (farthest-point sampling from view 0)"))
    init_views: tuple[int, ...] = field(default=(), metadata=_flag(None, "explicit seed view ids (overrides --num_init_views)"))
    seed_start: str = field(default="first", metadata=_flag(None, "farthest-point seeding starts from the first allowed view (the paper's protocols: every --seed gets the same seed views) or from one drawn with --seed (the seed views, and a deterministic selector's picks, vary with --seed)", ("first", "random")))
    exclude_views: tuple[int, ...] = field(default=(), metadata=_flag(None, "view ids never offered to the selector nor seeded (poses that cannot be captured)"))
    stage_method: tuple[str, ...] = field(default=(), metadata=_flag(None, "STAGE:NAME: the selector NAME makes acquisition STAGE's picks instead of --method (STAGE as in selection.json: 0 = the first acquisition; NAME takes the same selector flags)"))
    views_per_step: int = field(default=3, metadata=_flag(None, "K: views added per acquisition step"))
    max_views: int = field(default=11, metadata=_flag(None, "view budget (training views at the end)"))
    iters_per_view: int = field(default=100, metadata=_flag(None, "stage length = iters_per_view x current #views"))
    stage_reset: bool = field(default=False, metadata=_flag(None, "restart each stage from the initial point cloud (default: continue)"))
    sigma: float = same_field(FisherSettings, "sigma")  # the Fisher fields: `FisherSettings.from_active`
    delta_rel: float = same_field(FisherSettings, "delta_rel")
    delta_abs: float = same_field(FisherSettings, "delta_abs")
    fisher_params: str = same_field(FisherSettings, "fisher_params")
    fisher_mode: str = same_field(FisherSettings, "fisher_mode")
    fisher_cache_mb: int = same_field(FisherSettings, "fisher_cache_mb")


@dataclass(frozen=True)
class RunConfig:
    """The training loop: length, seed, logging and checkpoints."""

    iterations: int = field(default=3_000, metadata=_flag(None, "total training iterations"))
    seed: int = field(default=0, metadata=_flag(None, "random seed (same seed => same views and metrics on CPU)"))
    test_iterations: tuple[int, ...] = field(default=(), metadata=_flag(None, "iterations at which to report test PSNR (end always)"))
    save_iterations: tuple[int, ...] = field(default=(), metadata=_flag(None, "iterations at which to save a PLY (end always)"))
    checkpoint_iterations: tuple[int, ...] = field(default=(), metadata=_flag(None, "extra checkpoint iterations (stages always checkpoint)"))
    keep_checkpoints: int = field(default=2, metadata=_flag(None, "checkpoints kept, the newest; 0 keeps every one (e.g. to branch a run at an early acquisition: scripts/branch_pick.py --stage)"))
    quiet: bool = field(default=False, metadata=_flag("-q", "no progress bar"))
    resume: bool = field(default=False, metadata=_flag(None, "continue from the newest checkpoint (also automatic)"))
    overwrite: bool = field(default=False, metadata=_flag(None, "delete a finished or partial run in --model_path and start over"))


def _base_type(tp: Any) -> Any:
    """The element type of `tuple[X, ...]`, else the type itself."""
    if typing.get_origin(tp) is tuple:
        return typing.get_args(tp)[0]
    return tp


def add_config_args(parser: argparse.ArgumentParser, cls: type, title: str | None = None,
                    defaults: dict[str, Any] | None = None) -> None:
    """Add one option per field of dataclass `cls` (as an argument group named `title`)."""
    group = parser.add_argument_group(title or cls.__name__, (cls.__doc__ or "").strip().splitlines()[0])
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        meta = f.metadata or {}
        names = [f"--{f.name}"] + ([meta["short"]] if meta.get("short") else [])
        default = (defaults or {}).get(f.name, f.default)
        tp = hints[f.name]
        kwargs: dict[str, Any] = {"help": f"{meta.get('help', '')} (default: {default!r})", "default": default}
        if tp is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif typing.get_origin(tp) is tuple:
            kwargs.update(type=_base_type(tp), nargs="*")
        else:
            kwargs["type"] = tp
        if meta.get("choices"):
            kwargs["choices"] = meta["choices"]
        group.add_argument(*names, dest=f.name, **kwargs)


def config_from_args(cls: type[T], ns: argparse.Namespace) -> T:
    """Build dataclass `cls` from the matching attributes of an argparse namespace."""
    hints = typing.get_type_hints(cls)
    values = {}
    for f in dataclasses.fields(cls):
        value = getattr(ns, f.name)
        values[f.name] = tuple(value) if typing.get_origin(hints[f.name]) is tuple else value
    return cls(**values)


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """A JSON-ready dict of a config dataclass (tuples become lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()}


def config_from_dict(cls: type[T], values: dict[str, Any]) -> T:
    """Inverse of `config_to_dict`, ignoring unknown keys (older/newer config files)."""
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in values:
            v = values[f.name]
            kwargs[f.name] = tuple(v) if typing.get_origin(hints[f.name]) is tuple else v
    return cls(**kwargs)
