"""The packed lower-trapezoidal layout of view factors (`active.trapezoid`) and the compiled Householder LQ
(`logdet_kernels._lower_trapezoid_lanes`) against the torch QR twin: same R R^T, zeros above the diagonal, layout offsets
equal in Python and numba."""
import pytest
import torch

from active import logdet_kernels, trapezoid


@pytest.mark.parametrize("p, r", [(14, 9), (4, 9), (3, 2), (14, 14), (59, 9), (1, 1)])
def test_layout_offsets_and_round_trip(p, r):
    rows, cols = trapezoid.packed_positions(p, r)
    assert trapezoid.packed_width(p, r) == rows.shape[0] == sum(min(k + 1, r) for k in range(p))
    assert bool((cols <= rows).all()) and bool((cols < r).all())
    for k in range(p + 1):  # the compiled kernels' offsets are the same
        assert logdet_kernels._row_start(k, r) == trapezoid.row_start(k, r)
    assert trapezoid.row_start(p - 1, r) + min(p, r) == trapezoid.packed_width(p, r)
    g = torch.Generator().manual_seed(p * 100 + r)
    lower = torch.tril(torch.randn(5, p, r, generator=g, dtype=torch.float64))
    assert torch.equal(trapezoid.unpack(trapezoid.pack(lower), p, r), lower)


@pytest.mark.parametrize("p, r, rank", [(14, 9, 9), (14, 9, 4), (4, 9, 4), (59, 9, 9), (14, 14, 14)])
def test_lower_trapezoid_keeps_the_block_on_both_paths(p, r, rank):
    g = torch.Generator().manual_seed(rank)
    scales = 10.0 ** torch.linspace(-4, 4, p, dtype=torch.float64)  # rows in different units, as real factors
    factors = torch.randn(50, p, r, generator=g, dtype=torch.float64) * scales[None, :, None]
    factors[:, :, rank:] = 0.0
    block = factors @ factors.transpose(1, 2)  # [n, P, P]
    scale = block.flatten(1).abs().amax(1)[:, None, None]
    twin = trapezoid.lower_trapezoid(factors)
    lanes = logdet_kernels.LQ_LANES
    v, scratch = torch.empty(r, lanes, dtype=torch.float64), torch.empty(3, lanes, dtype=torch.float64)
    compiled = torch.empty_like(factors)
    for first in range(0, factors.shape[0], lanes):  # 50 blocks: 6 full groups and one of 2 (padded with zeros)
        group = torch.zeros(r, p, lanes, dtype=torch.float64)  # [r, P, lanes], R transposed per lane
        chunk = factors[first:first + lanes]
        group[:, :, :chunk.shape[0]] = chunk.permute(2, 1, 0)
        logdet_kernels._lower_trapezoid_lanes(group.numpy(), v.numpy(), *scratch.numpy())
        compiled[first:first + lanes] = group[:, :, :chunk.shape[0]].permute(2, 1, 0)
    for out in (twin, compiled):
        assert torch.count_nonzero(torch.triu(out, diagonal=1)) == 0
        assert float(((out @ out.transpose(1, 2) - block).abs() / scale).max()) < 1e-13
    assert torch.count_nonzero(compiled[:, :, rank:]) == 0  # zero columns stay zero
