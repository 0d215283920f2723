"""The non-local laws: their fixed points are what each law states, and bad input is named.

The laws are solved here as the step solves them (both by semismooth Newton), on a cloud of points
with given trial states; the converged increments are then checked against the laws' own
statements, written from the end states alone: the paper's ``d = A u`` with ``u`` the rate of
each end state, the overstress law's ``d = c <A x>`` with the end states' overstress.
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfin_mpm.averaging import NonlocalAverage, NonlocalLaw
from dolfin_mpm.averaging.complementarity import solve_rates
from dolfin_mpm.averaging.nonlocal_average import ball_weight
from dolfin_mpm.averaging.overstress import solve_overstress
from dolfin_mpm.materials import DruckerPragerViscoplastic
from dolfin_mpm.materials.base import Trial

SAND = DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3, N=1.0)
DT = 3e-5


def cloud(seed=0, n=24):
    """A lattice of points with trial states around the cone: a band of overstressed points."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n) + 0.5) / n
    x = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    p = 1e4 * (1.0 + 0.2 * rng.random(len(x)))
    band = np.exp(-(((x[:, 1] - 0.5) / 0.08) ** 2))  # overstress peaks along y = 0.5
    q = SAND.m * p * (0.8 + 0.6 * band + 0.05 * rng.random(len(x)))
    s = np.zeros((3, 3, len(x)))
    s[0, 1] = s[1, 0] = q / np.sqrt(3.0)  # pure shear: q = sqrt(3) |s_xy|
    return x, np.full(len(x), 1.0 / n**2), Trial(p, s, q)


def solve_overstress_law(average, trial, d0=None, tol=1e-9):
    """The overstress law solved as the step solves it; returns the increments and the stats."""
    y = SAND.yield_value(trial)
    c, N = SAND.perzyna(DT)
    f_t = trial.q - y
    f0 = f_t if d0 is None else f_t - 2.0 * SAND.G * d0
    b = 2.0 * SAND.G * c / y
    f, stats = solve_overstress(
        average, average.metric, f_t, b, np.full(len(y), N), y, f0, MPI.COMM_SELF, tol
    )
    return (f_t - f) / (2.0 * SAND.G), stats


def rate_of_end_state(trial, d):
    """``u = c <q / y - 1>`` of the end state ``q = q_trial - 2 G d`` (N = 1), and its overstress."""
    y = SAND.yield_value(trial)
    x = np.maximum(trial.q - 2.0 * SAND.G * d, 0.0) / y - 1.0
    return 1.5 * SAND.gamma * DT * np.maximum(x, 0.0), x


@pytest.mark.parametrize("boundary_correction", [False, True])
def test_paper_law_relaxes_by_the_average_of_the_end_states_rates(boundary_correction):
    x, volume, trial = cloud()
    average = NonlocalAverage(0.1, "wendland", boundary_correction=boundary_correction)
    average.update(x, volume, np.arange(len(x)))
    d, u_solved, stats = solve_rates(
        average, lambda u: SAND.increment_of_rate(trial, u, DT), np.zeros(len(x)), MPI.COMM_SELF, 1e-14
    )
    assert stats["converged"] and stats["newton"] <= 10
    u, _ = rate_of_end_state(trial, d)
    assert np.abs(u - u_solved).max() <= 1e-9 * u.max()
    expected = average(u)
    assert np.abs(d - expected).max() <= 1e-9 * d.max()
    # The law acts: the band's points relax by less than their own rate, the flanks by more.
    assert np.any(u > 1.05 * d) and np.any(d > 1.05 * u)


@pytest.mark.parametrize("radius", [0.1, 0.2])
def test_overstress_law_flows_by_the_averaged_overstress(radius):
    """Solved to 1e-9 Pa: the increments are ``c <A f / y>`` with the end states' overstress
    ``f = q - y``, whether r spans 2.4 or 4.8 spacings, from the trial or from the local return."""
    x, volume, trial = cloud(1)
    average = NonlocalAverage(radius, "wendland")
    average.update(x, volume, np.arange(len(x)))
    y = SAND.yield_value(trial)
    for first in (None, SAND.increment(trial, {}, DT)):
        d, stats = solve_overstress_law(average, trial, first)
        assert stats["converged"] and stats["newton"] <= 12, stats
        f = np.maximum(trial.q - 2.0 * SAND.G * d, 0.0) - y
        expected = 1.5 * SAND.gamma * DT * np.maximum(average(f) / y, 0.0)
        assert np.abs(d - expected).max() <= 1e-9 * d.max()
    # Elastic neighbours hold the band back: less flow than the local return everywhere.
    local = SAND.increment(trial, {}, DT)
    assert d.sum() < local.sum()


def test_max_law_is_not_iterated():
    assert not NonlocalLaw().iterative and NonlocalLaw("paper").iterative


@pytest.mark.parametrize("name", ["nonlocal", "over-nonlocal", "", None])
def test_bad_laws_are_named(name):
    with pytest.raises(ValueError, match="law must be one of"):
        NonlocalLaw(name)
    with pytest.raises(ValueError, match="law must be one of"):
        NonlocalAverage(0.1, law=name)


@pytest.mark.parametrize("weight", ["cubic", "constant", "gaussian"])
def test_iterative_laws_take_the_positive_definite_weight_alone(weight):
    with pytest.raises(ValueError, match="needs the positive-definite weight 'wendland'"):
        NonlocalAverage(0.1, weight, law="paper")


@pytest.mark.parametrize("spacing", [0.5, 0.25])
def test_only_wendlands_average_keeps_alternating_fields_positive(spacing):
    """The least eigenvalue of the average on a lattice of spacing ``spacing`` r: why the laws need it."""
    n = 16
    g = spacing * np.arange(n)
    x = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    least = {}
    for weight in ("cubic", "gaussian", "constant", "wendland"):
        average = NonlocalAverage(1.0, weight)
        average.update(x, np.ones(len(x)), np.arange(len(x)))
        A = np.column_stack([average(e) for e in np.eye(len(x))])
        least[weight] = np.linalg.eigvals(A).real.min()
    assert least["wendland"] > 0.0
    assert all(least[w] < 0.0 for w in ("cubic", "gaussian", "constant")), least


def test_bad_boundary_correction_is_named():
    with pytest.raises(ValueError, match="boundary_correction"):
        NonlocalAverage(0.1, boundary_correction="yes")


@pytest.mark.parametrize("weight", ["cubic", "constant", "gaussian", "wendland"])
def test_boundary_correction_gives_the_missing_weight_to_the_point_itself(weight):
    n = 60
    g = (np.arange(n) + 0.5) / n
    x = np.array(np.meshgrid(g, g, indexing="ij")).reshape(2, -1).T
    volume = np.full(len(x), 1.0 / n**2)
    r = 0.1
    plain, corrected = NonlocalAverage(r, weight), NonlocalAverage(r, weight, boundary_correction=True)
    for a in (plain, corrected):
        a.update(x, volume, np.arange(len(x)))
    # The ball's weight: the lattice's sums about an interior point come within 2 % of it.
    centre = np.argmin(np.linalg.norm(x - 0.5, axis=1))
    assert abs(plain.denominator[centre] / ball_weight(weight, r, 2) - 1.0) < 0.02
    # A constant stays constant; a field that is 1 at a corner point only is averaged into
    # that corner with the weight its missing three quarters of a ball give it.
    assert np.allclose(corrected(np.ones(len(x))), 1.0)
    corner = np.argmin(np.linalg.norm(x, axis=1))
    e = np.zeros(len(x))
    e[corner] = 1.0
    own_share_plain, own_share = plain(e)[corner], corrected(e)[corner]
    assert own_share > 3.0 * own_share_plain
    missing = 1.0 - plain.denominator[corner] / ball_weight(weight, r, 2)
    assert own_share == pytest.approx(missing + own_share_plain * (1.0 - missing), rel=1e-12)


def mix_bound(average) -> float:
    """The largest admissible factor of the over-non-local mix, ``1 / (1 - min A_ii)``."""
    return 1.0 / (1.0 - average.own_weight.min())


def test_overnonlocal_mix_relaxes_by_its_mix_of_the_end_states_rates():
    """Solved to 1e-14: ``d = m A u + (1 - m) u`` with ``u`` the rate of each end state, ``d >= 0``."""
    x, volume, trial = cloud(2)
    average = NonlocalAverage(0.1, "wendland")
    average.update(x, volume, np.arange(len(x)))
    bound = mix_bound(average)  # r spans 2.4 spacings: A_ii >= 0.38
    assert 1.5 < bound < 1.7
    rates = lambda u: SAND.increment_of_rate(trial, u, DT)  # noqa: E731
    solved = {}
    for m in (None, 0.5 * (1.0 + bound)):  # None: the paper's law
        law = NonlocalLaw("paper") if m is None else NonlocalLaw("overnonlocal", m)
        d, u_solved, stats = solve_rates(law.applied(average), rates, np.zeros(len(x)), MPI.COMM_SELF, 1e-14)
        assert stats["converged"] and stats["newton"] <= 12, stats
        u, _ = rate_of_end_state(trial, d)
        assert np.abs(u - u_solved).max() <= 1e-9 * u.max()
        expected = average(u) if m is None else m * average(u) + (1.0 - m) * u
        assert np.abs(d - expected).max() <= 1e-9 * d.max()
        assert d.min() >= 0.0
        if m is not None:
            assert law.own_weights(average).min() > 0.0
        solved[m] = u
    # Over-non-local: the band's core flows faster than with the paper's law, its rate less spread.
    paper, mix = solved.values()
    assert mix.max() > 1.02 * paper.max()


def test_overnonlocal_mix_beyond_its_bound_has_a_point_whose_own_rate_lowers_its_increment():
    """Where ``m A_ii + 1 - m < 0`` a point's row of ``B u - delta(u)`` falls as its rate grows."""
    x, volume, trial = cloud(2)
    average = NonlocalAverage(0.2, "wendland")  # r spans 4.8 spacings: A_ii ~ 0.1 inside
    average.update(x, volume, np.arange(len(x)))
    law = NonlocalLaw("overnonlocal", 2.0)
    assert mix_bound(average) < 1.15 and law.own_weights(average).max() < 0.0
    B = law.applied(average)
    i = int(np.argmax(trial.q / SAND.yield_value(trial)))  # the most overstressed point
    u = np.zeros(len(x))
    rows = []
    for u_i in (0.0, 1e-4, 2e-4):
        u[i] = u_i
        delta, _ = SAND.increment_of_rate(trial, u, DT)
        rows.append((B(u) - delta)[i])
    assert rows[0] < 0.0 and rows[2] < rows[1] < rows[0]  # r_i(0) < 0 and falling: no u_i solves it


@pytest.mark.parametrize(
    "law, m, message",
    [
        ("overnonlocal", None, "needs its factor m"),
        ("overnonlocal", 1.0, r"m must be in \(1, inf\)"),
        ("overnonlocal", 0.5, r"m must be in \(1, inf\)"),
        ("overnonlocal", float("nan"), r"m must be in \(1, inf\)"),
        ("overnonlocal", float("inf"), r"m must be in \(1, inf\)"),
        ("overnonlocal", True, "m must be a number"),
        ("overnonlocal", "2", "m must be a number"),
        ("overnonlocal", np.array([2.0, 3.0]), "m must be a number"),
        ("paper", 2.0, "m is the factor of law 'overnonlocal'"),
        ("max", 1.5, "m is the factor of law 'overnonlocal'"),
    ],
)
def test_bad_mix_factors_are_named(law, m, message):
    with pytest.raises(ValueError, match=message):
        NonlocalLaw(law, m)


def test_mix_factor_is_kept_as_a_float():
    law = NonlocalLaw("overnonlocal", np.float32(1.25))
    assert type(law.m) is float and law.m == 1.25 and hash(law) == hash(NonlocalLaw("overnonlocal", 1.25))
