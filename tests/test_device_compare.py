"""The CUDA tests' comparison code, proven on CPU: float32 against float64 agrees within the CUDA tolerances, and a
perturbed result is rejected (so `tests/test_cuda.py` can fail)."""
import pytest
import torch

from tests import device_compare as dc


@pytest.mark.parametrize("backend", dc.BACKENDS)
def test_float32_render_and_gradients_agree_with_float64_within_the_tolerances(backend):
    value = dc.render_with_grads("cpu", torch.float32, backend=backend)
    reference = dc.render_with_grads("cpu", torch.float64, backend=backend)
    assert reference.alpha.max() > 0.5 and all(g.abs().max() > 0 for g in reference.grads.values())
    assert dc.compare_renders(value, reference) == []


def test_a_perturbed_render_or_gradient_is_rejected():
    reference = dc.render_with_grads("cpu", torch.float64, backend="torch")
    image = reference.image.clone()
    image[1, 3, 4] += 3e-5
    grads = dict(reference.grads)
    grads["quats"] = grads["quats"] * (1 + 3e-4)
    problems = dc.compare_renders(dc.RenderResult(image, reference.alpha, grads), reference)
    assert len(problems) == 2 and problems[0].startswith("image") and problems[1].startswith("grad quats")


@pytest.mark.parametrize("backend", dc.BACKENDS)
def test_float32_fisher_blocks_agree_with_float64_and_a_perturbation_is_rejected(backend):
    reference = dc.fisher_blocks("cpu", torch.float64, backend=backend)
    assert dc.compare_fisher(dc.fisher_blocks("cpu", torch.float32, backend=backend), reference) == []
    assert len(dc.compare_fisher(reference * (1 + 3e-4), reference)) == 1


def test_selection_comparison_tells_a_near_tie_from_a_different_selection():
    ref = {"stages": [{"stage": 0, "selected": [4, 7, 1], "gains": [10.0, 8.0, 5.0]}]}
    same = {"stages": [{"stage": 0, "selected": [4, 7, 1], "gains": [10.0, 8.0, 5.0]}]}
    tie = {"stages": [{"stage": 0, "selected": [4, 1, 7], "gains": [10.0, 8.000001, 5.0]}]}
    other = {"stages": [{"stage": 0, "selected": [4, 2, 1], "gains": [10.0, 6.0, 5.0]}]}
    assert dc.compare_selections(same, ref) == []
    assert "near-tie flip" in dc.compare_selections(tie, ref)[0]
    assert "different selection" in dc.compare_selections(other, ref)[0]


def test_the_two_cpu_backends_agree_in_float64():
    # The CUDA tests compare with one CPU backend; this ties the two CPU backends together (float64 rounding).
    torch_run = dc.render_with_grads("cpu", torch.float64, backend="torch")
    compiled_run = dc.render_with_grads("cpu", torch.float64, backend="compiled")
    assert dc.compare_renders(compiled_run, torch_run) == []
