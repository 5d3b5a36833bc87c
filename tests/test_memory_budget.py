"""The Fisher pass's memory, known before the work (`active.memory_budget`): the estimate's formula, its growth, its
agreement with the measured peak, the check's three outcomes, and the CLIs refusing a model too large in seconds."""
from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import replace

import numpy as np
import pytest
import torch
from plyfile import PlyData, PlyElement

from active import build_selector
from arguments import FisherSettings
from active.memory_budget import (HEADROOM, FisherWork, device_available_bytes, estimate, fit_fisher_memory,
                                  selection_work, smaller_passes)
from arguments import ActiveConfig, ModelConfig, PipelineConfig, config_to_dict
from scene.cameras import Camera, look_at
from scene.gaussian_model import GaussianModel
from scene.ply_io import ply_attribute_names
from tests.conftest import run_cli
from tests.test_recommend import EYES, _cameras_json
from training.acquisition import fit_selection_memory
from training.config import parse_config
from utils.errors import UserError

GB = 10 ** 9
BIG_N = 3_000_000  # a full-SH prior alone is 3M x 59^2 x 8 B = 84 GB


def test_estimate_is_the_documented_formula():
    n, p, pixels, m, threads = 1000, 14, 64 * 48, 90, 2  # m: packed entries of a [14, 9] trapezoid
    view = n * (8 * (9 * p + 81 + 34 * (threads + 1)) + 560) + pixels * 64  # Jacobian, Gram, sums, render; pixels
    u = n * p * p * 8
    logdet = estimate(FisherWork("logdet", n, p, pixels, 5, threads), cache_bytes=10 ** 9)
    adding = u + max(view + n * m * 8, 2 * u + n * (9 * p + m) * 8)
    assert (logdet.prior, logdet.resident, logdet.view) == (max(5 * u, adding), 2 * u, view + n * m * 4)
    assert logdet.cache == 5 * n * (4 * m + 8)
    assert logdet.peak == max(logdet.prior, 2 * u + view + n * m * 4 + logdet.cache)
    assert estimate(FisherWork("logdet", n, p, pixels, 5, threads), cache_bytes=1000).cache == 1000
    uncertainty = estimate(FisherWork("uncertainty", n, p, pixels, 0, threads))
    assert uncertainty.peak == max(5 * u, 3 * u + n * 9 * p * 8 + view)
    d = n * p * 8
    diagonal = estimate(FisherWork("diagonal", n, p, pixels, 3, threads), cache_bytes=10 ** 9)
    gram_pass = view - n * 9 * p * 8  # the render and Gram end before J, G J and their product [n, 9, P] begin
    diag_view = max(gram_pass, n * (3 * 9 * p + 81) * 8 + d)
    assert (diagonal.prior, diagonal.resident, diagonal.view, diagonal.cache) == (d + diag_view, d, diag_view, 3 * d)
    grown = estimate(FisherWork("logdet", n, p, pixels, 5, threads, model_bytes=123), cache_bytes=10 ** 9)
    assert grown.peak == logdet.peak + 123 and grown.fixed == 123 + max(logdet.prior, 2 * u + logdet.view)


@pytest.mark.parametrize("kind", ["logdet", "uncertainty", "diagonal"])
def test_estimate_grows_with_gaussians_block_pixels_and_candidates(kind):
    base = FisherWork(kind, 20_000, 14, 200 * 150, 10, 1)
    peak = estimate(base, 10 ** 12).peak
    for field, larger in (("num_gaussians", 40_000), ("num_params", 59)):
        assert estimate(replace(base, **{field: larger}), 10 ** 12).peak > peak
    for field, larger in (("pixels", 1296 * 840), ("num_candidates", 40), ("threads", 16)):
        assert estimate(replace(base, **{field: larger}), 10 ** 12).peak >= peak
    if kind != "diagonal":  # at least the five dense copies of the prior: 418 GB for 3M full-SH Gaussians
        assert estimate(FisherWork(kind, BIG_N, 59, 1296 * 840)).peak >= 5 * BIG_N * 59 ** 2 * 8


@pytest.mark.skipif(not os.path.exists("/proc/self/clear_refs"), reason="needs Linux's /proc/self/clear_refs")
def test_estimate_is_within_the_headroom_of_the_measured_peak():
    """Measured peak resident memory (VmHWM) of real passes in a subprocess: logdet (P = 14, cache of two
    candidates), the full-SH uncertainty prior (P = 59) and the diagonal oracle, with glibc's mmap threshold fixed
    (the peak of the live buffers); estimate / measured in [0.90, 1.20] (1.00-1.10 measured on 2026-12-06,
    docs/performance.md)."""
    r = run_cli("-m", "tests.memory_probe", "logdet:60000:default", "uncertainty:8000:full_sh",
                "diagonal:40000:default", timeout=300)
    assert r.returncode == 0, r.stderr
    for line in r.stdout.splitlines():
        row = json.loads(line)
        assert 0.90 <= row["estimate"] / row["measured"] <= 1.20, row


def _work(kind: str = "logdet", p: int = 14) -> FisherWork:
    """100k Gaussians, 100 candidates: at P = 14 a full cache outgrows the prior's peak."""
    return FisherWork(kind, 100_000, p, 200 * 150, 100, 1)


def _usable(available: int) -> int:
    return int(available * HEADROOM)


def test_a_pass_that_fits_keeps_its_settings():
    fisher = FisherSettings()
    assert fit_fisher_memory(_work(), fisher, "the pass", {}, "no way", available=100 * GB) is fisher


def test_the_default_cache_is_lowered_to_what_scoring_leaves_and_says_so(caplog):
    work = _work()
    need = estimate(work)
    available = int((need.fixed + 2 ** 24) / HEADROOM)  # the prior's peak fits, a quarter of this on top of scoring not
    assert need.resident + need.view + available // 4 > _usable(available)
    with caplog.at_level(logging.WARNING):
        fitted = fit_fisher_memory(work, FisherSettings(), "the pass", {}, "no way", available=available)
    room = _usable(available) - need.resident - need.view
    assert fitted.fisher_mode == "cached" and fitted.fisher_cache_mb == room >> 20
    assert estimate(work, fitted.fisher_cache_mb << 20).peak <= _usable(available)
    assert "the pass: a Fisher cache of" in caplog.text and "caching at most" in caplog.text
    diagonal = _work("diagonal")  # its pass while scoring is its peak: no room is left for a cache
    tight = fit_fisher_memory(diagonal, FisherSettings(), "the pass", {}, "no way",
                              available=int(estimate(diagonal).fixed / HEADROOM) + 1000)
    assert tight.fisher_mode == "streaming"


def test_an_explicit_cache_too_large_is_refused_naming_the_budget_that_fits():
    work = _work()
    need = estimate(work)
    available = int((need.fixed + GB) / HEADROOM)
    room = _usable(available) - need.resident - need.view
    with pytest.raises(UserError, match=rf"with --fisher_cache_mb 50000 .* pass --fisher_cache_mb {room >> 20} or "
                                        r"--fisher_mode streaming$"):
        fit_fisher_memory(work, FisherSettings(fisher_cache_mb=50_000), "the pass", {}, "no way", available=available)


def test_a_pass_too_large_is_refused_with_the_estimate_and_the_remedies_that_fit():
    work, small = _work(p=59), _work(p=14)
    available = int(estimate(small).fixed / HEADROOM) + GB  # P = 14 fits, P = 59 does not
    remedies = {"--fisher_params default": small, "--width 100": replace(work, pixels=work.pixels // 4)}
    with pytest.raises(UserError) as err:
        fit_fisher_memory(work, FisherSettings(), "the X pass", remedies, "no way", available=available)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"the X pass needs about {estimate(work).peak / GB:.1f} GB")
    assert f"but {available / GB:.1f} GB is available ({_usable(available) / GB:.1f} GB usable)" in message
    assert message.endswith(f"; pass --fisher_params default (about {estimate(small).fixed / GB:.1f} GB)")
    with pytest.raises(UserError) as err:
        fit_fisher_memory(work, FisherSettings(), "the X pass", remedies, "no way", available=GB // 10)
    assert "--fisher_params default would still need" in str(err.value) and str(err.value).endswith("; no way")
    assert "--width" not in str(err.value)  # it saves under a tenth: not worth naming


def test_selection_work_follows_the_oracle_kind():
    gaussians = GaussianModel(3, {"means": torch.zeros(10, 3), "sh_dc": torch.zeros(10, 1, 3),
                                  "sh_rest": torch.zeros(10, 15, 3), "logit_opacities": torch.zeros(10),
                                  "log_scales": torch.zeros(10, 3), "quats": torch.zeros(10, 4)})
    assert selection_work("coverage", gaussians, 100, 5, "default") is None
    assert selection_work("logdet", gaussians, 100, 5, "default").num_params == 14
    assert selection_work("logdet_opacity", gaussians, 100, 5, "full_sh").num_params == 59
    assert selection_work("diagonal", gaussians, 100, 5, "default").num_params == 59  # every raw parameter
    assert selection_work("diagonal_reference", gaussians, 100, 5, "default").num_params == 55  # no rotation
    work = selection_work("logdet", gaussians, 100, 5, "full_sh", num_gaussians=BIG_N, model_bytes=7)
    assert (work.kind, work.num_gaussians, work.model_bytes) == ("logdet", BIG_N, 7)
    assert set(smaller_passes(work, gaussians, 64, "-r")) == {"--fisher_params default", "-r 32"}
    assert set(smaller_passes(replace(work, num_params=14), gaussians, 30, "-r")) == set()


def test_cuda_memory_is_the_devices_free_memory(monkeypatch):
    monkeypatch.setattr(torch.cuda, "mem_get_info", lambda device: (123, 456))
    assert device_available_bytes(torch.device("cuda")) == 123
    assert device_available_bytes(torch.device("cpu")) > 0


def test_an_acquisition_lowers_the_cache_or_refuses_with_train_flags(tiny_scene, monkeypatch):
    n = 200_000
    gaussians = GaussianModel(3, {"means": torch.zeros(n, 3), "sh_dc": torch.zeros(n, 1, 3),
                                  "sh_rest": torch.zeros(n, 15, 3), "logit_opacities": torch.zeros(n),
                                  "log_scales": torch.zeros(n, 3), "quats": torch.zeros(n, 4)})
    cameras = [Camera(i, f"c{i}", look_at(torch.tensor([3.0, float(i), 1.0])), 50, 50, 32, 32, 64, 64)
               for i in range(10)]
    default = selection_work("logdet", gaussians, 64 * 64, 8, "default")  # P = 14: the cache outgrows the prior
    monkeypatch.setattr("training.acquisition.device_available_bytes",
                        lambda device: int(estimate(default).fixed / 0.8))
    cfg = parse_config(["-s", str(tiny_scene), "--method", "pop_gs"])
    fisher = fit_selection_memory(cfg, build_selector("pop_gs"), gaussians, cameras, 8)
    assert 0 < fisher.fisher_cache_mb and fisher.fisher_mode == "cached"  # the default quarter, lowered
    cfg = parse_config(["-s", str(tiny_scene), "--method", "pop_gs", "--fisher_params", "full_sh"])
    with pytest.raises(UserError, match=rf"pop_gs Fisher pass over {n} Gaussians \(P = 59, --fisher_params "
                                        r"full_sh\) needs about .* pass --fisher_params default \(about"):
        fit_selection_memory(cfg, build_selector("pop_gs"), gaussians, cameras, 8)


@pytest.fixture(scope="module")
def big_ply(tmp_path_factory):
    """A PLY of `BIG_N` full-SH Gaussians in the 3DGS layout, written with plyfile (744 MB)."""
    path = tmp_path_factory.mktemp("big") / "big.ply"
    data = np.zeros(BIG_N, dtype=[(name, "f4") for name in ply_attribute_names(45)])
    g = np.random.default_rng(0)
    for axis in "xyz":
        data[axis] = g.uniform(-0.6, 0.6, BIG_N)
    data["rot_0"], data["opacity"] = 1.0, -2.0
    for i in range(3):
        data[f"scale_{i}"] = -5.0
    PlyData([PlyElement.describe(data, "vertex")]).write(str(path))
    return path


def _assert_refused_in_seconds(result, seconds: float, limit: float = 10.0) -> str:
    """One `error:` line naming the estimate and the available memory, in under `limit` s, exit 2."""
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "needs about" in lines[0] and "GB is available" in lines[0], lines[0]
    assert seconds <= limit, f"refused after {seconds:.1f} s"
    return lines[0]


def test_recommend_refuses_a_model_too_large_in_seconds(big_ply, tmp_path):
    cams = _cameras_json(tmp_path / "cameras.json", EYES)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    r = run_cli("recommend.py", "-m", str(big_ply), "--captured", str(cams), "--candidates", "orbit:8", "-k", "2",
                "--method", "pop_gs", "--fisher_params", "full_sh", "-o", str(out), "--quiet")
    line = _assert_refused_in_seconds(r, time.perf_counter() - t0)
    assert f"pop_gs Fisher pass over {BIG_N} Gaussians (P = 59, --fisher_params full_sh)" in line
    assert not out.exists()


def test_render_uncertainty_refuses_a_model_too_large_in_seconds(big_ply, tiny_scene, tmp_path):
    model = tmp_path / "model"
    (model / "point_cloud" / "iteration_1").mkdir(parents=True)
    (model / "point_cloud" / "iteration_1" / "point_cloud.ply").symlink_to(big_ply)
    (model / "cfg_args").write_text(json.dumps({
        "model": config_to_dict(ModelConfig(source_path=str(tiny_scene), sh_degree=3)),
        "pipeline": config_to_dict(PipelineConfig()), "active": config_to_dict(ActiveConfig(fisher_params="full_sh"))}))
    t0 = time.perf_counter()
    r = run_cli("render.py", "-m", str(model), "--uncertainty", "--quiet")
    line = _assert_refused_in_seconds(r, time.perf_counter() - t0)
    assert f"position_variance uncertainty over {BIG_N} Gaussians (P = 59" in line
    assert "--uncertainty_kind fisherrf,fisherrf_view" in line
    assert not (model / "train").exists()


def test_train_refuses_before_training_when_max_gaussians_would_not_fit(tiny_scene, tmp_path):
    model = tmp_path / "model"
    t0 = time.perf_counter()
    r = run_cli("train.py", "-s", str(tiny_scene), "-m", str(model), "--method", "pop_gs", "--fisher_params",
                "full_sh", "--max_gaussians", str(BIG_N), "--num_random_points", "500", "--quiet")
    line = _assert_refused_in_seconds(r, time.perf_counter() - t0, limit=30.0)
    assert f"over up to {BIG_N} Gaussians (P = 59, --fisher_params full_sh)" in line
    assert "pass --max_gaussians" in line
    assert not (model / "cfg_args").exists()
