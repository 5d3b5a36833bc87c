"""benchmarks/bench_approximation.py: the brute-force rho(S) equals committing the views one by one, OPT is the
maximum, and bad inputs (delta <= 0, K out of range, too many subsets) are one-line errors naming the numbers."""
import math
import sys
from pathlib import Path

import pytest
import torch

from active.fisher import fisher_view_blocks
from active.logdet import BlockInformation
from tests.test_fisher_oracle import BG, cameras, settings, tiny_model
from utils.errors import UserError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_approximation import check_inputs, subset_rhos  # noqa: E402


def test_subset_rhos_equal_sequential_commits():
    model, cams = tiny_model(seed=3), cameras()
    blocks = {v: fisher_view_blocks(model, cams[v], BG, settings("compiled")) for v in range(6)}
    prior = blocks[0] + blocks[3]
    rhos = subset_rhos(BlockInformation(prior, delta_rel=1e-6), blocks, [1, 2, 4, 5], 2)
    assert sorted(rhos) == [(1, 2), (1, 4), (1, 5), (2, 4), (2, 5), (4, 5)]
    for subset, value in rhos.items():
        info = BlockInformation(prior, delta_rel=1e-6)
        for v in subset:
            info.add(blocks[v])
        assert value == pytest.approx(info.rho(), rel=1e-9)
        assert value > 0


@pytest.mark.parametrize("m,ks,deltas,cap,needle", [
    (14, [3], [1e-6, 0.0], 5000, "--delta_rel must be positive, got 0"),
    (14, [3], [-1e-3], 5000, "--delta_rel must be positive, got -0.001"),
    (14, [15], [1e-6], 5000, "K = 15 must lie in 1..M = 14"),
    (30, [5], [1e-6], 5000, f"C(30, 5) = {math.comb(30, 5)} subsets exceeds the cap of 5000")])
def test_bad_inputs_are_one_line(m, ks, deltas, cap, needle):
    with pytest.raises(UserError, match=needle.replace("(", r"\(").replace(")", r"\)")) as err:
        check_inputs(m, ks, deltas, cap)
    assert "\n" not in str(err.value)
    check_inputs(14, [2, 3, 4], [1e-3, 1e-6, 1e-9], 5000)  # the defaults pass
