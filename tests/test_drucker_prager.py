"""Material-point drivers for the elastic–viscoplastic Drucker–Prager model (no grid)."""

import numpy as np
import pytest

from dolfin_mpm.materials import DruckerPragerViscoplastic, LinearElastic
from dolfin_mpm.materials.tensor import invariants

PAPER = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3}
P0 = 2000.0  # initial isotropic pressure [Pa]


def drive(mat, L, dt, duration, sigma0=None):
    """Constant velocity gradient L (2x2) for `duration`; returns stress history and state."""
    Lp = np.asarray(L, float)[None]
    sigma = -P0 * np.eye(3)[None] if sigma0 is None else sigma0
    state = {k: np.zeros(1) for k in mat.state_fields()}
    history = []
    for _ in range(round(duration / dt)):
        sigma = mat.update(sigma, Lp, dt, state)
        history.append(sigma[0].copy())
    return np.array(history), state


def steady_q(mat, e_eq):
    return mat.m * P0 * (1.0 + ((2.0 / 3.0) * e_eq / mat.gamma) ** (1.0 / mat.N))


def test_m_and_relaxation_time():
    mat = DruckerPragerViscoplastic(**PAPER)
    s = np.sin(np.radians(30.0))
    assert mat.m == pytest.approx(18 * s / (9 - s * s))
    t_relax = mat.m * P0 / (3 * mat.G * mat.gamma)
    assert 1e-6 < t_relax < 3e-6  # the issue's ~1e-6 s, far below an explicit step ~1e-5 s


def test_purely_elastic_below_yield():
    dp = DruckerPragerViscoplastic(**PAPER)
    el = LinearElastic(PAPER["E"], PAPER["nu"], PAPER["rho"])
    L = [[-1e-3, 0.02], [0.0, 0.0]]
    s_dp, state = drive(dp, L, 1e-5, 0.02)
    s_el, _ = drive(el, L, 1e-5, 0.02)
    _, q = invariants(s_dp)
    assert q.max() < dp.m * P0  # stayed elastic
    assert np.allclose(s_dp, s_el, rtol=1e-12, atol=1e-9)
    assert np.all(state["eps_vp"] == 0.0)


@pytest.mark.parametrize("N", [1.0, 0.5, 2.0])
@pytest.mark.parametrize("dt", [1e-6, 1e-5, 1e-4])
def test_simple_shear_steady_state(N, dt):
    mat = DruckerPragerViscoplastic(**PAPER, N=N)
    rate = 10.0  # engineering shear rate [1/s]
    history, state = drive(mat, [[0.0, rate], [0.0, 0.0]], dt, 0.003)
    p, q = invariants(history)
    e_eq = np.sqrt(3.0 / 4.0) * rate  # sqrt(3/2 e:e) of simple shear
    assert q[-1] == pytest.approx(steady_q(mat, e_eq), rel=0.005)
    assert np.allclose(p, P0, rtol=1e-12)  # plastic flow is isochoric
    assert state["eps_vp_rate"][0] == pytest.approx(e_eq, rel=0.005)
    assert np.all(np.isfinite(history))


def test_large_steps_are_stable_where_explicit_perzyna_is_not():
    mat = DruckerPragerViscoplastic(**PAPER)
    t_relax = mat.m * P0 / (3 * mat.G * mat.gamma)
    rate, e_eq = 10.0, np.sqrt(3.0 / 4.0) * 10.0
    for factor in (10, 100, 1000):
        dt = factor * t_relax
        history, _ = drive(mat, [[0.0, rate], [0.0, 0.0]], dt, 0.003)
        _, q = invariants(history)
        assert q[-1] == pytest.approx(steady_q(mat, e_eq), rel=0.005)
        assert np.all(q >= 0.0)
    # The forward-Euler Perzyna update, q' = 3G (2/3 e_eq - gamma Phi(q)), at dt = 100 t_relax
    # overshoots far past the yield surface to a negative q and never settles.
    dt, q, history = 100 * t_relax, mat.m * P0, []
    for _ in range(200):
        q = q + dt * 3 * mat.G * ((2 / 3) * e_eq - mat.gamma * max(q - mat.m * P0, 0.0) / (mat.m * P0))
        history.append(q)
    assert min(history) < 0.0
    assert max(abs(np.array(history[-50:]) / steady_q(mat, e_eq) - 1)) > 0.1


def test_q_never_exceeds_trial_nor_changes_sign():
    mat = DruckerPragerViscoplastic(**PAPER, N=0.7)
    rng = np.random.default_rng(0)
    n = 2000
    sigma = rng.normal(scale=3000.0, size=(n, 3, 3))
    sigma = 0.5 * (sigma + np.swapaxes(sigma, 1, 2))
    L = rng.normal(scale=5.0, size=(n, 2, 2))
    trial = mat.trial(sigma, L, 1e-4)
    de = mat.increment(trial, {}, 1e-4)
    assert np.all(de >= 0.0)
    p, q = invariants(mat.stress(trial, de))
    assert np.all(q <= trial.q * (1 + 1e-12)) and np.all(q >= 0.0)
    assert np.all(p >= 0.0)  # no tension
    # Non-local increments of any size keep q in [0, q_trial].
    _, q = invariants(mat.stress(trial, rng.random(n)))
    assert np.all(q >= 0.0) and np.all(q <= trial.q * (1 + 1e-12))


def test_tension_gives_stress_free_state_without_nan():
    mat = DruckerPragerViscoplastic(**PAPER)
    # Stress-free grains in free fall (d = 0), and a point pulled apart (d_kk > 0).
    history, state = drive(mat, [[0.0, 0.0], [0.0, 0.0]], 1e-5, 1e-3, sigma0=np.zeros((1, 3, 3)))
    assert np.all(history == 0.0)
    history, state = drive(mat, [[5.0, 1.0], [0.0, 5.0]], 1e-5, 1e-2)
    assert np.all(np.isfinite(history)) and np.all(history[-1] == 0.0)
    assert np.isfinite(state["eps_vp"][0])


@pytest.mark.parametrize(
    "kwargs, name",
    [({"phi": 0.0}, "phi"), ({"phi": 90.0}, "phi"), ({"gamma": 0.0}, "gamma"), ({"N": 0.0}, "N"),
     ({"N": -1.0}, "N"), ({"E": -1.0}, "E"), ({"nu": 0.6}, "nu"), ({"c": -1.0}, "c"),
     ({"gamma": np.nan}, "gamma")],
)  # fmt: skip
def test_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} must be in"):
        DruckerPragerViscoplastic(**(PAPER | kwargs))
