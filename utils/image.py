"""Image IO and PSNR."""
from __future__ import annotations

import os

import numpy as np
import torch
from PIL import Image


def load_rgba(path: str | os.PathLike) -> torch.Tensor:
    """An image file as float RGBA in [0, 1]. [4, H, W]"""
    with Image.open(path) as im:
        arr = np.asarray(im.convert("RGBA"), dtype=np.float32) / 255.0
    return torch.from_numpy(arr).permute(2, 0, 1).contiguous()


def save_image(image: torch.Tensor, path: str | os.PathLike) -> None:
    """Write [3, H, W] (or [4, H, W]) floats in [0, 1] as an 8-bit PNG."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    arr = (image.detach().clamp(0, 1).permute(1, 2, 0).cpu().numpy() * 255.0 + 0.5).astype(np.uint8)
    Image.fromarray(arr).save(path)


def psnr(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """PSNR in dB of images in [0, 1] (MSE over all pixels and channels)."""
    mse = torch.mean((img1 - img2) ** 2)
    return 10.0 * torch.log10(1.0 / mse.clamp_min(1e-20))
