"""Parameter surgery for densification: free functions over the model's parameters and the Adam state."""
from __future__ import annotations

import torch
from torch import nn

from scene.gaussian_model import GaussianModel


def _swap(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, name: str, new_value: torch.Tensor,
          remap_state) -> None:
    """Replace parameter `name` by `new_value`, transforming its Adam moments with `remap_state`."""
    for group in optimizer.param_groups:
        if group["name"] != name:
            continue
        old = group["params"][0]
        new = nn.Parameter(new_value.contiguous())
        state = optimizer.state.pop(old, None)
        if state is not None:
            state["exp_avg"] = remap_state(state["exp_avg"])
            state["exp_avg_sq"] = remap_state(state["exp_avg_sq"])
            optimizer.state[new] = state
        group["params"][0] = new
        gaussians.params[name] = new
        return
    raise KeyError(f"optimizer has no group named {name!r}")


@torch.no_grad()
def append_params(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, new: dict[str, torch.Tensor]) -> None:
    """Append Gaussians (`new[name]` rows for every parameter); their Adam moments start at zero."""
    for name, rows in new.items():
        old = gaussians.params[name]
        _swap(gaussians, optimizer, name, torch.cat([old.detach(), rows.to(old)], dim=0),
              lambda s, rows=rows: torch.cat([s, torch.zeros_like(rows, dtype=s.dtype)], dim=0))


@torch.no_grad()
def prune_params(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, keep: torch.Tensor) -> None:
    """Keep only the Gaussians where `keep` [N] is True (parameters and Adam moments alike)."""
    for name in list(gaussians.params):
        _swap(gaussians, optimizer, name, gaussians.params[name].detach()[keep], lambda s: s[keep])


@torch.no_grad()
def replace_param(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, name: str,
                  value: torch.Tensor) -> None:
    """Set parameter `name` to `value` and reset its Adam moments to zero."""
    _swap(gaussians, optimizer, name, value.detach().clone(), torch.zeros_like)
