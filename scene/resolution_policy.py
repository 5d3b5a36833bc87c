"""Which resolution a run trains at when `-r` is not given, and the check of an explicit `-r`.

3DGS scales images wider than 1.6k px down to 1.6k. On the CPU that is far too large (a step at 800 px takes
seconds), so a CPU run without `-r` trains on images at most `--cpu_max_width` px wide, picking the smallest of
the usual downscale factors 2/4/8 that fits (a target width when even 8 does not), and says so in one line.
The effective value is what the run records in `cfg_args`, so render.py and metrics.py load the same images.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from PIL import Image

from scene.frames import IMAGE_SUFFIXES, target_size
from scene.transforms_json import image_path
from utils.errors import UserError
from utils.io import read_json

CUDA_MAX_WIDTH = 1600  # the 3DGS rule: wider images are scaled to this width
MIN_IMAGE_SIDE = 16  # px; below this a few tiles cover the whole image and nothing useful is trained
DOWNSCALE_FACTORS = (2, 4, 8)  # the factors `-r` understands; any other value > 0 is a target width


@dataclass(frozen=True)
class ResolutionChoice:
    """The effective `-r` value, the training image size and the one-line notice (None when nothing changed)."""

    resolution: int  # what the run uses and records: -1/1 as is, 2/4/8 a factor, other > 0 a target width
    size: tuple[int, int]  # (width, height) of the training images
    full_size: tuple[int, int]  # (width, height) of the image files
    notice: str | None = None


def probe_image_size(source_path: str, images: str = "images") -> tuple[int, int] | None:
    """(width, height) of a dataset's first training image, or None when it cannot be found or read.

    Blender (`transforms_train.json`) and nerfstudio / instant-ngp (`transforms.json`): the first listed frame's
    image file, else that frame's (or the file's) `w` and `h`; COLMAP: the first image file of `images/` by name.
    None leaves every complaint to the dataset reader, which names the problem precisely.
    """
    source = Path(source_path)
    try:
        for name in ("transforms_train.json", "transforms.json"):
            if (source / name).is_file():
                data = read_json(source / name, damaged="none")  # damaged: the dataset reader says so
                return None if data is None else _first_frame_size(source, data)
        path = min(p for p in (source / images).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        with Image.open(path) as im:
            return im.size
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError):
        return None


def _first_frame_size(source: Path, data: dict) -> tuple[int, int] | None:
    """The size of the first frame of a transforms file: its image file, else its declared `w` x `h`."""
    frame = data["frames"][0]
    try:
        with Image.open(image_path(source, frame["file_path"])) as im:
            return im.size
    except OSError:
        w, h = frame.get("w", data.get("w")), frame.get("h", data.get("h"))
        if isinstance(w, (int, float)) and isinstance(h, (int, float)) and w >= 1 and h >= 1:
            return int(w), int(h)
        return None


def choose_resolution(requested: int, full_size: tuple[int, int], device: str, cpu_max_width: int) -> ResolutionChoice:
    """The resolution to train at for `-r requested` (-1 = not given) on `device`.

    Raises `UserError` for `cpu_max_width` <= 0 and for a resolution whose images would be smaller than
    `MIN_IMAGE_SIDE` px on a side (the message names the size it would give).
    """
    if cpu_max_width <= 0:
        raise UserError(f"--cpu_max_width must be a positive width in pixels, got {cpu_max_width}; the default is 200")
    full_w, full_h = full_size
    if requested != -1:
        return _checked(requested, full_size, None, f"-r {requested}")
    if device == "cpu" and full_w > cpu_max_width:
        factor = next((f for f in DOWNSCALE_FACTORS if target_size(full_w, full_h, f)[0] <= cpu_max_width), None)
        resolution = factor if factor is not None else cpu_max_width
        w, h = target_size(full_w, full_h, resolution)
        notice = (f"note: training at {w}x{h} px (-r {resolution}), not the images' {full_w}x{full_h}: on the CPU "
                  f"images are limited to --cpu_max_width {cpu_max_width} px; pass -r 1 for full resolution "
                  f"(much slower) or another -r")
        return _checked(resolution, full_size, notice, f"--cpu_max_width {cpu_max_width}")
    if device != "cpu" and full_w > CUDA_MAX_WIDTH:
        w, h = target_size(full_w, full_h, CUDA_MAX_WIDTH)
        notice = (f"note: training at {w}x{h} px (-r {CUDA_MAX_WIDTH}), not the images' {full_w}x{full_h}: images "
                  f"wider than {CUDA_MAX_WIDTH} px are scaled down as in 3DGS; pass -r 1 for full resolution")
        return _checked(CUDA_MAX_WIDTH, full_size, notice, "the 3DGS width limit")
    return _checked(-1, full_size, None, "the images as they are")


def _checked(resolution: int, full_size: tuple[int, int], notice: str | None, what: str) -> ResolutionChoice:
    """A `ResolutionChoice`, or a `UserError` when its images would be too small (`what` names the cause)."""
    w, h = target_size(full_size[0], full_size[1], resolution)
    if min(w, h) < MIN_IMAGE_SIDE:
        raise UserError(f"{what} would give {w}x{h} px images from the {full_size[0]}x{full_size[1]} originals; "
                        f"each side needs at least {MIN_IMAGE_SIDE} px: use a smaller factor or a larger width")
    return ResolutionChoice(resolution, (w, h), full_size, notice)


def training_resolution(model_cfg) -> ResolutionChoice | None:
    """`choose_resolution` for a `ModelConfig` (its source, -r, device and --cpu_max_width).

    None when the dataset's images cannot be probed: the run then keeps `-r` as given and the dataset reader
    reports what is wrong with the data.
    """
    if model_cfg.cpu_max_width <= 0:
        choose_resolution(model_cfg.resolution, (1, 1), model_cfg.device, model_cfg.cpu_max_width)  # raises
    full_size = probe_image_size(model_cfg.source_path, model_cfg.images)
    if full_size is None:
        return None
    return choose_resolution(model_cfg.resolution, full_size, model_cfg.device, model_cfg.cpu_max_width)
