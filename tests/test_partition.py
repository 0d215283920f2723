"""Cell partitions by weighted recursive coordinate bisection, and their ghost ranks."""

import numpy as np
import pytest

from dolfin_mpm.parallel.partition import bisection, destinations


@pytest.mark.parametrize("nparts", [2, 3, 4, 7])
def test_bisection_gives_parts_of_equal_weight(nparts):
    rng = np.random.default_rng(nparts)
    points = rng.random((4000, 2))
    weight = rng.random(4000)
    part = bisection(points, weight, nparts)
    assert set(np.unique(part)) == set(range(nparts))
    share = np.bincount(part, weights=weight) / weight.sum()
    assert np.abs(share - 1.0 / nparts).max() < 0.01


def test_strips_along_one_axis_keep_columns_whole():
    # Cells of a structured grid: 20 columns of 10, the left half twice as heavy.
    x, y = np.meshgrid(np.arange(20) + 0.5, np.arange(10) + 0.5, indexing="ij")
    points = np.c_[x.ravel(), y.ravel()]
    weight = np.where(points[:, 0] < 10, 2.0, 1.0)
    part = bisection(points, weight, 3, axes=(0,))
    for k in range(2):  # strips from left to right, columns never split
        assert points[part == k, 0].max() < points[part == k + 1, 0].min()
    share = np.bincount(part, weights=weight) / weight.sum()
    assert np.abs(share - 1 / 3).max() <= 2 * 10 / weight.sum()  # within one column


def test_zero_weight_counts_points_and_bad_weight_is_refused():
    points = np.random.default_rng(0).random((100, 3))
    assert np.bincount(bisection(points, np.zeros(100), 4)).tolist() == [25] * 4
    with pytest.raises(ValueError, match="weight"):
        bisection(points, -np.ones(100), 2)


def test_destinations_are_the_owner_then_the_ranks_sharing_a_vertex():
    rng = np.random.default_rng(1)
    cells = np.array([rng.choice(30, 3, replace=False) for _ in range(60)])
    part = rng.integers(0, 4, 60)
    data, offsets = destinations(cells, part)
    assert data.dtype == offsets.dtype == np.int32
    for c in range(len(cells)):
        ranks = data[offsets[c] : offsets[c + 1]]
        near = {part[d] for d in range(len(cells)) if set(cells[d]) & set(cells[c])} - {part[c]}
        assert ranks[0] == part[c] and sorted(ranks[1:]) == sorted(near)
