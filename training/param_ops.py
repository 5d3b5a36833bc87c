"""Parameter surgery for densification: free functions over the model's parameters and the Adam state.

Each op swaps in a new leaf `nn.Parameter` in both `gaussians.params` and its optimizer group (matched by the
group's `name`) and transforms the per-element optimizer state (Adam's `exp_avg`, `exp_avg_sq`, and
`max_exp_avg_sq` under amsgrad) the same way as the rows, so the next `optimizer.step()` treats every surviving
Gaussian exactly as before and every new one as a Gaussian whose gradient has been zero so far. The shared `step`
counter is kept.
"""
from __future__ import annotations

from typing import Callable

import torch
from torch import nn

from scene.gaussian_model import GaussianModel


def _swap(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, name: str, new_value: torch.Tensor,
          remap_state: Callable[[torch.Tensor], torch.Tensor]) -> None:
    """Replace parameter `name` by `new_value`, transforming its per-element optimizer state with `remap_state`."""
    for group in optimizer.param_groups:
        if group.get("name") != name:
            continue
        assert len(group["params"]) == 1, f"group {name!r} must hold exactly one parameter"
        old = group["params"][0]
        new = nn.Parameter(new_value.contiguous())
        state = optimizer.state.pop(old, None)
        if state is not None:
            for key, value in state.items():
                if key != "step" and torch.is_tensor(value) and value.shape == old.shape:
                    state[key] = remap_state(value)
            optimizer.state[new] = state
        group["params"][0] = new
        gaussians.params[name] = new
        return
    raise KeyError(f"optimizer has no group named {name!r}")


@torch.no_grad()
def append_params(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, new: dict[str, torch.Tensor]) -> None:
    """Append M Gaussians: `new[name]` holds M rows for every parameter. Their optimizer state starts at zero."""
    assert set(new) == set(gaussians.params), f"need rows for {sorted(gaussians.params)}, got {sorted(new)}"
    counts = {rows.shape[0] for rows in new.values()}
    assert len(counts) == 1, f"every parameter needs the same number of new rows, got {counts}"
    for name, rows in new.items():
        old = gaussians.params[name]
        assert rows.shape[1:] == old.shape[1:], f"{name}: rows {tuple(rows.shape)} vs parameter {tuple(old.shape)}"
        _swap(gaussians, optimizer, name, torch.cat([old.detach(), rows.to(old)], dim=0),
              lambda s, m=rows.shape[0]: torch.cat([s, s.new_zeros((m, *s.shape[1:]))], dim=0))


@torch.no_grad()
def prune_params(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, keep: torch.Tensor) -> None:
    """Keep only the Gaussians where `keep` [N] (bool) is True, parameters and optimizer state alike."""
    assert keep.dtype == torch.bool and keep.shape == (gaussians.num_gaussians,), \
        f"keep must be a bool mask [{gaussians.num_gaussians}], got {keep.dtype} {tuple(keep.shape)}"
    for name in list(gaussians.params):
        _swap(gaussians, optimizer, name, gaussians.params[name].detach()[keep], lambda s: s[keep])


@torch.no_grad()
def replace_param(gaussians: GaussianModel, optimizer: torch.optim.Optimizer, name: str,
                  value: torch.Tensor) -> None:
    """Set parameter `name` to `value` (same shape) and reset its optimizer state to zero."""
    old = gaussians.params[name]
    assert value.shape == old.shape, f"{name}: value {tuple(value.shape)} vs parameter {tuple(old.shape)}"
    _swap(gaussians, optimizer, name, value.detach().clone().to(old), torch.zeros_like)
