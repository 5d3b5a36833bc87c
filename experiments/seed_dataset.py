"""The seed-view dataset of recommend-then-train: a folder holding the images of S seed views and the test split, and
the poses (never the images) of the other training views, the candidates. Blender and COLMAP datasets.

Seeds are farthest-point samples of the training cameras' centres from a given first view (as train.py seeds). On
COLMAP, the seed folder's SfM points are the points that a seed image observes, so that the seed model starts from
the geometry its S captures see, not from all the points triangulated with the candidates' images. (Asking for two
seed observations keeps almost nothing: sequential matching links only neighbouring images, and farthest-point seeds
are far apart: 10 of bonsai's 35,102 points.) `seed_points="all"` keeps every point instead, as train.py's Setup 1
initialises from the whole SfM model: a diagnosis (what the Fisher does when the model already holds Gaussians where
no capture looked), not a capture a user could make.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from active.schedule import farthest_point_views
from scene import colmap_io
from scene.frames import LLFFHOLD, held_out
from scene.pose_files import read_pose_file
from utils.errors import UserError
from utils.io import read_json, write_json

IMAGE_EXTENSIONS = (".png", ".jpg", "")  # a Blender frame's file_path names its image without (or with) one
MIN_SEED_OBSERVATIONS = 1  # a kept SfM point is observed by this many seed images
SEED_POINTS = ("observed", "all")  # which SfM points a COLMAP seed folder keeps


@dataclass
class SeedDataset:
    """What `make_seed_dataset` wrote; seed and candidate ids index the full dataset's training views."""

    folder: Path  # OUT/data: the seed views' images, the test split, the candidates' poses
    seeds: list[int]
    candidates: list[int]
    candidate_poses: Path  # for recommend.py --candidates
    seed_flags: list[str]  # train.py flags of the seed model (on `folder`)
    full_flags: list[str]  # train.py flags of the continued training (on the full dataset)
    note: str = ""  # what was kept, for the log


def make_seed_dataset(data: Path, out: Path, num_seed: int, *, images: str = "images",
                      seed_points: str = "observed", start: int = 0) -> SeedDataset:
    """OUT/data for a Blender (transforms_train/test.json) or COLMAP (sparse/0) dataset `data`; `images` is
    train.py's -i of a COLMAP dataset, whose test split is train.py's --eval split; `seed_points` (COLMAP): keep the
    SfM points a seed view observes, or all; `start`: the training view farthest-point sampling starts from (the
    first seed view). Raises UserError for any other layout, a missing image, or candidate images present in
    OUT/data."""
    if seed_points not in SEED_POINTS:
        raise UserError(f"--seed_points must be one of {', '.join(SEED_POINTS)}, got {seed_points!r}")
    if (data / "transforms_train.json").is_file() and (data / "transforms_test.json").is_file():
        return _blender_seed_dataset(data, out / "data", num_seed, start)
    if (data / "sparse" / "0").is_dir():
        return _colmap_seed_dataset(data, out / "data", num_seed, images, seed_points == "all", start)
    raise UserError(f"{data} is neither a Blender dataset (transforms_train.json and transforms_test.json) nor a "
                    "COLMAP one (sparse/0); point --data at one (convert.py makes a COLMAP one from photographs)")


def training_centers(data: Path) -> torch.Tensor:
    """The camera centres of a Blender or COLMAP dataset's training views, in train.py's order (COLMAP: sorted by
    name, without --eval's test images). [V, 3] float64"""
    if (data / "transforms_train.json").is_file():
        cameras = read_pose_file(data / "transforms_train.json", default_size=(800, 800))
    elif (data / "sparse" / "0").is_dir():
        cameras = [c for i, c in enumerate(read_pose_file(data / "sparse" / "0")) if not held_out(i, LLFFHOLD)]
    else:
        raise UserError(f"{data} is neither a Blender dataset (transforms_train.json) nor a COLMAP one (sparse/0)")
    return torch.stack([c.camera_center for c in cameras]).double()


def _link(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    if not dst.exists():
        dst.symlink_to(src.resolve())


def seed_views(data: Path, num_seed: int, start: int) -> list[int]:
    """Farthest-point sampling of `num_seed` of the training views' camera centres from view `start` (train.py's
    seeding). Raises UserError when either is out of range."""
    centers = training_centers(data)
    if not 0 < num_seed <= len(centers):
        raise UserError(f"--num_seed_views must lie in [1, {len(centers)}] (the dataset's training views), "
                        f"got {num_seed}")
    if not 0 <= start < len(centers):
        raise UserError(f"the first seed view must be a training view id in [0, {len(centers) - 1}], got {start}")
    return farthest_point_views(centers, num_seed, start)


def _blender_seed_dataset(data: Path, folder: Path, num_seed: int, start: int) -> SeedDataset:
    train = read_json(data / "transforms_train.json", what="dataset split", fix="fix or regenerate it")
    test = read_json(data / "transforms_test.json", what="dataset split", fix="fix or regenerate it")
    frames = train["frames"]
    seeds = seed_views(data, num_seed, start)
    candidates = [v for v in range(len(frames)) if v not in seeds]
    for frame in [frames[v] for v in seeds] + test["frames"]:
        ext = next((e for e in IMAGE_EXTENSIONS if (data / (frame["file_path"] + e)).is_file()), None)
        if ext is None:
            raise UserError(f"{data}: no image for frame {frame['file_path']!r}")
        _link(data / (frame["file_path"] + ext), folder / (frame["file_path"] + ext))
    write_json(folder / "transforms_train.json", {**train, "frames": [frames[v] for v in seeds]})
    write_json(folder / "transforms_test.json", test)
    write_json(folder / "candidates.json", {**train, "frames": [frames[v] for v in candidates]})
    present = [v for v in candidates
               if any((folder / (frames[v]["file_path"] + e)).exists() for e in IMAGE_EXTENSIONS)]
    if present:
        raise UserError(f"{folder}: candidate images are present ({present[:5]}); remove them")
    return SeedDataset(folder, seeds, candidates, folder / "candidates.json", ["-w"], ["-w"])


def _colmap_seed_dataset(data: Path, folder: Path, num_seed: int, images: str, all_points: bool,
                         start: int) -> SeedDataset:
    sparse = data / "sparse" / "0"
    cams, imgs, (xyz, rgb) = colmap_io.read_model(sparse)
    ordered = sorted(imgs.values(), key=lambda im: im.name)  # the readers' order; held_out() splits it
    train = [i for i in range(len(ordered)) if not held_out(i, LLFFHOLD)]
    test = [i for i in range(len(ordered)) if held_out(i, LLFFHOLD)]
    seeds = seed_views(data, num_seed, start)
    candidates = [v for v in range(len(train)) if v not in seeds]
    for i in [train[v] for v in seeds] + test:
        src = data / images / ordered[i].name
        if not src.is_file():
            raise UserError(f"{data}: no image {src} for COLMAP image {ordered[i].name}")
        _link(src, folder / images / ordered[i].name)
    seed_ids = np.array([ordered[train[v]].id for v in seeds])
    tracks = colmap_io.read_point_tracks(sparse)
    keep = np.array([all_points or len(np.intersect1d(t, seed_ids)) >= MIN_SEED_OBSERVATIONS for t in tracks],
                    dtype=bool)
    if not keep.any():
        raise UserError(f"{sparse}: no SfM point is observed by the {num_seed} seed views; use more seed views "
                        "(--num_seed_views)")
    colmap_io.write_model_text(folder / "sparse" / "0", cams, imgs, xyz[keep], rgb[keep])
    candidate_images = {ordered[train[v]].id: ordered[train[v]] for v in candidates}
    colmap_io.write_model_text(folder / "candidates", cams, candidate_images, xyz[:0], rgb[:0])
    present = [ordered[train[v]].name for v in candidates if (folder / images / ordered[train[v]].name).exists()]
    if present:
        raise UserError(f"{folder / images}: candidate images are present ({present[:5]}); remove them")
    note = f"{int(keep.sum())} of {len(keep)} SfM points kept " + \
        ("(all: also those only candidates observe)" if all_points else "(observed by a seed view)")
    return SeedDataset(folder, seeds, candidates, folder / "candidates", ["-i", images, "--skip_missing_images"],
                       ["-i", images], note)
