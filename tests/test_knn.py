"""Exact kNN: the curve-sorted, box-filtered path against the all-pairs twin."""
import pytest
import torch

from utils.knn import (knn_sq_distances, knn_sq_distances_reference, mean_sq_dist_to_neighbours, morton_order,
                       random_point_cloud)


def _clouds():
    g = torch.Generator().manual_seed(0)
    uniform = torch.rand(3000, 3, generator=g)
    clustered = torch.cat([torch.randn(2000, 3, generator=g) * 0.01 + 50.0,  # tight cluster far from the origin
                           torch.randn(5, 3, generator=g) * 1e3])  # far outliers stretch the bounding box
    flat = torch.cat([torch.rand(1500, 2, generator=g), torch.zeros(1500, 1)], dim=1)  # a plane: ties in z
    dupes = torch.rand(700, 3, generator=g).repeat(2, 1)  # every point twice: zero nearest distance
    return {"uniform": uniform, "clustered": clustered, "flat": flat, "dupes": dupes}


@pytest.mark.parametrize("name", ["uniform", "clustered", "flat", "dupes"])
@pytest.mark.parametrize("k", [1, 3, 8])
def test_knn_matches_all_pairs(name, k):
    points = _clouds()[name].double()
    # small blocks and max_pairs force many superblocks, blocks and row sub-chunks
    fast = knn_sq_distances(points, k, block=64, superblock=512, max_pairs=5000)
    # same float64 differences on both sides; only the selection could differ, so equality is exact
    assert torch.equal(fast, knn_sq_distances_reference(points, k))


def test_knn_small_clouds_and_mean():
    points = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    # closed form: point 0's neighbours at squared distances 1, 4, 9
    assert torch.equal(knn_sq_distances(points, 3)[0], torch.tensor([1.0, 4.0, 9.0]))
    assert mean_sq_dist_to_neighbours(points, k=3)[0].item() == pytest.approx(14 / 3)
    assert mean_sq_dist_to_neighbours(points[:2], k=3).tolist() == [1.0, 1.0]  # only one neighbour each
    assert mean_sq_dist_to_neighbours(points[:1]).tolist() == [1.0]  # no neighbour: unit size


def test_morton_order_is_permutation_and_local():
    points = torch.rand(4096, 3, generator=torch.Generator().manual_seed(1))
    order = morton_order(points)
    assert torch.equal(order.sort().values, torch.arange(4096))
    step = (points[order][1:] - points[order][:-1]).norm(dim=1).median()
    random_step = (points[1:] - points[:-1]).norm(dim=1).median()
    assert step < 0.2 * random_step  # curve neighbours are spatial neighbours (about 0.06 vs 0.66 here)


def test_random_point_cloud_bounds_and_seed():
    pts, cols = random_point_cloud(500, 2.5, torch.Generator().manual_seed(3))
    again, _ = random_point_cloud(500, 2.5, torch.Generator().manual_seed(3))
    assert torch.equal(pts, again)
    assert pts.shape == (500, 3) and cols.shape == (500, 3)
    assert pts.abs().max() <= 2.5 and pts.abs().max() > 2.4  # fills the cube
    assert cols.min() >= 0 and cols.max() <= 1
