"""experiments.gain_diagnosis: the breakdown fractions sum to 1 and equal brute-force sums of the oracle's terms."""
import math

import torch

from active.fisher import FisherOracle
from active.gain_weights import area_weights
from experiments.gain_diagnosis import diagnose, gaussian_groups, per_gaussian_gains
from gaussian_renderer import RasterSettings
from scene.cameras import Camera
from scene.gaussian_model import GaussianModel
from tests.scenes import intrinsics_for, look_at_viewmat, random_gaussians

W, H = 16, 16
BG = torch.zeros(3, dtype=torch.float64)


def tiny():
    p = random_gaussians(12, seed=1, sh_degree=0, scale=0.2)
    p["means"][-2:] = torch.tensor([[3.0, 0.0, 0.0], [0.0, -3.0, 0.2]], dtype=torch.float64)  # far ones
    model = GaussianModel(0, {"means": p["means"], "quats": p["quats"], "log_scales": p["log_scales"],
                              "logit_opacities": p["logit_opacities"], "sh_dc": p["sh_coeffs"][:, :1],
                              "sh_rest": p["sh_coeffs"][:, 1:]})
    k = intrinsics_for(W, H, 55.0)
    cams = [Camera(i, f"v{i}", look_at_viewmat((4 * math.cos(a), 4 * math.sin(a), 1.2)), *k.tolist(), W, H)
            for i, a in enumerate(2 * math.pi * i / 6 for i in range(6))]
    return model, cams


def test_fractions_sum_to_one_and_match_brute_force():
    model, cams = tiny()
    settings = RasterSettings(tile_size=8, chunk_size=4, backend="torch")
    d = diagnose(model, cams, [0], [1, 2, 3, 4, 5], BG, settings, top=3)
    oracle = FisherOracle.build(model, cams, [0], BG, settings)
    for row in d["candidates"]:
        terms = per_gaussian_gains(oracle, row["id"])
        assert math.isclose(row["gain"], oracle.gain(row["id"]), rel_tol=1e-9)
        assert math.isclose(float(terms.sum()), row["gain"], rel_tol=1e-9)
        for key in ("prior", "opacity", "frustum", "distance", "spacing"):
            assert math.isclose(sum(row[key].values()), 1.0, rel_tol=1e-9, abs_tol=1e-12), (key, row[key])
        groups = gaussian_groups(model, cams, [0], torch.ones(12, dtype=torch.bool))
        for key in ("opacity", "frustum", "distance", "spacing"):
            for b, mask in groups[key].items():  # brute force: loop over Gaussians
                brute = sum(float(terms[i]) for i in range(12) if bool(mask[i]))
                assert math.isclose(row[key][b], brute / row["gain"], rel_tol=1e-9, abs_tol=1e-12)
    assert d["spread"]["max"] == d["candidates"][0]["gain"]
    assert set(d["rank_correlation"]) == {"logdet_vs_opacity", "logdet_vs_area", "logdet_vs_cover", "opacity_vs_cover",
                                          "logdet_vs_variance", "logdet_vs_per_visible"}
    rows = d["candidates"]  # the count check: a candidate's gain per Gaussian it sees, ranked against its gain
    per_visible = [r["gain"] / r["visible"] for r in rows]
    rank = lambda xs: torch.tensor(xs).argsort().argsort().double()
    expected = torch.corrcoef(torch.stack([rank([r["gain"] for r in rows]), rank(per_visible)]))[0, 1]
    assert math.isclose(d["rank_correlation"]["logdet_vs_per_visible"], float(expected), rel_tol=1e-9)
    visible = [r["visible"] for r in rows]
    assert d["visible_share"] == {"min": min(visible) / 12, "max": max(visible) / 12}
    area = area_weights(model.means)
    for row in d["candidates"]:  # the area-weighted gain: each Gaussian's term times its area share
        terms = per_gaussian_gains(oracle, row["id"])
        assert math.isclose(row["gain_area"], sum(float(terms[i] * area[i]) for i in range(12)), rel_tol=1e-9)
    variance = FisherOracle.build_render_variance(model, cams, [0], BG, settings)
    for row in d["candidates"]:  # the render-variance breakdown: the oracle's gain, shares summing to one
        assert math.isclose(row["gain_variance"], variance.gain(row["id"]), rel_tol=1e-9)
        for key in ("prior", "opacity", "frustum", "distance", "spacing"):
            assert math.isclose(sum(row["variance"][key].values()), 1.0, rel_tol=1e-9, abs_tol=1e-12)


def test_cli_missing_model_is_one_error_line(tmp_path):
    """scripts/diagnose_gain.py with a model that does not exist: one `error:` line, exit 2, no traceback."""
    from tests.conftest import run_cli
    r = run_cli("scripts/diagnose_gain.py", "-m", str(tmp_path / "nothing"), "--candidates", "orbit:4", "-o",
                str(tmp_path / "out"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [f"error: model {tmp_path / 'nothing'} does not exist: pass a train.py "
                                             "model directory or a 3DGS .ply file"]
    assert not (tmp_path / "out").exists()
