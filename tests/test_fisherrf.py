"""fisherrf: diagonals equal the block diagonals and a brute-force sum (dI/dtheta)^2; its picks and scores equal a
greedy written out on brute-force diagonals; counts; the diagonal oracle through build_oracle; bad options."""
import pytest
import torch

from active import build_selector
from active.base import SelectionContext
from active.fisher import (REFERENCE_DIAGONAL_GROUPS, DiagonalGainOracle, build_oracle, fisher_view_blocks,
                           fisher_view_diagonals, fisher_view_diagonals_reference, parameter_columns)
from arguments import FisherSettings
from gaussian_renderer.fisher_partials import RAW_PARAMETER_GROUPS
from tests.test_fisher_oracle import BG, H, W, cameras, reference_image, settings, tiny_model
from utils.errors import UserError


def bruteforce_diagonals(model, cam, sigma=1.0):
    """sigma^-2 sum over pixels and channels of (dI/dtheta)^2 for every raw parameter, from the full autograd
    Jacobian of the image rendered by the dense reference, in RAW_PARAMETER_GROUPS order. [N, 3 + 4 + 3 + 1 + 3 + 9]"""
    def image(*raw):
        return reference_image(cam, *raw)

    jac = torch.autograd.functional.jacobian(image, tuple(model.params[k].detach() for k in RAW_PARAMETER_GROUPS),
                                             vectorize=True)
    n = model.num_gaussians
    widths = [model.params[k][0].numel() for k in RAW_PARAMETER_GROUPS]
    j = torch.cat([part.reshape(-1, n, w) for part, w in zip(jac, widths)], dim=2)  # [pixels x channels, N, P]
    return (j ** 2).sum(0) / sigma**2


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_diagonals_equal_bruteforce_and_the_block_diagonals(backend):
    model, cam = tiny_model(seed=1), cameras()[2]
    expected = bruteforce_diagonals(model, cam, sigma=0.5)
    diag = fisher_view_diagonals(model, cam, BG, settings(backend), sigma=0.5)
    assert diag.shape == (6, 3 + 4 + 3 + 1 + 3 + 9) and expected[:, 14:].abs().max() > 1e-4  # sh_rest matters
    torch.testing.assert_close(diag, expected, rtol=1e-4, atol=1e-4 * expected.abs().max().item())
    blocks = fisher_view_blocks(model, cam, BG, settings(backend), sigma=0.5, param_groups=RAW_PARAMETER_GROUPS)
    torch.testing.assert_close(diag, torch.diagonal(blocks, dim1=-2, dim2=-1), rtol=1e-10, atol=1e-12)
    cols = parameter_columns(model, RAW_PARAMETER_GROUPS)
    assert cols["quats"] == slice(3, 7) and cols["sh_rest"] == slice(14, 23)


def bruteforce_reference_diagonals(model, cam, sigma=1.0):
    """What FisherRF's modified rasterizer accumulates, written out from the autograd Jacobian of the image w.r.t. the
    *activated* means, scales, opacities and the SH coefficients: geometry columns sum_pixels (sum_channels dI/da)^2
    times the activation derivative once (exp for scales, sigmoid for opacities); SH columns sum_pixels,channels
    (dI/dsh)^2. Columns in REFERENCE_DIAGONAL_GROUPS order. [N, 3 + 3 + 1 + 3 + 9]"""
    quats = model.params["quats"].detach()

    def image(means, scales, opacities, sh_dc, sh_rest):  # the dense reference image of the activated parameters
        return reference_image(cam, means, quats, torch.log(scales), torch.logit(opacities), sh_dc, sh_rest)

    log_scales, logits = model.params["log_scales"].detach(), model.params["logit_opacities"].detach()
    inputs = (model.params["means"].detach(), log_scales.exp(), torch.sigmoid(logits),
              model.params["sh_dc"].detach(), model.params["sh_rest"].detach())
    jac = torch.autograd.functional.jacobian(image, inputs)  # each [3, H, W, N, ...]
    n = model.num_gaussians
    summed = [(part.sum(0) ** 2).reshape(H * W, n, -1).sum(0) for part in jac[:3]]  # channel-summed, then squared
    squares = [(part ** 2).reshape(3 * H * W, n, -1).sum(0) for part in jac[3:]]
    o = torch.sigmoid(logits).reshape(-1, 1)
    geometry = [summed[0], summed[1] * log_scales.exp(), summed[2] * o * (1 - o)]
    return torch.cat(geometry + squares, dim=1) / sigma**2


@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_reference_diagonals_equal_fisherrf_code_written_out(backend):
    model, cam = tiny_model(seed=1), cameras()[2]
    expected = bruteforce_reference_diagonals(model, cam, sigma=0.5)
    diag = fisher_view_diagonals_reference(model, cam, BG, settings(backend), sigma=0.5)
    assert diag.shape == expected.shape == (6, 19)
    torch.testing.assert_close(diag, expected, rtol=1e-4, atol=1e-4 * expected.abs().max().item())
    exact = fisher_view_diagonals(model, cam, BG, settings(backend), sigma=0.5, param_groups=REFERENCE_DIAGONAL_GROUPS)
    torch.testing.assert_close(diag[:, 7:], exact[:, 7:], rtol=1e-10, atol=0.0)  # colour: the two agree
    assert not torch.allclose(diag[:, :7], exact[:, :7], rtol=1e-2)  # geometry and opacity: they differ
    with pytest.raises(UserError, match="rotation"):
        fisher_view_diagonals_reference(model, cam, BG, settings(backend), param_groups=("means", "quats"))


def greedy_reference(diags, train, candidates, k, keep, lam):
    """FisherRF's greedy written out: score sum h_c / (h + lam) over the kept columns, h += h_pick."""
    h = sum(diags[v] for v in train)
    ids, scores = [], []
    for _ in range(k):
        rest = [v for v in candidates if v not in ids]
        values = [float((diags[v][:, keep] / (h[:, keep] + lam)).sum()) for v in rest]
        best = max(range(len(rest)), key=lambda i: (values[i], -rest[i]))
        ids.append(rest[best])
        scores.append(values[best])
        h = h + diags[rest[best]]
    return ids, scores


@pytest.mark.parametrize("mode", ["cached", "streaming"])
@pytest.mark.parametrize("params,lam", [("means,log_scales,logit_opacities,sh_dc,sh_rest", 1e-6),
                                        ("quats,sh_dc", 1e-2)])
@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_selection_equals_greedy_on_bruteforce_diagonals(mode, params, lam, backend):
    model, cams = tiny_model(seed=2), cameras()
    diags = [bruteforce_diagonals(model, cam) for cam in cams]
    cols = parameter_columns(model, RAW_PARAMETER_GROUPS)
    keep = torch.cat([torch.arange(cols[g].start, cols[g].stop) for g in params.split(",")])
    ids, scores = greedy_reference(diags, [0, 3], [1, 2, 4, 5], 3, keep, lam)
    oracle = build_oracle("diagonal", model, cams, [0, 3], BG, settings(backend),
                          fisher=FisherSettings(fisher_mode=mode))
    ctx = SelectionContext([5, 1, 4, 2], oracle, torch.Generator().manual_seed(0), 0)
    sel = build_selector("fisherrf", fisherrf_lambda=lam, fisherrf_params=params).select(ctx, 3)
    assert sel.ids == ids
    torch.testing.assert_close(torch.tensor(sel.gains), torch.tensor(scores), rtol=1e-4, atol=0.0)
    assert oracle.evaluated == sel.conservative == 4 + 3 + 2 == build_selector("fisherrf").conservative_count(4, 3)
    assert oracle.views_computed == 4 and oracle.fisher_seconds > 0
    torch.testing.assert_close(oracle.information, sum(diags[v] for v in [0, 3] + ids), rtol=1e-4,
                               atol=1e-4 * float(oracle.information.abs().max()))


@pytest.mark.parametrize("mode", ["cached", "streaming"])
@pytest.mark.parametrize("backend", ["torch", "compiled"])
def test_reference_variant_equals_greedy_on_bruteforce_reference_diagonals(mode, backend):
    model, cams = tiny_model(seed=2), cameras()
    diags = [bruteforce_reference_diagonals(model, cam) for cam in cams]
    keep = torch.arange(diags[0].shape[1])  # the default groups are exactly REFERENCE_DIAGONAL_GROUPS
    ids, scores = greedy_reference(diags, [0, 3], [1, 2, 4, 5], 3, keep, 1e-6)
    selector = build_selector("fisherrf", fisherrf_variant="reference")
    assert selector.oracle_kind == "diagonal_reference"
    oracle = build_oracle(selector.oracle_kind, model, cams, [0, 3], BG, settings(backend),
                          fisher=FisherSettings(fisher_mode=mode))
    sel = selector.select(SelectionContext([5, 1, 4, 2], oracle, torch.Generator().manual_seed(0), 0), 3)
    assert sel.ids == ids
    torch.testing.assert_close(torch.tensor(sel.gains), torch.tensor(scores), rtol=1e-4, atol=0.0)


def test_rotation_is_left_out_by_default_and_ties_go_to_the_lowest_id():
    diag = torch.zeros(2, 4, dtype=torch.float64)
    diag[:, 1] = 5.0  # only the "quats" column differs between views: the default ignores it
    views = {7: diag, 3: torch.zeros_like(diag), 9: torch.zeros_like(diag)}
    oracle = DiagonalGainOracle(torch.zeros(2, 4), lambda v: views[v],
                                {"means": slice(0, 1), "quats": slice(1, 2), "log_scales": slice(2, 3),
                                 "logit_opacities": slice(3, 4), "sh_dc": slice(4, 4), "sh_rest": slice(4, 4)})
    sel = build_selector("fisherrf").select(SelectionContext([9, 7, 3], oracle, torch.Generator(), 0), 2)
    assert sel.ids == [3, 7] and sel.gains == [0.0, 0.0] and sel.conservative == 3 + 2
    sel = build_selector("fisherrf", fisherrf_params="quats").select(
        SelectionContext([9, 7, 3], DiagonalGainOracle(torch.zeros(2, 4), lambda v: views[v], oracle.columns),
                         torch.Generator(), 0), 1)
    assert sel.ids == [7] and sel.gains == [pytest.approx(2 * 5.0 / 1e-6)]


@pytest.mark.parametrize("options,needle", [({"fisherrf_lambda": 0.0}, "--fisherrf_lambda must be positive"),
                                            ({"fisherrf_lambda": -1e-3}, "--fisherrf_lambda must be positive"),
                                            ({"fisherrf_params": "means,rotation"}, "unknown: rotation"),
                                            ({"fisherrf_params": ""}, "--fisherrf_params"),
                                            ({"fisherrf_params": "means,means"}, "--fisherrf_params"),
                                            ({"fisherrf_variant": "paper"}, "choose one of exact, reference"),
                                            ({"fisherrf_variant": "reference", "fisherrf_params": "means,quats"},
                                             "cannot score quats")])
def test_bad_options_are_one_line(options, needle):
    with pytest.raises(UserError, match=needle) as err:
        build_selector("fisherrf", **options)
    assert "\n" not in str(err.value)
