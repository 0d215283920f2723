"""Non-local averaging: exactness, normalisation, KD-tree vs brute force, pair reuse."""

import numpy as np
import pytest

from dolfin_mpm.averaging.nonlocal_average import WEIGHTS, NonlocalAverage, _search

#: Weights in double precision from the positions; fields here lie in [0, 1].
ATOL = 1e-12

#: The paper's weights of s = distance / r, inside the ball.
PAPER_WEIGHTS = {
    "cubic": lambda s: 1.0 + s**2 * (2.0 * s - 3.0),
    "constant": lambda s: np.ones_like(s),
    "gaussian": lambda s: np.exp(-2.5 * s**2),
    "wendland": lambda s: (1.0 - s) ** 4 * (1.0 + 4.0 * s),
}


def brute_force(x, volume, e, r, weight):
    s = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2) / r
    w = np.where(s < 1.0, PAPER_WEIGHTS[weight](s), 0.0) * volume[None, :]
    return (w @ e) / w.sum(axis=1)


def cloud(n, dim, seed=0):
    rng = np.random.default_rng(seed)
    return rng.random((n, dim)), 0.5 + rng.random(n), rng.random(n)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("weight", sorted(WEIGHTS))
def test_kdtree_equals_brute_force(dim, weight):
    x, volume, e = cloud(400, dim)
    avg = NonlocalAverage(0.15, weight)
    avg.update(x, volume, np.arange(len(x)))
    assert np.allclose(avg(e), brute_force(x, volume, e, 0.15, weight), rtol=0.0, atol=ATOL)
    # The neighbourhood is exact: the average of particle k's indicator is non-zero within r.
    k = 7
    near = np.linalg.norm(x - x[k], axis=1) < 0.15
    assert np.array_equal(avg(np.eye(len(x))[k]) > 0.0, near)


@pytest.mark.parametrize("weight", sorted(WEIGHTS))
def test_uniform_field_and_normalisation(weight):
    x, volume, _ = cloud(300, 2, seed=1)
    avg = NonlocalAverage(0.2, weight)
    avg.update(x, volume, np.arange(len(x)))
    assert np.allclose(avg(np.full(len(x), 3.7)), 3.7, rtol=1e-14)
    # Weights are normalised: the average of a field lies within its neighbourhood's range.
    e = np.random.default_rng(2).random(len(x))
    a = avg(e)
    assert np.all(a >= e.min() - 1e-15) and np.all(a <= e.max() + 1e-15)


@pytest.mark.parametrize("boundary_correction", [False, True])
def test_the_average_is_self_adjoint_in_its_metric(boundary_correction):
    """What the overstress law's solver needs: ``G A`` symmetric."""
    x, volume, _ = cloud(120, 2, seed=3)
    avg = NonlocalAverage(0.2, "wendland", boundary_correction=boundary_correction)
    avg.update(x, volume, np.arange(len(x)))
    A = np.column_stack([avg(column) for column in np.eye(len(x))])
    GA = avg.metric[:, None] * A
    assert np.allclose(GA, GA.T, rtol=0.0, atol=1e-13 * np.abs(GA).max())


def test_weight_functions():
    """Two particles of equal volume at s = distance / r: the first's average of (1, 0) is 1 / (1 + w(s))."""
    w = {}
    for name in WEIGHTS:
        avg = NonlocalAverage(1.0, name)
        w[name] = []
        for s in (0.0, 0.5, 0.9, 1.0, 1.1):  # s >= 1: outside the ball
            avg.update(np.array([[0.0, 0.0], [s, 0.0]]), np.ones(2), np.arange(2) + 10 * len(w[name]))
            w[name].append(1.0 / avg(np.array([1.0, 0.0]))[0] - 1.0)
    assert np.allclose(w["cubic"], [1.0, 0.5, 1.0 + 0.81 * (1.8 - 3.0), 0.0, 0.0], rtol=0.0, atol=1e-15)
    assert np.allclose(w["gaussian"], [1.0, np.exp(-0.625), np.exp(-2.025), 0.0, 0.0], rtol=0.0, atol=1e-15)
    assert np.allclose(w["constant"], [1.0, 1.0, 1.0, 0.0, 0.0], rtol=0.0, atol=1e-15)


@pytest.mark.parametrize(
    "x",
    [
        np.random.default_rng(7).random((600, 2)),
        np.random.default_rng(8).random((600, 3)),
        np.random.default_rng(9).random((300, 3)) * [100.0, 1.0, 0.01],  # sparse: cubes grow
        np.c_[np.repeat(np.linspace(0.0, 1.0, 50), 3), np.zeros((150, 2))],  # on a line, repeated
        np.zeros((1, 2)),
    ],
    ids=["2d", "3d", "sparse", "line", "one"],
)
def test_pair_search_finds_each_close_pair_once(x):
    reach = 0.08
    found = _search(x, reach, capacity=1)  # too little room: the search runs again
    i, j = found.expand().T
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    expected = np.argwhere(np.triu(d2 <= reach**2, k=1))
    assert np.all(i < j) and np.all(np.diff(found.row) > 0)  # each pair once, runs in order
    assert np.array_equal(np.unique(np.c_[i, j], axis=0), expected) and len(i) == len(expected)


def test_skin_reuse_equals_fresh_rebuild():
    x, volume, e = cloud(500, 2, seed=3)
    ids = np.arange(len(x))
    kept = NonlocalAverage(0.1, "cubic", skin=0.04)
    kept.update(x, volume, ids)
    rng = np.random.default_rng(4)
    for _ in range(5):
        x = x + rng.uniform(-0.003, 0.003, x.shape)  # below half the skin in total
        kept.update(x, volume, ids)
        fresh = NonlocalAverage(0.1, "cubic", skin=0.0)
        fresh.update(x, volume, ids)
        assert np.allclose(kept(e), fresh(e), rtol=0.0, atol=ATOL)
    assert kept.rebuilds == 1
    x = x + 0.05  # a large move forces a rebuild
    kept.update(x, volume, ids)
    assert kept.rebuilds == 2
    # Removed, reordered and arrived particles keep the pair list: no rebuild, same averages.
    gone = rng.random(len(x)) < 0.1
    for select in (~gone, np.flatnonzero(~gone)[::-1], rng.permutation(len(x))):
        kept.update(x[select], volume[select], ids[select])
        fresh = NonlocalAverage(0.1, "cubic", skin=0.0)
        fresh.update(x[select], volume[select], ids[select])
        assert np.allclose(kept(e[select]), fresh(e[select]), rtol=0.0, atol=ATOL)
    assert kept.rebuilds == 2
    # Once particles have arrived, pairs found at different times: the rebuild comes at a
    # third of the skin (0.0133 here), not at half of it.
    x[:, 0] += 0.015
    kept.update(x, volume, ids)
    assert kept.rebuilds == 3
    x[:, 0] += 0.015
    kept.update(x, volume, ids)
    assert kept.rebuilds == 3


def test_more_pairs_closer_than_r_than_there_was_room_for():
    """A lattice whose neighbours all lie in the skin until its columns pair up, within half the skin."""
    i, j = np.meshgrid(np.arange(30), np.arange(30), indexing="ij")
    x = 0.105 * np.c_[i.ravel(), j.ravel()].astype(float)  # no pair within r = 0.1
    volume, e = np.ones(len(x)), np.random.default_rng(6).random(len(x))
    ids = np.arange(len(x))
    kept = NonlocalAverage(0.1, "cubic", skin=0.04)
    kept.update(x, volume, ids)
    kept.update(x, volume, ids, rebuild=True)  # rebuilt pairs get room for as many within r as before
    room = len(kept._within.j)
    x[:, 0] += np.where(i.ravel() % 2 == 0, 0.009, -0.009)  # columns 2k and 2k + 1 now 0.087 apart
    kept.update(x, volume, ids)
    assert kept.rebuilds == 2 and kept._within_count >= 30 * 15 > room
    assert np.allclose(kept(e), brute_force(x, volume, e, 0.1, "cubic"), rtol=0.0, atol=ATOL)


def test_arrivals_in_small_batches_equal_a_fresh_rebuild():
    """As under MPI: particles come and go each step while all move; 3D, every weight."""
    rng = np.random.default_rng(5)
    x, volume, e = cloud(800, 3, seed=6)
    ids = np.arange(len(x))
    for weight in WEIGHTS:
        kept = NonlocalAverage(0.2, weight, skin=0.06)
        present = rng.random(len(x)) < 0.7
        for _ in range(6):
            x = x + rng.uniform(-0.001, 0.001, x.shape)  # within a third of the skin in all
            present ^= rng.random(len(x)) < 0.03  # some leave, some (back) in
            select = rng.permutation(np.flatnonzero(present))
            kept.update(x[select], volume[select], ids[select])
            fresh = NonlocalAverage(0.2, weight, skin=0.0)
            fresh.update(x[select], volume[select], ids[select])
            assert np.allclose(kept(e[select]), fresh(e[select]), rtol=0.0, atol=ATOL)
        assert kept.rebuilds == 1


def test_local_switch_and_bad_input():
    avg = NonlocalAverage(0.0)
    e = np.arange(5.0)
    avg.update(np.zeros((5, 2)), np.ones(5), np.arange(5))
    assert avg(e) is e
    with pytest.raises(ValueError, match=r"^radius must be"):
        NonlocalAverage(-1.0)
    with pytest.raises(ValueError, match=r"^weight must be one of"):
        NonlocalAverage(0.1, "triangular")
    with pytest.raises(ValueError, match=r"^skin must be"):
        NonlocalAverage(0.1, skin=-0.1)
