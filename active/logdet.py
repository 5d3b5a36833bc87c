"""Block-diagonal D-optimal information: log-det gains of per-Gaussian Fisher blocks, in float64.

The running information of a stage is A = H_0 + sum_{v in S} H_v with the prior H_0 = (sum of the training views'
blocks) + ridge, all [N, P, P]. For a block-diagonal matrix the log-det is the sum of N small log-dets, so

    rho(S)     = logdet(A_S) - logdet(H_0)
    rho(v | S) = sum_i logdet(I + W_i),   W_i = L_i^-1 H_v,i L_i^-T,   L_i L_i^T = A_i (Cholesky),

the whitened form: L is cached and updated only when a view is committed.

A view enters as `ViewFactors`: only the Gaussians it sees (indices [n_v]; every other block of H_v is zero and
adds exactly 0), each block as a factor H_v,i = R_i R_i^T, R_i [P, r] (the Fisher oracle's r = 9 attributes:
R = J_proj^T G^1/2; dense [N, P, P] blocks are converted by `ViewFactors.from_blocks`, r = P), lower trapezoidal
(R -> R Q, Q orthogonal, leaves R R^T unchanged) and packed: 90 of 126 entries stored (`active.trapezoid`).
By Sylvester's identity logdet(I_P + W_i) = logdet(I_r + Y^T Y) with Y = L_i^-1 R_i, so one gain is a triangular
solve and an r x r Cholesky per visible block (`active.logdet_kernels`, numba; `factor_gain_terms_torch` is its
torch twin).

Numerics (real blocks are nearly singular: the normalised quaternion leaves an exact null direction, eigenvalue
ratios reach ~1e10, float32 accumulation leaves negative eigenvalues ~eps * |H|):
* blocks are cast to float64 and symmetrised, (B + B^T) / 2; the PSD part of H_v is taken once, when its factor is
  made (`from_blocks`: eigenvalues clamped at 0; the Fisher oracle clamps those of the 9 x 9 attribute Gram), so
  I + Y^T Y has eigenvalues >= 1 and its Cholesky cannot fail: no eigen-solve per gain. (The dense twin,
  `DenseBlockInformation`, clamps the eigenvalues of W instead; for PSD H_v both are the same number.)
* ridge: delta_i = delta_rel * max(diag(H_0,i)) + delta_abs (defaults: `arguments.FisherSettings`). The relative
  part makes every prior block positive definite whatever its units (an eigenvalue ratio of at most ~1/delta_rel);
  the absolute floor covers Gaussians no training view sees (all-zero prior blocks);
* each per-Gaussian term is clamped at 0 (exactly >= 0; roundoff may leave -1e-16), so a gain is finite, >= 0 and
  a continuous function of the blocks; a commit updates L <- L C with C C^T = I + Y Y^T for the blocks whose term
  is > 0, so rho(S) is the sum of the accepted gains and a commit cannot fail;
* non-finite blocks, or a prior that cannot be factorised, raise an error naming the Gaussian count and the
  ridge: a gain is never NaN.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Union

import torch

from active import trapezoid
from arguments import FisherSettings
from utils.errors import UserError

LOGDET_BACKENDS = ("auto", "compiled", "torch")


def symmetrize(blocks: torch.Tensor) -> torch.Tensor:
    """(B + B^T) / 2 in float64. [N, P, P] -> [N, P, P]"""
    b = blocks.double()
    return 0.5 * (b + b.transpose(-1, -2))


def check_finite(values: torch.Tensor, what: str, num_gaussians: int) -> None:
    """The one-line error for NaN or inf in a view's or the prior's Fisher information.

    A sum is NaN or inf when an element is, so one summation (a tenth of the cost of `isfinite` on the whole tensor)
    answers; only a non-finite sum, which an overflow of finite values can also give, is checked element by element.
    """
    if not bool(torch.isfinite(values.sum())) and not bool(torch.isfinite(values).all()):
        raise UserError(f"the {what} Fisher blocks of {num_gaussians} Gaussians contain NaN or inf "
                        "(the model diverged?); lower the learning rates or resume from an earlier checkpoint")


def finite_symmetric(blocks: torch.Tensor, what: str) -> torch.Tensor:
    """`symmetrize(blocks)`, refusing NaN or inf. [N, P, P] -> [N, P, P]"""
    check_finite(blocks, what, blocks.shape[0])
    return symmetrize(blocks)


def logdet_identity_plus(w: torch.Tensor) -> torch.Tensor:
    """Per-block logdet(I + max(W_i, 0)) = sum log1p(max(lambda, 0)) over the eigenvalues of each symmetric W_i.

    Args:
        w: symmetric float64 blocks. [N, P, P]
    Returns:
        per-block log-dets, each finite and >= 0. [N]
    """
    return torch.log1p(torch.linalg.eigvalsh(w).clamp_min(0.0)).sum(-1)


@dataclass(frozen=True)
class ViewFactors:
    """A view's Fisher information over the Gaussians it sees: H_v,i = R_b R_b^T for i = indices[b], 0 elsewhere, each
    R_b [P, r] lower trapezoidal and packed row by row (`active.trapezoid`: 90 of 126 entries for P = 14, r = 9).

    Finite by construction (`__post_init__` raises the one-line error otherwise). Storage may be float32; every
    use computes in float64.
    """

    indices: torch.Tensor  # [n] int64, the visible Gaussians, ascending
    packed: torch.Tensor  # [n, m] float32 or float64, m = trapezoid.packed_width(P, r)
    num_params: int  # P
    num_columns: int  # r
    num_gaussians: int  # N

    def __post_init__(self) -> None:
        m = trapezoid.packed_width(self.num_params, self.num_columns)
        assert self.indices.dim() == 1 and tuple(self.packed.shape) == (self.indices.shape[0], m), \
            f"ViewFactors needs indices [n] and packed factors [n, {m}], got {tuple(self.indices.shape)}, " \
            f"{tuple(self.packed.shape)}"
        check_finite(self.packed, "view", self.num_gaussians)

    @classmethod
    def from_factors(cls, indices: torch.Tensor, factors: torch.Tensor, num_gaussians: int) -> "ViewFactors":
        """Any factors R [n, P, r] of the visible blocks (made lower trapezoidal by LQ, then packed; dtype kept)."""
        check_finite(factors, "view", num_gaussians)
        packed = trapezoid.pack(trapezoid.lower_trapezoid(factors)).to(factors.dtype)
        return cls(indices, packed, factors.shape[1], factors.shape[2], num_gaussians)

    @property
    def nbytes(self) -> int:
        """Bytes held (indices and packed factors)."""
        return self.indices.numel() * self.indices.element_size() + self.packed.numel() * self.packed.element_size()

    def stored_as(self, dtype: torch.dtype) -> "ViewFactors":
        """The same view with its factors stored in `dtype` (float32 halves the cache; arithmetic stays float64)."""
        return ViewFactors(self.indices, self.packed.to(dtype), self.num_params, self.num_columns, self.num_gaussians)

    def factors(self) -> torch.Tensor:
        """The lower-trapezoidal factors R, float64. [n, P, r]"""
        return trapezoid.unpack(self.packed.double(), self.num_params, self.num_columns)

    def dense(self) -> torch.Tensor:
        """The blocks R R^T scattered into [N, P, P] float64 (zero for the Gaussians the view does not see)."""
        r = self.factors()
        out = r.new_zeros(self.num_gaussians, self.num_params, self.num_params)
        out[self.indices] = r @ r.transpose(-1, -2)
        return out

    @classmethod
    def from_blocks(cls, blocks: torch.Tensor) -> "ViewFactors":
        """The non-zero blocks of [N, P, P] (finite, symmetrised float64) with their PSD parts as factors
        R = V diag(max(lambda, 0))^1/2 from a symmetric eigen-solve, r = P."""
        h = finite_symmetric(blocks, "view")  # [N, P, P]
        indices = torch.nonzero(h.flatten(1).abs().amax(dim=1) > 0).flatten() if h.shape[0] else \
            torch.zeros(0, dtype=torch.long, device=h.device)  # [n]
        evals, evecs = torch.linalg.eigh(h[indices])  # [n, P], [n, P, P]
        return cls.from_factors(indices, evecs * evals.clamp_min(0.0).sqrt()[:, None, :], h.shape[0])


ViewInput = Union[torch.Tensor, ViewFactors]  # dense blocks [N, P, P] or a view's factors


def factor_gain_terms_torch(chol: torch.Tensor, view: ViewFactors) -> torch.Tensor:
    """Torch twin of `logdet_kernels.gain_terms`: max(logdet(I_r + Y^T Y), 0) with Y = L_i^-1 R per visible block.
    chol [N, P, P] float64 -> terms [n] float64"""
    r = view.factors()  # [n, P, r]
    y = torch.linalg.solve_triangular(chol[view.indices], r, upper=False)  # [n, P, r]
    g = torch.eye(r.shape[-1], dtype=r.dtype, device=r.device) + y.transpose(-1, -2) @ y  # [n, r, r]
    c = torch.linalg.cholesky(g)
    return (2.0 * torch.log(torch.diagonal(c, dim1=-2, dim2=-1)).sum(-1)).clamp_min(0.0)


def factor_commit_torch(chol: torch.Tensor, view: ViewFactors) -> torch.Tensor:
    """Torch twin of `logdet_kernels.commit`: L_i <- L_i C, C C^T = I_P + Y Y^T, for the visible blocks whose term is
    > 0, in place on chol [N, P, P]; returns the terms [n] (0 where skipped)."""
    r = view.factors()  # [n, P, r]
    l = chol[view.indices]  # [n, P, P]
    y = torch.linalg.solve_triangular(l, r, upper=False)  # [n, P, r]
    c = torch.linalg.cholesky(torch.eye(r.shape[1], dtype=r.dtype, device=r.device) + y @ y.transpose(-1, -2))
    terms = 2.0 * torch.log(torch.diagonal(c, dim1=-2, dim2=-1)).sum(-1)  # [n]
    keep = terms > 0
    chol[view.indices[keep]] = l[keep] @ c[keep]
    return torch.where(keep, terms, torch.zeros_like(terms))


def gram_root_factors_torch(gram: torch.Tensor, jac: torch.Tensor, sigma: float) -> torch.Tensor:
    """Torch twin of `logdet_kernels.gram_root_factors`: R = sigma^-1 J^T D^1/2 V diag(max(lambda, 0))^1/2 from the
    eigen-decomposition S = V diag(lambda) V^T of the equilibrated Gram S = D^-1/2 G D^-1/2, D = diag(G) (attributes
    with a zero diagonal drop out): the PSD part of G, computed where roundoff is relative to each attribute's scale.
    gram [n, A, A], jac [n, A, P] float64 -> R [n, P, A] float64"""
    root_diag = torch.diagonal(gram, dim1=-2, dim2=-1).clamp_min(0.0).sqrt()  # D^1/2 [n, A]
    inv = torch.where(root_diag > 0, 1.0 / root_diag.clamp_min(1e-300), torch.zeros_like(root_diag))
    evals, evecs = torch.linalg.eigh(gram * inv[:, :, None] * inv[:, None, :])  # [n, A], [n, A, A]
    root = root_diag[:, :, None] * evecs * (evals.clamp_min(0.0).sqrt() / sigma)[:, None, :]  # [n, A, A]
    return jac.transpose(1, 2) @ root


def gram_root_factors(gram: torch.Tensor, jac: torch.Tensor, sigma: float, backend: str = "auto",
                      dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The factors R_b [P, A] with R_b R_b^T = sigma^-2 J_b^T G_b+ J_b (G_b+: the PSD part of the attribute Gram), lower
    trapezoidal and packed (`active.trapezoid`): the numba pivoted-Cholesky + Householder-LQ kernel on the CPU, else
    (or with backend="torch") the eigen-decomposition twin made trapezoidal by QR. Computed in float64 and returned in
    `dtype` (float32: what a cache stores, written directly, no float64 copy).
    gram [n, A, A], jac [n, A, P] float64 -> packed R [n, trapezoid.packed_width(P, A)]"""
    n, a, p = jac.shape
    if not _compiled(backend, gram) or n == 0:
        return trapezoid.pack(trapezoid.lower_trapezoid(gram_root_factors_torch(gram, jac, sigma))).to(dtype)
    from active import logdet_kernels
    out = torch.empty(n, trapezoid.packed_width(p, a), dtype=dtype)
    logdet_kernels.gram_root_factors(gram.double().contiguous().numpy(), jac.double().contiguous().numpy(),
                                     1.0 / sigma, _kernel_threads(n), out.numpy())
    return out


def _compiled(backend: str, tensor: torch.Tensor) -> bool:
    """Whether the numba kernels run: CPU tensors and numba importable ("compiled" without numba is an error, "auto"
    then takes the torch twin)."""
    if backend not in LOGDET_BACKENDS:
        raise ValueError(f"unknown log-det backend {backend!r}, expected one of {LOGDET_BACKENDS}")
    if backend == "torch" or tensor.device.type != "cpu":
        return False
    from gaussian_renderer.compiled import numba_import_error
    error = numba_import_error()
    if error is not None and backend == "compiled":
        raise UserError(f"the compiled log-det kernels need numba ({error}); pip install numba (requirements.txt)")
    return error is None


def _kernel_threads(num_blocks: int) -> int:
    """Sets numba's thread count for a `logdet_kernels` call over `num_blocks` blocks (torch's count, at most one per
    block) and returns it as the kernel's slice count."""
    import numba
    threads = max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS, num_blocks))
    numba.set_num_threads(threads)
    return threads


def _kernel_args(chol: torch.Tensor, view: ViewFactors) -> tuple:
    """numpy views of (L, indices, packed factors), their column count r and the thread slice count for
    `logdet_kernels`."""
    threads = _kernel_threads(view.indices.shape[0])
    return chol.numpy(), view.indices.contiguous().numpy(), view.packed.contiguous().numpy(), view.num_columns, threads


def ridged_prior(prior_blocks: torch.Tensor, delta_rel: float, delta_abs: float) -> tuple[torch.Tensor, torch.Tensor]:
    """A = H_0 + delta_i I (delta_i = delta_rel max diag(H_0,i) + delta_abs) and its Cholesky factor, float64,
    with the one-line errors for a bad ridge, non-finite blocks or a prior that cannot be factorised.
    prior_blocks [N, P, P] -> (A [N, P, P], L [N, P, P])"""
    assert prior_blocks.dim() == 3 and prior_blocks.shape[1] == prior_blocks.shape[2], \
        f"prior_blocks must be [N, P, P], got {tuple(prior_blocks.shape)}"
    if delta_rel < 0 or delta_abs < 0 or delta_rel + delta_abs <= 0:
        raise UserError(f"the Fisher ridge needs delta_rel >= 0, delta_abs >= 0 and one of them > 0, got "
                        f"delta_rel={delta_rel:g}, delta_abs={delta_abs:g}; set --delta_rel / --delta_abs")
    h0 = finite_symmetric(prior_blocks, "prior")  # [N, P, P]
    p = h0.shape[-1]
    diag_max = torch.diagonal(h0, dim1=-2, dim2=-1).amax(dim=-1) if h0.shape[0] else h0.new_zeros(0)  # [N]
    ridge = delta_rel * diag_max.clamp_min(0.0) + delta_abs  # [N]
    matrix = h0 + ridge[:, None, None] * torch.eye(p, dtype=h0.dtype, device=h0.device)  # A [N, P, P]
    chol, info = torch.linalg.cholesky_ex(matrix)
    bad = info != 0
    if bool(bad.any()):
        raise UserError(f"the Fisher prior is not positive definite for {int(bad.sum())} of "
                        f"{matrix.shape[0]} Gaussians with ridge delta_rel={delta_rel:g}, "
                        f"delta_abs={delta_abs:g}; raise --delta_rel or --delta_abs")
    return matrix, chol.contiguous()


class BlockInformation:
    """The running information A = H_0 + ridge + sum_S H_v of a stage, with its Cholesky factor cached; gains and
    commits touch only the Gaussians a view sees (`ViewFactors`)."""

    def __init__(self, prior_blocks: torch.Tensor, delta_rel: float = FisherSettings.delta_rel,
                 delta_abs: float = FisherSettings.delta_abs, backend: str = "auto"):
        """Args:
            prior_blocks: sum of the training views' Fisher blocks (any float dtype, device kept). [N, P, P]
            delta_rel: relative ridge, times the largest diagonal entry of each prior block.
            delta_abs: absolute ridge added to every block (the floor for all-zero prior blocks).
            backend: "auto" (numba kernels on CPU when numba imports, else torch), "compiled" or "torch".
        """
        self.delta_rel, self.delta_abs = float(delta_rel), float(delta_abs)
        self.prior_matrix, self.chol = ridged_prior(prior_blocks, self.delta_rel, self.delta_abs)  # A_0, L [N, P, P]
        self.compiled = _compiled(backend, self.chol)
        self.committed = False
        self.prior_logdet = self.logdet()

    @property
    def num_gaussians(self) -> int:
        return self.chol.shape[0]

    @property
    def matrix(self) -> torch.Tensor:
        """A [N, P, P]: the ridged prior until a view is committed, then L L^T (formed on request only)."""
        return self.chol @ self.chol.transpose(-1, -2) if self.committed else self.prior_matrix

    def view(self, blocks: ViewInput) -> ViewFactors:
        """A view as factors over the Gaussians it sees (dense blocks converted), shape-checked."""
        if not isinstance(blocks, ViewFactors):
            assert blocks.shape == self.chol.shape, \
                f"view blocks must be {tuple(self.chol.shape)}, got {tuple(blocks.shape)}"
            return ViewFactors.from_blocks(blocks)
        assert blocks.num_gaussians == self.num_gaussians and blocks.num_params == self.chol.shape[-1], \
            f"view factors must cover {self.num_gaussians} Gaussians x {self.chol.shape[-1]} parameters, got " \
            f"{blocks.num_gaussians} x {blocks.num_params}"
        return blocks

    def gain_terms(self, view: ViewFactors) -> torch.Tensor:
        """Per visible Gaussian logdet(A_i + H_v,i) - logdet(A_i), each >= 0. [n] float64"""
        if view.indices.shape[0] == 0:
            return torch.zeros(0, dtype=torch.float64, device=self.chol.device)
        if self.compiled:
            from active import logdet_kernels
            return torch.from_numpy(logdet_kernels.gain_terms(*_kernel_args(self.chol, view)))
        return factor_gain_terms_torch(self.chol, view)

    def gain(self, blocks: ViewInput) -> float:
        """rho(v | S) = logdet(A + H_v) - logdet(A) for the view's blocks [N, P, P] or factors (not counted)."""
        return float(self.gain_terms(self.view(blocks)).sum())

    def add(self, blocks: ViewInput) -> float:
        """Commit a view: A <- A + H_v+ on the Gaussians it sees, with H_v+ the PSD part of H_v its factor holds, so
        logdet(A) grows by `gain(blocks)`. Returns that growth (the sum of the committed per-block terms)."""
        view = self.view(blocks)
        if view.indices.shape[0] == 0:
            return 0.0
        if self.compiled:
            from active import logdet_kernels
            terms = torch.from_numpy(logdet_kernels.commit(*_kernel_args(self.chol, view)))
        else:
            terms = factor_commit_torch(self.chol, view)
        self.committed = True
        return float(terms.sum())

    def logdet(self) -> float:
        """logdet(A) = sum of the per-Gaussian log-dets."""
        return float(2.0 * torch.log(torch.diagonal(self.chol, dim1=-2, dim2=-1)).sum())

    def rho(self) -> float:
        """rho(S) = logdet(A_S) - logdet(H_0): the information gained by the committed views."""
        return self.logdet() - self.prior_logdet


class DenseBlockInformation:
    """The dense twin of `BlockInformation` (the implementation before the sparse factor form): every gain whitens
    all N blocks, W = L^-1 H_v L^-T, and sums log1p(max(eig(W), 0)) from a batched symmetric eigen-solve; a commit
    updates L <- L C with C C^T = I + max(W, 0) from a QR. Tests compare the two; the benchmark times both."""

    def __init__(self, prior_blocks: torch.Tensor, delta_rel: float = FisherSettings.delta_rel,
                 delta_abs: float = FisherSettings.delta_abs):
        self.delta_rel, self.delta_abs = float(delta_rel), float(delta_abs)
        self.matrix, self.chol = ridged_prior(prior_blocks, self.delta_rel, self.delta_abs)  # A, L [N, P, P]
        self.prior_logdet = self.logdet()

    def whiten(self, blocks: torch.Tensor) -> torch.Tensor:
        """W = L^-1 H L^-T, symmetrised. [N, P, P] -> [N, P, P] (float64)"""
        assert blocks.shape == self.matrix.shape, \
            f"view blocks must be {tuple(self.matrix.shape)}, got {tuple(blocks.shape)}"
        x = torch.linalg.solve_triangular(self.chol, finite_symmetric(blocks, "view"), upper=False)  # L^-1 H
        w = torch.linalg.solve_triangular(self.chol, x.transpose(-1, -2), upper=False)  # L^-1 (L^-1 H)^T
        return 0.5 * (w + w.transpose(-1, -2))

    def gain(self, blocks: torch.Tensor) -> float:
        """rho(v | S) for the view's dense blocks [N, P, P]."""
        return self.gain_and_whitened(blocks)[0]

    def gain_and_whitened(self, blocks: torch.Tensor) -> tuple[float, torch.Tensor]:
        """`gain` and the whitened blocks W [N, P, P] it came from (what `add_whitened` takes)."""
        w = self.whiten(blocks)
        return float(logdet_identity_plus(w).sum()), w

    def add(self, blocks: torch.Tensor) -> None:
        """Commit a view's dense blocks [N, P, P]."""
        self.add_whitened(self.whiten(blocks))

    def add_whitened(self, w: torch.Tensor) -> None:
        """Commit W = L^-1 H_v L^-T [N, P, P]: L <- L C with C C^T = I + max(W, 0), C = R^T from a QR of
        (V diag(1 + max(lambda, 0))^1/2)^T (backward stable at any condition number)."""
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
        """rho(S) = logdet(A_S) - logdet(H_0)."""
        return self.logdet() - self.prior_logdet


class BlockGainOracle:
    """The counted `GainOracle` the selectors call; `view_blocks(view_id)` supplies H_v as `ViewFactors` or dense
    [N, P, P] blocks (it may cache them or recompute them on every call: the cached and streaming modes of
    `active.fisher`).

    It remembers the factors of the best view evaluated since the last commit: every selector commits the best gain
    of its pick, so a commit costs no second `view_blocks` call (in streaming mode, no Fisher recompute).
    Memory: one view's factors.

    With `weights` w [N] (>= 0) a gain is the weighted sum sum_i w_i (logdet(A_i + H_v,i) - logdet(A_i)): a
    non-negative combination of submodular terms, so still monotone submodular (lazy greedy stays exact); commits
    are unchanged (A grows by H_v whatever the weights).
    """

    def __init__(self, information: BlockInformation, view_blocks: Callable[[int], ViewInput],
                 weights: torch.Tensor | None = None):
        self.information = information
        self.view_blocks = view_blocks
        self.weights = None if weights is None else weights.detach().double().to(information.chol.device)  # [N]
        self.evaluated = 0  # oracle evaluations since construction or `reset_counts`
        self._best: tuple[int, float, Any] | None = None  # (view, gain, what `_score` returned) since the last commit

    def gain(self, view_id: int) -> float:
        """rho(v | S): one oracle evaluation."""
        self.evaluated += 1
        gain, reusable = self._score(view_id)
        if self._best is None or gain > self._best[1]:
            self._best = (view_id, gain, reusable)
        return gain

    def commit(self, view_id: int) -> None:
        """S <- S + {v}: adds H_v to the information (not an oracle evaluation), reusing the best gain's work since
        the last commit when v is that view."""
        if self._best is not None and self._best[0] == view_id:
            self._add_scored(self._best[2])
        else:
            self.information.add(self.view_blocks(view_id))
        self._best = None

    def _score(self, view_id: int) -> tuple[float, ViewFactors]:
        """The gain of `view_id` and what a commit of it can reuse (its factors in the information's form)."""
        view = self.information.view(self.view_blocks(view_id))
        terms = self.information.gain_terms(view)  # [n] over the Gaussians the view sees
        return float((terms if self.weights is None else terms * self.weights[view.indices]).sum()), view

    def _add_scored(self, reusable: ViewFactors) -> None:
        """Commit what `_score` returned."""
        self.information.add(reusable)

    def reset_counts(self) -> None:
        self.evaluated = 0
