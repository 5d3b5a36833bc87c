"""Lower-trapezoidal view factors packed row by row: the compact layout of a view's cached Fisher information.

A block H = R R^T (R [P, r]) is unchanged by R -> R Q for any orthogonal Q [r, r]. The LQ factorisation R = T Q gives
T lower trapezoidal (T[k, c] = 0 for c > k), so of its P r entries only sum_k min(k + 1, r) need storing: 90 of 126
for the Fisher oracle's P = 14, r = 9 (a 29 % smaller cache), and the whitened L^-1 T of a gain is lower trapezoidal
too (fewer flops). Row k holds columns 0 .. min(k, r - 1) and starts at `row_start(k, r)` of the packed vector.
The compiled root kernel (`active.logdet_kernels.gram_root_factors`) writes this layout by Householder LQ; here is
its torch twin (`lower_trapezoid`, by QR of R^T) and the packing both share.
"""
from __future__ import annotations

import torch


def row_start(k: int, r: int) -> int:
    """Offset of row k in a packed lower-trapezoidal factor with r columns (rows 0 .. r-1 grow by one entry each)."""
    return k * (k + 1) // 2 if k <= r else r * (r + 1) // 2 + (k - r) * r


def packed_width(p: int, r: int) -> int:
    """Entries of a packed lower-trapezoidal [P, r] factor: sum_k min(k + 1, r)."""
    return row_start(p, r)


def packed_positions(p: int, r: int, device: torch.device | str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """(row, column) of each packed entry, in packed order. -> ([m], [m]) int64"""
    rows = torch.repeat_interleave(torch.arange(p, device=device),
                                   torch.clamp(torch.arange(1, p + 1, device=device), max=r))
    cols = torch.arange(rows.shape[0], device=device) - torch.tensor([row_start(k, r) for k in range(p)],
                                                                     device=device)[rows]
    return rows, cols


def lower_trapezoid(factors: torch.Tensor) -> torch.Tensor:
    """T = R Q^T lower trapezoidal with T T^T = R R^T, from the QR factorisation R^T = Q' U (T = U^T), float64.
    [n, P, r] -> [n, P, r] (columns past min(P, r) are 0)"""
    n, p, r = factors.shape
    upper = torch.linalg.qr(factors.double().transpose(1, 2), mode="r").R  # [n, min(r, P), P]
    out = factors.new_zeros(n, p, r, dtype=torch.float64)
    out[:, :, :upper.shape[1]] = upper.transpose(1, 2)
    return out


def pack(factors: torch.Tensor) -> torch.Tensor:
    """The lower-trapezoidal part of [n, P, r], row by row (entries above it are dropped). -> [n, m], same dtype"""
    rows, cols = packed_positions(factors.shape[1], factors.shape[2], factors.device)
    return factors[:, rows, cols]


def unpack(packed: torch.Tensor, p: int, r: int) -> torch.Tensor:
    """[n, m] packed factors -> [n, P, r] lower trapezoidal, same dtype."""
    rows, cols = packed_positions(p, r, packed.device)
    out = packed.new_zeros(packed.shape[0], p, r)
    out[:, rows, cols] = packed
    return out
