"""Block-diagonal D-optimal information: log-det gains of per-Gaussian Fisher blocks, in float64.

The running information of a stage is A = H_0 + sum_{v in S} H_v with the prior H_0 = (sum of the training views'
blocks) + ridge, all [N, P, P]. For a block-diagonal matrix the log-det is the sum of N small log-dets, so

    rho(S)     = logdet(A_S) - logdet(H_0)
    rho(v | S) = sum_i logdet(I + W_i),   W_i = L_i^-1 H_v,i L_i^-T,   L_i L_i^T = A_i (Cholesky),

the whitened form: L is cached and updated only when a view is committed, so one gain costs two batched
triangular solves and one batched P x P symmetric eigen-solve, with no factorisation of A + H_v.

Numerics (real blocks are nearly singular: the normalised quaternion leaves an exact null direction, eigenvalue
ratios reach ~1e10, float32 accumulation leaves negative eigenvalues ~eps * |H|):
* every block is cast to float64 and symmetrised, (B + B^T) / 2;
* ridge: delta_i = delta_rel * max(diag(H_0,i)) + delta_abs (defaults 1e-6 and 1e-8). The relative part makes
  every prior block positive definite whatever its units (an eigenvalue ratio of at most ~1/delta_rel);
  the absolute floor covers Gaussians no training view sees (all-zero prior blocks);
* logdet(I + W_i) = sum log1p(max(lambda, 0)) over the eigenvalues of W_i (batched symmetric eigen-solver):
  H_v's spurious negative eigenvalues are clamped to 0, so each per-Gaussian term, hence each gain, is finite and
  >= 0 and a gain is a continuous function of the blocks. (A Cholesky of I + W would cost about half as much but
  keeps log(1 + lambda) < 0 for -1 < lambda < 0 and fails below -1; after whitening by a small ridge such
  negative lambda are not tiny, e.g. float32 noise of a view block over an all-zero prior block.)
* a commit adds the same clamped (PSD) part of H_v that the gain measured and updates L without refactorising
  (see `add`), so rho(S) is exactly the sum of the accepted gains and a commit cannot fail;
* non-finite blocks, or a prior that cannot be factorised, raise an error naming the Gaussian count and the
  ridge: a gain is never NaN.
"""
from __future__ import annotations

from typing import Callable

import torch

from utils.errors import UserError


def symmetrize(blocks: torch.Tensor) -> torch.Tensor:
    """(B + B^T) / 2 in float64. [N, P, P] -> [N, P, P]"""
    b = blocks.double()
    return 0.5 * (b + b.transpose(-1, -2))


def finite_symmetric(blocks: torch.Tensor, what: str) -> torch.Tensor:
    """`symmetrize(blocks)`, refusing NaN or inf. [N, P, P] -> [N, P, P]"""
    if not bool(torch.isfinite(blocks).all()):
        raise UserError(f"the {what} Fisher blocks of {blocks.shape[0]} Gaussians contain NaN or inf "
                        "(the model diverged?); lower the learning rates or resume from an earlier checkpoint")
    return symmetrize(blocks)


def logdet_identity_plus(w: torch.Tensor) -> torch.Tensor:
    """Per-block logdet(I + max(W_i, 0)) = sum log1p(max(lambda, 0)) over the eigenvalues of each symmetric W_i.

    Args:
        w: symmetric float64 blocks. [N, P, P]
    Returns:
        per-block log-dets, each finite and >= 0. [N]
    """
    return torch.log1p(torch.linalg.eigvalsh(w).clamp_min(0.0)).sum(-1)


class BlockInformation:
    """The running information A = H_0 + ridge + sum_S H_v of a stage, with its Cholesky factor cached."""

    def __init__(self, prior_blocks: torch.Tensor, delta_rel: float = 1e-6, delta_abs: float = 1e-8):
        """Args:
            prior_blocks: sum of the training views' Fisher blocks (any float dtype, device kept). [N, P, P]
            delta_rel: relative ridge, times the largest diagonal entry of each prior block.
            delta_abs: absolute ridge added to every block (the floor for all-zero prior blocks).
        """
        assert prior_blocks.dim() == 3 and prior_blocks.shape[1] == prior_blocks.shape[2], \
            f"prior_blocks must be [N, P, P], got {tuple(prior_blocks.shape)}"
        if delta_rel < 0 or delta_abs < 0 or delta_rel + delta_abs <= 0:
            raise UserError(f"the Fisher ridge needs delta_rel >= 0, delta_abs >= 0 and one of them > 0, got "
                            f"delta_rel={delta_rel:g}, delta_abs={delta_abs:g}; set --delta_rel / --delta_abs")
        self.delta_rel, self.delta_abs = float(delta_rel), float(delta_abs)
        h0 = finite_symmetric(prior_blocks, "prior")  # [N, P, P]
        p = h0.shape[-1]
        diag_max = torch.diagonal(h0, dim1=-2, dim2=-1).amax(dim=-1) if h0.shape[0] else h0.new_zeros(0)  # [N]
        ridge = self.delta_rel * diag_max.clamp_min(0.0) + self.delta_abs  # [N]
        self.matrix = h0 + ridge[:, None, None] * torch.eye(p, dtype=h0.dtype, device=h0.device)  # A [N, P, P]
        self._factorize()
        self.prior_logdet = self.logdet()

    @property
    def num_gaussians(self) -> int:
        return self.matrix.shape[0]

    def _view(self, blocks: torch.Tensor) -> torch.Tensor:
        """A view's blocks, shape-checked, finite, symmetrised float64. [N, P, P]"""
        assert blocks.shape == self.matrix.shape, \
            f"view blocks must be {tuple(self.matrix.shape)}, got {tuple(blocks.shape)}"
        return finite_symmetric(blocks, "view")

    def _factorize(self) -> None:
        chol, info = torch.linalg.cholesky_ex(self.matrix)
        bad = info != 0
        if bool(bad.any()):
            raise UserError(f"the Fisher prior is not positive definite for {int(bad.sum())} of "
                            f"{self.num_gaussians} Gaussians with ridge delta_rel={self.delta_rel:g}, "
                            f"delta_abs={self.delta_abs:g}; raise --delta_rel or --delta_abs")
        self.chol = chol  # L [N, P, P], lower triangular

    def whiten(self, blocks: torch.Tensor) -> torch.Tensor:
        """W = L^-1 H L^-T, symmetrised. [N, P, P] -> [N, P, P] (float64)"""
        x = torch.linalg.solve_triangular(self.chol, self._view(blocks), upper=False)  # L^-1 H
        w = torch.linalg.solve_triangular(self.chol, x.transpose(-1, -2), upper=False)  # L^-1 (L^-1 H)^T
        return 0.5 * (w + w.transpose(-1, -2))

    def gain(self, blocks: torch.Tensor) -> float:
        """rho(v | S) = logdet(A + H_v) - logdet(A) for the view's blocks H_v [N, P, P] (not counted)."""
        return self.gain_and_whitened(blocks)[0]

    def gain_and_whitened(self, blocks: torch.Tensor) -> tuple[float, torch.Tensor]:
        """`gain` and the whitened blocks W it came from (what `add_whitened` takes). W: [N, P, P]"""
        w = self.whiten(blocks)
        return float(logdet_identity_plus(w).sum()), w

    def add(self, blocks: torch.Tensor) -> None:
        """Commit a view: A <- A + H_v+, with H_v+ = L max(W, 0) L^T the PSD part of H_v in the metric of A
        (= H_v when H_v is PSD), so logdet(A) grows by exactly `gain(blocks)`."""
        self.add_whitened(self.whiten(blocks))

    def add_whitened(self, w: torch.Tensor) -> None:
        """`add` for a view already whitened by the current factor, W = L^-1 H_v L^-T [N, P, P].

        The factor updates as L <- L C with C C^T = I + max(W, 0): C = R^T from a QR of
        (V diag(1 + max(lambda, 0))^1/2)^T (backward stable at any condition number), so a commit never fails.
        """
        evals, evecs = torch.linalg.eigh(w)  # [N, P], [N, P, P]
        root = evecs * torch.sqrt(1.0 + evals.clamp_min(0.0))[:, None, :]  # M, M M^T = I + W+  [N, P, P]
        r = torch.linalg.qr(root.transpose(-1, -2), mode="r").R  # M^T = Q R  ->  M M^T = R^T R  [N, P, P]
        r = r * torch.sign(torch.diagonal(r, dim1=-2, dim2=-1))[..., None]  # positive diagonal (rows scaled +-1)
        self.chol = self.chol @ r.transpose(-1, -2)  # lower x lower
        self.matrix = self.chol @ self.chol.transpose(-1, -2)

    def logdet(self) -> float:
        """logdet(A) = sum of the per-Gaussian log-dets."""
        return float(2.0 * torch.log(torch.diagonal(self.chol, dim1=-2, dim2=-1)).sum())

    def rho(self) -> float:
        """rho(S) = logdet(A_S) - logdet(H_0): the information gained by the committed views."""
        return self.logdet() - self.prior_logdet


class BlockGainOracle:
    """The counted `GainOracle` the selectors call; `view_blocks(view_id)` supplies H_v [N, P, P] (it may cache
    the blocks or recompute them on every call: the cached and streaming modes of `active.fisher`).

    It remembers the whitened blocks of the best view evaluated since the last commit: every selector commits the
    best gain of its pick, so a commit costs no second `view_blocks` call (in streaming mode, no Fisher recompute)
    and no second whitening. Memory: one view's blocks.
    """

    def __init__(self, information: BlockInformation, view_blocks: Callable[[int], torch.Tensor]):
        self.information = information
        self.view_blocks = view_blocks
        self.evaluated = 0  # oracle evaluations since construction or `reset_counts`
        self._best: tuple[int, float, torch.Tensor] | None = None  # (view, gain, W) since the last commit

    def gain(self, view_id: int) -> float:
        """rho(v | S): one oracle evaluation."""
        self.evaluated += 1
        gain, w = self.information.gain_and_whitened(self.view_blocks(view_id))
        if self._best is None or gain > self._best[1]:
            self._best = (view_id, gain, w)
        return gain

    def commit(self, view_id: int) -> None:
        """S <- S + {v}: adds H_v to the information (not an oracle evaluation)."""
        if self._best is not None and self._best[0] == view_id:
            self.information.add_whitened(self._best[2])
        else:
            self.information.add(self.view_blocks(view_id))
        self._best = None

    def reset_counts(self) -> None:
        self.evaluated = 0
