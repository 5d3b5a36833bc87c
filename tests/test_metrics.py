"""LPIPS loading (shipped weights, hub cache, nothing) and metrics.py end to end on PNGs written here."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

import metrics
from tests.conftest import run_cli
from utils.errors import UserError
from utils.losses import ssim
from utils.lpips_loader import (LPIPS_MIN_SIDE, SHIPPED_WEIGHTS, VARIANTS, _build, default_weights_path, infer_variant,
                                load_lpips, lpips_distance)


@pytest.fixture(scope="module")
def squeeze_weights() -> Path:
    """The LPIPS-squeeze weights shipped in the repository (weights/lpips_squeeze.pt)."""
    assert SHIPPED_WEIGHTS.is_file(), f"{SHIPPED_WEIGHTS} is missing from the repository"
    return SHIPPED_WEIGHTS


@pytest.fixture(autouse=True)
def _no_env_weights(monkeypatch, tmp_path):
    """No $LITEGS_LPIPS_WEIGHTS and an empty torch hub cache, unless a test sets them."""
    monkeypatch.delenv("LITEGS_LPIPS_WEIGHTS", raising=False)
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path / "hub"))


def _images(n: int, h: int, w: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 3, h, w, generator=g)  # [n, 3, H, W]


def test_lpips_loads_shipped_weights_strictly(squeeze_weights):
    loaded = load_lpips("squeeze", squeeze_weights)
    assert loaded is not None
    model, variant = loaded
    assert variant == "squeeze" and not model.training
    assert all(not p.requires_grad for p in model.parameters())
    a, b = _images(2, 32, 40, 0), _images(2, 32, 40, 1)
    assert lpips_distance(model, variant, a[0], a[0]).item() == 0.0  # identical features: exactly zero
    d = lpips_distance(model, variant, a, b)  # [2]
    assert d.shape == (2,) and torch.all(d > 0.01)  # unrelated noise images are far apart
    # The batch gives each image's own distance (float32 convolution rounding).
    torch.testing.assert_close(d[1], lpips_distance(model, variant, a[1], b[1]), rtol=1e-5, atol=1e-6)
    # net=None takes the variant from the weights; another net is a user error naming the fix.
    assert load_lpips(None, squeeze_weights)[1] == "squeeze"
    with pytest.raises(UserError, match="--lpips_net squeeze"):
        load_lpips("alex", squeeze_weights)


def test_lpips_from_hub_cache_equals_full_state_dict(squeeze_weights, tmp_path, caplog):
    """A torchvision SqueezeNet file in the hub cache plus the package's linear layers = the full state dict."""
    state = torch.load(squeeze_weights, weights_only=True)
    # The shipped dict's backbone equals torchvision's squeezenet1_1 ImageNet weights; write it as torchvision names it.
    backbone = {k.replace("net.", "", 1).split(".", 1)[1]: v for k, v in state.items() if k.startswith("net.")}
    backbone = {f"features.{k}": v for k, v in backbone.items()}
    with caplog.at_level(logging.WARNING):
        assert load_lpips("squeeze") is None  # empty cache
    assert len(caplog.records) == 1 and "LPIPS unavailable" in caplog.text and "hub cache" in caplog.text
    cache = tmp_path / "hub" / "checkpoints"
    cache.mkdir(parents=True)
    torch.save(backbone, cache / "squeezenet1_1-b8a52dc0.pth")
    hub_model, variant = load_lpips(None)
    full_model, _ = load_lpips("squeeze", squeeze_weights)
    a, b = _images(1, 24, 24, 2), _images(1, 24, 24, 3)
    assert variant == "squeeze"
    # Same weights, same network: equal up to float32 rounding (the package's lin layers equal the shipped ones).
    torch.testing.assert_close(lpips_distance(hub_model, variant, a, b), lpips_distance(full_model, variant, a, b),
                               rtol=1e-6, atol=1e-7)


def test_lpips_unavailable_and_bad_inputs(tmp_path, caplog):
    torch.save({"weight": torch.zeros(3)}, tmp_path / "other.pt")
    (tmp_path / "junk.pt").write_text("not a checkpoint")
    for path in (tmp_path / "missing.pt", tmp_path / "other.pt", tmp_path / "junk.pt"):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            assert load_lpips("squeeze", path) is None
        assert len(caplog.records) == 1 and str(path) in caplog.text and "LPIPS unavailable" in caplog.text
    with pytest.raises(UserError, match="unknown LPIPS network"):
        load_lpips("resnet")


@pytest.mark.parametrize("net", VARIANTS)
def test_variant_inference_and_min_side(net):
    model = _build(net)
    assert infer_variant(model.state_dict()) == net
    side = LPIPS_MIN_SIDE[net]
    with torch.no_grad():
        model(torch.zeros(1, 3, side, 40), torch.zeros(1, 3, side, 40))  # the smallest side works
        with pytest.raises(RuntimeError):
            model(torch.zeros(1, 3, side - 1, 40), torch.zeros(1, 3, side - 1, 40))  # one less does not
    assert lpips_distance(model, net, torch.zeros(3, side - 1, 40), torch.zeros(3, side - 1, 40)) is None


def _write_png(path: Path, image: torch.Tensor) -> np.ndarray:
    """Write [3, H, W] in [0, 1] as 8-bit RGB; returns the stored values as float64 [H, W, 3] in [0, 1]."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arr = (image.permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)
    Image.fromarray(arr).save(path)
    return arr.astype(np.float64) / 255


def _model_dir(root: Path, methods: dict[str, int], size=(24, 20), seed=0) -> dict:
    """A model directory with test/ours_N/{renders,gt}/0000k.png; returns {method: {name: (render, gt)}}."""
    h, w = size
    stored = {}
    for i, (method, n) in enumerate(methods.items()):
        gts = _images(n, h, w, seed)
        renders = (gts + 0.05 * (i + 1) * torch.randn(n, 3, h, w, generator=torch.Generator().manual_seed(7))).clamp(0, 1)
        stored[method] = {}
        for k in range(n):
            name = f"{k:05d}.png"
            r = _write_png(root / "test" / method / "renders" / name, renders[k])
            g = _write_png(root / "test" / method / "gt" / name, gts[k])
            stored[method][name] = (r, g)
    return stored


def test_metrics_end_to_end(squeeze_weights, tmp_path, capsys):
    model = tmp_path / "runs" / "scene_a"
    stored = _model_dir(model, {"ours_30": 2, "ours_7": 3})
    (tmp_path / "runs" / "empty" / "test").mkdir(parents=True)  # a run without renders is skipped
    metrics.main(["-m", str(tmp_path / "runs"), "--lpips_weights", str(squeeze_weights), "-q"])
    results = json.loads((model / "results.json").read_text())
    per_view = json.loads((model / "per_view.json").read_text())
    assert list(results) == ["ours_7", "ours_30"] == list(per_view)  # by iteration, not by string
    lp_model, _ = load_lpips("squeeze", squeeze_weights)
    for method, views in stored.items():
        assert set(per_view[method]) == {"SSIM", "PSNR", "LPIPS"} and list(per_view[method]["PSNR"]) == list(views)
        for name, (r, g) in views.items():
            mse = np.mean((r - g) ** 2)  # float64 from the stored 8-bit values
            # PSNR from float32 images: relative rounding of the MSE ~1e-6 -> ~1e-5 dB.
            assert abs(per_view[method]["PSNR"][name] - 10 * math.log10(1 / mse)) < 1e-4
            rt, gt = (torch.from_numpy(x).permute(2, 0, 1) for x in (r, g))
            # SSIM against float64 evaluation of the (separately tested) formula: float32 rounding.
            assert abs(per_view[method]["SSIM"][name] - ssim(rt, gt).item()) < 1e-6
            expected_lpips = lpips_distance(lp_model, "squeeze", rt.float(), gt.float()).item()
            assert abs(per_view[method]["LPIPS"][name] - expected_lpips) < 1e-6  # same computation, float32
        for metric in ("SSIM", "PSNR", "LPIPS"):
            values = list(per_view[method][metric].values())
            assert abs(results[method][metric] - sum(values) / len(values)) < 1e-12  # float64 mean
        assert results[method]["LPIPS_variant"] == "squeeze" and results[method]["LPIPS"] > 0
    assert results["ours_30"]["PSNR"] > results["ours_7"]["PSNR"]  # ours_7, written second, got twice the noise
    assert not (tmp_path / "runs" / "empty" / "results.json").exists()
    assert not list(model.glob(".*.tmp"))  # atomic writes leave no temporaries
    table = capsys.readouterr().out.splitlines()
    assert table[0].split() == ["model", "method", "views", "PSNR", "SSIM", "LPIPS"]
    row = table[2].split()
    assert row[:3] == [str(model), "ours_7", "3"] and row[-1] == "(squeeze)"
    assert float(row[3]) == pytest.approx(results["ours_7"]["PSNR"], abs=0.005)  # printed with 2 decimals


def test_metrics_without_lpips_weights(tmp_path, caplog):
    _model_dir(tmp_path, {"ours_5": 2})
    with caplog.at_level(logging.WARNING):
        summary = metrics.evaluate([tmp_path], lpips_weights=tmp_path / "missing.pt", quiet=True)
    assert len([r for r in caplog.records if "LPIPS unavailable" in r.getMessage()]) == 1
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["ours_5"]["LPIPS"] is None and results["ours_5"]["LPIPS_variant"] is None
    assert results["ours_5"]["PSNR"] > 0
    per_view = json.loads((tmp_path / "per_view.json").read_text())
    assert per_view["ours_5"]["LPIPS"] == {"00000.png": None, "00001.png": None}
    assert "unavailable" in metrics.format_table(summary)


def test_fresh_clone_uses_shipped_weights_by_default(tmp_path, monkeypatch, caplog):
    # No ../shared, no hub cache (the autouse fixture empties it), no environment variable: the shipped file.
    import tests.conftest
    monkeypatch.setattr(tests.conftest, "SHARED", tmp_path / "no_shared")
    assert default_weights_path() == default_weights_path("squeeze") == SHIPPED_WEIGHTS
    assert default_weights_path("alex") is None  # AlexNet comes from the torch hub cache
    _model_dir(tmp_path, {"ours_5": 2})
    summary = metrics.evaluate([tmp_path], quiet=True)
    result = summary[str(tmp_path)]["ours_5"]
    assert result["LPIPS_variant"] == "squeeze" and result["LPIPS"] > 0
    # --lpips_net alex still looks in the (here empty) torch hub cache instead of refusing the shipped squeeze file.
    with caplog.at_level(logging.WARNING):
        summary = metrics.evaluate([tmp_path], lpips_net="alex", quiet=True)
    assert summary[str(tmp_path)]["ours_5"]["LPIPS"] is None and "alex backbone" in caplog.text


def test_lpips_null_for_images_below_min_side(squeeze_weights, tmp_path, caplog):
    _model_dir(tmp_path, {"ours_5": 1}, size=(12, 30))
    with caplog.at_level(logging.WARNING):
        metrics.evaluate([tmp_path], lpips_weights=squeeze_weights, quiet=True)
    assert json.loads((tmp_path / "results.json").read_text())["ours_5"]["LPIPS"] is None
    assert "under 17 px" in caplog.text


def test_render_gt_mismatches_are_user_errors(tmp_path):
    _model_dir(tmp_path / "a", {"ours_5": 2})
    (tmp_path / "a" / "test" / "ours_5" / "gt" / "00001.png").unlink()
    with pytest.raises(UserError, match="00001.png only in renders/"):
        metrics.evaluate([tmp_path / "a"], lpips_weights=tmp_path / "missing.pt", quiet=True)
    _model_dir(tmp_path / "b", {"ours_5": 1})
    _write_png(tmp_path / "b" / "test" / "ours_5" / "gt" / "00000.png", torch.zeros(3, 24, 21))
    with pytest.raises(UserError, match="20x24 px but gt/00000.png is 21x24"):
        metrics.evaluate([tmp_path / "b"], lpips_weights=tmp_path / "missing.pt", quiet=True)


def test_cli_without_renders_exits_2_with_one_line(tmp_path):
    (tmp_path / "model" / "test" / "ours_5" / "gt").mkdir(parents=True)
    proc = run_cli("metrics.py", "-m", str(tmp_path), timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: no rendered test views") and "ours_N/renders" in lines[0]
    assert "Traceback" not in proc.stderr
