"""LPIPS without downloads: the `lpips` package with weights already on disk, or nothing (never a made-up number).

Two sources, neither touching the network:
- a full LPIPS state dict (backbone + linear layers), by default the repository's weights/lpips_squeeze.pt
  (see weights/LICENSES.md), loaded strictly; its variant (alex / vgg / squeeze) is read from the keys;
- without one, torchvision's ImageNet backbone file if it is already in the torch hub cache
  (`<torch.hub.get_dir()>/checkpoints/`), plus the linear layers shipped inside the `lpips` package.
The network is always built with `pnet_rand=True` (random backbone, so torchvision downloads nothing) and the real
weights are loaded afterwards. Where no weights are found, one log line says why and `load_lpips` returns None.
"""
from __future__ import annotations

import logging
import os
import re
import warnings
from pathlib import Path

import torch

from utils.errors import UserError

log = logging.getLogger(__name__)

REPO_ROOT = Path(__file__).resolve().parents[1]
SHIPPED_WEIGHTS = REPO_ROOT / "weights" / "lpips_squeeze.pt"
WEIGHTS_ENV = "LITEGS_LPIPS_WEIGHTS"
VARIANTS = ("alex", "vgg", "squeeze")
# Smallest image side each backbone accepts (measured with lpips 0.1.4: one pixel less makes a pooling layer's
# output empty and the network raises). Checked in tests/test_metrics.py.
LPIPS_MIN_SIDE = {"squeeze": 17, "alex": 31, "vgg": 16}


def default_weights_path(net: str | None = None) -> Path | None:
    """$LITEGS_LPIPS_WEIGHTS when set (even if missing, so the caller reports it), else the repository's
    weights/lpips_squeeze.pt if it exists and `net` is None or "squeeze", else None (then the torch hub cache is
    tried for `net`, e.g. AlexNet)."""
    env = os.environ.get(WEIGHTS_ENV)
    if env:
        return Path(env)
    return SHIPPED_WEIGHTS if SHIPPED_WEIGHTS.is_file() and net in (None, "squeeze") else None


def infer_variant(state: dict) -> str | None:
    """The LPIPS backbone of a full LPIPS state dict, from its keys, or None if it is not one.

    squeeze has 7 linear layers (lin0..lin6), alex and vgg 5; alex's first conv is 11x11, vgg's 3x3.
    """
    lin_layers = {k.split(".")[0] for k in state if re.match(r"lin\d+\.model\.", k)}
    first = state.get("net.slice1.0.weight")
    if first is None or not isinstance(first, torch.Tensor) or first.dim() != 4:
        return None
    if len(lin_layers) == 7:
        return "squeeze"
    if len(lin_layers) == 5:
        return {11: "alex", 3: "vgg"}.get(first.shape[-1])
    return None


def _build(net: str):
    """An LPIPS network with a random backbone and the package's linear layers; downloads nothing."""
    import lpips  # imported here: torchvision is slow to import and only the metrics need it

    with warnings.catch_warnings():  # torchvision's deprecation notes about `pretrained`
        warnings.simplefilter("ignore")
        return lpips.LPIPS(net=net, pretrained=True, pnet_rand=True, verbose=False)


def _backbone_file(net: str) -> Path:
    """Where torchvision keeps the ImageNet weights of the LPIPS backbone `net` in the torch hub cache."""
    from torchvision.models import AlexNet_Weights, SqueezeNet1_1_Weights, VGG16_Weights

    url = {"alex": AlexNet_Weights, "vgg": VGG16_Weights, "squeeze": SqueezeNet1_1_Weights}[net].IMAGENET1K_V1.url
    return Path(torch.hub.get_dir()) / "checkpoints" / url.rsplit("/", 1)[-1]


def _from_state_dict(path: Path, net: str | None):
    """(model, variant) from a full LPIPS state dict, or None after one log line."""
    if not path.is_file():
        log.warning("LPIPS unavailable: weights file %s does not exist; reporting LPIPS as null", path)
        return None
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # any unreadable file: LPIPS is optional, the other metrics go on
        log.warning("LPIPS unavailable: cannot read %s (%s); reporting LPIPS as null", path, type(exc).__name__)
        return None
    variant = infer_variant(state) if isinstance(state, dict) else None
    if variant is None:
        log.warning("LPIPS unavailable: %s is not a full LPIPS state dict; reporting LPIPS as null", path)
        return None
    if net is not None and net != variant:
        raise UserError(f"--lpips_net {net} does not match {path}, which holds LPIPS-{variant} weights; "
                        f"pass --lpips_net {variant} or weights for {net}")
    model = _build(variant)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError:
        log.warning("LPIPS unavailable: %s does not match the LPIPS-%s network; reporting LPIPS as null", path,
                    variant)
        return None
    return model, variant


def _from_hub_cache(net: str):
    """(model, net) from torchvision's backbone file already in the torch hub cache, or None after one log line."""
    file = _backbone_file(net)
    if not file.is_file():
        log.warning("LPIPS unavailable: no weights given (--lpips_weights PATH or $%s) and the %s backbone %s is "
                    "not in the torch hub cache (nothing is downloaded); reporting LPIPS as null", WEIGHTS_ENV, net,
                    file)
        return None
    try:
        backbone = torch.load(file, map_location="cpu", weights_only=True)
    except Exception as exc:  # as above: a broken cache file only disables LPIPS
        log.warning("LPIPS unavailable: cannot read %s (%s); reporting LPIPS as null", file, type(exc).__name__)
        return None
    model = _build(net)
    # lpips keeps torchvision's `features[i]` as `slice<k>.<i>`: map each of its keys back to `features.<i>...`.
    wanted = model.net.state_dict().keys()
    renamed = {k: backbone.get(re.sub(r"^slice\d+\.", "features.", k)) for k in wanted}
    missing = [k for k, v in renamed.items() if v is None]
    if missing:
        log.warning("LPIPS unavailable: %s lacks %s for the LPIPS-%s backbone; reporting LPIPS as null", file,
                    missing[0], net)
        return None
    try:
        model.net.load_state_dict(renamed, strict=True)
    except RuntimeError:
        log.warning("LPIPS unavailable: %s does not match the LPIPS-%s backbone; reporting LPIPS as null", file, net)
        return None
    return model, net


def load_lpips(net: str | None = "squeeze", weights_path: str | os.PathLike | None = None,
               device: str | torch.device = "cpu"):
    """Load LPIPS from disk only: returns (model, variant), or None after one log line saying why.

    Args:
        net: Backbone: "squeeze", "alex" or "vgg". With `weights_path` it must match the weights (None: take the
            variant the weights hold); without, it picks the backbone looked up in the torch hub cache
            (None: "squeeze").
        weights_path: A full LPIPS state dict (as saved by `lpips.LPIPS(...).state_dict()`).
        device: Where the model goes.
    Returns:
        (model in eval mode without gradients, variant name), or None when no usable weights are found.
    Raises:
        UserError: `net` is not a known variant, or differs from the variant the weights hold.
    """
    if net is not None and net not in VARIANTS:
        raise UserError(f"unknown LPIPS network {net!r}; use one of {', '.join(VARIANTS)}")
    loaded = _from_state_dict(Path(weights_path), net) if weights_path else _from_hub_cache(net or "squeeze")
    if loaded is None:
        return None
    model, variant = loaded
    return model.eval().requires_grad_(False).to(device), variant


def lpips_distance(model: torch.nn.Module, variant: str, img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor | None:
    """LPIPS of images in [0, 1], or None when a side is below what the backbone accepts (LPIPS_MIN_SIDE).

    Args:
        img1, img2: Images. [3, H, W] or [B, 3, H, W]
    Returns:
        Scalar tensor for [3, H, W] inputs, per-image distances [B] for batches; None for too-small images.
    """
    assert img1.shape == img2.shape, f"shapes differ: {tuple(img1.shape)} vs {tuple(img2.shape)}"
    if min(img1.shape[-2:]) < LPIPS_MIN_SIDE[variant]:
        return None
    batched = img1.dim() == 4
    a, b = (img1, img2) if batched else (img1[None], img2[None])
    out = model(a * 2 - 1, b * 2 - 1).flatten()  # LPIPS takes [-1, 1]. [B]
    return out if batched else out[0]
