"""Image IO: 8-bit PNG <-> float tensors in [0, 1] (PSNR lives in utils.losses)."""
from __future__ import annotations

import os

import numpy as np
import torch
from PIL import Image


def load_rgba(path: str | os.PathLike) -> torch.Tensor:
    """An image file as float RGBA in [0, 1] (alpha 1 where the file has none). [4, H, W]"""
    with Image.open(path) as im:
        arr = np.asarray(im.convert("RGBA"), dtype=np.float32) / 255.0
    return torch.from_numpy(arr).permute(2, 0, 1).contiguous()


def save_image(image: torch.Tensor, path: str | os.PathLike) -> None:
    """Write an RGB [3, H, W] or RGBA [4, H, W] float image in [0, 1] (clamped, rounded) as an 8-bit PNG."""
    assert image.ndim == 3 and image.shape[0] in (3, 4), f"image must be [3|4, H, W], got {tuple(image.shape)}"
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    arr = (image.detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy() * 255.0 + 0.5).astype(np.uint8)
    Image.fromarray(arr).save(path)
