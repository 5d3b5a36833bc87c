"""How well an uncertainty map predicts the error: Spearman rank correlation and AUSE (numpy only).

AUSE (area under the sparsification error): sort the pixels by decreasing uncertainty, remove the first fraction f
for f = 0, 1/B, ..., (B - 1)/B, and take the RMSE (or MAE) of the absolute errors left; the oracle curve does the same
sorted by the error itself. AUSE is the trapezoid area between the two curves over f in [0, (B - 1)/B], in the error's
units (here colour values in [0, 1]); 0 means the uncertainty orders the pixels as the error does. The normalised
variants divide both curves by their common value at f = 0 (the RMSE / MAE of all pixels), so scaling every error by
a constant leaves them unchanged (FisherRF's ause.py normalises by the larger of the two curves' maxima, which is the
f = 0 value unless removing uncertain pixels raises the error).
"""
from __future__ import annotations

import numpy as np

from utils.errors import UserError

AUSE_VARIANTS = {  # name -> (curve statistic, normalised by the full-region error)
    "rmse": ("rmse", False), "mae": ("mae", False), "rmse_norm": ("rmse", True), "mae_norm": ("mae", True),
}


def parse_ause_variants(text: str) -> tuple[str, ...]:
    """Comma-separated AUSE variants -> a tuple; an empty or unknown one is a one-line UserError listing the valid."""
    variants = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [v for v in variants if v not in AUSE_VARIANTS]
    if bad or not variants:
        raise UserError(f"unknown AUSE variant {', '.join(bad) or repr(text)}; valid: {', '.join(AUSE_VARIANTS)}")
    return variants


def average_ranks(values: np.ndarray) -> np.ndarray:
    """Ranks 1..n of a 1-D array, ties getting the mean of the ranks they span. [n] -> [n] float64"""
    order = np.argsort(values, kind="stable")
    sorted_values = values[order]
    ranks = np.empty(len(values), dtype=np.float64)
    starts = np.flatnonzero(np.r_[True, sorted_values[1:] != sorted_values[:-1]])
    ends = np.r_[starts[1:], len(values)]
    for s, e in zip(starts, ends):
        ranks[order[s:e]] = 0.5 * (s + 1 + e)  # mean of ranks s+1 .. e
    return ranks


def spearman(x: np.ndarray, y: np.ndarray) -> float | None:
    """Spearman's rank correlation of two equally long arrays (Pearson on average ranks); None when either is
    constant (the correlation is undefined)."""
    x, y = np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
    assert x.shape == y.shape, f"spearman needs equal lengths, got {x.shape} and {y.shape}"
    rx, ry = average_ranks(x), average_ranks(y)
    rx, ry = rx - rx.mean(), ry - ry.mean()
    denom = np.sqrt((rx * rx).sum() * (ry * ry).sum())
    return float((rx * ry).sum() / denom) if denom > 0 else None


def sparsification_curve(order_key: np.ndarray, errors: np.ndarray, bins: int, statistic: str = "rmse") -> np.ndarray:
    """RMSE (or MAE, `statistic` "mae") of `errors` left after removing the fraction f = b / bins with the largest
    `order_key` (ties: the first in array order goes first), for b = 0 .. bins - 1. [bins]"""
    order = np.argsort(-order_key, kind="stable")
    values = errors[order] ** 2 if statistic == "rmse" else np.abs(errors[order])
    n = len(values)
    tail_sums = np.cumsum(values[::-1])[::-1]  # tail_sums[i] = sum of values[i:]
    curve = np.empty(bins)
    for b in range(bins):
        start = int(np.floor(b * n / bins))
        curve[b] = tail_sums[start] / (n - start)
    return np.sqrt(curve) if statistic == "rmse" else curve


def ause(uncertainty: np.ndarray, errors: np.ndarray, bins: int = 100, variant: str = "rmse") -> float | None:
    """Area between the uncertainty's and the oracle's sparsification curves (see the module docstring), for one of
    `AUSE_VARIANTS`; a normalised variant is None when every error is 0 (nothing to normalise by).

    Raises:
        UserError: an unknown variant (the message lists the valid ones).
    """
    if variant not in AUSE_VARIANTS:
        raise UserError(f"unknown AUSE variant {variant!r}; valid: {', '.join(AUSE_VARIANTS)}")
    statistic, normalised = AUSE_VARIANTS[variant]
    u, e = np.asarray(uncertainty, dtype=np.float64).ravel(), np.asarray(errors, dtype=np.float64).ravel()
    assert u.shape == e.shape and u.size > 0, f"ause needs equal non-empty lengths, got {u.shape} and {e.shape}"
    oracle = sparsification_curve(e, e, bins, statistic)
    gap = sparsification_curve(u, e, bins, statistic) - oracle
    if normalised:
        if oracle[0] == 0:
            return None
        gap = gap / oracle[0]  # oracle[0]: the error of all pixels, the same for both curves
    fractions = np.arange(bins) / bins
    return float(np.sum(0.5 * (gap[1:] + gap[:-1]) * np.diff(fractions)))
