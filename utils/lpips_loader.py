"""LPIPS without downloads: the `lpips` package with a full state dict from disk, or nothing (never a made-up number)."""
from __future__ import annotations

import logging
import os
import re
import warnings
from pathlib import Path

import torch

log = logging.getLogger(__name__)

REPO_ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("alex", "vgg", "squeeze")


def default_weights_path() -> Path | None:
    """$LITEGS_LPIPS_WEIGHTS, else ../shared/weights/lpips_squeeze.pt beside the repository, if it exists."""
    env = os.environ.get("LITEGS_LPIPS_WEIGHTS")
    candidates = [Path(env)] if env else [REPO_ROOT.parent / "shared" / "weights" / "lpips_squeeze.pt"]
    return next((p for p in candidates if p.is_file()), None)


def _variant_from_state(state: dict) -> str | None:
    """Guess the backbone from the state-dict keys (lin layer count and first-conv width)."""
    lin_layers = {k.split(".")[0] for k in state if re.match(r"lin\d+\.", k)}
    if len(lin_layers) == 7:
        return "squeeze"
    first = next((v for k, v in state.items() if k.startswith("net.") and k.endswith("weight")), None)
    if first is None:
        return None
    return "alex" if first.shape[0] == 64 and first.shape[-1] == 11 else "vgg"


def load_lpips(weights_path: str | os.PathLike | None = None, device: str = "cpu"):
    """Return (model, variant), or None after one log line saying why LPIPS is unavailable."""
    path = Path(weights_path) if weights_path else default_weights_path()
    if path is None:
        log.warning("LPIPS unavailable: no weights given (--lpips_weights PATH or $LITEGS_LPIPS_WEIGHTS) and "
                    "none found at ../shared/weights/lpips_squeeze.pt; reporting LPIPS as null")
        return None
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        log.warning("LPIPS unavailable: cannot read %s (%s); reporting LPIPS as null", path, type(exc).__name__)
        return None
    variant = _variant_from_state(state) if isinstance(state, dict) else None
    if variant is None:
        log.warning("LPIPS unavailable: %s is not an LPIPS state dict; reporting LPIPS as null", path)
        return None
    import lpips  # imported here: torchvision is slow to import and only metrics need it

    with warnings.catch_warnings():  # torchvision's deprecation notes about `pretrained`
        warnings.simplefilter("ignore")
        model = lpips.LPIPS(net=variant, pretrained=True, pnet_rand=True, verbose=False)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError:
        log.warning("LPIPS unavailable: %s does not match the %s LPIPS network; reporting LPIPS as null", path,
                    variant)
        return None
    return model.eval().to(device), variant
