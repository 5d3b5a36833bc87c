"""What every dataset reader shares: the `SceneInfo` it returns, and the way from listed frames to `Camera`s
(missing images, unreadable images, image size against the intrinsics, undistortion (cached), resizing to
`--resolution`, compositing on the background)."""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from scene.cameras import Camera
from scene.lens import Lens, Undistorter
from utils.errors import UserError

log = logging.getLogger(__name__)

MISSING_SHOWN = 3  # file names quoted in the missing-images error
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")  # image files the loaders accept
CACHE_DIR_NAME = ".undistorted"  # beside the dataset's images
CACHE_VERSION = 1
# Stored size / calibrated size factors accepted as "the same images, stored smaller or larger" (images_2, ...).
CLEAN_FACTORS = tuple(1 / k for k in range(16, 1, -1)) + tuple(range(1, 17))


# OpenGL/Blender camera axes (x right, y up, z back) -> OpenCV (x right, y down, z forward): flip y and z.
GL_TO_CV = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))


@dataclass
class PointCloud:
    """Initial points (SfM or random) with colours."""

    points: torch.Tensor  # [P, 3]
    colors: torch.Tensor  # [P, 3] in [0, 1]


@dataclass
class SceneInfo:
    """Everything a dataset provides: cameras, optional SfM points, the normalisation extent."""

    train_cameras: list[Camera]
    test_cameras: list[Camera]
    point_cloud: PointCloud | None
    scene_extent: float
    kind: str  # "blender" | "colmap" | "transforms" (nerfstudio / instant-ngp)
    dropped_images: list[str] = field(default_factory=list)  # listed but missing (--skip_missing_images)


def scene_extent(cameras: list[Camera]) -> float:
    """3DGS 'nerf normalization': 1.1 x the largest distance of a camera centre from their mean."""
    centers = torch.stack([c.camera_center.double().cpu() for c in cameras])  # [C, 3]
    return float(1.1 * (centers - centers.mean(0)).norm(dim=1).max().clamp_min(1e-6))


@dataclass
class Frame:
    """One listed view: where it was listed (for messages), its image file and its world-to-camera pose."""

    where: str
    path: Path
    viewmat: torch.Tensor  # [4, 4] float64, OpenCV axes

    @property
    def name(self) -> str:
        return self.path.stem


LLFFHOLD = 8  # --eval's default: every 8th image is a test image (Mip-NeRF 360's llffhold)


def held_out(index: int, llffhold: int) -> bool:
    """The test-split rule of `--eval` for COLMAP and transforms.json datasets: every `llffhold`-th listed frame
    (sorted by name, counting from 0), before missing images are dropped."""
    return index % llffhold == 0


def drop_missing(frames: list[Frame], skip_missing: bool, root: Path) -> tuple[list[Frame], list[str]]:
    """The frames whose image exists, and the (root-relative) names of those that do not.

    Raises:
        UserError: some images are missing and `skip_missing` is False (names the count, the first few files and
            the flag that proceeds).
    """
    missing = [f for f in frames if not f.path.is_file()]
    names = [os.path.relpath(f.path, root) for f in missing]
    if missing and not skip_missing:
        shown = ", ".join(names[:MISSING_SHOWN]) + (", ..." if len(names) > MISSING_SHOWN else "")
        raise UserError(f"{len(missing)} of {len(frames)} listed images are missing ({shown}; first listed at "
                        f"{missing[0].where}); restore them or pass --skip_missing_images to train on the others")
    if missing:
        log.warning("--skip_missing_images: dropped %d of %d listed frames whose image is missing (%s%s)",
                    len(missing), len(frames), ", ".join(names[:MISSING_SHOWN]),
                    ", ..." if len(names) > MISSING_SHOWN else "")
    kept = [f for f in frames if f.path.is_file()]
    if not kept:
        raise UserError(f"none of the {len(frames)} listed images exists (first: {names[0]}); check the dataset")
    return kept, names


def image_size(path: Path, where: str) -> tuple[int, int]:
    """(width, height) from an image file's header, or a one-line UserError."""
    if not path.is_file():
        raise UserError(f"{where}: image file {path} is missing")
    try:
        with Image.open(path) as im:
            return im.size
    except (OSError, SyntaxError, ValueError) as exc:
        raise UserError(f"{where}: cannot read image {path} ({exc}); the file is truncated or corrupt, "
                        "replace it") from None


def read_rgba(path: Path, where: str) -> np.ndarray:
    """All pixels of an image file as RGBA uint8; a truncated or corrupt file is a one-line UserError. [H, W, 4]"""
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGBA"), dtype=np.uint8).copy()
    except (OSError, SyntaxError, ValueError) as exc:  # Pillow: "image file is truncated", bad chunks, ...
        raise UserError(f"{where}: cannot read image {path} ({exc}); the file is truncated or corrupt, "
                        "replace it") from None


def stored_scale(lens_w: float, lens_h: float, file_w: int, file_h: int, where: str, name: str) -> tuple[float, float]:
    """(sx, sy) from calibrated pixels to the file's: 1 when they agree, the exact ratios when the file is a
    clean multiple (1/16..16) of the calibration, else a UserError naming the frame."""
    if (lens_w, lens_h) == (file_w, file_h):
        return 1.0, 1.0
    for f in CLEAN_FACTORS:
        if abs(lens_w * f - file_w) <= 1 and abs(lens_h * f - file_h) <= 1:
            return file_w / lens_w, file_h / lens_h
    raise UserError(f"{where}: image {name} is {file_w}x{file_h} but the intrinsics are for "
                    f"{lens_w:g}x{lens_h:g} (w/h); fix 'w'/'h' or the image")


def target_size(width: int, height: int, resolution: int) -> tuple[int, int]:
    """Image size for `--resolution`: -1/1 as is, 2/4/8 a downscale factor, any other positive value a width."""
    if resolution in (-1, 1):
        return width, height
    if resolution <= 0:
        raise UserError(f"--resolution must be -1, a factor 1/2/4/8 or a target width > 0; got {resolution}")
    if resolution in (2, 4, 8):
        return max(1, round(width / resolution)), max(1, round(height / resolution))
    return resolution, max(1, round(height * resolution / width))


def _resize_rgba(rgba: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Box-filter resize (Pillow resamples RGBA premultiplied by alpha). [H', W', 4] uint8"""
    im = Image.fromarray(rgba, "RGBA")
    return np.asarray(im.resize(size, Image.Resampling.BOX) if im.size != size else im, dtype=np.uint8)


def composite(rgba: np.ndarray, background: torch.Tensor) -> torch.Tensor:
    """RGBA uint8 [H, W, 4] composited on `background` [3]. [3, H, W] float32"""
    t = torch.from_numpy(rgba.astype(np.float32) / 255.0).permute(2, 0, 1)  # [4, H, W]
    rgb, alpha = t[:3], t[3:4]
    return (rgb * alpha + background[:, None, None] * (1 - alpha)).contiguous()


def load_composited(path: Path, size: tuple[int, int], background: torch.Tensor, where: str = "image"
                    ) -> torch.Tensor:
    """An image file resized to `size` (box filter, alpha-aware) and composited on `background` [3]. [3, H, W]"""
    return composite(_resize_rgba(read_rgba(path, where), size), background)


class UndistortCache:
    """Undistorted, resized RGBA images, kept as PNGs under `<dataset>/.undistorted/<key>/`.

    The key hashes the lens (model, size, intrinsics, coefficients) and the output size, so a change of either
    makes a new entry; each image's entry also carries its byte size and modification time. When the dataset
    directory is not writable the cache moves to `~/.cache/litegs/undistorted/<hash of the dataset path>/` (one
    log line says so). Files are written to a temporary name and renamed, so an interrupted run never leaves a
    partial image under a final name.
    """

    def __init__(self, root: Path):
        self.root = root
        self._dir: Path | None = None
        self._write_failed = False

    def _base(self) -> Path:
        if self._dir is None:
            beside = self.root / CACHE_DIR_NAME
            try:
                beside.mkdir(exist_ok=True)
                with tempfile.NamedTemporaryFile(dir=beside):
                    pass
                self._dir = beside
            except OSError:
                tag = hashlib.sha1(str(self.root.resolve()).encode()).hexdigest()[:16]
                self._dir = Path.home() / ".cache" / "litegs" / "undistorted" / tag
                self._dir.mkdir(parents=True, exist_ok=True)
                log.warning("dataset directory %s is not writable: undistorted images are cached in %s",
                            self.root, self._dir)
        return self._dir

    def path(self, lens: Lens, size: tuple[int, int], image: Path) -> Path:
        """The entry of `image`: its name, byte size and modification time are in the file name, so an image
        replaced in place gets a new entry."""
        rel = os.path.relpath(image, self.root).replace(os.sep, "__")
        stat = image.stat()
        return (self._base() / f"v{CACHE_VERSION}_{lens.key()}_{size[0]}x{size[1]}"
                / f"{rel}.{stat.st_size}-{stat.st_mtime_ns}.png")

    def get(self, path: Path) -> np.ndarray | None:
        if not path.is_file():
            return None
        try:
            with Image.open(path) as im:
                return np.asarray(im.convert("RGBA"), dtype=np.uint8).copy()
        except (OSError, SyntaxError, ValueError):
            return None  # a damaged cache entry is rebuilt

    def put(self, path: Path, rgba: np.ndarray) -> None:
        """Store an entry (a unique temporary name, then a rename: safe with concurrent runs); a failed write only
        costs the cache, with one log line."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
            with os.fdopen(fd, "wb") as fh:
                Image.fromarray(rgba, "RGBA").save(fh, format="PNG")
            os.replace(tmp, path)
        except OSError as exc:
            if not self._write_failed:
                log.warning("cannot write the undistortion cache in %s (%s); going on without it", path.parent, exc)
            self._write_failed = True


@dataclass
class CameraLoader:
    """Builds `Camera`s from frames: size check, undistortion (cached), resize, composite."""

    root: Path
    resolution: int
    background: torch.Tensor  # [3]
    ignore_distortion: bool = False
    _undistorters: dict[str, Undistorter] = field(default_factory=dict, init=False, repr=False)  # by lens key
    _cache: UndistortCache | None = field(default=None, init=False, repr=False)

    def camera(self, uid: int, frame: Frame, lens: Lens, size: tuple[int, int]) -> Camera:
        """The camera of `frame` whose image file is `size` = (w, h) and whose lens is in the file's pixels."""
        if self.ignore_distortion or not lens.distorted:
            pinhole, undistorter = lens.pinhole(), None
        else:
            key = lens.key()
            if key not in self._undistorters:
                self._undistorters[key] = Undistorter(lens, frame.where)
            undistorter = self._undistorters[key]
            pinhole = undistorter.pinhole
        w, h = target_size(size[0], size[1], self.resolution)
        if undistorter is None:
            rgba = _resize_rgba(read_rgba(frame.path, frame.where), (w, h))
        else:
            rgba = self._undistorted(undistorter, frame, (w, h))
        sx, sy = w / size[0], h / size[1]
        return Camera(uid, frame.name, frame.viewmat.float(), pinhole.fx * sx, pinhole.fy * sy, pinhole.cx * sx,
                      pinhole.cy * sy, w, h, composite(rgba, self.background))

    def _undistorted(self, undistorter: Undistorter, frame: Frame, size: tuple[int, int]) -> np.ndarray:
        if self._cache is None:
            self._cache = UndistortCache(self.root)
        path = self._cache.path(undistorter.lens, size, frame.path)
        cached = self._cache.get(path)
        if cached is not None and cached.shape[:2] == (size[1], size[0]):
            return cached
        rgba = read_rgba(frame.path, frame.where)
        if rgba.shape[:2] != (undistorter.lens.height, undistorter.lens.width):
            raise UserError(f"{frame.where}: image {frame.path.name} is {rgba.shape[1]}x{rgba.shape[0]} but its "
                            f"lens is {undistorter.lens.width}x{undistorter.lens.height}")
        out = _resize_rgba(undistorter.apply(rgba), size)
        self._cache.put(path, out)
        return out
