"""experiments/pick_spacing.py: pick distances to the seed views over the candidates' median, against hand values."""
import pytest
import torch

from experiments.pick_spacing import pick_spacing, spacing_table
from utils.io import write_json


def test_spacing_on_a_line_of_cameras():
    centers = torch.tensor([[float(x), 0.0, 0.0] for x in range(7)], dtype=torch.float64)  # views 0..6 at x = 0..6
    results = {"settings": {"seed_views": [0, 6]},
               "near/seed0": {"picks": [1, 5]}, "near/seed1": {"picks": [3]},  # the first seed's picks count
               "far/seed0": {"picks": [3, 2]}, "none/seed0": {"test_psnr": 1.0}}
    # nearest-seed distances of the candidates 1..5: 1, 2, 3, 2, 1 -> median 2
    spacing = pick_spacing(results, centers)
    assert spacing == {"near": pytest.approx((0.5, 0.5)), "far": pytest.approx((1.0, 1.25))}


def test_table_reads_a_results_file_and_its_dataset(tiny_scene, tmp_path):
    write_json(tmp_path / "results.json", {"settings": {"seed_views": [0, 1]}, "random/seed0": {"picks": [2, 3]}})
    table = spacing_table(tmp_path / "results.json", tiny_scene)
    assert table.splitlines()[0].startswith("| method |") and table.splitlines()[2].startswith("| random | ")
