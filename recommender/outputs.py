"""The output folder of a recommendation (docs/recommend.md lists every field):

    recommendations.json   the picks in order (pose, intrinsics, size, gain, rank), every candidate's gain where
                           evaluated, oracle counts, seconds (Fisher / gain), settings
    transforms.json        the picks as a nerfstudio transforms.json (file_path images/pick_NN.png, to be captured)
    previews/              pick_NN.png (the model rendered there), pick_NN_uncertainty.png (active.uncertainty map)
    topdown.png            the scene from above: captured cameras, candidates coloured by gain, picks numbered

Everything is written to a temporary folder beside the target and moved into place at the end, so an
interrupted run leaves no folder that looks complete.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from active.uncertainty import gaussian_uncertainty, uncertainty_map
from arguments import config_to_dict
from gaussian_renderer import render
from recommender.candidates import CaptureFrame
from recommender.pipeline import LoadedModel, Recommendation
from scene.cameras import Camera
from scene.pose_files import c2w_opengl
from utils.errors import UserError
from utils.image import save_image
from utils.io import write_json
from utils.provenance import environment_record

MARKER = "recommendations.json"  # an existing output folder holds this; anything else is not overwritten


def check_output_dir(out: str | Path) -> Path:
    """The output folder, refused up front when it exists and is not an earlier recommend output (or empty)."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not (out / MARKER).is_file())):
        raise UserError(f"output {out} exists and is not a recommend.py output folder; choose another -o")
    return out


def camera_record(camera: Camera) -> dict[str, Any]:
    """Pose (c2w and w2c in OpenCV axes, transform_matrix in OpenGL axes), intrinsics and size of a camera."""
    w2c = camera.viewmat.double().cpu()
    return {"c2w": torch.linalg.inv(w2c).tolist(), "w2c": w2c.tolist(), "transform_matrix": c2w_opengl(camera).tolist(),
            "fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
            "width": camera.width, "height": camera.height}


def recommendation_record(rec: Recommendation, model: LoadedModel, candidates_spec: str, device: str,
                          seconds: dict[str, float]) -> dict[str, Any]:
    """The content of recommendations.json."""
    pool, step = rec.pool, rec.acquisition
    evaluated = step.evaluated_gains if step else {}
    picks = [{"rank": r + 1, "candidate": pool.source_index[v], "name": pool.names[v], "gain": g,
              "visible_gaussians": rec.visible[v], **camera_record(pool.cameras[v]),
              "preview": f"previews/pick_{r + 1:02d}.png",
              "uncertainty_map": f"previews/pick_{r + 1:02d}_uncertainty.png"}
             for r, (v, g) in enumerate(zip(rec.picks, rec.pick_gains))]
    candidates = [{"candidate": pool.source_index[v], "name": pool.names[v],
                   "gain": evaluated.get(v, 0.0 if rec.visible[v] == 0 else None),
                   "evaluated": v in evaluated, "visible_gaussians": rec.visible[v],
                   "rank": rec.picks.index(v) + 1 if v in rec.picks else None,
                   "position": pool.cameras[v].camera_center.double().cpu().tolist()}
                  for v in pool.candidate_ids]
    return {
        "model": str(model.path), "model_kind": model.kind, "iteration": model.iteration,
        "num_gaussians": model.gaussians.num_gaussians,
        "prior": {"views": len(pool.train_ids), "names": [pool.cameras[v].image_name for v in pool.train_ids],
                  "view_ids": list(model.train_ids) if model.kind == "model_dir" else None},
        "candidates": {"source": candidates_spec, "count": len(pool.candidate_ids),
                       "visible": sum(1 for v in pool.candidate_ids if rec.visible[v] > 0)},
        "selector": rec.selector.name, "selector_options": rec.selector.options(),
        "selector_used": rec.used.name, "rule": rec.rule,
        "k": rec.k, "k_taken": len(rec.picks),
        "picks": picks,
        "candidate_gains": candidates,
        "oracle_calls": {"conservative": step.selection.conservative if step else 0,
                         "evaluated": step.evaluated if step else 0},
        "fisher_views_computed": step.fisher_views_computed if step else 0,
        "seconds": seconds,
        "settings": {"seed": rec.seed, "device": device, "width": pool.cameras[pool.candidate_ids[0]].width,
                     "background": model.background.cpu().tolist(),
                     "fisher": config_to_dict(model.fisher),
                     "raster": {"tile_size": model.settings.tile_size, "backend": model.settings.backend}},
        "provenance": environment_record(device=device),
        "notes": rec.notes,
    }


def picks_transforms(rec: Recommendation) -> dict[str, Any]:
    """A nerfstudio transforms.json of the picks (OpenGL camera-to-world, per-frame pinhole intrinsics)."""
    frames = []
    for r, v in enumerate(rec.picks):
        c = rec.pool.cameras[v]
        frames.append({"file_path": f"images/pick_{r + 1:02d}.png", "transform_matrix": c2w_opengl(c).tolist(),
                       "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy, "w": c.width, "h": c.height})
    return {"camera_model": "OPENCV", "frames": frames}


@torch.no_grad()
def write_previews(rec: Recommendation, model: LoadedModel, folder: Path) -> None:
    """pick_NN.png (the model rendered at the pick) and pick_NN_uncertainty.png (log10 of the per-pixel
    uncertainty of the prior, one colour scale over all picks)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pool = rec.pool
    u = gaussian_uncertainty(model.gaussians, pool.cameras, pool.train_ids, model.background, model.settings,
                             fisher=model.fisher)
    maps = []
    for r, v in enumerate(rec.picks):
        camera = pool.cameras[v]
        save_image(render(camera, model.gaussians, model.background, model.settings).image.clamp(0, 1),
                   folder / f"pick_{r + 1:02d}.png")
        maps.append(torch.log10(uncertainty_map(camera, model.gaussians, u, model.settings).cpu().double() + 1e-12))
    finite = torch.cat([m.flatten() for m in maps])
    lo, hi = float(finite.min()), float(finite.max())
    for r, m in enumerate(maps):
        plt.imsave(folder / f"pick_{r + 1:02d}_uncertainty.png", m.numpy(), cmap="magma", vmin=lo, vmax=max(hi, lo + 1e-9))


def write_topdown(rec: Recommendation, model: LoadedModel, path: Path, record: dict[str, Any]) -> None:
    """The scene from above (along the captured cameras' up): Gaussians grey, captured cameras black, candidates
    coloured by gain (hollow where not evaluated), picks numbered."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pool = rec.pool
    frame = CaptureFrame.of([pool.cameras[v] for v in pool.train_ids] or model.captured)
    e1 = torch.linalg.cross(frame.up, torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64))
    if e1.norm() < 1e-6:
        e1 = torch.linalg.cross(frame.up, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
    e1 = e1 / e1.norm()
    e2 = torch.linalg.cross(frame.up, e1)

    def plane(points: torch.Tensor) -> tuple[list[float], list[float]]:
        p = points.double().cpu() - frame.center
        return (p @ e1).tolist(), (p @ e2).tolist()

    fig, ax = plt.subplots(figsize=(6.5, 6))
    means = model.gaussians.means.detach()
    step = max(1, len(means) // 5000)
    ax.scatter(*plane(means[::step]), s=1, c="0.75", label="Gaussians", rasterized=True)
    ax.scatter(*plane(torch.stack([pool.cameras[v].camera_center for v in pool.train_ids])), marker="^", s=40,
               c="black", label=f"captured ({len(pool.train_ids)})")
    gains = {c["candidate"]: c["gain"] for c in record["candidate_gains"]}
    cand = pool.candidate_ids
    xs, ys = plane(torch.stack([pool.cameras[v].camera_center for v in cand]))
    evaluated = [i for i, v in enumerate(cand) if gains[pool.source_index[v]] is not None]
    others = [i for i in range(len(cand)) if i not in set(evaluated)]
    if others:
        ax.scatter([xs[i] for i in others], [ys[i] for i in others], s=22, facecolors="none", edgecolors="0.5",
                   label="candidates (not evaluated)")
    if evaluated:
        sc = ax.scatter([xs[i] for i in evaluated], [ys[i] for i in evaluated], s=26,
                        c=[gains[pool.source_index[cand[i]]] for i in evaluated], cmap="viridis",
                        label="candidates (gain)")
        fig.colorbar(sc, ax=ax, label="gain (last evaluated)")
    for r, v in enumerate(rec.picks):
        x, y = (float(t[0]) for t in plane(pool.cameras[v].camera_center[None]))
        ax.scatter([x], [y], s=160, facecolors="none", edgecolors="red", linewidths=1.5)
        ax.annotate(str(r + 1), (x, y), xytext=(5, 5), textcoords="offset points", color="red", weight="bold")
    ax.set_aspect("equal")
    ax.set_title(f"{rec.selector.name}: {len(rec.picks)} picks of {len(cand)} candidates (view from above)")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(rec: Recommendation, model: LoadedModel, out: str | Path, *, candidates_spec: str,
                  device: str = "cpu", previews: bool = True, seconds: dict[str, float] | None = None) -> dict:
    """Write the output folder (temporary folder, moved into place at the end); returns the JSON record."""
    out = check_output_dir(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        step = rec.acquisition
        times = dict(seconds or {})
        times.update({"fisher": step.fisher_seconds if step else 0.0, "gain": step.gain_seconds if step else 0.0,
                      "selection": rec.seconds})
        if previews:
            (tmp / "previews").mkdir()
            write_previews(rec, model, tmp / "previews")
        record = recommendation_record(rec, model, candidates_spec, device, times)
        if not previews:
            for pick in record["picks"]:
                pick["preview"] = pick["uncertainty_map"] = None
        write_topdown(rec, model, tmp / "topdown.png", record)
        record["seconds"]["outputs"] = time.perf_counter() - t0
        record["seconds"]["total"] = sum(record["seconds"].get(k, 0.0) for k in ("load", "selection", "outputs"))
        write_json(tmp / "transforms.json", picks_transforms(rec))
        write_json(tmp / MARKER, record)  # last: its presence marks a complete folder
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return record


def summary_lines(record: dict[str, Any]) -> list[str]:
    """One line per pick for stdout."""
    lines = []
    for p in record["picks"]:
        pos = p["c2w"]
        gain = ("n/a (no oracle)" if record["oracle_calls"]["evaluated"] == 0 or p["gain"] is None
                or math.isnan(p["gain"]) else f"{p['gain']:.4g}")
        lines.append(f"pick {p['rank']}: {p['name']} (candidate {p['candidate']}) gain {gain} at "
                     f"({pos[0][3]:.3f}, {pos[1][3]:.3f}, {pos[2][3]:.3f})")
    return lines
