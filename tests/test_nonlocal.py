"""Non-local averaging: exactness, normalisation, KD-tree vs brute force, pair reuse."""

import numpy as np
import pytest

from dolfin_mpm.nonlocal_average import WEIGHTS, NonlocalAverage

#: The weights are refreshed in single precision (see the module's docstring); fields here lie in [0, 1].
ATOL = 1e-6


def brute_force(x, volume, e, r, weight):
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2) / r
    w = WEIGHTS[weight](np.minimum(d, 1.0), np.empty_like(d)) * volume[None, :]
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


def test_weight_functions():
    t = np.array([0.0, 0.5, 0.9, 1.0])  # t = 1: outside the ball
    w = {name: f(t, np.empty_like(t)) for name, f in WEIGHTS.items()}
    assert np.allclose(w["cubic"], [1.0, 0.5, 1.0 + 0.81 * (1.8 - 3.0), 0.0])
    assert np.allclose(w["gaussian"], [1.0, np.exp(-0.625), np.exp(-2.025), 0.0])
    assert np.allclose(w["constant"], [1.0, 1.0, 1.0, 0.0])


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
    # Removed particles (sinks) only drop their pairs; added or reordered ones force a rebuild.
    gone = rng.random(len(x)) < 0.1
    kept.update(x[~gone], volume[~gone], ids[~gone])
    fresh = NonlocalAverage(0.1, "cubic", skin=0.0)
    fresh.update(x[~gone], volume[~gone], ids[~gone])
    assert kept.rebuilds == 2 and np.allclose(kept(e[~gone]), fresh(e[~gone]), rtol=0.0, atol=ATOL)
    kept.update(x[::-1], volume[::-1], ids[::-1])
    assert kept.rebuilds == 3
    kept.update(x, volume, ids)
    assert kept.rebuilds == 4


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
