"""The predicted rendering variance over the candidate poses: an I-optimal (V-optimal) criterion on the same
per-Gaussian Fisher blocks as the log-det.

Under the Laplace approximation the parameters of Gaussian i have covariance A_i^-1, A_i = H_0,i + ridge + sum_S H_v,i,
and the variance of the pixels a pose u renders is sum_i tr(J_u,i A_i^-1 J_u,i^T) = sigma^2 sum_i tr(A_i^-1 H_u,i).
Summed over the candidate poses u (never the test poses), the criterion is

    V(S) = sum_i tr(A_i^-1 T_i),   T_i = sum_u H_u,i   (the target: the pool's summed blocks)

and a view's gain is how much it lowers V: with H_v,i = R R^T (the view's factors, `ViewFactors`),

    V_i(S) - V_i(S + v) = tr(T_i Q Q^T),   Q = A_i^-1 R (I_r + R^T A_i^-1 R)^-1/2      (Woodbury)

Unlike the log-det, which counts every parameter's information the same whatever it does to an image, each Gaussian's
term is weighted by how much its parameters change the pixels of the poses the user may look from: a near-transparent
Gaussian moves few pixels (small T_i) and counts little. The gain is monotone (variance only falls) but not
submodular in general, so the selector using it is plain greedy (every candidate at every pick).
"""
from __future__ import annotations

import torch

from active.logdet import BlockInformation, ViewFactors, ViewInput, finite_symmetric
from arguments import FisherSettings


def variance_terms_torch(chol: torch.Tensor, target: torch.Tensor, view: ViewFactors) -> torch.Tensor:
    """Per visible Gaussian tr(T_i (A_i^-1 - (A_i + R R^T)^-1)) >= 0, A_i = L_i L_i^T.
    chol [N, P, P], target [N, P, P] float64 -> terms [n] float64"""
    r = view.factors()  # [n, P, r]
    l = chol[view.indices]  # [n, P, P]
    x = torch.linalg.solve_triangular(l, r, upper=False)  # L^-1 R  [n, P, r]
    z = torch.linalg.solve_triangular(l.transpose(-1, -2), x, upper=True)  # A^-1 R  [n, P, r]
    c = torch.linalg.cholesky(torch.eye(r.shape[-1], dtype=r.dtype, device=r.device) + x.transpose(-1, -2) @ x)
    q = torch.linalg.solve_triangular(c, z.transpose(-1, -2), upper=False).transpose(-1, -2)  # Z C^-T  [n, P, r]
    return (q * (target[view.indices] @ q)).sum(dim=(-2, -1)).clamp_min(0.0)


def variance_terms_dense(information: torch.Tensor, target: torch.Tensor, blocks: torch.Tensor) -> torch.Tensor:
    """The written-out twin: tr(T_i (inv(A_i) - inv(A_i + H_v,i))) with explicit inverses, every Gaussian.
    information A, target T, blocks H_v: [N, P, P] float64 -> [N]"""
    drop = torch.linalg.inv(information) - torch.linalg.inv(information + blocks)  # [N, P, P]
    return torch.diagonal(target @ drop, dim1=-2, dim2=-1).sum(-1)


class RenderVarianceInformation(BlockInformation):
    """`BlockInformation` (the same ridged prior and commits) whose gains are reductions of the predicted rendering
    variance over the target poses, sum_i tr(A_i^-1 T_i), instead of log-det growth."""

    def __init__(self, prior_blocks: torch.Tensor, target_blocks: torch.Tensor,
                 delta_rel: float = FisherSettings.delta_rel, delta_abs: float = FisherSettings.delta_abs):
        """Args:
            prior_blocks: sum of the training views' Fisher blocks. [N, P, P]
            target_blocks: sum of the target poses' Fisher blocks (the candidate pool), T. [N, P, P]
        """
        super().__init__(prior_blocks, delta_rel=delta_rel, delta_abs=delta_abs)  # commits: compiled on CPU
        self.target = finite_symmetric(target_blocks, "target").to(self.chol.device)  # T [N, P, P] float64
        self.prior_variance = self.variance()

    def gain_terms(self, view: ViewFactors) -> torch.Tensor:
        """Per visible Gaussian the variance the view removes, tr(T_i (A_i^-1 - (A_i + H_v,i)^-1)) >= 0. [n]"""
        if view.indices.shape[0] == 0:
            return torch.zeros(0, dtype=torch.float64, device=self.chol.device)
        return variance_terms_torch(self.chol, self.target, view)

    def add(self, blocks: ViewInput) -> float:
        """Commit a view (A <- A + H_v on the Gaussians it sees); returns the variance it removed."""
        view = self.view(blocks)
        removed = float(self.gain_terms(view).sum())
        super().add(view)
        return removed

    def variance(self) -> float:
        """V = sum_i tr(A_i^-1 T_i), the predicted rendering variance over the target poses (in units of sigma^2)."""
        eye = torch.eye(self.chol.shape[-1], dtype=self.chol.dtype, device=self.chol.device).expand_as(self.chol)
        inv_l = torch.linalg.solve_triangular(self.chol, eye, upper=False)  # L^-1  [N, P, P]
        return float((inv_l @ self.target * inv_l).sum())  # tr(L^-T L^-1 T) = sum((L^-1 T) * L^-1)

    def rho(self) -> float:
        """The variance the committed views removed: V(prior) - V(S) >= 0."""
        return self.prior_variance - self.variance()
