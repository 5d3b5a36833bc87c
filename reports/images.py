"""Images embedded in a report: base64 data URIs of downscaled JPEG/PNG, and per-pixel error maps."""
from __future__ import annotations

import base64
import io
from pathlib import Path

import numpy as np
from PIL import Image

from utils.errors import UserError

MAX_SIDE = 320  # embedded images are at most this many pixels a side (click to enlarge shows them larger)


def open_rgb(path: Path) -> np.ndarray:
    """The first three channels of an image file. [H, W, 3] uint8

    Raises:
        UserError: the file cannot be decoded.
    """
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"))
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot read image {path} ({type(exc).__name__}: {exc}); rerun render.py") from None


def data_uri(image: np.ndarray, fmt: str = "JPEG", max_side: int = MAX_SIDE, quality: int = 85) -> str:
    """A `data:image/...;base64,` URI of `image` [H, W, 3] uint8, shrunk (never enlarged) to `max_side`."""
    im = Image.fromarray(image)
    scale = max_side / max(im.size)
    if scale < 1:
        im = im.resize((max(1, round(im.width * scale)), max(1, round(im.height * scale))), Image.LANCZOS)
    buf = io.BytesIO()
    if fmt == "JPEG":
        im.save(buf, "JPEG", quality=quality)
    else:
        im.save(buf, "PNG", optimize=True)
    return f"data:image/{fmt.lower()};base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def file_uri(path: Path, fmt: str = "JPEG", max_side: int = MAX_SIDE) -> str:
    """`data_uri` of an image file."""
    return data_uri(open_rgb(path), fmt, max_side)


def error_map(gt: np.ndarray, render: np.ndarray) -> np.ndarray:
    """Mean absolute error over the channels, coloured with matplotlib's 'magma' on [0, 0.25] (clipped).

    gt, render: [H, W, 3] uint8. Returns [H, W, 3] uint8.
    """
    from matplotlib import colormaps

    err = np.abs(gt.astype(np.float32) - render.astype(np.float32)).mean(axis=2) / 255.0  # [H, W]
    rgba = colormaps["magma"](np.clip(err / 0.25, 0.0, 1.0))  # [H, W, 4]
    return (rgba[..., :3] * 255 + 0.5).astype(np.uint8)
