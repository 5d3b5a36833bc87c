"""`GaussianModel`: the raw per-Gaussian parameters and their activations, nothing more."""
from __future__ import annotations

import os

import torch
from torch import nn

from gaussian_renderer.sh import num_sh_bases, rgb_to_sh
from scene import ply_io
from utils.errors import UserError
from utils.knn import mean_sq_dist_to_neighbours

STATE_FORMAT_VERSION = 1
INITIAL_OPACITY = 0.1
MIN_INIT_SQ_DIST = 1e-7  # 3DGS clamp: coincident points still get a finite log-scale
MAX_SH_DEGREE = 3  # highest degree the renderer evaluates
SH_BAND_EVERY = 1000  # training activates one more SH band every this many iterations (3DGS)


class GaussianModel:
    """Raw parameters in `params` (means, sh_dc, sh_rest, log_scales, quats (wxyz), logit_opacities [N])."""

    def __init__(self, sh_degree: int, params: dict[str, torch.Tensor] | None = None):
        if not 0 <= sh_degree <= MAX_SH_DEGREE:
            raise UserError(f"SH degree {sh_degree} is not supported; use --sh_degree between 0 and {MAX_SH_DEGREE}")
        self.max_sh_degree = sh_degree
        self.active_sh_degree = 0
        self.params: dict[str, nn.Parameter] = {}
        if params is not None:
            self.set_params(params)

    def set_params(self, params: dict[str, torch.Tensor]) -> None:
        """Replace every parameter (as leaf `nn.Parameter`s)."""
        self.params = {k: nn.Parameter(v.detach().clone().contiguous()) for k, v in params.items()}

    # ---- activated views -------------------------------------------------------------------------------
    @property
    def means(self) -> torch.Tensor:  # [N, 3]
        return self.params["means"]

    @property
    def quats(self) -> torch.Tensor:  # [N, 4] raw (the projection normalises)
        return self.params["quats"]

    @property
    def unit_quats(self) -> torch.Tensor:  # [N, 4]
        q = self.params["quats"]
        return q / q.norm(dim=-1, keepdim=True)

    @property
    def scales(self) -> torch.Tensor:  # [N, 3]
        return torch.exp(self.params["log_scales"])

    @property
    def opacities(self) -> torch.Tensor:  # [N]
        return torch.sigmoid(self.params["logit_opacities"])

    @property
    def sh_coeffs(self) -> torch.Tensor:  # [N, K, 3]
        return torch.cat([self.params["sh_dc"], self.params["sh_rest"]], dim=1)

    @property
    def num_gaussians(self) -> int:
        return self.params["means"].shape[0]

    @property
    def device(self) -> torch.device:
        return self.params["means"].device

    @staticmethod
    def trained_sh_degree(iteration: int, max_degree: int, from_ply: bool) -> int:
        """The active SH degree of train.py's model after `iteration` iterations: one more band every
        `SH_BAND_EVERY`, or every band from the start for a run continued from a PLY (--init_ply, as 3DGS loads one)."""
        return max_degree if from_ply else min(iteration // SH_BAND_EVERY, max_degree)

    def increase_sh_degree(self) -> None:
        """Activate one more SH band, up to `max_sh_degree`."""
        self.active_sh_degree = min(self.active_sh_degree + 1, self.max_sh_degree)

    # ---- construction ----------------------------------------------------------------------------------
    @classmethod
    def from_point_cloud(cls, points: torch.Tensor, colors: torch.Tensor, sh_degree: int,
                         device: str | torch.device = "cpu") -> "GaussianModel":
        """The 3DGS initialisation: colour in the SH DC term, isotropic scale from the 3 nearest neighbours,
        identity rotation, opacity 0.1.

        Args:
            points: positions. [P, 3]
            colors: RGB in [0, 1]. [P, 3]
        """
        if points.dim() != 2 or points.shape[1] != 3 or colors.shape != points.shape or points.shape[0] == 0:
            raise UserError(f"initial point cloud must be non-empty [P, 3] points with [P, 3] colours, got "
                            f"{tuple(points.shape)} and {tuple(colors.shape)}; check the input PLY / points3D file")
        if not (torch.isfinite(points).all() and torch.isfinite(colors).all()):
            raise UserError("initial point cloud has NaN or infinite values; clean the input PLY / points3D file")
        points = points.to(device=device, dtype=torch.float32)
        n = points.shape[0]
        dist2 = mean_sq_dist_to_neighbours(points, k=3).clamp_min(MIN_INIT_SQ_DIST)  # [P]
        quats = torch.zeros(n, 4, device=device)
        quats[:, 0] = 1.0
        return cls(sh_degree, {
            "means": points,
            "sh_dc": rgb_to_sh(colors.to(device=device, dtype=torch.float32))[:, None, :],
            "sh_rest": torch.zeros(n, num_sh_bases(sh_degree) - 1, 3, device=device),
            "log_scales": torch.log(torch.sqrt(dist2))[:, None].repeat(1, 3),
            "quats": quats,
            "logit_opacities": torch.logit(torch.full((n,), INITIAL_OPACITY, device=device)),
        })

    # ---- persistence ------------------------------------------------------------------------------------
    def save_ply(self, path: str | os.PathLike) -> None:
        """Write the standard 3DGS PLY (opens in common splat viewers)."""
        ply_io.save_ply(path, {k: v.detach() for k, v in self.params.items()})

    @classmethod
    def load_ply(cls, path: str | os.PathLike, device: str | torch.device = "cpu") -> "GaussianModel":
        """Read a standard 3DGS PLY; the SH degree follows from its f_rest count (all of it active)."""
        params, degree = ply_io.load_ply(path)
        model = cls(degree, {k: v.to(device) for k, v in params.items()})
        model.active_sh_degree = degree
        return model

    def state_dict(self) -> dict:
        """Named, versioned snapshot: `format_version`, SH degrees and detached copies of `params`."""
        return {"format_version": STATE_FORMAT_VERSION, "max_sh_degree": self.max_sh_degree,
                "active_sh_degree": self.active_sh_degree,
                "params": {k: v.detach().clone() for k, v in self.params.items()}}

    def load_state_dict(self, state: dict) -> None:
        """Restore a `state_dict()`; parameters land on this model's device (CPU when it has none yet)."""
        if state.get("format_version") != STATE_FORMAT_VERSION:
            raise UserError(f"checkpoint holds GaussianModel state version {state.get('format_version')}, this code "
                            f"reads version {STATE_FORMAT_VERSION}; resume with the code that wrote it or retrain")
        self.max_sh_degree = state["max_sh_degree"]
        self.active_sh_degree = state["active_sh_degree"]
        device = self.device if self.params else "cpu"
        self.set_params({k: v.to(device) for k, v in state["params"].items()})
