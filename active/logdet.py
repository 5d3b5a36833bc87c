"""Block-diagonal D-optimal information: log-det gains of per-Gaussian Fisher blocks, in float64.

A = H_0 + sum_{v in S} H_v, with H_0 = (sum of the training views' blocks) + ridge. For a block-diagonal matrix the
log-det is a sum of small per-Gaussian log-dets. A marginal gain is computed in the whitened form

    rho(v | S) = sum_i logdet(I + L_i^-1 H_v,i L_i^-T),   L_i L_i^T = A_i (Cholesky, cached until the next commit),

which needs no factorisation of A + H_v. Real blocks are nearly singular (the normalised quaternion leaves an exact
null direction; float32 accumulation leaves tiny negative eigenvalues), so: blocks are symmetrised in float64; the
ridge is relative, delta_i = delta_rel * max diag(H_0,i) + delta_abs, so every prior block is positive definite
whatever its units; and I + W is factorised with a Cholesky whose rare failures (W's tiny negative eigenvalues) fall
back to an eigen-decomposition with eigenvalues clamped at 0. A gain is never NaN: a prior that cannot be factorised
is an error naming the Gaussian count and the ridge.
"""
from __future__ import annotations

from typing import Callable

import torch

from utils.errors import UserError


def symmetrize(blocks: torch.Tensor) -> torch.Tensor:
    """(B + B^T) / 2 in float64. [N, P, P]"""
    b = blocks.double()
    return 0.5 * (b + b.transpose(-1, -2))


def logdet_identity_plus(w: torch.Tensor) -> torch.Tensor:
    """sum_i logdet(I + W_i) for symmetric W_i >= -tiny. [N, P, P] -> scalar (float64)"""
    eye = torch.eye(w.shape[-1], dtype=w.dtype, device=w.device)
    chol, info = torch.linalg.cholesky_ex(eye + w)
    ok = info == 0
    total = 2.0 * torch.log(torch.diagonal(chol[ok], dim1=-2, dim2=-1)).sum()
    if not bool(ok.all()):
        eig = torch.linalg.eigvalsh(w[~ok]).clamp_min(0.0)
        total = total + torch.log1p(eig).sum()
    return total


class BlockInformation:
    """The running information A = H_0 + sum_S H_v of a stage, with its Cholesky factor cached."""

    def __init__(self, prior_blocks: torch.Tensor, delta_rel: float = 1e-6, delta_abs: float = 1e-8):
        """prior_blocks: sum of the training views' Fisher blocks. [N, P, P]"""
        h0 = symmetrize(prior_blocks)
        n, p, _ = h0.shape
        diag_max = torch.diagonal(h0, dim1=-2, dim2=-1).amax(dim=-1) if n else h0.new_zeros(0)  # [N]
        ridge = delta_rel * diag_max.clamp_min(0.0) + delta_abs
        eye = torch.eye(p, dtype=h0.dtype, device=h0.device)
        self.delta_rel, self.delta_abs = delta_rel, delta_abs
        self.matrix = h0 + ridge[:, None, None] * eye
        self._factorize()
        self.prior_logdet = self.logdet()

    def _factorize(self) -> None:
        chol, info = torch.linalg.cholesky_ex(self.matrix)
        if bool((info != 0).any()):
            bad = int((info != 0).sum())
            raise UserError(f"the Fisher prior is not positive definite for {bad} of {self.matrix.shape[0]} "
                            f"Gaussians with ridge delta_rel={self.delta_rel:g}, delta_abs={self.delta_abs:g}; "
                            "raise --delta_rel or --delta_abs")
        self.chol = chol

    def whiten(self, blocks: torch.Tensor) -> torch.Tensor:
        """L^-1 H L^-T, symmetrised. [N, P, P]"""
        x = torch.linalg.solve_triangular(self.chol, symmetrize(blocks), upper=False)  # L^-1 H
        w = torch.linalg.solve_triangular(self.chol, x.transpose(-1, -2), upper=False)  # L^-1 H L^-T
        return 0.5 * (w + w.transpose(-1, -2))

    def gain(self, blocks: torch.Tensor) -> float:
        """logdet(A + H) - logdet(A) for the view's blocks H [N, P, P]."""
        return float(logdet_identity_plus(self.whiten(blocks)))

    def add(self, blocks: torch.Tensor) -> None:
        """A <- A + H, refactorised."""
        self.matrix = self.matrix + symmetrize(blocks)
        self._factorize()

    def logdet(self) -> float:
        return float(2.0 * torch.log(torch.diagonal(self.chol, dim1=-2, dim2=-1)).sum())


class BlockGainOracle:
    """The counted gain oracle the selectors call: `view_blocks(view_id)` supplies H_v (cached or recomputed)."""

    def __init__(self, information: BlockInformation, view_blocks: Callable[[int], torch.Tensor]):
        self.information = information
        self.view_blocks = view_blocks
        self.evaluated = 0

    def gain(self, view_id: int) -> float:
        self.evaluated += 1
        return self.information.gain(self.view_blocks(view_id))

    def commit(self, view_id: int) -> None:
        self.information.add(self.view_blocks(view_id))
