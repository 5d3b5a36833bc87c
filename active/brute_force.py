"""Brute force over K-subsets of candidate views: the exact optimum rho(OPT) that greedy selectors approximate
(benchmarks/bench_approximation.py), and the input checks that keep it tractable."""
from __future__ import annotations

import itertools
import math

import torch

from active.logdet import BlockInformation
from utils.errors import UserError


def check_inputs(m: int, ks: list[int], deltas: list[float], max_subsets: int) -> None:
    """One-line UserErrors: delta_rel <= 0, K outside 1..M, or C(M, K) over the cap (the count and the cap named)."""
    bad = [d for d in deltas if not d > 0]
    if bad:
        raise UserError(f"--delta_rel must be positive, got {', '.join(f'{d:g}' for d in bad)}")
    for k in ks:
        if not 1 <= k <= m:
            raise UserError(f"--ks: K = {k} must lie in 1..M = {m}")
        if math.comb(m, k) > max_subsets:
            raise UserError(f"brute force over C({m}, {k}) = {math.comb(m, k)} subsets exceeds the cap of "
                            f"{max_subsets} (--max_subsets); lower --candidates or K")


def subset_rhos(information: BlockInformation, blocks: dict[int, torch.Tensor], candidates: list[int],
                k: int) -> dict[tuple[int, ...], float]:
    """rho(S) = logdet(A_0 + sum_S H_v) - logdet(A_0) for every K-subset S of `candidates`, by one Cholesky each."""
    out = {}
    for subset in itertools.combinations(candidates, k):
        total = information.matrix + sum(blocks[v] for v in subset)  # [N, P, P]
        chol = torch.linalg.cholesky(0.5 * (total + total.transpose(-1, -2)))
        out[subset] = float(2.0 * torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum()) - information.prior_logdet
    return out
