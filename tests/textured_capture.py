"""A small synthetic photo capture COLMAP can register: the inside of a box whose six faces carry multi-scale
noise textures, ray-cast (numpy) from pinhole cameras on an arc that all look into one corner. Known poses, so a
test can compare COLMAP's camera centres with the truth. Deterministic for a given seed.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

HALF = 2.0  # the box is [-2, 2]^3


def _texture(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Three octaves of smoothly upsampled colour noise. [size, size, 3] float32 in [0, 1]"""
    tex = np.zeros((size, size, 3), np.float32)
    for cells, weight in ((8, 0.5), (32, 0.3), (128, 0.2)):
        noise = rng.random((cells, cells, 3)).astype(np.float32)
        tex += weight * cv2.resize(noise, (size, size), interpolation=cv2.INTER_CUBIC)
    return np.clip(tex, 0.0, 1.0)


def camera_poses(num_views: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R world-to-camera [3,3], camera centre [3]) of cameras on an arc looking into the corner (-2, -2, -1)."""
    poses = []
    target = np.array([-HALF, -HALF, -1.0])
    for a in np.linspace(0.0, np.pi / 3, num_views):
        centre = np.array([0.9 * np.cos(a), 0.9 * np.sin(a), 0.3 + 0.2 * np.sin(3 * a)])
        z = target - centre
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)  # OpenCV: x right, y down, z forward
        poses.append((np.stack([x, y, z]), centre))
    return poses


def render_view(textures: list[np.ndarray], rot: np.ndarray, centre: np.ndarray, width: int, height: int,
                focal: float) -> np.ndarray:
    """Ray-cast the textured box from one pinhole camera. [H, W, 3] uint8"""
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    dirs_cam = np.stack([(u - width / 2) / focal, (v - height / 2) / focal, np.ones_like(u)], -1)  # [H,W,3]
    dirs = dirs_cam @ rot  # camera -> world (rot is world-to-camera)
    best_t = np.full(u.shape, np.inf)
    image = np.zeros((*u.shape, 3), np.float32)
    size = textures[0].shape[0]
    for face in range(6):
        axis, sign = face // 2, 1.0 if face % 2 else -1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (sign * HALF - centre[axis]) / dirs[..., axis]
        hit = (t > 0) & (t < best_t)
        pts = centre + t[..., None] * dirs
        a, b = [i for i in range(3) if i != axis]
        inside = hit & (np.abs(pts[..., a]) <= HALF) & (np.abs(pts[..., b]) <= HALF)
        ia = np.clip(((pts[..., a] + HALF) / (2 * HALF) * (size - 1)).astype(int), 0, size - 1)
        ib = np.clip(((pts[..., b] + HALF) / (2 * HALF) * (size - 1)).astype(int), 0, size - 1)
        image[inside] = textures[face][ib[inside], ia[inside]]
        best_t[inside] = t[inside]
    return (image * 255 + 0.5).astype(np.uint8)


def make_textured_capture(folder: Path, num_views: int = 12, width: int = 320, height: int = 240,
                          seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Write `num_views` JPEG photographs view_000.jpg ... into `folder`; returns their true poses."""
    rng = np.random.default_rng(seed)
    textures = [_texture(rng) for _ in range(6)]
    folder.mkdir(parents=True, exist_ok=True)
    poses = camera_poses(num_views)
    for i, (rot, centre) in enumerate(poses):
        Image.fromarray(render_view(textures, rot, centre, width, height, 0.8 * width)).save(
            folder / f"view_{i:03d}.jpg", quality=95)
    return poses
