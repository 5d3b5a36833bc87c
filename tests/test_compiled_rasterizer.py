"""Compiled (numba) rasterizer backend vs its torch twin and the dense reference; backend selection and bad input."""
import logging
import math
import os

import numpy as np
import pytest
import torch

from gaussian_renderer import RasterSettings, attribute_gram, rasterize
from gaussian_renderer import compiled
from gaussian_renderer.compiled import ops
from gaussian_renderer.reference import rasterize_reference
from tests.conftest import run_cli
from tests.test_rasterize import BG, _grads, _run, random_2d_scene
from utils.errors import UserError

pytest.importorskip("numba")

TOL = {torch.float64: 1e-9, torch.float32: 1e-5}  # relative to the largest entry of each compared tensor


def stacked_scene(n=12, dtype=torch.float64):
    """Opaque Gaussians on one spot: transmittance reaches the 1e-4 floor (early stop), centres clamp at 0.99."""
    g = torch.Generator().manual_seed(7)
    means2d = torch.full((n, 2), 4.0, dtype=dtype) + torch.rand(n, 2, generator=g, dtype=dtype)
    conics = torch.tensor([[0.05, 0.01, 0.06]], dtype=dtype).repeat(n, 1)
    opacities = torch.full((n,), 0.95, dtype=dtype)
    opacities[0] = 1.0
    return (means2d, conics, opacities, torch.rand(n, 3, generator=g, dtype=dtype), torch.arange(n, dtype=dtype),
            torch.full((n,), 6, dtype=torch.long))


def corner_scene(dtype=torch.float64):
    """A few Gaussians in the top-left corner of a 40 x 36 image: most tiles are empty."""
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(10, 8, 8, seed=3, dtype=dtype)
    return means2d.clamp(0, 8), conics, opacities, colors, depths, radii


CASES = {  # name: (scene factory, width, height, tile size)
    "mixed_tile4": (lambda dt: random_2d_scene(30, 24, 20, dtype=dt), 24, 20, 4),  # culled, off-screen, clamped
    "mixed_tile16_overhang": (lambda dt: random_2d_scene(60, 40, 17, seed=1, dtype=dt), 40, 17, 16),
    "many_tile8": (lambda dt: random_2d_scene(200, 33, 29, seed=2, dtype=dt), 33, 29, 8),
    "early_stop_clamped": (lambda dt: stacked_scene(dtype=dt), 8, 8, 4),
    "empty_tiles": (lambda dt: corner_scene(dtype=dt), 40, 36, 4),
    "block15_tile3": (lambda dt: random_2d_scene(60, 31, 23, seed=4, dtype=dt), 31, 23, 3),  # rows of 15 + padding
    "block32_tile32": (lambda dt: random_2d_scene(60, 45, 37, seed=5, dtype=dt), 45, 37, 32),  # one tile per block
}


def test_pixel_box_holds_every_reachable_pixel_and_little_else():
    """The in-tile pixel box of a pair against brute force over the tile: every pixel with power >= cut (the
    kernels' reach test) lies inside it, and it is the ellipse's bounding box (half-widths sqrt(-2 cut) sigma from
    the covariance) in pixels, give or take one (the rounding margin). Degenerate conics take the whole tile; cut > 0 (alpha_min out of reach) none of it."""
    from gaussian_renderer.compiled.kernels import _pixel_box
    box = _pixel_box.py_func
    tile, rng = 16, torch.Generator().manual_seed(5)
    centres = torch.arange(tile, dtype=torch.float64) + 0.5
    px, py = centres[None, :].expand(tile, tile), centres[:, None].expand(tile, tile)
    nonempty = 0
    for _ in range(400):
        mx, my = (torch.rand(2, generator=rng, dtype=torch.float64) * 40 - 12).tolist()
        sx, sy = torch.exp(torch.rand(2, generator=rng, dtype=torch.float64) * 4 - 1.5).tolist()
        rho = float(torch.rand(1, generator=rng, dtype=torch.float64)) * 1.9 - 0.95
        det = (sx * sy) ** 2 * (1 - rho ** 2)
        ca, cb, cc = sy ** 2 / det, -rho * sx * sy / det, sx ** 2 / det  # inverse of the 2x2 covariance
        cut = float(torch.rand(1, generator=rng, dtype=torch.float64)) * -6
        dx, dy = px - mx, py - my
        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
        ys, xs = torch.nonzero(power >= cut, as_tuple=True)
        got = x_lo, x_hi, y_lo, y_hi = box(mx, my, ca, cb, cc, cut, tile)
        hx, hy = math.sqrt(-2 * cut) * sx, math.sqrt(-2 * cut) * sy
        expect = (max(0, math.ceil(mx - hx - 0.5)), min(tile - 1, math.floor(mx + hx - 0.5)),
                  max(0, math.ceil(my - hy - 0.5)), min(tile - 1, math.floor(my + hy - 0.5)))
        assert all(abs(a - b) <= 1 for a, b in zip(got, expect)), (got, expect)
        if len(xs):
            nonempty += 1
            assert x_lo <= xs.min() and xs.max() <= x_hi and y_lo <= ys.min() and ys.max() <= y_hi
    assert nonempty > 100
    assert box(3.0, 3.0, 1.0, 2.0, 1.0, -2.0, tile) == (0, tile - 1, 0, tile - 1)  # not positive definite
    assert box(3.0, 3.0, float("nan"), 0.0, 1.0, -2.0, tile) == (0, tile - 1, 0, tile - 1)
    assert box(3.0, 3.0, 1e-150, 0.0, 1e-150, -2.0, tile) == (0, tile - 1, 0, tile - 1)  # reach ~1e75 px: capped
    x_lo, x_hi, _, _ = box(3.0, 3.0, 1.0, 0.0, 1.0, 0.5, tile)
    assert x_lo > x_hi


def _render_all(backend, scene, width, height, tile, dtype):
    settings = RasterSettings(tile_size=tile, chunk_size=3, backend=backend)
    bg = BG.to(dtype)
    leaves = [t.clone().requires_grad_(True) for t in (*scene[:4], bg)]
    image, alpha = rasterize(*leaves[:4], scene[4], scene[5], width, height, leaves[4], settings)
    grads = _grads(image, alpha, leaves)
    weights = torch.rand(height, width, generator=torch.Generator().manual_seed(4), dtype=dtype)
    gram = attribute_gram(*scene, width, height, bg, settings)
    gram_weighted = attribute_gram(*scene, width, height, bg, settings, weights=weights)
    return image, alpha, *grads, gram, gram_weighted


def _assert_close_rel(actual, expected, tol, what):
    scale = expected.abs().max().clamp_min(1e-30)
    err = (actual.double() - expected.double()).abs().max() / scale
    assert err <= tol, f"{what}: relative error {err:.2e} > {tol:.0e}"


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("case", list(CASES))
def test_compiled_matches_torch_twin(case, dtype):
    make, width, height, tile = CASES[case]
    scene = make(dtype)
    names = ["image", "alpha", "d means2d", "d conics", "d opacities", "d colors", "d background", "gram",
             "weighted gram"]
    torch_out = _render_all("torch", scene, width, height, tile, dtype)
    compiled_out = _render_all("compiled", scene, width, height, tile, dtype)
    for name, a, b in zip(names, compiled_out, torch_out):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        _assert_close_rel(a, b, TOL[dtype], f"{case} {dtype} {name}")


@pytest.mark.parametrize("channels", [1, 2, 4, 6])
def test_compiled_gram_matches_torch_twin_for_any_channel_count(channels):
    # The compiled Gram takes colour channels three at a time, padding with zero channels it then drops: every count
    # must give the torch twin's Gram (and 6 = two groups of three, no padding).
    means2d, conics, opacities, _, depths, radii = random_2d_scene(30, 24, 20)
    colors = torch.rand(30, channels, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    background = torch.linspace(0.2, 0.9, channels, dtype=torch.float64)
    scene = (means2d, conics, opacities, colors, depths, radii)
    grams = [attribute_gram(*scene, 24, 20, background, RasterSettings(tile_size=4, backend=backend))
             for backend in ("compiled", "torch")]
    assert grams[0].shape == grams[1].shape == (30, 6 + channels, 6 + channels)
    _assert_close_rel(grams[0], grams[1], TOL[torch.float64], f"{channels}-channel gram")
    assert grams[1][:, :6, 6:].abs().sum() > 0  # the cross (geometry x colour) terms are exercised


def test_kernels_see_the_listed_gaussians_renumbered_by_first_appearance():
    # The block lists in kernel indices must name the same Gaussians, in the same order, as the lists in ids.
    from gaussian_renderer.compiled import kernels
    lists = np.array([7, 2, 7, 9, 2, 4, 9, 7], np.int32)
    order, renumbered = kernels.first_appearance_order(lists, 12)
    assert order.tolist() == [7, 2, 9, 4] and renumbered.dtype == np.int32
    assert order[renumbered].tolist() == lists.tolist()
    means2d, conics, opacities, _, depths, radii = random_2d_scene(30, 24, 20)
    bins = ops.bin_gaussians_compiled(means2d, conics, opacities, radii, depths, 24, 20, RasterSettings(tile_size=4))
    assert sorted(bins.order.tolist()) == sorted(set(bins.order.tolist())) and len(bins.rects) == len(bins.order)
    assert set(bins.order.tolist()) < set(range(30))  # the culled and off-screen Gaussians are not listed


@pytest.mark.parametrize("case", list(CASES))
def test_transmittance_only_forward_equals_the_full_forward(case):
    # The replays' forward (no colours) must leave the same final transmittance and last contributor.
    make, width, height, tile = CASES[case]
    means2d, conics, opacities, colors, depths, radii = make(torch.float64)
    settings = RasterSettings(tile_size=tile, backend="compiled")
    bins = ops.bin_gaussians_compiled(means2d, conics, opacities, radii, depths, width, height, settings)
    _, trans, last = ops.composite_compiled(bins, means2d, conics, opacities, colors, BG.double(), width, height,
                                            settings)
    trans_only, last_only = ops.transmittance_compiled(bins, means2d, conics, opacities, width, height, settings)
    assert torch.equal(torch.from_numpy(trans_only), trans) and torch.equal(torch.from_numpy(last_only), last)
    assert (last > 0).any() and (trans < 1).any()


def test_cases_exercise_every_rule():
    # Guards the comparison above: early stop, clamping and empty tiles really happen.
    image, alpha = rasterize(*stacked_scene(), 8, 8, BG, RasterSettings(tile_size=4, backend="compiled"))
    assert 1 - 1e-3 < alpha.max() <= 1 - 1e-4  # stopped at the transmittance floor
    _, alpha = rasterize(*corner_scene(), 40, 36, BG, RasterSettings(tile_size=4, backend="compiled"))
    assert (alpha[12:, 12:] == 0).all() and alpha[:8, :8].max() > 0.1


def test_compiled_matches_dense_reference():
    scene = random_2d_scene(30, 24, 20)
    settings = RasterSettings(tile_size=4, backend="compiled")
    img, alpha, leaves = _run(rasterize, scene, 24, 20, settings)
    img_ref, alpha_ref, ref_leaves = _run(rasterize_reference, scene, 24, 20, settings)
    torch.testing.assert_close(img, img_ref, atol=1e-10, rtol=0)
    torch.testing.assert_close(alpha, alpha_ref, atol=1e-10, rtol=0)
    for fast, ref in zip(_grads(img, alpha, leaves), _grads(img_ref, alpha_ref, ref_leaves)):
        torch.testing.assert_close(fast, ref, atol=1e-9, rtol=1e-9)


def test_gradcheck_compiled():
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(4, 6, 5, seed=2)
    radii[:] = 6
    settings = RasterSettings(tile_size=4, backend="compiled")
    inputs = tuple(t.clone().requires_grad_(True) for t in (means2d, conics, opacities, colors, BG))
    assert torch.autograd.gradcheck(lambda m, c, o, col, bg: rasterize(m, c, o, col, depths, radii, 6, 5, bg,
                                                                       settings), inputs, eps=1e-6, atol=1e-5)


def test_non_contiguous_and_mixed_dtype_inputs_are_converted():
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(30, 24, 20)
    settings = RasterSettings(backend="compiled")
    expected = rasterize(means2d, conics, opacities, colors, depths, radii, 24, 20, BG, settings)[0]
    odd_means = means2d.T.contiguous().T  # same values, column-major strides
    odd_colors = colors.float().requires_grad_(True)  # float32 colours with float64 geometry
    image = rasterize(odd_means, conics, opacities, odd_colors, depths, radii, 24, 20, BG, settings)[0]
    assert not odd_means.is_contiguous() and image.dtype == torch.float64
    _assert_close_rel(image, expected, 1e-7, "image")
    image.sum().backward()
    assert odd_colors.grad.dtype == torch.float32 and odd_colors.grad.abs().sum() > 0


def test_integer_inputs_are_rejected_with_the_dtype_named():
    means2d, conics, opacities, colors, depths, radii = random_2d_scene(5, 8, 8)
    with pytest.raises(UserError, match="torch.int64"):
        rasterize(means2d.long(), conics, opacities, colors, depths, radii, 8, 8, BG,
                  RasterSettings(backend="compiled"))


def test_numba_threads_follow_torch():
    import numba
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        rasterize(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="compiled"))
        assert numba.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


def test_the_guard_fails_a_test_that_reaches_auto():
    # tests/conftest.py: without the auto_backend marker, a CPU call resolving backend="auto" fails the test.
    with pytest.raises(AssertionError, match='backend="auto"'):
        rasterize(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="auto"))
    with pytest.raises(AssertionError, match='backend="auto"'):
        attribute_gram(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="auto"))


@pytest.mark.parametrize("host, preset, bits, expected", [
    ("+avx2,+avx512f,+fma", None, None, "+avx2,+avx512f,+fma,-prefer-256-bit"),  # AVX-512: 512-bit vectors
    ("+avx2,-avx512f,+fma", None, None, None),  # no AVX-512: numba's defaults
    ("+avx2,+avx512f,+fma", "+avx2", None, "+avx2"),  # the user's own features stay
    ("+avx2,+avx512f,+fma", None, "256", None),  # opted out
])
def test_numba_vector_width_setting(monkeypatch, host, preset, bits, expected):
    import llvmlite.binding as llvm

    class Features:
        def flatten(self):
            return host

    monkeypatch.setattr(llvm, "get_host_cpu_features", Features)
    for name, value in (("NUMBA_CPU_FEATURES", preset), (compiled.VECTOR_BITS_ENV, bits)):
        if value is None:
            monkeypatch.delenv(name, raising=False)
        else:
            monkeypatch.setenv(name, value)
    compiled.configure_numba_environment()
    assert os.environ.get("NUMBA_CPU_FEATURES") == expected


@pytest.mark.auto_backend
def test_auto_takes_compiled_on_cpu(monkeypatch):
    calls = []
    from gaussian_renderer.compiled import ops
    real = ops.rasterize_compiled
    monkeypatch.setattr(ops, "rasterize_compiled", lambda *a: calls.append(1) or real(*a))
    rasterize(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="auto"))
    assert calls == [1]
    rasterize(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="torch"))
    assert calls == [1]


@pytest.mark.auto_backend
def test_missing_numba(monkeypatch, caplog):
    # Simulated import failure: auto falls back with one log line, an explicit request is a UserError.
    monkeypatch.setattr(compiled, "numba_import_error", lambda: "No module named 'numba'")
    monkeypatch.setattr(compiled, "_log_fallback", compiled._log_fallback.__wrapped__)
    with pytest.raises(UserError, match="numba.*--raster_backend torch"):
        RasterSettings(backend="compiled")
    with caplog.at_level(logging.INFO, logger="gaussian_renderer.compiled"):
        image, _ = rasterize(*random_2d_scene(5, 8, 8), 8, 8, BG, RasterSettings(backend="auto"))
    assert image.shape == (3, 8, 8) and "pure-torch" in caplog.text


def test_unknown_backend_is_a_user_error():
    with pytest.raises(UserError, match="backend"):
        RasterSettings(backend="cuda")


def test_cli_compiled_without_numba_is_one_error_line(tiny_scene, tmp_path):
    # numba made unimportable in the child (sys.modules entry None), then train.py run as __main__.
    code = ("import runpy, sys; sys.modules['numba'] = None; sys.argv = sys.argv[1:]; "
            "runpy.run_path('train.py', run_name='__main__')")
    proc = run_cli("-c", code, "train.py", "-s", str(tiny_scene), "-m", str(tmp_path / "model"), "--raster_backend",
                   "compiled", "--iterations", "1", "-q")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "numba" in lines[0] and "torch" in lines[0]
    assert not (tmp_path / "model").exists()  # refused while parsing the flags: nothing written


def test_exp_neg_matches_exp_where_the_kernels_use_it():
    """The vectorisable exp of `row_kernels` against math.exp over [EXP_MIN, 0] (relative 1e-13), NaN kept."""
    from gaussian_renderer.compiled.row_kernels import EXP_MIN, exp_neg
    xs = torch.linspace(EXP_MIN, 0.0, 20_001, dtype=torch.float64).tolist() + [-1e-300, math.log(1 / 255)]
    worst = max(abs(exp_neg(x) - math.exp(x)) / math.exp(x) for x in xs)
    assert worst < 1e-13, worst
    assert math.isnan(exp_neg(float("nan")))


def test_alpha_min_below_the_kernels_exp_range_is_refused():
    from gaussian_renderer.settings import ALPHA_MIN_FLOOR
    with pytest.raises(UserError, match="alpha_min must be at least"):
        RasterSettings(alpha_min=ALPHA_MIN_FLOOR / 2)
    assert math.log(ALPHA_MIN_FLOOR) > -22.0  # cut = ln(alpha_min / o) stays inside exp_neg's exact range
