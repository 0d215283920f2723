"""The return mappings the MPM and the FE solver share: yield conditions and consistent tangents."""

import numpy as np
import pytest

from dolfin_mpm.materials import DruckerPragerViscoplastic, VonMises
from dolfin_mpm.materials.tensor import from_mandel, invariants, to_mandel

ELASTIC = {"E": 10e6, "nu": 0.3, "rho": 2000.0}
RNG = np.random.default_rng(7)


def states(n=200, p_mean=40e3, spread=20e3):
    """Random stresses around a compressive mean and random strain increments (Mandel)."""
    sigma = from_mandel(RNG.normal(0.0, spread, (n, 6)))
    sigma -= p_mean * np.eye(3)
    deps = RNG.normal(0.0, 2e-3, (n, 6))
    return sigma, deps


def return_map(mat, sigma, deps, eps_p):
    """Stress after one implicit small-strain step and the increment of the return."""
    trial = mat.trial(sigma, from_mandel(deps), 1.0)
    inc = mat.increment(trial, {"eps_p": eps_p}, 1.0)
    return trial, inc, mat.stress(trial, inc)


MATERIALS = {
    "von Mises, perfect": VonMises(**ELASTIC, sigma_y=60e3),
    "von Mises, hardening": VonMises(**ELASTIC, sigma_y=60e3, H=2e6),
    "DP rate-independent": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=np.inf),
    "DP rate-independent, cohesive": DruckerPragerViscoplastic(**ELASTIC, phi=25.0, gamma=np.inf, c=10e3),
    "DP Perzyna N=1": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=0.05),
    "DP Perzyna N=2.5": DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=0.05, N=2.5),
}


@pytest.mark.parametrize("name", MATERIALS)
def test_consistent_tangent_matches_finite_differences(name):
    mat = MATERIALS[name]
    sigma, deps = states()
    eps_p = RNG.uniform(0.0, 0.02, len(sigma))
    trial, inc, _ = return_map(mat, sigma, deps, eps_p)
    D = mat.tangent(trial, inc, 1.0)
    assert 0.2 < np.mean(inc > 0) < 0.95, "the sample must mix elastic and plastic points"
    h = 1e-9
    D_fd = np.empty_like(D)
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        plus = to_mandel(return_map(mat, sigma, deps + e, eps_p)[2])
        minus = to_mandel(return_map(mat, sigma, deps - e, eps_p)[2])
        D_fd[:, :, k] = (plus - minus) / (2 * h)
    scale = 3 * mat.K + 2 * mat.G
    # Points within the finite-difference step of the yield surface have a one-sided tangent.
    trial_plus = return_map(mat, sigma, deps + 1e-6, eps_p)[1]
    smooth = (inc > 0) == (trial_plus > 0)
    np.testing.assert_allclose(D[smooth], D_fd[smooth], atol=1e-5 * scale)


def test_von_mises_returns_onto_the_hardened_surface():
    mat = MATERIALS["von Mises, hardening"]
    sigma, deps = states()
    eps_p = RNG.uniform(0.0, 0.02, len(sigma))
    trial, de, sig = return_map(mat, sigma, deps, eps_p)
    p, q = invariants(sig)
    plastic = de > 0
    deps_p = (2.0 / 3.0) * de  # the conventional measure sqrt(2/3 e_p:e_p) of the hardening law
    np.testing.assert_allclose(q[plastic], mat.sigma_y + mat.H * (eps_p + deps_p)[plastic], rtol=1e-12)
    np.testing.assert_allclose(q[~plastic], trial.q[~plastic], rtol=1e-12)
    np.testing.assert_allclose(p, trial.p, rtol=1e-12)  # isochoric flow


def test_rate_independent_drucker_prager_returns_onto_the_cone():
    mat = MATERIALS["DP rate-independent, cohesive"]
    sigma, deps = states(p_mean=20e3)
    trial, de, sig = return_map(mat, sigma, deps, None)
    p, q = invariants(sig)
    a = mat.tension_limit
    plastic, apex = (de > 0) & (trial.p > -a), trial.p <= -a
    assert plastic.sum() > 20 and apex.sum() > 5
    np.testing.assert_allclose(q[plastic], mat.m * (p[plastic] + a), rtol=1e-10)
    np.testing.assert_allclose(p[~apex], trial.p[~apex], rtol=1e-12)
    np.testing.assert_allclose(sig[apex], np.broadcast_to(a * np.eye(3), sig[apex].shape), rtol=1e-12)
    assert np.all(q <= mat.m * (p + a) * (1 + 1e-12))


def test_perzyna_tends_to_the_rate_independent_limit():
    sigma, deps = states()
    limit = return_map(MATERIALS["DP rate-independent"], sigma, deps, None)[2]
    for gamma, expected in ((1e3, 1e-4), (1e6, 1e-7)):
        mat = DruckerPragerViscoplastic(**ELASTIC, phi=30.0, gamma=gamma)
        err = np.abs(return_map(mat, sigma, deps, None)[2] - limit).max() / np.abs(limit).max()
        assert err < expected


@pytest.mark.parametrize("kwargs, name", [({"sigma_y": 0.0}, "sigma_y"), ({"sigma_y": 1.0, "H": -1.0}, "H")])
def test_bad_von_mises_parameters(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} must be in"):
        VonMises(**ELASTIC, **kwargs)
