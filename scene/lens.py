"""Lens models and undistortion with OpenCV: a distorted camera becomes a pinhole one, once, at load time.

A `Lens` holds a camera's intrinsics in the pixels of its image file (our convention: pixel (x, y) has its centre
at (x + 0.5, y + 0.5), as in COLMAP and nerfstudio) and its distortion coefficients in OpenCV's order:
- "OPENCV": (k1, k2, p1, p2[, k3[, k4, k5, k6]]) for `cv2.undistort*` (COLMAP SIMPLE_RADIAL, RADIAL, OPENCV,
  FULL_OPENCV; nerfstudio OPENCV);
- "OPENCV_FISHEYE": (k1, k2, k3, k4) for `cv2.fisheye` (COLMAP and nerfstudio OPENCV_FISHEYE).

`Undistorter` maps a distorted lens to the pinhole lens of `cv2.getOptimalNewCameraMatrix(alpha=0)` (fisheye:
`estimateNewCameraMatrixForUndistortRectify(balance=0)`): same image size, every output pixel sees the scene (no
black borders), at the cost of cropping the corners the distortion bends outwards.
"""
from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import dataclass, replace

import cv2
import numpy as np

from utils.errors import UserError

log = logging.getLogger(__name__)

LENS_MODELS = ("OPENCV", "OPENCV_FISHEYE")
# Undistortion is refused when fewer output pixels than this fraction sample inside the input image, or when the
# new focal length leaves this range relative to the old one: both mean the coefficients do not describe a lens.
MIN_VALID_FRACTION = 0.98
FOCAL_RATIO_RANGE = (0.25, 4.0)
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
ROUND_TRIP_PX = 0.5  # undistort-then-distort must land within this many pixels of where it started


@dataclass(frozen=True)
class Lens:
    """Intrinsics (pixels of a `width` x `height` image) and distortion coefficients in OpenCV order."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    model: str = "OPENCV"
    dist: tuple[float, ...] = ()

    @property
    def distorted(self) -> bool:
        return any(d != 0.0 for d in self.dist)

    def pinhole(self) -> "Lens":
        """The same intrinsics with the distortion dropped (what `--ignore_distortion` uses)."""
        return replace(self, model="OPENCV", dist=())

    def scaled(self, width: int, height: int) -> "Lens":
        """The lens for the same image stored at `width` x `height` (coefficients are resolution-free)."""
        sx, sy = width / self.width, height / self.height
        return replace(self, width=width, height=height, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx,
                       cy=self.cy * sy)

    def cv_matrix(self) -> np.ndarray:
        """OpenCV's camera matrix (pixel centres at integers, so the principal point moves by half a pixel). [3, 3]"""
        return np.array([[self.fx, 0, self.cx - 0.5], [0, self.fy, self.cy - 0.5], [0, 0, 1]], dtype=np.float64)

    def key(self) -> str:
        """A short hash of every parameter (the undistortion cache's key)."""
        text = json.dumps([self.model, self.width, self.height, self.fx, self.fy, self.cx, self.cy, list(self.dist)])
        return hashlib.sha1(text.encode()).hexdigest()[:16]


def _from_cv_matrix(k: np.ndarray, width: int, height: int) -> Lens:
    return Lens(width, height, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]) + 0.5, float(k[1, 2]) + 0.5)


def pixel_grid(width: int, height: int) -> np.ndarray:
    """OpenCV pixel-centre coordinates of every pixel, row-major. [H*W, 1, 2] float64"""
    xs, ys = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    return np.stack([xs.ravel(), ys.ravel()], axis=1)[:, None, :]


def undistort_points(lens: Lens, points: np.ndarray, target: Lens | None = None) -> np.ndarray:
    """Pixels of the distorted `lens` [M, 1, 2] (OpenCV coordinates) -> pixels of the pinhole `target`, or
    normalized coordinates without one. Iterated to convergence (OpenCV's default stops after 5 steps). [M, 1, 2]"""
    dist = np.array(lens.dist, dtype=np.float64)
    p = None if target is None else target.cv_matrix()
    if lens.model == "OPENCV_FISHEYE":
        return cv2.fisheye.undistortPoints(points, lens.cv_matrix(), dist, R=None, P=p, criteria=UNDISTORT_CRITERIA)
    return cv2.undistortPoints(points, lens.cv_matrix(), dist, R=None, P=p, criteria=UNDISTORT_CRITERIA)


class Undistorter:
    """The pinhole lens and the remap tables of one distorted lens (built once, applied to every image)."""

    def __init__(self, lens: Lens, where: str):
        if lens.model not in LENS_MODELS:
            raise UserError(f"{where}: unknown camera model {lens.model!r}; supported: {', '.join(LENS_MODELS)}")
        self.lens = lens
        size = (lens.width, lens.height)
        k, dist = lens.cv_matrix(), np.array(lens.dist, dtype=np.float64)
        try:
            if lens.model == "OPENCV_FISHEYE":
                if len(dist) != 4:
                    raise UserError(f"{where}: OPENCV_FISHEYE needs 4 coefficients k1..k4, got {len(dist)}")
                new_k = cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(k, dist, size, np.eye(3), balance=0.0)
                map_x, map_y = cv2.fisheye.initUndistortRectifyMap(k, dist, np.eye(3), new_k, size, cv2.CV_32FC1)
            else:
                new_k, _ = cv2.getOptimalNewCameraMatrix(k, dist, size, 0.0, size)
                map_x, map_y = cv2.initUndistortRectifyMap(k, dist, None, new_k, size, cv2.CV_32FC1)
        except cv2.error as exc:
            raise UserError(f"{where}: undistortion failed for coefficients {list(lens.dist)} "
                            f"({str(exc).strip().splitlines()[-1]}); check the distortion parameters") from None
        self.pinhole = _from_cv_matrix(new_k, lens.width, lens.height)
        self.map_x, self.map_y = map_x, map_y  # [H, W] each: where each output pixel samples the input
        self._check(where)

    def _check(self, where: str) -> None:
        """Refuse coefficients whose undistortion is degenerate: the distortion does not invert on the frame
        (it folds over, so undistorting then distorting again misses by more than ROUND_TRIP_PX), or the pinhole
        it gives is implausible (see MIN_VALID_FRACTION, FOCAL_RATIO_RANGE)."""
        p, lens = self.pinhole, self.lens
        error = round_trip_error(lens)
        if not error <= ROUND_TRIP_PX:
            raise UserError(f"{where}: undistortion failed for {lens.model} coefficients {list(lens.dist)}: the "
                            f"lens model folds over inside the {lens.width}x{lens.height} frame (round trip off by "
                            f"{error:.3g} px); check the distortion parameters or pass --ignore_distortion")
        ratio = p.fx / lens.fx if np.isfinite(p.fx) else float("nan")
        inside = ((self.map_x >= -0.5) & (self.map_x <= lens.width - 0.5) & (self.map_y >= -0.5)
                  & (self.map_y <= lens.height - 0.5))
        valid = float(inside.mean()) if np.isfinite(self.map_x).all() and np.isfinite(self.map_y).all() else 0.0
        finite = all(np.isfinite(v) for v in (p.fx, p.fy, p.cx, p.cy))
        if not finite or not FOCAL_RATIO_RANGE[0] <= ratio <= FOCAL_RATIO_RANGE[1] or valid < MIN_VALID_FRACTION:
            raise UserError(f"{where}: undistortion failed for {lens.model} coefficients {list(lens.dist)} "
                            f"(new focal {ratio:.3g}x the old, {100 * valid:.1f}% of pixels inside the image); "
                            "check the distortion parameters or pass --ignore_distortion")

    def apply(self, image: np.ndarray) -> np.ndarray:
        """Undistort an [H, W, C] uint8 image of `lens`'s size (bilinear). [H, W, C] uint8"""
        assert image.shape[:2] == (self.lens.height, self.lens.width), (image.shape, self.lens)
        return cv2.remap(image, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)


def round_trip_error(lens: Lens, samples: int = 24) -> float:
    """Largest pixel error of distort(undistort(x)) over a `samples` x `samples` grid and the frame's border."""
    xs, ys = np.linspace(0, lens.width - 1, samples), np.linspace(0, lens.height - 1, samples)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 1, 2)  # [S*S, 1, 2]
    k, dist = lens.cv_matrix(), np.array(lens.dist, dtype=np.float64)
    with np.errstate(all="ignore"):
        normalized = undistort_points(lens, grid)  # [M, 1, 2]
        if lens.model == "OPENCV_FISHEYE":
            back = cv2.fisheye.distortPoints(normalized, k, dist)
        else:
            points = np.concatenate([normalized[:, 0], np.ones((len(grid), 1))], axis=1)  # [M, 3]
            back, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, dist)
        error = np.abs(back.reshape(-1, 2) - grid.reshape(-1, 2)).max()
    return float(error) if np.isfinite(error) else float("inf")


def distortion_maps(lens: Lens, source: Lens) -> tuple[np.ndarray, np.ndarray]:
    """Remap tables that render a distorted `lens` image from a pinhole `source` image (the inverse of
    undistortion; used to make synthetic captures). [H, W] each, in `source` pixels."""
    grid = undistort_points(lens, pixel_grid(lens.width, lens.height), source)  # [H*W, 1, 2]
    xy = grid.reshape(lens.height, lens.width, 2).astype(np.float32)
    return xy[..., 0], xy[..., 1]
