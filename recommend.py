"""Where to capture next: rank candidate camera poses (no images needed) for a trained 3DGS model.

    python recommend.py -m output/lego --candidates orbit:100 -k 4 -o output/lego/next
    python recommend.py -m splat.ply --captured cameras.json --candidates hemisphere:200 -k 6
    python recommend.py -m output/lego5 --candidates unused -k 4 --method pop_gs

--model: a train.py model directory (prior: its recorded training views) or a graphdeco-layout PLY with --captured.
--candidates: orbit:N | hemisphere:N (around the captured views) | unused (a model directory's untrained dataset
views) | a pose file (transforms.json, 3DGS cameras.json, nerfstudio camera_path.json, COLMAP model folder).
Writes recommendations.json, transforms.json, previews/ and topdown.png to -o (see docs/recommend.md).
"""
from __future__ import annotations

import argparse
import logging
import time
from dataclasses import replace
from pathlib import Path

import torch

from active import build_selector_from, list_selectors
from active.fisher import FISHER_PARAM_GROUPS
from active.registry import selector_options_dataclass, unread_options_note
from arguments import add_config_args, config_from_args, config_to_dict
from recommender.outputs import check_output_dir, summary_lines, write_outputs
from recommender.pipeline import Recommendation, candidate_cameras, fit_memory, load_model, make_pool, recommend
from utils.dir_lock import WAYS_OUT, writer_lock
from utils.errors import UserError, run_cli
from utils.model_dir import folder_lock_file

SelectorOptions = selector_options_dataclass()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-m", "--model", required=True, help="train.py model directory or a 3DGS .ply")
    p.add_argument("--captured", help="views already taken, for a bare PLY: cameras.json, transforms.json or a "
                                      "COLMAP model folder")
    p.add_argument("--candidates", default="orbit:64", help="orbit:N, hemisphere:N, unused, or a pose file "
                                                            "(default: orbit:64)")
    p.add_argument("-k", type=int, default=4, help="views to recommend (default: 4)")
    p.add_argument("--method", default="auto", help=f"selector, one of {', '.join(list_selectors())} "
                   "(default: auto = cover_pool's geometric picks until 8 captured views trained 100 iterations "
                   "each, lite_gs's Fisher picks after; prints which and why; docs/recommend.md)")
    p.add_argument("-o", "--output", help="output folder (default: MODEL/recommend, or beside the PLY)")
    p.add_argument("--iteration", type=int, default=-1, help="model directory: saved iteration (default: last)")
    p.add_argument("--seed", type=int, default=0, help="selection seed (default: 0)")
    p.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--width", type=int, help="render width for the Fisher information (default: as given, capped "
                                             "at the CPU training width 200 px, or 1600 px on CUDA)")
    p.add_argument("--size", help="candidate image size WxH (default: the first captured camera's)")
    p.add_argument("--fov", type=float, help="candidate horizontal field of view in degrees (default: captured)")
    p.add_argument("--elevation", help="generated poses: elevation range LO,HI in degrees")
    p.add_argument("--radius", type=float, help="generated poses: distance to the look-at point")
    p.add_argument("--white_background", action="store_true", help="bare PLY: composite on white")
    p.add_argument("--fisher_params", choices=tuple(FISHER_PARAM_GROUPS),
                   help="override the model's Fisher parameter groups (a bare PLY: default)")
    p.add_argument("--fisher_mode", choices=("cached", "streaming"), help="override the model's Fisher mode")
    p.add_argument("--fisher_cache_mb", type=int, help="Fisher cache bound in MB (0 = a quarter of free RAM)")
    p.add_argument("--no_previews", action="store_true", help="skip the preview and uncertainty images")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_config_args(p, SelectorOptions, "Selector options (each used by the selectors named in brackets)")
    return p


def _pair(text: str | None, flag: str, kind: type, sep: str) -> tuple | None:
    if text is None:
        return None
    try:
        a, b = (kind(v) for v in text.split(sep))
    except ValueError:
        raise UserError(f"{flag} takes two numbers separated by {sep!r}, got {text!r}") from None
    return a, b


def main() -> None:
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    args = build_parser().parse_args()
    t0 = time.perf_counter()
    if args.method not in list_selectors():
        raise UserError(f"unknown --method {args.method!r}; choose one of: {', '.join(list_selectors())}")
    if args.device == "cuda" and not torch.cuda.is_available():
        raise UserError("--device cuda was asked for but torch sees no CUDA device; use --device cpu")
    if args.width is not None and args.width < 16:
        raise UserError(f"--width must be at least 16 px, got {args.width}")
    options = config_to_dict(config_from_args(SelectorOptions, args))
    selector = build_selector_from(args.method, options)
    note = unread_options_note(options, [args.method], f"--method {args.method}")  # validates every option's value
    if note:
        print(note)
    model_path = Path(args.model)
    out = check_output_dir(args.output or (model_path / "recommend" if model_path.is_dir()
                                           else model_path.with_name(model_path.stem + "_recommend")))
    with writer_lock(out, WAYS_OUT["recommend"], folder_lock_file(out)):  # beside it: the folder is replaced whole
        _recommend(args, selector, model_path, out, t0)


def _recommend(args: argparse.Namespace, selector, model_path: Path, out: Path, t0: float) -> None:
    """Load the model, rank the candidates, write the output folder `out` and print the summary."""
    model = load_model(model_path, args.captured, iteration=args.iteration, device=args.device,
                       white_background=args.white_background)
    overrides = {name: getattr(args, name) for name in ("fisher_params", "fisher_mode", "fisher_cache_mb")}
    model.fisher = replace(model.fisher, **{name: value for name, value in overrides.items() if value is not None})
    size = _pair(args.size, "--size", int, "x")
    candidates = candidate_cameras(args.candidates, model, elevation=_pair(args.elevation, "--elevation", float, ","),
                                   radius=args.radius, size=size, fov_deg=args.fov)
    pool = make_pool(model, candidates, args.width)
    model.fisher = fit_memory(model, pool, selector, previews=not args.no_previews)  # before any Fisher work
    load_seconds = time.perf_counter() - t0
    rec = recommend(model, pool, selector, args.k, seed=args.seed, progress=not args.quiet)
    record = write_outputs(rec, model, out, candidates_spec=args.candidates, device=args.device,
                           previews=not args.no_previews, seconds={"load": load_seconds})
    for line in summary_lines(record):
        print(line)
    s, calls = record["seconds"], record["oracle_calls"]
    print(f"{out}: {len(rec.picks)} of {len(pool.candidate_ids)} candidates with {_selector_label(rec)}, oracle calls "
          f"{calls['evaluated']} evaluated / {calls['conservative']} conservative, {s['total']:.1f} s "
          f"(Fisher {s['fisher']:.1f} s, gains {s['gain']:.1f} s)")


def _selector_label(rec: Recommendation) -> str:
    """The selector's name, with the one it ran in brackets where they differ (auto)."""
    asked, used = rec.selector.name, rec.used.name
    return asked if used == asked else f"{asked} ({used})"


if __name__ == "__main__":
    run_cli(main)
